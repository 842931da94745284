"""Columns by name, always (issue 47, part 1): every reader of a CSV maps its columns by the header's names, in
any order; a column it does not know is not read and said so; a header that does not name the required
columns, or names one twice, is refused (exit 3) naming them. Shuffled columns give the ordered file's result
bit for bit: analyze, serv and diagnose (dual-EMA and single axis)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hil.cli import main
from hil.errors import RecordingError
from hil.record.runfolder import read_signals
from hil.record.signals_csv import SIGNAL_COLUMNS

#: the resolvers, the LVDTs and the load cells each swapped: seven columns, all known
SHUFFLED7 = ("t", "phi2", "phi1", "s2", "s1", "F2", "F1")
#: ... and a column no reader knows in the middle
SHUFFLED = ("t", "phi2", "phi1", "temp_C", "s2", "s1", "F2", "F1")


def write_columns(path: Path, cols: dict, order) -> Path:
    """A bare CSV of ``cols`` (name -> array) in ``order``, every value written exactly (repr of the float)."""
    with open(path, "w") as fh:
        fh.write(",".join(order) + "\n")
        rows = np.column_stack([cols[c] for c in order])
        fh.writelines(",".join(repr(float(v)) for v in row) + "\n" for row in rows)
    return path


def _pair(tmp_path: Path, sig) -> tuple[Path, Path]:
    """The recording as a bare CSV in the written order and in :data:`SHUFFLED7`'s."""
    cols = {c: getattr(sig, c) for c in SIGNAL_COLUMNS}
    return (write_columns(tmp_path / "ordered.csv", cols, SIGNAL_COLUMNS),
            write_columns(tmp_path / "shuffled.csv", cols, SHUFFLED7))


def test_a_shuffled_header_reads_the_same_arrays_and_names_the_column_not_read(tmp_path):
    t = np.arange(400) * 0.002
    cols = {c: np.sin(t * (k + 1)) + k for k, c in enumerate(SIGNAL_COLUMNS)} | {"t": t, "temp_C": t * 0 + 20.0}
    a = read_signals(write_columns(tmp_path / "a.csv", cols, SIGNAL_COLUMNS))
    b = read_signals(write_columns(tmp_path / "b.csv", cols, SHUFFLED))
    for c in SIGNAL_COLUMNS:
        assert np.array_equal(getattr(a, c), getattr(b, c)), c
    assert b.s1[5] == cols["s1"][5] and b.s1[5] != cols["s2"][5]
    assert any("'temp_C' not read" in n for n in b.notes) and not any("not read" in n for n in a.notes)


def test_the_seven_columns_in_another_order_are_not_read_by_position(tmp_path):
    """Seven columns, all numeric, no step column: numpy's all-columns path took them in the file's order."""
    t = np.arange(300) * 0.002
    cols = {c: t * 0 + k for k, c in enumerate(SIGNAL_COLUMNS)} | {"t": t}
    order = ("t", "phi1", "phi2", "s2", "s1", "F1", "F2")
    sig = read_signals(write_columns(tmp_path / "x.csv", cols, order))
    assert sig.s1[0] == SIGNAL_COLUMNS.index("s1") and sig.s2[0] == SIGNAL_COLUMNS.index("s2")


@pytest.mark.parametrize("header, words", [
    ("t,phi1,phi2,s1,s2,s1,F1,F2", "column(s) s1 named more than once"),
    ("t,phi1,phi2,s1,F1,F2,x", "missing column(s) s2"),
    ("time,phi1,phi2,s1,s2,F1,F2", "missing column(s) t"),
])
def test_a_header_that_does_not_name_each_column_once_is_refused(tmp_path, header, words, capsys):
    p = tmp_path / "bad.csv"
    p.write_text(header + "\n" + "\n".join(",".join(["0"] * 7) for _ in range(5)) + "\n")
    with pytest.raises(RecordingError, match="line 1: " + words.replace("(", r"\(").replace(")", r"\)")):
        read_signals(p)
    assert main(["analyze", str(p), "--out", str(tmp_path / "o")]) == 3
    assert words in capsys.readouterr().err


