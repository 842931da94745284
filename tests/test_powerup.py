"""One drive's CiA 402 power-up and power-down by its statusword (hil/master/powerup.py, issue 36).

The sans-IO walk is fed statuswords with the time each was received and answers with the controlwords
to write: golden sequences for a drive that stays in Not ready to switch on until a controlword, a
statusword that goes stale, a drive in FAULT; then the preflight's drill over the simulated drives with
such a drive (the SDO controlwords on the bus, in order).
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.canopen.cia402 import Goal, State
from hil.master.powerup import PowerWalk, WalkStep
from sim.faults import Fault, FaultInjector
from sim.plant import RigPlant
from support.canopen_rig import make_pair

LABEL = "node 1 (EMA 1)"
T = 0.002


def _walk(goal=Goal.ENABLED, timeout_s=2.0, attempts=3) -> PowerWalk:
    return PowerWalk(LABEL, goal, 0.0, timeout_s, attempts)


def _drive(walk: PowerWalk, answers: list[tuple[int, float]]) -> list[WalkStep]:
    """Feed (statusword, time) in order; each step's words are 'written' one SYNC period after the reading."""
    steps = []
    for sw, t in answers:
        step = walk.on_statusword(sw, t)
        steps.append(step)
        if step.controlwords:
            walk.sent(t + T / 2)
    return steps


def test_a_drive_in_not_ready_to_switch_on_gets_disable_voltage_once_then_the_walk_up():
    walk = _walk()
    steps = _drive(walk, [(0x0200, 0.000), (0x0200, 0.002), (0x0200, 0.004), (0x0250, 0.006),
                          (0x0231, 0.008), (0x0233, 0.010), (0x0237, 0.012)])
    assert [s.controlwords for s in steps] == [(0x0000,), (), (), (0x0006,), (0x0007,), (0x000F,), ()]
    assert [s.what for s in steps[:1] + steps[3:6]] == ["disable voltage", "shutdown", "switch on",
                                                         "enable operation"]
    assert [s.done for s in steps] == [False] * 6 + [True]
    assert walk.t_nrtso_cw_s == 0.0


def test_a_drive_that_stays_in_not_ready_to_switch_on_is_given_up_at_the_timeout_naming_what_was_seen():
    walk = _walk(timeout_s=0.1)
    steps = _drive(walk, [(0x0200, 0.0), (0x0200, 0.05), (0x0200, 0.1)])
    assert [s.controlwords for s in steps] == [(0x0000,), (), ()] and not any(s.failed for s in steps)
    late = walk.on_statusword(0x0200, 0.1 + 1e-6)  # just past the bound
    assert late.failed == ("node 1 (EMA 1): not in OPERATION_ENABLED within canopen.enable_timeout_s = 0.1 s "
                           "(statusword 0x0200 (NOT_READY_TO_SWITCH_ON) read at t = 0.100 s; disable voltage "
                           "(0x0000) sent there at t = 0.000 s)")
    assert not late.in_fault


def test_a_statusword_read_before_the_last_command_is_not_used():
    walk = _walk(timeout_s=0.1)
    assert walk.on_statusword(0x0250, 0.0).controlwords == (0x0006,)
    walk.sent(0.010)
    # an answer that was on its way before the shutdown went out: READY_TO_SWITCH_ON is not confirmed by it
    stale = walk.on_statusword(0x0231, 0.010)
    assert stale == WalkStep(stale=True)
    # fresh: still switch on disabled (the drive had not taken it yet): shutdown again, as the table says
    assert walk.on_statusword(0x0250, 0.012).controlwords == (0x0006,)
    walk.sent(0.013)
    assert walk.on_statusword(0x0231, 0.014).controlwords == (0x0007,)  # fresh: ready to switch on


def test_a_stale_statusword_is_named_stale_since_the_command_when_the_walk_gives_up():
    walk = _walk(timeout_s=0.1)
    walk.on_statusword(0x0250, 0.0)
    walk.sent(0.2)  # the command went out; nothing read after it
    late = walk.on_statusword(0x0250, 0.15)
    assert late.failed == ("node 1 (EMA 1): not in OPERATION_ENABLED within canopen.enable_timeout_s = 0.1 s "
                           "(statusword 0x0250 (SWITCH_ON_DISABLED) read at t = 0.000 s, stale since t = 0.200 s "
                           "(the last command; none read after it))")


