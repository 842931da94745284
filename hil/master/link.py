"""The CANopen link: the master core over a transport, as the check loop's :class:`hil.check.runner.Link`.

:class:`CanopenLink` implements the :class:`hil.check.runner.Link` protocol, so the
check loop and the sequence core run unchanged whether the drives are
simulated or real; the transports of :mod:`hil.transport` move the frames.
It feeds every frame to the sans-IO :class:`hil.master.core.MasterCore`, logs it,
runs the SYNC cycle, watches sensor freshness and the master's lag, and
brings the drives to the safe state on close.

The master's heartbeat (what the drives' consumers watch to stop by
themselves if the master dies) is whatever :meth:`MasterCore.poll
<hil.master.core.MasterCore.poll>` returns: this loop polls after every frame it
takes, in the preflight, the cycles and the safe-state cycles of
:meth:`CanopenLink.close`, and its NMT pre-operational ends it. SYNC is
kernel-timed where the transport can (it would outlive a hung loop), else
sent by this loop on its monotonic schedule; the heartbeat never is.

On a real bus the link measures its own timing per SYNC cycle
(:attr:`CanopenLink.timing`, a :class:`hil.record.cycletiming.CycleTiming`): SYNC
arrival to the RPDOs sent, sample complete to RPDOs sent (the loop's work),
SYNC to SYNC; ``emacheck run`` writes it into meta.json ``timing``.

A stall of the master (its computer did not run it; frames waited) within the
freshness limit in force (:attr:`CanopenLink.stale`, docs/safety.md) is
tolerated: the frames that waited reach the master cycle by cycle
(:attr:`CanopenLink.held`), each sample is returned in order at its own SYNC's
time (:attr:`CanopenLink.behind` while newer ones wait; their setpoints are not
sent), and :attr:`CanopenLink.stall_watch` records it. A longer one stops the
check with :class:`StaleData` naming the limit and its profile key.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

import can

from hil.canopen.cia402 import State
from hil.canopen.drivelimits import KEPT_BY_DRIVE, LimitKind
from hil.canopen.frame import SYNC_COB_ID, Frame, sync_frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.sdo import SdoAbortError, SdoTimeout
from hil.canopen.signalmap import ForceControl
from hil.check.staleness import StaleLimit, stale_limit
from hil.errors import KNOWN_ERRORS, EmacheckError
from hil.master.core import MasterCore, PreflightError
from hil.master.powerup import CONFIRM_READS
from hil.master.stalls import StallWatch
from hil.profile.config import HARD_MAX_LAG_S
from hil.record.canlog import CanLogWriter
from hil.record.cycletiming import CycleTiming
from hil.transport import InProcessTransport

DISABLED = Setpoint(DriveMode.DISABLED, 0.0)


#: Safe-state cycles after which a drive still in OPERATION_ENABLED gets the quick stop by SDO
#: (and again every as many cycles): its RPDOs are not getting through.
SDO_FALLBACK_CYCLES = 5


class LinkError(EmacheckError, RuntimeError):
    """The cyclic exchange with the drives broke down (no samples)."""


class StaleData(LinkError):
    """Sensor freshness: no complete sample for more SYNC cycles, or the master took a SYNC later, than the
    freshness limit in force (``safety.max_stale_ms`` where both drives keep their limits, else
    ``safety.max_stale_cycles`` and ``safety.max_lag_s``)."""


class CanopenLink:
    """The drives over CANopen, as a :class:`hil.check.runner.Link`.

    Parameters
    ----------
    master : MasterCore
    transport : InProcessTransport or BusTransport
    log : CanLogWriter, optional
        Every frame sent and received is logged as it happens.
    on_event : callable, optional
        Receives the master's events (boot-up, states, EMCY, ...).
    max_missing_cycles : int
        Sensor freshness: SYNC cycles in a row without a complete sample before
        :class:`StaleData` is raised (the check's ``safety.max_stale_cycles``).
    max_lag_s : float, optional
        The longest a SYNC may wait in the master's socket before the master takes
        it [s] (``safety.max_lag_s``; in the dry-run, an injected stall); beyond it
        the master has fallen behind the bus (or the computer stalled) and stops
        with :class:`StaleData`. Default: ``max_missing_cycles`` SYNC periods.
    safety : Safety, optional
        The check's safety profile: once the preflight has written and read back the limits the drives
        keep, the freshness limit in force (:func:`hil.check.staleness.stale_limit`, :attr:`stale`); where it is
        the derived stall budget (both drives keep their limits), it replaces ``max_lag_s``: a stall of
        the master up to ``safety.max_stale_ms`` is tolerated, its frames taken in order, each sample at
        its own SYNC's time; and it replaces ``max_missing_cycles`` (SYNC cycles without a complete sample:
        while none comes the master sends no new setpoint, the drives hold, as in a stall).
    """

    def __init__(self, master: MasterCore, transport, log: CanLogWriter | None = None,
                 on_event: Callable | None = None, max_missing_cycles: int = 5,
                 max_lag_s: float | None = None, safety=None) -> None:
        self.m = master
        self.tr = transport
        self.log = log
        self.on_event = on_event
        self.max_missing = max_missing_cycles
        #: the longest a SYNC may have waited in the socket before the master took it [s]
        lag = max_lag_s if max_lag_s is not None else max_missing_cycles * getattr(transport, "T", 0.0)
        self.max_lag_s = min(lag, HARD_MAX_LAG_S)  # applied again here, whatever the caller passed
        self.safety = safety
        #: the freshness limit in force once the preflight said what the drives keep (None: not known)
        self.stale: StaleLimit | None = None
        #: frames received but not yet fed: a stall's backlog from the first SYNC after a sample not yet taken
        self.held: list[tuple[Frame, float, can.Message | None]] = []
        #: the setpoints the drives followed when the last sample returned was taken (None: the first)
        self.in_force: tuple[Setpoint, Setpoint] | None = None
        self.stall_watch = StallWatch(transport.T)  #: the master's stalls, as it saw them
        self._last: Sample | None = None
        self._closed = False
        self.sync_times: list[float] = []
        self.final_states: dict | None = None  #: per EMA, after :meth:`close`
        self._safe_cycles = 0
        self.close_errors: list[str] = []  #: errors met while stopping the drives (recorded, not raised)
        #: the loop's timing per SYNC cycle on a real bus (None in process, where time is simulated)
        self.clock = getattr(transport, "clock", None)
        self.timing = CycleTiming(transport.T) if self.clock is not None else None
        self._t_sample = 0.0  #: when the current sample was complete [s, transport time]
        self._cpu_sample = 0.0  #: the thread's CPU time then [s]

    # -------------------------------------------------------------- plumbing

    def _send(self, frames: list[Frame]) -> None:
        if not frames:
            return
        t = self.tr.now()
        self.tr.send(frames, t)
        log = self.log
        if log is not None:
            for f in frames:
                log.write(f, t, False)

    def _feed(self, got: list[tuple[Frame, float, can.Message | None]], in_order: bool = False) -> None:
        """Feed frames received to the master (and the log). ``in_order``: a SYNC that finds a complete
        sample not yet taken waits, with the frames after it (:attr:`held`), until that sample is taken:
        the frames of a stall's backlog reach the master cycle by cycle, each sample judged before the
        frames of the next cycle are (a drive's fault in a later cycle is seen after an earlier violation)."""
        log = self.log
        on_frame = self.m.on_frame
        now = self.tr.now
        timing = self.timing
        logged = seen = 0  # got[:logged] is in the log; got[:seen] reached the master
        try:
            for f, t, _msg in got:
                sync = f.arbitration_id == SYNC_COB_ID
                if sync and in_order and self.m.samples:
                    self.held = got[seen:]
                    break
                if sync and timing is not None:
                    timing.sync(t)
                seen += 1
                # a SYNC at its own time (the slot of the loop-timed SYNC, else when it arrived), so that
                # the sample answering it carries that time however late the master takes it
                out = on_frame(f, self._sync_time(t) if sync else now())
                if sync:
                    self._observe_sync(getattr(self.tr, "lag_s", 0.0))
                if out:
                    if log is not None:  # what came in before the answer to it, as on the bus
                        log.write_received(got[logged:seen])
                        logged = seen
                    self._send(out)
        finally:
            # every frame the master saw is logged, also when it raised on one
            if log is not None and logged < seen:
                log.write_received(got[logged:seen])
        events = self.m.drain_events()  # drained always: the master's list must not grow in the loop
        if self.on_event is not None:
            for ev in events:
                self.on_event(ev)

    def _sync_time(self, arrived: float) -> float:
        """The time of a SYNC received [s]: its slot on the schedule where the loop sends SYNC itself
        (:meth:`hil.transport.BusTransport.send_sync`), else when it arrived (the kernel's stamp)."""
        slot = getattr(self.tr, "sync_slot_s", None)
        return slot if slot is not None and self.tr.sync_due() is not None else arrived

    def _sync(self) -> None:
        due = self.tr.sync_due() if self.timing is not None else None
        if due is not None:
            # the loop's own SYNC: frames until it is due, then SYNC; the master takes it from the bus
            while self.tr.now() < due:
                self._take(self.tr.receive(due))
            # (a SYNC sent late: the loop stalled; at the period it was due in)
            self._observe_sync(self.tr.send_sync() - due, ahead=1)
            return
        t = self.tr.next_sync()
        if t is not None:
            self.sync_times.append(t)
            # the SYNC we sent is part of the traffic the master follows
            if self.log is not None:
                self.log.write(sync_frame(), t, rx=False)
            self.m.on_frame(sync_frame(), t)
            self._observe_sync(0.0)

    def _observe_sync(self, late_s: float, ahead: int = 0) -> None:
        """The stall watch told how late the master took (or sent) a SYNC [s], at its period's time on the
        check's time axis (the master's SYNC schedule; ``ahead`` periods after the last one it saw)."""
        watch = self.stall_watch
        if late_s <= watch.T:  # (on time, every SYNC: its time not needed)
            watch.on_time()
            return
        sched = getattr(self.m, "sync_schedule", None)
        if sched is not None:
            watch.observe(sched.t_s + ahead * sched.T, late_s)

    # --------------------------------------------------------------- phases

    def preflight(self) -> None:
        """Boot, identify and configure both drives (SDO), then NMT start."""
        t0 = self.tr.now()
        try:
            self._send(self.m.start(t0))
            limit = t0 + self.m.act.canopen.boot_timeout_s + 30.0
            while not self.m.preflight_done:
                now = self.tr.now()
                if now > limit:
                    raise PreflightError("preflight did not complete within "
                                         f"{limit - t0:.0f} s", "canopen.boot_timeout_s")
                self._feed(self.tr.receive(now + 0.01))
                self._send(self.m.poll(self.tr.now()))
        except (SdoAbortError, SdoTimeout) as exc:
            if getattr(exc, "abort_frame", None) is not None:
                self._send([exc.abort_frame])
            raise

    def _next_sample(self) -> Sample:
        """Run one SYNC cycle and return its sample (SYNC, TPDOs of both drives); after a stall, the next
        sample of its backlog (taken already, judged in order)."""
        waiting = self.m.take_sample()
        if waiting is None and self.held:  # the backlog's next cycle (its lag was judged when it came)
            got, self.held = self.held, []
            self._feed(got, in_order=True)
            self._send(self.m.poll(self.tr.now()))
            waiting = self.m.take_sample()
        if waiting is not None:
            self._last = waiting
            return waiting
        missing = 0
        while True:
            sample = self._cycle(stop_at_sample=True)
            if sample is not None:
                self._last = sample
                return sample
            missing += 1
            if missing > self.max_missing:
                err = StaleData(f"sensor data stale: no complete sample for {missing} SYNC cycles "
                                f"({self._missing_limit_text()}); missing: "
                                + ", ".join(f"COB-ID 0x{c:03X}" for c in self.m.decoder.missing())
                                + f"; drive states {[d.state.name for d in self.m.drives.values()]}")
                self.m.latch(err)
                raise err

    @property
    def kept_limits(self) -> tuple[frozenset[LimitKind], ...] | None:
        """Per EMA the limits its drive keeps itself (written and read back by the preflight); None
        before the preflight is done."""
        if not self.m.preflight_done:
            return None
        return tuple(frozenset(lim.kind for lim in self.m.drives[n].limits if lim.kept_by == KEPT_BY_DRIVE)
                     for n in self.m.order)

    def _apply_stale_limit(self) -> None:
        """The freshness limit in force from what the drives were confirmed to keep: the derived stall
        budget replaces the lag limit and the count of SYNC cycles without a complete sample; a drive that
        keeps none keeps today's short limits."""
        if self.safety is None:
            return
        self.stale = stale_limit(self.m.act, self.safety, self.kept_limits)
        if self.stale.derived:
            self.max_lag_s = min(self.stale.ms / 1000.0, HARD_MAX_LAG_S)
            self.max_missing = self.stale.cycles

    @property
    def behind(self) -> bool:
        """A stall's backlog: a sample newer than the last one returned is here already (complete, or the
        frames of a later SYNC cycle wait to be fed)."""
        return bool(self.m.samples) or bool(self.held)

    def stall_record(self) -> dict:
        """The master's stalls (:class:`hil.master.stalls.StallWatch`) and the limit they were held to (meta.json
        ``stalls``)."""
        st = self.stale
        key = f"safety.{st.name}" if st is not None and st.derived else "safety.max_lag_s"
        return {**self.stall_watch.as_json(), "limit_ms": round(self.max_lag_s * 1000.0, 6), "limit": key}

    def first_sample(self) -> Sample:
        """Preflight, start SYNC, enable both drives in CSP holding their position."""
        self.preflight()
        self._apply_stale_limit()
        self.tr.start_sync()
        smp = self._next_sample()
        deadline = self.tr.now() + self.m.act.canopen.enable_timeout_s
        while not self.m.all_in(State.OPERATION_ENABLED):
            if self.tr.now() > deadline:
                states = {n: d.state.name if d.last_tpdo_s is not None else "statusword never read"
                          for n, d in self.m.drives.items()}
                raise PreflightError(f"drives not in OPERATION_ENABLED within canopen.enable_timeout_s = "
                                     f"{self.m.act.canopen.enable_timeout_s} s: {states}", "canopen.enable_timeout_s")
            hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
            self._send(self.m.setpoint_frames(*hold, smp))
            smp = self._next_sample()
        return smp

    @property
    def force_by_position(self) -> tuple[bool, bool]:
        """Per EMA: its drive holds forces by the master's loop in CSP (no CST in the plan)."""
        return tuple(d.force_control is ForceControl.CSP for d in self.m.plan.drives)

    @property
    def frames_per_cycle(self) -> float:
        """CAN frames per SYNC cycle the check logs: SYNC, every PDO and the heartbeats of its bus-load plan."""
        return float(sum(i.frames_per_cycle for i in self.m.plan.load.items))

    def preflight_record(self) -> dict:
        """What meta.json records of the preflight, as far as it got (also when it stopped): the process image
        (PDOs, scalings as the drives reported them) once the drives are up, how each drive is protected against
        the master's death (configured, drilled: every drive whose reaction was configured or refused, the
        drill's refusal included), each EMA's identity as read (None: not read)."""
        m = self.m
        pf = m.preflight
        out = {"master_loss": {f"ema{d.ema}": d.master_loss.as_json() for d in pf.drives
                               if d.master_loss is not None},
               "identity": {f"ema{k}": ({"node": n, **pf.identities[n]} if pf.identities.get(n) else None)
                            for k, n in enumerate(m.order, start=1)}}
        if m.preflight_done:
            out = {"process_image": m.process_image(), **out}
        return out

    def exchange(self, sp1: Setpoint, sp2: Setpoint) -> Sample:
        stop = sp1.mode is DriveMode.DISABLED and sp2.mode is DriveMode.DISABLED
        if self.m.fault is not None and stop:
            # stopping after a fault: one safe-state cycle, no complete sample required
            self._safe_cycle()
            return self._last
        if self.behind:
            # a stall's backlog: the next sample is here already; the setpoints of a past SYNC are not
            # sent (the drives take the latest at the next SYNC), a stop is, at once
            if stop:
                self._send(self.m.setpoint_frames(sp1, sp2, self._last))
                self.in_force = (sp1, sp2)
            return self._next_sample()
        self.in_force = (sp1, sp2)
        self._send(self.m.setpoint_frames(sp1, sp2, self._last))
        if self.timing is not None:
            t = self.clock()
            self.timing.work(self._t_sample, t, time.thread_time() - self._cpu_sample)
            self.timing.answered(t)
        return self._next_sample()

    @property
    def last_sample(self) -> Sample | None:
        """The last complete sample the master took, the safe stop's included (None: none yet)."""
        return self._last

    def emcy_report(self) -> dict:
        """Per EMA, the EMCYs its drive sent in the check and its stop
        (:meth:`MasterCore.emcy_report <hil.master.core.MasterCore.emcy_report>`)."""
        return self.m.emcy_report()

    def _stopped_all(self, t: float) -> bool:
        """Every drive confirmed in the safe state, none unreachable (the end of the safe-state sequence)."""
        return self.m.in_safe_state(t) and not self.m.unreachable(t)

    def record_overdue_sync(self) -> None:
        """The loop stopped while its own SYNC was overdue by more than a period: it was held, and what waited
        for it (an EMCY, a heartbeat judged lost once it ran again) stopped it before the late SYNC was sent,
        where the stall is otherwise recorded. Recorded now, as long as it lasted so far (call before the stalls
        are read: :attr:`stall_watch`); a no-op where the SYNC is not the loop's own, or not overdue."""
        due = self.tr.sync_due() if self.timing is not None else None
        if due is not None:
            self._observe_sync(self.clock() - due, ahead=1)

    def abort(self) -> None:
        """The check aborted: drives go down by quick stop."""
        self.m.quick_stop = True

    def _safe_cycle(self) -> None:
        """One SYNC cycle of the safe-state sequence: DISABLED setpoints (quick stop when aborting),
        SYNC, whatever the drives answer; no complete sample needed (a drive may be gone)."""
        if self._last is not None:
            self._send(self.m.setpoint_frames(DISABLED, DISABLED, self._last))
        self._safe_cycles += 1
        if self._safe_cycles % SDO_FALLBACK_CYCLES == 0:  # a drive that ignores its RPDOs: by SDO
            self._send(self.m.fallback_stop_frames(self.tr.now()))
        sample = self._cycle(stop_at_sample=False)
        if sample is not None:
            self._last = sample

    def _cycle(self, stop_at_sample: bool) -> Sample | None:
        """SYNC, then the frames of this cycle; returns the cycle's sample if it completed.

        In-process: deliver what is in flight (time stands still until the next SYNC); on a
        bus: wait for frames until the cycle would end (or, with ``stop_at_sample``, until the
        sample is complete).
        """
        if self.held:  # (a backlog left when the check stopped: the master sees every frame, in order)
            got, self.held = self.held, []
            self._feed(got)
        self._sync()
        inproc = isinstance(self.tr, InProcessTransport)
        due = self.tr.sync_due() if self.timing is not None else None
        # a loop-timed SYNC is never held back waiting for a late sample: the cycle ends when it is due
        cycle_end = due if due is not None else self.tr.now() + self.tr.T
        found = None
        while True:
            got = self.tr.receive(self.tr.now() if inproc else cycle_end)
            self._take(got, in_order=stop_at_sample)
            sample = self.m.take_sample()
            while not stop_at_sample and self.m.samples:  # (the safe-state sequence keeps the latest)
                sample = self.m.take_sample()
            if sample is not None:
                found = sample
                if self.clock is not None:
                    self._t_sample = self.clock()
                    self._cpu_sample = time.thread_time()
                if stop_at_sample:
                    return found
            if not got or (not inproc and self.tr.now() >= cycle_end):
                return found

    def _take(self, got: list, in_order: bool = False) -> None:
        """Frames received: the master falling behind the bus stops the check; else feed them, then poll."""
        if got:
            lag = getattr(self.tr, "lag_s", 0.0)
            # (once stopping after a fault, the safe-state sequence goes on whatever the lag)
            if lag > self.max_lag_s and self.m.fault is None:
                # the master has fallen behind the bus: whatever it computes now is stale
                err = StaleData(f"sensor data stale: the master is {lag * 1e3:.3g} ms behind the bus "
                                f"(frames waited for it; {self._lag_limit_text()})")
                self._observe_sync(lag, ahead=1)  # the stall that stops the check is recorded too
                self.m.latch(err)
                with contextlib.suppress(*KNOWN_ERRORS):  # (the master latched: later faults are recorded)
                    self._feed(got)  # the frames that waited reach the master and the log
                raise err
            self._feed(got, in_order)
        self._send(self.m.poll(self.tr.now()))

    def _missing_limit_text(self) -> str:
        st = self.stale
        if st is not None and st.derived:
            return f"safety.max_stale_ms: {self.max_missing} SYNC cycles, {st.why}"
        return f"safety.max_stale_cycles = {self.max_missing}"

    def _lag_limit_text(self) -> str:
        st = self.stale
        if st is not None and st.derived:
            return f"safety.max_stale_ms: the stall the master tolerates is {self.max_lag_s * 1e3:g} ms ({st.why})"
        return f"safety.max_lag_s = {self.max_lag_s * 1e3:g} ms"

    def _confirm_stop(self) -> None:
        """After the last command of the safe stop: each drive's statusword read again by SDO
        (:meth:`MasterCore.confirm_frames <hil.master.core.MasterCore.confirm_frames>`), until every read
        ended (answered, aborted, or not answered in :data:`hil.master.powerup.CONFIRM_READS` reads of
        ``canopen.sdo_timeout_s`` each; bounded here once more)."""
        t0 = self.tr.now()
        self._send(self.m.confirm_frames(t0))
        limit = t0 + (CONFIRM_READS + 1) * self.m.act.canopen.sdo_timeout_s
        while not self.m.confirmation.done and self.tr.now() < limit:
            self._feed(self.tr.receive(self.tr.now() + 0.01))
            self._send(self.m.poll(self.tr.now()))

    def close(self) -> None:
        """Bring both drives down to the safe state, stop SYNC, NMT pre-operational, close the log.

        Orderly (disable operation, shutdown, disable voltage) after a finished check, quick stop
        then disable after an abort. A drive that cannot be reached (heartbeat lost, no statusword)
        does not hold up the other, which is stopped in the same cycles; it is commanded until
        ``canopen.enable_timeout_s`` has passed, in case it answers again (its process or the PC was held:
        left at once, it would end where the hold found it, in Operation enabled or Quick stop active).
        Every step runs even if an earlier one fails; the first error is re-raised at the end. Then each
        drive's state is read again by SDO (:meth:`_confirm_stop`): :attr:`final_states` holds what was seen,
        confirmed only by that read.
        """
        if self._closed:
            return
        self._closed = True
        errors: list[BaseException] = []
        try:
            if self._last is not None and self.m.preflight_done:
                deadline = self.tr.now() + self.m.act.canopen.enable_timeout_s
                # (a drive unreachable now may be a held process or a lapsed heartbeat and answer again: commanded
                # to the end, up to the deadline; the other is stopped in the same cycles meanwhile)
                while not self._stopped_all(self.tr.now()) and self.tr.now() < deadline:
                    try:
                        self._safe_cycle()
                    except KNOWN_ERRORS as exc:  # recorded; keep stopping the drives
                        errors.append(exc)
                        if len(errors) > 50:
                            break
        except BaseException as exc:
            errors.append(exc)
        if not self.m.preflight_done:
            try:  # the drill may have powered a drive up when the preflight failed: disable voltage by SDO
                self._send(self.m.abort_preflight_frames(self.tr.now()))
                self._feed(self.tr.receive(self.tr.now()))
            except BaseException as exc:
                errors.append(exc)
        try:
            self._confirm_stop()
        except BaseException as exc:
            errors.append(exc)
        self.final_states = self.m.safe_state_report(self.tr.now())
        self.close_errors = [f"{type(e).__name__}: {e}" for e in errors]
        for step in (self.tr.stop_sync,
                     lambda: self._send(self.m.nmt_frames(NmtCommand.PRE_OPERATIONAL)),
                     lambda: self._feed(self.tr.receive(self.tr.now()))):
            try:
                step()
            except BaseException as exc:
                errors.append(exc)
        if self.log is not None:
            try:
                self.log.close()
            except BaseException as exc:
                errors.append(exc)
        fatal = [e for e in errors if not isinstance(e, KNOWN_ERRORS)]
        if fatal:
            raise fatal[0]
