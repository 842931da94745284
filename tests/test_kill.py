"""The kill test: SIGKILL the master at random instants of dry-runs; every run folder stays analysable.

Each run is ``emacheck dry-run`` (``hil.cli.main``) in a child process forked
from this one (the imports and the numba compilation are paid once, so a run
costs its check, not the interpreter start-up) with a short check profile
(~3 s wall). The parent waits until the run folder's meta.json exists, then
SIGKILLs the child after a uniform random delay over the run's wall time
(seeded rng; the seed is in the assertion messages). ``emacheck analyze`` on
each folder must then succeed and report the run as incomplete; what it read
must reach to within the flush period (0.5 s of check time) of the last sample
the killed master had logged... which we cannot know from outside, so the
test checks the bound the other way round: the analysed data end no earlier
than the last step change recorded in meta.json (fsynced with the CSV).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np
import pytest

from hil.cli import main
from hil.runfolder import read_signals, resolve_recording

#: twenty dry-runs killed and analysed: not in the fast loop (-m "not slow")
pytestmark = pytest.mark.slow

SEED = 20261122
N_KILLS = 20
#: kill instants are drawn in [0, KILL_WINDOW) times the measured wall time of the cyclic part
KILL_WINDOW = 0.9

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


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_twenty_kills_leave_analysable_run_folders(tmp_path, capsys):
    chk = tmp_path / "short_check.toml"
    chk.write_text(SHORT_CHECK)
    # the cyclic part's wall time on this machine, from one run left alone: from meta.json
    # (written before the first frame) until its status leaves "running"
    probe = tmp_path / "probe"
    pid = _start_child(["dry-run", "--check", str(chk), "--out", str(probe), "--quiet"])
    t0 = time.monotonic()
    while not (probe / "meta.json").exists() and time.monotonic() - t0 < 30:
        time.sleep(0.002)
    t1 = time.monotonic()
    while json.loads((probe / "meta.json").read_text())["status"] == "running" and time.monotonic() - t1 < 60:
        time.sleep(0.002)
    run_wall_s = time.monotonic() - t1
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) in (0, 1), status
    rng = np.random.default_rng(SEED)
    delays: list[float] = []
    killed_mid_run = after_loop = 0
    # a run can be quicker than the probe (warm caches): a kill that comes after its cyclic part
    # (status no longer "running") does not count, another instant is drawn; at most 2 N tries
    for k in range(2 * N_KILLS):
        if killed_mid_run == N_KILLS:
            break
        delay = float(rng.uniform(0.0, KILL_WINDOW)) * run_wall_s
        out = tmp_path / f"run{k:02d}"
        pid = _start_child(["dry-run", "--check", str(chk), "--out", str(out), "--quiet"])
        t0 = time.monotonic()
        while not (out / "meta.json").exists() and time.monotonic() - t0 < 30:
            time.sleep(0.002)
        time.sleep(delay)
        os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        meta = json.loads((out / "meta.json").read_text())
        if meta["status"] != "running":
            after_loop += 1
            continue
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, \
            f"seed {SEED}, kill {k} at {delay:.3f} s: the run ended before the kill"
        killed_mid_run += 1
        delays.append(delay)
        rc = main(["analyze", str(out), "--out", str(out)])
        text = capsys.readouterr().out
        res = json.loads((out / "result.json").read_text())
        assert rc == 2 and res["status"] == "incomplete", f"seed {SEED}, kill {k} at {delay:.3f} s: {res}"
        assert "incomplete" in text
        # what was analysed reaches at least the last step change (flushed and fsynced there)
        steps = meta.get("steps") or {}
        if steps and "analysis_error" not in res:
            sig_path, _ = resolve_recording(out)
            if sig_path.suffix == ".csv":
                t_last = read_signals(sig_path).t[-1]
                assert t_last >= max(v[0] for v in steps.values()) - 1e-9
    assert killed_mid_run == N_KILLS
    print(f"kill test: seed {SEED}, cyclic part {run_wall_s:.2f} s, {N_KILLS} kills mid-run at "
          f"{np.round(delays, 3).tolist()} s ({after_loop} came after the loop and were drawn again)",
          file=sys.stderr)
