"""Default relevance floors of ``emacheck diagnose --reference`` with the dual-EMA model, and how measured.

The check profile's ``[diagnosis]`` table (:class:`hil.profile.config.DiagnosisFloors`) takes these as its
defaults; the diagnosis reads the floors from the profile (:mod:`hil.analysis.diagnose.floors`).

A change of a nominal parameter between two checks of one rig is to be named only when it is
statistically supported and above its floor (as :data:`hil.analysis.diagnose.single_axis.FORCE_FLOOR_N` for
a single axis). These are the defaults of the dual-EMA reference mode
(:mod:`hil.analysis.diagnose.dual_reference`; diagnosis.json ``floor.by_kind`` states the floors used); the
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
  (:func:`hil.analysis.diagnose.floors.nominal_changes`) between each pair, 3 x RMS per kind: play
  (internal, LVDT offset) 0.53 um, external play 0.80 um, contact stiffness 1.43 %, compliance 0.36 %,
  LVDT pitch 0.00096 %, friction (hinge and drives' at the check's speed; the independent rig's keys
  give no true friction) 0.34 N.

* **the library's effects at one EMA** (:data:`hil.analysis.diagnose.floors.LIBRARY_FLOORS`): each
  candidate's size parameters fitted at each EMA (and variant) where there is none (true 0), on the
  independent rig's five effect-free recordings (pooled sd about each series' mean, 3 sqrt(2) sd) and on
  the three simulated checks (3 x RMS of the pair changes): extra friction (Coulomb, viscous at the check's
  speed, asymmetric; 16 series) 2.05 / 0.56 N, Stribeck static force 43.3 / 7.4 N, LVDT bow and S
  0.58 / 1.25 um, LVDT gain drift 0.19 / 0.34 %/h, time skew 0.078 / 0.105 ms, stiffness asymmetry
  0.40 / 0.15 % (under the contact stiffness's 1.5 %), progressive stiffness 18.4 / 15.6 %/mm,
  visco-elastic stiffness 3960 / 1400 N/mm, load cell gain 0.034 / 0.019 %.

* **own simulator in the independent rig's layout** (``--bare``: the same three checks as CSVs of
  t,phi1,phi2,s1,s2,F1,F2 only, the phases found from the data): the same comparisons vary more there:
  LVDT pitch 0.0036 %, friction at the check's speed 1.01 N, load cell gain 0.103 %, extra friction at one
  EMA 3.64 N, Stribeck 856 N, time skew 0.119 ms, progressive stiffness 24.2 %/mm, visco-elastic stiffness
  3290 N/mm (the others under the defaults below).

Defaults, the largest of the three rounded up: play 0.6 um, external play 1.3 um, contact stiffness 1.5 %,
compliance 12 %, sensor gain 0.004 %, friction 1.1 N, load cell gain 0.11 %; the library's: extra friction
at one EMA 3.7 N, Stribeck 860 N (a check at one speed barely determines it), LVDT bow and S 1.3 um, LVDT
drift 0.35 %/h, time skew 0.12 ms, progressive stiffness 25 %/mm, visco-elastic stiffness 4000 N/mm. All
from rig models, which have no session-to-session change (temperature, re-assembly): on a real rig the
spread between checks is larger (the Cranfield actuator: 50 N between sessions against a statistical
uncertainty of 3-8 N), so these are lower bounds; a rig's own repeatability is to be stated.
"""

from __future__ import annotations

#: kind -> default floor in its unit (play um, stiffness and compliance %, sensor gain %, friction N)
DUAL_FLOORS = {"play_um": 0.6, "external_play_um": 1.3, "stiffness_pct": 1.5, "compliance_pct": 12.0,
               "sensor_gain_pct": 0.004, "friction_N": 1.1, "loadcell_gain_pct": 0.11,
               # the library's effects at one EMA (hil.analysis.diagnose.floors.LIBRARY_FLOORS)
               "ema_friction_N": 3.7, "stribeck_N": 860.0, "lvdt_linearity_um": 1.3, "lvdt_drift_pct_per_h": 0.35,
               "time_skew_ms": 0.12, "progressive_pct_per_mm": 25.0, "viscoelastic_N_per_mm": 4000.0}
