"""``emacheck serv``: BLFserv over a recording, serv.json and an HTML report (IO shell).

Input: a run folder (``signals.csv``, or ``can.log`` alone), a bare signals
CSV (columns ``t,phi1,phi2,s1,s2,F1,F2``) or a raw CAN log (``*.log``,
candump ``-L`` format, decoded by :func:`hil.canlog.decode_can_log`).

LVDT calibration, first that applies:

1. ``--calibration RESULT.json``: pitch and offset of both LVDTs from a
   maintenance check's result.json (a linear correction);
2. a run folder whose signals carry the check's calibration sweeps (step
   column ``cal1_sweep``/``cal2_sweep``): the full cubic calibration is fitted
   again from them (:func:`blf.calibration.fit_lvdt_calibration`);
3. the run folder's ``result.json`` calibration (pitch and offset, linear);
4. a slow sweep under load found in the recording itself (per EMA: ram
   speed 0.3 to 10 mm/s over at least half the stroke limit, its force of
   one sign, mean above 200 N, :func:`find_sweep`): cubic fit on it;
5. none: the LVDT data are used uncorrected, and serv.json and the report
   say so (a pitch error then shows as spurious jumps, paper 2.3).

Outputs in ``--out`` (default: the run folder, or the CSV's folder):
``serv.json`` and ``serv_report.html`` (not with ``--no-report``). Exit
status 0, or 3 for bad input.
"""

from __future__ import annotations

import argparse
import html
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from blf.accuracy import AccuracyBudget, backlash_error_budget
from blf.calibration import fit_lvdt_calibration
from blf.serv import METHODS, BlfServResult, blf_serv
from blf.signals import position_differences
from hil.config import Actuation
from hil.errors import AnalysisError, InputError, RecordingError
from hil.runfolder import Signals, resolve_recording, write_json_atomic
from hil.types import CHANNELS

_LABEL = {"int1": "D_{int,1}", "int2": "D_{int,2}", "ext": "D_{ext}"}
_MAX_POINTS = 8000
PAPER_PITCH_ERROR = 0.075  #: the paper's uncompensated pitch error, used when no calibration says otherwise


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


# ---------------------------------------------------------------------- calibration


def _linear(pitch: float, offset: float, s: np.ndarray) -> np.ndarray:
    return (s - offset) / pitch


def _from_result_json(path: Path) -> dict:
    try:
        res = json.loads(path.read_text())
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{path}: not valid JSON: {exc}") from None
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


def _smooth_speed(x: np.ndarray, period_s: float, window_s: float = 0.2) -> np.ndarray:
    v = np.gradient(x, period_s)
    n = max(1, int(round(window_s / period_s)))
    return np.convolve(v, np.ones(n) / n, mode="same")


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def find_sweep(x_mm: np.ndarray, f_N: np.ndarray, period_s: float, stroke_limit_mm: float) -> slice | None:
    """Longest slow sweep under a steady one-sided force, as a slice (trimmed 2 % each end), or None.

    Slow: 0.3 to 10 mm/s (0.2 s moving average of the motor-side speed); long:
    at least half the stroke limit of travel; steady load: mean force above
    200 N, the same sign in 99 % of the samples and a standard deviation
    below half the mean, so the internal path stays in contact on one flank
    and its deflection is constant on average (paper 2.3; the opposing EMA in
    force mode rings at a few Hz, which the regression averages out).
    """
    v = np.abs(_smooth_speed(x_mm, period_s))
    slow = (v >= 0.3) & (v <= 10.0)
    best = None
    for a, b in _runs(slow):
        if b - a < 50:
            continue
        xs, fs = x_mm[a:b], f_N[a:b]
        if np.ptp(xs) < 0.5 * stroke_limit_mm:
            continue
        fm = float(np.mean(fs))
        if abs(fm) < 200.0 or np.mean(np.sign(fs) == np.sign(fm)) < 0.99 or np.std(fs) > 0.5 * abs(fm):
            continue
        if best is None or b - a > best[1] - best[0]:
            best = (a, b)
    if best is None:
        return None
    a, b = best
    k = int(0.02 * (b - a))
    return slice(a + k, b - k)


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

    def linear(lin: dict, source: str) -> LvdtCorrection:
        return LvdtCorrection(source, {"ema1": "linear", "ema2": "linear"},
                              {k: lin[k][0] for k in lin}, {k: lin[k][1] for k in lin}, 1e-3,
                              _linear(*lin["ema1"], sig.s1), _linear(*lin["ema2"], sig.s2), tuple(notes))

    if calibration_file is not None:
        lin = _from_result_json(Path(calibration_file))
        if lin["ema1"] is None or lin["ema2"] is None:
            raise RecordingError(f"{calibration_file}: calibration of both LVDTs needed (ema1, ema2)")
        return linear(lin, f"--calibration {calibration_file}")
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
            return linear(lin, "run folder result.json (pitch, offset)")
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


