"""The simulated drive pair as its own process on a CAN bus (``emacheck sim-serve``).

:func:`serve` is the thin IO shell around the sans-IO
:class:`sim.drives.SimDrivePair`: it powers the pair on, then receives the
frames of any python-can bus (SocketCAN ``vcan0``, a real interface, the
``virtual`` bus in tests), feeds them to the pair and transmits the replies;
it lets time pass for the heartbeats by calling ``pair.tick`` on the clock.
The plant steps on each SYNC received (inside the pair), so the master's SYNC
paces the simulated rig exactly as it paces real drives.

Time given to the pair is the monotonic clock relative to the start of
:func:`serve` [s]. The loop ends when ``stop`` is set (the CLI sets it from
SIGINT/SIGTERM) and shuts the bus down.

:func:`simulated_rig` builds the simulated rig every command uses, served here or on the in-process bus of
``dry-run`` and ``commission --simulate``: the drive pair on the simulated-rig profile's plant, inside the
fault injector with that profile's ``[[faults]]`` (wiring faults among them), so a rig served by
``sim-serve`` behaves as the same rig in process.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import can

from hil.canopen.frame import SYNC_COB_ID, Frame
from hil.record.cycletiming import CycleTiming, TimingSummary
from hil.transport import SocketcanFrames

#: Longest wait for a frame [s] (fixed, so SocketCAN needs no timeout change per frame):
#: how late a stop request or a tick may be seen.
RECV_SLICE_S = 0.002


#: Interval of ``pair.tick`` calls [s] (heartbeats are due at multiples of 0x1017).
TICK_PERIOD_S = 0.002


#: The synchronous window (CiA 301 0x1007) as a fraction of the SYNC period (with ``period_s``):
#: TPDOs of a SYNC that are ready only later than this after the SYNC arrived (this process was
#: held up) are discarded, not sent: sent after the next SYNC, the master would take them for the
#: next cycle's, and a cycle's old positions under the next cycle's time read as a doubled speed.
#: The master sees a missing cycle instead (its freshness limit counts them).
SYNC_WINDOW_FRACTION = 0.9


#: Interval of ``on_stats`` calls while serving [s].
STATS_PERIOD_S = 1.0


@dataclass(frozen=True, slots=True)
class ServeStats:
    """What a :func:`serve` loop did (a snapshot).

    Attributes
    ----------
    duration_s : float
        Time since :func:`serve` started [s].
    frames_rx, frames_tx : int
        Frames received from / transmitted on the bus.
    frames_ignored : int
        Received messages that are not classic 11-bit data frames (extended,
        remote, error frames, DLC over 8); never given to the pair.
    send_errors : int
        Transmissions python-can refused (e.g. a full transmit queue).
    syncs, plant_steps, tpdos_sent, rpdos_late, heartbeats_sent : int
        The pair's counters (:class:`sim.drives.SimPairStats`).
    """

    duration_s: float = 0.0
    frames_rx: int = 0
    frames_tx: int = 0
    frames_ignored: int = 0
    send_errors: int = 0
    syncs: int = 0
    plant_steps: int = 0
    tpdos_sent: int = 0
    rpdos_late: int = 0
    heartbeats_sent: int = 0
    tpdos_discarded: int = 0  #: TPDOs not sent: their SYNC's window had passed (:data:`SYNC_WINDOW_FRACTION`)
    timing: TimingSummary | None = None  #: the loop's timing per SYNC (with ``period_s`` given to :func:`serve`)

    def line(self) -> str:
        """The one-line summary ``sim-serve`` prints at the end."""
        return (f"sim-serve: {self.duration_s:.1f} s, {self.syncs} SYNCs, {self.plant_steps} plant steps, "
                f"{self.rpdos_late} late RPDOs, {self.frames_rx} frames in, {self.frames_tx} out, "
                f"{self.send_errors} send errors, {self.frames_ignored} ignored, "
                f"{self.tpdos_discarded} TPDOs discarded (past their SYNC's window)")

    def lines(self) -> list[str]:
        """The summary: :meth:`line`, then the timing (reaction = SYNC in to TPDOs out)."""
        return [self.line()] + (self.timing.lines("sim-serve") if self.timing is not None else [])

    def as_json(self) -> dict:
        out = {k: getattr(self, k) for k in self.__slots__ if k != "timing"}
        out["timing"] = self.timing.as_json() if self.timing is not None else None
        return out


class _PythonCanIO:
    """Frames through the python-can API (any interface)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.ignored = 0

    def recv(self, timeout: float) -> tuple[Frame | None, float | None]:
        """One classic data frame (None after ``timeout`` [s] or for an ignored message) and its
        receive stamp (python-can's: wall-clock on udp_multicast and virtual, the interface's own
        elsewhere; :func:`serve` uses it only when it lies within the last second)."""
        msg = self.bus.recv(timeout)
        if msg is None:
            return None, None
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.dlc > 8:
            self.ignored += 1
            return None, None
        return Frame.trusted(msg.arbitration_id, bytes(msg.data)), msg.timestamp

    def send(self, f: Frame) -> bool:
        try:
            self.bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False,
                                      check=False), timeout=0.01)
            return True
        except can.CanError:
            return False


