"""BLFmaint's refusals pinned at their boundaries, and the contact fit on the low-passed force.

* "a soft spring, not free play" (blf/maint/blfmaint.py ``_FLAT_TO_STEEP_MAX`` = 25 %): a record whose gap is
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

import blf.maint.blfmaint
from blf.errors import AnalysisError, InputError
from blf.maint.blfmaint import blf_maint
from blf.maint.regions import CONTACT_NOISE_MULT, CONTACT_SHARE_MIN, contact_extremes
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
def test_a_soft_spring_in_the_gap_is_refused(ratio, sign, monkeypatch):
    d, f = spring_fight(np.random.default_rng(1), ratio, sign=sign)
    with pytest.raises(AnalysisError) as exc:
        blf_maint(d, f, FS_HZ)
    msg = str(exc.value)
    pct = int(re.search(r"N/mm, (\d+) % of the softer contact stiffness", msg).group(1))
    assert 25 < pct < 50  # measured below the true ratio (the margins), above the 25 % limit
    # the numbers of the message are the backlash line's slope and the softer contact stiffness
    monkeypatch.setattr(blf.maint.blfmaint, "_FLAT_TO_STEEP_MAX", 10.0)
    r = blf_maint(d, f, FS_HZ, centre_slope=True)
    slope, k_soft = abs(r.lines.centre.slope_N_per_mm), min(r.stiffness_left_N_per_mm, r.stiffness_right_N_per_mm)
    assert msg == ("no distinct backlash region: between the contact lines F still changes with D at "
                   f"{slope:.4g} N/mm, {100 * slope / k_soft:.0f} % of the softer contact stiffness {k_soft:.4g} N/mm "
                   "(a soft spring, not free play)")


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
    monkeypatch.setattr(blf.maint.blfmaint, "_FLAT_TO_STEEP_MAX", 10.0)
    r = blf_maint(d, f, FS_HZ, centre_slope=True)
    lhs = abs(r.lines.centre.slope_N_per_mm) - 3.0 * float(np.sqrt(r.lines.centre.cov[1, 1]))
    return lhs, min(r.stiffness_left_N_per_mm, r.stiffness_right_N_per_mm)


def _records_on_their_limit(monkeypatch, wanted: int = 2, seeds: int = 12):
    """The first ``wanted`` spring-fight records (seeds 0, 1, ...) whose limit lands exactly in floats.

    ``limit * k_soft == lhs`` has no float solution for some records (the product jumps over ``lhs``),
    and which ones depends on the last bits of the regression, so on the machine's BLAS: a fixed seed
    that lands on one machine jumps on another (seeds 0 and 2 did on this project's CI machines until
    2026-11-26). The records are taken in seed order, so the choice is deterministic on a machine."""
    found = []
    for seed in range(seeds):
        d, f = spring_fight(np.random.default_rng(seed), 0.3)
        lhs, k_soft = _flatness(d, f, monkeypatch)
        try:
            found.append((d, f, around(lambda x, k=k_soft: x * k, lhs, lhs / k_soft)))
        except AssertionError:
            continue
        if len(found) == wanted:
            return found
    raise AssertionError(f"only {len(found)} of {seeds} records land on their limit in floats")


def test_soft_spring_refusal_on_its_limit_and_one_step_below(monkeypatch):
    """With the limit set to a record's own statistic / stiffness (exact in floats), the record
    is measured (the rule is ``>``); one float step lower, it is refused (two records)."""
    for d, f, (below, at, above) in _records_on_their_limit(monkeypatch):
        _limit_sides(d, f, below, at, above, monkeypatch)


def _limit_sides(d, f, below, at, above, monkeypatch):
    assert 0.25 < at < 0.3
    for limit, refused in ((above, False), (at, False), (below, True)):
        monkeypatch.setattr(blf.maint.blfmaint, "_FLAT_TO_STEEP_MAX", limit)
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
                                            r"force fight \(correlation of the low-passed D and F -?0.300, "
                                            r"\|r\| < 0.3\)$"):
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
            end = "lower" if side == "left" else "upper"
            with pytest.raises(AnalysisError, match=r"^backlash not traversed: the force fight never reached contact "
                                                    rf"on the .* side .*, at the {end} end"
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


# ---------------------------------------------------------------------------- the fitted lines


@pytest.mark.parametrize("sign, k_left, k_right", [(-1, 80_000.0, 80_000.0), (1, 80_000.0, 80_000.0),
                                                   (-1, 90_000.0, 60_000.0), (1, 60_000.0, 90_000.0)])
def test_lines_meet_at_their_intersections_and_give_the_backlash(sign, k_left, k_right):
    """The three lines' own methods: D on a contact line and its inverse, F on the centre line; the
    reported intersections lie on both lines they join; B is their distance. The curve's threshold is
    half the softer contact, whichever side that is."""
    d, f, _, _ = make_force_fight(np.random.default_rng(6), slope_sign=sign, stiffness_left_N_per_mm=k_left,
                                  stiffness_right_N_per_mm=k_right)
    r = blf_maint(d, f, FS_HZ, centre_slope=True)
    L = r.lines
    for line in (L.left, L.right):
        forces = np.array([-3000.0, 0.0, 2500.0])
        assert np.allclose(line.d_mm(forces), line.d_at_zero_force_mm + line.compliance_mm_per_N * forces,
                           rtol=0, atol=1e-15)
        assert np.allclose(line.f_N(line.d_mm(forces)), forces, rtol=1e-12, atol=1e-9)
        assert np.sign(line.compliance_mm_per_N) == sign  # D and F move together with the global sign
    dd = np.array([-0.1, 0.0, 0.05])
    assert np.allclose(L.centre.f_N(dd), L.centre.f_at_zero_d_N + L.centre.slope_N_per_mm * dd, rtol=0, atol=1e-9)
    for dx, fx, contact in ((L.d_left_mm, L.f_left_N, L.left), (L.d_right_mm, L.f_right_N, L.right)):
        assert contact.d_mm(fx) == pytest.approx(dx, abs=1e-12)
        assert L.centre.f_N(dx) == pytest.approx(fx, abs=1e-9)
    assert r.backlash_mm == pytest.approx(L.d_right_mm - L.d_left_mm, abs=1e-15)
    assert r.stiffness_left_N_per_mm == pytest.approx(1.0 / abs(L.left.compliance_mm_per_N), rel=1e-12)
    assert r.stiffness_right_N_per_mm == pytest.approx(1.0 / abs(L.right.compliance_mm_per_N), rel=1e-12)
    assert r.slope_sign == sign and (L.left.side, L.right.side) == ("left", "right")
    k_soft = min(r.stiffness_left_N_per_mm, r.stiffness_right_N_per_mm)
    if k_left != k_right:  # the softer side is the one made softer
        assert k_soft == (r.stiffness_right_N_per_mm if k_right < k_left else r.stiffness_left_N_per_mm)
    assert r.curve.threshold_N_per_mm == pytest.approx(sign * 0.5 * k_soft, rel=1e-12)
    assert r.dfdd_median == np.median(r.curve.dfdd_N_per_mm)
    assert (r.n_left, r.n_centre, r.n_right) == (int(r.mask_left.sum()), int(r.mask_centre.sum()),
                                                 int(r.mask_right.sum())) == (L.left.n, L.centre.n, L.right.n)


# ---------------------------------------------------------------------------- the uncertainties, known answers


def _newey_west_ols(x, y, idx, n_total, lags):
    """Independent reference: OLS y = a + b x and the Newey-West (Bartlett) sandwich of (a, b), lag
    products only between samples adjacent in the full record, small-sample factor n / (n - 2)."""
    X = np.column_stack((np.ones_like(x), x))
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    u = y - X @ beta
    H = np.zeros((n_total, 2))
    H[idx] = X * u[:, None]
    S = H.T @ H
    for k in range(1, lags + 1):
        G = H[k:].T @ H[:-k]
        S += (1 - k / (lags + 1)) * (G + G.T)
    Qi = np.linalg.inv(X.T @ X)
    return beta, Qi @ S @ Qi * x.size / (x.size - 2), float(np.sqrt(np.mean(u**2)))


def _newey_west_mean(y, idx, n_total, lags):
    c0 = float(np.mean(y))
    full = np.zeros(n_total)
    full[idx] = y - c0
    s = full @ full + sum(2 * (1 - k / (lags + 1)) * (full[k:] @ full[:-k]) for k in range(1, lags + 1))
    return c0, s / y.size**2 * y.size / (y.size - 1), float(np.sqrt(np.mean((y - c0) ** 2)))


def _d_star(a, b, c0, c1):
    return (a + b * c0) / (1 - b * c1)


@pytest.mark.parametrize("centre_slope", [False, True])
@pytest.mark.parametrize("sign, kw", [(-1, dict(d_noise_ar1=0.6)), (1, dict(stiffness_left_N_per_mm=14e3,
                                                                         stiffness_right_N_per_mm=20e3)),
                                      (-1, "spring"), (1, "spring"), (-1, "three")])
def test_regressions_and_sigmas_match_an_independent_newey_west(centre_slope, sign, kw, monkeypatch):
    """Every line, covariance, residual and the backlash sigma against a separate implementation of
    the documented estimators (the masks and the low-pass are the result's and the docstring's):
    D on the low-passed G in contact, G's level or line on D in the backlash, Newey-West with lags up to
    hac_lag_s, B's sigma by first-order propagation (here with a numerical Jacobian)."""
    opts = {}
    if kw == "spring":  # a gap spring at 20 % of the contacts: 1 - b c1 ~ 0.8, the intersections' slope terms count;
        d, f = spring_fight(np.random.default_rng(12), 0.2, sign=sign)  # D offset 0.3 mm: the level at D = 0 too
        d = d + 0.3
        monkeypatch.setattr(blf.maint.blfmaint, "_FLAT_TO_STEEP_MAX", 10.0)
    elif kw == "three":  # the fewest samples a line may have: 3 in the backlash (small-sample factors n - 1, n - 2)
        d, f, _, _ = make_force_fight(np.random.default_rng(0), n_cycles=1)
        opts = dict(centre_margin_frac=0.496, min_centre_points=3)
    else:
        d, f, _, _ = make_force_fight(np.random.default_rng(12), slope_sign=sign, **kw)
    r = blf_maint(d, f, FS_HZ, centre_slope=centre_slope, **opts)
    if kw == "three":
        assert r.n_centre == 3
    assert r.slope_sign == sign
    lags = round(0.05 * FS_HZ)
    g, g_f = sign * f, sign * _lowpass(f)
    flip = np.diag([1.0, float(sign)])
    params = {}
    for side, line, mask in (("left", r.lines.left, r.mask_left), ("right", r.lines.right, r.mask_right)):
        idx = np.flatnonzero(mask)
        (a, b), cov, rms = _newey_west_ols(g_f[idx], d[idx], idx, d.size, lags)
        assert line.d_at_zero_force_mm == pytest.approx(a, rel=1e-9, abs=1e-12)
        assert line.compliance_mm_per_N == pytest.approx(sign * b, rel=1e-9)
        assert np.allclose(line.cov, flip @ cov @ flip, rtol=1e-7, atol=0)
        assert line.rmse_mm == pytest.approx(rms, rel=1e-9) and line.n == idx.size
        assert (line.f_min_N, line.f_max_N) == (f[idx].min(), f[idx].max())
        params[side] = (a, b, cov)
    idx = np.flatnonzero(r.mask_centre)
    if centre_slope:
        (c0, c1), cov_c, rms_c = _newey_west_ols(d[idx], g[idx], idx, d.size, lags)
    else:
        c0, var0, rms_c = _newey_west_mean(g[idx], idx, d.size, lags)
        c1, cov_c = 0.0, np.diag([var0, 0.0])
    C = r.lines.centre
    assert C.f_at_zero_d_N == pytest.approx(sign * c0, rel=1e-9) and C.slope_N_per_mm == pytest.approx(sign * c1,
                                                                                                        rel=1e-9)
    assert np.allclose(C.cov, cov_c, rtol=1e-7, atol=0) and C.rmse_N == pytest.approx(rms_c, rel=1e-9)
    assert (C.n, C.d_min_mm, C.d_max_mm) == (idx.size, d[idx].min(), d[idx].max())
    (a_l, b_l, cov_l), (a_r, b_r, cov_r) = params["left"], params["right"]
    theta = np.array([a_l, b_l, a_r, b_r, c0, c1])

    def backlash(t):
        return _d_star(t[2], t[3], t[4], t[5]) - _d_star(t[0], t[1], t[4], t[5])

    assert r.backlash_mm == pytest.approx(backlash(theta), rel=1e-9)
    J = np.array([(backlash(theta + h) - backlash(theta - h)) / (2 * h.sum())
                  for h in np.diag(np.maximum(np.abs(theta), 1e-3) * 1e-6)])
    cov = np.zeros((6, 6))
    cov[0:2, 0:2], cov[2:4, 2:4], cov[4:6, 4:6] = cov_l, cov_r, cov_c
    assert r.backlash_sigma_mm == pytest.approx(float(np.sqrt(J @ cov @ J)), rel=1e-5)
    assert r.stiffness_left_N_per_mm == pytest.approx(1 / b_l, rel=1e-9)
    assert r.stiffness_left_sigma_N_per_mm == pytest.approx(np.sqrt(cov_l[1, 1]) / b_l**2, rel=1e-7)
    assert r.stiffness_right_sigma_N_per_mm == pytest.approx(np.sqrt(cov_r[1, 1]) / b_r**2, rel=1e-7)
    assert r.lines.d_left_mm == pytest.approx(_d_star(a_l, b_l, c0, c1), rel=1e-9)
    assert r.lines.f_right_N == pytest.approx(sign * (c0 + c1 * _d_star(a_r, b_r, c0, c1)), rel=1e-9)


