"""The compiled kernel of the simulated rig (numba): vector layouts and one sample period.

:class:`sim.plant.RigPlant` packs the rig parameters into the vector ``P``
(``G_*`` rig-wide entries, then one ``E_*`` block per EMA), keeps the state
in the vector ``X`` (``S_*`` surface entries, then one ``SE_*`` block per
EMA) and the switchable effects in the table ``E`` of :mod:`sim.effects`;
all in SI units (m, N, rad, s). :func:`advance` advances one sample period
in place and returns the measured sample; :func:`run_batch` advances many,
recording the measured samples and the true states (``TR_*`` columns).
:func:`chain` is the closed-form load path of one EMA (also used by the
replay of :mod:`sim.replay`). The model equations, the integration scheme
and the sensor laws are documented in :mod:`sim.plant`.

Pure: arrays in, arrays out (``X`` and the work arrays updated in place).
"""

from __future__ import annotations

import math

from numba import njit

from sim.effects import (
    COL_BUMP_CENTER,
    COL_BUMP_REL,
    COL_BUMP_WIDTH,
    COL_COULOMB_BAND,
    COL_COULOMB_N,
    COL_FRIC_ASYM,
    COL_LEAD_AMP,
    COL_LEAD_PERIOD,
    COL_LVDT_DELAY,
    COL_LVDT_DRIFT,
    COL_PER_AMP,
    COL_PER_CENTER,
    COL_PER_HALFWIDTH,
    COL_PER_PERIOD,
    COL_PER_PHASE,
    COL_STRIBECK_N,
    COL_STRIBECK_V,
    COL_VE_ALPHA,
    COL_VE_K,
    COL_VISCOUS,
)

__all__ = ["chain", "advance", "run_batch", "P_LEN", "X_LEN", "TR_N"]

# ---------------------------------------------------------------- parameter vector P (SI)
G_IM = 0  # i_total, rad/m
G_J = 1  # motor inertia, kg m^2
G_B = 2  # motor viscous, N m s/rad
G_TLIM = 3  # torque limit, N m
G_KP = 4  # N m/rad
G_KD = 5  # N m s/rad
G_KI = 6  # N m/(rad s)
G_MS = 7  # surface mass, kg
G_CS = 8  # surface damping, N s/m
G_KLOAD = 9  # load stiffness, N/m
G_XLIM = 10  # stroke limit, m
G_KSTOP = 11  # end-stop stiffness, N/m
G_H = 12  # substep, s
G_NSUB = 13  # substeps per sample
G_PERIOD = 14  # sample period, s
G_Q = 15  # resolver quantum, rad
G_N = 16
# per-EMA block, base G_N + e * E_N
E_BI = 0  # internal play, m
E_BB = 1  # bearing play, m
E_KC = 2  # internal compression stiffness, N/m
E_KT = 3  # internal tension stiffness, N/m
E_KB = 4  # bearing stiffness, N/m
E_KH = 5  # housing stiffness, N/m
E_GAIN = 6  # LVDT gain
E_OFF = 7  # LVDT offset, mm
E_NL = 8  # LVDT cubic term at full scale, mm
E_FS = 9  # LVDT full scale, mm
E_LSIG = 10  # LVDT noise std, mm
E_LCG = 11  # load cell gain
E_LCSIG = 12  # load cell noise std, N
E_N = 13
P_LEN = G_N + 2 * E_N

# ---------------------------------------------------------------- state vector X (SI)
S_K = 0  # samples done
S_Y = 1  # surface position, m
S_V = 2  # surface velocity, m/s
S_N = 3
SE_PHI = 0  # motor angle, rad
SE_W = 1  # motor speed, rad/s
SE_I = 2  # integral of the position error, rad s
SE_R = 3  # ram position, m
SE_H = 4  # housing position, m
SE_F = 5  # load-path force, N
SE_S = 6  # stroke r - h, m
SE_ZC = 7  # Maxwell dashpot state, compression flank, m
SE_ZT = 8  # Maxwell dashpot state, tension flank, m
SE_PT = 9  # previous POSITION target, rad
SE_PV = 10  # previous target valid (1.0) or not (0.0)
SE_T = 11  # drive torque of the last substep, N m
SE_TMAX = 12  # max |torque| over the last sample, N m
SE_N = 13
X_LEN = S_N + 2 * SE_N

# ---------------------------------------------------------------- truth record columns (batch)
TR_PHI, TR_W, TR_S, TR_F, TR_R, TR_H, TR_T, TR_TMAX = 0, 2, 4, 6, 8, 10, 12, 14
TR_Y, TR_V = 16, 17
TR_N = 18


