"""End-to-end through the command line: simulate, analyze, exit codes, bad input."""

from __future__ import annotations

import dataclasses
import json

import pytest

from hil.cli import main
from hil.record.runfolder import MetaWriter, read_record
from support.profiles import write_profile_variant


@pytest.mark.slow
def test_simulate_writes_run_folder_and_passes(tmp_path):
    out = tmp_path / "run"
    rc = main(["simulate", "--out", str(out), "--seed", "7", "--quiet"])
    assert rc == 0
    for f in ("signals.csv", "meta.json", "result.json", "report.html"):
        assert (out / f).stat().st_size > 0, f
    res = json.loads((out / "result.json").read_text())
    meta = read_record(out)
    assert res["status"] == "pass" and meta.seed == 7 and meta.status == "done"
    assert meta.software.name == "emacheck" and meta.mode == "simulate"
    assert set(res["backlash_mm"]) == {"int1", "int2", "ext"}
    assert abs(res["backlash_mm"]["int2"] - res["truth"]["backlash_mm"]["int2"]) < 0.005
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 8 and "PASS" in html


@pytest.mark.slow
def test_analyze_run_folder_reproduces_result(default_run, tmp_path):
    run_dir, truth = default_run
    rc = main(["analyze", str(run_dir), "--out", str(tmp_path)])
    assert rc == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["segments"]["source"] == "step column"
    assert res["truth"] == truth  # carried in meta.json


@pytest.mark.slow
def test_analyze_bare_csv_finds_segments_itself(default_run, tmp_path):
    """A CSV recorded elsewhere: only t,phi1,phi2,s1,s2,F1,F2, no step column."""
    run_dir, truth = default_run
    lines = (run_dir / "signals.csv").read_text().splitlines()
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(",".join(line.split(",")[:7]) for line in lines) + "\n")
    rc = main(["analyze", str(bare), "--out", str(tmp_path / "a")])
    assert rc == 0
    res = json.loads((tmp_path / "a" / "result.json").read_text())
    assert res["segments"]["source"] == "detected"
    for ch in ("int1", "int2", "ext"):
        assert abs(res["backlash_mm"][ch] - truth["backlash_mm"][ch]) < 0.005, ch
    for k in ("ema1", "ema2"):
        assert res["calibration"][k]["pitch"] == pytest.approx(truth["calibration"][k]["pitch"], rel=1e-3)


@pytest.mark.slow
def test_analyze_force_fight_only_says_uncorrected(default_run, tmp_path):
    run_dir, truth = default_run
    lines = (run_dir / "signals.csv").read_text().splitlines()
    head = lines[0].split(",")
    step = head.index("step")
    keep = [lines[0]] + [line for line in lines[1:] if line.split(",")[step] == "force_fight"]
    p = tmp_path / "ff.csv"
    p.write_text("\n".join(",".join(line.split(",")[:7]) for line in keep) + "\n")
    rc = main(["analyze", str(p), "--out", str(tmp_path / "a")])
    res = json.loads((tmp_path / "a" / "result.json").read_text())
    # the shipped rig passes uncalibrated too: U carries the uncalibrated pitch (tests/test_check_known_answer.py)
    assert rc == 0 and res["status"] == "pass", res.get("verdict")
    assert res["calibration"] == {"ema1": None, "ema2": None}
    assert any("uncorrected" in n for n in res["notes"])


@pytest.mark.slow
def test_fail_against_spec_exits_1(default_run, tmp_path):
    run_dir, _ = default_run
    p = write_profile_variant("actuation.toml", tmp_path / "tight.toml", {"mechanics": {"backlash_spec_int_mm": 0.11}})
    rc = main(["analyze", str(run_dir), "--profile", str(p), "--out", str(tmp_path / "a")])
    assert rc == 1  # int2 has 0.12 mm > 0.11 mm
    assert json.loads((tmp_path / "a" / "result.json").read_text())["status"] == "fail"


def test_bad_input_exit_3_and_message(tmp_path, capsys):
    bad = write_profile_variant("check.toml", tmp_path / "check.toml", {"force_fight": {"cycles": 0}})
    assert main(["simulate", "--check", str(bad), "--out", str(tmp_path / "x"), "--quiet"]) == 3
    err = capsys.readouterr().err
    assert "check.toml: field 'force_fight.cycles' = 0 must be >= 1" in err
    assert not (tmp_path / "x").exists()  # nothing ran
    assert main(["analyze", str(tmp_path / "missing.csv")]) == 3
    assert "no such file" in capsys.readouterr().err


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "simulate" in out and "analyze" in out and "exit status" in out


def test_safety_violation_aborts_with_reason_and_exit_2(tmp_path):
    chk = write_profile_variant("check.toml", tmp_path / "check.toml", {"safety": {"max_following_error_mm": 0.002}})
    out = tmp_path / "run"
    rc = main(["simulate", "--check", str(chk), "--out", str(out), "--quiet"])
    assert rc == 2
    res = json.loads((out / "result.json").read_text())
    meta = read_record(out)
    assert res["status"] == "aborted" and meta.status == "aborted"
    assert "max_following_error_mm" in res["reason"] and "following error" in meta.reason
    assert meta.safety.limit == "max_following_error_mm" and meta.safety.value > meta.safety.threshold == 0.002
    # both drives were commanded to DISABLED on the abort, and the data up to it is kept
    lines = (out / "signals.csv").read_text().splitlines()
    last = lines[-1].split(",")
    assert last[-1] == "aborted" and last[7] == "0" and last[9] == "0"
    assert len(lines) > 2


@pytest.mark.slow
def test_run_cut_just_after_the_force_fight_began_is_incomplete_not_a_crash(default_run, tmp_path):
    """A master killed a few samples into the force fight: `analyze` reports the run incomplete and
    why (too few force-fight samples), exit 2, result.json written."""
    src, _ = default_run
    out = tmp_path / "cut"
    out.mkdir()
    lines = (src / "signals.csv").read_text().splitlines()
    step = lines[0].split(",").index("step")
    first_ff = next(k for k, ln in enumerate(lines) if k and ln.split(",")[step] == "force_fight")
    (out / "signals.csv").write_text("\n".join(lines[: first_ff + 5]) + "\n")
    # the record as a killed master leaves it: still running, never sealed (the seal is written as the loop ends)
    MetaWriter(out, dataclasses.replace(read_record(src), status="running", recording_sha256=None)).write()
    assert main(["analyze", str(out), "--out", str(out)]) == 2
    (made,) = out.glob("analysis-*/result.json")  # a new sub-folder: the run folder's files stay
    res = json.loads(made.read_text())
    assert res["status"] == "incomplete"
    assert "force-fight segment too short for BLFmaint: 5 samples (need >= 200)" in res["analysis_error"]
