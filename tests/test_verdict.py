"""The decision an inspector signs: guard-banded verdicts, their margins, exit status, traceability,
never overwriting, and every file written valid against its shipped JSON Schema."""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path

import jsonschema
import pytest

from blf.maint.verdict import COVERAGE_FACTOR, combine, decide, maint_uncertainty, overall, serv_uncertainty
from hil.cli import main
from hil.cli.args import ExitCode
from hil.record.runfolder import read_record
from support.figures import figures_unrendered
from support.profiles import write_profile_variant


def _schema(name: str) -> dict:
    return json.loads(resources.files("hil.schemas").joinpath(f"{name}.schema.json").read_text())


def validate(path: Path, name: str) -> dict:
    data = json.loads(Path(path).read_text())
    jsonschema.validate(data, _schema(name))
    return data


# ---------------------------------------------------------------------------- the rule itself


@pytest.mark.parametrize("b, u, limit, status, margin, on", [
    (0.100, 0.006, 0.200, "pass", 0.100, None),          # B + U = 0.106 <= 0.2
    (0.194, 0.006, 0.200, "pass", 0.006, "B + U"),       # B + U = 0.200: on the limit, still proven
    (0.197, 0.006, 0.200, "inconclusive", 0.003, None),  # the limit inside B +- U, below B + U
    (0.203, 0.006, 0.200, "inconclusive", -0.003, None),  # the limit inside B +- U, above B - U
    # B - U = 0.200 is not > limit. (0.206 - 0.006 is 0.19999999999999998 in floats and would never
    # reach the boundary; 0.2 + 0.006 = 0.20600000000000002 is the float whose B - U is 0.2 exactly)
    (0.200 + 0.006, 0.006, 0.200, "inconclusive", -0.006, "B - U"),
    (0.207, 0.006, 0.200, "fail", -0.007, None),         # B - U = 0.201 > 0.2
])
def test_guard_band_rule_and_exact_margins(b, u, limit, status, margin, on):
    if on == "B + U":  # the row must sit on the boundary in floats, not near it
        assert b + u == limit
    elif on == "B - U":
        assert b - u == limit
    v = decide(b, u, limit)
    assert v.status == status
    assert v.margin_mm == pytest.approx(margin, abs=1e-12) and v.limit_mm == limit and v.uncertainty_mm == u
    assert f"{limit:.4f}" in v.reason


def test_a_channel_not_measured_is_inconclusive_with_its_reason():
    v = decide(None, None, 0.2, missing="the force fight never reached contact on the tension side")
    assert v.status == "inconclusive" and v.backlash_mm is None and v.margin_mm is None
    assert "tension side" in v.reason
    assert overall({"int1": decide(0.1, 0.01, 0.2), "ext": v}) == "inconclusive"
    assert overall({"int1": decide(0.1, 0.01, 0.2), "ext": decide(0.3, 0.01, 0.2), "x": v}) == "fail"
    assert overall({"int1": decide(0.1, 0.01, 0.2), "ext": decide(0.05, 0.01, 0.2)}) == "pass"
    nt = decide(None, None, 0.2, not_traversed=True)
    assert nt.status == "not_traversed"
    assert overall({"int1": decide(0.1, 0.01, 0.2), "ext": nt}) == "pass"
    assert overall({"ext": nt}) == "inconclusive"


def test_uncertainty_budget_known_answer():
    # B = 0.1 mm, sigma 0.2 um, pitch 1e-3 relative, method max(5 um, 5 %) = 5 um rectangular
    u = maint_uncertainty(0.1, 0.0002, 1e-3)
    assert u.pitch_mm == pytest.approx(1e-4) and u.temperature_mm == 0.0
    assert u.method_mm == pytest.approx(0.005 / math.sqrt(3))
    assert u.combined_mm == pytest.approx(math.sqrt(0.0002**2 + 1e-4**2 + (0.005 / math.sqrt(3))**2))
    assert u.expanded_mm == pytest.approx(COVERAGE_FACTOR * u.combined_mm) and COVERAGE_FACTOR == 2.0
    big = maint_uncertainty(0.4, 0.0, 0.0)
    assert big.method_mm == pytest.approx(0.05 * 0.4 / math.sqrt(3))  # the relative part wins above 0.1 mm
    s = serv_uncertainty(0.1, 0.003, 0.002, 0.02, "improved")
    assert s.combined_mm == pytest.approx(math.sqrt(0.003**2 + 0.002**2 + (0.02 / math.sqrt(3))**2
                                                    + (0.1 * 0.1 / math.sqrt(3))**2))
    assert combine(3.0, 4.0, 0.0, 0.0).combined_mm == pytest.approx(5.0)


# ---------------------------------------------------------------------------- the commands


