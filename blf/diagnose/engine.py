"""Sim versus recording: localise the mismatch, name the missing physics, fit it.

Pure core: a replay model (arrays in, predicted channels out) and an explicit
sample period in, a frozen :class:`Diagnosis` out; no plotting or file IO.

Method
------
0. **Band.** Residuals are compared in the band the model claims to explain
   (``model.band_hz``, :mod:`blf.diagnose.band`): low-passed without phase shift and
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
   tied to the operating regime (:func:`blf.diagnose.mismatch.regime_score`): cells
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

Each step is a function with a frozen record as its result (steps 4 to 6 in
:mod:`blf.diagnose.selection`, the others here):
0 :class:`Comparison`, 1 :class:`NominalFit`, 2 :class:`NoiseFloor`, 3
:class:`ChannelTests` (over a :class:`TestFrame`), 4 :class:`Screening` (of
:class:`Screened` candidates, about the :class:`Standing` model of the
round), 5 the :class:`Refit` candidates and the :class:`Accepted` one, its
place decided, 6 :class:`NamedReference` parameters, 7 :class:`Verdict`.
:func:`diagnose` strings them together and builds the :class:`Diagnosis`
from their records.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from blf.diagnose.band import make_band
from blf.diagnose.fit import (
    Problem,
    fit_joint,
    fit_nominal,
    safe_predict,
)
from blf.diagnose.mismatch import excess, regime_cells, regime_score, regime_words, window_scores
from blf.diagnose.model import (
    Candidate,
    DiagnoseConfig,
    Diagnosis,
    DiagnosisVerdict,
    FittedEffect,
    Location,
    ReplayModel,
)
from blf.diagnose.records import (
    ChannelTests,
    Comparison,
    NoiseFloor,
    NominalFit,
    ResidualRms,
    TestFrame,
    Verdict,
)
from blf.diagnose.selection import named_references, select_effects
from blf.errors import AnalysisError
from blf.validate import positive_scalar

__all__ = ["band_comparison", "diagnose", "fit_effect"]


def band_comparison(model: ReplayModel, sample_period_s: float, cfg: DiagnoseConfig) -> Comparison:
    """Step 0: the band the model claims, the kept samples and the halves (also for blf.diagnose.covariance)."""
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    places = dict(getattr(model, "places", None) or {})
    band = make_band(1.0 / T, getattr(model, "band_hz", None))
    dvalid = dict(model.derived_valid) if getattr(model, "derived", None) else {}
    p = Problem(model, cfg, T, band, dvalid)
    if p.nfit < 10 * (len(model.nominal) + 1):
        raise AnalysisError(f"too few samples to compare in the band ({p.nfit} on the fit half) for "
                            f"{len(model.nominal)} nominal parameters")
    return Comparison(model, cfg, band, p, places)


def _nominal_fit(cmp: Comparison, say: Callable[[str], None]) -> NominalFit:
    """Step 1: bounded nonlinear least squares of the nominal parameters on the fit half, the noise
    floors of the model's channels set from the start values, then again from the fit."""
    model, p = cmp.model, cmp.problem
    theta = np.array([q.x0 for q in model.nominal], dtype=float)
    pred = safe_predict(model, theta, [])
    if pred is None:
        raise AnalysisError("the nominal model cannot be evaluated at its start values")
    say(f"band: {cmp.band.words}")
    say("nominal fit")
    p.set_floor(model.measured, pred)
    theta = fit_nominal(p, theta)
    pred0 = safe_predict(model, theta, []) or pred
    p.set_floor(model.measured, pred0)
    theta = fit_nominal(p, theta, max_nfev=10)
    pred0 = safe_predict(model, theta, []) or pred0
    return NominalFit(theta, pred0)


def _rms_floor(sig: dict, valid: dict, channels: tuple) -> dict:
    return {c: float(np.sqrt(np.mean(sig[c][valid[c]] ** 2))) if valid[c].any() else None for c in channels}


