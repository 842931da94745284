"""A single-axis recording as real drives record it, and its diagnosis against a reference recording.

The CSV layout (``emacheck diagnose FILE.csv --model single-axis``): ``t,q,q_ref`` (s, m, m), one
effort column, ``force`` (N), ``torque`` (N m, with ``--screw-lead-m``) or ``current`` (A, with
``--current-law`` and ``--current-per-force`` or a reference with a known load), and optionally
``load`` (N, a known external force on the axis, positive along +q). A ``.mat`` file holds the EMPS
keys ``t, qm, qg, vir, gtau`` (force ``gtau * vir``).

With ``--reference HEALTHY.csv`` (:func:`reference_diagnosis`) the nominal model is identified on
the reference and on the new recording alike (:mod:`blf.axis_reference`: masks, identifiability,
cluster-robust fit) and each nominal parameter is compared with its reference value; a change is
named only above its relevance floor (:data:`FORCE_FLOOR_N`, ``--force-floor-N``).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.errors import RecordingError

#: default relevance floor of a force parameter (friction, offset), N: 3 x the RMS of the
#: session-to-session changes of the healthy Cranfield actuator (``normal`` runs 1-5 against 6-10 at
#: +20 and +40 kgf: friction +15.8 and -43.2 N, offset -8.7 and +8.4 N; RMS 23.8 N, x 3 = 71.3 N),
#: rounded up to 75 N (docs/diagnose.md, "Floors"; tests/bench/bench_diagnose_cranfield.py --repeatability)
FORCE_FLOOR_N = 75.0
EFFORTS = ("force", "torque", "current")
_EFFECT = {"position_dependent_friction_N_per_m": "position_dependent_friction_change",
           "position_dependent_force_N_per_m": "position_dependent_force_change",
           "position_dependent_force_N_per_m2": "position_dependent_force_change",
           "friction_N": "friction_change", "coulomb_N": "coulomb_friction_change",
           "viscous_N_s_per_m": "viscous_friction_change", "offset_N": "direction_dependent_force_change",
           "mass_kg": "mass_change"}


@dataclass(frozen=True)
class AxisRecording:
    """One single-axis recording: columns in SI, the effort's kind, the sample rate."""

    path: Path
    t: np.ndarray
    q: np.ndarray
    q_ref: np.ndarray
    effort: np.ndarray
    kind: str  #: force, torque or current
    load: np.ndarray | None
    sample_rate_hz: float


@dataclass(frozen=True)
class AxisOptions:
    """How to read the effort and when a change is named."""

    current_law: str | None = None
    current_a_per_N: float | None = None
    screw_lead_m: float | None = None
    force_floor_N: float = FORCE_FLOOR_N
    z_min: float = 3.0


