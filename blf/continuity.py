"""Jumps in a recording: time that stops, a position that teleports (pure; arrays in, a frozen result out).

A recording that is two recordings joined (or one with samples lost) is not one continuous motion:
the analyses take a step in time or in position for motion that did not happen (a file of one recording
joined 180 times gave a BLFserv reading at half its true value, and PASS). :func:`find_jumps` finds the
first such step by two rules, each checking a physical impossibility, never a statistical rarity of the
motion itself.

**Time.** Let :math:`T` be the median sample period. A sample ``i`` whose time step
:math:`t_i - t_{i-1} > G \\cdot T` with :math:`G` = :data:`GAP_PERIODS` (= 10) is a gap: samples are
missing for longer than a recording from elsewhere should leave out (up to 9 lost samples in a row). A
check's own recording may hold a longer gap where its master tolerated a stall (up to the derived
freshness limit, 40 ms: 21 periods at 2 ms); its caller passes that as ``gap_periods``
(:func:`hil.record.signals_csv.gap_periods_for`, from the run record). A time step :math:`\\le 0` (time that
stands or goes back) is a jump too.

**Position.** For a position channel ``x`` (a motor angle in rad, an LVDT stroke in mm) with a largest
plausible speed :math:`v_x` (in the channel's unit per second) and a sample noise :math:`\\sigma_x`, a
step between two consecutive samples is impossible when

.. math:: |x_i - x_{i-1}| > v_x \\, (t_i - t_{i-1}) + K \\sqrt{2} \\, \\sigma_x

with :math:`K` = :data:`NOISE_K` (= 10): the motion at its fastest plus ten standard deviations of the
difference of two independent noisy samples (a Gaussian false alarm of about 1e-23 per sample).
:math:`\\sigma_x` is estimated from the recording itself, robustly (a few jumps do not move it), from
its second differences: for motion smooth over three samples :math:`\\Delta^2 x` is noise with variance
:math:`6\\sigma^2`, so :math:`\\hat\\sigma = 1.4826\\,\\mathrm{median}|\\Delta^2 x| / \\sqrt{6}`.
The caller chooses :math:`v_x` (emacheck: twice the ram-speed hard cap, 2 x 50 mm/s = 100 mm/s, in
rad/s through the gear ratio for the motor angles).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from blf.validate import as_1d_finite, positive_scalar

#: a time step longer than this many median sample periods is a gap
GAP_PERIODS = 10.0
#: a position step beyond the fastest motion by more than this many noise standard deviations of a
#: difference of two samples is a jump
NOISE_K = 10.0
#: the normal distribution's standard deviation over its median absolute deviation
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class Jump:
    """The first step of a recording that its physics cannot make.

    Attributes
    ----------
    kind : str
        ``"time_backwards"`` (:math:`\\Delta t \\le 0`), ``"time_gap"`` (:math:`\\Delta t > G T`) or
        ``"position_step"``.
    index : int
        The sample after the step (0-based): the step is from sample ``index - 1`` to ``index``.
    channel : str
        ``"t"`` for a time jump, else the position channel's name.
    before, after : float
        The channel's values at samples ``index - 1`` and ``index`` (s, or the channel's unit).
    limit : float
        The largest step allowed there (s for a gap: :math:`G T`; the channel's unit for a position).
    """

    kind: str
    index: int
    channel: str
    before: float
    after: float
    limit: float


@dataclass(frozen=True)
class Continuity:
    """What :func:`find_jumps` found: the first jump (None: the recording is continuous) and the rule.

    Attributes
    ----------
    first : Jump or None
        The earliest jump over all channels, None when there is none.
    count : int
        How many steps break a rule (all channels together).
    sample_period_s : float
        The median sample period :math:`T` [s].
    gap_limit_s : float
        :math:`G T` [s].
    noise : dict
        :math:`\\hat\\sigma_x` per position channel (its unit).
    """

    first: Jump | None
    count: int
    sample_period_s: float
    gap_limit_s: float
    noise: dict[str, float]


#: samples handled at a time where a whole-length temporary is not needed (issue 34)
_BLOCK = 1 << 18


def _over_limit(x: np.ndarray, dt: np.ndarray, v: float, allowance: float) -> np.ndarray:
    """Indices k where ``|x[k+1] - x[k]| > |dt[k]| v + allowance``, formed block by block (the same
    operations per element as on whole arrays: no temporary the length of the recording)."""
    bad = []
    for a in range(0, dt.size, _BLOCK):
        b = min(a + _BLOCK, dt.size)
        limit = np.abs(dt[a:b])
        limit *= v
        limit += allowance
        step = np.diff(x[a:b + 1])
        np.abs(step, out=step)
        bad.append(np.flatnonzero(step > limit) + a)
    return np.concatenate(bad) if bad else np.zeros(0, np.int64)


def noise_std(x: np.ndarray) -> float:
    """The sample noise :math:`\\hat\\sigma` of ``x`` from its second differences (module docstring)."""
    if x.size < 3:
        return 0.0
    d2 = np.empty(x.size - 2)
    for a in range(0, d2.size, _BLOCK):  # block by block: one array the length of x, for 10-million-sample recordings
        b = min(a + _BLOCK, d2.size)
        d2[a:b] = np.diff(x[a:b + 2], 2)
    np.abs(d2, out=d2)
    return float(MAD_TO_SIGMA * np.median(d2, overwrite_input=True) / math.sqrt(6.0))


def find_jumps(t_s, positions: Mapping[str, np.ndarray], max_speed: Mapping[str, float], *,
               gap_periods: float = GAP_PERIODS, noise_k: float = NOISE_K, part_starts=()) -> Continuity:
    """Find the steps in time and position that a continuous recording cannot make (module docstring).

    Parameters
    ----------
    t_s : array_like
        Sample times [s], 1-D, at least 2 samples.
    positions : mapping of str to array_like
        Position channels (name -> values in the channel's unit), each as long as ``t_s``.
    max_speed : mapping of str to float
        The largest plausible speed of each channel in ``positions`` [its unit per s], > 0.
    gap_periods : float
        :math:`G`: a time step above this many median periods is a gap.
    noise_k : float
        :math:`K`: noise standard deviations of a two-sample difference allowed beyond the motion.
    part_starts : sequence of int, optional
        Samples that begin a part its recording declares separately made (a simulated recording whose
        calibration sweeps and scenario were simulated one after the other, each from its own start):
        the position step into such a sample is not judged (each part is checked on its own; time is
        judged everywhere). Default: none, the whole recording is one motion.

    Returns
    -------
    Continuity
        The first jump (or None), how many, and the thresholds used.
    """
    t = as_1d_finite(t_s, "t_s", "s", min_len=2)
    dt = np.diff(t)
    period = float(np.median(dt))
    gap = positive_scalar(gap_periods, "gap_periods", "sample periods") * max(period, 0.0)
    found: list[Jump] = []
    count = 0
    back = np.flatnonzero(dt <= 0)
    gaps = np.flatnonzero(dt > gap)
    count += back.size + gaps.size
    if back.size:
        k = int(back[0])
        found.append(Jump("time_backwards", k + 1, "t", float(t[k]), float(t[k + 1]), 0.0))
    if gaps.size:
        k = int(gaps[0])
        found.append(Jump("time_gap", k + 1, "t", float(t[k]), float(t[k + 1]), gap))
    noise: dict[str, float] = {}
    for name, values in positions.items():
        x = as_1d_finite(values, name, "its unit", min_len=t.size)
        if x.size != t.size:
            from blf.errors import InputError

            raise InputError(f"{name} must have as many samples as t_s ({t.size}); got {x.size}")
        v = positive_scalar(max_speed[name], f"max_speed[{name!r}]", "unit/s")
        sigma = noise_std(x)
        noise[name] = sigma
        bad = _over_limit(x, dt, v, noise_k * math.sqrt(2.0) * sigma)
        if len(part_starts):
            bad = np.setdiff1d(bad, np.asarray(part_starts, dtype=np.int64) - 1, assume_unique=True)
        count += bad.size
        if bad.size:
            k = int(bad[0])
            limit_k = abs(dt[k:k + 1]) * v + noise_k * math.sqrt(2.0) * sigma  # as _over_limit formed it
            found.append(Jump("position_step", k + 1, name, float(x[k]), float(x[k + 1]), float(limit_k[0])))
    first = min(found, key=lambda j: j.index) if found else None
    return Continuity(first, int(count), period, gap, noise)
