"""The simulated drive's heartbeat consumer and producer pinned at their boundaries (sim/drives/nmt_slave.py).

Consumer (0x1016): a heartbeat event is the first tick at which *more than* the consumer time (plus
the 1 ns time tolerance of the drive) has passed since the producer's last heartbeat: on that limit
no event, one float step after it the event (EMCY 0x8130, ``heartbeat_events``). Producer (0x1017):
the heartbeat is due at each multiple of its time, within the same 1 ns. Driven through the pair's
public frames and ticks only (power on, an SDO download of 0x1016:01, heartbeat frames, ticks).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hil.canopen.frame import Frame
from hil.canopen.sdo import SdoClient, SdoEvent
from sim.drives import SimDrivePair
from sim.plant import RigPlant
from support.boundary import around
from support.canopen_rig import make_pair
from support.rigs import brief_rig, quiet

MASTER = 0x7F
EPS_S = 1e-9  #: the drive's time tolerance (sim.drives.nmt_slave.TIME_EPS_S), as documented there
HB_EMCY = bytes.fromhex("3081")  # EMCY error code 0x8130: heartbeat error


def _pair() -> SimDrivePair:
    pair = make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(0)))
    pair.power_on(0.0)
    return pair


def _sdo_write(pair: SimDrivePair, node: int, index: int, sub: int, data: bytes, t: float = 0.0) -> None:
    client = SdoClient(node)
    req = client.start_download(index, sub, data, t)
    for _ in range(8):
        (reply,) = [f for f in pair.on_frame(req, t) if f.arbitration_id == 0x580 + node]
        res = client.on_frame(reply, t)
        if isinstance(res, SdoEvent):
            return
        req = res
    raise AssertionError("SDO download did not finish")


def _watching(consumer_ms: int, node: int = 1) -> SimDrivePair:
    pair = _pair()
    _sdo_write(pair, node, 0x1016, 1, struct.pack("<I", MASTER << 16 | consumer_ms))
    return pair


def _events(frames: list[Frame], node: int) -> list[Frame]:
    return [f for f in frames if f.arbitration_id == 0x080 + node and f.data[:2] == HB_EMCY]


@pytest.mark.parametrize("consumer_ms, t_hb", [(125, 0.0), (50, 0.0), (1000, 0.0), (1000, 0.5)])
def test_consumer_event_one_step_after_its_time_not_on_it(consumer_ms, t_hb):
    limit = consumer_ms / 1000.0 + EPS_S
    below, at, above = around(lambda t: t - t_hb, limit, t_hb + limit)
    pair = _watching(consumer_ms)
    node = pair.nodes[0]
    assert pair.on_frame(Frame(0x700 + MASTER, b"\x05"), t_hb) == []  # its last heartbeat: monitoring starts
    for t in (below, at):
        assert _events(pair.tick(t), 1) == [] and node.heartbeat_events == [], t
    out = pair.tick(above)
    assert len(_events(out, 1)) == 1 and node.heartbeat_events == [(above, MASTER)]
    assert _events(out, 2) == [] and pair.nodes[1].heartbeat_events == []  # node 2 does not consume it
    assert _events(pair.tick(above + 1.0), 1) == []  # one event until the producer is back


def test_consumer_monitors_only_after_the_first_heartbeat_and_restarts_at_each():
    pair = _watching(125)
    node = pair.nodes[0]
    assert _events(pair.tick(5.0), 1) == [] and node.heartbeat_events == []  # never heard: not monitored
    t = 5.0
    for _ in range(10):  # a heartbeat every 125 ms (on the limit): never an event
        pair.on_frame(Frame(0x77F, b"\x05"), t)
        t += 0.125
        assert _events(pair.tick(t), 1) == []
    assert node.heartbeat_events == []
    pair.on_frame(Frame(0x77F, b"\x05"), t)
    assert _events(pair.tick(t + 0.125 + 2 * EPS_S), 1) and node.heartbeat_events == [(t + 0.125 + 2 * EPS_S, MASTER)]


def test_the_producer_comes_back_the_event_ends_and_the_consumer_rearms():
    pair = _watching(100)
    pair.on_frame(Frame(0x77F, b"\x05"), 0.0)
    assert _events(pair.tick(0.2), 1)
    pair.on_frame(Frame(0x77F, b"\x05"), 0.3)  # back: the event ends (the drive stays where 0x6007 sent it)
    assert _events(pair.tick(0.4), 1) == []  # 100 ms exactly: no event
    assert _events(pair.tick(0.4 + 2 * EPS_S), 1)  # just beyond it: the second event
    assert [t for t, _ in pair.nodes[0].heartbeat_events] == [0.2, 0.4 + 2 * EPS_S]


def test_heartbeat_producer_due_on_each_multiple_of_its_time_within_1ns():
    """0x1017 = 100 ms written at 0: due at 0.1 s, sent at a tick 1 ns before it, not at the tick one
    float step earlier than that."""
    pair = _pair()
    _sdo_write(pair, 1, 0x1017, 0, struct.pack("<H", 100))
    _sdo_write(pair, 2, 0x1017, 0, struct.pack("<H", 100))
    hb = [Frame(0x701, b"\x7f"), Frame(0x702, b"\x7f")]  # pre-operational
    due = 0.1
    early = due - EPS_S
    assert pair.tick(np.nextafter(early, 0.0)) == []
    assert pair.tick(early) == hb
    assert pair.tick(due) == []  # one per period
    assert pair.tick(0.2 - EPS_S) == hb
