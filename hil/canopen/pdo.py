"""PDO layouts and the PDO codec (sans-IO).

A :class:`PdoLayout` is the cyclic process data of one node: which objects sit
where in which PDO, with which COB-ID and transmission type. Layouts are
planned from the rig's signal map and each node's EDS
(:mod:`hil.canopen.plan`); this module holds the vocabulary, the one
little-endian codec of PDO payloads (:func:`pdo_codec`, held by each
:class:`PdoSpec`: :meth:`PdoSpec.pack`, :meth:`PdoSpec.unpack`; the simulated
drives' PDO engine uses it too), the one round-and-clip of a value into an
integer object (:func:`encode_raw`, :func:`raw_encoder`) and the SDO write
list that configures a layout in a node (CiA 301 7.5.2.35/36).
Unit scaling is :class:`hil.canopen.signalmap.Scale`, the bus load
:mod:`hil.canopen.busload`. Nothing here touches a bus, a clock or a file.

The shipped EMA drive (``profiles/ema_drive.eds``) with the shipped signal map
gets, per drive with node id ``n``:

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
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from functools import cache

from canopen.objectdictionary import datatypes as dt

from hil.canopen.errors import CanopenError, CanopenInputError
from hil.canopen.frame import Frame

__all__ = ["COB_ID_INVALID", "COB_ID_NO_RTR", "Direction", "MappedObject", "PdoCodec", "PdoError", "PdoLayout",
           "PdoLengthError", "PdoSpec", "SdoWrite", "TYPE_BITS", "TYPE_RANGE", "encode_raw", "pdo_codec", "raw_encoder",
           "predefined_cob_id"]

# --------------------------------------------------------------------------- layout


class PdoError(CanopenError, ValueError):
    """A PDO payload or value that does not fit the layout."""


class PdoLengthError(PdoError):
    """A PDO frame whose length differs from its mapping; names COB-ID, expected and got."""


class Direction(Enum):
    """Direction of a PDO, seen from the node (CiA 301 naming)."""

    RX = "rx"  #: RPDO, master -> node
    TX = "tx"  #: TPDO, node -> master


#: Bits of each data type a PDO of this codec can map, and its ``struct`` code.
TYPE_BITS: dict[int, tuple[int, str]] = {
    dt.INTEGER8: (8, "b"),
    dt.UNSIGNED8: (8, "B"),
    dt.INTEGER16: (16, "h"),
    dt.UNSIGNED16: (16, "H"),
    dt.INTEGER32: (32, "i"),
    dt.UNSIGNED32: (32, "I"),
    dt.REAL32: (32, "f"),
    dt.INTEGER64: (64, "q"),
    dt.UNSIGNED64: (64, "Q"),
}

#: The integer range of each integer data type (a value outside is clipped when encoded).
TYPE_RANGE: dict[int, tuple[int, int]] = {
    dt.INTEGER8: (-(2**7), 2**7 - 1),
    dt.UNSIGNED8: (0, 2**8 - 1),
    dt.INTEGER16: (-(2**15), 2**15 - 1),
    dt.UNSIGNED16: (0, 2**16 - 1),
    dt.INTEGER32: (-(2**31), 2**31 - 1),
    dt.UNSIGNED32: (0, 2**32 - 1),
    dt.INTEGER64: (-(2**63), 2**63 - 1),
    dt.UNSIGNED64: (0, 2**64 - 1),
}


def encode_raw(data_type: int, x: float) -> int | float:
    """The raw value of ``x`` for an entry of ``data_type``: rounded to nearest (ties to even) and clipped
    to the integer type's range (:data:`TYPE_RANGE`); a type without a range (REAL32) as it is.

    .. math:: r = \\min(\\max(\\mathrm{round}(x),\\ lo),\\ hi)

    ``x`` is the value in the object's unit (increments, per mille, 0.001 mm, ...): finite (``round``
    raises ValueError for NaN and OverflowError for an infinity). The hot paths hold
    :func:`raw_encoder` of their data type instead.
    """
    return raw_encoder(data_type)(x)


def _as_is(x: float) -> float:
    return x


@cache
def raw_encoder(data_type: int) -> Callable[[float], int | float]:
    """:func:`encode_raw` for one data type, its range bound once: ``raw_encoder(t)(x) == encode_raw(t, x)``
    (the one round-and-clip; the unit kernels of :mod:`hil.canopen.units`, the master's setpoints and the
    simulated drives' inputs call it per value)."""
    rng = TYPE_RANGE.get(data_type)
    if rng is None:
        return _as_is
    lo, hi = rng

    def round_clip(x: float) -> int:
        v = round(x)
        return lo if v < lo else hi if v > hi else v

    return round_clip


# --------------------------------------------------------------------------- codec


@dataclass(frozen=True, slots=True)
class PdoCodec:
    """The codec of one PDO payload: its raw values <-> its little-endian bytes, compiled once.

    The one encoding path of process data: :meth:`PdoSpec.pack` / :meth:`PdoSpec.unpack` and their
    users (the master's :class:`~hil.canopen.cycle.SetpointEncoder`, the CAN-log reader; the
    :class:`~hil.canopen.cycle.CycleDecoder` calls its PDO's ``codec.unpack`` and ``PdoSpec.unpack`` only
    for the error of a wrong length) and the simulated drives' PDO engine (:mod:`sim.drives.pdo_engine`)
    all pack and unpack through the codec :func:`pdo_codec` gives for the payload's ``struct`` codes.

    Attributes
    ----------
    codes : str
        One ``struct`` code per mapped entry, in payload order (``"Hih"``: u16, i32, i16); little endian.
    size : int
        Payload length [bytes].
    pack : callable
        ``pack(*values) -> bytes``: the raw values (in range of their types) as the payload; raises
        ``struct.error`` for a value out of range or of the wrong kind, or the wrong number of values.
    unpack : callable
        ``unpack(data) -> tuple``: the raw values of a payload of exactly :attr:`size` bytes; raises
        ``struct.error`` for another length.
    """

    codes: str
    size: int
    pack: Callable[..., bytes] = field(repr=False, compare=False)
    unpack: Callable[[bytes], tuple] = field(repr=False, compare=False)


@cache
def pdo_codec(codes: str) -> PdoCodec:
    """The codec of a payload of these ``struct`` codes (built once per distinct mapping, then shared)."""
    st = struct.Struct("<" + codes)
    return PdoCodec(codes, st.size, st.pack, st.unpack)


# --------------------------------------------------------------------------- layout (continued)


@dataclass(frozen=True, slots=True)
class MappedObject:
    """One object mapped into a PDO.

    Attributes
    ----------
    name : str
        Short name, e.g. ``"controlword"`` (a signal of the map, or the EDS name of an object a
        fixed mapping carries besides).
    index, subindex : int
        Object dictionary address.
    data_type : int
        CiA 301 data type code (``canopen.objectdictionary.datatypes``), one of :data:`TYPE_BITS`.
    """

    name: str
    index: int
    subindex: int
    data_type: int

    def __post_init__(self) -> None:
        if self.data_type not in TYPE_BITS:
            raise CanopenInputError(f"{self.name}: data type 0x{self.data_type:04X} cannot be mapped by this codec")

    @property
    def bit_length(self) -> int:
        """Mapped length in bits."""
        return TYPE_BITS[self.data_type][0]

    @property
    def mapping_entry(self) -> int:
        """The u32 mapping parameter ``index << 16 | subindex << 8 | bit_length``."""
        return (self.index << 16) | (self.subindex << 8) | self.bit_length


COB_ID_INVALID = 0x8000_0000  #: bit 31 of a PDO COB-ID: PDO does not exist / is not valid
COB_ID_NO_RTR = 0x4000_0000  #: bit 30 of a PDO COB-ID: no RTR allowed on this PDO


def predefined_cob_id(direction: Direction, number: int, node_id: int) -> int | None:
    """The COB-ID of PDO ``number`` (1..4) of ``node_id`` in CiA 301's predefined connection set.

    TPDO k: 0x180 + 0x100 (k - 1) + n, RPDO k: 0x200 + 0x100 (k - 1) + n; None for k > 4.
    """
    if not 1 <= number <= 4:
        return None
    return (0x180 if direction is Direction.TX else 0x200) + 0x100 * (number - 1) + node_id


@dataclass(frozen=True, slots=True)
class PdoSpec:
    """One PDO of a node's layout.

    Attributes
    ----------
    name : str
        ``"RPDO1"`` .. (CiA 301 numbering from the node's view).
    direction : Direction
        ``RX`` (master -> node) or ``TX`` (node -> master).
    number : int
        1-based PDO number; the communication parameter is at 0x1400 + number - 1
        (RX) or 0x1800 + number - 1 (TX), the mapping at that index + 0x200.
    cob_id : int
        The PDO's 11-bit COB-ID.
    transmission_type : int
        1 = synchronous every SYNC, 255 = event driven (manufacturer specific).
    entries : tuple of MappedObject
        The mapped objects in payload order.
    write_mapping, write_cob_id, write_transmission : bool
        Whether the master configures the mapping, the COB-ID and the transmission type by SDO
        (False: the node's EDS fixes it and it already is as planned).
    rtr_bit : int
        :data:`COB_ID_NO_RTR` when the COB-ID is written with bit 30 set (as the node's default has it).
    """

    name: str
    direction: Direction
    number: int
    cob_id: int
    transmission_type: int
    entries: tuple[MappedObject, ...]
    write_mapping: bool = True
    write_cob_id: bool = True
    write_transmission: bool = True
    rtr_bit: int = 0
    codec: PdoCodec = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not 0 <= self.cob_id <= 0x7FF:
            raise CanopenInputError(f"{self.name}: COB-ID 0x{self.cob_id:X} is not an 11-bit identifier")
        object.__setattr__(self, "codec", pdo_codec(self.struct_format[1:]))
        if self.codec.size > 8:
            raise CanopenInputError(f"{self.name}: {self.codec.size * 8} mapped bits exceed the 64 of a CAN frame")

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
        return "<" + "".join(TYPE_BITS[e.data_type][1] for e in self.entries)

    def unpack(self, frame: Frame) -> tuple:
        """The mapped values of a frame of this PDO; PdoLengthError unless its length is exact."""
        try:
            return self.codec.unpack(frame.data)  # (struct.error only for another length: data is bytes)
        except struct.error:
            raise PdoLengthError(f"{self.name} COB-ID 0x{frame.arbitration_id:03X}: expected "
                                 f"{self.codec.size} data bytes, got {len(frame.data)}") from None

    def pack(self, values) -> Frame:
        """The frame of this PDO with ``values`` (raw, in entry order, in range of their types: see
        :func:`encode_raw`)."""
        try:
            return _trusted(self.cob_id, self.codec.pack(*values))
        except struct.error as exc:
            raise PdoError(f"{self.name} COB-ID 0x{self.cob_id:03X}: cannot encode {tuple(values)!r}: {exc}") \
                from None

    def configuration_writes(self) -> list[SdoWrite]:
        """The SDO downloads that configure this PDO (CiA 301 7.5.2.35/36 procedure).

        Disable the PDO (COB-ID with bit 31 set), set the number of mapped
        objects to 0, write the mapping entries, set the number of mapped
        objects, set the transmission type, enable the PDO (COB-ID with bit 31
        clear); each step only where this PDO writes it (``write_*``).
        """
        writes: list[SdoWrite] = []
        c, m = self.comm_index, self.mapping_index
        cob = self.cob_id | self.rtr_bit
        if self.write_cob_id:
            writes.append(SdoWrite(c, 1, _u32(cob | COB_ID_INVALID), f"{self.name} disable"))
        if self.write_mapping:
            writes.append(SdoWrite(m, 0, _u8(0), f"{self.name} clear mapping"))
            for k, e in enumerate(self.entries, start=1):
                writes.append(SdoWrite(m, k, _u32(e.mapping_entry), f"{self.name} map {e.name}"))
            writes.append(SdoWrite(m, 0, _u8(len(self.entries)), f"{self.name} {len(self.entries)} objects"))
        if self.write_transmission:
            writes.append(SdoWrite(c, 2, _u8(self.transmission_type), f"{self.name} transmission type"))
        if self.write_cob_id:
            writes.append(SdoWrite(c, 1, _u32(cob), f"{self.name} enable"))
        return writes


_trusted = Frame.trusted  # (an 11-bit COB-ID and at most 8 packed bytes: checked in __post_init__)


@dataclass(frozen=True, slots=True)
class SdoWrite:
    """One SDO download the master performs to configure a node.

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


@dataclass(frozen=True, slots=True)
class PdoLayout:
    """The cyclic process-data layout of one node.

    Attributes
    ----------
    node_id : int
        The node, 1..127.
    pdos : tuple of PdoSpec
        The PDOs the check uses.
    disable : tuple of (int, int)
        Other PDOs of the node, enabled by its EDS, that the master disables: (communication
        index, the COB-ID word with bit 31 set).
    """

    node_id: int
    pdos: tuple[PdoSpec, ...]
    disable: tuple[tuple[int, int], ...] = ()

    def __getitem__(self, name: str) -> PdoSpec:
        for p in self.pdos:
            if p.name == name:
                return p
        raise KeyError(name)

    def configuration_writes(self) -> list[SdoWrite]:
        """The SDO downloads that configure this layout in the node: the unused PDOs disabled,
        then every PDO of the layout (:meth:`PdoSpec.configuration_writes`)."""
        writes = [SdoWrite(c, 1, _u32(word), f"PDO 0x{c:04X} not used: disable") for c, word in self.disable]
        for p in self.pdos:
            writes += p.configuration_writes()
        return writes
