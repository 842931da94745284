"""NMT slave, heartbeat producer, EMCY producer and error history of a simulated node.

The CiA 301 services of :class:`sim.drives.node.SimNode` (a drive or a sensor node) besides SDO
(:mod:`sim.drives.store`) and PDO (:mod:`sim.drives.pdo_engine`): boot-up,
NMT commands and state, the heartbeat (0x1017), the EMCY (0x1014) and the
pre-defined error field 0x1003. The frames are those of
:mod:`hil.canopen.nmt` and :mod:`hil.canopen.emcy`.

Choices (CiA 301 leaves them open or this drive restricts them)
---------------------------------------------------------------
* Power-on: the node's application boots instantly (a drive: CiA 402
  transition 1 at power-on, NMT INITIALISING -> boot-up frame ->
  PRE-OPERATIONAL).
* NMT reset node restores every object to its EDS default (plus the node's
  own data, see :mod:`sim.drives.served`) and the application (a drive: the
  state SWITCH_ON_DISABLED); reset communication restores 0x1000..0x1FFF and
  keeps the application's state. Leaving OPERATIONAL does not change the drive state: the
  drive keeps following the last values received. Entering OPERATIONAL
  restarts every PDO's runtime state; leaving it drops latched RPDOs.
* Heartbeat: sent at the first tick at or after each multiple of the
  producer time 0x1017 since boot-up (or since 0x1017 was written); if ticks
  are farther apart than the period, one heartbeat is sent and the schedule
  restarts from that tick.
* Heartbeat consumer (0x1016, up to its sub-index 0 entries): entry = node id
  (bits 16..23) and consumer time [ms] (bits 0..15); 0 in either is unused,
  bits 24..31 must be 0 and a node may be monitored by one entry only
  (0x06040043). Monitoring of an entry starts with the first heartbeat (or
  boot-up) of its producer after the entry was written; a heartbeat event is
  the first :meth:`~sim.drives.SimDrivePair.tick` (or free-running drive
  cycle) at which more than the consumer time passed since that producer's
  last heartbeat. The event sends EMCY 0x8130 (error register bits 0 and 4
  while it stands), is recorded in ``heartbeat_events`` and triggers the
  application's reaction: a drive's CiA 402 abort connection option 0x6007
  (:class:`~sim.drives.cia402_drive.Cia402Drive`); a sensor node has none.
  The NMT state is kept (no 0x1029 error behaviour). A heartbeat of that
  producer ends the event (EMCY 0x0000 when no other error stands) and
  re-arms the entry; the drive state is not restored.
* EMCY: COB-ID from 0x1014 (bit 31 = not sent), sent in PRE-OPERATIONAL and
  OPERATIONAL only; data = error code u16, error register 0x1001 u8, five
  zero manufacturer bytes. Error codes other than 0 are pushed into the
  pre-defined error field 0x1003 (4 entries; writing 0 to 0x1003:00 clears
  it).
* Error register 0x1001: the bits of the latched fault
  (:func:`hil.canopen.emcy.error_register_bits`) plus bits 0 and 4 while an
  RPDO length error stands.
* SYNC consumer (0x1005): the node is no SYNC producer (bit 30 refused),
  11-bit COB-IDs only. 0x1006 is stored; SYNC is not supervised (see the
  free-running drive cycle of :mod:`sim.drives.pair`). EMCY COB-ID (0x1014): the CAN-ID cannot change while
  the EMCY is valid.
"""

from __future__ import annotations

import struct

from hil.canopen.emcy import EmcyCode, emcy_frame
from hil.canopen.frame import EMCY_COB_ID_BASE, SYNC_COB_ID
from hil.canopen.nmt import NmtCommand, NmtState, heartbeat_frame
from hil.canopen.pdo import COB_ID_INVALID
from hil.canopen.sdo import SdoAbortCode
from sim.drives.store import abort

__all__ = [
    "EMCY_HEARTBEAT",
    "EMCY_NO_ERROR",
    "EMCY_PDO_LENGTH_ERROR",
    "EMCY_PDO_LENGTH_EXCEEDED",
    "ERROR_HISTORY_LEN",
    "TIME_EPS_S",
    "NmtSlave",
]

#: EMCY error code "error reset or no error".
EMCY_NO_ERROR = int(EmcyCode.NO_ERROR)
#: EMCY error code "PDO not processed due to length error".
EMCY_PDO_LENGTH_ERROR = int(EmcyCode.PDO_LENGTH)
#: EMCY error code "PDO length exceeded".
EMCY_PDO_LENGTH_EXCEEDED = int(EmcyCode.PDO_LENGTH_EXCEEDED)
#: EMCY error code "life guard error or heartbeat error" (a heartbeat consumer event).
EMCY_HEARTBEAT = int(EmcyCode.LIFE_GUARD_OR_HEARTBEAT)
#: Entries of the pre-defined error field 0x1003.
ERROR_HISTORY_LEN = 4
#: Tolerance of the time comparisons (heartbeat, inhibit and event timers) [s].
TIME_EPS_S = 1e-9

