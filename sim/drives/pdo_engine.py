"""The PDO engine of a simulated drive, driven by its object dictionary.

The PDOs are those of the EDS (communication records 0x1400.. / 0x1800..
with their mapping records 0x1600.. / 0x1A00..). Their configuration is
re-read from the data store whenever a communication object is written
and compiled into the PDO's codec (:class:`Pdo`; the master's one,
:func:`hil.canopen.pdo.pdo_codec`): a TPDO of live values is one pack of
their getters, an RPDO of numbers one unpack.

Choices (CiA 301 leaves them open or this drive restricts them)
---------------------------------------------------------------
* PDO mapping (CiA 301 7.5.2.35/36 procedure): entries and the number of
  entries can only be written while the PDO is invalid (COB-ID bit 31 set)
  and entries only while sub-index 0 is 0, else abort 0x06040043 (general
  parameter incompatibility). An entry must name an existing, PDO-mappable
  object, readable for a TPDO and writable for an RPDO, with its exact bit
  length (a whole number of bytes, EDS Granularity=8), else 0x06040041.
  Writing sub-index 0 checks the entries and aborts with 0x06040042 when
  they exceed 64 bits (or the number of entries the record has).
* PDO communication: 11-bit COB-IDs only; the CAN-ID cannot change while the
  PDO is valid and a valid PDO cannot use a CiA 301 restricted CAN-ID
  (0x06090030). Transmission types 0..240, 254, 255 (252/253 RTR-only and
  241..251 refused, 0x06090030). TPDO type 0 is sent at a SYNC when its
  payload changed; 254/255 when its payload changed after any event (SYNC,
  RPDO, SDO write, fault), not faster than the inhibit time (sub 3, 100 us,
  changeable only while invalid), and every event timer (sub 5, ms) from
  :meth:`sim.drives.SimDrivePair.tick`. RPDO event timers (deadline
  monitoring) are stored but not monitored.
* Synchronous RPDOs are latched and applied at the next SYNC; a newer one
  overwrites a latched one (counted as late). Event RPDOs (254/255) are
  applied on reception.
* RPDO length: shorter than mapped -> EMCY 0x8210, longer -> EMCY 0x8220,
  the frame is not processed. The EMCY is sent when the error appears (not
  for every further bad frame); the next RPDO of correct length resets it
  with EMCY 0x0000.
* RPDOs are processed in OPERATIONAL only (else counted as dropped).
* Any EDS (a vendor's too): a record whose sub-indices have gaps reads the
  missing ones as 0; an entry of 0 bits maps nothing; a default mapping
  (from the EDS) is taken as it is, even one an SDO write would be refused
  for: its entries of objects the node lacks (dummy entries, another
  variant's objects) are sent as zeros, received into nothing; entries
  beyond the 8 bytes of a CAN frame are dropped. A PDO record
  without a COB-ID (sub-index 1) is not valid; one without a transmission
  type (sub-index 2) is event driven (255).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import canopen.objectdictionary as cod

from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtState
from hil.canopen.pdo import COB_ID_INVALID, pdo_codec
from hil.canopen.sdo import SdoAbortCode
from sim.drives.nmt_slave import (
    EMCY_NO_ERROR,
    EMCY_PDO_LENGTH_ERROR,
    EMCY_PDO_LENGTH_EXCEEDED,
    TIME_EPS_S,
)
from sim.drives.store import INT_CODES, STRUCT_CODES, abort

__all__ = ["RESTRICTED_CAN_IDS", "Pdo", "PdoEngine"]

#: CiA 301 restricted CAN-IDs (may not be used by a PDO).
RESTRICTED_CAN_IDS = ((0x000, 0x000), (0x001, 0x07F), (0x101, 0x180), (0x581, 0x5FF),
                      (0x601, 0x67F), (0x6E0, 0x6FF), (0x701, 0x77F), (0x780, 0x7FF))
_K_CONTROLWORD = (0x6040, 0)
_trusted = Frame.trusted
_OPERATIONAL = NmtState.OPERATIONAL  # (a module constant: an Enum member read off its class is a Python lookup)
_ONLY_CONTROLWORD = (_K_CONTROLWORD,)


def _packed(pack: Callable[..., bytes], getters: tuple[Callable[[], int | float], ...]) -> Callable[[], bytes]:
    """The payload of a TPDO of live numbers: ``pack`` (its codec's) of its getters' values, read in
    mapping order (two and three entries, the drives' TPDOs, without building an argument list)."""
    if len(getters) == 3:
        g0, g1, g2 = getters
        return lambda: pack(g0(), g1(), g2())
    if len(getters) == 2:
        g0, g1 = getters
        return lambda: pack(g0(), g1())
    return lambda: pack(*[f() for f in getters])


@dataclass(eq=False, slots=True)
class Pdo:
    """One PDO of a node: configuration (from the data store) and runtime state.

    The fields after ``key`` are compiled from the configuration by
    :meth:`PdoEngine._compile_pdo` whenever it is (re-)read: a TPDO's payload
    is ``assemble()`` (whose entries are all live numeric objects: one pack of
    its getters' values by the PDO's codec, :func:`hil.canopen.pdo.pdo_codec`;
    else entry by entry from the data store); an RPDO of numeric objects is
    decoded by its codec's unpack (``unpack``, ``plan``: index, subindex, byte
    slice per entry).
    """

    rx: bool
    number: int
    comm_index: int
    map_index: int
    n_entries_max: int
    has_inhibit: bool
    has_event_timer: bool
    cob_id: int = 0
    valid: bool = False
    trans_type: int = 0
    entries: tuple[tuple[int, int, int], ...] = ()  # (index, subindex, bytes)
    length: int = 0
    inhibit_s: float = 0.0
    event_timer_s: float = 0.0
    sync_count: int = 0
    latched: bytes | None = None
    last_payload: bytes | None = None
    last_sent_t: float | None = None
    pending: bool = False
    key: tuple = field(default=())
    sync: bool = False  # trans_type <= 240
    event: bool = False  # trans_type >= 254
    assemble: Callable[[], bytes] | None = None  # a TPDO's payload now
    unpack: Callable[[bytes], tuple] | None = None
    plan: tuple[tuple[int, int, int, int], ...] = ()
    keys: tuple[tuple[int, int], ...] = ()
    cache_ok: tuple[bool, ...] = ()  # per entry: decoded value goes to the decoded-integer cache
    all_cache_ok: bool = False
    touches_cpr: bool = False  # maps 0x608F (counts per revolution)
    effects: tuple[tuple[int, int], ...] = ()  # entries with side effects (SimDrive.after_write)

    @property
    def is_synchronous(self) -> bool:
        return self.trans_type <= 240

    @property
    def is_event(self) -> bool:
        return self.trans_type >= 254

    def restart(self) -> None:
        """Forget the runtime state (SYNC count, latched RPDO, last payload, pending event)."""
        self.sync_count = 0
        self.latched = None
        self.last_payload = None
        self.pending = False


class PdoEngine:
    """Mixin of :class:`sim.drives.drive.SimDrive`: its PDOs, configured by the object dictionary.

    The attributes below are the ones this part owns (set in
    :meth:`init_pdos` and :meth:`refresh_pdos`). It uses ``store``,
    ``object_data``, ``int_cache``, ``int_value``, ``live_objects``, ``write_object``, ``outbox``,
    ``counters``, ``now_s`` and ``after_write`` of the drive, ``nmt_state``
    and ``send_emcy`` of :class:`~sim.drives.nmt_slave.NmtSlave`, and
    ``controlword_written`` and ``cpr_changed`` of
    :class:`~sim.drives.cia402_drive.Cia402Drive`.

    Attributes
    ----------
    _rpdos, _tpdos : list of Pdo
        Every PDO record of the EDS.
    rpdos_by_cob_id : dict
        COB-ID -> valid RPDOs of that COB-ID (a new dict at each refresh;
        :class:`sim.drives.SimDrivePair` keys its routes on its identity).
    _sync_tpdos_list, event_tpdos, _timed_tpdos_list : tuple of Pdo
        Valid TPDOs sent at SYNC (0..240), on events (254/255), on their
        event timer.
    _sync_rpdos : tuple of Pdo
        Valid synchronous RPDOs (the only ones that latch).
    comm_error : bool
        An RPDO length error stands (EMCY sent, 0x1001 bits 0 and 4).
    """

    def init_pdos(self) -> None:
        """Discover the PDO records of the EDS (configured by :meth:`refresh_pdos`)."""
        self._sync_tpdos_list: tuple[Pdo, ...] = ()
        self.event_tpdos: tuple[Pdo, ...] = ()
        self._timed_tpdos_list: tuple[Pdo, ...] = ()
        self._sync_rpdos: tuple[Pdo, ...] = ()
        self.comm_error = False
        self._rpdos = self._discover(rx=True)
        self._tpdos = self._discover(rx=False)
        self.rpdos_by_cob_id: dict[int, list[Pdo]] = {}

    # ------------------------------------------------------------------ configuration

    def _discover(self, rx: bool) -> list[Pdo]:
        od = self.store.object_dictionary
        var = self.store.var
        base = 0x1400 if rx else 0x1800
        pdos = []
        for k in range(512):
            comm, mapping = base + k, base + 0x200 + k
            if comm not in od or mapping not in od or isinstance(od[mapping], cod.ODVariable) \
                    or isinstance(od[comm], cod.ODVariable):
                continue
            n_max = max((s for s in od[mapping].subindices if s > 0), default=0)
            pdos.append(Pdo(rx=rx, number=k + 1, comm_index=comm, map_index=mapping, n_entries_max=n_max,
                            has_inhibit=var(comm, 3) is not None, has_event_timer=var(comm, 5) is not None))
        return pdos

    def _default_mapping_problems(self) -> list[str]:
        """What is wrong with the stored (EDS default) mapping of every PDO, one line each (a vendor's
        default may map what this node cannot serve: such entries are sent as zeros, see the module
        docstring)."""
        problems = []
        for p in self._rpdos + self._tpdos:
            problem = self._mapping_problem(p, self.store.int_or(p.map_index, 0, 0))
            if problem is not None:
                problems.append(f"0x{p.map_index:04X}: {problem[1]}")
        return problems

    def pdo_by_index(self, index: int) -> Pdo | None:
        for p in self._rpdos + self._tpdos:
            if index in (p.comm_index, p.map_index):
                return p
        return None

    def check_pdo_write(self, p: Pdo, index: int, subindex: int, value: int) -> None:
        """Validate an SDO write of ``p``'s communication or mapping record (raise to refuse)."""
        if index == p.comm_index:
            self._check_comm_write(p, subindex, value)
        else:
            self._check_map_write(p, subindex, value)

    def _check_comm_write(self, p: Pdo, subindex: int, value: int) -> None:
        if subindex == 1:
            if value & (1 << 29) or value & 0x1FFFF800:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # 11-bit identifiers only
            new_valid = not value & COB_ID_INVALID
            can_id = value & 0x7FF
            if p.valid and new_valid and can_id != p.cob_id:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # CiA 301: not while the PDO exists
            if new_valid and any(lo <= can_id <= hi for lo, hi in RESTRICTED_CAN_IDS):
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif subindex == 2:
            if not (0 <= value <= 240 or value in (254, 255)):
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif subindex == 3:
            if p.valid:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # inhibit time: only while invalid

    def _check_map_write(self, p: Pdo, subindex: int, value: int) -> None:
        if p.valid:
            raise abort(SdoAbortCode.PARAMETER_INCOMPATIBILITY)
        if subindex == 0:
            problem = self._mapping_problem(p, value)
            if problem is not None:
                raise abort(problem[0])
        else:
            if self.int_value(p.map_index, 0) != 0:
                raise abort(SdoAbortCode.PARAMETER_INCOMPATIBILITY)
            if value != 0 and self._entry_problem(value, p.rx) is not None:
                raise abort(SdoAbortCode.CANNOT_BE_MAPPED)

    def _entry_problem(self, entry: int, rx: bool) -> str | None:
        index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        var = self.store.var(index, subindex)
        where = f"entry 0x{entry:08X}"
        if var is None:
            return f"{where}: object 0x{index:04X}:{subindex:02X} does not exist"
        if not var.pdo_mappable:
            return f"{where}: object is not PDO-mappable"
        if rx and not var.writable:
            return f"{where}: object is not writable (RPDO)"
        if not rx and not var.readable:
            return f"{where}: object is not readable (TPDO)"
        if var.data_type not in cod.NUMBER_TYPES or bits % 8 or bits != len(var):
            return f"{where}: {bits} bits, the object has {len(var)} (whole bytes only)"
        return None

    def _mapping_problem(self, p: Pdo, count: int) -> tuple[SdoAbortCode, str] | None:
        """(abort code, reason) if ``count`` entries of ``p``'s stored mapping are not a valid PDO."""
        if count > p.n_entries_max:
            return SdoAbortCode.EXCEEDS_PDO_LENGTH, f"{count} entries exceed the {p.n_entries_max} of the record"
        total = 0
        for k in range(1, count + 1):
            entry = self.store.int_or(p.map_index, k, 0)
            problem = self._entry_problem(entry, p.rx)
            if problem is not None:
                return SdoAbortCode.CANNOT_BE_MAPPED, problem
            total += entry & 0xFF
        if total > 64:
            return SdoAbortCode.EXCEEDS_PDO_LENGTH, f"{total} mapped bits exceed 64"
        return None

    def refresh_pdos(self) -> None:
        """Re-read every PDO's configuration from the data store; keep runtime state if unchanged."""
        by_cob: dict[int, list[Pdo]] = {}
        int_or = self.store.int_or
        for p in self._rpdos + self._tpdos:
            cob = int_or(p.comm_index, 1, COB_ID_INVALID)
            count = min(int_or(p.map_index, 0, 0), p.n_entries_max)
            entries = []
            size = 0
            for k in range(1, count + 1):
                e = int_or(p.map_index, k, 0)
                n = (e & 0xFF) // 8
                if n and size + n <= 8:  # (an entry of 0 bits maps nothing; a CAN frame holds 8 bytes)
                    entries.append((e >> 16, (e >> 8) & 0xFF, n))
                    size += n
            p.cob_id = cob & 0x7FF
            p.valid = not cob & COB_ID_INVALID
            p.trans_type = int_or(p.comm_index, 2, 255)
            p.entries = tuple(entries)
            p.length = sum(n for _, _, n in entries)
            p.inhibit_s = self.int_value(p.comm_index, 3) * 1e-4 if p.has_inhibit else 0.0
            p.event_timer_s = self.int_value(p.comm_index, 5) * 1e-3 if p.has_event_timer else 0.0
            key = (p.cob_id, p.valid, p.trans_type, p.entries)
            if key != p.key:
                p.key = key
                p.restart()
            if p.rx and p.valid:
                by_cob.setdefault(p.cob_id, []).append(p)
            self._compile_pdo(p)
        self.rpdos_by_cob_id = by_cob
        self._sync_tpdos_list = tuple(p for p in self._tpdos if p.valid and p.sync)
        self.event_tpdos = tuple(p for p in self._tpdos if p.valid and p.event)
        self._timed_tpdos_list = tuple(p for p in self.event_tpdos if p.event_timer_s > 0.0)
        # a latched RPDO is always valid and synchronous: a change of either resets ``latched``
        self._sync_rpdos = tuple(p for p in self._rpdos if p.valid and p.sync)

    def _compile_pdo(self, p: Pdo) -> None:
        """Compile ``p``'s entries into its codec (see :class:`Pdo`); entry by entry otherwise."""
        p.sync = p.trans_type <= 240
        p.event = p.trans_type >= 254
        p.unpack = None
        p.assemble = None if p.rx else partial(self._entries_payload, p.entries)
        p.plan = p.cache_ok = ()
        p.all_cache_ok = False
        p.keys = tuple((i, s) for i, s, _ in p.entries)
        p.touches_cpr = any(i == 0x608F for i, _ in p.keys)
        p.effects = tuple((i, s) for i, s in p.keys if i == 0x6040 or i == 0x6060 or 0x1000 <= i <= 0x1FFF)
        codes = []
        for i, s, nbytes in p.entries:
            var = self.store.var(i, s)
            code = STRUCT_CODES.get(var.data_type) if var is not None else None
            if code is None or pdo_codec(code).size != nbytes:
                return
            codes.append(code)
        codec = pdo_codec("".join(codes))
        live = self.live_objects
        if p.rx:
            plan, off = [], 0
            for i, s, nbytes in p.entries:
                plan.append((i, s, off, off + nbytes))
                off += nbytes
            p.plan = tuple(plan)
            p.cache_ok = tuple(c in INT_CODES and k not in live for c, k in zip(codes, p.keys, strict=True))
            p.all_cache_ok = all(p.cache_ok)
            p.unpack = codec.unpack
        elif all(k in live for k in p.keys):
            p.assemble = _packed(codec.pack, tuple(live[k] for k in p.keys))

    def restart_pdos(self) -> None:
        """Entering OPERATIONAL: every PDO starts afresh."""
        for p in self._rpdos + self._tpdos:
            p.restart()

    def drop_latched_rpdos(self) -> None:
        for p in self._rpdos:
            p.latched = None

    # ------------------------------------------------------------------ TPDOs

    def _entries_payload(self, entries: tuple[tuple[int, int, int], ...]) -> bytes:
        """A TPDO's payload entry by entry (:meth:`_entry_bytes`): the mapping has an entry that is no live
        number (a stored value, a dummy entry, an object this node lacks)."""
        return b"".join(self._entry_bytes(i, s, n) for i, s, n in entries)

    def _entry_bytes(self, index: int, subindex: int, nbytes: int) -> bytes:
        """One mapped entry's bytes for a TPDO: its value cut or zero-padded to the mapped length;
        zeros for an object this node does not have (a dummy entry or a vendor's default mapping)."""
        if self.store.var(index, subindex) is None:
            return bytes(nbytes)
        raw = self.store.raw(index, subindex)
        return raw if len(raw) == nbytes else raw[:nbytes].ljust(nbytes, b"\0")

    def _send_tpdo(self, p: Pdo, t: float, payload: bytes | None = None) -> None:
        if payload is None:
            payload = p.assemble()
        # 11-bit COB-ID (cob & 0x7FF) and at most 64 mapped bits: a valid frame by construction
        self.outbox.append(_trusted(p.cob_id, payload))
        p.last_payload = payload
        p.last_sent_t = t
        p.pending = False
        self.counters.tpdos_sent += 1

    def send_sync_tpdos(self, t: float) -> None:
        """Send the synchronous TPDOs due at this SYNC (OPERATIONAL only)."""
        if self.nmt_state is not _OPERATIONAL:
            return
        send = self._send_tpdo
        for p in self._sync_tpdos_list:  # valid, transmission type 0..240
            tt = p.trans_type
            if tt:
                count = p.sync_count + 1
                if count < tt:
                    p.sync_count = count
                    continue
                p.sync_count = 0
                send(p, t, p.assemble())
            else:
                payload = p.assemble()
                if payload != p.last_payload:
                    send(p, t, payload)

    def send_event_tpdos(self, t: float) -> None:
        """Send event-driven TPDOs (254/255) whose payload changed, respecting the inhibit time."""
        if not self.event_tpdos or self.nmt_state is not _OPERATIONAL:
            return
        for p in self.event_tpdos:  # valid, transmission type 254/255
            payload = p.assemble()
            if payload == p.last_payload and not p.pending:
                continue
            if p.last_sent_t is None or t - p.last_sent_t >= p.inhibit_s - TIME_EPS_S:
                self._send_tpdo(p, t, payload)
            else:
                p.pending = True

    def send_timed_tpdos(self, t: float) -> None:
        if self.nmt_state is not _OPERATIONAL:
            return
        for p in self._timed_tpdos_list:  # valid, 254/255, event timer > 0
            if p.last_sent_t is None or t - p.last_sent_t >= p.event_timer_s - TIME_EPS_S:
                self._send_tpdo(p, t)
        self.send_event_tpdos(t)

    # ------------------------------------------------------------------ RPDOs

    def on_rpdo(self, pdos: list[Pdo], frame: Frame, t: float) -> None:
        """An RPDO frame for ``pdos`` (the node's valid RPDOs of its COB-ID): latch or apply."""
        self.now_s = t
        if self.nmt_state is not _OPERATIONAL:
            self.counters.rpdos_dropped += 1
            return
        n = len(frame.data)
        for p in pdos:
            if n != p.length:
                self.counters.rpdos_dropped += 1
                if not self.comm_error:
                    self.comm_error = True
                    self.send_emcy(EMCY_PDO_LENGTH_ERROR if n < p.length else EMCY_PDO_LENGTH_EXCEEDED)
                continue
            if self.comm_error:
                self.comm_error = False
                self.send_emcy(EMCY_NO_ERROR)
            if p.sync:
                if p.latched is not None:
                    self.counters.rpdos_late += 1
                p.latched = frame.data
            else:
                self._apply_rpdo(p, frame.data)

    def _apply_rpdo(self, p: Pdo, data: bytes) -> None:
        unpack = p.unpack
        if unpack is not None:
            # one unpack; raw bytes to the data store (the OD stays the source of truth)
            # and the decoded integers straight into the decoded-value cache
            if data.__class__ is not bytes:
                data = bytes(data)
            store = self.object_data
            for index, subindex, a, b in p.plan:
                d = store.get(index)
                if d is None:
                    d = store[index] = {}
                d[subindex] = data[a:b]
            values = unpack(data)
            ic = self.int_cache
            if p.all_cache_ok:
                ic.update(zip(p.keys, values, strict=True))
            else:
                for key, v, ok in zip(p.keys, values, p.cache_ok, strict=True):
                    if ok:
                        ic[key] = v
                    else:
                        ic.pop(key, None)
            if p.touches_cpr:
                self.cpr_changed()
        else:
            off = 0
            for index, subindex, nbytes in p.entries:
                self.write_object(index, subindex, data[off:off + nbytes])
                off += nbytes
        self.counters.rpdos_applied += 1
        effects = p.effects  # the entries _after_write acts on, in mapping order
        if effects:
            if effects == _ONLY_CONTROLWORD:
                self.controlword_written()
            else:
                self.after_write(effects)

    def apply_latched_rpdos(self) -> None:
        """At a SYNC: apply the synchronous RPDOs latched since the previous one."""
        for p in self._sync_rpdos:  # (only valid synchronous RPDOs latch)
            if p.latched is not None:
                data, p.latched = p.latched, None
                self._apply_rpdo(p, data)
