"""The CANopen link: the master core over a python-can bus (the thin IO shell).

:class:`CanopenLink` implements the :class:`hil.runner.Link` protocol, so the
check loop and the sequence core run unchanged whether the drives are
simulated or real. Two transports move the frames:

* :class:`InProcessTransport` (``emacheck dry-run``): the master's bus and the
  simulated drive pair's bus are python-can ``virtual`` buses on one channel;
  frames are pumped synchronously in this thread and the SYNC is sent once per
  cycle on simulated time, so a dry-run is deterministic for a seed and runs as
  fast as the CPU allows (``realtime=True`` paces SYNC at the SYNC period on
  the monotonic clock).
* :class:`BusTransport` (``emacheck run``): any python-can bus; SYNC by
  ``send_periodic`` (kernel-timed Broadcast Manager on SocketCAN), frames
  received on this thread, time from the monotonic clock.
"""

from __future__ import annotations

import queue
import socket
import struct
import time
from typing import Callable, Protocol

import can
from can.interfaces.virtual import VirtualBus

from hil.canlog import CanLogWriter
from hil.cia402 import State
from hil.config import HARD_MAX_LAG_S
from hil.errors import EmacheckError
from hil.master import MasterCore, PreflightError
from hil.nmt import NmtCommand
from hil.pdo import SYNC_COB_ID, Frame, sync_frame
from hil.sdo import SdoAbortError, SdoTimeout
from hil.types import DriveMode, Sample, Setpoint

DISABLED = Setpoint(DriveMode.DISABLED, 0.0)
#: Safe-state cycles after which a drive still in OPERATION_ENABLED gets the quick stop by SDO
#: (and again every as many cycles): its RPDOs are not getting through.
SDO_FALLBACK_CYCLES = 5


class LinkError(EmacheckError, RuntimeError):
    """The cyclic exchange with the drives broke down (no samples)."""


class StaleData(LinkError):
    """Sensor freshness: no complete sample for more SYNC cycles than ``safety.max_stale_cycles``."""


class Transport(Protocol):
    def now(self) -> float: ...

    def send(self, frames: list[Frame], t: float) -> None: ...

    def receive(self, deadline: float) -> list[tuple[Frame, float]]: ...

    def start_sync(self) -> None: ...

    def next_sync(self) -> float | None: ...

    def stop_sync(self) -> None: ...

    def close(self) -> None: ...


class SharedVirtualBus(VirtualBus):
    """python-can's in-process virtual bus, minus the deep copy of every message per recipient.

    The stock ``VirtualBus.send`` deep-copies each message for each receiver
    (about half of a dry-run's time). The link never mutates a message after
    sending it, so the receivers may share it. Everything else (channels,
    queues, ``recv``) is python-can's.
    """

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check_if_open()
        for bus_queue in self.channel:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            bus_queue.put_nowait(msg)

    def recv_nowait(self) -> can.Message | None:
        """The next queued message or None, straight from this bus's queue: the synchronous
        frame pump of a dry-run never waits, so python-can's ``recv`` (clock, filters, timed
        wait) is skipped; no filters are set on these buses."""
        try:
            return self.queue.get_nowait()
        except queue.Empty:
            return None


def _to_msg(f: Frame, t: float, rx: bool = False) -> can.Message:
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False,
                       is_rx=rx, check=False)


