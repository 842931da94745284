"""A check's record is written once (issue 34, part 1): no command writes over a file that exists.

Each case hashes every file before the command and after it: the earlier files are byte-identical, the
new ones are elsewhere (a new sub-folder, a new name). The rules are pinned at their boundaries: an
empty ``--out`` folder is used, one holding a single file is not.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import shutil
import types
from pathlib import Path

import pytest

from hil.cli import main
from hil.cli.args import ExitCode
from hil.errors import OutputError
from hil.record.outputs import Outputs, default_out, out_dir, outputs_for
from hil.record.runfolder import create_json, create_with
from support.diagnose_cases import base_params, record, short_check
from support.figures import figures_unrendered


def tree(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under ``folder``, by its relative path."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(folder).rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """A run folder of a short simulated check (~1 s) with its own result.json and report.html, as the
    check writes them at its end (its figures not drawn: support/figures.py)."""
    from hil.cli.console import make_console
    from hil.cli.result import analyze_and_report
    from hil.profile.load import load_actuation
    from hil.record.runfolder import read_record

    out = tmp_path_factory.mktemp("once") / "run"
    record(base_params(), 1, out, short_check())
    act = load_actuation(None)
    with figures_unrendered():
        result = analyze_and_report(out / "signals.csv", act, Outputs(out, own=True), None, read_record(out),
                                    make_console(quiet=True))
    assert result["status"] == "pass"
    return out


@pytest.fixture()
def run_copy(short_run, tmp_path):
    """A private copy of the run folder (a test may add to it)."""
    dst = tmp_path / "run"
    shutil.copytree(short_run, dst)
    return dst


# ------------------------------------------------------------------ the checks' own run folders


@pytest.mark.parametrize("command", [["dry-run"], ["simulate"], ["simulate", "--scenario", "cruise"],
                                     ["run", "--interface", "virtual", "--channel", "x", "--arm"]])
def test_a_check_refuses_an_out_folder_holding_one_file_and_writes_nothing(command, tmp_path, capsys):
    out = tmp_path / "earlier"
    out.mkdir()
    (out / "report.html").write_text("<p>PASS</p>")  # the boundary: one file
    before = tree(out)
    rc = main([*command, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT
    assert tree(out) == before and sorted(os.listdir(out)) == ["report.html"]
    assert f"--out {out}: the folder holds files already" in err and "omit --out" in err
    assert err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("command", [["dry-run"], ["simulate"],
                                     ["run", "--interface", "virtual", "--channel", "x", "--arm"]])
def test_a_check_refuses_an_out_that_is_a_file(command, tmp_path, capsys):
    out = tmp_path / "notes.txt"
    out.write_bytes(b"someone's notes\n")
    rc = main([*command, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and out.read_bytes() == b"someone's notes\n"
    assert f"--out {out}: a file, not a run folder" in err and err.count("\n") == 1


def test_an_empty_out_folder_is_the_run_folder_and_one_with_a_file_is_not(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert out_dir(empty, "dry-run") == empty
    new = tmp_path / "a" / "b"
    assert out_dir(new, "dry-run") == new and new.is_dir()
    (empty / ".keep").write_bytes(b"")  # a hidden file is a file
    with pytest.raises(OutputError, match="holds files already"):
        out_dir(empty, "dry-run")


def test_the_default_run_folder_is_new_even_twice_in_one_second(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    made = [default_out("dry-run") for _ in range(3)]
    assert len(set(made)) == 3 and all(p.is_dir() and not any(p.iterdir()) for p in made)
    assert made[1].name == made[0].name + "-2" and made[2].name == made[0].name + "-3"


def test_a_runs_can_log_and_meta_json_are_never_opened_over_existing_ones(tmp_path):
    from hil.record.canlog import CanLogWriter
    from hil.record.runfolder import MetaWriter
    from hil.record.runrecord import RunRecord

    (tmp_path / "can.log").write_bytes(b"(1.0) can0 080#\n")
    with pytest.raises(OutputError, match="can.log: exists"):
        CanLogWriter(tmp_path / "can.log")
    assert (tmp_path / "can.log").read_bytes() == b"(1.0) can0 080#\n"
    (tmp_path / "meta.json").write_text('{"run_id": "earlier"}')
    with pytest.raises(OutputError, match="meta.json: exists"):
        MetaWriter(tmp_path, RunRecord(run_id="later"), new=True).write()
    assert json.loads((tmp_path / "meta.json").read_text()) == {"run_id": "earlier"}
    # the run's own meta.json is updated during its run: created once, then replaced
    w = MetaWriter(tmp_path / "x", RunRecord(run_id="a", status="running"), new=True)
    (tmp_path / "x").mkdir()
    w.write()
    w.write(RunRecord(run_id="a", status="done"))
    assert json.loads((tmp_path / "x" / "meta.json").read_text())["status"] == "done"


# ------------------------------------------------------------------ exclusive creation


def test_create_never_replaces_and_leaves_no_temporary_file(tmp_path):
    p = tmp_path / "result.json"
    create_json(p, {"status": "pass"})
    with pytest.raises(OutputError, match="result.json: exists; emacheck never overwrites"):
        create_json(p, {"status": "fail"})
    with pytest.raises(OutputError):
        create_with(p, lambda tmp: tmp.write_text("<html>"))
    assert json.loads(p.read_text()) == {"status": "pass"}
    assert sorted(os.listdir(tmp_path)) == ["result.json"]
    # the run's own result (Outputs.own) is replaced in place
    Outputs(tmp_path, own=True).write_json("result.json", {"status": "fail"})
    assert json.loads(p.read_text()) == {"status": "fail"}


def test_a_race_lost_between_choosing_a_name_and_creating_it_overwrites_nothing(tmp_path):
    bare = tmp_path / "flight.csv"
    bare.write_text("t\n")
    outputs = outputs_for(None, bare, None, "analysis", ("result.json", "report.html"))
    assert outputs.path("result.json") == tmp_path / "flight.result.json"
    (tmp_path / "flight.result.json").write_text("the other process's")  # it came first
    with pytest.raises(OutputError):
        outputs.write_json("result.json", {"status": "pass"})
    assert (tmp_path / "flight.result.json").read_text() == "the other process's"


def test_bare_recordings_get_names_of_their_own(tmp_path):
    names = ("result.json", "report.html")
    for n in ("f.csv", "f.csv.gz", "f.log"):
        (tmp_path / n).write_text("")
    prefixes = [outputs_for(None, tmp_path / n, None, "analysis", names).prefix for n in ("f.csv", "f.csv.gz", "f.log")]
    assert prefixes == ["f.", "f.csv.gz.", "f.log."]
    (tmp_path / "f.report.html").write_text("")  # one of the two outputs exists: the next number
    assert outputs_for(None, tmp_path / "f.csv", None, "analysis", names).prefix == "f.2."
    (tmp_path / "f.2.result.json").write_text("")
    assert outputs_for(None, tmp_path / "f.csv", None, "analysis", names).prefix == "f.3."


# ------------------------------------------------------------------ analyze, serv, diagnose, history


def test_analyze_out_the_run_folder_keeps_the_checks_own_files(run_copy, tmp_path, capsys):
    before = tree(run_copy)
    assert {"result.json", "report.html", "meta.json", "signals.csv"} <= set(before)
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    with figures_unrendered():  # which files are written, not what they show
        assert main(["analyze", str(run_copy), "--out", str(run_copy), "--history", url]) == ExitCode.PASS
    after = tree(run_copy)
    assert {k: after[k] for k in before} == before
    new = sorted(set(after) - set(before))
    assert len(new) == 2 and new[0].startswith("analysis-") and new[0].endswith("/report.html")
    assert new[1] == new[0].replace("report.html", "result.json")


def test_analyze_out_a_folder_with_files_writes_a_new_sub_folder(run_copy, tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    (out / "result.json").write_text('{"status": "fail"}')  # another check's, copied there
    before = tree(out)
    assert main(["analyze", str(run_copy / "signals.csv"), "--out", str(out), "--no-history"]) == ExitCode.PASS
    after = tree(out)
    assert {k: after[k] for k in before} == before
    (sub,) = [p.name for p in out.iterdir() if p.is_dir()]
    assert sub.startswith("analysis-")
    assert sorted(set(after) - set(before)) == [f"{sub}/report.html", f"{sub}/result.json"]


def test_a_derived_out_folder_is_used_while_empty_and_gets_a_sub_folder_with_one_file(tmp_path):
    from hil.record.outputs import fresh_outputs

    out = tmp_path / "empty"
    out.mkdir()
    assert fresh_outputs(out, "analysis") == Outputs(out, made=False)  # there before: never removed
    assert fresh_outputs(tmp_path / "new", "analysis") == Outputs(tmp_path / "new", made=True)
    (out / "result.json").write_text("{}")  # the boundary: one file
    sub = fresh_outputs(out, "analysis").folder
    assert sub.parent == out and sub.name.startswith("analysis-") and sorted(os.listdir(out)) == [sub.name,
                                                                                                 "result.json"]


def test_a_bare_csv_analysed_twice_keeps_the_first_and_gz_gets_its_own_names(run_copy, tmp_path, capsys,
                                                                             monkeypatch):
    """(The reports' figures are not drawn here: which files are written, not what they show. The
    bare CSV's report is drawn in test_analyze_out_a_folder_with_files_writes_a_new_sub_folder.)

    The two analyses are given analysis times a minute apart: the history keeps a result once by its
    content, and two analyses within one second give the same content (test_the_same_result_twice_...)."""
    import hil.cli.result

    stamps = iter(["2026-11-26T10:00:00+00:00", "2026-11-26T10:01:00+00:00", "2026-11-26T10:02:00+00:00"])
    monkeypatch.setattr(hil.cli.result, "utc_iso", lambda: next(stamps))
    with figures_unrendered():
        _bare_csv_analysed_twice(run_copy, tmp_path, capsys)


def test_the_same_result_twice_is_one_history_record_and_both_files_stay(run_copy, tmp_path, capsys, monkeypatch):
    """Two analyses within one second that took as long (to the ms) write byte-identical results: both
    files stay (the second under its new name), the history holds that content once and says the second
    was already recorded."""
    import hil.cli.result

    monkeypatch.setattr(hil.cli.result, "utc_iso", lambda: "2026-11-26T10:00:00+00:00")
    monkeypatch.setattr(hil.cli.result, "time", types.SimpleNamespace(perf_counter=lambda: 0.0))  # analysis_s 0
    csv = tmp_path / "f.csv"
    csv.write_bytes((run_copy / "signals.csv").read_bytes())
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    with figures_unrendered():
        assert main(["analyze", str(csv), "--history", url]) == ExitCode.PASS
        assert main(["analyze", str(csv), "--history", url]) == ExitCode.PASS
    assert (tmp_path / "f.result.json").read_bytes() == (tmp_path / "f.2.result.json").read_bytes()
    assert "already recorded" in capsys.readouterr().out
    assert main(["history", "--history", url, "--json"]) == ExitCode.PASS
    checks = json.loads(capsys.readouterr().out)["checks"]
    assert [Path(c["result_path"]).name for c in checks] == ["f.result.json"] and checks[0]["current"]


def _bare_csv_analysed_twice(run_copy: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "bare"
    folder.mkdir()
    csv = folder / "f.csv"
    csv.write_bytes((run_copy / "signals.csv").read_bytes())
    with gzip.open(folder / "f.csv.gz", "wb") as fh:
        fh.write(csv.read_bytes())
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    assert main(["analyze", str(csv), "--history", url]) == ExitCode.PASS
    first = tree(folder)
    assert {"f.result.json", "f.report.html"} <= set(first)
    assert main(["analyze", str(csv), "--history", url]) == ExitCode.PASS
    second = tree(folder)
    assert {k: second[k] for k in first} == first
    assert sorted(set(second) - set(first)) == ["f.2.report.html", "f.2.result.json"]
    assert "f.2.result.json" in (folder / "f.2.report.html").read_text()
    # the history keeps both, each pointing at its own unchanged file; the second is current
    capsys.readouterr()
    assert main(["history", "--history", url, "--json"]) == ExitCode.PASS
    checks = json.loads(capsys.readouterr().out)["checks"]
    assert [Path(c["result_path"]).name for c in checks] == ["f.result.json", "f.2.result.json"]
    assert [c["current"] for c in checks] == [False, True] and checks[1]["supersedes"] == checks[0]["id"]
    assert main(["analyze", str(folder / "f.csv.gz"), "--no-history"]) == ExitCode.PASS
    third = tree(folder)
    assert {k: third[k] for k in second} == second
    assert sorted(set(third) - set(second)) == ["f.csv.gz.report.html", "f.csv.gz.result.json"]
    assert json.loads((folder / "f.csv.gz.result.json").read_text())["trace"]["recording"].endswith("f.csv.gz")


@pytest.mark.parametrize("command", ["analyze", "serv", "diagnose"])
def test_out_an_existing_file_is_refused_with_exit_3(command, run_copy, tmp_path, capsys):
    out = tmp_path / "taken"
    out.write_bytes(b"x")
    rc = main([command, str(run_copy), "--out", str(out)] + (["--no-history"] if command != "diagnose" else []))
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and out.read_bytes() == b"x"
    assert f"--out {out}: a file, not a folder" in err and err.count("\n") == 1


def test_history_out_a_file_or_an_unwritable_place_is_exit_3_in_one_line(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'none.sqlite'}"
    out = tmp_path / "taken"
    out.write_bytes(b"x")
    assert main(["history", "--history", url, "--out", str(out)]) == ExitCode.INPUT
    err = capsys.readouterr().err
    assert out.read_bytes() == b"x" and f"--out {out}: a file" in err and err.count("\n") == 1
    assert main(["history", "--history", url, "--out", "/proc/emacheck-history"]) == ExitCode.INPUT
    err = capsys.readouterr().err
    assert "/proc/emacheck-history" in err and "cannot be written" in err and "Traceback" not in err
    assert err.count("\n") == 1


def test_history_out_twice_keeps_the_first_page(tmp_path):
    url = f"sqlite:///{tmp_path / 'none.sqlite'}"
    out = tmp_path / "page"
    assert main(["history", "--history", url, "--out", str(out)]) == ExitCode.PASS
    first = tree(out)
    assert sorted(first) == ["history.html", "history.json"]
    assert main(["history", "--history", url, "--out", str(out)]) == ExitCode.PASS
    after = tree(out)
    assert {k: after[k] for k in first} == first and len(after) == 4


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_a_bare_file_in_a_read_only_folder_is_exit_3_naming_the_output(run_copy, tmp_path, capsys):
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "f.csv").write_bytes((run_copy / "signals.csv").read_bytes())
    folder.chmod(0o555)
    try:
        rc = main(["analyze", str(folder / "f.csv"), "--no-history"])
    finally:
        folder.chmod(0o755)
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and sorted(os.listdir(folder)) == ["f.csv"]
    assert f"{folder / 'f.result.json'}: cannot be written" in err and err.count("\n") == 1


def test_a_run_folder_that_cannot_be_analysed_gets_no_empty_sub_folder(run_copy, capsys):
    bad = run_copy / "signals.csv"
    bad.write_text(bad.read_text().replace("\n", "\nnot,a,number,row,here,at,all,0,0,0,0,x\n", 1))
    before = tree(run_copy)
    assert main(["analyze", str(run_copy), "--no-history"]) == ExitCode.INPUT  # changed after its check
    assert "signals.csv: changed after the check" in capsys.readouterr().err
    assert main(["analyze", str(run_copy), "--no-history", "--accept-modified"]) == ExitCode.INPUT
    assert "line 2" in capsys.readouterr().err
    assert tree(run_copy) == before and not [p for p in run_copy.iterdir() if p.is_dir()]


def test_a_read_only_file_system_is_one_line_naming_the_output(tmp_path, monkeypatch):
    import errno
    import tempfile

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(OutputError) as err:
        create_json(tmp_path / "flight.result.json", {"status": "pass"})
    assert str(err.value) == (f"{tmp_path / 'flight.result.json'}: cannot be written (Read-only file system); "
                              f"give --out a folder you can write to")
    assert os.listdir(tmp_path) == []


def test_sim_serve_refuses_an_existing_timing_json_before_it_serves(tmp_path, capsys):
    """sim-serve writes --timing-json at its end: an existing file is refused at the start (exit 3, named,
    unchanged), before any bus is opened."""
    existing = tmp_path / "timing.json"
    existing.write_text('{"earlier": true}\n')
    before = existing.read_bytes()
    assert main(["sim-serve", "--interface", "virtual", "--channel", "x", "--timing-json", str(existing)]) == 3
    assert f"--timing-json {existing}: exists; never overwritten" in capsys.readouterr().err
    assert existing.read_bytes() == before


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_an_output_file_gets_the_users_umask_not_mkstemps_0600(tmp_path, umask, mode):
    """An output created once (temporary name, then linked) is readable as any file the user makes: its mode
    is 0666 under the umask, as ``open`` gives it (mkstemp made it 0600)."""
    from hil.record.runfolder import create_json, new_file_mode

    old = os.umask(umask)
    try:
        assert new_file_mode() == mode
        path = create_json(tmp_path / "result.json", {"status": "pass"})
    finally:
        os.umask(old)
    assert (path.stat().st_mode & 0o777) == mode
