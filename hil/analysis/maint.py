"""From a recording to the check's result: segments, LVDT calibration, BLFmaint.

Pure orchestration over :mod:`blf` (no file IO here; the commands read and
write files). Works on a run folder's signals (with the step column) and on a
bare signals CSV recorded elsewhere, whose calibration sweeps and force-fight
segments it finds itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from blf.errors import AnalysisError
from blf.maint import (
    MIN_SAMPLES,
    AccuracyBudget,
    BlfMaintResult,
    ChannelVerdict,
    LvdtCalibration,
    Segments,
    UncertaintyBudget,
    backlash_error_budget,
    blf_maint,
    decide,
    fit_lvdt_calibration,
    maint_uncertainty,
    overall,
    trim,
)
from blf.maint import find_segments as blf_find_segments
from blf.signals import CHANNELS, position_differences
from hil.analysis import plausible
from hil.analysis.budget import PAPER_PITCH_ERROR, budget_dict
from hil.errors import IncompleteRecordingError, RecordingError
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE, Actuation
from hil.record.runfolder import Signals

#: Relative pitch uncertainty of an LVDT used uncalibrated: the pitch error the supervisor tolerates,
#: as a rectangular bound (the analysis then says so in its notes).
UNCALIBRATED_PITCH_UNCERTAINTY = HARD_LVDT_GAIN_TOLERANCE / 3.0 ** 0.5


@dataclass(frozen=True)
class Analysis:
    segments: Segments
    calibration: dict  #: "ema1"/"ema2" -> LvdtCalibration or None
    d_int1: np.ndarray
    d_int2: np.ndarray
    d_ext: np.ndarray
    maint: dict  #: "int1"/"int2"/"ext" -> BlfMaintResult, or an error message (str)
    uncertainty: dict  #: "int1"/"int2"/"ext" -> UncertaintyBudget (None where not measured)
    verdicts: dict  #: "int1"/"int2"/"ext" -> ChannelVerdict
    budget: AccuracyBudget  #: the error budget of paper 2.3 for this check's profile and calibration
    status: str  #: "pass" | "fail" | "inconclusive" (blf.maint.verdict.overall)
    notes: tuple[str, ...] = field(default_factory=tuple)


def find_segments(sig: Signals, act: Actuation) -> Segments:
    """Calibration sweeps and force-fight samples of a recording (:func:`blf.maint.segments.find_segments`).

    From the step column when the recording has one, else detected from the
    ram motion (motor angles) and the force fight ``|F1 - F2|/2``.
    """
    i = act.mechanics.i_total_rad_per_mm
    return blf_find_segments(sig.phi1 / i, sig.phi2 / i, sig.F1, sig.F2, sig.sample_period_s,
                             act.mechanics.stroke_limit_mm, step=sig.step)


def check_units(sig: Signals, act: Actuation) -> None:
    """Refuse a recording whose columns are plainly in other units than the file format's.

    Time [s]: the median sample period must be within a factor 2 of the actuation's SYNC
    period (a column in ms is 1000 times too large). Stroke [mm]: |s| must stay within twice
    the stroke limit (a column in um is 1000 times too large). Force [N]: |F| must stay within
    the limit load (in kN, a check's forces would stay below 10 "N", which is noted, not
    refused: an unloaded recording looks the same).
    """
    T = act.timing.sync_period_s
    dt = sig.sample_period_s
    if not 0.5 * T <= dt <= 2.0 * T:
        hint = " (time in ms?)" if 500 * T <= dt <= 2000 * T else ""
        raise RecordingError(f"column 't' [s]: median sample period {dt:g} s does not match the actuation's "
                             f"SYNC period timing.sync_period_s = {T:g} s{hint}")
    lim = act.mechanics.stroke_limit_mm
    for name in ("s1", "s2"):
        peak = float(np.max(np.abs(getattr(sig, name))))
        if peak > 2.0 * lim:
            raise RecordingError(f"column '{name}' [mm]: |{name}| reaches {peak:g}, beyond twice the stroke limit "
                                 f"{lim:g} mm (stroke in um?)")
    for name in ("F1", "F2"):
        peak = float(np.max(np.abs(getattr(sig, name))))
        if peak > act.mechanics.limit_load_N:
            raise RecordingError(f"column '{name}' [N]: |{name}| reaches {peak:g}, beyond the limit load "
                                 f"{act.mechanics.limit_load_N:g} N (force in another unit?)")


def refuse_implausible(sig: Signals, act: Actuation, seg: Segments | None,
                       force_fight_fraction: float | None = None) -> None:
    """Refuse (:class:`hil.errors.RecordingError`) a recording that cannot belong to this actuation
    (:mod:`hil.analysis.plausible`): an LVDT off its motor's stroke by more than a factor 2, a force fight
    below a tenth of its level, load cells that disagree in it. For the diagnosis, whose library holds LVDT
    and load-cell gain errors of tens of per cent, but not units."""
    i = act.mechanics.i_total_rad_per_mm
    problems = []
    for k, (mask, phi, s) in enumerate(((None if seg is None else seg.cal1, sig.phi1, sig.s1),
                                        (None if seg is None else seg.cal2, sig.phi2, sig.s2)), start=1):
        if mask is not None:
            m = trim(mask)
            pitch, how = fit_lvdt_calibration(phi[m] / i, s[m]).pitch, "its calibration sweep"
        else:
            pitch, how = plausible.slope_pitch(phi / i, s), "the slope over the whole recording"
        words, gross = ("", False) if pitch is None else plausible.pitch_problem(k, pitch, how)
        if gross:
            problems.append(words)
    if seg is not None and np.count_nonzero(seg.force_fight) >= MIN_SAMPLES:
        F1, F2 = sig.F1[seg.force_fight], sig.F2[seg.force_fight]
        commanded = plausible.commanded_force_fight_N(act, force_fight_fraction)
        problems += [w for w in (plausible.force_fight_problem(F1, F2, commanded),
                                 plausible.load_cells_problem(F1, F2)) if w][:1]
    if problems:
        raise RecordingError("; ".join(problems) + ": the recording cannot belong to this actuation")


#: the fewest samples a recording of the check must hold to be analysed
MIN_SAMPLES_CHECK = 1000


def analyze_signals(sig: Signals, act: Actuation, force_fight_fraction: float | None = None) -> Analysis:
    """Calibrate the LVDTs, form the D signals and run BLFmaint on all three channels.

    ``force_fight_fraction``: the check's ``force_fight.amplitude_fraction_of_limit`` (a run folder's check
    profile); None, a bare recording: the paper's 15 %. The recording is checked against the actuation in
    physical units (:mod:`hil.analysis.plausible`): a gross unit error refused, a channel that cannot be
    this actuation's not measured (inconclusive), never a PASS.
    """
    if sig.n < MIN_SAMPLES_CHECK:
        raise IncompleteRecordingError(f"recording too short for the check: {sig.n} samples "
                                       f"(need >= {MIN_SAMPLES_CHECK})")
    check_units(sig, act)
    seg = find_segments(sig, act)
    i = act.mechanics.i_total_rad_per_mm
    notes = list(sig.notes)
    cal: dict[str, LvdtCalibration | None] = {}
    s_corr = {}
    implausible = {1: "", 2: ""}  #: per EMA: why its LVDT's scale is not this actuation's ("" plausible)
    gross = {1: False, 2: False}  #: ... by more than a factor 2: the recording refused
    for k, (mask, phi, s) in enumerate(((seg.cal1, sig.phi1, sig.s1), (seg.cal2, sig.phi2, sig.s2)), start=1):
        if mask is None:
            cal[f"ema{k}"] = None
            s_corr[k] = s
            notes.append(f"no calibration sweep for EMA {k}: LVDT {k} used uncorrected")
            slope = plausible.slope_pitch(phi / i, s)
            if slope is None:
                notes.append(f"the scale of LVDT {k} against motor angle {k} is not verifiable: the ram travelled "
                             f"less than {plausible.MIN_TRAVEL_FOR_SCALE_MM:g} mm")
            else:
                implausible[k], gross[k] = plausible.pitch_problem(k, slope, "the slope over the whole recording")
            continue
        m = trim(mask)
        c = fit_lvdt_calibration(phi[m] / i, s[m])
        implausible[k], gross[k] = plausible.pitch_problem(k, c.pitch, "its calibration sweep")
        cal[f"ema{k}"] = c
        s_corr[k] = c.correct(s)
    if any(gross.values()):
        raise RecordingError("; ".join(implausible[k] for k in (1, 2) if gross[k])
                             + ": the recording cannot belong to this actuation")
    # the corrected strokes are needed only for D: handed over, freed as soon as used (issue 34)
    d = position_differences(sig.phi1, sig.phi2, s_corr.pop(1), s_corr.pop(2), i)
    ff = seg.force_fight
    if int(np.count_nonzero(ff)) < MIN_SAMPLES:
        # e.g. a run killed or aborted just after the force fight began
        raise AnalysisError(f"force-fight segment too short for BLFmaint: {int(np.count_nonzero(ff))} samples "
                            f"(need >= {MIN_SAMPLES})")
    rate = 1.0 / sig.sample_period_s
    pairs = {
        "int1": (d.d_int1_mm, sig.F1),
        "int2": (d.d_int2_mm, sig.F2),
        "ext": (d.d_ext_mm, None),
    }
    maint: dict[str, BlfMaintResult | str] = {}
    commanded = plausible.commanded_force_fight_N(act, force_fight_fraction)
    weak_fight = (plausible.force_fight_problem(sig.F1[ff], sig.F2[ff], commanded)
                  or plausible.load_cells_problem(sig.F1[ff], sig.F2[ff]))
    for ch, (dd, ff_force) in pairs.items():
        emas = (1, 2) if ch == "ext" else (int(ch[-1]),)
        why = weak_fight or "; ".join(implausible[k] for k in emas if implausible[k])
        if why:  # not this actuation's: not measured, never a reading (nor a trend point)
            maint[ch] = why
            continue
        try:
            # F2 - F1 formed on the force fight only (elementwise: the same values as masking the difference)
            f_ff = sig.F2[ff] - sig.F1[ff] if ff_force is None else ff_force[ff]
            r = blf_maint(dd[ff], f_ff, rate)
        except AnalysisError as exc:  # the channel's verdict says why (its reason), once
            maint[ch] = str(exc)
            continue
        cols = "'s2', 's1', 'F2', 'F1'" if ch == "ext" else f"'s{ch[-1]}', 'phi{ch[-1]}', 'F{ch[-1]}'"
        maint[ch] = plausible.stiffness_problem(
            ch, {"left": r.stiffness_left_N_per_mm, "right": r.stiffness_right_N_per_mm},
            plausible.stiffness_range(act, ch, commanded), cols) or r
    p_rel = {k: (UNCALIBRATED_PITCH_UNCERTAINTY if c is None else abs(c.coefficient_sigmas[1] / c.pitch))
             for k, c in cal.items()}
    p_ch = {"int1": p_rel["ema1"], "int2": p_rel["ema2"], "ext": (p_rel["ema1"] ** 2 + p_rel["ema2"] ** 2) ** 0.5}
    unc: dict[str, UncertaintyBudget | None] = {}
    verdicts: dict[str, ChannelVerdict] = {}
    for ch in CHANNELS:
        r = maint[ch]
        limit = spec_mm(act, ch)
        if isinstance(r, BlfMaintResult):
            unc[ch] = maint_uncertainty(r.backlash_mm, r.backlash_sigma_mm, p_ch[ch])
            verdicts[ch] = decide(r.backlash_mm, unc[ch].expanded_mm, limit)
        else:
            unc[ch] = None
            verdicts[ch] = decide(None, None, limit, missing=r)
    pitches = [abs(c.pitch - 1.0) for c in cal.values() if c is not None]
    budget = backlash_error_budget(
        act.mechanics.stroke_limit_mm, max(pitches) if pitches else PAPER_PITCH_ERROR,
        act.sensors.lvdt_noise_pp_mm / 6.0, rate, backlash_mm=act.mechanics.backlash_spec_int_mm,
        residual_pitch_error=max(max(p_rel.values()), 1e-6), temperature_error=0.0)
    return Analysis(seg, cal, d.d_int1_mm, d.d_int2_mm, d.d_ext_mm, maint, unc, verdicts,
                    budget, overall(verdicts), tuple(notes))


def spec_mm(act: Actuation, channel: str) -> float:
    """B_spec of a channel [mm]: internal for int1/int2, external for ext."""
    m = act.mechanics
    return m.backlash_spec_ext_mm if channel == "ext" else m.backlash_spec_int_mm


def _f(x: float) -> float:
    return float(x)


def verdict_entry(v, u) -> dict:
    """result.json's ``verdict`` entry of one channel: its decision ``v``
    (:class:`blf.maint.verdict.ChannelVerdict`) and the uncertainty budget ``u`` behind it (None where the
    channel was not measured)."""
    return {"status": v.status, "backlash_mm": v.backlash_mm, "uncertainty_mm": v.uncertainty_mm,
            "limit_mm": v.limit_mm, "margin_mm": v.margin_mm, "reason": v.reason,
            "uncertainty_budget_mm": None if u is None else {
                "statistical": u.statistical_mm, "pitch": u.pitch_mm, "temperature": u.temperature_mm,
                "method": u.method_mm, "combined": u.combined_mm, "expanded": u.expanded_mm,
                "coverage_factor": u.coverage_factor}}


def result_dict(an: Analysis, act: Actuation, truth: dict | None = None) -> dict:
    """result.json content (names and units as in the README)."""
    bl, bls, st, stsig, extra = {}, {}, {}, {}, {}
    for ch in CHANNELS:
        r = an.maint[ch]
        if isinstance(r, BlfMaintResult):
            bl[ch] = _f(r.backlash_mm)
            bls[ch] = _f(r.backlash_sigma_mm)
            st[ch] = {"left": _f(r.stiffness_left_N_per_mm), "right": _f(r.stiffness_right_N_per_mm)}
            stsig[ch] = {"left": _f(r.stiffness_left_sigma_N_per_mm), "right": _f(r.stiffness_right_sigma_N_per_mm)}
            extra[ch] = {"d_lc_mm": _f(r.d_lc_mm), "d_rc_mm": _f(r.d_rc_mm), "slope_sign": int(r.slope_sign)}
        else:
            bl[ch] = bls[ch] = None
            st[ch] = stsig[ch] = {"left": None, "right": None}
            extra[ch] = {"error": r}
    calib = {}
    for k in ("ema1", "ema2"):
        c = an.calibration[k]
        calib[k] = None if c is None else {
            "pitch": _f(c.pitch), "offset_mm": _f(c.offset_mm), "nonlinearity_mm": _f(c.nonlinearity_mm),
            "rmse_mm": _f(c.rmse_mm)}
    verdict = {}
    for ch in CHANNELS:
        verdict[ch] = verdict_entry(an.verdicts[ch], an.uncertainty[ch])
    out = {
        "status": an.status,
        "verdict": verdict,
        "decision_rule": "ISO 14253-1 guard band: pass if B + U <= limit on every channel, fail if B - U > "
                         "limit on any, otherwise inconclusive; U expanded uncertainty, k = 2",
        "backlash_mm": bl,
        "backlash_sigma_mm": bls,
        "stiffness_N_per_mm": st,
        "stiffness_sigma_N_per_mm": stsig,
        "calibration": calib,
        "spec": {"backlash_int_mm": act.mechanics.backlash_spec_int_mm,
                 "backlash_ext_mm": act.mechanics.backlash_spec_ext_mm},
        "accuracy": budget_dict(an.budget),
        "blf_maint": extra,
        "segments": {"source": an.segments.source,
                     "force_fight_samples": int(an.segments.force_fight.sum())},
        "notes": list(an.notes),
    }
    if truth is not None:
        out["truth"] = truth
    return out
