"""emacheck commission (issue 36 part 6): the rules of hil/master/commission.py at their boundaries, and the
whole commissioning over CANopen against the simulated rig, clean and with each wiring fault.

The end-to-end cases run once each (module-scoped) and are marked slow; the expected numbers come from the
simulated-rig profile (profiles/simrig.toml: LVDT gains 1.075 and 0.98, load-cell gains 1.0) and the
profile's scalings (mm_per_unit 0.001, N_per_unit 0.1), never from a run.
"""

from __future__ import annotations

import argparse
import json
import tomllib
from importlib import resources
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import tomli_w

from hil.canopen.frame import Frame
from hil.canopen.sdo import SdoAbortError, SdoTimeout
from hil.cli import main
from hil.cli.args import ExitCode
from hil.cli.check import master_setup
from hil.cli.commission import commission
from hil.cli.commission_setup import simulated_transport, wiring_fault
from hil.master.commission import TRANSITIONS, Commission, CommissionMaster, CommissionStop, Scan
from hil.master.commission_rules import (
    DEAD_FRACTION,
    FORCE_GAIN_TOLERANCE,
    MIN_MOTION_FRACTION,
    MIN_STEP_MOTION_MM,
    NOISE_FACTOR,
    Kind,
    Limits,
    Stage,
    drives_swapped,
    force_findings,
    lvdt_findings,
    push_findings,
    rest_findings,
    swap_findings,
)
from hil.master.preflight import Nmt, Now, SdoRead, Wait
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE
from hil.profile.load import default_profile_path, load_actuation, load_check, load_simrig
from sim.faults import Fault
from support.eds import write_eds_variant
from support.profiles import write_profile_variant
from support.sensor_rig import sensor_profile, sensor_rig

ACT = load_actuation(None)
CHECK = load_check(None, ACT)
SIMRIG = load_simrig(None)
PLAN = master_setup(ACT, None).plan
LIM = Limits.of(CHECK)
I_TOTAL = ACT.mechanics.i_total_rad_per_mm
#: the simulated LVDTs' pitch (profiles/simrig.toml sensors1/2.lvdt_gain): what the slope must find
G_LVDT = {1: SIMRIG.params.sensors1.lvdt_gain, 2: SIMRIG.params.sensors2.lvdt_gain}
SCHEMA = json.loads(resources.files("hil.schemas").joinpath("commission.schema.json").read_text())


# ------------------------------------------------------------------ the limits and the rules (fast)


def test_limits_are_a_quarter_of_the_check_and_below_it():
    cal = CHECK.calibration
    assert LIM.force_N == 0.25 * cal.opposing_force_N == 500.0
    assert LIM.speed_mm_per_s == 0.25 * cal.sweep_speed_mm_per_s == 0.5
    assert LIM.travel_mm == min(1.0, 0.1 * cal.sweep_amplitude_mm) == 1.0
    assert LIM.max_force_N == min(4 * LIM.force_N, CHECK.safety.max_force_N) == 2000.0
    assert 2 * LIM.force_N <= 0.5 * cal.opposing_force_N  # the step's peak: half the check's opposing force


def test_every_stage_has_its_transitions_and_the_ends_none():
    assert set(TRANSITIONS) == set(Stage)
    assert TRANSITIONS[Stage.DONE] == TRANSITIONS[Stage.STOPPED] == frozenset()
    assert all(Stage.STOPPED in v for k, v in TRANSITIONS.items() if k not in (Stage.DONE, Stage.STOPPED))


def _rest(n=250, seed=1, **over):
    rng = np.random.default_rng(seed)
    x = {"phi1": np.zeros(n), "phi2": np.zeros(n),
         "s1": 0.3 + np.round(rng.uniform(-0.0125, 0.0125, n), 3),
         "s2": -0.2 + np.round(rng.uniform(-0.0125, 0.0125, n), 3),
         "F1": np.round(rng.normal(0, 10, n), 1), "F2": np.round(rng.normal(0, 10, n), 1)}
    x.update(over)
    return x


def test_rest_clean_has_no_finding():
    assert rest_findings(_rest(), ACT, CHECK, LIM, PLAN) == []


def test_rest_frozen_run_at_the_limit_passes_one_more_is_dead():
    m = CHECK.safety.max_frozen_cycles
    for run, dead in ((m, False), (m + 1, True)):
        s1 = _rest()["s1"].copy()
        s1[100:100 + run] = 0.3005  # a value no neighbour has
        got = rest_findings(_rest(s1=s1), ACT, CHECK, LIM, PLAN)
        assert [(f.kind, f.key) for f in got] == ([(Kind.DEAD, "signals.ema1.lvdt")] if dead else []), run


