"""The CANopen master as a sans-IO core (CiA 302-style boot, CiA 402 drives, sensor nodes).

:class:`MasterCore` is fed every frame seen on the bus (including the SYNC
frames, whoever sends them) with a time value, and returns the frames to
transmit. It never touches a bus, a thread or a clock: the shells in
:mod:`hil.master.link` move frames over python-can, pace SYNC and pass time. What it
does with which node comes from the rig's :class:`~hil.canopen.plan.RigPlan`
(the actuation profile's signal map checked against every node's EDS).

Life cycle::

    PREFLIGHT  :class:`hil.master.preflight.Preflight`: NMT reset, boot-up of every node,
               identity, device type, heartbeat and PDOs of every node, each drive's
               modes, scalings, limits and reaction to the master's death, the
               master's-death drill, NMT start.
    CYCLIC     SYNC -> the TPDOs of every node -> one :class:`~hil.canopen.process.Sample`
               (:class:`hil.canopen.cycle.CycleDecoder`); setpoints -> each drive's RPDOs
               before the next SYNC (:class:`hil.canopen.cycle.SetpointEncoder`), the
               modes of operation only on a change, confirmed by 0x6061 within
               ``canopen.mode_change_timeout_s``. Heartbeat consumer of every node,
               EMCY consumer. The CiA 402 commands come from the one table of
               :mod:`hil.canopen.cia402` (:func:`~hil.canopen.cia402.master_command`).

Heartbeat producer: :meth:`MasterCore.poll` returns the master's heartbeat when due, from
:meth:`~MasterCore.start` to the NMT pre-operational at the end (silent only during the drill):
from the master's own loop (never a kernel-timed task), so that a dead or hung master stops it.

Errors are typed and name the node: :class:`~hil.master.preflight.PreflightError` (identity, device
type, ...), :class:`~hil.master.preflight.MasterLossReactionError`, :class:`~hil.canopen.sdo.SdoAbortError`
(code and meaning), :class:`~hil.canopen.sdo.SdoTimeout`, :class:`DriveFault` (EMCY, fault
state, a mode change not confirmed), :class:`HeartbeatLost`.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Generator
from dataclasses import replace

from hil.canopen.cia402 import (
    PLAIN_CONTROLWORDS,
    SAFE_STATES,
    Command,
    Controlword,
    Goal,
    OperationMode,
    State,
    controlword,
    decode_state,
    master_command,
)
from hil.canopen.cycle import CycleDecoder, SetpointEncoder, SyncSchedule, image_of
from hil.canopen.emcy import Emcy, EmcyCode, decode_emcy, describe_emcy
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
from hil.canopen.pdo import PdoError
from hil.canopen.plan import Channel, RigPlan
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.sdo import SdoAbortError, SdoClient, SdoEvent, SdoTimeout, expedited_download_frame
from hil.canopen.signalmap import ForceControl, NodeRole, ScaleSource, Signal
from hil.errors import EmacheckError
from hil.master import events as event
from hil.master.events import DriveFault, HeartbeatLost, MasterEvent
from hil.master.powerup import StopConfirmation, final_state
from hil.master.preflight import (
    Heartbeat,
    LastHeartbeat,
    MasterLossReactionError,
    Nmt,
    Now,
    Preflight,
    PreflightError,
    SdoRead,
    SdoWrite,
    Wait,
    WaitBoot,
)
from hil.master.views import RESET_WAIT_CYCLES, STILL_MM, DriveView, NodeView, Phase
from hil.profile.config import Actuation

_CSP = int(OperationMode.CSP)  #: the modes of operation as the RPDO carries them
_CST = int(OperationMode.CST)

__all__ = ["DriveFault", "DriveView", "HeartbeatLost", "MasterCore", "MasterEvent",
           "MasterLossReactionError", "NodeView", "Phase", "PreflightError", "SAFE_STATES"]


class MasterCore:
    """CANopen master of the rig's nodes, sans-IO.

    Parameters
    ----------
    actuation : Actuation
        Bus settings, timeouts, mechanics, the signal map.
    plan : RigPlan
        The signal map checked against every node's EDS (:func:`hil.profile.rig.plan_for`).
    forces : (float, float), optional
        The check's opposing force and the supervisor's force limit [N]: a drive holding forces in CST
        gets its max torque 0x6072 checked and set by the preflight (:class:`hil.master.preflight.Preflight`);
        ``safety`` (the check's): the limits the drives keep themselves (:mod:`hil.master.limits_setup`).
    """

    def __init__(self, actuation: Actuation, plan: RigPlan, forces: tuple[float, float] | None = None,
                 safety=None) -> None:
        self.act = actuation
        self.plan = plan
        c = actuation.canopen
        self.T = actuation.timing.sync_period_s
        self.i_total = actuation.mechanics.i_total_rad_per_mm
        self.node_id = c.master_node_id  #: the master's own node id (its heartbeat)
        self.hb_period_s = c.master_heartbeat_period_s  #: the master's heartbeat producer time [s]
        self.consumer_ms = round(c.master_consumer_time_s * 1000)  #: the drives' 0x1016 time [ms]
        self._hb_frame = heartbeat_frame(self.node_id, NmtState.OPERATIONAL)
        self._hb_next: float | None = None  #: when the next heartbeat is due; None: not producing
        self._hb_last: float | None = None  #: when the last heartbeat was handed out
        self.nodes: dict[int, NodeView] = {}
        for np_ in plan.nodes:
            s = np_.spec
            kw = dict(node_id=s.node_id, label=s.label, hb_timeout_s=s.heartbeat_period_s * c.heartbeat_timeout_factor)
            if s.role is NodeRole.DRIVE:
                ema = int(s.name[-1])
                view: NodeView = DriveView(**kw, ema=ema, force_control=plan.drives[ema - 1].force_control)
            else:
                view = NodeView(**kw)
            self.nodes[s.node_id] = view
        self.order = c.node_ids  # EMA 1, EMA 2
        self.drives: dict[int, DriveView] = {n: self.nodes[n] for n in self.order}
        self.phase = Phase.IDLE
        self.events: list[MasterEvent] = []
        self.emcy: list[Emcy] = []
        #: the EMCYs of the cyclic phase (the check and its stop), each with its SYNC period's time [s]
        self.emcy_in_check: list[tuple[float, Emcy]] = []
        self.cycle = 0  #: SYNC frames seen in the cyclic phase
        #: each SYNC's period (its sample's time), SYNC periods passed without one (``skipped``)
        self.sync_schedule = SyncSchedule(self.T)
        self.missing_cycles = 0  #: cycles whose TPDOs were incomplete at the next SYNC
        self.bad_frames = 0
        self.unknown_frames = 0
        self.quick_stop = False  #: shut down by quick stop (abort) rather than orderly
        self.fault: BaseException | None = None  #: the first error, latched
        self.fault_cycle: int | None = None  #: the cyclic-phase SYNC count when the fault latched
        self.later_faults: list[str] = []  #: errors after the first one (recorded, not raised again)
        self._sdo = {n: SdoClient(n, timeout_s=c.sdo_timeout_s) for n in self.nodes}
        self.preflight = Preflight(actuation, plan, self.emcy_codes_since, self._sdo_status, forces, safety)
        self._gen: Generator | None = None
        self.steps: Generator | None = None  #: run by start() instead of the preflight (hil.master.commission)
        self._pending: object | None = None
        self._boot_deadline = 0.0
        self._complete = False
        self.samples: deque[Sample] = deque()  #: complete samples not yet taken (several after a stall)
        self.decoder: CycleDecoder | None = None
        self.encoder: SetpointEncoder | None = None
        self.channels: tuple[Channel, ...] = plan.channels  #: with the scalings read from the drives
        self._own = frozenset([p.cob_id for p in plan.rx_pdos] + [SDO_TX_COB_ID_BASE + n for n in self.nodes])
        self._mode_cycles = max(1, int(c.mode_change_timeout_s / self.T + 0.5))
        self._enabled_once = False  #: both drives were in OPERATION_ENABLED: a FAULT now is a fault of the check
        self._still_rad = STILL_MM * self.i_total
        self.confirmation: StopConfirmation | None = None  #: the reads after a safe stop (:meth:`confirm_frames`)

    # ---------------------------------------------------------------- events

    def drain_events(self) -> list[MasterEvent]:
        ev, self.events = self.events, []
        return ev

    def emcy_codes_since(self, node: int, t: float) -> tuple[int, ...]:
        """EMCY error codes of ``node`` received at or after ``t`` [s]."""
        return tuple(e.code for e in self.emcy if e.node_id == node and e.t_s >= t)

    # ------------------------------------------------------------- preflight

    def start(self, t: float) -> list[Frame]:
        """Begin the preflight; returns the first frames to send."""
        if self.phase is not Phase.IDLE:
            raise PreflightError(f"master already started (phase {self.phase.value})")
        self.phase = Phase.PREFLIGHT
        self._hb_next = t  # the heartbeat starts with the first frame: the first poll sends it
        self._gen = self.preflight.run() if self.steps is None else self.steps
        return self._advance(None, t, first=True)

    @property
    def preflight_done(self) -> bool:
        return self.phase is Phase.CYCLIC

    def _finish_preflight(self, t: float) -> None:
        """The preflight is through: resolve the scalings, build the cycle codec, start the consumers."""
        chans = []
        for ch in self.plan.channels:
            setup = self.preflight.drives[ch.ema - 1]
            if ch.source is not ScaleSource.PROFILE and ch.signal in setup.scales:
                ch = replace(ch, scale=setup.scales[ch.signal])
            chans.append(ch)
        self.channels = tuple(chans)
        self.decoder = CycleDecoder(self.plan.tx_pdos, self.channels)
        self.encoder = SetpointEncoder(self.plan.rx_pdos, self.channels)
        for setup in self.preflight.drives:
            d = self.drives[self.order[setup.ema - 1]]
            d.rated_torque_Nm = setup.rated_torque_Nm
            d.master_loss, d.limits = setup.master_loss, setup.limits
            if not setup.plan.mode_by_pdo:
                d.mode_sent = d.mode_display = int(OperationMode.CSP)  # set once by SDO, confirmed
        for n, v in self.nodes.items():
            v.identity = self.preflight.identities.get(n, {})
            v.last_heartbeat_s = t  # the consumer starts now
        for node, what in self.preflight.events:
            self.events.append(event.NodeConfigured(t, node, what))
        self.phase = Phase.CYCLIC

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
                self._finish_preflight(t)
                return out
            result = None
            self._pending = req
            if isinstance(req, Nmt):
                out.append(nmt_frame(req.command, req.node))
                self.events.append(event.NmtSent(t, req.node, req.command))
                if req.command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
                    for v in self.nodes.values():
                        if req.node in (0, v.node_id):
                            v.booted = False
                result = True
            elif isinstance(req, WaitBoot):
                self._boot_deadline = t + self.act.canopen.boot_timeout_s
                if not all(v.booted for v in self.nodes.values()):
                    return out
                result = True
            elif isinstance(req, SdoRead):
                out.append(self._sdo[req.node].start_upload(req.index, req.sub, t))
                return out
            elif isinstance(req, SdoWrite):
                out.append(self._sdo[req.node].start_download(req.index, req.sub, req.data, t))
                return out
            elif isinstance(req, Wait):
                if t < req.until_s - 1e-12:
                    return out
                result = t
            elif isinstance(req, Now):
                result = t
            elif isinstance(req, LastHeartbeat):
                result = self._hb_last
            elif isinstance(req, Heartbeat):
                if req.on:
                    self._hb_next = t
                    self.events.append(event.MasterHeartbeatResumed(t, 0))
                else:
                    self._hb_next = None
                    result = self._hb_last if self._hb_last is not None else t
                    self.events.append(event.MasterFellSilent(t, 0, result))
            else:  # pragma: no cover
                raise PreflightError(f"internal: unknown preflight request {req!r}")

    def _sdo_status(self, node: int, sw: int, t: float) -> None:
        """A statusword the preflight read by SDO: the drive's state as the master knows it."""
        d = self.drives.get(node)
        if d is None:
            return
        d.statusword = sw
        d.last_tpdo_s = t
        new = decode_state(sw)
        if new is not d.state:
            self.events.append(event.DriveStateChanged(t, node, d.state, new, by_sdo=True))
            d.state = new

    # -------------------------------------------------------------- frames in

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """Feed one frame seen on the bus; returns frames to send.

        Raises the typed errors of the module on preflight failures, drive
        faults and protocol aborts. Unknown and malformed frames are counted
        and otherwise ignored. Any exception latches :attr:`fault` and sets
        :attr:`quick_stop` (fail closed) before it propagates.
        """
        # (one call per frame: the body is here, not in a method of its own; PdoError is counted, any other
        # exception latches)
        try:
            cid = frame.arbitration_id
            try:
                if cid == SYNC_COB_ID:
                    self._on_sync(t)
                    return []
                dec = self.decoder
                if dec is not None:
                    hit = dec.feed(frame)
                    if hit is not None:
                        if self.phase is Phase.CYCLIC:
                            for ema in hit:
                                self._on_status(self.drives[self.order[ema - 1]], t)
                            if not self._complete and dec.complete:
                                self._complete = True
                                self.samples.append(dec.sample(self.sync_schedule.t_s))  # (not the SYNC count)
                        return []
                base, node = split_cob_id(cid)
                if node in self.nodes:
                    if base == HEARTBEAT_COB_ID_BASE:
                        return self._on_heartbeat(node, frame.data, t)
                    if base == EMCY_COB_ID_BASE:
                        self._on_emcy(node, frame.data, t)
                        return []
                    if base == SDO_RX_COB_ID_BASE:
                        return self._on_sdo(node, frame, t)
                if cid in self._own or cid == NMT_COB_ID:
                    return []  # our own RPDOs, SDO requests, NMT seen on the bus
                self.unknown_frames += 1
                return []
            except PdoError as exc:
                self.bad_frames += 1
                self.events.append(event.BadFrame(t, split_cob_id(cid)[1], str(exc)))
                return []
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
        self.events.append(event.LaterFault(t, node, str(exc)))

    def _on_sdo(self, node: int, frame: Frame, t: float) -> list[Frame]:
        if self.confirmation is not None:
            got = self.confirmation.on_frame(node, frame, t)
            if got is not None and got.statusword is not None:
                self._sdo_status(node, got.statusword, t)
            return []
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
        v = self.nodes[node]
        state = data[0] & 0x7F
        v.last_heartbeat_s = t
        if node in self.drives:
            self.drives[node].tpdo_gap_s = 0.0  # (the gaps within the next heartbeat's silence)
        if state == NmtState.BOOT_UP:
            v.booted = True
            self.events.append(event.BootUp(t, node))
            if self.phase is Phase.PREFLIGHT and isinstance(self._pending, WaitBoot) and \
                    all(x.booted for x in self.nodes.values()):
                return self._advance(True, t)
            if self.phase is Phase.CYCLIC:
                self._fail(DriveFault(f"{v.label}: unexpected boot-up during the check (node reset)"), t, node)
            return []
        prev, v.nmt_state = v.nmt_state, state
        if self.phase is Phase.CYCLIC and state != NmtState.OPERATIONAL and prev == NmtState.OPERATIONAL:
            self._fail(DriveFault(f"{v.label}: left NMT operational (heartbeat state 0x{state:02X})"), t, node)
        return []

    def _on_emcy(self, node: int, data: bytes, t: float) -> None:
        e = decode_emcy(node, data, t)
        if e is None:
            self.bad_frames += 1
            return
        self.emcy.append(e)
        if self.phase is Phase.CYCLIC:
            self.emcy_in_check.append((self.sync_schedule.t_s, e))
        self.events.append(event.EmcyReceived(t, node, e))
        if e.code != EmcyCode.NO_ERROR and self.phase is Phase.CYCLIC:
            self._fail(DriveFault(str(e), emcy=e), t, node)

    # ------------------------------------------------------------------ timing

    def poll(self, t: float) -> list[Frame]:
        """Check timeouts at time ``t`` (boot-up, SDO, heartbeat); latches like :meth:`on_frame`.
        Advances a preflight that waits for time to pass; returns the frames that makes, and the
        master's own heartbeat when one is due (see the module docstring)."""
        try:
            out = self._poll(t)
        except BaseException as exc:
            self.latch(exc)
            raise
        nxt = self._hb_next
        if nxt is None or t < nxt - 1e-9:
            return out
        nxt += self.hb_period_s  # on its own schedule; restarted from t if it fell a period behind
        self._hb_next = nxt if nxt > t else t + self.hb_period_s
        self._hb_last = t
        out.append(self._hb_frame)
        return out

    def _poll(self, t: float) -> list[Frame]:
        if self.confirmation is not None:
            return self.confirmation.poll(t)
        if self.phase is Phase.PREFLIGHT:
            if isinstance(self._pending, WaitBoot) and t > self._boot_deadline:
                missing = [v.label for v in self.nodes.values() if not v.booted]
                raise PreflightError(f"{', '.join(missing)}: no boot-up within "
                                     f"canopen.boot_timeout_s = {self.act.canopen.boot_timeout_s} s of NMT reset",
                                     "canopen.boot_timeout_s")
            for n, c in self._sdo.items():
                try:
                    c.poll(t)  # raises SdoTimeout (its abort frame is in the exception)
                except SdoTimeout as exc:
                    pending = self._pending
                    if getattr(pending, "soft", False) and getattr(pending, "node", None) == n:
                        return [exc.abort_frame, *self._advance(exc, t)]  # a soft request gets it as its result
                    raise
            if isinstance(self._pending, Wait) and t >= self._pending.until_s - 1e-12:
                return self._advance(t, t)
        elif self.phase is Phase.CYCLIC:
            # polled once per SYNC period: fire at the first poll within half a period of the
            # timeout, so the consumer reacts no later than timeout + T/2 (= the timeout on the
            # SYNC grid), not timeout + T
            for n, v in self.nodes.items():
                if not v.lost and v.last_heartbeat_s is not None and \
                        t - v.last_heartbeat_s > v.hb_timeout_s - 0.5 * self.T:
                    v.lost = True
                    self.events.append(event.HeartbeatMissed(t, n))
                    spec = next(x.spec for x in self.plan.nodes if x.spec.node_id == n)
                    silent = t - v.last_heartbeat_s
                    last = getattr(v, "last_tpdo_s", None)  # (a drive's statuswords: the node silent altogether)
                    quiet = max(t - last, getattr(v, "tpdo_gap_s", 0.0)) if last is not None else math.nan
                    self._fail(HeartbeatLost(f"{v.label}: heartbeat lost (none for {silent:.3f} s, "
                                             f"timeout {v.hb_timeout_s:.3f} s)", key=f"{spec.key}.heartbeat_period_s",
                                             at_s=t, silent_s=silent,
                                             overdue_s=v.hb_timeout_s - spec.heartbeat_period_s,
                                             frames_silent_s=quiet), t, n)
        return []

    # ------------------------------------------------------------------ cyclic

    def _on_sync(self, t: float) -> None:
        if self.phase is not Phase.CYCLIC:
            return
        if self.cycle > 0 and not self._complete:
            self.missing_cycles += 1
            self.events.append(event.CycleIncomplete(t, 0, self.cycle))
        self.cycle += 1
        skipped = self.sync_schedule.on_sync(t)
        if skipped:
            self.events.append(event.SyncPeriodsSkipped(t, 0, self.sync_schedule.slot - skipped - 1,
                                                        self.sync_schedule.slot))
        self._complete = False  # (a sample not yet taken stays: the master takes a stall's backlog in order)
        self.decoder.reset()
        for d in self.drives.values():
            p = d.mode_pending
            if p is not None and self.cycle > p[1] and self.fault is None:
                d.mode_pending = None
                self._fail(DriveFault(f"{d.label}: modes of operation {p[0]} not confirmed by 0x6061 within "
                                      f"canopen.mode_change_timeout_s = {self.act.canopen.mode_change_timeout_s} s "
                                      f"(0x6061 = {d.mode_display})"), t, d.node_id)

    def _on_status(self, d: DriveView, t: float) -> None:
        """Statusword and mode of one drive, as soon as its PDO arrives (also without a complete
        sample, so that the safe-state sequence sees every drive it can reach)."""
        k = d.ema - 1
        dec = self.decoder
        if d.last_tpdo_s is not None and t - d.last_tpdo_s > d.tpdo_gap_s:
            d.tpdo_gap_s = t - d.last_tpdo_s
        d.last_tpdo_s = t
        d.statusword = sw = dec.statusword[k]
        md = dec.mode_display[k]
        if md is not None:
            d.mode_display = md
            p = d.mode_pending
            if p is not None and md == p[0]:
                d.mode_pending = None
        new = decode_state(sw)
        if new is not d.state:
            self.events.append(event.DriveStateChanged(t, d.node_id, d.state, new))
            d.state = new
            if new is not State.FAULT:
                d.fault_resets = 0
        if new in (State.FAULT, State.FAULT_REACTION_ACTIVE) and self._enabled_once:
            # (found in FAULT at power-up, a drive gets bounded fault resets instead)
            self._fail(DriveFault(f"{d.label}: drive in {new.name} (statusword 0x{sw:04X})"), t, d.node_id)

    def take_sample(self) -> Sample | None:
        """The oldest complete sample not yet taken (each SYNC's once every TPDO with an input arrived), else None."""
        return self.samples.popleft() if self.samples else None

    def state_of(self, ema: int) -> State:
        return self.drives[self.order[ema - 1]].state

    def _stopped(self, d: DriveView, phi: float) -> bool:
        """The drive stands still (QUICK STOP ACTIVE): its angle moved less than :data:`STILL_MM` of
        stroke over the last :data:`STILL_CYCLES` cycles."""
        d.still.append(phi)
        return len(d.still) == d.still.maxlen and max(d.still) - min(d.still) < self._still_rad

    def _command(self, d: DriveView, goal: Goal, phi: float) -> int:
        """The controlword for ``d`` on its way to ``goal`` (:func:`~hil.canopen.cia402.master_command`),
        with bounded fault resets (a rising edge of bit 7 every :data:`RESET_WAIT_CYCLES` cycles)."""
        state = d.state
        if state is not State.QUICK_STOP_ACTIVE:
            d.still.clear()
            cw = PLAIN_CONTROLWORDS.get((id(goal), id(state)))  # (the table's every cycle, without two calls)
            if cw is not None:
                return cw
        cmd = master_command(goal, state, stopped=self._stopped(d, phi) if state is State.QUICK_STOP_ACTIVE
                             else False)
        if cmd is Command.FAULT_RESET:
            if d.reset_wait > 0:
                d.reset_wait -= 1
                return d.last_cw
            if d.last_cw & Controlword.FAULT_RESET:
                return 0  # bit 7 low first: the reset acts on its rising edge
            if d.fault_resets >= self.act.canopen.fault_reset_attempts:
                if self.fault is None:
                    codes = self.emcy_codes_since(d.node_id, 0.0)
                    code = f" (last EMCY 0x{codes[-1]:04X})" if codes else ""
                    self._fail(DriveFault(f"{d.label}: still in FAULT after {d.fault_resets} fault resets "
                                          f"(canopen.fault_reset_attempts){code}"), 0.0, d.node_id)
                return 0
            d.fault_resets += 1
            d.reset_wait = RESET_WAIT_CYCLES
        return 0 if cmd is None else controlword(cmd)

    def setpoint_frames(self, sp1: Setpoint, sp2: Setpoint, sample: Sample) -> list[Frame]:
        """RPDO frames that carry the setpoints to the drives for the next SYNC.

        POSITION: CSP, target position; FORCE: CST, target torque (target
        position follows the actual one, so a switch back to CSP does not
        jump); DISABLED: down to SWITCH_ON_DISABLED, by quick stop when
        :attr:`quick_stop` is set. The controlword comes from the CiA 402
        master table (one transition per cycle).
        """
        out: list[Frame] = []
        enc = self.encoder
        order, drives = self.order, self.drives
        for k, n, sp, phi in ((0, order[0], sp1, sample.phi1_rad), (1, order[1], sp2, sample.phi2_rad)):
            d = drives[n]
            target, torque = phi, 0.0
            sp_mode = sp.mode
            if sp_mode is DriveMode.DISABLED:
                goal = Goal.QUICK_STOP if self.quick_stop else Goal.ORDERLY_DOWN
                mode = d.mode_sent if d.mode_sent is not None else _CSP
            else:
                goal = Goal.ENABLED
                if sp_mode is DriveMode.POSITION:
                    mode, target = _CSP, sp.value
                elif d.force_control is ForceControl.CST:
                    mode, torque = _CST, sp.value
                else:
                    raise DriveFault(f"{d.label}: a force setpoint for a drive that holds forces in CSP "
                                     f"(the sequence must close the force loop itself)")
            if mode != d.mode_sent:
                f = enc.mode_frame(k + 1, mode)
                if f is not None:
                    out.append(f)
                    d.mode_pending = (mode, self.cycle + self._mode_cycles)
                d.mode_sent = mode
            cw = self._command(d, goal, phi)
            d.last_cw = cw
            out += enc.frames(k + 1, cw, target, torque)
        if not self._enabled_once and all(d.state is State.OPERATION_ENABLED for d in self.drives.values()):
            self._enabled_once = True
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
        SDO download of the controlword (quick stop) to every drive whose fresh statusword
        still says OPERATION_ENABLED. Fire and forget: the response is not awaited (the cyclic
        phase ignores SDO responses); the statusword in its TPDO confirms.
        """
        out = []
        for n, d in self.drives.items():
            if self.quick_stop and d.state is State.OPERATION_ENABLED and self._confirmed(d, t):
                out.append(self._controlword_by_sdo(n, d.ema, Command.QUICK_STOP))
                self.events.append(event.QuickStopBySdo(t, n))
        return out

    def abort_preflight_frames(self, t: float) -> list[Frame]:
        """Disable voltage by SDO (controlword, expedited, not awaited) to every drive the drill may have
        powered up, when the preflight ends in an error the drill could not handle itself (an SDO timeout):
        fail closed before the link gives up."""
        out = []
        for setup in self.preflight.powered:
            n = setup.plan.node.spec.node_id
            out.append(self._controlword_by_sdo(n, setup.ema, Command.DISABLE_VOLTAGE))
            self.events.append(event.DisableBySdo(t, n))
        return out

    def _controlword_by_sdo(self, node: int, ema: int, command: Command) -> Frame:
        """An expedited SDO download of ``command``'s controlword to the drive's mapped controlword
        object (fire and forget: the statusword confirms)."""
        cw = self.plan.map.entry(ema, Signal.CONTROLWORD)
        return expedited_download_frame(node, cw.index, cw.subindex, struct.pack("<H", controlword(command)))

    def unreachable(self, t: float) -> list[int]:
        """Drives the master cannot reach: heartbeat lost and no statusword for a heartbeat timeout."""
        return [n for n, d in self.drives.items() if d.lost and not self._confirmed(d, t)]

    def _confirmed(self, d: DriveView, t: float) -> bool:
        """The drive's statusword is fresh (seen within the last heartbeat timeout)."""
        return d.last_tpdo_s is not None and t - d.last_tpdo_s <= d.hb_timeout_s

    def in_safe_state(self, t: float) -> bool:
        """Every drive the master can reach is in SWITCH_ON_DISABLED, confirmed by a fresh statusword."""
        gone = self.unreachable(t)
        return all(d.state in SAFE_STATES and self._confirmed(d, t)
                   for n, d in self.drives.items() if n not in gone)

    def confirm_frames(self, t: float) -> list[Frame]:
        """After the last command of a safe stop: each drive's statusword read again by SDO
        (:class:`hil.master.powerup.StopConfirmation`, bounded by ``canopen.sdo_timeout_s``); from now on the
        master takes only these answers. :attr:`confirmation` ``.done`` once each ended."""
        objs = {n: (e.index, e.subindex) for n, d in self.drives.items()
                for e in (self.plan.map.entry(d.ema, Signal.STATUSWORD),)}
        self.confirmation = StopConfirmation(objs, self.act.canopen.sdo_timeout_s)
        return self.confirmation.start(t)

    def safe_state_report(self, t: float) -> dict:
        """Per EMA: the drive's last state seen and when, whether it could be reached (heartbeat), whether
        that state is confirmed (read after the safe stop's last command, :meth:`confirm_frames`; without
        that read: a fresh statusword), in words (:func:`hil.master.powerup.final_state`), whether it is the safe
        state, and how it is protected against the master's death."""
        out = {}
        reads = self.confirmation.results if self.confirmation is not None else None
        for k, n in enumerate(self.order, start=1):
            d = self.drives[n]
            seen = None if d.last_tpdo_s is None else d.statusword
            fin = final_state(seen, d.last_tpdo_s, None if reads is None else reads.get(n), self._confirmed(d, t))
            ml = d.master_loss or self.preflight.drives[k - 1].master_loss  # (as far as a stopped preflight got)
            out[f"ema{k}"] = {"node": n, **fin, "reachable": not d.lost,
                              "master_loss": ml.as_json() if ml is not None else {},
                              "drive_limits": [lim.as_json() for lim in d.limits]}
        return out

    def emcy_report(self) -> dict:
        """Per EMA: the EMCYs its drive sent in the cyclic phase (the check and its stop), in order, each with
        the time of the SYNC period it arrived in [s, the samples' time], its code, error register and the
        code in words (:func:`hil.canopen.emcy.describe_emcy`)."""
        return {f"ema{k}": [{"t_s": t, "code": e.code, "error_register": e.error_register,
                             "text": describe_emcy(e.code)} for t, e in self.emcy_in_check if e.node_id == n]
                for k, n in enumerate(self.order, start=1)}

    def sensor_nodes_report(self) -> dict:
        """Per sensor node: node id and whether its heartbeat was heard to the end."""
        return {v.label: {"node": v.node_id, "reachable": not v.lost} for v in self.nodes.values()
                if not isinstance(v, DriveView)}

    def all_in(self, state: State) -> bool:
        return all(d.state is state for d in self.drives.values())

    def process_image(self) -> dict:
        """The PDOs and where each signal was in them, scaled as the drives said (meta.json, for the
        CAN-log reader: :func:`hil.canopen.cycle.image_of`)."""
        return image_of(self.plan.tx_pdos + self.plan.rx_pdos, self.channels)
