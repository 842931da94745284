"""Sim versus recording: localise the mismatch, name the missing physics, fit it.

Pure core: a replay model (arrays in, predicted channels out) and an explicit
sample period in, a frozen :class:`Diagnosis` out; no plotting or file IO.

Method
------
0. **Band.** Residuals are compared in the band the model claims to explain
   (``model.band_hz``, :mod:`blf.band`): low-passed without phase shift and
   decimated, as IDIM-LS does. Fit, tests and the figures of merit are all
   in that band; the raw-band RMS is reported beside them.
1. **Nominal fit.** The model's nominal parameters (including the
   calibration of its sensors and whatever physics every recording of a rig
   shares) are fitted by bounded nonlinear least squares on the *fit* half
   of the recording (alternate blocks of ``block_s``; the other half is held
   out and never fitted).
2. **Noise floor.** Per channel and sample, from the second differences of
   the raw nominal residual (rolling RMS over ``noise_window_s``,
   :math:`\\sigma = \\mathrm{rms}(\\Delta^2 r)/\\sqrt 6`): white measurement
   noise passes, slow model error does not; in the band it is
   :math:`\\sigma\\|h\\|_2` (the band's noise gain). Residuals are weighted by it.
3. **Significance.** Per channel the weighted band residual is summed over
   windows of ``window_s``; under "noise only" the window scores
   :math:`z_b = \\sum w_i/\\sqrt{\\rho n_b}` are standard normal (:math:`\\rho`,
   the band's ``sum_factor``, accounts for the correlation of kept samples).
   The channel differs when :math:`\\sum z_b^2/n_b` exceeds
   ``excess_threshold``; windows with :math:`|z_b| > 4` are the locations,
   described by the operating regime where their residual concentrates.
   A second test looks for a mismatch spread thinly along the recording but
   tied to the operating regime (:func:`blf.mismatch.regime_score`): cells
   of stroke position x sign of velocity x sign of the model's force, cell
   sums formed separately on the two halves, their products summed; about
   standard normal under noise, large for a mismatch that repeats wherever
   the regime repeats (threshold ``regime_threshold``).
4. **Screening.** Each candidate effect (a switchable physics term of the
   model) is linearised by finite differences of replays; the chi-square it
   removes together with the re-adjusted nominal parameters (their Jacobian
   is projected out) ranks it, penalised by BIC per parameter with the
   number of observations the term acts on.
5. **Refit and acceptance.** The best candidates are refitted (candidate
   parameters nonlinear, nominal parameters re-adjusted linearly, i.e.
   variable projection); one is accepted only if its BIC improves by more
   than ``bic_margin`` on the fit half *and* its chi-square improves by more
   than ``holdout_margin`` on the held-out half, judged by a replay at the
   linearised step, or, where that disagrees or a parameter bound cuts the
   step (then it is not the bounded optimum), after the nominal and the
   candidate are refitted together. Forward selection, up to
   ``max_effects``, while a candidate passes both tests. The best
   ``refit_top`` are refitted and every refit that passes on the
   linearisation is tried, best first; when the same physics passes at the
   other EMA too, the place is decided by the joint nonlinear fit of the
   nominal parameters with each of the two (the linearised re-adjustment
   ranks places poorly when a term moves the nominal far).
6. **Nominal parameters with a reference.** A nominal parameter the model
   compares with a reference value (an LVDT pitch calibrated on the
   recording against the simulator's, the hinge friction against the
   simulator's surface) is named as an effect when holding it at the
   reference costs more than BIC's penalty and ``bic_margin`` on the fit
   half and more than ``holdout_margin`` on the held-out half.
7. **Verdict.** ``unexplained`` if a channel still differs (by either test)
   after the accepted effects, or a flagged channel lost less than
   ``min_explained_fraction`` of its excess; then the places where the rest
   lies are ranked (:attr:`Diagnosis.where`) by the evidence of each place's
   channels in noise sigmas, those below the thresholds included: per
   channel the larger of the regime score and the window excess as
   :math:`(E - 1)\\sqrt{n_b/2}`, the load cells at half weight (both see the
   surface's force fight alike; an EMA's own LVDT and drive force tell which
   EMA it is). Otherwise ``explained`` if any
   effect was named, else ``no_mismatch``. ``effects`` lists every effect
   accepted, whatever the verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from blf.band import Band, make_band
from blf.diagnose_fit import (
    Problem,
    Projector,
    clip_nominal,
    fit_candidate,
    fit_joint,
    fit_nominal,
    nominal_jacobian,
    reference_test,
    safe_predict,
    screen,
)
from blf.errors import AnalysisError
from blf.mismatch import RegimeScore, excess, regime_cells, regime_score, regime_words, window_scores
from blf.validate import positive_scalar

__all__ = ["Param", "Candidate", "Reference", "ReplayModel", "DiagnoseConfig", "Location", "FittedEffect",
           "Diagnosis", "diagnose", "place_of"]


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
    """A candidate physics term: machine name, place, engineer's words, parameters; ``variant`` tells
    apart two forms of the same physics at the same place (e.g. friction in the drive or in the load
    path): at most one of them is accepted."""

    name: str
    where: str
    words: str
    params: tuple
    variant: str = ""


@dataclass(frozen=True)
class Reference:
    """A nominal parameter compared with a reference value; named as effect ``name`` at ``where``
    when it differs significantly. Reported as ``param`` = value - ``offset``."""

    index: int
    value: float
    name: str
    where: str
    words: str
    param: str
    offset: float = 0.0
    #: references with the same ``common`` = (name, where, words, param) that are all named and agree,
    #: relative to their reference values, within 3 combined standard uncertainties are one physics
    #: shared by their places (e.g. both LVDT pitches: the motor-to-ram ratio), named once
    common: tuple = ()


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

    # Optional: ``places`` ({channel: place} where :func:`place_of` would not do), ``band_hz`` (the band
    # the model claims, Hz; None: raw), ``references`` (tuple of
    # Reference), ``derived(channels) -> {name: ndarray}`` and ``derived_valid`` ({name: bool
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
    max_effects: int = 3
    refit_top: int = 5
    min_explained_fraction: float = 0.5  #: of each flagged channel's excess above 1, for "explained"
    regime_bins: int = 10  #: position bins of the regime test (x 2 velocity signs x 2 force signs)
    regime_threshold: float = 5.0  #: regime score S above which a channel differs (S ~ N(0, 1) under noise)
    #: forms of one physics at one place whose BIC lies within this of the best are indistinguishable
    #: (Kass and Raftery 1995: a BIC difference below 2 is "not worth more than a bare mention"):
    #: the one with the fewest parameters, then the first in the library, is named
    form_margin: float = 2.0


@dataclass(frozen=True)
class Location:
    channel: str
    t_start_s: float
    t_end_s: float
    regime: str
    score: float
    test: str = "window"  #: "window" (a time window) or "regime" (a regime cell, first to last visit)
    where: str = ""  #: the place the channel belongs to (ema1, ema2, external)


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
    source: str = "library"  #: "library" (a candidate term) or "nominal" (a nominal parameter off its reference)


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (plain dicts inside: JSON-ready, treat as read-only).

    RMS figures without ``raw`` are in the band (:attr:`band`); ``holdout`` ones
    over the held-out half only (never fitted)."""

    verdict: str
    effects: tuple
    locations: tuple
    where: tuple  #: places of the mismatch left after the effects (unexplained), best first
    band: Band
    residual_rms_before: dict
    residual_rms_after: dict
    residual_rms_holdout_before: dict
    residual_rms_holdout_after: dict
    residual_rms_raw_before: dict
    residual_rms_raw_after: dict
    residual_rms_raw_holdout_before: dict
    residual_rms_raw_holdout_after: dict
    noise_floor: dict  #: in the band
    noise_floor_raw: dict
    excess_before: dict
    excess_after: dict
    ic_before: float
    ic_after: float
    nominal: dict
    screening: tuple
    predicted_before: dict = field(repr=False)
    predicted_after: dict = field(repr=False)
    measured: dict = field(repr=False, default_factory=dict)  #: all reported channels, derived included
    valid: dict = field(repr=False, default_factory=dict)  #: raw samples compared, per channel
    held_out: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, bool))  #: raw samples never fitted
    kept: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, np.int64))  #: kept samples of the band
    kept_valid: dict = field(repr=False, default_factory=dict)  #: per channel, over the kept samples
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


