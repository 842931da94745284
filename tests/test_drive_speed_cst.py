"""The max motor speed 0x6080 in cyclic synchronous torque mode (sim/drives/limits.py, docs/safety.md).

A drive in CST limits the motor speed to 0x6080 by reducing the torque (the speed limitation drives have
in torque mode): over a cycle the free motor gains tau T / J, so the drive gives at most the torque that
brings it to the limit by the cycle's end. Known answers from the plant parameters (J = 1e-4 kg m^2,
i = 5.0265 rad/mm, T = 2 ms, 12-bit resolver): the speed stays within the limit plus the angle's
quantisation over one cycle, q / (T i) = 0.1526 mm/s at the ram; without 0x6080 it is not limited.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_drive_limits import Rig

from sim.drives.limits import DriveLimits
from sim.params import EmaMechanics
from sim.plant import RigPlant
from support.canopen_rig import make_pair
from support.rigs import I_TOTAL, T_S, brief_rig, quiet

RPM_10 = 480  # 10 mm/s: 480 / 60 rev/s * 2 pi / 5.0265 rad/mm
V_LIMIT = RPM_10 / 60 * 2 * math.pi / I_TOTAL  # 10.0 mm/s
Q_SPEED = 2 * math.pi / 4096 / (T_S * I_TOTAL)  # 0.1526 mm/s: one resolver count per cycle, at the ram
TMAX = 1591  # per mille of 1 N m: 7997 N at the ram (0x6072 of the shipped profile)
J = 1.0e-4  # kg m^2, the brief rig's motor


def _free_rig(rpm: int):
    """EMA 1 in CST with 2 mm of internal play (its motor free for 1 mm), EMA 2 in CSP holding 0."""
    wide = EmaMechanics(2.0, 80e3, 80e3, 0.05, 200e3, 20e3)
    rig = Rig(make_pair(RigPlant(quiet(brief_rig(ema1=wide)), np.random.default_rng(0))))
    rig.write(1, 0x6072, 0, "H", TMAX)
    rig.write(1, 0x6080, 0, "I", rpm)
    rig.enable(mode1=10, mode2=8)
    return rig


def _push(rig, cycles: int, torque: int = TMAX):
    """Cycles of EMA 1 pushing with ``torque``: its motor speed [mm/s] and statusword bit 11 per cycle."""
    v, bit11 = [], []
    for _ in range(cycles):
        rig.cycle(torque=(torque, 0))
        v.append(rig.pair.plant.state().omega_rad_s[0] / I_TOTAL)
        bit11.append(bool(rig.pair.nodes[0].statusword & 0x0800))
    return np.array(v), np.array(bit11)


def test_cst_speed_held_at_0x6080_through_the_backlash():
    rig = _free_rig(RPM_10)
    v, bit11 = _push(rig, 400)
    assert V_LIMIT == pytest.approx(10.0, abs=1e-12)
    assert v.max() <= V_LIMIT + Q_SPEED  # the derived overshoot: the angle's quantisation over one cycle
    assert v.max() > V_LIMIT - Q_SPEED  # it reached the limit (unlimited it would reach ~80 mm/s, below)
    held = np.flatnonzero(v > V_LIMIT - Q_SPEED)
    assert len(held) > 50 and bit11[held[1:]].all()  # limiting all the way through the play (~0.1 s)
    # the ram meets the surface: the motor slows against the chain (0.5 mm of spring at 8 kN, ~60 ms),
    # rings below 0.5 mm/s, and the target torque is applied again
    assert (abs(v[-100:]) < 0.5).all() and not bit11[-100:].any()
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(TMAX * I_TOTAL)
    assert rig.pair.plant.state().F_N[0] == pytest.approx(TMAX * I_TOTAL, rel=0.05)


def test_cst_without_0x6080_the_speed_is_not_limited():
    v, bit11 = _push(_free_rig(0), 150)
    assert v.max() > 5 * V_LIMIT  # 2 a d = 2 * 3.16 m/s^2 * 1 mm: about 80 mm/s
    assert not bit11.any()


def test_cst_speed_limit_both_directions():
    v, bit11 = _push(_free_rig(RPM_10), 150, torque=-TMAX)
    assert v.min() >= -V_LIMIT - Q_SPEED and v.min() < -V_LIMIT + Q_SPEED and bit11.any()


class _Stub(DriveLimits):
    """The mixin alone, at a 12-bit resolution: 0x6080 and the motor angle of each cycle."""

    def __init__(self, rpm: int) -> None:
        self.objects = {(0x6080, 0): rpm}
        self.store = self
        self.init_limits(T_S, J)

    def int_or(self, index: int, sub: int, default: int) -> int:
        return self.objects.get((index, sub), default)


def _coasting(rpm: int, omega: float, force_N: float, fmax: float = 8000.0) -> float:
    """The force a drive gives after one cycle of coasting (no torque) at ``omega`` [rad/s]."""
    d = _Stub(rpm)
    d.cycle_angle(0.0)
    assert d.speed_held(0.0, fmax, I_TOTAL) == 0.0  # no last angle yet: not limited
    d.cycle_angle(omega * T_S)
    return d.speed_held(force_N, fmax, I_TOTAL)


def test_cst_speed_limit_boundary():
    w_max = RPM_10 / 60 * 2 * math.pi
    k = J / T_S * I_TOTAL * 1000.0  # N per rad/s: 251.3
    # coasting just under the limit: no torque stays no torque; just over it: braked by k times the excess
    assert _coasting(RPM_10, w_max * (1 - 1e-9), 0.0) == 0.0
    assert _coasting(RPM_10, w_max + 0.1, 0.0) == pytest.approx(-k * 0.1)
    assert _coasting(RPM_10, -w_max - 0.1, 0.0) == pytest.approx(k * 0.1)
    # a push that ends the cycle at the limit is untouched; a larger one is cut to it
    at_limit = k * 1.0  # coasting 1 rad/s under the limit
    assert _coasting(RPM_10, w_max - 1.0, at_limit * (1 - 1e-9)) == at_limit * (1 - 1e-9)
    assert _coasting(RPM_10, w_max - 1.0, 5000.0) == pytest.approx(at_limit)
    assert _coasting(RPM_10, w_max - 1.0, -5000.0) == -5000.0  # braking is never limited
    # far beyond the limit the brake is 0x6072 at most; 0 = no 0x6080: no limit
    assert _coasting(RPM_10, 3 * w_max, 0.0, fmax=2000.0) == -2000.0
    assert _coasting(0, 3 * w_max, 3000.0) == 3000.0


def test_cst_speed_estimate_uses_the_last_cycles_torque():
    """The mean speed over a cycle lags the speed at its end by half the cycle's gain tau T / (2 J)."""
    d = _Stub(RPM_10)
    w_max = RPM_10 / 60 * 2 * math.pi
    d.cycle_angle(0.0)
    d.speed_held(1000.0, 8000.0, I_TOTAL)  # 1000 N: 0.199 N m, a gain of 3.98 rad/s over the cycle
    tau = 1000.0 / (I_TOTAL * 1000.0)
    gain = tau * T_S / J
    mean = w_max - gain  # the mean of this cycle: the motor ends it at w_max - gain / 2
    d.cycle_angle(mean * T_S)
    k = J / T_S * I_TOTAL * 1000.0
    assert d.speed_held(5000.0, 8000.0, I_TOTAL) == pytest.approx(k * gain / 2)
