"""Forces periodic in position: found from a residual's structure against position, not against time.

Pure: arrays in, frozen dataclasses out (no IO). A screw's lead, a gear's mesh, a motor's cogging, a
runout or misalignment make a force that repeats with the position of the part, whatever the speed; a
defect at one place on a raceway makes it repeat only where the defect is. The steps:

1. :func:`search_range` (:class:`PeriodSearch`): the periods a recording can show, from its positions
   alone: at least :data:`SAMPLES_PER_PERIOD` samples of travel per period (the position's own Nyquist
   limit, with margin), at most half the span travelled (two whole periods, else a period is a slope);
   the frequency resolution is the Rayleigh width :math:`1/L`, L the span (m);
2. :func:`amplitude_spectrum`: the amplitude (N) of a sinusoid in position fitted at each trial
   period, each direction of motion apart (Lomb-Scargle with a floating mean,
   :func:`scipy.signal.lombscargle`; the samples are uneven in position), combined as the RMS over the
   directions (a ripple may change its phase with the direction of the load on the part);
3. :func:`find_periods` (:class:`PeriodFound`): the strongest peaks, one after the other (each found
   one removed before the next is sought), each kept only where its power exceeds the local noise of
   the spectrum by the false-alarm level :math:`\\ln(M/\\alpha)` over the M independent periods
   searched (:math:`\\alpha` = :data:`FALSE_ALARM`); the period refined on a fine grid and its standard
   uncertainty from a delete-one-group jackknife over the strokes;
4. :func:`periodic_columns`: the regressor columns of a periodic force, per direction of motion and
   order (cos, sin of :math:`2\\pi h q / P`), fitted jointly with a nominal model elsewhere;
   :func:`periodic_amplitudes` turns their fitted coefficients into amplitudes (N) with uncertainties;
5. :func:`locality`: uniform along the travel (runout, misalignment) or local (a defect at a place);
6. :func:`lead_order`: with a stated lead (and gear ratio), which order of which part the period is,
   and whether it contradicts the stated lead beyond its uncertainty.

Model of a periodic force of period :math:`P` (m), orders :math:`h = 1..H`, in direction :math:`d`:

.. math:: F_p(q, d) = \\sum_h a_{h,d}\\cos(2\\pi h q / P) + b_{h,d}\\sin(2\\pi h q / P),
          \\qquad A_{h,d} = \\sqrt{a_{h,d}^2 + b_{h,d}^2}

A ripple at a fixed *time* frequency looks alike at one speed; two speeds would tell them apart (said in
the words where the recording has one speed level).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.errors import AnalysisError
from blf.validate import as_1d_finite, positive_scalar

__all__ = ["PeriodSearch", "PeriodFound", "Locality", "LeadOrder", "search_range", "amplitude_spectrum",
           "find_periods", "periodic_columns", "periodic_amplitudes", "locality", "lead_order", "column_name",
           "SAMPLES_PER_PERIOD", "FALSE_ALARM", "MIN_PERIODS", "DIRECTIONS"]

SAMPLES_PER_PERIOD = 2.5  #: fewest samples of travel per period (Nyquist's 2, with margin for uneven steps)
MIN_PERIODS = 2.0  #: fewest whole periods in the span travelled
FALSE_ALARM = 1e-3  #: probability that noise alone makes one peak over the whole search
DIRECTIONS = {1: "extend", -1: "retract"}  #: direction of motion -> its name in column and key names
_OVERSAMPLE = 5  #: trial periods per Rayleigh width on the coarse grid
_NOISE_HALF_WIDTH = 10  #: the local noise of the spectrum: median over this many Rayleigh widths each side
_GROUPS = 8  #: groups of strokes of the jackknife
_BINS_PER_PERIOD = 10  #: position bins per shortest trial period (:func:`_binned`)


@dataclass(frozen=True)
class PeriodSearch:
    """The periods a recording can show (m) and its resolution."""

    shortest_m: float
    longest_m: float
    span_m: float  #: position span travelled in each direction over the samples compared (the shorter), m
    step_m: float  #: 95th percentile of the travel between consecutive samples compared
    words: str

    @property
    def rayleigh_per_m(self) -> float:
        """Frequency resolution, cycles per m: two periods closer than this are not told apart."""
        return 1.0 / self.span_m


@dataclass(frozen=True)
class PeriodFound:
    """A period found in a residual: its value and standard uncertainty (m), amplitude (N), detection."""

    period_m: float
    period_u_m: float
    amplitude_N: float  #: RMS over the directions of the fitted amplitude at the period
    power_over_noise: float  #: peak power over the local noise power of the spectrum
    threshold: float  #: the false-alarm level it exceeded


@dataclass(frozen=True)
class Locality:
    """Where along the travel a periodic force acts."""

    uniform: bool
    span_m: tuple  #: (start, end) of the travel where it is strongest (m)
    share: float  #: share of its power in that stretch
    bin_amplitudes_N: tuple  #: amplitude in each stretch, in order of position
    bin_edges_m: tuple
    words: str


@dataclass(frozen=True)
class LeadOrder:
    """A period against a stated lead (and gear ratio): which order of which part it is."""

    part: str  #: "screw" or "motor"
    order: float  #: cycles of the period per turn of the part (1: once per turn)
    order_u: float
    nearest: int
    contradicts: bool
    words: str
    scale_difference: float = 0.0  #: c - 1: the position's scale (measured per true length) making it whole


def search_range(q_m, used, direction=None, shortest_m: float = 0.0) -> PeriodSearch:
    """The periods (m) a recording's positions can show.

    Parameters
    ----------
    q_m : array_like, shape (n,)
        Measured position, m.
    used : array_like of bool, shape (n,)
        The samples compared.
    direction : array_like, shape (n,), optional
        Direction of motion (+1, -1, 0); default the sign of the position's gradient.
    shortest_m : float
        A shorter period the model does not claim (e.g. the speed over the band it compares in), m: the
        shortest period sought is the larger of the two.

    Returns
    -------
    PeriodSearch
        Shortest :math:`2.5\\,\\Delta q_{95}` (the 95th percentile of the travel between consecutive
        samples compared), longest :math:`L/2` (L the span travelled: two whole periods).

    Raises
    ------
    AnalysisError
        The travel is shorter than two of the shortest periods: no periodic force can be named.
    """
    q = as_1d_finite(q_m, "q_m", "m", min_len=3)
    u = np.asarray(used, bool)
    if u.shape != q.shape or u.sum() < 3:
        raise AnalysisError("too few samples compared to look for a force periodic in position")
    idx = np.flatnonzero(u)
    steps = np.abs(np.diff(q[idx]))[np.diff(idx) == 1]
    step = float(np.percentile(steps, 95)) if steps.size else 0.0
    d = np.sign(np.gradient(q)) if direction is None else np.asarray(direction, float)
    spans = [float(np.ptp(q[idx][d[idx] == s])) for s in DIRECTIONS if np.sum(d[idx] == s) > 2]
    span = min(spans) if spans else 0.0  # the travel in each direction
    shortest, longest = max(SAMPLES_PER_PERIOD * step, float(shortest_m)), span / MIN_PERIODS
    if step <= 0 or span <= 0 or longest <= shortest:
        raise AnalysisError(f"the travel compared ({span * 1e3:.4g} mm) is shorter than two of the shortest "
                            f"periods it could show ({shortest * 1e3:.4g} mm, {SAMPLES_PER_PERIOD:g} samples of "
                            f"{step * 1e3:.3g} mm travel): no force periodic in position can be named")
    return PeriodSearch(shortest, longest, span, step, (
        f"periods from {shortest * 1e3:.3g} mm ({SAMPLES_PER_PERIOD:g} samples of {step * 1e3:.3g} mm travel) "
        f"to {longest * 1e3:.4g} mm (two whole periods in the {span * 1e3:.4g} mm travelled); periods closer "
        f"than one part in {span / shortest:.0f} at the shortest are not told apart"))


def _groups(used: np.ndarray, n_groups: int) -> np.ndarray:
    """Each compared sample's group: contiguous stretches (strokes) dealt round-robin into groups."""
    idx = np.flatnonzero(used)
    stroke = np.cumsum(np.r_[1, np.diff(idx) > 1]) - 1
    return stroke % max(1, min(n_groups, int(stroke[-1]) + 1)) if idx.size else stroke