def test_rest_noise_at_the_factor_passes_above_is_named_with_the_fitting_value():
    declared = ACT.sensors.lvdt_noise_pp_mm
    for ptp, named in ((NOISE_FACTOR * declared * 0.999, False), (NOISE_FACTOR * declared * 1.01, True)):
        s2 = -0.2 + np.linspace(-ptp / 2, ptp / 2, 250)[np.random.default_rng(2).permutation(250)]
        got = rest_findings(_rest(s2=s2), ACT, CHECK, LIM, PLAN)
        assert [(f.kind, f.key) for f in got] == ([(Kind.NOISE, "sensors.lvdt_noise_pp_mm")] if named else [])
        if named:
            assert got[0].fits == pytest.approx(ptp, rel=1e-2)


def test_rest_load_cell_offset_beyond_the_commissioning_force_fits_an_offset():
    for mean, named in ((LIM.force_N - 20, False), (LIM.force_N + 60, True)):
        got = rest_findings(_rest(F2=_rest()["F2"] + mean), ACT, CHECK, LIM, PLAN)
        assert [(f.kind, f.key) for f in got] == ([(Kind.OFFSET, "signals.ema2.force.offset_N")] if named else [])
        if named:
            assert got[0].fits == pytest.approx(-mean, abs=2.0)  # the shipped offset_N is 0


def _moved(g1: float, g2: float, k: int = 1, travel: float = 1.0) -> dict:
    x = np.concatenate([np.linspace(0, travel, 500), np.linspace(travel, 0, 500)])
    return {"phi1": x * I_TOTAL, "phi2": x * I_TOTAL, "s1": g1 * x + 0.3, "s2": g2 * x - 0.2, "F1": x * 0, "F2": x * 0}


TOL = HARD_LVDT_GAIN_TOLERANCE


@pytest.mark.parametrize("g,kind", [(1 + TOL - 1e-3, None), (1 + TOL + 1e-3, Kind.SCALE), (1 - TOL + 1e-3, None),
                                    (1 - TOL - 1e-3, Kind.SCALE), (-1.0, Kind.SIGN), (0.0, Kind.DEAD)])
def test_lvdt_gain_boundaries_and_the_fitting_scale(g, kind):
    got, gains = lvdt_findings(_moved(1.0, g), 1, ACT, LIM, PLAN)
    assert [f.kind for f in got] == ([] if kind is None else [kind])
    assert gains["ema1"] == pytest.approx(1.0)
    if kind in (Kind.SCALE, Kind.SIGN):
        assert got[0].key == "signals.ema2.lvdt.mm_per_unit"
        assert got[0].fits == pytest.approx(0.001 / g, rel=1e-3)


def test_a_motor_that_does_not_move_is_named_and_its_lvdt_not_judged():
    got, gains = lvdt_findings(_moved(1.0, 1.0, travel=(MIN_MOTION_FRACTION - 0.01) * LIM.travel_mm), 1, ACT, LIM,
                               PLAN)
    assert [(f.kind, f.key) for f in got] == [(Kind.STILL, "signals.ema1.motor_angle")]
    assert gains == {}
    got, gains = lvdt_findings(_moved(1.0, 1.0, travel=(MIN_MOTION_FRACTION + 0.01) * LIM.travel_mm), 1, ACT, LIM,
                               PLAN)
    assert got == [] and gains == pytest.approx({"ema1": 1.0, "ema2": 1.0})


def test_an_lvdt_that_hardly_follows_is_dead_not_a_scale():
    for g, kind in ((0.99 * DEAD_FRACTION, Kind.DEAD), (1.01 * DEAD_FRACTION, Kind.SCALE)):
        got, _ = lvdt_findings(_moved(g, 1.0), 1, ACT, LIM, PLAN)
        assert [f.kind for f in got] == [kind]


def test_a_load_cell_that_hardly_changes_is_dead_not_a_scale():
    for rel, kind in ((0.99 * DEAD_FRACTION, Kind.DEAD), (1.01 * DEAD_FRACTION, Kind.SCALE)):
        got, _ = force_findings({"F1": 0.0, "F2": 0.0}, {"F1": 500.0 * rel, "F2": -500.0}, 1, 500.0, PLAN)
        assert [(f.kind, f.key.split(".")[1]) for f in got] == [(kind, "ema1")]


