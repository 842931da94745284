"""Benchmark (not a test): where the default dry-run's time goes, phase by phase, in one fresh process.

Runs ``emacheck dry-run --quiet`` in this process once and prints the CPU time (``time.process_time``,
which another job on a shared machine changes less than wall time) and the wall time of each phase:

* ``start``: the interpreter's imports up to the command line (``hil.cli``);
* ``setup``: from the command line to the first SYNC (profiles, the EDS, the rig plan, the simulated
  drives and their imports: numba's plant kernel);
* ``loop``: the check over CANopen (``hil.cli.check.canopen_check``);
* ``analysis``: reading signals.csv back and the analysis, with their imports (scipy.signal, python-control);
* ``report``: the HTML report with its figures (matplotlib); 0 where the dry-run's analysis fork
  (``hil/cli/analysis_fork.py``) drew it: ``analysis`` is then the writing of its answer;
* ``rest``: what is left (with the fork: the wait for its answer; result.json, the console);
* ``exit``: from ``main()`` returning to the end of the process (wall; the tree's own entry point ends it).

Usage: python tests/bench/bench_dry_run_phases.py [--repeat N] [--old DIR]  (each repetition a fresh
process; ``--old``: another checkout run in turn with this one, old, new, old, ...)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_CHILD = r"""
import contextlib, functools, io, json, sys, tempfile, time
c0, w0 = time.process_time(), time.perf_counter()
import hil.cli
import hil.cli.check as ck
import hil.cli.dry_run as dr
marks = {"start": (time.process_time(), time.perf_counter())}
spent = {}

def timed(mod, name, phase):
    f = getattr(mod, name)
    @functools.wraps(f)
    def w(*a, **k):
        c, t = time.process_time(), time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            pc, pw = spent.get(phase, (0.0, 0.0))
            spent[phase] = (pc + time.process_time() - c, pw + time.perf_counter() - t)
            if phase == "loop":
                marks.setdefault("loop_start", (c, t))
    setattr(mod, name, w)

timed(dr, "canopen_check", "loop")
_analyze = ck.analyze_and_report

def analyze(*a, **k):  # the report module patched at the call (its import counted with the analysis)
    c, t = time.process_time(), time.perf_counter()
    if k.get("prepared") is not None:  # the analysis fork's answer, only written here: nothing to patch
        try:
            return _analyze(*a, **k)
        finally:
            spent["analysis+report"] = (time.process_time() - c, time.perf_counter() - t)
    import hil.report.maint as rm
    _write = rm.write_report

    def report(*ra, **rk):
        rc, rt = time.process_time(), time.perf_counter()
        try:
            return _write(*ra, **rk)
        finally:
            spent["report"] = (time.process_time() - rc, time.perf_counter() - rt)

    rm.write_report = report
    try:
        return _analyze(*a, **k)
    finally:
        rm.write_report = _write
        spent["analysis+report"] = (time.process_time() - c, time.perf_counter() - t)

ck.analyze_and_report = analyze
out = tempfile.mkdtemp(prefix="phases-") + "/run"
_main = hil.cli.main


def main(argv=None):  # the command, then the phases printed; the process then ends as the tree's entry ends it
    with contextlib.redirect_stdout(io.StringIO()):
        rc = _main(["dry-run", "--out", out, "--quiet"])
    c1, w1 = time.process_time(), time.perf_counter()
    phases(rc, c1, w1)
    return rc


def phases(rc, c1, w1):
    cs, ws = marks["start"]
    cl, wl = marks["loop_start"]
    ar = spent["analysis+report"]
    rp = spent.get("report", (0.0, 0.0))  # (0: the report was drawn in the analysis fork, hil/cli/analysis_fork.py)
    phases = {"start": (cs - c0, ws - w0), "setup": (cl - cs, wl - ws), "loop": spent["loop"],
              "analysis": (ar[0] - rp[0], ar[1] - rp[1]), "report": rp}
    phases["rest"] = (c1 - c0 - sum(p[0] for p in phases.values()), w1 - w0 - sum(p[1] for p in phases.values()))
    phases["whole"] = (c1 - c0, w1 - w0)
    print(json.dumps({"exit": rc, "phases": phases, "main_returned": time.time()}), flush=True)


hil.cli.main = main
if hasattr(hil.cli, "entry"):  # emacheck's entry point (since 2026-11-27: the heap frozen before the exit)
    hil.cli.entry()
sys.exit(main())
"""


def _run(tree: Path) -> dict:
    """One dry-run in a fresh process in ``tree``: its phases, and ``exit`` (wall only: from ``main()``
    returning to the process's end, measured here)."""
    p = subprocess.run([sys.executable, "-c", _CHILD], cwd=tree, capture_output=True, text=True, check=True,
                       env={**os.environ, "PYTHONPATH": str(tree)})
    end = time.time()
    got = json.loads(p.stdout.strip().splitlines()[-1])
    return {**got["phases"], "exit": (0.0, end - got["main_returned"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--old", type=Path, metavar="DIR", help="another checkout, run in turn with this one")
    args = ap.parse_args()
    trees = {"this tree": ROOT} if args.old is None else {"old": args.old.resolve(), "new": ROOT}
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    for _ in range(args.repeat):
        for name, tree in trees.items():
            runs[name].append(_run(tree))
    for name, rs in runs.items():
        print(f"{name} ({trees[name]}): {'phase':10s} {'CPU s (each run)':>28s} {'wall s (each run)':>28s}"
              f" {'median wall':>12s}")
        for phase in rs[0]:
            cpu = " ".join(f"{r[phase][0]:6.2f}" for r in rs)
            wall = " ".join(f"{r[phase][1]:6.2f}" for r in rs)
            print(f"  {phase:10s} {cpu:>28s} {wall:>28s} {statistics.median(r[phase][1] for r in rs):12.3f}")
    load = Path("/proc/loadavg").read_text().split()[0]
    print(f"(load average {load} at the end; {time.strftime('%Y-%m-%d %H:%M')})")


if __name__ == "__main__":
    main()
