"""The commands record their results: simulate with the wear option, analyze with the database down (the
check's exit status unchanged, `history sync` later), and `run` loads no history code before its loop."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.cli import main
from hil.history.store import HistoryStore
from hil.record.runfolder import read_record
from support.profiles import write_profile_variant

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_simulate_with_wear_records_a_simulated_check_at_its_flight_hours(tmp_path, capsys):
    """The simulated rig's [wear] option: the plant's backlash is on the wear line at --flight-hours (plus
    the scatter), BLFmaint measures it, and --history records it simulated, with the rig's serials."""
    sim = write_profile_variant("simrig.toml", tmp_path / "simrig.toml", {}, add={"wear": {
        "backlash_int1_mm_per_1000_fh": 0.025, "backlash_int2_mm_per_1000_fh": 0.02,
        "backlash_ext_mm_per_1000_fh": 0.01, "scatter_mm": 0.001}})
    url = f"sqlite:///{tmp_path}/h.sqlite"
    out = tmp_path / "run"
    rc = main(["simulate", "--sim", str(sim), "--seed", "3", "--out", str(out), "--quiet", "--flight-hours", "2000",
               "--flight-cycles", "1600", "--aircraft", "D-AXYZ", "--position", "left aileron", "--history", url])
    assert rc == 0
    assert "recorded in the history" in capsys.readouterr().out
    res = json.loads((out / "result.json").read_text())
    meta = read_record(out)
    assert meta.wear.line_mm["int1"] == pytest.approx(0.15) and meta.wear.flight_hours == 2000.0
    assert meta.installation.flight_cycles == 1600 and meta.installation.aircraft == "D-AXYZ"
    assert res["truth"]["backlash_mm"]["int1"] == pytest.approx(0.15, abs=0.004)  # the line + 1 um scatter
    for ch in ("int1", "int2", "ext"):
        assert res["backlash_mm"][ch] == pytest.approx(res["truth"]["backlash_mm"][ch], abs=0.005), ch
    t = res["trace"]
    assert (t["flight_hours"], t["flight_cycles"], t["aircraft"], t["position"]) == (2000.0, 1600, "D-AXYZ",
                                                                                      "left aileron")
    assert t["identity"]["ema1"]["serial"] == 0x5E000101
    with HistoryStore.open(url) as store:
        [row] = store.checks(serial=0x5E000102)
    assert row["simulated"] and row["flight_hours"] == 2000.0 and row["mode"] == "simulate"
    assert row["readings"]["int1"]["backlash_mm"] == res["backlash_mm"]["int1"]


@pytest.mark.slow
def test_analyze_with_the_database_down_keeps_its_exit_status_then_sync_records_once(default_run, tmp_path, capsys):
    run_dir, _ = default_run
    ref = main(["analyze", str(run_dir), "--out", str(tmp_path / "a0"), "--no-history"])
    capsys.readouterr()
    down = f"postgresql://emacheck:secret@/emacheck?host={tmp_path}"  # no server there
    rc = main(["analyze", str(run_dir), "--out", str(tmp_path / "a1"), "--history", down, "--flight-hours", "812.5"])
    out = capsys.readouterr().out
    assert rc == ref == 0
    assert "NOT recorded in the history" in out and "cannot reach the database server" in out and "secret" not in out
    assert "emacheck history sync" in out
    url = f"sqlite:///{tmp_path}/h.sqlite"
    assert main(["history", "sync", str(tmp_path / "a1"), "--history", url]) == 0
    assert main(["history", "sync", str(tmp_path / "a1"), "--history", url]) == 0
    assert "0 result(s) recorded, 1 already there" in capsys.readouterr().out
    with HistoryStore.open(url) as store:
        [row] = store.checks()
    assert row["flight_hours"] == 812.5 and row["simulated"] and row["kind"] == "maint"
    assert row["readings"]["int2"]["uncertainty_mm"] > 0


def test_run_loads_no_database_library_before_its_cyclic_loop(tmp_path):
    """`emacheck run` with --history: at the start of the check loop neither SQLAlchemy, psycopg,
    platformdirs nor the history's store/record/trends are imported (only the URL's form was checked)."""
    code = (
        "import os, sys\n"
        "import hil.cli.run as r\n"
        "def loop(*a, **k):\n"
        "    bad = sorted(m for m in sys.modules if m.split('.')[0] in ('sqlalchemy', 'psycopg', 'platformdirs')\n"
        "                 or m in ('hil.history.store', 'hil.history.record', 'hil.history.sync',\n"
        "                          'hil.history.trends', 'blf.wear'))\n"
        "    print('LOADED', bad, flush=True)\n"
        "    os._exit(0)\n"
        "r.canopen_check = loop\n"
        "from hil.cli import main\n"
        f"main(['run', '--interface', 'virtual', '--channel', 'emacheck-test-hist', '--arm', '--quiet',\n"
        f"      '--out', {str(tmp_path / 'run')!r}, '--history', 'postgresql://u@/db?host=/nowhere',\n"
        f"      '--aircraft', 'D-AXYZ', '--flight-hours', '100'])\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert "LOADED []" in r.stdout, r.stdout + r.stderr
