"""``emacheck dry-run``: the check over CANopen against two simulated drives on an in-process virtual bus."""

from __future__ import annotations

import argparse
import dataclasses
import gc
import math
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console

from hil.cli.analysis_fork import AnalysisFork
from hil.cli.args import add_history_args, add_parser, add_profile_args, add_trace_args
from hil.cli.check import (
    canopen_check,
    master_setup,
    record_can_stats,
    rig_hashes,
    rig_meta,
    rig_nodes_text,
    truth_dict,
    worn_simrig,
)
from hil.cli.console import make_console
from hil.cli.history_glue import installation, record_history, refuse_foreign_history
from hil.cli.result import result_after
from hil.master.stalls import EVERY_S_MAX, EVERY_S_MIN, STALL_MS_MAX
from hil.profile.load import load_actuation, load_check, load_simrig, snapshot
from hil.record.outputs import check_new_run_folder, file_hashes, out_dir
from hil.record.runfolder import MetaWriter
from hil.record.runrecord import Attribution, BusLoad, RunMode, start_record


@dataclass
class DryRun:
    """What :func:`dry_run` leaves behind: the exit status, the outcome and the live objects
    (the simulated pair with its fault injector and truth trace, the master, the link)."""

    exit_code: int
    outcome: object
    out: Path
    injector: object
    master: object
    link: object
    wall_s: float


def dry_run(act, check, simrig, out: Path, *, seed: int | None = None, faults=None, realtime: bool = False,
            quiet: bool = True, console: Console | None = None, profile_path=None,
            trace: dict | None = None, eds=None, rig=None, stall: tuple[float, float] | None = None,
            sim_rig=None) -> DryRun:
    """The check over CANopen against two simulated drives on an in-process virtual bus.

    ``faults`` (a :class:`sim.faults.Fault` sequence) replaces the simulated-rig profile's
    ``[[faults]]``. The profiles are validated by the caller; nothing is sent on the bus before
    the EDS and the bus load are checked here. ``trace`` (run record fields: ``attribution``,
    ``installation``, ``files_sha256``, ``wear``) goes into meta.json and from there into result.json.
    ``rig``: the planned rig (:func:`hil.cli.check.master_setup` of the profile and ``eds``) if the caller
    has planned it already. ``stall``: (ms, mean interval s) of the master's injected stalls
    (:class:`hil.master.stalls.MasterStalls`, drawn from ``[seed, 37]``; meta.json ``stalls.injected``).
    ``sim_rig``: the planned rig the simulated nodes are built as (default ``rig``: the profile under test); a
    rig of another profile shows that profile's mistakes (a scaling the rig's wiring does not have).
    """
    console = console or make_console(quiet=quiet)
    rig = rig if rig is not None else master_setup(act, profile_path, eds, check)
    fork = AnalysisFork(act, out)  # imports the analysis on the other core while the loop runs
    try:
        return _dry_run(act, check, simrig, out, fork, seed=seed, faults=faults, realtime=realtime, quiet=quiet,
                        console=console, rig=rig, trace=trace, stall=stall, sim_rig=sim_rig or rig)
    finally:
        fork.close()


def _dry_run(act, check, simrig, out: Path, fork, *, seed, faults, realtime, quiet, console, rig, trace,
             stall, sim_rig) -> DryRun:
    """:func:`dry_run` with its console, planned rig and :class:`~hil.cli.analysis_fork.AnalysisFork`."""
    import numpy as np

    from hil.master.core import MasterCore
    from hil.master.link import CanopenLink
    from hil.master.stalls import MasterStalls
    from hil.record.canlog import CanLogWriter
    from hil.sim_server import simulated_rig
    from hil.transport import InProcessTransport
    from sim.truth import rig_truth

    load = rig.plan.load
    seed = simrig.seed if seed is None else seed
    faults = tuple(simrig.faults if faults is None else faults)
    out.mkdir(parents=True, exist_ok=True)
    injector = simulated_rig(simrig, sim_rig, faults, seed=seed, record_truth=bool(faults) or stall is not None)
    truth = truth_dict(rig_truth(simrig.params))
    record = start_record(act, check, mode=RunMode.DRY_RUN, seed=seed, realtime=bool(realtime),
                          simrig=snapshot(simrig.params), truth=truth, faults=tuple(snapshot(f) for f in faults),
                          bus_load=BusLoad(load.load_nominal, load.load_worst), **rig_meta(rig), **(trace or {}))
    meta = MetaWriter(out, dataclasses.replace(record, files_sha256={**(record.files_sha256 or {}),
                                                                     **rig_hashes(rig)}), new=True)
    meta.write()  # the run folder says "running" from the start
    stalls = MasterStalls(*stall, rng=np.random.default_rng([seed, 37])) if stall is not None else None
    transport = InProcessTransport(injector, act.timing.sync_period_s, realtime=realtime, stalls=stalls)
    master = MasterCore(act, rig.plan, forces=(check.calibration.opposing_force_N, check.safety.max_force_N),
                        safety=check.safety)
    log = CanLogWriter(out / "can.log", channel="vcan-dry-run")
    link = CanopenLink(master, transport, log, max_missing_cycles=check.safety.max_stale_cycles,
                       max_lag_s=check.safety.max_lag_s, safety=check.safety)
    console.print(f"emacheck dry-run: simulated {rig_nodes_text(rig)} on an "
                  f"in-process virtual CAN bus, seed {seed}, bus load {load.load_worst:.1%} worst case"
                  + (f", {len(faults)} injected fault(s)" if faults else "")
                  + (f", the master stalling {stall[0]:g} ms every {stall[1]:g} s on average" if stall else "")
                  + f"; run folder {out}")
    gc_was_on = gc.isenabled()
    gc.disable()  # as run's loop: reference counting frees the loop's objects, no collector passes over the heap
    try:
        outcome, wall = canopen_check(console, act, check, link, meta, quiet)
    finally:
        if gc_was_on:
            gc.enable()
        transport.close()
    record_can_stats(meta, wall, log, master)
    if stalls is not None and meta.record.stalls is not None:  # the injection beside what the master saw
        meta.write(dataclasses.replace(meta.record, stalls=dataclasses.replace(meta.record.stalls,
                                                                               injected=stalls.as_json())))
    st = meta.record.stalls
    if st is not None and st.count:
        console.print(f"master stalls: {st.count}, the longest {st.longest_ms:g} ms (limit {st.limit_ms:g} ms, "
                      f"{st.limit})")
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s simulated in {wall:.2f} s wall "
                  f"({outcome.duration_s / max(wall, 1e-9):.1f}x real time); {log.frames} CAN frames logged")
    rc = result_after(out, act, truth, meta, outcome, console, prepare=lambda rec: fork.analysed(rec, truth))
    return DryRun(rc, outcome, out, injector, master, link, wall)


