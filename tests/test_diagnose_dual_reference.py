"""``emacheck diagnose NEW --reference HEALTHY`` with the dual-EMA model (issue 35, part 1).

Slow (about 4 min on a loaded machine): simulated checks of the shipped rig (``emacheck simulate``), healthy
with noise seed 11 and changed with seed 13: the contact stiffness of EMA 1 down 20 %, the internal play of
EMA 2 up 30 um, a Coulomb friction of 10 N in the drive of EMA 1 (a library effect, fitted on both checks),
the load cell gain of EMA 2 up 2 %. Each change is named at the right EMA with the right sign and a size
within 30 %. Extras are not asserted (docs/diagnose.md says which appear). Two healthy checks with different
noise seeds (14 against 11) name nothing. Then ``--reference history`` and the serial rule, the check
profile's floors, and the bad inputs (exit 3, nothing written).
"""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

from hil.cli import main
from support.figures import figures_unrendered
from support.profiles import write_profile_variant
from support.shared_fits import module_fits_once  # noqa: F401 (a fixture, used below)

# the module's diagnoses read and fit each recording once (support.shared_fits): no recording here changes at its
# path, none is refused for itself
pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("module_fits_once")]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """``simulated(seed, **variant)``: the run folder of ``emacheck simulate`` with that noise seed on the shipped
    rig changed as ``write_profile_variant("simrig.toml", ..., **variant)`` says, simulated once per module:
    several tests ask for the same check (seed 14 healthy; EMA 2's play up 30 um, seed 13), which they only read.
    Its report's figures are built, not drawn: no test here looks at the
    simulated check's report (the diagnosis reports are drawn)."""
    root = tmp_path_factory.mktemp("dual")
    made: dict = {}

    def simulate(seed: int, **variant) -> Path:
        key = (seed, json.dumps(variant, sort_keys=True))
        if key not in made:
            out = root / f"seed{seed}-{len(made)}"
            argv = ["simulate", "--seed", str(seed), "--out", str(out), "--quiet"]
            if variant:
                argv += ["--sim", str(write_profile_variant("simrig.toml", root / f"rig-{len(made)}.toml", **variant))]
            with figures_unrendered():
                assert main(argv) == 0
            made[key] = out
        return made[key]

    return simulate


@pytest.fixture(scope="module")
def healthy(simulated):
    return simulated(11)


