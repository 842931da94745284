"""Cyclic PDO layout of the two EMA drives, PDO codec, scaling and bus load (sans-IO).

This module is a leaf of the CANopen layer: it holds the :class:`Frame` value
type every protocol core exchanges, the fixed process-data layout of the
drives (which object sits where in which PDO), the little-endian codecs of
those PDOs, the SDO write list that configures the layout in a drive, the
unit scaling between physical values and the drive's integers, and the CAN
bus load of one SYNC cycle. Nothing here touches a bus, a clock or a file.

Layout per drive with node id ``n`` (the master is the SYNC producer):

=======  ==========  =========================  ==============================================
PDO      COB-ID      transmission type          mapped objects (little endian)
=======  ==========  =========================  ==============================================
RPDO1    0x200 + n   1 (sync, applied at SYNC)  0x6040 controlword u16, 0x607A target position
                                                i32 [inc], 0x6071 target torque i16 [per mille]
RPDO2    0x300 + n   255 (event, on reception)  0x6060 modes of operation i8
TPDO1    0x180 + n   1 (sent on every SYNC)     0x6041 statusword u16, 0x6064 position actual
                                                value i32 [inc], 0x6061 modes display i8
TPDO2    0x280 + n   1 (sent on every SYNC)     0x2100 LVDT stroke i32 [0.001 mm],
                                                0x2101 load-cell force i32 [0.1 N]
=======  ==========  =========================  ==============================================
"""

from __future__ import annotations

import math
import operator
import struct
from dataclasses import dataclass, field
from enum import Enum

from canopen.objectdictionary import datatypes as dt

from hil.errors import EmacheckError, InputError

# --------------------------------------------------------------------------- frames

MAX_NODE_ID = 127
SYNC_COB_ID = 0x080  #: COB-ID of the SYNC object (0x1005 default)
EMCY_COB_ID_BASE = 0x080  #: EMCY COB-ID = 0x80 + node id (0x1014 default)
HEARTBEAT_COB_ID_BASE = 0x700  #: NMT error control (heartbeat) COB-ID = 0x700 + node id


class FrameError(EmacheckError, ValueError):
    """A CAN frame that cannot exist (identifier not 11 bit, more than 8 data bytes)."""


@dataclass(frozen=True, slots=True)
class Frame:
    """One classic CAN data frame with an 11-bit identifier.

    Attributes
    ----------
    arbitration_id : int
        The 11-bit identifier (COB-ID), 0..0x7FF.
    data : bytes
        0..8 data bytes; a ``bytearray`` or list of ints is converted to ``bytes``.
    """

    arbitration_id: int
    data: bytes = b""

    def __post_init__(self) -> None:
        try:
            can_id = operator.index(self.arbitration_id)
        except TypeError:
            raise FrameError(
                f"arbitration_id must be an int, got {type(self.arbitration_id).__name__}"
            ) from None
        if not 0 <= can_id <= 0x7FF:
            raise FrameError(f"arbitration_id 0x{can_id:X} is not an 11-bit identifier (0..0x7FF)")
        data = bytes(self.data)
        if len(data) > 8:
            raise FrameError(f"frame 0x{can_id:03X}: {len(data)} data bytes, a CAN frame holds at most 8")
        object.__setattr__(self, "arbitration_id", can_id)
        object.__setattr__(self, "data", data)

    def __str__(self) -> str:
        return f"{self.arbitration_id:03X}#{self.data.hex().upper()}"

    @classmethod
    def trusted(cls, arbitration_id: int, data: bytes) -> "Frame":
        """A frame from a source that already guarantees an 11-bit id and <= 8 bytes of
        ``bytes`` (a python-can message, a struct-packed PDO): no re-validation (hot path)."""
        f = object.__new__(cls)
        object.__setattr__(f, "arbitration_id", arbitration_id)
        object.__setattr__(f, "data", data)
        return f


def sync_frame() -> Frame:
    """The SYNC frame (COB-ID 0x080, no data: the SYNC counter is not used)."""
    return Frame(SYNC_COB_ID, b"")


def _check_node_id(node_id: int) -> int:
    try:
        n = operator.index(node_id)
    except TypeError:
        raise InputError(f"node_id must be an int in 1..127, got {node_id!r}") from None
    if not 1 <= n <= MAX_NODE_ID:
        raise InputError(f"node_id = {n} is outside 1..127")
    return n


