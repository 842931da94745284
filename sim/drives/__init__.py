"""The rig's simulated CANopen nodes around one rig plant: two CiA 402 EMA drives and the sensor nodes (sans-IO).

:class:`SimDrivePair` (:mod:`sim.drives.pair`) is the entry point; the
modules of this package are listed in its docstring.
"""

from hil.canopen.emcy import error_register_bits
from hil.canopen.nmt import NmtCommand, NmtState
from sim.drives.cia402_drive import QUICK_STOP_HOLD_S, TARGET_WINDOW_INC
from sim.drives.drive import SimDrive
from sim.drives.nmt_slave import (
    EMCY_NO_ERROR,
    EMCY_PDO_LENGTH_ERROR,
    EMCY_PDO_LENGTH_EXCEEDED,
)
from sim.drives.node import LiveInput, SimNode
from sim.drives.pair import SimDrivePair, SimPairStats
from sim.drives.sensor_node import SimSensorNode

__all__ = [
    "EMCY_NO_ERROR",
    "EMCY_PDO_LENGTH_ERROR",
    "EMCY_PDO_LENGTH_EXCEEDED",
    "QUICK_STOP_HOLD_S",
    "TARGET_WINDOW_INC",
    "NmtCommand",
    "NmtState",
    "LiveInput",
    "SimDrive",
    "SimDrivePair",
    "SimNode",
    "SimPairStats",
    "SimSensorNode",
    "error_register_bits",
]
