"""BLFmaint's refusals pinned at their boundaries, and the contact fit on the low-passed force.

* "a soft spring, not free play" (blf/maint.py ``_FLAT_TO_STEEP_MAX`` = 25 %): a record whose gap is
  a spring at 35 % and 45 % of the contact stiffness is refused (at twice the limit both would pass),
  one at 15 % and 20 % is measured; and on the limit itself, for a measured record, the refusal's
  statistic (slope - 3 sigma) equal to the limit times the softer stiffness passes while one float
  step less of the limit refuses.
* the contact lines regress D on the *low-passed* force: with a small force amplitude and a noisy
  load cell (580 N, 42 N std) the raw force would raise the stiffness by ~10 % and shift B by
  ~12 um; here both stay within 2 % and 3 um.
* the counted gates (200 samples, the samples of each contact and of the backlash) on their limit
  and one sample short, the correlation gate (|r| >= 0.3) just either side, and the loading gates of
  both sides (10 % of the other side, 10 x the load-cell noise) on their limit and one step short.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import signal

import blf.maint
from blf.errors import AnalysisError, InputError
from blf.maint import blf_maint
from blf.maint_regions import CONTACT_NOISE_MULT, CONTACT_SHARE_MIN, contact_extremes
from support.blfmaint_data import FS_HZ, SIGMA_D_MM, make_force_fight
from support.boundary import around

# ---------------------------------------------------------------------------- a soft spring in the gap


def spring_fight(rng: np.random.Generator, ratio: float, k: float = 80e3, backlash_mm: float = 0.1,
                 f_max_N: float = 6000.0, ramp_s: float = 1.9, gap_speed_mm_per_s: float = 0.25, cycles: int = 3,
                 sigma_d_mm: float = 0.0042, sigma_f_N: float = 10.0, sign: int = -1):
    """A force fight whose gap is a spring of ``ratio * k`` (G = ratio k D for |D| < B/2), continuous
    into contacts of stiffness k: the F-D relation of a soft spring, not of free play."""
    kc = ratio * k
    n_ramp = int(round(ramp_s * FS_HZ))
    up = np.arange(n_ramp) / n_ramp
    g0 = kc * backlash_mm / 2
    tri = g0 + np.concatenate((up, 1 - up)) * (f_max_N - g0)
    n_gap = int(round(backlash_mm / gap_speed_mm_per_s * FS_HZ))
    gap = np.linspace(-backlash_mm / 2, backlash_mm / 2, n_gap, endpoint=False)
    ds, gs = [], []
    for _ in range(cycles):
        ds += [gap, backlash_mm / 2 + (tri - g0) / k, -gap, -backlash_mm / 2 - (tri - g0) / k]
        gs += [kc * gap, tri, -kc * gap, -tri]
    d, g = np.concatenate(ds), np.concatenate(gs)
    return d + rng.normal(0.0, sigma_d_mm, d.size), sign * g + rng.normal(0.0, sigma_f_N, g.size)


@pytest.mark.parametrize("ratio", [0.35, 0.45])
@pytest.mark.parametrize("sign", [-1, 1])
def test_a_soft_spring_in_the_gap_is_refused(ratio, sign):
    d, f = spring_fight(np.random.default_rng(1), ratio, sign=sign)
    with pytest.raises(AnalysisError) as exc:
        blf_maint(d, f, FS_HZ)
    msg = str(exc.value)
    assert msg.startswith("no distinct backlash region: between the contact lines F still changes with D at ")
    assert msg.endswith("N/mm (a soft spring, not free play)")
    pct = int(re.search(r"N/mm, (\d+) % of the softer contact stiffness", msg).group(1))
    assert 25 < pct < 50  # measured below the true ratio (the margins), above the 25 % limit


@pytest.mark.parametrize("ratio", [0.15, 0.2])
def test_a_stiffer_gap_below_the_limit_is_measured(ratio):
    d, f = spring_fight(np.random.default_rng(1), ratio)
    r = blf_maint(d, f, FS_HZ)
    # the contact lines meet the gap's level (0 N) at +-B/2 (1 - ratio): the spring's share of the gap
    assert r.backlash_mm == pytest.approx(0.1 * (1 - ratio), abs=0.004)
    assert r.stiffness_left_N_per_mm == pytest.approx(80e3, rel=0.02)


def _flatness(d, f, monkeypatch):
    """(slope - 3 sigma of the backlash line, softer contact stiffness) of a record, as BLFmaint
    computes them: the paper's centre line (centre_slope=True) is the line the refusal tests."""
    monkeypatch.setattr(blf.maint, "_FLAT_TO_STEEP_MAX", 10.0)
    r = blf_maint(d, f, FS_HZ, centre_slope=True)
    lhs = abs(r.lines.centre.slope_N_per_mm) - 3.0 * float(np.sqrt(r.lines.centre.cov[1, 1]))
    return lhs, min(r.stiffness_left_N_per_mm, r.stiffness_right_N_per_mm)


