"""A single-axis recording against a reference recording (``emacheck diagnose NEW --model single-axis
--reference HEALTHY``): which nominal parameter changed.

The nominal model is identified on the reference and on the new recording alike
(:mod:`blf.diagnose.axis_reference`: masks, identifiability, cluster-robust fit) and each nominal parameter
is compared with its reference value; a change is named only above its relevance floor
(:data:`hil.analysis.diagnose.single_axis.FORCE_FLOOR_N`, ``--force-floor-N``), and only when each
recording's effort sees its known load (:func:`effort_checks`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.analysis.diagnose.results import ident_dict, mask_dict, rounded, rounded_dict
from hil.analysis.diagnose.single_axis import (
    FORCE_FLOOR_N,
    AxisOptions,
    AxisRecording,
    Prepared,
    conversion,
    prepare,
    read_axis,
)
from hil.errors import RecordingError

_EFFECT = {"position_dependent_friction_N_per_m": "position_dependent_friction_change",
           "position_dependent_force_N_per_m": "position_dependent_force_change",
           "position_dependent_force_N_per_m2": "position_dependent_force_change",
           "friction_N": "friction_change", "coulomb_N": "coulomb_friction_change",
           "viscous_N_s_per_m": "viscous_friction_change", "offset_N": "direction_dependent_force_change",
           "mass_kg": "mass_change"}


def _check_pair(new: AxisRecording, ref: AxisRecording) -> None:
    if new.kind != ref.kind or (new.load is None) != (ref.load is None):
        what = lambda r: r.kind + (",load" if r.load is not None else "")  # noqa: E731
        raise RecordingError(f"{ref.path}: reference with other columns ({what(ref)}) than {new.path} ({what(new)})")
    if abs(new.sample_rate_hz / ref.sample_rate_hz - 1) > 0.01:
        raise RecordingError(f"{ref.path}: reference sampled at {ref.sample_rate_hz:.6g} Hz, {new.path} at "
                             f"{new.sample_rate_hz:.6g} Hz: not comparable")


def _common(ref, new, ref_path: Path):
    """The terms both recordings are fitted with: those both can separate.

    The reference must run in every direction and at every speed level of the recording diagnosed
    (else it is too short to identify the nominal model: :class:`RecordingError`); a term only one
    of them can separate (the mass, where only one has acceleration content) is fixed in both, and
    said so."""
    import dataclasses
    lacks = [f"direction {'+' if d > 0 else '-'}" for d in new.directions if d not in ref.directions]
    lacks += [f"speed {s:.4g} m/s" for s in new.speed_levels_m_per_s
              if not any(abs(s / r - 1) <= 0.1 for r in ref.speed_levels_m_per_s)]
    if lacks or not ref.columns:
        raise RecordingError(f"{ref_path}: reference too short to identify the nominal model: no motion in "
                             f"{', '.join(lacks) or 'any direction'} of the recording diagnosed")
    cols = tuple(c for c in new.columns if c in ref.columns)
    dropped = [c for c in new.columns + ref.columns if c not in cols]
    merged = list(new.merged) + [((c,), "", "separable in only one of the two recordings: held in both",
                                  "the same motion in both") for c in dict.fromkeys(dropped)]
    fixed = dict(new.fixed) | dict(ref.fixed) | {c: 0.0 for c in dropped}
    return dataclasses.replace(new, columns=cols, fixed=fixed, merged=tuple(merged))


def _floors(opts: AxisOptions, speed: float, half_stroke: float) -> dict:
    """Floors in each parameter's unit: the force floor at the running speed, or at the end of the stroke."""
    f = opts.force_floor_N
    out = {"friction_N": f, "coulomb_N": f, "offset_N": f}
    if speed > 0:
        out["viscous_N_s_per_m"] = f / speed
    if half_stroke > 0:
        out |= {"position_dependent_friction_N_per_m": f / half_stroke,
                "position_dependent_force_N_per_m": f / half_stroke,
                "position_dependent_force_N_per_m2": f / half_stroke ** 2}
    return out


def _stroke_candidates(pr: Prepared, pn: Prepared, ref: AxisRecording, new: AxisRecording, ident) -> tuple:
    """The terms along the stroke both recordings can separate from the nominal ones: (origin, half stroke,
    columns of the reference, columns of the new recording, not separable [(name, why)])."""
    from blf.diagnose import design_columns, separable, stroke_terms
    q_used = ref.q[pr.mask.used]
    origin, half = float(np.median(q_used)), float(np.ptp(q_used)) / 2
    tr, tn = stroke_terms(ref.q, pr.v, origin), stroke_terms(new.q, pn.v, origin)
    keep, drop = [], []
    for name in tr:
        ok = all(separable(design_columns(ident.columns, p.v, p.a)[p.mask.used], t[name][p.mask.used])
                 for p, t in ((pr, tr), (pn, tn)))
        (keep if ok else drop).append(name)
    # the two force terms are one candidate: both or neither
    return (origin, half, {k: tr[k] for k in keep}, {k: tn[k] for k in keep},
            [(n, "not separable from the nominal terms in both recordings") for n in drop])


