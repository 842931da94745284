"""The BLFserv report (``serv_report.html``): paper Fig. 8 per channel, backlash over time, error budget."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from blf.serv import BlfServResult
from blf.signals import CHANNELS
from hil.analysis.serv import ServAnalysis
from hil.profile.config import Actuation
from hil.report.shell import (
    column,
    esc,
    file_link,
    fmt,
    heading,
    identification,
    img,
    notes,
    page_title,
    pyplot,
    running_head,
    signoff_block,
    simulated_banner,
    table,
    thin,
    trace_lines,
    write_page,
)

_LABEL = {"int1": "D_{int,1}", "int2": "D_{int,2}", "ext": "D_{ext}"}


def figure_serv(ch: str, t: np.ndarray, d: np.ndarray, r: BlfServResult, truth_b: float | None):
    """Paper Figure 8 for one channel: D and filtered D, the two derivatives with the threshold
    zone, detected jumps; left the whole record, right zoomed on the largest counted jump."""
    plt = pyplot()
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
        sl = thin(int(m.sum()), 8000) if col == 0 else slice(None)
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
    return fig


def figure_over_time(an: ServAnalysis, truth: dict | None):
    """Backlash per channel over time: each detected jump's height, and the running result."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharex=True)
    for a, ch in zip(axes, CHANNELS, strict=True):
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
    return fig


def write_serv_report(path: Path, an: ServAnalysis, data: dict, act: Actuation, *,
                      json_name: str = "serv.json") -> None:
    """The self-contained HTML report of ``emacheck serv`` (``json_name``: serv.json beside it, linked)."""
    truth = data.get("truth")
    t = an.sig.t
    parts = [heading("emacheck serv: in-service backlash (BLFserv, paper 2.2)", data), simulated_banner(data),
             identification(data),
             f"<p>{esc(act.name)}; recording {esc(data['recording']['source'])}: "
             f"{an.sig.n} samples, {data['recording']['duration_s']:.1f} s; method <b>{an.method}</b>; "
             f"LVDT calibration: {esc(an.correction.source)}.</p>",
             notes(data["notes"])]
    cols = [column("channel"), column("backlash", "mm"), column("σ (statistical)", "mm"), column("traversals"),
            column("improved", "mm"), column("paper", "mm"), column("paper traversals"), column("noise σ", "mm"),
            column("thresh dD/dt", "mm/s"), column("thresh d²D/dt²", "mm/s²")]
    if truth:
        cols += [column("truth", "mm"), column("error", "mm")]
    rows = []
    for ch in CHANNELS:
        r = an.results[ch]
        cells = [ch, "not traversed" if r.backlash_mm is None else fmt(r.backlash_mm), fmt(r.backlash_sigma_mm),
                 str(r.traversals), fmt(r.backlash_improved_mm), fmt(r.backlash_paper_mm), str(r.traversals_paper),
                 fmt(r.noise_std_mm), fmt(r.threshold_d1_mm_per_s, 3), fmt(r.threshold_d2_mm_per_s2, 1)]
        if truth:
            tb = truth["backlash_mm"][ch]
            cells += [fmt(tb), fmt(None if r.backlash_mm is None else r.backlash_mm - tb)]
        rows.append(cells)
    verdict = data.get("verdict", {})
    vrows = [[ch, f"<span class='{v['status']}'>{esc(v['status'])}</span>", fmt(v["backlash_mm"]),
              fmt(v["uncertainty_mm"]), fmt(v["limit_mm"]), fmt(v["margin_mm"]), str(v["traversals"]), esc(v["reason"])]
             for ch, v in verdict.items()]
    parts.append("<h2>Decision</h2>"
                 + table([column("channel"), column("verdict"), column("backlash", "mm"), column("U (k = 2)", "mm"),
                          column("limit B_spec", "mm"), column("margin", "mm"), column("traversals"),
                          column("reason")], vrows, raw=True)
                 + f"<p>{esc(data.get('decision_rule', ''))}. U combines the spread of the counted jumps, the "
                 "LVDT pitch left after calibration over the stroke, the temperature bound of paper 2.3 and the "
                 "method's validated accuracy.</p>" + signoff_block(data, "in-service backlash reading"))
    parts.append(trace_lines(data.get("trace")))
    parts.append("<h2>Readings</h2>" + table(cols, rows))
    c = an.correction
    parts.append("<h3>LVDT calibration</h3>"
                 + table([column("LVDT"), column("kind"), column("pitch"), column("offset", "mm")],
                         [[k, c.kind[k], fmt(c.pitch[k], 5), fmt(c.offset_mm[k])] for k in ("ema1", "ema2")]))
    parts.append(f"<h2>Backlash per channel over time</h2>{img(figure_over_time(an, truth))}")
    for ch in CHANNELS:
        tb = truth["backlash_mm"][ch] if truth else None
        parts.append(f"<h2>{ch} (paper Fig. 8)</h2>{img(figure_serv(ch, t, an.d[ch], an.results[ch], tb))}")
    b = an.budget
    parts.append("<h2>Accuracy of the backlash measurement (paper 2.3)</h2>"
                 f"<p>Stroke {-b.stroke_mm:g} to +{b.stroke_mm:g} mm, uncompensated pitch error {b.pitch_error:.2%}, "
                 "residual after "
                 f"calibration {b.residual_pitch_error:.2%}, LVDT noise σ {b.lvdt_noise_std_mm:.4f} mm "
                 f"({b.filtered_noise_std_mm:.4f} mm after the low-pass), temperature error "
                 f"{b.temperature_error:.0%}; target {b.target_mm:.3f} mm (a tenth of B_spec = "
                 f"{b.backlash_mm:g} mm). Contributions to the backlash error:</p>"
                 + table([column("method"), column("LVDT travel", "mm"), column("pitch, uncompensated", "mm"),
                          column("pitch, calibrated", "mm"), column("noise (1σ)", "mm"), column("jump read", "mm"),
                          column("temperature 1 %", "mm"), column("total, calibrated", "mm"),
                          column("total, uncompensated", "mm")],
                         [[m.method, f"{m.travel_mm:.3f}", f"{m.pitch_uncompensated_mm:.4f}",
                           f"{m.pitch_compensated_mm:.4f}", f"{m.noise_mm:.4f}", f"{m.jump_mm:.3f}",
                           f"{m.temperature_mm:.4f}", f"{m.total_compensated_mm:.4f}",
                           f"{m.total_uncompensated_mm:.4f}"] for m in (b.maint, b.serv_paper, b.serv_improved)])
                 + "<p>BLFmaint's temperature term is zero in practice: the calibration runs minutes before it "
                 "(paper 2.3); its noise term is the single-reading bound before regression averaging.</p>")
    parts.append(file_link(json_name))
    write_page(path, page_title("emacheck serv", data), parts, running_head("emacheck serv", data))
