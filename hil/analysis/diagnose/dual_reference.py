"""A dual-EMA recording against a reference recording of the same rig: which parameter changed.

``emacheck diagnose NEW --reference HEALTHY`` (dual-EMA model): the nominal model
(:class:`sim.replay_model.DualEmaReplay`, :func:`blf.diagnose.engine.diagnose`) is identified on the
reference and on the new recording alike; each nominal parameter with a floor (per EMA internal play,
contact stiffness, compliance, LVDT pitch and offset) is compared with its reference value in its floor's
unit (um, %, N), and so are what a check determines where it cannot tell two parameters apart: the
external play (the two bearing plays' sum: the force fight loads the bearings equally and oppositely) and
the drives' and the hinge's friction at the check's speed (Coulomb + viscous x speed: one speed). A
parameter the recordings do not determine alone (variance inflation of the nominal fit at least
:data:`VIF_MAX`, :func:`blf.diagnose.covariance.nominal_covariance`) is listed, not separable, never named.

Uncertainty of a change: the measured repeatability of the nominal fit
(:mod:`hil.profile.floors`: the floor is :math:`3\\sqrt2\\,\\sigma`, so a change carries
:math:`u = \\sqrt2\\,\\sigma = \\mathrm{floor}/3`); a change is named when :math:`|\\Delta| >` its floor,
i.e. :math:`|z| = |\\Delta|/u > 3`: statistically supported against the measured spread, and
relevant, in one test (for floors left at their measured defaults; docs/diagnose.md).

Library effects: every candidate accepted on either recording's own diagnosis (``effects_recording``,
``effects_reference``) is fitted on the other too (:func:`blf.diagnose.engine.fit_effect`) and its parameters
compared (:func:`library_change`): u from the two fits, named when :math:`|z| > 3` and above the floor of
its kind (:data:`LIBRARY_FLOORS`: Coulomb friction N, load cell gain %). The report's fits before and after
(:class:`ReferenceFits`): the new recording replayed by the reference's model, and by it with the named
changes only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.analysis.diagnose.coverage import dual_coverage
from hil.analysis.diagnose.floors import KINDS, check_speed, floors_for, library_change, nominal_changes
from hil.analysis.diagnose.results import with_notes


def _active(model, d) -> tuple:
    """A diagnosis's accepted library effects as (Candidate, parameters) of ``model``."""
    return tuple((c, np.array([e.parameters[q.name] for q in c.params])) for e in d.effects
                 if e.source == "library" for c in model.candidates
                 if (c.name, c.where, c.variant) == (e.name, e.where, e.variant))


def _library_changes(fits: list, floors: dict, speed_mm_per_s: float) -> tuple:
    """Every library effect accepted on either recording, fitted on both, compared parameter by parameter:
    (changes, {(name, where, variant): (effect on the new recording, on the reference)}). Where only one
    recording has the effect, it is fitted on the other with its shape parameters held at that one's."""
    from blf.diagnose import fit_effect
    (m_ref, T_ref, d_ref), (m_new, T_new, d_new) = fits
    keys = []
    for d in (d_new, d_ref):
        keys += [(e.name, e.where, e.variant) for e in d.effects
                 if e.source == "library" and (e.name, e.where, e.variant) not in keys]
    out, pairs = [], {}
    sides = ((m_new, T_new, d_new, "new recording"), (m_ref, T_ref, d_ref, "reference"))
    for key in keys:
        own = [next((e for e in d.effects if (e.name, e.where, e.variant) == key), None) for _, _, d, _ in sides]
        having = next(e for e in own if e is not None)
        # the candidate of the recording that has the effect (one started from its data: a period found)
        first = (m_new, m_ref) if own[0] is not None else (m_ref, m_new)
        cand = next(c for m in first for c in m.candidates if (c.name, c.where, c.variant) == key)
        held = None if None not in own else sides[own.index(having)][3]
        pair = []
        for (model, T, d, _), e in zip(sides, own, strict=True):
            if e is None:
                c = cand
                e = fit_effect(model, T, d.nominal, c, _active(model, d),
                               fixed={q: having.parameters[q] for q in c.shape})
            pair.append(e)
        if None not in pair:
            got = library_change(pair[0], pair[1], floors, speed_mm_per_s, cand.shape, held)
            if "period_mm" in having.parameters:  # a force periodic in position: its period and amplitude
                got = [c | {"period_m": having.parameters["period_mm"] * 1e-3,
                            "amplitude_N": pair[0].parameters["amplitude_N"]} for c in got]
            out += got
            pairs[key] = tuple(pair)
    return out, pairs


