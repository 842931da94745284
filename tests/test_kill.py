"""The kill test: SIGKILL the master at random instants of dry-runs; every run folder stays analysable.

Each run is ``emacheck dry-run`` (``hil.cli.main``) in a child process forked
from this one (the imports and the numba compilation are paid once, so a run
costs its check, not the interpreter start-up) with a short check profile
(~1.5 s wall) whose force fight is more than half of it. The parent waits
until the run folder's meta.json exists, then SIGKILLs the child after a
random delay (seeded rng; the seed is in the assertion messages).

* Twenty kills land in the analysable part of the cyclic loop: from the end of
  the force fight's first cycle plus one flush period to the end of the loop.
  ``emacheck analyze`` on each folder must report the run as incomplete *and*
  measure it (no ``analysis_error``: BLFmaint had its force fight), and what it
  read must reach the last step change recorded in meta.json (fsynced with the
  CSV): the flush period of the killed master is all that may be lost.
* Four kills land before the force fight (calibration): analyze still reads the
  folder, reports it incomplete and names what is missing.

The wall time of the loop is measured on a probe run after a warm-up run in
this process: the numba kernels of the plant are compiled at the first plant
step, *after* meta.json exists, so on a fresh clone (no numba cache yet) the
first run's loop takes ~3 s longer than the next ones; a probe without the
warm-up measured that, drew kill instants over it, and most kills came after
the (faster) later runs had ended.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np
import pytest

import hil.report.maint
from hil.cli import main
from hil.record.runfolder import read_record, read_signals, resolve_recording
from hil.record.runrecord import RunRecord

#: twenty dry-runs killed and analysed: not in the fast loop (-m "not slow")
# SIGKILL at wall-clock times: one such test at a time (docs/testing.md, "Parallel")
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("wall_clock")]

SEED = 20261122
N_KILLS = 20
N_EARLY_KILLS = 4
#: the run folder's CSV is flushed at least every 500 rows (1 s of check time at 500 Hz) and at each
#: step change: BLFmaint needs the first fight cycle on disk
FLUSH_S = 1.0

#: the check of tests/test_master_loss.py's SIGKILL of `run` (two processes; unchanged)
SHORT_CHECK = """
[approach]
speed_mm_per_s = 5.0
settle_s = 0.5

[calibration]
sweep_speed_mm_per_s = 2.0
sweep_amplitude_mm = 1.0
opposing_force_N = 2000.0
force_ramp_s = 1.0

[force_fight]
amplitude_fraction_of_limit = 0.05
cycles = 1
force_rate_N_per_s = 4000.0
loop_gain_mm_per_N_s = 0.0007
max_excursion_rate_mm_per_s = 0.5

[safety]
max_force_N = 8000.0
max_stroke_mm = 19.5
max_velocity_mm_per_s = 10.0
max_following_error_mm = 0.5
max_d_int_mm = 0.6
"""

#: the kill test's check: short calibration (0.6 mm sweeps, 0.3 s ramps), three force-fight cycles of
#: 2 s: 6 of its 11 s of check time are force fight
KILL_CHECK = """
[approach]
speed_mm_per_s = 5.0
settle_s = 0.2

[calibration]
sweep_speed_mm_per_s = 2.0
sweep_amplitude_mm = 0.6
opposing_force_N = 2000.0
force_ramp_s = 0.3

[force_fight]
amplitude_fraction_of_limit = 0.05
cycles = 3
force_rate_N_per_s = 4000.0
loop_gain_mm_per_N_s = 0.0007
max_excursion_rate_mm_per_s = 0.5

