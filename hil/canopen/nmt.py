"""CiA 301 NMT: node states (the heartbeat state byte), command specifiers and their frames.

One definition shared by the master (:mod:`hil.master.core`) and the simulated
drives (:mod:`sim.drives`). Sans-IO: no bus, no clock.
"""

from __future__ import annotations

from enum import IntEnum

from hil.canopen.frame import HEARTBEAT_COB_ID_BASE, NMT_COB_ID, Frame


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


def nmt_frame(command: NmtCommand, node_id: int = 0) -> Frame:
    """The NMT command frame ``000#[cs, node]`` (node 0: all nodes)."""
    return Frame(NMT_COB_ID, bytes([int(command), node_id]))


def heartbeat_frame(node_id: int, state: NmtState) -> Frame:
    """The heartbeat ``0x700 + node [state]`` (state INITIALISING: the boot-up message)."""
    return Frame(HEARTBEAT_COB_ID_BASE + node_id, bytes([int(state)]))
