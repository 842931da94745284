"""Position-driven replay of a dual-EMA recording through the rig's load-path model.

Pure: arrays and an explicit sample period in, a frozen dataclass out.

The measured motor angles drive the motor side of both load paths
(:math:`x_{m,i} = \\varphi_i / i_{total}`), so the drives' controllers and
their differences from the simulator's do not count as mismatch. The surface
is quasi-static (its 50 Hz mode is far above the check's motions): at each
sample it sits where the two chain forces, the load spring and the hinge
friction balance,

.. math:: F_1(x_{m,1} - y) + F_2(x_{m,2} - y) = k_{load}\\,y + c_h\\dot y
          + F_{c,h}\\,\\mathrm{sign}(\\dot y),

with the Coulomb hinge friction set-valued (the surface sticks while the net
chain force stays within :math:`\\pm F_{c,h}`); where both chains are slack
the surface stays where it was. Each chain is a closed-form dead-zone spring
(internal play, tension and compression stiffness, progressive stiffening,
the Maxwell arm of :class:`sim.effects.Viscoelastic`, bearing play, series
bearing-plus-housing compliance). The sensors are applied after:
:func:`lvdt_model` and the load-cell gain. :mod:`sim.replay_model` builds the
diagnosis model on it (:class:`sim.replay_model.DualEmaReplay`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from blf.validate import as_1d_finite, instance_of, positive_scalar, same_shape, scalar

__all__ = ["ChainParams", "ReplayTrace", "replay_chains", "lvdt_model", "friction_force", "block_means"]


@dataclass(frozen=True)
class ChainParams:
    """Load path of one EMA for the replay (mm, N/mm, s, 1/mm).

    ``ve_stiffness_N_per_mm`` = 0 switches the Maxwell arm off;
    ``progressive_per_mm`` = 0 keeps the contact springs linear.
    """

    backlash_int_mm: float
    stiffness_compression_N_per_mm: float
    stiffness_tension_N_per_mm: float
    bearing_backlash_mm: float
    series_compliance_mm_per_N: float  #: bearing plus housing compliance 1/k_b + 1/k_h
    ve_stiffness_N_per_mm: float = 0.0
    ve_time_constant_s: float = 1.0
    progressive_per_mm: float = 0.0  #: contact spring F = k d (1 + p |d|), d its deflection


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
def _flank(w, k, cs, p):
    """Force of a contact flank (spring k, progressive p) in series with compliance cs at overlap w >= 0."""
    if p == 0.0:
        return w / (1.0 / k + cs)
    # d + cs k d (1 + p d) = w  ->  cs k p d^2 + (1 + cs k) d - w = 0
    a = cs * k * p
    b = 1.0 + cs * k
    disc = max(b * b + 4.0 * a * w, 0.25 * b * b)
    d = 2.0 * w / (b + math.sqrt(disc))
    return k * d * max(1.0 + p * d, 0.0)


@njit(cache=True)
def _chain(xm, y, r_prev, zc, zt, bi, bb, kc, kt, cs, kv, p, ff):
    """Closed-form load path of one EMA (SI). Returns F, r, s (= r - h), dmc, dmt.

    In contact the ram sits at r = y + F cs/2 + sign(F) bb/2 (the series
    compliance split evenly between bearing and housing, as in the plant) and
    the stroke is s = r + F cs/2; slack, the ram follows the play operator
    between the nut flanks and the bearing and s = r. A friction force ff
    between ram and housing (opposing the ram's motion, > 0 extending) is
    carried by the nut flank besides F: it shifts the flank by ff/k."""
    u = xm - y
    kcv = kc + kv
    ktv = kt + kv
    dc0 = kv * zc / kcv  # free material deflection of the compression flank (>= 0)
    dt0 = kv * zt / ktv  # ... of the tension flank (<= 0)
    half = 0.5 * (bi + bb)
    ac = half + dc0 + ff / kcv
    at = -half + dt0 + ff / ktv
    if u > ac:
        f = _flank(u - ac, kcv, cs, p)
        r = y + 0.5 * (f * cs + bb)
        return f, r, r + 0.5 * f * cs, (f + ff + kv * zc) / kcv, dt0
    if u < at:
        f = -_flank(at - u, ktv, cs, p)
        r = y + 0.5 * (f * cs - bb)
        return f, r, r + 0.5 * f * cs, dc0, (f + ff + kv * zt) / ktv
    lo = max(xm - 0.5 * bi - dc0, y - 0.5 * bb)
    hi = min(xm + 0.5 * bi - dt0, y + 0.5 * bb)
    r = min(max(r_prev, lo), hi)
    return 0.0, r, r, dc0, dt0


@njit(cache=True)
def _force(u, ac, at, kcv, ktv, cs, p):
    """Chain force at elongation u and its derivative dF/du, given the contact thresholds (SI)."""
    if u > ac:
        f = _flank(u - ac, kcv, cs, p)
        d = 1e-10
        return f, ((_flank(u - ac + d, kcv, cs, p) - f) / d if p != 0.0 else 1.0 / (1.0 / kcv + cs))
    if u < at:
        f = -_flank(at - u, ktv, cs, p)
        d = 1e-10
        return f, ((f + _flank(at - u - d, ktv, cs, p)) / d if p != 0.0 else 1.0 / (1.0 / ktv + cs))
    return 0.0, 0.0


@njit(cache=True)
def _branch(u, ac, at):
    """Contact branch of a chain at elongation u: 1 compression flank, -1 tension flank, 0 slack."""
    if u > ac:
        return 1
    if u < at:
        return -1
    return 0


@njit(cache=True)
def _solve(x1, x2, y, A, klin, c0, f1, d1, f2, d2):
    """Surface position with g(y) = c0 - klin y + F1(x1 - y) + F2(x2 - y) = 0 (g non-increasing):
    Newton with the exact slope, safeguarded by bisection, to 1e-13 m. A: per chain ac, at, kcv, ktv, cs, p;
    (f1, d1, f2, d2) the chain forces and slopes at the start value y.

    With linear flanks (p = 0) g is piecewise linear: a Newton step that keeps both chains on their
    branches lands on the root (to rounding), so it is returned without another evaluation."""
    lo = -1e300
    hi = 1e300
    linear = A[0, 5] == 0.0 and A[1, 5] == 0.0
    for it in range(80):
        if it > 0:
            f1, d1 = _force(x1 - y, A[0, 0], A[0, 1], A[0, 2], A[0, 3], A[0, 4], A[0, 5])
            f2, d2 = _force(x2 - y, A[1, 0], A[1, 1], A[1, 2], A[1, 3], A[1, 4], A[1, 5])
        g = c0 - klin * y + f1 + f2
        if g == 0.0:
            return y
        if g > 0.0:
            lo = y
        else:
            hi = y
        slope = -klin - d1 - d2
        yn = y - g / slope if slope < 0.0 else y
        if not (lo < yn < hi):
            # outside the bracket: bisect it once both ends are known, else step towards the root
            yn = 0.5 * (lo + hi) if lo > -1e300 and hi < 1e300 else y + (1e-4 if g > 0.0 else -1e-4)
        elif linear and slope < 0.0 \
                and _branch(x1 - yn, A[0, 0], A[0, 1]) == _branch(x1 - y, A[0, 0], A[0, 1]) \
                and _branch(x2 - yn, A[1, 0], A[1, 1]) == _branch(x2 - y, A[1, 0], A[1, 1]):
            return yn
        if abs(yn - y) < 1e-13:
            return yn
        y = yn
    return y


@njit(cache=True)
def _replay(xm1, xm2, P, kload, mass, damping, fc_hinge, period, ff1, ff2):
    n = xm1.shape[0]
    s = np.empty((n, 2))
    F = np.empty((n, 2))
    Y = np.empty(n)
    r = np.zeros(2)
    zc = np.zeros(2)
    zt = np.zeros(2)
    A = np.empty((2, 6))
    alpha = np.zeros(2)
    for j in range(2):
        if P[j, 5] > 0.0:
            alpha[j] = -math.expm1(-period / P[j, 6])
    y = 0.5 * (xm1[0] + xm2[0])
    r[0] = xm1[0]
    r[1] = xm2[0]
    y1 = y
    y2 = y
    mq = mass / (period * period)
    cq = damping / period
    klin = kload + mq + cq
    for k in range(n):
        # contact thresholds of each chain at this sample (Maxwell states and ram friction held over it)
        for j in range(2):
            kv = P[j, 5]
            kcv = P[j, 2] + kv
            ktv = P[j, 3] + kv
            half = 0.5 * (P[j, 0] + P[j, 1])
            ffj = ff1[k] if j == 0 else ff2[k]
            A[j, 0] = half + kv * zc[j] / kcv + ffj / kcv
            A[j, 1] = -half + kv * zt[j] / ktv + ffj / ktv
            A[j, 2] = kcv
            A[j, 3] = ktv
            A[j, 4] = P[j, 4]
            A[j, 5] = P[j, 7]
        # backward differences: m (y - 2 y1 + y2)/T^2 + c (y - y1)/T
        c0 = mq * (2.0 * y1 - y2) + cq * y1
        f1, d1 = _force(xm1[k] - y1, A[0, 0], A[0, 1], A[0, 2], A[0, 3], A[0, 4], A[0, 5])
        f2, d2 = _force(xm2[k] - y1, A[1, 0], A[1, 1], A[1, 2], A[1, 3], A[1, 4], A[1, 5])
        if fc_hinge > 0.0:
            g1 = c0 - klin * y1 + f1 + f2
            if abs(g1) <= fc_hinge:
                y = y1  # the hinge sticks
            else:
                y = _solve(xm1[k], xm2[k], y1, A, klin, c0 - (fc_hinge if g1 > 0.0 else -fc_hinge), f1, d1, f2, d2)
        else:
            y = _solve(xm1[k], xm2[k], y1, A, klin, c0, f1, d1, f2, d2)
        Y[k] = y
        y2 = y1
        y1 = y
        for j in range(2):
            xm = xm1[k] if j == 0 else xm2[k]
            f, rr, sj, dmc, dmt = _chain(xm, y, r[j], zc[j], zt[j], P[j, 0], P[j, 1], P[j, 2], P[j, 3],
                                         P[j, 4], P[j, 5], P[j, 7], ff1[k] if j == 0 else ff2[k])
            r[j] = rr
            s[k, j] = sj
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
    scalar(c.progressive_per_mm, f"{name}.progressive_per_mm", "1/mm")
    # SI row: bi, bb, kc, kt, cs, kv, tau, p
    return [c.backlash_int_mm * 1e-3, c.bearing_backlash_mm * 1e-3, c.stiffness_compression_N_per_mm * 1e3,
            c.stiffness_tension_N_per_mm * 1e3, c.series_compliance_mm_per_N * 1e-3, c.ve_stiffness_N_per_mm * 1e3,
            c.ve_time_constant_s, c.progressive_per_mm * 1e3]


def replay_chains(xm1_mm: np.ndarray, xm2_mm: np.ndarray, ema1: ChainParams, ema2: ChainParams,
                  sample_period_s: float, load_stiffness_N_per_mm: float = 0.0,
                  surface_mass_kg: float = 0.0, surface_damping_N_s_per_mm: float = 0.0,
                  hinge_coulomb_N: float = 0.0, friction1_N=None, friction2_N=None) -> ReplayTrace:
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
        Surface inertia (kg) and viscous hinge damping (N s/mm), >= 0; 0 = quasi-static.
    hinge_coulomb_N : float
        Coulomb friction of the surface hinge, N (>= 0).
    friction1_N, friction2_N : ndarray, shape (n,), optional
        Friction between ram and housing of each EMA per sample, N (opposing
        the ram's motion: > 0 while it extends); None: none.

    Returns
    -------
    ReplayTrace

    Notes
    -----
    Surface :math:`F_1 + F_2 = k_{load} y + m\\,\\ddot y + c\\,\\dot y + F_{c,h}\\,\\mathrm{sign}(\\dot y)`
    with backward differences (implicit, so the 50 Hz surface mode is damped
    numerically rather than resolved). With :math:`g(y)` the left side minus
    the smooth terms (non-increasing in y): the surface sticks,
    :math:`y_k = y_{k-1}`, while :math:`|g(y_{k-1})| \\le F_{c,h}`; otherwise
    :math:`g(y) = \\pm F_{c,h}` is solved by Newton with the exact slope,
    safeguarded by bisection, to 1e-13 m. A contact flank of stiffness k carries
    :math:`F = k\\,d\\,(1 + p|d|)` at deflection d [m], in series with the
    compliance :math:`c_s` (closed form, a quadratic in d). Maxwell states
    are updated once per sample, :math:`z \\leftarrow z + (\\delta - z)(1 - e^{-T_s/\\tau})`.
    A friction :math:`F_r` between ram and housing is carried by the nut
    flank besides the load-cell force: the flank deflects by
    :math:`(F + F_r)/k`, so the chain's contact thresholds shift by :math:`F_r/k`.
    """
    x1 = np.ascontiguousarray(as_1d_finite(xm1_mm, "xm1_mm", "mm", min_len=2))
    x2 = np.ascontiguousarray(as_1d_finite(xm2_mm, "xm2_mm", "mm", min_len=2))
    same_shape((x1, "xm1_mm", "mm"), (x2, "xm2_mm", "mm"))
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    k_load = scalar(load_stiffness_N_per_mm, "load_stiffness_N_per_mm", "N/mm", lo=0.0)
    mass = scalar(surface_mass_kg, "surface_mass_kg", "kg", lo=0.0)
    damping = scalar(surface_damping_N_s_per_mm, "surface_damping_N_s_per_mm", "N s/mm", lo=0.0)
    fch = scalar(hinge_coulomb_N, "hinge_coulomb_N", "N", lo=0.0)
    P = np.array([_chain_row(ema1, "ema1"), _chain_row(ema2, "ema2")], dtype=np.float64)
    ff = []
    for arr, name in ((friction1_N, "friction1_N"), (friction2_N, "friction2_N")):
        if arr is None:
            ff.append(np.zeros(x1.size))
        else:
            a = np.ascontiguousarray(as_1d_finite(arr, name, "N"))
            same_shape((x1, "xm1_mm", "mm"), (a, name, "N"))
            ff.append(a)
    s, F, y = _replay(x1 * 1e-3, x2 * 1e-3, P, k_load * 1e3, mass, damping * 1e3, fch, T, ff[0], ff[1])
    return ReplayTrace(s_mm=s * 1e3, F_N=F, y_mm=y * 1e3)


def lvdt_model(s_mm: np.ndarray, t_s: np.ndarray, *, gain: float = 1.0, offset_mm: float = 0.0,
               nonlinearity_mm: float = 0.0, full_scale_mm: float = 20.0, drift_per_s: float = 0.0,
               delay_s: float = 0.0, quadratic_mm: float = 0.0) -> np.ndarray:
    """LVDT reading of a true stroke (the sensor law of :mod:`sim.plant`, plus a quadratic bow).

    Parameters
    ----------
    s_mm, t_s : ndarray, shape (n,)
        True stroke (mm) and sample times (s).
    gain, offset_mm, nonlinearity_mm, full_scale_mm, drift_per_s, delay_s, quadratic_mm : float
        Pitch (1), offset (mm), cubic term at full scale (mm), full scale
        (mm, > 0), relative gain drift (1/s), sampling delay (s, either
        sign), quadratic term at full scale (mm).

    Returns
    -------
    ndarray, shape (n,)
        :math:`o + g(1 + d\\,t)\\,\\tilde s + n_2(\\tilde s/s_{fs})^2 + n_3(\\tilde s/s_{fs})^3`
        mm with :math:`\\tilde s = s - \\Delta\\,\\dot s` (first order in the delay).
    """
    s = as_1d_finite(s_mm, "s_mm", "mm")
    t = as_1d_finite(t_s, "t_s", "s")
    same_shape((s, "s_mm", "mm"), (t, "t_s", "s"))
    positive_scalar(full_scale_mm, "full_scale_mm", "mm")
    if delay_s != 0.0:
        s = s - delay_s * np.gradient(s, t)
    out = gain * s if drift_per_s == 0.0 else gain * (1.0 + drift_per_s * (t - t[0])) * s
    if nonlinearity_mm != 0.0 or quadratic_mm != 0.0:
        rel = s / full_scale_mm
        out = out + (quadratic_mm + nonlinearity_mm * rel) * (rel * rel)
    return out + offset_mm if offset_mm != 0.0 else out


#: the friction law's velocity band v_eps [mm/s] (:func:`friction_force`'s default)
FRICTION_BAND_MM_S = 0.1


def friction_force(v_mm_s: np.ndarray, *, coulomb_N: float = 0.0, viscous_N_s_per_mm: float = 0.0,
                   stribeck_N: float = 0.0, stribeck_velocity_mm_s: float = 1.0, asym_N: float = 0.0,
                   band_mm_s: float = FRICTION_BAND_MM_S, tanh_v: np.ndarray | None = None) -> np.ndarray:
    """Friction force on the motor-side motion (the law of :mod:`sim.effects`), N.

    ``tanh_v``: ``np.tanh(v_mm_s / band_mm_s)`` where the caller holds it (a model that asks about the
    same velocities many times, :class:`sim.replay_model.DualEmaReplay`); computed here without it.

    Notes
    -----
    :math:`F_f = (F_C + F_A \\tanh(v/v_\\varepsilon) + F_S e^{-(v/v_s)^2})\\tanh(v/v_\\varepsilon) + c v`
    with v in mm/s. Without a Stribeck term (:math:`F_S = \\pm 0`) its exponential is not evaluated: the
    term adds :math:`F_S` itself, the same signed zero every sample's :math:`F_S e^{\\ldots}` is (the
    result bit for bit the same, docs/performance.md "Test suite, sixth pass").
    """
    v = np.asarray(v_mm_s, dtype=np.float64)
    th = np.tanh(v / band_mm_s) if tanh_v is None else tanh_v
    stribeck = stribeck_N * np.exp(-(v / stribeck_velocity_mm_s) ** 2) if stribeck_N != 0.0 else stribeck_N
    level = coulomb_N + asym_N * th + stribeck
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
