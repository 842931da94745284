"""Ground truth of a simulated rig: the numbers the BLFmaint analysis should find.

Pure: parameters in, a frozen dataclass out.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from blf.errors import InputError
from blf.validate import generator, instance_of, scalar
from sim.params import EmaMechanics, RigParams, WearParams

__all__ = ["RigTruth", "rig_truth", "wear_line_mm", "apply_wear"]


@dataclass(frozen=True)
class RigTruth:
    """Backlash, stiffness and LVDT calibration of a simulated rig.

    The fields are plain dicts inside a frozen dataclass: treat them as
    read-only (they are built fresh by :func:`rig_truth`, JSON-serialisable).

    Attributes
    ----------
    backlash_mm : dict
        ``{"int1": B_int1, "int2": B_int2, "ext": B_b1 + B_b2}`` in mm.
    stiffness_N_per_mm : dict
        ``{"int1": {"left": k, "right": k}, "int2": {...}, "ext": {...}}``,
        positive magnitudes in N/mm; "left"/"right" are the regions of the
        F-D plane ordered by increasing D.
    calibration : dict
        ``{"ema1": {"pitch": gain, "offset_mm": offset}, "ema2": {...}}``:
        the LVDT law ``s_meas = offset_mm + pitch * s`` (nonlinearity, noise
        and drift excluded; pitch at t = 0).
    """

    backlash_mm: dict
    stiffness_N_per_mm: dict
    calibration: dict


def series_stiffness(*stiffness_N_per_mm: float) -> float:
    return 1.0 / sum(1.0 / k for k in stiffness_N_per_mm)


def rig_truth(params: RigParams) -> RigTruth:
    """Derive the true backlash, stiffness and calibration from rig parameters.

    Parameters
    ----------
    params : RigParams
        The rig (the same object given to :class:`sim.plant.RigPlant`).

    Returns
    -------
    RigTruth

    Raises
    ------
    blf.errors.InputError
        If ``params`` is not a RigParams or a stiffness is not > 0 N/mm.

    Notes
    -----
    Internal (paper eq. 1, :math:`D_{int} = s - \\varphi/i_{total}`): in contact
    :math:`D_{int} = -(F/k_{int}(F) + \\mathrm{sign}(F) B_{int}/2)`, so the
    compression branch (F > 0) lies at the smaller D ("left") with
    :math:`|dF/dD| = k_c`, the tension branch at the larger D ("right") with
    :math:`|dF/dD| = k_t`, and the jump through the slack region is
    :math:`B_{int}`.

    External (:math:`D_{ext} = s_2 - s_1`, with :math:`F_1 = -F_2`, no load):
    :math:`s_i - y = F_i/k_{s,i} + \\mathrm{sign}(F_i) B_{b,i}/2` with
    :math:`k_{s,i} = (1/k_{b,i} + 1/k_{h,i})^{-1}`, so

    .. math:: D_{ext} = \\tfrac{1}{2}(F_2 - F_1)(1/k_{s,1} + 1/k_{s,2})
              + \\mathrm{sign}(F_2)(B_{b,1} + B_{b,2})/2

    slope :math:`d(F_2 - F_1)/dD_{ext} = 2/(1/k_{s,1} + 1/k_{s,2})` on both
    sides and jump :math:`B_{b,1} + B_{b,2}`.

    A :class:`sim.effects.Viscoelastic` arm does not change these static
    values (its force relaxes to zero at constant deflection).
    """
    instance_of(params, RigParams, "params")

    def mech(name: str) -> EmaMechanics:
        m = getattr(params, name)
        for f in ("stiffness_compression_N_per_mm", "stiffness_tension_N_per_mm",
                  "bearing_stiffness_N_per_mm", "housing_stiffness_N_per_mm"):
            scalar(getattr(m, f), f"params.{name}.{f}", "N/mm", lo=0.0, lo_open=True)
        return m

    m1, m2 = mech("ema1"), mech("ema2")
    ks1 = series_stiffness(m1.bearing_stiffness_N_per_mm, m1.housing_stiffness_N_per_mm)
    ks2 = series_stiffness(m2.bearing_stiffness_N_per_mm, m2.housing_stiffness_N_per_mm)
    k_ext = 2.0 / (1.0 / ks1 + 1.0 / ks2)
    backlash = {
        "int1": float(m1.backlash_int_mm),
        "int2": float(m2.backlash_int_mm),
        "ext": float(m1.bearing_backlash_mm + m2.bearing_backlash_mm),
    }
    stiffness = {
        "int1": {"left": float(m1.stiffness_compression_N_per_mm),
                 "right": float(m1.stiffness_tension_N_per_mm)},
        "int2": {"left": float(m2.stiffness_compression_N_per_mm),
                 "right": float(m2.stiffness_tension_N_per_mm)},
        "ext": {"left": float(k_ext), "right": float(k_ext)},
    }
    calibration = {
        "ema1": {"pitch": float(params.sensors1.lvdt_gain), "offset_mm": float(params.sensors1.lvdt_offset_mm)},
        "ema2": {"pitch": float(params.sensors2.lvdt_gain), "offset_mm": float(params.sensors2.lvdt_offset_mm)},
    }
    return RigTruth(backlash_mm=backlash, stiffness_N_per_mm=stiffness, calibration=calibration)


def chain_stiffness_N_per_mm(params: RigParams) -> tuple[float, float]:
    """Contact stiffness of each EMA's whole load path, structure to surface.

    Parameters
    ----------
    params : RigParams

    Returns
    -------
    tuple of float
        ``(k_1, k_2)`` in N/mm.

    Notes
    -----
    Housing spring, internal path (mean of compression and tension) and
    bearing in series: :math:`k_i = (1/k_h + 1/k_{int} + 1/k_b)^{-1}` [N/mm]
    (14 815 N/mm with the default rig).
    """
    p = instance_of(params, RigParams, "params", "a sim.params.RigParams")
    out = []
    for m in (p.ema1, p.ema2):
        kint = 0.5 * (m.stiffness_compression_N_per_mm + m.stiffness_tension_N_per_mm)
        out.append(series_stiffness(m.housing_stiffness_N_per_mm, kint, m.bearing_stiffness_N_per_mm))
    return out[0], out[1]


def force_fight_play_mm(params: RigParams) -> float:
    """Relative motor offset at which the force fight starts, mm.

    Parameters
    ----------
    params : RigParams

    Returns
    -------
    float
        Half the total play between the two motors,
        :math:`(B_{int,1} + B_{b,1} + B_{int,2} + B_{b,2})/2` [mm]
        (0.16 mm with the default rig): with the surface free and no air load,
        :math:`F_1 = -F_2 = k_s(\\delta - \\text{this})` for
        :math:`\\delta` above it, :math:`k_s = (1/k_1 + 1/k_2)^{-1}`.
    """
    p = instance_of(params, RigParams, "params", "a sim.params.RigParams")
    return 0.5 * (p.ema1.backlash_int_mm + p.ema1.bearing_backlash_mm
                  + p.ema2.backlash_int_mm + p.ema2.bearing_backlash_mm)


def wear_line_mm(params: RigParams, wear: WearParams, flight_hours: float) -> dict[str, float]:
    """The backlash of each channel on the stated wear line at ``flight_hours`` (no scatter).

    Parameters
    ----------
    params : RigParams
        The rig at ``wear.reference_flight_hours``.
    wear : WearParams
    flight_hours : float
        Flight hours of the check (>= 0).

    Returns
    -------
    dict
        ``{"int1": mm, "int2": mm, "ext": mm}``: :func:`rig_truth`'s backlash plus
        rate times ``(flight_hours - reference) / 1000``.
    """
    instance_of(wear, WearParams, "wear", "a sim.params.WearParams")
    fh = scalar(flight_hours, "flight_hours", "FH", lo=0.0)
    base = rig_truth(params).backlash_mm
    dk = (fh - wear.reference_flight_hours) / 1000.0
    return {ch: base[ch] + wear.rate_mm_per_1000_fh(ch) * dk for ch in ("int1", "int2", "ext")}


def apply_wear(params: RigParams, wear: WearParams, flight_hours: float, rng: np.random.Generator) -> RigParams:
    """The rig worn to ``flight_hours``: each backlash on its wear line plus one draw of the scatter.

    Parameters
    ----------
    params : RigParams
        The rig at ``wear.reference_flight_hours``.
    wear : WearParams
    flight_hours : float
        Flight hours of the simulated check (>= 0).
    rng : numpy.random.Generator
        Draws the scatter (three normal numbers, int1, int2, ext, in that order).

    Returns
    -------
    RigParams
        ``params`` with ``ema1.backlash_int_mm``, ``ema2.backlash_int_mm`` and the two
        ``bearing_backlash_mm`` (sharing the external growth and scatter equally) replaced;
        :func:`rig_truth` of it is the check's truth.

    Raises
    ------
    blf.errors.InputError
        A backlash that would drop below zero (a negative rate run backwards too far).

    Notes
    -----
    The scatter stands for what makes one check's true backlash differ from the
    wear line (lubrication, temperature, the load history before the check); it
    is drawn per check, independent between checks and channels.
    """
    instance_of(params, RigParams, "params", "a sim.params.RigParams")
    line = wear_line_mm(params, wear, flight_hours)
    rng = generator(rng)
    scatter = rng.normal(0.0, 1.0, 3) * scalar(wear.scatter_mm, "wear.scatter_mm", "mm", lo=0.0)
    new = {ch: line[ch] + d for ch, d in zip(("int1", "int2", "ext"), scatter, strict=True)}
    for ch, v in new.items():
        if v < 0.0:
            raise InputError(f"wear at flight_hours = {flight_hours} gives a negative {ch} backlash ({v:.4f} mm)")
    half_ext = 0.5 * (new["ext"] - (params.ema1.bearing_backlash_mm + params.ema2.bearing_backlash_mm))
    ema1 = dataclasses.replace(params.ema1, backlash_int_mm=new["int1"],
                               bearing_backlash_mm=params.ema1.bearing_backlash_mm + half_ext)
    ema2 = dataclasses.replace(params.ema2, backlash_int_mm=new["int2"],
                               bearing_backlash_mm=params.ema2.bearing_backlash_mm + half_ext)
    if min(ema1.bearing_backlash_mm, ema2.bearing_backlash_mm) < 0.0:
        raise InputError(f"wear at flight_hours = {flight_hours} gives a negative bearing backlash")
    return dataclasses.replace(params, ema1=ema1, ema2=ema2)