def read_axis(path: Path) -> AxisRecording:
    """A single-axis recording (CSV or EMPS ``.mat``), validated; :class:`RecordingError` names what is wrong."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    from hil.record.runfolder import read_text
    text = read_text(path, "a text CSV file (columns t,q,q_ref and force, torque or current)")
    if not text.strip():
        raise RecordingError(f"{path}: empty file; need columns t,q,q_ref (s, m, m) and force, torque or current")
    try:
        arr = np.genfromtxt(io.StringIO(text), delimiter=",", names=True)
    except (ValueError, IndexError, TypeError) as exc:
        raise RecordingError(f"{path}: not a readable CSV ({type(exc).__name__}: {exc})") from None
    names = arr.dtype.names or ()
    efforts = [c for c in EFFORTS if c in names]
    if any(c not in names for c in ("t", "q", "q_ref")) or len(efforts) != 1:
        raise RecordingError(f"{path}: line 1: need columns t,q,q_ref (s, m, m) and exactly one of force (N), "
                             f"torque (N m), current (A), optionally load (N); got {','.join(names) or 'none'}")
    cols = {c: np.atleast_1d(np.asarray(arr[c], dtype=float)) for c in ("t", "q", "q_ref", efforts[0])
            + (("load",) if "load" in names else ())}
    if not all(np.all(np.isfinite(x)) for x in cols.values()) or np.any(np.diff(cols["t"]) <= 0):
        raise RecordingError(f"{path}: NaN, empty cells or non-increasing time")
    return _recording(path, cols["t"], cols["q"], cols["q_ref"], cols[efforts[0]], efforts[0], cols.get("load"))


def _read_mat(path: Path) -> AxisRecording:
    import struct
    import zlib

    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError
    try:
        d = loadmat(path)
    except (OSError, ValueError, EOFError, zlib.error, struct.error, TypeError, IndexError, KeyError,
            NotImplementedError, MatReadError) as exc:  # a corrupt or truncated file, whatever scipy met
        raise RecordingError(f"{path}: not a readable .mat file ({type(exc).__name__}: {exc})") from None
    missing = [k for k in ("t", "qm", "qg", "vir", "gtau") if k not in d]
    if missing:
        raise RecordingError(f"{path}: missing key(s) {', '.join(missing)}; expected t, qm, qg, vir, gtau")
    try:
        t = np.asarray(d["t"], dtype=float).ravel()
        force = float(np.ravel(d["gtau"])[0]) * np.asarray(d["vir"], dtype=float).ravel()
        q, qref = np.asarray(d["qm"], dtype=float).ravel(), np.asarray(d["qg"], dtype=float).ravel()
    except (TypeError, ValueError, IndexError) as exc:
        raise RecordingError(f"{path}: t, qm, qg, vir, gtau must be numeric arrays ({exc})") from None
    if not t.size == q.size == qref.size == force.size:
        raise RecordingError(f"{path}: t, qm, qg and vir must be equally long arrays "
                             f"(got {t.size}, {q.size}, {qref.size}, {force.size})")
    if not all(np.all(np.isfinite(x)) for x in (t, q, qref, force)) or np.any(np.diff(t) <= 0):
        raise RecordingError(f"{path}: NaN or non-increasing time in t, qm, qg, vir")
    return _recording(path, t, q, qref, force, "force", None)


def _recording(path, t, q, q_ref, effort, kind, load) -> AxisRecording:
    if t.size < 200:
        raise RecordingError(f"{path}: {t.size} samples: too short (need >= 200)")
    dt = np.diff(t)
    period = float(np.median(dt))
    if np.max(np.abs(dt - period)) > 0.01 * period:
        raise RecordingError(f"{path}: the sample period varies by more than 1 % (median {period:.6g} s)")
    return AxisRecording(path, t, q, q_ref, effort, kind, load, 1.0 / period)


def _direction(rec: AxisRecording, moving: np.ndarray) -> np.ndarray:
    vr = np.gradient(rec.q_ref, rec.t)
    return np.where(moving, np.sign(vr), 0.0)


def _mask(rec: AxisRecording, opts: AxisOptions, *, reference_mode: bool = False):
    """Dwells masked with a supply current (the holding current), and in the reference mode with any effort
    (standing still, the friction force is anywhere in its static band: the linear model's sign(v) is not
    defined there); catch-ups masked with a current."""
    from blf.axis_reference import effort_mask
    power = rec.kind == "current" and opts.current_law == "power"
    return effort_mask(rec.t, rec.q, rec.q_ref, rec.sample_rate_hz, dwell_says_nothing=power or reference_mode,
                       mask_transients=rec.kind == "current")


def conversion(rec: AxisRecording, opts: AxisOptions, reference: AxisRecording | None = None) -> tuple:
    """(A per N or None, words, relative standard uncertainty of the gain): how the effort becomes a force;
    :class:`RecordingError` where it cannot (a stated gain or a force, torque: uncertainty 0)."""
    from blf.axis_reference import identify_current_per_force
    from blf.errors import AnalysisError
    if rec.kind == "force":
        return None, "force column (N) as recorded", 0.0
    if rec.kind == "torque":
        if opts.screw_lead_m is None:
            raise RecordingError(f"{rec.path}: a torque (N m) needs the screw lead (--screw-lead-m) to become a force")
        return None, f"torque x 2 pi / lead ({opts.screw_lead_m:g} m per revolution)", 0.0
    if opts.current_law is None:
        raise RecordingError(f"{rec.path}: a current (A) with no way to convert it: state --current-law (torque: "
                             "a phase current that follows the torque; power: a supply current that follows "
                             "mechanical power)")
    if opts.current_a_per_N is not None:
        return opts.current_a_per_N, f"{opts.current_law} law, k = {opts.current_a_per_N:g} A/N (stated)", 0.0
    src = reference
    if src is None or src.load is None:
        raise RecordingError(f"{rec.path}: a current (A) with no way to convert it: state --current-per-force, or "
                             "give a --reference with a known load (a load column in N)")
    m = _mask(src, opts, reference_mode=True)
    try:
        gain = identify_current_per_force(src.effort, src.load, _direction(src, m.moving), m.used, opts.current_law)
    except AnalysisError as exc:
        raise RecordingError(f"{src.path}: {exc}") from None
    return (gain.a_per_N, gain.words + f" (identified on the reference {src.path.name})",
            gain.uncertainty_a_per_N / gain.a_per_N)


def axis_force(rec: AxisRecording, opts: AxisOptions, k: float | None, moving: np.ndarray) -> np.ndarray:
    """The drive's force along +q (N) from the recorded effort."""
    from blf.axis_reference import effort_to_force
    return effort_to_force(rec.effort, rec.kind, v_dir=_direction(rec, moving), lead_m=opts.screw_lead_m,
                           current_law=opts.current_law, current_a_per_N=k)


