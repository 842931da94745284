"""BLFmaint, segmentation: where the two contact regions and the backlash region of an F-D record are.

The paper (2.1, Figure 4) splits the F-D relation at the ends of the widest
D range where dF/dD is flatter than its median; emacheck then split the
binned slope into a flat and a steep cluster. Both rest on the flat part
standing out among the D bins; with a small backlash in a wide force fight
(external: 0.02-0.07 mm in +-0.8 mm) it is a few percent of them and the
cluster split found no flat part. Here the regions are found from the force, which
is what tells contact from backlash on a rig: in contact |F| is large and
grows with the deflection, in the backlash F stays at the (near-zero) gap
level while D moves freely.

1. :func:`contact_extremes`: both sides must have been loaded. The force
   extremes of the two sides (0.5 % and 99.5 % quantiles of the low-passed,
   sign-normalised force) must each reach 10 % of the other side's and 10
   times the load-cell noise; a force fight demands the same force on both
   sides, so a side far below is one whose contact was never reached.
2. :func:`locate_regions`: contact samples are those whose low-passed force
   is beyond the edge of the backlash's force band by ``contact_margin_frac``
   of the span to the force extreme (selected on the force, the regressor of
   the contact lines, never on D; a first pass takes 50 % of each extreme,
   clear of any gap friction). D is regressed on F there; the two lines' D
   at the gap force level are the corners ``d_lc``, ``d_rc``; the gap's
   force band is the 5-95 % quantile range of the force of the samples in
   the middle half between the corners, its level the band's midpoint
   (friction in the gap is +-, by direction; iterated, at most 3 times). The backlash region is distinct when the
   corners are more than 3 spreads of the low-passed D about the contact
   lines apart; its samples (for the centre regression) are those with the
   low-passed D inside the corners less ``centre_margin_frac`` of the width
   at each end, and outside the contact samples.
3. :func:`binned_curve`: the paper's Figure 4 (F and dF/dD binned along D)
   for the report, and the check that D is in mm.

Pure: arrays in, a frozen dataclass out, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from blf.errors import AnalysisError, InputError
from blf.validate import readonly

__all__ = ["Regions", "binned_curve", "contact_extremes", "locate_regions", "noise_std"]

MAX_BINS = 100_000
MIN_BINS_PER_RANGE = 40  #: the binned curve's bins are narrowed so that the D range holds at least this many
CONTACT_SHARE_MIN = 0.10  #: a side's force extreme must reach this share of the other side's
CONTACT_NOISE_MULT = 10.0  #: ... and this many load-cell noise stds
RESOLUTION_SPREADS = 3.0  #: the gap must be wider than this many spreads of the low-passed D about the lines
_EXTREME_Q = 0.005  #: quantile (and 1 - it) taken as a side's force extreme
_GAP_LEVEL_ITER = 3
_BAND_Q = 0.05  #: quantiles of the gap samples' force taken as the edges of the gap's force band


@dataclass(frozen=True)
class Regions:
    """The three regions of an F-D record, in the sign-normalised force G = sign * F.

    Attributes
    ----------
    g_gap_N : float
        Force level in the backlash (gap), N (sign-normalised).
    g_lo_N, g_hi_N : float
        Force extremes of the left (G < 0) and right (G > 0) contact, N.
    d_lc_mm, d_rc_mm : float
        Corners: D of the left and right contact line at the gap level, mm.
    spread_d_mm : float
        Robust spread (1.4826 x MAD) of the low-passed D about the contact
        lines, mm: the resolution of the corners.
    mask_left, mask_centre, mask_right : ndarray of bool, shape (n,)
        Samples of the left contact, backlash and right contact regressions.
    """

    g_gap_N: float
    g_lo_N: float
    g_hi_N: float
    d_lc_mm: float
    d_rc_mm: float
    spread_d_mm: float
    mask_left: np.ndarray
    mask_centre: np.ndarray
    mask_right: np.ndarray


def noise_std(x: np.ndarray, x_lowpassed: np.ndarray) -> float:
    """Robust std (1.4826 x MAD) of ``x - x_lowpassed``: the wide-band noise of a signal, its unit."""
    r = x - x_lowpassed
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def _side_name(side: str, sign: int) -> str:
    """Words for a contact side; ``side`` "left" (G < 0, smaller D) or "right"; F = sign * G."""
    f_positive = (side == "right") == (sign > 0)
    if sign < 0:  # an internal relation F_i - D_int: F > 0 compresses the EMA
        return "compression side (F > 0)" if f_positive else "tension side (F < 0)"
    return "F > 0 side" if f_positive else "F < 0 side"


def contact_extremes(g_f: np.ndarray, sigma_f_N: float, sign: int, d_range_mm: tuple[float, float]
                     ) -> tuple[float, float]:
    """Force extremes ``(g_lo, g_hi)`` of the two contact sides, N; AnalysisError if a side was not loaded.

    Parameters
    ----------
    g_f : ndarray, shape (n,)
        Low-passed sign-normalised force G = sign * F, N (increases with D).
    sigma_f_N : float
        Load-cell noise std, N.
    sign : int
        Global slope sign (F = sign * G).
    d_range_mm : (float, float)
        Recorded (low-passed) D range, mm, for the message.

    Notes
    -----
    ``g_hi`` is the 99.5 % quantile of G, ``g_lo`` the 0.5 % one. A side is
    loaded when its extreme reaches both ``CONTACT_SHARE_MIN`` (10 %) of the
    other side's and ``CONTACT_NOISE_MULT`` (10) x ``sigma_f_N``.
    """
    g_lo, g_hi = (float(v) for v in np.quantile(g_f, [_EXTREME_Q, 1.0 - _EXTREME_Q]))
    floor = CONTACT_NOISE_MULT * sigma_f_N
    reach = {"left": -g_lo, "right": g_hi}
    missing = [s for s, other in (("left", "right"), ("right", "left"))
               if reach[s] < max(CONTACT_SHARE_MIN * reach[other], floor)]
    if not missing:
        return g_lo, g_hi
    lo, hi = d_range_mm
    if len(missing) == 2:
        raise AnalysisError(
            "backlash not traversed: the force fight never reached contact on either side: |F| stayed below "
            f"{max(reach['left'], reach['right'], 0.0):.0f} N, less than {CONTACT_NOISE_MULT:g} x the load-cell "
            f"noise ({sigma_f_N:.3g} N std)"
        )
    side = missing[0]
    other = "right" if side == "left" else "left"
    end = "lower" if side == "left" else "upper"
    f_side = sign * (g_lo if side == "left" else g_hi)  # the side's extreme in the original sign of F
    bound = "below" if f_side >= 0 else "above"
    if reach[side] >= floor:
        why = (f"{100.0 * reach[side] / reach[other]:.0f} % of the {reach[other]:.0f} N reached on the "
               f"{_side_name(other, sign)}; a force fight loads both sides alike, and a contact line needs "
               f"at least {100 * CONTACT_SHARE_MIN:.0f} %")
    else:
        why = f"less than {CONTACT_NOISE_MULT:g} x the load-cell noise ({sigma_f_N:.3g} N std)"
    raise AnalysisError(
        f"backlash not traversed: the force fight never reached contact on the {_side_name(side, sign)}, at the "
        f"{end} end of the recorded D range [{lo:.4f}, {hi:.4f}] mm: F stayed {bound} {f_side:.0f} N there, {why}"
    )


def _ols(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Plain least squares y = a + b x; (a, b)."""
    xm, ym = float(x.mean()), float(y.mean())
    xc = x - xm
    sxx = float(xc @ xc)
    b = float(xc @ (y - ym)) / sxx if sxx > 0.0 else 0.0
    return ym - b * xm, b


