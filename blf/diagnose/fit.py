"""The fitting machinery of the diagnosis (:mod:`blf.diagnose.engine`): the problem in the band, the nominal
fit, its linear re-adjustment (variable projection), candidate screening and refits, and the test of a
nominal parameter against its reference value.

Every residual is formed in the model's band (:class:`blf.diagnose.band.Band`): the raw residual
:math:`r = y - \\hat y` of a channel (zero where the channel is not compared) is low-passed and
decimated, and weighted by its noise floor in that band,
:math:`w_j = (B r)_j / (\\sigma_j \\|h\\|_2)`, with :math:`\\sigma` the white-noise floor of the raw
residual (:func:`blf.diagnose.mismatch.noise_floor`) and :math:`\\|h\\|_2` the band's noise gain.

Pure: arrays in, arrays out; the model is called, never changed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from blf.diagnose.band import Band
from blf.diagnose.mismatch import noise_floor
from blf.errors import BlfError

__all__ = ["Problem", "fit_nominal", "nominal_jacobian", "Projector", "screen", "CandidateFit", "fit_candidate",
           "ReferenceTest", "reference_test", "JointFit", "fit_joint", "safe_predict"]


@dataclass(frozen=True)
class CandidateFit:
    """One candidate refitted with the nominal re-adjusted linearly (:func:`fit_candidate`).

    Attributes
    ----------
    x, uncertainty : ndarray, shape (k,)
        The candidate's parameters and their standard uncertainties, in its parameters' units.
    nominal_step : ndarray, shape (len(nominal),)
        The linear re-adjustment of the nominal parameters, in units of their ``scale``.
    chi2_fit, chi2_holdout : float
        Chi-square on the fit half and on the held-out half after the re-adjustment (linearised).
    """

    x: np.ndarray
    uncertainty: np.ndarray
    nominal_step: np.ndarray
    chi2_fit: float
    chi2_holdout: float


@dataclass(frozen=True)
class JointFit:
    """The nominal parameters and one candidate evaluated on the exact replay (:func:`fit_joint`, or the
    linearised step of a :class:`CandidateFit` applied).

    Attributes
    ----------
    theta : ndarray, shape (len(nominal),)
        Nominal parameters, in their units.
    x, uncertainty : ndarray, shape (k,)
        The candidate's parameters and their standard uncertainties.
    chi2_fit, chi2_holdout : float
        Chi-square on the fit half and on the held-out half.
    """

    theta: np.ndarray
    x: np.ndarray
    uncertainty: np.ndarray
    chi2_fit: float
    chi2_holdout: float


@dataclass(frozen=True)
class ReferenceTest:
    """What holding one nominal parameter at its reference value costs (:func:`reference_test`).

    Attributes
    ----------
    delta_chi2_fit, delta_chi2_holdout : float
        Chi-square increase on the fit half and on the held-out half, the other nominal
        parameters re-adjusted linearly.
    uncertainty : float
        Standard uncertainty of the parameter (all nominal parameters free), in its unit.
    """

    delta_chi2_fit: float
    delta_chi2_holdout: float
    uncertainty: float


def safe_predict(model, theta: np.ndarray, active: list) -> dict | None:
    """The model's prediction, or None if the parameters are outside what its physics accepts."""
    try:
        pred = model.predict(theta, active)
    except (BlfError, ValueError, FloatingPointError, ZeroDivisionError):
        return None
    if not all(np.all(np.isfinite(pred[c])) for c in model.channels):
        return None
    return pred


