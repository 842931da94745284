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
        lim = self.lim
        t = smp.t_s
        vals = (smp.s1_mm, smp.s2_mm, smp.F1_N, smp.F2_N, smp.phi1_rad, smp.phi2_rad)
        if not all(v - v == 0.0 for v in vals):  # NaN or inf from a sensor path
            return Violation(t, "sensor_invalid", f"non-finite sensor value in {vals}")
        for k, (f, x) in enumerate(((smp.F1_N, smp.s1_mm), (smp.F2_N, smp.s2_mm)), start=1):
            if abs(x) > lim.max_stroke_mm:
                return Violation(t, "max_stroke_mm", f"|s{k}| = {abs(x):.3f} mm > {lim.max_stroke_mm} mm",
                                 abs(x), lim.max_stroke_mm)
            if abs(f) > lim.max_force_N:
                return Violation(t, "max_force_N", f"|F{k}| = {abs(f):.0f} N > {lim.max_force_N:.0f} N",
                                 abs(f), lim.max_force_N)
        fight = abs(smp.F1_N - smp.F2_N) / 2.0
        if fight > lim.max_force_fight_N:
            return Violation(t, "max_force_fight_N", f"force fight |F1 - F2|/2 = {fight:.0f} N > "
                             f"{lim.max_force_fight_N:.0f} N", fight, lim.max_force_fight_N)
        imb = abs(smp.F1_N + smp.F2_N)
        if imb > lim.max_force_imbalance_N:
            return Violation(t, "max_force_imbalance_N", f"load cells disagree: |F1 + F2| = {imb:.0f} N > "
                             f"{lim.max_force_imbalance_N:.0f} N", imb, lim.max_force_imbalance_N)
        for k, (phi, sp) in enumerate(((smp.phi1_rad, sp1), (smp.phi2_rad, sp2)), start=1):
            if sp.mode == DriveMode.POSITION:
                err = abs(sp.value - phi) / self.i
                if err > lim.max_following_error_mm:
                    return Violation(t, "max_following_error_mm",
                                     f"EMA {k} following error {err:.3f} mm > {lim.max_following_error_mm} mm",
                                     err, lim.max_following_error_mm)
        if self._ref is None:
            self._ref = smp
        ref = self._ref
        for k, (s, x, s0, x0) in enumerate(((smp.s1_mm, smp.phi1_rad / self.i, ref.s1_mm, ref.phi1_rad / self.i),
                                           (smp.s2_mm, smp.phi2_rad / self.i, ref.s2_mm, ref.phi2_rad / self.i)),
                                          start=1):
            dd = abs((s - s0) - (x - x0))
            allowed = lim.max_d_int_mm + HARD_LVDT_GAIN_TOLERANCE * abs(x - x0)
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
                for k, (a, b) in enumerate(((smp.phi1_rad, prev.phi1_rad), (smp.phi2_rad, prev.phi2_rad)), start=1):
                    v = abs(a - b) / self.i / dt
                    if v > lim.max_velocity_mm_per_s:
                        return Violation(t, "max_velocity_mm_per_s",
                                         f"EMA {k} speed {v:.2f} mm/s > {lim.max_velocity_mm_per_s} mm/s",
                                         v, lim.max_velocity_mm_per_s)
            same = self._same
            for j, (a, b, name, unit) in enumerate(((smp.s1_mm, prev.s1_mm, "LVDT 1", "mm"),
                                                    (smp.s2_mm, prev.s2_mm, "LVDT 2", "mm"),
                                                    (smp.F1_N, prev.F1_N, "load cell 1", "N"),
                                                    (smp.F2_N, prev.F2_N, "load cell 2", "N"))):
                same[j] = same[j] + 1 if a == b else 0
                if same[j] > lim.max_frozen_cycles:
                    return Violation(t, "max_frozen_cycles", f"{name} frozen: the same value {a:.6g} {unit} for "
                                     f"{same[j]} cycles > {lim.max_frozen_cycles}", same[j], lim.max_frozen_cycles)
        return None
