"""Commissioning a rig before its first check (sans-IO core of ``emacheck commission``).

Fed frames, samples and a time value, returning setpoints and :class:`Finding` s; it never touches a
bus, a clock or a file (the IO shell is :mod:`hil.cli.commission`, over :mod:`hil.master.link`).

1. **Scan** (:class:`Scan`, a generator of the preflight's requests run by the master core before the
   preflight): NMT reset node, a bounded wait in which every boot-up and heartbeat is heard
   (:meth:`Commission.heard`), then per node of the profile its device type 0x1000 and identity
   0x1018 by SDO (a timeout: the node does not answer); every disagreement with the profile is a
   finding (:func:`hil.master.preflight.identity_problems`, the preflight's own comparison). Any
   finding stops here: nothing is powered.
2. **The preflight** as the check runs it (:class:`hil.master.preflight.Preflight`: identity again,
   configuration, the drive limits, the master's-death drill); its error is a finding.
3. **At rest** (both drives holding their position in CSP, :data:`REST_S`): every LVDT and load
   cell alive (not one value repeated for more than ``safety.max_frozen_cycles``), within range, its
   noise within :data:`NOISE_FACTOR` times the declared noise, the load cells near zero. A finding
   stops here: nothing moves.
4. **Movement**, EMA k in turn (j the other): j holds a small force in CST (:class:`Limits`: a
   quarter of the check's opposing force), k moves ``travel_mm`` out and back at a quarter of the
   check's sweep speed: each LVDT regressed on its motor angle over the gear ratio (slope 1 within
   the supervisor's LVDT pitch tolerance); then j's force steps up by the same amount: each load
   cell's change against j's torque (+1 for j, -1 for k, within :data:`FORCE_GAIN_TOLERANCE`), and
   which LVDT follows j's motor (LVDT j, else the two are swapped).
5. **End**: both drives disabled (the shell confirms Switch on disabled).

States are :class:`Stage` values, their transitions :data:`TRANSITIONS`.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from hil.canopen.cia402 import decode_state
from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.sdo import SdoAbortError, SdoTimeout
from hil.canopen.signalmap import ForceControl, NodeRole, Signal
from hil.errors import EmacheckError
from hil.master.preflight import MasterLossReactionError, Nmt, Now, PreflightError, SdoRead, Wait, identity_problems
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE, Actuation, Check

__all__ = ["Commission", "CommissionStop", "Finding", "Kind", "Limits", "Scan", "Stage", "TRANSITIONS"]

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
    SCAN = "scan"
    PREFLIGHT = "preflight"
    AT_REST = "at rest"
    LOAD = "load"
    MOVE = "move"
    STEP = "force step"
    UNLOAD = "unload"
    DONE = "done"
    STOPPED = "stopped"


#: The commissioning's transitions (an illegal one raises).
TRANSITIONS: dict[Stage, frozenset[Stage]] = {
    Stage.SCAN: frozenset({Stage.PREFLIGHT, Stage.STOPPED}),
    Stage.PREFLIGHT: frozenset({Stage.AT_REST, Stage.STOPPED}),
    Stage.AT_REST: frozenset({Stage.LOAD, Stage.STOPPED}),
    Stage.LOAD: frozenset({Stage.MOVE, Stage.STOPPED}),
    Stage.MOVE: frozenset({Stage.STEP, Stage.STOPPED}),
    Stage.STEP: frozenset({Stage.UNLOAD, Stage.STOPPED}),
    Stage.UNLOAD: frozenset({Stage.LOAD, Stage.DONE, Stage.STOPPED}),
    Stage.DONE: frozenset(),
    Stage.STOPPED: frozenset(),
}


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
    LIMIT = "commissioning limit"
    STOP = "stopped"
    NOT_SAFE = "not in Switch on disabled"


class CommissionStop(PreflightError):
    """The scan found problems: the commissioning stops before anything is powered."""


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


@dataclass(frozen=True, slots=True)
class Limits:
    """The commissioning's motion, from the check profile and well below it.

    Attributes
    ----------
    force_N : float
        The force the holding EMA applies, then once more on the step: a quarter of
        ``calibration.opposing_force_N`` (at most twice this, half the check's opposing force) [N].
    speed_mm_per_s : float
        A quarter of ``calibration.sweep_speed_mm_per_s`` [mm/s].
    travel_mm : float
        Out and back: a tenth of ``calibration.sweep_amplitude_mm``, at most 1 mm [mm].
    ramp_s, settle_s : float
        Force ramps, and the hold after each step [s]; the levels are averaged over the hold's second half
        (the surface on its load paths rings at about 25 Hz, barely damped: a shorter hold biased the
        load-cell gains by 3 %).
    max_force_N : float
        Any load cell beyond this stops the movement: four times ``force_N`` (at most the check's
        ``safety.max_force_N``); also the drives' own max torque 0x6072 during commissioning [N].
    max_travel_mm : float
        A motor angle farther than this from where it started stops the movement [mm].
    """

    force_N: float
    speed_mm_per_s: float
    travel_mm: float
    ramp_s: float
    settle_s: float
    max_force_N: float
    max_travel_mm: float
    max_following_error_mm: float

    @classmethod
    def of(cls, check: Check) -> Limits:
        cal = check.calibration
        force = 0.25 * cal.opposing_force_N
        travel = min(1.0, 0.1 * cal.sweep_amplitude_mm)
        return cls(force_N=force, speed_mm_per_s=0.25 * cal.sweep_speed_mm_per_s, travel_mm=travel,
                   ramp_s=0.5, settle_s=0.6, max_force_N=min(4.0 * force, check.safety.max_force_N),
                   max_travel_mm=travel + 0.5, max_following_error_mm=check.safety.max_following_error_mm)

    def as_json(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


def _node_id_key(spec) -> str:
    return f"canopen.node_id_{spec.name}" if spec.key == "canopen" else f"{spec.key}.node_id"


# ------------------------------------------------------------------ the scan


class Scan:
    """Which node ids answer, and whether each node of the profile is what the profile says."""

    def __init__(self, plan, wait_s: float, master_node_id: int) -> None:
        self.plan = plan
        self.wait_s = wait_s
        self.master_node_id = master_node_id
        self.heard: set[int] = set()  #: node ids heard (boot-up or heartbeat)
        self.nodes: dict[int, dict] = {}  #: per node id of the profile: what was read
        self.findings: list[Finding] = []

    def hear(self, frame: Frame) -> None:
        cid = frame.arbitration_id
        if 0x701 <= cid <= 0x77F and len(frame.data) == 1 and cid - 0x700 != self.master_node_id:
            self.heard.add(cid - 0x700)

    def run(self) -> Generator:
        """The scan as the preflight's requests; raises :class:`CommissionStop` with any finding."""
        yield Nmt(NmtCommand.RESET_NODE)
        yield Wait((yield Now()) + self.wait_s)
        for node in self.plan.nodes:
            yield from self._node(node)
        if self.findings:
            raise CommissionStop(f"the scan found {len(self.findings)} problem(s): "
                                 + "; ".join(f.text for f in self.findings))

    def _node(self, node) -> Generator:
        spec = node.spec
        nid = spec.node_id
        got: dict = {"node": nid, "heard": nid in self.heard}
        self.nodes[nid] = got
        devtype = yield SdoRead(nid, 0x1000, 0, "device type", soft=True)
        if isinstance(devtype, (SdoTimeout, SdoAbortError)):
            got["answers"] = False
            ours = {n.spec.node_id for n in self.plan.nodes}
            others = sorted(self.heard - ours)
            fits = others[0] if len(others) == 1 else None
            where = f"; node id {others[0]} answers and is not in the profile" if fits is not None else (
                f"; node ids not in the profile that answer: {others}" if others else "")
            self.findings.append(Finding(Stage.SCAN, Kind.ABSENT if fits is None else Kind.ELSEWHERE,
                                         _node_id_key(spec), f"{spec.label} does not answer (SDO 0x1000: "
                                         f"{type(devtype).__name__}){where}", fits=fits))
            return
        got["answers"] = True
        got["device_type"] = int.from_bytes(bytes(devtype[:4]), "little")
        ident = {}
        for sub, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"), (4, "serial")):
            v = yield SdoRead(nid, 0x1018, sub, key.replace("_", " "), soft=True)
            ident[key] = None if isinstance(v, (SdoTimeout, SdoAbortError)) else int.from_bytes(bytes(v[:4]), "little")
        got["identity"] = ident
        if spec.role is NodeRole.DRIVE:  # its state before anything is powered
            sw = yield SdoRead(nid, 0x6041, 0, "statusword", soft=True)
            if not isinstance(sw, (SdoTimeout, SdoAbortError)):
                got["state"] = decode_state(int.from_bytes(bytes(sw[:2]), "little")).name
        if None in (ident["vendor_id"], ident["product_code"], ident["revision"]):
            self.findings.append(Finding(Stage.SCAN, Kind.IDENTITY, spec.key, f"{spec.label}: identity 0x1018 "
                                         f"not readable ({ident})"))
            return
        for problem in identity_problems(spec, ident, got["device_type"]):
            if "device type" in problem:
                key, fits = f"{spec.key}.device_profile", got["device_type"] & 0xFFFF
            elif "revision" in problem and "below" in problem:
                key, fits = f"{spec.key}.revision_min", f"0x{ident['revision']:08X}"
            elif ident["vendor_id"] != spec.vendor_id:
                key, fits = f"{spec.key}.vendor_id", f"0x{ident['vendor_id']:08X}"
            else:
                key, fits = f"{spec.key}.product_code", f"0x{ident['product_code']:08X}"
            self.findings.append(Finding(Stage.SCAN, Kind.IDENTITY, key, problem, fits=fits))


# ------------------------------------------------------------------ evaluation (pure)


def _ema_key(plan, ema: int, signal: Signal) -> str:
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
            key = _ema_key(plan, ema, Signal.MOTOR_ANGLE)
            out.append(Finding(Stage.AT_REST, Kind.RANGE, key, f"{key}: moved {wander:.3f} mm of stroke while its "
                               f"drive held still (> safety.max_following_error_mm = {lim.max_following_error_mm:g})",
                               wander, "mm"))
        for sig, name, unit, noise, declared in (
                (Signal.LVDT, f"s{ema}", "mm", np.ptp(x[f"s{ema}"]), act.sensors.lvdt_noise_pp_mm),
                (Signal.FORCE, f"F{ema}", "N", np.std(x[f"F{ema}"]), act.sensors.loadcell_noise_std_N)):
            v = x[name]
            key = _ema_key(plan, ema, sig)
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


def lvdt_findings(x: dict[str, np.ndarray], k: int, act: Actuation, lim: Limits, plan) -> tuple[list[Finding], dict]:
    """EMA ``k`` moved (the other followed in CST): each LVDT against its motor angle over the gear ratio.

    The gain :math:`g_a` is the slope of :math:`s_a` on :math:`\\varphi_a / i` [mm/mm]; it must be within
    ``HARD_LVDT_GAIN_TOLERANCE`` of +1. The fitting scale is ``mm_per_unit / g``."""
    out, gains = [], {}
    i = act.mechanics.i_total_rad_per_mm
    for a in (1, 2):
        xa = x[f"phi{a}"] / i
        moved = float(np.ptp(xa))
        key = _ema_key(plan, a, Signal.LVDT)
        if moved < MIN_MOTION_FRACTION * lim.travel_mm:
            if a == k:
                out.append(Finding(Stage.MOVE, Kind.STILL, _ema_key(plan, a, Signal.MOTOR_ANGLE),
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
        key = _ema_key(plan, a, Signal.FORCE)
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
    key = _ema_key(plan, j, Signal.LVDT)
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


# ------------------------------------------------------------------ the cyclic core


@dataclass
class _Record:
    t: list = field(default_factory=list)
    rows: list = field(default_factory=list)

    def add(self, smp: Sample) -> None:
        self.rows.append((smp.phi1_rad, smp.phi2_rad, smp.s1_mm, smp.s2_mm, smp.F1_N, smp.F2_N))

    def arrays(self, last: int | None = None) -> dict[str, np.ndarray]:
        a = np.asarray(self.rows[-last:] if last else self.rows, dtype=float).reshape(-1, 6)
        return {n: a[:, c] for c, n in enumerate(("phi1", "phi2", "s1", "s2", "F1", "F2"))}


class Commission:
    """The commissioning core (see the module docstring): :meth:`steps` for the master core before the
    cyclic phase, :meth:`step` once per sample after it.

    Parameters
    ----------
    actuation, check : the validated profiles (the motion limits from ``check``: :class:`Limits`)
    plan : hil.canopen.plan.RigPlan
    """

    def __init__(self, actuation: Actuation, check: Check, plan) -> None:
        self.act, self.check, self.plan = actuation, check, plan
        self.lim = Limits.of(check)
        self.i = actuation.mechanics.i_total_rad_per_mm
        self.T = actuation.timing.sync_period_s
        c = actuation.canopen
        self.scan = Scan(plan, c.boot_timeout_s, c.master_node_id)
        self.stage = Stage.SCAN
        self.stopped_at: Stage | None = None  #: where an error stopped it (SCAN: nothing was powered)
        self.findings: list[Finding] = []
        self.ema = 1  #: the EMA that moves (the other holds the force)
        self.measured: dict = {"lvdt_gain": {}, "loadcell_gain": {}, "lvdt_follows": {}, "at_rest": {}}
        self._t0 = 0.0  #: the stage's start [s]
        self._start: tuple[float, float] | None = None  #: motor angles at rest [rad]
        self._hold: float | None = None  #: the holding EMA's angle once it is back in CSP [rad]
        self._rec = _Record()
        self._level: dict[str, float] = {}  #: mean forces / strokes / angles at the end of MOVE
        self._t = 0.0

    @property
    def done(self) -> bool:
        return self.stage in (Stage.DONE, Stage.STOPPED)

    @property
    def force_in_cst(self) -> bool:
        return all(d.force_control is ForceControl.CST for d in self.plan.drives)

    def heard(self, frame: Frame) -> None:
        """Every frame the master is fed, during the scan (boot-ups and heartbeats of any node id)."""
        if self.stage is Stage.SCAN:
            self.scan.hear(frame)

    def steps(self, preflight) -> Generator:
        """The scan, then the check's preflight (``preflight``: the master core's), as one generator."""
        yield from self.scan.run()
        self._goto(Stage.PREFLIGHT, 0.0)
        yield from preflight.run()

    def _add(self, found: list[Finding]) -> None:
        """Findings of a movement, each problem once (both movements see a wrong LVDT or load cell: the
        first names it)."""
        seen = {(f.kind, f.key) for f in self.findings}
        self.findings += [f for f in found if (f.kind, f.key) not in seen]

    def _goto(self, new: Stage, t: float) -> None:
        if new not in TRANSITIONS[self.stage]:
            raise EmacheckError(f"commissioning: no transition {self.stage.value} -> {new.value}")
        self.stage, self._t0 = new, t
        self._rec = _Record()

    def failed(self, exc: BaseException) -> None:
        """An error ended the commissioning (the scan's, the preflight's or the drill's, the link's): its
        findings, or the error itself as one; then stopped."""
        self.stopped_at = self.stage
        if isinstance(exc, CommissionStop):
            self.findings += self.scan.findings
        elif isinstance(exc, MasterLossReactionError):
            self.findings.append(Finding(Stage.PREFLIGHT, Kind.DRILL, "canopen.external_watchdog", str(exc)))
        elif isinstance(exc, KeyboardInterrupt):
            self.findings.append(Finding(self.stage, Kind.STOP, "", "interrupted by the operator"))
        else:
            stage = self.stage if self.stage is not Stage.STOPPED else Stage.PREFLIGHT
            kind = Kind.PREFLIGHT if stage in (Stage.SCAN, Stage.PREFLIGHT) else Kind.STOP
            self.findings.append(Finding(stage, kind, "", f"{type(exc).__name__}: {exc}"))
        self.stage = Stage.STOPPED

    # ------------------------------------------------------------ the cyclic phase

    def step(self, smp: Sample) -> tuple[Setpoint, Setpoint]:
        """One sample in, the two drives' setpoints for the next cycle out."""
        t = self._t = smp.t_s
        if self._start is None:
            self._start = (smp.phi1_rad, smp.phi2_rad)
            self._goto(Stage.AT_REST, t)
        if self.done:
            return _DISABLED, _DISABLED
        if self.stage is not Stage.AT_REST and (why := self._guard(smp)):
            self.findings.append(Finding(self.stage, Kind.LIMIT, why[0], why[1]))
            self.stage = Stage.STOPPED
            return _DISABLED, _DISABLED
        self._rec.add(smp)
        tau = t - self._t0
        if tau >= self._duration():
            self._end_of_stage(smp)
            if self.done:
                return _DISABLED, _DISABLED
            tau = 0.0
        return self._setpoints(tau, smp)

    def _duration(self) -> float:
        lim = self.lim
        return {Stage.AT_REST: REST_S, Stage.LOAD: lim.ramp_s + lim.settle_s,
                Stage.MOVE: 2 * lim.travel_mm / lim.speed_mm_per_s + 2 * lim.settle_s,
                Stage.STEP: lim.ramp_s + lim.settle_s, Stage.UNLOAD: lim.ramp_s + lim.settle_s}[self.stage]

    def _setpoints(self, tau: float, smp: Sample) -> tuple[Setpoint, Setpoint]:
        k, lim = self.ema, self.lim
        j = 3 - k
        start = self._start
        hold_k = Setpoint(DriveMode.POSITION, start[k - 1])
        ramp = min(1.0, tau / lim.ramp_s)
        if self.stage is Stage.AT_REST:
            sp = {1: Setpoint(DriveMode.POSITION, start[0]), 2: Setpoint(DriveMode.POSITION, start[1])}
            return sp[1], sp[2]
        if self.stage is Stage.LOAD:
            sp = {k: hold_k, j: Setpoint(DriveMode.FORCE, lim.force_N * ramp)}
        elif self.stage is Stage.MOVE:
            sp = {k: Setpoint(DriveMode.POSITION, start[k - 1] + self.i * self._excursion(tau)),
                  j: Setpoint(DriveMode.FORCE, lim.force_N)}
        elif self.stage is Stage.STEP:
            sp = {k: hold_k, j: Setpoint(DriveMode.FORCE, lim.force_N * (1.0 + ramp))}
        else:  # UNLOAD: the force off, then j holds where it is in CSP
            if tau < lim.ramp_s:
                sp = {k: hold_k, j: Setpoint(DriveMode.FORCE, 2.0 * lim.force_N * (1.0 - ramp))}
            else:
                if self._hold is None:
                    self._hold = smp.phi1_rad if j == 1 else smp.phi2_rad
                sp = {k: hold_k, j: Setpoint(DriveMode.POSITION, self._hold)}
        return sp[1], sp[2]

    def _excursion(self, tau: float) -> float:
        """Out ``travel_mm`` at ``speed``, hold, back, hold [mm of stroke]."""
        lim = self.lim
        tm = lim.travel_mm / lim.speed_mm_per_s
        if tau < tm:
            return lim.speed_mm_per_s * tau
        if tau < tm + lim.settle_s:
            return lim.travel_mm
        return max(0.0, lim.travel_mm - lim.speed_mm_per_s * (tau - tm - lim.settle_s))

    def _guard(self, smp: Sample) -> tuple[str, str] | None:
        """The commissioning's own limits (the drives keep a max torque of ``max_force_N`` besides)."""
        lim = self.lim
        for a, f in ((1, smp.F1_N), (2, smp.F2_N)):
            if abs(f) > lim.max_force_N:
                return (_ema_key(self.plan, a, Signal.FORCE),
                        f"load cell {a} read {f:.0f} N > {lim.max_force_N:g} N (the commissioning's force limit): "
                        f"movement stopped (a wrong scale of that load cell reads high)")
        for a, phi in ((1, smp.phi1_rad), (2, smp.phi2_rad)):
            away = abs(phi - self._start[a - 1]) / self.i
            if away > lim.max_travel_mm:
                return (_ema_key(self.plan, a, Signal.MOTOR_ANGLE),
                        f"EMA {a}'s motor angle moved {away:.2f} mm from where it started > {lim.max_travel_mm:g} mm: "
                        f"movement stopped")
        return None

    def _end_of_stage(self, smp: Sample) -> None:
        t, k = smp.t_s, self.ema
        n_hold = max(1, int(self.lim.settle_s / 2 / self.T))
        if self.stage is Stage.AT_REST:
            x = self._rec.arrays()
            self.measured["at_rest"] = {n: {"mean": float(np.mean(v)), "ptp": float(np.ptp(v)),
                                            "std": float(np.std(v))} for n, v in x.items()}
            found = rest_findings(x, self.act, self.check, self.lim, self.plan)
            self.findings += found
            if found:
                self.findings.append(Finding(Stage.AT_REST, Kind.STOP, "", "nothing was moved: a signal at rest "
                                             "is wrong"))
            if found or not self.force_in_cst:
                if not found:
                    self.findings.append(Finding(Stage.AT_REST, Kind.STOP, "canopen.force_control",
                                                 "movement checks need both drives in CST (the holding EMA's "
                                                 "force); this rig holds forces in CSP: not checked"))
                self.stage = Stage.STOPPED
                return
            self._goto(Stage.LOAD, t)
        elif self.stage is Stage.LOAD:
            self._goto(Stage.MOVE, t)
        elif self.stage is Stage.MOVE:
            found, gains = lvdt_findings(self._rec.arrays(), k, self.act, self.lim, self.plan)
            self._add(found)
            self.measured["lvdt_gain"][f"ema{k}_moving"] = gains
            self._level = {n: float(np.mean(v)) for n, v in self._rec.arrays(n_hold).items()}
            self._goto(Stage.STEP, t)
        elif self.stage is Stage.STEP:
            self._after_step(k, n_hold)
            self._goto(Stage.UNLOAD, t)
        elif self.stage is Stage.UNLOAD:
            self._hold = None
            if k == 1:
                self.ema = 2
                self._goto(Stage.LOAD, t)
            else:
                moving = self.measured["lvdt_gain"]
                gains = {a: moving.get(f"ema{a}_moving", {}).get(f"ema{a}") for a in (1, 2)}
                self._add(swap_findings(self.measured["lvdt_follows_raw"], self.plan, gains))
                self.findings = drives_swapped(self.findings, self.plan)
                self.measured.pop("lvdt_follows_raw")
                self._goto(Stage.DONE, t)

    def _after_step(self, k: int, n_hold: int) -> None:
        j = 3 - k
        after = {n: float(np.mean(v)) for n, v in self._rec.arrays(n_hold).items()}
        found, gains = force_findings(self._level, after, j, self.lim.force_N, self.plan)
        self._add(found)
        self.measured["loadcell_gain"][f"ema{j}_pushing"] = gains
        dx = (after[f"phi{j}"] - self._level[f"phi{j}"]) / self.i
        ds_j = after[f"s{j}"] - self._level[f"s{j}"]
        ds_k = after[f"s{k}"] - self._level[f"s{k}"]
        self.measured.setdefault("lvdt_follows_raw", {})[j] = (dx, ds_j, ds_k)
        self.measured["lvdt_follows"][f"ema{j}_pushing"] = {"motor_mm": dx, f"lvdt{j}_mm": ds_j,
                                                            f"lvdt{k}_mm": ds_k}


_DISABLED = Setpoint(DriveMode.DISABLED, 0.0)
