"""The object store of a simulated drive: object dictionary, data store, SDO server.

Each simulated node is built from the same EDS the master reads
(``profiles/ema_drive.eds`` through :func:`hil.canopen.od.load_eds`).
:class:`ObjectStore` holds it together with the values written since the
last reset and serves both to canopen's ``canopen.sdo.SdoServer``
(expedited and segmented transfers), through the three things the server
asks of its node: ``object_dictionary``, ``get_data`` and ``set_data``.
These follow ``canopen.LocalNode`` (canopen 2.4.1) exactly, without its NMT
slave, which would act on NMT frames and start a periodic heartbeat task on
the bus when 0x1017 is written; no private attribute of canopen is used.
:class:`SdoEndpoint` runs the server sans-IO: a request and a time in,
the reply frames out.

Read (``get_data``), in this order:

1. the object must exist: index (else abort 0x06020000) and, in a record or
   array, sub-index (else 0x06090011); with ``check_readable`` it must be
   readable (0x06010001);
2. a live value (a getter of the drive: statusword, position, ...), encoded
   with the object's data type;
3. the stored value (raw bytes, as written);
4. the EDS ParameterValue, then the EDS default;
5. else the data type's zero (0, 0.0, an empty string or domain, which
   canopen's server answers with abort 0x08000024, no data available): a device
   holds a value in every object, an EDS need not give it (vendors' files
   leave identity, ratings and measured values without a default; the
   node's own data, :mod:`sim.drives.served`, fills in those that matter).

Write (``set_data``): the object must exist, with ``check_writable`` be
writable (0x06010002), a number type must have its exact length
(0x06070010); then the drive's validation callback may refuse the value by
raising ``canopen.sdo.SdoAbortedError`` (its code is the abort code); else
the bytes are stored and the object noted in :attr:`ObjectStore.written`.

SDO choices (on top of canopen's server)
----------------------------------------
* Block transfers are refused (0x05040001), so is an invalid command
  specifier; a segment request outside a segmented transfer of its kind
  too (canopen would answer it).
* Initiate requests are checked first: the object and the sub-index must
  exist (0x06020000 / 0x06090011), and a segmented download of a read-only
  object is refused at once (0x06010002; canopen would only check after the
  last segment).
* Only 8-byte requests in PRE-OPERATIONAL and OPERATIONAL are served (the
  node, :class:`sim.drives.drive.SimDrive`, filters them).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import canopen.objectdictionary as cod
from canopen.sdo import SdoAbortedError, SdoServer

from hil.canopen.frame import SDO_RX_COB_ID_BASE, SDO_TX_COB_ID_BASE, Frame
from hil.canopen.od import lookup
from hil.canopen.pdo import TYPE_BITS, PdoCodec, pdo_codec
from hil.canopen.sdo import SdoAbortCode, server_abort_frame

__all__ = ["INT_CODES", "STRUCT_CODES", "ObjectStore", "SdoEndpoint", "abort"]

#: ``struct`` format character of each number data type (little endian).
STRUCT_CODES = {**{t: code for t, (_, code) in TYPE_BITS.items()}, cod.BOOLEAN: "?", cod.REAL64: "d"}
#: The integer ones among :data:`STRUCT_CODES` (decoded values that may be cached).
INT_CODES = frozenset("bBhHiIqQ")

_MUX = struct.Struct("<HB")  # index, subindex (bytes 1..3 of an SDO request)


def abort(code: int) -> SdoAbortedError:
    """The exception that makes canopen's SDO server answer with abort ``code``."""
    return SdoAbortedError(int(code))


