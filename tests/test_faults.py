"""Every injected fault: reaction time, peak true force and stroke, safe state, run folder.

Each test runs the dry-run (in-process virtual bus, plant stepped per SYNC) with
one fault of :mod:`sim.faults` and asserts on the logged data: the plant's true
force and stroke (the injector's truth trace), the drives' own final CiA 402
states, and the run folder (meta.json, result.json, signals.csv, can.log).

Stated reaction bounds (T = SYNC period 2 ms, P = heartbeat period 0.1 s):

* force / stroke limits: the supervisor flags the first sample beyond the limit
  (0 cycles) and the quick stop is in the drives one cycle later: <= 2 T.
* heartbeat loss: <= 1.5 P after the last heartbeat, i.e. after the onset.
* EMCY: the cycle of the EMCY (<= 1 T); fault state without EMCY: <= 2 T.
* lost / late TPDOs, bus errors (freshness): <= (STALE_CYCLES + 1) T, the derived freshness limit
  (both drives keep their limits); a TPDO late by up to STALE_CYCLES cycles is not caught.
* frozen sensor: <= (max_frozen_cycles + 1) T; spike, resolver wrap: the same cycle.
* lost RPDOs and runaway (following error): max_following_error / speed + 0.1 s;
  a drive deaf to its RPDOs gets the quick stop by SDO after SDO_FALLBACK_CYCLES.
* stalls of the master (``STALL_CASES``): tolerated up to the derived freshness
  limit (50 ms, the shipped e / v), every one recorded; a longer one stops when it ends, naming
  ``safety.max_stale_ms``; a violation inside one is judged at its own sample
  and the drives get the quick stop within 2 T of the stall's end.

Overshoot margin on the true force and stroke: what the fastest true rate seen
in the run allows during 2 T, plus the sensor noise (5 sigma of the load cell,
the LVDT's peak-to-peak noise). The limit plus that margin must itself stay well
inside the physics it protects: the force within the hard cap of 25 % of the
limit load (10 kN of 40 kN), the stroke inside the rig's end stops (20 mm).

Every test that runs a dry-run is ``slow`` (fault-injection end to end); the
check that every fault kind has a case stays in the fast loop.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hil.canopen.cia402 import State, decode_state
from hil.canopen.frame import Frame
from hil.canopen.process import DriveMode
from hil.check.staleness import NEEDED, stale_limit
from hil.check.supervisor import Limits
from hil.cli.dry_run import dry_run
from hil.master.link import SDO_FALLBACK_CYCLES
from hil.profile.config import HARD_MAX_FORCE_FRACTION
from hil.profile.load import load_actuation, load_check, load_simrig
from hil.record.canlog import decode_can_log
from hil.record.runfolder import read_record, read_signals
from sim.faults import Fault, FaultInjector, FaultKind
from sim.plant import RigPlant
from support.canopen_rig import make_pair
from support.profiles import write_profile_variant
from support.rigs import brief_rig, quiet
from support.sim_bus import Bus

T = 0.002
P_HB = 0.1
#: SYNC cycles without a complete sample the master tolerates: the derived freshness limit, both shipped drives
#: keeping their limits (docs/safety.md, *A stall of the master*: 50 ms = 25 cycles)
STALE_CYCLES = stale_limit(load_actuation(), load_check(None, load_actuation()).safety, (NEEDED, NEEDED)).cycles
END_STOP_MM = load_simrig().params.stroke_limit_mm  #: the simulated rig's mechanical end stops [mm]
SAFE = {State.SWITCH_ON_DISABLED, State.FAULT}


@pytest.fixture(scope="module")
def profiles():
    act = load_actuation()
    return act, load_check(None, act), load_simrig()


def _check_with(tmp_path: Path, act, **overrides) -> object:
    """The shipped check profile with ``overrides`` ({table: {key: value}}), loaded against ``act``."""
    return load_check(write_profile_variant("check.toml", tmp_path / "check.toml", overrides), act)


def _run(tmp_path, profiles, fault: Fault, check=None):
    act, chk, sim = profiles
    r = dry_run(act, check or chk, sim, tmp_path / "run", faults=[fault])
    meta = read_record(r.out)
    return r, meta


def _t_detect(r, meta) -> float:
    if meta.safety is not None:
        return meta.safety.t_s
    assert r.master.fault_cycle is not None, "neither the supervisor nor the master reacted"
    return r.master.fault_cycle * T


def _t_safe_command(tr, t_detect: float, reachable=(0, 1)) -> float:
    """First truth time after the detection at which every reachable drive left OPERATION_ENABLED."""
    for t, st in zip(tr.t_s, tr.state, strict=True):
        if t >= t_detect - 1e-9 and all(st[k] != State.OPERATION_ENABLED.name for k in reachable):
            return float(t)
    return math.inf


def _assert_run_folder(r, meta, t_detect, act, lost: float | None = None):
    assert meta.status == "aborted" and meta.reason
    res = json.loads((r.out / "result.json").read_text())
    assert res["status"] == "aborted" and res["reason"] == meta.reason
    sig = read_signals(r.out / "signals.csv")
    # the data up to the detection is kept (the samples the detection waited for cannot be; ``lost``: the
    # gap the fault itself leaves before it is detected)
    if lost is None:
        lost = (STALE_CYCLES + 1 if "StaleData" in meta.reason else 1) * T
    assert sig.t[-1] >= t_detect - lost - 1e-9
    if meta.safety is not None:
        assert sig.step[-1] == "aborted" and sig.mode1[-1] == 0 and sig.mode2[-1] == 0
    dec = decode_can_log(r.out / "can.log", act)
    assert dec.signals.t[-1] >= t_detect - lost - 1e-9
    assert meta.drives_final["ema1"].node == 1
    return sig


def _peaks_within_limits(tr, t_onset, lim: Limits, act):
    m = tr.t_s >= t_onset
    F, s = np.abs(tr.F_N[m]), np.abs(tr.s_mm[m])
    dF = np.max(np.abs(np.diff(tr.F_N, axis=0))) / T
    ds = np.max(np.abs(np.diff(tr.s_mm, axis=0))) / T
    f_margin = 2 * T * dF + 5 * act.sensors.loadcell_noise_std_N
    s_margin = 2 * T * ds + act.sensors.lvdt_noise_pp_mm
    # the bounds themselves well inside the physics: a margin grown from a fast true rate must not
    # carry the bound to the limit load or the end stops
    assert lim.max_force_N + f_margin <= HARD_MAX_FORCE_FRACTION * act.mechanics.limit_load_N, f_margin
    assert lim.max_stroke_mm + s_margin < END_STOP_MM, s_margin
    assert F.max() <= lim.max_force_N + f_margin, (F.max(), f_margin)
    assert s.max() <= lim.max_stroke_mm + s_margin, (s.max(), s_margin)
    return F.max(), s.max()


#: fault, expected words in the reason, reaction bound [s] from the onset
CASES = [
    (Fault("heartbeat_stop", 2, 2.0), "HeartbeatLost: node 2", 1.5 * P_HB),
    (Fault("emcy_over_current", 1, 2.0), "EMCY 0x2310 (over current)", T),
    (Fault("emcy_over_temperature", 2, 2.0), "EMCY 0x4310 (drive over temperature)", T),
    (Fault("drive_fault", 1, 2.0), "node 1 (EMA 1): drive in FAULT", 2 * T),
    (Fault("tpdo_missing", 2, 2.0, duration_s=0.5), "StaleData", (STALE_CYCLES + 1) * T),
    (Fault("tpdo_late", 1, 2.0, value=STALE_CYCLES + 1), "StaleData", (STALE_CYCLES + 1) * T),
    (Fault("rpdo_lost", 1, 3.0), "max_following_error_mm", 0.5 / 2.0 + 0.1),
    (Fault("lvdt_stuck", 1, 3.0), "LVDT 1 frozen", 26 * T),
    (Fault("lvdt_spike", 2, 3.0), "max_d_int_mm", 0.0),
    (Fault("loadcell_saturation", 2, 2.0, value=1500.0), "load cell 2 frozen", 26 * T),
    (Fault("resolver_wrap", 1, 3.0), "EMA 1 following error", 0.0),
    (Fault("runaway", 1, 3.0), "EMA 1 following error", 0.5 / 5.0 + 0.1),
    # 50 % frame loss leaves complete samples often enough for the derived freshness limit (25 cycles): a
    # drive's heartbeat lost twice in a row stops it
    (Fault("bus_errors", 1, 3.0, duration_s=0.3), "HeartbeatLost: node 2", 1.5 * P_HB),
]


@pytest.mark.parametrize("fault,words,bound", CASES, ids=[c[0].kind for c in CASES])
@pytest.mark.slow
def test_fault_reaction_safe_state_and_run_folder(tmp_path, profiles, fault, words, bound):
    act, chk, _ = profiles
    r, meta = _run(tmp_path, profiles, fault)
    assert r.exit_code == 2 and r.outcome.status == "aborted"
    assert words in meta.reason
    onset = r.injector.onset_s[fault.kind]
    assert onset == pytest.approx(fault.start_s, abs=T / 2)
    t_det = _t_detect(r, meta)
    assert 0.0 <= t_det - onset <= bound + 1e-9, (t_det - onset, bound)
    tr = r.injector.truth
    # the safe-state command reached both drives within 2 SYNC cycles of the detection
    # (a drive whose RPDOs are lost gets it when they come back: asserted on the other one)
    reach = {"rpdo_lost": (2 - fault.ema,)}.get(fault.kind, (0, 1))
    # (with bus errors the quick stop, repeated every cycle, is itself lost at times: 4 retries allowed)
    retries = 4 * T if fault.kind == "bus_errors" else 0.0
    assert _t_safe_command(tr, t_det, reach) - t_det <= 2 * T + retries + 1e-9
    if fault.kind == "rpdo_lost":  # the drive deaf to its RPDOs gets the quick stop by SDO
        assert _t_safe_command(tr, t_det, (fault.ema - 1,)) - t_det <= (SDO_FALLBACK_CYCLES + 2) * T + 1e-9
    _peaks_within_limits(tr, onset, Limits.of(act, chk), act)
    assert set(r.injector.final_states()) <= SAFE
    assert all(v.safe for v in meta.drives_final.values()), meta.drives_final
    # (bus errors: samples incomplete for up to the freshness limit before the heartbeat's loss stops it)
    _assert_run_folder(r, meta, t_det, act, (STALE_CYCLES + 1) * T if fault.kind == "bus_errors" else None)


#: the master's stalls (``dry-run --master-stall-ms MS --master-stall-every-s S``, hil/master/stalls.py): stall [ms],
#: mean interval [s], a runaway drive (15 mm/s, over the 10 mm/s limit) from the first stall's second SYNC,
#: words in the reason (None: the check passes). The derived freshness limit is 50 ms (docs/safety.md).
STALL_CASES = [
    (45.0, 5.0, False, None),
    (50.0, 5.0, False, None),
    (51.0, 5.0, False, "safety.max_stale_ms"),
    (50.0, 5.0, True, "safety limit safety.max_velocity_mm_per_s: EMA 1 speed"),
]
#: the derived freshness limit of the shipped check [ms]
STALL_LIMIT_MS = stale_limit(load_actuation(), load_check(None, load_actuation()).safety, (NEEDED, NEEDED)).ms


def _first_stall_s(seed: int, every_s: float) -> float:
    """The check time of the first injected stall (:class:`hil.master.stalls.MasterStalls`: one interval drawn from
    ``[seed, 37]`` after the first SYNC, at the first SYNC at or after it)."""
    gap = float(np.random.default_rng([seed, 37]).uniform(0.5, 1.5)) * every_s
    return math.ceil(gap / T - 1e-9) * T


@pytest.mark.parametrize("stall_ms,every_s,runaway,words", STALL_CASES,
                         ids=["45ms-passes", "50ms-passes", "51ms-stops", "overspeed-in-a-stall"])
@pytest.mark.slow
def test_master_stalls_tolerated_up_to_the_limit_and_judged_sample_by_sample(tmp_path, profiles, stall_ms,
                                                                              every_s, runaway, words, request):
    act, chk, sim = profiles
    t_stall, end = _first_stall_s(sim.seed, every_s), _first_stall_s(sim.seed, every_s) + stall_ms / 1000.0
    faults = [Fault("runaway", 1, t_stall + 2 * T, value=15.0)] if runaway else []
    if not faults and every_s == 5.0 and stall_ms in (45.0, 50.0):
        # the same dry-run as test_master_stalls.py's (no fault, the shipped profiles, stall_ms every 5 s): made once
        # per test run (conftest ``stalled_dry_runs``; docs/performance.md, "Test suite, sixth pass")
        r = request.getfixturevalue("stalled_dry_runs")[stall_ms]
    else:
        r = dry_run(act, chk, sim, tmp_path / "run", faults=faults, stall=(stall_ms, every_s))
    meta = read_record(r.out)
    st = meta.stalls
    assert st.at[0] == [pytest.approx(t_stall, abs=1e-9), stall_ms]  # every stall in the record
    assert st.count == len(r.link.tr.stalls.injected) == len(st.at) and st.longest_ms == stall_ms
    assert st.limit == "safety.max_stale_ms" and st.limit_ms == STALL_LIMIT_MS == 50.0
    assert (stall_ms <= STALL_LIMIT_MS) == (words is None or runaway)  # the case's stall within the limit or not
    if words is None:
        assert r.exit_code == 0 and meta.status == "done" and st.count >= 20
        return
    assert r.exit_code == 2 and words in meta.reason, meta.reason
    tr = r.injector.truth
    if not runaway:  # one stall over the limit: stopped when it ends, naming the limit and its profile key
        assert st.count == 1 and meta.safety is None
        assert f"the master is {stall_ms:g} ms behind the bus (frames waited for it; safety.max_stale_ms: " \
               "the stall the master tolerates is 50 ms" in meta.reason
        assert r.master.fault_cycle * T == pytest.approx(t_stall - T, abs=1e-9)  # (the cycle before the stall)
        assert end - 1e-9 <= _t_safe_command(tr, end) <= end + 2 * T + 1e-9
    else:  # the overspeed inside the stall: judged at its own SYNC's time, caught late, the stop names it
        assert st.count == 1 and t_stall + 2 * T <= meta.safety.t_s <= end
        assert meta.safety.value > 10.0 and meta.safety.threshold == 10.0
        assert end - 1e-9 <= _t_safe_command(tr, meta.safety.t_s, reachable=(1,)) <= end + 2 * T + 1e-9
    assert set(r.injector.final_states()) <= SAFE
    assert all(v.safe for v in meta.drives_final.values()), meta.drives_final


@pytest.mark.slow
def test_unreachable_drive_other_goes_safe_and_reason_names_it(tmp_path, profiles):
    act, chk, _ = profiles
    r, meta = _run(tmp_path, profiles, Fault("node_silent", 2, 2.0))
    t_det = _t_detect(r, meta)
    assert t_det - 2.0 <= (STALE_CYCLES + 1) * T + 1e-9
    ema1, ema2 = r.injector.final_states()
    assert ema1 is State.SWITCH_ON_DISABLED  # the reachable drive went to the safe state
    assert ema2 is State.OPERATION_ENABLED  # the silent one heard nothing (holds its last target)
    assert "EMA 2 (node 2) unreachable (heartbeat lost)" in meta.reason
    assert meta.drives_final["ema1"].safe and not meta.drives_final["ema2"].reachable
    assert _t_safe_command(r.injector.truth, t_det, reachable=(0,)) - t_det <= 2 * T + 1e-9
    _assert_run_folder(r, meta, t_det, act)


@pytest.mark.slow
def test_a_drive_unreachable_for_a_while_is_stopped_once_it_answers_again(tmp_path, profiles):
    """Drive 2 silent for 0.3 s (a held process, a lapsed cable contact): the check stops on it, the other drive
    goes safe, and the safe-state sequence keeps commanding the silent one until ``canopen.enable_timeout_s`` has
    passed; it answers again at 2.3 s and is brought to Switch on disabled too (left at once, it ran on in
    Operation enabled, holding its last target)."""
    act, chk, _ = profiles
    r, meta = _run(tmp_path, profiles, Fault("node_silent", 2, 2.0, duration_s=0.3))
    assert 2.3 - 2.0 < act.canopen.enable_timeout_s
    assert r.injector.final_states() == (State.SWITCH_ON_DISABLED, State.SWITCH_ON_DISABLED)
    assert meta.drives_final["ema1"].safe and meta.drives_final["ema2"].safe
    back = _t_safe_command(r.injector.truth, 2.3, reachable=(1,))
    assert 2.3 - 1e-9 <= back <= 2.3 + 3 * T + 1e-9  # commanded at the first cycles it hears again


@pytest.mark.slow
def test_heartbeat_loss_detected_within_1p5_periods_of_the_last_heartbeat(tmp_path, profiles):
    act, chk, _ = profiles
    r, meta = _run(tmp_path, profiles, Fault("heartbeat_stop", 1, 2.05))
    hb = [ln for ln in (r.out / "can.log").read_text().splitlines() if " 701#05" in ln]
    t_last = float(hb[-1].split(")")[0].strip("(")) - _t0_of_sync(r.out)
    t_det = _t_detect(r, meta)
    assert t_det - t_last <= 1.5 * P_HB + 1e-9
    assert t_det - t_last >= 1.5 * P_HB - T  # and not before its timeout


def _t0_of_sync(out: Path) -> float:
    """Bus time of SYNC 0 (the check's t = SYNC count * T)."""
    syncs = [float(ln.split(")")[0].strip("(")) for ln in (out / "can.log").read_text().splitlines()
             if " 080#" in ln]
    return syncs[0] - T


@pytest.mark.slow
def test_sdo_abort_in_preflight_aborts_before_anything_moves(tmp_path, profiles):
    r, meta = _run(tmp_path, profiles, Fault("sdo_abort", 2, value=float(0x1017)))
    assert r.exit_code == 2
    assert "SdoAbortError" in meta.reason and "0x08000020" in meta.reason
    assert "0x1017" in meta.reason
    assert r.injector.syncs == 0  # no SYNC: nothing was enabled
    assert set(r.injector.final_states()) == {State.SWITCH_ON_DISABLED}
    res = json.loads((r.out / "result.json").read_text())
    assert res["status"] == "aborted"


@pytest.mark.slow
def test_force_limit_reaction_within_two_cycles(tmp_path, profiles):
    """A runaway drive against the other one holding position: the force limit trips."""
    act, _, _ = profiles
    chk = _check_with(tmp_path, act, safety={"max_following_error_mm": 2.0, "max_force_fight_N": 7900.0,
                                             "max_force_imbalance_N": 4000.0})
    r, meta = _run(tmp_path, profiles, Fault("runaway", 1, 0.6, value=5.0), check=chk)
    assert meta.safety.limit in ("max_force_N", "max_force_fight_N"), meta.reason
    lim = Limits.of(act, chk)
    sig = read_signals(r.out / "signals.csv")
    fl = {"max_force_N": lim.max_force_N, "max_force_fight_N": lim.max_force_fight_N}[meta.safety.limit]
    q = np.maximum(np.abs(sig.F1), np.abs(sig.F2)) if meta.safety.limit == "max_force_N" \
        else np.abs(sig.F1 - sig.F2) / 2
    t_first = sig.t[np.flatnonzero(q > fl)[0]]
    t_det = meta.safety.t_s
    assert t_det - t_first <= 2 * T + 1e-9
    tr = r.injector.truth
    assert _t_safe_command(tr, t_det) - t_first <= 2 * T + 1e-9
    F_peak, _ = _peaks_within_limits(tr, 0.6, lim, act)
    assert F_peak > 0.8 * lim.max_force_N  # the fault really drove the force up to the limit
    assert set(r.injector.final_states()) <= SAFE


@pytest.mark.slow
def test_stroke_limit_reaction_within_two_cycles(tmp_path, profiles):
    act, _, _ = profiles
    chk = _check_with(tmp_path, act, calibration={"sweep_amplitude_mm": 2.5},
                      safety={"max_stroke_mm": 3.0, "max_following_error_mm": 2.0})
    r, meta = _run(tmp_path, profiles, Fault("runaway", 1, 2.7, value=5.0), check=chk)
    assert meta.safety.limit == "max_stroke_mm", meta.reason
    sig = read_signals(r.out / "signals.csv")
    t_first = sig.t[np.flatnonzero(np.maximum(np.abs(sig.s1), np.abs(sig.s2)) > 3.0)[0]]
    t_det = meta.safety.t_s
    assert t_det - t_first <= 2 * T + 1e-9
    tr = r.injector.truth
    assert _t_safe_command(tr, t_det) - t_first <= 2 * T + 1e-9
    _peaks_within_limits(tr, 2.7, Limits.of(act, chk), act)
    assert set(r.injector.final_states()) <= SAFE


@pytest.mark.slow
def test_faults_from_the_simrig_profile(tmp_path):
    p = write_profile_variant("simrig.toml", tmp_path / "simrig.toml",
                              add={"faults": [{"kind": "emcy_over_temperature", "ema": 1, "start_s": 1.0}]})
    sim = load_simrig(p)
    assert sim.faults == (Fault("emcy_over_temperature", 1, 1.0),)
    from hil.cli import main
    rc = main(["dry-run", "--sim", str(p), "--out", str(tmp_path / "run"), "--quiet"])
    assert rc == 2
    meta = read_record(tmp_path / "run")
    assert "EMCY 0x4310" in meta.reason and meta.faults[0]["kind"] == "emcy_over_temperature"
    bad = write_profile_variant("simrig.toml", tmp_path / "bad.toml", add={"faults": [{"kind": "hartbeat_stop"}]})
    with pytest.raises(ValueError, match=r"faults\[0\]\.kind.*did you mean 'heartbeat_stop'"):
        load_simrig(bad)


@pytest.mark.slow
def test_sensor_node_silent_stops_the_check_and_both_drives(tmp_path, profiles):
    """The LVDTs and load cells on a CiA 401 node (tests/support/sensor_rig.py) that falls silent: the
    master misses its TPDO (freshness) and stops both drives, as for a drive's lost TPDOs."""
    from support.sensor_rig import sensor_profile

    _, chk, sim = profiles
    path = sensor_profile(tmp_path / "actuation.toml")
    act = load_actuation(path)
    r = dry_run(act, load_check(None, act), sim, tmp_path / "run", faults=[Fault("sensor_node_silent", start_s=2.0)],
                profile_path=path)
    meta = read_record(r.out)
    assert r.exit_code == 2 and "StaleData" in meta.reason and "missing: COB-ID 0x183" in meta.reason
    onset = r.injector.onset_s["sensor_node_silent"]
    assert onset == pytest.approx(2.0, abs=T / 2)
    t_det = _t_detect(r, meta)
    assert 0.0 <= t_det - onset <= (STALE_CYCLES + 1) * T + 1e-9
    assert _t_safe_command(r.injector.truth, t_det) - t_det <= 2 * T + 1e-9
    assert set(r.injector.final_states()) <= SAFE


# ------------------------------------------------------------------ the drive faults, at the simulated drive
# (the master's reactions to them: the drive-fault dry-runs below and the master's own tests)


def _drive_bus(faults, *, t_on: float = 0.0):
    """The shipped pair (quiet rig) behind a fault injector, powered on at ``t_on``; a minimal master."""
    inj = FaultInjector(make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(0))), faults,
                        record_truth=False)
    bus = Bus(inj)
    bus.t = t_on
    boot = inj.power_on(t_on)
    return inj, bus, boot


