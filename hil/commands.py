"""The commands behind the CLI (IO shell: files, terminal, clocks)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from hil.config import Actuation
from hil.errors import AnalysisError, EmacheckError, IncompleteRecordingError, RecordingError
from hil.profiles import build_dataclass, load_actuation, load_check, load_simrig, snapshot
from hil.runfolder import read_signals, resolve_recording, write_json_atomic
from hil.types import CHANNELS

EXIT_PASS, EXIT_FAIL, EXIT_ABORTED = 0, 1, 2


def _out_dir(args: argparse.Namespace, kind: str) -> Path:
    if args.out is not None:
        return Path(args.out)
    from hil.cli import _default_out
    return _default_out(kind)


class LiveProgress:
    """Terminal progress of a running check: step, progress, forces and strokes."""

    def __init__(self, console: Console, total_s: float, enabled: bool) -> None:
        self.enabled = enabled and console.is_terminal
        self._p = Progress(TextColumn("[bold]{task.fields[step]:<12}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                           TextColumn("{task.fields[values]}"), TimeElapsedColumn(), console=console,
                           transient=False, disable=not self.enabled, refresh_per_second=8)
        self._task = self._p.add_task("check", total=1.0, step="", values="")
        self._n = 0

    def __enter__(self) -> "LiveProgress":
        self._p.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._p.__exit__(*exc)

    def __call__(self, prog, smp) -> None:
        self._n += 1
        if not self.enabled or self._n % 25:
            return
        vals = (f"F1 {smp.F1_N / 1e3:+6.2f} kN  F2 {smp.F2_N / 1e3:+6.2f} kN  "
                f"s1 {smp.s1_mm:+7.3f} mm  s2 {smp.s2_mm:+7.3f} mm  t {smp.t_s:6.1f} s")
        self._p.update(self._task, completed=prog.total_fraction, step=prog.step.value, values=vals)


def print_summary(console: Console, result: dict, out_dir: Path | None) -> None:
    """The result as a table, truth beside it when known."""
    truth = result.get("truth")
    tab = Table(title=f"BLFmaint result: [bold]{result['status'].upper()}[/bold]")
    tab.add_column("channel")
    tab.add_column("backlash mm", justify="right")
    tab.add_column("± 1σ", justify="right")
    tab.add_column("c_left N/mm", justify="right")
    tab.add_column("c_right N/mm", justify="right")
    if truth:
        tab.add_column("truth B mm", justify="right")
        tab.add_column("truth c_l / c_r", justify="right")
    for ch in CHANNELS:
        b = result["backlash_mm"][ch]
        row = [ch, "—" if b is None else f"{b:.4f}",
               "—" if b is None else f"{result['backlash_sigma_mm'][ch]:.4f}",
               "—" if b is None else f"{result['stiffness_N_per_mm'][ch]['left']:.0f}",
               "—" if b is None else f"{result['stiffness_N_per_mm'][ch]['right']:.0f}"]
        if truth:
            row += [f"{truth['backlash_mm'][ch]:.4f}",
                    f"{truth['stiffness_N_per_mm'][ch]['left']:.0f} / {truth['stiffness_N_per_mm'][ch]['right']:.0f}"]
        tab.add_row(*row)
    console.print(tab)
    for k in ("ema1", "ema2"):
        c = result["calibration"][k]
        if c is None:
            console.print(f"LVDT {k[-1]}: not calibrated (no sweep)")
        else:
            tr = truth["calibration"][k]["pitch"] if truth else None
            console.print(f"LVDT {k[-1]}: pitch {c['pitch']:.5f}" + (f" (truth {tr:.5f})" if tr else "")
                          + f", offset {c['offset_mm']:+.4f} mm, rmse {c['rmse_mm']:.4f} mm")
    for n in result.get("notes", []):
        console.print(f"[yellow]note:[/yellow] {n}")
    if out_dir is not None:
        console.print(f"run folder: {out_dir}")


def load_recording(sig_path: Path, act: Actuation, meta: dict | None):
    """Signals from a CSV, or decoded from a raw CAN log (``*.log``), step labels from meta.json."""
    if sig_path.suffix != ".log":
        return read_signals(sig_path)
    from hil.canlog import decode_can_log
    import dataclasses
    import numpy as np

    dec = decode_can_log(sig_path, act)
    sig = dec.signals
    steps = (meta or {}).get("steps") or {}
    if steps:
        label = np.full(sig.n, "", dtype=object)
        for name, span in steps.items():
            t0 = span[0]
            t1 = span[1] if len(span) > 1 else np.inf
            label[(sig.t >= t0 - 1e-9) & (sig.t < t1 - 1e-9)] = name
        sig = dataclasses.replace(sig, step=label.astype(str),
                                  notes=sig.notes + ("step labels from meta.json step times",))
    return sig


def analyze_and_report(sig_path: Path, act: Actuation, out_dir: Path, truth: dict | None,
                       meta: dict | None, console: Console) -> dict:
    """Read the signals back, analyse, write result.json and report.html."""
    # imported here, not at the top: `emacheck run` loads the analysis only after the cyclic loop
    from hil.analyze import analyze_signals, result_dict
    from hil.report import write_report
    t0 = time.perf_counter()
    sig = load_recording(sig_path, act, meta)
    an = analyze_signals(sig, act)
    result = result_dict(an, act, truth)
    if meta is not None and meta.get("status") == "aborted":
        result["status"] = "aborted"
        result["reason"] = meta.get("reason", "")
    elif meta is not None and meta.get("status") == "running":
        result["status"] = "incomplete"
        result["reason"] = INCOMPLETE_REASON
    if sig.notes:
        result.setdefault("notes", [])
        result["notes"] = list(result["notes"]) + [n for n in sig.notes if n not in result["notes"]]
    result["analysis_s"] = round(time.perf_counter() - t0, 3)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out_dir / "result.json", result)
    write_report(out_dir / "report.html", sig, an, result, act, meta)
    return result


INCOMPLETE_REASON = ("the run did not finish (meta.json still says running: the master was killed or lost "
                     "power); analysed what was logged up to its last flush")


def _exit_for(result: dict) -> int:
    return {"pass": EXIT_PASS, "fail": EXIT_FAIL}.get(result["status"], EXIT_ABORTED)


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
    out = _out_dir(args, "simulate")
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
    return _result_after(out, act, truth, meta, outcome, console)


def _master_setup(act, profile_path, out: Path):
    """Checks before anything touches a bus: EDS against the layout, bus load."""
    from hil.drive_od import check_drive_od, load_drive_od
    from hil.pdo import DEFAULT_LAYOUT, bus_load
    from hil.profiles import resolve_eds

    eds = resolve_eds(act, profile_path)
    od = load_drive_od(eds)
    check_drive_od(od, source=str(eds))
    c = act.canopen
    _check_eds_identity(od, c, eds)
    load = bus_load(DEFAULT_LAYOUT, 2, c.bitrate_bps, act.timing.sync_period_s, c.heartbeat_period_s)
    if load.load_worst >= 0.5:
        from hil.errors import ProfileError
        raise ProfileError(f"bus load of the PDO layout at canopen.bitrate_bps = {c.bitrate_bps} is "
                           f"{load.load_worst:.1%} (worst case), not below 50 %")
    return eds, load


def _check_eds_identity(od, c, eds) -> None:
    """The EDS must describe the drive the profile expects (identity 0x1018:01/02/03 defaults)."""
    from hil.errors import ProfileError

    ident = od[0x1018] if 0x1018 in od else None
    for sub, field_name, want, cmp in ((1, "vendor_id", c.vendor_id, "=="), (2, "product_code", c.product_code, "=="),
                                       (3, "revision_min", c.revision_min, ">=")):
        var = ident.subindices.get(sub) if ident is not None else None
        have = getattr(var, "default", None)
        if have is None:
            raise ProfileError(f"EDS {eds}: identity 0x1018:{sub:02X} has no default value; cannot check it "
                               f"against the profile's canopen.{field_name}")
        ok = have == want if cmp == "==" else have >= want
        if not ok:
            raise ProfileError(f"EDS {eds}: identity 0x1018:{sub:02X} = 0x{have:08X} does not match the profile's "
                               f"canopen.{field_name} = 0x{want:08X}: the EDS describes another drive")


def _canopen_check(console: Console, act, check, link, out: Path, meta: dict, quiet: bool):
    """The check loop over CANopen. An error inside (heartbeat lost, drive fault, SDO abort,
    ...) has already stopped the drives and closed the log when it arrives here: it becomes an
    aborted outcome with the reason, and result.json says so."""
    from hil.runner import LoopOutcome, run_check

    t0 = time.perf_counter()
    try:
        with LiveProgress(console, 0.0, not quiet) as live:
            outcome = run_check(link, act, check, out, meta, on_cycle=live)
    except EmacheckError as exc:
        reason = f"{type(exc).__name__}: {exc}"
        outcome = LoopOutcome("aborted", reason, meta.get("samples", 0), meta.get("duration_s", 0.0),
                              meta.get("steps", {}))
    wall = time.perf_counter() - t0
    return outcome, wall


def _page_faults() -> int:
    """Page faults of this process so far (minor and major)."""
    import resource
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_minflt + r.ru_majflt


def _record_can_stats(out: Path, meta: dict, wall: float, log, master, transport=None,
                      page_faults: int | None = None) -> None:
    meta["wall_s"] = round(wall, 3)
    meta["can"] = {"frames_logged": log.frames, "missing_cycles": master.missing_cycles,
                   "bad_frames": master.bad_frames, "unknown_frames": master.unknown_frames}
    if transport is not None and hasattr(transport, "max_lag_s"):
        # how far the master fell behind the bus at worst (a frame waiting in its socket) [ms]
        meta["can"]["max_lag_ms"] = round(transport.max_lag_s * 1e3, 2)
    if page_faults is not None:
        meta["can"]["page_faults"] = page_faults  # during the check (each costs time)
    write_json_atomic(out / "meta.json", meta)


def _result_after(out: Path, act, truth, meta: dict, outcome, console: Console) -> int:
    """Analyse a finished check; an aborted one gets result.json with the reason (and the
    analysis where enough data was recorded)."""
    if outcome.status != "done":
        console.print(f"[red]aborted:[/red] {outcome.reason}")
        meta["status"], meta["reason"] = "aborted", meta.get("reason") or outcome.reason
        write_json_atomic(out / "meta.json", meta)
        try:
            result = analyze_and_report(out / "signals.csv", act, out, truth, meta, console)
        except EmacheckError as exc:
            result = {"status": "aborted", "reason": meta["reason"], "analysis_error": str(exc)}
            if truth is not None:
                result["truth"] = truth
            write_json_atomic(out / "result.json", result)
            console.print(f"no analysis: {exc}")
            return EXIT_ABORTED
        print_summary(console, result, out)
        return EXIT_ABORTED
    result = analyze_and_report(out / "signals.csv", act, out, truth, meta, console)
    print_summary(console, result, out)
    return _exit_for(result)


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
            quiet: bool = True, console: Console | None = None, profile_path=None) -> DryRun:
    """The check over CANopen against two simulated drives on an in-process virtual bus.

    ``faults`` (a :class:`sim.faults.Fault` sequence) replaces the simulated-rig profile's
    ``[[faults]]``. The profiles are validated by the caller; nothing is sent on the bus before
    the EDS and the bus load are checked here.
    """
    import numpy as np

    from hil.canlog import CanLogWriter
    from hil.canopen_link import CanopenLink, InProcessTransport
    from hil.drive_od import load_drive_od
    from hil.master import MasterCore
    from hil.runner import start_meta
    from sim.faults import FaultInjector
    from sim.plant import RigPlant
    from sim.slave import SimDrivePair
    from sim.truth import rig_truth

    console = console or Console(quiet=quiet)
    eds, load = _master_setup(act, profile_path, None)
    seed = simrig.seed if seed is None else seed
    faults = tuple(simrig.faults if faults is None else faults)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    plant = RigPlant(simrig.params, rng)
    pair = SimDrivePair(plant, lambda node_id=None: load_drive_od(eds, node_id=node_id), node_ids=act.canopen.node_ids)
    injector = FaultInjector(pair, faults, rng=np.random.default_rng([seed, 7]), record_truth=bool(faults))
    truth = truth_dict(rig_truth(simrig.params))
    meta = start_meta(act, check, {"mode": "dry-run", "seed": seed, "realtime": bool(realtime),
                                   "simrig": snapshot(simrig.params), "truth": truth,
                                   "faults": [snapshot(f) for f in faults],
                                   "bus_load": {"nominal": load.load_nominal, "worst": load.load_worst},
                                   "eds": str(eds)})
    write_json_atomic(out / "meta.json", meta)  # the run folder says "running" from the start
    # a channel of its own: python-can's virtual channels are process-global by name
    transport = InProcessTransport(injector, act.timing.sync_period_s, channel=f"emacheck-dry-run-{id(injector):x}",
                                   realtime=realtime)
    master = MasterCore(act)
    log = CanLogWriter(out / "can.log", channel="vcan-dry-run")
    link = CanopenLink(master, transport, log, max_missing_cycles=check.safety.max_stale_cycles,
                       max_lag_s=check.safety.max_lag_s)
    console.print(f"emacheck dry-run: two simulated CiA 402 drives (nodes {act.canopen.node_ids}) on an "
                  f"in-process virtual CAN bus, seed {seed}, bus load {load.load_worst:.1%} worst case"
                  + (f", {len(faults)} injected fault(s)" if faults else "") + f"; run folder {out}")
    try:
        outcome, wall = _canopen_check(console, act, check, link, out, meta, quiet)
    finally:
        transport.close()
    _record_can_stats(out, meta, wall, log, master)
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s simulated in {wall:.2f} s wall "
                  f"({outcome.duration_s / max(wall, 1e-9):.1f}x real time); {log.frames} CAN frames logged")
    rc = _result_after(out, act, truth, meta, outcome, console)
    return DryRun(rc, outcome, out, injector, master, link, wall)


def cmd_dry_run(args: argparse.Namespace) -> int:
    """``emacheck dry-run``: the check over CANopen against two simulated drives (virtual bus)."""
    console = Console()
    # every profile is validated before anything is sent on the bus
    act = load_actuation(args.profile)
    check = load_check(args.check, act)
    simrig = load_simrig(args.sim)
    out = _out_dir(args, "dry-run")
    return dry_run(act, check, simrig, out, seed=args.seed, realtime=args.realtime, quiet=args.quiet,
                   console=console, profile_path=args.profile).exit_code


def cmd_run(args: argparse.Namespace) -> int:
    """``emacheck run``: the check on real drives (same code path as dry-run, wall-clock SYNC)."""
    import can

    from hil.canlog import CanLogWriter
    from hil.canopen_link import BusTransport, CanopenLink
    from hil.master import MasterCore
    from hil.runner import start_meta

    console = Console()
    act = load_actuation(args.profile)
    check = load_check(args.check, act)
    eds, load = _master_setup(act, args.profile, None)
    if not args.arm:
        console.print("[red]refusing to move anything:[/red] `emacheck run` drives real actuators; "
                      "add --arm to confirm the rig is clear (profiles were checked, nothing was sent)")
        return 3
    out = _out_dir(args, "run")
    out.mkdir(parents=True, exist_ok=True)
    bitrate = args.bitrate or act.canopen.bitrate_bps
    kwargs = {"interface": args.interface, "channel": args.channel}
    if args.interface not in ("virtual", "socketcan"):
        kwargs["bitrate"] = bitrate
    if args.interface == "virtual":
        kwargs["receive_own_messages"] = True  # the SYNC task's frames are part of the traffic
    bus = can.Bus(**kwargs)
    transport = BusTransport(bus, act.timing.sync_period_s)
    master = MasterCore(act)
    log = CanLogWriter(out / "can.log", channel=args.channel)
    link = CanopenLink(master, transport, log, max_missing_cycles=check.safety.max_stale_cycles,
                       max_lag_s=check.safety.max_lag_s)
    meta = start_meta(act, check, {"mode": "run", "interface": args.interface, "channel": args.channel,
                                   "bitrate_bps": bitrate,
                                   "bus_load": {"nominal": load.load_nominal, "worst": load.load_worst},
                                   "eds": str(eds)})
    console.print(f"emacheck run on {args.interface}:{args.channel}, nodes {act.canopen.node_ids}; run folder {out}")
    from hil.serve import end_realtime, prepare_realtime
    console.print(f"real time: {prepare_realtime(args.rt_priority, bounded=True)}")
    faults0 = _page_faults()
    try:
        outcome, wall = _canopen_check(console, act, check, link, out, meta, args.quiet)
    finally:
        transport.close()
        bus.shutdown()
        end_realtime()  # the analysis and the report run at normal priority, GC on
    _record_can_stats(out, meta, wall, log, master, transport, _page_faults() - faults0)
    console.print(f"check {outcome.status} after {outcome.duration_s:.1f} s in {wall:.2f} s wall; "
                  f"{log.frames} CAN frames logged")
    return _result_after(out, act, None, meta, outcome, console)


def truth_dict(truth) -> dict:
    """The simulator's truth in result.json's shape."""
    return {"backlash_mm": dict(truth.backlash_mm),
            "stiffness_N_per_mm": {k: dict(v) for k, v in truth.stiffness_N_per_mm.items()},
            "calibration": {k: dict(v) for k, v in truth.calibration.items()}}


def read_meta(run_dir: Path | None) -> dict | None:
    """A run folder's meta.json, or None (no run folder, or no meta.json in it)."""
    if run_dir is None or not (run_dir / "meta.json").exists():
        return None
    try:
        return json.loads((run_dir / "meta.json").read_text())
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{run_dir / 'meta.json'}: not valid JSON: {exc}") from None


