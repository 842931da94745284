"""Forces periodic in position in diagnosis.json (``periodic``, and the effects named from it).

The comparison itself is pure (:mod:`blf.diagnose.axis_periodic`, :mod:`blf.diagnose.periodic`); here
each component becomes its entry: its period in metres of travel (``period_m``), its amplitude in
newtons (``amplitude_N``) in the recording and the reference, per direction of motion, the change with
its uncertainty, the floor, where along the travel and, with a stated lead, which order of which part.
"""

from __future__ import annotations

from hil.analysis.diagnose.results import rounded


def _component(c, trusted: bool) -> dict:
    per_dir = {d: {"amplitude_N": rounded(v[0]), "amplitude_u_N": rounded(v[1]), "reference_N": rounded(v[2]),
                   "reference_u_N": rounded(v[3]), "change_N": rounded(v[4]), "uncertainty_N": rounded(v[5]),
                   "z": rounded(v[6], 4), "named": d in c.named and trusted}
               for d, v in c.amplitude.items()}
    out = {"period_m": rounded(c.period_m), "period_u_m": rounded(c.period_u_m),
           "period_reference_m": rounded(c.period_reference_m), "found_in": c.found_in,
           "amplitude_N": rounded(c.amplitude_N), "amplitude_reference_N": rounded(c.amplitude_reference_N),
           "change_N": rounded(c.change_N), "uncertainty_N": rounded(c.change_u_N), "floor_N": rounded(c.floor_N),
           "named": bool(c.named) and trusted, "directions": per_dir,
           "harmonics": [{"order": h, "amplitude_N": rounded(a), "reference_N": rounded(b)}
                         for h, (a, b) in c.harmonics.items()],
           "where": {"uniform": c.where.uniform, "span_m": [rounded(x) for x in c.where.span_m],
                     "share": rounded(c.where.share), "bin_edges_m": [rounded(x) for x in c.where.bin_edges_m],
                     "bin_amplitudes_N": [rounded(x) for x in c.where.bin_amplitudes_N], "words": c.where.words},
           "words": c.words if trusted else c.words + "; not diagnosed: the effort is not trusted"}
    if c.lead is not None:
        out["order"] = {"part": c.lead.part, "order": rounded(c.lead.order), "order_u": rounded(c.lead.order_u),
                        "nearest": c.lead.nearest, "contradicts_stated_lead": c.lead.contradicts,
                        "scale_difference": rounded(c.lead.scale_difference),
                        "words": c.lead.words}
    return out


def _profile(prof: dict) -> dict:
    return {d: {k: [round(float(x), 6 if k == "q_m" else 2) for x in arr]
                for k, arr in zip(("q_m", "force_N", "model_without_N", "model_with_N"), v, strict=True)}
            for d, v in prof.items()}


def periodic_dict(p, trusted: bool = True) -> dict:
    """diagnosis.json's ``periodic`` from :class:`blf.diagnose.axis_periodic.AxisPeriodic`; ``profile``: the
    effort against position, cycle-averaged (bins of a sixth of the first component's period), of the
    recording and the reference, with each one's model without and with the periodic terms."""
    return {"components": [_component(c, trusted) for c in p.changes], "floor_N": rounded(p.floor_N),
            **({"profile": {"period_m": rounded(p.changes[0].period_m), "recording": _profile(p.profiles[0]),
                            "reference": _profile(p.profiles[1])}} if p.profiles else {}),
            "holdout_rms_before_N": rounded(p.holdout_rms_before_N),
            "holdout_rms_after_N": rounded(p.holdout_rms_after_N),
            "words": p.words + ("; held-out strokes (every other stroke of each direction, fitted on the rest): "
                                f"residual RMS {p.holdout_rms_before_N:.4g} N without the periodic terms, "
                                f"{p.holdout_rms_after_N:.4g} N with them" if p.holdout_rms_after_N is not None
                                else "")}


def periodic_effects(p) -> list:
    """The effects named from the periodic comparison (``periodic_force_change``, at ``axis``)."""
    if p is None:
        return []
    out = []
    for c in p.changes:
        if not c.named:
            continue
        par = {"period_m": rounded(c.period_m), "amplitude_N": rounded(c.amplitude_N)}
        par |= {f"amplitude_{d}_N": rounded(v[0]) for d, v in c.amplitude.items()}
        out.append({"name": "periodic_force_change", "where": "axis", "words": c.words, "source": "reference",
                    "period_m": rounded(c.period_m), "amplitude_N": rounded(c.amplitude_N),
                    "parameters": par,
                    "uncertainty": {"period_m": rounded(c.period_u_m), "amplitude_N": rounded(c.change_u_N)},
                    "change": {"amplitude_N": rounded(c.change_N)}, "floor": {"amplitude_N": rounded(c.floor_N)},
                    "directions": list(c.named), "delta_bic": None, "delta_chi2_holdout": None,
                    "evidence": f"|change| {abs(c.change_N):.3g} N > floor {c.floor_N:g} N and > 3 u in "
                                f"{' and '.join(c.named)}"})
    return out
