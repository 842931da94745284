"""Backlash measurement error budget of paper section 2.3, as computed numbers.

Three error sources of the LVDT-based backlash readings, for BLFmaint and
BLFserv (paper method and improved method):

* the LVDT **pitch** (gain) error, uncompensated and after calibration:
  the pitch error times the LVDT travel that enters the reading;
* **noise** after filtering: the LVDT noise through the filters' noise gain
  and the estimator's geometry;
* a **temperature**-induced LVDT error (1 % assumed, paper 2.3) over the size
  of the jump read.

Pure: numbers in, a frozen dataclass out; no IO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from blf.serv.filters import design_serv_filters
from blf.validate import positive_scalar, scalar

__all__ = ["MethodErrors", "AccuracyBudget", "backlash_error_budget"]


@dataclass(frozen=True)
class MethodErrors:
    """Backlash error contributions of one method, mm (all >= 0, one-sided bounds or 1-sigma).

    Attributes
    ----------
    method : str
        ``"BLFmaint"``, ``"BLFserv (paper)"`` or ``"BLFserv (improved)"``.
    travel_mm : float
        LVDT travel that enters the reading (pitch term), mm.
    pitch_uncompensated_mm : float
        ``travel_mm * pitch_error``: error bound without LVDT calibration.
    pitch_compensated_mm : float
        ``travel_mm * residual_pitch_error``: after calibration.
    noise_mm : float
        Standard deviation of the reading from the LVDT noise after filtering.
    jump_mm : float
        Size of the D change the reading spans (temperature term), mm.
    temperature_mm : float
        ``jump_mm * temperature_error``.
    total_compensated_mm : float
        Root sum of squares of ``pitch_compensated_mm``, ``noise_mm`` and
        ``temperature_mm``.
    total_uncompensated_mm : float
        Same with ``pitch_uncompensated_mm``.
    """

    method: str
    travel_mm: float
    pitch_uncompensated_mm: float
    pitch_compensated_mm: float
    noise_mm: float
    jump_mm: float
    temperature_mm: float
    total_compensated_mm: float
    total_uncompensated_mm: float


@dataclass(frozen=True)
class AccuracyBudget:
    """The error budget of paper 2.3 for one actuation profile.

    Attributes
    ----------
    maint, serv_paper, serv_improved : MethodErrors
        BLFmaint, BLFserv with the paper's Delta D, BLFserv improved.
    stroke_mm : float
        Half stroke (the paper's "+-20 mm"), mm.
    pitch_error : float
        Uncompensated relative LVDT pitch error (0.075 = the paper's 7.5 %).
    residual_pitch_error : float
        Relative pitch error left after calibration.
    lvdt_noise_std_mm : float
        LVDT noise standard deviation, mm (peak-to-peak / 6).
    filtered_noise_std_mm : float
        Noise of the low-passed D, mm (``noise_gain[0] * lvdt_noise_std_mm``).
    temperature_error : float
        Relative temperature-induced LVDT error (0.01).
    backlash_mm : float
        Backlash the readings are about (the specification), mm.
    target_mm : float
        Required accuracy, one order of magnitude below the backlash
        (paper 2), mm.
    """

    maint: MethodErrors
    serv_paper: MethodErrors
    serv_improved: MethodErrors
    stroke_mm: float
    pitch_error: float
    residual_pitch_error: float
    lvdt_noise_std_mm: float
    filtered_noise_std_mm: float
    temperature_error: float
    backlash_mm: float
    target_mm: float


def _line_value_variance(n: int, dist: int) -> float:
    """Variance factor of a least-squares line over n consecutive samples evaluated ``dist`` samples
    before the first (or after the last) of them."""
    xbar = dist + (n - 1) / 2.0
    sxx = n * (n * n - 1) / 12.0
    return 1.0 / n + xbar * xbar / sxx


def backlash_error_budget(stroke_mm: float, pitch_error: float, lvdt_noise_std_mm: float, sample_rate_Hz: float, *,
                          backlash_mm: float, residual_pitch_error: float = 1e-3, temperature_error: float = 0.01,
                          jump_bound_mm: float | None = None, lowpass_rad_s: float = 40.0, dt1_rad_s: float = 100.0,
                          plateau_s: float = 0.15, guard_before_s: float = 0.05, guard_after_s: float = 0.02,
                          event_s: float = 0.1) -> AccuracyBudget:
    """Compute the backlash error budget of paper 2.3 for BLFmaint and BLFserv.

    Parameters
    ----------
    stroke_mm : float
        Half of the full mechanical stroke, mm (20 for +-20 mm).
    pitch_error : float
        Uncompensated relative LVDT pitch error, e.g. 0.075.
    lvdt_noise_std_mm : float
        LVDT noise standard deviation, mm (the paper's 0.025 mm
        peak-to-peak / 6).
    sample_rate_Hz : float
        Sample rate, Hz.
    backlash_mm : float
        Backlash the readings are about (the specification), mm.
    residual_pitch_error : float, optional
        Relative pitch error left after calibration (default 1e-3; the
        simulated check's calibration recovers the pitch within 0.1 %).
    temperature_error : float, optional
        Relative temperature-induced LVDT error (default 0.01, paper).
    jump_bound_mm : float, optional
        Largest D jump BLFserv reads, mm (default ``stroke_mm / 10``: the
        paper's "a tenth of the full mechanical stroke, i.e. 2 mm").
    lowpass_rad_s, dt1_rad_s : float, optional
        BLFserv filters (:func:`blf.serv.filters.design_serv_filters`).
    plateau_s, guard_before_s, guard_after_s : float, optional
        Plateau fits of the improved BLFserv (:func:`blf.serv.blfserv.blf_serv`).
    event_s : float, optional
        Duration of a detected event, s (default 0.1, typical on the rig).

    Returns
    -------
    AccuracyBudget

    Raises
    ------
    blf.errors.InputError
        Negative, non-finite or non-scalar arguments.

    Notes
    -----
    With :math:`s` = ``stroke_mm``, :math:`p` = ``pitch_error``,
    :math:`p_r` = ``residual_pitch_error``, :math:`\\sigma` =
    ``lvdt_noise_std_mm``, :math:`\\tau` = ``temperature_error``,
    :math:`B` = ``backlash_mm`` (all lengths in mm):

    **Pitch.** BLFserv reads D while the surface moves over the whole stroke:
    an uncompensated pitch error adds :math:`p\\,x` to D at stroke :math:`x`,
    so the bound is :math:`s\\,p` (paper: 20 mm x 7.5 % = 1.5 mm); after
    calibration :math:`s\\,p_r`. BLFmaint holds the surface; only the LVDT
    travel across the play enters, :math:`B\\,p` (:math:`B\\,p_r`
    calibrated).

    **Noise.** :math:`g_0` = RMS of the low-pass impulse response
    (:attr:`blf.serv.filters.ServFilters.noise_gain`), :math:`\\sigma_f = g_0\\sigma`.
    A difference of two low-passed readings far apart (the paper's
    :math:`\\Delta D`; BLFmaint's corner readings before regression
    averaging, an upper bound) has :math:`\\sqrt 2\\,\\sigma_f`. The improved
    BLFserv reads two straight lines on raw D over :math:`n_p` =
    ``plateau_s`` x :math:`f_s` samples each, evaluated :math:`d` samples
    beyond them (guard plus half the event):
    :math:`\\sigma\\sqrt{v(n_p, d_b) + v(n_p, d_a)}`,
    :math:`v(n, d) = 1/n + \\bar x^2/S_{xx}`, :math:`\\bar x = d + (n-1)/2`,
    :math:`S_{xx} = n(n^2-1)/12`.

    **Temperature.** A relative LVDT error :math:`\\tau` scales the jump read:
    BLFserv :math:`\\tau\\,J` with :math:`J` = ``jump_bound_mm`` (paper:
    2 mm x 1 % = 0.02 mm); BLFmaint :math:`\\tau B` (and zero in practice: the
    calibration runs minutes before, paper 2.3).

    Totals are root sums of squares; ``target_mm`` is :math:`B/10`.
    """
    s = scalar(stroke_mm, "stroke_mm", "mm", lo=0.0)
    p = scalar(pitch_error, "pitch_error", "(relative)", lo=0.0)
    sig = scalar(lvdt_noise_std_mm, "lvdt_noise_std_mm", "mm", lo=0.0)
    fs = positive_scalar(sample_rate_Hz, "sample_rate_Hz", "Hz")
    b = positive_scalar(backlash_mm, "backlash_mm", "mm")
    pr = scalar(residual_pitch_error, "residual_pitch_error", "(relative)", lo=0.0)
    tau = scalar(temperature_error, "temperature_error", "(relative)", lo=0.0)
    jb = s / 10.0 if jump_bound_mm is None else scalar(jump_bound_mm, "jump_bound_mm", "mm", lo=0.0)
    plat = positive_scalar(plateau_s, "plateau_s", "s")
    gb = scalar(guard_before_s, "guard_before_s", "s", lo=0.0)
    ga = scalar(guard_after_s, "guard_after_s", "s", lo=0.0)
    ev = scalar(event_s, "event_s", "s", lo=0.0)
    sig_f, diff_noise, imp_noise = _noise_mm(sig, fs, lowpass_rad_s, dt1_rad_s, plat, gb, ga, ev)
    return AccuracyBudget(
        maint=_method_errors("BLFmaint", b, diff_noise, b, p, pr, tau),
        serv_paper=_method_errors("BLFserv (paper)", s, diff_noise, jb, p, pr, tau),
        serv_improved=_method_errors("BLFserv (improved)", s, imp_noise, jb, p, pr, tau),
        stroke_mm=s, pitch_error=p, residual_pitch_error=pr, lvdt_noise_std_mm=sig, filtered_noise_std_mm=sig_f,
        temperature_error=tau, backlash_mm=b, target_mm=b / 10.0,
    )


def _noise_mm(sig: float, fs: float, lowpass_rad_s: float, dt1_rad_s: float, plateau_s: float, guard_before_s: float,
              guard_after_s: float, event_s: float) -> tuple[float, float, float]:
    """Noise terms (Notes of :func:`backlash_error_budget`), mm: the low-passed noise, a difference of two
    low-passed readings, and the improved BLFserv's difference of two plateau lines."""
    filt = design_serv_filters(fs, lowpass_rad_s=lowpass_rad_s, dt1_rad_s=dt1_rad_s)
    sig_f = filt.noise_gain[0] * sig
    diff_noise = math.sqrt(2.0) * sig_f
    n_p = max(3, int(round(plateau_s * fs)))
    half_ev = 0.5 * event_s * fs
    v = (_line_value_variance(n_p, int(round(guard_before_s * fs + half_ev)))
         + _line_value_variance(n_p, int(round(guard_after_s * fs + half_ev))))
    return sig_f, diff_noise, sig * math.sqrt(v)


def _method_errors(name: str, travel: float, noise: float, jump: float, p: float, pr: float, tau: float
                   ) -> MethodErrors:
    """One method's terms: pitch over ``travel`` (uncompensated ``p``, calibrated ``pr``), ``noise``,
    temperature ``tau`` over ``jump`` (mm), and their root sums of squares."""
    pu, pc, te = travel * p, travel * pr, jump * tau
    return MethodErrors(
        method=name, travel_mm=travel, pitch_uncompensated_mm=pu, pitch_compensated_mm=pc, noise_mm=noise,
        jump_mm=jump, temperature_mm=te, total_compensated_mm=math.sqrt(pc * pc + noise * noise + te * te),
        total_uncompensated_mm=math.sqrt(pu * pu + noise * noise + te * te))
