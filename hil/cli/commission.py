"""``emacheck commission``: a rig brought up before its first check (the IO shell of
:mod:`hil.master.commission`, over :mod:`hil.master.link` as the check runs).

Real drives: ``--interface``, ``--channel`` and ``--arm``. Simulated drives in process: ``--simulate``
(the dry-run's simulated rig, with ``--wiring-fault`` or the simulated-rig profile's ``[[faults]]``).
The report (``commission.json``, ``commission.html``), the profile patch, a copy of the profiles judged and the
CAN log go into a new folder, written once (:mod:`hil.cli.commission_out`).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

from hil.cli.args import ExitCode, add_bus_args, add_parser, add_profile_args
from hil.cli.bus import multicast_hops_for, open_bus
from hil.cli.check import master_setup, rig_nodes_text
from hil.cli.commission_out import identities, print_summary, report_data, write_outputs
from hil.cli.console import make_console
from hil.profile.load import load_actuation, load_check, load_simrig
from hil.record.outputs import check_new_run_folder, file_hashes, out_dir


@dataclass
class CommissionRun:
    """What :func:`commission` leaves behind: the exit status, the report (as written), the live objects."""

    exit_code: int
    report: dict
    out: Path
    core: object
    link: object


def wiring_fault(text: str):
    """``--wiring-fault KIND[:EMA[:VALUE]]`` -> a :class:`sim.faults.Fault` (argparse type)."""
    from blf.errors import InputError
    from sim.faults import WIRING_KINDS, Fault, FaultKind

    parts = text.split(":")
    kinds = sorted(k.value for k in WIRING_KINDS)
    if parts[0] not in kinds:
        raise argparse.ArgumentTypeError(f"{parts[0]!r} is not a wiring fault; known: {', '.join(kinds)}")
    try:
        ema = int(parts[1]) if len(parts) > 1 and parts[1] else 1
        kw = {"value": float(parts[2])} if len(parts) > 2 else {}
        return Fault(FaultKind(parts[0]).value, ema=ema, **kw)
    except (ValueError, InputError) as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc} (KIND[:EMA[:VALUE]], EMA 1 or 2)") from None


def simulated_transport(act, rig, simrig, faults, seed: int | None):
    """The dry-run's simulated rig on the in-process bus, with ``faults`` (wiring faults among them)."""
    import numpy as np

    from hil.canopen.od import load_eds
    from hil.transport import InProcessTransport
    from sim.drives import SimDrivePair
    from sim.faults import FaultInjector
    from sim.plant import RigPlant

    seed = simrig.seed if seed is None else seed
    rng = np.random.default_rng(seed)
    pair = SimDrivePair(RigPlant(simrig.params, rng), rig.plan,
                        lambda name, node_id: load_eds(rig.eds_paths[name], node_id=node_id), serials=simrig.serials)
    injector = FaultInjector(pair, faults, rng=np.random.default_rng([seed, 7]), record_truth=False)
    return InProcessTransport(injector, act.timing.sync_period_s)


def commission(act, check, rig, transport, out: Path, *, console=None, context: dict | None = None,
               paths: dict | None = None, eds: Path | None = None) -> CommissionRun:
    """Commission the rig over ``transport``; the report, the profile patch, a copy of each profile judged
    (``paths``: ``{"actuation": file, "check": file}``, None: the shipped one) and the CAN log go into ``out``
    (new or empty).

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
                       max_lag_s=check.safety.max_lag_s)
    try:
        smp = link.first_sample()
        while True:
            sp1, sp2 = core.step(smp)
            if core.done:
                break
            smp = link.exchange(sp1, sp2)
    except (*KNOWN_ERRORS, CanopenError, KeyboardInterrupt) as exc:
        core.failed(exc)
        link.abort()
        interrupted = isinstance(exc, KeyboardInterrupt)
    else:
        interrupted = False
    finally:
        link.close()
    final = link.final_states or {}
    for ema, d in final.items():
        scanned = core.scan.nodes.get(d["node"], {})
        nothing_powered = core.stopped_at is Stage.SCAN
        # the scan read its state and nothing was powered since; a node that does not answer is named already
        if d["safe"] or (nothing_powered and scanned.get("state") == "SWITCH_ON_DISABLED") or \
                scanned.get("answers") is False:
            continue
        core.findings.append(Finding(Stage.DONE, Kind.NOT_SAFE, f"canopen.node_id_{ema}",
                                     f"{ema}: last known {d['state']}, confirmed {d['confirmed']}, reachable "
                                     f"{d['reachable']}"))
    paths = {"actuation": None, "check": None} | (paths or {})
    explanation = _explained(core, act, paths["actuation"], eds)
    report = report_data(core, master, link, final, context, explanation, identities(act, rig, core.scan.nodes))
    rc = ExitCode.PASS if report["status"] == "ready" else ExitCode.NOT_READY
    rc = ExitCode.ABORTED if interrupted else rc  # Ctrl-C: the drives stopped, the report written, exit 2
    report["exit_code"] = int(rc)
    i = act.mechanics.i_total_rad_per_mm
    traces = {name: {**x, "x1": x["phi1"] / i, "x2": x["phi2"] / i} for name, x in core.traces.items()}
    write_outputs(out, report, traces, act.timing.sync_period_s, paths)
    print_summary(console, report, out)
    return CommissionRun(rc, report, out, core, link)


def _explained(core, act, profile: Path | None, eds: Path | None):
    """The findings explained jointly (:mod:`hil.master.hypotheses`), a pinned serial checked; the core's
    findings replaced by the explanation's."""
    from hil.master.commission_explain import explain_commission, serial_findings
    from hil.profile.load import default_profile_path
    from hil.profile.tables import read_toml

    core.findings[:0] = serial_findings(act, core.scan.nodes)
    data = read_toml(Path(profile) if profile is not None else default_profile_path("actuation.toml"))
    explanation = explain_commission(core, act, data, profile, eds)
    core.findings[:] = list(explanation.findings)
    return explanation


