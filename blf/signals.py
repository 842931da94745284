"""Position differences of the dual-EMA actuation (paper eq. 1).

Pure functions: arrays in, frozen dataclasses out, no IO. The private
validators at the end of this module are shared by the other ``blf`` modules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.errors import InputError

__all__ = ["PositionDifferences", "position_differences"]


@dataclass(frozen=True)
class PositionDifferences:
    """Internal and external position differences of one recording.

    Attributes
    ----------
    d_int1_mm, d_int2_mm : ndarray, shape (n,)
        Internal (EMA) differences ``D_int,i = s_i - phi_i / i_total`` in mm.
    d_ext_mm : ndarray, shape (n,)
        External (surface mechanism) difference ``D_ext = s_2 - s_1`` in mm.

    The arrays are read-only.
    """

    d_int1_mm: np.ndarray
    d_int2_mm: np.ndarray
    d_ext_mm: np.ndarray


def position_differences(
    phi1_rad: np.ndarray,
    phi2_rad: np.ndarray,
    s1_mm: np.ndarray,
    s2_mm: np.ndarray,
    i_total_rad_per_mm: float,
) -> PositionDifferences:
    """Compute the internal and external position differences (paper eq. 1).

    Parameters
    ----------
    phi1_rad, phi2_rad : array_like, shape (n,)
        Motor angles of EMA 1 and 2 in rad (positive = ram extends).
    s1_mm, s2_mm : array_like, shape (n,)
        LVDT strokes of EMA 1 and 2 in mm (calibrated, i.e. on the motor-angle
        scale, see :meth:`blf.calibration.LvdtCalibration.correct`).
    i_total_rad_per_mm : float
        Total gear ratio motor angle per ram stroke in rad/mm (> 0), e.g.
        ``2*pi*4/5 = 5.0265`` for a 4:1 gearbox and a 5 mm ballscrew lead.

    Returns
    -------
    PositionDifferences
        ``d_int1_mm``, ``d_int2_mm`` and ``d_ext_mm``, each shape (n,), in mm.

    Raises
    ------
    hil.errors.InputError
        If the arrays are not 1-D, differ in shape, are empty or not finite, or
        if ``i_total_rad_per_mm`` is not a finite positive number.

    Notes
    -----
    Paper eq. (1):

    .. math::

        D_{int,i} = s_i - \\frac{\\varphi_i}{i_{total}} \\quad [mm], \\qquad
        D_{ext} = s_2 - s_1 \\quad [mm]

    with :math:`\\varphi_i` in rad, :math:`s_i` in mm and :math:`i_{total}` in
    rad/mm. ``D_int`` is the deflection of the internal load path (gear,
    ballscrew) including its backlash; in compression (``F > 0``) the ram lags
    the motor, so ``D_int`` decreases with increasing force.

    Examples
    --------
    >>> import numpy as np
    >>> pd = position_differences(np.array([5.0265]), np.array([0.0]),
    ...                           np.array([1.01]), np.array([0.02]), 5.0265)
    >>> round(float(pd.d_int1_mm[0]), 6), round(float(pd.d_ext_mm[0]), 6)
    (0.01, -0.99)
    """
    phi1 = _as_1d_finite(phi1_rad, "phi1_rad", "rad")
    phi2 = _as_1d_finite(phi2_rad, "phi2_rad", "rad")
    s1 = _as_1d_finite(s1_mm, "s1_mm", "mm")
    s2 = _as_1d_finite(s2_mm, "s2_mm", "mm")
    _same_shape(
        (phi1, "phi1_rad", "rad"),
        (phi2, "phi2_rad", "rad"),
        (s1, "s1_mm", "mm"),
        (s2, "s2_mm", "mm"),
    )
    i_total = _positive_scalar(i_total_rad_per_mm, "i_total_rad_per_mm", "rad/mm")
    return PositionDifferences(
        d_int1_mm=_readonly(s1 - phi1 / i_total),
        d_int2_mm=_readonly(s2 - phi2 / i_total),
        d_ext_mm=_readonly(s2 - s1),
    )


# --------------------------------------------------------------------------
# shared private validators (used by blf.calibration and blf.maint)
# --------------------------------------------------------------------------


def _as_1d_finite(value, name: str, unit: str, *, min_len: int = 1) -> np.ndarray:
    """Return ``value`` as a float64 1-D array or raise InputError naming it."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name} must be a 1-D numeric array in {unit}; got {type(value).__name__} "
            f"that cannot be converted to float ({exc})"
        ) from None
    if arr.ndim != 1:
        raise InputError(
            f"{name} must be a 1-D array in {unit}; got shape {arr.shape}"
        )
    if arr.size < min_len:
        raise InputError(
            f"{name} must have at least {min_len} samples in {unit}; got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise InputError(
            f"{name} must be finite (in {unit}); got {bad} NaN/inf value(s) in shape {arr.shape}"
        )
    return arr


def _same_shape(*items: tuple[np.ndarray, str, str]) -> None:
    """Raise InputError unless all (array, name, unit) items share one shape."""
    ref, ref_name, ref_unit = items[0]
    for arr, name, unit in items[1:]:
        if arr.shape != ref.shape:
            raise InputError(
                f"{name} (in {unit}) must have the same shape as {ref_name} (in {ref_unit}); "
                f"got {name} shape {arr.shape} and {ref_name} shape {ref.shape}"
            )


def _positive_scalar(value, name: str, unit: str) -> float:
    """Return ``value`` as a finite positive float or raise InputError naming it."""
    if np.ndim(value) != 0 or isinstance(value, bool):
        raise InputError(
            f"{name} must be a finite positive scalar in {unit}; got {value!r} "
            f"(shape {np.shape(value)})"
        )
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(
            f"{name} must be a finite positive number in {unit}; got {value!r} "
            f"(shape {np.shape(value)})"
        ) from None
    if not np.isfinite(x) or x <= 0.0:
        raise InputError(
            f"{name} must be a finite positive number in {unit}; got {x!r} (shape ())"
        )
    return x


def _readonly(arr: np.ndarray) -> np.ndarray:
    """Return a read-only copy-owned array (for frozen result dataclasses)."""
    out = np.array(arr, copy=True)
    out.flags.writeable = False
    return out
