"""The two-process benchmark's readers (tests/bench/bench_two_process.py): the interrupt-handler durations
from a kernel trace, the stall a handler is inside, and the stalls read from a CAN log.

The trace lines are tracefs's text format as this project's development machine wrote it (Linux 6.18,
``trace_clock`` mono); the stamps are made up so that the answers are known.
"""

from __future__ import annotations

import pytest
from bench.bench_two_process import (
    SILENT_MS,
    SLOW_HANDLER_MS,
    Handler,
    KernelTrace,
    Silence,
    is_shared,
    parse_irq_trace,
    slowest_inside,
    stalls,
)

TRACE = """\
# tracer: nop
#
#           TASK-PID     CPU#  |||||  TIMESTAMP  FUNCTION
#              | |         |   |||||     |         |
          <idle>-0       [000] d.h1. 100.000000: local_timer_entry: vector=236
          <idle>-0       [000] dNh4. 100.000002: sched_wakeup: comm=python pid=18391 prio=59 target_cpu=000
          <idle>-0       [000] dNh1. 100.000010: local_timer_exit: vector=236
          <idle>-0       [001] d.h1. 100.001000: call_function_single_entry: vector=251
          <idle>-0       [001] dNh1. 100.001004: call_function_single_exit: vector=251
          python-18387   [000] d.H2. 100.002000: local_timer_entry: vector=236
          <idle>-0       [001] d.h1. 100.002100: irq_handler_entry: irq=36 name=virtio1-req.0
          <idle>-0       [001] d.h1. 100.002106: irq_handler_exit: irq=36 ret=handled
          <idle>-0       [001] d.h1. 100.010000: local_timer_entry: vector=236
          <idle>-0       [001] d.h1. 100.010008: local_timer_exit: vector=236
          python-18387   [000] dNH2. 100.023160: local_timer_exit: vector=236
          python-18391   [001] d.h1. 100.030000: reschedule_entry: vector=253
CPU:1 [LOST 17 EVENTS]
          python-18391   [001] d.h1. 100.030300: reschedule_exit: vector=253
          python-18391   [001] d.h1. 100.040000: local_timer_exit: vector=236
"""


def test_handlers_are_paired_per_cpu_and_name():
    got = parse_irq_trace(TRACE.splitlines(), offset_s=1000.0)
    # 6 pairs: 10 us, 4 us, 6 us, 8 us (CPU 1's timer inside CPU 0's), 21.16 ms, 0.3 ms; the last exit has
    # no entry and is not counted
    assert got["n"] == 6
    assert got["max_ms"] == pytest.approx(21.16, abs=1e-9)
    assert got["over_1ms"] == 1
    assert got["p50_us"] == pytest.approx(9.0)
    assert got["lost_events"] == 17
    assert got["slow"] == [Handler(0, pytest.approx(1100.002), 21.16, "local_timer"),
                           Handler(1, pytest.approx(1100.03), 0.3, "reschedule")]
    # each CPU's intervals without an interrupt event of at least SILENT_MS, from its last event before
    assert got["silent"] == [Silence(0, pytest.approx(1100.002), 21.16),
                             Silence(1, pytest.approx(1100.002106), 7.894),
                             Silence(1, pytest.approx(1100.010008), 19.992),
                             Silence(1, pytest.approx(1100.0303), 9.7)]


def test_slow_threshold_is_inclusive():
    exactly = (f"  x-1 [000] d.h1. 5.000000: irq_work_entry: vector=246\n"
               f"  x-1 [000] d.h1. {5 + SLOW_HANDLER_MS / 1e3:.6f}: irq_work_exit: vector=246\n")
    below = ("  x-1 [001] d.h1. 6.000000: irq_work_entry: vector=246\n"
             "  x-1 [001] d.h1. 6.000199: irq_work_exit: vector=246\n")
    got = parse_irq_trace((exactly + below).splitlines())
    assert [h.cpu for h in got["slow"]] == [0]


