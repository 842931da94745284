"""The check on drives other than the shipped one, end to end over CANopen (dry-runs): a drive without CST,
the record of each drive's reaction to the master's death."""

from __future__ import annotations

import html
import json

import numpy as np
import pytest

from hil.cli.dry_run import dry_run
from hil.profile.load import load_actuation, load_check
from hil.record.runfolder import read_record, read_signals
from hil.report.shell import master_loss_text
from support.eds import write_eds_variant
from support.profiles import write_profile_variant


@pytest.mark.slow
def test_dry_run_with_drives_without_cst_holds_the_opposing_force_in_csp(tmp_path, simrig):
    eds = write_eds_variant(tmp_path / "csp_only.eds", defaults={(0x6502, 0): "0x00000080"})
    prof = write_profile_variant("actuation.toml", tmp_path / "act.toml", {"canopen": {"eds": str(eds)}})
    act = load_actuation(prof)
    check = load_check(None, act)
    r = dry_run(act, check, simrig, tmp_path / "run", profile_path=prof)
    assert r.exit_code == 0, r.outcome.reason
    res = json.loads((tmp_path / "run" / "result.json").read_text())
    for ch in ("int1", "int2", "ext"):
        assert abs(res["backlash_mm"][ch] - res["truth"]["backlash_mm"][ch]) < 0.005, ch
    for k in ("ema1", "ema2"):
        assert res["calibration"][k]["pitch"] == pytest.approx(res["truth"]["calibration"][k]["pitch"], rel=1e-3)
    assert res["trace"]["force_control"] == {"ema1": "csp", "ema2": "csp"}
    assert "the master's force loop on the measured force in CSP" in html.unescape(
        (tmp_path / "run" / "report.html").read_text())
    # the opposing force held by the loop through each sweep
    sig = read_signals(tmp_path / "run" / "signals.csv")
    f = check.calibration.opposing_force_N
    for step, F in (("cal1_sweep", sig.F2), ("cal2_sweep", sig.F1)):
        m = sig.step == step
        assert abs(np.mean(F[m]) + f) < 0.02 * f, step
        assert np.max(np.abs(F[m] + f)) < 0.25 * f, step  # never near slack: the play stays closed
    # no mode changes by PDO: every mode column is CSP (8) or disabled (0)
    assert set(np.unique(sig.mode1)) <= {0.0, 8.0} and set(np.unique(sig.mode2)) <= {0.0, 8.0}


@pytest.mark.slow
def test_the_default_dry_run_records_the_drill_and_reports_it(dry_run):
    out, rc = dry_run
    meta = read_record(out)
    res = json.loads((out / "result.json").read_text())
    for k in ("ema1", "ema2"):
        ml = meta.master_loss[k]
        assert ml["configured"] and ml["drill"]["outcome"] == "reacted"
        assert 125.0 <= ml["drill"]["reaction_ms"] <= 129.0  # consumer time + two SYNC cycles
        assert res["trace"]["master_loss"][k] == ml
        assert meta.drives_final[k].state == "SWITCH_ON_DISABLED" and meta.drives_final[k].safe
    report = html.unescape((out / "report.html").read_text())
    assert "drill: reacted 126.0 ms after the master's last heartbeat" in report
    cob_ids = {p["cob_id"] for p in meta.process_image["pdos"]}
    assert cob_ids == {0x181, 0x182, 0x281, 0x282, 0x201, 0x202, 0x301, 0x302}


@pytest.mark.parametrize("ml,says", [
    ({"configured": True, "consumer_heartbeat_ms": 125, "master_node_id": 127, "abort_connection_option": 3,
      "drill": {"outcome": "reacted", "reaction_ms": 126.0, "state_after": "QUICK_STOP_ACTIVE", "emcy": ["0x8130"]}},
     "configured: consumer heartbeat 125 ms on node 127, abort connection option 3 (written and read back by SDO); "
     "drill: reacted 126.0 ms after the master's last heartbeat (to QUICK_STOP_ACTIVE, EMCY 0x8130)"),
    ({"configured": True, "consumer_heartbeat_ms": 125, "master_node_id": 127, "abort_connection_option": 3,
      "drill": {"outcome": "no reaction", "waited_ms": 352.0}, "external_watchdog": "relay drops STO"},
     "drill: NO REACTION: still OPERATION ENABLED after 352.0 ms of the master's silence (EMCY none); external "
     "watchdog stated: relay drops STO"),
    ({"configured": True, "drill": {"outcome": "skipped", "note": "bench without load"}},
     "drill skipped: bench without load"),
    ({"configured": False, "problems": [], "drill": {"outcome": "not configured"}, "external_watchdog": "relay"},
     "NOT configured: the drive has none; not drilled; external watchdog stated: relay"),
    ({"configured": True, "drill": {"outcome": "not run", "note": "stopped before the master fell silent: x"}},
     "; drill not run (stopped before the master fell silent: x)"),
    ({"configured": True, "drill": {"outcome": "not run", "note": ""}},
     "; drill not run (the preflight stopped before it)"),
])
def test_the_report_says_configured_and_drilled_for_what_each_is(ml, says):
    assert says in master_loss_text(ml)
