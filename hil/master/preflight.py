"""The master's preflight as a sans-IO generator: boot, identify, configure, the master's-death drill.

:class:`Preflight` is driven by :class:`hil.master.core.MasterCore`: it yields
requests (an NMT command, wait for boot-up, an SDO read or write, let time
pass, the master's own heartbeat off or on) and receives their results; it
never touches a bus or a clock. What it learns goes into the master's views
of the nodes and into :attr:`Preflight.scales` (the scalings read from the
drives) and the typed :class:`MasterLossRecord` of each drive.

Sequence (CiA 302-style, per node as the rig's :class:`~hil.canopen.plan.RigPlan` says):

1. NMT reset node (all), boot-up of every node of the rig.
2. Every node, one after the other: identity 0x1018 and device type 0x1000
   against the profile, producer heartbeat 0x1017, its PDOs (the unused ones
   disabled); and for a drive: supported modes 0x6502 (CSP; CST where it holds forces in
   CST), the gear ratio object and 0x608F against the profile where they
   exist, the scalings it reports (0x608F, 0x6091/0x6092, rated torque
   0x6076), the limits it keeps itself where its EDS offers them (0x607D,
   0x6072, 0x6080, 0x6065/0x6066, 0x6085; written and read back: hil/master/limits_setup.py),
   interpolation period 0x60C2, quick stop option 0x605A = 2 and 0x1006 where writable, the modes of
   operation (CSP, set once by SDO for a drive without CST), the reaction to
   the master's death (0x1016:01, 0x6007 = 3, written and read back).
3. The drill (unless ``canopen.skip_master_loss_drill`` says why not): every
   drive whose reaction is configured is powered up by SDO at standstill,
   holding its position; the master stops its heartbeat (no SYNC, no PDO
   runs yet) for longer than the consumer time while it keeps listening,
   reads each statusword by SDO every SYNC period and notes EMCYs; a drive that
   leaves OPERATION_ENABLED has reacted (the time since the master's last
   heartbeat is its reaction time). Then the heartbeat resumes, NMT
   pre-operational restores SDO on a drive whose error behaviour stopped it,
   and each drive is brought to SWITCH_ON_DISABLED. A drive that did not
   react stops the preflight (:class:`~hil.master.core.MasterLossReactionError`)
   unless ``canopen.external_watchdog`` states the rig's protection.
4. NMT start (all).
"""

from __future__ import annotations

import contextlib
import math
import struct
from collections.abc import Generator
from dataclasses import dataclass, field

from canopen.objectdictionary import datatypes as dt

from hil.canopen.cia402 import Goal, OperationMode, State, decode_state
from hil.canopen.drivelimits import KEPT_BY_DRIVE, DriveLimit, LimitKind
from hil.canopen.nmt import NmtCommand
from hil.canopen.od import QUICK_STOP_OPTION, AbortConnectionOption, master_loss_steps
from hil.canopen.pdo import TYPE_BITS
from hil.canopen.plan import CSP_BIT, CST_BIT, DrivePlan, NodePlan, RigPlan
from hil.canopen.sdo import SdoAbortError, SdoTimeout, describe
from hil.canopen.signalmap import (
    ForceControl,
    ScaleSource,
    Signal,
    angle_scale_counts,
    angle_scale_factor_group,
    object_name,
    torque_scale,
)
from hil.errors import EmacheckError
from hil.master.drill import DrillOutcome, DrillResult, MasterLossRecord, ReactionConfig
from hil.master.limits_setup import limit_targets, limits_for, readback_problem
from hil.master.powerup import PowerWalk
from hil.profile.config import Actuation, Safety

__all__ = ["DrillOutcome", "DrillResult", "MasterLossRecord", "Preflight", "PreflightError", "identity_problems",
           "MasterLossReactionError", "ReactionConfig", "SameSerialError"]


class PreflightError(EmacheckError, RuntimeError):
    """A node does not match the profile or did not come up; ``key``: the profile key it concerns ("" where
    none is known), as the commissioning names its findings."""

    def __init__(self, message: str = "", key: str = "") -> None:
        super().__init__(message)
        self.key = key


class SameSerialError(PreflightError):
    """EMA 1 and EMA 2 report one identity (vendor, product and a serial number other than 0): the check
    could not say which actuator it measured, so it is refused before anything moves (exit status 3)."""

    bad_input = True


