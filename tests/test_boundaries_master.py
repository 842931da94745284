"""The master's own timeouts and its heartbeat consumer, pinned at their boundaries.

Each rule on its limit and one float step either side (tests/support/boundary.py), asserting which
side trips:

* boot-up after NMT reset (hil/master/core.py: ``t > start + canopen.boot_timeout_s`` fails the preflight);
* the SDO response (hil/canopen/sdo.py: ``t - sent >= canopen.sdo_timeout_s`` is a timeout: the limit
  itself trips);
* the heartbeat consumer in the cyclic phase (``t - last > timeout - T/2``: polled once per SYNC, it
  reacts no later than the timeout on the SYNC grid);
* the master's own heartbeat producer (due at its period, within 1 ns);
* the link (hil/master/link.py): CiA 402 power-up within ``canopen.enable_timeout_s``, the master's lag
  behind the bus (``lag > safety.max_lag_s``, capped at 0.5 s) and its count of cycles without a
  complete sample (``missing > max_stale_cycles``).

The link's tests run over a scripted transport (exact dyadic times: a SYNC period of 2**-9 s), the
drives' TPDOs written as raw CiA 301 frames (COB-IDs 0x180/0x280 + node), so they hold whatever the
PDO layer's internals look like.
"""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np
import pytest

from hil.canopen.frame import Frame
from hil.canopen.sdo import SdoTimeout
from hil.master.core import HeartbeatLost, MasterCore, Phase, PreflightError
from hil.master.link import CanopenLink, StaleData
from sim.plant import RigPlant
from support.boundary import around
from support.canopen_rig import cyclic_master, make_master

SW_SOD, SW_OE = 0x0250, 0x0237  # statuswords: switch on disabled, operation enabled


def _replace_canopen(act, **kw):
    return dataclasses.replace(act, canopen=dataclasses.replace(act.canopen, **kw))


# ---------------------------------------------------------------------------- boot-up


@pytest.mark.parametrize("t0", [0.0, 0.75])
def test_boot_timeout_on_its_limit_and_one_step_after(actuation, t0):
    limit = actuation.canopen.boot_timeout_s
    assert limit == 2.0
    below, at, above = around(lambda t: t, t0 + limit, t0 + limit)
    for t in (below, at):
        m = make_master(actuation)
        m.start(t0)
        m.poll(t)
        assert m.fault is None and m.phase is Phase.PREFLIGHT, t
    m = make_master(actuation)
    m.start(t0)
    with pytest.raises(PreflightError, match=r"^node 1 \(EMA 1\), node 2 \(EMA 2\): no boot-up within "
                                             r"canopen.boot_timeout_s = 2.0 s of NMT reset$"):
        m.poll(above)
    assert isinstance(m.fault, PreflightError) and m.quick_stop


def test_boot_timeout_names_only_the_drive_that_did_not_boot(actuation):
    m = make_master(actuation)
    m.start(0.0)
    assert m.on_frame(Frame(0x702, b"\x00"), 1.999) == []
    m.poll(2.0)
    with pytest.raises(PreflightError, match=r"^node 1 \(EMA 1\): no boot-up"):
        m.poll(math.nextafter(2.0, 3.0))


def test_boot_timeout_applies_only_while_waiting_for_boot_up(actuation):
    m = make_master(actuation)
    m.start(0.0)
    out = m.on_frame(Frame(0x701, b"\x00"), 1.9) + m.on_frame(Frame(0x702, b"\x00"), 1.9)
    assert out and out[0].arbitration_id == 0x601  # the first SDO request
    m.poll(2.1)  # past the boot deadline, within the SDO timeout of the request sent at 1.9
    assert m.fault is None


# ---------------------------------------------------------------------------- SDO response