@njit(cache=True)
def chain(xm, y, r_prev, zc, zt, bi, bb, kc, kt, kb, kh, kv):
    """Closed-form load path of one EMA (SI). Returns F, r, h, dmc, dmt."""
    u = xm - y
    kcv = kc + kv
    ktv = kt + kv
    dc0 = kv * zc / kcv  # free material deflection of the compression flank (>= 0)
    dt0 = kv * zt / ktv  # ... of the tension flank (<= 0)
    half = 0.5 * (bi + bb)
    ac = half + dc0
    at = -half + dt0
    if u > ac:
        f = (u - ac) / (1.0 / kh + 1.0 / kb + 1.0 / kcv)
        h = -f / kh
        r = y + f / kb + 0.5 * bb
        return f, r, h, (f + kv * zc) / kcv, dt0
    if u < at:
        f = (u - at) / (1.0 / kh + 1.0 / kb + 1.0 / ktv)
        h = -f / kh
        r = y + f / kb - 0.5 * bb
        return f, r, h, dc0, (f + kv * zt) / ktv
    lo = max(xm - 0.5 * bi - dc0, y - 0.5 * bb)
    hi = min(xm + 0.5 * bi - dt0, y + 0.5 * bb)
    r = min(max(r_prev, lo), hi)
    return 0.0, r, 0.0, dc0, dt0


@njit(cache=True)
def _solve_chains(X, P, E, dm):
    """Chain solve of both EMAs at the current positions; fills X[F, R, H, S] and dm."""
    im = P[G_IM]
    y = X[S_Y]
    for e in range(2):
        b = S_N + e * SE_N
        p = G_N + e * E_N
        xm = X[b + SE_PHI] / im
        kc = P[p + E_KC]
        kt = P[p + E_KT]
        if E[e, COL_BUMP_REL] > 0.0:
            g = 1.0 + E[e, COL_BUMP_REL] * math.exp(-((xm - E[e, COL_BUMP_CENTER]) / E[e, COL_BUMP_WIDTH]) ** 2)
            kc *= g
            kt *= g
        if E[e, COL_LEAD_AMP] > 0.0:
            xm += E[e, COL_LEAD_AMP] * math.sin(2.0 * math.pi * xm / E[e, COL_LEAD_PERIOD])
        f, r, h, dmc, dmt = chain(
            xm, y, X[b + SE_R], X[b + SE_ZC], X[b + SE_ZT],
            P[p + E_BI], P[p + E_BB], kc, kt, P[p + E_KB], P[p + E_KH],
            E[e, COL_VE_K],
        )
        X[b + SE_F] = f
        X[b + SE_R] = r
        X[b + SE_H] = h
        X[b + SE_S] = r - h
        dm[2 * e] = dmc
        dm[2 * e + 1] = dmt


@njit(cache=True)
def _kick(X, P, E, e, mode, val, wff, hk, implicit):
    """Half-kick of motor ``e`` over ``hk`` s.

    Velocity terms (drive D-gain, viscous losses, linearised friction) are
    explicit in the first half-kick and implicit in the second (together the
    trapezoidal rule). Uses the chain force stored in X (current positions)
    and the CSP integrator state; returns (torque, saturated).
    """
    b = S_N + e * SE_N
    if mode == 0:
        X[b + SE_W] = 0.0
        return 0.0, False
    im = P[G_IM]
    J = P[G_J]
    tlim = P[G_TLIM]
    kd = P[G_KD]
    phi = X[b + SE_PHI]
    w = X[b + SE_W]
    # explicit load torque: chain + end stop
    xm = phi / im
    fstop = 0.0
    if xm > P[G_XLIM]:
        fstop = P[G_KSTOP] * (xm - P[G_XLIM])
    elif xm < -P[G_XLIM]:
        fstop = P[G_KSTOP] * (xm + P[G_XLIM])
    # passive velocity terms (implicit): motor viscous, ram viscous, Coulomb (linearised)
    c_lin = P[G_B] + E[e, COL_VISCOUS] / (im * im)
    t_rest = -(X[b + SE_F] + fstop) / im
    if E[e, COL_PER_AMP] > 0.0:  # a force periodic in the ram's position, in the drive
        hw = E[e, COL_PER_HALFWIDTH]
        if hw <= 0.0 or abs(xm - E[e, COL_PER_CENTER]) <= hw:
            t_rest -= E[e, COL_PER_AMP] * math.cos(2.0 * math.pi * xm / E[e, COL_PER_PERIOD] + E[e, COL_PER_PHASE]) / im
    fc = E[e, COL_COULOMB_N]
    fs = E[e, COL_STRIBECK_N]
    fa = E[e, COL_FRIC_ASYM]
    if fc > 0.0 or fs > 0.0 or fa != 0.0:
        band = E[e, COL_COULOMB_BAND]
        v = w / im
        th = math.tanh(v / band)
        dth = (1.0 - th * th) / band
        level = fc + fa * th
        dlevel = fa * dth
        if fs > 0.0:
            vs = E[e, COL_STRIBECK_V]
            gs = math.exp(-(v / vs) ** 2)
            level += fs * gs
            dlevel -= 2.0 * fs * gs * v / (vs * vs)
        # linearised in the velocity; a falling (Stribeck) slope stays explicit
        dtf = max(level * dth + th * dlevel, 0.0) / (im * im)
        t_rest -= level * th / im - dtf * w
        c_lin += dtf
    sat = False
    if not implicit:
        # explicit: all terms at the current speed
        t_rest -= c_lin * w
        c_lin = 0.0
    if mode == 8:
        t_lin = P[G_KP] * (val - phi) + kd * wff + P[G_KI] * X[b + SE_I]
        if implicit:
            w_new = (J * w + hk * (t_lin + t_rest)) / (J + hk * (c_lin + kd))
            torque = t_lin - kd * w_new
        else:
            torque = t_lin - kd * w
        if torque > tlim or torque < -tlim:
            sat = True
            torque = tlim if torque > 0.0 else -tlim
            w_new = (J * w + hk * (torque + t_rest)) / (J + hk * c_lin)
        elif not implicit:
            w_new = w + hk * (torque + t_rest) / J
    else:
        torque = val / im
        if torque > tlim:
            torque = tlim
        elif torque < -tlim:
            torque = -tlim
        w_new = (J * w + hk * (torque + t_rest)) / (J + hk * c_lin)
    X[b + SE_W] = w_new
    X[b + SE_T] = torque
    if abs(torque) > X[b + SE_TMAX]:
        X[b + SE_TMAX] = abs(torque)
    return torque, sat


