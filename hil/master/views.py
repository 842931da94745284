"""What the master core knows of each node and its own phase (typed views it owns and mutates).

:class:`NodeView` per node, :class:`DriveView` per EMA's drive (its CiA 402 state as the last
statusword said, when that was, its setpoints' bookkeeping, how it is protected against the
master's death), :class:`Phase` of :class:`hil.master.core.MasterCore`.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from enum import Enum

from hil.canopen.cia402 import State
from hil.canopen.signalmap import ForceControl
from hil.master.drill import MasterLossRecord

__all__ = ["DriveView", "NodeView", "Phase", "RESET_WAIT_CYCLES", "STILL_CYCLES", "STILL_MM"]


#: QUICK STOP ACTIVE: the drive stands still when its motor angle moved less than this over the last
#: :data:`STILL_CYCLES` SYNC cycles [mm of ram stroke] (0.5 mm/s at 2 ms)
STILL_MM = 0.01
STILL_CYCLES = 10
#: SYNC cycles a fault reset is given to take before the next is tried
RESET_WAIT_CYCLES = 10


class Phase(Enum):
    IDLE = "idle"
    PREFLIGHT = "preflight"
    CYCLIC = "cyclic"
    FAILED = "failed"


@dataclass
class NodeView:
    """What the master knows of one node (mutable, owned by the core)."""

    node_id: int
    label: str
    last_heartbeat_s: float | None = None
    nmt_state: int | None = None
    booted: bool = False
    lost: bool = False  #: heartbeat lost (the consumer fired for this node)
    hb_timeout_s: float = 0.15
    identity: dict = field(default_factory=dict)


@dataclass
class DriveView(NodeView):
    """What the master knows of one EMA's drive."""

    ema: int = 0
    force_control: ForceControl = ForceControl.CST
    rated_torque_Nm: float | None = None
    state: State = State.NOT_READY_TO_SWITCH_ON
    statusword: int = 0
    mode_display: int = 0
    mode_sent: int | None = None
    #: (mode, last cycle by which 0x6061 must show it) of a mode change not yet confirmed
    mode_pending: tuple[int, int] | None = None
    last_tpdo_s: float | None = None  #: when the last statusword was received (TPDO or SDO); None: never
    #: the longest time between two statuswords since the last heartbeat [s] (a node silent altogether within
    #: its heartbeat's silence: hil.master.stalls.process_held)
    tpdo_gap_s: float = 0.0
    last_cw: int = 0
    fault_resets: int = 0  #: fault resets sent in a row (bounded by canopen.fault_reset_attempts)
    reset_wait: int = 0  #: cycles left to wait for the last fault reset to take
    still: deque = field(default_factory=lambda: deque(maxlen=STILL_CYCLES))  #: angles in QUICK STOP ACTIVE
    #: how this drive is protected against the master's death (set by the preflight)
    master_loss: MasterLossRecord | None = None
    limits: tuple = ()  #: the limits it keeps itself or the master only (hil.canopen.drivelimits.DriveLimit)
