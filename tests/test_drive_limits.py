"""The limits each drive keeps itself (docs/safety.md, *Limits the drives keep themselves*).

Known answers computed here independently of hil.canopen.drivelimits: the shipped rig's position unit is
4096 increments per motor revolution and its gear 4 motor revolutions per 5 mm of ram (i k = 3276.8
increments per mm exactly), its rated torque 1 N m (0x6076 = 1000 mN m, one per mille = i newton at the
ram). The simulated drive enforces what the master writes: the target clipped to 0x607D (the ram never
passes the stroke), the demand's step limited by 0x6080, a following error beyond 0x6065 for longer than
0x6066 faults it with EMCY 0x8611, the target torque clipped to 0x6072.
"""

from __future__ import annotations

import dataclasses
import json
import math
import struct
from fractions import Fraction
from pathlib import Path

import canopen
import numpy as np
import pytest
from test_master import Pump

from hil.canopen.cia402 import State
from hil.canopen.drivelimits import (
    KEPT_BY_DRIVE,
    KEPT_BY_MASTER,
    LIMIT_OBJECTS,
    DriveLimit,
    LimitKind,
    LimitTargets,
    drive_limits,
    offered,
)
from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import Frame, sync_frame
from hil.master.core import MasterCore, PreflightError
from hil.master.limits_setup import limit_targets, limits_for, readback_problem
from hil.profile.load import default_profile_path, load_actuation
from hil.profile.rig import plan_for
from sim.drives.limits import DriveLimits
from sim.plant import RigPlant
from support.canopen_rig import make_pair
from support.eds import write_eds_variant
from support.profiles import write_profile_variant
from support.rigs import I_TOTAL, T_S, brief_rig, quiet
from support.sim_bus import Bus

INC_PER_MM = Fraction(4096 * 4, 5)  # 4096 increments per motor revolution, 4 revolutions per 5 mm: 3276.8
VENDOR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vendor-eds"
EXAMPLES = default_profile_path("examples")
ALL = set(LimitKind)


def _floor(x: Fraction) -> int:
    return math.floor(x)


# ------------------------------------------------------------------ the conversions


def test_shipped_profile_limits_in_drive_units(actuation, check_profile):
    s = check_profile.safety
    assert (s.max_stroke_mm, s.max_force_N, s.max_velocity_mm_per_s, s.max_following_error_mm) == (19.5, 8000, 10, 0.5)
    k = 4096 / (2 * math.pi)  # increments per rad, as the map scales the motor angle
    q = 1.0 / (1.0 * actuation.mechanics.i_total_rad_per_mm)  # per mille per N at 1 N m rated torque
    got = {lim.kind: lim for lim in drive_limits(limit_targets(actuation, s, None, k, q))}
    want = {
        LimitKind.POSITION_MIN: -_floor(Fraction("19.5") * INC_PER_MM),  # -63897 (63897.6 rounded towards 0)
        LimitKind.POSITION_MAX: _floor(Fraction("19.5") * INC_PER_MM),
        LimitKind.MAX_TORQUE: _floor(Fraction(8000) * 5 / (8 * Fraction(math.pi))),  # 8000 N / (1 N m * i)
        LimitKind.MAX_MOTOR_SPEED: 10 * 4 * 60 // 5,  # 10 mm/s * 0.8 rev/mm * 60 s/min = 480 rpm
        LimitKind.FOLLOWING_ERROR_WINDOW: _floor(Fraction(1, 2) * INC_PER_MM),  # 1638
        LimitKind.FOLLOWING_ERROR_TIME: 4,  # 2 SYNC periods of 2 ms
        LimitKind.QUICK_STOP_DECELERATION: math.ceil(Fraction(10) / Fraction(4, 1000) * INC_PER_MM),  # 2500 mm/s^2
    }
    assert {kd: lim.value for kd, lim in got.items()} == want
    assert want[LimitKind.POSITION_MAX] == 63897 and want[LimitKind.MAX_TORQUE] == 1591
    assert want[LimitKind.QUICK_STOP_DECELERATION] == 8_192_000
    assert all(lim.kept_by == KEPT_BY_DRIVE for lim in got.values())
    assert got[LimitKind.MAX_MOTOR_SPEED].si_value == 10.0 and got[LimitKind.POSITION_MIN].si_value == -19.5


