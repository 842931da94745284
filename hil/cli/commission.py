"""``emacheck commission``: a rig brought up before its first check (the IO shell of
:mod:`hil.master.commission`, over :mod:`hil.master.link` as the check runs).

Real drives: ``--interface``, ``--channel`` and ``--arm`` (``--rt-priority``). Simulated drives in process:
``--simulate`` (the simulated rig sim-serve serves, with ``--wiring-fault`` or the simulated-rig profile's
``[[faults]]``; with ``--sim`` built from that rig's own actuation profile): :mod:`hil.cli.commission_setup`.
The report (``commission.json``, ``commission.html``), the profile patch, a copy of the profiles judged and the
CAN log go into a new folder, written once (:mod:`hil.cli.commission_out`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from hil.cli.args import ExitCode, add_bus_args, add_parser, add_profile_args
from hil.cli.check import master_setup, rig_nodes_text
from hil.cli.commission_out import identities, print_summary, report_data, write_outputs
from hil.cli.commission_setup import add_rig_args, ended_in, open_rig, refused, stale_finding
from hil.cli.console import make_console
from hil.profile.load import load_actuation, load_check
from hil.record.outputs import check_new_run_folder, file_hashes, out_dir


@dataclass
class CommissionRun:
    """What :func:`commission` leaves behind: the exit status, the report (as written), the live objects."""

    exit_code: int
    report: dict
    out: Path
    core: object
    link: object


def commission(act, check, rig, transport, out: Path, *, console=None, context: dict | None = None,
               rt_priority: int | None = None, loop_ended=None, paths: dict | None = None,
               eds: Path | None = None, copies: dict | None = None) -> CommissionRun:
    """Commission the rig over ``transport``; the report, the profile patch, a copy of each profile judged
    (``paths``: ``{"actuation": file, "check": file}``, None: the shipped one) and the CAN log go into ``out``
    (new or empty), with ``copies`` (file name -> path: the simulated rig's profiles of a rehearsal).

    The link keeps the check's freshness rule (:func:`hil.check.staleness.stale_limit`: the derived stall budget
    where both drives keep their limits); a stop on stale data names the PC (``rt_priority``: the loop's
    SCHED_FIFO priority, for its words). ``loop_ended`` is called once the drives are stopped, before the report.
    Returns the exit status (0 ready, :attr:`ExitCode.NOT_READY` with every problem named) and the report.
    """
    from hil.canopen.errors import CanopenError
    from hil.errors import KNOWN_ERRORS
    from hil.master.commission import Commission, CommissionMaster
    from hil.master.commission_rules import Finding, Kind, Stage
    from hil.master.jog_rules import commissioning_safety
    from hil.master.link import CanopenLink
    from hil.record.canlog import CanLogWriter
    from hil.transport import InProcessTransport

    console = console or make_console(quiet=True)
    sim = isinstance(transport, InProcessTransport)
    context = {"simulated": sim, "bus": {"interface": "in-process" if sim else "?", "channel": "simulated" if sim
                                         else "?"}} | (context or {})
    core = Commission(act, check, rig.plan)
    lim = core.lim
    # during commissioning the drives keep the commissioning's force limit as their max torque themselves
    safety = commissioning_safety(check.safety, lim, core.jog_plan)  # (docs/commission.md: the drives' limits)
    # every frame the master is fed is heard by the scan too (any node id); the scan runs before the preflight
    master = CommissionMaster(core, act, rig.plan, forces=(2.0 * lim.force_N, lim.max_force_N), safety=safety)
    # wall-clock stamps on a real bus, as candump writes them (run does the same)
    log = CanLogWriter(out / "can.log", channel=str(context["bus"]["channel"]),
                       time_offset_s=0.0 if sim else transport.wall_clock_offset_s)
    link = CanopenLink(master, transport, log, max_missing_cycles=check.safety.max_stale_cycles,
                       max_lag_s=check.safety.max_lag_s, safety=safety)
    try:
        smp = link.first_sample()
        while True:
            sp1, sp2 = core.step(smp)
            if core.done:
                break
            smp = link.exchange(sp1, sp2)
    except (*KNOWN_ERRORS, CanopenError, KeyboardInterrupt) as exc:
        core.failed(exc)
        link.record_overdue_sync()  # (a hold that ended in the stop: what waited for it was judged first)
        stall, bus = link.stall_watch.recent, str(context["bus"]["interface"])  # (the PC named where the evidence
        core.findings[-1:] = [stale_finding(f, exc, rt_priority, stall, bus, act.canopen,  # says)
                                            master.sync_schedule.on_axis) for f in core.findings[-1:]]
        link.abort()
        interrupted = isinstance(exc, KeyboardInterrupt)
    else:
        interrupted = False
    finally:
        link.close()
        if loop_ended is not None:
            loop_ended()
    final = link.final_states or {}
    for ema, d in final.items():
        scanned = core.scan.nodes.get(d["node"], {})
        nothing_powered = core.stopped_at is Stage.SCAN
        # the scan read its state and nothing was powered since; a node that does not answer is named already
        if d["safe"] or (nothing_powered and scanned.get("state") == "SWITCH_ON_DISABLED") or \
                scanned.get("answers") is False:
            continue
        core.findings.append(Finding(Stage.DONE, Kind.NOT_SAFE, f"canopen.node_id_{ema}",
                                     f"{ema}: ended in {ended_in(d, scanned)}, reachable {d['reachable']}"))
    paths = {"actuation": None, "check": None} | (paths or {})
    explanation = _explained(core, act, paths["actuation"], eds)
    report = report_data(core, master, link, final, context, explanation, identities(act, rig, core.scan.nodes))
    rc = ExitCode.PASS if report["status"] == "ready" else ExitCode.NOT_READY
    rc = ExitCode.ABORTED if interrupted else rc  # Ctrl-C: the drives stopped, the report written, exit 2
    report["exit_code"] = int(rc)
    i = act.mechanics.i_total_rad_per_mm
    traces = {name: {**x, "x1": x["phi1"] / i, "x2": x["phi2"] / i} for name, x in core.traces.items()}
    write_outputs(out, report, traces, act.timing.sync_period_s, paths, copies)
    print_summary(console, report, out)
    return CommissionRun(rc, report, out, core, link)


def _explained(core, act, profile: Path | None, eds: Path | None):
    """The findings explained jointly (:mod:`hil.master.hypotheses`), a pinned serial checked; the core's
    findings replaced by the explanation's."""
    from hil.master.commission_explain import explain_commission, serial_findings
    from hil.master.commission_rules import keyed_stops
    from hil.profile.load import default_profile_path
    from hil.profile.tables import read_toml

    core.findings[:0] = serial_findings(act, core.scan.nodes)
    data = read_toml(Path(profile) if profile is not None else default_profile_path("actuation.toml"))
    explanation = explain_commission(core, act, data, profile, eds)
    core.findings[:] = keyed_stops(explanation.findings)  # (a step's stop names the keys of what stopped it)
    return explanation


