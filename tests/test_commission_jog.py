"""The force-free jog of ``emacheck commission`` (issue 49 part 1): nothing moves under load before the motion
scale is confirmed.

The rules of hil/master/jog_rules.py and the motion of hil/master/jog.py at their boundaries (fast), then the
whole commissioning over CANopen against the simulated rig (slow) whose gear ratio is the shipped one while
the profile under test says 57.3 times it (degrees for radians) or 0.159 times it (revolutions for radians),
with no gear-ratio object in the drives: stopped in the jog, no load cell and no true force beyond 10 % of
the commissioning's force limit on any sample, the gear ratio named with the factor that fits. The expected
numbers come from the profiles (the LVDT pitch errors 1.075 and 0.98 of profiles/simrig.toml), never from a
run.
"""

from __future__ import annotations

import dataclasses
import json
import math
from importlib import resources
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from hil.canopen.process import Sample
from hil.cli import main
from hil.cli.args import ExitCode
from hil.cli.check import master_setup
from hil.cli.commission import commission
from hil.master.commission_rules import Kind, Limits, Stage
from hil.master.jog import Jog, JogPhase, outward_s, outward_travel, smooth_travel
from hil.master.jog_rules import (
    DRIVE_SPEED_FACTOR,
    JOG_FORCE_FRACTION,
    JogPlan,
    commissioning_safety,
    explain,
    jog_gain,
    lvdt_ahead,
    unit_error,
)
from hil.master.limits_setup import limit_targets
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE
from hil.profile.load import load_actuation, load_check, load_simrig
from support.eds import write_eds_variant
from support.profiles import write_profile_variant

ACT = load_actuation(None)
CHECK = load_check(None, ACT)
SIMRIG = load_simrig(None)
PLAN = master_setup(ACT, None).plan
LIM = Limits.of(CHECK)
JOG = JogPlan.of(ACT, LIM, PLAN)
I_TOTAL = ACT.mechanics.i_total_rad_per_mm
T = ACT.timing.sync_period_s  # the SYNC period [s]
#: the simulated LVDTs' pitch (profiles/simrig.toml): the jog's gains include it
G_LVDT = {1: SIMRIG.params.sensors1.lvdt_gain, 2: SIMRIG.params.sensors2.lvdt_gain}
DEG = 180.0 / math.pi  # degrees for radians
REV = 1.0 / (2.0 * math.pi)  # revolutions for radians
SCHEMA = json.loads(resources.files("hil.schemas").joinpath("commission.schema.json").read_text())


# ------------------------------------------------------------------ the plan and its limits (fast)


def test_the_plan_comes_from_the_profiles():
    q = 2 * math.pi / 4096 / I_TOTAL  # one resolver count over the gear ratio [mm]
    assert JOG.travel_mm == LIM.travel_mm == 1.0 and JOG.speed_mm_per_s == LIM.speed_mm_per_s == 0.5
    delta = 0.025 + q + 0.20  # the LVDT noise, one resolver count, the internal play
    assert JOG.delta_mm == pytest.approx((delta, delta), rel=1e-12)
    assert JOG.engaged_mm == ACT.sensors.lvdt_noise_pp_mm == 0.025
    # travel - the deceleration (0.5 mm/s x 0.5 s / 2) - internal play - noise
    assert JOG.min_range_mm == pytest.approx(1.0 - 0.125 - 0.20 - 0.025)
    assert JOG.max_force_change_N == JOG_FORCE_FRACTION * LIM.max_force_N == 200.0
    assert JOG.gain_tolerance == HARD_LVDT_GAIN_TOLERANCE
    # the tolerance of a gain over R mm of motor travel: 0.10 + delta / R; the widest a passing jog accepts
    assert JOG.tolerance(1, 0.5) == pytest.approx(0.1 + delta / 0.5)
    assert JOG.widest_tolerance == pytest.approx(0.1 + delta / 0.65) == pytest.approx(0.4466, abs=1e-4)
    assert JOG.max_lvdt_mm == pytest.approx(1.0 * (1 + JOG.widest_tolerance) + delta)  # beyond any passing jog


