"""``emacheck simulate``: the check against the plant directly (no CAN), then analysis and report."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hil.cli.args import add_history_args, add_parser, add_profile_args, add_trace_args
from hil.cli.check import refuse_shared_serial, simulated_identity, truth_dict, worn_simrig
from hil.cli.console import check_progress, make_console
from hil.cli.history_glue import installation, record_history, refuse_foreign_history
from hil.cli.result import result_after
from hil.profile.load import load_actuation, load_check, load_simrig, snapshot
from hil.record.outputs import file_hashes, out_dir
from hil.record.runfolder import MetaWriter, open_new
from hil.record.runrecord import Attribution, RunMode, RunStatus, start_record


def cmd_simulate(args: argparse.Namespace) -> int:
    """``emacheck simulate``: the check on the plant, then analysis and report; with ``--scenario``
    a normal-operation recording for ``emacheck serv`` instead."""
    if args.scenario is not None:
        return simulate_scenario(args)
    import numpy as np

    from hil.check.runner import PlantLink, run_check
    from sim.plant import RigPlant
    from sim.truth import rig_truth

    console = make_console()
    act = load_actuation(args.profile)
    check = load_check(args.check, act, args.profile)
    simrig = load_simrig(args.sim)
    refuse_shared_serial(act, simrig, args.sim)
    refuse_foreign_history(args, act, simulated=True)
    seed = simrig.seed if args.seed is None else args.seed
    out = out_dir(args.out, "simulate")
    simrig, wear = worn_simrig(simrig, args.flight_hours, seed)
    rng = np.random.default_rng(seed)
    plant = RigPlant(simrig.params, rng)
    truth = truth_dict(rig_truth(simrig.params))
    # identity: as the simulated drives would report it (there are none without CAN)
    meta = MetaWriter(out, start_record(act, check, mode=RunMode.SIMULATE, seed=seed,
                                        simrig=snapshot(simrig.params), truth=truth,
                                        attribution=Attribution(args.operator, args.work_order),
                                        installation=installation(args, act),
                                        files_sha256=file_hashes(actuation=args.profile, check=args.check,
                                                                 simrig=args.sim),
                                        identity=simulated_identity(act, simrig), wear=wear), new=True)
    console.print(f"emacheck simulate: seed {seed}, run folder {out}")
    t0 = time.perf_counter()
    with check_progress(console, args.quiet) as live:
        outcome = run_check(PlantLink(plant), act, check, meta, on_cycle=live if live.enabled else None)
    wall = time.perf_counter() - t0
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s simulated "
                  f"({outcome.samples} samples) in {wall:.2f} s wall")
    rc = result_after(out, act, truth, meta, outcome, console)
    record_history(console, args, act, out / "result.json", run_folder=out)
    return rc


def simulate_scenario(args: argparse.Namespace) -> int:
    """A normal-operation recording of scenario ``--scenario`` (sim.scenarios), preceded by the two LVDT
    calibration sweeps under opposing force, written as a run folder (signals.csv with a step column,
    meta.json with the simulator's truth) that ``emacheck serv`` reads as it is."""
    import numpy as np

    from sim.operation import simulate_calibration_sweep, simulate_operation
    from sim.scenarios import SCENARIOS, scenario_profile

    console = make_console()
    act = load_actuation(args.profile)
    check = load_check(args.check, act, args.profile)
    simrig = load_simrig(args.sim)
    refuse_shared_serial(act, simrig, args.sim)
    seed = simrig.seed if args.seed is None else args.seed
    out = out_dir(args.out, f"simulate-{args.scenario}")
    rng = np.random.default_rng(seed)
    params = simrig.params
    console.print(f"emacheck simulate --scenario {args.scenario}: {SCENARIOS[args.scenario]}; seed {seed}")
    sw = [simulate_calibration_sweep(params, rng, ema=k, amplitude_mm=check.calibration.sweep_amplitude_mm,
                                     speed_mm_per_s=check.calibration.sweep_speed_mm_per_s,
                                     opposing_force_N=check.calibration.opposing_force_N) for k in (1, 2)]
    rec = simulate_operation(params, scenario_profile(args.scenario, params, rng), rng)
    parts = [(sw[0], "cal1_sweep"), (sw[1], "cal2_sweep"), (rec, args.scenario)]
    cols = {c: np.concatenate([getattr(x, c) for x, _ in parts])
            for c in ("phi1_rad", "phi2_rad", "s1_mm", "s2_mm", "F1_N", "F2_N")}
    steps = np.concatenate([np.full(x.t_s.size, name, dtype=object) for x, name in parts])
    T = params.sample_period_s
    t = (np.arange(steps.size) + 1) * T
    with open_new(out / "signals.csv") as fh:
        fh.write("t,phi1,phi2,s1,s2,F1,F2,step\n")
        for k in range(steps.size):
            fh.write(f"{t[k]:.4f},{cols['phi1_rad'][k]:.7f},{cols['phi2_rad'][k]:.7f},{cols['s1_mm'][k]:.6f},"
                     f"{cols['s2_mm'][k]:.6f},{cols['F1_N'][k]:.3f},{cols['F2_N'][k]:.3f},{steps[k]}\n")
    truth = truth_dict(rec.truth)
    truth["traversed"] = {k: bool(v) for k, v in rec.traversed.items()}
    # identity: as the simulated drives would report it (`serv` of this recording traces it)
    MetaWriter(out, start_record(act, check, mode=RunMode.SIMULATE_SCENARIO, scenario=args.scenario, seed=seed,
                                 simrig=snapshot(params), truth=truth, status=RunStatus.DONE,
                                 attribution=Attribution(args.operator, args.work_order),
                                 files_sha256=file_hashes(actuation=args.profile, check=args.check,
                                                          simrig=args.sim),
                                 identity=simulated_identity(act, simrig)), new=True).write()
    crossed = ", ".join(k for k, v in rec.traversed.items() if v) or "none"
    console.print(f"{steps.size} samples ({steps.size * T:.1f} s: two calibration sweeps, then the scenario); "
                  f"backlash crossed in truth: {crossed}")
    console.print(f"recording in {out}; next: emacheck serv {out}")
    return 0


def register(sub) -> None:
    p = add_parser(sub, "simulate", handler=cmd_simulate,
                   help="run the check on the simulated rig, no CAN in between",
                   description="Run the whole check against the simulated plant directly "
                               "(no CANopen), then analyse it and write the run folder and report.")
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-simulate)")
    add_profile_args(p, sim=True, eds=False)
    add_trace_args(p)
    add_history_args(p, simulated=True)
    p.add_argument("--quiet", action="store_true", help="no progress display")
    from sim.scenarios import SCENARIOS

    p.add_argument("--scenario", choices=tuple(SCENARIOS), metavar="NAME",
                   help="instead of the check: a normal-operation recording for `emacheck serv`, after the two "
                        "LVDT calibration sweeps: " + "; ".join(f"{k}: {v}" for k, v in SCENARIOS.items()))
