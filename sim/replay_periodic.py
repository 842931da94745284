"""A force periodic in the ram's position in a drive of the dual-EMA replay: its candidate and its force.

The period is found from the recording, not assumed: while an EMA holds a force target, its load cell
reads the target less its drive's friction, inertia and any force periodic in the ram's position
(:mod:`sim.effects` ``PeriodicForce``; the drive's momentum balance, :mod:`sim.replay_model` ``Fd``). The
load-cell force minus the target, against the motor-side position, per direction of motion (the friction
is a constant per direction: the periodogram's floating mean takes it), is searched for periods by
:func:`blf.diagnose.periodic.find_periods`; the strongest one found starts the candidate
``periodic_force`` at that EMA (amplitude, phase and period, the last two its shape), which the diagnosis
then screens, refits and accepts or not like any other (:func:`blf.diagnose.engine.diagnose`).

.. math:: F_p(x_m) = A\\cos(2\\pi x_m / p + \\varphi)\\,W(x_m)\\quad [N],\\qquad
          F_d = g_{lc}(F_{target} - F_f(v) - F_p(x_m) - M a)

with :math:`W = 1` for a uniform ripple and, for a local defect, :func:`envelope`: a window with fitted
edges (centre, half width, edge width), which follows a defect's sharp ends as well as a gradual one.
"""

from __future__ import annotations

import numpy as np

from blf.diagnose import Candidate, Param

__all__ = ["periodic_start", "periodic_candidate", "periodic_force", "envelope"]

_DECIMATE = 10  #: every 10th sample searched (the period is tens of samples of travel long at the check's speed)
_MOVING_MM_PER_S = 0.5  #: slower than this the ram is taken as standing


def periodic_start(xm_mm, v_mm_per_s, force_N, target_N, hold, band_hz: float,
                   decimate: int = _DECIMATE) -> tuple | None:
    """(period mm, amplitude N, phase rad, local span or None) of the strongest force periodic in the ram's
    position while the EMA holds force and moves, or None where none is found (or the travel is shorter
    than two periods). Local (:func:`blf.diagnose.periodic.locality` in stretches of two periods): its
    span (centre mm, half width mm) from the power of the complex demodulate at the period (its centroid,
    and sqrt(3) times its standard deviation: a flat stretch's half width).
    Periods shorter than the travel in one period of the band's edge (the 95th percentile of the speed
    over ``band_hz``) are not sought: the replay does not claim them."""
    from blf.diagnose.periodic import find_periods, locality, search_range
    from blf.errors import AnalysisError
    k = max(1, int(decimate))
    x = np.asarray(xm_mm, float)[::k] * 1e-3
    v = np.asarray(v_mm_per_s, float)[::k]
    r = (np.asarray(force_N, float) - np.asarray(target_N, float))[::k]
    used = np.asarray(hold, bool)[::k] & (np.abs(v) > _MOVING_MM_PER_S)
    d = np.where(used, np.sign(v), 0.0)
    if used.sum() < 50:
        return None
    try:
        fastest = float(np.percentile(np.abs(v[used]), 95)) * 1e-3
        found = find_periods(x, r, d, used, search_range(x, used, d, fastest / band_hz), max_periods=1)
    except AnalysisError:
        return None
    if not found:
        return None
    p = found[0].period_m
    where = locality(x, r, d, used, p, search_range(x, used, d), periods_per_bin=2.0)
    env = np.ones(x.size)
    span = None
    if not where.uniform:  # centre and half width of the envelope from the complex demodulate's power
        z = np.abs(np.convolve(np.where(used, r * np.exp(-2j * np.pi * x / p), 0), np.ones(25), "same")) ** 2
        z = np.where(used, z, 0.0)
        c = float(np.sum(z[used] * x[used]) / np.sum(z[used]))
        w = float(np.sqrt(3 * np.sum(z[used] * (x[used] - c) ** 2) / np.sum(z[used])))
        span = (c * 1e3, max(w, p) * 1e3)
        env = envelope(x * 1e3, *span, _edge_start(span[1]))
    cols = [np.ones(x.size), env * np.cos(2 * np.pi * x / p), env * np.sin(2 * np.pi * x / p)]
    X = np.column_stack([cols[0] * (d > 0), cols[0] * (d < 0), cols[1], cols[2]])
    a, b = np.linalg.lstsq(X[used], r[used], rcond=None)[0][2:]
    # the load cell reads -F_p: -A cos(theta + phi) = a cos(theta) + b sin(theta)
    return p * 1e3, float(np.hypot(a, b)), float(np.arctan2(-b, -a)), span