def _noise_floor(cmp: Comparison, nom: NominalFit) -> NoiseFloor:
    """Step 2: the noise floor of every reported channel from the nominal model's raw residual."""
    p = cmp.problem
    meas = cmp.full(cmp.model.measured)
    channels = tuple(meas)
    pred_all = cmp.full(nom.predicted)
    p.set_floor(meas, pred_all, channels)
    return NoiseFloor(channels, meas, pred_all, _rms_floor(p.sig, p.valid, channels),
                      _rms_floor(p.sig_raw, p.valid_raw, channels))


def _test_frame(cmp: Comparison, nom: NominalFit) -> TestFrame:
    """Step 3's windows and regime cells. A cell chosen by the sign of a measured force would pick
    that channel's noise: the force regimes of fitted channels use the nominal model."""
    model, p, cfg = cmp.model, cmp.problem, cmp.cfg
    n_window = max(2, int(round(cfg.window_s / (p.T * cmp.band.step))))
    pred0 = nom.predicted
    cell_regimes = {k: (pred0[k.split()[-1]] if k.startswith("force ") and k.split()[-1] in pred0 else x)[p.idx]
                    for k, x in model.regimes.items()}
    cells, labels = regime_cells(cell_regimes, cfg.regime_bins)
    return TestFrame(n_window, np.sqrt(cmp.band.sum_factor), cells, tuple(labels),
                     {k: x[p.idx] for k, x in model.regimes.items()}, model.t_s[p.idx])


def _tests(cmp: Comparison, frame: TestFrame, floor: NoiseFloor, pred_all: dict) -> ChannelTests:
    """Step 3: the window test and the regime test of every reported channel."""
    p, rho = cmp.problem, frame.rho
    w = {c: x / rho for c, x in p.weighted(pred_all, floor.measured, floor.channels).items()}
    return ChannelTests(
        pred_all, w,
        {c: excess(window_scores(w[c], p.valid[c], frame.n_window)[0]) for c in floor.channels},
        {c: regime_score(w[c] * rho, p.valid[c], p.fit, p.block, frame.cells, len(frame.labels))
         for c in floor.channels})


def _locate(cmp: Comparison, frame: TestFrame, floor: NoiseFloor, t: ChannelTests) -> list:
    """Step 7, the locations of what is left: per channel the windows of the window test beyond
    4 sigma (the five strongest runs) and the three strongest regime cells."""
    p, cfg, nwin = cmp.problem, cmp.cfg, frame.n_window
    locs = []
    rb = {c: p.residual(c, floor.measured[c], t.predicted[c]) for c in floor.channels}
    for c in floor.channels:
        z, starts = window_scores(t.weighted[c], p.valid[c], nwin)
        bad = np.where(np.abs(np.nan_to_num(z)) > 4.0)[0]
        if bad.size and excess(z) > cfg.excess_threshold:
            groups = np.split(bad, np.where(np.diff(bad) > 1)[0] + 1)
            groups.sort(key=lambda g: -float(np.sum(z[g] ** 2)))
            for g in groups[:5]:
                i0, i1 = starts[g[0]], min(starts[g[-1]] + nwin, frame.t_s.size)
                ii = np.arange(i0, i1)
                ii = ii[p.valid[c][ii]]
                locs.append(Location(c, float(frame.t_s[i0]), float(frame.t_s[i1 - 1]),
                                     regime_words(ii, rb[c], frame.regimes), float(np.sum(z[g] ** 2)), "window",
                                     cmp.place(c)))
        if c in cmp.model.channels and t.regime[c].score > cfg.regime_threshold:
            prod = t.regime[c].products
            for b in np.argsort(-np.nan_to_num(prod, nan=-np.inf))[:3]:
                sel = np.flatnonzero(p.valid[c] & (frame.cells == b))
                if not np.isfinite(prod[b]) or prod[b] < 4.0 or sel.size == 0:
                    continue
                locs.append(Location(c, float(frame.t_s[sel[0]]), float(frame.t_s[sel[-1]]),
                                     f"{frame.labels[b]} (mean residual {rb[c][sel].mean():+.3g}, repeated in "
                                     f"fit and held-out halves)", float(prod[b]), "regime", cmp.place(c)))
    return locs


