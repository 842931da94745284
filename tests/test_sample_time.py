"""Timing told from physics (issue "Holds the shipped 500 Hz"): a sample carries the time of the SYNC
period it answers, not the count of SYNCs seen, so periods without a SYNC (its producer, or the master's
own loop, was late) are neither read as speed nor lost for freshness.

In process, over the dry-run's transport with a SYNC producer that is late once by ``extra`` periods:
the master, the simulated pair (its drives' own cycle over the gap), the check sequence (its profile
held, not leaping ahead) and the supervisor (speed and freshness on the samples' own times).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hil.canopen.frame import Frame, sync_frame
from hil.check.sequence import CheckSequence, Step
from hil.check.supervisor import Supervisor
from hil.master.core import MasterCore
from hil.master.link import CanopenLink
from hil.transport import InProcessTransport
from sim.plant import RigPlant
from support.canopen_rig import make_pair, shipped_rig

STALL_AT = 1400  #: the SYNC (counted from the first) that comes late: 0.28 s into the LVDT 1 sweep at 2 mm/s


class LateSyncTransport(InProcessTransport):
    """The dry-run's transport whose SYNC number ``stall_at`` comes ``extra`` periods late."""

    def __init__(self, pair, T: float, stall_at: int, extra: int) -> None:
        super().__init__(pair, T)
        self.n, self.stall_at, self.extra = 0, stall_at, extra

    def next_sync(self) -> float | None:
        if self._sync_on:
            self.n += 1
            if self.n == self.stall_at:
                self.t += self.extra * self.T
        return super().next_sync()


def _run(actuation, check, simrig, extra: int, cycles: int = STALL_AT + 60):
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(1)))
    tr = LateSyncTransport(pair, actuation.timing.sync_period_s, STALL_AT, extra)
    m = MasterCore(actuation, shipped_rig().plan,
                   forces=(check.calibration.opposing_force_N, check.safety.max_force_N))
    link = CanopenLink(m, tr, max_missing_cycles=check.safety.max_stale_cycles, max_lag_s=check.safety.max_lag_s)
    seq, sup = CheckSequence(actuation, check), Supervisor(actuation, check)
    try:
        samples, violation = _loop(link, seq, sup, cycles)
    finally:
        tr.close()
    return m, pair, seq, samples, violation


def _loop(link, seq, sup, cycles: int, each=None):
    """The check loop in process: ``cycles`` samples through the sequence and the supervisor (``each``
    called with every sample first); returns the samples and the first violation (None)."""
    samples, violation = [], None
    smp = link.first_sample()
    sp = (None, None)
    for _ in range(cycles):
        samples.append(smp)
        if each is not None:
            each(smp)
        if sp[0] is not None:
            violation = sup.check(smp, *sp)
            if violation is not None:
                break
        out = seq.step(smp)
        sp = (out.sp1, out.sp2)
        smp = link.exchange(*sp)
    return samples, violation


