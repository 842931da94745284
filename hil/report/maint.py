"""Self-contained HTML report with the paper's figures (matplotlib, embedded PNG).

Figures: force and D versus time (paper Fig. 3), F versus D with dF/dD, its
median, D_lc and D_rc (Fig. 4), the three regression lines with backlash and
stiffness (Figs. 5 and 6), the LVDT calibration regression (Fig. 9), and a
summary table with truth where the data came from the simulator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from blf.maint import BlfMaintResult
from blf.signals import CHANNELS
from hil.analysis.maint import Analysis
from hil.profile.config import Actuation
from hil.record.runfolder import Signals
from hil.record.runrecord import RunRecord, Timing
from hil.report.shell import (
    Drawing,
    column,
    drawn,
    drives_left,
    esc,
    file_link,
    fmt,
    heading,
    identification,
    img,
    notes,
    page_html,
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

_LABEL = {"int1": ("F_1", "D_{int,1}"), "int2": ("F_2", "D_{int,2}"), "ext": ("F_2 - F_1", "D_{ext}")}


def _channel_data(sig: Signals, an: Analysis, ch: str) -> tuple[np.ndarray, np.ndarray]:
    ff = an.segments.force_fight
    if ch == "int1":
        return an.d_int1[ff], sig.F1[ff]
    if ch == "int2":
        return an.d_int2[ff], sig.F2[ff]
    return an.d_ext[ff], sig.F2[ff] - sig.F1[ff]


def figure_time(sig: Signals, an: Analysis, act: Actuation):
    """Paper Figure 3: forces and D signals versus time during the force fight."""
    ff = an.segments.force_fight
    t = sig.t[ff]
    sl = thin(t.size)
    fig, axes = pyplot().subplots(2, 3, figsize=(13, 5.5), sharex=True)
    # the layout's start near where it ends for a check's data (its ticks then stay: one pass, not two)
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.11, top=0.88, wspace=0.23, hspace=0.1)
    for j, ch in enumerate(CHANNELS):
        d, f = _channel_data(sig, an, ch)
        fl, dl = _LABEL[ch]
        axes[0, j].plot(t[sl], f[sl] / 1e3, lw=0.6)
        axes[0, j].set_ylabel(f"${fl}$ [kN]")
        axes[0, j].set_title(ch)
        axes[1, j].plot(t[sl], d[sl], lw=0.4, color="C1")
        axes[1, j].set_ylabel(f"${dl}$ [mm]")
        axes[1, j].set_xlabel("t [s]")
        for a in axes[:, j]:
            a.grid(alpha=0.3)
    fig.suptitle(f"Force fight: forces and position differences (F_limit = {act.mechanics.limit_load_N / 1e3:g} kN)")
    return fig


def figure_dfdd(ch: str, d: np.ndarray, f: np.ndarray, r: BlfMaintResult):
    """Paper Figure 4: F versus D and the binned derivative dF/dD with median, D_lc, D_rc."""
    fl, dl = _LABEL[ch]
    sl = thin(d.size)
    fig, (a0, a1) = pyplot().subplots(2, 1, figsize=(9, 6), sharex=True)
    a0.plot(d[sl], f[sl] / 1e3, ".", ms=1.5, alpha=0.3, label="samples")
    a0.plot(r.curve.d_mm, r.curve.f_N / 1e3, "-", color="k", lw=1, label="binned (median per bin)")
    a0.set_ylabel(f"${fl}$ [kN]")
    a1.plot(r.curve.d_mm, r.curve.dfdd_N_per_mm / 1e3, "-", color="C2", label="dF/dD (binned)")
    a1.axhline(r.dfdd_median / 1e3, color="C3", ls="--", label=f"median {r.dfdd_median / 1e3:.1f} kN/mm")
    a1.axhline(r.curve.threshold_N_per_mm / 1e3, color="C4", ls=":",
               label=f"contact threshold {r.curve.threshold_N_per_mm / 1e3:.1f} kN/mm")
    for a in (a0, a1):
        a.axvline(r.d_lc_mm, color="gray", ls="--", lw=0.8)
        a.axvline(r.d_rc_mm, color="gray", ls="--", lw=0.8)
        a.grid(alpha=0.3)
        outside_legend(a)
    a1.set_ylabel("dF/dD [kN/mm]")
    a1.set_xlabel(f"${dl}$ [mm]   (dashed verticals: D_lc = {r.d_lc_mm:.4f}, D_rc = {r.d_rc_mm:.4f})")
    a0.set_title(f"{ch}: F versus D and its derivative (paper Fig. 4)")
    return fig


def outside_legend(ax) -> None:
    """The axes' legend to the right of them, outside, so that it never covers a data point."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def reading_text(ch: str, r: BlfMaintResult, u_mm: float | None, truth: dict | None) -> str:
    """The reading as the decision table gives it: B ± U (expanded, k = 2), then the regression's
    statistical sigma labelled as such (never behind a bare ±), then the truth of simulated data."""
    txt = f"B = {r.backlash_mm:.4f} mm" + ("" if u_mm is None else f" ± {u_mm:.4f} mm (U, k = 2)")
    txt += f"\nσ (statistical) = {r.backlash_sigma_mm:.4f} mm"
    if truth is not None:
        txt += f"\ntruth {truth['backlash_mm'][ch]:.4f} mm"
    return txt


