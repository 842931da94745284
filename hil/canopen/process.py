"""The process image both ends exchange: drive modes, setpoints, samples.

What the master tells a drive for the next SYNC cycle (:class:`Setpoint`) and
what the two drives' TPDOs carry back (:class:`Sample`), in physical units;
the sequence core, the supervisor, the master and the simulated rig all speak
these. A leaf: no IO, no clocks, no imports from the rest of emacheck.
Units are in the field names; sign conventions:

* ``phi`` is the motor angle in rad, positive when the ram extends.
* ``s`` is the LVDT stroke in mm (ram relative to housing), positive extended.
* ``F`` is the EMA force in N measured by the load cell at the housing,
  positive in compression (the EMA pushes the surface towards +s).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum


class DriveMode(IntEnum):
    """Operating mode of one drive, numbered as CiA 402 modes of operation (0x6060)."""

    DISABLED = 0  #: power stage off, holding brake engaged (motor angle held)
    POSITION = 8  #: cyclic synchronous position (CSP): ``value`` is the motor angle target in rad
    FORCE = 10  #: cyclic synchronous torque (CST): ``value`` is the ram force target in N


@dataclass(frozen=True, slots=True)
class Setpoint:
    """What one drive is told to do for the next sample period."""

    mode: DriveMode
    value: float  # rad for POSITION, N for FORCE, ignored for DISABLED


@dataclass(frozen=True, slots=True)
class Sample:
    """One synchronous sensor sample of both EMAs (as measured, raw units)."""

    t_s: float
    phi1_rad: float
    phi2_rad: float
    s1_mm: float
    s2_mm: float
    F1_N: float
    F2_N: float


#: The seven measured channels of a recording, in file order: (column name, unit). The fields of
#: :class:`Sample` are ``f"{name}_{unit}"``; the first seven columns of a run folder's
#: signals.csv are the names (:data:`hil.record.signals_csv.SIGNAL_COLUMNS`).
MEASURED_CHANNELS: tuple[tuple[str, str], ...] = (
    ("t", "s"), ("phi1", "rad"), ("phi2", "rad"), ("s1", "mm"), ("s2", "mm"), ("F1", "N"), ("F2", "N"))
