"""blf.diagnose.phases: a held part found from the check's design ends before the unload ramp it may run into.

A sweep's end found from the motion can lie up to about a second after the motion stops, inside the
unload ramp of the drive that held the opposing force (seen on a simulated check in the bare
t,phi1..F2 layout, noise seed 14: 0.57 s of the ramp were compared as held at the full force). The
trailing stretch whose force changes faster than a quarter of the ramp's rate is cut (0.2 s means).
"""

from __future__ import annotations

import numpy as np
import pytest

from blf.diagnose.phases import _RAMP_FRACTION, _RATE_WINDOW_S, _before_ramp

T = 0.002


def _hold_then_ramp(rate_N_per_s: float, hold_s: float = 4.0, ramp_s: float = 1.0, noise_N: float = 10.0):
    rng = np.random.default_rng(5)
    n_hold, n_ramp = int(hold_s / T), int(ramp_s / T)
    f = np.r_[np.full(n_hold, 2000.0), 2000.0 - rate_N_per_s * T * np.arange(1, n_ramp + 1)]
    return f + rng.normal(0.0, noise_N, f.size), n_hold


def test_the_unload_ramp_is_cut_and_the_hold_kept():
    f, n_hold = _hold_then_ramp(2000.0)  # the shipped profile: 2000 N off in 1 s
    end = _before_ramp(f, T, _RAMP_FRACTION * 2000.0 / 1.0)
    assert n_hold - int(2 * _RATE_WINDOW_S / T) <= end <= n_hold  # at most two windows of the hold lost


def test_a_stepped_ramp_is_a_ramp_too():
    """A drive's ramp of 200 N setpoint steps every 0.1 s (as the simulated drives record it)."""
    n_hold = int(4.0 / T)
    steps = np.repeat(2000.0 - 200.0 * np.arange(1, 11), int(0.1 / T))
    f = np.r_[np.full(n_hold, 2000.0), steps] + np.random.default_rng(6).normal(0.0, 10.0, n_hold + steps.size)
    end = _before_ramp(f, T, _RAMP_FRACTION * 2000.0)
    assert n_hold - int(2 * _RATE_WINDOW_S / T) <= end <= n_hold


@pytest.mark.parametrize("rate, cut", [(520.0, True), (480.0, False)])
def test_the_rate_limit_is_a_quarter_of_the_ramp(rate, cut):
    """A trailing drift of 520 N/s is a ramp (limit 500 N/s); one of 480 N/s is the hold's own (kept whole)."""
    f, n_hold = _hold_then_ramp(rate, ramp_s=1.0, noise_N=0.0)
    end = _before_ramp(f, T, _RAMP_FRACTION * 2000.0)
    assert (end < f.size) is cut
    if cut:
        assert end <= n_hold


def test_a_hold_without_a_ramp_is_kept_whole():
    f = 2000.0 + np.random.default_rng(7).normal(0.0, 10.0, int(4.0 / T))
    assert _before_ramp(f, T, _RAMP_FRACTION * 2000.0) == f.size
    assert _before_ramp(f[:100], T, 500.0) == 100  # shorter than two windows: nothing to judge
