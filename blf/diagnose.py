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

Each step is a function of this module with a frozen record as its result:
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

from blf.band import make_band
from blf.diagnose_fit import (
    CandidateFit,
    JointFit,
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
from blf.diagnose_model import (
    EIGEN_FLOOR,
    Candidate,
    DiagnoseConfig,
    Diagnosis,
    DiagnosisVerdict,
    FittedEffect,
    Location,
    NominalCovariance,
    Param,
    ParamVector,
    Reference,
    RegimeScore,
    ReplayModel,
    place_of,
)
from blf.diagnose_records import (
    Accepted,
    ChannelTests,
    Comparison,
    NamedReference,
    NoiseFloor,
    NominalFit,
    Refit,
    ResidualRms,
    Screened,
    Screening,
    Selection,
    Standing,
    TestFrame,
    Verdict,
)
from blf.errors import AnalysisError
from blf.mismatch import excess, regime_cells, regime_score, regime_words, window_scores
from blf.validate import positive_scalar

#: the model's vocabulary and the result (:mod:`blf.diagnose_model`) are imported from here
__all__ = ["Param", "ParamVector", "Candidate", "Reference", "ReplayModel", "DiagnoseConfig", "Location",
           "FittedEffect", "Diagnosis", "DiagnosisVerdict", "RegimeScore", "NominalCovariance", "EIGEN_FLOOR",
           "diagnose", "fit_effect", "place_of"]


def band_comparison(model: ReplayModel, sample_period_s: float, cfg: DiagnoseConfig) -> Comparison:
    """Step 0: the band the model claims, the kept samples and the halves (also for blf.diagnose_cov)."""
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


def _standing(cmp: Comparison, theta: np.ndarray, active: tuple) -> Standing:
    """The model so far, and the linear re-adjustment of its nominal parameters (variable projection)."""
    p = cmp.problem
    wb = p.weighted(safe_predict(cmp.model, theta, list(active)))
    proj = Projector(p, nominal_jacobian(p, theta, list(active), wb))
    _, rf_b, _ = proj.solve(wb)
    return Standing(theta, active, p.chi2(wb, p.fit), p.chi2(wb, ~p.fit), proj, rf_b, p.vec(wb, p.fit))


def _screen(cmp: Comparison, cur: Standing, taken: set) -> Screening:
    """Step 4: every candidate not yet named, linearised, ranked by the chi-square it removes less
    its BIC penalty with the samples it acts on."""
    rows, pen = [], {}
    for cand in cmp.model.candidates:
        if (cand.name, cand.where) in taken:
            continue
        sc = screen(cmp.problem, cur.projector, cur.theta, list(cur.active), cand, cur.residual_fit, cur.weighted_fit)
        if sc is None:
            continue
        red, n_eff = sc
        pen[cand] = len(cand.params) * float(np.log(max(n_eff, 2)))
        rows.append(Screened(cand, red, red - pen[cand]))
    rows.sort(key=lambda s: -s.gain)
    log = [{"name": s.candidate.name, "where": s.candidate.where, "variant": s.candidate.variant,
            "delta_chi2_linear": round(s.delta_chi2, 1), "delta_bic_linear": round(-s.gain, 1)} for s in rows]
    return Screening(tuple(rows), pen, log)


def _refit_row(cand: Candidate, fit: CandidateFit, penalty: float, chi_fit: float, chi_val: float) -> Refit:
    return Refit((fit.chi2_fit - chi_fit) + penalty, fit.chi2_holdout - chi_val, cand, fit)


def _forms_alike(refits: list, where: str, variant: str, margin: float) -> list:
    """The refits of the forms of one physics at ``where`` (``variant``) whose BIC lies within
    ``margin`` of the best of them: the forms the recording cannot tell apart (step 5)."""
    forms = [r for r in refits if variant and (r.candidate.where, r.candidate.variant) == (where, variant)]
    if not forms:
        return []
    lim = min(r.delta_bic for r in forms) + margin
    return [r for r in forms if r.delta_bic <= lim]


def _prefer_simpler_law(refits: list, library: tuple, pen: dict, taken: set, margin: float,
                        refit: Callable[[Candidate], CandidateFit | None], chi_fit: float, chi_val: float,
                        say: Callable[[str], None]) -> list:
    """Among forms of one physics at one place (same ``where`` and non-empty ``variant``, e.g. the
    friction laws of a drive) whose refitted BIC lies within ``margin`` of the best, the one with
    the fewest parameters goes first, then the one listed first in the model's library (which lists
    the simpler law first): the recording cannot tell them apart (at the check's two sweep speeds,
    1-3 mm/s, Coulomb, viscous and Stribeck friction differ only at the few reversals, and a
    direction-dependent friction at its size looks like a Coulomb one), and the simpler law claims
    less. Beyond ``margin`` the better BIC decides, so a form with more parameters earns them by
    evidence. The simpler forms not yet refitted are refitted here. ``refits`` are :class:`Refit`
    sorted by BIC change, best first."""
    if not refits or not refits[0].candidate.variant:
        return refits
    best = refits[0].candidate
    order = {c: i for i, c in enumerate(library)}
    have = {r.candidate for r in refits}
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
            refits.append(_refit_row(c, fitted, pen[c], chi_fit, chi_val))
    refits.sort(key=lambda r: r.delta_bic)
    tied = _forms_alike(refits, best.where, best.variant, margin)
    first = min(tied, key=lambda r: (len(r.candidate.params), order.get(r.candidate, len(order))))
    return [first] + [r for r in refits if r is not first]


def _refits(cmp: Comparison, cur: Standing, scr: Screening, taken: set, say: Callable[[str], None]) -> list:
    """Step 5, the refits: the best ``refit_top`` candidates above ``bic_margin``, refitted, best
    first (the simplest of the forms of one physics the recording cannot tell apart first)."""
    cfg, p = cmp.cfg, cmp.problem

    def refit(cand: Candidate) -> CandidateFit | None:
        return fit_candidate(p, cur.projector, cur.theta, list(cur.active), cand)

    refits = []
    for s in scr.ranked[: cfg.refit_top]:
        if s.gain <= cfg.bic_margin:
            break
        say(f"refit {s.candidate.name} at {s.candidate.where}")
        fitted = refit(s.candidate)
        if fitted is not None:
            refits.append(_refit_row(s.candidate, fitted, scr.penalty[s.candidate], cur.chi2_fit, cur.chi2_holdout))
    refits.sort(key=lambda r: r.delta_bic)
    return _prefer_simpler_law(refits, cmp.model.candidates, scr.penalty, taken, cfg.form_margin, refit,
                               cur.chi2_fit, cur.chi2_holdout, say)


def _passes(cfg: DiagnoseConfig, delta_bic: float, delta_chi2_holdout: float) -> bool:
    """Both acceptance tests: BIC on the fit half, chi-square on the held-out half."""
    return delta_bic < -cfg.bic_margin and delta_chi2_holdout < -cfg.holdout_margin


def _exact_fit(cmp: Comparison, cur: Standing, r: Refit, penalty: float) -> JointFit | None:
    """A refit on the exact replay: the re-adjustment only ranks. First the linearised step itself;
    if the replay disagrees with it or a bound cuts it (then it is not the bounded optimum: a shared
    nominal term held at its bound leaves the rest of its channel unfitted), nominal and candidate
    refitted together."""
    model, p, cfg = cmp.model, cmp.problem, cmp.cfg
    scale = np.array([q.scale for q in model.nominal])
    th_lin = cur.theta + r.fit.nominal_step * scale
    th_new = clip_nominal(model, th_lin)
    pr = safe_predict(model, th_new, list(cur.active) + [(r.candidate, r.fit.x)]) \
        if np.array_equal(th_new, th_lin) else None
    exact = None
    if pr is not None:
        wn = p.weighted(pr)
        exact = JointFit(th_new, r.fit.x, r.fit.uncertainty, p.chi2(wn, p.fit), p.chi2(wn, ~p.fit))
    if exact is None or not (exact.chi2_fit - cur.chi2_fit + penalty < -cfg.bic_margin
                             and exact.chi2_holdout - cur.chi2_holdout < -cfg.holdout_margin):
        joint = fit_joint(p, cur.theta, list(cur.active), r.candidate, r.fit.x)
        if joint is not None and (exact is None or joint.chi2_fit < exact.chi2_fit):
            exact = joint
    return exact


def _accept(cmp: Comparison, cur: Standing, refits: list, pen: dict, say: Callable[[str], None]) -> Accepted | None:
    """Step 5, the acceptance: the first refit that passes both tests on the linearisation and then on
    the exact replay (:func:`_exact_fit`); None if none does."""
    cfg = cmp.cfg
    for r in refits:
        if not _passes(cfg, r.delta_bic, r.delta_chi2_holdout):
            continue
        exact = _exact_fit(cmp, cur, r, pen[r.candidate])
        if exact is None:
            continue
        dbic = (exact.chi2_fit - cur.chi2_fit) + pen[r.candidate]
        dval = exact.chi2_holdout - cur.chi2_holdout
        if _passes(cfg, dbic, dval):
            return Accepted(r.candidate, dbic, dval, exact)
        say(f"candidate {r.candidate.name} at {r.candidate.where} not accepted (dBIC {dbic:.1f}, held-out {dval:.1f})")
    return None


def _place(cmp: Comparison, cur: Standing, refits: list, chosen: Accepted, pen: dict,
           say: Callable[[str], None]) -> Accepted:
    """Step 5, the place: when the same physics passes at the other place too, the linearised
    re-adjustment of the nominal ranks places poorly when the term moves the nominal far (a
    stiffening first read as a stiffer spring), so the place is decided by the joint nonlinear fit of
    the nominal and each of the two."""
    cfg, c0 = cmp.cfg, chosen.candidate
    twin = next((r for r in refits if r.candidate is not c0 and r.candidate.name == c0.name
                 and r.candidate.variant == c0.variant and r.candidate.where != c0.where
                 and _passes(cfg, r.delta_bic, r.delta_chi2_holdout)), None)
    if twin is None:
        return chosen
    say(f"{c0.name} at {c0.where} or {twin.candidate.where}: both refitted with the nominal")
    for c, x0 in ((c0, chosen.fit.x), (twin.candidate, twin.fit.x)):
        joint = fit_joint(cmp.problem, cur.theta, list(cur.active), c, x0)
        if joint is None:
            continue
        dbic, dval = (joint.chi2_fit - cur.chi2_fit) + pen[c], joint.chi2_holdout - cur.chi2_holdout
        if dbic < min(chosen.delta_bic, -cfg.bic_margin) and dval < -cfg.holdout_margin:
            chosen = Accepted(c, dbic, dval, joint)
    return chosen


def _library_effect(cfg: DiagnoseConfig, cur: Standing, scr: Screening, refits: list, a: Accepted) -> FittedEffect:
    """The effect of an accepted candidate, its evidence in words: what it removed, the next best
    candidate, and the forms of its physics the recording could not tell from it (said, not hidden)."""
    cand = a.candidate
    others = [s for s in scr.ranked if s.candidate is not cand]
    ev = (f"chi-square on the fit half reduced by {cur.chi2_fit - a.fit.chi2_fit:.0f} (BIC {a.delta_bic:+.0f}), on "
          f"the held-out half by {-a.delta_chi2_holdout:.0f}; "
          + (f"next best candidate {others[0].candidate.name} at {others[0].candidate.where} explains "
             f"{others[0].delta_chi2:.0f} (linearised)" if others else "no other candidate"))
    alike = [r for r in _forms_alike(refits, cand.where, cand.variant, cfg.form_margin) if r.candidate is not cand]
    if alike:
        ev += (f"; as good within {cfg.form_margin:g} BIC units, so the form with the fewest parameters is "
               "named: " + ", ".join(f"{r.candidate.name} (BIC {r.delta_bic:+.1f}, linearised)" for r in alike))
    return FittedEffect(name=cand.name, where=cand.where, words=cand.words,
                        parameters={q.name: float(v) for q, v in zip(cand.params, a.fit.x, strict=True)},
                        uncertainty={q.name: float(u) for q, u in zip(cand.params, a.fit.uncertainty, strict=True)},
                        delta_bic=float(a.delta_bic), delta_chi2_holdout=float(a.delta_chi2_holdout), evidence=ev,
                        variant=cand.variant)


def _ln_n(p: Problem) -> float:
    """ln N of BIC's penalty, N the kept samples of the fit half."""
    return float(np.log(max(p.nfit, 2)))


def _select(cmp: Comparison, nom: NominalFit, say: Callable[[str], None]) -> Selection:
    """Steps 4-6, forward selection: screening, refit and acceptance, place, up to ``max_effects``
    rounds while a candidate passes both tests."""
    model, p, cfg = cmp.model, cmp.problem, cmp.cfg
    pen_cur = len(model.nominal) * _ln_n(p)
    ic0 = p.chi2(p.weighted(nom.predicted), p.fit) + pen_cur
    theta, active, effects, log, ic_cur = nom.theta, (), [], [], ic0
    for _round in range(cfg.max_effects):
        cur = _standing(cmp, theta, active)
        say("screening candidates")
        taken = {(e.name, e.where) for e in effects}
        scr = _screen(cmp, cur, taken)
        log.append(scr.log)
        refits = _refits(cmp, cur, scr, taken, say)
        chosen = _accept(cmp, cur, refits, scr.penalty, say)
        if chosen is None:
            break
        chosen = _place(cmp, cur, refits, chosen, scr.penalty, say)
        theta, active = chosen.fit.theta, active + ((chosen.candidate, chosen.fit.x),)
        pen_cur += scr.penalty[chosen.candidate]
        ic_cur = chosen.fit.chi2_fit + pen_cur
        effects.append(_library_effect(cfg, cur, scr, refits, chosen))
        say(f"accepted {chosen.candidate.name} at {chosen.candidate.where}")
    return Selection(theta, active, tuple(effects), tuple(log), float(ic0), float(ic_cur))


def _reference_effects(named: list, refs: tuple, nominal: tuple, lnN: float) -> list:
    """The effects of the named nominal parameters (:class:`NamedReference`).

    References sharing a ``common`` key that are all named and whose relative deviations
    :math:`d_i = v_i / r_i - 1` agree within 3 combined standard uncertainties are named once, as
    the ``common`` physics with their weighted mean deviation: the recording cannot tell one shared
    cause from the same error at every place (both LVDTs reading alike against the motor angles is
    the motor-to-ram ratio differing from the profile's)."""
    out, done = [], set()
    for n in named:
        ref = n.reference
        if ref in done:
            continue
        if ref.common:
            group = [r for r in refs if r.common == ref.common]
            rows = [m for m in named if m.reference in group]
            if len(rows) == len(group) > 1 and all(m.reference.value != 0.0 for m in rows):
                d = np.array([m.value / m.reference.value - 1.0 for m in rows])
                u = np.array([m.uncertainty / abs(m.reference.value) for m in rows])
                if np.ptp(d) <= 3.0 * float(np.sqrt(np.sum(u ** 2))):
                    w = 1.0 / np.maximum(u, 1e-300) ** 2
                    name, where, words, param = ref.common
                    mean, sd_mean = float(np.sum(w * d) / np.sum(w)), float(1.0 / np.sqrt(np.sum(w)))
                    done.update(group)
                    out.append(FittedEffect(
                        name, where, words, {param: mean}, {param: sd_mean},
                        float(-sum(m.delta_chi2_fit - lnN for m in rows)),
                        float(-sum(m.delta_chi2_holdout for m in rows)),
                        "nominal parameters " + ", ".join(f"{nominal[m.reference.index].name} = {m.value:.6g}"
                                                          for m in rows)
                        + " against " + ", ".join(f"{m.reference.value:.6g}" for m in rows)
                        + f": the same relative deviation, {mean:+.3g} ± {sd_mean:.2g}", "nominal"))
                    continue
        out.append(FittedEffect(
            ref.name, ref.where, ref.words, {ref.param: n.value - ref.offset}, {ref.param: n.uncertainty},
            float(-(n.delta_chi2_fit - lnN)), float(-n.delta_chi2_holdout),
            f"nominal parameter {nominal[ref.index].name} = {n.value:.6g} against the simulator's "
            f"{ref.value:.6g}: holding it there costs {n.delta_chi2_fit:.0f} in chi-square on the fit half and "
            f"{n.delta_chi2_holdout:.0f} on the held-out half", "nominal"))
    return out


def _references(cmp: Comparison, sel: Selection, pred_cur: dict) -> list:
    """Step 6: the nominal parameters with a reference value (:class:`Reference`) that holding there
    costs more than BIC's penalty and ``bic_margin`` on the fit half and ``holdout_margin`` on the
    held-out half, as effects."""
    model, p, cfg = cmp.model, cmp.problem, cmp.cfg
    refs = tuple(getattr(model, "references", ()) or ())
    if not refs:
        return []
    lnN = _ln_n(p)
    active = list(sel.active)
    wc = p.weighted(pred_cur)
    Jn = nominal_jacobian(p, sel.theta, active, wc)
    _, rf_c, rv_c = Projector(p, Jn).solve(wc)
    cf, cv = float(rf_c @ rf_c), float(rv_c @ rv_c)
    named = []
    for ref in refs:
        res = reference_test(p, sel.theta, active, Jn, ref.index, ref.value, cf, cv)
        if res is None:
            continue
        if res.delta_chi2_fit > lnN + cfg.bic_margin and res.delta_chi2_holdout > cfg.holdout_margin:
            named.append(NamedReference(ref, float(sel.theta[ref.index]), res.uncertainty, res.delta_chi2_fit,
                                        res.delta_chi2_holdout))
    return _reference_effects(named, refs, model.nominal, lnN)


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
    sel = _select(cmp, nom, say)
    pred_cur = safe_predict(model, sel.theta, list(sel.active))
    effects = list(sel.effects) + _references(cmp, sel, pred_cur)
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

    For a comparison of two recordings (:mod:`hil.analysis.diagnose_dual_ref`): the candidate a
    diagnosis accepted on one recording, fitted on the other from its diagnosis's nominal parameters
    ``nominal`` ({name: value}) with its accepted effects ``active`` ((Candidate, parameters), ...),
    nominal and candidate refitted together on the fit half (:func:`blf.diagnose_fit.fit_joint`,
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
