"""Stalls of the master (issue 37 parts 3 and 4): injected on the dry-run's simulated time axis, observed and
recorded by every check, tolerated up to the derived freshness limit (docs/safety.md, *A stall of the master*).

The sans-IO parts are pinned at their boundaries here (the injection's option ranges, a SYNC taken one SYNC
period late versus later, the link's stall limit exactly versus one float step beyond); the whole check with
stalls against the stall-free one is ``slow``. The fault table's stall rows are in tests/test_faults.py.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from test_boundaries_master import T_EXACT, ScriptedBus

from hil.canopen.frame import SYNC_COB_ID
from hil.cli.dry_run import dry_run as dry_run_in_process
from hil.master.link import CanopenLink, StaleData
from hil.master.stalls import EVERY_S_MAX, EVERY_S_MIN, STALL_MS_MAX, MasterStalls, StallWatch
from hil.profile.load import load_actuation, load_check, load_simrig
from hil.record.runfolder import read_record, read_signals
from hil.transport import InProcessTransport
from sim.plant import RigPlant
from support.boundary import around
from support.canopen_rig import cyclic_master, make_pair
from support.rigs import brief_rig, quiet

T = 0.002
UP = math.inf


# ------------------------------------------------------------------ the injection's ranges

@pytest.mark.parametrize("stall_ms, every_s, ok", [
    (math.nextafter(0.0, UP), 5.0, True), (0.0, 5.0, False), (-1.0, 5.0, False),
    (STALL_MS_MAX, 5.0, True), (math.nextafter(STALL_MS_MAX, UP), 5.0, False),
    (40.0, EVERY_S_MIN, True), (40.0, math.nextafter(EVERY_S_MIN, 0.0), False),
    (40.0, EVERY_S_MAX, True), (40.0, math.nextafter(EVERY_S_MAX, UP), False),
    # a stall must be shorter than half the mean interval (the shortest drawn interval)
    (math.nextafter(50.0, 0.0), 0.1, True), (50.0, 0.1, False),
    (math.nan, 5.0, False), (40.0, math.inf, False),
])
def test_master_stalls_ranges_on_their_boundaries(stall_ms, every_s, ok):
    rng = np.random.default_rng(0)
    if ok:
        s = MasterStalls(stall_ms, every_s, rng)
        assert s.stall_s == stall_ms / 1000.0 and s.every_s == every_s
    else:
        with pytest.raises(ValueError, match=r"^(stall_ms|every_s) = "):
            MasterStalls(stall_ms, every_s, rng)


def _schedule(seed: int, n: int, stall_ms=45.0, every_s=5.0) -> list[tuple[float, float]]:
    s = MasterStalls(stall_ms, every_s, np.random.default_rng([seed, 37]))
    s.start(1.0)
    k = 0
    while len(s.injected) < n:
        k += 1
        s.due(1.0 + k * T)
    return s.injected


def test_master_stalls_are_deterministic_for_a_seed_and_keep_their_mean_interval():
    a, b, c = _schedule(42, 400), _schedule(42, 400), _schedule(43, 400)
    assert a == b and a != c
    begins = np.array([t for t, _ in a])
    gaps = np.diff(begins) - 0.045  # from the end of one stall to the begin of the next
    assert begins[0] - 1.0 >= 2.5 - T and begins[0] - 1.0 <= 7.5 + T
    assert gaps.min() >= 2.5 - 1e-9 and gaps.max() <= 7.5 + T + 1e-9
    # uniform on [2.5, 7.5] s: the mean of 399 draws within 4 standard errors (1.44 s / sqrt(399))
    assert abs(gaps.mean() - 5.0) < 4 * (5.0 / math.sqrt(12.0)) / math.sqrt(len(gaps))
    assert all(d == 0.045 for _, d in a)


def test_master_stalls_begin_at_the_first_sync_at_or_after_their_drawn_time():
    s = MasterStalls(40.0, 5.0, np.random.default_rng(1))
    s.start(0.0)
    first = s._next  # (the drawn begin, to test the SYNC it falls on)
    assert s.due(first - 1e-6) is None
    assert s.due(first) == 0.04 and s.injected == [(first, 0.04)]
    assert s.due(first + T) is None  # the next is drawn from there


# ------------------------------------------------------------------ the watch

def test_stall_watch_one_sync_period_late_is_no_stall_a_float_step_more_is():
    w = StallWatch(T)
    w.observe(0.100, T)
    w.observe(0.102, 0.0)
    assert w.as_json() == {"count": 0, "longest_ms": 0.0, "at": []}
    w.observe(0.104, math.nextafter(T, UP))
    w.observe(0.106, 0.0)
    assert w.count == 1 and w.listed == [(0.104, math.nextafter(T, UP))]


def test_stall_watch_merges_consecutive_late_syncs_into_one_stall_as_long_as_the_latest():
    w = StallWatch(T)
    for k, late in enumerate((0.0, 0.045, 0.043, 0.041, 0.0, 0.0, 0.010, 0.0)):
        w.observe(k * T, late)
    assert w.as_json() == {"count": 2, "longest_ms": 45.0, "at": [[0.002, 45.0], [0.012, 10.0]]}
    w.observe(0.1, 0.02)  # still open at the end: counted
    assert w.as_json()["count"] == 3


# ------------------------------------------------------------------ the in-process bus stalls

class _At:
    """A stall schedule of one stall of ``stall_s`` at the SYNC of time ``t`` [s]."""

    def __init__(self, t: float, stall_s: float) -> None:
        self.t, self.stall_s = t, stall_s

    def start(self, t: float) -> None:
        pass

    def due(self, t: float) -> float | None:
        return self.stall_s if abs(t - self.t) < 1e-9 else None


@pytest.mark.parametrize("stall_s, syncs", [(0.040, 21), (0.041, 21), (0.0399, 20)])
def test_in_process_stall_queues_every_sync_of_the_stall_for_the_master_lag_the_stall(stall_s, syncs):
    pair = make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(0)))
    tr = InProcessTransport(pair, T, stalls=_At(3 * T, stall_s))
    tr.receive(0.0)
    tr.start_sync()
    assert tr.next_sync() == pytest.approx(T) and tr.next_sync() == pytest.approx(2 * T)
    tr.receive(tr.now())
    assert tr.next_sync() is None  # the master stalls at the third SYNC
    got = tr.receive(tr.now())
    stamps = [t for f, t, _ in got if f.arbitration_id == SYNC_COB_ID]
    assert len(stamps) == syncs and stamps[0] == pytest.approx(3 * T) and np.allclose(np.diff(stamps), T)
    assert tr.lag_s == stall_s and tr.max_lag_s == stall_s  # the first SYNC waited the whole stall
    assert tr.now() == stamps[-1] <= 3 * T + stall_s + 1e-12
    assert tr.receive(tr.now()) == [] and tr.lag_s == 0.0
    assert tr.next_sync() == pytest.approx(stamps[-1] + T)  # the SYNC grid goes on


# ------------------------------------------------------------------ the link's limit

@pytest.fixture(scope="module")
def check():
    return load_check(None, load_actuation())


def _stalling_link(safety, lag: float, with_safety_master: bool = True) -> CanopenLink:
    act, sim = load_actuation(), load_simrig()
    m = cyclic_master(act, RigPlant(sim.params, np.random.default_rng(1)),
                      safety=safety if with_safety_master else None)
    link = CanopenLink(m, ScriptedBus(T_EXACT, lag=lambda k: lag), max_missing_cycles=2, max_lag_s=0.02,
                       safety=safety)
    link.preflight = lambda: None
    link._apply_stale_limit()  # (what first_sample does after the preflight)
    return link


def test_link_tolerates_a_stall_exactly_at_the_derived_limit_and_stops_one_step_beyond(check):
    """The shipped derived limit, 50 ms (0.5 mm / 10 mm/s): a SYNC 50 ms late is taken, a float step later stops."""
    ok = _stalling_link(check.safety, 0.050)
    assert ok.stale.derived and ok.stale.ms == 50.0 and ok.max_lag_s == 0.050
    assert ok._next_sample().t_s == ok.m.T and ok.m.fault is None
    assert ok.stall_record()["limit"] == "safety.max_stale_ms" and ok.stall_record()["limit_ms"] == 50.0
    over = _stalling_link(check.safety, math.nextafter(0.050, UP))
    with pytest.raises(StaleData, match=r"^sensor data stale: the master is 50 ms behind the bus \(frames waited "
                                        r"for it; safety.max_stale_ms: the stall the master tolerates is 50 ms "):
        over._next_sample()
    assert isinstance(over.m.fault, StaleData) and over.m.quick_stop


def _silent_link(safety, lost: int) -> CanopenLink:
    act, sim = load_actuation(), load_simrig()
    m = cyclic_master(act, RigPlant(sim.params, np.random.default_rng(1)), safety=safety)
    bus = ScriptedBus(T_EXACT, silent=lambda k: k <= lost)
    link = CanopenLink(m, bus, max_missing_cycles=2, max_lag_s=0.02, safety=safety)
    link.preflight = lambda: None
    link._apply_stale_limit()
    return link


def test_link_tolerates_cycles_without_a_sample_up_to_the_derived_limit_and_stops_one_beyond(check):
    """Both drives keep their limits: the derived limit's 25 SYNC cycles without a complete sample replace
    ``safety.max_stale_cycles`` (2): 25 in a row are tolerated, the 26th stops naming ``safety.max_stale_ms``."""
    ok = _silent_link(check.safety, 25)
    assert ok.max_missing == 25 and ok._next_sample() is not None and ok.tr.k == 26 and ok.m.fault is None
    over = _silent_link(check.safety, 26)
    with pytest.raises(StaleData, match=r"^sensor data stale: no complete sample for 26 SYNC cycles "
                                        r"\(safety.max_stale_ms: 25 SYNC cycles, safety.max_stale_ms = 50 ms\)"):
        over._next_sample()
    assert over.tr.k == 26 and isinstance(over.m.fault, StaleData)


def test_link_of_drives_that_keep_not_all_limits_keeps_the_short_lag_limit(check):
    """A master without the check's safety profile writes no speed limit (0x6080): the derived budget does
    not apply, the lag limit stays ``safety.max_lag_s`` (20 ms), and a 21 ms stall stops naming it."""
    link = _stalling_link(check.safety, 0.021, with_safety_master=False)
    assert not link.stale.derived and "does not keep max motor speed" in link.stale.why
    assert link.max_lag_s == 0.02 and link.max_missing == 2 and link.stall_record()["limit"] == "safety.max_lag_s"
    with pytest.raises(StaleData, match=r"safety.max_lag_s = 20 ms\)$"):
        link._next_sample()


# ------------------------------------------------------------------ the whole check (slow)

@pytest.fixture(scope="module")
def check_runs(dry_run, stalled_dry_runs):
    """The shipped check stall-free and with the master stalling every 5 s for 45 ms (the issue's figure) and
    for 50 ms (the derived limit), one seed. (Not the short check of support.diagnose_cases: made for the plant
    without drives, over CANopen its 4 mm/s sweep start trips the 10 mm/s speed limit stall-free.) The
    stall-free one is the session's ``emacheck dry-run`` (conftest ``dry_run``: the same profiles and seed, made
    once per test run; its signals.csv is byte for byte this function's, docs/performance.md); the stalled ones
    are conftest ``stalled_dry_runs`` (``dry_run_in_process`` of the same profiles, once per test run: the same
    two checks test_faults.py's passing stall cases read)."""
    free = SimpleNamespace(out=dry_run[0], exit_code=dry_run[1])
    return free, stalled_dry_runs


@pytest.mark.slow
@pytest.mark.parametrize("stall_ms", [45.0, 50.0], ids=["45ms-the-issues", "50ms-the-limit"])
def test_a_check_with_stalls_up_to_the_limit_passes_with_the_backlash_of_the_stall_free_one(check_runs, stall_ms):
    free, stalled = check_runs[0], check_runs[1][stall_ms]
    assert free.exit_code == 0 and stalled.exit_code == 0
    a, b = (json.loads((r.out / "result.json").read_text()) for r in (free, stalled))
    for ch in ("int1", "int2", "ext"):
        assert abs(a["backlash_mm"][ch] - b["backlash_mm"][ch]) <= 1e-3, ch  # within 1 um
    assert read_record(free.out).stalls.count == 0
    # every stall in the record: as many as injected, each as long, as far apart
    st = read_record(stalled.out).stalls
    injected = stalled.link.tr.stalls.injected
    assert st.count == len(injected) == len(st.at) >= 20 and st.longest_ms == stall_ms
    assert st.limit == "safety.max_stale_ms" and st.limit_ms == 50.0
    assert st.injected == {"stall_ms": stall_ms, "every_s": 5.0, "count": len(injected)}
    assert all(ms == stall_ms for _, ms in st.at)
    assert np.allclose(np.diff([t for t, _ in st.at]), np.diff([t for t, _ in injected]), atol=1e-9)
    # every sample of the stalls judged and recorded: no SYNC period missing in signals.csv
    sig = read_signals(stalled.out / "signals.csv")
    assert np.allclose(np.diff(sig.t), T) and len(sig.t) > len(read_signals(free.out / "signals.csv").t)
    # during a stall the rows carry the setpoints the drives held (the last ones sent before it)
    for t0, _ in st.at:
        k = int(np.searchsorted(sig.t, t0 - 1e-9))
        n = int(stall_ms / 1000.0 / T)  # the SYNCs inside the stall (22 of 45 ms, 25 of 50 ms; at least)
        held = sig.sp1[k - 1:k + n]  # the row before the stall's first sample, then n more
        assert np.all(held == held[0]), t0


@pytest.mark.slow
def test_the_same_seed_gives_the_same_stalls(check_runs, tmp_path):
    stalled = check_runs[1][45.0]
    act, sim = load_actuation(), load_simrig()
    again = dry_run_in_process(act, load_check(None, act), sim, tmp_path / "again", stall=(45.0, 5.0))
    assert read_record(again.out).stalls.at == read_record(stalled.out).stalls.at
    assert (again.out / "signals.csv").read_bytes() == (stalled.out / "signals.csv").read_bytes()


# ------------------------------------------------------------------ the dry-run's options

@pytest.mark.parametrize("argv, got", [
    (["--master-stall-ms", "45"], (45.0, 5.0)),  # the mean interval's default: 5 s
    (["--master-stall-ms", "1e-300", "--master-stall-every-s", "0.1"], (1e-300, 0.1)),
    (["--master-stall-ms", "1000", "--master-stall-every-s", "3600"], (1000.0, 3600.0)),
    ([], (None, 5.0)),
])
def test_dry_run_stall_options_in_range(argv, got):
    from hil.cli import build_parser

    a = build_parser().parse_args(["dry-run", *argv])
    assert (a.master_stall_ms, a.master_stall_every_s) == got


@pytest.mark.parametrize("argv, words", [
    (["--master-stall-ms", "0"], "argument --master-stall-ms: 0: a stall of the master [ms] is a number above 0 "
                                 "to 1000"),
    (["--master-stall-ms", "1000.0000000000001"], "is a number above 0 to 1000"),
    (["--master-stall-ms", "nan"], "is a number above 0 to 1000"),
    (["--master-stall-ms", "x"], "not a number (a stall of the master [ms]): 'x'"),
    (["--master-stall-ms", "4", "--master-stall-every-s", "0.09999999999999999"],
     "argument --master-stall-every-s: 0.09999999999999999: the mean interval between stalls [s] is a number "
     "from 0.1 to 3600"),
    (["--master-stall-ms", "4", "--master-stall-every-s", "3600.0000000000005"], "from 0.1 to 3600"),
])
def test_dry_run_stall_options_out_of_range_exit_3_naming_the_option(argv, words, capsys):
    from hil.cli import main

    with pytest.raises(SystemExit) as e:
        main(["dry-run", *argv])
    assert e.value.code == 3 and words in capsys.readouterr().err


def test_dry_run_stall_of_half_the_interval_is_refused_before_the_run_folder(tmp_path, capsys):
    """Exactly half the mean interval (the shortest drawn one) is refused, exit 3, nothing made; a float step
    shorter is accepted (:func:`test_master_stalls_ranges_on_their_boundaries`, the same rule)."""
    from hil.cli import main

    rc = main(["dry-run", "--master-stall-ms", "600", "--master-stall-every-s", "1.2", "--out", str(tmp_path / "r")])
    assert rc == 3 and not (tmp_path / "r").exists()
    assert "--master-stall-ms 600 is not shorter than half of --master-stall-every-s 1.2 s" in capsys.readouterr().err


# ------------------------------------------------------------------ the analysis reads what the master accepted

def _held_gap(periods: float):
    """A smooth recording at 2 ms with one gap of ``periods`` SYNC periods (both drives holding over it)."""
    from hil.record.runfolder import Signals

    t = np.concatenate([np.arange(1, 2001) * T, 2000 * T + periods * T + np.arange(0, 2000) * T])
    x = np.where(t < 2000 * T + 1e-9, 0.5 * np.sin(t), 0.5 * np.sin(2000 * T))
    x[2000:] = 0.5 * np.sin(2000 * T) + 0.5 * (np.sin(t[2000:] - periods * T) - np.sin(2000 * T))
    z = np.zeros_like(t)
    return Signals(t, x * 5.0, x * 5.0, x, x, z, z)


@pytest.mark.parametrize("periods, with_stalls, refused", [
    (10.0, False, False), (11.0, False, True),  # a recording from elsewhere: 10 periods
    (26.0, True, False), (27.0, True, True),  # a check held to 50 ms: 25 missed SYNCs, a gap of 26 periods
])
def test_a_gap_the_master_accepted_is_one_the_analysis_reads(periods, with_stalls, refused, tmp_path):
    from hil.errors import RecordingError
    from hil.record.runrecord import RunRecord, Stalls
    from hil.record.signals_csv import gap_periods_for, refuse_jumps

    meta = RunRecord(stalls=Stalls(0, 0.0, [], 50.0, "safety.max_stale_ms")) if with_stalls else None
    assert gap_periods_for(meta, T) == pytest.approx(26.0 if with_stalls else 10.0, abs=1e-12)
    sig = _held_gap(periods)
    if refused:
        with pytest.raises(RecordingError, match=rf"a jump in time: .* more than {26 if with_stalls else 10} "
                                                 r"sample periods"):
            refuse_jumps(sig, tmp_path / "signals.csv", 5.0, lines=True, meta=meta, sync_period_s=T)
    else:
        refuse_jumps(sig, tmp_path / "signals.csv", 5.0, lines=True, meta=meta, sync_period_s=T)


class _LoopSync:
    """A transport whose loop sends its own SYNC (udp_multicast): the next one due at ``due``, the clock at ``now``."""

    T = T_EXACT

    def __init__(self, due: float | None, now: float) -> None:
        self.due, self.now = due, now

    def clock(self) -> float:
        return self.now

    def sync_due(self) -> float | None:
        return self.due


def test_a_hold_that_ended_in_the_stop_is_recorded_as_the_stall_it_was():
    """The loop held 211 ms with its SYNC due at 0.644 s; on waking, an EMCY that waited stopped it before the late
    SYNC went out (where a stall is otherwise recorded): the stall is recorded from the overdue SYNC, more than one
    period late (not on it), and nothing where the SYNC is not the loop's own."""
    from support.canopen_rig import make_master

    def recent(due, now):
        link = CanopenLink(make_master(), _LoopSync(due, now))
        link.record_overdue_sync()
        return link.stall_watch.recent

    got = recent(0.644, 0.855)
    assert len(got) == 1 and got[0][1] == pytest.approx(0.211)
    assert got[0][0] == make_master().sync_schedule.T  # at the period after the last SYNC the master saw
    below, at, above = around(lambda now: now - 0.644, T_EXACT, 0.644 + T_EXACT)
    assert recent(0.644, below) == () and recent(0.644, at) == ()
    assert recent(0.644, above)[0][1] > T_EXACT
    assert recent(None, 0.855) == ()
