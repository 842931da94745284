"""``emacheck diagnose``: simulation versus recording (IO shell around :mod:`blf.diagnose`).

Loads a run folder, a signals CSV (dual-EMA) or a .mat/CSV single-axis
recording, builds the replay model, runs the diagnosis, prints the answer and
writes ``diagnosis.json`` and ``diagnosis_report.html``.
"""

from __future__ import annotations

import argparse
import base64
import io
import time
from pathlib import Path

import numpy as np

from hil.errors import RecordingError

__all__ = ["cmd_diagnose", "load_model", "diagnosis_dict"]


def _load_dual(path: Path, profile: Path | None):
    from hil.commands import actuation_for, load_recording, read_meta
    from sim.replay import DualEmaReplay

    run_dir = path if path.is_dir() else None
    sig_path = path / "signals.csv" if run_dir else path
    if run_dir and not sig_path.exists() and (path / "can.log").exists():
        sig_path = path / "can.log"
    meta = read_meta(run_dir)
    act = actuation_for(profile, meta)
    sig = load_recording(sig_path, act, meta)
    period = float(np.median(np.diff(sig.t)))
    model = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2,
                          act.mechanics.i_total_rad_per_mm, period, sig.mode1, sig.sp1, sig.mode2, sig.sp2)
    return model, period


def _load_single(path: Path):
    from sim.single_axis import SingleAxisReplay
    if path.suffix.lower() == ".mat":
        from scipy.io import loadmat
        try:
            d = loadmat(path)
        except (OSError, ValueError) as exc:
            raise RecordingError(f"{path}: not a readable .mat file ({exc})") from None
        missing = [k for k in ("t", "qm", "qg", "vir", "gtau") if k not in d]
        if missing:
            raise RecordingError(f"{path}: missing key(s) {', '.join(missing)}; expected t, qm, qg, vir, gtau")
        t = d["t"].ravel()
        force = float(np.ravel(d["gtau"])[0]) * d["vir"].ravel()
        q, qref = d["qm"].ravel(), d["qg"].ravel()
    else:
        try:
            arr = np.genfromtxt(path, delimiter=",", names=True)
        except (OSError, ValueError) as exc:
            raise RecordingError(f"{path}: not a readable CSV ({exc})") from None
        need = ("t", "q", "q_ref", "force")
        if arr.dtype.names is None or any(c not in arr.dtype.names for c in need):
            raise RecordingError(f"{path}: line 1: need columns t,q,q_ref,force (s, m, m, N)")
        t, q, qref, force = (arr[c] for c in need)
    period = float(np.median(np.diff(t)))
    return SingleAxisReplay(t, q, qref, force, period), period


def load_model(path: Path, model: str, profile: Path | None):
    """Replay model and sample period of a recording (run folder, CSV, .mat)."""
    if not path.exists():
        raise RecordingError(f"{path}: no such file or folder")
    return _load_single(path) if model == "single-axis" else _load_dual(path, profile)


def _r(x, nd=6):
    return None if x is None else float(f"{x:.{nd}g}")


def diagnosis_dict(d, model_name: str, seconds: float) -> dict:
    """JSON shape of issue 6."""
    eff = lambda e: {"name": e.name, "where": e.where, "words": e.words,  # noqa: E731
                     "parameters": {k: _r(v) for k, v in e.parameters.items()},
                     "uncertainty": {k: _r(v) for k, v in e.uncertainty.items()},
                     "delta_bic": _r(e.delta_bic), "delta_chi2_holdout": _r(e.delta_chi2_holdout),
                     "evidence": e.evidence}
    return {
        "verdict": d.verdict, "model": model_name,
        "effects": [eff(e) for e in d.effects],
        "partial_effects": [eff(e) for e in d.partial_effects],
        "locations": [{"channel": l.channel, "t_start_s": _r(l.t_start_s), "t_end_s": _r(l.t_end_s),
                       "regime": l.regime, "score": _r(l.score), "test": l.test} for l in d.locations],
        "residual_rms_before": {k: _r(v) for k, v in d.residual_rms_before.items()},
        "residual_rms_after": {k: _r(v) for k, v in d.residual_rms_after.items()},
        "residual_rms_holdout_before": {k: _r(v) for k, v in d.residual_rms_holdout_before.items()},
        "residual_rms_holdout_after": {k: _r(v) for k, v in d.residual_rms_holdout_after.items()},
        "noise_floor": {k: _r(v) for k, v in d.noise_floor.items()},
        "excess_before": {k: _r(v) for k, v in d.excess_before.items()},
        "excess_after": {k: _r(v) for k, v in d.excess_after.items()},
        "regime_score_before": {k: _r(v) for k, v in d.regime_before.items()},
        "regime_score_after": {k: _r(v) for k, v in d.regime_after.items()},
        "ic": "BIC", "ic_before": _r(d.ic_before, 9), "ic_after": _r(d.ic_after, 9),
        "nominal": {k: _r(v) for k, v in d.nominal.items()},
        "screening": list(d.screening),
        "diagnosis_s": round(seconds, 2),
    }


