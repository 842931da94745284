"""Stalls of the master's computer: injected in the dry-run, observed in every check (pure, sans-IO).

A stall is a time in which the master's process does not run (the host took its CPU, a page fault, a
timer that fired late) while the bus goes on: on a real bus SYNC keeps its kernel- or hardware-timed
period (or, where the loop sends SYNC itself, the next one leaves late), the drives hold their last
setpoint and keep answering, and their frames wait, stamped, in the master's socket. What the master
tolerates is the freshness limit in force (:func:`hil.check.staleness.stale_limit`, docs/safety.md, *A stall of
the master*); a stall within it costs nothing but the master's reaction time, and it is recorded.

:class:`StallWatch` is what every check keeps (the link feeds it each SYNC with how late the master took
it): how many stalls, the longest, and when each began; meta.json ``stalls``.

:class:`MasterStalls` is the dry-run's injection (``emacheck dry-run --master-stall-ms MS
--master-stall-every-s S``): the master stalls for ``MS`` at intervals drawn uniformly from
``[S/2, 3S/2]`` (mean ``S``) on the simulated time axis, from the first SYNC; deterministic for a seed.
:class:`hil.transport.InProcessTransport` applies it: during a stall the simulated drives run on, SYNC
keeps its period and every frame waits for the master with the time it was sent.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["EVERY_S_MAX", "EVERY_S_MIN", "RECENT_STALLS", "STALL_MS_MAX", "MasterStalls", "StallWatch", "process_held",
           "stall_explains"]

#: ``--master-stall-ms``: above 0, at most this [ms] (far beyond any freshness limit: the drives' consumer
#: heartbeat stops them first)
STALL_MS_MAX = 1000.0
#: ``--master-stall-every-s``: the mean interval between stalls [s], from this ...
EVERY_S_MIN = 0.1
#: ... to this [s]
EVERY_S_MAX = 3600.0
#: The most stalls :class:`StallWatch` lists one by one (the count and the longest go on beyond it).
MAX_LISTED = 1000
#: The latest stalls :class:`StallWatch` keeps for :func:`stall_explains` (:attr:`StallWatch.recent`): two
#: stalls are at least two SYNC periods apart (a late SYNC, then one on time), so 256 span at least 1.02 s at
#: 500 Hz, more than a heartbeat's timeout (0.15 s shipped) or a drive's consumer time (0.125 s).
RECENT_STALLS = 256


class MasterStalls:
    """When the dry-run's master stalls, and for how long (see the module docstring).

    Parameters
    ----------
    stall_ms : float
        Length of each stall [ms], ``0 < stall_ms <= STALL_MS_MAX``.
    every_s : float
        Mean interval between the starts of two stalls [s], ``EVERY_S_MIN <= every_s <= EVERY_S_MAX``
        and more than twice the stall (two stalls never run into each other).
    rng : numpy.random.Generator
        Draws the intervals.
    """

    def __init__(self, stall_ms: float, every_s: float, rng: np.random.Generator) -> None:
        if not (math.isfinite(stall_ms) and 0.0 < stall_ms <= STALL_MS_MAX):
            raise ValueError(f"stall_ms = {stall_ms!r}: a stall is longer than 0 and at most {STALL_MS_MAX:g} ms")
        if not (math.isfinite(every_s) and EVERY_S_MIN <= every_s <= EVERY_S_MAX):
            raise ValueError(f"every_s = {every_s!r}: the mean interval is {EVERY_S_MIN:g} to {EVERY_S_MAX:g} s")
        if stall_ms / 1000.0 >= every_s / 2.0:
            raise ValueError(f"stall_ms = {stall_ms:g} ms is not shorter than half the mean interval "
                             f"every_s = {every_s:g} s: two stalls would run into each other")
        self.stall_s = stall_ms / 1000.0
        self.every_s = every_s
        self._rng = rng
        self._next: float | None = None  #: when the next stall begins [s, transport time]
        self.injected: list[tuple[float, float]] = []  #: (begin [s, transport time], length [s]) of each

    def _gap(self) -> float:
        return float(self._rng.uniform(0.5, 1.5)) * self.every_s

    def start(self, t: float) -> None:
        """SYNC starts at ``t`` [s]: the first stall is one drawn interval after it."""
        self._next = t + self._gap()

    def due(self, t: float) -> float | None:
        """The stall's length [s] if the master stalls at the SYNC of time ``t`` [s] (the first SYNC at or
        after a stall's drawn begin; the next is drawn from there), else None."""
        nxt = self._next
        if nxt is None or t < nxt - 1e-9:
            return None
        self._next = t + self.stall_s + self._gap()
        self.injected.append((t, self.stall_s))
        return self.stall_s

    def as_json(self) -> dict:
        """The injection as meta.json records it (``stalls.injected``)."""
        return {"stall_ms": self.stall_s * 1000.0, "every_s": self.every_s, "count": len(self.injected)}


@dataclass
class _Open:
    at_s: float
    late_s: float