@pytest.mark.parametrize("section, values, param, where, change", [
    ("ema1", {"stiffness_compression_N_per_mm": 64000.0, "stiffness_tension_N_per_mm": 64000.0},
     "stiffness_int1_N_per_mm", "ema1", -20.0),
    ("ema2", {"backlash_int_mm": 0.15}, "backlash_int2_mm", "ema2", 30.0),
    ("effects", [{"name": "coulomb_friction", "where": "ema1", "force_N": 10.0}], "coulomb_friction.force_N",
     "ema1", 10.0),
    ("sensors2", {"loadcell_gain": 1.02}, "loadcell_gain.gain_error", "ema2", 2.0),
])
def test_a_changed_rig_is_named_at_the_right_ema_with_sign_and_size(healthy, simulated, tmp_path, section, values,
                                                                     param, where, change):
    run = simulated(13, **({"add": {section: values}} if section == "effects" else {"overrides": {section: values}}))
    out = tmp_path / "o"
    assert main(["diagnose", str(run), "--reference", str(healthy), "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    from importlib import resources
    jsonschema.validate(data, json.loads(resources.files("hil.schemas").joinpath("diagnosis.schema.json").read_text()))
    (e,) = [e for e in data["effects"] if param in e["change"]]
    assert e["where"] == where
    assert e["change"][param] == pytest.approx(change, rel=0.3)
    assert e["change"][param] * change > 0 and e["floor"][param] < abs(change)
    (c,) = [c for c in data["changes"] if c["parameter"] == param]
    assert c["named"] and abs(c["z"]) > 3
    # the fits before and after: the reference's model with the named changes fits this check better
    before, after = data["fits"]["before"], data["fits"]["after"]
    assert max(before[k] / after[k] for k in before) > 1.15
    assert all(after[k] <= 1.01 * before[k] for k in before)
    html = (out / "diagnosis_report.html").read_text()
    assert "change ± U (k=2)" in html and param in html and "Fits before and after" in html


def test_two_healthy_checks_with_different_noise_name_nothing(healthy, simulated, tmp_path):
    """Seed 14 against seed 11 of the shipped rig (14 not among the floors' measurements): every change
    under its floor, nothing named."""
    run = simulated(14)
    out = tmp_path / "o"
    assert main(["diagnose", str(run), "--reference", str(healthy), "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    assert data["verdict"] == "no_mismatch" and data["effects"] == []
    assert len(data["changes"]) >= 14 and not any(c["named"] for c in data["changes"])
    assert all(abs(c["change"]) <= c["floor"] for c in data["changes"] if c["floor"] is not None)


def test_in_the_independent_rigs_layout_a_change_is_named_and_healthy_checks_name_nothing(healthy, simulated,
                                                                                           tmp_path):
    """The checks as bare CSVs in the independent rig's layout (t,phi1,phi2,s1,s2,F1,F2 only: no run folder, no
    step or mode columns, the phases found from the data): EMA 2's internal play up 30 um is named there within
    30 %; seed 14 against seed 11 names nothing (tests/bench/bench_diagnose_reference_pairs.py --bare: all nine)."""
    from bench.bench_diagnose_reference_pairs import bare
    runs = {"play": simulated(13, overrides={"ema2": {"backlash_int_mm": 0.15}}), "h14": simulated(14)}
    ref = bare(healthy, tmp_path / "healthy.csv")
    assert ref.read_text().splitlines()[0] == "t,phi1,phi2,s1,s2,F1,F2"
    for name, run in runs.items():
        out = tmp_path / f"o-{name}"
        assert main(["diagnose", str(bare(run, tmp_path / f"{name}.csv")), "--reference", str(ref), "--out", str(out),
                     "--quiet", "--no-report"]) == 0
        data = json.loads((out / "diagnosis.json").read_text())
        if name == "play":
            (e,) = [e for e in data["effects"] if "backlash_int2_mm" in e["change"]]
            assert e["where"] == "ema2" and e["change"]["backlash_int2_mm"] == pytest.approx(30.0, rel=0.3)
            assert {e["name"] for e in data["effects"]} == {"internal_play_change"}
        else:
            assert data["verdict"] == "no_mismatch" and data["effects"] == []


# --reference history (the wear history's last check of the same actuator serials) and the serial rule


@pytest.fixture(scope="module")
def history_runs(healthy, simulated, tmp_path_factory):
    """After ``healthy`` (seed 11): ``other``, EMA 2 replaced (another serial, seed 12), then ``later``, the
    healthy actuators with 10 N more Coulomb friction in the drive of EMA 1 (seed 13). ``same.db`` records
    ``healthy``; ``mixed.db`` records ``healthy`` and ``other``."""
    root = tmp_path_factory.mktemp("hist")
    other = simulated(12, overrides={"identity": {"serial_ema2": 0x5E000199}})
    # simulated here, after ``other`` (not the module's check of the same rig and seed, which may be older): the
    # wear history's reference is the last check before it in time
    later_rig = write_profile_variant("simrig.toml", root / "later.toml", add={"effects": [
        {"name": "coulomb_friction", "where": "ema1", "force_N": 10.0}]})
    later = root / "later"
    with figures_unrendered():
        assert main(["simulate", "--sim", str(later_rig), "--seed", "13", "--out", str(later), "--quiet"]) == 0
    same, mixed = f"sqlite:///{root / 'same.db'}", f"sqlite:///{root / 'mixed.db'}"
    assert main(["history", "sync", str(healthy), "--history", same]) == 0
    assert main(["history", "sync", str(healthy), str(other), "--history", mixed]) == 0
    return {"healthy": healthy, "other": other, "later": later, "same": same, "mixed": mixed, "root": root}


def test_reference_history_takes_the_last_check_of_the_same_serials(history_runs, tmp_path):
    h = history_runs
    out = tmp_path / "o"
    assert main(["diagnose", str(h["later"]), "--reference", "history", "--history", h["same"], "--out", str(out),
                 "--quiet"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    assert data["reference_history"]["run_folder"] == str(h["healthy"].resolve())
    assert data["reference_history"]["same_serials"] and data["serials"]["same"]
    (e,) = [e for e in data["effects"] if "coulomb_friction.force_N" in e["change"]]
    assert e["where"] == "ema1" and e["change"]["coulomb_friction.force_N"] == pytest.approx(10.0, rel=0.3)


def test_other_serials_are_refused_unless_allowed(history_runs, tmp_path, capsys):
    """The last check sharing an actuator with ``later`` is ``other`` (EMA 2 replaced): refused, exit 3, nothing
    written; the same for ``other`` given as the reference; taken with --allow-other-serials and said so."""
    h = history_runs
    out = tmp_path / "o"
    for ref in (["--reference", "history", "--history", h["mixed"]], ["--reference", str(h["other"])]):
        assert main(["diagnose", str(h["later"]), *ref, "--out", str(out), "--quiet"]) == 3
        assert not out.exists()
        err = capsys.readouterr().err
        assert "0x5E000199" in err and "0x5E000102" in err and "--allow-other-serials" in err
    assert main(["diagnose", str(h["later"]), "--reference", "history", "--history", h["mixed"],
                 "--allow-other-serials", "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    assert data["reference_history"]["run_folder"] == str(h["other"].resolve())
    assert data["reference_history"]["same_serials"] is False and data["serials"]["same"] is False


def test_bad_history_reference_exits_3_and_writes_nothing(history_runs, tmp_path, capsys):
    h = history_runs
    slow = write_profile_variant("simrig.toml", tmp_path / "slow.toml", {"rig": {"sample_period_s": 0.004}})
    slow_run = tmp_path / "slow"
    assert main(["simulate", "--sim", str(slow), "--seed", "14", "--out", str(slow_run), "--quiet"]) == 0
    axis = tmp_path / "axis.csv"  # a single-axis recording: the other model
    axis.write_text("t,q,q_ref,force\n" + "".join(f"{k * 0.01},{k * 1e-5},{k * 1e-5},1.0\n" for k in range(2000)))
    cases = [
        (["--reference", str(axis)], h["later"], "axis.csv"),
        (["--reference", "history", "--history", f"sqlite:///{tmp_path / 'none.db'}"], h["later"], "no wear history"),
        (["--reference", "history", "--history", h["same"]], h["healthy"], "no earlier check"),
        (["--reference", "history", "--history", h["same"]], h["later"] / "signals.csv", "not a run folder"),
        (["--reference", "history", "--history", h["same"], "--model", "single-axis"], h["later"], "single axis"),
        (["--reference", str(slow_run)], h["later"], "another sample rate"),
    ]
    for args, rec, words in cases:
        out = tmp_path / "o"
        assert main(["diagnose", str(rec), *args, "--out", str(out), "--quiet"]) == 3, words
        assert not out.exists()
        assert words in capsys.readouterr().err


def test_the_check_profile_sets_the_floors_and_diagnosis_json_states_them(history_runs, tmp_path, capsys):
    """``[diagnosis] ema_friction_N = 20`` in the check profile given with --check: the 10 N drive friction is
    supported but under that floor, not named; the source and the floors are in diagnosis.json. A floor
    that is not > 0 is refused (exit 3) naming the field, nothing written."""
    h = history_runs
    check = write_profile_variant("check.toml", tmp_path / "check.toml", add={"diagnosis": {"ema_friction_N": 20.0}})
    out = tmp_path / "o"
    assert main(["diagnose", str(h["later"]), "--reference", str(h["healthy"]), "--check", str(check),
                 "--out", str(out), "--quiet", "--no-report"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    assert data["floor"]["by_kind"]["ema_friction_N"] == 20.0 and str(check) in data["floor"]["source"]
    assert data["floor"]["by_kind"]["play_um"] == data["floor"]["defaults"]["play_um"] == 0.6
    (c,) = [c for c in data["changes"] if c["parameter"] == "coulomb_friction.force_N"]
    assert 5.0 < c["change"] < 20.0 and c["supported"] and not c["named"] and c["floor"] == 20.0
    assert not any("coulomb_friction.force_N" in e["change"] for e in data["effects"])
    bad = write_profile_variant("check.toml", tmp_path / "bad.toml", add={"diagnosis": {"ema_friction_N": 0.0}})
    out2 = tmp_path / "o2"
    assert main(["diagnose", str(h["later"]), "--reference", str(h["healthy"]), "--check", str(bad),
                 "--out", str(out2), "--quiet"]) == 3
    assert not out2.exists() and "diagnosis.ema_friction_N" in capsys.readouterr().err
