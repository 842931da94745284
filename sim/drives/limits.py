"""The limits a simulated drive keeps itself beyond the clipping of its targets (CiA 402).

:class:`DriveLimits` is a mixin of :class:`sim.drives.drive.SimDrive`. The software position limits
0x607D and the max torque 0x6072 clip the targets in :meth:`sim.drives.cia402_drive.Cia402Drive.drive_cycle`;
this part adds, in CSP (the objects and their units: :mod:`hil.canopen.drivelimits`):

* max motor speed 0x6080 [rpm]: the position demand moves by at most the distance that speed covers in one
  drive cycle (the sample period), from the last demand (from the position actual value when the drive
  enters CSP); a demand so limited sets statusword bit 11 (internal limit active), as a clipped target does.
  0 (the shipped EDS's default: not set) or no 0x6080: no limit.
* following error window 0x6065 [position units] and time out 0x6066 [ms]: when the position actual value
  lies farther than the window from the demand the drive followed for longer than the time out (counted in
  drive cycles: ``n T > time out``), the drive faults with error code 0x8611 (EMCY, transition 13:
  FAULT REACTION ACTIVE, then FAULT, the drive function disabled). 0xFFFFFFFF or no 0x6065: no monitoring.

It uses ``store``, ``position_inc``, ``angle_increments_per_rad`` and ``enter_fault`` of the drive.
"""

from __future__ import annotations

import math

from hil.canopen.drivelimits import rpm_to_rad_per_s
from hil.canopen.emcy import EmcyCode

__all__ = ["FOLLOWING_ERROR_OFF", "DriveLimits"]

#: 0x6065 = this value switches the following error monitoring off (CiA 402).
FOLLOWING_ERROR_OFF = 0xFFFF_FFFF


class DriveLimits:
    """Mixin: the max motor speed and the following error monitoring of a simulated drive in CSP.

    Attributes
    ----------
    limit_period_us : int
        The drive's cycle (the plant's sample period) [us].
    following_error_cycles : int
        Drive cycles in a row with the following error beyond the window.
    """

    def init_limits(self, sample_period_s: float) -> None:
        self.limit_period_us = round(sample_period_s * 1e6)
        self.following_error_cycles = 0

    def speed_limited(self, demand_inc: int, previous_inc: int | None) -> int:
        """The position demand of this cycle after the max motor speed 0x6080 (``previous_inc``: the last
        cycle's demand, None when the drive enters CSP: from the position actual value)."""
        rpm = self.store.int_or(0x6080, 0, 0)
        if rpm <= 0:
            return demand_inc
        base = self.position_inc if previous_inc is None else previous_inc
        step = rpm_to_rad_per_s(rpm) * self.angle_increments_per_rad() * self.limit_period_us * 1e-6
        if abs(demand_inc - base) <= step:
            return demand_inc
        return base + (math.floor(step) if demand_inc > base else -math.floor(step))

    def following_error_exceeded(self, demand_inc: int | None) -> bool:
        """Judge the last cycle's demand against the position actual value now; True when the drive has
        just faulted (0x8611) on a following error beyond 0x6065 for longer than 0x6066."""
        window = self.store.int_or(0x6065, 0, FOLLOWING_ERROR_OFF)
        if demand_inc is None or window == FOLLOWING_ERROR_OFF or abs(demand_inc - self.position_inc) <= window:
            self.following_error_cycles = 0
            return False
        self.following_error_cycles += 1
        if self.following_error_cycles * self.limit_period_us > self.store.int_or(0x6066, 0, 0) * 1000:
            self.following_error_cycles = 0
            self.enter_fault(int(EmcyCode.FOLLOWING_ERROR))
            return True
        return False
