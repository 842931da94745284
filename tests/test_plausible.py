"""Plausibility against the profile, in physical units (issue 47, part 2): a recording whose forces, strokes
or angles cannot belong to this actuation is refused or its channels made inconclusive, naming the column and
the likely unit; never a PASS, never a reading a wear trend could take. Each rule pinned at its boundary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.analysis import plausible
from hil.analysis.maint import analyze_signals, refuse_implausible, result_dict
from hil.errors import ProfileError, RecordingError
from hil.history.record import record_from_result
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE
from hil.profile.load import actuation_from_tables, actuation_tables, load_actuation
from hil.record.runfolder import read_signals

# ------------------------------------------------------------------ the rules, each at its boundary


def test_a_unit_is_named_within_its_match_factor_and_not_beyond():
    f = plausible.UNIT_MATCH_FACTOR
    assert plausible.likely_units(1e-3, plausible.FORCE_UNITS) == ["kN"]
    assert plausible.likely_units(1e-3 * f * (1 - 1e-12), plausible.FORCE_UNITS) == ["kN"]
    assert plausible.likely_units(1e-3 * f * (1 + 1e-9), plausible.FORCE_UNITS) == []
    assert plausible.likely_units(1e-3 / f / (1 + 1e-9), plausible.FORCE_UNITS) == []
    assert plausible.likely_units(180 / math.pi, plausible.ANGLE_UNITS) == ["degrees"]
    assert plausible.likely_units(0.0, plausible.FORCE_UNITS) == [] and plausible.likely_units(
        float("nan"), plausible.FORCE_UNITS) == []


def _fight(level_N: float, n: int = 2000, imbalance_N: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A force fight whose ``|F2 - F1| / 2`` is ``level_N`` exactly on every sample (a square wave)."""
    f = level_N * np.where(np.arange(n) % 200 < 100, 1.0, -1.0)
    return -f + imbalance_N / 2, f + imbalance_N / 2


def test_the_force_fight_must_reach_a_tenth_of_its_commanded_level():
    commanded = 6000.0
    bound = plausible.MIN_FORCE_FIGHT_FRACTION * commanded
    assert plausible.force_fight_problem(*_fight(bound), commanded) == ""
    words = plausible.force_fight_problem(*_fight(math.nextafter(bound, 0.0)), commanded)
    assert words.startswith("columns 'F1', 'F2' [N]: the force fight reached") and "tenth" in words
    assert "(forces in kN?)" in plausible.force_fight_problem(*_fight(commanded * 1e-3), commanded)
    # one load cell with the wrong sign: the two "fight" with the same sign, the difference is about 0
    F1, F2 = _fight(commanded)
    assert "wrong sign" in plausible.force_fight_problem(-F1, F2, commanded)


def test_the_load_cells_may_disagree_by_half_the_level_and_no_more():
    level = 5000.0
    F1, F2 = _fight(level, imbalance_N=plausible.MAX_IMBALANCE_RATIO * level)
    assert plausible.load_cells_problem(F1, F2) == ""
    F1, F2 = _fight(level, imbalance_N=plausible.MAX_IMBALANCE_RATIO * level * (1 + 1e-6))
    assert "the load cells disagree" in plausible.load_cells_problem(F1, F2)
    # the derivation: one load cell reading r = 0.6 of the other is exactly the limit
    r = 0.6
    assert 2 * (1 - r) / (1 + r) == pytest.approx(plausible.MAX_IMBALANCE_RATIO)
    F1, F2 = _fight(level)
    assert "'F1' in kN?" in plausible.load_cells_problem(F1 * 1e-3, F2)
    assert "'F2' in lbf?" in plausible.load_cells_problem(F1, F2 / 4.4482216)


