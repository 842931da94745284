"""Whose database a history file is, looked at before anything is written to it.

The history writes only to its own database: an SQLite file that holds another program's tables and no
``emacheck_schema`` is refused (:class:`~hil.errors.HistoryInputError`, exit status 3), by a
command that records and by ``emacheck history`` alike, and is left exactly as it was. The file is read
with the standard library's sqlite3, read-only and immutable (no lock, no journal, no side file), so
``run``, ``analyze`` and ``serv`` can refuse a foreign ``--history`` before the check, without importing
SQLAlchemy. A missing or empty file is emacheck's to create, but only by a command that records.
"""

from __future__ import annotations

from pathlib import Path

from hil.errors import HistoryInputError
from hil.profile.history_url import dialect, masked, sqlite_path

#: the version table: a database holding it is an emacheck history
SCHEMA_TABLE = "emacheck_schema"

MISSING, EMPTY, OWN, SERVER = "missing", "empty", "own", "server"


def sqlite_tables(path: Path, shown: str) -> list[str] | None:
    """The names in an SQLite file's schema (tables, views, indexes, triggers; not sqlite's own), [] for an
    empty file, None for no file; a folder, or a file that is not an SQLite database, is refused."""
    import sqlite3

    path = Path(path)
    if not path.exists():
        return None
    if path.is_dir():
        raise HistoryInputError(f"history {shown}: {path} is a folder, not an SQLite file")
    if path.stat().st_size == 0:
        return []
    try:
        conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
        try:
            return [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE name NOT LIKE 'sqlite_%' "
                                               "ORDER BY name")]
        finally:
            conn.close()
    except sqlite3.DatabaseError as exc:
        text = " ".join(str(exc).split())
        if "not a database" in text or "malformed" in text or "corrupt" in text:
            raise HistoryInputError(f"history {shown}: not an SQLite database or corrupt ({text}); move the "
                                    f"file aside or give another --history") from None
        raise HistoryInputError(f"history {shown}: cannot open or read the file ({text})") from None


def refuse_foreign(url: str) -> str:
    """What the history database of ``url`` is: :data:`MISSING`, :data:`EMPTY` (a file with nothing in it),
    :data:`OWN` (an emacheck history) or :data:`SERVER` (PostgreSQL: looked at when connected); an SQLite
    file holding anything else is refused, naming it and what it holds."""
    if dialect(url) != "sqlite":
        return SERVER
    shown = masked(url)
    names = sqlite_tables(sqlite_path(url), shown)
    if names is None:
        return MISSING
    if not names:
        return EMPTY
    if SCHEMA_TABLE in names:
        return OWN
    some = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
    raise HistoryInputError(f"history {shown}: not an emacheck history: {sqlite_path(url)} holds another "
                            f"program's tables ({some}) and no {SCHEMA_TABLE}; emacheck writes only to its own "
                            f"database: give --history a new file or an emacheck history")
