"""Which nominal parameters a recording determines: the shape of the nominal fit's covariance.

For the comparison of two recordings (:mod:`hil.analysis.diagnose.dual_reference`): a parameter the
recording does not determine alone is not compared alone. Pure: a model and its sample period in,
a :class:`blf.diagnose.model.NominalCovariance` out.
"""

from __future__ import annotations

import numpy as np

from blf.diagnose.engine import band_comparison
from blf.diagnose.fit import nominal_jacobian, safe_predict
from blf.diagnose.model import EIGEN_FLOOR, DiagnoseConfig, NominalCovariance, ReplayModel
from blf.errors import AnalysisError

__all__ = ["nominal_covariance"]


def nominal_covariance(model: ReplayModel, sample_period_s: float, nominal: dict,
                       config: DiagnoseConfig | None = None) -> NominalCovariance:
    """The shape of the nominal parameters' covariance at a nominal fit: which of them the recording separates.

    Parameters
    ----------
    model : ReplayModel
    sample_period_s : float
        Sample period of the recording, s (> 0).
    nominal : dict
        {name: value} of every nominal parameter (a :class:`Diagnosis`'s ``nominal``).
    config : DiagnoseConfig, optional

    Returns
    -------
    NominalCovariance
        From the Jacobian J of the weighted band residual (both halves, the noise floors set at
        ``nominal``) with respect to the scaled parameters: :math:`F = J^T J`, normalised
        :math:`F_n = D^{-1/2} F D^{-1/2}` (D its diagonal), eigenvalues clipped at
        :data:`EIGEN_FLOOR` times the largest, inverted, scaled back to physical units.

    Raises
    ------
    blf.errors.AnalysisError
        The nominal model cannot be evaluated at ``nominal``.
    """
    cfg = config or DiagnoseConfig()
    cmp = band_comparison(model, sample_period_s, cfg)
    p = cmp.problem
    theta = np.array([float(nominal[q.name]) for q in model.nominal])
    pred = safe_predict(model, theta, [])
    if pred is None:
        raise AnalysisError("the nominal model cannot be evaluated at the fitted parameters")
    p.set_floor(model.measured, pred)
    Jn = nominal_jacobian(p, theta, [], p.weighted(pred))
    J = np.concatenate([Jn[c][p.valid[c]] for c in model.channels])
    F = J.T @ J
    d = np.sqrt(np.maximum(np.diag(F), 1e-300))
    w, V = np.linalg.eigh(F / np.outer(d, d))
    w = np.maximum(w, EIGEN_FLOOR * max(float(w.max()), 1e-300))
    Cn = (V / w) @ V.T
    sc = np.array([q.scale for q in model.nominal], dtype=float) / d
    return NominalCovariance(tuple(q.name for q in model.nominal), Cn * np.outer(sc, sc), np.diag(Cn).copy())
