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
