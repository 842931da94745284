"""Cyclic PDO layout of the two EMA drives and the PDO codec (sans-IO).

The fixed process-data layout of the drives (which object sits where in
which PDO), the little-endian codecs of those PDOs, and the SDO write list
that configures the layout in a drive. Unit scaling is in
:mod:`hil.canopen.units`, the bus load in :mod:`hil.canopen.busload`.
Nothing here touches a bus, a clock or a file.

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

import struct
from dataclasses import dataclass, field
from enum import Enum

from canopen.objectdictionary import datatypes as dt

from hil.canopen.errors import CanopenError, InputError
from hil.canopen.frame import MAX_NODE_ID, Frame, split_cob_id
from hil.canopen.validate import integer
from hil.canopen.validate import node_id as _node_id

# --------------------------------------------------------------------------- layout


class PdoError(CanopenError, ValueError):
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
        return self.cob_id_base + _node_id(node_id)


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
        n = _node_id(node_id)
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
        base, n = split_cob_id(cob_id)
        for p in self.pdos:
            if p.cob_id_base == base and n >= 1:
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
        v = integer(f"{cls}.{name}", getattr(obj, name), lo, hi, error=PdoError)
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
        raise InputError(f"frame must be a hil.canopen.frame.Frame, got {type(frame).__name__}")
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
