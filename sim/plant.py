"""Simulated dual-EMA aileron rig: two drives, two backlash load paths, one surface.

Pure physics: no clocks, no IO. Time advances only by :meth:`RigPlant.step`
(one sample period per call); randomness comes only from the
``numpy.random.Generator`` given to the constructor.

Coordinates and signs
---------------------
All positions lie on the ram axis, positive when the ram extends; forces are
positive in compression (the EMA pushes the surface towards +y). The public
API uses mm, N, rad, s; the numba kernel (:mod:`sim.plant_kernel`) works in
SI (m, N, rad, s) and converts at the boundary (``i_total`` in rad/m = 1000 x
rad/mm).

Per EMA i in {1, 2}:

* motor angle :math:`\\varphi_i` [rad] relative to the housing, motor-side
  ram position :math:`x_{m,i} = \\varphi_i / i_{total}`;
* motor dynamics :math:`J\\ddot\\varphi_i = T_i - b\\dot\\varphi_i - F_i/i_{total}
  - T_{fric,i} - F_{stop,i}/i_{total}` (reflected mass
  :math:`M = J\\,i_{total}^2` ~ 2500 kg with the default rig);
* quasi-static load path (massless housing and ram): structure --k_h--
  housing (h_i) --motor (x_m)-- internal path (play B_int, k_c for F > 0,
  k_t for F < 0) -- ram (r_i) -- bearing (play B_b, k_b) -- surface (y).
  With :math:`u_i = x_{m,i} - y` the chain force is the closed-form dead-zone
  spring

  .. math:: u = F/k_h + F/k_{int}(F) + F/k_b + \\mathrm{sign}(F)(B_{int} + B_b)/2

  in contact :math:`h_i = -F_i/k_h`, :math:`r_i = y + F_i/k_b + \\mathrm{sign}(F_i)B_b/2`;
  slack (:math:`|u_i| < (B_{int}+B_b)/2`): :math:`F_i = 0`, :math:`h_i = 0`
  and the ram follows the play operator
  :math:`r_i = \\mathrm{clip}(r_i^-, \\max(x - B_{int}/2, y - B_b/2), \\min(x + B_{int}/2, y + B_b/2))`,
  :math:`x = h_i + x_{m,i}`;
* stroke (LVDT truth) :math:`s_i = r_i - h_i`; load cell truth :math:`F_i`;
  so :math:`D_{int,i} = s_i - \\varphi_i/i_{total} = -(F_i/k_{int} + \\mathrm{sign}(F_i)B_{int}/2)`
  in contact (paper eq. 1).

Surface: :math:`m_s\\ddot y = F_1 + F_2 - c_s\\dot y - k_{load}y + F_{load}`.

End stops: a protective spring of 1e6 N/mm acts on the motor when
:math:`|x_{m,i}| >` ``stroke_limit_mm`` (on the motor side, which differs from
s by :math:`D_{int}`, a fraction of a mm). It is reacted inside the EMA and is
not seen by the load cell. It is not meant to be reached by a valid sequence.

Drives (continuous-time laws evaluated every substep; the real drive's current
loop is taken as ideal):

* POSITION (CSP): :math:`T = K_p e + K_d(\\omega_{ff} - \\dot\\varphi) + K_i\\int e`,
  :math:`e = \\varphi_{target} - \\varphi`, target held over the sample period,
  velocity feed-forward :math:`\\omega_{ff}` = difference of successive targets
  / period (0 on the first POSITION sample), :math:`K_p = J\\omega_n^2`,
  :math:`K_d = 2\\zeta\\omega_n J`, :math:`K_i = J\\omega_n^2/T_i` (none if
  :math:`T_i = 0`); conditional-integration anti-windup; :math:`|T| \\le T_{lim}`.
* FORCE (CST): :math:`T = \\mathrm{clip}(F_{target}/i_{total}, \\pm T_{lim})`.
* DISABLED: holding brake, :math:`\\dot\\varphi = 0`, integrator reset.

Integration: Stormer-Verlet (kick-drift-kick) with ``params.substeps``
substeps per sample (second order; one closed-form chain solve per substep):
half-kick of all velocities with the forces at the current positions, drift of
all positions with the half-step velocities, chain solve at the new
positions, second half-kick. Velocity-proportional terms (drive D-gain,
viscous losses, linearised friction, surface damping) are explicit in the
first half-kick and implicit in the second, i.e. trapezoidal; the CSP
integrator uses the trapezoidal rule too; the Maxwell states are updated
exactly with the deflection frozen over the substep. Stable for
:math:`h\\,\\omega_{max} < 2`; the constructor rejects :math:`h\\,\\omega_{max} > 1`
(Gershgorin bound of the stiffest mode) and :math:`h\\,c/(2M) > 1` for the
damping terms. Verified against scipy DOP853 (3.5e-5 mm on a 1 s dynamic
contact case with 8 substeps of 0.25 ms; error / 4 per substep doubling).

Switchable effects (:mod:`sim.effects`, compiled once into a (3, n) table):
Coulomb and viscous friction act on the motor-side motion of one EMA; a
Viscoelastic Maxwell arm adds, per flank of the internal play, a dashpot state
z with flank force :math:`k\\delta + k_v(\\delta - z)` (the chain solve stays
closed form with z frozen over a substep: the contact threshold moves to
:math:`(B_{int}+B_b)/2 + k_v z/(k + k_v)` and the contact compliance uses
:math:`k + k_v`); LvdtDrift and TimeSkew change the LVDT reading only.

Dynamics worth knowing: an EMA in FORCE mode is an almost undamped 2.5 t
reflected mass on the chain springs (7.9 Hz, 2 % damping with the default
rig: damping only from ``motor_viscous``, the surface damping and the other
drive), and the 300 kg surface between the two chains rings at about 50 Hz
with 0.3 % damping and rattles in the backlash after abrupt motions; the
contacts themselves are lossless.

Sensors, sampled at the end of each period (time stamp :math:`t_k = kT_s`):
resolver :math:`\\varphi_{meas} = q\\,\\mathrm{round}(\\varphi/q)`,
:math:`q = 2\\pi/2^{bits}` (multi-turn); LVDT
:math:`s_{meas} = o + g s + n_3 (s/s_{fs})^3 + N(0, (pp/6)^2)`; load cell
:math:`F_{meas} = g_F F + N(0, \\sigma_F^2)`. Noise is drawn from the
generator in blocks of :data:`NOISE_BLOCK` samples x 4 channels
(LVDT1, LVDT2, load cell 1, load cell 2), so a seed fixes the whole record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from blf.errors import InputError
from blf.validate import count, generator, instance_of, scalar
from hil.canopen.process import DriveMode, Sample, Setpoint
from sim import effects as _fx
from sim.params import RigParams
from sim.plant_kernel import (
    E_BB,
    E_BI,
    E_FS,
    E_GAIN,
    E_KB,
    E_KC,
    E_KH,
    E_KT,
    E_LCG,
    E_LCSIG,
    E_LSIG,
    E_N,
    E_NL,
    E_OFF,
    G_B,
    G_CS,
    G_H,
    G_IM,
    G_J,
    G_KD,
    G_KI,
    G_KLOAD,
    G_KP,
    G_KSTOP,
    G_MS,
    G_N,
    G_NSUB,
    G_PERIOD,
    G_Q,
    G_TLIM,
    G_XLIM,
    P_LEN,
    S_K,
    S_N,
    S_V,
    S_Y,
    SE_F,
    SE_H,
    SE_I,
    SE_N,
    SE_PHI,
    SE_R,
    SE_S,
    SE_T,
    SE_W,
    TR_F,
    TR_H,
    TR_N,
    TR_PHI,
    TR_R,
    TR_S,
    TR_T,
    TR_TMAX,
    TR_V,
    TR_W,
    TR_Y,
    X_LEN,
    advance,
    run_batch,
)
from sim.truth import RigTruth, rig_truth

__all__ = ["RigPlant", "PlantState", "PlantTrace", "END_STOP_STIFFNESS_N_PER_MM", "NOISE_BLOCK"]

#: Stiffness of the protective end stops.
END_STOP_STIFFNESS_N_PER_MM = 1.0e6
#: Samples of sensor noise drawn from the generator at once.
NOISE_BLOCK = 4096

_DISABLED = int(DriveMode.DISABLED)
_POSITION = int(DriveMode.POSITION)
_FORCE = int(DriveMode.FORCE)
_MODES = frozenset((_DISABLED, _POSITION, _FORCE))


# ====================================================================== public types


@dataclass(frozen=True)
class PlantState:
    """True internal state of the rig at the end of the last sample (no sensor errors).

    Per-EMA quantities are ``(ema1, ema2)`` tuples.

    Attributes
    ----------
    t_s : float
        Time of the last sample, s.
    phi_rad, omega_rad_s : tuple of float
        Motor angle (rad) and speed (rad/s), relative to the housing.
    y_mm, v_mm_s : float
        Surface position (mm) and velocity (mm/s).
    r_mm, h_mm : tuple of float
        Ram and housing absolute positions, mm.
    F_N : tuple of float
        Load-path force, N (> 0 compression).
    s_mm : tuple of float
        True stroke ``r - h``, mm.
    torque_Nm : tuple of float
        Drive torque of the last substep, N m (0 when DISABLED).
    integral_rad_s : tuple of float
        CSP integrator state (integral of the angle error), rad s.
    """

    t_s: float
    phi_rad: tuple
    omega_rad_s: tuple
    y_mm: float
    v_mm_s: float
    r_mm: tuple
    h_mm: tuple
    F_N: tuple
    s_mm: tuple
    torque_Nm: tuple
    integral_rad_s: tuple


@dataclass(frozen=True)
class PlantTrace:
    """Record of a batch :meth:`RigPlant.run`: measured samples and true states.

    Measured arrays, shape (n,), same fields and units as :class:`hil.canopen.process.Sample`:
    ``t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N``.

    True arrays, shape (n, 2) per EMA (column 0 = EMA1): ``true_phi_rad``,
    ``true_omega_rad_s``, ``true_s_mm``, ``true_F_N``, ``true_r_mm``,
    ``true_h_mm``, ``torque_Nm`` (last substep), ``torque_abs_max_Nm`` (max over
    the sample's substeps); shape (n,): ``y_mm``, ``v_mm_s``.
    """

    t_s: np.ndarray
    phi1_rad: np.ndarray
    phi2_rad: np.ndarray
    s1_mm: np.ndarray
    s2_mm: np.ndarray
    F1_N: np.ndarray
    F2_N: np.ndarray
    true_phi_rad: np.ndarray
    true_omega_rad_s: np.ndarray
    true_s_mm: np.ndarray
    true_F_N: np.ndarray
    true_r_mm: np.ndarray
    true_h_mm: np.ndarray
    torque_Nm: np.ndarray
    torque_abs_max_Nm: np.ndarray
    y_mm: np.ndarray
    v_mm_s: np.ndarray


# ====================================================================== validation


def _build_vectors(params: RigParams) -> tuple[np.ndarray, np.ndarray, float]:
    """Validate ``params`` and pack them into the kernel's P vector and effect table."""
    instance_of(params, RigParams, "params")
    P = np.zeros(P_LEN, dtype=np.float64)
    i_mm = scalar(params.i_total_rad_per_mm, "params.i_total_rad_per_mm", "rad/mm", lo=0.0, lo_open=True)
    xlim = scalar(params.stroke_limit_mm, "params.stroke_limit_mm", "mm", lo=0.0, lo_open=True)
    period = scalar(params.sample_period_s, "params.sample_period_s", "s", lo=0.0, lo_open=True)
    nsub = count(params.substeps, "params.substeps", 1, 100_000)
    d = params.drive
    J = scalar(d.motor_inertia_kg_m2, "params.drive.motor_inertia_kg_m2", "kg m^2", lo=0.0, lo_open=True)
    bm = scalar(d.motor_viscous_Nm_s_per_rad, "params.drive.motor_viscous_Nm_s_per_rad", "N m s/rad", lo=0.0)
    tlim = scalar(d.torque_limit_Nm, "params.drive.torque_limit_Nm", "N m", lo=0.0, lo_open=True)
    wn = scalar(d.position_bandwidth_rad_s, "params.drive.position_bandwidth_rad_s", "rad/s", lo=0.0, lo_open=True)
    zeta = scalar(d.position_damping, "params.drive.position_damping", "(dimensionless)", lo=0.0)
    ti = scalar(d.position_integral_time_s, "params.drive.position_integral_time_s", "s", lo=0.0)
    sf = params.surface
    ms = scalar(sf.mass_kg, "params.surface.mass_kg", "kg", lo=0.0, lo_open=True)
    cs = scalar(sf.damping_N_s_per_mm, "params.surface.damping_N_s_per_mm", "N s/mm", lo=0.0)
    kload = scalar(sf.load_stiffness_N_per_mm, "params.surface.load_stiffness_N_per_mm", "N/mm", lo=0.0)

    im = i_mm * 1e3
    h = period / nsub
    P[G_IM] = im
    P[G_J] = J
    P[G_B] = bm
    P[G_TLIM] = tlim
    P[G_KP] = J * wn * wn
    P[G_KD] = 2.0 * zeta * wn * J
    P[G_KI] = J * wn * wn / ti if ti > 0.0 else 0.0
    P[G_MS] = ms
    P[G_CS] = cs * 1e3
    P[G_KLOAD] = kload * 1e3
    P[G_XLIM] = xlim * 1e-3
    P[G_KSTOP] = END_STOP_STIFFNESS_N_PER_MM * 1e3
    P[G_H] = h
    P[G_NSUB] = nsub
    P[G_PERIOD] = period

    bits = None
    for e, (mname, sname) in enumerate((("ema1", "sensors1"), ("ema2", "sensors2"))):
        m = getattr(params, mname)
        s = getattr(params, sname)
        p = G_N + e * E_N
        pre = f"params.{mname}."
        P[p + E_BI] = scalar(m.backlash_int_mm, pre + "backlash_int_mm", "mm", lo=0.0) * 1e-3
        P[p + E_BB] = scalar(m.bearing_backlash_mm, pre + "bearing_backlash_mm", "mm", lo=0.0) * 1e-3
        for col, f in ((E_KC, "stiffness_compression_N_per_mm"), (E_KT, "stiffness_tension_N_per_mm"),
                       (E_KB, "bearing_stiffness_N_per_mm"), (E_KH, "housing_stiffness_N_per_mm")):
            P[p + col] = scalar(getattr(m, f), pre + f, "N/mm", lo=0.0, lo_open=True) * 1e3
        pre = f"params.{sname}."
        P[p + E_GAIN] = scalar(s.lvdt_gain, pre + "lvdt_gain", "(mm/mm)", lo=0.0, lo_open=True)
        P[p + E_OFF] = scalar(s.lvdt_offset_mm, pre + "lvdt_offset_mm", "mm")
        P[p + E_NL] = scalar(s.lvdt_nonlinearity_mm, pre + "lvdt_nonlinearity_mm", "mm")
        P[p + E_FS] = scalar(s.lvdt_full_scale_mm, pre + "lvdt_full_scale_mm", "mm", lo=0.0, lo_open=True)
        P[p + E_LSIG] = scalar(s.lvdt_noise_pp_mm, pre + "lvdt_noise_pp_mm", "mm", lo=0.0) / 6.0
        P[p + E_LCG] = scalar(s.loadcell_gain, pre + "loadcell_gain", "(N/N)", lo=0.0, lo_open=True)
        P[p + E_LCSIG] = scalar(s.loadcell_noise_std_N, pre + "loadcell_noise_std_N", "N", lo=0.0)
        b = count(s.resolver_bits, pre + "resolver_bits", 1, 40)
        if bits is not None and b != bits:
            raise InputError(f"params.sensors2.resolver_bits must equal params.sensors1.resolver_bits "
                             f"(one resolver quantum per rig), got {b} and {bits}")
        bits = b
    P[G_Q] = 2.0 * math.pi / 2.0**bits

    table = _fx.compile_effects(params.effects, period, nsub)

    # stability of the explicit spring terms: Gershgorin bound of M^-1 K
    M = J * im * im
    kch = []
    for e in range(2):
        p = G_N + e * E_N
        kint = max(P[p + E_KC], P[p + E_KT]) * (1.0 + table[e, _fx.COL_BUMP_REL]) + table[e, _fx.COL_VE_K]
        kch.append(1.0 / (1.0 / P[p + E_KH] + 1.0 / P[p + E_KB] + 1.0 / kint))
    w2 = max(
        (P[G_KP] * im * im + 2.0 * max(kch) + P[G_KSTOP]) / M,
        (2.0 * (kch[0] + kch[1]) + P[G_KLOAD]) / ms,
    )
    hw = h * math.sqrt(w2)
    # explicit half-kick of the damping terms (trapezoidal rule): h/2 * c/m <= 1
    visc = max(table[0, _fx.COL_VISCOUS], table[1, _fx.COL_VISCOUS])
    damp = 0.5 * h * max((P[G_KD] + bm + visc / (im * im)) / J, P[G_CS] / ms)
    if damp > 1.0:
        need = math.ceil(nsub * damp)
        raise InputError(
            f"params.substeps = {nsub} is too few for the damping terms: substep/2 x damping rate "
            f"= {damp:.3g} > 1; use at least {need} substeps"
        )
    if hw > 1.0:
        need = math.ceil(nsub * hw)
        raise InputError(
            f"params.substeps = {nsub} is too few: substep {h:.3g} s times the stiffest mode "
            f"{math.sqrt(w2):.4g} rad/s = {hw:.3g} > 1; use at least {need} substeps"
        )
    return P, table, hw


# ====================================================================== the plant


class RigPlant:
    """The simulated rig, advanced one sample period per :meth:`step`.

    Parameters
    ----------
    params : RigParams
        Rig parameters (validated here; :class:`blf.errors.InputError` names the field).
    rng : numpy.random.Generator
        Source of all sensor noise.
    s0_mm : float, optional
        Initial stroke of both EMAs, mm (default 0). The rig starts at rest,
        chains slack and centred (motor, ram and surface all at ``s0_mm``),
        drives DISABLED.

    Notes
    -----
    See the module docstring for the model equations and units. The per-sample
    kernel is compiled with numba (cached on disk); the first construction in
    a process triggers the compilation (seconds) unless the cache is warm.
    """

    def __init__(self, params: RigParams, rng: np.random.Generator, *, s0_mm: float = 0.0) -> None:
        P, table, hw = _build_vectors(params)
        generator(rng)
        s0 = scalar(s0_mm, "s0_mm", "mm", lo=-params.stroke_limit_mm, hi=params.stroke_limit_mm)
        self._params = params
        self._rng = rng
        self._P = P
        self._E = table
        self.stability_number = hw  #: substep x stiffest mode frequency (must be <= 1)
        X = np.zeros(X_LEN, dtype=np.float64)
        x0 = s0 * 1e-3
        X[S_Y] = x0
        for e in range(2):
            b = S_N + e * SE_N
            X[b + SE_PHI] = x0 * P[G_IM]
            X[b + SE_R] = x0
            X[b + SE_S] = x0
        self._X = X
        self._sbuf = np.zeros((2, int(P[G_NSUB]) + 1), dtype=np.float64)
        self._dm = np.zeros(4, dtype=np.float64)
        self._noise = rng.standard_normal((NOISE_BLOCK, 4))
        self._kn = 0
        self._period = float(params.sample_period_s)

    # ------------------------------------------------------------------ stepping
    def step_raw(self, mode1: int, value1: float, mode2: int, value2: float,
                 load_N: float = 0.0) -> tuple:
        """Advance one sample period with plain numbers (fast path of :meth:`step`).

        Parameters
        ----------
        mode1, mode2 : int
            Drive modes as :class:`hil.canopen.process.DriveMode` values (0, 8, 10).
        value1, value2 : float
            Motor angle target (rad) for POSITION, ram force target (N) for
            FORCE, ignored for DISABLED.
        load_N : float
            External force on the surface over this period, N (+ towards +y).

        Returns
        -------
        tuple
            ``(t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N)`` measured at
            the end of the period, ``t_s = k * sample_period_s``.
        """
        if mode1 not in _MODES:
            raise InputError(f"mode1 must be a DriveMode value in {sorted(_MODES)}, got {mode1!r}")
        if mode2 not in _MODES:
            raise InputError(f"mode2 must be a DriveMode value in {sorted(_MODES)}, got {mode2!r}")
        if mode1 == _DISABLED:
            value1 = 0.0
        elif not math.isfinite(value1):
            raise InputError(f"value1 must be finite (rad for POSITION, N for FORCE), got {value1!r}")
        if mode2 == _DISABLED:
            value2 = 0.0
        elif not math.isfinite(value2):
            raise InputError(f"value2 must be finite (rad for POSITION, N for FORCE), got {value2!r}")
        if not math.isfinite(load_N):
            raise InputError(f"load_N must be a finite scalar in N, got {load_N!r}")
        if self._kn >= NOISE_BLOCK:
            self._noise = self._rng.standard_normal((NOISE_BLOCK, 4))
            self._kn = 0
        out = advance(self._X, self._P, self._E, self._sbuf, self._dm, int(mode1), float(value1),
                       int(mode2), float(value2), float(load_N), self._noise, self._kn)
        self._kn += 1
        return out

    def step(self, sp1: Setpoint, sp2: Setpoint, load_N: float = 0.0) -> Sample:
        """Advance one sample period and return the sample measured at its end.

        Parameters
        ----------
        sp1, sp2 : hil.canopen.process.Setpoint
            Commands of drive 1 and 2, held over the period.
        load_N : float, optional
            External force on the surface, N (+ towards +y), held over the period.

        Returns
        -------
        hil.canopen.process.Sample
            Measured (quantised, noisy, miscalibrated) sample at ``t_s = k * period``.

        Raises
        ------
        blf.errors.InputError
            ``sp1``/``sp2`` not a Setpoint, unknown mode, non-finite value or load.
        """
        if not isinstance(sp1, Setpoint):
            raise InputError(f"sp1 must be a hil.canopen.process.Setpoint, got {type(sp1).__name__}")
        if not isinstance(sp2, Setpoint):
            raise InputError(f"sp2 must be a hil.canopen.process.Setpoint, got {type(sp2).__name__}")
        try:
            return Sample(*self.step_raw(sp1.mode, sp1.value, sp2.mode, sp2.value, load_N))
        except InputError as exc:
            msg = str(exc).replace("mode1", "sp1.mode").replace("value1", "sp1.value")
            msg = msg.replace("mode2", "sp2.mode").replace("value2", "sp2.value")
            raise InputError(msg) from None
        except TypeError as exc:
            raise InputError(f"sp1.value, sp2.value and load_N must be real scalars: {exc}") from None

    def run(self, mode1: Any, value1: Any, mode2: Any, value2: Any, load_N: Any = 0.0) -> PlantTrace:
        """Advance many sample periods in one compiled loop (tests, benchmarks).

        Identical to calling :meth:`step_raw` once per row (same noise draws
        for the same generator state), but without the per-call overhead.

        Parameters
        ----------
        mode1, mode2 : int or array_like of int, shape (n,)
            Drive modes per sample (DriveMode values); scalars are broadcast.
        value1, value2 : float or array_like, shape (n,)
            Targets per sample: rad (POSITION) or N (FORCE).
        load_N : float or array_like, shape (n,)
            External surface force per sample, N.

        Returns
        -------
        PlantTrace
            Measured samples and true states after each period.

        Raises
        ------
        blf.errors.InputError
            Shapes that do not broadcast to one length n >= 1, unknown modes,
            non-finite values.
        """
        arrs = {}
        for name, a in (("mode1", mode1), ("value1", value1), ("mode2", mode2), ("value2", value2),
                        ("load_N", load_N)):
            arr = np.asarray(a)
            if arr.ndim > 1:
                raise InputError(f"{name} must be a scalar or 1-D array, got shape {arr.shape}")
            arrs[name] = arr
        try:
            b = np.broadcast_arrays(*arrs.values())
        except ValueError:
            raise InputError("mode1, value1, mode2, value2 and load_N must broadcast to one length n; got "
                             + ", ".join(f"{k} shape {v.shape}" for k, v in arrs.items())) from None
        n = b[0].size if b[0].ndim == 1 else 1
        if n < 1:
            raise InputError("run needs at least one sample (n >= 1), got n = 0")
        m1, v1, m2, v2, ld = (np.ascontiguousarray(np.broadcast_to(x, (n,))) for x in b)
        mm = []
        for name, m in (("mode1", m1), ("mode2", m2)):
            if not np.issubdtype(m.dtype, np.integer) or not np.isin(m, list(_MODES)).all():
                raise InputError(f"{name} must hold DriveMode values {sorted(_MODES)} (int), shape ({n},)")
            mm.append(m.astype(np.int64))
        vv = []
        for name, v, m in (("value1", v1, mm[0]), ("value2", v2, mm[1])):
            v = np.where(m == _DISABLED, 0.0, v.astype(np.float64))
            if not np.isfinite(v).all():
                raise InputError(f"{name} must be finite where the drive is enabled (rad or N), shape ({n},)")
            vv.append(v)
        ld = ld.astype(np.float64)
        if not np.isfinite(ld).all():
            raise InputError(f"load_N must be finite, N, shape ({n},)")

        meas = np.empty((n, 7), dtype=np.float64)
        truth = np.empty((n, TR_N), dtype=np.float64)
        i = 0
        while i < n:
            if self._kn >= NOISE_BLOCK:
                self._noise = self._rng.standard_normal((NOISE_BLOCK, 4))
                self._kn = 0
            m = min(n - i, NOISE_BLOCK - self._kn)
            sl = slice(i, i + m)
            run_batch(self._X, self._P, self._E, self._sbuf, self._dm, mm[0][sl], vv[0][sl], mm[1][sl],
                 vv[1][sl], ld[sl], self._noise, self._kn, meas, truth, i)
            self._kn += m
            i += m
        return PlantTrace(
            t_s=meas[:, 0], phi1_rad=meas[:, 1], phi2_rad=meas[:, 2], s1_mm=meas[:, 3],
            s2_mm=meas[:, 4], F1_N=meas[:, 5], F2_N=meas[:, 6],
            true_phi_rad=truth[:, TR_PHI:TR_PHI + 2], true_omega_rad_s=truth[:, TR_W:TR_W + 2],
            true_s_mm=truth[:, TR_S:TR_S + 2], true_F_N=truth[:, TR_F:TR_F + 2],
            true_r_mm=truth[:, TR_R:TR_R + 2], true_h_mm=truth[:, TR_H:TR_H + 2],
            torque_Nm=truth[:, TR_T:TR_T + 2], torque_abs_max_Nm=truth[:, TR_TMAX:TR_TMAX + 2],
            y_mm=truth[:, TR_Y], v_mm_s=truth[:, TR_V],
        )

    # ------------------------------------------------------------------ inspection
    @property
    def t_s(self) -> float:
        """Time of the last sample, s (0 before the first step)."""
        return float(self._X[S_K]) * self._period

    @property
    def params(self) -> RigParams:
        """The rig parameters this plant was built from."""
        return self._params

    def state(self) -> PlantState:
        """True internal state at the end of the last sample (copy)."""
        X = self._X

        def pair(idx: int, scale: float = 1.0) -> tuple:
            return (float(X[S_N + idx]) * scale, float(X[S_N + SE_N + idx]) * scale)

        return PlantState(
            t_s=self.t_s,
            phi_rad=pair(SE_PHI), omega_rad_s=pair(SE_W),
            y_mm=float(X[S_Y]) * 1e3, v_mm_s=float(X[S_V]) * 1e3,
            r_mm=pair(SE_R, 1e3), h_mm=pair(SE_H, 1e3), F_N=pair(SE_F), s_mm=pair(SE_S, 1e3),
            torque_Nm=pair(SE_T), integral_rad_s=pair(SE_I),
        )

    def truth(self) -> RigTruth:
        """Backlash, stiffness and calibration of this rig (:func:`sim.truth.rig_truth`)."""
        return rig_truth(self._params)