# --------------------------------------------------------------------------- layout


class PdoError(EmacheckError, ValueError):
    """A PDO payload or value that does not fit the layout."""


class PdoLengthError(PdoError):
    """A PDO frame whose length differs from its mapping; names COB-ID, expected and got."""


class Direction(Enum):
    """Direction of a PDO, seen from the drive (CiA 301 naming)."""

    RX = "rx"  #: RPDO, master -> drive
    TX = "tx"  #: TPDO, drive -> master


_BITS = {
    dt.INTEGER8: 8,
    dt.UNSIGNED8: 8,
    dt.INTEGER16: 16,
    dt.UNSIGNED16: 16,
    dt.INTEGER32: 32,
    dt.UNSIGNED32: 32,
}
_STRUCT_CODE = {
    dt.INTEGER8: "b",
    dt.UNSIGNED8: "B",
    dt.INTEGER16: "h",
    dt.UNSIGNED16: "H",
    dt.INTEGER32: "i",
    dt.UNSIGNED32: "I",
}


@dataclass(frozen=True, slots=True)
class MappedObject:
    """One object mapped into a PDO.

    Attributes
    ----------
    name : str
        Short name, e.g. ``"controlword"``.
    index, subindex : int
        Object dictionary address.
    data_type : int
        CiA 301 data type code (``canopen.objectdictionary.datatypes``), integers only.
    """

    name: str
    index: int
    subindex: int
    data_type: int

    def __post_init__(self) -> None:
        if self.data_type not in _BITS:
            raise InputError(f"{self.name}: data type 0x{self.data_type:04X} cannot be mapped by this codec")

    @property
    def bit_length(self) -> int:
        """Mapped length in bits."""
        return _BITS[self.data_type]

    @property
    def mapping_entry(self) -> int:
        """The u32 mapping parameter ``index << 16 | subindex << 8 | bit_length``."""
        return (self.index << 16) | (self.subindex << 8) | self.bit_length


@dataclass(frozen=True, slots=True)
class PdoSpec:
    """One PDO of the layout.

    Attributes
    ----------
    name : str
        ``"RPDO1"`` .. (CiA 301 numbering from the drive's view).
    direction : Direction
        ``RX`` (master -> drive) or ``TX`` (drive -> master).
    number : int
        1-based PDO number; the communication parameter is at 0x1400 + number - 1
        (RX) or 0x1800 + number - 1 (TX), the mapping at that index + 0x200.
    cob_id_base : int
        COB-ID without the node id (COB-ID = base + node id).
    transmission_type : int
        1 = synchronous every SYNC, 255 = event driven (manufacturer specific).
    entries : tuple of MappedObject
        The mapped objects in payload order.
    """

    name: str
    direction: Direction
    number: int
    cob_id_base: int
    transmission_type: int
    entries: tuple[MappedObject, ...]

    @property
    def comm_index(self) -> int:
        """Index of the communication parameter record (0x1400.. / 0x1800..)."""
        return (0x1400 if self.direction is Direction.RX else 0x1800) + self.number - 1

    @property
    def mapping_index(self) -> int:
        """Index of the mapping parameter record (0x1600.. / 0x1A00..)."""
        return self.comm_index + 0x200

    @property
    def length_bytes(self) -> int:
        """Payload length in bytes (sum of the mapped bit lengths / 8)."""
        return sum(e.bit_length for e in self.entries) // 8

    @property
    def is_synchronous(self) -> bool:
        """True for transmission types 1..240 (one frame per 1..240 SYNCs)."""
        return 1 <= self.transmission_type <= 240

    @property
    def struct_format(self) -> str:
        """``struct`` format of the payload, little endian."""
        return "<" + "".join(_STRUCT_CODE[e.data_type] for e in self.entries)

    def cob_id(self, node_id: int) -> int:
        """COB-ID of this PDO for drive ``node_id``."""
        return self.cob_id_base + _check_node_id(node_id)


@dataclass(frozen=True, slots=True)
class SdoWrite:
    """One SDO download the master performs to configure a drive.

    ``data`` is the little-endian value with the object's exact size.
    """

    index: int
    subindex: int
    data: bytes
    what: str = field(default="", compare=False)


def _u32(v: int) -> bytes:
    return struct.pack("<I", v)


def _u8(v: int) -> bytes:
    return struct.pack("<B", v)


