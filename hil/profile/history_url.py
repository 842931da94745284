"""``--history`` URLs and the default history file, without importing a database library.

A URL is ``sqlite:///RELATIVE/PATH``, ``sqlite:////ABSOLUTE/PATH`` or
``postgresql://USER[:PASSWORD]@HOST[:PORT]/DATABASE`` (``postgresql+psycopg://``
and ``postgres://`` too; ``?host=/run/postgresql`` for a Unix socket). The
default is ``history.sqlite`` in the user's data directory as platformdirs
finds it (``~/.local/share/emacheck`` on Linux). Passwords never appear in a
message: :func:`masked` hides them.
"""

from __future__ import annotations

import re
from pathlib import Path

from hil.errors import HistoryInputError

#: the file name of the default history in the user's data directory
DEFAULT_FILE = "history.sqlite"

_SCHEMES = {"sqlite": "sqlite", "postgresql": "postgresql", "postgres": "postgresql",
            "postgresql+psycopg": "postgresql"}


def default_path() -> Path:
    """The default history file: ``history.sqlite`` in the user's data directory (platformdirs)."""
    import platformdirs

    return Path(platformdirs.user_data_dir("emacheck", appauthor=False)) / DEFAULT_FILE


def default_url() -> str:
    """``sqlite:///`` URL of :func:`default_path`."""
    return f"sqlite:///{default_path()}"


def dialect(url: str) -> str:
    """``"sqlite"`` or ``"postgresql"`` for a URL :func:`check_url` accepts."""
    return _SCHEMES[url.split("://", 1)[0].lower()]


def check_url(text: str) -> str:
    """``text`` if it is a history URL emacheck can use, else :class:`HistoryInputError` saying why.

    Only the form is checked here (no database library is imported): the scheme, a file path for
    SQLite (not the in-memory database: nothing would be kept), a database name for PostgreSQL.
    """
    text = str(text).strip()
    m = re.match(r"^([A-Za-z][A-Za-z0-9+.-]*)://(.*)$", text)
    hint = "give sqlite:///PATH (a file) or postgresql://USER@HOST/DATABASE"
    if not m:
        raise HistoryInputError(f"{masked(text)!r} is not a database URL; {hint}")
    scheme, rest = m.group(1).lower(), m.group(2)
    if scheme not in _SCHEMES:
        raise HistoryInputError(f"{masked(text)!r}: unknown database scheme {scheme!r} "
                                f"(known: sqlite, postgresql); {hint}")
    if _SCHEMES[scheme] == "sqlite":
        path = rest[1:] if rest.startswith("/") else ""
        path = path.split("?", 1)[0]
        if not path or path == ":memory:":
            raise HistoryInputError(f"{text!r}: an SQLite history needs a file (sqlite:///history.sqlite, "
                                    f"sqlite:////abs/path/history.sqlite); an in-memory database keeps nothing")
    else:
        netloc_path = rest.split("?", 1)[0]
        db = netloc_path.split("/", 1)[1] if "/" in netloc_path else ""
        if not db:
            raise HistoryInputError(f"{masked(text)!r}: name the database "
                                    f"(postgresql://USER@HOST/DATABASE)")
    return text


def sqlite_path(url: str) -> Path:
    """The file of an ``sqlite:///`` URL."""
    return Path(url.split("://", 1)[1][1:].split("?", 1)[0])


def masked(url: str) -> str:
    """The URL with any password replaced by ``***``."""
    return re.sub(r"^([A-Za-z][A-Za-z0-9+.-]*://[^:/@?]*):[^@/?]*@", r"\1:***@", str(url))
