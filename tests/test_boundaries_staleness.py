"""Which freshness limit applies (hil/check/staleness.py, docs/safety.md *A stall of the master*), each rule at
its boundary.

* drives whose limits are not known, or a drive that does not keep 0x607D, 0x6072 and 0x6080 itself:
  today's short limit, ``safety.max_stale_cycles`` (2) SYNC cycles;
* both drives keep them: ``min(max_stale_ms, HARD_MAX_STALE_MS, e / v, C - P_hb - 2 T)`` in whole SYNC
  periods (shipped: 50 ms = 25 cycles, the shipped e / v): 25 missed cycles pass, 26 trip;
* the hard cap ``HARD_MAX_STALE_MS`` (100 ms, the rig's independent stop path) binds where every other term
  is longer, and a profile key above it is refused at load naming the field.
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
from hil.profile.config import HARD_MAX_STALE_MS
from hil.profile.load import load_check
from support.profiles import write_profile_variant

ALL = frozenset(LimitKind)
HOLD = Setpoint(DriveMode.DISABLED, 0.0)


def _safety(check, **kw):
    return dataclasses.replace(check.safety, **kw)


def _smp(t: float, F1: float) -> Sample:
    return Sample(t_s=t, phi1_rad=0.0, phi2_rad=0.0, s1_mm=0.0, s2_mm=0.0, F1_N=F1, F2_N=0.0)


def test_the_hard_cap_is_the_independent_stop_paths_100_ms():
    """docs/safety.md: the master is never blind longer than the rig's independent stop path on its loss
    (docs/drives.md section 5, the watchdog relay's 100 ms); no longer e / v at the two caps (40 ms)."""
    assert HARD_MAX_STALE_MS == 100.0


def _wide(actuation, check_profile, **kw):
    """Every term but the ones in ``kw`` longer than the hard cap: e / v = 2 mm / 10 mm/s = 200 ms, the consumer
    term at a 100 ms master heartbeat 250 - 100 - 4 = 146 ms, the profile key 1000 ms (not loaded: the run-time
    min applies the cap again)."""
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen,
                                                                     master_heartbeat_period_s=0.1))
    return act, _safety(check_profile, **{"max_stale_ms": 1000.0, "max_following_error_mm": 2.0, **kw})


def test_shipped_profile_with_drives_keeping_their_limits_is_its_e_over_v_50_ms(actuation, check_profile):
    s = check_profile.safety
    # e / v = 0.5 mm / 10 mm/s = 50 ms = the profile's key; C - P_hb - 2 T = 125 - 50 - 4 = 71 ms; the hard cap 100
    assert (s.max_stale_ms, s.max_following_error_mm, s.max_velocity_mm_per_s) == (50.0, 0.5, 10.0)
    assert actuation.canopen.master_consumer_time_s == 0.125 and actuation.canopen.master_heartbeat_period_s == 0.05
    got = stale_limit(actuation, s, [ALL, ALL])
    assert (got.cycles, got.ms, got.derived, got.name) == (25, 50.0, True, "max_stale_ms")
    assert got.why == "safety.max_stale_ms = 50 ms"
    # the profile key and e / v agree: either alone sets 50 ms
    assert stale_limit(actuation, _safety(check_profile, max_stale_ms=1000.0), [ALL, ALL]).why == \
        "max_following_error_mm / max_velocity_mm_per_s = 50 ms"


@pytest.mark.parametrize("e,cycles", [(0.5, 25), (math.nextafter(0.5, 0.0), 25), (0.498, 24), (0.518, 25),
                                      (0.52, 26)])
def test_e_over_v_of_the_shipped_speed_on_its_boundary(actuation, check_profile, e, cycles):
    """At v = 10 mm/s: 0.5 mm is 50 ms (25 periods), 0.518 mm 51.8 ms (25: whole periods), 0.52 mm 52 ms (26); a period
    shorter, 0.498 mm, 24."""
    got = stale_limit(actuation, _safety(check_profile, max_stale_ms=100.0, max_following_error_mm=e), [ALL, ALL])
    assert got.cycles == cycles and got.why.startswith("max_following_error_mm / max_velocity_mm_per_s = ")


