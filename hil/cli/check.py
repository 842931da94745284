"""Running the check over CANopen: shared by dry-run, run, simulate and commission.

The simulated rig of a dry-run (worn, its identity, its truth), the master set up from the profiles
with the EDS and bus-load checks before anything is sent, the check loop with its progress, and what
the record keeps of the bus and the loop. The result made from it: :mod:`hil.cli.result`.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from rich.console import Console

from hil.cli.console import check_progress
from hil.errors import KNOWN_ERRORS
from hil.record.runfolder import MetaWriter
from hil.record.runrecord import (
    CanStats,
    Identity,
    RunStatus,
    Timing,
    Wear,
)


def worn_simrig(simrig, flight_hours: float | None, seed: int):
    """The simulated rig worn to ``flight_hours`` by its ``[wear]`` table (sim.truth.apply_wear, the scatter
    drawn from ``seed``), and what to record of it in meta.json; unchanged (and None) without both."""
    if simrig.wear is None or flight_hours is None:
        return simrig, None
    import dataclasses

    import numpy as np

    from hil.profile.load import snapshot
    from sim.truth import apply_wear, wear_line_mm

    params = apply_wear(simrig.params, simrig.wear, flight_hours, np.random.default_rng([seed, 0x16]))
    info = Wear(flight_hours, snapshot(simrig.wear), wear_line_mm(simrig.params, simrig.wear, flight_hours))
    return dataclasses.replace(simrig, params=params), info


def simulated_identity(act, simrig) -> dict[str, Identity] | None:
    """The identity (0x1018) the simulated drives report, for a check without them (``simulate``):
    vendor and product the profile expects, its lowest revision, the simulated rig's serial numbers."""
    if simrig.serials is None:
        return None
    c = act.canopen
    return {f"ema{k}": Identity(n, c.vendor_id, c.product_code, c.revision_min, s)
            for k, (n, s) in enumerate(zip(c.node_ids, simrig.serials, strict=True), start=1)}


def refuse_shared_serial(act, simrig, sim_path) -> None:
    """``simulate`` has no preflight to read the drives' identity: a simulated-rig profile whose
    ``[identity]`` gives both EMAs one serial is refused here instead (:class:`hil.errors.ProfileError`,
    exit status 3), as the preflight of a dry-run or run refuses two such drives."""
    from hil.errors import ProfileError
    from hil.record.runrecord import shared_serial

    ident = simulated_identity(act, simrig) or {}
    clash = shared_serial({k: v.as_json() for k, v in ident.items()})
    if clash is not None:
        raise ProfileError(f"{sim_path or 'simrig.toml (shipped)'}: identity.serial_ema1 = identity.serial_ema2: "
                           f"{clash}; give each simulated EMA its own serial")


def truth_dict(truth) -> dict:
    """The simulator's truth in result.json's shape."""
    return {"backlash_mm": dict(truth.backlash_mm),
            "stiffness_N_per_mm": {k: dict(v) for k, v in truth.stiffness_N_per_mm.items()},
            "calibration": {k: dict(v) for k, v in truth.calibration.items()}}


def master_setup(act, profile_path, eds=None, check=None):
    """Checks before anything touches a bus: every node's EDS against the signal map, the PDO layout,
    the bus load (:func:`hil.profile.rig.plan_for`); with the check profile, each quantised LVDT and
    load cell against its noise (:func:`hil.check.resolution.refuse_coarse_sensors`); returns the
    planned :class:`hil.profile.rig.Rig`."""
    from hil.check.resolution import refuse_coarse_sensors
    from hil.profile.rig import plan_for

    rig = plan_for(act, profile_path, eds)
    if check is not None:
        refuse_coarse_sensors(rig.plan, act, check, Path(profile_path).name if profile_path else "actuation.toml")
    return rig


def rig_nodes_text(rig) -> str:
    """``nodes 1 (EMA 1), 2 (EMA 2), 3 (io)``: the rig's nodes for a console line."""
    return "nodes " + ", ".join(n.spec.label.removeprefix("node ") for n in rig.plan.nodes)


