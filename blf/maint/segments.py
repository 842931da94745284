"""Segments of a recording: calibration sweeps, the force fight, a slow sweep under load.

The maintenance check records three phases (paper 2.1, 2.3): a slow
calibration sweep of each EMA, then the force fight. A run folder names them
in its step column; a recording made elsewhere carries only the signals, and
the phases are found from the motion of the rams and the forces
(:func:`find_segments`). In normal operation a slow sweep under a steady
one-sided load can stand in for the calibration sweep (:func:`find_sweep`).

Shared pieces: :func:`runs` (contiguous stretches of a mask),
:func:`smooth_speed` (the ram speed the motion tests use) and :func:`trim`
(drop the acceleration phases at the ends of each stretch).

Pure: arrays and an explicit sample period in, masks and a frozen
dataclass out; no IO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from blf.errors import AnalysisError, InputError
from blf.validate import as_1d_finite, positive_scalar, same_shape, scalar

__all__ = ["Segments", "runs", "smooth_speed", "trim", "find_segments", "find_sweep"]

#: Step names of a run folder's step column.
STEP_CAL1, STEP_CAL2, STEP_FORCE_FIGHT = "cal1_sweep", "cal2_sweep", "force_fight"

_MOVING_MM_S = 0.5  # a ram moves faster than this (find_segments)
_BRIDGE_S = 1.0  # stops shorter than this inside a sweep (reversals) are bridged
_SWEEP_FRACTION = 0.25  # a calibration sweep spans more than this fraction of the full stroke 2 x limit
_FIGHT_FRACTION = 0.2  # force-fight samples: |F1 - F2|/2 above this fraction of its maximum
_MIN_FIGHT_SAMPLES = 100
_SLOW_MM_S = (0.3, 10.0)  # speed range of a slow sweep (find_sweep)
_MIN_SWEEP_SAMPLES = 50
_MIN_LOAD_N = 200.0
_TRIM = 0.02  # fraction dropped at each end of a sweep


@dataclass(frozen=True)
class Segments:
    """The phases of a maintenance-check recording as boolean masks over its samples.

    Attributes
    ----------
    cal1, cal2 : ndarray of bool, shape (n,), or None
        Samples of the calibration sweep of EMA 1 and EMA 2 (None: no sweep).
        A detected single sweep serves both EMAs (the same mask).
    force_fight : ndarray of bool, shape (n,)
        Samples of the force fight.
    source : str
        ``"step column"`` or ``"detected"``.
    """

    cal1: np.ndarray | None
    cal2: np.ndarray | None
    force_fight: np.ndarray
    source: str


def runs(mask) -> list[tuple[int, int]]:
    """Contiguous stretches of True in a 1-D boolean mask.

    Parameters
    ----------
    mask : array_like of bool, shape (n,)

    Returns
    -------
    list of (int, int)
        ``(start, stop)`` of each stretch, ``mask[start:stop]`` all True, in
        order; empty if the mask has no True.
    """
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False])).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def smooth_speed(x_mm, sample_period_s: float, window_s: float = 0.2) -> np.ndarray:
    """Speed of a position signal, smoothed by a moving average.

    Parameters
    ----------
    x_mm : array_like, shape (n,)
        Position, mm (n >= 2).
    sample_period_s : float
        Sample period, s.
    window_s : float, optional
        Length of the moving average, s (default 0.2).

    Returns
    -------
    ndarray, shape (n,)
        Speed in mm/s.

    Notes
    -----
    Central differences (:func:`numpy.gradient`, one-sided at the ends),
    then a centred moving average over :math:`N = \\max(1, \\mathrm{round}(w/T))`
    samples (:func:`scipy.ndimage.uniform_filter1d`; the ends are padded with
    the end values, so a speed at the edge of the recording is not pulled
    towards zero):

    .. math:: \\bar v_k = \\frac{1}{N} \\sum_{j} \\frac{x_{j+1} - x_{j-1}}{2T} \\quad [mm/s]
    """
    x = as_1d_finite(x_mm, "x_mm", "mm", min_len=2)
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    n = max(1, int(round(positive_scalar(window_s, "window_s", "s") / T)))
    v = np.gradient(x, T)
    return ndimage.uniform_filter1d(v, n, mode="nearest", output=v)  # in place: scipy filters a copy of the line


def _trimmed(a: int, b: int, frac: float) -> tuple[int, int]:
    k = int((b - a) * frac)
    return a + k, b - k


def trim(mask, frac: float = _TRIM) -> np.ndarray:
    """Drop the first and last ``frac`` of each stretch of True (the acceleration at its ends).

    Parameters
    ----------
    mask : array_like of bool, shape (n,)
    frac : float, optional
        Fraction of each stretch's length dropped at either end, in [0, 0.5)
        (default 0.02; rounded down to whole samples).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    f = scalar(frac, "frac", "(fraction, dimensionless)", lo=0.0, hi=0.5, hi_open=True)
    m = np.asarray(mask, dtype=bool)
    out = np.zeros_like(m)
    for a, b in runs(m):
        a, b = _trimmed(a, b, f)
        out[a:b] = True
    return out