def _binned(q: np.ndarray, y: np.ndarray, width: float) -> tuple:
    """Mean position, mean value and count in bins of ``width`` along the position (the strokes averaged
    at each place, as the cycle-averaged effort against position): a sinusoid of period P >= 10 widths
    keeps sinc(pi/10) > 98 % of its amplitude, and the fit is weighted by the counts."""
    k = np.floor((q - q.min()) / width).astype(int)
    n = np.bincount(k).astype(float)
    ok = n > 0
    return (np.bincount(k, q)[ok] / n[ok], np.bincount(k, y)[ok] / n[ok], n[ok])


def amplitude_spectrum(q_m, r, direction, used, periods_m) -> np.ndarray:
    """Amplitude (residual's unit) of a sinusoid in position at each trial period.

    Per direction of motion (``direction`` +1/-1; 0 not used) the residual averaged in position bins of a
    tenth of the shortest trial period (:func:`_binned`), then a Lomb-Scargle fit with a floating mean
    weighted by the bins' counts; the result is the RMS over the directions present,
    :math:`\\sqrt{\\mathrm{mean}_d A_d^2(P)}`.
    """
    from scipy.signal import lombscargle
    q, y, d = np.asarray(q_m, float), np.asarray(r, float), np.asarray(direction, float)
    u = np.asarray(used, bool)
    w = 2 * np.pi / np.asarray(periods_m, float)
    acc, n = np.zeros(w.size), 0
    for s in DIRECTIONS:
        sel = u & (d == s)
        if sel.sum() < 10 or np.ptp(q[sel]) < MIN_PERIODS * float(np.max(periods_m)) * (1 - 1e-9):
            continue  # fewer than two periods travelled in this direction: it says nothing of them
        x, m, n_in = _binned(q[sel], y[sel], float(np.min(periods_m)) / _BINS_PER_PERIOD)
        acc += np.abs(lombscargle(x, m, w, normalize="amplitude", floating_mean=True, weights=n_in)) ** 2
        n += 1
    if n == 0:
        raise AnalysisError("no direction of motion with 10 samples compared over two periods: no periodic "
                            "force can be sought")
    return np.sqrt(acc / n)