def _accel_noise(q: np.ndarray, fs: float) -> float:
    from scipy.signal import savgol_coeffs
    sq = float(np.sqrt(np.mean(np.diff(q, 2) ** 2) / 6))
    w = max(7, int(round(0.4 * fs)) | 1)
    return sq * float(np.linalg.norm(savgol_coeffs(w, 3, deriv=2, delta=1 / fs)))


@dataclass(frozen=True)
class _Prepared:
    force: np.ndarray
    v: np.ndarray
    a: np.ndarray
    mask: object
    ident: object


def _prepare(rec: AxisRecording, opts: AxisOptions, k: float | None) -> _Prepared:
    from blf.axis_reference import axis_kinematics, identifiability
    m = _mask(rec, opts, reference_mode=True)
    v, a = axis_kinematics(rec.q, rec.sample_rate_hz)
    vr = np.gradient(rec.q_ref, rec.t)
    ident = identifiability(v, a, vr, m.used, _accel_noise(rec.q, rec.sample_rate_hz))
    return _Prepared(axis_force(rec, opts, k, m.moving), v, a, m, ident)


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


def _stroke_candidates(pr: _Prepared, pn: _Prepared, ref: AxisRecording, new: AxisRecording, ident) -> tuple:
    """The terms along the stroke both recordings can separate from the nominal ones: (origin, half stroke,
    columns of the reference, columns of the new recording, not separable [(name, why)])."""
    from blf.axis_reference import design_columns, separable, stroke_terms
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


def identifiability_dict(model) -> dict | None:
    """diagnosis.json's ``identifiability`` of a single-axis replay model (None for another model)."""
    ident = getattr(model, "identifiability", None)
    if ident is None:
        return None
    out = _ident_dict(ident) | {"not_candidates": [{"name": n, "why": w} for n, w in model.not_candidates]}
    if getattr(model, "effort_mask", None) is not None:
        out["mask"] = _mask_dict(model.effort_mask)
    return out


def _ident_dict(ident) -> dict:
    return {"fitted": list(ident.columns), "fixed": dict(ident.fixed),
            "cannot_tell_apart": [{"terms": list(t), "into": into, "why": why, "would_separate": motion}
                                  for t, into, why, motion in ident.merged],
            "speed_levels_m_per_s": [float(f"{s:.6g}") for s in ident.speed_levels_m_per_s],
            "directions": list(ident.directions), "variance_inflation": {k: float(f"{v:.4g}")
                                                                          for k, v in ident.vif.items()}}


def _mask_dict(m) -> dict:
    r = lambda s: [[round(a, 3), round(b, 3)] for a, b in s]  # noqa: E731
    return {"samples_used": int(m.used.sum()), "dwell_masked": m.n_dwell, "transient_masked": m.n_transient,
            "dwell_spans_s": r(m.dwell_spans_s[:50]), "transient_spans_s": r(m.transient_spans_s[:50]),
            "words": m.words}


