"""Two simulated CiA 402 EMA drives as real CANopen slaves around one rig plant (sans-IO).

:class:`SimDrivePair` replaces the two EMA drives of the rig in dry-runs and
tests. Each node (:class:`SimDrive`) is built from the same EDS the master
reads (``profiles/ema_drive.eds`` through :func:`hil.canopen.od.load_drive_od`)
and serves it with a ``canopen.LocalNode`` (SDO server and data store). The
pair consumes every frame seen on the bus and returns the frames it
transmits; time is passed in. No threads, no clocks, no bus objects: the
caller (an IO shell on a python-can bus, or a test) moves the frames.

What canopen 2.4.1's ``LocalNode`` lacks is implemented here: the NMT slave
(boot-up, NMT commands, heartbeat producer), the PDO engine driven by the
object dictionary (SYNC-driven TPDOs, latched synchronous and event RPDOs,
mapping validation), the EMCY producer and the CiA 402 drive behaviour
(:class:`hil.canopen.cia402.DriveStateMachine`). ``LocalNode`` is used only for the
SDO server (expedited and segmented transfers) and the data store; its own
NMT slave is detached (it would start a periodic heartbeat task on the bus).

Per SYNC (COB-ID of 0x1005, 0x080 by default) the pair, in this order:

1. sends the due synchronous TPDOs of every OPERATIONAL node with the current
   sample (the plant state at this SYNC);
2. applies the synchronous RPDOs latched since the previous SYNC;
3. computes both drives' setpoints and steps the plant once, so that the
   current sample becomes the state at the next SYNC.

A statusword change commanded by a synchronous RPDO therefore shows in the
TPDO of the SYNC after the one that applied it (one cycle of latency, as on
the real bus).

Choices (CiA 301 / CiA 402 leave them open or this drive restricts them)
-------------------------------------------------------------------------
* Power-on: the drives' application boots instantly (CiA 402 transition 1 at
  power-on, NMT INITIALISING -> boot-up frame -> PRE-OPERATIONAL). At the
  first power-on the plant is stepped once with both drives DISABLED, so the
  current sample is the measured rig at rest; this step counts in
  ``stats.plant_steps`` (``plant_steps == syncs + 1``).
* Modes of operation: CSP (8) and CST (10). An SDO write of another value to
  0x6060 is aborted (0x06090030); an RPDO cannot be refused, so a drive whose
  0x6060 holds another value keeps 0x6061 unchanged, clears statusword bit 12
  and commands DISABLED (holding brake), even in OPERATION_ENABLED.
* Quick stop (option code 2): the drive holds the motor angle measured when
  the quick stop began for :data:`QUICK_STOP_HOLD_S` (a fixed 50 ms, counted
  in SYNC cycles of the plant's sample period; 0x6085 is not used), then
  takes transition 12 to SWITCH_ON_DISABLED (brake).
* Fault reaction: FAULT_REACTION_ACTIVE lasts until the next SYNC, then FAULT;
  both command DISABLED. A fault reset (rising edge of controlword bit 7)
  sends EMCY 0x0000.
* Illegal controlwords leave the state unchanged and are counted
  (``stats.illegal_commands``), no EMCY. A repeated controlword is a no-op.
  Bit 8 (halt) is not implemented.
* PDO mapping (CiA 301 7.5.2.35/36 procedure): entries and the number of
  entries can only be written while the PDO is invalid (COB-ID bit 31 set)
  and entries only while sub-index 0 is 0, else abort 0x06040043 (general
  parameter incompatibility). An entry must name an existing, PDO-mappable
  object, readable for a TPDO and writable for an RPDO, with its exact bit
  length (a whole number of bytes, EDS Granularity=8), else 0x06040041.
  Writing sub-index 0 checks the entries and aborts with 0x06040042 when
  they exceed 64 bits (or the number of entries the record has).
* PDO communication: 11-bit COB-IDs only; the CAN-ID cannot change while the
  PDO is valid and a valid PDO cannot use a CiA 301 restricted CAN-ID
  (0x06090030). Transmission types 0..240, 254, 255 (252/253 RTR-only and
  241..251 refused, 0x06090030). TPDO type 0 is sent at a SYNC when its
  payload changed; 254/255 when its payload changed after any event (SYNC,
  RPDO, SDO write, fault), not faster than the inhibit time (sub 3, 100 us,
  changeable only while invalid), and every event timer (sub 5, ms) from
  :meth:`SimDrivePair.tick`. RPDO event timers (deadline monitoring) and the
  consumer heartbeat 0x1016 are stored but not monitored.
* RPDO length: shorter than mapped -> EMCY 0x8210, longer -> EMCY 0x8220,
  the frame is not processed. The EMCY is sent when the error appears (not
  for every further bad frame); the next RPDO of correct length resets it
  with EMCY 0x0000.
* EMCY: COB-ID from 0x1014 (bit 31 = not sent), sent in PRE-OPERATIONAL and
  OPERATIONAL only; data = error code u16, error register 0x1001 u8, five
  zero manufacturer bytes. Error codes other than 0 are pushed into the
  pre-defined error field 0x1003 (4 entries; writing 0 to 0x1003:00 clears it).
* NMT reset node restores every object to its EDS default (plus the drive's
  own data, see ``counts_per_rev``) and the drive state to SWITCH_ON_DISABLED;
  reset communication restores 0x1000..0x1FFF and keeps the drive state.
  Leaving OPERATIONAL does not change the drive state: the drive keeps
  following the last values received.
* Software position limits 0x607D: a write that makes max < min is aborted
  (0x06090036). Rated torque 0x6076 and 0x608F must be > 0 (0x06090032).
* Time passed to :meth:`SimDrivePair.on_frame` and :meth:`SimDrivePair.tick`
  never runs backwards: a smaller ``t`` than the last one is taken as the last.
"""

from __future__ import annotations

import math
import operator
import struct
from dataclasses import dataclass, field
from typing import Any, Callable

import canopen
import canopen.objectdictionary as cod
from canopen.sdo import SdoAbortedError

from hil.canopen.cia402 import DriveStateMachine, IllegalTransition, OperationMode, State, Statusword, state_word
from hil.canopen.od import check_drive_od, load_drive_od
from hil.canopen.errors import EdsError, InputError
from hil.canopen.nmt import NmtCommand, NmtState
from hil.canopen.pdo import COB_ID_INVALID
from hil.canopen.frame import HEARTBEAT_COB_ID_BASE, Frame
from hil.canopen.units import increments_per_rad, increments_to_rad, mm_to_lvdt_um, newton_to_force_dN, permille_to_force_N, rad_to_increments
from hil.canopen.frame import SDO_RX_COB_ID_BASE, SDO_TX_COB_ID_BASE
from hil.canopen.sdo import SdoAbortCode
from hil.canopen.process import DriveMode, Sample, Setpoint
from sim.plant import RigPlant

__all__ = [
    "SimDrivePair",
    "SimDrive",
    "SimPairStats",
    "NmtState",
    "NmtCommand",
    "QUICK_STOP_HOLD_S",
    "TARGET_WINDOW_INC",
    "EMCY_NO_ERROR",
    "EMCY_PDO_LENGTH_ERROR",
    "EMCY_PDO_LENGTH_EXCEEDED",
    "error_register_bits",
]

#: How long a quick stop holds the motor angle before SWITCH_ON_DISABLED [s].
QUICK_STOP_HOLD_S = 0.05
#: CSP target reached (statusword bit 10) when |target - actual| <= this [increments].
TARGET_WINDOW_INC = 20
#: EMCY error code "error reset or no error".
EMCY_NO_ERROR = 0x0000
#: EMCY error code "PDO not processed due to length error".
EMCY_PDO_LENGTH_ERROR = 0x8210
#: EMCY error code "PDO length exceeded".
EMCY_PDO_LENGTH_EXCEEDED = 0x8220

_SUPPORTED_MODES = frozenset((int(OperationMode.CSP), int(OperationMode.CST)))
_ERROR_HISTORY_LEN = 4
_TIME_EPS_S = 1e-9
_I16 = (-(2**15), 2**15 - 1)
_I32_LO, _I32_HI = -(2**31), 2**31 - 1
# Hot-path constants (plain ints and identities instead of enum arithmetic and hashing).
_CSP = int(OperationMode.CSP)
_CST = int(OperationMode.CST)
_MODE_DISABLED = int(DriveMode.DISABLED)
_MODE_POSITION = int(DriveMode.POSITION)
_MODE_FORCE = int(DriveMode.FORCE)
_REMOTE = int(Statusword.REMOTE)
_SW_FOLLOWS = int(Statusword.DRIVE_FOLLOWS_COMMAND)
_SW_LIMIT = int(Statusword.INTERNAL_LIMIT_ACTIVE)
_SW_REACHED = int(Statusword.TARGET_REACHED)
_OE = State.OPERATION_ENABLED
_QSA = State.QUICK_STOP_ACTIVE
_FRA = State.FAULT_REACTION_ACTIVE
_K_CONTROLWORD = (0x6040, 0)
_ONLY_CONTROLWORD = (_K_CONTROLWORD,)
_K_MODE = (0x6060, 0)
_K_TARGET_POS = (0x607A, 0)
_K_POS_MIN = (0x607D, 1)
_K_POS_MAX = (0x607D, 2)
_K_TARGET_TORQUE = (0x6071, 0)
_K_MAX_TORQUE = (0x6072, 0)
_K_RATED_TORQUE = (0x6076, 0)
#: CiA 301 restricted CAN-IDs (may not be used by a PDO).
_RESTRICTED_CAN_IDS = ((0x000, 0x000), (0x001, 0x07F), (0x101, 0x180), (0x581, 0x5FF),
                       (0x601, 0x67F), (0x6E0, 0x6FF), (0x701, 0x77F), (0x780, 0x7FF))
