"""What BLFmaint gives (:func:`blf.maint.blfmaint.blf_maint`): its three regression lines, the binned
F-D curve and the result, as frozen dataclasses (units in every name: D in mm, F in N).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BinnedCurve", "BlfMaintResult", "CentreLine", "ContactLine", "FdLines"]


@dataclass(frozen=True)
class ContactLine:
    """Regression line of one contact (elastic) region, D regressed on F.

    Model ``D = d_at_zero_force_mm + compliance_mm_per_N * F`` (original sign
    of F). Units: D in mm, F in N.

    Attributes
    ----------
    side : str
        ``"left"`` (smaller D) or ``"right"``.
    d_at_zero_force_mm : float
        D of the line at F = 0, mm.
    compliance_mm_per_N : float
        dD/dF of the line, mm/N (negative for a negative F-D slope).
    cov : ndarray, shape (2, 2)
        Covariance of ``(d_at_zero_force_mm, compliance_mm_per_N)``
        (units mm**2, mm**2/N, mm**2/N**2), heteroscedasticity and
        autocorrelation consistent (Newey-West).
    n : int
        Samples used.
    f_min_N, f_max_N : float
        Force range of the samples used, N.
    rmse_mm : float
        RMS residual in D, mm.
    """

    side: str
    d_at_zero_force_mm: float
    compliance_mm_per_N: float
    cov: np.ndarray
    n: int
    f_min_N: float
    f_max_N: float
    rmse_mm: float

    def d_mm(self, f_N) -> np.ndarray:
        """D on the line for forces ``f_N`` (N), in mm."""
        return self.d_at_zero_force_mm + self.compliance_mm_per_N * np.asarray(f_N, dtype=float)

    def f_N(self, d_mm) -> np.ndarray:
        """F on the line for differences ``d_mm`` (mm), in N."""
        return (np.asarray(d_mm, dtype=float) - self.d_at_zero_force_mm) / self.compliance_mm_per_N


@dataclass(frozen=True)
class CentreLine:
    """Line of the backlash (centre) region, F on D.

    Model ``F = f_at_zero_d_N + slope_N_per_mm * D`` (original sign of F). By
    default the free play is fitted as a level (``slope_N_per_mm = 0``, F is
    the mean force in the backlash); with ``blf_maint(..., centre_slope=True)``
    it is the paper's regression line.

    Attributes
    ----------
    f_at_zero_d_N : float
        F of the line at D = 0, N.
    slope_N_per_mm : float
        dF/dD of the line in the backlash, N/mm (0 for a level).
    cov : ndarray, shape (2, 2)
        Covariance of ``(f_at_zero_d_N, slope_N_per_mm)`` (Newey-West; only
        the first entry is non-zero for a level).
    n : int
        Samples used.
    d_min_mm, d_max_mm : float
        D range of the samples used, mm.
    rmse_N : float
        RMS residual in F, N.
    """

    f_at_zero_d_N: float
    slope_N_per_mm: float
    cov: np.ndarray
    n: int
    d_min_mm: float
    d_max_mm: float
    rmse_N: float

    def f_N(self, d_mm) -> np.ndarray:
        """F on the line for differences ``d_mm`` (mm), in N."""
        return self.f_at_zero_d_N + self.slope_N_per_mm * np.asarray(d_mm, dtype=float)


@dataclass(frozen=True)
class FdLines:
    """The three regression lines and their intersections (paper Figure 5).

    Attributes
    ----------
    left, right : ContactLine
        Contact regions at smaller and larger D.
    centre : CentreLine
        Backlash region.
    d_left_mm, f_left_N : float
        Intersection of ``left`` and ``centre`` (mm, N).
    d_right_mm, f_right_N : float
        Intersection of ``centre`` and ``right`` (mm, N).
    """

    left: ContactLine
    centre: CentreLine
    right: ContactLine
    d_left_mm: float
    f_left_N: float
    d_right_mm: float
    f_right_N: float


@dataclass(frozen=True)
class BinnedCurve:
    """The F-D relation binned along D and its slope (paper Figure 4).

    Attributes
    ----------
    d_mm : ndarray, shape (m,)
        Median low-passed D of each populated bin, mm (increasing).
    f_N : ndarray, shape (m,)
        Median low-passed F of each bin, N (original sign).
    dfdd_N_per_mm : ndarray, shape (m,)
        Slope dF/dD of the binned curve (local linear fit over
        ``2*slope_window_bins + 1`` bins, then a 3-point running median),
        N/mm, original sign.
    count : ndarray of int, shape (m,)
        Samples per bin.
    bin_width_mm : float
        Bin width used, mm: the requested one, narrowed to 1/40 of the D
        range when that is smaller.
    threshold_N_per_mm : float
        Slope level drawn between contact and backlash in the figure: half
        the softer fitted contact stiffness, N/mm, original sign. (The
        regions are found from the force, not from this level.)
    """

    d_mm: np.ndarray
    f_N: np.ndarray
    dfdd_N_per_mm: np.ndarray
    count: np.ndarray
    bin_width_mm: float
    threshold_N_per_mm: float


@dataclass(frozen=True)
class BlfMaintResult:
    """Backlash and stiffness of one F-D relation (BLFmaint).

    Attributes
    ----------
    backlash_mm, backlash_sigma_mm : float
        Backlash ``B = d_right - d_left`` between the line intersections and
        its standard uncertainty, mm.
    stiffness_left_N_per_mm, stiffness_left_sigma_N_per_mm : float
        Contact stiffness magnitude ``|dF/dD|`` of the left region (smaller D)
        and its standard uncertainty, N/mm. For an internal relation
        (``slope_sign = -1``) left is compression (F > 0); for the external
        relation (``+1``) left is F < 0.
    stiffness_right_N_per_mm, stiffness_right_sigma_N_per_mm : float
        Same for the right region (larger D), N/mm.
    slope_sign : int
        Global sign of dF/dD: -1 (F decreases with D) or +1.
    d_lc_mm, d_rc_mm : float
        Left and right corners: D of the left and right contact line at the
        force level of the backlash, mm (the ends of the backlash region).
    dfdd_median : float
        Median of the binned slope dF/dD over the populated bins, N/mm,
        original sign (the paper's reference level, reported for Figure 4;
        not used to find the regions).
    lines : FdLines
        The three regression lines and their intersections.
    curve : BinnedCurve
        Binned F-D curve and its slope.
    n_left, n_centre, n_right : int
        Samples used by the three regressions.
    mask_left, mask_centre, mask_right : ndarray of bool, shape (n,)
        Which input samples each regression used.
    """

    backlash_mm: float
    backlash_sigma_mm: float
    stiffness_left_N_per_mm: float
    stiffness_left_sigma_N_per_mm: float
    stiffness_right_N_per_mm: float
    stiffness_right_sigma_N_per_mm: float
    slope_sign: int
    d_lc_mm: float
    d_rc_mm: float
    dfdd_median: float
    lines: FdLines
    curve: BinnedCurve
    n_left: int
    n_centre: int
    n_right: int
    mask_left: np.ndarray
    mask_centre: np.ndarray
    mask_right: np.ndarray
