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
  speed loop runs at kHz; here the drive acts once per drive cycle T (the plant's sample period), so it
  gives at most the torque that brings the motor to the limit by the cycle's end. In speed gained per
  cycle (:math:`g = \\tau T / J`, J the plant's motor inertia [kg m^2], :math:`\\tau` [N m]), with the
  motor angles :math:`\\varphi` sampled at this and the last two cycles, the mean speeds
  :math:`m_k = (\\varphi_k - \\varphi_{k-1})/T` and the torques the drive commanded in CST
  (:math:`g_{k-1}, g_{k-2}`; 0 in another mode):

  .. math:: \\hat d = m_k - m_{k-1} - \\tfrac12 (g_{k-1} + g_{k-2}),\\qquad
            \\hat\\omega_{k+1}(g) = m_k + \\tfrac12 g_{k-1} + \\tfrac32 \\hat d + g,\\qquad
            |\\hat\\omega_{k+1}| \\le \\omega_{max}

  i.e. :math:`\\tau_k = \\mathrm{clip}(\\tau_{cmd}, \\tfrac{J}{T}(-\\omega_{max} - \\hat\\omega_{k+1}(0)),
  \\tfrac{J}{T}(\\omega_{max} - \\hat\\omega_{k+1}(0)))`, then clipped to 0x6072
  (:math:`\\omega_{max}` = 0x6080 in rad/s). Derivation: over a cycle with the torque held and a load
  d (speed per cycle) constant over two cycles, :math:`\\omega_{k+1} = \\omega_k + g_k + d` and the mean
  lags the end, :math:`m_k = \\omega_k - (g_{k-1} + d)/2`; the difference of two means gives d, so
  :math:`\\hat\\omega_{k+1}` is exact for a free motor (d = 0) and for a steady load (in contact the
  chain's force: the torque is kept up to the limit itself, not cut early as a free-motor prediction
  would at long cycles). The gain J/T [N m s/rad] is dead-beat: a limited cycle ends at the limit.
  Overshoot: the estimate's error from the angle's quantisation q (each sample rounded by q/2:
  :math:`(\\tfrac52 e_k - 4 e_{k-1} + \\tfrac32 e_{k-2})/T`), at most :math:`4q/T`: shipped 12-bit
  resolver, T = 2 ms, i = 5.027 rad/mm: 0.61 mm/s at the ram (0.12 mm/s at the vcan stage's 10 ms), plus
  a change of the load within a cycle. Stability: with a load of effective inertia J' the loop
  (states :math:`\\omega, m_k, m_{k-1}, g_{k-1}, g_{k-2}`) has its poles inside the unit circle for
  :math:`0.6 J < J'` (spectral radius 0.42 at J' = 1.1 J, 0.76 at 2 J, 0.96 at 10 J, 0 at J' = J), so at
  the drive cycle whatever the load the motor carries (J' >= J). Statusword bit 11 while it limits. 0 or
  no 0x6080: no limit (a drive whose EDS lacks 0x6080 keeps no speed limit in CST either).

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
    angles_rad : tuple
        ``(phi_k, phi_k-1, phi_k-2)``: the motor angles sampled at this and the last two drive cycles [rad]
        (None before they exist); :meth:`cycle_angle` shifts them.
    cst_torques_Nm : tuple
        ``(tau_k-1, tau_k-2)``: the motor torques the drive commanded in CST in the last two cycles [N m]
        (0 in another mode).
    cst_torque_Nm : float
        The torque commanded in CST in this cycle [N m] (0 until :meth:`speed_held`).
    """

    def init_limits(self, sample_period_s: float, motor_inertia_kg_m2: float) -> None:
        self.limit_period_us = round(sample_period_s * 1e6)
        self.limit_period_s = float(sample_period_s)
        self.motor_inertia_kg_m2 = float(motor_inertia_kg_m2)
        self.following_error_cycles = 0
        self.reset_speed_estimate()

    def reset_speed_estimate(self) -> None:
        """No motor angles of earlier cycles (power-on, reset node): the CST speed limit waits a cycle."""
        self.angles_rad: tuple = (None, None, None)
        self.cst_torques_Nm: tuple = (0.0, 0.0)
        self.cst_torque_Nm = 0.0

    def cycle_angle(self, phi_rad: float) -> None:
        """A drive cycle begins with the motor angle ``phi_rad`` [rad] sampled now (every mode)."""
        a = self.angles_rad
        self.angles_rad = (phi_rad, a[0], a[1])
        self.cst_torques_Nm = (self.cst_torque_Nm, self.cst_torques_Nm[0])
        self.cst_torque_Nm = 0.0

    def speed_held(self, force_N: float, force_max_N: float, i_total_rad_per_mm: float) -> float:
        """The ram force of this CST cycle after the max motor speed 0x6080 (module docstring): ``force_N``
        (the target torque after 0x6072, as a ram force [N]) clipped to the range whose predicted speed
        at the cycle's end lies within +-0x6080, then to +-``force_max_N`` (0x6072 as a ram force [N]).
        Called once per drive cycle in CST, after :meth:`cycle_angle`."""
        phi, phi1, phi2 = self.angles_rad
        tau1, tau2 = self.cst_torques_Nm
        gear = i_total_rad_per_mm * 1000.0  # rad/m: motor torque [N m] = force [N] / gear
        rpm = self.store.int_or(0x6080, 0, 0)
        f = force_N
        if rpm > 0 and phi1 is not None:
            T = self.limit_period_s
            J = self.motor_inertia_kg_m2
            c = T / J  # speed gained per N m over a cycle [rad/s]
            m = (phi - phi1) / T  # the mean speed over the last cycle [rad/s]
            d = 0.0 if phi2 is None else m - (phi1 - phi2) / T - 0.5 * c * (tau1 + tau2)  # the load's gain
            w_end = m + 0.5 * c * tau1 + 1.5 * d  # the speed at the cycle's end without torque
            w_max = rpm_to_rad_per_s(rpm)
            k = gear / c  # [N per rad/s]: the dead-beat gain J / T, as a ram force
            hi = k * (w_max - w_end)
            if f > hi:
                f = hi if hi > -force_max_N else -force_max_N
            else:
                lo = k * (-w_max - w_end)
                if f < lo:
                    f = lo if lo < force_max_N else force_max_N
        self.cst_torque_Nm = f / gear
        return f

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
