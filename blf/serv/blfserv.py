"""BLFserv: backlash from the jumps of a position difference in normal operation (paper 2.2).

In service the aileron's two EMAs are never driven into a force fight on
purpose; backlash shows only where a load-path force changes sign, as a short
jump of the position difference ``D`` (paper eq. 1: ``D_int,1``,
``D_int,2`` or ``D_ext``). BLFserv traces these jumps from motor angles and
LVDT strokes alone (no force sensors) and measures their height:

1. ``D`` is low-passed (first order, 40 rad/s) and differentiated twice by
   DT1 filters (paper eqs. 2, 3), all designed in continuous time with
   python-control and discretised at the sample rate
   (:func:`design_serv_filters`), applied with :func:`scipy.signal.lfilter`
   carrying the filter state (``zi``) between calls: ``dD/dt`` in one call
   with the product low-pass x DT1 (the same transfer function as the
   cascade), ``d2D/dt2`` from it with the DT1; the filtered ``D`` itself is
   needed only as differences (the paper's Delta D), which the detector
   rebuilds exactly from ``dD/dt`` by inverting the DT1, and for plots;
2. a traversal is detected where both derivatives leave the threshold zone
   ``{-thresh, thresh}`` (paper 2.2); the thresholds follow from the noise
   level of the data (:func:`estimate_noise_std_mm`, Method below);
3. its height is measured either as in the paper (``method="paper"``: the
   change of the filtered ``D`` while both derivatives stay outside the zone,
   the largest amplitude is the backlash) or from the levels of ``D`` before
   and after the traversal (``method="improved"``, the default; what changed
   and why: Method below).

Two forms with identical results: :func:`blf_serv` over a whole recording and
:class:`BlfServMonitor`, fed sample by sample or chunk by chunk, which keeps
the filter and detector state across calls (what a real-time system runs).
Both run the same compiled detector (numba, :mod:`blf.serv.detect`) on the
same filter outputs (:mod:`blf.serv.filters`), so they agree to the last bit
whatever the chunking.

Method
------
**Filters** (paper eqs. 2, 3; :func:`design_serv_filters`):
:math:`D_f = G_{LP} D`, :math:`\\dot D = G_{DT1} D_f`,
:math:`\\ddot D = G_{DT1} \\dot D` with :math:`G_{LP} = 1/(1 + s/\\omega_c)`,
:math:`G_{DT1} = s/(1 + s/\\omega_d)`, Tustin-discretised; the low-pass
starts in steady state at the first sample.

**Thresholds, from the noise of the data.** The white-noise level
:math:`\\hat\\sigma` of D (:func:`estimate_noise_std_mm`: MAD of the second
differences, robust to jumps and motion) goes through the exact noise
gains :math:`g_1` [1/s], :math:`g_2` [1/s^2] of the discrete filter chain:

.. math::

    thresh_1 = k\\,g_1\\hat\\sigma \\;[mm/s], \\qquad
    thresh_2 = k\\,g_2\\hat\\sigma \\;[mm/s^2], \\qquad k = 5

Noise alone leaves a zone with probability 6e-7 per sample and
derivative; both at once (they are uncorrelated at equal times) about
3e-13: no false detection in hours of quiet data. (Defaults at 500 Hz
and 0.025 mm peak-to-peak LVDT noise: 0.21 mm/s and 16 mm/s^2.)

**Detection (both methods, paper 2.2).** A traversal is detected at a
sample where :math:`|\\dot D| > thresh_1` and
:math:`|\\ddot D| > thresh_2`. The event around it spans the excursion of
:math:`|\\ddot D|` beyond :math:`thresh_2` that contains it (excursions
less than ``merge_gap_s`` apart merged: the rattle after an impact).
Excursions without a detection (a smooth elastic or motion change that
moves only one derivative) are ignored.

**Paper method** (``method="paper"``): over each stretch where both
derivatives are outside the zone, :math:`\\Delta D = D_f(t_{out}) -
D_f(t_{in})` from the sample where both left to the first sample where
one returned; the largest :math:`|\\Delta D|` over the recording is the
backlash; an event counts if its :math:`|\\Delta D| \\ge` ``min_jump_mm``.

**Improved method** (``method="improved"``, the default): what changed
and why. :math:`\\ddot D` changes sign in the middle of a jump (the
inflection of the filtered step), so the paper's stretch ends half-way
and misses the ramp-in and ramp-out of the low-passed jump: the paper
method reads 32-37 % low (internal channels; 21 % external) on the
simulated rig with these filters, 13-26 % with a 60 rad/s DT1 corner (the
paper's "about a quarter lower" is this filter effect), so its value
depends on the filter corners. The improved
method uses the filters only to find the event and measures the height
on the raw D: a straight line is fitted (least squares) on the
``plateau_s`` of raw D before the event (ending ``guard_before_s`` before
it, not reaching back into the previous event) and another after it
(starting ``guard_after_s`` after it); both are evaluated at the instant
of the jump :math:`t_j` (centroid of :math:`|\\dot D| - thresh_1 > 0` over
the event, minus the filter delay ``delay_samples``) and

.. math:: h = \\hat D_{after}(t_j) - \\hat D_{before}(t_j) \\quad [mm]

The lines carry the elastic change of D (:math:`-\\dot F/k` while the load
ramps) and an LVDT pitch error times the velocity through the jump, which
the paper's :math:`\\Delta D` includes. An event counts if both plateaus
have at least ``min_plateau_s`` of samples, their fit residuals are below
``max_residual_factor`` x :math:`\\hat\\sigma` (quiet: no rattle, no second
traversal inside), the event is shorter than ``max_event_s`` and
:math:`|h| \\ge` ``min_jump_mm``. The backlash is the **median** of the
counted :math:`|h|` rather than the paper's largest amplitude: the
largest of N noisy readings is biased up (by ~1.5 sigma for N = 10)
and by any single misfit, whereas one clean traversal suffices for the
median. Its standard uncertainty is :math:`1.2533\\,s/\\sqrt{N}`
(:math:`s` the spread of the counted heights) for N >= 3, else the fit
uncertainty :math:`\\hat\\sigma\\sqrt{v_{before} + v_{after}}` of the
jump, with :math:`v` the variance factor of each line's value at
:math:`t_j`.

Simulated rig, default noise and LVDT errors with calibration
(``tests/bench/bench_serv.py``, 20 seeds, five normal-operation scenarios):
improved bias -1.6 to +4.9 %, seed-to-seed standard deviation 1-2 %,
worst seed 7.3 % for ``int1``, ``int2`` and, where crossed, ``ext``;
paper method 21-37 % low.

**Not traversed**: no counted event gives ``backlash_mm`` None and
``traversals`` 0 (quiet cruise; ``D_ext`` in symmetric operation, where
both EMA forces change sign together and :math:`D_{ext}` moves by
:math:`B_{b,2} - B_{b,1}` only).

**Calibration matters.** On raw LVDT data D carries the pitch error
times the stroke (paper 2.3: +-20 mm x 7.5 % = +-1.5 mm over the full
stroke); the acceleration phases of a full-rate stroke then look like
jumps of 0.03 to 0.2 mm in both methods. Calibrate first
(:mod:`blf.maint.calibration`).

Pure: arrays and an explicit sample rate in, frozen dataclasses out; no
plotting, logging, file IO or clocks.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from blf.errors import InputError
from blf.serv.detect import (
    O_CH,
    O_HEIGHT,
    O_LAST,
    O_N,
    O_NPOST,
    O_NPRE,
    O_PAPER,
    O_RPOST,
    O_RPRE,
    O_SIGF,
    O_START,
    O_STATUS,
    O_TC,
    ST_TOO_LONG,
    detect,
    flush,
    new_state,
    params_vector,
)
from blf.serv.filters import design_serv_filters, robust_noise_std
from blf.serv.results import BlfServResult, ServJump, readings
from blf.validate import as_1d_finite, as_finite, count, one_of, positive_scalar, readonly, scalar

__all__ = ["METHODS", "BlfServMonitor", "blf_serv"]

#: Measurement methods: ``"improved"`` (default) and ``"paper"``.
METHODS = ("improved", "paper")


# ====================================================================== the monitor


_DEFAULTS = dict(
    lowpass_rad_s=40.0,
    dt1_rad_s=100.0,
    discretisation="tustin",
    threshold_factor=5.0,
    min_jump_mm=None,
    plateau_s=0.15,
    min_plateau_s=0.05,
    guard_before_s=0.05,
    guard_after_s=0.02,
    merge_gap_s=0.1,
    max_event_s=1.0,
    max_residual_factor=2.5,
)


class BlfServMonitor:
    """Streaming BLFserv over one or more D channels (the real-time form).

    Feed samples with :meth:`update` (one sample or a chunk at a time); the
    filter states (``scipy.signal.lfilter`` ``zi``) and the detector state are
    kept between calls, so the result does not depend on the chunking and
    equals :func:`blf_serv` over the same samples with the same
    ``noise_std_mm``.

    Parameters
    ----------
    sample_rate_Hz : float
        Sample rate, Hz.
    noise_std_mm : float or sequence of float
        White-noise standard deviation of each channel's D, mm (> 0); its
        length sets the number of channels k. From the LVDT specification
        (peak-to-peak / 6 for D_int, times sqrt(2) for D_ext) or from
        :func:`estimate_noise_std_mm` on a stretch of data.
    method : {"improved", "paper"}, optional
        What :meth:`result` reports as ``backlash_mm`` (default ``"improved"``;
        both are always computed).
    t0_s : float, optional
        Time of the first sample, s (default 0).
    lowpass_rad_s : float, optional
        Low-pass crossover, rad/s (default 40, paper).
    dt1_rad_s : float, optional
        DT1 corner, rad/s (default 100).
    discretisation : {"tustin", "zoh"}, optional
        Discretisation of the filters (default ``"tustin"``).
    threshold_factor : float, optional
        Thresholds in units of the filtered derivatives' noise standard
        deviation (default 5).
    min_jump_mm : float, optional
        Smallest height counted as a traversal, mm (default
        ``6 * noise_std_mm``: the peak-to-peak noise of D).
    plateau_s : float, optional
        Length of the plateau fits before and after a jump, s (default 0.15).
    min_plateau_s : float, optional
        Shortest usable plateau, s (default 0.05).
    guard_before_s, guard_after_s : float, optional
        Gaps between the plateaus and the detected event, s (defaults 0.05
        and 0.02).
    merge_gap_s : float, optional
        Excursions of the second derivative closer than this are one event
        (impact rattle), s (default 0.1).
    max_event_s : float, optional
        Longer events are not jumps (``"event too long"``), s (default 1).
    max_residual_factor : float, optional
        A plateau whose fit residual exceeds this times ``noise_std_mm`` is
        not quiet (default 2.5).

    Raises
    ------
    blf.errors.InputError
        Bad rate, noise level or options.

    Notes
    -----
    Memory is bounded: a ring buffer of the last
    ``guard_before_s + 2*plateau_s + max_event_s + merge_gap_s + guard_after_s``
    seconds of raw D per channel plus the counted jumps. Cost per 2 ms sample
    for three channels: about 30 microseconds (two ``lfilter`` calls on a
    (3, 1) block and one compiled detector step; ``tests/bench/bench_serv.py``).
    """

    def __init__(self, sample_rate_Hz: float, noise_std_mm, *, method: str = "improved", t0_s: float = 0.0,
                 **options) -> None:
        unknown = sorted(set(options) - set(_DEFAULTS))
        if unknown:
            raise InputError(f"unknown option(s) {unknown}; known: {sorted(_DEFAULTS)}")
        opt = dict(_DEFAULTS)
        opt.update(options)
        fs = positive_scalar(sample_rate_Hz, "sample_rate_Hz", "Hz")
        one_of(method, "method", METHODS)
        t0 = scalar(t0_s, "t0_s", "s")
        sig = np.atleast_1d(np.asarray(noise_std_mm, dtype=float)) if np.ndim(noise_std_mm) <= 1 else None
        if sig is None or sig.ndim != 1 or sig.size < 1 or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise InputError(f"noise_std_mm must be a positive finite scalar or 1-D sequence in mm; got "
                             f"{noise_std_mm!r} (shape {np.shape(noise_std_mm)})")
        self._filters = design_serv_filters(fs, lowpass_rad_s=opt["lowpass_rad_s"], dt1_rad_s=opt["dt1_rad_s"],
                                            discretisation=opt["discretisation"])
        kf = positive_scalar(opt["threshold_factor"], "threshold_factor", "(dimensionless)")
        secs = {key: scalar(opt[key], key, "s", lo=0.0, lo_open=key in ("plateau_s", "min_plateau_s", "max_event_s"))
                for key in ("plateau_s", "min_plateau_s", "guard_before_s", "guard_after_s", "merge_gap_s",
                            "max_event_s")}
        if secs["min_plateau_s"] > secs["plateau_s"]:
            raise InputError(f"min_plateau_s ({secs['min_plateau_s']} s) must not exceed plateau_s "
                             f"({secs['plateau_s']} s)")
        rq = positive_scalar(opt["max_residual_factor"], "max_residual_factor", "(dimensionless)")
        self.k = int(sig.size)
        self.sample_rate_Hz = fs
        self.method = method
        self.t0_s = t0
        self.noise_std_mm = sig.copy()
        g = self._filters.noise_gain
        self.threshold_d1 = kf * sig * g[1]
        self.threshold_d2 = kf * sig * g[2]
        mj = opt["min_jump_mm"]
        if mj is None:
            self.min_jump_mm = 6.0 * sig
        else:
            mj_arr = np.atleast_1d(np.asarray(mj, dtype=float))
            if mj_arr.ndim != 1 or mj_arr.size not in (1, self.k) or not np.all(np.isfinite(mj_arr)) \
                    or np.any(mj_arr < 0):
                raise InputError(f"min_jump_mm must be None or a finite scalar/sequence >= 0 in mm, one per "
                                 f"channel; got {mj!r}")
            self.min_jump_mm = np.broadcast_to(mj_arr, (self.k,)).astype(float)
        self.max_residual_factor = rq
        smp = lambda x: int(round(x * fs))  # noqa: E731
        self._gpre = smp(secs["guard_before_s"])
        self._gpost = smp(secs["guard_after_s"])
        self._w = max(3, smp(secs["plateau_s"]))
        self._min_n = max(3, smp(secs["min_plateau_s"]))
        self._merge = smp(secs["merge_gap_s"])
        self._maxlen = max(1, smp(secs["max_event_s"]))
        self._H = self._gpre + 2 * self._w + self._maxlen + self._merge + self._gpost + 16
        self._ring, self._ist, self._fst = new_state(self.k, self._H, self.threshold_d1, self.threshold_d2)
        f = self._filters
        self._par = params_vector(f.delay_samples, self._gpre, self._gpost, self._w, self._merge, self._maxlen,
                                  f.dt1_b[0], f.dt1_a[1])
        # D -> dD/dt in one lfilter call (low-pass times DT1), then dD/dt -> d2D/dt2
        self._bd = np.asarray(f.dt1_b)
        self._ad = np.asarray(f.dt1_a)
        self._b1 = np.convolve(f.lowpass_b, f.dt1_b)
        self._a1 = np.convolve(f.lowpass_a, f.dt1_a)
        self._z1 = self._z2 = None
        self._rows: list[np.ndarray] = []
        self._n = 0
        self._out = np.empty((self.k * 4, O_N))

    # ------------------------------------------------------------------ feeding
    def update(self, d_mm) -> int:
        """Feed samples; return the number of events finished by them.

        Parameters
        ----------
        d_mm : array_like
            For one channel: a scalar or shape (m,) (m samples). For k > 1
            channels: shape (k,) (one sample of every channel) or (m, k).
            In mm. Empty input is allowed.

        Returns
        -------
        int
            Events completed (their after-plateau collected) during this call.

        Raises
        ------
        blf.errors.InputError
            Wrong shape or NaN/inf.
        """
        return self._feed(self._as_block(d_mm))[0]

    def _feed(self, x: np.ndarray, keep: bool = False):
        """Filter and detect a (k, m) block; returns (events finished, (dD/dt, d2D/dt2) if keep)."""
        m = x.shape[1]
        if m == 0:
            return 0, None
        if self._z1 is None:
            # start in steady state at the first sample: constant D, zero derivatives
            self._z1 = np.outer(x[:, 0], signal.lfilter_zi(self._b1, self._a1))
            self._z2 = np.zeros((self.k, self._ad.size - 1))
        if self.k == 1:  # 1-D calls are faster than axis=1 on a (1, m) block; same arithmetic
            d1, z1 = signal.lfilter(self._b1, self._a1, x[0], zi=self._z1[0])
            d2, z2 = signal.lfilter(self._bd, self._ad, d1, zi=self._z2[0])
            d1, d2, self._z1, self._z2 = d1.reshape(1, -1), d2.reshape(1, -1), z1.reshape(1, -1), z2.reshape(1, -1)
        else:
            d1, self._z1 = signal.lfilter(self._b1, self._a1, x, axis=1, zi=self._z1)
            d2, self._z2 = signal.lfilter(self._bd, self._ad, d1, axis=1, zi=self._z2)
        cap = self.k * (m // (self._merge + 1) + m // self._maxlen + 3)
        out = self._out if cap <= self._out.shape[0] else np.empty((cap, O_N))
        nout = detect(x, d1, d2, self._ring, self._ist, self._fst, self._par, out)
        if nout:
            self._rows.append(out[:nout].copy())
        self._n += m
        return int(nout), ((d1, d2) if keep else None)

    def _as_block(self, d_mm) -> np.ndarray:
        a = as_finite(d_mm, "d_mm", "mm")
        k = self.k
        if k == 1:
            if a.ndim > 1:
                raise InputError(f"d_mm of a one-channel monitor must be a scalar or shape (m,) in mm; "
                                 f"got shape {a.shape}")
            x = a.reshape(1, -1)
        else:
            if a.shape == (k,):
                x = a.reshape(k, 1)
            elif a.ndim == 2 and a.shape[1] == k:
                x = np.ascontiguousarray(a.T)
            else:
                raise InputError(f"d_mm of a {k}-channel monitor must have shape ({k},) or (m, {k}) in mm; "
                                 f"got shape {a.shape}")
        return x

    # ------------------------------------------------------------------ results
    @property
    def n_samples(self) -> int:
        """Samples fed so far."""
        return self._n

    def result(self, channel: int = 0) -> BlfServResult:
        """The result so far for one channel, open events closed with the data there is.

        Parameters
        ----------
        channel : int, optional
            Channel index, 0..k-1 (default 0).

        Returns
        -------
        BlfServResult
            With ``d_filtered_mm`` etc. None. The monitor's state is not
            changed: later updates continue as if this had not been called.
        """
        return self._summarise(count(channel, "channel", 0, self.k - 1), self._all_rows(), None)

    def _all_rows(self) -> np.ndarray:
        parts = list(self._rows)
        if self._n:
            ist, fst = self._ist.copy(), self._fst.copy()
            out = np.empty((self.k, O_N))
            nout = flush(self._ring, ist, fst, self._par, out)
            if nout:
                parts.append(out[:nout])
        return np.concatenate(parts) if parts else np.empty((0, O_N))

    def _summarise(self, c: int, rows: np.ndarray, arrays) -> BlfServResult:
        fs = self.sample_rate_Hz
        sig = float(self.noise_std_mm[c])
        min_jump = float(self.min_jump_mm[c])
        rq = self.max_residual_factor * sig
        sel = rows[rows[:, O_CH] == c] if rows.size else rows
        sel = sel[np.argsort(sel[:, O_START], kind="stable")] if sel.size else sel
        jumps = []
        for r in sel:
            h = float(r[O_HEIGHT])
            npre, npost = int(r[O_NPRE]), int(r[O_NPOST])
            rpre, rpost = float(r[O_RPRE]), float(r[O_RPOST])
            if int(r[O_STATUS]) == ST_TOO_LONG:
                reason = "event too long"
            elif npre < self._min_n or not np.isfinite(rpre):
                reason = "plateau before too short"
            elif npost < self._min_n or not np.isfinite(rpost):
                reason = "plateau after too short"
            elif rpre > rq:
                reason = "plateau before not quiet"
            elif rpost > rq:
                reason = "plateau after not quiet"
            elif not abs(h) >= min_jump:
                reason = "below min jump"
            else:
                reason = "ok"
            paper = float(r[O_PAPER])
            jumps.append(ServJump(
                t_start_s=self.t0_s + r[O_START] / fs, t_end_s=self.t0_s + r[O_LAST] / fs,
                t_jump_s=self.t0_s + r[O_TC] / fs, height_mm=h, height_sigma_mm=float(r[O_SIGF]) * sig,
                paper_delta_mm=paper, n_before=npre, n_after=npost, residual_before_mm=rpre,
                residual_after_mm=rpost, accepted=reason == "ok", paper_accepted=abs(paper) >= min_jump,
                reason=reason))
        df = d1 = d2 = None
        if arrays is not None:
            df, d1, d2 = (readonly(a) for a in arrays)
        return BlfServResult(
            **readings(jumps, self.method), method=self.method, jumps=tuple(jumps), noise_std_mm=sig,
            threshold_d1_mm_per_s=float(self.threshold_d1[c]), threshold_d2_mm_per_s2=float(self.threshold_d2[c]),
            min_jump_mm=min_jump, filters=self._filters, n_samples=self._n, t0_s=self.t0_s,
            d_filtered_mm=df, d1_mm_per_s=d1, d2_mm_per_s2=d2)


# ====================================================================== batch


def blf_serv(d_mm: np.ndarray, sample_rate_Hz: float, *, method: str = "improved", noise_std_mm: float | None = None,
             t0_s: float = 0.0, lowpass_rad_s: float = 40.0, dt1_rad_s: float = 100.0, discretisation: str = "tustin",
             threshold_factor: float = 5.0, min_jump_mm: float | None = None, plateau_s: float = 0.15,
             min_plateau_s: float = 0.05, guard_before_s: float = 0.05, guard_after_s: float = 0.02,
             merge_gap_s: float = 0.1, max_event_s: float = 1.0, max_residual_factor: float = 2.5,
             keep_signals: bool = True) -> BlfServResult:
    """Measure backlash from the jumps of one position difference over a recording.

    Parameters
    ----------
    d_mm : array_like, shape (n,)
        Position difference, mm: ``D_int,1``, ``D_int,2`` or ``D_ext`` (paper
        eq. 1, :func:`blf.signals.position_differences`) from **calibrated**
        LVDT strokes (:meth:`blf.maint.calibration.LvdtCalibration.correct`);
        n >= 10.
    sample_rate_Hz : float
        Sample rate, Hz (500 on the rig).
    method : {"improved", "paper"}, optional
        Which measurement is reported as ``backlash_mm`` (default
        ``"improved"``); the other is in ``backlash_paper_mm`` /
        ``backlash_improved_mm``.
    noise_std_mm : float, optional
        White-noise standard deviation of D, mm; default: estimated from
        ``d_mm`` by :func:`estimate_noise_std_mm`.
    t0_s : float, optional
        Time of the first sample, s (default 0).
    lowpass_rad_s, dt1_rad_s, discretisation, threshold_factor, min_jump_mm, plateau_s, min_plateau_s,
    guard_before_s, guard_after_s, merge_gap_s, max_event_s, max_residual_factor : optional
        The filters' and the detector's options, as in :class:`BlfServMonitor` (units and defaults
        there).
    keep_signals : bool, optional
        Return the filter outputs (for plotting; the filtered D costs one more
        ``lfilter`` pass), default True.

    Returns
    -------
    BlfServResult
        Backlash (None and 0 traversals if none was crossed), all events, the
        thresholds and the filter outputs (for paper Figure 8).

    Raises
    ------
    blf.errors.InputError
        Bad shape, NaN/inf, fewer than 10 samples, bad options.
    blf.errors.AnalysisError
        If the noise level cannot be estimated (noise-free D; pass
        ``noise_std_mm``).

    Notes
    -----
    The filters (paper eqs. 2, 3), the thresholds from the noise of the data, the detection and
    the two measurements (the paper's, and the improved one: what changed and why) are in the
    module docstring (Method).
    """
    d = as_1d_finite(d_mm, "d_mm", "mm", min_len=10)
    sig = robust_noise_std(d) if noise_std_mm is None else positive_scalar(noise_std_mm, "noise_std_mm", "mm")
    mon = BlfServMonitor(
        sample_rate_Hz, sig, method=method, t0_s=t0_s, lowpass_rad_s=lowpass_rad_s, dt1_rad_s=dt1_rad_s,
        discretisation=discretisation, threshold_factor=threshold_factor, min_jump_mm=min_jump_mm,
        plateau_s=plateau_s, min_plateau_s=min_plateau_s, guard_before_s=guard_before_s,
        guard_after_s=guard_after_s, merge_gap_s=merge_gap_s, max_event_s=max_event_s,
        max_residual_factor=max_residual_factor)
    _, (d1, d2) = mon._feed(d.reshape(1, -1), keep=True)
    rows = mon._all_rows()
    arrays = None
    if keep_signals:
        f = mon._filters
        df, _ = signal.lfilter(f.lowpass_b, f.lowpass_a, d, zi=signal.lfilter_zi(f.lowpass_b, f.lowpass_a) * d[0])
        arrays = (df, d1[0], d2[0])
    return mon._summarise(0, rows, arrays)
