"""A single-axis recording against a reference recording (``emacheck diagnose NEW --model single-axis
--reference HEALTHY``): which nominal parameter changed.

Both recordings are read and prepared alike (:func:`hil.analysis.diagnose.single_axis.prepared_pair`), then
compared in one pure step (:func:`blf.diagnose.axis_compare.compare_axis`: the nominal model identified on
both, each nominal parameter against its reference value, named only above its relevance floor,
:data:`hil.analysis.diagnose.single_axis.FORCE_FLOOR_N` or ``--force-floor-N``, and only when each
recording's effort sees its known load); here that comparison becomes diagnosis.json.
"""

from __future__ import annotations

from pathlib import Path

from hil.analysis.diagnose.results import ident_dict, mask_dict, rounded, rounded_dict
from hil.analysis.diagnose.single_axis import FORCE_FLOOR_N, AxisOptions, prepared_pair
from hil.errors import RecordingError

_EFFECT = {"position_dependent_friction_N_per_m": "position_dependent_friction_change",
           "position_dependent_force_N_per_m": "position_dependent_force_change",
           "position_dependent_force_N_per_m2": "position_dependent_force_change",
           "friction_N": "friction_change", "coulomb_N": "coulomb_friction_change",
           "viscous_N_s_per_m": "viscous_friction_change", "offset_N": "direction_dependent_force_change",
           "mass_kg": "mass_change"}


def reference_diagnosis(new_path: Path, ref_path: Path, opts: AxisOptions, more_refs: tuple = (),
                        floor_stated: bool = False) -> dict:
    """diagnosis.json of a single-axis recording against a reference (nothing written here).

    ``more_refs``: further healthy references; with them the floors are measured from the spread of all
    (:func:`hil.analysis.diagnose.coverage.floors_from_references`; a force floor ``floor_stated`` is kept).
    The tracking error is compared too and set against the effort
    (:func:`hil.analysis.diagnose.witness.apply_witness`).

    :class:`RecordingError` (exit 3) for a reference of the other model, other sample rate or other
    columns, a current with no way to convert it, a reference too short to identify the nominal model.
    """
    import dataclasses

    from blf.diagnose import compare_axis
    from blf.errors import AnalysisError
    from hil.analysis.diagnose import coverage, witness
    w_floors, cov = witness.WITNESS_FLOORS, coverage.default_coverage(floor_stated)
    if more_refs:
        force_floor, w_floors, cov = coverage.floors_from_references((ref_path, *more_refs), opts, floor_stated)
        opts = dataclasses.replace(opts, force_floor_N=force_floor)
    pair = prepared_pair(new_path, ref_path, opts)
    new, ref, pn, pr = pair.new, pair.ref, pair.prepared_new, pair.prepared_ref
    try:
        cmp = compare_axis(pn, pr, opts.force_floor_N, opts.z_min, pair.gain_rel_u, opts.periodic_floor_N,
                           opts.screw_lead_m, opts.gear_ratio, opts.position_scale_tolerance)
    except AnalysisError as exc:
        raise RecordingError(str(exc)) from None
    fn, fr, ident, changes = cmp.recording, cmp.reference, cmp.ident, cmp.changes
    origin, half, not_cand, conv_words = cmp.origin_m, cmp.half_stroke_m, cmp.not_candidates, pair.conversion_words
    effort = effort_checks(cmp, pair, opts)
    from hil.analysis.diagnose.periodic import periodic_dict, periodic_effects
    effects = [_effect(c) for c in changes if c.named] + periodic_effects(cmp.periodic)
    effects = effects if effort["trusted"] else []
    verdict = "untrusted_effort" if not effort["trusted"] else "explained" if effects else "no_mismatch"
    floor_words = (f"force parameters {opts.force_floor_N:g} N" + (
        " (measured from the references' spread)" if cov.get("measured") and "force_N" in cov["measured"] else
        " (default: 3 x RMS of the healthy Cranfield actuator's changes between halves of one session)"
        if opts.force_floor_N == FORCE_FLOOR_N else " (stated)"))
    periods = witness.named_periods(cmp.periodic) if effort["trusted"] else ((), ())
    w_changes, w_section = witness.compare_pair(new, ref, w_floors, opts.z_min, periods)
    data = {
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
            + floor_words + f"; the tracking error's lag {1e6 * w_floors['tracking_lag_m']:.3g} um, jitter "
            f"{100 * w_floors['tracking_jitter_ratio']:.3g} %"),
            "tracking_lag_m": rounded(w_floors["tracking_lag_m"]),
            "tracking_jitter_ratio": rounded(w_floors["tracking_jitter_ratio"]), "coverage": cov},
        "identifiability": ident_dict(ident) | {"not_candidates": [{"name": n, "why": w} for n, w in not_cand]},
        "stroke": {"origin_m": rounded(origin), "half_stroke_m": rounded(half), "words": (
            "terms along the stroke screened against the reference (fitted beside the nominal ones on both); "
            "their floors: the force floor at the end of the stroke, half_stroke_m from the origin")},
        "conversion": conv_words, "sample_rate_hz": rounded(new.sample_rate_hz),
        "running_speed_m_per_s": rounded(fn.running_speed_m_per_s),
    } | ({"periodic": periodic_dict(cmp.periodic, effort["trusted"])} if cmp.periodic is not None else {}) | (
        {"notes": list(new.notes + ref.notes)} if new.notes + ref.notes else {})
    return witness.apply_witness(data, w_changes, w_section)


def effort_checks(cmp, pair, opts: AxisOptions) -> dict:
    """diagnosis.json's ``effort``: does each recording's effort see its known load
    (:func:`blf.diagnose.axis_effort.effort_load_check`, allowance the force floor; ``cmp``:
    :class:`blf.diagnose.axis_compare.AxisComparison`)? ``trusted`` is False when either does not: its force
    content is contradicted by the load, nothing is diagnosed from it."""
    out, bad = {}, []
    identified_on_ref = opts.current_a_per_N is None and pair.new.kind == "current"
    for key, c, rec in (("recording", cmp.effort_recording, pair.new), ("reference", cmp.effort_reference, pair.ref)):
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
