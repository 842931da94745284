"""The rig's CANopen plan: the signal map checked against each node's EDS, PDO layouts computed (pure).

:func:`plan_rig` takes the :class:`~hil.canopen.signalmap.SignalMap` of an
actuation profile and the object dictionary of every node (parsed from its
EDS) and returns a :class:`RigPlan`: per node the PDOs the check uses (count,
entries, COB-IDs, transmission types, from what the map needs and what the
EDS allows), where each signal lands in them (:class:`Channel`), how each EMA
holds a force (CST or the master's force loop in CSP) and the bus load. Every
problem found is collected, each naming its profile key and object
(:class:`Problem`), and raised together as :class:`PlanError`: ``emacheck
profile check`` prints them, ``run`` and ``dry-run`` refuse to send a frame.

Planning rules
--------------
* Inputs of the check (motor angle, LVDT, force, statusword, modes display)
  go into synchronous TPDOs (transmission type 1), outputs (controlword,
  target position, target torque) into synchronous RPDOs, the modes of
  operation into an event-driven RPDO (type 255) of its own, sent only on a
  mode change. Objects are packed first-fit in signal order, at most 64 bits
  and the mapping record's number of entries per PDO.
* A PDO whose mapping the EDS fixes (sub-index 0 not writable) is used as it
  is when it carries a needed object; what else it carries is decoded and
  ignored. Every other PDO of a node that its EDS enables is disabled.
* COB-IDs: the profile's ``canopen.cob_ids`` first, else CiA 301's
  predefined connection set for PDOs 1..4, else the EDS default; a COB-ID the
  EDS fixes stays. All COB-IDs must be distinct, valid for a PDO (CiA 301
  restricted identifiers excluded) and clear of every node's SYNC, EMCY,
  SDO, NMT and heartbeat identifiers, the master's heartbeat included.
* A drive's force control (``canopen.force_control``): CST needs 0x6071 and
  0x6060 RPDO-mappable, 0x6061 TPDO-mappable, the rated torque (0x6076 or
  ``rated_torque_Nm``) and, where the EDS says, CST in 0x6502; ``auto``
  takes CST where all of that holds and CSP otherwise (the master's force
  loop on the measured force). A drive whose EDS announces neither CSP nor
  CST in 0x6502 is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType

import canopen.objectdictionary as cod
from canopen.objectdictionary import datatypes as dt

from hil.canopen.busload import BusLoad, bus_load
from hil.canopen.errors import CanopenError
from hil.canopen.od import type_name
from hil.canopen.pdo import TYPE_BITS, Direction, MappedObject, PdoLayout, PdoSpec
from hil.canopen.pdoplan import RESTRICTED_CAN_IDS, EdsView, Need, PdoPacker
from hil.canopen.signalmap import (
    DeviceProfile,
    ForceControl,
    NodeRole,
    NodeSpec,
    Scale,
    ScaleSource,
    Signal,
    SignalEntry,
    SignalMap,
    object_name,
)

__all__ = ["Channel", "DrivePlan", "NodePlan", "PlanError", "Problem", "RigPlan", "plan_rig",
           "RESTRICTED_CAN_IDS", "CSP_BIT", "CST_BIT"]

#: The data types CiA 402 gives the drive objects the check exchanges every cycle.
CIA402_TYPES = {(0x6040, 0): dt.UNSIGNED16, (0x6041, 0): dt.UNSIGNED16, (0x6060, 0): dt.INTEGER8,
                (0x6061, 0): dt.INTEGER8, (0x6064, 0): dt.INTEGER32, (0x6071, 0): dt.INTEGER16,
                (0x607A, 0): dt.INTEGER32}
CSP_BIT = 7  #: 0x6502 bit of cyclic synchronous position
CST_BIT = 9  #: 0x6502 bit of cyclic synchronous torque

#: Signals in the order they are packed into PDOs.
_TX_ORDER = (Signal.STATUSWORD, Signal.MOTOR_ANGLE, Signal.MODE_DISPLAY, Signal.LVDT, Signal.FORCE)
_RX_ORDER = (Signal.CONTROLWORD, Signal.TARGET_POSITION, Signal.TARGET_TORQUE)


@dataclass(frozen=True, slots=True)
class Problem:
    """One reason a profile cannot run on its rig: the profile key, the object, what is wrong."""

    key: str
    obj: str | None
    message: str

    def __str__(self) -> str:
        return f"{self.key}: {self.obj}: {self.message}" if self.obj else f"{self.key}: {self.message}"


class PlanError(CanopenError, ValueError):
    """The profile, its signal map and the nodes' EDS files do not fit together; lists every problem."""

    bad_input = True  #: the command layer exits 3 (bad input)

    def __init__(self, problems: tuple[Problem, ...] | list[Problem]) -> None:
        self.problems = tuple(problems)
        n = len(self.problems)
        super().__init__(f"the profile and its nodes' EDS files do not fit together ({n} problem{'s' * (n != 1)}):"
                         + "".join(f"\n  {p}" for p in self.problems))