def test_the_lvdt_pitch_tolerance_and_the_gross_factor():
    tol = HARD_LVDT_GAIN_TOLERANCE
    assert plausible.pitch_problem(1, 1.0 + tol, "x") == ("", False)
    assert plausible.pitch_problem(1, 1.0 - tol, "x") == ("", False)
    words, gross = plausible.pitch_problem(1, math.nextafter(1.0 + tol, 2.0), "x")
    assert words and not gross and "i_total_rad_per_mm" in words
    assert plausible.pitch_problem(2, plausible.GROSS_PITCH_FACTOR, "x")[1] is False
    words, gross = plausible.pitch_problem(2, math.nextafter(plausible.GROSS_PITCH_FACTOR, 3.0), "x")
    assert gross and words.startswith("columns 's2' [mm], 'phi2' [rad]")
    words, gross = plausible.pitch_problem(1, 1.075e-3, "x")
    assert gross and "'s1' in m" in words
    words, gross = plausible.pitch_problem(1, 1.0 / (180 / math.pi), "x")
    assert gross and "'phi1' in degrees" in words


def test_a_pitch_needs_travel_to_be_estimated():
    x = np.linspace(0.0, plausible.MIN_TRAVEL_FOR_SCALE_MM, 100)
    assert plausible.slope_pitch(x, 1.05 * x + 0.3) == pytest.approx(1.05)
    assert plausible.slope_pitch(x[:-1], 1.05 * x[:-1]) is None


def test_the_stiffness_range_is_the_profiles_or_derived(actuation):
    stated = plausible.stiffness_range(actuation, "int1", 6000.0)
    assert (stated.min_N_per_mm, stated.max_N_per_mm) == (26700.0, 240000.0)
    ext = plausible.stiffness_range(actuation, "ext", 6000.0)
    assert (ext.min_N_per_mm, ext.max_N_per_mm) == (6300.0, 57000.0)
    tables = actuation_tables(actuation)
    for k in ("int_min", "int_max", "ext_min", "ext_max"):
        tables["mechanics"][f"stiffness_{k}_N_per_mm"] = 0.0
    derived = plausible.stiffness_range(actuation_from_tables(tables, "a.toml"), "int2", 6000.0)
    m = actuation.mechanics
    assert derived.min_N_per_mm == m.limit_load_N / m.stroke_limit_mm
    assert derived.max_N_per_mm == 6000.0 / actuation.sensors.lvdt_noise_pp_mm
    assert "derived" in derived.source
    # the bounds themselves pass, a float beyond either fails, and the force unit that fits is named
    assert plausible.stiffness_problem("int1", {"left": 26700.0, "right": 240000.0}, stated, "c") == ""
    assert plausible.stiffness_problem("int1", {"left": math.nextafter(26700.0, 0), "right": 8e4}, stated, "c")
    assert plausible.stiffness_problem("int1", {"left": 8e4, "right": math.nextafter(240000.0, 1e6)}, stated, "c")
    assert "(forces in kN?)" in plausible.stiffness_problem("int1", {"left": 80.0, "right": 79.0}, stated, "c")


def test_a_stated_stiffness_range_is_stated_whole_and_not_empty(actuation):
    tables = actuation_tables(actuation)
    tables["mechanics"]["stiffness_int_max_N_per_mm"] = 0.0
    with pytest.raises(ProfileError, match="stiffness_int_min_N_per_mm' and .*give both or neither"):
        actuation_from_tables(tables, "a.toml")
    tables = actuation_tables(actuation)
    tables["mechanics"]["stiffness_ext_min_N_per_mm"] = 57000.0
    with pytest.raises(ProfileError, match="stiffness_ext_min_N_per_mm' = 57000 is not below"):
        actuation_from_tables(tables, "a.toml")


# ------------------------------------------------------------------ a check's recording in other units