def _walk_up(bus: Bus, node: int) -> None:
    """Shutdown, switch on, enable operation by SDO (as the master's drill does), CSP holding 0."""
    bus.write(node, 0x6060, 0, "b", 8)
    for cw in (0x06, 0x07, 0x0F):
        bus.write(node, 0x6040, 0, "H", cw)


def _state(bus: Bus, node: int) -> State:
    return decode_state(bus.read(node, 0x6041, 0, "H"))


def test_ignore_abort_connection_drive_sends_its_emcy_and_stays_enabled():
    inj, bus, _ = _drive_bus([Fault("ignore_abort_connection", 2)])
    for n in (1, 2):
        bus.write(n, 0x1016, 1, "I", 0x7F << 16 | 125)
        bus.write(n, 0x6007, 0, "h", 3)
        assert bus.read(n, 0x6007, 0, "h") == 3  # accepted and read back
        _walk_up(bus, n)
    bus.send(Frame(0x77F, b"\x05"))  # the master's last heartbeat
    emcy = [f for k in range(1, 80) for f in inj.tick(k * 0.002) if 0x81 <= f.arbitration_id <= 0x82]
    assert [(f.arbitration_id, f.data[:2]) for f in emcy] == [(0x81, b"\x30\x81"), (0x82, b"\x30\x81")]
    assert _state(bus, 1) is State.QUICK_STOP_ACTIVE  # the drive without the fault reacted (0x6007 = 3)
    assert _state(bus, 2) is State.OPERATION_ENABLED  # the faulty one did nothing
    assert inj.pair.nodes[1].heartbeat_events  # its consumer saw the event
    assert inj.onset_s == {"ignore_abort_connection": 0.0}


