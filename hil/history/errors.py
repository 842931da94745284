"""Errors of the wear history: a database that cannot be used says so in one line.

Both derive from :class:`hil.errors.EmacheckError`. ``bad_input`` tells the
command layer the exit status (3 for bad input, else 2; docs/history.md):

* :class:`HistoryInputError`: the URL, file or login given cannot be used
  (not a database URL, not an SQLite database or corrupt, login refused, a
  schema newer than this emacheck): exit 3;
* :class:`HistoryUnavailableError`: the database is there but cannot be used
  now (server down or unreachable, SQLite file locked by another program):
  exit 2, try again later.

After a check, neither changes the check's exit status: the recording says
on one line that the result was not recorded and how to record it later.
"""

from __future__ import annotations

from hil.errors import EmacheckError


class HistoryError(EmacheckError):
    """Base of the history's errors."""

    bad_input = False


class HistoryInputError(HistoryError, ValueError):
    """The history URL, file or login cannot be used (exit 3)."""

    bad_input = True


class HistoryUnavailableError(HistoryError, ConnectionError):
    """The history database cannot be reached or is locked now (exit 2)."""
