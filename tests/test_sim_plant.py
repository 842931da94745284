"""Tests of the simulated dual-EMA rig (sim.plant, sim.effects, sim.truth).

Known answers come from the closed-form statics of the load path (paper eq. 1),
an independent scipy ``solve_ivp`` reference of the drive and chain dynamics,
and the sensor error model.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from blf.errors import InputError
from hil.canopen.process import DriveMode, Sample, Setpoint
from sim.effects import (
    CoulombFriction,
    LvdtDrift,
    TimeSkew,
    Viscoelastic,
    ViscousFriction,
    compile_effects,
)
from sim.params import DriveParams, EmaMechanics, RigParams, SensorParams, SurfaceParams
from sim.plant import PlantState, RigPlant
from sim.truth import RigTruth, rig_truth
from support.rigs import I_TOTAL, T_S, brief_rig, quiet

POS, FRC, DIS = int(DriveMode.POSITION), int(DriveMode.FORCE), int(DriveMode.DISABLED)


make_params = brief_rig  # the brief's rig; keyword overrides replace RigParams fields


@pytest.fixture
def params() -> RigParams:
    return make_params()


def asym_params() -> RigParams:
    return make_params(
        ema1=EmaMechanics(0.10, 90e3, 50e3, 0.05, 200e3, 20e3),
        ema2=EmaMechanics(0.12, 60e3, 110e3, 0.04, 150e3, 25e3),
    )


def compliance(m: EmaMechanics, compression: bool) -> float:
    k = m.stiffness_compression_N_per_mm if compression else m.stiffness_tension_N_per_mm
    return 1 / m.housing_stiffness_N_per_mm + 1 / m.bearing_stiffness_N_per_mm + 1 / k


def hold_then(n_hold: int, values: np.ndarray) -> np.ndarray:
    return np.concatenate([np.zeros(n_hold), values])


# ---------------------------------------------------------------- (1) statics


@pytest.mark.parametrize("asym", [False, True])
@pytest.mark.parametrize("delta_mm", [0.3, -0.25])
def test_static_force_fight_matches_dead_zone(asym: bool, delta_mm: float) -> None:
    prm = asym_params() if asym else make_params()
    plant = RigPlant(prm, np.random.default_rng(1), s0_mm=2.0)
    phi0 = 2.0 * I_TOTAL
    n = 2000  # 4 s: integrators settle (Ti = 0.05 s)
    ramp = np.clip(np.arange(n) / 200, 0, 1) * delta_mm * I_TOTAL
    plant.run(POS, phi0 + ramp, POS, phi0 - ramp)
    st = plant.state()
    F1, F2 = st.F_N
    m1, m2 = prm.ema1, prm.ema2
    comp1 = delta_mm > 0  # EMA1 pushes (compression), EMA2 pulls
    B1 = m1.backlash_int_mm + m1.bearing_backlash_mm
    B2 = m2.backlash_int_mm + m2.bearing_backlash_mm
    # u1 - u2 = 2 delta = F (C1 + C2) + sign(F) (B1 + B2) / 2 with F = F1 = -F2
    F_expected = (2 * delta_mm - math.copysign((B1 + B2) / 2, delta_mm)) / (
        compliance(m1, comp1) + compliance(m2, not comp1))
    assert abs(F1 + F2) <= 1e-6 * abs(F1)
    assert F1 == pytest.approx(F_expected, rel=1e-6)
    assert abs(F1) > 2000
    for e, (m, comp) in enumerate(((m1, comp1), (m2, not comp1))):
        D_int = st.s_mm[e] - st.phi_rad[e] / I_TOTAL
        k = m.stiffness_compression_N_per_mm if comp else m.stiffness_tension_N_per_mm
        F = st.F_N[e]
        D_model = -(F / k + math.copysign(m.backlash_int_mm / 2, F))
        assert D_int == pytest.approx(D_model, rel=1e-6, abs=1e-9)
        assert st.h_mm[e] == pytest.approx(-F / m.housing_stiffness_N_per_mm, rel=1e-9)
    # external: s_i - y = F_i / ks_i + sign(F_i) Bb_i / 2
    ks1 = 1 / (1 / m1.bearing_stiffness_N_per_mm + 1 / m1.housing_stiffness_N_per_mm)
    ks2 = 1 / (1 / m2.bearing_stiffness_N_per_mm + 1 / m2.housing_stiffness_N_per_mm)
    D_ext = st.s_mm[1] - st.s_mm[0]
    D_ext_model = (F2 - F1) / 2 * (1 / ks1 + 1 / ks2) + math.copysign(
        (m1.bearing_backlash_mm + m2.bearing_backlash_mm) / 2, F2)
    assert D_ext == pytest.approx(D_ext_model, rel=1e-6)
    # the motors sit at their targets
    assert st.phi_rad[0] == pytest.approx(phi0 + delta_mm * I_TOTAL, abs=1e-9)


def test_initial_state_is_slack_centred_disabled(params: RigParams) -> None:
    plant = RigPlant(params, np.random.default_rng(0), s0_mm=-3.0)
    st = plant.state()
    assert isinstance(st, PlantState)
    assert plant.t_s == 0.0
    assert st.s_mm == pytest.approx((-3.0, -3.0), abs=1e-12)
    assert st.y_mm == pytest.approx(-3.0, abs=1e-12)
    assert st.phi_rad == pytest.approx((-3.0 * I_TOTAL,) * 2, abs=1e-12)
    plant.run(DIS, 0.0, DIS, 0.0, np.zeros(50))
    st = plant.state()
    assert st.F_N == (0.0, 0.0)
    assert st.y_mm == pytest.approx(-3.0, abs=1e-12)
    assert plant.t_s == pytest.approx(50 * T_S, rel=1e-12)


# ---------------------------------------------------------------- (2) jumps through slack


def _intercepts(x: np.ndarray, F: np.ndarray, lim: float) -> tuple[float, float, float, float]:
    """Line fits x(F) on F > lim and F < -lim: (x at F=0+, x at F=0-, slope+, slope-)."""
    p = F > lim
    m = F < -lim
    cp = np.polyfit(F[p], x[p], 1)
    cm = np.polyfit(F[m], x[m], 1)
    return cp[1], cm[1], cp[0], cm[0]


@pytest.mark.parametrize("asym", [False, True])
def test_backlash_jumps_in_quasi_static_sweep(asym: bool) -> None:
    prm = asym_params() if asym else make_params()
    plant = RigPlant(prm, np.random.default_rng(2))
    n = 4000  # 8 s sweep +0.4 -> -0.4 mm per EMA (0.1 mm/s)
    d = hold_then(500, np.linspace(0.4, -0.4, n))
    d[:500] = np.clip(np.arange(500) / 250, 0, 1) * 0.4
    tr = plant.run(POS, d * I_TOTAL, POS, -d * I_TOTAL)
    sl = slice(500, None)
    F = tr.true_F_N[sl]
    s = tr.true_s_mm[sl]
    D_int = s - tr.true_phi_rad[sl] / I_TOTAL
    truth = rig_truth(prm)
    for e, key in enumerate(("int1", "int2")):
        m = prm.ema1 if e == 0 else prm.ema2
        x_pos, x_neg, sl_pos, sl_neg = _intercepts(D_int[:, e], F[:, e], 200.0)
        assert x_neg - x_pos == pytest.approx(truth.backlash_mm[key], abs=1e-6)
        assert -1 / sl_pos == pytest.approx(m.stiffness_compression_N_per_mm, rel=1e-6)
        assert -1 / sl_neg == pytest.approx(m.stiffness_tension_N_per_mm, rel=1e-6)
        # the sweep really traverses: slack samples lie inside the play, both flanks reached
        slack = F[:, e] == 0.0
        assert slack.sum() > 100
        B = m.backlash_int_mm
        assert D_int[slack, e].min() >= -B / 2 - 1e-12 and D_int[slack, e].max() <= B / 2 + 1e-12
        assert D_int[:, e].min() < -B / 2 - 0.01 and D_int[:, e].max() > B / 2 + 0.01
    D_ext = s[:, 1] - s[:, 0]
    fight = F[:, 1] - F[:, 0]
    x_pos, x_neg, sl_pos, sl_neg = _intercepts(D_ext, fight, 400.0)
    assert x_pos - x_neg == pytest.approx(truth.backlash_mm["ext"], abs=2e-5)
    assert 1 / sl_pos == pytest.approx(truth.stiffness_N_per_mm["ext"]["right"], rel=2e-4)
    assert 1 / sl_neg == pytest.approx(truth.stiffness_N_per_mm["ext"]["left"], rel=2e-4)


# ---------------------------------------------------------------- (3) CSP tracking


def _free_motor_reference(prm: RigParams, targets: np.ndarray, wff: np.ndarray, phi0: float) -> np.ndarray:
    """solve_ivp of J phi'' = Kp e + Kd (wff - phi') + Ki int e - b phi' (no load), per sample."""
    d = prm.drive
    J, b = d.motor_inertia_kg_m2, d.motor_viscous_Nm_s_per_rad
    kp = J * d.position_bandwidth_rad_s**2
    kd = 2 * d.position_damping * d.position_bandwidth_rad_s * J
    ki = kp / d.position_integral_time_s
    x = np.array([phi0, 0.0, 0.0])
    out = np.empty(len(targets))
    for k, (th, wf) in enumerate(zip(targets, wff, strict=True)):
        def rhs(_t, z, th=th, wf=wf):
            e = th - z[0]
            return [z[1], (kp * e + kd * (wf - z[1]) + ki * z[2] - b * z[1]) / J, e]
        x = solve_ivp(rhs, (0, T_S), x, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
        out[k] = x[0]
    return out


def test_csp_step_follows_reference_and_bandwidth(params: RigParams) -> None:
    # EMA1 steps 0.1 rad (0.02 mm) inside its play (EMA2 braked): pure drive + motor dynamics
    plant = RigPlant(params, np.random.default_rng(3))
    n_hold, n = 10, 150
    step = 0.1
    targets = np.full(n_hold + n, step)
    targets[:n_hold] = 0.0
    tr = plant.run(POS, targets, DIS, 0.0)
    assert np.all(tr.true_F_N[:, 0] == 0.0)  # stayed in the play
    wff = np.zeros_like(targets)
    wff[n_hold] = step / T_S  # velocity feed-forward of the step sample
    ref = _free_motor_reference(params, targets, wff, 0.0)
    err = np.abs(tr.true_phi_rad[:, 0] - ref)
    assert err.max() < 0.005 * step  # Verlet substeps vs DOP853: measured 0.06 %
    # bandwidth: 2 % settling of the reference (wn = 150 rad/s, zeta = 0.8, Ti = 0.05 s)
    e_ref = np.abs(ref[n_hold:] - step)
    settle = np.nonzero(e_ref > 0.02 * step)[0].max() + 1
    assert 10 <= settle <= 40  # 20 .. 80 ms
    e_sim = np.abs(tr.true_phi_rad[n_hold:, 0] - step)
    assert e_sim[settle:].max() < 0.021 * step
    assert e_sim[-20:].max() < 1e-3 * step


def test_csp_large_step_saturates_and_settles(params: RigParams) -> None:
    # both EMAs +2 mm (10 rad) in one sample: the P and feed-forward terms ask for > 100 N m
    plant = RigPlant(params, np.random.default_rng(4))
    n = 1250
    target = 2.0 * I_TOTAL
    tr = plant.run(POS, hold_then(20, np.full(n, target)), POS, hold_then(20, np.full(n, target)))
    tmax = tr.torque_abs_max_Nm
    assert tmax.max() <= params.drive.torque_limit_Nm * (1 + 1e-12)
    assert (tmax > params.drive.torque_limit_Nm * (1 - 1e-12)).sum() >= 5  # it did saturate
    assert np.all(np.isfinite(tr.true_phi_rad))
    # linear design (zeta = 0.8 with integral, wn Ti = 7.5) overshoots 19.5 %; saturation and
    # conditional-integration anti-windup keep the large step below that
    overshoot = (tr.true_phi_rad[:, 0].max() - target) / target
    assert 0.05 < overshoot < 0.195
    # the surface rattles in the backlash after the stop and is calmed by the drives' damping
    tail = slice(-250, None)  # last 0.5 s
    assert np.abs(tr.true_phi_rad[tail] - target).max() < 1e-3
    assert np.abs(tr.true_F_N[tail]).max() < 50.0
    assert tr.y_mm[-1] == pytest.approx(2.0, abs=0.08)


# ---------------------------------------------------------------- (4) FORCE mode


def _sweep_profile(v_mm_s: float, t_turn_s: float, t_const_s: float) -> tuple[np.ndarray, np.ndarray]:
    """EMA1 sweep out and back: position (mm) per sample and the plateau velocity label.

    Velocity 0 -> +v -> -v -> 0 with raised-cosine transitions of ``t_turn_s`` and
    plateaus of ``t_const_s``; label = plateau velocity, 0 during transitions.
    """
    segs = [(0.0, v_mm_s, t_turn_s), (v_mm_s, v_mm_s, t_const_s), (v_mm_s, -v_mm_s, t_turn_s),
            (-v_mm_s, -v_mm_s, t_const_s), (-v_mm_s, 0.0, t_turn_s)]
    vel, lab = [], []
    for a, b, dur in segs:
        n = int(round(dur / T_S))
        tau = (np.arange(n) + 0.5) / n
        vel.append(a + (b - a) * 0.5 * (1 - np.cos(np.pi * tau)))
        lab.append(np.full(n, a if a == b else 0.0))
    return np.cumsum(np.concatenate(vel)) * T_S, np.concatenate(lab)


def _force_sweep(prm: RigParams, seed: int = 5):
    """EMA2 FORCE -3000 N against EMA1 sweeping in POSITION at 2 mm/s.

    The preload is built in POSITION (well damped) and EMA2 then switches to
    FORCE at the same force: an EMA in ideal torque mode is a nearly undamped
    2.5 t reflected mass on the chain springs (7.9 Hz, 2 % damping), so an
    impact start would ring for seconds.
    """
    plant = RigPlant(prm, np.random.default_rng(seed))
    m1, m2 = prm.ema1, prm.ema2
    x2 = -(3000.0 * (compliance(m1, True) + compliance(m2, False))
           + (m1.backlash_int_mm + m1.bearing_backlash_mm + m2.backlash_int_mm + m2.bearing_backlash_mm) / 2)
    plant.run(POS, 0.0, POS, np.clip(np.arange(500) / 250, 0, 1) * x2 * I_TOTAL)
    x, label = _sweep_profile(2.0, 1.0, 2.0)
    tr = plant.run(POS, x * I_TOTAL, FRC, -3000.0)
    return tr, label


def _steady_force(tr, label) -> tuple[np.ndarray, np.ndarray]:
    """F1 on the +2 and -2 mm/s plateaus, skipping 0.5 s after the turn and 0.1 s before the next."""
    F1 = tr.true_F_N[:, 0]
    out = []
    for v in (2.0, -2.0):
        idx = np.nonzero(label == v)[0]
        assert np.all(np.diff(idx) == 1)  # one plateau per direction
        out.append(F1[idx[0] + 250: idx[-1] - 50])
        assert out[-1].size > 500
    return out[0], out[1]


def test_force_mode_opposes_position_sweep(params: RigParams) -> None:
    tr, label = _force_sweep(params)
    F_up, F_down = _steady_force(tr, label)
    d = params.drive
    im = I_TOTAL * 1e3
    v = 2.0e-3  # m/s
    visc = d.motor_viscous_Nm_s_per_rad * v * im * im  # EMA2 motor loss referred to the ram, N
    cs = params.surface.damping_N_s_per_mm * 2.0  # surface damping at 2 mm/s, N
    assert visc == pytest.approx(5.05, abs=0.01)
    # F1 = -F2 + c_s v,  F2 = -3000 - b w2 i  (EMA2 motor at constant speed)
    assert F_up.mean() == pytest.approx(3000.0 + visc + cs, abs=0.5)
    assert F_down.mean() == pytest.approx(3000.0 - visc - cs, abs=0.5)
    assert np.abs(F_up - (3000.0 + visc + cs)).max() < 3.0  # residual 7.9 Hz ringing, measured 1 N
    assert np.abs(F_down - (3000.0 - visc - cs)).max() < 3.0
    D_int1 = tr.true_s_mm[:, 0] - tr.true_phi_rad[:, 0] / I_TOTAL
    assert np.ptp(D_int1) < 1e-3  # whole sweep, turnarounds included
    assert D_int1.mean() == pytest.approx(-(3000 / 80e3 + 0.05), abs=2e-5)
    assert np.ptp(tr.true_phi_rad[:, 0]) / I_TOTAL > 2.5  # it did sweep


# ---------------------------------------------------------------- (5) sensors


def test_resolver_quantisation(params: RigParams) -> None:
    plant = RigPlant(params, np.random.default_rng(6))
    x = np.linspace(0, 0.5, 2000) * I_TOTAL  # slow ramp: many quanta
    tr = plant.run(POS, x, DIS, 0.0)
    q = 2 * math.pi / 2**12
    meas, true = tr.phi1_rad, tr.true_phi_rad[:, 0]
    counts = meas / q
    assert np.abs(counts - np.round(counts)).max() < 1e-9
    err = meas - true
    assert np.abs(err).max() <= q / 2 * (1 + 1e-9)
    assert np.abs(err).max() > 0.45 * q  # the error really spans the quantum
    steps = np.diff(np.unique(np.round(counts)))
    assert steps.min() == 1 and len(np.unique(counts)) > 300


def test_lvdt_and_loadcell_error_model(params: RigParams) -> None:
    # noise-free: exact law along a motion
    plant = RigPlant(quiet(params), np.random.default_rng(7))
    x = np.concatenate([np.linspace(0, 8, 1500), np.linspace(8, -8, 1500)]) * I_TOTAL
    tr = plant.run(POS, x, POS, x)
    for e, sp in enumerate((params.sensors1, params.sensors2)):
        s = tr.true_s_mm[:, e]
        model = sp.lvdt_offset_mm + sp.lvdt_gain * s + sp.lvdt_nonlinearity_mm * (s / sp.lvdt_full_scale_mm) ** 3
        meas = tr.s1_mm if e == 0 else tr.s2_mm
        assert np.abs(meas - model).max() < 1e-12
        Fm = tr.F1_N if e == 0 else tr.F2_N
        assert np.abs(Fm - sp.loadcell_gain * tr.true_F_N[:, e]).max() < 1e-9
    # noise: at rest, 1e5 samples
    s0 = 5.0
    plant = RigPlant(params, np.random.default_rng(8), s0_mm=s0)
    n = 100_000
    tr = plant.run(DIS, 0.0, DIS, 0.0, np.zeros(n))
    for e, sp in enumerate((params.sensors1, params.sensors2)):
        meas = tr.s1_mm if e == 0 else tr.s2_mm
        mean = sp.lvdt_offset_mm + sp.lvdt_gain * s0 + sp.lvdt_nonlinearity_mm * (s0 / sp.lvdt_full_scale_mm) ** 3
        sig = sp.lvdt_noise_pp_mm / 6
        assert meas.mean() == pytest.approx(mean, abs=5 * sig / math.sqrt(n))
        assert meas.std() == pytest.approx(sig, rel=0.05)
        Fm = tr.F1_N if e == 0 else tr.F2_N
        assert Fm.mean() == pytest.approx(0.0, abs=5 * sp.loadcell_noise_std_N / math.sqrt(n))
        assert Fm.std() == pytest.approx(sp.loadcell_noise_std_N, rel=0.05)
    # the four channels are independent
    c = np.corrcoef(np.vstack([tr.s1_mm, tr.s2_mm, tr.F1_N, tr.F2_N]))
    assert np.abs(c - np.eye(4)).max() < 0.02


def test_reproducible_for_seed_and_step_equals_run(params: RigParams) -> None:
    n = 5000  # crosses a noise block boundary (4096)
    x = np.sin(np.arange(n) * 0.01) * I_TOTAL
    a = RigPlant(params, np.random.default_rng(42)).run(POS, x, FRC, -500.0)
    b = RigPlant(params, np.random.default_rng(42)).run(POS, x, FRC, -500.0)
    c = RigPlant(params, np.random.default_rng(43)).run(POS, x, FRC, -500.0)
    for f in ("t_s", "phi1_rad", "phi2_rad", "s1_mm", "s2_mm", "F1_N", "F2_N"):
        assert np.array_equal(getattr(a, f), getattr(b, f))
    assert not np.array_equal(a.s1_mm, c.s1_mm)
    assert np.array_equal(a.phi1_rad, c.phi1_rad)  # the physics has no noise
    plant = RigPlant(params, np.random.default_rng(42))
    samples = [plant.step(Setpoint(DriveMode.POSITION, float(x[k])), Setpoint(DriveMode.FORCE, -500.0))
               for k in range(4200)]
    assert isinstance(samples[0], Sample)
    arr = np.array([[s.t_s, s.phi1_rad, s.phi2_rad, s.s1_mm, s.s2_mm, s.F1_N, s.F2_N] for s in samples])
    ref = np.column_stack([a.t_s, a.phi1_rad, a.phi2_rad, a.s1_mm, a.s2_mm, a.F1_N, a.F2_N])[:4200]
    assert np.array_equal(arr, ref)
    assert samples[-1].t_s == pytest.approx(4200 * T_S, rel=1e-12)
    raw = plant.step_raw(POS, float(x[4200]), FRC, -500.0)
    assert raw == (a.t_s[4200], a.phi1_rad[4200], a.phi2_rad[4200], a.s1_mm[4200], a.s2_mm[4200],
                   a.F1_N[4200], a.F2_N[4200])


# ---------------------------------------------------------------- (6) integration accuracy


def _dynamic_case(substeps: int):
    n = 1000  # 2 s
    t = np.arange(1, n + 1) * T_S
    d = 0.3 * np.sin(2 * np.pi * 0.5 * t)  # force fight through both backlashes
    c = 1.0 * np.sin(2 * np.pi * 0.2 * t)  # common motion
    plant = RigPlant(make_params(substeps=substeps), np.random.default_rng(0))
    return plant.run(POS, (c + d) * I_TOTAL, POS, (c - d) * I_TOTAL)


def test_doubling_substeps_changes_trajectory_below_1um() -> None:
    a, b, c = _dynamic_case(8), _dynamic_case(16), _dynamic_case(32)
    assert np.abs(a.true_F_N).max() > 2000  # it is in contact, both flanks
    assert (a.true_F_N[:, 0] == 0).sum() > 50
    d816 = max(np.abs(a.true_s_mm - b.true_s_mm).max(), np.abs(a.y_mm - b.y_mm).max())
    d1632 = max(np.abs(b.true_s_mm - c.true_s_mm).max(), np.abs(b.y_mm - c.y_mm).max())
    assert d816 < 1e-3
    assert d1632 < 0.35 * d816  # second order (Stormer-Verlet): measured ratio 4.7


def test_contact_dynamics_match_solve_ivp_reference(params: RigParams) -> None:
    """Full rig (drives, chains, surface) vs an independent DOP853 reference."""
    prm = quiet(params)
    plant = RigPlant(prm, np.random.default_rng(9))
    n = 500
    t = np.arange(n) * T_S
    x1 = (0.5 * np.sin(2 * np.pi * 1.0 * t)) * I_TOTAL  # EMA1 CSP, EMA2 pulls 2 kN
    plant.run(POS, 0.0, FRC, -2000.0, np.zeros(400))  # settle into contact
    st = plant.state()
    tgt = x1 + st.phi_rad[0]
    tr = plant.run(POS, tgt, FRC, -2000.0)

    d = prm.drive
    J, b = d.motor_inertia_kg_m2, d.motor_viscous_Nm_s_per_rad
    kp = J * d.position_bandwidth_rad_s**2
    kd = 2 * d.position_damping * d.position_bandwidth_rad_s * J
    ki = kp / d.position_integral_time_s
    im = I_TOTAL * 1e3
    ms, cs = prm.surface.mass_kg, prm.surface.damping_N_s_per_mm * 1e3

    def G(u_m: float, m: EmaMechanics) -> float:  # dead-zone spring, SI
        half = (m.backlash_int_mm + m.bearing_backlash_mm) / 2e3
        if u_m > half:
            return (u_m - half) / (compliance(m, True) * 1e-3)
        if u_m < -half:
            return (u_m + half) / (compliance(m, False) * 1e-3)
        return 0.0

    z = np.array([st.phi_rad[0], st.omega_rad_s[0], st.integral_rad_s[0], st.phi_rad[1],
                  st.omega_rad_s[1], st.y_mm * 1e-3, st.v_mm_s * 1e-3])
    prev = 0.0  # the settle phase held target 0 rad
    ys, F1s = [], []
    for k in range(n):
        th = tgt[k]
        wf = (th - prev) / T_S
        prev = th

        def rhs(_t, s, th=th, wf=wf):
            F1 = G(s[0] / im - s[5], prm.ema1)
            F2 = G(s[3] / im - s[5], prm.ema2)
            e = th - s[0]
            T1 = kp * e + kd * (wf - s[1]) + ki * s[2]
            T2 = -2000.0 / im
            return [s[1], (T1 - b * s[1] - F1 / im) / J, e,
                    s[4], (T2 - b * s[4] - F2 / im) / J,
                    s[6], (F1 + F2 - cs * s[6]) / ms]

        z = solve_ivp(rhs, (0, T_S), z, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
        ys.append(z[5] * 1e3)
        F1s.append(G(z[0] / im - z[5], prm.ema1))
    assert np.abs(tr.torque_abs_max_Nm[:, 0]).max() < d.torque_limit_Nm  # linear drive law held
    assert np.ptp(tr.true_F_N[:, 0]) > 1000  # a dynamic case (ringing of the FORCE-mode EMA2)
    err_y = np.abs(tr.y_mm - np.array(ys)).max()
    err_F = np.abs(tr.true_F_N[:, 0] - np.array(F1s)).max()
    assert err_y < 1e-4  # mm; measured 3.5e-5 (8 substeps), 8.5e-6 (16): second order
    assert err_F < 1.5  # N of a 300..3800 N swing; measured 0.4


# ---------------------------------------------------------------- (7) effects


@pytest.mark.parametrize("effect, offset_N", [
    (CoulombFriction("ema2", 200.0), 200.0),
    (ViscousFriction("ema2", 5.0), 10.0),  # 5 N s/mm at 2 mm/s
])
def test_friction_offsets_force_and_reverses_with_direction(params: RigParams, effect, offset_N) -> None:
    up0, down0 = _steady_force(*_force_sweep(params))
    up1, down1 = _steady_force(*_force_sweep(make_params(effects=(effect,))))
    # plateau means; the 7.9 Hz ringing of the lightly damped FORCE-mode EMA kicked at the
    # reversals averages to < 0.3 N over the 1.4 s windows
    assert up1.mean() - up0.mean() == pytest.approx(offset_N, abs=1.0)
    assert down1.mean() - down0.mean() == pytest.approx(-offset_N, abs=1.0)


def test_friction_on_position_drive_is_not_seen_by_load_cell(params: RigParams) -> None:
    up0, down0 = _steady_force(*_force_sweep(params))
    up1, down1 = _steady_force(*_force_sweep(make_params(effects=(CoulombFriction("ema1", 300.0),))))
    assert up1.mean() == pytest.approx(up0.mean(), abs=1.0)
    assert down1.mean() == pytest.approx(down0.mean(), abs=1.0)


@pytest.mark.parametrize("kv, tau", [(40e3, 0.3), (80e3, 0.2)])
def test_viscoelastic_force_relaxes_with_time_constant(kv: float, tau: float) -> None:
    prm = make_params(effects=(Viscoelastic("ema1", kv, tau),))
    plant = RigPlant(prm, np.random.default_rng(10))
    d = np.concatenate([np.zeros(10), np.linspace(0, 0.3, 25), np.full(100, 0.3)])
    plant.run(POS, d * I_TOTAL, POS, -d * I_TOTAL)  # fast preload, the Maxwell arm lags
    st = plant.state()
    tr = plant.run(DIS, 0.0, DIS, 0.0, np.zeros(1000))  # brakes: motor angles frozen
    assert np.array_equal(tr.true_phi_rad[-1], np.array(st.phi_rad))
    # quasi-static force (F1 - F2)/2, the 50 Hz surface ringing averaged out over 10 samples
    F = np.convolve(0.5 * (tr.true_F_N[:, 0] - tr.true_F_N[:, 1]), np.ones(10) / 10, mode="valid")
    t = np.arange(F.size) * T_S + 4.5 * T_S
    m1, m2 = prm.ema1, prm.ema2
    U = (st.phi_rad[0] - st.phi_rad[1]) / I_TOTAL
    B = (m1.backlash_int_mm + m1.bearing_backlash_mm + m2.backlash_int_mm + m2.bearing_backlash_mm) / 2
    F_inf = (U - B) / (compliance(m1, True) + compliance(m2, False))  # static stiffness unchanged
    assert F[0] - F_inf > 50  # there is something to relax
    assert F[-1] - F_inf == pytest.approx(0.0, abs=0.02 * (F[0] - F_inf))
    # linear ODE of the Maxwell state with both motors fixed:
    # tau_eff = tau / (k_c / K + k_v / (K^2 C_tot)), K = k_c + k_v
    K = m1.stiffness_compression_N_per_mm + kv
    C_tot = compliance(m2, False) + 1 / m1.housing_stiffness_N_per_mm + 1 / m1.bearing_stiffness_N_per_mm + 1 / K
    tau_eff = tau / (m1.stiffness_compression_N_per_mm / K + kv / (K * K * C_tot))
    sel = (t > 0.05) & (t < 1.5)
    slope = np.polyfit(t[sel], np.log(F[sel] - F_inf), 1)[0]
    assert -1 / slope == pytest.approx(tau_eff, rel=0.01)


def test_without_viscoelastic_braked_force_does_not_relax(params: RigParams) -> None:
    plant = RigPlant(params, np.random.default_rng(10))
    d = np.concatenate([np.zeros(10), np.linspace(0, 0.3, 25), np.full(100, 0.3)])
    plant.run(POS, d * I_TOTAL, POS, -d * I_TOTAL)
    tr = plant.run(DIS, 0.0, DIS, 0.0, np.zeros(1000))
    F = np.convolve(0.5 * (tr.true_F_N[:, 0] - tr.true_F_N[:, 1]), np.ones(10) / 10, mode="valid")
    assert np.ptp(F[50:]) < 1.0


def test_viscoelastic_rounds_the_transition_and_keeps_static_law() -> None:
    """Fast loading: stiffer than k_c near contact; held: back on the static dead-zone law."""
    prm = make_params(effects=(Viscoelastic("ema1", 80e3, 0.2),))
    plant = RigPlant(prm, np.random.default_rng(11))
    d = np.concatenate([np.linspace(0, 0.3, 100), np.full(2500, 0.3)])
    tr = plant.run(POS, d * I_TOTAL, POS, -d * I_TOTAL)
    F1 = tr.true_F_N[:, 0]
    D1 = tr.true_s_mm[:, 0] - tr.true_phi_rad[:, 0] / I_TOTAL
    load = (F1 > 300) & (np.arange(F1.size) < 100)
    k_fast = -np.polyfit(D1[load], F1[load], 1)[0]
    assert k_fast > 1.3 * 80e3  # the Maxwell arm stiffens the fast loading
    assert D1[-1] == pytest.approx(-(F1[-1] / 80e3 + 0.05), abs=2e-6)  # relaxed: static law


def test_lvdt_drift_gain_grows_linearly(params: RigParams) -> None:
    drift = 1e-3  # 1/s
    plant = RigPlant(quiet(make_params(effects=(LvdtDrift("ema1", drift),))), np.random.default_rng(12),
                     s0_mm=5.0)
    tr = plant.run(DIS, 0.0, DIS, 0.0, np.zeros(2500))
    sp = params.sensors1
    nl = sp.lvdt_nonlinearity_mm * (5.0 / sp.lvdt_full_scale_mm) ** 3
    expected = sp.lvdt_offset_mm + sp.lvdt_gain * (1 + drift * tr.t_s) * 5.0 + nl
    assert np.abs(tr.s1_mm - expected).max() < 1e-12
    assert tr.s1_mm[-1] - tr.s1_mm[0] == pytest.approx(sp.lvdt_gain * drift * 5.0 * (tr.t_s[-1] - tr.t_s[0]))
    assert np.ptp(tr.s2_mm) < 1e-12  # EMA2 unaffected


@pytest.mark.parametrize("delay_s", [0.0007, 0.0019])
def test_time_skew_lvdt_lags(params: RigParams, delay_s: float) -> None:
    prm = quiet(make_params(effects=(TimeSkew("ema1", delay_s),)))
    plant = RigPlant(prm, np.random.default_rng(13))
    v = 5.0  # mm/s
    x = hold_then(100, np.arange(1, 1001) * T_S * v) * I_TOTAL
    tr = plant.run(POS, x, POS, x)
    sp = prm.sensors1
    s = tr.true_s_mm[:, 0]
    no_skew = sp.lvdt_offset_mm + sp.lvdt_gain * s + sp.lvdt_nonlinearity_mm * (s / sp.lvdt_full_scale_mm) ** 3
    lag = (no_skew - tr.s1_mm)[500:]  # constant-velocity part
    assert lag.mean() == pytest.approx(sp.lvdt_gain * v * delay_s, rel=0.02)
    sp2 = prm.sensors2
    s2 = tr.true_s_mm[:, 1]
    no_skew2 = sp2.lvdt_offset_mm + sp2.lvdt_gain * s2 + sp2.lvdt_nonlinearity_mm * (s2 / sp2.lvdt_full_scale_mm) ** 3
    assert np.abs(no_skew2 - tr.s2_mm).max() < 1e-12


def test_end_stop_limits_motor_stroke(params: RigParams) -> None:
    plant = RigPlant(params, np.random.default_rng(14), s0_mm=18.0)
    tr = plant.run(FRC, 5000.0, FRC, 5000.0, np.zeros(500))
    x_m = tr.true_phi_rad / I_TOTAL
    assert x_m.max() > 20.0  # it reached the stop at ~75 mm/s
    assert x_m.max() < 20.0 + 0.2  # 2.5 t on 1e6 N/mm: ~0.12 mm penetration
    assert x_m[-1].max() < 20.0 + 0.01
    assert np.all(np.isfinite(tr.y_mm))


# ---------------------------------------------------------------- (8) validation


@pytest.mark.parametrize("override, field", [
    (dict(ema1=EmaMechanics(0.10, -80e3, 80e3, 0.05, 200e3, 20e3)), "params.ema1.stiffness_compression_N_per_mm"),
    (dict(ema2=EmaMechanics(-0.1, 80e3, 80e3, 0.05, 200e3, 20e3)), "params.ema2.backlash_int_mm"),
    (dict(substeps=0), "params.substeps"),
    (dict(substeps=1), "params.substeps"),  # too few for the stiffest mode
    (dict(sample_period_s=float("nan")), "params.sample_period_s"),
    (dict(i_total_rad_per_mm=0.0), "params.i_total_rad_per_mm"),
    (dict(drive=DriveParams(1.0e-4, 1e-4, -10.0, 150.0, 0.8, 0.05)), "params.drive.torque_limit_Nm"),
    (dict(surface=SurfaceParams(0.0, 0.5, 0.0)), "params.surface.mass_kg"),
    (dict(sensors2=SensorParams(0.98, -0.2, 0.02, 0.0, 0.025, 1.0, 10.0, 12)), "params.sensors2.lvdt_full_scale_mm"),
    (dict(sensors1=SensorParams(1.075, 0.3, 0.02, 20.0, 0.025, 1.0, 10.0, 12.5)), "params.sensors1.resolver_bits"),
    (dict(effects=(TimeSkew("ema1", 0.002),)), "TimeSkew.delay_s"),
    (dict(effects=(LvdtDrift("ema1", 1e-3), LvdtDrift("ema1", 2e-3))), "duplicate LvdtDrift"),
    (dict(effects=("friction",)), "effects[0]"),
])
def test_invalid_params_name_the_field(override: dict, field: str) -> None:
    with pytest.raises(InputError, match=field.replace(".", r"\.").replace("[", r"\[").replace("]", r"\]")):
        RigPlant(make_params(**override), np.random.default_rng(0))


def test_invalid_effects_and_inputs_name_the_argument(params: RigParams) -> None:
    with pytest.raises(InputError, match=r"CoulombFriction\.where"):
        CoulombFriction("external", 10.0)
    with pytest.raises(InputError, match=r"Viscoelastic\.time_constant_s"):
        Viscoelastic("ema1", 1e3, 0.0)
    with pytest.raises(InputError, match=r"ViscousFriction\.coeff_N_s_per_mm"):
        ViscousFriction("ema2", -1.0)
    with pytest.raises(InputError, match="rng"):
        RigPlant(params, 42)
    with pytest.raises(InputError, match="s0_mm"):
        RigPlant(params, np.random.default_rng(0), s0_mm=25.0)
    plant = RigPlant(params, np.random.default_rng(0))
    ok = Setpoint(DriveMode.DISABLED, float("nan"))  # value ignored when disabled
    plant.step(ok, ok)
    with pytest.raises(InputError, match=r"sp1\.value"):
        plant.step(Setpoint(DriveMode.POSITION, float("nan")), ok)
    with pytest.raises(InputError, match=r"sp2\.mode"):
        plant.step(ok, Setpoint(7, 0.0))
    with pytest.raises(InputError, match="sp1"):
        plant.step((8, 0.0), ok)
    with pytest.raises(InputError, match="load_N"):
        plant.step(ok, ok, float("inf"))
    with pytest.raises(InputError, match="mode2"):
        plant.run(POS, np.zeros(3), np.array([0, 8, 9]), np.zeros(3))
    with pytest.raises(InputError, match="broadcast"):
        plant.run(POS, np.zeros(3), POS, np.zeros(4))
    assert plant.t_s == pytest.approx(T_S)  # failed calls did not advance time
    table = compile_effects((CoulombFriction("ema2", 50.0),), T_S, 8)
    assert table.shape == (3, table.shape[1]) and table[1].any() and not table[0].any()


# ---------------------------------------------------------------- (9) truth


def test_rig_truth_values(params: RigParams) -> None:
    t = rig_truth(params)
    assert isinstance(t, RigTruth)
    assert t.backlash_mm == pytest.approx({"int1": 0.10, "int2": 0.12, "ext": 0.10})
    ks = 1 / (1 / 200e3 + 1 / 20e3)
    assert t.stiffness_N_per_mm["int1"] == {"left": 80e3, "right": 80e3}
    assert t.stiffness_N_per_mm["ext"]["left"] == pytest.approx(ks, rel=1e-12)
    assert t.stiffness_N_per_mm["ext"]["left"] == pytest.approx(18181.818181818, rel=1e-9)
    assert t.calibration == {"ema1": {"pitch": 1.075, "offset_mm": 0.3},
                             "ema2": {"pitch": 0.98, "offset_mm": -0.2}}
    a = rig_truth(asym_params())
    assert a.stiffness_N_per_mm["int1"] == {"left": 90e3, "right": 50e3}
    assert a.stiffness_N_per_mm["int2"] == {"left": 60e3, "right": 110e3}
    ks1, ks2 = 1 / (1 / 200e3 + 1 / 20e3), 1 / (1 / 150e3 + 1 / 25e3)
    assert a.stiffness_N_per_mm["ext"]["right"] == pytest.approx(2 / (1 / ks1 + 1 / ks2), rel=1e-12)
    assert a.backlash_mm["ext"] == pytest.approx(0.09)
    assert RigPlant(params, np.random.default_rng(0)).truth() == t
    with pytest.raises(InputError, match="params"):
        rig_truth("not params")