def _where_the_rest_lies(cmp: Comparison, frame: TestFrame, t: ChannelTests) -> tuple:
    """Step 7, the places ranked by every fitted channel's evidence in noise sigmas, the ones below
    the thresholds too (a fault in one EMA's load path shows in both load cells alike; its own LVDT
    and drive force tell which)."""
    p = cmp.problem
    score: dict = {}
    regime = t.regime_score
    for c in cmp.model.channels:
        z = window_scores(t.weighted[c], p.valid[c], frame.n_window)[0]
        z_excess = (t.excess[c] - 1.0) * np.sqrt(np.isfinite(z).sum() / 2.0)
        s = max(z_excess, regime[c], 0.0)
        w = 0.5 if c.startswith("F") and not c.startswith("Fd") else 1.0  # F1 and F2 share the surface
        if s > 0.0:
            score[cmp.place(c)] = score.get(cmp.place(c), 0.0) + w * s
    return tuple(k for k, _ in sorted(score.items(), key=lambda kv: -kv[1]))


def _verdict(cmp: Comparison, frame: TestFrame, floor: NoiseFloor, before: ChannelTests, after: ChannelTests,
             effects: list) -> Verdict:
    """Step 7: ``unexplained`` if a fitted channel still differs (either test) or a flagged one lost
    less than ``min_explained_fraction`` of its excess, ``explained`` if an effect was named, else
    ``no_mismatch``."""
    cfg, fitted_ch = cmp.cfg, cmp.model.channels
    excess0, regime0 = before.excess, before.regime_score
    excess_cur, regime_cur = after.excess, after.regime_score
    flagged0 = [c for c in fitted_ch if excess0[c] > cfg.excess_threshold]
    flag_r0 = [c for c in fitted_ch if regime0[c] > cfg.regime_threshold]
    still = [c for c in fitted_ch if excess_cur[c] > cfg.excess_threshold or regime_cur[c] > cfg.regime_threshold]
    removed = (all(excess0[c] - excess_cur[c] >= cfg.min_explained_fraction * (excess0[c] - 1.0) for c in flagged0)
               and all(regime0[c] - regime_cur[c] >= cfg.min_explained_fraction * regime0[c] for c in flag_r0))
    lib = [e for e in effects if e.source == "library"]
    if still or (lib and not removed):
        return Verdict(DiagnosisVerdict.UNEXPLAINED, tuple(_locate(cmp, frame, floor, after)),
                       _where_the_rest_lies(cmp, frame, after))
    return Verdict(DiagnosisVerdict.EXPLAINED if effects else DiagnosisVerdict.NO_MISMATCH)


def _residual_rms(cmp: Comparison, floor: NoiseFloor, pred_all: dict) -> ResidualRms:
    p = cmp.problem

    def rms(part=None, raw=False) -> dict:
        out = {}
        for c in floor.channels:
            if raw:
                sel = p.valid_raw[c] if part is None else p.valid_raw[c] & part
                out[c] = float(np.sqrt(np.mean((floor.measured[c] - pred_all[c])[sel] ** 2))) if sel.any() else None
            else:
                sel = p.valid[c] if part is None else p.valid[c] & part
                r = p.residual(c, floor.measured[c], pred_all[c])
                out[c] = float(np.sqrt(np.mean(r[sel] ** 2))) if sel.any() else None
        return out

    return ResidualRms(rms(), rms(~p.fit), rms(raw=True), rms(~p.fit_raw, raw=True))