class ObjectStore:
    """Object dictionary, data store and decoded-integer cache of one node.

    Parameters
    ----------
    od : canopen.ObjectDictionary
        The node's object dictionary (``$NODEID`` resolved).
    live : dict
        ``(index, subindex) -> getter()``: objects whose value the drive
        computes when read (never stored, never cached).
    validate : callable
        ``validate(index, subindex, var, data)`` checks a write before it is
        stored; it raises ``canopen.sdo.SdoAbortedError`` to refuse it.

    Attributes
    ----------
    object_dictionary : canopen.ObjectDictionary
        The EDS (the name canopen's SDO server reads).
    data : dict
        ``index -> {subindex: bytes}``, the values written since the last
        reset (the data store).
    icache : dict
        ``(index, subindex) -> int``: decoded stored integers. Whoever
        stores an object drops its entry (or puts the decoded value).
    live : dict
        As the parameter.
    written : set
        Objects stored by :meth:`set_data` since the owner last cleared it.

    Notes
    -----
    The drive shares :attr:`data` and :attr:`icache` (the same dict
    objects, never rebound) with its PDO engine, which writes received
    RPDOs straight into them.
    """

    __slots__ = ("_packers", "data", "icache", "live", "object_dictionary", "validate", "written")

    def __init__(self, od: cod.ObjectDictionary, live: dict[tuple[int, int], Callable[[], int | float]],
                 validate: Callable[[int, int, cod.ODVariable, bytes], None]) -> None:
        self.object_dictionary = od
        self.data: dict[int, dict[int, bytes]] = {}
        self.icache: dict[tuple[int, int], int] = {}
        self.live = live
        self.validate = validate
        self.written: set[tuple[int, int]] = set()
        self._packers: dict[tuple[int, int], Any] = {}

    # ------------------------------------------------------------------ the node interface of SdoServer

    def find_object(self, index: int, subindex: int) -> cod.ODVariable:
        """The variable ``index:subindex`` as canopen's ``LocalNode`` finds it.

        Raises
        ------
        canopen.sdo.SdoAbortedError
            0x06020000 no such index, 0x06090011 no such sub-index (in a
            record or array; a plain variable answers any sub-index).
        """
        od = self.object_dictionary
        if index not in od:
            raise abort(SdoAbortCode.OBJECT_DOES_NOT_EXIST)
        obj = od[index]
        if not isinstance(obj, cod.ODVariable):
            if subindex not in obj:
                raise abort(SdoAbortCode.SUBINDEX_DOES_NOT_EXIST)
            obj = obj[subindex]
        return obj

    def get_data(self, index: int, subindex: int, check_readable: bool = False) -> bytes:
        """Encoded value of ``index:subindex``: live, stored, EDS ParameterValue, EDS default, zero.

        Raises
        ------
        canopen.sdo.SdoAbortedError
            See :meth:`find_object`; 0x06010001 not readable (with
            ``check_readable``).
        """
        obj = self.find_object(index, subindex)
        if check_readable and not obj.readable:
            raise abort(SdoAbortCode.READ_OF_WRITE_ONLY)
        f = self.live.get((index, subindex))
        if f is not None:
            result = f()
            if result is not None:
                return obj.encode_raw(result)
        try:
            return self.data[index][subindex]
        except KeyError:
            if obj.value is not None:
                return obj.encode_raw(obj.value)
            if obj.default is not None:
                return obj.encode_raw(obj.default)
        return obj.encode_raw(0) if obj.data_type in cod.NUMBER_TYPES else b""

    def set_data(self, index: int, subindex: int, data: bytes, check_writable: bool = False) -> None:
        """Validate and store ``data`` at ``index:subindex``; note it in :attr:`written`.

        Raises
        ------
        canopen.sdo.SdoAbortedError
            See :meth:`find_object`; 0x06010002 not writable (with
            ``check_writable``); 0x06070010 wrong length for a number type;
            whatever the validation callback raises.
        """
        obj = self.find_object(index, subindex)
        if check_writable and not obj.writable:
            raise abort(SdoAbortCode.WRITE_OF_READ_ONLY)
        if obj.data_type in cod.NUMBER_TYPES and 8 * len(data) != len(obj):
            raise abort(SdoAbortCode.LENGTH_MISMATCH)
        self.validate(index, subindex, obj, data)
        self.written.add((index, subindex))
        self.data.setdefault(index, {})[subindex] = bytes(data)

    # ------------------------------------------------------------------ the drive's access

    def var(self, index: int, subindex: int) -> cod.ODVariable | None:
        """The real variable at ``index:subindex`` (:func:`hil.canopen.od.lookup`), or None."""
        return lookup(self.object_dictionary, index, subindex)

    def int_value(self, index: int, subindex: int = 0) -> int:
        """Decoded integer value of an existing object (cached unless live)."""
        key = (index, subindex)
        v = self.icache.get(key)
        if v is None:
            v = int(lookup(self.object_dictionary, index, subindex).decode_raw(self.get_data(index, subindex)))
            if key not in self.live:
                self.icache[key] = v  # invalidated by every store of this object
        return v

    def int_or(self, index: int, subindex: int, default: int) -> int:
        """:meth:`int_value` of an object the EDS may lack; ``default`` when it has no such object."""
        v = self.icache.get((index, subindex))
        if v is not None:
            return v
        if lookup(self.object_dictionary, index, subindex) is None:
            return default
        return self.int_value(index, subindex)

    def put(self, index: int, subindex: int, data: bytes) -> None:
        """Store ``data`` without validation (the drive's own writes)."""
        self.data.setdefault(index, {})[subindex] = bytes(data)
        self.icache.pop((index, subindex), None)

    def packer(self, index: int, subindex: int) -> PdoCodec | None:
        """The PDO codec of a numeric object mapped alone (:func:`hil.canopen.pdo.pdo_codec`), or None for
        other types (cached)."""
        key = (index, subindex)
        if key not in self._packers:
            var = self.var(index, subindex)
            code = STRUCT_CODES.get(var.data_type) if var is not None else None
            self._packers[key] = pdo_codec(code) if code else None
        return self._packers[key]

    def raw(self, index: int, subindex: int) -> bytes:
        """Encoded value for a PDO: live values packed directly, stored ones from the store."""
        f = self.live.get((index, subindex))
        if f is not None:
            pk = self.packer(index, subindex)
            if pk is not None:
                return pk.pack(f())
        else:
            raw = self.data.get(index, {}).get(subindex)
            if raw is not None:
                return raw
        return self.get_data(index, subindex)

    def reset(self, *, communication_only: bool) -> None:
        """Forget written values: all of them, or those of the communication area 0x1000..0x1FFF."""
        self.icache.clear()
        store = self.data
        if communication_only:
            for index in [i for i in store if 0x1000 <= i <= 0x1FFF]:
                del store[index]
        else:
            store.clear()
        self.written.clear()