def _without(d: dict, *keys) -> dict:
    return {k: v for k, v in d.items() if k not in keys}


@pytest.mark.slow
def test_analyze_and_serv_of_shuffled_columns_give_the_ordered_result_bit_for_bit(dry_run, tmp_path):
    run, _ = dry_run
    ordered, shuffled = _pair(tmp_path, read_signals(run / "signals.csv"))
    out = {}
    for name, csv in (("ordered", ordered), ("shuffled", shuffled)):
        assert main(["analyze", str(csv), "--out", str(tmp_path / f"a-{name}"), "--no-history"]) in (0, 5)
        assert main(["serv", str(csv), "--out", str(tmp_path / f"s-{name}"), "--no-history",
                     "--calibration", str(run / "result.json")]) in (0, 5)
        out[name] = (json.loads((tmp_path / f"a-{name}" / "result.json").read_text()),
                     json.loads((tmp_path / f"s-{name}" / "serv.json").read_text()))
    (a0, s0), (a1, s1) = out["ordered"], out["shuffled"]
    assert a0["status"] == "pass" and set(a0["backlash_mm"]) == {"int1", "int2", "ext"}
    assert _without(a0, "trace", "analysis_s") == _without(a1, "trace", "analysis_s")
    assert _without(s0, "trace", "analysis_s", "recording") == _without(s1, "trace", "analysis_s", "recording")
    assert _without(s0["recording"], "source") == _without(s1["recording"], "source")


@pytest.mark.slow
def test_diagnose_of_shuffled_columns_gives_the_ordered_result_bit_for_bit(default_run, tmp_path):
    run, _ = default_run
    ordered, shuffled = _pair(tmp_path, read_signals(run / "signals.csv"))
    data = []
    for name, csv in (("ordered", ordered), ("shuffled", shuffled)):
        assert main(["diagnose", str(csv), "--out", str(tmp_path / f"d-{name}"), "--quiet", "--no-report"]) == 0
        data.append(json.loads((tmp_path / f"d-{name}" / "diagnosis.json").read_text()))
    assert data[0]["verdict"] in ("no_mismatch", "explained", "unexplained") and data[0]["effects"] is not None
    assert _without(data[0], "diagnosis_s", "trace") == _without(data[1], "diagnosis_s", "trace")


def test_a_single_axis_csv_is_read_by_name_too(tmp_path):
    """The single-axis reader: shuffled columns and a column it does not know give the same diagnosis; a
    column named twice is refused (exit 3)."""
    from test_diagnose_reference import K_A_PER_N, write_csv
    src = write_csv(tmp_path / "axis.csv")
    arr = np.genfromtxt(src, delimiter=",", names=True)
    cols = {n: arr[n] for n in arr.dtype.names} | {"temp_C": np.full(arr.size, 20.0)}
    shuffled = write_columns(tmp_path / "axis-shuffled.csv", cols, ("load", "temp_C", "current", "q_ref", "t", "q"))
    ordered = write_columns(tmp_path / "axis-ordered.csv", cols, ("t", "q", "q_ref", "current", "load"))
    data = []
    for name, csv in (("o", ordered), ("s", shuffled)):
        assert main(["diagnose", str(csv), "--model", "single-axis", "--current-law", "power", "--current-per-force",
                     str(K_A_PER_N), "--out", str(tmp_path / name), "--quiet", "--no-report"]) == 0
        data.append(json.loads((tmp_path / name / "diagnosis.json").read_text()))
    # (trace: when and from which file, each its own)
    skip = ("diagnosis_s", "notes", "effort", "trace")
    assert _without(data[0], *skip) == _without(data[1], *skip)
    assert data[0]["effort"]["trusted"] == data[1]["effort"]["trusted"]
    assert any("'temp_C' not read" in n for n in data[1]["notes"]) and "notes" not in data[0]
    twice = tmp_path / "twice.csv"
    twice.write_text("t,q,q,q_ref,current\n" + "0,0,0,0,0\n" * 300)
    assert main(["diagnose", str(twice), "--model", "single-axis", "--out", str(tmp_path / "t")]) == 3
