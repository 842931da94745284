"""Shared pieces of the command layer: exit codes, output folders, loading recordings and profiles.

Every command module of :mod:`hil.cli` takes what it shares from here (and
from :mod:`hil.cli.check`), never from another command.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path

from hil.profile.config import Actuation
from hil.profile.load import actuation_from_snapshot, load_actuation
from hil.record.runfolder import is_can_log, read_signals
from hil.record.runrecord import INSTALLATION_KEYS, Installation, RunRecord


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


def add_profile_args(p: argparse.ArgumentParser, *, check: bool = True, sim: bool = False, eds: bool = True) -> None:
    """``--profile``, ``--eds`` (and ``--check``, ``--sim``, ``--seed``): the profiles a command reads."""
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile (mechanics, SYNC period, the drives and sensor nodes, the signal map)")
    if eds:
        add_eds_arg(p)
    if check:
        p.add_argument("--check", metavar="CHECK.toml", type=Path,
                       help="check profile (sweep, opposing force, force fight, safety limits)")
    if sim:
        p.add_argument("--sim", metavar="SIMRIG.toml", type=Path,
                       help="simulated-rig profile (physical parameters, sensor errors, seed)")
        add_seed_arg(p)


def add_seed_arg(p: argparse.ArgumentParser) -> None:
    """``--seed``: the simulated rig's noise seed, 0 to 2^63 - 1."""
    p.add_argument("--seed", type=_seed, help="noise seed, an integer 0 to 2^63-1 (default: the simulated-rig "
                                              "profile's); recorded in meta.json")


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


#: udp_multicast's hop limit when --multicast-hops is not given: the frames never leave this host. With
#: python-can's default (1) every frame also went out of the network card: in a virtual machine each
#: was a transmit to its host, and the sends held both loops for milliseconds (docs/performance.md)
MULTICAST_HOPS_DEFAULT = 0


def _multicast_hops(text: str) -> int:
    """argparse type of ``--multicast-hops``: an IP hop limit, a whole number from 0 to 255."""
    v = _count("an IP hop limit")(text)
    if v > 255:
        raise argparse.ArgumentTypeError(f"{v} is over 255; an IP hop limit (TTL) is 0-255")
    return v


_multicast_hops.__name__ = "IP hop limit"


def multicast_hops_for(interface: str, multicast_hops: int | None) -> int | None:
    """The IP hop limit a bus on ``interface`` is opened with: udp_multicast's (``multicast_hops``, else
    :data:`MULTICAST_HOPS_DEFAULT`), None for any other interface (where ``--multicast-hops`` is refused)."""
    if interface == "udp_multicast":
        return MULTICAST_HOPS_DEFAULT if multicast_hops is None else multicast_hops
    return None


def open_bus(interface: str, channel: str, bitrate: int, *, receive_own_messages: bool = False,
             multicast_hops: int | None = None):
    """A python-can bus, or :class:`hil.errors.InterfaceError` saying what to check (exit status 3).

    ``multicast_hops``: udp_multicast's IP hop limit (default :data:`MULTICAST_HOPS_DEFAULT`: this host
    only); given for another interface, it is refused.
    """
    import can

    from hil.errors import InterfaceError

    kwargs = {"interface": interface, "channel": channel}
    if interface not in ("virtual", "socketcan", "udp_multicast"):
        kwargs["bitrate"] = bitrate
    if receive_own_messages:
        kwargs["receive_own_messages"] = True
    if interface == "udp_multicast":
        kwargs["hop_limit"] = multicast_hops_for(interface, multicast_hops)
    elif multicast_hops is not None:
        raise InterfaceError(f"--multicast-hops {multicast_hops}: applies to --interface udp_multicast only "
                             f"(not {interface!r})")
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        hint = ("check that the interface exists and is up (`ip link show {ch}`; "
                "`sudo ip link set {ch} up type can bitrate {br}`)" if interface == "socketcan" else
                "check that the adapter is connected, its driver installed and the channel name right")
        known = ", ".join(sorted(getattr(can, "VALID_INTERFACES", ()))) or "see python-can"
        raise InterfaceError(
            f"cannot open CAN interface {interface!r} channel {channel!r}: {type(exc).__name__}: {exc}; "
            + hint.format(ch=channel, br=bitrate) + f"; --interface must be one python-can knows ({known})"
        ) from None
    if interface == "udp_multicast":
        _hear_own_group_only(bus, channel)
    return bus


