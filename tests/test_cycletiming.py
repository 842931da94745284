"""Unit tests of the loop-timing statistics (hil/record/cycletiming.py): known answers, fixed memory."""

from __future__ import annotations

import pytest

from hil.record.cycletiming import CycleTiming, Histogram


def test_percentiles_are_nearest_rank_bin_upper_edges():
    # 1000 values 0.5, 1.5, ..., 999.5 us in 1 us bins: the k-th smallest lies in bin k-1 (upper edge k us)
    h = Histogram(period_s=2e-3, bin_s=1e-6, range_s=2e-3)
    for k in range(1000):
        h.add((k + 0.5) * 1e-6, t_s=float(k), cycle=k + 1)
    assert h.percentile(50) == pytest.approx(500e-6)  # rank 500
    assert h.percentile(99) == pytest.approx(990e-6)  # rank 990
    assert h.percentile(99.9) == pytest.approx(999e-6)  # rank 999
    assert h.percentile(100) == pytest.approx(999.5e-6)  # the exact maximum, not the bin edge
    s = h.summary()
    assert (s.n, s.p50_ms, s.p99_ms, s.p999_ms, s.max_ms) == (1000, 0.5, 0.99, 0.999, 0.9995)
    assert s.mean_ms == pytest.approx(0.5)
    assert [w.cycle for w in s.worst] == [1000, 999, 998, 997, 996]
    assert s.worst[0].t_s == 999.0 and s.over_period == 0


def test_overflow_bin_reports_the_exact_maximum_and_counts_over_period():
    h = Histogram(period_s=2e-3, bin_s=10e-6, range_s=5e-3, worst_k=2)
    for v in [100e-6] * 998 + [3e-3, 0.25]:
        h.add(v, 0.0, 1)
    assert h.percentile(99.8) == pytest.approx(110e-6)  # rank 998: still the 100 us bin
    assert h.percentile(99.9) == pytest.approx(3.01e-3)  # rank 999: the 3 ms value's bin
    assert h.percentile(100) == 0.25  # overflow bin: the exact maximum
    s = h.summary()
    assert s.over_period == 2 and [w.value_ms for w in s.worst] == [250.0, 3.0]
    assert s.histogram == ((0.1, 998), (3.0, 1), (5.0, 1))


def test_memory_is_fixed_whatever_the_count():
    h = Histogram(period_s=2e-3, bin_s=10e-6, range_s=1e-3, worst_k=3)
    for k in range(20000):
        h.add((k % 997) * 1e-6, 0.0, k)
    assert len(h._counts) == 101 and len(h._worst) == 3 and h.n == 20000


def test_cycle_timing_reaction_gaps_missing_unanswered_late():
    T = 2e-3
    ct = CycleTiming(T, bin_s=10e-6)
    # cycle 1: answered after 0.305 ms (work 0.105 ms); cycle 2 (on time): after 2.5 ms (late);
    # then SYNC 3 comes 3 periods after SYNC 2 (2 missing), cycle 3 unanswered, cycle 4 answered
    ct.sync(0.0)
    ct.work(0.0002, 0.000305)
    ct.answered(0.000305)
    ct.answered(0.0009)  # a second send in the same cycle does not count
    ct.sync(0.002)
    ct.answered(0.0045)
    ct.sync(0.008)
    ct.sync(0.010)
    ct.answered(0.0101)
    s = ct.summary()
    assert (s.cycles, s.syncs_missing, s.unanswered, s.late) == (4, 2, 1, 1)
    assert s.reaction.n == 3 and s.reaction.max_ms == 2.5
    assert s.reaction.p50_ms == pytest.approx(0.31)  # 0.305 ms: in the 0.30-0.31 ms bin
    assert s.gap.n == 3 and s.gap.max_ms == 6.0 and s.gap.over_period == 1
    assert s.work.n == 1 and s.work.max_ms == pytest.approx(0.105)
    js = s.as_json()
    assert js["reaction"]["worst"][0] == {"ms": 2.5, "t_s": 0.002, "cycle": 2}
    assert js["late"] == 1 and "p99.9_ms" in js["gap"]


def test_bad_arguments_are_refused_with_their_values():
    with pytest.raises(ValueError, match="bin_s > 0"):
        Histogram(2e-3, bin_s=0.0)
    with pytest.raises(ValueError, match=r"\(0, 100\]"):
        Histogram(2e-3).percentile(0)


def test_the_reports_timing_section_shows_the_measured_percentiles():
    from hil.record.runrecord import Timing
    from hil.report.maint import timing_section

    ct = CycleTiming(2e-3)
    for k in range(1000):  # reaction 0.105 ms, one cycle 1.505 ms
        ct.sync(k * 2e-3)
        ct.work(k * 2e-3, k * 2e-3 + 5e-5, 4e-5)
        ct.answered(k * 2e-3 + (1.505e-3 if k == 500 else 1.05e-4))
    html = timing_section(Timing(ct.summary(), t0_unix_s=0.0, sync="loop-timed", sync_skipped=0,
                                 sync_late_max_ms=0.0))
    row = html.split("<tr>")[2]
    assert row.startswith("<td>SYNC received to RPDOs sent</td><td>1000</td><td>0.110</td><td>0.110</td>"
                          "<td>0.110</td><td>1.505</td>")
    assert "0 answered after a period, 0 unanswered, 0 SYNC periods missing (SYNC loop-timed)" in html
    assert "<img src='data:image/png;base64," in html