def test_rounding_never_loosens_a_limit_and_whole_values_stay_whole():
    t = LimitTargets(I_TOTAL, 4096 / (2 * math.pi), None, stroke_mm=20.0, following_error_mm=0.5,
                     max_speed_mm_per_s=12.5, quick_stop_decel_mm_per_s2=1.0)
    got = {lim.kind: lim.value for lim in drive_limits(t)}
    assert got[LimitKind.POSITION_MAX] == 65536  # 20 * 3276.8: a whole number stays whole
    assert got[LimitKind.MAX_MOTOR_SPEED] == 600  # 12.5 * 48
    assert got[LimitKind.FOLLOWING_ERROR_WINDOW] == 1638  # 1638.4 down
    assert got[LimitKind.QUICK_STOP_DECELERATION] == 3277  # 3276.8 up: a quicker stop
    assert LimitKind.MAX_TORQUE not in got  # no torque scaling: not asked
    # a drive whose position counts against the motor angle (negative scale) gets the same magnitudes
    flipped = dataclasses.replace(t, position_units_per_rad=-t.position_units_per_rad)
    neg = {lim.kind: lim.value for lim in drive_limits(flipped)}
    assert neg == got


@pytest.mark.parametrize("field,value", [("stroke_mm", 0.0), ("stroke_mm", -1.0), ("max_speed_mm_per_s", math.nan),
                                         ("i_total_rad_per_mm", math.inf), ("position_units_per_rad", 0.0)])
def test_a_limit_or_scaling_that_is_not_positive_is_refused(field, value):
    t = LimitTargets(I_TOTAL, 651.9, 0.2, stroke_mm=20.0, max_speed_mm_per_s=10.0)
    with pytest.raises(CanopenInputError, match=field.split("_rad")[0] if field != "position_units_per_rad"
                       else "position_units_per_rad"):
        drive_limits(dataclasses.replace(t, **{field: value}))


def test_targets_take_the_smaller_of_the_profile_and_the_actuation_stroke(actuation, check_profile):
    wide = dataclasses.replace(check_profile.safety, max_stroke_mm=25.0)
    assert limit_targets(actuation, wide, None, 1.0, 1.0).stroke_mm == actuation.mechanics.stroke_limit_mm == 20.0
    # without a safety profile (a master built for a protocol test): the actuation's stroke and the force
    t = limit_targets(actuation, None, (2000.0, 7000.0), 1.0, 1.0)
    assert (t.stroke_mm, t.max_force_N, t.max_speed_mm_per_s, t.following_error_mm) == (20.0, 7000.0, None, None)


def test_a_limit_the_drive_lacks_is_kept_by_the_master_only():
    t = LimitTargets(I_TOTAL, 651.9, 0.2, stroke_mm=20.0, max_force_N=8000.0, following_error_mm=0.5,
                     following_error_time_s=0.004)
    lims = limits_for(t, lambda i, s: (i, s) not in ((0x6065, 0), (0x607D, 2)))
    by = {lim.kind: lim.kept_by for lim in lims}
    assert by == {LimitKind.POSITION_MIN: KEPT_BY_MASTER, LimitKind.POSITION_MAX: KEPT_BY_MASTER,  # both or none
                  LimitKind.MAX_TORQUE: KEPT_BY_DRIVE, LimitKind.FOLLOWING_ERROR_WINDOW: KEPT_BY_MASTER,
                  LimitKind.FOLLOWING_ERROR_TIME: KEPT_BY_DRIVE}


def test_a_read_back_that_differs_names_the_object_and_both_values():
    lim = DriveLimit(LimitKind.FOLLOWING_ERROR_WINDOW, 1638, 0.5)
    assert readback_problem("EMA 1 (node 1)", lim, 1638) is None
    msg = readback_problem("EMA 1 (node 1)", lim, 1637)
    assert "0x6065:00" in msg and "reads back 1637 after 1638" in msg and msg.startswith("EMA 1 (node 1)")
    assert readback_problem("EMA 1", lim, RuntimeError("abort")) is not None


