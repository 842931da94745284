"""LVDT calibration against the motor angle (paper section 2.3, Figure 9).

During a slow full-stroke sweep under a constant opposing force the internal
load path deflection is constant, so the motor angle referred to the ram,
``x = phi / i_total``, is an exact (resolver-accurate) measure of the ram
stroke up to a constant. A polynomial regression of the LVDT reading ``s``
on ``x`` captures the LVDT's offset, pitch (gain) and non-linearity; its
inverse maps later LVDT readings back onto the motor-angle scale.

A calibration known only by its pitch and offset (a maintenance check's
result.json) is applied by :func:`correct_linear`.

Pure: arrays in, frozen dataclass out, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from blf.errors import AnalysisError, InputError
from blf.validate import as_1d_finite, as_finite, count, positive_scalar, same_shape, scalar

__all__ = ["LvdtCalibration", "fit_lvdt_calibration", "correct_linear"]

_GRID_POINTS = 2001  # dense grid for the non-linearity figure


@dataclass(frozen=True)
class LvdtCalibration:
    """Polynomial LVDT calibration ``s = sum_k c_k x**k`` and its inverse.

    Attributes
    ----------
    coefficients : tuple of float
        ``(c0, c1, ..., c_deg)`` of ``s = sum_k c_k x**k``; ``c_k`` is in
        mm**(1-k) (``c0`` in mm, ``c1`` dimensionless, ``c3`` in 1/mm**2).
    coefficient_sigmas : tuple of float
        Standard errors of ``coefficients`` (same units), from the residual
        variance with ``n - degree - 1`` degrees of freedom.
    degree : int
        Polynomial degree.
    pitch : float
        ``ds/dx`` at ``x = 0`` (= ``c1``), dimensionless; 1.075 for an LVDT
        reading 7.5 % high.
    offset_mm : float
        ``s`` at ``x = 0`` (= ``c0``), mm. Includes the (constant) internal
        deflection during the sweep, which is harmless for backlash.
    nonlinearity_mm : float
        Maximum absolute deviation of the polynomial from its least-squares
        best straight line over the swept range, mm.
    rmse_mm : float
        Root-mean-square residual of the regression, mm.
    x_min_mm, x_max_mm : float
        Swept range of ``x = phi / i_total``, mm.
    n : int
        Number of samples used.
    monotone : bool
        Whether the polynomial is strictly monotone on the swept range
        (required by :meth:`correct`).
    """

    coefficients: tuple
    coefficient_sigmas: tuple
    degree: int
    pitch: float
    offset_mm: float
    nonlinearity_mm: float
    rmse_mm: float
    x_min_mm: float
    x_max_mm: float
    n: int
    monotone: bool

    def evaluate(self, x_mm) -> np.ndarray:
        """LVDT reading predicted for ``x_mm`` (motor-angle scale), in mm.

        Parameters
        ----------
        x_mm : array_like
            Ram position on the motor-angle scale, ``phi / i_total``, mm.

        Returns
        -------
        ndarray
            ``s = sum_k c_k x**k`` in mm, same shape as ``x_mm``.
        """
        x = as_finite(x_mm, "x_mm", "mm")
        return _polyval(self.coefficients, x)

    def correct(self, s_mm) -> np.ndarray:
        """Map LVDT readings onto the motor-angle scale (invert the polynomial).

        Parameters
        ----------
        s_mm : array_like
            Raw LVDT readings in mm, any shape.

        Returns
        -------
        ndarray
            ``x`` in mm with ``P(x) = s`` (same shape as ``s_mm``).

        Raises
        ------
        blf.errors.InputError
            If ``s_mm`` contains NaN or inf.
        blf.errors.AnalysisError
            If the polynomial is not strictly monotone on the swept range.

        Notes
        -----
        Solves :math:`P(x) = \\sum_k c_k x^k = s` for :math:`x` [mm] by a
        vectorised, bracketed Newton iteration on the swept range
        :math:`[x_{min}, x_{max}]` (bisection whenever a Newton step leaves
        the bracket) until :math:`|P(x) - s|` is at round-off level, so
        ``correct(evaluate(x)) == x`` to ~1e-12 mm. Readings beyond
        :math:`P(x_{min})`, :math:`P(x_{max})` are extrapolated linearly with
        the end slope :math:`P'` (continuous, monotone; the cubic is not
        trusted outside the sweep).
        """
        s = as_finite(s_mm, "s_mm", "mm")
        if not self.monotone:
            raise AnalysisError(
                "LVDT calibration polynomial is not strictly monotone on the swept range "
                f"[{self.x_min_mm:.3f}, {self.x_max_mm:.3f}] mm; it cannot be inverted"
            )
        return _invert_monotone(self.coefficients, s, self.x_min_mm, self.x_max_mm)


def fit_lvdt_calibration(
    x_mm: np.ndarray,
    s_mm: np.ndarray,
    *,
    degree: int = 3,
    min_span_mm: float = 1.0,
) -> LvdtCalibration:
    """Fit the LVDT calibration polynomial from a slow full-stroke sweep.

    Parameters
    ----------
    x_mm : array_like, shape (n,)
        Motor angle referred to the ram, ``phi / i_total``, in mm, recorded
        during the sweep (n >= 50).
    s_mm : array_like, shape (n,)
        Raw LVDT stroke in mm at the same instants.
    degree : int, optional
        Polynomial degree, 1..5 (default 3: offset, pitch, quadratic and cubic
        non-linearity).
    min_span_mm : float, optional
        Minimum swept range ``max(x) - min(x)`` in mm (default 1.0); shorter
        sweeps cannot separate pitch from non-linearity.

    Returns
    -------
    LvdtCalibration
        Coefficients, their standard errors, pitch, offset, non-linearity,
        residual RMS, swept range and the inverse mapping ``correct``.

    Raises
    ------
    blf.errors.InputError
        Bad shapes, NaN/inf, fewer than 50 samples, a bad ``degree`` or a
        swept range shorter than ``min_span_mm``.
    blf.errors.AnalysisError
        If the regression is rank deficient.

    Notes
    -----
    Model (ordinary least squares, Gaussian LVDT noise :math:`e` in mm):

    .. math::

        s = c_0 + c_1 x + c_2 x^2 + c_3 x^3 + e \\qquad [mm]

    For conditioning the regression is solved in the centred, scaled variable
    :math:`u = (x - x_c) / x_h \\in [-1, 1]` (``x_c``, ``x_h`` centre and half
    span of the sweep) by a QR-based least-squares solve; the coefficients
    and their covariance :math:`\\hat\\sigma^2 (V^T V)^{-1}` are then mapped
    linearly to the power basis in :math:`x`. ``pitch`` is
    :math:`P'(0) = c_1` (the paper's 1.075), ``offset_mm`` is :math:`c_0`.
    ``nonlinearity_mm`` is :math:`\\max |P(x) - (a + b x)|` over the sweep with
    :math:`a + b x` the least-squares line through :math:`P` on a uniform grid;
    for a pure cubic term :math:`c_3 x^3` on :math:`[-L, L]` it equals
    :math:`0.4\\,c_3 L^3`. ``rmse_mm`` is :math:`\\sqrt{RSS / n}`.

    During the sweep the internal deflection :math:`d` is constant, so the
    true stroke is :math:`x - d`; :math:`d` only shifts :math:`c_0` and the
    corrected strokes by a constant, which cancels in backlash and stiffness.
    """
    x, s, degree, x_min, x_max = _checked_sweep(x_mm, s_mm, degree, min_span_mm)
    coeffs, cov, rss = _power_basis_fit(x, s, degree, x_min, x_max)
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    coeff_t = tuple(float(c) for c in coeffs)
    return LvdtCalibration(
        coefficients=coeff_t,
        coefficient_sigmas=tuple(float(v) for v in sig),
        degree=degree,
        pitch=float(coeffs[1]),
        offset_mm=float(coeffs[0]),
        nonlinearity_mm=_nonlinearity_mm(coeff_t, x_min, x_max),
        rmse_mm=float(np.sqrt(rss / x.size)),
        x_min_mm=x_min,
        x_max_mm=x_max,
        n=int(x.size),
        monotone=_is_strictly_monotone(coeff_t, x_min, x_max),
    )


def _checked_sweep(x_mm, s_mm, degree, min_span_mm) -> tuple[np.ndarray, np.ndarray, int, float, float]:
    """The sweep (x, s in mm), the degree and the swept range (mm), validated in that order."""
    x = as_1d_finite(x_mm, "x_mm", "mm")
    s = as_1d_finite(s_mm, "s_mm", "mm")
    same_shape((x, "x_mm", "mm"), (s, "s_mm", "mm"))
    degree = count(degree, "degree", 1, 5)
    if x.size < 50:
        raise InputError(
            f"x_mm and s_mm must have at least 50 samples (mm); got shape {x.shape}"
        )
    span_min = scalar(min_span_mm, "min_span_mm", "mm")
    x_min, x_max = float(np.min(x)), float(np.max(x))
    if not (x_max - x_min >= span_min and x_max > x_min):
        raise InputError(
            f"x_mm must span at least {span_min:g} mm (a full-stroke sweep); got range "
            f"{x_max - x_min:.4g} mm in shape {x.shape}"
        )
    if np.unique(x).size < degree + 2:
        raise InputError(
            f"x_mm needs at least {degree + 2} distinct values (mm) for degree {degree}; "
            f"got {np.unique(x).size} in shape {x.shape}"
        )
    return x, s, degree, x_min, x_max


def _power_basis_fit(x: np.ndarray, s: np.ndarray, degree: int, x_min: float, x_max: float
                     ) -> tuple[np.ndarray, np.ndarray, float]:
    """Least squares in the centred, scaled variable u (QR), mapped to the power basis in x:
    coefficients, their covariance and the residual sum of squares (mm^2). Refused when rank deficient."""
    n = x.size
    p = degree + 1
    x_c = 0.5 * (x_min + x_max)
    x_h = 0.5 * (x_max - x_min)
    u = (x - x_c) / x_h
    vander = np.vander(u, p, increasing=True)
    q_mat, r_mat = np.linalg.qr(vander)
    diag = np.abs(np.diag(r_mat))
    if diag.min() <= 1e-10 * diag.max():
        raise AnalysisError(
            f"LVDT calibration regression of degree {degree} is rank deficient for the "
            f"{n} samples given (x_mm range {x_min:.3f}..{x_max:.3f} mm)"
        )
    a_scaled = np.linalg.solve(r_mat, q_mat.T @ s)
    resid = s - vander @ a_scaled
    rss = float(resid @ resid)
    dof = n - p
    sigma2 = rss / dof
    r_inv = np.linalg.inv(r_mat)
    cov_scaled = sigma2 * (r_inv @ r_inv.T)

    # map u-basis coefficients to x-power-basis coefficients: c = T a
    t_mat = np.zeros((p, p))
    for k in range(p):
        for j in range(k + 1):
            t_mat[j, k] = comb(k, j) * (-x_c) ** (k - j) / x_h**k
    return t_mat @ a_scaled, t_mat @ cov_scaled @ t_mat.T, rss


def _nonlinearity_mm(coeffs: tuple, x_min: float, x_max: float) -> float:
    """max |P(x) - (a + b x)| over the sweep, a + b x the least-squares line through P on a uniform grid."""
    grid = np.linspace(x_min, x_max, _GRID_POINTS)
    p_grid = _polyval(coeffs, grid)
    line = np.polynomial.polynomial.polyfit(grid, p_grid, 1)
    return float(np.max(np.abs(p_grid - (line[0] + line[1] * grid))))


def correct_linear(s_mm, pitch: float, offset_mm: float) -> np.ndarray:
    """Map LVDT readings onto the motor-angle scale with a linear calibration.

    Parameters
    ----------
    s_mm : array_like
        Raw LVDT readings, mm, any shape.
    pitch : float
        LVDT pitch ``ds/dx`` (dimensionless, > 0; 1.075 for a reading 7.5 % high).
    offset_mm : float
        LVDT reading at ``x = 0``, mm.

    Returns
    -------
    ndarray
        ``x`` in mm, same shape as ``s_mm``.

    Raises
    ------
    blf.errors.InputError
        NaN/inf readings, a pitch that is not a finite number > 0, a
        non-finite offset.

    Notes
    -----
    The inverse of the straight line :math:`s = o + p\\,x` (the first two
    terms of :class:`LvdtCalibration`, as result.json carries them):

    .. math:: x = (s - o) / p \\quad [mm]
    """
    s = as_finite(s_mm, "s_mm", "mm")
    p = positive_scalar(pitch, "pitch", "(dimensionless)")
    o = scalar(offset_mm, "offset_mm", "mm")
    return (s - o) / p


# --------------------------------------------------------------------------
# private helpers
# --------------------------------------------------------------------------


def _polyval(coeffs, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Horner evaluation of ``sum_k coeffs[k] * x**k`` (into ``out`` when given: no temporaries)."""
    if out is None:
        out = np.full_like(x, coeffs[-1], dtype=np.float64)
    else:
        out.fill(coeffs[-1])
    for c in coeffs[-2::-1]:
        out *= x
        out += c
    return out


def _polyder(coeffs) -> tuple:
    return tuple(k * c for k, c in enumerate(coeffs))[1:] or (0.0,)


def _is_strictly_monotone(coeffs, x_min: float, x_max: float) -> bool:
    """Exact check: P evaluated at the ends and at all critical points in between."""
    dcoef = np.asarray(_polyder(coeffs), dtype=np.float64)
    pts = [x_min, x_max]
    nz = np.flatnonzero(dcoef)
    if nz.size == 0:
        return False  # constant polynomial
    trimmed = dcoef[: nz[-1] + 1]
    if trimmed.size > 1:
        roots = np.polynomial.polynomial.polyroots(trimmed)
        real = roots[np.abs(roots.imag) <= 1e-9 * (1.0 + np.abs(roots.real))].real
        pts.extend(r for r in real if x_min < r < x_max)
    pts = np.sort(np.asarray(pts))
    vals = _polyval(coeffs, pts)
    dv = np.diff(vals)
    return bool(np.all(dv > 0.0) or np.all(dv < 0.0))


def _invert_monotone(coeffs, s: np.ndarray, x_min: float, x_max: float) -> np.ndarray:
    """Solve P(x) = s for x on a monotone range; linear extrapolation outside."""
    dcoef = _polyder(coeffs)
    s_flat = s.reshape(-1)
    p_lo = float(_polyval(coeffs, np.array(x_min)))
    p_hi = float(_polyval(coeffs, np.array(x_max)))
    direction = 1.0 if p_hi > p_lo else -1.0
    # work on the increasing polynomial direction*P
    t = s_flat if direction > 0 else -s_flat  # 1.0 * s is s: no copy
    t_lo, t_hi = direction * p_lo, direction * p_hi
    x = np.empty_like(s_flat)

    below = t < t_lo
    above = t > t_hi
    inside = ~(below | above)
    if np.any(below):
        slope = float(_polyval(dcoef, np.array(x_min)))
        x[below] = x_min + (s_flat[below] - p_lo) / slope
    if np.any(above):
        slope = float(_polyval(dcoef, np.array(x_max)))
        x[above] = x_max + (s_flat[above] - p_hi) / slope
    del below, above
    if np.any(inside):
        rng = (x_min, x_max, t_lo, t_hi, max(abs(p_lo), abs(p_hi), 1.0))
        _solve_inside(coeffs, dcoef, direction, t, inside, x, rng)
    return x.reshape(s.shape)


#: readings solved at a time by :func:`_solve_inside` (the iteration's buffers are this long, not the recording)
_CHUNK = 1 << 18
_MAX_ITER = 200


def _solve_inside(coeffs, dcoef, direction: float, t: np.ndarray, inside: np.ndarray, x: np.ndarray,
                  rng: tuple) -> None:
    """``x[inside]`` from the bracketed Newton iteration, chunk by chunk, bit-identical to one iteration
    over all of them (issue 34: that one held a dozen arrays the length of the recording).

    Each reading's iterates depend on that reading alone; only the number of steps is common: the
    iteration stops at the first step k where every reading is final (|P(x) - s| at round-off), or
    after the first step where no reading moved more than the tolerance. A chunk whose readings are
    all final stays as it is. So: each chunk is iterated until all its readings are final (recording,
    per step, whether all were final and whether none moved); the common number of steps follows from
    those records; a chunk that took more steps than that (rare) is iterated again for exactly that many.
    """
    bounds = [(a, min(a + _CHUNK, t.size)) for a in range(0, t.size, _CHUNK)]
    records = []
    for a, b in bounds:
        m = inside[a:b]
        if not m.any():
            records.append(None)
            continue
        xi, final_at, small = _newton(coeffs, dcoef, direction, t[a:b][m], *rng, _MAX_ITER)
        x[a:b][m] = xi
        records.append((final_at, small))
    steps = _common_steps([r for r in records if r is not None])
    for (a, b), rec in zip(bounds, records, strict=True):
        if rec is not None and len(rec[1]) > steps:
            m = inside[a:b]
            x[a:b][m] = _newton(coeffs, dcoef, direction, t[a:b][m], *rng, steps)[0]


def _common_steps(records: list) -> int:
    """The number of steps one iteration over all the chunks would take (see :func:`_solve_inside`):
    ``records`` per chunk (final_at, small), ``final_at`` the step at which all its readings were final
    (None: not within the steps it ran), ``small[k]`` whether no reading moved beyond tolerance in step k."""
    for k in range(_MAX_ITER):
        if all(fa is not None and fa <= k for fa, _ in records):
            return k
        if all((fa is not None and fa <= k) or sm[k] for fa, sm in records):
            return k + 1
    return _MAX_ITER


def _newton(coeffs, dcoef, direction: float, ti: np.ndarray, x_min: float, x_max: float, t_lo: float, t_hi: float,
            s_scale: float, max_iter: int) -> tuple[np.ndarray, int | None, list]:
    """The bracketed Newton iteration of :func:`_invert_monotone` on readings inside the range, for at most
    ``max_iter`` steps or until all are final (written into preallocated buffers). Returns x, the step at
    which all were final (None if not) and, per step taken, whether no reading moved beyond tolerance."""
    xi = x_min + (ti - t_lo) / (t_hi - t_lo) * (x_max - x_min)
    lo = np.full(ti.shape, x_min)
    hi = np.full(ti.shape, x_max)
    scale = max(abs(x_min), abs(x_max), 1.0)
    tol_f = 1e-14 * s_scale
    f = np.empty_like(ti)
    xn = np.empty_like(ti)
    small = []
    for k in range(max_iter):
        _polyval(coeffs, xi, out=f)
        f *= direction
        f -= ti
        # an element whose residual is already small is final: stepping it again
        # could move it (Newton step below the bracket's resolution -> bisection)
        done = np.abs(f) <= tol_f
        if np.all(done):
            return xi, k, small
        pos = f > 0.0
        np.copyto(hi, xi, where=pos)
        np.invert(pos, out=pos)
        np.copyto(lo, xi, where=pos)
        del pos
        _polyval(dcoef, xi, out=xn)
        xn *= direction
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(f, xn, out=xn)
        np.subtract(xi, xn, out=xn)  # xi - f / P'(xi)
        bad = ~np.isfinite(xn)
        bad |= xn < lo
        bad |= xn > hi
        np.add(lo, hi, out=f)
        f *= 0.5
        np.copyto(xn, f, where=bad)
        del bad
        np.copyto(xn, xi, where=done)
        np.subtract(xn, xi, out=f)
        np.abs(f, out=f)
        xi, xn = xn, xi
        small.append(bool(np.all(f <= 1e-14 * scale)))
    return xi, None, small