def figure_lines(ch: str, d: np.ndarray, f: np.ndarray, r: BlfMaintResult, truth: dict | None,
                 u_mm: float | None = None):
    """Paper Figures 5/6: the three regression lines, backlash (± U, the decision's expanded uncertainty
    ``u_mm``) and stiffness; legend and reading beside the axes, off the data."""
    fl, dl = _LABEL[ch]
    sl = thin(d.size)
    L = r.lines
    fig, ax = pyplot().subplots(figsize=(9, 4.5))
    ax.plot(d[sl], f[sl] / 1e3, ".", ms=1.5, alpha=0.25, color="C0", label="samples")
    for line, col in ((L.left, "C3"), (L.right, "C2")):
        fr = np.linspace(min(line.f_min_N, 0.0), max(line.f_max_N, 0.0), 50)
        ax.plot(line.d_mm(fr), fr / 1e3, color=col, lw=1.5,
                label=f"c_{line.side} = {abs(1.0 / line.compliance_mm_per_N) / 1e3:.1f} kN/mm")
    dr = np.linspace(L.d_left_mm, L.d_right_mm, 20)
    ax.plot(dr, L.centre.f_N(dr) / 1e3, color="k", lw=1.5, label="c_center")
    ax.plot([L.d_left_mm, L.d_right_mm], [L.f_left_N / 1e3, L.f_right_N / 1e3], "ko", ms=5)
    ax.annotate("", xy=(L.d_right_mm, 0), xytext=(L.d_left_mm, 0),
                arrowprops=dict(arrowstyle="<->", color="k"))
    ax.text(1.01, 0.0, reading_text(ch, r, u_mm, truth), transform=ax.transAxes, fontsize=8, va="bottom",
            ha="left")
    ax.set_xlabel(f"${dl}$ [mm]")
    ax.set_ylabel(f"${fl}$ [kN]")
    ax.set_title(f"{ch}: backlash and stiffness (paper Fig. {'6' if ch == 'ext' else '5'})")
    ax.grid(alpha=0.3)
    outside_legend(ax)
    return fig


def figure_calibration(sig: Signals, an: Analysis, act: Actuation):
    """Paper Figure 9: LVDT stroke versus motor angle referred to the ram, and residuals."""
    i = act.mechanics.i_total_rad_per_mm
    fig, axes = pyplot().subplots(2, 2, figsize=(12, 6), sharex="col")
    fig.subplots_adjust(left=0.075, right=0.99, bottom=0.1, top=0.94, wspace=0.18, hspace=0.16)  # (as above)
    for j, (k, mask, phi, s) in enumerate((("ema1", an.segments.cal1, sig.phi1, sig.s1),
                                           ("ema2", an.segments.cal2, sig.phi2, sig.s2))):
        c = an.calibration[k]
        ax, axr = axes[0, j], axes[1, j]
        if c is None or mask is None:
            ax.text(0.5, 0.5, "no calibration sweep", ha="center", transform=ax.transAxes)
            continue
        x, y = phi[mask] / i, s[mask]
        sl = thin(x.size)
        ax.plot(x[sl], y[sl], ".", ms=1, alpha=0.4, label="LVDT s (raw)")
        xx = np.linspace(x.min(), x.max(), 200)
        ax.plot(xx, c.evaluate(xx), "k-", lw=1, label=f"regression, pitch {c.pitch:.4f}")
        ax.plot(xx, xx, "--", color="gray", lw=0.8, label="s = φ/i_total")
        ax.set_ylabel("s [mm]")
        ax.set_title(f"LVDT {k[-1]} calibration (paper Fig. 9)")
        ax.legend(fontsize=8)
        axr.plot(x[sl], (y - c.evaluate(x))[sl], ".", ms=1, alpha=0.4)
        axr.set_ylabel("residual [mm]")
        axr.set_xlabel("φ / i_total [mm]")
        axr.set_title(f"rmse {c.rmse_mm:.4f} mm, nonlinearity {c.nonlinearity_mm:.4f} mm", fontsize=9)
        for a in (ax, axr):
            a.grid(alpha=0.3)
    return fig


