"""Fault injection for the simulated nodes of the rig (sans-IO, deterministic for a seed).

:class:`FaultInjector` wraps a :class:`sim.drives.SimDrivePair` (the two
drives and the sensor nodes) with the same sans-IO interface (``power_on``,
``on_frame``, ``tick``) and applies a :class:`Fault` schedule to the frames
going in and out of the nodes and to the drives themselves, so the master
sees exactly what a faulty rig would put on the bus. Faults come from the
simulated-rig profile (``[[faults]]`` tables) or from tests. The sensor
faults (``lvdt_*``, ``loadcell_saturation``, ``resolver_wrap``) change the
EMA's reading in whichever TPDO carries it, a drive's or a sensor node's,
through the rig's cycle codec (:class:`hil.canopen.cycle.CycleDecoder`).

Time base: a fault's ``start_s`` is on the check's time axis, the SYNC count
times the SYNC period (``t`` of signals.csv; once SYNC has stopped, for more than
:data:`SYNC_STOPPED_PERIODS` periods, the bus time since SYNC 0, so that a window
such as a ``bus_errors`` burst ends when it says while the drives free-run and
the master reads their state after the check), for every kind but the drive
faults below, which act before SYNC starts (the preflight, the master's-death
drill) as well as after: their ``start_s`` is the bus time since the drives'
power-on (:meth:`FaultInjector.power_on`), so the default ``start_s = 0``
means "built that way", from power-on to the end of the run. ``sdo_abort``
acts whenever its object is accessed. A fault is active for
``start_s <= t < start_s + duration_s``; :attr:`FaultInjector.onset_s` holds
each onset on its own time axis.

Kinds (``value`` is kind-specific; ``ema`` is 1 or 2):

======================  =====================================================
``heartbeat_stop``      the drive's heartbeat frames stop (the drive works on)
``node_silent``         the drive is unreachable: sends nothing, hears nothing
                        (keeps following the last setpoint it received)
``emcy_over_current``   EMCY 0x2310 and the drive goes to FAULT
``emcy_over_temperature`` EMCY 0x4310 and the drive goes to FAULT
``drive_fault``         the drive drops to FAULT without an EMCY (0x5000)
``tpdo_missing``        the drive's TPDOs are lost
``tpdo_late``           the drive's TPDOs arrive ``value`` SYNC cycles late
``rpdo_lost``           RPDOs to the drive are lost (it keeps its last target)
``sdo_abort``           the SDO server aborts access to object ``value``
                        (e.g. 0x1017) with 0x08000020 during the preflight
``lvdt_stuck``          the LVDT reading freezes at its value at onset
``lvdt_spike``          one LVDT reading offset by ``value`` mm
``loadcell_saturation`` the load-cell reading clips at +- ``value`` N
``resolver_wrap``       the position reading jumps by one revolution
``runaway``             the drive ignores its target and moves at ``value``
                        mm/s while OPERATION_ENABLED (its state machine still
                        obeys: quick stop and disable work)
``bus_errors``          every frame to and from the drives is lost with
                        probability ``value`` (error frames, CRC errors)
``master_silent``       the master dies: from ``start_s`` every frame it sends
                        (SYNC, RPDOs, SDO, NMT, its heartbeat) is dropped
                        before the drives (``ema`` ignored); the drives go on
                        on their own clock (free-running cycle, heartbeat
                        consumer, abort connection option 0x6007)
``sensor_node_silent``  the sensor node with node id ``value`` (default the
                        plan's first) stops sending anything: TPDOs,
                        heartbeat, EMCY, SDO responses (``ema`` ignored; a
                        rig without a sensor node is refused)
======================  =====================================================

Wiring faults (a rig wired wrongly, as ``emacheck commission`` must find it; on the check's time axis like
the sensor faults, so the default ``start_s = 0`` means "wired that way"; the reading in the TPDO,
whichever node carries it):

======================  =====================================================
``lvdt_sign``           the LVDT reads the stroke with the wrong sign
``lvdt_scale``          the LVDT reads ``value`` times the stroke (default 0.5)
``lvdt_dead``           the LVDT input reads 0 (a broken wire)
``loadcell_sign``       the load cell reads the force with the wrong sign
``loadcell_scale``      the load cell reads ``value`` times the force (0.5)
``loadcell_dead``       the load-cell input reads 0
``lvdts_swapped``       LVDT 1 reads EMA 2's stroke and LVDT 2 EMA 1's
                        (``ema`` ignored)
``loadcells_swapped``   load cell 1 reads EMA 2's force and load cell 2
                        EMA 1's (``ema`` ignored)
======================  =====================================================

Drive faults (time base: bus time since power-on, see above; ``ema`` is the
drive), behaviours of drives seen in the field that the master's CiA 402
rules must catch or handle:

===========================  ================================================
``ignore_abort_connection``  the drive accepts 0x6007 and reads it back, and
                             its heartbeat consumer sends EMCY 0x8130 on the
                             master's silence, but it does nothing else: it
                             stays OPERATION_ENABLED (the master's-death
                             drill must report no reaction)
``quick_stop_stays``         after a quick stop the drive stays in
                             QUICK_STOP_ACTIVE (holding its position) until
                             disable voltage, whatever 0x605A says (like a
                             lely-based drive seen in the field)
``starts_in_fault``          the drive boots (power-on and every NMT reset
                             node) into FAULT with error code ``value``
                             (default 0x5000) and an EMCY, until one fault
                             reset clears it
``fault_reset_ignored``      as ``starts_in_fault`` (error code 0x5000), and
                             every FAULT of the drive clears only at the
                             ``value``-th fault reset (default 4: one more
                             than the shipped canopen.fault_reset_attempts);
                             the earlier ones are ignored
``mode_not_confirmed``       the modes of operation display 0x6061 does not
                             follow 0x6060 (by SDO or RPDO): the drive keeps
                             running in the mode it shows
``not_ready_until_controlword`` after power-on and every NMT reset node the
                             drive stays in NOT_READY_TO_SWITCH_ON until it
                             receives a controlword (any value, RPDO or SDO),
                             then takes transition 1 to SWITCH_ON_DISABLED
                             (like a CiA 402 slave on lely-core seen in the
                             field); the master's power-up sends disable
                             voltage there (hil/master/powerup.py)
===========================  ================================================

The injector also records the plant's truth after every SYNC and every step
of the drives' own cycle (:attr:`FaultInjector.truth`): true forces and
strokes (no sensor errors) and both drives' CiA 402 states, for tests and
benchmarks; and the bus time of the last frame that reached the drives
(:attr:`FaultInjector.last_inbound_t`, the master's last frame under
``master_silent``).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from dataclasses import replace as _replace
from enum import Enum

import numpy as np

from blf.errors import InputError
from hil.canopen.cia402 import State
from hil.canopen.cycle import CycleDecoder
from hil.canopen.frame import Frame
from hil.canopen.pdo import Direction
from hil.canopen.process import DriveMode
from hil.canopen.signalmap import Scale, Signal

__all__ = ["BOOT_FAULT_CODE", "DRIVE_KINDS", "WIRING_KINDS", "FaultKind", "Fault", "FaultInjector",
           "SYNC_STOPPED_PERIODS", "TruthTrace", "SDO_ABORT_CODE"]

#: SYNC periods without a SYNC after which the check's time axis follows the bus time (SYNC stopped)
SYNC_STOPPED_PERIODS = 2

#: Abort code the ``sdo_abort`` fault answers with: data cannot be transferred or stored.
SDO_ABORT_CODE = 0x08000020


class FaultKind(Enum):
    HEARTBEAT_STOP = "heartbeat_stop"
    NODE_SILENT = "node_silent"
    EMCY_OVER_CURRENT = "emcy_over_current"
    EMCY_OVER_TEMPERATURE = "emcy_over_temperature"
    DRIVE_FAULT = "drive_fault"
    TPDO_MISSING = "tpdo_missing"
    TPDO_LATE = "tpdo_late"
    RPDO_LOST = "rpdo_lost"
    SDO_ABORT = "sdo_abort"
    LVDT_STUCK = "lvdt_stuck"
    LVDT_SPIKE = "lvdt_spike"
    LOADCELL_SATURATION = "loadcell_saturation"
    RESOLVER_WRAP = "resolver_wrap"
    RUNAWAY = "runaway"
    BUS_ERRORS = "bus_errors"
    MASTER_SILENT = "master_silent"
    SENSOR_NODE_SILENT = "sensor_node_silent"
    IGNORE_ABORT_CONNECTION = "ignore_abort_connection"
    QUICK_STOP_STAYS = "quick_stop_stays"
    STARTS_IN_FAULT = "starts_in_fault"
    FAULT_RESET_IGNORED = "fault_reset_ignored"
    MODE_NOT_CONFIRMED = "mode_not_confirmed"
    NOT_READY_UNTIL_CONTROLWORD = "not_ready_until_controlword"
    LVDT_SIGN = "lvdt_sign"
    LVDT_SCALE = "lvdt_scale"
    LVDT_DEAD = "lvdt_dead"
    LOADCELL_SIGN = "loadcell_sign"
    LOADCELL_SCALE = "loadcell_scale"
    LOADCELL_DEAD = "loadcell_dead"
    LVDTS_SWAPPED = "lvdts_swapped"
    LOADCELLS_SWAPPED = "loadcells_swapped"


#: Drive faults: they act from the drives' power-on, before SYNC starts (``start_s`` is the bus time
#: since power-on).
DRIVE_KINDS = frozenset((FaultKind.IGNORE_ABORT_CONNECTION, FaultKind.QUICK_STOP_STAYS,
                         FaultKind.STARTS_IN_FAULT, FaultKind.FAULT_RESET_IGNORED,
                         FaultKind.MODE_NOT_CONFIRMED, FaultKind.NOT_READY_UNTIL_CONTROLWORD))
#: Wiring faults: the rig's sensors wired wrongly (a sign, a scale, a dead input, two LVDTs swapped).
WIRING_KINDS = frozenset((FaultKind.LVDT_SIGN, FaultKind.LVDT_SCALE, FaultKind.LVDT_DEAD, FaultKind.LOADCELL_SIGN,
                          FaultKind.LOADCELL_SCALE, FaultKind.LOADCELL_DEAD, FaultKind.LVDTS_SWAPPED,
                          FaultKind.LOADCELLS_SWAPPED))
#: Error code of a drive that boots into FAULT (``starts_in_fault``, ``fault_reset_ignored``).
BOOT_FAULT_CODE = 0x5000


#: Default ``value`` per kind (None: the kind takes no value).
DEFAULT_VALUE: dict[FaultKind, float | None] = {
    FaultKind.TPDO_LATE: 3.0,  # SYNC cycles
    FaultKind.SDO_ABORT: float(0x1017),  # object index
    FaultKind.LVDT_SPIKE: 2.0,  # mm
    FaultKind.LOADCELL_SATURATION: 2500.0,  # N
    FaultKind.RUNAWAY: 5.0,  # mm/s
    FaultKind.BUS_ERRORS: 0.5,  # loss probability
    FaultKind.STARTS_IN_FAULT: float(BOOT_FAULT_CODE),  # error code
    FaultKind.FAULT_RESET_IGNORED: 4.0,  # fault resets a FAULT takes to clear
    FaultKind.LVDT_SCALE: 0.5,  # reading / true stroke
    FaultKind.LOADCELL_SCALE: 0.5,  # reading / true force
}

_EMCY_CODE = {FaultKind.EMCY_OVER_CURRENT: 0x2310, FaultKind.EMCY_OVER_TEMPERATURE: 0x4310,
              FaultKind.DRIVE_FAULT: 0x5000}


@dataclass(frozen=True)
class Fault:
    """One scheduled fault.

    Parameters
    ----------
    kind : str
        A :class:`FaultKind` value, e.g. ``"heartbeat_stop"``.
    ema : int
        1 or 2 (ignored by ``bus_errors``, which hits every frame).
    start_s : float
        Onset on the check's time axis [s] (SYNC count times the SYNC period); for the drive
        faults (:data:`DRIVE_KINDS`) the bus time since the drives' power-on [s].
    duration_s : float
        How long it lasts [s] (``inf``: to the end; ``lvdt_spike`` lasts one cycle).
    value : float
        Kind-specific, see the module docstring; NaN takes :data:`DEFAULT_VALUE`.
    """

    kind: str
    ema: int = 1
    start_s: float = 0.0
    duration_s: float = math.inf
    value: float = math.nan

    def __post_init__(self) -> None:
        try:
            FaultKind(self.kind)
        except ValueError:
            raise InputError(f"fault kind {self.kind!r} is not known; known: "
                             + ", ".join(k.value for k in FaultKind)) from None
        if self.ema not in (1, 2):
            raise InputError(f"fault {self.kind}: ema = {self.ema!r} must be 1 or 2")
        if not (math.isfinite(self.start_s) and self.start_s >= 0):
            raise InputError(f"fault {self.kind}: start_s = {self.start_s!r} s must be finite and >= 0")
        if not self.duration_s > 0:
            raise InputError(f"fault {self.kind}: duration_s = {self.duration_s!r} s must be > 0")
        if not (math.isnan(self.value) or math.isfinite(self.value)):
            raise InputError(f"fault {self.kind}: value = {self.value!r} must be finite")
        v = self.param
        kind = self.fault_kind
        if kind is FaultKind.FAULT_RESET_IGNORED and not (v == int(v) and 1 <= v <= 1000):
            raise InputError(f"fault {self.kind}: value = {v!r} must be a whole number of fault resets, 1..1000")
        if kind is FaultKind.STARTS_IN_FAULT and not (v == int(v) and 1 <= v <= 0xFFFF):
            raise InputError(f"fault {self.kind}: value = {v!r} must be an error code 0x0001..0xFFFF")
        if kind is FaultKind.SENSOR_NODE_SILENT and not math.isnan(v) and not (v == int(v) and 1 <= v <= 127):
            raise InputError(f"fault {self.kind}: value = {v!r} must be the node id of a sensor node, 1..127")

    @property
    def fault_kind(self) -> FaultKind:
        return FaultKind(self.kind)

    @property
    def param(self) -> float:
        """``value``, or the kind's default."""
        d = DEFAULT_VALUE.get(self.fault_kind)
        return d if math.isnan(self.value) and d is not None else self.value