COB_ID_INVALID = 0x8000_0000  #: bit 31 of a PDO COB-ID: PDO does not exist / is not valid


@dataclass(frozen=True, slots=True)
class PdoLayout:
    """The cyclic process-data layout of one drive type."""

    pdos: tuple[PdoSpec, ...]

    def __getitem__(self, name: str) -> PdoSpec:
        for p in self.pdos:
            if p.name == name:
                return p
        raise KeyError(name)

    def configuration_writes(self, node_id: int) -> list[SdoWrite]:
        """The SDO downloads that configure this layout in drive ``node_id``.

        Per PDO, in order (CiA 301 7.5.2.35/36 procedure): disable the PDO
        (COB-ID with bit 31 set), set the number of mapped objects to 0, write
        the mapping entries, set the number of mapped objects, set the
        transmission type, enable the PDO (COB-ID with bit 31 clear).

        Parameters
        ----------
        node_id : int
            Node id of the drive, 1..127.

        Returns
        -------
        list of SdoWrite
            COB-IDs and mapping entries as u32, counts and transmission types as u8.
        """
        n = _check_node_id(node_id)
        writes: list[SdoWrite] = []
        for p in self.pdos:
            cob = p.cob_id_base + n
            c, m = p.comm_index, p.mapping_index
            writes.append(SdoWrite(c, 1, _u32(cob | COB_ID_INVALID), f"{p.name} disable"))
            writes.append(SdoWrite(m, 0, _u8(0), f"{p.name} clear mapping"))
            for k, e in enumerate(p.entries, start=1):
                writes.append(SdoWrite(m, k, _u32(e.mapping_entry), f"{p.name} map {e.name}"))
            writes.append(SdoWrite(m, 0, _u8(len(p.entries)), f"{p.name} {len(p.entries)} objects"))
            writes.append(SdoWrite(c, 2, _u8(p.transmission_type), f"{p.name} transmission type"))
            writes.append(SdoWrite(c, 1, _u32(cob), f"{p.name} enable"))
        return writes

    def find(self, cob_id: int) -> tuple[PdoSpec, int] | None:
        """The PDO and node id a COB-ID belongs to, or None if it is no PDO of this layout."""
        for p in self.pdos:
            n = cob_id - p.cob_id_base
            if 1 <= n <= MAX_NODE_ID:
                return p, n
        return None


CONTROLWORD = MappedObject("controlword", 0x6040, 0, dt.UNSIGNED16)
TARGET_POSITION = MappedObject("target_position_inc", 0x607A, 0, dt.INTEGER32)
TARGET_TORQUE = MappedObject("target_torque_permille", 0x6071, 0, dt.INTEGER16)
MODES_OF_OPERATION = MappedObject("modes_of_operation", 0x6060, 0, dt.INTEGER8)
STATUSWORD = MappedObject("statusword", 0x6041, 0, dt.UNSIGNED16)
POSITION_ACTUAL = MappedObject("position_inc", 0x6064, 0, dt.INTEGER32)
MODES_DISPLAY = MappedObject("mode_display", 0x6061, 0, dt.INTEGER8)
LVDT_STROKE = MappedObject("lvdt_um", 0x2100, 0, dt.INTEGER32)
LOADCELL_FORCE = MappedObject("force_dN", 0x2101, 0, dt.INTEGER32)

RPDO1 = PdoSpec("RPDO1", Direction.RX, 1, 0x200, 1, (CONTROLWORD, TARGET_POSITION, TARGET_TORQUE))
RPDO2 = PdoSpec("RPDO2", Direction.RX, 2, 0x300, 255, (MODES_OF_OPERATION,))
TPDO1 = PdoSpec("TPDO1", Direction.TX, 1, 0x180, 1, (STATUSWORD, POSITION_ACTUAL, MODES_DISPLAY))
TPDO2 = PdoSpec("TPDO2", Direction.TX, 2, 0x280, 1, (LVDT_STROKE, LOADCELL_FORCE))

#: The layout the master configures in every drive and the simulated drives default to.
DEFAULT_LAYOUT = PdoLayout((RPDO1, RPDO2, TPDO1, TPDO2))


# --------------------------------------------------------------------------- decoded contents

_I8 = (-(2**7), 2**7 - 1)
_U16 = (0, 2**16 - 1)
_I16 = (-(2**15), 2**15 - 1)
_I32 = (-(2**31), 2**31 - 1)