def test_no_statusword_after_the_command_is_never_read():
    walk = _walk(timeout_s=0.1)
    walk.sent(0.3)
    late = walk.on_statusword(0x0237, 0.2)
    assert late.failed.endswith("(no statusword read after the command at t = 0.300 s)")
    fresh = _walk(timeout_s=0.1)
    assert fresh.on_statusword(0x0250, 0.2).failed.endswith(
        "(statusword 0x0250 (SWITCH_ON_DISABLED) read at t = 0.200 s)")


def test_fault_resets_on_the_rising_edge_and_bounded():
    walk = _walk(attempts=2)
    steps = _drive(walk, [(0x0218, 0.0), (0x0218, 0.01), (0x0218, 0.02)])
    assert [s.controlwords for s in steps[:2]] == [(0x0080,), (0x0000, 0x0080)]
    assert steps[2].failed == "node 1 (EMA 1): still in FAULT after 2 fault resets (canopen.fault_reset_attempts)"
    assert steps[2].in_fault


def test_power_down_is_disable_voltage_at_once_from_every_state_a_command_leaves():
    for sw, state in ((0x0237, State.OPERATION_ENABLED), (0x0217, State.QUICK_STOP_ACTIVE),
                      (0x0233, State.SWITCHED_ON), (0x0231, State.READY_TO_SWITCH_ON),
                      (0x0200, State.NOT_READY_TO_SWITCH_ON)):
        assert _walk(Goal.DISABLED).on_statusword(sw, 0.0).controlwords == (0x0000,), state
    assert _walk(Goal.DISABLED).on_statusword(0x0250, 0.0).done
    assert _walk(Goal.DISABLED).on_statusword(0x021F, 0.0) == WalkStep()  # fault reaction active: wait
    with pytest.raises(ValueError, match="ENABLED or DISABLED"):
        PowerWalk(LABEL, Goal.QUICK_STOP, 0.0, 1.0, 3)


def _controlwords_by_sdo(traffic, node: int) -> list[int]:
    """The values of every SDO download to 0x6040:00 of ``node`` the master sent, in order."""
    return [int.from_bytes(f.data[4:6], "little") for who, f in traffic
            if who == "M" and f.arbitration_id == 0x600 + node and f.data[0] & 0xE0 == 0x20
            and f.data[1:4] == b"\x40\x60\x00"]


@pytest.mark.parametrize("waits", [False, True], ids=["ready", "not-ready-until-controlword"])
def test_the_drills_power_up_by_sdo_golden_controlwords(actuation, simrig, waits):
    from test_master import Pump, _master

    inj = FaultInjector(make_pair(RigPlant(simrig.params, np.random.default_rng(3))),
                        [Fault("not_ready_until_controlword", 1), Fault("not_ready_until_controlword", 2)]
                        if waits else [], record_truth=False)
    m = _master(actuation)
    p = Pump(m, inj)
    p.preflight()
    up = [0x0000] if waits else []  # disable voltage in Not ready to switch on, then the walk up and down
    for node in (1, 2):
        assert _controlwords_by_sdo(p.traffic, node) == up + [0x0006, 0x0007, 0x000F, 0x0000]
        assert m.drives[node].master_loss.drill.outcome.value == "reacted"
    assert {n.state_machine.state for n in inj.pair.nodes} == {State.SWITCH_ON_DISABLED}


# --------------------------------------------------------------------------- the end of a safe stop


def _check_and_stop(pair, cycles: int = 30, deaf_after_enable: int | None = None):
    """Preflight, enable, hold ``cycles`` SYNC cycles, close (the safe stop and its confirming reads)."""
    from hil.canopen.process import DriveMode, Setpoint
    from hil.master.link import CanopenLink
    from hil.transport import InProcessTransport
    from support.canopen_rig import make_master

    tr = InProcessTransport(pair, T)
    link = CanopenLink(make_master(), tr)
    try:
        smp = link.first_sample()
        if deaf_after_enable is not None:  # that drive's SDO server stops answering (its PDOs go on)
            pair.nodes[deaf_after_enable - 1].on_sdo = lambda frame, t: None
        for _ in range(cycles):
            smp = link.exchange(Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        t_stop = tr.now()
        link.close()
    finally:
        tr.close()
    return link, t_stop


def test_a_safe_stop_is_confirmed_by_reading_each_statusword_after_the_last_command(simrig):
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(11)))
    link, t_stop = _check_and_stop(pair)
    for k in (1, 2):
        fin = link.final_states[f"ema{k}"]
        assert (fin["state"], fin["confirmed"], fin["safe"]) == ("SWITCH_ON_DISABLED", True, True)
        assert fin["seen_t_s"] > t_stop  # the read came after the stop's last command
        assert fin["seen"] == f"read after the stop at t = {fin['seen_t_s']:.3f} s"
    assert {n.state_machine.state for n in pair.nodes} == {State.SWITCH_ON_DISABLED}


