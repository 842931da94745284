"""Wear trend of a backlash over flight hours: weighted fit, bands, the crossing of the limit, steps.

Backlash grows with wear. Given the readings of one actuator channel (flight
hours or calendar days ``x``, backlash ``y`` in mm and each reading's expanded
uncertainty ``U`` in mm, k = 2), this module fits a straight wear line by
weighted least squares, gives the confidence band of the line and the
prediction band of a future reading, predicts where the line reaches a limit
(``B_spec``) with an interval, and finds the steps (a repair or a replacement:
the backlash drops) that start a new trend.

Pure: arrays in, frozen dataclasses out (numpy and ``scipy.special`` only).

Examples
--------
>>> import numpy as np
>>> fh = np.array([0.0, 500.0, 1000.0, 1500.0, 2000.0])
>>> fit = fit_wear(fh, 0.10 + 2e-5 * fh, np.full(5, 0.006))
>>> round(fit.rate, 8), round(limit_crossing(fit, 0.2).x, 3)
(2e-05, 5000.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blf.errors import InputError
from blf.validate import as_1d_finite, readonly, same_shape, scalar

__all__ = ["WearFit", "LimitCrossing", "fit_wear", "trend_band", "limit_crossing", "wear_segments",
           "COVERAGE_FACTOR", "CONFIDENCE"]

COVERAGE_FACTOR = 2.0  #: k of the readings' expanded uncertainties U (as in blf.maint.verdict)
CONFIDENCE = 0.95  #: two-sided confidence of the bands and intervals
STEP_THRESHOLD = 3.0  #: a drop of more than this many combined standard uncertainties is a step


@dataclass(frozen=True)
class WearFit:
    """A straight wear line ``y = level + rate * (x - x0)`` fitted by weighted least squares.

    Attributes
    ----------
    x0 : float
        Centre of the fit (the weighted mean of ``x``); ``level`` and ``rate``
        are uncorrelated there.
    level : float
        Fitted backlash at ``x0`` [mm].
    rate : float
        Wear rate [mm per unit of ``x``].
    level_sigma, rate_sigma : float
        Standard uncertainties of ``level`` and ``rate`` (after the scatter scaling).
    scale : float
        Factor applied to the stated standard uncertainties: ``sqrt(chi2 / dof)``
        when the scatter about the line exceeds them, else 1 (never below 1).
    chi2 : float
        Weighted sum of squared residuals with the stated uncertainties.
    dof : int
        Degrees of freedom ``n - 2``.
    quantile : float
        Two-sided quantile of the bands and intervals at :data:`CONFIDENCE`:
        Student's t with ``dof`` degrees of freedom when the scatter sets the
        uncertainty (``scale > 1``), else the normal quantile (the stated
        uncertainties are taken as known).
    n : int
        Number of readings.
    x_first, x_last : float
        Range of ``x`` fitted.
    sigma_typical : float
        Median stated standard uncertainty of a reading [mm] (``U / k``), used
        for the prediction band of a future reading.
    residuals : ndarray
        ``y - fitted`` [mm], read-only.
    """

    x0: float
    level: float
    rate: float
    level_sigma: float
    rate_sigma: float
    scale: float
    chi2: float
    dof: int
    quantile: float
    n: int
    x_first: float
    x_last: float
    sigma_typical: float
    residuals: np.ndarray

    @property
    def chi2_per_dof(self) -> float:
        """``chi2 / dof`` (NaN with no degree of freedom): about 1 when the stated U describe the scatter."""
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    def predict(self, x) -> np.ndarray:
        """The fitted backlash at ``x`` [mm]."""
        return self.level + self.rate * (np.asarray(x, dtype=float) - self.x0)

    def line_sigma(self, x) -> np.ndarray:
        """Standard uncertainty of the fitted line at ``x`` [mm] (the fit's covariance, scaled)."""
        u = np.asarray(x, dtype=float) - self.x0
        return np.sqrt(self.level_sigma ** 2 + (u * self.rate_sigma) ** 2)


@dataclass(frozen=True)
class LimitCrossing:
    """Where a wear line reaches a limit, with its confidence interval.

    Attributes
    ----------
    x : float
        Point estimate, ``x0 + (limit - level) / rate``; NaN when the fitted rate
        is not positive (no crossing predicted).
    lo, hi : float
        Confidence interval at :data:`CONFIDENCE` by inverting the line's
        confidence band (Fieller): ``-inf``/``inf`` where it is not bounded, NaN
        when the data say nothing (the band contains the limit everywhere).
    sigma_delta : float
        Standard uncertainty of ``x`` by the delta method,
        ``line_sigma(x) / rate`` (NaN when ``x`` is); symmetric, for comparison.
    limit : float
        The limit [mm].
    """

    x: float
    lo: float
    hi: float
    sigma_delta: float
    limit: float

    @property
    def bounded(self) -> bool:
        """True when the interval is finite at both ends."""
        return bool(np.isfinite(self.lo) and np.isfinite(self.hi))


def _inputs(x, y, u, min_len: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = as_1d_finite(x, "x", "flight hours or days", min_len=min_len)
    y = as_1d_finite(y, "backlash_mm", "mm", min_len=min_len)
    u = as_1d_finite(u, "uncertainty_mm", "mm", min_len=min_len)
    same_shape((x, "x", "flight hours or days"), (y, "backlash_mm", "mm"), (u, "uncertainty_mm", "mm"))
    if np.any(u <= 0.0):
        raise InputError(f"uncertainty_mm must be > 0 mm for every reading; got {int(np.sum(u <= 0))} "
                         f"value(s) <= 0 in shape {u.shape}")
    return x, y, u


def _quantile(dof: int | None, confidence: float) -> float:
    """Two-sided quantile: normal (dof None) or Student's t."""
    from scipy.special import ndtri, stdtrit

    p = 0.5 + confidence / 2.0
    return float(ndtri(p)) if dof is None else float(stdtrit(dof, p))


def fit_wear(x, backlash_mm, uncertainty_mm, *, coverage_factor: float = COVERAGE_FACTOR,
             confidence: float = CONFIDENCE) -> WearFit:
    """Fit a straight wear line to backlash readings, weighted by their uncertainties.

    Parameters
    ----------
    x : array_like, shape (n,)
        Flight hours (or calendar days) of the readings, at least two distinct values.
    backlash_mm : array_like, shape (n,)
        The readings [mm].
    uncertainty_mm : array_like, shape (n,)
        Each reading's expanded uncertainty U [mm] (> 0), with coverage factor
        ``coverage_factor``.
    coverage_factor : float, optional
        k of ``uncertainty_mm`` (2: the U of result.json).
    confidence : float, optional
        Two-sided confidence of the quantile stored in the fit (0.95).

    Returns
    -------
    WearFit

    Raises
    ------
    blf.errors.InputError
        Arrays of different shapes, not finite, an uncertainty <= 0, fewer than
        two readings or all at the same ``x``.

    Notes
    -----
    Each reading's standard uncertainty is :math:`\\sigma_i = U_i / k`; the
    weights are :math:`w_i = 1/\\sigma_i^2`. With :math:`x_0 = \\sum w_i x_i /
    \\sum w_i` the estimates are uncorrelated:

    .. math:: \\hat a = \\frac{\\sum w_i y_i}{\\sum w_i}, \\quad
              \\hat b = \\frac{\\sum w_i (x_i - x_0) y_i}{S_{xx}}, \\quad
              S_{xx} = \\sum w_i (x_i - x_0)^2,

    with variances :math:`s^2/\\sum w_i` and :math:`s^2/S_{xx}`. The factor
    :math:`s^2 = \\max(1, \\chi^2/\\nu)`, :math:`\\nu = n - 2`, is the Birge
    ratio: where the readings scatter about the line more than their stated
    uncertainties allow (wear is not exactly linear, or U is optimistic), the
    covariance grows with the observed scatter and the intervals use Student's
    t with :math:`\\nu` degrees of freedom (as ``scipy.optimize.curve_fit``
    with ``absolute_sigma=False``); where they scatter less, the stated
    uncertainties stand (``absolute_sigma=True``) and the normal quantile
    applies. It is never scaled below 1: a part of each U is a bound on the
    method's error (blf.maint.verdict), which a small scatter does not disprove.
    """
    x, y, u = _inputs(x, backlash_mm, uncertainty_mm, 2)
    k = scalar(coverage_factor, "coverage_factor", "(dimensionless)", lo=0.0, lo_open=True)
    conf = scalar(confidence, "confidence", "(dimensionless)", lo=0.0, lo_open=True, hi=1.0, hi_open=True)
    sigma = u / k
    w = 1.0 / sigma ** 2
    sw = float(np.sum(w))
    x0 = float(np.sum(w * x) / sw)
    dx = x - x0
    sxx = float(np.sum(w * dx ** 2))
    if not sxx > 0.0 or np.ptp(x) <= 0.0:
        raise InputError(f"x must hold at least two distinct values (flight hours or days); got {x.size} "
                         f"reading(s) all at x = {x[0]!r}")
    level = float(np.sum(w * y) / sw)
    rate = float(np.sum(w * dx * y) / sxx)
    resid = y - (level + rate * dx)
    chi2 = float(np.sum(w * resid ** 2))
    dof = x.size - 2
    scaled = dof >= 1 and chi2 / dof > 1.0
    s2 = chi2 / dof if scaled else 1.0
    q = _quantile(dof if scaled else None, conf)
    return WearFit(x0=x0, level=level, rate=rate, level_sigma=math.sqrt(s2 / sw), rate_sigma=math.sqrt(s2 / sxx),
                   scale=math.sqrt(s2), chi2=chi2, dof=dof, quantile=q, n=int(x.size), x_first=float(x.min()),
                   x_last=float(x.max()), sigma_typical=float(np.median(sigma)), residuals=readonly(resid))


def trend_band(fit: WearFit, x, *, prediction: bool = False,
               reading_sigma_mm: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fitted line at ``x`` with its confidence band or the prediction band of a new reading.

    Parameters
    ----------
    fit : WearFit
    x : array_like
        Where to evaluate (flight hours or days).
    prediction : bool, optional
        False (default): the confidence band of the line (where the true
        backlash lies). True: the prediction band of one future reading (the
        line's uncertainty and the reading's own, combined).
    reading_sigma_mm : float, optional
        Standard uncertainty of that future reading [mm]; default the fit's
        typical one (``fit.sigma_typical``). Scaled by ``fit.scale`` like the
        readings were.

    Returns
    -------
    lo, mid, hi : ndarray
        Lower band edge, line, upper band edge [mm].
    """
    if not isinstance(fit, WearFit):
        raise InputError(f"fit must be a WearFit, got {type(fit).__name__}")
    xs = as_1d_finite(np.atleast_1d(x), "x", "flight hours or days")
    mid = fit.predict(xs)
    var = fit.line_sigma(xs) ** 2
    if prediction:
        s_new = fit.sigma_typical if reading_sigma_mm is None else scalar(
            reading_sigma_mm, "reading_sigma_mm", "mm", lo=0.0)
        var = var + (fit.scale * s_new) ** 2
    half = fit.quantile * np.sqrt(var)
    return mid - half, mid, mid + half


def limit_crossing(fit: WearFit, limit_mm: float) -> LimitCrossing:
    """Where the wear line reaches ``limit_mm``, with a confidence interval.

    Parameters
    ----------
    fit : WearFit
    limit_mm : float
        The limit (B_spec) [mm].

    Returns
    -------
    LimitCrossing

    Notes
    -----
    The interval is the set of :math:`x` at which the limit lies inside the
    line's confidence band (Fieller's theorem, the inversion of the band):

    .. math:: (\\hat a - L + \\hat b u)^2 \\le q^2 (\\sigma_a^2 + u^2 \\sigma_b^2),
              \\quad u = x - x_0,

    a quadratic in :math:`u`. It uses the fit's covariance, already scaled by
    the scatter where the scatter exceeds the stated uncertainties
    (:func:`fit_wear`), and the fit's quantile. Unlike the delta method
    (:math:`\\sigma_x = \\sigma_{line}(\\hat x)/\\hat b`, given as
    ``sigma_delta``) it is asymmetric, as the reciprocal of a rate is, and
    honest about a rate that is not clearly positive: when
    :math:`\\hat b^2 < q^2 \\sigma_b^2` the set is unbounded (``hi = inf``:
    the data cannot say the limit will ever be reached; ``lo`` still says
    how soon it could be). It answers "when does the true backlash reach the
    limit"; a reading is expected to exceed the limit earlier or later by the
    prediction band (:func:`trend_band`), and a check stops passing once
    the reading plus its U reaches the limit.
    """
    if not isinstance(fit, WearFit):
        raise InputError(f"fit must be a WearFit, got {type(fit).__name__}")
    L = scalar(limit_mm, "limit_mm", "mm", lo=0.0, lo_open=True)
    a, b, q = fit.level, fit.rate, fit.quantile
    va, vb = fit.level_sigma ** 2, fit.rate_sigma ** 2
    c = a - L
    x_hat = fit.x0 - c / b if b > 0.0 else math.nan
    sigma_delta = (float(fit.line_sigma(x_hat)) / b) if b > 0.0 else math.nan
    A = b * b - q * q * vb
    B = 2.0 * c * b
    C = c * c - q * q * va
    disc = B * B - 4.0 * A * C
    lo = hi = math.nan
    if A > 0.0 and b > 0.0:  # the rate is clearly positive: a bounded interval around the estimate
        r = math.sqrt(max(disc, 0.0))
        r1, r2 = sorted(((-B - r) / (2.0 * A), (-B + r) / (2.0 * A)))
        lo, hi = fit.x0 + r1, fit.x0 + r2
    elif A < 0.0 and disc > 0.0:
        # the rate is not clearly non-zero: two half-lines (-inf, r1] and [r2, inf); the one holding the
        # estimate (without one, the one ahead: the limit cannot be reached before r2)
        r = math.sqrt(disc)
        r1, r2 = sorted(((-B - r) / (2.0 * A), (-B + r) / (2.0 * A)))
        if b > 0.0 and x_hat - fit.x0 <= r1:
            lo, hi = -math.inf, fit.x0 + r1
        else:
            lo, hi = fit.x0 + r2, math.inf
    return LimitCrossing(x=float(x_hat), lo=float(lo), hi=float(hi), sigma_delta=float(sigma_delta), limit=L)


def wear_segments(x, backlash_mm, uncertainty_mm, *, coverage_factor: float = COVERAGE_FACTOR,
                  threshold: float = STEP_THRESHOLD) -> list[np.ndarray]:
    """Split a series of readings at its steps down (a repair or replacement starts a new trend).

    Parameters
    ----------
    x : array_like, shape (n,)
        Flight hours or days, in the order of the checks (non-decreasing).
    backlash_mm, uncertainty_mm : array_like, shape (n,)
        Readings and their expanded uncertainties U [mm].
    coverage_factor : float, optional
        k of ``uncertainty_mm``.
    threshold : float, optional
        A reading lower than the one before by more than ``threshold`` combined
        standard uncertainties is a step (3: a false step once in about 740
        pairs of an unworn actuator, none in a wearing one).

    Returns
    -------
    list of ndarray
        Index arrays of the segments, in order, covering ``0..n-1``.

    Notes
    -----
    Wear does not go backwards, so only a drop counts. A drop confirmed by the
    next reading (also below the reading before the drop by the same margin)
    or at the end of the series (the latest check after a repair) starts a
    new segment; a single low reading between two higher ones is an outlier
    and stays in its segment (it is not dropped: the fit's scatter shows it).
    """
    x, y, u = _inputs(x, backlash_mm, uncertainty_mm, 1)
    if np.any(np.diff(x) < 0):
        raise InputError("x must be non-decreasing (the readings in the order of the checks)")
    k = scalar(coverage_factor, "coverage_factor", "(dimensionless)", lo=0.0, lo_open=True)
    z = scalar(threshold, "threshold", "(dimensionless)", lo=0.0, lo_open=True)
    s = u / k

    def drop(i: int, j: int) -> bool:  # reading j significantly below reading i
        return bool(y[i] - y[j] > z * math.hypot(s[i], s[j]))

    starts = [0]
    for i in range(1, y.size):
        if drop(i - 1, i) and (i == y.size - 1 or drop(i - 1, i + 1)):
            starts.append(i)
    bounds = starts + [y.size]
    return [np.arange(bounds[j], bounds[j + 1]) for j in range(len(starts))]