def cmd_commission(args: argparse.Namespace) -> int:
    """``emacheck commission``: scan, identity, signals at rest, signs and scales in motion, drill, safe end."""
    console = make_console()
    if args.profile_pos is not None and args.profile is not None and args.profile_pos != args.profile:
        console.print(f"[red]two actuation profiles given:[/red] {args.profile_pos} and --profile {args.profile}")
        return ExitCode.INPUT
    profile = args.profile_pos or args.profile
    act = load_actuation(profile)
    check = load_check(args.check, act)
    if not args.simulate and (args.interface is None or args.channel is None):
        console.print("[red]give --interface and --channel[/red] (real drives), or --simulate")
        return ExitCode.INPUT
    if not args.simulate and not args.arm:
        console.print("[red]refusing to move anything:[/red] `emacheck commission` moves real actuators a little; "
                      "add --arm to confirm the rig is clear (profiles were checked, nothing was sent)")
        return ExitCode.INPUT
    if args.wiring_fault and not args.simulate:
        console.print("[red]--wiring-fault needs --simulate[/red]")
        return ExitCode.INPUT
    rig = master_setup(act, profile, args.eds)
    check_new_run_folder(args.out)
    context = {"profiles": {"actuation": str(profile or "(shipped)"), "check": str(args.check or "(shipped)")},
               "files_sha256": file_hashes(actuation=profile, check=args.check)}
    bus = None
    if args.simulate:
        simrig = load_simrig(args.sim)
        faults = tuple(simrig.faults) + tuple(args.wiring_fault or ())
        transport = simulated_transport(act, rig, simrig, faults, args.seed)
        wiring = [{"kind": f.kind, "ema": f.ema, "value": f.param if math.isfinite(f.param) else None}
                  for f in faults if f.kind in _wiring_kinds()]
        context |= {"simulated": True, "seed": simrig.seed if args.seed is None else args.seed,
                    "wiring_faults": wiring, "bus": {"interface": "in-process", "channel": "simulated"}}
    else:
        bitrate = args.bitrate or act.canopen.bitrate_bps
        bus = open_bus(args.interface, args.channel, bitrate, receive_own_messages=args.interface == "virtual",
                       multicast_hops=args.multicast_hops)
        from hil.transport import BusTransport

        transport = BusTransport(bus, act.timing.sync_period_s)
        context |= {"simulated": False, "bus": {"interface": args.interface, "channel": args.channel,
                                                "bitrate_bps": bitrate,
                                                "multicast_hops": multicast_hops_for(args.interface,
                                                                                     args.multicast_hops)}}
    out = out_dir(args.out, "commission")
    console.print(f"emacheck commission: {rig_nodes_text(rig)} on {context['bus']['interface']}:"
                  f"{context['bus']['channel']}; folder {out}")
    try:
        run = commission(act, check, rig, transport, out, console=console, context=context,
                         paths={"actuation": profile, "check": args.check}, eds=args.eds)
    finally:
        transport.close()
        if bus is not None:
            bus.shutdown()
    return run.exit_code


def _wiring_kinds() -> set[str]:
    from sim.faults import WIRING_KINDS

    return {k.value for k in WIRING_KINDS}


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
            "make the rig ready: emacheck profile apply-patch), judged-*.toml and can.log into a new folder.\n\n"
            "  emacheck commission my-rig.toml --interface socketcan --channel can0 --arm\n"
            "  emacheck commission --simulate --wiring-fault lvdt_sign:2 --wiring-fault lvdts_swapped"))
    p.add_argument("profile_pos", nargs="?", metavar="PROFILE", type=Path,
                   help="actuation profile (default: the shipped one; --profile says the same)")
    p.add_argument("--simulate", action="store_true",
                   help="the simulated drives on an in-process bus instead of --interface/--channel (no --arm)")
    p.add_argument("--wiring-fault", action="append", type=wiring_fault, metavar="KIND[:EMA[:VALUE]]",
                   help="with --simulate, wire the simulated rig wrongly (repeatable): lvdt_sign, lvdt_scale "
                        "(VALUE: reading / stroke, default 0.5), lvdt_dead, loadcell_sign, loadcell_scale, "
                        "loadcell_dead, lvdts_swapped, loadcells_swapped; e.g. lvdt_sign:2, loadcell_scale:1:0.1")
    p.add_argument("--arm", action="store_true", help="confirm that the actuators may move (real drives)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="new or empty folder for the report (default emacheck-runs/<time>-commission)")
    add_profile_args(p, sim=True)
    add_bus_args(p.add_argument_group("real drives (with --arm)"), "socketcan, pcan, kvaser", required=False)