class InProcessTransport:
    """Master bus and simulated drive pair on an in-process python-can virtual bus.

    ``pair`` is a :class:`sim.slave.SimDrivePair`; its frames are produced in
    this thread as soon as the master's frames reach its bus.
    """

    def __init__(self, pair, sync_period_s: float, channel: str = "emacheck-dry-run",
                 realtime: bool = False) -> None:
        self.pair = pair
        self.T = sync_period_s
        self.t = 0.0
        self.realtime = realtime
        self.master_bus = SharedVirtualBus(channel=channel, preserve_timestamps=True)
        self.slave_bus = SharedVirtualBus(channel=channel, preserve_timestamps=True)
        self._sync_on = False
        self._t0_wall: float | None = None
        self._pending: list[tuple[Frame, float]] = []
        for f in pair.power_on(self.t):
            self.slave_bus.send(_to_msg(f, self.t, rx=True))

    def now(self) -> float:
        return self.t

    def send(self, frames: list[Frame], t: float) -> list[can.Message]:
        msgs = [_to_msg(f, t) for f in frames]
        for m in msgs:
            self.master_bus.send(m)
        return msgs

    def _pump_slaves(self) -> None:
        bus = self.slave_bus
        pair = self.pair
        while True:
            msg = bus.recv_nowait()
            if msg is None:
                return
            out = pair.on_frame(Frame.trusted(msg.arbitration_id, bytes(msg.data)), self.t)
            for f in out:
                bus.send(_to_msg(f, self.t, rx=True))

    def receive(self, deadline: float) -> list[tuple[Frame, float, can.Message]]:
        """Deliver everything in flight; simulated time advances to ``deadline`` if idle."""
        self._pump_slaves()
        got = []
        bus = self.master_bus
        while True:
            msg = bus.recv_nowait()
            if msg is None:
                break
            got.append((Frame.trusted(msg.arbitration_id, bytes(msg.data)), msg.timestamp, msg))
        if not got and deadline > self.t:
            # nothing in flight: let simulated time pass (heartbeats, boot-up)
            self.t = min(deadline, self.t + self.T)
            for f in self.pair.tick(self.t):
                self.slave_bus.send(_to_msg(f, self.t, rx=True))
            self._pump_slaves()
        return got

    def start_sync(self) -> None:
        self._sync_on = True
        self._t0_wall = time.monotonic()

    def next_sync(self) -> float | None:
        """Advance one SYNC period and send SYNC (the pair steps its plant on it)."""
        if not self._sync_on:
            return None
        self.t += self.T
        if self.realtime and self._t0_wall is not None:
            delay = self._t0_wall + self.t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        for f in self.pair.tick(self.t):
            self.slave_bus.send(_to_msg(f, self.t, rx=True))
        self.master_bus.send(_to_msg(sync_frame(), self.t))
        return self.t

    def stop_sync(self) -> None:
        self._sync_on = False

    def close(self) -> None:
        self.master_bus.shutdown()
        self.slave_bus.shutdown()


_CAN_FRAME = struct.Struct("<IB3x8s")  # struct can_frame: id, dlc, pad, data[8]


#: SO_TIMESTAMPNS (asm-generic/socket.h; Python's socket module does not name it)
_SO_TIMESTAMPNS = 35
_ANC_SPACE = socket.CMSG_SPACE(16) if hasattr(socket, "CMSG_SPACE") else 64


def _stamp(anc: list) -> float | None:
    """The SO_TIMESTAMPNS receive time [s, CLOCK_REALTIME] in a ``recvmsg`` ancillary list, or None."""
    for level, kind, data in anc:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = struct.unpack_from("@ll", data)
            return sec + nsec * 1e-9
    return None


