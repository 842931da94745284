"""The effort of a single axis (:mod:`blf.diagnose.axis_reference`) as a force, and whether it sees a known load.

Pure: arrays in, frozen dataclasses out (no IO).

Conversions (:func:`effort_to_force`, :func:`identify_current_per_force`):
a force (N) is used as it is; a torque :math:`\\tau` (N m) through the lead
:math:`p` (m per revolution), :math:`F = 2\\pi\\tau/p`; a current :math:`I` (A)
through a law and a gain :math:`k` (A/N):

* ``torque``: a phase current that follows the torque, :math:`F = I/k`;
* ``power``: a supply current that follows mechanical power at one running
  speed, :math:`I = I_0 + k F\\,\\mathrm{sign}(\\dot q)`, so
  :math:`F = \\mathrm{sign}(\\dot q) I/k` while moving (the drive's loss
  :math:`I_0/k` then reads as friction at the running speed and cancels in a
  change against a reference at the same speed); nothing at standstill.

:func:`effort_load_check` (:class:`EffortCheck`): does the effort, so converted, see the recording's known load
(its fitted load coefficient near 1 within an allowance)?
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blf.diagnose.axis_reference import AxisFit
from blf.errors import AnalysisError, InputError
from blf.validate import as_1d_finite, one_of, positive_scalar, same_shape, scalar

__all__ = ["CurrentGain", "EffortCheck", "effort_to_force", "identify_current_per_force", "effort_load_check", "LAWS"]


LAWS = ("torque", "power")


@dataclass(frozen=True)
class CurrentGain:
    """The current per newton along the motion, identified on a recording with a known load."""

    law: str
    a_per_N: float
    uncertainty_a_per_N: float
    words: str


@dataclass(frozen=True)
class EffortCheck:
    """Whether the effort sees the recording's known load (:func:`effort_load_check`); forces in N."""

    made: bool  #: False: the check could not be made (``words`` says why)
    trusted: bool | None  #: None when not made
    load_N: float | None  #: the known load, mean over the samples compared
    seen_N: float | None  #: the load the effort implies: mean known load minus the fitted offset F_0
    uncertainty_N: float | None  #: standard uncertainty of ``seen_N``
    words: str


def effort_to_force(effort, kind: str, *, v_dir=None, lead_m: float | None = None,
                    current_law: str | None = None, current_a_per_N: float | None = None) -> np.ndarray:
    """The force the drive delivers along +q (N) from its recorded effort.

    Parameters
    ----------
    effort : array_like, shape (n,)
        Force (N), torque (N m) or current (A), as ``kind`` says.
    kind : {"force", "torque", "current"}
    v_dir : array_like, shape (n,), optional
        Direction of motion (+1, -1, 0); needed for the ``power`` law.
    lead_m : float, optional
        Screw lead, m per revolution (torque): :math:`F = 2\\pi\\tau/p`.
    current_law : {"torque", "power"}, optional
    current_a_per_N : float, optional
        k, A per N along the motion.

    Returns
    -------
    ndarray
        N; 0 at standstill under the ``power`` law (mask those samples).
    """
    x = as_1d_finite(effort, "effort", {"force": "N", "torque": "N m", "current": "A"}.get(kind, "?"))
    one_of(kind, "kind", ("force", "torque", "current"))
    if kind == "force":
        return x
    if kind == "torque":
        return 2 * np.pi * x / positive_scalar(lead_m, "lead_m", "m")
    law = one_of(current_law, "current_law", LAWS)
    k = positive_scalar(current_a_per_N, "current_a_per_N", "A/N")
    if law == "torque":
        return x / k
    if v_dir is None:
        raise InputError("the power law needs the direction of motion v_dir")
    return np.sign(np.asarray(v_dir, float)) * x / k


def identify_current_per_force(current_A, load_N, v_dir, used, law: str) -> CurrentGain:
    """The current per newton (A/N) from a recording with a known load.

    Parameters
    ----------
    current_A, load_N, v_dir : array_like, shape (n,)
        Current (A), known external force (N, along +q), direction of motion (+1, -1, 0).
    used : array_like of bool, shape (n,)
        Samples compared (moving, no transient).
    law : {"torque", "power"}

    Returns
    -------
    CurrentGain

    Notes
    -----
    ``power``: :math:`I = k F_f + k (F_0 - F_{load})\\,\\mathrm{sign}(\\dot q)`;
    ``torque``: :math:`I = k F_f\\,\\mathrm{sign}(\\dot q) + k (F_0 - F_{load})`.
    With one load level :math:`F_0` cannot be told from the load and is taken
    as 0 (the part of the current that changes with direction (power) or not
    (torque) is the load's); with two or more levels it is fitted.
    """
    law = one_of(law, "law", LAWS)
    i = as_1d_finite(current_A, "current_A", "A")
    L = as_1d_finite(load_N, "load_N", "N")
    d = np.sign(as_1d_finite(v_dir, "v_dir", "1"))
    u = np.asarray(used, bool) & (d != 0)
    same_shape((i, "current_A", "A"), (L, "load_N", "N"), (d, "v_dir", "1"), (u, "used", ""))
    levels = np.unique(np.round(L[u], 6))
    if u.sum() < 20 or np.all(levels == 0) or not (np.any(d[u] > 0) and np.any(d[u] < 0)):
        raise AnalysisError("identifying the current per newton needs a known non-zero load while moving in "
                            "both directions")
    load_col = -L * d if law == "power" else -L
    cols = [np.ones_like(i) if law == "power" else d, load_col]
    if levels.size >= 2:
        cols.append(d if law == "power" else np.ones_like(i))
    X = np.column_stack(cols)[u]
    theta, *_ = np.linalg.lstsq(X, i[u], rcond=None)
    r = i[u] - X @ theta
    cov = np.linalg.pinv(X.T @ X) * float(r @ r) / max(1, r.size - X.shape[1])
    k, uk = float(theta[1]), float(np.sqrt(max(cov[1, 1], 0.0)))
    if not k > 0:
        raise AnalysisError(f"the current does not rise with the load as the {law} law says (k = {k:.3g} A/N)")
    assume = ("fitted beside it" if levels.size >= 2 else
              "taken as 0 (one load level: the part of the current that "
              + ("changes with direction" if law == "power" else "does not change with direction")
              + " is the load's)")
    return CurrentGain(law, k, uk, f"{law} law, k = {k:.4g} A/N from {int(u.sum())} samples at "
                       f"{levels.size} load level(s); the direction-dependent force offset {assume}")


