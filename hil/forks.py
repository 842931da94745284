"""Work done in a fork of this process, its answer pickled back through a pipe: the one home of the fork
plumbing (the rule of when to fork, the fork's setup and end, the wait with its timeout, the reaping).

Two callers: the report's figures drawn by two processes (:func:`hil.report.shell.drawn`, through
:func:`run_in_two`) and the dry-run's analysis prepared during its loop
(:class:`hil.cli.analysis_fork.AnalysisFork`). Each keeps only its own work; whatever goes wrong with a
fork leaves the caller to do that work itself:

* no fork where there is no ``os.fork`` or another thread runs (a fork copies only the calling thread,
  :func:`can_fork`), nor where ``os.fork`` fails (:func:`start` returns None);
* a fork that crashes, is interrupted or raises ends without an answer (:meth:`Fork.answer` None);
* a fork that has not answered within :data:`FORK_TIMEOUT_S` is stopped (SIGTERM) and given up.

A fork runs nothing of the parent's: SIGINT and SIGTERM end it (not the parent's handlers) and it leaves
by ``os._exit`` (no atexit handlers, no flush of buffers it shares with the parent). Only the standard
library is imported here (the dry-run imports this before its loop).
"""

from __future__ import annotations

import contextlib
import gc
import os
import pickle
import select
import signal
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

#: how long a process waits for its fork's answer [s] before it stops the fork and does the work itself: a
#: hung fork (the analysis and report take ~1 s on a quiet machine, ~10 s at a load average of 8)
FORK_TIMEOUT_S = 600.0


def can_fork() -> bool:
    """Whether this process may fork: there is ``os.fork`` and no other thread runs (a fork copies only the
    calling thread: what another thread holds, a lock among it, would be held for ever in the fork)."""
    return hasattr(os, "fork") and threading.active_count() == 1


class Fork:
    """A running fork (:func:`start`): its process id ``pid`` and the read end ``fd`` of the pipe its answer
    comes through (a live handle, closed once)."""

    def __init__(self, pid: int, fd: int) -> None:
        self.pid, self.fd, self.closed = pid, fd, False

    def answer(self, timeout_s: float = FORK_TIMEOUT_S) -> Any | None:
        """What the fork returned (unpickled), or None: it ended without a whole answer (it returned None,
        raised, crashed, was interrupted) or did not answer within ``timeout_s``. The fork is then
        reaped (:meth:`close`)."""
        try:
            data = read_until_eof(self.fd, timeout_s)
        finally:
            self.close()
        try:
            return pickle.loads(data) if data else None
        except (EOFError, pickle.UnpicklingError):  # cut short: the fork died while it sent
            return None

    def close(self) -> None:
        """Close the answer's pipe and wait for the fork, stopped first if it still runs (:func:`reap_fork`);
        once."""
        if self.closed:
            return
        self.closed = True
        os.close(self.fd)
        reap_fork(self.pid)


def start(work: Callable[[], Any], *, child_closes: Iterable[int] = (), freeze_gc: bool = False) -> Fork | None:
    """Fork this process; the fork runs ``work()`` and sends back what it returns (pickled; nothing for
    None), then ends. None (nothing started) where this process may not fork (:func:`can_fork`) or
    ``os.fork`` fails.

    In the fork, before ``work``: SIGINT and SIGTERM back to their defaults (an interrupt ends it
    silently) and the file descriptors ``child_closes`` closed (the parent's ends of the caller's own
    pipes). The fork never returns: it leaves by ``os._exit`` (0 after ``work`` returned, 1 if it
    raised). ``freeze_gc``: the heap as it is moved out of the collector's passes for the fork
    (``gc.freeze``), the pages the two processes share staying shared longer.
    """
    if not can_fork():
        return None
    r, w = os.pipe()
    if freeze_gc:
        gc.freeze()
    try:
        pid = os.fork()
    except OSError:  # no process to be had (EAGAIN, ENOMEM): the caller does the work itself
        if freeze_gc:
            gc.unfreeze()
        os.close(r)
        os.close(w)
        return None
    if freeze_gc and pid != 0:  # the fork keeps the heap frozen: its collector never walks (and copies) it
        gc.unfreeze()
    if pid == 0:  # the fork: never returns, runs nothing of the parent's (atexit, buffers, handlers)
        code = 1
        try:
            for s in (signal.SIGINT, signal.SIGTERM):
                signal.signal(s, signal.SIG_DFL)
            os.close(r)
            for fd in child_closes:
                os.close(fd)
            out = work()
            if out is not None:
                send(w, out)
            code = 0
        finally:
            os._exit(code)
    os.close(w)
    return Fork(pid, r)


def send(fd: int, obj: Any) -> None:
    """Pickle ``obj`` into the pipe ``fd`` and close it (the reader then sees its end)."""
    with os.fdopen(fd, "wb") as f:
        pickle.dump(obj, f, protocol=pickle.HIGHEST_PROTOCOL)


def read_until_eof(fd: int, timeout_s: float = FORK_TIMEOUT_S) -> bytes:
    """What the pipe ``fd`` gives until its writer (a fork) closes it; ``b""`` if that takes longer than
    ``timeout_s``."""
    chunks = []
    deadline = time.monotonic() + timeout_s
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return b""
        if not (b := os.read(fd, 1 << 20)):
            return b"".join(chunks)
        chunks.append(b)


def reap_fork(pid: int) -> None:
    """Wait for the fork ``pid``; stop it first (SIGTERM) if it is still running (this process interrupted,
    or the fork hung)."""
    if os.waitpid(pid, os.WNOHANG)[0] == 0:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
        os.waitpid(pid, 0)


def run_in_two(jobs: dict[int, Callable[[], Any]], order: Iterable[int] | None = None) -> dict[int, Any]:
    """What the ``jobs`` (index 0-255: callable) return, run by this process and a fork of it at once:
    each takes the next index not yet taken, in the ``order`` given (every index once, else ValueError;
    default increasing), from a pipe holding them (one byte each; a read of one byte from a pipe is
    atomic); the fork's share pickled back. A job the fork did not return (it died, or was stopped by the
    interrupt that stops this process) is missing from the answer: the caller runs it. Nothing run where
    there is no fork (:func:`start`); the caller runs them all.
    """
    todo = sorted(jobs) if order is None else list(order)
    if sorted(todo) != sorted(jobs):
        raise ValueError(f"run_in_two: the order {todo} is not the jobs' indices {sorted(jobs)}, each once")
    todo_r, todo_w = os.pipe()
    os.write(todo_w, bytes(todo))  # at most 256 indices: less than a pipe's buffer
    os.close(todo_w)  # the pipe empty: a read returns b"", no job left

    def take() -> dict[int, Any]:
        done = {}
        while (b := os.read(todo_r, 1)):
            done[b[0]] = jobs[b[0]]()
        return done

    try:
        fork = start(take, freeze_gc=True)
        if fork is None:
            return {}
        try:
            done = take()
            done.update(fork.answer() or {})
        finally:
            fork.close()
    finally:
        os.close(todo_r)
    return done