def test_quick_stop_stays_whatever_605a_says_until_disable_voltage():
    inj, bus, _ = _drive_bus([Fault("quick_stop_stays", 1)])
    bus.nmt(0x01)
    for n in (1, 2):
        assert bus.read(n, 0x605A, 0, "h") == 2  # switch on disabled after the stop, as told
        _walk_up(bus, n)
        bus.write(n, 0x6040, 0, "H", 0x02)  # quick stop
    for _ in range(100):  # 0.2 s: four times the quick stop hold
        bus.sync()
    assert _state(bus, 2) is State.SWITCH_ON_DISABLED
    assert _state(bus, 1) is State.QUICK_STOP_ACTIVE
    assert inj.pair.nodes[0].setpoint.mode is DriveMode.POSITION  # holding its position
    bus.write(1, 0x6040, 0, "H", 0x00)  # disable voltage
    assert _state(bus, 1) is State.SWITCH_ON_DISABLED


@pytest.mark.parametrize("kind,value,resets", [("starts_in_fault", math.nan, 1), ("fault_reset_ignored", 3.0, 3),
                                                ("fault_reset_ignored", math.nan, 4)])
def test_drive_booting_into_fault_needs_its_fault_resets(kind, value, resets):
    inj, bus, boot = _drive_bus([Fault(kind, 2, value=value)])
    # boot-up of both, then the EMCY of the fault found at boot (0x5000 device hardware, register 0x01: generic)
    assert boot == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00"), Frame(0x082, bytes.fromhex("0050 01 0000000000"))]
    assert _state(bus, 2) is State.FAULT and bus.read(2, 0x603F, 0, "H") == 0x5000
    assert bus.nmt(0x81, 2)[0] == Frame(0x702, b"\x00")  # NMT reset node: in FAULT again
    assert _state(bus, 2) is State.FAULT
    states = []
    for _ in range(resets):  # the master's fault reset: bit 7 low, then high (its rising edge)
        bus.write(2, 0x6040, 0, "H", 0x00)
        bus.write(2, 0x6040, 0, "H", 0x80)
        states.append(_state(bus, 2))
    assert states == [State.FAULT] * (resets - 1) + [State.SWITCH_ON_DISABLED]
    assert bus.read(2, 0x603F, 0, "H") == 0
    assert bus.nmt(0x81, 2) == [Frame(0x702, b"\x00")]  # the cause is cleared: no fault at the next boot
    assert _state(bus, 2) is State.SWITCH_ON_DISABLED and _state(bus, 1) is State.SWITCH_ON_DISABLED
    if kind == "fault_reset_ignored":  # any later fault takes as many resets
        bus.nmt(0x01)
        _walk_up(bus, 2)
        inj.pair.inject_fault(1, 0x2310)
        bus.sync()
        for _ in range(resets):
            assert _state(bus, 2) is State.FAULT
            bus.write(2, 0x6040, 0, "H", 0x00)
            bus.write(2, 0x6040, 0, "H", 0x80)
        assert _state(bus, 2) is State.SWITCH_ON_DISABLED


