"""Timing of a cyclic loop, measured per SYNC cycle (sans-IO: fed times, reads no clock).

Both ends of a hardware-in-the-loop check keep one :class:`CycleTiming`: the
master (:class:`hil.master.link.CanopenLink`, into meta.json ``timing``) and the
simulated drives (:func:`hil.sim_server.serve`, into sim-serve's summary).
The IO shell measures the times (the SYNC's arrival, the start and end of the
cycle's work, when the answer left) and passes them in; this object only
counts, in memory fixed at construction (a histogram of fixed bins and the K
worst cycles per measure), so feeding it in the loop allocates nothing that
grows.

Per SYNC cycle :math:`k` with SYNC arrival :math:`t^{sync}_k` [s]:

* **reaction** :math:`r_k = t^{sent}_k - t^{sync}_k`: SYNC arrival to this
  process's PDOs of the cycle sent (the master's RPDOs; the drives' TPDOs);
* **work** :math:`w_k`: the cycle's own computation (the master: sample
  complete to RPDOs sent, i.e. supervisor, sequence, logging; the drives:
  handling the SYNC, plant step included), on the wall clock and, where the
  shell passes it, in the thread's CPU time: a cycle whose wall time far
  exceeds its CPU time waited (preempted by another process, the GIL, a
  blocking write), one whose CPU time is long computed (a collection, a
  first-call compile);
* **gap** :math:`g_k = t^{sync}_k - t^{sync}_{k-1}`: the SYNC period as this
  process saw it; a gap over 1.5 T means SYNCs missing or late
  (:attr:`TimingSummary.syncs_missing` counts :math:`\\mathrm{round}(g_k/T) - 1`);
* **unanswered**: cycles that ended (the next SYNC came) without an answer,
  **late**: answers later than one period (:math:`r_k > T`).

Percentiles are nearest-rank over the histogram: the :math:`p`-th percentile
is the upper edge of the bin holding the :math:`\\lceil p\\,n / 100 \\rceil`-th
smallest value (never below the true value, at most one bin width above it);
the maximum is exact.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

#: Histogram bin width [s] (10 us) and range [s] (above it: the overflow bin, the maximum exact).
BIN_S = 10e-6
RANGE_S = 0.1
#: Worst cycles kept per measure.
WORST_K = 5
#: The percentiles reported [%].
PERCENTILES = (50.0, 90.0, 99.0, 99.9)


@dataclass(frozen=True, slots=True)
class Worst:
    """One of the worst cycles of a measure."""

    value_ms: float  #: the measured duration [ms]
    t_s: float  #: the cycle's SYNC arrival [s, the process's clock since its start]
    cycle: int  #: the cycle's number (1 = first SYNC)


@dataclass(frozen=True, slots=True)
class Distribution:
    """A measure over the cycles: count, nearest-rank percentiles (bin upper edges), exact max [ms]."""

    n: int
    p50_ms: float
    p90_ms: float
    p99_ms: float
    p999_ms: float
    max_ms: float
    mean_ms: float
    over_period: int  #: values longer than one SYNC period
    worst: tuple[Worst, ...]
    bin_ms: float  #: the histogram's bin width [ms]
    histogram: tuple[tuple[float, int], ...]  #: (bin lower edge [ms], count) of every non-empty bin

    def as_json(self, histogram: bool = True) -> dict:
        out = {"n": self.n, "p50_ms": self.p50_ms, "p90_ms": self.p90_ms, "p99_ms": self.p99_ms,
               "p99.9_ms": self.p999_ms, "max_ms": self.max_ms, "mean_ms": self.mean_ms,
               "over_period": self.over_period,
               "worst": [{"ms": w.value_ms, "t_s": w.t_s, "cycle": w.cycle} for w in self.worst]}
        if histogram:
            out["histogram"] = {"bin_ms": self.bin_ms, "bins": [[lo, c] for lo, c in self.histogram]}
        return out

    def line(self) -> str:
        return (f"p50 {self.p50_ms:.3f} p99 {self.p99_ms:.3f} p99.9 {self.p999_ms:.3f} "
                f"max {self.max_ms:.3f} ms (n {self.n})")


class Histogram:
    """Durations [s] in fixed bins of ``bin_s`` over ``[0, range_s)`` plus one overflow bin, with the
    exact count, sum and maximum and the ``worst_k`` largest values with their cycle.

    Memory is fixed at construction; :meth:`add` allocates only when a value enters the worst list.
    """

    def __init__(self, period_s: float, bin_s: float = BIN_S, range_s: float = RANGE_S,
                 worst_k: int = WORST_K) -> None:
        if not (bin_s > 0 and range_s > bin_s and period_s > 0 and worst_k >= 0):
            raise ValueError(f"Histogram: need bin_s > 0 (got {bin_s} s), range_s > bin_s (got {range_s} s), "
                             f"period_s > 0 (got {period_s} s), worst_k >= 0 (got {worst_k})")
        self.bin_s = bin_s
        self.period_s = period_s
        self._nbins = int(math.ceil(range_s / bin_s))
        self._counts = [0] * (self._nbins + 1)
        self.n = 0
        self._sum = 0.0
        self.max = 0.0
        self.over_period = 0
        self._k = worst_k
        self._worst: list[tuple[float, int, float]] = []  # min-heap of (value, cycle, t)

    def add(self, value_s: float, t_s: float, cycle: int) -> None:
        """One cycle's value [s] (negative values count as 0: clocks of different resolution)."""
        if value_s < 0.0:
            value_s = 0.0
        i = int(value_s / self.bin_s)
        self._counts[i if i < self._nbins else self._nbins] += 1
        self.n += 1
        self._sum += value_s
        if value_s > self.max:
            self.max = value_s
        if value_s > self.period_s:
            self.over_period += 1
        w = self._worst
        if len(w) < self._k:
            heapq.heappush(w, (value_s, cycle, t_s))
        elif self._k and value_s > w[0][0]:
            heapq.heapreplace(w, (value_s, cycle, t_s))

    def percentile(self, p: float) -> float:
        """Nearest-rank ``p``-th percentile [s]: the upper edge of the bin holding the
        ceil(p n / 100)-th smallest value (the exact maximum when that is the overflow bin or the
        largest value's bin); 0 when empty."""
        if not 0.0 < p <= 100.0:
            raise ValueError(f"percentile p must be in (0, 100] %, got {p}")
        if self.n == 0:
            return 0.0
        rank = max(1, math.ceil(p * self.n / 100.0 - 1e-9))
        seen = 0
        for i, c in enumerate(self._counts):
            seen += c
            if seen >= rank:
                return min((i + 1) * self.bin_s, self.max) if i < self._nbins else self.max
        return self.max  # pragma: no cover (the counts sum to n)

    def summary(self) -> Distribution:
        ms = 1e3
        pcts = [round(self.percentile(p) * ms, 4) for p in PERCENTILES]
        worst = tuple(Worst(round(v * ms, 4), round(t, 6), c) for v, c, t in sorted(self._worst, reverse=True))
        hist = tuple((round(i * self.bin_s * ms, 4), c) for i, c in enumerate(self._counts) if c)
        return Distribution(self.n, *pcts, round(self.max * ms, 4),
                            round(self._sum / self.n * ms, 4) if self.n else 0.0, self.over_period, worst,
                            round(self.bin_s * ms, 6), hist)


