r"""The force-free jog's plan and judgement (pure): does the motion scale hold before anything moves under load?

Before any force is commanded, :mod:`hil.master.jog` moves both EMAs together, out by the commissioning's
travel and back, each in CSP by the same motor angle (no force commanded: the rams and the surface move
together). Every observation of how far a ram moved must agree: the motor angle over the profile's gear
ratio :math:`x_a = \Delta\varphi_a / i` [mm] (the resolver through the encoder resolution, the drive's
0x608F or the profile's ``counts_per_rev``), and the LVDT :math:`\Delta s_a` [mm]. Their ratio, the
*jog gain*

.. math:: g_a = \frac{\mathrm d s_a}{\mathrm d x_a}
          \quad\text{(least-squares slope over the outward stroke once the ram moves)}

must be 1 within :math:`\varepsilon_a = \varepsilon_0 + \delta_a / R_a`, where :math:`\varepsilon_0` =
``HARD_LVDT_GAIN_TOLERANCE`` (0.10: the LVDT pitch error the supervisor allows; the paper's LVDT has
7.5 %), :math:`\delta_a` how far the ram's travel by LVDT and by motor may differ with nothing wrong (the
declared LVDT noise peak to peak, one motor-angle unit, and the internal play: unloaded, the ram may sit
anywhere in it; :attr:`JogPlan.delta_mm`, 0.2253 mm for the shipped profiles) and :math:`R_a` the motor
travel the slope was taken over, at least :attr:`JogPlan.min_range_mm` (0.65 mm) for a gain to confirm the
scale: :math:`\varepsilon` = 0.1 + 0.2253 / 0.65 = 0.447 at the widest, 0.38 for the clean simulated rig.
The same bound on the two ends of the stroke so far is the on-line rule (:func:`lvdt_ahead`): an LVDT ahead
of its motor by more than :math:`\varepsilon_0 |\Delta x| + \delta_a` stops the jog at once.

Which scale fits every observation (:func:`explain`), each hypothesis one profile key times a factor r:

==============================  ===============  ============================================
hypothesis                      predicts         rejected when
==============================  ===============  ============================================
gear ratio (and screw lead)     g1 = g2 = r      the drive reports the gear ratio
``mechanics.i_total_rad_per_mm``                 (``canopen.gear_ratio_object``, compared
fits ``i / r``                                   with the profile in the preflight)
LVDT scale of EMA a             g_a = r, g_b = 1 (never by the jog alone)
encoder resolution of EMA a     g_a = r, g_b = 1 the profile's ``counts_per_rev`` was compared
                                                 with the drive's 0x608F in the preflight
both LVDT scales (two keys)     g1 = g2 = r      (never: named as also fitting)
==============================  ===============  ============================================

The rams move together, so an LVDT scale and an encoder resolution of one EMA predict the same (both
say so where both are open). One key is simpler than two: a shared factor is named as the gear ratio
(``i`` is 2 pi N / lead: gear ratio and screw lead are one key), the two LVDT scales are said to fit
as well. A factor close to a unit error (180/pi: degrees for radians; 1/(2 pi): revolutions for
radians; a power of ten) is named as such.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hil.canopen.signalmap import ScaleSource, Signal
from hil.master.commission_rules import Finding, Kind, Limits, Stage, ema_key, slope
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE, Actuation, Safety

__all__ = ["DRIVE_SPEED_FACTOR", "JOG_FORCE_FRACTION", "JOG_GROWTH_S", "JOG_HOLD_S", "JOG_RAMP_S", "JOG_SEED_MM",
           "JOG_SPEED_FRACTION", "Hypothesis", "JogGain", "JogPlan", "JogVerdict", "commissioning_safety", "explain",
           "gear_se", "jog_gain", "lvdt_ahead", "unit_error"]

#: The jog's speed: this fraction of the commissioning speed (0.5 mm/s for the shipped check).
JOG_SPEED_FRACTION = 1.0
#: Speed ramps of the jog's deceleration and of its way back (a cosine in velocity) [s].
JOG_RAMP_S = 0.5
#: On the way out the speed grows with the travel so far, :math:`v = (x + x_0) / \tau` (an exponential start):
#: the travel never more than doubles between two looks of the on-line check, so a ram that moves 57 times
#: as far as the motor says is seen while it is slow. :math:`\tau` [s]:
JOG_GROWTH_S = 0.3
#: ... and :math:`x_0` [mm] (the motion starts at :math:`x_0 / \tau`, 3 um/s).
JOG_SEED_MM = 0.001
#: Holds at the far end and after the return [s].
JOG_HOLD_S = 0.3
#: A load cell that changes by more than this fraction of the commissioning's force limit during the jog
#: stops it (nothing is commanded to push: the surface's and the rams' inertia at the jog's acceleration
#: need a few newtons; 200 N for the shipped check is 20 times the declared load-cell noise).
JOG_FORCE_FRACTION = 0.1
#: During commissioning the drives' max motor speed 0x6080 is this many times the commissioning speed
#: (the position loop's overshoot; the check's own limit where lower).
DRIVE_SPEED_FACTOR = 4.0

#: Unit errors a factor is compared with (the profile's gear ratio over the one that fits).
_UNIT_ERRORS = ((180.0 / math.pi, "degrees where radians were meant (x 180/pi)"),
                (math.pi / 180.0, "radians where degrees were meant (x pi/180)"),
                (1.0 / (2.0 * math.pi), "revolutions where radians were meant (x 1/(2 pi))"),
                (2.0 * math.pi, "radians where revolutions were meant (x 2 pi)"))


@dataclass(frozen=True, slots=True)
class JogPlan:
    """The jog's motion, its limits and its tolerance, from the profiles (docs/commission.md).

    Attributes
    ----------
    travel_mm : float
        Out and back by this much motor travel over the profile's gear ratio: the commissioning's travel
        (``Limits.travel_mm``) [mm].
    speed_mm_per_s : float
        :data:`JOG_SPEED_FRACTION` of the commissioning speed [mm/s].
    ramp_s, hold_s, growth_s : float
        :data:`JOG_RAMP_S`, :data:`JOG_HOLD_S`, :data:`JOG_GROWTH_S` [s].
    seed_mm : float
        :data:`JOG_SEED_MM` [mm].
    gain_tolerance : float
        :math:`\\varepsilon_0` = ``HARD_LVDT_GAIN_TOLERANCE``.
    delta_mm : (float, float)
        :math:`\\delta_a` per EMA, how far the ram's travel by LVDT and by motor angle may differ with nothing
        wrong: ``sensors.lvdt_noise_pp_mm``, one motor-angle unit over the gear ratio (0 where the drive gives
        the scale) and the internal play ``mechanics.backlash_spec_int_mm`` (unloaded, the ram may sit anywhere
        in it, and the surface running on drags it across: over a real bus, whose setpoints jitter, seen by
        0.07 mm in 0.4 mm) [mm].
    engaged_mm : float
        An LVDT this far from its mean at rest has started to move (the ram is past its internal play):
        ``sensors.lvdt_noise_pp_mm`` (noise alone stays within half of it of the mean) [mm].
    min_range_mm : float
        The least motor travel after engagement that a gain confirms the scale over: the travel less the
        deceleration (:math:`v t_r / 2`: the gain is taken before it), the internal play
        ``mechanics.backlash_spec_int_mm`` and ``engaged_mm`` [mm].
    max_force_change_N : float
        :data:`JOG_FORCE_FRACTION` of the commissioning's force limit [N].
    max_lvdt_mm : float
        An LVDT farther than this from its mean at rest stops the jog: beyond anything a passing jog accepts,
        the travel times :math:`1 + \\varepsilon_{max}` (:attr:`widest_tolerance`) plus :math:`\\delta` [mm].
    fit_mm : float
        Once an LVDT ran ahead of its motor, the jog goes on at the speed it had until an LVDT moved this far
        from rest, then stops: half the travel (a slope over 0.5 mm of LVDT: the factor that fits to a few
        per cent, at the speed the exponential start had when it was seen) [mm].
    i_total_rad_per_mm : float
        The profile's gear ratio (under test) [rad/mm].
    """

    travel_mm: float
    speed_mm_per_s: float
    ramp_s: float
    hold_s: float
    growth_s: float
    seed_mm: float
    gain_tolerance: float
    delta_mm: tuple[float, float]
    engaged_mm: float
    min_range_mm: float
    max_force_change_N: float
    max_lvdt_mm: float
    fit_mm: float
    i_total_rad_per_mm: float

    @classmethod
    def of(cls, act: Actuation, lim: Limits, plan) -> JogPlan:
        p = cls._of(act, lim, plan)
        return dataclasses.replace(p, max_lvdt_mm=p.travel_mm * (1.0 + p.widest_tolerance) + max(p.delta_mm))

    @classmethod
    def _of(cls, act: Actuation, lim: Limits, plan) -> JogPlan:
        i = act.mechanics.i_total_rad_per_mm
        noise = act.sensors.lvdt_noise_pp_mm
        play = act.mechanics.backlash_spec_int_mm
        delta = []
        for ema in (1, 2):
            ch = plan.channel(ema, Signal.MOTOR_ANGLE)
            k = ch.scale.units_per_si if ch is not None and ch.scale is not None else math.inf
            delta.append(noise + 1.0 / (abs(k) * i) + play)
        speed = JOG_SPEED_FRACTION * lim.speed_mm_per_s
        return cls(travel_mm=lim.travel_mm, speed_mm_per_s=speed,
                   ramp_s=JOG_RAMP_S, hold_s=JOG_HOLD_S, growth_s=JOG_GROWTH_S, seed_mm=JOG_SEED_MM,
                   gain_tolerance=HARD_LVDT_GAIN_TOLERANCE,
                   delta_mm=(delta[0], delta[1]), engaged_mm=noise,
                   min_range_mm=max(lim.travel_mm - 0.5 * speed * JOG_RAMP_S - play - noise, 0.25 * lim.travel_mm),
                   max_force_change_N=JOG_FORCE_FRACTION * lim.max_force_N,
                   max_lvdt_mm=math.inf, fit_mm=0.5 * lim.travel_mm, i_total_rad_per_mm=i)

    def tolerance(self, ema: int, range_mm: float) -> float:
        """:math:`\\varepsilon_a = \\varepsilon_0 + \\delta_a / R` for a gain taken over ``range_mm`` [mm]."""
        return self.gain_tolerance + self.delta_mm[ema - 1] / range_mm if range_mm > 0 else math.inf

    @property
    def widest_tolerance(self) -> float:
        """The widest band a passing jog accepts (the gain over the least range judged)."""
        return max(self.tolerance(a, self.min_range_mm) for a in (1, 2))

    def as_json(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in
                ((f.name, getattr(self, f.name)) for f in dataclasses.fields(self))}


def lvdt_ahead(dx_mm: float, ds_mm: float, plan: JogPlan, ema: int) -> bool:
    r"""The on-line rule: since its LVDT started to move, EMA ``ema``'s LVDT moved ``ds_mm`` while its motor
    moved ``dx_mm`` over the gear ratio; ahead when :math:`|\Delta s| > (1 + \varepsilon_0)|\Delta x| + \delta_a`
    (the ram moves farther than the profile's scale says by more than the pitch tolerance and the noise)."""
    return abs(ds_mm) > (1.0 + plan.gain_tolerance) * abs(dx_mm) + plan.delta_mm[ema - 1]


def commissioning_safety(safety: Safety, lim: Limits, plan: JogPlan) -> Safety:
    r"""The safety profile the preflight writes the drives' own limits from during commissioning.

    * max torque 0x6072: the commissioning's force limit over :math:`1 + \varepsilon_{max}`
      (:attr:`JogPlan.widest_tolerance`). The torque limit becomes a ram force through the gear ratio,
      :math:`F = \tau\, T_r\, i_{true}`, and :math:`i_{true}` is the suspect scale. No torque is commanded
      before the jog confirmed :math:`i` against the LVDTs within :math:`\varepsilon`; for every
      :math:`i_{true} \le i (1 + \varepsilon_{max})` the jog accepts, the drive's limit
      :math:`\tau = F_{max} / (T_r\, i\, (1 + \varepsilon_{max}))` gives at most :math:`F_{max}`.
      During the jog the force is bounded by what is commanded (no torque; the rams move together) and
      checked on every sample (:data:`JOG_FORCE_FRACTION`).
    * max motor speed 0x6080: :data:`DRIVE_SPEED_FACTOR` times the commissioning speed (the check's
      ``safety.max_velocity_mm_per_s`` where lower).
    """
    return dataclasses.replace(
        safety, max_force_N=lim.max_force_N / (1.0 + plan.widest_tolerance),
        max_velocity_mm_per_s=min(safety.max_velocity_mm_per_s, DRIVE_SPEED_FACTOR * lim.speed_mm_per_s))


# ------------------------------------------------------------------ one EMA's gain


@dataclass(frozen=True, slots=True)
class JogGain:
    r"""One EMA's jog gain (None: its LVDT did not move past :attr:`JogPlan.engaged_mm`).

    ``tolerance`` is :math:`\varepsilon_a` (absolute, on :math:`g - 1`); ``rel_tolerance`` the same bound on
    the gain itself relative to its value, :math:`\varepsilon_0 + \delta_a / |\Delta s|` (the LVDT's own
    travel): the uncertainty of a factor that fits. ``confirms``: the slope was taken over at least
    :attr:`JogPlan.min_range_mm` (a gain within the tolerance over less confirms nothing)."""

    ema: int
    gain: float | None
    range_mm: float  #: motor travel over the gear ratio the slope was taken over [mm]
    lvdt_mm: float  #: the LVDT's largest change from its mean at rest [mm]
    motor_mm: float  #: the motor's largest travel over the gear ratio from its start [mm]
    tolerance: float | None
    rel_tolerance: float | None = None
    confirms: bool = False

    @property
    def agrees(self) -> bool | None:
        """True: within the tolerance over enough travel; False: outside it; None: not judged, or too little."""
        if self.gain is None:
            return None
        if abs(self.gain - 1.0) > self.tolerance:
            return False
        return True if self.confirms else None

    def as_json(self) -> dict:
        return {"gain": self.gain, "range_mm": self.range_mm, "lvdt_mm": self.lvdt_mm, "motor_mm": self.motor_mm,
                "tolerance": self.tolerance, "rel_tolerance": self.rel_tolerance, "confirms": self.confirms}


def jog_gain(x_mm: np.ndarray, s_mm: np.ndarray, s_rest_mm: float, ema: int, plan: JogPlan) -> JogGain:
    """EMA ``ema``'s gain over the outward stroke: ``x_mm`` motor travel over the gear ratio from its start,
    ``s_mm`` the LVDT [mm], both from the jog's first sample to its farthest point; ``s_rest_mm`` the LVDT's
    mean at rest. The slope is taken from the first sample the LVDT is :attr:`JogPlan.engaged_mm` from its
    rest (the ram past its play) on, with its tolerance for the motor travel it was taken over."""
    x, s = np.asarray(x_mm, float), np.asarray(s_mm, float)
    away = np.abs(s - s_rest_mm)
    lvdt, motor = float(away.max(initial=0.0)), float(np.abs(x).max(initial=0.0))
    hit = np.flatnonzero(away >= plan.engaged_mm)
    e = int(hit[0]) if hit.size else x.size
    rng = float(np.ptp(x[e:])) if x.size - e >= 3 else 0.0
    if rng <= 0:
        return JogGain(ema, None, rng, lvdt, motor, None)
    g = slope(x[e:], s[e:])
    moved = abs(g) * rng
    rel = plan.gain_tolerance + plan.delta_mm[ema - 1] / moved if moved > 0 else math.inf
    return JogGain(ema, g, rng, lvdt, motor, plan.tolerance(ema, rng), rel, rng >= plan.min_range_mm)


# ------------------------------------------------------------------ which scale fits


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """One explanation tried: ``keys`` (one, or two for a pair) times ``factor``; kept or rejected, and why."""

    name: str
    keys: tuple[str, ...]
    factor: float | None
    fits: float | str | None
    kept: bool
    why: str

    def as_json(self) -> dict:
        return {"name": self.name, "keys": list(self.keys), "factor": self.factor, "fits": self.fits,
                "kept": self.kept, "why": self.why}


@dataclass(frozen=True)
class JogVerdict:
    """The jog judged: the gains, the hypotheses tried, the findings, and whether the commissioning stops
    (the motion scale is not confirmed)."""

    gains: tuple[JogGain, JogGain]
    hypotheses: tuple[Hypothesis, ...]
    findings: tuple[Finding, ...]
    stop: bool

    def as_json(self) -> dict:
        return {"gains": {f"ema{g.ema}": g.as_json() for g in self.gains},
                "hypotheses": [h.as_json() for h in self.hypotheses], "stop": self.stop}


def unit_error(factor: float, tol: float) -> str | None:
    """The unit error ``factor`` (the profile's value over the one that fits) is, the nearest of degrees for
    radians, revolutions for radians, ..., a power of ten, if within ``tol`` relative of it; None: none."""
    if not (math.isfinite(factor) and factor > 0):
        return None
    k = round(math.log10(factor))
    known = (*_UNIT_ERRORS, (10.0 ** k, f"a unit error by a factor 10^{k}")) if k else _UNIT_ERRORS
    f, words = min(known, key=lambda fw: abs(math.log(factor / fw[0])))  # the nearest
    return words if abs(factor / f - 1.0) <= tol else None


def _encoder(plan, ema: int) -> tuple[str, str | None]:
    """EMA ``ema``'s motor-angle scale: (the key or object that holds it, why it cannot be wrong or None)."""
    ch = plan.channel(ema, Signal.MOTOR_ANGLE)
    drive = plan.drives[ema - 1].node
    if ch is None:
        return f"signals.ema{ema}.motor_angle", None
    if ch.source is ScaleSource.PROFILE:
        key = f"{ch.key}.counts_per_rev"
        if ch.node_id == drive.spec.node_id and drive.can_read(0x608F, 1) and drive.can_read(0x608F, 2):
            return key, "the preflight compared it with the drive's encoder resolution 0x608F"
        return key, None
    return f"{ch.key} (the drive's {ch.source.value} as read)", None


def _gear(plan, act_i: float, r: float) -> Hypothesis:
    key = "mechanics.i_total_rad_per_mm"
    if r <= 0:
        return Hypothesis("gear ratio", (key,), r, None, False, "a gear ratio is positive: it cannot turn the sign")
    fits = float(f"{act_i / r:.4g}")
    if plan.gear_ratio_object is not None:
        gi, gs = plan.gear_ratio_object
        return Hypothesis("gear ratio", (key,), r, fits, False, f"the drives report the gear ratio (0x{gi:04X}:"
                          f"{gs:02X}) and the preflight found it equal to the profile's")
    return Hypothesis("gear ratio", (key,), r, fits, True, "one key explains both EMAs (gear ratio and screw "
                      "lead: i = 2 pi N / lead)")


def explain(gains: tuple[JogGain, JogGain], plan, jog: JogPlan, *, stopped: str | None = None,
            stopped_key: str = "") -> JogVerdict:
    """Which scale fits the jog's gains (module docstring), as findings.

    ``stopped``: why the jog was stopped on line (None: it ran its course), ``stopped_key`` the key of the
    signal that stopped it. The motion scale is confirmed when both gains agree over enough travel
    (:attr:`JogGain.agrees`); it is also when only one EMA's LVDT disagrees (or never moved) and that EMA's
    encoder resolution was checked against its drive (the other LVDT and both motors agree: the LVDT alone is
    wrong, judged again in the move, no finding here) -- unless the jog was stopped. Anything else stops the
    commissioning: a gain outside its tolerance is explained, a jog stopped with no gain outside names what
    stopped it, and a gain within its tolerance over too little travel confirms nothing."""
    i = jog.i_total_rad_per_mm
    g = {x.ema: x for x in gains}
    off = [a for a in (1, 2) if g[a].agrees is False]  # outside the tolerance
    still = [a for a in (1, 2) if g[a].gain is None and g[a].motor_mm > jog.min_range_mm]  # never moved
    if not off and not still and stopped is None and all(g[a].agrees for a in (1, 2)):
        return JogVerdict(gains, (), (), False)
    hyps: list[Hypothesis] = []
    findings: list[Finding] = []
    if len(off) == 2 and _same(g[1], g[2]):
        r = math.copysign(math.sqrt(abs(g[1].gain * g[2].gain)), g[1].gain)
        findings.append(_shared(plan, i, r, g, hyps))
    elif len(still) == 2:
        findings.append(_still(plan, i, g, jog, hyps))
    else:
        bad = sorted(off + still)
        for a in bad:
            findings.append(_one(plan, a, g, hyps))
        if len(bad) == 1 and not stopped and _encoder(plan, bad[0])[1] is not None and g[3 - bad[0]].agrees:
            return JogVerdict(gains, tuple(hyps), (), False)  # the LVDT alone: judged in the move
    if stopped and not findings:
        findings.append(Finding(Stage.JOG, Kind.LIMIT, stopped_key, stopped))
    texts = "; ".join(f"EMA {x.ema}: " + (f"gain {x.gain:.4g} (1 +- {x.tolerance:.3f})" if x.gain is not None else
                                         f"LVDT moved {x.lvdt_mm:.3f} mm, motor {x.motor_mm:.3f} mm")
                      for x in gains)
    findings.append(Finding(Stage.JOG, Kind.STOP, "", f"nothing was loaded: the motion scale is not confirmed "
                            f"({texts})" + (f"; the jog was stopped: {stopped}" if stopped else "")))
    return JogVerdict(gains, tuple(hyps), tuple(findings), True)


def _same(a: JogGain, b: JogGain) -> bool:
    r"""Two gains of one factor: their ratio within the product of their relative bands,
    :math:`|\ln(g_1/g_2)| \le \ln(1 + e_1) + \ln(1 + e_2)` (symmetric in the two)."""
    return a.gain * b.gain > 0 and \
        abs(math.log(a.gain / b.gain)) <= math.log1p(a.rel_tolerance) + math.log1p(b.rel_tolerance)


def _shared(plan, i: float, r: float, g: dict, hyps: list) -> Finding:
    """Both EMAs by one factor r: the gear ratio (one key), else both LVDT scales (two keys) or both encoders."""
    lv = tuple(f"{ema_key(plan, a, Signal.LVDT)}.mm_per_unit" for a in (1, 2))
    gear = _gear(plan, i, r)
    hyps.append(gear)
    hyps.append(Hypothesis("both LVDT scales", lv, r, "; ".join(
        f"{k} = {_per_unit(plan, a) / r:.4g}" for a, k in zip((1, 2), lv, strict=True)) if all(
        _per_unit(plan, a) for a in (1, 2)) else None, True, "two keys wrong by the same factor"))
    enc = [_encoder(plan, a) for a in (1, 2)]
    both_enc = all(why is None for _, why in enc)
    hyps.append(Hypothesis("both encoder resolutions", tuple(k for k, _ in enc), r, None, both_enc,
                           "two keys wrong by the same factor" if both_enc else
                           "; ".join(f"EMA {a}: {why}" for a, (_, why) in zip((1, 2), enc, strict=True) if why)))
    tol = max(g[1].rel_tolerance, g[2].rel_tolerance)
    unit = unit_error(r, tol)
    seen = (f"the rams moved {r:.4g} times as far as the motors' angles over the profile's gear ratio say "
            f"(LVDT 1: {g[1].gain:.4g}, LVDT 2: {g[2].gain:.4g} mm per mm of motor travel, each to +- "
            f"{100 * tol:.0f} %)")
    if unit:
        seen += f": {unit}"
    also = [h for h in hyps[1:] if h.kept]
    if gear.kept:  # named as the hypotheses name it (kind gear ratio), with the fit's standard error
        se = gear_se(gear.fits, g[1].gain, g[2].gain)
        return Finding(Stage.JOG, Kind.GEAR, gear.keys[0], f"{gear.keys[0]}: {seen}; fits {gear.fits:.4g} rad/mm "
                       f"(standard error {se:.2g} rad/mm, from the two gains' spread); fits as well: "
                       + ", ".join(f"{h.name} ({', '.join(h.keys)})" for h in also), r, "mm/mm", gear.fits)
    first = also[0]
    return Finding(Stage.JOG, Kind.SCALE, ", ".join(first.keys), f"{seen}; not the gear ratio ({gear.why}); fits "
                   "equally: " + " or ".join(f"{h.name} ({', '.join(h.keys)})" for h in also), r, "mm/mm",
                   first.fits)


def gear_se(fits: float, g1: float, g2: float) -> float:
    r"""The standard error [rad/mm] of the gear ratio ``fits`` = :math:`i / \sqrt{g_1 g_2}` fitted to two jog gains.

    The fitted factor is the mean of the two log gains; their spread (the LVDTs' pitch errors, the play) is what
    the fit cannot remove, so the standard error of the mean of two, :math:`|\ln(g_1 / g_2)| / 2`, is that of
    :math:`\ln r`, and by the delta method :math:`\mathrm{SE}(i/r) = (i/r)\,|\ln(g_1/g_2)| / 2`. Two equal gains
    give 0: the spread is then below what the jog resolves (its tolerance says how far)."""
    return abs(fits) * abs(math.log(g1 / g2)) / 2.0


def _still(plan, i: float, g: dict, jog: JogPlan, hyps: list) -> Finding:
    """Neither LVDT left its noise while both motors moved: one shared factor below the LVDTs' travel over the
    motors' (the gear ratio, or both LVDT scales), no value fits."""
    bound = max(g[a].lvdt_mm / g[a].motor_mm for a in (1, 2))
    gear = _gear(plan, i, bound)
    gear = dataclasses.replace(gear, factor=None, fits=None)
    lv = tuple(f"{ema_key(plan, a, Signal.LVDT)}.mm_per_unit" for a in (1, 2))
    hyps += [gear, Hypothesis("both LVDT scales", lv, None, None, True, "two keys wrong by the same factor")]
    key = gear.keys[0] if gear.kept else ", ".join(lv)
    return Finding(Stage.JOG, Kind.STILL, key, f"{key}: neither LVDT moved more than {jog.engaged_mm:g} mm (its "
                   f"noise) while both motors moved {min(g[a].motor_mm for a in (1, 2)):.3f} mm over the gear "
                   f"ratio: the rams moved at most {bound:.3g} times as far as the profile's scale says "
                   f"({'the gear ratio' if gear.kept else 'not the gear ratio: ' + gear.why}; or both LVDT scales, "
                   f"or dead LVDTs); no value fits", bound, "mm/mm")


def _one(plan, a: int, g: dict, hyps: list) -> Finding:
    """EMA a alone: its LVDT scale, or its encoder resolution (the rams move together: the same prediction)."""
    x = g[a]
    lv = f"{ema_key(plan, a, Signal.LVDT)}.mm_per_unit"
    enc, why = _encoder(plan, a)
    if x.gain is None:
        text = (f"EMA {a}: its LVDT moved {x.lvdt_mm:.3f} mm while its motor moved {x.motor_mm:.3f} mm over the "
                f"gear ratio: too little to judge the scale (at least {x.range_mm:.3f} mm of motor travel after "
                f"the LVDT moved {x.lvdt_mm:.3f} mm)")
        keys = (lv,) if why is not None else (lv, enc)
        hyps.append(Hypothesis(f"LVDT {a}" + ("" if why is not None else " or its encoder resolution"), keys, None,
                               None, True, text if why is None else f"{text}; not the encoder resolution ({why})"))
        return Finding(Stage.JOG, Kind.STILL, ", ".join(keys), hyps[-1].why, x.lvdt_mm, "mm")
    r = x.gain
    per = _per_unit(plan, a)
    lv_fit = float(f"{per / r:.4g}") if per else None
    hyps.append(Hypothesis(f"LVDT {a} scale", (lv,), r, lv_fit, True, "one key explains EMA {a}; the other agrees"
                           .replace("{a}", str(a))))
    hyps.append(Hypothesis(f"encoder resolution of EMA {a}", (enc,), r, None, why is None,
                           why or "one key explains EMA {a}; the rams move together: LVDT and encoder predict the "
                                  "same".replace("{a}", str(a))))
    seen = (f"LVDT {a} reads {r:.4g} mm per mm of its motor's travel over the gear ratio (1 +- {x.tolerance:.3f})")
    kind = Kind.SIGN if r < 0 else Kind.SCALE
    if why is not None:
        return Finding(Stage.JOG, kind, lv, f"{lv}: {seen}; not the encoder resolution ({why})", r, "mm/mm", lv_fit)
    return Finding(Stage.JOG, kind, f"{lv}, {enc}", f"{seen}: the LVDT scale ({lv}, fits {lv_fit}) or the encoder "
                   f"resolution ({enc}, x {r:.4g}) fit equally: the rams move together, the jog cannot tell them "
                   f"apart", r, "mm/mm", lv_fit)


def _per_unit(plan, a: int) -> float | None:
    e = plan.map.entry(a, Signal.LVDT)
    return e.scale.si_per_unit if e is not None and e.scale is not None else None
