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

and in CST the max motor speed 0x6080 as a speed limitation of the torque (:meth:`DriveLimits.speed_held`):

* CiA 402 says only that 0x6080 is the motor's maximal allowed speed in either direction; drives with a
  speed limitation in torque mode (Lenze i700 0x2946, ABB ACSM1, Delta ASDA, CiA 402's extended torque
  mode 0x60C8/0x60C9 with 0x60CA; sources in docs/safety.md) reduce the torque so that the speed stays at
  the limit, and hand back to the target torque once a counter-torque brings the speed below it. Their
  speed loop runs at tens of kHz; here the drive acts once per drive cycle T (the plant's sample period),
  so it limits the torque of the cycle to what brings the motor to the limit by the cycle's end:

  .. math:: \\hat\\omega_k = \\frac{\\varphi_k - \\varphi_{k-1}}{T} + \\frac{T}{2J}\\,\\tau_{k-1},\\qquad
            \\tau_k = \\mathrm{clip}\\Big(\\tau_{cmd},\\ \\frac{J}{T}(-\\omega_{max} - \\hat\\omega_k),\\
            \\frac{J}{T}(\\omega_{max} - \\hat\\omega_k)\\Big)

  (motor angle :math:`\\varphi` [rad] as sampled, :math:`\\tau_{k-1}` the torque the drive commanded in the
  last cycle [N m], 0 when it was not in CST; :math:`J` the motor inertia [kg m^2] of the plant parameters,
  :math:`\\omega_{max}` = 0x6080 [rad/s]); then clipped to 0x6072. Derivation: the free motor (in its
  backlash, no load) obeys :math:`\\omega_{k+1} = \\omega_k + \\tau_k T / J` over a cycle with the torque
  held, and the mean speed over the last cycle lags the speed at its end by :math:`\\tau_{k-1}T/(2J)`, so
  :math:`\\hat\\omega_k` is that speed and the gain :math:`J/T` [N m s/rad] is dead-beat: a limited cycle
  ends at :math:`\\pm\\omega_{max}` exactly. Overshoot: only the estimate's error, the angle's quantisation
  q (each sample rounded by q/2): :math:`\\omega \\le \\omega_{max} + q/T` at the samples and, the torque
  constant within a cycle, between them (shipped: 12-bit resolver, T = 2 ms, i = 5.027 rad/mm:
  q / (T i) = 0.15 mm/s at the ram). Viscous loss and friction slow the motor below the estimate (the
  limit acts earlier). With a load of effective inertia :math:`J' \\ge J` (the motor in contact carries
  the chain and the surface), :math:`\\rho = J/J'`, the error e = omega - omega_max and the torque obey
  :math:`u_k = -e_k - c\\,u_{k-1}`, :math:`e_{k+1} = e_k + \\rho u_k`, :math:`c = (1-\\rho)/2`, with
  poles :math:`\\lambda^2 - c\\lambda - c = 0`, inside the unit circle for every :math:`0 < \\rho \\le 1`
  (the larger root is below 1 iff c < 1/2): stable at the drive cycle whatever the load, without
  overshoot beyond one cycle of an external force that pushes the motor the way it moves
  (:math:`\\tfrac{3}{2}\\,T\\,F_{ext}/(J i^2)` at the ram). Statusword bit 11 while it limits. 0 or no
  0x6080: no limit (a drive whose EDS lacks 0x6080 keeps no speed limit in CST either).

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
    """Mixin: the max motor speed (CSP and CST) and the following error monitoring (CSP) of a simulated drive.

    Attributes
    ----------
    limit_period_us : int
        The drive's cycle (the plant's sample period) [us].
    limit_period_s : float
        The same [s].
    motor_inertia_kg_m2 : float
        The motor's inertia J [kg m^2] (the plant's), the CST speed limit's gain J / T.
    following_error_cycles : int
        Drive cycles in a row with the following error beyond the window.
    last_cycle_phi_rad : float or None
        The motor angle sampled at the last drive cycle [rad] (None before the first).
    last_cst_torque_Nm : float
        The motor torque the drive commanded in that cycle in CST [N m] (0 in another mode).
    """

    def init_limits(self, sample_period_s: float, motor_inertia_kg_m2: float) -> None:
        self.limit_period_us = round(sample_period_s * 1e6)
        self.limit_period_s = float(sample_period_s)
        self.motor_inertia_kg_m2 = float(motor_inertia_kg_m2)
        self.following_error_cycles = 0
        self.reset_speed_estimate()

    def reset_speed_estimate(self) -> None:
        """No motor angle of a last cycle (power-on, reset node): the CST speed limit waits one cycle."""
        self.last_cycle_phi_rad: float | None = None
        self.last_cst_torque_Nm = 0.0

    def speed_held(self, force_N: float, force_max_N: float, i_total_rad_per_mm: float) -> float:
        """The ram force of this CST cycle after the max motor speed 0x6080 (module docstring): ``force_N``
        (the target torque after 0x6072, as a ram force [N]) clipped to the range that keeps the motor
        speed within 0x6080 by the cycle's end, then to +-``force_max_N`` (0x6072 [N]). Call once per
        drive cycle in CST, after :meth:`cycle_angle`; it remembers the torque for the next estimate."""
        prev = self.speed_prev_phi
        gear = i_total_rad_per_mm * 1000.0  # rad/m: motor torque [N m] = force [N] / gear
        rpm = self.store.int_or(0x6080, 0, 0)
        f = force_N
        if rpm > 0 and prev is not None:
            T = self.limit_period_s
            J = self.motor_inertia_kg_m2
            w_hat = (self.cycle_phi_rad - prev) / T + self.speed_prev_torque_Nm * T / (2.0 * J)
            w_max = rpm_to_rad_per_s(rpm)
            k = J / T * gear  # [N per rad/s]: the dead-beat gain J / T, as a ram force
            hi = k * (w_max - w_hat)
            if f > hi:
                f = hi if hi > -force_max_N else -force_max_N
            else:
                lo = k * (-w_max - w_hat)
                if f < lo:
                    f = lo if lo < force_max_N else force_max_N
        self.last_cst_torque_Nm = f / gear
        return f

    def cycle_angle(self, phi_rad: float) -> None:
        """The start of a drive cycle with the motor angle ``phi_rad`` [rad] sampled now: keeps the last
        cycle's angle and torque (0 unless it was a CST cycle) for :meth:`speed_held`."""
        self.speed_prev_phi = self.last_cycle_phi_rad
        self.speed_prev_torque_Nm = self.last_cst_torque_Nm
        self.cycle_phi_rad = phi_rad
        self.last_cycle_phi_rad = phi_rad
        self.last_cst_torque_Nm = 0.0

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
