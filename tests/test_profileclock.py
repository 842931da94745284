"""The profile clock (hil.check.profileclock): periods without a sample are held, at its 1.5-period rule."""

from __future__ import annotations

import math

import pytest

from hil.check.profileclock import ProfileClock
from support.boundary import around

T = 0.002


def test_a_gap_beyond_one_and_a_half_periods_is_held_less_one_period():
    c = ProfileClock(T)
    c.restart(1.0)
    assert c.elapsed(1.0) == 0.0 and c.elapsed(1.002) == pytest.approx(0.002)
    assert c.elapsed(1.042) == pytest.approx(0.004)  # 40 ms without a sample: one period of it counts
    assert c.held_s == pytest.approx(0.038)
    c.restart(1.042)  # a new step: its own time from 0
    assert c.elapsed(1.044) == pytest.approx(0.002) and c.held_s == 0.0


def test_the_hold_rule_on_its_limit_and_one_step_beyond():
    """A gap of exactly 1.5 periods (a late SYNC) holds nothing; one float beyond, it holds the gap less T."""
    below, at, above = around(lambda g: g - 0.0, 1.5 * T, 1.5 * T)  # the gap from a sample at 0, as the rule takes it
    for gap, held in ((below, False), (at, False), (above, True)):
        c = ProfileClock(T)
        c.restart(0.0)
        c.elapsed(0.0)
        tau = c.elapsed(gap)
        assert (c.held_s > 0) is held, gap
        assert tau == (T if held else gap)


@pytest.mark.parametrize("bad", [0.0, -0.002, math.nan, math.inf])
def test_a_period_that_is_not_a_time_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match=r"period_s must be finite and > 0 \[s\]"):
        ProfileClock(bad)