# ------------------------------------------------------------------ which objects vendor drives offer


def _od_can_write(path: Path):
    od = canopen.import_od(str(path), 1)

    def can_write(index: int, sub: int) -> bool:
        try:
            obj = od[index]
            var = obj[sub] if isinstance(obj, (canopen.objectdictionary.ODRecord, canopen.objectdictionary.ODArray)) \
                else obj
        except KeyError:
            return False
        return "w" in var.access_type
    return can_write


_VENDOR_OFFERS = {  # read from the files (docs/drives.md): the objects each has, all writable
    "maxon_EPOS4.eds": ALL - {LimitKind.MAX_TORQUE},
    "Nanotec_CL4-E-1-12.eds": ALL,
    "Technosoft_iPOS.eds": ALL - {LimitKind.MAX_TORQUE, LimitKind.MAX_MOTOR_SPEED},
    "Schunk_PRL120.eds": {LimitKind.FOLLOWING_ERROR_WINDOW},
}


@pytest.mark.parametrize("name", sorted(_VENDOR_OFFERS))
def test_vendor_eds_limits_offered(name):
    path = VENDOR / name
    if not path.is_file():
        pytest.skip(f"{name} not present at {VENDOR} (../shared/data/vendor-eds)")
    has = offered(_od_can_write(path))
    assert {k for k, v in has.items() if v} == _VENDOR_OFFERS[name]


@pytest.mark.parametrize("profile,eds", [("maxon_epos4.toml", "maxon_EPOS4.eds"),
                                         ("nanotec_cl4e_cia401.toml", "Nanotec_CL4-E-1-12.eds")])
def test_vendor_rig_plan_lists_the_limits_each_drive_keeps(profile, eds):
    if not (VENDOR / eds).is_file():
        pytest.skip(f"{eds} not present at {VENDOR} (../shared/data/vendor-eds)")
    act = load_actuation(EXAMPLES / profile)
    rig = plan_for(act, EXAMPLES / profile, VENDOR / eds)
    t = LimitTargets(act.mechanics.i_total_rad_per_mm, 1000.0, 0.2, stroke_mm=10.0, max_force_N=1000.0,
                     max_speed_mm_per_s=10.0, following_error_mm=0.5, following_error_time_s=0.004,
                     quick_stop_decel_mm_per_s2=2500.0)
    for d in rig.plan.drives:
        kept = {lim.kind for lim in limits_for(t, d.node.can_write) if lim.kept_by == KEPT_BY_DRIVE}
        assert kept == _VENDOR_OFFERS[eds], (profile, d.ema)


# ------------------------------------------------------------------ the simulated drive enforces them


class Rig(Bus):
    """Both simulated drives in CSP (or CST) through RPDO1 (controlword, target position, target torque)."""

    def __init__(self, pair) -> None:
        super().__init__(pair, T_S)
        pair.power_on(0.0)

    def cycle(self, pos=(0, 0), torque=(0, 0), cw=0x0F) -> dict[int, Frame]:
        for k, node in enumerate((1, 2)):
            self.send(Frame(0x200 + node, struct.pack("<Hih", cw, pos[k], torque[k])))
        self.t += self.T
        return {f.arbitration_id: f for f in self.send(sync_frame())}

    def enable(self, mode1: int = 8, mode2: int = 8) -> None:
        self.nmt(0x01)
        self.send(Frame(0x301, struct.pack("<b", mode1)))
        self.send(Frame(0x302, struct.pack("<b", mode2)))
        for cw in (0x06, 0x07, 0x0F):
            self.cycle(cw=cw)
        assert all(n.state_machine.state is State.OPERATION_ENABLED for n in self.pair.nodes)


@pytest.fixture
def rig():
    return Rig(make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(0))))