class _RawIO:
    """Frames on a SocketCAN socket through :class:`hil.transport.SocketcanFrames`."""

    def __init__(self, raw: SocketcanFrames) -> None:
        self.raw = raw

    @property
    def ignored(self) -> int:
        return self.raw.ignored

    def recv(self, timeout: float) -> tuple[Frame | None, float | None]:
        """A frame and the kernel's receive stamp (CLOCK_REALTIME [s], SO_TIMESTAMPNS) or None."""
        _, f, stamp = self.raw.recv_stamped(timeout)
        return f, stamp

    def send(self, f: Frame) -> bool:
        try:
            self.raw.send(f)
            return True
        except can.CanError:  # ENOBUFS: transmit queue full
            return False


def simulated_rig(simrig, rig, faults=None, *, seed: int | None = None, record_truth: bool = False):
    """The simulated rig: the drive pair of ``rig`` on the plant of ``simrig``, with its faults.

    Parameters
    ----------
    simrig : hil.profile.load.SimRigProfile
        The simulated-rig profile: the plant's parameters, the seed, the serial numbers, ``[[faults]]``.
    rig : hil.profile.rig.Rig
        The planned rig the simulated nodes are built as (their PDOs, signal map and scalings, the EDS
        files they serve).
    faults : sequence of sim.faults.Fault, optional
        The faults to apply; default (None) the simulated-rig profile's ``[[faults]]``.
    seed : int, optional
        The seed; default the simulated-rig profile's. The plant's noise is drawn from
        ``numpy.random.default_rng(seed)``, the random frame losses of ``bus_errors`` from
        ``default_rng([seed, 7])``: the same rig, bit for bit, in process and served.
    record_truth : bool
        Record the plant's truth after every SYNC (:attr:`sim.faults.FaultInjector.truth`).

    Returns
    -------
    sim.faults.FaultInjector
        The pair inside its fault injector, with the sans-IO interface of the pair (``power_on``,
        ``on_frame``, ``tick``; without faults it passes every frame through unchanged).
    """
    import numpy as np

    from hil.canopen.od import load_eds
    from sim.drives import SimDrivePair
    from sim.faults import FaultInjector
    from sim.plant import RigPlant

    seed = simrig.seed if seed is None else seed
    faults = tuple(simrig.faults if faults is None else faults)
    pair = SimDrivePair(RigPlant(simrig.params, np.random.default_rng(seed)), rig.plan,
                        lambda name, node_id: load_eds(rig.eds_paths[name], node_id=node_id), serials=simrig.serials)
    return FaultInjector(pair, faults, rng=np.random.default_rng([seed, 7]), record_truth=record_truth)


def faults_text(faults) -> str:
    """The faults a simulated rig applies, for the console: ``no faults`` or e.g.
    ``2 fault(s): lvdt_sign (EMA 2), loadcell_scale 0.1 (EMA 1) from 3 s``."""
    import math

    if not faults:
        return "no faults"
    words = []
    for f in faults:
        value = f" {f.value:g}" if math.isfinite(f.value) else ""
        start = f" from {f.start_s:g} s" if f.start_s else ""
        words.append(f"{f.kind}{value} (EMA {f.ema}){start}")
    return f"{len(faults)} fault(s): " + ", ".join(words)


def _io_for(bus: can.BusABC):
    raw = SocketcanFrames.for_bus(bus)
    return _RawIO(raw) if raw is not None else _PythonCanIO(bus)