def _check_fields(obj: object, ranges: dict[str, tuple[int, int]]) -> None:
    cls = type(obj).__name__
    for name, (lo, hi) in ranges.items():
        raw = getattr(obj, name)
        if isinstance(raw, bool):
            raise PdoError(f"{cls}.{name} must be an int, got bool")
        try:
            v = operator.index(raw)
        except TypeError:
            raise PdoError(f"{cls}.{name} must be an int, got {type(raw).__name__} {raw!r}") from None
        if not lo <= v <= hi:
            raise PdoError(f"{cls}.{name} = {v} is outside {lo}..{hi}")
        object.__setattr__(obj, name, v)


@dataclass(frozen=True, slots=True)
class Rpdo1:
    """RPDO1 contents: controlword, target position [increments], target torque [per mille]."""

    controlword: int
    target_position_inc: int
    target_torque_permille: int

    def __post_init__(self) -> None:
        _check_fields(self, {"controlword": _U16, "target_position_inc": _I32, "target_torque_permille": _I16})


@dataclass(frozen=True, slots=True)
class Rpdo2:
    """RPDO2 contents: modes of operation (0x6060, e.g. 8 = CSP, 10 = CST)."""

    mode: int

    def __post_init__(self) -> None:
        _check_fields(self, {"mode": _I8})


@dataclass(frozen=True, slots=True)
class Tpdo1:
    """TPDO1 contents: statusword, position actual value [increments], modes display."""

    statusword: int
    position_inc: int
    mode_display: int

    def __post_init__(self) -> None:
        _check_fields(self, {"statusword": _U16, "position_inc": _I32, "mode_display": _I8})


@dataclass(frozen=True, slots=True)
class Tpdo2:
    """TPDO2 contents: LVDT stroke [0.001 mm = um], load-cell force [0.1 N = dN]."""

    lvdt_um: int
    force_dN: int

    def __post_init__(self) -> None:
        _check_fields(self, {"lvdt_um": _I32, "force_dN": _I32})


_RPDO1_S = struct.Struct(RPDO1.struct_format)  # "<Hih", 8 bytes
_RPDO2_S = struct.Struct(RPDO2.struct_format)  # "<b", 1 byte
_TPDO1_S = struct.Struct(TPDO1.struct_format)  # "<Hib", 7 bytes
_TPDO2_S = struct.Struct(TPDO2.struct_format)  # "<ii", 8 bytes


def _trusted(cls: type, values: tuple) -> object:
    """Instance of a PDO-contents dataclass from ``struct.unpack`` values, which are in
    range by construction: skips ``__post_init__`` validation (hot path of the master)."""
    obj = object.__new__(cls)
    for name, v in zip(cls.__slots__, values):
        object.__setattr__(obj, name, v)
    return obj


def _payload(frame: Frame, spec: PdoSpec, s: struct.Struct) -> bytes:
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a hil.pdo.Frame, got {type(frame).__name__}")
    n = frame.arbitration_id - spec.cob_id_base
    if not 1 <= n <= MAX_NODE_ID:
        raise PdoError(
            f"COB-ID 0x{frame.arbitration_id:03X} is not a {spec.name} COB-ID "
            f"(0x{spec.cob_id_base + 1:03X}..0x{spec.cob_id_base + MAX_NODE_ID:03X})"
        )
    if len(frame.data) != s.size:
        raise PdoLengthError(
            f"{spec.name} COB-ID 0x{frame.arbitration_id:03X}: expected {s.size} data bytes, "
            f"got {len(frame.data)}"
        )
    return frame.data


def encode_rpdo1(node_id: int, msg: Rpdo1) -> Frame:
    """RPDO1 frame to drive ``node_id``: ``<H i h`` = controlword, target position, target torque."""
    return Frame.trusted(RPDO1.cob_id(node_id), _RPDO1_S.pack(msg.controlword, msg.target_position_inc,
                                                      msg.target_torque_permille))


def decode_rpdo1(frame: Frame) -> Rpdo1:
    """Decode an RPDO1 frame; raises PdoLengthError unless it has exactly 8 data bytes."""
    return _trusted(Rpdo1, _RPDO1_S.unpack(_payload(frame, RPDO1, _RPDO1_S)))


def encode_rpdo2(node_id: int, msg: Rpdo2) -> Frame:
    """RPDO2 frame to drive ``node_id``: ``<b`` = modes of operation."""
    return Frame.trusted(RPDO2.cob_id(node_id), _RPDO2_S.pack(msg.mode))


