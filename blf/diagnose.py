"""Sim versus recording: localise the mismatch, name the missing physics, fit it.

Pure core: a replay model (arrays in, predicted channels out) and an explicit
sample period in, a frozen :class:`Diagnosis` out; no plotting or file IO.

Method
------
1. **Nominal fit.** The model's nominal parameters are fitted by nonlinear
   least squares (scipy ``least_squares``) on the *fit* half of the recording
   (alternate blocks of ``block_s``; the other half is held out).
2. **Noise floor.** Per channel and sample, from the second differences of
   the nominal residual (rolling RMS over ``noise_window_s``,
   :math:`\\sigma = \\mathrm{rms}(\\Delta^2 r)/\\sqrt 6`): white measurement
   noise passes, slow model error does not. Residuals are weighted by it.
   A channel valid only on a coarser grid (block means) is handled on that
   grid, over at least 31 of its values.
3. **Significance.** Per channel, the weighted residual is averaged over
   windows of ``window_s``; under "noise only" the window scores
   :math:`z_b = \\sum w_i/\\sqrt{n_b}` are standard normal. The channel differs
   when :math:`\\sum z_b^2/n_b` exceeds ``excess_threshold``; windows with
   :math:`|z_b| > 4` are the locations, described by the operating regime
   where their residual concentrates.
   A second test looks for a mismatch spread thinly along the recording but
   tied to the operating regime (a stiffness that changes along the stroke):
   samples are grouped in cells (stroke-position quantiles x sign of velocity
   x sign of force), and the cell sums of the weighted residual are formed
   separately on the fit and the held-out half,
   :math:`z_{f,b} = \\sum_{fit} w_i / \\sqrt{\\phi n_{f,b}}` (likewise
   :math:`z_{h,b}`). The regime score
   :math:`S = \\sum_b z_{f,b} z_{h,b} / \\sqrt{B}` is about standard normal
   under noise only (the halves are independent) and grows with a mismatch
   that repeats wherever the regime repeats. :math:`\\phi` is the
   over-dispersion of the per-block cell sums around their cell mean
   (correlated noise and imperfect weights widen it, a repeated mismatch
   does not), so the score does not depend on the noise floor being exact,
   which the window test does. A channel differs when S exceeds
   ``regime_threshold``; the cells with the largest products are located.
4. **Screening.** Each candidate effect (a switchable physics term of the
   model) is linearised by finite differences of replays; the chi-square it
   removes together with the re-adjusted nominal parameters (their Jacobian
   is projected out) ranks it, penalised by BIC per parameter with the
   number of observations the term acts on (a drive-force term touches only
   the FORCE-mode blocks, not every sample of every channel).
5. **Refit and acceptance.** The best candidates are refitted (candidate
   parameters nonlinear, nominal parameters re-adjusted linearly, i.e.
   variable projection); one is accepted only if its BIC improves by more
   than ``bic_margin`` on the fit half *and* its chi-square improves by more
   than ``holdout_margin`` on the held-out half. Forward selection, up to
   ``max_effects``: it goes on while a candidate passes both tests, also
   after the window test stops flagging (a second effect can hide below it
   and still be significant over the whole recording).
6. **Verdict.** ``no_mismatch`` if no channel differs after the nominal fit
   and no candidate is accepted (a concealed effect below the window test
   can still be found by the chi-square of the whole recording);
   ``explained`` if effects were accepted, no channel differs any more (by
   either test) and every channel that differed lost at least
   ``min_explained_fraction`` of its excess over 1 and of its regime score
   (an effect that only nudges a channel under the threshold has not
   explained it);
   ``unexplained`` otherwise (the accepted effects are then reported as
   partial, and the locations still stand).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
from scipy.optimize import least_squares

from blf.mismatch import RegimeScore, excess, noise_floor, regime_cells, regime_score, regime_words, window_scores  # noqa: F401
from blf.validate import positive_scalar

__all__ = ["Param", "Candidate", "ReplayModel", "DiagnoseConfig", "Location", "FittedEffect",
           "Diagnosis", "diagnose"]


@dataclass(frozen=True)
class Param:
    """One fitted parameter: name (with unit), start value, scale, bounds."""

    name: str
    x0: float
    scale: float
    lo: float = -np.inf
    hi: float = np.inf


@dataclass(frozen=True)
class Candidate:
    """A candidate physics term: machine name, place, engineer's words, parameters."""

    name: str
    where: str
    words: str
    params: tuple


