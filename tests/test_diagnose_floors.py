"""The dual-EMA model's default floors (hil.profile.floors) against their measurement (issue 35, part 2).

Slow (about 30 s CPU): diagnoses the independent rig's effect-free recordings (../shared, skipped with the
reason where absent) and checks that each default floor covers 3 sqrt(2) times the standard deviation of
the nominal fit's identification error (the default is the larger of this and the simulated checks'
spread, docs/diagnose.md).
"""

from __future__ import annotations

import pytest

from support.ci import skip_or_fail
from support.independent_rig import DATA, KEYS, SharedFits

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def fits(run_shared) -> dict:
    """Each independent-rig recording's fit, made once for the comparisons below: its diagnosis once per test
    run (test_diagnose_independent.py's dev set makes the same ones: support.independent_rig.diagnosed)."""
    return SharedFits(run_shared)


def test_the_play_stiffness_compliance_and_gain_floors_cover_three_sqrt2_times_the_identification_spread(run_shared):
    if not (DATA / "keys.json").exists():
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")
    from bench.bench_diagnose_floors import independent

    from hil.profile.floors import DUAL_FLOORS
    ind = independent(shared=run_shared)
    for kind in ("play_um", "external_play_um", "stiffness_pct", "sensor_gain_pct", "loadcell_gain_pct"):
        assert ind[kind]["floor_3sqrt2_sd"] <= DUAL_FLOORS[kind], kind
        assert abs(ind[kind]["mean"]) < 3 * ind[kind]["sd"]  # no bias beyond the spread: the fit is right
    for kind, lib in ind["library"].items():  # the quick set's library candidates (true 0)
        assert lib["floor_3sqrt2_sd"] <= DUAL_FLOORS[kind], kind
    # the compliance's truth is one external stiffness, the same in every recording: its scatter is the error
    assert ind["compliance_pct"]["true_same_in_all"]
    assert ind["compliance_pct"]["floor_3sqrt2_sd"] <= DUAL_FLOORS["compliance_pct"]


def test_pairs_of_the_independent_rig_name_their_keyed_changes_and_nothing_unseparable(fits):
    """Ten pairs of the independent rig's effect-free draws (tests/bench/bench_diagnose_independent_pairs.py):
    every keyed change (internal play, contact stiffness, LVDT pitch and offset per EMA, external play; the
    compliance, whose truth is the same in all) judged right by its rule; the bearing plays one by one never
    named; the frictions at the check's speed have no key: their changes, within 0.45 N in these ten pairs, are
    asserted under the friction floor (a change of fit, not of behaviour, would show here)."""
    if not (DATA / "keys.json").exists():
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")
    from bench.bench_diagnose_independent_pairs import run_pairs

    from hil.profile.floors import DUAL_FLOORS
    pairs = run_pairs(cache=fits)
    assert len(pairs) == 10
    wrong = [(p["new"], p["ref"], r) for p in pairs for r in p["rows"] if r["ok"] is False]
    assert not wrong
    judged = sum(r["ok"] is not None for p in pairs for r in p["rows"])
    assert judged == 130
    named = {(p["new"], p["ref"]): {n for n, _ in p["named"]} for p in pairs}
    assert all("bearing_play_change" not in n and "compliance_change" not in n for n in named.values())
    assert all("external_play_change" in n for n in named.values())  # every pair's external play differs > 2 floors
    fr = [abs(r["change"]) for p in pairs for r in p["rows"] if r["parameter"].endswith("friction_N")]
    assert len(fr) == 20 and max(fr) < DUAL_FLOORS["friction_N"]


def test_effects_that_appear_between_two_checks_are_named_at_their_ema_and_nothing_else_is(fits):
    """Recordings of the independent rig with one library effect (a friction increase at one EMA as Coulomb,
    viscous or direction-dependent friction, a load cell gain error, visco-elastic creep) against its
    effect-free null-a (tests/bench/bench_diagnose_independent_pairs.py, all twelve there): the effect's change
    named at the EMA its key says, no library change named anywhere else, every keyed nominal change right."""
    if not (DATA / "keys.json").exists():
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")
    from bench.bench_diagnose_independent_pairs import run_effect_pairs
    only = ("coulomb-1", "viscous-2", "asymfric-1", "loadgain-1", "viscoelastic-2")
    rows = run_effect_pairs("null-a", only, cache=fits)
    assert [r["new"] for r in rows] == [n for n in KEYS if n in only]
    for r in rows:
        assert r["ok"] and not r["keyed_wrong"], r
        assert all(f"{n}_change" in {e for e, _ in r["named"]} for n, _ in r["expect"]), r


def test_physics_outside_the_library_that_appears_is_reported_unexplained_at_its_ema(fits):
    """spall-2 and leaderror-1 (keys: unexplained at ema2, ema1) against null-a: the comparison's verdict is
    unexplained, located first at that EMA, whatever nominal changes it also names."""
    if not (DATA / "keys.json").exists():
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")
    from bench.bench_diagnose_independent_pairs import run_unexplained_pairs
    rows = run_unexplained_pairs("null-a", cache=fits)
    assert {r["new"] for r in rows} == {"spall-2", "leaderror-1"}
    assert all(r["ok"] for r in rows), rows
