"""Where each signal of the check lives on the bus: the rig's nodes and the signal map (pure).

A rig has the two EMA drives (CiA 402) and, optionally, nodes of their own for
the sensors (a CiA 401 I/O module, a CiA 404 measuring device). The *signal
map* says, per EMA, at which node and object each signal of the check lives,
its data type and the linear scaling to SI units:

==================  =========  =============================  ======================================
signal              direction  default object (the drive's)   scaling
==================  =========  =============================  ======================================
``motor_angle``     in         0x6064:00 position actual      rad: counts per revolution (profile),
                                                              0x608F or 0x6091/0x6092 as read
``lvdt``            in         (none: the rig says)           mm = raw * mm_per_unit + offset_mm
``force``           in         (none: the rig says)           N = raw * N_per_unit + offset_N
``statusword``      in         0x6041:00                      (bits)
``mode_display``    in         0x6061:00                      (mode number)
``controlword``     out        0x6040:00                      (bits)
``target_position`` out        0x607A:00                      as ``motor_angle``
``target_torque``   out        0x6071:00                      per mille of the rated torque (0x6076
                                                              as read, or the profile's), as ram
                                                              force through the gear ratio
``mode``            out        0x6060:00                      (mode number)
==================  =========  =============================  ======================================

The profile (:mod:`hil.profile.load`) builds these frozen dataclasses; the PDO
layout is planned from them and each node's EDS (:mod:`hil.canopen.plan`);
the master, the CAN-log reader and the simulated nodes all convert with the
same :class:`Scale`. No IO, no clock.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import Enum, IntEnum

from hil.canopen.errors import CanopenInputError
from hil.canopen.pdo import Direction

__all__ = [
    "DEFAULT_OBJECTS", "DRIVE_ROLE", "DeviceProfile", "ForceControl", "NodeRole", "NodeSpec", "Scale",
    "ScaleSource", "Signal", "SignalEntry", "SignalMap", "angle_scale_counts", "angle_scale_factor_group",
    "object_name", "parse_object", "torque_scale",
]


class Signal(Enum):
    """The signals of the check, per EMA (value: the profile key)."""

    MOTOR_ANGLE = "motor_angle"
    LVDT = "lvdt"
    FORCE = "force"
    STATUSWORD = "statusword"
    MODE_DISPLAY = "mode_display"
    CONTROLWORD = "controlword"
    TARGET_POSITION = "target_position"
    TARGET_TORQUE = "target_torque"
    MODE = "mode"

    @property
    def direction(self) -> Direction:
        """RX for what the master writes (an RPDO of the node), TX for what it reads (a TPDO)."""
        return Direction.RX if self in _OUTPUTS else Direction.TX

    @property
    def unit(self) -> str:
        """SI unit of the physical value ("" for words and mode numbers)."""
        return _UNIT.get(self, "")

    @property
    def drive_only(self) -> bool:
        """True for the CiA 402 objects that only the EMA's own drive can hold."""
        return self not in (Signal.LVDT, Signal.FORCE, Signal.MOTOR_ANGLE)


_OUTPUTS = frozenset((Signal.CONTROLWORD, Signal.TARGET_POSITION, Signal.TARGET_TORQUE, Signal.MODE))
_UNIT = {Signal.MOTOR_ANGLE: "rad", Signal.LVDT: "mm", Signal.FORCE: "N", Signal.TARGET_POSITION: "rad",
         Signal.TARGET_TORQUE: "N"}

#: The default object of each signal on the EMA's drive (CiA 402); LVDT and force have none.
DEFAULT_OBJECTS: dict[Signal, tuple[int, int]] = {
    Signal.MOTOR_ANGLE: (0x6064, 0),
    Signal.STATUSWORD: (0x6041, 0),
    Signal.MODE_DISPLAY: (0x6061, 0),
    Signal.CONTROLWORD: (0x6040, 0),
    Signal.TARGET_POSITION: (0x607A, 0),
    Signal.TARGET_TORQUE: (0x6071, 0),
    Signal.MODE: (0x6060, 0),
}


class ScaleSource(Enum):
    """Where the scaling of a physical signal comes from."""

    PROFILE = "profile"  #: the profile states it
    ENCODER = "0x608F"  #: increments per revolution 0x608F:01 / 0x608F:02 as read from the drive
    FACTOR_GROUP = "0x6091/0x6092"  #: position user units through gear ratio and feed constant as read
    RATED_TORQUE = "0x6076"  #: per mille of the motor rated torque 0x6076 [mN m] as read from the drive

    @property
    def read_objects(self) -> tuple[tuple[int, int], ...]:
        """The objects the preflight reads from the drive to resolve this scaling."""
        return {ScaleSource.PROFILE: (),
                ScaleSource.ENCODER: ((0x608F, 1), (0x608F, 2)),
                ScaleSource.FACTOR_GROUP: ((0x6091, 1), (0x6091, 2), (0x6092, 1), (0x6092, 2)),
                ScaleSource.RATED_TORQUE: ((0x6076, 0),)}[self]