def test_the_drives_keep_the_force_limit_for_every_gear_ratio_the_jog_accepts():
    """0x6072 = F_max / (T_r i (1 + eps_max)): at the largest true gear ratio a passing jog accepts,
    i (1 + eps_max), the drive's limit is the commissioning's force limit, not more."""
    safety = commissioning_safety(CHECK.safety, LIM, JOG)
    eps = JOG.widest_tolerance
    assert safety.max_force_N == pytest.approx(LIM.max_force_N / (1 + eps))
    assert safety.max_force_N * (1 + eps) == pytest.approx(2000.0) and safety.max_force_N >= 2 * LIM.force_N
    assert safety.max_velocity_mm_per_s == min(CHECK.safety.max_velocity_mm_per_s,
                                               DRIVE_SPEED_FACTOR * LIM.speed_mm_per_s) == 2.0
    # in the drive's unit: per mille of the rated torque (1 N m: 5.03 N per mille at i = 5.03 rad/mm)
    from hil.canopen.drivelimits import LimitKind, drive_limits
    t = limit_targets(ACT, safety, None, 4096 / (2 * math.pi), 1.0 / (1.0 * I_TOTAL))
    torque = next(x for x in drive_limits(t) if x.kind is LimitKind.MAX_TORQUE)
    assert torque.value == math.floor(2000.0 / (1 + eps) / I_TOTAL) == 275  # per mille
    assert torque.value * I_TOTAL * (1 + eps) <= 2000.0  # the true force at the largest accepted ratio


# ------------------------------------------------------------------ the motion (fast)


def test_the_way_out_starts_slow_and_grows_with_the_travel():
    p = JOG
    out = (p.travel_mm, p.speed_mm_per_s, p.ramp_s, p.growth_s, p.seed_mm)
    total = outward_s(*out)
    t = np.arange(0.0, total + 0.01, 0.002)
    xv = np.array([outward_travel(*out, tau) for tau in t])
    x, v = xv[:, 0], xv[:, 1]
    assert x[0] == 0.0 and x[-1] == pytest.approx(p.travel_mm, abs=1e-12) and v[-1] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.diff(x) >= 0) and v.max() == pytest.approx(p.speed_mm_per_s)
    grow = x < p.speed_mm_per_s * p.growth_s - p.seed_mm  # the exponential start: v = (x + x0) / tau
    assert np.allclose(v[grow], (x[grow] + p.seed_mm) / p.growth_s)
    assert np.allclose(np.gradient(x, t)[5:-5], v[5:-5], atol=2e-3)  # the speed is the travel's derivative
    # a ram that moves 57.3 times as far as the motor says: at 0.1 mm of true travel it moves at
    # (0.1 + 57.3 x0) / tau = 0.52 mm/s (the commissioning's 0.5 mm/s), not 57.3 times that
    k = np.searchsorted(x, 0.1 / DEG)
    assert v[k] * DEG == pytest.approx((0.1 + DEG * p.seed_mm) / p.growth_s, rel=0.01)
    back = [smooth_travel(1.0, 0.5, p.ramp_s, tau) for tau in (0.0, 1.0 / 0.5 + p.ramp_s)]
    assert back == [0.0, pytest.approx(1.0)]


def test_lvdt_ahead_at_its_boundary():
    d = JOG.delta_mm[0]
    dx = 0.01
    edge = (1 + HARD_LVDT_GAIN_TOLERANCE) * dx + d
    assert not lvdt_ahead(dx, edge * (1 - 1e-9), JOG, 1) and lvdt_ahead(dx, edge * (1 + 1e-9), JOG, 1)
    assert lvdt_ahead(-dx, -edge * (1 + 1e-9), JOG, 1)  # either direction


def _gains(g1, g2, rng=0.9):
    """Two JogGains as jog_gain finds them for LVDTs reading g times the motor travel, exactly."""
    x = np.linspace(0.0, 1.0, 501)
    return tuple(jog_gain(x, 0.3 + g * x, 0.3, a, JOG) for a, g in ((1, g1), (2, g2)))