@dataclass(frozen=True, slots=True)
class Channel:
    """Where one signal of the map lands in the layout.

    Attributes
    ----------
    signal : Signal
    ema : int
    node_id : int
        The node whose PDO carries it.
    cob_id : int
        That PDO's COB-ID.
    position : int
        Index of the value in the PDO's unpacked tuple (entry order).
    data_type : int
        The object's data type (CiA 301 code).
    scale : Scale or None
        raw -> SI; None until resolved from the drive (``source`` not PROFILE), and for words.
    source : ScaleSource
    key : str
        The profile key of the signal.
    """

    signal: Signal
    ema: int
    node_id: int
    cob_id: int
    position: int
    data_type: int
    scale: Scale | None
    source: ScaleSource
    key: str


@dataclass(frozen=True, slots=True)
class NodePlan:
    """One node's part of the plan.

    Attributes
    ----------
    spec : NodeSpec
    layout : PdoLayout
    readable, writable : frozenset of (int, int)
        The objects the node's EDS has that the master may read / write by SDO.
    types : Mapping
        (index, subindex) -> data type (CiA 301 code) of every object of the node's EDS.
    eds : str
        The EDS file name (for messages).
    """

    spec: NodeSpec
    layout: PdoLayout
    readable: frozenset[tuple[int, int]]
    writable: frozenset[tuple[int, int]]
    types: Mapping[tuple[int, int], int]
    eds: str

    def can_read(self, index: int, subindex: int = 0) -> bool:
        return (index, subindex) in self.readable

    def can_write(self, index: int, subindex: int = 0) -> bool:
        return (index, subindex) in self.writable


@dataclass(frozen=True, slots=True)
class DrivePlan:
    """What the preflight does with one EMA's drive besides its PDOs.

    Attributes
    ----------
    ema : int
    node : NodePlan
    force_control : ForceControl
        CST or CSP (never AUTO).
    mode_by_pdo : bool
        The modes of operation 0x6060 travels in an RPDO (CST in use); else it is set to CSP once by SDO.
    angle_source, torque_source : ScaleSource
        Where the motor angle and the torque scales come from.
    reaction : bool
        The drive's own reaction to the master's death (0x1016:01, 0x6007) is configured; False
        only under ``canopen.external_watchdog`` for a drive that lacks it.
    """

    ema: int
    node: NodePlan
    force_control: ForceControl
    mode_by_pdo: bool
    angle_source: ScaleSource
    torque_source: ScaleSource | None
    reaction: bool