def decode_rpdo2(frame: Frame) -> Rpdo2:
    """Decode an RPDO2 frame; raises PdoLengthError unless it has exactly 1 data byte."""
    return _trusted(Rpdo2, _RPDO2_S.unpack(_payload(frame, RPDO2, _RPDO2_S)))


def encode_tpdo1(node_id: int, msg: Tpdo1) -> Frame:
    """TPDO1 frame from drive ``node_id``: ``<H i b`` = statusword, position, mode display."""
    return Frame.trusted(TPDO1.cob_id(node_id), _TPDO1_S.pack(msg.statusword, msg.position_inc, msg.mode_display))


def decode_tpdo1(frame: Frame) -> Tpdo1:
    """Decode a TPDO1 frame; raises PdoLengthError unless it has exactly 7 data bytes."""
    return _trusted(Tpdo1, _TPDO1_S.unpack(_payload(frame, TPDO1, _TPDO1_S)))


def encode_tpdo2(node_id: int, msg: Tpdo2) -> Frame:
    """TPDO2 frame from drive ``node_id``: ``<i i`` = LVDT stroke [um], force [dN]."""
    return Frame.trusted(TPDO2.cob_id(node_id), _TPDO2_S.pack(msg.lvdt_um, msg.force_dN))


def decode_tpdo2(frame: Frame) -> Tpdo2:
    """Decode a TPDO2 frame; raises PdoLengthError unless it has exactly 8 data bytes."""
    return _trusted(Tpdo2, _TPDO2_S.unpack(_payload(frame, TPDO2, _TPDO2_S)))


# --------------------------------------------------------------------------- scaling


def _finite(name: str, value: float, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number [{unit}], got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} = {v} [{unit}] must be finite")
    return v


def _positive(name: str, value: float, unit: str) -> float:
    v = _finite(name, value, unit)
    if v <= 0.0:
        raise InputError(f"{name} = {v} [{unit}] must be > 0")
    return v


def _clip_round(x: float, lo: int, hi: int) -> int:
    return int(min(max(round(x), lo), hi))


def increments_per_rad(counts_per_rev: int) -> float:
    """Position increments per radian of motor angle.

    Parameters
    ----------
    counts_per_rev : int
        Encoder increments per motor revolution (0x608F:01 / 0x608F:02), 4096
        for the 12-bit resolver.

    Returns
    -------
    float
        Increments per rad [1/rad].

    Notes
    -----
    .. math:: k = \\frac{N_{rev}}{2 \\pi}

    4096 counts/rev gives 651.898... inc/rad.
    """
    return _positive("counts_per_rev", counts_per_rev, "increments/rev") / (2.0 * math.pi)


def rad_to_increments(angle_rad: float, counts_per_rev: int) -> int:
    """Motor angle [rad] to position increments (0x607A/0x6064), rounded, clipped to i32.

    Notes
    -----
    :math:`p = \\mathrm{round}(\\varphi \\, N_{rev} / 2\\pi)` [inc], clipped to
    -2**31 .. 2**31 - 1.
    """
    phi = _finite("angle_rad", angle_rad, "rad")
    return _clip_round(phi * increments_per_rad(counts_per_rev), *_I32)


def increments_to_rad(position_inc: int, counts_per_rev: int) -> float:
    """Position increments to motor angle [rad].

    Notes
    -----
    :math:`\\varphi = 2\\pi \\, p / N_{rev}` [rad].
    """
    p = _finite("position_inc", position_inc, "increments")
    return p / increments_per_rad(counts_per_rev)