def test_the_gain_is_judged_at_its_tolerance():
    x = np.linspace(0.0, 1.0, 501)
    for g in (1.075, 0.98):
        got = jog_gain(x, -0.2 + g * x, -0.2, 1, JOG)
        assert got.gain == pytest.approx(g, rel=1e-9) and got.confirms
    # engaged from the first sample 0.025 mm from rest on: the range it was taken over sets the tolerance
    got = jog_gain(x, 0.3 + 1.0 * x, 0.3, 1, JOG)
    e = np.flatnonzero(np.abs(x) >= JOG.engaged_mm)[0]
    assert got.range_mm == pytest.approx(1.0 - x[e]) and got.tolerance == pytest.approx(JOG.tolerance(1, 1 - x[e]))
    # engaged at the first sample whatever g near the boundary: the range 0.95 mm, the tolerance fixed
    x = np.linspace(0.05, 1.0, 476)
    eps = JOG.tolerance(1, 0.95)
    assert eps == pytest.approx(0.1 + JOG.delta_mm[0] / 0.95)
    for g, agrees in ((1 + eps * 0.999, True), (1 + eps * 1.001, False), (1 - eps * 0.999, True),
                      (1 - eps * 1.001, False)):
        got = jog_gain(x, 0.3 + g * x, 0.3, 1, JOG)
        assert got.range_mm == pytest.approx(0.95) and got.agrees is agrees, g
    # too little travel after the ram moved: a gain within the tolerance confirms nothing
    short = np.linspace(0.0, JOG.min_range_mm * 0.9, 300)
    g = jog_gain(short, 0.3 + short, 0.3, 1, JOG)
    assert g.gain == pytest.approx(1.0) and not g.confirms and g.agrees is None
    # an LVDT that never left its noise: not judged
    assert jog_gain(x, 0.3 + 0.01 * np.sin(x), 0.3, 1, JOG).gain is None


# ------------------------------------------------------------------ which scale fits (fast)


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    """The shipped plan without the gear-ratio object; and one whose drives do not report 0x608F."""
    base = tmp_path_factory.mktemp("jog-plans")
    no_obj = write_profile_variant("actuation.toml", base / "no_obj.toml", {"canopen": {"gear_ratio_object": ""}})
    eds = write_eds_variant(base / "no_608f.eds", remove=[0x608F])
    return {"no_object": master_setup(load_actuation(no_obj), no_obj).plan,
            "no_608f": master_setup(load_actuation(no_obj), no_obj, eds).plan}


@pytest.mark.parametrize("factor,words", [(DEG, "degrees where radians"), (REV, "revolutions where radians"),
                                          (10.0, "10^1"), (0.1, "10^-1"), (2.5, None)])
def test_a_shared_factor_is_the_gear_ratio_with_the_value_that_fits(plans, factor, words):
    v = explain(_gains(factor * G_LVDT[1], factor * G_LVDT[2]), plans["no_object"], JOG)
    assert v.stop and [(f.stage, f.kind, f.key) for f in v.findings] == [
        (Stage.JOG, Kind.GEAR, "mechanics.i_total_rad_per_mm"), (Stage.JOG, Kind.STOP, "")]
    r = math.sqrt(G_LVDT[1] * G_LVDT[2]) * factor  # the geometric mean of the two gains
    f = v.findings[0]
    assert f.measured == pytest.approx(r) and f.fits == pytest.approx(I_TOTAL / r, rel=1e-3)
    assert (words in f.text) if words else ("where" not in f.text and "10^" not in f.text)
    assert "fits as well: both LVDT scales" in f.text
    kept = {h.name: h.kept for h in v.hypotheses}
    assert kept == {"gear ratio": True, "both LVDT scales": True, "both encoder resolutions": False}


def test_neither_lvdt_moving_is_a_shared_factor_too_small_to_fit(plans):
    v = explain(_gains(1e-3, 1e-3), plans["no_object"], JOG)
    f = v.findings[0]
    assert v.stop and (f.kind, f.key, f.fits) == (Kind.STILL, "mechanics.i_total_rad_per_mm", None)
    assert f.measured == pytest.approx(1e-3)  # at most the LVDTs' travel over the motors'


def test_where_the_drives_report_the_gear_ratio_the_lvdt_scales_are_named_instead():
    v = explain(_gains(DEG, DEG), PLAN, JOG)  # the shipped profile: the drives report i in 0x2102
    f = v.findings[0]
    assert f.key == "signals.ema1.lvdt.mm_per_unit, signals.ema2.lvdt.mm_per_unit" and v.stop
    assert "not the gear ratio (the drives report the gear ratio (0x2102:00)" in f.text
    assert f.fits == f"signals.ema1.lvdt.mm_per_unit = {0.001 / DEG:.4g}; signals.ema2.lvdt.mm_per_unit = " \
                     f"{0.001 / DEG:.4g}"