class SocketcanFrames:
    """Classic CAN frames straight on a SocketCAN socket: one system call per frame.

    python-can's ``recv`` costs ``time()``, ``select`` and ``recvmsg`` (with a
    timestamp) per frame plus as many for the empty probe that ends a drain,
    and ``send`` a ``select`` plus ``send``. Where a system call is expensive
    (user-mode-linux: ~0.12 ms on the CI machines; small embedded masters)
    that alone fills a SYNC cycle. Here a frame costs one blocking ``recvmsg``
    with a receive timeout (queued or waited for alike) and ``send`` one
    ``send``. Extended, remote, error and CAN FD frames are dropped (counted
    in :attr:`ignored`).
    """

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.ignored = 0
        self._rcvtimeo: float | None = None
        sock.setblocking(True)

    @classmethod
    def for_bus(cls, bus: can.BusABC) -> "SocketcanFrames | None":
        """The fast path for a python-can SocketCAN bus, None for any other bus."""
        sock = getattr(bus, "socket", None)
        if isinstance(sock, socket.socket) and sock.family == getattr(socket, "AF_CAN", None):
            return cls(sock)
        return None

    def _decode(self, raw: bytes) -> Frame | None:
        cid = int.from_bytes(raw[0:4], "little")
        if len(raw) != 16 or cid & 0xE0000000 or raw[4] > 8:
            self.ignored += 1
            return None
        return Frame.trusted(cid, raw[8:8 + raw[4]])

    def recv_stamped(self, timeout: float) -> tuple[bool, Frame | None, float | None]:
        """One frame, waiting up to ``timeout`` [s] (SO_RCVTIMEO, set only when it changes), with
        the kernel's receive time (CLOCK_REALTIME [s], from SO_TIMESTAMPNS, which python-can
        enables on its sockets; None if absent): (True, frame or None if ignored, stamp) or
        (False, None, None) after the timeout. One system call, whether the frame was queued or
        came while waiting."""
        self._set_rcvtimeo(timeout)
        try:
            raw, anc, _flags, _addr = self.sock.recvmsg(72, _ANC_SPACE)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return False, None, None
        return True, self._decode(raw), _stamp(anc)

    def _set_rcvtimeo(self, timeout: float) -> None:
        if timeout != self._rcvtimeo:
            us = max(1, int(timeout * 1e6))  # 0 would mean "forever"
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", us // 1000000, us % 1000000))
            self._rcvtimeo = timeout

    def send(self, f: Frame) -> None:
        try:
            self.sock.send(_CAN_FRAME.pack(f.arbitration_id, len(f.data), f.data))
        except OSError as exc:
            raise can.CanOperationError(f"Failed to transmit: {exc.strerror}", exc.errno) from exc


class BusTransport:
    """A real python-can bus (SocketCAN, or any interface python-can knows).

    On SocketCAN, frames go through the bus's socket directly
    (:class:`SocketcanFrames`, one frame per :meth:`receive`); elsewhere
    through python-can.
    """

    def __init__(self, bus: can.BusABC, sync_period_s: float) -> None:
        self.bus = bus
        self.T = sync_period_s
        self._task = None
        self._t0 = time.monotonic()
        #: CLOCK_REALTIME minus CLOCK_MONOTONIC: turns the kernel's receive stamps into our time base
        self._rt_minus_mono = time.time() - time.monotonic()
        self._raw = SocketcanFrames.for_bus(bus)
        self._now = 0.0
        #: how long the last SYNC waited in the socket before it was taken [s]
        self.lag_s = 0.0
        self.max_lag_s = 0.0  #: the largest lag seen [s]
        #: longest single wait for a frame [s]: a receive may end this much after its deadline
        self._slice = sync_period_s / 4
        self._sync_started = 0.0  #: when start_sync() returned [s]

    def now(self) -> float:
        """Monotonic time [s] since the transport was made; on SocketCAN, the time of the last
        event :meth:`receive` delivered.

        On SocketCAN that is the kernel's receive time of the frame just taken
        (event time): when the master has fallen behind and frames wait in the
        socket, every frame, and every timeout judged after it (heartbeat
        consumer, SDO, cycle end), carries the time it arrived, not the time it
        was read; a heartbeat still queued is never judged missing. When the
        queue was empty, it is the clock at the end of the wait. (Reading the
        clock is a system call where there is no vDSO, as in user-mode-linux:
        this path reads it only when a wait times out, and once per SYNC.)
        :attr:`lag_s` says how long the last SYNC waited in the socket before
        the master took it.
        """
        if self._raw is None:
            return time.monotonic() - self._t0
        return self._now

    def _clock(self) -> float:
        self._now = time.monotonic() - self._t0
        return self._now

    def send(self, frames: list[Frame], t: float) -> list[can.Message]:
        msgs = [_to_msg(f, t) for f in frames]
        if self._raw is not None:
            for f in frames:
                self._raw.send(f)
            return msgs
        for m in msgs:
            self.bus.send(m)
        return msgs

    def receive(self, deadline: float) -> list[tuple[Frame, float, can.Message]]:
        if self._raw is not None:
            while True:
                # one system call per frame, queued or waited for; the clock is read only when
                # the wait times out and once per SYNC (to measure the lag)
                got, f, ts = self._raw.recv_stamped(self._slice)
                if got:
                    break
                if self._clock() >= deadline:
                    self.lag_s = 0.0
                    return []
            if ts is None:
                t = self._clock()
            else:
                t = ts - self._rt_minus_mono - self._t0
                self._now = t
                if f is not None and f.arbitration_id == SYNC_COB_ID:
                    # how long the cycle's first frame waited in the socket: the master's lag
                    # (not counting what came while start_sync() itself was setting SYNC up)
                    self.lag_s = max(0.0, time.monotonic() - self._t0 - max(t, self._sync_started))
                    if self.lag_s > self.max_lag_s:
                        self.max_lag_s = self.lag_s
            if f is None:
                return []
            return [(f, t, _to_msg(f, t, rx=True))]
        timeout = max(0.0, deadline - self.now())
        msg = self.bus.recv(timeout)
        out = []
        while msg is not None:
            if not msg.is_extended_id and not msg.is_error_frame and not msg.is_remote_frame and msg.dlc <= 8:
                out.append((Frame.trusted(msg.arbitration_id, bytes(msg.data)), self.now(), msg))
            msg = self.bus.recv(0.0)
        return out

    def start_sync(self) -> None:
        # kernel-timed on socketcan (Broadcast Manager), a thread elsewhere
        self._task = self.bus.send_periodic(
            can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False), self.T)
        self._sync_started = time.monotonic() - self._t0

    def next_sync(self) -> float | None:
        return None  # SYNC comes from the periodic task; the master sees it on the bus

    def stop_sync(self) -> None:
        if self._task is not None:
            self._task.stop()
            self._task = None

    def close(self) -> None:
        self.stop_sync()