#: Objects this simulation needs besides what hil.canopen.od.check_drive_od demands.
_SIM_REQUIRED = ((0x1001, 0), (0x1005, 0), (0x1014, 0), (0x1017, 0), (0x6040, 0), (0x6041, 0),
                 (0x6060, 0), (0x6061, 0), (0x6064, 0), (0x6071, 0), (0x6072, 0), (0x6076, 0),
                 (0x6077, 0), (0x607A, 0), (0x607D, 1), (0x607D, 2), (0x608F, 1), (0x608F, 2),
                 (0x2100, 0), (0x2101, 0), (0x2102, 0))


def error_register_bits(code: int) -> int:
    """The error register 0x1001 bits an EMCY error code sets (CiA 301 Table 48).

    Parameters
    ----------
    code : int
        EMCY error code, 0..0xFFFF.

    Returns
    -------
    int
        0 for code 0; otherwise bit 0 (generic) plus bit 1 for 0x2xxx
        (current), bit 2 for 0x3xxx (voltage), bit 3 for 0x4xxx (temperature),
        bit 4 for 0x81xx/0x82xx (communication), bit 7 for 0xFFxx
        (manufacturer specific).

    Notes
    -----
    E.g. 0x2310 (continuous over-current) -> 0x03, 0x8210 (PDO length) -> 0x11.
    """
    c = _check_code(code, "code", allow_zero=True)
    if c == 0:
        return 0
    reg = 0x01
    group = c >> 12
    if group == 0x2:
        reg |= 0x02
    elif group == 0x3:
        reg |= 0x04
    elif group == 0x4:
        reg |= 0x08
    elif c >> 8 in (0x81, 0x82):
        reg |= 0x10
    elif c >> 8 == 0xFF:
        reg |= 0x80
    return reg


def _check_code(code: int, name: str, *, allow_zero: bool) -> int:
    if isinstance(code, bool):
        raise InputError(f"{name} must be an int error code 0x0001..0xFFFF, got bool")
    try:
        c = operator.index(code)
    except TypeError:
        raise InputError(f"{name} must be an int error code 0x0001..0xFFFF, got {code!r}") from None
    lo = 0 if allow_zero else 1
    if not lo <= c <= 0xFFFF:
        raise InputError(f"{name} = 0x{c:X} is outside 0x{lo:04X}..0xFFFF (16-bit EMCY error code)")
    return c


def _check_time(t: float) -> float:
    if isinstance(t, bool):
        raise InputError("t must be a time in s (float), got bool")
    try:
        v = float(t)
    except (TypeError, ValueError):
        raise InputError(f"t must be a time in s (float), got {t!r}") from None
    if not math.isfinite(v):
        raise InputError(f"t = {v} [s] must be finite")
    return v


def _abort(code: int) -> SdoAbortedError:
    return SdoAbortedError(int(code))


# --------------------------------------------------------------------------- stats


@dataclass(frozen=True, slots=True)
class SimPairStats:
    """Counters of a :class:`SimDrivePair` (a snapshot; both nodes together).

    Attributes
    ----------
    syncs : int
        SYNC frames processed.
    plant_steps : int
        Calls of ``plant.step`` (one per SYNC plus one at the first power-on).
    tpdos_sent : int
        TPDO frames transmitted.
    rpdos_applied : int
        RPDOs written into a data store (synchronous ones at their SYNC).
    rpdos_late : int
        Latched synchronous RPDOs overwritten by a newer one before their
        SYNC (the older one missed its cycle).
    rpdos_dropped : int
        RPDOs not processed: node not OPERATIONAL, or wrong length.
    bad_frames_ignored : int
        Frames no node consumes (unknown COB-ID, another node's traffic,
        NMT for other nodes) or that are malformed (NMT not 2 bytes, SYNC
        over 1 byte, SDO request not 8 bytes, unknown NMT command).
    frames_unpowered : int
        Frames received before :meth:`SimDrivePair.power_on`.
    sdo_requests : int
        SDO request frames served.
    illegal_commands : int
        Controlwords refused by the CiA 402 state machine.
    emcys_sent, heartbeats_sent : int
        EMCY and heartbeat frames transmitted (boot-up frames excluded).
    """

    syncs: int = 0
    plant_steps: int = 0
    tpdos_sent: int = 0
    rpdos_applied: int = 0
    rpdos_late: int = 0
    rpdos_dropped: int = 0
    bad_frames_ignored: int = 0
    frames_unpowered: int = 0
    sdo_requests: int = 0
    illegal_commands: int = 0
    emcys_sent: int = 0
    heartbeats_sent: int = 0


class _Counters:
    """Mutable counters shared by the pair and its nodes."""

    __slots__ = SimPairStats.__slots__

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def snapshot(self) -> SimPairStats:
        return SimPairStats(**{name: getattr(self, name) for name in self.__slots__})


# --------------------------------------------------------------------------- sans-IO glue


_STRUCT_CODES = {
    cod.BOOLEAN: "?", cod.INTEGER8: "b", cod.INTEGER16: "h", cod.INTEGER32: "i", cod.INTEGER64: "q",
    cod.UNSIGNED8: "B", cod.UNSIGNED16: "H", cod.UNSIGNED32: "I", cod.UNSIGNED64: "Q",
    cod.REAL32: "f", cod.REAL64: "d",
}


class _CaptureBus:
    """The python-can "bus" of a node's private ``canopen.Network``: ``send`` only records.

    canopen calls ``bus.send(can.Message)`` for the SDO responses; the node
    drains :attr:`sent` into :class:`hil.canopen.frame.Frame` objects right after each
    request. Nothing else of the ``can.BusABC`` interface is used.
    """

    channel_info = "emacheck simulated drive (sans-IO)"

    def __init__(self) -> None:
        self.sent: list[Any] = []

    def send(self, msg: Any, timeout: float | None = None) -> None:
        self.sent.append(msg)


_INT_CODES = frozenset("bBhHiIqQ")


@dataclass(eq=False, slots=True)
class _Pdo:
    """One PDO of a node: configuration (from the data store) and runtime state.

    The fields after ``key`` are compiled from the configuration by
    :meth:`SimDrive._compile_pdo` whenever it is (re-)read: a TPDO whose entries
    are all live numeric objects is assembled by one ``struct`` pack of its
    getters (``pack``, ``getters``); an RPDO of numeric objects is decoded by one
    unpack (``unpack``, ``plan``: index, subindex, byte slice per entry).
    """

    rx: bool
    number: int
    comm_index: int
    map_index: int
    n_entries_max: int
    has_inhibit: bool
    has_event_timer: bool
    cob_id: int = 0
    valid: bool = False
    trans_type: int = 0
    entries: tuple[tuple[int, int, int], ...] = ()  # (index, subindex, bytes)
    length: int = 0
    inhibit_s: float = 0.0
    event_timer_s: float = 0.0
    sync_count: int = 0
    latched: bytes | None = None
    last_payload: bytes | None = None
    last_sent_t: float | None = None
    pending: bool = False
    key: tuple = field(default=())
    sync: bool = False  # trans_type <= 240
    event: bool = False  # trans_type >= 254
    pack: Callable[..., bytes] | None = None
    getters: tuple[Callable[[], int | float], ...] = ()
    unpack: Callable[[bytes], tuple] | None = None
    plan: tuple[tuple[int, int, int, int], ...] = ()
    keys: tuple[tuple[int, int], ...] = ()
    cache_ok: tuple[bool, ...] = ()  # per entry: decoded value goes to SimDrive._icache
    all_cache_ok: bool = False
    touches_cpr: bool = False  # maps 0x608F (counts per revolution)
    effects: tuple[tuple[int, int], ...] = ()  # entries with side effects (SimDrive._after_write)

    @property
    def is_synchronous(self) -> bool:
        return self.trans_type <= 240

    @property
    def is_event(self) -> bool:
        return self.trans_type >= 254


# --------------------------------------------------------------------------- one node


