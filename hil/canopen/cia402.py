"""CiA 402 drive state machine (CiA 402-2 / IEC 61800-7-201), device and master side.

One transition table, :data:`TRANSITIONS`, drives both sides: the simulated
drive applies it to the controlword it receives (:class:`DriveStateMachine`),
the master searches it for the commands that bring a drive to a target state
(:func:`path`, :func:`next_command`). No IO, no clocks.

Power drive state machine (transition numbers as in CiA 402)::

    NOT_READY_TO_SWITCH_ON --1 (boot done)--> SWITCH_ON_DISABLED
    SWITCH_ON_DISABLED  --2 shutdown-->          READY_TO_SWITCH_ON
    READY_TO_SWITCH_ON  --3 switch on-->         SWITCHED_ON
    SWITCHED_ON         --4 enable operation-->  OPERATION_ENABLED
    OPERATION_ENABLED   --5 disable operation--> SWITCHED_ON
    SWITCHED_ON         --6 shutdown-->          READY_TO_SWITCH_ON
    READY_TO_SWITCH_ON  --7 disable voltage / quick stop--> SWITCH_ON_DISABLED
    OPERATION_ENABLED   --8 shutdown-->          READY_TO_SWITCH_ON
    OPERATION_ENABLED   --9 disable voltage-->   SWITCH_ON_DISABLED
    SWITCHED_ON         --10 disable voltage / quick stop--> SWITCH_ON_DISABLED
    OPERATION_ENABLED   --11 quick stop-->       QUICK_STOP_ACTIVE
    QUICK_STOP_ACTIVE   --12 quick stop done / disable voltage--> SWITCH_ON_DISABLED
    any                 --13 fault-->            FAULT_REACTION_ACTIVE
    FAULT_REACTION_ACTIVE --14 reaction done-->  FAULT
    FAULT               --15 fault reset-->      SWITCH_ON_DISABLED
    QUICK_STOP_ACTIVE   --16 enable operation--> OPERATION_ENABLED  (quick stop option code 5..8 only)

Transition 16 is in the table, marked conditional (:data:`CONDITIONAL`): CiA 402 (IEC 61800-7-201)
allows it only while the quick stop option code 0x605A is 5..8 (the drive stays in QUICK STOP ACTIVE
after its ramp); a :class:`DriveStateMachine` takes it only with ``quick_stop_stays`` set. The
master never uses it: :func:`path` leaves it out (after a quick stop a drive is taken down to
SWITCH_ON_DISABLED and walked up again), and emacheck writes 0x605A = 2.

In NOT_READY_TO_SWITCH_ON the drive initialises and processes no command (:data:`IGNORING`): a
controlword received there is ignored, not refused. Some drives leave it only once a first
controlword arrived (a CiA 402 slave on lely-core); the master sends disable voltage (0x0000) there,
harmless in every state (:data:`MASTER_COMMANDS`).
"""

from __future__ import annotations

from collections import deque
from enum import Enum, IntEnum, IntFlag

from hil.canopen.errors import CanopenError, CanopenInputError
from hil.canopen.validate import word16 as _word


class State(Enum):
    """States of the CiA 402 power drive state machine."""

    NOT_READY_TO_SWITCH_ON = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP_ACTIVE = "quick stop active"
    FAULT_REACTION_ACTIVE = "fault reaction active"
    FAULT = "fault"


class Statusword(IntFlag):
    """Bits of the statusword 0x6041."""

    READY_TO_SWITCH_ON = 1 << 0
    SWITCHED_ON = 1 << 1
    OPERATION_ENABLED = 1 << 2
    FAULT = 1 << 3
    VOLTAGE_ENABLED = 1 << 4
    QUICK_STOP = 1 << 5  #: active low: 1 = quick stop NOT active
    SWITCH_ON_DISABLED = 1 << 6
    WARNING = 1 << 7
    REMOTE = 1 << 9  #: controlword is processed (remote control by the master)
    TARGET_REACHED = 1 << 10
    INTERNAL_LIMIT_ACTIVE = 1 << 11
    #: mode specific; CSP and CST: 1 = drive follows the command value,
    #: 0 = target position (CSP) / target torque (CST) ignored
    DRIVE_FOLLOWS_COMMAND = 1 << 12
    FOLLOWING_ERROR = 1 << 13  #: mode specific (CSP: following error)