@dataclass(frozen=True)
class ReferenceFits:
    """The new recording's channels against two models (for the report's figures; arrays, not in JSON).

    ``before``: the reference's model (its nominal parameters and library effects) replayed with the new
    recording's motor angles; ``after``: the same with the named changes only (the named nominal
    parameters and library effects at their values on the new recording)."""

    t_s: np.ndarray
    channels: tuple
    measured: dict
    valid: dict
    before: dict
    after: dict


def _fits(m_new, d_ref, d_new, changes: list, pairs: dict) -> ReferenceFits | None:
    """Replays of the new recording by the reference's model, and by it with the named changes."""
    from blf.diagnose import safe_predict
    named = {p for c in changes if c["named"] for p in (c["parameter"], *c.get("of", ()))}
    th_ref = np.array([float(d_ref.nominal[q.name]) for q in m_new.nominal])
    th_after = np.array([float((d_new if q.name in named else d_ref).nominal[q.name]) for q in m_new.nominal])
    act_ref, act_after = [], []
    for cand in m_new.candidates:
        pair = pairs.get((cand.name, cand.where, cand.variant))
        if pair is None:
            continue
        e_new, e_ref = pair
        x_ref = np.array([e_ref.parameters[q.name] for q in cand.params])
        x_new = np.array([e_new.parameters[q.name] for q in cand.params])
        act_ref.append((cand, x_ref))
        act_after.append((cand, np.where([f"{cand.name}.{q.name}" in named for q in cand.params], x_new, x_ref)))
    before, after = safe_predict(m_new, th_ref, act_ref), safe_predict(m_new, th_after, act_after)
    if before is None or after is None:
        return None
    ch = tuple(c for c in m_new.channels if c in before and np.asarray(m_new.valid[c]).any())
    return ReferenceFits(m_new.t_s, ch, {c: m_new.measured[c] for c in ch}, {c: m_new.valid[c] for c in ch},
                         {c: before[c] for c in ch}, {c: after[c] for c in ch})


def fits_rms(f: ReferenceFits) -> dict:
    """Residual RMS per channel (its unit) of the reference's model and of it with the named changes."""
    def rms(pred: dict, c: str) -> float:
        r = (f.measured[c] - pred[c])[f.valid[c]]
        return float(np.sqrt(np.mean(r ** 2)))
    return {"before": {c: rms(f.before, c) for c in f.channels}, "after": {c: rms(f.after, c) for c in f.channels}}


def dual_reference(new_path: Path, reference: Path | None, profile: Path | None, check: Path | None = None,
                   history_url: str | None = None, allow_other_serials: bool = False, *,
                   accept_modified: bool = False) -> tuple:
    """``emacheck diagnose NEW --reference HEALTHY|history`` with the dual-EMA model: (diagnosis.json,
    :class:`ReferenceFits` or None).

    The reference is ``reference``, or with ``history_url`` the wear history's last check of the same
    actuators (:func:`hil.analysis.diagnose.history_reference.reference_from_history`); a reference of other
    actuators is refused unless ``allow_other_serials``; the floors are the check profile's
    (:func:`hil.analysis.diagnose.floors.floors_for`, ``check``: ``--check``), and with ``history_url`` and two
    or more healthy checks of the same actuators there, measured from their spread
    (:func:`history_floors`: a reproducibility)."""
    from hil.analysis.diagnose.history_reference import healthy_checks, reference_from_history, refuse_other_serials
    hist, healthy = None, []
    if history_url is not None:
        ref_path, hist = reference_from_history(new_path, history_url, allow_other_serials)
        healthy = healthy_checks(new_path, history_url)
    else:
        ref_path = Path(reference)
    serials = refuse_other_serials(new_path, ref_path, allow_other_serials)
    cache: dict = {}
    new, ref = load_pair(new_path, ref_path, profile, cache, accept_modified)
    floors, source = floors_for(new, check)
    cov = None
    if len(healthy) >= 2:
        floors, cov = history_floors(healthy, profile, floors, source, cache)
        if cov["measured"]:
            source += "; " + ", ".join(cov["measured"]) + " measured from the wear history's healthy checks"
    data, fits = compare_pair(new, ref, floors, source, cache)
    if cov is not None:
        data["floor"]["coverage"] = cov
    data["serials"] = serials
    if hist is not None:
        data["reference_history"] = hist
    return data, fits


