"""Transports: how frames get between the master and the drives (the thin IO shell, python-can).

Two transports move the frames of :class:`hil.master.link.CanopenLink`:

* :class:`InProcessTransport` (``emacheck dry-run``): the master and the
  simulated drive pair on an in-process bus of the project's own
  :class:`~hil.canopen.frame.Frame` objects (two FIFO queues, no python-can);
  frames are pumped synchronously in this thread and the SYNC is sent once per
  cycle on simulated time, so a dry-run is deterministic for a seed and runs as
  fast as the CPU allows (``realtime=True`` paces SYNC at the SYNC period on
  the monotonic clock).
* :class:`BusTransport` (``emacheck run``): any python-can bus; SYNC by
  ``send_periodic`` where it is kernel- or hardware-timed (Broadcast Manager on
  SocketCAN), else sent by the loop itself on a monotonic schedule (python-can's
  fallback, a thread in this process, waits for the GIL while the loop
  computes); frames received on this thread, time from the monotonic clock or,
  on SocketCAN, the kernel's receive stamp of each frame (event time).

Both implement :class:`Transport`, the one seam between the link and a bus.
python-can messages exist only at a real bus (:class:`BusTransport`): a
received frame comes as ``(frame, time, message)``, the message None where
there is none (in process, the SocketCAN fast path), else python-can's (the
CAN log keeps its channel and direction).
"""

from __future__ import annotations

import math
import socket
import struct
import time
from collections import deque
from typing import Protocol

import can

from hil.canopen.frame import SYNC_COB_ID, Frame, sync_frame
from hil.errors import LinkLostError


class Transport(Protocol):
    def now(self) -> float: ...

    def send(self, frames: list[Frame], t: float) -> None: ...

    def receive(self, deadline: float) -> list[tuple[Frame, float, can.Message | None]]: ...

    def start_sync(self) -> None: ...

    def next_sync(self) -> float | None: ...

    def stop_sync(self) -> None: ...

    def close(self) -> None: ...


def _to_msg(f: Frame, t: float, rx: bool = False) -> can.Message:
    """A frame as a python-can message (the boundary to a real bus)."""
    return can.Message(timestamp=t, arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False,
                       is_rx=rx, check=False)


