"""hil/record/signals_csv.py: the chunked CSV reader gives exactly what Python's float gives, across chunk
boundaries and when its arrays grow, and names the bad line wherever it is."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

import hil.record.signals_csv as reader
from hil.errors import RecordingError
from hil.record.runfolder import read_signals

HEADER = "t,phi1,phi2,s1,s2,F1,F2,mode1,sp1,mode2,sp2,step"


def _lines(n: int, seed: int = 4) -> list[str]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        v = rng.normal(0, 1, 6) * 10.0 ** rng.integers(-3, 4, 6)
        digits = 12 if k < 10 else 3  # long lines first: the first chunk's estimate is too small, the arrays grow
        out.append(f"{0.002 * (k + 1):.4f}," + ",".join(f"{x:.{digits}g}" for x in v)
                   + f",8,{v[0]:.7g},10,-1e-3,step{k % 3}")
    return out


@pytest.mark.parametrize("gz", [False, True])
def test_the_arrays_are_python_floats_across_chunks_and_growth(tmp_path, monkeypatch, gz):
    monkeypatch.setattr(reader, "CHUNK_LINES", 7)
    lines = _lines(200)
    text = HEADER + "\n" + "\n".join(lines) + "\n"
    p = tmp_path / ("x.csv.gz" if gz else "x.csv")
    p.write_bytes(gzip.compress(text.encode()) if gz else text.encode())
    sig = read_signals(p)
    cells = [ln.split(",") for ln in lines]
    for j, c in enumerate(HEADER.split(",")[:-1]):
        want = np.array([float(r[j]) for r in cells])
        got = getattr(sig, c)
        assert got.dtype == np.float64 and got.size == 200 and np.array_equal(got, want), c
        assert got.flags.owndata and got.flags.c_contiguous
    assert list(sig.step[:4]) == ["step0", "step1", "step2", "step0"] and sig.notes == ()


@pytest.mark.parametrize("bad,words", [
    ("0.4000,1,2,3,4,5,x,8,0,10,0,s", "line 201: column 'F2': not a number: 'x'"),
    ("0.4000,1,2,3,4,5,6,8,0,10,0", "line 201: 11 fields, header has 12"),
    ("", "line 201: 1 fields, header has 12"),
    ("0.4000,1,2,3,nan,5,6,8,0,10,0,s", "line 201: column 's2' [mm] is nan"),
])
def test_a_bad_line_in_a_later_chunk_is_named(tmp_path, monkeypatch, bad, words):
    monkeypatch.setattr(reader, "CHUNK_LINES", 7)
    lines = _lines(199) + [bad] + _lines(5, seed=9)
    p = tmp_path / "x.csv"
    p.write_text(HEADER + "\n" + "\n".join(lines) + "\n")
    with pytest.raises(RecordingError) as exc:
        read_signals(p)
    assert str(exc.value) == f"{p}: {words}"


def test_seven_columns_with_a_short_line_and_a_cut_last_line(tmp_path, monkeypatch):
    monkeypatch.setattr(reader, "CHUNK_LINES", 3)
    p = tmp_path / "x.csv"
    p.write_text("t,phi1,phi2,s1,s2,F1,F2\n0.002,1,2,3,4,5,6\n0.004,1,2,3,4,5,6\n0.006,1,2,3,4,5\n")
    with pytest.raises(RecordingError, match=r"line 4: 6 fields, header has 7"):
        read_signals(p)
    p.write_text("t,phi1,phi2,s1,s2,F1,F2\n0.002,1,2,3,4,5,6\n0.004,1,2,3,4,5,6\n0.006,1,2")
    sig = read_signals(p)
    assert sig.n == 2 and sig.notes == ("last line incomplete (recording cut short), dropped",)
    assert np.array_equal(sig.F2, [6.0, 6.0])