def place_of(channel: str) -> str:
    """The place a channel belongs to: ``ema1``/``ema2`` by its number, ``external`` otherwise."""
    if channel.endswith("1"):
        return "ema1"
    if channel.endswith("2"):
        return "ema2"
    return "external"


def _forms_alike(refits: list, where: str, variant: str, margin: float) -> list:
    """The refits of the forms of one physics at ``where`` (``variant``) whose BIC lies within
    ``margin`` of the best of them: the forms the recording cannot tell apart (step 5)."""
    forms = [r for r in refits if variant and (r[2].where, r[2].variant) == (where, variant)]
    if not forms:
        return []
    lim = min(r[0] for r in forms) + margin
    return [r for r in forms if r[0] <= lim]


def _prefer_simpler_law(refits: list, library: tuple, pen: dict, taken: set, margin: float, refit, chi_fit: float,
                        chi_val: float, say) -> list:
    """Among forms of one physics at one place (same ``where`` and non-empty ``variant``, e.g. the
    friction laws of a drive) whose refitted BIC lies within ``margin`` of the best, the one with
    the fewest parameters goes first, then the one listed first in the model's library (which lists
    the simpler law first): the recording cannot tell them apart (at the check's two sweep speeds,
    1-3 mm/s, Coulomb, viscous and Stribeck friction differ only at the few reversals, and a
    direction-dependent friction at its size looks like a Coulomb one), and the simpler law claims
    less. Beyond ``margin`` the better BIC decides, so a form with more parameters earns them by
    evidence. The simpler forms not yet refitted are refitted here."""
    if not refits or not refits[0][2].variant:
        return refits
    best = refits[0][2]
    order = {c: i for i, c in enumerate(library)}
    have = {r[2] for r in refits}
    for c in library:
        if order[c] >= order[best]:
            break
        if (c.where, c.variant) != (best.where, best.variant) or len(c.params) > len(best.params) or c in have \
                or c not in pen \
                or (c.name, c.where) in taken:
            continue
        say(f"refit {c.name} at {c.where} (same physics, simpler form)")
        fitted = refit(c)
        if fitted is not None:
            x, unc, beta, chi_f, chi_v = fitted
            refits.append(((chi_f - chi_fit) + pen[c], chi_v - chi_val, c, x, unc, beta))
    refits.sort(key=lambda r: r[0])
    tied = _forms_alike(refits, best.where, best.variant, margin)
    first = min(tied, key=lambda r: (len(r[2].params), order.get(r[2], len(order))))
    return [first] + [r for r in refits if r is not first]