def force_to_permille(F_N: float, i_total_rad_per_mm: float, rated_torque_Nm: float) -> int:
    """Ram force [N] to a CST target torque (0x6071) in per mille of the rated torque.

    Parameters
    ----------
    F_N : float
        Ram force [N], positive in compression (the EMA pushes towards +s).
    i_total_rad_per_mm : float
        Total gear ratio motor angle / ram stroke [rad/mm], > 0.
    rated_torque_Nm : float
        Motor rated torque (0x6076 / 1000, the object is in mNm) [N m], > 0.

    Returns
    -------
    int
        Target torque [per mille of the rated torque], rounded to nearest
        (ties to even) and clipped to i16 (-32768..32767).

    Notes
    -----
    Lossless gear: the motor power equals the ram power,
    :math:`T \\omega = F v` with :math:`v = \\omega / (1000\\, i_{total})`, so

    .. math:: T = \\frac{F}{1000 \\, i_{total}}, \\qquad
              \\tau_{permille} = \\mathrm{round}\\left(1000 \\frac{T}{T_{rated}}\\right)

    with :math:`T` in N m, :math:`F` in N, :math:`i_{total}` in rad/mm. For
    i_total = 5.0265 rad/mm and T_rated = 1 N m, 1 per mille is 5.03 N.
    """
    F = _finite("F_N", F_N, "N")
    i_total = _positive("i_total_rad_per_mm", i_total_rad_per_mm, "rad/mm")
    t_rated = _positive("rated_torque_Nm", rated_torque_Nm, "N m")
    torque_Nm = F / (i_total * 1000.0)
    return _clip_round(1000.0 * torque_Nm / t_rated, *_I16)


def permille_to_force_N(torque_permille: int, i_total_rad_per_mm: float, rated_torque_Nm: float) -> float:
    """Torque in per mille of the rated torque to the equivalent ram force [N].

    Notes
    -----
    Inverse of :func:`force_to_permille` (without rounding):
    :math:`F = 1000 \\, i_{total} \\, T_{rated} \\, \\tau_{permille} / 1000` [N].
    """
    tau = _finite("torque_permille", torque_permille, "per mille")
    i_total = _positive("i_total_rad_per_mm", i_total_rad_per_mm, "rad/mm")
    t_rated = _positive("rated_torque_Nm", rated_torque_Nm, "N m")
    return tau / 1000.0 * t_rated * i_total * 1000.0


def mm_to_lvdt_um(stroke_mm: float) -> int:
    """LVDT stroke [mm] to the 0x2100 integer [0.001 mm], rounded, clipped to i32."""
    return _clip_round(_finite("stroke_mm", stroke_mm, "mm") * 1000.0, *_I32)


def lvdt_um_to_mm(lvdt_um: int) -> float:
    """0x2100 LVDT stroke [0.001 mm] to mm."""
    return _finite("lvdt_um", lvdt_um, "0.001 mm") / 1000.0


def newton_to_force_dN(F_N: float) -> int:
    """Load-cell force [N] to the 0x2101 integer [0.1 N], rounded, clipped to i32."""
    return _clip_round(_finite("F_N", F_N, "N") * 10.0, *_I32)


def force_dN_to_newton(force_dN: int) -> float:
    """0x2101 load-cell force [0.1 N] to N."""
    return _finite("force_dN", force_dN, "0.1 N") / 10.0


# --------------------------------------------------------------------------- bus load

FRAME_OVERHEAD_BITS = 47
"""Bits of a standard (11-bit) data frame besides the data field, including the
3-bit interframe space: SOF 1 + identifier 11 + RTR 1 + IDE 1 + r0 1 + DLC 4 +
CRC 15 + CRC delimiter 1 + ACK slot 1 + ACK delimiter 1 + EOF 7 + IFS 3."""


def frame_bits(n_bytes: int, *, worst_case: bool) -> int:
    """Bits on the bus of one standard data frame with ``n_bytes`` data bytes.

    Notes
    -----
    Nominal :math:`47 + 8n`; worst case adds the maximum number of stuff bits,
    which can occur in the 34 + 8n bits from SOF to the end of the CRC:
    :math:`\\lfloor (34 + 8n - 1) / 4 \\rfloor`. 8 bytes: 111 / 135 bits.
    """
    n = operator.index(n_bytes)
    if not 0 <= n <= 8:
        raise InputError(f"n_bytes = {n} is outside 0..8 [bytes]")
    bits = FRAME_OVERHEAD_BITS + 8 * n
    if worst_case:
        bits += (34 + 8 * n - 1) // 4
    return bits


@dataclass(frozen=True, slots=True)
class BusLoadItem:
    """One kind of frame in the bus load.

    ``frames_per_cycle`` may be fractional (heartbeats) or 0 (event-driven PDOs).
    """

    name: str
    data_bytes: int
    frames_per_cycle: float
    bits_per_frame_nominal: int
    bits_per_frame_worst: int