def _refine(q, y, d, u, period, rayleigh, n=81) -> tuple:
    f0 = 1.0 / period
    f = np.linspace(f0 - rayleigh, f0 + rayleigh, n)
    f = f[f > 0]
    a = amplitude_spectrum(q, y, d, u, 1.0 / f)
    k = int(np.argmax(a))
    fk = f[k]
    if 0 < k < f.size - 1:  # the vertex of the parabola through the peak and its neighbours
        den = a[k - 1] - 2 * a[k] + a[k + 1]
        if den < 0:
            fk = f[k] + 0.5 * (a[k - 1] - a[k + 1]) / den * (f[1] - f[0])
    return float(1.0 / fk), float(a[k])


def _sinusoid(q, y, d, u, period, orders=(1,)) -> np.ndarray:
    """The least-squares periodic part (per direction, with a mean) of y at a period, over all samples."""
    out = np.zeros_like(y)
    for s in DIRECTIONS:
        sel = u & (d == s)
        if sel.sum() < 3 + 2 * len(orders):
            continue
        cols = [np.ones(q.size)] + [f(2 * np.pi * h * q / period) for h in orders for f in (np.cos, np.sin)]
        X = np.column_stack(cols)
        c, *_ = np.linalg.lstsq(X[sel], y[sel], rcond=None)
        out[d == s] = (X[:, 1:] @ c[1:])[d == s]
    return out


