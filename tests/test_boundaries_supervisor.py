"""Every supervisor limit pinned at its boundary: on the limit, one float step below and above.

hil/check/supervisor.py trips when a measured quantity is *beyond* its limit (``>``). Each test here feeds
the shipped profiles' limits (and the hard caps, for a check whose profile asks for more) exactly, in
floats (tests/support/boundary.py walks the input by nextafter until the quantity, computed with the
supervisor's own float operations, is the limit), and asserts: on the limit and below, no violation;
one step above, the violation of that limit, with its value and threshold. A rule made ``>=``, a limit
off by one step, or a cap not applied fails a test here. The other limits stay clear of theirs
(no cross-talk: each case trips only the limit it is about).
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.supervisor import Limits, Supervisor, Violation
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE
from support.boundary import around

HOLD = Setpoint(DriveMode.DISABLED, 0.0)
FIELDS = ("s1_mm", "s2_mm", "F1_N", "F2_N", "phi1_rad", "phi2_rad")


def _smp(t: float = 0.0, **f) -> Sample:
    base = dict(t_s=t, phi1_rad=0.0, phi2_rad=0.0, s1_mm=0.0, s2_mm=0.0, F1_N=0.0, F2_N=0.0)
    return Sample(**(base | f))


def _check(sup: Supervisor, smp: Sample, sp1: Setpoint = HOLD, sp2: Setpoint = HOLD) -> Violation | None:
    return sup.check(smp, sp1, sp2)


def _first(actuation, check, smp: Sample, sp1: Setpoint = HOLD, sp2: Setpoint = HOLD) -> Violation | None:
    """The verdict of a fresh supervisor on one sample (the first: no rate, no freshness yet)."""
    return _check(Supervisor(actuation, check), smp, sp1, sp2)


def _replace_safety(check, **kw):
    return dataclasses.replace(check, safety=dataclasses.replace(check.safety, **kw))


def _assert_trips(v: Violation | None, limit: str, value: float, threshold: float, t: float = 0.0) -> None:
    assert v is not None, f"{limit}: no violation at {value!r} > {threshold!r}"
    assert (v.limit, v.value, v.threshold, v.t_s) == (limit, value, threshold, t), v


# ---------------------------------------------------------------------------- stroke, force, fight, imbalance


@pytest.mark.parametrize("field", ["s1_mm", "s2_mm"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_stroke_limit(actuation, check_profile, field, sign):
    lim = Limits.of(actuation, check_profile).max_stroke_mm
    assert lim == check_profile.safety.max_stroke_mm == 19.5  # the profile's, below the 20 mm stroke limit
    below, at, above = around(abs, lim, lim)
    for x in (below, at):
        assert _first(actuation, check_profile, _smp(**{field: sign * x})) is None, x
    v = _first(actuation, check_profile, _smp(**{field: sign * above}))
    _assert_trips(v, "max_stroke_mm", above, lim)
    assert v.detail == f"|s{field[1]}| = {above:.3f} mm > {lim} mm"


def test_stroke_limit_is_capped_by_the_actuations_stroke_limit(actuation, check_profile):
    chk = _replace_safety(check_profile, max_stroke_mm=25.0)  # past the loader: the cap still holds
    cap = actuation.mechanics.stroke_limit_mm
    assert Limits.of(actuation, chk).max_stroke_mm == cap == 20.0
    assert _first(actuation, chk, _smp(s2_mm=-cap)) is None
    _assert_trips(_first(actuation, chk, _smp(s2_mm=-math.nextafter(cap, 99.0))), "max_stroke_mm",
                  math.nextafter(cap, 99.0), cap)


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_force_limit(actuation, check_profile, k, sign):
    lim = Limits.of(actuation, check_profile).max_force_N
    assert lim == 8000.0
    below, at, above = around(abs, lim, lim)
    other = -sign * 5750.0  # |F1 - F2| / 2 <= 6875 N and |F1 + F2| <= 2250 N: clear of fight and imbalance
    for f in (below, at, above):
        smp = _smp(**{f"F{k}_N": sign * f, f"F{3 - k}_N": other})
        v = _first(actuation, check_profile, smp)
        if f > lim:
            _assert_trips(v, "max_force_N", f, lim)
            assert v.detail == f"|F{k}| = {f:.0f} N > {lim:.0f} N"
        else:
            assert v is None, (f, v)


def test_force_limit_is_capped_at_a_quarter_of_the_limit_load(actuation, check_profile):
    chk = _replace_safety(check_profile, max_force_N=30000.0, max_force_fight_N=30000.0,
                          max_force_imbalance_N=30000.0)
    cap = 0.25 * actuation.mechanics.limit_load_N
    assert Limits.of(actuation, chk).max_force_N == cap == 10000.0
    # F2 = -F1 + 4000 would be an imbalance beyond its own cap (4000 N): F2 = -6000 N, fight 8000 N = its cap
    assert _first(actuation, chk, _smp(F1_N=cap, F2_N=-6000.0)) is None
    _assert_trips(_first(actuation, chk, _smp(F1_N=math.nextafter(cap, 1e9), F2_N=-6000.0)), "max_force_N",
                  math.nextafter(cap, 1e9), cap)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_force_fight_limit(actuation, check_profile, sign):
    """|F1 - F2| / 2 with F2 = -F1 (no imbalance)."""
    lim = Limits.of(actuation, check_profile).max_force_fight_N
    assert lim == 7000.0
    fight = lambda a: abs(a - (-a)) / 2.0  # noqa: E731  (the supervisor's operations)
    below, at, above = around(fight, lim, lim)
    for a in (below, at):
        assert _first(actuation, check_profile, _smp(F1_N=sign * a, F2_N=-sign * a)) is None, a
    v = _first(actuation, check_profile, _smp(F1_N=sign * above, F2_N=-sign * above))
    _assert_trips(v, "max_force_fight_N", fight(above), lim)
    assert v.detail == f"force fight |F1 - F2|/2 = {fight(above):.0f} N > {lim:.0f} N"


def test_force_fight_limit_asymmetric_and_capped(actuation, check_profile):
    # 7600 N against -6400 N: fight 7000 N exactly, imbalance 1200 N
    below, at, above = around(lambda f2: abs(-6400.0 - f2) / 2.0, 7000.0, 7600.0)
    for f2 in (below, at):
        assert _first(actuation, check_profile, _smp(F1_N=-6400.0, F2_N=f2)) is None
    v = _first(actuation, check_profile, _smp(F1_N=-6400.0, F2_N=above))
    assert v is not None and v.limit == "max_force_fight_N"
    chk = _replace_safety(check_profile, max_force_fight_N=9999.0, max_force_N=30000.0)
    assert Limits.of(actuation, chk).max_force_fight_N == 0.2 * actuation.mechanics.limit_load_N == 8000.0
    _, at, above = around(lambda f2: abs(8000.0 - (-f2)) / 2.0, 8000.0, 8000.0)
    assert _first(actuation, chk, _smp(F1_N=8000.0, F2_N=-at)) is None
    assert _first(actuation, chk, _smp(F1_N=8000.0, F2_N=-above)).limit == "max_force_fight_N"


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_force_imbalance_limit(actuation, check_profile, sign):
    """|F1 + F2| (the load cells disagree) with F1 = F2 (no fight)."""
    lim = Limits.of(actuation, check_profile).max_force_imbalance_N
    assert lim == 2500.0
    imb = lambda a: abs(a + a)  # noqa: E731
    below, at, above = around(imb, lim, lim / 2)
    for a in (below, at):
        assert _first(actuation, check_profile, _smp(F1_N=sign * a, F2_N=sign * a)) is None, a
    v = _first(actuation, check_profile, _smp(F1_N=sign * above, F2_N=sign * above))
    _assert_trips(v, "max_force_imbalance_N", imb(above), lim)
    assert v.detail == f"load cells disagree: |F1 + F2| = {imb(above):.0f} N > {lim:.0f} N"
    chk = _replace_safety(check_profile, max_force_imbalance_N=9999.0)
    assert Limits.of(actuation, chk).max_force_imbalance_N == 4000.0  # 10 % of F_limit
    assert _first(actuation, chk, _smp(F1_N=sign * 4000.0)) is None
    assert _first(actuation, chk, _smp(F1_N=sign * math.nextafter(4000.0, 1e9))).limit == "max_force_imbalance_N"


# ---------------------------------------------------------------------------- following error


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("phi, sign", [(0.0, 1.0), (0.0, -1.0), (3.25, 1.0), (-7.5, -1.0)])
def test_following_error_limit_in_position_mode(actuation, check_profile, k, phi, sign):
    i = actuation.mechanics.i_total_rad_per_mm
    lim = Limits.of(actuation, check_profile).max_following_error_mm
    assert lim == 0.5
    err = lambda tgt: abs(tgt - phi) / i  # noqa: E731  (target above phi: increasing in the target)
    if sign > 0:
        below, at, above = around(err, lim, phi + lim * i)
    else:  # target below phi: walk the mirrored input
        b, a, ab = around(lambda m: abs(-m - phi) / i, lim, -(phi - lim * i))
        below, at, above = -b, -a, -ab
    smp = _smp(**{f"phi{k}_rad": phi, f"s{k}_mm": phi / i})
    for tgt in (below, at):
        sp = [HOLD, HOLD]
        sp[k - 1] = Setpoint(DriveMode.POSITION, tgt)
        assert _first(actuation, check_profile, smp, *sp) is None, tgt
    sp = [HOLD, HOLD]
    sp[k - 1] = Setpoint(DriveMode.POSITION, above)
    v = _first(actuation, check_profile, smp, *sp)
    _assert_trips(v, "max_following_error_mm", err(above), lim)
    assert v.detail.startswith(f"EMA {k} following error ") and v.detail.endswith(" mm > 0.5 mm")


@pytest.mark.parametrize("mode", [DriveMode.FORCE, DriveMode.DISABLED])
def test_no_following_error_outside_position_mode(actuation, check_profile, mode):
    far = Setpoint(mode, 1000.0)  # a force target in N, or ignored: never a position error
    assert _first(actuation, check_profile, _smp(), far, far) is None


def test_following_error_cap(actuation, check_profile):
    i = actuation.mechanics.i_total_rad_per_mm
    chk = _replace_safety(check_profile, max_following_error_mm=9.0)
    assert Limits.of(actuation, chk).max_following_error_mm == 2.0
    _, at, above = around(lambda tgt: abs(tgt - 0.0) / i, 2.0, 2.0 * i)
    assert _first(actuation, chk, _smp(), Setpoint(DriveMode.POSITION, at), HOLD) is None
    assert _first(actuation, chk, _smp(), Setpoint(DriveMode.POSITION, above), HOLD).limit == "max_following_error_mm"


# ---------------------------------------------------------------------------- D plausibility


def _ramp(actuation, n: int, v_mm_per_s: float, k: int = 1, t0: float = 0.0, x0_mm: float = 0.0) -> list[Sample]:
    """EMA ``k`` moving at ``v`` with its LVDT following the motor (+-0.05 um); load cells alternating by
    0.5 N (never frozen, no fight, no imbalance); the other EMA at rest with an alternating LVDT."""
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    out = []
    for j in range(n):
        x = x0_mm + v_mm_per_s * j * T
        w = 0.5 if j % 2 else -0.5
        out.append(_smp(t0 + j * T, **{f"phi{k}_rad": x * i, f"s{k}_mm": x + w * 1e-4, f"s{3 - k}_mm": w * 1e-3,
                                       "F1_N": w, "F2_N": w}))
    return out


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("moved_mm, side, start_mm", [(0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (1.0, 1.0, 0.0),
                                                      (1.0, -1.0, 0.0), (-2.0, 1.0, 0.0), (1.0, 1.0, -3.0),
                                                      (-1.0, -1.0, 2.0)])
def test_d_plausibility_limit_with_its_lvdt_gain_tolerance(actuation, check_profile, k, moved_mm, side, start_mm):
    """|(s - s0) - (x - x0)| <= max_d_int + 0.1 |x - x0| (x = phi / i, index 0 the first sample):
    at rest the 0.6 mm of the profile; after a move of 1 or 2 mm, 0.1 or 0.2 mm more, wherever the
    move started (the tolerance grows with the motion, not with the position)."""
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    lim = Limits.of(actuation, check_profile).max_d_int_mm
    assert lim == 0.6 and HARD_LVDT_GAIN_TOLERANCE == 0.10
    n = 1 + round(abs(moved_mm) / (5.0 * T))
    stream = _ramp(actuation, n, math.copysign(5.0, moved_mm), k, x0_mm=start_mm)
    last = stream[-1]
    ref = stream[0]
    s0, x0 = getattr(ref, f"s{k}_mm"), getattr(ref, f"phi{k}_rad") / i
    x = getattr(last, f"phi{k}_rad") / i
    allowed = lim + HARD_LVDT_GAIN_TOLERANCE * abs(x - x0)
    dd = lambda s: abs((s - s0) - (x - x0))  # noqa: E731
    if side > 0:
        below, at, above = around(dd, allowed, s0 + (x - x0) + allowed)
    else:
        b, a, ab = around(lambda m: dd(-m), allowed, -(s0 + (x - x0) - allowed))
        below, at, above = -b, -a, -ab
    t_next = last.t_s + T
    for s, trips in ((below, False), (at, False), (above, True)):
        sup = Supervisor(actuation, check_profile)
        for smp in stream:
            assert _check(sup, smp) is None, smp
        v = _check(sup, dataclasses.replace(last, t_s=t_next, **{f"s{k}_mm": s}))
        if trips:
            _assert_trips(v, "max_d_int_mm", dd(s), allowed, t_next)
            assert v.detail == (f"EMA {k} LVDT versus motor angle implausible: D moved {dd(s):.3f} mm > "
                                f"{allowed:.3f} mm")
        else:
            assert v is None, (s, v)


def test_d_plausibility_reference_is_the_first_sample_not_zero(actuation, check_profile):
    """An LVDT offset at the start (s1 = 0.375 mm with the motor at 0, more than the 0.6 mm limit
    would allow from zero with the motion below) is not a D violation: D is measured from the first
    sample; 0.6 mm more is the limit, one step more trips."""
    sup = Supervisor(actuation, check_profile)
    assert _check(sup, _smp(s1_mm=0.375, F1_N=0.5)) is None
    below, at, above = around(lambda s: abs((s - 0.375) - (0.0 - 0.0)), 0.6, 0.975)
    assert at > 0.6  # from zero it would be beyond the limit
    assert _check(sup, _smp(0.002, s1_mm=at, F1_N=-0.5)) is None
    v = _check(sup, _smp(0.004, s1_mm=above, F1_N=0.5))
    assert v is not None and v.limit == "max_d_int_mm" and v.threshold == 0.6


def test_d_plausibility_cap(actuation, check_profile):
    chk = _replace_safety(check_profile, max_d_int_mm=9.0)
    assert Limits.of(actuation, chk).max_d_int_mm == 2.0
    sup = Supervisor(actuation, chk)
    assert _check(sup, _smp(F1_N=0.5)) is None
    assert _check(sup, _smp(0.002, s2_mm=-2.0, F1_N=-0.5)) is None
    assert _check(sup, _smp(0.004, s2_mm=-math.nextafter(2.0, 9.0), F1_N=0.5)).limit == "max_d_int_mm"


# ---------------------------------------------------------------------------- velocity


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("t0", [0.0, 1.0, 123.456])
def test_velocity_limit(actuation, check_profile, k, sign, t0):
    """|phi_k - phi_k,prev| / i / dt, dt = t - t_prev (one SYNC period): 10 mm/s on the limit passes,
    one step faster trips (not 1.5 x the limit: a rule 20-40 % too lax fails here)."""
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    lim = Limits.of(actuation, check_profile).max_velocity_mm_per_s
    assert lim == 10.0
    t1 = t0 + T
    dt = t1 - t0
    speed = lambda d: abs(d - 0.0) / i / dt  # noqa: E731
    below, at, above = around(speed, lim, lim * dt * i)
    for d, trips in ((below, False), (at, False), (above, True)):
        sup = Supervisor(actuation, check_profile)
        assert _check(sup, _smp(t0, F1_N=0.5)) is None
        v = _check(sup, _smp(t1, F1_N=-0.5, **{f"phi{k}_rad": sign * d}))
        if trips:
            _assert_trips(v, "max_velocity_mm_per_s", speed(d), lim, t1)
            assert v.detail == f"EMA {k} speed {speed(d):.2f} mm/s > {lim} mm/s"
        else:
            assert v is None, (d, v)


def test_velocity_over_a_longer_gap_is_the_mean_speed(actuation, check_profile):
    """Two SYNC periods between the samples (one missed, within max_stale_cycles): the same angle step
    is half the speed."""
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    sup = Supervisor(actuation, check_profile)
    assert _check(sup, _smp(0.0, F1_N=0.5)) is None
    step = 1.5 * 10.0 * T * i  # 15 mm/s over one period, 7.5 mm/s over two
    assert _check(sup, _smp(2 * T, phi1_rad=step, F1_N=-0.5)) is None
    v = _check(sup, _smp(3 * T, phi1_rad=2 * step, F1_N=0.5))
    assert v is not None and v.limit == "max_velocity_mm_per_s" and v.value == pytest.approx(15.0)


def test_velocity_not_computed_for_a_repeated_time(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    assert _check(sup, _smp(0.5, F1_N=0.5)) is None
    assert _check(sup, _smp(0.5, phi1_rad=0.01, F1_N=-0.5)) is None  # dt = 0: no speed, no division


def test_velocity_cap(actuation, check_profile):
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    chk = _replace_safety(check_profile, max_velocity_mm_per_s=500.0)
    assert Limits.of(actuation, chk).max_velocity_mm_per_s == 50.0
    speed = lambda d: abs(d - 0.0) / i / T  # noqa: E731
    _, at, above = around(speed, 50.0, 50.0 * T * i)
    for d, limit in ((at, None), (above, "max_velocity_mm_per_s")):
        sup = Supervisor(actuation, chk)
        sup.check(_smp(0.0, F1_N=0.5), HOLD, HOLD)
        v = sup.check(_smp(T, phi2_rad=d, F1_N=-0.5), HOLD, HOLD)
        assert (v.limit if v else None) == limit


# ---------------------------------------------------------------------------- stale data


@pytest.mark.parametrize("t0", [0.0, 2.0, 77.777])
def test_stale_limit_counts_whole_sync_cycles(actuation, check_profile, t0):
    """missed = round(dt / T) - 1 SYNC cycles without a sample: max_stale_cycles (2) missed passes,
    one more trips; within half a period of jitter either side it is the same count."""
    T = actuation.timing.sync_period_s
    lim = Limits.of(actuation, check_profile).max_stale_cycles
    assert lim == 2
    cases = [(lim, False), (lim + 1, False), (lim + 2, True), (lim + 3, True),  # periods between samples
             (lim + 1.49, False), (lim + 1.51, True), (lim + 0.51, False), (1, False)]
    for periods, trips in cases:
        sup = Supervisor(actuation, check_profile)
        assert _check(sup, _smp(t0, F1_N=0.5)) is None
        t1 = t0 + periods * T
        v = _check(sup, _smp(t1, F1_N=-0.5))
        missed = int(round((t1 - t0) / T)) - 1
        if trips:
            _assert_trips(v, "max_stale_cycles", missed, lim, t1)
            assert v.detail == f"sensor data stale: {missed} SYNC cycles without a sample > {lim}"
        else:
            assert v is None, (periods, v)


def test_stale_limit_cap(actuation, check_profile):
    T = actuation.timing.sync_period_s
    chk = _replace_safety(check_profile, max_stale_cycles=50)
    assert Limits.of(actuation, chk).max_stale_cycles == 5
    for periods, limit in ((6, None), (7, "max_stale_cycles")):
        sup = Supervisor(actuation, chk)
        sup.check(_smp(0.0, F1_N=0.5), HOLD, HOLD)
        v = sup.check(_smp(periods * T, F1_N=-0.5), HOLD, HOLD)
        assert (v.limit if v else None) == limit


# ---------------------------------------------------------------------------- frozen sensors


def _noisy(j: int, T: float) -> dict:
    w = 0.25 if j % 2 else -0.25
    return dict(t_s=j * T, s1_mm=w * 1e-3, s2_mm=-w * 1e-3, F1_N=w, F2_N=w)


@pytest.mark.parametrize("field, name, unit", [("s1_mm", "LVDT 1", "mm"), ("s2_mm", "LVDT 2", "mm"),
                                               ("F1_N", "load cell 1", "N"), ("F2_N", "load cell 2", "N")])
def test_frozen_limit_counts_exact_repeats(actuation, check_profile, field, name, unit):
    """A noisy sensor repeating exactly the same value: max_frozen_cycles (25) repeats pass, the 26th
    trips; a changed value restarts the count."""
    T = actuation.timing.sync_period_s
    lim = Limits.of(actuation, check_profile).max_frozen_cycles
    assert lim == 25
    # a value as a scaled raw integer gives it (the LVDT 2): printed at 6 significant digits, not as the float
    frozen = -0.1999999999999993 if field.startswith("s") else 3.0
    for repeats in (lim - 1, lim, lim + 1):
        sup = Supervisor(actuation, check_profile)
        vs = [_check(sup, Sample(phi1_rad=0.0, phi2_rad=0.0, **(_noisy(j, T) | {field: frozen})))
              for j in range(repeats + 1)]  # the first sample, then `repeats` exact repeats
        if repeats > lim:
            assert vs[:-1] == [None] * repeats
            _assert_trips(vs[-1], "max_frozen_cycles", repeats, lim, repeats * T)
            shown = "-0.2" if field.startswith("s") else "3"
            assert vs[-1].detail == f"{name} frozen: the same value {shown} {unit} for {repeats} cycles > {lim}"
            assert vs[-1].key == "safety.max_frozen_cycles"
        else:
            assert vs == [None] * (repeats + 1)
    # 25 repeats, one other value, 25 repeats again: the count restarted
    sup = Supervisor(actuation, check_profile)
    values = [frozen] * (lim + 1) + [frozen + 1e-3] + [frozen] * (lim + 1)
    assert [_check(sup, Sample(phi1_rad=0.0, phi2_rad=0.0, **(_noisy(j, T) | {field: x})))
            for j, x in enumerate(values)] == [None] * len(values)


def test_frozen_limit_cap(actuation, check_profile):
    T = actuation.timing.sync_period_s
    chk = _replace_safety(check_profile, max_frozen_cycles=5000)
    assert Limits.of(actuation, chk).max_frozen_cycles == 100
    sup = Supervisor(actuation, chk)
    vs = [_check(sup, Sample(phi1_rad=0.0, phi2_rad=0.0, **(_noisy(j, T) | {"F2_N": 7.0}))) for j in range(102)]
    assert vs[:101] == [None] * 101 and vs[101].limit == "max_frozen_cycles" and vs[101].value == 101


# ---------------------------------------------------------------------------- invalid values, latching, errors


@pytest.mark.parametrize("field", FIELDS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_sensor_value_is_a_violation(actuation, check_profile, field, bad):
    v = _first(actuation, check_profile, _smp(1.5, **{field: bad}))
    assert v is not None and v.limit == "sensor_invalid" and v.t_s == 1.5
    assert v.detail.startswith("non-finite sensor value in (")


@pytest.mark.parametrize("field", FIELDS)
def test_the_largest_finite_value_is_no_sensor_fault_but_trips_a_limit(actuation, check_profile, field):
    sup = Supervisor(actuation, check_profile)
    assert _check(sup, _smp(0.0, F1_N=0.5)) is None
    v = _check(sup, _smp(0.002, **{field: 1e300}))
    assert v is not None and v.limit != "sensor_invalid"


def test_the_first_violation_latches(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    v = _check(sup, _smp(0.0, F1_N=9000.0, F2_N=-6000.0))
    assert v.limit == "max_force_N" and sup.latched is v
    assert _check(sup, _smp(0.002)) is v  # a clean sample later: still the first violation
    assert _check(sup, _smp(0.004, s1_mm=math.nan)) is v


def test_an_error_inside_is_a_latched_violation_and_propagates(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    bad = Setpoint(DriveMode.POSITION, None)  # cannot be compared with an angle
    with pytest.raises(TypeError):
        sup.check(_smp(0.25), bad, HOLD)
    assert sup.latched is not None and sup.latched.limit == "supervisor_error" and sup.latched.t_s == 0.25
    assert sup.latched.detail.startswith("supervisor error: TypeError(")
    assert _check(sup, _smp(0.5)) is sup.latched


def test_the_previous_sample_is_the_last_one_checked(actuation, check_profile):
    """Speed and freshness compare with the sample just before, not the first one."""
    i, T = actuation.mechanics.i_total_rad_per_mm, actuation.timing.sync_period_s
    sup = Supervisor(actuation, check_profile)
    for j, smp in enumerate(_ramp(actuation, 200, 9.0)):  # 9 mm/s for 0.4 s: 3.6 mm, never too fast
        assert _check(sup, smp) is None, j
    assert sup.latched is None
    sup = Supervisor(actuation, check_profile)
    for smp in _ramp(actuation, 100, 0.0):
        assert _check(sup, smp) is None
    # 100 samples in: a sample 3 periods after the last one is stale (not 100 after the first)
    assert _check(sup, _smp(99 * T + 3 * T, F1_N=1.0)) is None
    assert _check(sup, _smp(102 * T + 4 * T, F1_N=-1.0)).limit == "max_stale_cycles"
    assert i > 0


@pytest.mark.parametrize("limit, key", [("max_force_N", "safety.max_force_N"),
                                        ("max_frozen_cycles", "safety.max_frozen_cycles"),
                                        ("max_stale_ms", "safety.max_stale_ms"),
                                        ("sensor_invalid", "sensor_invalid"), ("supervisor_error", "supervisor_error")])
def test_a_violation_names_the_profile_key_that_sets_its_limit(limit, key):
    from hil.check.supervisor import Violation

    assert Violation(0.0, limit, "").key == key
