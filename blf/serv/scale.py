"""BLFserv's counted jumps against the LVDT's scale: which jump shows the backlash band crossed whatever the
LVDT's pitch may be (a recording without an LVDT calibration, or with one of a known residual).

Method
------
The LVDT reads the stroke with a pitch error :math:`p` (relative; paper 2.3: up to 7.5 %), so a position
difference is read as :math:`D_m = D + p\\,s` (``D_int``; ``D_ext = s_2 - s_1`` carries
:math:`p_2 s_2 - p_1 s_1`). The improved method's height :math:`h` is a linear function of the data (two
straight lines on the plateaus either side of the jump, their difference at :math:`t_j`), so

.. math:: h_m = h + p\\,\\delta x, \\qquad |p| \\le p_{max}

with :math:`\\delta x` the same measurement made on the ram's travel (:func:`motion_through_jumps`): on the
motor angle over the gear ratio, :math:`\\varphi / i` [mm], whose scale is exact (encoder counts and gear
ratio), not on the LVDT whose scale is the unknown. (:math:`\\delta s = \\delta x + h` inside a jump of
``D_int``: the difference is :math:`p h`, the jump's own scale error, which makes no jump.) A stroke that
only accelerates through an event (:math:`h = 0`) is read as a jump of up to :math:`p_{max}|\\delta x|`:
the artefacts of an uncalibrated full stroke (0.03 to 0.2 mm, paper 2.3).

A traversal moves ``D`` across the whole backlash band. The recording proves that it did only where what
is left of the jump after the most the unknown scale can make of the motion through it still clears the
detection floor (``min_jump_mm``, the peak-to-peak noise of D):

.. math:: |h_m| - c\\,p_{max}\\,|\\delta x| \\ge h_{min}

:math:`c = 1` for ``D_int`` (one LVDT), :math:`c = 2` for ``D_ext`` (two LVDTs of unknown pitch:
:math:`|p_2 - p_1| \\le 2 p_{max}`, :math:`\\delta x` the mean travel of both rams). A jump that fails is
not counted (``reason`` says why); a channel left with none is *not traversed*. Without a calibration
:math:`p_{max}` is the largest LVDT pitch error the house admits (10 %); with one, its residual.

On the simulated rig's full stroke without calibration (``tests/test_serv_scale.py``): the four reversals
of ``D_int`` move the rams by less than 0.002 mm through the jump (:math:`|h_m|/|\\delta x| > 90`), the
eight acceleration artefacts of ``D_int`` and ``D_ext`` by 0.37 to 1.09 mm with
:math:`|h_m|/|\\delta x|` = 0.07 to 0.10 (the rig's pitch errors +7.5 % and -2 %).

Pure: arrays and an explicit sample rate in, frozen dataclasses out.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from blf.errors import InputError
from blf.serv.results import BlfServResult, readings
from blf.validate import as_1d_finite, positive_scalar, scalar

__all__ = ["motion_through_jumps", "with_known_scale"]


def _line_at(x: np.ndarray, a: int, b: int, tc: float) -> float:
    """A straight line through samples ``a..b-1`` of ``x`` (least squares), its value at index ``tc``."""
    k = np.arange(a, b, dtype=float) - tc
    slope, level = np.polyfit(k, x[a:b], 1)
    return float(level)


def motion_through_jumps(x_mm, sample_rate_Hz: float, jumps, *, t0_s: float = 0.0, guard_before_s: float = 0.05,
                         guard_after_s: float = 0.02) -> np.ndarray:
    """The travel of ``x`` through each jump, measured as the improved method measures its height.

    Parameters
    ----------
    x_mm : array_like, shape (n,)
        The ram's position on an exact scale, mm (the motor angle over the gear ratio), sampled as the D
        the jumps were found in.
    sample_rate_Hz : float
        Sample rate, Hz.
    jumps : sequence of :class:`blf.serv.ServJump`
        The detected events (:attr:`blf.serv.BlfServResult.jumps`).
    t0_s : float, optional
        Time of the first sample, s (as given to :func:`blf.serv.blf_serv`).
    guard_before_s, guard_after_s : float, optional
        The detector's guards, s (as given to :func:`blf.serv.blf_serv`; its defaults).

    Returns
    -------
    ndarray, shape (len(jumps),)
        :math:`\\delta x` [mm]: the line on the ``n_after`` samples from ``guard_after_s`` after the event
        minus the line on the ``n_before`` samples ending ``guard_before_s`` before it, both at the jump
        instant; where a plateau has fewer than 3 samples, :math:`x(t_{end}) - x(t_{start})` of the event.

    Raises
    ------
    blf.errors.InputError
        Bad shape, NaN/inf, a bad rate, or a jump outside the samples.
    """
    x = as_1d_finite(x_mm, "x_mm", "mm", min_len=3)
    fs = positive_scalar(sample_rate_Hz, "sample_rate_Hz", "Hz")
    t0 = scalar(t0_s, "t0_s", "s")
    gpre = int(round(scalar(guard_before_s, "guard_before_s", "s", lo=0.0) * fs))
    gpost = int(round(scalar(guard_after_s, "guard_after_s", "s", lo=0.0) * fs))
    out = np.empty(len(jumps))
    for m, j in enumerate(jumps):
        start, last = int(round((j.t_start_s - t0) * fs)), int(round((j.t_end_s - t0) * fs))
        if not 0 <= start <= last < x.size:
            raise InputError(f"jump {m} at t = {j.t_start_s:g}..{j.t_end_s:g} s lies outside the {x.size} samples "
                             f"of x_mm (t0_s = {t0:g} s, {fs:g} Hz)")
        p1 = start - gpre
        p0, q0 = p1 - int(j.n_before), last + gpost + 1
        q1 = q0 + int(j.n_after)
        if j.n_before >= 3 and j.n_after >= 3 and p0 >= 0 and q1 <= x.size:
            tc = (j.t_jump_s - t0) * fs
            out[m] = _line_at(x, q0, q1, tc) - _line_at(x, p0, p1, tc)
        else:
            out[m] = x[last] - x[start]
    return out


def with_known_scale(result: BlfServResult, motion_mm, pitch_bound: float, *, lvdts: int = 1) -> BlfServResult:
    """``result`` with only the jumps that cross the backlash band whatever the LVDT's scale (Method above).

    Parameters
    ----------
    result : BlfServResult
        BLFserv's result of one channel (:func:`blf.serv.blf_serv`).
    motion_mm : array_like, shape (len(result.jumps),)
        The ram's travel through each jump, mm (:func:`motion_through_jumps`).
    pitch_bound : float
        :math:`p_{max}`, the largest relative pitch error the LVDT may have (0.10: 10 %), >= 0.
    lvdts : {1, 2}, optional
        LVDTs in the channel's D: 1 for ``D_int``, 2 for ``D_ext`` (:math:`c` above).

    Returns
    -------
    BlfServResult
        A jump with :math:`|h| - c\\,p_{max}|\\delta x| < h_{min}` is not counted (reason ``"within the
        LVDT scale's reach: ..."``), by either method; the paper method's :math:`|\\Delta D|` is held to the
        same rule besides (an event whose height was not measured: to that alone); the
        backlash, its uncertainty and the counts are those of the jumps left.
    """
    dx = as_1d_finite(motion_mm, "motion_mm", "mm", min_len=0)
    if dx.size != len(result.jumps):
        raise InputError(f"motion_mm must hold one travel per jump ({len(result.jumps)}); got {dx.size}")
    p = scalar(pitch_bound, "pitch_bound", "(relative)", lo=0.0, hi=1.0)
    if lvdts not in (1, 2):
        raise InputError(f"lvdts must be 1 (D_int) or 2 (D_ext); got {lvdts!r}")
    reach = lvdts * p * np.abs(dx)
    floor = result.min_jump_mm
    jumps = []
    for j, r, d in zip(result.jumps, reach, np.abs(dx), strict=True):
        # (a height not measured, NaN: the event is held to the rule by its paper delta alone)
        ok = abs(j.height_mm) - r >= floor if np.isfinite(j.height_mm) else True
        paper_ok = j.paper_accepted and ok and abs(j.paper_delta_mm) - r >= floor
        if j.accepted and not ok:
            j = dataclasses.replace(j, accepted=False, reason=(
                f"within the LVDT scale's reach: |h| {abs(j.height_mm):.4f} mm - {lvdts} x {p:g} x travel "
                f"{d:.4f} mm < {floor:.4f} mm"))
        jumps.append(dataclasses.replace(j, paper_accepted=paper_ok))
    return dataclasses.replace(result, **readings(jumps, result.method),
                               jumps=tuple(jumps))