class ReplayModel(Protocol):
    """What :func:`diagnose` needs from a model of the recording."""

    t_s: np.ndarray
    channels: tuple
    measured: dict  #: channel -> ndarray (n,)
    valid: dict  #: channel -> bool ndarray (n,), samples where the channel is modelled
    nominal: tuple  #: of Param
    candidates: tuple  #: of Candidate
    regimes: dict  #: regime variable name -> ndarray (n,)

    def predict(self, theta: np.ndarray, active: list) -> dict: ...

    # Optional: ``derived(channels) -> {name: ndarray}`` and ``derived_valid`` ({name: bool
    # ndarray}): signals computed from the channels (e.g. the paper's D signals), reported
    # (excess, locations, RMS) but not fitted, so nothing is counted twice.


@dataclass(frozen=True)
class DiagnoseConfig:
    """Tuning of :func:`diagnose` (seconds, chi-square units)."""

    block_s: float = 2.0
    window_s: float = 1.0
    noise_window_s: float = 0.2
    excess_threshold: float = 3.0
    bic_margin: float = 10.0
    holdout_margin: float = 10.0
    max_effects: int = 2
    refit_top: int = 3
    min_explained_fraction: float = 0.5  #: of each flagged channel's excess above 1, for "explained"
    regime_bins: int = 10  #: position bins of the regime test (x 2 velocity signs x 2 force signs)
    regime_threshold: float = 5.0  #: regime score S above which a channel differs (S ~ N(0, 1) under noise)


@dataclass(frozen=True)
class Location:
    channel: str
    t_start_s: float
    t_end_s: float
    regime: str
    score: float
    test: str = "window"  #: "window" (a time window) or "regime" (a regime cell, first to last visit)