#: Linux's socket options that make a socket bound to a port on every address receive only the multicast
#: groups it joined itself (linux/in.h IP_MULTICAST_ALL, linux/in6.h IPV6_MULTICAST_ALL; default 1: every
#: group joined by any socket on the host)
_IP_MULTICAST_ALL = 49
_IPV6_MULTICAST_ALL = 29


def _hear_own_group_only(bus, channel: str) -> None:
    """Make a udp_multicast bus receive its own group only (Linux), or close it and refuse (fail closed).

    python-can binds the port on every address; on Linux such a socket receives every group joined on the
    host (IP_MULTICAST_ALL defaults to on), so two emacheck buses on two groups would hear each other: a
    check took another job's SDO answer. Turning the option off leaves exactly the group the bus joined.
    Other systems are left as python-can opens them (not verified there; docs/vcan.md).
    """
    import socket

    from hil.errors import InterfaceError

    if not sys.platform.startswith("linux"):
        return
    try:
        sock = bus._multicast._socket  # python-can's GeneralPurposeUdpMulticastBus: its one socket
        if ":" in channel:
            sock.setsockopt(socket.IPPROTO_IPV6, _IPV6_MULTICAST_ALL, 0)
        else:
            sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
    except (AttributeError, OSError) as exc:
        bus.shutdown()
        raise InterfaceError(
            f"udp_multicast group {channel!r}: cannot make the bus hear its own group only "
            f"({type(exc).__name__}: {exc}); without it, it would receive every group joined on this host"
        ) from None


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


def utc_stamp() -> str:
    """The current UTC time as ``20261123T141500Z`` (for folder names)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def utc_iso() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class Outputs:
    """Where a command writes its files: a folder and a prefix for the file names.

    Its files are created, never written over an existing one (:meth:`write_json`, :meth:`write_with`),
    unless ``own``: a run's own result.json and report.html, written into its run folder during the run.
    """

    folder: Path
    prefix: str = ""
    own: bool = False
    made: bool = False  #: the folder was made for these outputs (:meth:`discard_if_empty` may remove it)

    def path(self, name: str) -> Path:
        """The path of output ``name`` (e.g. ``"result.json"``)."""
        return self.folder / f"{self.prefix}{name}"

    def discard_if_empty(self) -> None:
        """After a command failed before writing: remove the folder it made for its outputs, if still empty."""
        if self.made:
            import contextlib

            with contextlib.suppress(OSError):
                self.folder.rmdir()  # (fails, and is left, where anything was written into it)

    def write_json(self, name: str, obj) -> Path:
        """Output ``name`` as JSON: created (:class:`hil.errors.OutputError` if it exists), or for ``own``
        replaced atomically."""
        from hil.record.runfolder import create_json, write_json_atomic

        path = self.path(name)
        if self.own:
            write_json_atomic(path, obj)
            return path
        return create_json(path, obj)

    def write_with(self, name: str, write) -> Path:
        """Output ``name`` written by ``write(path)`` (a report writer): created under a temporary name and
        linked to its own only if that does not exist; for ``own`` written in place."""
        from hil.record.runfolder import create_with

        path = self.path(name)
        if self.own:
            write(path)
            return path
        return create_with(path, write)


def output_stem(path: Path) -> str:
    """The name an analysis of a bare recording is named after: a ``.csv`` file's stem (``flight.csv`` ->
    ``flight``), any other recording's whole name (``flight.csv.gz``, ``flight.log``), so that two
    recordings beside each other never share their outputs' names."""
    if path.name.lower().endswith(".csv") and len(path.name) > 4:
        return path.name[:-4]
    return path.name