def test_a_master_commanding_beyond_the_stroke_is_stopped_by_the_drive(rig):
    lim = _floor(Fraction("19.5") * INC_PER_MM)  # 63897: 19.5 mm
    for node in (1, 2):
        rig.write(node, 0x607D, 1, "i", -lim)
        rig.write(node, 0x607D, 2, "i", lim)
        rig.write(node, 0x6080, 0, "I", 480)  # 10 mm/s
    rig.enable()
    s_max = x_max = 0.0
    for k in range(1500):  # both ram targets at 16 mm/s towards 28 mm (a runaway master), 3 s
        p = round(min(k * 16 * T_S, 28.0) * float(INC_PER_MM))
        rig.cycle((p, p))
        st = rig.pair.plant.state()
        s_max = max(s_max, *st.s_mm)
        x_max = max(x_max, *(phi / I_TOTAL for phi in st.phi_rad))
    assert rig.pair.nodes[0].statusword & 0x0800  # internal limit active
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(lim * 2 * math.pi / 4096)
    # the motor stops at the limit, overshooting by less than 2 SYNC periods at the max speed (its position
    # loop's lag), and the ram with it, up to the internal play (0.12 mm) and the load path's spring (< 1 kN
    # at 80 kN/mm here); both well inside the actuation's 20 mm stroke
    assert 19.5 - 0.01 < x_max <= 19.5 + 10.0 * 2 * T_S
    assert 19.4 < s_max <= 19.5 + 10.0 * 2 * T_S + 0.12 + 1000.0 / 80_000 < 20.0
    assert all(n.state_machine.state is State.OPERATION_ENABLED for n in rig.pair.nodes)


def test_the_target_torque_above_0x6072_is_clipped(rig):
    tmax = _floor(Fraction(8000) * 5 / (8 * Fraction(math.pi)))  # 1591 per mille: 8000 N at the ram
    rig.write(1, 0x6072, 0, "H", tmax)
    rig.enable(mode1=10, mode2=8)
    rig.cycle(torque=(3000, 0))
    sp = rig.pair.nodes[0].setpoint
    assert sp.value == pytest.approx(tmax * I_TOTAL)  # one per mille = 1 N m / 1000 * i * 1000 N
    assert sp.value <= 8000.0
    assert rig.pair.nodes[0].statusword & 0x0800  # internal limit active
    rig.cycle(torque=(tmax, 0))
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(tmax * I_TOTAL)
    assert not rig.pair.nodes[0].statusword & 0x0800  # at the limit is not beyond it


def test_max_motor_speed_limits_the_demand_per_cycle(rig):
    rig.write(1, 0x6080, 0, "I", 480)  # 10 mm/s: 480 / 60 * 4096 * 0.002 = 65.536 increments per cycle
    rig.enable()
    steps = []
    for _ in range(5):
        rig.cycle((10_000, 0))
        steps.append(round(rig.pair.nodes[0].setpoint.value * 4096 / (2 * math.pi)))
    assert np.diff(steps).tolist() == [65] * 4
    assert rig.pair.nodes[0].statusword & 0x0800
    assert rig.pair.nodes[1].setpoint.value == 0.0  # EMA 2 (no 0x6080 written: the EDS's 0, no limit)


def test_following_error_beyond_window_and_time_faults_with_emcy_8611(rig):
    for node in (1, 2):
        rig.write(node, 0x6065, 0, "I", 1638)
        rig.write(node, 0x6066, 0, "H", 4)
    rig.enable()
    emcy, states = [], []
    for _ in range(6):  # a jump of 1.5 mm: the motor cannot follow within a cycle
        frames = rig.cycle((4915, 0))
        emcy += [f for f in frames.values() if f.arbitration_id == 0x81]
        states.append(rig.pair.nodes[0].state_machine.state)
    assert len(emcy) == 1 and struct.unpack("<H", emcy[0].data[:2])[0] == 0x8611
    assert State.FAULT in states and rig.pair.nodes[0].state_machine.error_code == 0x8611
    assert rig.pair.nodes[0].setpoint.mode.name == "DISABLED"
    assert rig.pair.nodes[1].state_machine.state is State.OPERATION_ENABLED


