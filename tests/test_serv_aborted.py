"""`emacheck serv` of a run folder cut short (issue 47): a check aborted 52 s in was read from its first second,
the drives' enabling (0.038 and 0.048 mm against 0.100/0.120), the abort not mentioned. Now the run's status is
said (console, serv.json, report), BLFserv reads only the longest stretch of motion (never idle, enable, the LVDT
calibration, done, aborted), and a folder with none of at least MIN_SAMPLES_SERV samples is judged nothing
(status aborted or incomplete, every channel not measured, exit 2, no report)."""

from __future__ import annotations

import json
import shutil
from importlib import resources

import jsonschema
import numpy as np
import pytest

from hil.analysis.serv import MIN_SAMPLES_SERV, NOT_SERVICE, analyse, choose_calibration, serv_steps
from hil.cli import main
from hil.cli.args import ExitCode
from hil.cli.result import INCOMPLETE_REASON
from hil.errors import UnusableRecordingError
from hil.record.recording import load_recording
from hil.record.runfolder import read_record

SCHEMA = json.loads(resources.files("hil.schemas").joinpath("serv.schema.json").read_text())


def _aborted(tmp_path_factory, actuation, check_profile, simrig, at_s: float):
    """A dry-run whose drive 1 reports an over-current at ``at_s`` (its check aborts there)."""
    from hil.cli.dry_run import dry_run
    from sim.faults import Fault

    out = tmp_path_factory.mktemp("aborted") / "run"
    r = dry_run(actuation, check_profile, simrig, out, faults=[Fault("emcy_over_current", 1, at_s)])
    assert r.exit_code == ExitCode.ABORTED
    return out


@pytest.fixture(scope="module")
def at_52s(tmp_path_factory, actuation, check_profile, simrig):
    """The issue's case: aborted 52 s in, in the second LVDT calibration sweep."""
    return _aborted(tmp_path_factory, actuation, check_profile, simrig, 52.0)


@pytest.fixture(scope="module")
def at_06s(tmp_path_factory, actuation, check_profile, simrig):
    """Aborted 0.6 s in: the enable step (250 samples) and 43 samples of the approach."""
    return _aborted(tmp_path_factory, actuation, check_profile, simrig, 0.6)


def _serv(tmp_path, capsys, folder, *extra):
    out = tmp_path / "out"
    rc = main(["serv", str(folder), "--out", str(out), "--no-history", *extra])
    console = capsys.readouterr().out
    data = json.loads((out / "serv.json").read_text())
    jsonschema.validate(data, SCHEMA)
    return rc, data, out, console


@pytest.mark.slow
def test_aborted_52s_in_reads_only_the_motion_and_says_the_run_aborted(at_52s, tmp_path, capsys):
    meta = read_record(at_52s)
    assert meta.status == "aborted"
    rc, data, out, console = _serv(tmp_path, capsys, at_52s)
    # said: on the console, in serv.json (its run and its first note) and in the report
    assert data["run"] == {"status": "aborted", "reason": meta.reason, "words": data["notes"][0]}
    assert data["notes"][0].startswith(f"the check was aborted ({meta.reason})")
    assert f"run aborted: {meta.reason}" in console.replace("\n", " ")
    assert "the check was aborted" in (out / "serv_report.html").read_text()
    # read from the approach only (0.514..1.024 s): the enable step's D steps (0.038/0.048 mm at 0.51 s) are gone
    steps = {st.name: st for st in meta.steps}
    enable_end = steps["enable"].t_end_s
    rec = data["recording"]
    assert rec["steps"] == ["approach"] and rec["t_start_s"] >= enable_end
    assert rec["t_end_s"] < steps["cal1_load"].t_start_s
    for ch in ("int1", "int2", "ext"):
        # (the tail of the enable step's D step, cut at the stretch's start, has no plateau before: not counted)
        assert all(j["reason"] == "plateau before too short" for j in data["jumps"][ch] if j["t_s"] < enable_end + 0.1)
        assert data["backlash_mm"][ch] is None and data["verdict"][ch]["status"] == "not_traversed"
    # the approach crossed no play: nothing traversed, nothing decided (exit 5), never the enable step's PASS
    assert rc == ExitCode.INCONCLUSIVE and data["status"] == "inconclusive"