def test_one_lvdt_alone_goes_on_to_the_move_where_the_encoder_was_checked(plans):
    v = explain(_gains(0.1 * G_LVDT[1], G_LVDT[2]), plans["no_object"], JOG)
    assert not v.stop and v.findings == ()  # (the move names it, under load, with its better slope)
    assert [(h.name, h.kept) for h in v.hypotheses] == [("LVDT 1 scale", True), ("encoder resolution of EMA 1", False)]
    v = explain(_gains(0.001, G_LVDT[2]), plans["no_object"], JOG)  # LVDT 1 never left its noise: the same
    assert not v.stop and v.gains[0].gain is None
    # where the encoder was not checked against the drive, the same stops: the motion scale of EMA 1 is open
    v = explain(_gains(0.001, G_LVDT[2]), plans["no_608f"], JOG)
    assert v.stop and [(f.kind, f.key) for f in v.findings] == [
        (Kind.STILL, "signals.ema1.lvdt.mm_per_unit, signals.ema1.motor_angle.counts_per_rev"), (Kind.STOP, "")]
    # ... but stopped on line: named here
    v = explain(_gains(10 * G_LVDT[1], G_LVDT[2]), plans["no_object"], JOG, stopped="LVDT 1 ran ahead")
    assert v.stop and [(f.kind, f.key) for f in v.findings] == [
        (Kind.SCALE, "signals.ema1.lvdt.mm_per_unit"), (Kind.STOP, "")]
    assert v.findings[0].fits == pytest.approx(0.001 / (10 * G_LVDT[1]), rel=1e-3)


def test_a_jog_stopped_by_a_load_cell_names_it_and_confirms_nothing(plans):
    x = np.linspace(0.0, 0.3, 150)  # stopped after 0.3 mm: gains within the tolerance, too little to confirm
    gains = tuple(jog_gain(x, 0.3 + G_LVDT[a] * x, 0.3, a, JOG) for a in (1, 2))
    assert all(g.agrees is None and not g.confirms for g in gains)
    v = explain(gains, plans["no_object"], JOG, stopped="load cell 1 changed by +250 N",
                stopped_key="signals.ema1.force")
    assert v.stop and [(f.kind, f.key) for f in v.findings] == [(Kind.LIMIT, "signals.ema1.force"), (Kind.STOP, "")]
    assert explain(gains, plans["no_object"], JOG).stop  # not stopped, still not confirmed: no load


def test_where_the_encoder_is_not_reported_the_lvdt_and_the_encoder_fit_equally(plans):
    v = explain(_gains(0.5, 1.0), plans["no_608f"], JOG)
    assert v.stop
    f = v.findings[0]
    assert f.key == "signals.ema1.lvdt.mm_per_unit, signals.ema1.motor_angle.counts_per_rev"
    assert "fit equally" in f.text and f.fits == pytest.approx(0.002, rel=1e-3)
    assert [h.kept for h in v.hypotheses] == [True, True]


def test_two_different_factors_are_two_findings(plans):
    v = explain(_gains(0.5, 2.0), plans["no_608f"], JOG)
    assert v.stop and [f.key for f in v.findings][:2] == [
        "signals.ema1.lvdt.mm_per_unit, signals.ema1.motor_angle.counts_per_rev",
        "signals.ema2.lvdt.mm_per_unit, signals.ema2.motor_angle.counts_per_rev"]


def test_the_same_factor_within_the_two_tolerances_and_not_beyond(plans):
    a, b = _gains(DEG, DEG)
    edge = (1 + a.rel_tolerance) * (1 + b.rel_tolerance)
    for ratio, shared in ((edge * 0.999, True), (edge * 1.001, False), (1 / edge / 0.999, True),
                          (1 / edge / 1.001, False)):
        g2 = dataclasses.replace(b, gain=a.gain / ratio)
        keys = [f.key for f in explain((a, g2), plans["no_object"], JOG).findings]
        assert (keys[0] == "mechanics.i_total_rad_per_mm") is shared, ratio


def test_unit_error_at_its_tolerance():
    assert unit_error(DEG * 1.0499, 0.05) and not unit_error(DEG * 1.0501, 0.05)
    assert unit_error(1.0, 0.1) is None and unit_error(-DEG, 0.1) is None
    assert "10^-1" in unit_error(0.1026, 0.35) and "revolutions" in unit_error(0.15, 0.35)  # the nearest


# ------------------------------------------------------------------ the jog as a sequence (fast)


