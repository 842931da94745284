"""Can this recording belong to this actuation? Its forces, strokes and angles against the profile, in SI units.

A signed result must never come from a recording in other units than the file format's (issue 47): forces in
kN instead of N give the same backlash and a stiffness 1000 times too small; strokes in metres calibrate to an
LVDT pitch of 0.001 and pass. The rules here are the physics of the actuation and of the check, each bound
derived below; a rule that fails names the column and, where one fits, the unit it was likely written in.

The rules (docs/decision.md, "Plausibility against the profile"):

* **the force fight reached its level** -- its peak ``|F2 - F1| / 2`` must reach a tenth of the level the check
  commanded (``force_fight.amplitude_fraction_of_limit * limit_load_N``; a bare recording: the paper's 15 %).
  Below a tenth the excursions stay inside the backlash region plus a tenth of the intended deflection, so the
  stiffness lines BLFmaint intersects are not measured at the levels the method assumes; a unit error of 1000
  (kN) lands a hundred times below the bound, a normal check (peak ~ the commanded level) ten times above it.
  Failing: every channel inconclusive (all three read forces), naming F1 and F2 and the likely unit.
* **the two load cells read the same force fight** -- ``|F1 + F2|`` at most half the level
  (:func:`load_cells_problem` derives it: one load cell 40 % off). Failing: every channel inconclusive, naming
  the column whose unit (or sign) is likely wrong.
* **the LVDTs read the motor's stroke at the profile's scale** -- the calibrated pitch ``ds/dx`` (LVDT per
  motor-derived stroke ``x = phi / i_total``) must lie within ``1 +- HARD_LVDT_GAIN_TOLERANCE`` (10 %), the
  pitch error the supervisor tolerates during a check (the paper's LVDT has 7.5 %). Outside it but within a
  factor 2: the EMA's channels inconclusive (the LVDT or ``mechanics.i_total_rad_per_mm`` is not this
  actuation's). Beyond a factor 2 no LVDT of this kind is that wrong: a unit (m, cm, in for mm; degrees,
  revolutions, mrad for rad) or the gear ratio; the recording is refused naming the column and the unit.
  Without a calibration sweep the pitch is the slope of ``s`` over ``x`` where the ram travelled at least
  :data:`MIN_TRAVEL_FOR_SCALE_MM` (else the scale is not verifiable and a note says so).
* **the stiffness is one this actuation can have and this check can measure** -- each channel's stiffness
  lines (left and right) within ``[k_min, k_max]`` of its chain (internal: int1, int2; external: ext): stated
  in the profile (``mechanics.stiffness_int_min_N_per_mm`` .. ``stiffness_ext_max_N_per_mm``; the shipped
  profile states its design stiffness within a factor 3 either way: wear and assembly move a chain's stiffness
  by tens of per cent, the independent rig model's recordings span 66-94 kN/mm internal, while a force column
  in another unit is off by at least a factor 4.4, lbf), else derived: ``k_min = limit_load_N /
  stroke_limit_mm`` (softer, the actuation would deflect beyond its stroke under its own limit load: it could
  not carry it), ``k_max = F_ff / lvdt_noise_pp_mm`` (stiffer, the deflection under the force fight ``F_ff``
  would stay below the LVDT's peak-to-peak noise: the check cannot have measured it). Outside: that channel
  is not measured (inconclusive), naming the columns and the force unit that would bring it into the range.

A channel a rule makes inconclusive carries no reading: it is never a point of a wear trend.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.profile.config import HARD_FORCE_FIGHT_FRACTION, HARD_LVDT_GAIN_TOLERANCE, Actuation

#: the force fight must reach this fraction of its commanded level (issue 47: "a tenth")
MIN_FORCE_FIGHT_FRACTION = 0.1
#: the load cells' disagreement |F1 + F2| in the force fight, at most this times its level (load_cells_problem)
MAX_IMBALANCE_RATIO = 0.5
#: a calibrated LVDT pitch beyond this factor (either way) is a unit or a gear ratio, not an LVDT error: refused
GROSS_PITCH_FACTOR = 2.0
#: the ram travel (motor-derived, mm) over which a pitch without calibration sweep is estimated: 10 times the
#: largest internal backlash plus deflection a check sees (0.2 mm + 6000 N / 80 kN/mm = 0.275 mm), so those
#: bend the slope by at most a few per cent
MIN_TRAVEL_FOR_SCALE_MM = 3.0
#: a candidate unit is named when the observed ratio lies within this factor of its conversion factor
UNIT_MATCH_FACTOR = 1.5

#: units a column may have been written in instead of the format's: (name, value in that unit per SI value)
FORCE_UNITS = (("kN", 1e-3), ("daN", 0.1), ("kgf", 1 / 9.80665), ("lbf", 1 / 4.4482216), ("mN", 1e3))
STROKE_UNITS = (("m", 1e-3), ("cm", 0.1), ("in", 1 / 25.4), ("um", 1e3))
ANGLE_UNITS = (("degrees", 180 / math.pi), ("revolutions", 1 / (2 * math.pi)), ("mrad", 1e3))


def likely_units(ratio: float, units: tuple[tuple[str, float], ...]) -> list[str]:
    """The units whose conversion factor is within :data:`UNIT_MATCH_FACTOR` of ``ratio`` (observed/expected)."""
    if not (ratio > 0 and math.isfinite(ratio)):
        return []
    return [name for name, f in units if abs(math.log(ratio / f)) <= math.log(UNIT_MATCH_FACTOR)]


def _in(units: list[str], what: str) -> str:
    return f" ({what} in {' or '.join(units)}?)" if units else ""


@dataclass(frozen=True)
class StiffnessRange:
    """The stiffness a channel of this actuation may show [N/mm], and where the bounds come from."""

    min_N_per_mm: float
    max_N_per_mm: float
    source: str


def stiffness_range(act: Actuation, channel: str, force_fight_N: float) -> StiffnessRange:
    """``[k_min, k_max]`` of channel ``channel`` (the module docstring): the profile's statement for the
    internal (int1, int2) or external (ext) chain, else the derived bounds."""
    m = act.mechanics
    part = "ext" if channel == "ext" else "int"
    lo_stated = getattr(m, f"stiffness_{part}_min_N_per_mm")
    hi_stated = getattr(m, f"stiffness_{part}_max_N_per_mm")
    lo = lo_stated or m.limit_load_N / m.stroke_limit_mm
    hi = hi_stated or force_fight_N / act.sensors.lvdt_noise_pp_mm
    src = (f"mechanics.stiffness_{part}_min/max_N_per_mm" if lo_stated and hi_stated else
           f"derived where the profile states no mechanics.stiffness_{part}_min/max_N_per_mm: "
           "limit_load_N / stroke_limit_mm .. force-fight level / lvdt_noise_pp_mm")
    return StiffnessRange(lo, max(hi, lo), src)


def commanded_force_fight_N(act: Actuation, amplitude_fraction: float | None) -> float:
    """The force-fight level the check commanded [N]: its profile's fraction of F_limit, else the paper's 15 %."""
    frac = HARD_FORCE_FIGHT_FRACTION if amplitude_fraction is None else amplitude_fraction
    return frac * act.mechanics.limit_load_N


def force_fight_problem(F1: np.ndarray, F2: np.ndarray, commanded_N: float) -> str:
    """Why the force fight (samples ``F1``, ``F2`` [N]) cannot be this check's, or "" when it can.

    Its level is the 99th percentile of ``|F2 - F1| / 2`` (one spike does not make a force fight).
    """
    if F1.size == 0:
        return ""
    level = float(np.percentile(np.abs(F2 - F1), 99)) / 2.0
    bound = MIN_FORCE_FIGHT_FRACTION * commanded_N
    if level >= bound:
        return ""
    if float(np.percentile(np.abs(F1 + F2), 99)) / 2.0 >= bound:  # the two "fight" with the same sign
        hint = " (one load cell with the wrong sign? F1 + F2 reaches the level instead)"
    else:
        hint = _in(likely_units(level / commanded_N, FORCE_UNITS), "forces")
    return (f"columns 'F1', 'F2' [N]: the force fight reached {level:.4g} N, below a tenth of its commanded "
            f"{commanded_N:.4g} N ({bound:.4g} N){hint}: not a force fight of this actuation")


def load_cells_problem(F1: np.ndarray, F2: np.ndarray) -> str:
    """Why the two load cells (force-fight samples ``F1``, ``F2`` [N]) cannot both be this rig's, or "".

    In a force fight the two EMAs push on the same shaft at rest: the load cells read the same force with
    opposite signs, and ``F1 + F2`` is the shaft's friction and inertia (43 N at 99 % in a dry-run whose
    force fight reaches 5870 N). If one load cell reads a fraction ``r`` of the other (a gain or unit error),
    ``|F1 + F2| = (1 - r) |F|`` while the level ``|F2 - F1| / 2 = (1 + r) |F| / 2``: the ratio
    ``2 (1 - r) / (1 + r)`` exceeds :data:`MAX_IMBALANCE_RATIO` (0.5) for ``r < 0.6``, a load cell 40 % off,
    which no load-cell calibration error is and every unit error is (at least a factor 4.4, lbf).
    """
    if F1.size == 0:
        return ""
    level = float(np.percentile(np.abs(F2 - F1), 99)) / 2.0
    imbalance = float(np.percentile(np.abs(F1 + F2), 99))
    if level <= 0 or imbalance <= MAX_IMBALANCE_RATIO * level:
        return ""
    a1, a2 = (float(np.percentile(np.abs(f - np.median(f)), 99)) for f in (F1, F2))
    hint = ""
    if a1 > 0 and a2 > 0:
        small, big, r = ("F1", "F2", a1 / a2) if a1 < a2 else ("F2", "F1", a2 / a1)
        units = likely_units(r, FORCE_UNITS[:-1])
        hint = (f" ('{small}' in {' or '.join(units)}?)" if units else
                " (one load cell with the wrong sign?)" if r > 0.6 else "")
    return (f"columns 'F1', 'F2' [N]: the load cells disagree in the force fight, |F1 + F2| reaches "
            f"{imbalance:.4g} N against a force-fight level of {level:.4g} N (at most {MAX_IMBALANCE_RATIO:g} "
            f"times it){hint}: not the two load cells of this actuation")


def pitch_problem(k: int, pitch: float, how: str) -> tuple[str, bool]:
    """``(words, gross)`` for LVDT ``k``'s pitch, ``("", False)`` when plausible; ``gross``: beyond a factor
    :data:`GROSS_PITCH_FACTOR` (a unit or the gear ratio, the recording refused)."""
    tol = HARD_LVDT_GAIN_TOLERANCE
    if 1.0 - tol <= pitch <= 1.0 + tol:
        return "", False
    gross = not (1.0 / GROSS_PITCH_FACTOR <= pitch <= GROSS_PITCH_FACTOR)
    hints = [f"'s{k}' in {u}" for u in likely_units(pitch, STROKE_UNITS)]
    hints += [f"'phi{k}' in {u}" for u in likely_units(1.0 / pitch, ANGLE_UNITS) if pitch > 0]
    cause = (f" ({' or '.join(hints)}?)" if hints else
             " (mechanics.i_total_rad_per_mm not this actuation's gear ratio and lead, or the LVDT's scale)")
    return (f"columns 's{k}' [mm], 'phi{k}' [rad]: LVDT {k} reads {pitch:.4g} mm per mm of motor-derived stroke "
            f"({how}), outside 1 +- {tol:g}{cause}"), gross


def slope_pitch(x_mm: np.ndarray, s_mm: np.ndarray) -> float | None:
    """The least-squares slope of ``s`` over ``x`` [-], or None when ``x`` spans less than
    :data:`MIN_TRAVEL_FOR_SCALE_MM`."""
    finite = np.isfinite(x_mm) & np.isfinite(s_mm)
    x, s = x_mm[finite], s_mm[finite]
    if x.size < 2 or float(np.ptp(x)) < MIN_TRAVEL_FOR_SCALE_MM:
        return None
    xc = x - x.mean()
    return float(np.dot(xc, s - s.mean()) / np.dot(xc, xc))


def stiffness_problem(channel: str, lines: dict[str, float], rng: StiffnessRange, columns: str) -> str:
    """Why channel ``channel``'s stiffness lines (``{"left": k, "right": k}`` [N/mm]) cannot be this
    actuation's, or "". The likely units are those of the forces that would bring every line into the range."""
    bad = {side: k for side, k in lines.items() if not rng.min_N_per_mm <= abs(k) <= rng.max_N_per_mm}
    if not bad:
        return ""
    units = [u for u, f in FORCE_UNITS
             if all(rng.min_N_per_mm <= abs(k) / f <= rng.max_N_per_mm for k in lines.values())]
    sides = ", ".join(f"{side} {v:.4g}" for side, v in bad.items())
    return (f"{channel}: stiffness {sides} N/mm outside the range this actuation can have and the check can "
            f"measure, {rng.min_N_per_mm:.4g} .. {rng.max_N_per_mm:.4g} N/mm ({rng.source}); columns {columns}"
            f"{_in(units, 'forces')}")
