"""Pure BLFmaint analysis and LVDT calibration (paper sections 2.1 and 2.3).

Everything here is pure: arrays and explicit sample rates in, frozen
dataclasses out; no plotting, logging, file IO or clocks.
"""

from .calibration import LvdtCalibration, fit_lvdt_calibration
from .maint import (
    BinnedCurve,
    BlfMaintResult,
    CentreLine,
    ContactLine,
    FdLines,
    blf_maint,
)
from .signals import PositionDifferences, position_differences

__all__ = [
    "BinnedCurve",
    "BlfMaintResult",
    "CentreLine",
    "ContactLine",
    "FdLines",
    "LvdtCalibration",
    "PositionDifferences",
    "blf_maint",
    "fit_lvdt_calibration",
    "position_differences",
]