class Controlword(IntFlag):
    """Bits of the controlword 0x6040."""

    SWITCH_ON = 1 << 0
    ENABLE_VOLTAGE = 1 << 1
    QUICK_STOP = 1 << 2  #: active low: 0 = quick stop
    ENABLE_OPERATION = 1 << 3
    FAULT_RESET = 1 << 7  #: rising edge = fault reset
    HALT = 1 << 8


class Command(Enum):
    """Device control commands (CiA 402 Table 'device control commands')."""

    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch on"
    DISABLE_VOLTAGE = "disable voltage"
    QUICK_STOP = "quick stop"
    DISABLE_OPERATION = "disable operation"
    ENABLE_OPERATION = "enable operation"
    FAULT_RESET = "fault reset"


class OperationMode(IntEnum):
    """Modes of operation (0x6060 / 0x6061)."""

    PROFILE_POSITION = 1
    PROFILE_VELOCITY = 3
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CSP = 8
    CSV = 9
    CST = 10


class IllegalTransition(CanopenError, ValueError):
    """A command or event that the state machine does not allow in the current state."""


# (mask, value) of the command bits 7, 3, 2, 1, 0.
_COMMAND_PATTERN: dict[Command, tuple[int, int]] = {
    Command.SHUTDOWN: (0x0087, 0x0006),  # 0xxx x110
    Command.SWITCH_ON: (0x008F, 0x0007),  # 0xxx 0111
    Command.DISABLE_VOLTAGE: (0x0082, 0x0000),  # 0xxx xx0x
    Command.QUICK_STOP: (0x0086, 0x0002),  # 0xxx x01x
    Command.DISABLE_OPERATION: (0x008F, 0x0007),  # 0xxx 0111 (same bits as switch on)
    Command.ENABLE_OPERATION: (0x008F, 0x000F),  # 0xxx 1111
    Command.FAULT_RESET: (0x0080, 0x0080),  # rising edge of bit 7
}

_CONTROLWORD: dict[Command, int] = {
    Command.SHUTDOWN: 0x0006,
    Command.SWITCH_ON: 0x0007,
    Command.DISABLE_VOLTAGE: 0x0000,
    Command.QUICK_STOP: 0x0002,
    Command.DISABLE_OPERATION: 0x0007,
    Command.ENABLE_OPERATION: 0x000F,
    Command.FAULT_RESET: 0x0080,
}
_CONTROLWORD_BY_ID: dict[int, int] = {id(c): w for c, w in _CONTROLWORD.items()}  #: (:func:`controlword`)

# (mask, value) of the statusword bits 6, 5, 3, 2, 1, 0.
_STATE_PATTERN: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x004F, 0x0000),  # x0xx 0000
    State.SWITCH_ON_DISABLED: (0x004F, 0x0040),  # x1xx 0000
    State.READY_TO_SWITCH_ON: (0x006F, 0x0021),  # x01x 0001
    State.SWITCHED_ON: (0x006F, 0x0023),  # x01x 0011
    State.OPERATION_ENABLED: (0x006F, 0x0027),  # x01x 0111
    State.QUICK_STOP_ACTIVE: (0x006F, 0x0007),  # x00x 0111
    State.FAULT_REACTION_ACTIVE: (0x004F, 0x000F),  # x0xx 1111
    State.FAULT: (0x004F, 0x0008),  # x0xx 1000
}

_STATE_BITS = 0x006F  # the bits state_word owns: 0, 1, 2, 3, 5, 6

# The statusword of each state; voltage enabled (bit 4) once the drive is
# initialised, quick stop bit (5, active low) set where the pattern has it.
_STATE_WORD: dict[State, int] = {
    State.NOT_READY_TO_SWITCH_ON: 0x0000,
    State.SWITCH_ON_DISABLED: 0x0050,
    State.READY_TO_SWITCH_ON: 0x0031,
    State.SWITCHED_ON: 0x0033,
    State.OPERATION_ENABLED: 0x0037,
    State.QUICK_STOP_ACTIVE: 0x0017,
    State.FAULT_REACTION_ACTIVE: 0x001F,
    State.FAULT: 0x0018,
}

