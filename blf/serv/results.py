"""What BLFserv gives (:func:`blf.serv.blfserv.blf_serv`, :class:`blf.serv.blfserv.BlfServMonitor`): each
traversal of the backlash it detected and the result per D channel, as frozen dataclasses (mm, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blf.serv.filters import ServFilters

__all__ = ["ServJump", "BlfServResult", "improved_reading", "paper_reading"]


@dataclass(frozen=True)
class ServJump:
    """One detected traversal of the backlash (an event of the detector).

    Attributes
    ----------
    t_start_s, t_end_s : float
        First and last sample (s) where the second derivative was outside its
        threshold zone (excursions closer than the merge gap joined).
    t_jump_s : float
        Estimated instant of the jump, s: centroid of the part of
        :math:`|\\dot D|` above its threshold, minus the filters' delay.
    height_mm : float
        Improved method: level of D after minus level before, both
        extrapolated to ``t_jump_s`` from straight lines fitted on the
        plateaus either side, mm (signed; NaN if a plateau was unusable).
    height_sigma_mm : float
        Standard uncertainty of ``height_mm`` from the noise level and the
        fit geometry, mm.
    paper_delta_mm : float
        Paper method: change of the filtered D over the stretch where both
        derivatives were outside the zone (largest magnitude if there were
        several stretches in this event), mm, signed.
    n_before, n_after : int
        Samples in the plateau fits.
    residual_before_mm, residual_after_mm : float
        RMS residuals of the plateau fits, mm (NaN if not fitted).
    accepted : bool
        Counted by the improved method (see ``reason``).
    paper_accepted : bool
        Counted by the paper method: ``|paper_delta_mm| >= min_jump_mm``.
    reason : str
        ``"ok"`` or why the improved method did not count it:
        ``"plateau before too short"``, ``"plateau after too short"``,
        ``"plateau before not quiet"``, ``"plateau after not quiet"``,
        ``"below min jump"``, ``"event too long"``.
    """

    t_start_s: float
    t_end_s: float
    t_jump_s: float
    height_mm: float
    height_sigma_mm: float
    paper_delta_mm: float
    n_before: int
    n_after: int
    residual_before_mm: float
    residual_after_mm: float
    accepted: bool
    paper_accepted: bool
    reason: str


@dataclass(frozen=True)
class BlfServResult:
    """BLFserv result for one D channel.

    Attributes
    ----------
    backlash_mm : float or None
        Backlash by ``method``, mm; None if the backlash was not traversed
        (no counted jump).
    traversals : int
        Counted jumps of ``method`` (0: "not traversed").
    method : str
        ``"improved"`` or ``"paper"``.
    backlash_sigma_mm : float or None
        Standard uncertainty of ``backlash_mm`` (improved: of the median of
        the counted heights, from their spread, or the fit uncertainty for
        one or two; paper: not available, None).
    backlash_improved_mm, backlash_paper_mm : float or None
        Both methods' backlash (for comparison), mm.
    traversals_improved, traversals_paper : int
        Both methods' counts.
    jumps : tuple of ServJump
        All detected events, in time order.
    noise_std_mm : float
        White-noise level of D used for the thresholds, mm.
    threshold_d1_mm_per_s, threshold_d2_mm_per_s2 : float
        Half-widths of the threshold zones of the first and second derivative.
    min_jump_mm : float
        Smallest height counted as a traversal, mm.
    filters : ServFilters
    n_samples : int
        Samples analysed.
    t0_s : float
        Time of the first sample, s.
    d_filtered_mm, d1_mm_per_s, d2_mm_per_s2 : ndarray or None
        The filter outputs, shape (n,) (batch form with ``keep_signals``;
        None from the streaming monitor, which keeps no history). Read-only.
    """

    backlash_mm: float | None
    traversals: int
    method: str
    backlash_sigma_mm: float | None
    backlash_improved_mm: float | None
    backlash_paper_mm: float | None
    traversals_improved: int
    traversals_paper: int
    jumps: tuple
    noise_std_mm: float
    threshold_d1_mm_per_s: float
    threshold_d2_mm_per_s2: float
    min_jump_mm: float
    filters: ServFilters
    n_samples: int
    t0_s: float
    d_filtered_mm: np.ndarray | None
    d1_mm_per_s: np.ndarray | None
    d2_mm_per_s2: np.ndarray | None


def improved_reading(counted) -> tuple[float | None, float | None]:
    """The improved method's backlash and its standard uncertainty from its counted jumps, mm: the median
    of :math:`|h|`; :math:`1.2533\\,s/\\sqrt{N}` (``s`` the spread of the counted heights) for N >= 3,
    else the largest fit uncertainty of a jump; ``(None, None)`` for none counted (not traversed)."""
    if not counted:
        return None, None
    hs = np.array([abs(j.height_mm) for j in counted])
    b = float(np.median(hs))
    if hs.size >= 3:
        return b, float(1.2533 * np.std(hs, ddof=1) / math.sqrt(hs.size))
    return b, float(max(j.height_sigma_mm for j in counted))


def paper_reading(counted) -> float | None:
    """The paper method's backlash from its counted jumps: the largest :math:`|\\Delta D|`, mm (None: none)."""
    return float(max(abs(j.paper_delta_mm) for j in counted)) if counted else None


def readings(jumps, method: str) -> dict:
    """The readings of a channel from its jumps: both methods' backlash and counts, and the one ``method``
    ("improved" or "paper") reports as ``backlash_mm``, ``traversals``, ``backlash_sigma_mm`` (the fields of
    :class:`BlfServResult` they fill)."""
    acc = [j for j in jumps if j.accepted]
    pac = [j for j in jumps if j.paper_accepted]
    b_imp, s_imp = improved_reading(acc)
    b_pap = paper_reading(pac)
    b, n, s = (b_imp, len(acc), s_imp) if method == "improved" else (b_pap, len(pac), None)
    return {"backlash_mm": b, "traversals": n, "backlash_sigma_mm": s, "backlash_improved_mm": b_imp,
            "backlash_paper_mm": b_pap, "traversals_improved": len(acc), "traversals_paper": len(pac)}
