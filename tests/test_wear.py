"""Known-answer tests of the wear statistics (blf/wear.py): the weighted fit against numpy and scipy,
the bands, the crossing of the limit (Fieller) against a brute-force inversion of the band and by
Monte Carlo coverage, the step detection, and the simulated rig's wear option (sim/truth.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, stats

from blf.errors import InputError
from blf.wear import fit_wear, limit_crossing, trend_band, wear_segments


def _series(rng, n=12, rate=2.5e-5, b0=0.1, sigma=0.003, scatter=0.0, x_max=3000.0):
    x = np.linspace(0.0, x_max, n)
    y = b0 + rate * x + rng.normal(0.0, sigma, n) + rng.normal(0.0, scatter, n)
    return x, y, np.full(n, 2.0 * sigma)


def test_exact_line_is_found_exactly_with_the_stated_covariance():
    x = np.array([0.0, 400.0, 1100.0, 2000.0, 2600.0])
    u = np.array([0.006, 0.004, 0.008, 0.005, 0.006])
    f = fit_wear(x, 0.1 + 3e-5 * x, u)
    assert f.rate == pytest.approx(3e-5, rel=1e-12) and float(f.predict(0.0)) == pytest.approx(0.1, abs=1e-14)
    assert f.scale == 1.0 and f.chi2 == pytest.approx(0.0, abs=1e-20)
    assert f.quantile == pytest.approx(1.959964, abs=1e-6)
    w = 1.0 / (u / 2.0) ** 2  # k = 2
    sxx = np.sum(w * (x - np.sum(w * x) / np.sum(w)) ** 2)
    assert f.rate_sigma == pytest.approx(1.0 / math.sqrt(sxx), rel=1e-12)
    assert f.level_sigma == pytest.approx(1.0 / math.sqrt(np.sum(w)), rel=1e-12)


def test_fit_agrees_with_numpy_and_curve_fit_absolute_and_scaled():
    rng = np.random.default_rng(4)
    x, y, u = _series(rng)  # readings scatter as stated: stated covariance (absolute_sigma=True)
    f = fit_wear(x, y, u)
    (b, a), cov = np.polyfit(x, y, 1, w=2.0 / u, cov="unscaled")
    assert f.rate == pytest.approx(b, rel=1e-10) and f.predict(0.0) == pytest.approx(a, rel=1e-10)
    if f.chi2_per_dof <= 1.0:
        assert f.rate_sigma == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-8)
    x2, y2, u2 = _series(rng, scatter=0.008)  # scatter far above the stated U: the Birge ratio scales
    g = fit_wear(x2, y2, u2)
    p, cov2 = optimize.curve_fit(lambda t, a0, b0: a0 + b0 * t, x2, y2, sigma=u2 / 2.0, absolute_sigma=False)
    assert g.scale > 1.0 and g.rate == pytest.approx(p[1], rel=1e-8)
    assert g.rate_sigma == pytest.approx(math.sqrt(cov2[1, 1]), rel=1e-6)
    assert g.quantile == pytest.approx(stats.t.ppf(0.975, x2.size - 2), rel=1e-10)


def test_bands_confidence_inside_prediction_and_widest_away_from_the_centre():
    rng = np.random.default_rng(5)
    f = fit_wear(*_series(rng))
    xs = np.array([f.x0, 3000.0, 5000.0])
    lo, mid, hi = trend_band(f, xs)
    plo, pmid, phi = trend_band(f, xs, prediction=True)
    assert np.allclose(mid, pmid) and np.all(plo < lo) and np.all(phi > hi)
    half = (hi - lo) / 2
    assert half[0] == pytest.approx(f.quantile * f.level_sigma) and half[0] < half[1] < half[2]
    # prediction band of a reading with U = 6 um and the stated scatter: sqrt(line^2 + 3 um^2) * q
    _, _, h = trend_band(f, [f.x0], prediction=True, reading_sigma_mm=0.003)
    assert (h - f.predict(f.x0))[0] == pytest.approx(f.quantile * math.hypot(f.level_sigma, f.scale * 0.003))


def test_crossing_is_the_inversion_of_the_confidence_band():
    rng = np.random.default_rng(6)
    f = fit_wear(*_series(rng))
    c = limit_crossing(f, 0.2)
    assert c.bounded and c.lo < c.x < c.hi
    assert c.x == pytest.approx(f.x0 + (0.2 - f.level) / f.rate)
    grid = np.linspace(2000.0, 7000.0, 200_001)
    lo, _, hi = trend_band(f, grid)
    inside = grid[(lo <= 0.2) & (hi >= 0.2)]
    assert inside.min() == pytest.approx(c.lo, abs=0.05) and inside.max() == pytest.approx(c.hi, abs=0.05)
    assert c.sigma_delta == pytest.approx(float(f.line_sigma(c.x)) / f.rate)
    assert (c.hi - c.x) > (c.x - c.lo)  # the reciprocal of a rate: longer towards the future


def test_crossing_of_a_rate_not_clearly_positive_is_unbounded_above():
    x = np.linspace(0.0, 1000.0, 6)
    y = 0.10 + np.array([0.0, 0.004, -0.003, 0.002, -0.001, 0.003])
    c = limit_crossing(fit_wear(x, y, np.full(6, 0.008)), 0.2)
    assert not c.bounded and c.hi == math.inf and c.lo > 1000.0  # "not before lo", maybe never
    flat = limit_crossing(fit_wear(x, np.full(6, 0.1) - 1e-6 * x, np.full(6, 0.008)), 0.2)
    assert math.isnan(flat.x) and flat.hi == math.inf


def test_monte_carlo_coverage_of_the_rate_and_the_crossing():
    """The 95 % intervals cover the truth in about 95 % of 2000 series (stated U right, and scatter
    above the stated U: Birge-scaled with Student's t)."""
    rng = np.random.default_rng(7)
    for scatter in (0.0, 0.004):
        hit_rate = hit_cross = 0
        n_sim = 1000
        for _ in range(n_sim):
            x, y, u = _series(rng, scatter=scatter)
            f = fit_wear(x, y, u)
            hit_rate += abs(f.rate - 2.5e-5) <= f.quantile * f.rate_sigma
            c = limit_crossing(f, 0.2)
            hit_cross += c.lo <= 4000.0 <= c.hi
        assert 0.93 <= hit_rate / n_sim <= 0.985, (scatter, hit_rate)
        assert 0.93 <= hit_cross / n_sim <= 0.985, (scatter, hit_cross)


def test_steps_down_split_the_series_a_lone_outlier_does_not():
    x = np.arange(10) * 300.0
    y = 0.10 + 2.5e-5 * x
    u = np.full(10, 0.006)
    assert [s.tolist() for s in wear_segments(x, y, u)] == [list(range(10))]
    rep = y.copy()
    rep[6:] -= 0.05  # a repair between the 6th and 7th check
    assert [s.tolist() for s in wear_segments(x, rep, u)] == [list(range(6)), list(range(6, 10))]
    out = y.copy()
    out[4] -= 0.05  # one low reading between two higher ones: an outlier, kept in place
    assert len(wear_segments(x, out, u)) == 1
    last = y.copy()
    last[-1] -= 0.05  # the latest check after a repair: a new segment of one
    assert [s.tolist() for s in wear_segments(x, last, u)][-1] == [9]
    assert len(wear_segments(x, y - 0.8 * 3 * math.sqrt(2) * 0.003 * (np.arange(10) % 2), u)) == 1  # within 3 sigma


@pytest.mark.parametrize("args, words", [
    (([0, 1, 2], [0.1, 0.2], [0.006] * 3), "same shape"),
    (([0, 1, 2], [0.1, 0.1, np.nan], [0.006] * 3), "finite"),
    (([0, 1], [0.1, 0.11], [0.006, 0.0]), "> 0 mm"),
    (([5, 5, 5], [0.1, 0.11, 0.12], [0.006] * 3), "two distinct"),
    (([1], [0.1], [0.006]), "at least 2"),
])
def test_bad_inputs_name_the_argument(args, words):
    with pytest.raises(InputError, match=words):
        fit_wear(*args)


def test_simulated_rig_wear_option_grows_the_truth_on_its_line():
    from hil.profile.load import load_simrig
    from sim.params import WearParams
    from sim.truth import apply_wear, rig_truth, wear_line_mm

    params = load_simrig().params
    wear = WearParams(0.025, 0.020, 0.010, scatter_mm=0.0, reference_flight_hours=500.0)
    line = wear_line_mm(params, wear, 2500.0)
    assert line == pytest.approx({"int1": 0.15, "int2": 0.16, "ext": 0.12})
    worn = apply_wear(params, wear, 2500.0, np.random.default_rng(0))
    assert rig_truth(worn).backlash_mm == pytest.approx(line)
    assert worn.ema1.bearing_backlash_mm == pytest.approx(0.06) and worn.drive == params.drive
    draws = np.array([rig_truth(apply_wear(params, WearParams(0.025, 0.02, 0.01, scatter_mm=0.002), 2000.0,
                                           np.random.default_rng(s))).backlash_mm["int1"] for s in range(400)])
    assert draws.mean() == pytest.approx(0.15, abs=0.0004) and draws.std() == pytest.approx(0.002, rel=0.15)
    with pytest.raises(InputError, match="negative"):
        apply_wear(params, WearParams(-0.1, 0.0, 0.0), 2000.0, np.random.default_rng(0))
