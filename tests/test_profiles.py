"""Profiles: the shipped ones load; bad ones are refused with the field named."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from hil.errors import ProfileError
from hil.profiles import default_profile_path, load_actuation, load_check, load_simrig


def _edit(tmp_path: Path, name: str, pattern: str, repl: str) -> Path:
    text = default_profile_path(name).read_text()
    new, n = re.subn(pattern, repl, text, count=1, flags=re.M)
    assert n == 1, f"pattern {pattern!r} not found in {name}"
    p = tmp_path / name
    p.write_text(new)
    return p


def test_shipped_profiles_load():
    act = load_actuation()
    assert act.mechanics.i_total_rad_per_mm == pytest.approx(2 * 3.141592653589793 * 4 / 5)
    assert act.timing.sync_period_s == 0.002
    chk = load_check(None, act)
    assert chk.force_fight.amplitude_fraction_of_limit == 0.15
    sim = load_simrig()
    assert sim.params.ema2.backlash_int_mm == 0.12
    assert sim.seed == 20261122


@pytest.mark.parametrize("name,pattern,repl,message", [
    ("actuation.toml", r"^limit_load_N = .*$", "", r"missing field 'mechanics.limit_load_N'"),
    ("actuation.toml", r"^stroke_limit_mm", "stroke_limit_cm", r"unknown field 'mechanics.stroke_limit_cm'.*did you mean 'stroke_limit_mm'"),
    ("actuation.toml", r"^sync_period_s = .*$", "sync_period_s = \"2 ms\"", r"'timing.sync_period_s' must be a number"),
    ("actuation.toml", r"^i_total_rad_per_mm = .*$", "i_total_rad_per_mm = -5.0", r"'mechanics.i_total_rad_per_mm' = -5.0 must be > 0"),
    ("check.toml", r"^amplitude_fraction_of_limit = .*$", "amplitude_fraction_of_limit = 0.2",
     r"'force_fight.amplitude_fraction_of_limit' = 0.2 is above the hard cap 0.15"),
    ("check.toml", r"^sweep_speed_mm_per_s", "sweep_speed_mm_per_min", r"did you mean 'sweep_speed_mm_per_s'"),
    ("check.toml", r"^max_force_N = .*$", "max_force_N = 20000.0", r"'safety.max_force_N' = 20000.0 is above the hard cap 10000 N"),
    ("check.toml", r"^max_stroke_mm = .*$", "max_stroke_mm = 25.0", r"'safety.max_stroke_mm' = 25.0 is above the hard cap 20.0 mm"),
    ("check.toml", r"^opposing_force_N = .*$", "opposing_force_N = 9000.0", r"'calibration.opposing_force_N'"),
    ("check.toml", r"^cycles = .*$", "cycles = 2.5", r"'force_fight.cycles' must be an integer"),
    ("check.toml", r"^max_velocity_mm_per_s = .*$", "max_velocity_mm_per_s = 80.0", r"above the hard cap 50.0"),
])
def test_bad_actuation_and_check(tmp_path, name, pattern, repl, message):
    path = _edit(tmp_path, name, pattern, repl)
    with pytest.raises(ProfileError, match=message):
        if name == "actuation.toml":
            load_actuation(path)
        else:
            load_check(path, load_actuation())


@pytest.mark.parametrize("pattern,repl,message", [
    (r"^seed = .*$", "seed = -3", r"'seed' must be a non-negative integer"),
    (r"^backlash_int_mm = 0.10$", "backlash_int_mm = 7.0", r"'ema1.backlash_int_mm' = 7.0 must be <= 5.0"),
    (r"^substeps = 8$", "substeps = 0", r"'rig.substeps' = 0 must be >= 1"),
    (r"^\[surface\]", "[surfaces]", r"unknown field 'surfaces'.*did you mean 'surface'"),
    (r"^# \[\[effects\]\]\n# name = \"coulomb_friction\"\n# where = \"ema1\"\n# force_N = 150.0",
     "[[effects]]\nname = \"coulomb_frictoin\"\nwhere = \"ema1\"\nforce_N = 150.0",
     r"'effects\[0\].name' = 'coulomb_frictoin' is not a known effect \(did you mean 'coulomb_friction'"),
    (r"^# \[\[effects\]\]\n# name = \"coulomb_friction\"\n# where = \"ema1\"\n# force_N = 150.0",
     "[[effects]]\nname = \"coulomb_friction\"\nwhere = \"ema1\"\nforce_kN = 0.15",
     r"unknown field 'effects\[0\].force_kN'.*did you mean 'force_N'"),
])
def test_bad_simrig(tmp_path, pattern, repl, message):
    with pytest.raises(ProfileError, match=message):
        load_simrig(_edit(tmp_path, "simrig.toml", pattern, repl))


def test_effect_loads(tmp_path):
    p = _edit(tmp_path, "simrig.toml",
              r"^# \[\[effects\]\]\n# name = \"coulomb_friction\"\n# where = \"ema1\"\n# force_N = 150.0",
              "[[effects]]\nname = \"coulomb_friction\"\nwhere = \"ema1\"\nforce_N = 150.0")
    sim = load_simrig(p)
    (eff,) = sim.params.effects
    assert type(eff).__name__ == "CoulombFriction" and eff.force_N == 150.0 and eff.where == "ema1"


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "x.toml"
    bad.write_text("this is = = not toml")
    with pytest.raises(ProfileError, match="x.toml: not valid TOML"):
        load_actuation(bad)
    with pytest.raises(ProfileError, match="profile not found"):
        load_check(tmp_path / "nope.toml")
