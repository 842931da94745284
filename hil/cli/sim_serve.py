"""``emacheck sim-serve``: the two simulated drives on a CAN bus until SIGINT/SIGTERM."""

from __future__ import annotations

import argparse
import signal
from pathlib import Path

from hil.cli.args import add_bus_args, add_cpu_latency_arg, add_eds_arg, add_parser, add_seed_arg, rt_priority_arg
from hil.cli.bus import open_bus
from hil.cli.check import rig_nodes_text
from hil.cli.realtime import prepare_realtime
from hil.record.runfolder import create_json


def cmd_sim_serve(args: argparse.Namespace) -> int:
    """``emacheck sim-serve``: the two simulated drives on a CAN bus until SIGINT/SIGTERM."""
    from hil.profile.load import load_actuation, load_simrig
    from hil.profile.rig import plan_for
    from hil.sim_server import faults_text, serve, simulated_rig

    if args.timing_json is not None and Path(args.timing_json).exists():  # written at the end: refused now
        from hil.errors import OutputError
        raise OutputError(f"--timing-json {args.timing_json}: exists; never overwritten (name a new file)")
    simrig = load_simrig(args.sim)
    # the nodes as --profile says (the master's profile), else as the simulated rig's own (`actuation = `)
    profile = args.profile if args.profile is not None else simrig.actuation
    act = load_actuation(profile)
    rig = plan_for(act, profile, args.eds)
    seed = simrig.seed if args.seed is None else args.seed
    pair = simulated_rig(simrig, rig, seed=seed)  # with the simulated rig's [[faults]], as in process
    bus = open_bus(args.interface, args.channel, args.bitrate or act.canopen.bitrate_bps,
                   multicast_hops=args.multicast_hops)

    stop = _StopFlag()

    def _stop(signum, _frame) -> None:
        stop.set()

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    rt = prepare_realtime(args.rt_priority, cpu_latency_us=args.cpu_latency_us)

    def ready() -> None:
        print(f"sim-serve: {rig_nodes_text(rig)} on {args.interface}:{args.channel}, seed {seed}, "
              f"{faults_text(pair.faults)}, {rt}; ready", flush=True)

    try:
        stats = serve(bus, pair, stop=stop, on_ready=ready, period_s=act.timing.sync_period_s)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    print("\n".join(stats.lines()), flush=True)
    if args.timing_json is not None:
        create_json(args.timing_json, stats.as_json())
    return 0


class _StopFlag:
    """The stop request set by a signal handler: no lock (``threading.Event.set`` takes one, and a
    second signal arriving inside the first handler's ``set`` deadlocked sim-serve on it)."""

    def __init__(self) -> None:
        self._set = False

    def set(self) -> None:
        self._set = True

    def is_set(self) -> bool:
        return self._set


def register(sub) -> None:
    p = add_parser(sub, "sim-serve", handler=cmd_sim_serve,
                   help="the two simulated drives on a CAN bus (until SIGINT/SIGTERM)",
                   description="Serve two simulated CiA 402 drives on a python-can bus (e.g. socketcan "
                               "vcan0) for `emacheck run` in another process; the plant steps on each "
                               "SYNC received. SIGINT/SIGTERM end it cleanly.")
    add_bus_args(p, "socketcan, virtual")
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile the simulated nodes are built as (their node ids, EDS files, signal "
                        "map and scalings); default: the simulated-rig profile's own (its `actuation`, else the "
                        "shipped one)")
    add_eds_arg(p)
    p.add_argument("--sim", metavar="SIMRIG.toml", type=Path,
                   help="simulated-rig profile (the plant, the seed, the serial numbers; its [[faults]], wiring "
                        "faults included, are applied as in `dry-run` and `commission --simulate`)")
    add_seed_arg(p, "printed on its ready line")
    rt_priority_arg(p, "run under SCHED_FIFO priority N (1-99; default 0: normal scheduling)")
    add_cpu_latency_arg(p)
    p.add_argument("--timing-json", metavar="FILE", type=Path,
                   help="at the end, write the counters and the loop's timing per SYNC cycle (reaction: "
                        "SYNC in to TPDOs out) to FILE as JSON")