def decision_table(result: dict) -> str:
    """Per channel: the decision against the limit with U and the margin, then stiffness (truth beside
    it for simulated data); the rule, and each channel's reason once."""
    truth = result.get("truth")
    verdict = result.get("verdict", {})
    cols = [column("channel"), column("verdict"), column("backlash", "mm"), column("U (k = 2)", "mm"),
            column("limit B_spec", "mm"), column("margin", "mm"), column("c_left", "N/mm"), column("c_right", "N/mm")]
    if truth:
        cols += [column("truth backlash", "mm"), column("truth c_left / c_right", "N/mm"), column("error", "mm")]
    rows = []
    for ch in CHANNELS:
        b = result["backlash_mm"][ch]
        st = result["stiffness_N_per_mm"][ch]
        v = verdict.get(ch, {})
        status = v.get("status", "")
        cells = [ch, f"<span class='{status}'>{esc(status)}</span>", fmt(b), fmt(v.get("uncertainty_mm")),
                 fmt(v.get("limit_mm")), fmt(v.get("margin_mm")), fmt(st["left"], 0), fmt(st["right"], 0)]
        if truth:
            tb = truth["backlash_mm"][ch]
            ts = truth["stiffness_N_per_mm"][ch]
            cells += [fmt(tb), f"{ts['left']:.0f} / {ts['right']:.0f}", fmt(None if b is None else b - tb)]
        rows.append(cells)
    reasons = "".join(f"<li><span class='{esc(verdict[ch].get('status', ''))}'>{ch}</span>: "
                      f"{esc(verdict[ch]['reason'])}</li>" for ch in CHANNELS if ch in verdict)
    return (table(cols, rows, raw=True)
            + f"<p>{esc(result.get('decision_rule', ''))}.</p><ul class='reasons'>{reasons}</ul>")


def calibration_table(result: dict) -> str:
    """The LVDT calibration of this check (truth beside the pitch for simulated data)."""
    truth = result.get("truth")
    cal_rows = []
    for k in ("ema1", "ema2"):
        c = result["calibration"][k]
        if c is None:
            cal_rows.append([k, "not calibrated", "", "", ""])
            continue
        tp = f" (truth {truth['calibration'][k]['pitch']:.5f})" if truth else ""
        cal_rows.append([k, f"{c['pitch']:.5f}{tp}", f"{c['offset_mm']:+.4f}", f"{c['nonlinearity_mm']:.4f}",
                         f"{c['rmse_mm']:.4f}"])
    return table([column("LVDT"), column("pitch"), column("offset", "mm"), column("non-linearity", "mm"),
                  column("rmse", "mm")], cal_rows)


def head_parts(result: dict, intro: str) -> list[str]:
    """The report's first page: heading (verdict in its colour, SIMULATED for simulated data), what was
    checked, when, by which software and which run, ``intro`` (the actuation and the recording), why it stopped
    and where the drives were left (an aborted or incomplete check), and the decision section: each
    channel's verdict and reason once, the notes, the sign-off block."""
    parts = [heading("emacheck maintenance check", result), simulated_banner(result), identification(result),
             intro]
    if result.get("reason"):
        st = result["status"]
        parts.append(f"<p class='{esc(st)}'>{esc(st.capitalize())}: {esc(result['reason'])}</p>")
    if result.get("status") in ("aborted", "incomplete"):
        parts.append(drives_left(result))
    parts.append("<h2>Decision</h2>" + decision_table(result) + notes(result.get("notes", []), css="")
                 + signoff_block(result))
    parts.append("<h3>LVDT calibration</h3>" + calibration_table(result))
    return parts


