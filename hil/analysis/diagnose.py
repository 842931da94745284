"""Simulation versus recording: a recording as a replay model, and diagnosis.json (for ``emacheck diagnose``).

A run folder, a signals CSV or a CAN log becomes the dual-EMA replay
(:class:`sim.replay.DualEmaReplay`); a ``.mat`` or ``t,q,q_ref,force`` CSV of
one positioning axis becomes :class:`sim.single_axis.SingleAxisReplay`. The
diagnosis itself is :func:`blf.diagnose.diagnose` (pure).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.errors import RecordingError


def _load_dual(path: Path, profile: Path | None):
    from hil.cli.common import actuation_for, load_recording, read_meta
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