def find_segments(x1_mm, x2_mm, f1_N, f2_N, sample_period_s: float, stroke_limit_mm: float, *,
                  step=None) -> Segments:
    """Calibration sweeps and force-fight samples of a maintenance-check recording.

    Parameters
    ----------
    x1_mm, x2_mm : array_like, shape (n,)
        Motor angles referred to the rams, ``phi / i_total``, mm.
    f1_N, f2_N : array_like, shape (n,)
        Load-cell forces, N.
    sample_period_s : float
        Sample period, s.
    stroke_limit_mm : float
        Stroke limit (end stops at +- this), mm.
    step : array_like of str, shape (n,), optional
        The run folder's step column. With it the phases are its
        ``cal1_sweep``, ``cal2_sweep`` and ``force_fight`` samples; without
        it they are detected.

    Returns
    -------
    Segments

    Raises
    ------
    blf.errors.InputError
        Bad shapes, NaN/inf, a non-positive period or stroke limit.
    blf.errors.AnalysisError
        A step column without force-fight samples; no stationary stretch or
        no force fight found.

    Notes
    -----
    Detection (no step column): the rams move where the speed of either
    (:func:`smooth_speed`, 0.2 s average) exceeds 0.5 mm/s, stops shorter
    than 1 s bridged (a binary closing: the reversals of a sweep). A moving
    stretch is a sweep if either ram travels more than a quarter of the
    full stroke :math:`2 x_{lim}` in it; the first sweep calibrates EMA 1,
    the second EMA 2 (both LVDTs see a constant load-path deflection in
    either, so with only one sweep both use it). The force fight lies after
    the last sweep, where both rams are still and
    :math:`|F_1 - F_2|/2` exceeds 20 % of its maximum over the still
    samples: from its first to its last such sample, still samples only.
    """
    x1 = as_1d_finite(x1_mm, "x1_mm", "mm")
    x2 = as_1d_finite(x2_mm, "x2_mm", "mm")
    f1 = as_1d_finite(f1_N, "f1_N", "N")
    f2 = as_1d_finite(f2_N, "f2_N", "N")
    same_shape((x1, "x1_mm", "mm"), (x2, "x2_mm", "mm"), (f1, "f1_N", "N"), (f2, "f2_N", "N"))
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    lim = positive_scalar(stroke_limit_mm, "stroke_limit_mm", "mm")
    if step is not None:
        return _from_step_column(np.asarray(step), x1.shape)
    moving = _moving(x1, T)
    moving |= _moving(x2, T)
    gap = int(round(_BRIDGE_S / T))
    moving = ndimage.binary_closing(moving, structure=np.ones(gap, bool)) | moving
    sweeps = [(a, b) for a, b in runs(moving)
              if max(np.ptp(x1[a:b]), np.ptp(x2[a:b])) > _SWEEP_FRACTION * 2 * lim]
    masks = []
    for a, b in sweeps[:2]:
        m = np.zeros(x1.size, bool)
        m[a:b] = True
        masks.append(m)
    cal1 = masks[0] if masks else None
    cal2 = masks[1] if len(masks) > 1 else cal1
    start = sweeps[-1][1] if sweeps else 0
    still = ~moving
    still[:start] = False
    fff = np.subtract(f1, f2)  # |F1 - F2|/2 in one array (the same operations as abs(0.5 * (f1 - f2)))
    fff *= 0.5
    np.abs(fff, out=fff)
    if not still.any():
        raise AnalysisError("no stationary stretch for the force fight found in the recording")
    idx = np.flatnonzero(still & (fff > _FIGHT_FRACTION * fff[still].max()))
    if idx.size < _MIN_FIGHT_SAMPLES:
        raise AnalysisError("no force-fight segment found (|F1 - F2|/2 never rises while the rams are still)")
    ff = np.zeros(x1.size, bool)
    ff[idx[0]:idx[-1] + 1] = True
    ff &= still
    return Segments(cal1, cal2, ff, "detected")


