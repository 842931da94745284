"""Every problem of a profile named at once (issue 36, part 4): one run of ``profile check`` (or of any
command that loads the profile) lists them all, each naming file and field; a single problem reads as
before (no count)."""

from __future__ import annotations

import json

import pytest

from hil.cli import main
from hil.errors import ProfileError
from hil.profile.load import load_actuation, load_check, load_simrig
from support.profiles import write_profile_variant

OLD_FORMAT = """\
name = "an actuation profile of the format before the signal map"
[mechanics]
i_total_rad_per_mm = 5.0
stroke_limit_mm = 20.0
limit_load_N = -5.0
backlash_spec_int_mm = 0.20
backlash_spec_ext_mm = 0.20
[sensors]
lvdt_full_scale_mm = 20.0
lvdt_noise_pp_mm = 0.025
loadcell_noise_std_N = 10.0
resolver_counts_per_rev = 4096
[timing]
sync_periode = 0.002
"""


def _problems(fn, *args) -> tuple[str, ...]:
    with pytest.raises(ProfileError) as exc:
        fn(*args)
    return exc.value.problems


def test_an_old_format_profile_names_every_problem_in_one_run(tmp_path):
    p = tmp_path / "old.toml"
    p.write_text(OLD_FORMAT)
    probs = _problems(load_actuation, p)
    expected = ["field 'sensors.resolver_counts_per_rev' has moved to 'signals.ema1.motor_angle.counts_per_rev",
                "field 'mechanics.limit_load_N' = -5.0 must be > 0.0",
                "unknown field 'timing.sync_periode' (did you mean 'sync_period_s'?",
                "missing field 'timing.sync_period_s'",
                "missing field 'canopen'",
                "missing tables '[signals.ema1]' and '[signals.ema2]'"]
    for text in expected:
        assert sum(text in m for m in probs) == 1, (text, probs)
    assert all(m.startswith("old.toml: ") for m in probs)
    # the moved key is not also refused as an unknown one
    assert not any("unknown field 'sensors.resolver_counts_per_rev'" in m for m in probs)


def test_problems_in_fields_cross_rules_and_signal_map_are_named_together(tmp_path):
    p = write_profile_variant("actuation.toml", tmp_path / "a.toml",
                              {"canopen": {"node_id_ema2": 1},
                               "signals": {"ema2": {"force": {"N_per_unit": 0.0}}}},
                              add={"signals": {"ema1": {"lvdt": {"type": "INTEGER23"}}},
                                   "canopen": {"cob_ids": {"ema3.TPDO1": 0x181}}})
    probs = _problems(load_actuation, p)
    assert len(probs) == 4, probs
    for text in ("'canopen.node_id_ema1' and 'canopen.node_id_ema2' are both 1",
                 "'signals.ema1.lvdt.type' = 'INTEGER23'", "'signals.ema2.force.N_per_unit' = 0",
                 "'canopen.cob_ids.ema3.TPDO1'"):
        assert sum(text in m for m in probs) == 1, (text, probs)


def test_one_problem_reads_as_one_line(tmp_path):
    p = write_profile_variant("actuation.toml", tmp_path / "a.toml", {"mechanics": {"stroke_limit_mm": -1.0}})
    with pytest.raises(ProfileError) as exc:
        load_actuation(p)
    assert str(exc.value) == "a.toml: field 'mechanics.stroke_limit_mm' = -1.0 must be > 0.0"
    assert exc.value.problems == (str(exc.value),)


def test_every_unknown_key_of_a_table_is_named(tmp_path):
    p = write_profile_variant("check.toml", tmp_path / "c.toml",
                              add={"safety": {"max_force_kN": 1.0, "max_strok_mm": 2.0}})
    probs = _problems(load_check, p)
    assert len(probs) == 2 and "'safety.max_force_kN'" in probs[0] and "'safety.max_strok_mm'" in probs[1]


def test_the_check_against_its_actuation_names_every_rule_broken(tmp_path):
    act = load_actuation()
    p = write_profile_variant("check.toml", tmp_path / "c.toml",
                              {"calibration": {"opposing_force_N": 9000.0, "sweep_amplitude_mm": 19.5},
                               "approach": {"speed_mm_per_s": 15.0}})
    probs = _problems(load_check, p, act)
    assert len(probs) == 3, probs
    for text in ("'calibration.opposing_force_N' = 9000", "'calibration.sweep_amplitude_mm' = 19.5",
                 "'approach.speed_mm_per_s' = 15.0"):
        assert sum(text in m for m in probs) == 1, (text, probs)


def test_a_simulated_rig_profile_names_every_problem(tmp_path):
    p = write_profile_variant("simrig.toml", tmp_path / "s.toml",
                              {"rig": {"substeps": 0}, "ema1": {"backlash_int_mm": -1.0}, "seed": -3})
    probs = _problems(load_simrig, p)
    assert len(probs) == 3, probs
    for text in ("'rig.substeps' = 0", "'ema1.backlash_int_mm' = -1.0", "'seed' must be a non-negative"):
        assert sum(text in m for m in probs) == 1, (text, probs)


def test_profile_check_lists_every_problem_with_its_key(tmp_path, capsys):
    p = tmp_path / "old.toml"
    p.write_text(OLD_FORMAT)
    assert main(["profile", "check", str(p), "--json"]) == 3
    out = json.loads(capsys.readouterr().out)
    keys = [q["key"] for q in out["problems"]]
    assert out["ok"] is False and len(keys) == len(_problems(load_actuation, p))
    assert {"sensors.resolver_counts_per_rev", "mechanics.limit_load_N", "timing.sync_periode"} <= set(keys)
    assert main(["profile", "check", str(p)]) == 3
    err = capsys.readouterr().err
    assert f"old.toml: {len(keys)} problems (all of them" in err and "Traceback" not in err