@pytest.mark.parametrize("e,v,ms", [(0.5, 50.0, 10.0), (2.0, 50.0, 40.0), (0.5, 10.0, 50.0), (2.0, 10.0, 200.0)])
def test_e_over_v_is_computed_from_the_runs_own_limits(actuation, check_profile, e, v, ms):
    """The old hard cap 40 ms was 2 mm / 50 mm/s, one point of this function (docs/safety.md)."""
    act, s = _wide(actuation, check_profile, max_following_error_mm=e, max_velocity_mm_per_s=v)
    got = stale_limit(act, s, [ALL, ALL])
    assert got.ms == min(ms, HARD_MAX_STALE_MS) == got.cycles * 2.0


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
    assert stale_limit(actuation, check_profile.safety, [NEEDED, NEEDED]).cycles == 25


@pytest.mark.parametrize("ms,cycles", [(30.0, 15), (math.nextafter(30.0, 0.0), 15), (29.99, 14), (31.99, 15),
                                       (32.0, 16), (0.5, 0), (2.0, 1)])
def test_the_profiles_ms_in_whole_sync_periods(actuation, check_profile, ms, cycles):
    """floor(ms / T): a limit between two periods takes the shorter (a float a last bit below a whole
    period is that period)."""
    got = stale_limit(actuation, _safety(check_profile, max_stale_ms=ms), [ALL, ALL])
    assert (got.cycles, got.ms) == (cycles, cycles * 2.0)


@pytest.mark.parametrize("key_ms,cycles,why", [
    (1000.0, 50, "HARD_MAX_STALE_MS = 100 ms"), (math.nextafter(100.0, math.inf), 50, "HARD_MAX_STALE_MS = 100 ms"),
    (100.0, 50, "safety.max_stale_ms = 100 ms"), (98.0, 49, "safety.max_stale_ms = 98 ms")])
def test_the_hard_cap_applies_again_at_run_time(actuation, check_profile, key_ms, cycles, why):
    """Every other term longer (:func:`_wide`): the cap, 100 ms = 50 SYNC periods, and a period either side."""
    act, s = _wide(actuation, check_profile, max_stale_ms=key_ms)
    got = stale_limit(act, s, [ALL, ALL])
    assert (got.cycles, got.why) == (cycles, why)


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
    """25 missed SYNC cycles (26 periods between two samples) pass, 26 trip naming max_stale_ms."""
    T = actuation.timing.sync_period_s
    for periods, trips in ((26, False), (26.49, False), (27, True)):
        sup = Supervisor(actuation, check_profile, kept=[ALL, ALL])
        assert sup.check(_smp(1.0, 0.5), HOLD, HOLD) is None
        v = sup.check(_smp(1.0 + periods * T, -0.5), HOLD, HOLD)
        if trips:
            assert (v.limit, v.value, v.threshold) == ("max_stale_ms", 26, 25)
            assert v.detail.endswith("> 25 (safety.max_stale_ms = 50 ms)")
        else:
            assert v is None


def test_supervisor_learns_what_the_drives_keep_after_the_preflight(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    assert (sup.lim.max_stale_cycles, sup.lim.stale_name) == (2, "max_stale_cycles")
    sup.drives_keep([ALL, ALL])
    assert (sup.lim.max_stale_cycles, sup.lim.stale_name) == (25, "max_stale_ms")
    sup.drives_keep([ALL, set()])
    assert Limits.of(actuation, check_profile, [ALL, set()]).max_stale_cycles == sup.lim.max_stale_cycles == 2


def test_profile_key_and_its_hard_cap(tmp_path, actuation):
    ok = write_profile_variant("check.toml", tmp_path / "ok.toml", {"safety": {"max_stale_ms": 100.0}})
    assert load_check(ok, actuation).safety.max_stale_ms == 100.0
    over = write_profile_variant("check.toml", tmp_path / "over.toml", {"safety": {"max_stale_ms": 100.000001}})
    with pytest.raises(ProfileError, match=r"field 'safety.max_stale_ms' = 100.000001 is above the hard cap 100"):
        load_check(over, actuation)


def test_an_old_profile_without_max_stale_ms_loads_with_its_cycles_as_the_short_limit(tmp_path, actuation):
    old = write_profile_variant("check.toml", tmp_path / "old.toml", remove=["safety.max_stale_ms"])
    assert "max_stale_ms" not in old.read_text() and "max_stale_cycles = 2" in old.read_text()
    chk = load_check(old, actuation)
    assert (chk.safety.max_stale_ms, chk.safety.max_stale_cycles) == (50.0, 2)
    assert Limits.of(actuation, chk).max_stale_cycles == 2
