"""Parameters of the simulated dual-EMA rig, as validated frozen dataclasses.

All fields carry their unit in the name. Loading from TOML and validation of
ranges live in :mod:`hil.profile.load`; these classes only hold values.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class EmaMechanics:
    """Load path of one EMA (paper Figure 1), from motor to surface.

    Chain: rig structure --housing spring-- housing/motor --internal path
    (backlash, stiffness)-- ram --ram-end bearing (play, stiffness)-- surface.
    """

    backlash_int_mm: float  #: total play of the internal load path (gear, ballscrew)
    stiffness_compression_N_per_mm: float  #: internal path stiffness when F > 0
    stiffness_tension_N_per_mm: float  #: internal path stiffness when F < 0
    bearing_backlash_mm: float  #: total play of the ram-end spherical bearing (external)
    bearing_stiffness_N_per_mm: float
    housing_stiffness_N_per_mm: float  #: spring between rig structure and housing


@dataclass(frozen=True)
class DriveParams:
    """Motor and the drive's own control loops (identical for both EMAs)."""

    motor_inertia_kg_m2: float  #: rotor plus gear inertia at the motor shaft
    motor_viscous_Nm_s_per_rad: float  #: viscous loss at the motor shaft
    torque_limit_Nm: float  #: the drive's torque saturation
    position_bandwidth_rad_s: float  #: natural frequency of the CSP position loop
    position_damping: float  #: damping ratio of the CSP position loop
    position_integral_time_s: float  #: integral time of the CSP position loop (0 = no I)


@dataclass(frozen=True)
class SurfaceParams:
    """The common surface (rig shaft), as an equivalent mass at the EMA attachment."""

    mass_kg: float
    damping_N_s_per_mm: float
    load_stiffness_N_per_mm: float  #: aerodynamic-like restoring load (0 on the ground)


@dataclass(frozen=True)
class SensorParams:
    """Sensor errors of one EMA.

    LVDT: ``s_meas = offset + gain * s + nonlinearity * (s / full_scale)**3 + noise``,
    noise Gaussian with standard deviation ``lvdt_noise_pp_mm / 6``.
    """

    lvdt_gain: float  #: pitch of the LVDT (1.075 = the paper's 7.5 % pitch error)
    lvdt_offset_mm: float
    lvdt_nonlinearity_mm: float  #: cubic term at full scale
    lvdt_full_scale_mm: float
    lvdt_noise_pp_mm: float  #: peak-to-peak noise (6 sigma)
    loadcell_gain: float
    loadcell_noise_std_N: float
    resolver_bits: int  #: resolution per motor revolution (12 on the rig)


@dataclass(frozen=True)
class RigParams:
    """Everything the simulated rig needs.

    ``effects`` holds the switchable physics terms of :mod:`sim.effects`
    (friction, visco-elasticity, LVDT drift, ...); empty means the core model.
    """

    i_total_rad_per_mm: float  #: total gear ratio, motor angle per ram stroke
    stroke_limit_mm: float  #: mechanical end stops at +- this value
    sample_period_s: float  #: sensor sample period (2 ms on the rig)
    substeps: int  #: integration steps per sample period
    ema1: EmaMechanics
    ema2: EmaMechanics
    drive: DriveParams
    surface: SurfaceParams
    sensors1: SensorParams
    sensors2: SensorParams
    effects: tuple = field(default_factory=tuple)


@dataclass(frozen=True)
class WearParams:
    """Wear of the simulated rig with flight hours (simulated-rig profile ``[wear]``, optional).

    The backlash values of ``[ema1]``/``[ema2]`` hold at ``reference_flight_hours``; a check
    simulated at flight hours H has each backlash grown by its rate times
    ``(H - reference_flight_hours) / 1000`` plus a scatter of standard deviation
    ``scatter_mm`` drawn per check (:func:`sim.truth.apply_wear`). The external rate is
    shared equally by the two ram-end bearings.
    """

    backlash_int1_mm_per_1000_fh: float  #: growth of EMA 1's internal backlash
    backlash_int2_mm_per_1000_fh: float  #: growth of EMA 2's internal backlash
    backlash_ext_mm_per_1000_fh: float  #: growth of the external backlash (both bearings together)
    scatter_mm: float = 0.0  #: standard deviation of each check's true backlash about the wear line
    reference_flight_hours: float = 0.0  #: flight hours at which the profile's backlash values hold

    def rate_mm_per_1000_fh(self, channel: str) -> float:
        """The stated growth rate of ``channel`` ("int1", "int2" or "ext") [mm per 1000 FH]."""
        return {"int1": self.backlash_int1_mm_per_1000_fh, "int2": self.backlash_int2_mm_per_1000_fh,
                "ext": self.backlash_ext_mm_per_1000_fh}[channel]