#: THE transition table: (state, command) -> (new state, CiA 402 transition number).
#: Transitions 1, 13, 14 and the automatic 12 are events, see DriveStateMachine.
TRANSITIONS: dict[tuple[State, Command], tuple[State, int]] = {
    (State.SWITCH_ON_DISABLED, Command.SHUTDOWN): (State.READY_TO_SWITCH_ON, 2),
    (State.READY_TO_SWITCH_ON, Command.SWITCH_ON): (State.SWITCHED_ON, 3),
    (State.SWITCHED_ON, Command.ENABLE_OPERATION): (State.OPERATION_ENABLED, 4),
    (State.OPERATION_ENABLED, Command.DISABLE_OPERATION): (State.SWITCHED_ON, 5),
    (State.SWITCHED_ON, Command.SHUTDOWN): (State.READY_TO_SWITCH_ON, 6),
    (State.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE): (State.SWITCH_ON_DISABLED, 7),
    (State.READY_TO_SWITCH_ON, Command.QUICK_STOP): (State.SWITCH_ON_DISABLED, 7),
    (State.OPERATION_ENABLED, Command.SHUTDOWN): (State.READY_TO_SWITCH_ON, 8),
    (State.OPERATION_ENABLED, Command.DISABLE_VOLTAGE): (State.SWITCH_ON_DISABLED, 9),
    (State.SWITCHED_ON, Command.DISABLE_VOLTAGE): (State.SWITCH_ON_DISABLED, 10),
    (State.SWITCHED_ON, Command.QUICK_STOP): (State.SWITCH_ON_DISABLED, 10),
    (State.OPERATION_ENABLED, Command.QUICK_STOP): (State.QUICK_STOP_ACTIVE, 11),
    (State.QUICK_STOP_ACTIVE, Command.DISABLE_VOLTAGE): (State.SWITCH_ON_DISABLED, 12),
    (State.FAULT, Command.FAULT_RESET): (State.SWITCH_ON_DISABLED, 15),
    (State.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION): (State.OPERATION_ENABLED, 16),
}

#: Transitions a drive takes only under a condition of its configuration: 16 only with the quick stop
#: option code 0x605A = 5..8 (:attr:`DriveStateMachine.quick_stop_stays`); :func:`path` never uses them.
CONDITIONAL = frozenset((16,))

#: States in which a drive processes no command (CiA 402: initialisation): a controlword there leaves
#: the state as it is, it is not refused.
IGNORING = frozenset((State.NOT_READY_TO_SWITCH_ON,))

#: Commands that lead into a state: receiving one of them again in that state
#: is a no-op (the master repeats the controlword every SYNC cycle).
HOLDING_COMMANDS: dict[State, frozenset[Command]] = {
    s: frozenset(c for (_, c), (dst, _) in TRANSITIONS.items() if dst is s) for s in State
}


def controlword(cmd: Command) -> int:
    """The standard controlword of a command (bits 4..6, 8..15 clear).

    SHUTDOWN 0x0006, SWITCH_ON 0x0007, DISABLE_VOLTAGE 0x0000, QUICK_STOP
    0x0002, DISABLE_OPERATION 0x0007, ENABLE_OPERATION 0x000F, FAULT_RESET
    0x0080 (the drive acts on the rising edge of bit 7, so the word before
    must have bit 7 clear).
    """
    # (keyed by the member's identity, an int: an Enum member hashes through Enum.__hash__, in Python; the
    # members live as long as the module)
    return _CONTROLWORD_BY_ID[id(cmd if cmd.__class__ is Command else Command(cmd))]


def decode_command(cw: int, previous_cw: int | None = None) -> Command | None:
    """The command a controlword carries (CiA 402 device control commands).

    Parameters
    ----------
    cw : int
        Controlword, 0..0xFFFF.
    previous_cw : int, optional
        The controlword received before; a set bit 7 is a fault reset only on
        its rising edge. Without it, a set bit 7 is taken as a fault reset.

    Returns
    -------
    Command or None
        None when bit 7 is held high (no new command). The patterns of
        SWITCH_ON and DISABLE_OPERATION coincide (0xxx 0111): this returns
        SWITCH_ON; the state decides which one it is (see
        :meth:`DriveStateMachine.on_controlword`).

    Notes
    -----
    With bit 7 clear the five command bits (3, 2, 1, 0) partition into
    shutdown ``x110``, switch on ``0111``, enable operation ``1111``,
    disable voltage ``xx0x`` and quick stop ``x01x``.
    """
    w = _word("cw", cw)
    if w & Controlword.FAULT_RESET:
        if previous_cw is not None and _word("previous_cw", previous_cw) & Controlword.FAULT_RESET:
            return None
        return Command.FAULT_RESET
    for cmd in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION,
                Command.DISABLE_VOLTAGE, Command.QUICK_STOP):
        mask, value = _COMMAND_PATTERN[cmd]
        if w & mask == value:
            return cmd
    raise AssertionError(f"controlword 0x{w:04X} matched no command")  # unreachable: patterns partition


