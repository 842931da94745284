"""Default relevance floors of the dual-EMA model's nominal parameters (issue 35, part 2), and how measured.

A change of a nominal parameter between two checks of one rig is to be named only when it is
statistically supported and above its floor (as :data:`hil.analysis.diagnose_axis.FORCE_FLOOR_N` for
a single axis). These are the defaults of the dual-EMA reference mode
(:mod:`hil.analysis.diagnose_dual_ref`; diagnosis.json ``floor.by_kind`` states the floors used); the
check profile's ``[diagnosis]`` keys set a rig's own (:class:`hil.profile.config.DiagnosisFloors`).

Measured by ``python tests/bench/bench_diagnose_floors.py /tmp/floors.json`` (docs/diagnose.md,
"Floors of the dual-EMA model"); each default is the larger of two measurements, rounded up:

* **independent rig** (play um, contact stiffness %, LVDT pitch %): the identification error of the
  nominal fit (fitted minus true) on its effect-free recordings (null-a/b/c, pitch-a/b, both EMAs:
  10 values): sd 0.123 um, 0.140 %, 3.7e-4 %; a change between two checks carries two such errors,
  3 sqrt(2) sd = 0.52 um, 0.59 %, 0.0016 %; the external play (the two bearing plays' sum against the
  key's one external play, 5 values): sd 0.292 um, 1.24 um; the compliance per EMA (the key's external
  stiffness is the same in every recording: the scatter about each EMA's mean, 10 values): sd 2.75 %,
  11.7 %; the load cell gain (library candidate ``loadcell_gain`` fitted at each EMA, true 0): sd
  0.0078 %, 3 sqrt(2) sd = 0.033 %;
* **own simulator**: three healthy checks of the shipped simulated rig (``emacheck simulate``, noise
  seeds 11, 12, 13), the change of every comparison the reference mode makes
  (:func:`hil.analysis.diagnose_dual_ref.nominal_changes`) between each pair, 3 x RMS per kind: play
  (internal, LVDT offset) 0.53 um, external play 0.80 um, contact stiffness 1.43 %, compliance 0.36 %,
  LVDT pitch 0.00096 %, friction (hinge and drives' at the check's speed, and the library's Coulomb
  friction in the drive of each EMA; the independent rig's keys give no true friction) 0.62 N, load cell
  gain (the library's ``loadcell_gain`` at each EMA) 0.019 %.

Defaults: play 0.6 um, external play 1.3 um, contact stiffness 1.5 %, compliance 12 %, sensor gain
0.002 %, friction 0.9 N (kept from the first measurement, 0.88 N of the Coulomb frictions alone; the
frictions at the check's speed now give 0.62 N: not lowered on one simulator's three checks), load cell
gain 0.04 %. All from rig models, which have no session-to-session change (temperature, re-assembly):
on a real rig the spread between checks is larger (the Cranfield actuator: 50 N between sessions
against a statistical uncertainty of 3-8 N), so these are lower bounds; a rig's own repeatability is to
be stated.
"""

from __future__ import annotations

#: kind -> default floor in its unit (play um, stiffness and compliance %, sensor gain %, friction N)
DUAL_FLOORS = {"play_um": 0.6, "external_play_um": 1.3, "stiffness_pct": 1.5, "compliance_pct": 12.0,
               "sensor_gain_pct": 0.002, "friction_N": 0.9, "loadcell_gain_pct": 0.04}
