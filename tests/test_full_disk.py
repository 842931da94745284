"""A full disk during a check (issue 47, part 4): refused before anything moves when the record cannot fit
(exit 3, saying how much is needed); a write that fails mid-check stops the drives first, then whatever can
still be written is closed: meta.json and result.json ``aborted`` naming the file and the cause, the report
written into the space kept for it, exit 2, never 4. On a small tmpfs (root; where it cannot be mounted the
stage skips, and fails under CI=true)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hil.record.space import CANLOG_BYTES_PER_FRAME, END_BYTES, SIGNALS_BYTES_PER_ROW, EndReserve, record_bytes
from support.ci import skip_or_fail

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def small_fs(tmp_path):
    """A tmpfs of the size asked for, mounted under ``tmp_path`` (unmounted after the test)."""
    mounted = []

    def mount(size: str) -> Path:
        where = tmp_path / f"fs-{len(mounted)}"
        where.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True,
                           text=True)
        if r.returncode != 0:
            skip_or_fail(f"cannot mount a {size} tmpfs (needs root): {r.stderr.strip() or r.returncode}")
        mounted.append(where)
        return where

    yield mount
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _fill(folder: Path) -> None:
    """Another program fills the disk: a file written until no space is left."""
    with open(folder / "filler", "wb") as fh:
        try:
            while True:
                fh.write(bytes(1 << 16))
                fh.flush()
        except OSError:
            pass


def test_the_record_size_is_the_longest_check_at_the_measured_sizes():
    """406 s at 2 ms with 7.08 frames a cycle (the shipped plan): 203 000 rows and 1.44 million frames."""
    n = record_bytes(406.0, 0.002, 7.08)
    assert n == int(203_000 * (SIGNALS_BYTES_PER_ROW + 7.08 * CANLOG_BYTES_PER_FRAME)) + END_BYTES
    assert 95e6 < n < 110e6
    assert record_bytes(406.0, 0.002, 0.0) == int(203_000 * SIGNALS_BYTES_PER_ROW) + END_BYTES  # simulate: no CAN


def test_the_end_reserve_keeps_its_bytes_and_gives_them_back(tmp_path):
    r = EndReserve(tmp_path, 1 << 20)
    assert r.kept and r.path.stat().st_size == 1 << 20
    r.release()
    r.release()
    assert not r.path.exists() and not r.kept


def test_a_dry_run_into_3_mib_is_refused_before_anything_moves(small_fs, capsys):
    from hil.cli import main
    out = small_fs("3m") / "run"
    assert main(["dry-run", "--out", str(out), "--quiet"]) == 3
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "aborted" and meta["reason"].startswith("not started: ")
    assert "MB free, the check's record needs up to" in meta["reason"]
    assert meta.get("drives_final") in (None, {}) or all(
        d["state"] != "OPERATION_ENABLED" for d in meta["drives_final"].values())
    assert not (out / "signals.csv").exists() or (out / "signals.csv").stat().st_size == 0


@pytest.mark.slow
def test_a_disk_that_fills_mid_check_stops_the_drives_then_closes_the_record(small_fs):
    fs = small_fs("110m")
    out = fs / "run"
    proc = subprocess.Popen([sys.executable, "-m", "hil", "dry-run", "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        if "] cal1_sweep" in line:  # the check runs: another program fills the disk
            _fill(fs)
            break
    rest, _ = proc.communicate(timeout=120)
    assert proc.returncode == 2, rest
    meta = json.loads((out / "meta.json").read_text())
    result = json.loads((out / "result.json").read_text())
    assert meta["status"] == "aborted" and "No space left on device" in meta["reason"]
    assert str(out / "can.log") in meta["reason"] or str(out / "signals.csv") in meta["reason"]
    assert result["status"] == "aborted" and (out / "report.html").stat().st_size > 0
    assert all(d["state"] != "OPERATION_ENABLED" for d in meta["drives_final"].values())
    assert "internal error" not in rest and not (out / ".emacheck-end-reserve").exists()
    os.remove(fs / "filler")


@pytest.mark.slow
@pytest.mark.parametrize("argv, name", [
    (["analyze", "{run}"], "result.json"), (["serv", "{run}"], "serv.json"),
    (["diagnose", "{run}", "--no-report", "--quiet"], "diagnosis.json"), (["history"], "history.json"),
])
def test_every_writing_command_on_a_full_disk_exits_3_naming_the_file_and_the_cause(small_fs, dry_run, argv, name,
                                                                                      capsys):
    from hil.cli import main
    run, _ = dry_run
    fs = small_fs("3m")
    _fill(fs)
    out = fs / "out"
    rc = main([a.format(run=run) for a in argv] + ["--out", str(out)] + (["--no-history"] if argv[0] in (
        "analyze", "serv") else []))
    err = capsys.readouterr().err
    assert rc == 3 and f"{out / name}: cannot be written (No space left on device)" in err, err