def _reference_effects(named: list, refs: tuple, nominal: tuple, lnN: float) -> list:
    """The effects of the named nominal parameters (:class:`Reference`), ``named`` as
    (reference, value, standard uncertainty, chi-square cost on the fit half, on the held-out half).

    References sharing a ``common`` key that are all named and whose relative deviations
    :math:`d_i = v_i / r_i - 1` agree within 3 combined standard uncertainties are named once, as
    the ``common`` physics with their weighted mean deviation: the recording cannot tell one shared
    cause from the same error at every place (both LVDTs reading alike against the motor angles is
    the motor-to-ram ratio differing from the profile's)."""
    out, done = [], set()
    for ref, v, sd, dfit, dval in named:
        if ref in done:
            continue
        if ref.common:
            group = [r for r in refs if r.common == ref.common]
            rows = [n for n in named if n[0] in group]
            if len(rows) == len(group) > 1 and all(n[0].value != 0.0 for n in rows):
                d = np.array([n[1] / n[0].value - 1.0 for n in rows])
                u = np.array([n[2] / abs(n[0].value) for n in rows])
                if np.ptp(d) <= 3.0 * float(np.sqrt(np.sum(u ** 2))):
                    w = 1.0 / np.maximum(u, 1e-300) ** 2
                    name, where, words, param = ref.common
                    mean, sd_mean = float(np.sum(w * d) / np.sum(w)), float(1.0 / np.sqrt(np.sum(w)))
                    done.update(group)
                    out.append(FittedEffect(
                        name, where, words, {param: mean}, {param: sd_mean},
                        float(-sum(n[3] - lnN for n in rows)), float(-sum(n[4] for n in rows)),
                        "nominal parameters " + ", ".join(f"{nominal[n[0].index].name} = {n[1]:.6g}" for n in rows)
                        + " against " + ", ".join(f"{n[0].value:.6g}" for n in rows)
                        + f": the same relative deviation, {mean:+.3g} ± {sd_mean:.2g}", "nominal"))
                    continue
        out.append(FittedEffect(
            ref.name, ref.where, ref.words, {ref.param: v - ref.offset}, {ref.param: sd},
            float(-(dfit - lnN)), float(-dval),
            f"nominal parameter {nominal[ref.index].name} = {v:.6g} against the simulator's "
            f"{ref.value:.6g}: holding it there costs {dfit:.0f} in chi-square on the fit half and "
            f"{dval:.0f} on the held-out half", "nominal"))
    return out


