"""`emacheck serv` end to end: run folder, bare CSV, raw CAN log, calibration sources, exit codes."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from blf.maint.calibration import fit_lvdt_calibration
from hil.canopen.frame import sync_frame
from hil.canopen.units import mm_to_lvdt_um, newton_to_force_dN, rad_to_increments
from hil.cli import main
from hil.cli.args import ExitCode
from hil.record.canlog import CanLogWriter
from sim import operation as op
from sim import scenarios as sc
from support.canopen_rig import shipped_rig

HEADER = "t,phi1,phi2,s1,s2,F1,F2"


def _write_csv(path, t, phi1, phi2, s1, s2, F1, F2) -> None:
    a = np.column_stack([t, phi1, phi2, s1, s2, F1, F2])
    np.savetxt(path, a, delimiter=",", header=HEADER, comments="",
               fmt=["%.4f", "%.7f", "%.7f", "%.6f", "%.6f", "%.3f", "%.3f"])


@pytest.fixture(scope="module")
def sim_data(simrig):
    params = simrig.params
    rng = np.random.default_rng(77)
    sw1 = op.simulate_calibration_sweep(params, rng, ema=1)
    sw2 = op.simulate_calibration_sweep(params, rng, ema=2)
    rec = op.simulate_operation(params, sc.full_stroke_profile(params), rng)
    cal1 = fit_lvdt_calibration(sw1.x_mm, sw1.s_mm)
    cal2 = fit_lvdt_calibration(sw2.x_mm, sw2.s_mm)
    return {"params": params, "rec": rec, "sweeps": (sw1, sw2), "cal": (cal1, cal2)}


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory, sim_data):
    """signals.csv of a full stroke at full rate, result.json with the LVDT calibration, meta.json with truth."""
    d = tmp_path_factory.mktemp("serv") / "run"
    d.mkdir()
    rec = sim_data["rec"]
    _write_csv(d / "signals.csv", rec.t_s, rec.phi1_rad, rec.phi2_rad, rec.s1_mm, rec.s2_mm, rec.F1_N, rec.F2_N)
    cal1, cal2 = sim_data["cal"]
    (d / "result.json").write_text(json.dumps({"status": "pass", "calibration": {
        "ema1": {"pitch": cal1.pitch, "offset_mm": cal1.offset_mm},
        "ema2": {"pitch": cal2.pitch, "offset_mm": cal2.offset_mm}}}))
    (d / "meta.json").write_text(json.dumps({"truth": {"backlash_mm": dict(rec.truth.backlash_mm)}}))
    return d


def _serv(tmp_path, *args, report=False):
    out = tmp_path / "out"
    rc = main(["serv", *map(str, args), "--out", str(out)] + ([] if report else ["--no-report"]))
    data = json.loads((out / "serv.json").read_text()) if (out / "serv.json").exists() else None
    return rc, data, out


def test_run_folder_uses_its_calibration_and_finds_the_truth(run_folder, tmp_path):
    rc, data, out = _serv(tmp_path, run_folder, report=True)
    assert rc == 0
    assert data["method"] == "improved"
    assert data["calibration"]["source"] == "run folder result.json (pitch, offset)"
    assert data["calibration"]["ema1"]["pitch"] == pytest.approx(1.075, rel=1e-3)
    for ch, truth in (("int1", 0.10), ("int2", 0.12)):
        assert abs(data["backlash_mm"][ch] / truth - 1.0) < 0.10, ch
        assert data["traversals"][ch] == 2
        assert 0.55 < data["backlash_paper_mm"][ch] / truth < 0.9
    # symmetric operation: the external play is never crossed
    assert data["backlash_mm"]["ext"] is None and data["traversals"]["ext"] == 0
    assert data["truth"]["backlash_mm"]["int1"] == 0.10
    acc = data["accuracy"]
    assert acc["BLFserv_paper"]["temperature_mm"] == pytest.approx(0.02)
    assert acc["BLFserv_paper"]["pitch_uncompensated_mm"] == pytest.approx(20.0 * 0.075, rel=0.01)
    html = (out / "serv_report.html").read_text()
    assert html.count("data:image/png;base64,") == 4
    assert "paper Fig. 8" in html and "Accuracy of the backlash measurement" in html
    # default output place: a new sub-folder of the run folder, twice two different ones (nothing overwritten)
    before = (run_folder / "result.json").read_bytes()
    assert main(["serv", str(run_folder), "--no-report"]) == 0 and main(["serv", str(run_folder), "--no-report"]) == 0
    made = sorted(run_folder.glob("serv-*/serv.json"))
    assert len(made) == 2 and not list(run_folder.glob("serv-*/serv_report.html"))
    assert not (run_folder / "serv.json").exists() and (run_folder / "result.json").read_bytes() == before


def test_bare_csv_without_calibration_reports_only_channels_it_saw_crossed(run_folder, sim_data, tmp_path):
    """Issue 47: without an LVDT calibration `serv` read ext 0.077 +- 0.058 mm from 4 "traversals" (the full
    stroke's acceleration phases through LVDTs of unknown pitch; symmetric operation never crosses ext) and
    int1 from 6 (4 of them such artefacts). Now a jump counts only where it clears what the unknown scale can
    make of the ram's travel through it (blf.serv.scale): the two reversals per EMA remain."""
    bare = tmp_path / "flight.csv"
    shutil.copy(run_folder / "signals.csv", bare)
    rc, data, _ = _serv(tmp_path, bare)
    assert rc == 0
    assert data["calibration"]["source"] == "none"
    assert any("uncorrected" in n for n in data["notes"])
    truth = sim_data["rec"].truth.backlash_mm
    for ch in ("int1", "int2"):
        # within the calibrated run's 10 % plus the uncorrected pitch's scale error on the height itself (7.5 %)
        assert data["traversals"][ch] == 2 and abs(data["backlash_mm"][ch] / truth[ch] - 1.0) < 0.175, ch
        assert data["verdict"][ch]["status"] == "pass"
    assert sum(j["reason"].startswith("within the LVDT scale's reach") for j in data["jumps"]["int1"]) == 4
    v = data["verdict"]["ext"]
    assert data["backlash_mm"]["ext"] is None and data["traversals"]["ext"] == 0 and v["status"] == "not_traversed"
    assert "not measured: 4 jump(s) found" in v["reason"] and "not shown crossed" in v["reason"]
    assert all(j["reason"].startswith("within the LVDT scale's reach") and not j["accepted"]
               for j in data["jumps"]["ext"]) and len(data["jumps"]["ext"]) == 4


def test_explicit_calibration_file_and_paper_method(run_folder, tmp_path):
    bare = tmp_path / "flight.csv"
    shutil.copy(run_folder / "signals.csv", bare)
    rc, data, _ = _serv(tmp_path, bare, "--calibration", run_folder / "result.json", "--method", "paper")
    assert rc == 0
    assert data["method"] == "paper" and data["calibration"]["source"].startswith("--calibration")
    assert 0.55 < data["backlash_mm"]["int1"] / 0.10 < 0.9
    assert abs(data["backlash_improved_mm"]["int1"] / 0.10 - 1.0) < 0.10


def test_calibration_sweeps_found_in_the_recording(sim_data, tmp_path):
    sw1, sw2 = sim_data["sweeps"]
    cols = []
    # the two sweeps joined by the rig's move between them (20 ms in a straight line): joined end to start
    # they would jump 2 rad in one sample, and a recording with a jump is refused (test_bad_recordings.py)
    w = np.arange(1, 11) / 11
    for name in ("phi1_rad", "phi2_rad", "s1_mm", "s2_mm", "F1_N", "F2_N"):
        a, b = getattr(sw1, name), getattr(sw2, name)
        cols.append(np.concatenate([a, a[-1] + w * (b[0] - a[-1]), b]))
    t = np.arange(cols[0].size) * 0.002 + 0.002
    path = tmp_path / "sweeps.csv"
    _write_csv(path, t, *cols)
    rc, data, _ = _serv(tmp_path, path)
    # the sweeps' two reversals give two jumps per EMA that read ~50 % high (0.16 mm for 0.10/0.12): their U
    # straddles B_spec, so the decision is inconclusive (exit 5), not a pass; ext is never crossed
    assert rc == ExitCode.INCONCLUSIVE and data["status"] == "inconclusive"
    v = data["verdict"]
    assert v["ext"]["status"] == "not_traversed" and v["ext"]["traversals"] == 0
    for ch in ("int1", "int2"):
        assert v[ch]["status"] == "inconclusive" and v[ch]["traversals"] < 5
        assert v[ch]["backlash_mm"] - v[ch]["uncertainty_mm"] <= 0.2 < v[ch]["backlash_mm"] + v[ch]["uncertainty_mm"]
    assert any("counted traversal(s)" in n for n in data["notes"])
    assert data["calibration"]["source"] == "slow sweeps under load detected in the recording"
    assert data["calibration"]["ema1"]["pitch"] == pytest.approx(1.075, rel=2e-3)
    assert data["calibration"]["ema2"]["pitch"] == pytest.approx(0.98, rel=2e-3)


def test_raw_can_log(sim_data, run_folder, tmp_path, actuation):
    rec = sim_data["rec"]
    log = tmp_path / "flight.log"
    w = CanLogWriter(log)
    plan = shipped_rig().plan  # the shipped drives' TPDOs, as a CAN log of them would carry them
    counts = 4096
    for k in range(rec.t_s.size):
        t = float(rec.t_s[k])
        w.write(sync_frame(), t, rx=False)
        for ema, phi, s, f in ((1, rec.phi1_rad[k], rec.s1_mm[k], rec.F1_N[k]),
                               (2, rec.phi2_rad[k], rec.s2_mm[k], rec.F2_N[k])):
            lay = plan.node(f"ema{ema}").layout
            w.write(lay["TPDO1"].pack((0x0237, rad_to_increments(float(phi), counts), 8)), t, rx=True)
            w.write(lay["TPDO2"].pack((mm_to_lvdt_um(float(s)), newton_to_force_dN(float(f)))), t, rx=True)
    w.close()
    rc, data, _ = _serv(tmp_path, log, "--calibration", run_folder / "result.json")
    assert rc == 0
    assert data["recording"]["samples"] == rec.t_s.size
    assert abs(data["backlash_mm"]["int1"] / 0.10 - 1.0) < 0.10
    assert abs(data["backlash_mm"]["int2"] / 0.12 - 1.0) < 0.10
    assert data["backlash_mm"]["ext"] is None


def test_bad_input_exits_3(run_folder, tmp_path, capsys):
    assert main(["serv", str(tmp_path / "missing.csv")]) == 3
    bad = tmp_path / "bad.csv"
    bad.write_text("t,phi1,s1\n0.002,0.1,0.2\n")
    assert main(["serv", str(bad)]) == 3
    short = tmp_path / "short.csv"
    _write_csv(short, np.arange(1, 51) * 0.002, *np.zeros((6, 50)))
    assert main(["serv", str(short)]) == 3
    notjson = tmp_path / "result.json"
    notjson.write_text("{not json")
    assert main(["serv", str(run_folder / "signals.csv"), "--calibration", str(notjson),
                 "--out", str(tmp_path / "o")]) == 3
    nocal = tmp_path / "nocal.json"
    nocal.write_text(json.dumps({"status": "pass"}))
    assert main(["serv", str(run_folder / "signals.csv"), "--calibration", str(nocal),
                 "--out", str(tmp_path / "o")]) == 3
    assert main(["serv", str(run_folder), "--profile", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    assert "missing.csv" in err and "line 1: missing column" in err and "too short" in err
    assert "'calibration'" in err and "nope.toml" in err
