"""``emacheck serv``: BLFserv (paper 2.2) on a normal-operation recording; serv.json and serv_report.html."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rich import box
from rich.console import Console
from rich.table import Table

from blf.signals import CHANNELS
from hil.cli.args import ExitCode, add_history_args, add_parser, add_recording_args, add_trace_args
from hil.cli.console import make_console
from hil.cli.history_glue import installation, record_history, refuse_foreign_history
from hil.cli.result import INCOMPLETE_REASON, exit_for, trace_of
from hil.errors import IncompleteRecordingError, RecordingError
from hil.record.inputs import input_entry, recording_inputs
from hil.record.outputs import Outputs, outputs_for
from hil.record.recording import actuation_for, load_recording
from hil.record.runfolder import read_record, resolve_run
from hil.record.runrecord import RunStatus
from hil.record.seal import check_seal


def print_summary(console: Console, data: dict, outputs: Outputs, report: bool) -> None:
    """The BLFserv result as a table on the console: per channel the reading with U, its traversals,
    the limit, margin and verdict (truth beside it when known)."""
    from hil.cli.console import styled
    from hil.report.shell import fmt

    truth = data.get("truth")
    st = data.get("status", "")
    run = data.get("run") or {}
    if run.get("status") in ("aborted", "incomplete"):
        console.print(f"[red]run {run['status']}:[/red] {run['reason']}", soft_wrap=True)
    tab = Table(title=f"BLFserv ({data['method'] or 'nothing analysed'}): {styled(st.upper(), st, bold=True)}",
                box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("channel", "backlash ± U mm", "traversals", "limit mm", "margin mm", "verdict", "paper mm",
                "truth mm" if truth else None):
        if col:
            tab.add_column(col, justify="left" if col in ("channel", "verdict") else "right")
    for ch in CHANNELS:
        b = data["backlash_mm"][ch]
        v = data.get("verdict", {}).get(ch, {})
        u = v.get("uncertainty_mm")
        s = v.get("status", "")
        missing = "not traversed" if s == "not_traversed" else "not measured"
        row = [ch, missing if b is None else f"{b:.4f}" + ("" if u is None else f" ± {u:.4f}"),
               str(data["traversals"][ch]), fmt(v.get("limit_mm"), 3),
               "—" if v.get("margin_mm") is None else f"{v['margin_mm']:+.4f}",
               styled(s, s) if s else "—", fmt(data["backlash_paper_mm"][ch])]
        if truth:
            row.append(fmt(truth["backlash_mm"][ch]))
        tab.add_row(*row)
    console.print(tab)
    console.print(f"LVDT calibration: {data['calibration']['source']}")
    for n in data["notes"]:
        console.print(f"[yellow]note:[/yellow] {n}")
    written = [outputs.path("serv.json").name] + ([outputs.path("serv_report.html").name] if report else [])
    console.print(f"{' and '.join(written)} in {outputs.folder}")


def cmd_serv(args: argparse.Namespace) -> int:
    """``emacheck serv RECORDING [--profile ACTUATION.toml] [--out DIR] [--calibration RESULT.json]
    [--method improved|paper] [--no-report]``."""
    # imported here: python-control, numba and scipy.signal cost seconds (not for other commands)
    from blf.errors import AnalysisError, InputError
    from blf.serv import METHODS
    from hil.analysis.serv import MIN_SAMPLES_SERV, analyse, choose_calibration, serv_dict, unjudged_dict
    from hil.record.signals_csv import SERV_CHANNELS
    from hil.report.serv import write_serv_report

    console = make_console()
    t0 = time.perf_counter()
    method = getattr(args, "method", None) or "improved"
    if method not in METHODS:
        raise RecordingError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    arg = Path(args.recording)
    sig_path, run_dir = resolve_run(arg)  # a run folder killed before its first data too
    meta = read_record(run_dir)
    modified = check_seal(sig_path, meta, args.accept_modified)  # before anything is written
    act = actuation_for(args.profile, meta)
    refuse_foreign_history(args, act)
    run = run_state(meta)
    # a run cut short (aborted, or killed: still `running`): read as analyze reads it (its last samples may hold
    # the sensor fault that stopped it, a jump or a signal held still), and judged only where it can be
    cut_short = run is not None and run["status"] != "done"
    an = None
    try:
        sig = load_recording(sig_path, act, meta, channels=() if cut_short else SERV_CHANNELS,
                             min_rows=MIN_SAMPLES_SERV, what="BLFserv", jumps=not cut_short)
        corr = choose_calibration(sig, act, run_dir, getattr(args, "calibration", None))
        an = analyse(sig, act, corr, method)
    except (InputError, AnalysisError, RecordingError) as exc:
        if not (cut_short and isinstance(exc, (IncompleteRecordingError, AnalysisError))):
            # each message names the file it is about: the recording's, unless it names a file itself
            named = [str(p) for p in (sig_path, getattr(args, "calibration", None)) if p is not None]
            if any(n in str(exc) for n in named):
                raise
            raise RecordingError(f"{sig_path}: {exc}") from None
        why = str(exc)
    truth = meta.truth if meta is not None else None
    report = not getattr(args, "no_report", False) and an is not None
    outputs = outputs_for(args.out, sig_path, run_dir, "serv", ("serv.json", "serv_report.html"))
    data = serv_dict(an, truth, str(sig_path)) if an is not None else unjudged_dict(act, run["status"], why,
                                                                                     str(sig_path))
    if truth is not None:
        data["truth"] = truth
    data["run"] = run
    inputs = recording_inputs(sig_path, run_dir, meta, args.profile) + (
        [input_entry("calibration", an.correction.file)] if an is not None and an.correction.file is not None else [])
    data["trace"] = trace_of(meta, sig_path, {"operator": args.operator, "work_order": args.work_order,
                                              **installation(args, act, meta).as_json(), "modified": modified,
                                              "inputs": inputs})
    # said first among the notes, on the console and in the report: a run cut short, a recording changed
    data["notes"] = ([run["words"]] if cut_short else []) + ([modified["words"]] if modified else []) + list(
        data["notes"])
    data["analysis_s"] = round(time.perf_counter() - t0, 3)
    outputs.write_json("serv.json", data)
    if report:
        outputs.write_with("serv_report.html", lambda path: write_serv_report(
            path, an, data, act, json_name=outputs.path("serv.json").name))
    print_summary(console, data, outputs, report)
    record_history(console, args, act, outputs.path("serv.json"), run_folder=run_dir, recording=sig_path)
    return ExitCode.ABORTED if an is None else exit_for(data)


def run_state(meta) -> dict | None:
    """serv.json's ``run``: the run folder's status (``done``; ``aborted`` or ``incomplete``, a run killed
    while ``running``) and why, in words; None for a recording without a run record."""
    if meta is None or meta.status is None:
        return None
    if meta.status is RunStatus.DONE:
        return {"status": "done", "reason": None, "words": "the check finished"}
    if meta.status is RunStatus.ABORTED:
        status, why = "aborted", meta.reason or "no reason recorded"
    else:
        status, why = "incomplete", INCOMPLETE_REASON
    return {"status": status, "reason": why,
            "words": f"the check was {'aborted' if status == 'aborted' else 'cut short'} ({why}): BLFserv read only "
                     "the stretch of motion recorded before (never the drives' enabling, the LVDT calibration or "
                     "the safe stop); what it could not see is not measured"}


def register(sub) -> None:
    p = add_parser(sub, "serv", handler=cmd_serv, help="BLFserv: in-service backlash from a normal-operation recording",
                   description="Measure internal and external backlash from the jumps of the position "
                               "differences during normal operation (paper 2.2, no force sensors): a run "
                               "folder, a signals CSV (t,phi1,phi2,s1,s2,F1,F2) or a raw CAN log. Writes "
                               "serv.json and serv_report.html (paper Fig. 8, error budget of paper 2.3).")
    add_recording_args(p, "serv.json and serv_report.html")
    add_trace_args(p)
    add_history_args(p, simulated=False)
    p.add_argument("--calibration", metavar="RESULT.json", type=Path,
                   help="LVDT pitch and offset from a maintenance check's result.json")
    p.add_argument("--method", choices=("improved", "paper"), default="improved",
                   help="backlash from plateau levels (improved, default) or the paper's Delta D")
    p.add_argument("--no-report", action="store_true", help="write serv.json only, no HTML report")
