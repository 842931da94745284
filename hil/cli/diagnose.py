"""``emacheck diagnose``: simulation versus recording; locate the mismatch, name the missing physics, fit it.

The arguments become one request (:class:`hil.analysis.diagnose.request.DiagnoseRequest`), the analysis
answers it in one call (:func:`hil.analysis.diagnose.request.diagnose_recording`; everything is checked
before anything is written); here its outcome is written (diagnosis.json, the report) and said.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.cli.args import add_parser, add_recording_args, history_url_type
from hil.cli.console import make_console
from hil.record.outputs import outputs_for

#: exit status of a diagnosis whose effort is not trusted: inconclusive, the reason in diagnosis.json
UNTRUSTED_EXIT = 5
_NAMES = ("diagnosis.json", "diagnosis_report.html")


def cmd_diagnose(args: argparse.Namespace) -> int:
    """``emacheck diagnose RECORDING [--profile] [--out] [--model] [--reference HEALTHY|history]``."""
    from hil.analysis.diagnose.request import diagnose_recording
    console = make_console()
    req = _request(args)
    out = diagnose_recording(req, progress=None if args.quiet else (lambda s: console.print(f"  {s}")))
    # the folder only once there is something to write into it (a refused recording leaves none)
    run_dir = req.recording if out.kind == "model" and req.recording.is_dir() else None
    outputs = outputs_for(args.out, req.recording, run_dir, "diagnose", _NAMES)
    out.data["trace"] = _trace(req, out)
    outputs.write_json("diagnosis.json", out.data)
    written = outputs.path("diagnosis.json")
    if out.untrusted and out.kind == "model":
        console.print(f"[bold]effort not trusted, not diagnosed[/bold]: {out.data['effort']['words']}; written "
                      f"{written}")
        return UNTRUSTED_EXIT
    if not args.no_report:
        outputs.write_with("diagnosis_report.html", lambda p: _write_report(p, out, written.name))
    {"model": _say_model, "axis_reference": _say_axis_reference, "dual_reference": _say_dual_reference}[out.kind](
        console, out, args, written)
    return UNTRUSTED_EXIT if out.untrusted else 0


def _request(args: argparse.Namespace):
    """The request of the arguments; a number that cannot be is refused (exit 3) naming its option."""
    from hil.analysis.diagnose.request import DiagnoseRequest
    from hil.analysis.diagnose.single_axis import FORCE_FLOOR_N, AxisOptions
    from hil.errors import RecordingError
    for name in ("current_per_force", "screw_lead_m", "force_floor_N"):
        val = getattr(args, name)
        if val is not None and not val > 0:
            raise RecordingError(f"--{name.replace('_', '-')}: must be > 0; got {val}")
    tol = getattr(args, "position_scale_tolerance", 0.0)
    if not 0.0 <= tol < 0.5:
        raise RecordingError(f"--position-scale-tolerance: must be in [0, 0.5) (a fraction); got {tol}")
    axis = AxisOptions(current_law=args.current_law, current_a_per_N=args.current_per_force,
                       screw_lead_m=args.screw_lead_m, position_scale_tolerance=tol,
                       force_floor_N=FORCE_FLOOR_N if args.force_floor_N is None else args.force_floor_N)
    refs = list(args.reference or [])
    from_history = [str(r) for r in refs] == ["history"]
    if len(refs) > 1 and "history" in map(str, refs):
        raise RecordingError("--reference history: the wear history's last check is one reference; give recordings "
                             "to measure the floors from several")
    url = None
    if from_history and args.model == "dual-ema":
        from hil.cli.history_glue import history_url_for
        url = history_url_for(args.history, args.profile)
    return DiagnoseRequest(Path(args.recording), args.model, args.profile, axis, args.force_floor_N is not None,
                           None if not refs or from_history else refs[0], tuple(refs[1:]), from_history, url,
                           args.check, args.allow_other_serials, args.accept_modified)


def _read(path: Path, model: str, profile: Path | None, prefix: str = "") -> tuple[list[dict], Path | None, object]:
    """The inputs of one recording argument (hil.record.inputs), its run folder and run record."""
    from hil.record.inputs import input_entry, recording_inputs
    from hil.record.runfolder import read_record, resolve_recording

    if model != "dual-ema":
        return [input_entry(prefix + "recording", path)], None, None
    sig_path, run_dir = resolve_recording(path)
    meta = read_record(run_dir)
    return recording_inputs(sig_path, run_dir, meta, profile, prefix=prefix), run_dir, meta


def _trace(req, out) -> dict:
    """diagnosis.json's ``trace``: when, which software, and every file read, by role, with its SHA-256: the
    recording (its run record and profiles), the reference (likewise) and the history it was looked up in."""
    from hil import __version__
    from hil.record.inputs import history_input, profile_input
    from hil.record.outputs import utc_iso

    inputs, run_dir, meta = _read(req.recording, req.model, req.profile)
    if req.model == "dual-ema":  # (its check profile: the calibration's opposing force; with a reference, floors)
        snap = meta is not None and meta.profiles is not None and meta.profiles.check is not None
        inputs.append(profile_input("check_profile", req.check if out.kind == "dual_reference" else None, run_dir,
                                    snap, "check.toml"))
    ref = (out.data.get("reference") or {}).get("recording") if out.kind == "dual_reference" else req.reference
    if ref:
        inputs += _read(Path(ref), req.model, req.profile, prefix="reference_")[0]
    if req.from_history and req.history_url:
        inputs.append(history_input(req.history_url))
    return {"analysed_utc": utc_iso(), "software": {"name": "emacheck", "version": __version__}, "inputs": inputs}


def _write_report(path: Path, out, json_name: str) -> None:
    if out.kind == "dual_reference":
        from hil.report.diagnose_ref import write_dual_reference_report
        write_dual_reference_report(path, out.data, out.fits, json_name=json_name)
    elif out.kind == "axis_reference":
        from hil.report.diagnose import write_reference_report
        write_reference_report(path, out.data, json_name=json_name)
    else:
        from hil.report.diagnose import write_report
        write_report(path, out.model, out.diagnosis, out.data, json_name=json_name)


def _say_model(console, out, args: argparse.Namespace, written: Path) -> None:
    """The console's account of a diagnosis against the simulation."""
    data, d = out.data, out.diagnosis
    ident = data.get("identifiability") or {}
    words = {"no_mismatch": "no significant mismatch between simulation and recording",
             "explained": "mismatch explained", "unexplained": "mismatch NOT explained by the candidate library"}
    console.print(f"[bold]{words[d.verdict]}[/bold] ({data['diagnosis_s']:.1f} s)")
    for e in data["effects"]:
        console.print(f"  {e['words']} ({e['name']} at {e['where']}): " + ", ".join(
            f"{k} = {v} ± {e['uncertainty'][k]}" for k, v in e["parameters"].items()))
    for e in data.get("below_floor", []):
        console.print(f"  under the floor of {args.force_floor_N:g} N, not named: {e['name']} ({e['size_N']} N)")
    if data["where"]:
        console.print("  the rest lies at: " + ", ".join(data["where"]))
    for m in ident.get("cannot_tell_apart", []):
        console.print(f"  cannot tell apart {', '.join(m['terms'])}: {m['why']}; would need {m['would_separate']}")
    for m in ident.get("not_candidates", []):
        console.print(f"  not a candidate: {m['name']}: {m['why']}")
    if "mask" in data:
        console.print(f"  masked: {data['mask']['words']}")
    for loc in data["locations"][:6]:
        console.print(f"  where: {loc['channel']} {loc['t_start_s']}-{loc['t_end_s']} s ({loc['test']} test), "
                      f"{loc['regime']}")
    console.print(f"  compared in the band: {d.band.words}")
    shown = [c for c in d.measured if d.valid[c].any()]
    for head, before, after in (("residual RMS before -> after (band)", "residual_rms_before", "residual_rms_after"),
                                ("on the held-out half (never fitted)", "residual_rms_holdout_before",
                                 "residual_rms_holdout_after"),
                                ("held-out, raw band", "residual_rms_raw_holdout_before",
                                 "residual_rms_raw_holdout_after")):
        console.print(f"  {head}: " + ", ".join(f"{c} {data[before][c]} -> {data[after][c]}" for c in shown))
    console.print(f"  BIC {data['ic_before']} -> {data['ic_after']}; written {written}")


