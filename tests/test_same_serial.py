"""Two EMAs of one serial number (issue 34, part 6): refused by the preflight (exit 3, both nodes and the
serial named), by ``simulate``, by the history; said in the report."""

from __future__ import annotations

import json

import pytest

from hil.cli import main
from hil.cli.args import ExitCode
from hil.record.runrecord import shared_serial
from hil.report.shell import trace_lines
from support.profiles import write_profile_variant

SERIAL = 0x5E000101


def ident(serial1, serial2, vendor2=0xE3A):
    return {"ema1": {"node": 1, "vendor_id": 0xE3A, "product_code": 0x402, "revision": 0x10000, "serial": serial1},
            "ema2": {"node": 2, "vendor_id": vendor2, "product_code": 0x402, "revision": 0x10000, "serial": serial2}}


def test_shared_serial_at_its_boundary():
    assert shared_serial(ident(SERIAL, SERIAL)) == ("EMA 1 (node 1) and EMA 2 (node 2) report the same serial "
                                                     "number 0x5E000101: two actuators of one serial cannot be traced")
    assert shared_serial(ident(SERIAL, SERIAL + 1)) is None
    assert shared_serial(ident(SERIAL, SERIAL, vendor2=0xE3B)) is None  # another vendor's numbering
    assert shared_serial(ident(0, 0)) is None  # none set (the EDS default): nothing to compare
    assert shared_serial(ident(None, None)) is None and shared_serial(None) is None
    assert shared_serial({"ema1": ident(SERIAL, SERIAL)["ema1"], "ema2": None}) is None


def test_the_report_says_so_in_one_line():
    html = trace_lines({"identity": ident(SERIAL, SERIAL)})
    assert html.count("<b>Identity:</b>") == 1 and "report the same serial number 0x5E000101" in html
    assert "<b>Identity:</b>" not in trace_lines({"identity": ident(SERIAL, SERIAL + 1)})


@pytest.fixture()
def same_serial_rig(tmp_path):
    return write_profile_variant("simrig.toml", tmp_path / "simrig.toml",
                                 {"identity": {"serial_ema1": SERIAL, "serial_ema2": SERIAL}})


def test_dry_run_with_two_drives_of_one_serial_stops_in_the_preflight_with_exit_3(same_serial_rig, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()  # an empty folder is a run folder
    rc = main(["dry-run", "--sim", str(same_serial_rig), "--out", str(out), "--quiet"])
    console = capsys.readouterr().out
    assert rc == ExitCode.INPUT
    meta = json.loads((out / "meta.json").read_text())
    result = json.loads((out / "result.json").read_text())
    assert meta["status"] == "aborted" and result["status"] == "aborted"
    why = "node 1 (EMA 1) and node 2 (EMA 2) both report serial number 0x5E000101"
    assert why in meta["reason"] and why in result["reason"] and why in " ".join(console.split())
    # nothing moved: the preflight stopped before the drill and the cyclic phase (EMA 1's reaction was configured:
    # the record says its drill was not run; EMA 2 was stopped at its identity, before its reaction)
    assert meta.get("samples", 0) == 0
    assert {k: ml["drill"]["outcome"] for k, ml in meta["master_loss"].items()} == {"ema1": "not run"}
    # the identity read is recorded, both serials
    assert [meta["identity"][k]["serial"] for k in ("ema1", "ema2")] == [SERIAL, SERIAL]


def test_simulate_refuses_a_rig_of_one_serial_before_making_a_folder(same_serial_rig, tmp_path, capsys):
    out = tmp_path / "sim"
    rc = main(["simulate", "--sim", str(same_serial_rig), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and not out.exists()
    assert f"{same_serial_rig}: identity.serial_ema1 = identity.serial_ema2" in err and "0x5E000101" in err
    assert err.count("\n") == 1


def test_the_history_refuses_a_pair_of_one_serial(tmp_path, capsys):
    from support.wear import wear_results

    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    good, bad = wear_results(n=2, simulated=False)[:2]
    (tmp_path / "good.result.json").write_text(json.dumps(good))
    assert main(["history", "sync", str(tmp_path / "good.result.json"), "--history", url]) == ExitCode.PASS
    capsys.readouterr()
    bad["trace"]["identity"]["ema2"]["serial"] = bad["trace"]["identity"]["ema1"]["serial"]
    serial = bad["trace"]["identity"]["ema1"]["serial"]
    (tmp_path / "bad.result.json").write_text(json.dumps(bad))
    db = (tmp_path / "h.sqlite").read_bytes()
    rc = main(["history", "sync", str(tmp_path / "bad.result.json"), "--history", url])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and f"report the same serial number 0x{serial:08X}" in err
    assert "bad.result.json" in err and err.count("\n") == 1
    assert (tmp_path / "h.sqlite").read_bytes() == db
    assert main(["history", "--history", url, "--json"]) == ExitCode.PASS
    assert len(json.loads(capsys.readouterr().out)["checks"]) == 1
