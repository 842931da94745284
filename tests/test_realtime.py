"""The real-time set-up's CPU wake-up latency request (hil.cli.realtime) and its flag."""

from __future__ import annotations

import os

import pytest

from hil.cli import realtime
from support.run_flags import assert_run_flag


def test_the_latency_request_is_written_as_linux_reads_it_held_and_let_go(tmp_path):
    """PM QoS reads a 32-bit integer of microseconds from the open file and holds it until the
    file is closed: written as 4 bytes, held after the call, closed by end_realtime()."""
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    assert realtime.hold_cpu_latency(0, str(dev)) == "CPU wake-up latency <= 0 us requested"
    fd = realtime._latency_fd
    assert fd is not None and dev.read_bytes() == (0).to_bytes(4, "little")
    os.fstat(fd)  # still open: the request holds
    realtime.end_realtime()
    assert realtime._latency_fd is None
    with pytest.raises(OSError):
        os.fstat(fd)
    dev.write_bytes(b"")
    realtime.hold_cpu_latency(250, str(dev))
    realtime.hold_cpu_latency(7, str(dev))  # a second request replaces the first (one held)
    assert dev.read_bytes()[-4:] == (7).to_bytes(4, "little")
    realtime.release_cpu_latency()
    assert realtime._latency_fd is None


def test_the_latency_request_is_best_effort_and_refuses_a_negative_value(tmp_path):
    assert realtime.hold_cpu_latency(0, str(tmp_path / "no" / "such")).startswith(
        "CPU wake-up latency not held (")
    assert realtime._latency_fd is None
    with pytest.raises(ValueError, match=r"max_us = -1: a wake-up latency is >= 0 us"):
        realtime.hold_cpu_latency(-1, str(tmp_path / "x"))


@pytest.mark.parametrize("value,ok", [("0", True), ("off", True), ("OFF", True), ("-1", False), ("1.5", False)])
def test_the_cpu_latency_flag_takes_whole_microseconds_from_0_or_off(value, ok, capsys):
    """On its boundary: 0 is taken, -1 refused with the flag named (exit 3, no traceback); 'off' means
    no request. (Without --arm, run refuses to move anything after parsing: exit 3 either way, so the
    message tells which.)"""
    assert_run_flag(["run", "--interface", "virtual", "--channel", "x", "--cpu-latency-us", value],
                    "--cpu-latency-us", ok, capsys)



#: run in a process of its own: mallopt changes the whole process's allocator (not the test worker's)
_HEAP_PROBE = """
import resource, sys
from hil.cli import realtime

said = realtime.hold_heap(int(sys.argv[1])) if sys.argv[1] != "none" else "not held"
before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
items = []
for _ in range(200_000):  # a list grown past 16 384 items: its block is 1.6 MiB at the end
    items.append(None)
del items
faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before
realtime.release_heap()
print(faults, realtime._heap_held, said, sep=";")
"""


def _heap_probe(reserve: str) -> tuple[int, str, str]:
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", _HEAP_PROBE, reserve], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    faults, still, said = r.stdout.strip().split(";")
    return int(faults), still, said


def test_a_held_heap_serves_a_growing_buffer_without_page_faults():
    """A list grown to 200 000 items in a cycle: glibc maps its block of its own once it passes 128 KiB
    and re-maps it as it grows, faulting in each new 4 KiB page (1.6 MiB: ~390 pages, 584-586 measured).
    With the heap held and an 8 MiB reserve, the block grows inside pages faulted in before (at most
    8, the interpreter's own). Released, glibc's defaults are back."""
    free, _, said = _heap_probe("none")
    assert free >= 390 and said == "not held"  # the probe sees the faults the hold removes
    held, still, said = _heap_probe(str(8 << 20))
    assert held <= 8 and said == "heap held (8 MiB reserve)" and still == "False", (held, said)


def test_a_heap_reserve_is_not_negative():
    with pytest.raises(ValueError, match=r"reserve_bytes = -1: a heap reserve is >= 0 bytes"):
        realtime.hold_heap(-1)
    assert realtime._heap_held is False