class MasterLossReactionError(PreflightError):
    """A drive lacks, refuses or does not perform its reaction to the master's death, and no other
    protection is stated."""


# ------------------------------------------------------------------ requests the generator yields


@dataclass(frozen=True, slots=True)
class Nmt:
    command: NmtCommand
    node: int = 0  #: 0: all nodes


@dataclass(frozen=True, slots=True)
class WaitBoot:
    pass


@dataclass(frozen=True, slots=True)
class SdoRead:
    node: int
    index: int
    sub: int
    what: str
    soft: bool = False  #: an abort comes back as the result (not raised)


@dataclass(frozen=True, slots=True)
class SdoWrite:
    node: int
    index: int
    sub: int
    data: bytes
    what: str
    soft: bool = False


@dataclass(frozen=True, slots=True)
class Wait:
    """Let time pass until ``until_s``; the result is the time then."""

    until_s: float


@dataclass(frozen=True, slots=True)
class Now:
    """The result is the time now."""


@dataclass(frozen=True, slots=True)
class LastHeartbeat:
    """The result is the time the master's last heartbeat went out (None: none yet)."""


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """The master's own heartbeat off (``on`` False; result: the time of its last heartbeat) or on."""

    on: bool


def _refusal(r) -> str:
    """An SDO read's failure in words: the abort's code and meaning, or the timeout."""
    return f"SDO abort 0x{int(r.code):08X}, {describe(r.code)}" if isinstance(r, SdoAbortError) else "no answer"


# ------------------------------------------------------------------ value codec


_STD_TYPES = {(0x1006, 0): dt.UNSIGNED32, (0x1016, 1): dt.UNSIGNED32, (0x1017, 0): dt.UNSIGNED16,
              (0x6007, 0): dt.INTEGER16, (0x6040, 0): dt.UNSIGNED16, (0x605A, 0): dt.INTEGER16,
              (0x6060, 0): dt.INTEGER8, (0x607A, 0): dt.INTEGER32, (0x607D, 1): dt.INTEGER32,
              (0x607D, 2): dt.INTEGER32, (0x60C2, 1): dt.UNSIGNED8, (0x60C2, 2): dt.INTEGER8,
              (0x6065, 0): dt.UNSIGNED32, (0x6066, 0): dt.UNSIGNED16, (0x6072, 0): dt.UNSIGNED16,
              (0x6080, 0): dt.UNSIGNED32, (0x6085, 0): dt.UNSIGNED32}


def _code(node: NodePlan, index: int, sub: int) -> str:
    t = node.types.get((index, sub), _STD_TYPES.get((index, sub), dt.UNSIGNED32))
    if t in (dt.REAL64,):
        return "d"
    return TYPE_BITS.get(t, (32, "I"))[1]


def encode(node: NodePlan, index: int, sub: int, value: int | float) -> bytes:
    """``value`` in the object's data type as the node's EDS gives it (little endian)."""
    code = _code(node, index, sub)
    if code not in "fd":
        bits = struct.calcsize(code) * 8
        lo, hi = (-(1 << bits - 1), (1 << bits - 1) - 1) if code.islower() else (0, (1 << bits) - 1)
        value = max(lo, min(hi, int(value)))
    return struct.pack("<" + code, value)


def decode(node: NodePlan, index: int, sub: int, data: bytes) -> int | float:
    """Bytes read from an object, decoded with its data type (shorter data is zero-extended)."""
    code = _code(node, index, sub)
    size = struct.calcsize(code)
    raw = bytes(data[:size]).ljust(size, b"\0")
    return struct.unpack("<" + code, raw)[0]


def identity_problems(spec, ident: dict | None, devtype: int | None = None) -> list[str]:
    """What disagrees between a node's identity as read (0x1018 ``ident``: ``vendor_id``, ``product_code``,
    ``revision``; device type 0x1000 ``devtype``; None: not compared) and the profile's node ``spec``. The
    preflight stops at the first; the commissioning (:mod:`hil.master.commission`) names them all."""
    out = []
    if ident is not None:
        hexed = {k: "not read" if v is None else f"0x{v:08X}" for k, v in ident.items()}
        if ident["vendor_id"] != spec.vendor_id or ident.get("product_code") not in (None, spec.product_code):
            out.append(f"{spec.label}: identity 0x1018 vendor {hexed['vendor_id']} product "
                       f"{hexed.get('product_code', 'not read')} does not match the profile ({spec.key}.vendor_id "
                       f"0x{spec.vendor_id:08X}, {spec.key}.product_code 0x{spec.product_code:08X})")
        if ident.get("revision") is not None and ident["revision"] < spec.revision_min:
            out.append(f"{spec.label}: revision 0x{ident['revision']:08X} below "
                       f"{spec.key}.revision_min 0x{spec.revision_min:08X}")
    if devtype is not None and devtype & 0xFFFF != spec.device_profile:
        out.append(f"{spec.label}: device type 0x{devtype:08X} is not a CiA {spec.device_profile} "
                   f"device (0x1000 bits 0..15 = {devtype & 0xFFFF})")
    return out


