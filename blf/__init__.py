"""Pure backlash analysis: BLFmaint, BLFserv, LVDT calibration, error budget (paper 2.1-2.3).

Everything here is pure: arrays and explicit sample rates in, frozen
dataclasses out; no plotting, logging, file IO or clocks.
"""

from .accuracy import AccuracyBudget, MethodErrors, backlash_error_budget
from .calibration import LvdtCalibration, fit_lvdt_calibration
from .maint import (
    BinnedCurve,
    BlfMaintResult,
    CentreLine,
    ContactLine,
    FdLines,
    blf_maint,
)
from .serv import (
    BlfServMonitor,
    BlfServResult,
    ServFilters,
    ServJump,
    blf_serv,
    design_serv_filters,
    estimate_noise_std_mm,
)
from .signals import PositionDifferences, position_differences

__all__ = [
    "AccuracyBudget",
    "BinnedCurve",
    "BlfServMonitor",
    "BlfServResult",
    "MethodErrors",
    "ServFilters",
    "ServJump",
    "backlash_error_budget",
    "blf_serv",
    "design_serv_filters",
    "estimate_noise_std_mm",
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