def uncertainty_section(result: dict) -> str:
    """The uncertainty of each reading (what U is made of) and the error budget of paper 2.3."""
    verdict = result.get("verdict", {})
    rows = []
    for ch in CHANNELS:
        u = (verdict.get(ch) or {}).get("uncertainty_budget_mm")
        if u is None:
            rows.append([ch, "—", "—", "—", "—", "—", "—"])
            continue
        rows.append([ch, f"{u['statistical']:.5f}", f"{u['pitch']:.5f}", f"{u['temperature']:.5f}",
                     f"{u['method']:.5f}", f"{u['combined']:.5f}", f"{u['expanded']:.5f}"])
    out = ("<h2>Uncertainty of the readings</h2><p>Standard uncertainties of each backlash reading, combined "
           "as a root sum of squares and expanded with k = 2 (U, used by the decision; the ± of this report). "
           "σ (statistical): the regression's scatter (Newey-West); pitch: the LVDT pitch left after this "
           "check's calibration over the travel across the play; temperature: none, the calibration ran "
           "minutes before in the same check (paper 2.3); method: BLFmaint's validated accuracy bound, "
           "max(5 um, 5 %), rectangular.</p>"
           + table([column("channel"), column("σ (statistical)", "mm"), column("pitch", "mm"),
                    column("temperature", "mm"), column("method", "mm"), column("combined u", "mm"),
                    column("U (k = 2)", "mm")], rows))
    b = result.get("accuracy")
    if b:
        m = b["BLFmaint"]
        out += ("<h3>Error budget of paper 2.3 for this check</h3>"
                f"<p>LVDT pitch error {b['pitch_error']:.2%} before calibration (as measured), "
                f"{b['residual_pitch_error']:.3%} after; LVDT noise σ {b['lvdt_noise_std_mm']:.4f} mm; "
                f"for a backlash of B_spec = {b['backlash_mm']:g} mm, target accuracy {b['target_mm']:.3f} mm "
                "(a tenth of it, paper 2). Without the calibration the pitch error alone would read "
                f"{m['pitch_uncompensated_mm']:.4f} mm into the backlash; with it {m['pitch_compensated_mm']:.5f} "
                "mm.</p>"
                + table([column("method"), column("LVDT travel", "mm"), column("pitch, uncompensated", "mm"),
                         column("pitch, calibrated", "mm"), column("noise bound (1σ)", "mm"),
                         column("temperature", "mm"), column("total, calibrated", "mm"),
                         column("total, uncompensated", "mm")],
                        [["BLFmaint", f"{m['travel_mm']:.3f}", f"{m['pitch_uncompensated_mm']:.4f}",
                          f"{m['pitch_compensated_mm']:.5f}", f"{m['noise_mm']:.4f}", f"{m['temperature_mm']:.4f}",
                          f"{m['total_compensated_mm']:.4f}", f"{m['total_uncompensated_mm']:.4f}"]])
                + "<p>The noise bound is a single reading's before the regression averages it; the "
                "statistical term above is what the regression actually left.</p>")
    return out


def figure_timing(timing: Timing):
    """Histogram of the master's reaction (SYNC in to RPDOs out) [ms] per SYNC cycle, log counts,
    with its p99.9, maximum and the SYNC period (meta.json ``timing``, :mod:`hil.record.cycletiming`)."""
    plt = pyplot()
    r = timing.summary.reaction
    bins = np.asarray(r.histogram, dtype=float).reshape(-1, 2)
    w = r.bin_ms
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.bar(bins[:, 0], bins[:, 1], width=w, align="edge", color="#4477aa")
    ax.set_yscale("log")
    for x, style, label in ((r.p999_ms, "--", f"p99.9 {r.p999_ms:.3f} ms"),
                            (r.max_ms, ":", f"max {r.max_ms:.3f} ms"),
                            (timing.summary.period_ms, "-", f"SYNC period {timing.summary.period_ms:g} ms")):
        ax.axvline(x, color="k", ls=style, lw=1, label=label)
    ax.set_xlabel("SYNC received to RPDOs sent [ms]")
    ax.set_ylabel("SYNC cycles")
    ax.legend(fontsize=8)
    return fig