def effort_load_check(fit: AxisFit, load_N, used, allowance_N: float, z_min: float = 3.0,
                      gain_rel_u: float = 0.0) -> EffortCheck:
    """Whether the effort sees the recording's known external load with the sign the conversion predicts.

    Parameters
    ----------
    fit : AxisFit
        The nominal model fitted on the recording with its load
        (:func:`blf.diagnose.axis_reference.fit_axis`); its ``offset_N`` :math:`F_0` is the force along
        the motion's direction-dependent (``power`` law) or constant (force, torque, ``torque`` law) part
        of the effort that the stated load does not explain.
    load_N : array_like, shape (n,), or None
        The known external force on the axis, N (positive along +q); None: no load column.
    used : array_like of bool, shape (n,)
        The samples compared.
    allowance_N : float
        The largest direction-dependent force change that is not named (the force floor), N.
    z_min : float
        Statistical support, as in :func:`blf.diagnose.axis_reference.compare_fits`.
    gain_rel_u : float
        Relative standard uncertainty of the conversion (e.g. of the current per newton), 1.

    Returns
    -------
    EffortCheck

    Notes
    -----
    The effort implies the load :math:`L_{seen} = \\bar L - F_0` (N) with standard uncertainty
    :math:`u = \\sqrt{u_{F_0}^2 + (L_{seen}\\,u_k/k)^2}`. The check is made when the load is large
    enough to be seen beyond what an unnamed change may hide and the two answers below are apart by
    more than the statistics, :math:`|\\bar L| > \\max(z_{min} u + F_{allow},\\ 2 z_{min} u)`, and with
    both directions of motion (else :math:`F_0` is one force with the friction). Two answers, the
    nearer wins: the effort sees the load (:math:`L_{seen} = \\bar L` plus a change) or it does not
    (:math:`L_{seen} = 0`: a re-levelled, unloaded or unrelated signal). The effort is **not
    trusted** when it is nearer to seeing no load, or sees the opposite one:
    :math:`L_{seen}\\,\\mathrm{sign}(\\bar L) \\le |\\bar L|/2`. Then at least half the known load,
    more than the floor, is missing: the effort's force content, not the rig, is contradicted. A seen
    load of the right sign nearer the known one is left to the comparison (a direction-dependent force
    change: an offset, a direction-dependent friction, another load).
    """
    allow = scalar(allowance_N, "allowance_N", "N", lo=0)
    z_min = positive_scalar(z_min, "z_min", "1")
    rel = scalar(gain_rel_u, "gain_rel_u", "1", lo=0)
    if load_N is None:
        return EffortCheck(False, None, None, None, None, "no load column: the effort could not be checked "
                           "against a known load")
    u = np.asarray(used, bool)
    L = as_1d_finite(load_N, "load_N", "N")
    if L.shape != u.shape:
        raise InputError(f"load_N has {L.size} samples, used {u.size}")
    if "offset_N" not in fit.parameters or fit.uncertainty.get("offset_N", 0.0) == 0.0 or not u.any():
        return EffortCheck(False, None, None, None, None, "one direction of motion: the direction-dependent "
                           "force cannot be told from the friction; the effort could not be checked against the load")
    lbar = float(np.mean(L[u]))
    seen = lbar - float(fit.parameters["offset_N"])
    unc = float(np.hypot(fit.uncertainty["offset_N"], seen * rel))
    tol = max(z_min * unc + allow, 2 * z_min * unc)
    if abs(lbar) <= tol:
        return EffortCheck(False, None, lbar, seen, unc, f"the known load ({lbar:.4g} N) is within {tol:.4g} N "
                           f"({z_min:g} u + the floor of {allow:g} N): too small to check the effort against")
    ok = bool(seen * np.sign(lbar) > abs(lbar) / 2)
    how = ("sees it" if ok else "sees the opposite load" if seen * np.sign(lbar) < -z_min * unc else
           "does not see it (nearer to no load than to the known one)")
    words = (f"known load {lbar:.4g} N; the effort implies {seen:.4g} ± {unc:.2g} N: it {how}"
             + ("" if ok else ": its force content is contradicted by the known load; not diagnosed"))
    return EffortCheck(True, ok, lbar, seen, unc, words)