@pytest.fixture(scope="module")
def checked(tmp_path_factory, actuation, check_profile, simrig):
    """A simulated check (default rig: 0.100 / 0.120 / 0.100 mm, B_spec 0.2 mm) and its result."""
    out = tmp_path_factory.mktemp("verdict") / "run"
    rc = main(["simulate", "--quiet", "--out", str(out), "--operator", "A. Inspector", "--work-order", "WO-4711"])
    return out, rc


@pytest.mark.slow
def test_simulated_check_passes_with_its_verdict_traceable_and_valid(checked):
    out, rc = checked
    assert rc == ExitCode.PASS
    r = validate(out / "result.json", "result")
    assert r["status"] == "pass"
    for ch, truth in (("int1", 0.100), ("int2", 0.120), ("ext", 0.100)):
        v = r["verdict"][ch]
        assert v["status"] == "pass" and v["limit_mm"] == 0.2
        assert v["margin_mm"] == pytest.approx(0.2 - r["backlash_mm"][ch], abs=1e-12)
        # U: 2 x about 2.9 um of method bound dominates; the reading lies within U of the truth
        assert 0.005 < v["uncertainty_mm"] < 0.008 and abs(v["backlash_mm"] - truth) < v["uncertainty_mm"]
    t = r["trace"]
    assert t["operator"] == "A. Inspector" and t["work_order"] == "WO-4711" and len(t["run_id"]) == 32
    assert t["started_utc"].endswith("+00:00") and t["software"]["version"]
    assert set(t["files_sha256"]) == {"actuation", "check", "simrig"}
    assert all(len(h) == 64 for h in t["files_sha256"].values())
    html = (out / "report.html").read_text()
    assert "Uncertainty of the readings" in html and "Traceability" in html and "WO-4711" in html
    assert "<a href='result.json'>" in html and '"backlash_mm"' not in html  # linked, not dumped


@pytest.mark.slow
@pytest.mark.parametrize("spec_mm, ch, status, code", [
    (0.123, "int2", "inconclusive", ExitCode.INCONCLUSIVE),  # int2 = 0.1195 +- 0.0069 straddles it; int1 passes
    (0.090, "int1", "fail", ExitCode.FAIL),  # int1 = 0.1000 +- 0.0058 is proven above it
])
def test_inconclusive_and_fail_against_a_tighter_spec(checked, tmp_path, spec_mm, ch, status, code):
    out, _ = checked
    act = write_profile_variant("actuation.toml", tmp_path / "actuation.toml",
                                {"mechanics": {"backlash_spec_int_mm": spec_mm, "backlash_spec_ext_mm": 0.2}})
    res = tmp_path / "analysis"
    rc = main(["analyze", str(out), "--profile", str(act), "--out", str(res)])
    r = validate(res / "result.json", "result")
    v = r["verdict"][ch]
    assert rc == code and r["status"] == status == v["status"]
    assert v["limit_mm"] == spec_mm and v["margin_mm"] == pytest.approx(spec_mm - v["backlash_mm"], abs=1e-12)
    if status == "inconclusive":
        assert v["backlash_mm"] - v["uncertainty_mm"] <= spec_mm < v["backlash_mm"] + v["uncertainty_mm"]
        assert r["verdict"]["int1"]["status"] == "pass"
    else:
        assert v["backlash_mm"] - v["uncertainty_mm"] > spec_mm
    assert r["verdict"]["ext"]["status"] == "pass"


@pytest.mark.slow
def test_analyze_never_overwrites_and_bare_files_get_their_own_names(checked, tmp_path):
    """(Which files are written, not what the reports show: their figures are built but not drawn,
    support/figures.py; the check's own report, drawn, is tested above.)"""
    with figures_unrendered():
        _analyze_never_overwrites(checked, tmp_path)


def _analyze_never_overwrites(checked, tmp_path) -> None:
    out, _ = checked
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert main(["analyze", str(out)]) == ExitCode.PASS
    assert main(["analyze", str(out)]) == ExitCode.PASS
    made = sorted(out.glob("analysis-*/result.json"))
    assert len(made) == 2 and all((m.parent / "report.html").exists() for m in made)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    for m in made:
        validate(m, "result")
    bare = tmp_path / "flight-a.csv"
    bare.write_bytes((out / "signals.csv").read_bytes())
    other = tmp_path / "flight-b.csv"
    other.write_bytes((out / "signals.csv").read_bytes())
    assert main(["analyze", str(bare)]) == ExitCode.PASS and main(["analyze", str(other)]) == ExitCode.PASS
    assert (tmp_path / "flight-a.result.json").exists() and (tmp_path / "flight-b.result.json").exists()
    assert "flight-a.result.json" in (tmp_path / "flight-a.report.html").read_text()