@pytest.mark.parametrize("seed", [0, 2])
def test_soft_spring_refusal_on_its_limit_and_one_step_below(seed, monkeypatch):
    """With the limit set to this record's own statistic / stiffness (exact in floats), the record
    is measured (the rule is ``>``); one float step lower, it is refused."""
    d, f = spring_fight(np.random.default_rng(seed), 0.3)
    lhs, k_soft = _flatness(d, f, monkeypatch)
    below, at, above = around(lambda x: x * k_soft, lhs, lhs / k_soft)
    assert 0.25 < at < 0.3
    for limit, refused in ((above, False), (at, False), (below, True)):
        monkeypatch.setattr(blf.maint, "_FLAT_TO_STEEP_MAX", limit)
        if refused:
            with pytest.raises(AnalysisError, match=r"\(a soft spring, not free play\)$"):
                blf_maint(d, f, FS_HZ)
        else:
            assert blf_maint(d, f, FS_HZ).backlash_mm > 0.05


def test_soft_spring_limit_is_a_quarter_of_the_softer_contact(monkeypatch):
    """The shipped limit between the statistics of two records: 0.22 passes, 0.30 is refused."""
    stats = {}
    for ratio in (0.22, 0.3):
        lhs, k_soft = _flatness(*spring_fight(np.random.default_rng(1), ratio), monkeypatch)
        stats[ratio] = lhs / k_soft
    monkeypatch.undo()
    assert stats[0.22] < 0.25 < stats[0.3] < 0.3
    blf_maint(*spring_fight(np.random.default_rng(1), 0.22), FS_HZ)
    with pytest.raises(AnalysisError, match="a soft spring"):
        blf_maint(*spring_fight(np.random.default_rng(1), 0.3), FS_HZ)


# ---------------------------------------------------------------------------- the low-passed force


NOISY_SMALL = dict(backlash_mm=0.1, stiffness_left_N_per_mm=5e3, stiffness_right_N_per_mm=5e3, f_max_N=580.0,
                   sigma_f_N=42.0, sigma_d_mm=SIGMA_D_MM)


@pytest.mark.parametrize("seed", range(4))
def test_contact_lines_regress_on_the_low_passed_force(seed):
    """580 N of force fight, a 42 N std load cell: D on the raw F would read the stiffness ~10 % high
    (F's noise attenuates the compliance) and B ~12 um long; the low-passed F keeps both."""
    d, f, _, _ = make_force_fight(np.random.default_rng(seed), **NOISY_SMALL)
    r = blf_maint(d, f, FS_HZ)
    assert abs(r.stiffness_left_N_per_mm / 5e3 - 1) < 0.02 and abs(r.stiffness_right_N_per_mm / 5e3 - 1) < 0.02
    assert abs(r.backlash_mm - 0.1) < 0.003
    # what the raw force would give on the same contact samples: the errors-in-variables attenuation
    m = r.mask_left
    raw_k = 1.0 / np.polyfit(-f[m], d[m], 1)[0]
    assert 0.06 < raw_k / 5e3 - 1 < 0.15


# ---------------------------------------------------------------------------- counted gates


def test_two_hundred_samples_are_the_fewest():
    d, f, _, _ = make_force_fight(np.random.default_rng(0))
    with pytest.raises(InputError, match=r"^d_mm and f_N need at least 200 samples \(mm, N\); got shape \(199,\)$"):
        blf_maint(d[:199], f[:199], FS_HZ)
    with pytest.raises(AnalysisError):  # past the size gate: 200 samples of a contact ramp are no force fight
        blf_maint(d[:200], f[:200], FS_HZ)


def _min_passing(kw_name: str, d, f) -> int:
    """The most samples a region may be required to have for this record (each refusal names the count
    it had: follow them down until the record passes)."""
    m = 10**6
    for _ in range(8):
        try:
            blf_maint(d, f, FS_HZ, **{kw_name: m})
            return m
        except AnalysisError as exc:
            m = int(re.search(r"too few samples: (\d+) < ", str(exc)).group(1))
    raise AssertionError("did not converge")


@pytest.mark.parametrize("kw_name, region", [("min_contact_points", "contact"), ("min_centre_points", "centre")])
def test_region_sample_counts_on_their_limit_and_one_more(kw_name, region):
    d, f, _, _ = make_force_fight(np.random.default_rng(4))
    m = _min_passing(kw_name, d, f)
    assert m > 100
    r = blf_maint(d, f, FS_HZ, **{kw_name: m})
    if region == "centre":
        assert r.n_centre == m
    with pytest.raises(AnalysisError, match=rf"{region}.* region has too few samples: {m} < {m + 1} "):
        blf_maint(d, f, FS_HZ, **{kw_name: m + 1})


@pytest.mark.parametrize("kw_name", ["min_contact_points", "min_centre_points"])
def test_region_sample_counts_at_least_three(kw_name):
    d, f, _, _ = make_force_fight(np.random.default_rng(4))
    blf_maint(d, f, FS_HZ, **{kw_name: 3})
    with pytest.raises(InputError, match=rf"^{kw_name} must be an int >= 3 \(count\), got 2$"):
        blf_maint(d, f, FS_HZ, **{kw_name: 2})


