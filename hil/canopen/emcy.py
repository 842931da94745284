"""CiA 301 emergency objects (EMCY): error codes, the error register, the frame.

Both ends use it: the simulated drives produce EMCYs (:func:`emcy_frame`,
:func:`error_register_bits`), the master consumes them (:func:`decode_emcy`,
:class:`Emcy`). Sans-IO.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from hil.canopen.frame import Frame
from hil.canopen.validate import error_code

_EMCY = struct.Struct("<HB5s")  # error code u16, error register 0x1001 u8, 5 manufacturer bytes


class EmcyCode(IntEnum):
    """Common CiA 301 / CiA 402 emergency error codes (0x603F / EMCY bytes 0-1)."""

    NO_ERROR = 0x0000  #: error reset or no error
    GENERIC = 0x1000
    CURRENT = 0x2000
    OVER_CURRENT = 0x2310
    SHORT_CIRCUIT = 0x2320
    VOLTAGE = 0x3000
    DC_LINK_OVER_VOLTAGE = 0x3210
    DC_LINK_UNDER_VOLTAGE = 0x3220
    TEMPERATURE = 0x4000
    DRIVE_OVER_TEMPERATURE = 0x4310
    MOTOR_OVER_TEMPERATURE = 0x4410
    DEVICE_HARDWARE = 0x5000
    SOFTWARE = 0x6000
    MONITORING = 0x8000
    COMMUNICATION = 0x8100
    CAN_OVERRUN = 0x8110
    CAN_PASSIVE = 0x8120
    LIFE_GUARD_OR_HEARTBEAT = 0x8130
    CAN_BUS_OFF_RECOVERED = 0x8140
    PDO_LENGTH = 0x8210  #: PDO not processed due to length error
    PDO_LENGTH_EXCEEDED = 0x8220
    SYNC_LENGTH = 0x8240
    RPDO_TIMEOUT = 0x8250
    FOLLOWING_ERROR = 0x8611
    SENSOR = 0x7300
    POSITION_SENSOR = 0x7320


def describe_emcy(code: int) -> str:
    """Words for an error code: its name, its class's name, or "manufacturer specific"/"unknown"."""
    try:
        return EmcyCode(code).name.replace("_", " ").lower()
    except ValueError:
        try:
            return EmcyCode(code & 0xFF00).name.replace("_", " ").lower() + " (class)"
        except ValueError:
            return "manufacturer specific" if code >= 0xFF00 else "unknown"


def error_register_bits(code: int) -> int:
    """The error register 0x1001 bits an EMCY error code sets (CiA 301 Table 48).

    Parameters
    ----------
    code : int
        EMCY error code, 0..0xFFFF.

    Returns
    -------
    int
        0 for code 0; otherwise bit 0 (generic) plus bit 1 for 0x2xxx
        (current), bit 2 for 0x3xxx (voltage), bit 3 for 0x4xxx (temperature),
        bit 4 for 0x81xx/0x82xx (communication), bit 7 for 0xFFxx
        (manufacturer specific).

    Notes
    -----
    E.g. 0x2310 (continuous over-current) -> 0x03, 0x8210 (PDO length) -> 0x11.
    """
    c = error_code(code, "code", allow_zero=True)
    if c == 0:
        return 0
    reg = 0x01
    group = c >> 12
    if group == 0x2:
        reg |= 0x02
    elif group == 0x3:
        reg |= 0x04
    elif group == 0x4:
        reg |= 0x08
    elif c >> 8 in (0x81, 0x82):
        reg |= 0x10
    elif c >> 8 == 0xFF:
        reg |= 0x80
    return reg


@dataclass(frozen=True, slots=True)
class Emcy:
    """One received EMCY: when, from which node, its code and error register."""

    t_s: float
    node_id: int
    code: int
    error_register: int
    data: bytes

    def __str__(self) -> str:
        return (f"node {self.node_id}: EMCY 0x{self.code:04X} ({describe_emcy(self.code)}), "
                f"error register 0x{self.error_register:02X}")


def emcy_frame(cob_id: int, code: int, error_register: int) -> Frame:
    """The EMCY frame: error code u16, error register u8, five zero manufacturer bytes."""
    return Frame(cob_id, _EMCY.pack(code, error_register, b""))


def decode_emcy(node_id: int, data: bytes, t_s: float) -> Emcy | None:
    """An EMCY's contents, or None when it is not 8 bytes long (a malformed frame)."""
    if len(data) != 8:
        return None
    code, reg, extra = _EMCY.unpack(data)
    return Emcy(t_s, node_id, code, reg, bytes(data[3:]))
