"""SIGTERM and SIGHUP stop a check exactly as one Ctrl-C does, and no later signal cuts the stop short
(issue 47, part 4): the drives to their safe stop, meta.json and result.json ``aborted`` with the reason,
report.html written, exit 2."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil.cli.stopping import StopOnSignals
from hil.errors import StopRequest

ROOT = Path(__file__).resolve().parents[1]


def test_the_first_signal_stops_later_ones_are_counted_and_ignored():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    with StopOnSignals() as stop:
        with pytest.raises(StopRequest, match="SIGTERM"):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)  # (the handler runs at the next bytecode; never reached)
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGHUP)
        time.sleep(0.05)
        assert stop.first == signal.SIGTERM and stop.ignored == 2
    assert {s: signal.getsignal(s) for s in before} == before


def test_ctrl_c_first_is_a_plain_keyboard_interrupt():
    with StopOnSignals(), pytest.raises(KeyboardInterrupt) as exc:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)
    assert type(exc.value) is KeyboardInterrupt and str(exc.value) == ""


@pytest.mark.slow
@pytest.mark.parametrize("sigs, reason", [
    ((signal.SIGTERM,), "stopped by SIGTERM"),
    ((signal.SIGHUP,), "stopped by SIGHUP"),
    ((signal.SIGTERM, signal.SIGTERM), "stopped by SIGTERM"),
    ((signal.SIGINT, signal.SIGINT, signal.SIGINT), "interrupted by the operator"),
], ids=["term", "hup", "term-twice", "ctrl-c-three-times"])
def test_a_signal_during_a_dry_run_stops_it_safely_and_keeps_its_record(tmp_path, sigs, reason):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "hil", "dry-run", "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen = []
    for line in proc.stdout:  # a pipe: the progress lines say where the check stands
        seen.append(line)
        if "] cal1_sweep" in line:
            break
    for s in sigs:
        proc.send_signal(s)
        time.sleep(0.02)
    rest, _ = proc.communicate(timeout=120)
    assert proc.returncode == 2, "".join(seen) + rest
    meta = json.loads((out / "meta.json").read_text())
    result = json.loads((out / "result.json").read_text())
    assert meta["status"] == "aborted" and reason in meta["reason"]
    assert result["status"] == "aborted" and reason in result["reason"]
    assert (out / "report.html").stat().st_size > 0
    finals = meta["drives_final"]
    assert set(finals) == {"ema1", "ema2"} and all(d["state"] != "OPERATION_ENABLED" for d in finals.values())
