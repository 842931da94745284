"""Profiles: the shipped ones load; bad ones are refused with the field named."""

from __future__ import annotations

import pytest

from hil.errors import ProfileError
from hil.profile.load import load_actuation, load_check, load_simrig
from support.profiles import write_profile_variant


def test_shipped_profiles_load():
    act = load_actuation()
    assert act.mechanics.i_total_rad_per_mm == pytest.approx(2 * 3.141592653589793 * 4 / 5)
    assert act.timing.sync_period_s == 0.002
    chk = load_check(None, act)
    assert chk.force_fight.amplitude_fraction_of_limit == 0.15
    sim = load_simrig()
    assert sim.params.ema2.backlash_int_mm == 0.12
    assert sim.seed == 20261122


@pytest.mark.parametrize("name,variant,message", [
    ("actuation.toml", dict(remove=["mechanics.limit_load_N"]), r"missing field 'mechanics.limit_load_N'"),
    ("actuation.toml", dict(rename={"mechanics.stroke_limit_mm": "stroke_limit_cm"}),
     r"unknown field 'mechanics.stroke_limit_cm'.*did you mean 'stroke_limit_mm'"),
    ("actuation.toml", dict(overrides={"timing": {"sync_period_s": "2 ms"}}),
     r"'timing.sync_period_s' must be a number"),
    ("actuation.toml", dict(overrides={"mechanics": {"i_total_rad_per_mm": -5.0}}),
     r"'mechanics.i_total_rad_per_mm' = -5.0 must be > 0"),
    ("check.toml", dict(overrides={"force_fight": {"amplitude_fraction_of_limit": 0.2}}),
     r"'force_fight.amplitude_fraction_of_limit' = 0.2 is above the hard cap 0.15"),
    ("check.toml", dict(rename={"calibration.sweep_speed_mm_per_s": "sweep_speed_mm_per_min"}),
     r"did you mean 'sweep_speed_mm_per_s'"),
    ("check.toml", dict(overrides={"safety": {"max_force_N": 20000.0}}),
     r"'safety.max_force_N' = 20000.0 is above the hard cap 10000 N"),
    ("check.toml", dict(overrides={"safety": {"max_stroke_mm": 25.0}}),
     r"'safety.max_stroke_mm' = 25.0 is above the hard cap 20.0 mm"),
    ("check.toml", dict(overrides={"calibration": {"opposing_force_N": 9000.0}}), r"'calibration.opposing_force_N'"),
    ("check.toml", dict(overrides={"force_fight": {"cycles": 2.5}}), r"'force_fight.cycles' must be an integer"),
    ("check.toml", dict(overrides={"safety": {"max_velocity_mm_per_s": 80.0}}), r"above the hard cap 50.0"),
])
def test_bad_actuation_and_check(tmp_path, name, variant, message):
    path = write_profile_variant(name, tmp_path / name, **variant)
    with pytest.raises(ProfileError, match=message):
        if name == "actuation.toml":
            load_actuation(path)
        else:
            load_check(path, load_actuation())


_EFFECT = {"name": "coulomb_friction", "where": "ema1", "force_N": 150.0}


@pytest.mark.parametrize("variant,message", [
    (dict(overrides={"seed": -3}), r"'seed' must be a non-negative integer"),
    (dict(overrides={"ema1": {"backlash_int_mm": 7.0}}), r"'ema1.backlash_int_mm' = 7.0 must be <= 5.0"),
    (dict(overrides={"rig": {"substeps": 0}}), r"'rig.substeps' = 0 must be >= 1"),
    (dict(rename={"surface": "surfaces"}), r"unknown field 'surfaces'.*did you mean 'surface'"),
    (dict(add={"effects": [dict(_EFFECT, name="coulomb_frictoin")]}),
     r"'effects\[0\].name' = 'coulomb_frictoin' is not a known effect \(did you mean 'coulomb_friction'"),
    (dict(add={"effects": [{"name": "coulomb_friction", "where": "ema1", "force_kN": 0.15}]}),
     r"unknown field 'effects\[0\].force_kN'.*did you mean 'force_N'"),
])
def test_bad_simrig(tmp_path, variant, message):
    with pytest.raises(ProfileError, match=message):
        load_simrig(write_profile_variant("simrig.toml", tmp_path / "simrig.toml", **variant))


def test_effect_loads(tmp_path):
    p = write_profile_variant("simrig.toml", tmp_path / "simrig.toml", add={"effects": [_EFFECT]})
    sim = load_simrig(p)
    (eff,) = sim.params.effects
    assert type(eff).__name__ == "CoulombFriction" and eff.force_N == 150.0 and eff.where == "ema1"


def test_variant_helper_refuses_a_key_the_profile_does_not_have(tmp_path):
    """An override of a key that is not in the profile is a mistake in the test, not a variant."""
    with pytest.raises(KeyError, match=r"safety\.max_strok_mm"):
        write_profile_variant("check.toml", tmp_path / "check.toml", {"safety": {"max_strok_mm": 3.0}})
    with pytest.raises(KeyError, match=r"mechanics\.nope"):
        write_profile_variant("actuation.toml", tmp_path / "a.toml", remove=["mechanics.nope"])
    with pytest.raises(KeyError, match=r"'seed'"):
        write_profile_variant("simrig.toml", tmp_path / "s.toml", add={"seed": 1})
    assert not (tmp_path / "check.toml").exists()


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "x.toml"
    bad.write_text("this is = = not toml")
    with pytest.raises(ProfileError, match="x.toml: not valid TOML"):
        load_actuation(bad)
    with pytest.raises(ProfileError, match="profile not found"):
        load_check(tmp_path / "nope.toml")