class _Stub(DriveLimits):
    """The mixin alone: a position actual value and the objects it reads."""

    def __init__(self, objects: dict) -> None:
        self.objects = objects
        self.position_inc = 0
        self.faults: list[int] = []
        self.store = self
        self.init_limits(T_S, 1.0e-4)

    def int_or(self, index: int, sub: int, default: int) -> int:
        return self.objects.get((index, sub), default)

    def enter_fault(self, code: int) -> None:
        self.faults.append(code)

    def angle_increments_per_rad(self) -> float:
        return 4096 / (2 * math.pi)


@pytest.mark.parametrize("error,cycles,faults", [(1638, 10, 0), (1639, 2, 0), (1639, 3, 1)])
def test_following_error_boundaries(error, cycles, faults):
    """At the window is inside; beyond it, 2 cycles of 2 ms are not longer than 4 ms, 3 are."""
    d = _Stub({(0x6065, 0): 1638, (0x6066, 0): 4})
    got = [d.following_error_exceeded(error) for _ in range(cycles)]
    assert d.faults == [0x8611] * faults and got.count(True) == faults
    assert not _Stub({(0x6066, 0): 0}).following_error_exceeded(10**9)  # no 0x6065: no monitoring


def test_speed_limit_boundary():
    d = _Stub({(0x6080, 0): 480})  # 65.536 increments per 2 ms
    assert d.speed_limited(65, 0) == 65 and d.speed_limited(-65, 0) == -65
    assert d.speed_limited(66, 0) == 65 and d.speed_limited(-66, 0) == -65
    assert d.speed_limited(66, None) == 65  # from the position actual value (0) when CSP begins
    assert _Stub({}).speed_limited(10**6, 0) == 10**6
    whole = _Stub({(0x6080, 0): 1875})  # 1875 / 60 * 4096 * 0.002 = 256 increments exactly
    assert whole.speed_limited(256, 0) == 256 and whole.speed_limited(257, 0) == 256
    assert whole.speed_limited(-1000, -100) == -356


# ------------------------------------------------------------------ the preflight writes and reads back


def _master_run(act, rig, safety, pair) -> tuple[MasterCore, Pump]:
    m = MasterCore(act, rig.plan, forces=(2000.0, safety.max_force_N), safety=safety)
    p = Pump(m, pair)
    p.preflight()
    return m, p


def _pair_of(act, rig):
    from hil.canopen.od import load_eds
    from sim.drives import SimDrivePair
    return SimDrivePair(RigPlant(quiet(brief_rig()), np.random.default_rng(0)), rig.plan,
                        lambda name, node_id: load_eds(rig.eds_paths[name], node_id=node_id))


def test_preflight_writes_and_reads_back_every_limit(actuation, check_profile):
    rig = plan_for(actuation)
    pair = _pair_of(actuation, rig)
    m, p = _master_run(actuation, rig, check_profile.safety, pair)
    assert m.preflight_done
    for node in (1, 2):
        written = set(p.sdo_writes(node))
        read = set(p.sdo_reads(node))
        for obj in LIMIT_OBJECTS.values():
            assert (obj.index, obj.sub) in written and (obj.index, obj.sub) in read
    n1 = pair.nodes[0]
    assert [n1.read(0x607D, 1), n1.read(0x607D, 2), n1.read(0x6072), n1.read(0x6080), n1.read(0x6065),
            n1.read(0x6066), n1.read(0x6085)] == [-63897, 63897, 1591, 480, 1638, 4, 8_192_000]
    report = m.safe_state_report(0.0)["ema2"]["drive_limits"]
    assert [r["object"] for r in report] == ["0x607D:01", "0x607D:02", "0x6072:00", "0x6080:00", "0x6065:00",
                                             "0x6066:00", "0x6085:00"]
    assert {r["kept_by"] for r in report} == {"drive"}