# ---------------------------------------------------------------------- analysis


@dataclass(frozen=True)
class ServAnalysis:
    sig: Signals
    correction: LvdtCorrection
    d: dict  #: channel -> D array, mm
    results: dict  #: channel -> BlfServResult
    budget: AccuracyBudget
    method: str


def analyse(sig: Signals, act: Actuation, correction: LvdtCorrection, method: str) -> ServAnalysis:
    """Position differences from the corrected strokes, BLFserv on each, and the error budget."""
    if sig.n < 100:
        raise RecordingError(f"recording too short for BLFserv: {sig.n} samples (need >= 100)")
    i = act.mechanics.i_total_rad_per_mm
    pd = position_differences(sig.phi1, sig.phi2, correction.s1_mm, correction.s2_mm, i)
    d = {"int1": pd.d_int1_mm, "int2": pd.d_int2_mm, "ext": pd.d_ext_mm}
    rate = 1.0 / sig.sample_period_s
    results = {ch: blf_serv(d[ch], rate, method=method, t0_s=float(sig.t[0])) for ch in CHANNELS}
    pitches = [abs(p - 1.0) for p in correction.pitch.values() if p is not None]
    pitch_err = max(pitches) if pitches else PAPER_PITCH_ERROR
    budget = backlash_error_budget(
        act.mechanics.stroke_limit_mm, pitch_err, act.sensors.lvdt_noise_pp_mm / 6.0, rate,
        backlash_mm=act.mechanics.backlash_spec_int_mm,
        residual_pitch_error=correction.residual_pitch_error if correction.residual_pitch_error is not None else 1e-3)
    return ServAnalysis(sig, correction, d, results, budget, method)


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
        "recording": {"source": source, "samples": int(an.sig.n),
                      "duration_s": float(an.sig.t[-1] - an.sig.t[0]),
                      "sample_period_s": float(an.sig.sample_period_s)},
        "notes": list(an.sig.notes) + list(c.notes),
    }
    if truth is not None:
        out["truth"] = truth
    return out


def budget_dict(b: AccuracyBudget) -> dict:
    def m(x):
        return {"travel_mm": x.travel_mm, "pitch_uncompensated_mm": x.pitch_uncompensated_mm,
                "pitch_compensated_mm": x.pitch_compensated_mm, "noise_mm": x.noise_mm, "jump_mm": x.jump_mm,
                "temperature_mm": x.temperature_mm, "total_compensated_mm": x.total_compensated_mm,
                "total_uncompensated_mm": x.total_uncompensated_mm}
    return {"stroke_mm": b.stroke_mm, "pitch_error": b.pitch_error, "residual_pitch_error": b.residual_pitch_error,
            "lvdt_noise_std_mm": b.lvdt_noise_std_mm, "filtered_noise_std_mm": b.filtered_noise_std_mm,
            "temperature_error": b.temperature_error, "backlash_mm": b.backlash_mm, "target_mm": b.target_mm,
            "BLFmaint": m(b.maint), "BLFserv_paper": m(b.serv_paper), "BLFserv_improved": m(b.serv_improved)}


# ---------------------------------------------------------------------- report


