"""Command line of emacheck.

Exit status: 0 pass, 1 fail (backlash above B_spec), 2 aborted, 3 bad input
(profile, recording, arguments), 4 internal error.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path

from hil import __version__
from hil.errors import EmacheckError, ProfileError, RecordingError

EXIT_PASS, EXIT_FAIL, EXIT_ABORTED, EXIT_INPUT, EXIT_INTERNAL = 0, 1, 2, 3, 4

_EPILOG = """\
exit status: 0 pass, 1 fail (backlash above B_spec), 2 check aborted
(analyze: also a run that did not finish, reported incomplete),
3 bad input (profile, recording, arguments), 4 internal error.
Profiles default to the ones shipped in the package (profiles/*.toml)."""


def _default_out(kind: str) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("emacheck-runs") / f"{stamp}-{kind}"


def _add_profile_args(p: argparse.ArgumentParser, sim: bool) -> None:
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (gear ratio, stroke, F_limit, B_spec, SYNC period)")
    p.add_argument("--check", metavar="CHECK.toml", type=Path,
                   help="check profile (sweep, opposing force, force fight, safety limits)")
    if sim:
        p.add_argument("--sim", metavar="SIMRIG.toml", type=Path,
                       help="simulated-rig profile (physical parameters, sensor errors, seed)")
        p.add_argument("--seed", type=int, help="noise seed (default: the simulated-rig profile's)")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="emacheck",
        description="Maintenance check of a dual-EMA flight-control actuation: LVDT calibration "
                    "under opposing force, force-fight excursions to +-15 %% of limit load, then "
                    "backlash and stiffness by BLFmaint (Schallert et al.).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"emacheck {__version__}")
    sub = ap.add_subparsers(dest="cmd", metavar="COMMAND")

    p = sub.add_parser("dry-run", help="the check over CANopen against two simulated drives (the main job)",
                       description="Run the complete check through the CANopen master against two simulated "
                                   "CiA 402 drives on an in-process virtual CAN bus, log every frame, analyse "
                                   "and report, with the simulator's truth beside the measurement.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-dry-run)")
    _add_profile_args(p, sim=True)
    p.add_argument("--realtime", action="store_true", help="pace SYNC at the SYNC period (default: as fast as possible)")
    p.add_argument("--quiet", action="store_true", help="no progress display")

    p = sub.add_parser("run", help="the check on real drives (needs --arm)",
                       description="Run the check on two real CiA 402 drives on a CAN bus: the same code path "
                                   "as dry-run, SYNC on the wall clock (kernel-timed on SocketCAN).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--interface", required=True, help="python-can interface, e.g. socketcan, pcan, kvaser")
    p.add_argument("--channel", required=True, help="channel, e.g. can0 or vcan0")
    p.add_argument("--bitrate", type=int, metavar="BPS", help="bit rate (default: the actuation profile's)")
    p.add_argument("--arm", action="store_true", help="confirm that the actuators may move")
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-run)")
    _add_profile_args(p, sim=False)
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run the cyclic loop under SCHED_FIFO priority N (1-99, needs the privilege; "
                        "default 0: normal scheduling); analysis and report run at normal priority "
                        "after it. Memory is locked either way (best effort).")

    p = sub.add_parser("sim-serve", help="the two simulated drives on a CAN bus (until SIGINT/SIGTERM)",
                       description="Serve two simulated CiA 402 drives on a python-can bus (e.g. socketcan "
                                   "vcan0) for `emacheck run` in another process; the plant steps on each "
                                   "SYNC received. SIGINT/SIGTERM end it cleanly.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--interface", required=True, help="python-can interface, e.g. socketcan, virtual")
    p.add_argument("--channel", required=True, help="channel, e.g. vcan0")
    p.add_argument("--bitrate", type=int, metavar="BPS", help="bit rate (default: the actuation profile's)")
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path, help="actuation profile (node ids, EDS)")
    p.add_argument("--sim", metavar="SIMRIG.toml", type=Path, help="simulated-rig profile")
    p.add_argument("--seed", type=int, help="noise seed (default: the simulated-rig profile's)")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run under SCHED_FIFO priority N (1-99; default 0: normal scheduling)")

    p = sub.add_parser("simulate", help="run the check on the simulated rig, no CAN in between",
                       description="Run the whole check against the simulated plant directly "
                                   "(no CANopen), then analyse it and write the run folder and report.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", metavar="DIR", type=Path, help="run folder (default emacheck-runs/<time>-simulate)")
    _add_profile_args(p, sim=True)
    p.add_argument("--quiet", action="store_true", help="no progress display")

    p = sub.add_parser("analyze", help="BLFmaint on a run folder or a signals CSV",
                       description="Recompute calibration, backlash and stiffness from a run folder "
                                   "or a bare signals CSV (columns t,phi1,phi2,s1,s2,F1,F2 in s, rad, mm, N). "
                                   "Without a step column the calibration sweeps and force-fight "
                                   "segments are found automatically.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="RUN_FOLDER|SIGNALS.csv", type=Path)
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (default: the run folder's snapshot, else the shipped one)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="where result.json and report.html go (default: the run folder, or next to the CSV)")

    p = sub.add_parser("serv", help="BLFserv: in-service backlash from a normal-operation recording",
                       description="Measure internal and external backlash from the jumps of the position "
                                   "differences during normal operation (paper 2.2, no force sensors): a run "
                                   "folder, a signals CSV (t,phi1,phi2,s1,s2,F1,F2) or a raw CAN log. Writes "
                                   "serv.json and serv_report.html (paper Fig. 8, error budget of paper 2.3).",
                       epilog="exit status: 0 done, 3 bad input (profile, recording, arguments).",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="RECORDING", type=Path, help="run folder, signals CSV or CAN log (*.log)")
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (default: the run folder's snapshot, else the shipped one)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="where serv.json and serv_report.html go (default: the run folder, or next to the file)")
    p.add_argument("--calibration", metavar="RESULT.json", type=Path,
                   help="LVDT pitch and offset from a maintenance check's result.json")
    p.add_argument("--method", choices=("improved", "paper"), default="improved",
                   help="backlash from plateau levels (improved, default) or the paper's Delta D")
    p.add_argument("--no-report", action="store_true", help="write serv.json only, no HTML report")

    p = sub.add_parser("diagnose", help="simulation versus recording: locate the mismatch, name the missing physics",
                       description="Replay a recording through the simulation driven by the measured motor "
                                   "angles, fit the nominal model, localise where they differ, screen a library "
                                   "of candidate physics terms, refit the best and accept it only if BIC and a "
                                   "held-out half of the recording both improve. Writes diagnosis.json and "
                                   "diagnosis_report.html.",
                       epilog="exit status: 0 done, 3 bad input (profile, recording, arguments).",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="RECORDING", type=Path,
                   help="run folder, signals CSV (t,phi1,phi2,s1,s2,F1,F2), CAN log; single-axis: .mat or "
                        "CSV t,q,q_ref,force")
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path, help="actuation profile (gear ratio)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="where diagnosis.json and diagnosis_report.html go (default: the run folder, or next to the file)")
    p.add_argument("--model", choices=("dual-ema", "single-axis"), default="dual-ema",
                   help="dual-EMA rig (default) or a single positioning axis (e.g. EMPS)")
    p.add_argument("--no-report", action="store_true", help="write diagnosis.json only")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.cmd is None:
        ap.print_help()
        return EXIT_INPUT
    try:
        if args.cmd == "dry-run":
            from hil.commands import cmd_dry_run
            return cmd_dry_run(args)
        if args.cmd == "run":
            from hil.commands import cmd_run
            return cmd_run(args)
        if args.cmd == "sim-serve":
            from hil.serve import cmd_sim_serve
            return cmd_sim_serve(args)
        if args.cmd == "simulate":
            from hil.commands import cmd_simulate
            return cmd_simulate(args)
        if args.cmd == "serv":
            from hil.serv_cmd import cmd_serv
            return cmd_serv(args)
        if args.cmd == "diagnose":
            from hil.diagnose_cmd import cmd_diagnose
            return cmd_diagnose(args)
        if args.cmd == "analyze":
            from hil.commands import cmd_analyze
            return cmd_analyze(args)
    except (ProfileError, RecordingError) as exc:
        print(f"emacheck: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except EmacheckError as exc:
        print(f"emacheck: error: {exc}", file=sys.stderr)
        return EXIT_ABORTED
    except KeyboardInterrupt:
        print("emacheck: interrupted", file=sys.stderr)
        return EXIT_ABORTED
    ap.error(f"unknown command {args.cmd}")  # pragma: no cover
    return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