def test_a_ram_ahead_of_its_motor_is_stopped_at_once_and_slowly():
    """Fed a rig whose rams move 57.3 times as far as the motors say (no play, exact sensors): the jog sees it
    once its LVDT ran ahead by delta (0.23 mm), creeps at the speed it had until an LVDT moved half the travel,
    and stops; the true ram speed never beyond the exponential start's when the rule fires (about 1 mm/s)."""
    jog = Jog(JOG, PLAN, (0.0, 0.0), {"s1": 0.0, "s2": 0.0, "F1": 0.0, "F2": 0.0}, 0.0, T)
    t, sp = 0.0, None
    x_true = 0.0
    while not jog.done and t < 30:
        phi = 0.0 if sp is None else sp[0].value
        x_true = DEG * phi / I_TOTAL
        sp = jog.step(Sample(t, phi, phi, x_true, x_true, 0.0, 0.0))
        t += 0.002
    assert jog.done and jog.stopped is not None and "LVDT 1" in jog.stopped
    x = jog.arrays()
    x_seen = JOG.engaged_mm / DEG + JOG.delta_mm[0] / (DEG - 1 - HARD_LVDT_GAIN_TOLERANCE)  # motor travel [mm]
    v_seen = (x_seen + JOG.seed_mm) / JOG.growth_s * DEG  # the true speed then [mm/s]
    assert v_seen == pytest.approx(1.045, abs=0.01)
    v_max = v_seen * math.exp(2 * 0.002 / JOG.growth_s)  # (the rule looks once per sample)
    assert np.max(np.abs(np.diff(x["x_cmd"]))) / 0.002 * DEG < v_max
    # the ram moved half the travel by its LVDT, then the stop: at v_max over tau, v_max tau / 2 (and a sample)
    assert np.max(np.abs(x["x_cmd"])) * DEG < JOG.fit_mm + v_max * (JOG.growth_s / 2 + 0.002)
    v = jog.verdict()
    assert v.stop and v.findings[0].key == "signals.ema1.lvdt.mm_per_unit, signals.ema2.lvdt.mm_per_unit"
    assert v.findings[0].measured == pytest.approx(DEG, rel=0.01)


def _jog_setpoints(gap_after: int | None, gap_periods: int) -> list[float]:
    """The setpoints [rad] of a whole jog on an exact rig (each ram where its motor says), the samples every period
    but ``gap_periods`` periods without a sample after sample ``gap_after`` (the PC held the loop)."""
    jog = Jog(JOG, PLAN, (0.0, 0.0), {"s1": 0.0, "s2": 0.0, "F1": 0.0, "F2": 0.0}, 0.0, T)
    out, phi, k, t = [], 0.0, 0, 0.0
    while not jog.done and k < 20000:
        sp = jog.step(Sample(t, phi, phi, phi / I_TOTAL, phi / I_TOTAL, 0.0, 0.0))
        out.append(sp[0].value)
        assert sp[0].value == sp[1].value
        phi = sp[0].value
        t += T * (gap_periods if k == gap_after else 1)
        k += 1
    assert jog.done and jog.stopped is None
    return out


@pytest.mark.parametrize("gap_after", [100, 600, 900])
def test_the_jog_resumes_where_it_was_after_periods_without_a_sample(gap_after):
    """A hold of 40 ms (20 periods) on the way out, the hold or the way back: the setpoints after it go on from
    where they were, the same sequence as without the hold; read on the samples' clock they would leap by the
    motion missed (at 0.5 mm/s, 0.02 mm: 100 times a period's step)."""
    plain, held = _jog_setpoints(None, 1), _jog_setpoints(gap_after, 20)
    np.testing.assert_allclose(held, plain, rtol=0, atol=1e-9)  # [rad]: the same but for the float time's rounding
    assert len(held) == len(plain)
    steps = np.abs(np.diff(held))
    assert steps[gap_after] <= np.max(np.delete(steps, gap_after))
    assert np.max(steps) / I_TOTAL < JOG.speed_mm_per_s * T * 1.0001  # never more than a period at the speed


def test_a_load_cell_that_changes_stops_the_jog_at_its_limit():
    for dF, stops in ((JOG.max_force_change_N * 0.999, False), (JOG.max_force_change_N * 1.001, True)):
        jog = Jog(JOG, PLAN, (0.0, 0.0), {"s1": 0.0, "s2": 0.0, "F1": 5.0, "F2": 0.0}, 0.0, T)
        jog.step(Sample(0.0, 0.0, 0.0, 0.0, 0.0, 5.0 + dF, 0.0))
        assert (jog.phase is JogPhase.STOPPING) is stops and (jog.stop_key == "signals.ema1.force") is stops


# ------------------------------------------------------------------ over CANopen (slow)