def match_state(sw: int) -> State | None:
    """The state whose statusword pattern ``sw`` matches, None if it matches none."""
    w = _word("sw", sw)
    for state, (mask, value) in _STATE_PATTERN.items():
        if w & mask == value:
            return state
    return None


def decode_state(sw: int) -> State:
    """The drive state a statusword reports (CiA 402 masks 0x004F / 0x006F).

    Total over all 16-bit words: a word that matches no pattern (an invalid
    combination of bits 0..3, 5, 6) decodes as NOT_READY_TO_SWITCH_ON, the
    state in which the drive accepts no command and the master waits; use
    :func:`match_state` to tell those words apart.

    Notes
    -----
    ======================  ======  =====================
    state                   mask    value (bits 6 5 3..0)
    ======================  ======  =====================
    not ready to switch on  0x004F  0x0000 (x0xx 0000)
    switch on disabled      0x004F  0x0040 (x1xx 0000)
    ready to switch on      0x006F  0x0021 (x01x 0001)
    switched on             0x006F  0x0023 (x01x 0011)
    operation enabled       0x006F  0x0027 (x01x 0111)
    quick stop active       0x006F  0x0007 (x00x 0111)
    fault reaction active   0x004F  0x000F (x0xx 1111)
    fault                   0x004F  0x0008 (x0xx 1000)
    ======================  ======  =====================
    """
    return _DECODED[_word("sw", sw)]  # (word16 refuses anything but a 16-bit word, naming "sw")


def _decoded_words() -> tuple[State, ...]:
    """:func:`decode_state` of every 16-bit word, from :func:`match_state` of its bits 0..6: every
    pattern's mask lies in 0x007F, so bits 7..15 never change the state and the 128 states of
    words 0..0x7F repeat 512 times."""
    assert all(mask & ~0x007F == 0 for mask, _ in _STATE_PATTERN.values())
    return tuple([match_state(w) or State.NOT_READY_TO_SWITCH_ON for w in range(0x80)] * 0x200)


#: The state each 16-bit word reports, indexed by the word (:func:`decode_state`); built at import,
#: about 0.3 ms
_DECODED: tuple[State, ...] = _decoded_words()


def state_word(state: State, *, extra: Statusword | int = 0) -> int:
    """The statusword a drive reports in ``state``, OR-ed with ``extra`` bits.

    Voltage enabled (bit 4) is set in every state but NOT_READY_TO_SWITCH_ON;
    quick stop (bit 5, active low) is set in ready to switch on, switched on
    and operation enabled. ``extra`` may hold any bit but the state bits
    0, 1, 2, 3, 5, 6 (e.g. REMOTE | TARGET_REACHED); with REMOTE, switch on
    disabled is 0x0250 and operation enabled 0x0237.
    """
    x = _word("extra", int(extra))
    if x & _STATE_BITS:
        raise CanopenInputError(f"extra = 0x{x:04X} touches the state bits 0x{_STATE_BITS:04X}")
    return _STATE_WORD[State(state)] | x


def _targets(state: State, cmd: Command, conditional: bool = False) -> tuple[State, int] | None:
    """The transition of ``cmd`` in ``state``; a :data:`CONDITIONAL` one only with ``conditional``."""
    hit = TRANSITIONS.get((state, cmd))
    if hit is not None and hit[1] in CONDITIONAL and not conditional:
        return None
    return hit


