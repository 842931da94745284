"""What ``emacheck commission`` runs on and how it reads a stop: the simulated rig of ``--simulate`` (its own
actuation profile with ``--sim``, its ``[[faults]]`` and ``--wiring-fault``), a real bus, the real-time set-up
(``--rt-priority``) and the finding of a stop on stale data (the PC is the likely cause).

Shared by :mod:`hil.cli.commission` (a shared module, no command of its own).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

from hil.cli.args import add_cpu_latency_arg, add_seed_arg, rt_priority_arg

#: The key of the finding of a stop on stale data: not a profile key, the PC running emacheck.
STALE_KEY = "pc.stale_data"
#: The key of a node's heartbeat lost while the master's own loop was held as long, or, on a software bus, the
#: node's process sent nothing at all as long (the PC, not the node).
HEARTBEAT_PC_KEY = "pc.heartbeat_lost"
#: python-can interfaces whose nodes are processes on a PC, not devices (``sim-serve``'s simulated drives).
SOFTWARE_BUSES = frozenset({"udp_multicast", "virtual"})


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


def add_rig_args(p) -> None:
    """The options of the rig commissioned: ``--simulate``'s (``--sim``, ``--seed``, ``--wiring-fault``) and the
    real-time set-up of a bus (``--rt-priority``, ``--cpu-latency-us``)."""
    p.add_argument("--sim", metavar="SIMRIG.toml", type=Path,
                   help="with --simulate: the simulated rig's own profile (plant, seed, serials, [[faults]]); the "
                        "simulated nodes are built as its `actuation` profile says (default the shipped one), not "
                        "as the profile under test, so a mistake in that profile shows. Without --sim: the "
                        "shipped simulated rig, built as the profile under test")
    add_seed_arg(p, "with --simulate; recorded in commission.json")
    p.add_argument("--wiring-fault", action="append", type=wiring_fault, metavar="KIND[:EMA[:VALUE]]",
                   help="with --simulate, wire the simulated rig wrongly (repeatable): lvdt_sign, lvdt_scale "
                        "(VALUE: reading / stroke, default 0.5), lvdt_dead, loadcell_sign, loadcell_scale, "
                        "loadcell_dead, lvdts_swapped, loadcells_swapped; e.g. lvdt_sign:2, loadcell_scale:1:0.1")
    rt_priority_arg(p, "on a bus (real drives, or sim-serve's): run the cyclic loop under SCHED_FIFO priority N (1-99, "
                       "needs the privilege; "
                       "default 0: normal scheduling), as `emacheck run` does; the report is written at normal "
                       "priority after it. On a loaded PC the loop may fall behind the bus at normal priority "
                       "(a stop on stale data, finding pc.stale_data)")
    add_cpu_latency_arg(p)


def refused(args) -> str | None:
    """Why the options do not go together (None: they do): what applies to simulated drives only, or to a bus."""
    if args.wiring_fault and not args.simulate:
        return "--wiring-fault needs --simulate"
    if args.sim is not None and not args.simulate:
        return "--sim needs --simulate"
    if args.simulate and (args.rt_priority or args.cpu_latency_us is not None):
        return "--rt-priority and --cpu-latency-us apply to a bus (real drives), not to --simulate (simulated time)"
    return None


def simulated_transport(act, rig, simrig, faults, seed: int | None):
    """The simulated rig (:func:`hil.sim_server.simulated_rig`, as ``sim-serve`` serves it) built as ``rig``
    on the in-process bus at the SYNC period of ``act``, with ``faults`` (wiring faults among them)."""
    from hil.sim_server import simulated_rig
    from hil.transport import InProcessTransport

    return InProcessTransport(simulated_rig(simrig, rig, faults, seed=seed), act.timing.sync_period_s)


def simulated_rig_profile(args, profile: Path | None, rig, simrig):
    """(the planned rig the simulated nodes are built as, its actuation profile's path or None): the profile
    under test (``rig``, today's rehearsal) without ``--sim``, else the simulated rig's own ``actuation``
    (the shipped one where it names none), planned with its own EDS files (``--eds`` is the profile under
    test's; it applies to the rig too where both are one file)."""
    from hil.profile.load import default_profile_path, load_actuation
    from hil.profile.rig import plan_for

    if args.sim is None:
        return rig, None
    own = Path(simrig.actuation or default_profile_path("actuation.toml"))
    mine = Path(profile or default_profile_path("actuation.toml"))
    if own.resolve() == mine.resolve():
        return rig, own
    return plan_for(load_actuation(own), own, None), own


def open_rig(args, act, rig, profile: Path | None):
    """(transport, bus or None, the report's context of it) for ``--simulate`` or ``--interface/--channel``."""
    from hil.cli.bus import multicast_hops_for, open_bus
    from hil.profile.load import load_simrig
    from hil.record.outputs import file_hashes
    from sim.faults import WIRING_KINDS

    if args.simulate:
        simrig = load_simrig(args.sim)
        faults = tuple(simrig.faults) + tuple(args.wiring_fault or ())
        true_rig, own = simulated_rig_profile(args, profile, rig, simrig)
        transport = simulated_transport(act, true_rig, simrig, faults, args.seed)
        wiring = [{"kind": f.kind, "ema": f.ema, "value": f.param if math.isfinite(f.param) else None}
                  for f in faults if f.fault_kind in WIRING_KINDS]
        simulated = {"simrig": str(args.sim or "(shipped)"),
                     "simulated_rig_actuation": str(own) if own is not None else "(the profile under test)"}
        return transport, None, {
            "simulated": True, "seed": simrig.seed if args.seed is None else args.seed, "wiring_faults": wiring,
            "bus": {"interface": "in-process", "channel": "simulated"}, "simulated_rig": simulated,
            "files_sha256": file_hashes(simrig=args.sim, **({"simulated_rig_actuation": own} if own else {})),
            # kept beside the judged profiles: the rig rehearsed on, as given
            "copies": {k: v for k, v in (("simulated-rig.toml", args.sim), ("simulated-rig-actuation.toml", own))
                       if v is not None}}
    from hil.transport import BusTransport

    bitrate = args.bitrate or act.canopen.bitrate_bps
    bus = open_bus(args.interface, args.channel, bitrate, receive_own_messages=args.interface == "virtual",
                   multicast_hops=args.multicast_hops)
    return BusTransport(bus, act.timing.sync_period_s), bus, {
        "simulated": False, "bus": {"interface": args.interface, "channel": args.channel, "bitrate_bps": bitrate,
                                    "multicast_hops": multicast_hops_for(args.interface, args.multicast_hops)}}


def stale_finding(finding, exc: BaseException, rt_priority: int | None, stalls=(), interface: str = "",
                  canopen=None, on_axis=None):
    """The finding of a stop ``exc``: a stop on stale data (:class:`hil.master.link.StaleData`) is given the key
    :data:`STALE_KEY` and says that the PC is the likely cause, with what to do; a node's heartbeat lost
    (:class:`hil.master.events.HeartbeatLost`) while the master's own loop was held as long (``stalls``: the
    latest stalls of its loop, :attr:`hil.master.stalls.StallWatch.recent`; the rule
    :func:`hil.master.stalls.stall_explains`), or on a software bus (``interface`` in :data:`SOFTWARE_BUSES`)
    with the node silent altogether as long (:func:`hil.master.stalls.process_held`), likewise,
    :data:`HEARTBEAT_PC_KEY`; so is a drive's EMCY 0x8130 (it lost the master's heartbeat) where the master's
    loop, which sends that heartbeat, was held at least the drive's consumer time less the master's heartbeat
    period within the consumer time before it (``canopen``: the profile's table; the same rule). Any other is
    ``finding``. The stalls are on the samples' axis (SYNC periods since the cyclic phase began), a heartbeat
    lost or an EMCY on the master's clock (since the preflight began): ``on_axis`` takes the latter to the
    former (:meth:`hil.canopen.cycle.SyncSchedule.on_axis`; None: the same axis).

    The drives answer every SYNC within microseconds; a sample missing for the freshness limit in force, or a
    SYNC taken late by the master, is most often the master's PC not running its loop in time (a loaded PC at
    normal scheduling: docs/performance.md). ``rt_priority``: the SCHED_FIFO priority the loop ran at (0 or
    None: normal scheduling)."""
    from hil.master.events import HeartbeatLost
    from hil.master.link import StaleData
    from hil.master.stalls import process_held, stall_explains

    axis = on_axis if on_axis is not None else (lambda t: t)
    if isinstance(exc, StaleData):
        key, seen, idle = STALE_KEY, "", "check that each drive sends its TPDOs on every SYNC"
    elif isinstance(exc, HeartbeatLost) and (stall := stall_explains(stalls, axis(exc.at_s), exc.silent_s,
                                                                      exc.overdue_s)) is not None:
        key = HEARTBEAT_PC_KEY
        seen = (f" (the master's own loop was held {stall[1] * 1e3:.0f} ms at t = {stall[0]:.3f} s, within the "
                f"heartbeat's {exc.silent_s * 1e3:.0f} ms of silence: at least the {exc.overdue_s * 1e3:.0f} ms a "
                f"heartbeat may be overdue ({exc.key}); a producer on this PC, or its frames, were held as long)")
        idle = f"check the node's heartbeat ({exc.key})"
    elif isinstance(exc, HeartbeatLost) and interface in SOFTWARE_BUSES and \
            process_held(exc.frames_silent_s, exc.overdue_s):
        key = HEARTBEAT_PC_KEY
        seen = (f" (on {interface} the node is a process on a PC, and it sent nothing at all, no statusword either, "
                f"for {exc.frames_silent_s * 1e3:.0f} ms at a stretch within that silence: at least the "
                f"{exc.overdue_s * 1e3:.0f} ms a heartbeat may "
                f"be overdue ({exc.key}); the process serving it was not run)")
        idle = f"check the node's heartbeat ({exc.key})"
    elif (emcy := _master_heartbeat_lost(exc, canopen)) is not None and (stall := stall_explains(
            stalls, axis(emcy.t_s), canopen.master_consumer_time_s, margin := _consumer_margin_s(canopen))) is not None:
        key = HEARTBEAT_PC_KEY
        seen = (f" (the drive lost the master's heartbeat, which the master's loop sends: the loop was held "
                f"{stall[1] * 1e3:.0f} ms at t = {stall[0]:.3f} s, at least the {margin * 1e3:.0f} ms the drive's "
                f"consumer time (canopen.master_heartbeat_consumer_factor) leaves beyond the master's period)")
        idle = "check the drives' consumer heartbeat (canopen.master_heartbeat_consumer_factor)"
    else:
        return finding
    ran = f"SCHED_FIFO {rt_priority}" if rt_priority else "normal scheduling"
    hint = (f"the likely cause is the PC running emacheck ({ran}): it did not keep up with the bus; run with "
            "--rt-priority N (e.g. 50) and without other load on the PC, then commission again" if not rt_priority
            else f"the likely cause is the PC running emacheck ({ran}): unload the PC and commission again; "
                 f"if it repeats on an idle PC, {idle}")
    return dataclasses.replace(finding, key=key, text=f"{finding.text}{seen}; {hint}")


def _master_heartbeat_lost(exc: BaseException, canopen):
    """The EMCY of a drive that lost the master's heartbeat (0x8130, life guard or heartbeat) that stopped the
    commissioning (``exc``), or None."""
    from hil.canopen.emcy import EmcyCode
    from hil.master.events import DriveFault

    e = getattr(exc, "emcy", None) if isinstance(exc, DriveFault) and canopen is not None else None
    return e if e is not None and e.code == EmcyCode.LIFE_GUARD_OR_HEARTBEAT else None


def _consumer_margin_s(canopen) -> float:
    """How long the master's heartbeat may be late before a drive's consumer fires [s]: its consumer time less
    the master's heartbeat period (125 - 50 = 75 ms with the shipped profile)."""
    return canopen.master_consumer_time_s - canopen.master_heartbeat_period_s


def ended_in(d: dict, scanned: dict) -> str:
    """Where a drive ended, in words: its last state seen (``d``: :attr:`hil.master.link.CanopenLink.final_states`
    of one EMA), else the state the scan read (``scanned``: the scan's record of its node) while nothing was
    powered since, else what is known (the statusword never read)."""
    if d.get("state") is not None:
        return f"{d['state']} (confirmed {d['confirmed']})"
    if scanned.get("state") is not None:
        return f"{scanned['state']} (read by the scan; nothing was powered since)"
    return f"an unknown state ({d.get('seen') or 'statusword never read'})"