@njit(cache=True)
def _kick_surface(X, P, hk, load, implicit):
    fsum = X[S_N + SE_F] + X[S_N + SE_N + SE_F]
    ms = P[G_MS]
    if implicit:
        X[S_V] = (ms * X[S_V] + hk * (fsum - P[G_KLOAD] * X[S_Y] + load)) / (ms + hk * P[G_CS])
    else:
        X[S_V] += hk * (fsum - P[G_KLOAD] * X[S_Y] + load - P[G_CS] * X[S_V]) / ms


@njit(cache=True, inline="always")
def _feed_forward(X, e, mode, val, period):
    """Velocity feed-forward of drive ``e`` over this period (rad/s, held over it): the change of its
    POSITION target since the last period; outside POSITION mode its integrator is reset. Also
    restarts the period's peak torque."""
    b = S_N + e * SE_N
    wff = 0.0
    if mode == 8:
        if X[b + SE_PV] > 0.5:
            wff = (val - X[b + SE_PT]) / period
    else:
        X[b + SE_I] = 0.0
    X[b + SE_TMAX] = 0.0
    return wff


@njit(cache=True, inline="always")
def _remember_targets(X, mode1, val1, mode2, val2):
    """Drive memory for the next period's velocity feed-forward: the POSITION target, or none."""
    for e in range(2):
        b = S_N + e * SE_N
        mode = mode1 if e == 0 else mode2
        if mode == 8:
            X[b + SE_PT] = val1 if e == 0 else val2
            X[b + SE_PV] = 1.0
        else:
            X[b + SE_PV] = 0.0


@njit(cache=True, inline="always")
def _sensors(X, P, E, sbuf, n, t, noise, kn):
    """LVDT readings (mm; delayed by interpolation in ``sbuf``, gain drift, offset, cubic
    non-linearity, noise) and load-cell readings (N; gain, noise) of both EMAs at time ``t``:
    (s1, s2, F1, F2)."""
    h = P[G_H]
    smeas0 = 0.0
    smeas1 = 0.0
    fmeas0 = 0.0
    fmeas1 = 0.0
    for e in range(2):
        b = S_N + e * SE_N
        p = G_N + e * E_N
        delay = E[e, COL_LVDT_DELAY]
        if delay > 0.0:
            x = n - delay / h
            j0 = int(math.floor(x))
            if j0 >= n:
                s_true = sbuf[e, n]
            else:
                fr = x - j0
                s_true = sbuf[e, j0] * (1.0 - fr) + sbuf[e, j0 + 1] * fr
        else:
            s_true = X[b + SE_S]
        s_mm = s_true * 1e3
        gain = P[p + E_GAIN] * (1.0 + E[e, COL_LVDT_DRIFT] * t)
        rel = s_mm / P[p + E_FS]
        sm = P[p + E_OFF] + gain * s_mm + P[p + E_NL] * rel * rel * rel + P[p + E_LSIG] * noise[kn, e]
        fm = P[p + E_LCG] * X[b + SE_F] + P[p + E_LCSIG] * noise[kn, 2 + e]
        if e == 0:
            smeas0 = sm
            fmeas0 = fm
        else:
            smeas1 = sm
            fmeas1 = fm
    return smeas0, smeas1, fmeas0, fmeas1