def test_mode_not_confirmed_0x6061_does_not_follow_and_the_drive_keeps_its_mode():
    inj, bus, _ = _drive_bus([Fault("mode_not_confirmed", 1)])
    bus.nmt(0x01)
    for n in (1, 2):
        bus.write(n, 0x6060, 0, "b", 8)
        assert bus.read(n, 0x6060, 0, "b") == 8  # written and read back
    assert bus.read(1, 0x6061, 0, "b") == 0 and bus.read(2, 0x6061, 0, "b") == 8
    for n in (1, 2):
        _walk_up(bus, n)
        bus.write(n, 0x607A, 0, "i", 500)
    bus.sync()
    bus.sync()
    # drive 1 runs in the mode it shows (0: none), so it follows no target: its power stage commands nothing
    assert inj.pair.nodes[0].setpoint.mode is DriveMode.DISABLED
    assert inj.pair.nodes[1].setpoint.mode is DriveMode.POSITION
    assert bus.read(1, 0x6041, 0, "H") & 0x1000 == 0  # bit 12 clear: it does not follow the command


def test_drive_faults_time_base_is_the_bus_time_since_power_on():
    """A drive fault with start_s = 0.3 s: on from 0.3 s after the power-on (at t = 5 s), not before."""
    inj, bus, boot = _drive_bus([Fault("mode_not_confirmed", 2, start_s=0.3, duration_s=0.2)], t_on=5.0)
    node = inj.pair.nodes[1]
    seen = []
    for t in (5.1, 5.299, 5.301, 5.49, 5.51):
        inj.tick(t)
        seen.append(node.mode_frozen)
    assert seen == [False, False, True, True, False]
    assert inj.onset_s == {"mode_not_confirmed": pytest.approx(0.301)}
    assert inj.t_power_on == 5.0