def test_binned_curve_known_answer():
    """The binned F-D curve (report Figure 4): bins of at least min_bin_count (3) samples, the slope a
    local linear fit over 2 * slope_window_bins + 1 = 5 bins then a 3-point running median."""
    d, f, d_true, _ = make_force_fight(np.random.default_rng(3), sigma_d_mm=0.0, sigma_f_N=0.0)
    # then 60 um further into the right contact at 1 mm/s: 2.5 samples per 5 um bin, sparse bins
    ramp = d_true.max() + np.arange(1, 31) * 1.0 / FS_HZ
    rng = np.random.default_rng(1)
    d = np.concatenate((d, ramp)) + rng.normal(0.0, 0.0042, d.size + ramp.size)
    f = np.concatenate((f, -(ramp - 0.05) * 80e3)) + rng.normal(0.0, 10.0, d.size)
    r = blf_maint(d, f, FS_HZ)
    c = r.curve
    assert c.count.min() == 3  # bins of fewer samples dropped, of three kept
    assert blf_maint(d, f, FS_HZ, min_bin_count=1).curve.count.min() < 3
    x, y = c.d_mm, c.f_N
    raw = np.array([np.polyfit(x[max(0, k - 2):k + 3], y[max(0, k - 2):k + 3], 1)[0] for k in range(x.size)])
    med = raw.copy()
    med[1:-1] = np.median(np.stack((raw[:-2], raw[1:-1], raw[2:])), axis=0)
    assert np.allclose(c.dfdd_N_per_mm, med, rtol=1e-6, atol=1e-6)
    assert c.bin_width_mm == 0.005 and np.all(np.diff(x) > 0)


