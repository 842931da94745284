"""Issue 13's development acceptance: ``emacheck diagnose`` on the 19 independent-rig recordings.

Recordings of a rig model written independently of sim/ (../shared/data/independent-rig,
7-column gzip'd CSVs, no mode column), judged by issue 13's rules
(:func:`support.independent_rig.judge`): at least 90 % right, no crash, and < 30 s CPU per
recording. Skipped with the reason where ../shared is absent. The benchmark that prints the
per-file table is tests/bench/bench_diagnose_dev.py.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from support.ci import skip_or_fail
from support.independent_rig import DATA, KEYS, diagnosed, judge

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _needs_the_shared_recordings():
    if not KEYS:
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")


def _one(name: str, shared: Path) -> tuple[str, bool, str, float]:
    d, secs = diagnosed(name, shared)  # a crash fails the test; once per run (test_diagnose_floors reads it)
    ok, why = judge(KEYS[name]["expect"], d.verdict, [(e.name, e.where) for e in d.effects], list(d.where))
    return name, ok, why, secs


def test_dev_set_at_least_90_percent_right(run_shared):
    # one recording per core (the diagnosis is single-threaded); each one's CPU time is its own
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as pool:
        rows = list(pool.map(_one, KEYS, [run_shared] * len(KEYS), chunksize=1))
    assert len(rows) == len(KEYS) == 19
    for name, _, _, secs in rows:
        assert secs < 30.0, (name, secs)
    right = sum(r[1] for r in rows)
    assert right >= 0.9 * len(rows), [r for r in rows if not r[1]]


def test_the_rig_profile_is_the_shipped_one_with_the_readme_ratio():
    # the README states the rig's motor-to-ram ratio; the diagnoses above use it and nothing else new
    import dataclasses

    from hil.profile.load import load_actuation
    from support.independent_rig import SHIPPED_ACTUATION, rig_i_total, rig_profile

    shipped, rig = load_actuation(SHIPPED_ACTUATION), load_actuation(rig_profile())
    assert rig_i_total() == rig.mechanics.i_total_rad_per_mm
    assert abs(rig.mechanics.i_total_rad_per_mm / shipped.mechanics.i_total_rad_per_mm - 1.0) < 1e-4
    same_ratio = dataclasses.replace(rig.mechanics, i_total_rad_per_mm=shipped.mechanics.i_total_rad_per_mm)
    assert dataclasses.replace(rig, mechanics=same_ratio) == shipped
