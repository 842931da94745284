"""The CANopen master as a sans-IO core (CiA 302-style boot, CiA 402 drives).

:class:`MasterCore` is fed every frame seen on the bus (including the SYNC
frames, whoever sends them) with a time value, and returns the frames to
transmit. It never touches a bus, a thread or a clock: the shells in
:mod:`hil.link` move frames over python-can, pace SYNC and pass time.

Life cycle::

    PREFLIGHT  NMT reset node -> boot-up of both drives -> per drive, by SDO:
               identity 0x1018 against the profile, device type 0x1000 (CiA 402),
               supported modes 0x6502 (CSP, CST), gear ratio 0x2102 and encoder
               resolution 0x608F against the profile, rated/max torque,
               heartbeat producer 0x1017, interpolation period 0x60C2,
               software position limits 0x607D (the stroke limits), quick stop
               option 0x605A, PDO mapping of :data:`hil.canopen.pdo.DEFAULT_LAYOUT`,
               the reaction to the master's death (read back: consumer heartbeat
               0x1016:01, abort connection option 0x6007 = 3, 0x605A, 0x1006)
               -> NMT start.
    CYCLIC     SYNC -> TPDO1/TPDO2 of both drives -> one :class:`~hil.canopen.process.Sample`;
               setpoints -> RPDO2 (mode, only on change) and RPDO1 (controlword,
               targets) before the next SYNC. Heartbeat consumer with a timeout
               per drive, EMCY consumer.

Heartbeat producer: :meth:`MasterCore.poll` returns the master's heartbeat when due, from
:meth:`~MasterCore.start` to the NMT pre-operational at the end: from the master's own loop
(never a kernel-timed task), so that a dead or hung master stops it.

Errors are typed and name the drive: :class:`PreflightError` (identity,
device type, ...), :class:`MasterLossReactionError`, :class:`~hil.canopen.sdo.SdoAbortError`
(code and meaning), :class:`~hil.canopen.sdo.SdoTimeout`, :class:`DriveFault` (EMCY, fault
state), :class:`HeartbeatLost`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from enum import Enum
from typing import Generator

from hil.canopen.cia402 import Command, OperationMode, State, controlword, decode_state, next_command
from hil.canopen.emcy import Emcy, EmcyCode, decode_emcy
from hil.canopen.frame import (
    EMCY_COB_ID_BASE,
    HEARTBEAT_COB_ID_BASE,
    NMT_COB_ID,
    SDO_RX_COB_ID_BASE,
    SDO_TX_COB_ID_BASE,
    SYNC_COB_ID,
    Frame,
    split_cob_id,
)
from hil.canopen.nmt import NmtCommand, NmtState, heartbeat_frame, nmt_frame
from hil.canopen.od import QUICK_STOP_OPTION, AbortConnectionOption, master_loss_steps
from hil.canopen.pdo import (
    DEFAULT_LAYOUT,
    RPDO1,
    RPDO2,
    TPDO1,
    TPDO2,
    PdoError,
    Rpdo1,
    Rpdo2,
    decode_tpdo1,
    decode_tpdo2,
    encode_rpdo1,
    encode_rpdo2,
)
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.sdo import SdoAbortError, SdoClient, SdoEvent, describe, expedited_download_frame
from hil.canopen.units import force_dN_to_newton, force_to_permille, increments_to_rad, lvdt_um_to_mm, rad_to_increments
from hil.config import Actuation
from hil.errors import EmacheckError

_TPDO1, _TPDO2 = TPDO1.cob_id_base, TPDO2.cob_id_base
#: The function codes of the frames the master only sees go by: its own RPDOs and SDO requests.
_OWN_TRAFFIC = frozenset((RPDO1.cob_id_base, RPDO2.cob_id_base, SDO_TX_COB_ID_BASE))


class PreflightError(EmacheckError, RuntimeError):
    """A drive does not match the profile or did not come up."""


class DriveFault(EmacheckError, RuntimeError):
    """A drive reported a fault (EMCY or fault state) during the check."""


class HeartbeatLost(EmacheckError, RuntimeError):
    """A drive's heartbeat did not arrive within its timeout."""


