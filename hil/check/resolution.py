"""Can the check run on these sensors? A quantised LVDT or load cell against its stated noise.

The supervisor stops the check when an LVDT or a load cell repeats exactly the same value for more than
``check.safety.max_frozen_cycles`` SYNC cycles: a live sensor's noise moves its reading every few
cycles, a dead input or a frozen PDO does not. A sensor whose raw step (its profile's ``mm_per_unit``
or ``N_per_unit``) is coarse against its noise (``sensors.lvdt_noise_pp_mm``,
``sensors.loadcell_noise_std_N``) repeats its value at rest as a frozen one does, and the check
stops on it. This module finds that before anything moves (``profile check``, ``dry-run``, ``run``).

The rule
--------
A reading is the true value plus Gaussian noise of standard deviation :math:`\\sigma` (for the LVDT
:math:`\\sigma` = ``lvdt_noise_pp_mm`` / 6, as the error budget and the simulator take it), rounded to
a step :math:`q`. At rest, the reading falls in bin :math:`k` with probability :math:`P_k`; the
largest is :math:`P_0 = \\operatorname{erf}\\big(q / (2\\sqrt2\\,\\sigma)\\big)`, the true value at a bin's
centre (the worst case). Samples being independent, :math:`n` readings in a row are all equal with
probability :math:`\\sum_k P_k^n \\le P_0^{\\,n-1}`. The supervisor stops after :math:`M + 1` equal pairs
(:math:`M` = ``max_frozen_cycles``), so a false stop begins at a given cycle with probability at most
:math:`P_0^{M+1}`, and over a check of :math:`N` cycles (its planned duration over the SYNC period,
all of it counted as rest: an upper bound) the expected number of false stops is at most
:math:`N P_0^{M+1}`. Requiring that below :data:`FALSE_STOPS` (one check in a thousand) gives the
largest step that works:

.. math::

    q_{max} = 2\\sqrt2\\,\\sigma\\,\\operatorname{erf}^{-1}\\!\\Big(\\big(\\alpha / N\\big)^{1/(M+1)}\\Big)

For the shipped profiles (:math:`\\sigma` = 0.025 / 6 mm, :math:`M` = 25, :math:`N` = 55 750)
:math:`q_{max}` = 0.0057 mm for the LVDT (the shipped 0.001 mm is 5.7 times finer) and 13.6 N for the
load cell (shipped: 0.1 N). A 10-bit input over +-20 mm (0.04 mm) fails by a factor of 7; no
``max_frozen_cycles`` up to its cap (100) would admit it (q_max = 0.0116 mm there).

Within :math:`q_{max}` the quantisation also costs the measurement little: it adds
:math:`q^2/12` to the noise variance, at :math:`q = 1.36\\,\\sigma` (the shipped :math:`M`) 7.4 % to the
noise's standard deviation, so the backlash and calibration uncertainties (which scale with it) grow
by at most that. A sensor sent as REAL32 / REAL64 has no step and is not judged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

from hil.canopen.plan import Problem, RigPlan
from hil.canopen.signalmap import Signal
from hil.check.sequence import CheckSequence
from hil.errors import ProfileError
from hil.profile.config import HARD_MAX_FROZEN_CYCLES, Actuation, Check

__all__ = ["FALSE_STOPS", "SensorStep", "largest_step", "refuse_coarse_sensors", "sensor_steps", "step_problems"]

#: Expected false frozen-sensor stops per check the rule accepts (one check in a thousand).
FALSE_STOPS = 1e-3
#: CiA 301 codes of the floating-point types: no step to judge.
_REAL_TYPES = (0x0008, 0x0011)


def largest_step(sigma: float, max_frozen_cycles: int, cycles: float, false_stops: float = FALSE_STOPS) -> float:
    """The largest raw step of a sensor with noise ``sigma`` that a check of ``cycles`` SYNC cycles stops on
    as frozen (more than ``max_frozen_cycles`` repeats) less than ``false_stops`` times on average.

    Parameters
    ----------
    sigma : float
        Standard deviation of the sensor's noise, in its SI unit (mm, N); > 0.
    max_frozen_cycles : int
        The supervisor's limit :math:`M` (>= 1).
    cycles : float
        The check's length :math:`N` in SYNC cycles (>= 1).
    false_stops : float
        :math:`\\alpha`, in (0, 1).

    Returns
    -------
    float
        :math:`q_{max} = 2\\sqrt2\\,\\sigma\\,\\operatorname{erf}^{-1}((\\alpha/N)^{1/(M+1)})`, in the unit
        of ``sigma``.
    """
    if not (sigma > 0 and math.isfinite(sigma)):
        raise ValueError(f"sigma = {sigma!r} must be a finite number > 0")
    if max_frozen_cycles < 1 or cycles < 1 or not 0 < false_stops < 1:
        raise ValueError(f"max_frozen_cycles = {max_frozen_cycles}, cycles = {cycles}, false_stops = "
                         f"{false_stops}: need >= 1, >= 1 and in (0, 1)")
    p0 = (false_stops / cycles) ** (1.0 / (max_frozen_cycles + 1))
    return 2.0 * math.sqrt(2.0) * sigma * _erfinv(p0)


def _erfinv(p: float) -> float:
    """:math:`\\operatorname{erf}^{-1}(p) = -\\Phi^{-1}\\big((1 - p)/2\\big)/\\sqrt2` for p in (0, 1), with the
    standard library's normal quantile (scipy.special, 0.13 s to import, is not needed before the check's
    loop): within 6e-15 (relative) of ``scipy.special.erfinv`` from p = 0.01 to 1 - 1e-12 and within 6e-11
    down to p = 1e-6 (the rule's p is at least sqrt(alpha / N): 1e-6 for N = 1e9 cycles, 23 days at 2 ms)."""
    return -NormalDist().inv_cdf((1.0 - p) / 2.0) / math.sqrt(2.0)


@dataclass(frozen=True)
class SensorStep:
    """One quantised sensor judged: its key, step, noise and the largest step that works (SI units)."""

    key: str  #: the profile key of the scaling (``signals.ema2.lvdt.mm_per_unit``)
    what: str  #: "LVDT 2", "load cell 1"
    unit: str  #: "mm" or "N"
    step: float  #: the raw step in the unit
    sigma: float  #: the stated noise (standard deviation) in the unit
    noise_key: str  #: the profile key that states the noise
    stated: float  #: its value (peak to peak for the LVDT, a standard deviation for the load cell)
    largest: float  #: q_max at the check's max_frozen_cycles
    largest_at_cap: float  #: q_max at the hard cap of max_frozen_cycles

    @property
    def ok(self) -> bool:
        return self.step <= self.largest

    def message(self, max_frozen_cycles: int) -> str:
        """Why the check would stop on this sensor at rest, and what would work."""
        raise_it = (f"; or raise check safety.max_frozen_cycles (hard cap {HARD_MAX_FROZEN_CYCLES}: up to "
                    f"{_fmt(self.largest_at_cap)} {self.unit} there)" if self.step <= self.largest_at_cap
                    else f" (no safety.max_frozen_cycles up to its cap {HARD_MAX_FROZEN_CYCLES} admits it)")
        return (f"a step of {_fmt(self.step)} {self.unit} per raw unit is coarse against {self.what}'s noise "
                f"({self.noise_key} = {_fmt(self.stated)}: sigma {_fmt(self.sigma)} {self.unit}): at rest its "
                f"reading repeats for more than safety.max_frozen_cycles = {max_frozen_cycles} cycles and the "
                f"supervisor stops the check as on a frozen sensor; the largest step that works is "
                f"{_fmt(self.largest)} {self.unit} per raw unit (a finer input or scaling){raise_it}")


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def sensor_steps(plan: RigPlan, act: Actuation, check: Check) -> tuple[SensorStep, ...]:
    """Every integer-coded LVDT and load cell of the plan judged against its noise (docs above)."""
    seq = CheckSequence(act, check)
    cycles = max(1.0, seq.planned_duration_s() / act.timing.sync_period_s)
    m = check.safety.max_frozen_cycles
    sens = act.sensors
    noise = {Signal.LVDT: (sens.lvdt_noise_pp_mm / 6.0, "mm", "sensors.lvdt_noise_pp_mm", sens.lvdt_noise_pp_mm,
                           "LVDT", "mm_per_unit"),
             Signal.FORCE: (sens.loadcell_noise_std_N, "N", "sensors.loadcell_noise_std_N", sens.loadcell_noise_std_N,
                            "load cell", "N_per_unit")}
    out = []
    for ch in plan.channels:
        if ch.signal not in noise or ch.scale is None or ch.data_type in _REAL_TYPES:
            continue
        sigma, unit, noise_key, stated, what, scale_key = noise[ch.signal]
        out.append(SensorStep(f"{ch.key}.{scale_key}", f"{what} {ch.ema}", unit, 1.0 / abs(ch.scale.units_per_si),
                              sigma, noise_key, stated, largest_step(sigma, m, cycles),
                              largest_step(sigma, HARD_MAX_FROZEN_CYCLES, cycles)))
    return tuple(out)


def step_problems(plan: RigPlan, act: Actuation, check: Check) -> list[Problem]:
    """The sensors the check would stop on at rest, each a :class:`~hil.canopen.plan.Problem` with its key."""
    m = check.safety.max_frozen_cycles
    return [Problem(s.key, None, s.message(m)) for s in sensor_steps(plan, act, check) if not s.ok]


def refuse_coarse_sensors(plan: RigPlan, act: Actuation, check: Check, fname: str = "actuation profile") -> None:
    """Raise :class:`~hil.errors.ProfileError` (exit 3, every sensor at once) naming each sensor the check would
    stop on at rest, with its key, its step and the largest step that works."""
    m = check.safety.max_frozen_cycles
    bad = [s for s in sensor_steps(plan, act, check) if not s.ok]
    if bad:
        raise ProfileError.of([f"{fname}: field '{s.key}' = {_fmt(s.step)}: {s.message(m)}" for s in bad])
