"""The max motor speed 0x6080 in cyclic synchronous torque mode (sim/drives/limits.py, docs/safety.md).

A drive in CST limits the motor speed to 0x6080 by reducing the torque (the speed limitation drives have
in torque mode): over a cycle the motor gains (tau + load) T / J, so the drive gives at most the torque
that brings it to the limit by the cycle's end, the load estimated from the last cycles. Known answers
from the plant parameters (J = 1e-4 kg m^2, i = 5.0265 rad/mm, T = 2 ms, 12-bit resolver): the speed
stays within the limit plus the estimate's quantisation error, 4 q / (T i) = 0.61 mm/s at the ram;
without 0x6080 it is not limited.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from test_drive_limits import Rig

from hil.cli import main
from hil.record.runfolder import read_signals
from sim.drives.limits import DriveLimits
from sim.params import EmaMechanics
from sim.plant import RigPlant
from support.canopen_rig import make_pair
from support.rigs import I_TOTAL, T_S, brief_rig, quiet

RPM_10 = 480  # 10 mm/s: 480 / 60 rev/s * 2 pi / 5.0265 rad/mm
V_LIMIT = RPM_10 / 60 * 2 * math.pi / I_TOTAL  # 10.0 mm/s
Q_SPEED = 2 * math.pi / 4096 / (T_S * I_TOTAL)  # 0.1526 mm/s: one resolver count per cycle, at the ram
OVERSHOOT = 4 * Q_SPEED  # 0.61 mm/s: the estimate's error (sim/drives/limits.py)
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
    v, bit11 = _push(rig, 1000)
    assert V_LIMIT == pytest.approx(10.0, abs=1e-12)
    assert abs(v).max() <= V_LIMIT + OVERSHOOT  # the derived overshoot
    assert v.max() > V_LIMIT - Q_SPEED  # it reached the limit (unlimited it would reach ~80 mm/s, below)
    crossing = np.flatnonzero(v > V_LIMIT - OVERSHOOT)
    assert len(crossing) > 50 and bit11[1:crossing[-1]].mean() > 0.9  # limiting through the play (0.2 s)
    # the ram meets the surface at the limit speed and rings on the chain (7.9 Hz, 2 % damping, the speed
    # never beyond the limit); the target torque is applied again
    assert abs(v[-200:]).max() < 0.5 * V_LIMIT and not bit11[-200:].any()
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(TMAX * I_TOTAL)
    assert rig.pair.plant.state().F_N[0] == pytest.approx(TMAX * I_TOTAL, rel=0.05)


def test_cst_without_0x6080_the_speed_is_not_limited():
    v, bit11 = _push(_free_rig(0), 150)  # (the same rig, 0x6080 = 0)
    assert v.max() > 5 * V_LIMIT  # 2 a d = 2 * 3.16 m/s^2 * 1 mm: about 80 mm/s
    assert not bit11.any()


def test_cst_speed_limit_both_directions():
    v, bit11 = _push(_free_rig(RPM_10), 150, torque=-TMAX)
    assert -V_LIMIT - OVERSHOOT <= v.min() < -V_LIMIT + Q_SPEED and bit11.any()


class _Stub(DriveLimits):
    """The mixin alone, at a 12-bit resolution: 0x6080 and the motor angle of each cycle."""

    def __init__(self, rpm: int) -> None:
        self.objects = {(0x6080, 0): rpm}
        self.store = self
        self.init_limits(T_S, J)

    def int_or(self, index: int, sub: int, default: int) -> int:
        return self.objects.get((index, sub), default)


K = J / T_S * I_TOTAL * 1000.0  # N per rad/s: 251.3, the dead-beat gain J / T as a ram force
W_MAX = RPM_10 / 60 * 2 * math.pi  # rad/s


def _after(rpm: int, omega: float, force_N: float, torque_Nm: float = 0.0, fmax: float = 8000.0) -> float:
    """The force a drive gives after three cycles at a constant speed ``omega`` [rad/s] under a torque
    ``torque_Nm`` held in CST in the last two (0: coasting; else balanced by a load, as in contact)."""
    d = _Stub(0)  # (no limit while the history builds up)
    for j in range(3):
        d.cycle_angle(j * omega * T_S)
        d.speed_held(torque_Nm * I_TOTAL * 1000.0, fmax, I_TOTAL)
    d.cycle_angle(3 * omega * T_S)
    d.objects[(0x6080, 0)] = rpm
    return d.speed_held(force_N, fmax, I_TOTAL)


def test_cst_speed_limit_boundary_coasting():
    # coasting just under the limit: no torque stays no torque; just over it: braked by K times the excess
    assert _after(RPM_10, W_MAX * (1 - 1e-9), 0.0) == 0.0
    assert _after(RPM_10, W_MAX + 0.1, 0.0) == pytest.approx(-K * 0.1)
    assert _after(RPM_10, -W_MAX - 0.1, 0.0) == pytest.approx(K * 0.1)
    # a push that ends the cycle at the limit is untouched; a larger one is cut to it
    assert _after(RPM_10, W_MAX - 1.0, K * (1 - 1e-9)) == K * (1 - 1e-9)
    assert _after(RPM_10, W_MAX - 1.0, 5000.0) == pytest.approx(K)
    assert _after(RPM_10, W_MAX - 1.0, -5000.0) == -5000.0  # braking is never limited
    # far beyond the limit the brake is 0x6072 at most; 0 = no 0x6080: no limit
    assert _after(RPM_10, 3 * W_MAX, 0.0, fmax=2000.0) == -2000.0
    assert _after(0, 3 * W_MAX, 3000.0) == 3000.0


def test_cst_speed_limit_boundary_against_a_load():
    """A steady speed under a torque a load balances: the torque is kept up to the limit itself (the load
    observer: the last cycles' speed change against their torque), not cut as for a free motor."""
    tau = 1000.0 / (I_TOTAL * 1000.0)  # 1000 N at the ram
    assert _after(RPM_10, W_MAX * (1 - 1e-9), 1000.0, tau) == pytest.approx(1000.0, abs=1e-9)
    assert _after(RPM_10, W_MAX * 0.5, 1000.0, tau) == 1000.0  # a free motor would be cut at 0.5 W_MAX
    assert _after(RPM_10, W_MAX + 0.1, 1000.0, tau) == pytest.approx(1000.0 - K * 0.1)


def test_cst_speed_estimate_of_a_free_motor_is_exact():
    """A free motor under a constant torque for three cycles: its speed now, omega_0 + 3 g, is estimated
    from the angles and the torques; the drive gives what brings it to the limit by the cycle's end."""
    tau = 1000.0 / (I_TOTAL * 1000.0)
    g = tau * T_S / J  # rad/s per cycle
    w0 = W_MAX - 1.0 - 3 * g  # the motor is 1 rad/s under the limit now
    d = _Stub(0)
    for j in range(3):
        d.cycle_angle(w0 * j * T_S + g * j * j * T_S / 2)
        d.speed_held(1000.0, 8000.0, I_TOTAL)
    d.cycle_angle(w0 * 3 * T_S + g * 9 * T_S / 2)
    d.objects[(0x6080, 0)] = RPM_10
    assert d.speed_held(5000.0, 8000.0, I_TOTAL) == pytest.approx(K * 1.0)


VCAN = Path(__file__).resolve().parent / "vcan"


@pytest.mark.slow
def test_worn_play_crossing_in_force_mode_held_by_the_drive_in_a_whole_check(tmp_path):
    """The vcan stage's profiles (10 ms SYNC, v = 12.5 mm/s, so 0x6080 = 600 rpm) with 0.5 mm of internal
    play in both EMAs: EMA 1 in force mode crosses its play as its opposing force ramps on. Before the
    drives kept 0x6080 in CST it reached 12.91 mm/s there and the master stopped the check
    (docs/safety.md, *Speed in cyclic torque mode*); now the drive holds it and the check runs to its end."""
    data = tomllib.loads((VCAN / "simrig.toml").read_text())
    data["ema1"]["backlash_int_mm"] = data["ema2"]["backlash_int_mm"] = 0.5
    sim = tmp_path / "simrig.toml"
    sim.write_text(tomli_w.dumps(data))
    out = tmp_path / "run"
    main(["dry-run", "--profile", str(VCAN / "actuation.toml"), "--sim", str(sim), "--check",
          str(VCAN / "check.toml"), "--quiet", "--out", str(out)])
    sig = read_signals(out / "signals.csv")
    t, phi1, mode1 = sig.t, sig.phi1, np.asarray(sig.mode1, dtype=float)
    v = np.abs(np.diff(phi1)) / I_TOTAL / np.diff(t)
    cst = mode1[1:] == 10
    assert t[-1] > 50.0  # the whole check (55.5 s): not stopped by the master's speed check
    assert 11.5 < v[cst].max() <= 12.5  # the crossing, held at 0x6080 (it engages: unlimited 12.91)
