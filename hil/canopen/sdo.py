"""Sans-IO SDO client (CiA 301 expedited and segmented transfer) and the SDO abort codes.

The client talks to one SDO server (a drive) over the default SDO channel:
requests on COB-ID 0x600 + node id, responses on 0x580 + node id. It never
touches a bus or a clock: the caller passes every received frame and the
current time ``t`` (float seconds, any monotonic origin) and transmits the
frames the client returns. One transfer at a time; a queue is the caller's.

Typical use by the IO shell::

    client = SdoClient(2)
    send(client.start_download(0x1017, 0, struct.pack("<H", 100), t))
    ...
    for every received frame:              # and periodically: client.poll(t)
        out = client.on_frame(frame, t)    # Frame -> send it; SdoEvent -> done
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum, IntEnum

from hil.canopen.errors import CanopenError, CanopenInputError
from hil.canopen.frame import SDO_RX_COB_ID_BASE, SDO_TX_COB_ID_BASE, Frame
from hil.canopen.validate import integer, time_s
from hil.canopen.validate import node_id as _check_node_id

# Command specifiers (bits 7..5 of byte 0).
_CCS_SEGMENT_DOWNLOAD = 0
_CCS_INITIATE_DOWNLOAD = 1
_CCS_INITIATE_UPLOAD = 2
_CCS_SEGMENT_UPLOAD = 3
_CS_ABORT = 4
_SCS_SEGMENT_UPLOAD = 0
_SCS_SEGMENT_DOWNLOAD = 1
_SCS_INITIATE_UPLOAD = 2
_SCS_INITIATE_DOWNLOAD = 3

_MUX = struct.Struct("<BHB")  # command byte, index, subindex
_ABORT = struct.Struct("<BHBI")


class SdoAbortCode(IntEnum):
    """SDO abort codes of CiA 301 (Table 22), with their standard meaning."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x0503_0000
    PROTOCOL_TIMED_OUT = 0x0504_0000
    COMMAND_SPECIFIER_INVALID = 0x0504_0001
    INVALID_BLOCK_SIZE = 0x0504_0002
    INVALID_SEQUENCE_NUMBER = 0x0504_0003
    CRC_ERROR = 0x0504_0004
    OUT_OF_MEMORY = 0x0504_0005
    UNSUPPORTED_ACCESS = 0x0601_0000
    READ_OF_WRITE_ONLY = 0x0601_0001
    WRITE_OF_READ_ONLY = 0x0601_0002
    OBJECT_DOES_NOT_EXIST = 0x0602_0000
    CANNOT_BE_MAPPED = 0x0604_0041
    EXCEEDS_PDO_LENGTH = 0x0604_0042
    PARAMETER_INCOMPATIBILITY = 0x0604_0043
    INTERNAL_INCOMPATIBILITY = 0x0604_0047
    HARDWARE_ERROR = 0x0606_0000
    LENGTH_MISMATCH = 0x0607_0010
    LENGTH_TOO_HIGH = 0x0607_0012
    LENGTH_TOO_LOW = 0x0607_0013
    SUBINDEX_DOES_NOT_EXIST = 0x0609_0011
    VALUE_RANGE_EXCEEDED = 0x0609_0030
    VALUE_TOO_HIGH = 0x0609_0031
    VALUE_TOO_LOW = 0x0609_0032
    MAX_LESS_THAN_MIN = 0x0609_0036
    RESOURCE_NOT_AVAILABLE = 0x060A_0023
    GENERAL_ERROR = 0x0800_0000
    CANNOT_TRANSFER = 0x0800_0020
    CANNOT_TRANSFER_LOCAL_CONTROL = 0x0800_0021
    CANNOT_TRANSFER_DEVICE_STATE = 0x0800_0022
    NO_OBJECT_DICTIONARY = 0x0800_0023
    NO_DATA_AVAILABLE = 0x0800_0024

    @property
    def meaning(self) -> str:
        """The standard text of the abort code (CiA 301)."""
        return _MEANING[self]


