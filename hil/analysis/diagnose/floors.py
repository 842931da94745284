"""Each parameter a dual-EMA comparison names, against its floor: which floors apply, what each change is.

The floors come from the check profile (``[diagnosis]``, :class:`hil.profile.config.DiagnosisFloors`;
their measured defaults and how measured: :mod:`hil.profile.floors`): :func:`floors_for` picks the
profile (``--check``, else the run folder's snapshot, else the shipped one). Each nominal parameter is
compared in its floor's unit (:data:`KINDS`), and so is what a check determines where it cannot tell two
parameters apart: the external play (the sum of the bearing plays, :data:`SUMS`) and the friction at the
check's speed (:data:`FRICTIONS`, :func:`check_speed`); a parameter the recordings do not determine alone
(:data:`VIF_MAX`) is listed, never named (:func:`nominal_changes`). A library effect's parameters are
compared by :func:`library_change` against :data:`LIBRARY_FLOORS`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: nominal parameter name prefix -> (floor key of DUAL_FLOORS, unit, words); the Coulomb frictions are not
#: compared alone but as the force at the check's speed (:data:`FRICTIONS`), the bearing plays also as their
#: sum (:data:`SUMS`)
KINDS = {"backlash_int": ("play_um", "um", "internal play"), "backlash_bearing": ("play_um", "um", "bearing play"),
          "stiffness_int": ("stiffness_pct", "%", "contact stiffness"),
          "compliance_ext": ("compliance_pct", "%", "bearing-plus-housing compliance"),
          "lvdt_pitch": ("sensor_gain_pct", "%", "LVDT pitch (gain)"),
          "lvdt_offset": ("play_um", "um", "LVDT offset")}


#: derived parameter -> (the nominal parameters summed, floor key, unit, words): the check's force fight loads the
#: two EMAs' bearings with equal and opposite forces, so only their sum is in the recording (docs/diagnose.md)
SUMS = {"external_play_mm": (("backlash_bearing1_mm", "backlash_bearing2_mm"), "external_play_um", "um",
                              "external play (both bearings)")}


#: derived parameter -> (Coulomb parameter N, viscous parameter N s/mm, words): the friction force
#: F(v) = F_c + b v at the check's speed v (mm/s; :func:`check_speed`): a check that moves at one speed
#: determines the friction there, not F_c and b apart (on the independent rig their fitted split moves by
#: 16 N between recordings while F at 2 mm/s stays within 0.5 N; docs/diagnose.md)
FRICTIONS = {"drive_friction_N": ("drive_coulomb_N", "drive_viscous_N_s_per_mm", "drives' friction"),
              "hinge_friction_N": ("hinge_coulomb_N", "hinge_viscous_N_s_per_mm", "hinge friction")}


#: a nominal parameter whose variance inflation factor (:func:`blf.diagnose.covariance.nominal_covariance`) reaches
#: this on either recording is not compared alone: its white-noise uncertainty is then at least 1000 times what it would
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
    kind = kind or next((v for k, v in KINDS.items() if name.startswith(k)), None)
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
    summed = next((k for k, v in SUMS.items() if c["parameter"] in v[0]), None)
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
    :class:`blf.diagnose.model.NominalCovariance`. Per parameter of :data:`KINDS` the change in its floor's unit,
    not separable (never named) where its variance inflation reaches :data:`VIF_MAX` on either recording; the
    sums of :data:`SUMS`; the frictions of :data:`FRICTIONS` at ``speed_mm_per_s`` (the reference's
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
    for name, (parts, key, unit, words) in SUMS.items():
        if all(q in new and q in ref for q in parts):
            c = _change(name, sum(float(new[q]) for q in parts), sum(float(ref[q]) for q in parts), floors,
                        (key, unit, words))
            out.append(c | {"of": list(parts)})
    for name, (fc, b, words) in FRICTIONS.items():
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
#: tests/bench/bench_diagnose_floors.py); a shape parameter (:attr:`blf.diagnose.model.Candidate.shape`) has none
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
    # an extra force at one EMA, as the frictions' (docs/diagnose.md, "Forces periodic in position")
    ("periodic_force", "amplitude_N"): ("ema_friction_N", "N", 1.0, "amplitude of a force periodic in position"),
}


def library_change(e_new, e_ref, floors: dict, speed_mm_per_s: float = 0.0, shape: tuple = (),
                   held: str | None = None) -> list:
    """The changes of one library effect's parameters between the reference and the new recording, each
    fitted on both (:func:`blf.diagnose.engine.fit_effect` where not accepted): change = new - reference in the
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


def floors_for(new, check_path: Path | None) -> tuple[dict, str]:
    """(floors by kind, where they came from) of a comparison of the recording ``new``
    (:class:`hil.analysis.diagnose.load.DualRecording`): the check profile's ``[diagnosis]`` table
    (``--check``, else the one it was made with: its run folder's snapshot in meta.json, else the shipped
    check.toml); a key not given there is the measured default (:data:`hil.profile.floors.DUAL_FLOORS`)."""
    import dataclasses

    from hil.profile.load import load_check
    if check_path is not None:
        check, src = load_check(check_path, new.act), f"check profile {check_path} [diagnosis]"
    else:
        meta = new.meta
        snap = meta is not None and meta.profiles is not None and meta.profiles.check is not None
        check = new.check
        src = (f"the check profile of {new.run_dir} (meta.json snapshot) [diagnosis]" if snap
               else "the shipped check profile [diagnosis]")
    return dataclasses.asdict(check.diagnosis), src
