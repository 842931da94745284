"""The dry-run's two forks: the report's figures drawn by two processes (hil.report.shell.drawn) and the
analysis prepared during the loop (hil.cli.analysis_fork.AnalysisFork); each gives what one process gives,
and where the fork (hil.forks) fails, hangs or cannot be had the caller does the work itself."""

from __future__ import annotations

import json
import os
import re
import threading
import time

import pytest

from hil.report.shell import drawn

needs_fork = pytest.mark.skipif(not hasattr(os, "fork") or threading.active_count() != 1,
                                reason="no os.fork, or another thread runs in this test process (no fork then)")


def _meet(folder, name: str) -> str:
    """A figure that waits (up to 30 s) until two processes have each started one: whoever draws it first
    cannot take the other as well, so both processes draw one (or the test fails after 30 s)."""
    (folder / f"{name}-{os.getpid()}").touch()
    t0 = time.monotonic()
    while len({p.name.split("-")[1] for p in folder.iterdir()}) < 2:
        assert time.monotonic() - t0 < 30.0, "only one process drew the figures"
        time.sleep(0.005)
    return f"<{name} by {os.getpid()}>"


@needs_fork
def test_two_processes_draw_the_figures_in_the_order_of_the_parts(tmp_path):
    parts = ["a", lambda: _meet(tmp_path, "x"), ("b", lambda: _meet(tmp_path, "y"), lambda: "z"), "c"]
    out = drawn(parts)
    assert out[0] == "a" and out[3] == "c"
    pids = {int(m) for m in re.findall(r"by (\d+)>", out[1] + out[2])}
    assert len(pids) == 2 and os.getpid() in pids, out  # one of them the fork's
    assert out[1].startswith("<x by ") and re.fullmatch(r"b<y by \d+>z", out[2]), out


def test_one_process_draws_the_same():
    parts = ["a", lambda: "1", ("b", lambda: "2", lambda: "3"), "c"]
    assert drawn(parts, processes=1) == drawn(parts) == ["a", "1", "b23", "c"]


def test_the_figures_with_more_axes_are_taken_first(monkeypatch):
    """Two processes take the costliest figures first (a Drawing's axes; 1 for a bare callable), ties in
    the order of the parts, so that no process is left drawing the costliest figure alone at the end."""
    from hil.report import shell

    taken = []
    monkeypatch.setattr(shell, "can_fork", lambda: True)
    monkeypatch.setattr(shell, "run_in_two", lambda jobs, order: taken.extend(order) or {})
    parts = ["h", shell.Drawing(lambda: "6", axes=6), (shell.Drawing(lambda: "2a", axes=2), lambda: "1a"),
             (shell.Drawing(lambda: "2b", axes=2), lambda: "1b"), shell.Drawing(lambda: "4", axes=4)]
    assert drawn(parts) == ["h", "6", "2a1a", "2b1b", "4"]  # (drawn here: run_in_two returned nothing)
    assert taken == [1, 6, 2, 4, 3, 5]


@needs_fork
def test_run_in_two_takes_the_order_given_and_refuses_another_set():
    from hil.forks import run_in_two

    jobs = {i: (lambda i=i: i * i) for i in range(5)}
    assert run_in_two(jobs, order=[4, 0, 3, 1, 2]) == {i: i * i for i in range(5)}
    with pytest.raises(ValueError, match="not the jobs' indices"):
        run_in_two(jobs, order=[4, 0, 3, 1])


@needs_fork
def test_what_the_fork_did_not_return_is_drawn_here():
    me = os.getpid()

    def dies_in_the_fork(text: str):
        def draw() -> str:
            if os.getpid() != me:
                os._exit(3)  # the fork dies with the figure it took
            return text
        return draw

    parts = [dies_in_the_fork(str(i)) for i in range(6)]
    assert drawn(parts) == [str(i) for i in range(6)]


