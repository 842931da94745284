"""The level and step rules tried for the re-levelled -40 kgf Cranfield current (issue 35; docs/diagnose.md,
"Can the re-levelled -40 kgf current be detected?"): their statistics on synthetic currents with known
answers (offset steps injected away from the motion: flagged; physical level changes at the motion's
events: not), and the figures the docs give on the development set (none of the rules separates the
-40 kgf rows from the +20/+40 kgf ones, which is why none is shipped). The Cranfield part (slow, about
2.5 s) reads ../shared/data/cranfield-actuator and skips with the reason where absent.
"""

from __future__ import annotations

import numpy as np
import pytest
from bench import bench_diagnose_cranfield_relevel as rl
from scipy import stats

from support import cranfield

WIN = {"extension": (40, 120), "dwell": (164, 195), "retraction": (239, 320)}
LEVEL = np.r_[np.full(124, 0.75), np.full(75, 0.40), np.full(125, 0.96)]  # A, one cycle's segment levels
SEGMENTS = ((0, 124), (124, 199), (199, 324))


def _honest(seed: int, runs: int = 10, cycles: int = 5, noise_A: float = 0.04) -> list:
    rng = np.random.default_rng(seed)
    return [LEVEL + noise_A * rng.standard_normal((cycles, rl.CYCLE)) for _ in range(runs)]


def _relevelled(runs: list) -> list:
    """Each cycle's segment shifted so that its mean over the steady window is the nominal level."""
    out = []
    for c in runs:
        c = c.copy()
        for a, b in WIN.values():
            lo, hi = next(s for s in SEGMENTS if s[0] <= a < s[1])
            c[:, lo:hi] += LEVEL[a] - c[:, a:b].mean(1, keepdims=True)
        out.append(c)
    return out


def _trapezoid(seed: int, cycles: int = 50, steps_A=None, at: int = 80) -> tuple:
    """Synthetic cycles (set point mm, position error mm, current A) of the README's trapezoid.

    Extension at 0.96 mm a sample from sample 0 to 124, a dwell to 199, retraction to 324. The position
    error lags by 4.5 mm after each set-point step and decays with 8 samples' time constant (0.25 mm
    noise); the current changes level at each step with a transient of 4 samples' time constant (the
    acceleration's, faster than the catch-up: in the Cranfield mean cycles the current's peak after a
    start is back within about 8 samples, the position error within about 27) and a size that varies
    from cycle to cycle (physics at the motion's events), plus 0.04 A white noise.
    ``steps_A`` (one per cycle) adds an offset step at sample ``at`` of every cycle, mid-stroke.
    """
    rng = np.random.default_rng(seed)
    k = np.arange(rl.CYCLE)
    v = np.where(k < 124, 0.96, np.where(k < 199, 0.0, -0.96))
    sp = np.tile(20.96 + np.concatenate([[0.0], np.cumsum(v[:-1])]), (cycles, 1))
    lag = np.zeros(rl.CYCLE)
    for e0, sign in ((0, 1.0), (124, -1.0), (199, -1.0)):
        t = k - e0
        lag += np.where(t >= 1, sign * 4.5 * np.exp(-(t - 1) / 8.0) * (t < 75), 0.0)
    err = lag + 0.25 * rng.standard_normal((cycles, rl.CYCLE))
    cur = np.tile(LEVEL, (cycles, 1)) + 0.04 * rng.standard_normal((cycles, rl.CYCLE))
    for e0 in (0, 124, 199):  # a transient after each event, of a size varying per cycle
        t = k - e0
        cur += rng.normal(0.3, 0.1, (cycles, 1)) * np.where(t >= 1, np.exp(-(t - 1) / 4.0), 0.0) * (t < 75)
    cur += rng.normal(0.0, 0.05, (cycles, 1)) * ((k >= 124) & (k < 199))  # the dwell's level varies by cycle
    if steps_A is not None:
        cur[:, at:] += np.asarray(steps_A, float)[:, None] * (k[at:] < (124 if at < 124 else rl.CYCLE))
    return sp, err, cur


def test_the_motion_zones_follow_the_set_point_and_the_catch_up_transient():
    sp, err, _ = _trapezoid(5)
    zones = rl.motion_zones(sp, err)
    assert [a for a, _ in zones] == [0, 124, 199, rl.CYCLE - 1]
    for a, b in zones[:3]:  # 4.5 exp(-t/8) <= 0.25 mm after t = 8 ln 18 = 23 samples (plus the noise)
        assert 18 <= b - a <= 30