def rig_meta(rig) -> dict:
    """What the run record holds of the planned rig (:class:`~hil.record.runrecord.RunRecord` fields): the
    drives' EDS, every node's EDS, the notes of the plan, how each EMA holds a force."""
    return {"eds": str(rig.eds_paths["ema1"]), "eds_nodes": {k: str(v) for k, v in rig.eds_paths.items()},
            "plan_notes": tuple(rig.plan.notes),
            "force_control": {f"ema{d.ema}": d.force_control.value for d in rig.plan.drives}}


def rig_hashes(rig) -> dict:
    """SHA-256 of the drives' EDS (``eds``) and of each sensor node's (``eds_NAME``)."""
    from hil.record.outputs import file_hashes

    return file_hashes(eds=rig.eds_paths["ema1"],
                       **{f"eds_{k}": v for k, v in rig.eds_paths.items() if k not in ("ema1", "ema2")})


def canopen_check(console: Console, act, check, link, meta: MetaWriter, quiet: bool):
    """The check loop over CANopen. An error inside (heartbeat lost, drive fault, SDO abort,
    ...) or Ctrl-C has already stopped the drives and closed the log when it arrives here: it
    becomes an aborted outcome with the reason, and result.json says so."""
    from hil.check.runner import INTERRUPTED, LoopOutcome, run_check

    t0 = time.perf_counter()
    try:
        with check_progress(console, quiet) as live:
            # (no progress display: no progress computed either, a Progress per cycle for nothing)
            outcome = run_check(link, act, check, meta, on_cycle=live if live.enabled else None)
    except (*KNOWN_ERRORS, KeyboardInterrupt) as exc:
        reason = (str(exc) or INTERRUPTED) if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
        rec = meta.record
        outcome = LoopOutcome(RunStatus.ABORTED, reason, rec.samples if rec.samples is not None else 0,
                              rec.duration_s if rec.duration_s is not None else 0.0, rec.steps or (),
                              bad_input=bool(getattr(exc, "bad_input", False)))
    wall = time.perf_counter() - t0
    return outcome, wall


def page_faults() -> int:
    """Page faults of this process so far (minor and major)."""
    import resource
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_minflt + r.ru_majflt


def record_can_stats(meta: MetaWriter, wall: float, log, master, transport=None,
                     page_faults: int | None = None, timing=None) -> None:
    """Into the run record after the loop: its wall time, the CAN statistics, the master's loop timing
    (``timing``, a :class:`hil.record.cycletiming.CycleTiming`) and each EMA's identity."""
    # how far the master fell behind the bus at worst (a frame waiting in its socket) [ms]
    lag = round(transport.max_lag_s * 1e3, 2) if transport is not None and hasattr(transport, "max_lag_s") else None
    can = CanStats(log.frames, master.missing_cycles, master.bad_frames, master.unknown_frames,
                   max_lag_ms=lag, page_faults=page_faults)  # page faults: during the check (each costs time)
    loop = None
    if timing is not None:  # the master's loop per SYNC cycle (hil.record.cycletiming)
        loop = Timing(timing.summary(), t0_unix_s=round(getattr(transport, "wall_clock_offset_s", 0.0), 6),
                      sync="loop-timed" if getattr(transport, "loop_sync", False) else "periodic task",
                      sync_skipped=getattr(transport, "sync_skipped", 0),
                      sync_late_max_ms=round(getattr(transport, "sync_late_max_s", 0.0) * 1e3, 4),
                      sync_periods_skipped=master.sync_schedule.skipped)
    # each EMA's identity as the drive reported it by SDO (0x1018) in the preflight
    # (a preflight that stopped early: what it had read, e.g. two drives of one serial)
    read = getattr(getattr(master, "preflight", None), "identities", {})
    ident = {f"ema{k}": Identity.of(n, master.drives[n].identity or read.get(n, {}))
             for k, n in enumerate(master.order, start=1)}
    meta.write(dataclasses.replace(meta.record, wall_s=round(wall, 3), can=can, timing=loop or meta.record.timing,
                                   identity=ident))


