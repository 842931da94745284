"""A single positioning axis against a reference recording: what changed, in physical units.

Pure: arrays and a sample rate in, frozen dataclasses out (no IO). The steps,
each a function with its record:

1. :func:`effort_mask` (:class:`EffortMask`): the samples whose effort says
   something about the force. Masked: a dwell (set point standing still) when
   the effort is a supply current (no mechanical power, only the holding
   current), and the catch-up transient after each step of the set point's
   velocity, from the step until the tracking error is back within
   ``3 sigma`` of its steady value (sigma its robust spread) for ``hold_s``.
2. :func:`identifiability` (:class:`Identifiability`): which nominal
   parameters this recording can separate, decided from the data over the
   samples kept: the number of distinct speed levels, both directions of
   motion, acceleration content above its noise, then the variance inflation
   of each regressor column. What it cannot separate is merged (one friction
   at the running speed instead of Coulomb plus viscous; an offset with the
   friction of the one direction) or fixed (the mass at 0), and it says what
   motion would separate them.
3. :func:`fit_axis` (:class:`AxisFit`): the nominal model, linear in its
   parameters, by least squares with a cluster-robust covariance (each
   contiguous stretch of kept samples a cluster: the residual is correlated
   along a stroke, not across strokes).
4. :func:`compare_fits` (:class:`ParameterChange`): each nominal parameter
   against its reference value; a change is *named* only when it is
   statistically supported (``|change| > z_min`` combined standard
   uncertainties) **and** larger than its relevance floor in physical units.

Nominal model (force the drive delivers along +q, N):

.. math:: F = M\\ddot q + F_v\\dot q + F_c\\,\\mathrm{sign}(\\dot q) + F_0 - F_{load}

with :math:`F_{load}` a known external force on the axis (N, positive along
+q), :math:`\\dot q, \\ddot q` Savitzky-Golay derivatives of the measured
position (m/s, m/s^2).

The effort of a recording (a force, torque or current) becomes a force, and is checked against a
known load, in :mod:`blf.diagnose.axis_effort`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.errors import AnalysisError
from blf.maint.segments import runs
from blf.validate import as_1d_finite, positive_scalar, same_shape, scalar

__all__ = ["EffortMask", "Identifiability", "AxisFit", "ParameterChange", "effort_mask", "axis_kinematics",
           "identifiability", "fit_axis", "compare_fits", "design_columns", "separable", "stroke_terms",
           "STROKE_TERMS", "NOMINAL_UNITS"]

#: the nominal parameters and their units
NOMINAL_UNITS = {"mass_kg": "kg", "viscous_N_s_per_m": "N s/m", "coulomb_N": "N", "friction_N": "N",
                 "offset_N": "N", "position_dependent_friction_N_per_m": "N/m",
                 "position_dependent_force_N_per_m": "N/m", "position_dependent_force_N_per_m2": "N/m^2"}
_MOVING = 0.05  #: |set-point velocity| above this fraction of its largest value: moving
_MIN_SHARE = 0.05  #: a speed level or a direction needs this share of the kept samples
_LEVEL_GAP = 0.10  #: speed levels closer than this (relative) are one level
_VIF_MAX = 1e3  #: a column whose variance inflation exceeds this is not separable from the others


@dataclass(frozen=True)
class EffortMask:
    """Samples compared (``used``) and those masked, with where (s)."""

    used: np.ndarray
    moving: np.ndarray
    n_dwell: int
    n_transient: int
    dwell_spans_s: tuple  #: ((t_start, t_end), ...)
    transient_spans_s: tuple
    words: str


@dataclass(frozen=True)
class Identifiability:
    """What this recording can separate: ``columns`` kept, the rest merged or fixed, with reasons."""

    columns: tuple  #: nominal parameter names fitted, in order
    fixed: dict  #: name -> value it is held at
    merged: tuple  #: ((names, into, why, what motion would separate them), ...)
    speed_levels_m_per_s: tuple
    directions: tuple  #: of +1/-1 present
    accel_rms_m_per_s2: float
    accel_noise_m_per_s2: float
    vif: dict  #: column -> variance inflation over the kept samples


@dataclass(frozen=True)
class AxisFit:
    """The nominal model fitted: parameters and standard uncertainties (SI), residual, samples."""

    parameters: dict
    uncertainty: dict
    residual_rms_N: float
    n_used: int
    n_clusters: int
    running_speed_m_per_s: float


@dataclass(frozen=True)
class ParameterChange:
    """A nominal parameter against its reference value (SI units)."""

    name: str
    value: float
    reference: float
    change: float
    uncertainty: float  #: of the change, combined standard
    z: float
    floor: float | None  #: relevance floor, same unit; None: no floor, never named
    supported: bool  #: |z| > z_min
    relevant: bool  #: |change| > floor
    named: bool  #: supported and relevant
    words: str


def axis_kinematics(q_m, sample_rate_hz: float, window_s: float = 0.4):
    """Velocity and acceleration (m/s, m/s^2) of the measured position by a Savitzky-Golay filter.

    Parameters
    ----------
    q_m : array_like, shape (n,)
        Measured position, m.
    sample_rate_hz : float
        Sample rate, Hz.
    window_s : float
        Filter length, s (at least 7 samples, odd; cubic).

    Returns
    -------
    v, a : ndarray
    """
    from scipy.signal import savgol_filter
    q = as_1d_finite(q_m, "q_m", "m", min_len=20)
    fs = positive_scalar(sample_rate_hz, "sample_rate_hz", "Hz")
    w = max(7, int(round(positive_scalar(window_s, "window_s", "s") * fs)) | 1)
    return (savgol_filter(q, w, 3, deriv=1, delta=1 / fs, mode="interp"),
            savgol_filter(q, w, 3, deriv=2, delta=1 / fs, mode="interp"))


def _spans(mask: np.ndarray, t: np.ndarray) -> tuple:
    return tuple((float(t[a]), float(t[b - 1])) for a, b in runs(mask))


def effort_mask(t_s, q_m, q_ref_m, sample_rate_hz: float, *, dwell_says_nothing: bool,
                mask_transients: bool, hold_s: float = 0.2) -> EffortMask:
    """The samples whose effort says something about the force.

    Parameters
    ----------
    t_s, q_m, q_ref_m : array_like, shape (n,)
        Time (s), measured and set-point position (m).
    sample_rate_hz : float
        Hz.
    dwell_says_nothing : bool
        Mask the set point's dwells (a supply current at standstill is the holding current; standing
        still, a friction force is anywhere in its static band).
    mask_transients : bool
        Mask the catch-up after each step of the set point's velocity.
    hold_s : float
        How long the tracking error must stay within 3 sigma to end a transient, s.

    Returns
    -------
    EffortMask

    Notes
    -----
    Moving: :math:`|\\dot q_{ref}| > 0.05 \\max|\\dot q_{ref}|`. Tracking error
    :math:`e = q_{ref} - q`; its steady value per direction is the median over
    the moving samples and sigma :math:`1.4826\\,\\mathrm{MAD}` (robust to
    the transients, a minority of the samples).
    """
    t = as_1d_finite(t_s, "t_s", "s", min_len=20)
    q = as_1d_finite(q_m, "q_m", "m", min_len=20)
    qr = as_1d_finite(q_ref_m, "q_ref_m", "m", min_len=20)
    same_shape((t, "t_s", "s"), (q, "q_m", "m"), (qr, "q_ref_m", "m"))
    fs = positive_scalar(sample_rate_hz, "sample_rate_hz", "Hz")
    vr = np.gradient(qr, t)
    vmax = float(np.max(np.abs(vr)))
    if vmax <= 0:
        raise AnalysisError("the set point never moves: nothing to compare")
    moving = np.abs(vr) > _MOVING * vmax
    dwell = ~moving if dwell_says_nothing else np.zeros(t.size, bool)
    transient = np.zeros(t.size, bool)
    if mask_transients:
        transient = _transients(q, qr, vr, vmax, moving, max(2, int(round(hold_s * fs)))) & ~dwell
    used = ~dwell & ~transient
    words = (f"{int(dwell.sum())} samples of dwell (standing still) and {int(transient.sum())} of catch-up "
             f"after a set-point step masked; {int(used.sum())} of {t.size} compared")
    return EffortMask(used, moving, int(dwell.sum()), int(transient.sum()), _spans(dwell, t),
                      _spans(transient, t), words)


def _transients(q, qr, vr, vmax, moving, hold) -> np.ndarray:
    e = qr - q
    steady = np.zeros_like(e)
    for s in (1, -1):
        sel = moving & (np.sign(vr) == s)
        if sel.any():
            steady[np.sign(vr) == s] = np.median(e[sel])
    sel = moving if moving.any() else np.ones(e.size, bool)
    dev = e[sel] - steady[sel]
    sigma = 1.4826 * float(np.median(np.abs(dev - np.median(dev)))) or float(np.std(dev)) or 1e-12
    calm = np.abs(e - steady) <= 3 * sigma
    steps = np.flatnonzero(np.abs(np.diff(vr)) > _MOVING * vmax) + 1
    if moving[0]:  # a recording that starts moving starts with a step
        steps = np.r_[0, steps]
    out = np.zeros(e.size, bool)
    for k in steps:
        j = k
        while j < e.size and not calm[j:j + hold].all():
            j += 1
        out[k:j] = True
    return out


def _levels(speeds: np.ndarray) -> tuple:
    """Speed levels: gaps of more than 10 % split the sorted speeds; a group that itself spans a range
    (5th to 95th percentile more than 1.5 apart: a speed varying continuously) gives its two ends."""
    if speeds.size == 0:
        return ()
    s = np.sort(speeds)
    groups, start = [], 0
    for i in range(1, s.size + 1):
        if i == s.size or s[i] > s[i - 1] * (1 + _LEVEL_GAP):
            groups.append(s[start:i])
            start = i
    out = []
    for g in (g for g in groups if g.size >= _MIN_SHARE * s.size):
        lo, hi = np.percentile(g, [5, 95])
        out += [float(lo), float(hi)] if hi > 1.5 * lo else [float(np.median(g))]
    return tuple(out)


def _vif(X: np.ndarray) -> np.ndarray:
    out = np.empty(X.shape[1])
    for j in range(X.shape[1]):
        others = np.delete(X, j, axis=1)
        y = X[:, j]
        if others.shape[1] == 0:
            out[j] = 1.0
            continue
        r = y - others @ np.linalg.lstsq(others, y, rcond=None)[0]
        ss = float(y @ y)
        out[j] = np.inf if ss == 0 else ss / max(float(r @ r), ss * 1e-16)
    return out


def identifiability(v_m_per_s, a_m_per_s2, v_ref_m_per_s, used, accel_noise_m_per_s2: float) -> Identifiability:
    """Which nominal parameters the kept samples can separate, decided from the data.

    Parameters
    ----------
    v_m_per_s, a_m_per_s2 : array_like, shape (n,)
        Velocity and acceleration of the measured position (m/s, m/s^2).
    v_ref_m_per_s : array_like, shape (n,)
        Set-point velocity, m/s (its levels are the speeds the recording runs at).
    used : array_like of bool, shape (n,)
        The samples compared (:class:`EffortMask`).
    accel_noise_m_per_s2 : float
        Standard deviation of the acceleration's noise, m/s^2.

    Returns
    -------
    Identifiability

    Notes
    -----
    Rules, in order: the mass needs acceleration content,
    :math:`\\mathrm{rms}(\\ddot q) > 3\\sigma_{\\ddot q}` over the kept samples,
    else it is fixed at 0; at fewer than two speed levels (levels of
    :math:`|\\dot q_{ref}|` more than 10 % apart, each with >= 5 % of the kept
    moving samples) Coulomb and viscous friction are one friction at the
    running speed (``friction_N``); with one direction only the offset is
    merged into it; then any column with variance inflation above 1000 is
    merged into the others.
    """
    v = as_1d_finite(v_m_per_s, "v_m_per_s", "m/s")
    a = as_1d_finite(a_m_per_s2, "a_m_per_s2", "m/s^2")
    vr = as_1d_finite(v_ref_m_per_s, "v_ref_m_per_s", "m/s")
    u = np.asarray(used, bool)
    same_shape((v, "v", "m/s"), (a, "a", "m/s^2"), (vr, "v_ref", "m/s"), (u, "used", ""))
    noise = scalar(accel_noise_m_per_s2, "accel_noise_m_per_s2", "m/s^2", lo=0)
    vmax = float(np.max(np.abs(vr[u]))) if u.any() else 0.0
    mov = u & (np.abs(vr) > _MOVING * vmax)
    levels = _levels(np.abs(vr[mov]))
    dirs = tuple(s for s in (1, -1) if np.sum(np.sign(vr[mov]) == s) >= _MIN_SHARE * max(1, mov.sum()))
    a_rms = float(np.sqrt(np.mean(a[u] ** 2))) if u.any() else 0.0
    cols = ["mass_kg", "viscous_N_s_per_m", "coulomb_N", "offset_N"]
    fixed, merged = {}, []
    if a_rms <= 3 * noise:
        cols.remove("mass_kg")
        fixed["mass_kg"] = 0.0
        merged.append((("mass_kg",), "", f"no acceleration above its noise in the samples compared "
                       f"(rms {a_rms:.3g} m/s^2 against noise {noise:.3g} m/s^2): the mass is held at 0",
                       "accelerations the effort follows (a sinusoidal set point or a slower ramp)"))
    if len(levels) < 2:
        cols[cols.index("coulomb_N")] = "friction_N"
        cols.remove("viscous_N_s_per_m")
        merged.append((("coulomb_N", "viscous_N_s_per_m"), "friction_N",
                       "one speed level: Coulomb and viscous friction (a force in |v| or a constant) are one "
                       "friction at the running speed", "a second speed level"))
    if len(dirs) < 2:
        cols.remove("offset_N")
        fixed["offset_N"] = 0.0
        merged.append((("offset_N",), cols[-1], "one direction of motion: an offset and the friction are one force",
                       "a reversal under the same load"))
    X = _design(cols, v, a)[u]
    vif = dict(zip(cols, _vif(X).tolist(), strict=True)) if X.size else {}
    for name in [c for c in cols if vif.get(c, 1.0) > _VIF_MAX and c != "offset_N"]:
        cols.remove(name)
        fixed[name] = 0.0
        merged.append(((name,), "", f"variance inflation {vif[name]:.3g} over the samples compared: "
                       "not separable from the other terms", "motion that excites it on its own"))
    return Identifiability(tuple(cols), fixed, tuple(merged), levels, dirs, a_rms, noise, vif)


#: terms along the stroke screened against a reference (name -> words)
STROKE_TERMS = {"position_dependent_friction_N_per_m": "friction that varies along the stroke",
                "position_dependent_force_N_per_m": "a force that varies linearly along the stroke",
                "position_dependent_force_N_per_m2": "a force that varies quadratically along the stroke"}


def stroke_terms(q_m, v_m_per_s, origin_m: float) -> dict:
    """Columns of the terms along the stroke (:data:`STROKE_TERMS`), about ``origin_m``.

    .. math:: \\tilde q\\,\\mathrm{sign}(\\dot q),\\quad \\tilde q,\\quad \\tilde q^2,
              \\qquad \\tilde q = q - q_0

    (N per m, N per m, N per m^2 once fitted). Both recordings of a comparison use the same origin.
    """
    q = as_1d_finite(q_m, "q_m", "m")
    qc = q - scalar(origin_m, "origin_m", "m")
    s = np.sign(as_1d_finite(v_m_per_s, "v_m_per_s", "m/s"))
    return dict(zip(STROKE_TERMS, (qc * s, qc, qc * qc), strict=True))


def design_columns(cols, v_m_per_s, a_m_per_s2) -> np.ndarray:
    """The nominal model's regressor columns ``cols`` (names of :data:`NOMINAL_UNITS`), shape (n, len(cols))."""
    return _design(tuple(cols), np.asarray(v_m_per_s, float), np.asarray(a_m_per_s2, float))