def make_folder(folder: Path) -> Path:
    """Make ``folder`` (and its parents); :class:`hil.errors.OutputError` naming it if it cannot be made."""
    from hil.errors import OutputError
    from hil.record.runfolder import output_error

    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{folder}: a file, not a folder; give --out a new or empty folder") from None
    except OSError as exc:
        raise output_error(folder, exc) from None
    if not folder.is_dir():
        raise OutputError(f"{folder}: a file, not a folder; give --out a new or empty folder")
    return folder


def new_folder(parent: Path, name: str) -> Path:
    """A new folder ``parent/name`` (``name-2``, ``name-3`` ... where it exists), made here and now (mkdir
    is exclusive: two commands in the same second get two folders)."""
    from hil.record.runfolder import output_error

    make_folder(parent)
    k = 1
    while True:
        folder = Path(parent) / (name if k == 1 else f"{name}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            k += 1
        except OSError as exc:
            raise output_error(folder, exc) from None


def is_empty_folder(path: Path) -> bool:
    """True for a folder that holds nothing."""
    try:
        return path.is_dir() and next(path.iterdir(), None) is None
    except OSError:
        return False


def fresh_outputs(out: Path, kind: str) -> Outputs:
    """``--out`` of a command that derives files (analyze, serv, diagnose, history): a new or empty folder
    is used as it is; a folder that holds files already (a run folder, an earlier analysis) gets a new
    sub-folder ``<kind>-<UTC time>/``, so nothing in it is written over; a file is refused (exit 3)."""
    from hil.errors import OutputError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: a file, not a folder; give a new or empty folder (or omit --out)")
    if not out.exists() or is_empty_folder(out):
        made = not out.exists()
        return Outputs(make_folder(out), made=made)
    return Outputs(new_folder(out, f"{kind}-{utc_stamp()}"), made=True)


def outputs_for(out: Path | None, recording: Path, run_dir: Path | None, kind: str,
                names: tuple[str, ...] = ()) -> Outputs:
    """Where an analysis of a recording writes, never over what is there: ``--out`` as
    :func:`fresh_outputs` says; for a run folder a new sub-folder ``<kind>-<UTC time>/`` (the check's own
    result stays untouched); for a bare file, files named after it next to it (``flight.csv`` ->
    ``flight.result.json``; ``flight.2.result.json`` where any of ``names`` exists already, then
    ``flight.3.`` ...). The files are created exclusively (:meth:`Outputs.write_json`)."""
    if out is not None:
        return fresh_outputs(out, kind)
    if run_dir is not None:
        return Outputs(new_folder(run_dir, f"{kind}-{utc_stamp()}"), made=True)
    stem, folder = output_stem(recording), recording.parent
    k = 1
    while True:
        prefix = f"{stem}." if k == 1 else f"{stem}.{k}."
        if not any((folder / f"{prefix}{n}").exists() or (folder / f"{prefix}{n}").is_symlink() for n in names):
            return Outputs(folder, prefix=prefix)
        k += 1


def file_hashes(**paths: Path | None) -> dict[str, str]:
    """SHA-256 of each named file (a profile given as None: the shipped one), for traceability."""
    import hashlib

    from hil.profile.load import default_profile_path

    defaults = {"actuation": "actuation.toml", "check": "check.toml", "simrig": "simrig.toml"}
    out = {}
    for name, path in paths.items():
        if path is None:
            if name not in defaults:
                continue
            path = default_profile_path(defaults[name])
        try:
            out[name] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:
            out[name] = ""
    return out


def add_trace_args(p: argparse.ArgumentParser) -> None:
    """``--operator`` and ``--work-order``: who ran the check, for which work order (into result.json)."""
    p.add_argument("--operator", metavar="NAME", help="who runs the check (recorded in meta.json and result.json)")
    p.add_argument("--work-order", metavar="ID", help="the work order it is run for (recorded likewise)")


def history_url_type(text: str) -> str:
    """argparse type of ``--history``: a database URL (only its form is checked here; no database
    library is imported before a check)."""
    from hil.history.errors import HistoryInputError
    from hil.history.url import check_url

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
    g.add_argument("--aircraft", metavar="REG", help="aircraft registration (default: the profile's history.aircraft)")
    g.add_argument("--position", metavar="TEXT", help="where the actuation sits, e.g. 'left aileron' "
                                                      "(default: the profile's history.position)")
    g.add_argument("--rig", metavar="NAME", help="the rig or station (default: the profile's history.rig)")
    g.add_argument("--flight-hours", type=_flight_hours, metavar="FH",
                   help="the aircraft's flight hours at the check (the wear trend's axis)"
                        + ("; with a simulated-rig [wear] table the backlash is worn to them" if simulated else ""))
    g.add_argument("--flight-cycles", type=_flight_cycles, metavar="N", help="the aircraft's flight cycles")


def installation(args: argparse.Namespace, act: Actuation, meta: RunRecord | None = None) -> Installation:
    """Aircraft, position, rig, flight hours and cycles of a check (what the history records about where
    and when it was made): the flags, else the run's record, else the actuation profile's ``[history]``
    (None where nobody said)."""
    held = meta.installation if meta is not None and meta.installation is not None else Installation()
    out = {}
    for k in INSTALLATION_KEYS:
        v = getattr(args, k, None)
        if v is None:
            v = getattr(held, k)
        if v is None and k in ("aircraft", "position", "rig"):
            v = getattr(act.history, k) or None
        out[k] = v
    return Installation(**out)


def history_url(url: str | None, act: Actuation) -> str:
    """The wear history's database: ``url`` (``--history``), else the actuation profile's
    ``history.url``, else the user's SQLite file."""
    if url:
        return url
    if act.history.url:
        return act.history.url
    from hil.history.url import default_url

    return default_url()


def refuse_foreign_history(args: argparse.Namespace, act: Actuation, *, simulated: bool = False) -> None:
    """Before a command that records does anything: a history database given to it (``--history URL``,
    else the actuation profile's ``history.url``) that is an SQLite file of another program is refused
    (exit 3) and left untouched (:mod:`hil.history.guard`; the standard library's sqlite3 only). A
    ``simulated`` check records only with ``--history``."""
    explicit = getattr(args, "history", None)
    if getattr(args, "no_history", False) or (simulated and explicit is None):
        return
    url = explicit if isinstance(explicit, str) else act.history.url or None
    if url:
        from hil.history.guard import refuse_foreign

        refuse_foreign(url)


def record_history(console, args: argparse.Namespace, act: Actuation, result_path: Path, *,
                   run_folder: Path | None, recording: Path | None = None) -> None:
    """After a command wrote its result: record it in the wear history, one line on the console
    either way; never raises and never changes the command's exit status (docs/history.md).

    A real result is recorded unless ``--no-history``; a simulated one only with ``--history``."""
    explicit = getattr(args, "history", None)
    if getattr(args, "no_history", False) or not Path(result_path).is_file():
        return
    from rich.markup import escape

    from hil.history.record import is_simulated, load_result, record_after_check

    try:
        simulated = is_simulated(load_result(result_path))
    except Exception as exc:  # noqa: BLE001 - reported; the command's outcome stands
        console.print(escape(f"NOT recorded in the history: {exc}"), soft_wrap=True)
        return
    if simulated and explicit is None:
        return
    # --history URL (True: --history alone, the profile's or the user's database)
    url = history_url(explicit if isinstance(explicit, str) else None, act)
    record_after_check(url, Path(result_path), run_folder=run_folder, recording=recording,
                       say=lambda m: console.print(escape(m), soft_wrap=True))


def make_console(**kwargs):
    """The terminal of a command (rich); 120 columns when the output is a file or a pipe, so that the
    result table is not folded in a log."""
    import sys

    from rich.console import Console

    if not sys.stdout.isatty():
        kwargs.setdefault("width", 120)
    return Console(**kwargs)


def default_out(kind: str) -> Path:
    """``emacheck-runs/<local time>-<kind>``, made here (``-2``, ``-3`` ... for a second one in the same
    second): where a command writes when ``--out`` is not given."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return new_folder(Path("emacheck-runs"), f"{stamp}-{kind}")


def check_new_run_folder(out: Path | None) -> None:
    """``--out`` of a check (run, dry-run, simulate): a check's record is written once, so a folder that
    holds anything, or a file, is refused (:class:`hil.errors.OutputError`, exit 3) before anything
    is done; a new or empty folder is fine."""
    from hil.errors import OutputError

    if out is None:
        return
    out = Path(out)
    hint = "choose another, or omit --out for a new folder emacheck-runs/<time>-<command>"
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: a file, not a run folder; {hint}")
    if out.is_dir() and not is_empty_folder(out):
        raise OutputError(f"--out {out}: the folder holds files already (a check's record is written once, "
                          f"never into another's); {hint}")


def out_dir(args: argparse.Namespace, kind: str) -> Path:
    """The run folder of a check, made: ``--out`` if it is new or empty (:func:`check_new_run_folder`),
    else :func:`default_out`."""
    if args.out is not None:
        check_new_run_folder(args.out)
        return make_folder(Path(args.out))
    return default_out(kind)


def load_recording(sig_path: Path, act: Actuation, meta: RunRecord | None, *,
                   channels: tuple[str, ...] = (), min_rows: int = 2, what: str = "the analysis",
                   jumps: bool = True):
    """Signals from a CSV, or decoded from a raw CAN log (``*.log``, ``*.log.gz``), step labels from
    the run record's step times. Refused with a jump in time or position (a RecordingError naming the
    file and the line or sample), with fewer than ``min_rows`` rows or a constant signal among
    ``channels`` (an IncompleteRecordingError naming the signal; :mod:`hil.record.signals_csv`). ``jumps``
    False: not checked for jumps (a run that aborted: the sensor fault that stopped it may be one)."""
    from hil.record.signals_csv import refuse_jumps, refuse_unusable

    sig = read_signals(sig_path) if not is_can_log(sig_path) else _decoded(sig_path, act, meta)
    refuse_unusable(sig, channels=channels, min_rows=min_rows, what=what)
    if jumps:
        refuse_jumps(sig, sig_path, act.mechanics.i_total_rad_per_mm, lines=not is_can_log(sig_path), meta=meta,
                     sync_period_s=act.timing.sync_period_s)
    return sig


def _decoded(sig_path: Path, act: Actuation, meta: RunRecord | None):
    import dataclasses

    import numpy as np

    from hil.record.canlog import decode_can_log

    dec = decode_can_log(sig_path, act, meta)
    sig = dec.signals
    steps = meta.steps if meta is not None else None
    if steps:
        label = np.full(sig.n, "", dtype=object)
        for s in steps:
            t1 = s.t_end_s if s.t_end_s is not None else np.inf
            label[(sig.t >= s.t_start_s - 1e-9) & (sig.t < t1 - 1e-9)] = s.name
        sig = dataclasses.replace(sig, step=label.astype(str),
                                  notes=sig.notes + ("step labels from meta.json step times",))
    return sig


def actuation_for(profile: Path | None, meta: RunRecord | None) -> Actuation:
    """The actuation to analyse a recording with: ``--profile`` if given, else the run folder's
    snapshot (what the run used), else the shipped profile."""
    if profile is not None:
        return load_actuation(profile)
    snap = meta.profiles.actuation if meta is not None and meta.profiles is not None else None
    if snap is not None:
        return actuation_from_snapshot(snap)
    return load_actuation(None)
