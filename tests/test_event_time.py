"""Event time on a real bus: frames carry the kernel's receive time, not the time the master read them.

A master that has fallen behind (frames waiting in its socket) must judge its timeouts
(heartbeat consumer) at the time each frame arrived; and when it lags more than
``safety.max_stale_cycles`` SYNC periods behind the bus it must stop (stale data).
No SocketCAN needed: the socket is replaced by a queue of stamped frames.
"""

from __future__ import annotations

import time
from collections import deque

import can
import pytest

from hil.canopen.frame import Frame
from hil.master.core import HeartbeatLost
from hil.master.link import CanopenLink, StaleData
from hil.transport import BusTransport
from support.canopen_rig import make_master


class QueuedSocket:
    """Stands in for :class:`hil.transport.SocketcanFrames`: frames with CLOCK_REALTIME stamps."""

    def __init__(self) -> None:
        self.q: deque = deque()
        self.sent: list[Frame] = []

    def put(self, frame: Frame, realtime_s: float) -> None:
        self.q.append((frame, realtime_s))

    def recv_stamped(self, timeout: float):
        if not self.q:
            return False, None, None
        f, ts = self.q.popleft()
        return True, f, ts

    def send(self, f: Frame) -> None:
        self.sent.append(f)


@pytest.fixture
def transport():
    bus = can.Bus(interface="virtual", channel="emacheck-event-time")
    tr = BusTransport(bus, 0.002)
    tr._raw = QueuedSocket()
    tr._sync_started = float("-inf")  # SYNC was started long ago
    yield tr
    bus.shutdown()


def _realtime_of(tr: BusTransport, t_rel: float) -> float:
    return t_rel + tr._t0 + tr._rt_minus_mono


def test_backlog_frames_carry_their_arrival_time(transport):
    tr = transport
    now = time.monotonic() - tr._t0
    # a SYNC and two heartbeats that arrived 0.9, 0.5 and 0.1 s ago, all still queued
    for age, f in ((0.9, Frame(0x080, b"")), (0.5, Frame(0x701, b"\x05")), (0.1, Frame(0x701, b"\x05"))):
        tr._raw.put(f, _realtime_of(tr, now - age))
    times = []
    for _ in range(3):
        got = tr.receive(deadline=now + 1.0)
        assert len(got) == 1
        times.append(got[0][1])
        assert tr.now() == got[0][1]  # timeouts judged after this frame use its time
    assert times == pytest.approx([now - 0.9, now - 0.5, now - 0.1], abs=1e-6)
    # the lag is measured on the SYNC (the first frame of a cycle)
    assert tr.max_lag_s == pytest.approx(0.9, abs=0.05)
    # queue empty: the clock is the event time again, and no lag
    assert tr.receive(deadline=tr.now()) == []
    assert tr.lag_s == 0.0 and tr.now() >= now


def test_heartbeat_in_the_backlog_is_not_judged_lost(transport, actuation):
    """The consumer fires only if no heartbeat *arrived* within the timeout (1.5 periods)."""
    tr = transport
    m = make_master(actuation)
    hb = actuation.canopen.heartbeat_period_s
    from hil.master.core import Phase
    m.phase = Phase.CYCLIC
    now = time.monotonic() - tr._t0
    start = now - 4 * hb  # the consumer started 4 periods ago; heartbeats came every period
    for d in m.drives.values():
        d.last_heartbeat_s = start
        d.nmt_state = 0x05
    for k in range(1, 5):
        for n in m.drives:
            tr._raw.put(Frame(0x700 + n, b"\x05"), _realtime_of(tr, start + k * hb - 0.01))
    while True:
        got = tr.receive(deadline=tr.now())
        if not got:
            break
        for f, t, _msg in got:
            m.on_frame(f, t)
        m.poll(tr.now())  # judged at the frame's time: never more than one period since the last
    assert m.fault is None
    # the consumer holds each drive's last heartbeat at its arrival time, not at the time it was read
    # (0.01 s to 0.4 s later): its timeout runs from there, to the float
    last = start + 4 * hb - 0.01
    assert [d.last_heartbeat_s for d in m.drives.values()] == pytest.approx([last, last], abs=1e-6)
    limit = m.drives[1].hb_timeout_s - 0.5 * m.T
    m.poll(m.drives[1].last_heartbeat_s + limit)
    assert m.fault is None
    with pytest.raises(HeartbeatLost):
        m.poll(m.drives[1].last_heartbeat_s + limit + 1e-6)


def test_master_behind_the_bus_stops_with_stale_data(transport, actuation):
    tr = transport
    m = make_master(actuation)
    link = CanopenLink(m, tr, max_missing_cycles=5)
    assert link.max_lag_s == pytest.approx(5 * 0.002)
    now = time.monotonic() - tr._t0
    tr._raw.put(Frame(0x080, b""), _realtime_of(tr, now - 0.5))  # a SYNC that waited 0.5 s
    with pytest.raises(StaleData, match="behind the bus"):
        link._cycle(stop_at_sample=True)
    assert isinstance(m.fault, StaleData) and m.quick_stop
    # stopping after the fault is not interrupted by the lag: the safe-state cycle goes on
    tr._raw.put(Frame(0x080, b""), _realtime_of(tr, time.monotonic() - tr._t0 - 0.5))
    link._cycle(stop_at_sample=False)