def _transport(true_rig, record: bool = True):
    """The simulated rig of the shipped profiles (the true gear ratio), the plant's truth recorded."""
    from hil.canopen.od import load_eds
    from hil.transport import InProcessTransport
    from sim.drives import SimDrivePair
    from sim.faults import FaultInjector
    from sim.plant import RigPlant

    rng = np.random.default_rng(SIMRIG.seed)
    pair = SimDrivePair(RigPlant(SIMRIG.params, rng), true_rig.plan,
                        lambda name, node_id: load_eds(true_rig.eds_paths[name], node_id=node_id),
                        serials=SIMRIG.serials)
    injector = FaultInjector(pair, (), rng=np.random.default_rng([SIMRIG.seed, 7]), record_truth=record)
    return InProcessTransport(injector, ACT.timing.sync_period_s), injector


def _wrong_gear(base: Path, factor: float) -> Path:
    return write_profile_variant("actuation.toml", base / f"gear_{factor:.4g}.toml",
                                 {"mechanics": {"i_total_rad_per_mm": I_TOTAL * factor},
                                  "canopen": {"gear_ratio_object": ""}})


@pytest.fixture(scope="module")
def gear_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("commission-gear")
    out = {}
    for name, factor in (("x57", DEG), ("x0.16", REV), ("right", 1.0)):
        prof = _wrong_gear(base, factor)
        act = load_actuation(prof)
        transport, injector = _transport(master_setup(ACT, None))
        (base / name).mkdir()
        out[name] = (commission(act, CHECK, master_setup(act, prof), transport, base / name), injector)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name,factor", [("x57", DEG), ("x0.16", REV)])
def test_a_wrong_gear_ratio_is_stopped_in_the_force_free_jog_and_named(gear_runs, name, factor):
    run, injector = gear_runs[name]
    assert run.exit_code == ExitCode.NOT_READY and run.report["stage_reached"] == "stopped"
    f = run.report["findings"]
    gear = "mechanics.i_total_rad_per_mm"  # named as the hypotheses name it; the stop names what stopped it
    assert [(x["stage"], x["kind"], x["key"]) for x in f] == [("jog", "gear ratio", gear), ("jog", "stopped", gear)]
    jog = run.report["measured"]["jog"]
    rel = max(g["rel_tolerance"] for g in jog["gains"].values())
    r = f[0]["measured"]  # the gear ratio's factor: 57.3 (0.159) times the LVDTs' mean pitch (1.026)
    assert r == pytest.approx(factor, rel=rel) and abs(r / factor - 1) < 0.05
    assert f[0]["fits"] == pytest.approx(I_TOTAL, rel=0.05)  # the rig's own 5.027 rad/mm, to the LVDT pitch
    assert ("degrees where radians" if factor > 1 else "revolutions where radians") in f[0]["text"]
    assert not run.core.traces and "move 1" not in run.core.traces  # nothing was loaded
    # no force beyond 10 % of the commissioning's limit: on every sample the master read, and in the plant
    limit = JOG_FORCE_FRACTION * LIM.max_force_N
    x = run.core.jog.arrays()
    assert np.max(np.abs(np.r_[x["F1"], x["F2"]])) < limit
    assert np.max(np.abs(injector.truth.F_N)) < limit
    for ema in ("ema1", "ema2"):
        assert run.report["drives_final"][ema]["state"] == "SWITCH_ON_DISABLED"
    jsonschema.validate(json.loads((run.out / "commission.json").read_text()), SCHEMA)
    assert [h["name"] for h in jog["hypotheses"] if h["kept"]] == ["gear ratio", "both LVDT scales"]


@pytest.mark.slow
def test_the_right_gear_ratio_without_its_object_passes_the_jog_and_is_ready(gear_runs):
    run, injector = gear_runs["right"]
    assert run.exit_code == ExitCode.PASS and run.report["findings"] == []
    jog = run.report["measured"]["jog"]
    for a in (1, 2):
        g = jog["gains"][f"ema{a}"]
        assert g["gain"] == pytest.approx(G_LVDT[a], abs=0.01) and g["confirms"]
        assert abs(g["gain"] - 1) <= g["tolerance"]
    assert jog["peak_force_change_N"] < JOG_FORCE_FRACTION * LIM.max_force_N
    assert sorted(run.core.traces) == ["force step 1", "force step 2", "move 1", "move 2"]


@pytest.mark.slow
def test_the_command_line_names_the_gear_ratio(tmp_path, capsys):
    prof = _wrong_gear(tmp_path, DEG)
    rc = main(["commission", str(prof), "--simulate", "--out", str(tmp_path / "out")])
    assert rc == ExitCode.NOT_READY
    out = capsys.readouterr().out
    assert "[jog] gear ratio: mechanics.i_total_rad_per_mm" in out and "degrees where radians" in out