def timing_section(timing: Timing) -> str:
    """The master's loop timing: a table of the measures and the reaction's histogram."""
    rows = []
    s = timing.summary
    for q, what in ((s.reaction, "SYNC received to RPDOs sent"), (s.work, "sample complete to RPDOs sent"),
                    (s.work_cpu, "the same, CPU time"), (s.gap, "SYNC to SYNC")):
        if q.n:
            rows.append([what, q.n, fmt(q.p50_ms, 3), fmt(q.p99_ms, 3), fmt(q.p999_ms, 3), fmt(q.max_ms, 3)])
    tab = table(["measure", "cycles", column("p50", "ms"), column("p99", "ms"), column("p99.9", "ms"),
                 column("max", "ms")], rows)
    note = (f"<p>{s.cycles} SYNC cycles, {s.late} answered after a period, "
            f"{s.unanswered} unanswered, {s.syncs_missing} SYNC periods missing "
            f"(SYNC {esc(timing.sync)}).</p>")
    return tab + note + img(figure_timing(timing), dpi=90)


def write_report(path: Path, sig: Signals, an: Analysis, result: dict, act: Actuation, meta: RunRecord | None, *,
                 json_name: str = "result.json") -> None:
    """Write the self-contained HTML report (``json_name``: the result file beside it, linked)."""
    text = report_html(sig, an, result, act, meta, json_name=json_name)
    Path(path).write_text(text)


def report_html(sig: Signals, an: Analysis, result: dict, act: Actuation, meta: RunRecord | None, *,
                json_name: str = "result.json") -> str:
    """The text of the HTML report (:func:`write_report`); its figures drawn by two processes at once
    (:func:`hil.report.shell.drawn`)."""
    source = {"step column": "the run's step column", "detected": "the recording itself (no step column)"}
    intro = (f"<p>Actuation: {esc(getattr(act, 'name', ''))}; B_spec internal {act.mechanics.backlash_spec_int_mm} mm, "
             f"external {act.mechanics.backlash_spec_ext_mm} mm; {sig.n} samples, "
             f"{sig.t[-1] - sig.t[0]:.1f} s; calibration sweeps and force fight found from "
             f"{esc(source.get(an.segments.source, an.segments.source))}.</p>")
    if meta is not None and meta.seed is not None:
        intro += f"<p>Simulated rig, seed {meta.seed}.</p>"
    parts: list = head_parts(result, intro)
    parts.append(trace_lines(result.get("trace")))
    parts.append(uncertainty_section(result))
    parts.append(("<h2>Force fight (paper Fig. 3)</h2>",
                  Drawing(lambda: img(figure_time(sig, an, act), dpi=90), axes=6)))
    truth = result.get("truth")
    for ch in CHANNELS:
        r = an.maint[ch]
        parts.append(f"<h2>{ch}</h2>")
        if not isinstance(r, BlfMaintResult):
            parts.append("<p class='inconclusive'>Not measured (the reason is in the decision above).</p>")
            continue
        d, f = _channel_data(sig, an, ch)
        u_mm = (result.get("verdict", {}).get(ch) or {}).get("uncertainty_mm")
        parts.append((Drawing(lambda ch=ch, d=d, f=f, r=r: img(figure_dfdd(ch, d, f, r), dpi=90), axes=2),
                      lambda ch=ch, d=d, f=f, r=r, u_mm=u_mm: img(figure_lines(ch, d, f, r, truth, u_mm), dpi=90)))
    parts.append(("<h2>LVDT calibration</h2>",
                  Drawing(lambda: img(figure_calibration(sig, an, act), dpi=90), axes=4)))
    timing = meta.timing if meta is not None else None
    if timing is not None and timing.summary.reaction.n:
        parts.append(("<h2>Loop timing (master)</h2>", lambda: timing_section(timing)))
    parts.append(file_link(json_name))
    return page_html(page_title("emacheck maintenance check", result), drawn(parts),
                     running_head("emacheck maintenance check", result))


def write_stopped_report(path: Path, result: dict, *, json_name: str = "result.json") -> None:
    """The report of a check that stopped with nothing to analyse (a preflight that refused the drives): the
    heading, why it stopped, where the drives were left, why there is no analysis, and the traceability block
    (identity as read, each drive's reaction to losing the master and its drill, limits), linked to
    ``json_name``."""
    parts = [heading("emacheck maintenance check", result), simulated_banner(result), identification(result)]
    st = str(result.get("status") or "")
    if result.get("reason"):
        parts.append(f"<p class='{esc(st)}'>{esc(st.capitalize())}: {esc(result['reason'])}</p>")
    parts.append(drives_left(result))
    if result.get("analysis_error"):
        parts.append(f"<p>No analysis: {esc(result['analysis_error'])}</p>")
    parts += [trace_lines(result.get("trace")), file_link(json_name)]
    write_page(path, page_title("emacheck maintenance check", result), parts,
               running_head("emacheck maintenance check", result))
