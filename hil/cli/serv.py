"""``emacheck serv``: BLFserv (paper 2.2) on a normal-operation recording; serv.json and serv_report.html."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from blf.signals import CHANNELS
from hil.cli.common import actuation_for, add_parser, add_recording_args, load_recording, read_meta
from hil.errors import RecordingError
from hil.runfolder import resolve_recording, write_json_atomic


def print_summary(console: Console, data: dict, out_dir: Path) -> None:
    """The BLFserv result as a table on the console, truth beside it when known."""
    from hil.report.shell import fmt

    truth = data.get("truth")
    tab = Table(title=f"BLFserv ({data['method']})")
    for col in ("channel", "backlash mm", "traversals", "paper mm", "truth mm" if truth else None):
        if col:
            tab.add_column(col, justify="right")
    for ch in CHANNELS:
        b = data["backlash_mm"][ch]
        row = [ch, "not traversed" if b is None else f"{b:.4f}", str(data["traversals"][ch]),
               fmt(data["backlash_paper_mm"][ch])]
        if truth:
            row.append(fmt(truth["backlash_mm"][ch]))
        tab.add_row(*row)
    console.print(tab)
    console.print(f"LVDT calibration: {data['calibration']['source']}")
    for n in data["notes"]:
        console.print(f"[yellow]note:[/yellow] {n}")
    console.print(f"serv.json and serv_report.html in {out_dir}")


def cmd_serv(args: argparse.Namespace) -> int:
    """``emacheck serv RECORDING [--profile ACTUATION.toml] [--out DIR] [--calibration RESULT.json]
    [--method improved|paper] [--no-report]``."""
    # imported here: python-control, numba and scipy.signal cost seconds (not for other commands)
    from blf.errors import AnalysisError, InputError
    from blf.serv import METHODS
    from hil.analysis.serv import analyse, choose_calibration, serv_dict
    from hil.report.serv import write_serv_report

    console = Console()
    t0 = time.perf_counter()
    method = getattr(args, "method", None) or "improved"
    if method not in METHODS:
        raise RecordingError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    sig_path, run_dir = resolve_recording(args.recording)
    meta = read_meta(run_dir)
    act = actuation_for(args.profile, meta)
    try:
        sig = load_recording(sig_path, act, meta)
        corr = choose_calibration(sig, act, run_dir, getattr(args, "calibration", None))
        an = analyse(sig, act, corr, method)
    except (InputError, AnalysisError) as exc:
        raise RecordingError(f"{sig_path}: {exc}") from None
    truth = meta.get("truth") if isinstance(meta, dict) else None
    out = Path(args.out) if args.out is not None else (run_dir if run_dir is not None else sig_path.parent)
    out.mkdir(parents=True, exist_ok=True)
    data = serv_dict(an, truth, str(sig_path))
    data["analysis_s"] = round(time.perf_counter() - t0, 3)
    write_json_atomic(out / "serv.json", data)
    if not getattr(args, "no_report", False):
        write_serv_report(out / "serv_report.html", an, data, act)
    print_summary(console, data, out)
    return 0


def register(sub) -> None:
    p = add_parser(sub, "serv", handler=cmd_serv, help="BLFserv: in-service backlash from a normal-operation recording",
                   description="Measure internal and external backlash from the jumps of the position "
                               "differences during normal operation (paper 2.2, no force sensors): a run "
                               "folder, a signals CSV (t,phi1,phi2,s1,s2,F1,F2) or a raw CAN log. Writes "
                               "serv.json and serv_report.html (paper Fig. 8, error budget of paper 2.3).")
    add_recording_args(p, "serv.json and serv_report.html")
    p.add_argument("--calibration", metavar="RESULT.json", type=Path,
                   help="LVDT pitch and offset from a maintenance check's result.json")
    p.add_argument("--method", choices=("improved", "paper"), default="improved",
                   help="backlash from plateau levels (improved, default) or the paper's Delta D")
    p.add_argument("--no-report", action="store_true", help="write serv.json only, no HTML report")