class SimDrive:
    """One simulated EMA drive: a CANopen slave (CiA 301) with a CiA 402 drive core.

    Created by :class:`SimDrivePair`; not meant to be built alone (it has no
    plant: the pair feeds it the measured sample and steps the plant).

    Attributes
    ----------
    node_id : int
        CANopen node id, 1..127.
    ema_index : int
        0 for EMA 1, 1 for EMA 2 of the plant.
    local : canopen.LocalNode
        SDO server and data store (``local.data_store``), from the EDS.
    network : canopen.Network
        The node's private network; its ``bus`` only captures sent messages.
    nmt_state : NmtState
        Current NMT state.
    state_machine : hil.canopen.cia402.DriveStateMachine
        The CiA 402 power drive state machine (remote bit 9 reported).
    heartbeat_enabled : bool
        Fault hook: False suppresses the heartbeat frames (the producer timer
        keeps running, so re-enabling resumes in phase).
    """

    def __init__(self, node_id: int, ema_index: int, od: cod.ObjectDictionary, *,
                 gear_ratio_rad_per_mm: float, counts_per_rev: int | None, sample_period_s: float,
                 counters: _Counters, outbox: list[Frame]) -> None:
        self.node_id = node_id
        self.ema_index = ema_index
        self._od = od
        self._i_total = float(gear_ratio_rad_per_mm)
        self._cpr_override = counts_per_rev
        self._qs_cycles = max(1, math.ceil(QUICK_STOP_HOLD_S / sample_period_s - 1e-9))
        self._counters = counters
        self._out = outbox

        self._bus = _CaptureBus()
        self.network = canopen.Network(self._bus)
        self.local = canopen.LocalNode(node_id, od)
        self._icache: dict[tuple[int, int], int] = {}  # decoded stored values (not live ones)
        self._packers: dict[tuple[int, int], Any] = {}
        self.network.add_node(self.local)
        # Detach LocalNode's own NMT slave: it would act on NMT frames and start a
        # periodic heartbeat task on the bus when 0x1017 is written.
        self.network.unsubscribe(0, self.local.nmt.on_command)
        callbacks = getattr(self.local, "_write_callbacks", None)
        if callbacks is not None and self.local.nmt.on_write in callbacks:
            callbacks.remove(self.local.nmt.on_write)
        self.local.add_read_callback(self._on_read)
        self.local.add_write_callback(self._on_write)
        self.sdo_request_cob_id = SDO_TX_COB_ID_BASE + node_id  #: requests to this node
        self.sdo_response_cob_id = SDO_RX_COB_ID_BASE + node_id  #: its responses

        self._live: dict[tuple[int, int], Callable[[], int | float]] = {
            (0x6041, 0): self._statusword_now,
            (0x6061, 0): lambda: self._mode_display,
            (0x6064, 0): self._position_now,
            (0x6077, 0): lambda: self.torque_actual_permille,
            (0x2100, 0): self._lvdt_um_now,
            (0x2101, 0): self._force_dN_now,
            (0x2102, 0): lambda: self._i_total,
            (0x603F, 0): lambda: self.state_machine.error_code,
            (0x1001, 0): lambda: self.error_register,
        }

        self.nmt_state = NmtState.INITIALISING
        self.state_machine = DriveStateMachine(remote=True)
        self.heartbeat_enabled = True
        #: fault hook (:mod:`sim.faults`): ``f(node, t, mode, value) -> (mode, value)`` replaces the
        #: plant command the drive computed at each SYNC (e.g. a runaway drive); None = no fault
        self.command_override: Callable[["SimDrive", float, int, float], tuple[int, float]] | None = None
        self._now = 0.0
        self._phi_rad = 0.0
        self._s_mm = 0.0
        self._F_N = 0.0
        # Derived values, computed when first needed and kept until their inputs change:
        # the measured values after each plant step (_measure), the increments per rad
        # and the position when 0x608F changes (_cpr_changed).
        self._torque_val = 0.0
        self._torque_stale = False
        self._torque_fetch: Callable[[], None] = self._no_torque_source  # set by SimDrivePair
        self._inc_per_rad: float | None = None
        self._pos_memo: int | None = None
        self._um_memo: int | None = None
        self._dN_memo: int | None = None
        self._sw_state: State | None = None  # statusword bits of this state: _sw_base
        self._sw_base = 0
        # controlword -> states in which receiving it again (same word as the previous one)
        # was seen to leave the state machine unchanged (a pure function of state and words)
        self._cw_noop: dict[int, tuple[State, ...]] = {}
        self._sp_mode = _MODE_DISABLED
        self._sp_value = 0.0
        self._sp_obj: Setpoint | None = None
        self._sync_tpdos_list: tuple[_Pdo, ...] = ()
        self._event_tpdos_list: tuple[_Pdo, ...] = ()
        self._timed_tpdos_list: tuple[_Pdo, ...] = ()
        self._sync_rpdos: tuple[_Pdo, ...] = ()
        self._reset_drive()
        self._hb_period_s = 0.0
        self._hb_next: float | None = None
        self._sync_cob_id = 0x080
        self._emcy_cob_id: int | None = 0x80 + node_id
        self._comm_error = False
        self._pending: set[tuple[int, int]] = set()
        self._sdo_phase: int | None = None  # segment command specifier expected next
        self._sdo_mux: tuple[int, int] = (0, 0)  # index, subindex of the last transfer

        self._rpdos = self._discover(rx=True)
        self._tpdos = self._discover(rx=False)
        self._rx_by_cob: dict[int, list[_Pdo]] = {}
        problems = []
        for p in self._rpdos + self._tpdos:
            problem = self._mapping_problem(p, self._int(p.map_index, 0))
            if problem is not None:
                problems.append(f"0x{p.map_index:04X}: {problem[1]}")
        if problems:
            raise InputError(f"node {node_id} object dictionary: default PDO mapping invalid: "
                             + "; ".join(problems))
        self._refresh_comm(restart_heartbeat=False)

    # ------------------------------------------------------------------ OD access

    def _var(self, index: int, subindex: int) -> cod.ODVariable | None:
        """The real variable at index:subindex (no synthesised array members)."""
        if index not in self._od:
            return None
        obj = self._od[index]
        if isinstance(obj, cod.ODVariable):
            return obj if subindex == 0 else None
        return obj.subindices.get(subindex)

    def read(self, index: int, subindex: int = 0) -> int | float | str | bytes:
        """Decoded value of ``index:subindex`` as an SDO upload would return it.

        Raises
        ------
        hil.canopen.errors.InputError
            The object does not exist in this node's object dictionary.
        """
        var = self._var(index, subindex)
        if var is None:
            raise InputError(f"index:subindex 0x{index:04X}:{subindex:02X} is not in the object "
                             f"dictionary of node {self.node_id}")
        return var.decode_raw(self.local.get_data(index, subindex))

    def _int(self, index: int, subindex: int = 0) -> int:
        key = (index, subindex)
        v = self._icache.get(key)
        if v is None:
            v = int(self._var(index, subindex).decode_raw(self.local.get_data(index, subindex)))
            if key not in self._live:
                self._icache[key] = v  # invalidated by every store of this object
        return v

    def _store(self, index: int, subindex: int, data: bytes) -> None:
        self.local.data_store.setdefault(index, {})[subindex] = bytes(data)
        self._icache.pop((index, subindex), None)
        if index == 0x608F:
            self._cpr_changed()

    def _cpr_changed(self) -> None:
        """0x608F (may have) changed: drop the values derived from the counts per revolution."""
        self._inc_per_rad = None
        self._pos_memo = None

    def _k_inc(self) -> float:
        """Increments per rad, :func:`hil.canopen.units.increments_per_rad` of :attr:`counts_per_rev` (cached)."""
        k = self._inc_per_rad
        if k is None:
            k = self._inc_per_rad = increments_per_rad(self.counts_per_rev)
        return k

    def _packer(self, index: int, subindex: int) -> Any:
        """struct.Struct of a numeric object (cached), or None for other types."""
        key = (index, subindex)
        if key not in self._packers:
            var = self._var(index, subindex)
            code = _STRUCT_CODES.get(var.data_type) if var is not None else None
            self._packers[key] = struct.Struct("<" + code) if code else None
        return self._packers[key]

    def _raw(self, index: int, subindex: int) -> bytes:
        """Encoded value for a PDO: live values packed directly, stored ones from the store."""
        f = self._live.get((index, subindex))
        if f is not None:
            pk = self._packer(index, subindex)
            if pk is not None:
                return pk.pack(f())
        else:
            raw = self.local.data_store.get(index, {}).get(subindex)
            if raw is not None:
                return raw
        return self.local.get_data(index, subindex)

    # ------------------------------------------------------------------ live values

    def _measure(self, raw: tuple) -> None:
        """Take this EMA's values of a plant sample ``(t_s, phi1, phi2, s1, s2, F1, F2)``.

        The drive torque is fetched from the plant only when it is first needed
        (0x6077), see :meth:`SimDrivePair._fetch_torque`.
        """
        k = self.ema_index
        self._phi_rad = raw[1 + k]
        self._s_mm = raw[3 + k]
        self._F_N = raw[5 + k]
        self._pos_memo = self._um_memo = self._dN_memo = None
        self._torque_stale = True

    def _no_torque_source(self) -> None:
        self._torque_stale = False

    @property
    def _torque_Nm(self) -> float:
        """Drive torque [N m] of the current sample."""
        if self._torque_stale:
            self._torque_fetch()
        return self._torque_val

    @property
    def counts_per_rev(self) -> float:
        """Position increments per motor revolution, 0x608F:01 / 0x608F:02."""
        return self._int(0x608F, 1) / self._int(0x608F, 2)

    @property
    def position_inc(self) -> int:
        """Position actual value 0x6064 [increments] of the current sample."""
        return self._position_now()

    def _position_now(self) -> int:
        # = rad_to_increments(self._phi_rad, self.counts_per_rev), the same float operations
        v = self._pos_memo
        if v is None:
            phi = self._phi_rad
            try:
                v = round(phi * self._k_inc())  # (an int: _clip_round without the int() of an int)
                if v < _I32_LO:
                    v = _I32_LO
                elif v > _I32_HI:
                    v = _I32_HI
            except (ValueError, ArithmeticError):  # (InputError is a ValueError)
                return rad_to_increments(phi, self.counts_per_rev)  # raises its own error
            self._pos_memo = v
        return v

    def _lvdt_um_now(self) -> int:
        # = mm_to_lvdt_um(self._s_mm)
        v = self._um_memo
        if v is None:
            s_mm = self._s_mm
            try:
                v = round(s_mm * 1000.0)  # (an int: _clip_round without the int() of an int)
                if v < _I32_LO:
                    v = _I32_LO
                elif v > _I32_HI:
                    v = _I32_HI
            except (ValueError, OverflowError):
                return mm_to_lvdt_um(s_mm)  # raises its own error
            self._um_memo = v
        return v

    def _force_dN_now(self) -> int:
        # = newton_to_force_dN(self._F_N)
        v = self._dN_memo
        if v is None:
            F_N = self._F_N
            try:
                v = round(F_N * 10.0)  # (an int: _clip_round without the int() of an int)
                if v < _I32_LO:
                    v = _I32_LO
                elif v > _I32_HI:
                    v = _I32_HI
            except (ValueError, OverflowError):
                return newton_to_force_dN(F_N)  # raises its own error
            self._dN_memo = v
        return v

    @property
    def torque_actual_permille(self) -> int:
        """Torque actual value 0x6077 [per mille of the rated torque 0x6076]."""
        rated_Nm = self._int(0x6076) / 1000.0
        return int(min(max(round(1000.0 * self._torque_Nm / rated_Nm), _I16[0]), _I16[1]))

    @property
    def error_register(self) -> int:
        """Error register 0x1001: bits of the latched fault plus bits 0 and 4 for a PDO length error."""
        reg = 0
        sm = self.state_machine
        if sm.state in (State.FAULT_REACTION_ACTIVE, State.FAULT) and sm.error_code:
            reg |= error_register_bits(sm.error_code)
        if self._comm_error:
            reg |= 0x11
        return reg

    @property
    def statusword(self) -> int:
        """Statusword 0x6041 now.

        State bits from the state machine, remote (bit 9) always; in
        OPERATION_ENABLED with a supported mode: bit 12 (drive follows the
        command), bit 11 when the last target was clipped (software position
        limits 0x607D in CSP, max torque 0x6072 in CST), bit 10 in CSP when
        ``|effective target - position actual| <= TARGET_WINDOW_INC``.
        """
        return self._statusword_now()

    def _statusword_now(self) -> int:
        # = sm.statusword(extra): hil.canopen.cia402.state_word of the state | remote bit | extra
        sm = self.state_machine
        state = sm.state
        extra = 0
        if state is _OE:
            mode = self._icache.get(_K_MODE)
            if mode is None:
                mode = self._int(0x6060)
            if mode in _SUPPORTED_MODES:
                extra = _SW_FOLLOWS
                if self._limit_active:
                    extra |= _SW_LIMIT
                eff = self._target_eff_inc
                if (mode == _CSP and eff is not None
                        and abs(eff - self._position_now()) <= TARGET_WINDOW_INC):
                    extra |= _SW_REACHED
        if state is not self._sw_state:
            self._sw_base = state_word(state)
            self._sw_state = state
        return self._sw_base | extra | (_REMOTE if sm.remote else 0)

    @property
    def setpoint(self) -> Setpoint:
        """What the drive commanded the plant at the last SYNC."""
        sp = self._sp_obj
        if sp is None:
            sp = self._sp_obj = Setpoint(DriveMode(self._sp_mode), self._sp_value)
        return sp

    def _on_read(self, index: int, subindex: int, od: Any = None, **_: Any) -> int | float | None:
        f = self._live.get((index, subindex))
        return None if f is None else f()

    # ------------------------------------------------------------------ write validation (SDO)

    def _on_write(self, index: int, subindex: int, od: cod.ODVariable, data: bytes, **_: Any) -> None:
        """Validate an SDO write (raise SdoAbortedError to refuse) and note its side effects."""
        value = od.decode_raw(bytes(data)) if od.data_type in cod.NUMBER_TYPES else None
        self._icache.pop((index, subindex), None)
        pdo = self._pdo_by_index(index)
        if pdo is not None:
            if index == pdo.comm_index:
                self._check_comm_write(pdo, subindex, value)
            else:
                self._check_map_write(pdo, subindex, value)
        elif index == 0x1005:
            if value & ((1 << 30) | (1 << 29)) or value & 0x1FFFF800:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # this node is no SYNC producer; 11 bit
        elif index == 0x1014:
            if value & (1 << 29) or value & 0x1FFFF800:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
            old = self._int(0x1014)
            if not (old | value) & COB_ID_INVALID and (old ^ value) & 0x7FF:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x1003 and subindex == 0:
            if value != 0:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x6060:
            if value not in _SUPPORTED_MODES:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x607D and subindex in (1, 2):
            lo = value if subindex == 1 else self._int(0x607D, 1)
            hi = value if subindex == 2 else self._int(0x607D, 2)
            if hi < lo:
                raise _abort(SdoAbortCode.MAX_LESS_THAN_MIN)
        elif index in (0x6076, 0x608F):
            if value is not None and value <= 0:
                raise _abort(SdoAbortCode.VALUE_TOO_LOW)
        self._pending.add((index, subindex))

    def _pdo_by_index(self, index: int) -> _Pdo | None:
        for p in self._rpdos + self._tpdos:
            if index in (p.comm_index, p.map_index):
                return p
        return None

    def _check_comm_write(self, p: _Pdo, subindex: int, value: int) -> None:
        if subindex == 1:
            if value & (1 << 29) or value & 0x1FFFF800:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # 11-bit identifiers only
            new_valid = not value & COB_ID_INVALID
            can_id = value & 0x7FF
            if p.valid and new_valid and can_id != p.cob_id:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # CiA 301: not while the PDO exists
            if new_valid and any(lo <= can_id <= hi for lo, hi in _RESTRICTED_CAN_IDS):
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif subindex == 2:
            if not (0 <= value <= 240 or value in (254, 255)):
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif subindex == 3:
            if p.valid:
                raise _abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)  # inhibit time: only while invalid

    def _check_map_write(self, p: _Pdo, subindex: int, value: int) -> None:
        if p.valid:
            raise _abort(SdoAbortCode.PARAMETER_INCOMPATIBILITY)
        if subindex == 0:
            problem = self._mapping_problem(p, value)
            if problem is not None:
                raise _abort(problem[0])
        else:
            if self._int(p.map_index, 0) != 0:
                raise _abort(SdoAbortCode.PARAMETER_INCOMPATIBILITY)
            if value != 0 and self._entry_problem(value, p.rx) is not None:
                raise _abort(SdoAbortCode.CANNOT_BE_MAPPED)

    def _entry_problem(self, entry: int, rx: bool) -> str | None:
        index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        var = self._var(index, subindex)
        where = f"entry 0x{entry:08X}"
        if var is None:
            return f"{where}: object 0x{index:04X}:{subindex:02X} does not exist"
        if not var.pdo_mappable:
            return f"{where}: object is not PDO-mappable"
        if rx and not var.writable:
            return f"{where}: object is not writable (RPDO)"
        if not rx and not var.readable:
            return f"{where}: object is not readable (TPDO)"
        if var.data_type not in cod.NUMBER_TYPES or bits % 8 or bits != len(var):
            return f"{where}: {bits} bits, the object has {len(var)} (whole bytes only)"
        return None

    def _mapping_problem(self, p: _Pdo, count: int) -> tuple[SdoAbortCode, str] | None:
        """(abort code, reason) if ``count`` entries of ``p``'s stored mapping are not a valid PDO."""
        if count > p.n_entries_max:
            return SdoAbortCode.EXCEEDS_PDO_LENGTH, f"{count} entries exceed the {p.n_entries_max} of the record"
        total = 0
        for k in range(1, count + 1):
            entry = self._int(p.map_index, k)
            problem = self._entry_problem(entry, p.rx)
            if problem is not None:
                return SdoAbortCode.CANNOT_BE_MAPPED, problem
            total += entry & 0xFF
        if total > 64:
            return SdoAbortCode.EXCEEDS_PDO_LENGTH, f"{total} mapped bits exceed 64"
        return None

    # ------------------------------------------------------------------ PDO configuration

    def _discover(self, rx: bool) -> list[_Pdo]:
        base = 0x1400 if rx else 0x1800
        pdos = []
        for k in range(512):
            comm, mapping = base + k, base + 0x200 + k
            if comm not in self._od or mapping not in self._od:
                continue
            n_max = max((s for s in self._od[mapping].subindices if s > 0), default=0)
            pdos.append(_Pdo(rx=rx, number=k + 1, comm_index=comm, map_index=mapping, n_entries_max=n_max,
                             has_inhibit=self._var(comm, 3) is not None,
                             has_event_timer=self._var(comm, 5) is not None))
        return pdos

    def _refresh_pdos(self) -> None:
        """Re-read every PDO's configuration from the data store; keep runtime state if unchanged."""
        by_cob: dict[int, list[_Pdo]] = {}
        for p in self._rpdos + self._tpdos:
            cob = self._int(p.comm_index, 1)
            count = self._int(p.map_index, 0)
            entries = []
            for k in range(1, count + 1):
                e = self._int(p.map_index, k)
                entries.append((e >> 16, (e >> 8) & 0xFF, (e & 0xFF) // 8))
            p.cob_id = cob & 0x7FF
            p.valid = not cob & COB_ID_INVALID
            p.trans_type = self._int(p.comm_index, 2)
            p.entries = tuple(entries)
            p.length = sum(n for _, _, n in entries)
            p.inhibit_s = self._int(p.comm_index, 3) * 1e-4 if p.has_inhibit else 0.0
            p.event_timer_s = self._int(p.comm_index, 5) * 1e-3 if p.has_event_timer else 0.0
            key = (p.cob_id, p.valid, p.trans_type, p.entries)
            if key != p.key:
                p.key = key
                p.sync_count = 0
                p.latched = None
                p.last_payload = None
                p.pending = False
            if p.rx and p.valid:
                by_cob.setdefault(p.cob_id, []).append(p)
            self._compile_pdo(p)
        self._rx_by_cob = by_cob
        self._sync_tpdos_list = tuple(p for p in self._tpdos if p.valid and p.sync)
        self._event_tpdos_list = tuple(p for p in self._tpdos if p.valid and p.event)
        self._timed_tpdos_list = tuple(p for p in self._event_tpdos_list if p.event_timer_s > 0.0)
        # a latched RPDO is always valid and synchronous: a change of either resets ``latched``
        self._sync_rpdos = tuple(p for p in self._rpdos if p.valid and p.sync)

    def _compile_pdo(self, p: _Pdo) -> None:
        """Precompile ``p``'s entries into one struct (see :class:`_Pdo`); generic path otherwise."""
        p.sync = p.trans_type <= 240
        p.event = p.trans_type >= 254
        p.pack = p.unpack = None
        p.getters = p.plan = p.cache_ok = ()
        p.all_cache_ok = False
        p.keys = tuple((i, s) for i, s, _ in p.entries)
        p.touches_cpr = any(i == 0x608F for i, _ in p.keys)
        p.effects = tuple((i, s) for i, s in p.keys if i == 0x6040 or i == 0x6060 or 0x1000 <= i <= 0x1FFF)
        codes = []
        for i, s, nbytes in p.entries:
            var = self._var(i, s)
            code = _STRUCT_CODES.get(var.data_type) if var is not None else None
            if code is None or struct.calcsize("<" + code) != nbytes:
                return
            codes.append(code)
        st = struct.Struct("<" + "".join(codes))
        if p.rx:
            plan, off = [], 0
            for i, s, nbytes in p.entries:
                plan.append((i, s, off, off + nbytes))
                off += nbytes
            p.plan = tuple(plan)
            p.cache_ok = tuple(c in _INT_CODES and k not in self._live for c, k in zip(codes, p.keys))
            p.all_cache_ok = all(p.cache_ok)
            p.unpack = st.unpack
        elif all(k in self._live for k in p.keys):
            p.getters = tuple(self._live[k] for k in p.keys)
            p.pack = st.pack

    def _refresh_comm(self, *, restart_heartbeat: bool) -> None:
        self._sync_cob_id = self._int(0x1005) & 0x7FF
        emcy = self._int(0x1014)
        self._emcy_cob_id = None if emcy & COB_ID_INVALID else emcy & 0x7FF
        if restart_heartbeat:
            period_ms = self._int(0x1017)
            self._hb_period_s = period_ms / 1000.0
            self._hb_next = self._now + self._hb_period_s if period_ms > 0 else None
        self._refresh_pdos()

    # ------------------------------------------------------------------ NMT

    def _reset_drive(self) -> None:
        self.state_machine = DriveStateMachine(remote=True)
        self.state_machine.boot_done()
        self._mode_display = int(self._od[0x6061].default or 0)
        self._limit_active = False
        self._target_eff_inc: int | None = None
        self._qs_phi_rad = 0.0
        self._qs_left = 0
        self._set_setpoint(_MODE_DISABLED, 0.0)

    def _set_setpoint(self, mode: int, value: float) -> None:
        """The plant command of this cycle (``mode`` a DriveMode value); :attr:`setpoint` builds it."""
        self._sp_mode = mode
        self._sp_value = value
        self._sp_obj = None

    def _apply_own_data(self) -> None:
        if self._cpr_override is not None:
            self._store(0x608F, 1, struct.pack("<I", self._cpr_override))
            self._store(0x608F, 2, struct.pack("<I", 1))

    def _boot(self, t: float, *, communication_only: bool) -> None:
        """Power-on / reset: restore defaults, boot-up frame, PRE-OPERATIONAL."""
        self._now = t
        store = self.local.data_store
        self._icache.clear()
        self._cpr_changed()
        if communication_only:
            for index in [i for i in store if 0x1000 <= i <= 0x1FFF]:
                del store[index]
        else:
            store.clear()
            self._apply_own_data()
            self._reset_drive()
        self._comm_error = False
        self._pending.clear()
        self._sdo_phase = None
        self.nmt_state = NmtState.INITIALISING
        self._out.append(Frame(HEARTBEAT_COB_ID_BASE + self.node_id, b"\x00"))
        self.nmt_state = NmtState.PRE_OPERATIONAL
        self._refresh_comm(restart_heartbeat=True)

    def _nmt(self, cs: int, t: float) -> None:
        self._now = t
        if cs == NmtCommand.START:
            if self.nmt_state is not NmtState.OPERATIONAL:
                self.nmt_state = NmtState.OPERATIONAL
                for p in self._rpdos + self._tpdos:
                    p.sync_count = 0
                    p.latched = None
                    p.last_payload = None
                    p.pending = False
        elif cs == NmtCommand.STOP:
            self.nmt_state = NmtState.STOPPED
            self._drop_latched()
        elif cs == NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt_state = NmtState.PRE_OPERATIONAL
            self._drop_latched()
        elif cs == NmtCommand.RESET_NODE:
            self._boot(t, communication_only=False)
        elif cs == NmtCommand.RESET_COMMUNICATION:
            self._boot(t, communication_only=True)

    def _drop_latched(self) -> None:
        for p in self._rpdos:
            p.latched = None

    # ------------------------------------------------------------------ SDO

    def _on_sdo(self, frame: Frame, t: float) -> None:
        """Serve one SDO request (expedited and segmented; block transfers are refused).

        The initiate requests are checked here first (object and sub-index
        exist, segmented download of a read-only object) and segment requests
        are only passed on inside a segmented transfer; everything else is
        canopen's ``SdoServer`` on the node's data store.
        """
        self._now = t
        if self.nmt_state not in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL):
            self._counters.bad_frames_ignored += 1
            return
        data = frame.data
        if len(data) != 8:
            self._counters.bad_frames_ignored += 1
            return
        self._counters.sdo_requests += 1
        ccs = data[0] >> 5
        if ccs == 4:  # abort by the client
            self._sdo_phase = None
        elif ccs in (1, 2):  # initiate download / upload: check the object first
            self._sdo_mux = struct.unpack_from("<HB", data, 1)
            self._sdo_phase = None
            code = self._access_problem(*self._sdo_mux, download=ccs == 1, expedited=bool(data[0] & 0x02))
            if code is not None:
                self._sdo_abort(code)
                return
        elif ccs in (0, 3):  # download / upload segment: only inside that transfer
            if self._sdo_phase != ccs:
                self._sdo_abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
                return
        else:  # 5, 6 block upload / download (not supported), 7 invalid
            self._sdo_mux = struct.unpack_from("<HB", data, 1)
            self._sdo_phase = None
            self._sdo_abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            return
        self._pending.clear()
        self.network.notify(frame.arbitration_id, bytearray(data), t)
        for msg in self._bus.sent:
            reply = Frame(msg.arbitration_id, bytes(msg.data))
            self._out.append(reply)
            self._sdo_phase = self._next_sdo_phase(ccs, data[0], reply.data[0])
        self._bus.sent.clear()
        if self._pending:
            # the decoded-value cache is invalidated once the values are stored (a
            # write callback may have read the old value of the object it checks)
            for key in self._pending:
                self._icache.pop(key, None)
                if key[0] == 0x608F:
                    self._cpr_changed()
            self._after_write(sorted(self._pending))
            self._pending.clear()

    def _sdo_abort(self, code: int) -> None:
        index, subindex = self._sdo_mux
        self._sdo_phase = None
        self._out.append(Frame(self.sdo_response_cob_id, struct.pack("<BHBI", 0x80, index, subindex, int(code))))

    @staticmethod
    def _next_sdo_phase(ccs: int, request: int, response: int) -> int | None:
        """Segment ccs expected next (0 download, 3 upload) after a request/response pair, or None."""
        if response >> 5 == 4:  # the server aborted
            return None
        if ccs == 1:
            return None if request & 0x02 else 0  # expedited done / segments follow
        if ccs == 2:
            return None if response & 0x02 else 3
        if ccs in (0, 3):
            last = request & 0x01 if ccs == 0 else response & 0x01
            return None if last else ccs
        return None

    def _access_problem(self, index: int, subindex: int, *, download: bool, expedited: bool) -> int | None:
        """Abort code for an initiate request LocalNode would not catch (or catch too late)."""
        if index not in self._od:
            return SdoAbortCode.OBJECT_DOES_NOT_EXIST
        if self._var(index, subindex) is None:
            return SdoAbortCode.SUBINDEX_DOES_NOT_EXIST
        if download and not expedited and not self._var(index, subindex).writable:
            return SdoAbortCode.WRITE_OF_READ_ONLY  # LocalNode would only check after the last segment
        return None

    def _after_write(self, written: list[tuple[int, int]]) -> None:
        """Side effects of objects just written (by SDO or RPDO), after they are stored."""
        comm = False
        restart_hb = False
        for index, subindex in written:
            if index == 0x6040:
                self._controlword()
            elif index == 0x6060:
                mode = self._int(0x6060)
                if mode in _SUPPORTED_MODES:
                    self._mode_display = mode
            elif index == 0x1003 and subindex == 0:
                for k in range(1, _ERROR_HISTORY_LEN + 1):
                    self.local.data_store.get(0x1003, {}).pop(k, None)
                    self._icache.pop((0x1003, k), None)
            elif 0x1000 <= index <= 0x1FFF:
                comm = True
                restart_hb |= index == 0x1017
        if comm:
            self._refresh_comm(restart_heartbeat=restart_hb)

    # ------------------------------------------------------------------ EMCY

    def _emcy(self, code: int) -> None:
        if code:
            self._push_error(code)
        if self.nmt_state not in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL) or self._emcy_cob_id is None:
            return
        self._out.append(Frame(self._emcy_cob_id, struct.pack("<HB5x", code, self.error_register)))
        self._counters.emcys_sent += 1

    def _push_error(self, code: int) -> None:
        if self._var(0x1003, 0) is None:
            return
        n = min(self._int(0x1003, 0), _ERROR_HISTORY_LEN)
        old = [self.local.get_data(0x1003, k) for k in range(1, n + 1)]
        self._store(0x1003, 1, struct.pack("<I", code))
        for k, raw in enumerate(old[:_ERROR_HISTORY_LEN - 1], start=2):
            self._store(0x1003, k, raw)
        self._store(0x1003, 0, bytes([min(n + 1, _ERROR_HISTORY_LEN)]))

    def _inject_fault(self, code: int) -> None:
        self.state_machine.fault(code)
        self._emcy(code)

    # ------------------------------------------------------------------ CiA 402

    def _controlword(self) -> None:
        sm = self.state_machine
        old = sm.state
        cw = self._icache.get(_K_CONTROLWORD)
        if cw is None:
            cw = self._int(0x6040)
        # The master repeats the controlword every cycle: the same word as the previous
        # one in a state where that was seen to be a no-op is a no-op again (the outcome
        # of on_controlword depends only on the state, the previous and this word).
        repeated = cw == getattr(sm, "_previous_cw", None)
        if repeated:
            seen = self._cw_noop.get(cw)
            if seen is not None and old in seen:
                return
            before = (sm.last_transition, sm.error_code)
        try:
            sm.on_controlword(cw)
        except IllegalTransition:
            self._counters.illegal_commands += 1
            return
        new = sm.state
        if repeated and new is old and (sm.last_transition, sm.error_code) == before:
            self._cw_noop[cw] = self._cw_noop.get(cw, ()) + (old,)
        if new is State.QUICK_STOP_ACTIVE and old is not State.QUICK_STOP_ACTIVE:
            self._qs_phi_rad = self._phi_rad
            self._qs_left = self._qs_cycles
        if old is State.FAULT and new is State.SWITCH_ON_DISABLED:
            self._emcy(EMCY_NO_ERROR)

    def _cycle(self) -> tuple[int, float]:
        """The drive's control cycle at a SYNC: internal transitions and the plant command.

        Returns the plant command ``(mode, value)`` (a DriveMode value and rad / N),
        also kept as :attr:`setpoint`.
        """
        sm = self.state_machine
        if sm.state is _FRA:
            sm.fault_reaction_done()
        if sm.state is _QSA:
            if self._qs_left > 0:
                self._qs_left -= 1
                self._limit_active = False
                self._target_eff_inc = None
                value = self._qs_phi_rad
                self._set_setpoint(_MODE_POSITION, value)
                return _MODE_POSITION, value
            sm.quick_stop_done()
        self._limit_active = False
        self._target_eff_inc = None
        mode_out, value = _MODE_DISABLED, 0.0
        if sm.state is _OE:
            ic = self._icache
            mode = ic.get(_K_MODE)
            if mode is None:
                mode = self._int(0x6060)
            if mode == _CSP:  # (a supported mode, so the effective one)
                target = ic.get(_K_TARGET_POS)
                if target is None:
                    target = self._int(0x607A)
                lo = ic.get(_K_POS_MIN)
                if lo is None:
                    lo = self._int(0x607D, 1)
                hi = ic.get(_K_POS_MAX)
                if hi is None:
                    hi = self._int(0x607D, 2)
                eff = min(max(target, lo), hi)
                self._limit_active = eff != target
                self._target_eff_inc = eff
                # = increments_to_rad(eff, self.counts_per_rev), the same float operations
                try:
                    value = float(eff) / self._k_inc()
                except (ArithmeticError, InputError):
                    value = increments_to_rad(eff, self.counts_per_rev)  # raises its own error
                mode_out = _MODE_POSITION
            elif mode == _CST:
                tau = ic.get(_K_TARGET_TORQUE)
                if tau is None:
                    tau = self._int(0x6071)
                tmax = ic.get(_K_MAX_TORQUE)
                if tmax is None:
                    tmax = self._int(0x6072)
                eff = min(max(tau, -tmax), tmax)
                self._limit_active = eff != tau
                rated = ic.get(_K_RATED_TORQUE)
                if rated is None:
                    rated = self._int(0x6076)
                rated_Nm = rated / 1000.0
                i_total = self._i_total
                if 0.0 < rated_Nm < math.inf and 0.0 < i_total < math.inf:
                    # = permille_to_force_N(eff, i_total, rated_Nm), the same float operations
                    value = float(eff) / 1000.0 * rated_Nm * i_total * 1000.0
                else:
                    value = permille_to_force_N(eff, i_total, rated_Nm)  # raises its own error
                mode_out = _MODE_FORCE
        self._set_setpoint(mode_out, value)
        return mode_out, value

    # ------------------------------------------------------------------ PDO engine

    def _assemble(self, p: _Pdo) -> bytes:
        pack = p.pack
        if pack is not None:  # all entries live numbers: one struct pack of the getters
            g = p.getters
            n = len(g)
            if n == 3:
                return pack(g[0](), g[1](), g[2]())
            if n == 2:
                return pack(g[0](), g[1]())
            return pack(*[f() for f in g])
        raw = self._raw
        return b"".join(raw(i, s) for i, s, _ in p.entries)

    def _send_tpdo(self, p: _Pdo, t: float, payload: bytes | None = None) -> None:
        if payload is None:
            payload = self._assemble(p)
        # 11-bit COB-ID (cob & 0x7FF) and at most 64 mapped bits: a valid frame by construction
        self._out.append(Frame.trusted(p.cob_id, payload))
        p.last_payload = payload
        p.last_sent_t = t
        p.pending = False
        self._counters.tpdos_sent += 1

    def _sync_tpdos(self, t: float) -> None:
        if self.nmt_state is not NmtState.OPERATIONAL:
            return
        out = self._out
        counters = self._counters
        for p in self._sync_tpdos_list:  # valid, transmission type 0..240
            tt = p.trans_type
            if tt:
                count = p.sync_count + 1
                if count < tt:
                    p.sync_count = count
                    continue
                p.sync_count = 0
                pack = p.pack
                if pack is not None and len(p.getters) == 3:  # (_assemble inlined)
                    g0, g1, g2 = p.getters
                    payload = pack(g0(), g1(), g2())
                elif pack is not None and len(p.getters) == 2:
                    g0, g1 = p.getters
                    payload = pack(g0(), g1())
                else:
                    payload = self._assemble(p)
            else:
                payload = self._assemble(p)
                if payload == p.last_payload:
                    continue
            # (_send_tpdo inlined)
            out.append(Frame.trusted(p.cob_id, payload))
            p.last_payload = payload
            p.last_sent_t = t
            p.pending = False
            counters.tpdos_sent += 1

    def _event_tpdos(self, t: float) -> None:
        """Send event-driven TPDOs (254/255) whose payload changed, respecting the inhibit time."""
        if not self._event_tpdos_list or self.nmt_state is not NmtState.OPERATIONAL:
            return
        for p in self._event_tpdos_list:  # valid, transmission type 254/255
            payload = self._assemble(p)
            if payload == p.last_payload and not p.pending:
                continue
            if p.last_sent_t is None or t - p.last_sent_t >= p.inhibit_s - _TIME_EPS_S:
                self._send_tpdo(p, t, payload)
            else:
                p.pending = True

    def _timed_tpdos(self, t: float) -> None:
        if self.nmt_state is not NmtState.OPERATIONAL:
            return
        for p in self._timed_tpdos_list:  # valid, 254/255, event timer > 0
            if p.last_sent_t is None or t - p.last_sent_t >= p.event_timer_s - _TIME_EPS_S:
                self._send_tpdo(p, t)
        self._event_tpdos(t)

    def _on_rpdo(self, pdos: list[_Pdo], frame: Frame, t: float) -> None:
        self._now = t
        if self.nmt_state is not NmtState.OPERATIONAL:
            self._counters.rpdos_dropped += 1
            return
        n = len(frame.data)
        for p in pdos:
            if n != p.length:
                self._counters.rpdos_dropped += 1
                if not self._comm_error:
                    self._comm_error = True
                    self._emcy(EMCY_PDO_LENGTH_ERROR if n < p.length else EMCY_PDO_LENGTH_EXCEEDED)
                continue
            if self._comm_error:
                self._comm_error = False
                self._emcy(EMCY_NO_ERROR)
            if p.sync:
                if p.latched is not None:
                    self._counters.rpdos_late += 1
                p.latched = frame.data
            else:
                self._apply_rpdo(p, frame.data)

    def _apply_rpdo(self, p: _Pdo, data: bytes) -> None:
        unpack = p.unpack
        if unpack is not None:
            # one unpack; raw bytes to the data store (the OD stays the source of truth)
            # and the decoded integers straight into the decoded-value cache
            if data.__class__ is not bytes:
                data = bytes(data)
            store = self.local.data_store
            for index, subindex, a, b in p.plan:
                d = store.get(index)
                if d is None:
                    d = store[index] = {}
                d[subindex] = data[a:b]
            values = unpack(data)
            ic = self._icache
            if p.all_cache_ok:
                ic.update(zip(p.keys, values))
            else:
                for key, v, ok in zip(p.keys, values, p.cache_ok):
                    if ok:
                        ic[key] = v
                    else:
                        ic.pop(key, None)
            if p.touches_cpr:
                self._cpr_changed()
        else:
            off = 0
            for index, subindex, nbytes in p.entries:
                self._store(index, subindex, data[off:off + nbytes])
                off += nbytes
        self._counters.rpdos_applied += 1
        effects = p.effects  # the entries _after_write acts on, in mapping order
        if effects:
            if effects == _ONLY_CONTROLWORD:
                self._controlword()
            else:
                self._after_write(effects)

    def _apply_latched(self) -> None:
        for p in self._sync_rpdos:  # (only valid synchronous RPDOs latch)
            if p.latched is not None:
                data, p.latched = p.latched, None
                self._apply_rpdo(p, data)

    def _tick(self, t: float) -> None:
        self._now = t
        if self._hb_next is not None and t >= self._hb_next - _TIME_EPS_S:
            if self.heartbeat_enabled:
                self._out.append(Frame(HEARTBEAT_COB_ID_BASE + self.node_id, bytes([int(self.nmt_state)])))
                self._counters.heartbeats_sent += 1
            self._hb_next += self._hb_period_s
            if self._hb_next <= t:
                self._hb_next = t + self._hb_period_s
        if self._event_tpdos_list:  # (_timed_tpdos only acts on valid event-driven TPDOs)
            self._timed_tpdos(t)