def separable(nominal, term) -> bool:
    """Whether a term's columns can be told apart from the nominal columns (and from each other).

    Parameters
    ----------
    nominal : array_like, shape (n, p)
        The nominal model's regressor columns over the samples compared.
    term : array_like, shape (n, m)
        The term's columns (its sensitivities) over the same samples.

    Returns
    -------
    bool
        False when any of the term's columns has a variance inflation above 1000 against the others
        (:math:`\\|r\\|^2 < 10^{-3}\\|x\\|^2`, r its part not in the span of the others): e.g. a friction
        in :math:`|\\dot q|` against an offset at one speed, a Stribeck curve against a Coulomb
        friction at one speed.
    """
    X = np.column_stack([np.asarray(nominal, float), np.asarray(term, float)])
    m = np.asarray(term).reshape(X.shape[0], -1).shape[1]
    return bool(np.all(_vif(X)[-m:] <= _VIF_MAX))


def _design(cols, v, a) -> np.ndarray:
    s = np.sign(v)
    col = {"mass_kg": a, "viscous_N_s_per_m": v, "coulomb_N": s, "friction_N": s, "offset_N": np.ones_like(v)}
    return np.column_stack([col[c] for c in cols]) if cols else np.zeros((v.size, 0))


def fit_axis(force_N, v_m_per_s, a_m_per_s2, used, ident: Identifiability, load_N=None, extra=None) -> AxisFit:
    """Least-squares fit of the identifiable nominal parameters, cluster-robust uncertainties.

    Parameters
    ----------
    force_N : array_like, shape (n,)
        Force the drive delivers along +q, N.
    v_m_per_s, a_m_per_s2 : array_like, shape (n,)
    used : array_like of bool, shape (n,)
    ident : Identifiability
    load_N : array_like, shape (n,), optional
        Known external force on the axis, N (positive along +q); added to the force.
    extra : dict, optional
        Further terms fitted beside the nominal ones: name -> column, shape (n,) (e.g.
        :func:`stroke_terms`).

    Returns
    -------
    AxisFit

    Notes
    -----
    :math:`\\hat\\theta = (X^TX)^{-1}X^Ty`, covariance
    :math:`\\frac{G}{G-1}(X^TX)^{-1}\\sum_g X_g^T r_g r_g^T X_g (X^TX)^{-1}`
    over the :math:`G` contiguous stretches of kept samples.
    """
    F = as_1d_finite(force_N, "force_N", "N")
    v = as_1d_finite(v_m_per_s, "v_m_per_s", "m/s")
    a = as_1d_finite(a_m_per_s2, "a_m_per_s2", "m/s^2")
    u = np.asarray(used, bool)
    same_shape((F, "force_N", "N"), (v, "v", "m/s"), (a, "a", "m/s^2"), (u, "used", ""))
    y = F + (0.0 if load_N is None else as_1d_finite(load_N, "load_N", "N"))
    extra = dict(extra or {})
    cols = list(ident.columns) + list(extra)
    if not ident.columns or u.sum() < 3 * len(cols) + 10:
        raise AnalysisError(f"{int(u.sum())} samples compared: too few to identify the nominal model")
    X = _design(ident.columns, v, a)
    if extra:
        X = np.column_stack([X] + [as_1d_finite(c, n, "1") for n, c in extra.items()])
    idx = np.flatnonzero(u)
    Xu, yu = X[idx], y[idx]
    theta, *_ = np.linalg.lstsq(Xu, yu, rcond=None)
    r = yu - Xu @ theta
    cluster = np.cumsum(np.r_[1, np.diff(idx) > 1])
    G = int(cluster[-1])
    bread = np.linalg.pinv(Xu.T @ Xu)
    meat = np.zeros((len(cols), len(cols)))
    for g in range(1, G + 1):
        sg = Xu[cluster == g].T @ r[cluster == g]
        meat += np.outer(sg, sg)
    cov = bread @ meat @ bread * (G / max(G - 1, 1))
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    par = dict(zip(cols, theta.tolist(), strict=True)) | dict(ident.fixed)
    unc = dict(zip(cols, sd.tolist(), strict=True)) | {k: 0.0 for k in ident.fixed}
    speed = float(np.median(np.abs(v[idx][np.abs(v[idx]) > 0]))) if np.any(v[idx]) else 0.0
    return AxisFit(par, unc, float(np.sqrt(np.mean(r ** 2))), int(idx.size), G, speed)