def test_preflight_refuses_a_read_back_that_differs(actuation, check_profile):
    rig = plan_for(actuation)
    pair = _pair_of(actuation, rig)
    node = pair.nodes[1]
    after = node.after_write

    def keeps_its_own(written):  # the drive stores another window than it was told (a clamp of its own)
        after(written)
        if (0x6065, 0) in written:
            node.store.put(0x6065, 0, struct.pack("<I", 1000))
            node.int_cache.pop((0x6065, 0), None)
    node.after_write = keeps_its_own
    with pytest.raises(PreflightError,
                       match=r"node 2 \(EMA 2\): following error window 0x6065:00 reads back 1000 after 1638"):
        _master_run(actuation, rig, check_profile.safety, pair)


def test_an_eds_without_0x6065_leaves_the_window_to_the_master(tmp_path, actuation, check_profile):
    eds = write_eds_variant(tmp_path / "drive.eds", remove=(0x6065,))
    prof = write_profile_variant("actuation.toml", tmp_path / "actuation.toml", {"canopen": {"eds": str(eds)}})
    act = load_actuation(prof)
    rig = plan_for(act, prof)
    pair = _pair_of(act, rig)
    m, p = _master_run(act, rig, check_profile.safety, pair)
    assert m.preflight_done
    assert (0x6065, 0) not in p.sdo_writes(1)
    lims = {r["limit"]: r for r in m.safe_state_report(0.0)["ema1"]["drive_limits"]}
    assert lims["following error window"]["kept_by"] == "master"
    assert lims["following error window"]["value"] == 1638  # what the drive would have been told
    assert {r["kept_by"] for k, r in lims.items() if k != "following error window"} == {"drive"}


@pytest.mark.slow
def test_dry_run_without_0x6065_runs_and_records_who_keeps_each_limit(tmp_path, simrig, check_profile):
    from hil.cli.dry_run import dry_run

    eds = write_eds_variant(tmp_path / "drive.eds", remove=(0x6065,))
    act = load_actuation(None)
    c = check_profile  # short: 1 mm sweeps, one force-fight cycle at 5 % of F_limit (tests/test_kill.py's)
    short = dataclasses.replace(
        c, calibration=dataclasses.replace(c.calibration, sweep_amplitude_mm=1.0),
        force_fight=dataclasses.replace(c.force_fight, amplitude_fraction_of_limit=0.05, cycles=1,
                                        force_rate_N_per_s=4000.0))
    r = dry_run(act, short, simrig, tmp_path / "run", eds=eds)
    meta = json.loads((tmp_path / "run" / "meta.json").read_text())
    assert meta["status"] == "done" and r.exit_code == 0, (r, meta.get("reason"))
    for ema in ("ema1", "ema2"):
        lims = {x["object"]: x for x in meta["drives_final"][ema]["drive_limits"]}
        assert lims["0x6065:00"]["kept_by"] == "master"
        assert [lims[o]["kept_by"] for o in ("0x607D:01", "0x607D:02", "0x6072:00", "0x6080:00", "0x6066:00",
                                              "0x6085:00")] == ["drive"] * 6
        assert (lims["0x607D:02"]["value"], lims["0x6080:00"]["value"]) == (63897, 480)
    report = (tmp_path / "run" / "report.html").read_text()
    assert ("ema1 limits not written (no writable object in its EDS)</td><td>following error window 0x6065:00 = 1638 "
            "position units (0.5 mm)</td>") in report
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["trace"]["drive_limits"]["ema2"] == meta["drives_final"]["ema2"]["drive_limits"]


def test_report_traceability_says_who_keeps_each_limit():
    from hil.report.shell import trace_lines

    lims = [DriveLimit(LimitKind.MAX_TORQUE, 1591, 8000.0).as_json(),
            DriveLimit(LimitKind.FOLLOWING_ERROR_WINDOW, 1638, 0.5, KEPT_BY_MASTER).as_json()]
    html = trace_lines({"drive_limits": {"ema1": lims}})
    assert ("<td>ema1 limits written to the drive and read back</td><td>max torque 0x6072:00 = 1591 per mille of "
            "rated torque (8000 N)</td>") in html
    assert ("<td>ema1 limits not written (no writable object in its EDS)</td><td>following error window 0x6065:00 = "
            "1638 position units (0.5 mm)</td>") in html
