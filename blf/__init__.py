"""Pure backlash analysis (paper 2.1-2.3): arrays and explicit sample rates in, frozen dataclasses out.

No plotting, logging, file IO or clocks. Three wings, one per method, each behind its door (its
``__init__``, which lists what it offers):

* :mod:`blf.maint`: BLFmaint, the ground check (paper 2.1): the force-fight F-D analysis, the LVDT
  calibration, the check's segments, the error budget (paper 2.3) and the verdict against B_spec;
* :mod:`blf.serv`: BLFserv, backlash in service from motor angle and LVDT only (paper 2.2): the
  detector and its filters;
* :mod:`blf.diagnose`: a model against a recording: where they differ, which physics was left out,
  its fit; the dual-EMA engine and the single-axis reference comparison.

Under all three, five modules: :mod:`blf.errors`, :mod:`blf.validate` (argument checks naming the
bad value and its unit), :mod:`blf.signals` (the position differences, paper eq. 1),
:mod:`blf.continuity` (jumps in a recording) and :mod:`blf.wear` (backlash against flight hours).

Wings use one another downward only: diagnose may use maint and serv, maint may use serv, serv
neither; the five modules use no wing (``tests/test_layers.py``). Wings are imported on first use
(``lazy_loader``, SPEC 1): ``import blf`` costs nothing, and the master's process, which takes
only the five modules, never loads python-control, scipy.signal or numba.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__, submodules=["maint", "serv", "diagnose", "errors", "validate", "signals", "continuity", "wear"])