@dataclass(frozen=True)
class FittedEffect:
    name: str
    where: str
    words: str
    parameters: dict
    uncertainty: dict
    delta_bic: float
    delta_chi2_holdout: float
    evidence: str


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (plain dicts inside: JSON-ready, treat as read-only)."""

    verdict: str
    effects: tuple
    partial_effects: tuple
    locations: tuple
    residual_rms_before: dict
    residual_rms_after: dict
    residual_rms_holdout_before: dict  #: on the held-out half only (never fitted)
    residual_rms_holdout_after: dict
    noise_floor: dict
    excess_before: dict
    excess_after: dict
    ic_before: float
    ic_after: float
    nominal: dict
    screening: tuple
    predicted_before: dict = field(repr=False)
    predicted_after: dict = field(repr=False)
    measured: dict = field(repr=False, default_factory=dict)  #: all reported channels, derived included
    valid: dict = field(repr=False, default_factory=dict)
    held_out: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, bool))  #: samples never fitted
    regime_cells_before: dict = field(repr=False, default_factory=dict)  #: channel -> RegimeScore (step 3)
    regime_cells_after: dict = field(repr=False, default_factory=dict)
    regime_labels: tuple = ()  #: description of each cell

    @property
    def regime_before(self) -> dict:
        """Regime-test score S per channel after the nominal fit."""
        return {c: r.score for c, r in self.regime_cells_before.items()}

    @property
    def regime_after(self) -> dict:
        """Regime-test score S per channel with the accepted effects."""
        return {c: r.score for c, r in self.regime_cells_after.items()}


# ------------------------------------------------------------------ core


class _Problem:
    def __init__(self, model: ReplayModel, cfg: DiagnoseConfig, period_s: float) -> None:
        self.m = model
        self.cfg = cfg
        self.T = period_s
        n = model.t_s.size
        blk = max(1, int(round(cfg.block_s / period_s)))
        self.block = np.arange(n) // blk
        self.fit_mask = (self.block % 2) == 0
        self.sig = {c: np.ones(n) for c in model.channels}
        self.nfit = sum(int((model.valid[c] & self.fit_mask).sum()) for c in model.channels)

    def weighted(self, pred: dict) -> dict:
        return {c: np.where(self.m.valid[c], (self.m.measured[c] - pred[c]) / self.sig[c], 0.0)
                for c in self.m.channels}

    def vec(self, w: dict, part: np.ndarray) -> np.ndarray:
        return np.concatenate([w[c][self.m.valid[c] & part] for c in self.m.channels])

    def chi2(self, w: dict, part: np.ndarray) -> float:
        v = self.vec(w, part)
        return float(v @ v)


def _fit_nominal(p: _Problem) -> np.ndarray:
    nom = p.m.nominal
    x0 = np.array([q.x0 / q.scale for q in nom])
    lo = np.array([q.lo / q.scale for q in nom])
    hi = np.array([q.hi / q.scale for q in nom])
    sc = np.array([q.scale for q in nom])

    def fun(x):
        return p.vec(p.weighted(p.m.predict(x * sc, [])), p.fit_mask)

    sol = least_squares(fun, np.clip(x0, lo, hi), bounds=(lo, hi), diff_step=1e-4, x_scale=1.0,
                        max_nfev=40, ftol=1e-6, xtol=1e-6, method="trf")
    return sol.x * sc


def _nominal_jacobian(p: _Problem, theta: np.ndarray, active: list, base: dict) -> dict:
    """Per-channel Jacobian of the weighted residual w.r.t. the scaled nominal parameters."""
    cols = []
    for j, q in enumerate(p.m.nominal):
        th = theta.copy()
        th[j] += 1e-3 * q.scale
        wp = p.weighted(p.m.predict(th, active))
        cols.append({c: (wp[c] - base[c]) / 1e-3 for c in p.m.channels})
    return {c: np.stack([col[c] for col in cols], axis=1) for c in p.m.channels}


class _Projector:
    """Linear re-adjustment of the nominal parameters (variable projection)."""

    def __init__(self, p: _Problem, Jn: dict) -> None:
        self.p = p
        self.Jfit = np.concatenate([Jn[c][p.m.valid[c] & p.fit_mask] for c in p.m.channels])
        self.Jval = np.concatenate([Jn[c][p.m.valid[c] & ~p.fit_mask] for c in p.m.channels])
        self.Jall = Jn
        self.Q, self.R = np.linalg.qr(self.Jfit)

    def solve(self, w: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rf = self.p.vec(w, self.p.fit_mask)
        rv = self.p.vec(w, ~self.p.fit_mask)
        beta = np.linalg.lstsq(self.R, self.Q.T @ rf, rcond=None)[0]
        # w = meas - pred; adding J beta to pred (J = dw/dx) gives w + J beta ... sign: w(x+b) ~ w + J b
        # minimise |w + J b|: b = -lstsq(J, w)
        return -beta, rf - self.Jfit @ beta, rv - self.Jval @ beta


def _eval_candidate(p: _Problem, proj: _Projector, theta: np.ndarray, cand: Candidate,
                    xc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = p.weighted(p.m.predict(theta, [(cand, xc)]))
    return proj.solve(w)


def _fit_candidate(p: _Problem, proj: _Projector, theta: np.ndarray, active: list, cand: Candidate):
    sc = np.array([q.scale for q in cand.params])
    x0 = np.array([q.x0 for q in cand.params]) / sc
    lo = np.array([q.lo for q in cand.params]) / sc
    hi = np.array([q.hi for q in cand.params]) / sc

    def resid(x):
        w = p.weighted(p.m.predict(theta, active + [(cand, x * sc)]))
        return proj.solve(w)

    def fun(x):
        return resid(x)[1]

    best = None
    starts = [np.clip(x0, lo, hi)]
    if np.all(np.isfinite(lo)) and np.all(lo < 0) and np.all(hi > 0):
        starts.append(np.clip(-x0, lo, hi))
    for s in starts:
        sol = least_squares(fun, s, bounds=(lo, hi), diff_step=1e-3, max_nfev=40, method="trf")
        if best is None or sol.cost < best.cost:
            best = sol
    x = best.x
    beta, rf, rv = resid(x)
    # uncertainty: candidate columns together with the nominal ones
    J = np.concatenate([best.jac, proj.Jfit], axis=1)
    dof = max(rf.size - J.shape[1], 1)
    s2 = float(rf @ rf) / dof
    try:
        cov = np.linalg.pinv(J.T @ J) * max(s2, 1.0)
        unc = np.sqrt(np.maximum(np.diag(cov)[: x.size], 0.0)) * sc
    except np.linalg.LinAlgError:
        unc = np.full(x.size, np.nan)
    return x * sc, unc, beta, float(rf @ rf), float(rv @ rv)


def diagnose(model: ReplayModel, sample_period_s: float, config: DiagnoseConfig | None = None,
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose the mismatch between a replay model and its recording.

    Parameters
    ----------
    model : ReplayModel
        Recording and replay (e.g. :class:`sim.replay.DualEmaReplay`,
        :class:`sim.single_axis.SingleAxisReplay`).
    sample_period_s : float
        Sample period of the recording, s (> 0).
    config : DiagnoseConfig, optional
    progress : callable, optional
        Called with a short text at each stage (the shell may print it).

    Returns
    -------
    Diagnosis

    Notes
    -----
    Information criterion (Gaussian, noise floor known):
    :math:`\\mathrm{BIC} = \\chi^2 + k_0 \\ln N + \\sum_j k_j \\ln N_j` with
    :math:`\\chi^2 = \\sum (r/\\sigma)^2` over the fit half, :math:`k_0` nominal
    parameters over all :math:`N` fitted samples and :math:`k_j` parameters
    of accepted effect j over the :math:`N_j` samples that effect changes.
    See the module docstring for the steps.
    """
    cfg = config or DiagnoseConfig()
    positive_scalar(sample_period_s, "sample_period_s", "s")
    say = progress or (lambda s: None)
    p = _Problem(model, cfg, sample_period_s)
    win = max(5, int(round(cfg.noise_window_s / sample_period_s)))

    def set_floor(pred):
        for c in model.channels:
            r = np.where(model.valid[c], model.measured[c] - pred[c], 0.0)
            p.sig[c] = noise_floor(r, model.valid[c], win)

    say("nominal fit")
    set_floor(model.predict(np.array([q.x0 for q in model.nominal]), []))
    theta = _fit_nominal(p)
    pred0 = model.predict(theta, [])
    set_floor(pred0)
    w0 = p.weighted(pred0)
    nwin = max(2, int(round(cfg.window_s / sample_period_s)))
    k_nom = len(model.nominal)
    lnN = float(np.log(max(p.nfit, 2)))
    ic0 = p.chi2(w0, p.fit_mask) + k_nom * lnN
    # reported channels: the model's and its derived signals (not fitted)
    derive = getattr(model, "derived", None)

    def full(pred):
        return {**pred, **derive(pred)} if derive else dict(pred)

    meas = full(model.measured)
    valid = {**model.valid, **(model.derived_valid if derive else {})}
    sig = dict(p.sig)
    pred0_all = full(pred0)
    for c in meas:
        if c not in p.sig:
            sig[c] = noise_floor(np.where(valid[c], meas[c] - pred0_all[c], 0.0), valid[c], win)

    def wall(pred_all):
        return {c: np.where(valid[c], (meas[c] - pred_all[c]) / sig[c], 0.0) for c in meas}

    def excess_all(w):
        return {c: excess(window_scores(w[c], valid[c], nwin)[0]) for c in meas}

    w0_all = wall(pred0_all)
    excess0 = excess_all(w0_all)
    # a cell chosen by the sign of a measured force would pick that channel's noise (its cell
    # means would be biased by selection): force regimes of fitted channels use the nominal model
    cell_regimes = {k: (pred0[k.split()[-1]] if k.startswith("force ") and k.split()[-1] in pred0 else x)
                    for k, x in model.regimes.items()}
    cells, cell_labels = regime_cells(cell_regimes, cfg.regime_bins)

    def regime_all(w):
        return {c: regime_score(w[c], valid[c], p.fit_mask, p.block, cells, len(cell_labels)) for c in meas}

    rs0 = regime_all(w0_all)
    regime0 = {c: r.score for c, r in rs0.items()}

    def locate_regime(pred_all, rs):
        """The cells that carry the regime score of each flagged fitted channel."""
        locs = []
        for c in model.channels:
            if rs[c].score <= cfg.regime_threshold:
                continue
            prod = rs[c].products
            r = meas[c] - pred_all[c]
            for b in np.argsort(-np.nan_to_num(prod, nan=-np.inf))[:3]:
                sel = np.flatnonzero(valid[c] & (cells == b))
                if not np.isfinite(prod[b]) or prod[b] < 4.0 or sel.size == 0:
                    continue
                locs.append(Location(c, float(model.t_s[sel[0]]), float(model.t_s[sel[-1]]),
                                     f"{cell_labels[b]} (mean residual {r[sel].mean():+.3g}, "
                                     f"repeated in fit and held-out halves)", float(prod[b]), "regime"))
        return locs

    floor = {c: float(np.sqrt(np.mean(sig[c][valid[c]] ** 2))) if valid[c].any() else None for c in meas}

    def rms(pred_all, part=None):
        out = {}
        for c in meas:
            sel = valid[c] if part is None else valid[c] & part
            out[c] = float(np.sqrt(np.mean((meas[c] - pred_all[c])[sel] ** 2))) if sel.any() else None
        return out

    def locate(pred_all, w):
        locs = []
        for c in meas:
            z, starts = window_scores(w[c], valid[c], nwin)
            bad = np.where(np.abs(np.nan_to_num(z)) > 4.0)[0]
            if bad.size == 0 or excess(z) <= cfg.excess_threshold:
                continue
            # merge consecutive windows
            groups = np.split(bad, np.where(np.diff(bad) > 1)[0] + 1)
            groups.sort(key=lambda g: -float(np.sum(z[g] ** 2)))
            for g in groups[:5]:
                i0, i1 = starts[g[0]], min(starts[g[-1]] + nwin, model.t_s.size)
                idx = np.arange(i0, i1)
                idx = idx[valid[c][idx]]
                r = meas[c] - pred_all[c]
                locs.append(Location(c, float(model.t_s[i0]), float(model.t_s[i1 - 1]),
                                     regime_words(idx, r, model.regimes), float(np.sum(z[g] ** 2))))
        return locs

    pred_cur = pred0
    locations = locate(pred0_all, w0_all) + locate_regime(pred0_all, rs0)
    flag_r0 = [c for c in model.channels if regime0[c] > cfg.regime_threshold]
    significant = any(excess0[c] > cfg.excess_threshold for c in model.channels) or bool(flag_r0)
    say("excess over noise: " + ", ".join(f"{c} {v:.2f}" for c, v in excess0.items()))
    say("regime score: " + ", ".join(f"{c} {v:.1f}" for c, v in regime0.items()))

    active: list = []
    accepted: list[FittedEffect] = []
    screening_log: list = []
    chi_fit_cur = p.chi2(w0, p.fit_mask)
    chi_val_cur = p.chi2(w0, ~p.fit_mask)
    ic_cur = ic0
    pen_cur = k_nom * lnN
    excess_cur = excess0
    for _round in range(cfg.max_effects):
        base_pred = model.predict(theta, active)
        wb = p.weighted(base_pred)
        Jn = _nominal_jacobian(p, theta, active, wb)
        proj = _Projector(p, Jn)
        _, rf_b, rv_b = proj.solve(wb)
        chi_fit_cur, chi_val_cur = float(rf_b @ rf_b), float(rv_b @ rv_b)
        # screening: linearised chi-square reduction per candidate
        say("screening candidates")
        scores = []
        pen: dict = {}
        taken = {(e.name, e.where) for e in accepted}
        for cand in model.candidates:
            if (cand.name, cand.where) in taken:
                continue
            cols = []
            for j, q in enumerate(cand.params):
                xc = np.array([qq.x0 for qq in cand.params], dtype=float)
                wpl = p.weighted(model.predict(theta, active + [(cand, xc)]))
                xc2 = xc.copy()
                xc2[j] = 0.5 * xc[j] if xc[j] != 0 else q.scale
                wmi = p.weighted(model.predict(theta, active + [(cand, xc2)]))
                cols.append((p.vec(wpl, p.fit_mask) - p.vec(wmi, p.fit_mask)) / (xc[j] - xc2[j] or 1.0))
            A = np.stack(cols, axis=1)
            # BIC's N for this term: the observations it acts on (a drive-force term touches only
            # the FORCE-mode blocks, not every sample of every channel)
            amax = float(np.max(np.abs(A))) if A.size else 0.0
            n_eff = int(np.count_nonzero(np.any(np.abs(A) > 1e-6 * amax, axis=1))) if amax > 0 else 2
            pen[(cand.name, cand.where)] = len(cand.params) * float(np.log(max(n_eff, 2)))
            A = A - proj.Q @ (proj.Q.T @ A)
            b = proj.Q @ (proj.Q.T @ rf_b)  # rf_b is already orthogonal; keep for clarity
            rhs = rf_b - b
            coef, *_ = np.linalg.lstsq(A, rhs, rcond=None)
            red = float(rhs @ rhs - (rhs - A @ coef) @ (rhs - A @ coef))
            scores.append((red - pen[(cand.name, cand.where)], red, cand))
        scores.sort(key=lambda s: -s[0])
        screening_log.append([{"name": c.name, "where": c.where, "delta_chi2_linear": round(r, 1),
                               "delta_bic_linear": round(-s, 1)} for s, r, c in scores])
        best = None
        for s, red, cand in scores[: cfg.refit_top]:
            if s <= 0:
                break
            say(f"refit {cand.name} at {cand.where}")
            x, unc, beta, chi_f, chi_v = _fit_candidate(p, proj, theta, active, cand)
            dbic = (chi_f - chi_fit_cur) + pen[(cand.name, cand.where)]
            dval = chi_v - chi_val_cur
            if best is None or dbic < best[0]:
                best = (dbic, dval, cand, x, unc, beta, chi_f, chi_v)
        if best is None:
            break
        dbic, dval, cand, x, unc, beta, chi_f, chi_v = best
        others = [s for s in scores if s[2] is not cand]
        runner = others[0] if others else None
        if not (dbic < -cfg.bic_margin and dval < -cfg.holdout_margin):
            say(f"best candidate {cand.name} at {cand.where} not accepted (dBIC {dbic:.1f}, held-out {dval:.1f})")
            break
        theta = theta + beta * np.array([q.scale for q in model.nominal]) * 1.0
        active.append((cand, x))
        pen_cur += pen[(cand.name, cand.where)]
        ic_cur = chi_f + pen_cur
        ev = (f"chi-square on the fit half reduced by {chi_fit_cur - chi_f:.0f} "
              f"(BIC {dbic:+.0f}), on the held-out half by {-dval:.0f}; "
              + (f"next best candidate {runner[2].name} at {runner[2].where} explains "
                 f"{runner[1]:.0f} (linearised)" if runner else "no other candidate"))
        accepted.append(FittedEffect(cand.name, cand.where, cand.words,
                                     {q.name: float(v) for q, v in zip(cand.params, x)},
                                     {q.name: float(u) for q, u in zip(cand.params, unc)},
                                     float(dbic), float(dval), ev))
        pred_cur = model.predict(theta, active)
        excess_cur = excess_all(wall(full(pred_cur)))
        say(f"accepted {cand.name} at {cand.where}; excess now " +
            ", ".join(f"{c} {v:.2f}" for c, v in excess_cur.items()))
    cur_all = full(pred_cur)
    w_cur = wall(cur_all)
    rs_cur = regime_all(w_cur)
    regime_cur = {c: r.score for c, r in rs_cur.items()}
    still = (any(excess_cur[c] > cfg.excess_threshold for c in model.channels)
             or any(regime_cur[c] > cfg.regime_threshold for c in model.channels))
    # an effect that only nudges a flagged channel under the threshold has not explained it
    flagged = [c for c in model.channels if excess0[c] > cfg.excess_threshold]
    removed = (all(excess0[c] - excess_cur[c] >= cfg.min_explained_fraction * (excess0[c] - 1.0) for c in flagged)
               and all(regime0[c] - regime_cur[c] >= cfg.min_explained_fraction * regime0[c] for c in flag_r0))
    if accepted and not still and removed:
        verdict, eff, part = "explained", tuple(accepted), ()
    elif not accepted and not significant:
        verdict, eff, part = "no_mismatch", (), ()
    else:
        verdict, eff, part = "unexplained", (), tuple(accepted)
    if still:
        locations = (locate(cur_all, w_cur) + locate_regime(cur_all, rs_cur)) or locations
    return Diagnosis(verdict, eff, part, tuple(locations), rms(pred0_all), rms(cur_all),
                     rms(pred0_all, ~p.fit_mask), rms(cur_all, ~p.fit_mask), floor, excess0,
                     excess_cur, float(ic0), float(ic_cur), _named(model.nominal, theta),
                     tuple(screening_log), pred0_all, cur_all, meas, valid, ~p.fit_mask,
                     rs0, rs_cur, tuple(cell_labels))


def _named(params: tuple, theta: np.ndarray) -> dict:
    return {q.name: float(v) for q, v in zip(params, theta)}