def reference_diagnosis(new_path: Path, ref_path: Path, opts: AxisOptions) -> dict:
    """diagnosis.json of a single-axis recording against a reference (nothing written here).

    :class:`RecordingError` (exit 3) for a reference of the other model, other sample rate or other
    columns, a current with no way to convert it, a reference too short to identify the nominal model.
    """
    from blf.axis_reference import compare_fits, fit_axis
    from blf.errors import AnalysisError
    new = read_axis(new_path)
    try:
        ref = read_axis(ref_path)
    except RecordingError as exc:
        raise RecordingError(f"--reference: {exc} (a single-axis recording is needed)") from None
    _check_pair(new, ref)
    k, conv_words, k_rel_u = conversion(new, opts, ref)
    pn, pr = _prepare(new, opts, k), _prepare(ref, opts, k)
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
        "reference": {"recording": str(ref.path), "nominal": _rd(fr.parameters), "uncertainty": _rd(fr.uncertainty),
                      "residual_rms_N": _r(fr.residual_rms_N), "mask": _mask_dict(pr.mask)},
        "nominal": _rd(fn.parameters), "nominal_uncertainty": _rd(fn.uncertainty),
        "residual_rms_N": _r(fn.residual_rms_N), "mask": _mask_dict(pn.mask),
        "changes": [_change(c, effort["trusted"]) for c in changes],
        "floor": {"force_N": opts.force_floor_N, "z_min": opts.z_min, "words": (
            "a change is named only when |change| > z_min combined standard uncertainties and > its floor; "
            f"force parameters {opts.force_floor_N:g} N" + (" (default: 3 x RMS of the healthy Cranfield "
                                                            "actuator's session-to-session changes)"
                                                            if opts.force_floor_N == FORCE_FLOOR_N else
                                                            " (stated)"))},
        "identifiability": _ident_dict(ident) | {"not_candidates": [{"name": n, "why": w} for n, w in not_cand]},
        "stroke": {"origin_m": _r(origin), "half_stroke_m": _r(half), "words": (
            "terms along the stroke screened against the reference (fitted beside the nominal ones on both); "
            "their floors: the force floor at the end of the stroke, half_stroke_m from the origin")},
        "conversion": conv_words, "sample_rate_hz": _r(new.sample_rate_hz),
        "running_speed_m_per_s": _r(fn.running_speed_m_per_s),
    }


def effort_checks(fn, fr, new: AxisRecording, ref: AxisRecording, pn, pr, opts: AxisOptions, k_rel_u: float) -> dict:
    """diagnosis.json's ``effort``: does each recording's effort see its known load
    (:func:`blf.axis_reference.effort_load_check`, allowance the force floor)? ``trusted`` is False when
    either does not: its force content is contradicted by the load, nothing is diagnosed from it."""
    from blf.axis_reference import effort_load_check
    out, bad = {}, []
    identified_on_ref = opts.current_a_per_N is None and new.kind == "current"
    for key, fit, rec, p in (("recording", fn, new, pn), ("reference", fr, ref, pr)):
        c = effort_load_check(fit, rec.load, p.mask.used, opts.force_floor_N, opts.z_min, k_rel_u)
        words = c.words + ("; the conversion was identified on this load (consistent by construction)"
                           if key == "reference" and identified_on_ref and c.made else "")
        out[key] = {"path": str(rec.path), "checked": c.made, "trusted": c.trusted, "load_N": _r(c.load_N),
                    "seen_N": _r(c.seen_N), "uncertainty_N": _r(c.uncertainty_N), "words": words}
        if c.made and not c.trusted:
            bad.append(f"{rec.path.name}: {c.words}")
    out["trusted"] = not bad
    out["words"] = ("; ".join(bad) if bad else "each effort that could be checked sees its known load with the "
                    "sign the conversion predicts")
    return out


def _change(c, trusted: bool = True) -> dict:
    words = c.words if trusted else c.words.split("; ")[0] + "; not diagnosed: the effort is not trusted"
    return {"parameter": c.name, "value": _r(c.value), "reference": _r(c.reference), "change": _r(c.change),
            "uncertainty": _r(c.uncertainty), "z": _r(c.z, 4), "floor": _r(c.floor),
            "supported": c.supported, "above_floor": c.relevant, "named": c.named and trusted, "words": words}


def _effect(c) -> dict:
    return {"name": _EFFECT.get(c.name, c.name + "_change"), "where": "axis", "words": c.words,
            "source": "reference", "parameters": {c.name: _r(c.value)}, "uncertainty": {c.name: _r(c.uncertainty)},
            "change": {c.name: _r(c.change)}, "floor": {c.name: _r(c.floor)}, "delta_bic": None,
            "delta_chi2_holdout": None, "evidence": f"z = {c.z:.1f}, |change| {abs(c.change):.4g} > floor {c.floor:g}"}