def history_floors(folders: list, profile: Path | None, floors: dict, source: str, cache: dict) -> tuple:
    """(floors by kind, diagnosis.json's ``floor.coverage``) from the wear history's healthy checks of the same
    actuators (``folders``, :func:`hil.analysis.diagnose.history_reference.healthy_checks`): every pair compared
    as a recording is against its reference (:func:`compare_pair`, ``floors`` as given), the changes of each
    floor's kind pooled (separable, sized parameters only), the floors 3 x their RMS
    (:func:`hil.analysis.diagnose.coverage.dual_floors_from_spread`)."""
    from itertools import combinations

    from hil.analysis.diagnose.coverage import dual_floors_from_spread
    pooled: dict = {}
    for a, b in combinations(folders, 2):
        new, ref = load_pair(b, a, profile, cache)
        data, _ = compare_pair(new, ref, floors, source, cache)
        for c in data["changes"]:
            if c.get("floor_key") and c.get("separable", True) and not c.get("shape"):
                pooled.setdefault(c["floor_key"], []).append(float(c["change"]))
    return dual_floors_from_spread(pooled, folders, floors)


def _key(path: Path, profile: Path | None) -> tuple:
    return str(Path(path).resolve()), str(profile)


def load_pair(new_path: Path, ref_path: Path, profile: Path | None, cache: dict,
              accept_modified: bool = False) -> tuple:
    """(new, reference) :class:`hil.analysis.diagnose.load.DualRecording`, each read once per ``cache`` (a dict
    the caller keeps); a reference at another sample rate (more than 1 % apart) is refused (exit 3)."""
    from hil.analysis.diagnose.load import load_dual
    from hil.errors import RecordingError
    out = []
    for path in (new_path, ref_path):
        k = ("loaded", *_key(path, profile))
        if k not in cache:
            cache[k] = load_dual(Path(path), profile, accept_modified)
        out.append(cache[k])
    new, ref = out
    if abs(ref.period_s / new.period_s - 1.0) > 0.01:
        raise RecordingError(f"--reference {ref_path}: another sample rate: {1 / ref.period_s:.6g} Hz, this "
                             f"recording {1 / new.period_s:.6g} Hz (more than 1 % apart)")
    return new, ref


def _fitted(rec, cache: dict) -> tuple:
    """(diagnosis, nominal covariance) of a loaded recording, once per ``cache``."""
    from blf.diagnose import diagnose, nominal_covariance
    from blf.errors import AnalysisError, InputError
    from hil.errors import RecordingError
    k = ("fitted", id(rec))
    if k not in cache:
        try:
            d = diagnose(rec.model, rec.period_s)
            cache[k] = (d, nominal_covariance(rec.model, rec.period_s, d.nominal))
        except (InputError, AnalysisError) as exc:
            raise RecordingError(f"{rec.path}: cannot be diagnosed: {exc}") from None
    return cache[k]


def dual_reference_diagnosis(new_path: Path, ref_path: Path, profile: Path | None,
                             floors: dict | None = None, floors_source: str = "the measured defaults",
                             cache: dict | None = None) -> tuple:
    """(diagnosis.json, :class:`ReferenceFits` or None) of a dual-EMA recording against a reference
    recording with the floors given (nothing written here). ``cache`` (a dict the caller keeps, for many pairs
    of few recordings): each recording's fit is looked up there by its path and the profile, and put there."""
    cache = {} if cache is None else cache
    new, ref = load_pair(new_path, ref_path, profile, cache)
    return compare_pair(new, ref, floors, floors_source, cache)