_TALKING = (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


class NmtSlave:
    """Mixin of :class:`sim.drives.node.SimNode`: NMT slave, heartbeat, EMCY, error history.

    The attributes below are the ones this part owns (set in
    :meth:`init_nmt`). It uses ``node_id``, ``now_s``, ``outbox``,
    ``counters``, ``store``, ``sdo``, ``int_cache``, ``int_value`` and ``write_object``
    of the node, its application hooks (``cpr_changed``,
    ``apply_own_data``, ``reset_application``, ``after_boot``,
    ``connection_lost``, ``app_error_bits``), and ``comm_error``,
    the PDO lists, ``refresh_pdos``, ``restart_pdos``, ``drop_latched_rpdos``
    and ``send_timed_tpdos`` of :class:`~sim.drives.pdo_engine.PdoEngine`.

    Attributes
    ----------
    nmt_state : NmtState
        Current NMT state.
    heartbeat_enabled : bool
        Fault hook: False suppresses the heartbeat frames (the producer
        timer keeps running, so re-enabling resumes in phase).
    _hb_period_s : float
        Heartbeat producer time 0x1017 [s].
    _hb_next : float or None
        Time of the next heartbeat [s], None when the producer is off.
    sync_cob_id : int
        COB-ID of the SYNC this node consumes (0x1005).
    _emcy_cob_id : int or None
        COB-ID of its EMCY (0x1014), None when invalid.
    heartbeat_consumers : dict
        Heartbeat consumer (0x1016): producer node id -> ``[time_s, last_s, in_error]``
        (``last_s`` None until its first heartbeat).
    _hb_error : bool
        A heartbeat event stands (error register bits 0 and 4).
    heartbeat_events : list of (float, int)
        Time [s] and producer node id of every heartbeat event.
    """

    def init_nmt(self) -> None:
        """Initial state (INITIALISING until the pair powers the node on)."""
        self.nmt_state = NmtState.INITIALISING
        self.heartbeat_enabled = True
        self._hb_period_s = 0.0
        self._hb_next: float | None = None
        self.sync_cob_id = SYNC_COB_ID
        self._emcy_cob_id: int | None = EMCY_COB_ID_BASE + self.node_id
        self.heartbeat_consumers: dict[int, list] = {}
        self._hb_error = False
        self.heartbeat_events: list[tuple[float, int]] = []

    # ------------------------------------------------------------------ boot and NMT commands

    def boot(self, t: float, *, communication_only: bool) -> None:
        """Power-on / reset: restore defaults, boot-up frame, PRE-OPERATIONAL."""
        self.now_s = t
        self.store.reset(communication_only=communication_only)
        self.cpr_changed()
        if not communication_only:
            self.apply_own_data()
            self.reset_application()
        self.comm_error = False
        self._hb_error = False
        self.heartbeat_consumers = {}
        self.sdo.reset()
        self.nmt_state = NmtState.INITIALISING
        self.outbox.append(heartbeat_frame(self.node_id, NmtState.BOOT_UP))
        self.nmt_state = NmtState.PRE_OPERATIONAL
        self.refresh_comm(restart_heartbeat=True)
        if not communication_only:
            self.after_boot()

    def on_nmt_command(self, cs: int, t: float) -> None:
        """Apply NMT command specifier ``cs`` (a valid :class:`NmtCommand` value) at time ``t``."""
        self.now_s = t
        if cs == NmtCommand.START:
            if self.nmt_state is not NmtState.OPERATIONAL:
                self.nmt_state = NmtState.OPERATIONAL
                self.restart_pdos()
        elif cs == NmtCommand.STOP:
            self.nmt_state = NmtState.STOPPED
            self.drop_latched_rpdos()
        elif cs == NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt_state = NmtState.PRE_OPERATIONAL
            self.drop_latched_rpdos()
        elif cs == NmtCommand.RESET_NODE:
            self.boot(t, communication_only=False)
        elif cs == NmtCommand.RESET_COMMUNICATION:
            self.boot(t, communication_only=True)

    def refresh_comm(self, *, restart_heartbeat: bool) -> None:
        """Re-read the communication objects (SYNC, EMCY, heartbeat if asked, PDOs)."""
        self.sync_cob_id = self.store.int_or(0x1005, 0, SYNC_COB_ID) & 0x7FF
        emcy = self.store.int_or(0x1014, 0, EMCY_COB_ID_BASE + self.node_id)
        self._emcy_cob_id = None if emcy & COB_ID_INVALID else emcy & 0x7FF
        if restart_heartbeat:
            period_ms = self.store.int_or(0x1017, 0, 0)
            self._hb_period_s = period_ms / 1000.0
            self._hb_next = self.now_s + self._hb_period_s if period_ms > 0 else None
        self._refresh_consumers()
        self.refresh_pdos()

    def _refresh_consumers(self) -> None:
        """Re-read the heartbeat consumer entries 0x1016; an unchanged entry keeps its monitoring,
        a changed one waits for its producer's first heartbeat again."""
        store = self.store
        new: dict[int, list] = {}
        if store.var(0x1016, 0) is not None:
            for k in range(1, self.int_value(0x1016, 0) + 1):
                if store.var(0x1016, k) is None:
                    continue
                v = self.int_value(0x1016, k)
                node, time_s = v >> 16 & 0xFF, (v & 0xFFFF) / 1000.0
                if node and time_s:
                    old = self.heartbeat_consumers.get(node)
                    new[node] = old if old is not None and old[0] == time_s else [time_s, None, False]
        self.heartbeat_consumers = new

    def check_comm_object_write(self, index: int, subindex: int, value: int) -> None:
        """Validate an SDO write of 0x1005, 0x1014, 0x1003 or 0x1016 (raise SdoAbortedError to refuse)."""
        if index == 0x1005:
            if value & ((1 << 30) | (1 << 29)) or value & 0x1FFFF800:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # this node is no SYNC producer; 11 bit
        elif index == 0x1014:
            if value & (1 << 29) or value & 0x1FFFF800:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
            old = self.int_value(0x1014)
            if not (old | value) & COB_ID_INVALID and (old ^ value) & 0x7FF:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x1003 and subindex == 0:
            if value != 0:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x1016:
            node = value >> 16 & 0xFF
            if value >> 24 or node > 127:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
            for k in range(1, self.int_value(0x1016, 0) + 1):
                if k == subindex or self.store.var(0x1016, k) is None:
                    continue
                other = self.int_value(0x1016, k)
                if node and value & 0xFFFF and other >> 16 & 0xFF == node and other & 0xFFFF:
                    raise abort(SdoAbortCode.PARAMETER_INCOMPATIBILITY)  # one entry per producer

    # ------------------------------------------------------------------ heartbeat

    def nmt_tick(self, t: float) -> None:
        """Time passes to ``t``: the heartbeat consumer, the heartbeat if due, the timed event TPDOs."""
        self.now_s = t
        if self.heartbeat_consumers:
            self.supervise_heartbeats(t)
        if self._hb_next is not None and t >= self._hb_next - TIME_EPS_S:
            if self.heartbeat_enabled:
                self.outbox.append(heartbeat_frame(self.node_id, self.nmt_state))
                self.counters.heartbeats_sent += 1
            self._hb_next += self._hb_period_s
            if self._hb_next <= t:
                self._hb_next = t + self._hb_period_s
        if self.event_tpdos:  # (_timed_tpdos only acts on valid event-driven TPDOs)
            self.send_timed_tpdos(t)

    # ------------------------------------------------------------------ heartbeat consumer

    def on_heartbeat(self, producer: int, t: float) -> bool:
        """A heartbeat (or boot-up) of node ``producer`` at ``t``; False if this node does not consume it."""
        c = self.heartbeat_consumers.get(producer)
        if c is None:
            return False
        c[1] = t
        if c[2]:  # the event ends; the drive state is not restored
            c[2] = False
            if not any(e[2] for e in self.heartbeat_consumers.values()):
                self._hb_error = False
                if not self.error_register:
                    self.send_emcy(EMCY_NO_ERROR)
        return True

    def supervise_heartbeats(self, t: float) -> None:
        """Heartbeat events at time ``t``: more than the consumer time since the producer's last heartbeat."""
        for node, c in self.heartbeat_consumers.items():
            last = c[1]
            if last is not None and not c[2] and t - last > c[0] + TIME_EPS_S:
                c[2] = True
                self._hb_error = True
                self.heartbeat_events.append((t, node))
                self.send_emcy(EMCY_HEARTBEAT)
                self.connection_lost()

    # ------------------------------------------------------------------ EMCY and error history

    @property
    def error_register(self) -> int:
        """Error register 0x1001: the application's bits (a drive's latched fault) plus bits 0 and 4 for
        a PDO length error or a heartbeat event."""
        reg = self.app_error_bits()
        if self.comm_error or self._hb_error:
            reg |= 0x11
        return reg

    def send_emcy(self, code: int) -> None:
        """Produce EMCY ``code`` (0: error reset); a code other than 0 goes into 0x1003 first."""
        if code:
            self._push_error(code)
        if self.nmt_state not in _TALKING or self._emcy_cob_id is None:
            return
        self.outbox.append(emcy_frame(self._emcy_cob_id, code, self.error_register))
        self.counters.emcys_sent += 1

    def _push_error(self, code: int) -> None:
        store = self.store
        if store.var(0x1003, 0) is None:
            return
        n = min(self.int_value(0x1003, 0), ERROR_HISTORY_LEN)
        old = [store.get_data(0x1003, k) for k in range(1, n + 1)]
        self.write_object(0x1003, 1, struct.pack("<I", code))
        for k, raw in enumerate(old[:ERROR_HISTORY_LEN - 1], start=2):
            self.write_object(0x1003, k, raw)
        self.write_object(0x1003, 0, bytes([min(n + 1, ERROR_HISTORY_LEN)]))

    def clear_error_history(self) -> None:
        """0 written to 0x1003:00: forget the entries."""
        for k in range(1, ERROR_HISTORY_LEN + 1):
            self.store.data.get(0x1003, {}).pop(k, None)
            self.int_cache.pop((0x1003, k), None)