class ForceControl(Enum):
    """How an EMA holds a force (the calibration's opposing force)."""

    AUTO = "auto"  #: CST where the drive offers it (EDS), else CSP
    CST = "cst"  #: the drive's cyclic synchronous torque mode (0x6071)
    CSP = "csp"  #: the master's own force loop on the measured force, commanding positions (CSP)


class NodeRole(Enum):
    DRIVE = "drive"  #: an EMA's CiA 402 drive
    SENSORS = "sensors"  #: a node with sensors only (CiA 401 I/O, CiA 404 measuring device)


#: Node name of the EMA drives in the map.
DRIVE_ROLE = {"ema1": 1, "ema2": 2}


@dataclass(frozen=True, slots=True)
class Scale:
    """Linear scaling of a raw object value to SI: ``si = raw / units_per_si + offset``.

    Attributes
    ----------
    units_per_si : float
        Raw units per SI unit (1000 for an LVDT in 0.001 mm; 651.9 inc/rad for
        4096 increments per revolution), finite and non-zero; negative flips the sign.
    offset : float
        The SI value at raw 0 (mm, N; 0 for angles).

    Notes
    -----
    .. math:: x_{SI} = \\frac{r}{k} + x_0, \\qquad r = \\mathrm{round}\\big(k\\,(x_{SI} - x_0)\\big)

    Division by :math:`k` (rather than multiplication by :math:`1/k`) keeps the
    values bit for bit those of the fixed 0.001 mm / 0.1 N / increment codecs.
    """

    units_per_si: float
    offset: float = 0.0

    def __post_init__(self) -> None:
        k = self.units_per_si
        if isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k) or k == 0:
            raise CanopenInputError(f"units_per_si = {k!r} must be a finite, non-zero number")
        if isinstance(self.offset, bool) or not isinstance(self.offset, (int, float)) \
                or not math.isfinite(self.offset):
            raise CanopenInputError(f"offset = {self.offset!r} must be a finite number")
        object.__setattr__(self, "units_per_si", float(k))
        object.__setattr__(self, "offset", float(self.offset))

    @classmethod
    def per_unit(cls, si_per_unit: float, offset: float = 0.0) -> Scale:
        """From SI per raw unit (``mm_per_unit = 0.001``), as a profile states it."""
        return cls(1.0 / si_per_unit, offset)

    @property
    def si_per_unit(self) -> float:
        return 1.0 / self.units_per_si

    def to_si(self, raw: float) -> float:
        """The SI value of a raw value."""
        v = raw / self.units_per_si
        return v + self.offset if self.offset else v

    def to_raw(self, si: float) -> float:
        """The (unrounded) raw value of an SI value."""
        return (si - self.offset) * self.units_per_si if self.offset else si * self.units_per_si


def angle_scale_counts(counts_per_rev: float) -> Scale:
    """Angle scale of position increments: ``counts_per_rev / 2 pi`` increments per rad."""
    return Scale(counts_per_rev / (2.0 * math.pi))


def angle_scale_factor_group(gear_motor_rev: int, gear_shaft_rev: int, feed: int, feed_shaft_rev: int) -> Scale:
    """Angle scale of position user units (CiA 402 factor group).

    Notes
    -----
    With 0x6091 = motor revolutions / shaft revolutions and 0x6092 = feed /
    shaft revolutions, one user (feed) unit is :math:`1/f` shaft revolutions
    and :math:`g/f` motor revolutions, so

    .. math:: k = \\frac{f}{2\\pi g}\\ \\text{[units/rad]}, \\quad
              g = \\frac{0x6091{:}01}{0x6091{:}02},\\ f = \\frac{0x6092{:}01}{0x6092{:}02}
    """
    g = gear_motor_rev / gear_shaft_rev
    f = feed / feed_shaft_rev
    return Scale(f / (2.0 * math.pi * g))


def torque_scale(rated_torque_Nm: float, i_total_rad_per_mm: float) -> Scale:
    """Scale of a torque in per mille of the rated torque as ram force [N].

    Notes
    -----
    :math:`F = \\tau / 1000 \\cdot T_r \\cdot 1000\\, i`: one per mille is
    :math:`T_r\\, i` newton (:func:`hil.canopen.units.permille_to_force_N`).
    """
    return Scale(1.0 / (rated_torque_Nm * i_total_rad_per_mm))


_OBJ = re.compile(r"^\s*(?:0x)?([0-9A-Fa-f]{4})\s*(?:(?::|sub)\s*(?:0x)?([0-9A-Fa-f]{1,2}))?\s*$")