def cmd_commission(args: argparse.Namespace) -> int:
    """``emacheck commission``: scan, identity, signals at rest, signs and scales in motion, drill, safe end."""
    console = make_console()
    if args.profile_pos is not None and args.profile is not None and args.profile_pos != args.profile:
        console.print(f"[red]two actuation profiles given:[/red] {args.profile_pos} and --profile {args.profile}")
        return ExitCode.INPUT
    profile = args.profile_pos or args.profile
    act = load_actuation(profile)
    check = load_check(args.check, act, profile)
    if not args.simulate and (args.interface is None or args.channel is None):
        console.print("[red]give --interface and --channel[/red] (real drives), or --simulate")
        return ExitCode.INPUT
    if not args.simulate and not args.arm:
        console.print("[red]refusing to move anything:[/red] `emacheck commission` moves real actuators a little; "
                      "add --arm to confirm the rig is clear (profiles were checked, nothing was sent)")
        return ExitCode.INPUT
    if why := refused(args):
        console.print(f"[red]{why}[/red]")
        return ExitCode.INPUT
    rig = master_setup(act, profile, args.eds)
    check_new_run_folder(args.out)
    context = {"profiles": {"actuation": str(profile or "(shipped)"), "check": str(args.check or "(shipped)")},
               "files_sha256": file_hashes(actuation=profile, check=args.check)}
    transport, bus, more = open_rig(args, act, rig, profile)
    context["files_sha256"] |= more.pop("files_sha256", {})
    copies = more.pop("copies", {})
    context |= more
    out = out_dir(args.out, "commission")
    console.print(f"emacheck commission: {rig_nodes_text(rig)} on {context['bus']['interface']}:"
                  f"{context['bus']['channel']}; folder {out}")
    from hil.cli.realtime import end_realtime, prepare_realtime

    try:
        if bus is not None:  # a real bus: the loop set up as run's (memory locked, SCHED_FIFO on request)
            rt = prepare_realtime(args.rt_priority, bounded=True, cpu_latency_us=args.cpu_latency_us)
            console.print(f"real time: {rt}")
        run = commission(act, check, rig, transport, out, console=console, context=context,
                         rt_priority=args.rt_priority, loop_ended=end_realtime if bus is not None else None,
                         paths={"actuation": profile, "check": args.check}, eds=args.eds, copies=copies)
    finally:
        transport.close()
        if bus is not None:
            bus.shutdown()
            end_realtime()
    return run.exit_code


