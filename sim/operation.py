"""Running the normal-operation scenarios of :mod:`sim.scenarios` (and the LVDT calibration sweep) on the plant.

:func:`simulate_operation` runs an :class:`~sim.scenarios.OperationProfile`
on a :class:`sim.plant.RigPlant`, closing the force-fight compensation loop on
the measured forces sample by sample, and returns the measured signals and the
simulator's truth as an :class:`OperationRecord`; :func:`simulate_calibration_sweep`
is the slow LVDT calibration sweep under an opposing force (paper 2.3), to
calibrate the LVDTs before BLFserv. Pure: parameters and an explicit
``numpy.random.Generator`` in, frozen dataclasses out.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blf.errors import InputError
from blf.validate import generator, instance_of, one_of, scalar
from hil.canopen.process import DriveMode
from sim.params import RigParams
from sim.plant import RigPlant
from sim.scenarios import OperationProfile
from sim.truth import RigTruth, chain_stiffness_N_per_mm, rig_truth, series_stiffness

__all__ = ["OperationRecord", "CalibrationSweep", "simulate_operation", "simulate_calibration_sweep"]

_POS = int(DriveMode.POSITION)


_FRC = int(DriveMode.FORCE)


#: Minimum |F| on both sides of a sign change for it to count as a traversal, N.
CONTACT_FORCE_N = 20.0


@dataclass(frozen=True)
class OperationRecord:
    """Measured signals of a simulated manoeuvre, with the simulator's truth.

    Attributes
    ----------
    name : str
        The profile's name.
    t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N : ndarray, shape (n,)
        The measured samples (run-folder columns ``t,phi1,phi2,s1,s2,F1,F2``):
        time in s, motor angles in rad, raw LVDT strokes in mm (with the
        profile's pitch, offset, non-linearity and noise), load-cell forces in N.
    true_F_N : ndarray, shape (n, 2)
        True load-path forces of EMA 1 and 2, N.
    true_s_mm : ndarray, shape (n, 2)
        True strokes, mm.
    offset_mm : ndarray, shape (n,)
        Relative motor offset actually commanded (compensation or schedule), mm.
    truth : sim.truth.RigTruth
        Backlash, stiffness and LVDT law of the rig.
    traversed : dict
        ``{"int1": bool, "int2": bool, "ext": bool}``: whether the true
        forces crossed the play (see Notes of :func:`simulate_operation`).
    expected_backlash_mm : dict
        ``{"int1": B or None, ...}``: the truth's backlash where traversed,
        None where not; what BLFserv should report.
    sample_period_s : float
        s.

    Arrays are read-only.
    """

    name: str
    t_s: np.ndarray
    phi1_rad: np.ndarray
    phi2_rad: np.ndarray
    s1_mm: np.ndarray
    s2_mm: np.ndarray
    F1_N: np.ndarray
    F2_N: np.ndarray
    true_F_N: np.ndarray
    true_s_mm: np.ndarray
    offset_mm: np.ndarray
    truth: RigTruth
    traversed: dict
    expected_backlash_mm: dict
    sample_period_s: float


@dataclass(frozen=True)
class CalibrationSweep:
    """One EMA's slow sweep under a constant opposing force (paper 2.3, Fig. 9).

    Attributes
    ----------
    ema : int
        1 or 2.
    x_mm : ndarray, shape (n,)
        Motor angle referred to the ram, ``phi / i_total``, mm.
    s_mm : ndarray, shape (n,)
        Raw LVDT stroke, mm.
    opposing_force_N : float
        Force of the other EMA (FORCE mode), N.
    t_s, phi1_rad, phi2_rad, s1_mm, s2_mm, F1_N, F2_N : ndarray, shape (n,)
        The measured samples of both EMAs during the sweep (run-folder
        columns), with ``t_s`` from 0.

    Feed ``x_mm, s_mm`` to :func:`blf.maint.calibration.fit_lvdt_calibration`.
    Arrays are read-only.
    """

    ema: int
    x_mm: np.ndarray
    s_mm: np.ndarray
    opposing_force_N: float
    t_s: np.ndarray
    phi1_rad: np.ndarray
    phi2_rad: np.ndarray
    s1_mm: np.ndarray
    s2_mm: np.ndarray
    F1_N: np.ndarray
    F2_N: np.ndarray


def _ro(a) -> np.ndarray:
    out = np.array(a, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out


def _params(params) -> RigParams:
    return instance_of(params, RigParams, "params", "a sim.params.RigParams")


def simulate_operation(params: RigParams, profile: OperationProfile, rng: np.random.Generator) -> OperationRecord:
    """Run a normal-operation profile on the simulated rig.

    Parameters
    ----------
    params : RigParams
        The rig (sensor errors and noise included).
    profile : OperationProfile
        From one of the generators of this module.
    rng : numpy.random.Generator
        Source of the sensor noise (handed to :class:`sim.plant.RigPlant`).

    Returns
    -------
    OperationRecord

    Raises
    ------
    blf.errors.InputError
        Bad arguments, or a profile whose sample period differs from the rig's.

    Notes
    -----
    Both drives in POSITION: EMA 1 at :math:`(c_k + \\delta_k/2)\\,i_{total}`,
    EMA 2 at :math:`(c_{k-l} - \\delta_k/2)\\,i_{total}` [rad] with the
    command :math:`c` [mm], the lag :math:`l` and the relative offset
    :math:`\\delta` [mm]. Unless scheduled, :math:`\\delta` comes from the
    force-fight compensation, a slow integral loop on the measured forces:

    .. math:: \\delta_{k+1} = \\delta_k - T\\,\\omega_{ff}\\,\\frac{F_{1,k} - F_{2,k}}{2 k_s}

    with :math:`k_s` the series stiffness of the two chains
    (:func:`chain_stiffness_N_per_mm`), so that :math:`F_1 - F_2` decays with
    the bandwidth :math:`\\omega_{ff}` [rad/s] while both chains are in
    contact; :math:`|\\delta| \\le 1` mm.

    The air load enters the plant as an extra surface load stiffness
    :math:`k_a` (added to ``params.surface.load_stiffness_N_per_mm``) and the
    load array :math:`k_a y_0 + g`; the truth (:func:`sim.truth.rig_truth`)
    is that of ``params``. ``profile.warmup_s`` of settling at the first
    command is simulated first and not recorded.

    Traversal truth, from the true forces: an internal play counts as crossed
    when :math:`F_i` is seen below :math:`-F_c` and above :math:`+F_c`
    (:data:`CONTACT_FORCE_N` = 20 N); the external play when both
    configurations :math:`(F_1 > F_c, F_2 < -F_c)` and
    :math:`(F_1 < -F_c, F_2 > F_c)` occur (a change of sign of both forces in
    opposite sense; a same-sense change moves :math:`D_{ext}` by
    :math:`B_{b,2} - B_{b,1}` only).
    """
    p = _params(params)
    instance_of(profile, OperationProfile, "profile", "an OperationProfile")
    r = generator(rng)
    T = p.sample_period_s
    if abs(profile.sample_period_s - T) > 1e-12:
        raise InputError(f"profile.sample_period_s = {profile.sample_period_s} s differs from "
                         f"params.sample_period_s = {T} s")
    ka = profile.aero_stiffness_N_per_mm
    run_params = replace(p, surface=replace(p.surface, load_stiffness_N_per_mm=p.surface.load_stiffness_N_per_mm + ka))
    c = _with_warmup(profile, T)
    k1, k2 = chain_stiffness_N_per_mm(p)
    gain = T * profile.ff_bandwidth_rad_s / (2.0 * series_stiffness(k1, k2))
    # start near the equilibrium deflection under the initial load to keep the warm-up short
    plant = RigPlant(run_params, r, s0_mm=float(np.clip(c.cmd1[0], -p.stroke_limit_mm, p.stroke_limit_mm)))
    meas, true_f, true_s, offs = _run_positions(plant, c, gain, p.i_total_rad_per_mm)
    nw = c.n_warmup
    sl = slice(nw, c.cmd1.size)
    F = true_f[sl]
    trav = _traversed(F)
    truth = rig_truth(p)
    expected = {ch: (truth.backlash_mm[ch] if trav[ch] else None) for ch in ("int1", "int2", "ext")}
    return OperationRecord(
        name=profile.name, t_s=_ro(meas[sl, 0] - meas[nw - 1, 0] if nw else meas[sl, 0]),
        phi1_rad=_ro(meas[sl, 1]), phi2_rad=_ro(meas[sl, 2]), s1_mm=_ro(meas[sl, 3]), s2_mm=_ro(meas[sl, 4]),
        F1_N=_ro(meas[sl, 5]), F2_N=_ro(meas[sl, 6]), true_F_N=_ro(F), true_s_mm=_ro(true_s[sl]),
        offset_mm=_ro(offs[sl]), truth=truth, traversed=trav, expected_backlash_mm=expected,
        sample_period_s=float(T))


@dataclass(frozen=True)
class _Commands:
    """A profile with its warm-up prepended, per sample: the commands of EMA 1 and (lagged) EMA 2
    (mm), the surface load (N) and the scheduled relative offset (mm; None: force-fight
    compensation); ``n_warmup`` samples of warm-up first."""

    cmd1: np.ndarray
    cmd2: np.ndarray
    load: np.ndarray
    offset: np.ndarray | None
    n_warmup: int


def _with_warmup(profile: OperationProfile, T: float) -> _Commands:
    """Prepend the warm-up at the first command; the air load and a scheduled offset are faded in
    smoothly (raised cosine over 70 % of it) so that the lightly damped surface is not set ringing."""
    ka = profile.aero_stiffness_N_per_mm
    cmd = np.asarray(profile.command_mm, dtype=float)
    load = np.asarray(profile.load_N, dtype=float)
    sched = None if profile.offset_mm is None else np.asarray(profile.offset_mm, dtype=float)
    lag = int(profile.lag2_samples)
    nw = int(round(profile.warmup_s / T))
    ramp = np.ones(nw)
    nr = int(0.7 * nw)
    if nr > 0:
        ramp[:nr] = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, nr + 1) / nr)
    cmd_all = np.concatenate([np.full(nw, cmd[0]), cmd])
    # the plant's load stiffness -ka*y acts in full from the start: the warm-up load
    # ramp*load[0] + (1 - ramp)*ka*cmd[0] makes the total ramp*(load[0] - ka*y) (y ~ cmd[0])
    load_all = np.concatenate([ramp * load[0] + (1.0 - ramp) * ka * cmd[0], load])
    sched_all = None if sched is None else np.concatenate([ramp * sched[0], sched])
    cmd2_all = np.concatenate([np.full(lag, cmd_all[0]), cmd_all[:cmd_all.size - lag]]) if lag else cmd_all
    return _Commands(cmd_all, cmd2_all, load_all, sched_all, nw)


def _run_positions(plant: RigPlant, c: _Commands, gain: float, i_tot: float) -> tuple:
    """Both drives in POSITION through the commands, the relative offset scheduled or from the
    force-fight compensation (integral gain ``gain``, mm/N; clipped to +-1 mm). Returns the measured
    samples (n, 7), the true forces and strokes (n, 2) and the offsets (n,)."""
    ntot = c.cmd1.size
    meas = np.empty((ntot, 7))
    true_f = np.empty((ntot, 2))
    true_s = np.empty((ntot, 2))
    offs = np.empty(ntot)
    sched_all = c.offset
    delta = 0.0 if sched_all is None else float(sched_all[0])
    step = plant.step_raw
    state = plant.state
    for k in range(ntot):
        if sched_all is not None:
            delta = float(sched_all[k])
        offs[k] = delta
        o = step(_POS, (c.cmd1[k] + 0.5 * delta) * i_tot, _POS, (c.cmd2[k] - 0.5 * delta) * i_tot, float(c.load[k]))
        meas[k] = o
        st = state()
        true_f[k] = st.F_N
        true_s[k] = st.s_mm
        if sched_all is None and gain > 0.0:
            delta -= gain * (o[5] - o[6])
            delta = min(max(delta, -1.0), 1.0)
    return meas, true_f, true_s, offs


def _traversed(F: np.ndarray) -> dict:
    """Which plays the true forces ``F`` (n, 2) crossed (Notes of :func:`simulate_operation`)."""
    fc = CONTACT_FORCE_N
    return {
        "int1": bool(np.any(F[:, 0] > fc) and np.any(F[:, 0] < -fc)),
        "int2": bool(np.any(F[:, 1] > fc) and np.any(F[:, 1] < -fc)),
        "ext": bool(np.any((F[:, 0] > fc) & (F[:, 1] < -fc)) and np.any((F[:, 0] < -fc) & (F[:, 1] > fc))),
    }


def simulate_calibration_sweep(
    params: RigParams,
    rng: np.random.Generator,
    *,
    ema: int = 1,
    amplitude_mm: float = 17.0,
    speed_mm_per_s: float = 5.0,
    opposing_force_N: float = 2000.0,
    force_ramp_s: float = 1.0,
) -> CalibrationSweep:
    """Slow LVDT calibration sweep of one EMA under a constant opposing force.

    Parameters
    ----------
    params : RigParams
    rng : numpy.random.Generator
        Sensor noise.
    ema : {1, 2}, optional
        The EMA swept in POSITION mode; the other holds ``opposing_force_N``
        in FORCE mode (default 1).
    amplitude_mm : float, optional
        Sweep ``0 -> +A -> -A -> 0``, mm (default 17).
    speed_mm_per_s : float, optional
        Sweep speed, mm/s (default 5).
    opposing_force_N : float, optional
        Force of the other EMA (compression), N (default 2000).
    force_ramp_s : float, optional
        Ramp of the opposing force before the sweep, s (default 1).

    Returns
    -------
    CalibrationSweep
        The sweep samples only (ramp excluded).

    Notes
    -----
    Paper 2.3: under a constant opposing force :math:`F` the swept EMA's
    internal deflection :math:`D_{int} = -(F/k + \\mathrm{sign}(F) B/2)` is
    constant, so :math:`x = \\varphi/i_{total}` is the stroke up to a
    constant and the regression of :math:`s` on :math:`x` is the LVDT law.
    """
    p = _params(params)
    r = generator(rng)
    one_of(ema, "ema", (1, 2), "1 or 2, no unit")
    amp = scalar(amplitude_mm, "amplitude_mm", "mm", lo=0.0, lo_open=True, hi=0.95 * p.stroke_limit_mm)
    v = scalar(speed_mm_per_s, "speed_mm_per_s", "mm/s", lo=0.0, lo_open=True, hi=50.0)
    f = scalar(opposing_force_N, "opposing_force_N", "N", lo=0.0, lo_open=True, hi=20000.0)
    tr = scalar(force_ramp_s, "force_ramp_s", "s", lo=0.0, lo_open=True, hi=60.0)
    T = p.sample_period_s
    i_tot = p.i_total_rad_per_mm
    nr = int(round(tr / T))
    period = 4.0 * amp / v
    ns = int(round(period / T))
    t = np.arange(1, ns + 1) * T
    x = amp * (1.0 - 2.0 * np.abs(2.0 * ((t / period + 0.25) % 1.0) - 1.0))  # triangle 0 -> A -> -A -> 0
    settle = int(round(0.5 / T))
    pos = np.concatenate([np.zeros(nr + settle), x]) * i_tot
    frc = np.concatenate([np.linspace(0.0, f, nr), np.full(settle + ns, f)])
    plant = RigPlant(p, r)
    if ema == 1:
        trc = plant.run(_POS, pos, _FRC, frc, 0.0)
        phi, s = trc.phi1_rad, trc.s1_mm
    else:
        trc = plant.run(_FRC, frc, _POS, pos, 0.0)
        phi, s = trc.phi2_rad, trc.s2_mm
    sl = slice(nr + settle, None)
    return CalibrationSweep(
        ema=int(ema), x_mm=_ro(phi[sl] / i_tot), s_mm=_ro(s[sl]), opposing_force_N=f,
        t_s=_ro(trc.t_s[sl] - trc.t_s[nr + settle - 1]), phi1_rad=_ro(trc.phi1_rad[sl]),
        phi2_rad=_ro(trc.phi2_rad[sl]), s1_mm=_ro(trc.s1_mm[sl]), s2_mm=_ro(trc.s2_mm[sl]),
        F1_N=_ro(trc.F1_N[sl]), F2_N=_ro(trc.F2_N[sl]))