class Problem:
    """The recording in the model's band: kept samples, halves, validity and noise floors."""

    def __init__(self, model, cfg, period_s: float, band: Band, extra_valid: dict | None = None) -> None:
        self.m = model
        self.cfg = cfg
        self.T = period_s
        self.band = band
        t = model.t_s
        n = t.size
        self.idx = band.indices(n)
        rel = (t - t[0]) / cfg.block_s
        blk = np.floor(rel).astype(np.int64)
        self.block_raw = blk
        self.fit_raw = blk % 2 == 0
        self.block = blk[self.idx]
        self.fit = self.fit_raw[self.idx]
        if band.cutoff_hz is not None:
            g = 0.5 / band.cutoff_hz / cfg.block_s  # guard at the halves' boundaries, in blocks
            frac = rel[self.idx] - self.block
            near = (frac < g) | (frac > 1.0 - g)
        else:
            near = np.zeros(self.idx.size, bool)
        self.valid_raw = dict(model.valid, **(extra_valid or {}))
        self.valid = {c: band.keep(v) & ~near for c, v in self.valid_raw.items()}
        self.sig_raw = {c: np.ones(n) for c in self.valid_raw}
        self.sig = {c: np.ones(self.idx.size) for c in self.valid_raw}
        self.win = max(5, int(round(cfg.noise_window_s / period_s)))
        self._memo: dict = {}
        self.nfit = sum(int((self.valid[c] & self.fit).sum()) for c in model.channels)

    def residual(self, c: str, meas: np.ndarray, pred: np.ndarray) -> np.ndarray:
        """Band residual of channel ``c`` at the kept samples (not weighted)."""
        v = self.valid_raw[c]
        if not self.valid[c].any():
            return np.zeros(self.idx.size)
        key = (c, id(meas), hash(np.ascontiguousarray(pred).tobytes()))
        out = self._memo.get(key)
        if out is None:
            out = self.band.reduce(np.where(v, meas - pred, 0.0))
            if len(self._memo) > 400:
                self._memo.clear()
            self._memo[key] = out
        return out

    def set_floor(self, meas: dict, pred: dict, channels=None) -> None:
        """Noise floors of the raw residuals and, scaled by the band's noise gain, in the band."""
        for c in channels or self.m.channels:
            v = self.valid_raw[c]
            self.sig_raw[c] = noise_floor(np.where(v, meas[c] - pred[c], 0.0), v, self.win)
            self.sig[c] = self.sig_raw[c][self.idx] * self.band.noise_gain

    def weighted(self, pred: dict, meas: dict | None = None, channels=None) -> dict:
        meas = meas or self.m.measured
        out = {}
        for c in channels or self.m.channels:
            r = self.residual(c, meas[c], pred[c])
            out[c] = np.where(self.valid[c], r / self.sig[c], 0.0)
        return out

    def vec(self, w: dict, part: np.ndarray) -> np.ndarray:
        return np.concatenate([w[c][self.valid[c] & part] for c in self.m.channels])

    def chi2(self, w: dict, part: np.ndarray) -> float:
        v = self.vec(w, part)
        return float(v @ v)


def _bounds(params) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    sc = np.array([q.scale for q in params], dtype=float)
    x0 = np.array([q.x0 for q in params], dtype=float) / sc
    lo = np.array([q.lo for q in params], dtype=float) / sc
    hi = np.array([q.hi for q in params], dtype=float) / sc
    return sc, np.clip(x0, lo, hi), lo, hi


def clip_nominal(model, theta: np.ndarray) -> np.ndarray:
    lo = np.array([q.lo for q in model.nominal], dtype=float)
    hi = np.array([q.hi for q in model.nominal], dtype=float)
    return np.clip(theta, lo, hi)


def fit_nominal(p: Problem, theta0: np.ndarray | None = None, max_nfev: int = 30) -> np.ndarray:
    """Nonlinear least squares of the nominal parameters on the fit half (bounded, scaled)."""
    sc, x0, lo, hi = _bounds(p.m.nominal)
    if theta0 is not None:
        x0 = np.clip(np.asarray(theta0, dtype=float) / sc, lo, hi)
    bad = None

    def fun(x):
        nonlocal bad
        pred = safe_predict(p.m, x * sc, [])
        if pred is None:
            if bad is None:
                bad = np.full(p.nfit, 1e3)
            return bad
        v = p.vec(p.weighted(pred), p.fit)
        if bad is None:
            bad = np.full(v.size, 1e3)
        return v

    sol = least_squares(fun, x0, bounds=(lo, hi), diff_step=1e-4, x_scale=1.0, max_nfev=max_nfev,
                        ftol=1e-4, xtol=1e-4, method="trf")
    return np.clip(sol.x, lo, hi) * sc


def nominal_jacobian(p: Problem, theta: np.ndarray, active: list, base: dict) -> dict:
    """Per-channel Jacobian of the weighted band residual w.r.t. the scaled nominal parameters."""
    cols = []
    for j, q in enumerate(p.m.nominal):
        th = theta.copy()
        step = 1e-3 * q.scale
        if th[j] + step > q.hi:
            step = -step
        th[j] += step
        pred = safe_predict(p.m, th, active)
        if pred is None:
            cols.append({c: np.zeros_like(base[c]) for c in p.m.channels})
            continue
        wp = p.weighted(pred)
        cols.append({c: (wp[c] - base[c]) / (step / q.scale) for c in p.m.channels})
    return {c: np.stack([col[c] for col in cols], axis=1) for c in p.m.channels}