@dataclass(frozen=True, slots=True)
class RigPlan:
    """The checked signal map, every node's PDO layout and the bus load.

    Attributes
    ----------
    map : SignalMap
        With every entry's data type filled in from its EDS.
    nodes : tuple of NodePlan
        Drive of EMA 1, of EMA 2, then the sensor nodes.
    drives : tuple of DrivePlan
        EMA 1, EMA 2.
    channels : tuple of Channel
        Every signal of the map in the layout.
    load : BusLoad
    notes : tuple of str
        What the engineer should know (a drive holding forces in CSP, a PDO fixed by the EDS, ...).
    """

    map: SignalMap
    nodes: tuple[NodePlan, ...]
    drives: tuple[DrivePlan, DrivePlan]
    channels: tuple[Channel, ...]
    load: BusLoad
    notes: tuple[str, ...]
    gear_ratio_object: tuple[int, int] | None = None

    def node(self, name: str) -> NodePlan:
        for n in self.nodes:
            if n.spec.name == name:
                return n
        raise KeyError(name)

    def channel(self, ema: int, signal: Signal) -> Channel | None:
        for c in self.channels:
            if c.ema == ema and c.signal is signal:
                return c
        return None

    @property
    def tx_pdos(self) -> tuple[PdoSpec, ...]:
        return tuple(p for n in self.nodes for p in n.layout.pdos if p.direction is Direction.TX)

    @property
    def rx_pdos(self) -> tuple[PdoSpec, ...]:
        return tuple(p for n in self.nodes for p in n.layout.pdos if p.direction is Direction.RX)


# --------------------------------------------------------------------------- EDS views


