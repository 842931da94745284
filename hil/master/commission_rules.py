"""The commissioning's vocabulary and rules (pure): its stages, what a problem is (:class:`Finding`), the
motion limits (:class:`Limits`), and the judgements of the signals at rest and in motion, each a function of
arrays (samples in SI units) and the rig plan returning findings. The sequence that feeds them is
:mod:`hil.master.commission`; docs/commission.md gives every threshold with its reason.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import Enum

import numpy as np

from hil.canopen.signalmap import Signal
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE, Actuation, Check

__all__ = ["DEAD_FRACTION", "FORCE_GAIN_TOLERANCE", "MIN_MOTION_FRACTION", "MIN_STEP_MOTION_MM", "NOISE_FACTOR",
           "OPERATOR_KEY", "REST_S", "Finding", "Kind", "Limits", "Stage", "drives_swapped", "ema_key",
           "force_findings", "gain_se", "key_of", "keyed_stops", "lvdt_findings", "push_findings", "rest_findings",
           "slope", "slope_se", "swap_findings"]

#: The key of a stop by the operator (Ctrl-C): not a profile key, the person at the rig.
OPERATOR_KEY = "operator.interrupt"

#: Time both drives hold still while every signal is read at rest [s].
REST_S = 0.5
#: A measured noise above this many times the declared one is a finding.
NOISE_FACTOR = 4.0
#: A load cell's change against the drive's torque may differ from 1 by this much (the drive's torque
#: constant and the gear's efficiency; a wrong scale is a factor 2, 10 or 1000).
FORCE_GAIN_TOLERANCE = 0.25
#: A channel whose change is below this fraction of the expected one does not respond (a dead input: its
#: noise alone); above it, a wrong scale is named with the value that fits (down to a factor 50).
DEAD_FRACTION = 0.02
#: A move too small to judge a channel by: the motor angle moved less than this fraction of its target.
MIN_MOTION_FRACTION = 0.5
#: The LVDT swap is judged only if j's motor moved at least this much during the force step [mm].
MIN_STEP_MOTION_MM = 0.005


class Stage(Enum):
    """Where the commissioning is (its transitions: :data:`hil.master.commission.TRANSITIONS`)."""

    SCAN = "scan"
    PREFLIGHT = "preflight"
    AT_REST = "at rest"
    JOG = "jog"  #: the force-free jog (:mod:`hil.master.jog`)
    LOAD = "load"
    MOVE = "move"
    STEP = "force step"
    UNLOAD = "unload"
    DONE = "done"
    STOPPED = "stopped"


class Kind(Enum):
    """What is wrong."""

    ABSENT = "does not answer"
    ELSEWHERE = "answers at another node id"
    IDENTITY = "identity"
    PREFLIGHT = "preflight"
    DRILL = "master-loss drill"
    DEAD = "dead"
    RANGE = "out of range"
    NOISE = "noise"
    OFFSET = "offset"
    STILL = "did not move"
    SIGN = "sign"
    SCALE = "scale"
    SWAPPED = "swapped"
    GEAR = "gear ratio"
    UNIT = "unit error"
    WIRING = "wiring"
    SERIAL = "serial number"
    LIMIT = "commissioning limit"
    STOP = "stopped"
    NOT_SAFE = "not in Switch on disabled"


@dataclass(frozen=True, slots=True)
class Finding:
    """One problem, named with the profile key it concerns and, where one does, the value that would fit.

    ``measured`` is in the unit ``unit``; ``fits`` is the profile value that would make the measurement
    agree (None where no value can: a dead input, a drive that does not answer)."""

    stage: Stage
    kind: Kind
    key: str
    text: str
    measured: float | None = None
    unit: str = ""
    fits: float | int | str | None = None

    def as_json(self) -> dict:
        return {"stage": self.stage.value, "kind": self.kind.value, "key": self.key, "text": self.text,
                "measured": self.measured, "unit": self.unit, "fits": self.fits}


def keyed_stops(findings) -> list[Finding]:
    """``findings`` with every stop that names no key of its own (``nothing was moved``: the summary of a step that
    stopped the commissioning) given the keys of the problems that stopped it: those of its own stage found before
    it, else every problem before it (comma-separated, each once, in order). A stop with nothing before it keeps
    its empty key (nothing to name)."""
    import dataclasses

    out: list[Finding] = []
    for f in findings:
        if f.kind is Kind.STOP and not f.key:
            before = [x for x in out if x.kind is not Kind.STOP and x.key]
            mine = [x for x in before if x.stage is f.stage] or before
            f = dataclasses.replace(f, key=", ".join(dict.fromkeys(x.key for x in mine)))
        out.append(f)
    return out


@dataclass(frozen=True, slots=True)
class Limits:
    """The commissioning's motion, from the check profile and well below it.

    Attributes
    ----------
    force_N : float
        The force the holding EMA applies, then once more on the step: a quarter of
        ``calibration.opposing_force_N`` (at most twice this, half the check's opposing force) [N]; a
        rig without CST pushes until a load cell changed by this much.
    speed_mm_per_s : float
        A quarter of ``calibration.sweep_speed_mm_per_s`` [mm/s].
    travel_mm : float
        Out and back: a tenth of ``calibration.sweep_amplitude_mm``, at most 1 mm [mm].
    ramp_s, settle_s : float
        Force ramps, and the hold after each step [s]; the levels are averaged over the hold's second half
        (the load paths with the surface and the motors' reflected inertia ring at about 10 Hz, barely
        damped: a shorter hold biased the load-cell gains by 3 %).
    max_force_N : float
        Any load cell beyond this stops the movement: four times ``force_N`` (at most the check's
        ``safety.max_force_N``); over 1 + the jog's widest tolerance, the drives' own max torque 0x6072
        during commissioning (:func:`hil.master.jog_rules.commissioning_safety`) [N].
    max_travel_mm : float
        A motor angle farther than this from where it started stops the movement [mm].
    max_following_error_mm : float
        The check's ``safety.max_following_error_mm``: a motor angle that wanders more at rest [mm].
    push_mm : float
        A rig without CST: the longest push of one EMA against the other held [mm] (half the travel).
    """

    force_N: float
    speed_mm_per_s: float
    travel_mm: float
    ramp_s: float
    settle_s: float
    max_force_N: float
    max_travel_mm: float
    max_following_error_mm: float
    push_mm: float

    @classmethod
    def of(cls, check: Check) -> Limits:
        cal = check.calibration
        force = 0.25 * cal.opposing_force_N
        travel = min(1.0, 0.1 * cal.sweep_amplitude_mm)
        return cls(force_N=force, speed_mm_per_s=0.25 * cal.sweep_speed_mm_per_s, travel_mm=travel,
                   ramp_s=0.5, settle_s=0.6, max_force_N=min(4.0 * force, check.safety.max_force_N),
                   max_travel_mm=travel + 0.5, max_following_error_mm=check.safety.max_following_error_mm,
                   push_mm=0.5 * travel)

    def as_json(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


# ------------------------------------------------------------------ the rules


#: The profile tables a key of an error's message may start with.
_KEY = re.compile(r"\b((?:canopen|signals|safety|mechanics|sensors|timing|calibration|nodes)\.[A-Za-z0-9_]+"
                  r"(?:\.[A-Za-z0-9_]+)*)")


def key_of(text: str, default: str) -> str:
    """The first profile key an error's ``text`` names (``canopen.heartbeat_period_s``, ``safety.max_stale_cycles``),
    else ``default``: an error of the preflight or of the link still names the table it concerns."""
    m = _KEY.search(text)
    return m.group(1) if m else default


def ema_key(plan, ema: int, signal: Signal) -> str:
    """The profile key of EMA ``ema``'s ``signal`` (``signals.ema1.lvdt``)."""
    e = plan.map.entry(ema, signal)
    return e.key if e is not None else f"signals.ema{ema}.{signal.value}"


def rest_findings(x: dict[str, np.ndarray], act: Actuation, check: Check, lim: Limits, plan) -> list[Finding]:
    """Every LVDT and load cell at rest: alive, in range, noise as declared, load cells near zero; each motor
    angle still (both drives hold their position: a motor angle that wanders by more than
    ``safety.max_following_error_mm`` of stroke reads wrongly, or its drive does not hold).

    ``x``: the at-rest samples, arrays ``phi1, phi2`` [rad], ``s1, s2`` [mm] and ``F1, F2`` [N]."""
    out = []
    frozen_max = check.safety.max_frozen_cycles
    s_max = min(act.sensors.lvdt_full_scale_mm, act.mechanics.stroke_limit_mm)
    for ema in (1, 2):
        wander = float(np.ptp(x[f"phi{ema}"])) / act.mechanics.i_total_rad_per_mm
        if wander > lim.max_following_error_mm:
            key = ema_key(plan, ema, Signal.MOTOR_ANGLE)
            out.append(Finding(Stage.AT_REST, Kind.RANGE, key, f"{key}: moved {wander:.3f} mm of stroke while its "
                               f"drive held still (> safety.max_following_error_mm = {lim.max_following_error_mm:g})",
                               wander, "mm"))
        for sig, name, unit, noise, declared in (
                (Signal.LVDT, f"s{ema}", "mm", np.ptp(x[f"s{ema}"]), act.sensors.lvdt_noise_pp_mm),
                (Signal.FORCE, f"F{ema}", "N", np.std(x[f"F{ema}"]), act.sensors.loadcell_noise_std_N)):
            v = x[name]
            key = ema_key(plan, ema, sig)
            run = _longest_run(v)
            if run > frozen_max:
                out.append(Finding(Stage.AT_REST, Kind.DEAD, key, f"{key}: dead or frozen: the same value "
                                   f"{v[0]:.6g} {unit} for {run} cycles at rest (> safety.max_frozen_cycles = "
                                   f"{frozen_max}): check the wiring (no scaling fits)", float(v[0]), unit))
                continue
            what = "peak to peak" if sig is Signal.LVDT else "standard deviation"
            decl_key = "sensors.lvdt_noise_pp_mm" if sig is Signal.LVDT else "sensors.loadcell_noise_std_N"
            if noise > NOISE_FACTOR * declared:
                out.append(Finding(Stage.AT_REST, Kind.NOISE, decl_key, f"{key}: noise {noise:.4g} {unit} {what} "
                                   f"at rest > {NOISE_FACTOR:g} x {decl_key} = {declared:g}", float(noise), unit,
                                   float(f"{noise:.3g}")))
            mean = float(np.mean(v))
            if sig is Signal.LVDT and abs(mean) > s_max:
                out.append(Finding(Stage.AT_REST, Kind.RANGE, key, f"{key}: {mean:.3f} mm at rest, beyond the "
                                   f"stroke range +-{s_max:g} mm", mean, unit))
            if sig is Signal.FORCE and abs(mean) > lim.force_N:
                off = _entry_offset(plan, ema, sig)
                out.append(Finding(Stage.AT_REST, Kind.OFFSET, f"{key}.offset_N", f"{key}: {mean:.0f} N at rest "
                                   f"with no load (> {lim.force_N:g} N)", mean, unit, round(off - mean, 1)))
    return out


def _longest_run(v: np.ndarray) -> int:
    """The longest run of one value repeated in consecutive samples (1: none repeated)."""
    if v.size == 0:
        return 0
    change = np.flatnonzero(np.diff(v) != 0)
    edges = np.concatenate(([-1], change, [v.size - 1]))
    return int(np.max(np.diff(edges)))


def _entry_offset(plan, ema: int, sig: Signal) -> float:
    e = plan.map.entry(ema, sig)
    return e.scale.offset if e is not None and e.scale is not None else 0.0


def _per_unit(plan, ema: int, sig: Signal) -> float | None:
    e = plan.map.entry(ema, sig)
    return e.scale.si_per_unit if e is not None and e.scale is not None else None


def slope(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope of ``y`` on ``x`` (with an intercept)."""
    xc = x - x.mean()
    den = float(np.dot(xc, xc))
    return float(np.dot(xc, y - y.mean()) / den) if den > 0 else math.nan


def slope_se(x: np.ndarray, y: np.ndarray) -> float:
    r"""Standard error of :func:`slope`: :math:`\sqrt{\sum e^2 / (n - 2) / \sum (x - \bar x)^2}` (the residuals
    taken as independent) [unit of y per unit of x]; NaN below 3 samples."""
    xc = x - x.mean()
    den = float(np.dot(xc, xc))
    if x.size < 3 or den <= 0:
        return math.nan
    b = float(np.dot(xc, y - y.mean()) / den)
    e = (y - y.mean()) - b * xc
    return math.sqrt(float(np.dot(e, e)) / (x.size - 2) / den)


def gain_se(x: dict[str, np.ndarray], k: int, i_total: float, before: dict, after: dict, dF: float,
            n: int) -> dict[str, float]:
    """Standard errors of the gains of EMA ``k``'s turn: each LVDT's slope on its motor's travel in the move
    (``x``: the move's arrays), and each load cell's change over the force step ``dF`` [N] from the two
    holds' standard deviations ``before``/``after`` over ``n`` samples each (as if independent: the ringing
    left in the holds makes the true one larger)."""
    out = {f"lvdt{a}_ema{k}_moving": slope_se(x[f"phi{a}"] / i_total, x[f"s{a}"]) for a in (1, 2)}
    for a in (1, 2):
        out[f"force{a}_ema{3 - k}_pushing"] = math.hypot(before[f"F{a}"], after[f"F{a}"]) / math.sqrt(n) / abs(dF)
    return out


def lvdt_findings(x: dict[str, np.ndarray], k: int, act: Actuation, lim: Limits, plan) -> tuple[list[Finding], dict]:
    """EMA ``k`` moved (the other followed in CST): each LVDT against its motor angle over the gear ratio.

    The gain :math:`g_a` is the slope of :math:`s_a` on :math:`\\varphi_a / i` [mm/mm]; it must be within
    ``HARD_LVDT_GAIN_TOLERANCE`` of +1. The fitting scale is ``mm_per_unit / g``."""
    out, gains = [], {}
    i = act.mechanics.i_total_rad_per_mm
    for a in (1, 2):
        xa = x[f"phi{a}"] / i
        moved = float(np.ptp(xa))
        key = ema_key(plan, a, Signal.LVDT)
        if moved < MIN_MOTION_FRACTION * lim.travel_mm:
            if a == k:
                out.append(Finding(Stage.MOVE, Kind.STILL, ema_key(plan, a, Signal.MOTOR_ANGLE),
                                   f"EMA {a} was told to move {lim.travel_mm:g} mm; its motor angle moved "
                                   f"{moved:.3f} mm", moved, "mm"))
            continue
        g = slope(xa, x[f"s{a}"])
        gains[f"ema{a}"] = g
        per = _per_unit(plan, a, Signal.LVDT)
        fits = None if per is None or not g else float(f"{per / g:.4g}")
        if not abs(g) >= DEAD_FRACTION:
            out.append(Finding(Stage.MOVE, Kind.DEAD, key, f"{key}: does not follow EMA {a}'s motor ({moved:.3f} mm "
                               f"moved, the LVDT {float(np.ptp(x[f's{a}'])):.4f} mm)", g))
        elif g < 0:
            out.append(Finding(Stage.MOVE, Kind.SIGN, f"{key}.mm_per_unit", f"{key}: wrong sign: {g:+.3f} mm per mm "
                               f"of motor travel (the ram extends with the motor angle)", g, "mm/mm", fits))
        elif abs(g - 1.0) > HARD_LVDT_GAIN_TOLERANCE:
            out.append(Finding(Stage.MOVE, Kind.SCALE, f"{key}.mm_per_unit", f"{key}: reads {g:.3f} mm per mm of "
                               f"motor travel (1 +- {HARD_LVDT_GAIN_TOLERANCE:g} expected)", g, "mm/mm", fits))
    return out, gains


def force_findings(before: dict[str, float], after: dict[str, float], j: int, dF: float,
                   plan) -> tuple[list[Finding], dict]:
    """EMA ``j``'s force stepped by ``dF`` [N] in CST, the other holding: load cell j must change by +dF,
    the other by -dF (their sum is the surface's load, zero), each within :data:`FORCE_GAIN_TOLERANCE`.
    ``before``/``after``: mean ``F1``, ``F2`` [N] of the two holds."""
    out, gains = [], {}
    for a, want in ((j, 1.0), (3 - j, -1.0)):
        g = (after[f"F{a}"] - before[f"F{a}"]) / dF
        gains[f"ema{a}"] = g
        key = ema_key(plan, a, Signal.FORCE)
        per = _per_unit(plan, a, Signal.FORCE)
        rel = g / want
        fits = None if per is None or not g else float(f"{per / rel:.4g}")
        text = f"{key}: changed by {g * dF:+.0f} N when EMA {j}'s torque changed the force by {dF:+.0f} N " \
               f"(expected {want * dF:+.0f} N)"
        if not abs(rel) >= DEAD_FRACTION:
            out.append(Finding(Stage.STEP, Kind.DEAD, key, text + ": it does not respond", rel))
        elif rel < 0:
            out.append(Finding(Stage.STEP, Kind.SIGN, f"{key}.N_per_unit", text + ": wrong sign", rel, "", fits))
        elif abs(rel - 1.0) > FORCE_GAIN_TOLERANCE:
            out.append(Finding(Stage.STEP, Kind.SCALE, f"{key}.N_per_unit", text + f": gain {rel:.3f} "
                               f"(1 +- {FORCE_GAIN_TOLERANCE:g})", rel, "", fits))
    return out, gains


def push_findings(before: dict[str, float], after: dict[str, float], k: int, force_N: float,
                  plan) -> tuple[list[Finding], dict]:
    r"""EMA ``k`` pushed (extended) against the other EMA j held, both in CSP (a rig without CST: no torque to
    compare with): load cell k must go into compression (+), load cell j into tension (-), and by the same
    amount (the surface is free: :math:`\Delta F_1 + \Delta F_2 = 0`) within :data:`FORCE_GAIN_TOLERANCE`;
    below :data:`DEAD_FRACTION` of the larger change a load cell is dead. A wrong sign fits ``-N_per_unit``;
    which of two disagreeing load cells is wrong cannot be told (no value fits). ``before``/``after``: mean
    ``F1``, ``F2`` [N]."""
    j = 3 - k
    d = {k: after[f"F{k}"] - before[f"F{k}"], j: after[f"F{j}"] - before[f"F{j}"]}
    big = max(abs(d[k]), abs(d[j]))
    out = []
    if big < DEAD_FRACTION * force_N:
        return [Finding(Stage.STEP, Kind.DEAD, f"{ema_key(plan, 1, Signal.FORCE)}, {ema_key(plan, 2, Signal.FORCE)}",
                        f"neither load cell changed when EMA {k} pushed against EMA {j} (by {d[k]:+.0f} N and "
                        f"{d[j]:+.0f} N)")], {f"ema{a}": v for a, v in d.items()}
    for a, want in ((k, 1.0), (j, -1.0)):
        key = ema_key(plan, a, Signal.FORCE)
        text = f"{key}: changed by {d[a]:+.0f} N when EMA {k} pushed against EMA {j} (expected " \
               f"{'compression, +' if want > 0 else 'tension, -'})"
        per = _per_unit(plan, a, Signal.FORCE)
        if abs(d[a]) < DEAD_FRACTION * big:
            out.append(Finding(Stage.STEP, Kind.DEAD, key, text + ": it does not respond", d[a], "N"))
        elif d[a] * want < 0:
            out.append(Finding(Stage.STEP, Kind.SIGN, f"{key}.N_per_unit", text + ": wrong sign", d[a], "N",
                               None if per is None else -per))
    if not out:
        ratio = -d[j] / d[k]
        if abs(ratio - 1.0) > FORCE_GAIN_TOLERANCE:
            out.append(Finding(Stage.STEP, Kind.SCALE, f"{ema_key(plan, 1, Signal.FORCE)}.N_per_unit, "
                               f"{ema_key(plan, 2, Signal.FORCE)}.N_per_unit",
                               f"the load cells disagree: load cell {j} changed {ratio:.3f} times as much as load "
                               f"cell {k} (1 +- {FORCE_GAIN_TOLERANCE:g}); one of the scalings is wrong", ratio))
    return out, {f"ema{a}": v for a, v in d.items()}


def swap_findings(follows: dict[int, tuple[float, float, float]], plan, gains: dict | None = None) -> list[Finding]:
    """``follows[j] = (dx_j, ds_j, ds_k)``: in EMA j's force step its motor moved ``dx_j`` [mm], LVDT j
    ``ds_j`` and the other LVDT ``ds_k``, each divided by its gain measured in motion (``gains``:
    ``{1: g1, 2: g2}``, so that a wrong scale does not look like a swap). LVDT j must move more than the
    other; if in both steps the other moved more, the LVDTs are swapped (each fits the other's object)."""
    g = {1: 1.0, 2: 1.0} | {a: abs(v) for a, v in (gains or {}).items() if v and math.isfinite(v)}
    judged = {j: abs(v[2]) / g[3 - j] > abs(v[1]) / g[j] for j, v in follows.items()
              if abs(v[0]) >= MIN_STEP_MOTION_MM}
    if not judged or not any(judged.values()):
        return []
    e1, e2 = plan.map.entry(1, Signal.LVDT), plan.map.entry(2, Signal.LVDT)
    if len(judged) == 2 and all(judged.values()):
        return [Finding(Stage.STEP, Kind.SWAPPED, f"{e1.key}, {e2.key}",
                        f"{e1.key} ({e1.where}) follows EMA 2 and {e2.key} ({e2.where}) EMA 1: the LVDTs are "
                        f"swapped", fits=f"{e1.key} = {e2.where}; {e2.key} = {e1.where}")]
    j = next(j for j, sw in judged.items() if sw)
    dx, ds_j, ds_k = follows[j]
    key = ema_key(plan, j, Signal.LVDT)
    return [Finding(Stage.STEP, Kind.SWAPPED, key, f"when EMA {j}'s motor moved {dx:.4f} mm, {key} moved "
                    f"{ds_j:.4f} mm and the other LVDT {ds_k:.4f} mm: swapped or misplaced?")]


def drives_swapped(findings: list[Finding], plan) -> list[Finding]:
    """With the sensors on a node of their own, the two drives at each other's node id show as the LVDTs
    swapped and both load cells of the wrong sign (each pushing drive moves and loads the other EMA's
    sensors): those three findings become one, naming the node ids and the values that fit."""
    lvdts = [f for f in findings if f.kind is Kind.SWAPPED and ", " in f.key]
    signs = [f for f in findings if f.kind is Kind.SIGN and f.key.endswith(".force.N_per_unit")]
    drives = {"ema1", "ema2"}
    on_node = all(e.node not in drives for e in plan.map.entries if e.signal in (Signal.LVDT, Signal.FORCE))
    if not (lvdts and len(signs) == 2 and on_node):
        return findings
    n1, n2 = (d.node.spec.node_id for d in plan.drives)
    merged = Finding(Stage.STEP, Kind.SWAPPED, "canopen.node_id_ema1, canopen.node_id_ema2",
                     f"the drive at node {n1} moves EMA 2's sensors and the drive at node {n2} EMA 1's (the LVDTs "
                     f"follow the other drive, both load cells read the other way): the drives are at each other's "
                     f"node id", fits=f"canopen.node_id_ema1 = {n2}; canopen.node_id_ema2 = {n1}")
    drop = {id(f) for f in (*lvdts, *signs)}
    return [f for f in findings if id(f) not in drop] + [merged]
