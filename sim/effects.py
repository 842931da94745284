"""Switchable physics terms of the simulated rig.

Each effect is a frozen dataclass holding its parameters (units in the field
names) and, where it applies to one place only, a ``where`` field naming it:
``"ema1"``, ``"ema2"`` or ``"external"``. A :class:`~sim.params.RigParams`
collects them in its ``effects`` tuple; an empty tuple is the core model.

The numba kernel of :mod:`sim.plant` cannot take arbitrary Python objects, so
:func:`compile_effects` turns the tuple once, at plant construction, into an
effect table: a float64 array of shape ``(3, N_COLUMNS)`` whose rows are the
places (:data:`WHERE_ROW`) and whose columns are named by the ``COL_*``
constants below (SI units). A column left at its neutral value (0) switches
the term off, so the kernel needs no flags.

Adding an effect is a local change:

1. define a frozen dataclass here with a ``NAME`` class variable (its machine
   name in profiles), validate in ``__post_init__``, add it to ``_KNOWN``;
2. give it a ``COL_*`` column (append to :data:`COLUMNS`) and a
   ``_compile(table, row, sample_period_s)`` method that writes it;
3. read the column in the kernel of :mod:`sim.plant` where the physics acts.

Sign conventions are those of :mod:`sim.plant`: ram-axis positions positive
extended, force positive in compression.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from blf.errors import InputError
from blf.validate import count, instance_of, one_of, scalar

__all__ = [
    "CoulombFriction",
    "ViscousFriction",
    "Viscoelastic",
    "LvdtDrift",
    "TimeSkew",
    "StribeckFriction",
    "AsymmetricFriction",
    "LeadError",
    "StiffnessBump",
    "PeriodicForce",
    "COLUMNS",
    "N_COLUMNS",
    "WHERE_ROW",
    "compile_effects",
    "EFFECTS",
]

#: Row of the effect table for each place.
WHERE_ROW = {"ema1": 0, "ema2": 1, "external": 2}

#: Column names of the effect table (SI units), in column order.
COLUMNS = (
    "coulomb_force_N",  # Coulomb friction level on the motor-side motion
    "coulomb_band_m_per_s",  # velocity band of the smooth sign (tanh)
    "viscous_N_s_per_m",  # viscous friction on the motor-side motion
    "ve_stiffness_N_per_m",  # Maxwell arm spring
    "ve_alpha",  # 1 - exp(-substep / tau) of the Maxwell dashpot
    "ve_time_constant_s",  # tau (kept for diagnostics, not read by the kernel)
    "lvdt_drift_per_s",  # relative LVDT gain change per second
    "lvdt_delay_s",  # LVDT sampling delay relative to the resolver
    "stribeck_extra_N",  # static friction above the Coulomb level
    "stribeck_velocity_m_per_s",  # Stribeck velocity
    "friction_asym_N",  # half the difference extend minus retract of the Coulomb level
    "lead_error_m",  # amplitude of the periodic ballscrew lead error
    "lead_period_m",  # period of the lead error along the motor-side stroke
    "bump_rel",  # relative internal stiffness increase at the bump centre
    "bump_center_m",  # motor-side position of the stiffness bump
    "bump_width_m",  # Gaussian width of the stiffness bump
    "periodic_amp_N",  # amplitude of a force periodic in the motor-side position (drive, behind the load cell)
    "periodic_period_m",  # its period along the motor-side stroke
    "periodic_phase_rad",  # its phase at position 0
    "periodic_center_m",  # centre of the stretch where it acts (local)
    "periodic_halfwidth_m",  # half the length of that stretch; 0: everywhere (uniform)
)
N_COLUMNS = len(COLUMNS)
COL_COULOMB_N = COLUMNS.index("coulomb_force_N")
COL_COULOMB_BAND = COLUMNS.index("coulomb_band_m_per_s")
COL_VISCOUS = COLUMNS.index("viscous_N_s_per_m")
COL_VE_K = COLUMNS.index("ve_stiffness_N_per_m")
COL_VE_ALPHA = COLUMNS.index("ve_alpha")
COL_VE_TAU = COLUMNS.index("ve_time_constant_s")
COL_LVDT_DRIFT = COLUMNS.index("lvdt_drift_per_s")
COL_LVDT_DELAY = COLUMNS.index("lvdt_delay_s")
COL_STRIBECK_N = COLUMNS.index("stribeck_extra_N")
COL_STRIBECK_V = COLUMNS.index("stribeck_velocity_m_per_s")
COL_FRIC_ASYM = COLUMNS.index("friction_asym_N")
COL_LEAD_AMP = COLUMNS.index("lead_error_m")
COL_LEAD_PERIOD = COLUMNS.index("lead_period_m")
COL_BUMP_REL = COLUMNS.index("bump_rel")
COL_BUMP_CENTER = COLUMNS.index("bump_center_m")
COL_BUMP_WIDTH = COLUMNS.index("bump_width_m")
COL_PER_AMP = COLUMNS.index("periodic_amp_N")
COL_PER_PERIOD = COLUMNS.index("periodic_period_m")
COL_PER_PHASE = COLUMNS.index("periodic_phase_rad")
COL_PER_CENTER = COLUMNS.index("periodic_center_m")
COL_PER_HALFWIDTH = COLUMNS.index("periodic_halfwidth_m")

_EMA_ONLY = ("ema1", "ema2")


class _Effect:
    """Validation shared by the effects: ``where`` in ``_WHERE`` and every field of ``_LIMITS``
    a finite number in its range: ``(field, unit, lower bound, lower bound open)``."""

    _WHERE: ClassVar[tuple] = _EMA_ONLY
    _LIMITS: ClassVar[tuple] = ()

    def __post_init__(self) -> None:
        cls = type(self).__name__
        one_of(self.where, f"{cls}.where", self._WHERE)
        for field, unit, lo, lo_open in self._LIMITS:
            scalar(getattr(self, field), f"{cls}.{field}", unit, lo=lo, lo_open=lo_open, hi_open=True)


@dataclass(frozen=True)
class CoulombFriction(_Effect):
    """Coulomb friction of the ballscrew/nut, acting on the motor-side motion.

    Parameters
    ----------
    where : {"ema1", "ema2"}
        The EMA whose motor-side motion is braked.
    force_N : float
        Friction force level at the ram, >= 0 N.
    velocity_band_mm_per_s : float
        Width of the smooth sign, > 0 mm/s (default 0.1 mm/s).

    Notes
    -----
    Friction force along the ram axis, opposing the motor-side ram velocity
    :math:`v = \\dot\\varphi / i_{total}`:

    .. math:: F_f = F_C \\tanh(v / v_\\varepsilon)

    It acts on the motor as the torque :math:`F_f / i_{total}` [N m] with
    :math:`i_{total}` in rad/m. The kernel linearises it in the velocity
    (trapezoidal rule); the explicit half-kick moves the velocity by at most
    :math:`h F_C / (2M)`, so even a very narrow band stays bounded (measured:
    the same force offset for bands from 1e-5 to 0.1 mm/s). It is
    not seen by the load cell (it is reacted inside the EMA); it appears in the
    load-path force only through the drive: an EMA in FORCE mode delivers
    :math:`F = F_{target} - F_f` at steady velocity.
    """

    NAME: ClassVar[str] = "coulomb_friction"  #: machine name in profiles

    where: str
    force_N: float
    velocity_band_mm_per_s: float = 0.1

    _LIMITS: ClassVar[tuple] = (
        ("force_N", "N", 0.0, False),
        ("velocity_band_mm_per_s", "mm/s", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_COULOMB_N] += float(self.force_N)
        table[row, COL_COULOMB_BAND] = float(self.velocity_band_mm_per_s) * 1e-3


@dataclass(frozen=True)
class ViscousFriction(_Effect):
    """Viscous friction on the motor-side motion of one EMA.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    coeff_N_s_per_mm : float
        Friction coefficient at the ram, >= 0 N s/mm.

    Notes
    -----
    :math:`F_v = c\\,v`, with :math:`v = \\dot\\varphi / i_{total}` the
    motor-side ram velocity [mm/s]; acts on the motor as the torque
    :math:`F_v / i_{total}` (trapezoidal rule in the kernel).
    """

    NAME: ClassVar[str] = "viscous_friction"  #: machine name in profiles

    where: str
    coeff_N_s_per_mm: float

    _LIMITS: ClassVar[tuple] = (("coeff_N_s_per_mm", "N s/mm", 0.0, False),)

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_VISCOUS] = float(self.coeff_N_s_per_mm) * 1e3


@dataclass(frozen=True)
class Viscoelastic(_Effect):
    """Maxwell arm in parallel with the internal contact spring of one EMA.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    stiffness_N_per_mm : float
        Spring of the Maxwell arm, > 0 N/mm.
    time_constant_s : float
        Relaxation time :math:`\\tau = c_v / k_v` of the arm, > 0 s.

    Notes
    -----
    Each flank of the internal play (compression, tension) carries a material
    deflection :math:`\\delta` beyond the play and a dashpot state :math:`z`.
    The flank force is

    .. math:: F = k\\,\\delta + k_v(\\delta - z), \\qquad \\dot z = (\\delta - z)/\\tau

    with :math:`k` = ``k_c`` (compression) or ``k_t`` (tension). Just after
    contact the flank is stiffer (:math:`k + k_v`); held at constant
    :math:`\\delta` the force relaxes to :math:`k\\delta` with time constant
    :math:`\\tau`; unloaded (F = 0) the material is still deflected by
    :math:`\\delta_0 = k_v z/(k + k_v)` and recovers with time constant
    :math:`\\tau (k + k_v)/k`, so contact is lost before the geometric flank
    and the backlash-to-contact transition is rounded. The static stiffness is
    unchanged (``k``). The chain solve stays closed form because :math:`z` is
    frozen over one substep and updated exactly afterwards,
    :math:`z \\leftarrow z + (\\delta - z)(1 - e^{-h/\\tau})`.
    """

    NAME: ClassVar[str] = "viscoelastic"  #: machine name in profiles

    where: str
    stiffness_N_per_mm: float
    time_constant_s: float

    _LIMITS: ClassVar[tuple] = (
        ("stiffness_N_per_mm", "N/mm", 0.0, True),
        ("time_constant_s", "s", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_VE_K] = float(self.stiffness_N_per_mm) * 1e3
        table[row, COL_VE_ALPHA] = -math.expm1(-substep_s / float(self.time_constant_s))
        table[row, COL_VE_TAU] = float(self.time_constant_s)


@dataclass(frozen=True)
class LvdtDrift(_Effect):
    """LVDT gain drifting linearly with time (temperature).

    Parameters
    ----------
    where : {"ema1", "ema2"}
    gain_drift_per_s : float
        Relative gain change per second (any sign), 1/s.

    Notes
    -----
    ``s_meas = offset + gain * (1 + drift * t) * s + nonlinearity * (s / full_scale)**3 + noise``
    with ``t`` the sample time in s (0 at plant construction).
    """

    NAME: ClassVar[str] = "lvdt_drift"  #: machine name in profiles

    where: str
    gain_drift_per_s: float

    _LIMITS: ClassVar[tuple] = (("gain_drift_per_s", "1/s", -math.inf, True),)

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_LVDT_DRIFT] = float(self.gain_drift_per_s)


@dataclass(frozen=True)
class TimeSkew(_Effect):
    """The LVDT of one EMA is latched ``delay_s`` earlier than the resolver sample.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    delay_s : float
        Skew in s, ``0 <= delay_s < sample_period_s`` (checked by
        :func:`compile_effects`).

    Notes
    -----
    The sample stamped :math:`t_k` carries :math:`s(t_k - \\Delta)`: the LVDT
    lags the resolver. The true stroke is interpolated linearly between the
    integration substeps of the current sample period.
    """

    NAME: ClassVar[str] = "time_skew"  #: machine name in profiles

    where: str
    delay_s: float

    _LIMITS: ClassVar[tuple] = (("delay_s", "s", 0.0, False),)

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        if not float(self.delay_s) < sample_period_s:
            raise InputError(
                f"TimeSkew.delay_s must be < sample_period_s = {sample_period_s} s, got {self.delay_s!r} s"
            )
        table[row, COL_LVDT_DELAY] = float(self.delay_s)


def _set_band(table: np.ndarray, row: int, band_mm_per_s: float) -> None:
    """Velocity band of the smooth sign shared by the friction effects (first one wins)."""
    if table[row, COL_COULOMB_BAND] <= 0.0:
        table[row, COL_COULOMB_BAND] = float(band_mm_per_s) * 1e-3


@dataclass(frozen=True)
class StribeckFriction(_Effect):
    """Stribeck friction: extra static friction decaying with speed, on the motor-side motion.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    extra_force_N : float
        Static friction above the Coulomb level at standstill, >= 0 N.
    stribeck_velocity_mm_per_s : float
        Decay speed :math:`v_s`, > 0 mm/s.
    velocity_band_mm_per_s : float
        Width of the smooth sign, > 0 mm/s (default 0.1).

    Notes
    -----
    Adds :math:`F_S e^{-(v/v_s)^2} \\tanh(v/v_\\varepsilon)` [N] to the
    friction of :class:`CoulombFriction` (same place and sign convention).
    """

    NAME: ClassVar[str] = "stribeck_friction"  #: machine name in profiles

    where: str
    extra_force_N: float
    stribeck_velocity_mm_per_s: float
    velocity_band_mm_per_s: float = 0.1

    _LIMITS: ClassVar[tuple] = (
        ("extra_force_N", "N", 0.0, False),
        ("stribeck_velocity_mm_per_s", "mm/s", 0.0, True),
        ("velocity_band_mm_per_s", "mm/s", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_STRIBECK_N] = float(self.extra_force_N)
        table[row, COL_STRIBECK_V] = float(self.stribeck_velocity_mm_per_s) * 1e-3
        _set_band(table, row, self.velocity_band_mm_per_s)


@dataclass(frozen=True)
class AsymmetricFriction(_Effect):
    """Coulomb friction that differs with the direction of motion.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    force_extend_N, force_retract_N : float
        Friction level when the ram extends (v > 0) and retracts (v < 0), >= 0 N.
    velocity_band_mm_per_s : float
        Width of the smooth sign, > 0 mm/s (default 0.1).

    Notes
    -----
    :math:`F_f = (\\bar F + \\Delta F \\tanh(v/v_\\varepsilon)) \\tanh(v/v_\\varepsilon)`
    with :math:`\\bar F = (F_+ + F_-)/2`, :math:`\\Delta F = (F_+ - F_-)/2`;
    added to any :class:`CoulombFriction` at the same place.
    """

    NAME: ClassVar[str] = "asymmetric_friction"  #: machine name in profiles

    where: str
    force_extend_N: float
    force_retract_N: float
    velocity_band_mm_per_s: float = 0.1

    _LIMITS: ClassVar[tuple] = (
        ("force_extend_N", "N", 0.0, False),
        ("force_retract_N", "N", 0.0, False),
        ("velocity_band_mm_per_s", "mm/s", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_COULOMB_N] += 0.5 * (float(self.force_extend_N) + float(self.force_retract_N))
        table[row, COL_FRIC_ASYM] = 0.5 * (float(self.force_extend_N) - float(self.force_retract_N))
        _set_band(table, row, self.velocity_band_mm_per_s)


@dataclass(frozen=True)
class LeadError(_Effect):
    """Periodic ballscrew lead error: the ram-side motion deviates periodically from phi/i_total.

    Parameters
    ----------
    where : {"ema1", "ema2"}
    amplitude_mm : float
        Amplitude of the error, >= 0 mm.
    period_mm : float
        Period along the stroke, > 0 mm (one lead = 5 mm on the rig).

    Notes
    -----
    The motor-side position entering the load path is
    :math:`x_m = \\varphi/i_{total} + A \\sin(2\\pi (\\varphi/i_{total})/p)` [m].
    """

    NAME: ClassVar[str] = "lead_error"  #: machine name in profiles

    where: str
    amplitude_mm: float
    period_mm: float = 5.0

    _LIMITS: ClassVar[tuple] = (
        ("amplitude_mm", "mm", 0.0, False),
        ("period_mm", "mm", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_LEAD_AMP] = float(self.amplitude_mm) * 1e-3
        table[row, COL_LEAD_PERIOD] = float(self.period_mm) * 1e-3


@dataclass(frozen=True)
class StiffnessBump(_Effect):
    """Internal stiffness that rises locally along the stroke (a tight spot of the ballscrew).

    Parameters
    ----------
    where : {"ema1", "ema2"}
    relative_increase : float
        Relative increase of both flank stiffnesses at the centre, >= 0.
    center_mm : float
        Motor-side position of the centre, mm.
    width_mm : float
        Gaussian width, > 0 mm.

    Notes
    -----
    :math:`k(x_m) = k\\,(1 + a\\,e^{-((x_m - x_0)/w)^2})` for both flanks.
    """

    NAME: ClassVar[str] = "stiffness_bump"  #: machine name in profiles

    where: str
    relative_increase: float
    center_mm: float = 0.0
    width_mm: float = 2.0

    _LIMITS: ClassVar[tuple] = (
        ("relative_increase", "(dimensionless)", 0.0, False),
        ("center_mm", "mm", -math.inf, True),
        ("width_mm", "mm", 0.0, True),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_BUMP_REL] = float(self.relative_increase)
        table[row, COL_BUMP_CENTER] = float(self.center_mm) * 1e-3
        table[row, COL_BUMP_WIDTH] = float(self.width_mm) * 1e-3


@dataclass(frozen=True)
class PeriodicForce(_Effect):
    """A force periodic in the ram's position, in the drive (behind the load cell): a screw's runout or
    misalignment (uniform), or a defect on the raceway (local, over one stretch of the stroke).

    Parameters
    ----------
    where : {"ema1", "ema2"}
    amplitude_N : float
        Amplitude, >= 0 N.
    period_mm : float
        Period along the motor-side stroke, > 0 mm (once per turn of a 5 mm lead: 5 mm).
    phase_rad : float
        Phase at the motor-side position 0, rad.
    center_mm, width_mm : float
        Local: it acts only within ``width_mm`` (> 0) around ``center_mm`` (motor-side position, mm);
        ``width_mm`` 0: everywhere (uniform).

    Notes
    -----
    The drive's motor carries, besides the load path's force,
    :math:`F_p = A\\cos(2\\pi x_m/p + \\varphi)\\,[\\,|x_m - x_0| \\le w/2\\,]` (N, the sign of a
    load on the ram: positive opposes extension), :math:`x_m = \\varphi_m/i_{total}`.
    """

    NAME: ClassVar[str] = "periodic_force"  #: machine name in profiles

    where: str
    amplitude_N: float
    period_mm: float = 5.0
    phase_rad: float = 0.0
    center_mm: float = 0.0
    width_mm: float = 0.0

    _LIMITS: ClassVar[tuple] = (
        ("amplitude_N", "N", 0.0, False),
        ("period_mm", "mm", 0.0, True),
        ("phase_rad", "rad", -math.inf, True),
        ("center_mm", "mm", -math.inf, True),
        ("width_mm", "mm", 0.0, False),
    )

    def _compile(self, table: np.ndarray, row: int, sample_period_s: float, substep_s: float) -> None:
        table[row, COL_PER_AMP] = float(self.amplitude_N)
        table[row, COL_PER_PERIOD] = float(self.period_mm) * 1e-3
        table[row, COL_PER_PHASE] = float(self.phase_rad)
        table[row, COL_PER_CENTER] = float(self.center_mm) * 1e-3
        table[row, COL_PER_HALFWIDTH] = 0.5 * float(self.width_mm) * 1e-3


_KNOWN = (CoulombFriction, ViscousFriction, Viscoelastic, LvdtDrift, TimeSkew,
          StribeckFriction, AsymmetricFriction, LeadError, StiffnessBump, PeriodicForce)

#: Machine name (profiles, diagnosis) -> effect class.
EFFECTS = {cls.NAME: cls for cls in _KNOWN}


def compile_effects(effects: tuple, sample_period_s: float, substeps: int) -> np.ndarray:
    """Compile the effects tuple of a RigParams into the kernel's effect table.

    Parameters
    ----------
    effects : tuple
        Instances of the effect classes of this module; at most one of each
        class per place.
    sample_period_s : float
        Sample period, s (> 0).
    substeps : int
        Integration substeps per sample (>= 1).

    Returns
    -------
    numpy.ndarray
        float64 array of shape ``(3, N_COLUMNS)``; rows per :data:`WHERE_ROW`,
        columns per :data:`COLUMNS` (SI units), 0 where no effect applies.

    Raises
    ------
    blf.errors.InputError
        Unknown effect type, duplicate (class, where) or out-of-range parameter.

    Notes
    -----
    The substep is :math:`h = T_s / n`; time-constant effects store
    :math:`1 - e^{-h/\\tau}` so the kernel's update is exact for a frozen input.
    """
    instance_of(effects, tuple, "effects", "a tuple of effect objects")
    period = scalar(sample_period_s, "sample_period_s", "s", lo=0.0, lo_open=True)
    nsub = count(substeps, "substeps", 1)
    table = np.zeros((3, N_COLUMNS), dtype=np.float64)
    seen: set[tuple[type, str]] = set()
    for k, eff in enumerate(effects):
        if not isinstance(eff, _KNOWN):
            raise InputError(
                f"effects[{k}] must be one of {[c.__name__ for c in _KNOWN]}, got {type(eff).__name__}"
            )
        key = (type(eff), eff.where)
        if key in seen:
            raise InputError(
                f"effects[{k}]: duplicate {type(eff).__name__} at where={eff.where!r}; combine them into one"
            )
        seen.add(key)
        eff._compile(table, WHERE_ROW[eff.where], period, period / nsub)
    return table
