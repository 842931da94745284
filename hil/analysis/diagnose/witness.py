"""The tracking error as a second witness of a single axis against its reference, and the rule that sets it
against the effort (issue 48, "Every signal a witness"; docs/diagnose.md, "The second witness").

A single-axis recording holds the set point ``q_ref`` beside the measured position ``q``: its position
loop's tracking error ``q_ref - q`` sees the force the loop fights without the effort's conversion. Its
steady lag and jitter (:func:`blf.diagnose.witness.tracking_witness`) are compared with the reference's
(:func:`blf.diagnose.witness.compare_witness`) against their floors (:data:`WITNESS_FLOORS`, or measured from
several references: :mod:`hil.analysis.diagnose.coverage`). The rule (:func:`apply_witness`), where the
effort's own check passed and it names no change:

* the lag changed, or the jitter **rose**, beyond its floor: the force the loop fights changed (larger, or
  rougher) and the effort does not show it; the verdict is ``untrusted_effort`` (exit 5), the words naming
  both witnesses with their figures (:func:`blf.diagnose.witness.witnesses_disagree`);
* only the jitter **fell** beyond its floor (smoother than the reference): no degradation is missed; the
  change is named from the witness that sees it (an effect of source ``witness``, with its uncertainty),
  verdict ``explained``.

Where the effort names a change, it stands; the witness's changes are listed beside it (``witness``).
"""

from __future__ import annotations

from hil.analysis.diagnose.results import rounded

#: default floors of the tracking error's changes: 3 x the RMS of the changes between halves of the healthy
#: Cranfield actuator's runs (``normal`` runs 6-10 against 1-5 and even against odd, at +20, +40 and -40 kgf:
#: the position is not re-levelled at -40 kgf): lag +4.3, +4.8, +1.5, +1.6, -0.0, +1.3 um, 3 x RMS
#: 8.50 um, rounded up to 9 um; jitter -7.2, -3.8, +5.4, +0.4, +0.5, -2.1 %, 3 x RMS 12.27 %, rounded up
#: to 13 % (tests/bench/bench_diagnose_witness.py --floors). Halves of one session: a repeatability
#: (:data:`hil.analysis.diagnose.coverage.REPEATABILITY_WORDS`)
WITNESS_FLOORS = {"tracking_lag_m": 9e-6, "tracking_jitter_ratio": 0.13}

_FORCES = ("friction_N", "coulomb_N", "offset_N")
_EFFECT = {"tracking_lag_m": "tracking_lag_change", "tracking_jitter_ratio": "tracking_jitter_change"}


def witness_of(rec, periods_m=()):
    """The tracking witness of a single-axis recording (:class:`hil.analysis.diagnose.single_axis.AxisRecording`),
    or the reason (str) it has none; ``periods_m``: the periods (m of travel) of the periodic force the effort
    names in it, removed from the jitter (:func:`blf.diagnose.witness.tracking_witness`)."""
    from blf.diagnose.witness import tracking_witness
    from blf.errors import AnalysisError
    try:
        return tracking_witness(rec.t, rec.q, rec.q_ref, rec.sample_rate_hz, periods_m=periods_m)
    except AnalysisError as exc:
        return f"{rec.path.name}: {exc}"


def change_dict(c) -> dict:
    """diagnosis.json's entry of a :class:`blf.diagnose.witness.WitnessChange`."""
    return {"parameter": c.name, "value_m": rounded(c.value), "reference_m": rounded(c.reference),
            "change": rounded(c.change), "uncertainty": rounded(c.uncertainty), "unit": c.unit,
            "z": rounded(c.z, 4), "floor": rounded(c.floor), "supported": c.supported, "above_floor": c.relevant,
            "named": c.named, "words": c.words}


def _stat_dict(w) -> dict:
    return {"lag_m": rounded(w.lag_m), "lag_u_m": rounded(w.lag_u_m), "jitter_m": rounded(w.jitter_m),
            "jitter_u_m": rounded(w.jitter_u_m), "strokes": w.n_strokes, "samples": w.n_samples}


def named_periods(periodic) -> tuple:
    """((recording's periods, reference's periods) in m) of the periodic components named
    (:class:`blf.diagnose.axis_periodic` comparison, or None)."""
    comps = [c for c in (periodic.changes if periodic is not None else ()) if c.named]
    return tuple(c.period_m for c in comps), tuple(c.period_reference_m for c in comps)