def find_periods(q_m, r, direction, used, search: PeriodSearch, max_periods: int = 3,
                 alpha: float = FALSE_ALARM) -> tuple:
    """Periods found in a residual against position, strongest first.

    Parameters
    ----------
    q_m, r, direction : array_like, shape (n,)
        Position (m), residual (N), direction of motion (+1, -1; 0 where standing still).
    used : array_like of bool, shape (n,)
        The samples compared.
    search : PeriodSearch
    max_periods : int
        At most this many.
    alpha : float
        False-alarm probability of the whole search.

    Returns
    -------
    tuple of PeriodFound

    Notes
    -----
    A peak is kept when its power :math:`A^2` exceeds the local noise power
    :math:`\\bar N = \\mathrm{median}(A^2)/\\ln 2` (the median over
    :data:`_NOISE_HALF_WIDTH` Rayleigh widths each side: a noise power is exponential, its median
    :math:`\\ln 2` times its mean) by :math:`\\ln(M/\\alpha)`, M the independent periods searched
    (:math:`L(1/P_{min} - 1/P_{max})`). Each kept one is removed (its sinusoid per direction) before the
    next is sought. The period's uncertainty: delete-one-group jackknife (strokes dealt into
    :data:`_GROUPS` groups), :math:`u^2 = \\frac{G-1}{G}\\sum_g (P_{(g)} - \\bar P)^2`.
    """
    from scipy.ndimage import median_filter
    q = as_1d_finite(q_m, "q_m", "m")
    y = as_1d_finite(r, "r", "N").copy()
    d = np.asarray(direction, float)
    u = np.asarray(used, bool) & (d != 0)
    ray = search.rayleigh_per_m
    f = np.arange(1.0 / search.longest_m, 1.0 / search.shortest_m, ray / _OVERSAMPLE)
    if f.size < 3:
        return ()
    m = max(2.0, search.span_m * (f[-1] - f[0]))
    threshold = float(np.log(m / positive_scalar(alpha, "alpha", "1")))
    groups = _groups(u, _GROUPS)
    idx = np.flatnonzero(u)
    found = []
    for _ in range(max_periods):
        a2 = amplitude_spectrum(q, y, d, u, 1.0 / f) ** 2
        half = _NOISE_HALF_WIDTH * _OVERSAMPLE
        noise = median_filter(a2, size=2 * half + 1, mode="nearest") / np.log(2)
        ratio = a2 / np.maximum(noise, 1e-300)
        for p in found:  # a period already found is not found again
            ratio[np.abs(f - 1 / p.period_m) < ray] = 0.0
        k = int(np.argmax(ratio))
        if ratio[k] <= threshold:
            break
        period, amp = _refine(q, y, d, u, 1.0 / f[k], ray / 2)
        jack = []
        for g in np.unique(groups):
            keep = u.copy()
            keep[idx[groups == g]] = False
            jack.append(_refine(q, y, d, keep, period, ray / 4, 21)[0])
        jack = np.asarray(jack)
        uj = float(np.sqrt((jack.size - 1) / jack.size * np.sum((jack - jack.mean()) ** 2))) if jack.size > 1 else 0.0
        found.append(PeriodFound(period, uj, amp, float(ratio[k]), threshold))
        y = y - _sinusoid(q, y, d, u, period)
    return tuple(found)


def column_name(i: int, order: int, sign: int, fn: str) -> str:
    """The name of a periodic column: component i, order, direction, cos or sin."""
    return f"periodic{i}_h{order}_{DIRECTIONS[sign]}_{fn}"


def periodic_columns(q_m, direction, period_m: float, orders=(1,), i: int = 0) -> dict:
    """Regressor columns of a force periodic in position: name -> column (N per N of coefficient).

    Per direction of motion :math:`d` and order :math:`h`: :math:`[d]\\cos(2\\pi h q/P)`,
    :math:`[d]\\sin(2\\pi h q/P)` (zero in the other direction and standing still).
    """
    q = as_1d_finite(q_m, "q_m", "m")
    d = np.asarray(direction, float)
    p = positive_scalar(period_m, "period_m", "m")
    out = {}
    for s in DIRECTIONS:
        on = (d == s).astype(float)
        for h in orders:
            ph = 2 * np.pi * h * q / p
            out[column_name(i, h, s, "cos")] = on * np.cos(ph)
            out[column_name(i, h, s, "sin")] = on * np.sin(ph)
    return out


