"""BLFmaint: backlash and stiffness from a force-fight F-D relation (paper 2.1).

The maintenance check drives the two EMAs into small opposite excursions
(force fight through +-15 % of limit load, several cycles). One F-D relation
(``D_int,i`` with ``F_i``, or ``D_ext`` with ``F_2 - F_1``) then shows two
elastic contact branches joined by a flat backlash branch (paper Figures 4-6).
:func:`blf_maint` splits the relation into the three parts, fits a straight
line to each and returns the backlash (horizontal distance between the two
line intersections) and the two contact stiffnesses with standard
uncertainties. The parts are found from the force (:mod:`blf.maint.regions`):
contact is where |F| is large, the backlash where F stays at the gap level
and D moves freely. docs/blfmaint.md compares this with the paper's rule and
gives the envelope it was benchmarked over.

Method
------
The algorithm follows the paper (three parts, three straight lines, B =
distance of the intersections; the model of the relation, in the
sign-normalised force G, is in the Notes of :func:`blf_maint`) with these
choices:

1. D and F are low-passed identically, zero phase (``sosfiltfilt``,
   2nd-order Butterworth at ``lowpass_rad_s``). The low-passed signals
   select the regions and are the regressor of the contact lines; the
   responses (D in contact, F in the backlash) stay unfiltered.
2. The parts are found from the force (:func:`blf.maint.regions.
   locate_regions`), not from the slope dF/dD: the paper's rule (the
   widest D range where dF/dD is flatter than its median) needs that
   range to stand out against the flat runs the noise of dF/dD makes in
   the contact branches, and a two-cluster split of the binned slope
   finds no flat cluster when the backlash is a few percent of the D
   range (external backlash 0.02-0.07 mm in +-0.8 mm). Both sides must have
   been loaded: each side's force extreme (0.5/99.5 % quantile of G)
   reaches 10 % of the other's and 10 x the load-cell noise. Contact
   samples: G beyond the edge of the backlash's force band by
   ``contact_margin_frac`` of the span to the extreme (first pass: 50 %
   of the extreme). The contact lines' D at the gap level :math:`G_0`
   are the corners :math:`d_{lc}, d_{rc}`; the band (5-95 % quantiles)
   and :math:`G_0` (its midpoint: gap friction is +-, by direction) come
   from the samples in the middle half between the corners (iterated). The backlash is distinct when
   :math:`d_{rc} - d_{lc}` exceeds 3 robust spreads of the low-passed D
   about the contact lines; its samples are those with the low-passed D
   in :math:`[d_{lc} + m, d_{rc} - m]`, :math:`m` =
   ``centre_margin_frac`` x :math:`(d_{rc} - d_{lc})`. The binned curve
   (F and dF/dD binned along D, paper Figure 4) is kept for the report.
3. Contact lines regress D on F, :math:`D = a + bG`: F is nearly
   noise-free against D (10 N ~ 0.1 um at 80 kN/mm, LVDT ~4 um), and
   regressing F on D would attenuate the stiffness by the
   errors-in-variables factor :math:`var(D_{true}) / (var(D_{true}) +
   \\sigma_D^2)`, 4-6 % at 80 kN/mm and +-6 kN. The regressor is the
   low-passed F: with a small force amplitude and a noisy load cell
   (580 N, 42 N std) even F's own noise attenuates b by ~13 % (the
   low-pass cuts it ~6 x; zero phase, so no lag). Samples are selected
   on the low-passed force only (selection on the regressor does not
   bias OLS; one on D would).
4. The backlash is fitted as a level :math:`G = c_0` (mean of the
   unfiltered G over its samples): in free play dF/dD = 0 and gap
   friction is a level (+-, by direction). The paper's sloped line
   (``centre_slope=True``) adds the noise of its slope :math:`c_1`,
   which enters B multiplied by the compliance b, so it costs accuracy
   with soft contacts and wide D ranges (envelope benchmark: worst error
   3.4 x the target max(5 um, 5 % of B) with the line, 0.67 x with the
   level); a true slope :math:`c_1` in the backlash would shift B by
   only about :math:`(c_1/c) B`.
5. Intersections: with contact line :math:`D = a + bG` and centre line
   :math:`G = c_0 + c_1 D`, :math:`D^* = (a + b c_0) / (1 - b c_1)`;
   :math:`B = D^*_{right} - D^*_{left}`, :math:`c = 1/b`.

Uncertainties: each regression's coefficient covariance is the
Newey-West (Bartlett kernel, lags up to ``hac_lag_s``) sandwich estimate,
with lag products taken only between samples that are adjacent in time,
so it stays valid if the D noise is coloured; the three fits use disjoint
samples and are treated as independent (the level's variance is the
Newey-West variance of a mean). ``backlash_sigma_mm`` follows by
first-order propagation through :math:`D^*`; the stiffness sigma is
:math:`\\sigma_b / b^2`. On measurement noise these sigmas match the
seed-to-seed spread (tests: ratio 0.8-1.2, white and AR(1)-coloured D
noise; +-100 N of gap friction: sigma of B 0.25 um vs a seed spread of
0.23 um, the level is not disturbed by the friction's two signs).
Residual structure that is slow but repeats (visco-elastic loops) enters
through the HAC lags and makes them conservative; a systematic
model error that does not show in the residuals (e.g. a contact law that
is curved beyond the margin) is not included.

The lines are fitted to the quasi-static record as it is: a visco-elastic
(Maxwell) stiffening whose time constant is not small against the force
ramp shows as a higher, rate-dependent stiffness and a shifted backlash
(simulated rig, 2 kN/s ramps, arm 40 kN/mm in parallel with 80 kN/mm:
tau 0.1 s gives +0.7 % and +0.4 um, tau 0.5 s gives +15 % and +9 um).

Pure: arrays and an explicit sample rate in, frozen dataclasses out, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from blf.errors import AnalysisError, InputError
from blf.maint.regions import Regions, binned_curve, contact_extremes, locate_regions, noise_std
from blf.maint.results import BinnedCurve, BlfMaintResult, CentreLine, ContactLine, FdLines
from blf.validate import (
    as_1d_finite,
    below_nyquist,
    count,
    instance_of,
    positive_scalar,
    readonly,
    same_shape,
    scalar,
)

__all__ = ["MIN_SAMPLES", "blf_maint"]

MIN_SAMPLES = 200  #: fewest force-fight samples BLFmaint accepts
_FLAT_TO_STEEP_MAX = 0.25  # the backlash line must be flatter than 25 % of the softer contact (beyond 3 sigma)


def blf_maint(d_mm: np.ndarray, f_N: np.ndarray, sample_rate_Hz: float, *, lowpass_rad_s: float = 40.0,
              bin_width_mm: float = 0.005, slope_window_bins: int = 2, min_bin_count: int = 3,
              contact_margin_frac: float = 0.2, centre_margin_frac: float = 0.15, hac_lag_s: float = 0.05,
              min_contact_points: int = 50, min_centre_points: int = 10, centre_slope: bool = False,
              ) -> BlfMaintResult:
    """Measure backlash and contact stiffness from a force-fight F-D record.

    Parameters
    ----------
    d_mm : array_like, shape (n,)
        Position difference in mm: ``D_int,i`` (paper eq. 1, from calibrated
        LVDT strokes) or ``D_ext``.
    f_N : array_like, shape (n,)
        Force in N at the same instants: ``F_i`` with ``D_int,i``, or
        ``F_2 - F_1`` with ``D_ext``. Either global sign of dF/dD is accepted.
    sample_rate_Hz : float
        Sample rate in Hz (500 on the rig). n must be >= 200.
    lowpass_rad_s : float, optional
        Corner of the zero-phase 2nd-order Butterworth low-pass applied
        identically to D and F for the segmentation step, rad/s (default 40,
        as in the paper). Must be below the Nyquist frequency.
    bin_width_mm : float, optional
        Width of the D bins of the binned curve, mm (default 0.005).
    slope_window_bins : int, optional
        Half-width of the local linear fit giving the binned slope, in bins
        (default 2, i.e. 5 bins).
    min_bin_count : int, optional
        Bins with fewer samples are dropped from the binned curve (default 3).
    contact_margin_frac : float, optional
        Fraction of the force span between the edge of the backlash's force
        band and the force extreme that is excluded next to the corner from
        the contact regressions (default 0.2; removes the visco-elastic
        rounding of the transition).
    centre_margin_frac : float, optional
        Fraction of ``d_rc - d_lc`` excluded at each end of the backlash
        region from the centre fit (default 0.15).
    hac_lag_s : float, optional
        Maximum lag of the Newey-West (Bartlett) covariance of the regression
        coefficients, s (default 0.05 s = 25 samples at 500 Hz).
    min_contact_points, min_centre_points : int, optional
        Minimum samples in each contact region (default 50) and in the centre
        region (default 10); fewer raise :class:`~blf.errors.AnalysisError`.
    centre_slope : bool, optional
        False (default): the backlash is fitted as a level of F (free play,
        dF/dD = 0). True: the paper's regression line F on D.

    Returns
    -------
    BlfMaintResult
        Backlash, stiffnesses, their standard uncertainties, slope sign,
        corners, binned curve, fitted lines and region masks.

    Raises
    ------
    blf.errors.InputError
        Bad shapes (not 1-D, unequal), NaN/inf, fewer than 200 samples, or
        bad options.
    blf.errors.AnalysisError
        No F-D relation; backlash not traversed (the force fight never
        reached contact on a side: the message names the side, the end of
        the D range and the force reached); no distinct backlash region (the
        two contact lines meet the gap force closer than the resolution of
        the low-passed D, or F still rises with D between them); a region
        with too few samples. Each message says what is missing in the
        record, in mm and N.

    Notes
    -----
    Model of the relation, in sign-normalised force :math:`G = \\sigma F`
    (:math:`\\sigma = \\pm 1` the global slope sign, so :math:`G` increases
    with :math:`D`), D in mm, F in N, stiffnesses in N/mm:

    .. math::

        D = -\\frac{B}{2} + \\frac{G}{c_{left}} \\; (G < 0), \\qquad
        G \\approx G_0 \\; (|D| < B/2), \\qquad
        D = \\frac{B}{2} + \\frac{G}{c_{right}} \\; (G > 0)

    (plus an arbitrary offset of D; :math:`G_0` the small force in the
    backlash: friction, load-cell offset). The steps, the choices made in them (where they depart
    from the paper and why) and the uncertainties are in the module docstring (Method).
    """
    d, f, opt = _checked(d_mm, f_N, sample_rate_Hz, lowpass_rad_s, bin_width_mm, slope_window_bins, min_bin_count,
                         contact_margin_frac, centre_margin_frac, hac_lag_s, min_contact_points, min_centre_points,
                         centre_slope)
    rel = _relation(d, f, opt)
    # the binned curve along D and its slope (paper Figure 4; refuses D not in mm)
    curve = binned_curve(rel.d_f, rel.g_f, opt.bin_width_mm, opt.half_win, opt.min_count)
    # the regions from the force: both sides loaded, contact lines, corners, backlash samples
    d_range = (float(rel.d_f.min()), float(rel.d_f.max()))
    g_lo, g_hi = contact_extremes(rel.g_f, noise_std(f, rel.f_f), rel.sign, d_range)
    reg = locate_regions(d, rel.d_f, rel.g_f, g_lo, g_hi, rel.sign, contact_margin_frac=opt.contact_margin,
                         centre_margin_frac=opt.centre_margin, min_contact=opt.min_contact, min_centre=opt.min_centre)
    fit = _regressions(d, rel, reg, opt)
    return _result(d, f, rel, reg, fit, curve)


# --------------------------------------------------------------------------
# private helpers
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Options:
    """The options of :func:`blf_maint`, checked (Hz, rad/s, mm, samples)."""

    fs: float
    wc: float
    bin_width_mm: float
    half_win: int
    min_count: int
    min_contact: int
    min_centre: int
    contact_margin: float
    centre_margin: float
    max_lag: int
    centre_slope: bool


def _checked(d_mm, f_N, sample_rate_Hz, lowpass_rad_s, bin_width_mm, slope_window_bins, min_bin_count,
             contact_margin_frac, centre_margin_frac, hac_lag_s, min_contact_points, min_centre_points,
             centre_slope) -> tuple[np.ndarray, np.ndarray, _Options]:
    """The record (D in mm, F in N) and the options, validated in that order (InputError names the bad one)."""
    d = as_1d_finite(d_mm, "d_mm", "mm")
    f = as_1d_finite(f_N, "f_N", "N")
    same_shape((d, "d_mm", "mm"), (f, "f_N", "N"))
    if d.size < MIN_SAMPLES:
        raise InputError(
            f"d_mm and f_N need at least {MIN_SAMPLES} samples (mm, N); got shape {d.shape}"
        )
    fs = positive_scalar(sample_rate_Hz, "sample_rate_Hz", "Hz")
    wc = below_nyquist(lowpass_rad_s, "lowpass_rad_s", fs)
    bw = positive_scalar(bin_width_mm, "bin_width_mm", "mm")
    half_win = count(slope_window_bins, "slope_window_bins", 1)
    min_count = count(min_bin_count, "min_bin_count", 1)
    min_contact = count(min_contact_points, "min_contact_points", 3)
    min_centre = count(min_centre_points, "min_centre_points", 3)
    c_margin = scalar(contact_margin_frac, "contact_margin_frac", "(fraction, dimensionless)", lo=0.0, hi=0.5,
                      hi_open=True)
    m_margin = scalar(centre_margin_frac, "centre_margin_frac", "(fraction, dimensionless)", lo=0.0, hi=0.5,
                      hi_open=True)
    max_lag = int(round(scalar(hac_lag_s, "hac_lag_s", "s", lo=0.0) * fs))
    instance_of(centre_slope, bool, "centre_slope", "a bool (no unit)")
    return d, f, _Options(fs, wc, bw, half_win, min_count, min_contact, min_centre, c_margin, m_margin, max_lag,
                          centre_slope)


@dataclass(frozen=True)
class _Relation:
    """Step 1: D and F low-passed identically (mm, N), the global slope sign and the sign-normalised
    force G = sign * F, raw and low-passed (N)."""

    d_f: np.ndarray
    f_f: np.ndarray
    sign: int
    g: np.ndarray
    g_f: np.ndarray


def _relation(d: np.ndarray, f: np.ndarray, opt: _Options) -> _Relation:
    """Step 1: the identical zero-phase low-pass of D and F (the selections, and the contact lines'
    regressor), and the global slope sign; refused where D and F do not move together."""
    sos = signal.butter(2, opt.wc / (2.0 * np.pi), btype="low", fs=opt.fs, output="sos")
    d_f = signal.sosfiltfilt(sos, d)
    f_f = signal.sosfiltfilt(sos, f)
    sd_d, sd_f = float(np.std(d_f)), float(np.std(f_f))
    if sd_d == 0.0 or sd_f == 0.0:
        raise AnalysisError(
            "no F-D relation: the low-passed D or F is constant "
            f"(std D = {sd_d:.3g} mm, std F = {sd_f:.3g} N)"
        )
    corr = float(np.corrcoef(d_f, f_f)[0, 1])
    if not abs(corr) >= 0.3:
        raise AnalysisError(
            "no F-D relation: D and F do not move together, as they do in a force fight (correlation of the "
            f"low-passed D and F {corr:.3f}, |r| < 0.3)"
        )
    sign = 1 if corr > 0 else -1
    return _Relation(d_f, f_f, sign, sign * f, sign * f_f)


@dataclass(frozen=True)
class _Fit:
    """Steps 3-5: the contact lines D = a + b G (left, right) and the centre line G = c0 + c1 D with
    their Newey-West covariances, RMS residuals and sample indices; the intersections D* and the
    backlash with its variance (mm, mm^2)."""

    left: tuple  #: (a, b, cov, rms, idx)
    right: tuple
    centre: tuple  #: (c0, c1, cov, rms, idx)
    d_left: float
    d_right: float
    backlash: float
    var_backlash: float


def _regressions(d: np.ndarray, rel: _Relation, reg: Regions, opt: _Options) -> _Fit:
    """Steps 3-5: raw D on the low-passed G in contact, the raw G's level (or line on raw D) in the
    backlash; refused where F still changes with D between the contact lines (a soft spring, not free
    play) or the centre line is as steep as a contact line. Then the intersections and the backlash."""
    g, g_f, n_total, max_lag = rel.g, rel.g_f, d.size, opt.max_lag
    idx_l = np.flatnonzero(reg.mask_left)
    idx_r = np.flatnonzero(reg.mask_right)
    idx_c = np.flatnonzero(reg.mask_centre)
    a_l, b_l, cov_l, rms_l = _ols_hac(g_f[idx_l], d[idx_l], idx_l, n_total, max_lag, "left contact")
    a_r, b_r, cov_r, rms_r = _ols_hac(g_f[idx_r], d[idx_r], idx_r, n_total, max_lag, "right contact")
    c0, c1, cov_c, rms_c = _ols_hac(d[idx_c], g[idx_c], idx_c, n_total, max_lag, "centre")
    slope_c, slope_c_sigma = c1, float(np.sqrt(cov_c[1, 1]))  # the backlash line's slope, for the flatness check
    if not opt.centre_slope:
        c0, c1, cov_c, rms_c = _level_hac(g[idx_c], idx_c, n_total, max_lag)
    # (b_l, b_r > 0: locate_regions fitted the same lines and refused others)
    k_soft = min(1.0 / b_l, 1.0 / b_r)
    if abs(slope_c) - 3.0 * slope_c_sigma > _FLAT_TO_STEEP_MAX * k_soft:
        raise AnalysisError(
            "no distinct backlash region: between the contact lines F still changes with D at "
            f"{abs(slope_c):.4g} N/mm, {100 * abs(slope_c) / k_soft:.0f} % of the softer contact stiffness "
            f"{k_soft:.4g} N/mm (a soft spring, not free play)"
        )
    dl, jl = _intersection(a_l, b_l, c0, c1)
    dr, jr = _intersection(a_r, b_r, c0, c1)
    den_l, den_r = 1.0 - b_l * c1, 1.0 - b_r * c1
    if den_l <= 0.0 or den_r <= 0.0:
        raise AnalysisError("centre line is as steep as a contact line; no backlash intersection")
    # gradient w.r.t. (a_l, b_l), (a_r, b_r), (c0, c1)
    var_b = (
        jl[:2] @ cov_l @ jl[:2]
        + jr[:2] @ cov_r @ jr[:2]
        + (jr[2:] - jl[2:]) @ cov_c @ (jr[2:] - jl[2:])
    )
    return _Fit((a_l, b_l, cov_l, rms_l, idx_l), (a_r, b_r, cov_r, rms_r, idx_r), (c0, c1, cov_c, rms_c, idx_c),
                dl, dr, dr - dl, var_b)


def _contact_line(side: str, line: tuple, sign: int, f: np.ndarray) -> ContactLine:
    """A contact line in the original sign of F (the fit was on G = sign * F)."""
    a, b, cov, rms, idx = line
    flip = np.array([[1.0, 0.0], [0.0, float(sign)]])
    return ContactLine(side=side, d_at_zero_force_mm=float(a), compliance_mm_per_N=float(sign * b),
                       cov=readonly(flip @ cov @ flip), n=int(idx.size), f_min_N=float(f[idx].min()),
                       f_max_N=float(f[idx].max()), rmse_mm=rms)


def _result(d: np.ndarray, f: np.ndarray, rel: _Relation, reg: Regions, fit: _Fit, curve: tuple) -> BlfMaintResult:
    """The result in the original sign of F: lines, intersections, binned curve, backlash and stiffnesses."""
    sign = rel.sign
    cd, cg, counts, slope, bw_used = curve
    (_, b_l, cov_l, _, _), (_, b_r, cov_r, _, _) = fit.left, fit.right
    c0, c1, cov_c, rms_c, idx_c = fit.centre
    mask_left, mask_centre, mask_right = reg.mask_left, reg.mask_centre, reg.mask_right
    n_left, n_right, n_centre = (int(np.count_nonzero(m)) for m in (mask_left, mask_right, mask_centre))
    k_l, k_r = 1.0 / b_l, 1.0 / b_r
    centre_line = CentreLine(f_at_zero_d_N=float(sign * c0), slope_N_per_mm=float(sign * c1), cov=readonly(cov_c),
                             n=n_centre, d_min_mm=float(d[idx_c].min()), d_max_mm=float(d[idx_c].max()), rmse_N=rms_c)
    lines = FdLines(left=_contact_line("left", fit.left, sign, f), centre=centre_line,
                    right=_contact_line("right", fit.right, sign, f), d_left_mm=float(fit.d_left),
                    f_left_N=float(sign * (c0 + c1 * fit.d_left)), d_right_mm=float(fit.d_right),
                    f_right_N=float(sign * (c0 + c1 * fit.d_right)))
    curve_rec = BinnedCurve(d_mm=readonly(cd), f_N=readonly(sign * cg), dfdd_N_per_mm=readonly(sign * slope),
                            count=readonly(counts), bin_width_mm=bw_used,
                            threshold_N_per_mm=float(sign * 0.5 * min(1.0 / b_l, 1.0 / b_r)))
    return BlfMaintResult(
        backlash_mm=float(fit.backlash), backlash_sigma_mm=float(np.sqrt(max(fit.var_backlash, 0.0))),
        stiffness_left_N_per_mm=float(k_l), stiffness_left_sigma_N_per_mm=float(np.sqrt(cov_l[1, 1])) / b_l**2,
        stiffness_right_N_per_mm=float(k_r), stiffness_right_sigma_N_per_mm=float(np.sqrt(cov_r[1, 1])) / b_r**2,
        slope_sign=sign, d_lc_mm=float(reg.d_lc_mm), d_rc_mm=float(reg.d_rc_mm),
        dfdd_median=float(sign * np.median(slope)), lines=lines, curve=curve_rec, n_left=n_left,
        n_centre=n_centre, n_right=n_right, mask_left=readonly(mask_left), mask_centre=readonly(mask_centre),
        mask_right=readonly(mask_right))


def _ols_hac(x: np.ndarray, y: np.ndarray, idx: np.ndarray, n_total: int, max_lag: int, name: str):
    """OLS y = a + b x with a Newey-West covariance of (a, b).

    Lag products are formed only between samples adjacent in time (``idx``
    are the sample indices in the full record of length ``n_total``).
    Returns a, b, cov (2x2), rms residual.
    """
    n = x.size
    xm = float(x.mean())
    xc = x - xm
    sxx = float(xc @ xc)
    if not sxx > 0.0:
        raise AnalysisError(f"{name} region has no spread in its regressor; cannot fit a line")
    ym = float(y.mean())
    b = float(xc @ (y - ym)) / sxx
    u = y - ym - b * xc
    full = np.zeros((n_total, 2))
    full[idx, 0] = u
    full[idx, 1] = u * xc
    s_mat = full.T @ full
    for k in range(1, min(max_lag, n_total - 1) + 1):
        w = 1.0 - k / (max_lag + 1.0)
        gam = full[k:].T @ full[:-k]
        s_mat += w * (gam + gam.T)
    bread = np.diag([1.0 / n, 1.0 / sxx])
    cov_c = bread @ s_mat @ bread * (n / max(n - 2, 1))
    jac = np.array([[1.0, -xm], [0.0, 1.0]])
    cov = jac @ cov_c @ jac.T
    a = ym - b * xm
    return a, b, cov, float(np.sqrt(np.mean(u * u)))


def _level_hac(y: np.ndarray, idx: np.ndarray, n_total: int, max_lag: int):
    """Mean level of y as the line y = c0 + 0 x, with the Newey-West variance of the mean.

    Returns c0, cov (2x2, only the c0 entry non-zero), rms residual; lag
    products as in :func:`_ols_hac`.
    """
    n = y.size
    c0 = float(y.mean())
    u = y - c0
    full = np.zeros(n_total)
    full[idx] = u
    s = float(full @ full)
    for k in range(1, min(max_lag, n_total - 1) + 1):
        s += 2.0 * (1.0 - k / (max_lag + 1.0)) * float(full[k:] @ full[:-k])
    cov = np.zeros((2, 2))
    cov[0, 0] = max(s, 0.0) / n**2 * (n / max(n - 1, 1))
    return c0, 0.0, cov, float(np.sqrt(np.mean(u * u)))


def _intersection(a: float, b: float, c0: float, c1: float) -> tuple[float, np.ndarray]:
    """D* of D = a + b G and G = c0 + c1 D, and its gradient w.r.t. (a, b, c0, c1)."""
    den = 1.0 - b * c1
    num = a + b * c0
    d_star = num / den
    grad = np.array(
        [
            1.0 / den,
            (c0 * den + num * c1) / den**2,
            b / den,
            num * b / den**2,
        ]
    )
    return float(d_star), grad