_CHANGE_WORDS = {
    "friction_N": "friction at the running speed (both directions alike; from a supply current, the drive's own "
                  "loss at that speed reads as friction too)",
    "coulomb_N": "Coulomb friction", "viscous_N_s_per_m": "viscous friction", "mass_kg": "moving mass",
    "position_dependent_friction_N_per_m": "friction varying along the stroke (slope)",
    "position_dependent_force_N_per_m": "a force varying linearly along the stroke (slope)",
    "position_dependent_force_N_per_m2": "a force varying quadratically along the stroke (curvature)",
    "offset_N": "a force in one direction: an offset, a friction that differs with direction or a load other "
                "than the one stated (this recording cannot tell them apart)",
}


def compare_fits(new: AxisFit, ref: AxisFit, floors: dict, z_min: float = 3.0) -> tuple:
    """Each nominal parameter fitted on both recordings against its reference value.

    Parameters
    ----------
    new, ref : AxisFit
        The recording diagnosed and the reference (healthy) one.
    floors : dict
        Parameter name -> relevance floor in its unit (SI); a parameter without one is never named.
    z_min : float
        Statistical support: :math:`|\\Delta| > z_{min}\\sqrt{u_{new}^2 + u_{ref}^2}`.

    Returns
    -------
    tuple of ParameterChange
        Only parameters fitted (not fixed) on both.
    """
    z_min = positive_scalar(z_min, "z_min", "1")
    out = []
    for name, val in new.parameters.items():
        if name not in ref.parameters or new.uncertainty[name] == 0 or ref.uncertainty.get(name, 0) == 0:
            continue
        ch = val - ref.parameters[name]
        u = float(np.hypot(new.uncertainty[name], ref.uncertainty[name]))
        z = ch / u if u > 0 else np.inf
        fl = floors.get(name)
        sup, rel = bool(abs(z) > z_min), bool(fl is not None and abs(ch) > fl)
        unit = NOMINAL_UNITS.get(name, "")
        verb = "increased" if ch > 0 else "decreased"
        if sup and rel:
            how = f"named: above its floor of {fl:.4g} {unit}"
        elif sup:
            how = (f"real (z = {z:.1f}) but under its floor of {fl:.4g} {unit}: not named" if fl is not None else
                   f"real (z = {z:.1f}); no floor for it: not named")
        else:
            how = f"not statistically supported (z = {z:.1f})"
        words = f"{_CHANGE_WORDS.get(name, name)} {verb} by {abs(ch):.4g} ± {u:.2g} {unit}; {how}"
        out.append(ParameterChange(name, val, ref.parameters[name], ch, u, float(z), fl, sup, rel, sup and rel,
                                   words))
    return tuple(out)


