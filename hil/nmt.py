"""CiA 301 NMT: node states (the heartbeat state byte) and command specifiers.

One definition shared by the master (:mod:`hil.master`) and the simulated
slaves (:mod:`sim.slave`). A leaf module: no IO, no imports from emacheck.
"""

from __future__ import annotations

from enum import IntEnum


class NmtState(IntEnum):
    """NMT states of a CANopen slave, valued as the heartbeat state byte."""

    INITIALISING = 0x00  #: also the boot-up message
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F

    BOOT_UP = 0x00  # alias of INITIALISING: the boot-up heartbeat


class NmtCommand(IntEnum):
    """NMT command specifiers (byte 0 of the NMT frame, COB-ID 0)."""

    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82

    PRE_OPERATIONAL = 0x80  # alias of ENTER_PRE_OPERATIONAL