@pytest.mark.slow
@needs_fork
def test_the_fork_analyses_as_the_dry_run_does(dry_run, actuation):
    """The result and report the fork sends back are those of the analysis in process (but the time of
    the analysis and what it took)."""
    from hil.cli.analysis_fork import AnalysisFork
    from hil.cli.result import analysed
    from hil.record.runfolder import read_record
    from hil.report.maint import report_html

    out, rc = dry_run
    assert rc == 0
    rec = read_record(out)
    truth = json.loads((out / "result.json").read_text())["truth"]
    fork = AnalysisFork(actuation, out)
    assert fork.pid is not None
    got = fork.analysed(rec, truth)
    assert got is not None and fork.pid is None
    result, html = got
    sig, an, want = analysed(out / "signals.csv", actuation, truth, rec)
    want_html = report_html(sig, an, want, actuation, rec)
    for r in (result, want):
        r.pop("analysis_s")
        r["trace"].pop("analysed_utc")
    assert result == want
    # the analysis time: in the traceability table and on page 1 (the check's line, hil.report.shell)
    when = re.compile(r"analysed \(UTC\)</td><td>[^<]*<|, analysed \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC")
    assert when.sub("", html) == when.sub("", want_html)


@needs_fork
def test_a_fork_never_asked_ends_when_closed(tmp_path, actuation):
    from hil.cli.analysis_fork import AnalysisFork

    fork = AnalysisFork(actuation, tmp_path)
    pid = fork.pid
    fork.close()
    assert fork.pid is None
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # reaped
    assert not list(tmp_path.iterdir())  # it wrote nothing


@needs_fork
def test_a_fork_that_fails_answers_none(tmp_path, actuation):
    """No signals.csv: the fork's analysis raises, it ends without an answer (the dry-run then analyses in
    process, where the error is raised as it always was)."""
    from hil.cli.analysis_fork import AnalysisFork

    fork = AnalysisFork(actuation, tmp_path)
    assert fork.analysed(None, None) is None
    assert fork.pid is None


def test_a_hung_fork_is_given_up_after_the_timeout():
    from hil.forks import read_until_eof

    r, w = os.pipe()
    try:
        os.write(w, b"part of an answer")
        t0 = time.monotonic()
        assert read_until_eof(r, timeout_s=0.2) == b""  # the writer never closed: no answer
        assert 0.15 < time.monotonic() - t0 < 5.0
        os.close(w)
        w = -1
        assert read_until_eof(r, timeout_s=0.2) == b""  # (what was read before is not kept)
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)
    r, w = os.pipe()
    os.write(w, b"a whole answer")
    os.close(w)
    assert read_until_eof(r, timeout_s=5.0) == b"a whole answer"
    os.close(r)


def _open_fds() -> set[int]:
    return {int(x) for x in os.listdir("/proc/self/fd")} if os.path.isdir("/proc/self/fd") else set()


def test_where_os_fork_fails_the_caller_does_the_work_and_no_pipe_is_left_open(monkeypatch, tmp_path, actuation):
    """os.fork raising (EAGAIN, ENOMEM): no fork, the figures drawn here, the analysis fork answers None."""
    from hil.cli.analysis_fork import AnalysisFork

    def no_fork():
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    before = _open_fds()
    me = os.getpid()
    parts = ["a", lambda: f"1 by {os.getpid()}", ("b", lambda: f"2 by {os.getpid()}")]
    assert drawn(parts) == ["a", f"1 by {me}", f"b2 by {me}"]
    fork = AnalysisFork(actuation, tmp_path)
    assert fork.pid is None and fork.analysed(None, None) is None
    fork.close()
    assert _open_fds() == before


def test_no_fork_while_another_thread_runs(tmp_path, actuation):
    """A fork copies only the calling thread: while another runs, the figures are drawn here, no analysis fork."""
    from hil.cli.analysis_fork import AnalysisFork
    from hil.forks import can_fork

    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    try:
        assert not can_fork()
        me = os.getpid()
        assert drawn([lambda: str(os.getpid()), lambda: str(os.getpid())]) == [str(me), str(me)]
        fork = AnalysisFork(actuation, tmp_path)
        assert fork.pid is None and fork.analysed(None, None) is None
    finally:
        stop.set()
        other.join()


@needs_fork
def test_a_fork_that_raises_or_hangs_answers_none_and_is_reaped():
    from hil.forks import start

    def fails():
        raise ValueError("in the fork")

    fork = start(fails)
    assert fork is not None and fork.answer() is None
    with pytest.raises(ChildProcessError):
        os.waitpid(fork.pid, os.WNOHANG)  # reaped
    fork = start(lambda: time.sleep(60))
    t0 = time.monotonic()
    assert fork.answer(timeout_s=0.2) is None  # given up after the timeout, stopped, reaped
    assert time.monotonic() - t0 < 10.0
    with pytest.raises(ChildProcessError):
        os.waitpid(fork.pid, os.WNOHANG)
    fork = start(lambda: {"answer": 42})
    assert fork.answer() == {"answer": 42}