# ---------------------------------------------------------------------------- refusals name argument and unit


@pytest.mark.parametrize("change, message", [
    (dict(d_mm=np.zeros((2, 300))), r"^d_mm must be a 1-D array in mm; got shape \(2, 300\)$"),
    (dict(d_mm="D"), r"^d_mm must be a 1-D numeric array in mm; got str that cannot be converted to float"),
    (dict(f_N=np.zeros((300, 1))), r"^f_N must be a 1-D array in N; got shape \(300, 1\)$"),
    (dict(f_N=[None] * 300), r"^f_N must be finite \(in N\); got 300 NaN/inf value\(s\) in shape \(300,\)$"),
    (dict(f_N=np.zeros(299)), r"^f_N \(in N\) must have the same shape as d_mm \(in mm\); got f_N shape \(299,\) and "
                              r"d_mm shape \(300,\)$"),
    (dict(sample_rate_Hz=0.0), r"^sample_rate_Hz must be a finite positive number in Hz; got 0.0 \(shape \(\)\)$"),
    (dict(lowpass_rad_s=-40.0), r"^lowpass_rad_s must be a finite positive number in rad/s; got -40.0"),
    (dict(lowpass_rad_s=1600.0), r"^lowpass_rad_s must be below the Nyquist frequency pi\*sample_rate_Hz = 1571 rad/s; "
                                 r"got 1600 rad/s \(shape \(\)\)$"),
    (dict(bin_width_mm=0.0), r"^bin_width_mm must be a finite positive number in mm; got 0.0 \(shape \(\)\)$"),
    (dict(slope_window_bins=0), r"^slope_window_bins must be an int >= 1 \(count\), got 0$"),
    (dict(min_bin_count=0), r"^min_bin_count must be an int >= 1 \(count\), got 0$"),
    (dict(min_contact_points=2.5), r"^min_contact_points must be an int >= 3 \(count\), got 2.5$"),
    (dict(min_centre_points=True), r"^min_centre_points must be an int >= 3 \(count\), got True$"),
    (dict(contact_margin_frac=0.5), r"^contact_margin_frac must be a finite scalar in \[0.0, 0.5\) \(fraction, "
                                    r"dimensionless\), got 0.5$"),
    (dict(centre_margin_frac=-0.01), r"^centre_margin_frac must be a finite scalar in \[0.0, 0.5\) \(fraction, "
                                     r"dimensionless\), got -0.01$"),
    (dict(hac_lag_s=-0.05), r"^hac_lag_s must be a finite scalar >= 0.0 s, got -0.05$"),
    (dict(centre_slope=1), r"^centre_slope must be a bool \(no unit\), got int$"),
])
def test_every_argument_refused_by_its_name_and_unit(change, message):
    args = dict(d_mm=np.zeros(300), f_N=np.zeros(300), sample_rate_Hz=FS_HZ) | change
    with pytest.raises(InputError, match=message):
        blf_maint(**args)


