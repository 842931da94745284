"""The maintenance-check sequence as a sans-IO core.

:class:`CheckSequence` is fed one measured :class:`~hil.canopen.process.Sample` per
SYNC cycle and returns the two drives' :class:`~hil.canopen.process.Setpoint` for the
next cycle plus events. It never reads a clock (time is ``sample.t_s``), never
touches a bus, and knows nothing about whether the drives are simulated: the
same object drives the plant directly (``emacheck simulate``) and two CiA 402
drives over CANopen.

Steps (paper 2.3, then 2.1)::

    IDLE -> ENABLE -> APPROACH
         -> CAL1_LOAD -> CAL1_SWEEP -> CAL1_UNLOAD      LVDT 1 calibration sweep,
         -> CAL2_LOAD -> CAL2_SWEEP -> CAL2_UNLOAD      EMA 2 opposing in force mode, then swapped
         -> FORCE_FIGHT -> UNLOAD -> DONE
    any non-terminal step -> ABORTED

Force fight: both EMAs hold the surface in position mode; the core commands
opposite excursions ``+delta`` (EMA 1) and ``-delta`` (EMA 2) and integrates
``delta`` on the force-fight error,

.. math:: \\dot\\delta = \\mathrm{clip}(K (F_{dem}(t) - F_{ff}),\\ \\pm v_{max}),
          \\qquad F_{ff} = (F_1 - F_2)/2,

with ``F_dem`` a triangle through ``+-amplitude_fraction_of_limit * F_limit``.
The rate limit makes the backlash be traversed quasi-statically.

Time: each sample's own time (the SYNC period it answers). A step's profile
runs on the samples: periods without one (a late SYNC, a cycle whose sample
did not complete; the drives held their last setpoints) are held, so the
profile resumes where it stood instead of leaping ahead by them; the step
just takes that much longer. Events carry the samples' time.

Opposing force of the calibration: the opposing EMA ``j`` holds ``F_opp`` in
FORCE mode (the drive's CST). A drive without CST (``force_by_position``)
holds it by the same kind of loop in position mode: it follows the sweeping
EMA's commanded motion and adds an excursion integrated on its own force
error,

.. math:: \\varphi_j = \\varphi_{j,0} + (\\varphi^*_k - \\varphi^*_{k,0}) + i\\,\\delta_j, \\qquad
          \\dot\\delta_j = \\mathrm{clip}(K (F_{opp}(t) - F_j),\\ \\pm v_{max}),

with the force-fight loop's gain ``K`` and rate limit ``v_max``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.profileclock import ProfileClock
from hil.errors import SequenceError
from hil.profile.config import Actuation, Check


class Step(Enum):
    """Steps of the check; the value is the name written to the step column."""

    IDLE = "idle"
    ENABLE = "enable"
    APPROACH = "approach"
    CAL1_LOAD = "cal1_load"
    CAL1_SWEEP = "cal1_sweep"
    CAL1_UNLOAD = "cal1_unload"
    CAL2_LOAD = "cal2_load"
    CAL2_SWEEP = "cal2_sweep"
    CAL2_UNLOAD = "cal2_unload"
    FORCE_FIGHT = "force_fight"
    UNLOAD = "unload"
    DONE = "done"
    ABORTED = "aborted"


_ORDER = [Step.IDLE, Step.ENABLE, Step.APPROACH, Step.CAL1_LOAD, Step.CAL1_SWEEP, Step.CAL1_UNLOAD,
          Step.CAL2_LOAD, Step.CAL2_SWEEP, Step.CAL2_UNLOAD, Step.FORCE_FIGHT, Step.UNLOAD, Step.DONE]

#: The transition table: each step may go to the next one in order or abort.
TRANSITIONS: dict[Step, frozenset[Step]] = {
    s: frozenset({_ORDER[i + 1], Step.ABORTED}) for i, s in enumerate(_ORDER[:-1])
}
TRANSITIONS[Step.DONE] = frozenset()
TRANSITIONS[Step.ABORTED] = frozenset()

TERMINAL = frozenset({Step.DONE, Step.ABORTED})


@dataclass(frozen=True, slots=True)
class Event:
    """A step change for the shell to log: the step entered (ABORTED: an abort, DONE: the end) and why."""

    t_s: float
    step: Step
    detail: str = ""


@dataclass(frozen=True, slots=True)
class CycleOutput:
    sp1: Setpoint
    sp2: Setpoint
    step: Step
    events: tuple[Event, ...]


@dataclass(frozen=True, slots=True)
class Progress:
    step: Step
    step_fraction: float  #: 0..1 within the current step (estimated)
    total_fraction: float  #: 0..1 over the whole check (by planned duration)
    force_fight_demand_N: float


_HOLD_DISABLED = Setpoint(DriveMode.DISABLED, 0.0)

#: The position-mode force loop (a drive without CST): the sweep starts once the opposing force is within
#: this fraction of its target ...
OPPOSING_FORCE_TOLERANCE = 0.1
#: ... and the check aborts when it is not after this long beyond the ramp and the settling [s].
OPPOSING_FORCE_TIMEOUT_S = 10.0


def _triangle(t: float, amplitude: float, period: float) -> float:
    """Triangle 0 -> +A -> -A -> 0 over one period, repeated."""
    x = (t / period) % 1.0
    if x < 0.25:
        return amplitude * 4.0 * x
    if x < 0.75:
        return amplitude * (2.0 - 4.0 * x)
    return amplitude * (4.0 * x - 4.0)


def _sweep(t: float, amplitude: float, speed: float) -> tuple[float, bool]:
    """Sweep offset 0 -> +A -> -A -> 0 at constant speed; returns (offset, finished)."""
    quarter = amplitude / speed
    period = 4.0 * quarter
    if t >= period:
        return 0.0, True
    return _triangle(t, amplitude, period), False


class CheckSequence:
    """The check, one SYNC cycle at a time.

    Parameters
    ----------
    actuation : Actuation
        Gear ratio, limit load, sample period.
    check : Check
        The check profile (validated against ``actuation``).
    force_by_position : (bool, bool)
        Per EMA: its drive has no CST, it holds the calibration's opposing force by the
        position-mode loop of the module docstring.

    Notes
    -----
    Positions are commanded as motor angles, ``phi = x * i_total`` with ``x``
    the ram-side position in mm; forces (drive in FORCE mode) in N at the ram.
    The centre position is estimated at ENABLE from the raw LVDT reading
    (``phi_c = phi - s * i_total``); the calibration needs no better.
    """

    def __init__(self, actuation: Actuation, check: Check,
                 force_by_position: tuple[bool, bool] = (False, False)) -> None:
        self.act = actuation
        #: per EMA: it holds a force by the master's loop in position mode (its drive has no CST)
        self.force_by_position = (bool(force_by_position[0]), bool(force_by_position[1]))
        self._opp_delta = 0.0  # the opposing EMA's excursion of the position-mode force loop [mm]
        self._opp_base = (0.0, 0.0)  # its angle and the sweeping EMA's when the loop took over [rad]
        self.check = check
        self.i = actuation.mechanics.i_total_rad_per_mm
        self.T = actuation.timing.sync_period_s
        self._step = Step.IDLE
        self._t0 = 0.0  # start time of the current step
        #: the step's profile time: it waits for periods without a sample (a late SYNC, a missing sample: the
        #: drives held their last setpoints; hil.check.profileclock)
        self._clock = ProfileClock(self.T)
        self._events: list[Event] = []
        self._phi_hold = [0.0, 0.0]  # position targets (rad)
        self._phi_start = [0.0, 0.0]
        self._phi_centre = [0.0, 0.0]
        self._force = 0.0  # FORCE-mode target of the opposing EMA
        self._delta = 0.0  # force-fight excursion (mm)
        self._demand = 0.0
        self._opposer_in_force = True  # the next LOAD step still has to capture the start force
        self._opposer_in_position = False
        self._force_start = 0.0
        self._t_last: float | None = None
        self.abort_reason = ""
        c = check
        self._ff_amp = c.force_fight.amplitude_fraction_of_limit * actuation.mechanics.limit_load_N
        self._ff_period = 4.0 * self._ff_amp / c.force_fight.force_rate_N_per_s
        self._sweep_T = 4.0 * c.calibration.sweep_amplitude_mm / c.calibration.sweep_speed_mm_per_s
        self._planned = self._plan()
        #: (step, planned s before it, its planned s, the check's planned s): :meth:`progress`'s sums
        self._progress_base: tuple[Step, float, float, float] | None = None

    # ------------------------------------------------------------ public API

    @property
    def step_now(self) -> Step:
        return self._step

    @property
    def finished(self) -> bool:
        st = self._step  # (= st in TERMINAL, without hashing an Enum member: every cycle)
        return st is Step.DONE or st is Step.ABORTED

    def planned_duration_s(self) -> float:
        """Planned duration of the whole check in s (for progress displays)."""
        return sum(self._planned.values())

    def progress(self, t_s: float) -> Progress:
        """Where the check stands at time ``t_s``."""
        base = self._progress_base
        if base is None or base[0] is not self._step:
            # the planned durations before this step, its own and the whole check's: once per step
            done = 0.0
            for s in _ORDER:
                if s == self._step:
                    break
                done += self._planned.get(s, 0.0)
            base = self._progress_base = (self._step, done, self._planned.get(self._step, 0.0),
                                          self.planned_duration_s())
        _, done, dur, total = base
        frac = min(1.0, (t_s - self._t0) / dur) if dur > 0 else (1.0 if self._step in TERMINAL else 0.0)
        tot = 1.0 if self._step == Step.DONE else min(1.0, (done + frac * dur) / total)
        return Progress(self._step, frac, tot, self._demand)

    def abort(self, t_s: float, reason: str) -> CycleOutput:
        """Abort the check: both drives to DISABLED (holding brake), latched."""
        if self._step not in TERMINAL:
            self._goto(Step.ABORTED, t_s, reason)
            self.abort_reason = reason
        ev = tuple(self._events)
        self._events.clear()
        return CycleOutput(_HOLD_DISABLED, _HOLD_DISABLED, self._step, ev)

    def step(self, sample: Sample) -> CycleOutput:
        """Advance one cycle with the latest measured sample.

        An exception inside aborts the sequence (latched) and is re-raised.
        """
        try:
            return self._cycle(sample)
        except Exception as exc:
            self.abort(sample.t_s, f"sequence core error: {exc!r}")
            raise

    # ------------------------------------------------------------- internals

    def _plan(self) -> dict[Step, float]:
        c = self.check
        settle = c.approach.settle_s
        ramp = c.calibration.force_ramp_s
        return {
            Step.ENABLE: settle,
            Step.APPROACH: 10.0 / c.approach.speed_mm_per_s + settle,  # typical
            Step.CAL1_LOAD: ramp + settle, Step.CAL1_SWEEP: self._sweep_T, Step.CAL1_UNLOAD: ramp + settle,
            Step.CAL2_LOAD: ramp + settle, Step.CAL2_SWEEP: self._sweep_T, Step.CAL2_UNLOAD: ramp + settle,
            Step.FORCE_FIGHT: c.force_fight.cycles * self._ff_period,
            Step.UNLOAD: 2.0 + settle,
        }

    def _goto(self, new: Step, t_s: float, detail: str = "") -> None:
        if new not in TRANSITIONS[self._step]:
            raise SequenceError(f"illegal step transition {self._step.name} -> {new.name}")
        self._step = new
        self._t0 = t_s
        self._clock.restart(t_s)
        self._events.append(Event(t_s, new, detail))

    def _pos(self, k: int) -> Setpoint:
        return Setpoint(DriveMode.POSITION, self._phi_hold[k])

    def _cycle(self, smp: Sample) -> CycleOutput:
        t = smp.t_s
        last = self._t_last
        if last is not None:
            if not t > last:
                raise SequenceError(f"sample time not increasing: {t} after {last}")
        self._t_last = t
        phi = (smp.phi1_rad, smp.phi2_rad)
        c = self.check
        i = self.i
        dt = self._clock.elapsed(t)  # the step's profile time (its time on the samples' clock, less periods held)
        st = self._step
        settle = c.approach.settle_s

        if st == Step.IDLE:
            # take over where the drives are: hold the measured position
            self._phi_hold = [phi[0], phi[1]]
            # both rams move by the same stroke (the surface is common): no force fight builds up
            shift = -0.5 * (smp.s1_mm + smp.s2_mm) * i
            self._phi_centre = [phi[0] + shift, phi[1] + shift]
            self._goto(Step.ENABLE, t)
        elif st == Step.ENABLE:
            if dt >= settle:
                self._phi_start = list(self._phi_hold)
                self._goto(Step.APPROACH, t)
        elif st == Step.APPROACH:
            v = c.approach.speed_mm_per_s * i
            arrived = True
            for k in (0, 1):
                err = self._phi_centre[k] - self._phi_start[k]
                step = min(abs(err), v * dt)
                self._phi_hold[k] = self._phi_start[k] + math.copysign(step, err)
                arrived &= step >= abs(err)
            if arrived and dt >= max(abs(self._phi_centre[k] - self._phi_start[k]) for k in (0, 1)) / v + settle:
                self._goto(Step.CAL1_LOAD, t)
        elif st in (Step.CAL1_LOAD, Step.CAL1_SWEEP, Step.CAL1_UNLOAD,
                    Step.CAL2_LOAD, Step.CAL2_SWEEP, Step.CAL2_UNLOAD):
            return self._calibration(st, smp, dt)
        elif st == Step.FORCE_FIGHT:
            self._force_fight(smp, dt)
            if dt >= c.force_fight.cycles * self._ff_period:
                self._demand = 0.0
                self._goto(Step.UNLOAD, t)
        elif st == Step.UNLOAD:
            # excursions back to zero at the excursion rate limit, then done
            v = c.force_fight.max_excursion_rate_mm_per_s * self.T
            self._delta -= math.copysign(min(abs(self._delta), v), self._delta)
            self._set_excursion()
            if self._delta == 0.0 and dt >= settle:
                self._goto(Step.DONE, t)
        if self._step in TERMINAL:
            return self._emit(_HOLD_DISABLED, _HOLD_DISABLED)
        return self._emit(self._pos(0), self._pos(1))

    def _emit(self, sp1: Setpoint, sp2: Setpoint) -> CycleOutput:
        ev = tuple(self._events)
        self._events.clear()
        return CycleOutput(sp1, sp2, self._step, ev)

    def _calibration(self, st: Step, smp: Sample, dt: float) -> CycleOutput:
        c = self.check.calibration
        settle = self.check.approach.settle_s
        k = 0 if st in (Step.CAL1_LOAD, Step.CAL1_SWEEP, Step.CAL1_UNLOAD) else 1  # sweeping EMA
        j = 1 - k  # opposing EMA, in FORCE mode: it pulls (tension), the sweeping EMA pushes
        f_opp = -c.opposing_force_N
        t = smp.t_s
        if st in (Step.CAL1_LOAD, Step.CAL2_LOAD):
            if self._opposer_in_force:  # first cycle: ramp from the force the opposer carries now
                self._force_start = (smp.F1_N, smp.F2_N)[j]
                self._opposer_in_force = False
                self._opp_delta = 0.0
                self._opp_base = (self._phi_hold[j], self._phi_hold[k])
            a = min(1.0, dt / c.force_ramp_s)
            self._force = (1.0 - a) * self._force_start + a * f_opp
            if dt >= c.force_ramp_s + settle and self._opposing_force_held(smp, j, f_opp, dt):
                self._phi_start = list(self._phi_hold)
                self._goto(Step.CAL1_SWEEP if k == 0 else Step.CAL2_SWEEP, t)
        elif st in (Step.CAL1_SWEEP, Step.CAL2_SWEEP):
            off, finished = _sweep(dt, c.sweep_amplitude_mm, c.sweep_speed_mm_per_s)
            self._phi_hold[k] = self._phi_start[k] + off * self.i
            if finished:
                self._goto(Step.CAL1_UNLOAD if k == 0 else Step.CAL2_UNLOAD, t)
        else:  # unload: ramp the opposing force off, then hold it in position mode and settle
            if dt < c.force_ramp_s:
                self._force = f_opp * (1.0 - dt / c.force_ramp_s)
            else:
                if not self._opposer_in_position:
                    self._phi_hold[j] = (smp.phi1_rad, smp.phi2_rad)[j]
                    self._opposer_in_position = True
                if dt >= c.force_ramp_s + settle:
                    nxt = Step.CAL2_LOAD if k == 0 else Step.FORCE_FIGHT
                    self._phi_start = list(self._phi_hold)
                    self._delta = 0.0
                    self._goto(nxt, t)
                    self._opposer_in_force = True
                    self._opposer_in_position = False
                return self._emit(self._pos(0), self._pos(1))
        sps = [self._pos(0), self._pos(1)]
        if self.force_by_position[j]:
            sps[j] = Setpoint(DriveMode.POSITION, self._force_by_position(smp, j, k))
        else:
            sps[j] = Setpoint(DriveMode.FORCE, self._force)
        return self._emit(sps[0], sps[1])

    def _opposing_force_held(self, smp: Sample, j: int, f_opp: float, dt: float) -> bool:
        """The sweep may start: the drive holds the opposing force itself (CST), or the position-mode loop
        has brought EMA ``j``'s force within :data:`OPPOSING_FORCE_TOLERANCE` of it (it first traverses the
        chain's play). Raises SequenceError when that takes longer than :data:`OPPOSING_FORCE_TIMEOUT_S`."""
        if not self.force_by_position[j]:
            return True
        if abs((smp.F1_N, smp.F2_N)[j] - f_opp) <= OPPOSING_FORCE_TOLERANCE * abs(f_opp):
            return True
        c = self.check.calibration
        if dt > c.force_ramp_s + self.check.approach.settle_s + OPPOSING_FORCE_TIMEOUT_S:
            raise SequenceError(f"EMA {j + 1} did not reach the opposing force {f_opp:g} N within "
                                f"{OPPOSING_FORCE_TIMEOUT_S:g} s of its ramp (force {(smp.F1_N, smp.F2_N)[j]:.0f} N; "
                                f"it holds forces by the position-mode loop, its drive has no CST)")
        return False

    def _force_by_position(self, smp: Sample, j: int, k: int) -> float:
        """The opposing EMA ``j``'s angle target: it follows EMA ``k``'s commanded motion plus an
        excursion integrated on its force error (module docstring) [rad]."""
        ff = self.check.force_fight
        err = self._force - (smp.F1_N, smp.F2_N)[j]
        rate = max(-ff.max_excursion_rate_mm_per_s, min(ff.max_excursion_rate_mm_per_s, ff.loop_gain_mm_per_N_s * err))
        self._opp_delta += rate * self.T
        base_j, base_k = self._opp_base
        return base_j + (self._phi_hold[k] - base_k) + self._opp_delta * self.i

    def _set_excursion(self) -> None:
        self._phi_hold[0] = self._phi_start[0] + self._delta * self.i
        self._phi_hold[1] = self._phi_start[1] - self._delta * self.i

    def _force_fight(self, smp: Sample, dt: float) -> None:
        ff = self.check.force_fight
        self._demand = _triangle(dt, self._ff_amp, self._ff_period)
        f_ff = 0.5 * (smp.F1_N - smp.F2_N)
        rate = ff.loop_gain_mm_per_N_s * (self._demand - f_ff)
        vmax = ff.max_excursion_rate_mm_per_s
        rate = max(-vmax, min(vmax, rate))
        self._delta += rate * self.T
        self._set_excursion()