class MasterLossReactionError(PreflightError):
    """A drive lacks or refuses its reaction to the master's death (0x1016, 0x6007) and no other is stated."""


class EventKind(Enum):
    """What a :class:`MasterEvent` reports."""

    NMT = "nmt"  #: an NMT command sent
    BOOT = "boot"  #: a drive's boot-up message
    SDO = "sdo"  #: an SDO sent outside the preflight (the quick stop by SDO)
    PREFLIGHT = "preflight"  #: a drive identified and configured
    STATE = "state"  #: a drive's CiA 402 state changed
    EMCY = "emcy"  #: an emergency message
    MISSING = "missing"  #: a SYNC cycle whose TPDOs were incomplete at the next SYNC
    BAD_FRAME = "bad_frame"  #: a malformed PDO, counted and ignored
    HEARTBEAT = "heartbeat"  #: a drive's heartbeat lost
    FAULT = "fault"  #: a fault after the first one (recorded, not raised again)


@dataclass(frozen=True, slots=True)
class MasterEvent:
    """Something the master saw or did, for the log (the core never prints)."""

    t_s: float
    kind: EventKind
    node_id: int
    detail: str


# ------------------------------------------------------------ preflight requests


@dataclass(frozen=True, slots=True)
class _Nmt:
    command: NmtCommand


@dataclass(frozen=True, slots=True)
class _WaitBoot:
    pass


@dataclass(frozen=True, slots=True)
class _SdoRead:
    node: int
    index: int
    sub: int
    what: str
    soft: bool = False  #: an abort comes back to the preflight as the result (not raised)


@dataclass(frozen=True, slots=True)
class _SdoWrite:
    node: int
    index: int
    sub: int
    data: bytes
    what: str
    soft: bool = False


class Phase(Enum):
    IDLE = "idle"
    PREFLIGHT = "preflight"
    CYCLIC = "cyclic"
    FAILED = "failed"


@dataclass
class DriveView:
    """What the master knows of one drive (mutable, owned by the core)."""

    node_id: int
    rated_torque_Nm: float = 1.0
    max_torque_permille: int = 0
    state: State = State.NOT_READY_TO_SWITCH_ON
    statusword: int = 0
    mode_display: int = 0
    mode_sent: int | None = None
    last_heartbeat_s: float | None = None
    nmt_state: int | None = None
    booted: bool = False
    tpdo1: object | None = None
    tpdo2: object | None = None
    identity: dict = field(default_factory=dict)
    last_tpdo_s: float | None = None  #: time of the last TPDO1 (statusword) seen in the cyclic phase
    lost: bool = False  #: heartbeat lost (the consumer fired for this node)
    #: how this drive is protected against the master's death (set by the preflight)
    master_loss: dict = field(default_factory=dict)


def _u(data: bytes) -> int:
    return int.from_bytes(data, "little", signed=False)