@dataclass(frozen=True, slots=True)
class BusLoad:
    """Bus load of one SYNC cycle.

    Attributes
    ----------
    items : tuple of BusLoadItem
        SYNC, every PDO of the layout (all drives together) and the heartbeats.
    bits_per_cycle_nominal, bits_per_cycle_worst : float
        Sum of ``frames_per_cycle * bits_per_frame`` without / with worst-case stuffing.
    load_nominal, load_worst : float
        Fraction of the bit rate: bits per cycle / (bit rate * SYNC period).
    event_bits_worst : float
        Worst-case bits of sending every event-driven PDO once to every drive
        (the cycle in which the master changes the mode of both drives); not
        included in ``bits_per_cycle_*``.
    """

    bitrate_bps: float
    sync_period_s: float
    n_drives: int
    items: tuple[BusLoadItem, ...]
    bits_per_cycle_nominal: float
    bits_per_cycle_worst: float
    load_nominal: float
    load_worst: float
    event_bits_worst: float


def bus_load(
    layout: PdoLayout,
    n_drives: int,
    bitrate_bps: float,
    sync_period_s: float,
    heartbeat_period_s: float,
    *,
    heartbeat_producers: int | None = None,
) -> BusLoad:
    """Bits per SYNC cycle and bus load of the cyclic CANopen traffic.

    Parameters
    ----------
    layout : PdoLayout
        PDO layout of every drive.
    n_drives : int
        Number of drives, >= 1.
    bitrate_bps : float
        CAN bit rate [bit/s], > 0.
    sync_period_s : float
        SYNC (communication cycle) period [s], > 0.
    heartbeat_period_s : float
        Heartbeat producer time [s], > 0, or 0 for no heartbeats.
    heartbeat_producers : int, optional
        Number of heartbeat producers; default ``n_drives + 1`` (every drive
        and the master, whose heartbeat the drives consume via 0x1016).

    Returns
    -------
    BusLoad

    Notes
    -----
    Per cycle: one SYNC (0 bytes), for every drive one frame of every
    synchronous PDO with transmission type ``k`` every ``k`` SYNCs, and
    ``producers * T_sync / T_hb`` heartbeats (1 byte). Event-driven PDOs
    (type >= 241) are listed with 0 frames per cycle. Frame lengths as in
    :func:`frame_bits`:

    .. math:: b = 47 + 8n \\;(+\\lfloor (34 + 8n - 1)/4 \\rfloor \\text{ worst case}),
              \\qquad U = \\frac{\\sum_i f_i \\, b_i}{R \\, T_{sync}}

    SDO traffic (configuration before the cyclic phase) is not included.
    """
    if not isinstance(layout, PdoLayout):
        raise InputError(f"layout must be a PdoLayout, got {type(layout).__name__}")
    nd = operator.index(n_drives)
    if nd < 1:
        raise InputError(f"n_drives = {nd} must be >= 1")
    rate = _positive("bitrate_bps", bitrate_bps, "bit/s")
    t_sync = _positive("sync_period_s", sync_period_s, "s")
    t_hb = _finite("heartbeat_period_s", heartbeat_period_s, "s")
    if t_hb < 0.0:
        raise InputError(f"heartbeat_period_s = {t_hb} [s] must be >= 0 (0 = no heartbeat)")
    producers = nd + 1 if heartbeat_producers is None else operator.index(heartbeat_producers)
    if producers < 0:
        raise InputError(f"heartbeat_producers = {producers} must be >= 0")

    def item(name: str, n_bytes: int, per_cycle: float) -> BusLoadItem:
        return BusLoadItem(name, n_bytes, per_cycle,
                           frame_bits(n_bytes, worst_case=False), frame_bits(n_bytes, worst_case=True))

    items = [item("SYNC", 0, 1.0)]
    event_bits = 0.0
    for p in layout.pdos:
        if p.is_synchronous:
            items.append(item(p.name, p.length_bytes, nd / p.transmission_type))
        else:
            it = item(p.name, p.length_bytes, 0.0)
            items.append(it)
            event_bits += nd * it.bits_per_frame_worst
    hb_per_cycle = producers * t_sync / t_hb if t_hb > 0.0 else 0.0
    items.append(item("heartbeat", 1, hb_per_cycle))

    nominal = sum(i.frames_per_cycle * i.bits_per_frame_nominal for i in items)
    worst = sum(i.frames_per_cycle * i.bits_per_frame_worst for i in items)
    capacity = rate * t_sync
    return BusLoad(rate, t_sync, nd, tuple(items), nominal, worst, nominal / capacity, worst / capacity,
                   event_bits)
