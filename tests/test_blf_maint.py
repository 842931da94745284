"""Tests of blf.maint.blfmaint.blf_maint (BLFmaint, paper 2.1) on synthetic force-fight data.

The generator (tests/support/blfmaint_data.py) builds the F-D relation of a
quasi-static force fight with known backlash and stiffness; the analysis must
recover them to the product's acceptance figures (backlash within 0.005 mm,
stiffness within 3 %, seed-to-seed std of the backlash < 0.003 mm), at the
corners of the envelope to max(5 um, 5 % of B) (tests/bench/bench_envelope.py
covers the whole envelope), and on the simulated rig with a small external
backlash (slow). A channel that cannot be measured raises an error that says
what is missing in the record.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import simulate_run

from blf.errors import AnalysisError, InputError
from blf.maint import BlfMaintResult, blf_maint
from support.blfmaint_data import FS_HZ, make_force_fight
from support.profiles import write_profile_variant

SIGMA_D_MM = 0.0042  # LVDT noise (0.025 mm pp)
SIGMA_F_N = 10.0

# make_force_fight (tests/support/blfmaint_data.py) builds the F-D relation of a quasi-static
# force fight: per cycle the gap traversed to the right at gap_speed (G = +friction), the right
# contact loaded G: 0 -> f_max -> 0, the gap traversed to the left, the left contact loaded;
# contact law D = +-B/2 + G/k -+ r exp(-|G|/G_r) (r = rounding_mm), F = slope_sign * G; Gaussian
# D noise (white or AR(1)) and F noise. Returns (d_mm, f_N, d_true, f_true).


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


# ------------------------------------------------------------ envelope corners

SQ2 = np.sqrt(2.0)  # external pair D_ext = s2 - s1 with F2 - F1: two LVDTs, two load cells

CORNERS = {
    # name: (generator kwargs, stiffness checked to 3 %?) -- truth B and k are in the kwargs
    # small backlash in a wide D range: B/D range = 0.01 (D +-1 mm at 5 kN/mm)
    "B0.02_Drange2mm_soft5k": (dict(backlash_mm=0.02, stiffness_left_N_per_mm=5e3, stiffness_right_N_per_mm=5e3,
                                    f_max_N=5000.0), True),
    # the external channel that failed: 0.02 mm at 18 kN/mm through F2 - F1 = +-12 kN (D +-0.66 mm)
    "ext_B0.02_18k_12kN": (dict(backlash_mm=0.02, stiffness_left_N_per_mm=18.2e3, stiffness_right_N_per_mm=18.2e3,
                                slope_sign=+1, f_max_N=12_000.0, sigma_d_mm=SIGMA_D_MM * SQ2,
                                sigma_f_N=SIGMA_F_N * SQ2), True),
    "ext_B0.03_18k_12kN_offset": (dict(backlash_mm=0.03, stiffness_left_N_per_mm=18.2e3,
                                       stiffness_right_N_per_mm=18.2e3, slope_sign=+1, f_max_N=12_000.0,
                                       d_offset_mm=0.01, sigma_d_mm=SIGMA_D_MM * SQ2, sigma_f_N=SIGMA_F_N * SQ2),
                                  True),
    "B0.02_stiff200k": (dict(backlash_mm=0.02, stiffness_left_N_per_mm=200e3, stiffness_right_N_per_mm=200e3), True),
    "B0.5_soft5k_asym": (dict(backlash_mm=0.5, stiffness_left_N_per_mm=4e3, stiffness_right_N_per_mm=6e3,
                              f_max_N=5000.0, gap_speed_mm_per_s=0.5), True),
    "B0.5_stiff200k": (dict(backlash_mm=0.5, stiffness_left_N_per_mm=200e3, stiffness_right_N_per_mm=200e3,
                            gap_speed_mm_per_s=0.5), True),
    "B0.02_noise3x": (dict(backlash_mm=0.02, stiffness_left_N_per_mm=80e3, stiffness_right_N_per_mm=80e3,
                           sigma_d_mm=3 * SIGMA_D_MM, sigma_f_N=3 * SIGMA_F_N), True),
    # small force amplitude, noisy load cells, friction in the gap at 17 % of the amplitude: F's own
    # noise would attenuate a D-on-raw-F slope by ~13 %, and 100 N of friction is no contact
    "ext_B0.1_soft5k_580N_noise3x_friction": (dict(backlash_mm=0.1, stiffness_left_N_per_mm=4.4e3,
                                                   stiffness_right_N_per_mm=5.6e3, slope_sign=+1, f_max_N=580.0,
                                                   gap_friction_N=100.0, sigma_d_mm=3 * SIGMA_D_MM * SQ2,
                                                   sigma_f_N=3 * SIGMA_F_N * SQ2), False),
    # backlash 90 % of the D range: contact deflection 12.5 um per side
    "B0.2_ratio0.9_stiff200k_5kN": (dict(backlash_mm=0.2, stiffness_left_N_per_mm=200e3,
                                         stiffness_right_N_per_mm=200e3, f_max_N=2500.0), False),
}


@pytest.mark.parametrize("name", list(CORNERS))
def test_envelope_corners_known_answer(name):
    """Within max(5 um, 5 % of B) at the corners of the envelope, every seed; stiffness within 3 %."""
    kw, check_k = CORNERS[name]
    b_true = kw["backlash_mm"]
    tol = max(0.005, 0.05 * b_true)
    for seed in range(5):
        r = blf_maint(*make_force_fight(np.random.default_rng(2000 + seed), **kw)[:2], FS_HZ)
        assert abs(r.backlash_mm - b_true) <= tol, (seed, r.backlash_mm - b_true)
        # the error is within the reported uncertainty (4 sigma + 0.5 um)
        assert abs(r.backlash_mm - b_true) < 4 * r.backlash_sigma_mm + 0.0005, (seed, r.backlash_sigma_mm)
        if check_k:
            assert abs(r.stiffness_left_N_per_mm / kw["stiffness_left_N_per_mm"] - 1) < 0.03
            assert abs(r.stiffness_right_N_per_mm / kw["stiffness_right_N_per_mm"] - 1) < 0.03
        # corners at +-B/2 (plus offset) within 2 um + 10 % of B
        off = kw.get("d_offset_mm", 0.0)
        assert r.d_lc_mm == pytest.approx(off - b_true / 2, abs=0.002 + 0.1 * b_true)
        assert r.d_rc_mm == pytest.approx(off + b_true / 2, abs=0.002 + 0.1 * b_true)


def test_small_backlash_is_a_few_percent_of_the_bins():
    """The case that failed (no flat cluster): the backlash is ~2 % of the D range; the regions come from F."""
    kw, _ = CORNERS["ext_B0.02_18k_12kN"]
    d, f, _, f_true = make_force_fight(np.random.default_rng(1), **kw)
    r = blf_maint(d, f, FS_HZ)
    assert 0.01 < 0.02 / (d.max() - d.min()) < 0.02
    assert abs(r.backlash_mm - 0.02) < 0.002
    # backlash samples are those of the gap traversals (F = 0), contact samples are loaded
    assert np.all(f_true[r.mask_centre] == 0.0)
    assert np.all(np.abs(f_true[r.mask_left | r.mask_right]) > 0.15 * 12_000.0)


def test_centre_is_a_level_unless_the_paper_line_is_asked_for():
    """Default: the backlash is a level (dF/dD = 0); centre_slope=True fits the paper's line, also within acceptance."""
    d, f, _, _ = make_force_fight(np.random.default_rng(8))
    level = blf_maint(d, f, FS_HZ)
    line = blf_maint(d, f, FS_HZ, centre_slope=True)
    assert level.lines.centre.slope_N_per_mm == 0.0
    assert level.lines.centre.cov[1, 1] == 0.0 and level.lines.centre.cov[0, 0] > 0.0
    assert line.lines.centre.slope_N_per_mm != 0.0
    for r in (level, line):
        assert abs(r.backlash_mm - 0.10) < 0.0015
        assert abs(r.stiffness_left_N_per_mm / 80e3 - 1) < 0.01
    assert abs(level.backlash_mm - line.backlash_mm) < 0.001