def register(sub) -> None:
    p = add_parser(
        sub, "commission", handler=cmd_commission,
        help="bring a rig up before its first check: nodes, identities, signals, signs and scales, drill",
        description=(
            "Commission a rig before its first check (docs/commission.md). In order, stopping at the\n"
            "first step that finds a problem, every problem of that step named with its profile key and\n"
            "the value that would fit:\n"
            "  1. scan: NMT reset node, which node ids answer (boot-up, heartbeat, SDO 0x1000), identity\n"
            "     0x1018 and device type against the profile (nothing is powered);\n"
            "  2. the check's preflight: configuration, the drives' own limits (max torque: the\n"
            "     commissioning's force limit / 1.45, motor speed 4x its speed), the master's-death drill;\n"
            "  3. at rest (0.5 s, drives holding): each LVDT and load cell alive, in range, noise within\n"
            "     4x the declared, load cells within the commissioning force of zero (nothing moves yet);\n"
            "  4. a force-free jog: both EMAs out by the travel and back together in CSP, no force\n"
            "     commanded: motor angle over the gear ratio and LVDT agree, 0.10 + (noise+play)/travel;\n"
            "     a ram ahead of its motor, a load cell changed by 1/10 of the force limit: stopped; a\n"
            "     disagreement names the scale that fits (gear ratio, LVDT, encoder), nothing is loaded;\n"
            "  5. each EMA in turn, the other holding 1/4 of the opposing force in CST: out and back by\n"
            "     min(1 mm, 1/10 sweep amplitude) at 1/4 sweep speed: LVDT gains (1 +- 0.10); the force\n"
            "     stepped up: load cells against the torque (+1 / -1 within 0.25), LVDT swaps; below 2 %\n"
            "     dead; a load cell beyond 4x the force or a motor 0.5 mm past the travel stops. Without\n"
            "     CST: the other EMA follows, then each pushes against the other held (load-cell signs).\n"
            "  6. both drives to Switch on disabled, confirmed.\n"
            "The findings are then explained jointly: one cause for several symptoms (the gear ratio for\n"
            "all gains, a swap, a unit error by a power of ten), the simplest hypothesis that explains\n"
            "every measurement within its tolerance; advice the profile loader refuses is a wiring fix.\n"
            "Exit 0: ready for its first check; 6: not ready (every problem named); 2: Ctrl-C;\n"
            "3: bad input. Writes commission.json, commission.html, profile.patch.toml (the keys that\n"
            "make the rig ready: emacheck profile apply-patch), judged-*.toml (with --sim also\n"
            "simulated-rig.toml, simulated-rig-actuation.toml) and can.log into a new folder.\n\n"
            "  emacheck commission my-rig.toml --interface socketcan --channel can0 --arm\n"
            "  emacheck commission --simulate --wiring-fault lvdt_sign:2 --wiring-fault lvdts_swapped"))
    p.add_argument("profile_pos", nargs="?", metavar="PROFILE", type=Path,
                   help="actuation profile (default: the shipped one; --profile says the same)")
    p.add_argument("--simulate", action="store_true",
                   help="the simulated drives on an in-process bus instead of --interface/--channel (no --arm)")
    p.add_argument("--arm", action="store_true", help="confirm that the actuators may move (real drives)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="new or empty folder for the report (default emacheck-runs/<time>-commission)")
    add_profile_args(p)
    add_rig_args(p)
    add_bus_args(p.add_argument_group("real drives (with --arm)"), "socketcan, pcan, kvaser", required=False)