def _say_axis_reference(console, out, args: argparse.Namespace, written: Path) -> None:
    """The console's account of a single axis against a reference recording."""
    data = out.data
    head = ("effort not trusted, not diagnosed" if out.untrusted else
            "changes named" if data["effects"] else "no change above its floor")
    console.print(f"[bold]{head}[/bold] against {data['reference']['recording']} ({data['diagnosis_s']:.1f} s); "
                  f"effort: {data['conversion']}")
    console.print(f"  effort against the known load: {data['effort']['words']}")
    for c in data["changes"]:
        console.print(f"  {c['parameter']}: {c['words']}")
    for c in data.get("periodic", {}).get("components", []):
        console.print(f"  periodic {c['period_m'] * 1e3:.4g} mm: {c['words']}")
    for m in data["identifiability"]["cannot_tell_apart"]:
        console.print(f"  cannot tell apart {', '.join(m['terms'])}: {m['why']}; would need {m['would_separate']}")
    if data.get("witness"):
        console.print(f"  second witness, the tracking error: {data['witness']['words']}")
    cov = data["floor"].get("coverage")
    if cov:
        console.print(f"  floors: {cov['kind']}: {cov['words']}")
    console.print(f"  masked: {data['mask']['words']}")
    console.print(f"  written {written}")