def locate_regions(d: np.ndarray, d_f: np.ndarray, g_f: np.ndarray, g_lo: float, g_hi: float,
                   sign: int, *, contact_margin_frac: float, centre_margin_frac: float, min_contact: int,
                   min_centre: int) -> Regions:
    """The contact and backlash regions of a record whose two sides were loaded.

    Parameters
    ----------
    d : ndarray, shape (n,)
        D, mm, unfiltered (the response of the contact lines that place the
        corners).
    d_f, g_f : ndarray, shape (n,)
        Low-passed D (mm) and sign-normalised force G = sign * F (N): the
        selections are made on these, and G_f is the lines' regressor.
    g_lo, g_hi : float
        Force extremes of the two sides (:func:`contact_extremes`), N.
    sign : int
        Global slope sign, for the messages.
    contact_margin_frac, centre_margin_frac : float
        Margins of :func:`blf.maint.blfmaint.blf_maint` (fractions).
    min_contact, min_centre : int
        Fewest samples in each contact region and in the backlash region.

    Returns
    -------
    Regions

    Raises
    ------
    blf.errors.AnalysisError
        A contact region with too few samples or without an elastic slope, no
        distinct backlash region (the corners closer than 3 spreads of the
        low-passed D), or too few samples inside the backlash.

    Notes
    -----
    Contact: :math:`G_f \\ge G_+ + m_c (G_{hi} - G_+)` (right) and
    :math:`G_f \\le G_- - m_c (G_- - G_{lo})` (left), :math:`[G_-, G_+]` the
    force band of the backlash (N), :math:`m_c` = ``contact_margin_frac``;
    lines :math:`D = a + bG_f` (OLS, D in mm); corners :math:`d_{lc} = a_l +
    b_l G_0`, :math:`d_{rc} = a_r + b_r G_0` (mm). :math:`[G_-, G_+]` are
    the 5-95 % quantiles of :math:`G_f`, :math:`G_0` their midpoint, over
    the samples with :math:`D_f` in the middle half of
    :math:`[d_{lc}, d_{rc}]` (first pass: :math:`G_0 = G_\\pm = 0`,
    :math:`m_c = 0.5`). Distinct backlash: :math:`w = d_{rc} - d_{lc} > 3 s`,
    :math:`s` = 1.4826 MAD of :math:`D_f - (a + bG_f)` over the contact
    samples. Backlash samples: :math:`d_{lc} + m w \\le D_f \\le d_{rc} - m w`,
    :math:`m` = ``centre_margin_frac``, not a contact sample.
    """
    c = _contacts(d, d_f, g_f, g_lo, g_hi, sign, contact_margin_frac, min_contact)
    spread = _distinct_backlash(c, d_f, g_f, sign)
    d_lc, d_rc, w = c.d_lc, c.d_rc, c.d_rc - c.d_lc
    mask_l, mask_r = c.mask_left, c.mask_right
    mask_c = (d_f >= d_lc + centre_margin_frac * w) & (d_f <= d_rc - centre_margin_frac * w) & ~mask_l & ~mask_r
    n_c = int(np.count_nonzero(mask_c))
    if n_c < min_centre:
        raise AnalysisError(
            f"centre (backlash) region has too few samples: {n_c} < {min_centre} (the force fight crossed the "
            f"{w:.4f} mm backlash between the corners d_lc = {d_lc:.4f} mm and d_rc = {d_rc:.4f} mm too quickly "
            "or too rarely to fit its line)"
        )
    return Regions(g_gap_N=float(c.g_gap), g_lo_N=float(g_lo), g_hi_N=float(g_hi), d_lc_mm=float(d_lc),
                   d_rc_mm=float(d_rc), spread_d_mm=spread, mask_left=readonly(mask_l), mask_centre=readonly(mask_c),
                   mask_right=readonly(mask_r))