# -------------------------------------------- unmeasurable channels, in words

_INTERNALS = ("cluster", "quantile", "MAD", "G_", "g_hi", "binned slope")


def _no_internals(msg: str) -> None:
    for word in _INTERNALS:
        assert word not in msg, f"message quotes an internal step ({word!r}): {msg}"


def test_error_names_the_side_never_loaded():
    """Internal relation without tension: the message names the side, the D end and the force reached."""
    d, f, _, f_true = _good()
    keep = f_true >= 0.0
    with pytest.raises(AnalysisError) as exc:
        blf_maint(d[keep], f[keep], FS_HZ)
    msg = str(exc.value)
    assert "backlash not traversed: the force fight never reached contact on the tension side (F < 0)" in msg
    assert "upper end of the recorded D range" in msg
    assert "F stayed above" in msg and "load-cell noise" in msg
    _no_internals(msg)


def test_error_names_the_side_barely_loaded():
    """Tension only to 300 N against 6 kN in compression: the shares are quoted."""
    rng = np.random.default_rng(5)
    _, _, d_true, f_true = make_force_fight(rng)
    f2 = np.where(f_true < 0.0, f_true * 300.0 / 6000.0, f_true)
    d2 = np.where(f_true < 0.0, 0.05 - f2 / 80e3, d_true) + rng.normal(0, SIGMA_D_MM, d_true.size)
    with pytest.raises(AnalysisError) as exc:
        blf_maint(d2, f2 + rng.normal(0, SIGMA_F_N, f2.size), FS_HZ)
    msg = str(exc.value)
    assert "never reached contact on the tension side (F < 0)" in msg
    assert "5 % of the" in msg and "reached on the compression side (F > 0)" in msg
    _no_internals(msg)


