"""Every numeric option of every command on its boundaries: the last value taken and the first refused on
both sides (exit 3, the option named with its range, no traceback; hil/cli/args.py).

``run``'s flags go through :func:`support.run_flags.assert_run_flag` (run refuses to move anything without
--arm after parsing: the message tells a value taken from one refused); flags of commands that would run
on (dry-run, simulate, sim-serve, history) through :func:`support.run_flags.assert_flag` (parsed only).
(--multicast-hops: test_multicast_bus.py; --cpu-latency-us 0 and -1: test_realtime.py.)
"""

from __future__ import annotations

import pytest

from hil.cli import main
from hil.cli.args import (
    BITRATE_MAX,
    BITRATE_MIN,
    CPU_LATENCY_MAX_US,
    FLIGHT_CYCLES_MAX,
    FLIGHT_HOURS_MAX,
    RT_PRIORITY_MAX,
    SEED_MAX,
)
from support.run_flags import assert_flag, assert_run_flag

RUN = ["run", "--interface", "virtual", "--channel", "emacheck-flags"]


def test_the_documented_ranges():
    assert (RT_PRIORITY_MAX, BITRATE_MIN, BITRATE_MAX) == (99, 10_000, 1_000_000)
    assert (SEED_MAX, CPU_LATENCY_MAX_US) == (2**63 - 1, 2_000_000_000)
    assert FLIGHT_HOURS_MAX == FLIGHT_CYCLES_MAX == 1_000_000


@pytest.mark.parametrize("flag,value,ok", [
    ("--rt-priority", "-1", False), ("--rt-priority", "0", True), ("--rt-priority", "99", True),
    ("--rt-priority", "100", False), ("--rt-priority", "-3", False), ("--rt-priority", "1.5", False),
    ("--bitrate", "9999", False), ("--bitrate", "10000", True), ("--bitrate", "1000000", True),
    ("--bitrate", "1000001", False), ("--bitrate", "-5", False), ("--bitrate", "1e6", False),
    ("--flight-hours", "-0.001", False), ("--flight-hours", "0", True), ("--flight-hours", "1000000", True),
    ("--flight-hours", "1000000.001", False), ("--flight-hours", "nan", False), ("--flight-hours", "inf", False),
    ("--flight-cycles", "-1", False), ("--flight-cycles", "0", True), ("--flight-cycles", "1000000", True),
    ("--flight-cycles", "1000001", False),
    ("--cpu-latency-us", "2000000000", True), ("--cpu-latency-us", "2000000001", False),
    ("--multicast-hops", "256", False),
])
def test_run_flag_on_its_boundary(flag, value, ok, capsys):
    assert_run_flag([*RUN, flag, value], flag, ok, capsys)


def test_a_refused_value_is_named_with_its_range(capsys):
    with pytest.raises(SystemExit):
        main([*RUN, "--rt-priority", "100"])
    err = capsys.readouterr().err
    assert "argument --rt-priority: 100 is over 99; a SCHED_FIFO priority (0: normal scheduling) is a whole " \
           "number 0-99" in err
    with pytest.raises(SystemExit):
        main([*RUN, "--bitrate", "-5"])
    assert "argument --bitrate: -5 bit/s is outside 10000-1000000" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["dry-run"], ["simulate"],
                                     ["sim-serve", "--interface", "virtual", "--channel", "x"]])
@pytest.mark.parametrize("value,parsed", [("-1", None), ("0", 0), (str(2**63 - 1), 2**63 - 1),
                                          (str(2**63), None), ("x", None)])
def test_seed_on_its_boundary(command, value, parsed, capsys):
    assert_flag([*command, "--seed", value], "--seed", parsed, capsys)


@pytest.mark.parametrize("value,parsed", [("-1", None), ("0", 0), ("99", 99), ("100", None)])
def test_sim_serve_rt_priority_on_its_boundary(value, parsed, capsys):
    assert_flag(["sim-serve", "--interface", "virtual", "--channel", "x", "--rt-priority", value], "--rt-priority",
                parsed, capsys)


@pytest.mark.parametrize("value,parsed", [("9999", None), ("10000", 10_000), ("1000000", 1_000_000),
                                          ("1000001", None)])
def test_sim_serve_bitrate_on_its_boundary(value, parsed, capsys):
    assert_flag(["sim-serve", "--interface", "virtual", "--channel", "x", "--bitrate", value], "--bitrate",
                parsed, capsys)


@pytest.mark.parametrize("value,parsed", [("-1", None), ("0", 0), ("0xFFFFFFFF", 0xFFFF_FFFF),
                                          ("0x100000000", None)])
def test_history_actuator_serial_on_its_boundary(value, parsed, capsys):
    assert_flag(["history", "--actuator", value], "--actuator", parsed, capsys)


@pytest.mark.parametrize("command", [["dry-run"], ["analyze", "x.csv"], ["serv", "x.csv"]])
@pytest.mark.parametrize("value,parsed", [("-0.5", None), ("0", 0.0), ("1000000", 1e6), ("1000000.5", None)])
def test_flight_hours_on_its_boundary_for_every_command(command, value, parsed, capsys):
    assert_flag([*command, "--flight-hours", value], "--flight-hours", parsed, capsys)
