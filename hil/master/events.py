"""What the master core reports: its events for the log and the faults it raises (typed, naming the node).

One small frozen class per kind of event (h11's ``_events.py``): a consumer matches by type, never on a
kind string, and reads typed fields; ``str(event)`` is the line for a log."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.canopen.cia402 import State
from hil.canopen.emcy import Emcy
from hil.canopen.nmt import NmtCommand
from hil.errors import EmacheckError

__all__ = ["BadFrame", "BootUp", "CycleIncomplete", "DisableBySdo", "DriveFault", "DriveStateChanged", "EmcyReceived",
           "HeartbeatLost", "HeartbeatMissed", "LaterFault", "MasterEvent", "MasterFellSilent",
           "MasterHeartbeatResumed", "NmtSent", "NodeConfigured", "QuickStopBySdo", "SyncPeriodsSkipped"]


class DriveFault(EmacheckError, RuntimeError):
    """A drive reported a fault (EMCY or fault state), or did not follow a command, during the check.

    ``emcy``: the EMCY that reported it (None: a state or a command not followed)."""

    def __init__(self, message: str = "", *, emcy: Emcy | None = None) -> None:
        super().__init__(message)
        self.emcy = emcy


class HeartbeatLost(EmacheckError, RuntimeError):
    """A node's heartbeat did not arrive within its timeout.

    ``key``: the profile key of the node's heartbeat (``canopen.heartbeat_period_s`` for a drive,
    ``nodes.NAME.heartbeat_period_s`` for a sensor node); ``at_s``: when it was judged lost [s, the master's
    time]; ``silent_s``: since its last heartbeat [s]; ``overdue_s``: how long a heartbeat may be overdue before
    it is lost, the timeout less the producer period [s]; ``frames_silent_s``: the longest the node sent no
    statusword (TPDO) within the heartbeat's silence [s], the time since its last one or a gap between two since
    its last heartbeat, whichever is longer (NaN: not a drive, or none yet): a node silent altogether, not only
    its heartbeat."""

    def __init__(self, message: str = "", *, key: str = "", at_s: float = math.nan, silent_s: float = math.nan,
                 overdue_s: float = math.nan, frames_silent_s: float = math.nan) -> None:
        super().__init__(message)
        self.key, self.at_s, self.silent_s, self.overdue_s = key, at_s, silent_s, overdue_s
        self.frames_silent_s = frames_silent_s


@dataclass(frozen=True, slots=True)
class MasterEvent:
    """Something the master saw or did, for the log (the core never prints): the base of the
    event classes below, one per kind of event, matched by type (``isinstance`` or ``match``).

    ``str(event)`` is its line for a log.
    """

    t_s: float  #: the master's time of the event [s]
    node_id: int  #: the node it concerns, 0 for the master itself or the bus


@dataclass(frozen=True, slots=True)
class NmtSent(MasterEvent):
    """An NMT command sent (``node_id`` 0: to all nodes)."""

    command: NmtCommand

    def __str__(self) -> str:
        return f"NMT {self.command.name} to " + (f"node {self.node_id}" if self.node_id else "all nodes")


@dataclass(frozen=True, slots=True)
class BootUp(MasterEvent):
    """A node's boot-up message."""

    def __str__(self) -> str:
        return "boot-up"


@dataclass(frozen=True, slots=True)
class NodeConfigured(MasterEvent):
    """The preflight's word on a node: identified and configured, or an option it refused."""

    what: str

    def __str__(self) -> str:
        return self.what


@dataclass(frozen=True, slots=True)
class MasterFellSilent(MasterEvent):
    """The master's-death drill: the master stops its heartbeat (``node_id`` 0)."""

    last_heartbeat_s: float  #: when its last heartbeat went out [s]

    def __str__(self) -> str:
        return f"the master falls silent (last heartbeat at {self.last_heartbeat_s:.3f} s)"


@dataclass(frozen=True, slots=True)
class MasterHeartbeatResumed(MasterEvent):
    """The master's-death drill: the master's heartbeat resumes (``node_id`` 0)."""

    def __str__(self) -> str:
        return "the master's heartbeat resumes"


@dataclass(frozen=True, slots=True)
class DriveStateChanged(MasterEvent):
    """A drive's CiA 402 state changed, as its statusword shows (by PDO, or read by SDO)."""

    old: State
    new: State
    by_sdo: bool = False

    def __str__(self) -> str:
        return f"{self.old.name} -> {self.new.name}" + (" (SDO)" if self.by_sdo else "")


@dataclass(frozen=True, slots=True)
class EmcyReceived(MasterEvent):
    """An emergency message."""

    emcy: Emcy

    def __str__(self) -> str:
        return str(self.emcy)


@dataclass(frozen=True, slots=True)
class CycleIncomplete(MasterEvent):
    """A SYNC cycle whose TPDOs were incomplete at the next SYNC (``node_id`` 0)."""

    cycle: int

    def __str__(self) -> str:
        return f"cycle {self.cycle}: TPDOs incomplete at the next SYNC"


@dataclass(frozen=True, slots=True)
class SyncPeriodsSkipped(MasterEvent):
    """SYNC periods of the cyclic phase without a SYNC (``node_id`` 0): the SYNC after period
    ``last`` came in period ``slot`` (counted from the first cyclic SYNC)."""

    last: int
    slot: int

    def __str__(self) -> str:
        n = self.slot - self.last - 1
        return f"SYNC periods {self.last + 1}..{self.slot - 1} without a SYNC ({n} skipped)"


@dataclass(frozen=True, slots=True)
class BadFrame(MasterEvent):
    """A malformed PDO, counted and ignored."""

    problem: str

    def __str__(self) -> str:
        return self.problem


@dataclass(frozen=True, slots=True)
class HeartbeatMissed(MasterEvent):
    """A node's heartbeat lost (the fault :class:`HeartbeatLost` follows)."""

    def __str__(self) -> str:
        return "heartbeat lost"


@dataclass(frozen=True, slots=True)
class QuickStopBySdo(MasterEvent):
    """Quick stop written to a drive's controlword by SDO: it did not follow the RPDOs."""

    def __str__(self) -> str:
        return "quick stop by SDO (controlword): the drive did not follow the RPDOs"


@dataclass(frozen=True, slots=True)
class DisableBySdo(MasterEvent):
    """Disable voltage written to a drive's controlword by SDO: the preflight failed during the drill."""

    def __str__(self) -> str:
        return "disable voltage by SDO: the preflight failed during the drill"


@dataclass(frozen=True, slots=True)
class LaterFault(MasterEvent):
    """A fault after the first one (recorded, not raised again)."""

    problem: str

    def __str__(self) -> str:
        return self.problem