def _r(x, nd=6):
    return None if x is None else float(f"{x:.{nd}g}")


def _rd(d: dict) -> dict:
    return {k: _r(v) for k, v in d.items()}


def model_effort_check(rec: AxisRecording, opts: AxisOptions) -> dict | None:
    """Without a reference: diagnosis.json's ``effort`` of a single-axis recording (:func:`read_axis`) with a
    known load (the nominal model fitted on it alone, :func:`blf.axis_reference.effort_load_check`); None
    without a load."""
    from blf.axis_reference import effort_load_check, fit_axis
    from blf.errors import AnalysisError
    if rec.load is None:
        return None
    k, _, rel = conversion(rec, opts)
    p = _prepare(rec, opts, k)
    try:
        fit = fit_axis(p.force, p.v, p.a, p.mask.used, p.ident, rec.load)
    except AnalysisError as exc:
        return {"trusted": True, "words": f"the effort could not be checked against the load ({exc})"}
    c = effort_load_check(fit, rec.load, p.mask.used, opts.force_floor_N, opts.z_min, rel)
    entry = {"path": str(rec.path), "checked": c.made, "trusted": c.trusted, "load_N": _r(c.load_N),
             "seen_N": _r(c.seen_N), "uncertainty_N": _r(c.uncertainty_N), "words": c.words}
    return {"trusted": not (c.made and not c.trusted), "words": c.words, "recording": entry}


def untrusted_dict(effort: dict) -> dict:
    """diagnosis.json of a recording whose effort is not trusted: the reason, nothing diagnosed."""
    return {"verdict": "untrusted_effort", "model": "single-axis", "mode": "model", "effects": [], "where": [],
            "locations": [], "effort": effort,
            "band": {"cutoff_hz": None, "step": 1, "words": "nothing compared: the effort is not trusted"}}


def single_axis_model(rec: AxisRecording, opts: AxisOptions):
    """The replay model of :func:`blf.diagnose.diagnose` (no reference) and its sample period (s), of a
    single-axis recording (:func:`read_axis`).

    A current needs its conversion stated (law and gain); the masked samples are not compared."""
    from sim.single_axis import SingleAxisReplay
    k, _, _ = conversion(rec, opts)
    m = _mask(rec, opts)
    force = axis_force(rec, opts, k, m.moving)
    if rec.load is not None:
        force = force + rec.load
    model = SingleAxisReplay(rec.t, rec.q, rec.q_ref, force, 1.0 / rec.sample_rate_hz, valid=m.used)
    model.effort_mask = m
    return model, 1.0 / rec.sample_rate_hz


def effect_sizes_N(model, d) -> dict:
    """Each library effect's size as a force: the largest change of the predicted force over the samples
    compared when it alone is taken out (N), at the fitted nominal parameters."""
    theta = np.array([d.nominal[n] for n in model.names])
    by_name = {c.name: c for c in model.candidates}
    active = [(by_name[e.name], np.array([e.parameters[p.name] for p in by_name[e.name].params]))
              for e in d.effects if e.name in by_name]
    ok = model.valid["force"]
    full = model.predict(theta, active)["force"]
    return {cand.name: float(np.max(np.abs(full - model.predict(theta, [a for a in active if a[0] is not cand])
                                           ["force"])[ok]))
            for cand, _ in active}


def apply_force_floor(data: dict, sizes: dict, floor_N: float) -> dict:
    """diagnosis.json of a single axis without a reference with a stated force floor: an effect whose force
    is under it is moved to ``below_floor`` (named no more); an ``explained`` verdict left without
    effects becomes ``no_mismatch``. The residual figures stay those of the fit with every effect."""
    keep, below = [], []
    for e in data["effects"]:
        size = sizes.get(e["name"])
        e["size_N"] = _r(size)
        (below if size is not None and size <= floor_N else keep).append(e)
    data["effects"], data["below_floor"] = keep, below
    data["floor"] = {"force_N": floor_N, "words": (
        f"an effect is named only when its force (the largest change of the predicted force it makes over the "
        f"samples compared) exceeds {floor_N:g} N (stated); residual figures include every accepted effect")}
    if data["verdict"] == "explained" and not keep:
        data["verdict"] = "no_mismatch"
    return data