class _Planner:
    def __init__(self, smap: SignalMap, ods: Mapping[str, cod.ObjectDictionary], eds_names: Mapping[str, str],
                 *, bitrate_bps: int, sync_period_s: float, master_node_id: int,
                 master_heartbeat_period_s: float, external_watchdog: bool,
                 gear_ratio_object: tuple[int, int] | None, i_total_rad_per_mm: float,
                 max_bus_load: float) -> None:
        self.smap = smap
        self.eds = {n.name: EdsView(ods[n.name], eds_names.get(n.name, n.eds)) for n in smap.nodes}
        self.bitrate = bitrate_bps
        self.T = sync_period_s
        self.master_node_id = master_node_id
        self.master_hb = master_heartbeat_period_s
        self.watchdog = external_watchdog
        self.gear_ratio_object = gear_ratio_object
        self.i_total = i_total_rad_per_mm
        self.max_load = max_bus_load
        self.problems: list[Problem] = []
        self.notes: list[str] = []

    def problem(self, key: str, obj: str | None, message: str) -> None:
        self.problems.append(Problem(key, obj, message))

    # ------------------------------------------------------------ objects

    def _check_entry(self, e: SignalEntry, *, pdo: bool) -> SignalEntry | None:
        """The entry with its EDS data type, or None (and a problem) if its object cannot serve."""
        where = e.where
        if e.node not in self.eds:
            self.problem(e.key, None, f"node {e.node!r} is not a node of the rig (the drives ema1, ema2 or a "
                                      f"[nodes.NAME] table)")
            return None
        eds = self.eds[e.node]
        if e.signal.drive_only and self.smap.node(e.node).role is not NodeRole.DRIVE:
            self.problem(e.key, where, "this signal must live on the EMA's own drive")
            return None
        var = eds.var(e.index, e.subindex)
        if var is None:
            self.problem(e.key, where, f"no such object in {eds.name}")
            return None
        ok = True
        dtype = var.data_type if e.data_type is None else e.data_type  # a stated type overrides the EDS's
        if dtype != var.data_type:
            self.notes.append(f"{e.key}.type = {type_name(dtype)} overrides {eds.name}'s {type_name(var.data_type)} "
                              f"for {where}: the drive is taken to send what the profile states")
        std = CIA402_TYPES.get(e.object)
        if e.data_type is None and std is not None and var.data_type != std and e.node.startswith("ema"):
            self.problem(e.key, where, f"data type {type_name(var.data_type)} in {eds.name}, CiA 402 says "
                                       f"{type_name(std)}: state the type the drive sends ({e.key}.type): the "
                                       f"EDS's if it is right, else the one that overrides it")
            ok = False
        if pdo and dtype not in TYPE_BITS:
            self.problem(e.key, where, f"data type {type_name(dtype)} cannot be carried in a PDO "
                                       f"(integers of 8..64 bits and REAL32 only)")
            ok = False
        if e.signal.direction is Direction.RX and not var.writable:
            self.problem(e.key, where, f"is not writable in {eds.name} (access {var.access_type})")
            ok = False
        if e.signal.direction is Direction.TX and not var.readable:
            self.problem(e.key, where, f"is not readable in {eds.name} (access {var.access_type})")
            ok = False
        if pdo and not var.pdo_mappable:
            self.problem(e.key, where, f"is not PDO-mappable in {eds.name}")
            ok = False
        if e.scale is None and e.source is ScaleSource.PROFILE and e.signal in _PHYSICAL:
            self.problem(e.key, where, "has no scaling")
            ok = False
        return replace(e, data_type=dtype) if ok else None

    def _require(self, node: NodeSpec, index: int, subindex: int, what: str, key: str, *,
                 write: bool = False, read: bool = True, why: str = "") -> bool:
        eds = self.eds[node.name]
        var = eds.var(index, subindex)
        where = f"{object_name(index, subindex)} ({what}) at {node.name}"
        tail = f": {why}" if why else ""
        if var is None:
            self.problem(key, where, f"not in {eds.name}{tail}")
            return False
        if read and not var.readable:
            self.problem(key, where, f"not readable in {eds.name}{tail}")
            return False
        if write and not var.writable:
            self.problem(key, where, f"not writable in {eds.name} (access {var.access_type}){tail}")
            return False
        return True

    # ------------------------------------------------------------ the plan

    def plan(self) -> RigPlan:
        entries: list[SignalEntry] = []
        drive_info = []
        for node in self.smap.nodes:
            self._check_node(node)
        for ema, node in ((1, self.smap.node("ema1")), (2, self.smap.node("ema2"))):
            info, ents = self._plan_drive(ema, node)
            drive_info.append(info)
            entries += ents
        for e in self.smap.entries:
            if e.signal in (Signal.LVDT, Signal.FORCE):
                checked = self._check_entry(e, pdo=True)
                if checked is not None:
                    entries.append(checked)
        for ema in (1, 2):
            for sig in (Signal.MOTOR_ANGLE, Signal.LVDT, Signal.FORCE):
                if not any(x.ema == ema and x.signal is sig for x in self.smap.entries):
                    self.problem(f"signals.ema{ema}.{sig.value}", None, "missing: where does the check read it?")
        layouts, channels = self._layouts(entries, drive_info)
        stated = {(e.node, e.index, e.subindex): e.data_type for e in entries if e.data_type is not None}
        nodes = tuple(self._node_plan(n, layouts[n.name], stated) for n in self.smap.nodes)
        drives = tuple(DrivePlan(ema, nodes[ema - 1], fc, fc is ForceControl.CST, angle_src, torque_src, reaction)
                       for ema, (fc, angle_src, torque_src, reaction) in zip((1, 2), drive_info, strict=True))
        load = self._load(layouts)
        if self.problems:
            raise PlanError(_merged(self.problems))
        smap = replace(self.smap, entries=tuple(entries))
        return RigPlan(smap, nodes, drives, tuple(channels), load, tuple(self.notes), self.gear_ratio_object)

    def _check_node(self, node: NodeSpec) -> None:
        eds = self.eds[node.name]
        key = f"{node.key}.eds"
        self._require(node, 0x1000, 0, "device type", key)
        # 0x1018:02..04 are optional (CiA 301): the preflight reads them from the node where the EDS is silent
        self._require(node, 0x1018, 1, "vendor-ID", key)
        self._require(node, 0x1017, 0, "producer heartbeat time", key, write=True,
                      why="the master sets and watches every node's heartbeat")
        devtype = eds.default(0x1000, 0)
        if isinstance(devtype, int) and devtype & 0xFFFF != node.device_profile:
            self.problem(f"{node.key}.device_profile" if node.role is NodeRole.SENSORS else key,
                         f"0x1000:00 (device type) at {node.name}",
                         f"{eds.name} says device profile {devtype & 0xFFFF} (0x{devtype:08X}), "
                         f"the profile expects {node.device_profile}")
        self._check_identity(node, eds)

    def _check_identity(self, node: NodeSpec, eds: EdsView) -> None:
        """The EDS must describe the node the profile expects: its 0x1018 defaults and its ``[DeviceInfo]``
        numbers agree with each other and with the profile (0 or absent: the EDS does not say)."""
        info = getattr(eds.od, "device_information", None)
        for sub, field_name, info_name, info_key, want, exact in (
                (1, "vendor_id", "VendorNumber", "vendor_number", node.vendor_id, True),
                (2, "product_code", "ProductNumber", "product_number", node.product_code, True),
                (3, "revision_min", "RevisionNumber", "revision_number", node.revision_min, False)):
            have = eds.default(0x1018, sub)
            have = have if isinstance(have, int) and have else None
            declared = getattr(info, info_key, None)
            declared = declared if isinstance(declared, int) and declared else None
            obj = f"0x1018:{sub:02X} at {node.name}"
            if have is not None and declared is not None and declared != have:
                self.problem(f"{node.key}.eds", obj, f"{eds.name}: [DeviceInfo] {info_name} = 0x{declared:08X} but the "
                                                     f"identity object defaults to 0x{have:08X}: the file contradicts "
                                                     f"itself")
            value, what = (have, f"identity 0x1018:{sub:02X}") if have is not None else (declared, info_name)
            if value is None:
                continue  # the EDS does not say: the preflight reads it from the node
            if not (value == want if exact else value >= want):
                self.problem(f"{node.key}.{field_name}", obj,
                             f"{eds.name}: {what} = 0x{value:08X} does not match the profile's {node.key}.{field_name} "
                             f"= 0x{want:08X}: the EDS describes another device")

    def _plan_drive(self, ema: int, node: NodeSpec):
        """Check one EMA's drive; returns ((force control, angle source, torque source, reaction), entries).

        The steps, in the order their problems are listed: the drive modes it announces, the cyclic
        objects every check needs, the motor angle's scaling, the force control (CST or the master's
        force loop in CSP) and its objects, the reaction to the master's death, the gear ratio object."""
        smap = self.smap
        modes, cst_eds = self._drive_modes(ema, node)
        ents = self._cyclic_entries(ema, node)
        angle_src = self._angle_source(ema, node)
        torque, mode, display = (smap.entry(ema, sig) for sig in (Signal.TARGET_TORQUE, Signal.MODE,
                                                                   Signal.MODE_DISPLAY))
        fc = smap.force_control
        reasons = self._no_cst_reasons(ema, node, modes, cst_eds, torque, mode, display)
        if fc is ForceControl.CST and reasons:
            for r in reasons:
                self.problem("canopen.force_control", None, f"EMA {ema}: CST is asked for, but {r}")
        use_cst = fc is ForceControl.CST or (fc is ForceControl.AUTO and not reasons)
        fc_eff = ForceControl.CST if use_cst else ForceControl.CSP
        if fc_eff is ForceControl.CSP and ema == 1:
            self.notes.append("the EMAs hold forces by the master's own force loop on the measured force in CSP "
                              + ("(canopen.force_control = \"csp\")" if fc is ForceControl.CSP
                                 else f"(no CST: {reasons[0]})"))
        torque_src = None
        if use_cst:
            for e in (torque, mode, display):
                checked = self._check_entry(e, pdo=True)
                if checked is not None:
                    ents.append(checked)
            torque_src = torque.source
        else:
            ents += self._csp_mode_entries(node, mode, display)
        reaction = self._master_loss_reaction(node)
        self._check_gear_ratio(node)
        return (fc_eff, angle_src, torque_src, reaction), ents

    def _drive_modes(self, ema: int, node: NodeSpec) -> tuple[object, bool]:
        """0x6502 (supported drive modes) required, CSP announced; returns (0x6502's default, CST possible)."""
        eds = self.eds[node.name]
        key = f"{node.key}.eds"
        self._require(node, 0x6502, 0, "supported drive modes", key)
        modes = eds.default(0x6502, 0)
        cst_eds = not isinstance(modes, int) or bool(modes >> CST_BIT & 1)
        if isinstance(modes, int) and not (modes >> CSP_BIT & 1):
            what = "neither CSP nor CST" if not modes >> CST_BIT & 1 else "no CSP"
            self.problem(key, f"0x6502:00 (supported drive modes) at {node.name}",
                         f"{eds.name} announces {what} (0x6502 = 0x{modes:08X}): the check commands "
                         f"positions in cyclic synchronous position mode (CSP, 8)")
        return modes, cst_eds

    def _cyclic_entries(self, ema: int, node: NodeSpec) -> list[SignalEntry]:
        """The statusword, motor angle, controlword and target position: given, on the drive (the motor
        angle may come from another node), in PDOs; returns the checked entries."""
        ents = []
        for sig in (Signal.STATUSWORD, Signal.MOTOR_ANGLE, Signal.CONTROLWORD, Signal.TARGET_POSITION):
            e = self.smap.entry(ema, sig)
            if e is None:
                self.problem(f"signals.ema{ema}.{sig.value}", None, "missing")
                continue
            if e.node != node.name and sig is not Signal.MOTOR_ANGLE:
                self.problem(e.key, e.where, f"must live on EMA {ema}'s drive ({node.name})")
                continue
            checked = self._check_entry(e, pdo=True)
            if checked is not None:
                ents.append(checked)
        return ents

    def _angle_source(self, ema: int, node: NodeSpec) -> ScaleSource:
        """Where the motor angle's scaling comes from; the objects it is read from required on the drive."""
        angle = self.smap.entry(ema, Signal.MOTOR_ANGLE)
        angle_src = angle.source if angle is not None else ScaleSource.PROFILE
        if angle is not None and angle.node == node.name:
            for i, s in angle_src.read_objects:
                self._require(node, i, s, "position scaling", angle.key,
                              why=f"the motor angle's scaling is {angle_src.value} as read from the drive")
        return angle_src

    def _no_cst_reasons(self, ema: int, node: NodeSpec, modes, cst_eds: bool, torque: SignalEntry | None,
                        mode: SignalEntry | None, display: SignalEntry | None) -> list[str]:
        """Why cyclic synchronous torque mode cannot be used on this drive (empty: it can)."""
        eds = self.eds[node.name]
        reasons = []
        if torque is None:
            reasons.append(f"signals.ema{ema}.target_torque is not given")
        else:
            v = eds.var(torque.index, torque.subindex)
            if v is None or not v.pdo_mappable or not v.writable:
                reasons.append(f"{torque.where} (target torque) is not a writable, PDO-mappable object of {eds.name}")
            if torque.source is ScaleSource.RATED_TORQUE and not eds.readable(0x6076, 0):
                reasons.append(f"0x6076 (motor rated torque) is not in {eds.name} and "
                               f"signals.ema{ema}.target_torque.rated_torque_Nm is not given")
        if not cst_eds:
            reasons.append(f"0x6502 of {eds.name} announces no CST (0x6502 = 0x{modes:08X})")
        for sig, obj in ((Signal.MODE, mode), (Signal.MODE_DISPLAY, display)):
            if obj is None:
                reasons.append(f"signals.ema{ema}.{sig.value} is not given")
                continue
            v = eds.var(obj.index, obj.subindex)
            if v is None or not v.pdo_mappable:
                reasons.append(f"{obj.where} ({sig.value.replace('_', ' ')}) is not PDO-mappable in {eds.name}")
        return reasons

    def _csp_mode_entries(self, node: NodeSpec, mode: SignalEntry | None,
                          display: SignalEntry | None) -> list[SignalEntry]:
        """CSP only: the mode is set once by SDO and its display read back (in a PDO where it can be)."""
        eds = self.eds[node.name]
        ents = []
        if mode is not None and self._require(node, mode.index, mode.subindex, "modes of operation", mode.key,
                                              write=True, read=False):
            ents.append(replace(mode, data_type=eds.var(mode.index, mode.subindex).data_type))
        if display is not None:
            v = eds.var(display.index, display.subindex)
            if v is not None and v.pdo_mappable and v.readable and v.data_type in TYPE_BITS:
                ents.append(replace(display, data_type=v.data_type))
            else:
                self._require(node, display.index, display.subindex, "modes of operation display",
                              display.key)
        return ents

    def _master_loss_reaction(self, node: NodeSpec) -> bool:
        """Whether the drive can be set to stop by itself when the master dies (0x1016:01 and 0x6007
        writable); required unless the profile states an external watchdog."""
        eds = self.eds[node.name]
        if not self.watchdog:
            why = ("the drive must stop by itself when the master dies; a rig with another protection states "
                   "it in canopen.external_watchdog")
            ok = self._require(node, 0x1016, 1, "consumer heartbeat time", "canopen.external_watchdog",
                               write=True, why=why)
            ok &= self._require(node, 0x6007, 0, "abort connection option code", "canopen.external_watchdog",
                                write=True, why=why)
            return ok
        return eds.writable(0x1016, 1) and eds.writable(0x6007, 0)

    def _check_gear_ratio(self, node: NodeSpec) -> None:
        """The profile's gear ratio object, where given: on the drive and a REAL32 or REAL64."""
        if self.gear_ratio_object is None:
            return
        gi, gs = self.gear_ratio_object
        if self._require(node, gi, gs, "gear ratio", "canopen.gear_ratio_object"):
            t = self.eds[node.name].var(gi, gs).data_type
            if t not in (dt.REAL32, dt.REAL64):
                self.problem("canopen.gear_ratio_object", f"{object_name(gi, gs)} at {node.name}",
                             f"has type {type_name(t)}; the gear ratio is read as REAL32 or REAL64 [rad/mm]")

    # ------------------------------------------------------------ PDOs

    def _needs(self, entries: list[SignalEntry], drive_info) -> dict[str, list[Need]]:
        needs: dict[str, list[Need]] = {n.name: [] for n in self.smap.nodes}
        order = {s: k for k, s in enumerate(_TX_ORDER + _RX_ORDER + (Signal.MODE,))}
        for ema in (1, 2):
            fc = drive_info[ema - 1][0]
            for e in sorted((x for x in entries if x.ema == ema), key=lambda x: order[x.signal]):
                if e.signal is Signal.MODE and fc is not ForceControl.CST:
                    continue  # set once by SDO
                group = ("rx_event" if e.signal is Signal.MODE else
                         "rx" if e.signal.direction is Direction.RX else "tx")
                obj = MappedObject(e.signal.value, e.index, e.subindex, e.data_type)
                needs[e.node].append(Need(e, obj, group))
        return needs

    def _layouts(self, entries: list[SignalEntry], drive_info):
        needs = self._needs(entries, drive_info)
        packer = PdoPacker(self.smap, self.eds, self.problem, self.notes, self.master_node_id)
        layouts: dict[str, PdoLayout] = {}
        channels: list[Channel] = []
        for node in self.smap.nodes:
            layout, placed = packer.node_layout(node, needs[node.name])
            layouts[node.name] = layout
            for need, cob, pos in placed:
                e = need.entry
                channels.append(Channel(e.signal, e.ema, node.node_id, cob, pos, e.data_type, e.scale, e.source, e.key))
        packer.check_cob_ids(layouts)
        return layouts, channels

    def _node_plan(self, node: NodeSpec, layout: PdoLayout, stated: Mapping[tuple, int]) -> NodePlan:
        """The node's readable and writable objects and their data types: the EDS's, where the profile
        states a type (``signals.emaN.SIGNAL.type``) that one."""
        od = self.eds[node.name].od
        readable, writable, types = set(), set(), {}
        for index in od:
            obj = od[index]
            vars_ = [(0, obj)] if isinstance(obj, cod.ODVariable) else list(obj.subindices.items())
            for sub, v in vars_:
                types[(index, sub)] = stated.get((node.name, index, sub), v.data_type)
                if v.readable:
                    readable.add((index, sub))
                if v.writable:
                    writable.add((index, sub))
        return NodePlan(node, layout, frozenset(readable), frozenset(writable), MappingProxyType(types),
                        self.eds[node.name].name)

    def _load(self, layouts: dict[str, PdoLayout]) -> BusLoad:
        periods = [n.heartbeat_period_s for n in self.smap.nodes]
        load = bus_load(tuple(layouts.values()), self.bitrate, self.T, periods,
                        master_heartbeat_period_s=self.master_hb)
        if load.load_worst >= self.max_load:
            self.problem("canopen.bitrate_bps", None,
                         f"the PDO layout loads the bus to {load.load_worst:.1%} in the worst case at "
                         f"{self.bitrate} bit/s and a {self.T * 1e3:g} ms SYNC, not below {self.max_load:.0%}")
        return load


