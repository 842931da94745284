"""The diagnosis: where a model and a recording differ, which physics was left out, its fit.

Offers, by module:

* :mod:`~blf.diagnose.model`: the vocabulary a replay model speaks and the result (:class:`ReplayModel`,
  :class:`Param`, :class:`ParamVector`, :class:`Candidate`, :class:`Reference`, :class:`DiagnoseConfig`,
  :class:`Diagnosis`, :class:`FittedEffect`, :class:`Location`, :class:`DiagnosisVerdict`,
  :class:`NominalCovariance`, :func:`place_of`);
* :mod:`~blf.diagnose.engine`: :func:`diagnose` (band, nominal fit, noise floor, mismatch tests,
  library screening and refits, verdict), :func:`fit_effect` (one candidate fitted for a comparison
  of two recordings), :func:`band_comparison`; steps 4-6 in :mod:`~blf.diagnose.selection`, the step
  records in :mod:`~blf.diagnose.records`, the fitting machinery in :mod:`~blf.diagnose.fit`
  (:func:`safe_predict`), the band in :mod:`~blf.diagnose.band`, the mismatch tests in
  :mod:`~blf.diagnose.mismatch`;
* :mod:`~blf.diagnose.covariance`: :func:`nominal_covariance` (what a recording can separate);
* :mod:`~blf.diagnose.phases`: the phases a replay holds or skips (:func:`holding`, :func:`transients`,
  :func:`mode_changes`, :func:`segment_changes`, :func:`slack`, :func:`change_mask`, :class:`Holding`);
* :mod:`~blf.diagnose.axis_reference`: a single axis against a reference recording (:func:`effort_mask`,
  :func:`identifiability`, :func:`fit_axis`, :func:`compare_fits`, ...); its effort as a force in
  :mod:`~blf.diagnose.axis_effort` (:func:`effort_to_force`, :func:`identify_current_per_force`,
  :func:`effort_load_check`); the whole comparison of two recordings in one step in
  :mod:`~blf.diagnose.axis_compare` (:func:`compare_axis`, :class:`AxisSamples`, :class:`AxisComparison`);
* :mod:`~blf.diagnose.periodic`: forces periodic in position found from a residual against position
  (:func:`search_range`, :func:`find_periods`, :func:`periodic_columns`, :func:`locality`,
  :func:`lead_order`); their comparison against a reference in :mod:`~blf.diagnose.axis_periodic`.

Uses :mod:`blf.maint` (the check's segments) and blf's five modules.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(__name__, submod_attrs={
    "model": ["Param", "ParamVector", "Candidate", "Reference", "ReplayModel", "DiagnoseConfig", "Location",
              "FittedEffect", "Diagnosis", "DiagnosisVerdict", "RegimeScore", "NominalCovariance", "EIGEN_FLOOR",
              "place_of"],
    "engine": ["band_comparison", "diagnose", "fit_effect"],
    "fit": ["safe_predict"],
    "covariance": ["nominal_covariance"],
    "phases": ["Holding", "slack", "change_mask", "mode_changes", "segment_changes", "holding", "transients"],
    "axis_reference": ["EffortMask", "Identifiability", "AxisFit", "ParameterChange", "effort_mask",
                       "axis_kinematics", "identifiability", "fit_axis", "compare_fits", "design_columns",
                       "separable", "stroke_terms", "STROKE_TERMS", "NOMINAL_UNITS"],
    "axis_effort": ["CurrentGain", "EffortCheck", "effort_to_force", "identify_current_per_force",
                    "effort_load_check", "LAWS"],
    "axis_compare": ["AxisSamples", "AxisComparison", "compare_axis", "common_terms", "stroke_candidates",
                     "axis_floors"],
    "periodic": ["PeriodSearch", "PeriodFound", "Locality", "LeadOrder", "search_range", "amplitude_spectrum",
                 "find_periods", "periodic_columns", "periodic_amplitudes", "locality", "lead_order", "column_name",
                 "SAMPLES_PER_PERIOD", "FALSE_ALARM", "MIN_PERIODS", "DIRECTIONS"],
    "axis_periodic": ["AxisPeriodic", "PeriodicChange", "PeriodicPlan", "periodic_pair", "compare_periodic",
                      "axis_residual", "directions", "profile"],
})
