"""diagnosis.json's parts (hil/schemas/diagnosis.schema.json): what a diagnosis, an identifiability and an
effort mask are in JSON, and the figures' rounding; the outcome of a diagnosis (its JSON and what its report
is drawn from).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DiagnoseOutcome:
    """diagnosis.json (``data``) and what its report is drawn from.

    ``kind``: ``"model"`` (against the simulation: ``model``, the replay model, and ``diagnosis``, its
    :class:`blf.diagnose.Diagnosis`), ``"axis_reference"`` (a single axis against a reference recording) or
    ``"dual_reference"`` (a dual-EMA check against a reference: ``fits``, its
    :class:`hil.analysis.diagnose.dual_reference.ReferenceFits` or None)."""

    kind: str
    data: dict
    model: object | None = None
    diagnosis: object | None = None
    fits: object | None = None

    @property
    def untrusted(self) -> bool:
        """The effort is not trusted: nothing diagnosed (exit status 5)."""
        return self.data["verdict"] == "untrusted_effort"


def identifiability_dict(model) -> dict | None:
    """diagnosis.json's ``identifiability`` of a single-axis replay model (None for another model)."""
    ident = getattr(model, "identifiability", None)
    if ident is None:
        return None
    out = ident_dict(ident) | {"not_candidates": [{"name": n, "why": w} for n, w in model.not_candidates]}
    if getattr(model, "effort_mask", None) is not None:
        out["mask"] = mask_dict(model.effort_mask)
    return out


def ident_dict(ident) -> dict:
    return {"fitted": list(ident.columns), "fixed": dict(ident.fixed),
            "cannot_tell_apart": [{"terms": list(t), "into": into, "why": why, "would_separate": motion}
                                  for t, into, why, motion in ident.merged],
            "speed_levels_m_per_s": [float(f"{s:.6g}") for s in ident.speed_levels_m_per_s],
            "directions": list(ident.directions), "variance_inflation": {k: float(f"{v:.4g}")
                                                                          for k, v in ident.vif.items()}}


def mask_dict(m) -> dict:
    r = lambda s: [[round(a, 3), round(b, 3)] for a, b in s]  # noqa: E731
    return {"samples_used": int(m.used.sum()), "dwell_masked": m.n_dwell, "transient_masked": m.n_transient,
            "dwell_spans_s": r(m.dwell_spans_s[:50]), "transient_spans_s": r(m.transient_spans_s[:50]),
            "words": m.words}


def rounded(x, nd=6):
    """``x`` to ``nd`` significant digits (None stays None): the figures of diagnosis.json."""
    return None if x is None else float(f"{x:.{nd}g}")


def rounded_dict(d: dict) -> dict:
    """Each value of ``d`` :func:`rounded`."""
    return {k: rounded(v) for k, v in d.items()}


def untrusted_dict(effort: dict) -> dict:
    """diagnosis.json of a recording whose effort is not trusted: the reason, nothing diagnosed."""
    return {"verdict": "untrusted_effort", "model": "single-axis", "mode": "model", "effects": [], "where": [],
            "locations": [], "effort": effort,
            "band": {"cutoff_hz": None, "step": 1, "words": "nothing compared: the effort is not trusted"}}


def _periodic_keys(par: dict) -> dict:
    """A force periodic in position carries its period in metres of travel and its amplitude in N."""
    if "period_mm" not in par or "amplitude_N" not in par:
        return {}
    return {"period_m": rounded(par["period_mm"] * 1e-3), "amplitude_N": rounded(par["amplitude_N"])}


def diagnosis_dict(d, model_name: str, seconds: float) -> dict:
    """JSON shape of diagnosis.json (hil/schemas/diagnosis.schema.json): ``effects`` lists every
    effect accepted whatever the verdict; RMS figures in the compared band, ``raw`` ones beside."""
    eff = lambda e: {"name": e.name, "where": e.where, "words": e.words, "source": e.source,  # noqa: E731
                     "parameters": rounded_dict(e.parameters), "uncertainty": rounded_dict(e.uncertainty),
                     "delta_bic": rounded(e.delta_bic), "delta_chi2_holdout": rounded(e.delta_chi2_holdout),
                     "evidence": e.evidence} | _periodic_keys(e.parameters)
    b = d.band
    return {
        "verdict": d.verdict, "model": model_name,
        "effects": [eff(e) for e in d.effects],
        "where": list(d.where),
        "band": {"cutoff_hz": rounded(b.cutoff_hz), "step": int(b.step), "words": b.words},
        "locations": [{"channel": loc.channel, "where": loc.where, "t_start_s": rounded(loc.t_start_s),
                       "t_end_s": rounded(loc.t_end_s), "regime": loc.regime, "score": rounded(loc.score),
                       "test": loc.test}
                      for loc in d.locations],
        "residual_rms_before": rounded_dict(d.residual_rms_before),
        "residual_rms_after": rounded_dict(d.residual_rms_after),
        "residual_rms_holdout_before": rounded_dict(d.residual_rms_holdout_before),
        "residual_rms_holdout_after": rounded_dict(d.residual_rms_holdout_after),
        "residual_rms_raw_before": rounded_dict(d.residual_rms_raw_before),
        "residual_rms_raw_after": rounded_dict(d.residual_rms_raw_after),
        "residual_rms_raw_holdout_before": rounded_dict(d.residual_rms_raw_holdout_before),
        "residual_rms_raw_holdout_after": rounded_dict(d.residual_rms_raw_holdout_after),
        "noise_floor": rounded_dict(d.noise_floor),
        "noise_floor_raw": rounded_dict(d.noise_floor_raw),
        "excess_before": rounded_dict(d.excess_before),
        "excess_after": rounded_dict(d.excess_after),
        "regime_score_before": rounded_dict(d.regime_before),
        "regime_score_after": rounded_dict(d.regime_after),
        "ic": "BIC", "ic_before": rounded(d.ic_before, 9), "ic_after": rounded(d.ic_after, 9),
        "nominal": rounded_dict(d.nominal),
        "screening": list(d.screening),
        "diagnosis_s": round(seconds, 2),
    }


def with_notes(data: dict, notes) -> dict:
    """diagnosis.json ``data`` with what was noted while reading the recordings (``notes``; none: unchanged)."""
    if notes:
        data["notes"] = list(dict.fromkeys(list(data.get("notes", [])) + list(notes)))
    return data