_PHYSICAL = (Signal.MOTOR_ANGLE, Signal.LVDT, Signal.FORCE, Signal.TARGET_POSITION, Signal.TARGET_TORQUE)


def _merged(problems: list[Problem]) -> list[Problem]:
    """Problems that differ only in the drive they were found at (``at ema1``, ``at ema2``: both drives
    share the EDS) said once, ``at ema1, ema2``."""
    out: list[Problem] = []
    seen: dict[tuple, int] = {}
    for p in problems:
        obj = p.obj or ""
        base = obj.rsplit(" at ", 1)[0] if obj.endswith((" at ema1", " at ema2")) else None
        key = (p.key, base, p.message)
        if base is not None and key in seen:
            k = seen[key]
            out[k] = Problem(p.key, f"{out[k].obj}, {obj.rsplit(' at ', 1)[1]}", p.message)
            continue
        if base is not None:
            seen[key] = len(out)
        out.append(p)
    return out


def plan_rig(smap: SignalMap, ods: Mapping[str, cod.ObjectDictionary], *, eds_names: Mapping[str, str] | None = None,
             bitrate_bps: int, sync_period_s: float, master_node_id: int, master_heartbeat_period_s: float,
             external_watchdog: bool, gear_ratio_object: tuple[int, int] | None = None,
             i_total_rad_per_mm: float, max_bus_load: float = 0.5) -> RigPlan:
    """Check a signal map against the nodes' object dictionaries and plan the PDO layouts.

    Parameters
    ----------
    smap : SignalMap
        The rig's nodes and signals, from the actuation profile.
    ods : mapping
        Node name -> ``canopen.ObjectDictionary`` of its EDS (``$NODEID`` resolved for its node id).
    eds_names : mapping, optional
        Node name -> the EDS file name quoted in problems (default: the profile's).
    bitrate_bps, sync_period_s : int, float
        Bus bit rate [bit/s] and SYNC period [s] (bus load).
    master_node_id : int
        The master's own node id (its heartbeat COB-ID is reserved).
    master_heartbeat_period_s : float
        The master's heartbeat period [s] (bus load).
    external_watchdog : bool
        The profile states another protection against the master's death: a drive without
        0x1016/0x6007 is then accepted.
    gear_ratio_object : (int, int), optional
        An object of the drives that reports the gear ratio [rad/mm] for the preflight to compare.
    i_total_rad_per_mm : float
        The gear ratio (torque scaling).
    max_bus_load : float
        Worst-case bus load at which the plan is refused (0.5).

    Returns
    -------
    RigPlan

    Raises
    ------
    PlanError
        Listing every problem, each with its profile key and object.
    """
    if not math.isfinite(sync_period_s) or sync_period_s <= 0:
        raise PlanError([Problem("timing.sync_period_s", None, f"{sync_period_s} must be > 0")])
    return _Planner(smap, ods, eds_names or {}, bitrate_bps=bitrate_bps, sync_period_s=sync_period_s,
                    master_node_id=master_node_id, master_heartbeat_period_s=master_heartbeat_period_s,
                    external_watchdog=external_watchdog, gear_ratio_object=gear_ratio_object,
                    i_total_rad_per_mm=i_total_rad_per_mm, max_bus_load=max_bus_load).plan()


#: Device profiles a node of each role may have.
ROLE_PROFILES = {NodeRole.DRIVE: (DeviceProfile.DRIVE,), NodeRole.SENSORS: (DeviceProfile.IO, DeviceProfile.MEASURING)}