# ---------------------------------------------------------------------------- the correlation gate


def _lowpass(x):
    """The documented low-pass of BLFmaint's segmentation: zero-phase 2nd-order Butterworth, 40 rad/s."""
    sos = signal.butter(2, 40.0 / (2.0 * np.pi), btype="low", fs=FS_HZ, output="sos")
    return signal.sosfiltfilt(sos, x)


@pytest.mark.parametrize("target_sign", [1.0, -1.0])
def test_correlation_gate_just_either_side_of_0p3(target_sign):
    """F = target_sign * G + beta * (an unrelated slow signal): beta bisected until the low-passed
    D and F correlate at 0.3 -+ 1e-9."""
    d, _, _, g_true = make_force_fight(np.random.default_rng(0))
    t = np.arange(d.size) / FS_HZ
    other = 6000.0 * np.sin(2 * np.pi * 0.37 * t)
    d_f, g_f, o_f = _lowpass(d), _lowpass(-g_true), _lowpass(other)

    def corr(beta):
        return abs(float(np.corrcoef(d_f, target_sign * g_f + beta * o_f)[0, 1]))

    def beta_for(target):
        lo, hi = 0.0, 100.0  # corr falls from ~0.99 at beta = 0 to ~0 at 100
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if corr(mid) > target else (lo, mid)
        return lo

    b_above, b_below = beta_for(0.3 + 1e-9), beta_for(0.3 - 1e-9)
    assert corr(b_above) == pytest.approx(0.3 + 1e-9, abs=1e-13)
    assert corr(b_below) == pytest.approx(0.3 - 1e-9, abs=1e-13)
    f_above = target_sign * (-g_true) + b_above * other
    f_below = target_sign * (-g_true) + b_below * other
    with pytest.raises(AnalysisError, match=r"^no F-D relation: D and F do not move together, as they do in a "
                                            r"force fight \(correlation of the low-passed D and F -?0.300, \|r\| < 0.3\)$"):
        blf_maint(d, f_below, FS_HZ)
    try:
        blf_maint(d, f_above, FS_HZ)
    except AnalysisError as exc:  # a later refusal is fine; the correlation gate is passed
        assert "do not move together" not in str(exc)


# ---------------------------------------------------------------------------- both sides loaded


def _cloud(left_N: float, right_N: float, n: int = 1000, k: int = 100) -> np.ndarray:
    """A low-passed force whose 0.5 % and 99.5 % quantiles are exactly -left and right (k of n samples
    at each extreme, the rest 0)."""
    g = np.zeros(n)
    g[:k], g[-k:] = -left_N, right_N
    return g


def test_cloud_quantiles_are_exact():
    lo, hi = (float(v) for v in np.quantile(_cloud(1234.5, 98.25), [0.005, 0.995]))
    assert (lo, hi) == (-1234.5, 98.25)


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_side_loaded_to_10_percent_of_the_other_on_the_limit_and_one_step_short(side):
    assert CONTACT_SHARE_MIN == 0.10 and CONTACT_NOISE_MULT == 10.0
    big = 1000.0
    share = CONTACT_SHARE_MIN * big  # 100 N exactly
    for small, refused in ((math.nextafter(share, 1e9), False), (share, False), (math.nextafter(share, 0.0), True)):
        g = _cloud(small, big) if side == "left" else _cloud(big, small)
        if refused:
            with pytest.raises(AnalysisError, match=r"^backlash not traversed: the force fight never reached contact "
                                                    rf"on the .* side .*, at the {'lower' if side == 'left' else 'upper'} end"
                                                    r".* a contact line needs at least 10 %$"):
                contact_extremes(g, 1.0, -1, (-0.2, 0.2))
        else:
            lo, hi = contact_extremes(g, 1.0, -1, (-0.2, 0.2))
            assert (lo, hi) == ((-small, big) if side == "left" else (-big, small))


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_side_loaded_to_10_load_cell_noises_on_the_limit_and_one_step_short(side):
    """Both sides loaded alike (no share problem): the noise floor 10 x sigma_F decides."""
    reach = 500.0
    g = _cloud(reach, 4000.0) if side == "left" else _cloud(4000.0, reach)
    below, at, above = around(lambda s: CONTACT_NOISE_MULT * s, reach, reach / 10)
    for sigma, refused in ((below, False), (at, False), (above, True)):
        if refused:
            with pytest.raises(AnalysisError, match=r"less than 10 x the load-cell noise \(50 N std\)$"):
                contact_extremes(g, sigma, -1, (-0.2, 0.2))
        else:
            contact_extremes(g, sigma, -1, (-0.2, 0.2))


def test_neither_side_loaded_names_the_force_reached():
    with pytest.raises(AnalysisError, match=r"^backlash not traversed: the force fight never reached contact on "
                                            r"either side: \|F\| stayed below 90 N, less than 10 x the load-cell "
                                            r"noise \(10 N std\)$"):
        contact_extremes(_cloud(90.0, 80.0), 10.0, -1, (-0.2, 0.2))
