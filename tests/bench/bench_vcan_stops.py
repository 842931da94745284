"""Benchmark (not a test): the vcan stage's whole check inside user-mode-linux, the machine stopped now and then.

Runs ``tests/vcan/vcan_check_traffic.py -k whole_check`` (sim-serve and run over vcan0, the stage's
profiles) inside user-mode-linux as the stage does (``tests/vcan/vcan_stage.run_in_uml``), and, from
``--start`` s after the guest's vcan0 is up, ``--count`` times every ``--every`` s, stops the whole machine
for ``--stop-ms``: one SCHED_FIFO 99 process per CPU spins for that long, so nothing else runs (the guest,
its processes and its clock's interrupts included), as when a host stops a VM's CPUs. ``--count 0``: no
stops. Prints the inner test's result and, from the run's meta.json, the master's page faults in the cyclic
loop, its largest lag behind the bus and its stalls.

Needs root (SCHED_FIFO 99), user-mode-linux with CAN modules and can-utils (as the stage).

Usage: python tests/bench/bench_vcan_stops.py WORKDIR [--stop-ms 50] [--start 35] [--every 8] [--count 5]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "tests" / "vcan"))
import vcan_stage  # noqa: E402

SPIN = ("import os, sys, time\nos.sched_setaffinity(0, {int(sys.argv[1])})\nsys.stdin.readline()\n"
        "os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))\nt = time.monotonic() + float(sys.argv[2])\n"
        "while time.monotonic() < t:\n    pass\n")


def stop_machine(seconds: float) -> None:
    """Every CPU busy at SCHED_FIFO 99 for ``seconds`` (the spinners start first, then spin together)."""
    spin = [subprocess.Popen([sys.executable, "-c", SPIN, str(cpu), str(seconds)], stdin=subprocess.PIPE, text=True)
            for cpu in sorted(os.sched_getaffinity(0))]
    time.sleep(0.3)  # their interpreters started, at normal priority
    for p in spin:
        p.stdin.write("go\n")
        p.stdin.flush()
    for p in spin:
        p.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--stop-ms", type=float, default=50.0)
    ap.add_argument("--start", type=float, default=35.0, help="s after vcan0 is up (processes start in ~30 s)")
    ap.add_argument("--every", type=float, default=8.0)
    ap.add_argument("--count", type=int, default=5)
    a = ap.parse_args(argv)
    work = a.workdir.resolve()
    if work.exists():
        ap.error(f"{work} exists: name a new folder (nothing is overwritten)")
    inner = "/dev/shm/emacheck-vcan"
    cmd = [sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", "-o", "addopts=-ra",
           "tests/vcan/vcan_check_traffic.py", "-k", "whole_check", "--basetemp", inner]
    full = ["sh", "-c", f"{shlex.join(cmd)}; rc=$?; cp -a {inner} {shlex.quote(str(work / 'keep'))}; exit $rc"]
    stops: list[float] = []

    def stopper() -> None:
        booted = work / "uml" / "booted"
        while not booted.exists():
            time.sleep(0.05)
        t0 = time.monotonic()
        for i in range(a.count):
            while time.monotonic() - t0 < a.start + i * a.every:
                time.sleep(0.01)
            stop_machine(a.stop_ms / 1e3)
            stops.append(round(time.monotonic() - t0, 1))

    threading.Thread(target=stopper, daemon=True).start()
    res = vcan_stage.run_in_uml(full, work / "uml", 600.0, cwd=ROOT)
    tail = [ln for ln in res.output.splitlines() if " passed" in ln or " failed" in ln]
    print(f"inner exit {res.status}, {res.wall_s:.1f} s in UML; {tail[-1] if tail else res.output[-2000:]}")
    print(f"machine stopped {a.stop_ms:g} ms at {stops} s after vcan0 was up")
    metas = sorted((work / "keep").glob("*/run/meta.json"))
    if metas:
        m = json.loads(metas[0].read_text())
        can, st = m.get("can", {}), m.get("stalls", {})
        print(f"run: {m.get('status')}; loop page faults {can.get('loop_page_faults')} (whole run "
              f"{can.get('page_faults')}); max lag {can.get('max_lag_ms')} ms; stalls {st.get('count')}, "
              f"longest {st.get('longest_ms')} ms (limit {st.get('limit_ms')} ms)")
    return 0 if res.status == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
