"""Tests of blf.maint.blf_maint (BLFmaint, paper 2.1) on synthetic force-fight data.

The generator below builds the F-D relation of a quasi-static force fight
with known backlash and stiffness; the analysis must recover them to the
product's acceptance figures (backlash within 0.005 mm, stiffness within 3 %,
seed-to-seed std of the backlash < 0.003 mm).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from blf import BlfMaintResult, blf_maint
from blf.errors import AnalysisError, InputError

FS_HZ = 500.0
SIGMA_D_MM = 0.0042  # LVDT noise (0.025 mm pp)
SIGMA_F_N = 10.0


def make_force_fight(
    rng: np.random.Generator,
    *,
    stiffness_left_N_per_mm: float = 80_000.0,
    stiffness_right_N_per_mm: float = 80_000.0,
    backlash_mm: float = 0.10,
    slope_sign: int = -1,
    f_max_N: float = 6_000.0,
    n_cycles: int = 3,
    ramp_s: float = 1.9,
    gap_speed_mm_per_s: float = 0.25,
    rounding_mm: float = 0.0,
    rounding_force_N: float = 400.0,
    gap_friction_N: float = 0.0,
    d_offset_mm: float = 0.0,
    sigma_d_mm: float = SIGMA_D_MM,
    sigma_f_N: float = SIGMA_F_N,
    d_noise_ar1: float = 0.0,
):
    """Quasi-static force fight through +-f_max_N, sampled at 500 Hz.

    Works in the sign-normalised force G (increasing with D); F = slope_sign*G.
    Per cycle (4*ramp_s + 2*gap time, ~8.4 s): traverse the gap to the right
    at gap_speed (G = +friction), right contact G: 0 -> f_max -> 0, traverse
    the gap to the left (G = -friction), left contact G: 0 -> -f_max -> 0.

    Contact law (truth = asymptotes, B is the distance between them at G = 0)::

        right:  D =  B/2 + G/k_right - r * exp(-|G|/G_r)
        left:   D = -B/2 + G/k_left  + r * exp(-|G|/G_r)

    r = rounding_mm softens the first ~r of each contact (visco-elastic-like
    rounding; the initial slope is k / (1 + k r / G_r)). For slope_sign = -1
    (internal) this is D = -(F/k_c + B/2) for F > 0 and D = -(F/k_t - B/2)
    for F < 0 with k_c = k_left, k_t = k_right.

    D noise is Gaussian with std sigma_d_mm, white or, with d_noise_ar1 = a,
    AR(1) coloured (e[k] = a e[k-1] + w[k], same stationary std).

    Returns (d_mm, f_N) with noise, and the noise-free (d_true, f_true).
    """
    n_ramp = int(round(ramp_s * FS_HZ))
    up = np.arange(n_ramp) / n_ramp
    tri = np.concatenate((up, 1.0 - up)) * f_max_N
    edge = backlash_mm / 2.0 - rounding_mm
    n_gap = max(1, int(round(2.0 * edge / gap_speed_mm_per_s * FS_HZ)))
    gap = np.linspace(-edge, edge, n_gap, endpoint=False)

    def right(gv):
        soft = rounding_mm * np.exp(-np.abs(gv) / rounding_force_N)
        return backlash_mm / 2 + gv / stiffness_right_N_per_mm - soft

    def left(gv):
        soft = rounding_mm * np.exp(-np.abs(gv) / rounding_force_N)
        return -backlash_mm / 2 + gv / stiffness_left_N_per_mm + soft

    ds, gs = [], []
    for _ in range(n_cycles):
        ds += [gap, right(tri), -gap, left(-tri)]
        gs += [np.full(n_gap, gap_friction_N), tri, np.full(n_gap, -gap_friction_N), -tri]
    d_true = np.concatenate(ds) + d_offset_mm
    f_true = slope_sign * np.concatenate(gs)
    w = rng.normal(0.0, sigma_d_mm * np.sqrt(1.0 - d_noise_ar1**2), d_true.size)
    d = d_true + lfilter([1.0], [1.0, -d_noise_ar1], w)
    f = f_true + rng.normal(0.0, sigma_f_N, f_true.size)
    return d, f, d_true, f_true


CASES = {
    # name: (generator kwargs, truth B, truth k_left, truth k_right)
    "internal_80k_B0.10": (dict(), 0.10, 80e3, 80e3),
    "external_14k_B0.10": (
        dict(stiffness_left_N_per_mm=14e3, stiffness_right_N_per_mm=14e3, slope_sign=+1),
        0.10, 14e3, 14e3,
    ),
    "asymmetric_kc90_kt70": (
        dict(stiffness_left_N_per_mm=90e3, stiffness_right_N_per_mm=70e3),
        0.10, 90e3, 70e3,
    ),
    "rounded_0.01mm": (dict(rounding_mm=0.01), 0.10, 80e3, 80e3),
    "rounded_external": (
        dict(stiffness_left_N_per_mm=14e3, stiffness_right_N_per_mm=14e3, slope_sign=+1, rounding_mm=0.01),
        0.10, 14e3, 14e3,
    ),
    "B0.05": (dict(backlash_mm=0.05), 0.05, 80e3, 80e3),
    "B0.05_rounded": (dict(backlash_mm=0.05, rounding_mm=0.01), 0.05, 80e3, 80e3),
    "B0.20": (dict(backlash_mm=0.20), 0.20, 80e3, 80e3),
    # robustness: Coulomb friction in the gap, fast gap traversal, D offset
    "gap_friction_100N": (dict(gap_friction_N=100.0), 0.10, 80e3, 80e3),
    "fast_gap_5mm_per_s": (dict(gap_speed_mm_per_s=5.0), 0.10, 80e3, 80e3),
    "offset_0.3mm": (dict(d_offset_mm=0.3), 0.10, 80e3, 80e3),
}

N_SEEDS_ACC = 10


@pytest.fixture(scope="module")
def case_results():
    """Analyse every case for N_SEEDS_ACC seeds once (about 1 s in total)."""
    out = {}
    for name, (kw, *_truth) in CASES.items():
        out[name] = [
            blf_maint(*make_force_fight(np.random.default_rng(1000 + seed), **kw)[:2], FS_HZ)
            for seed in range(N_SEEDS_ACC)
        ]
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_backlash_and_stiffness_within_acceptance(case_results, name):
    _kw, b_true, kl_true, kr_true = CASES[name]
    res = case_results[name]
    b = np.array([r.backlash_mm for r in res])
    kl = np.array([r.stiffness_left_N_per_mm for r in res])
    kr = np.array([r.stiffness_right_N_per_mm for r in res])
    # acceptance figures, every seed
    assert np.all(np.abs(b - b_true) < 0.005), b - b_true
    assert np.all(np.abs(kl / kl_true - 1.0) < 0.03), kl / kl_true - 1
    assert np.all(np.abs(kr / kr_true - 1.0) < 0.03), kr / kr_true - 1
    assert np.std(b, ddof=1) < 0.003
    # what the method actually achieves here (measured: |bias| <= 0.9 um,
    # std 0.15-0.35 um, stiffness bias <= 0.3 %): a regression guard
    assert abs(b.mean() - b_true) < 0.0015
    assert np.std(b, ddof=1) < 0.0006
    assert abs(kl.mean() / kl_true - 1.0) < 0.01
    assert abs(kr.mean() / kr_true - 1.0) < 0.01


@pytest.mark.parametrize(
    "name, sign", [("internal_80k_B0.10", -1), ("external_14k_B0.10", +1), ("asymmetric_kc90_kt70", -1)]
)
def test_slope_sign_corners_and_lines(case_results, name, sign):
    r: BlfMaintResult = case_results[name][0]
    _kw, b_true, kl_true, kr_true = CASES[name]
    assert r.slope_sign == sign
    # corners at the ends of the flat part, within 2 bins of +-B/2
    assert r.d_lc_mm == pytest.approx(-b_true / 2, abs=0.01)
    assert r.d_rc_mm == pytest.approx(+b_true / 2, abs=0.01)
    # backlash is the distance of the two intersections; both at F ~ 0
    assert r.backlash_mm == pytest.approx(r.lines.d_right_mm - r.lines.d_left_mm, abs=1e-12)
    assert abs(r.lines.f_left_N) < 30.0 and abs(r.lines.f_right_N) < 30.0
    # line slopes carry the sign; stiffness is the magnitude
    assert np.sign(r.lines.left.compliance_mm_per_N) == sign
    assert 1.0 / abs(r.lines.left.compliance_mm_per_N) == pytest.approx(r.stiffness_left_N_per_mm)
    assert abs(r.lines.centre.slope_N_per_mm) < 0.05 * min(kl_true, kr_true)
    # internal (sign -1): left contact is compression (F > 0)
    if sign < 0:
        assert r.lines.left.f_min_N > 500.0 and r.lines.right.f_max_N < -500.0
    else:
        assert r.lines.left.f_max_N < -500.0 and r.lines.right.f_min_N > 500.0
    # binned derivative: ~0 in the gap, ~contact stiffness outside, threshold between
    c = r.curve
    mid = np.abs(c.d_mm) < 0.3 * b_true
    out_l = c.d_mm < -b_true / 2 - 0.02
    out_r = c.d_mm > b_true / 2 + 0.02
    assert np.all(np.abs(c.dfdd_N_per_mm[mid]) < 0.1 * kl_true)
    assert np.median(c.dfdd_N_per_mm[out_l]) == pytest.approx(sign * kl_true, rel=0.1)
    assert np.median(c.dfdd_N_per_mm[out_r]) == pytest.approx(sign * kr_true, rel=0.1)
    assert 0.3 < c.threshold_N_per_mm / (sign * min(kl_true, kr_true)) < 0.7
    # regions are disjoint and counted
    assert not np.any(r.mask_left & r.mask_right)
    assert not np.any(r.mask_centre & (r.mask_left | r.mask_right))
    assert (r.n_left, r.n_centre, r.n_right) == (
        int(r.mask_left.sum()), int(r.mask_centre.sum()), int(r.mask_right.sum()))
    assert r.n_left > 3000 and r.n_right > 3000 and r.n_centre > 300


def test_regressing_f_on_d_would_attenuate_stiffness():
    """Justifies 'D on F': F-on-D OLS on the same contact samples is ~4 % low."""
    d, f, _, _ = make_force_fight(np.random.default_rng(7))
    r = blf_maint(d, f, FS_HZ)
    m = r.mask_left
    slope_f_on_d = np.polyfit(d[m], f[m], 1)[0]
    attenuation = abs(slope_f_on_d) / 80e3 - 1.0
    assert -0.07 < attenuation < -0.02  # errors-in-variables bias
    assert abs(r.stiffness_left_N_per_mm / 80e3 - 1.0) < 0.01  # D-on-F is unbiased


@pytest.mark.parametrize(
    "kw",
    [
        dict(),
        dict(stiffness_left_N_per_mm=14e3, stiffness_right_N_per_mm=14e3, slope_sign=+1),
        dict(d_noise_ar1=0.8),
    ],
    ids=["internal", "external", "internal_coloured_noise"],
)
def test_sigmas_match_seed_spread(kw):
    """Reported sigmas agree with the spread over 20 noise seeds (factor 2).

    The coloured case (AR(1), a = 0.8: the variance of a mean is 9x that of
    white noise) shows why the Newey-West covariance is used: plain OLS
    sigmas would be ~3x too small there.
    """
    res = [blf_maint(*make_force_fight(np.random.default_rng(s), **kw)[:2], FS_HZ) for s in range(20)]
    for value, sigma in (
        ("backlash_mm", "backlash_sigma_mm"),
        ("stiffness_left_N_per_mm", "stiffness_left_sigma_N_per_mm"),
        ("stiffness_right_N_per_mm", "stiffness_right_sigma_N_per_mm"),
    ):
        spread = np.std([getattr(r, value) for r in res], ddof=1)
        reported = np.mean([getattr(r, sigma) for r in res])
        assert 0.5 < reported / spread < 2.0, (value, reported, spread)
    if kw.get("d_noise_ar1", 0.0) == 0.0:
        # the figure itself (white noise, ~4500 contact samples per side)
        assert 0.00015 < np.mean([r.backlash_sigma_mm for r in res]) < 0.0005


def test_result_is_frozen_and_arrays_read_only():
    r = blf_maint(*make_force_fight(np.random.default_rng(3))[:2], FS_HZ)
    with pytest.raises(AttributeError):
        r.backlash_mm = 0.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        r.mask_left[0] = True
    with pytest.raises(ValueError):
        r.curve.d_mm[0] = 0.0


# ------------------------------------------------------------------ errors


def _good():
    d, f, d_true, f_true = make_force_fight(np.random.default_rng(11))
    return d, f, d_true, f_true


def test_input_errors_name_argument_shape_and_unit():
    d, f, _, _ = _good()
    with pytest.raises(InputError, match=r"f_N.*shape \(12599,\)"):
        blf_maint(d, f[:-1], FS_HZ)
    with pytest.raises(InputError, match=r"d_mm.*1-D.*mm.*\(2, 6300\)"):
        blf_maint(d.reshape(2, -1), f, FS_HZ)
    bad = d.copy()
    bad[100] = np.nan
    with pytest.raises(InputError, match=r"d_mm.*finite.*1 NaN"):
        blf_maint(bad, f, FS_HZ)
    badf = f.copy()
    badf[5] = np.inf
    with pytest.raises(InputError, match="f_N"):
        blf_maint(d, badf, FS_HZ)
    with pytest.raises(InputError, match=r"at least 200 samples.*\(150,\)"):
        blf_maint(d[:150], f[:150], FS_HZ)
    with pytest.raises(InputError, match="sample_rate_Hz.*Hz"):
        blf_maint(d, f, 0.0)
    with pytest.raises(InputError, match="lowpass_rad_s.*Nyquist"):
        blf_maint(d, f, FS_HZ, lowpass_rad_s=2000.0)
    with pytest.raises(InputError, match="bin_width_mm"):
        blf_maint(d, f, FS_HZ, bin_width_mm=-0.005)
    with pytest.raises(InputError, match="contact_margin_frac"):
        blf_maint(d, f, FS_HZ, contact_margin_frac=0.7)
    # D given in metres or micrometres instead of mm: refused, not mis-binned
    with pytest.raises(AnalysisError, match="units of d_mm"):
        blf_maint(d * 1e-3, f, FS_HZ)
    with pytest.raises(InputError, match="units of d_mm"):
        blf_maint(d * 1e3, f, FS_HZ, bin_width_mm=1e-6)
    assert issubclass(InputError, ValueError)


def test_backlash_not_traversed_one_sided_force():
    """Force fight that never reverses: contact on one side only."""
    d, f, _, f_true = _good()
    keep = f_true >= 0.0  # internal: compression contact and the gap, no tension
    with pytest.raises(AnalysisError, match="backlash not traversed"):
        blf_maint(d[keep], f[keep], FS_HZ)


def test_backlash_not_traversed_tension_barely_reached():
    """Tension side reaches only 300 N (contact deflection 4 um < noise)."""
    rng = np.random.default_rng(5)
    _, _, d_true, f_true = make_force_fight(rng)
    f2 = np.where(f_true < 0.0, f_true * 300.0 / 6000.0, f_true)
    d2 = np.where(f_true < 0.0, 0.05 - f2 / 80e3, d_true)
    d2 = d2 + rng.normal(0, SIGMA_D_MM, d2.size)
    f2 = f2 + rng.normal(0, SIGMA_F_N, f2.size)
    with pytest.raises(AnalysisError, match="backlash not traversed.*upper end"):
        blf_maint(d2, f2, FS_HZ)


def test_no_backlash_region():
    d, f, _, _ = make_force_fight(np.random.default_rng(2), backlash_mm=0.0)
    with pytest.raises(AnalysisError, match="no distinct backlash region"):
        blf_maint(d, f, FS_HZ)


def test_no_fd_relation():
    rng = np.random.default_rng(4)
    with pytest.raises(AnalysisError, match="no F-D relation"):
        blf_maint(rng.normal(0, 0.004, 5000), rng.normal(0, 10, 5000), FS_HZ)
    with pytest.raises(AnalysisError, match="no F-D relation"):
        blf_maint(np.zeros(500), rng.normal(0, 10, 500), FS_HZ)


def test_too_few_points_in_a_region():
    d, f, _, _ = _good()
    with pytest.raises(AnalysisError, match="left contact region has too few samples"):
        blf_maint(d, f, FS_HZ, min_contact_points=100_000)
    with pytest.raises(AnalysisError, match="centre .* too few samples"):
        blf_maint(d, f, FS_HZ, min_centre_points=100_000)
    assert issubclass(AnalysisError, ValueError)
