"""Mismatch tests of the diagnosis: noise floor, window test and regime test (:mod:`blf.diagnose.engine`).

Given the residual ``r`` of a model against a recording, in the units of the
channel:

* :func:`noise_floor`: the per-sample noise level from second differences,
  :math:`\\sigma = \\mathrm{rms}(\\Delta^2 r)/\\sqrt 6` over a rolling window,
  so residuals can be weighted, :math:`w = r/\\sigma` (dimensionless);
* :func:`window_scores` and :func:`excess`: the window test,
  :math:`z_b = \\sum_{i \\in b} w_i/\\sqrt{n_b}` per window and their mean
  square (1 under noise only);
* :func:`regime_cells`, :func:`regime_score`: the regime test, cells of the
  operating regime and the cross-validated score S of a residual repeated in
  them (about standard normal under noise only);
* :func:`regime_words`: which regime variable a located window's residual
  concentrates in, in words.

Pure: arrays in, arrays or a frozen dataclass out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

__all__ = ["noise_floor", "window_scores", "excess", "regime_words", "regime_cells", "RegimeScore",
           "regime_score"]


def noise_floor(r: np.ndarray, valid: np.ndarray, win: int) -> np.ndarray:
    """Per-sample noise sigma from second differences of consecutive valid samples.

    A channel valid only every ``step`` samples (block means) is handled on
    its own grid: second differences are taken between valid samples spaced
    ``step`` apart (not across gaps) and the rolling window shrinks by ``step``.
    """
    n = r.size
    idx = np.flatnonzero(valid)
    if idx.size < 5:
        return np.ones(n)
    gaps = np.diff(idx)
    step = int(np.median(gaps))
    rv = r[idx]
    d2 = np.zeros(idx.size)
    d2[1:-1] = rv[2:] - 2.0 * rv[1:-1] + rv[:-2]
    ok = np.zeros(idx.size, bool)
    ok[1:-1] = (gaps[1:] == step) & (gaps[:-1] == step)
    w = max(31, win // step) if step > 1 else win  # a sparse channel needs more values per estimate
    num = uniform_filter1d(np.where(ok, d2 * d2, 0.0), w, mode="nearest")
    den = uniform_filter1d(ok.astype(float), w, mode="nearest")
    sv = np.sqrt(np.maximum(num, 0.0) / np.maximum(den, 1e-12) / 6.0)
    glob = float(np.median(sv[ok])) if ok.any() else 1.0
    sv = np.maximum(sv, 0.5 * glob) if glob > 0 else np.maximum(sv, 1e-12)
    sig = np.full(n, glob if glob > 0 else 1.0)
    sig[idx] = sv
    return sig


def window_scores(w: np.ndarray, valid: np.ndarray, nwin: int) -> tuple[np.ndarray, np.ndarray]:
    n = w.size
    m = n // nwin
    ww = np.where(valid, w, 0.0)[: m * nwin].reshape(m, nwin)
    cnt = valid[: m * nwin].reshape(m, nwin).sum(1)
    z = np.where(cnt >= 5, ww.sum(1) / np.sqrt(np.maximum(cnt, 1)), np.nan)
    return z, np.arange(m) * nwin


def excess(z: np.ndarray) -> float:
    z = z[np.isfinite(z)]
    return float(np.mean(z * z)) if z.size else 0.0


def regime_words(idx: np.ndarray, r: np.ndarray, regimes: dict) -> str:
    """Name the regime variable whose bins concentrate the residual inside ``idx``."""
    best, best_score = "whole window", 0.0
    for name, x in regimes.items():
        xs = x[idx]
        if not np.all(np.isfinite(xs)) or np.ptp(xs) == 0:
            continue
        for lab, sel in ((f"{name} > 0", xs > 0), (f"{name} < 0", xs < 0)):
            if sel.sum() < 10 or (~sel).sum() < 10:
                continue
            a, b = r[idx][sel], r[idx][~sel]
            score = abs(a.mean() - b.mean()) / (np.std(r[idx]) / np.sqrt(min(sel.sum(), (~sel).sum())) + 1e-30)
            if score > best_score:
                best, best_score = f"{lab} (mean residual {a.mean():+.3g} vs {b.mean():+.3g} elsewhere)", score
    return best


def regime_cells(regimes: dict, nbins: int) -> tuple[np.ndarray, list]:
    """Cell index per sample: position bin (quantiles) x sign of velocity x sign of force.

    Uses the regime variables ``"position along the stroke"``, ``"velocity"``
    and the first ``"force ..."`` one that are present; returns the cell of
    every sample and a description of each cell.
    """
    pos = regimes.get("position along the stroke")
    if pos is None:
        return np.full(next(iter(regimes.values())).size, -1), []
    edges = np.unique(np.round(np.quantile(pos, np.linspace(0.0, 1.0, nbins + 1)), 9))
    if edges.size < 2:
        edges = np.array([edges[0] - 1.0, edges[0] + 1.0])
    nbins = edges.size - 1  # a stroke position held for long (the force fight) fills several quantiles
    cell = np.clip(np.searchsorted(edges[1:-1], pos, side="right"), 0, nbins - 1)
    labels = [f"position along the stroke {edges[b]:+.3g}..{edges[b + 1]:+.3g}" for b in range(nbins)]
    frc = next((k for k in regimes if k.startswith("force") and "rate" not in k), None)
    for key in ("velocity", frc):
        if key is None or key not in regimes:
            continue
        cell = 2 * cell + (regimes[key] > 0)
        labels = [f"{lab}, {key} {sgn} 0" for lab in labels for sgn in ("<=", ">")]
    return cell, labels


@dataclass(frozen=True)
class RegimeScore:
    """Result of :func:`regime_score`: the score S and the cell scores of each half
    (NaN where a cell has too few valid samples in either half)."""

    score: float
    z_fit: np.ndarray
    z_held: np.ndarray

    @property
    def products(self) -> np.ndarray:
        return self.z_fit * self.z_held


def regime_score(w: np.ndarray, valid: np.ndarray, fit: np.ndarray, block: np.ndarray,
                 cell: np.ndarray, ncell: int) -> RegimeScore:
    """Cross-validated regime statistic of a weighted residual (see :func:`blf.diagnose.engine.diagnose`, step 3).

    Parameters
    ----------
    w : ndarray, shape (n,)
        Residual over its noise floor (dimensionless).
    valid : ndarray of bool, shape (n,)
    fit : ndarray of bool, shape (n,)
        True on the fit half, False on the held-out half.
    block : ndarray of int, shape (n,)
        Block index of each sample (the alternating blocks of the halves).
    cell : ndarray of int, shape (n,)
        Regime cell of each sample, -1 for none.
    ncell : int

    Returns
    -------
    RegimeScore

    Notes
    -----
    :math:`z_{f,b} = \\sum_{i \\in b, fit} w_i / \\sqrt{\\phi n_{f,b}}`, likewise
    :math:`z_{h,b}` on the held-out half, and
    :math:`S = \\sum_b z_{f,b} z_{h,b} / \\sqrt{B}` over the B cells with at least
    20 valid samples in each half (5 for a channel valid only on a coarser grid).
    :math:`\\phi` is the pooled variance of the per-block cell sums around their
    cell mean, per sample: 1 for white noise of unit variance, more for correlated
    noise, and not raised by a mismatch that repeats within the cell.
    """
    nan = np.full(ncell, np.nan)
    sel = valid & (cell >= 0)
    if np.count_nonzero(sel) < 10 or ncell == 0:
        return RegimeScore(0.0, nan, nan.copy())
    min_n = 20 if int(np.median(np.diff(np.flatnonzero(sel)))) == 1 else 5
    key = 2 * cell[sel] + fit[sel].astype(int)  # cell x half
    piece = key.astype(np.int64) * (int(block.max()) + 1) + block[sel]
    upiece, inv = np.unique(piece, return_inverse=True)
    s_p = np.bincount(inv, w[sel])
    n_p = np.bincount(inv).astype(float)
    k_p = upiece // (int(block.max()) + 1)
    s_k = np.bincount(key, w[sel], minlength=2 * ncell)
    n_k = np.bincount(key, minlength=2 * ncell).astype(float)
    mu = np.where(n_k > 0, s_k / np.maximum(n_k, 1.0), 0.0)
    dof = upiece.size - int(np.count_nonzero(n_k))
    # over-dispersion of piece sums around their cell-half mean: correlated noise and
    # imperfect weights widen it, a mismatch that repeats in the cell does not
    phi = float(np.sum((s_p - mu[k_p] * n_p) ** 2 / n_p) / dof) if dof >= 10 else 1.0
    n_h, n_f = n_k[0::2], n_k[1::2]
    ok = (n_h >= min_n) & (n_f >= min_n)
    zf, zh = nan.copy(), nan.copy()
    zf[ok] = s_k[1::2][ok] / np.sqrt(phi * n_f[ok])
    zh[ok] = s_k[0::2][ok] / np.sqrt(phi * n_h[ok])
    nb = int(ok.sum())
    return RegimeScore(float(np.nansum(zf * zh) / np.sqrt(nb)) if nb else 0.0, zf, zh)