def envelope(xm_mm, center_mm: float, half_width_mm: float, edge_mm: float) -> np.ndarray:
    """A local defect's envelope: a window of half width :math:`w` around :math:`x_0` whose two edges are
    logistic of width :math:`s`,

    .. math:: W(x) = \\sigma\\!\\left(\\frac{x - x_0 + w}{s}\\right)\\,
              \\sigma\\!\\left(\\frac{x_0 + w - x}{s}\\right),\\qquad \\sigma(u) = \\frac{1}{1 + e^{-u}}

    (all mm). :math:`s \\to 0` is a box (a defect with sharp ends, as the simulator's ``periodic_force``
    with ``width_mm``), :math:`s` of the order of :math:`w` a gradual rise; :math:`W(x_0 \\pm w) = 1/2`
    where :math:`s \\ll w`, so :math:`w` is the half width at half height whatever the edges. The edge
    width is fitted (a shape parameter of the candidate), not assumed.
    """
    x = np.asarray(xm_mm, float)
    s = float(edge_mm)
    lo = np.clip((x - center_mm + half_width_mm) / s, -60.0, 60.0)
    hi = np.clip((center_mm + half_width_mm - x) / s, -60.0, 60.0)
    return 1.0 / ((1.0 + np.exp(-lo)) * (1.0 + np.exp(-hi)))


def _edge_start(half_width_mm: float) -> float:
    """The edge width a local candidate starts from: a sixth of its half width (between a box and a bump;
    the fit moves it)."""
    return half_width_mm / 6.0


def periodic_candidate(where: str, n: str, start: tuple) -> Candidate:
    """The candidate ``periodic_force`` at an EMA, started where :func:`periodic_start` found it."""
    p, a, ph, span = start
    params = (Param("amplitude_N", a, max(a, 1.0), 0.0, 1e4),
              Param("phase_rad", ph, 0.5, ph - 2 * np.pi, ph + 2 * np.pi),
              Param("period_mm", p, p * 0.01, p * 0.9, p * 1.1))
    shape = ("phase_rad", "period_mm")
    place = f"the ram's position in the drive of EMA {n}" if n else "position on the axis"
    words = f"a force periodic in {place} (period {p:.4g} mm of travel found in the data"
    if span is None:
        words += ", uniform along the stroke: a screw's runout or misalignment)"
    else:
        c, w = span
        # the edge width from a hundredth of the half width (a box to the sampling's eye) to the half width
        params += (Param("center_mm", c, w / 4, c - w, c + w), Param("half_width_mm", w, w / 4, w / 3, 3 * w),
                   Param("edge_mm", _edge_start(w), w / 12, w / 100, w))
        shape += ("center_mm", "half_width_mm", "edge_mm")
        words += f", local: around {c:+.3g} mm of the stroke: a defect on the raceway there)"
    return Candidate("periodic_force", where, words, params, "", shape)


def periodic_force(xm_mm, x) -> np.ndarray:
    """:math:`F_p` (N) at the motor-side positions for the candidate's parameters (amplitude, phase, period,
    and for a local one the centre, half width and edge width of its :func:`envelope`)."""
    a, ph, p = (float(v) for v in x[:3])
    f = a * np.cos(2 * np.pi * np.asarray(xm_mm, float) / p + ph)
    return f * envelope(xm_mm, float(x[3]), float(x[4]), float(x[5])) if len(x) == 6 else f
