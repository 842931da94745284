"""The command line's arguments: exit codes, the common epilog, each shared option and its type.

Every command module of :mod:`hil.cli` takes what it shares from the shared modules (this, :mod:`hil.cli.bus`,
:mod:`hil.cli.console`, :mod:`hil.cli.history_glue`, :mod:`hil.cli.check`) and from :mod:`hil.record`
(:mod:`hil.record.outputs`, :mod:`hil.record.recording`), never from another command.
"""

from __future__ import annotations

import argparse
from enum import IntEnum
from pathlib import Path


class ExitCode(IntEnum):
    """Exit status of every command (README, "Exit status")."""

    PASS = 0  #: the check passed (analyze, dry-run, run, simulate); done (serv, diagnose, sim-serve)
    FAIL = 1  #: a backlash above B_spec
    ABORTED = 2  #: the check aborted or the run is incomplete; result.json says why
    INPUT = 3  #: bad input: profile, recording, EDS or arguments; the message names file, field or line
    INTERNAL = 4  #: an internal error (a bug): one line on the console, the traceback in the log
    INCONCLUSIVE = 5  #: a reading's uncertainty straddles its limit, or a channel was not measured
    NOT_READY = 6  #: commission: the rig is not ready for its first check (every problem named in its report)


EPILOG = """\
exit status: 0 pass (diagnose, sim-serve: done), 1 fail (a backlash proven above B_spec),
2 check aborted or run incomplete (result.json says why), 3 bad input (profile,
recording, EDS, CAN interface, arguments, an --out that is a file or, for a check, holds
files, two EMAs of one serial: the message names the file, field or line),
4 internal error, 5 inconclusive (a reading whose uncertainty straddles B_spec, or a
channel not measured), 6 commission: the rig is not ready (every problem named).
history: 2 its database is down or locked, 3 its URL, file or login cannot be used; a
check's recording in the history never changes its exit status.
Profiles default to the shipped ones (profiles/*.toml)."""