@dataclass(frozen=True, slots=True)
class TimingSummary:
    """A process's loop timing over its SYNC cycles (see the module's docstring)."""

    period_ms: float
    cycles: int  #: SYNCs seen
    reaction: Distribution  #: SYNC arrival to this process's PDOs sent
    work: Distribution  #: the cycle's own computation (wall clock)
    work_cpu: Distribution  #: the same in the thread's CPU time (n = 0 if not measured)
    gap: Distribution  #: SYNC to SYNC as seen here
    syncs_missing: int  #: SYNC periods without a SYNC (gaps over 1.5 T, in periods)
    unanswered: int  #: cycles that ended without this process's answer
    late: int  #: answers later than one period

    def as_json(self) -> dict:
        return {"period_ms": self.period_ms, "cycles": self.cycles, "syncs_missing": self.syncs_missing,
                "unanswered": self.unanswered, "late": self.late,
                "reaction": self.reaction.as_json(), "work": self.work.as_json(),
                "work_cpu": self.work_cpu.as_json(histogram=False), "gap": self.gap.as_json()}

    def lines(self, who: str) -> list[str]:
        """The summary for a terminal, one measure per line."""
        return [f"{who} timing: {self.cycles} SYNC cycles, {self.syncs_missing} SYNC periods missing, "
                f"{self.unanswered} unanswered, {self.late} answered after a period",
                f"{who} reaction (SYNC in to PDOs out): {self.reaction.line()}",
                f"{who} work per cycle: {self.work.line()}"
                + (f"; CPU {self.work_cpu.line()}" if self.work_cpu.n else ""),
                f"{who} SYNC to SYNC: {self.gap.line()}"]


