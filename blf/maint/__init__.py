"""BLFmaint, the ground check (paper 2.1, 2.3): backlash and stiffness from force against position difference.

Offers, by module:

* :mod:`~blf.maint.blfmaint`: :func:`blf_maint` (the F-D analysis of one relation), ``MIN_SAMPLES``;
  its results in :mod:`~blf.maint.results` (:class:`BlfMaintResult`, :class:`ContactLine`,
  :class:`CentreLine`, :class:`FdLines`, :class:`BinnedCurve`); the contact and backlash regions it
  finds in :mod:`~blf.maint.regions` (internal);
* :mod:`~blf.maint.calibration`: :func:`fit_lvdt_calibration` (LVDT stroke on motor angle under
  opposing force: pitch, offset, non-linearity), :class:`LvdtCalibration`, :func:`correct_linear`;
* :mod:`~blf.maint.segments`: the check's phases found in the data (:func:`find_segments`,
  :func:`find_sweep`, :class:`Segments`, :func:`trim`, :func:`runs`, :func:`smooth_speed`);
* :mod:`~blf.maint.accuracy`: the error budget of paper 2.3 (:func:`backlash_error_budget`,
  :class:`AccuracyBudget`, :class:`MethodErrors`), for BLFmaint and BLFserv;
* :mod:`~blf.maint.verdict`: the decision against B_spec, guard-banded by U (k = 2, ISO 14253-1):
  :func:`decide`, :func:`overall`, :func:`maint_uncertainty`, :func:`serv_uncertainty`,
  :class:`ChannelVerdict`, :class:`UncertaintyBudget`, :func:`combine`, ``COVERAGE_FACTOR``.

Uses :mod:`blf.serv` (the BLFserv filters, for the error budget) and blf's five modules.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(__name__, submod_attrs={
    "blfmaint": ["MIN_SAMPLES", "blf_maint"],
    "results": ["BinnedCurve", "BlfMaintResult", "CentreLine", "ContactLine", "FdLines"],
    "calibration": ["LvdtCalibration", "fit_lvdt_calibration", "correct_linear"],
    "segments": ["Segments", "runs", "smooth_speed", "trim", "find_segments", "find_sweep"],
    "accuracy": ["MethodErrors", "AccuracyBudget", "backlash_error_budget"],
    "verdict": ["COVERAGE_FACTOR", "UncertaintyBudget", "ChannelVerdict", "combine", "maint_uncertainty",
                "serv_uncertainty", "decide", "overall"],
})