# --------------------------------------------------------------------------- the pair


class SimDrivePair:
    """Two simulated CiA 402 EMA drives (CANopen slaves) moving one simulated rig.

    Parameters
    ----------
    plant : sim.plant.RigPlant
        The rig; ``node_ids[0]`` drives EMA 1, ``node_ids[1]`` EMA 2. The pair
        steps it once per SYNC (and once at the first power-on).
    od_factory : callable, optional
        ``od_factory(node_id=n)`` returns a fresh ``canopen.ObjectDictionary``
        for node ``n`` (default :func:`hil.canopen.od.load_drive_od`, the shipped
        EDS with ``$NODEID`` resolved). It must pass
        :func:`hil.canopen.od.check_drive_od` and hold the objects the drive
        serves (0x1001, 0x1005, 0x1014, 0x6072, 0x6077, ...).
    node_ids : tuple of two int, optional
        Distinct node ids 1..127, default (1, 2).
    counts_per_rev : int, optional
        Encoder increments per motor revolution. None: the EDS's 0x608F
        (4096 / 1). Given: written to 0x608F:01 (and 1 to 0x608F:02) as the
        drive's own data at every power-on and reset node.

    Attributes
    ----------
    nodes : tuple of SimDrive
        The two drives, in ``node_ids`` order.
    plant : RigPlant
        The simulated rig.

    Raises
    ------
    hil.canopen.errors.InputError
        Wrong plant type, node ids, ``counts_per_rev``, or an object
        dictionary that lacks what the drive needs.

    Notes
    -----
    Conversions between the plant (rad, mm, N) and the drive objects, per
    EMA with :math:`N = \\text{0x608F:01} / \\text{0x608F:02}` increments per
    revolution, :math:`T_r = \\text{0x6076} / 1000` N m and the plant's gear
    ratio :math:`i` [rad/mm] (also served as 0x2102, REAL32):

    .. math::

        p_{actual} = \\mathrm{round}(\\varphi N / 2\\pi)\\ \\text{[inc]},\\quad
        \\text{0x2100} = \\mathrm{round}(1000\\, s)\\ [\\mu m],\\quad
        \\text{0x2101} = \\mathrm{round}(10\\, F)\\ [0.1\\,N],

        \\text{0x6077} = \\mathrm{round}(1000\\, T / T_r)\\ [per mille],\\quad
        \\varphi_{target} = 2\\pi\\,\\mathrm{clip}(p_{target}, p_{min}, p_{max}) / N
        \\ \\text{(CSP)},

        F_{target} = \\mathrm{clip}(\\tau, \\pm\\tau_{max}) / 1000 \\cdot T_r \\cdot 1000\\, i
        \\ \\text{[N] (CST)},

    with :math:`\\varphi, s, F` the measured sample of that EMA, :math:`T`
    the plant's drive torque [N m], :math:`p_{min}, p_{max}` = 0x607D:01/02,
    :math:`\\tau` = 0x6071 and :math:`\\tau_{max}` = 0x6072 [per mille].
    Commands to the plant per drive state: OPERATION_ENABLED + CSP ->
    POSITION, + CST -> FORCE; QUICK_STOP_ACTIVE -> POSITION at the angle
    measured when the quick stop began, for :data:`QUICK_STOP_HOLD_S`;
    anything else -> DISABLED (holding brake). See the module docstring for
    the protocol choices.
    """

    def __init__(self, plant: RigPlant, od_factory: Callable[..., cod.ObjectDictionary] = load_drive_od,
                 node_ids: tuple[int, int] = (1, 2), *, counts_per_rev: int | None = None) -> None:
        if not isinstance(plant, RigPlant):
            raise InputError(f"plant must be a sim.plant.RigPlant, got {type(plant).__name__}")
        if not callable(od_factory):
            raise InputError(f"od_factory must be callable as od_factory(node_id=n), got {od_factory!r}")
        try:
            ids = tuple(operator.index(n) for n in node_ids)
        except TypeError:
            raise InputError(f"node_ids must be two ints in 1..127, got {node_ids!r}") from None
        if len(ids) != 2 or ids[0] == ids[1] or not all(1 <= n <= 127 for n in ids):
            raise InputError(f"node_ids must be two distinct ints in 1..127 (shape (2,)), got {node_ids!r}")
        if counts_per_rev is not None:
            if isinstance(counts_per_rev, bool):
                raise InputError("counts_per_rev must be an int > 0 [increments/rev], got bool")
            try:
                cpr = operator.index(counts_per_rev)
            except TypeError:
                raise InputError(f"counts_per_rev must be an int > 0 [increments/rev], "
                                 f"got {counts_per_rev!r}") from None
            if not 0 < cpr < 2**32:
                raise InputError(f"counts_per_rev = {cpr} [increments/rev] must be in 1..2**32-1")
            counts_per_rev = cpr
        self.plant = plant
        self._counters = _Counters()
        self._out: list[Frame] = []
        self._powered = False
        self._now = -math.inf
        self._raw_sample: tuple | None = None  # plant.step_raw output; :attr:`sample` builds the Sample
        self._sample: Sample | None = None
        params = plant.params
        nodes = []
        for k, n in enumerate(ids):
            od = od_factory(node_id=n)
            if not isinstance(od, cod.ObjectDictionary):
                raise InputError(f"od_factory(node_id={n}) must return a canopen ObjectDictionary, "
                                 f"got {type(od).__name__}")
            try:
                check_drive_od(od, source=f"node {n} object dictionary")
            except EdsError as exc:
                raise InputError(str(exc)) from None
            missing = [f"0x{i:04X}:{s:02X}" for i, s in _SIM_REQUIRED if _lookup(od, i, s) is None]
            if missing:
                raise InputError(f"node {n} object dictionary lacks objects the simulated drive serves: "
                                 + ", ".join(missing))
            nodes.append(SimDrive(n, k, od, gear_ratio_rad_per_mm=params.i_total_rad_per_mm,
                                  counts_per_rev=counts_per_rev, sample_period_s=params.sample_period_s,
                                  counters=self._counters, outbox=self._out))
        self.nodes: tuple[SimDrive, SimDrive] = (nodes[0], nodes[1])
        for node in self.nodes:
            node._torque_fetch = self._fetch_torque
        # COB-ID -> ((node, its RPDOs of that COB-ID), ...), valid for the nodes' _rx_by_cob dicts
        self._routes: dict[int, tuple[tuple[SimDrive, list[_Pdo]], ...]] = {}
        self._routes_rx: tuple[dict, dict] = (nodes[0]._rx_by_cob, nodes[1]._rx_by_cob)

    # ------------------------------------------------------------------ inspection

    @property
    def stats(self) -> SimPairStats:
        """Snapshot of the counters."""
        return self._counters.snapshot()

    @property
    def sample(self) -> Sample | None:
        """The current sample (plant state at the next SYNC); None before the first power-on."""
        if self._sample is None and self._raw_sample is not None:
            self._sample = Sample(*self._raw_sample)
        return self._sample

    @property
    def powered(self) -> bool:
        """True after :meth:`power_on`."""
        return self._powered

    # ------------------------------------------------------------------ internals

    def _clock(self, t: float) -> float:
        v = _check_time(t)
        if v > self._now:
            self._now = v
        return self._now

    def _drain(self) -> list[Frame]:
        out = list(self._out)
        self._out.clear()
        return out

    def _step(self, mode1: int, value1: float, mode2: int, value2: float) -> None:
        """Step the plant with both drives' commands (DriveMode values, rad / N).

        ``plant.step_raw`` is ``plant.step`` without the Setpoint and Sample
        objects; on an error ``plant.step`` is called with the same commands so
        that it raises its own error (the plant validates before it advances).
        The drive torques (0x6077) are read from the plant only when needed
        (:meth:`_fetch_torque`): the pair is the only one stepping its plant.
        """
        plant = self.plant
        try:
            raw = plant.step_raw(mode1, value1, mode2, value2)
        except (InputError, TypeError):
            plant.step(Setpoint(DriveMode(mode1), value1), Setpoint(DriveMode(mode2), value2))
            raise
        self._raw_sample = raw
        self._sample = None
        self._counters.plant_steps += 1
        n0, n1 = self.nodes
        n0._measure(raw)
        n1._measure(raw)

    def _fetch_torque(self) -> None:
        """Read both drive torques [N m] of the last plant step into the nodes."""
        torque = self.plant.state().torque_Nm
        for node in self.nodes:
            node._torque_val = float(torque[node.ema_index])
            node._torque_stale = False

    def _node_index(self, node_index: int) -> SimDrive:
        if isinstance(node_index, bool):
            raise InputError("node_index must be 0 or 1 (int), got bool")
        try:
            k = operator.index(node_index)
        except TypeError:
            raise InputError(f"node_index must be 0 or 1 (int), got {node_index!r}") from None
        if k not in (0, 1):
            raise InputError(f"node_index = {k} must be 0 (node {self.nodes[0].node_id}) "
                             f"or 1 (node {self.nodes[1].node_id})")
        return self.nodes[k]

    # ------------------------------------------------------------------ the sans-IO interface

    def power_on(self, t: float) -> list[Frame]:
        """Switch both drives on (or power-cycle them) at time ``t`` [s].

        Returns
        -------
        list of Frame
            The boot-up frames ``0x700 + n [00]`` of both nodes, in ``node_ids``
            order; both nodes are then PRE-OPERATIONAL, drives SWITCH_ON_DISABLED.

        Notes
        -----
        The first power-on steps the plant once with both drives DISABLED so
        that the current sample is the measured rig at rest.
        """
        now = self._clock(t)
        if self._raw_sample is None:
            self._step(_MODE_DISABLED, 0.0, _MODE_DISABLED, 0.0)
        self._powered = True
        for node in self.nodes:
            node._boot(now, communication_only=False)
        return self._drain()

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """Process one frame seen on the bus at time ``t`` [s]; return the frames to transmit.

        NMT (COB-ID 0, ``[cs, node or 0]``), SYNC (COB-ID of 0x1005), SDO
        requests (0x600 + n) and the RPDOs valid in each node are consumed;
        anything else is counted in ``stats.bad_frames_ignored`` and ignored.
        Never raises for frame contents.

        Raises
        ------
        hil.canopen.errors.InputError
            ``frame`` is not a :class:`hil.canopen.frame.Frame` or ``t`` not a finite time.
        """
        if not isinstance(frame, Frame):
            raise InputError(f"frame must be a hil.canopen.frame.Frame, got {type(frame).__name__}")
        if t.__class__ is float and t - t == 0.0:  # finite float: _clock without the conversions
            now = self._now
            if t > now:
                now = self._now = t
        else:
            now = self._clock(t)
        if not self._powered:
            self._counters.frames_unpowered += 1
            return []
        cob = frame.arbitration_id
        n0, n1 = self.nodes
        if cob == 0:
            self._on_nmt(frame, now)
        elif cob == n0._sync_cob_id or cob == n1._sync_cob_id:
            self._on_sync(frame, now)
        elif cob == n0.sdo_request_cob_id or cob == n1.sdo_request_cob_id:
            consumed = False
            for node in (n0, n1):
                if cob == node.sdo_request_cob_id:
                    node._on_sdo(frame, now)
                    consumed = True
                rx = node._rx_by_cob.get(cob)
                if rx:
                    node._on_rpdo(rx, frame, now)
                    consumed = True
            if not consumed:
                self._counters.bad_frames_ignored += 1
        else:
            # RPDOs (or nothing): the nodes' RPDOs of this COB-ID, looked up once per
            # configuration (a node's RPDO only changes that node's configuration)
            if n0._rx_by_cob is not self._routes_rx[0] or n1._rx_by_cob is not self._routes_rx[1]:
                self._routes = {}
                self._routes_rx = (n0._rx_by_cob, n1._rx_by_cob)
            route = self._routes.get(cob)
            if route is None:
                route = self._routes[cob] = tuple(
                    (node, node._rx_by_cob[cob]) for node in (n0, n1) if node._rx_by_cob.get(cob))
            if route:
                for node, rx in route:
                    node._on_rpdo(rx, frame, now)
            else:
                self._counters.bad_frames_ignored += 1
        if n0._event_tpdos_list:
            n0._event_tpdos(now)
        if n1._event_tpdos_list:
            n1._event_tpdos(now)
        out = self._out
        if out:
            frames = out.copy()
            out.clear()
            return frames
        return []

    def _on_nmt(self, frame: Frame, t: float) -> None:
        if len(frame.data) != 2:
            self._counters.bad_frames_ignored += 1
            return
        cs, target = frame.data
        try:
            NmtCommand(cs)
        except ValueError:
            self._counters.bad_frames_ignored += 1
            return
        targets = [n for n in self.nodes if target in (0, n.node_id)]
        if not targets:
            self._counters.bad_frames_ignored += 1
        for node in targets:
            node._nmt(cs, t)

    def _on_sync(self, frame: Frame, t: float) -> None:
        if len(frame.data) > 1:
            self._counters.bad_frames_ignored += 1
            return
        self._counters.syncs += 1
        cob = frame.arbitration_id
        n0, n1 = self.nodes
        c0 = n0._sync_cob_id == cob
        c1 = n1._sync_cob_id == cob
        if c0:
            n0._now = t
            n0._sync_tpdos(t)
        if c1:
            n1._now = t
            n1._sync_tpdos(t)
        if c0:
            n0._apply_latched()
        if c1:
            n1._apply_latched()
        mode1, value1 = n0._cycle()
        mode2, value2 = n1._cycle()
        if n0.command_override is not None:
            mode1, value1 = n0.command_override(n0, t, mode1, value1)
        if n1.command_override is not None:
            mode2, value2 = n1.command_override(n1, t, mode2, value2)
        self._step(mode1, value1, mode2, value2)

    def tick(self, t: float) -> list[Frame]:
        """Let time pass to ``t`` [s]: heartbeats (0x1017) and timed event TPDOs that are due.

        A heartbeat is sent at the first tick at or after each multiple of the
        producer time since boot-up (or since 0x1017 was written); if ticks are
        farther apart than the period, one heartbeat is sent and the schedule
        restarts from ``t``.

        Returns
        -------
        list of Frame
            Heartbeats ``0x700 + n [state]`` (0x7F pre-operational, 0x05
            operational, 0x04 stopped) and event TPDOs, node by node.
        """
        if t.__class__ is float and t - t == 0.0:  # finite float: _clock without the conversions
            now = self._now
            if t > now:
                now = self._now = t
        else:
            now = self._clock(t)
        if self._powered:
            for node in self.nodes:
                node._tick(now)
        out = self._out
        if out:
            frames = out.copy()
            out.clear()
            return frames
        return []

    # ------------------------------------------------------------------ fault hooks

    def inject_fault(self, node_index: int, emcy_code: int) -> list[Frame]:
        """Make drive ``node_index`` (0 or 1) fault with error code ``emcy_code``.

        The state machine goes to FAULT_REACTION_ACTIVE (FAULT at the next
        SYNC), 0x603F and the error register 0x1001 are set
        (:func:`error_register_bits`), the code is pushed into 0x1003.

        Returns
        -------
        list of Frame
            The EMCY ``[code u16, 0x1001, 0, 0, 0, 0, 0]`` (empty if the node is
            STOPPED or 0x1014 is invalid).

        Raises
        ------
        hil.canopen.errors.InputError
            ``node_index`` not 0/1, ``emcy_code`` not in 0x0001..0xFFFF, or the
            pair is not powered on.
        """
        node = self._node_index(node_index)
        code = _check_code(emcy_code, "emcy_code", allow_zero=False)
        if not self._powered:
            raise InputError("inject_fault needs a powered pair: call power_on(t) first")
        node._inject_fault(code)
        node._event_tpdos(self._now)
        return self._drain()

    def set_heartbeat_enabled(self, node_index: int, enabled: bool) -> None:
        """Fault hook: stop (False) or resume (True) the heartbeat frames of drive ``node_index``."""
        node = self._node_index(node_index)
        if not isinstance(enabled, bool):
            raise InputError(f"enabled must be a bool, got {enabled!r}")
        node.heartbeat_enabled = enabled


def _lookup(od: cod.ObjectDictionary, index: int, subindex: int) -> cod.ODVariable | None:
    if index not in od:
        return None
    obj = od[index]
    if isinstance(obj, cod.ODVariable):
        return obj if subindex == 0 else None
    return obj.subindices.get(subindex)
