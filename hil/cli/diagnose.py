"""``emacheck diagnose``: simulation versus recording; locate the mismatch, name the missing physics, fit it."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hil.cli.common import add_parser, add_recording_args, make_console, outputs_for


def cmd_diagnose(args: argparse.Namespace) -> int:
    """``emacheck diagnose RECORDING [--profile] [--out] [--model]``."""

    from blf.diagnose import diagnose
    from blf.errors import AnalysisError, InputError
    from hil.analysis.diagnose import diagnosis_dict, load_model
    from hil.errors import RecordingError
    from hil.report.diagnose import write_report
    from hil.runfolder import write_json_atomic
    console = make_console()
    path = Path(args.recording)
    t0 = time.perf_counter()
    try:
        model, period = load_model(path, args.model, args.profile)
        d = diagnose(model, period, progress=None if args.quiet else (lambda s: console.print(f"  {s}")))
    except (InputError, AnalysisError) as exc:  # the recording does not support a diagnosis: bad input
        raise RecordingError(f"{path}: cannot be diagnosed: {exc}") from None
    secs = time.perf_counter() - t0
    # the folder only once there is something to write into it (a refused recording leaves none)
    outputs = outputs_for(args.out, path, path if path.is_dir() else None, "diagnose")
    outputs.folder.mkdir(parents=True, exist_ok=True)
    data = diagnosis_dict(d, args.model, secs)
    write_json_atomic(outputs.path("diagnosis.json"), data)
    if not args.no_report:
        write_report(outputs.path("diagnosis_report.html"), model, d, data,
                     json_name=outputs.path("diagnosis.json").name)
    words = {"no_mismatch": "no significant mismatch between simulation and recording",
             "explained": "mismatch explained", "unexplained": "mismatch NOT explained by the candidate library"}
    console.print(f"[bold]{words[d.verdict]}[/bold] ({secs:.1f} s)")
    for e in data["effects"]:
        console.print(f"  {e['words']} ({e['name']} at {e['where']}): " + ", ".join(
            f"{k} = {v} ± {e['uncertainty'][k]}" for k, v in e["parameters"].items()))
    if data["where"]:
        console.print("  the rest lies at: " + ", ".join(data["where"]))
    for loc in data["locations"][:6]:
        console.print(f"  where: {loc['channel']} {loc['t_start_s']}-{loc['t_end_s']} s ({loc['test']} test), "
                      f"{loc['regime']}")
    console.print(f"  compared in the band: {d.band.words}")
    console.print("  residual RMS before -> after (band): " + ", ".join(
        f"{c} {data['residual_rms_before'][c]} -> {data['residual_rms_after'][c]}"
        for c in d.measured if d.valid[c].any()))
    console.print("  on the held-out half (never fitted): " + ", ".join(
        f"{c} {data['residual_rms_holdout_before'][c]} -> {data['residual_rms_holdout_after'][c]}"
        for c in d.measured if d.valid[c].any()))
    console.print("  held-out, raw band: " + ", ".join(
        f"{c} {data['residual_rms_raw_holdout_before'][c]} -> {data['residual_rms_raw_holdout_after'][c]}"
        for c in d.measured if d.valid[c].any()))
    console.print(f"  BIC {data['ic_before']} -> {data['ic_after']}; written {outputs.path('diagnosis.json')}")
    return 0


def register(sub) -> None:
    p = add_parser(sub, "diagnose", handler=cmd_diagnose,
                   help="simulation versus recording: locate the mismatch, name the missing physics",
                   description="Replay a recording through the simulation driven by the measured motor "
                               "angles, fit the nominal model, localise where they differ, screen a library "
                               "of candidate physics terms, refit the best and accept it only if BIC and a "
                               "held-out half of the recording both improve. Writes diagnosis.json and "
                               "diagnosis_report.html.")
    add_recording_args(p, "diagnosis.json and diagnosis_report.html",
                       recording_help="run folder, signals CSV (t,phi1,phi2,s1,s2,F1,F2), CAN log; single-axis: "
                                      ".mat or CSV t,q,q_ref,force")
    p.add_argument("--model", choices=("dual-ema", "single-axis"), default="dual-ema",
                   help="dual-EMA rig (default) or a single positioning axis (e.g. EMPS)")
    p.add_argument("--no-report", action="store_true", help="write diagnosis.json only")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
