"""A result knows what it was made from (issue 47, part 3): a check seals its recording when it ends (meta.json
``recording_sha256``); analyze, serv and diagnose of a run folder whose recording changed after the check
refuse it (exit 3, nothing written) unless ``--accept-modified``, and then say so in the result and its
report."""

from __future__ import annotations

import json
import shutil

import pytest

from hil.cli import main
from hil.errors import RecordingError
from hil.record.runrecord import RunRecord
from hil.record.seal import check_seal, seal_of, sha256_file


def test_the_seal_holds_each_recording_files_hash_and_a_changed_file_is_named(tmp_path):
    (tmp_path / "signals.csv").write_text("t,phi1\n0,1\n")
    seal = seal_of(tmp_path)
    assert seal == {"signals.csv": sha256_file(tmp_path / "signals.csv")} and len(seal["signals.csv"]) == 64
    meta = RunRecord(recording_sha256=seal)
    assert check_seal(tmp_path / "signals.csv", meta) is None
    assert check_seal(tmp_path / "signals.csv", None) is None and check_seal(tmp_path / "signals.csv", RunRecord()) \
        is None  # a bare file, a run folder of an older emacheck: nothing to check
    (tmp_path / "signals.csv").write_text("t,phi1\n0,2\n")
    with pytest.raises(RecordingError, match=r"signals.csv: changed after the check .*--accept-modified"):
        check_seal(tmp_path / "signals.csv", meta)
    mark = check_seal(tmp_path / "signals.csv", meta, accept_modified=True)
    assert mark["sha256_sealed"] == seal["signals.csv"] and mark["sha256_now"] == sha256_file(tmp_path / "signals.csv")
    assert "at the user's request" in mark["words"]
    assert RunRecord.from_json(meta.as_json()).recording_sha256 == seal  # meta.json both ways


@pytest.mark.slow
def test_a_dry_run_seals_its_recording(dry_run):
    run, rc = dry_run
    meta = json.loads((run / "meta.json").read_text())
    assert meta["recording_sha256"] == {"signals.csv": sha256_file(run / "signals.csv"),
                                        "can.log": sha256_file(run / "can.log")}


@pytest.mark.slow
@pytest.mark.parametrize("argv, name", [(["analyze", "--no-history"], "result.json"),
                                        (["serv", "--no-history"], "serv.json"),
                                        (["diagnose", "--no-report", "--quiet"], "diagnosis.json")])
def test_a_recording_changed_after_its_check_is_refused_unless_accepted(dry_run, tmp_path, argv, name, capsys):
    run, _ = dry_run
    copy = tmp_path / "run"
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("analysis-*", "serv-*", "diagnose-*"))
    lines = (copy / "signals.csv").read_text().splitlines(keepends=True)
    cells = lines[1000].split(",")
    cells[3] = repr(float(cells[3]) + 0.001)  # one LVDT reading, a micrometre off
    lines[1000] = ",".join(cells)
    (copy / "signals.csv").write_text("".join(lines))
    before = sorted(p.name for p in copy.iterdir())
    assert main([argv[0], str(copy), *argv[1:]]) == 3
    assert "signals.csv: changed after the check" in capsys.readouterr().err
    assert sorted(p.name for p in copy.iterdir()) == before  # nothing written
    out = tmp_path / "out"
    assert main([argv[0], str(copy), *argv[1:], "--accept-modified", "--out", str(out)]) in (0, 5)
    data = json.loads((out / name).read_text())
    notes = data.get("notes", [])
    assert any("changed after the check" in n and "--accept-modified" in n for n in notes), notes
    if name != "diagnosis.json":
        assert data["trace"]["modified"]["sha256_sealed"] == sha256_file(run / "signals.csv")
