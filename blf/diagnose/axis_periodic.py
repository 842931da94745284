"""A single axis against a reference: forces periodic in position, found, fitted jointly, compared.

Pure: arrays in, frozen dataclasses out (no IO); the periodic physics itself is in
:mod:`blf.diagnose.periodic`. Given both recordings prepared alike (:class:`AxisSamples`) and their
nominal fits, :func:`periodic_pair`

1. finds the periods in each recording's residual against position (:func:`blf.diagnose.periodic.find_periods`)
   and takes their union, periods within two Rayleigh widths of each other being one component (one
   part's order: the period in measured travel moves with the position sensor's scale between
   sessions, by up to 4 % on the Cranfield actuator, about one Rayleigh width of its 119 mm stroke);
2. gives each recording its own period of each component (the peak within one Rayleigh width) and the
   columns of each (:func:`blf.diagnose.periodic.periodic_columns`: per direction of motion, the
   fundamental and the orders up to 3 that the sampling resolves), to be fitted jointly with the
   nominal model (:func:`blf.diagnose.axis_compare.compare_axis`);
3. after that joint fit (:func:`compare_periodic`) compares each component's amplitude per direction
   with the reference's: a change is *named* only when statistically supported (:math:`|z| > z_{min}`)
   and above its floor (N), in each direction of motion apart (the ripple of the Cranfield actuator
   is larger in the direction the load drives the nut, and a fault may change it in one direction only);
4. shows the fit on held-out strokes (every other stroke fitted, the rest held out) with and without
   the periodic terms, and says where along the travel the new recording's component acts
   (:func:`blf.diagnose.periodic.locality`) and, with a stated lead, which order of which part it is
   (:func:`blf.diagnose.periodic.lead_order`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.diagnose.axis_reference import design_columns, fit_axis
from blf.diagnose.periodic import (
    DIRECTIONS,
    FALSE_ALARM,
    find_periods,
    lead_order,
    locality,
    periodic_amplitudes,
    periodic_columns,
    search_range,
)
from blf.errors import AnalysisError

__all__ = ["PeriodicPlan", "PeriodicChange", "AxisPeriodic", "periodic_pair", "compare_periodic",
           "axis_residual", "directions", "profile"]

MAX_ORDER = 3  #: harmonics fitted with a fundamental, where the sampling resolves them


@dataclass(frozen=True)
class PeriodicPlan:
    """The periodic components to fit on both recordings (:func:`periodic_pair`)."""

    periods_new_m: tuple  #: each component's period in the recording diagnosed
    periods_ref_m: tuple  #: and in the reference
    periods_u_m: tuple  #: standard uncertainty of the recording's period (jackknife), m
    orders: tuple  #: per component, the orders fitted
    found_in: tuple  #: per component, where it was found ("recording", "reference", or both)
    columns_new: dict
    columns_ref: dict
    words: str  #: the search (or why there is none)


@dataclass(frozen=True)
class PeriodicChange:
    """One periodic component of the recording against the reference."""

    index: int
    period_m: float
    period_u_m: float
    period_reference_m: float
    amplitude: dict  #: direction -> (new N, u N, reference N, u N, change N, u N, z)
    harmonics: dict  #: order -> (new N, reference N): RMS over directions
    named: tuple  #: directions whose change is named
    change_N: float  #: the named change (mean over the named directions; else over both), N
    change_u_N: float
    amplitude_N: float  #: the recording's amplitude (mean over the same directions), N
    amplitude_reference_N: float
    floor_N: float
    where: object  #: :class:`blf.diagnose.periodic.Locality` on the recording
    lead: object  #: :class:`blf.diagnose.periodic.LeadOrder` or None
    found_in: str
    words: str


@dataclass(frozen=True)
class AxisPeriodic:
    """The periodic comparison: components, the held-out fit of the recording, the search."""

    changes: tuple
    holdout_rms_before_N: float | None  #: held-out strokes, nominal model only
    holdout_rms_after_N: float | None  #: with the periodic terms
    floor_N: float
    words: str
    profiles: tuple = ()  #: (recording, reference) of :func:`profile` at the first component's period


def directions(p) -> np.ndarray:
    """+1/-1 per sample by the sign of the measured speed where compared, 0 elsewhere."""
    return np.where(p.mask.used, np.sign(p.v_m_per_s), 0.0)


def axis_residual(p, ident, fit, extra: dict) -> np.ndarray:
    """Force minus the fitted model over every sample, N (``fit`` from :func:`fit_axis` with ``extra``)."""
    X = design_columns(ident.columns, p.v_m_per_s, p.a_m_per_s2)
    th = np.array([fit.parameters[c] for c in ident.columns])
    r = p.force_N + (0.0 if p.load_N is None else p.load_N) - X @ th
    for name, col in extra.items():
        r = r - fit.parameters[name] * col
    return r


def _orders(period: float, shortest: float) -> tuple:
    return tuple(h for h in range(1, MAX_ORDER + 1) if period / h >= shortest)


def _own_period(p, r, period, ray) -> float:
    from blf.diagnose.periodic import amplitude_spectrum
    f0 = 1.0 / period
    f = np.linspace(f0 - ray, f0 + ray, 81)
    a = amplitude_spectrum(p.q_m, r, directions(p), p.mask.used, 1.0 / f[f > 0])
    return float(1.0 / f[f > 0][int(np.argmax(a))])


def periodic_pair(new, ref, ident, fit_new, fit_ref, extra_new: dict, extra_ref: dict) -> PeriodicPlan:
    """The periodic components of both recordings' residuals against position (after their nominal fits
    with ``extra`` terms), and the columns to fit them jointly with the nominal model."""
    try:
        sn = search_range(new.q_m, new.mask.used, directions(new))
        sr = search_range(ref.q_m, ref.mask.used, directions(ref))
    except AnalysisError as exc:
        return PeriodicPlan((), (), (), (), (), {}, {}, str(exc))
    rn, rr = axis_residual(new, ident, fit_new, extra_new), axis_residual(ref, ident, fit_ref, extra_ref)
    fnew = find_periods(new.q_m, rn, directions(new), new.mask.used, sn)
    fref = find_periods(ref.q_m, rr, directions(ref), ref.mask.used, sr)
    ray = max(sn.rayleigh_per_m, sr.rayleigh_per_m)
    shortest = max(sn.shortest_m, sr.shortest_m)
    comps = []  # [period, u, found_in]
    for where, found in (("recording", fnew), ("reference", fref)):
        for f in found:
            if f.period_m < shortest or f.period_m > min(sn.longest_m, sr.longest_m):
                continue
            same = [c for c in comps if abs(1 / c[0] - 1 / f.period_m) < 2 * ray]
            if same:
                same[0][2] = "both" if same[0][2] != where else where
            else:
                comps.append([f.period_m, f.period_u_m, where])
    pn, pr, us, orders, cn, cr = [], [], [], [], {}, {}
    for i, (period, u, _) in enumerate(comps):
        p_new, p_ref = _own_period(new, rn, period, ray), _own_period(ref, rr, period, ray)
        o = _orders(min(p_new, p_ref), shortest)
        pn.append(p_new)
        pr.append(p_ref)
        found = [f for f in fnew if abs(1 / f.period_m - 1 / p_new) < 2 * ray]
        us.append(found[0].period_u_m if found else u)
        orders.append(o)
        cn |= periodic_columns(new.q_m, directions(new), p_new, o, i)
        cr |= periodic_columns(ref.q_m, directions(ref), p_ref, o, i)
    words = (f"searched {sn.words}; {len(comps)} component(s) found in the residuals against position "
             f"(false-alarm probability {FALSE_ALARM:g} per search)")
    return PeriodicPlan(tuple(pn), tuple(pr), tuple(us), tuple(orders), tuple(c[2] for c in comps), cn, cr, words)


def _holdout(p, ident, extra: dict, cols: dict) -> tuple:
    """Residual RMS (N) on every other stroke of each direction, fitted on the rest: without and with the
    periodic columns."""
    idx = np.flatnonzero(p.mask.used)
    stroke = np.cumsum(np.r_[1, np.diff(idx) > 1])
    sign = np.sign(p.v_m_per_s[idx])
    held = np.zeros(idx.size, bool)
    for s in (1, -1):  # every other stroke of each direction held out
        ids = [g for g in np.unique(stroke[sign == s]) if np.median(sign[stroke == g]) == s]
        held |= np.isin(stroke, ids[1::2])
    fit_half, test = np.zeros(p.mask.used.size, bool), np.zeros(p.mask.used.size, bool)
    fit_half[idx[~held]] = True
    test[idx[held]] = True
    out = []
    for terms in (extra, extra | cols):
        try:
            f = fit_axis(p.force_N, p.v_m_per_s, p.a_m_per_s2, fit_half, ident, p.load_N, extra=terms)
        except AnalysisError:
            return None, None
        out.append(float(np.sqrt(np.mean(axis_residual(p, ident, f, terms)[test] ** 2))))
    return tuple(out)


def _words(amp: dict, named: tuple, period: float, floor: float) -> str:
    def one(d):
        a_n, _, a_r, _, ch, u, z = amp[d]
        return f"{d} {a_r:.3g} -> {a_n:.3g} N ({ch:+.3g} ± {u:.2g} N, z = {z:.1f})"
    body = "; ".join(one(d) for d in amp)
    p = f"a force periodic in position, period {period * 1e3:.4g} mm of travel"
    if not named:
        return f"{p}: amplitude {body}; not named (a change must be supported and above its floor {floor:g} N)"
    verb = "increased" if amp[named[0]][4] > 0 else "decreased"
    how = "in both directions of motion" if len(named) == len(amp) else f"in {named[0]} only"
    return f"{p}, its amplitude {verb} {how}: {body}; named: above its floor {floor:g} N"


def compare_periodic(plan: PeriodicPlan, new, ref, ident, fit_new, fit_ref, floor_N: float, z_min: float,
                     extra_new: dict, lead_m: float | None = None, gear_ratio: float | None = None,
                     extra_ref: dict | None = None, scale_tolerance: float = 0.0) -> AxisPeriodic:
    """Each component's amplitude per direction against the reference's, after the joint fits
    (``fit_new``, ``fit_ref`` with the plan's columns), with where it acts and which order it is."""
    words = plan.words
    try:
        longest = search_range(new.q_m, new.mask.used, directions(new)).longest_m
    except AnalysisError:
        longest = 0.0
    if lead_m and lead_m > longest:
        words += (f"; the stated lead ({lead_m * 1e3:.4g} mm) is longer than half the travel of each direction "
                  f"({longest * 1e3:.4g} mm): a ripple once per turn of the screw cannot be named from this recording "
                  f"(it needs two whole periods)")
    if not plan.periods_new_m:
        return AxisPeriodic((), None, None, floor_N, words)
    resid = axis_residual(new, ident, fit_new, extra_new | plan.columns_new)
    out = []
    for i, (pn, pr, u, o, fin) in enumerate(zip(plan.periods_new_m, plan.periods_ref_m, plan.periods_u_m,
                                                plan.orders, plan.found_in, strict=True)):
        an = periodic_amplitudes(fit_new.parameters, fit_new.uncertainty, i, o)
        ar = periodic_amplitudes(fit_ref.parameters, fit_ref.uncertainty, i, o)
        amp = {}
        for d in DIRECTIONS.values():
            if (d, 1) in an and (d, 1) in ar:
                (a1, u1, _), (a0, u0, _) = an[(d, 1)], ar[(d, 1)]
                uc = float(np.hypot(u1, u0))
                amp[d] = (a1, u1, a0, u0, a1 - a0, uc, (a1 - a0) / uc if uc > 0 else 0.0)
        named = tuple(d for d, v in amp.items() if abs(v[6]) > z_min and abs(v[4]) > floor_N)
        if len(named) == 2 and np.sign(amp[named[0]][4]) != np.sign(amp[named[1]][4]):
            named = (max(named, key=lambda d: abs(amp[d][6])),)
        use = named or tuple(amp)
        ch = float(np.mean([amp[d][4] for d in use])) if use else 0.0
        chu = float(np.sqrt(np.sum([amp[d][5] ** 2 for d in use])) / max(1, len(use)))
        harm = {h: (float(np.sqrt(np.mean([an[(d, h)][0] ** 2 for d in DIRECTIONS.values() if (d, h) in an] or [0]))),
                    float(np.sqrt(np.mean([ar[(d, h)][0] ** 2 for d in DIRECTIONS.values() if (d, h) in ar] or [0]))))
                for h in o}
        own = resid + sum(fit_new.parameters[k] * c for k, c in plan.columns_new.items()
                          if k.startswith(f"periodic{i}_"))
        where = locality(new.q_m, own, directions(new), new.mask.used, pn,
                         search_range(new.q_m, new.mask.used, directions(new)))
        lead = lead_order(pn, u, lead_m, gear_ratio, scale_tolerance=scale_tolerance) if lead_m else None
        words = _words(amp, named, pn, floor_N) + f"; {where.words}" + (f"; {lead.words}" if lead else "")
        out.append(PeriodicChange(i, pn, u, pr, amp, harm, named, ch, chu,
                                  float(np.mean([amp[d][0] for d in use])) if use else 0.0,
                                  float(np.mean([amp[d][2] for d in use])) if use else 0.0,
                                  floor_N, where, lead, fin, words))
    before, after = _holdout(new, ident, extra_new, plan.columns_new)
    prof = tuple(profile(p, ident, f, x, cols, plan.periods_new_m[0])
                 for p, f, x, cols in ((new, fit_new, extra_new, plan.columns_new),
                                       (ref, fit_ref, extra_ref, plan.columns_ref))) if extra_ref is not None else ()
    return AxisPeriodic(tuple(out), before, after, floor_N, words, prof)


def profile(p, ident, fit, extra: dict, cols: dict, period_m: float) -> dict:
    """The effort against position, cycle-averaged: per direction of motion, the force and the model
    without and with the periodic terms, each averaged in position bins of a sixth of the period (N).

    Returns {direction: (bin centres m, force N, model without N, model with N)}."""
    y = p.force_N + (0.0 if p.load_N is None else p.load_N)
    with_p = y - axis_residual(p, ident, fit, extra | cols)
    without = with_p - sum((fit.parameters[k] * c for k, c in cols.items()), np.zeros_like(y))
    d = directions(p)
    out = {}
    width = period_m / 6
    for s, name in DIRECTIONS.items():
        sel = p.mask.used & (d == s)
        if sel.sum() < 10:
            continue
        q = p.q_m[sel]
        k = np.floor((q - q.min()) / width).astype(int)
        n = np.bincount(k).astype(float)
        ok = n >= 3
        out[name] = tuple((np.bincount(k, v[sel])[ok] / n[ok]) for v in (p.q_m, y, without, with_p))
    return out