@dataclass(frozen=True)
class _Contacts:
    """The contact samples of both sides, their lines D = a + b G_f (mm, mm/N), the gap's force level
    G_0 (N) and the corners, the lines' D at G_0 (mm)."""

    mask_left: np.ndarray
    mask_right: np.ndarray
    line_left: tuple
    line_right: tuple
    g_gap: float
    d_lc: float
    d_rc: float


def _contact_line(side: str, mask: np.ndarray, d: np.ndarray, d_f: np.ndarray, g_f: np.ndarray, sign: int,
                  min_contact: int, frac: float) -> tuple[float, float]:
    """The line D = a + b G_f of one side's contact samples; refused with too few samples or without an
    elastic slope of the global sign."""
    n = int(np.count_nonzero(mask))
    if n < min_contact:
        raise AnalysisError(
            f"{side} contact region has too few samples: {n} < {min_contact} (the "
            f"{_side_name(side, sign)} was loaded beyond {100 * frac:.0f} % of its force "
            f"span for {n} samples only)"
        )
    a, b = _ols(g_f[mask], d[mask])
    if not b > 0.0:
        g_a, g_b = float(g_f[mask].min()), float(g_f[mask].max())
        f_a, f_b = sorted((sign * g_a, sign * g_b))
        raise AnalysisError(
            f"{side} contact region has no elastic slope of the global sign: on the "
            f"{_side_name(side, sign)} D does not follow the force (dD/dF = {sign * b:.4g} mm/N, "
            f"{b * (g_b - g_a) * 1e3:+.1f} um over the {f_a:.0f} to {f_b:.0f} N loaded, against a D noise "
            f"of {noise_std(d, d_f) * 1e3:.1f} um std): the contact deflection is lost in the noise; a "
            "larger force-fight amplitude would show it"
        )
    return a, b