def reference_diagnosis(new_path: Path, ref_path: Path, opts: AxisOptions) -> dict:
    """diagnosis.json of a single-axis recording against a reference (nothing written here).

    :class:`RecordingError` (exit 3) for a reference of the other model, other sample rate or other
    columns, a current with no way to convert it, a reference too short to identify the nominal model.
    """
    from blf.diagnose import compare_fits, fit_axis
    from blf.errors import AnalysisError
    new = read_axis(new_path)
    try:
        ref = read_axis(ref_path)
    except RecordingError as exc:
        raise RecordingError(f"--reference: {exc} (a single-axis recording is needed)") from None
    _check_pair(new, ref)
    k, conv_words, k_rel_u = conversion(new, opts, ref)
    pn, pr = prepare(new, opts, k), prepare(ref, opts, k)
    ident = _common(pr.ident, pn.ident, ref.path)
    origin, half, xr, xn, not_cand = _stroke_candidates(pr, pn, ref, new, ident)
    try:
        fr = fit_axis(pr.force, pr.v, pr.a, pr.mask.used, ident, ref.load, extra=xr)
    except AnalysisError as exc:
        raise RecordingError(f"{ref.path}: reference too short to identify the nominal model ({exc})") from None
    try:
        fn = fit_axis(pn.force, pn.v, pn.a, pn.mask.used, ident, new.load, extra=xn)
    except AnalysisError as exc:
        raise RecordingError(f"{new.path}: {exc}") from None
    floors = _floors(opts, fr.running_speed_m_per_s, half)
    changes = compare_fits(fn, fr, floors, opts.z_min)
    effort = effort_checks(fn, fr, new, ref, pn, pr, opts, k_rel_u)
    effects = [_effect(c) for c in changes if c.named] if effort["trusted"] else []
    verdict = "untrusted_effort" if not effort["trusted"] else "explained" if effects else "no_mismatch"
    return {
        "verdict": verdict, "model": "single-axis", "mode": "reference", "effort": effort,
        "effects": effects, "where": [], "locations": [],
        "band": {"cutoff_hz": None, "step": 1, "words": "every sample kept (a least-squares fit of a model linear "
                 "in its parameters, uncertainties robust to correlation along a stroke)"},
        "reference": {"recording": str(ref.path), "nominal": rounded_dict(fr.parameters),
                      "uncertainty": rounded_dict(fr.uncertainty), "residual_rms_N": rounded(fr.residual_rms_N),
                      "mask": mask_dict(pr.mask)},
        "nominal": rounded_dict(fn.parameters), "nominal_uncertainty": rounded_dict(fn.uncertainty),
        "residual_rms_N": rounded(fn.residual_rms_N), "mask": mask_dict(pn.mask),
        "changes": [_change(c, effort["trusted"]) for c in changes],
        "floor": {"force_N": opts.force_floor_N, "z_min": opts.z_min, "words": (
            "a change is named only when |change| > z_min combined standard uncertainties and > its floor; "
            f"force parameters {opts.force_floor_N:g} N" + (" (default: 3 x RMS of the healthy Cranfield "
                                                            "actuator's session-to-session changes)"
                                                            if opts.force_floor_N == FORCE_FLOOR_N else
                                                            " (stated)"))},
        "identifiability": ident_dict(ident) | {"not_candidates": [{"name": n, "why": w} for n, w in not_cand]},
        "stroke": {"origin_m": rounded(origin), "half_stroke_m": rounded(half), "words": (
            "terms along the stroke screened against the reference (fitted beside the nominal ones on both); "
            "their floors: the force floor at the end of the stroke, half_stroke_m from the origin")},
        "conversion": conv_words, "sample_rate_hz": rounded(new.sample_rate_hz),
        "running_speed_m_per_s": rounded(fn.running_speed_m_per_s),
    }


def effort_checks(fn, fr, new: AxisRecording, ref: AxisRecording, pn, pr, opts: AxisOptions, k_rel_u: float) -> dict:
    """diagnosis.json's ``effort``: does each recording's effort see its known load
    (:func:`blf.diagnose.axis_effort.effort_load_check`, allowance the force floor)? ``trusted`` is False when
    either does not: its force content is contradicted by the load, nothing is diagnosed from it."""
    from blf.diagnose import effort_load_check
    out, bad = {}, []
    identified_on_ref = opts.current_a_per_N is None and new.kind == "current"
    for key, fit, rec, p in (("recording", fn, new, pn), ("reference", fr, ref, pr)):
        c = effort_load_check(fit, rec.load, p.mask.used, opts.force_floor_N, opts.z_min, k_rel_u)
        words = c.words + ("; the conversion was identified on this load (consistent by construction)"
                           if key == "reference" and identified_on_ref and c.made else "")
        out[key] = {"path": str(rec.path), "checked": c.made, "trusted": c.trusted, "load_N": rounded(c.load_N),
                    "seen_N": rounded(c.seen_N), "uncertainty_N": rounded(c.uncertainty_N), "words": words}
        if c.made and not c.trusted:
            bad.append(f"{rec.path.name}: {c.words}")
    out["trusted"] = not bad
    out["words"] = ("; ".join(bad) if bad else "each effort that could be checked sees its known load with the "
                    "sign the conversion predicts")
    return out


def _change(c, trusted: bool = True) -> dict:
    words = c.words if trusted else c.words.split("; ")[0] + "; not diagnosed: the effort is not trusted"
    return {"parameter": c.name, "value": rounded(c.value), "reference": rounded(c.reference),
            "change": rounded(c.change), "uncertainty": rounded(c.uncertainty), "z": rounded(c.z, 4),
            "floor": rounded(c.floor), "supported": c.supported, "above_floor": c.relevant,
            "named": c.named and trusted, "words": words}


def _effect(c) -> dict:
    return {"name": _EFFECT.get(c.name, c.name + "_change"), "where": "axis", "words": c.words,
            "source": "reference", "parameters": {c.name: rounded(c.value)},
            "uncertainty": {c.name: rounded(c.uncertainty)}, "change": {c.name: rounded(c.change)},
            "floor": {c.name: rounded(c.floor)}, "delta_bic": None, "delta_chi2_holdout": None,
            "evidence": f"z = {c.z:.1f}, |change| {abs(c.change):.4g} > floor {c.floor:g}"}
