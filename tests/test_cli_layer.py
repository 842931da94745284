"""The command layer itself: dispatch, exit status of bad arguments, the catch-all, the help."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from hil.canopen.process import MEASURED_CHANNELS, Sample
from hil.cli import COMMANDS, build_parser, main
from hil.cli.args import ExitCode
from hil.record.runfolder import Signals
from hil.record.signals_csv import COLUMN_UNITS, SIGNAL_COLUMNS


def test_every_command_registers_a_handler():
    ap = build_parser()
    names = {"dry-run", "run", "commission", "profile", "simulate", "analyze", "serv", "diagnose", "history",
             "sim-serve"}
    sub = next(a for a in ap._actions if a.dest == "cmd")  # argparse's sub-parser action
    assert set(sub.choices) == names and len(COMMANDS) == len(names)
    for name, p in sub.choices.items():
        assert callable(p.get_default("handler")), name


@pytest.mark.parametrize("argv, words", [
    (["dry-run", "--seed", "-5"], "negative"),
    (["dry-run", "--seed", "abc"], "not an integer"),
    (["analyze"], "the following arguments are required: RECORDING"),
    (["no-such-command"], "invalid choice"),
    (["run", "--channel", "can0"], "--interface"),
])
def test_bad_arguments_exit_3_with_one_message(argv, words, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == ExitCode.INPUT == 3
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_no_command_prints_help_and_exits_3(capsys):
    assert main([]) == ExitCode.INPUT
    assert "dry-run" in capsys.readouterr().out


def test_an_unexpected_exception_is_one_line_and_exit_4(monkeypatch, capsys, tmp_path):
    import hil.cli.analyze as cmd

    def boom(args):
        raise ZeroDivisionError("division by zero in the middle of something")

    monkeypatch.setattr(cmd, "cmd_analyze", boom)  # register() binds the handler when main() builds the parser
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    rc = main(["analyze", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == ExitCode.INTERNAL == 4
    assert len(err) == 1 and err[0].startswith("emacheck: internal error: ZeroDivisionError: division by zero")
    saved = list(tmp_path.glob("emacheck-internal-error-*.txt"))
    assert len(saved) == 1 and "Traceback" in saved[0].read_text() and str(saved[0]) in err[0]


def test_a_known_error_of_each_root_gets_its_exit_status(monkeypatch, capsys):
    import hil.cli.analyze as cmd
    from blf.errors import AnalysisError
    from hil.canopen.errors import EdsError
    from hil.canopen.sdo import SdoAbortError
    from hil.errors import RecordingError

    for exc, code in ((RecordingError("x.csv: line 3: bad"), ExitCode.INPUT), (EdsError("bad.eds: no"), ExitCode.INPUT),
                      (SdoAbortError(2, 0x6040, 0, 0x06090030), ExitCode.ABORTED),
                      (AnalysisError("no distinct backlash region"), ExitCode.ABORTED)):
        def raise_it(args, exc=exc):
            raise exc
        monkeypatch.setattr(cmd, "cmd_analyze", raise_it)
        assert main(["analyze", "x"]) == code
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(exc) in err


def test_the_seven_measured_channels_are_declared_once():
    assert [f.name for f in dataclasses.fields(Sample)] == [f"{n}_{u}" for n, u in MEASURED_CHANNELS]
    assert SIGNAL_COLUMNS == tuple(n for n, _ in MEASURED_CHANNELS) and COLUMN_UNITS == dict(MEASURED_CHANNELS)
    assert [f.name for f in dataclasses.fields(Signals)][:7] == list(SIGNAL_COLUMNS)


def test_python_dash_m_runs_the_command_line():
    """``python -m hil.cli`` (what the vcan stage and the benchmarks start) and ``python -m hil``."""
    import subprocess
    import sys

    for mod in ("hil.cli", "hil"):
        r = subprocess.run([sys.executable, "-m", mod, "--version"], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and r.stdout.startswith("emacheck "), (mod, r.stdout, r.stderr)


def test_the_entry_point_exits_with_the_commands_status(tmp_path):
    """``python -m hil`` and ``python -m hil.cli`` go through :func:`hil.cli.entry` (main, then the heap
    frozen before exit): a command's documented status reaches the shell, its error one line, no traceback."""
    import subprocess
    import sys

    missing = tmp_path / "absent.csv"
    for mod in ("hil", "hil.cli"):
        r = subprocess.run([sys.executable, "-m", mod, "analyze", str(missing)], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 3, (mod, r.returncode, r.stderr)
        assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0 and str(missing) in r.stderr


def test_no_help_prints_a_doubled_percent_sign():
    """argparse formats ``help=`` strings (``%%`` is a percent sign there) but not descriptions: every command's
    ``--help`` and the top-level one print ``%`` once."""
    parser = build_parser()
    texts = {"emacheck": parser.format_help()}
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    texts |= {name: p.format_help() for name, p in sub.choices.items()}
    assert "+-15 % of limit load" in texts["emacheck"] and "95 % interval" in texts["history"]
    assert not [name for name, text in texts.items() if "%%" in text]
