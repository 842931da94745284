"""Two emacheck processes on one bus in a private network namespace: ``sim-serve`` and a master (``commission``,
``run``) on python-can's ``udp_multicast``, whose frames stay on the namespace's loopback (``unshare -n``, as
tests/bench/bench_master_loss.py does; ``unshare -r -n`` where the tests do not run as root).

:func:`serve_and_master` is what a test calls: it runs this file again inside the namespace, where :func:`_main`
starts ``sim-serve``, waits for its ready line, runs the master to its end (optionally sending it signals once a
line of its output matches), stops ``sim-serve`` with SIGTERM and hands back both outputs and exit statuses.
Where no namespace can be made (no ``unshare``, no ``ip``, no msgpack) it says why (:func:`cannot_run`); the
tests skip with that reason (fail under CI=true, :func:`support.ci.skip_or_fail`).
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: a multicast group on the namespace's loopback only
GROUP = "239.74.0.39"
READY_TIMEOUT_S = 60.0


def _ip() -> str:
    return shutil.which("ip") or "/usr/sbin/ip"


def _unshare() -> list[str]:
    return ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-r", "-n"]


def _setup() -> str:
    ip = _ip()
    return f"{ip} link set lo up && {ip} link set lo multicast on && {ip} route add 224.0.0.0/4 dev lo"


def cannot_run() -> str | None:
    """Why two processes cannot share a private udp_multicast bus here, or None."""
    try:
        from can.interfaces.udp_multicast.utils import is_msgpack_installed
        if not is_msgpack_installed(raise_exception=False):
            return "python-can's udp_multicast needs msgpack"
    except ImportError as exc:
        return f"python-can has no udp_multicast interface: {exc}"
    if shutil.which("unshare") is None or not Path(_ip()).exists():
        return "`unshare` or `ip` not found (util-linux, iproute2): no private network namespace for multicast"
    probe = subprocess.run([*_unshare(), "sh", "-c", _setup()], capture_output=True, text=True, check=False)
    if probe.returncode != 0:
        return f"no private network namespace here (`{' '.join(_unshare())}`): {probe.stderr.strip()}"
    return None


def serve_and_master(serve: list[str], master: list[str], *, timeout_s: float = 300.0,
                     signal_on: str | None = None, signals: tuple[int, ...] = ()) -> dict:
    """``emacheck sim-serve SERVE...`` and, once it is ready, ``emacheck MASTER...`` in a private network
    namespace (both with ``--interface udp_multicast --channel GROUP`` added); ``signals`` are sent to the
    master once a line of its output contains ``signal_on``. Returns ``master_rc``, ``master_out``,
    ``serve_rc``, ``serve_out`` and ``signalled`` (whether the line came)."""
    spec = json.dumps({"serve": serve, "master": master, "timeout_s": timeout_s, "signal_on": signal_on,
                       "signals": list(signals)})
    cmd = " ".join(shlex.quote(a) for a in [sys.executable, str(Path(__file__).resolve()), spec])
    r = subprocess.run([*_unshare(), "sh", "-c", f"{_setup()} && exec {cmd}"], capture_output=True, text=True,
                       timeout=timeout_s + 2 * READY_TIMEOUT_S, check=False, cwd=ROOT)
    lines = r.stdout.strip().splitlines()
    if r.returncode != 0 or not lines:
        raise RuntimeError(f"the two-process driver failed (exit {r.returncode}):\n{r.stdout[-3000:]}\n"
                           f"{r.stderr[-3000:]}")
    return json.loads(lines[-1])


def _cli(command: list[str]) -> list[str]:
    return [sys.executable, "-m", "hil", command[0], "--interface", "udp_multicast", "--channel", GROUP, *command[1:]]


def _main(spec: dict) -> dict:
    """Inside the namespace: sim-serve, the master, sim-serve stopped; both outputs."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    serve = subprocess.Popen(_cli(["sim-serve", *spec["serve"]]), cwd=ROOT, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    serve_out: list[str] = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < READY_TIMEOUT_S:
        line = serve.stdout.readline()
        if not line and serve.poll() is not None:
            break
        serve_out.append(line)
        if line.rstrip().endswith("; ready"):
            break
    reader = threading.Thread(target=lambda: serve_out.extend(serve.stdout), daemon=True)
    reader.start()
    out = {"master_rc": None, "master_out": "", "signalled": False}
    if serve_out and serve_out[-1].rstrip().endswith("; ready"):
        master = subprocess.Popen(_cli(spec["master"]), cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        seen: list[str] = []
        deadline = time.monotonic() + spec["timeout_s"]
        timer = threading.Timer(spec["timeout_s"], master.kill)
        timer.start()
        for line in master.stdout:
            seen.append(line)
            if spec["signal_on"] is not None and not out["signalled"] and spec["signal_on"] in line:
                out["signalled"] = True
                for s in spec["signals"]:
                    master.send_signal(s)
                    time.sleep(0.02)
        master.wait(max(1.0, deadline - time.monotonic()))
        timer.cancel()
        out.update(master_rc=master.returncode, master_out="".join(seen))
    if serve.poll() is None:
        serve.send_signal(signal.SIGTERM)
    try:
        serve.wait(30)
    except subprocess.TimeoutExpired:
        serve.kill()
        serve.wait()
    reader.join(5)
    out.update(serve_rc=serve.returncode, serve_out="".join(serve_out))
    return out


if __name__ == "__main__":
    print(json.dumps(_main(json.loads(sys.argv[1]))), flush=True)
