"""The loop-timed SYNC of hil.transport.BusTransport (interfaces without a kernel- or hardware-timed
periodic send): its schedule keeps its phase, late periods are skipped and counted."""

from __future__ import annotations

import can
import pytest

from hil.transport import BusTransport

# a 0.5 s wall-clock wait for frames: one such test at a time (docs/testing.md, "Parallel")
pytestmark = pytest.mark.xdist_group("wall_clock")


def test_loop_sync_schedule_keeps_phase_and_counts_skipped_periods():
    bus = can.Bus(interface="virtual", channel="emacheck-loop-sync", receive_own_messages=True)
    try:
        tr = BusTransport(bus, 0.002)
        assert tr.loop_sync  # virtual: python-can's periodic send would be a thread in this process
        now = [0.0]
        tr.clock = lambda: now[0]
        tr.start_sync()
        assert tr.sync_due() == 0.0
        sent = []
        for t in (0.0001, 0.0021, 0.0071, 0.0095, 0.0105):
            now[0] = t
            sent.append((tr.send_sync(), tr.sync_due()))
        # on time: next due one period on; the 4 ms SYNC sent 3.1 ms late is the 8 ms slot's (the nearest):
        # the 4 and 6 ms slots skipped, next at 10 ms
        assert sent == [(0.0001, 0.002), (0.0021, 0.004), (0.0071, pytest.approx(0.010)),
                        (0.0095, pytest.approx(0.012)), (0.0105, pytest.approx(0.014))]
        assert tr.sync_skipped == 2 and tr.sync_late_max_s == pytest.approx(0.0031)
        assert [m.arbitration_id for m in iter(lambda: bus.recv(0.1), None)] == [0x080] * 5
        tr.stop_sync()
        assert tr.sync_due() is None
    finally:
        bus.shutdown()


def test_sim_serve_discards_tpdos_past_their_syncs_window():
    """hil.sim_server.serve: a SYNC whose TPDOs are ready only after the synchronous window (0.9 T:
    this process was held up) gets none sent, so that the master cannot take them for the next
    cycle's; in time, the four TPDOs go out."""
    import threading
    import time

    import numpy as np

    from hil.profile.load import load_simrig
    from hil.sim_server import serve
    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    pair = make_pair(RigPlant(load_simrig().params, np.random.default_rng(1)))
    channel = "emacheck-test-window"
    master = can.Bus(interface="virtual", channel=channel)
    slow = [0.0]  # added to the clock at every reading once set: the SYNC's handling "takes" that long
    now = [0.0]

    def clock() -> float:
        # the test's own time, 1 us per reading: how long this machine takes to handle a SYNC (a loaded
        # CI host took over 1.8 ms for one "in time") does not decide the answer
        now[0] += 1e-6 + slow[0]
        return now[0]

    stop, ready, out = threading.Event(), threading.Event(), {}
    th = threading.Thread(target=lambda: out.update(stats=serve(
        can.Bus(interface="virtual", channel=channel), pair, stop=stop, on_ready=ready.set, clock=clock,
        period_s=0.002)))
    th.start()
    tpdo = (0x181, 0x182, 0x281, 0x282)
    try:
        assert ready.wait(10)
        master.send(can.Message(arbitration_id=0x000, data=[0x01, 0], is_extended_id=False))  # NMT start
        got = []
        for s in (0.0, 0.0025, 0.0):  # in time, 2.5 ms per SYNC handled (over 1.8 ms), in time
            slow[0] = s
            master.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            ids, t_end = [], time.monotonic() + 0.5
            while time.monotonic() < t_end and len([i for i in ids if i in tpdo]) < 4:
                m = master.recv(0.05)
                if m is not None:
                    ids.append(m.arbitration_id)
            got.append(len([i for i in ids if i in tpdo]))
            slow[0] = 0.0
    finally:
        stop.set()
        th.join(10)
        master.shutdown()
    st = out["stats"]
    assert got == [4, 0, 4] and st.tpdos_discarded == 4 and st.syncs == 3
    assert st.timing.reaction.n == 2 and st.timing.cycles == 3