def test_rest_a_motor_angle_that_wanders_is_named():
    e = LIM.max_following_error_mm
    for ptp, named in ((0.99 * e, False), (1.01 * e, True)):
        phi2 = np.linspace(0.0, ptp * I_TOTAL, 250)
        got = rest_findings(_rest(phi2=phi2), ACT, CHECK, LIM, PLAN)
        assert [(f.kind, f.key) for f in got] == ([(Kind.RANGE, "signals.ema2.motor_angle")] if named else [])


def test_rest_lvdt_beyond_the_stroke_range_is_named():
    lim_mm = min(ACT.sensors.lvdt_full_scale_mm, ACT.mechanics.stroke_limit_mm)
    for mean, named in ((lim_mm - 0.05, False), (lim_mm + 0.05, True)):
        got = rest_findings(_rest(s1=_rest()["s1"] - 0.3 + mean), ACT, CHECK, LIM, PLAN)
        assert [(f.kind, f.key) for f in got] == ([(Kind.RANGE, "signals.ema1.lvdt")] if named else [])


FTOL = FORCE_GAIN_TOLERANCE


@pytest.mark.parametrize("rel,kind", [(1 + FTOL - 1e-3, None), (1 + FTOL + 1e-3, Kind.SCALE), (1 - FTOL + 1e-3, None),
                                      (1 - FTOL - 1e-3, Kind.SCALE), (-1.0, Kind.SIGN), (0.01, Kind.DEAD)])
def test_load_cell_gain_boundaries_against_the_torque(rel, kind):
    before = {"F1": -500.0, "F2": 500.0}
    after = {"F1": -1000.0, "F2": 500.0 + 500.0 * rel}  # EMA 2 pushes +500 N: F2 +500 x rel, F1 -500
    got, gains = force_findings(before, after, 2, 500.0, PLAN)
    assert [f.kind for f in got] == ([] if kind is None else [kind])
    assert gains == pytest.approx({"ema2": rel, "ema1": -1.0})
    if kind in (Kind.SCALE, Kind.SIGN):
        assert got[0].key == "signals.ema2.force.N_per_unit"
        assert got[0].fits == pytest.approx(0.1 / rel, rel=1e-3)


def test_push_rule_of_a_rig_without_cst():
    before = {"F1": 0.0, "F2": 0.0}
    for ratio, kind in ((1 + FTOL - 1e-3, None), (1 + FTOL + 1e-3, Kind.SCALE), (1 - FTOL + 1e-3, None),
                        (1 - FTOL - 1e-3, Kind.SCALE)):
        got, d = push_findings(before, {"F1": 500.0, "F2": -500.0 * ratio}, 1, 500.0, PLAN)  # EMA 1 pushed
        assert [f.kind for f in got] == ([] if kind is None else [kind]), ratio
        assert d == pytest.approx({"ema1": 500.0, "ema2": -500.0 * ratio})
    (f,) = push_findings(before, {"F1": -500.0, "F2": -500.0}, 1, 500.0, PLAN)[0]
    assert (f.kind, f.key, f.fits) == (Kind.SIGN, "signals.ema1.force.N_per_unit", -0.1)
    (f,) = push_findings(before, {"F1": 500.0, "F2": -0.99 * DEAD_FRACTION * 500.0}, 1, 500.0, PLAN)[0]
    assert (f.kind, f.key) == (Kind.DEAD, "signals.ema2.force")
    (f,) = push_findings(before, {"F1": 0.99 * DEAD_FRACTION * 500.0, "F2": 0.0}, 1, 500.0, PLAN)[0]
    assert (f.kind, f.key) == (Kind.DEAD, "signals.ema1.force, signals.ema2.force")


def test_swap_rule():
    ok = {1: (0.07, 0.063, 0.006), 2: (0.07, 0.068, 0.007)}
    assert swap_findings(ok, PLAN) == []
    swapped = {1: (0.07, 0.006, 0.063), 2: (0.07, 0.007, 0.068)}
    (f,) = swap_findings(swapped, PLAN)
    assert f.kind is Kind.SWAPPED and f.key == "signals.ema1.lvdt, signals.ema2.lvdt"
    assert f.fits == "signals.ema1.lvdt = 0x2100:00 at ema2; signals.ema2.lvdt = 0x2100:00 at ema1"
    (one,) = swap_findings({1: swapped[1], 2: ok[2]}, PLAN)
    assert one.key == "signals.ema1.lvdt" and one.fits is None
    # too little motion to judge; a wrong LVDT scale (gain 0.1) is divided out, not taken for a swap
    assert swap_findings({j: (MIN_STEP_MOTION_MM * 0.99, *v[1:]) for j, v in swapped.items()}, PLAN) == []
    assert len(swap_findings({j: (MIN_STEP_MOTION_MM * 1.01, *v[1:]) for j, v in swapped.items()}, PLAN)) == 1
    scaled = {1: (0.07, 0.0063, 0.0065), 2: (0.07, 0.068, 0.0007)}
    assert swap_findings(scaled, PLAN, {1: 0.1, 2: 1.0}) == []
    assert swap_findings(scaled, PLAN) != []


