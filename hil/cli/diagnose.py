"""``emacheck diagnose``: simulation versus recording; locate the mismatch, name the missing physics, fit it."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hil.cli.args import add_parser, add_recording_args, history_url_type
from hil.cli.console import make_console
from hil.record.outputs import outputs_for


def cmd_diagnose(args: argparse.Namespace) -> int:
    """``emacheck diagnose RECORDING [--profile] [--out] [--model]``."""

    from blf.diagnose import diagnose
    from blf.errors import AnalysisError, InputError
    from hil.analysis.diagnose.load import load_model
    from hil.analysis.diagnose.results import diagnosis_dict
    from hil.analysis.diagnose.single_axis import single_axis_model
    from hil.errors import RecordingError
    from hil.report.diagnose import write_report
    console = make_console()
    path = Path(args.recording)
    opts = _axis_options(args)
    if args.reference is not None:
        return _cmd_reference(args, path, opts, console)
    t0 = time.perf_counter()
    axis = _single_axis(args, path)  # read once: the effort check and the model are made of the same arrays
    read_s = time.perf_counter() - t0
    effort = _model_effort(args, axis, opts)
    if effort is not None and not effort["trusted"]:
        from hil.analysis.diagnose.results import untrusted_dict
        outputs = outputs_for(args.out, path, path if path.is_dir() else None, "diagnose",
                              ("diagnosis.json", "diagnosis_report.html"))
        outputs.write_json("diagnosis.json", untrusted_dict(effort))
        console.print(f"[bold]effort not trusted, not diagnosed[/bold]: {effort['words']}; written "
                      f"{outputs.path('diagnosis.json')}")
        return 5  # inconclusive: the reason is in diagnosis.json (README, Exit status)
    t0 = time.perf_counter() - read_s  # (the diagnosis's time includes reading the recording, as it did)
    try:
        model, period = single_axis_model(axis, opts) if axis is not None else \
            load_model(path, args.model, args.profile, opts)
        d = diagnose(model, period, progress=None if args.quiet else (lambda s: console.print(f"  {s}")))
    except (InputError, AnalysisError) as exc:  # the recording does not support a diagnosis: bad input
        raise RecordingError(f"{path}: cannot be diagnosed: {exc}") from None
    secs = time.perf_counter() - t0
    # the folder only once there is something to write into it (a refused recording leaves none)
    outputs = outputs_for(args.out, path, path if path.is_dir() else None, "diagnose",
                          ("diagnosis.json", "diagnosis_report.html"))
    data = diagnosis_dict(d, args.model, secs)
    from hil.analysis.diagnose.results import identifiability_dict
    ident = identifiability_dict(model)
    if args.model == "single-axis" and args.force_floor_N is not None:
        from hil.analysis.diagnose.against_model import apply_force_floor, effect_sizes_N
        data = apply_force_floor(data, effect_sizes_N(model, d), args.force_floor_N)
    if ident is not None:
        mask = ident.pop("mask", None)
        data["identifiability"] = ident
        if mask is not None:
            data["mask"] = mask
    if effort is not None:
        data["effort"] = effort
    outputs.write_json("diagnosis.json", data)
    if not args.no_report:
        outputs.write_with("diagnosis_report.html", lambda p: write_report(
            p, model, d, data, json_name=outputs.path("diagnosis.json").name))
    words = {"no_mismatch": "no significant mismatch between simulation and recording",
             "explained": "mismatch explained", "unexplained": "mismatch NOT explained by the candidate library"}
    console.print(f"[bold]{words[d.verdict]}[/bold] ({secs:.1f} s)")
    for e in data["effects"]:
        console.print(f"  {e['words']} ({e['name']} at {e['where']}): " + ", ".join(
            f"{k} = {v} ± {e['uncertainty'][k]}" for k, v in e["parameters"].items()))
    for e in data.get("below_floor", []):
        console.print(f"  under the floor of {args.force_floor_N:g} N, not named: {e['name']} ({e['size_N']} N)")
    if data["where"]:
        console.print("  the rest lies at: " + ", ".join(data["where"]))
    for m in (ident or {}).get("cannot_tell_apart", []):
        console.print(f"  cannot tell apart {', '.join(m['terms'])}: {m['why']}; would need {m['would_separate']}")
    for m in (ident or {}).get("not_candidates", []):
        console.print(f"  not a candidate: {m['name']}: {m['why']}")
    if "mask" in data:
        console.print(f"  masked: {data['mask']['words']}")
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


def _single_axis(args: argparse.Namespace, path: Path):
    """The single-axis recording (:func:`hil.analysis.diagnose.single_axis.read_axis`), read once for the effort
    check and the model; None for the dual-EMA model."""
    if args.model != "single-axis":
        return None
    from hil.analysis.diagnose.single_axis import read_axis
    return read_axis(path)


def _model_effort(args: argparse.Namespace, axis, opts):
    """Single axis (``axis``: its recording) with a load column, no reference: whether its effort sees the
    load (None otherwise: no load column, an EMPS ``.mat`` has none)."""
    if axis is None:
        return None
    from hil.analysis.diagnose.single_axis import AxisOptions, model_effort_check
    floor = args.force_floor_N if args.force_floor_N is not None else AxisOptions().force_floor_N
    import dataclasses
    return model_effort_check(axis, dataclasses.replace(opts, force_floor_N=floor))


def _axis_options(args: argparse.Namespace):
    from hil.analysis.diagnose.single_axis import FORCE_FLOOR_N, AxisOptions
    from hil.errors import RecordingError
    for name in ("current_per_force", "screw_lead_m", "force_floor_N"):
        val = getattr(args, name)
        if val is not None and not val > 0:
            raise RecordingError(f"--{name.replace('_', '-')}: must be > 0; got {val}")
    return AxisOptions(current_law=args.current_law, current_a_per_N=args.current_per_force,
                       screw_lead_m=args.screw_lead_m,
                       force_floor_N=FORCE_FLOOR_N if args.force_floor_N is None else args.force_floor_N)


def _cmd_reference(args: argparse.Namespace, path: Path, opts, console) -> int:
    """``--reference``: single axis against a healthy recording; everything checked before anything is written."""
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.errors import RecordingError
    if str(args.reference) == "history":
        if args.model != "dual-ema":
            raise RecordingError("--reference history: the wear history holds dual-EMA checks; a single axis needs "
                                 "its reference recording")
        return _cmd_dual_reference(args, path, console)
    if not Path(args.reference).exists():
        raise RecordingError(f"--reference {args.reference}: no such file")
    if args.model != "single-axis":
        return _cmd_dual_reference(args, path, console)
    t0 = time.perf_counter()
    data = reference_diagnosis(path, Path(args.reference), opts)
    data["diagnosis_s"] = round(time.perf_counter() - t0, 2)
    outputs = outputs_for(args.out, path, None, "diagnose", ("diagnosis.json", "diagnosis_report.html"))
    outputs.write_json("diagnosis.json", data)
    if not args.no_report:
        from hil.report.diagnose import write_reference_report
        outputs.write_with("diagnosis_report.html", lambda p: write_reference_report(
            p, data, json_name=outputs.path("diagnosis.json").name))
    untrusted = data["verdict"] == "untrusted_effort"
    head = ("effort not trusted, not diagnosed" if untrusted else
            "changes named" if data["effects"] else "no change above its floor")
    console.print(f"[bold]{head}[/bold] against {args.reference} ({data['diagnosis_s']:.1f} s); effort: "
                  f"{data['conversion']}")
    console.print(f"  effort against the known load: {data['effort']['words']}")
    for c in data["changes"]:
        console.print(f"  {c['parameter']}: {c['words']}")
    for m in data["identifiability"]["cannot_tell_apart"]:
        console.print(f"  cannot tell apart {', '.join(m['terms'])}: {m['why']}; would need {m['would_separate']}")
    console.print(f"  masked: {data['mask']['words']}")
    console.print(f"  written {outputs.path('diagnosis.json')}")
    return 5 if untrusted else 0  # inconclusive: the reason is in diagnosis.json (README, Exit status)


def _cmd_dual_reference(args: argparse.Namespace, path: Path, console) -> int:
    """``--reference`` with the dual-EMA model: each nominal parameter and library effect against the reference's."""
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    from hil.analysis.diagnose.floors import floors_for
    from hil.analysis.diagnose.history_reference import reference_from_history, refuse_other_serials
    t0 = time.perf_counter()
    hist = None
    if str(args.reference) == "history":
        from hil.cli.history_glue import history_url_for
        ref, hist = reference_from_history(path, history_url_for(args.history, args.profile), args.allow_other_serials)
    else:
        ref = Path(args.reference)
    serials = refuse_other_serials(path, ref, args.allow_other_serials)
    floors, source = floors_for(path, args.profile, args.check)
    data, fits = dual_reference_diagnosis(path, ref, args.profile, floors, source)
    data["serials"] = serials
    if hist is not None:
        data["reference_history"] = hist
    data["diagnosis_s"] = round(time.perf_counter() - t0, 2)
    outputs = outputs_for(args.out, path, None, "diagnose", ("diagnosis.json", "diagnosis_report.html"))
    outputs.write_json("diagnosis.json", data)
    if not args.no_report:
        from hil.report.diagnose_ref import write_dual_reference_report
        outputs.write_with("diagnosis_report.html", lambda p: write_dual_reference_report(
            p, data, fits, json_name=outputs.path("diagnosis.json").name))
    console.print(f"[bold]{'changes named' if data['effects'] else 'no change above its floor'}[/bold] against "
                  f"{ref} ({data['diagnosis_s']:.1f} s)" + (f"; {hist['words']}" if hist else ""))
    if data["verdict"] == "unexplained":
        console.print(f"  [bold]unexplained[/bold]: {data['unexplained']['words']}")
    for c in data["changes"]:
        console.print(f"  {c['parameter']} ({c['where']}): {c['words']}")
    console.print(f"  written {outputs.path('diagnosis.json')}")
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
                                      ".mat or CSV t,q,q_ref + force|torque|current [+ load]")
    p.add_argument("--model", choices=("dual-ema", "single-axis"), default="dual-ema",
                   help="dual-EMA rig (default) or a single positioning axis (e.g. EMPS)")
    p.add_argument("--no-report", action="store_true", help="write diagnosis.json only")
    p.add_argument("--reference", metavar="HEALTHY", type=Path,
                   help="compare with this healthy recording of the same rig (single axis: same columns and sample "
                        "rate; dual-EMA: a run folder or recording, or 'history': the last check of the same "
                        "actuator serials in the wear history): the "
                        "nominal model identified on both, each parameter's change with its uncertainty, named "
                        "only above its floor")
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
                   help="single axis with a torque column: the screw lead, m per revolution")
    p.add_argument("--force-floor-N", dest="force_floor_N", type=float, metavar="N",
                   help="relevance floor of a force change (friction, offset), N (with --reference default 75: "
                        "docs/diagnose.md; without, single axis: no floor unless stated)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