def compare_pair(rec_new, rec_ref, floors: dict | None, floors_source: str, cache: dict) -> tuple:
    """(diagnosis.json, :class:`ReferenceFits` or None) of two loaded recordings (:func:`load_pair`): each
    diagnosed (once per ``cache``), every nominal parameter and library effect compared against its floor."""
    from hil.profile.floors import DUAL_FLOORS
    floors = dict(DUAL_FLOORS) | dict(floors or {})
    ref, cov_ref = _fitted(rec_ref, cache)
    new, cov_new = _fitted(rec_new, cache)
    fits = [(rec_ref.model, rec_ref.period_s, ref), (rec_new.model, rec_new.period_s, new)]
    ref_path = rec_ref.path
    speed = check_speed(fits[0][0])
    changes = nominal_changes(new.nominal, ref.nominal, cov_new, cov_ref, floors, speed)
    lib, pairs = _library_changes(fits, floors, speed)
    changes += lib
    effects = [_effect_of(c) for c in changes if c["named"]]
    rf = _fits(fits[1][0], ref, new, changes, pairs)
    eff = lambda d: [{"name": e.name, "where": e.where} for e in d.effects]  # noqa: E731
    unexplained = _unexplained(new, ref)
    appeared = unexplained["recording"] and not unexplained["reference"]
    return with_notes({
        "verdict": "unexplained" if appeared else "explained" if effects else "no_mismatch",
        "model": "dual-ema", "mode": "reference", "unexplained": unexplained,
        "fits": None if rf is None else {**fits_rms(rf), "words": (
            "residual RMS of the new recording (raw band, channel units), before: the reference's model (its "
            "nominal parameters and library effects) replayed with this recording's motor angles; after: the same "
            "with the named changes only")},
        "effects": effects, "where": list(new.where) if appeared else [], "locations": [],
        "band": {"cutoff_hz": None, "step": 1, "words": "each recording's nominal fit (emacheck diagnose)"},
        "reference": {"recording": str(ref_path), "nominal": dict(ref.nominal), "uncertainty": {},
                      "words": "no per-fit uncertainty of the nominal parameters: each nominal change's is the "
                               "measured repeatability (changes); a library effect's from its fits"},
        "nominal": dict(new.nominal), "changes": changes,
        "floor": {"force_N": floors["friction_N"], "z_min": 3.0, "by_kind": floors, "source": floors_source,
                  "defaults": dict(DUAL_FLOORS), "coverage": dual_coverage(floors), "words": (
            "a change is named only when supported (|z| > 3) and above its floor (play um, stiffness, sensor and "
            "load cell gain %, friction N); a nominal parameter's floor is 3 sqrt(2) x the measured spread of the "
            "nominal fit and its u = floor/3 (hil/profile/floors.py, docs/diagnose.md)")},
        "effects_recording": eff(new), "effects_reference": eff(ref),
    }, rec_new.notes + rec_ref.notes), rf


def _unexplained(new, ref) -> dict:
    """diagnosis.json ``unexplained``: which recording's own diagnosis leaves a mismatch the library does not
    explain, where the new one's is, and what that means for the comparison."""
    n, r = new.verdict == "unexplained", ref.verdict == "unexplained"
    if n and not r:
        words = (f"this recording's own diagnosis leaves a mismatch the library does not explain, first at "
                 f"{new.where[0] if new.where else 'no one place'}, and the reference's does not: physics outside "
                 f"the library appeared (the named changes, if any, are what the nominal model and the library "
                 f"can say)")
    elif n and r:
        words = ("both recordings' own diagnoses leave a mismatch the library does not explain: the named changes "
                 "are between two imperfect fits")
    elif r:
        words = ("the reference's own diagnosis leaves a mismatch the library does not explain and this "
                 "recording's does not: the named changes are against an imperfect fit of the reference")
    else:
        words = "neither recording's own diagnosis leaves a mismatch the library does not explain"
    return {"recording": n, "reference": r, "where": list(new.where) if n else [], "words": words}


def _effect_of(c: dict) -> dict:
    """The effect of a named change (diagnosis.json ``effects``)."""
    name = c["effect"] + "_change" if c.get("source") == "library" else _effect_name(c["parameter"])
    return {"name": name, "where": c["where"], "words": c["words"], "source": "reference",
            "parameters": {c["parameter"]: c["value"]}, "uncertainty": {c["parameter"]: c["uncertainty"]},
            "change": {c["parameter"]: c["change"]}, "floor": {c["parameter"]: c["floor"]},
            "delta_bic": None, "delta_chi2_holdout": None,
            "evidence": f"z = {c['z']:.1f}" + (" from the two fits" if c.get("source") == "library"
                                               else " against the measured repeatability")} | {
        k: c[k] for k in ("period_m", "amplitude_N") if k in c}


def _effect_name(parameter: str) -> str:
    for k in KINDS:
        if parameter.startswith(k):
            return {"backlash_int": "internal_play_change", "backlash_bearing": "bearing_play_change",
                    "stiffness_int": "stiffness_change", "compliance_ext": "compliance_change",
                    "lvdt_pitch": "lvdt_pitch_change", "lvdt_offset": "lvdt_offset_change",
                    }[k]
    return {"external_play_mm": "external_play_change", "drive_friction_N": "drive_friction_change",
            "hinge_friction_N": "hinge_friction_change"}.get(parameter, parameter + "_change")