def test_silence_threshold_is_inclusive():
    ev = "  x-1 [{cpu:03d}] d.h1. {t:.6f}: local_timer_{edge}: vector=236"
    lines = [ev.format(cpu=0, t=1.0, edge="entry"), ev.format(cpu=0, t=1.000005, edge="exit"),
             ev.format(cpu=0, t=1.000005 + SILENT_MS / 1e3, edge="entry"),
             ev.format(cpu=1, t=1.0, edge="entry"), ev.format(cpu=1, t=1.000005, edge="exit"),
             ev.format(cpu=1, t=1.000004 + SILENT_MS / 1e3, edge="entry")]
    assert [x.cpu for x in parse_irq_trace(lines)["silent"]] == [0]


def test_empty_trace():
    got = parse_irq_trace(["# tracer: nop"])
    assert got["n"] == 0 and got["max_ms"] is None and got["slow"] == [] and got["p99.9_us"] is None
    assert got["silent"] == []


def _stall(a: float, b: float) -> dict:
    return {"first": {"start": a, "end": b, "ms": (b - a) * 1e3}}


def test_slowest_handler_inside_a_stall():
    slow = [Handler(0, 10.000, 0.5, "local_timer"), Handler(1, 10.004, 21.0, "local_timer"),
            Handler(0, 10.100, 3.0, "call_function_single")]
    assert slowest_inside(_stall(10.001, 10.030), slow).ms == 21.0
    # a handler that began before the gap and ran into it counts; one that ended before it does not
    assert slowest_inside(_stall(10.0004, 10.0030), slow) == Handler(0, 10.000, 0.5, "local_timer")
    assert slowest_inside(_stall(10.0006, 10.0030), slow) is None
    assert slowest_inside(_stall(10.050, 10.0995), slow) is None


def test_stalls_from_a_can_log(tmp_path):
    """SYNC every 2 ms; drive 1's TPDO silent for 8 ms once; the master's RPDOs (sent, and udp_multicast's
    echo of them) are not a stream of the drives."""
    lines = []
    t = 1000.0
    for k in range(20):
        ts = t + k * 0.002
        lines.append(f"({ts:.6f}) can0 080#")
        if not 8 <= k <= 10:  # three periods without drive 1's TPDO: a 8 ms gap between k=7 and k=11
            lines.append(f"({ts + 0.0002:.6f}) can0 181#0011223344556677 R")
        if k < 5:
            lines.append(f"({ts + 0.0003:.6f}) can0 201#00112233 T")
            lines.append(f"({ts + 0.0004:.6f}) can0 201#00112233 R")
    log = tmp_path / "can.log"
    log.write_text("\n".join(lines) + "\n")
    got = stalls(log)
    assert len(got) == 1
    st = got[0]
    assert st["silent"] == "sim-serve (TPDO)" and st["streams"] == ["0x181"]
    assert st["first"]["ms"] == pytest.approx(8.0, abs=1e-3) and st["period_ms"] == 2.0
    # at the vcan stage's 10 ms SYNC period the same log has no stall (8 ms < 2.5 periods), and the SYNC
    # stream itself is judged on that period
    assert stalls(log, period_s=0.010) == []
    assert [x["period_ms"] for x in stalls(log, period_s=0.003)] == [3.0]  # 8 ms > 7.5 ms


@pytest.mark.parametrize("held_ms,shared", [(3.0, True), (2.99, False)])
def test_a_stall_is_shared_when_a_bystander_was_held_half_as_long_as_it_was_late(held_ms, shared):
    """First gap 8 ms at a 2 ms period: 6 ms late; a bystander held 3 ms shares it, 2.99 ms does not."""
    st = {"first": {"start": 0.0, "end": 0.008, "ms": 8.0}, "period_ms": 2.0,
          "bystanders_held_ms": {0: 0.0, 1: held_ms}}
    assert is_shared(st) is shared


def test_kernel_trace_says_why_it_cannot_run(tmp_path):
    assert "not mounted" in KernelTrace.problem(tmp_path)
