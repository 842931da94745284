"""``emacheck run``: the check on real drives (the dry-run's code path, wall-clock SYNC)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.cli.args import (
    ExitCode,
    add_bus_args,
    add_cpu_latency_arg,
    add_history_args,
    add_parser,
    add_profile_args,
    add_trace_args,
    rt_priority_arg,
)
from hil.cli.bus import multicast_hops_for, open_bus
from hil.cli.check import (
    canopen_check,
    master_setup,
    page_faults,
    record_can_stats,
    rig_hashes,
    rig_meta,
    rig_nodes_text,
)
from hil.cli.console import make_console
from hil.cli.history_glue import installation, record_history, refuse_foreign_history
from hil.cli.result import result_after
from hil.profile.load import load_actuation, load_check
from hil.record.outputs import check_new_run_folder, file_hashes, out_dir


def cmd_run(args: argparse.Namespace) -> int:
    """``emacheck run``: the check on real drives (same code path as dry-run, wall-clock SYNC)."""
    from hil.master.core import MasterCore
    from hil.master.link import CanopenLink
    from hil.record.canlog import CanLogWriter
    from hil.record.runfolder import DiskSync, MetaWriter
    from hil.record.runrecord import Attribution, Bus, BusLoad, RunMode, start_record
    from hil.transport import BusTransport

    console = make_console()
    act = load_actuation(args.profile)
    check = load_check(args.check, act, args.profile)
    rig = master_setup(act, args.profile, args.eds, check)
    load = rig.plan.load
    if not args.arm:
        console.print("[red]refusing to move anything:[/red] `emacheck run` drives real actuators; "
                      "add --arm to confirm the rig is clear (profiles were checked, nothing was sent)")
        return ExitCode.INPUT
    check_new_run_folder(args.out)  # a check's record is written once: refused before the bus is opened
    refuse_foreign_history(args, act)
    bitrate = args.bitrate or act.canopen.bitrate_bps
    # the bus first: an interface that cannot be opened leaves no half-made run folder behind
    # (virtual: the SYNC task's frames are part of the traffic the master follows)
    bus = open_bus(args.interface, args.channel, bitrate, receive_own_messages=args.interface == "virtual",
                   multicast_hops=args.multicast_hops)
    out = out_dir(args.out, "run")
    out.mkdir(parents=True, exist_ok=True)
    transport = BusTransport(bus, act.timing.sync_period_s)
    master = MasterCore(act, rig.plan, forces=(check.calibration.opposing_force_N, check.safety.max_force_N),
                        safety=check.safety)
    # the run folder's writer thread (the CAN log, signals.csv, meta.json) is made before the memory
    # is locked and the loop's page faults are counted (locked, each page of a new thread's stack
    # faults at once); wall-clock stamps in the CAN log, as candump writes them
    disk = DiskSync(background=True)
    log = CanLogWriter(out / "can.log", channel=args.channel, time_offset_s=transport.wall_clock_offset_s,
                       disk=disk)
    link = CanopenLink(master, transport, log, max_missing_cycles=check.safety.max_stale_cycles,
                       max_lag_s=check.safety.max_lag_s, safety=check.safety)
    bus_rec = Bus(args.interface, args.channel, bitrate, multicast_hops_for(args.interface, args.multicast_hops))
    record = start_record(act, check, mode=RunMode.RUN, bus=bus_rec,
                          bus_load=BusLoad(load.load_nominal, load.load_worst), **rig_meta(rig),
                          attribution=Attribution(args.operator, args.work_order),
                          installation=installation(args, act),
                          files_sha256={**file_hashes(actuation=args.profile, check=args.check), **rig_hashes(rig)})
    console.print(f"emacheck run on {args.interface}:{args.channel}, {rig_nodes_text(rig)}; run folder {out}")
    from hil.cli.realtime import end_realtime, prepare_realtime
    meta = MetaWriter(out, record, disk, new=True)
    console.print(f"real time: {prepare_realtime(args.rt_priority, bounded=True, cpu_latency_us=args.cpu_latency_us)}")
    faults0 = page_faults()
    try:
        outcome, wall = canopen_check(console, act, check, link, meta, args.quiet)
        faults = page_faults() - faults0  # the check's, before the bus and real time are let go
    finally:
        transport.close()
        bus.shutdown()
        end_realtime()  # the analysis and the report run at normal priority, GC on
    record_can_stats(meta, wall, log, master, transport, faults, link.timing)
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s in {wall:.2f} s wall; "
                  f"{log.frames} CAN frames logged")
    if link.timing is not None:
        for line in link.timing.summary().lines("master"):
            console.print(line, highlight=False)
    rc = result_after(out, act, None, meta, outcome, console)
    # the wear history is imported and written only now, after the cyclic loop and the result
    record_history(console, args, act, out / "result.json", run_folder=out)
    return rc


def register(sub) -> None:
    p = add_parser(sub, "run", handler=cmd_run, help="the check on real drives (needs --arm)",
                   description="Run the check on two real CiA 402 drives on a CAN bus: the same code path "
                               "as dry-run, SYNC on the wall clock (kernel-timed on SocketCAN).")
    add_bus_args(p, "socketcan, pcan, kvaser")
    p.add_argument("--arm", action="store_true", help="confirm that the actuators may move")
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-run)")
    add_profile_args(p)
    add_trace_args(p)
    add_history_args(p, simulated=False)
    p.add_argument("--quiet", action="store_true", help="no progress display")
    rt_priority_arg(p, "run the cyclic loop under SCHED_FIFO priority N (1-99, needs the privilege; "
                        "default 0: normal scheduling); analysis and report run at normal priority "
                        "after it. Memory is locked either way (best effort).")
    add_cpu_latency_arg(p)