def _figure(model, d, channel: str) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t = model.t_s
    ok = d.valid[channel]
    stride = max(1, t.size // 6000)
    fig, ax = plt.subplots(2, 1, figsize=(9, 4.5), sharex=True)
    m = d.measured[channel]
    ax[0].plot(t[ok][::stride], m[ok][::stride], ".", ms=1, color="0.6", label="recording")
    ax[0].plot(t[ok][::stride], d.predicted_before[channel][ok][::stride], lw=0.8, label="nominal model")
    ax[0].plot(t[ok][::stride], d.predicted_after[channel][ok][::stride], lw=0.8, label="with fitted effects")
    ax[0].legend(fontsize=7)
    unit = "N" if channel.startswith("F") or channel == "force" else ("m" if channel in ("q", "q_ref") else "mm")
    ax[0].set_ylabel(f"{channel} [{unit}]")
    from scipy.ndimage import uniform_filter1d
    w = max(1, int(0.5 / np.median(np.diff(t))))
    for pred, lab in ((d.predicted_before, "residual before"), (d.predicted_after, "residual after")):
        r = np.where(ok, m - pred[channel], np.nan)
        rs = uniform_filter1d(np.nan_to_num(r), w) 
        ax[1].plot(t[ok][::stride], rs[ok][::stride], lw=0.8, label=lab + " (0.5 s mean)")
    ax[1].set_ylabel(f"residual [{unit}]")
    for loc in d.locations:
        if loc.channel == channel and loc.test == "window":  # a regime cell spans many visits
            ax[1].axvspan(loc.t_start_s, loc.t_end_s, color="red", alpha=0.1)
    # held-out blocks (never fitted): grey
    ho = np.asarray(d.held_out, dtype=bool)
    if ho.size == t.size and ho.any():
        edges = np.flatnonzero(np.diff(np.r_[0, ho.astype(np.int8), 0]))
        for k, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
            ax[1].axvspan(t[a], t[b - 1], color="0.5", alpha=0.12, lw=0,
                          label="held out (not fitted)" if k == 0 else None)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_xlabel("t [s]")
    ax[1].legend(fontsize=7)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _regime_figure(d, channel: str) -> str:
    """Regime cells of one channel: cell score on the fit half against the held-out half,
    before and after the fitted effects (a mismatch tied to the regime lies on the diagonal)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5))
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
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def write_report(path: Path, model, d, data: dict) -> None:
    """Self-contained HTML report: verdict, effects, table before/after, overlay and residual plots."""
    import html
    rows = "".join(
        f"<tr><td>{c}</td><td>{data['residual_rms_before'][c]}</td><td>{data['residual_rms_after'][c]}</td>"
        f"<td>{data['residual_rms_holdout_before'][c]}</td><td>{data['residual_rms_holdout_after'][c]}</td>"
        f"<td>{data['noise_floor'][c]}</td><td>{data['excess_before'][c]}</td><td>{data['excess_after'][c]}</td>"
        f"<td>{data['regime_score_before'][c]}</td><td>{data['regime_score_after'][c]}</td></tr>"
        for c in d.measured if d.valid[c].any())
    effs = "".join(
        f"<li><b>{html.escape(e['words'])}</b> (<code>{e['name']}</code> at {e['where']}): "
        + ", ".join(f"{k} = {v} ± {e['uncertainty'][k]}" for k, v in e["parameters"].items())
        + f"<br><small>{html.escape(e['evidence'])}</small></li>"
        for e in data["effects"] + data["partial_effects"])
    locs = "".join(f"<li>{l['channel']}: {l['t_start_s']}–{l['t_end_s']} s ({l['test']} test), "
                   f"{html.escape(l['regime'])}</li>"
                   for l in data["locations"][:12])
    figs = "".join(f"<h3>{c}</h3><img src='{_figure(model, d, c)}'>" for c in d.measured if d.valid[c].any())
    from blf.diagnose import DiagnoseConfig
    thr = DiagnoseConfig().regime_threshold
    flagged = [c for c in model.channels if max(d.regime_before.get(c, 0.0), d.regime_after.get(c, 0.0)) > thr]
    if flagged and d.regime_labels:
        figs += ("<h2>Regime test</h2><p>Each point is a regime cell (stroke position x sign of velocity x "
                 "sign of force); a mismatch tied to the operating regime repeats in both halves and lies "
                 "on the diagonal, noise scatters around the origin.</p>"
                 + "".join(f"<img src='{_regime_figure(d, c)}'>" for c in flagged))
    path.write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>emacheck diagnose</title></head><body>"
        f"<h1>Simulation versus recording: {data['verdict']}</h1>"
        f"<p>BIC before {data['ic_before']}, after {data['ic_after']}.</p>"
        f"<h2>Effects</h2><ul>{effs or '<li>none</li>'}</ul><h2>Where</h2><ul>{locs or '<li>nowhere</li>'}</ul>"
        "<h2>Residual RMS</h2><table border=1><tr><th>channel</th><th>before</th><th>after</th>"
        "<th>held-out before</th><th>held-out after</th>"
        f"<th>noise floor</th><th>excess before</th><th>excess after</th>"
        f"<th>regime score before</th><th>regime score after</th></tr>{rows}</table>"
        f"<h2>Overlay and residuals</h2>{figs}</body></html>")


def cmd_diagnose(args: argparse.Namespace) -> int:
    """``emacheck diagnose RECORDING [--profile] [--out] [--model]``."""
    from rich.console import Console

    from blf.diagnose import diagnose
    from hil.runfolder import write_json_atomic
    console = Console()
    path = Path(args.recording)
    model, period = load_model(path, args.model, args.profile)
    out = args.out or (path if path.is_dir() else path.parent)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    d = diagnose(model, period, progress=None if args.quiet else (lambda s: console.print(f"  {s}")))
    secs = time.perf_counter() - t0
    data = diagnosis_dict(d, args.model, secs)
    write_json_atomic(out / "diagnosis.json", data)
    if not args.no_report:
        write_report(out / "diagnosis_report.html", model, d, data)
    words = {"no_mismatch": "no significant mismatch between simulation and recording",
             "explained": "mismatch explained", "unexplained": "mismatch NOT explained by the candidate library"}
    console.print(f"[bold]{words[d.verdict]}[/bold] ({secs:.1f} s)")
    for e in data["effects"] + data["partial_effects"]:
        tag = "" if d.verdict == "explained" else " (partial)"
        console.print(f"  {e['words']}{tag}: " + ", ".join(
            f"{k} = {v} ± {e['uncertainty'][k]}" for k, v in e["parameters"].items()))
    for l in data["locations"][:6]:
        console.print(f"  where: {l['channel']} {l['t_start_s']}-{l['t_end_s']} s ({l['test']} test), {l['regime']}")
    console.print("  residual RMS before -> after: " + ", ".join(
        f"{c} {data['residual_rms_before'][c]} -> {data['residual_rms_after'][c]}"
        for c in d.measured if d.valid[c].any()))
    console.print("  on the held-out half (never fitted): " + ", ".join(
        f"{c} {data['residual_rms_holdout_before'][c]} -> {data['residual_rms_holdout_after'][c]}"
        for c in d.measured if d.valid[c].any()))
    console.print(f"  BIC {data['ic_before']} -> {data['ic_after']}; written {out / 'diagnosis.json'}")
    return 0
