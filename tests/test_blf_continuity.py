"""blf.continuity: the jump rules on their boundaries (exact binary numbers: no rounding at the limit).

Time: a step above GAP_PERIODS = 10 median periods is a gap, a step <= 0 goes back. Position: a step
above v * dt + NOISE_K * sqrt(2) * sigma (sigma from the second differences) is a jump.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from blf.continuity import GAP_PERIODS, MAD_TO_SIGMA, NOISE_K, find_jumps, noise_std
from blf.errors import InputError

T = 0.25  # [s] a period exact in binary
EPS = 2.0**-20


def _times(step_at: int, step: float, n: int = 40) -> np.ndarray:
    dt = np.full(n - 1, T)
    dt[step_at - 1] = step
    return np.concatenate([[0.0], np.cumsum(dt)])


def test_the_constants():
    assert (GAP_PERIODS, NOISE_K, MAD_TO_SIGMA) == (10.0, 10.0, 1.4826)


@pytest.mark.parametrize("step,kind", [(GAP_PERIODS * T, None), (GAP_PERIODS * T + EPS, "time_gap"),
                                       (EPS, None), (0.0, "time_backwards"), (-T, "time_backwards")])
def test_a_time_step_on_its_boundary(step, kind):
    t = _times(20, step)
    c = find_jumps(t, {}, {})
    assert c.sample_period_s == T and c.gap_limit_s == GAP_PERIODS * T
    if kind is None:
        assert c.first is None and c.count == 0
    else:
        assert (c.first.kind, c.first.index, c.first.channel, c.count) == (kind, 20, "t", 1)
        assert (c.first.before, c.first.after) == (t[19], t[20])


@pytest.mark.parametrize("step,jump", [(1.0, False), (1.0 + EPS, True), (-1.0, False), (-1.0 - EPS, True)])
def test_a_position_step_on_its_boundary_without_noise(step, jump):
    """A still channel (noise 0) that steps once: allowed v * dt = 4 * 0.25 = 1.0, in either direction."""
    t = np.arange(40) * T
    x = np.where(np.arange(40) >= 25, step, 0.0)
    c = find_jumps(t, {"s1": x}, {"s1": 4.0})
    assert c.noise == {"s1": 0.0}
    if jump:
        j = c.first
        assert (j.kind, j.index, j.channel, j.before, j.after, j.limit) == ("position_step", 25, "s1", 0.0, step, 1.0)
    else:
        assert c.first is None


def test_the_noise_term_widens_the_limit_by_k_sqrt2_sigma():
    """Noise +-a alternating: every second difference is +-4a, sigma = 1.4826 * 4a / sqrt(6); a step of
    exactly the limit passes, the next float above it does not."""
    n, a, v = 400, 0.01, 4.0
    base = a * (-1.0) ** np.arange(n)
    sigma = MAD_TO_SIGMA * 4 * a / math.sqrt(6.0)
    assert noise_std(base) == pytest.approx(sigma, rel=1e-12)
    t = np.arange(n) * T
    # a step placed where the alternating noise goes from -a to +a: its difference is 2a plus the step
    limit = v * T + NOISE_K * math.sqrt(2.0) * noise_std(base)
    k = 201  # base[200] = +a, base[201] = -a: the noise difference there is -2a
    for extra, jump in ((0.0, False), (1e-9, True)):
        x = base.copy()
        x[k:] += limit + 2 * a + extra
        c = find_jumps(t, {"phi1": x}, {"phi1": v})
        got = c.first is not None and c.first.index == k
        assert got is jump, (extra, c.first, c.noise)


def test_noise_is_estimated_robustly_from_gaussian_noise_on_a_smooth_motion():
    rng = np.random.default_rng(3)
    t = np.arange(200_000) * 0.002
    x = 5.0 * np.sin(2 * np.pi * 0.2 * t) + rng.normal(0.0, 0.004, t.size)
    x[50_000:] += 3.0  # one jump does not move the estimate
    assert noise_std(x) == pytest.approx(0.004, rel=0.02)
    c = find_jumps(t, {"s1": x}, {"s1": 100.0})
    assert (c.first.kind, c.first.index, c.count) == ("position_step", 50_000, 1)


def test_the_earliest_jump_over_all_channels_is_first_and_all_are_counted():
    t = np.arange(100) * T
    x1 = np.where(np.arange(100) >= 60, 5.0, 0.0)
    x2 = np.where(np.arange(100) >= 30, 5.0, 0.0)
    t = t.copy()
    t[80:] += 10.0  # and a gap at 80
    c = find_jumps(t, {"s1": x1, "s2": x2}, {"s1": 4.0, "s2": 4.0})
    assert (c.first.channel, c.first.index, c.count) == ("s2", 30, 3)


def test_bad_arrays_are_refused_naming_them():
    with pytest.raises(InputError, match="t_s must have at least 2 samples"):
        find_jumps([0.0], {}, {})
    with pytest.raises(InputError, match="s1 must have as many samples as t_s"):
        find_jumps([0.0, 1.0, 2.0], {"s1": [0.0, 1.0, 2.0, 3.0]}, {"s1": 1.0})
    with pytest.raises(InputError, match="max_speed"):
        find_jumps([0.0, 1.0], {"s1": [0.0, 1.0]}, {"s1": 0.0})


@pytest.mark.parametrize("starts,found", [((25,), None), ((24,), 25), ((26,), 25), ((), 25)])
def test_a_position_step_into_a_declared_part_start_only_is_not_judged(starts, found):
    """A step of 2 (limit 1) into sample 25: not judged where 25 starts a part made apart, judged one
    sample either side; the time rule does not look at parts (a gap into a part start is still one)."""
    t = np.arange(40) * T
    x = np.where(np.arange(40) >= 25, 2.0, 0.0)
    c = find_jumps(t, {"s1": x}, {"s1": 4.0}, part_starts=starts)
    assert (c.first.index if c.first else None) == found and c.count == (0 if found is None else 1)
    t_gap = t.copy()
    t_gap[25:] += 11 * T
    g = find_jumps(t_gap, {"s1": np.zeros(40)}, {"s1": 4.0}, part_starts=(25,))
    assert (g.first.kind, g.first.index) == ("time_gap", 25)


def test_block_wise_checks_equal_whole_arrays(monkeypatch):
    """Issue 34: the position-step test and the noise estimate formed block by block find the same."""
    import blf.continuity as cont

    rng = np.random.default_rng(34)
    t = np.arange(3000) * 1e-3
    x = np.cumsum(rng.normal(0.0, 1e-3, t.size))
    x[[700, 2100]] += 2.0
    whole = cont.find_jumps(t, {"s1": x}, {"s1": 1.0})
    assert whole.first is not None
    for block in (1, 64):
        monkeypatch.setattr(cont, "_BLOCK", block)
        assert cont.find_jumps(t, {"s1": x}, {"s1": 1.0}) == whole