@pytest.mark.parametrize("t_boot", [0.0, 0.5, 1.25])
def test_sdo_timeout_trips_on_its_limit_not_one_step_before(actuation, t_boot):
    """SdoClient.poll: ``t - sent >= timeout`` (0.5 s): on the limit it is a timeout."""
    limit = actuation.canopen.sdo_timeout_s
    assert limit == 0.5
    below, at, above = around(lambda t: t - t_boot, limit, t_boot + limit)
    for t, trips in ((below, False), (at, True), (above, True)):
        m = make_master(actuation)
        m.start(0.0)
        m.on_frame(Frame(0x701, b"\x00"), t_boot)
        m.on_frame(Frame(0x702, b"\x00"), t_boot)  # the first SDO request goes out now
        if trips:
            with pytest.raises(SdoTimeout) as exc:
                m.poll(t)
            assert exc.value.timeout_s == limit and exc.value.node_id == 1
            assert exc.value.abort_frame.data[:4] == bytes([0x80, 0x18, 0x10, 0x01])  # abort 0x1018:01
            assert exc.value.abort_frame.data[4:] == (0x05040000).to_bytes(4, "little")  # SDO protocol timed out
            assert isinstance(m.fault, SdoTimeout)
        else:
            m.poll(t)
            assert m.fault is None, t


# ---------------------------------------------------------------------------- heartbeat consumer


def _through_preflight(act, simrig) -> MasterCore:
    """A master through its preflight against the simulated drives, every frame at t = 0 (the
    consumer starts then), in the cyclic phase (:func:`support.canopen_rig.cyclic_master`)."""
    m = cyclic_master(act, RigPlant(simrig.params, np.random.default_rng(1)))
    assert [d.last_heartbeat_s for d in m.drives.values()] == [0.0, 0.0]
    return m


@pytest.fixture(scope="module")
def cyclic(simrig, actuation):
    """A factory of fresh masters in the cyclic phase (:func:`_through_preflight`)."""
    return lambda: _through_preflight(actuation, simrig)


def _consumer_limit(m: MasterCore) -> float:
    return m.drives[1].hb_timeout_s - 0.5 * m.T  # the master's own operations


def test_heartbeat_consumer_limit_is_the_timeout_less_half_a_sync_period(actuation, cyclic):
    m = cyclic()
    c = actuation.canopen
    assert m.drives[1].hb_timeout_s == c.heartbeat_period_s * c.heartbeat_timeout_factor
    assert _consumer_limit(m) == pytest.approx(0.149, abs=1e-15)


def test_heartbeat_consumer_on_its_limit_and_one_step_after(cyclic):
    limit = _consumer_limit(cyclic())
    below, at, above = around(lambda t: t - 0.0, limit, limit)
    for t in (below, at):
        m = cyclic()
        m.poll(t)
        assert m.fault is None and not any(d.lost for d in m.drives.values()), t
    m = cyclic()
    with pytest.raises(HeartbeatLost, match=r"^node 1 \(EMA 1\): heartbeat lost \(none for 0.149 s, "
                                            r"timeout 0.150 s\)$"):
        m.poll(above)
    assert m.drives[1].lost and not m.drives[2].lost and isinstance(m.fault, HeartbeatLost)


@pytest.mark.parametrize("late", [1, 2])
def test_heartbeat_consumer_per_drive_from_its_last_heartbeat(cyclic, late):
    """The other drive's heartbeat at 0.1 s keeps it alive; the late one trips one step past 0.149 s."""
    m = cyclic()
    other = 3 - late
    m.on_frame(Frame(0x700 + other, b"\x05"), 0.1)
    limit = _consumer_limit(m)
    _, at, above = around(lambda t: t - 0.0, limit, limit)
    m.poll(at)
    assert m.fault is None
    with pytest.raises(HeartbeatLost, match=rf"^node {late} \(EMA {late}\): heartbeat lost"):
        m.poll(above)
    assert m.drives[late].lost and not m.drives[other].lost


def test_heartbeat_consumer_restarts_at_each_heartbeat(cyclic):
    m = cyclic()
    limit = _consumer_limit(m)
    t = 0.0
    for _ in range(20):  # heartbeats every 0.148 s: never lost
        t += 0.148
        m.poll(t)
        for n in (1, 2):
            m.on_frame(Frame(0x700 + n, b"\x05"), t)
    assert m.fault is None
    with pytest.raises(HeartbeatLost):
        m.poll(t + limit + 1e-9)