class MasterCore:
    """CANopen master of the two EMA drives, sans-IO.

    Parameters
    ----------
    actuation : Actuation
        Node ids, bit rate, heartbeat, identity, gear ratio, stroke limits,
        resolver resolution, SYNC period.
    """

    def __init__(self, actuation: Actuation) -> None:
        self.act = actuation
        c = actuation.canopen
        self.T = actuation.timing.sync_period_s
        self.i_total = actuation.mechanics.i_total_rad_per_mm
        self.counts = actuation.sensors.resolver_counts_per_rev
        self.hb_timeout_s = c.heartbeat_period_s * c.heartbeat_timeout_factor
        self.node_id = c.master_node_id  #: the master's own node id (its heartbeat)
        self.hb_period_s = c.master_heartbeat_period_s  #: the master's heartbeat producer time [s]
        self.consumer_ms = round(c.master_consumer_time_s * 1000)  #: the drives' 0x1016 time [ms]
        self._hb_frame = heartbeat_frame(self.node_id, NmtState.OPERATIONAL)
        self._hb_next: float | None = None  #: when the next heartbeat is due; None: not producing
        self.drives = {n: DriveView(n) for n in c.node_ids}
        self.order = c.node_ids  # EMA 1, EMA 2
        self.phase = Phase.IDLE
        self.events: list[MasterEvent] = []
        self.emcy: list[Emcy] = []
        self.cycle = 0  #: SYNC frames seen in the cyclic phase
        self.missing_cycles = 0  #: cycles whose TPDOs were incomplete at the next SYNC
        self.bad_frames = 0
        self.unknown_frames = 0
        self.quick_stop = False  #: shut down by quick stop (abort) rather than orderly
        self.fault: BaseException | None = None  #: the first error, latched
        self.fault_cycle: int | None = None  #: the cyclic-phase SYNC count when the fault latched
        self.later_faults: list[str] = []  #: errors after the first one (recorded, not raised again)
        self._sdo = {n: SdoClient(n, timeout_s=c.sdo_timeout_s) for n in c.node_ids}
        self._gen: Generator | None = None
        self._pending: object | None = None
        self._boot_deadline = 0.0
        self._complete = False
        self._sample: Sample | None = None

    # ---------------------------------------------------------------- events

    def _event(self, t: float, kind: EventKind, node: int, detail: str) -> None:
        self.events.append(MasterEvent(t, kind, node, detail))

    def drain_events(self) -> list[MasterEvent]:
        ev, self.events = self.events, []
        return ev

    # ------------------------------------------------------------- preflight

    def start(self, t: float) -> list[Frame]:
        """Begin the preflight; returns the first frames to send."""
        if self.phase is not Phase.IDLE:
            raise PreflightError(f"master already started (phase {self.phase.value})")
        self.phase = Phase.PREFLIGHT
        self._hb_next = t  # the heartbeat starts with the first frame: the first poll sends it
        self._gen = self._preflight()
        return self._advance(None, t, first=True)

    @property
    def preflight_done(self) -> bool:
        return self.phase is Phase.CYCLIC

    def _preflight(self) -> Generator:
        a = self.act
        c = a.canopen
        yield _Nmt(NmtCommand.RESET_NODE)
        yield _WaitBoot()
        for n in self.order:
            d = self.drives[n]
            ema = self.order.index(n) + 1
            vendor = _u((yield _SdoRead(n, 0x1018, 1, "vendor id")))
            product = _u((yield _SdoRead(n, 0x1018, 2, "product code")))
            revision = _u((yield _SdoRead(n, 0x1018, 3, "revision")))
            serial = _u((yield _SdoRead(n, 0x1018, 4, "serial number")))
            d.identity = {"vendor_id": vendor, "product_code": product, "revision": revision, "serial": serial}
            if vendor != c.vendor_id or product != c.product_code:
                raise PreflightError(
                    f"node {n} (EMA {ema}): identity 0x1018 vendor 0x{vendor:08X} product 0x{product:08X} "
                    f"does not match the profile (canopen.vendor_id 0x{c.vendor_id:08X}, "
                    f"canopen.product_code 0x{c.product_code:08X})")
            if revision < c.revision_min:
                raise PreflightError(f"node {n} (EMA {ema}): revision 0x{revision:08X} below "
                                     f"canopen.revision_min 0x{c.revision_min:08X}")
            devtype = _u((yield _SdoRead(n, 0x1000, 0, "device type")))
            if devtype & 0xFFFF != 402:
                raise PreflightError(f"node {n} (EMA {ema}): device type 0x{devtype:08X} is not a CiA 402 drive")
            modes = _u((yield _SdoRead(n, 0x6502, 0, "supported drive modes")))
            for mode, bit in ((OperationMode.CSP, 7), (OperationMode.CST, 9)):
                if not modes >> bit & 1:
                    raise PreflightError(f"node {n} (EMA {ema}): does not support {mode.name} (0x6502 = 0x{modes:08X})")
            ratio = struct.unpack("<f", (yield _SdoRead(n, 0x2102, 0, "gear ratio")))[0]
            if not math.isclose(ratio, self.i_total, rel_tol=1e-5):
                raise PreflightError(f"node {n} (EMA {ema}): gear ratio 0x2102 = {ratio:.6f} rad/mm, profile "
                                     f"mechanics.i_total_rad_per_mm = {self.i_total:.6f}")
            inc = _u((yield _SdoRead(n, 0x608F, 1, "encoder increments")))
            revs = _u((yield _SdoRead(n, 0x608F, 2, "motor revolutions")))
            if revs == 0 or inc / revs != self.counts:
                raise PreflightError(f"node {n} (EMA {ema}): encoder resolution 0x608F = {inc}/{revs} "
                                     f"increments per revolution, profile sensors.resolver_counts_per_rev = {self.counts}")
            d.rated_torque_Nm = _u((yield _SdoRead(n, 0x6076, 0, "rated torque"))) / 1000.0
            if d.rated_torque_Nm <= 0:
                raise PreflightError(f"node {n} (EMA {ema}): rated torque 0x6076 is 0")
            d.max_torque_permille = _u((yield _SdoRead(n, 0x6072, 0, "max torque")))
            hb_ms = int(round(c.heartbeat_period_s * 1000))
            yield _SdoWrite(n, 0x1017, 0, struct.pack("<H", hb_ms), "producer heartbeat time")
            period_us = int(round(self.T * 1e6))
            yield _SdoWrite(n, 0x60C2, 1, struct.pack("<B", int(round(self.T * 1000))), "interpolation period value")
            yield _SdoWrite(n, 0x60C2, 2, struct.pack("<b", -3), "interpolation period index")
            lim = rad_to_increments(a.mechanics.stroke_limit_mm * self.i_total, self.counts)
            yield _SdoWrite(n, 0x607D, 1, struct.pack("<i", -lim), "software position limit min")
            yield _SdoWrite(n, 0x607D, 2, struct.pack("<i", lim), "software position limit max")
            yield _SdoWrite(n, 0x605A, 0, struct.pack("<h", QUICK_STOP_OPTION), "quick stop option code")
            yield _SdoWrite(n, 0x1006, 0, struct.pack("<I", period_us), "communication cycle period")
            for w in DEFAULT_LAYOUT.configuration_writes(n):
                yield _SdoWrite(n, w.index, w.subindex, w.data, w.what)
            yield from self._master_loss_reaction(n, ema, period_us)
            self._event(0.0, EventKind.PREFLIGHT, n, f"configured: identity {d.identity}, rated torque "
                                             f"{d.rated_torque_Nm} Nm, heartbeat {hb_ms} ms")
        yield _Nmt(NmtCommand.START)

    def _master_loss_reaction(self, n: int, ema: int, period_us: int) -> Generator:
        """Configure and read back the drive's own reaction to the master's death
        (:func:`~hil.canopen.od.master_loss_steps`); a missing, refused or not kept object stops the
        preflight naming it, unless the profile states another protection (then it is noted)."""
        problems = []
        for st in master_loss_steps(self.node_id, self.consumer_ms, period_us):
            r = (yield _SdoWrite(n, st.index, st.subindex, st.data, st.what, soft=True)) if st.write else None
            if not isinstance(r, SdoAbortError):
                r = yield _SdoRead(n, st.index, st.subindex, st.what, soft=True)
            name = f"0x{st.index:04X}:{st.subindex:02X} ({st.what})"
            if isinstance(r, SdoAbortError):
                problems.append(f"{name}: SDO abort 0x{int(r.code):08X} ({describe(r.code)})")
            elif bytes(r[:len(st.data)]).ljust(len(st.data), b"\0") != st.data:
                problems.append(f"{name} reads back 0x{_u(r):X}, not 0x{_u(st.data):X}")
        watchdog = self.act.canopen.external_watchdog
        self.drives[n].master_loss = {"consumer_heartbeat_ms": self.consumer_ms, "master_node_id": self.node_id,
                                      "abort_connection_option": int(AbortConnectionOption.QUICK_STOP),
                                      "verified": not problems, "problems": problems, "external_watchdog": watchdog}
        if problems and not watchdog:
            raise MasterLossReactionError(
                f"node {n} (EMA {ema}): its reaction to the master's death is not in place: " + "; ".join(problems)
                + " (it would keep its last command if the master died; canopen.external_watchdog states another"
                " protection of the rig)")

    def _advance(self, result: object, t: float, first: bool = False) -> list[Frame]:
        """Run the preflight generator until it waits for something."""
        out: list[Frame] = []
        assert self._gen is not None
        while True:
            try:
                req = next(self._gen) if first else self._gen.send(result)
                first = False
            except StopIteration:
                self._gen = None
                self._pending = None
                self.phase = Phase.CYCLIC
                for d in self.drives.values():
                    d.last_heartbeat_s = t  # the consumer starts now
                return out
            result = None
            self._pending = req
            if isinstance(req, _Nmt):
                out.append(nmt_frame(req.command))
                self._event(t, EventKind.NMT, 0, f"NMT {req.command.name} to all nodes")
                if req.command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
                    for d in self.drives.values():
                        d.booted = False
                result = True
                continue
            if isinstance(req, _WaitBoot):
                self._boot_deadline = t + self.act.canopen.boot_timeout_s
                if all(d.booted for d in self.drives.values()):
                    result = True
                    continue
                return out
            if isinstance(req, _SdoRead):
                out.append(self._sdo[req.node].start_upload(req.index, req.sub, t))
                return out
            if isinstance(req, _SdoWrite):
                out.append(self._sdo[req.node].start_download(req.index, req.sub, req.data, t))
                return out
            raise PreflightError(f"internal: unknown preflight request {req!r}")  # pragma: no cover

    # -------------------------------------------------------------- frames in

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """Feed one frame seen on the bus; returns frames to send.

        Raises the typed errors of the module on preflight failures, drive
        faults and protocol aborts. Unknown and malformed frames are counted
        and otherwise ignored. Any exception latches :attr:`fault` and sets
        :attr:`quick_stop` (fail closed) before it propagates.
        """
        try:
            return self._on_frame(frame, t)
        except BaseException as exc:
            self.latch(exc)
            raise

    def latch(self, exc: BaseException) -> None:
        """Latch ``exc`` as the fault (the first one stays) and stop by quick stop: fail closed.

        Called by the core on any exception and by the link for the faults it
        detects itself (stale data, the master's lag)."""
        if self.fault is None:
            self.fault = exc
            self.fault_cycle = self.cycle
        self.quick_stop = True

    def _fail(self, exc: EmacheckError, t: float, node: int) -> None:
        """Raise a fault of the cyclic phase, only the first one: once the master is stopping the
        drives, later faults are recorded (:attr:`later_faults`, an event) so that the safe-state
        sequence is not interrupted by them."""
        if self.fault is None:
            raise exc
        self.later_faults.append(f"{type(exc).__name__}: {exc}")
        self._event(t, EventKind.FAULT, node, str(exc))

    def _on_frame(self, frame: Frame, t: float) -> list[Frame]:
        cid = frame.arbitration_id
        try:
            if cid == SYNC_COB_ID:
                self._on_sync(t)
                return []
            base, node = split_cob_id(cid)
            if node in self.drives:
                if base == _TPDO1:
                    self._on_tpdo1(self.drives[node], decode_tpdo1(frame), t)
                    self._check_complete(t)
                    return []
                if base == _TPDO2:
                    self.drives[node].tpdo2 = decode_tpdo2(frame)
                    self._check_complete(t)
                    return []
                if base == HEARTBEAT_COB_ID_BASE:
                    return self._on_heartbeat(node, frame.data, t)
                if base == EMCY_COB_ID_BASE:
                    self._on_emcy(node, frame.data, t)
                    return []
                if base == SDO_RX_COB_ID_BASE:
                    return self._on_sdo(node, frame, t)
                if base in _OWN_TRAFFIC:
                    return []  # our own RPDOs / SDO requests seen on the bus
            if cid == NMT_COB_ID:
                return []  # NMT (ours; one on our heartbeat's COB-ID is another node's or an echo: counted)
            self.unknown_frames += 1
            return []
        except PdoError as exc:
            self.bad_frames += 1
            self._event(t, EventKind.BAD_FRAME, split_cob_id(cid)[1], str(exc))
            return []

    def _on_sdo(self, node: int, frame: Frame, t: float) -> list[Frame]:
        if self.phase is not Phase.PREFLIGHT:
            return []
        try:
            res = self._sdo[node].on_frame(frame, t)  # raises SdoAbortError with code and meaning
        except SdoAbortError as exc:  # a soft request gets the abort as its result
            if exc.abort_frame is not None or not getattr(self._pending, "soft", False):
                raise
            return self._advance(exc, t)
        if isinstance(res, Frame):
            return [res]
        if isinstance(res, SdoEvent):
            return self._advance(res.data if res.transfer.value == "upload" else True, t)
        return []

    def _on_heartbeat(self, node: int, data: bytes, t: float) -> list[Frame]:
        if len(data) != 1:
            self.bad_frames += 1
            return []
        d = self.drives[node]
        state = data[0] & 0x7F
        d.last_heartbeat_s = t
        if state == NmtState.BOOT_UP:
            d.booted = True
            self._event(t, EventKind.BOOT, node, "boot-up")
            if self.phase is Phase.PREFLIGHT and isinstance(self._pending, _WaitBoot) and \
                    all(x.booted for x in self.drives.values()):
                return self._advance(True, t)
            if self.phase is Phase.CYCLIC:
                self._fail(DriveFault(f"node {node}: unexpected boot-up during the check (drive reset)"), t, node)
            return []
        prev, d.nmt_state = d.nmt_state, state
        if self.phase is Phase.CYCLIC and state != NmtState.OPERATIONAL and prev == NmtState.OPERATIONAL:
            self._fail(DriveFault(f"node {node}: left NMT operational (heartbeat state 0x{state:02X})"), t, node)
        return []

    def _on_emcy(self, node: int, data: bytes, t: float) -> None:
        e = decode_emcy(node, data, t)
        if e is None:
            self.bad_frames += 1
            return
        self.emcy.append(e)
        self._event(t, EventKind.EMCY, node, str(e))
        if e.code != EmcyCode.NO_ERROR and self.phase is Phase.CYCLIC:
            self._fail(DriveFault(str(e)), t, node)

    # ------------------------------------------------------------------ timing

    def poll(self, t: float) -> list[Frame]:
        """Check timeouts at time ``t`` (boot-up, SDO, heartbeat); latches like :meth:`on_frame`.
        Returns the master's own heartbeat when one is due (see the module docstring)."""
        try:
            self._poll(t)
        except BaseException as exc:
            self.latch(exc)
            raise
        nxt = self._hb_next
        if nxt is None or t < nxt - 1e-9:
            return []
        nxt += self.hb_period_s  # on its own schedule; restarted from t if it fell a period behind
        self._hb_next = nxt if nxt > t else t + self.hb_period_s
        return [self._hb_frame]

    def _poll(self, t: float) -> None:
        if self.phase is Phase.PREFLIGHT:
            if isinstance(self._pending, _WaitBoot) and t > self._boot_deadline:
                missing = [n for n, d in self.drives.items() if not d.booted]
                raise PreflightError(f"node(s) {missing}: no boot-up within "
                                     f"canopen.boot_timeout_s = {self.act.canopen.boot_timeout_s} s of NMT reset")
            for c in self._sdo.values():
                c.poll(t)  # raises SdoTimeout (its abort frame is in the exception)
        elif self.phase is Phase.CYCLIC:
            # polled once per SYNC period: fire at the first poll within half a period of the
            # timeout, so the consumer reacts no later than timeout + T/2 (= the timeout on the
            # SYNC grid), not timeout + T
            limit = self.hb_timeout_s - 0.5 * self.T
            for n, d in self.drives.items():
                if not d.lost and d.last_heartbeat_s is not None and t - d.last_heartbeat_s > limit:
                    d.lost = True
                    self._event(t, EventKind.HEARTBEAT, n, "heartbeat lost")
                    self._fail(HeartbeatLost(f"node {n} (EMA {self.order.index(n) + 1}): heartbeat lost "
                                             f"(none for {t - d.last_heartbeat_s:.3f} s, "
                                             f"timeout {self.hb_timeout_s:.3f} s)"), t, n)

    # ------------------------------------------------------------------ cyclic

    def _on_sync(self, t: float) -> None:
        if self.phase is not Phase.CYCLIC:
            return
        if self.cycle > 0 and not self._complete:
            self.missing_cycles += 1
            self._event(t, EventKind.MISSING, 0, f"cycle {self.cycle}: TPDOs incomplete at the next SYNC")
        self.cycle += 1
        self._complete = False
        self._sample = None
        for d in self.drives.values():
            d.tpdo1 = d.tpdo2 = None

    def _on_tpdo1(self, d: DriveView, tp, t: float) -> None:
        """Statusword and mode of one drive, as soon as its TPDO1 arrives (also without a
        complete sample, so that the safe-state sequence sees every drive it can reach)."""
        d.tpdo1 = tp
        if self.phase is not Phase.CYCLIC:
            return
        d.last_tpdo_s = t
        d.statusword = tp.statusword
        new = decode_state(d.statusword)
        if new != d.state:
            self._event(t, EventKind.STATE, d.node_id, f"{d.state.name} -> {new.name}")
            d.state = new
        d.mode_display = tp.mode_display
        if new in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            self._fail(DriveFault(f"node {d.node_id}: drive in {new.name} (statusword 0x{d.statusword:04X})"),
                       t, d.node_id)

    def _check_complete(self, t: float) -> None:
        if self.phase is not Phase.CYCLIC or self._complete:
            return
        if any(d.tpdo1 is None or d.tpdo2 is None for d in self.drives.values()):
            return
        self._complete = True
        d1, d2 = (self.drives[n] for n in self.order)
        self._sample = Sample(
            t_s=self.cycle * self.T,
            phi1_rad=increments_to_rad(d1.tpdo1.position_inc, self.counts),
            phi2_rad=increments_to_rad(d2.tpdo1.position_inc, self.counts),
            s1_mm=lvdt_um_to_mm(d1.tpdo2.lvdt_um),
            s2_mm=lvdt_um_to_mm(d2.tpdo2.lvdt_um),
            F1_N=force_dN_to_newton(d1.tpdo2.force_dN),
            F2_N=force_dN_to_newton(d2.tpdo2.force_dN),
        )

    def take_sample(self) -> Sample | None:
        """The sample of the current cycle once both drives' TPDOs arrived (else None)."""
        s, self._sample = self._sample, None
        return s

    def state_of(self, ema: int) -> State:
        return self.drives[self.order[ema - 1]].state

    def setpoint_frames(self, sp1: Setpoint, sp2: Setpoint, sample: Sample) -> list[Frame]:
        """RPDO frames that carry the setpoints to the drives for the next SYNC.

        POSITION: CSP, target position; FORCE: CST, target torque (target
        position follows the actual one, so a switch back to CSP does not
        jump); DISABLED: down to SWITCH_ON_DISABLED, by quick stop when
        :attr:`quick_stop` is set. The controlword walks the CiA 402 state
        machine one transition per cycle towards Operation enabled.
        """
        out: list[Frame] = []
        for n, sp, phi in ((self.order[0], sp1, sample.phi1_rad), (self.order[1], sp2, sample.phi2_rad)):
            d = self.drives[n]
            pos = rad_to_increments(phi, self.counts)
            torque = 0
            if sp.mode is DriveMode.DISABLED:
                if self.quick_stop and d.state is State.OPERATION_ENABLED:
                    cmd = Command.QUICK_STOP
                elif d.state is State.QUICK_STOP_ACTIVE:
                    cmd = Command.QUICK_STOP  # keep it until the drive is through
                elif self.quick_stop and d.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
                    cmd = None  # aborting: a faulted drive is safe (power stage off); never reset it here
                else:
                    # orderly: disable operation (drive stops under control), shutdown, disable voltage;
                    # not the shortest path (disable voltage cuts the power stage at once)
                    cmd = _ORDERLY_DOWN.get(d.state) or _HOLD.get(d.state)
                mode = d.mode_sent if d.mode_sent is not None else int(OperationMode.CSP)
            else:
                mode = int(OperationMode.CSP if sp.mode is DriveMode.POSITION else OperationMode.CST)
                if sp.mode is DriveMode.POSITION:
                    pos = rad_to_increments(sp.value, self.counts)
                else:
                    torque = force_to_permille(sp.value, self.i_total, d.rated_torque_Nm)
                target = State.OPERATION_ENABLED
                cmd = next_command(d.state, target) if d.state is not State.FAULT else Command.FAULT_RESET
                if cmd is None:
                    cmd = _HOLD.get(d.state)
            if mode != d.mode_sent:
                out.append(encode_rpdo2(n, Rpdo2(mode)))
                d.mode_sent = mode
            cw = controlword(cmd) if cmd is not None else 0
            out.append(encode_rpdo1(n, Rpdo1(cw, pos, torque)))
        return out

    def nmt_frames(self, command: NmtCommand) -> list[Frame]:
        """The NMT frame of ``command`` to all nodes; any command but START also ends the master's
        heartbeat (the check's last frame is NMT pre-operational)."""
        if command != NmtCommand.START:
            self._hb_next = None
        return [nmt_frame(command)]

    def fallback_stop_frames(self, t: float) -> list[Frame]:
        """Quick stop by SDO for drives still in OPERATION_ENABLED although the RPDOs asked for it.

        Fallback of the safe-state sequence when a drive's RPDOs do not get through: an expedited
        SDO download of the controlword (0x6040 = quick stop) to every drive whose fresh statusword
        still says OPERATION_ENABLED. Fire and forget: the response is not awaited (the cyclic
        phase ignores SDO responses); the statusword in TPDO1 confirms.
        """
        out = []
        for n, d in self.drives.items():
            if self.quick_stop and d.state is State.OPERATION_ENABLED and self._confirmed(d, t):
                out.append(expedited_download_frame(n, 0x6040, 0, struct.pack("<H", controlword(Command.QUICK_STOP))))
                self._event(t, EventKind.SDO, n, "quick stop by SDO (0x6040): the drive did not follow the RPDOs")
        return out

    def unreachable(self, t: float) -> list[int]:
        """Nodes the master cannot reach: heartbeat lost and no statusword for a heartbeat timeout."""
        return [n for n, d in self.drives.items() if d.lost and not self._confirmed(d, t)]

    def _confirmed(self, d: DriveView, t: float) -> bool:
        """The drive's statusword is fresh (seen within the last heartbeat timeout)."""
        return d.last_tpdo_s is not None and t - d.last_tpdo_s <= self.hb_timeout_s

    def in_safe_state(self, t: float) -> bool:
        """Every drive the master can reach is disabled: SWITCH_ON_DISABLED (or below) or FAULT."""
        gone = self.unreachable(t)
        return all(d.state in SAFE_STATES and self._confirmed(d, t)
                   for n, d in self.drives.items() if n not in gone)

    def safe_state_report(self, t: float) -> dict:
        """Per EMA: the drive's last known state, whether it could be reached (heartbeat), whether
        that state is confirmed by a fresh statusword, and whether it is the safe state."""
        out = {}
        for k, n in enumerate(self.order, start=1):
            d = self.drives[n]
            ok = self._confirmed(d, t)
            out[f"ema{k}"] = {"node": n, "state": d.state.name, "reachable": not d.lost, "confirmed": ok,
                              "safe": ok and d.state in SAFE_STATES, "master_loss": d.master_loss}
        return out

    def all_in(self, state: State) -> bool:
        return all(d.state is state for d in self.drives.values())

    def modes_confirmed(self, sp1: Setpoint, sp2: Setpoint) -> bool:
        want = [int(OperationMode.CSP if sp.mode is DriveMode.POSITION else OperationMode.CST) for sp in (sp1, sp2)]
        return all(self.drives[n].mode_display == w for n, w in zip(self.order, want))


#: CiA 402 states in which a drive's power stage is off (the safe state of an abort).
SAFE_STATES = frozenset((State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, State.FAULT))

_ORDERLY_DOWN = {
    State.OPERATION_ENABLED: Command.DISABLE_OPERATION,
    State.SWITCHED_ON: Command.SHUTDOWN,
    State.READY_TO_SWITCH_ON: Command.DISABLE_VOLTAGE,
    State.FAULT: Command.FAULT_RESET,
}

#: The command that keeps a drive where it is.
_HOLD = {
    State.SWITCH_ON_DISABLED: Command.DISABLE_VOLTAGE,
    State.READY_TO_SWITCH_ON: Command.SHUTDOWN,
    State.SWITCHED_ON: Command.SWITCH_ON,
    State.OPERATION_ENABLED: Command.ENABLE_OPERATION,
    State.QUICK_STOP_ACTIVE: Command.QUICK_STOP,
}
