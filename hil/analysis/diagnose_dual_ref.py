"""A dual-EMA recording against a reference recording of the same rig: which parameter changed.

``emacheck diagnose NEW --reference HEALTHY`` (dual-EMA model): the nominal model
(:class:`sim.replay_model.DualEmaReplay`, :func:`blf.diagnose.diagnose`) is identified on the
reference and on the new recording alike; each nominal parameter with a floor (per EMA internal play,
contact stiffness, compliance, LVDT pitch and offset) is compared with its reference value in its floor's
unit (um, %, N), and so are what a check determines where it cannot tell two parameters apart: the
external play (the two bearing plays' sum: the force fight loads the bearings equally and oppositely) and
the drives' and the hinge's friction at the check's speed (Coulomb + viscous x speed: one speed). A
parameter the recordings do not determine alone (variance inflation of the nominal fit at least
:data:`VIF_MAX`, :func:`blf.diagnose_cov.nominal_covariance`) is listed, not separable, never named.

Uncertainty of a change: the measured repeatability of the nominal fit
(:mod:`hil.analysis.diagnose_floors`: the floor is :math:`3\\sqrt2\\,\\sigma`, so a change carries
:math:`u = \\sqrt2\\,\\sigma = \\mathrm{floor}/3`); a change is named when :math:`|\\Delta| >` its floor,
i.e. :math:`|z| = |\\Delta|/u > 3`: statistically supported against the measured spread, and
relevant, in one test (for floors left at their measured defaults; docs/diagnose.md).

Library effects: every candidate accepted on either recording's own diagnosis (``effects_recording``,
``effects_reference``) is fitted on the other too (:func:`blf.diagnose.fit_effect`) and its parameters
compared (:func:`library_change`): u from the two fits, named when :math:`|z| > 3` and above the floor of
its kind (:data:`LIBRARY_FLOORS`: Coulomb friction N, load cell gain %). The report's fits before and after
(:class:`ReferenceFits`): the new recording replayed by the reference's model, and by it with the named
changes only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: nominal parameter name prefix -> (floor key of DUAL_FLOORS, unit, words); the Coulomb frictions are not
#: compared alone but as the force at the check's speed (:data:`_FRICTIONS`), the bearing plays also as their
#: sum (:data:`_SUMS`)
_KINDS = {"backlash_int": ("play_um", "um", "internal play"), "backlash_bearing": ("play_um", "um", "bearing play"),
          "stiffness_int": ("stiffness_pct", "%", "contact stiffness"),
          "compliance_ext": ("compliance_pct", "%", "bearing-plus-housing compliance"),
          "lvdt_pitch": ("sensor_gain_pct", "%", "LVDT pitch (gain)"),
          "lvdt_offset": ("play_um", "um", "LVDT offset")}

#: derived parameter -> (the nominal parameters summed, floor key, unit, words): the check's force fight loads the
#: two EMAs' bearings with equal and opposite forces, so only their sum is in the recording (docs/diagnose.md)
_SUMS = {"external_play_mm": (("backlash_bearing1_mm", "backlash_bearing2_mm"), "external_play_um", "um",
                              "external play (both bearings)")}

#: derived parameter -> (Coulomb parameter N, viscous parameter N s/mm, words): the friction force
#: F(v) = F_c + b v at the check's speed v (mm/s; :func:`check_speed`): a check that moves at one speed
#: determines the friction there, not F_c and b apart (on the independent rig their fitted split moves by
#: 16 N between recordings while F at 2 mm/s stays within 0.5 N; docs/diagnose.md)
_FRICTIONS = {"drive_friction_N": ("drive_coulomb_N", "drive_viscous_N_s_per_mm", "drives' friction"),
              "hinge_friction_N": ("hinge_coulomb_N", "hinge_viscous_N_s_per_mm", "hinge friction")}

#: a nominal parameter whose variance inflation factor (:func:`blf.diagnose_cov.nominal_covariance`) reaches this on
#: either recording is not compared alone: its white-noise uncertainty is then at least 1000 times what it would
#: be were the others known, 25-100 times the spread between checks the floors measure (the white-noise one is
#: 10-40 times below it): the recording does not determine it and its fitted value is where the fit started.
#: Measured: the bearing plays 2e9-9e10 (exactly one direction, their difference, not in the data), every other
#: parameter at most 1.1e4 (docs/diagnose.md, "What a check can separate")
VIF_MAX = 1e6


def _where(name: str) -> str:
    """ema1, ema2 for a per-EMA parameter (its prefix followed by the EMA's number), else external."""
    import re
    m = re.match(r"^(?:backlash_int|stiffness_int|backlash_bearing|compliance_ext|lvdt_pitch|lvdt_offset)([12])", name)
    return f"ema{m.group(1)}" if m else "external"


def _change(name: str, new: float, ref: float, floors: dict, kind: tuple | None = None) -> dict | None:
    kind = kind or next((v for k, v in _KINDS.items() if name.startswith(k)), None)
    if kind is None:
        return None
    key, unit, words = kind
    if unit == "um":
        ch = 1000.0 * (new - ref)
    elif unit == "%":
        ch = 100.0 * (new / ref - 1.0)
    else:
        ch = new - ref
    floor = float(floors[key])
    u = floor / 3.0
    named = bool(abs(ch) > floor)
    verb = "increased" if ch > 0 else "decreased"
    how = f"named: above its floor of {floor:g} {unit}" if named else f"under its floor of {floor:g} {unit}: not named"
    return {"parameter": name, "where": _where(name), "value": new, "reference": ref, "change": ch, "unit": unit,
            "uncertainty": u, "z": ch / u, "floor": floor, "supported": named, "above_floor": named, "named": named,
            "separable": True, "floor_key": key, "words": f"{words} {verb} by {abs(ch):.3g} ± {u:.2g} {unit}; {how}"}


def _not_separable(c: dict, vif: float, cov) -> dict:
    """A compared parameter the recordings do not determine alone: listed with why, never named."""
    i = cov.index(c["parameter"])
    r = cov.covariance[i] / np.sqrt(cov.covariance[i, i] * np.diag(cov.covariance))
    r[i] = 0.0
    other = cov.names[int(np.argmax(np.abs(r)))]
    summed = next((k for k, v in _SUMS.items() if c["parameter"] in v[0]), None)
    tail = f"; their sum is compared ({summed})" if summed else ""
    return c | {"supported": False, "above_floor": False, "named": False, "separable": False, "vif": vif,
                "words": (f"{c['words'].split(';')[0]}; not separable by this check (variance inflation "
                          f"{vif:.2g} >= {VIF_MAX:g}: the recording determines it only together with "
                          f"{other}{tail}): not named")}


def check_speed(model) -> float:
    """The speed a recording's check moves at, mm/s: the median of the replay's velocity
    (``regimes["velocity"]``, the mean of the two rams') over the samples moving faster than 5 % of its
    99th percentile; 0 where nothing moves."""
    v = np.abs(np.asarray(model.regimes["velocity"], dtype=float))
    moving = v > 0.05 * float(np.percentile(v, 99)) if v.size else v.astype(bool)
    return float(np.median(v[moving])) if moving.any() else 0.0


def nominal_changes(new: dict, ref: dict, cov_new, cov_ref, floors: dict, speed_mm_per_s: float) -> list:
    """Every nominal comparison of a new recording's fit against its reference's (diagnosis.json ``changes``).

    ``new``, ``ref``: {name: value} of the two nominal fits; ``cov_new``, ``cov_ref``: their
    :class:`blf.diagnose.NominalCovariance`. Per parameter of :data:`_KINDS` the change in its floor's unit,
    not separable (never named) where its variance inflation reaches :data:`VIF_MAX` on either recording; the
    sums of :data:`_SUMS`; the frictions of :data:`_FRICTIONS` at ``speed_mm_per_s`` (the reference's
    :func:`check_speed`)."""
    out = []
    for n in new:
        if n not in ref:
            continue
        c = _change(n, float(new[n]), float(ref[n]), floors)
        if c is None:
            continue
        vif, cov = max(((float(cv.vif[cv.index(n)]), cv) for cv in (cov_new, cov_ref)), key=lambda t: t[0])
        out.append(c if vif < VIF_MAX else _not_separable(c, vif, cov))
    for name, (parts, key, unit, words) in _SUMS.items():
        if all(q in new and q in ref for q in parts):
            c = _change(name, sum(float(new[q]) for q in parts), sum(float(ref[q]) for q in parts), floors,
                        (key, unit, words))
            out.append(c | {"of": list(parts)})
    for name, (fc, b, words) in _FRICTIONS.items():
        if not all(q in new and q in ref for q in (fc, b)):
            continue
        v = float(speed_mm_per_s)
        c = _change(name, float(new[fc]) + v * float(new[b]), float(ref[fc]) + v * float(ref[b]), floors,
                    ("friction_N", "N", f"{words} at {v:.3g} mm/s"))
        out.append(c | {"of": [fc, b], "speed_mm_per_s": v,
                        "words": c["words"] + f" (Coulomb + viscous x {v:.3g} mm/s, the speed the reference "
                                              f"check moves at: one speed does not tell the two apart)"})
    return out


#: library candidate parameter -> (floor key of DUAL_FLOORS, unit, scale to the unit, words); a candidate's
#: null value is 0 (no such physics); scale "speed": times the check's speed (a viscous coefficient compared as
#: its force at the speed the check moves at). Every size parameter of the library has one (measured by
#: tests/bench/bench_diagnose_floors.py); a shape parameter (:attr:`blf.diagnose.Candidate.shape`) has none
LIBRARY_FLOORS = {
    ("coulomb_friction", "force_N"): ("ema_friction_N", "N", 1.0, "extra Coulomb friction"),
    ("viscous_friction", "coeff_N_s_per_mm"): ("ema_friction_N", "N", "speed",
                                               "extra viscous friction (its force at the check's speed)"),
    ("asymmetric_friction", "force_extend_N"): ("ema_friction_N", "N", 1.0, "extra friction extending"),
    ("asymmetric_friction", "force_retract_N"): ("ema_friction_N", "N", 1.0, "extra friction retracting"),
    ("stribeck_friction", "extra_force_N"): ("stribeck_N", "N", 1.0, "static friction above Coulomb (Stribeck)"),
    ("loadcell_gain", "gain_error"): ("loadcell_gain_pct", "%", 100.0, "load cell gain"),
    ("lvdt_nonlinearity", "quadratic_mm"): ("lvdt_linearity_um", "um", 1000.0, "LVDT bow over the stroke"),
    ("lvdt_nonlinearity", "nonlinearity_mm"): ("lvdt_linearity_um", "um", 1000.0, "LVDT S over the stroke"),
    ("lvdt_drift", "gain_drift_per_s"): ("lvdt_drift_pct_per_h", "%/h", 360000.0, "LVDT gain drift"),
    ("time_skew", "delay_s"): ("time_skew_ms", "ms", 1000.0, "time skew between resolver and LVDT"),
    ("stiffness_asymmetry", "tension_over_compression_minus_1"): ("stiffness_pct", "%", 100.0,
                                                                  "tension against compression stiffness"),
    ("progressive_stiffness", "progressive_per_mm"): ("progressive_pct_per_mm", "%/mm", 100.0,
                                                      "progressive stiffness"),
    ("viscoelastic", "stiffness_N_per_mm"): ("viscoelastic_N_per_mm", "N/mm", 1.0, "visco-elastic stiffness"),
}


def library_change(e_new, e_ref, floors: dict, speed_mm_per_s: float = 0.0, shape: tuple = (),
                   held: str | None = None) -> list:
    """The changes of one library effect's parameters between the reference and the new recording, each
    fitted on both (:func:`blf.diagnose.fit_effect` where not accepted): change = new - reference in the
    floor's unit with u = sqrt(u_new^2 + u_ref^2) from the fits; named when |z| > 3 and |change| > its floor.
    A shape parameter (``shape``) is listed, never named; ``held``: the recording whose value it was held
    at on the other (the effect is on one recording only)."""
    out = []
    for k, v in e_new.parameters.items():
        key, unit, scale, words = LIBRARY_FLOORS.get((e_new.name, k), (None, "", 1.0, f"{e_new.name} {k}"))
        scale = float(speed_mm_per_s) if scale == "speed" else scale
        ch = scale * (v - e_ref.parameters[k])
        u = scale * float(np.hypot(e_new.uncertainty[k], e_ref.uncertainty[k]))
        floor = None if key is None or k in shape else float(floors[key])
        z = ch / u if u > 0 else (float("inf") * np.sign(ch) if ch else 0.0)
        sup, above = bool(abs(z) > 3.0), floor is not None and abs(ch) > floor
        verb = "increased" if ch > 0 else "decreased" if ch < 0 else "unchanged"
        how = (("a shape parameter (the term's form, not its size)" + (f", held at the value of the {held}"
                                                                        if held else "") + ": not named")
               if k in shape else "no floor measured for it: not named" if floor is None else
               f"named: supported and above its floor of {floor:g} {unit}" if sup and above else
               f"under its floor of {floor:g} {unit}: not named" if sup else "not supported (|z| <= 3): not named")
        where = f" ({e_new.variant})" if e_new.variant else ""
        out.append({"parameter": f"{e_new.name}.{k}", "effect": e_new.name, "variant": e_new.variant,
                    "where": e_new.where, "value": float(v), "reference": float(e_ref.parameters[k]),
                    "change": ch, "unit": unit or "", "uncertainty": u, "z": z, "floor": floor, "supported": sup,
                    "above_floor": bool(above), "named": bool(sup and above), "source": "library",
                    "floor_key": None if floor is None else key, "shape": k in shape,
                    "words": f"{words}{where} at {e_new.where} {verb} by {abs(ch):.3g} ± {u:.2g} {unit}; {how}"})
    return out


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
        cand = next(c for m in (m_new, m_ref) for c in m.candidates if (c.name, c.where, c.variant) == key)
        having = next(e for e in own if e is not None)
        held = None if None not in own else sides[own.index(having)][3]
        pair = []
        for (model, T, d, _), e in zip(sides, own, strict=True):
            if e is None:
                c = next(c for c in model.candidates if (c.name, c.where, c.variant) == key)
                e = fit_effect(model, T, d.nominal, c, _active(model, d),
                               fixed={q: having.parameters[q] for q in c.shape})
            pair.append(e)
        if None not in pair:
            out += library_change(pair[0], pair[1], floors, speed_mm_per_s, cand.shape, held)
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
    from blf.diagnose_fit import safe_predict
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


def floors_for(new_path: Path, profile: Path | None, check_path: Path | None) -> tuple[dict, str]:
    """(floors by kind, where they came from): the check profile's ``[diagnosis]`` table (``--check``, else
    the new recording's run folder's snapshot in meta.json, else the shipped check.toml); a key not given
    there is the measured default (:data:`hil.analysis.diagnose_floors.DUAL_FLOORS`)."""
    import dataclasses

    from hil.analysis.diagnose import check_for
    from hil.cli.common import actuation_for
    from hil.profile.load import load_check
    from hil.record.runfolder import read_record, resolve_recording
    _, run_dir = resolve_recording(new_path)
    meta = read_record(run_dir)
    act = actuation_for(profile, meta)
    if check_path is not None:
        check, src = load_check(check_path, act), f"check profile {check_path} [diagnosis]"
    else:
        snap = meta is not None and meta.profiles is not None and meta.profiles.check is not None
        check = check_for(meta, act)
        src = (f"the check profile of {run_dir} (meta.json snapshot) [diagnosis]" if snap
               else "the shipped check profile [diagnosis]")
    return dataclasses.asdict(check.diagnosis), src


def dual_reference_diagnosis(new_path: Path, ref_path: Path, profile: Path | None,
                             floors: dict | None = None, floors_source: str = "the measured defaults",
                             cache: dict | None = None) -> tuple:
    """(diagnosis.json, :class:`ReferenceFits` or None) of a dual-EMA recording against a reference
    recording (nothing written here). ``cache`` (a dict the caller keeps, for many pairs of few recordings):
    each recording's fit is looked up there by its path and the profile, and put there."""
    from blf.diagnose import diagnose
    from hil.analysis.diagnose import load_dual
    from hil.analysis.diagnose_floors import DUAL_FLOORS
    floors = dict(DUAL_FLOORS) | dict(floors or {})
    from blf.diagnose_cov import nominal_covariance
    from blf.errors import AnalysisError, InputError
    from hil.errors import RecordingError
    cache = {} if cache is None else cache
    keys = [(str(Path(path).resolve()), str(profile)) for path in (ref_path, new_path)]
    loaded = [cache[k][:2] if k in cache else load_dual(Path(path), profile)
              for k, path in zip(keys, (ref_path, new_path), strict=True)]
    (_, t_ref), (_, t_new) = loaded
    if abs(t_ref / t_new - 1.0) > 0.01:
        raise RecordingError(f"--reference {ref_path}: another sample rate: {1 / t_ref:.6g} Hz, this recording "
                             f"{1 / t_new:.6g} Hz (more than 1 % apart)")
    for k, path, (model, period) in zip(keys, (ref_path, new_path), loaded, strict=True):
        if k not in cache:
            try:
                d = diagnose(model, period)
                cache[k] = (model, period, d, nominal_covariance(model, period, d.nominal))
            except (InputError, AnalysisError) as exc:
                raise RecordingError(f"{path}: cannot be diagnosed: {exc}") from None
    fits = [cache[k][:3] for k in keys]
    (ref, cov_ref), (new, cov_new) = (cache[k][2:] for k in keys)
    speed = check_speed(fits[0][0])
    changes = nominal_changes(new.nominal, ref.nominal, cov_new, cov_ref, floors, speed)
    lib, pairs = _library_changes(fits, floors, speed)
    changes += lib
    effects = [_effect_of(c) for c in changes if c["named"]]
    rf = _fits(fits[1][0], ref, new, changes, pairs)
    eff = lambda d: [{"name": e.name, "where": e.where} for e in d.effects]  # noqa: E731
    unexplained = _unexplained(new, ref)
    appeared = unexplained["recording"] and not unexplained["reference"]
    return {
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
                  "defaults": dict(DUAL_FLOORS), "words": (
            "a change is named only when supported (|z| > 3) and above its floor (play um, stiffness, sensor and "
            "load cell gain %, friction N); a nominal parameter's floor is 3 sqrt(2) x the measured spread of the "
            "nominal fit and its u = floor/3 (hil/analysis/diagnose_floors.py, docs/diagnose.md)")},
        "effects_recording": eff(new), "effects_reference": eff(ref),
    }, rf


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
                                               else " against the measured repeatability")}


def _effect_name(parameter: str) -> str:
    for k in _KINDS:
        if parameter.startswith(k):
            return {"backlash_int": "internal_play_change", "backlash_bearing": "bearing_play_change",
                    "stiffness_int": "stiffness_change", "compliance_ext": "compliance_change",
                    "lvdt_pitch": "lvdt_pitch_change", "lvdt_offset": "lvdt_offset_change",
                    }[k]
    return {"external_play_mm": "external_play_change", "drive_friction_N": "drive_friction_change",
            "hinge_friction_N": "hinge_friction_change"}.get(parameter, parameter + "_change")
