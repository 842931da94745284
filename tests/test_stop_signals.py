"""SIGTERM and SIGHUP stop a check exactly as one Ctrl-C does, and no later signal cuts the stop short
(issue 47, part 4): the drives to their safe stop, meta.json and result.json ``aborted`` with the reason,
report.html written, exit 2; a dry-run, and ``sim-serve`` + ``run`` as two processes over a bus."""

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


@pytest.mark.slow
@pytest.mark.xdist_group("wall_clock")
@pytest.mark.parametrize("sig, reason", [(signal.SIGTERM, "stopped by SIGTERM"), (signal.SIGHUP, "stopped by SIGHUP")],
                         ids=["term", "hup"])
def test_a_signal_during_a_two_process_run_stops_it_safely_and_keeps_its_record(tmp_path, sig, reason):
    """`sim-serve` and `run` as two processes on udp_multicast in a private network namespace (the vcan stage's
    100 Hz profiles, the kill test's short check): the signal once the calibration's sweep began; the drives
    stopped and confirmed in Switch on disabled (read after the stop), meta.json and result.json aborted with
    the reason, report.html written, exit 2. (SIGKILL of the same pair: tests/test_master_loss.py.)"""
    from test_kill import SHORT_CHECK

    from support.ci import skip_or_fail
    from support.netns import cannot_run, serve_and_master

    why = cannot_run()
    if why is not None:
        skip_or_fail(why)
    vcan = ROOT / "tests" / "vcan"
    chk = tmp_path / "short_check.toml"
    chk.write_text(SHORT_CHECK)
    out = tmp_path / "run"
    prof = ["--profile", str(vcan / "actuation.toml")]
    r = serve_and_master([*prof, "--sim", str(vcan / "simrig.toml")],
                         ["run", "--arm", "--no-history", *prof, "--check", str(chk), "--out", str(out)],
                         timeout_s=180.0, signal_on="] cal1_sweep", signals=(sig,))
    assert r["signalled"] and r["master_rc"] == 2, r["master_out"][-3000:]
    meta = json.loads((out / "meta.json").read_text())
    result = json.loads((out / "result.json").read_text())
    assert meta["status"] == "aborted" and reason in meta["reason"]
    assert result["status"] == "aborted" and reason in result["reason"]
    assert (out / "report.html").stat().st_size > 0
    finals = meta["drives_final"]
    assert set(finals) == {"ema1", "ema2"}
    assert all(d["state"] == "SWITCH_ON_DISABLED" and d["confirmed"] for d in finals.values()), finals
    assert r["serve_rc"] == 0
