"""End-to-end: the whole check through CANopen frames against the simulated drive pair.

Acceptance of issue "The maintenance check over CANopen": backlash within
0.005 mm of truth, stiffness within 3 %, pitch within 0.1 % (default noise,
7.5 % LVDT pitch error on); the raw CAN log alone decodes into the same
signals as the CSV; SYNC/TPDO/RPDO order within every cycle; nothing is sent
before the profiles validated; `run` without --arm refuses.

The tests on the whole dry-run are ``slow`` (deselected by ``-m "not slow"``); the
refusals before anything is sent stay in the fast loop.
"""

from __future__ import annotations

import json
import shutil

import can
import numpy as np
import pytest

from blf.signals import CHANNELS
from hil.cli import main
from hil.record.canlog import decode_can_log
from hil.record.runfolder import read_record, read_signals
from hil.record.runrecord import RunMode, RunStatus
from support.profiles import write_profile_variant


@pytest.mark.slow
def test_dry_run_recovers_truth_through_canopen(dry_run):
    out, rc = dry_run
    assert rc == 0
    res = json.loads((out / "result.json").read_text())
    meta = read_record(out)
    truth = res["truth"]
    assert meta.mode is RunMode.DRY_RUN and meta.status is RunStatus.DONE
    for ch in CHANNELS:
        assert abs(res["backlash_mm"][ch] - truth["backlash_mm"][ch]) < 0.005, ch
        for side in ("left", "right"):
            got, want = res["stiffness_N_per_mm"][ch][side], truth["stiffness_N_per_mm"][ch][side]
            assert abs(got / want - 1) < 0.03, (ch, side, got, want)
    for k in ("ema1", "ema2"):
        assert res["calibration"][k]["pitch"] == pytest.approx(truth["calibration"][k]["pitch"], rel=1e-3)
    assert meta.bus_load.worst < 0.5
    assert meta.can.missing_cycles == 0 and meta.can.bad_frames == 0


@pytest.mark.slow
def test_can_log_decodes_into_the_csv_signals(dry_run, actuation):
    out, _ = dry_run
    csv = read_signals(out / "signals.csv")
    dec = decode_can_log(out / "can.log", actuation)
    sig = dec.signals
    assert dec.incomplete_cycles == 0 and dec.bad_lines == 0
    # the CSV holds the check loop's samples; the log also has the enabling cycles before it
    k0 = int(np.searchsorted(sig.t, csv.t[0] - 1e-9))
    n = csv.n
    np.testing.assert_allclose(sig.t[k0:k0 + n], csv.t, atol=1e-9)
    for name, tol in (("phi1", 1e-6), ("phi2", 1e-6), ("s1", 1e-6), ("s2", 1e-6), ("F1", 1e-3), ("F2", 1e-3)):
        np.testing.assert_allclose(getattr(sig, name)[k0:k0 + n], getattr(csv, name), atol=tol, err_msg=name)
    # modes and setpoints as commanded (the last row's setpoints are the final DISABLED ones)
    np.testing.assert_array_equal(sig.mode1[k0:k0 + n - 1], csv.mode1[:-1])
    np.testing.assert_array_equal(sig.mode2[k0:k0 + n - 1], csv.mode2[:-1])
    pos = csv.mode1[:-1] == 8
    np.testing.assert_allclose(sig.sp1[k0:k0 + n - 1][pos], csv.sp1[:-1][pos], atol=2 * np.pi / 4096)


@pytest.mark.slow
def test_every_cycle_sync_then_tpdos_then_rpdos(dry_run):
    out, _ = dry_run
    lines = (out / "can.log").read_text().splitlines()
    ids = [int(line.split()[2].split("#")[0], 16) for line in lines]
    syncs = [k for k, i in enumerate(ids) if i == 0x080]
    assert len(syncs) > 55000
    bad = 0
    for a, b in zip(syncs[1000:-200], syncs[1001:-199], strict=True):
        cyc = ids[a + 1:b]
        tp = [i for i in cyc if i in (0x181, 0x182, 0x281, 0x282)]
        rp = [i for i in cyc if i in (0x201, 0x202)]
        if sorted(tp) != [0x181, 0x182, 0x281, 0x282] or sorted(rp) != [0x201, 0x202]:
            bad += 1
            continue
        # the setpoints of a cycle leave after its last TPDO arrived, before the next SYNC
        last_tpdo = max(k for k, i in enumerate(cyc) if i in (0x181, 0x182, 0x281, 0x282))
        if min(k for k, i in enumerate(cyc) if i in (0x201, 0x202)) < last_tpdo:
            bad += 1
    assert bad == 0


@pytest.mark.slow
def test_analyze_from_can_log_alone(dry_run, tmp_path):
    out, _ = dry_run
    run = tmp_path / "run"
    run.mkdir()
    for f in ("can.log", "meta.json"):
        shutil.copy(out / f, run / f)
    rc = main(["analyze", str(run), "--out", str(run)])
    assert rc == 0
    (made,) = run.glob("analysis-*/result.json")  # a new sub-folder: the run folder's files stay
    res = json.loads(made.read_text())
    ref = json.loads((out / "result.json").read_text())
    for ch in CHANNELS:
        assert res["backlash_mm"][ch] == pytest.approx(ref["backlash_mm"][ch], abs=2e-4), ch
    assert any("decoded from CAN log" in n for n in res["notes"])


@pytest.mark.slow
def test_analyze_reads_a_gzipped_can_log_directly(dry_run, tmp_path):
    """A bare can.log.gz (no run folder, no meta.json): decoded as it is, the segments found from the
    data, the same backlash as the check's own result. (A whole dry-run and a whole analysis: slow. The
    fast loop decodes a short run's gzipped log against its plain one, test_faults_bad_input.py.)"""
    import gzip

    out, _ = dry_run
    gz = tmp_path / "can.log.gz"
    with open(out / "can.log", "rb") as src, gzip.open(gz, "wb") as dst:
        dst.write(src.read())
    assert main(["analyze", str(gz), "--out", str(tmp_path / "a"), "--no-history"]) == 0
    res = json.loads((tmp_path / "a" / "result.json").read_text())
    ref = json.loads((out / "result.json").read_text())
    for ch in CHANNELS:
        assert res["backlash_mm"][ch] == pytest.approx(ref["backlash_mm"][ch], abs=2e-4), ch
    assert any("decoded from CAN log" in n for n in res["notes"])


def test_nothing_sent_before_profiles_validate_and_run_needs_arm(tmp_path, capsys):
    listener = can.Bus(interface="virtual", channel="emacheck-test-arm")
    try:
        bad = write_profile_variant("check.toml", tmp_path / "check.toml",
                                    {"force_fight": {"amplitude_fraction_of_limit": 0.3}})
        rc = main(["run", "--interface", "virtual", "--channel", "emacheck-test-arm", "--arm",
                   "--check", str(bad), "--out", str(tmp_path / "r1")])
        assert rc == 3
        assert "above the hard cap 0.15" in capsys.readouterr().err
        rc = main(["run", "--interface", "virtual", "--channel", "emacheck-test-arm", "--out", str(tmp_path / "r2")])
        assert rc == 3
        assert "refusing to move anything" in capsys.readouterr().out
        assert listener.recv(0.2) is None  # not one frame on the bus
        assert not (tmp_path / "r1").exists() and not (tmp_path / "r2").exists()
        rc = main(["dry-run", "--check", str(bad), "--out", str(tmp_path / "d")])
        assert rc == 3 and not (tmp_path / "d").exists()
    finally:
        listener.shutdown()