def _speeds_mm_per_s(samples, i_rad_per_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample intervals [s] and both rams' speeds [mm/s] from motor angles, shape (n - 1, 2)."""
    t = np.array([s.t_s for s in samples])
    phi = np.array([[s.phi1_rad, s.phi2_rad] for s in samples])
    return np.diff(t), np.abs(np.diff(phi, axis=0)) / i_rad_per_mm / np.diff(t)[:, None]


@pytest.fixture(scope="module")
def on_time(actuation, check_profile, simrig):
    """The same cycles with every SYNC on time: the speeds [mm/s] the rig really had, per EMA."""
    *_, samples, violation = _run(actuation, check_profile, simrig, 0)
    assert violation is None
    return _speeds_mm_per_s(samples, actuation.mechanics.i_total_rad_per_mm)[1]


@pytest.mark.parametrize("extra", [1, 2])
def test_a_late_sync_gives_its_sample_the_periods_time_and_no_speed(actuation, check_profile, simrig, extra,
                                                                    on_time):
    m, pair, seq, samples, violation = _run(actuation, check_profile, simrig, extra)
    T = actuation.timing.sync_period_s
    dt = np.diff([s.t_s for s in samples])
    v = _speeds_mm_per_s(samples, actuation.mechanics.i_total_rad_per_mm)[1]
    gap = int(np.argmax(dt))
    assert violation is None and seq.step_now is Step.CAL1_SWEEP
    # the sample after the late SYNC is (1 + extra) periods after the one before; every other one period
    assert dt[gap] == pytest.approx((1 + extra) * T, abs=1e-9)
    assert np.delete(dt, gap) == pytest.approx(T, abs=1e-9)
    assert m.sync_schedule.skipped == extra
    # the simulated drives ran their own cycle over the gap (on the last setpoints): the rig did not wait
    assert pair.stats.free_steps == extra
    # no speed above what the rig had with every SYNC on time: over the gap (read over its own time;
    # over one period it would read 1 + extra times that) and after it (the sequence's profile resumed
    # where it stood instead of leaping ahead by the periods missed; the drive that ran on to its last
    # target over the gap is slower for a cycle, not faster)
    window = slice(gap, gap + 20)
    assert v[gap].max() <= on_time[gap].max() + 0.2
    assert v[gap].max() * (1 + extra) > on_time[gap].max() + 1.0
    assert v[window].max() < 1.1 * on_time[window].max()


def test_sync_periods_missed_count_for_freshness_on_the_limit_and_one_beyond(actuation, check_profile, simrig):
    check = check_profile
    lim = check.safety.max_stale_cycles
    *_, ok = _run(actuation, check, simrig, lim, cycles=STALL_AT + 5)
    assert ok is None
    *_, samples, violation = _run(actuation, check, simrig, lim + 1, cycles=STALL_AT + 5)
    assert violation is not None and violation.limit == "max_stale_cycles"
    assert violation.value == lim + 1 and violation.t_s == samples[-1].t_s


def test_the_loop_timed_sync_takes_the_nearest_slot_on_its_boundary():
    """BusTransport.send_sync: a SYNC that leaves up to half a period after its due time is its slot's;
    one that leaves later is the next slot's (the sample answering it carries that slot's time)."""
    import can

    from hil.transport import BusTransport

    bus = can.Bus(interface="virtual", channel="emacheck-sync-slot")
    try:
        tr = BusTransport(bus, 0.002)
        now = [0.0]
        tr.clock = lambda: now[0]
        tr.start_sync()
        got = []
        for late in (0.001, 0.001 + 1e-9, 0.0):  # T/2 late: its own slot; a nanosecond more: the next
            now[0] = tr.sync_due() + late
            tr.send_sync()
            got.append((tr.sync_slot_s, tr.sync_due(), tr.sync_skipped))
        assert got == [(0.0, 0.002, 0), (pytest.approx(0.004), pytest.approx(0.006), 1),
                       (pytest.approx(0.006), pytest.approx(0.008), 1)]
    finally:
        bus.shutdown()


@pytest.mark.parametrize("extra", [1, 2])
def test_the_sequence_holds_its_profile_over_periods_without_a_sample(actuation, check_profile, simrig, extra):
    """CheckSequence: the same samples, from the late one on each ``extra`` periods later, give the same
    setpoints (the profile waits) where a profile on the clock would lead by ``extra`` periods."""
    *_, samples, _ = _run(actuation, check_profile, simrig, 0)
    T = actuation.timing.sync_period_s
    k = len(samples) - 40
    late = samples[:k] + [replace(s, t_s=s.t_s + extra * T) for s in samples[k:]]
    a, b = CheckSequence(actuation, check_profile), CheckSequence(actuation, check_profile)
    out_a = [a.step(s) for s in samples]
    out_b = [b.step(s) for s in late]
    assert a.step_now is b.step_now is Step.CAL1_SWEEP
    # (equal to rounding: t - t0 - held is not bit for bit t - t0 a few periods on)
    assert [(o.sp1.mode, o.sp2.mode) for o in out_b] == [(o.sp1.mode, o.sp2.mode) for o in out_a]
    assert np.array([(o.sp1.value, o.sp2.value) for o in out_b]) == \
        pytest.approx(np.array([(o.sp1.value, o.sp2.value) for o in out_a]), rel=0, abs=1e-12)
    assert out_a[k].sp1 != out_a[k - 1].sp1  # (the sweep moves: a lead would show)


def test_the_link_gives_the_master_a_sync_at_its_slot_not_when_it_was_read():
    """CanopenLink: a loop-timed SYNC read back from the bus reaches the master with its slot's time
    (:attr:`hil.transport.BusTransport.sync_slot_s`), whatever the time it is read at."""
    from hil.canopen.frame import sync_frame

    class Transport:
        T, sync_slot_s = 0.002, 0.004

        def now(self) -> float:
            return 0.0057  # read late

        def sync_due(self) -> float:
            return 0.006

    class Master:
        got: list = []

        def on_frame(self, f, t):
            self.got.append((f.arbitration_id, t))
            return []

        def drain_events(self):
            return []

    link = CanopenLink(Master(), Transport())
    f = sync_frame()
    link._feed([(f, 0.0049, None), (Frame(0x181, b"\0" * 8), 0.0052, None)])
    assert link.m.got == [(0x080, 0.004), (0x181, 0.0057)]


def test_sync_schedule_takes_the_nearest_period_on_its_boundary():
    """hil.canopen.cycle.SyncSchedule: the periods since the last SYNC are the nearest whole number, at
    least one (a SYNC up to T/2 late is its period's; an early one is never the last one's again)."""
    from hil.canopen.cycle import SyncSchedule

    T = 0.002
    s = SyncSchedule(T)
    t, got = 10.0, []
    for gap in (0.0, 1.2 * T, 1.5 * T - 1e-9, 1.5 * T + 1e-9, 0.3 * T, 3 * T):
        t += gap
        got.append((s.on_sync(t), s.slot))
    assert got == [(0, 1), (0, 2), (0, 3), (1, 5), (0, 6), (2, 9)]
    assert s.skipped == 3 and s.t_s == pytest.approx(9 * T)


@pytest.mark.parametrize("ppm", [-100.0, 100.0])
def test_sync_schedule_follows_a_producer_whose_clock_runs_apart(ppm):
    """A SYNC producer on its own clock (a drive), 100 ppm fast or slow, for 60 s at 2 ms: no period is
    ever taken as skipped (counted from the first SYNC, one would be every 5 000 SYNCs)."""
    from hil.canopen.cycle import SyncSchedule

    T = 0.002
    s = SyncSchedule(T)
    n = 30_000
    for k in range(n):
        s.on_sync(5.0 + k * T * (1 + ppm * 1e-6))
    assert s.skipped == 0 and s.slot == n


class LoopTimedTransport(InProcessTransport):
    """The dry-run's transport with the master's loop-timed SYNC (issue 37): SYNC number ``n`` leaves
    ``late[n]`` [s] after its due time, the slot it belongs to is :meth:`hil.transport.BusTransport.send_sync`'s
    (the master's sample carries it) and the simulated pair sees the SYNC when it left."""

    def __init__(self, pair, T: float, late: dict[int, float], bias: float = 0.0, latency: float = 0.0) -> None:
        import can

        from hil.transport import BusTransport

        super().__init__(pair, T)
        self.n, self.late, self._now = 0, late, 0.0
        self.bias, self.latency = bias, latency  # every other SYNC leaves bias late; the pair sees it latency on
        self.loop = BusTransport(can.Bus(interface="virtual", channel="emacheck-loop-timed"), T)
        self.loop.clock = lambda: self._now

    def next_sync(self) -> float | None:
        if not self._sync_on:
            return None
        self.n += 1
        if self.n == 1:
            self._now = self.t + self.T
            self.loop.start_sync()
        leave = self._now = self.loop.sync_due() + self.late.get(self.n, self.bias)
        self.loop.send_sync()
        slot = self.loop.sync_slot_s
        self.t = leave = leave + self.latency
        self._to_master.extend([(f, slot) for f in self.pair.tick(leave)])
        self._to_slaves.append(sync_frame())
        self._pump_slaves()  # the pair's TPDOs in answer, stamped when the SYNC left
        self.t = slot
        return slot

    def close(self) -> None:
        super().close()
        self.loop.close()
        self.loop.bus.shutdown()


AT_APPROACH = 262  #: the SYNC (counted from the first) 6 samples into the approach at 5 mm/s


def _run_loop_timed(actuation, check, simrig, late: dict[int, float], cycles: int = AT_APPROACH + 20, **kw):
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(1)))
    tr = LoopTimedTransport(pair, actuation.timing.sync_period_s, late, **kw)
    m = MasterCore(actuation, shipped_rig().plan,
                   forces=(check.calibration.opposing_force_N, check.safety.max_force_N))
    link = CanopenLink(m, tr, max_missing_cycles=check.safety.max_stale_cycles, max_lag_s=check.safety.max_lag_s)
    seq, sup = CheckSequence(actuation, check), Supervisor(actuation, check)
    plant_t = []
    try:
        samples, violation = _loop(link, seq, sup, cycles, lambda smp: plant_t.append(pair.plant.t_s))
        skipped = tr.loop.sync_skipped
    finally:
        tr.close()
    return pair, seq, samples, np.array(plant_t), violation, skipped


