"""Steps 4 to 6 of the diagnosis (:func:`blf.diagnose.engine.diagnose`): screen the library against the
standing model, refit the best candidates jointly with the nominal parameters, accept one only if BIC
and the held-out half both improve, decide its place, and name the reference parameters that moved.

:func:`select_effects` runs the rounds of steps 4 and 5 and returns a :class:`Selection`;
:func:`named_references` is step 6. The module docstring of :mod:`blf.diagnose.engine` gives the
method and its equations.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from blf.diagnose.fit import (
    CandidateFit,
    JointFit,
    Problem,
    Projector,
    clip_nominal,
    fit_candidate,
    fit_joint,
    nominal_jacobian,
    reference_test,
    safe_predict,
    screen,
)
from blf.diagnose.model import Candidate, DiagnoseConfig, FittedEffect
from blf.diagnose.records import (
    Accepted,
    Comparison,
    NamedReference,
    NominalFit,
    Refit,
    Screened,
    Screening,
    Selection,
    Standing,
)

__all__ = ["select_effects", "named_references"]


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


def select_effects(cmp: Comparison, nom: NominalFit, say: Callable[[str], None]) -> Selection:
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


def named_references(cmp: Comparison, sel: Selection, pred_cur: dict) -> list:
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