@pytest.mark.slow
def test_serv_of_a_scenario_recording_is_valid_and_decided(tmp_path):
    """``simulate --scenario`` writes what ``serv`` reads; serv.json validates and carries the verdicts.
    (diagnosis.json is validated in tests/test_diagnose.py.)"""
    rec = tmp_path / "rec"
    assert main(["simulate", "--scenario", "full-stroke", "--out", str(rec)]) == 0
    assert main(["serv", str(rec), "--out", str(tmp_path / "serv")]) == ExitCode.PASS
    s = validate(tmp_path / "serv" / "serv.json", "serv")
    assert s["status"] == "pass" and s["trace"]["run_id"] and s["trace"]["mode"] == "simulate-scenario"
    for ch, truth in (("int1", 0.100), ("int2", 0.120)):
        v = s["verdict"][ch]
        assert v["status"] == "pass" and v["traversals"] >= 2 and abs(v["backlash_mm"] - truth) < v["uncertainty_mm"]
    assert s["verdict"]["ext"]["status"] == "not_traversed"  # symmetric operation: the external play never crossed
    assert any("fewer than 5" in n for n in s["notes"]) and any("calibration" in n for n in s["notes"])


def test_a_can_interface_that_cannot_be_opened_exits_3_and_leaves_no_run_folder(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", "--interface", "socketcan", "--channel", "nosuchcan0", "--arm", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and not out.exists()
    assert "cannot open CAN interface 'socketcan' channel 'nosuchcan0'" in err and "ip link" in err
    assert "Traceback" not in err and err.count("\n") == 1
    rc = main(["run", "--interface", "nosuchinterface", "--channel", "x", "--arm", "--out", str(out)])
    assert rc == ExitCode.INPUT and not out.exists()
    assert "must be one python-can knows" in capsys.readouterr().err


@pytest.mark.slow
def test_ctrl_c_writes_an_aborted_result_and_names_each_drives_final_state(tmp_path, monkeypatch, capsys):
    import hil.check.runner as runner

    calls = {"n": 0}
    original = runner.run_check

    def interrupt(prog, smp):
        calls["n"] += 1
        if calls["n"] == 3000:  # 6 s into the check: the operator presses Ctrl-C
            raise KeyboardInterrupt

    # the loop's per-cycle callback (a quiet run has none: nothing is displayed) is where the interrupt lands
    monkeypatch.setattr(runner, "run_check", lambda *a, on_cycle=None, **k: original(*a, on_cycle=interrupt, **k))
    out = tmp_path / "run"
    rc = main(["dry-run", "--quiet", "--out", str(out)])
    console = capsys.readouterr().out
    assert rc == ExitCode.ABORTED
    r = validate(out / "result.json", "result")
    assert r["status"] == "aborted" and r["reason"].startswith("interrupted by the operator")
    meta = read_record(out)
    assert meta.status == "aborted" and all(d.safe for d in meta.drives_final.values())
    # the drives' identity as read by SDO in the preflight: the simulated rig's serial numbers
    ident = r["trace"]["identity"]
    assert (ident["ema1"]["serial"], ident["ema2"]["serial"]) == (0x5E000101, 0x5E000102)
    assert ident["ema1"]["node"] == 1 and ident["ema1"]["vendor_id"] == 0x00000E3A
    assert "EMA 1 (node 1): SWITCH_ON_DISABLED, safe" in console
    assert "EMA 2 (node 2): SWITCH_ON_DISABLED, safe" in console


def test_the_eds_device_info_must_agree_with_its_identity_object(tmp_path, capsys):
    from hil.profile.load import default_profile_path

    text = default_profile_path("ema_drive.eds").read_text()
    assert "ProductNumber=0x00000402" in text
    (tmp_path / "ema_drive.eds").write_text(text.replace("ProductNumber=0x00000402", "ProductNumber=0x00000403"))
    act = write_profile_variant("actuation.toml", tmp_path / "actuation.toml", {})
    rc = main(["dry-run", "--quiet", "--profile", str(act), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and "[DeviceInfo] ProductNumber = 0x00000403" in err and "0x1018:02" in err


def test_recordings_that_cannot_be_analysed_name_the_file_and_exit_3(tmp_path, capsys):
    short = tmp_path / "short.csv"
    # (moving slowly: a recording whose signals are constant is refused as such, test_bad_recordings.py)
    rows = ["t,phi1,phi2,s1,s2,F1,F2,step"] + [f"{0.002 * (k + 1):.4f}" + f",{1e-4 * k:.4f}" * 6 + ",approach"
                                               for k in range(1200)]
    short.write_text("\n".join(rows) + "\n")
    assert main(["analyze", str(short)]) == ExitCode.INPUT
    err = capsys.readouterr().err
    assert str(short) in err and "force_fight" in err and err.count("\n") == 1
    mat = tmp_path / "DATA.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file\x00\x01\x02\xff\xfe" * 10)
    assert main(["analyze", str(mat)]) == ExitCode.INPUT
    err = capsys.readouterr().err
    assert "a MATLAB file" in err and "--model single-axis" in err
