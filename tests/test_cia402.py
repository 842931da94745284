"""CiA 402 state machine: the transition table, golden controlword/statusword paths, decoding."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.canopen.cia402 import (
    MASTER_COMMANDS,
    TRANSITIONS,
    Command,
    Controlword,
    DriveStateMachine,
    Goal,
    IllegalTransition,
    OperationMode,
    State,
    Statusword,
    controlword,
    decode_command,
    decode_state,
    enables_operation,
    master_command,
    match_state,
    next_command,
    path,
    state_word,
)
from hil.canopen.errors import CanopenError, CanopenInputError
from hil.canopen.process import DriveMode

S = State
C = Command

# Independent copy of CiA 402 (IEC 61800-7-201): the test's known answer. Transition 16 (enable
# operation in quick stop active) only with quick stop option code 5..8 (CONDITIONAL below).
EXPECTED = {
    (S.SWITCH_ON_DISABLED, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 2),
    (S.READY_TO_SWITCH_ON, C.SWITCH_ON): (S.SWITCHED_ON, 3),
    (S.SWITCHED_ON, C.ENABLE_OPERATION): (S.OPERATION_ENABLED, 4),
    (S.OPERATION_ENABLED, C.DISABLE_OPERATION): (S.SWITCHED_ON, 5),
    (S.SWITCHED_ON, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 6),
    (S.READY_TO_SWITCH_ON, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 7),
    (S.READY_TO_SWITCH_ON, C.QUICK_STOP): (S.SWITCH_ON_DISABLED, 7),
    (S.OPERATION_ENABLED, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 8),
    (S.OPERATION_ENABLED, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 9),
    (S.SWITCHED_ON, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 10),
    (S.SWITCHED_ON, C.QUICK_STOP): (S.SWITCH_ON_DISABLED, 10),
    (S.OPERATION_ENABLED, C.QUICK_STOP): (S.QUICK_STOP_ACTIVE, 11),
    (S.QUICK_STOP_ACTIVE, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 12),
    (S.FAULT, C.FAULT_RESET): (S.SWITCH_ON_DISABLED, 15),
    (S.QUICK_STOP_ACTIVE, C.ENABLE_OPERATION): (S.OPERATION_ENABLED, 16),
}
CONDITIONAL = {(S.QUICK_STOP_ACTIVE, C.ENABLE_OPERATION)}  # 0x605A = 5..8 only
# In not ready to switch on the drive processes no command: every one is ignored there (not refused).
IGNORED = {(S.NOT_READY_TO_SWITCH_ON, c) for c in C}
# Repeating the command that leads into a state is a no-op there.
NO_OP = {
    (S.SWITCH_ON_DISABLED, C.DISABLE_VOLTAGE), (S.SWITCH_ON_DISABLED, C.QUICK_STOP),
    (S.SWITCH_ON_DISABLED, C.FAULT_RESET), (S.READY_TO_SWITCH_ON, C.SHUTDOWN),
    (S.SWITCHED_ON, C.SWITCH_ON), (S.SWITCHED_ON, C.DISABLE_OPERATION),
    (S.OPERATION_ENABLED, C.ENABLE_OPERATION), (S.QUICK_STOP_ACTIVE, C.QUICK_STOP),
}
MASKS = [  # (state, mask, value) from CiA 402
    (S.NOT_READY_TO_SWITCH_ON, 0x4F, 0x00), (S.SWITCH_ON_DISABLED, 0x4F, 0x40),
    (S.READY_TO_SWITCH_ON, 0x6F, 0x21), (S.SWITCHED_ON, 0x6F, 0x23),
    (S.OPERATION_ENABLED, 0x6F, 0x27), (S.QUICK_STOP_ACTIVE, 0x6F, 0x07),
    (S.FAULT_REACTION_ACTIVE, 0x4F, 0x0F), (S.FAULT, 0x4F, 0x08),
]


def machine_in(state: State) -> DriveStateMachine:
    m = DriveStateMachine()
    m.state = state
    return m


def test_table_is_the_standard_one():
    assert TRANSITIONS == EXPECTED


@pytest.mark.parametrize("state,cmd", list(itertools.product(State, Command)),
                         ids=lambda v: v.name)
def test_every_state_and_command(state, cmd):
    m = machine_in(state)
    if (state, cmd) in CONDITIONAL:
        with pytest.raises(IllegalTransition, match=f"{cmd.name} not allowed in state {state.name}"):
            m.apply(cmd)
        m.quick_stop_stays = True
    if (state, cmd) in EXPECTED:
        new, number = EXPECTED[(state, cmd)]
        assert m.apply(cmd) is new
        assert (m.state, m.last_transition) == (new, number)
    elif (state, cmd) in NO_OP or (state, cmd) in IGNORED:
        assert m.apply(cmd) is state
        assert m.last_transition is None
    else:
        with pytest.raises(IllegalTransition, match=f"{cmd.name} not allowed in state {state.name}"):
            m.apply(cmd)
        assert m.state is state


def test_illegal_transition_is_typed():
    assert issubclass(IllegalTransition, CanopenError) and issubclass(IllegalTransition, ValueError)


def test_controlword_bit_patterns():
    assert {c: controlword(c) for c in Command} == {
        C.SHUTDOWN: 0x0006, C.SWITCH_ON: 0x0007, C.DISABLE_VOLTAGE: 0x0000, C.QUICK_STOP: 0x0002,
        C.DISABLE_OPERATION: 0x0007, C.ENABLE_OPERATION: 0x000F, C.FAULT_RESET: 0x0080,
    }
    assert Controlword.ENABLE_OPERATION | Controlword.QUICK_STOP | Controlword.ENABLE_VOLTAGE \
        | Controlword.SWITCH_ON == 0x000F
    assert (Controlword.FAULT_RESET, Controlword.HALT) == (0x80, 0x100)
    assert (Statusword.REMOTE, Statusword.TARGET_REACHED, Statusword.FOLLOWING_ERROR) == (0x200, 0x400, 0x2000)


@pytest.mark.parametrize("cw,cmd", [
    (0x0006, C.SHUTDOWN), (0x000E, C.SHUTDOWN), (0x0076, C.SHUTDOWN),  # bit 3 and bits 4..6 are x
    (0x0007, C.SWITCH_ON), (0x0107, C.SWITCH_ON), (0x000F, C.ENABLE_OPERATION), (0x011F, C.ENABLE_OPERATION),
    (0x0000, C.DISABLE_VOLTAGE), (0x000D, C.DISABLE_VOLTAGE), (0x0002, C.QUICK_STOP),
    (0x000B, C.QUICK_STOP), (0x0080, C.FAULT_RESET), (0x008F, C.FAULT_RESET),
])
def test_decode_command_masks(cw, cmd):
    assert decode_command(cw) is cmd


def test_fault_reset_needs_a_rising_edge():
    assert decode_command(0x0080, previous_cw=0x000F) is C.FAULT_RESET
    assert decode_command(0x0080, previous_cw=0x0080) is None


@given(st.integers(0, 0xFFFF))
def test_decode_command_only_reads_command_bits(cw):
    assert decode_command(cw) is decode_command(cw & 0x008F)


def test_decode_rejects_non_words():
    with pytest.raises(CanopenInputError, match="0x10000"):
        decode_state(0x10000)
    for bad in (-1, -0x10000, 1.0, "0x0237", True, None):  # (a negative index would read the table backwards)
        with pytest.raises(CanopenInputError, match="^sw "):
            decode_state(bad)
    with pytest.raises(CanopenInputError):
        decode_command(-1)


def test_decode_state_all_words(monkeypatch):
    import hil.canopen.cia402 as cia402

    # decode_state reads a table of every word built at import: built afresh here (what the module's
    # builder gives now, not what it gave at import) and read through decode_state
    table = cia402._decoded_words()
    assert len(table) == 0x10000 and table == cia402._DECODED
    monkeypatch.setattr(cia402, "_DECODED", table)
    unmatched = 0
    for sw in range(0x10000):
        hits = [s for s, mask, value in MASKS if sw & mask == value]
        assert len(hits) <= 1  # the patterns are disjoint
        got = decode_state(sw)
        if hits:
            assert got is hits[0] and match_state(sw) is hits[0]
        else:
            unmatched += 1
            assert got is S.NOT_READY_TO_SWITCH_ON and match_state(sw) is None
    # of the 128 values of bits 0..6, 24 are valid (4 per 0x004F mask, 2 per 0x006F mask);
    # bits 7..15 are free: 104 * 512 words match no state
    assert unmatched == 104 * 512


@given(st.sampled_from(list(State)), st.integers(0, 0xFFFF).map(lambda x: x & ~0x006F))
def test_state_word_decodes_back(state, extra):
    sw = state_word(state, extra=extra)
    assert decode_state(sw) is state
    assert sw & ~0x007F == extra & ~0x007F


def test_state_words_golden():
    r = Statusword.REMOTE
    assert [state_word(s, extra=r) for s in State] == [
        0x0200, 0x0250, 0x0231, 0x0233, 0x0237, 0x0217, 0x021F, 0x0218,
    ]
    with pytest.raises(CanopenInputError, match="state bits"):
        state_word(S.FAULT, extra=Statusword.SWITCHED_ON)


def test_master_enable_path_golden():
    drive = DriveStateMachine()
    assert drive.statusword() == 0x0200  # not ready to switch on, remote
    drive.boot_done()
    assert (drive.last_transition, drive.statusword()) == (1, 0x0250)

    cmds = path(decode_state(drive.statusword()), S.OPERATION_ENABLED)
    assert cmds == [C.SHUTDOWN, C.SWITCH_ON, C.ENABLE_OPERATION]
    cws = [controlword(c) for c in cmds]
    assert cws == [0x06, 0x07, 0x0F]
    reported = []
    for cw in cws:
        drive.on_controlword(cw)
        reported.append(drive.statusword())
    assert reported == [0x0231, 0x0233, 0x0237]

    # The master keeps sending 0x0F every SYNC: no-op, not an error.
    for _ in range(3):
        assert drive.on_controlword(0x0F) is S.OPERATION_ENABLED
    assert drive.last_transition == 4


def test_master_loop_with_next_command():
    drive = DriveStateMachine()
    drive.boot_done()
    sent = []
    for _ in range(10):
        cmd = next_command(decode_state(drive.statusword()), S.OPERATION_ENABLED)
        if cmd is None:
            break
        sent.append(controlword(cmd))
        drive.on_controlword(sent[-1])
    assert sent == [0x06, 0x07, 0x0F] and drive.state is S.OPERATION_ENABLED


def test_disable_operation_shares_the_switch_on_pattern():
    drive = machine_in(S.OPERATION_ENABLED)
    assert drive.on_controlword(0x0007) is S.SWITCHED_ON and drive.last_transition == 5
    assert drive.on_controlword(0x0007) is S.SWITCHED_ON and drive.last_transition == 5  # repeat: no-op
    drive = machine_in(S.READY_TO_SWITCH_ON)
    with pytest.raises(IllegalTransition, match=r"0x000F \(ENABLE_OPERATION\).*READY_TO_SWITCH_ON"):
        drive.on_controlword(0x000F)  # no combined 3 + 4
    assert drive.state is S.READY_TO_SWITCH_ON


def test_quick_stop_path():
    drive = machine_in(S.OPERATION_ENABLED)
    assert drive.on_controlword(0x0002) is S.QUICK_STOP_ACTIVE and drive.last_transition == 11
    assert drive.statusword() == 0x0217
    assert drive.on_controlword(0x0002) is S.QUICK_STOP_ACTIVE  # repeated while ramping
    with pytest.raises(IllegalTransition):  # transition 16 needs option code 5..8
        drive.on_controlword(0x000F)
    staying = machine_in(S.QUICK_STOP_ACTIVE)
    staying.quick_stop_stays = True  # 0x605A = 5..8: enable operation takes it back (transition 16)
    assert staying.on_controlword(0x000F) is S.OPERATION_ENABLED and staying.last_transition == 16
    assert drive.quick_stop_done() is S.SWITCH_ON_DISABLED and drive.last_transition == 12
    assert drive.statusword() == 0x0250
    assert drive.on_controlword(0x0002) is S.SWITCH_ON_DISABLED  # still quick stop: no-op
    with pytest.raises(IllegalTransition, match="quick stop done"):
        drive.quick_stop_done()
    # disable voltage during the ramp is transition 12 as well
    drive = machine_in(S.QUICK_STOP_ACTIVE)
    assert drive.on_controlword(0x0000) is S.SWITCH_ON_DISABLED and drive.last_transition == 12
    assert path(S.QUICK_STOP_ACTIVE, S.OPERATION_ENABLED) == [
        C.DISABLE_VOLTAGE, C.SHUTDOWN, C.SWITCH_ON, C.ENABLE_OPERATION]


def test_fault_and_fault_reset_path():
    drive = DriveStateMachine()
    drive.boot_done()
    for cw in (0x06, 0x07, 0x0F):
        drive.on_controlword(cw)
    assert drive.fault(0x8611) is S.FAULT_REACTION_ACTIVE and drive.last_transition == 13
    assert (drive.statusword(), drive.error_code) == (0x021F, 0x8611)
    assert drive.fault(0x2310) is S.FAULT_REACTION_ACTIVE and drive.error_code == 0x8611  # first latched
    assert next_command(S.FAULT_REACTION_ACTIVE, S.OPERATION_ENABLED) is None  # master waits
    with pytest.raises(IllegalTransition):
        drive.on_controlword(0x0F)
    assert drive.fault_reaction_done() is S.FAULT and drive.last_transition == 14
    assert drive.statusword() == 0x0218
    with pytest.raises(IllegalTransition, match=r"0x000F.*FAULT"):
        drive.on_controlword(0x0F)  # the master has not noticed yet
    assert drive.state is S.FAULT

    assert path(S.FAULT, S.SWITCH_ON_DISABLED) == [C.FAULT_RESET]
    cws = [controlword(c) for c in path(S.FAULT, S.OPERATION_ENABLED)]
    assert cws == [0x80, 0x06, 0x07, 0x0F]
    assert drive.on_controlword(0x80) is S.SWITCH_ON_DISABLED and drive.last_transition == 15
    assert drive.error_code == 0 and drive.statusword() == 0x0250
    assert drive.on_controlword(0x80) is S.SWITCH_ON_DISABLED  # bit 7 held: no new command
    for cw in cws[1:]:
        drive.on_controlword(cw)
    assert drive.statusword() == 0x0237


def test_fault_reset_needs_edge_on_the_drive():
    drive = machine_in(S.SWITCH_ON_DISABLED)
    drive.on_controlword(0x80)  # bit 7 already high when the fault comes
    drive.fault(0x5530)
    drive.fault_reaction_done()
    assert drive.on_controlword(0x80) is S.FAULT  # held high: no edge
    with pytest.raises(IllegalTransition):
        drive.on_controlword(0x00)  # not allowed in FAULT, but bit 7 drops
    assert drive.on_controlword(0x80) is S.SWITCH_ON_DISABLED and drive.last_transition == 15


def test_internal_events_only_from_their_state():
    drive = DriveStateMachine()
    with pytest.raises(IllegalTransition, match="fault reaction done"):
        drive.fault_reaction_done()
    # not ready to switch on processes no command: ignored (the master's disable voltage there), not refused
    assert drive.on_controlword(0x06) is S.NOT_READY_TO_SWITCH_ON and drive.last_transition is None
    assert drive.on_controlword(0x00) is S.NOT_READY_TO_SWITCH_ON and drive.previous_controlword == 0x00
    drive.boot_done()
    with pytest.raises(IllegalTransition, match="boot done"):
        drive.boot_done()
    assert drive.fault(0x1000) is S.FAULT_REACTION_ACTIVE  # 13 from any state


@pytest.mark.parametrize("src,dst,expected", [
    (S.SWITCH_ON_DISABLED, S.OPERATION_ENABLED, [C.SHUTDOWN, C.SWITCH_ON, C.ENABLE_OPERATION]),
    (S.OPERATION_ENABLED, S.SWITCH_ON_DISABLED, [C.DISABLE_VOLTAGE]),
    (S.OPERATION_ENABLED, S.READY_TO_SWITCH_ON, [C.SHUTDOWN]),
    (S.OPERATION_ENABLED, S.SWITCHED_ON, [C.DISABLE_OPERATION]),
    (S.READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED, [C.DISABLE_VOLTAGE]),
    (S.SWITCHED_ON, S.QUICK_STOP_ACTIVE, [C.ENABLE_OPERATION, C.QUICK_STOP]),
    (S.FAULT, S.READY_TO_SWITCH_ON, [C.FAULT_RESET, C.SHUTDOWN]),
    (S.SWITCHED_ON, S.SWITCHED_ON, []),
])
def test_path_examples(src, dst, expected):
    assert path(src, dst) == expected


@pytest.mark.parametrize("src,dst", [
    (S.OPERATION_ENABLED, S.FAULT), (S.SWITCH_ON_DISABLED, S.NOT_READY_TO_SWITCH_ON),
    (S.FAULT_REACTION_ACTIVE, S.OPERATION_ENABLED), (S.NOT_READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED),
])
def test_unreachable_targets(src, dst):
    with pytest.raises(IllegalTransition, match=f"from {src.name} to {dst.name}"):
        path(src, dst)


def test_next_command():
    assert next_command(S.SWITCHED_ON, S.SWITCH_ON_DISABLED) is C.DISABLE_VOLTAGE
    assert next_command(S.OPERATION_ENABLED, S.OPERATION_ENABLED) is None
    assert next_command(S.NOT_READY_TO_SWITCH_ON, S.OPERATION_ENABLED) is None
    with pytest.raises(IllegalTransition):
        next_command(S.SWITCH_ON_DISABLED, S.FAULT)


@pytest.mark.parametrize("src,dst", list(itertools.product(State, State)), ids=lambda v: v.name)
def test_path_drives_the_device_there(src, dst):
    try:
        cmds = path(src, dst)
    except IllegalTransition:
        return
    drive = machine_in(src)
    for c in cmds:
        drive.on_controlword(controlword(c))
    assert drive.state is dst


def test_operation_modes():
    assert [int(m) for m in OperationMode] == [1, 3, 6, 7, 8, 9, 10]
    assert OperationMode.CSP == DriveMode.POSITION and OperationMode.CST == DriveMode.FORCE


# --------------------------------------------------------------------------- pinned by mutation (issue 26)
# Each error names its argument exactly (the word validators quote the name they are given), the
# drive's initial values and the master's table are stated, not assumed.

WORD_RANGE = r" = 0x10000 is outside 0x0\.\.0xFFFF \(16-bit word\)$"


@pytest.mark.parametrize("call,name", [
    (lambda: decode_command(0x10000), "cw"),
    (lambda: decode_command(0x0080, previous_cw=0x10000), "previous_cw"),
    (lambda: match_state(0x10000), "sw"),
    (lambda: decode_state(0x10000), "sw"),
    (lambda: state_word(S.FAULT, extra=0x10000), "extra"),
    (lambda: DriveStateMachine().on_controlword(0x10000), "cw"),
    (lambda: machine_in(S.OPERATION_ENABLED).fault(0x10000), "code"),
], ids=["cw", "previous_cw", "match_state", "decode_state", "extra", "on_controlword", "fault_code"])
def test_word_errors_name_the_argument(call, name):
    with pytest.raises(CanopenInputError, match="^" + name + WORD_RANGE):
        call()


def test_a_refused_word_leaves_the_drive_unchanged():
    drive = machine_in(S.OPERATION_ENABLED)
    drive.on_controlword(0x000F)
    with pytest.raises(CanopenInputError):
        drive.on_controlword(0x10000)
    with pytest.raises(CanopenInputError):
        drive.fault(-1)
    assert (drive.state, drive.error_code, drive.previous_controlword) == (S.OPERATION_ENABLED, 0, 0x000F)


@pytest.mark.parametrize("event,state,message", [
    ("boot_done", S.SWITCH_ON_DISABLED, "boot done (transition 1) not allowed in state SWITCH_ON_DISABLED"),
    ("fault_reaction_done", S.FAULT, "fault reaction done (transition 14) not allowed in state FAULT"),
    ("quick_stop_done", S.OPERATION_ENABLED,
     "quick stop done (transition 12) not allowed in state OPERATION_ENABLED"),
])
def test_internal_event_refusals_word_for_word(event, state, message):
    drive = machine_in(state)
    with pytest.raises(IllegalTransition) as exc:
        getattr(drive, event)()
    assert str(exc.value) == message
    assert drive.state is state and drive.last_transition is None


def test_a_new_drive_has_no_error_and_saw_controlword_0():
    drive = DriveStateMachine()
    assert (drive.state, drive.last_transition, drive.error_code, drive.previous_controlword) == (
        S.NOT_READY_TO_SWITCH_ON, None, 0, 0)
    assert type(drive.error_code) is int and type(drive.previous_controlword) is int


def test_fault_reset_in_the_first_controlword_is_a_rising_edge():
    """The word before the first is 0: a drive that boots into FAULT is reset by a first 0x0080."""
    drive = DriveStateMachine()
    drive.fault(0x5530)
    drive.fault_reaction_done()
    assert drive.error_code == 0x5530
    assert drive.on_controlword(0x0080) is S.SWITCH_ON_DISABLED and drive.last_transition == 15
    assert (drive.error_code, drive.previous_controlword) == (0, 0x0080)


@pytest.mark.parametrize("remote,words", [
    (True, [0x0200, 0x0250, 0x0231, 0x0233, 0x0237]),
    (False, [0x0000, 0x0050, 0x0031, 0x0033, 0x0037]),
])
def test_statusword_remote_bit_only_when_remote(remote, words):
    drive = DriveStateMachine(remote=remote)
    got = [drive.statusword()]
    drive.boot_done()
    got.append(drive.statusword())
    for cw in (0x06, 0x07, 0x0F):
        drive.on_controlword(cw)
        got.append(drive.statusword())
    assert got == words
    assert drive.statusword(Statusword.TARGET_REACHED) == words[-1] | 0x0400


def test_master_table_commands_are_transitions_or_hold_the_state():
    for (goal, state), cmd in MASTER_COMMANDS.items():
        assert master_command(goal, state) is cmd, (goal, state)
        if cmd is not None:
            assert (state, cmd) in EXPECTED or (state, cmd) in NO_OP or (state, cmd) in IGNORED, (goal, state, cmd)
            assert (state, cmd) not in CONDITIONAL  # never transition 16
    assert {(g, s) for g in Goal for s in State if s is not S.QUICK_STOP_ACTIVE} == set(MASTER_COMMANDS)


def test_controlword_and_master_command_take_a_member_or_its_value():
    """The hot path takes the members as they are and anything else through its Enum (b09b4a3): a value
    gives its member's answer, a value of no member is refused."""
    for c in Command:
        assert controlword(c.value) == controlword(c), c
    for (goal, state), cmd in MASTER_COMMANDS.items():
        assert master_command(goal.value, state) is cmd, (goal, state)
        assert master_command(goal, state.value) is cmd, (goal, state)
        assert master_command(goal.value, state.value) is cmd, (goal, state)
    with pytest.raises(ValueError, match="'halt' is not a valid Command"):
        controlword("halt")
    with pytest.raises(ValueError, match="'up' is not a valid Goal"):
        master_command("up", S.FAULT)