@pytest.fixture(scope="module")
def approach_on_time(actuation, check_profile, simrig):
    """Every loop-timed SYNC on time: the approach's speeds [mm/s], per EMA, and its peak."""
    _, seq, samples, _, violation, skipped = _run_loop_timed(actuation, check_profile, simrig, {})
    assert violation is None and skipped == 0 and seq.step_now is Step.APPROACH
    v = _speeds_mm_per_s(samples, actuation.mechanics.i_total_rad_per_mm)[1]
    assert v.max() > 5.0  # (the approach at 5 mm/s is under way: a doubled period would read ~10)
    return v


T_NOM = 0.002  #: the shipped SYNC period [s] (asserted in the test)


_BOUNDARIES = [(0.5 - 5e-7, 0.0), (0.5 + 5e-7, 0.0), (1.5 - 5e-7, 0.0), (1.5 + 5e-7, 0.0)]  # 1 ns either side
_EARLY_THEN_LATE = [(0.7, 0.3), (0.7, 0.45), (1.7, 0.3), (2.3, 0.0)]  # early for its slot, then the next late


@pytest.mark.parametrize("late_T, bias_latency_T", [(x, (0.0, 0.0)) for x in _BOUNDARIES + _EARLY_THEN_LATE]
                         + [(x, (0.1, 0.3)) for x in _EARLY_THEN_LATE])
