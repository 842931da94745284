"""Single-axis positioning drive (e.g. the EMPS recording) as a replay model for the diagnosis.

Pure: arrays in, predicted channels out.

Nominal model (rigid mass, symmetric Coulomb and viscous friction, offset),
replayed by inverse dynamics from the measured position:

.. math:: F = M\\ddot q + F_v \\dot q + F_c\\,\\mathrm{sign}(\\dot q) + F_0

with :math:`\\dot q, \\ddot q` from a Savitzky-Golay filter of the measured
position (m/s, m/s^2) and F the drive force ``gtau * vir`` (N). The channel
compared is ``force``; driving by the measured position removes the
controller from the comparison.

The comparison band (``band_hz``) is 20 Hz (at most 80 % of the Nyquist
frequency of a slower recording), as in the dataset authors'
IDIM-LS (low-pass without phase shift, then decimation, :mod:`blf.diagnose.band`):
above it lie the controller's reaction to encoder quantisation and the
noise of the twice-differentiated position, which a rigid-body model does
not claim.

Candidates (added to F; :math:`\\tilde q = q - \\mathrm{median}(q)`,
:math:`s = \\tanh(\\dot q / 10^{-4})`):

* ``stribeck_friction``: :math:`F_s e^{-(\\dot q/v_s)^2} s`;
* ``asymmetric_friction``: :math:`\\Delta F_v |\\dot q|`, viscous friction
  :math:`F_v \\pm \\Delta F_v` in the two directions (a Coulomb asymmetry
  is the offset, already nominal);
* ``position_dependent_friction``: :math:`a\\,\\tilde q\\,s`;
* ``position_dependent_force``: :math:`b_1 \\tilde q + b_2 \\tilde q^2`
  (a spring, cable carrier or gravity component);
* ``periodic_force``, where the recording shows one (its period found from the
  force against position, :mod:`sim.replay_periodic`): :math:`-A\\cos(2\\pi q/P + \\varphi)`
  (with an envelope where it is local).
"""

from __future__ import annotations

import numpy as np

from blf.diagnose import Candidate, Param, ParamVector
from blf.errors import InputError
from blf.validate import as_1d_finite, positive_scalar, same_shape
from sim.replay_periodic import periodic_force

__all__ = ["SingleAxisReplay", "single_axis_candidates"]

_BAND_M_S = 1e-4  #: smooth sign width, m/s
BAND_HZ = 20.0  #: the band the rigid-body model claims (IDIM-LS's), Hz


def single_axis_candidates() -> tuple:
    """Candidate library of the single-axis model."""
    return (
        Candidate("stribeck_friction", "axis", "Stribeck (static above Coulomb) friction of the ballscrew",
                  (Param("extra_force_N", 2.0, 2.0, 0.0, 1e3),
                   Param("stribeck_velocity_m_per_s", 0.01, 0.01, 1e-4, 1.0))),
        Candidate("asymmetric_friction", "axis",
                  "viscous friction that differs with the direction of motion",
                  (Param("viscous_asymmetry_N_s_per_m", 10.0, 10.0, -1e5, 1e5),)),
        Candidate("position_dependent_friction", "axis",
                  "friction that varies along the stroke (ballscrew wear or misalignment)",
                  (Param("slope_N_per_m", 10.0, 10.0, -1e5, 1e5),)),
        Candidate("position_dependent_force", "axis",
                  "a force that depends on the position along the stroke (spring, cable carrier or gravity)",
                  (Param("linear_N_per_m", 10.0, 10.0, -1e6, 1e6),
                   Param("quadratic_N_per_m2", 100.0, 100.0, -1e8, 1e8))),
    )