def test_a_confirming_read_that_times_out_leaves_the_drive_not_confirmed(simrig, actuation):
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(12)))
    link, t_stop = _check_and_stop(pair, deaf_after_enable=2)
    assert link.final_states["ema1"]["safe"] is True
    fin = link.final_states["ema2"]
    # the drive went down (its TPDO said so) but no read after the last command answered: not confirmed
    assert pair.nodes[1].state_machine.state is State.SWITCH_ON_DISABLED
    assert (fin["state"], fin["confirmed"], fin["safe"]) == ("SWITCH_ON_DISABLED", False, False)
    assert fin["seen"] == (f"statusword stale since t = {fin['seen_t_s']:.3f} s (0x6041 not answered by SDO: 3 "
                           f"reads of canopen.sdo_timeout_s = {actuation.canopen.sdo_timeout_s} s each)")
    from hil.record.runrecord import RunRecord

    rec = RunRecord().with_final_states(link.final_states, None)
    assert rec.drives_final["ema2"].unsafe_note("ema2") == (
        f"EMA 2 (node 2) {fin['seen']}, last seen SWITCH_ON_DISABLED")


def test_final_state_words_for_a_statusword_never_read():
    from hil.master.powerup import Confirmed, final_state

    never = final_state(None, None, Confirmed(problem="SDO abort 0x05040000 (SDO protocol timed out)"), False)
    assert never == {"state": None, "seen_t_s": None, "confirmed": False, "safe": False,
                     "seen": "statusword never read (SDO abort 0x05040000 (SDO protocol timed out))"}
    assert final_state(None, None, None, False)["seen"] == "statusword never read"
    assert final_state(0x0250, 1.5, None, False)["seen"] == "statusword stale since t = 1.500 s"
    ok = final_state(0x0250, 1.5, None, True)
    assert (ok["confirmed"], ok["safe"], ok["seen"]) == (True, True, "statusword fresh at t = 1.500 s")


def test_stop_confirmation_answers_stray_frames_aborts_and_its_timeout_on_the_boundary():
    from hil.canopen.frame import Frame
    from hil.master.powerup import CONFIRM_READS, Confirmed, StopConfirmation

    c = StopConfirmation({1: (0x6041, 0), 2: (0x6041, 0)}, timeout_s=0.5)
    assert c.start(1.0) == [Frame(0x601, bytes.fromhex("4041600000000000")),
                            Frame(0x602, bytes.fromhex("4041600000000000"))]
    # the answer to a controlword written by SDO before (fire and forget) is passed over, not an error
    assert c.on_frame(1, Frame(0x581, bytes.fromhex("6040600000000000")), 1.001) is None
    got = c.on_frame(1, Frame(0x581, bytes.fromhex("4B41600050020000")), 1.002)
    assert got == Confirmed(0x0250, 1.002) and not c.done
    abort = Frame(0x602, bytes.fromhex("8041600000000405"))  # 0x05040000, SDO protocol timed out
    ask = Frame(0x602, bytes.fromhex("4041600000000000"))
    t = 1.0
    for k in range(1, CONFIRM_READS):  # each read bounded by the SDO timeout, then asked again
        assert c.poll(t + 0.5 - 1e-9) == [] and 2 not in c.results  # just inside the SDO timeout
        t += 0.5
        assert c.poll(t) == [abort, ask] and 2 not in c.results, k
    assert c.poll(t + 0.5 - 1e-9) == [] and not c.done
    assert c.poll(t + 0.5) == [abort]  # the last read: given up after CONFIRM_READS * 0.5 s
    assert c.results[2] == Confirmed(problem="0x6041 not answered by SDO: 3 reads of canopen.sdo_timeout_s = 0.5 s "
                                             "each")
    assert c.done and c.poll(9.0) == [] and CONFIRM_READS == 3
    aborted = StopConfirmation({1: (0x6041, 0)}, timeout_s=0.5)
    aborted.start(0.0)
    res = aborted.on_frame(1, Frame(0x581, bytes.fromhex("8041600000000206")), 0.01)  # 0x06020000
    assert res.statusword is None and res.problem.startswith("SDO abort 0x06020000 (")
