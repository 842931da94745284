"""The wear history page (``emacheck history --out DIR``): trends, the plots a planner wants, the checks.

One figure per series (an actuator's internal backlash, or the external
backlash of a pair, at one installation): the readings against flight hours
(or dates) with their expanded uncertainty as error bars, B_spec, each
segment's wear line with the 95 % confidence band of the line and the 95 %
prediction band of a future reading, and where the line reaches B_spec with
its interval. BLFserv readings are drawn hollow (not fitted). Built from the
report shell (:mod:`hil.report.shell`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blf.wear import trend_band
from hil.history.trends import NO_IDENTITY, Series, fmt_serial, iso
from hil.report.shell import column, esc, file_link, fmt, img, pyplot, table, write_page

#: figures drawn at most (the page stays readable; filter with --actuator / --aircraft)
MAX_FIGURES = 40


def figure_series(s: Series):
    """Backlash against flight hours (or date): readings with U, B_spec, trend, bands, crossing."""
    fig, ax = pyplot().subplots(figsize=(9, 4.2))
    fh_axis = not s.segments or s.segments[0].axis == "flight_hours"
    x_hi = max([p.x for p in s.points + s.serv_points if math.isfinite(p.x)] or [0.0])
    for j, seg in enumerate(s.segments):
        col = f"C{j % 10}"
        xs = np.array([p.x for p in seg.points])
        ax.errorbar(xs, [p.backlash_mm for p in seg.points], yerr=[p.uncertainty_mm for p in seg.points], fmt="o",
                    ms=4, color=col, capsize=2, lw=0.8, label=f"checks (segment {j + 1})" if len(s.segments) > 1
                    else "checks (B ± U)")
        if seg.fit is None:
            continue
        end = xs.max()
        current = j == len(s.segments) - 1  # an older segment (before a repair) is drawn over its own checks
        c = seg.crossing if current else None
        if c is not None and math.isfinite(c.x):
            far = c.hi if math.isfinite(c.hi) else c.x + 0.5 * (c.x - xs.min())
            end = max(end, min(far, xs.max() + 3.0 * max(np.ptp(xs), 1.0)))
        grid = np.linspace(xs.min(), end, 200)
        lo, mid, hi = trend_band(seg.fit, grid)
        plo, _, phi = trend_band(seg.fit, grid, prediction=True)
        ax.plot(grid, mid, "-", color=col, lw=1.2, label="trend (weighted fit)" if j == len(s.segments) - 1 else None)
        ax.fill_between(grid, lo, hi, color=col, alpha=0.18, lw=0,
                        label="95 % band of the trend" if j == len(s.segments) - 1 else None)
        ax.plot(grid, plo, ":", color=col, lw=0.8)
        ax.plot(grid, phi, ":", color=col, lw=0.8,
                label="95 % band of a next reading" if j == len(s.segments) - 1 else None)
        if c is not None and math.isfinite(c.x):
            ax.axvline(c.x, color=col, ls="--", lw=0.8)
            a, b = (c.lo if math.isfinite(c.lo) else grid[0]), (c.hi if math.isfinite(c.hi) else end)
            ax.axvspan(a, b, color="C3", alpha=0.07, lw=0,
                       label="B_spec reached (95 % interval)" if j == len(s.segments) - 1 else None)
        x_hi = max(x_hi, end)
    sp = [p for p in s.serv_points if math.isfinite(p.x)]
    if sp:
        ax.errorbar([p.x for p in sp], [p.backlash_mm for p in sp],
                    yerr=[p.uncertainty_mm or 0.0 for p in sp], fmt="o", mfc="none", color="gray", ms=4, capsize=2,
                    lw=0.6, label="BLFserv readings (not fitted)")
    if s.limit_mm is not None:
        ax.axhline(s.limit_mm, color="C3", lw=1.2, label=f"B_spec {s.limit_mm:.3f} mm")
    if fh_axis:
        ax.set_xlabel("flight hours [FH]")
    else:
        ax.xaxis_date()  # x in days since 1970, matplotlib's date unit
        ax.set_xlabel("date (UTC)")
    ax.set_ylabel("backlash [mm]")
    ax.set_title(s.title(), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    return fig


def _trend_rows(doc: dict) -> list[list[str]]:
    rows = []
    for t in doc["trends"]:
        who = fmt_serial(t["serial"]) if t["ema"] else " / ".join(fmt_serial(v) for v in t["pair"].values())
        where = " ".join(x for x in (t["aircraft"], t["position"]) if x) or "—"
        rate = t["rate_mm_per_1000_fh"] if t["rate_mm_per_1000_fh"] is not None else t["rate_mm_per_year"]
        lo, hi = t["limit_at_fh_interval"]
        dlo, dhi = t["limit_at_date_interval"]
        rows.append([who, t["channel"], esc(where) + (" <i>(simulated)</i>" if t["simulated"] else ""),
                     f"{t['segment'] + 1}{'' if t['current'] else ' (old)'}", t["n"],
                     "—" if rate is None else f"{rate:.4f} {t['rate_unit']} (σ {t['rate_sigma']:.4f})",
                     fmt(t["backlash_now_mm"]), fmt(t["limit_mm"], 3),
                     "—" if t["limit_at_fh"] is None else f"{t['limit_at_fh']:.0f}",
                     "—" if (lo, hi) == (None, None) else f"{'…' if lo is None else f'{lo:.0f}'} – "
                                                          f"{'…' if hi is None else f'{hi:.0f}'}",
                     t["limit_at_date"] or "—",
                     "—" if (dlo, dhi) == (None, None) else f"{dlo or '…'} – {dhi or '…'}",
                     esc(t["reason"] or "")])
    return rows


def _check_rows(s: Series) -> list[list[object]]:
    rows = []
    for p in sorted(s.points + s.serv_points, key=lambda p: p.time):
        r = p.row
        rows.append([iso(r["time_utc"]), "—" if r["flight_hours"] is None else f"{r['flight_hours']:.0f}",
                     "—" if r["flight_cycles"] is None else r["flight_cycles"], r["kind"],
                     (r["run_id"] or r["run_key"])[:12], fmt(p.backlash_mm), fmt(p.uncertainty_mm), p.verdict or "—",
                     p.segment + 1 if r["kind"] == "maint" else "serv", r["operator"] or "—", r["work_order"] or "—"])
    return rows


def _not_trended(doc: dict) -> list[str]:
    """The results in no trend and why (their actuators' identity unknown), as the console lists them."""
    out = [c for c in doc["checks"] if c.get("not_trended")]
    if not out:
        return []
    rows = [[c["time_utc"], c["kind"], c["status"],
             ", ".join(f"{ch} {fmt(v)}" for ch, v in c["backlash_mm"].items() if v is not None) or "—",
             c.get("recording") or c["run_key"], c["not_trended"]] for c in out]
    return [f"<h2>In no trend</h2><p>{len(out)} result(s): {esc(NO_IDENTITY)}</p>",
            table(["time (UTC)", "kind", "status", column("backlash", "mm"), "recording", "why"], rows)]


def write_history_report(path: Path, doc: dict, series: list[Series], *, json_name: str | None = None) -> None:
    """Write the self-contained history page."""
    parts = [f"<h1>Wear history</h1><p>Database {esc(doc['history'])}; "
             f"{len(doc['checks'])} result(s), {len(series)} series"
             + "".join(f", {k} {esc(v)}" for k, v in doc["filters"].items() if v is not None) + ".</p>"]
    if json_name:
        parts.append(file_link(json_name, "the same as data"))
    parts.append(
        "<p>Per actuator and channel: the maintenance checks (BLFmaint) in order, a wear line fitted by weighted "
        "least squares (weights from each reading's U, k = 2; the scatter widens the band where it exceeds the "
        "stated uncertainties), and the flight hours at which the line reaches B_spec with its 95 % interval "
        "(the inversion of the line's confidence band); the date at the utilisation the checks record. A step "
        "down (repair) or another actuator at a position starts a new segment. Simulated checks are never in a "
        "real actuator's trend. BLFserv readings are shown, not fitted.</p>")
    parts.append("<h2>Trends</h2>" + table(
        ["actuator", "channel", "where", "segment", "n", column("rate (σ: standard uncertainty)"),
         column("backlash now", "mm"),
         column("B_spec", "mm"), column("B_spec reached", "FH"), column("95 % interval", "FH"), "date",
         "date 95 % interval", "note"], _trend_rows(doc), raw=True))
    parts += _not_trended(doc)
    for k, s in enumerate(series):
        parts.append(f"<h2>{esc(s.title())}</h2>")
        if k < MAX_FIGURES and s.points + s.serv_points:
            parts.append(img(figure_series(s), dpi=80))
        elif k == MAX_FIGURES:
            parts.append(f"<p class='warn'>figures after the first {MAX_FIGURES} series are left out: "
                         f"filter with --actuator or --aircraft</p>")
        parts.append(table(["time (UTC)", column("flight hours", "FH"), "cycles", "kind", "run",
                            column("backlash", "mm"), column("U (k = 2)", "mm"), "verdict", "segment", "operator",
                            "work order"], _check_rows(s)))
    write_page(path, "emacheck wear history", parts)