@pytest.mark.parametrize("kind,value,message", [
    ("fault_reset_ignored", 0.0, "whole number of fault resets"),
    ("fault_reset_ignored", 2.5, "whole number of fault resets"),
    ("starts_in_fault", 0x10000, "error code"),
    ("sensor_node_silent", 200.0, "node id of a sensor node"),
])
def test_drive_fault_values_are_validated(kind, value, message):
    with pytest.raises(ValueError, match=message):
        Fault(kind, value=value)


#: drive faults (time base: from power-on): fault, the words of the master's refusal before any SYNC (None:
#: the master handles the drive and the check starts with both drives enabled)
DRIVE_CASES = [
    (Fault("ignore_abort_connection", 2), "did not react to the master's death"),
    (Fault("fault_reset_ignored", 2), "still in FAULT after 3 fault resets (canopen.fault_reset_attempts)"),
    (Fault("mode_not_confirmed", 2), "not confirmed by 0x6061 within canopen.mode_change_timeout_s"),
    (Fault("quick_stop_stays", 1), None),
    (Fault("starts_in_fault", 2), None),
    (Fault("fault_reset_ignored", 1, value=3.0), None),
    (Fault("not_ready_until_controlword", 1), None),
]
_REFUSED = [c for c in DRIVE_CASES if c[1] is not None]
_HANDLED = [c[0] for c in DRIVE_CASES if c[1] is None]


