"""A check's recording turned into a result: its trace (who, what, from which files), the analysis and
report, the exit status; after a check over CANopen, what is said and written (:func:`result_after`).
Shared by dry-run, run, simulate and analyze.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from rich.console import Console

from hil.cli.args import ExitCode
from hil.cli.console import print_drives_final, print_master_loss, print_summary
from hil.errors import KNOWN_ERRORS
from hil.profile.config import Actuation
from hil.record.driveparts import last_known
from hil.record.outputs import Outputs, utc_iso
from hil.record.recording import load_recording
from hil.record.runfolder import MetaWriter, write_json_atomic
from hil.record.runrecord import INSTALLATION_KEYS, RunRecord, RunStatus


def _recording_hash(path: Path) -> dict:
    from hil.record.seal import sha256_file

    h = sha256_file(path)
    return {"recording": h} if h else {}


def trace_of(meta: RunRecord | None, sig_path: Path, extra: dict | None = None) -> dict:
    """The traceability block of result.json: when, which software, which actuators (0x1018 read in the
    preflight), who and for which work order, which files (SHA-256: the check's profiles, ``files_sha256``;
    every file this result was read from, by role, ``inputs``), which run and recording; ``extra`` (the
    command's flags: operator, work order, installation; ``inputs``, :mod:`hil.record.inputs`) before the
    record's."""
    from hil import __version__

    rec, extra = meta or RunRecord(), dict(extra or {})
    inputs = extra.pop("inputs", None)
    if inputs is None:  # (a check's own result: its recording; hil.record.inputs)
        from hil.record.inputs import input_entry

        inputs = [input_entry("recording", sig_path)]
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
        # every file this result was made from, by role, with its SHA-256 (hil.record.inputs)
        "inputs": inputs,
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
        # where each drive was left: its CiA 402 state, its last sample (position, stroke, force), its EMCYs
        **({"drives_last": last_known(rec.drives_final, rec.drives_last)}
           if rec.drives_final or rec.drives_last else {}),
        # the master's stalls (a CANopen check): how many, the longest, when, the limit they were held to
        **({"master_stalls": rec.stalls.as_json()} if rec.stalls is not None else {}),
        # where and when in the aircraft's life (the wear history's keys): aircraft, position, rig,
        # flight hours and cycles
        **place,
        # a run folder's recording changed after its check, analysed at the user's request (hil.record.seal)
        **({"modified": extra["modified"]} if extra.get("modified") else {}),
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
    an = analyze_signals(sig, act, force_fight_fraction(meta))
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
    if "modified" in result["trace"]:  # said first among the notes: on the console and in the report
        result["notes"] = [result["trace"]["modified"]["words"]] + list(result.get("notes", []))
    result["analysis_s"] = round(time.perf_counter() - t0, 3)
    return sig, an, result


def force_fight_fraction(meta: RunRecord | None) -> float | None:
    """The force-fight level the run's check profile commanded, as a fraction of F_limit (None: not known)."""
    check = meta.profiles.check if meta is not None and meta.profiles is not None else None
    value = ((check or {}).get("force_fight") or {}).get("amplitude_fraction_of_limit")
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0 else None


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
        print_summary(console, result, out / "report.html")
        return ExitCode.INPUT if outcome.bad_input else ExitCode.ABORTED
    print_master_loss(console, rec)
    result = analyze_and_report(out / "signals.csv", act, run, truth, rec, console,
                                prepared=prepare(rec) if prepare is not None else None)
    print_summary(console, result, out / "report.html")
    return exit_for(result)
