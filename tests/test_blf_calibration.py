"""Tests of blf.maint.calibration (LVDT calibration against the motor angle, paper 2.3)."""

from __future__ import annotations

import numpy as np
import pytest

from blf.errors import AnalysisError, InputError
from blf.maint import LvdtCalibration, fit_lvdt_calibration
from blf.maint.calibration import correct_linear
from blf.signals import position_differences

# The simulator's LVDT law (sim/params.py SensorParams), paper values:
GAIN = 1.075  # 7.5 % pitch error
OFFSET_MM = 0.30
NONLIN_MM = 0.02  # cubic term at full scale
FULL_SCALE_MM = 20.0
SIGMA_S_MM = 0.025 / 6.0  # 0.025 mm peak-to-peak
DEFLECTION_MM = 0.025  # constant internal deflection during the sweep (2 kN / 80 kN/mm)
I_TOTAL = 2 * np.pi * 4 / 5


def lvdt(s_true_mm):
    return OFFSET_MM + GAIN * s_true_mm + NONLIN_MM * (s_true_mm / FULL_SCALE_MM) ** 3


def sweep(rng: np.random.Generator, amplitude_mm: float = 18.0, n: int = 4000):
    """Slow sweep -A..+A..-A of x = phi/i_total; s measured on the ram (x - d)."""
    x = amplitude_mm * np.concatenate((np.linspace(-1, 1, n // 2), np.linspace(1, -1, n // 2)))
    s = lvdt(x - DEFLECTION_MM) + rng.normal(0.0, SIGMA_S_MM, x.size)
    return x, s


def true_coefficients():
    """s(x) = off + g (x - d) + n3 ((x - d)/FS)^3 expanded in powers of x."""
    g, d, c = GAIN, DEFLECTION_MM, NONLIN_MM / FULL_SCALE_MM**3
    return np.array([OFFSET_MM - g * d - c * d**3, g + 3 * c * d**2, -3 * c * d, c])


def test_recovers_pitch_offset_and_cubic():
    cal = fit_lvdt_calibration(*sweep(np.random.default_rng(1)))
    truth = true_coefficients()
    sig = np.array(cal.coefficient_sigmas)
    assert isinstance(cal, LvdtCalibration)
    assert cal.degree == 3 and cal.n == 4000
    assert (cal.x_min_mm, cal.x_max_mm) == (-18.0, 18.0)
    # every coefficient within 4 standard errors of the truth
    assert np.all(np.abs(np.array(cal.coefficients) - truth) < 4 * sig), (cal.coefficients, truth, sig)
    # the paper's figures
    assert cal.pitch == pytest.approx(1.075, abs=1e-4)
    assert cal.offset_mm == pytest.approx(OFFSET_MM - GAIN * DEFLECTION_MM, abs=3e-4)
    assert cal.coefficients[3] == pytest.approx(NONLIN_MM / FULL_SCALE_MM**3, rel=0.1)
    # standard errors of the right size: sigma / sqrt(n) scaled by the design
    assert 5e-5 < sig[0] < 2e-4 and 5e-6 < sig[1] < 3e-5
    # max deviation from the least-squares straight line of c3 x^3 on [-L, L]: 0.4 c3 L^3
    expected_nl = 0.4 * (NONLIN_MM / FULL_SCALE_MM**3) * 18.0**3  # 0.00583 mm
    assert cal.nonlinearity_mm == pytest.approx(expected_nl, rel=0.1)
    # residual RMS is the LVDT noise (paper: "rmse < 0.02")
    assert cal.rmse_mm == pytest.approx(SIGMA_S_MM, rel=0.05)
    assert cal.monotone


def test_exact_polynomial_is_recovered_exactly():
    x = np.linspace(-20, 20, 200)
    c = (0.3, 1.075, -2e-5, 2.5e-6)
    s = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3
    cal = fit_lvdt_calibration(x, s)
    np.testing.assert_allclose(cal.coefficients, c, rtol=1e-9, atol=1e-12)
    assert cal.rmse_mm < 1e-12
    # straight line: no non-linearity
    lin = fit_lvdt_calibration(x, 0.1 + 0.98 * x, degree=1)
    assert lin.pitch == pytest.approx(0.98, abs=1e-12)
    assert lin.offset_mm == pytest.approx(0.1, abs=1e-12)
    assert lin.nonlinearity_mm < 1e-12


def test_correct_inverts_exactly_and_removes_the_lvdt_error():
    x, s = sweep(np.random.default_rng(2))
    cal = fit_lvdt_calibration(x, s)
    grid = np.linspace(-18, 18, 10_001)
    back = cal.correct(cal.evaluate(grid))
    assert np.max(np.abs(back - grid)) < 1e-11
    # shape is kept
    block = grid[:10_000].reshape(1000, 10)
    np.testing.assert_allclose(cal.correct(cal.evaluate(block)), block, rtol=0, atol=1e-11)
    # noise-free readings map to the motor-angle scale: corrected = s_true + d = x,
    # up to the fit's own noise (~0.1 um mid-stroke, < 1 um at the sweep ends)
    err = cal.correct(lvdt(grid - DEFLECTION_MM)) - grid
    assert np.max(np.abs(err)) < 1.5e-3
    assert np.mean(np.abs(err)) < 3e-4
    # beyond the sweep: continuous, linear extrapolation with the end slope
    s_end = float(cal.evaluate(np.array(18.0)))
    slope_end = cal.coefficients[1] + 2 * cal.coefficients[2] * 18 + 3 * cal.coefficients[3] * 18**2
    assert cal.correct(np.array([s_end + 0.5]))[0] == pytest.approx(18.0 + 0.5 / slope_end, abs=1e-12)


def test_correct_converges_for_every_element_of_a_long_random_array():
    # elements converge at different iterations; a converged one must stay put
    # (a former defect moved a few per thousand to the bisection midpoint)
    rng = np.random.default_rng(11)
    x, s = sweep(rng)
    cal = fit_lvdt_calibration(x, s)
    lo, hi = cal.evaluate(np.array([cal.x_min_mm, cal.x_max_mm]))
    readings = rng.uniform(lo, hi, 200_000)
    back = cal.correct(readings)
    assert np.max(np.abs(cal.evaluate(back) - readings)) < 1e-10


def test_pitch_correction_makes_d_int_flat_over_the_stroke():
    """Paper 2.3: an uncorrected 7.5 % pitch error ruins D_int over the stroke."""
    rng = np.random.default_rng(3)
    x, s = sweep(rng)
    cal = fit_lvdt_calibration(x, s)
    phi = x * I_TOTAL
    raw = position_differences(phi, phi, s, s, I_TOTAL).d_int1_mm
    corr = position_differences(phi, phi, cal.correct(s), cal.correct(s), I_TOTAL).d_int1_mm
    # uncorrected: D_int drifts by 0.075 * 36 mm = 2.7 mm over the sweep
    assert np.ptp(np.polyval(np.polyfit(x, raw, 1), [-18, 18])) == pytest.approx(2.7, rel=0.01)
    # corrected: constant (the constant deflection is absorbed in the offset), noise only
    assert abs(np.mean(corr)) < 2e-4
    assert np.std(corr) == pytest.approx(SIGMA_S_MM / GAIN, rel=0.05)


def test_sigmas_match_seed_spread():
    cals = [fit_lvdt_calibration(*sweep(np.random.default_rng(100 + k), n=2000)) for k in range(20)]
    for j in range(4):
        spread = np.std([c.coefficients[j] for c in cals], ddof=1)
        reported = np.mean([c.coefficient_sigmas[j] for c in cals])
        assert 0.5 < reported / spread < 2.0, (j, reported, spread)


def test_non_monotone_polynomial_is_refused_by_correct():
    x = np.linspace(-2, 2, 100)
    cal = fit_lvdt_calibration(x, x**3 - 3 * x)  # turns at x = +-1
    assert not cal.monotone
    with pytest.raises(AnalysisError, match="not strictly monotone"):
        cal.correct(np.array([0.0]))
    # a decreasing LVDT is fine (monotone), and inverted exactly
    dec = fit_lvdt_calibration(x, 0.5 - 1.1 * x + 0.01 * x**3)
    assert dec.monotone and dec.pitch == pytest.approx(-1.1)
    np.testing.assert_allclose(dec.correct(dec.evaluate(x)), x, atol=1e-12)


def test_input_errors_name_argument_shape_and_unit():
    x, s = sweep(np.random.default_rng(4), n=200)
    with pytest.raises(InputError, match=r"at least 50 samples.*\(49,\)"):
        fit_lvdt_calibration(x[:49], s[:49])
    bad = s.copy()
    bad[3] = np.nan
    with pytest.raises(InputError, match=r"s_mm must be finite.*mm.*\(200,\)"):
        fit_lvdt_calibration(x, bad)
    with pytest.raises(InputError, match=r"s_mm.*same shape as x_mm.*\(199,\).*\(200,\)"):
        fit_lvdt_calibration(x, s[:-1])
    with pytest.raises(InputError, match=r"x_mm must be a 1-D array in mm; got shape \(2, 100\)"):
        fit_lvdt_calibration(x.reshape(2, 100), s)
    with pytest.raises(InputError, match=r"x_mm must span at least 1 mm.*0.5 mm"):
        fit_lvdt_calibration(np.linspace(0, 0.5, 200), s)
    with pytest.raises(InputError, match="degree"):
        fit_lvdt_calibration(x, s, degree=0)
    with pytest.raises(InputError, match="degree"):
        fit_lvdt_calibration(x, s, degree=2.0)
    cal = fit_lvdt_calibration(x, s)
    with pytest.raises(InputError, match="s_mm must be finite"):
        cal.correct(np.array([1.0, np.inf]))


def test_frozen():
    cal = fit_lvdt_calibration(*sweep(np.random.default_rng(5), n=200))
    with pytest.raises(AttributeError):
        cal.pitch = 1.0  # type: ignore[misc]


def test_linear_correction_inverts_pitch_and_offset():
    """result.json's calibration (pitch, offset): x = (s - offset) / pitch, any shape."""
    x = np.linspace(-18.0, 18.0, 12).reshape(3, 4)
    s = OFFSET_MM + GAIN * x
    np.testing.assert_allclose(correct_linear(s, GAIN, OFFSET_MM), x, rtol=0, atol=1e-12)
    # the straight line of the full calibration: the same correction up to the non-linearity
    cal = fit_lvdt_calibration(*sweep(np.random.default_rng(6)))
    xs = np.linspace(-15.0, 15.0, 7)
    lin = correct_linear(cal.evaluate(xs), cal.pitch, cal.offset_mm)
    assert np.max(np.abs(lin - xs)) < 0.05
    with pytest.raises(InputError, match="pitch"):
        correct_linear(s, 0.0, OFFSET_MM)
    with pytest.raises(InputError, match="offset_mm"):
        correct_linear(s, GAIN, float("nan"))
    with pytest.raises(InputError, match=r"s_mm must be finite \(in mm\)"):
        correct_linear(np.array([np.nan]), GAIN, OFFSET_MM)


def test_correct_chunked_equals_one_pass(monkeypatch):
    """Issue 34: the inversion solved chunk by chunk gives the same bits as over all readings at once
    (chunks of 1 and 7 readings: the common step count reconstructed from the chunks' records)."""
    import blf.maint.calibration as cal_mod

    rng = np.random.default_rng(34)
    x = np.linspace(-40.0, 40.0, 2001)
    cal = fit_lvdt_calibration(x, 0.3 + 1.05 * x + 2e-4 * x**2 - 3e-6 * x**3 + rng.normal(0.0, 1e-3, x.size))
    s = np.concatenate([rng.uniform(-60.0, 60.0, 3000), [0.0, cal.evaluate(np.array(40.0))]])
    whole = cal.correct(s)
    for chunk in (1, 7):
        monkeypatch.setattr(cal_mod, "_CHUNK", chunk)
        assert np.array_equal(cal.correct(s), whole)