def _say_dual_reference(console, out, args: argparse.Namespace, written: Path) -> None:
    """The console's account of a dual-EMA check against a reference."""
    data = out.data
    hist = data.get("reference_history")
    console.print(f"[bold]{'changes named' if data['effects'] else 'no change above its floor'}[/bold] against "
                  f"{data['reference']['recording']} ({data['diagnosis_s']:.1f} s)"
                  + (f"; {hist['words']}" if hist else ""))
    if data["verdict"] == "unexplained":
        console.print(f"  [bold]unexplained[/bold]: {data['unexplained']['words']}")
    for c in data["changes"]:
        console.print(f"  {c['parameter']} ({c['where']}): {c['words']}")
    console.print(f"  written {written}")


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
                                      ".mat or CSV t,q,q_ref + force|torque|current [+ load]")
    p.add_argument("--model", choices=("dual-ema", "single-axis"), default="dual-ema",
                   help="dual-EMA rig (default) or a single positioning axis (e.g. EMPS)")
    p.add_argument("--no-report", action="store_true", help="write diagnosis.json only")
    p.add_argument("--reference", metavar="HEALTHY", type=Path, action="append",
                   help="compare with this healthy recording of the same rig (single axis: same columns and sample "
                        "rate; dual-EMA: a run folder or recording, or 'history': the last check of the same "
                        "actuator serials in the wear history): the "
                        "nominal model identified on both, each parameter's change with its uncertainty, named "
                        "only above its floor. Single axis: given more than once, the recording is compared with "
                        "the first and the floors are measured from the spread of all (a reproducibility)")
    p.add_argument("--check", metavar="CHECK.toml", type=Path,
                   help="dual-EMA --reference: the check profile whose [diagnosis] floors to use (default: the "
                        "recording's run folder's snapshot, else the shipped check.toml)")
    p.add_argument("--allow-other-serials", action="store_true",
                   help="dual-EMA: compare with a reference of other actuators (serials differ); refused otherwise")
    p.add_argument("--history", metavar="URL", type=history_url_type,
                   help="--reference history: the wear history database (default: the actuation profile's "
                        "history.url, else the user's SQLite file)")
    p.add_argument("--current-law", choices=("torque", "power"),
                   help="single axis with a current column: torque (a phase current following the torque) or "
                        "power (a supply current following mechanical power at the running speed)")
    p.add_argument("--current-per-force", type=float, metavar="A_PER_N",
                   help="current per newton along the motion (default: identified on --reference's load column)")
    p.add_argument("--screw-lead-m", type=float, metavar="M",
                   help="single axis: the screw lead, m per revolution (a torque column becomes a force; a force "
                        "periodic in position is named an order of the screw)")
    p.add_argument("--position-scale-tolerance", type=float, default=0.0, metavar="FRACTION",
                   help="single axis with --screw-lead-m: the position sensor's scale tolerance (e.g. 0.05 for "
                        "+-5 %%) allowed between a period found and an order of the lead (default 0: exact)")
    p.add_argument("--force-floor-N", dest="force_floor_N", type=float, metavar="N",
                   help="relevance floor of a force change (friction, offset), N (with --reference default 75: "
                        "docs/diagnose.md; without, single axis: no floor unless stated)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
