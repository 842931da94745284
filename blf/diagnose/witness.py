"""A second witness of a positioning axis: its position loop's tracking error, against a reference's.

Pure: arrays and a sample rate in, frozen dataclasses out (no IO). Where a recording holds the set point
beside the measured position, the tracking error :math:`e = q_{ref} - q` is a witness of the force the
loop fights that does not pass through the effort's conversion (a current's gain, its offsets, a
re-levelling in preprocessing): a friction that grows makes the loop lag more in the direction of motion;
a force that grows rougher (dry or damaged contacts, play) makes it jitter more. Two statistics, over the
**steady** samples only (:func:`steady_samples`: moving, the catch-up after each set-point step masked as
:func:`blf.diagnose.axis_reference.effort_mask` does, so the lag at a start or stop is not in them):

* the **lag** :math:`L`: the mean of :math:`e\\,\\mathrm{sign}(\\dot q_{ref})` (m; positive: the
  position behind the set point), over each steady stretch less as many samples again as its catch-up
  lasted: the catch-up mask ends where :math:`e` is within 3 sigma of its steady value, and its tail
  (an exponential of the loop's time constant) would otherwise bias the lag by about
  :math:`3\\sigma\\tau/T` and make it grow with the jitter; after as long again it has decayed by the
  catch-up's own ratio (6 mm to 0.3 mm on a 24 mm/s start: to about 15 um);
* the **jitter** :math:`J`: the RMS of the tracking error's fast part, :math:`e` less its local
  quadratic trend (a Savitzky-Golay fit over ``window_s``, 1 s by default, about the loop's settling time:
  what varies more slowly is the lag, not jitter), m.

Each is a mean over the steady strokes (each contiguous stretch of steady samples, at least one window
long) weighted by their samples, with a cluster-robust standard uncertainty (strokes independent, samples
within a stroke not). :func:`compare_witness` compares them with a reference's: the lag's change in m, the
jitter's as a ratio less 1 (dimensionless: a jitter scales with the sensor and the loop of the rig);
a change is named when statistically supported (:math:`|z| > z_{min}`) and above its floor, as a force
parameter is (:func:`blf.diagnose.axis_reference.compare_fits`). :func:`witnesses_disagree` is the rule
that sets the two witnesses against each other; :func:`floor_from_spread` the floor of several healthy
references.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.errors import AnalysisError
from blf.maint.segments import runs
from blf.validate import as_1d_finite, positive_scalar, same_shape

__all__ = ["TrackingWitness", "WitnessChange", "steady_samples", "tracking_witness", "compare_witness",
           "witnesses_disagree", "floor_from_spread", "WITNESS_UNITS"]

#: each witness statistic compared and the unit of its change
WITNESS_UNITS = {"tracking_lag_m": "m", "tracking_jitter_ratio": "1"}
_WORDS = {"tracking_lag_m": "the tracking error's steady lag (set point minus position along the motion)",
          "tracking_jitter_ratio": "the tracking error's steady jitter"}


@dataclass(frozen=True)
class TrackingWitness:
    """The tracking error of one recording in steady motion.

    Attributes
    ----------
    lag_m, lag_u_m : float
        Mean of :math:`e\\,\\mathrm{sign}(\\dot q_{ref})` over the steady samples and its standard uncertainty, m.
    jitter_m, jitter_u_m : float
        RMS of the fast part of :math:`e` and its standard uncertainty, m.
    n_strokes, n_samples : int
        Steady strokes and samples used.
    window_s : float
        The trend's window, s.
    periods_removed_m : tuple of float
        Periods in position (m of travel) whose component (orders 1-3 per direction of motion) was
        removed from the fast part before its RMS (:func:`tracking_witness` ``periods_m``); empty: none.
    """

    lag_m: float
    lag_u_m: float
    jitter_m: float
    jitter_u_m: float
    n_strokes: int
    n_samples: int
    window_s: float
    periods_removed_m: tuple = ()


@dataclass(frozen=True)
class WitnessChange:
    """One witness statistic against its reference value.

    ``value`` and ``reference`` in m (the lag, the jitter); ``change``, ``uncertainty`` and ``floor`` in
    ``unit`` (m for the lag; 1 for the jitter: the ratio less 1)."""

    name: str
    value: float
    reference: float
    change: float
    uncertainty: float
    unit: str
    z: float
    floor: float
    supported: bool
    relevant: bool
    named: bool
    words: str


def steady_samples(t_s, q_m, q_ref_m, sample_rate_hz: float, *, with_transients: bool = False):
    """The samples in steady motion (bool, shape (n,)): moving, not in the catch-up after a set-point step;
    ``with_transients``: (steady, catch-up) masks.

    The mask of :func:`blf.diagnose.axis_reference.effort_mask` with the dwells and the catch-up transients
    masked (the catch-up ends when :math:`e` stays within 3 robust sigma of its steady value for 0.2 s)."""
    from blf.diagnose.axis_reference import effort_mask
    m = effort_mask(t_s, q_m, q_ref_m, sample_rate_hz, dwell_says_nothing=True, mask_transients=True)
    if not with_transients:
        return m.used
    return m.used, ~m.used & m.moving


def _catch_up(transient: np.ndarray, a: int) -> int:
    """Samples of the catch-up that ends just before sample ``a`` (0 where none does)."""
    k = a
    while k > 0 and transient[k - 1]:
        k -= 1
    return a - k


def _cluster_mean(x: np.ndarray, n: np.ndarray) -> tuple:
    """Sample-weighted mean of per-stroke values and its cluster-robust standard uncertainty."""
    N = float(n.sum())
    m = float(np.sum(n * x) / N)
    G = x.size
    u = float(np.sqrt(G / (G - 1) * np.sum((n * (x - m)) ** 2)) / N)
    return m, u


def _without_periods(fast: np.ndarray, q: np.ndarray, s: np.ndarray, periods, dq: float) -> np.ndarray:
    """``fast`` less its least-squares component at each period in position (orders 1-3 where the travel
    between samples resolves them: :math:`P/h \\ge 2.5\\,\\Delta q`), per direction of motion."""
    out = fast.copy()
    for sign in (1.0, -1.0):
        k = s == sign
        cols = [np.ones(int(k.sum()))]
        for P in periods:
            for h in (1, 2, 3):
                if P / h >= 2.5 * dq:
                    cols += [np.cos(2 * np.pi * h * q[k] / P), np.sin(2 * np.pi * h * q[k] / P)]
        if len(cols) == 1 or k.sum() <= 2 * len(cols):
            continue
        X = np.column_stack(cols)
        coef, *_ = np.linalg.lstsq(X, fast[k], rcond=None)
        out[k] = fast[k] - X[:, 1:] @ coef[1:]
    return out


def tracking_witness(t_s, q_m, q_ref_m, sample_rate_hz: float, window_s: float = 1.0,
                     periods_m=()) -> TrackingWitness:
    """The steady lag and jitter of a recording's tracking error.

    Parameters
    ----------
    t_s, q_m, q_ref_m : array_like, shape (n,)
        Time (s), measured and set-point position (m).
    sample_rate_hz : float
        Hz.
    window_s : float
        The trend's window (s): at least 7 samples, odd.
    periods_m : sequence of float
        Periods in position (m of travel) of a force the effort names (a periodic change): their component
        (orders 1-3, per direction of motion, least squares over all steady samples) is removed from the
        fast part before its RMS, so the jitter is what the named periodic force does **not** account for.

    Returns
    -------
    TrackingWitness

    Raises
    ------
    AnalysisError
        Fewer than two steady strokes at least one window long: no uncertainty can be given.

    Notes
    -----
    Per stroke :math:`k` (:math:`n_k` samples): :math:`L_k = \\overline{e\\,s}` (over the stroke less
    as many samples as its catch-up lasted, :math:`n'_k` of them, at least one window; else the stroke
    gives no lag),
    :math:`M_k = \\overline{(e - \\tilde e)^2}` with :math:`\\tilde e` the quadratic Savitzky-Golay trend over
    the window (less the component at ``periods_m``, where given);
    :math:`L = \\sum n'_k L_k / N'`, :math:`J = \\sqrt{\\sum n_k M_k / N}`,
    :math:`u(\\bar x) = \\sqrt{\\tfrac{G}{G-1}\\sum_k n_k^2 (x_k - \\bar x)^2}/N` over the :math:`G` strokes
    and :math:`u(J) = u(J^2) / 2J`.
    """
    from scipy.signal import savgol_filter
    t = as_1d_finite(t_s, "t_s", "s", min_len=20)
    q = as_1d_finite(q_m, "q_m", "m", min_len=20)
    qr = as_1d_finite(q_ref_m, "q_ref_m", "m", min_len=20)
    same_shape((t, "t_s", "s"), (q, "q_m", "m"), (qr, "q_ref_m", "m"))
    fs = positive_scalar(sample_rate_hz, "sample_rate_hz", "Hz")
    w = max(7, int(round(positive_scalar(window_s, "window_s", "s") * fs)) | 1)
    used, transient = steady_samples(t, q, qr, fs, with_transients=True)
    e, s = qr - q, np.sign(np.gradient(qr, t))
    periods = tuple(positive_scalar(P, "periods_m", "m") for P in periods_m)
    fast = np.full(e.shape, np.nan)
    for a, b in runs(used):
        if b - a >= w:
            fast[a:b] = e[a:b] - savgol_filter(e[a:b], w, 2, mode="interp")
    if periods and np.isfinite(fast).any():
        ok = np.isfinite(fast)
        dq = float(np.median(np.abs(np.diff(q)[ok[1:] & ok[:-1]]))) if ok.sum() > 1 else 0.0
        fast[ok] = _without_periods(fast[ok], q[ok], s[ok], periods, dq)
    lag, n_lag, ms, n = [], [], [], []
    for a, b in runs(used):
        if b - a < w:
            continue
        ms.append(float(np.mean(fast[a:b] ** 2)))
        n.append(b - a)
        c = a + _catch_up(transient, a)
        if b - c >= w:
            lag.append(float(np.mean(e[c:b] * s[c:b])))
            n_lag.append(b - c)
    if len(n) < 2 or len(n_lag) < 2:
        raise AnalysisError(f"{min(len(n), len(n_lag))} steady stroke(s) of at least {w} samples ({w / fs:.3g} s) "
                            "after their catch-up: the tracking error's lag and jitter need two or more")
    n_arr = np.asarray(n, float)
    L, uL = _cluster_mean(np.asarray(lag), np.asarray(n_lag, float))
    M, uM = _cluster_mean(np.asarray(ms), n_arr)
    J = float(np.sqrt(M))
    return TrackingWitness(L, uL, J, uM / (2 * J) if J > 0 else 0.0, len(n), int(n_arr.sum()), w / fs, periods)


def _change(name, value, reference, ch, u, floor, unit, z_min) -> WitnessChange:
    z = ch / u if u > 0 else (np.inf if ch else 0.0)
    sup, rel = bool(abs(z) > z_min), bool(abs(ch) > floor)
    verb = "rose" if ch > 0 else "fell"
    if unit == "1":
        what = (f"from {1e3 * reference:.3g} to {1e3 * value:.3g} mm ({100 * ch:+.1f} ± {100 * u:.1f} %)",
                f"{100 * floor:.3g} %")
    else:
        what = f"from {1e6 * reference:.3g} to {1e6 * value:.3g} um ({1e6 * ch:+.1f} ± {1e6 * u:.1f} um)", \
            f"{1e6 * floor:.3g} um"
    how = (f"named: above its floor of {what[1]}" if sup and rel else
           f"real (z = {z:.1f}) but under its floor of {what[1]}: not named" if sup else
           f"not statistically supported (z = {z:.1f})")
    words = f"{_WORDS[name]} {verb} {what[0]}; {how}"
    return WitnessChange(name, value, reference, ch, u, unit, float(z), floor, sup, rel, sup and rel, words)


def compare_witness(new: TrackingWitness, ref: TrackingWitness, floors: dict, z_min: float = 3.0) -> tuple:
    """The lag's and the jitter's change against the reference.

    Parameters
    ----------
    new, ref : TrackingWitness
    floors : dict
        ``tracking_lag_m`` (m) and ``tracking_jitter_ratio`` (1): the relevance floor of each change.
    z_min : float
        Statistical support: :math:`|\\Delta| > z_{min}\\,u`.

    Returns
    -------
    tuple of WitnessChange
        The lag (:math:`\\Delta = L - L_{ref}`, :math:`u = \\sqrt{u_L^2 + u_{L,ref}^2}`, m) and the jitter
        (:math:`\\Delta = J/J_{ref} - 1`, :math:`u = (1 + \\Delta)\\sqrt{(u_J/J)^2 + (u_{J,ref}/J_{ref})^2}`).
    """
    z_min = positive_scalar(z_min, "z_min", "1")
    f_lag = positive_scalar(floors["tracking_lag_m"], "tracking_lag_m floor", "m")
    f_jit = positive_scalar(floors["tracking_jitter_ratio"], "tracking_jitter_ratio floor", "1")
    if not ref.jitter_m > 0:
        raise AnalysisError("the reference's tracking error has no jitter: nothing to compare a ratio with")
    lag = _change("tracking_lag_m", new.lag_m, ref.lag_m, new.lag_m - ref.lag_m,
                  float(np.hypot(new.lag_u_m, ref.lag_u_m)), f_lag, "m", z_min)
    ratio = new.jitter_m / ref.jitter_m
    u = ratio * float(np.hypot(new.jitter_u_m / new.jitter_m if new.jitter_m > 0 else 0.0,
                               ref.jitter_u_m / ref.jitter_m))
    jit = _change("tracking_jitter_ratio", new.jitter_m, ref.jitter_m, ratio - 1.0, u, f_jit, "1", z_min)
    return lag, jit


def witnesses_disagree(effort_trusted: bool, effort_named: bool, witness: tuple) -> bool:
    """The rule that sets the effort against the tracking error.

    Parameters
    ----------
    effort_trusted : bool
        The effort's own check passed (it sees its known load with the sign its conversion predicts).
    effort_named : bool
        The effort names a change of its mean-force model (a nominal or stroke parameter above its floor). A
        periodic change named does not count: its component is removed from the tracking error's jitter
        (:func:`tracking_witness` ``periods_m``), so a jitter that still rose is one the periodic force does
        not account for (on the Cranfield actuator removing it moves the jitter change by 2.7 points at
        most: the loop follows a 5 mm ripple at 24 mm/s, 4.8 Hz, without a tracking error of its size).
    witness : tuple of WitnessChange
        The tracking error's changes (:func:`compare_witness`).

    Returns
    -------
    bool
        True when the effort is trusted by its own check, names no change, and the tracking error says the
        force the loop fights changed: its lag changed beyond its floor (either sign: the mean force), or its
        jitter **rose** beyond its floor (the force grew rougher: dry or damaged contacts, play).

    Notes
    -----
    Physics: the position loop closes on the measured position, so a change of the force it fights shows in
    its tracking error whatever the effort's conversion does (a current's gain, its offsets, a re-levelling
    in preprocessing). An effort that shows no change then is not trusted to say "no change": a missed
    degradation is the failure a maintenance check must not make. A jitter that **fell** beyond its floor
    (the new recording tracks more smoothly than the reference) contradicts no "no degradation" and is named
    from the witness instead. Where the effort names a change, both witnesses say something changed and the
    effort's change stands (its size is the effort's). A periodic change named beside an untrusted mean
    force stays named: a current's offsets and re-levelling, which make its mean untrustworthy, leave a
    ripple against position within a stroke (a floating mean per direction) as it was.
    """
    return bool(effort_trusted and not effort_named and any(c.named and (c.unit == "m" or c.change > 0)
                                                              for c in witness))


def floor_from_spread(changes) -> float:
    """The floor of a change measured from healthy comparisons: :math:`3\\sqrt{\\overline{\\Delta^2}}`.

    Parameters
    ----------
    changes : array_like, shape (m,)
        The changes between healthy recordings (each pair of references, or two halves of one), in the
        change's unit (m >= 1).

    Returns
    -------
    float
        Three times their RMS: a healthy change exceeds it with a probability of about 0.3 % where the
        changes are normal with zero mean (with few pairs, an estimate of that: the words say how many).
    """
    d = as_1d_finite(changes, "changes", "the change's unit", min_len=1)
    return float(3.0 * np.sqrt(np.mean(d ** 2)))