#: column -> factor of a recording written in another unit than the format's, and what must be said
NONSENSE = {
    "forces in kN": ({"F1": 1e-3, "F2": 1e-3}, "(forces in kN?)"),
    "forces in kgf": ({"F1": 1 / 9.80665, "F2": 1 / 9.80665}, "kgf"),
    "forces in lbf": ({"F1": 1 / 4.4482216, "F2": 1 / 4.4482216}, "lbf"),
    "F1 alone in kN": ({"F1": 1e-3}, "'F1' in kN?"),
    "F1 with the wrong sign": ({"F1": -1.0}, "wrong sign"),
}
REFUSED = {
    "strokes in m": ({"s1": 1e-3, "s2": 1e-3}, "'s1' in m"),
    "s2 alone in cm": ({"s2": 0.1}, "'s2' in cm"),
}


def _scaled(sig, factors: dict):
    from dataclasses import replace
    return replace(sig, **{c: getattr(sig, c) * f for c, f in factors.items()})


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(NONSENSE))
def test_a_recording_in_other_units_is_never_a_pass_nor_a_trend_point(dry_run, actuation, case):
    run, _ = dry_run
    sig = read_signals(run / "signals.csv")
    healthy = result_dict(analyze_signals(sig, actuation), actuation)
    assert healthy["status"] == "pass"  # the same recording in its own units passes
    factors, words = NONSENSE[case]
    res = result_dict(analyze_signals(_scaled(sig, factors), actuation), actuation)
    assert res["status"] == "inconclusive"
    assert any(words in v["reason"] and v["status"] == "inconclusive" for v in res["verdict"].values())
    assert all(res["backlash_mm"][ch] is None for ch in ("int1", "int2", "ext"))
    readings = record_from_result(res).readings
    assert len(readings) == 3 and all(r["backlash_mm"] is None and r["uncertainty_mm"] is None for r in readings)


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_recording_whose_strokes_are_in_other_units_is_refused_naming_the_column(dry_run, actuation, case):
    run, _ = dry_run
    sig = _scaled(read_signals(run / "signals.csv"), REFUSED[case][0])
    with pytest.raises(RecordingError, match=REFUSED[case][1].replace("'", "'")):
        analyze_signals(sig, actuation)
    with pytest.raises(RecordingError, match="cannot belong to this actuation"):
        refuse_implausible(sig, actuation, None)


@pytest.mark.slow
def test_the_cli_says_why_and_exits_5_or_3(dry_run, tmp_path, capsys):
    from test_columns_by_name import write_columns

    from hil.cli import main
    from hil.record.signals_csv import SIGNAL_COLUMNS
    sig = read_signals(dry_run[0] / "signals.csv")
    kn = _scaled(sig, {"F1": 1e-3, "F2": 1e-3})
    csv = write_columns(tmp_path / "kN.csv", {c: getattr(kn, c) for c in SIGNAL_COLUMNS}, SIGNAL_COLUMNS)
    assert main(["analyze", str(csv), "--out", str(tmp_path / "a"), "--no-history"]) == 5
    assert "(forces in kN?)" in capsys.readouterr().out
    assert main(["diagnose", str(csv), "--out", str(tmp_path / "d")]) == 3
    assert "(forces in kN?)" in capsys.readouterr().err
    m = _scaled(sig, {"s1": 1e-3, "s2": 1e-3})
    csv = write_columns(tmp_path / "m.csv", {c: getattr(m, c) for c in SIGNAL_COLUMNS}, SIGNAL_COLUMNS)
    assert main(["analyze", str(csv), "--out", str(tmp_path / "b"), "--no-history"]) == 3
    assert "'s1' in m" in capsys.readouterr().err
    assert main(["serv", str(csv), "--out", str(tmp_path / "s"), "--no-history"]) == 3
    assert "'s2' in m" in capsys.readouterr().err
    assert main(["diagnose", str(csv), "--out", str(tmp_path / "dm")]) == 3
    assert "cannot belong to this actuation" in capsys.readouterr().err


def test_the_shipped_profile_states_its_stiffness_ranges():
    m = load_actuation().mechanics
    assert 0 < m.stiffness_int_min_N_per_mm < m.stiffness_int_max_N_per_mm
    assert 0 < m.stiffness_ext_min_N_per_mm < m.stiffness_ext_max_N_per_mm