class Projector:
    """Linear re-adjustment of the nominal parameters (variable projection), optionally without some."""

    def __init__(self, p: Problem, Jn: dict, drop: tuple = ()) -> None:
        keep = [j for j in range(len(p.m.nominal)) if j not in drop]
        self.p = p
        self.keep = keep
        self.Jfit = np.concatenate([Jn[c][p.valid[c] & p.fit][:, keep] for c in p.m.channels])
        self.Jval = np.concatenate([Jn[c][p.valid[c] & ~p.fit][:, keep] for c in p.m.channels])
        self.Q, self.R = np.linalg.qr(self.Jfit)
        d = np.abs(np.diag(self.R))
        self.ok = d > 1e-9 * max(float(d.max()) if d.size else 1.0, 1e-300)

    def solve(self, w: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(step of the scaled nominal parameters, fit-half residual, held-out residual) after re-adjustment."""
        rf = self.p.vec(w, self.p.fit)
        rv = self.p.vec(w, ~self.p.fit)
        beta = np.linalg.lstsq(self.R, self.Q.T @ rf, rcond=1e-10)[0]
        full = np.zeros(len(self.p.m.nominal))
        full[self.keep] = -beta  # w(x + b) ~ w + J b: the step that minimises |w + J b|
        return full, rf - self.Jfit @ beta, rv - self.Jval @ beta


def screen(p: Problem, proj: Projector, theta: np.ndarray, active: list, cand, rf_b: np.ndarray, wb: np.ndarray):
    """Linearised chi-square a candidate removes on the fit half, and the samples it acts on.

    ``wb`` is the fit-half weighted residual without the candidate (before re-adjustment). A
    one-parameter term is linearised from zero (its signature at the start value), one with more
    parameters about its start values. Returns (reduction, number of kept samples it changes) or
    None if its replay fails."""
    x0 = np.array([q.x0 for q in cand.params], dtype=float)
    base = safe_predict(p.m, theta, active + [(cand, x0)])
    if base is None:
        return None
    wc = p.vec(p.weighted(base), p.fit)
    if x0.size == 1:
        cols = [(wb - wc) / (x0[0] or 1.0)]
    else:
        cols = []
        for j, q in enumerate(cand.params):
            x2 = x0.copy()
            x2[j] = 0.5 * x0[j] if x0[j] != 0 else q.scale
            pr = safe_predict(p.m, theta, active + [(cand, x2)])
            if pr is None:
                return None
            cols.append((wc - p.vec(p.weighted(pr), p.fit)) / ((x0[j] - x2[j]) or 1.0))
    A = np.stack(cols, axis=1)
    amax = float(np.max(np.abs(A))) if A.size else 0.0
    n_eff = int(np.count_nonzero(np.any(np.abs(A) > 1e-6 * amax, axis=1))) if amax > 0 else 2
    A = A - proj.Q @ (proj.Q.T @ A)
    coef, *_ = np.linalg.lstsq(A, rf_b, rcond=None)
    r = rf_b - A @ coef
    return float(rf_b @ rf_b - r @ r), n_eff


def fit_candidate(p: Problem, proj: Projector, theta: np.ndarray, active: list, cand) -> CandidateFit | None:
    """Refit one candidate (nonlinear in its parameters, nominal re-adjusted linearly); None if its
    replay fails."""
    sc, x0, lo, hi = _bounds(cand.params)
    fail = None

    def resid(x):
        pred = safe_predict(p.m, theta, active + [(cand, x * sc)])
        if pred is None:
            return None
        return proj.solve(p.weighted(pred))

    def fun(x):
        nonlocal fail
        out = resid(x)
        if out is None:
            return fail
        if fail is None:
            fail = np.full(out[1].size, 1e3)
        return out[1]

    if resid(x0) is None:
        return None
    best = None
    starts = [x0]
    if np.all(np.isfinite(lo)) and np.all(lo < 0) and np.all(hi > 0):
        starts.append(np.clip(-x0, lo, hi))
    for s in starts:
        try:
            sol = least_squares(fun, s, bounds=(lo, hi), diff_step=1e-3, max_nfev=15, method="trf",
                                ftol=1e-5, xtol=1e-5)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        return None
    x = np.clip(best.x, lo, hi)
    out = resid(x)
    if out is None:
        return None
    beta, rf, rv = out
    J = np.concatenate([best.jac, proj.Jfit], axis=1)
    dof = max(rf.size - J.shape[1], 1)
    s2 = float(rf @ rf) / dof
    try:
        cov = np.linalg.pinv(J.T @ J) * max(s2, 1.0)
        unc = np.sqrt(np.maximum(np.diag(cov)[: x.size], 0.0)) * sc
    except np.linalg.LinAlgError:
        unc = np.full(x.size, np.nan)
    return CandidateFit(x * sc, unc, beta, float(rf @ rf), float(rv @ rv))


def reference_test(p: Problem, theta: np.ndarray, active: list, Jn: dict, j: int, ref: float,
                   chi_fit: float, chi_val: float) -> ReferenceTest | None:
    """Chi-square increase on each half when nominal parameter ``j`` is held at ``ref``.

    The other nominal parameters are re-adjusted linearly. None if the replay fails there."""
    q = p.m.nominal[j]
    th = theta.copy()
    th[j] = min(max(ref, q.lo), q.hi)
    pred = safe_predict(p.m, th, active)
    if pred is None:
        return None
    proj = Projector(p, Jn, drop=(j,))
    _, rf, rv = proj.solve(p.weighted(pred))
    full = Projector(p, Jn)
    # standard uncertainty of parameter j from the fit half's Jacobian (all nominal parameters free)
    try:
        Rinv = np.linalg.pinv(full.R)
        sd = float(np.sqrt(np.sum(Rinv[j] ** 2))) * q.scale
    except np.linalg.LinAlgError:
        sd = float("nan")
    return ReferenceTest(float(rf @ rf) - chi_fit, float(rv @ rv) - chi_val, sd)


def fit_joint(p: Problem, theta: np.ndarray, active: list, cand, x: np.ndarray,
              max_nfev: int = 8, free: np.ndarray | None = None) -> JointFit | None:
    """Nonlinear refit of the nominal parameters and one candidate together, from (theta, x); None if
    the replay fails. ``free`` (bool per candidate parameter, default all): the others are held at ``x``
    (their uncertainty 0)."""
    sn, _, lon, hin = _bounds(p.m.nominal)
    sc_all, _, loc_all, hic_all = _bounds(cand.params)
    free = np.ones(sc_all.size, bool) if free is None else np.asarray(free, bool)
    x_all = np.clip(np.asarray(x, dtype=float) / sc_all, loc_all, hic_all)
    sc, loc, hic = sc_all[free], loc_all[free], hic_all[free]
    k = sn.size
    z0 = np.r_[np.clip(theta / sn, lon, hin), x_all[free]]
    lo, hi = np.r_[lon, loc], np.r_[hin, hic]
    fail = None

    def cand_x(zc):
        out = x_all.copy()
        out[free] = zc
        return out * sc_all

    def pred_of(z):
        return safe_predict(p.m, z[:k] * sn, active + [(cand, cand_x(z[k:]))])

    def fun(z):
        nonlocal fail
        pr = pred_of(z)
        if pr is None:
            return fail
        v = p.vec(p.weighted(pr), p.fit)
        if fail is None:
            fail = np.full(v.size, 1e3)
        return v

    if pred_of(z0) is None:
        return None
    try:
        sol = least_squares(fun, z0, bounds=(lo, hi), diff_step=1e-4, max_nfev=max_nfev, method="trf",
                            ftol=1e-4, xtol=1e-4)
    except (ValueError, np.linalg.LinAlgError):
        return None
    z = np.clip(sol.x, lo, hi)
    pr = pred_of(z)
    if pr is None:
        return None
    w = p.weighted(pr)
    rf, rv = p.vec(w, p.fit), p.vec(w, ~p.fit)
    J = sol.jac
    unc = np.zeros(sc_all.size)
    try:
        cov = np.linalg.pinv(J.T @ J) * max(float(rf @ rf) / max(rf.size - J.shape[1], 1), 1.0)
        unc[free] = np.sqrt(np.maximum(np.diag(cov)[k:], 0.0)) * sc
    except np.linalg.LinAlgError:
        unc[free] = np.nan
    return JointFit(z[:k] * sn, cand_x(z[k:]), unc, float(rf @ rf), float(rv @ rv))