def _contacts(d: np.ndarray, d_f: np.ndarray, g_f: np.ndarray, g_lo: float, g_hi: float, sign: int,
              contact_margin_frac: float, min_contact: int) -> _Contacts:
    """Contact samples, lines, gap level and corners (Notes of :func:`locate_regions`, iterated)."""
    # pass 0: contact beyond half of each extreme (clear of any gap friction); then contact beyond the gap's
    # force band by contact_margin_frac of the span to the extreme, the band and level from the gap samples
    g_gap, band_lo, band_hi, frac = 0.0, 0.0, 0.0, max(contact_margin_frac, 0.5)
    for it in range(_GAP_LEVEL_ITER + 1):
        mask_r = g_f >= band_hi + frac * (g_hi - band_hi)
        mask_l = g_f <= band_lo - frac * (band_lo - g_lo)
        a_l, b_l = _contact_line("left", mask_l, d, d_f, g_f, sign, min_contact, frac)
        a_r, b_r = _contact_line("right", mask_r, d, d_f, g_f, sign, min_contact, frac)
        d_lc, d_rc = a_l + b_l * g_gap, a_r + b_r * g_gap
        w = d_rc - d_lc
        inner = (d_f > d_lc + 0.25 * w) & (d_f < d_rc - 0.25 * w) & ~mask_l & ~mask_r
        if it == _GAP_LEVEL_ITER or not w > 0.0 or np.count_nonzero(inner) < 3:
            break
        lo_q, hi_q = (float(v) for v in np.quantile(g_f[inner], [_BAND_Q, 1.0 - _BAND_Q]))
        new = (0.5 * (lo_q + hi_q), lo_q, hi_q, contact_margin_frac)
        if not (g_lo < new[1] and new[2] < g_hi) or new == (g_gap, band_lo, band_hi, frac):
            break  # a band reaching an extreme is no gap band: the last selection stands
        g_gap, band_lo, band_hi, frac = new
    return _Contacts(mask_l, mask_r, (a_l, b_l), (a_r, b_r), g_gap, d_lc, d_rc)