def cmd_dry_run(args: argparse.Namespace) -> int:
    """``emacheck dry-run``: the check over CANopen against two simulated drives (virtual bus)."""
    console = make_console()
    if args.master_stall_ms is not None and args.master_stall_ms / 1000.0 >= args.master_stall_every_s / 2.0:
        from hil.errors import ArgumentsError
        raise ArgumentsError(f"--master-stall-ms {args.master_stall_ms:g} is not shorter than half of "
                             f"--master-stall-every-s {args.master_stall_every_s:g} s: two stalls would run "
                             "into each other")
    # every profile is validated before anything is sent on the bus
    act = load_actuation(args.profile)
    check = load_check(args.check, act, args.profile)
    simrig = load_simrig(args.sim)
    refuse_foreign_history(args, act, simulated=True)
    check_new_run_folder(args.out)
    rig = master_setup(act, args.profile, args.eds, check)  # a bad EDS, map or sensor: refused before a run folder
    sim_rig, own = rig, None
    if args.sim is not None and simrig.actuation is not None:  # built as the simulated rig's own profile says
        from hil.cli.commission_setup import simulated_rig_profile

        sim_rig, own = simulated_rig_profile(args, args.profile, rig, simrig)
    out = out_dir(args.out, "dry-run")
    simrig, wear = worn_simrig(simrig, args.flight_hours, simrig.seed if args.seed is None else args.seed)
    trace = {"attribution": Attribution(args.operator, args.work_order), "installation": installation(args, act),
             "files_sha256": file_hashes(actuation=args.profile, check=args.check, simrig=args.sim,
                                         **({"simulated_rig_actuation": own} if own is not None else {})),
             "wear": wear}
    stall = (args.master_stall_ms, args.master_stall_every_s) if args.master_stall_ms is not None else None
    rc = dry_run(act, check, simrig, out, seed=args.seed, realtime=args.realtime, quiet=args.quiet,
                 console=console, profile_path=args.profile, trace=trace, eds=args.eds, rig=rig,
                 stall=stall, sim_rig=sim_rig).exit_code
    record_history(console, args, act, out / "result.json", run_folder=out)
    return rc


def register(sub) -> None:
    p = add_parser(sub, "dry-run", handler=cmd_dry_run,
                   help="the check over CANopen against two simulated drives (the main job)",
                   description="Run the complete check through the CANopen master against two simulated "
                               "CiA 402 drives on an in-process virtual CAN bus, log every frame, analyse "
                               "and report, with the simulator's truth beside the measurement.")
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-dry-run)")
    add_profile_args(p, sim=True, sim_nodes=True)
    add_trace_args(p)
    add_history_args(p, simulated=True)
    p.add_argument("--realtime", action="store_true",
                   help="pace SYNC at the SYNC period (default: as fast as possible)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--master-stall-ms", type=_stall_ms, metavar="MS",
                   help=f"make the master stall for MS ms (above 0, at most {STALL_MS_MAX:g}) now and then, in "
                        "simulated time: the simulated drives run on, SYNC keeps its period, their frames wait "
                        "for the master, stamped; a stall within the freshness limit (safety.max_stale_ms where "
                        "both drives keep their limits) is tolerated and recorded (meta.json stalls), a longer "
                        "one stops the check; deterministic for --seed")
    p.add_argument("--master-stall-every-s", type=_stall_every_s, metavar="S", default=5.0,
                   help=f"the mean interval between two stalls [s] ({EVERY_S_MIN:g} to {EVERY_S_MAX:g}, more than "
                        "twice the stall; each interval drawn uniformly from S/2 to 3S/2; default 5)")


def _number_in(what: str, lo: float, hi: float, lo_open: bool):
    """argparse type of a finite number from ``lo`` (excluded where ``lo_open``) to ``hi``, named ``what``."""
    span = f"{'above' if lo_open else 'from'} {lo:g} to {hi:g}"

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number ({what}): {text!r}") from None
        if not math.isfinite(v) or v > hi or v < lo or (lo_open and v == lo):
            raise argparse.ArgumentTypeError(f"{text}: {what} is a number {span}")
        return v

    parse.__name__ = what
    return parse


_stall_ms = _number_in("a stall of the master [ms]", 0.0, STALL_MS_MAX, lo_open=True)
_stall_every_s = _number_in("the mean interval between stalls [s]", EVERY_S_MIN, EVERY_S_MAX, lo_open=False)
