"""The compiled BLFserv detector: state layout and numba kernels (used by :mod:`blf.serv.blfserv`).

Each channel's detector keeps an integer state row (``I_*``), a float state
row (``F_*``) and a ring buffer of raw D; the parameters shared by all
channels are one float vector (``P_*``); a finished event is one output row
(``O_*``). :func:`detect` runs the detector over a block of samples,
:func:`flush` closes the open events at the end of the data. The detection
and measurement rules are documented in :func:`blf.serv.blfserv.blf_serv`.

Pure: arrays in, arrays out (the state arrays passed in are updated in place).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["new_state", "params_vector", "detect", "flush"]

# ---------------------------------------------------------------- detector state layout
# integer state per channel
I_G = 0  # global index of the next sample
I_PHASE = 1  # 0 idle, 1 active (within the merge gap of the last |D''| excursion), 2 collecting the after-plateau
I_START = 2  # first sample of the event (first |D''| > thresh2)
I_LAST = 3  # last sample with |D''| > thresh2
I_TRIG = 4  # both derivatives were outside the zone at one sample (the paper's detection)
I_SEG = 5  # a paper segment (both outside) is open
I_PREV = 6  # last sample of the previous event (its after-plateau may not be re-used before)
I_N = 7
# float state per channel
F_SEG_D0 = 0  # filtered D (relative) at the start of the open paper segment
F_PAPER = 1  # signed paper Delta D of largest magnitude within the event
F_S0 = 2  # centroid weights sum
F_S1 = 3  # centroid first moment (samples after the event start)
F_DF = 4  # filtered D relative to its first sample, rebuilt from dD/dt (see detect)
F_LAST_D1 = 5  # dD/dt of the previous sample
F_TH1 = 6  # threshold of dD/dt, mm/s
F_TH2 = 7  # threshold of d2D/dt2, mm/s^2
F_N = 8
# parameters (one float vector for all channels)
P_DELAY, P_GPRE, P_GPOST, P_W, P_MERGE, P_MAXLEN, P_B0, P_A1 = range(8)
P_N = 8
# output row layout of a finished event
(O_CH, O_START, O_LAST, O_TC, O_HEIGHT, O_SIGF, O_PAPER, O_NPRE, O_NPOST, O_RPRE, O_RPOST,
 O_STATUS) = range(12)
O_N = 12
ST_OK, ST_TOO_LONG = 0, 3

NO_PREV = -(1 << 40)


@njit(cache=True)
def _fit_level(ring, c, a, b, tc):
    """Straight line through ring samples a..b-1 (global indices), value at tc.

    Returns (level, variance factor of the level per unit noise variance, n, rms residual).
    """
    H = ring.shape[1]
    n = b - a
    if n < 3:
        return np.nan, np.nan, max(n, 0), np.nan
    xm = 0.0
    ym = 0.0
    for j in range(a, b):
        xm += j - tc
        ym += ring[c, j % H]
    xm /= n
    ym /= n
    sxx = 0.0
    sxy = 0.0
    for j in range(a, b):
        x = j - tc - xm
        sxx += x * x
        sxy += x * (ring[c, j % H] - ym)
    slope = sxy / sxx
    level = ym - slope * xm
    rss = 0.0
    for j in range(a, b):
        r = ring[c, j % H] - (ym + slope * (j - tc - xm))
        rss += r * r
    return level, 1.0 / n + xm * xm / sxx, n, math.sqrt(rss / (n - 2)) if n > 2 else np.nan


@njit(cache=True)
def _finalize(ring, ist, fst, c, q1, gnow, gpre, gpost, w, delay, status, out, nout):
    """Close the event of channel c: plateau fits, one output row; back to idle."""
    H = ring.shape[1]
    start = ist[c, I_START]
    last = ist[c, I_LAST]
    if ist[c, I_TRIG] == 1 and nout < out.shape[0]:
        tc = start + fst[c, F_S1] / fst[c, F_S0] - delay if fst[c, F_S0] > 0.0 else 0.5 * (start + last) - delay
        oldest = max(gnow - H + 1, 0)
        p1 = start - gpre
        p0 = max(p1 - w, ist[c, I_PREV] + gpost + 1, oldest)
        q0 = last + gpost + 1
        q1 = min(q1, gnow + 1)
        lv0, vf0, n0, r0 = _fit_level(ring, c, p0, p1, tc)
        lv1, vf1, n1, r1 = _fit_level(ring, c, q0, q1, tc)
        o = out[nout]
        o[O_CH] = c
        o[O_START] = start
        o[O_LAST] = last
        o[O_TC] = tc
        o[O_HEIGHT] = lv1 - lv0
        o[O_SIGF] = math.sqrt(vf0 + vf1)
        o[O_PAPER] = fst[c, F_PAPER]
        o[O_NPRE] = n0
        o[O_NPOST] = n1
        o[O_RPRE] = r0
        o[O_RPOST] = r1
        o[O_STATUS] = status
        nout += 1
    ist[c, I_PREV] = last
    ist[c, I_PHASE] = 0
    ist[c, I_SEG] = 0
    return nout


@njit(cache=True)
def _start_event(ist, fst, c, g):
    ist[c, I_PHASE] = 1
    ist[c, I_START] = g
    ist[c, I_LAST] = g
    ist[c, I_TRIG] = 0
    ist[c, I_SEG] = 0
    fst[c, F_PAPER] = 0.0
    fst[c, F_S0] = 0.0
    fst[c, F_S1] = 0.0


@njit(cache=True)
def detect(d, d1, d2, ring, ist, fst, par, out):
    """Run the detector over samples d[c, :] (raw D), d1 (dD/dt), d2 (d2D/dt2) of every channel c.

    The filtered D is not an input: the DT1 filter with numerator ``b0 (1 - z^-1)``
    and denominator ``1 + a1 z^-1`` is inverted sample by sample,
    ``Df[i] - Df[i-1] = (d1[i] + a1 d1[i-1]) / b0``, which is all the paper's
    Delta D needs (a difference of Df; rounding error ~1e-16 mm per sample). Returns the
    number of rows written to out.
    """
    H = ring.shape[1]
    k, m = d.shape
    delay = par[P_DELAY]
    gpre = int(par[P_GPRE])
    gpost = int(par[P_GPOST])
    w = int(par[P_W])
    merge = int(par[P_MERGE])
    maxlen = int(par[P_MAXLEN])
    inv_b0 = 1.0 / par[P_B0]
    a1c = par[P_A1]
    nout = 0
    for c in range(k):
        t1 = fst[c, F_TH1]
        t2 = fst[c, F_TH2]
        dfr = fst[c, F_DF]
        prev1 = fst[c, F_LAST_D1]
        g = ist[c, I_G]
        pos = g % H
        for j in range(m):
            ring[c, pos] = d[c, j]
            pos += 1
            if pos == H:
                pos = 0
            x1 = d1[c, j]
            dfr += (x1 + a1c * prev1) * inv_b0
            prev1 = x1
            a1 = abs(x1)
            o1 = a1 > t1
            o2 = abs(d2[c, j]) > t2
            ph = ist[c, I_PHASE]
            if o2:
                if ph == 0:
                    _start_event(ist, fst, c, g)
                elif ph == 2:
                    # a new excursion after the merge gap: close the previous event, its
                    # after-plateau cut short before this one's guard
                    nout = _finalize(ring, ist, fst, c, g - gpre, g, gpre, gpost, w, delay, ST_OK, out, nout)
                    _start_event(ist, fst, c, g)
                else:
                    ist[c, I_LAST] = g
            elif ph != 0:
                if ph == 1 and g - ist[c, I_LAST] > merge:
                    if ist[c, I_TRIG] == 1:
                        ist[c, I_PHASE] = 2
                    else:
                        ist[c, I_PREV] = ist[c, I_LAST]
                        ist[c, I_PHASE] = 0
                        ist[c, I_SEG] = 0
                if ist[c, I_PHASE] == 2 and g >= ist[c, I_LAST] + gpost + w:
                    nout = _finalize(ring, ist, fst, c, ist[c, I_LAST] + gpost + 1 + w, g, gpre, gpost, w,
                                     delay, ST_OK, out, nout)
            ph = ist[c, I_PHASE]
            if ph != 0:
                if ph == 1:
                    if o1 and o2:
                        ist[c, I_TRIG] = 1
                        if ist[c, I_SEG] == 0:
                            ist[c, I_SEG] = 1
                            fst[c, F_SEG_D0] = dfr
                    elif ist[c, I_SEG] == 1:
                        delta = dfr - fst[c, F_SEG_D0]
                        if abs(delta) > abs(fst[c, F_PAPER]):
                            fst[c, F_PAPER] = delta
                        ist[c, I_SEG] = 0
                if g <= ist[c, I_LAST] + gpost:
                    wgt = a1 - t1
                    if wgt > 0.0:
                        fst[c, F_S0] += wgt
                        fst[c, F_S1] += wgt * (g - ist[c, I_START])
                if ph == 1 and g - ist[c, I_START] >= maxlen:
                    if ist[c, I_SEG] == 1:
                        delta = dfr - fst[c, F_SEG_D0]
                        if abs(delta) > abs(fst[c, F_PAPER]):
                            fst[c, F_PAPER] = delta
                    nout = _finalize(ring, ist, fst, c, g + 1, g, gpre, gpost, w, delay, ST_TOO_LONG, out, nout)
                    ist[c, I_PREV] = g
            g += 1
            ist[c, I_G] = g
        fst[c, F_DF] = dfr
        fst[c, F_LAST_D1] = prev1
    return nout


@njit(cache=True)
def flush(ring, ist, fst, par, out):
    """End of data: close every open event with what is there (changes the state passed in)."""
    delay = par[P_DELAY]
    gpre = int(par[P_GPRE])
    gpost = int(par[P_GPOST])
    w = int(par[P_W])
    nout = 0
    for c in range(ist.shape[0]):
        if ist[c, I_PHASE] == 0:
            continue
        gnow = ist[c, I_G] - 1
        if ist[c, I_SEG] == 1:
            delta = fst[c, F_DF] - fst[c, F_SEG_D0]
            if abs(delta) > abs(fst[c, F_PAPER]):
                fst[c, F_PAPER] = delta
        nout = _finalize(ring, ist, fst, c, ist[c, I_LAST] + gpost + 1 + w, gnow, gpre, gpost, w, delay,
                         ST_OK, out, nout)
    return nout


def new_state(k: int, ring_len: int, threshold_d1: np.ndarray, threshold_d2: np.ndarray):
    """Fresh detector state of ``k`` channels: (ring buffer, integer state, float state)."""
    ring = np.zeros((k, ring_len))
    ist = np.zeros((k, I_N), dtype=np.int64)
    ist[:, I_PREV] = NO_PREV
    fst = np.zeros((k, F_N))
    fst[:, F_TH1] = threshold_d1
    fst[:, F_TH2] = threshold_d2
    return ring, ist, fst


def params_vector(delay_samples: float, guard_before: int, guard_after: int, plateau: int, merge_gap: int,
                  max_len: int, dt1_b0: float, dt1_a1: float) -> np.ndarray:
    """The parameter vector of :func:`detect` (lengths in samples; DT1 coefficients b0, a1)."""
    par = np.zeros(P_N)
    par[P_DELAY] = delay_samples
    par[P_GPRE] = guard_before
    par[P_GPOST] = guard_after
    par[P_W] = plateau
    par[P_MERGE] = merge_gap
    par[P_MAXLEN] = max_len
    par[P_B0] = dt1_b0
    par[P_A1] = dt1_a1
    return par
