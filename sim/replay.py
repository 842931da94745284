"""Position-driven replay of a dual-EMA recording through the rig's load-path model.

Pure: arrays and an explicit sample period in, a frozen dataclass out.

The measured motor angles drive the motor side of both load paths
(:math:`x_{m,i} = \\varphi_i / i_{total}`), so the drives' controllers and
their differences from the simulator's do not count as mismatch. The surface
is quasi-static (its 50 Hz mode is far above the check's motions): at each
sample it sits where the two chain forces and the load spring balance,

.. math:: F_1(x_{m,1} - y) + F_2(x_{m,2} - y) = k_{load}\\,y,

and where both chains are slack (the force passes zero) it stays where it was
(the nearest point of the zero-force interval). The chains are the closed-form
dead-zone springs of :func:`sim.plant_kernel.chain` (internal play, tension and
compression stiffness, Maxwell arm of :class:`sim.effects.Viscoelastic`,
bearing play and stiffness, housing spring). The sensors are applied after:
:func:`lvdt_model` and the load-cell gain.

An EMA in FORCE mode gives one more channel: the force the drive delivers,
from the momentum balance of its motor over short blocks (:func:`block_means`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from blf.validate import as_1d_finite, instance_of, positive_scalar, same_shape, scalar
from sim.plant_kernel import chain

__all__ = ["ChainParams", "ReplayTrace", "replay_chains", "lvdt_model", "friction_force", "block_means"]


@dataclass(frozen=True)
class ChainParams:
    """Load path of one EMA for the replay (mm, N/mm, s).

    ``ve_stiffness_N_per_mm`` = 0 switches the Maxwell arm off.
    """

    backlash_int_mm: float
    stiffness_compression_N_per_mm: float
    stiffness_tension_N_per_mm: float
    bearing_backlash_mm: float
    series_compliance_mm_per_N: float  #: bearing plus housing compliance 1/k_b + 1/k_h
    ve_stiffness_N_per_mm: float = 0.0
    ve_time_constant_s: float = 1.0


@dataclass(frozen=True)
class ReplayTrace:
    """True strokes and load-path forces of a replay, shape (n, 2) (column 0 = EMA 1).

    ``s_mm`` stroke r - h in mm, ``F_N`` load-path force in N (> 0 compression),
    ``y_mm`` surface position, shape (n,).
    """

    s_mm: np.ndarray
    F_N: np.ndarray
    y_mm: np.ndarray


@njit(cache=True)
def _g(xm, y, r, zc, zt, P, e, kload, mq, cq, c0):
    """Sum of chain forces minus load spring and inertia at surface position y (non-increasing in y)."""
    tot = c0 - (kload + mq + cq) * y
    for j in range(2):
        q = e[j]
        f, _, _, _, _ = chain(xm[j], y, r[j], zc[j], zt[j], P[q, 0], P[q, 1], P[q, 2], P[q, 3],
                              P[q, 4], P[q, 5], P[q, 6])
        tot += f
    return tot


@njit(cache=True)
def _replay(xm1, xm2, P, kload, mass, damping, period):
    n = xm1.shape[0]
    s = np.empty((n, 2))
    F = np.empty((n, 2))
    Y = np.empty(n)
    xm = np.empty(2)
    r = np.zeros(2)
    zc = np.zeros(2)
    zt = np.zeros(2)
    e = np.array([0, 1])
    alpha = np.empty(2)
    for j in range(2):
        tau = P[j, 7]
        alpha[j] = -math.expm1(-period / tau) if P[j, 6] > 0.0 else 0.0
    xm[0] = xm1[0]
    xm[1] = xm2[0]
    y = 0.5 * (xm[0] + xm[1])
    r[0] = xm[0]
    r[1] = xm[1]
    y1 = y
    y2 = y
    mq = mass / (period * period)
    cq = damping / period
    for k in range(n):
        xm[0] = xm1[k]
        xm[1] = xm2[k]
        # backward differences: m (y - 2 y1 + y2)/T^2 + c (y - y1)/T
        c0 = mq * (2.0 * y1 - y2) + cq * y1
        g0 = _g(xm, y, r, zc, zt, P, e, kload, mq, cq, c0)
        # safeguarded Newton on the non-increasing, piecewise-linear g
        lo = -1e300
        hi = 1e300
        g = g0
        for _ in range(60):
            if g == 0.0:
                break
            if g > 0.0:
                lo = y
            else:
                hi = y
            d = 1e-9
            slope = (_g(xm, y + d, r, zc, zt, P, e, kload, mq, cq, c0) - g) / d
            yn = y - g / slope if slope < 0.0 else y
            if not (lo < yn < hi):
                if lo > -1e300 and hi < 1e300:
                    yn = 0.5 * (lo + hi)
                else:
                    yn = y + (1e-4 if g > 0.0 else -1e-4)
            if abs(yn - y) < 1e-13:
                y = yn
                break
            y = yn
            g = _g(xm, y, r, zc, zt, P, e, kload, mq, cq, c0)
        Y[k] = y
        y2 = y1
        y1 = y
        for j in range(2):
            f, rr, hh, dmc, dmt = chain(xm[j], y, r[j], zc[j], zt[j], P[j, 0], P[j, 1], P[j, 2],
                                        P[j, 3], P[j, 4], P[j, 5], P[j, 6])
            r[j] = rr
            s[k, j] = rr - hh
            F[k, j] = f
            if alpha[j] > 0.0:
                zc[j] += (dmc - zc[j]) * alpha[j]
                zt[j] += (dmt - zt[j]) * alpha[j]
    return s, F, Y


#: ChainParams fields: (name, unit, strictly positive)
_CHAIN_FIELDS = (
    ("backlash_int_mm", "mm", False), ("bearing_backlash_mm", "mm", False),
    ("stiffness_compression_N_per_mm", "N/mm", True), ("stiffness_tension_N_per_mm", "N/mm", True),
    ("series_compliance_mm_per_N", "mm/N", True), ("ve_stiffness_N_per_mm", "N/mm", False),
    ("ve_time_constant_s", "s", True),
)


def _chain_row(c: ChainParams, name: str) -> list[float]:
    instance_of(c, ChainParams, name)
    for field, unit, positive in _CHAIN_FIELDS:
        scalar(getattr(c, field), f"{name}.{field}", unit, lo=0.0, lo_open=positive)
    # SI row: bi, bb, kc, kt, kb, kh, kv, tau (kb, kh split evenly: only their series counts)
    ks = 1e3 / c.series_compliance_mm_per_N  # N/m
    return [c.backlash_int_mm * 1e-3, c.bearing_backlash_mm * 1e-3,
            c.stiffness_compression_N_per_mm * 1e3, c.stiffness_tension_N_per_mm * 1e3,
            2.0 * ks, 2.0 * ks, c.ve_stiffness_N_per_mm * 1e3, c.ve_time_constant_s]


def replay_chains(xm1_mm: np.ndarray, xm2_mm: np.ndarray, ema1: ChainParams, ema2: ChainParams,
                  sample_period_s: float, load_stiffness_N_per_mm: float = 0.0,
                  surface_mass_kg: float = 0.0, surface_damping_N_s_per_mm: float = 0.0) -> ReplayTrace:
    """Replay the load paths driven by the motor-side positions.

    Parameters
    ----------
    xm1_mm, xm2_mm : ndarray, shape (n,)
        Motor-side ram positions :math:`\\varphi_i / i_{total}`, mm.
    ema1, ema2 : ChainParams
    sample_period_s : float
        Sample period, s (> 0).
    load_stiffness_N_per_mm : float
        Restoring load spring on the surface, N/mm (>= 0).
    surface_mass_kg, surface_damping_N_s_per_mm : float
        Surface inertia (kg) and damping (N s/mm), >= 0; 0 = quasi-static.

    Returns
    -------
    ReplayTrace

    Notes
    -----
    Surface :math:`F_1 + F_2 = k_{load} y + m\\,\\ddot y + c\\,\\dot y` with
    backward differences (implicit, so the 50 Hz surface mode is damped
    numerically rather than resolved), solved by safeguarded Newton
    (bisection fallback) to 1e-13 m each sample (the residual function is non-increasing in y); chain per :func:`sim.plant_kernel.chain`; Maxwell states updated once per
    sample, :math:`z \\leftarrow z + (\\delta - z)(1 - e^{-T_s/\\tau})`.
    """
    x1 = np.ascontiguousarray(as_1d_finite(xm1_mm, "xm1_mm", "mm", min_len=2))
    x2 = np.ascontiguousarray(as_1d_finite(xm2_mm, "xm2_mm", "mm", min_len=2))
    same_shape((x1, "xm1_mm", "mm"), (x2, "xm2_mm", "mm"))
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    k_load = scalar(load_stiffness_N_per_mm, "load_stiffness_N_per_mm", "N/mm", lo=0.0)
    mass = scalar(surface_mass_kg, "surface_mass_kg", "kg", lo=0.0)
    damping = scalar(surface_damping_N_s_per_mm, "surface_damping_N_s_per_mm", "N s/mm", lo=0.0)
    P = np.array([_chain_row(ema1, "ema1"), _chain_row(ema2, "ema2")], dtype=np.float64)
    s, F, y = _replay(x1 * 1e-3, x2 * 1e-3, P, k_load * 1e3, mass, damping * 1e3, T)
    return ReplayTrace(s_mm=s * 1e3, F_N=F, y_mm=y * 1e3)


def lvdt_model(s_mm: np.ndarray, t_s: np.ndarray, *, gain: float = 1.0, offset_mm: float = 0.0,
               nonlinearity_mm: float = 0.0, full_scale_mm: float = 20.0, drift_per_s: float = 0.0,
               delay_s: float = 0.0) -> np.ndarray:
    """LVDT reading of a true stroke (the sensor law of :mod:`sim.plant`).

    Parameters
    ----------
    s_mm, t_s : ndarray, shape (n,)
        True stroke (mm) and sample times (s).
    gain, offset_mm, nonlinearity_mm, full_scale_mm, drift_per_s, delay_s : float
        Pitch (1), offset (mm), cubic term at full scale (mm), full scale
        (mm, > 0), relative gain drift (1/s), sampling delay (s).

    Returns
    -------
    ndarray, shape (n,)
        :math:`o + g(1 + d\\,t)\\,\\tilde s + n_3(\\tilde s/s_{fs})^3` mm with
        :math:`\\tilde s = s - \\Delta\\,\\dot s` (first order in the delay).
    """
    s = as_1d_finite(s_mm, "s_mm", "mm")
    t = as_1d_finite(t_s, "t_s", "s")
    same_shape((s, "s_mm", "mm"), (t, "t_s", "s"))
    positive_scalar(full_scale_mm, "full_scale_mm", "mm")
    if delay_s != 0.0:
        s = s - delay_s * np.gradient(s, t)
    out = gain * s if drift_per_s == 0.0 else gain * (1.0 + drift_per_s * (t - t[0])) * s
    if nonlinearity_mm != 0.0:
        rel = s / full_scale_mm
        out = out + nonlinearity_mm * (rel * rel * rel)
    return out + offset_mm if offset_mm != 0.0 else out


def friction_force(v_mm_s: np.ndarray, *, coulomb_N: float = 0.0, viscous_N_s_per_mm: float = 0.0,
                   stribeck_N: float = 0.0, stribeck_velocity_mm_s: float = 1.0, asym_N: float = 0.0,
                   band_mm_s: float = 0.1) -> np.ndarray:
    """Friction force on the motor-side motion (the law of :mod:`sim.effects`), N.

    Notes
    -----
    :math:`F_f = (F_C + F_A \\tanh(v/v_\\varepsilon) + F_S e^{-(v/v_s)^2})\\tanh(v/v_\\varepsilon) + c v`
    with v in mm/s.
    """
    v = np.asarray(v_mm_s, dtype=np.float64)
    th = np.tanh(v / band_mm_s)
    level = coulomb_N + asym_N * th + stribeck_N * np.exp(-(v / stribeck_velocity_mm_s) ** 2)
    return level * th + viscous_N_s_per_mm * v


def block_means(x: np.ndarray, k0: np.ndarray, block: int) -> np.ndarray:
    """Time means of a sampled signal over the intervals :math:`[t_{k_0-1}, t_{k_0+B-1}]`.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Signal sampled at :math:`t_k`.
    k0 : ndarray of int, shape (m,)
        First sample of each block (>= 1).
    block : int
        Samples per block, B (>= 1).

    Returns
    -------
    ndarray, shape (m,)

    Notes
    -----
    Trapezoidal rule over the B periods ending at samples
    :math:`k_0 \\ldots k_0 + B - 1`:
    :math:`\\bar x = \\frac{1}{B}\\left(\\sum_{k=k_0}^{k_0+B-1} x_k + \\tfrac12 (x_{k_0-1} - x_{k_0+B-1})\\right)`.
    A drive's momentum balance over the same interval needs no acceleration:
    :math:`\\bar F = \\bar F_{target} - \\bar F_f - M (v_{k_0+B-1} - v_{k_0-1}) / (B T)`.
    """
    cs = np.r_[0.0, np.cumsum(x)]
    return (cs[k0 + block] - cs[k0] + 0.5 * (x[k0 - 1] - x[k0 + block - 1])) / block


# ====================================================================== diagnosis model

_FULL_SCALE_MM = 20.0
_TRANSIENT_S = 1.0  #: s, after a drive-mode change, where s and F are not compared
_FD_BLOCK_S = 0.1  #: the drive-force channels are compared as means over blocks of this length


def _cand(name, where, words, *params):
    from blf.diagnose import Candidate, Param
    return Candidate(name, where, words, tuple(Param(*q) for q in params))


def dual_ema_candidates() -> tuple:
    """The candidate library of the dual-EMA replay (machine names as in :mod:`sim.effects`)."""
    out = []
    for e, n in (("ema1", "1"), ("ema2", "2")):
        out += [
            _cand("lvdt_pitch", e, f"LVDT {n} pitch (gain) error", ("gain_error", 1e-3, 1e-3, -0.3, 0.3)),
            _cand("lvdt_offset", e, f"LVDT {n} offset", ("offset_mm", 5e-3, 5e-3, -2.0, 2.0)),
            _cand("lvdt_nonlinearity", e, f"LVDT {n} non-linearity (cubic over the stroke)",
                  ("nonlinearity_mm", 5e-3, 5e-3, -1.0, 1.0)),
            _cand("lvdt_drift", e, f"LVDT {n} gain drift over time (temperature)",
                  ("gain_drift_per_s", 1e-5, 1e-5, -1e-2, 1e-2)),
            _cand("time_skew", e, f"time skew between resolver {n} and LVDT {n} sampling",
                  ("delay_s", 5e-4, 5e-4, 0.0, 0.02)),
            _cand("loadcell_gain", e, f"load cell {n} gain error", ("gain_error", 1e-3, 1e-3, -0.3, 0.3)),
            _cand("stiffness_asymmetry", e, f"tension and compression stiffness differ in the EMA {n} load path",
                  ("tension_over_compression_minus_1", 0.05, 0.05, -0.9, 5.0)),
            _cand("viscoelastic", e, f"visco-elastic creep/relaxation in the EMA {n} load path",
                  ("stiffness_N_per_mm", 5000.0, 5000.0, 0.0, 1e6), ("time_constant_s", 0.3, 0.3, 0.01, 30.0)),
            _cand("coulomb_friction", e, f"Coulomb friction in the EMA {n} ballscrew",
                  ("force_N", 5.0, 5.0, 0.0, 1e4)),
            _cand("stribeck_friction", e, f"Stribeck (static above Coulomb) friction in the EMA {n} ballscrew",
                  ("extra_force_N", 5.0, 5.0, 0.0, 1e4), ("stribeck_velocity_mm_per_s", 0.5, 0.5, 0.01, 50.0)),
            _cand("asymmetric_friction", e, f"friction of the EMA {n} ballscrew that differs with the direction of motion",
                  ("force_extend_N", 5.0, 5.0, 0.0, 1e4), ("force_retract_N", 1.0, 5.0, 0.0, 1e4)),
        ]
    return tuple(out)


def _savgol(x: np.ndarray, period_s: float, deriv: int, window: int = 21) -> np.ndarray:
    from scipy.signal import savgol_filter
    return savgol_filter(x, window, 3, deriv=deriv, delta=period_s, mode="interp")


class DualEmaReplay:
    """The dual-EMA recording and its position-driven replay, for :func:`blf.diagnose.diagnose`.

    Channels: ``s1, s2`` (LVDT, mm), ``F1, F2`` (load cells, N) from the
    replayed load paths, and ``Fd1, Fd2`` (N): the load-cell force an EMA in
    FORCE mode should show by the momentum balance of its motor, only where
    the recording carries the drive modes and setpoints. ``Fd`` is compared
    as means over blocks of 0.1 s (valid at the block centres only):

    .. math:: \\bar F = \\overline{F_{target} - F_f(v) - c\\,v}
              - M\\,\\frac{v(t_{end}) - v(t_{start})}{t_{end} - t_{start}}

    so the motor acceleration is never differentiated from the quantised
    angle (per sample that error is as large as the load-cell noise); the
    measured side is the trapezoidal time mean of the load cell over the same
    interval. Where modes are recorded, s and F are not compared in the 1 s
    after a drive-mode change (the quasi-static surface does not model the
    ringing after the impact that follows).

    Nominal parameters: per EMA internal play, stiffness (equal in tension
    and compression), bearing play, bearing-plus-housing
    compliance; the reflected motor mass and the drive's viscous loss (so
    motor-side viscous friction is nominal here, not a candidate: the two
    cannot be told apart from these channels). Sensors ideal.

    Parameters
    ----------
    t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N : ndarray, shape (n,)
    i_total_rad_per_mm : float
    sample_period_s : float
    mode1, sp1, mode2, sp2 : ndarray or None
        Drive modes (0, 8, 10) and setpoints (rad or N) per sample, when recorded.
    """

    def __init__(self, t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N, i_total_rad_per_mm: float,
                 sample_period_s: float, mode1=None, sp1=None, mode2=None, sp2=None) -> None:
        from blf.diagnose import Param
        items = [(as_1d_finite(a, name, unit, min_len=200), name, unit) for a, name, unit in (
            (t_s, "t_s", "s"), (phi1_rad, "phi1_rad", "rad"), (phi2_rad, "phi2_rad", "rad"), (s1_mm, "s1_mm", "mm"),
            (s2_mm, "s2_mm", "mm"), (F1_N, "F1_N", "N"), (F2_N, "F2_N", "N"))]
        same_shape(*items)
        arrs = [a for a, _, _ in items]
        n = arrs[0].size
        i_total = positive_scalar(i_total_rad_per_mm, "i_total_rad_per_mm", "rad/mm")
        self.t_s = arrs[0]
        self.T = positive_scalar(sample_period_s, "sample_period_s", "s")
        self.xm = (arrs[1] / i_total, arrs[2] / i_total)
        self.channels = ("s1", "s2", "F1", "F2", "Fd1", "Fd2")
        self.measured = {"s1": arrs[3], "s2": arrs[4], "F1": arrs[5], "F2": arrs[6]}
        self.v = tuple(_savgol(x, self.T, 1) for x in self.xm)
        valid = {c: np.ones(n, bool) for c in ("s1", "s2", "F1", "F2")}
        self.target = []
        self.blocks = []
        blk = max(2, int(round(_FD_BLOCK_S / self.T)))
        for e, (mode, sp) in enumerate(((mode1, sp1), (mode2, sp2))):
            ok = np.zeros(n, bool)
            tgt = np.zeros(n)
            if mode is not None and sp is not None:
                mode = np.asarray(mode, dtype=float)
                sp = np.asarray(sp, dtype=float)
                force = mode == 10
                # the setpoint of sample k acts over the period ending at sample k + 1
                ok[1:] = force[:-1]
                tgt[1:] = sp[:-1]
                # settle: 0.3 s after entering FORCE mode
                start = np.where(ok & ~np.r_[False, ok[:-1]])[0]
                for k in start:
                    ok[k:k + int(0.3 / self.T)] = False
            # blocks of `blk` samples inside each FORCE run (the remainder of a run is dropped)
            k0 = []
            edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
            for a, b in zip(edges[::2], edges[1::2]):
                k0.extend(range(max(a, 1), b - blk + 1, blk))
            k0 = np.asarray(k0, dtype=np.int64)
            centre = k0 + blk // 2
            vmask = np.zeros(n, bool)
            vmask[centre] = True
            meas = np.zeros(n)
            # time mean of the load cell over the interval of the drive's momentum balance
            meas[centre] = block_means(arrs[5 + e], k0, blk)
            self.measured[f"Fd{e + 1}"] = meas
            valid[f"Fd{e + 1}"] = vmask
            self.target.append(tgt)
            self.blocks.append((k0, centre, blk))
        if mode1 is not None and mode2 is not None:
            # the quasi-static surface does not model the 50 Hz ringing after a drive enters or
            # leaves FORCE mode (free flight across the play, impact): not compared for 1 s
            change = np.zeros(n, bool)
            change[1:] = (np.diff(np.asarray(mode1, dtype=float)) != 0) | (np.diff(np.asarray(mode2, dtype=float)) != 0)
            k = int(round(_TRANSIENT_S / self.T))
            transient = np.convolve(change, np.ones(k), mode="full")[:n] > 0
            for c in ("s1", "s2", "F1", "F2"):
                valid[c] &= ~transient
        self.valid = valid
        self.derived_valid = {"Dint1": valid["s1"], "Dint2": valid["s2"], "Dext": valid["s1"] & valid["s2"]}
        self.nominal = (
            Param("backlash_int1_mm", 0.1, 0.01, 0.0, 2.0), Param("stiffness_int1_N_per_mm", 8e4, 1e4, 1e3, 1e7),
            Param("backlash_bearing1_mm", 0.05, 0.01, 0.0, 2.0),
            Param("compliance_ext1_mm_per_N", 5.5e-5, 5e-6, 1e-7, 1e-2),
            Param("backlash_int2_mm", 0.1, 0.01, 0.0, 2.0), Param("stiffness_int2_N_per_mm", 8e4, 1e4, 1e3, 1e7),
            Param("backlash_bearing2_mm", 0.05, 0.01, 0.0, 2.0),
            Param("compliance_ext2_mm_per_N", 5.5e-5, 5e-6, 1e-7, 1e-2),
            Param("reflected_mass_kg", 2500.0, 500.0, 0.0, 1e6),
            Param("drive_viscous_N_s_per_mm", 10.0, 10.0, 0.0, 1e4),
        )
        if not (valid["Fd1"].any() or valid["Fd2"].any()):
            self.nominal = self.nominal[:-2]
        self.candidates = dual_ema_candidates()
        self.regimes = {
            "position along the stroke": 0.5 * (self.xm[0] + self.xm[1]) - np.median(0.5 * (self.xm[0] + self.xm[1])),
            "velocity": 0.5 * (self.v[0] + self.v[1]),
            "force F1": arrs[5],
            "force rate": _savgol(arrs[5], self.T, 1),
            "time since start": self.t_s - 0.5 * (self.t_s[0] + self.t_s[-1]),
        }
        self._cache: dict = {}

    def derived(self, ch: dict) -> dict:
        """The paper's D signals (mm): D_int,i = s_i - phi_i / i_total, D_ext = s2 - s1."""
        return {"Dint1": ch["s1"] - self.xm[0], "Dint2": ch["s2"] - self.xm[1], "Dext": ch["s2"] - ch["s1"]}

    def _block_drive_force(self, e: int, friction_N: np.ndarray, reflected_mass_kg: float) -> np.ndarray:
        """Load-path force the FORCE-mode drive delivers, as block means at the block centres
        (zeros elsewhere); see :func:`block_means`."""
        k0, centre, blk = self.blocks[e]
        out = np.zeros(self.t_s.size)
        if k0.size == 0:
            return out
        k1 = k0 + blk - 1
        # over [t_{k0-1}, t_{k1}]: the target is held per period (tgt[k] over (t_{k-1}, t_k]),
        # so its mean is a plain sum; friction is sampled: trapezoid
        gt = np.r_[0.0, np.cumsum(self.target[e])]
        fric = block_means(friction_N, k0, blk)
        v = self.v[e]
        # momentum over the block: M (v(t_{k1}) - v(t_{k0-1})) / (B T), M in kg, v in mm/s
        dv = v[k1] - v[k0 - 1]
        out[centre] = (gt[k0 + blk] - gt[k0]) / blk - fric - reflected_mass_kg * 1e-3 * dv / (blk * self.T)
        return out

    def predict(self, theta: np.ndarray, active: list) -> dict:
        """Predicted channels for nominal ``theta`` and the active effects [(Candidate, params)]."""
        th = list(theta) + [0.0] * (10 - len(theta))
        fx = {(c.name, c.where): np.asarray(x, dtype=float) for c, x in active}
        chains = []
        for e, where in enumerate(("ema1", "ema2")):
            bi, k, bb, cs = th[4 * e: 4 * e + 4]
            asym = fx.get(("stiffness_asymmetry", where))
            kt = k * (1.0 + asym[0]) if asym is not None else k
            ve = fx.get(("viscoelastic", where))
            kv, tau = (float(ve[0]), float(ve[1])) if ve is not None else (0.0, 1.0)
            chains.append(ChainParams(max(bi, 0.0), k, max(kt, 1.0), max(bb, 0.0), cs, max(kv, 0.0), tau))
        key = tuple(chains)
        tr = self._cache.get(key)
        if tr is None:
            tr = replay_chains(self.xm[0], self.xm[1], chains[0], chains[1], self.T, 0.0, 300.0, 0.5)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = tr
        out = {}
        for e, where in enumerate(("ema1", "ema2")):
            g = lambda name: fx.get((name, where))  # noqa: E731
            kw = {}
            if g("lvdt_pitch") is not None:
                kw["gain"] = 1.0 + g("lvdt_pitch")[0]
            if g("lvdt_offset") is not None:
                kw["offset_mm"] = g("lvdt_offset")[0]
            if g("lvdt_nonlinearity") is not None:
                kw["nonlinearity_mm"] = g("lvdt_nonlinearity")[0]
            if g("lvdt_drift") is not None:
                kw["drift_per_s"] = g("lvdt_drift")[0]
            if g("time_skew") is not None:
                kw["delay_s"] = g("time_skew")[0]
            out[f"s{e + 1}"] = lvdt_model(tr.s_mm[:, e], self.t_s, full_scale_mm=_FULL_SCALE_MM, **kw)
            lg = 1.0 + (g("loadcell_gain")[0] if g("loadcell_gain") is not None else 0.0)
            out[f"F{e + 1}"] = lg * tr.F_N[:, e]
            fk = {}
            if g("coulomb_friction") is not None:
                fk["coulomb_N"] = g("coulomb_friction")[0]
            if g("stribeck_friction") is not None:
                fk["stribeck_N"], fk["stribeck_velocity_mm_s"] = g("stribeck_friction")
            if g("asymmetric_friction") is not None:
                fp, fm = g("asymmetric_friction")
                fk["coulomb_N"] = fk.get("coulomb_N", 0.0) + 0.5 * (fp + fm)
                fk["asym_N"] = 0.5 * (fp - fm)
            ff = friction_force(self.v[e], viscous_N_s_per_mm=th[9], **fk)
            out[f"Fd{e + 1}"] = lg * self._block_drive_force(e, ff, th[8])
        return out
