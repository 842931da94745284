"""Safety supervisor core: checks every SYNC cycle against the check's hard limits.

Sans-IO: fed the measured sample and the setpoints in force, returns a
:class:`Violation` or None. It is independent of the sequence logic; the loop
that owns both aborts the sequence on a violation. Latching: once violated it
keeps returning the first violation.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.config import Actuation, Check
from hil.types import DriveMode, Sample, Setpoint


@dataclass(frozen=True, slots=True)
class Violation:
    t_s: float
    limit: str  #: machine name of the limit, e.g. "max_force_N"
    detail: str  #: human-readable, with the measured value and the limit


class Supervisor:
    """Hard-limit monitor (force, stroke, velocity, following error).

    Parameters
    ----------
    actuation, check : the validated profiles; limits come from ``check.safety``.
    """

    def __init__(self, actuation: Actuation, check: Check) -> None:
        self.i = actuation.mechanics.i_total_rad_per_mm
        self.s = check.safety
        self._prev: Sample | None = None
        self.latched: Violation | None = None

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
        s = self.s
        t = smp.t_s
        for k, (f, x) in enumerate(((smp.F1_N, smp.s1_mm), (smp.F2_N, smp.s2_mm)), start=1):
            if abs(f) > s.max_force_N:
                return Violation(t, "max_force_N", f"|F{k}| = {abs(f):.0f} N > {s.max_force_N:.0f} N")
            if abs(x) > s.max_stroke_mm:
                return Violation(t, "max_stroke_mm", f"|s{k}| = {abs(x):.3f} mm > {s.max_stroke_mm} mm")
        for k, (phi, sp) in enumerate(((smp.phi1_rad, sp1), (smp.phi2_rad, sp2)), start=1):
            if sp.mode == DriveMode.POSITION:
                err = abs(sp.value - phi) / self.i
                if err > s.max_following_error_mm:
                    return Violation(t, "max_following_error_mm",
                                     f"EMA {k} following error {err:.3f} mm > {s.max_following_error_mm} mm")
        if self._prev is not None:
            dt = t - self._prev.t_s
            if dt > 0:
                for k, (a, b) in enumerate(((smp.phi1_rad, self._prev.phi1_rad),
                                            (smp.phi2_rad, self._prev.phi2_rad)), start=1):
                    v = abs(a - b) / self.i / dt
                    if v > s.max_velocity_mm_per_s:
                        return Violation(t, "max_velocity_mm_per_s",
                                         f"EMA {k} speed {v:.2f} mm/s > {s.max_velocity_mm_per_s} mm/s")
        return None
