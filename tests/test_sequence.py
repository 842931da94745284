"""Unit tests of the sans-IO check sequence core (no plant, no IO, no sleeps)."""

from __future__ import annotations

import pytest

from hil.canopen.process import DriveMode, Sample
from hil.check.sequence import TRANSITIONS, CheckSequence, Step, _triangle
from hil.errors import SequenceError


def _smp(t, phi1=0.0, phi2=0.0, s1=0.0, s2=0.0, F1=0.0, F2=0.0):
    return Sample(t, phi1, phi2, s1, s2, F1, F2)


def test_transition_table_is_a_chain_with_abort():
    assert TRANSITIONS[Step.IDLE] == {Step.ENABLE, Step.ABORTED}
    assert TRANSITIONS[Step.FORCE_FIGHT] == {Step.UNLOAD, Step.ABORTED}
    assert TRANSITIONS[Step.DONE] == frozenset() and TRANSITIONS[Step.ABORTED] == frozenset()


def test_illegal_transition_raises(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    with pytest.raises(SequenceError, match="illegal step transition IDLE -> FORCE_FIGHT"):
        seq._goto(Step.FORCE_FIGHT, 0.0)


def test_enable_holds_measured_position_then_approach_moves_both_rams_equally(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    i = actuation.mechanics.i_total_rad_per_mm
    out = seq.step(_smp(0.002, phi1=10.0, phi2=-4.0, s1=1.0, s2=0.6))
    assert out.step == Step.ENABLE and out.events[0].step == Step.ENABLE
    assert out.sp1.mode == DriveMode.POSITION and out.sp1.value == 10.0 and out.sp2.value == -4.0
    t = 0.002
    while seq.step_now != Step.CAL1_LOAD:
        t += 0.002
        out = seq.step(_smp(t, phi1=10.0, phi2=-4.0, s1=1.0, s2=0.6))
        assert t < 10
    # both rams moved by the same stroke, -(1.0 + 0.6)/2 = -0.8 mm
    assert (out.sp1.value - 10.0) / i == pytest.approx(-0.8)
    assert (out.sp2.value + 4.0) / i == pytest.approx(-0.8)


def test_opposing_force_ramps_from_the_measured_force(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    t = 0.0
    while seq.step_now != Step.CAL1_LOAD:
        t += 0.002
        out = seq.step(_smp(t, F1=500.0, F2=-500.0))
    t += 0.002
    out = seq.step(_smp(t, F1=500.0, F2=-500.0))
    assert out.sp2.mode == DriveMode.FORCE and out.sp1.mode == DriveMode.POSITION
    assert out.sp2.value == pytest.approx(-500.0, abs=5.0)  # no jump to 0 N
    while seq.step_now == Step.CAL1_LOAD:
        t += 0.002
        out = seq.step(_smp(t, F1=500.0, F2=-500.0))
    assert out.sp2.value == pytest.approx(-check_profile.calibration.opposing_force_N)


def test_abort_latches_and_disables(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    seq.step(_smp(0.002))
    out = seq.abort(0.004, "test")
    assert out.step == Step.ABORTED and out.sp1.mode == DriveMode.DISABLED and out.sp2.mode == DriveMode.DISABLED
    assert seq.finished and seq.abort_reason == "test"
    assert seq.abort(0.006, "again").step == Step.ABORTED and seq.abort_reason == "test"


def test_exception_in_core_aborts_and_reraises(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    seq.step(_smp(0.002))
    with pytest.raises(SequenceError, match="not increasing"):
        seq.step(_smp(0.002))
    assert seq.step_now == Step.ABORTED and "not increasing" in seq.abort_reason


def test_force_fight_demand_triangle():
    assert _triangle(0.0, 6000.0, 12.0) == 0.0
    assert _triangle(3.0, 6000.0, 12.0) == pytest.approx(6000.0)
    assert _triangle(6.0, 6000.0, 12.0) == pytest.approx(0.0)
    assert _triangle(9.0, 6000.0, 12.0) == pytest.approx(-6000.0)
    assert _triangle(1.5, 6000.0, 12.0) == pytest.approx(3000.0)


@pytest.mark.slow  # the session's whole simulated check
def test_run_goes_through_all_steps_in_order(default_run):
    from hil.record.runfolder import read_record
    from hil.record.runrecord import RunStatus

    run_dir, _ = default_run
    meta = read_record(run_dir)
    names = [s.name for s in meta.steps]
    assert names == ["enable", "approach", "cal1_load", "cal1_sweep", "cal1_unload", "cal2_load",
                     "cal2_sweep", "cal2_unload", "force_fight", "unload", "done"]
    assert meta.status is RunStatus.DONE
    assert all(a.t_end_s == b.t_start_s for a, b in zip(meta.steps, meta.steps[1:], strict=False))


# ------------------------------------------------------------------ a drive without CST: the position-mode force loop


def _to_cal1_load(seq, F2=0.0):
    t = 0.0
    while seq.step_now != Step.CAL1_LOAD:
        t += 0.002
        seq.step(_smp(t, F2=F2))
    return t


def test_a_drive_without_cst_opposes_in_position_mode_integrating_its_force_error(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile, force_by_position=(False, True))
    ff = check_profile.force_fight
    i = actuation.mechanics.i_total_rad_per_mm
    t = _to_cal1_load(seq)
    phi_hold2 = seq._phi_hold[1]
    t += 0.002
    out = seq.step(_smp(t))
    assert out.sp2.mode == DriveMode.POSITION and out.sp1.mode == DriveMode.POSITION
    # the force error grows with the ramp (0 -> -2000 N in 1 s); past 0.25 / 0.0007 = 357 N of error the
    # excursion runs at the rate limit, 0.25 mm/s, retracting (more tension)
    for _ in range(250):
        t += 0.002
        out = seq.step(_smp(t))
    before = out.sp2.value
    for _ in range(400):
        t += 0.002
        out = seq.step(_smp(t))
    assert (out.sp2.value - before) / i == pytest.approx(-ff.max_excursion_rate_mm_per_s * 400 * 0.002, rel=1e-9)
    # below the limit the rate is the loop gain times the error: at the target force the excursion stands
    for _ in range(10):
        t += 0.002
        out = seq.step(_smp(t, F2=-check_profile.calibration.opposing_force_N))
    held = out.sp2.value
    t += 0.002
    out = seq.step(_smp(t, F2=-check_profile.calibration.opposing_force_N + 100.0))  # 100 N short
    assert (out.sp2.value - held) / i == pytest.approx(-ff.loop_gain_mm_per_N_s * 100.0 * 0.002, rel=1e-9)
    assert out.sp2.value < phi_hold2


def test_the_sweep_starts_once_the_opposing_force_is_within_ten_percent(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile, force_by_position=(False, True))
    t = _to_cal1_load(seq)
    f = check_profile.calibration.opposing_force_N
    ramp = check_profile.calibration.force_ramp_s + check_profile.approach.settle_s
    t0 = t
    while t - t0 < ramp + 0.1:  # past the ramp and the settling, the force 10.5 % short: no sweep
        t += 0.002
        seq.step(_smp(t, F2=-0.895 * f))
    assert seq.step_now == Step.CAL1_LOAD
    t += 0.002
    seq.step(_smp(t, F2=-0.9 * f))  # at the tolerance: the sweep starts
    assert seq.step_now == Step.CAL1_SWEEP


def test_an_opposing_force_never_reached_aborts_the_check_naming_the_ema(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile, force_by_position=(False, True))
    t = _to_cal1_load(seq)
    t0 = t
    ramp = check_profile.calibration.force_ramp_s + check_profile.approach.settle_s
    with pytest.raises(SequenceError, match=r"EMA 2 did not reach the opposing force -2000 N within 10 s of its ramp"):
        while True:
            t += 0.002
            seq.step(_smp(t, F2=-100.0))
    assert t - t0 == pytest.approx(ramp + 10.0, abs=0.005) and seq.step_now == Step.ABORTED


def test_a_drive_with_cst_is_not_waited_for(actuation, check_profile):
    seq = CheckSequence(actuation, check_profile)
    t = _to_cal1_load(seq)
    t0 = t
    while seq.step_now == Step.CAL1_LOAD:
        t += 0.002
        seq.step(_smp(t, F2=0.0))
    ramp = check_profile.calibration.force_ramp_s + check_profile.approach.settle_s
    assert t - t0 == pytest.approx(ramp + 0.002, abs=0.003)