@dataclass(frozen=True)
class TruthTrace:
    """The plant's truth after every SYNC, arrays of shape (n,) or (n, 2) (column 0 = EMA 1).

    ``t_s`` is on the check's time axis; ``F_N`` true load-path force [N],
    ``s_mm`` true stroke [mm], ``state`` the drives' CiA 402 states (names).
    """

    t_s: np.ndarray
    F_N: np.ndarray
    s_mm: np.ndarray
    state: np.ndarray = field(repr=False)


class FaultInjector:
    """A :class:`sim.drives.SimDrivePair` with faults, as the same sans-IO interface.

    Parameters
    ----------
    pair : sim.drives.SimDrivePair
    faults : sequence of Fault
    rng : numpy.random.Generator
        For the random frame losses of ``bus_errors``.
    record_truth : bool
        Record :attr:`truth` (one plant-state copy per SYNC).
    """

    def __init__(self, pair, faults=(), rng: np.random.Generator | None = None,
                 record_truth: bool = True) -> None:
        self.pair = pair
        self.faults = tuple(faults)
        for f in self.faults:
            if not isinstance(f, Fault):
                raise InputError(f"faults must be sim.faults.Fault, got {type(f).__name__}")
        if any(f.fault_kind is FaultKind.BUS_ERRORS for f in self.faults) and rng is None:
            raise InputError("a bus_errors fault needs rng (numpy.random.Generator)")
        self.rng = rng
        self.T = pair.plant.params.sample_period_s
        self.syncs = 0
        self.record_truth = record_truth
        self._truth: list[tuple] = []
        self._held: list[tuple[int, Frame]] = []  # (due SYNC count, frame) of late TPDOs
        self._stuck: dict[int, float] = {}  # EMA -> frozen LVDT value [mm]
        self._now: dict[tuple[int, Signal], float] = {}  # this SYNC's LVDT [mm] and force [N] (the swaps)
        self._started: set[int] = set()  # indices of faults whose onset happened
        #: kind -> time of the onset: check time, bus time since power-on for the drive faults
        self.onset_s: dict[str, float] = {}
        self.dropped = 0
        self._nodes = {k + 1: n for k, n in enumerate(pair.nodes)}
        plan = pair.plan
        self._tpdos = {n.spec.node_id: frozenset(p.cob_id for p in n.layout.pdos if p.direction is Direction.TX)
                       for n in plan.nodes}
        self._rpdos = {n.spec.node_id: frozenset(p.cob_id for p in n.layout.pdos if p.direction is Direction.RX)
                       for n in plan.nodes}
        self._tpdo_owner = {c: n for n, cobs in self._tpdos.items() for c in cobs}  # COB-ID -> node id
        self._rpdo_owner = {c: n for n, cobs in self._rpdos.items() for c in cobs}
        self._drive_ids = frozenset(n.node_id for n in pair.nodes)
        sensors = getattr(pair, "sensors", ())
        self._silent_sensor: dict[int, int] = {}  # fault index -> sensor node id (sensor_node_silent)
        for k, f in enumerate(self.faults):
            if f.fault_kind is not FaultKind.SENSOR_NODE_SILENT:
                continue
            if not sensors:
                raise InputError(f"fault {f.kind}: the rig has no sensor node (its profile has no [nodes.NAME])")
            ids = [x.node_id for x in sensors]
            nid = ids[0] if math.isnan(f.value) else int(f.value)
            if nid not in ids:
                raise InputError(f"fault {f.kind}: value = {nid} is not a sensor node of the rig "
                                 f"(node ids {', '.join(map(str, ids))})")
            self._silent_sensor[k] = nid
        #: drive faults (time base: bus time since power-on) by fault index, and whether each is on
        self._drive_faults = {k: f for k, f in enumerate(self.faults) if f.fault_kind in DRIVE_KINDS}
        self._drive_on: dict[int, bool] = {}
        self.t_power_on: float | None = None  #: bus time of the drives' (first) power-on [s]
        # the measured inputs of every TPDO, as the simulated nodes scale them
        chans = []
        for ch in plan.channels:
            if ch.scale is None and ch.signal is Signal.MOTOR_ANGLE:
                ch = _replace(ch, scale=Scale(self._nodes[ch.ema].angle_increments_per_rad()))
            chans.append(ch)
        self._codec = CycleDecoder(plan.tx_pdos, [c for c in chans if c.signal.direction is Direction.TX])
        #: bus time [s] of the last frame that reached the drives (None before the first)
        self.last_inbound_t: float | None = None
        self.t0_bus: float | None = None  #: bus time of SYNC 0 (the first SYNC's time less T) [s]
        self._t_bus = 0.0  #: the latest bus time seen [s]
        self._t_sync: float | None = None  #: bus time of the last SYNC [s]
        if record_truth:
            pair.on_free_step = self._free_step

    # ------------------------------------------------------------ delegation

    def __getattr__(self, name: str):
        return getattr(self.pair, name)

    @property
    def t_check(self) -> float:
        """The check's time axis: SYNCs seen times the SYNC period [s]; once SYNC stopped (none for more
        than :data:`SYNC_STOPPED_PERIODS` periods of bus time), the bus time since SYNC 0."""
        t_sync = self._t_sync
        if t_sync is not None and self._t_bus - t_sync > SYNC_STOPPED_PERIODS * self.T + 1e-9:
            return max(self.syncs * self.T, self._t_bus - self.t0_bus)
        return self.syncs * self.T

    def _active(self, kind: FaultKind, node_id: int | None = None) -> list[Fault]:
        t = self.t_check
        out = []
        for f in self.faults:
            if f.fault_kind is not kind:
                continue
            if node_id is not None and self._nodes[f.ema].node_id != node_id and kind is not FaultKind.BUS_ERRORS:
                continue
            dur = self.T * 0.5 if kind is FaultKind.LVDT_SPIKE else f.duration_s
            if kind is FaultKind.SDO_ABORT or (f.start_s - 1e-9 <= t < f.start_s + dur - 1e-9 and self.syncs > 0):
                out.append(f)
        return out

    # ------------------------------------------------------------ onsets

    def _onsets(self) -> list[Frame]:
        """Faults that act once at their onset (EMCY, drive fault, runaway); at a SYNC."""
        out: list[Frame] = []
        t = self.t_check
        for k, f in enumerate(self.faults):
            if k in self._started or k in self._drive_faults or self.syncs == 0 or t < f.start_s - 1e-9:
                continue
            self._started.add(k)
            self.onset_s.setdefault(f.kind, t)
            kind = f.fault_kind
            node = self._nodes[f.ema]
            if kind in (FaultKind.EMCY_OVER_CURRENT, FaultKind.EMCY_OVER_TEMPERATURE):
                out += self.pair.inject_fault(f.ema - 1, _EMCY_CODE[kind])
            elif kind is FaultKind.DRIVE_FAULT:
                node.state_machine.fault(_EMCY_CODE[kind])  # no EMCY: seen only in the statusword
            elif kind is FaultKind.RUNAWAY:
                node.command_override = _runaway(f.param, self.pair.plant.params.i_total_rad_per_mm,
                                                 f.start_s + f.duration_s, self)
        return out

    # ------------------------------------------------------------ frames

    def _inbound_dropped(self, frame: Frame) -> bool:
        cid = frame.arbitration_id
        node = cid & 0x7F
        base = cid & 0x780
        if self._active(FaultKind.MASTER_SILENT):
            return True  # the master is dead: nothing it would send reaches the drives
        if cid != 0x080 and self._active(FaultKind.BUS_ERRORS) and self._lose():
            return True  # (SYNC exempt: the simulated physics advances on it)
        target = node if base == 0x600 else self._rpdo_owner.get(cid)
        if target is not None:
            if self._active(FaultKind.NODE_SILENT, target):
                return True
            if base != 0x600 and self._active(FaultKind.RPDO_LOST, target):
                return True
        return False

    def _lose(self) -> bool:
        p = max(f.param for f in self._active(FaultKind.BUS_ERRORS))
        hit = bool(self.rng.random() < p)
        self.dropped += hit
        return hit

    def _sdo_abort(self, frame: Frame) -> Frame | None:
        cid = frame.arbitration_id
        if cid & 0x780 != 0x600 or len(frame.data) != 8:
            return None
        node = cid & 0x7F
        index = int.from_bytes(frame.data[1:3], "little")
        for f in self._active(FaultKind.SDO_ABORT, node):
            if index == int(f.param):
                self.onset_s.setdefault(f.kind, self.t_check)
                return Frame(0x580 + node, bytes([0x80]) + frame.data[1:4] + struct.pack("<I", SDO_ABORT_CODE))
        return None

    def _outbound(self, frames: list[Frame], at_sync: bool) -> list[Frame]:
        out: list[Frame] = []
        if at_sync and self._held:  # late TPDOs due now, ahead of this SYNC's frames
            out += [self._sensor_faults(f) for k, f in self._held if k <= self.syncs]
            self._held = [(k, f) for k, f in self._held if k > self.syncs]
        drive_ids = self._drive_ids
        if at_sync and (self._active(FaultKind.LVDTS_SWAPPED) or self._active(FaultKind.LOADCELLS_SWAPPED)):
            for fr in frames:  # both readings of this SYNC, before either is changed
                for (ema, sig), v in self._codec.scaled(fr).items():
                    self._now[(ema, sig)] = v
        silent = self._silent_sensors() if self._silent_sensor else ()
        for fr in frames:
            cid = fr.arbitration_id
            node, base = cid & 0x7F, cid & 0x780
            if self._active(FaultKind.BUS_ERRORS) and self._lose():
                continue
            owner = self._tpdo_owner.get(cid)
            if silent and (owner in silent or (owner is None and node in silent and base != 0x000)):
                continue
            if owner is not None:
                if owner in drive_ids:
                    if self._active(FaultKind.NODE_SILENT, owner) or self._active(FaultKind.TPDO_MISSING, owner):
                        continue
                    late = self._active(FaultKind.TPDO_LATE, owner)
                    if late and at_sync:
                        self._held.append((self.syncs + int(late[0].param), fr))
                        continue
                out.append(self._sensor_faults(fr))
                continue
            if node not in drive_ids:
                out.append(fr)
                continue
            if self._active(FaultKind.NODE_SILENT, node):
                continue
            if base == 0x700 and self._active(FaultKind.HEARTBEAT_STOP, node):
                continue
            out.append(fr)
        return out

    def _silent_sensors(self) -> frozenset[int]:
        """Node ids of the sensor nodes silent now (``sensor_node_silent``, check time axis)."""
        t = self.t_check
        if self.syncs == 0:
            return frozenset()
        return frozenset(nid for k, nid in self._silent_sensor.items()
                         if self.faults[k].start_s - 1e-9 <= t
                         < self.faults[k].start_s + self.faults[k].duration_s - 1e-9)

    def _drive_hooks(self, t: float) -> None:
        """Switch the drive faults on or off at bus time ``t`` (their time base: since power-on)."""
        if self.t_power_on is None:
            return
        since = t - self.t_power_on
        for k, f in self._drive_faults.items():
            on = f.start_s - 1e-9 <= since < f.start_s + f.duration_s - 1e-9
            if on == self._drive_on.get(k, False):
                continue
            self._drive_on[k] = on
            if on:
                self.onset_s.setdefault(f.kind, since)
            node = self._nodes[f.ema]
            kind = f.fault_kind
            if kind is FaultKind.IGNORE_ABORT_CONNECTION:
                node.ignore_abort_connection = on
            elif kind is FaultKind.QUICK_STOP_STAYS:
                node.quick_stop_stays = on
            elif kind is FaultKind.MODE_NOT_CONFIRMED:
                node.mode_frozen = on
            elif kind is FaultKind.NOT_READY_UNTIL_CONTROLWORD:
                node.not_ready_until_controlword = on
            elif kind is FaultKind.STARTS_IN_FAULT:
                node.boot_fault = int(f.param) if on else 0
            elif kind is FaultKind.FAULT_RESET_IGNORED:
                node.boot_fault = BOOT_FAULT_CODE if on else 0
                node.fault_resets_needed = int(f.param) if on else 1

    def _sensor_faults(self, fr: Frame) -> Frame:
        """The sensor faults of the EMAs whose measured values ``fr`` carries, applied to those values."""
        values = self._codec.scaled(fr)
        if not values:
            return fr
        changes = {}
        for (ema, sig), v in values.items():
            node = self._nodes[ema].node_id
            if sig is Signal.LVDT:
                x = self._lvdt_wiring(ema, node, v)
                if self._active(FaultKind.LVDT_STUCK, node):
                    x = self._stuck.setdefault(ema, v)
                for f in self._active(FaultKind.LVDT_SPIKE, node):
                    x += f.param
                if x != v:
                    changes[(ema, sig)] = x
            elif sig is Signal.FORCE:
                w = self._now.get((3 - ema, sig), v) if self._active(FaultKind.LOADCELLS_SWAPPED) else v
                x = self._wired(w, node, FaultKind.LOADCELL_SIGN, FaultKind.LOADCELL_SCALE, FaultKind.LOADCELL_DEAD)
                for f in self._active(FaultKind.LOADCELL_SATURATION, node):
                    if abs(x) > f.param:
                        x = math.copysign(f.param, x)
                if x != v:
                    changes[(ema, sig)] = x
            elif sig is Signal.MOTOR_ANGLE and self._active(FaultKind.RESOLVER_WRAP, node):
                changes[(ema, sig)] = v + 2.0 * math.pi
        return self._codec.rescaled(fr, changes) if changes else fr

    def _lvdt_wiring(self, ema: int, node: int, v: float) -> float:
        """The LVDT reading as the rig's wiring makes it (``lvdts_swapped``, then sign, scale, dead)."""
        if self._active(FaultKind.LVDTS_SWAPPED):
            v = self._now.get((3 - ema, Signal.LVDT), v)
        return self._wired(v, node, FaultKind.LVDT_SIGN, FaultKind.LVDT_SCALE, FaultKind.LVDT_DEAD)

    def _wired(self, v: float, node: int, sign: FaultKind, scale: FaultKind, dead: FaultKind) -> float:
        """A reading through a wrong sign, a wrong scale or a dead input of the EMA whose drive is ``node``."""
        if self._active(dead, node):
            return 0.0
        for f in self._active(scale, node):
            v *= f.param
        return -v if self._active(sign, node) else v

    def _node(self, node_id: int):
        return next(n for n in self.pair.nodes if n.node_id == node_id)

    # ------------------------------------------------------------ the sans-IO interface

    def power_on(self, t: float) -> list[Frame]:
        """As :meth:`sim.drives.SimDrivePair.power_on`; the drive faults' time base starts here."""
        if self.t_power_on is None:
            self.t_power_on = float(t)
        if self._drive_faults:
            self._drive_hooks(float(t))
        return self._outbound(self.pair.power_on(t), at_sync=False)

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """As :meth:`sim.drives.SimDrivePair.on_frame`, with the faults applied."""
        is_sync = frame.arbitration_id == 0x080 and len(frame.data) <= 1
        if t > self._t_bus:  # (= max(self._t_bus, t), every frame)
            self._t_bus = t
        if is_sync:
            self._t_sync = t
            self.syncs += 1
            if self.t0_bus is None:
                self.t0_bus = t - self.T
        if not self.faults and not self.record_truth:
            return self.pair.on_frame(frame, t)  # nothing scheduled: the pair as it is
        if self._drive_faults:
            self._drive_hooks(t)
        pre = self._onsets() if is_sync else []
        abort = self._sdo_abort(frame)
        if abort is not None:
            return [abort]
        if self._inbound_dropped(frame):
            return self._outbound(pre, at_sync=False) if pre else []
        self.last_inbound_t = t
        out = self.pair.on_frame(frame, t)
        if is_sync and self.record_truth:
            st = self.pair.plant.state()
            self._truth.append((self.t_check + self.T, st.F_N, st.s_mm,
                                tuple(n.state_machine.state.name for n in self.pair.nodes)))
        return self._outbound(pre + out, at_sync=is_sync)

    def tick(self, t: float) -> list[Frame]:
        self._t_bus = max(self._t_bus, t)
        if not self.faults:
            return self.pair.tick(t)
        if self._drive_faults:
            self._drive_hooks(t)
        return self._outbound(self.pair.tick(t), at_sync=False)

    def _free_step(self, t: float) -> None:
        """Truth after a step of the drives' own cycle at bus time ``t`` (SYNC missing)."""
        if self.t0_bus is None:
            return
        st = self.pair.plant.state()
        self._truth.append((t - self.t0_bus + self.T, st.F_N, st.s_mm,
                            tuple(n.state_machine.state.name for n in self.pair.nodes)))

    # ------------------------------------------------------------ results

    @property
    def truth(self) -> TruthTrace:
        """The plant's truth after every SYNC so far."""
        if not self._truth:
            e = np.empty((0, 2))
            return TruthTrace(np.empty(0), e, e, np.empty((0, 2), dtype=object))
        t, F, s, st = zip(*self._truth, strict=True)
        return TruthTrace(np.asarray(t), np.asarray(F, dtype=float), np.asarray(s, dtype=float),
                          np.asarray(st, dtype=object))

    def final_states(self) -> tuple[State, State]:
        """Both drives' CiA 402 states now (the drives' own view)."""
        return tuple(n.state_machine.state for n in self.pair.nodes)


def _runaway(speed_mm_per_s: float, i_total: float, t_end: float, inj: FaultInjector):
    """Command override of a runaway drive: in OPERATION_ENABLED it commands a ramp
    ``phi(t) = phi_0 + v i (t - t_0)`` whatever its target (``phi_0`` its angle at onset)."""
    start: dict = {}

    def override(node, t: float, mode: int, value: float) -> tuple[int, float]:
        if inj.t_check >= t_end - 1e-9 or node.state_machine.state is not State.OPERATION_ENABLED:
            return mode, value
        if "phi0" not in start:
            start["phi0"], start["t0"] = node.motor_angle_rad, t
        return int(DriveMode.POSITION), start["phi0"] + speed_mm_per_s * i_total * (t - start["t0"])

    return override