def periodic_amplitudes(parameters: dict, uncertainty: dict, i: int = 0, orders=(1,)) -> dict:
    """Amplitude (N), its standard uncertainty and phase (rad) per direction and order of component i.

    :math:`A = \\sqrt{a^2+b^2}`, :math:`u_A = \\sqrt{(a u_a)^2 + (b u_b)^2}/A` (cos and sin columns
    taken uncorrelated: over whole periods they are orthogonal), phase :math:`\\mathrm{atan2}(-b, a)`
    (:math:`A\\cos(2\\pi h q/P + \\varphi)`). Keys ``(direction name, order)``; a direction not fitted is
    left out.
    """
    out = {}
    for s, name in DIRECTIONS.items():
        for h in orders:
            kc, ks = column_name(i, h, s, "cos"), column_name(i, h, s, "sin")
            if kc not in parameters or uncertainty.get(kc, 0.0) == 0.0:
                continue
            a, b = parameters[kc], parameters[ks]
            amp = float(np.hypot(a, b))
            ua = float(np.hypot(a * uncertainty[kc], b * uncertainty[ks]) / amp) if amp > 0 else float(
                np.hypot(uncertainty[kc], uncertainty[ks]) / np.sqrt(2))
            out[(name, h)] = (amp, ua, float(np.arctan2(-b, a)))
    return out


