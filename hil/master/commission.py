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
3a. **The force-free jog** (:class:`hil.master.jog.Jog`): both EMAs out and back together in CSP, no force
   commanded; the motor angles over the gear ratio and the LVDTs must agree on how far the rams moved
   (:mod:`hil.master.jog_rules`). A disagreement stops here, naming the scale that fits: nothing is loaded.
4. **Movement**, EMA k in turn (j the other): j holds a small force in CST (:class:`Limits`: a
   quarter of the check's opposing force), k moves ``travel_mm`` out and back at a quarter of the
   check's sweep speed: each LVDT regressed on its motor angle over the gear ratio (slope 1 within
   the supervisor's LVDT pitch tolerance); then j's force steps up by the same amount: each load
   cell's change against j's torque (+1 for j, -1 for k, within :data:`FORCE_GAIN_TOLERANCE`), and
   which LVDT follows j's motor (LVDT j, else the two are swapped). A holding drive without CST follows
   k's excursion instead, and k then pushes against it held until a load cell changed by that force
   (the load cells' signs and their ratio: :func:`~hil.master.commission_rules.push_findings`).
5. **End**: both drives disabled (the shell confirms Switch on disabled).

States are :class:`~hil.master.commission_rules.Stage` values, their transitions :data:`TRANSITIONS`; the
vocabulary, the limits and the rules that judge the signals are :mod:`hil.master.commission_rules`.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np

from hil.canopen.cia402 import decode_state
from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.sdo import SdoAbortError, SdoTimeout
from hil.canopen.signalmap import ForceControl, NodeRole, Signal
from hil.check.profileclock import ProfileClock
from hil.errors import EmacheckError
from hil.master.commission_rules import (
    OPERATOR_KEY,
    REST_S,
    Finding,
    Kind,
    Limits,
    Stage,
    drives_swapped,
    ema_key,
    force_findings,
    gain_se,
    key_of,
    lvdt_findings,
    push_findings,
    rest_findings,
    swap_findings,
)
from hil.master.core import MasterCore
from hil.master.jog import Jog
from hil.master.jog_rules import JogPlan
from hil.master.preflight import MasterLossReactionError, Nmt, Now, PreflightError, SdoRead, Wait, identity_problems
from hil.profile.config import Actuation, Check

__all__ = ["Commission", "CommissionMaster", "CommissionStop", "Scan", "TRANSITIONS"]

#: The commissioning's transitions (an illegal one raises).
TRANSITIONS: dict[Stage, frozenset[Stage]] = {
    Stage.SCAN: frozenset({Stage.PREFLIGHT, Stage.STOPPED}),
    Stage.PREFLIGHT: frozenset({Stage.AT_REST, Stage.STOPPED}),
    Stage.AT_REST: frozenset({Stage.JOG, Stage.STOPPED}),
    Stage.JOG: frozenset({Stage.LOAD, Stage.STOPPED}),
    Stage.LOAD: frozenset({Stage.MOVE, Stage.STOPPED}),
    Stage.MOVE: frozenset({Stage.STEP, Stage.STOPPED}),
    Stage.STEP: frozenset({Stage.UNLOAD, Stage.STOPPED}),
    Stage.UNLOAD: frozenset({Stage.LOAD, Stage.DONE, Stage.STOPPED}),
    Stage.DONE: frozenset(),
    Stage.STOPPED: frozenset(),
}


class CommissionStop(PreflightError):
    """The scan found problems: the commissioning stops before anything is powered."""


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
        self._compare(spec, ident, got["device_type"])

    def _compare(self, spec, ident: dict, devtype: int) -> None:
        """The identity read against the profile (the preflight's comparison), each problem with its key and the
        value read; a sub-index the node does not have (CiA 301 makes 0x1018:02..04 optional) is not compared."""
        if ident["vendor_id"] is None:
            self.findings.append(Finding(Stage.SCAN, Kind.IDENTITY, f"{spec.key}.vendor_id",
                                         f"{spec.label}: identity 0x1018:01 (vendor id) not readable"))
            return
        read = {"vendor_id": ident["vendor_id"],
                "product_code": spec.product_code if ident["product_code"] is None else ident["product_code"],
                "revision": spec.revision_min if ident["revision"] is None else ident["revision"]}
        keys = []
        if read["vendor_id"] != spec.vendor_id:
            keys.append((f"{spec.key}.vendor_id", f"0x{read['vendor_id']:08X}"))
        elif read["product_code"] != spec.product_code:
            keys.append((f"{spec.key}.product_code", f"0x{read['product_code']:08X}"))
        if read["revision"] < spec.revision_min:
            keys.append((f"{spec.key}.revision_min", f"0x{read['revision']:08X}"))
        keys.append((f"{spec.key}.device_profile", devtype & 0xFFFF))
        # identity_problems names them in this order: vendor or product, revision, device type
        for problem, (key, fits) in zip(identity_problems(spec, read, devtype), keys, strict=False):
            self.findings.append(Finding(Stage.SCAN, Kind.IDENTITY, key, problem, fits=fits))


# ------------------------------------------------------------------ the cyclic core


@dataclass
class _Record:
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
        self.jog_plan = JogPlan.of(actuation, self.lim, plan)  #: the force-free jog before anything is loaded
        self.jog: Jog | None = None
        self.i = actuation.mechanics.i_total_rad_per_mm
        self.T = actuation.timing.sync_period_s
        c = actuation.canopen
        self.scan = Scan(plan, c.boot_timeout_s, c.master_node_id)
        self.stage = Stage.SCAN
        self.stopped_at: Stage | None = None  #: where an error stopped it (SCAN: nothing was powered)
        self.findings: list[Finding] = []
        self.ema = 1  #: the EMA that moves (the other holds the force)
        self.measured: dict = {"lvdt_gain": {}, "loadcell_gain": {}, "lvdt_follows": {}, "at_rest": {}}
        #: the samples of each movement and force step, ``"move 1"``, ``"force step 1"`` (k) -> arrays (the report's
        #: figures)
        self.traces: dict[str, dict[str, np.ndarray]] = {}
        self._t0 = 0.0  #: the stage's start [s]
        #: the stage's profile time: it waits for periods without a sample (hil.check.profileclock), so a move
        #: resumes where it was after the PC held the loop instead of leaping by the motion missed
        self._clock = ProfileClock(self.T)
        self._start: tuple[float, float] | None = None  #: motor angles at rest [rad]
        self._hold: float | None = None  #: the holding EMA's angle once it is back in CSP [rad]
        self._rec = _Record()
        self._level: dict[str, float] = {}  #: mean forces / strokes / angles at the end of MOVE
        self._level_sd: dict[str, float] = {}  #: and their standard deviations
        self._move: dict[str, np.ndarray] = {}  #: the samples of the last MOVE
        self._t = 0.0
        self._push = 0.0  #: a CSP rig's push [mm of stroke] (the force step of a drive without CST)
        self._pushed = False  #: the push reached the commissioning force (or its travel)

    @property
    def done(self) -> bool:
        return self.stage in (Stage.DONE, Stage.STOPPED)

    def in_cst(self, ema: int) -> bool:
        """EMA ``ema``'s drive holds forces in CST (else: the CSP variant, docs/commission.md)."""
        return self.plan.drives[ema - 1].force_control is ForceControl.CST

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
        self._clock.restart(t)
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
            text = str(exc) or "interrupted by the operator"
            self.findings.append(Finding(self.stage, Kind.STOP, OPERATOR_KEY, text))
        else:
            stage = self.stage if self.stage is not Stage.STOPPED else Stage.PREFLIGHT
            kind = Kind.PREFLIGHT if stage in (Stage.SCAN, Stage.PREFLIGHT) else Kind.STOP
            text = f"{type(exc).__name__}: {exc}"
            # the key the error carries or names, else the table it concerns: the drives' configuration, or the
            # link's limits
            key = self._key_of(exc) or key_of(text, "canopen" if kind is Kind.PREFLIGHT else "safety")
            self.findings.append(Finding(stage, kind, key, text))
        self.stage = Stage.STOPPED

    def _key_of(self, exc: BaseException) -> str:
        """The profile key an error that stopped the commissioning concerns: its own (a preflight's), the SDO
        timeout, or the EDS of a node that refused an object its EDS offers; "" where none is known."""
        if key := getattr(exc, "key", ""):
            return key
        if isinstance(exc, SdoTimeout):
            return "canopen.sdo_timeout_s"
        spec = next((n.spec for n in self.plan.nodes if n.spec.node_id == getattr(exc, "node_id", None)), None)
        return f"{spec.key}.eds" if isinstance(exc, SdoAbortError) and spec is not None else ""

    # ------------------------------------------------------------ the cyclic phase

    def step(self, smp: Sample) -> tuple[Setpoint, Setpoint]:
        """One sample in, the two drives' setpoints for the next cycle out."""
        t = self._t = smp.t_s
        if self._start is None:
            self._start = (smp.phi1_rad, smp.phi2_rad)
            self._goto(Stage.AT_REST, t)
        tau = self._clock.elapsed(t)
        if self.done:
            return _DISABLED, _DISABLED
        if self.stage is not Stage.AT_REST and (why := self._guard(smp)):
            self.findings.append(Finding(self.stage, Kind.LIMIT, why[0], why[1]))
            self.stage = Stage.STOPPED
            return _DISABLED, _DISABLED
        self._rec.add(smp)
        if self.stage is Stage.JOG:
            return self._jog_step(smp)
        if tau >= self._duration():
            self._end_of_stage(smp)
            if self.done:
                return _DISABLED, _DISABLED
            tau = 0.0
        return self._setpoints(tau, smp)

    def _jog_step(self, smp: Sample) -> tuple[Setpoint, Setpoint]:
        """The force-free jog (:mod:`hil.master.jog`); once it is done, its verdict: the commissioning stops
        (the motion scale not confirmed) or goes on to load."""
        sp = self.jog.step(smp)
        if not self.jog.done:
            return sp
        verdict = self.jog.verdict()
        self.measured["jog"] = verdict.as_json() | {"stopped": self.jog.stopped, "plan": self.jog_plan.as_json(),
                                                    "peak_force_change_N": self.jog.peak_force_change_N()}
        if verdict.stop:
            self.findings += list(verdict.findings)
            self.stage = Stage.STOPPED
            return _DISABLED, _DISABLED
        self._goto(Stage.LOAD, smp.t_s)
        return self._setpoints(0.0, smp)

    def _duration(self) -> float:
        lim = self.lim
        if not self.in_cst(3 - self.ema) and self.stage in (Stage.STEP, Stage.UNLOAD):
            return lim.push_mm / lim.speed_mm_per_s + lim.settle_s  # the push out, or back
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
        if not self.in_cst(j):
            return self._setpoints_csp(tau, smp)
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

    def _setpoints_csp(self, tau: float, smp: Sample) -> tuple[Setpoint, Setpoint]:
        """A holding EMA j without CST: no force to hold; j follows k's excursion (the rams move together,
        unloaded), then k pushes against j held until a load cell changed by ``force_N`` (or ``push_mm``),
        and goes back."""
        k, lim, start = self.ema, self.lim, self._start
        j = 3 - k
        pos = lambda a, mm: Setpoint(DriveMode.POSITION, start[a - 1] + self.i * mm)  # noqa: E731
        if self.stage is Stage.MOVE:
            exc = self._excursion(tau)
            sp = {k: pos(k, exc), j: pos(j, exc)}
        elif self.stage is Stage.STEP:
            if not self._pushed and self._level:
                changed = max(abs(smp.F1_N - self._level["F1"]), abs(smp.F2_N - self._level["F2"]))
                self._pushed = changed >= lim.force_N or self._push >= lim.push_mm
            if not self._pushed:
                self._push = min(lim.push_mm, self._push + lim.speed_mm_per_s * self.T)
            sp = {k: pos(k, self._push), j: pos(j, 0.0)}
        elif self.stage is Stage.UNLOAD:
            self._push = max(0.0, self._push - lim.speed_mm_per_s * self.T)
            sp = {k: pos(k, self._push), j: pos(j, 0.0)}
        else:  # LOAD: both hold
            sp = {k: pos(k, 0.0), j: pos(j, 0.0)}
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
                return (ema_key(self.plan, a, Signal.FORCE),
                        f"load cell {a} read {f:.0f} N > {lim.max_force_N:g} N (the commissioning's force limit): "
                        f"movement stopped (a wrong scale of that load cell reads high)")
        for a, phi in ((1, smp.phi1_rad), (2, smp.phi2_rad)):
            away = abs(phi - self._start[a - 1]) / self.i
            if away > lim.max_travel_mm:
                return (ema_key(self.plan, a, Signal.MOTOR_ANGLE),
                        f"EMA {a}'s motor angle moved {away:.2f} mm from where it started > {lim.max_travel_mm:g} mm: "
                        f"movement stopped")
        return None

    def _end_of_stage(self, smp: Sample) -> None:
        t, k = smp.t_s, self.ema
        n_hold = max(1, int(self.lim.settle_s / 2 / self.T))
        if self.stage in (Stage.MOVE, Stage.STEP):
            self.traces[f"{self.stage.value} {k}"] = self._rec.arrays()
        if self.stage is Stage.AT_REST:
            x = self._rec.arrays()
            self.measured["at_rest"] = {n: {"mean": float(np.mean(v)), "ptp": float(np.ptp(v)),
                                            "std": float(np.std(v))} for n, v in x.items()}
            found = rest_findings(x, self.act, self.check, self.lim, self.plan)
            self.findings += found
            if found:
                self.findings.append(Finding(Stage.AT_REST, Kind.STOP, "", "nothing was moved: a signal at rest "
                                             "is wrong"))
                self.stage = Stage.STOPPED
                return
            self._goto(Stage.JOG, t)
            self.jog = Jog(self.jog_plan, self.plan, self._start,
                           {n: self.measured["at_rest"][n]["mean"] for n in ("s1", "s2", "F1", "F2")}, t, self.T)
        elif self.stage is Stage.LOAD:
            self._goto(Stage.MOVE, t)
        elif self.stage is Stage.MOVE:
            found, gains = lvdt_findings(self._rec.arrays(), k, self.act, self.lim, self.plan)
            self._add(found)
            self.measured["lvdt_gain"][f"ema{k}_moving"] = gains
            self._level = {n: float(np.mean(v)) for n, v in self._rec.arrays(n_hold).items()}
            self._level_sd = {n: float(np.std(v)) for n, v in self._rec.arrays(n_hold).items()}
            self._move = self._rec.arrays()
            self._goto(Stage.STEP, t)
        elif self.stage is Stage.STEP:
            self._after_step(k, n_hold)
            self._goto(Stage.UNLOAD, t)
        elif self.stage is Stage.UNLOAD:
            self._hold, self._push, self._pushed = None, 0.0, False
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
        """The force step judged: the load cells against j's torque (CST), or against each other after k's
        push (CSP); and whether the LVDT that moved with the moving motor is its own."""
        j = 3 - k
        after = {n: float(np.mean(v)) for n, v in self._rec.arrays(n_hold).items()}
        if self.in_cst(j):
            mover = j
            found, gains = force_findings(self._level, after, j, self.lim.force_N, self.plan)
            self.measured["loadcell_gain"][f"ema{j}_pushing"] = gains
            sd = {n: float(np.std(v)) for n, v in self._rec.arrays(n_hold).items()}
            self.measured.setdefault("gain_se", {}).update(
                gain_se(self._move, k, self.i, self._level_sd, sd, self.lim.force_N, n_hold))
        else:
            mover = k
            found, changes = push_findings(self._level, after, k, self.lim.force_N, self.plan)
            self.measured.setdefault("loadcell_push_N", {})[f"ema{k}_pushing"] = changes
        self._add(found)
        other = 3 - mover
        dx = (after[f"phi{mover}"] - self._level[f"phi{mover}"]) / self.i
        ds_m = after[f"s{mover}"] - self._level[f"s{mover}"]
        ds_o = after[f"s{other}"] - self._level[f"s{other}"]
        self.measured.setdefault("lvdt_follows_raw", {})[mover] = (dx, ds_m, ds_o)
        self.measured["lvdt_follows"][f"ema{mover}_pushing"] = {"motor_mm": dx, f"lvdt{mover}_mm": ds_m,
                                                                f"lvdt{other}_mm": ds_o}


_DISABLED = Setpoint(DriveMode.DISABLED, 0.0)


class CommissionMaster(MasterCore):
    """The master core of a commissioning: :class:`~hil.master.core.MasterCore` as the check's, but every
    frame it is fed is heard by the commissioning's scan too (:meth:`Commission.heard`: boot-ups and
    heartbeats of any node id) before the master handles it, and :meth:`~hil.master.core.MasterCore.start`
    runs the scan and then the preflight (:meth:`Commission.steps`) instead of the preflight alone.

    Parameters
    ----------
    core : Commission
        The commissioning that hears the frames.
    actuation, plan, forces, safety
        As :class:`~hil.master.core.MasterCore`'s.
    """

    def __init__(self, core: Commission, actuation: Actuation, plan, forces: tuple[float, float], safety) -> None:
        super().__init__(actuation, plan, forces=forces, safety=safety)
        self.commission = core
        self.steps = core.steps(self.preflight)

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """:meth:`Commission.heard`, then :meth:`MasterCore.on_frame <hil.master.core.MasterCore.on_frame>`."""
        self.commission.heard(frame)
        return super().on_frame(frame, t)