@pytest.mark.parametrize("seed", [6, 7, 8, 11, 12])
def test_physical_steps_at_the_motion_events_are_not_flagged(seed):
    sp, err, cur = _trapezoid(seed)
    zones = rl.motion_zones(sp, err)
    assert not rl.recurring_steps(cur, zones)["flagged"]
    assert not rl.varying_steps(list(cur.reshape(10, 5, rl.CYCLE)), zones)["flagged"]


def test_an_offset_step_at_a_fixed_sample_away_from_the_motion_is_flagged_there():
    sp, err, cur = _trapezoid(9, steps_A=np.full(50, 0.03))  # 30 mA, under the sample noise (40 mA)
    e = rl.recurring_steps(cur, rl.motion_zones(sp, err))
    assert e["flagged"] and all(80 - rl.STEP_W < k < 80 + rl.STEP_W for k in e["flagged"])
    assert e["at"] == 80 and e["step_A"] == pytest.approx(0.03, abs=0.01)


def test_offset_steps_of_either_sign_at_a_fixed_sample_are_flagged_by_their_variance():
    steps = np.random.default_rng(10).choice([-0.08, 0.08], 50)
    sp, err, cur = _trapezoid(10, steps_A=steps)
    zones = rl.motion_zones(sp, err)
    f = rl.varying_steps(list(cur.reshape(10, 5, rl.CYCLE)), zones)
    assert f["flagged"] and abs(f["at"] - 80) < rl.STEP_W


def _forced(runs: list) -> list:
    """Each run's steady windows shifted so that their mean over the run is the nominal level."""
    out = []
    for c in runs:
        c = c.copy()
        for a, b in WIN.values():
            c[:, a:b] += LEVEL[a] - c[:, a:b].mean()
        out.append(c)
    return out


def test_the_pair_rule_flags_imposed_levels_and_not_independent_recordings():
    assert stats.norm.cdf(rl.C_PAIR) - stats.norm.cdf(-rl.C_PAIR) == pytest.approx(rl.ALPHA ** (1 / 3))
    honest = rl.pair_z((_honest(1), WIN), (_honest(2), WIN))
    imposed = rl.pair_z((_forced(_honest(1)), WIN), (_forced(_honest(2)), WIN))
    assert all(abs(imposed[k]["z"]) < 1e-6 for k in rl.KINDS)
    assert not all(abs(honest[k]["z"]) < rl.C_PAIR for k in rl.KINDS)


def test_the_cycle_rule_sees_under_dispersion_of_a_relevelled_current_only():
    honest = rl.under_dispersion((_honest(3), WIN))
    relevelled = rl.under_dispersion((_relevelled(_honest(3)), WIN))
    for k in rl.KINDS:
        assert honest[k]["p_under"] > rl.P_UNDER
        assert relevelled[k]["F"] < 0.1 and relevelled[k]["p_under"] < rl.P_UNDER  # not 0: blocks != window


def test_the_run_rule_sees_under_dispersion_of_runs_forced_to_one_level_and_not_of_drifting_runs():
    runs = _honest(4)
    drift = [c + 0.01 * i for i, c in enumerate(runs)]  # 10 mA a session, as sessions drift
    assert rl.run_dispersion((drift, WIN))["p_under"] > 0.5
    assert rl.run_dispersion((_forced(runs), WIN))["p_under"] < rl.P_UNDER


@pytest.fixture(scope="module")
def rows():
    cranfield.require()
    return rl.table()


@pytest.mark.slow
def test_on_cranfield_no_rule_separates_the_relevelled_rows_as_the_docs_say(rows):
    minus = [r for r in rows if r["load_kgf"] < 0]
    plus = [r for r in rows if r["load_kgf"] > 0]
    assert len(minus) == 7 and len(plus) == 14
    counts = {rule: (sum(r[f"flag_{rule}"] for r in minus), sum(r[f"flag_{rule}"] for r in plus))
              for rule in "abcef"}
    assert counts == {"a": (0, 0), "b": (0, 4), "c": (2, 0), "e": (7, 14), "f": (6, 12)}
