"""Two simulated CiA 402 EMA drives as CANopen slaves around one rig plant (sans-IO).

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
from sim.drives.pair import SimDrivePair, SimPairStats

__all__ = [
    "EMCY_NO_ERROR",
    "EMCY_PDO_LENGTH_ERROR",
    "EMCY_PDO_LENGTH_EXCEEDED",
    "QUICK_STOP_HOLD_S",
    "TARGET_WINDOW_INC",
    "NmtCommand",
    "NmtState",
    "SimDrive",
    "SimDrivePair",
    "SimPairStats",
    "error_register_bits",
]