@pytest.mark.parametrize("gap_s", [0.06, 0.0])
def test_heartbeat_lost_carries_the_longest_silence_of_the_nodes_statuswords(simrig, actuation, gap_s):
    """A drive's process held ``gap_s`` (no statusword either), then run again: its TPDOs answer SYNCs before its
    heartbeat is judged lost, so the node's silence is the longest gap between its statuswords since its last
    heartbeat, not only the time since the last one (hil.master.stalls.process_held)."""
    from support.canopen_rig import make_pair

    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(1)))
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen,
                                                                     skip_master_loss_drill="not this test's"))
    m = make_master(act)
    to_slaves, to_master = list(m.start(0.0)), list(pair.power_on(0.0))
    while to_slaves or to_master:  # the preflight, every frame at t = 0 (as support.canopen_rig.cyclic_master)
        while to_slaves:
            to_master += pair.on_frame(to_slaves.pop(0), 0.0)
        while to_master:
            to_slaves += m.on_frame(to_master.pop(0), 0.0)
    assert m.phase is Phase.CYCLIC
    T = m.T
    with pytest.raises(HeartbeatLost) as exc:
        for k in range(1, 200):
            t = k * T
            for f in pair.on_frame(Frame(0x80, b""), t):
                held = f.arbitration_id & 0x7F == 1 and 0.02 < t <= 0.02 + gap_s
                if 0x180 <= f.arbitration_id < 0x580 and not held:
                    m.on_frame(f, t)  # TPDOs only: no heartbeat arrives
            m.poll(t)
    lost = exc.value
    assert lost.key == "canopen.heartbeat_period_s" and lost.overdue_s == pytest.approx(0.05)
    if gap_s:  # the statuswords of node 1 stopped from 0.022 s to 0.08 s (the first after the gap at 0.082 s)
        assert lost.frames_silent_s == pytest.approx(0.06 + T, abs=1e-9)
    else:
        assert lost.frames_silent_s == pytest.approx(T, abs=1e-9)


# ---------------------------------------------------------------------------- the master's heartbeat producer


def test_master_heartbeat_is_due_on_its_period_within_a_nanosecond(actuation):
    m = make_master(actuation)
    hb = Frame(0x77F, b"\x05")
    assert hb in m.start(0.0) or m.poll(0.0) == [hb]  # the first with the start
    period = actuation.canopen.master_heartbeat_period_s
    assert period == 0.05
    due = 0.0 + period
    early = math.nextafter(due - 1e-9, 0.0)
    assert m.poll(early) == []
    assert m.poll(due - 1e-9) == [hb]  # within 1 ns of its time
    assert m.poll(due) == []  # once per period
    assert m.poll(2 * period) == [hb]


# ---------------------------------------------------------------------------- the link: a scripted bus


T_EXACT = 2.0 ** -9  # a SYNC period whose multiples are exact in floats [s]


class ScriptedBus:
    """A transport whose clock advances exactly one SYNC period per SYNC, both drives answering each
    SYNC with TPDO1 (the scripted statusword) and TPDO2, unless ``silent`` says that cycle is lost."""

    def __init__(self, T: float, statusword=lambda k: SW_OE, silent=lambda k: False, lag=lambda k: 0.0) -> None:
        self.T = T
        self.t = 0.0
        self.k = 0
        self.statusword, self.silent, self.lag = statusword, silent, lag
        self.lag_s = 0.0
        self.sent: list[Frame] = []
        self._queue: list[Frame] = []

    def now(self) -> float:
        return self.t

    def send(self, frames, t):
        self.sent += frames
        return []

    def start_sync(self) -> None:
        pass

    def stop_sync(self) -> None:
        pass

    def next_sync(self) -> float:
        self.k += 1
        self.t += self.T
        self.lag_s = self.lag(self.k)
        if not self.silent(self.k):
            sw = self.statusword(self.k)
            for n in (1, 2):
                self._queue.append(Frame(0x180 + n, struct.pack("<Hib", sw, 0, 8)))
                self._queue.append(Frame(0x280 + n, struct.pack("<ii", 0, 0)))
        return self.t

    def receive(self, deadline: float):
        got, self._queue = [(f, self.t, None) for f in self._queue], []
        return got


