"""A flag of ``emacheck run`` on its boundary: taken, or refused by argparse naming it.

Without ``--arm``, run refuses to move anything after parsing: exit 3 either way, so the messages tell
which (a value taken reaches the refusal; a value refused names the flag, with no traceback).
"""

from __future__ import annotations

import pytest

from hil.cli import main


def assert_run_flag(args: list[str], flag: str, ok: bool, capsys) -> None:
    """``emacheck run ARGS`` (no --arm): ``flag``'s value taken when ``ok``, else refused naming ``flag``."""
    if ok:
        rc = main(args)
    else:
        with pytest.raises(SystemExit) as exc:
            main(args)
        rc = exc.value.code
    err = capsys.readouterr()
    assert rc == 3
    if ok:
        assert f"argument {flag}" not in err.err and "refusing to move anything" in err.out
    else:
        assert f"argument {flag}" in err.err and "Traceback" not in err.err


def assert_flag(args: list[str], flag: str, value, capsys) -> None:
    """``emacheck ARGS`` parsed only (any command): ``flag`` taken as ``value`` (its parsed value, looked up
    under the flag's name), or, with ``value`` None, refused by argparse naming ``flag`` (exit 3, no
    traceback). For flags whose command would run on when the value is taken (dry-run, sim-serve)."""
    from hil.cli import build_parser

    if value is not None:
        ns = build_parser().parse_args(args)
        assert getattr(ns, flag.lstrip("-").replace("-", "_")) == value
        return
    with pytest.raises(SystemExit) as exc:
        main(args)
    err = capsys.readouterr().err
    assert exc.value.code == 3
    assert f"argument {flag}" in err and "Traceback" not in err
