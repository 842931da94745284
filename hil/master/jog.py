r"""The force-free jog (sans-IO): both EMAs out and back together before anything moves under load.

Fed one :class:`~hil.canopen.process.Sample` per SYNC, returning both drives' setpoints; it never touches a
bus or a clock. Both EMAs move in CSP by the same motor travel :math:`x(t)` over the profile's gear ratio
(:math:`\varphi_a = \varphi_{a,0} + i\,x`): no force is commanded and, the two EMAs being alike, the rams and
the surface move together (the only forces are the surface's inertia and friction). A drive without CST
moves the same way: one sequence for every rig.

:math:`x(t)`: out by :attr:`~hil.master.jog_rules.JogPlan.travel_mm` at
:attr:`~hil.master.jog_rules.JogPlan.speed_mm_per_s`, the speed ramped up and down as a half cosine over
:attr:`~hil.master.jog_rules.JogPlan.ramp_s` (the acceleration has no step), hold, back the same way, hold.

Checked on every sample (any one stops the jog: the motion decelerates over one ramp from the speed it had
and holds, then the jog ends; the judgement and the reason are :meth:`Jog.verdict`):

* each load cell within :attr:`~hil.master.jog_rules.JogPlan.max_force_change_N` of its mean at rest;
* each LVDT within :attr:`~hil.master.jog_rules.JogPlan.max_lvdt_mm` of its mean at rest;
* on the way out until it decelerates (where the gains are taken), once an LVDT moved
  (:attr:`~hil.master.jog_rules.JogPlan.engaged_mm`), it is not ahead of its motor:
  :math:`|\Delta s| \le (1 + \varepsilon_0)|\Delta x| + \delta` from that sample on
  (:func:`~hil.master.jog_rules.lvdt_ahead`; a ram that moves 57 times as far as the profile's scale says is
  seen within 0.3 mm of its travel). A ram ahead goes on at the speed it had until an LVDT moved
  :attr:`~hil.master.jog_rules.JogPlan.fit_mm` (for a slope), then stops; the other rules stop at once.

The gains and which scale fits are :mod:`hil.master.jog_rules`.
"""

from __future__ import annotations

import math
from enum import Enum

import numpy as np

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.signalmap import Signal
from hil.check.profileclock import ProfileClock
from hil.master.commission_rules import ema_key
from hil.master.jog_rules import JogGain, JogPlan, JogVerdict, explain, jog_gain, lvdt_ahead

__all__ = ["Jog", "JogPhase", "outward_s", "outward_travel", "smooth_travel"]


class JogPhase(Enum):
    OUT = "out"
    HOLD = "hold"
    BACK = "back"
    SETTLE = "settle"
    CREEP = "creep"
    STOPPING = "stopping"
    DONE = "done"


def smooth_travel(d_mm: float, v_mm_per_s: float, ramp_s: float, tau_s: float) -> float:
    r"""Travel [mm] at ``tau_s`` of a move by ``d_mm`` at ``v_mm_per_s``, the speed ramped as a half cosine over
    ``ramp_s`` at either end: :math:`v(t) = \frac v2 (1 - \cos \pi t / t_r)` on the way up (covering
    :math:`v t_r / 2`), constant, then the mirror image; the move lasts :math:`d / v + t_r` (a shorter move
    lowers the top speed to :math:`d / t_r`)."""
    if d_mm <= 0:
        return 0.0
    v = min(v_mm_per_s, d_mm / ramp_s)
    total = d_mm / v + ramp_s
    t = min(max(tau_s, 0.0), total)
    up = lambda s: 0.5 * v * (s - ramp_s / math.pi * math.sin(math.pi * s / ramp_s))  # noqa: E731
    if t <= ramp_s:
        return up(t)
    if t <= total - ramp_s:
        return 0.5 * v * ramp_s + v * (t - ramp_s)
    return d_mm - up(total - t)