class SdoEndpoint:
    """The SDO server of one node (default SDO channel), sans-IO.

    canopen's ``SdoServer`` serves :class:`ObjectStore`; its ``network`` is
    this object, whose :meth:`send_message` only collects the replies.

    Parameters
    ----------
    node_id : int
        The node id, 1..127.
    store : ObjectStore
        What the server reads and writes.

    Attributes
    ----------
    request_cob_id, response_cob_id : int
        0x600 + node id (requests to the node), 0x580 + node id (its replies).
    server : canopen.sdo.SdoServer
        canopen's server.
    """

    __slots__ = ("_mux", "_phase", "_replies", "node_id", "request_cob_id", "response_cob_id", "server", "store")

    def __init__(self, node_id: int, store: ObjectStore) -> None:
        self.node_id = node_id
        self.store = store
        self.request_cob_id = SDO_TX_COB_ID_BASE + node_id
        self.response_cob_id = SDO_RX_COB_ID_BASE + node_id
        self.server = SdoServer(self.request_cob_id, self.response_cob_id, store)
        self.server.network = self
        self._replies: list[Frame] = []
        self._phase: int | None = None  # segment command specifier expected next
        self._mux: tuple[int, int] = (0, 0)  # index, subindex of the last transfer

    def send_message(self, cob_id: int, data: bytes | bytearray, remote: bool = False) -> None:
        """The server's way out (``network.send_message``): collect the reply."""
        self._replies.append(Frame(cob_id, bytes(data)))

    def reset(self) -> None:
        """No segmented transfer in progress (power-on, NMT reset)."""
        self._phase = None

    def serve(self, data: bytes, t: float, out: list[Frame]) -> None:
        """Serve one SDO request; append the reply (if any) to ``out``.

        Parameters
        ----------
        data : bytes
            The request, 8 bytes.
        t : float
            Time of reception [s] (passed on to canopen's server).
        out : list of Frame
            Where the reply goes (an abort frame included).

        Notes
        -----
        Objects written are noted in the store's ``written`` set.
        """
        ccs = data[0] >> 5
        if ccs == 4:  # abort by the client
            self._phase = None
        elif ccs in (1, 2):  # initiate download / upload: check the object first
            self._mux = _MUX.unpack_from(data, 1)
            self._phase = None
            code = self._access_problem(*self._mux, download=ccs == 1, expedited=bool(data[0] & 0x02))
            if code is not None:
                self._abort(code, out)
                return
        elif ccs in (0, 3):  # download / upload segment: only inside that transfer
            if self._phase != ccs:
                self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID, out)
                return
        else:  # 5, 6 block upload / download (not supported), 7 invalid
            self._mux = _MUX.unpack_from(data, 1)
            self._phase = None
            self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID, out)
            return
        self.server.on_request(self.request_cob_id, bytearray(data), t)
        for reply in self._replies:
            out.append(reply)
            self._phase = self._next_phase(ccs, data[0], reply.data[0])
        self._replies.clear()

    def _abort(self, code: int, out: list[Frame]) -> None:
        index, subindex = self._mux
        self._phase = None
        out.append(server_abort_frame(self.node_id, index, subindex, code))

    @staticmethod
    def _next_phase(ccs: int, request: int, response: int) -> int | None:
        """Segment ccs expected next (0 download, 3 upload) after a request/response pair, or None."""
        if response >> 5 == 4:  # the server aborted
            return None
        if ccs == 1:
            return None if request & 0x02 else 0  # expedited done / segments follow
        if ccs == 2:
            return None if response & 0x02 else 3
        if ccs in (0, 3):
            last = request & 0x01 if ccs == 0 else response & 0x01
            return None if last else ccs
        return None

    def _access_problem(self, index: int, subindex: int, *, download: bool, expedited: bool) -> int | None:
        """Abort code for an initiate request the server would not catch (or catch too late)."""
        store = self.store
        if index not in store.object_dictionary:
            return SdoAbortCode.OBJECT_DOES_NOT_EXIST
        var = store.var(index, subindex)
        if var is None:
            return SdoAbortCode.SUBINDEX_DOES_NOT_EXIST
        if download and not expedited and not var.writable:
            return SdoAbortCode.WRITE_OF_READ_ONLY  # the server would only check after the last segment
        return None