class CycleTiming:
    """The per-cycle timing of one process (sans-IO: the caller passes every time [s]).

    Call :meth:`sync` when a SYNC arrives, :meth:`work` with a cycle's computation,
    :meth:`answered` when this process's PDOs of the cycle have been sent (the first call per
    cycle counts), :meth:`summary` at any time.
    """

    def __init__(self, period_s: float, *, bin_s: float = BIN_S, range_s: float = RANGE_S,
                 worst_k: int = WORST_K) -> None:
        self.T = period_s
        self.reaction = Histogram(period_s, bin_s, range_s, worst_k)
        self.work_h = Histogram(period_s, bin_s, range_s, worst_k)
        self.work_cpu = Histogram(period_s, bin_s, range_s, worst_k)
        self.gap = Histogram(period_s, bin_s, range_s, worst_k)
        self.cycles = 0
        self.syncs_missing = 0
        self.unanswered = 0
        self.late = 0
        self._t_sync: float | None = None
        self._answered = True

    def sync(self, t_s: float) -> None:
        """A SYNC arrived at ``t_s`` [s]: a new cycle (the previous one unanswered if it was not)."""
        prev = self._t_sync
        if prev is not None:
            g = t_s - prev
            self.gap.add(g, t_s, self.cycles + 1)
            if g > 1.5 * self.T:
                self.syncs_missing += int(round(g / self.T)) - 1
            if not self._answered:
                self.unanswered += 1
        self.cycles += 1
        self._t_sync = t_s
        self._answered = False

    def work(self, start_s: float, end_s: float, cpu_s: float | None = None) -> None:
        """The cycle's computation ran from ``start_s`` to ``end_s`` [s], using ``cpu_s`` [s] of the
        thread's CPU time (optional)."""
        self.work_h.add(end_s - start_s, start_s, self.cycles)
        if cpu_s is not None:
            self.work_cpu.add(cpu_s, start_s, self.cycles)

    def answered(self, t_s: float) -> None:
        """This process's PDOs of the current cycle left at ``t_s`` [s] (later calls in the cycle: ignored)."""
        if self._answered or self._t_sync is None:
            return
        self._answered = True
        r = t_s - self._t_sync
        self.reaction.add(r, self._t_sync, self.cycles)
        if r > self.T:
            self.late += 1

    def summary(self) -> TimingSummary:
        return TimingSummary(round(self.T * 1e3, 6), self.cycles, self.reaction.summary(), self.work_h.summary(),
                             self.work_cpu.summary(), self.gap.summary(), self.syncs_missing, self.unanswered,
                             self.late)