@pytest.mark.parametrize("fault,words", _REFUSED, ids=[c[0].kind for c in _REFUSED])
@pytest.mark.slow
def test_drive_fault_is_refused_before_any_sync(tmp_path, profiles, fault, words):
    r, meta = _run(tmp_path, profiles, fault)
    assert r.exit_code == 2 and meta.status == "aborted"
    assert words in meta.reason and f"node {fault.ema} (EMA {fault.ema})" in meta.reason
    assert r.injector.syncs == 0  # no check started
    assert r.injector.onset_s == {fault.kind: 0.0}


@pytest.mark.parametrize("fault", [c[0] for c in _REFUSED], ids=[c[0].kind for c in _REFUSED])
@pytest.mark.slow
def test_a_refused_drive_fault_leaves_every_drive_disabled(tmp_path, profiles, fault):
    r, meta = _run(tmp_path, profiles, fault)
    assert r.exit_code == 2
    assert set(r.injector.final_states()) <= SAFE, r.injector.final_states()


@pytest.mark.parametrize("fault", _HANDLED, ids=[f"{f.kind}-{f.value:g}" for f in _HANDLED])
def test_drive_fault_handled_by_the_master_up_to_operation_enabled(fault):
    """The master's preflight and drill with the faulty drive, up to both drives enabled for the check."""
    from hil.master.link import CanopenLink
    from hil.transport import InProcessTransport
    from support.canopen_rig import make_master

    act = load_actuation()
    inj = FaultInjector(make_pair(RigPlant(load_simrig().params, np.random.default_rng(2))), [fault],
                        record_truth=False)
    tr = InProcessTransport(inj, act.timing.sync_period_s)
    try:
        link = CanopenLink(make_master(), tr)
        link.first_sample()
        record = link.preflight_record()
    finally:
        tr.close()
    assert set(inj.final_states()) == {State.OPERATION_ENABLED}
    drill = record["master_loss"][f"ema{fault.ema}"]["drill"]
    assert drill["outcome"] == "reacted"
    if fault.kind == "quick_stop_stays":  # it stayed there: the master took it out by disable voltage
        assert drill["state_after"] == "QUICK_STOP_ACTIVE"


