"""The CiA 402 drive behaviour of a simulated EMA drive.

The controlword is handled by :class:`hil.canopen.cia402.DriveStateMachine`
(remote bit 9 reported); this module adds what a drive does around it: the
statusword, the quick-stop hold, the plant command of each SYNC cycle and the
live values served from the plant's sample (position, LVDT, force, torque).
Scaling is :mod:`hil.canopen.units` (the unchecked kernels on the hot path,
falling back to the validated function, which raises its own error, when a
value is not finite).

Choices (CiA 402 leaves them open or this drive restricts them)
---------------------------------------------------------------
* Modes of operation: CSP (8) and CST (10). An SDO write of another value to
  0x6060 is aborted (0x06090030); an RPDO cannot be refused, so a drive whose
  0x6060 holds another value keeps 0x6061 unchanged, clears statusword bit 12
  and commands DISABLED (holding brake), even in OPERATION_ENABLED.
* Quick stop, as the quick stop option code 0x605A says (read when the
  quick stop begins; a drive without 0x605A takes 2): 1..4 the drive holds
  the motor angle measured when the quick stop began for
  :data:`QUICK_STOP_HOLD_S` (a fixed 50 ms standing for the ramp, counted in
  SYNC cycles of the plant's sample period; 0x6085 is not used), then takes
  transition 12 to SWITCH_ON_DISABLED (brake); 0 disables the drive function
  at once (SWITCH_ON_DISABLED at the next drive cycle); 5..8 hold the angle
  and stay in QUICK_STOP_ACTIVE until disable voltage (transition 12 by
  command) or enable operation (transition 16 back to OPERATION_ENABLED, taken
  only by such a drive: :data:`hil.canopen.cia402.CONDITIONAL`). Other
  values of 0x605A are refused (0x06090030).
* Fault reaction: FAULT_REACTION_ACTIVE lasts until the next SYNC, then FAULT;
  both command DISABLED.
* Abort connection option 0x6007 (0..3; manufacturer-specific negative
  values are refused, 0x06090030): on a heartbeat event of the consumer
  0x1016 the drive applies 1 fault signal (transition 13, error code 0x8130),
  2 disable voltage or 3 quick stop, as commands through
  :data:`hil.canopen.cia402.TRANSITIONS` (3 in OPERATION_ENABLED: quick stop,
  the hold below, then SWITCH_ON_DISABLED; where the table has no such
  transition, as in FAULT, the state is kept). Bus-off, NMT stopped and
  reset communication do not trigger it here. A fault reset (rising edge of controlword bit 7)
  sends EMCY 0x0000.
* Illegal controlwords leave the state unchanged and are counted
  (``stats.illegal_commands``), no EMCY. A repeated controlword is a no-op.
  Bit 8 (halt) is not implemented.
* Software position limits 0x607D: a write that makes max < min is aborted
  (0x06090036). In CSP the target is clipped to them (CiA 402), in CST the target torque to the max
  torque 0x6072; the max motor speed 0x6080 and the following error window and time out 0x6065/0x6066
  (fault 0x8611) are :mod:`sim.drives.limits`, as is 0x6080 in CST (a speed limitation of the
  torque: it is reduced so that the motor speed stays within 0x6080). Rated torque 0x6076 and 0x608F
  must be > 0 (0x06090032).
* Fault hooks (set by :mod:`sim.faults`, off by default): ``boot_fault``
  (an error code: the drive enters FAULT at every boot, power-on or reset
  node, with an EMCY after its boot-up frame, until a fault reset clears
  it), ``fault_resets_needed`` (the rising edges of bit 7 a FAULT takes to
  clear: the earlier ones are ignored), ``ignore_abort_connection`` (a
  heartbeat event sends its EMCY but 0x6007 is not applied),
  ``quick_stop_stays`` (QUICK_STOP_ACTIVE is kept whatever 0x605A says),
  ``mode_frozen`` (0x6061 does not follow 0x6060: the drive keeps running in
  the mode it shows) and ``not_ready_until_controlword`` (after power-on and
  every reset node the drive stays in NOT_READY_TO_SWITCH_ON until it receives
  a controlword, by RPDO or SDO, whichever: that word is ignored, then it takes
  transition 1 to SWITCH_ON_DISABLED; a CiA 402 slave on lely-core seen in the field).
* Statusword: bit 12 (drive follows the command) in OPERATION_ENABLED with a
  supported mode, bit 11 when the last target was clipped (0x607D or 0x6080 in CSP,
  0x6072 or 0x6080 in CST), bit 10 in CSP when the effective target is within
  :data:`TARGET_WINDOW_INC` of the position.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

from hil.canopen.cia402 import (
    Command,
    DriveStateMachine,
    IllegalTransition,
    OperationMode,
    State,
    Statusword,
    state_word,
)
from hil.canopen.emcy import error_register_bits
from hil.canopen.errors import CanopenInputError
from hil.canopen.od import AbortConnectionOption
from hil.canopen.process import DriveMode, Setpoint
from hil.canopen.sdo import SdoAbortCode
from hil.canopen.signalmap import Signal, angle_scale_factor_group
from hil.canopen.units import (
    increments_per_rad,
    increments_to_rad,
    increments_to_rad_unchecked,
    permille_to_force_N,
    permille_to_force_N_unchecked,
    rad_to_increments,
    rad_to_increments_unchecked,
    torque_to_permille_unchecked,
)
from sim.drives.nmt_slave import EMCY_HEARTBEAT, EMCY_NO_ERROR
from sim.drives.store import abort

__all__ = ["QUICK_STOP_HOLD_S", "SUPPORTED_MODES", "TARGET_WINDOW_INC", "Cia402Drive"]

#: How long a quick stop holds the motor angle before SWITCH_ON_DISABLED [s].
QUICK_STOP_HOLD_S = 0.05
#: CSP target reached (statusword bit 10) when |target - actual| <= this [increments].
TARGET_WINDOW_INC = 20
#: Modes of operation (0x6060) the drive can simulate: CSP and CST (each drive offers those its 0x6502 says).
SUPPORTED_MODES = frozenset((int(OperationMode.CSP), int(OperationMode.CST)))
_CSP_CST_BITS = 1 << 7 | 1 << 9
#: Abort connection option codes (0x6007) the drive supports, and the commands of 2 and 3.
_ABORT_OPTIONS = frozenset(int(o) for o in AbortConnectionOption)
_ABORT_COMMAND = {int(AbortConnectionOption.DISABLE_VOLTAGE): Command.DISABLE_VOLTAGE,
                  int(AbortConnectionOption.QUICK_STOP): Command.QUICK_STOP}
#: Quick stop option codes 0x605A the drive accepts (CiA 402 0..8), those that stay in
#: QUICK_STOP_ACTIVE, and the code of a drive without 0x605A.
_QUICK_STOP_OPTIONS = frozenset(range(9))
_QS_STAY = frozenset((5, 6, 7, 8))
_QS_DEFAULT = 2
_FAULTY = (State.FAULT_REACTION_ACTIVE, State.FAULT)

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
_NRTSO = State.NOT_READY_TO_SWITCH_ON
_K_CONTROLWORD = (0x6040, 0)
_K_MODE = (0x6060, 0)
_K_TARGET_POS = (0x607A, 0)
_K_POS_MIN = (0x607D, 1)
_K_POS_MAX = (0x607D, 2)
_K_TARGET_TORQUE = (0x6071, 0)
_K_MAX_TORQUE = (0x6072, 0)


class Cia402Drive:
    """Mixin of :class:`sim.drives.drive.SimDrive`: the CiA 402 drive and its live values.

    The attributes below are the ones this part owns (set in
    :meth:`init_drive`, :meth:`reset_application` and :meth:`measure`; the
    pair writes ``torque_fetch`` once and ``torque_value`` /
    ``torque_stale`` when it fetches the torques). It uses ``ema_index``,
    ``store``, ``int_value``, ``int_cache``, ``write_object`` and ``counters`` of the
    drive, and ``send_emcy`` and ``error_register`` of
    :class:`~sim.drives.nmt_slave.NmtSlave`.

    Attributes
    ----------
    state_machine : hil.canopen.cia402.DriveStateMachine
        The CiA 402 power drive state machine (remote bit 9 reported).
    command_override : callable or None
        Fault hook (:mod:`sim.faults`): ``f(node, t, mode, value) -> (mode, value)``
        replaces the plant command the drive computed at each SYNC (e.g. a
        runaway drive); None = no fault.
    boot_fault : int
        Fault hook: an error code (0: none); the drive boots into FAULT with it until a fault reset.
    fault_resets_needed : int
        Fault hook: fault resets (rising edges of controlword bit 7) a FAULT takes to clear (1).
    ignore_abort_connection : bool
        Fault hook: a heartbeat event does not apply 0x6007 (its EMCY is still sent).
    quick_stop_stays : bool
        Fault hook: QUICK_STOP_ACTIVE is kept until disable voltage, whatever 0x605A says.
    mode_frozen : bool
        Fault hook: 0x6061 does not follow 0x6060; the drive runs in the mode it shows.
    not_ready_until_controlword : bool
        Fault hook: the drive boots into NOT_READY_TO_SWITCH_ON and leaves it (transition 1) only
        when a controlword arrives.
    _i_total : float
        The plant's gear ratio [rad/mm] (0x2102).
    _cpr_override : int or None
        The drive's own 0x608F:01, written at power-on and reset node.
    _qs_cycles : int
        Quick-stop hold in SYNC cycles.
    _phi_rad : float
        This EMA's motor angle [rad] of the current sample (:meth:`measure`; the
        measured inputs read the whole sample ``raw_sample``).
    torque_value : float
        Drive torque [N m], valid unless ``torque_stale``.
    torque_stale : bool
        The torque of the current sample is not fetched yet.
    torque_fetch : callable
        Fetches it (:meth:`sim.drives.SimDrivePair._fetch_torque`).
    _inc_per_rad : float or None
        Increments per rad, None until needed after a change of 0x608F.
    _pos_memo : int or None
        Position actual value of the current sample (computed once).
    input_memo : list
        The measured inputs' raw values of the current sample (computed once each).
    _sw_state : State or None
        The state whose statusword bits ``_sw_base`` holds.
    _sw_base : int
        Statusword bits of ``_sw_state``.
    _cw_noop : dict
        Controlword -> states in which receiving it again was seen to be a no-op.
    _sp_mode, _sp_value, _sp_obj
        The plant command of the last SYNC (a DriveMode value, rad or N) and
        its Setpoint (None until :attr:`setpoint` builds it).
    _mode_display : int
        Modes of operation display 0x6061.
    _limit_active : bool
        The last target was clipped (statusword bit 11).
    _target_eff_inc : int or None
        The clipped CSP target [increments] of the last SYNC.
    _qs_phi_rad : float
        The angle a quick stop holds [rad].
    _qs_left : int
        SYNC cycles of the hold left.
    _qs_stay : bool
        The quick stop stays active after the hold (0x605A = 5..8, or ``quick_stop_stays``).
    _resets_seen : int
        Fault resets received in the current FAULT (``fault_resets_needed``).
    """

    def init_drive(self, gear_ratio_rad_per_mm: float, counts_per_rev: int | None, sample_period_s: float,
                    *, angle_units_per_rad: float | None = None, rated_torque_Nm: float | None = None) -> None:
        """Initial state: drive in SWITCH_ON_DISABLED, no sample yet (see :class:`~sim.drives.drive.SimDrive`)."""
        self._i_total = float(gear_ratio_rad_per_mm)
        self._cpr_override = counts_per_rev
        self.boot_fault = 0
        self.fault_resets_needed = 1
        self.ignore_abort_connection = False
        self.quick_stop_stays = False
        self.mode_frozen = False
        self.not_ready_until_controlword = False
        self._resets_seen = 0
        self._qs_stay = False
        self._angle_k = angle_units_per_rad  # position units per rad the profile states (a drive without 0x608F)
        self._rated_override = rated_torque_Nm
        self._qs_cycles = max(1, math.ceil(QUICK_STOP_HOLD_S / sample_period_s - 1e-9))
        self.state_machine = DriveStateMachine(remote=True)
        self.command_override: Callable[[Cia402Drive, float, int, float], tuple[int, float]] | None = None
        self._phi_rad = 0.0
        self.torque_value = 0.0
        self.torque_stale = False
        self.torque_fetch: Callable[[], None] = self._no_torque_source  # set by SimDrivePair
        self._inc_per_rad: float | None = None
        self._pos_memo: int | None = None
        self._sw_state: State | None = None  # statusword bits of this state: _sw_base
        self._sw_base = 0
        # controlword -> states in which receiving it again (same word as the previous one)
        # was seen to leave the state machine unchanged (a pure function of state and words)
        self._cw_noop: dict[int, tuple[State, ...]] = {}
        self._sp_mode = _MODE_DISABLED
        self._sp_value = 0.0
        self._sp_obj: Setpoint | None = None
        self.reset_application()

    def build_live_objects(self) -> dict[tuple[int, int], Callable[[], int | float]]:
        """The objects whose value the drive computes when read: the node's (error register, the
        measured inputs the rig's map puts on this drive), its CiA 402 objects and the gear-ratio object."""
        live = super().build_live_objects()
        live.update({
            (0x6041, 0): self._statusword_now,
            (0x6061, 0): lambda: self._mode_display,
            (0x6064, 0): self._position_now,
            (0x603F, 0): lambda: self.state_machine.error_code,
        })
        if 0x6077 in self.store_od:
            live[(0x6077, 0)] = lambda: self.torque_actual_permille
        if self.gear_object is not None:
            live[self.gear_object] = lambda: self._i_total
        return live

    def input_getter(self, k: int, inp) -> Callable[[], int | float]:
        """Getter of a measured input; this EMA's motor angle in the drive's own position units
        (0x6064, or the profile leaves the scaling to the drive) is its position actual value."""
        if inp.signal is Signal.MOTOR_ANGLE and inp.ema == self.ema_index + 1 \
                and (inp.scale is None or inp.key == (0x6064, 0)):
            return self._position_now
        return super().input_getter(k, inp)

    # ------------------------------------------------------------------ reset and own data

    def reset_application(self) -> None:
        """Power-on / reset node: SWITCH_ON_DISABLED (FAULT with ``boot_fault``; NOT_READY_TO_SWITCH_ON
        with ``not_ready_until_controlword``), 0x6061 from the EDS,
        plant command DISABLED, the modes it supports from its 0x6502 (CSP bit 7, CST bit 9)."""
        modes = self.store.int_or(0x6502, 0, _CSP_CST_BITS)
        self._modes = frozenset(m for m, bit in ((_CSP, 7), (_CST, 9)) if modes >> bit & 1)
        self.state_machine = DriveStateMachine(remote=True)
        if not self.not_ready_until_controlword:
            self.state_machine.boot_done()
        d = self.store.var(0x6061, 0)
        self._mode_display = int(d.default or 0) if d is not None else 0
        self._limit_active = False
        self._target_eff_inc: int | None = None
        self.reset_speed_estimate()
        self._qs_phi_rad = 0.0
        self._qs_left = 0
        self._qs_stay = False
        self._resets_seen = 0
        self._set_setpoint(_MODE_DISABLED, 0.0)
        if self.boot_fault:
            self.state_machine.fault(self.boot_fault)
            self.state_machine.fault_reaction_done()

    def after_boot(self) -> None:
        """A drive that booted into FAULT says so (EMCY with its error code)."""
        if self.boot_fault and self.state_machine.state is State.FAULT:
            self.send_emcy(self.state_machine.error_code)

    def app_error_bits(self) -> int:
        """Error register bits of the latched fault (:func:`hil.canopen.emcy.error_register_bits`)."""
        sm = self.state_machine
        if sm.state in _FAULTY and sm.error_code:
            return error_register_bits(sm.error_code)
        return 0

    def apply_own_data(self) -> None:
        """The drive's own data, restored at power-on and reset node: what its EDS leaves open
        (identity, device type, supported modes, rated torque, ... :attr:`own_data`), its serial
        number (0x1018:04) and, where given, its encoder resolution (0x608F)."""
        super().apply_own_data()
        if self._cpr_override is not None:
            self.write_object(0x608F, 1, struct.pack("<I", self._cpr_override))
            self.write_object(0x608F, 2, struct.pack("<I", 1))

    def check_app_write(self, index: int, subindex: int, value: float | None) -> None:
        """Validate an SDO write of a drive object (raise SdoAbortedError to refuse)."""
        if index == 0x6060:
            if value not in self._modes:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x607D and subindex in (1, 2):
            lo = value if subindex == 1 else self.int_value(0x607D, 1)
            hi = value if subindex == 2 else self.int_value(0x607D, 2)
            if hi < lo:
                raise abort(SdoAbortCode.MAX_LESS_THAN_MIN)
        elif index in (0x6076, 0x608F):
            if value is not None and value <= 0:
                raise abort(SdoAbortCode.VALUE_TOO_LOW)
        elif index == 0x6007:
            if value not in _ABORT_OPTIONS:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)
        elif index == 0x605A:
            if value not in _QUICK_STOP_OPTIONS:
                raise abort(SdoAbortCode.VALUE_RANGE_EXCEEDED)

    def mode_written(self) -> None:
        """0x6060 written: a supported mode shows in 0x6061 (another one is ignored; with
        ``mode_frozen`` every one)."""
        mode = self.int_value(0x6060)
        if mode in self._modes and not self.mode_frozen:
            self._mode_display = mode

    # ------------------------------------------------------------------ live values

    def measure(self, raw: tuple) -> None:
        """Take this EMA's values of a plant sample ``(t_s, phi1, phi2, s1, s2, F1, F2)``.

        The drive torque is fetched from the plant only when it is first needed
        (0x6077), see :meth:`sim.drives.SimDrivePair._fetch_torque`.
        """
        k = self.ema_index
        self.raw_sample = raw
        self._phi_rad = raw[1 + k]
        self._pos_memo = None
        memo = self.input_memo
        memo[:] = (None,) * len(memo)  # (the same list: the input getters share it)
        self.torque_stale = True

    def _no_torque_source(self) -> None:
        self.torque_stale = False

    @property
    def _torque_Nm(self) -> float:
        """Drive torque [N m] of the current sample."""
        if self.torque_stale:
            self.torque_fetch()
        return self.torque_value

    @property
    def motor_angle_rad(self) -> float:
        """Motor angle [rad] of the current sample (what 0x6064 is computed from)."""
        return self._phi_rad

    def cpr_changed(self) -> None:
        """0x608F (may have) changed: drop the values derived from the counts per revolution."""
        self._inc_per_rad = None
        self._pos_memo = None

    def angle_increments_per_rad(self) -> float:
        """Increments (position units) per rad, cached: the drive's own units, in this order the
        position factor group 0x6091/0x6092 (where the map reads the angle in user units), the encoder
        resolution 0x608F where the drive has one, the scaling the profile states, 4096 per revolution."""
        k = self._inc_per_rad
        if k is None:
            if self.factor_group:
                so = self.store.int_or
                k = angle_scale_factor_group(so(0x6091, 1, 1), so(0x6091, 2, 1), so(0x6092, 1, 1),
                                             so(0x6092, 2, 1)).units_per_si
            elif self._angle_k is not None and self.store.var(0x608F, 1) is None:
                k = self._angle_k
            else:
                k = increments_per_rad(self.counts_per_rev)
            self._inc_per_rad = k
        return k

    @property
    def counts_per_rev(self) -> float:
        """Position increments per motor revolution: 0x608F:01 / 0x608F:02 (a drive without 0x608F:
        the profile's, else 4096)."""
        so = self.store.int_or
        if self._angle_k is not None and self.store.var(0x608F, 1) is None:
            return self._angle_k * 2.0 * math.pi
        return so(0x608F, 1, 4096) / so(0x608F, 2, 1)

    @property
    def position_inc(self) -> int:
        """Position actual value 0x6064 [increments] of the current sample."""
        return self._position_now()

    def _position_now(self) -> int:
        v = self._pos_memo
        if v is None:
            phi = self._phi_rad
            try:
                k = self._inc_per_rad
                if k is None:
                    k = self.angle_increments_per_rad()
                v = rad_to_increments_unchecked(phi, k)
            except (ValueError, ArithmeticError):  # (CanopenInputError is a ValueError)
                return rad_to_increments(phi, self.counts_per_rev)  # raises its own error
            self._pos_memo = v
        return v

    @property
    def torque_actual_permille(self) -> int:
        """Torque actual value 0x6077 [per mille of the rated torque 0x6076]."""
        return torque_to_permille_unchecked(self._torque_Nm, self._rated_Nm())

    def _rated_Nm(self) -> float:
        """The motor's rated torque [N m]: the profile's where it states it, else 0x6076 [mN m]."""
        if self._rated_override is not None:
            return self._rated_override
        return self.store.int_or(0x6076, 0, 1000) / 1000.0

    @property
    def statusword(self) -> int:
        """Statusword 0x6041 now.

        State bits from the state machine, remote (bit 9) always; in
        OPERATION_ENABLED with a supported mode: bit 12 (drive follows the
        command), bit 11 when the last target was clipped (software position
        limits 0x607D or max motor speed 0x6080 in CSP, max torque 0x6072 or
        the speed limitation by 0x6080 in CST), bit 10 in CSP when
        ``|effective target - position actual| <= TARGET_WINDOW_INC``.
        """
        return self._statusword_now()

    def _statusword_now(self) -> int:
        # = sm.statusword(extra): hil.canopen.cia402.state_word of the state | remote bit | extra
        sm = self.state_machine
        state = sm.state
        extra = 0
        if state is _OE:
            mode = self.int_cache.get(_K_MODE)
            if mode is None:
                mode = self.int_value(0x6060)
            if self.mode_frozen:
                mode = self._mode_display
            if mode in self._modes:
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

    def _set_setpoint(self, mode: int, value: float) -> None:
        """The plant command of this cycle (``mode`` a DriveMode value); :attr:`setpoint` builds it."""
        self._sp_mode = mode
        self._sp_value = value
        self._sp_obj = None

    # ------------------------------------------------------------------ the state machine

    def enter_fault(self, code: int) -> None:
        """Transition 13 with error ``code`` and its EMCY."""
        self.state_machine.fault(code)
        self.send_emcy(code)

    def controlword_written(self) -> None:
        """Apply the controlword 0x6040 just written (by RPDO or SDO)."""
        sm = self.state_machine
        old = sm.state
        cw = self.int_cache.get(_K_CONTROLWORD)
        if cw is None:
            cw = self.int_value(0x6040)
        if old is _NRTSO:  # processes no command (ignored); (hook) the first controlword ends the wait
            sm.on_controlword(cw)
            if self.not_ready_until_controlword:
                sm.boot_done()
            return
        # The master repeats the controlword every cycle: the same word as the previous
        # one in a state where that was seen to be a no-op is a no-op again (the outcome
        # of on_controlword depends only on the state, the previous and this word).
        repeated = cw == sm.previous_controlword
        before_code, before_transition = sm.error_code, sm.last_transition
        if repeated:
            seen = self._cw_noop.get(cw)
            if seen is not None and old in seen:
                return
            before = (sm.last_transition, sm.error_code)
        try:
            sm.on_controlword(cw)
        except IllegalTransition:
            self.counters.illegal_commands += 1
            return
        new = sm.state
        if old is State.FAULT and new is not old:
            self._resets_seen += 1
            if self._resets_seen < self.fault_resets_needed:  # (hook) this reset is ignored
                sm.state, sm.error_code, sm.last_transition = old, before_code, before_transition
                return
            self._resets_seen = 0
            self.boot_fault = 0  # the cause of a fault found at boot is cleared
        if repeated and new is old and (sm.last_transition, sm.error_code) == before:
            self._cw_noop[cw] = self._cw_noop.get(cw, ()) + (old,)
        self._entered(old, new)
        if old is State.FAULT and new is State.SWITCH_ON_DISABLED:
            self.send_emcy(EMCY_NO_ERROR)

    def _entered(self, old: State, new: State) -> None:
        """A transition ``old`` -> ``new`` was taken: a quick stop starts as 0x605A says (holding the
        angle measured now)."""
        if new is State.QUICK_STOP_ACTIVE and old is not State.QUICK_STOP_ACTIVE:
            option = self.store.int_or(0x605A, 0, _QS_DEFAULT)
            self._qs_phi_rad = self._phi_rad
            self._qs_left = 0 if option == 0 else self._qs_cycles
            self._qs_stay = self.quick_stop_stays or option in _QS_STAY
            self.state_machine.quick_stop_stays = self._qs_stay  # transition 16 only then

    def connection_lost(self) -> None:
        """The abort connection option 0x6007 on a connection loss (a heartbeat event), through
        the CiA 402 transition table: 1 fault, 2 disable voltage, 3 quick stop (0 nothing)."""
        if self.ignore_abort_connection:
            return  # (fault hook) the EMCY went out, the drive goes on
        sm = self.state_machine
        old = sm.state
        option = self.int_value(0x6007) if self.store.var(0x6007, 0) is not None else 0
        try:
            if option == AbortConnectionOption.FAULT:
                sm.fault(EMCY_HEARTBEAT)
            elif option in _ABORT_COMMAND:
                sm.apply(_ABORT_COMMAND[option])
        except IllegalTransition:
            return  # no such transition in this state (FAULT, NOT_READY_TO_SWITCH_ON): kept
        self._entered(old, sm.state)

    def drive_cycle(self) -> tuple[int, float]:
        """The drive's control cycle at a SYNC: internal transitions and the plant command.

        Returns the plant command ``(mode, value)`` (a DriveMode value and rad / N),
        also kept as :attr:`setpoint`.
        """
        sm = self.state_machine
        prev_demand = self._target_eff_inc  # the last cycle's CSP demand (None: it was not in CSP)
        self.cycle_angle(self._phi_rad)  # (sim.drives.limits: the CST speed estimate)
        if sm.state is _FRA:
            sm.fault_reaction_done()
        if sm.state is _QSA:
            if self._qs_left > 0 or self._qs_stay:
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
            ic = self.int_cache
            mode = ic.get(_K_MODE)
            if mode is None:
                mode = self.int_value(0x6060)
            if self.mode_frozen:
                mode = self._mode_display
            if mode == _CSP and _CSP in self._modes and self.following_error_exceeded(prev_demand):
                mode = None  # faulted (0x8611): FAULT REACTION ACTIVE, the drive function disabled
            if mode == _CSP and _CSP in self._modes:  # (a supported mode, so the effective one)
                target = ic.get(_K_TARGET_POS)
                if target is None:
                    target = self.int_value(0x607A)
                lo = ic.get(_K_POS_MIN)
                if lo is None:
                    lo = self.store.int_or(0x607D, 1, -(2**31))
                hi = ic.get(_K_POS_MAX)
                if hi is None:
                    hi = self.store.int_or(0x607D, 2, 2**31 - 1)
                eff = self.speed_limited(min(max(target, lo), hi), prev_demand)  # (sim.drives.limits)
                self._limit_active = eff != target
                self._target_eff_inc = eff
                try:
                    k = self._inc_per_rad
                    if k is None:
                        k = self.angle_increments_per_rad()
                    value = increments_to_rad_unchecked(eff, k)  # (an int divided by a float: float(eff) / k)
                except (ArithmeticError, CanopenInputError):
                    value = increments_to_rad(eff, self.counts_per_rev)  # raises its own error
                mode_out = _MODE_POSITION
            elif mode == _CST and _CST in self._modes:
                tau = ic.get(_K_TARGET_TORQUE)
                if tau is None:
                    tau = self.int_value(0x6071)
                tmax = ic.get(_K_MAX_TORQUE)
                if tmax is None:
                    tmax = self.store.int_or(0x6072, 0, 32767)
                eff = min(max(tau, -tmax), tmax)
                rated_Nm = self._rated_Nm()
                i_total = self._i_total
                if 0.0 < rated_Nm < math.inf and 0.0 < i_total < math.inf:
                    force = permille_to_force_N_unchecked(eff, i_total, rated_Nm)
                else:
                    force = permille_to_force_N(eff, i_total, rated_Nm)  # raises its own error
                # the max motor speed 0x6080 (sim.drives.limits), within 0x6072
                value = self.speed_held(force, permille_to_force_N_unchecked(tmax, i_total, rated_Nm), i_total)
                self._limit_active = eff != tau or value != force
                mode_out = _MODE_FORCE
        self._sp_mode = mode_out  # (_set_setpoint inlined)
        self._sp_value = value
        self._sp_obj = None
        return mode_out, value
