"""The CAN frame every protocol core exchanges, and the CiA 301 COB-ID plan.

:class:`Frame` is a classic data frame with an 11-bit identifier. The
predefined connection set of CiA 301 gives each service a function code
(bits 10..7 of the COB-ID) and each node its id (bits 6..0):
:func:`split_cob_id` is the one place that takes a COB-ID apart, used by the
master, the CAN-log decoder and the PDO layout.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

from hil.canopen.errors import CanopenError
from hil.canopen.validate import MAX_NODE_ID

NMT_COB_ID = 0x000  #: NMT commands (master -> all nodes)
SYNC_COB_ID = 0x080  #: COB-ID of the SYNC object (0x1005 default)
EMCY_COB_ID_BASE = 0x080  #: EMCY COB-ID = 0x80 + node id (0x1014 default)
SDO_RX_COB_ID_BASE = 0x580  #: SDO server -> client (response), + node id
SDO_TX_COB_ID_BASE = 0x600  #: SDO client -> server (request), + node id
HEARTBEAT_COB_ID_BASE = 0x700  #: NMT error control (heartbeat, boot-up) = 0x700 + node id

_FUNCTION_MASK = 0x780
_NODE_MASK = 0x07F

__all__ = ["Frame", "FrameError", "split_cob_id", "sync_frame", "MAX_NODE_ID", "NMT_COB_ID", "SYNC_COB_ID",
           "EMCY_COB_ID_BASE", "SDO_RX_COB_ID_BASE", "SDO_TX_COB_ID_BASE", "HEARTBEAT_COB_ID_BASE"]


class FrameError(CanopenError, ValueError):
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
    def trusted(cls, arbitration_id: int, data: bytes) -> Frame:
        """A frame from a source that already guarantees an 11-bit id and <= 8 bytes of
        ``bytes`` (a python-can message, a struct-packed PDO): no re-validation (hot path)."""
        f = _new(cls)
        _set_id(f, arbitration_id)  # the slots' own setters: what object.__setattr__ finds, without the lookup
        _set_data(f, data)
        return f


_new = object.__new__
_set_id = Frame.__dict__["arbitration_id"].__set__
_set_data = Frame.__dict__["data"].__set__


_SYNC_FRAME = Frame(SYNC_COB_ID, b"")


def sync_frame() -> Frame:
    """The SYNC frame (COB-ID 0x080, no data: the SYNC counter is not used); one shared instance (a
    frame is immutable), not a new one per SYNC cycle."""
    return _SYNC_FRAME


def split_cob_id(cob_id: int) -> tuple[int, int]:
    """A COB-ID of the predefined connection set as ``(function code base, node id)``.

    Notes
    -----
    ``base = cob_id & 0x780`` (e.g. 0x180 TPDO1, 0x580 SDO response, 0x700
    heartbeat), ``node = cob_id & 0x07F``. SYNC (0x080) and NMT (0x000) give
    node 0; EMCY shares SYNC's base with node 1..127.
    """
    return cob_id & _FUNCTION_MASK, cob_id & _NODE_MASK
