"""Fuzzing every reader of a file (hypothesis): random bytes, and a small valid file mutated (bytes flipped,
cut short, bytes inserted or deleted), fed to the command that reads it, in-process (``hil.cli.main``).

The outcome must be a normal result (0 pass, 1 fail, 5 inconclusive) or bad input (3, with one line that
names the file; ``profile check`` lists the problems, naming the file), never an internal error (4), never a
traceback. Readers: an actuation profile (``profile check FILE``), a signals CSV and its ``.gz``
(``serv``), a CAN log (``analyze FILE.log``), an EDS (``profile check actuation.toml --eds FILE``), a
single-axis recording as ``.mat`` and as CSV (``diagnose --model single-axis``).
"""

from __future__ import annotations

import gzip
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.canopen.od import default_eds_path
from hil.cli import main
from hil.profile.load import default_profile_path

ACTUATION = default_profile_path("actuation.toml")
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                    database=None)


def _csv_bytes(rows: int = 150) -> bytes:
    rng = np.random.default_rng(9)
    t = np.arange(1, rows + 1) * 0.002
    x = 2.0 * np.sin(2 * np.pi * 0.5 * t)
    a = np.column_stack([t, 5.0265 * x, 5.0265 * x, x + rng.normal(0, 4e-3, rows), x + rng.normal(0, 4e-3, rows),
                         rng.normal(0, 10, rows), rng.normal(0, 10, rows)])
    lines = ["t,phi1,phi2,s1,s2,F1,F2"] + [
        f"{r[0]:.4f},{r[1]:.7f},{r[2]:.7f},{r[3]:.6f},{r[4]:.6f},{r[5]:.3f},{r[6]:.3f}" for r in a]
    return ("\n".join(lines) + "\n").encode()


def _can_log_bytes(rows: int = 20) -> bytes:
    out = []
    for k in range(rows):
        t = 1000.0 + 0.002 * k
        out.append(f"({t:.6f}) vcan0 080#")
        out.append(f"({t:.6f}) vcan0 181#3702{k:08X}08")
        out.append(f"({t:.6f}) vcan0 281#{k:04X}0000{k:04X}0000")
    return ("\n".join(out) + "\n").encode()


def _mat_bytes(rows: int = 400) -> bytes:
    """A small single-axis recording as MATLAB saves it (compressed: zlib inside), too short to diagnose."""
    import io

    from scipy.io import savemat

    t = np.arange(rows) * 0.001
    buf = io.BytesIO()
    savemat(buf, {"t": t[:, None], "qm": np.sin(t)[:, None], "qg": 1.01 * np.sin(t)[:, None],
                  "vir": np.cos(t)[:, None], "gtau": np.array([[35.15]])}, do_compression=True)
    return buf.getvalue()


def _single_csv_bytes(rows: int = 400) -> bytes:
    t = np.arange(rows) * 0.001
    lines = ["t,q,q_ref,force"] + [f"{x:.4f},{np.sin(x):.6f},{1.01 * np.sin(x):.6f},{np.cos(x):.3f}" for x in t]
    return ("\n".join(lines) + "\n").encode()


VALID = {
    "profile": ACTUATION.read_bytes(),
    "csv": _csv_bytes(),
    "csv.gz": gzip.compress(_csv_bytes(), mtime=0),
    "log": _can_log_bytes(),
    "eds": default_eds_path().read_bytes(),
    "mat": _mat_bytes(),
    "single.csv": _single_csv_bytes(),
}


@st.composite
def mutated(draw, kind: str) -> bytes:
    """A valid file of ``kind`` with 1-4 mutations, or (one time in eight) bytes at random."""
    if draw(st.integers(0, 7)) == 0:
        return draw(st.binary(max_size=2000))
    data = bytearray(VALID[kind])
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(("flip", "truncate", "insert", "delete")))
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "flip" and data:
            data[pos] ^= draw(st.integers(1, 255))
        elif op == "truncate":
            del data[pos:]
        elif op == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif op == "delete":
            del data[pos:pos + draw(st.integers(1, 64))]
    return bytes(data)


def _run(kind: str, data: bytes, capsys) -> None:
    with tempfile.TemporaryDirectory(prefix="emacheck-fuzz-") as tmp:
        name = {"profile": "actuation.toml", "csv": "flight.csv", "csv.gz": "flight.csv.gz", "log": "can.log",
                "eds": "drive.eds", "mat": "DATA.mat", "single.csv": "axis.csv"}[kind]
        f = Path(tmp) / name
        f.write_bytes(data)
        out = Path(tmp) / "out"
        argv = {"profile": ["profile", "check", str(f)],
                "csv": ["serv", str(f), "--out", str(out), "--no-report", "--no-history"],
                "csv.gz": ["serv", str(f), "--out", str(out), "--no-report", "--no-history"],
                "log": ["analyze", str(f), "--out", str(out), "--no-history"],
                "eds": ["profile", "check", str(ACTUATION), "--eds", str(f)],
                "mat": ["diagnose", str(f), "--model", "single-axis", "--out", str(out), "--quiet", "--no-report"],
                "single.csv": ["diagnose", str(f), "--model", "single-axis", "--out", str(out), "--quiet",
                               "--no-report"]}[kind]
        rc = main(argv)
        got = capsys.readouterr()
    text = got.out + got.err
    assert rc in (0, 1, 3, 5), (rc, text)
    assert "Traceback" not in text and "internal error" not in text, text
    if rc == 3:  # the file named (profile check: by its name in the list of problems)
        assert f.name in text, text


def test_the_valid_files_are_read(capsys):
    """The seeds of the mutations are valid: each reader's normal outcome (the CAN log and the single-axis
    recordings are too short for their analyses: a refusal naming the file)."""
    for kind, want in (("profile", 0), ("eds", 0), ("csv", 5), ("csv.gz", 5), ("log", 3), ("mat", 3),
                       ("single.csv", 3)):
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / ("x." + kind if kind != "profile" else "actuation.toml")
            single = ["diagnose", str(f), "--model", "single-axis", "--out", str(Path(tmp) / "o"), "--quiet"]
            f.write_bytes(VALID[kind])
            argv = {"profile": ["profile", "check", str(f)],
                    "eds": ["profile", "check", str(ACTUATION), "--eds", str(f)],
                    "log": ["analyze", str(f), "--out", str(Path(tmp) / "o"), "--no-history"],
                    "mat": single, "single.csv": single}.get(
                kind, ["serv", str(f), "--out", str(Path(tmp) / "o"), "--no-report", "--no-history"])
            assert main(argv) == want, (kind, capsys.readouterr())
            capsys.readouterr()


@pytest.mark.parametrize("kind", sorted(VALID))
def test_a_mutated_file_is_a_result_or_bad_input_never_an_internal_error(kind, capsys):
    @SETTINGS
    @given(mutated(kind))
    def fuzz(data: bytes) -> None:
        _run(kind, data, capsys)

    fuzz()