def test_a_loop_timed_sync_late_in_the_approach_steps_the_drives_its_slots_periods(
        actuation, check_profile, simrig, approach_on_time, late_T, bias_latency_T):
    """Issue 37: a loop-timed SYNC leaves late (its slot is the nearest, up to T/2 early for it) and the
    next leaves late within its slot: the simulated drives step the plant the periods the samples'
    times say (their cycle locked to SYNC, not re-timed by each SYNC's jitter), so the supervisor
    reads the approach's speed, not one period's extra motion over one period (2x, > 10 mm/s). Also
    with every other SYNC 0.1 T late and 0.3 T of latency to the pair (the lock takes that phase)."""
    T = actuation.timing.sync_period_s
    assert T == T_NOM
    bias, latency = bias_latency_T
    late = {AT_APPROACH: late_T[0] * T, AT_APPROACH + 1: late_T[1] * T}
    pair, seq, samples, plant_t, violation, skipped = _run_loop_timed(
        actuation, check_profile, simrig, late, bias=bias * T, latency=latency * T)
    assert violation is None and seq.step_now is Step.APPROACH
    v = _speeds_mm_per_s(samples, actuation.mechanics.i_total_rad_per_mm)[1]
    assert v.max() <= approach_on_time.max() + 0.2
    expect_skipped = sum(int(x + 0.5) if x > 0.5 else 0 for x in late_T)
    assert skipped == expect_skipped and pair.stats.free_steps == expect_skipped
    t = np.array([s.t_s for s in samples])
    assert np.diff(plant_t) == pytest.approx(np.diff(t), abs=1e-9)  # plant time = the samples' time