def _link(actuation, simrig, bus: ScriptedBus, **kw) -> CanopenLink:
    m = _through_preflight(actuation, simrig)  # (its frames went to the simulated pair; here: what follows)
    link = CanopenLink(m, bus, **kw)
    link.preflight = lambda: None
    return link


@pytest.mark.parametrize("k_on", [3, 10, 37])
def test_enable_timeout_on_its_limit_and_one_step_short(actuation, simrig, k_on):
    """The drives report Operation enabled from SYNC ``k_on``: the deadline (the first sample's time
    T + the timeout) must not have passed at the SYNC before, ``(k_on - 1) T``; so a timeout whose
    deadline is exactly that lets them in, one step shorter fails naming canopen.enable_timeout_s and
    the drives' states."""
    T = T_EXACT
    short, need, longer = around(lambda e: T + e, (k_on - 1) * T, (k_on - 2) * T)  # the link's deadline
    for timeout, ok in ((need, True), (longer, True), (short, False)):
        act = dataclasses.replace(_replace_canopen(actuation, enable_timeout_s=timeout),
                                  timing=dataclasses.replace(actuation.timing, sync_period_s=T))
        bus = ScriptedBus(T, statusword=lambda k: SW_OE if k >= k_on else SW_SOD)
        link = _link(act, simrig, bus)
        if ok:
            smp = link.first_sample()
            assert bus.k == k_on and smp.t_s == k_on * T and link.m.all_in(link.m.drives[1].state)
        else:
            with pytest.raises(PreflightError, match=rf"^drives not in OPERATION_ENABLED within "
                                                     rf"canopen.enable_timeout_s = {timeout} s: "
                                                     r"\{1: 'SWITCH_ON_DISABLED', 2: 'SWITCH_ON_DISABLED'\}$"):
                link.first_sample()
            assert bus.k == k_on - 1


@pytest.mark.parametrize("max_lag_s, expected", [(0.02, 0.02), (None, 5 * T_EXACT), (3.0, 0.5)])
def test_master_lag_on_its_limit_and_one_step_beyond(actuation, simrig, max_lag_s, expected):
    """lag > safety.max_lag_s stops with StaleData (default: max_missing_cycles periods; capped at 0.5 s)."""
    for lag, trips in ((math.nextafter(expected, 0.0), False), (expected, False),
                       (math.nextafter(expected, 1.0), True)):
        bus = ScriptedBus(T_EXACT, lag=lambda k, lag=lag: lag)
        link = _link(actuation, simrig, bus, max_missing_cycles=5, max_lag_s=max_lag_s)
        assert link.max_lag_s == expected
        if trips:
            with pytest.raises(StaleData, match=r"^sensor data stale: the master is [\d.]+ ms behind the bus"):
                link._next_sample()
            assert isinstance(link.m.fault, StaleData) and link.m.quick_stop
        else:
            assert link._next_sample().t_s == link.m.T  # the first cycle's sample
            assert link.m.fault is None


@pytest.mark.parametrize("max_missing", [1, 2, 5])
def test_cycles_without_a_complete_sample_on_the_limit_and_one_more(actuation, simrig, max_missing):
    """``max_missing_cycles`` SYNC cycles in a row without a sample are tolerated; one more is stale."""
    for lost, trips in ((max_missing - 1, False), (max_missing, False), (max_missing + 1, True)):
        bus = ScriptedBus(T_EXACT, silent=lambda k, lost=lost: k <= lost)
        link = _link(actuation, simrig, bus, max_missing_cycles=max_missing)
        if trips:
            with pytest.raises(StaleData, match=rf"^sensor data stale: no complete sample for {max_missing + 1} "
                                                rf"SYNC cycles \(safety.max_stale_cycles = {max_missing}\)"):
                link._next_sample()
            assert bus.k == max_missing + 1 and isinstance(link.m.fault, StaleData)
        else:
            smp = link._next_sample()
            assert bus.k == lost + 1 and smp is not None and link.m.fault is None