class DriveStateMachine:
    """Device side of the CiA 402 state machine (the simulated drive's core).

    Parameters
    ----------
    remote : bool
        Report the remote bit (9) in :meth:`statusword`.

    Attributes
    ----------
    state : State
        Current state; starts in NOT_READY_TO_SWITCH_ON.
    last_transition : int or None
        CiA 402 number of the last transition taken.
    error_code : int
        The fault's error code (0x603F), 0 when no fault is latched.
    quick_stop_stays : bool
        The quick stop option code keeps the drive in QUICK_STOP_ACTIVE (0x605A = 5..8): enable
        operation there is transition 16 (else refused).
    """

    def __init__(self, *, remote: bool = True) -> None:
        self.state = State.NOT_READY_TO_SWITCH_ON
        self.last_transition: int | None = None
        self.error_code = 0
        self.remote = bool(remote)
        self.quick_stop_stays = False
        self._previous_cw = 0

    @property
    def previous_controlword(self) -> int:
        """The controlword received last (0 before the first): bit 7 acts on its rising edge."""
        return self._previous_cw

    def _go(self, new: State, number: int) -> State:
        self.state = new
        self.last_transition = number
        if number == 15:  # fault reset clears the latched error
            self.error_code = 0
        return new

    def _illegal(self, what: str) -> IllegalTransition:
        return IllegalTransition(f"{what} not allowed in state {self.state.name}")

    def apply(self, cmd: Command) -> State:
        """Apply a command; a command leading into the current state is a no-op, and so is any
        command in a state that processes none (:data:`IGNORING`).

        Raises
        ------
        IllegalTransition
            The command is neither a transition nor a no-op in this state.
        """
        cmd = Command(cmd)
        if self.state in IGNORING:
            return self.state
        hit = _targets(self.state, cmd, self.quick_stop_stays)
        if hit is not None:
            return self._go(*hit)
        if cmd in HOLDING_COMMANDS[self.state]:
            return self.state
        raise self._illegal(f"command {cmd.name}")

    def on_controlword(self, cw: int) -> State:
        """Apply the controlword received at a SYNC (or on reception) and return the new state.

        Bit 7 acts on its rising edge only; while it is held high nothing
        happens. The pattern 0xxx 0111 is SWITCH_ON or DISABLE_OPERATION,
        whichever the current state allows. A fault reset is a no-op in
        SWITCH_ON_DISABLED (where it leads) and raises in the other states
        but FAULT, like any other command not allowed there. The combined
        "switch on + enable operation" (0x000F in READY_TO_SWITCH_ON,
        transitions 3 + 4) is not accepted: the master sends the steps of
        :func:`path` one by one. In NOT_READY_TO_SWITCH_ON every controlword is ignored
        (:data:`IGNORING`); enable operation in QUICK_STOP_ACTIVE is transition 16 only with
        :attr:`quick_stop_stays`.

        Raises
        ------
        IllegalTransition
            The command is not allowed in the current state (the state is
            unchanged; the device wrapper reports it, e.g. by an EMCY).
        """
        w = _word("cw", cw)
        previous, self._previous_cw = self._previous_cw, w
        cmd = decode_command(w, previous)
        if cmd is None or self.state in IGNORING:
            return self.state
        candidates = [cmd]
        if cmd is Command.SWITCH_ON:
            candidates.append(Command.DISABLE_OPERATION)
        for c in candidates:
            hit = _targets(self.state, c, self.quick_stop_stays)
            if hit is not None:
                return self._go(*hit)
        for c in candidates:
            if c in HOLDING_COMMANDS[self.state]:
                return self.state
        raise self._illegal(f"controlword 0x{w:04X} ({cmd.name})")

    def boot_done(self) -> State:
        """Transition 1: initialisation done, NOT_READY_TO_SWITCH_ON -> SWITCH_ON_DISABLED."""
        if self.state is not State.NOT_READY_TO_SWITCH_ON:
            raise self._illegal("boot done (transition 1)")
        return self._go(State.SWITCH_ON_DISABLED, 1)

    def fault(self, code: int) -> State:
        """Transition 13: a fault occurred; any state -> FAULT_REACTION_ACTIVE.

        ``code`` is the error code (0x603F, e.g. 0x8611 following error). In
        FAULT_REACTION_ACTIVE or FAULT the first code stays latched and the
        state is unchanged.
        """
        c = _word("code", code)
        if self.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return self.state
        self.error_code = c
        return self._go(State.FAULT_REACTION_ACTIVE, 13)

    def fault_reaction_done(self) -> State:
        """Transition 14: fault reaction completed, FAULT_REACTION_ACTIVE -> FAULT."""
        if self.state is not State.FAULT_REACTION_ACTIVE:
            raise self._illegal("fault reaction done (transition 14)")
        return self._go(State.FAULT, 14)

    def quick_stop_done(self) -> State:
        """Transition 12 (option code 2): ramp finished, QUICK_STOP_ACTIVE -> SWITCH_ON_DISABLED."""
        if self.state is not State.QUICK_STOP_ACTIVE:
            raise self._illegal("quick stop done (transition 12)")
        return self._go(State.SWITCH_ON_DISABLED, 12)

    def statusword(self, extra: Statusword | int = 0) -> int:
        """The statusword for the current state (remote bit per ``remote``) OR ``extra``."""
        x = int(extra) | (Statusword.REMOTE if self.remote else 0)
        return state_word(self.state, extra=x)


