"""A result knows what it was made from (issue 47): result.json, serv.json and diagnosis.json name every file
they were read from, by role, with the SHA-256 of its bytes (``trace.inputs``, hil.record.inputs)."""

from __future__ import annotations

import json
import shutil
from importlib import resources
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from hil.analysis.diagnose.request import DiagnoseRequest
from hil.analysis.diagnose.results import DiagnoseOutcome
from hil.cli import main
from hil.profile.load import default_profile_path
from hil.record.seal import sha256_file
from sim import operation as op
from sim import scenarios as sc
from support.profiles import write_profile_variant

HEADER = "t,phi1,phi2,s1,s2,F1,F2"


def _schema(name: str) -> dict:
    return json.loads(resources.files("hil.schemas").joinpath(f"{name}.schema.json").read_text())


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory, simrig):
    """A normal-operation recording in a run folder with a result.json (its LVDT calibration) and a meta.json."""
    rec = op.simulate_operation(simrig.params, sc.full_stroke_profile(simrig.params), np.random.default_rng(5))
    d = tmp_path_factory.mktemp("inputs") / "run"
    d.mkdir()
    a = np.column_stack([rec.t_s, rec.phi1_rad, rec.phi2_rad, rec.s1_mm, rec.s2_mm, rec.F1_N, rec.F2_N])
    np.savetxt(d / "signals.csv", a, delimiter=",", header=HEADER, comments="",
               fmt=["%.4f", "%.7f", "%.7f", "%.6f", "%.6f", "%.3f", "%.3f"])
    (d / "result.json").write_text(json.dumps({"status": "pass", "calibration": {
        "ema1": {"pitch": 1.075, "offset_mm": 0.0}, "ema2": {"pitch": 0.98, "offset_mm": 0.0}}}))
    (d / "meta.json").write_text(json.dumps({"truth": {"backlash_mm": dict(rec.truth.backlash_mm)}}))
    return d


def _by_role(inputs: list[dict]) -> dict:
    roles = [i["role"] for i in inputs]
    assert len(roles) == len(set(roles)), roles
    for i in inputs:  # each hash is the file's as it is
        assert i["sha256"] == sha256_file(Path(i["file"])), i
    return {i["role"]: i for i in inputs}


def _serv(tmp_path, *args, report: bool = False) -> dict:
    out = tmp_path / "out"
    assert main(["serv", *map(str, args), "--out", str(out), "--no-history"] + ([] if report else ["--no-report"])) == 0
    data = json.loads((out / "serv.json").read_text())
    jsonschema.validate(data, _schema("serv"))
    return data


def test_serv_of_a_run_folder_names_its_recording_record_profile_and_calibration(run_folder, tmp_path):
    got = _by_role(_serv(tmp_path, run_folder, report=True)["trace"]["inputs"])
    assert set(got) == {"recording", "run_record", "actuation_profile", "calibration"}
    html = (tmp_path / "out" / "serv_report.html").read_text()  # the traceability table lists each
    assert all(f"read: {r} (sha256)</td><td>{got[r]['file']}: {got[r]['sha256'][:16]}" in html for r in got)
    assert got["recording"]["file"] == str(run_folder / "signals.csv")
    assert got["run_record"]["file"] == str(run_folder / "meta.json")
    # meta.json holds no profile snapshot here: the shipped profile was read
    assert got["actuation_profile"]["file"] == str(default_profile_path("actuation.toml"))
    assert got["calibration"]["file"] == str(run_folder / "result.json")


def test_serv_of_a_bare_csv_with_a_profile_and_a_calibration_file(run_folder, tmp_path):
    bare = tmp_path / "flight.csv"
    shutil.copy(run_folder / "signals.csv", bare)
    cal = tmp_path / "cal.json"
    shutil.copy(run_folder / "result.json", cal)
    prof = write_profile_variant("actuation.toml", tmp_path / "act.toml", {})
    got = _by_role(_serv(tmp_path, bare, "--profile", prof, "--calibration", cal)["trace"]["inputs"])
    assert {k: v["file"] for k, v in got.items()} == {"recording": str(bare), "actuation_profile": str(prof),
                                                      "calibration": str(cal)}
    # without a calibration file none is named (the recording's own sweeps or none)
    shutil.rmtree(tmp_path / "out")
    assert "calibration" not in _by_role(_serv(tmp_path, bare)["trace"]["inputs"])


@pytest.mark.slow
def test_analyze_names_the_run_record_and_the_profile_it_read(dry_run, tmp_path):
    run_dir, _ = dry_run
    prof = write_profile_variant("actuation.toml", tmp_path / "act.toml", {})
    for extra, profile in (([], (str(run_dir / "meta.json"), "profiles.actuation")), (["--profile", str(prof)],
                                                                                      (str(prof), None))):
        out = tmp_path / f"a{len(extra)}"
        assert main(["analyze", str(run_dir), "--out", str(out), "--no-history", *extra]) == 0
        res = json.loads((out / "result.json").read_text())
        jsonschema.validate(res, _schema("result"))
        got = _by_role(res["trace"]["inputs"])
        assert got["recording"]["file"] == str(run_dir / "signals.csv")
        assert got["run_record"]["file"] == str(run_dir / "meta.json")
        assert (got["actuation_profile"]["file"], got["actuation_profile"].get("part")) == profile
    # the check's own result names its recording (its profiles: files_sha256, hashed as it started)
    own = json.loads((run_dir / "result.json").read_text())["trace"]
    assert [i["role"] for i in own["inputs"]] == ["recording"]
    assert own["inputs"][0]["sha256"] == sha256_file(run_dir / "signals.csv") and own["files_sha256"]["actuation"]


def test_diagnosis_names_the_recording_the_reference_and_the_history(run_folder, tmp_path):
    """diagnosis.json's trace (hil.cli.diagnose): both recordings with their run records and profiles, the check
    profile, and the history database the reference was looked up in (an SQLite file, hashed)."""
    from hil.cli.diagnose import _trace

    ref = tmp_path / "ref"
    shutil.copytree(run_folder, ref)
    db = tmp_path / "h.sqlite"
    db.write_bytes(b"SQLite format 3\x00" + bytes(100))
    req = DiagnoseRequest(run_folder, "dual-ema", from_history=True, history_url=f"sqlite:///{db}")
    out = DiagnoseOutcome("dual_reference", {"verdict": "no_mismatch", "model": "dual-ema", "effects": [],
                                             "band": {}, "where": [], "reference": {"recording": str(ref)}})
    trace = _trace(req, out)
    jsonschema.validate(trace, _schema("diagnosis")["properties"]["trace"])
    got = _by_role(trace["inputs"])
    assert {k: v["file"] for k, v in got.items()} == {
        "recording": str(run_folder / "signals.csv"), "run_record": str(run_folder / "meta.json"),
        "actuation_profile": str(default_profile_path("actuation.toml")),
        "check_profile": str(default_profile_path("check.toml")),
        "reference_recording": str(ref / "signals.csv"), "reference_run_record": str(ref / "meta.json"),
        "reference_actuation_profile": str(default_profile_path("actuation.toml")), "history": str(db)}
    # a single axis: its recording and its reference file, nothing else
    single = _trace(DiagnoseRequest(run_folder / "signals.csv", "single-axis", reference=ref / "signals.csv"),
                    DiagnoseOutcome("axis_reference", {}))
    assert [(i["role"], i["file"]) for i in single["inputs"]] == [
        ("recording", str(run_folder / "signals.csv")), ("reference_recording", str(ref / "signals.csv"))]
