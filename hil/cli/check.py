"""Running the check and turning it into a result: shared by dry-run, run, simulate and analyze.

The terminal progress display, the summary table, the EDS and bus-load
checks before anything is sent, the check loop over CANopen with its abort
handling, and the analysis plus report at the end.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from rich import box
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from blf.signals import CHANNELS
from hil.cli.common import ExitCode, Outputs, load_recording, utc_iso
from hil.errors import KNOWN_ERRORS
from hil.profile.config import Actuation
from hil.record.runfolder import MetaWriter, write_json_atomic
from hil.record.runrecord import (
    INSTALLATION_KEYS,
    CanStats,
    Identity,
    RunRecord,
    RunStatus,
    Timing,
    Wear,
)


class LiveProgress:
    """Terminal progress of a running check: step, progress, forces and strokes."""

    def __init__(self, console: Console, total_s: float, enabled: bool) -> None:
        self.enabled = enabled and console.is_terminal
        self._p = Progress(TextColumn("[bold]{task.fields[step]:<12}"), BarColumn(),
                           TextColumn("{task.percentage:>3.0f}%"), TextColumn("{task.fields[values]}"),
                           TimeElapsedColumn(), console=console, transient=False, disable=not self.enabled,
                           refresh_per_second=8)
        self._task = self._p.add_task("check", total=1.0, step="", values="")
        self._n = 0

    def __enter__(self) -> LiveProgress:
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


_STATUS_STYLE = {"pass": "green", "fail": "red", "inconclusive": "yellow", "aborted": "red", "incomplete": "yellow"}


def styled(text: str, status: str, bold: bool = False) -> str:
    """``text`` in the console colour of a verdict or run status (plain when it has none)."""
    style = (("bold " if bold else "") + _STATUS_STYLE.get(status, "")).strip()
    return f"[{style}]{text}[/]" if style else text


def print_summary(console: Console, result: dict, out_dir: Path | None) -> None:
    """The result as a table: per channel the decision against its limit with the expanded
    uncertainty and the margin, then stiffness; truth beside it when known."""
    truth = result.get("truth")
    status = result["status"]
    tab = Table(title=f"BLFmaint result: {styled(status.upper(), status, bold=True)}",
                box=box.SIMPLE_HEAD, pad_edge=False)
    for col, just in (("channel", "left"), ("backlash ± U mm", "right"), ("limit mm", "right"),
                      ("margin mm", "right"), ("verdict", "left"), ("c_l / c_r kN/mm", "right")):
        tab.add_column(col, justify=just)
    if truth:
        tab.add_column("truth B mm", justify="right")
        tab.add_column("truth c kN/mm", justify="right")
    verdict = result.get("verdict", {})
    kn = lambda x: "—" if x is None else f"{x / 1e3:.1f}"  # noqa: E731
    for ch in CHANNELS:
        b = result["backlash_mm"][ch]
        v = verdict.get(ch, {})
        st = v.get("status", "")
        u = v.get("uncertainty_mm")
        stf = result["stiffness_N_per_mm"][ch]
        row = [ch, "—" if b is None else f"{b:.4f}" + ("" if u is None else f" ± {u:.4f}"),
               "—" if v.get("limit_mm") is None else f"{v['limit_mm']:.3f}",
               "—" if v.get("margin_mm") is None else f"{v['margin_mm']:+.4f}",
               styled(st, st) if st else "—",
               f"{kn(stf['left'])} / {kn(stf['right'])}"]
        if truth:
            ts = truth["stiffness_N_per_mm"][ch]
            row += [f"{truth['backlash_mm'][ch]:.4f}", f"{kn(ts['left'])} / {kn(ts['right'])}"]
        tab.add_row(*row)
    console.print(tab)
    for ch in CHANNELS:
        v = verdict.get(ch, {})
        if v.get("status") not in (None, "pass"):
            console.print(f"{ch}: {v['status']}: {v['reason']}")
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
    if result.get("reason"):
        console.print(f"[red]{status}:[/red] {result['reason']}")
    if out_dir is not None:
        console.print(f"written to: {out_dir}")


def _recording_hash(path: Path) -> dict:
    from hil.history.record import file_sha256

    h = file_sha256(path)
    return {"recording": h} if h else {}


def trace_of(meta: RunRecord | None, sig_path: Path, extra: dict | None = None) -> dict:
    """The traceability block of result.json: when, which software, which actuators (0x1018 read in the
    preflight), who and for which work order, which files (SHA-256), which run and recording; ``extra``
    (the command's flags: operator, work order, installation) before the record's."""
    from hil import __version__

    rec, extra = meta or RunRecord(), extra or {}
    held = rec.installation.as_json() if rec.installation is not None else {}
    place = {k: extra[k] if extra.get(k) is not None else held.get(k) for k in INSTALLATION_KEYS}
    extra = {k: v for k, v in extra.items() if v}
    who = rec.attribution
    return {
        "run_id": rec.run_id,
        "started_utc": rec.started_utc,
        "analysed_utc": utc_iso(),
        "software": {"name": "emacheck", "version": __version__,
                     "check_run_with": rec.software.version if rec.software is not None else None},
        "operator": extra.get("operator", who.operator if who is not None else None),
        "work_order": extra.get("work_order", who.work_order if who is not None else None),
        "identity": {k: None if v is None else v.as_json() for k, v in (rec.identity or {}).items()},
        # a recording without run record (analyze file.csv): the file's own hash names what was analysed
        "files_sha256": rec.files_sha256 or ({} if meta is not None else _recording_hash(sig_path)),
        "recording": str(sig_path),
        "mode": rec.mode.value if rec.mode is not None else None,
        # each drive's reaction to losing the master: configured, and what the drill observed (or the
        # external watchdog stated instead)
        "master_loss": rec.master_loss or {k: d.master_loss for k, d in (rec.drives_final or {}).items()
                                           if d.master_loss},
        # the limits each drive keeps itself (written and read back) and those only the master keeps
        "drive_limits": {k: [lim.as_json() for lim in d.drive_limits] for k, d in (rec.drives_final or {}).items()
                         if d.drive_limits},
        # how each EMA held a force: its drive's CST, or the master's force loop in CSP
        "force_control": rec.force_control or {},
        # the master's stalls (a CANopen check): how many, the longest, when, the limit they were held to
        **({"master_stalls": rec.stalls.as_json()} if rec.stalls is not None else {}),
        # where and when in the aircraft's life (the wear history's keys): aircraft, position, rig,
        # flight hours and cycles
        **place,
    }


def analysed(sig_path: Path, act: Actuation, truth: dict | None, meta: RunRecord | None,
             trace_extra: dict | None = None) -> tuple:
    """Read the signals back and analyse them: ``(signals, analysis, result)``, the result as result.json
    holds it."""
    # imported here, not at the top: `emacheck run` loads the analysis only after the cyclic loop
    from hil.analysis.maint import MIN_SAMPLES_CHECK, analyze_signals, result_dict
    from hil.record.signals_csv import CHECK_CHANNELS

    t0 = time.perf_counter()
    # a run that stopped early may have held still (its analysis says what is missing, not "constant"),
    # and the sensor fault that stopped it may be a jump (an LVDT spike): analysed as before, what it holds
    cut_short = meta is not None and meta.status in (RunStatus.ABORTED, RunStatus.RUNNING)
    sig = load_recording(sig_path, act, meta, channels=() if cut_short else CHECK_CHANNELS,
                         min_rows=MIN_SAMPLES_CHECK, what="the check", jumps=not cut_short)
    an = analyze_signals(sig, act)
    result = result_dict(an, act, truth)
    status = meta.status if meta is not None else None
    if status is RunStatus.ABORTED:
        result["status"] = "aborted"
        result["reason"] = meta.reason or ""
    elif status is RunStatus.RUNNING:
        result["status"] = "incomplete"
        result["reason"] = INCOMPLETE_REASON
    if sig.notes:
        result.setdefault("notes", [])
        result["notes"] = list(result["notes"]) + [n for n in sig.notes if n not in result["notes"]]
    result["trace"] = trace_of(meta, sig_path, trace_extra)
    result["analysis_s"] = round(time.perf_counter() - t0, 3)
    return sig, an, result


def analyze_and_report(sig_path: Path, act: Actuation, outputs: Outputs, truth: dict | None,
                       meta: RunRecord | None, console: Console, trace_extra: dict | None = None,
                       prepared: tuple[dict, str] | None = None) -> dict:
    """Read the signals back, analyse, write result.json and report.html into ``outputs``. ``prepared``:
    the result and the report's HTML of exactly this (:class:`hil.cli.analysis_fork.AnalysisFork`), only
    written here. The report is drawn after result.json is written (an interrupt while it is drawn
    leaves the result)."""
    if prepared is not None:
        result, html = prepared

        def write(path: Path) -> None:
            Path(path).write_text(html)
    else:
        from hil.report.maint import write_report

        sig, an, result = analysed(sig_path, act, truth, meta, trace_extra)

        def write(path: Path) -> None:
            write_report(path, sig, an, result, act, meta, json_name=outputs.path("result.json").name)
    outputs.folder.mkdir(parents=True, exist_ok=True)
    outputs.write_json("result.json", result)  # created, never over another result (but a run's own)
    outputs.write_with("report.html", write)
    return result


INCOMPLETE_REASON = ("the run did not finish (meta.json still says running: the master was killed or lost "
                     "power); analysed what was logged up to its last flush")


def exit_for(result: dict) -> int:
    """The exit status of a result: pass 0, fail 1, inconclusive 5, aborted or incomplete 2."""
    return {"pass": ExitCode.PASS, "fail": ExitCode.FAIL,
            "inconclusive": ExitCode.INCONCLUSIVE}.get(result["status"], ExitCode.ABORTED)


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
    from hil.cli.common import file_hashes

    return file_hashes(eds=rig.eds_paths["ema1"],
                       **{f"eds_{k}": v for k, v in rig.eds_paths.items() if k not in ("ema1", "ema2")})


def canopen_check(console: Console, act, check, link, meta: MetaWriter, quiet: bool):
    """The check loop over CANopen. An error inside (heartbeat lost, drive fault, SDO abort,
    ...) or Ctrl-C has already stopped the drives and closed the log when it arrives here: it
    becomes an aborted outcome with the reason, and result.json says so."""
    from hil.check.runner import INTERRUPTED, LoopOutcome, run_check

    t0 = time.perf_counter()
    try:
        with LiveProgress(console, 0.0, not quiet) as live:
            # (no progress display: no progress computed either, a Progress per cycle for nothing)
            outcome = run_check(link, act, check, meta, on_cycle=live if live.enabled else None)
    except (*KNOWN_ERRORS, KeyboardInterrupt) as exc:
        reason = INTERRUPTED if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
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


def print_drives_final(console: Console, meta: RunRecord) -> None:
    """Each drive's CiA 402 state after the check as it was seen (meta.json ``drives_final``)."""
    for ema, d in (meta.drives_final or {}).items():
        safe = "safe" if d.safe else "[red]NOT confirmed safe[/red]"
        how = "" if d.reachable else ", unreachable (heartbeat lost)"
        state = d.state if d.state is not None else "state unknown"
        console.print(f"EMA {ema[-1]} (node {d.node}): {state}, {safe}{how}" + (f" ({d.seen})" if d.seen else ""))


def print_master_loss(console: Console, meta: RunRecord) -> None:
    """Each drive's reaction to the master's death as configured and as the drill saw it (meta.json
    ``master_loss``, the refusal's included), and the external watchdog where the profile states one."""
    from rich.markup import escape

    from hil.report.shell import master_loss_text

    for ema, ml in (meta.master_loss or {}).items():
        console.print(f"EMA {ema[-1]} reaction to losing the master: {escape(master_loss_text(ml))}")


def result_after(out: Path, act, truth, meta: MetaWriter, outcome, console: Console, prepare=None) -> int:
    """Analyse a finished check; an aborted one gets result.json with the reason (and the
    analysis where enough data was recorded) and the console says where each drive ended. ``prepare``
    (a finished check's record -> the result and the report's HTML, or None): who analyses a finished
    check if not this process (:meth:`hil.cli.analysis_fork.AnalysisFork.analysed`)."""
    run = Outputs(out, own=True)  # the run's own result, written into its folder as the run ends
    rec = meta.record
    if outcome.status != RunStatus.DONE:
        console.print(f"[red]aborted:[/red] {outcome.reason}")
        rec = meta.write(dataclasses.replace(rec, status=RunStatus.ABORTED, reason=rec.reason or outcome.reason))
        print_drives_final(console, rec)
        print_master_loss(console, rec)
        try:
            result = analyze_and_report(out / "signals.csv", act, run, truth, rec, console)
        except KNOWN_ERRORS as exc:
            result = {"status": "aborted", "reason": rec.reason, "analysis_error": str(exc),
                      "trace": trace_of(rec, out / "signals.csv")}
            if truth is not None:
                result["truth"] = truth
            write_json_atomic(out / "result.json", result)
            from hil.report.maint import write_stopped_report  # (the report holds what the preflight recorded)

            run.write_with("report.html", lambda path: write_stopped_report(path, result))
            console.print(f"no analysis: {exc}")
            return ExitCode.INPUT if outcome.bad_input else ExitCode.ABORTED
        print_summary(console, result, out)
        return ExitCode.INPUT if outcome.bad_input else ExitCode.ABORTED
    print_master_loss(console, rec)
    result = analyze_and_report(out / "signals.csv", act, run, truth, rec, console,
                                prepared=prepare(rec) if prepare is not None else None)
    print_summary(console, result, out)
    return exit_for(result)
