"""The dry-run's analysis prepared in a fork while its check loop runs.

The loop keeps one core busy; the analysis and report import scipy.signal, python-control and
matplotlib (about 0.8 s of CPU) before they compute anything. :class:`AnalysisFork` forks the
dry-run before its loop; the fork imports them on the other core and waits. When the check has
finished, the fork gets the finished run record, analyses the run folder's signals.csv as it is
on disk (the same function as in process, :func:`hil.cli.result.analysed`) and draws the report
(its figures by two processes, :func:`hil.report.shell.drawn`); it sends back the result and the
report's HTML and writes nothing: result.json and report.html are written by the dry-run itself
(:func:`hil.cli.result.analyze_and_report`). Whatever goes wrong in the fork (an analysis error, a
crash, an interrupt, no answer within :data:`hil.forks.FORK_TIMEOUT_S`) ends it without an answer, and
the dry-run analyses in process as before: an error is then raised there, as it always was. The fork
itself (when to fork, its setup and end, the wait, the reaping) is :mod:`hil.forks`; this module is
only what the fork does.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path

from hil.forks import can_fork, send, start


class AnalysisFork:
    """A fork of this process that imports the analysis now and analyses the run folder ``out`` when
    asked (:meth:`analysed`); nothing (``pid`` None) where there is no fork (:func:`hil.forks.start`:
    no ``os.fork``, another thread runs, or ``os.fork`` fails)."""

    def __init__(self, act, out: Path) -> None:
        self._fork = None
        self._req = -1
        if not can_fork():
            return
        req_r, req_w = os.pipe()
        self._fork = start(lambda: _serve(req_r, act, Path(out)), child_closes=(req_w,))
        os.close(req_r)
        if self._fork is None:
            os.close(req_w)
        else:
            self._req = req_w

    @property
    def pid(self) -> int | None:
        """The fork's process id; None: no fork, or it has ended (:meth:`close`)."""
        return self._fork.pid if self._fork is not None else None

    def analysed(self, rec, truth: dict | None) -> tuple[dict, str] | None:
        """The result and the report's HTML of the finished check whose record is ``rec`` (``truth``: the
        simulator's truth beside it), or None (no fork, or it ended without an answer or hung:
        :meth:`hil.forks.Fork.answer`)."""
        if self._fork is None:
            return None
        try:
            req, self._req = self._req, -1
            send(req, (rec, truth))
            return self._fork.answer()
        except (OSError, pickle.PicklingError):  # the fork is gone (a broken pipe)
            return None
        finally:
            self.close()

    def close(self) -> None:
        """End the fork (if it still waits: the request pipe closed, then stopped) and wait for it."""
        if self._req >= 0:
            os.close(self._req)
            self._req = -1
        if self._fork is not None:
            fork, self._fork = self._fork, None
            fork.close()


def _serve(req_r: int, act, out: Path) -> tuple[dict, str] | None:
    """In the fork: import, wait for the finished check's record, analyse and draw; the result and the
    report's HTML (sent back by :func:`hil.forks.start`), None if the dry-run did not ask."""
    from hil.cli.result import analysed
    from hil.record.outputs import Outputs
    from hil.report.maint import report_html
    from hil.report.shell import pyplot

    pyplot()
    with os.fdopen(req_r, "rb") as f:
        data = f.read()
    if not data:  # the dry-run did not ask (its check did not finish)
        return None
    rec, truth = pickle.loads(data)
    sig, an, result = analysed(out / "signals.csv", act, truth, rec)
    html = report_html(sig, an, result, act, rec, json_name=Outputs(out, own=True).path("result.json").name)
    return result, html