class InProcessTransport:
    """Master and simulated drive pair on an in-process bus of :class:`Frame` objects.

    The bus is two FIFO queues of ``(frame, time)`` in this thread: what the
    master sends goes to the drives, what the drives send to the master (no
    python-can messages, thread queues or locks: nothing else is on this bus).
    ``pair`` is a :class:`sim.drives.SimDrivePair`; its frames are produced in
    this thread as soon as the master's frames reach it, stamped with the
    simulated time.

    ``stalls`` (a :class:`hil.master.stalls.MasterStalls`) makes the master stall on the simulated time axis:
    at a stall's SYNC, :meth:`next_sync` runs the bus on for the stall's length (SYNC every period, the
    drives answering, every frame queued for the master with the time it was sent, the SYNC frames too)
    and returns None; the master then takes the whole backlog, :attr:`lag_s` saying how late (the
    stall's length), as from a real bus's socket.
    """

    def __init__(self, pair, sync_period_s: float, realtime: bool = False, stalls=None) -> None:
        self.pair = pair
        self.T = sync_period_s
        self.t = 0.0
        self.realtime = realtime
        self.stalls = stalls
        #: how late the master takes the frames :meth:`receive` delivers [s]: an injected stall's length
        #: for its backlog, else 0 (the in-process bus has no socket to wait in)
        self.lag_s = 0.0
        self.max_lag_s = 0.0  #: the largest lag [s]
        self._stall_lag = 0.0  #: the lag of the backlog still in flight [s]
        #: frames on their way to the drives, in order (the master's)
        self._to_slaves: deque[Frame] = deque()
        #: frames on their way to the master, in order, with the time they were sent [s]
        self._to_master: deque[tuple[Frame, float]] = deque()
        self._sync_on = False
        self._t0_wall: float | None = None
        t = self.t
        self._to_master.extend([(f, t) for f in pair.power_on(t)])

    def now(self) -> float:
        return self.t

    def send(self, frames: list[Frame], t: float) -> None:
        """The master's frames onto the bus (the drives take them at the next :meth:`receive`)."""
        self._to_slaves.extend(frames)

    def inject(self, frame: Frame, t: float) -> None:
        """A frame from another node on the bus at time ``t`` [s]: the master sees it (tests)."""
        self._to_master.append((frame, t))

    def _pump_slaves(self) -> None:
        todo = self._to_slaves
        if not todo:
            return
        out = self._to_master
        on_frame = self.pair.on_frame
        t = self.t
        pop = todo.popleft
        while todo:
            answer = on_frame(pop(), t)
            if answer:
                out.extend([(f, t) for f in answer])

    def receive(self, deadline: float) -> list[tuple[Frame, float, None]]:
        """Deliver everything in flight; simulated time advances to ``deadline`` if idle.

        Each frame comes with the time it was sent [s] and None (no python-can message)."""
        self._pump_slaves()
        inbox = self._to_master
        if inbox:
            got = [(f, t, None) for f, t in inbox]
            inbox.clear()
            self.lag_s, self._stall_lag = self._stall_lag, 0.0
            return got
        self.lag_s = 0.0
        if deadline > self.t:
            # nothing in flight: let simulated time pass (heartbeats, boot-up)
            t = self.t = min(deadline, self.t + self.T)
            inbox.extend([(f, t) for f in self.pair.tick(t)])
            self._pump_slaves()
        return []

    def start_sync(self) -> None:
        self._sync_on = True
        self._t0_wall = time.monotonic()
        if self.stalls is not None:
            self.stalls.start(self.t)

    def next_sync(self) -> float | None:
        """Advance one SYNC period and send SYNC (the pair steps its plant on it); None where the master
        stalls instead (``stalls``): the SYNCs of the stall wait for it on the bus."""
        if not self._sync_on:
            return None
        if self.stalls is not None:
            stall = self.stalls.due(self.t + self.T)
            if stall is not None:
                self._stall(stall)
                return None
        self.t += self.T
        if self.realtime and self._t0_wall is not None:
            delay = self._t0_wall + self.t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        t = self.t
        self._to_master.extend([(f, t) for f in self.pair.tick(t)])
        self._to_slaves.append(sync_frame())
        return t

    def _stall(self, stall_s: float) -> None:
        """The master stalls for ``stall_s`` [s] from the next SYNC: every SYNC period within it (its end
        included) SYNC goes to the drives and to the master's queue, the drives answer; simulated time
        ends at the stall's last SYNC, the master taking the backlog ``stall_s`` late."""
        n = math.floor(stall_s / self.T + 1e-9)
        inbox = self._to_master
        for _ in range(n + 1):
            self.t += self.T
            t = self.t
            inbox.extend([(f, t) for f in self.pair.tick(t)])
            inbox.append((sync_frame(), t))
            self._to_slaves.append(sync_frame())
            self._pump_slaves()
        self._stall_lag = stall_s
        self.max_lag_s = max(self.max_lag_s, stall_s)

    def stop_sync(self) -> None:
        self._sync_on = False

    def close(self) -> None:
        self._to_slaves.clear()
        self._to_master.clear()


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
    def for_bus(cls, bus: can.BusABC) -> SocketcanFrames | None:
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
        #: SYNC sent by the loop (:meth:`sync_due`, :meth:`send_sync`) where the interface has no
        #: kernel- or hardware-timed periodic send (python-can's fallback is a thread in this process,
        #: which waits for the GIL while the loop computes: SYNC late by up to the switch interval)
        self.loop_sync = self._raw is None and (
            type(bus)._send_periodic_internal is can.BusABC._send_periodic_internal)
        self._due: float | None = None
        self.sync_skipped = 0  #: SYNC periods the loop-timed SYNC skipped (the loop was that late)
        self.sync_late_max_s = 0.0  #: the latest a loop-timed SYNC left after its due time [s]
        #: the slot on the schedule (k T from the first) of the last loop-timed SYNC sent [s]: the
        #: time of the sample that answers it (:meth:`send_sync`); None before the first
        self.sync_slot_s: float | None = None

    @property
    def wall_clock_offset_s(self) -> float:
        """Add to this transport's time to get wall-clock (UNIX) time [s]: the CAN log's stamps."""
        return self._t0 + self._rt_minus_mono

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

    def clock(self) -> float:
        """Monotonic time [s] since the transport was made, read now (for the loop's timing)."""
        return time.monotonic() - self._t0

    def _arrival(self, msg: can.Message, now: float) -> float:
        """When ``msg`` arrived [s, this transport's time]: its receive stamp where that is the
        kernel's wall-clock stamp (udp_multicast, virtual: within a second before ``now``), else ``now``."""
        t = msg.timestamp - self._rt_minus_mono - self._t0
        return t if now - 1.0 < t <= now else now

    def send(self, frames: list[Frame], t: float) -> None:
        try:
            if self._raw is not None:
                for f in frames:
                    self._raw.send(f)
                return
            for f in frames:
                self.bus.send(_to_msg(f, t))
        except (OSError, can.CanError) as exc:
            raise self.lost(exc) from exc

    def lost(self, exc: BaseException) -> LinkLostError:
        """The CAN interface gone (an adapter unplugged, the interface taken down: ENETDOWN, ENODEV ...), as
        :class:`hil.errors.LinkLostError` naming it and the cause."""
        import errno

        code = getattr(exc, "errno", None)
        if not isinstance(code, int):
            code = getattr(exc, "error_code", None)
        name = errno.errorcode.get(code, "") if isinstance(code, int) else ""
        return LinkLostError(f"the CAN interface {self.bus.channel_info!r} went away: {type(exc).__name__}: {exc}"
                             + (f" ({name})" if name else "") + "; the master can no longer reach the drives, "
                             "they are left to their own reaction to losing the master, as configured and drilled "
                             "before the check (meta.json master_loss)")

    def receive(self, deadline: float) -> list[tuple[Frame, float, can.Message | None]]:
        try:
            return self._receive(deadline)
        except (OSError, can.CanError) as exc:
            raise self.lost(exc) from exc

    def _receive(self, deadline: float) -> list[tuple[Frame, float, can.Message | None]]:
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
            return [(f, t, None)]
        timeout = max(0.0, deadline - self.now())
        msg = self.bus.recv(timeout)
        out = []
        while msg is not None:
            if not msg.is_extended_id and not msg.is_error_frame and not msg.is_remote_frame and msg.dlc <= 8:
                now = self.now()
                t = self._arrival(msg, now)
                if msg.arbitration_id == SYNC_COB_ID:
                    self.lag_s = now - t  # how long the SYNC waited before the master took it
                    if self.lag_s > self.max_lag_s:
                        self.max_lag_s = self.lag_s
                out.append((Frame.trusted(msg.arbitration_id, bytes(msg.data)), t, msg))
            msg = self.bus.recv(0.0)
        return out

    def start_sync(self) -> None:
        # kernel-timed on socketcan (Broadcast Manager), hardware-timed where the interface can,
        # else sent by the loop on its own schedule (sync_due, send_sync)
        if self.loop_sync:
            self._due = self.clock()
        else:
            self._task = self.bus.send_periodic(
                can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False), self.T)
        self._sync_started = time.monotonic() - self._t0

    def next_sync(self) -> float | None:
        return None  # SYNC comes from the periodic task or send_sync; the master sees it on the bus

    def sync_due(self) -> float | None:
        """When the loop must send the next SYNC [s] (loop-timed SYNC running), else None."""
        return self._due

    def send_sync(self) -> float:
        """Send the SYNC that is due now; returns when it left [s].

        The schedule keeps its phase (slots k T from the first). A SYNC belongs
        to the slot nearest to when it left, :attr:`sync_slot_s`: one that left
        more than half a period after its due time is the next slot's (sent
        early for it), so every SYNC leaves within T/2 of its slot and the
        sample answering it carries that slot's time. Slots passed over are
        counted in :attr:`sync_skipped`; the next is due one period after the
        slot taken.
        """
        try:
            self.bus.send(can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False, check=False))
        except (OSError, can.CanError) as exc:
            raise self.lost(exc) from exc
        t = self.clock()
        due = self._due
        late = t - due
        if late > self.sync_late_max_s:
            self.sync_late_max_s = late
        skip = int(late / self.T + 0.5) if late > 0.5 * self.T else 0
        self.sync_skipped += skip
        slot = due + skip * self.T
        self.sync_slot_s = slot
        self._due = slot + self.T
        return t

    def stop_sync(self) -> None:
        self._due = None
        if self._task is not None:
            self._task.stop()
            self._task = None

    def close(self) -> None:
        self.stop_sync()