def compare_pair(new, ref, floors: dict, z_min: float, periods=((), ())) -> tuple:
    """(changes or None, diagnosis.json's ``witness`` without the rule's words) of two recordings;
    ``periods``: :func:`named_periods`, removed from each recording's jitter."""
    from blf.diagnose.witness import compare_witness
    wn, wr = witness_of(new, periods[0]), witness_of(ref, periods[1])
    if isinstance(wn, str) or isinstance(wr, str):
        why = "; ".join(w for w in (wn, wr) if isinstance(w, str))
        return None, {"compared": False, "changes": [], "words": f"the tracking error was not compared ({why})"}
    if flat := [f"{r.path.name}: its tracking error has no jitter (set point and position the same or held)"
                for r, w in ((new, wn), (ref, wr)) if not w.jitter_m > 0]:
        return None, {"compared": False, "changes": [],
                      "words": f"the tracking error was not compared ({'; '.join(flat)})"}
    changes = compare_witness(wn, wr, floors, z_min)
    removed = ({"periods_removed_m": [rounded(p) for p in wn.periods_removed_m],
                "periods_removed_reference_m": [rounded(p) for p in wr.periods_removed_m]}
               if wn.periods_removed_m else {})
    return changes, removed | {"compared": True, "window_s": rounded(wn.window_s), "recording": _stat_dict(wn),
                     "reference": _stat_dict(wr), "changes": [change_dict(c) for c in changes]}


def _effect(c) -> dict:
    return {"name": _EFFECT[c.name], "where": "axis", "words": c.words + " (seen by the tracking error; the "
            "effort's nominal model, mean forces, does not represent it)", "source": "witness",
            "parameters": {c.name: rounded(c.change)}, "uncertainty": {c.name: rounded(c.uncertainty)},
            "change": {c.name: rounded(c.change)}, "floor": {c.name: rounded(c.floor)}, "delta_bic": None,
            "delta_chi2_holdout": None, "evidence": f"z = {c.z:.1f}, |change| {abs(c.change):.4g} > floor "
                                                    f"{c.floor:g} ({c.unit})"}


def _periodic(effect: dict) -> bool:
    return effect["name"].startswith("periodic")


def apply_witness(data: dict, changes, section: dict) -> dict:
    """diagnosis.json ``data`` (of :func:`hil.analysis.diagnose.axis_reference.reference_diagnosis`) with the
    tracking error's comparison (``witness``) and the rule applied: returns the new dict."""
    from blf.diagnose.witness import witnesses_disagree
    data = dict(data)
    effort = dict(data["effort"])
    # the effort's mean-force changes: a periodic change's component is removed from the witness's jitter
    named_effort = [e for e in data["effects"] if e.get("source") != "witness" and not _periodic(e)]
    periodic = [e for e in data["effects"] if _periodic(e)]
    if changes is None:
        data["witness"] = section
        return data
    lag, jit = changes
    if witnesses_disagree(effort["trusted"], bool(named_effort), changes):
        said = ", ".join(f"{c['parameter']} {c['change']:+.1f} ± {c['uncertainty']:.1f} N" for c in data["changes"]
                         if c["parameter"] in _FORCES)
        seen = "; ".join(c.words for c in changes if c.named)
        said = said or "no force parameter"
        words = (f"the two witnesses disagree: the effort names no change of its mean force ({said}; floor "
                 f"{data['floor']['force_N']:g} N) while {seen}"
                 + (" (less the component at the period the effort names)" if periodic else "")
                 + ". The force the position loop fights "
                 + ("changed" if lag.named else "grew rougher") + " and the effort does not show it: the effort "
                 "is not trusted to say 'no change'" + (
                     "; the force periodic in position it names stays named (a current's offsets or "
                     "re-levelling leave a ripple within a stroke as it was)" if periodic else ""))
        effort |= {"trusted": False, "words": words, "witness_disagrees": True}
        data |= {"verdict": "untrusted_effort", "effort": effort, "effects": periodic,
                 "changes": [c | {"named": False} for c in data["changes"]]}
        section = section | {"rule": "untrusted", "words": words}
    elif effort["trusted"] and not named_effort and jit.named:
        data |= {"verdict": "explained", "effects": periodic + [_effect(jit)]}
        section = section | {"rule": "named", "words": f"named from the tracking error: {jit.words}; the effort "
                                                       "names no change of its mean force (a smoother tracking "
                                                       "misses no degradation)"}
    else:
        moved = "changed beyond its floors" if lag.named or jit.named else "did not change beyond its floors"
        agree = (f"the effort failed its own check against the known load; the tracking error {moved}"
                 if not effort["trusted"] else f"the effort names a change and the tracking error {moved}"
                 if named_effort else "the effort names a force periodic in position only and the tracking "
                 f"error, less that period's component, {moved}" if periodic
                 else "neither witness changed beyond its floors")
        section = section | {"rule": "none", "words": agree}
    data["witness"] = section
    return data
