"""Forces periodic in position on the Cranfield actuator's development set (issue 48's rules).

Reads ../shared/data/cranfield-actuator where present (never copied) and skips with the reason where
absent. Each condition against ``normal`` at the same load, with the screw's 5 mm lead stated
(tests/bench/bench_diagnose_cranfield_periodic.py prints the table). Slow: about 20 s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from support import cranfield

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    cranfield.require()
    from bench.bench_diagnose_cranfield_periodic import pairs, row
    folder = Path(tmp_path_factory.mktemp("cranfield-periodic"))
    return {(p[0], p[2]): row(folder, *p) for p in pairs()}


def _periodic(r):
    return [n for n in r["named"] if n.startswith("periodic_force_change")]


@pytest.mark.parametrize("name", ["spalling1", "spalling3", "spalling5", "spalling7"])
@pytest.mark.parametrize("load", [20, -40])
def test_spalling_is_named_a_periodic_force_increase_near_the_screws_lead(rows, name, load):
    r = rows[(name, load)]
    per = _periodic(r)
    assert len(per) == 1 and " +" in per[0]
    c = next(c for c in r["components"] if c["named"])
    assert c["change_N"] > c["floor_N"] and 4.5e-3 < c["period_m"] < 5.5e-3
    assert c["order"]["nearest"] == 1 and c["order"]["part"] == "screw"
    assert not any(n.startswith("friction_change +") for n in r["named"])
    assert r["holdout_after_N"] < r["holdout_before_N"]


@pytest.mark.parametrize("load", [20, 40])
def test_lack_of_lubrication_names_no_periodic_increase(rows, load):
    assert not any(" +" in n for n in _periodic(rows[("lackLubrication1", load)]))


def test_backlash_at_plus_40_names_no_periodic_increase(rows):
    assert not any(" +" in n for n in _periodic(rows[("backlash1", 40)]))


@pytest.mark.parametrize("split", ["normal 6-10 vs 1-5", "normal odd vs even"])
@pytest.mark.parametrize("load", [20, 40, -40])
def test_healthy_against_healthy_names_nothing(rows, split, load):
    r = rows[(split, load)]
    assert r["verdict"] == "no_mismatch" and r["named"] == []


def test_the_periodic_floor_is_three_times_the_rms_of_the_healthy_changes(rows):
    from bench.bench_diagnose_cranfield_periodic import floor

    from hil.analysis.diagnose.single_axis import PERIODIC_FLOOR_N
    f = floor(list(rows.values()))
    assert len(f["changes_N"]) == 8
    assert f["floor_3rms_N"] <= PERIODIC_FLOOR_N <= f["floor_3rms_N"] + 0.5  # rounded up to 1 N


def test_a_pair_is_diagnosed_in_under_2_s(rows):
    assert max(r["cpu_s"] for r in rows.values()) < 2.0