def _named(params: tuple, theta: np.ndarray) -> dict:
    return {q.name: float(v) for q, v in zip(params, theta, strict=True)}


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
    say = progress or (lambda s: None)
    cmp = band_comparison(model, sample_period_s, cfg)
    nom = _nominal_fit(cmp, say)
    floor = _noise_floor(cmp, nom)
    frame = _test_frame(cmp, nom)
    before = _tests(cmp, frame, floor, floor.predicted)
    say("excess over noise: " + ", ".join(f"{c} {v:.2f}" for c, v in before.excess.items()))
    say("regime score: " + ", ".join(f"{c} {v:.1f}" for c, v in before.regime_score.items()))
    sel = select_effects(cmp, nom, say)
    pred_cur = safe_predict(model, sel.theta, list(sel.active))
    effects = list(sel.effects) + named_references(cmp, sel, pred_cur)
    after = _tests(cmp, frame, floor, cmp.full(pred_cur))
    v = _verdict(cmp, frame, floor, before, after, effects)
    p = cmp.problem
    rms0, rms1 = _residual_rms(cmp, floor, before.predicted), _residual_rms(cmp, floor, after.predicted)
    return Diagnosis(
        verdict=v.verdict, effects=tuple(effects), locations=v.locations, where=v.where, band=cmp.band,
        residual_rms_before=rms0.in_band, residual_rms_after=rms1.in_band,
        residual_rms_holdout_before=rms0.in_band_holdout, residual_rms_holdout_after=rms1.in_band_holdout,
        residual_rms_raw_before=rms0.raw, residual_rms_raw_after=rms1.raw,
        residual_rms_raw_holdout_before=rms0.raw_holdout, residual_rms_raw_holdout_after=rms1.raw_holdout,
        noise_floor=floor.in_band, noise_floor_raw=floor.raw, excess_before=before.excess, excess_after=after.excess,
        ic_before=sel.ic_before, ic_after=sel.ic_after, nominal=_named(model.nominal, sel.theta),
        screening=sel.screening, predicted_before=before.predicted, predicted_after=after.predicted,
        measured=floor.measured, valid=dict(p.valid_raw), held_out=~p.fit_raw, kept=p.idx, kept_valid=dict(p.valid),
        regime_cells_before=before.regime, regime_cells_after=after.regime, regime_labels=frame.labels)


def fit_effect(model: ReplayModel, sample_period_s: float, nominal: dict, candidate: Candidate,
               active: tuple = (), config: DiagnoseConfig | None = None,
               fixed: dict | None = None) -> FittedEffect | None:
    """One candidate fitted on a recording whether or not it would be accepted there.

    For a comparison of two recordings (:mod:`hil.analysis.diagnose.dual_reference`): the candidate a
    diagnosis accepted on one recording, fitted on the other from its diagnosis's nominal parameters
    ``nominal`` ({name: value}) with its accepted effects ``active`` ((Candidate, parameters), ...),
    nominal and candidate refitted together on the fit half (:func:`blf.diagnose.fit.fit_joint`,
    standard uncertainties from its Jacobian, scaled by the reduced chi-square where above 1).

    ``fixed`` ({parameter name: value}, e.g. a shape parameter at the value the other recording found):
    those are held, not fitted (uncertainty 0).

    Returns
    -------
    FittedEffect or None
        ``delta_bic``, ``delta_chi2_holdout``: the chi-square change against the nominal model with
        ``active`` (no penalty); None if the replay fails.
    """
    cfg = config or DiagnoseConfig()
    cmp = band_comparison(model, sample_period_s, cfg)
    p = cmp.problem
    theta = np.array([float(nominal[q.name]) for q in model.nominal])
    pred = safe_predict(model, theta, list(active))
    if pred is None:
        return None
    p.set_floor(model.measured, pred)
    w0 = p.weighted(pred)
    fixed = dict(fixed or {})
    x0 = np.array([float(fixed.get(q.name, q.x0)) for q in candidate.params])
    free = np.array([q.name not in fixed for q in candidate.params])
    joint = fit_joint(p, theta, list(active), candidate, x0, free=free)
    if joint is None:
        return None
    return FittedEffect(candidate.name, candidate.where, candidate.words, _named(candidate.params, joint.x),
                        _named(candidate.params, joint.uncertainty), joint.chi2_fit - p.chi2(w0, p.fit),
                        joint.chi2_holdout - p.chi2(w0, ~p.fit), "fitted for a comparison, not screened",
                        variant=candidate.variant)
