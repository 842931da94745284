"""Issue 49's targets through the command line, as a new user meets them: a rehearsal that rehearses (the
simulated rig built as ITS OWN actuation profile says, the true one, ``commission --simulate --sim RIG.toml``)
of a profile under test that carries the mistake; the patch applied with ``emacheck profile apply-patch``;
commissioned again READY; ``emacheck dry-run`` of the patched profile on the same rig passing. Also the pieces
that make it hold together: the jog's finding in the patch, each stop keyed, the PC named for a heartbeat lost
while the master's own loop was held, the fitted gear ratio's standard error, the copies of the simulated rig.

The expected numbers come from the mistakes written into the profiles (x 180/pi, x 1/(2 pi), x 10, x 1000, the
load cells' objects exchanged) and the simulated rig's truth (profiles/simrig.toml: i = 5.0265 rad/mm, LVDT
pitch 1.075 and 0.98, so a gear ratio fitted from the LVDTs carries their geometric mean 1.026).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from hil.cli import main
from hil.cli.args import ExitCode
from hil.cli.commission_setup import HEARTBEAT_PC_KEY, STALE_KEY, stale_finding
from hil.master.commission_explain import jog_patched
from hil.master.commission_rules import OPERATOR_KEY, Finding, Kind, Stage, keyed_stops
from hil.master.events import HeartbeatLost
from hil.master.hypotheses import Explanation, Observation, ObsKind, explain
from hil.master.jog_rules import gear_se
from hil.master.stalls import StallWatch, process_held, stall_explains
from hil.profile.load import default_profile_path
from hil.profile.patch import read_patch
from support.figures import figures_unrendered
from support.profiles import write_profile_variant
from support.sensor_rig import sensor_profile

I_TOTAL = 2 * math.pi * 4 / 5  # the simulated rig's gear ratio [rad/mm]
DEG, REV = 180 / math.pi, 1 / (2 * math.pi)


# ------------------------------------------------------------------ pure pieces


def _jog_gear(fits=4.901, key="mechanics.i_total_rad_per_mm"):
    return Finding(Stage.JOG, Kind.GEAR, key, "the rams moved 58.8 times as far", 58.8, "mm/mm", fits)


def _stop(stage=Stage.JOG, key=""):
    return Finding(stage, Kind.STOP, key, "nothing was loaded")


def test_a_jog_finding_with_one_key_and_a_value_goes_into_the_patch():
    ex = Explanation((), (), None, (_jog_gear(), _stop()))
    assert jog_patched(ex, lambda p: None).patch == {"mechanics.i_total_rad_per_mm": 4.901}
    # two keys that fit equally (an LVDT scale or its encoder resolution): no single fix, not patched
    two = _jog_gear(0.00093, "signals.ema1.lvdt.mm_per_unit, signals.ema1.motor_angle.counts_per_rev")
    assert jog_patched(Explanation((), (), None, (two,)), lambda p: None).patch == {}
    # no value fits (neither LVDT moved): nothing; the loader refuses: nothing
    assert jog_patched(Explanation((), (), None, (_jog_gear(None),)), lambda p: None).patch == {}
    assert jog_patched(Explanation((), (), None, (_jog_gear(),)), lambda p: "refused").patch == {}
    # a finding of another stage with a value (a serial read, an identity) is not advice to patch
    serial = Finding(Stage.SCAN, Kind.SERIAL, "canopen.serial_ema1", "another actuator", 1.0, "", "0x5E000101")
    assert jog_patched(Explanation((), (), None, (serial,)), lambda p: None).patch == {}


def test_the_jog_gear_ratio_standard_error_is_half_the_log_spread_of_its_two_gains():
    assert gear_se(4.901, 61.52, 56.12) == pytest.approx(4.901 * math.log(61.52 / 56.12) / 2, rel=1e-12)
    assert gear_se(4.901, 56.12, 61.52) == pytest.approx(gear_se(4.901, 61.52, 56.12), rel=1e-12)  # symmetric
    assert gear_se(5.0, 2.0, 2.0) == 0.0


def _gain(kind, sensor, ema, mover, g):
    tol = 0.10 if kind is ObsKind.LVDT_GAIN else 0.25
    key = f"signals.ema{ema}.{sensor}"
    return Observation(kind, sensor, ema, mover, g, tol, "mm/mm" if sensor == "lvdt" else "N/N", key, 1e-4)


def test_the_hypotheses_gear_ratio_carries_the_standard_error_of_its_gains_spread():
    c = 1.25
    lv = {1: 1.075 * c, 2: 0.98 * c}  # the LVDTs' pitch on top of the gear ratio
    obs = (_gain(ObsKind.LVDT_GAIN, "lvdt", 1, 1, lv[1]), _gain(ObsKind.LVDT_GAIN, "lvdt", 2, 2, lv[2]),
           _gain(ObsKind.FORCE_GAIN, "force", 1, 1, 1 / c), _gain(ObsKind.FORCE_GAIN, "force", 2, 1, -1 / c),
           _gain(ObsKind.FORCE_GAIN, "force", 1, 2, -1 / c), _gain(ObsKind.FORCE_GAIN, "force", 2, 2, 1 / c))
    ex = explain(obs, (), scales={("lvdt", a): 0.001 for a in (1, 2)} | {("force", a): 0.1 for a in (1, 2)},
                 i_total=I_TOTAL)
    logs = [math.log(lv[1]), math.log(lv[2])] + [-math.log(1 / c)] * 4
    m = sum(logs) / 6
    s = math.sqrt(sum((x - m) ** 2 for x in logs) / 5)
    k = math.exp(m)
    assert ex.accepted.fitted["gear_factor"] == pytest.approx(k, rel=1e-6)
    assert ex.accepted.fitted["gear_factor_se"] == pytest.approx(k * s / math.sqrt(6), abs=5e-7)  # (to 6 places)
    (f,) = ex.findings
    se = f.fits * s / math.sqrt(6)  # SE(i / c) = (i / c) SE(c) / c
    assert f.kind is Kind.GEAR and f"standard error {se:.2g} rad/mm, from the 6 gains' spread" in f.text


def test_a_stop_names_the_keys_of_what_stopped_it_and_ctrl_c_the_operator():
    dead = Finding(Stage.AT_REST, Kind.DEAD, "signals.ema1.lvdt", "dead")
    noise = Finding(Stage.AT_REST, Kind.NOISE, "sensors.loadcell_noise_std_N", "noisy")
    serial = Finding(Stage.SCAN, Kind.SERIAL, "canopen.serial_ema1", "another")
    got = keyed_stops([serial, dead, noise, dead, _stop(Stage.AT_REST)])
    assert got[-1].key == "signals.ema1.lvdt, sensors.loadcell_noise_std_N"  # its own stage's, each once
    assert keyed_stops([serial, _stop(Stage.JOG)])[-1].key == "canopen.serial_ema1"  # else all before it
    assert keyed_stops([_stop()])[0].key == ""  # nothing to name
    assert keyed_stops([dead, _stop(Stage.AT_REST, OPERATOR_KEY)])[-1].key == OPERATOR_KEY  # its own kept


def test_ctrl_c_is_keyed_to_the_operator_in_the_core():
    from hil.cli.check import master_setup
    from hil.master.commission import Commission
    from hil.profile.load import load_actuation, load_check

    act = load_actuation(None)
    core = Commission(act, load_check(None, act), master_setup(act, None).plan)
    core.failed(KeyboardInterrupt())
    assert [(f.kind, f.key) for f in core.findings] == [(Kind.STOP, OPERATOR_KEY)]


def _lost(at=10.0, silent=0.151, overdue=0.05, frames=0.004):
    return HeartbeatLost("EMA 1: heartbeat lost", key="canopen.heartbeat_period_s", at_s=at, silent_s=silent,
                         overdue_s=overdue, frames_silent_s=frames)


def test_a_node_silent_altogether_for_the_overdue_margin_is_its_process_held():
    assert process_held(0.05, 0.05) and not process_held(math.nextafter(0.05, 0.0), 0.05)
    assert not process_held(math.nan, 0.05)


def test_on_a_software_bus_a_node_silent_altogether_names_the_pc_on_a_real_bus_never():
    base = Finding(Stage.MOVE, Kind.STOP, "canopen.heartbeat_period_s", "HeartbeatLost: EMA 1: heartbeat lost")
    held = _lost(frames=0.06)  # no statusword for 60 ms either: the node's process was not run
    pc = stale_finding(base, held, 0, (), "udp_multicast")
    assert pc.key == HEARTBEAT_PC_KEY and "sent nothing at all" in pc.text and "60 ms" in pc.text
    assert stale_finding(base, held, 0, (), "socketcan") is base  # a real drive silent: its power, its cable
    assert stale_finding(base, _lost(frames=0.049), 0, (), "udp_multicast") is base  # shorter: the node
    assert stale_finding(base, _lost(frames=0.004), 0, (), "virtual") is base  # TPDOs came: its heartbeat


def test_a_stall_explains_a_heartbeat_lost_from_the_overdue_margin_on_and_within_the_silence():
    at, silent, over = 10.0, 0.151, 0.05

    def ok(b, n, at_s=at):
        return stall_explains([(b, n)], at_s, silent, over) == (b, n)

    assert ok(9.9, over)  # held exactly as long as a heartbeat may be overdue
    assert not ok(9.9, math.nextafter(over, 0.0))  # a float step shorter
    assert ok(at - silent - over, over)  # ends where the silence begins
    assert not ok(at - silent - over - 1e-9, over)  # ended before it
    assert ok(at, over) and not ok(at + 1e-9, over)  # begins when it was judged lost, or after
    assert stall_explains((), at, silent, over) is None and not ok(9.9, 1.0, math.nan)
    # not only the latest: the longest of the recent stalls that explains it (short ones came after it)
    assert stall_explains([(9.0, 0.2), (9.9, 0.08), (9.95, 0.003), (9.99, 0.004)], at, silent, over) == (9.9, 0.08)


def test_a_heartbeat_lost_names_the_pc_only_where_the_masters_loop_was_held():
    base = Finding(Stage.MOVE, Kind.STOP, "canopen.heartbeat_period_s", "HeartbeatLost: EMA 1: heartbeat lost")
    pc = stale_finding(base, _lost(), 0, [(9.95, 0.08), (10.0, 0.003)])
    assert pc.key == HEARTBEAT_PC_KEY and "held 80 ms" in pc.text and "--rt-priority N" in pc.text
    rt = stale_finding(base, _lost(), 50, [(9.95, 0.08)])
    assert "SCHED_FIFO 50" in rt.text and "check the node's heartbeat (canopen.heartbeat_period_s)" in rt.text
    assert stale_finding(base, _lost(), 0, [(9.95, 0.02)]) is base  # a shorter hold: the node, not the PC
    assert stale_finding(base, _lost(), 0, ()) is base
    assert STALE_KEY != HEARTBEAT_PC_KEY


def test_the_stall_watch_keeps_the_recent_stalls_open_or_closed_at_most_its_bound():
    from hil.master.stalls import RECENT_STALLS

    w = StallWatch(0.002)
    assert w.recent == ()
    w.observe(1.0, 0.01)
    w.observe(1.002, 0.03)
    assert w.recent == ((1.0, 0.03),)  # still open
    w.on_time()
    w.observe(2.0, 0.004)
    w.on_time()
    assert w.recent == ((1.0, 0.03), (2.0, 0.004)) and w.count == 2
    for k in range(RECENT_STALLS):
        w.observe(3.0 + k, 0.005)
        w.on_time()
    assert len(w.recent) == RECENT_STALLS and w.recent[0] == (3.0, 0.005) and w.count == RECENT_STALLS + 2


def test_the_seed_help_says_where_each_command_records_it(capsys):
    for cmd, where in (("commission", "recorded in commission.json"), ("dry-run", "recorded in meta.json")):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        seed = text[text.index("--seed SEED noise seed"):][:200]
        assert where in seed, (cmd, seed)


# ------------------------------------------------------------------ the targets through the command line (slow)


def _rig(base: Path, true: Path) -> Path:
    """A simulated-rig profile (the shipped one's plant, seed, serials) built as ``true`` says."""
    text = default_profile_path("simrig.toml").read_text()
    rig = base / f"rig-{true.stem}.toml"
    rig.write_text(text.replace('actuation = "actuation.toml"', f'actuation = "{true.name}"'))
    return rig


def _io_swapped(base: Path) -> tuple[Path, Path]:
    true = sensor_profile(base / "true-io.toml")
    text = true.read_text()
    a, b = '"0x6401:02"', '"0x6401:04"'  # EMA 1's and EMA 2's load cells on the CiA 401 node
    wrong = base / "loadcells-swapped.toml"
    wrong.write_text(text.replace(a, "@").replace(b, a).replace("@", b))
    return true, wrong


def _shipped_variant(base: Path, name: str, over: dict) -> tuple[Path, Path]:
    true = base / "true.toml"
    if not true.exists():
        true.write_bytes(default_profile_path("actuation.toml").read_bytes())
    return true, write_profile_variant("actuation.toml", base / f"{name}.toml", over)


def _gear(f):
    return {"mechanics": {"i_total_rad_per_mm": I_TOTAL * f}, "canopen": {"gear_ratio_object": ""}}


CASES = {
    # name: (profile overrides of the shipped one (None: the sensor node's load cells swapped), stage, kind, key,
    #        the value that fits, its relative tolerance)
    "gear x57": (_gear(DEG), "jog", "gear ratio", "mechanics.i_total_rad_per_mm", I_TOTAL, 0.05),
    "gear x0.16": (_gear(REV), "jog", "gear ratio", "mechanics.i_total_rad_per_mm", I_TOTAL, 0.05),
    "gear x1.25": (_gear(1.25), "move", "gear ratio", "mechanics.i_total_rad_per_mm", I_TOTAL, 0.05),
    "lvdt x10": ({"signals": {"ema1": {"lvdt": {"mm_per_unit": 0.01}}}}, "at rest", "unit error",
                 "signals.ema1.lvdt.mm_per_unit", 0.001, 1e-12),
    "lvdt x1000": ({"signals": {"ema1": {"lvdt": {"mm_per_unit": 1.0}}}}, "at rest", "unit error",
                   "signals.ema1.lvdt.mm_per_unit", 0.001, 1e-12),
    "load cell x10": ({"signals": {"ema2": {"force": {"N_per_unit": 1.0}}}}, "at rest", "unit error",
                      "signals.ema2.force.N_per_unit", 0.1, 1e-12),
    "load cell x1000": ({"signals": {"ema2": {"force": {"N_per_unit": 100.0}}}}, "at rest", "unit error",
                        "signals.ema2.force.N_per_unit", 0.1, 1e-12),
    "load cells swapped": (None, "force step", "swapped", "signals.ema1.force, signals.ema2.force", None, None),
}


def _report(folder: Path) -> dict:
    return json.loads((folder / "commission.json").read_text())


class _Targets(dict):
    """Each case's commission, patch, commission again and dry-run, made when a test first asks for it (a soak
    case is made only where soak tests run)."""

    def __init__(self, base: Path):
        super().__init__()
        self.base = base

    def __missing__(self, name: str) -> dict:
        base, (over, *_rest) = self.base, CASES[name]
        true, wrong = _io_swapped(base) if over is None else _shipped_variant(base, name.replace(" ", "-"), over)
        rig = _rig(base, true)
        d = base / name.replace(" ", "-")
        fixed = d / "fixed.toml"
        # the reports' figures built, not drawn: these tests read commission.json, the patch and meta.json
        # (test_commission.py and test_dry_run.py draw both reports)
        with figures_unrendered():
            rc1 = main(["commission", str(wrong), "--simulate", "--sim", str(rig), "--out", str(d / "c1")])
            rcp = main(["profile", "apply-patch", str(wrong), str(d / "c1" / "profile.patch.toml"),
                        "--out", str(fixed)])
            rc2 = main(["commission", str(fixed), "--simulate", "--sim", str(rig), "--out", str(d / "c2")])
            rcd = main(["dry-run", "--profile", str(fixed), "--sim", str(rig), "--out", str(d / "dry"), "--quiet"])
        self[name] = {"rc": (rc1, rcp, rc2, rcd), "dir": d, "rig": rig, "true": true, "wrong": wrong}
        return self[name]


@pytest.fixture(scope="module")
def targets(tmp_path_factory):
    return _Targets(tmp_path_factory.mktemp("targets"))


#: the cases that repeat another's path with another factor (x0.16 as x57 in the jog, x10 as x1000 at rest):
#: soak tests, run on request (python -m pytest -m soak), so that the default run stays within its time
SOAK = ("gear x0.16", "lvdt x10", "load cell x1000")


def _params(names):
    return [pytest.param(n, marks=pytest.mark.soak) if n in SOAK else n for n in names]


@pytest.mark.slow
@pytest.mark.parametrize("name", _params(CASES))
def test_each_mistake_named_once_patched_ready_and_the_dry_run_passes(targets, name):
    _, stage, kind, key, fits, rel = CASES[name]
    t = targets[name]
    assert t["rc"] == (ExitCode.NOT_READY, 0, ExitCode.PASS, ExitCode.PASS), name
    first = _report(t["dir"] / "c1")
    problems = [f for f in first["findings"] if f["kind"] != "stopped"]
    assert [(f["stage"], f["kind"], f["key"]) for f in problems] == [(stage, kind, key)]  # one finding, not four
    assert all(f["key"] for f in first["findings"])  # every finding keyed, the stops too
    if fits is not None:
        assert problems[0]["fits"] == pytest.approx(fits, rel=rel)
        assert read_patch(t["dir"] / "c1" / "profile.patch.toml") == {key: problems[0]["fits"]}
    else:  # the swap: the patch exchanges the two objects on the sensor node
        assert read_patch(t["dir"] / "c1" / "profile.patch.toml") == {
            "signals.ema1.force.object": "0x6401:02", "signals.ema2.force.object": "0x6401:04"}
    assert first["simulated_rig"]["simulated_rig_actuation"] == str(t["true"])
    for copy, src in (("simulated-rig.toml", t["rig"]), ("simulated-rig-actuation.toml", t["true"]),
                      ("judged-actuation.toml", t["wrong"])):
        assert (t["dir"] / "c1" / copy).read_bytes() == src.read_bytes(), copy
    again = _report(t["dir"] / "c2")
    assert again["status"] == "ready" and again["findings"] == []
    meta = json.loads((t["dir"] / "dry" / "meta.json").read_text())
    assert "simulated_rig_actuation" in meta["files_sha256"]  # the dry-run ran on the rig's own profile


@pytest.mark.slow
@pytest.mark.parametrize("name", _params(["gear x57", "gear x0.16"]))
def test_a_wrong_gear_ratio_stops_in_the_jog_below_a_tenth_of_the_force_limit(targets, name):
    first = _report(targets[name]["dir"] / "c1")
    jog = first["measured"]["jog"]
    assert jog["stop"] and jog["peak_force_change_N"] < 0.1 * first["limits"]["max_force_N"]
    assert "lvdt_gain" not in first["measured"] or first["measured"]["lvdt_gain"] == {}  # nothing loaded
    f = first["findings"][0]
    assert "standard error" in f["text"] and ("degrees" if "57" in name else "revolutions") in f["text"]


@pytest.mark.slow
def test_the_gear_ratio_passing_the_jog_is_named_once_by_the_hypotheses_not_by_the_jog(targets):
    first = _report(targets["gear x1.25"]["dir"] / "c1")
    jog = first["measured"]["jog"]
    assert not jog["stop"] and all(g["confirms"] for g in jog["gains"].values())  # the jog let x1.25 through
    assert first["hypotheses"]["accepted"] == "gear ratio"
    assert [f["stage"] for f in first["findings"]] == ["move"]  # no jog finding beside it


@pytest.mark.slow
def test_the_dry_run_on_the_rigs_own_profile_refuses_the_unpatched_mistake(targets, tmp_path):
    """The dry-run of the mistaken profile on the same simulated rig does not pass: its simulated nodes are the
    rig's (the true scaling), not the profile's, so the mistake shows (before, a rig built as the profile under
    test passed whatever scaling it said)."""
    t = targets["lvdt x1000"]
    rc = main(["dry-run", "--profile", str(t["wrong"]), "--sim", str(t["rig"]), "--out", str(tmp_path / "d"),
               "--quiet"])
    assert rc != ExitCode.PASS


@pytest.mark.slow
def test_a_heartbeat_lost_in_simulated_time_is_keyed_to_the_nodes_heartbeat_not_the_pc(tmp_path):
    """A drive whose heartbeat stops (the simulated rig's [[faults]]) while nothing holds the master's loop (in
    process, simulated time: no stall): the node is named, ``canopen.heartbeat_period_s``, not the PC."""
    rig = write_profile_variant("simrig.toml", tmp_path / "rig.toml",
                                add={"faults": [{"kind": "heartbeat_stop", "ema": 1, "start_s": 1.0}]})
    rc = main(["commission", "--simulate", "--sim", str(rig), "--out", str(tmp_path / "c")])
    f = _report(tmp_path / "c")["findings"]
    assert rc == ExitCode.NOT_READY and [(x["kind"], x["key"]) for x in f] == [
        ("stopped", "canopen.heartbeat_period_s")]
    assert "HeartbeatLost" in f[0]["text"] and "PC" not in f[0]["text"]


def test_a_drive_that_lost_the_masters_heartbeat_names_the_pc_where_the_loop_was_held_the_consumer_margin():
    """EMCY 0x8130 from a drive: the master's heartbeat (sent from its loop every 50 ms) missed the drive's
    consumer time (125 ms); a loop held at least 125 - 50 = 75 ms within those 125 ms explains it."""
    from hil.canopen.emcy import Emcy
    from hil.master.events import DriveFault
    from hil.profile.load import load_actuation

    c = load_actuation(None).canopen
    margin = c.master_consumer_time_s - c.master_heartbeat_period_s
    assert margin == pytest.approx(0.075)
    fault = DriveFault("node 1: EMCY 0x8130", emcy=Emcy(4.55, 1, 0x8130, 0x11, bytes(5)))
    base = Finding(Stage.JOG, Kind.STOP, "safety", "DriveFault: node 1: EMCY 0x8130 (life guard or heartbeat)")
    pc = stale_finding(base, fault, 0, [(4.426, margin)], "udp_multicast", c)
    assert pc.key == HEARTBEAT_PC_KEY and "lost the master's heartbeat" in pc.text
    rt = stale_finding(base, fault, 50, [(4.426, margin)], "udp_multicast", c)
    assert "SCHED_FIFO 50" in rt.text and "check the drives' consumer heartbeat" in rt.text
    assert stale_finding(base, fault, 0, [(4.426, math.nextafter(margin, 0.0))], "udp_multicast", c) is base
    assert stale_finding(base, fault, 0, [(4.426, margin)], "udp_multicast", None) is base  # no profile: no rule
    other = DriveFault("node 1: EMCY 0x4310", emcy=Emcy(4.55, 1, 0x4310, 0x09, bytes(5)))
    assert stale_finding(base, other, 0, [(4.426, 0.2)], "udp_multicast", c) is base  # another fault: the drive's


def test_the_pc_rules_take_a_fault_on_the_masters_clock_to_the_stalls_axis():
    """The master's stalls are on the samples' axis (SYNC periods since the cyclic phase began), a heartbeat lost
    or an EMCY on the master's clock (since the preflight began, 2.4 s earlier here): compared as they come, the
    113 ms hold just before an EMCY 0x8130 lies 2.4 s away from it and explains nothing."""
    from hil.canopen.cycle import SyncSchedule
    from hil.canopen.emcy import Emcy
    from hil.master.events import DriveFault
    from hil.profile.load import load_actuation

    c = load_actuation(None).canopen
    sched = SyncSchedule(0.002)
    for k in range(8235):  # the first SYNC of the cyclic phase at 2.4 s on the master's clock: 8235 periods
        sched.on_sync(2.4 + k * 0.002)
    assert sched.on_axis(2.4 + 8234 * 0.002) == pytest.approx(sched.t_s) and sched.t_s == pytest.approx(16.47)
    assert sched.on_axis(18.95) == pytest.approx(16.552)
    fault = DriveFault("node 1: EMCY 0x8130", emcy=Emcy(18.95, 1, 0x8130, 0x11, bytes(5)))
    base = Finding(Stage.LOAD, Kind.STOP, "safety", "DriveFault: node 1: EMCY 0x8130 (life guard or heartbeat)")
    stalls = [(16.468, 0.113)]
    assert stale_finding(base, fault, 0, stalls, "udp_multicast", c, sched.on_axis).key == HEARTBEAT_PC_KEY
    assert stale_finding(base, fault, 0, stalls, "udp_multicast", c) is base  # on the wrong axis: nothing
    lost = _lost(at=18.95, silent=0.151, overdue=0.05, frames=0.004)
    assert stale_finding(base, lost, 0, [(16.50, 0.06)], "socketcan", c, sched.on_axis).key == HEARTBEAT_PC_KEY
    assert stale_finding(base, lost, 0, [(16.50, 0.06)], "socketcan", c) is base
    assert SyncSchedule(0.002).on_axis(1.25) == 1.25  # before the first SYNC: the master's clock
