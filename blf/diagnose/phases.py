"""Phases of a check for the diagnosis: which drive holds force when, and what is not compared.

A replay driven by the measured motor angles models the load paths
quasi-statically. Two kinds of stretch are outside what it claims, and are
not compared (:func:`transients`):

* **slack load paths**: where a load path's force is within the load-cell
  noise of zero, the ram's place inside the play is set by forces below the
  load cell's resolution (ram friction and inertia, hinge drag), which a
  quasi-static chain does not carry; and the impact that ends a crossing
  rings. A path counts as slack where the 0.1 s mean of its force is within
  6 standard errors of zero, and the ``settle_s`` after it re-engages are
  not compared either;
* **mode changes**: a drive entering or leaving FORCE mode flies freely
  across its backlash and hits the far flank. With the modes recorded, the
  ``after_s`` following each change are skipped; without them the changes
  are found from the data with the same segmentation the maintenance
  analysis uses (:func:`blf.maint.segments.find_segments`): the ends of each
  calibration sweep and of the force fight, and the hand-over inside a sweep
  where both forces change sign (two sweeps run back to back).

Which EMA holds force (:func:`holding`): with recorded modes, the FORCE-mode
samples; without, the check's design: during the first calibration sweep
EMA 2 holds the opposing force while EMA 1 sweeps, during the second EMA 1
holds it; the target is the check profile's opposing force with the sign of
the holding EMA's mean force there.

Pure: arrays and an explicit sample period in, frozen dataclasses out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from blf.maint.segments import Segments, runs
from blf.validate import as_1d_finite, positive_scalar, same_shape

__all__ = ["Holding", "slack", "change_mask", "mode_changes", "segment_changes", "holding", "transients"]

_MEAN_S = 0.1  #: averaging time of the force for the slack test
_SLACK_SE = 6.0  #: slack: |mean force| within this many standard errors of zero
_SETTLE_FORCE_S = 0.3  #: a drive's first samples in FORCE mode (the flight across its play) are not compared
#: from the design: a held part ends before its last stretch whose force changes faster than this fraction of
#: the unload ramp's rate (|F_opp| / force_ramp_s), in means over _RATE_WINDOW_S on each side of a sample
#: (longer than a ramp's setpoint steps): a sweep's end found from the motion can lie inside the unload ramp
_RAMP_FRACTION = 0.25
_RATE_WINDOW_S = 0.2


@dataclass(frozen=True)
class Holding:
    """Where each EMA holds a force target (FORCE mode) and what the target is.

    Attributes
    ----------
    hold1, hold2 : ndarray of bool, shape (n,)
        Samples where EMA 1 / EMA 2 is in FORCE mode and settled.
    target1_N, target2_N : ndarray, shape (n,)
        Force target acting over the period ending at each sample, N (0 elsewhere).
    source : str
        ``"recorded modes"``, ``"check design"`` or ``"none"``.
    """

    hold1: np.ndarray
    hold2: np.ndarray
    target1_N: np.ndarray
    target2_N: np.ndarray
    source: str


def _noise_sigma(x: np.ndarray) -> float:
    """White-noise standard deviation of a signal from its second differences (robust median)."""
    if x.size < 5:
        return 0.0
    d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
    return float(1.4826 * np.median(np.abs(d2)) / np.sqrt(6.0))


def slack(f1_N, f2_N, sample_period_s: float) -> np.ndarray:
    """Samples where either load path is slack: its 0.1 s mean force within 6 standard errors of 0.

    Parameters
    ----------
    f1_N, f2_N : array_like, shape (n,)
        Load-cell forces, N.
    sample_period_s : float
        Sample period, s.

    Returns
    -------
    ndarray of bool, shape (n,)

    Notes
    -----
    With :math:`\\sigma_i` the load cell's white noise (second differences,
    median absolute deviation) and :math:`\\bar F_i` the centred mean over
    :math:`m` = 0.1 s of samples, slack where
    :math:`|\\bar F_i| < 6\\,\\sigma_i/\\sqrt m` for i = 1 or 2 [N]. Both
    paths share the surface, so where one is slack the surface (and with it
    the other ram's place in its play) is held only by the hinge.
    """
    f1 = as_1d_finite(f1_N, "f1_N", "N")
    f2 = as_1d_finite(f2_N, "f2_N", "N")
    same_shape((f1, "f1_N", "N"), (f2, "f2_N", "N"))
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    m = max(1, int(round(_MEAN_S / T)))
    out = np.zeros(f1.size, bool)
    for f in (f1, f2):
        thr = _SLACK_SE * max(_noise_sigma(f), 1e-9) / np.sqrt(m)
        out |= np.abs(uniform_filter1d(f, m, mode="nearest")) < thr
    return out


def change_mask(n: int, starts, sample_period_s: float, after_s: float, before_s: float = 0.0) -> np.ndarray:
    """True from ``before_s`` before to ``after_s`` after each sample index in ``starts``."""
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    out = np.zeros(n, bool)
    a, b = int(round(before_s / T)), int(round(after_s / T))
    for k in np.asarray(starts, dtype=np.int64):
        out[max(0, k - a):min(n, k + b + 1)] = True
    return out


def mode_changes(mode1, mode2) -> np.ndarray:
    """Sample indices where either recorded drive mode changes."""
    m1 = np.asarray(mode1, dtype=float)
    m2 = np.asarray(mode2, dtype=float)
    return np.flatnonzero((np.diff(m1) != 0) | (np.diff(m2) != 0)) + 1


def _hand_overs(f1: np.ndarray, f2: np.ndarray, a: int, b: int, T: float) -> list[int]:
    """Inside a sweep [a, b): where the two smoothed forces change sign together (a hand-over)."""
    m = max(1, int(round(0.2 / T)))
    g1 = np.sign(uniform_filter1d(f1[a:b], m, mode="nearest"))
    g2 = np.sign(uniform_filter1d(f2[a:b], m, mode="nearest"))
    flip = np.flatnonzero((g1[1:] != g1[:-1]) & (g1[1:] != 0))
    out = []
    for k in flip:
        lo, hi = max(0, k - m), min(b - a, k + m + 1)
        if np.any(g2[lo:hi] != g2[max(0, lo - 1)]) and (not out or k + a - out[-1] > int(round(1.0 / T))):
            out.append(int(k + a + 1))
    return out


def _sweep_parts(seg: Segments, f1: np.ndarray, f2: np.ndarray, T: float) -> list[tuple[int, int]]:
    """The calibration sweeps in time order, a merged pair split at its hand-over."""
    masks = [m for m in (seg.cal1, seg.cal2) if m is not None]
    spans: list[tuple[int, int]] = []
    for m in masks:
        for a, b in runs(m):
            if (a, b) not in spans:
                spans.append((int(a), int(b)))
    spans.sort()
    parts = []
    for a, b in spans:
        # a sign change within 1 s of a sweep's end is that phase change itself (the other drive
        # entering force mode), not a hand-over between two sweeps
        edge = int(round(1.0 / T))
        cuts = [a] + [k for k in _hand_overs(f1, f2, a, b, T) if k - a > edge and b - k > edge] + [b]
        parts += [(cuts[j], cuts[j + 1]) for j in range(len(cuts) - 1) if cuts[j + 1] - cuts[j] > 10]
    return parts


def segment_changes(seg: Segments, f1_N, f2_N, sample_period_s: float) -> np.ndarray:
    """Sample indices of the phase changes found in the data: each sweep part's and the force fight's ends."""
    f1 = as_1d_finite(f1_N, "f1_N", "N")
    f2 = as_1d_finite(f2_N, "f2_N", "N")
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    out = []
    for a, b in _sweep_parts(seg, f1, f2, T):
        out += [a, b]
    for a, b in runs(seg.force_fight):
        out += [int(a), int(b)]
    return np.unique(np.asarray(out, dtype=np.int64))


def _before_ramp(f: np.ndarray, T: float, rate_N_per_s: float) -> int:
    """Samples of a held part ``f`` before its trailing stretch changing faster than ``rate_N_per_s``."""
    w = max(1, int(round(_RATE_WINDOW_S / T)))
    if f.size <= 2 * w:
        return int(f.size)
    c = np.concatenate(([0.0], np.cumsum(f)))
    k = np.arange(w, f.size - w + 1)
    rate = np.abs((c[k + w] - c[k]) - (c[k] - c[k - w])) / (w * w * T)
    fast = rate > rate_N_per_s
    if not fast[-1]:
        return int(f.size)
    slow = np.flatnonzero(~fast)
    return int(k[slow[-1]]) - w if slow.size else 0


def holding(n: int, sample_period_s: float, *, mode1=None, sp1=None, mode2=None, sp2=None,
            segments: Segments | None = None, f1_N=None, f2_N=None,
            opposing_force_N: float | None = None, force_ramp_s: float = 0.0) -> Holding:
    """Where each EMA holds a force target, from the recorded modes or from the check's design.

    Parameters
    ----------
    n : int
        Samples in the recording.
    sample_period_s : float
        Sample period, s.
    mode1, sp1, mode2, sp2 : array_like, shape (n,), optional
        Recorded drive modes (CiA 402: 10 = cyclic torque, i.e. FORCE) and
        setpoints (N in FORCE mode). Used when all four are given.
    segments : Segments, optional
        The phases found by :func:`blf.maint.segments.find_segments` (used when
        the modes are not recorded).
    f1_N, f2_N : array_like, shape (n,), optional
        Load-cell forces, N (the sign of the held force, the hand-overs).
    opposing_force_N : float, optional
        The check profile's opposing force, N (its magnitude is the target).
    force_ramp_s : float, optional
        The check profile's ramp of the opposing force on and off, s: the
        last ``force_ramp_s`` of each sweep part are not held at the target
        (from the design only; recorded setpoints carry the ramp).

    Returns
    -------
    Holding

    Notes
    -----
    Recorded: the setpoint of sample k acts over the period ending at sample
    k + 1, so sample k holds ``sp[k-1]`` where ``mode[k-1]`` is FORCE (the mean
    of ``sp[k-1]`` and ``sp[k]`` where both are, centred on sample k); the
    first 0.3 s of each FORCE stretch are dropped (the flight across the
    play). From the design: the sweep parts of :func:`segment_changes` in
    time order alternate EMA 2, EMA 1 as the holding drive (a check
    calibrates EMA 1 first); the target is
    :math:`\\mathrm{sign}(\\bar F_h)\\,|F_{opp}|` [N] with :math:`\\bar F_h` the
    holding EMA's mean force over the part, less its first 0.3 s. A part
    ends before its trailing stretch in which the holding EMA's force changes
    faster than a quarter of the unload ramp's rate (|F_opp| /
    ``force_ramp_s``; the difference of 0.05 s means on either side of each
    sample): a sweep's end found from the motion may lie inside that ramp.
    """
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    hold = [np.zeros(n, bool), np.zeros(n, bool)]
    tgt = [np.zeros(n), np.zeros(n)]
    settle = int(round(_SETTLE_FORCE_S / T))
    if all(x is not None for x in (mode1, sp1, mode2, sp2)):
        for e, (mode, sp) in enumerate(((mode1, sp1), (mode2, sp2))):
            mode = np.asarray(mode, dtype=float)
            sp = np.asarray(sp, dtype=float)
            ok = np.zeros(n, bool)
            ok[1:] = mode[:-1] == 10
            tgt[e][1:] = np.where(ok[1:], sp[:-1], 0.0)
            # sample k lies between the periods of sp[k-1] and sp[k]: their mean where both hold force
            both = ok[1:-1] & (mode[1:-1] == 10)
            tgt[e][1:-1] = np.where(both, 0.5 * (sp[:-2] + sp[1:-1]), tgt[e][1:-1])
            for a, _b in runs(ok):
                ok[a:a + settle] = False
            hold[e] = ok
        return Holding(hold[0], hold[1], tgt[0], tgt[1], "recorded modes")
    if segments is None or f1_N is None or f2_N is None or opposing_force_N is None:
        return Holding(hold[0], hold[1], tgt[0], tgt[1], "none")
    f = (as_1d_finite(f1_N, "f1_N", "N"), as_1d_finite(f2_N, "f2_N", "N"))
    mag = abs(float(opposing_force_N))
    ramp = int(round(max(float(force_ramp_s), 0.0) / T))
    for j, (a, b) in enumerate(_sweep_parts(segments, f[0], f[1], T)):
        e = 1 if j % 2 == 0 else 0  # first sweep: EMA 2 holds while EMA 1 sweeps
        a2 = a + settle
        b = b - ramp
        if b - a2 < 10:
            continue
        if ramp > 0:
            b = a2 + _before_ramp(f[e][a2:b], T, _RAMP_FRACTION * mag / (ramp * T))
        if b - a2 < 10:
            continue
        sign = np.sign(np.mean(f[e][a2:b]))
        hold[e][a2:b] = True
        tgt[e][a2:b] = sign * mag
    return Holding(hold[0], hold[1], tgt[0], tgt[1], "check design")


def transients(f1_N, f2_N, sample_period_s: float, change_indices, *, settle_s: float = 0.3,
               after_s: float = 1.0) -> np.ndarray:
    """Samples not compared: slack load paths and their settling, and the time after each phase change.

    Parameters
    ----------
    f1_N, f2_N : array_like, shape (n,)
        Load-cell forces, N.
    sample_period_s : float
        Sample period, s.
    change_indices : array_like of int
        Phase changes (:func:`mode_changes` or :func:`segment_changes`).
    settle_s, after_s : float, optional
        Settling after a slack path re-engages and time skipped after a
        phase change, s (defaults 0.3 and 1.0).

    Returns
    -------
    ndarray of bool, shape (n,)
        True where s, F and the drive force are not compared.
    """
    f1 = as_1d_finite(f1_N, "f1_N", "N")
    T = positive_scalar(sample_period_s, "sample_period_s", "s")
    sl = slack(f1, f2_N, T)
    out = sl.copy()
    k = int(round(settle_s / T))
    for a, b in runs(sl):
        out[max(0, a - int(round(0.05 / T))):min(f1.size, b + k)] = True
    return out | change_mask(f1.size, change_indices, T, after_s)