def actuation_for(profile: Path | None, meta: dict | None) -> Actuation:
    """The actuation to analyse a recording with: ``--profile`` if given, else the run folder's
    snapshot (what the run used), else the shipped profile."""
    if profile is not None:
        return load_actuation(profile)
    snap = ((meta or {}).get("profiles") or {}).get("actuation")
    if snap is not None:
        return build_dataclass(Actuation, snap, "meta.json (actuation snapshot)")
    return load_actuation(None)


def cmd_analyze(args: argparse.Namespace) -> int:
    """``emacheck analyze``: recompute the result from a run folder or a signals CSV."""
    console = Console()
    arg = Path(args.recording)
    try:
        sig_path, run_dir = resolve_recording(arg)
    except IncompleteRecordingError:
        if not (arg.is_dir() and (arg / "meta.json").exists()):
            raise
        sig_path, run_dir = arg / "signals.csv", arg  # a run folder killed before its first data
    meta = read_meta(run_dir)
    act = actuation_for(args.profile, meta)
    out = Path(args.out) if args.out is not None else (run_dir if run_dir is not None else sig_path.parent)
    truth = meta.get("truth") if meta else None
    incomplete = meta is not None and meta.get("status") == "running"
    try:
        result = analyze_and_report(sig_path, act, out, truth, meta, console)
    except (IncompleteRecordingError, AnalysisError) as exc:
        # (bad content, e.g. garbage lines or NaN, is refused whatever the run's status)
        if not incomplete and not (meta is not None and meta.get("status") == "aborted"):
            raise
        # an interrupted run with too little data for the analysis: say so, keep what is known
        result = {"status": "incomplete" if incomplete else "aborted",
                  "reason": INCOMPLETE_REASON if incomplete else meta.get("reason", ""),
                  "analysis_error": f"{type(exc).__name__}: {exc}", "recording": str(sig_path)}
        if truth is not None:
            result["truth"] = truth
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(out / "result.json", result)
        console.print(f"[yellow]{result['status']}:[/yellow] {result['reason']}; no analysis: {exc}")
        return EXIT_ABORTED
    if incomplete:
        console.print(f"[yellow]incomplete:[/yellow] {INCOMPLETE_REASON}")
    print_summary(console, result, out)
    return _exit_for(result)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(2)
