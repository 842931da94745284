"""The dry-run's analysis prepared in a fork while its check loop runs.

The loop keeps one core busy; the analysis and report import scipy.signal, python-control and
matplotlib (about 0.8 s of CPU) before they compute anything. :class:`AnalysisFork` forks the
dry-run before its loop; the fork imports them on the other core and waits. When the check has
finished, the fork gets the finished run record, analyses the run folder's signals.csv as it is
on disk (the same function as in process, :func:`hil.cli.check.analysed`) and draws the report
(its figures by two processes, :func:`hil.report.shell.drawn`); it sends back the result and the
report's HTML and writes nothing: result.json and report.html are written by the dry-run itself
(:func:`hil.cli.check.analyze_and_report`). Whatever goes wrong in the fork (an analysis error, a
crash, an interrupt) ends it without an answer, and the dry-run analyses in process as before: an
error is then raised there, as it always was.
"""

from __future__ import annotations

import os
import pickle
import signal
import threading
from pathlib import Path


class AnalysisFork:
    """A fork of this process that imports the analysis now and analyses the run folder ``out`` when
    asked (:meth:`analysed`); nothing (``pid`` None) where there is no ``os.fork`` or another thread
    runs (a fork copies only the calling thread)."""

    def __init__(self, act, out: Path) -> None:
        self.pid: int | None = None
        if not hasattr(os, "fork") or threading.active_count() != 1:
            return
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the fork: never returns, runs nothing of the parent's (atexit, buffers, handlers)
            code = 1
            try:
                for s in (signal.SIGINT, signal.SIGTERM):  # an interrupt ends the fork, silently
                    signal.signal(s, signal.SIG_DFL)
                os.close(req_w)
                os.close(res_r)
                _serve(req_r, res_w, act, Path(out))
                code = 0
            finally:
                os._exit(code)
        os.close(req_r)
        os.close(res_w)
        self.pid, self._req, self._res = pid, req_w, res_r

    def analysed(self, rec, truth: dict | None) -> tuple[dict, str] | None:
        """The result and the report's HTML of the finished check whose record is ``rec`` (``truth``: the
        simulator's truth beside it), or None (no fork, or it ended without an answer)."""
        if self.pid is None:
            return None
        from hil.report.shell import read_until_eof

        try:
            with os.fdopen(self._req, "wb") as f:
                self._req = -1
                pickle.dump((rec, truth), f, protocol=pickle.HIGHEST_PROTOCOL)
            data = read_until_eof(self._res)  # (b"" from a fork that ended without an answer or hung)
        except (OSError, pickle.PicklingError):  # the fork is gone (a broken pipe)
            data = b""
        finally:
            self.close()
        try:
            return pickle.loads(data) if data else None
        except (EOFError, pickle.UnpicklingError):  # cut short: the fork died while it sent
            return None

    def close(self) -> None:
        """End the fork (if it still waits: the request pipe closed, then stopped) and wait for it."""
        for fd in (self._req, self._res) if self.pid is not None else ():
            if fd >= 0:
                os.close(fd)
        self._req = self._res = -1
        if self.pid is None:
            return
        pid, self.pid = self.pid, None
        from hil.report.shell import reap_fork  # (here: `run` imports this module, never the report before its loop)

        reap_fork(pid)


def _serve(req_r: int, res_w: int, act, out: Path) -> None:
    """In the fork: import, wait for the finished check's record, analyse and draw, send."""
    from hil.cli.check import analysed
    from hil.cli.common import Outputs
    from hil.report.maint import report_html
    from hil.report.shell import pyplot

    pyplot()
    with os.fdopen(req_r, "rb") as f:
        data = f.read()
    if not data:  # the dry-run did not ask (its check did not finish)
        return
    rec, truth = pickle.loads(data)
    sig, an, result = analysed(out / "signals.csv", act, truth, rec)
    html = report_html(sig, an, result, act, rec, json_name=Outputs(out, own=True).path("result.json").name)
    with os.fdopen(res_w, "wb") as f:
        pickle.dump((result, html), f, protocol=pickle.HIGHEST_PROTOCOL)
