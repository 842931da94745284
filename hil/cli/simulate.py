"""``emacheck simulate``: the check against the plant directly (no CAN), then analysis and report."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rich.console import Console

from hil.cli.check import LiveProgress, result_after, truth_dict
from hil.cli.common import add_parser, add_profile_args, out_dir
from hil.profiles import load_actuation, load_check, load_simrig, snapshot


def cmd_simulate(args: argparse.Namespace) -> int:
    """``emacheck simulate``: the check on the plant, then analysis and report."""
    import numpy as np

    from hil.runner import PlantLink, run_check, start_meta
    from sim.plant import RigPlant
    from sim.truth import rig_truth

    console = Console(stderr=False)
    act = load_actuation(args.profile)
    check = load_check(args.check, act)
    simrig = load_simrig(args.sim)
    seed = simrig.seed if args.seed is None else args.seed
    out = out_dir(args, "simulate")
    rng = np.random.default_rng(seed)
    plant = RigPlant(simrig.params, rng)
    truth = truth_dict(rig_truth(simrig.params))
    meta = start_meta(act, check, {"mode": "simulate", "seed": seed,
                                   "simrig": snapshot(simrig.params), "truth": truth})
    console.print(f"emacheck simulate: seed {seed}, run folder {out}")
    t0 = time.perf_counter()
    with LiveProgress(console, 0.0, not args.quiet) as live:
        outcome = run_check(PlantLink(plant), act, check, out, meta, on_cycle=live)
    wall = time.perf_counter() - t0
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s simulated "
                  f"({outcome.samples} samples) in {wall:.2f} s wall")
    return result_after(out, act, truth, meta, outcome, console)


def register(sub) -> None:
    p = add_parser(sub, "simulate", handler=cmd_simulate,
                   help="run the check on the simulated rig, no CAN in between",
                   description="Run the whole check against the simulated plant directly "
                               "(no CANopen), then analyse it and write the run folder and report.")
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-simulate)")
    add_profile_args(p, sim=True)
    p.add_argument("--quiet", action="store_true", help="no progress display")