def _moving(x: np.ndarray, T: float) -> np.ndarray:
    """Where the smoothed speed of ``x`` exceeds the moving threshold (one temporary the length of x)."""
    v = smooth_speed(x, T)
    np.abs(v, out=v)
    return v > _MOVING_MM_S


def _from_step_column(step: np.ndarray, shape: tuple) -> Segments:
    if step.shape != shape:
        raise InputError(f"step (step names, no unit) must have the same shape as x1_mm (in mm); "
                         f"got step shape {step.shape} and x1_mm shape {shape}")
    cal1 = step == STEP_CAL1
    cal2 = step == STEP_CAL2
    ff = step == STEP_FORCE_FIGHT
    if not ff.any():
        raise AnalysisError("the recording's step column has no 'force_fight' samples")
    return Segments(cal1 if cal1.any() else None, cal2 if cal2.any() else None, ff, "step column")


def find_sweep(x_mm, f_N, sample_period_s: float, stroke_limit_mm: float) -> slice | None:
    """Longest slow sweep under a steady one-sided force, trimmed 2 % at each end.

    Parameters
    ----------
    x_mm : array_like, shape (n,)
        Motor angle referred to the ram, ``phi / i_total``, mm.
    f_N : array_like, shape (n,)
        The EMA's load-cell force, N.
    sample_period_s : float
        Sample period, s.
    stroke_limit_mm : float
        Stroke limit, mm.

    Returns
    -------
    slice or None
        The sweep's samples, or None if there is none.

    Raises
    ------
    blf.errors.InputError
        Bad shapes, NaN/inf, a non-positive period or stroke limit.

    Notes
    -----
    Slow: :math:`0.3 \\le |v| \\le 10` mm/s (:func:`smooth_speed`, 0.2 s
    average of the motor-side speed), for at least 50 samples; long: at least
    half the stroke limit of travel; steady load: mean force
    :math:`|\\bar F| > 200` N, of the sign of the mean in 99 % of the samples
    and a standard deviation below :math:`|\\bar F|/2`. The internal load path
    then stays in contact on one flank and its deflection is constant on
    average (paper 2.3; the opposing EMA in force mode rings at a few Hz,
    which the calibration regression averages out). Of several such
    stretches the longest is taken; :func:`trim` drops its ends.
    """
    x = as_1d_finite(x_mm, "x_mm", "mm", min_len=2)
    f = as_1d_finite(f_N, "f_N", "N")
    same_shape((x, "x_mm", "mm"), (f, "f_N", "N"))
    lim = positive_scalar(stroke_limit_mm, "stroke_limit_mm", "mm")
    v = np.abs(smooth_speed(x, sample_period_s))
    best = None
    for a, b in runs((v >= _SLOW_MM_S[0]) & (v <= _SLOW_MM_S[1])):
        if b - a < _MIN_SWEEP_SAMPLES or np.ptp(x[a:b]) < 0.5 * lim:
            continue
        fs = f[a:b]
        fm = float(np.mean(fs))
        if abs(fm) < _MIN_LOAD_N or np.mean(np.sign(fs) == np.sign(fm)) < 0.99 or np.std(fs) > 0.5 * abs(fm):
            continue
        if best is None or b - a > best[1] - best[0]:
            best = (a, b)
    return None if best is None else slice(*_trimmed(*best, _TRIM))
