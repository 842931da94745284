"""Tests of ``emacheck diagnose`` (blf.diagnose, sim.replay, sim.single_axis, hil.diagnose_cmd).

Recordings are short simulated checks (~40 s, see ``bench_diagnose.short_check``)
with concealed effects generated as in the benchmark, with their own seeds
(31001..), never the benchmark's. The full >= 30-case benchmark is
``python tests/bench_diagnose.py``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

import bench_diagnose as B  # noqa: E402
from blf.diagnose import diagnose  # noqa: E402
from hil.cli import main  # noqa: E402
from hil.errors import InputError  # noqa: E402
from sim.replay import ChainParams, DualEmaReplay, replay_chains  # noqa: E402

EMPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "emps" / "DATA_EMPS.mat"


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    return B.short_check()


def _case(kind_effects, seed, tmp, check):
    case = {"id": "t", "kind": "single", "effects": kind_effects, "seed": seed}
    sig, truths, s, _ = B.generate(case, tmp, check)
    return sig, truths, s


def _diag(sig):
    m = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2, B.I_TOTAL, 0.002,
                      sig.mode1, sig.sp1, sig.mode2, sig.sp2)
    return diagnose(m, 0.002)


def test_replay_reproduces_plant_within_noise(tmp_path, short):
    """Driven by the measured motor angles with the true parameters, the replay leaves only noise in s."""
    sig = B.record(B.base_params(), 31001, tmp_path, short)
    ks = 1 / 200000 + 1 / 20000
    tr = replay_chains(sig.phi1 / B.I_TOTAL, sig.phi2 / B.I_TOTAL, ChainParams(0.10, 8e4, 8e4, 0.05, ks),
                       ChainParams(0.12, 8e4, 8e4, 0.05, ks), 0.002, 0.0, 300.0, 0.5)
    sigma = 0.025 / 6
    for j, s in enumerate((sig.s1, sig.s2)):
        rms = float(np.sqrt(np.mean((s - tr.s_mm[:, j]) ** 2)))
        assert rms < 1.1 * sigma, (j, rms)


def test_replay_refuses_bad_input():
    c = ChainParams(0.1, 8e4, 8e4, 0.05, 5e-5)
    with pytest.raises(InputError, match="same shape|one shape"):
        replay_chains(np.zeros(5), np.zeros(4), c, c, 0.002)
    with pytest.raises(InputError, match="> 0"):
        replay_chains(np.zeros(5), np.zeros(5), ChainParams(0.1, -1.0, 8e4, 0.05, 5e-5), c, 0.002)


def test_null_is_no_mismatch(tmp_path, short):
    sig, _, _ = _case([], 31002, tmp_path, short)
    d = _diag(sig)
    assert d.verdict == "no_mismatch", (d.excess_before, [e.name for e in d.partial_effects])
    assert d.effects == ()


def test_concealed_coulomb_friction_found(tmp_path):
    """A full-length check: the concealed friction needs the whole recording to stand out."""
    sig, truths, s = _case([("coulomb_friction", "ema1")], 31003, tmp_path, None)
    assert max(v for c, v in s.items() if not c.startswith("phi")) < 1.0
    d = _diag(sig)
    assert d.verdict == "explained"
    assert [(e.name, e.where) for e in d.effects] == [("coulomb_friction", "ema1")]
    true_f = truths[0]["parameters"]["force_N"]
    fit = d.effects[0].parameters["force_N"]
    assert abs(fit - true_f) < 0.2 * true_f, (fit, true_f)
    assert d.ic_after < d.ic_before
    assert d.residual_rms_after["Fd1"] < d.residual_rms_before["Fd1"]


def test_out_of_library_is_unexplained(tmp_path, short):
    sig, _, _ = _case([("lead_error", "ema1")], 31004, tmp_path, short)
    d = _diag(sig)
    assert d.verdict in ("unexplained", "no_mismatch"), [e.name for e in d.effects]
    assert d.effects == ()


@pytest.mark.skipif(not EMPS.exists(), reason=f"EMPS recording not present at {EMPS} (../shared/data)")
def test_emps_cli(tmp_path):
    rc = main(["diagnose", str(EMPS), "--model", "single-axis", "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert set(data) >= {"verdict", "effects", "locations", "residual_rms_before", "residual_rms_after",
                         "ic_before", "ic_after"}
    named = data["effects"] + data["partial_effects"]
    assert named, data["verdict"]
    assert all(e["delta_chi2_holdout"] < -10 for e in named)
    assert data["ic_after"] < data["ic_before"]
    assert data["residual_rms_after"]["force"] < data["residual_rms_before"]["force"]
    assert data["locations"]
    assert (tmp_path / "diagnosis_report.html").stat().st_size > 10_000


def test_cli_bad_recording(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("t,phi1\n0,0\n")
    assert main(["diagnose", str(bad), "--out", str(tmp_path)]) == 3