[safety]
max_force_N = 8000.0
max_stroke_mm = 19.5
max_velocity_mm_per_s = 10.0
max_following_error_mm = 0.5
max_d_int_mm = 0.6
"""
CYCLES = 3


def _start_child(args: list[str]) -> int:
    pid = os.fork()
    if pid == 0:  # child: the master, output discarded
        try:
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            rc = main(args)
        except BaseException:
            rc = 99
        os._exit(rc)
    return pid


def _wait_for(path, timeout_s: float = 30.0) -> float:
    t0 = time.monotonic()
    while not path.exists():
        assert time.monotonic() - t0 < timeout_s, f"{path} not written within {timeout_s} s"
        time.sleep(0.001)
    return time.monotonic()


def _no_report(path, *args, **kwargs) -> None:
    """Stands in for hil.report.maint.write_report after the first analysable kill: the report's eight
    figures take ~2 s and are tested on complete runs (tests/test_dry_run.py, tests/test_verdict.py)."""
    _no_report.calls += 1


_no_report.calls = 0


def _meta(out) -> RunRecord:
    return read_record(out)


def _steps(meta: RunRecord) -> dict[str, list[float]]:
    """Step name -> [t_start, t_end] (the open one [t_start]) of a run record, as meta.json holds them."""
    return {s.name: s.as_json() for s in meta.steps or ()}


def _wait_for_step(out, t_meta: float, step: str, timeout_s: float = 60.0) -> tuple[float, RunRecord]:
    """Wall time [s from meta.json] at which meta.json first shows ``step`` (or the run ended)."""
    while True:
        meta = _meta(out)
        now = time.monotonic() - t_meta
        if step in _steps(meta) or meta.status != "running":
            return now, meta
        assert now < timeout_s, f"{out}: no step {step!r} within {timeout_s} s"
        time.sleep(0.001)


def _probe(args: list[str], out) -> dict:
    """One run left alone: the check times of its steps, and the wall time per check second up to the
    force fight."""
    pid = _start_child(args)
    t_meta = _wait_for(out / "meta.json")
    w_ff, meta = _wait_for_step(out, t_meta, "force_fight")
    w_end, meta = _wait_for_step(out, t_meta, "done")
    _, status = os.waitpid(pid, 0)
    meta = _meta(out)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0 and meta.status == "done", (status, meta)
    steps = _steps(meta)
    return {"steps": steps, "rate": w_ff / steps["force_fight"][0], "wall_s": w_end}


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_twenty_kills_leave_analysable_run_folders(tmp_path, capsys, monkeypatch):
    chk = tmp_path / "kill_check.toml"
    chk.write_text(KILL_CHECK)
    # warm-up in this process: every kernel compiled and every module imported before the first fork
    assert main(["dry-run", "--check", str(chk), "--out", str(tmp_path / "warm"), "--quiet"]) == 0
    capsys.readouterr()
    probe = _probe(["dry-run", "--check", str(chk), "--out", str(tmp_path / "probe"), "--quiet"], tmp_path / "probe")
    steps0 = probe["steps"]
    ff0, ff1 = steps0["force_fight"]
    t_done = steps0["done"][0]
    t_a = ff0 + (ff1 - ff0) / CYCLES  # the first fight cycle on disk: BLFmaint has both contacts
    rng = np.random.default_rng(SEED)
    kills = {"analysable": [], "early": []}
    redrawn = {"after the loop": 0, "in the fight's first cycle": 0, "before the first step": 0}
    for k in range(3 * (N_KILLS + N_EARLY_KILLS)):
        if len(kills["analysable"]) == N_KILLS and len(kills["early"]) >= N_EARLY_KILLS:
            break
        aim = "early" if len(kills["early"]) < N_EARLY_KILLS else "analysable"
        out = tmp_path / f"run{k:02d}"
        pid = _start_child(["dry-run", "--check", str(chk), "--out", str(out), "--quiet"])
        t_meta = _wait_for(out / "meta.json")
        if aim == "early":  # in the calibration, at the probe's pace
            t_kill = float(rng.uniform(steps0["cal1_load"][0], ff0 - 0.5))
            delay = t_kill * probe["rate"]
        else:  # past the first fight cycle plus a flush, at this run's own pace through its calibration
            t_kill = float(rng.uniform(t_a + FLUSH_S, t_done - 1.5))
            w_cal, _ = _wait_for_step(out, t_meta, "cal2_sweep")
            w_ff, _ = _wait_for_step(out, t_meta, "force_fight")
            pace = (w_ff - w_cal) / (ff0 - steps0["cal2_sweep"][0])  # wall s per check s, just before the fight
            delay = w_ff + (t_kill - ff0) * pace
        time.sleep(max(0.0, delay - (time.monotonic() - t_meta)))
        os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        meta = _meta(out)
        where = f"seed {SEED}, kill {k} at check time {t_kill:.3f} s ({delay:.3f} s wall, aimed {aim})"
        if meta.status != "running":  # a run quicker than its pace said: another instant is drawn
            redrawn["after the loop"] += 1
            continue
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, f"{where}: ended before the kill"
        steps = _steps(meta)
        if not steps:  # killed before its first step change reached the disk (a slow start): drawn again
            redrawn["before the first step"] += 1
            continue
        sig_path, _ = resolve_recording(out)
        t_logged = read_signals(sig_path).t[-1]
        # where the kill landed, from the folder: before the fight, or past its first cycle on disk
        kind = "early" if "force_fight" not in steps else "analysable" if t_logged >= t_a else None
        if kind is None:  # in the first fight cycle: BLFmaint may or may not have its data; drawn again
            redrawn["in the fight's first cycle"] += 1
            continue
        if kind == "analysable" and kills["analysable"]:  # the first one's report is drawn, the others' not
            monkeypatch.setattr(hil.report.maint, "write_report", _no_report)
        rc = main(["analyze", str(out), "--out", str(out), "--no-history"])
        text = capsys.readouterr().out
        (made,) = out.glob("analysis-*/")  # the run folder's own files are never written into
        res = json.loads((made / "result.json").read_text())
        assert rc == 2 and res["status"] == "incomplete", f"{where}: {res}"
        assert "incomplete" in text, where
        # what was analysed reaches at least the last step change (flushed and fsynced there)
        assert sig_path.suffix == ".csv" and res["trace"]["recording"] == str(sig_path), (where, res["trace"])
        assert t_logged >= max(v[0] for v in steps.values()) - 1e-9, (where, t_logged, steps)
        if kind == "analysable":
            assert "analysis_error" not in res, f"{where}: {res['analysis_error']}"
            assert set(res["backlash_mm"]) == {"int1", "int2", "ext"}, where
            assert all(0.05 < b < 0.15 for b in res["backlash_mm"].values()), (where, res["backlash_mm"])
            assert (made / "report.html").exists() or _no_report.calls, where
        else:
            # (a kill between the step change's flush of the CSV and meta.json's update: one fight sample)
            assert res["analysis_error"].startswith((
                "AnalysisError: the recording's step column has no 'force_fight' samples",
                "IncompleteRecordingError: recording too short for the check",
                "AnalysisError: force-fight segment too short for BLFmaint: 1 samples")), (where, res["analysis_error"])
        if len(kills[kind]) < (N_KILLS if kind == "analysable" else N_EARLY_KILLS):
            kills[kind].append(round(t_kill, 3))
    assert (len(kills["analysable"]), len(kills["early"])) == (N_KILLS, N_EARLY_KILLS), (SEED, kills, redrawn)
    print(f"kill test: seed {SEED}, probe {probe['wall_s']:.2f} s wall for {t_done:.2f} s of check, force fight "
          f"{ff0:.2f}-{ff1:.2f} s, analysable from {t_a:.2f} s; kills at check times {kills}; drawn again: {redrawn}",
          file=sys.stderr)