def _stride(n: int) -> int:
    return max(1, n // _MAX_POINTS)


def figure_serv(ch: str, t: np.ndarray, d: np.ndarray, r: BlfServResult, truth_b: float | None):
    """Paper Figure 8 for one channel: D and filtered D, the two derivatives with the threshold
    zone, detected jumps; left the whole record, right zoomed on the largest counted jump."""
    import matplotlib.pyplot as plt

    acc = [j for j in r.jumps if j.accepted]
    focus = max(acc, key=lambda j: abs(j.height_mm)) if acc else (r.jumps[0] if r.jumps else None)
    fig, axes = plt.subplots(3, 2, figsize=(13, 8), sharex="col")
    lab = _LABEL[ch]
    for col in range(2):
        if col == 0:
            m = np.ones(t.size, bool)
        elif focus is not None:
            m = (t >= focus.t_start_s - 0.5) & (t <= focus.t_end_s + 0.6)
        else:
            m = t <= t[0] + 2.0
        sl = slice(None, None, _stride(int(m.sum())) if col == 0 else 1)
        tt = t[m][sl]
        a0, a1, a2 = axes[:, col]
        a0.plot(tt, d[m][sl], lw=0.4, color="0.6", label="D")
        a0.plot(tt, r.d_filtered_mm[m][sl], lw=1.0, color="C0", label="D filtered")
        a1.plot(tt, r.d1_mm_per_s[m][sl], lw=0.8, color="C1")
        a2.plot(tt, r.d2_mm_per_s2[m][sl], lw=0.8, color="C2")
        a1.axhspan(-r.threshold_d1_mm_per_s, r.threshold_d1_mm_per_s, color="C1", alpha=0.15)
        a2.axhspan(-r.threshold_d2_mm_per_s2, r.threshold_d2_mm_per_s2, color="C2", alpha=0.15)
        t_lo, t_hi = (tt[0], tt[-1]) if tt.size else (0.0, 1.0)
        for j in r.jumps:
            if j.t_end_s < t_lo or j.t_start_s > t_hi:
                continue
            colr = "C3" if j.accepted else "0.5"
            for a in (a0, a1, a2):
                a.axvspan(j.t_start_s, j.t_end_s, color=colr, alpha=0.15 if j.accepted else 0.08, lw=0)
            if col == 1 and np.isfinite(j.height_mm):
                a0.axvline(j.t_jump_s, color=colr, lw=0.8, ls="--")
                a0.annotate(f"h = {j.height_mm:+.4f} mm\nΔD(paper) = {j.paper_delta_mm:+.4f} mm",
                            xy=(j.t_jump_s, float(np.interp(j.t_jump_s, t, r.d_filtered_mm))),
                            xytext=(8, 8), textcoords="offset points", fontsize=7,
                            bbox=dict(facecolor="white", alpha=0.7, edgecolor="none"))
        a0.set_ylabel(f"${lab}$ [mm]")
        a1.set_ylabel(f"$\\dot{{{lab}}}$ [mm/s]")
        a2.set_ylabel(f"$\\ddot{{{lab}}}$ [mm/s²]")
        a2.set_xlabel("t [s]")
        for a in (a0, a1, a2):
            a.grid(alpha=0.3)
        a0.legend(fontsize=7, loc="best")
    b = "not traversed" if r.backlash_mm is None else f"B = {r.backlash_mm:.4f} mm ({r.traversals} jumps)"
    tb = "" if truth_b is None else f", truth {truth_b:.4f} mm"
    axes[0, 0].set_title(f"{ch}: BLFserv ({r.method}) {b}{tb} (paper Fig. 8)")
    axes[0, 1].set_title("zoom: " + ("largest counted jump" if acc else "first event" if r.jumps else "start"))
    fig.tight_layout()
    return fig


def figure_over_time(an: ServAnalysis, truth: dict | None):
    """Backlash per channel over time: each detected jump's height, and the running result."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharex=True)
    for a, ch in zip(axes, CHANNELS):
        r = an.results[ch]
        acc = [j for j in r.jumps if j.accepted]
        rej = [j for j in r.jumps if not j.accepted and np.isfinite(j.height_mm)]
        pap = [j for j in r.jumps if j.paper_accepted]
        if acc:
            tj = np.array([j.t_jump_s for j in acc])
            hj = np.array([abs(j.height_mm) for j in acc])
            a.plot(tj, hj, "o", ms=4, color="C3", label="jump height (counted)")
            run = [float(np.median(hj[:k + 1])) for k in range(hj.size)]
            a.step(tj, run, where="post", color="k", lw=1, label="running median (backlash)")
        if rej:
            a.plot([j.t_jump_s for j in rej], [abs(j.height_mm) for j in rej], "x", ms=4, color="0.5",
                   label="not counted")
        if pap:
            a.plot([j.t_jump_s for j in pap], [abs(j.paper_delta_mm) for j in pap], "s", ms=3, mfc="none",
                   color="C0", label="paper ΔD")
        if truth is not None and ch in truth.get("backlash_mm", {}):
            a.axhline(truth["backlash_mm"][ch], color="C2", ls="--", lw=1, label="truth")
        a.set_title(f"{ch}: " + ("not traversed" if r.backlash_mm is None else f"{r.backlash_mm:.4f} mm"))
        a.set_xlabel("t [s]")
        a.grid(alpha=0.3)
        a.set_ylim(bottom=0)
    axes[0].set_ylabel("backlash [mm]")
    axes[0].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


def _fmt(x, nd=4) -> str:
    return "—" if x is None else f"{x:.{nd}f}"


_CSS = """body{font-family:sans-serif;max-width:1300px;margin:1em auto;color:#222}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee}img{max-width:100%}.warn{color:#b60}"""


def fig_to_data_uri(fig, dpi: int = 80) -> str:
    """PNG data URI of a laid-out figure (closes it)."""
    import base64
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def write_serv_report(path: Path, an: ServAnalysis, data: dict, act: Actuation) -> None:
    """The self-contained HTML report of ``emacheck serv``."""

    truth = data.get("truth")
    t = an.sig.t
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>emacheck serv</title><style>{_CSS}</style>"
             "</head><body>",
             "<h1>emacheck serv: in-service backlash (BLFserv, paper 2.2)</h1>",
             f"<p>{html.escape(act.name)}; recording {html.escape(data['recording']['source'])}: "
             f"{an.sig.n} samples, {data['recording']['duration_s']:.1f} s; method <b>{an.method}</b>; "
             f"LVDT calibration: {html.escape(an.correction.source)}.</p>"]
    for n in data["notes"]:
        parts.append(f"<p class='warn'><b>note:</b> {html.escape(n)}</p>")
    head = ("<tr><th>channel</th><th>backlash [mm]</th><th>±1σ [mm]</th><th>traversals</th>"
            "<th>improved [mm]</th><th>paper [mm]</th><th>paper traversals</th><th>noise σ [mm]</th>"
            "<th>thresh dD/dt [mm/s]</th><th>thresh d²D/dt² [mm/s²]</th>")
    if truth:
        head += "<th>truth [mm]</th><th>error [mm]</th>"
    rows = []
    for ch in CHANNELS:
        r = an.results[ch]
        cells = [ch, "not traversed" if r.backlash_mm is None else _fmt(r.backlash_mm), _fmt(r.backlash_sigma_mm),
                 str(r.traversals), _fmt(r.backlash_improved_mm), _fmt(r.backlash_paper_mm), str(r.traversals_paper),
                 _fmt(r.noise_std_mm), _fmt(r.threshold_d1_mm_per_s, 3), _fmt(r.threshold_d2_mm_per_s2, 1)]
        if truth:
            tb = truth["backlash_mm"][ch]
            cells += [_fmt(tb), _fmt(None if r.backlash_mm is None else r.backlash_mm - tb)]
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    parts.append("<h2>Summary</h2><table>" + head + "</tr>" + "".join(rows) + "</table>")
    c = an.correction
    parts.append("<h3>LVDT calibration</h3><table><tr><th>LVDT</th><th>kind</th><th>pitch</th><th>offset [mm]</th></tr>"
                 + "".join(f"<tr><td>{k}</td><td>{c.kind[k]}</td><td>{_fmt(c.pitch[k], 5)}</td>"
                           f"<td>{_fmt(c.offset_mm[k])}</td></tr>" for k in ("ema1", "ema2")) + "</table>")
    parts.append(f"<h2>Backlash per channel over time</h2><img src='{fig_to_data_uri(figure_over_time(an, truth))}'>")
    for ch in CHANNELS:
        tb = truth["backlash_mm"][ch] if truth else None
        fig = figure_serv(ch, t, an.d[ch], an.results[ch], tb)
        parts.append(f"<h2>{ch} (paper Fig. 8)</h2><img src='{fig_to_data_uri(fig)}'>")
    b = an.budget
    parts.append("<h2>Accuracy of the backlash measurement (paper 2.3)</h2>"
                 f"<p>Stroke ±{b.stroke_mm:g} mm, uncompensated pitch error {b.pitch_error:.2%}, residual after "
                 f"calibration {b.residual_pitch_error:.2%}, LVDT noise σ {b.lvdt_noise_std_mm:.4f} mm "
                 f"({b.filtered_noise_std_mm:.4f} mm after the low-pass), temperature error "
                 f"{b.temperature_error:.0%}; target {b.target_mm:.3f} mm (a tenth of B_spec = "
                 f"{b.backlash_mm:g} mm). Contributions to the backlash error, mm:</p>"
                 "<table><tr><th>method</th><th>LVDT travel</th><th>pitch, uncompensated</th>"
                 "<th>pitch, calibrated</th><th>noise (1σ)</th><th>jump read</th><th>temperature 1 %</th>"
                 "<th>total, calibrated</th><th>total, uncompensated</th></tr>"
                 + "".join(f"<tr><td>{m.method}</td><td>{m.travel_mm:.3f}</td><td>{m.pitch_uncompensated_mm:.4f}</td>"
                           f"<td>{m.pitch_compensated_mm:.4f}</td><td>{m.noise_mm:.4f}</td><td>{m.jump_mm:.3f}</td>"
                           f"<td>{m.temperature_mm:.4f}</td><td>{m.total_compensated_mm:.4f}</td>"
                           f"<td>{m.total_uncompensated_mm:.4f}</td></tr>"
                           for m in (b.maint, b.serv_paper, b.serv_improved)) + "</table>"
                 "<p>BLFmaint's temperature term is zero in practice: the calibration runs minutes before it "
                 "(paper 2.3); its noise term is the single-reading bound before regression averaging.</p>")
    parts.append("<h2>serv.json</h2><pre>" + html.escape(json.dumps(
        {k: v for k, v in data.items() if k != "jumps"}, indent=1)) + "</pre>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts))


# ---------------------------------------------------------------------- the command


def print_summary(console: Console, data: dict, out_dir: Path) -> None:
    truth = data.get("truth")
    tab = Table(title=f"BLFserv ({data['method']})")
    for col in ("channel", "backlash mm", "traversals", "paper mm", "truth mm" if truth else None):
        if col:
            tab.add_column(col, justify="right")
    for ch in CHANNELS:
        b = data["backlash_mm"][ch]
        row = [ch, "not traversed" if b is None else f"{b:.4f}", str(data["traversals"][ch]),
               _fmt(data["backlash_paper_mm"][ch])]
        if truth:
            row.append(_fmt(truth["backlash_mm"][ch]))
        tab.add_row(*row)
    console.print(tab)
    console.print(f"LVDT calibration: {data['calibration']['source']}")
    for n in data["notes"]:
        console.print(f"[yellow]note:[/yellow] {n}")
    console.print(f"serv.json and serv_report.html in {out_dir}")


def cmd_serv(args: argparse.Namespace) -> int:
    """``emacheck serv RECORDING [--profile ACTUATION.toml] [--out DIR] [--calibration RESULT.json]
    [--method improved|paper] [--no-report]``."""
    from hil.commands import actuation_for, load_recording, read_meta

    console = Console()
    t0 = time.perf_counter()
    method = getattr(args, "method", None) or "improved"
    if method not in METHODS:
        raise RecordingError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    sig_path, run_dir = resolve_recording(args.recording)
    meta = read_meta(run_dir)
    act = actuation_for(args.profile, meta)
    try:
        sig = load_recording(sig_path, act, meta)
        corr = choose_calibration(sig, act, run_dir, getattr(args, "calibration", None))
        an = analyse(sig, act, corr, method)
    except (InputError, AnalysisError) as exc:
        raise RecordingError(f"{sig_path}: {exc}") from None
    truth = meta.get("truth") if isinstance(meta, dict) else None
    out = Path(args.out) if args.out is not None else (run_dir if run_dir is not None else sig_path.parent)
    out.mkdir(parents=True, exist_ok=True)
    data = serv_dict(an, truth, str(sig_path))
    data["analysis_s"] = round(time.perf_counter() - t0, 3)
    write_json_atomic(out / "serv.json", data)
    if not getattr(args, "no_report", False):
        write_serv_report(out / "serv_report.html", an, data, act)
    print_summary(console, data, out)
    return 0
