"""Safety supervisor core: checks every SYNC cycle against the check's hard limits.

Sans-IO: fed the measured sample and the setpoints in force, returns a
:class:`Violation` or None. It is independent of the sequence logic; the loop
that owns both aborts the sequence on a violation and the link drives both
EMAs to the safe state (CiA 402 quick stop, then disabled). Latching: once
violated it keeps returning the first violation; an exception inside is a
violation too (fail closed).

Limits (``check.safety``, each capped again here by the constants of
:mod:`hil.profile.config` that no profile can raise):

========================  ====================================================
``max_force_N``           :math:`|F_k|`, cap 25 % of F_limit
``max_force_fight_N``     force-fight level :math:`|F_1 - F_2| / 2`, cap 20 %
``max_force_imbalance_N`` load-cell plausibility :math:`|F_1 + F_2|`, cap 10 %
``max_stroke_mm``         :math:`|s_k|` (LVDT), cap: the actuation's stroke limit
``max_velocity_mm_per_s`` :math:`|\\Delta\\varphi_k| / (i\\,\\Delta t)`
``max_following_error_mm`` CSP target versus motor angle, :math:`|\\varphi^* - \\varphi| / i`
``max_d_int_mm``          D plausibility (LVDT versus motor angle), below
``max_stale_cycles``      sensor freshness: SYNC cycles between two samples - 1 (today's short limit;
                          ``max_stale_ms`` where both drives keep their limits: hil/check/staleness.py)
``max_frozen_cycles``     sensor freshness: a noisy LVDT or load cell repeating
                          exactly the same value for more cycles than this
========================  ====================================================

D plausibility: with :math:`x_k = \\varphi_k / i` and the first sample of the
check as reference (index 0),

.. math::

    \\big|(s_k - s_{k,0}) - (x_k - x_{k,0})\\big|
    \\le D_{max} + g_{tol}\\,|x_k - x_{k,0}|

where :math:`g_{tol}` = :data:`hil.profile.config.HARD_LVDT_GAIN_TOLERANCE` admits the
LVDT pitch error the calibration is there to measure (7.5 % in the paper).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, fields

from hil.canopen.drivelimits import LimitKind
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.staleness import stale_limit
from hil.profile.config import (
    HARD_LVDT_GAIN_TOLERANCE,
    HARD_MAX_D_INT_MM,
    HARD_MAX_FOLLOWING_ERROR_MM,
    HARD_MAX_FORCE_FIGHT_FRACTION,
    HARD_MAX_FORCE_FRACTION,
    HARD_MAX_FORCE_IMBALANCE_FRACTION,
    HARD_MAX_FROZEN_CYCLES,
    HARD_MAX_VELOCITY_MM_PER_S,
    Actuation,
    Check,
    Safety,
)

#: The limits a check profile sets (``[safety]``).
_SAFETY_KEYS = frozenset(f.name for f in fields(Safety))


@dataclass(frozen=True, slots=True)
class Violation:
    t_s: float
    limit: str  #: machine name of the limit, e.g. "max_force_N"
    detail: str  #: human-readable, with the measured value and the limit
    value: float = float("nan")  #: the measured value (unit of the limit)
    threshold: float = float("nan")  #: the limit in force

    @property
    def key(self) -> str:
        """The check profile's key that sets the limit (``safety.max_force_N``); the limit's name where none
        does (``sensor_invalid``, ``supervisor_error``)."""
        return f"safety.{self.limit}" if self.limit in _SAFETY_KEYS else self.limit


@dataclass(frozen=True)
class Limits:
    """The limits the supervisor applies: ``min(profile value, hard cap)``."""

    max_force_N: float
    max_force_fight_N: float
    max_force_imbalance_N: float
    max_stroke_mm: float
    max_velocity_mm_per_s: float
    max_following_error_mm: float
    max_d_int_mm: float
    max_stale_cycles: int
    max_frozen_cycles: int
    stale_name: str = "max_stale_cycles"  #: the freshness limit in force (hil.check.staleness.StaleLimit.name)
    stale_why: str = ""

    @classmethod
    def of(cls, actuation: Actuation, check: Check, kept: Sequence[Collection[LimitKind]] | None = None) -> Limits:
        """``kept``: per EMA the limits its drive keeps itself (None: not known): which freshness limit
        applies (:func:`hil.check.staleness.stale_limit`)."""
        s = check.safety
        stale = stale_limit(actuation, s, kept)
        f_lim = actuation.mechanics.limit_load_N
        return cls(
            max_force_N=min(s.max_force_N, HARD_MAX_FORCE_FRACTION * f_lim),
            max_force_fight_N=min(s.max_force_fight_N, HARD_MAX_FORCE_FIGHT_FRACTION * f_lim),
            max_force_imbalance_N=min(s.max_force_imbalance_N, HARD_MAX_FORCE_IMBALANCE_FRACTION * f_lim),
            max_stroke_mm=min(s.max_stroke_mm, actuation.mechanics.stroke_limit_mm),
            max_velocity_mm_per_s=min(s.max_velocity_mm_per_s, HARD_MAX_VELOCITY_MM_PER_S),
            max_following_error_mm=min(s.max_following_error_mm, HARD_MAX_FOLLOWING_ERROR_MM),
            max_d_int_mm=min(s.max_d_int_mm, HARD_MAX_D_INT_MM),
            max_stale_cycles=stale.cycles,
            max_frozen_cycles=min(s.max_frozen_cycles, HARD_MAX_FROZEN_CYCLES),
            stale_name=stale.name, stale_why=stale.why,
        )


class Supervisor:
    """Hard-limit monitor, one call per SYNC cycle.

    Parameters
    ----------
    actuation, check : the validated profiles; limits from ``check.safety``
        capped by the hard constants (:class:`Limits`).
    """

    def __init__(self, actuation: Actuation, check: Check,
                 kept: Sequence[Collection[LimitKind]] | None = None) -> None:
        self.i = actuation.mechanics.i_total_rad_per_mm
        self.T = actuation.timing.sync_period_s
        self._profiles = (actuation, check)
        self.lim = Limits.of(actuation, check, kept)
        self._prev: Sample | None = None
        self._ref: Sample | None = None
        self._same = [0, 0, 0, 0]  # consecutive repeats of s1, s2, F1, F2
        self.latched: Violation | None = None

    def drives_keep(self, kept: Sequence[Collection[LimitKind]] | None) -> None:
        """The limits each drive keeps itself, once the preflight has written and read them back: the
        freshness limit that applies from now on (:func:`hil.check.staleness.stale_limit`)."""
        self.lim = Limits.of(*self._profiles, kept)

    def check(self, smp: Sample, sp1: Setpoint, sp2: Setpoint) -> Violation | None:
        """Check one sample; ``sp1/sp2`` are the setpoints the drives were following."""
        if self.latched is not None:
            return self.latched
        try:
            v = self._check(smp, sp1, sp2)
        except Exception as exc:  # fail closed: an error in the supervisor is a violation
            v = Violation(smp.t_s, "supervisor_error", f"supervisor error: {exc!r}")
            self.latched = v
            raise
        self._prev = smp
        if v is not None:
            self.latched = v
        return v

    def _check(self, smp: Sample, sp1: Setpoint, sp2: Setpoint) -> Violation | None:
        # (once per SYNC cycle: the sample's fields read once, the checks in a fixed order, each EMA's
        # written out; a message is made only for a violation)
        lim = self.lim
        t, phi1, phi2, s1, s2, F1, F2 = smp.t_s, smp.phi1_rad, smp.phi2_rad, smp.s1_mm, smp.s2_mm, smp.F1_N, smp.F2_N
        if not (s1 - s1 == 0.0 and s2 - s2 == 0.0 and F1 - F1 == 0.0 and F2 - F2 == 0.0
                and phi1 - phi1 == 0.0 and phi2 - phi2 == 0.0):  # NaN or inf from a sensor path
            return Violation(t, "sensor_invalid", f"non-finite sensor value in {(s1, s2, F1, F2, phi1, phi2)}")
        stroke, force = lim.max_stroke_mm, lim.max_force_N
        a1, a2, f1, f2 = abs(s1), abs(s2), abs(F1), abs(F2)
        if a1 > stroke:
            return _stroke(t, 1, a1, stroke)
        if f1 > force:
            return _force(t, 1, f1, force)
        if a2 > stroke:
            return _stroke(t, 2, a2, stroke)
        if f2 > force:
            return _force(t, 2, f2, force)
        fight = abs(F1 - F2) / 2.0
        if fight > lim.max_force_fight_N:
            return Violation(t, "max_force_fight_N", f"force fight |F1 - F2|/2 = {fight:.0f} N > "
                             f"{lim.max_force_fight_N:.0f} N", fight, lim.max_force_fight_N)
        imb = abs(F1 + F2)
        if imb > lim.max_force_imbalance_N:
            return Violation(t, "max_force_imbalance_N", f"load cells disagree: |F1 + F2| = {imb:.0f} N > "
                             f"{lim.max_force_imbalance_N:.0f} N", imb, lim.max_force_imbalance_N)
        i = self.i
        for k, phi, sp in ((1, phi1, sp1), (2, phi2, sp2)):
            if sp.mode == DriveMode.POSITION:
                err = abs(sp.value - phi) / i
                if err > lim.max_following_error_mm:
                    return Violation(t, "max_following_error_mm",
                                     f"EMA {k} following error {err:.3f} mm > {lim.max_following_error_mm} mm",
                                     err, lim.max_following_error_mm)
        if self._ref is None:
            self._ref = smp
        ref = self._ref
        d_int = lim.max_d_int_mm
        for k, s, x, s0, x0 in ((1, s1, phi1 / i, ref.s1_mm, ref.phi1_rad / i),
                                (2, s2, phi2 / i, ref.s2_mm, ref.phi2_rad / i)):
            dd = abs((s - s0) - (x - x0))
            allowed = d_int + HARD_LVDT_GAIN_TOLERANCE * abs(x - x0)
            if dd > allowed:
                return Violation(t, "max_d_int_mm", f"EMA {k} LVDT versus motor angle implausible: "
                                 f"D moved {dd:.3f} mm > {allowed:.3f} mm", dd, allowed)
        prev = self._prev
        if prev is not None:
            dt = t - prev.t_s
            missed = int(round(dt / self.T)) - 1
            if missed > lim.max_stale_cycles:
                why = f" ({lim.stale_why})" if lim.stale_name == "max_stale_ms" else ""
                return Violation(t, lim.stale_name, f"sensor data stale: {missed} SYNC cycles without a "
                                 f"sample > {lim.max_stale_cycles}{why}", missed, lim.max_stale_cycles)
            if dt > 0:
                vmax = lim.max_velocity_mm_per_s
                for k, a, b in ((1, phi1, prev.phi1_rad), (2, phi2, prev.phi2_rad)):
                    v = abs(a - b) / i / dt
                    if v > vmax:
                        return Violation(t, "max_velocity_mm_per_s", f"EMA {k} speed {v:.2f} mm/s > {vmax} mm/s",
                                         v, vmax)
            same = self._same
            frozen = lim.max_frozen_cycles
            same[0] = same[0] + 1 if s1 == prev.s1_mm else 0
            same[1] = same[1] + 1 if s2 == prev.s2_mm else 0
            same[2] = same[2] + 1 if F1 == prev.F1_N else 0
            same[3] = same[3] + 1 if F2 == prev.F2_N else 0
            # (each counter checked on its own, in the order s1, s2, F1, F2: no pre-filter whose
            # comparison a test could not tell from the one it guards)
            if same[0] > frozen:
                return _frozen(t, "LVDT 1", s1, "mm", same[0], frozen)
            if same[1] > frozen:
                return _frozen(t, "LVDT 2", s2, "mm", same[1], frozen)
            if same[2] > frozen:
                return _frozen(t, "load cell 1", F1, "N", same[2], frozen)
            if same[3] > frozen:
                return _frozen(t, "load cell 2", F2, "N", same[3], frozen)
        return None


def _stroke(t: float, k: int, x_mm: float, limit_mm: float) -> Violation:
    return Violation(t, "max_stroke_mm", f"|s{k}| = {x_mm:.3f} mm > {limit_mm} mm", x_mm, limit_mm)


def _force(t: float, k: int, f_N: float, limit_N: float) -> Violation:
    return Violation(t, "max_force_N", f"|F{k}| = {f_N:.0f} N > {limit_N:.0f} N", f_N, limit_N)


def _frozen(t: float, name: str, value: float, unit: str, cycles: int, limit: int) -> Violation:
    return Violation(t, "max_frozen_cycles", f"{name} frozen: the same value {value:.6g} {unit} for {cycles} "
                     f"cycles > {limit}", cycles, limit)
