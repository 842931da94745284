"""A dual-EMA recording against a reference recording of the same rig: which nominal parameter changed.

``emacheck diagnose NEW --reference HEALTHY`` (dual-EMA model): the nominal model
(:class:`sim.replay_model.DualEmaReplay`, :func:`blf.diagnose.diagnose`) is identified on the
reference and on the new recording alike; each nominal parameter with a floor (per EMA internal play,
bearing play, contact stiffness, compliance, LVDT pitch and offset; hinge and drive Coulomb friction)
is compared with its reference value in its floor's unit (um, %, N).

Uncertainty of a change: the measured repeatability of the nominal fit
(:mod:`hil.analysis.diagnose_floors`: the floor is :math:`3\\sqrt2\\,\\sigma`, so a change carries
:math:`u = \\sqrt2\\,\\sigma = \\mathrm{floor}/3`); a change is named when :math:`|\\Delta| >` its floor,
i.e. :math:`|z| = |\\Delta|/u > 3`: statistically supported against the measured spread, and
relevant, in one test. The library effects each recording's own diagnosis accepts are listed beside
(``effects_recording``, ``effects_reference``), not named as changes.
"""

from __future__ import annotations

from pathlib import Path

#: nominal parameter name prefix -> (floor key of DUAL_FLOORS, unit, words)
_KINDS = {"backlash_int": ("play_um", "um", "internal play"), "backlash_bearing": ("play_um", "um", "bearing play"),
          "stiffness_int": ("stiffness_pct", "%", "contact stiffness"),
          "compliance_ext": ("stiffness_pct", "%", "bearing-plus-housing compliance"),
          "lvdt_pitch": ("sensor_gain_pct", "%", "LVDT pitch (gain)"),
          "lvdt_offset": ("play_um", "um", "LVDT offset"),
          "hinge_coulomb_N": ("friction_N", "N", "hinge Coulomb friction"),
          "drive_coulomb_N": ("friction_N", "N", "drives' Coulomb friction")}


def _where(name: str) -> str:
    """ema1, ema2 for a per-EMA parameter (its prefix followed by the EMA's number), else external."""
    import re
    m = re.match(r"^(?:backlash_int|stiffness_int|backlash_bearing|compliance_ext|lvdt_pitch|lvdt_offset)([12])", name)
    return f"ema{m.group(1)}" if m else "external"


def _change(name: str, new: float, ref: float, floors: dict) -> dict | None:
    kind = next((v for k, v in _KINDS.items() if name.startswith(k)), None)
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
            "words": f"{words} {verb} by {abs(ch):.3g} ± {u:.2g} {unit}; {how}"}


def dual_reference_diagnosis(new_path: Path, ref_path: Path, profile: Path | None, floors: dict | None = None) -> dict:
    """diagnosis.json of a dual-EMA recording against a reference recording (nothing written here)."""
    from blf.diagnose import diagnose
    from hil.analysis.diagnose import load_dual
    from hil.analysis.diagnose_floors import DUAL_FLOORS
    floors = dict(DUAL_FLOORS) | dict(floors or {})
    fits = []
    for path in (ref_path, new_path):
        model, period = load_dual(Path(path), profile)
        fits.append(diagnose(model, period))
    ref, new = fits
    changes = [c for c in (_change(n, float(new.nominal[n]), float(ref.nominal[n]), floors)
                           for n in new.nominal if n in ref.nominal) if c is not None]
    effects = [{"name": _effect_name(c["parameter"]), "where": c["where"], "words": c["words"], "source": "reference",
                "parameters": {c["parameter"]: c["value"]}, "uncertainty": {c["parameter"]: c["uncertainty"]},
                "change": {c["parameter"]: c["change"]}, "floor": {c["parameter"]: c["floor"]},
                "delta_bic": None, "delta_chi2_holdout": None, "evidence": f"z = {c['z']:.1f} against the measured "
                "repeatability"} for c in changes if c["named"]]
    eff = lambda d: [{"name": e.name, "where": e.where} for e in d.effects]  # noqa: E731
    return {
        "verdict": "explained" if effects else "no_mismatch", "model": "dual-ema", "mode": "reference",
        "effects": effects, "where": [], "locations": [],
        "band": {"cutoff_hz": None, "step": 1, "words": "each recording's nominal fit (emacheck diagnose)"},
        "reference": {"recording": str(ref_path), "nominal": dict(ref.nominal), "uncertainty": {},
                      "words": "no per-fit uncertainty: each change's is the measured repeatability (changes)"},
        "nominal": dict(new.nominal), "changes": changes,
        "floor": {"force_N": floors["friction_N"], "z_min": 3.0, "by_kind": floors, "words": (
            "a change is named only above its floor (play um, stiffness and sensor gain %, friction N); the floor is "
            "3 sqrt(2) x the measured spread of the nominal fit, so above it |z| > 3 (hil/analysis/diagnose_floors.py, "
            "docs/diagnose.md)")},
        "effects_recording": eff(new), "effects_reference": eff(ref),
    }


def _effect_name(parameter: str) -> str:
    for k in _KINDS:
        if parameter.startswith(k):
            return {"backlash_int": "internal_play_change", "backlash_bearing": "bearing_play_change",
                    "stiffness_int": "stiffness_change", "compliance_ext": "compliance_change",
                    "lvdt_pitch": "lvdt_pitch_change", "lvdt_offset": "lvdt_offset_change",
                    "hinge_coulomb_N": "hinge_friction_change", "drive_coulomb_N": "drive_friction_change"}[k]
    return parameter + "_change"
