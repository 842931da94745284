"""The decision on a measured backlash: its uncertainty budget and a guard-banded verdict (ISO 14253-1).

A reading is compared with its limit ``B_spec`` together with its expanded
uncertainty ``U`` (coverage factor k = 2):

* **pass** (conformance proven): ``B + U <= limit``;
* **fail** (non-conformance proven): ``B - U > limit``;
* **inconclusive** otherwise, or when the channel could not be measured.

The uncertainty of a BLFmaint backlash (paper 2.3, for this check's profile
and measured calibration) combines, as standard uncertainties in mm:

* the regression's own scatter (``backlash_sigma_mm`` of
  :class:`blf.maint.results.BlfMaintResult`: LVDT and load-cell noise after the
  regression's averaging, Newey-West);
* the LVDT pitch left after calibration, over the LVDT travel that enters the
  reading (the backlash itself): ``B * p_r`` with ``p_r`` the calibration's
  relative pitch uncertainty (uncalibrated: the pitch error bound, rectangular);
* the temperature-induced LVDT error: zero for BLFmaint, whose calibration
  runs minutes before it in the same check (paper 2.3), stated as such;
* the method: BLFmaint's validated accuracy over its envelope
  (``max(5 um, 5 %)`` of the backlash, docs/blfmaint.md), a bound taken as
  rectangular (divided by sqrt 3).

Pure: numbers in, frozen dataclasses out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from blf.errors import InputError
from blf.validate import positive_scalar, scalar

__all__ = ["COVERAGE_FACTOR", "UncertaintyBudget", "ChannelVerdict", "combine", "maint_uncertainty", "serv_uncertainty",
           "decide", "overall"]

COVERAGE_FACTOR = 2.0  #: k of the expanded uncertainty (about 95 % coverage)
METHOD_BOUND_MM = 0.005  #: BLFmaint's validated accuracy bound over its envelope, absolute part [mm]
METHOD_BOUND_REL = 0.05  #: ... and relative part (the larger of the two applies)

#: BLFserv's method bound, relative: the improved method read within +-7.3 % of truth over 20 seeds and five
#: scenarios (docs/blfserv.md), taken as 10 %; the paper's Delta D reads 21-39 % low, taken as 40 %.
SERV_METHOD_REL = {"improved": 0.10, "paper": 0.40}


class Status(StrEnum):
    """A channel's or a check's decision; a ``str`` whose value is what result.json and the history
    hold (``json.dumps(Status.PASS) == '"pass"'``)."""

    PASS = "pass"
    FAIL = "fail"
    INCONCLUSIVE = "inconclusive"
    NOT_TRAVERSED = "not_traversed"  #: BLFserv found no backlash crossing (a channel only, never the check)


@dataclass(frozen=True)
class UncertaintyBudget:
    """Standard uncertainties [mm] of one backlash reading and their expanded total.

    Attributes
    ----------
    statistical_mm : float
        The regression's scatter (noise after averaging).
    pitch_mm : float
        LVDT pitch left after calibration, over the travel across the play.
    temperature_mm : float
        Temperature-induced LVDT error (0 for BLFmaint: calibrated in the same check).
    method_mm : float
        The method's validated accuracy bound, as a standard uncertainty.
    combined_mm : float
        Root sum of squares of the four.
    expanded_mm : float
        ``coverage_factor * combined_mm``: the U of the verdict.
    coverage_factor : float
        k (2).
    """

    statistical_mm: float
    pitch_mm: float
    temperature_mm: float
    method_mm: float
    combined_mm: float
    expanded_mm: float
    coverage_factor: float = COVERAGE_FACTOR


@dataclass(frozen=True)
class ChannelVerdict:
    """The decision on one channel.

    Attributes
    ----------
    status : Status
        ``"pass"``, ``"fail"``, ``"inconclusive"`` or (BLFserv) ``"not_traversed"``.
    backlash_mm, uncertainty_mm : float or None
        The reading and its expanded uncertainty U (k = 2); None when not measured.
    limit_mm : float
        B_spec of the channel.
    margin_mm : float or None
        ``limit - backlash`` (positive: below the limit).
    reason : str
        The rule that decided, in words, with the numbers.
    """

    status: Status
    backlash_mm: float | None
    uncertainty_mm: float | None
    limit_mm: float
    margin_mm: float | None
    reason: str


def combine(statistical_mm: float, pitch_mm: float, temperature_mm: float, method_mm: float) -> UncertaintyBudget:
    """Root sum of squares of four standard uncertainties [mm] and U = k u_c (k = 2)."""
    terms = [scalar(v, n, "mm", lo=0.0) for v, n in ((statistical_mm, "statistical_mm"), (pitch_mm, "pitch_mm"),
                                                     (temperature_mm, "temperature_mm"), (method_mm, "method_mm"))]
    uc = math.sqrt(sum(t * t for t in terms))
    return UncertaintyBudget(*terms, uc, COVERAGE_FACTOR * uc)


def maint_uncertainty(backlash_mm: float, sigma_mm: float, pitch_rel_uncertainty: float, *,
                      temperature_error: float = 0.0) -> UncertaintyBudget:
    """Uncertainty budget of a BLFmaint backlash reading (see the module docstring).

    Parameters
    ----------
    backlash_mm : float
        The reading B [mm], >= 0.
    sigma_mm : float
        Its regression standard deviation [mm], >= 0.
    pitch_rel_uncertainty : float
        Relative standard uncertainty of the LVDT pitch after calibration
        (dimensionless, e.g. 1e-4); for an uncalibrated LVDT the pitch error
        bound divided by sqrt 3.
    temperature_error : float, optional
        Relative temperature-induced LVDT error over the reading (default 0:
        BLFmaint calibrates in the same check).

    Returns
    -------
    UncertaintyBudget

    Notes
    -----
    .. math::

        u_c = \\sqrt{\\sigma^2 + (B p_r)^2 + (B\\tau)^2
              + \\left(\\max(b_0, b_r B)/\\sqrt{3}\\right)^2},
        \\qquad U = k\\,u_c,\\ k = 2

    with :math:`b_0` = 5 um and :math:`b_r` = 5 % the method's validated bound.
    """
    b = scalar(backlash_mm, "backlash_mm", "mm", lo=0.0)
    s = scalar(sigma_mm, "sigma_mm", "mm", lo=0.0)
    pr = scalar(pitch_rel_uncertainty, "pitch_rel_uncertainty", "(relative)", lo=0.0)
    tau = scalar(temperature_error, "temperature_error", "(relative)", lo=0.0)
    return combine(s, b * pr, b * tau, max(METHOD_BOUND_MM, METHOD_BOUND_REL * b) / math.sqrt(3.0))


def serv_uncertainty(backlash_mm: float, sigma_mm: float, pitch_mm: float, temperature_bound_mm: float,
                     method: str = "improved") -> UncertaintyBudget:
    r"""Uncertainty budget of a BLFserv backlash reading.

    Parameters
    ----------
    backlash_mm, sigma_mm : float
        The reading (median of the counted jumps) and its standard error [mm].
    pitch_mm : float
        LVDT pitch left after calibration over the stroke the surface moved
        (:attr:`blf.maint.accuracy.MethodErrors.pitch_compensated_mm`) [mm].
    temperature_bound_mm : float
        The temperature-induced LVDT error bound over the jump read (paper 2.3:
        1 % of 2 mm), rectangular [mm].
    method : str
        ``"improved"`` or ``"paper"``: the method bound (:data:`SERV_METHOD_REL`).

    Notes
    -----
    :math:`u_c = \sqrt{\sigma^2 + u_p^2 + (T/\sqrt 3)^2 + (m B/\sqrt 3)^2}`, :math:`U = 2 u_c`.
    """
    b = scalar(backlash_mm, "backlash_mm", "mm", lo=0.0)
    rel = SERV_METHOD_REL.get(method)
    if rel is None:
        raise InputError(f"method must be one of {tuple(SERV_METHOD_REL)}, got {method!r}")
    t = scalar(temperature_bound_mm, "temperature_bound_mm", "mm", lo=0.0)
    return combine(sigma_mm, pitch_mm, t / math.sqrt(3.0), rel * b / math.sqrt(3.0))


def decide(backlash_mm: float | None, uncertainty_mm: float | None, limit_mm: float, *,
           missing: str = "", not_traversed: bool = False) -> ChannelVerdict:
    """Guard-banded decision of one reading against its limit (ISO 14253-1).

    Parameters
    ----------
    backlash_mm : float or None
        The reading [mm]; None when the channel could not be measured.
    uncertainty_mm : float or None
        Its expanded uncertainty U [mm] (k = 2).
    limit_mm : float
        The limit B_spec [mm], > 0.
    missing : str, optional
        Why the channel was not measured (used when ``backlash_mm`` is None).
    not_traversed : bool, optional
        With ``backlash_mm`` None: the status is ``"not_traversed"`` (BLFserv found no backlash
        crossing), which :func:`overall` leaves out, instead of ``"inconclusive"``.

    Returns
    -------
    ChannelVerdict
        pass if ``B + U <= limit``; fail if ``B - U > limit``; else inconclusive.
    """
    lim = positive_scalar(limit_mm, "limit_mm", "mm")
    if backlash_mm is None:
        if not_traversed:
            return ChannelVerdict(Status.NOT_TRAVERSED, None, None, lim, None,
                                  missing or "no backlash traversal in the recording")
        why = missing or "not measured"
        return ChannelVerdict(Status.INCONCLUSIVE, None, None, lim, None, f"not measured: {why}")
    b = scalar(backlash_mm, "backlash_mm", "mm")
    u = scalar(uncertainty_mm, "uncertainty_mm", "mm", lo=0.0)
    margin = lim - b
    if b + u <= lim:
        return ChannelVerdict(Status.PASS, b, u, lim, margin, f"B + U = {b + u:.4f} mm <= limit {lim:.4f} mm")
    if b - u > lim:
        return ChannelVerdict(Status.FAIL, b, u, lim, margin, f"B - U = {b - u:.4f} mm > limit {lim:.4f} mm")
    return ChannelVerdict(Status.INCONCLUSIVE, b, u, lim, margin,
                          f"the limit {lim:.4f} mm lies within B +- U = {b:.4f} +- {u:.4f} mm: "
                          "neither conformance nor non-conformance is proven")


def overall(verdicts: Mapping[str, ChannelVerdict]) -> Status:
    """The check's decision from its channels: pass only if every channel passes, fail if any
    fails, else inconclusive. Channels ``not_traversed`` (BLFserv: no backlash crossing in the
    recording, expected for the external channel in symmetric operation) do not count, unless
    no channel was traversed."""
    states = [v.status for v in verdicts.values() if v.status != Status.NOT_TRAVERSED]
    if not states:
        return Status.INCONCLUSIVE
    if any(s == Status.FAIL for s in states):
        return Status.FAIL
    if all(s == Status.PASS for s in states):
        return Status.PASS
    return Status.INCONCLUSIVE
