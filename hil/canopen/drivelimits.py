"""The limits a CiA 402 drive can keep by itself: which object holds which, and their scaling (pure).

The master writes them in the preflight (:mod:`hil.master.preflight`) from the check's safety profile and
reads each back; the simulated drive (:mod:`sim.drives.cia402_drive`) enforces exactly the objects it
was written. Both ends take the objects and the conversions from here.

==========================  =========  ==========  =============================================  ==========
limit                       object     data type   drive unit (value from the SI limit)           rounded
==========================  =========  ==========  =============================================  ==========
software position limit     0x607D:01  INTEGER32   position units: ``-s i k``                     towards 0
 (min / max)                0x607D:02              ``+s i k``
max torque                  0x6072:00  UNSIGNED16  per mille of the rated torque 0x6076: ``F q``  down
max motor speed             0x6080:00  UNSIGNED32  rpm of the motor: ``v i 60 / 2 pi``            down
following error window      0x6065:00  UNSIGNED32  position units: ``e i k``                      down
following error time out    0x6066:00  UNSIGNED16  ms                                             down
quick stop deceleration     0x6085:00  UNSIGNED32  position units per s^2: ``a i k``              up
==========================  =========  ==========  =============================================  ==========

``s`` stroke [mm], ``F`` force [N], ``v`` ram speed [mm/s], ``e`` following error [mm], ``a`` ram
deceleration [mm/s^2], ``i`` the gear ratio [rad of motor per mm of ram], ``k`` the drive's position
units per rad of motor angle (the signal map's motor-angle :class:`~hil.canopen.signalmap.Scale` as
the drive reported it), ``q`` per mille per newton at the ram (the target-torque Scale). A limit is
rounded so that the drive is never looser than the profile (a deceleration up: a quicker stop); the
position units per s^2 of 0x6085 are CiA 402's acceleration units where a drive has no acceleration
factor of its own (0x6097).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from hil.canopen.errors import CanopenInputError

__all__ = ["KEPT_BY_DRIVE", "KEPT_BY_MASTER", "LIMIT_OBJECTS", "DriveLimit", "LimitKind", "LimitObject",
           "LimitTargets", "drive_limits", "offered", "rpm_to_rad_per_s", "rad_per_s_to_rpm"]

KEPT_BY_DRIVE = "drive"  #: written to the drive and read back (that it enforces it is the drive's, not observed here)
KEPT_BY_MASTER = "master"  #: not written: the drive's EDS has no such object, or not writable (the master's supervisor
#: keeps the stroke, force, speed and following-error limits; the quick-stop deceleration and the time out it has not)

_U16 = 0xFFFF
_U32 = 0xFFFF_FFFF
_I32 = 0x7FFF_FFFF


class LimitKind(Enum):
    """The limits a drive can keep; value: the name meta.json and the report give it."""

    POSITION_MIN = "software position limit min"
    POSITION_MAX = "software position limit max"
    MAX_TORQUE = "max torque"
    MAX_MOTOR_SPEED = "max motor speed"
    FOLLOWING_ERROR_WINDOW = "following error window"
    FOLLOWING_ERROR_TIME = "following error time out"
    QUICK_STOP_DECELERATION = "quick stop deceleration"


@dataclass(frozen=True, slots=True)
class LimitObject:
    """Where a drive keeps a limit (CiA 402) and in which unit."""

    index: int
    sub: int
    unit: str  #: the drive's unit of the object's value
    si_unit: str  #: the unit of the profile's limit it comes from

    @property
    def name(self) -> str:
        return f"0x{self.index:04X}:{self.sub:02X}"


#: The objects of each limit (CiA 402-2).
LIMIT_OBJECTS: dict[LimitKind, LimitObject] = {
    LimitKind.POSITION_MIN: LimitObject(0x607D, 1, "position units", "mm"),
    LimitKind.POSITION_MAX: LimitObject(0x607D, 2, "position units", "mm"),
    LimitKind.MAX_TORQUE: LimitObject(0x6072, 0, "per mille of rated torque", "N"),
    LimitKind.MAX_MOTOR_SPEED: LimitObject(0x6080, 0, "rpm", "mm/s"),
    LimitKind.FOLLOWING_ERROR_WINDOW: LimitObject(0x6065, 0, "position units", "mm"),
    LimitKind.FOLLOWING_ERROR_TIME: LimitObject(0x6066, 0, "ms", "s"),
    LimitKind.QUICK_STOP_DECELERATION: LimitObject(0x6085, 0, "position units/s^2", "mm/s^2"),
}


@dataclass(frozen=True, slots=True)
class LimitTargets:
    """The limits in SI (at the ram) that the drives should keep, and the scalings to their units.

    A limit of None is not asked of the drive. ``position_units_per_rad`` None: no position limit can
    be converted (the drive's position unit is unknown); ``torque_permille_per_N`` None: no torque limit.
    """

    i_total_rad_per_mm: float
    position_units_per_rad: float | None
    torque_permille_per_N: float | None
    stroke_mm: float | None = None
    max_force_N: float | None = None
    max_speed_mm_per_s: float | None = None
    following_error_mm: float | None = None
    following_error_time_s: float | None = None
    quick_stop_decel_mm_per_s2: float | None = None


@dataclass(frozen=True, slots=True)
class DriveLimit:
    """One limit of one drive: the value in the drive's unit, the SI limit it stands for, who keeps it."""

    kind: LimitKind
    value: int  #: in the drive's unit (:attr:`unit`)
    si_value: float  #: the profile's limit it comes from (:attr:`si_unit`)
    kept_by: str = KEPT_BY_DRIVE  #: :data:`KEPT_BY_DRIVE` or :data:`KEPT_BY_MASTER`

    @property
    def obj(self) -> LimitObject:
        return LIMIT_OBJECTS[self.kind]

    @property
    def unit(self) -> str:
        return self.obj.unit

    @property
    def si_unit(self) -> str:
        return self.obj.si_unit

    def as_json(self) -> dict:
        return {"limit": self.kind.value, "object": self.obj.name, "value": self.value, "unit": self.unit,
                "si_value": self.si_value, "si_unit": self.si_unit, "kept_by": self.kept_by}


def _down(x: float) -> int:
    """``floor(x)`` for x >= 0, forgiving the last bits of a float product that should be whole."""
    return math.floor(x + abs(x) * 1e-12)


def _up(x: float) -> int:
    return math.ceil(x - abs(x) * 1e-12)


def _positive(name: str, v: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise CanopenInputError(f"{name} = {v!r} must be a finite number > 0")
    return float(v)


def rad_per_s_to_rpm(w_rad_per_s: float) -> float:
    """Motor speed [rad/s] in revolutions per minute."""
    return w_rad_per_s * 60.0 / (2.0 * math.pi)


def rpm_to_rad_per_s(rpm: float) -> float:
    """Revolutions per minute in motor speed [rad/s]."""
    return rpm * 2.0 * math.pi / 60.0


def drive_limits(t: LimitTargets) -> tuple[DriveLimit, ...]:
    """The limits of ``t`` in the drive's units (all kept by the drive; :func:`offered` says which
    objects a drive has), in the order of :class:`LimitKind`; a limit that cannot be expressed is left out.

    Raises
    ------
    CanopenInputError
        A limit or scaling that is not a finite positive number.
    """
    i = _positive("i_total_rad_per_mm", t.i_total_rad_per_mm)
    k = _positive("|position_units_per_rad|", abs(t.position_units_per_rad)) \
        if t.position_units_per_rad is not None else None
    out: list[DriveLimit] = []
    if t.stroke_mm is not None and k is not None:
        s = _positive("stroke_mm", t.stroke_mm)
        p = min(_down(s * i * k), _I32)
        out += [DriveLimit(LimitKind.POSITION_MIN, -p, -s), DriveLimit(LimitKind.POSITION_MAX, p, s)]
    if t.max_force_N is not None and t.torque_permille_per_N is not None:
        f = _positive("max_force_N", t.max_force_N)
        out.append(DriveLimit(LimitKind.MAX_TORQUE, min(_down(f * abs(t.torque_permille_per_N)), _U16), f))
    if t.max_speed_mm_per_s is not None:
        v = _positive("max_speed_mm_per_s", t.max_speed_mm_per_s)
        out.append(DriveLimit(LimitKind.MAX_MOTOR_SPEED, min(_down(rad_per_s_to_rpm(v * i)), _U32), v))
    if t.following_error_mm is not None and k is not None:
        e = _positive("following_error_mm", t.following_error_mm)
        out.append(DriveLimit(LimitKind.FOLLOWING_ERROR_WINDOW, min(_down(e * i * k), _U32), e))
    if t.following_error_time_s is not None:
        ts = _positive("following_error_time_s", t.following_error_time_s)
        out.append(DriveLimit(LimitKind.FOLLOWING_ERROR_TIME, min(_down(ts * 1000.0), _U16), ts))
    if t.quick_stop_decel_mm_per_s2 is not None and k is not None:
        a = _positive("quick_stop_decel_mm_per_s2", t.quick_stop_decel_mm_per_s2)
        out.append(DriveLimit(LimitKind.QUICK_STOP_DECELERATION, min(_up(a * i * k), _U32), a))
    return tuple(out)


def offered(can_write: Callable[[int, int], bool]) -> dict[LimitKind, bool]:
    """Per limit: whether a drive offers its object writable (``can_write(index, sub)``, e.g.
    :meth:`hil.canopen.plan.NodePlan.can_write`); the position limits need both sub-indices."""
    both = can_write(0x607D, 1) and can_write(0x607D, 2)
    return {kind: both if obj.index == 0x607D else bool(can_write(obj.index, obj.sub))
            for kind, obj in LIMIT_OBJECTS.items()}