class SingleAxisReplay:
    """Recording of one axis and its inverse-dynamics replay, for :func:`blf.diagnose.engine.diagnose`.

    Parameters
    ----------
    t_s, q_m, q_ref_m, force_N : ndarray, shape (n,)
        Time (s), measured and reference position (m), drive force (N).
    sample_period_s : float
    valid : array_like of bool, shape (n,), optional
        Samples whose force is compared (default all): a drive's current says nothing about the
        force in a dwell at holding current or in the catch-up after a set-point step.
    """

    def __init__(self, t_s, q_m, q_ref_m, force_N, sample_period_s: float, valid=None) -> None:
        from scipy.signal import savgol_filter

        # any shape, flattened (a .mat file holds columns)
        items = [(as_1d_finite(np.ravel(a), name, unit, min_len=200), name, unit) for a, name, unit in (
            (t_s, "t_s", "s"), (q_m, "q_m", "m"), (q_ref_m, "q_ref_m", "m"), (force_N, "force_N", "N"))]
        same_shape(*items)
        arrs = [a for a, _, _ in items]
        n = arrs[0].size
        self.t_s = arrs[0]
        self.q = arrs[1]
        self.q_ref = arrs[2]
        T = positive_scalar(sample_period_s, "sample_period_s", "s")
        self.v = savgol_filter(self.q, 21, 3, deriv=1, delta=T, mode="interp")
        self.a = savgol_filter(self.q, 21, 3, deriv=2, delta=T, mode="interp")
        self.channels = ("force",)
        # the band follows the recording's Nyquist frequency: at most 80 % of it
        self.band_hz = min(BAND_HZ, 0.4 / T)
        self.places = {"force": "axis"}
        self.measured = {"force": arrs[3]}
        ok = np.ones(n, bool) if valid is None else np.asarray(valid, bool).ravel()
        if ok.shape != (n,) or not ok.any():
            raise InputError(f"valid must be a bool array of shape ({n},) with a sample compared; got {ok.shape}")
        self.valid = {"force": ok}
        #: the loader's record of the samples masked and why (blf.diagnose.axis_reference.EffortMask), or None
        self.effort_mask = None
        full = (Param("mass_kg", 50.0, 10.0, 0.0, 1e5), Param("viscous_N_s_per_m", 100.0, 50.0, 0.0, 1e6),
                Param("coulomb_N", 20.0, 5.0, 0.0, 1e4), Param("offset_N", 0.0, 5.0, -1e4, 1e4))
        self.qc = self.q - np.median(self.q)
        #: what this recording can separate (blf.diagnose.axis_reference.identifiability over the samples compared)
        # judged away from masked samples by the derivative filter's half-width: its span there carries them
        from scipy.ndimage import binary_erosion
        ok_far = binary_erosion(ok, np.ones(21, bool), border_value=1) if not ok.all() else ok
        self.identifiability = self._identify(T, ok_far if ok_far.any() else ok)
        cols = {"friction_N": "coulomb_N"}
        fitted = {cols.get(c, c) for c in self.identifiability.columns}
        self.nominal = tuple(p for p in full if p.name in fitted)
        self.names = tuple(q.name for q in self.nominal)  #: of the nominal vector, read with ParamVector
        #: candidates this recording cannot tell apart from the nominal model: (name, why), not screened
        self.not_candidates = ()
        self.candidates = self._separable_candidates(ok_far if ok_far.any() else ok)
        # a force periodic in position, where the recording shows one (its period found from the data)
        from sim.replay_periodic import periodic_candidate, periodic_start
        fs = 1.0 / T
        start = periodic_start(self.q * 1e3, self.v * 1e3, arrs[3], 0.0, ok_far if ok_far.any() else ok,
                               self.band_hz, decimate=max(1, int(fs // 100)))
        if start is not None:
            self.candidates += (periodic_candidate("axis", "", start),)
        self.regimes = {"position along the stroke": self.qc, "velocity": self.v,
                        "acceleration": self.a, "time since start": self.t_s - np.median(self.t_s)}

    def _identify(self, T: float, ok: np.ndarray):
        from scipy.signal import savgol_coeffs

        from blf.diagnose import identifiability
        sq = float(np.sqrt(np.mean(np.diff(self.q, 2) ** 2) / 6))  # position noise, m
        noise = sq * float(np.linalg.norm(savgol_coeffs(21, 3, deriv=2, delta=T)))
        return identifiability(self.v, self.a, np.gradient(self.q_ref, self.t_s), ok, noise)

    def _separable_candidates(self, ok: np.ndarray) -> tuple:
        """The library less the terms this recording cannot tell apart from the nominal model."""
        from scipy.signal import savgol_filter

        from blf.diagnose import design_columns, separable
        # on the commanded motion: what the recording excites, not the noise of the measured derivatives
        T = float(np.median(np.diff(self.t_s)))
        vr = savgol_filter(self.q_ref, 21, 3, deriv=1, delta=T, mode="interp")
        ar = savgol_filter(self.q_ref, 21, 3, deriv=2, delta=T, mode="interp")
        X = design_columns(self.identifiability.columns, vr, ar)[ok]
        theta = np.array([p.x0 for p in self.nominal])
        keep, drop = [], []
        for cand in single_axis_candidates():
            x0 = np.array([p.x0 for p in cand.params])
            base = self._force(vr, ar, theta, [(cand, x0)])
            cols = []
            for j, p in enumerate(cand.params):
                x = x0.copy()
                x[j] += 1e-3 * p.scale
                cols.append((self._force(vr, ar, theta, [(cand, x)]) - base)[ok])
            if separable(X, np.column_stack(cols)):
                keep.append(cand)
            else:
                drop.append((cand.name, "its signature over the samples compared lies in the span of the nominal "
                             "model's terms (" + ", ".join(self.identifiability.columns) + ")"))
        self.not_candidates = tuple(drop)
        return tuple(keep)

    def predict(self, theta: np.ndarray, active: list) -> dict:
        """Predicted drive force for nominal ``theta`` (M, Fv, Fc, F0, read by name; a parameter this recording
        cannot identify is not in it and counts 0) and the active effects."""
        return {"force": self._force(self.v, self.a, theta, active)}

    def _force(self, v: np.ndarray, a: np.ndarray, theta: np.ndarray, active: list) -> np.ndarray:
        th = ParamVector(self.names, theta)
        vals = {n: th[n] for n in self.names}
        M, fv, fc, f0 = (vals.get(n, 0.0) for n in ("mass_kg", "viscous_N_s_per_m", "coulomb_N", "offset_N"))
        th = np.tanh(v / _BAND_M_S)
        f = M * a + fv * v + fc * th + f0
        for cand, x in active:
            if cand.name == "stribeck_friction":
                f = f + x[0] * np.exp(-(v / x[1]) ** 2) * th
            elif cand.name == "asymmetric_friction":
                f = f + x[0] * np.abs(v)
            elif cand.name == "position_dependent_friction":
                f = f + x[0] * self.qc * th
            elif cand.name == "position_dependent_force":
                f = f + x[0] * self.qc + x[1] * self.qc * self.qc
            elif cand.name == "periodic_force":
                f = f - periodic_force(self.q * 1e3, x)  # the replay's sign: the recorded force reads -F_p
        return f
