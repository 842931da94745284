r"""The dual-EMA recording and its position-driven replay, as a model for :func:`blf.diagnose.engine.diagnose`.

Pure: arrays in, predicted channels out. The replay itself (load paths,
surface, sensors) is :mod:`sim.replay`; the phases (which drive holds force,
what is not compared) come from :mod:`blf.diagnose.phases`.

Channels
--------
``s1, s2`` (LVDT, mm) and ``F1, F2`` (load cells, N) from the replayed load
paths; ``Fd1, Fd2`` (N): while an EMA holds a force target (FORCE mode), the
load-cell force its motor's momentum balance predicts,

.. math:: F_d = g_{lc}\\left(F_{target} - F_f(v) - M\\,a\\right),
          \\quad F_f = F_c \\tanh(v/v_\\varepsilon) + c\\,v + \\ldots

with v and a the Savitzky-Golay velocity and acceleration of the measured
motor angle (mm/s, mm/s^2; the comparison band removes what is left of the
angle's quantisation). ``Dint1, Dint2, Dext`` (mm) are reported, not fitted.

Nominal model
-------------
Per EMA: internal play, contact stiffness (equal in tension and compression),
bearing play, bearing-plus-housing compliance, LVDT pitch and offset (the
calibration, taken from the recording: the fit starts from the sweeps'
regression); the surface hinge's viscous and Coulomb friction; the damping of the load
paths' contacts (as a time constant: :math:`F = F_s + \tau_d \dot F_s`,
common to both EMAs); the drives' reflected mass and their viscous and Coulomb friction (common to both EMAs:
the same product). Physics every recording of a rig shares is nominal; the
LVDT calibration and the hinge friction are named as effects (``lvdt_pitch``,
``lvdt_offset`` at the EMA, ``viscous_friction``/``coulomb_friction`` at
``external``) where they differ significantly from the simulator's nominal.

Candidates (per EMA): LVDT non-linearity (quadratic and cubic over the
stroke), drift, time skew; load-cell gain; tension/compression stiffness
asymmetry, progressive stiffness, visco-elastic creep of the load path; and,
where the EMA holds force, extra Coulomb, viscous, Stribeck or
direction-dependent friction of its drive (>= 0: added to the common nominal), and a force periodic
in the ram's position in its drive where the recording shows one (its period found from the data,
:mod:`sim.replay_periodic`).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from blf.diagnose import Candidate, Param, ParamVector, Reference, holding, mode_changes, segment_changes, transients
from blf.validate import as_1d_finite, positive_scalar, same_shape
from sim.replay import FRICTION_BAND_MM_S, ChainParams, friction_force, lvdt_model, replay_chains
from sim.replay_periodic import periodic_candidate, periodic_force, periodic_start

__all__ = ["DualEmaReplay", "dual_ema_candidates", "BAND_HZ"]

BAND_HZ = 10.0  #: the band the quasi-static replay claims (Hz)
_FULL_SCALE_MM = 20.0
_SIM_SURFACE_DAMPING = 0.5  #: N s/mm, the simulator's surface (profiles/simrig.toml)
_SURFACE_MASS = 300.0  #: kg
#: both LVDT pitches off their references by the same relative amount: one physics shared by the two
#: EMAs (blf.diagnose.model.Reference.common), named once at "external" (neither EMA on its own)
RATIO = ("transmission_ratio", "external",
         "both LVDTs read alike against the motor angles: the motor-to-ram ratio differs from the profile's "
         "i_total (the rig's is i_total / (1 + gain_error)), or both LVDTs share that pitch error; state the "
         "rig's ratio in the actuation profile", "gain_error")


def _cand(name, where, words, *params, variant="", shape=()):
    return Candidate(name, where, words, tuple(Param(*q) for q in params), variant, shape)


def _friction(where: str, n: str, variant: str, place: str) -> list:
    return [
        _cand("coulomb_friction", where, f"extra Coulomb friction {place} of EMA {n}",
              ("force_N", 5.0, 5.0, 0.0, 1e4), variant=variant),
        _cand("viscous_friction", where, f"extra viscous friction {place} of EMA {n}",
              ("coeff_N_s_per_mm", 2.0, 2.0, 0.0, 1e4), variant=variant),
        _cand("stribeck_friction", where, f"Stribeck friction (static above Coulomb) {place} of EMA {n}",
              ("extra_force_N", 5.0, 5.0, 0.0, 1e4), ("stribeck_velocity_mm_per_s", 1.0, 1.0, 0.05, 20.0),
              variant=variant, shape=("stribeck_velocity_mm_per_s",)),
        _cand("asymmetric_friction", where,
              f"extra friction {place} of EMA {n} that differs with the direction of motion",
              ("force_extend_N", 5.0, 5.0, 0.0, 1e4), ("force_retract_N", 1.0, 5.0, 0.0, 1e4), variant=variant),
    ]


def dual_ema_candidates(drive: tuple = (True, True)) -> tuple:
    """The candidate library of the dual-EMA replay (drive-friction terms where ``drive[e]``)."""
    out = []
    for e, (where, n) in enumerate((("ema1", "1"), ("ema2", "2"))):
        out += [
            _cand("lvdt_nonlinearity", where, f"LVDT {n} non-linearity (a bow and an S over the stroke)",
                  ("quadratic_mm", 5e-3, 5e-3, -1.0, 1.0), ("nonlinearity_mm", 5e-3, 5e-3, -1.0, 1.0)),
            _cand("lvdt_drift", where, f"LVDT {n} gain drift over time (temperature)",
                  ("gain_drift_per_s", 1e-5, 1e-5, -1e-2, 1e-2)),
            _cand("time_skew", where, f"time skew between resolver {n} and LVDT {n} sampling",
                  ("delay_s", 5e-4, 5e-4, -0.02, 0.02)),
            _cand("loadcell_gain", where, f"load cell {n} gain error", ("gain_error", 1e-3, 1e-3, -0.3, 0.3)),
            _cand("stiffness_asymmetry", where,
                  f"tension and compression stiffness differ in the EMA {n} load path",
                  ("tension_over_compression_minus_1", 0.05, 0.05, -0.9, 5.0)),
            _cand("progressive_stiffness", where,
                  f"contact stiffness of the EMA {n} load path rises with its deflection",
                  ("progressive_per_mm", 1.0, 1.0, -5.0, 50.0)),
            _cand("viscoelastic", where, f"visco-elastic creep/relaxation in the EMA {n} load path",
                  ("stiffness_N_per_mm", 5000.0, 5000.0, 0.0, 1e6), ("time_constant_s", 0.3, 0.3, 0.01, 30.0),
                  shape=("time_constant_s",)),
        ]
        out += _friction(where, n, "load path", "between ram and housing (in the load path)")
        if drive[e]:
            out += _friction(where, n, "drive", "in the ballscrew (the drive, behind the load cell)")
    return tuple(out)


def _surface_damping(rig: dict) -> float:
    """The simulated rig's surface damping (N s/mm), the simulator's default without one."""
    return float((rig.get("surface") or {}).get("damping_N_s_per_mm", _SIM_SURFACE_DAMPING))


def _nominal_params(rig: dict, g0: list, o0: list, drive: bool) -> tuple:
    """The nominal parameters: per EMA the load path (from the simulated rig ``rig`` where given),
    the hinge and the contact damping, per EMA the LVDT calibration (from ``g0``, ``o0``, the
    recording's regression) and, where a drive holds force, the drives' reflected mass and friction."""
    P = Param
    nom = []
    for e in (1, 2):
        c = rig.get(f"ema{e}") or {}
        ks = 1.0 / (1.0 / c.get("bearing_stiffness_N_per_mm", 2e5) + 1.0 / c.get("housing_stiffness_N_per_mm", 2e4))
        nom += [P(f"backlash_int{e}_mm", float(c.get("backlash_int_mm", 0.1)), 0.01, 0.0, 2.0),
                P(f"stiffness_int{e}_N_per_mm", float(c.get("stiffness_compression_N_per_mm", 8e4)), 1e4, 1e3, 1e7),
                P(f"backlash_bearing{e}_mm", float(c.get("bearing_backlash_mm", 0.05)), 0.01, 0.0, 2.0),
                P(f"compliance_ext{e}_mm_per_N", 1.0 / ks, 5e-6, 1e-7, 1e-2)]
    nom += [P("hinge_viscous_N_s_per_mm", max(_surface_damping(rig), 0.5), 2.0, 0.0, 1e4),
            P("hinge_coulomb_N", 1.0, 5.0, 0.0, 1e4),
            P("contact_damping_time_s", 0.0, 1e-3, -0.02, 0.02)]
    for e in (0, 1):
        nom += [P(f"lvdt_pitch{e + 1}", g0[e], 1e-3, 0.5, 2.0), P(f"lvdt_offset{e + 1}_mm", o0[e], 1e-3, -5.0, 5.0)]
    if drive:
        nom += [P("reflected_mass_kg", 2500.0, 500.0, 0.0, 1e6), P("drive_viscous_N_s_per_mm", 2.5, 5.0, 0.0, 1e4),
                P("drive_coulomb_N", 1.0, 5.0, 0.0, 1e4)]
    return tuple(nom)


def _references(names: tuple, sens: list, damping: float) -> tuple:
    """The nominal parameters compared with a reference (the simulated rig's LVDTs ``sens`` and surface
    damping): LVDT pitch and offset per EMA, the hinge's viscous and Coulomb friction."""
    def at(name: str) -> int:
        return ParamVector.position(names, name)

    refs = []
    for e, s in enumerate(sens):
        n = e + 1
        refs += [Reference(at(f"lvdt_pitch{n}"), float(s.get("lvdt_gain", 1.0)), "lvdt_pitch", f"ema{n}",
                           f"LVDT {n} pitch (gain) differs from nominal: calibrated on the recording",
                           "gain_error", 1.0, RATIO),
                 Reference(at(f"lvdt_offset{n}_mm"), float(s.get("lvdt_offset_mm", 0.0)), "lvdt_offset", f"ema{n}",
                           f"LVDT {n} offset: calibrated on the recording", "offset_mm", 0.0)]
    refs += [Reference(at("hinge_viscous_N_s_per_mm"), damping, "viscous_friction", "external",
                       "viscous friction of the surface hinge (the simulator's surface damping differs)",
                       "coeff_N_s_per_mm", 0.0),
             Reference(at("hinge_coulomb_N"), 0.0, "coulomb_friction", "external",
                       "Coulomb friction of the surface hinge", "force_N", 0.0)]
    return tuple(refs)


class DualEmaReplay:
    """The dual-EMA recording and its position-driven replay, for :func:`blf.diagnose.engine.diagnose`.

    Parameters
    ----------
    t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N : ndarray, shape (n,)
        The recording (s, rad, mm, N).
    i_total_rad_per_mm : float
    sample_period_s : float
    mode1, sp1, mode2, sp2 : ndarray or None
        Drive modes (0, 8, 10) and setpoints (rad or N) per sample, when recorded.
    segments : blf.maint.segments.Segments, optional
        The phases found in the data (:func:`blf.maint.segments.find_segments`), used
        when the modes are not recorded.
    opposing_force_N : float, optional
        The check profile's opposing force (the held target without recorded setpoints), N.
    force_ramp_s : float, optional
        The check profile's ramp of that force on and off, s (not compared as held).
    nominal_rig : dict, optional
        The simulated rig the recording was made with (meta.json ``simrig``):
        its values start the fit and are the nominal the calibrated LVDTs
        and the hinge are compared with.
    """

    def __init__(self, t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N, i_total_rad_per_mm: float,
                 sample_period_s: float, mode1=None, sp1=None, mode2=None, sp2=None, *, segments=None,
                 opposing_force_N: float | None = None, force_ramp_s: float = 0.0,
                 nominal_rig: dict | None = None) -> None:
        items = [(as_1d_finite(a, name, unit, min_len=200), name, unit) for a, name, unit in (
            (t_s, "t_s", "s"), (phi1_rad, "phi1_rad", "rad"), (phi2_rad, "phi2_rad", "rad"), (s1_mm, "s1_mm", "mm"),
            (s2_mm, "s2_mm", "mm"), (F1_N, "F1_N", "N"), (F2_N, "F2_N", "N"))]
        same_shape(*items)
        t, phi1, phi2, s1, s2, f1, f2 = (a for a, _, _ in items)
        n = t.size
        i_total = positive_scalar(i_total_rad_per_mm, "i_total_rad_per_mm", "rad/mm")
        self.t_s = t
        self.T = T = positive_scalar(sample_period_s, "sample_period_s", "s")
        self.band_hz = BAND_HZ
        self.xm = (phi1 / i_total, phi2 / i_total)
        self.v = tuple(savgol_filter(x, 21, 3, deriv=1, delta=T, mode="interp") for x in self.xm)
        # order 4 for the acceleration: order 3 biases it by (w h)^2 (0.06 N of M a at 0.7 Hz); the band removes
        # the extra noise it lets through
        self.a = tuple(savgol_filter(x, 21, 4, deriv=2, delta=T, mode="interp") for x in self.xm)
        #: tanh(v / v_eps) of the friction law at its band (FRICTION_BAND_MM_S), asked at every prediction
        self._tanh_v = tuple(np.tanh(np.asarray(v, dtype=np.float64) / FRICTION_BAND_MM_S) for v in self.v)
        recorded = all(x is not None for x in (mode1, sp1, mode2, sp2))
        if recorded:
            hold = holding(n, T, mode1=mode1, sp1=sp1, mode2=mode2, sp2=sp2)
            changes = mode_changes(mode1, mode2)
        else:
            hold = holding(n, T, segments=segments, f1_N=f1, f2_N=f2, opposing_force_N=opposing_force_N,
                           force_ramp_s=force_ramp_s)
            changes = segment_changes(segments, f1, f2, T) if segments is not None else np.zeros(0, np.int64)
        self.holding = hold
        trans = transients(f1, f2, T, changes)
        self.not_compared = trans
        self.channels = ("s1", "s2", "F1", "F2", "Fd1", "Fd2")
        self.measured = {"s1": s1, "s2": s2, "F1": f1, "F2": f2, "Fd1": f1, "Fd2": f2}
        self.valid = {c: ~trans for c in ("s1", "s2", "F1", "F2")}
        self.valid["Fd1"] = hold.hold1 & ~trans
        self.valid["Fd2"] = hold.hold2 & ~trans
        self.targets = (hold.target1_N, hold.target2_N)
        self.derived_valid = {"Dint1": self.valid["s1"], "Dint2": self.valid["s2"], "Dext": self.valid["s1"]}
        rig = nominal_rig or {}
        sens = [rig.get("sensors1") or {}, rig.get("sensors2") or {}]
        self.lvdt_nominal = [(float(s.get("lvdt_nonlinearity_mm", 0.0)), float(s.get("lvdt_full_scale_mm",
                                                                                        _FULL_SCALE_MM))) for s in sens]
        g0, o0 = self._calibration_start(trans)
        self.drive = (bool(self.valid["Fd1"].any()), bool(self.valid["Fd2"].any()))
        self.nominal = _nominal_params(rig, g0, o0, any(self.drive))
        self.names = tuple(q.name for q in self.nominal)  #: of the nominal vector, read with ParamVector
        self.candidates = dual_ema_candidates(self.drive)
        for e, (where, n) in enumerate((("ema1", "1"), ("ema2", "2"))):  # a force periodic in position, if found
            start = periodic_start(self.xm[e], self.v[e], (f1, f2)[e], self.targets[e],
                                   self.valid[f"Fd{e + 1}"], self.band_hz) if self.drive[e] else None
            if start is not None:
                self.candidates += (periodic_candidate(where, n, start),)
        self.references = _references(self.names, sens, _surface_damping(rig))
        xc = 0.5 * (self.xm[0] + self.xm[1])
        self.regimes = {
            "position along the stroke": xc - np.median(xc),
            "velocity": 0.5 * (self.v[0] + self.v[1]),
            "force F1": f1,
            "force rate": savgol_filter(f1, 21, 3, deriv=1, delta=T, mode="interp"),
            "time since start": t - 0.5 * (t[0] + t[-1]),
        }
        self._cache: dict = {}

    def _calibration_start(self, trans: np.ndarray) -> tuple[list, list]:
        """Start of the LVDT calibration: regression of s on (1, x, F, sign F) where compared and moving."""
        g0, o0 = [1.0, 1.0], [0.0, 0.0]
        for e in (0, 1):
            x, s, f = self.xm[e], self.measured[f"s{e + 1}"], self.measured[f"F{e + 1}"]
            sel = ~trans & (np.abs(self.v[e]) > 0.5)
            if sel.sum() < 200 or np.ptp(x[sel]) < 1.0:
                sel = ~trans
            if sel.sum() < 50 or np.ptp(x[sel]) < 0.1:
                continue
            A = np.stack([np.ones(sel.sum()), x[sel], f[sel], np.sign(f[sel])], axis=1)
            coef = np.linalg.lstsq(A, s[sel], rcond=None)[0]
            if np.isfinite(coef[1]) and 0.5 < coef[1] < 2.0:
                g0[e] = float(coef[1])
                o0[e] = float(np.clip(coef[0], -5.0, 5.0))
        return g0, o0

    def derived(self, ch: dict) -> dict:
        """The paper's D signals (mm): D_int,i = s_i - phi_i / i_total, D_ext = s2 - s1."""
        return {"Dint1": ch["s1"] - self.xm[0], "Dint2": ch["s2"] - self.xm[1], "Dext": ch["s2"] - ch["s1"]}

    @staticmethod
    def _friction_kw(fx: dict, where: str, variant: str) -> dict | None:
        """Friction-law arguments of the accepted friction terms of one variant at one place."""
        kw: dict = {}
        for name in ("coulomb_friction", "viscous_friction", "stribeck_friction", "asymmetric_friction"):
            x = fx.get((name, where, variant))
            if x is None:
                continue
            if name == "coulomb_friction":
                kw["coulomb_N"] = kw.get("coulomb_N", 0.0) + float(x[0])
            elif name == "viscous_friction":
                kw["viscous_N_s_per_mm"] = float(x[0])
            elif name == "stribeck_friction":
                kw["stribeck_N"], kw["stribeck_velocity_mm_s"] = float(x[0]), float(x[1])
            else:
                kw["coulomb_N"] = kw.get("coulomb_N", 0.0) + 0.5 * (float(x[0]) + float(x[1]))
                kw["asym_N"] = 0.5 * (float(x[0]) - float(x[1]))
        return kw or None

    def _tanh_of(self, kw: dict, e: int) -> np.ndarray | None:
        """The held tanh(v / v_eps) of EMA ``e`` where the friction law ``kw`` has the band it was taken at;
        None (computed by :func:`sim.replay.friction_force`) for another band."""
        return self._tanh_v[e] if kw.get("band_mm_s", FRICTION_BAND_MM_S) == FRICTION_BAND_MM_S else None

    def _trace(self, th, fx):
        chains = []
        for n, where in ((1, "ema1"), (2, "ema2")):
            bi, k, bb, cs = (th[f"backlash_int{n}_mm"], th[f"stiffness_int{n}_N_per_mm"],
                             th[f"backlash_bearing{n}_mm"], th[f"compliance_ext{n}_mm_per_N"])
            k = max(k, 1.0)
            asym = fx.get(("stiffness_asymmetry", where, ""))
            kt = max(k * (1.0 + float(asym[0])), 1.0) if asym is not None else k
            ve = fx.get(("viscoelastic", where, ""))
            kv, tau = (max(float(ve[0]), 0.0), max(float(ve[1]), 1e-3)) if ve is not None else (0.0, 1.0)
            prog = fx.get(("progressive_stiffness", where, ""))
            p = float(prog[0]) if prog is not None else 0.0
            chains.append(ChainParams(max(bi, 0.0), k, kt, max(bb, 0.0), max(cs, 1e-9), kv, tau, p))
        hv, hc = max(th["hinge_viscous_N_s_per_mm"], 0.0), max(th["hinge_coulomb_N"], 0.0)
        lp = tuple(self._friction_kw(fx, w, "load path") for w in ("ema1", "ema2"))
        key = (tuple(chains), hv, hc, tuple(None if k is None else tuple(sorted(k.items())) for k in lp))
        tr = self._cache.get(key)
        if tr is None:
            ff = [None if lp[e] is None else friction_force(self.v[e], **lp[e], tanh_v=self._tanh_of(lp[e], e))
                  for e in (0, 1)]
            tr = replay_chains(self.xm[0], self.xm[1], chains[0], chains[1], self.T, 0.0, _SURFACE_MASS, hv, hc,
                               ff[0], ff[1])
            if len(self._cache) > 48:
                self._cache.clear()
            self._cache[key] = tr
        return tr

    def _rate(self, tr, e: int) -> np.ndarray:
        """Time derivative of a replayed load-path force (Savitzky-Golay, N/s), kept with its trace."""
        key = ("rate", id(tr), e)
        out = self._cache.get(key)
        if out is None or out[0] is not tr:
            out = (tr, savgol_filter(tr.F_N[:, e], 21, 3, deriv=1, delta=self.T, mode="interp"))
            self._cache[key] = out
        return out[1]

    def predict(self, theta: np.ndarray, active: list) -> dict:
        """Predicted channels for nominal ``theta`` (in the order of :attr:`nominal`, read by name) and
        the active effects [(Candidate, params)]."""
        th = ParamVector(self.names, theta)
        fx = {(c.name, c.where, c.variant): np.asarray(x, dtype=float) for c, x in active}
        tr = self._trace(th, fx)
        out = {}
        for e, where in enumerate(("ema1", "ema2")):
            n = e + 1
            nl, drift, skew, lc = (fx.get((name, where, "")) for name in (
                "lvdt_nonlinearity", "lvdt_drift", "time_skew", "loadcell_gain"))
            n3, fs = self.lvdt_nominal[e]
            kw = {"gain": th[f"lvdt_pitch{n}"], "offset_mm": th[f"lvdt_offset{n}_mm"], "nonlinearity_mm": n3}
            if nl is not None:
                kw["quadratic_mm"] = float(nl[0])
                kw["nonlinearity_mm"] = n3 + float(nl[1])
            if drift is not None:
                kw["drift_per_s"] = float(drift[0])
            if skew is not None:
                kw["delay_s"] = float(skew[0])
            out[f"s{n}"] = lvdt_model(tr.s_mm[:, e], self.t_s, full_scale_mm=fs, **kw)
            lg = 1.0 + (float(lc[0]) if lc is not None else 0.0)
            out[f"F{n}"] = lg * (tr.F_N[:, e] + th["contact_damping_time_s"] * self._rate(tr, e))
            if not self.drive[e]:
                out[f"Fd{n}"] = np.zeros(self.t_s.size)
                continue
            M, c, fc = th["reflected_mass_kg"], th["drive_viscous_N_s_per_mm"], th["drive_coulomb_N"]
            ff = friction_force(self.v[e], coulomb_N=fc, viscous_N_s_per_mm=c, tanh_v=self._tanh_v[e])
            for variant in ("drive", "load path"):
                kwf = self._friction_kw(fx, where, variant)
                if kwf is not None:
                    ff = ff + friction_force(self.v[e], **kwf, tanh_v=self._tanh_of(kwf, e))
            per = fx.get(("periodic_force", where, ""))
            if per is not None:
                ff = ff + periodic_force(self.xm[e], per)
            out[f"Fd{n}"] = lg * (self.targets[e] - ff - M * 1e-3 * self.a[e])
        return out