class StallWatch:
    """The stalls of the master in one check, as it observed them.

    Fed once per SYNC (:meth:`observe`) with the SYNC's time and how late the master took it (on a
    real bus: how long the SYNC waited in its socket, or how late the loop sent its own SYNC; in the
    dry-run: how long the injected stall kept it). A SYNC taken more than one SYNC period late belongs
    to a stall; consecutive late SYNCs are one stall, as long as the latest of them.
    """

    def __init__(self, sync_period_s: float) -> None:
        self.T = sync_period_s
        self.count = 0
        self.longest_s = 0.0
        self.listed: list[tuple[float, float]] = []  #: (begin [s, SYNC time], length [s]), the first MAX_LISTED
        self._open: _Open | None = None
        #: the latest stalls closed, (begin, length) [s], at most RECENT_STALLS
        self._recent: deque[tuple[float, float]] = deque(maxlen=RECENT_STALLS)

    def observe(self, t_s: float, late_s: float) -> None:
        """The SYNC of time ``t_s`` [s] was taken ``late_s`` [s] after it arrived (or was due)."""
        if late_s <= self.T:
            if self._open is not None:
                self._close()
            return
        o = self._open
        if o is None:
            self._open = _Open(t_s, late_s)
        elif late_s > o.late_s:
            o.late_s = late_s

    def on_time(self) -> None:
        """A SYNC taken within one period of its time (:meth:`observe` of a lateness up to ``T``, whatever
        its time): it ends an open stall."""
        if self._open is not None:
            self._close()

    def _close(self) -> None:
        o, self._open = self._open, None
        self.count += 1
        self.longest_s = max(self.longest_s, o.late_s)
        self._recent.append((o.at_s, o.late_s))
        if len(self.listed) < MAX_LISTED:
            self.listed.append((o.at_s, o.late_s))

    @property
    def recent(self) -> tuple[tuple[float, float], ...]:
        """The latest stalls, oldest first, the one still open last: (begin [s, SYNC time], length [s]) each; at
        most :data:`RECENT_STALLS` closed ones."""
        o = self._open
        return tuple(self._recent) + (((o.at_s, o.late_s),) if o is not None else ())

    def as_json(self) -> dict:
        """count, longest [ms] and each stall's begin [s] and length [ms] (a stall still open counted)."""
        if self._open is not None:
            self._close()
        return {"count": self.count, "longest_ms": round(self.longest_s * 1000.0, 3),
                "at": [[round(t, 6), round(d * 1000.0, 3)] for t, d in self.listed]}


def stall_explains(stalls, at_s: float, silent_s: float, overdue_s: float) -> tuple[float, float] | None:
    r"""Whether a stall of the master's own loop explains a node's heartbeat lost: the PC, not the node.

    A heartbeat is judged lost at :math:`t_l` (``at_s``) when none came for ``silent_s`` (more than its timeout);
    it was then at least ``overdue_s`` = timeout - producer period late. A stall (of ``stalls``, each begin
    :math:`b`, length :math:`L` [s]: :attr:`StallWatch.recent`) explains it when the master's loop itself was
    held at least as long, :math:`L \ge` ``overdue_s``, within the silence, :math:`b \le t_l` and
    :math:`b + L \ge t_l -` ``silent_s``: a PC that held its own loop that long in that window did not run a
    heartbeat producer on it either (the simulated drives of ``sim-serve`` on the same PC), or took the frames
    late. A shorter stall, or one outside the silence, leaves the node (its wiring, its power, its 0x1017) the
    cause. Returns the longest stall that
    explains it, None where none does."""
    if not (math.isfinite(at_s) and math.isfinite(silent_s) and math.isfinite(overdue_s)):
        return None
    fits = [(b, n) for b, n in stalls or () if n >= overdue_s and b <= at_s and b + n >= at_s - silent_s]
    return max(fits, key=lambda x: x[1]) if fits else None


def process_held(frames_silent_s: float, overdue_s: float) -> bool:
    """Whether a node whose heartbeat was lost was silent altogether, no statusword (TPDO) either, for at least
    ``overdue_s`` (timeout - producer period [s], as in :func:`stall_explains`) at a stretch within the
    heartbeat's silence (``frames_silent_s``: :attr:`hil.master.events.HeartbeatLost.frames_silent_s`; a process
    held that long, then run again, answers SYNCs before its heartbeat is judged lost).

    Only meaningful on a software bus (python-can's ``udp_multicast``, ``virtual``), where every node is a
    process on a PC (``sim-serve``'s simulated drives): a process that sent nothing at all for that long was not
    run, the PC's doing; its heartbeat producer only late while its TPDOs came would be the node's own. (On a
    real bus a drive silent altogether is its power, its cable or a bus-off: the caller never asks there.) False
    where the time is not known (NaN: not a drive, no statusword yet)."""
    return math.isfinite(frames_silent_s) and math.isfinite(overdue_s) and frames_silent_s >= overdue_s
