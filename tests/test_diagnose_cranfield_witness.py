"""The second witness and the floors' coverage on the Cranfield actuator's development set (issue 48, parts 3-4).

Reads ../shared/data/cranfield-actuator where present (never copied) and skips with the reason where absent.
Each condition against ``normal`` at the same load, +20, +40 and -40 kgf, and ``normal`` against itself in
two splits per load, through ``emacheck diagnose --model single-axis --reference``
(tests/bench/bench_diagnose_witness.py prints the table; docs/diagnose.md, "The second witness"). The rule
is one for every row: nothing here is keyed to a file or a load. Slow: about 20 s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from support import cranfield

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    cranfield.require()
    from bench.bench_diagnose_witness import table
    out = {}
    for r in table(Path(tmp_path_factory.mktemp("witness"))):
        out.setdefault((r["condition"], r["load_kgf"]), []).append(r)
    return out


@pytest.fixture(scope="module")
def one(rows):
    return {k: v[0] for k, v in rows.items()}


def mean_named(r) -> list:
    """The effects named from the effort's mean-force model (a periodic change is not one: its period's
    component is removed from the jitter, so it does not answer the witness)."""
    return [n for n in r["named"] if not n.startswith("periodic")]


@pytest.mark.parametrize("name", ["lackLubrication1", "backlash1"])
def test_at_minus_40_the_effort_names_nothing_and_the_witness_makes_it_untrusted(one, name):
    r = one[(name, -40)]
    assert mean_named(r) == [] and r["verdict"] == "untrusted_effort" and r["rule"] == "untrusted"
    assert r["jitter_named"] and r["jitter_change"] > 0.4  # +66 % and +56 %
    words = r["untrusted_words"]
    assert "the effort names no change of its mean force (friction_N" in words
    assert "the tracking error's steady jitter rose" in words


@pytest.mark.parametrize("load", [20, 40])
def test_lack_of_lubrication_at_plus_20_and_40_is_a_friction_increase_as_before(one, load):
    r = one[("lackLubrication1", load)]
    assert r["verdict"] == "explained" and mean_named(r) == ["friction_change"] and r["friction_change_N"] > 200
    assert r["rule"] == "none" and r["jitter_named"] and r["jitter_change"] > 0  # the witnesses agree


def test_backlash1_names_no_friction_increase_and_is_untrusted_only_where_the_effort_sees_nothing(one):
    """+40 kgf: the effort names a friction decrease, which stands; +20 kgf: it names nothing (-66 ± 8 N, under
    the 75 N floor) while the jitter rose by 49 %: the rule says untrusted there."""
    r40, r20 = one[("backlash1", 40)], one[("backlash1", 20)]
    assert mean_named(r40) == ["friction_change"] and r40["friction_change_N"] < 0 and r40["rule"] == "none"
    assert mean_named(r20) == [] and r20["verdict"] == "untrusted_effort" and r20["jitter_change"] > 0.4


@pytest.mark.parametrize("load", [20, 40, -40])
def test_normal_against_normal_in_two_splits_names_nothing(rows, load):
    splits = rows[("normal", load)]
    assert [r["against"] for r in splits] == ["6-10 vs 1-5", "even vs odd"]
    for r in splits:
        assert (r["verdict"], r["named"], r["rule"]) == ("no_mismatch", [], "none")
        assert not r["lag_named"] and not r["jitter_named"]


@pytest.mark.parametrize("name", ["spalling1", "spalling3", "spalling5", "spalling7"])
@pytest.mark.parametrize("load", [20, 40, -40])
def test_spalling_is_untrusted_only_where_its_jitter_rose_never_from_a_session_offset(one, name, load):
    """The session offsets of the current (friction -58..+51 N under the floor) make nothing untrusted: only a
    jitter risen beyond its floor does (less the named period's component), with an effort that names no
    change of its mean force; the periodic change named stays named."""
    r = one[(name, load)]
    untrusted = r["verdict"] == "untrusted_effort"
    assert untrusted is (mean_named(r) == [] and r["jitter_named"] and r["jitter_change"] > 0)
    assert "periodic_force_change" in r["named"]
    assert not r["lag_named"]  # the steady lag never moves beyond its floor on this rig


def test_the_jitter_of_lack_of_lubrication_and_backlash_rises_at_every_load(one):
    for name in ("lackLubrication1", "backlash1"):
        for load in (20, 40, -40):
            r = one[(name, load)]
            assert r["jitter_named"] and r["jitter_change"] > 0  # +24..+66 %, floor 13 %


def test_the_default_witness_floors_are_three_times_the_rms_of_the_healthy_halves():
    cranfield.require()
    from bench.bench_diagnose_witness import floors

    from hil.analysis.diagnose.witness import WITNESS_FLOORS
    fl = floors()
    assert len(fl["rows"]) == 6
    assert fl["lag_3rms_m"] <= WITNESS_FLOORS["tracking_lag_m"] <= fl["lag_3rms_m"] + 1e-6  # rounded up to 1 um
    assert fl["jitter_3rms"] <= WITNESS_FLOORS["tracking_jitter_ratio"] <= fl["jitter_3rms"] + 0.01  # to 1 %


def test_every_row_labels_its_floors_a_repeatability(one):
    for r in one.values():
        assert r["floor"]["coverage"]["kind"] == "repeatability"


def test_three_healthy_references_give_a_reproducibility_from_their_spread(tmp_path):
    cranfield.require()
    from bench.bench_diagnose_witness import several
    (r,) = several(tmp_path, names=("lackLubrication1",), loads=(40,))
    cov = r["floor"]["coverage"]
    assert cov["kind"] == "reproducibility" and cov["pairs"] == 3
    assert r["floor"]["force_N"] == pytest.approx(cov["from_spread"]["force_N"])
    assert r["named"][0] == "friction_change" and r["friction_change_N"] > 150