def path(from_state: State, to: State) -> list[Command]:
    """Shortest list of commands that takes a drive from ``from_state`` to ``to``.

    Breadth-first search over :data:`TRANSITIONS` without the :data:`CONDITIONAL` ones (transition 16
    depends on the drive's 0x605A); ties are broken by the order of :class:`Command`. ``path(s, s) == []``.

    Raises
    ------
    IllegalTransition
        No sequence of commands reaches ``to`` (e.g. to FAULT, or from
        FAULT_REACTION_ACTIVE, which only an internal event leaves).
    """
    src, dst = State(from_state), State(to)
    if src is dst:
        return []
    previous: dict[State, tuple[State, Command]] = {}
    queue = deque([src])
    seen = {src}
    while queue:
        s = queue.popleft()
        for cmd in Command:
            hit = _targets(s, cmd)
            if hit is None or hit[0] in seen:
                continue
            nxt = hit[0]
            seen.add(nxt)
            previous[nxt] = (s, cmd)
            if nxt is dst:
                cmds: list[Command] = []
                node = dst
                while node is not src:
                    node, c = previous[node]
                    cmds.append(c)
                return cmds[::-1]
            queue.append(nxt)
    raise IllegalTransition(f"no command sequence leads from {src.name} to {dst.name}")


_WAIT_STATES = frozenset(
    s for s in State if not any(src is s for (src, _) in TRANSITIONS)
)  # NOT_READY_TO_SWITCH_ON, FAULT_REACTION_ACTIVE: only an internal event leaves them (no command does)


def next_command(current: State, target: State) -> Command | None:
    """The command the master sends next to bring a drive from ``current`` towards ``target``.

    Returns None when ``current`` is ``target`` or when the drive is in a
    state no command leaves (NOT_READY_TO_SWITCH_ON, FAULT_REACTION_ACTIVE):
    the master waits for the drive's internal transition.

    Raises
    ------
    IllegalTransition
        ``target`` cannot be reached by commands (e.g. FAULT).
    """
    cur, tgt = State(current), State(target)
    if cur is tgt or cur in _WAIT_STATES:
        return None
    return path(cur, tgt)[0]


# --------------------------------------------------------------------------- the master's side


class Goal(Enum):
    """Where the master is taking a drive."""

    ENABLED = "enabled"  #: power up to OPERATION_ENABLED and hold it there
    ORDERLY_DOWN = "orderly down"  #: disable operation, shutdown, disable voltage (a finished check)
    QUICK_STOP = "quick stop"  #: quick stop, then disable voltage (an abort)
    #: disable voltage from any state at once (transitions 7, 9, 10, 12): a drive at standstill holding
    #: its position, powered up by SDO for the master's-death drill
    DISABLED = "disabled"


#: The state a drive is confirmed safe in: the power stage off and no command to move accepted
#: until the master walks it up again. Whatever its quick stop option code 0x605A says, the master
#: takes every drive there at the end of a check (from QUICK_STOP_ACTIVE once it stands still, from
#: FAULT by fault reset).
SAFE_STATES = frozenset((State.SWITCH_ON_DISABLED,))

_QSA = State.QUICK_STOP_ACTIVE