_MEANING = {
    SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED: "toggle bit not alternated",
    SdoAbortCode.PROTOCOL_TIMED_OUT: "SDO protocol timed out",
    SdoAbortCode.COMMAND_SPECIFIER_INVALID: "client/server command specifier not valid or unknown",
    SdoAbortCode.INVALID_BLOCK_SIZE: "invalid block size (block mode only)",
    SdoAbortCode.INVALID_SEQUENCE_NUMBER: "invalid sequence number (block mode only)",
    SdoAbortCode.CRC_ERROR: "CRC error (block mode only)",
    SdoAbortCode.OUT_OF_MEMORY: "out of memory",
    SdoAbortCode.UNSUPPORTED_ACCESS: "unsupported access to an object",
    SdoAbortCode.READ_OF_WRITE_ONLY: "attempt to read a write only object",
    SdoAbortCode.WRITE_OF_READ_ONLY: "attempt to write a read only object",
    SdoAbortCode.OBJECT_DOES_NOT_EXIST: "object does not exist in the object dictionary",
    SdoAbortCode.CANNOT_BE_MAPPED: "object cannot be mapped to the PDO",
    SdoAbortCode.EXCEEDS_PDO_LENGTH: "the number and length of the objects to be mapped would exceed PDO length",
    SdoAbortCode.PARAMETER_INCOMPATIBILITY: "general parameter incompatibility reason",
    SdoAbortCode.INTERNAL_INCOMPATIBILITY: "general internal incompatibility in the device",
    SdoAbortCode.HARDWARE_ERROR: "access failed due to a hardware error",
    SdoAbortCode.LENGTH_MISMATCH: "data type does not match, length of service parameter does not match",
    SdoAbortCode.LENGTH_TOO_HIGH: "data type does not match, length of service parameter too high",
    SdoAbortCode.LENGTH_TOO_LOW: "data type does not match, length of service parameter too low",
    SdoAbortCode.SUBINDEX_DOES_NOT_EXIST: "sub-index does not exist",
    SdoAbortCode.VALUE_RANGE_EXCEEDED: "value range of parameter exceeded",
    SdoAbortCode.VALUE_TOO_HIGH: "value of parameter written too high",
    SdoAbortCode.VALUE_TOO_LOW: "value of parameter written too low",
    SdoAbortCode.MAX_LESS_THAN_MIN: "maximum value is less than minimum value",
    SdoAbortCode.RESOURCE_NOT_AVAILABLE: "resource not available: SDO connection",
    SdoAbortCode.GENERAL_ERROR: "general error",
    SdoAbortCode.CANNOT_TRANSFER: "data cannot be transferred or stored to the application",
    SdoAbortCode.CANNOT_TRANSFER_LOCAL_CONTROL:
        "data cannot be transferred or stored to the application because of local control",
    SdoAbortCode.CANNOT_TRANSFER_DEVICE_STATE:
        "data cannot be transferred or stored to the application because of the present device state",
    SdoAbortCode.NO_OBJECT_DICTIONARY:
        "object dictionary dynamic generation fails or no object dictionary is present",
    SdoAbortCode.NO_DATA_AVAILABLE: "no data available",
}


def describe(code: int) -> str:
    """The standard meaning of an abort code, ``"unknown abort code"`` if it is
    not in CiA 301 Table 22 (e.g. a manufacturer-specific one)."""
    try:
        return SdoAbortCode(code).meaning
    except ValueError:
        return "unknown abort code"


def _as_code(code: int) -> SdoAbortCode | int:
    try:
        return SdoAbortCode(code)
    except ValueError:
        return int(code)