class CanopenLink:
    """The drives over CANopen, as a :class:`hil.runner.Link`.

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
        On a real bus, the longest a SYNC may wait in the master's socket before
        the master takes it [s] (``safety.max_lag_s``); beyond it the master has
        fallen behind the bus (or the computer stalled) and stops with
        :class:`StaleData`. Default: ``max_missing_cycles`` SYNC periods.
    """

    def __init__(self, master: MasterCore, transport, log: CanLogWriter | None = None,
                 on_event: Callable | None = None, max_missing_cycles: int = 5,
                 max_lag_s: float | None = None) -> None:
        self.m = master
        self.tr = transport
        self.log = log
        self.on_event = on_event
        self.max_missing = max_missing_cycles
        #: the longest a SYNC may have waited in the socket before the master took it [s]
        lag = max_lag_s if max_lag_s is not None else max_missing_cycles * getattr(transport, "T", 0.0)
        self.max_lag_s = min(lag, HARD_MAX_LAG_S)  # applied again here, whatever the caller passed
        self._last: Sample | None = None
        self._closed = False
        self.sync_times: list[float] = []
        self.final_states: dict | None = None  #: per EMA, after :meth:`close`
        self._safe_cycles = 0
        self.close_errors: list[str] = []  #: errors met while stopping the drives (recorded, not raised)

    # -------------------------------------------------------------- plumbing

    def _send(self, frames: list[Frame]) -> None:
        if not frames:
            return
        msgs = self.tr.send(frames, self.tr.now())
        if self.log is not None:
            for m in msgs:
                self.log.write_msg(m)

    def _feed(self, got: list[tuple[Frame, float, can.Message]]) -> None:
        log = self.log
        on_frame = self.m.on_frame
        now = self.tr.now
        for f, t, msg in got:
            if log is not None:
                if msg.timestamp != t:
                    msg.timestamp = t  # log the time the master saw it
                log.write_msg(msg)
            out = on_frame(f, now())
            if out:
                self._send(out)
        events = self.m.drain_events()  # drained always: the master's list must not grow in the loop
        if self.on_event is not None:
            for ev in events:
                self.on_event(ev)

    def _sync(self) -> None:
        t = self.tr.next_sync()
        if t is not None:
            self.sync_times.append(t)
            # the SYNC we sent is part of the traffic the master follows
            if self.log is not None:
                self.log.write(sync_frame(), t, rx=False)
            self.m.on_frame(sync_frame(), t)

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
                                         f"{limit - t0:.0f} s")
                self._feed(self.tr.receive(now + 0.01))
                self._send(self.m.poll(self.tr.now()))
        except (SdoAbortError, SdoTimeout) as exc:
            if getattr(exc, "abort_frame", None) is not None:
                self._send([exc.abort_frame])
            raise

    def _next_sample(self) -> Sample:
        """Run one SYNC cycle and return its sample (SYNC, TPDOs of both drives)."""
        missing = 0
        while True:
            sample = self._cycle(stop_at_sample=True)
            if sample is not None:
                self._last = sample
                return sample
            missing += 1
            if missing > self.max_missing:
                err = StaleData(f"sensor data stale: no complete sample for {missing} SYNC cycles "
                                f"(safety.max_stale_cycles = {self.max_missing}); missing: "
                                + ", ".join(f"node {n} TPDO{k}" for n, d in self.m.drives.items()
                                            for k, tp in ((1, d.tpdo1), (2, d.tpdo2)) if tp is None)
                                + f"; drive states {[d.state.name for d in self.m.drives.values()]}")
                self.m._latch(err)
                raise err

    def first_sample(self) -> Sample:
        """Preflight, start SYNC, enable both drives in CSP holding their position."""
        self.preflight()
        self.tr.start_sync()
        smp = self._next_sample()
        deadline = self.tr.now() + self.m.act.canopen.enable_timeout_s
        while not self.m.all_in(State.OPERATION_ENABLED):
            if self.tr.now() > deadline:
                states = {n: d.state.name for n, d in self.m.drives.items()}
                raise PreflightError(f"drives not in OPERATION_ENABLED within canopen.enable_timeout_s = "
                                     f"{self.m.act.canopen.enable_timeout_s} s: {states}")
            hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
            self._send(self.m.setpoint_frames(*hold, smp))
            smp = self._next_sample()
        return smp

    def exchange(self, sp1: Setpoint, sp2: Setpoint) -> Sample:
        if self.m.fault is not None and sp1.mode is DriveMode.DISABLED and sp2.mode is DriveMode.DISABLED:
            # stopping after a fault: one safe-state cycle, no complete sample required
            self._safe_cycle()
            return self._last
        self._send(self.m.setpoint_frames(sp1, sp2, self._last))
        return self._next_sample()

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
        self._sync()
        inproc = isinstance(self.tr, InProcessTransport)
        cycle_end = self.tr.now() + self.tr.T
        found = None
        while True:
            got = self.tr.receive(self.tr.now() if inproc else cycle_end)
            if got:
                lag = getattr(self.tr, "lag_s", 0.0)
                # (once stopping after a fault, the safe-state sequence goes on whatever the lag)
                if lag > self.max_lag_s and self.m.fault is None:
                    # the master has fallen behind the bus: whatever it computes now is stale
                    err = StaleData(f"sensor data stale: the master is {lag * 1e3:.0f} ms behind the bus "
                                    f"(frames wait in its socket; safety.max_lag_s = {self.max_lag_s * 1e3:.0f} ms)")
                    self.m._latch(err)
                    raise err
                self._feed(got)
            self._send(self.m.poll(self.tr.now()))
            sample = self.m.take_sample()
            if sample is not None:
                found = sample
                if stop_at_sample:
                    return found
            if not got or (not inproc and self.tr.now() >= cycle_end):
                return found

    def close(self) -> None:
        """Bring both drives down to the safe state, stop SYNC, NMT pre-operational, close the log.

        Orderly (disable operation, shutdown, disable voltage) after a finished check, quick stop
        then disable after an abort. A drive that cannot be reached (heartbeat lost, no statusword)
        does not hold up the other. Every step runs even if an earlier one fails; the first error
        is re-raised at the end. :attr:`final_states` then holds each drive's last known state.
        """
        if self._closed:
            return
        self._closed = True
        errors: list[BaseException] = []
        try:
            if self._last is not None and self.m.preflight_done:
                deadline = self.tr.now() + self.m.act.canopen.enable_timeout_s
                while not self.m.in_safe_state(self.tr.now()) and self.tr.now() < deadline:
                    try:
                        self._safe_cycle()
                    except EmacheckError as exc:  # recorded; keep stopping the drives
                        errors.append(exc)
                        if len(errors) > 50:
                            break
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
        fatal = [e for e in errors if not isinstance(e, EmacheckError)]
        if fatal:
            raise fatal[0]
