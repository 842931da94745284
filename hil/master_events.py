"""What the master core reports: its events for the log and the faults it raises (typed, naming the node)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from hil.errors import EmacheckError

__all__ = ["DriveFault", "EventKind", "HeartbeatLost", "MasterEvent"]


class DriveFault(EmacheckError, RuntimeError):
    """A drive reported a fault (EMCY or fault state), or did not follow a command, during the check."""


class HeartbeatLost(EmacheckError, RuntimeError):
    """A node's heartbeat did not arrive within its timeout."""


class EventKind(Enum):
    """What a :class:`MasterEvent` reports."""

    NMT = "nmt"  #: an NMT command sent
    BOOT = "boot"  #: a node's boot-up message
    SDO = "sdo"  #: an SDO sent outside the preflight (the quick stop by SDO)
    PREFLIGHT = "preflight"  #: a node identified and configured
    DRILL = "drill"  #: the master's-death drill: silent, heard back
    STATE = "state"  #: a drive's CiA 402 state changed
    EMCY = "emcy"  #: an emergency message
    MISSING = "missing"  #: a SYNC cycle whose TPDOs were incomplete at the next SYNC
    BAD_FRAME = "bad_frame"  #: a malformed PDO, counted and ignored
    HEARTBEAT = "heartbeat"  #: a node's heartbeat lost
    FAULT = "fault"  #: a fault after the first one (recorded, not raised again)


@dataclass(frozen=True, slots=True)
class MasterEvent:
    """Something the master saw or did, for the log (the core never prints)."""

    t_s: float
    kind: EventKind
    node_id: int
    detail: str