@njit(cache=True)
def advance(X, P, E, sbuf, dm, mode1, val1, mode2, val2, load, noise, kn):
    """Advance one sample period in place; return the measured sample (t, phi1, phi2, s1, s2, F1, F2)
    (s, rad, rad, mm, mm, N, N): the drives' feed-forward, ``P[G_NSUB]`` substeps, the drives'
    memory, then the sensors (resolvers quantised to ``P[G_Q]``)."""
    h = P[G_H]
    hh = 0.5 * h
    n = int(P[G_NSUB])
    period = P[G_PERIOD]
    ki = P[G_KI]
    wff0 = _feed_forward(X, 0, mode1, val1, period)
    wff1 = _feed_forward(X, 1, mode2, val2, period)
    _solve_chains(X, P, E, dm)
    for j in range(n):  # substeps h: kick (h/2), drift (h), kick (h/2)
        sbuf[0, j] = X[S_N + SE_S]
        sbuf[1, j] = X[S_N + SE_N + SE_S]
        # Maxwell arms: exact exponential update with the deflection frozen over the substep
        for e in range(2):
            alpha = E[e, COL_VE_ALPHA]
            if alpha > 0.0:
                b = S_N + e * SE_N
                X[b + SE_ZC] += (dm[2 * e] - X[b + SE_ZC]) * alpha
                X[b + SE_ZT] += (dm[2 * e + 1] - X[b + SE_ZT]) * alpha
        # kick (h/2) with the forces at the current positions
        _, sat0 = _kick(X, P, E, 0, mode1, val1, wff0, hh, False)
        _, sat1 = _kick(X, P, E, 1, mode2, val2, wff1, hh, False)
        _kick_surface(X, P, hh, load, False)
        # drift (h), CSP integrator by the trapezoidal rule, conditional anti-windup
        for e in range(2):
            b = S_N + e * SE_N
            phi = X[b + SE_PHI]
            phin = phi + h * X[b + SE_W]
            X[b + SE_PHI] = phin
            mode = mode1 if e == 0 else mode2
            if mode == 8 and ki > 0.0:
                val = val1 if e == 0 else val2
                err = 0.5 * ((val - phi) + (val - phin))
                sat = sat0 if e == 0 else sat1
                if (not sat) or err * X[b + SE_T] < 0.0:
                    X[b + SE_I] += err * h
        X[S_Y] += h * X[S_V]
        # forces at the new positions, second kick (h/2)
        _solve_chains(X, P, E, dm)
        _kick(X, P, E, 0, mode1, val1, wff0, hh, True)
        _kick(X, P, E, 1, mode2, val2, wff1, hh, True)
        _kick_surface(X, P, hh, load, True)
    sbuf[0, n] = X[S_N + SE_S]
    sbuf[1, n] = X[S_N + SE_N + SE_S]
    k = X[S_K] + 1.0
    X[S_K] = k
    t = k * period
    _remember_targets(X, mode1, val1, mode2, val2)
    q = P[G_Q]
    phim0 = math.floor(X[S_N + SE_PHI] / q + 0.5) * q
    phim1 = math.floor(X[S_N + SE_N + SE_PHI] / q + 0.5) * q
    smeas0, smeas1, fmeas0, fmeas1 = _sensors(X, P, E, sbuf, n, t, noise, kn)
    return t, phim0, phim1, smeas0, smeas1, fmeas0, fmeas1


@njit(cache=True)
def run_batch(X, P, E, sbuf, dm, modes1, vals1, modes2, vals2, loads, noise, kn0, meas, truth, i0):
    """Batch of samples: rows i0.. of meas (n, 7) and truth (n, TR_N)."""
    m = modes1.shape[0]
    for i in range(m):
        out = advance(X, P, E, sbuf, dm, modes1[i], vals1[i], modes2[i], vals2[i], loads[i], noise, kn0 + i)
        row = i0 + i
        for c in range(7):
            meas[row, c] = out[c]
        for e in range(2):
            b = S_N + e * SE_N
            truth[row, TR_PHI + e] = X[b + SE_PHI]
            truth[row, TR_W + e] = X[b + SE_W]
            truth[row, TR_S + e] = X[b + SE_S] * 1e3
            truth[row, TR_F + e] = X[b + SE_F]
            truth[row, TR_R + e] = X[b + SE_R] * 1e3
            truth[row, TR_H + e] = X[b + SE_H] * 1e3
            truth[row, TR_T + e] = X[b + SE_T]
            truth[row, TR_TMAX + e] = X[b + SE_TMAX]
        truth[row, TR_Y] = X[S_Y] * 1e3
        truth[row, TR_V] = X[S_V] * 1e3