def test_drives_at_each_others_node_id_only_where_the_sensors_are_on_a_node_of_their_own(tmp_path):
    swapped = {1: (0.07, 0.006, 0.063), 2: (0.07, 0.007, 0.068)}
    signs = force_findings({"F1": 0.0, "F2": 0.0}, {"F1": -500.0, "F2": 500.0}, 1, 500.0, PLAN)[0]
    assert [f.kind for f in signs] == [Kind.SIGN, Kind.SIGN]
    found = swap_findings(swapped, PLAN) + signs
    assert drives_swapped(found, PLAN) == found  # sensors on the drives' inputs: nothing to tell
    plan = sensor_rig(tmp_path / "sensors.toml")[1].plan
    found = swap_findings(swapped, plan) + force_findings({"F1": 0.0, "F2": 0.0}, {"F1": -500.0, "F2": 500.0}, 1,
                                                          500.0, plan)[0]
    (merged,) = drives_swapped(found, plan)
    assert merged.key == "canopen.node_id_ema1, canopen.node_id_ema2"
    assert merged.fits == "canopen.node_id_ema1 = 2; canopen.node_id_ema2 = 1"
    assert drives_swapped(found[1:], plan) == found[1:]  # one load cell's sign alone: not the drives


def _drive_scan(scan: Scan, answer) -> list:
    """Run the scan's generator by hand (sans-IO): ``answer(request)`` gives each SDO read's result."""
    g, asked = scan.run(), []
    req = next(g)
    try:
        while True:
            asked.append(req)
            if isinstance(req, SdoRead):
                req = g.send(answer(req))
            elif isinstance(req, Now):
                req = g.send(0.0)
            elif isinstance(req, Wait):
                req = g.send(req.until_s)
            else:
                req = g.send(True)
    except StopIteration:
        return asked


def test_scan_names_each_problem_with_its_key_and_the_value_read():
    scan = Scan(PLAN, 2.0, 127)
    scan.hear(Frame(0x705, b"\x00"))  # a boot-up of node 5
    scan.hear(Frame(0x77F, b"\x05"))  # the master's own heartbeat is not a node of the rig
    values = {(0x1000, 0): 0x00020192, (0x1018, 1): 0x0E3A, (0x1018, 2): 0x0403, (0x1018, 3): 0x0000FFFF,
              (0x6041, 0): 0x0040}

    def answer(req):
        if req.node == 2:
            return SdoTimeout(2, req.index, req.sub, 0.5, Frame(0x602, bytes(8)))
        if (req.index, req.sub) == (0x1018, 4):  # no serial number: optional, not compared
            return SdoAbortError(1, 0x1018, 4, 0x06090011)
        return values[(req.index, req.sub)].to_bytes(4, "little")

    with pytest.raises(CommissionStop):
        _drive_scan(scan, answer)
    got = [(f.kind, f.key, f.fits) for f in scan.findings]
    assert got == [(Kind.IDENTITY, "canopen.product_code", "0x00000403"),
                   (Kind.IDENTITY, "canopen.revision_min", "0x0000FFFF"),
                   (Kind.ELSEWHERE, "canopen.node_id_ema2", 5)]
    assert scan.heard == {5} and scan.nodes[1]["state"] == "SWITCH_ON_DISABLED"
    assert scan.nodes[1]["identity"]["serial"] is None and scan.nodes[2]["answers"] is False


def test_scan_of_a_rig_as_the_profile_says_finds_nothing_and_a_missing_sub_index_is_not_compared():
    scan = Scan(PLAN, 2.0, 127)
    spec = PLAN.nodes[0].spec
    values = {(0x1000, 0): 0x00020192, (0x1018, 1): spec.vendor_id, (0x1018, 4): 7, (0x6041, 0): 0x0040}

    def answer(req):
        v = values.get((req.index, req.sub))
        return SdoAbortError(req.node, req.index, req.sub, 0x06090011) if v is None else v.to_bytes(4, "little")

    asked = _drive_scan(scan, answer)
    assert scan.findings == [] and isinstance(asked[0], Nmt) and isinstance(asked[2], Wait)
    assert asked[2].until_s == 2.0  # the bounded wait for boot-ups