class SdoAbortError(CanopenError, IOError):
    """An SDO transfer ended by an abort.

    Attributes
    ----------
    node_id, index, subindex : int
        The server and the object of the transfer.
    code : SdoAbortCode or int
        The abort code (an int if it is not a standard code).
    abort_frame : Frame or None
        Set when the *client* aborted the transfer on a protocol error: the
        abort frame the caller must transmit to the server. None when the
        server aborted.
    """

    def __init__(self, node_id: int, index: int, subindex: int, code: int,
                 *, abort_frame: Frame | None = None, reason: str = "") -> None:
        self.node_id = node_id
        self.index = index
        self.subindex = subindex
        self.code = _as_code(code)
        self.abort_frame = abort_frame
        self.reason = reason
        msg = (f"node {node_id}: SDO abort 0x{int(code):08X} ({describe(code)}) "
               f"on 0x{index:04X}:{subindex:02X}")
        if abort_frame is not None:
            msg += " (aborted by the client" + (f": {reason})" if reason else ")")
        super().__init__(msg)


class SdoTimeout(CanopenError, TimeoutError):
    """No SDO response within the timeout.

    ``abort_frame`` is the abort (code 0x05040000) the caller must transmit to
    the server so that it drops the transfer too.
    """

    def __init__(self, node_id: int, index: int, subindex: int, timeout_s: float, abort_frame: Frame) -> None:
        self.node_id = node_id
        self.index = index
        self.subindex = subindex
        self.timeout_s = timeout_s
        self.abort_frame = abort_frame
        super().__init__(f"node {node_id}: SDO timeout, no response within {timeout_s:g} s "
                         f"on 0x{index:04X}:{subindex:02X}")


class SdoUsageError(CanopenError, RuntimeError):
    """The client was asked for something its state does not allow (e.g. two transfers at once)."""


class SdoTransfer(Enum):
    """Kind of a completed transfer."""

    DOWNLOAD = "download"  #: client -> server (write)
    UPLOAD = "upload"  #: server -> client (read)


@dataclass(frozen=True, slots=True)
class SdoEvent:
    """A completed SDO transfer.

    ``data`` is the uploaded bytes for an upload and the written bytes for a
    download; ``t_start_s`` / ``t_end_s`` are the times passed to ``start_*``
    and to the ``on_frame`` that completed it.
    """

    node_id: int
    transfer: SdoTransfer
    index: int
    subindex: int
    data: bytes
    t_start_s: float
    t_end_s: float


def abort_frame(node_id: int, index: int, subindex: int, code: int) -> Frame:
    """The abort frame a client sends to server ``node_id`` (COB-ID 0x600 + node id).

    Byte 0 = 0x80, bytes 1..2 index (little endian), byte 3 subindex, bytes 4..7
    abort code (u32 little endian).
    """
    n = _check_node_id(node_id)
    return Frame(SDO_TX_COB_ID_BASE + n, _ABORT.pack(_CS_ABORT << 5, index, subindex, int(code)))


def server_abort_frame(node_id: int, index: int, subindex: int, code: int) -> Frame:
    """The abort frame a *server* sends to its client (COB-ID 0x580 + node id), same layout
    as :func:`abort_frame`."""
    return Frame(SDO_RX_COB_ID_BASE + node_id, _ABORT.pack(_CS_ABORT << 5, index, subindex, int(code)))


def expedited_download_frame(node_id: int, index: int, subindex: int, data: bytes) -> Frame:
    """A stand-alone expedited download request (1..4 bytes, size indicated), for a write whose
    response is not awaited (the master's quick stop by SDO: fire and forget)."""
    n = len(data)
    if not 1 <= n <= 4:
        raise CanopenInputError(f"data has {n} bytes; an expedited download carries 1..4")
    cmd = (_CCS_INITIATE_DOWNLOAD << 5) | ((4 - n) << 2) | 0x02 | 0x01
    return Frame(SDO_TX_COB_ID_BASE + _check_node_id(node_id), _MUX.pack(cmd, index, subindex) + data.ljust(4, b"\x00"))


def _check_mux(index: int, subindex: int) -> tuple[int, int]:
    return integer("index", index, 0, 0xFFFF, show="0x{:X}"), integer("subindex", subindex, 0, 0xFF, show="0x{:X}")


