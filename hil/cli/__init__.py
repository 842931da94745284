"""The command line of emacheck: one module per command, dispatched by argparse's ``set_defaults``.

Each command module (``dry_run``, ``run``, ``profile``, ``simulate``,
``analyze``, ``serv``, ``diagnose``, ``history``, ``sim_serve``) registers its sub-parser with a
``register(sub)`` function and keeps its heavy imports (analysis, plotting,
python-control, numba) inside the command, so ``emacheck run`` loads no more
than its cyclic loop needs before the first SYNC. Shared pieces, one module per concern:
:mod:`hil.cli.args` (exit codes, the options and their types), :mod:`hil.cli.bus` (opening a
CAN bus), :mod:`hil.cli.console` (the terminal, progress, the result table),
:mod:`hil.cli.history_glue` (the wear history from the command line) and :mod:`hil.cli.check`
(running a check and turning it into a result); where outputs go and loading a recording are
below, in :mod:`hil.record.outputs` and :mod:`hil.record.recording`.

Exit status (:class:`hil.cli.args.ExitCode`): 0 pass, 1 fail (backlash
above B_spec), 2 aborted, 3 bad input (profile, recording, EDS, arguments,
a history database URL, file or login that cannot be used), 4 internal error,
5 inconclusive, 6 not ready (commission). Any error, expected or not, is one line on the console;
an unexpected one leaves its traceback in a file whose path that line names.
"""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

from hil import __version__
from hil.cli import analyze, commission, diagnose, dry_run, history, profile, run, serv, sim_serve, simulate
from hil.cli.args import EPILOG, ExitCode
from hil.cli.stopping import CHECK_COMMANDS, StopOnSignals

#: The commands in the order ``--help`` lists them.
COMMANDS = (dry_run, run, commission, profile, simulate, analyze, serv, diagnose, history, sim_serve)


class _Parser(argparse.ArgumentParser):
    """argparse with the documented exit status for bad arguments (3, not argparse's 2)."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(ExitCode.INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The whole command line (every sub-command registered by its module)."""
    ap = _Parser(
        prog="emacheck",
        description="Maintenance check of a dual-EMA flight-control actuation: LVDT calibration "
                    "under opposing force, force-fight excursions to +-15 % of limit load, then "
                    "backlash and stiffness by BLFmaint (Schallert et al.).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"emacheck {__version__}")
    sub = ap.add_subparsers(dest="cmd", metavar="COMMAND", parser_class=_Parser)
    for module in COMMANDS:
        module.register(sub)
    return ap


_PARSER: argparse.ArgumentParser | None = None


def _parser() -> argparse.ArgumentParser:
    """:func:`build_parser`'s parser, built on the first :func:`main` of this process and kept: parsing
    never changes it (every default is a constant, a namespace is new per call), and building it costs
    ~2 ms, which the tests' hundreds of ``main()`` calls paid each time."""
    global _PARSER
    if _PARSER is None:
        _PARSER = build_parser()
    return _PARSER


def _current(handler):
    """The command's handler as its module names it now (``module.cmd_x``), not as the kept parser
    bound it: a handler replaced after the parser was built (a test's ``monkeypatch``) is the one run."""
    module = sys.modules.get(getattr(handler, "__module__", None) or "")
    return getattr(module, getattr(handler, "__name__", ""), handler) if module is not None else handler


def _internal_error(exc: BaseException) -> int:
    """One line for an unexpected exception; its traceback goes to a file that line names.

    The file is new for every error (``emacheck-internal-error-<local time>-<random>.txt``, created
    exclusively by :func:`tempfile.mkstemp`): two errors within one second keep both tracebacks.
    """
    import datetime as _dt
    import os
    import tempfile
    import traceback

    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    try:
        fd, where = tempfile.mkstemp(prefix=f"emacheck-internal-error-{stamp}-", suffix=".txt")
        with os.fdopen(fd, "w") as fh:
            fh.write("".join(traceback.format_exception(exc)))
        saved = f"; traceback in {where}"
    except OSError:
        saved = ""
    print(f"emacheck: internal error: {type(exc).__name__}: {exc}{saved}", file=sys.stderr)
    return ExitCode.INTERNAL


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns its exit status (see the module docstring)."""
    from blf.errors import BlfError
    from hil.canopen.errors import CanopenError, EdsError
    from hil.errors import EmacheckError, InterfaceError, ProfileError, RecordingError

    ap = _parser()
    args = ap.parse_args(argv)
    if args.cmd is None:
        ap.print_help()
        return ExitCode.INPUT
    try:
        if args.cmd in CHECK_COMMANDS:
            with StopOnSignals():
                return int(_current(args.handler)(args))
        return int(_current(args.handler)(args))
    except (ProfileError, RecordingError, EdsError, InterfaceError) as exc:
        print(f"emacheck: error: {exc}", file=sys.stderr)
        return ExitCode.INPUT
    except (EmacheckError, CanopenError, BlfError) as exc:
        print(f"emacheck: error: {exc}", file=sys.stderr)
        # an error may say it is about bad input (the wear history's URL, file or login: exit 3)
        return ExitCode.INPUT if getattr(exc, "bad_input", False) else ExitCode.ABORTED
    except KeyboardInterrupt:
        print("emacheck: interrupted", file=sys.stderr)
        return ExitCode.ABORTED
    except OSError as exc:
        if not _about_an_input(exc, args):
            return _internal_error(exc)
        # a reader let it through (each should say it itself): the file is one the command was given
        print(f"emacheck: error: {exc.filename}: cannot be read: {exc.strerror or exc}", file=sys.stderr)
        return ExitCode.INPUT
    except Exception as exc:  # noqa: BLE001 - the catch-all: one line and exit 4, never a traceback
        return _internal_error(exc)


def entry() -> NoReturn:
    """The process's entry point (``emacheck``, ``python -m hil``): :func:`main` with the process's own
    arguments, then exit with its status.

    Before the interpreter exits, the heap is frozen (``gc.freeze``): the interpreter's final garbage
    collections then skip it, and its reference cycles are left to the end of the process, which
    returns all its memory at once. They took ~0.25 s after a dry-run (~140 000 objects with numba's,
    scipy's and matplotlib's modules; 0.03 s frozen). Everything else of the exit is as before: the
    atexit handlers run, objects freed by reference counting are freed (a file closed by its last
    reference is flushed), the console's streams are flushed; every record file is closed by its
    writer before :func:`main` returns. Only here: :func:`main` called in a process that goes on (the
    tests) leaves the collector as it was.
    """
    import gc

    status = main()
    gc.freeze()
    sys.exit(status)


#: the arguments that name files a command reads (never one it writes: --out, --timing-json)
INPUT_ARGS = ("recording", "profile", "check", "sim", "eds", "calibration", "folders", "sync_profile")
#: the files of a run folder a command reads (its run record is read by hil.record.runfolder.read_record, which
#: names its own errors)
RUN_FOLDER_FILES = ("signals.csv", "can.log", "result.json")


def _about_an_input(exc: OSError, args: argparse.Namespace) -> bool:
    """Whether ``exc`` is about a file the command reads: one of its input arguments, or a run folder's
    file read from an input folder (not an output's, which lie deeper)."""
    from pathlib import Path

    if not exc.filename:
        return False
    failed = Path(exc.filename).absolute()
    for name in INPUT_ARGS:
        given = getattr(args, name, None)
        for p in given if isinstance(given, list) else [given]:
            if p is None:
                continue
            p = Path(p).absolute()
            if failed == p or (failed.parent == p and failed.name in RUN_FOLDER_FILES):
                return True
    return False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
