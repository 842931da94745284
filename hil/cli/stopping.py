"""A running check stopped by a signal exactly as by one Ctrl-C, and never cut short by the next.

During a command that moves drives (``run``, ``dry-run``, ``simulate``, ``commission``): the first SIGINT,
SIGTERM or SIGHUP raises in the main thread (Ctrl-C's KeyboardInterrupt; SIGTERM and SIGHUP a
:class:`hil.errors.StopRequest` naming the signal), so the check loop brings both drives to their safe
stop, closes its records and the command writes result.json and the report; every later one of the three
is counted and ignored until the command is done, so a second or third Ctrl-C, or a service manager's
repeated SIGTERM, cannot interrupt the stop or the writing. SIGHUP (the session closed) also sends the
console's output to the null device: the terminal is gone, the record is what is kept.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys

from hil.errors import StopRequest

#: the signals that stop a check, and the reason each gives
STOP_SIGNALS = {signal.SIGINT: None, signal.SIGTERM: "stopped by SIGTERM (a service manager or kill)",
                signal.SIGHUP: "stopped by SIGHUP (the terminal or session closed)"}
#: the commands that move drives (or their simulation)
CHECK_COMMANDS = ("run", "dry-run", "simulate", "commission")


class StopOnSignals:
    """The signal handlers of a command that moves drives (a context manager; see the module docstring)."""

    def __init__(self) -> None:
        self.first: int | None = None  #: the signal that stopped the check
        self.ignored = 0  #: later signals, counted and ignored
        self._old: dict = {}

    def __enter__(self) -> StopOnSignals:
        self._old = {s: signal.signal(s, self._handle) for s in STOP_SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)

    def _handle(self, signum: int, frame) -> None:
        if self.first is not None:
            self.ignored += 1
            return
        self.first = signum
        if signum == signal.SIGHUP:
            _quiet_console()
        reason = STOP_SIGNALS[signal.Signals(signum)]
        raise StopRequest(reason) if reason else KeyboardInterrupt


def _quiet_console() -> None:
    """The terminal is gone: stdout and stderr to the null device (a write to a closed terminal would fail)."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
            os.dup2(null, stream.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # no file descriptor (a test's captured stream): leave it
        pass
