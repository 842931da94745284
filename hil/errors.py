"""Typed exception tree of the controller (hil/).

Every error the tool raises on purpose derives from one of three roots, each
mixing in the builtin that describes its nature, so callers can catch either:

* :class:`EmacheckError` (here): profiles, recordings, the check sequence,
  the master and the link;
* :class:`hil.canopen.errors.CanopenError`: the CANopen vocabulary (frames,
  PDOs, SDO aborts and timeouts, CiA 402 transitions, EDS files), shared with
  the simulated drives and importing nothing from the rest of hil;
* :class:`blf.errors.BlfError`: the pure analysis and the physics (bad arrays,
  data that do not support an analysis).

:data:`KNOWN_ERRORS` is the three together: what the command layer turns
into a one-line message and a documented exit status.
"""

from __future__ import annotations

from blf.errors import BlfError
from hil.canopen.errors import CanopenError


class EmacheckError(Exception):
    """Base of the controller's errors."""


class ProfileError(EmacheckError, ValueError):
    """A profile (TOML) is malformed, incomplete or outside the hard limits.

    ``problems`` holds every problem found, each a message naming file and field: a loader collects
    them (:class:`hil.profile.tables.Problems`) so that one run names them all; the message of several
    is the file (where they share one), a count and one line each.
    """

    def __init__(self, message: str, problems: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.problems: tuple[str, ...] = tuple(problems) or (message,)

    @classmethod
    def of(cls, problems: list[str] | tuple[str, ...]) -> ProfileError:
        """One error for every problem: the problem itself if there is one, else a count and a line each."""
        if len(problems) == 1:
            return cls(problems[0])
        files = {p.split(": ", 1)[0] for p in problems}
        where = f"{files.pop()}: " if len(files) == 1 else ""
        return cls(f"{where}{len(problems)} problems (all of them; fix each before the next run):\n  "
                   + "\n  ".join(problems), tuple(problems))


class RecordingError(EmacheckError, ValueError):
    """A recording (signals CSV, run folder, CAN log) cannot be used."""


class IncompleteRecordingError(RecordingError):
    """A recording that is well-formed but ends too early or holds no data (e.g. a killed run)."""


class UnusableRecordingError(IncompleteRecordingError):
    """A well-formed recording with nothing to analyse: too few rows, or a signal that never changes
    (exit 3 for a recording on its own; an aborted or killed run's folder reports it as incomplete)."""


class RunRecordError(RecordingError):
    """A run folder's meta.json holds a field of the wrong type or value; ``field`` names it
    (dotted: ``steps.cal1_sweep``, ``drives_final.ema2.safe``)."""

    def __init__(self, field: str, problem: str, source: str) -> None:
        super().__init__(f"{source}: field '{field}': {problem}")
        self.field = field


class InterfaceError(EmacheckError, OSError):
    """A CAN interface that cannot be opened; the message names interface, channel and what to check."""


class OutputError(EmacheckError, OSError):
    """A command's output cannot be written where asked: ``--out`` is a file or a folder that holds files
    already (a check's record is written once), a file of that name exists (never overwritten), or the
    folder cannot be written (read-only, no permission). The message names the path (exit status 3)."""

    bad_input = True


class ArgumentsError(EmacheckError, ValueError):
    """Command-line options each in range but not together; the message names them (exit status 3)."""

    bad_input = True


class SequenceError(EmacheckError, RuntimeError):
    """The check sequence reached a state it cannot continue from."""


# ---- the wear history (hil/history): a database that cannot be used says so in one line.
# Both derive from :class:`hil.errors.EmacheckError`. ``bad_input`` tells the
# command layer the exit status (3 for bad input, else 2; docs/history.md):
#
# * :class:`HistoryInputError`: the URL, file or login given cannot be used
#   (not a database URL, not an SQLite database or corrupt, login refused, a
#   schema newer than this emacheck): exit 3;
# * :class:`HistoryUnavailableError`: the database is there but cannot be used
#   now (server down or unreachable, SQLite file locked by another program):
#   exit 2, try again later.
#
# After a check, neither changes the check's exit status: the recording says
# on one line that the result was not recorded and how to record it later.


class HistoryError(EmacheckError):
    """Base of the history's errors."""

    bad_input = False


class HistoryInputError(HistoryError, ValueError):
    """The history URL, file or login cannot be used (exit 3)."""

    bad_input = True


class HistoryUnavailableError(HistoryError, ConnectionError):
    """The history database cannot be reached or is locked now (exit 2)."""


#: Every error raised on purpose, whichever package raised it.
KNOWN_ERRORS: tuple[type[Exception], ...] = (EmacheckError, CanopenError, BlfError)


class StopRequest(KeyboardInterrupt):
    """A request to stop a running check as Ctrl-C does (a SIGTERM from a service manager, a SIGHUP of a
    closed session: :mod:`hil.cli.stopping`); its message is the reason the record gives."""


class LinkLostError(EmacheckError, ConnectionError):
    """The CAN interface went away during a check (an USB adapter unplugged, the interface taken down): the
    master can no longer reach the drives; they are left to their own reaction to losing the master (as the
    preflight configured and drilled it: their heartbeat consumers, 0x1016, or the stated external
    watchdog). The message names the interface and the cause (exit status 2)."""


class RecordWriteError(EmacheckError, OSError):
    """A check's record could not be written any more (a full disk, an IO error, a file system gone
    read-only) while the drives were running: they were brought to their safe stop first; the message names
    the file and the cause (exit status 2)."""