#: THE master's table: (goal, state) -> the command to send in that state (None: send nothing new,
#: wait for the drive's own transition). QUICK_STOP_ACTIVE is resolved by :func:`master_command`
#: (quick stop until the drive stands still, then disable voltage, transition 12); FAULT is a fault
#: reset (transition 15), which the master repeats a bounded number of times. NOT_READY_TO_SWITCH_ON:
#: disable voltage (0x0000), ignored there by a drive that initialises (:data:`IGNORING`), the first
#: controlword a drive may wait for before it takes transition 1; the master waits, bounded.
MASTER_COMMANDS: dict[tuple[Goal, State], Command | None] = {
    **{(Goal.ENABLED, s): c for s, c in (
        (State.NOT_READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCH_ON_DISABLED, Command.SHUTDOWN),
        (State.READY_TO_SWITCH_ON, Command.SWITCH_ON), (State.SWITCHED_ON, Command.ENABLE_OPERATION),
        (State.OPERATION_ENABLED, Command.ENABLE_OPERATION), (State.FAULT_REACTION_ACTIVE, None),
        (State.FAULT, Command.FAULT_RESET))},
    **{(Goal.ORDERLY_DOWN, s): c for s, c in (
        (State.NOT_READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCH_ON_DISABLED, Command.DISABLE_VOLTAGE),
        (State.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCHED_ON, Command.SHUTDOWN),
        (State.OPERATION_ENABLED, Command.DISABLE_OPERATION), (State.FAULT_REACTION_ACTIVE, None),
        (State.FAULT, Command.FAULT_RESET))},
    **{(Goal.QUICK_STOP, s): c for s, c in (
        (State.NOT_READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCH_ON_DISABLED, Command.DISABLE_VOLTAGE),
        (State.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCHED_ON, Command.DISABLE_VOLTAGE),
        (State.OPERATION_ENABLED, Command.QUICK_STOP), (State.FAULT_REACTION_ACTIVE, None),
        (State.FAULT, Command.FAULT_RESET))},
    **{(Goal.DISABLED, s): c for s, c in (
        (State.NOT_READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCH_ON_DISABLED, Command.DISABLE_VOLTAGE),
        (State.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE), (State.SWITCHED_ON, Command.DISABLE_VOLTAGE),
        (State.OPERATION_ENABLED, Command.DISABLE_VOLTAGE), (State.FAULT_REACTION_ACTIVE, None),
        (State.FAULT, Command.FAULT_RESET))},
}

#: :data:`MASTER_COMMANDS` keyed by the members' identities (:func:`master_command`)
_MASTER_BY_ID: dict[tuple[int, int], Command | None] = {(id(g), id(s)): c for (g, s), c in MASTER_COMMANDS.items()}
#: the controlwords of :data:`MASTER_COMMANDS` keyed by the identities of (goal, state), for every entry but
#: QUICK_STOP_ACTIVE's and those whose command is a fault reset or none (those need :func:`master_command`
#: and the master's own handling): the master's every cycle, one look-up
PLAIN_CONTROLWORDS: dict[tuple[int, int], int] = {
    (id(g), id(s)): _CONTROLWORD[c] for (g, s), c in MASTER_COMMANDS.items()
    if s is not State.QUICK_STOP_ACTIVE and c is not None and c is not Command.FAULT_RESET}


def master_command(goal: Goal, state: State, *, stopped: bool = False) -> Command | None:
    """The command the master sends a drive in ``state`` on its way to ``goal``.

    Parameters
    ----------
    goal : Goal
    state : State
        The drive's state as its statusword reports it.
    stopped : bool
        The drive stands still (only read in QUICK_STOP_ACTIVE).

    Returns
    -------
    Command or None
        From :data:`MASTER_COMMANDS`; in QUICK_STOP_ACTIVE quick stop while the drive
        still moves and disable voltage (transition 12) once it stands still, for every goal
        but DISABLED (disable voltage at once): a drive whose quick stop option code keeps it
        there (0x605A = 5..8) is still taken to SWITCH_ON_DISABLED (never transition 16).
        Every command returned is a transition of :data:`TRANSITIONS`, holds the state or is
        sent in a state that ignores commands (a test checks the table against it).
    """
    if state is _QSA:
        return Command.DISABLE_VOLTAGE if stopped or goal is Goal.DISABLED else Command.QUICK_STOP
    # (the members themselves as they are, anything else through its Enum; looked up by their identities,
    # ints, not through Enum.__hash__, in Python: the master's hot path)
    return _MASTER_BY_ID[(id(goal if goal.__class__ is Goal else Goal(goal)),
                          id(state if state.__class__ is State else State(state)))]


def enables_operation(cw: int) -> bool:
    """True when a controlword carries enable operation (bits 0..3 set, bit 7 clear): the drive
    follows its targets (the CAN-log reader's mode columns)."""
    return decode_command(cw) is Command.ENABLE_OPERATION
