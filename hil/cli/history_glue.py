"""The wear history from the command line: where a result is recorded (``--history``, the profile, the
user's file), what the record says of the installation, a foreign database refused before anything is done,
and the recording after a command wrote its result (docs/history.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.profile.config import Actuation
from hil.record.runrecord import INSTALLATION_KEYS, Installation, RunRecord


def installation(args: argparse.Namespace, act: Actuation, meta: RunRecord | None = None) -> Installation:
    """Aircraft, position, rig, flight hours and cycles of a check (what the history records about where
    and when it was made): the flags, else the run's record, else the actuation profile's ``[history]``
    (None where nobody said)."""
    held = meta.installation if meta is not None and meta.installation is not None else Installation()
    out = {}
    for k in INSTALLATION_KEYS:
        v = getattr(args, k, None)
        if v is None:
            v = getattr(held, k)
        if v is None and k in ("aircraft", "position", "rig"):
            v = getattr(act.history, k) or None
        out[k] = v
    return Installation(**out)


def history_url(url: str | None, act: Actuation) -> str:
    """The wear history's database: ``url`` (``--history``), else the actuation profile's
    ``history.url``, else the user's SQLite file."""
    if url:
        return url
    if act.history.url:
        return act.history.url
    from hil.profile.history_url import default_url

    return default_url()


def refuse_foreign_history(args: argparse.Namespace, act: Actuation, *, simulated: bool = False) -> None:
    """Before a command that records does anything: a history database given to it (``--history URL``,
    else the actuation profile's ``history.url``) that is an SQLite file of another program is refused
    (exit 3) and left untouched (:mod:`hil.history.guard`; the standard library's sqlite3 only). A
    ``simulated`` check records only with ``--history``."""
    explicit = getattr(args, "history", None)
    if getattr(args, "no_history", False) or (simulated and explicit is None):
        return
    url = explicit if isinstance(explicit, str) else act.history.url or None
    if url:
        from hil.history.guard import refuse_foreign

        refuse_foreign(url)


def record_history(console, args: argparse.Namespace, act: Actuation, result_path: Path, *,
                   run_folder: Path | None, recording: Path | None = None) -> None:
    """After a command wrote its result: record it in the wear history, one line on the console
    either way; never raises and never changes the command's exit status (docs/history.md).

    A real result is recorded unless ``--no-history``; a simulated one only with ``--history``."""
    explicit = getattr(args, "history", None)
    if getattr(args, "no_history", False) or not Path(result_path).is_file():
        return
    from rich.markup import escape

    from hil.history.record import is_simulated, load_result
    from hil.history.sync import record_after_check

    try:
        simulated = is_simulated(load_result(result_path))
    except Exception as exc:  # noqa: BLE001 - reported; the command's outcome stands
        console.print(escape(f"NOT recorded in the history: {exc}"), soft_wrap=True)
        return
    if simulated and explicit is None:
        return
    # --history URL (True: --history alone, the profile's or the user's database)
    url = history_url(explicit if isinstance(explicit, str) else None, act)
    record_after_check(url, Path(result_path), run_folder=run_folder, recording=recording,
                       say=lambda m: console.print(escape(m), soft_wrap=True))


def history_url_for(url: str | None, profile: Path | None) -> str:
    """``--history``, else the actuation profile's ``history.url``, else the user's SQLite file."""
    if url:
        return url  # no profile to read
    from hil.profile.load import load_actuation

    return history_url(None, load_actuation(profile))
