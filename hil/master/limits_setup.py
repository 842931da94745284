"""The limits the drives keep themselves, from the check's safety profile (docs/safety.md).

:func:`limit_targets` turns the profile's limits (each capped by its hard constant, as the supervisor
caps it) into the SI targets of :class:`hil.canopen.drivelimits.LimitTargets`; the preflight converts
them to each drive's units (:func:`hil.canopen.drivelimits.drive_limits`), writes what the drive's EDS
offers and reads each back (:func:`readback_problem`). What a drive does not offer is kept by the
master only; the run record says which (``drives_final.emaN.drive_limits``).
"""

from __future__ import annotations

from hil.canopen.drivelimits import (
    KEPT_BY_MASTER,
    DriveLimit,
    LimitTargets,
    drive_limits,
    offered,
)
from hil.profile.config import (
    HARD_MAX_FOLLOWING_ERROR_MM,
    HARD_MAX_FORCE_FRACTION,
    HARD_MAX_VELOCITY_MM_PER_S,
    Actuation,
    Safety,
)

__all__ = ["FOLLOWING_ERROR_TIME_CYCLES", "QUICK_STOP_CYCLES", "limit_targets", "limits_for",
           "readback_problem"]

#: The drive faults on a following error beyond its window for longer than this many SYNC periods: the
#: master's own reaction (the supervisor sees the sample, the quick stop goes out with the next SYNC).
FOLLOWING_ERROR_TIME_CYCLES = 2
#: The quick stop deceleration stops the ram from the drive's max speed within this many SYNC periods.
QUICK_STOP_CYCLES = 2


def limit_targets(act: Actuation, safety: Safety | None, forces: tuple[float, float] | None,
                  position_units_per_rad: float | None, torque_permille_per_N: float | None) -> LimitTargets:
    """The SI limits a drive of ``act`` should keep under the check's ``safety`` profile.

    Each limit is ``min(profile value, hard cap)`` as :class:`hil.check.supervisor.Limits` applies it: the
    stroke ``min(safety.max_stroke_mm, mechanics.stroke_limit_mm)``, the force ``safety.max_force_N``
    (25 % of F_limit at most), the ram speed ``safety.max_velocity_mm_per_s`` (50 mm/s), the following
    error ``safety.max_following_error_mm`` (2 mm) for :data:`FOLLOWING_ERROR_TIME_CYCLES` SYNC periods,
    and a quick stop from that speed within :data:`QUICK_STOP_CYCLES` SYNC periods. Without a safety
    profile (a master built for a protocol test) only the stroke limit of the actuation and the force
    limit of ``forces`` (opposing, limit) are asked.
    """
    m = act.mechanics
    T = act.timing.sync_period_s
    force = None
    if safety is not None:
        force = min(safety.max_force_N, HARD_MAX_FORCE_FRACTION * m.limit_load_N)
    elif forces is not None:
        force = forces[1]
    base = dict(i_total_rad_per_mm=m.i_total_rad_per_mm, position_units_per_rad=position_units_per_rad,
                torque_permille_per_N=torque_permille_per_N, max_force_N=force)
    if safety is None:
        return LimitTargets(**base, stroke_mm=m.stroke_limit_mm)
    v = min(safety.max_velocity_mm_per_s, HARD_MAX_VELOCITY_MM_PER_S)
    return LimitTargets(**base, stroke_mm=min(safety.max_stroke_mm, m.stroke_limit_mm), max_speed_mm_per_s=v,
                        following_error_mm=min(safety.max_following_error_mm, HARD_MAX_FOLLOWING_ERROR_MM),
                        following_error_time_s=FOLLOWING_ERROR_TIME_CYCLES * T,
                        quick_stop_decel_mm_per_s2=v / (QUICK_STOP_CYCLES * T))


def limits_for(targets: LimitTargets, can_write) -> tuple[DriveLimit, ...]:
    """The limits of ``targets`` in the drive's units, each marked kept by the drive where it offers the
    object writable (``can_write(index, sub)``), else by the master only."""
    has = offered(can_write)
    return tuple(lim if has[lim.kind] else DriveLimit(lim.kind, lim.value, lim.si_value, KEPT_BY_MASTER)
                 for lim in drive_limits(targets))


def readback_problem(label: str, lim: DriveLimit, read) -> str | None:
    """Why a read-back refuses the preflight (None: it reads back what was written)."""
    if isinstance(read, (int, float)) and read == lim.value:
        return None
    return (f"{label}: {lim.kind.value} {lim.obj.name} reads back {read!r} after {lim.value} "
            f"({lim.unit}) was written; the drive would not keep the limit the check relies on")