def locality(q_m, r, direction, used, period_m: float, search: PeriodSearch, periods_per_bin: float = 4.0,
             local_share: float = 0.5) -> Locality:
    """Uniform along the travel, or local: the periodic force's amplitude stretch by stretch.

    The travel is cut into stretches of at least ``periods_per_bin`` periods (3 to 6 stretches); in each
    the amplitude at the period (RMS over the directions) is fitted on ``r`` (a residual holding the
    periodic force). **Local** when one stretch holds more than ``local_share`` of the power summed over
    the stretches (with 3 stretches or more: a uniform ripple gives each about 1/n), else uniform.
    """
    q = as_1d_finite(q_m, "q_m", "m")
    y = as_1d_finite(r, "r", "N")
    d = np.asarray(direction, float)
    u = np.asarray(used, bool) & (d != 0)
    lo, hi = float(q[u].min()), float(q[u].max())
    n = int(min(6, max(1, (hi - lo) // (periods_per_bin * period_m))))
    if n < 3:
        return Locality(True, (lo, hi), 1.0, (), (lo, hi), (
            f"the travel holds fewer than {3 * periods_per_bin:g} periods: where along it is not told (taken "
            "uniform)"))
    edges = np.linspace(lo, hi, n + 1)
    amps = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = u & (q >= a) & (q <= b)
        try:
            amps.append(float(amplitude_spectrum(q, y, d, sel, [period_m])[0]) if sel.sum() > 20 else 0.0)
        except AnalysisError:  # under two periods travelled in this stretch in either direction
            amps.append(0.0)
    p = np.square(amps)
    k = int(np.argmax(p))
    share = float(p[k] / p.sum()) if p.sum() > 0 else 0.0
    local = share > local_share
    span = (float(edges[k]), float(edges[k + 1])) if local else (lo, hi)
    words = (f"local: {share:.0%} of its power between {span[0] * 1e3:.4g} and {span[1] * 1e3:.4g} mm of travel "
             f"(a defect at a place: a spall or a dent on the raceway there)" if local else
             f"uniform along the travel (no stretch of {n} holds more than {local_share:.0%} of its power; "
             f"largest {share:.0%}): once per period everywhere, as a runout, an eccentricity or a "
             f"misalignment makes it")
    return Locality(not local, span, share, tuple(amps), tuple(edges.tolist()), words)


def lead_order(period_m: float, period_u_m: float, lead_m: float, gear_ratio: float | None = None,
               z_max: float = 3.0, max_order: int = 12, scale_tolerance: float = 0.0) -> LeadOrder:
    """Which order of which part a period is, given the screw's lead (m of travel per screw turn) and
    optionally the motor turns per screw turn, and the tolerance of the position sensor's scale.

    The order is the cycles per turn of a part: :math:`n = L/P` for the screw, :math:`n = L/(gP)` for the
    motor, with :math:`u_n = n u_P / P`. A period is found in the **measured** position: where the sensor's
    scale is :math:`c` (measured per true length), :math:`P = c L / k` for order :math:`k`, so the order
    seen is :math:`n = k / c`. With a stated scale tolerance :math:`s` (:math:`|c - 1| \\le s`) order
    :math:`k` is consistent with :math:`n` where the gap :math:`\\max(0, |n - k| - s n)` is within
    ``z_max`` :math:`u_n`; the scale that makes it whole is :math:`c = k / n`. With :math:`s = 0` (the
    default: the scale taken as exact) this is :math:`|n - k| \\le z_{max} u_n`. Orders :math:`k` and
    :math:`k + 1` cannot be told apart once :math:`s \\ge 1/(2k + 1)` (their bands of :math:`n` meet): the
    words say so. The part whose order is consistent is named; where several are, the lowest order (a
    1 mm period with a 5 mm lead and 5 motor turns per screw turn: the motor once per turn, not the screw
    five times). **Contradicts** the stated lead when no part's order is consistent: the period found is
    used, and the words give the scale :math:`c - 1` that would make the nearest order whole (either the
    lead is not the one stated or the position's scale is off by that).

    Raises
    ------
    AnalysisError
        ``scale_tolerance`` not in [0, 0.5).
    """
    P = positive_scalar(period_m, "period_m", "m")
    L = positive_scalar(lead_m, "lead_m", "m")
    s = float(scale_tolerance)
    if not 0.0 <= s < 0.5:
        raise AnalysisError(f"scale_tolerance: must be in [0, 0.5) (a fraction of the position's scale); got {s}")
    uP = max(float(period_u_m), 1e-12)
    parts = [("screw", L / P)] + ([("motor", L / (positive_scalar(gear_ratio, "gear_ratio", "1") * P))]
                                  if gear_ratio else [])
    cands = []
    for part, n in parts:
        un = n * uP / P
        k = int(min(max_order, max(1, round(n))))
        cands.append((part, n, un, k, max(0.0, abs(n - k) - s * n) / un))
    # among the parts whose order is whole within z_max the lowest order (the fastest part's), else the nearest
    part, n, un, k, z = min(cands, key=lambda c: (c[4] > z_max, c[3] if c[4] <= z_max else c[4]))
    ok = z <= z_max
    scale = k / n - 1.0  #: c - 1: the position's scale that makes order k whole
    what = {1: "once per turn"}.get(k, f"{k} times per turn")
    words = (f"order {k} of the {part} ({what}; {n:.4g} ± {un:.2g} cycles per turn with the stated lead "
             f"{L * 1e3:.4g} mm" + (f" and {gear_ratio:g} motor turns per screw turn" if gear_ratio else "") + ")")
    if ok and s > 0 and abs(n - k) > z_max * un:
        words += (f" in the position's scale: the period found, {P * 1e3:.4g} ± {uP * 1e3:.2g} mm, is the "
                  f"part's in a position scaled by {scale * 100:+.2g} %, within the stated tolerance of the "
                  f"position sensor's scale ± {s * 100:.3g} %")
    if ok and s >= 1.0 / (2 * k + 1):
        words += (f"; with a scale tolerance of ± {s * 100:.3g} % orders {k} and {k + 1} cannot be told apart "
                  f"(they can below ± {100 / (2 * k + 1):.3g} %)")
    if not ok:
        beyond = f" beyond the stated tolerance of the position's scale ± {s * 100:.3g} %" if s > 0 else ""
        words = (f"the stated lead {L * 1e3:.4g} mm contradicts the period found, {P * 1e3:.4g} ± {uP * 1e3:.2g} mm"
                 f"{beyond}: nearest is order {k} of the {part} ({n:.4g} ± {un:.2g} cycles per turn, {z:.1f} "
                 f"standard uncertainties from {k}" + (" less the tolerance" if s > 0 else "") + "); the period "
                 f"found is used. Either the lead is not the one stated or the position's scale is off by "
                 f"{scale * 100:+.2g} %")
    return LeadOrder(part, n, un, k, not ok, words, scale)
