"""BLFserv on a recording: the LVDT calibration to use, the analysis, serv.json (for ``emacheck serv``).

Input: a run folder (``signals.csv``, or ``can.log`` alone), a bare signals
CSV (columns ``t,phi1,phi2,s1,s2,F1,F2``) or a raw CAN log (``*.log``,
candump ``-L`` format, decoded by :func:`hil.record.canlog.decode_can_log`).

LVDT calibration, first that applies:

1. ``--calibration RESULT.json``: pitch and offset of both LVDTs from a
   maintenance check's result.json (a linear correction);
2. a run folder whose signals carry the check's calibration sweeps (step
   column ``cal1_sweep``/``cal2_sweep``): the full cubic calibration is fitted
   again from them (:func:`blf.maint.calibration.fit_lvdt_calibration`);
3. the run folder's ``result.json`` calibration (pitch and offset, linear);
4. a slow sweep under load found in the recording itself (per EMA: ram
   speed 0.3 to 10 mm/s over at least half the stroke limit, its force of
   one sign, mean above 200 N, :func:`blf.maint.segments.find_sweep`): cubic fit on it;
5. none: the LVDT data are used uncorrected, and serv.json and the report
   say so (a pitch error then shows as spurious jumps, paper 2.3).

Outputs in ``--out`` (default: the run folder, or the CSV's folder):
``serv.json`` and ``serv_report.html`` (not with ``--no-report``). Exit
status 0, or 3 for bad input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from blf.errors import AnalysisError, InputError
from blf.maint import (
    AccuracyBudget,
    backlash_error_budget,
    correct_linear,
    decide,
    find_sweep,
    fit_lvdt_calibration,
    overall,
    runs,
    serv_uncertainty,
)
from blf.serv import blf_serv, estimate_noise_std_mm, motion_through_jumps, with_known_scale
from blf.signals import CHANNELS, position_differences
from hil.analysis import plausible
from hil.analysis.budget import PAPER_PITCH_ERROR, budget_dict
from hil.analysis.maint import spec_mm
from hil.errors import RecordingError, UnusableRecordingError
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE, Actuation
from hil.record.runfolder import Signals


@dataclass(frozen=True)
class LvdtCorrection:
    """How the LVDT strokes of one recording were corrected."""

    source: str  #: where the calibration came from (see the module docstring)
    kind: dict  #: "ema1"/"ema2" -> "polynomial" | "linear" | "none"
    pitch: dict  #: "ema1"/"ema2" -> pitch or None
    offset_mm: dict  #: "ema1"/"ema2" -> offset or None
    residual_pitch_error: float | None  #: relative pitch uncertainty left (for the accuracy budget)
    s1_mm: np.ndarray
    s2_mm: np.ndarray
    notes: tuple
    file: Path | None = None  #: the result.json the calibration was read from (None: none, or the recording's own)


def _from_result_json(path: Path) -> dict:
    from hil.record.runfolder import read_json

    res = read_json(path)
    cal = res.get("calibration") if isinstance(res, dict) else None
    if not isinstance(cal, dict):
        raise RecordingError(f"{path}: no 'calibration' object (expected a maintenance check's result.json)")
    out = {}
    for k in ("ema1", "ema2"):
        c = cal.get(k)
        if c is None:
            out[k] = None
            continue
        try:
            pitch, off = float(c["pitch"]), float(c["offset_mm"])
        except (KeyError, TypeError, ValueError):
            raise RecordingError(f"{path}: calibration.{k} needs numeric 'pitch' and 'offset_mm'") from None
        if not (math.isfinite(pitch) and pitch > 0 and math.isfinite(off)):
            raise RecordingError(f"{path}: calibration.{k}: pitch {pitch!r} must be > 0, offset finite")
        out[k] = (pitch, off)
    return out


def choose_calibration(sig: Signals, act: Actuation, run_dir: Path | None,
                       calibration_file: Path | None) -> LvdtCorrection:
    """Pick the LVDT calibration for a recording (order in the module docstring) and apply it."""
    i = act.mechanics.i_total_rad_per_mm
    notes: list[str] = []

    def poly(cals: dict, source: str) -> LvdtCorrection:
        s = {}
        res_err = []
        for k, raw in (("ema1", sig.s1), ("ema2", sig.s2)):
            s[k] = cals[k].correct(raw)
            res_err.append(cals[k].coefficient_sigmas[1] / cals[k].pitch)
        return LvdtCorrection(source, {"ema1": "polynomial", "ema2": "polynomial"},
                              {k: float(cals[k].pitch) for k in cals}, {k: float(cals[k].offset_mm) for k in cals},
                              max(1e-4, float(max(res_err))), s["ema1"], s["ema2"], tuple(notes))

    def linear(lin: dict, source: str, file: Path) -> LvdtCorrection:
        return LvdtCorrection(source, {"ema1": "linear", "ema2": "linear"},
                              {k: lin[k][0] for k in lin}, {k: lin[k][1] for k in lin}, 1e-3,
                              correct_linear(sig.s1, *lin["ema1"]), correct_linear(sig.s2, *lin["ema2"]),
                              tuple(notes), Path(file))

    if calibration_file is not None:
        lin = _from_result_json(Path(calibration_file))
        if lin["ema1"] is None or lin["ema2"] is None:
            raise RecordingError(f"{calibration_file}: calibration of both LVDTs needed (ema1, ema2)")
        return linear(lin, f"--calibration {calibration_file}", calibration_file)
    if sig.step is not None:
        m1, m2 = sig.step == "cal1_sweep", sig.step == "cal2_sweep"
        if m1.sum() >= 100 and m2.sum() >= 100:
            cals = {"ema1": fit_lvdt_calibration(sig.phi1[m1] / i, sig.s1[m1]),
                    "ema2": fit_lvdt_calibration(sig.phi2[m2] / i, sig.s2[m2])}
            return poly(cals, "calibration sweeps of the run folder (step column)")
    if run_dir is not None and (run_dir / "result.json").exists():
        try:
            lin = _from_result_json(run_dir / "result.json")
        except RecordingError as exc:
            notes.append(f"result.json not usable for calibration: {exc}")
            lin = None
        if lin is not None and lin["ema1"] is not None and lin["ema2"] is not None:
            return linear(lin, "run folder result.json (pitch, offset)", run_dir / "result.json")
    T = sig.sample_period_s
    cals = {}
    for k, phi, s, f in (("ema1", sig.phi1, sig.s1, sig.F1), ("ema2", sig.phi2, sig.s2, sig.F2)):
        sl = find_sweep(phi / i, f, T, act.mechanics.stroke_limit_mm)
        if sl is not None:
            try:
                cals[k] = fit_lvdt_calibration(phi[sl] / i, s[sl])
            except (InputError, AnalysisError) as exc:
                notes.append(f"sweep of {k} found but not usable: {exc}")
    if len(cals) == 2:
        return poly(cals, "slow sweeps under load detected in the recording")
    notes.append("no LVDT calibration (no --calibration, no calibration sweep, no result.json): LVDT data "
                 "uncorrected; a pitch error makes the stroke's acceleration phases look like jumps "
                 "(paper 2.3: +-20 mm x 7.5 % = +-1.5 mm over the full stroke)")
    return LvdtCorrection("none", {"ema1": "none", "ema2": "none"}, {"ema1": None, "ema2": None},
                          {"ema1": None, "ema2": None}, None, sig.s1, sig.s2, tuple(notes))


@dataclass(frozen=True)
class ServAnalysis:
    sig: Signals
    correction: LvdtCorrection
    d: dict  #: channel -> D array, mm
    results: dict  #: channel -> BlfServResult
    budget: AccuracyBudget
    method: str
    act: Actuation
    steps: tuple = ()  #: the steps of the stretch analysed (a recording with a step column), else ()


def pitch_bound(correction: LvdtCorrection) -> float:
    """The largest relative pitch error the corrected LVDT strokes may still carry: the calibration's residual,
    else (no calibration) the largest the house admits for an LVDT, ``HARD_LVDT_GAIN_TOLERANCE`` (10 %; the
    paper's is 7.5 %). What a jump must clear to count (:mod:`blf.serv.scale`)."""
    if correction.residual_pitch_error is not None:
        return float(correction.residual_pitch_error)
    return HARD_LVDT_GAIN_TOLERANCE


#: the fewest samples a recording must hold for BLFserv
MIN_SAMPLES_SERV = 100

#: a check's steps that are not a motion BLFserv may read (its step column): before the drives hold their
#: position (idle; enable, whose D steps are the motors pulling in as their current comes on: 0.04 to 0.05 mm
#: on the simulated rig, no load reversal) and after the check (done; aborted: the safe stop)
NOT_SERVICE = ("idle", "enable", "done", "aborted")
NOT_SERVICE_WORDS = "LVDT calibration, the drives' enabling or the check's end (idle, enable, cal*, done, aborted)"


def serv_steps(step: np.ndarray) -> np.ndarray:
    """Which samples of a recording's step column BLFserv may read (bool per sample): none of the LVDT
    calibration (``cal1_*``, ``cal2_*``) nor of :data:`NOT_SERVICE`."""
    return np.array([not (str(x).startswith(("cal1_", "cal2_")) or str(x) in NOT_SERVICE) for x in step], dtype=bool)


def refuse_gross_scale(sig: Signals, act: Actuation, correction: LvdtCorrection) -> None:
    """Refuse (:class:`hil.errors.RecordingError`) a recording whose LVDTs read the motors' stroke off by more than
    a factor 2 (:mod:`hil.analysis.plausible`): the calibration's pitch, else the slope over the recording. A
    unit (m, cm; degrees) or the gear ratio, never a BLFserv reading."""
    i = act.mechanics.i_total_rad_per_mm
    gross = []
    for k, phi, s in ((1, sig.phi1, sig.s1), (2, sig.phi2, sig.s2)):
        pitch = correction.pitch.get(f"ema{k}")
        how = f"its calibration ({correction.source})"
        if pitch is None:
            pitch, how = plausible.slope_pitch(phi / i, s), "the slope over the whole recording"
        if pitch is not None:
            words, bad = plausible.pitch_problem(k, float(pitch), how)
            gross += [words] if bad else []
    if gross:
        raise RecordingError("; ".join(gross) + ": the recording cannot belong to this actuation")


def analyse(sig: Signals, act: Actuation, correction: LvdtCorrection, method: str) -> ServAnalysis:
    """Position differences from the corrected strokes, BLFserv on each, and the error budget."""
    if sig.n < MIN_SAMPLES_SERV:
        raise RecordingError(f"recording too short for BLFserv: {sig.n} samples (need >= {MIN_SAMPLES_SERV})")
    i = act.mechanics.i_total_rad_per_mm
    refuse_gross_scale(sig, act, correction)
    s1, s2 = correction.s1_mm, correction.s2_mm
    steps = ()
    if sig.step is not None:
        # BLFserv is for normal operation: of a recording with a step column only the longest stretch of
        # steps in motion (never the LVDT calibration, the drives' enabling, or what follows an abort)
        operation = serv_steps(sig.step)
        spans = runs(operation)
        a, b = max(spans, key=lambda r: r[1] - r[0]) if spans else (0, 0)
        if b - a < MIN_SAMPLES_SERV:
            raise UnusableRecordingError(
                f"{b - a} sample(s) of motion (BLFserv needs at least {MIN_SAMPLES_SERV}): the step column marks "
                f"the rest as {NOT_SERVICE_WORDS}")
        steps = tuple(dict.fromkeys(str(x) for x in sig.step[a:b]))
        if b - a < sig.n:
            keep = np.zeros(sig.n, bool)
            keep[a:b] = True
            sig = sig.select(keep)
            s1, s2 = s1[a:b], s2[a:b]
            correction = replace(correction, notes=correction.notes + (
                f"BLFserv on t = {sig.t[0]:.1f}..{sig.t[-1]:.1f} s only (step {', '.join(steps)}): the step column "
                f"marks the rest as {NOT_SERVICE_WORDS}, not normal operation",))
    pd = position_differences(sig.phi1, sig.phi2, s1, s2, i)
    d = {"int1": pd.d_int1_mm, "int2": pd.d_int2_mm, "ext": pd.d_ext_mm}
    rate = 1.0 / sig.sample_period_s
    for ch in CHANNELS:
        _noisy(d[ch], ch)
    results = {ch: blf_serv(d[ch], rate, method=method, t0_s=float(sig.t[0])) for ch in CHANNELS}
    # a jump counts only where it crosses the band whatever the LVDT's scale (blf.serv.scale): the ram's travel
    # through it on the motor's exact scale, phi / i, times the largest pitch error the scale may have
    x = {"int1": sig.phi1 / i, "int2": sig.phi2 / i, "ext": 0.5 * (sig.phi1 + sig.phi2) / i}
    bound = pitch_bound(correction)
    for ch in CHANNELS:
        dx = motion_through_jumps(x[ch], rate, results[ch].jumps, t0_s=float(sig.t[0]))
        results[ch] = with_known_scale(results[ch], dx, bound, lvdts=2 if ch == "ext" else 1)
    pitches = [abs(p - 1.0) for p in correction.pitch.values() if p is not None]
    pitch_err = max(pitches) if pitches else PAPER_PITCH_ERROR
    budget = backlash_error_budget(
        act.mechanics.stroke_limit_mm, pitch_err, act.sensors.lvdt_noise_pp_mm / 6.0, rate,
        backlash_mm=act.mechanics.backlash_spec_int_mm,
        residual_pitch_error=correction.residual_pitch_error if correction.residual_pitch_error is not None else 1e-3)
    return ServAnalysis(sig, correction, d, results, budget, method, act, steps)


#: each channel's D in words, for messages
D_WORDS = {"int1": "s1 - phi1 / i", "int2": "s2 - phi2 / i", "ext": "s2 - s1"}


def _noisy(d_mm: np.ndarray, ch: str) -> None:
    """Refuse a D without noise (BLFserv's thresholds are multiples of it) in words a user can act on."""
    try:
        estimate_noise_std_mm(d_mm)
    except AnalysisError:
        raise UnusableRecordingError(
            f"D_{ch} = {D_WORDS[ch]} holds no measurement noise (below 1e-6 mm): the LVDT or motor angle is not "
            f"a raw measurement (computed from the other, or smoothed); BLFserv needs the recorded signals"
        ) from None


def _f(x):
    return None if x is None or not math.isfinite(x) else float(x)


def serv_dict(an: ServAnalysis, truth: dict | None, source: str) -> dict:
    """serv.json content."""
    res = an.results
    c = an.correction
    out = {
        "backlash_mm": {ch: _f(res[ch].backlash_mm) for ch in CHANNELS},
        "traversals": {ch: int(res[ch].traversals) for ch in CHANNELS},
        "method": an.method,
        "backlash_sigma_mm": {ch: _f(res[ch].backlash_sigma_mm) for ch in CHANNELS},
        "backlash_improved_mm": {ch: _f(res[ch].backlash_improved_mm) for ch in CHANNELS},
        "backlash_paper_mm": {ch: _f(res[ch].backlash_paper_mm) for ch in CHANNELS},
        "traversals_improved": {ch: int(res[ch].traversals_improved) for ch in CHANNELS},
        "traversals_paper": {ch: int(res[ch].traversals_paper) for ch in CHANNELS},
        "jumps": {ch: [{"t_s": round(j.t_jump_s, 4), "height_mm": _f(j.height_mm),
                        "height_sigma_mm": _f(j.height_sigma_mm), "paper_delta_mm": _f(j.paper_delta_mm),
                        "accepted": bool(j.accepted), "paper_accepted": bool(j.paper_accepted),
                        "reason": j.reason} for j in res[ch].jumps] for ch in CHANNELS},
        "noise_std_mm": {ch: res[ch].noise_std_mm for ch in CHANNELS},
        "thresholds": {ch: {"d1_mm_per_s": res[ch].threshold_d1_mm_per_s,
                            "d2_mm_per_s2": res[ch].threshold_d2_mm_per_s2,
                            "min_jump_mm": res[ch].min_jump_mm} for ch in CHANNELS},
        "filters": {"lowpass_rad_s": res["int1"].filters.lowpass_rad_s, "dt1_rad_s": res["int1"].filters.dt1_rad_s,
                    "discretisation": res["int1"].filters.discretisation},
        "calibration": {"source": c.source, **{k: {"kind": c.kind[k], "pitch": c.pitch[k],
                                                    "offset_mm": c.offset_mm[k]} for k in ("ema1", "ema2")}},
        "accuracy": budget_dict(an.budget),
        "recording": {"source": source, "samples": int(an.sig.n), "t_start_s": float(an.sig.t[0]),
                      "t_end_s": float(an.sig.t[-1]), "steps": list(an.steps),
                      "duration_s": float(an.sig.t[-1] - an.sig.t[0]),
                      "sample_period_s": float(an.sig.sample_period_s)},
        "notes": list(an.sig.notes) + list(c.notes),
    }
    verdicts, notes = serv_verdicts(an)
    out["status"] = overall(verdicts)
    out["verdict"] = {ch: {"status": v.status, "backlash_mm": v.backlash_mm, "uncertainty_mm": v.uncertainty_mm,
                           "limit_mm": v.limit_mm, "margin_mm": v.margin_mm, "traversals": int(res[ch].traversals),
                           "reason": v.reason} for ch, v in verdicts.items()}
    out["decision_rule"] = ("ISO 14253-1 guard band per traversed channel: pass if B + U <= limit, fail if B - U > "
                            "limit, otherwise inconclusive; U expanded uncertainty, k = 2; channels not traversed "
                            "do not count unless none was")
    out["notes"] += notes
    if truth is not None:
        out["truth"] = truth
    return out


#: A BLFserv reading resting on fewer counted traversals than this gets a warning.
MIN_TRAVERSALS = 5


def serv_verdicts(an: ServAnalysis) -> tuple[dict, list[str]]:
    """Per channel the decision against B_spec (:mod:`blf.maint.verdict`) and warnings about thin readings."""
    notes = []
    verdicts = {}
    b = an.budget
    m = b.serv_improved if an.method == "improved" else b.serv_paper
    for ch in CHANNELS:
        r = an.results[ch]
        limit = spec_mm(an.act, ch)
        if r.backlash_mm is None or not math.isfinite(r.backlash_mm):
            verdicts[ch] = decide(None, None, limit, not_traversed=True, missing=_why_not(an, ch))
            continue
        sigma = r.backlash_sigma_mm if r.backlash_sigma_mm is not None and math.isfinite(r.backlash_sigma_mm) else 0.0
        u = serv_uncertainty(r.backlash_mm, sigma, m.pitch_compensated_mm, m.temperature_mm, an.method)
        verdicts[ch] = decide(r.backlash_mm, u.expanded_mm, limit)
        if r.traversals < MIN_TRAVERSALS:
            notes.append(f"{ch}: the reading rests on {r.traversals} counted traversal(s); fewer than "
                         f"{MIN_TRAVERSALS} leave the spread of single jumps, and so its uncertainty, poorly known")
    return verdicts, notes




def _why_not(an: ServAnalysis, ch: str) -> str:
    """Why channel ``ch`` has no reading: no crossing, or jumps the LVDT's unknown scale could have made."""
    scaled = [j for j in an.results[ch].jumps if j.reason.startswith("within the LVDT scale's reach")]
    if not scaled:
        return "not traversed: no backlash crossing counted in this recording"
    cal = ("no LVDT calibration: its pitch may be off by up to "
           f"{pitch_bound(an.correction):.0%}" if an.correction.residual_pitch_error is None
           else f"the calibration leaves a pitch error of up to {pitch_bound(an.correction):.2%}")
    return (f"not measured: {len(scaled)} jump(s) found, none larger than the LVDT's scale could make of the "
            f"ram's travel through it ({cal}); the backlash band is not shown crossed (docs/blfserv.md)")


def unjudged_dict(act: Actuation, status: str, why: str, source: str) -> dict:
    """serv.json of a run cut short (``status`` ``"aborted"`` or ``"incomplete"``) whose recording holds
    nothing BLFserv can read (``why``): every channel not measured, no reading, no report."""
    verdicts = {ch: decide(None, None, spec_mm(act, ch), missing=f"the run was cut short; {why}")
                for ch in CHANNELS}
    return {
        "status": status, "analysis_error": why, "method": None,
        "backlash_mm": dict.fromkeys(CHANNELS), "backlash_sigma_mm": dict.fromkeys(CHANNELS),
        "traversals": dict.fromkeys(CHANNELS, 0), "jumps": {ch: [] for ch in CHANNELS},
        "backlash_paper_mm": dict.fromkeys(CHANNELS),
        "calibration": {"source": "none (nothing analysed)", "ema1": None, "ema2": None},
        "recording": {"source": source, "samples": 0, "duration_s": 0.0, "sample_period_s": None},
        "verdict": {ch: {"status": v.status, "backlash_mm": None, "uncertainty_mm": None, "limit_mm": v.limit_mm,
                         "margin_mm": None, "traversals": 0, "reason": v.reason} for ch, v in verdicts.items()},
        "decision_rule": "nothing judged: the recording of a run cut short holds no stretch BLFserv can read",
        "notes": [],
    }
