"""The commissioning report (``commission.html``): ready or not, every problem with its profile key and
the value that would fit, what was measured, the drill, where the drives ended."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.report.shell import esc, file_link, fmt, img, master_loss_text, notes, pyplot, table, thin, write_page


def _gain_rows(measured: dict, what: str) -> list[list[str]]:
    rows = []
    for phase, gains in (measured.get(what) or {}).items():
        for ema, g in gains.items():
            rows.append([phase.replace("_", " "), ema, fmt(g, 4)])
    return rows


#: The unit of each signal at rest (the samples' names: phi motor angle, s LVDT stroke, F load-cell force).
REST_UNITS = {"phi": "rad", "s": "mm", "F": "N"}


def figure_movements(traces: dict, T: float, lvdt_tol: float = 0.10, force_tol: float = 0.25,
                     force_N: float | None = None):
    """Per EMA's turn: each LVDT's stroke change against its motor's travel while that EMA moved (the dashed
    line: slope 1, a right sign and scale), and both load cells' change through the force step.

    ``traces``: ``"move k"`` / ``"force step k"`` -> arrays ``x1, x2`` (motor angle over the gear ratio) [mm],
    ``s1, s2`` [mm], ``F1, F2`` [N], one sample per SYNC period ``T`` [s]. The expected band is shaded: slope
    1 +- ``lvdt_tol``; the force step's +-``force_N`` [N] +- ``force_tol`` of it (the pushing drive's own load
    cell up, the other down)."""
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(10, 7))
    for row, k in enumerate((1, 2)):
        move, step = traces.get(f"move {k}"), traces.get(f"force step {k}")
        a = ax[row][0]
        if move is not None:
            sl = thin(move["x1"].size, 2000)
            for e, style in ((1, "C0"), (2, "C1")):
                x, y = move[f"x{e}"] - move[f"x{e}"][0], move[f"s{e}"] - move[f"s{e}"][0]
                a.plot(x[sl], y[sl], style, lw=1, label=f"LVDT {e} vs motor {e}")
            lim = max(1e-3, float(abs(move[f"x{k}"] - move[f"x{k}"][0]).max()))
            a.plot([0, lim], [0, lim], "k--", lw=0.8, label="slope 1")
            a.fill_between([0, lim], [0, lim * (1 - lvdt_tol)], [0, lim * (1 + lvdt_tol)], color="0.85",
                           label=f"expected: 1 +- {lvdt_tol:g}")
        a.set(title=f"EMA {k} moves", xlabel="motor travel / gear ratio [mm]", ylabel="LVDT change [mm]")
        a.legend(fontsize=8)
        a = ax[row][1]
        if step is not None:
            t = T * (1 + np.arange(step["F1"].size))
            for e in (1, 2):
                a.plot(t, step[f"F{e}"] - step[f"F{e}"][0], lw=1, label=f"load cell {e}")
            if force_N:
                j = 3 - k  # the drive that pushes in EMA k's turn
                for sign in (1, -1):
                    lo, hi = sorted((sign * force_N * (1 - force_tol), sign * force_N * (1 + force_tol)))
                    a.axhspan(lo, hi, color="0.85", zorder=0)
                    a.axhline(sign * force_N, color="k", ls="--", lw=0.8)
                a.plot([], [], color="0.85", lw=6, label=f"expected: load cell {j} +{force_N:g} N, {k} -{force_N:g} N "
                                                          f"(+- {force_tol:.0%})")
        a.set(title=f"force step in EMA {k}'s turn", xlabel="t [s]", ylabel="force change [N]")
        a.legend(fontsize=8)
    return fig


def _hypotheses(report: dict) -> list[str]:
    """Each gain with its standard error, residual and tolerance, and every hypothesis tried with its verdict."""
    h = report.get("hypotheses") or {}
    out = []
    if obs := h.get("observations"):
        rows = []
        for o in obs:
            want = -1.0 if o["kind"] == "load-cell gain" and o["ema"] != o["mover"] else 1.0
            gain = o["kind"] in ("LVDT gain", "load-cell gain")
            follows = o["kind"] == "LVDT follows"
            rows.append([o["kind"], f"{o['sensor']} {o['ema']}", o["mover"] or "at rest",
                         f"{fmt(o['measured'], 4)} {o['unit']}", "" if o["se"] is None else f"{o['se']:.2g}",
                         fmt(want, 1) if gain else ("0 (its own LVDT)" if follows else ""),
                         fmt(o["measured"] / want - 1.0, 3) if gain else "",
                         "" if follows else f"{'+- ' if gain else '<= '}{o['tolerance']:g}", o["key"]])
        out.append(table(["observation", "channel", "EMA moving / pushing", "measured", "standard error", "expected",
                          "residual (relative)", "tolerance", "profile key"], rows))
    if tried := h.get("tried"):
        out.append("<h2>Hypotheses tried (simplest first)</h2>")
        out.append(table(["hypothesis", "causes", "free values", "fitted", "verdict", "why"],
                         [[t["hypothesis"], t["causes"], t["free_values"],
                           ", ".join(f"{k} {v:.4g}" for k, v in t["fitted"].items()), t["status"], t["why"]]
                          for t in tried]))
    return out


def _patch(report: dict) -> list[str]:
    p = report.get("patch") or {}
    if not p.get("keys") and not p.get("wiring_fixes"):
        return []
    out = ["<h2>Profile patch</h2>"]
    if p.get("keys"):
        out.append(table(["profile key", "value that makes the rig ready"], [[k, v] for k, v in p["keys"].items()]))
        out.append(f"<p>{esc(p['file'])}: <code>emacheck profile apply-patch PROFILE.toml {esc(p['file'])} --out "
                   f"NEW.toml</code>, then commission again.</p>")
    if p.get("wiring_fixes"):
        out.append(notes([f"wiring fix (no profile key): {w}" for w in p["wiring_fixes"]]))
    return out


def write_commission_report(path: Path, report: dict, traces: dict | None = None, T: float = 0.002) -> None:
    """The page of ``report`` (the commissioning's JSON, :mod:`hil.cli.commission`); ``traces`` (see
    :func:`figure_movements`) adds the movements' figure."""
    ready = report["status"] == "ready"
    badge = "pass" if ready else "fail"
    sim = " <span class='simulated'>SIMULATED</span>" if report.get("simulated") else ""
    parts = [f"<h1>Commissioning: <span class='badge {badge}'>{'READY' if ready else 'NOT READY'}</span>{sim}</h1>",
             f"<p>{esc(report['created'])}, emacheck {esc(report['software']['emacheck'])}; bus "
             f"{esc(report['bus']['interface'])}:{esc(report['bus']['channel'])}; reached: "
             f"{esc(report['stage_reached'])}</p>"]
    if report.get("wiring_faults"):
        parts.append(notes([f"wiring fault injected: {f['kind']} (EMA {f['ema']}"
                            + (f", value {f['value']:g})" if f.get("value") is not None else ")")
                            for f in report["wiring_faults"]]))
    parts.append("<h2>Problems</h2>")
    if report["findings"]:
        parts.append(table(["step", "what", "profile key", "finding", "measured", "fits"],
                           [[f["stage"], f["kind"], f["key"] or "-", f["text"],
                             "" if f["measured"] is None else f"{fmt(f['measured'], 4)} {f['unit']}",
                             "" if f["fits"] is None else f["fits"]] for f in report["findings"]]))
    else:
        parts.append("<p>None: the rig is ready for its first check.</p>")
    parts += _patch(report)
    parts.append("<h2>Nodes</h2>")
    if idents := report.get("identities"):
        hexed = lambda v: "-" if v is None else f"0x{v:08X}"  # noqa: E731
        parts.append(table(["node", "EMA / name", "vendor expected / read", "product expected / read",
                            "revision at least / read", "serial pinned / read (0x1018:04)"],
                           [[i["node"], i["name"],
                             f"{hexed(i['expected']['vendor_id'])} / {hexed(i['read']['vendor_id'])}",
                             f"{hexed(i['expected']['product_code'])} / {hexed(i['read']['product_code'])}",
                             f"{hexed(i['expected']['revision_min'])} / {hexed(i['read']['revision'])}",
                             f"{hexed(i['expected']['serial'])} / {hexed(i['read']['serial'])}"] for i in idents]))
    parts.append(table(["node", "heard", "answers", "device type", "identity 0x1018", "state before power-up"],
                       [[k, v.get("heard"), v.get("answers"), f"0x{v['device_type']:08X}" if "device_type" in v else "",
                         ", ".join(f"{n} 0x{x:08X}" for n, x in (v.get("identity") or {}).items() if x is not None),
                         v.get("state", "")] for k, v in report["scan"]["nodes"].items()]))
    m = report["measured"]
    parts.append("<h2>Measured</h2>")
    rest = m.get("at_rest") or {}
    if rest:
        parts.append(table(["signal at rest", "unit", "mean", "peak to peak", "std"],
                           [[n, REST_UNITS.get(n.rstrip("12"), ""), fmt(v["mean"], 4), fmt(v["ptp"], 4),
                             fmt(v["std"], 4)] for n, v in rest.items()]))
    parts += _hypotheses(report)
    if rows := _gain_rows(m, "lvdt_gain"):
        parts.append(table(["LVDT gain (mm per mm of motor travel), while", "EMA", "gain"], rows))
    if rows := _gain_rows(m, "loadcell_gain"):
        parts.append(table(["load-cell change per change of the force, while", "EMA", "gain"], rows))
    if rows := _gain_rows(m, "loadcell_push_N"):
        parts.append(table(["load-cell change [N], drives without CST: while", "EMA", "N"], rows))
    if rows := _gain_rows(m, "lvdt_follows"):
        parts.append(table(["force step of", "moved", "mm"], rows))
    if traces:
        th = report["thresholds"]
        parts.append(img(figure_movements(traces, T, th["lvdt_gain_tolerance"], th["force_gain_tolerance"],
                                          report["limits"]["force_N"])))
    lim = report["limits"]
    parts.append(f"<p>Motion limits: force {lim['force_N']:g} N (then twice that), speed "
                 f"{lim['speed_mm_per_s']:g} mm/s, travel {lim['travel_mm']:g} mm; movement stopped beyond "
                 f"{lim['max_force_N']:g} N or {lim['max_travel_mm']:g} mm from the start.</p>")
    parts.append("<h2>The master's death</h2>")
    parts.append(table(["EMA", "reaction"], [[k, master_loss_text(v)] for k, v in report["master_loss"].items()])
                 if report["master_loss"] else "<p>Not reached.</p>")
    parts.append("<h2>Drives at the end</h2>")
    parts.append(table(["EMA", "node", "state", "confirmed", "reachable"],
                       [[k, d["node"], d["state"], d["confirmed"], d["reachable"]]
                        for k, d in report["drives_final"].items()]))
    parts.append(file_link("commission.json", "the report as data"))
    write_page(path, "emacheck commissioning", parts)
