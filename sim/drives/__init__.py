"""Two simulated CiA 402 EMA drives as CANopen slaves around one rig plant (sans-IO)."""

from sim.drives.pair import *  # noqa: F401,F403
from sim.drives.pair import __all__  # noqa: F401