def serve(bus: can.BusABC, pair, *, stop: threading.Event | None = None,
          clock: Callable[[], float] = time.monotonic,
          on_stats: Callable[[ServeStats], None] | None = None,
          on_ready: Callable[[], None] | None = None,
          period_s: float | None = None) -> ServeStats:
    """Run the simulated drive pair on ``bus`` until ``stop`` is set.

    Parameters
    ----------
    bus : can.BusABC
        Any python-can bus; it is shut down when the loop ends. On SocketCAN
        the frames go through the bus's socket directly (about one system call
        per frame, see :class:`hil.transport.SocketcanFrames`).
    pair : sim.drives.SimDrivePair
        The two simulated drives (fresh or already powered).
    stop : threading.Event, optional
        Ends the loop when set (checked at least every :data:`RECV_SLICE_S`).
        None: serve until KeyboardInterrupt.
    clock : callable, optional
        Monotonic time [s]; the pair sees ``clock() - clock()_at_start``.
    on_stats : callable, optional
        Called with a :class:`ServeStats` every :data:`STATS_PERIOD_S` and once at the end.
    on_ready : callable, optional
        Called once after power-on (boot-up frames sent), before the first receive.
    period_s : float, optional
        The SYNC period [s]: given, the loop measures its timing per SYNC
        (:class:`hil.record.cycletiming.CycleTiming`: SYNC arrival to the TPDOs sent,
        the SYNC's handling, SYNC to SYNC) into :attr:`ServeStats.timing`.

    Returns
    -------
    ServeStats
        The counters at the end.

    Notes
    -----
    Each frame received at time :math:`t` [s] goes to ``pair.on_frame(frame, t)``
    and its replies are sent at once; ``pair.tick(t)`` runs when
    :data:`TICK_PERIOD_S` has passed since the last tick, so heartbeats
    leave within :data:`TICK_PERIOD_S` plus one receive of their due time.
    On SocketCAN (with the default clock) :math:`t` is the kernel's receive
    stamp of the frame (event time): after a stall of this process, the
    master's heartbeats still queued in the socket carry the time they came,
    so the drives' heartbeat consumer does not judge a live master lost.
    """
    stop = stop if stop is not None else threading.Event()
    io = _io_for(bus)
    t0 = clock()
    # CLOCK_REALTIME minus this clock: turns kernel receive stamps into the pair's time (default clock only)
    rt_minus_clock = time.time() - clock() if clock is time.monotonic else None
    rx = tx = send_errors = 0

    def send(frames: list[Frame]) -> None:
        nonlocal tx, send_errors
        for f in frames:
            if io.send(f):
                tx += 1
            else:
                send_errors += 1

    timing = CycleTiming(period_s) if period_s is not None else None
    window_s = SYNC_WINDOW_FRACTION * period_s if period_s is not None else float("inf")
    discarded = 0

    def snapshot() -> ServeStats:
        s = pair.stats
        return ServeStats(duration_s=clock() - t0, frames_rx=rx, frames_tx=tx, frames_ignored=io.ignored,
                          send_errors=send_errors, syncs=s.syncs, plant_steps=s.plant_steps,
                          tpdos_sent=s.tpdos_sent, rpdos_late=s.rpdos_late, heartbeats_sent=s.heartbeats_sent,
                          tpdos_discarded=discarded, timing=timing.summary() if timing is not None else None)

    try:
        send(pair.power_on(clock() - t0))
        if on_ready is not None:
            on_ready()
        t = clock() - t0
        next_tick = t + TICK_PERIOD_S
        next_stats = t + STATS_PERIOD_S
        while not stop.is_set():
            f, stamp = io.recv(RECV_SLICE_S)
            now = t = clock() - t0
            if stamp is not None and rt_minus_clock is not None:
                ts = stamp - rt_minus_clock - t0
                if now - 1.0 < ts < now:
                    t = ts  # event time (never later than now; a stamp of another base is not used)
            if f is not None:
                rx += 1
                if timing is not None and f.arbitration_id == SYNC_COB_ID:
                    timing.sync(t)
                    cpu = time.thread_time()
                    out = pair.on_frame(f, t)
                    if out and clock() - t0 - t > window_s:
                        # the synchronous window has passed (the next SYNC is out): these TPDOs would
                        # be taken for the next cycle's; discarded, as CiA 301 0x1007 has it
                        kept = [g for g in out if not 0x180 <= g.arbitration_id < 0x580]
                        discarded += len(out) - len(kept)
                        out = kept
                    if out:
                        send(out)
                    done = clock() - t0
                    timing.work(now, done, time.thread_time() - cpu)
                    if out:
                        timing.answered(done)
                else:
                    out = pair.on_frame(f, t)
                    if out:
                        send(out)
            if t >= next_tick:
                out = pair.tick(t)
                if out:
                    send(out)
                next_tick = t + TICK_PERIOD_S
                if on_stats is not None and t >= next_stats:
                    on_stats(snapshot())
                    next_stats = t + STATS_PERIOD_S
    finally:
        final = snapshot()
        bus.shutdown()
    if on_stats is not None:
        on_stats(final)
    return final
