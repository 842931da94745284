"""Default relevance floors of the dual-EMA model's nominal parameters (issue 35, part 2), and how measured.

A change of a nominal parameter between two checks of one rig is to be named only when it is
statistically supported and above its floor (as :data:`hil.analysis.diagnose_axis.FORCE_FLOOR_N` for
a single axis). These are the measured defaults for the dual-EMA reference mode (``diagnose
--reference`` of a dual-EMA recording: not built yet; its floors are to be settable by a profile key or
a command-line option and stated in diagnosis.json).

Measured by ``python tests/bench/bench_diagnose_floors.py /tmp/floors.json`` (docs/diagnose.md,
"Floors of the dual-EMA model"):

* play (internal play of each EMA, um) and contact stiffness (%): the identification error of the
  nominal fit (fitted minus true) on the independent rig's effect-free recordings (null-a/b/c,
  pitch-a/b, both EMAs: 10 values): sd 0.12 um and 0.14 %; a change between two checks carries two
  such errors, floor 3 sqrt(2) sd = 0.52 um and 0.59 %, rounded up;
* sensor gain (LVDT pitch, %): the same recordings, sd 3.6e-4 %: 3 sqrt(2) sd = 1.5e-3 %, rounded up;
* friction (hinge and drive Coulomb friction, N): no truth for it in the independent rig's keys; two
  healthy simulated checks of the shipped rig with noise seeds 11 and 12 (``emacheck simulate``): the
  changes -0.078 and -0.124 N, 3 x RMS = 0.31 N, rounded up (one pair: provisional).

All from simulated rigs, which have no session-to-session change (temperature, re-assembly): on a real
rig the spread between checks is larger (the Cranfield actuator: 50 N between sessions against a
statistical uncertainty of 3-8 N), so these are lower bounds; a rig's own repeatability is to be stated.
"""

from __future__ import annotations

#: kind -> default floor in its unit (play um, stiffness %, sensor gain %, friction N)
DUAL_FLOORS = {"play_um": 0.6, "stiffness_pct": 0.6, "sensor_gain_pct": 0.002, "friction_N": 0.35}