def test_the_commissionings_master_lets_the_scan_hear_every_frame_it_is_fed():
    """CommissionMaster (a MasterCore): the scan hears each frame before the master handles it, only during
    the scan; start() runs the scan first (steps); nothing is patched on the instance."""
    core = Commission(ACT, CHECK, PLAN)
    master = CommissionMaster(core, ACT, PLAN, forces=(2.0 * LIM.force_N, LIM.max_force_N), safety=CHECK.safety)
    assert "on_frame" not in vars(master) and master.steps is not None
    unknown = master.unknown_frames
    master.on_frame(Frame(0x705, b"\x00"), 0.0)  # a boot-up of node 5, at an id the rig does not have
    assert core.scan.heard == {5} and master.unknown_frames == unknown + 1  # heard, and handled by the master
    core.stage = Stage.PREFLIGHT
    master.on_frame(Frame(0x706, b"\x00"), 0.0)
    assert core.scan.heard == {5}  # after the scan, not heard


def test_wiring_fault_option():
    f = wiring_fault("loadcell_scale:2:0.1")
    assert (f.kind, f.ema, f.param) == ("loadcell_scale", 2, 0.1)
    assert wiring_fault("lvdts_swapped").ema == 1
    for bad in ("lvdt_stuck", "lvdt_sign:3", "lvdt_scale:1:x"):
        with pytest.raises(argparse.ArgumentTypeError):
            wiring_fault(bad)


def test_commission_refuses_real_drives_without_arm_and_without_a_bus(tmp_path, capsys):
    assert main(["commission", "--interface", "virtual", "--channel", "x", "--out", str(tmp_path / "a")]) == 3
    assert "--arm" in capsys.readouterr().out
    assert main(["commission", "--arm", "--out", str(tmp_path / "b")]) == 3
    assert main(["commission", "--wiring-fault", "lvdt_sign", "--arm", "--interface", "virtual", "--channel", "x",
                 "--out", str(tmp_path / "c")]) == 3
    assert main(["commission", "a.toml", "--profile", "b.toml", "--simulate", "--out", str(tmp_path / "d")]) == 3
    assert not any(tmp_path.iterdir())  # nothing written


# ------------------------------------------------------------------ over CANopen (slow)


def _run(out: Path, faults=(), act=ACT, profile=None, eds=None, true_profile=None):
    """Commission with the profile ``act`` (``profile``, ``eds``) a simulated rig built as ``true_profile``
    (default: the shipped one) says."""
    rig = master_setup(act, profile, eds)
    true_act = ACT if true_profile is None else load_actuation(true_profile)
    true_rig = master_setup(true_act, true_profile, eds)
    out.mkdir()
    return commission(act, CHECK, rig, simulated_transport(true_act, true_rig, SIMRIG, tuple(faults), None), out)


