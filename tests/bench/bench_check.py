"""Benchmark (not a test): the whole maintenance check on the simulated plant.

Prints and writes JSON:
* plant_s: the plant alone replaying the setpoints of a whole check (one step() call per 2 ms sample)
* loop_s: the check loop (sequence core + supervisor + CSV logging + plant), as `emacheck simulate`
* analysis_s: reading signals.csv back, calibration and BLFmaint on three channels
* report_s: the HTML report with its figures

Usage: python tests/bench/bench_check.py [--json bench_check.json] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (conftest, support)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default="bench_check.json")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from conftest import simulate_run

    from hil.analysis.maint import analyze_signals, result_dict
    from hil.canopen.process import DriveMode, Setpoint
    from hil.profile.load import load_actuation, load_check, load_simrig
    from hil.record.runfolder import read_signals
    from hil.report.maint import write_report
    from sim.plant import RigPlant

    act = load_actuation()
    chk = load_check(None, act)
    sim = load_simrig()
    # warm up the JIT (compiled once, cached on disk)
    off = Setpoint(DriveMode.DISABLED, 0)
    RigPlant(sim.params, np.random.default_rng(0)).step(off, off)
    loop, plant_t, ana, rep = [], [], [], []
    with tempfile.TemporaryDirectory() as td:
        for k in range(args.repeat):
            out = Path(td) / f"r{k}"
            t0 = time.perf_counter()
            outcome, truth = simulate_run(out, act, chk, sim, sim.seed + k)
            loop.append(time.perf_counter() - t0)
            sig = read_signals(out / "signals.csv")
            # plant alone: replay the recorded setpoints open loop
            sps = [(Setpoint(DriveMode(int(m1)), v1), Setpoint(DriveMode(int(m2)), v2))
                   for m1, v1, m2, v2 in zip(sig.mode1, sig.sp1, sig.mode2, sig.sp2, strict=True)]
            plant = RigPlant(sim.params, np.random.default_rng(1))
            t0 = time.perf_counter()
            for a, b in sps:
                plant.step(a, b)
            plant_t.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            sig = read_signals(out / "signals.csv")
            an = analyze_signals(sig, act)
            res = result_dict(an, act, truth)
            ana.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            write_report(out / "report.html", sig, an, res, act, None)
            rep.append(time.perf_counter() - t0)
    fig = {
        "simulated_s": round(outcome.duration_s, 1),
        "samples": outcome.samples,
        "plant_s": round(statistics.median(plant_t), 3),
        "loop_s": round(statistics.median(loop), 3),
        "analysis_s": round(statistics.median(ana), 3),
        "report_s": round(statistics.median(rep), 3),
        "repeat": args.repeat,
    }
    for k, v in fig.items():
        print(f"{k:>12}: {v}")
    Path(args.json).write_text(json.dumps(fig, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
