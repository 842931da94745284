"""Benchmark (not a test): the whole dry-run over CANopen, simulated versus wall seconds.

Runs `emacheck dry-run` (master + two simulated CiA 402 drives on the in-process
virtual bus, synchronous pump, CSV and CAN logging) and reports the check loop's
wall time against the simulated duration (target: at most a tenth), plus the
analysis and report time. Prints and writes JSON.

Usage: python tests/bench/bench_dry_run.py [--json bench_dry_run.json] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository (hil, blf, sim)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default="bench_dry_run.json")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    from hil.cli import main as cli

    loop, total, sim = [], [], 0.0
    frames = 0
    with tempfile.TemporaryDirectory() as td:
        for k in range(args.repeat):
            out = Path(td) / f"r{k}"
            t0 = time.perf_counter()
            rc = cli(["dry-run", "--out", str(out), "--quiet"])
            total.append(time.perf_counter() - t0)
            meta = json.loads((out / "meta.json").read_text())
            assert rc == 0, rc
            loop.append(meta["wall_s"])
            sim = meta["duration_s"]
            frames = meta["can"]["frames_logged"]
    fig = {
        "simulated_s": round(sim, 1),
        "check_wall_s": round(statistics.median(loop), 2),
        "ratio_sim_to_wall": round(sim / statistics.median(loop), 2),
        "per_cycle_us": round(1e6 * statistics.median(loop) / (sim / 0.002), 1),
        "command_total_s": round(statistics.median(total), 2),
        "can_frames": frames,
        "repeat": args.repeat,
    }
    for k, v in fig.items():
        print(f"{k:>18}: {v}")
    Path(args.json).write_text(json.dumps(fig, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