@pytest.mark.parametrize("goal", [g for g in Goal if g is not Goal.DISABLED], ids=lambda g: g.name)
def test_master_in_quick_stop_active_waits_for_standstill(goal):
    """Quick stop while the drive may still move (the default: not known to stand still), disable
    voltage (transition 12) once it stands still, whatever the goal but DISABLED."""
    assert master_command(goal, S.QUICK_STOP_ACTIVE) is C.QUICK_STOP
    assert master_command(goal, S.QUICK_STOP_ACTIVE, stopped=False) is C.QUICK_STOP
    assert master_command(goal, S.QUICK_STOP_ACTIVE, stopped=True) is C.DISABLE_VOLTAGE


def test_goal_disabled_is_disable_voltage_at_once_even_in_quick_stop_active():
    """The drill's drive at standstill (powered up by SDO): disable voltage from every state a command
    leaves, fault reset in FAULT, nothing in fault reaction active."""
    for state in S:
        want = {S.FAULT: C.FAULT_RESET, S.FAULT_REACTION_ACTIVE: None}.get(state, C.DISABLE_VOLTAGE)
        assert master_command(Goal.DISABLED, state) is want, state


@pytest.mark.parametrize("cw,expected", [
    (0x000F, True), (0x001F, True), (0x010F, True),  # bits 4..6 and halt do not matter
    (0x0007, False), (0x000E, False), (0x000B, False), (0x0006, False), (0x0000, False),
    (0x008F, False),  # bit 7 set: fault reset, not enable operation
])
def test_enables_operation(cw, expected):
    assert enables_operation(cw) is expected


def test_enables_operation_names_a_bad_word():
    with pytest.raises(CanopenInputError, match="^cw" + WORD_RANGE):
        enables_operation(0x10000)