def add_parser(sub, name: str, *, help: str, description: str, handler) -> argparse.ArgumentParser:
    """A sub-command's parser with the common epilog; ``handler(args) -> int`` runs it."""
    p = sub.add_parser(name, help=help, description=description, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(handler=handler)
    return p


def add_profile_args(p: argparse.ArgumentParser, *, check: bool = True, sim: bool = False, eds: bool = True,
                     sim_nodes: bool = False) -> None:
    """``--profile``, ``--eds`` (and ``--check``, ``--sim``, ``--seed``): the profiles a command reads;
    ``sim_nodes``: the command builds simulated CANopen nodes (as the simulated rig's own ``actuation`` says)."""
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (mechanics, SYNC period, the drives and sensor nodes, the signal map)")
    if eds:
        add_eds_arg(p)
    if check:
        p.add_argument("--check", metavar="CHECK.toml", type=Path,
                       help="check profile (sweep, opposing force, force fight, safety limits)")
    if sim:
        p.add_argument("--sim", metavar="SIMRIG.toml", type=Path,
                       help="simulated-rig profile (physical parameters, sensor errors, seed, [[faults]])"
                            + ("; where it names an `actuation` profile, the simulated nodes are built as that one "
                               "says, not as the profile under test, so a mistake in that profile shows"
                               if sim_nodes else ""))
        add_seed_arg(p)


def add_seed_arg(p: argparse.ArgumentParser, recorded: str = "recorded in meta.json") -> None:
    """``--seed``: the simulated rig's noise seed, 0 to 2^63 - 1; ``recorded``: where the command records it."""
    p.add_argument("--seed", type=_seed, help="noise seed, an integer 0 to 2^63-1 (default: the simulated-rig "
                                              f"profile's); {recorded}")


def add_eds_arg(p: argparse.ArgumentParser) -> None:
    """``--eds PATH``: the drives' EDS where the user keeps it (overrides the profile's canopen.eds)."""
    p.add_argument("--eds", metavar="PATH", type=Path,
                   help="the drives' EDS file as its vendor ships it (overrides canopen.eds of the profile)")


def add_recording_args(
        p: argparse.ArgumentParser, writes: str, *,
        recording_help: str = "run folder, signals CSV (t,phi1,phi2,s1,s2,F1,F2) or CAN log (*.log)") -> None:
    """The recording to read, ``--profile`` to read it with and ``--out`` for what the command ``writes``."""
    p.add_argument("recording", metavar="RECORDING", type=Path, help=recording_help)
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (default: the run folder's snapshot, else the shipped one)")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help=f"where {writes} go (default: a new sub-folder of the run folder, or files named after "
                        f"the recording next to it: nothing is overwritten)")
    p.add_argument("--accept-modified", action="store_true",
                   help="analyse a run folder whose recording changed after its check (its SHA-256 in meta.json "
                        "no longer matches: refused otherwise, exit 3); the result then says so")


def add_bus_args(p: argparse.ArgumentParser, interfaces: str, *, required: bool = True) -> None:
    """``--interface``, ``--channel``, ``--bitrate``: a python-can bus (``required``: the first two)."""
    p.add_argument("--interface", required=required, help=f"python-can interface, e.g. {interfaces}")
    p.add_argument("--channel", required=required, help="channel, e.g. can0 or vcan0")
    p.add_argument("--bitrate", type=_bitrate, metavar="BPS",
                   help="bit rate in bit/s, 10000-1000000 (default: the actuation profile's)")
    p.add_argument("--multicast-hops", type=_multicast_hops, default=None, metavar="N",
                   help="udp_multicast only: the datagrams' IP hop limit (TTL), 0-255. Default 0: the frames "
                        "stay on this host (both processes on one machine) and never reach a network card; "
                        "1 reaches the other hosts of the local network (sim-serve on another machine)")


def _multicast_hops(text: str) -> int:
    """argparse type of ``--multicast-hops``: an IP hop limit, a whole number from 0 to 255."""
    v = _count("an IP hop limit")(text)
    if v > 255:
        raise argparse.ArgumentTypeError(f"{v} is over 255; an IP hop limit (TTL) is 0-255")
    return v


_multicast_hops.__name__ = "IP hop limit"


def _cpu_latency(text: str) -> int | None:
    """argparse type of ``--cpu-latency-us``: a whole number of microseconds >= 0, or ``off``."""
    if text.strip().lower() == "off":
        return None
    return _count("CPU wake-up latency [us]", CPU_LATENCY_MAX_US)(text)


_cpu_latency.__name__ = "CPU wake-up latency"


def add_cpu_latency_arg(p) -> None:
    """``--cpu-latency-us``: the CPUs' wake-up latency held while the cyclic loop runs (hil.cli.realtime)."""
    p.add_argument("--cpu-latency-us", type=_cpu_latency, default=None, metavar="N|off",
                   help="while the cyclic loop runs, ask Linux to keep every CPU able to wake within N us "
                        "(/dev/cpu_dma_latency, as cyclictest does; needs root, best effort); 0: idle CPUs "
                        "poll instead of sleeping. For a PC whose deep C-states wake slowly. Default off: in "
                        "a virtual machine the polling may cost more than it saves (measured in a 2-core "
                        "VM: both loops stalled 6 ms every 0.1-0.4 s, the check stopped by its freshness "
                        "limit within seconds)")


def _count(what: str, hi: int | None = None):
    """argparse type of a whole number from 0 to ``hi`` (None: no upper bound), named ``what`` in its
    error (a seed, flight cycles); argparse names the option: ``argument --rt-priority: 100 is over 99;
    a SCHED_FIFO priority is 0-99``."""
    span = ">= 0" if hi is None else f"0-{hi}"

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer ({what}): {text!r}") from None
        if v < 0:
            raise argparse.ArgumentTypeError(f"{v} is negative; {what} is a whole number {span}")
        if hi is not None and v > hi:
            raise argparse.ArgumentTypeError(f"{v} is over {hi}; {what} is a whole number {span}")
        return v

    parse.__name__ = what  # argparse names the type in "invalid <name> value"
    return parse


#: the largest seed: a signed 64-bit integer (meta.json and the history are read by other tools too)
SEED_MAX = 2**63 - 1
#: CAN bit rates [bit/s]: CiA 301's lowest (10 kbit/s) to classic CAN's highest (1 Mbit/s); rates between the
#: standard ones (83.3 kbit/s, ...) are the adapter's business
BITRATE_MIN, BITRATE_MAX = 10_000, 1_000_000
#: the largest SCHED_FIFO priority on Linux (0: normal scheduling)
RT_PRIORITY_MAX = 99
#: the largest CPU wake-up latency [us] Linux's PM QoS takes (its default, "no constraint": 2e9 us)
CPU_LATENCY_MAX_US = 2_000_000_000
#: the most flight hours and flight cycles an airframe can have (5 times the longest design lives, ~2e5)
FLIGHT_HOURS_MAX = FLIGHT_CYCLES_MAX = 1_000_000

_rt_priority = _count("a SCHED_FIFO priority (0: normal scheduling)", RT_PRIORITY_MAX)


def rt_priority_arg(p: argparse.ArgumentParser, help: str) -> None:
    """``--rt-priority N``: SCHED_FIFO priority 1-99 of the cyclic loop, 0 (the default) normal scheduling."""
    p.add_argument("--rt-priority", type=_rt_priority, default=0, metavar="N", help=help)


def _bitrate(text: str) -> int:
    """argparse type of ``--bitrate``: a whole number of bit/s from 10 000 to 1 000 000."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer (a CAN bit rate in bit/s): {text!r}") from None
    if not BITRATE_MIN <= v <= BITRATE_MAX:
        raise argparse.ArgumentTypeError(
            f"{v} bit/s is outside {BITRATE_MIN}-{BITRATE_MAX}; a CAN bit rate is 10 kbit/s to 1 Mbit/s "
            f"(CiA 301: 10000, 20000, 50000, 125000, 250000, 500000, 800000, 1000000)")
    return v


_bitrate.__name__ = "CAN bit rate"


_seed = _count("a seed", SEED_MAX)


def identity_text(text: str) -> str:
    """argparse type of an identity text (``--aircraft``, ``--position``, ``--rig``, ``--operator``,
    ``--work-order``): at most :data:`hil.profile.config.IDENTITY_MAX_CHARS` characters (argparse names the
    option: ``argument --aircraft: 65 characters; an identity text is at most 64``, exit 3)."""
    from hil.profile.config import IDENTITY_MAX_CHARS

    if len(text) > IDENTITY_MAX_CHARS:
        raise argparse.ArgumentTypeError(f"{len(text)} characters; an identity text is at most {IDENTITY_MAX_CHARS} "
                                         f"(a registration, part or serial number needs at most 32; docs/report.md)")
    return text


identity_text.__name__ = "identity text"


def add_trace_args(p: argparse.ArgumentParser) -> None:
    """``--operator`` and ``--work-order``: who ran the check, for which work order (into result.json)."""
    p.add_argument("--operator", metavar="NAME", type=identity_text,
                   help="who runs the check (recorded in meta.json and result.json; at most 64 characters)")
    p.add_argument("--work-order", metavar="ID", type=identity_text,
                   help="the work order it is run for (recorded likewise; at most 64 characters)")


def history_url_type(text: str) -> str:
    """argparse type of ``--history``: a database URL (only its form is checked here; no database
    library is imported before a check)."""
    from hil.errors import HistoryInputError
    from hil.profile.history_url import check_url

    try:
        return check_url(text)
    except HistoryInputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _flight_hours(text: str) -> float:
    import math

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of flight hours: {text!r}") from None
    if not math.isfinite(v) or not 0 <= v <= FLIGHT_HOURS_MAX:
        raise argparse.ArgumentTypeError(f"{text} flight hours: must be a finite number from 0 to {FLIGHT_HOURS_MAX}")
    return v


_flight_cycles = _count("flight cycles", FLIGHT_CYCLES_MAX)


def add_history_args(p: argparse.ArgumentParser, *, simulated: bool) -> None:
    """The wear history's flags (docs/history.md): where the result is recorded and what the record
    says about the installation. A real check is recorded unless ``--no-history``; a simulated one
    (``simulated``) only with ``--history``."""
    g = p.add_argument_group("wear history (docs/history.md)")
    if simulated:
        g.add_argument("--history", nargs="?", const=True, metavar="URL", type=history_url_type,
                       help="record this simulated check in the wear history, marked simulated (never in a real "
                            "actuator's trend): into URL, else the actuation profile's history.url, else the "
                            "user's SQLite file")
    else:
        g.add_argument("--history", metavar="URL", type=history_url_type,
                       help="record the result into this database (sqlite:///PATH or postgresql://USER@HOST/DB) "
                            "instead of the actuation profile's history.url or the user's SQLite file")
        g.add_argument("--no-history", action="store_true", help="do not record this result in the wear history")
    g.add_argument("--aircraft", metavar="REG", type=identity_text,
                   help="aircraft registration (default: the profile's history.aircraft); identity texts: at most "
                        "64 characters")
    g.add_argument("--position", metavar="TEXT", type=identity_text,
                   help="where the actuation sits, e.g. 'left aileron' (default: the profile's history.position)")
    g.add_argument("--rig", metavar="NAME", type=identity_text,
                   help="the rig or station (default: the profile's history.rig)")
    g.add_argument("--flight-hours", type=_flight_hours, metavar="FH",
                   help="the aircraft's flight hours at the check (the wear trend's axis)"
                        + ("; with a simulated-rig [wear] table the backlash is worn to them" if simulated else ""))
    g.add_argument("--flight-cycles", type=_flight_cycles, metavar="N", help="the aircraft's flight cycles")


