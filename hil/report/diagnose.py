"""The diagnosis report (``diagnosis_report.html``): verdict, effects, residuals before and after, regime cells."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.report.shell import column, esc, file_link, img, pyplot, table, thin, write_page


def _unit(channel: str) -> str:
    return "N" if channel.startswith("F") or channel == "force" else ("m" if channel in ("q", "q_ref") else "mm")


def figure_overlay(model, d, channel: str):
    """One channel: recording, nominal model and model with the fitted effects; residuals in the compared
    band before and after, the flagged windows red, the held-out blocks grey."""
    from scipy.ndimage import uniform_filter1d

    t = model.t_s
    ok = d.valid[channel]
    sl = thin(t.size)
    fig, ax = pyplot().subplots(2, 1, figsize=(9, 4.5), sharex=True)
    m = d.measured[channel]
    ax[0].plot(t[ok][sl], m[ok][sl], ".", ms=1, color="0.6", label="recording")
    ax[0].plot(t[ok][sl], d.predicted_before[channel][ok][sl], lw=0.8, label="nominal model")
    ax[0].plot(t[ok][sl], d.predicted_after[channel][ok][sl], lw=0.8, label="with fitted effects")
    ax[0].legend(fontsize=7)
    unit = _unit(channel)
    ax[0].set_ylabel(f"{channel} [{unit}]")
    kept = np.asarray(d.kept)
    kv = d.kept_valid.get(channel) if d.kept_valid else None
    for pred, lab in ((d.predicted_before, "residual before"), (d.predicted_after, "residual after")):
        r = np.where(ok, m - pred[channel], 0.0)
        if kept.size and kv is not None:  # in the compared band, at its kept samples
            rb = d.band.reduce(r)
            ax[1].plot(t[kept][kv], rb[kv], lw=0.8, label=lab + " (in the band)")
        else:
            rs = uniform_filter1d(r, max(1, int(0.5 / np.median(np.diff(t)))))
            ax[1].plot(t[ok][sl], rs[ok][sl], lw=0.8, label=lab + " (0.5 s mean)")
    ax[1].set_ylabel(f"residual [{unit}]")
    for loc in d.locations:
        if loc.channel == channel and loc.test == "window":  # a regime cell spans many visits
            ax[1].axvspan(loc.t_start_s, loc.t_end_s, color="red", alpha=0.1)
    # held-out blocks (never fitted): grey
    ho = np.asarray(d.held_out, dtype=bool)
    if ho.size == t.size and ho.any():
        edges = np.flatnonzero(np.diff(np.r_[0, ho.astype(np.int8), 0]))
        for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
            ax[1].axvspan(t[a], t[b - 1], color="0.5", alpha=0.12, lw=0,
                          label="held out (not fitted)" if k == 0 else None)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_xlabel("t [s]")
    ax[1].legend(fontsize=7)
    return fig


def figure_residuals_pair(t, measured, valid, before, after, channel: str, labels: tuple):
    """One channel against two models (e.g. a reference's and it with the named changes): the recording and
    both predictions, and both residuals as 0.5 s means (no band)."""
    from scipy.ndimage import uniform_filter1d

    ok = np.asarray(valid, dtype=bool)
    sl = thin(int(ok.sum()))
    fig, ax = pyplot().subplots(2, 1, figsize=(9, 4.5), sharex=True)
    unit = _unit(channel)
    ax[0].plot(t[ok][sl], measured[ok][sl], ".", ms=1, color="0.6", label="recording")
    n = max(1, int(0.5 / np.median(np.diff(t))))
    for pred, lab in ((before, labels[0]), (after, labels[1])):
        ax[0].plot(t[ok][sl], pred[ok][sl], lw=0.8, label=lab)
        r = uniform_filter1d(np.where(ok, measured - pred, 0.0), n)
        ax[1].plot(t[ok][sl], r[ok][sl], lw=0.8, label=f"residual, {lab} (0.5 s mean)")
    ax[0].set_ylabel(f"{channel} [{unit}]")
    ax[0].legend(fontsize=7)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_ylabel(f"residual [{unit}]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(fontsize=7)
    return fig


def figure_regime(d, channel: str):
    """Regime cells of one channel: cell score on the fit half against the held-out half,
    before and after the fitted effects (a mismatch tied to the regime lies on the diagonal)."""
    fig, ax = pyplot().subplots(figsize=(5.5, 5))
    lim = 3.0
    for rs, lab, col in ((d.regime_cells_before[channel], "nominal model", "C0"),
                         (d.regime_cells_after[channel], "with fitted effects", "C1")):
        ax.plot(rs.z_fit, rs.z_held, "o", ms=4, color=col, alpha=0.7, label=f"{lab}: S = {rs.score:.1f}")
        lim = max(lim, float(np.nanmax(np.abs(np.r_[rs.z_fit, rs.z_held, 0.0]))) * 1.1)
        if rs is d.regime_cells_before[channel]:
            for b in np.argsort(-np.nan_to_num(rs.products, nan=-np.inf))[:3]:
                if np.isfinite(rs.products[b]) and rs.products[b] > 4.0:
                    ax.annotate(d.regime_labels[b].replace("position along the stroke", "x").replace(", ", "\n"),
                                (rs.z_fit[b], rs.z_held[b]), fontsize=6)
    ax.plot([-lim, lim], [-lim, lim], "k", lw=0.5)
    ax.axhline(0, color="0.7", lw=0.5)
    ax.axvline(0, color="0.7", lw=0.5)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("cell score, fit half")
    ax.set_ylabel("cell score, held-out half")
    ax.set_title(f"{channel}: regime cells", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def _g(x, nd: int = 4) -> str:
    """A number to ``nd`` significant digits, "—" for None."""
    return "—" if x is None else f"{x:.{nd}g}"


def _param_unit(name: str) -> str:
    """The unit a parameter's name ends with (``force_N`` -> N, ``delay_s`` -> s); "1" if none."""
    for suffix, unit in (("_N_s_per_mm", "N s/mm"), ("_N_s_per_m", "N s/m"), ("_N_per_mm", "N/mm"),
                         ("_N_per_m2", "N/m²"), ("_N_per_m", "N/m"), ("_mm_per_s", "mm/s"), ("_m_per_s", "m/s"),
                         ("_per_mm", "1/mm"), ("_per_s", "1/s"), ("_mm", "mm"), ("_N", "N"), ("_s", "s")):
        if name.endswith(suffix):
            return unit
    return "1"


def write_report(path: Path, model, d, data: dict, *, json_name: str = "diagnosis.json") -> None:
    """Self-contained HTML report in the shell of the maintenance report: verdict, the band compared,
    effects with units, where the rest lies, residual table (band and raw, whole and held-out),
    overlays and regime cells."""
    from blf.diagnose import DiagnoseConfig

    channels = [c for c in d.measured if d.valid[c].any()]
    cols = [column("channel"), column("unit"), column("RMS before"), column("RMS after"),
            column("held-out RMS before"), column("held-out RMS after"), column("noise floor"),
            column("held-out raw RMS before"), column("held-out raw RMS after"), column("raw noise floor"),
            column("excess before", "1"), column("excess after", "1"), column("regime score before", "1"),
            column("regime score after", "1")]
    rows = [[c, _unit(c), *(_g(data[k].get(c)) for k in (
        "residual_rms_before", "residual_rms_after", "residual_rms_holdout_before", "residual_rms_holdout_after",
        "noise_floor", "residual_rms_raw_holdout_before", "residual_rms_raw_holdout_after", "noise_floor_raw",
        "excess_before", "excess_after", "regime_score_before", "regime_score_after"))] for c in channels]
    erows = [[f"<b>{esc(e['name'])}</b>", esc(e["where"]), esc(e["words"]),
              "<br>".join(f"{esc(k)} = {_g(v)} {esc(_param_unit(k))} (σ {_g(e['uncertainty'].get(k), 2)})"
                          for k, v in e["parameters"].items()),
              f"{_g(e.get('delta_bic'))}", f"{_g(e.get('delta_chi2_holdout'))}",
              f"<small>{esc(e['evidence'])}</small>"] for e in data["effects"]]
    effs = (table([column("effect"), column("where"), column("what"), column("parameters (σ: standard uncertainty)"),
                   column("ΔBIC", "1"),
                   column("Δχ² held out", "1"), column("evidence")], erows, raw=True)
            if erows else "<p>none</p>")
    locs = "".join(f"<li>{esc(loc['channel'])} ({esc(loc.get('where', ''))}): "
                   f"{_g(loc['t_start_s'])}–{_g(loc['t_end_s'])} s "
                   f"({esc(loc['test'])} test), {esc(loc['regime'])}</li>" for loc in data["locations"][:12])
    css = {"no_mismatch": "pass", "explained": "pass", "unexplained": "fail"}[data["verdict"]]
    where = (f"<p>The rest of the mismatch lies at: <b>{esc(', '.join(data['where']))}</b> (strongest first).</p>"
             if data.get("where") else "")
    parts = [f"<h1>Simulation versus recording: <span class='badge {css}'>{esc(data['verdict'])}</span></h1>",
             f"<p>Model {esc(data['model'])}; compared in the band: {esc(data['band']['words'])}; "
             f"BIC before {_g(data['ic_before'], 7)}, after {_g(data['ic_after'], 7)} (dimensionless); "
             f"diagnosis {_g(data['diagnosis_s'], 3)} s.</p>",
             "<h2>Effects the fit accepted</h2>" + effs, where,
             f"<h2>Where</h2><ul>{locs or '<li>nowhere</li>'}</ul>",
             "<h2>Residual RMS</h2><p>RMS in the channel's unit, in the compared band unless marked raw; "
             "held-out: on the half never fitted. Excess and regime score are dimensionless (noise alone: "
             "excess about 1, regime score about standard normal).</p>" + table(cols, rows),
             "<h2>Overlay and residuals</h2>",
             *(f"<h3>{esc(c)} [{_unit(c)}]</h3>{img(figure_overlay(model, d, c))}" for c in channels)]
    thr = DiagnoseConfig().regime_threshold
    flagged = [c for c in model.channels if max(d.regime_before.get(c, 0.0), d.regime_after.get(c, 0.0)) > thr]
    if flagged and d.regime_labels:
        parts.append("<h2>Regime test</h2><p>Each point is a regime cell (stroke position x sign of velocity x "
                     "sign of force); a mismatch tied to the operating regime repeats in both halves and lies "
                     "on the diagonal, noise scatters around the origin.</p>"
                     + "".join(img(figure_regime(d, c)) for c in flagged))
    parts.append(file_link(json_name))
    write_page(path, "emacheck diagnose", parts)


def write_reference_report(path: Path, data: dict, *, json_name: str = "diagnosis.json") -> None:
    """The report of ``diagnose --reference`` (single axis): each nominal parameter against its reference
    value, the floors, what this recording cannot tell apart, the masked samples."""
    from blf.diagnose import NOMINAL_UNITS
    untrusted = ("the effort's mean force not trusted (the witnesses disagree); a force periodic in position named"
                 if data["effects"] else "effort not trusted: not diagnosed")
    verdict = (untrusted if data["verdict"] == "untrusted_effort" else
               "changes named" if data["effects"] else "no change above its floor")
    g = lambda x: "—" if x is None else f"{x:.4g}"  # noqa: E731
    rows = [(c["parameter"], NOMINAL_UNITS.get(c["parameter"], ""), g(c["reference"]), g(c["value"]),
             f"{g(c['change'])} ± {g(c['uncertainty'])}", g(c["z"]), g(c["floor"]),
             "named" if c["named"] else ("under its floor" if c["supported"] else "not supported"))
            for c in data["changes"]]
    ident = data["identifiability"]
    parts = [
        "<h1>Single axis against a reference</h1>",
        f"<p><b>{esc(verdict)}</b> ({esc(data['verdict'])}); reference {esc(data['reference']['recording'])}</p>",
        f"<p>Effort: {esc(data['conversion'])}</p>",
        f"<p>Effort against the known load: {esc(data['effort']['words'])}</p>",
        f"<p>{esc(data['floor']['words'])}</p>",
        coverage_paragraph(data["floor"]),
        "<h2>Nominal parameters against the reference</h2>",
        table(["parameter", "unit", "reference", "this recording", "change ± u", "z", "floor", "status"], rows),
        *witness_parts(data.get("witness")),
        "<h2>What this recording cannot tell apart</h2>",
        table(["terms", "why", "what motion would separate them"],
              [(", ".join(m["terms"]), m["why"], m["would_separate"]) for m in ident["cannot_tell_apart"]]),
        *_periodic_parts(data.get("periodic")),
        "<h2>Samples not compared</h2>",
        f"<p>This recording: {esc(data['mask']['words'])}.<br>"
        f"Reference: {esc(data['reference']['mask']['words'])}.</p>",
        file_link(json_name),
    ]
    write_page(path, "diagnosis against a reference", parts)


def figure_periodic_profile(prof: dict):
    """The effort against position, cycle-averaged, per direction: the recording and the reference, each with
    its model without and with the periodic terms (diagnosis.json ``periodic.profile``)."""
    dirs = [d for d in ("extend", "retract") if d in prof["recording"] or d in prof["reference"]]
    fig, ax = pyplot().subplots(len(dirs), 1, figsize=(9, 2.6 * len(dirs) + 0.6), squeeze=False)
    for a, d in zip(ax[:, 0], dirs, strict=True):
        for key, col, lab in (("reference", "0.55", "reference"), ("recording", "C0", "this recording")):
            p = prof[key].get(d)
            if p is None:
                continue
            q = np.asarray(p["q_m"]) * 1e3
            a.plot(q, p["force_N"], ".", ms=2.5, color=col, label=f"{lab}: effort (cycle-averaged)")
            a.plot(q, p["model_without_N"], "--", lw=0.8, color=col, label=f"{lab}: fit without the periodic term")
            a.plot(q, p["model_with_N"], "-", lw=0.9, color=col, label=f"{lab}: fit with it")
        a.set_ylabel(f"force N ({d})")
    ax[-1, 0].set_xlabel("position mm")
    ax[0, 0].legend(fontsize=7, ncol=2)
    ax[0, 0].set_title(f"effort against position, period {prof['period_m'] * 1e3:.4g} mm", fontsize=9)
    fig.tight_layout()
    return fig


def _periodic_parts(per: dict | None) -> list:
    """The report's section on forces periodic in position (single axis against a reference)."""
    if per is None:
        return []
    g = lambda x: "—" if x is None else f"{x:.4g}"  # noqa: E731
    rows = [(g(c["period_m"] * 1e3), g(c["period_reference_m"] * 1e3),
             "; ".join(f"{d} {g(v['reference_N'])} -> {g(v['amplitude_N'])} "
                       f"({g(v['change_N'])} ± {g(v['uncertainty_N'])})" for d, v in c["directions"].items()),
             g(c["floor_N"]), "named" if c["named"] else "not named",
             c["where"]["words"], c.get("order", {}).get("words", "—")) for c in per["components"]]
    parts = ["<h2>Forces periodic in position</h2>", f"<p>{esc(per['words'])}</p>",
             table(["period mm", "reference's mm", "amplitude per direction N: reference -> this (change ± u)",
                    "floor N", "status", "where along the travel", "order"], rows)]
    if per.get("profile"):
        parts.append(img(figure_periodic_profile(per["profile"])))
    return parts


def coverage_paragraph(floor: dict) -> str:
    """What the floors cover (diagnosis.json ``floor.coverage``): a repeatability, a reproducibility or stated."""
    cov = floor.get("coverage")
    if not cov:
        return ""
    return (f"<p><b>What the floors cover: {esc(cov['kind'])}.</b> {esc(cov['words'][:1].upper() + cov['words'][1:])}."
            "</p>")


def witness_parts(w: dict | None) -> list:
    """The tracking error as a second witness (diagnosis.json ``witness``): its lag and jitter against the
    reference's, the rule that applied."""
    if not w:
        return []
    parts = ["<h2>Second witness: the tracking error</h2>", f"<p>{esc(w['words'])}</p>"]
    if w.get("compared"):
        g = lambda x, k=1.0: "—" if x is None else f"{k * x:.4g}"  # noqa: E731
        rows = [(c["parameter"], "um" if c["unit"] == "m" else "mm", g(c["reference_m"], 1e6 if c["unit"] == "m"
                                                                       else 1e3),
                 g(c["value_m"], 1e6 if c["unit"] == "m" else 1e3),
                 (f"{g(c['change'], 1e6)} ± {g(c['uncertainty'], 1e6)} um" if c["unit"] == "m" else
                  f"{g(c['change'], 100)} ± {g(c['uncertainty'], 100)} %"),
                 g(c["z"]), g(c["floor"], 1e6) + " um" if c["unit"] == "m" else g(c["floor"], 100) + " %",
                 "named" if c["named"] else ("under its floor" if c["supported"] else "not supported"))
                for c in w["changes"]]
        parts.append(table(["statistic", "unit", "reference", "this recording", "change ± u", "z", "floor",
                            "status"], rows))
        parts.append(f"<p>Steady samples only (moving, the catch-up after each set-point step masked): "
                     f"{w['recording']['strokes']} strokes here, {w['reference']['strokes']} in the reference; "
                     f"jitter: the tracking error less its quadratic trend over {g(w.get('window_s'))} s.</p>")
    return parts