WIRING = {
    "lvdt_sign": Fault("lvdt_sign", ema=2),
    "lvdt_scale": Fault("lvdt_scale", ema=1, value=0.1),
    "lvdt_dead": Fault("lvdt_dead", ema=1),
    "loadcell_sign": Fault("loadcell_sign", ema=1),
    "loadcell_scale": Fault("loadcell_scale", ema=2, value=0.5),
    "loadcell_scale_10": Fault("loadcell_scale", ema=1, value=0.1),  # a unit mistake
    "loadcell_dead": Fault("loadcell_dead", ema=2),
    "lvdts_swapped": Fault("lvdts_swapped"),
    "loadcells_swapped": Fault("loadcells_swapped"),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("commission")
    out = {"clean": _run(base / "clean")}
    for name, f in WIRING.items():
        out[name] = _run(base / name, [f])
    out["drill"] = _run(base / "drill", [Fault("ignore_abort_connection", ema=2)])
    moved = write_profile_variant("actuation.toml", base / "ids.toml", {"canopen": {"node_id_ema2": 5}})
    out["node_id"] = _run(base / "node_id", act=load_actuation(moved), profile=moved)
    # the LVDTs and load cells on a CiA 401 node of their own; the drives at each other's node id
    sensors = sensor_profile(base / "sensors.toml")
    data = tomllib.loads(sensors.read_text())
    data["canopen"]["node_id_ema1"], data["canopen"]["node_id_ema2"] = 2, 1
    crossed = base / "crossed.toml"
    crossed.write_text(tomli_w.dumps(data))
    act = load_actuation(sensors)
    out["sensor_clean"] = _run(base / "sensor_clean", act=act, profile=sensors, true_profile=sensors)
    out["drives_swapped"] = _run(base / "drives_swapped", act=act, profile=sensors, true_profile=crossed)
    return out


@pytest.fixture(scope="module")
def identity_run(tmp_path_factory):
    """Drives of another product (0x403, their own EDS says so) where the profile expects 0x402."""
    base = tmp_path_factory.mktemp("commission-identity")
    text = default_profile_path("ema_drive.eds").read_text()
    assert text.count("0x00000402") == 2  # [DeviceInfo] ProductNumber and 0x1018:02's default
    (base / "other_drive.eds").write_text(text.replace("0x00000402", "0x00000403"))
    other = write_profile_variant("actuation.toml", base / "other.toml",
                                  {"canopen": {"product_code": 0x403, "eds": "other_drive.eds"}})
    return _run(base / "identity", true_profile=other)


def test_every_wiring_fault_kind_is_commissioned_below():
    from sim.faults import WIRING_KINDS

    assert {f.kind for f in WIRING.values()} == {k.value for k in WIRING_KINDS}


def _keys(run) -> list[tuple[str, str]]:
    return [(f["kind"], f["key"]) for f in run.report["findings"]]


def _no_nan(word: str):
    raise AssertionError(f"commission.json holds {word}: not JSON")


def _safe(run) -> None:
    """Both drives ended in Switch on disabled, confirmed; no check was started (no check record)."""
    for ema in ("ema1", "ema2"):
        d = run.report["drives_final"][ema]
        assert d["state"] == "SWITCH_ON_DISABLED", (ema, d)
    assert not (run.out / "signals.csv").exists() and not (run.out / "result.json").exists()
    text = (run.out / "commission.json").read_text()
    jsonschema.validate(json.loads(text, parse_constant=_no_nan), SCHEMA)  # strict JSON: no NaN, no Infinity
    assert (run.out / "commission.html").stat().st_size > 1000


@pytest.mark.slow
def test_clean_rig_is_ready_with_the_simulators_gains(runs):
    r = runs["clean"]
    assert r.exit_code == ExitCode.PASS and r.report["status"] == "ready" and r.report["findings"] == []
    _safe(r)
    assert (r.out / "commission.html").read_text().count("data:image/png;base64,") == 1  # the movements' figure
    assert sorted(r.core.traces) == ["force step 1", "force step 2", "move 1", "move 2"]
    assert all(r.report["drives_final"][e]["confirmed"] for e in ("ema1", "ema2"))
    m = r.report["measured"]
    for moving in ("ema1_moving", "ema2_moving"):
        for a in (1, 2):  # the slope over 1 mm: LVDT noise and the 0.02 mm cubic non-linearity < 0.002
            assert m["lvdt_gain"][moving][f"ema{a}"] == pytest.approx(G_LVDT[a], abs=0.002)
    for j in (1, 2):  # load cells of gain 1.0; the drive's torque in whole per mille of 1 N m (0.5 %) and
        # the surface's ringing left in the averaged hold (< 1 %): within 2 %
        g = m["loadcell_gain"][f"ema{j}_pushing"]
        assert g[f"ema{j}"] == pytest.approx(1.0, abs=0.02) and g[f"ema{3 - j}"] == pytest.approx(-1.0, abs=0.02)
        f = m["lvdt_follows"][f"ema{j}_pushing"]  # the pushing EMA's LVDT follows its motor, the other's hardly
        assert abs(f[f"lvdt{j}_mm"]) > 5 * abs(f[f"lvdt{3 - j}_mm"])
    for ema in ("ema1", "ema2"):
        drill = r.report["master_loss"][ema]["drill"]
        assert drill["outcome"] == "reacted" and 125 <= drill["reaction_ms"] <= 125 + 2 * 2  # + 2 SYNC periods


@pytest.mark.slow
@pytest.mark.parametrize("name,expected,fits,rel", [
    ("lvdt_sign", [("sign", "signals.ema2.lvdt.mm_per_unit")], -0.001 / G_LVDT[2], 0.005),
    # a factor of ten is a unit error: the power of ten fits, not the pitch (the check's calibration corrects it)
    ("lvdt_scale", [("unit error", "signals.ema1.lvdt.mm_per_unit")], 0.001 / 0.1, 1e-9),
    ("loadcell_sign", [("sign", "signals.ema1.force.N_per_unit")], -0.1, 0.02),
    ("loadcell_scale", [("scale", "signals.ema2.force.N_per_unit")], 0.1 / 0.5, 0.02),
    ("loadcell_scale_10", [("unit error", "signals.ema1.force.N_per_unit")], 0.1 / 0.1, 1e-9),
    # the drives' own inputs: the signal map cannot move an LVDT to the other drive (no TPDO left): a wiring fix
    ("lvdts_swapped", [("wiring", "signals.ema1.lvdt, signals.ema2.lvdt")], None, None),
    ("loadcells_swapped", [("wiring", "signals.ema1.force, signals.ema2.force")], None, None),
])
def test_each_wiring_fault_is_named_with_its_key_and_the_fitting_value(runs, name, expected, fits, rel):
    r = runs[name]
    assert r.exit_code == ExitCode.NOT_READY and r.report["status"] == "not ready"
    assert _keys(r) == expected
    got = r.report["findings"][0]["fits"]
    # the fitting value absorbs the simulated LVDT's pitch (the slope's 0.002) or the load cell's 2 %
    assert got == fits if rel is None else got == pytest.approx(fits, rel=rel)
    _safe(r)


@pytest.mark.slow
@pytest.mark.parametrize("name,key", [("lvdt_dead", "signals.ema1.lvdt"), ("loadcell_dead", "signals.ema2.force")])
def test_a_dead_input_stops_before_anything_moves(runs, name, key):
    r = runs[name]
    assert r.exit_code == ExitCode.NOT_READY
    assert _keys(r) == [("dead", key), ("stopped", key)]  # the stop names the key of what stopped it
    assert r.report["findings"][0]["fits"] is None and r.report["findings"][0]["measured"] == 0.0
    assert r.report["measured"]["lvdt_gain"] == {} and r.report["stage_reached"] == "stopped"
    _safe(r)


@pytest.mark.slow
def test_a_drive_that_does_not_react_to_the_masters_death_is_named(runs):
    r = runs["drill"]
    assert r.exit_code == ExitCode.NOT_READY and _keys(r) == [("master-loss drill", "canopen.external_watchdog")]
    assert "node 2 (EMA 2): did not react" in r.report["findings"][0]["text"]
    drills = {e: r.report["master_loss"][e]["drill"] for e in ("ema1", "ema2")}  # the drill's outcome recorded
    assert drills["ema1"]["outcome"] == "reacted" and drills["ema2"]["outcome"] == "no reaction"
    assert drills["ema2"]["emcy"] == ["0x8130"] and drills["ema2"]["waited_ms"] >= 2 * 125
    _safe(r)


@pytest.mark.slow
def test_the_scan_names_a_node_at_another_id_before_anything_is_powered(runs):
    r = runs["node_id"]
    assert r.exit_code == ExitCode.NOT_READY
    assert _keys(r) == [("answers at another node id", "canopen.node_id_ema2")]
    assert r.report["findings"][0]["fits"] == 2 and r.report["scan"]["heard"] == [1, 2]
    assert r.report["scan"]["nodes"]["1"]["state"] == "SWITCH_ON_DISABLED"
    assert r.report["stage_reached"] == "stopped" and r.report["master_loss"] == {}
    jsonschema.validate(r.report, SCHEMA)


@pytest.mark.slow
def test_the_scan_names_a_wrong_identity_with_the_value_read(identity_run):
    r = identity_run
    assert r.exit_code == ExitCode.NOT_READY
    assert _keys(r) == [("identity", "canopen.product_code")] * 2  # both drives
    assert {f["fits"] for f in r.report["findings"]} == {"0x00000403"}
    assert r.report["stage_reached"] == "stopped" and r.report["master_loss"] == {}
    jsonschema.validate(r.report, SCHEMA)


@pytest.mark.slow
def test_cli_clean_exit_0_and_a_wiring_fault_exit_6(tmp_path, capsys):
    assert main(["commission", "--simulate", "--out", str(tmp_path / "ok")]) == 0
    assert "READY for its first check" in capsys.readouterr().out
    assert main(["commission", str(default_profile_path("actuation.toml")), "--simulate",
                 "--wiring-fault", "lvdt_sign:1", "--out", str(tmp_path / "bad")]) == 6
    report = json.loads((tmp_path / "bad" / "commission.json").read_text(), parse_constant=_no_nan)
    assert report["wiring_faults"] == [{"kind": "lvdt_sign", "ema": 1, "value": None}]
    assert report["simulated"] is True and report["seed"] == SIMRIG.seed
    out = capsys.readouterr().out
    assert "signals.ema1.lvdt.mm_per_unit" in out and "NOT READY" in out
    assert main(["commission", "--simulate", "--out", str(tmp_path / "bad")]) == 3  # written once


@pytest.mark.slow
def test_sensors_on_a_node_of_their_own_clean_and_the_drives_at_each_others_node_id(runs):
    r = runs["sensor_clean"]
    assert r.exit_code == ExitCode.PASS and r.report["findings"] == []
    assert r.report["scan"]["heard"] == [1, 2, 3]
    for moving in ("ema1_moving", "ema2_moving"):  # 0.000625 mm per unit: the slope as on the drives' inputs
        for a in (1, 2):
            assert r.report["measured"]["lvdt_gain"][moving][f"ema{a}"] == pytest.approx(G_LVDT[a], abs=0.002)
    _safe(r)
    r = runs["drives_swapped"]
    assert r.exit_code == ExitCode.NOT_READY
    assert _keys(r) == [("swapped", "canopen.node_id_ema1, canopen.node_id_ema2")]
    assert r.report["findings"][0]["fits"] == "canopen.node_id_ema1 = 2; canopen.node_id_ema2 = 1"
    # the serial numbers read name which actuator each node drives
    assert r.report["identity"]["ema1"]["serial"] == SIMRIG.serials[1]
    _safe(r)


@pytest.fixture(scope="module")
def csp_runs(tmp_path_factory):
    """Drives without CST (their EDS offers CSP only, 0x6502 = 0x80): clean and with three wiring faults."""
    base = tmp_path_factory.mktemp("commission-csp")
    eds = write_eds_variant(base / "csp_only.eds", defaults={(0x6502, 0): "0x00000080"})
    prof = write_profile_variant("actuation.toml", base / "act.toml", {"canopen": {"eds": str(eds)}})
    act = load_actuation(prof)
    cases = {"clean": [], "loadcell_sign": [Fault("loadcell_sign", ema=1)], "lvdts_swapped": [Fault("lvdts_swapped")],
             "loadcell_scale": [Fault("loadcell_scale", ema=2, value=0.5)]}
    return {name: _run(base / name, f, act=act, profile=prof, true_profile=prof) for name, f in cases.items()}


@pytest.mark.slow
def test_a_rig_without_cst_pushes_one_ema_against_the_other(csp_runs):
    r = csp_runs["clean"]
    assert [d.force_control.value for d in r.core.plan.drives] == ["csp", "csp"]
    assert r.exit_code == ExitCode.PASS and r.report["findings"] == []
    for moving in ("ema1_moving", "ema2_moving"):  # both rams moved together (the play shifts: 0.01)
        for a in (1, 2):
            assert r.report["measured"]["lvdt_gain"][moving][f"ema{a}"] == pytest.approx(G_LVDT[a], abs=0.01)
    for k in (1, 2):  # the push stops once a load cell changed by the commissioning force (+ the last cycles)
        d = r.report["measured"]["loadcell_push_N"][f"ema{k}_pushing"]
        assert LIM.force_N <= d[f"ema{k}"] <= 1.1 * LIM.force_N
        assert d[f"ema{3 - k}"] == pytest.approx(-d[f"ema{k}"], rel=0.02)
    _safe(r)
    r = csp_runs["loadcell_sign"]
    assert _keys(r) == [("sign", "signals.ema1.force.N_per_unit")] and r.report["findings"][0]["fits"] == -0.1
    _safe(r)
    assert _keys(csp_runs["lvdts_swapped"]) == [("wiring", "signals.ema1.lvdt, signals.ema2.lvdt")]
    r = csp_runs["loadcell_scale"]  # no torque to compare with: which one is wrong cannot be told
    assert _keys(r) == [("scale", "signals.ema1.force.N_per_unit, signals.ema2.force.N_per_unit")]
    f = r.report["findings"][0]
    assert f["fits"] is None and f["measured"] == pytest.approx(0.5, abs=0.02)
    _safe(r)


VENDOR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vendor-eds"


@pytest.mark.slow
@pytest.mark.parametrize("example,eds", [("maxon_epos4.toml", "maxon_EPOS4.eds"),
                                         ("nanotec_cl4e_cia401.toml", "Nanotec_CL4-E-1-12.eds")])
def test_the_runnable_examples_commission_clean_on_their_vendors_eds(tmp_path, example, eds):
    """The examples on simulated drives serving the vendor's EDS (../shared/data/vendor-eds, never copied)."""
    path = VENDOR / eds
    if not path.is_file():
        pytest.skip(f"{path} not present (../shared/data/vendor-eds)")
    profile = default_profile_path("examples") / example
    r = _run(tmp_path / "c", act=load_actuation(profile), profile=profile, eds=path, true_profile=profile)
    assert r.exit_code == ExitCode.PASS and r.report["findings"] == []
    for moving in ("ema1_moving", "ema2_moving"):
        for a in (1, 2):
            assert r.report["measured"]["lvdt_gain"][moving][f"ema{a}"] == pytest.approx(G_LVDT[a], abs=0.002)
    _safe(r)