def _distinct_backlash(c: _Contacts, d_f: np.ndarray, g_f: np.ndarray, sign: int) -> float:
    """The spread of the low-passed D about the contact lines (1.4826 MAD, mm); refused when the corners
    are not more than :data:`RESOLUTION_SPREADS` spreads apart."""
    (a_l, b_l), (a_r, b_r) = c.line_left, c.line_right
    mask_l, mask_r, d_lc, d_rc = c.mask_left, c.mask_right, c.d_lc, c.d_rc
    w = d_rc - d_lc
    resid = np.concatenate((d_f[mask_l] - (a_l + b_l * g_f[mask_l]), d_f[mask_r] - (a_r + b_r * g_f[mask_r])))
    spread = float(1.4826 * np.median(np.abs(resid - np.median(resid))))
    if not w > RESOLUTION_SPREADS * spread:
        f_gap = sign * c.g_gap if abs(c.g_gap) >= 0.5 else 0.0  # no "-0 N"
        res = f"{RESOLUTION_SPREADS:g} x the {spread * 1e3:.2f} um spread of the low-passed D about them"
        where = (f"only {w * 1e3:.1f} um apart (D = {d_lc:.4f} and {d_rc:.4f} mm), not more than {res}: any "
                 "backlash is below that resolution" if w > 0.0 else
                 f"at D = {d_lc:.4f} mm (left) and {d_rc:.4f} mm (right), with no gap between them: any backlash "
                 f"is below the resolution, {res}")
        raise AnalysisError(
            "no distinct backlash region: D does not move freely at the gap force; the two contact lines reach "
            f"F = {f_gap:.0f} N {where}"
        )
    return spread


def binned_curve(d_f: np.ndarray, g_f: np.ndarray, bin_width_mm: float, half_win: int, min_count: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The low-passed (D, G) cloud binned along D and its slope dG/dD (paper Figure 4).

    Returns ``(d_mm, g_N, count, slope_N_per_mm, width_mm)``: median D and G
    of each bin with at least ``min_count`` samples, the slope of the binned
    curve (local linear fit over ``2 half_win + 1`` bins, then a 3-point
    running median) and the bin width used: ``bin_width_mm``, narrowed to
    1/40 of the D range when that is smaller (but not below
    ``bin_width_mm / 20``). The bin medians do not depend on how long the
    record dwells at a D.

    Raises InputError when the bins would be more than 100 000, AnalysisError
    when fewer than ``2 half_win + 5`` bins are populated (both: D is not in
    mm).
    """
    d_lo, d_hi = float(d_f.min()), float(d_f.max())
    span = d_hi - d_lo
    bw = min(bin_width_mm, max(span / MIN_BINS_PER_RANGE, bin_width_mm / 20.0))
    n_bins = int(np.ceil(span / bw)) + 1
    if n_bins > MAX_BINS:
        raise InputError(
            f"bin_width_mm = {bin_width_mm:g} mm is too small for the D range {span:.4g} mm "
            f"({n_bins} bins > {MAX_BINS}); check the units of d_mm (shape {d_f.shape})"
        )
    labels = np.floor((d_f - d_lo) / bw).astype(np.int64)
    counts_all = np.bincount(labels, minlength=n_bins)
    populated = np.flatnonzero(counts_all >= min_count)
    if populated.size < 2 * half_win + 5:
        raise AnalysisError(
            f"D range {span:.4g} mm gives only {populated.size} populated bins of "
            f"{bw:g} mm; need at least {2 * half_win + 5} to separate contact and backlash "
            "(check the units of d_mm)"
        )
    cd = np.asarray(ndimage.median(d_f, labels=labels, index=populated), dtype=float)
    cg = np.asarray(ndimage.median(g_f, labels=labels, index=populated), dtype=float)
    slope = _running_median3(_local_slope(cd, cg, half_win))
    return cd, cg, counts_all[populated], slope, float(bw)


def _local_slope(x: np.ndarray, y: np.ndarray, half_win: int) -> np.ndarray:
    """Slope of a local least-squares line over +-half_win neighbouring points."""
    m = x.size
    out = np.empty(m)
    for i in range(m):
        lo, hi = max(0, i - half_win), min(m, i + half_win + 1)
        xs, ys = x[lo:hi], y[lo:hi]
        xc = xs - xs.mean()
        sxx = float(xc @ xc)
        out[i] = float(xc @ (ys - ys.mean())) / sxx if sxx > 0.0 else 0.0
    return out


def _running_median3(v: np.ndarray) -> np.ndarray:
    """3-point running median with edge replication."""
    padded = np.concatenate(([v[0]], v, [v[-1]]))
    stack = np.stack((padded[:-2], padded[1:-1], padded[2:]))
    return np.median(stack, axis=0)