# ------------------------------------------------------------------ the preflight


@dataclass
class DriveSetup:
    """What the preflight learned of one drive (filled as it goes)."""

    ema: int
    plan: DrivePlan
    identity: dict = field(default_factory=dict)
    rated_torque_Nm: float | None = None
    scales: dict = field(default_factory=dict)  #: Signal -> Scale read from the drive
    master_loss: MasterLossRecord | None = None
    modes: int | None = None  #: 0x6502 as read
    limits: tuple[DriveLimit, ...] = ()  #: the limits it keeps itself, or the master only (kept_by)


class Preflight:
    """The preflight of one check (see the module docstring); :meth:`run` is the generator.

    Parameters
    ----------
    actuation : Actuation
    plan : RigPlan
    emcy_since : callable
        ``emcy_since(node, t) -> tuple of int``: EMCY codes the node sent since ``t`` (the master
        core keeps them).
    on_status : callable, optional
        ``on_status(node, statusword, t)``: every statusword the preflight reads by SDO (the master's
        view of the drive's state before the cyclic phase).
    forces : (float, float), optional
        The check's opposing force and the supervisor's force limit [N] (``check.calibration.opposing_force_N``,
        ``check.safety.max_force_N``): a drive holding forces in CST must allow the opposing force.
    safety : Safety, optional
        The check's safety profile: the limits each drive keeps itself (:mod:`hil.master.limits_setup`); None:
        only the actuation's stroke limit and the force limit of ``forces``.
    """

    def __init__(self, actuation: Actuation, plan: RigPlan, emcy_since, on_status=None,
                 forces: tuple[float, float] | None = None, safety: Safety | None = None) -> None:
        self.act = actuation
        self.plan = plan
        self.forces = forces  #: (opposing force, force limit) [N], or None
        self.safety = safety
        self.c = actuation.canopen
        self.T = actuation.timing.sync_period_s
        self.consumer_ms = round(self.c.master_consumer_time_s * 1000)
        self.drives = [DriveSetup(d.ema, d) for d in plan.drives]
        self.identities: dict[int, dict] = {}
        self._emcy_since = emcy_since
        self._on_status = on_status  #: ``on_status(node, statusword, t)``: a statusword read by SDO
        #: drives the drill is powering up or has powered up (emptied when it brought them down again)
        self.powered: list[DriveSetup] = []
        self.events: list[tuple[int, str]] = []  #: (node, what) for the master's event log

    # ------------------------------------------------------------ helpers

    def _read(self, node: NodePlan, index: int, sub: int, what: str, soft: bool = False):
        """The decoded value; with ``soft`` an abort or a timeout comes back as the result (not raised)."""
        r = yield SdoRead(node.spec.node_id, index, sub, what, soft)
        if isinstance(r, (SdoAbortError, SdoTimeout)):
            return r
        return decode(node, index, sub, r)

    def _write(self, node: NodePlan, index: int, sub: int, value, what: str, soft: bool = False):
        return (yield SdoWrite(node.spec.node_id, index, sub, encode(node, index, sub, value), what, soft))

    # ------------------------------------------------------------ the sequence

    def run(self) -> Generator:
        yield Nmt(NmtCommand.RESET_NODE)
        yield WaitBoot()
        drives = {d.plan.node.spec.node_id: d for d in self.drives}
        for node in self.plan.nodes:
            yield from self._identify(node)
            yield from self._common(node)
            if node.spec.node_id in drives:
                yield from self._drive(drives[node.spec.node_id])
        yield from self._drill()
        yield Nmt(NmtCommand.START)

    def _identify(self, node: NodePlan) -> Generator:
        """Identity 0x1018 against the profile: :01 (mandatory, CiA 301) must answer; :02, :03, :04 are read
        whether the EDS lists them or not (optional in CiA 301), must answer where it lists :02/:03, and a
        sub-index the drive refuses is recorded None and not compared (the event log says so)."""
        spec = node.spec
        ident, unread = {}, []
        for sub, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"), (4, "serial")):
            soft = sub == 4 or (sub > 1 and not node.can_read(0x1018, sub))
            v = yield from self._read(node, 0x1018, sub, key.replace("_", " "), soft=soft)
            ident[key] = None if isinstance(v, (SdoAbortError, SdoTimeout)) else int(v)
            if ident[key] is None and sub < 4:
                unread.append(f"0x1018:{sub:02X} ({key.replace('_', ' ')}: {_refusal(v)})")
            self.identities[spec.node_id] = dict(ident)  # what was read so far, also if the next read fails
        if unread:
            self.events.append((spec.node_id, f"identity {'; '.join(unread)} not read: not compared with the "
                                              f"profile's {spec.key}.product_code / revision_min"))
        for problem in identity_problems(spec, ident):
            raise PreflightError(problem, f"{spec.key}.revision_min" if " revision " in problem
                                 else f"{spec.key}.product_code")
        self._distinct_serial(spec)
        devtype = int((yield from self._read(node, 0x1000, 0, "device type")))
        for problem in identity_problems(spec, None, devtype):
            raise PreflightError(problem, f"{spec.key}.device_profile")

    def _distinct_serial(self, spec) -> None:
        """The drive ``spec`` must not report the serial number (0x1018:04, with vendor and product) of the
        other drive identified before it: two actuators of one serial cannot be told apart in the record
        (:class:`SameSerialError`). A serial of 0 (none set, the EDS default) or none read is not compared."""
        drives = [d.plan.node.spec for d in self.drives]
        if spec.node_id not in [s.node_id for s in drives]:
            return
        key = tuple(self.identities[spec.node_id].get(k) for k in ("vendor_id", "product_code", "serial"))
        if not key[2]:
            return
        for other in drives:
            if other.node_id == spec.node_id or other.node_id not in self.identities:
                continue
            if tuple(self.identities[other.node_id].get(k) for k in ("vendor_id", "product_code", "serial")) == key:
                raise SameSerialError(
                    f"{other.label} and {spec.label} both report serial number 0x{key[2]:08X} (0x1018:04, "
                    f"vendor 0x{key[0]:08X}, product 0x{key[1]:08X}): two actuators of one serial cannot be "
                    f"traced; check each drive's identity (a copied parameter set?) before the check",
                    "canopen.node_id_ema1, canopen.node_id_ema2")

    def _common(self, node: NodePlan) -> Generator:
        hb_ms = int(round(node.spec.heartbeat_period_s * 1000))
        yield from self._write(node, 0x1017, 0, hb_ms, "producer heartbeat time")
        for w in node.layout.configuration_writes():
            yield SdoWrite(node.spec.node_id, w.index, w.subindex, w.data, w.what)

    def _drive(self, d: DriveSetup) -> Generator:
        node, spec, plan = d.plan.node, d.plan.node.spec, d.plan
        modes = int((yield from self._read(node, 0x6502, 0, "supported drive modes")))
        d.modes = modes
        if not modes >> CSP_BIT & 1:
            raise PreflightError(f"{spec.label}: does not support CSP (0x6502 = 0x{modes:08X}); the check "
                                 f"commands positions in cyclic synchronous position mode", f"{spec.key}.eds")
        if plan.force_control is ForceControl.CST and not modes >> CST_BIT & 1:
            raise PreflightError(f"{spec.label}: does not support CST (0x6502 = 0x{modes:08X}); set "
                                 f"canopen.force_control = \"csp\" (the master's force loop) or check the drive",
                                 "canopen.force_control")
        if self.plan.gear_ratio_object is not None:
            gi, gs = self.plan.gear_ratio_object
            ratio = float((yield from self._read(node, gi, gs, "gear ratio")))
            want = self.act.mechanics.i_total_rad_per_mm
            if not math.isclose(ratio, want, rel_tol=1e-5):
                raise PreflightError(f"{spec.label}: gear ratio {object_name(gi, gs)} = {ratio:.6f} rad/mm, profile "
                                     f"mechanics.i_total_rad_per_mm = {want:.6f}", "mechanics.i_total_rad_per_mm")
        yield from self._scales(d)
        yield from self._limits(d)
        if node.can_write(0x60C2, 1) and node.can_write(0x60C2, 2):
            yield from self._write(node, 0x60C2, 1, int(round(self.T * 1000)), "interpolation period value")
            yield from self._write(node, 0x60C2, 2, -3, "interpolation period index")
        if node.can_write(0x605A, 0):
            r = yield from self._write(node, 0x605A, 0, QUICK_STOP_OPTION, "quick stop option code", soft=True)
            if isinstance(r, SdoAbortError):
                self.events.append((spec.node_id, f"0x605A = {QUICK_STOP_OPTION} refused ({describe(r.code)}); "
                                                  f"the master takes the drive out of QUICK STOP ACTIVE itself"))
        if node.can_write(0x1006, 0):
            yield from self._write(node, 0x1006, 0, int(round(self.T * 1e6)), "communication cycle period")
        if not plan.mode_by_pdo:
            yield from self._set_mode_by_sdo(d, OperationMode.CSP)
        d.master_loss = yield from self._reaction(d)
        self.events.append((spec.node_id, f"configured: identity {self.identities[spec.node_id]}, "
                                          f"force control {plan.force_control.value}"))

    def _scales(self, d: DriveSetup) -> Generator:
        """The scalings the drive reports, and the profile's counts per revolution checked against 0x608F."""
        node, spec = d.plan.node, d.plan.node.spec
        angle = self.plan.channel(d.ema, Signal.MOTOR_ANGLE)
        counts = None
        if angle.source is ScaleSource.ENCODER or (angle.source is ScaleSource.PROFILE and node.can_read(0x608F, 1)
                                                   and node.can_read(0x608F, 2)):
            inc = yield from self._read(node, 0x608F, 1, "encoder increments")
            revs = yield from self._read(node, 0x608F, 2, "motor revolutions")
            if revs <= 0 or inc <= 0:
                raise PreflightError(f"{spec.label}: encoder resolution 0x608F = {inc}/{revs} is not a resolution",
                                     f"signals.ema{d.ema}.motor_angle")
            counts = inc / revs
        if angle.source is ScaleSource.ENCODER:
            d.scales[Signal.MOTOR_ANGLE] = angle_scale_counts(counts)
        elif angle.source is ScaleSource.FACTOR_GROUP:
            vals = []
            for i, s, what in ((0x6091, 1, "gear ratio motor revolutions"), (0x6091, 2, "gear ratio shaft revolutions"),
                               (0x6092, 1, "feed"), (0x6092, 2, "feed shaft revolutions")):
                vals.append(int((yield from self._read(node, i, s, what))))
            if min(vals) <= 0:
                raise PreflightError(f"{spec.label}: position factor 0x6091 = {vals[0]}/{vals[1]}, 0x6092 = "
                                     f"{vals[2]}/{vals[3]} is not a scaling", f"signals.ema{d.ema}.motor_angle")
            d.scales[Signal.MOTOR_ANGLE] = angle_scale_factor_group(*vals)
        elif counts is not None and angle.node_id == spec.node_id and \
                not math.isclose(angle.scale.units_per_si, angle_scale_counts(counts).units_per_si, rel_tol=1e-9):
            want = angle.scale.units_per_si * 2 * math.pi
            raise PreflightError(f"{spec.label}: encoder resolution 0x608F = {counts:g} increments per revolution, "
                                 f"profile signals.ema{d.ema}.motor_angle.counts_per_rev = {want:.6g}",
                                 f"signals.ema{d.ema}.motor_angle.counts_per_rev")
        if Signal.MOTOR_ANGLE in d.scales:
            d.scales[Signal.TARGET_POSITION] = d.scales[Signal.MOTOR_ANGLE]
        torque = self.plan.channel(d.ema, Signal.TARGET_TORQUE)
        if torque is not None and torque.source is ScaleSource.RATED_TORQUE:
            rated_mNm = int((yield from self._read(node, 0x6076, 0, "rated torque")))
            if rated_mNm <= 0:
                raise PreflightError(f"{spec.label}: rated torque 0x6076 is {rated_mNm} mN m; give "
                                     f"signals.ema{d.ema}.target_torque.rated_torque_Nm",
                                     f"signals.ema{d.ema}.target_torque.rated_torque_Nm")
            d.rated_torque_Nm = rated_mNm / 1000.0
            d.scales[Signal.TARGET_TORQUE] = torque_scale(d.rated_torque_Nm, self.act.mechanics.i_total_rad_per_mm)
        elif torque is not None:
            d.rated_torque_Nm = 1.0 / (torque.scale.units_per_si * self.act.mechanics.i_total_rad_per_mm)

    def _limits(self, d: DriveSetup) -> Generator:
        """The limits the drive keeps itself (:mod:`hil.master.limits_setup`): each one its EDS offers written and
        read back (another value refuses the preflight), the others kept by the master only; then a drive
        holding forces in CST must allow the calibration's opposing force under its max torque 0x6072."""
        node, spec = d.plan.node, d.plan.node.spec
        angle = d.scales.get(Signal.MOTOR_ANGLE) or self.plan.channel(d.ema, Signal.MOTOR_ANGLE).scale
        ch = self.plan.channel(d.ema, Signal.TARGET_TORQUE)
        torque = d.scales.get(Signal.TARGET_TORQUE) or (ch.scale if ch is not None else None)
        d.limits = limits_for(limit_targets(self.act, self.safety, self.forces, angle and angle.units_per_si,
                                            torque and torque.units_per_si), node.can_write)
        max_torque = None
        for lim in d.limits:
            if lim.kept_by == KEPT_BY_DRIVE:
                o = lim.obj
                yield from self._write(node, o.index, o.sub, lim.value, lim.kind.value)
                got = yield from self._read(node, o.index, o.sub, lim.kind.value, soft=True)
                if problem := readback_problem(spec.label, lim, got):
                    raise PreflightError(problem, f"{spec.key}.eds")
                max_torque = got if lim.kind is LimitKind.MAX_TORQUE else max_torque
        if self.forces is None or d.plan.force_control is not ForceControl.CST or torque is None:
            return
        if max_torque is None and node.can_read(0x6072, 0):
            max_torque = yield from self._read(node, 0x6072, 0, "max torque", soft=True)
        k, opposing_N = torque.units_per_si, self.forces[0]
        if isinstance(max_torque, (int, float)) and max_torque < opposing_N * k:
            raise PreflightError(
                f"{spec.label}: max torque 0x6072 = {int(max_torque)} per mille of the rated torque allows "
                f"{max_torque / k:.0f} N at the ram; the calibration's opposing force needs {opposing_N:g} N "
                f"(check profile calibration.opposing_force_N): set 0x6072 in the drive, or hold forces in CSP "
                f"(canopen.force_control = \"csp\")", "calibration.opposing_force_N")

    def _set_mode_by_sdo(self, d: DriveSetup, mode: OperationMode) -> Generator:
        """0x6060 = ``mode`` by SDO, confirmed by 0x6061 within ``canopen.mode_change_timeout_s``."""
        node, spec = d.plan.node, d.plan.node.spec
        mode_e = self.plan.map.entry(d.ema, Signal.MODE)
        disp_e = self.plan.map.entry(d.ema, Signal.MODE_DISPLAY)
        yield from self._write(node, mode_e.index, mode_e.subindex, int(mode), "modes of operation")
        deadline = (yield Now()) + self.c.mode_change_timeout_s
        while True:
            shown = int((yield from self._read(node, disp_e.index, disp_e.subindex, "modes of operation display")))
            if shown == int(mode):
                return
            t = yield Now()
            if t > deadline:
                raise PreflightError(f"{spec.label}: modes of operation {int(mode)} ({mode.name}) not confirmed by "
                                     f"0x6061 within canopen.mode_change_timeout_s = {self.c.mode_change_timeout_s} s "
                                     f"(0x6061 = {shown})", "canopen.mode_change_timeout_s")
            yield Wait(t + self.T)

    def _reaction(self, d: DriveSetup) -> Generator:
        """Configure and read back the drive's own reaction to the master's death."""
        node, spec = d.plan.node, d.plan.node.spec
        watchdog = self.c.external_watchdog
        if not d.plan.reaction:  # (the plan allows it only with an external watchdog stated)
            lacks = [f"{object_name(st.index, st.subindex)} ({st.what})"
                     for st in master_loss_steps(self.c.master_node_id, self.consumer_ms)
                     if not node.can_write(st.index, st.subindex)]
            cfg = ReactionConfig(None, None, None, False, (
                f"its EDS has no writable {' nor '.join(lacks)}: nothing written",))
            return MasterLossRecord(cfg, DrillResult(DrillOutcome.NOT_CONFIGURED, note="external watchdog stated"),
                                    watchdog)
        problems = []
        for st in master_loss_steps(self.c.master_node_id, self.consumer_ms):
            r = yield SdoWrite(spec.node_id, st.index, st.subindex, st.data, st.what, soft=True)
            if not isinstance(r, SdoAbortError):
                r = yield SdoRead(spec.node_id, st.index, st.subindex, st.what, soft=True)
            name = f"{object_name(st.index, st.subindex)} ({st.what})"
            if isinstance(r, SdoAbortError):
                problems.append(f"{name}: SDO abort 0x{int(r.code):08X} ({describe(r.code)})")
            elif bytes(r[:len(st.data)]).ljust(len(st.data), b"\0") != st.data:
                problems.append(f"{name} reads back 0x{int.from_bytes(bytes(r), 'little'):X}, "
                                f"not 0x{int.from_bytes(st.data, 'little'):X}")
        cfg = ReactionConfig(self.consumer_ms, self.c.master_node_id, int(AbortConnectionOption.QUICK_STOP),
                             not problems, tuple(problems))
        if problems and not watchdog:
            raise MasterLossReactionError(
                f"{spec.label}: its reaction to the master's death is not in place: " + "; ".join(problems)
                + " (it would keep its last command if the master died; canopen.external_watchdog states another"
                " protection of the rig)")
        drill = DrillResult(DrillOutcome.SKIPPED, note=self.c.skip_master_loss_drill) \
            if self.c.skip_master_loss_drill else DrillResult(DrillOutcome.NOT_RUN if not problems
                                                              else DrillOutcome.NOT_CONFIGURED)
        return MasterLossRecord(cfg, drill, watchdog)

    # ------------------------------------------------------------ the drill

    def _drill(self) -> Generator:
        if self.c.skip_master_loss_drill:
            return
        drives = [d for d in self.drives if d.master_loss.reaction.configured]
        if not drives:
            return
        self.powered = list(drives)  # what a failure must bring down (see MasterCore.abort_preflight_frames)
        try:
            yield from self._drill_of(drives)
        except PreflightError as exc:
            for d in drives:  # the record says the drill did not get to the master's silence, and why
                if d.master_loss.drill.outcome is DrillOutcome.NOT_RUN and not d.master_loss.drill.note:
                    d.master_loss = MasterLossRecord(d.master_loss.reaction, DrillResult(
                        DrillOutcome.NOT_RUN, note=f"stopped before the master fell silent: {exc}"),
                        d.master_loss.external_watchdog)
            # fail closed: every drive the drill may have powered up goes to switch on disabled before the
            # error is told (a drive that does not follow is stopped by SDO when the master gives up)
            yield Heartbeat(True)
            for d in drives:
                with contextlib.suppress(PreflightError):
                    yield from self._power_down_by_sdo(d)
            raise
        self.powered = []

    def _drill_of(self, drives: list[DriveSetup]) -> Generator:
        for d in drives:
            yield from self._power_up_by_sdo(d)
        # a consumer watches from the first heartbeat after its configuration (CiA 301): one goes out first
        t_cfg = yield Now()
        while True:
            last = yield LastHeartbeat()
            if last is not None and last > t_cfg:
                break
            yield Wait((yield Now()) + self.T)
        t_last = yield Heartbeat(False)
        deadline = t_last + 2.0 * self.consumer_ms / 1000.0 + 0.1
        reacted: dict[int, tuple[float | None, State]] = {}
        mute: set[int] = set()  # drives whose SDO server fell silent (0x1029: stopped): read afterwards
        t = yield Now()
        while len(reacted) + len(mute) < len(drives) and t <= deadline:
            for d in drives:
                if d.ema in reacted or d.ema in mute:
                    continue
                sw = yield from self._statusword(d, soft=True)
                if isinstance(sw, SdoTimeout):
                    mute.add(d.ema)
                    continue
                state = decode_state(sw)
                if state is not State.OPERATION_ENABLED:
                    reacted[d.ema] = ((yield Now()), state)
            t = yield Wait(t + self.T)
        if mute:
            yield Wait(deadline)
        t_end = yield Now()
        yield Heartbeat(True)
        for d in drives:  # SDO again on a drive whose error behaviour (0x1029) stopped it
            yield Nmt(NmtCommand.ENTER_PRE_OPERATIONAL, d.plan.node.spec.node_id)
        for d in drives:
            if d.ema in mute:  # it went silent: what is its state now?
                state = decode_state((yield from self._statusword(d)))
                if state is not State.OPERATION_ENABLED:
                    reacted[d.ema] = (None, state)
        for d in drives:
            emcy = tuple(self._emcy_since(d.plan.node.spec.node_id, t_last))
            waited = round((t_end - t_last) * 1e3, 1)
            if d.ema in reacted:
                tr, state = reacted[d.ema]
                ms = None if tr is None else round((tr - t_last) * 1e3, 1)
                note = "" if tr is not None else "its SDO server fell silent (NMT stopped): left OPERATION ENABLED, " \
                                                 "seen after the drill"
                res = DrillResult(DrillOutcome.REACTED, ms, waited, state.name, emcy, note)
            else:
                res = DrillResult(DrillOutcome.NO_REACTION, None, waited, State.OPERATION_ENABLED.name, emcy,
                                  "still OPERATION ENABLED when the drill ended")
            d.master_loss = MasterLossRecord(d.master_loss.reaction, res, d.master_loss.external_watchdog)
        for d in drives:
            yield from self._power_down_by_sdo(d)
        bad = [d for d in drives if d.master_loss.drill.outcome is DrillOutcome.NO_REACTION]
        if bad and not self.c.external_watchdog:
            d = bad[0]
            res = d.master_loss.drill
            seen = ", ".join(f"0x{c:04X}" for c in res.emcy) or "none"
            also = "".join(f"; {o.plan.node.spec.label}: did not react either" for o in bad[1:])
            raise MasterLossReactionError(
                f"{d.plan.node.spec.label}: did not react to the master's death: the master was silent "
                f"{res.waited_ms:.0f} ms (its consumer time 0x1016:01 is {self.consumer_ms} ms) and the drive stayed "
                f"OPERATION ENABLED (EMCY seen: {seen}){also}; the check is not started. State the rig's other "
                f"protection in canopen.external_watchdog, or repair the drive's reaction (0x6007, 0x1029)")

    def _statusword(self, d: DriveSetup, soft: bool = False) -> Generator:
        """The drive's statusword by SDO (told to the master's view of it); with ``soft`` a timeout is returned."""
        node = d.plan.node
        sw = yield from self._read(node, 0x6041, 0, "statusword", soft=soft)
        if isinstance(sw, (SdoTimeout, SdoAbortError)):
            if isinstance(sw, SdoAbortError):
                raise sw
            return sw
        sw = int(sw)
        if self._on_status is not None:
            self._on_status(node.spec.node_id, sw, (yield Now()))
        return sw

    def _power_up_by_sdo(self, d: DriveSetup) -> Generator:
        """CSP, target = actual position, then the walk to OPERATION_ENABLED by SDO (pre-operational)."""
        node = d.plan.node
        pos = yield from self._read(node, 0x6064, 0, "position actual value")
        yield from self._write(node, 0x607A, 0, int(pos), "target position (hold)")
        if d.plan.mode_by_pdo:
            yield from self._set_mode_by_sdo(d, OperationMode.CSP)
        yield from self._walk(d, Goal.ENABLED)

    def _power_down_by_sdo(self, d: DriveSetup) -> Generator:
        yield from self._walk(d, Goal.DISABLED)

    def _walk(self, d: DriveSetup, goal: Goal) -> Generator:
        """Controlwords by SDO as :class:`hil.master.powerup.PowerWalk` says, each statusword read by SDO after
        the last command, until the drive is there (bounded: fault resets, ``canopen.enable_timeout_s``)."""
        node = d.plan.node
        walk = PowerWalk(node.spec.label, goal, (yield Now()), self.c.enable_timeout_s, self.c.fault_reset_attempts)
        while True:
            sw = yield from self._statusword(d)
            step = walk.on_statusword(sw, (yield Now()))
            if step.done:
                return
            if step.failed:
                err = ""
                if step.in_fault and node.can_read(0x603F, 0):
                    code = yield from self._read(node, 0x603F, 0, "error code", soft=True)
                    if not isinstance(code, (SdoAbortError, SdoTimeout)):
                        err = f", error code 0x603F = 0x{int(code):04X}"
                key = "canopen.fault_reset_attempts" if "fault_reset_attempts" in step.failed else \
                    "canopen.enable_timeout_s"
                raise PreflightError(step.failed + err, key)
            for cw in step.controlwords:
                yield from self._write(node, 0x6040, 0, cw, f"controlword ({step.what})")
            if step.controlwords:
                walk.sent((yield Now()))
            yield Wait((yield Now()) + self.T)