def _named(params: tuple, theta: np.ndarray) -> dict:
    return {q.name: float(v) for q, v in zip(params, theta)}


def diagnose(model: ReplayModel, sample_period_s: float, config: DiagnoseConfig | None = None,
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose the mismatch between a replay model and its recording.

    Parameters
    ----------
    model : ReplayModel
        Recording and replay (e.g. :class:`sim.replay_model.DualEmaReplay`,
        :class:`sim.single_axis.SingleAxisReplay`).
    sample_period_s : float
        Sample period of the recording, s (> 0).
    config : DiagnoseConfig, optional
    progress : callable, optional
        Called with a short text at each stage (the shell may print it).

    Returns
    -------
    Diagnosis

    Raises
    ------
    blf.errors.InputError
        A non-positive sample period.
    blf.errors.AnalysisError
        No channel has samples to compare, or the nominal model cannot be
        evaluated at its start values.

    Notes
    -----
    Information criterion (Gaussian, noise floor known):
    :math:`\\mathrm{BIC} = \\chi^2 + k_0 \\ln N + \\sum_j k_j \\ln N_j` with
    :math:`\\chi^2 = \\sum w^2` over the kept samples of the fit half,
    :math:`k_0` nominal parameters over all :math:`N` of them and :math:`k_j`
    parameters of accepted effect j over the :math:`N_j` samples that effect
    changes. See the module docstring for the steps.
    """
    cfg = config or DiagnoseConfig()
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    places = dict(getattr(model, "places", None) or {})

    def place(c: str) -> str:
        return places.get(c) or place_of(c)

    say = progress or (lambda s: None)
    band = make_band(1.0 / T, getattr(model, "band_hz", None))
    derive = getattr(model, "derived", None)
    dvalid = dict(model.derived_valid) if derive else {}
    p = Problem(model, cfg, T, band, dvalid)
    if p.nfit < 10 * (len(model.nominal) + 1):
        raise AnalysisError(f"too few samples to compare in the band ({p.nfit} on the fit half) for "
                            f"{len(model.nominal)} nominal parameters")
    theta = np.array([q.x0 for q in model.nominal], dtype=float)
    pred = safe_predict(model, theta, [])
    if pred is None:
        raise AnalysisError("the nominal model cannot be evaluated at its start values")
    say(f"band: {band.words}")
    say("nominal fit")
    p.set_floor(model.measured, pred)
    theta = fit_nominal(p, theta)
    pred0 = safe_predict(model, theta, []) or pred
    p.set_floor(model.measured, pred0)
    theta = fit_nominal(p, theta, max_nfev=10)
    pred0 = safe_predict(model, theta, []) or pred0

    def full(pr):
        return {**pr, **derive(pr)} if derive else dict(pr)

    meas = full(model.measured)
    rep = list(meas)
    pred0_all = full(pred0)
    p.set_floor(meas, pred0_all, rep)
    w0 = p.weighted(pred0)
    k_nom = len(model.nominal)
    lnN = float(np.log(max(p.nfit, 2)))
    ic0 = p.chi2(w0, p.fit) + k_nom * lnN
    nwin = max(2, int(round(cfg.window_s / (T * band.step))))
    rho = np.sqrt(band.sum_factor)

    def wall(pred_all):
        return {c: w / rho for c, w in p.weighted(pred_all, meas, rep).items()}

    def excess_all(w):
        return {c: excess(window_scores(w[c], p.valid[c], nwin)[0]) for c in rep}

    t_k = model.t_s[p.idx]
    # a cell chosen by the sign of a measured force would pick that channel's noise: force regimes of
    # fitted channels use the nominal model
    cell_regimes = {k: (pred0[k.split()[-1]] if k.startswith("force ") and k.split()[-1] in pred0 else x)[p.idx]
                    for k, x in model.regimes.items()}
    regimes_k = {k: x[p.idx] for k, x in model.regimes.items()}
    cells, cell_labels = regime_cells(cell_regimes, cfg.regime_bins)

    def regime_all(w):
        return {c: regime_score(w[c] * rho, p.valid[c], p.fit, p.block, cells, len(cell_labels)) for c in rep}

    def band_resid(pred_all):
        return {c: p.residual(c, meas[c], pred_all[c]) for c in rep}

    def locate(pred_all, w, rs):
        locs = []
        rb = band_resid(pred_all)
        for c in rep:
            z, starts = window_scores(w[c], p.valid[c], nwin)
            bad = np.where(np.abs(np.nan_to_num(z)) > 4.0)[0]
            if bad.size and excess(z) > cfg.excess_threshold:
                groups = np.split(bad, np.where(np.diff(bad) > 1)[0] + 1)
                groups.sort(key=lambda g: -float(np.sum(z[g] ** 2)))
                for g in groups[:5]:
                    i0, i1 = starts[g[0]], min(starts[g[-1]] + nwin, t_k.size)
                    ii = np.arange(i0, i1)
                    ii = ii[p.valid[c][ii]]
                    locs.append(Location(c, float(t_k[i0]), float(t_k[i1 - 1]), regime_words(ii, rb[c], regimes_k),
                                         float(np.sum(z[g] ** 2)), "window", place(c)))
            if c in model.channels and rs[c].score > cfg.regime_threshold:
                prod = rs[c].products
                for b in np.argsort(-np.nan_to_num(prod, nan=-np.inf))[:3]:
                    sel = np.flatnonzero(p.valid[c] & (cells == b))
                    if not np.isfinite(prod[b]) or prod[b] < 4.0 or sel.size == 0:
                        continue
                    locs.append(Location(c, float(t_k[sel[0]]), float(t_k[sel[-1]]),
                                         f"{cell_labels[b]} (mean residual {rb[c][sel].mean():+.3g}, repeated in "
                                         f"fit and held-out halves)", float(prod[b]), "regime", place(c)))
        return locs

    def rms(pred_all, part=None, raw=False):
        out = {}
        for c in rep:
            if raw:
                sel = p.valid_raw[c] if part is None else p.valid_raw[c] & part
                out[c] = float(np.sqrt(np.mean((meas[c] - pred_all[c])[sel] ** 2))) if sel.any() else None
            else:
                sel = p.valid[c] if part is None else p.valid[c] & part
                r = p.residual(c, meas[c], pred_all[c])
                out[c] = float(np.sqrt(np.mean(r[sel] ** 2))) if sel.any() else None
        return out

    w0_all = wall(pred0_all)
    excess0 = excess_all(w0_all)
    rs0 = regime_all(w0_all)
    regime0 = {c: r.score for c, r in rs0.items()}
    say("excess over noise: " + ", ".join(f"{c} {v:.2f}" for c, v in excess0.items()))
    say("regime score: " + ", ".join(f"{c} {v:.1f}" for c, v in regime0.items()))

    active: list = []
    accepted: list[FittedEffect] = []
    screening_log: list = []
    pen_cur = k_nom * lnN
    ic_cur = ic0
    for _round in range(cfg.max_effects):
        base_pred = safe_predict(model, theta, active)
        wb = p.weighted(base_pred)
        chi_fit_cur, chi_val_cur = p.chi2(wb, p.fit), p.chi2(wb, ~p.fit)
        Jn = nominal_jacobian(p, theta, active, wb)
        proj = Projector(p, Jn)
        _, rf_b, _ = proj.solve(wb)
        wb_fit = p.vec(wb, p.fit)
        say("screening candidates")
        scores = []
        pen: dict = {}
        taken = {(e.name, e.where) for e in accepted}
        for cand in model.candidates:
            if (cand.name, cand.where) in taken:
                continue
            sc = screen(p, proj, theta, active, cand, rf_b, wb_fit)
            if sc is None:
                continue
            red, n_eff = sc
            pen[cand] = len(cand.params) * float(np.log(max(n_eff, 2)))
            scores.append((red - pen[cand], red, cand))
        scores.sort(key=lambda s: -s[0])
        screening_log.append([{"name": c.name, "where": c.where, "variant": c.variant, "delta_chi2_linear": round(r, 1),
                               "delta_bic_linear": round(-s, 1)} for s, r, c in scores])
        refits = []
        for s, red, cand in scores[: cfg.refit_top]:
            if s <= cfg.bic_margin:
                break
            say(f"refit {cand.name} at {cand.where}")
            fitted = fit_candidate(p, proj, theta, active, cand)
            if fitted is not None:
                x, unc, beta, chi_f, chi_v = fitted
                refits.append(((chi_f - chi_fit_cur) + pen[cand], chi_v - chi_val_cur, cand, x, unc, beta))
        refits.sort(key=lambda r: r[0])
        refits = _prefer_simpler_law(refits, model.candidates, pen, taken, cfg.form_margin,
                                     lambda c: fit_candidate(p, proj, theta, active, c), chi_fit_cur, chi_val_cur, say)
        chosen = None
        scale = np.array([q.scale for q in model.nominal])
        for lin_bic, lin_val, cand, x, unc, beta in refits:
            if not (lin_bic < -cfg.bic_margin and lin_val < -cfg.holdout_margin):
                continue
            # exact acceptance: the re-adjustment only ranks. First the linearised step itself; if the
            # replay disagrees with it or a bound cuts it (then it is not the bounded optimum: a shared
            # nominal term held at its bound leaves the rest of its channel unfitted), nominal and
            # candidate refitted together
            th_lin = theta + beta * scale
            th_new = clip_nominal(model, th_lin)
            pr = safe_predict(model, th_new, active + [(cand, x)]) if np.array_equal(th_new, th_lin) else None
            exact = None
            if pr is not None:
                wn = p.weighted(pr)
                exact = (th_new, x, unc, p.chi2(wn, p.fit), p.chi2(wn, ~p.fit))
            if exact is None or not (exact[3] - chi_fit_cur + pen[cand] < -cfg.bic_margin
                                     and exact[4] - chi_val_cur < -cfg.holdout_margin):
                joint = fit_joint(p, theta, active, cand, x)
                if joint is not None and (exact is None or joint[3] < exact[3]):
                    exact = joint
            if exact is None:
                continue
            th_new, x_new, unc_new, chi_f, chi_v = exact
            dbic = (chi_f - chi_fit_cur) + pen[cand]
            dval = chi_v - chi_val_cur
            if dbic < -cfg.bic_margin and dval < -cfg.holdout_margin:
                chosen = (dbic, dval, cand, th_new, x_new, unc_new, chi_f)
                break
            say(f"candidate {cand.name} at {cand.where} not accepted (dBIC {dbic:.1f}, held-out {dval:.1f})")
        if chosen is None:
            break
        twin = next((r for r in refits if r[2] is not chosen[2] and r[2].name == chosen[2].name
                     and r[2].variant == chosen[2].variant and r[2].where != chosen[2].where
                     and r[0] < -cfg.bic_margin and r[1] < -cfg.holdout_margin), None)
        if twin is not None:
            # the same physics passes at the other place too: the linearised re-adjustment of the nominal
            # ranks places poorly when the term moves the nominal far (a stiffening first read as a stiffer
            # spring), so the place is decided by the joint nonlinear fit of the nominal and each of the two
            say(f"{chosen[2].name} at {chosen[2].where} or {twin[2].where}: both refitted with the nominal")
            for c, x0 in ((chosen[2], chosen[4]), (twin[2], twin[3])):
                joint = fit_joint(p, theta, active, c, x0)
                if joint is None:
                    continue
                th_j, x_j, unc_j, chi_f, chi_v = joint
                dbic, dval = (chi_f - chi_fit_cur) + pen[c], chi_v - chi_val_cur
                if dbic < min(chosen[0], -cfg.bic_margin) and dval < -cfg.holdout_margin:
                    chosen = (dbic, dval, c, th_j, x_j, unc_j, chi_f)
        dbic, dval, cand, theta, x, unc, chi_f = chosen
        others = [s for s in scores if s[2] is not cand]
        active.append((cand, x))
        pen_cur += pen[cand]
        ic_cur = chi_f + pen_cur
        ev = (f"chi-square on the fit half reduced by {chi_fit_cur - chi_f:.0f} (BIC {dbic:+.0f}), on the "
              f"held-out half by {-dval:.0f}; "
              + (f"next best candidate {others[0][2].name} at {others[0][2].where} explains {others[0][1]:.0f} "
                 f"(linearised)" if others else "no other candidate"))
        # the forms of this physics the recording could not tell from it (step 5): said, not hidden
        alike = [r for r in _forms_alike(refits, cand.where, cand.variant, cfg.form_margin) if r[2] is not cand]
        if alike:
            ev += (f"; as good within {cfg.form_margin:g} BIC units, so the form with the fewest parameters is "
                   "named: " + ", ".join(f"{r[2].name} (BIC {r[0]:+.1f}, linearised)" for r in alike))
        accepted.append(FittedEffect(cand.name, cand.where, cand.words,
                                     {q.name: float(v) for q, v in zip(cand.params, x)},
                                     {q.name: float(u) for q, u in zip(cand.params, unc)},
                                     float(dbic), float(dval), ev))
        say(f"accepted {cand.name} at {cand.where}")
    # the nominal parameters with a reference value
    pred_cur = safe_predict(model, theta, active)
    refs = tuple(getattr(model, "references", ()) or ())
    if refs:
        wc = p.weighted(pred_cur)
        Jn = nominal_jacobian(p, theta, active, wc)
        _, rf_c, rv_c = Projector(p, Jn).solve(wc)
        cf, cv = float(rf_c @ rf_c), float(rv_c @ rv_c)
        named = []
        for ref in refs:
            res = reference_test(p, theta, active, Jn, ref.index, ref.value, cf, cv)
            if res is None:
                continue
            dfit, dval, sd = res
            if dfit > lnN + cfg.bic_margin and dval > cfg.holdout_margin:
                named.append((ref, float(theta[ref.index]), sd, dfit, dval))
        accepted += _reference_effects(named, refs, model.nominal, lnN)
    cur_all = full(pred_cur)
    w_cur = wall(cur_all)
    excess_cur = excess_all(w_cur)
    rs_cur = regime_all(w_cur)
    regime_cur = {c: r.score for c, r in rs_cur.items()}
    fitted_ch = model.channels
    flagged0 = [c for c in fitted_ch if excess0[c] > cfg.excess_threshold]
    flag_r0 = [c for c in fitted_ch if regime0[c] > cfg.regime_threshold]
    still = [c for c in fitted_ch if excess_cur[c] > cfg.excess_threshold or regime_cur[c] > cfg.regime_threshold]
    removed = (all(excess0[c] - excess_cur[c] >= cfg.min_explained_fraction * (excess0[c] - 1.0) for c in flagged0)
               and all(regime0[c] - regime_cur[c] >= cfg.min_explained_fraction * regime0[c] for c in flag_r0))
    lib = [e for e in accepted if e.source == "library"]
    if still or (lib and not removed):
        verdict = "unexplained"
    elif accepted:
        verdict = "explained"
    else:
        verdict = "no_mismatch"
    if verdict == "unexplained":
        locations = locate(cur_all, w_cur, rs_cur)
        # every fitted channel's evidence in noise sigmas, the ones below the thresholds too (a fault in
        # one EMA's load path shows in both load cells alike; its own LVDT and drive force tell which)
        score: dict = {}
        for c in fitted_ch:
            z = window_scores(w_cur[c], p.valid[c], nwin)[0]
            z_excess = (excess_cur[c] - 1.0) * np.sqrt(np.isfinite(z).sum() / 2.0)
            s = max(z_excess, regime_cur[c], 0.0)
            w = 0.5 if c.startswith("F") and not c.startswith("Fd") else 1.0  # F1 and F2 share the surface
            if s > 0.0:
                score[place(c)] = score.get(place(c), 0.0) + w * s
        where = tuple(k for k, _ in sorted(score.items(), key=lambda kv: -kv[1]))
    else:
        locations, where = [], ()
    return Diagnosis(verdict, tuple(accepted), tuple(locations), where, band,
                     rms(pred0_all), rms(cur_all), rms(pred0_all, ~p.fit), rms(cur_all, ~p.fit),
                     rms(pred0_all, raw=True), rms(cur_all, raw=True), rms(pred0_all, ~p.fit_raw, raw=True),
                     rms(cur_all, ~p.fit_raw, raw=True),
                     {c: float(np.sqrt(np.mean(p.sig[c][p.valid[c]] ** 2))) if p.valid[c].any() else None for c in rep},
                     {c: float(np.sqrt(np.mean(p.sig_raw[c][p.valid_raw[c]] ** 2))) if p.valid_raw[c].any() else None
                      for c in rep},
                     excess0, excess_cur, float(ic0), float(ic_cur), _named(model.nominal, theta),
                     tuple(screening_log), pred0_all, cur_all, meas, dict(p.valid_raw), ~p.fit_raw, p.idx,
                     dict(p.valid), rs0, rs_cur, tuple(cell_labels))


__all__ += ["RegimeScore"]