def outward_travel(d_mm: float, v_mm_per_s: float, ramp_s: float, growth_s: float, seed_mm: float,
                   tau_s: float) -> tuple[float, float]:
    r"""Travel [mm] and speed [mm/s] at ``tau_s`` of the jog's way out: the speed grows with the travel,
    :math:`x = x_0 (e^{t/\tau} - 1)`, :math:`v = (x + x_0)/\tau`, until it reaches ``v_mm_per_s`` (at
    :math:`x_A = v \tau - x_0`), constant, then a half cosine down to 0 over ``ramp_s`` (covering
    :math:`v t_r / 2`) ending at ``d_mm``; it lasts :func:`outward_s`."""
    v, tau, x0 = v_mm_per_s, growth_s, seed_mm
    x_a = v * tau - x0
    t_a = tau * math.log(v * tau / x0)
    x_c = d_mm - 0.5 * v * ramp_s  # where the deceleration starts
    if x_a > x_c:
        raise ValueError(f"jog: a travel of {d_mm} mm is too short for its speed {v} mm/s")
    t = max(tau_s, 0.0)
    if t <= t_a:
        x = x0 * (math.exp(t / tau) - 1.0)
        return x, (x + x0) / tau
    t_c = t_a + (x_c - x_a) / v
    if t <= t_c:
        return x_a + v * (t - t_a), v
    u = min(t - t_c, ramp_s)
    return (x_c + 0.5 * v * (u + ramp_s / math.pi * math.sin(math.pi * u / ramp_s)),
            0.5 * v * (1.0 + math.cos(math.pi * u / ramp_s)))


def outward_s(d_mm: float, v_mm_per_s: float, ramp_s: float, growth_s: float, seed_mm: float) -> float:
    """How long :func:`outward_travel` lasts [s]."""
    v = v_mm_per_s
    x_a = v * growth_s - seed_mm
    return growth_s * math.log(v * growth_s / seed_mm) + (d_mm - 0.5 * v * ramp_s - x_a) / v + ramp_s


