"""Normal-operation scenarios of the dual-EMA aileron: what the surface does in service.

In service both EMAs run in POSITION mode and follow the same surface
command (active-active); a slow force-fight compensation equalises their
forces by small opposite offsets; the air load on the surface changes with
its deflection (hinge moment) and with gusts. Backlash is crossed only where
a load-path force changes sign, so every manoeuvre here is built around a
sign change of the load (or, for the external play, of the force fight).

The profile generators (:func:`full_stroke_profile`,
:func:`small_manoeuvre_profile`, :func:`gust_profile`, :func:`cruise_profile`,
:func:`ext_crossing_profile`, listed by name in :data:`SCENARIOS`) return
sample arrays of the surface command, the external load and optionally a
scheduled force-fight offset, as an :class:`OperationProfile`;
:mod:`sim.operation` runs them on the plant. ``emacheck simulate --scenario
NAME`` writes such a recording for BLFserv. Pure: parameters and an explicit
``numpy.random.Generator`` in, frozen dataclasses out; no clocks, no IO.

Sign conventions are those of :mod:`sim.plant`: positions on the ram axis,
positive extended; forces positive in compression (the EMA pushes the
surface towards +y); the load ``load_N`` pushes the surface towards +y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blf.errors import InputError
from blf.validate import count, generator, instance_of, scalar
from sim.params import RigParams
from sim.truth import chain_stiffness_N_per_mm, force_fight_play_mm, series_stiffness

__all__ = ["AirLoad", "AIR", "OperationProfile", "SCENARIOS", "scenario_profile", "full_stroke_profile",
           "small_manoeuvre_profile", "gust_profile", "cruise_profile", "ext_crossing_profile"]

@dataclass(frozen=True)
class AirLoad:
    """The air on the surface and the force-fight compensation of a normal-operation profile.

    Attributes
    ----------
    aero_stiffness_N_per_mm : float
        Hinge-load stiffness :math:`k_a`, N/mm: the air adds
        :math:`-k_a (y - y_0)` to the surface force (default 1000).
    zero_load_mm : float
        Surface deflection :math:`y_0` of zero hinge load, mm (default 2).
    ff_bandwidth_rad_s : float
        Bandwidth of the force-fight compensation loop, rad/s (default 1; 0: off).
    """

    aero_stiffness_N_per_mm: float = 1000.0
    zero_load_mm: float = 2.0
    ff_bandwidth_rad_s: float = 1.0


#: The default air load of the profiles.
AIR = AirLoad()


@dataclass(frozen=True)
class OperationProfile:
    """What the flight control computer and the air do during one manoeuvre.

    Attributes
    ----------
    name : str
        Short name (``"full_stroke"``, ``"small_manoeuvres"``, ...).
    description : str
        One sentence on what happens physically.
    sample_period_s : float
        Sample period of the arrays, s.
    command_mm : ndarray, shape (n,)
        Surface command on the ram axis per sample, mm (both EMAs).
    load_N : ndarray, shape (n,)
        External surface force per sample apart from the deflection-dependent
        hinge load (gusts, trim bias), N, + towards +y.
    aero_stiffness_N_per_mm : float
        Hinge-load stiffness, N/mm: the air adds
        ``-aero_stiffness_N_per_mm * (y - zero_load_mm)`` to the surface force.
    zero_load_mm : float
        Surface position at which the hinge load is zero, mm.
    offset_mm : ndarray, shape (n,), or None
        Scheduled relative offset ``delta`` of the two motors, mm (EMA 1 at
        ``command + delta/2``, EMA 2 at ``command - delta/2``); None: the
        force-fight compensation loop sets it (see :func:`sim.operation.simulate_operation`).
    lag2_samples : int
        Transport delay of EMA 2's command, samples (0: none).
    ff_bandwidth_rad_s : float
        Bandwidth of the force-fight compensation loop, rad/s (0: off).
    warmup_s : float
        Settling time simulated before the record starts (drives engaged,
        load applied), s; not part of the arrays above.

    Arrays are read-only.
    """

    name: str
    description: str
    sample_period_s: float
    command_mm: np.ndarray
    load_N: np.ndarray
    aero_stiffness_N_per_mm: float
    zero_load_mm: float
    offset_mm: np.ndarray | None
    lag2_samples: int
    ff_bandwidth_rad_s: float
    warmup_s: float

    @property
    def n(self) -> int:
        """Number of recorded samples."""
        return int(self.command_mm.size)


def _ro(a) -> np.ndarray:
    out = np.array(a, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out


def _params(params) -> RigParams:
    return instance_of(params, RigParams, "params", "a sim.params.RigParams")


def _air(p: RigParams, air: AirLoad) -> tuple[float, float, float]:
    """The air-load options, validated: (k_a N/mm, y_0 mm, w_ff rad/s)."""
    instance_of(air, AirLoad, "air", "an AirLoad")
    return (scalar(air.aero_stiffness_N_per_mm, "air.aero_stiffness_N_per_mm", "N/mm", lo=0.0),
            scalar(air.zero_load_mm, "air.zero_load_mm", "mm", lo=-p.stroke_limit_mm, hi=p.stroke_limit_mm),
            scalar(air.ff_bandwidth_rad_s, "air.ff_bandwidth_rad_s", "rad/s", lo=0.0))


def _at_trim(params, rng, duration_s, trim_mm) -> tuple:
    """Options of the profiles held at trim, validated: (params, rng, duration s, trim mm, period s, samples)."""
    p = _params(params)
    r = generator(rng)
    dur = scalar(duration_s, "duration_s", "s", lo=0.0, lo_open=True, hi=3600.0)
    trim = scalar(trim_mm, "trim_mm", "mm", lo=-p.stroke_limit_mm, hi=p.stroke_limit_mm)
    return p, r, dur, trim, p.sample_period_s, int(math.ceil(dur / p.sample_period_s))


def _trapezoid_move(t: np.ndarray, t0: float, y0: float, y1: float, rate: float, accel: float) -> tuple:
    """Positions of a rate- and acceleration-limited move from y0 to y1 starting at t0; and its end time."""
    d = abs(y1 - y0)
    sgn = 1.0 if y1 >= y0 else -1.0
    ta = rate / accel
    v = rate
    if d < v * ta:
        ta = math.sqrt(d / accel)
        v = accel * ta
    tc = (d - v * ta) / v if v > 0 else 0.0
    tau = t - t0
    s = np.where(tau <= 0, 0.0, 0.0)
    s = np.where((tau > 0) & (tau <= ta), 0.5 * accel * tau**2, s)
    s = np.where((tau > ta) & (tau <= ta + tc), 0.5 * accel * ta**2 + v * (tau - ta), s)
    r = 2 * ta + tc - tau
    s = np.where((tau > ta + tc) & (tau <= 2 * ta + tc), d - 0.5 * accel * r**2, s)
    s = np.where(tau > 2 * ta + tc, d, s)
    return y0 + sgn * s, t0 + 2 * ta + tc


def _smooth_noise(rng: np.random.Generator, n: int, std: float, bandwidth_rad_s: float,
                  period_s: float) -> np.ndarray:
    """Stationary second-order (critically damped) Gauss-Markov sequence of standard deviation ``std``.

    White noise through two identical first-order low-passes with corner
    ``bandwidth_rad_s`` (exact pole ``a = exp(-w T)``), scaled by the filter's
    noise gain to ``std``; ``ceil(10 / (w T))`` leading samples are discarded so
    the sequence starts in steady state.
    """
    a = math.exp(-bandwidth_rad_s * period_s)
    nw = int(math.ceil(10.0 / (bandwidth_rad_s * period_s)))
    e = rng.standard_normal(n + nw)
    b1 = np.array([1.0 - a])
    a1 = np.array([1.0, -a])
    from scipy import signal  # here, not at import: `emacheck --help` lists the scenarios without scipy

    x = signal.lfilter(b1, a1, signal.lfilter(b1, a1, e))
    # noise gain of the cascade (1 - a)^2 / (1 - a z^-1)^2: sum h_k^2 = (1-a)^4 (1 + a^2) / (1 - a^2)^3
    gain = (1.0 - a) ** 2 * math.sqrt((1.0 + a * a) / (1.0 - a * a) ** 3)
    return x[nw:] * (std / gain)


def _profile(name, description, period, command, load, aero_k, zero_mm, offset, lag, ff_bw, warmup):
    return OperationProfile(
        name=name, description=description, sample_period_s=float(period),
        command_mm=_ro(command), load_N=_ro(load), aero_stiffness_N_per_mm=float(aero_k),
        zero_load_mm=float(zero_mm), offset_mm=None if offset is None else _ro(offset),
        lag2_samples=int(lag), ff_bandwidth_rad_s=float(ff_bw), warmup_s=float(warmup))


def full_stroke_profile(
    params: RigParams,
    *,
    rate_mm_per_s: float = 40.0,
    accel_mm_per_s2: float = 400.0,
    stroke_fraction: float = 0.9,
    cycles: int = 1,
    dwell_s: float = 1.0,
    air: AirLoad = AIR,
) -> OperationProfile:
    """Full stroke at full rate with force-fight compensation (paper Figure 7).

    Parameters
    ----------
    params : RigParams
        The rig (stroke limit, sample period).
    rate_mm_per_s : float, optional
        Surface rate on the ram axis, mm/s (default 40, below the 50 mm/s cap).
    accel_mm_per_s2 : float, optional
        Acceleration limit of the command, mm/s^2 (default 400).
    stroke_fraction : float, optional
        The surface moves between ``-/+ stroke_fraction * stroke_limit_mm``
        (default 0.9, i.e. +-18 mm).
    cycles : int, optional
        Number of out-and-back strokes (default 1).
    dwell_s : float, optional
        Hold at each end and at the start, s (default 1).
    air : AirLoad, optional
        Hinge load and force-fight compensation (default :data:`AIR`:
        1000 N/mm, +-18 kN at the ends; zero load at 2 mm, so the load changes
        sign once on every stroke, there the backlash is crossed).

    Returns
    -------
    OperationProfile

    Notes
    -----
    Command: rate- and acceleration-limited moves (trapezoidal velocity)
    :math:`-A \\to +A \\to -A`, :math:`A` = ``stroke_fraction`` x
    ``stroke_limit_mm``. Air load on the surface
    :math:`L = -k_a (y - y_0)` [N] with :math:`k_a` in N/mm, :math:`y`,
    :math:`y_0` in mm; the EMAs share it, :math:`F_1 \\approx F_2 \\approx
    -(L + m\\ddot y)/2`. Both forces change sign as :math:`y` passes
    :math:`y_0`; the surface then floats through the play of both chains
    under the small, growing net load (about 20 ms here) and hits the other
    flank; both internal plays are crossed, the external one is not (same-
    sense change, :math:`D_{ext}` jumps by :math:`B_{b,2} - B_{b,1} = 0`).
    """
    p = _params(params)
    rate = scalar(rate_mm_per_s, "rate_mm_per_s", "mm/s", lo=0.0, lo_open=True, hi=50.0)
    acc = scalar(accel_mm_per_s2, "accel_mm_per_s2", "mm/s^2", lo=0.0, lo_open=True)
    frac = scalar(stroke_fraction, "stroke_fraction", "(fraction of stroke_limit_mm)", lo=0.0, lo_open=True, hi=0.95)
    cycles = count(cycles, "cycles", 1, 100)
    dwell = scalar(dwell_s, "dwell_s", "s", lo=0.0)
    ka, y0, ffb = _air(p, air)
    T = p.sample_period_s
    a = frac * p.stroke_limit_mm
    # plan the moves
    moves = []
    t0 = dwell
    ya = -a
    for _ in range(int(cycles)):
        for yb in (a, -a):
            tt = np.array([0.0])
            _, t_end = _trapezoid_move(tt, t0, ya, yb, rate, acc)
            moves.append((t0, ya, yb))
            t0 = t_end + dwell
            ya = yb
    n = int(math.ceil(t0 / T))
    t = np.arange(1, n + 1) * T
    y = np.full(n, -a)
    for (ts, ya, yb) in moves:
        pos, te = _trapezoid_move(t, ts, ya, yb, rate, acc)
        m = t > ts
        y[m] = pos[m]
    load = np.full(n, ka * y0)  # L = -ka*y (plant load stiffness) + ka*y0
    return _profile("full_stroke",
                    f"full stroke +-{a:g} mm at {rate:g} mm/s, hinge load {ka:g} N/mm, zero load at {y0:g} mm",
                    T, y, load, ka, y0, None, 0, ffb, 1.5)


def small_manoeuvre_profile(
    params: RigParams,
    *,
    amplitude_mm: float = 1.5,
    frequencies_Hz: tuple = (0.5, 1.0, 1.5, 0.75),
    dwell_s: float = 0.8,
    trim_mm: float = 2.5,
    air: AirLoad = AIR,
) -> OperationProfile:
    """Small-amplitude manoeuvres about a trim where the hinge load is near zero.

    Parameters
    ----------
    params : RigParams
    amplitude_mm : float, optional
        Amplitude of each manoeuvre, mm (default 1.5).
    frequencies_Hz : tuple of float, optional
        One full sine period per entry, at that frequency, Hz (default
        0.5, 1, 1.5, 0.75 Hz).
    dwell_s : float, optional
        Hold at trim before, between and after the manoeuvres, s (default 0.8).
    trim_mm : float, optional
        Trim deflection, mm (default 2.5: 500 N of hinge load, both chains
        in contact at trim).
    air : AirLoad, optional
        Hinge load :math:`L = -k_a (y - y_0)` and force-fight compensation
        (default :data:`AIR`: 1000 N/mm, 2 mm, 1 rad/s).

    Returns
    -------
    OperationProfile

    Notes
    -----
    Command :math:`y = y_{trim} + A \\sin(2\\pi f (t - t_j))` over one period
    per manoeuvre. The hinge load :math:`-k_a (y - y_0)` (-500 N at trim,
    -2 kN to +1 kN during a manoeuvre) changes sign twice per manoeuvre, at
    rates up to :math:`2\\pi f k_a A` = 4.7 to 14 kN/s; both internal plays are
    crossed at each sign change.
    """
    p = _params(params)
    amp = scalar(amplitude_mm, "amplitude_mm", "mm", lo=0.0, lo_open=True, hi=0.5 * p.stroke_limit_mm)
    freqs = np.asarray(frequencies_Hz, dtype=float)
    if freqs.ndim != 1 or freqs.size < 1 or not np.all(np.isfinite(freqs)) or np.any(freqs <= 0) or np.any(freqs > 10):
        raise InputError(f"frequencies_Hz must be a 1-D sequence of values in (0, 10] Hz, got {frequencies_Hz!r} "
                         f"(shape {np.shape(frequencies_Hz)})")
    dwell = scalar(dwell_s, "dwell_s", "s", lo=0.0)
    trim = scalar(trim_mm, "trim_mm", "mm", lo=-p.stroke_limit_mm + amp, hi=p.stroke_limit_mm - amp)
    ka, y0, ffb = _air(p, air)
    T = p.sample_period_s
    total = dwell + float(np.sum(1.0 / freqs + dwell))
    n = int(math.ceil(total / T))
    t = np.arange(1, n + 1) * T
    y = np.full(n, trim)
    ts = dwell
    for f in freqs:
        m = (t > ts) & (t <= ts + 1.0 / f)
        y[m] = trim + amp * np.sin(2 * np.pi * f * (t[m] - ts))
        ts += 1.0 / f + dwell
    load = np.full(n, ka * y0)
    return _profile("small_manoeuvres",
                    f"{freqs.size} sine manoeuvres of {amp:g} mm at {', '.join(f'{f:g}' for f in freqs)} Hz "
                    f"about trim {trim:g} mm (hinge load zero at {y0:g} mm)",
                    T, y, load, ka, y0, None, 0, ffb, 1.5)


def gust_profile(
    params: RigParams,
    rng: np.random.Generator,
    *,
    duration_s: float = 20.0,
    gust_std_N: float = 1500.0,
    gust_bandwidth_rad_s: float = 3.0,
    trim_mm: float = 2.0,
    air: AirLoad = AIR,
) -> OperationProfile:
    """Surface held at trim, random gust load (turbulence).

    Parameters
    ----------
    params : RigParams
    rng : numpy.random.Generator
        Source of the gust sequence.
    duration_s : float, optional
        s (default 20).
    gust_std_N : float, optional
        Standard deviation of the gust force on the surface, N (default 1500).
    gust_bandwidth_rad_s : float, optional
        Corner of the (second-order) gust spectrum, rad/s (default 3).
    trim_mm : float, optional
        Trim deflection, mm (default 2: at the zero-load deflection, so the
        mean load is zero and the gusts change its sign at random).
    air : AirLoad, optional
        As in :func:`small_manoeuvre_profile`.

    Returns
    -------
    OperationProfile

    Notes
    -----
    Gust force: a stationary, critically damped second-order Gauss-Markov
    process (white noise through :math:`\\omega_g^2/(s + \\omega_g)^2`, the
    surface's aerodynamic lag smoothing the turbulence; exact discretisation),
    scaled to ``gust_std_N`` [N]. Its path is differentiable, so the load
    passes zero at a definite rate; a first-order (Ornstein-Uhlenbeck) gust
    would be a random walk on short time scales and chatter through zero.
    With the trim at the zero-load deflection the mean load is zero and the
    gusts change its sign at random times and rates.
    """
    p, r, dur, trim, T, n = _at_trim(params, rng, duration_s, trim_mm)
    gs = scalar(gust_std_N, "gust_std_N", "N", lo=0.0)
    gb = scalar(gust_bandwidth_rad_s, "gust_bandwidth_rad_s", "rad/s", lo=0.0, lo_open=True)
    ka, y0, ffb = _air(p, air)
    gust = _smooth_noise(r, n, gs, gb, T)
    y = np.full(n, trim)
    load = ka * y0 + gust
    return _profile("gusts", f"surface at trim {trim:g} mm, gusts {gs:g} N rms, {gb:g} rad/s",
                    T, y, load, ka, y0, None, 0, ffb, 1.5)


def cruise_profile(
    params: RigParams,
    rng: np.random.Generator,
    *,
    duration_s: float = 20.0,
    trim_mm: float = -2.0,
    turbulence_std_N: float = 200.0,
    turbulence_bandwidth_rad_s: float = 3.0,
    command_jitter_mm: float = 0.05,
    air: AirLoad = AIR,
) -> OperationProfile:
    """Quiet cruise: trim away from zero load, light turbulence; backlash never crossed.

    Parameters
    ----------
    params : RigParams
    rng : numpy.random.Generator
        Source of the turbulence and of the small command corrections.
    duration_s : float, optional
        s (default 20).
    trim_mm : float, optional
        Trim deflection, mm (default -2: 4 kN of hinge load, 2 kN per EMA).
    turbulence_std_N : float, optional
        Standard deviation of the turbulence force, N (default 200).
    turbulence_bandwidth_rad_s : float, optional
        Corner of the turbulence spectrum, rad/s (default 3; second order as
        in :func:`gust_profile`).
    command_jitter_mm : float, optional
        Standard deviation of slow autopilot corrections of the command, mm
        (default 0.05; bandwidth 1 rad/s).
    air : AirLoad, optional
        As in :func:`full_stroke_profile`.

    Returns
    -------
    OperationProfile

    Notes
    -----
    Surface force :math:`L = -k_a (y - y_0) + g(t)` with
    :math:`k_a (y_0 - y_{trim})` = 4 kN against a turbulence of 200 N rms
    (a 20-sigma margin): the forces never change sign, so no play is
    crossed and BLFserv must report "not traversed".
    """
    p, r, dur, trim, T, n = _at_trim(params, rng, duration_s, trim_mm)
    ts = scalar(turbulence_std_N, "turbulence_std_N", "N", lo=0.0)
    tb = scalar(turbulence_bandwidth_rad_s, "turbulence_bandwidth_rad_s", "rad/s", lo=0.0, lo_open=True)
    cj = scalar(command_jitter_mm, "command_jitter_mm", "mm", lo=0.0, hi=1.0)
    ka, y0, ffb = _air(p, air)
    turb = _smooth_noise(r, n, ts, tb, T)
    y = trim + _smooth_noise(r, n, cj, 1.0, T)
    load = ka * y0 + turb
    return _profile("cruise", f"cruise at trim {trim:g} mm, turbulence {ts:g} N rms (no sign change)",
                    T, y, load, ka, y0, None, 0, ffb, 1.5)


def _reversal_schedule(dp: float, d_fight: float, ramp: float, rate: float, reversals: int, dwell: float,
                       T: float) -> np.ndarray:
    """Relative offset (mm) per sample of :func:`ext_crossing_profile`: ``dwell`` s at the force fight
    (offset ``dp + d_fight``), then per reversal a ramp over ``ramp`` s to the play's edge ``dp``, the
    crossing of the slack ``2 dp`` at ``rate`` mm/s, a ramp to the opposite force fight and a dwell."""
    d_end = dp + d_fight
    # one reversal: ramp d_end -> dp, cross to -dp, ramp -dp -> -d_end
    t_cross = 2 * dp / rate
    seg = [dwell]
    for _ in range(reversals):
        seg.append(ramp + t_cross + ramp + dwell)
    total = float(sum(seg))
    n = int(math.ceil(total / T))
    t = np.arange(1, n + 1) * T
    delta = np.full(n, d_end)
    ts = dwell
    sgn = 1.0
    for _ in range(reversals):
        tau = t - ts
        a = sgn * (d_end - (d_end - dp) * tau / ramp)
        b = sgn * (dp - rate * (tau - ramp))
        c = sgn * (-dp - (d_end - dp) * np.minimum(tau - ramp - t_cross, ramp) / ramp)
        m = tau > 0
        delta = np.where(m & (tau <= ramp), a, delta)
        delta = np.where(m & (tau > ramp) & (tau <= ramp + t_cross), b, delta)
        delta = np.where(m & (tau > ramp + t_cross), c, delta)
        ts += ramp + t_cross + ramp + dwell
        sgn = -sgn
    return delta


def ext_crossing_profile(
    params: RigParams,
    *,
    force_fight_N: float = 1500.0,
    ramp_s: float = 1.5,
    crossing_rate_mm_per_s: float = 30.0,
    reversals: int = 2,
    dwell_s: float = 0.5,
    trim_mm: float = 0.0,
) -> OperationProfile:
    """Force-fight reversal on the ground: both forces change sign in opposite sense.

    Parameters
    ----------
    params : RigParams
        The rig; its plays and stiffnesses place the crossing (see Notes).
    force_fight_N : float, optional
        Force fight at the ends of the ramps, N (default 1500).
    ramp_s : float, optional
        Duration of each ramp from the end force fight to zero, s (default 1.5).
    crossing_rate_mm_per_s : float, optional
        Rate of the relative offset while crossing the play, mm/s (default 30).
    reversals : int, optional
        Number of force-fight reversals (default 2: there and back).
    dwell_s : float, optional
        Hold at the start, between reversals and at the end, s (default 0.5).
    trim_mm : float, optional
        Surface position, mm (default 0).

    Returns
    -------
    OperationProfile
        With a scheduled ``offset_mm`` (the compensation loop is off) and no
        air load.

    Notes
    -----
    On the ground (no air load) the surface is held at trim while the
    force-fight compensator reverses the force fight. With the relative offset
    :math:`\\delta` (EMA 1 at :math:`+\\delta/2`, EMA 2 at :math:`-\\delta/2`),
    :math:`F_1 = -F_2 = k_s(\\delta - \\delta_p)` for
    :math:`\\delta > \\delta_p` (EMA 1 pushes, EMA 2 holds back) and
    :math:`F_1 = -F_2 = k_s(\\delta + \\delta_p)` for
    :math:`\\delta < -\\delta_p`, slack in between, with
    :math:`\\delta_p` = :func:`force_fight_play_mm` (0.16 mm) and
    :math:`k_s = (1/k_1 + 1/k_2)^{-1}` (7.4 kN/mm) from
    :func:`chain_stiffness_N_per_mm`. The schedule ramps the force fight
    linearly to zero (the compensator's integral action), crosses the
    :math:`2\\delta_p` of slack at ``crossing_rate_mm_per_s`` (the
    compensator's rate limit: in the slack the force error is all there is,
    nothing opposes), then ramps the opposite force fight up. Both forces
    change sign in opposite sense at the same instant: the rams swap flanks
    in both bearings and :math:`D_{ext} = s_2 - s_1` jumps by
    :math:`B_{b,1} + B_{b,2}` (both internal plays are crossed too), while the
    elastic part :math:`-2F_1/k_{s,ext}` only ramps and is removed by
    BLFserv's plateau fits.

    Why not simply a lagging drive at a rate reversal: there the relative
    offset sweeps straight through the slack at the same rate as through the
    contact, and the elastic change of :math:`D_{ext}` per mm of relative
    offset in contact (:math:`2k_s/k_{s,ext}` = 0.81 mm/mm here, housing
    springs included in the LVDT stroke) exceeds that in the slack
    (:math:`B_{ext}/2\\delta_p` = 0.31 mm/mm): the external play shows as a
    flattening of :math:`D_{ext}`, not as a jump, and no force-free method can
    separate it from the elastic change (BLFmaint does, with the forces).
    """
    p = _params(params)
    ff = scalar(force_fight_N, "force_fight_N", "N", lo=0.0, lo_open=True, hi=20000.0)
    ramp = scalar(ramp_s, "ramp_s", "s", lo=0.0, lo_open=True, hi=60.0)
    rate = scalar(crossing_rate_mm_per_s, "crossing_rate_mm_per_s", "mm/s", lo=0.0, lo_open=True, hi=50.0)
    reversals = count(reversals, "reversals", 1, 100)
    dwell = scalar(dwell_s, "dwell_s", "s", lo=0.0)
    trim = scalar(trim_mm, "trim_mm", "mm", lo=-p.stroke_limit_mm, hi=p.stroke_limit_mm)
    T = p.sample_period_s
    k1, k2 = chain_stiffness_N_per_mm(p)
    ks = series_stiffness(k1, k2)
    delta = _reversal_schedule(force_fight_play_mm(p), ff / ks, ramp, rate, int(reversals), dwell, T)
    n = delta.size
    y = np.full(n, trim)
    load = np.zeros(n)
    return _profile("ext_crossing",
                    f"ground, no air load: force fight +-{ff:g} N reversed {int(reversals)}x, play crossed at "
                    f"{rate:g} mm/s relative offset",
                    T, y, load, 0.0, trim, delta, 0, 0.0, 1.5)


#: The scenarios ``emacheck simulate --scenario NAME`` knows: name -> what it is.
SCENARIOS = {
    "full-stroke": "the full stroke at full rate and back, force-fight compensation on",
    "small-manoeuvres": "small manoeuvres about trim, each crossing a load reversal",
    "gusts": "random gust loads at trim",
    "ext-crossing": "a manoeuvre whose force fight crosses the external play",
    "cruise": "quiet cruise: no backlash crossed (BLFserv must say 'not traversed')",
}


def scenario_profile(name: str, params: RigParams, rng: np.random.Generator) -> OperationProfile:
    """The :class:`OperationProfile` of scenario ``name`` (a key of :data:`SCENARIOS`) with its defaults."""
    if name not in SCENARIOS:
        raise InputError(f"scenario must be one of {', '.join(SCENARIOS)}, got {name!r}")
    if name == "full-stroke":
        return full_stroke_profile(params)
    if name == "small-manoeuvres":
        return small_manoeuvre_profile(params)
    if name == "gusts":
        return gust_profile(params, rng)
    if name == "ext-crossing":
        return ext_crossing_profile(params)
    return cruise_profile(params, rng)
