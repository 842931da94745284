"""``emacheck analyze``: the check's result again from a run folder, a signals CSV or a CAN log."""

from __future__ import annotations

import argparse
from pathlib import Path

from blf.errors import AnalysisError
from hil.cli.args import ExitCode, add_history_args, add_parser, add_recording_args, add_trace_args
from hil.cli.console import make_console, print_summary
from hil.cli.history_glue import installation, record_history, refuse_foreign_history
from hil.cli.result import INCOMPLETE_REASON, analyze_and_report, exit_for, trace_of
from hil.errors import IncompleteRecordingError, RecordingError
from hil.record.inputs import recording_inputs
from hil.record.outputs import outputs_for
from hil.record.recording import actuation_for
from hil.record.runfolder import read_record, resolve_run
from hil.record.runrecord import RunStatus
from hil.record.seal import check_seal


def cmd_analyze(args: argparse.Namespace) -> int:
    """``emacheck analyze``: recompute the result from a run folder or a signals CSV."""
    console = make_console()
    arg = Path(args.recording)
    sig_path, run_dir = resolve_run(arg)  # a run folder killed before its first data too
    meta = read_record(run_dir)
    modified = check_seal(sig_path, meta, args.accept_modified)  # before anything is written
    act = actuation_for(args.profile, meta)
    refuse_foreign_history(args, act)
    outputs = outputs_for(args.out, sig_path, run_dir, "analysis", ("result.json", "report.html"))
    truth = meta.truth if meta is not None else None
    status = meta.status if meta is not None else None
    incomplete = status is RunStatus.RUNNING
    extra = {"operator": args.operator, "work_order": args.work_order, **installation(args, act, meta).as_json(),
             "modified": modified, "inputs": recording_inputs(sig_path, run_dir, meta, args.profile)}
    try:
        result = analyze_and_report(sig_path, act, outputs, truth, meta, console, trace_extra=extra)
    except BaseException as exc:
        outputs.discard_if_empty()  # no empty analysis-<UTC>/ left behind by a recording that cannot be read
        if not isinstance(exc, (IncompleteRecordingError, AnalysisError)):
            raise
        # (bad content, e.g. garbage lines or NaN, is refused whatever the run's status)
        if not incomplete and status is not RunStatus.ABORTED:
            if str(exc).startswith(str(sig_path)):
                raise
            raise RecordingError(f"{sig_path}: cannot be analysed: {exc}") from None
        # an interrupted run with too little data for the analysis: say so, keep what is known
        result = {"status": "incomplete" if incomplete else "aborted",
                  "reason": INCOMPLETE_REASON if incomplete else meta.reason or "",
                  "analysis_error": f"{type(exc).__name__}: {exc}", "recording": str(sig_path),
                  "trace": trace_of(meta, sig_path, extra)}
        if truth is not None:
            result["truth"] = truth
        outputs.folder.mkdir(parents=True, exist_ok=True)
        outputs.write_json("result.json", result)
        console.print(f"[yellow]{result['status']}:[/yellow] {result['reason']}; no analysis: {exc}")
        record_history(console, args, act, outputs.path("result.json"), run_folder=run_dir, recording=sig_path)
        return ExitCode.ABORTED
    if incomplete:
        console.print(f"[yellow]incomplete:[/yellow] {INCOMPLETE_REASON}")
    print_summary(console, result, outputs.path("report.html"))
    record_history(console, args, act, outputs.path("result.json"), run_folder=run_dir, recording=sig_path)
    return exit_for(result)


def register(sub) -> None:
    p = add_parser(sub, "analyze", handler=cmd_analyze, help="BLFmaint on a run folder or a signals CSV",
                   description="Recompute calibration, backlash and stiffness from a run folder "
                               "or a bare signals CSV (columns t,phi1,phi2,s1,s2,F1,F2 in s, rad, mm, N). "
                               "Without a step column the calibration sweeps and force-fight "
                               "segments are found automatically.")
    add_recording_args(p, "result.json and report.html")
    add_trace_args(p)
    add_history_args(p, simulated=False)