def test_error_external_side_named_by_sign():
    """External relation (slope +1) without the F2 - F1 > 0 side."""
    d, f, _, f_true = make_force_fight(np.random.default_rng(6), slope_sign=+1, stiffness_left_N_per_mm=18e3,
                                       stiffness_right_N_per_mm=18e3)
    keep = f_true <= 0.0
    with pytest.raises(AnalysisError, match=r"never reached contact on the F > 0 side, at the upper end") as exc:
        blf_maint(d[keep], f[keep], FS_HZ)
    _no_internals(str(exc.value))


def test_error_no_backlash_says_d_does_not_move_freely():
    d, f, _, _ = make_force_fight(np.random.default_rng(2), backlash_mm=0.0)
    with pytest.raises(AnalysisError) as exc:
        blf_maint(d, f, FS_HZ)
    msg = str(exc.value)
    assert msg.startswith("no distinct backlash region: D does not move freely at the gap force; the two contact "
                          "lines reach F = ")
    assert "with no gap between them: any backlash is below the resolution, 3 x the" in msg
    assert "um spread of the low-passed D" in msg
    # a gap narrower than the resolution: its width is quoted
    d, f, _, _ = make_force_fight(np.random.default_rng(2), backlash_mm=0.0015)
    with pytest.raises(AnalysisError, match=r"only 1\.\d um apart .* any backlash is below that resolution"):
        blf_maint(d, f, FS_HZ)
    _no_internals(msg)


def test_error_contact_deflection_lost_in_noise():
    """200 kN/mm loaded to 300 N: 1.5 um of deflection under 12 um of D noise, with the slope's sign lost."""
    for seed in range(40):
        d, f, _, _ = make_force_fight(np.random.default_rng(seed), backlash_mm=0.1, stiffness_left_N_per_mm=200e3,
                                      stiffness_right_N_per_mm=200e3, f_max_N=300.0, sigma_d_mm=3 * SIGMA_D_MM)
        try:
            blf_maint(d, f, FS_HZ)
        except AnalysisError as exc:
            msg = str(exc)
            assert "contact region has no elastic slope" in msg
            assert "the contact deflection is lost in the noise" in msg and "um std" in msg
            _no_internals(msg)
            return
    pytest.fail("no seed gave a contact slope of the wrong sign")


# ------------------------------------------------ the simulated rig, small ext

#: a shorter check than the shipped one: two force-fight cycles, a +-10 mm calibration sweep
SHORT_CHECK = {"force_fight": {"cycles": 2}, "calibration": {"sweep_amplitude_mm": 10.0}}


@pytest.mark.slow
@pytest.mark.parametrize("bearing_mm", [0.01, 0.015])
def test_small_external_backlash_on_the_simulated_rig(tmp_path, actuation, bearing_mm):
    """bearing_backlash_mm 0.01 / 0.015 at both EMAs (ext 0.02 / 0.03 mm in a +-0.66 mm D range): pass, ext
    within 5 um (it said FAIL: no flat part of the binned slope)."""
    from hil.analysis.maint import analyze_signals, result_dict
    from hil.profile.load import load_check, load_simrig
    from hil.record.runfolder import read_signals

    chk = load_check(write_profile_variant("check.toml", tmp_path / "check.toml", SHORT_CHECK), actuation)
    sim = load_simrig(write_profile_variant("simrig.toml", tmp_path / "simrig.toml", {
        "ema1": {"bearing_backlash_mm": bearing_mm}, "ema2": {"bearing_backlash_mm": bearing_mm}}))
    outcome, truth = simulate_run(tmp_path / "run", actuation, chk, sim, 7)
    assert outcome.status == "done", outcome.reason
    res = result_dict(analyze_signals(read_signals(tmp_path / "run" / "signals.csv"), actuation), actuation, truth)
    assert truth["backlash_mm"]["ext"] == pytest.approx(2 * bearing_mm)
    assert res["status"] == "pass", res["notes"]
    for ch in ("int1", "int2", "ext"):
        assert res["backlash_mm"][ch] is not None, res["blf_maint"][ch]
        assert abs(res["backlash_mm"][ch] - truth["backlash_mm"][ch]) < 0.005, ch
        for side in ("left", "right"):
            c, tc = res["stiffness_N_per_mm"][ch][side], truth["stiffness_N_per_mm"][ch][side]
            assert abs(c / tc - 1) < 0.03, (ch, side)
