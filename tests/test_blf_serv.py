"""BLFserv (blf.serv.blfserv) and the error budget (blf.maint.accuracy) on synthetic signals with known answers.

Known answers: closed-form Tustin/ZOH coefficients and noise gains of first-order
sections, Monte-Carlo noise levels, noise-free steps (exact heights), an
independent re-implementation of the paper's Delta D, and the paper's 2.3
numbers (20 mm x 7.5 % = 1.5 mm, 2 mm x 1 % = 0.02 mm).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import signal

from blf.errors import AnalysisError, InputError
from blf.maint.accuracy import AccuracyBudget, backlash_error_budget
from blf.serv import BlfServMonitor, BlfServResult, blf_serv, design_serv_filters, estimate_noise_std_mm

FS = 500.0
T = 1.0 / FS
SIGMA = 0.025 / 6.0  # the paper's LVDT noise, 0.025 mm peak to peak


def smooth_step(t: np.ndarray, t0: float, height: float, rise_s: float) -> np.ndarray:
    """A jump of ``height`` mm centred at t0 rising over rise_s (cosine ramp)."""
    u = np.clip((t - t0) / rise_s + 0.5, 0.0, 1.0)
    return height * (0.5 - 0.5 * np.cos(np.pi * u))


def synthetic(rng, n=6000, jumps=((3.0, 0.1), (8.0, -0.1)), slope=0.05, rise_s=0.012, sigma=SIGMA):
    """Elastic ramp (mm/s) plus backlash jumps plus white noise, at 500 Hz."""
    t = np.arange(n) * T
    d = 0.02 + slope * t
    for t0, h in jumps:
        d = d + smooth_step(t, t0, h, rise_s)
    if sigma:
        d = d + sigma * rng.standard_normal(n)
    return t, d


# ---------------------------------------------------------------------- filters


@pytest.mark.parametrize("wc,wd", [(40.0, 100.0), (40.0, 60.0), (25.0, 150.0)])
def test_tustin_coefficients_match_closed_form(wc, wd):
    f = design_serv_filters(FS, lowpass_rad_s=wc, dt1_rad_s=wd)
    al = wc * T / (wc * T + 2.0)
    np.testing.assert_allclose(f.lowpass_b, [al, al], rtol=1e-12)
    np.testing.assert_allclose(f.lowpass_a, [1.0, (wc * T - 2.0) / (wc * T + 2.0)], rtol=1e-12)
    g = 2.0 * wd / (2.0 + wd * T)
    np.testing.assert_allclose(f.dt1_b, [g, -g], rtol=1e-12)
    np.testing.assert_allclose(f.dt1_a, [1.0, (wd * T - 2.0) / (wd * T + 2.0)], rtol=1e-12)
    # noise gain of the first-order low-pass: sum h^2 = b0^2 + (b1 - a1 b0)^2 / (1 - a1^2)
    b0, b1 = f.lowpass_b
    a1 = f.lowpass_a[1]
    assert f.noise_gain[0] == pytest.approx(math.sqrt(b0 ** 2 + (b1 - a1 * b0) ** 2 / (1 - a1 ** 2)), rel=1e-9)
    # delay of the derivative pulse: DC group delay 1/wc + 1/wd
    assert f.delay_samples == pytest.approx((1.0 / wc + 1.0 / wd) * FS, rel=1e-3)


def test_zoh_coefficients_match_closed_form():
    f = design_serv_filters(FS, discretisation="zoh")
    e = math.exp(-40.0 * T)
    np.testing.assert_allclose(f.lowpass_b, [0.0, 1.0 - e], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(f.lowpass_a, [1.0, -e], rtol=1e-12)
    np.testing.assert_allclose(f.dt1_b, [100.0, -100.0], rtol=1e-12)
    np.testing.assert_allclose(f.dt1_a, [1.0, -math.exp(-100.0 * T)], rtol=1e-12)


def test_noise_gains_match_monte_carlo():
    f = design_serv_filters(FS)
    e = np.random.default_rng(1).standard_normal(400_000)
    y0 = signal.lfilter(f.lowpass_b, f.lowpass_a, e)
    y1 = signal.lfilter(f.dt1_b, f.dt1_a, y0)
    y2 = signal.lfilter(f.dt1_b, f.dt1_a, y1)
    for g, y in zip(f.noise_gain, (y0, y1, y2), strict=True):
        assert np.std(y[2000:]) == pytest.approx(g, rel=0.01)
    # 0.025 mm pp LVDT noise: thresholds 5 sigma of the filtered derivatives
    r = blf_serv(e[:3000] * SIGMA, FS, noise_std_mm=SIGMA)
    assert r.threshold_d1_mm_per_s == pytest.approx(5 * SIGMA * f.noise_gain[1], rel=1e-12)
    assert r.threshold_d2_mm_per_s2 == pytest.approx(5 * SIGMA * f.noise_gain[2], rel=1e-12)
    assert r.threshold_d1_mm_per_s == pytest.approx(0.208, abs=0.001)
    assert r.threshold_d2_mm_per_s2 == pytest.approx(16.09, abs=0.01)


@pytest.mark.parametrize("kw,needle", [
    (dict(lowpass_rad_s=0.0), "lowpass_rad_s"),
    (dict(dt1_rad_s=2000.0), "dt1_rad_s"),
    (dict(discretisation="euler"), "discretisation"),
])
def test_filter_design_rejects_bad_options(kw, needle):
    with pytest.raises(InputError, match=needle):
        design_serv_filters(FS, **kw)


# ---------------------------------------------------------------------- noise level


def test_noise_estimate_is_robust_to_jumps_and_motion():
    rng = np.random.default_rng(2)
    t, d = synthetic(rng, n=20000, jumps=[(k, 0.1 * (-1) ** k) for k in range(2, 40, 3)])
    d = d + 2.0 * np.sin(2 * np.pi * 0.3 * t)  # mm-scale smooth motion
    assert estimate_noise_std_mm(d) == pytest.approx(SIGMA, rel=0.03)
    with pytest.raises(AnalysisError, match="noise-free"):
        estimate_noise_std_mm(np.linspace(0.0, 1.0, 100))
    with pytest.raises(InputError, match="d_mm"):
        estimate_noise_std_mm(np.zeros((5, 5)))


# ---------------------------------------------------------------------- known answers


def test_noise_free_steps_exact_height_and_time():
    """Same elastic slope both sides: the plateau lines give the step exactly, wherever t_jump lands."""
    t, d = synthetic(None, sigma=0.0)
    r = blf_serv(d, FS, noise_std_mm=SIGMA)
    assert r.traversals == 2 and r.method == "improved"
    h = [j.height_mm for j in r.jumps]
    np.testing.assert_allclose(h, [0.1, -0.1], atol=1e-12)
    assert r.backlash_mm == pytest.approx(0.1, abs=1e-12)
    # the jump instant within 4 samples of the true centre (the centroid ignores the pulse's
    # tail below the threshold, so it lands a little early)
    assert [j.t_jump_s for j in r.jumps] == pytest.approx([3.0, 8.0], abs=4 * T)


def test_paper_delta_d_matches_independent_implementation():
    """Paper 2.2: Delta D of the filtered D from both-outside to first return, largest amplitude."""
    t, d = synthetic(None, sigma=0.0)
    r = blf_serv(d, FS, noise_std_mm=SIGMA, method="paper")
    f = design_serv_filters(FS)
    df = signal.lfilter(f.lowpass_b, f.lowpass_a, d, zi=signal.lfilter_zi(f.lowpass_b, f.lowpass_a) * d[0])[0]
    d1 = signal.lfilter(f.dt1_b, f.dt1_a, df)
    d2 = signal.lfilter(f.dt1_b, f.dt1_a, d1)
    both = (np.abs(d1) > r.threshold_d1_mm_per_s) & (np.abs(d2) > r.threshold_d2_mm_per_s2)
    stretches = []  # (first sample with both outside, first sample after it with one inside)
    k = 0
    while k < both.size:
        if both[k]:
            e = k
            while e < both.size and both[e]:
                e += 1
            stretches.append((k, e))
            k = e
        k += 1
    assert len(stretches) >= 2
    deltas = np.array([df[e] - df[a] for a, e in stretches])
    starts = np.array([a for a, _ in stretches])
    # per jump the largest-magnitude stretch (two stretches per jump: d2 changes sign mid-jump)
    per_jump = [deltas[starts < 3000], deltas[starts >= 3000]]
    expect = [x[np.argmax(np.abs(x))] for x in per_jump]
    assert [j.paper_delta_mm for j in r.jumps] == pytest.approx(expect, abs=1e-10)
    assert r.backlash_mm == pytest.approx(max(abs(e) for e in expect), abs=1e-10)
    assert r.method == "paper" and r.traversals == 2
    # the paper's stretch ends at the inflection: it reads well below the jump
    assert 0.4 < r.backlash_mm / 0.1 < 0.8
    assert r.backlash_improved_mm == pytest.approx(0.1, abs=1e-12)


def test_noisy_steps_within_seven_percent_and_sigma_consistent():
    errs, sig = [], []
    for seed in range(6):
        t, d = synthetic(np.random.default_rng(10 + seed), slope=0.2)
        r = blf_serv(d, FS)
        assert r.traversals == 2
        errs += [abs(j.height_mm) - 0.1 for j in r.jumps]
        sig += [j.height_sigma_mm for j in r.jumps]
        assert r.noise_std_mm == pytest.approx(SIGMA, rel=0.08)
    errs = np.array(errs)
    assert np.max(np.abs(errs)) < 0.007
    assert abs(np.mean(errs)) < 0.002
    # the fit uncertainty describes the scatter (ratio within a factor 1.6 over 12 jumps)
    assert 0.6 < np.std(errs) / np.mean(sig) < 1.6


def test_not_traversed_on_elastic_motion_and_noise():
    rng = np.random.default_rng(3)
    t = np.arange(15000) * T
    d = 0.03 * np.sin(2 * np.pi * 0.5 * t) + 0.01 * np.sin(2 * np.pi * 2.0 * t) + SIGMA * rng.standard_normal(t.size)
    for method in ("improved", "paper"):
        r = blf_serv(d, FS, method=method)
        assert r.backlash_mm is None and r.traversals == 0
        assert r.backlash_improved_mm is None and r.backlash_paper_mm is None


def test_small_jump_below_min_jump_is_not_counted():
    t, d = synthetic(np.random.default_rng(4), jumps=((3.0, 0.015), (8.0, -0.015)))
    r = blf_serv(d, FS, noise_std_mm=SIGMA, threshold_factor=3.0)
    assert r.min_jump_mm == pytest.approx(6 * SIGMA)
    assert r.traversals == 0 and r.backlash_mm is None
    assert all(j.reason == "below min jump" for j in r.jumps if np.isfinite(j.height_mm))
    r2 = blf_serv(d, FS, noise_std_mm=SIGMA, threshold_factor=3.0, min_jump_mm=0.01)
    assert r2.traversals >= 1 and r2.backlash_mm == pytest.approx(0.015, abs=0.004)


def test_jump_at_the_edges_lacks_a_plateau():
    t, d = synthetic(np.random.default_rng(5), n=2200, jumps=((0.06, 0.1), (4.35, -0.1)))
    r = blf_serv(d, FS, noise_std_mm=SIGMA)
    reasons = [j.reason for j in r.jumps]
    assert reasons == ["plateau before too short", "plateau after too short"]
    assert r.traversals == 0 and r.traversals_paper == 2


def test_result_types_and_readonly_signals():
    t, d = synthetic(np.random.default_rng(6))
    r = blf_serv(d, FS)
    assert isinstance(r, BlfServResult) and r.n_samples == d.size
    assert r.d_filtered_mm.shape == d.shape and not r.d_filtered_mm.flags.writeable
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.backlash_mm = 1.0
    r2 = blf_serv(d, FS, keep_signals=False, t0_s=100.0)
    assert r2.d_filtered_mm is None and r2.backlash_mm == r.backlash_mm
    assert r2.jumps[0].t_jump_s == pytest.approx(r.jumps[0].t_jump_s + 100.0)


@pytest.mark.parametrize("args,kw,needle", [
    ((np.zeros((10, 2)), FS), {}, "d_mm"),
    ((np.array([0.0] * 20 + [np.nan]), FS), {}, "d_mm"),
    ((np.zeros(5), FS), {}, "d_mm"),
    ((np.zeros(100), -1.0), {"noise_std_mm": 0.004}, "sample_rate_Hz"),
    ((np.zeros(100), FS), {"noise_std_mm": 0.0}, "noise_std_mm"),
    ((np.zeros(100), FS), {"noise_std_mm": 0.004, "method": "best"}, "method"),
    ((np.zeros(100), FS), {"noise_std_mm": 0.004, "plateau_s": -1.0}, "plateau_s"),
])
def test_bad_input_is_refused_with_the_argument_named(args, kw, needle):
    with pytest.raises(InputError, match=needle):
        blf_serv(*args, **kw)


# ---------------------------------------------------------------------- streaming = batch


def _compare(a: BlfServResult, b: BlfServResult) -> None:
    assert len(a.jumps) == len(b.jumps)
    for ja, jb in zip(a.jumps, b.jumps, strict=True):
        for f in ("t_start_s", "t_end_s", "t_jump_s", "height_mm", "height_sigma_mm", "paper_delta_mm",
                  "residual_before_mm", "residual_after_mm"):
            x, y = getattr(ja, f), getattr(jb, f)
            assert (np.isnan(x) and np.isnan(y)) or abs(x - y) <= 1e-12, f
        assert (ja.accepted, ja.paper_accepted, ja.reason) == (jb.accepted, jb.paper_accepted, jb.reason)
    for f in ("backlash_mm", "backlash_paper_mm", "backlash_improved_mm", "backlash_sigma_mm"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None and y is None) or abs(x - y) <= 1e-12, f
    assert (a.traversals, a.traversals_paper) == (b.traversals, b.traversals_paper)


def test_streaming_equals_batch_sample_by_sample_and_in_chunks():
    rng = np.random.default_rng(7)
    chans = [synthetic(rng, jumps=((1.5, 0.1), (4.0, -0.1), (9.0, 0.1)))[1],
             synthetic(rng, jumps=((2.0, -0.12), (7.0, 0.12)), slope=-0.1)[1],
             synthetic(rng, jumps=(), slope=0.0)[1]]
    noise = [estimate_noise_std_mm(c) for c in chans]
    batch = [blf_serv(c, FS, noise_std_mm=s) for c, s in zip(chans, noise, strict=True)]
    assert [b.traversals for b in batch] == [3, 2, 0]
    X = np.column_stack(chans)
    # sample by sample, three channels at once; an intermediate result() does not disturb
    mon = BlfServMonitor(FS, noise)
    for k in range(X.shape[0]):
        mon.update(X[k])
        if k == 2600:
            mid = mon.result(0)
            assert mid.n_samples == 2601 and mid.traversals == 2
    assert mon.n_samples == X.shape[0]
    for c in range(3):
        _compare(batch[c], mon.result(c))
    # random chunks
    mon2 = BlfServMonitor(FS, noise)
    cuts = np.sort(rng.choice(np.arange(1, X.shape[0]), size=40, replace=False))
    for blk in np.split(X, cuts):
        mon2.update(blk)
    for c in range(3):
        _compare(batch[c], mon2.result(c))
    # one channel fed as 1-D chunks
    mon3 = BlfServMonitor(FS, noise[1], method="paper")
    for blk in np.array_split(chans[1], 7):
        mon3.update(blk)
    _compare(blf_serv(chans[1], FS, noise_std_mm=noise[1], method="paper"), mon3.result())
    assert mon3.result().d_filtered_mm is None


def test_monitor_rejects_bad_shapes_and_values():
    mon = BlfServMonitor(FS, [SIGMA, SIGMA, SIGMA])
    with pytest.raises(InputError, match=r"shape \(3,\) or \(m, 3\)"):
        mon.update(np.zeros(2))
    with pytest.raises(InputError, match="finite"):
        mon.update(np.array([0.0, np.inf, 0.0]))
    with pytest.raises(InputError, match="channel"):
        mon.result(3)
    with pytest.raises(InputError, match="noise_std_mm"):
        BlfServMonitor(FS, [SIGMA, -1.0])
    with pytest.raises(InputError, match="unknown option"):
        BlfServMonitor(FS, SIGMA, threshold=3.0)
    assert mon.update(np.zeros((0, 3))) == 0
    assert mon.result(0).backlash_mm is None and mon.result(0).n_samples == 0


# ---------------------------------------------------------------------- accuracy budget (paper 2.3)


def test_error_budget_reproduces_the_papers_numbers():
    b = backlash_error_budget(20.0, 0.075, SIGMA, FS, backlash_mm=0.1)
    assert isinstance(b, AccuracyBudget)
    # pitch: +-20 mm x 7.5 % = 1.5 mm for BLFserv; BLFmaint reads only across the play
    assert b.serv_paper.pitch_uncompensated_mm == pytest.approx(1.5)
    assert b.serv_improved.pitch_uncompensated_mm == pytest.approx(1.5)
    assert b.maint.pitch_uncompensated_mm == pytest.approx(0.1 * 0.075)
    assert b.serv_paper.pitch_compensated_mm == pytest.approx(20.0 * 1e-3)
    # temperature: 2 mm x 1 % = 0.02 mm (a tenth of the stroke); BLFmaint 1 % of the play
    assert b.serv_paper.temperature_mm == pytest.approx(0.02)
    assert b.maint.temperature_mm == pytest.approx(0.001)
    # noise: the low-pass noise gain, Tustin 40 rad/s at 500 Hz
    f = design_serv_filters(FS)
    assert b.filtered_noise_std_mm == pytest.approx(f.noise_gain[0] * SIGMA)
    assert b.serv_paper.noise_mm == pytest.approx(math.sqrt(2) * f.noise_gain[0] * SIGMA)
    assert b.serv_paper.noise_mm == pytest.approx(0.00116, abs=2e-5)
    # improved: two 75-sample lines extrapolated 50 and 35 samples: sigma sqrt(v_b + v_a)
    v = sum(1 / 75 + (dd + 37) ** 2 / (75 * (75 ** 2 - 1) / 12) for dd in (50, 35))
    assert b.serv_improved.noise_mm == pytest.approx(SIGMA * math.sqrt(v), rel=1e-9)
    assert b.serv_paper.total_uncompensated_mm == pytest.approx(
        math.sqrt(1.5 ** 2 + b.serv_paper.noise_mm ** 2 + 0.02 ** 2))
    assert b.target_mm == pytest.approx(0.01)


def test_error_budget_rejects_bad_numbers():
    with pytest.raises(InputError, match="pitch_error"):
        backlash_error_budget(20.0, -0.1, SIGMA, FS, backlash_mm=0.1)
    with pytest.raises(InputError, match="backlash_mm"):
        backlash_error_budget(20.0, 0.075, SIGMA, FS, backlash_mm=0.0)
    with pytest.raises(InputError, match="stroke_mm"):
        backlash_error_budget(float("nan"), 0.075, SIGMA, FS, backlash_mm=0.1)