@pytest.mark.parametrize("name, default, words", [
    ("lowpass_rad_s", 40.0, "(default 40,"), ("bin_width_mm", 0.005, "(default 0.005)"),
    ("slope_window_bins", 2, "(default 2, i.e. 5 bins)"), ("min_bin_count", 3, "(default 3)"),
    ("contact_margin_frac", 0.2, "(default 0.2;"), ("centre_margin_frac", 0.15, "(default 0.15)"),
    ("hac_lag_s", 0.05, "(default 0.05 s"), ("min_contact_points", 50, "(default 50)"),
    ("min_centre_points", 10, "(default 10)"), ("centre_slope", False, "False (default)"),
])
def test_defaults_are_the_documented_ones(name, default, words):
    import inspect

    assert inspect.signature(blf_maint).parameters[name].default == default
    doc = blf_maint.__doc__
    assert words in doc[doc.index(name):], (name, words)


def test_constant_d_or_f_is_no_relation_and_says_which_std():
    d, f, _, _ = make_force_fight(np.random.default_rng(0))
    # (exactly constant after the low-pass: zeros; a constant 0.25 mm comes out of the filter with 1e-17 of
    # ripple and is refused by the correlation gate instead)
    for dd, ff, std_d, std_f in ((np.zeros(d.size), f, "0", None), (d, np.zeros(f.size), None, "0")):
        with pytest.raises(AnalysisError) as exc:
            blf_maint(dd, ff, FS_HZ)
        msg = str(exc.value)
        assert msg.startswith("no F-D relation: the low-passed D or F is constant (std D = "), msg
        assert (f"std D = {std_d} mm" in msg) if std_d else (f"std F = {std_f} N)" in msg), msg


def test_a_noise_free_gap_force_has_no_level_uncertainty():
    """Gap force exactly 0 N (no friction, no load-cell noise): the backlash level's variance is 0."""
    d, f, _, _ = make_force_fight(np.random.default_rng(0), sigma_f_N=0.0)
    r = blf_maint(d, f, FS_HZ)
    assert r.lines.centre.f_at_zero_d_N == 0.0 and r.lines.centre.cov[0, 0] == 0.0 and r.lines.centre.rmse_N == 0.0


def test_the_default_sample_counts_are_50_per_contact_and_10_in_the_backlash():
    d, f, _, _ = make_force_fight(np.random.default_rng(0), ramp_s=0.05, n_cycles=1)  # 0.05 s force ramps
    with pytest.raises(AnalysisError, match=r"^left contact region has too few samples: 46 < 50 "):
        blf_maint(d, f, FS_HZ)
    d, f, _, _ = make_force_fight(np.random.default_rng(0), n_cycles=1)
    with pytest.raises(AnalysisError, match=r"^centre \(backlash\) region has too few samples: 9 < 10 "):
        blf_maint(d, f, FS_HZ, centre_margin_frac=0.49)  # 2 % of the gap left for the level