class Jog:
    """One jog of both EMAs (module docstring).

    Parameters
    ----------
    plan : JogPlan
    rig : hil.canopen.plan.RigPlan
        For the keys of the findings.
    start_rad : (float, float)
        Both motor angles where the jog starts (their angles at rest) [rad].
    rest : dict
        Means at rest of ``s1, s2`` [mm] and ``F1, F2`` [N].
    t0_s : float
        Time of the first sample [s].
    period_s : float
        The SYNC period [s]: the jog's profile waits for periods without a sample
        (:class:`hil.check.profileclock.ProfileClock`: after the PC held the loop it resumes where it was; a
        trajectory read on the samples' clock would leap by the motion missed).
    """

    def __init__(self, plan: JogPlan, rig, start_rad: tuple[float, float], rest: dict, t0_s: float,
                 period_s: float) -> None:
        self.plan, self.rig = plan, rig
        self.start = start_rad
        self.rest = rest
        self.phase = JogPhase.OUT
        self._clock = ProfileClock(period_s)
        self._clock.restart(t0_s)
        self._t_phase = 0.0  #: the phase's start on the jog's profile clock [s]
        self._tp_prev: float | None = None  #: the last sample's profile time [s]
        self.stopped: str | None = None  #: why the jog was stopped (None: it ran its course)
        self.stop_key = ""  #: the key of the signal that stopped it
        self.rows: list[tuple] = []  #: t, x (commanded), phi1, phi2, s1, s2, F1, F2
        #: rows the gains are taken over: the way out up to where it decelerates (the surface, unloaded, runs on
        #: and drags the rams across their internal play as the motors slow down: over a real bus, whose
        #: setpoints jitter, by the whole play, 0.1 mm)
        self.fit_end: int | None = None
        self._x = 0.0  #: commanded travel [mm]
        self._v = 0.0  #: commanded speed [mm/s]
        self._engaged: dict[int, tuple[float, float]] = {}  #: EMA -> (x, s) where its LVDT started to move
        self._stop_from: tuple[float, float] = (0.0, 0.0)  #: (travel, speed) where the stop began

    @property
    def done(self) -> bool:
        return self.phase is JogPhase.DONE

    # ------------------------------------------------------------ the cycle

    def step(self, smp: Sample) -> tuple[Setpoint, Setpoint]:
        """One sample in, both setpoints out (holding where the jog ended once :attr:`done`)."""
        p = self.plan
        i = p.i_total_rad_per_mm
        tp = self._clock.elapsed(smp.t_s)  # the jog's profile time
        x_meas = ((smp.phi1_rad - self.start[0]) / i, (smp.phi2_rad - self.start[1]) / i)
        self.rows.append((smp.t_s, self._x, smp.phi1_rad, smp.phi2_rad, smp.s1_mm, smp.s2_mm, smp.F1_N, smp.F2_N))
        if self.phase not in (JogPhase.STOPPING, JogPhase.DONE) and (why := self._check(smp, x_meas)):
            key, text, ahead = why
            if self.stopped is None:
                self.stop_key, self.stopped = key, text
            if not ahead and self.fit_end is None:
                self.fit_end = len(self.rows)
            if ahead:  # on at the speed it had, for a slope (the deceleration after it is still outward)
                self._enter(JogPhase.CREEP, tp)
            else:
                self._stop_from = (self._x, self._v)
                self._enter(JogPhase.STOPPING, tp)
        self._advance(tp)
        self._tp_prev = tp
        return (Setpoint(DriveMode.POSITION, self.start[0] + i * self._x),
                Setpoint(DriveMode.POSITION, self.start[1] + i * self._x))

    def _enter(self, phase: JogPhase, t: float) -> None:
        self.phase, self._t_phase = phase, t

    def _advance(self, t: float) -> None:
        """The commanded travel for the next cycle, and the phase (``t``: the jog's profile time [s])."""
        p = self.plan
        tau = t - self._t_phase
        dt = t - self._tp_prev if self._tp_prev is not None else 0.0
        move_s = p.travel_mm / min(p.speed_mm_per_s, p.travel_mm / p.ramp_s) + p.ramp_s
        x_prev = self._x
        if self.phase is JogPhase.OUT:
            out = (p.travel_mm, p.speed_mm_per_s, p.ramp_s, p.growth_s, p.seed_mm)
            self._x, self._v = outward_travel(*out, tau)
            if tau >= outward_s(*out) - p.ramp_s and self.fit_end is None:
                self.fit_end = len(self.rows)
            if tau >= outward_s(*out):
                self._enter(JogPhase.HOLD, t)
        elif self.phase is JogPhase.HOLD:
            if tau >= p.hold_s:
                self._enter(JogPhase.BACK, t)
        elif self.phase is JogPhase.BACK:
            self._x = p.travel_mm - smooth_travel(p.travel_mm, p.speed_mm_per_s, p.ramp_s, tau)
            if tau >= move_s:
                self._x = 0.0
                self._enter(JogPhase.SETTLE, t)
        elif self.phase is JogPhase.SETTLE:
            if tau >= p.hold_s:
                self._enter(JogPhase.DONE, t)
        elif self.phase is JogPhase.CREEP:
            far = max(abs(self.rows[-1][4] - self.rest["s1"]), abs(self.rows[-1][5] - self.rest["s2"]))
            if far >= p.fit_mm or self._x >= p.travel_mm:
                self.fit_end = len(self.rows) if self.fit_end is None else self.fit_end
                self._stop_from = (self._x, self._v)
                self._enter(JogPhase.STOPPING, t)
            else:
                self._x += self._v * dt
                return
        if self.phase is JogPhase.STOPPING:
            tau = t - self._t_phase
            x0, v0 = self._stop_from
            ts = self.stop_s(v0)  # v(t) = v0 / 2 (1 + cos pi t / t_s): down to 0 at the planned deceleration
            tr = min(tau, ts)
            self._x = x0 + 0.5 * v0 * (tr + ts / math.pi * math.sin(math.pi * tr / ts))
            if tau >= ts + p.hold_s:
                self._enter(JogPhase.DONE, t)
        if dt > 0 and self.phase is not JogPhase.OUT:
            self._v = (self._x - x_prev) / dt

    def stop_s(self, v0_mm_per_s: float) -> float:
        r"""How long a stop from ``v0_mm_per_s`` takes: at most the planned ramps' deceleration
        :math:`\pi v / (2 t_r)`, and not quicker than the growth's :math:`\tau`: :math:`t_s = \max(t_r |v_0| / v,
        \tau)` [s] (the stop travels :math:`v_0 t_s / 2`)."""
        p = self.plan
        return max(p.ramp_s * abs(v0_mm_per_s) / p.speed_mm_per_s, p.growth_s)

    def _check(self, smp: Sample, x_meas: tuple[float, float]) -> tuple[str, str, bool] | None:
        """Why the jog must stop now (key, text, whether an LVDT ran ahead of its motor), or None."""
        p, rig = self.plan, self.rig
        for a, f in ((1, smp.F1_N), (2, smp.F2_N)):
            d = f - self.rest[f"F{a}"]
            if abs(d) > p.max_force_change_N:
                key = ema_key(rig, a, Signal.FORCE)
                return key, (f"load cell {a} changed by {d:+.0f} N during the force-free jog (> "
                             f"{p.max_force_change_N:g} N): the rams do not move together, or a wrong load-cell "
                             f"scale"), False
        for a, s in ((1, smp.s1_mm), (2, smp.s2_mm)):
            ds = s - self.rest[f"s{a}"]
            if abs(ds) > p.max_lvdt_mm:
                return ema_key(rig, a, Signal.LVDT), (f"LVDT {a} moved {ds:+.3f} mm from rest (> {p.max_lvdt_mm:g} mm: "
                                                      f"the travel, the internal play and the noise) while the "
                                                      f"motors moved {x_meas[a - 1]:+.4f} mm over the gear "
                                                      f"ratio"), False
            if self.phase is not JogPhase.OUT or self.fit_end is not None:
                continue  # (on the way out at the speed it had: where the gains are taken)
            if a not in self._engaged and abs(ds) >= p.engaged_mm:
                self._engaged[a] = (x_meas[a - 1], s)
            if a in self._engaged:
                x0, s0 = self._engaged[a]
                dx, dsa = x_meas[a - 1] - x0, s - s0
                if lvdt_ahead(dx, dsa, p, a):
                    return ema_key(rig, a, Signal.LVDT), (
                        f"LVDT {a} moved {dsa:+.4f} mm while its motor moved {dx:+.4f} mm over the gear ratio (more "
                        f"than (1 + {p.gain_tolerance:g}) x {abs(dx):.4f} + {p.delta_mm[a - 1]:.4f} mm): the ram "
                        f"moves farther than the profile's scale says"), True
        return None

    # ------------------------------------------------------------ the judgement

    def arrays(self) -> dict[str, np.ndarray]:
        """Every sample of the jog: ``t, x_cmd`` [s, mm], ``phi1, phi2`` [rad], ``s1, s2`` [mm], ``F1, F2`` [N],
        and ``x1, x2`` (each motor's travel over the gear ratio from its start) [mm]."""
        a = np.asarray(self.rows, dtype=float).reshape(-1, 8)
        out = {n: a[:, c] for c, n in enumerate(("t", "x_cmd", "phi1", "phi2", "s1", "s2", "F1", "F2"))}
        i = self.plan.i_total_rad_per_mm
        out["x1"], out["x2"] = (out["phi1"] - self.start[0]) / i, (out["phi2"] - self.start[1]) / i
        return out

    def gains(self) -> tuple[JogGain, JogGain]:
        """Both EMAs' gains over the way out up to where it decelerates (a stopped jog: over what it moved at the
        speed it had, however little)."""
        x = self.arrays()
        n = self.fit_end if self.fit_end is not None else len(self.rows)
        return tuple(jog_gain(x[f"x{a}"][:n], x[f"s{a}"][:n], self.rest[f"s{a}"], a, self.plan) for a in (1, 2))

    def verdict(self) -> JogVerdict:
        """The jog judged (:func:`hil.master.jog_rules.explain`)."""
        return explain(self.gains(), self.rig, self.plan, stopped=self.stopped, stopped_key=self.stop_key)

    def peak_force_change_N(self) -> float:
        """The largest change of either load cell from its mean at rest during the jog [N]."""
        x = self.arrays()
        return float(max(np.max(np.abs(x[f"F{a}"] - self.rest[f"F{a}"]), initial=0.0) for a in (1, 2)))
