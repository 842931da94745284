"""Position differences of the dual-EMA actuation (paper eq. 1).

Pure functions: arrays in, frozen dataclasses out, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.validate import as_1d_finite, positive_scalar, same_shape

__all__ = ["CHANNELS", "PositionDifferences", "position_differences"]

#: The three BLF channels: EMA 1 internal, EMA 2 internal, external (paper eq. 1).
CHANNELS = ("int1", "int2", "ext")


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
        scale, see :meth:`blf.maint.calibration.LvdtCalibration.correct`).
    i_total_rad_per_mm : float
        Total gear ratio motor angle per ram stroke in rad/mm (> 0), e.g.
        ``2*pi*4/5 = 5.0265`` for a 4:1 gearbox and a 5 mm ballscrew lead.

    Returns
    -------
    PositionDifferences
        ``d_int1_mm``, ``d_int2_mm`` and ``d_ext_mm``, each shape (n,), in mm.

    Raises
    ------
    blf.errors.InputError
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
    phi1 = as_1d_finite(phi1_rad, "phi1_rad", "rad")
    phi2 = as_1d_finite(phi2_rad, "phi2_rad", "rad")
    s1 = as_1d_finite(s1_mm, "s1_mm", "mm")
    s2 = as_1d_finite(s2_mm, "s2_mm", "mm")
    same_shape(
        (phi1, "phi1_rad", "rad"),
        (phi2, "phi2_rad", "rad"),
        (s1, "s1_mm", "mm"),
        (s2, "s2_mm", "mm"),
    )
    i_total = positive_scalar(i_total_rad_per_mm, "i_total_rad_per_mm", "rad/mm")
    # s - phi / i written into the quotient's array (the same operations, one temporary less); a caller
    # that holds no other reference to s1, s2 has them freed here, as soon as they are used
    d_ext = s2 - s1
    d_int1 = np.divide(phi1, i_total)
    np.subtract(s1, d_int1, out=d_int1)
    del s1, s1_mm
    d_int2 = np.divide(phi2, i_total)
    np.subtract(s2, d_int2, out=d_int2)
    for arr in (d_int1, d_int2, d_ext):  # fresh arrays owned here: made read-only in place, not copied
        arr.flags.writeable = False
    return PositionDifferences(d_int1_mm=d_int1, d_int2_mm=d_int2, d_ext_mm=d_ext)
