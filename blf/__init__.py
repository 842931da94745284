"""Pure backlash analysis: BLFmaint, BLFserv, LVDT calibration, error budget (paper 2.1-2.3).

Everything here is pure: arrays and explicit sample rates in, frozen
dataclasses out; no plotting, logging, file IO or clocks.
"""

import importlib

#: Public name -> submodule. Imported on first use (PEP 562): ``from blf.calibration import ...``
#: in the master's process does not pull in python-control, scipy.signal and numba (BLFserv),
#: which cost seconds at start-up where page faults are expensive (user-mode-linux).
_WHERE = {
    "AccuracyBudget": "accuracy", "MethodErrors": "accuracy", "backlash_error_budget": "accuracy",
    "LvdtCalibration": "calibration", "correct_linear": "calibration", "fit_lvdt_calibration": "calibration",
    "BinnedCurve": "maint", "BlfMaintResult": "maint", "CentreLine": "maint", "ContactLine": "maint",
    "FdLines": "maint", "blf_maint": "maint",
    "BlfServMonitor": "serv", "BlfServResult": "serv", "ServJump": "serv", "blf_serv": "serv",
    "ServFilters": "serv_filters", "design_serv_filters": "serv_filters", "estimate_noise_std_mm": "serv_filters",
    "Segments": "segments", "find_segments": "segments", "find_sweep": "segments",
    "PositionDifferences": "signals", "position_differences": "signals",
}


def __getattr__(name: str):
    try:
        mod = _WHERE[name]
    except KeyError:
        raise AttributeError(f"module 'blf' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"blf.{mod}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


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
    "correct_linear",
    "fit_lvdt_calibration",
    "position_differences",
    "Segments",
    "find_segments",
    "find_sweep",
]
