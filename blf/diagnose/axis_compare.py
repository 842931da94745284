"""A single positioning axis against a reference recording, in one pure step: what changed, in physical units.

Pure: arrays in, frozen dataclasses out (no IO). Given both recordings prepared alike
(:class:`AxisSamples`: force along the motion, speed and acceleration, the samples kept and what they can
separate, :mod:`blf.diagnose.axis_reference`), :func:`compare_axis`

1. fits both with the terms both can separate (:func:`common_terms`): the reference must run in every
   direction and at every speed level of the recording diagnosed; a term only one can separate (the mass,
   where only one has acceleration content) is held in both, and said so;
2. screens the terms along the stroke (:data:`blf.diagnose.axis_reference.STROKE_TERMS`) both recordings
   can separate from the nominal ones (:func:`stroke_candidates`), fitted beside them on both;
3. compares each parameter with its reference value against its floor (:func:`axis_floors`: the force floor
   :math:`F_f` at the running speed :math:`v_r` for the viscous term, :math:`F_f/v_r`, and at the end of
   the stroke for the terms along it, :math:`F_f/h` and :math:`F_f/h^2` with :math:`h` the half stroke);
4. checks each recording's effort against its known load
   (:func:`blf.diagnose.axis_effort.effort_load_check`, allowance the force floor).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from blf.diagnose.axis_effort import EffortCheck, effort_load_check
from blf.diagnose.axis_reference import (
    AxisFit,
    EffortMask,
    Identifiability,
    compare_fits,
    design_columns,
    fit_axis,
    separable,
    stroke_terms,
)
from blf.errors import AnalysisError
from blf.validate import positive_scalar

__all__ = ["AxisSamples", "AxisComparison", "compare_axis", "common_terms", "stroke_candidates", "axis_floors"]

#: why a term along the stroke is not a candidate
_NOT_SEPARABLE = "not separable from the nominal terms in both recordings"


@dataclass(frozen=True)
class AxisSamples:
    """One single-axis recording prepared for a fit.

    Attributes
    ----------
    name : str
        What the recording is called in a message (its path).
    q_m, force_N, v_m_per_s, a_m_per_s2 : ndarray, shape (n,)
        Position (m), the drive's force along +q (N), Savitzky-Golay speed (m/s) and acceleration (m/s^2).
    mask : EffortMask
        The samples compared (``mask.used``).
    ident : Identifiability
        What those samples can separate.
    load_N : ndarray, shape (n,), or None
        The known external force on the axis (N, positive along +q); None: no load column.
    """

    name: str
    q_m: np.ndarray
    force_N: np.ndarray
    v_m_per_s: np.ndarray
    a_m_per_s2: np.ndarray
    mask: EffortMask
    ident: Identifiability
    load_N: np.ndarray | None


@dataclass(frozen=True)
class AxisComparison:
    """The result of :func:`compare_axis`.

    Attributes
    ----------
    ident : Identifiability
        The terms both recordings were fitted with.
    origin_m, half_stroke_m : float
        The stroke terms' origin (median position of the reference's samples used) and half stroke, m.
    not_candidates : tuple of (str, str)
        Stroke terms not screened, with why.
    reference, recording : AxisFit
        The fits of the reference and of the recording diagnosed.
    floors : dict
        Each parameter's floor in its unit (:func:`axis_floors`).
    changes : tuple of ParameterChange
        Each parameter against its reference value (:func:`blf.diagnose.axis_reference.compare_fits`).
    effort_recording, effort_reference : EffortCheck
        Each effort against its known load.
    """

    ident: Identifiability
    origin_m: float
    half_stroke_m: float
    not_candidates: tuple
    reference: AxisFit
    recording: AxisFit
    floors: dict
    changes: tuple
    effort_recording: EffortCheck
    effort_reference: EffortCheck
    periodic: object = None  #: :class:`blf.diagnose.axis_periodic.AxisPeriodic`, or None: not sought


def common_terms(ref: Identifiability, new: Identifiability, ref_name: str) -> Identifiability:
    """The terms both recordings are fitted with: those both can separate (``new`` with the columns both
    have, the others held at 0 and said so).

    Raises
    ------
    AnalysisError
        The reference lacks a direction or a speed level (within 10 %) of the recording diagnosed, or has
        no column at all: too short to identify the nominal model.
    """
    lacks = [f"direction {'+' if d > 0 else '-'}" for d in new.directions if d not in ref.directions]
    lacks += [f"speed {s:.4g} m/s" for s in new.speed_levels_m_per_s
              if not any(abs(s / r - 1) <= 0.1 for r in ref.speed_levels_m_per_s)]
    if lacks or not ref.columns:
        raise AnalysisError(f"{ref_name}: reference too short to identify the nominal model: no motion in "
                            f"{', '.join(lacks) or 'any direction'} of the recording diagnosed")
    cols = tuple(c for c in new.columns if c in ref.columns)
    dropped = [c for c in new.columns + ref.columns if c not in cols]
    merged = list(new.merged) + [((c,), "", "separable in only one of the two recordings: held in both",
                                  "the same motion in both") for c in dict.fromkeys(dropped)]
    fixed = dict(new.fixed) | dict(ref.fixed) | {c: 0.0 for c in dropped}
    return dataclasses.replace(new, columns=cols, fixed=fixed, merged=tuple(merged))


def axis_floors(force_floor_N: float, speed_m_per_s: float, half_stroke_m: float) -> dict:
    """Each parameter's floor in its unit: the force floor (N) for the forces, at the running speed
    (m/s) for the viscous coefficient, at the end of the stroke (m from the origin) for the terms along it."""
    f = positive_scalar(force_floor_N, "force_floor_N", "N")
    out = {"friction_N": f, "coulomb_N": f, "offset_N": f}
    if speed_m_per_s > 0:
        out["viscous_N_s_per_m"] = f / speed_m_per_s
    if half_stroke_m > 0:
        out |= {"position_dependent_friction_N_per_m": f / half_stroke_m,
                "position_dependent_force_N_per_m": f / half_stroke_m,
                "position_dependent_force_N_per_m2": f / half_stroke_m ** 2}
    return out


def stroke_candidates(ref: AxisSamples, new: AxisSamples, ident: Identifiability) -> tuple:
    """The terms along the stroke both recordings can separate from the nominal ones: (origin m, half stroke m,
    columns of the reference, columns of the recording diagnosed, not separable [(name, why)])."""
    q_used = ref.q_m[ref.mask.used]
    origin, half = float(np.median(q_used)), float(np.ptp(q_used)) / 2
    tr, tn = stroke_terms(ref.q_m, ref.v_m_per_s, origin), stroke_terms(new.q_m, new.v_m_per_s, origin)
    keep, drop = [], []
    for name in tr:
        ok = all(separable(design_columns(ident.columns, p.v_m_per_s, p.a_m_per_s2)[p.mask.used],
                           t[name][p.mask.used]) for p, t in ((ref, tr), (new, tn)))
        (keep if ok else drop).append(name)
    return (origin, half, {k: tr[k] for k in keep}, {k: tn[k] for k in keep},
            tuple((n, _NOT_SEPARABLE) for n in drop))


def _fit(p: AxisSamples, ident: Identifiability, extra: dict) -> AxisFit:
    return fit_axis(p.force_N, p.v_m_per_s, p.a_m_per_s2, p.mask.used, ident, p.load_N, extra=extra)


def compare_axis(new: AxisSamples, ref: AxisSamples, force_floor_N: float, z_min: float = 3.0,
                 gain_rel_u: float = 0.0, periodic_floor_N: float | None = None, lead_m: float | None = None,
                 gear_ratio: float | None = None, scale_tolerance: float = 0.0) -> AxisComparison:
    """A single-axis recording against its reference: both fitted with the terms both can separate, each
    parameter compared against its floor, each effort checked against its known load.

    Parameters
    ----------
    new, ref : AxisSamples
        The recording diagnosed and its reference, prepared alike (the same effort conversion).
    force_floor_N : float
        The relevance floor of a force change, N (> 0).
    z_min : float
        Statistical support of a named change (|change| > z_min combined standard uncertainties).
    gain_rel_u : float
        Relative standard uncertainty of the effort conversion (e.g. the current per newton).
    periodic_floor_N : float, optional
        The relevance floor of a periodic force's amplitude change, N; None: forces periodic in position
        are not sought. Where sought they are found in both residuals and fitted jointly with the nominal
        model (:mod:`blf.diagnose.axis_periodic`), so the nominal changes are those of the joint fit.
    lead_m, gear_ratio : float, optional
        The screw's lead (m per turn) and motor turns per screw turn: which order of which part a period is.
    scale_tolerance : float
        The stated tolerance of the position sensor's scale (fraction, [0, 0.5)) in that order's check
        (:func:`blf.diagnose.periodic.lead_order`); 0: the scale taken as exact.

    Returns
    -------
    AxisComparison

    Raises
    ------
    AnalysisError
        The reference cannot identify the nominal model (too short, a direction or speed level missing), or
        a recording cannot be fitted; the message names the recording.
    """
    ident = common_terms(ref.ident, new.ident, ref.name)
    origin, half, xr, xn, not_cand = stroke_candidates(ref, new, ident)
    try:
        fr = _fit(ref, ident, xr)
    except AnalysisError as exc:
        raise AnalysisError(f"{ref.name}: reference too short to identify the nominal model ({exc})") from None
    try:
        fn = _fit(new, ident, xn)
    except AnalysisError as exc:
        raise AnalysisError(f"{new.name}: {exc}") from None
    periodic = None
    if periodic_floor_N is not None:
        from blf.diagnose.axis_periodic import compare_periodic, periodic_pair
        plan = periodic_pair(new, ref, ident, fn, fr, xn, xr)
        if plan.periods_new_m:
            fr, fn = _fit(ref, ident, xr | plan.columns_ref), _fit(new, ident, xn | plan.columns_new)
        periodic = compare_periodic(plan, new, ref, ident, fn, fr, periodic_floor_N, z_min, xn, lead_m, gear_ratio,
                                    xr, scale_tolerance)
    floors = axis_floors(force_floor_N, fr.running_speed_m_per_s, half)
    changes = [c for c in compare_fits(fn, fr, floors, z_min) if not c.name.startswith("periodic")]
    checks = [effort_load_check(fit, p.load_N, p.mask.used, force_floor_N, z_min, gain_rel_u)
              for fit, p in ((fn, new), (fr, ref))]
    return AxisComparison(ident, origin, half, not_cand, fr, fn, floors, tuple(changes), *checks, periodic)