def parse_object(text: object, key: str) -> tuple[int, int]:
    """``"0x6064:00"`` as ``(index, subindex)``; CanopenInputError naming ``key``.

    Index and sub-index are hexadecimal as in an EDS (``"0x3160:01"``, ``"3160sub1"``, ``"0x6064"`` for
    sub-index 0)."""
    m = _OBJ.match(text) if isinstance(text, str) else None
    if m is None:
        raise CanopenInputError(f"'{key}' = {text!r} is not an object address like \"0x6064:00\" (index:sub-index)")
    index = int(m.group(1), 16)
    sub = 0 if m.group(2) is None else int(m.group(2), 16)
    if not 0x1000 <= index <= 0xFFFF or not 0 <= sub <= 0xFF:
        raise CanopenInputError(f"'{key}' = {text!r}: index must be 0x1000..0xFFFF and sub-index 0..255")
    return index, sub


def object_name(index: int, subindex: int) -> str:
    """``0x6064:00``."""
    return f"0x{index:04X}:{subindex:02X}"


class DeviceProfile(IntEnum):
    """CiA device profile numbers (0x1000 bits 0..15) a node of the rig may have."""

    IO = 401
    DRIVE = 402
    MEASURING = 404


@dataclass(frozen=True, slots=True)
class NodeSpec:
    """One node of the rig as the profile describes it.

    Attributes
    ----------
    name : str
        ``"ema1"``, ``"ema2"`` (the drives) or the name of a sensor node (``[nodes.NAME]``).
    role : NodeRole
    node_id : int
        1..127.
    eds : str
        The node's EDS as the profile names it (resolved to a path by the caller).
    vendor_id, product_code, revision_min : int
        The identity 0x1018 the node must report (revision at least ``revision_min``).
    device_profile : int
        The CiA profile 0x1000 bits 0..15 must give (402 for a drive; 401 or 404).
    heartbeat_period_s : float
        The node's producer heartbeat 0x1017 the master sets and watches [s].
    key : str
        The profile table (``"canopen"``, ``"nodes.io"``) quoted in errors.
    """

    name: str
    role: NodeRole
    node_id: int
    eds: str
    vendor_id: int
    product_code: int
    revision_min: int
    device_profile: int
    heartbeat_period_s: float
    key: str

    @property
    def label(self) -> str:
        """``node 1 (EMA 1)``, ``node 3 (io)``."""
        what = f"EMA {self.name[-1]}" if self.role is NodeRole.DRIVE else self.name
        return f"node {self.node_id} ({what})"


@dataclass(frozen=True, slots=True)
class SignalEntry:
    """Where one signal of one EMA lives.

    Attributes
    ----------
    signal : Signal
    ema : int
        1 or 2.
    node : str
        The node holding the object: ``"ema1"``/``"ema2"`` (a drive) or a sensor node's name.
    index, subindex : int
        The object.
    data_type : int or None
        CiA 301 data type code the profile states; None: as the EDS says (the plan fills it in).
    scale : Scale or None
        raw -> SI; None for words and modes, and until resolved from the drive (``source``).
    source : ScaleSource
        Where the scale comes from (PROFILE: ``scale`` is final).
    key : str
        The profile key, e.g. ``"signals.ema1.lvdt"``, quoted in every error about it.
    """

    signal: Signal
    ema: int
    node: str
    index: int
    subindex: int
    data_type: int | None
    scale: Scale | None
    source: ScaleSource
    key: str

    @property
    def object(self) -> tuple[int, int]:
        return (self.index, self.subindex)

    @property
    def where(self) -> str:
        """``0x2100:00 at ema1`` for messages."""
        return f"{object_name(self.index, self.subindex)} at {self.node}"


@dataclass(frozen=True, slots=True)
class SignalMap:
    """The rig's nodes and where each signal of the check lives.

    Attributes
    ----------
    nodes : tuple of NodeSpec
        EMA 1's drive, EMA 2's drive, then the sensor nodes.
    entries : tuple of SignalEntry
        Every signal of both EMAs that the check exchanges (an absent
        ``target_torque``/``mode``: the EMA holds forces in CSP).
    force_control : ForceControl
        As the profile says (AUTO is decided by the plan from the EDS).
    cob_ids : tuple of (str, str, int)
        COB-IDs the profile fixes: (node name, PDO name such as ``"TPDO1"``, COB-ID).
    """

    nodes: tuple[NodeSpec, ...]
    entries: tuple[SignalEntry, ...]
    force_control: ForceControl = ForceControl.AUTO
    cob_ids: tuple[tuple[str, str, int], ...] = ()

    def node(self, name: str) -> NodeSpec:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(name)

    @property
    def drives(self) -> tuple[NodeSpec, NodeSpec]:
        return (self.node("ema1"), self.node("ema2"))

    def entry(self, ema: int, signal: Signal) -> SignalEntry | None:
        for e in self.entries:
            if e.ema == ema and e.signal is signal:
                return e
        return None

    def at(self, node: str) -> tuple[SignalEntry, ...]:
        """The entries whose object lives at ``node``."""
        return tuple(e for e in self.entries if e.node == node)
