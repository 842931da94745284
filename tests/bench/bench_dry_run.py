"""Benchmark (not a test): the whole dry-run over CANopen, simulated versus wall seconds.

Runs `emacheck dry-run` (master + two simulated CiA 402 drives on the in-process
bus, synchronous pump, CSV and CAN logging) and reports the check loop's wall
time against the simulated duration, plus the whole command's time. Prints and
writes JSON.

Without ``--old`` the command runs in this process ``--repeat`` times. With
``--old DIR`` (another checkout, e.g. ``git worktree add /tmp/old-main main``)
each repetition runs ``python -m hil dry-run`` in a fresh process in that tree
and in this one, interleaved (old, new, old, new, ...: a shared machine's load
falls on both alike), and reports per tree the medians of the whole command's
wall time, the check loop's wall time (meta.json ``wall_s``) and the process's
CPU time (user + system), and checks that both trees wrote the same
signals.csv and can.log.

Usage: python tests/bench/bench_dry_run.py [--json bench_dry_run.json] [--repeat 2] [--old DIR]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # the repository (hil, blf, sim)


def _in_process(repeat: int) -> dict:
    from hil.cli import main as cli

    loop, total, sim = [], [], 0.0
    frames = 0
    with tempfile.TemporaryDirectory() as td:
        for k in range(repeat):
            out = Path(td) / f"r{k}"
            t0 = time.perf_counter()
            rc = cli(["dry-run", "--out", str(out), "--quiet"])
            total.append(time.perf_counter() - t0)
            meta = json.loads((out / "meta.json").read_text())
            assert rc == 0, rc
            loop.append(meta["wall_s"])
            sim = meta["duration_s"]
            frames = meta["can"]["frames_logged"]
    return {
        "simulated_s": round(sim, 1),
        "check_wall_s": round(statistics.median(loop), 2),
        "ratio_sim_to_wall": round(sim / statistics.median(loop), 2),
        "per_cycle_us": round(1e6 * statistics.median(loop) / (sim / 0.002), 1),
        "command_total_s": round(statistics.median(total), 2),
        "can_frames": frames,
        "repeat": repeat,
    }


def _one(tree: Path, out: Path) -> dict:
    """``python -m hil dry-run`` in ``tree``, in a process of its own: wall, loop, CPU, file hashes."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "hil", "dry-run", "--out", str(out), "--quiet"], cwd=tree,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                       env={**os.environ, "PYTHONPATH": str(tree)})
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"{tree}: dry-run exit {r.returncode}\n{r.stderr[-2000:]}")
    meta = json.loads((out / "meta.json").read_text())
    return {"total_s": wall, "loop_s": meta["wall_s"], "sim_s": meta["duration_s"],
            "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "signals_sha256": hashlib.sha256((out / "signals.csv").read_bytes()).hexdigest(),
            "can_log_sha256": hashlib.sha256((out / "can.log").read_bytes()).hexdigest()}


def _old_vs_new(old: Path, repeat: int) -> dict:
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory() as td:
        for k in range(repeat):
            for name, tree in (("old", old), ("new", ROOT)):
                r = _one(tree, Path(td) / f"{name}{k}")
                runs[name].append(r)
                print(f"{name} {k + 1}/{repeat}: command {r['total_s']:.2f} s, loop {r['loop_s']:.2f} s, "
                      f"CPU {r['cpu_s']:.2f} s", flush=True)
    fig = {"repeat": repeat, "old_tree": str(old), "new_tree": str(ROOT)}
    for name, rs in runs.items():
        sim = rs[0]["sim_s"]
        med = {key: statistics.median(r[key] for r in rs) for key in ("total_s", "loop_s", "cpu_s")}
        fig[name] = {
            "simulated_s": round(sim, 1),
            "command_total_s": round(med["total_s"], 2),
            "command_x_real_time": round(sim / med["total_s"], 1),
            "check_loop_s": round(med["loop_s"], 2),
            "check_loop_x_real_time": round(sim / med["loop_s"], 1),
            "command_cpu_s": round(med["cpu_s"], 2),
            "runs": rs,
        }
    fig["same_signals_csv"] = len({r["signals_sha256"] for rs in runs.values() for r in rs}) == 1
    fig["same_can_log"] = len({r["can_log_sha256"] for rs in runs.values() for r in rs}) == 1
    return fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default="bench_dry_run.json")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--old", type=Path, metavar="DIR", help="another checkout to run interleaved with this one")
    args = ap.parse_args()
    if args.old is None:
        fig = _in_process(args.repeat)
        for k, v in fig.items():
            print(f"{k:>18}: {v}")
    else:
        fig = _old_vs_new(args.old.resolve(), args.repeat)
        for name in ("old", "new"):
            print(name, {k: v for k, v in fig[name].items() if k != "runs"})
        print("same signals.csv:", fig["same_signals_csv"], " same can.log:", fig["same_can_log"])
    Path(args.json).write_text(json.dumps(fig, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