@pytest.mark.slow
def test_aborted_with_no_stretch_of_motion_judges_nothing(at_06s, tmp_path, capsys):
    meta = read_record(at_06s)
    rc, data, out, console = _serv(tmp_path, capsys, at_06s)
    assert rc == ExitCode.ABORTED and data["status"] == "aborted"
    assert data["run"]["status"] == "aborted" and data["run"]["reason"] == meta.reason
    why = data["analysis_error"]
    assert "43 sample(s) of motion" in why and f"at least {MIN_SAMPLES_SERV}" in why
    for ch in ("int1", "int2", "ext"):
        v = data["verdict"][ch]
        assert v["status"] == "inconclusive" and v["backlash_mm"] is None and v["reason"].startswith(
            "not measured: the run was cut short; 43 sample(s)")
    assert not (out / "serv_report.html").exists()
    assert "run aborted" in console and "not measured" in console


@pytest.mark.slow
@pytest.mark.parametrize("rows", [None, 0])
def test_a_run_killed_while_running_is_incomplete(at_06s, tmp_path, capsys, rows):
    """meta.json still `running` and unsealed (the master killed): said as incomplete, judged as the aborted
    one; the same where it was killed before its first data (signals.csv its header, no can.log)."""
    run = tmp_path / "run"
    shutil.copytree(at_06s, run)
    meta = json.loads((run / "meta.json").read_text())
    meta["status"], meta["reason"] = "running", None
    meta.pop("recording_sha256", None)
    (run / "meta.json").write_text(json.dumps(meta))
    if rows == 0:
        (run / "signals.csv").write_text((run / "signals.csv").read_text().splitlines()[0] + "\n")
        (run / "can.log").unlink()
    rc, data, _, console = _serv(tmp_path, capsys, run)
    assert rc == ExitCode.ABORTED and data["status"] == "incomplete"
    assert data["run"]["status"] == "incomplete" and data["run"]["reason"] == INCOMPLETE_REASON
    assert "run incomplete" in console
    assert ("43 sample(s) of motion" if rows is None else "signals.csv") in data["analysis_error"]


def test_serv_steps_never_read_the_enable_calibration_or_end():
    step = np.array(["idle", "enable", "approach", "cal1_load", "cal1_sweep", "cal2_unload", "force_fight",
                     "unload", "done", "aborted", "cruise"])
    assert serv_steps(step).tolist() == [False, False, True, False, False, False, True, True, False, False, True]
    assert NOT_SERVICE == ("idle", "enable", "done", "aborted")


@pytest.mark.slow
def test_the_stretch_of_motion_at_its_boundary(at_52s, actuation):
    """The approach cut to MIN_SAMPLES_SERV - 1 samples is nothing to read; to MIN_SAMPLES_SERV it is read."""
    sig = load_recording(at_52s / "signals.csv", actuation, read_record(at_52s), jumps=False)
    first = int(np.flatnonzero(sig.step == "approach")[0])
    for n, readable in ((MIN_SAMPLES_SERV - 1, False), (MIN_SAMPLES_SERV, True)):
        keep = np.zeros(sig.n, bool)
        keep[:first + n] = True
        cut = sig.select(keep)
        corr = choose_calibration(cut, actuation, None, None)
        if readable:
            an = analyse(cut, actuation, corr, "improved")
            assert an.sig.n == n and an.steps == ("approach",)
        else:
            with pytest.raises(UnusableRecordingError, match=f"{n} sample\\(s\\) of motion"):
                analyse(cut, actuation, corr, "improved")