class _Phase(Enum):
    IDLE = 0
    DOWNLOAD_INIT = 1
    DOWNLOAD_SEGMENT = 2
    UPLOAD_INIT = 3
    UPLOAD_SEGMENT = 4


class SdoClient:
    """Sans-IO SDO client for one server (expedited and segmented transfers).

    Parameters
    ----------
    node_id : int
        Node id of the server, 1..127 (requests on 0x600 + id, responses on 0x580 + id).
    timeout_s : float
        Longest wait for each response [s]; :meth:`poll` raises
        :class:`SdoTimeout` when it has passed.

    Notes
    -----
    Frames (byte 0 = command specifier, CiA 301 7.2.4.3):

    * initiate download, expedited with size: ``0x23 | (4 - n) << 2``, index,
      subindex, n data bytes padded to 4 (``2B`` for 2 bytes);
    * initiate download, segmented with size: ``0x21``, index, subindex, u32 size;
      download segment ``t << 4 | (7 - n) << 1 | c`` with up to 7 bytes;
    * initiate upload ``0x40``; upload segment request ``0x60 | t << 4``;
    * abort ``0x80``, index, subindex, u32 code.

    The toggle bit ``t`` starts at 0 and alternates with every segment.
    """

    def __init__(self, node_id: int, timeout_s: float = 0.5) -> None:
        self.node_id = _check_node_id(node_id)
        to = time_s(timeout_s, "timeout_s")
        if to <= 0.0:
            raise CanopenInputError(f"timeout_s = {to} [s] must be > 0")
        self.timeout_s = to
        self.tx_cob_id = SDO_TX_COB_ID_BASE + self.node_id  #: requests, client -> server
        self.rx_cob_id = SDO_RX_COB_ID_BASE + self.node_id  #: responses, server -> client
        self._reset()

    # ------------------------------------------------------------------ state

    def _reset(self) -> None:
        self._phase = _Phase.IDLE
        self._index = 0
        self._subindex = 0
        self._data = b""  # download payload
        self._offset = 0  # download bytes already sent
        self._last_segment = False
        self._toggle = 0
        self._buffer = bytearray()  # upload payload
        self._size: int | None = None  # upload size indicated by the server
        self._t_start = 0.0
        self._t_sent = 0.0

    @property
    def busy(self) -> bool:
        """True while a transfer is in progress."""
        return self._phase is not _Phase.IDLE

    def _frame(self, payload: bytes) -> Frame:
        return Frame(self.tx_cob_id, payload.ljust(8, b"\x00"))

    def _begin(self, index: int, subindex: int, t: float) -> tuple[int, int, float]:
        if self.busy:
            raise SdoUsageError(
                f"node {self.node_id}: SDO transfer on 0x{self._index:04X}:{self._subindex:02X} "
                "still in progress (one transfer at a time)"
            )
        i, s = _check_mux(index, subindex)
        tt = time_s(t)
        self._reset()
        self._index, self._subindex = i, s
        self._t_start = self._t_sent = tt
        return i, s, tt

    # ------------------------------------------------------------------ requests

    def start_download(self, index: int, subindex: int, data: bytes, t: float) -> Frame:
        """Begin writing ``data`` to ``index:subindex``; returns the initiate frame.

        Expedited for 1..4 bytes, segmented for more.
        """
        if isinstance(data, str):
            raise CanopenInputError("data must be bytes, got str: encode it first (e.g. drive_od.encode_value)")
        payload = bytes(data)
        if not payload:
            raise CanopenInputError("data is empty [bytes]: an SDO download needs at least 1 byte")
        i, s, _ = self._begin(index, subindex, t)
        self._data = payload
        self._phase = _Phase.DOWNLOAD_INIT
        n = len(payload)
        if n <= 4:
            cmd = (_CCS_INITIATE_DOWNLOAD << 5) | ((4 - n) << 2) | 0x02 | 0x01
            self._offset = n
            self._last_segment = True
            return self._frame(_MUX.pack(cmd, i, s) + payload)
        cmd = (_CCS_INITIATE_DOWNLOAD << 5) | 0x01
        return self._frame(_MUX.pack(cmd, i, s) + struct.pack("<I", n))

    def start_upload(self, index: int, subindex: int, t: float) -> Frame:
        """Begin reading ``index:subindex``; returns the initiate-upload frame."""
        i, s, _ = self._begin(index, subindex, t)
        self._phase = _Phase.UPLOAD_INIT
        return self._frame(_MUX.pack(_CCS_INITIATE_UPLOAD << 5, i, s))

    def abort(self, code: int = SdoAbortCode.GENERAL_ERROR) -> Frame:
        """Abort the transfer in progress; returns the abort frame to transmit."""
        if not self.busy:
            raise SdoUsageError(f"node {self.node_id}: no SDO transfer in progress to abort")
        frame = abort_frame(self.node_id, self._index, self._subindex, code)
        self._reset()
        return frame

    # ------------------------------------------------------------------ responses

    def _protocol_error(self, code: SdoAbortCode, reason: str) -> SdoAbortError:
        index, subindex = self._index, self._subindex
        frame = abort_frame(self.node_id, index, subindex, code)
        self._reset()
        return SdoAbortError(self.node_id, index, subindex, code, abort_frame=frame, reason=reason)

    def _done(self, transfer: SdoTransfer, data: bytes, t: float) -> SdoEvent:
        ev = SdoEvent(self.node_id, transfer, self._index, self._subindex, data, self._t_start, t)
        self._reset()
        return ev

    def _next_download_segment(self, t: float) -> Frame:
        chunk = self._data[self._offset:self._offset + 7]
        self._offset += len(chunk)
        self._last_segment = self._offset >= len(self._data)
        cmd = (_CCS_SEGMENT_DOWNLOAD << 5) | (self._toggle << 4) | ((7 - len(chunk)) << 1)
        cmd |= 0x01 if self._last_segment else 0x00
        self._phase = _Phase.DOWNLOAD_SEGMENT
        self._t_sent = t
        return self._frame(bytes([cmd]) + chunk)

    def _upload_segment_request(self, t: float) -> Frame:
        self._phase = _Phase.UPLOAD_SEGMENT
        self._t_sent = t
        return self._frame(bytes([(_CCS_SEGMENT_UPLOAD << 5) | (self._toggle << 4)]))

    def on_frame(self, frame: Frame, t: float) -> SdoEvent | Frame | None:
        """Feed one received frame.

        Returns
        -------
        SdoEvent
            The transfer completed.
        Frame
            The next request to transmit (segment of a segmented transfer).
        None
            The frame is not a response of this server, or no transfer is in
            progress (a late response after a timeout or abort is dropped).

        Raises
        ------
        SdoAbortError
            The server aborted (``abort_frame`` None), or the response broke the
            protocol (wrong command specifier, multiplexer, toggle bit, length):
            the client ends the transfer and ``abort_frame`` holds the abort to
            transmit to the server.
        """
        if frame.arbitration_id != self.rx_cob_id or not self.busy:
            return None
        tt = time_s(t)
        d = frame.data
        if len(d) != 8:
            raise self._protocol_error(SdoAbortCode.GENERAL_ERROR,
                                       f"response with {len(d)} data bytes, SDO frames have 8")
        cmd = d[0]
        scs = cmd >> 5
        if scs == _CS_ABORT:
            _, index, subindex, code = _ABORT.unpack(d)
            mine = (self._index, self._subindex)
            self._reset()
            raise SdoAbortError(self.node_id, *mine, code)

        phase = self._phase
        if phase in (_Phase.DOWNLOAD_INIT, _Phase.UPLOAD_INIT):
            expected = _SCS_INITIATE_DOWNLOAD if phase is _Phase.DOWNLOAD_INIT else _SCS_INITIATE_UPLOAD
            if scs != expected:
                raise self._protocol_error(SdoAbortCode.COMMAND_SPECIFIER_INVALID,
                                           f"server command specifier {scs}, expected {expected}")
            _, index, subindex = _MUX.unpack_from(d)
            if (index, subindex) != (self._index, self._subindex):
                raise self._protocol_error(
                    SdoAbortCode.GENERAL_ERROR,
                    f"response for 0x{index:04X}:{subindex:02X}, expected 0x{self._index:04X}:{self._subindex:02X}",
                )
            if phase is _Phase.DOWNLOAD_INIT:
                if self._last_segment:  # expedited
                    return self._done(SdoTransfer.DOWNLOAD, self._data, tt)
                return self._next_download_segment(tt)
            # initiate upload response
            expedited, size_indicated = bool(cmd & 0x02), bool(cmd & 0x01)
            if expedited:
                n = 4 - ((cmd >> 2) & 0x03) if size_indicated else 4
                return self._done(SdoTransfer.UPLOAD, bytes(d[4:4 + n]), tt)
            self._size = struct.unpack_from("<I", d, 4)[0] if size_indicated else None
            return self._upload_segment_request(tt)

        if phase is _Phase.DOWNLOAD_SEGMENT:
            if scs != _SCS_SEGMENT_DOWNLOAD:
                raise self._protocol_error(SdoAbortCode.COMMAND_SPECIFIER_INVALID,
                                           f"server command specifier {scs}, expected {_SCS_SEGMENT_DOWNLOAD}")
            if (cmd >> 4) & 1 != self._toggle:
                raise self._protocol_error(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED,
                                           f"segment response toggle {(cmd >> 4) & 1}, expected {self._toggle}")
            if self._last_segment:
                return self._done(SdoTransfer.DOWNLOAD, self._data, tt)
            self._toggle ^= 1
            return self._next_download_segment(tt)

        # UPLOAD_SEGMENT
        if scs != _SCS_SEGMENT_UPLOAD:
            raise self._protocol_error(SdoAbortCode.COMMAND_SPECIFIER_INVALID,
                                       f"server command specifier {scs}, expected {_SCS_SEGMENT_UPLOAD}")
        if (cmd >> 4) & 1 != self._toggle:
            raise self._protocol_error(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED,
                                       f"upload segment toggle {(cmd >> 4) & 1}, expected {self._toggle}")
        n = 7 - ((cmd >> 1) & 0x07)
        self._buffer += d[1:1 + n]
        if self._size is not None and len(self._buffer) > self._size:
            raise self._protocol_error(SdoAbortCode.LENGTH_TOO_HIGH,
                                       f"{len(self._buffer)} bytes received, server indicated {self._size}")
        if cmd & 0x01:  # no more segments
            if self._size is not None and len(self._buffer) != self._size:
                raise self._protocol_error(SdoAbortCode.LENGTH_MISMATCH,
                                           f"{len(self._buffer)} bytes received, server indicated {self._size}")
            return self._done(SdoTransfer.UPLOAD, bytes(self._buffer), tt)
        self._toggle ^= 1
        return self._upload_segment_request(tt)

    def poll(self, t: float) -> None:
        """Check the response timeout at time ``t``.

        Raises
        ------
        SdoTimeout
            ``t - (time of the last request) >= timeout_s`` while a transfer is
            in progress; the transfer ends and ``abort_frame`` (code 0x05040000)
            must be transmitted to the server.
        """
        tt = time_s(t)
        if self.busy and tt - self._t_sent >= self.timeout_s:
            index, subindex = self._index, self._subindex
            frame = abort_frame(self.node_id, index, subindex, SdoAbortCode.PROTOCOL_TIMED_OUT)
            self._reset()
            raise SdoTimeout(self.node_id, index, subindex, self.timeout_s, frame)
