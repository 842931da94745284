"""Which freshness limit applies (hil/check/staleness.py, docs/safety.md *A stall of the master*), each rule at
its boundary.

* drives whose limits are not known, or a drive that does not keep 0x607D, 0x6072 and 0x6080 itself:
  today's short limit, ``safety.max_stale_cycles`` (2) SYNC cycles;
* both drives keep them: ``min(max_stale_ms, HARD_MAX_STALE_MS, e / v, C - P_hb - 2 T)`` in whole SYNC
  periods (shipped: 40 ms = 20 cycles): 20 missed cycles pass, 21 trip.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from hil.canopen.drivelimits import LimitKind
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.staleness import NEEDED, stale_limit
from hil.check.supervisor import Limits, Supervisor
from hil.errors import ProfileError
from hil.profile.config import HARD_MAX_FOLLOWING_ERROR_MM, HARD_MAX_STALE_MS, HARD_MAX_VELOCITY_MM_PER_S
from hil.profile.load import load_check
from support.profiles import write_profile_variant

ALL = frozenset(LimitKind)
HOLD = Setpoint(DriveMode.DISABLED, 0.0)


def _safety(check, **kw):
    return dataclasses.replace(check.safety, **kw)


def _smp(t: float, F1: float) -> Sample:
    return Sample(t_s=t, phi1_rad=0.0, phi2_rad=0.0, s1_mm=0.0, s2_mm=0.0, F1_N=F1, F2_N=0.0)


def test_the_hard_cap_is_the_hard_following_error_over_the_hard_speed():
    assert HARD_MAX_STALE_MS == 1000.0 * 2.0 / 50.0 == 1000.0 * HARD_MAX_FOLLOWING_ERROR_MM / HARD_MAX_VELOCITY_MM_PER_S


def test_shipped_profile_with_drives_keeping_their_limits_is_40_ms(actuation, check_profile):
    s = check_profile.safety
    # e / v = 0.5 mm / 10 mm/s = 50 ms; C - P_hb - 2 T = 125 - 50 - 4 = 71 ms; the profile's and the hard cap 40
    assert (s.max_stale_ms, s.max_following_error_mm, s.max_velocity_mm_per_s) == (40.0, 0.5, 10.0)
    assert actuation.canopen.master_consumer_time_s == 0.125 and actuation.canopen.master_heartbeat_period_s == 0.05
    got = stale_limit(actuation, s, [ALL, ALL])
    assert (got.cycles, got.ms, got.derived, got.name) == (20, 40.0, True, "max_stale_ms")
    assert got.why == "safety.max_stale_ms = 40 ms"


@pytest.mark.parametrize("kept", [None, [ALL, set()], [set(), ALL], [ALL, ALL - {LimitKind.MAX_MOTOR_SPEED}],
                                  [ALL - {LimitKind.POSITION_MAX}, ALL], [ALL - {LimitKind.MAX_TORQUE}, ALL]])
def test_a_drive_that_does_not_keep_stroke_torque_and_speed_keeps_the_short_limit(actuation, check_profile, kept):
    got = stale_limit(actuation, check_profile.safety, kept)
    assert (got.cycles, got.ms, got.derived, got.name) == (2, 4.0, False, "max_stale_cycles")
    if kept is not None:
        ema = 1 if set(kept[0]) != ALL else 2
        assert got.why.startswith(f"EMA {ema} does not keep ")


def test_the_three_needed_limits_are_enough(actuation, check_profile):
    assert NEEDED == {LimitKind.POSITION_MIN, LimitKind.POSITION_MAX, LimitKind.MAX_TORQUE, LimitKind.MAX_MOTOR_SPEED}
    assert stale_limit(actuation, check_profile.safety, [NEEDED, NEEDED]).cycles == 20


@pytest.mark.parametrize("ms,cycles", [(30.0, 15), (math.nextafter(30.0, 0.0), 15), (29.99, 14), (31.99, 15),
                                       (32.0, 16), (0.5, 0), (2.0, 1)])
def test_the_profiles_ms_in_whole_sync_periods(actuation, check_profile, ms, cycles):
    """floor(ms / T): a limit between two periods takes the shorter (a float a last bit below a whole
    period is that period)."""
    got = stale_limit(actuation, _safety(check_profile, max_stale_ms=ms), [ALL, ALL])
    assert (got.cycles, got.ms) == (cycles, cycles * 2.0)


def test_the_hard_cap_applies_again_at_run_time(actuation, check_profile):
    got = stale_limit(actuation, _safety(check_profile, max_stale_ms=1000.0), [ALL, ALL])
    assert (got.cycles, got.why) == (20, "HARD_MAX_STALE_MS = 40 ms")


@pytest.mark.parametrize("e,cycles", [(0.06, 3), (0.05, 2), (0.0599, 2)])
def test_following_error_over_speed(actuation, check_profile, e, cycles):
    """e / v: 0.06 mm at 10 mm/s is 6 ms (3 periods), 0.05 mm 5 ms (2)."""
    got = stale_limit(actuation, _safety(check_profile, max_following_error_mm=e), [ALL, ALL])
    assert got.cycles == cycles and got.why.startswith("max_following_error_mm / max_velocity_mm_per_s = ")


@pytest.mark.parametrize("period_s,cycles", [(0.02, 13), (0.012, 7), (0.01, 5)])
def test_never_longer_than_the_consumer_heartbeat_minus_a_heartbeat_period_and_2_periods(
        actuation, check_profile, period_s, cycles):
    """C = 2.5 P: P = 20 ms gives 50 - 20 - 4 = 26 ms (13 periods), 12 ms 30 - 12 - 4 = 14 ms (7), 10 ms 11 ms (5)."""
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(
        actuation.canopen, master_heartbeat_period_s=period_s))
    got = stale_limit(act, check_profile.safety, [ALL, ALL])
    assert got.cycles == cycles
    assert got.why.startswith("consumer heartbeat - master heartbeat period - 2 SYNC periods = ")


def test_supervisor_at_the_derived_limit(actuation, check_profile):
    """20 missed SYNC cycles (21 periods between two samples) pass, 21 trip naming max_stale_ms."""
    T = actuation.timing.sync_period_s
    for periods, trips in ((21, False), (21.49, False), (22, True)):
        sup = Supervisor(actuation, check_profile, kept=[ALL, ALL])
        assert sup.check(_smp(1.0, 0.5), HOLD, HOLD) is None
        v = sup.check(_smp(1.0 + periods * T, -0.5), HOLD, HOLD)
        if trips:
            assert (v.limit, v.value, v.threshold) == ("max_stale_ms", 21, 20)
            assert v.detail.endswith("> 20 (safety.max_stale_ms = 40 ms)")
        else:
            assert v is None


def test_supervisor_learns_what_the_drives_keep_after_the_preflight(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    assert (sup.lim.max_stale_cycles, sup.lim.stale_name) == (2, "max_stale_cycles")
    sup.drives_keep([ALL, ALL])
    assert (sup.lim.max_stale_cycles, sup.lim.stale_name) == (20, "max_stale_ms")
    sup.drives_keep([ALL, set()])
    assert Limits.of(actuation, check_profile, [ALL, set()]).max_stale_cycles == sup.lim.max_stale_cycles == 2


def test_profile_key_and_its_hard_cap(tmp_path, actuation):
    ok = write_profile_variant("check.toml", tmp_path / "ok.toml", {"safety": {"max_stale_ms": 40.0}})
    assert load_check(ok, actuation).safety.max_stale_ms == 40.0
    over = write_profile_variant("check.toml", tmp_path / "over.toml", {"safety": {"max_stale_ms": 40.000001}})
    with pytest.raises(ProfileError, match=r"field 'safety.max_stale_ms' = 40.000001 is above the hard cap 40"):
        load_check(over, actuation)


def test_an_old_profile_without_max_stale_ms_loads_with_its_cycles_as_the_short_limit(tmp_path, actuation):
    old = write_profile_variant("check.toml", tmp_path / "old.toml", remove=["safety.max_stale_ms"])
    assert "max_stale_ms" not in old.read_text() and "max_stale_cycles = 2" in old.read_text()
    chk = load_check(old, actuation)
    assert (chk.safety.max_stale_ms, chk.safety.max_stale_cycles) == (40.0, 2)
    assert Limits.of(actuation, chk).max_stale_cycles == 2