def test_every_fault_kind_is_covered():
    # master_silent: the master's own death, which the drives handle (consumer heartbeat, 0x6007),
    # not the master: tests/test_master_loss.py asserts their reaction, the truth and the run folder;
    # sensor_node_silent: tests/test_sim_nodes.py (the node) and the sensor-rig dry-run below;
    # the wiring faults: tests/test_commission.py (each named by the commissioning)
    from sim.faults import WIRING_KINDS

    covered = ({c[0].kind for c in CASES} | {c[0].kind for c in DRIVE_CASES}
               | {"node_silent", "sdo_abort", "master_silent", "sensor_node_silent"} | {k.value for k in WIRING_KINDS})
    assert covered == {k.value for k in FaultKind}


def test_the_check_axis_follows_the_bus_time_once_sync_stopped():
    """A fault's window on the check's axis (SYNC count x T) ends when it says also after the check: once
    no SYNC came for more than SYNC_STOPPED_PERIODS periods, the axis is the bus time since SYNC 0."""
    from hil.canopen.frame import sync_frame
    from sim.faults import SYNC_STOPPED_PERIODS

    inj = FaultInjector(make_pair(RigPlant(load_simrig().params, np.random.default_rng(2))),
                        [Fault("bus_errors", 1, 0.004, duration_s=0.006)], rng=np.random.default_rng(3),
                        record_truth=False)
    inj.power_on(0.0)
    for k in range(1, 4):  # SYNC 1..3 at 10.002 .. 10.006 s of bus time: SYNC 0 at 10.000 s
        inj.on_frame(sync_frame(), 10.0 + k * T)
    assert inj.t_check == pytest.approx(3 * T) and len(inj._active(FaultKind.BUS_ERRORS)) == 1
    t_last = 10.0 + 3 * T
    inj.tick(t_last + SYNC_STOPPED_PERIODS * T)  # on the boundary: still the SYNC count
    assert inj.t_check == pytest.approx(3 * T)
    inj.tick(t_last + SYNC_STOPPED_PERIODS * T + 1e-6)  # past it: the bus time since SYNC 0
    assert inj.t_check == pytest.approx(5 * T + 1e-6)
    inj.tick(t_last + 5 * T)
    assert inj.t_check == pytest.approx(8 * T) and inj._active(FaultKind.BUS_ERRORS) == []  # the burst ended
