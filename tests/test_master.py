"""Protocol tests of the sans-IO CANopen master core: golden frames, preflight, the drill, CiA 402 rules, errors.

A tiny synchronous pump in the test connects MasterCore and the simulated drive pair frame by frame
(no bus, no threads, no sleeps); time passes only when the pump says so.
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from hil.canopen.cia402 import State
from hil.canopen.frame import Frame, sync_frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.plan import PlanError
from hil.canopen.process import DriveMode, Setpoint
from hil.canopen.sdo import SdoAbortError
from hil.canopen.signalmap import ForceControl
from hil.master import events as event
from hil.master.core import DriveFault, HeartbeatLost, MasterCore, MasterLossReactionError, PreflightError
from hil.master.drill import DrillOutcome
from hil.profile.load import load_actuation
from hil.profile.rig import plan_for
from sim.faults import Fault, FaultInjector
from sim.plant import RigPlant
from support.canopen_rig import make_pair, shipped_rig
from support.eds import write_eds_variant
from support.profiles import write_profile_variant

T = 0.002  # the shipped SYNC period [s]
HB = Frame(0x77F, b"\x05")  # the master's heartbeat: node 127, operational
OFF = Setpoint(DriveMode.DISABLED, 0.0)


class Pump:
    """Master <-> simulated pair, delivering frames in order; records all traffic."""

    def __init__(self, master: MasterCore, pair) -> None:
        self.m, self.pair = master, pair
        self.t = 0.0
        self.traffic: list[tuple[str, Frame]] = []
        self.to_slaves: list[Frame] = []
        self.to_master: list[Frame] = []
        if pair is not None:
            self.to_master += pair.power_on(0.0)

    def send(self, frames):
        for f in frames:
            self.traffic.append(("M", f))
            self.to_slaves.append(f)

    def run(self):
        while self.to_slaves or self.to_master:
            while self.to_slaves:
                f = self.to_slaves.pop(0)
                if self.pair is not None:
                    for g in self.pair.on_frame(f, self.t):
                        self.traffic.append(("S", g))
                        self.to_master.append(g)
            while self.to_master:
                f = self.to_master.pop(0)
                self.send(self.m.on_frame(f, self.t))

    def tick(self):
        """Let one SYNC period pass without SYNC: the drives' timers, the master's poll."""
        self.t += T
        self.to_master += self.pair.tick(self.t)
        self.run()
        self.send(self.m.poll(self.t))
        self.run()

    def preflight(self, limit_s: float = 5.0):
        self.send(self.m.start(self.t))
        self.send(self.m.poll(self.t))
        self.run()
        while not self.m.preflight_done:
            assert self.t < limit_s, "preflight did not finish"
            self.tick()

    def sync(self):
        self.t += T
        if self.pair is not None:
            self.to_master += self.pair.tick(self.t)
        self.send(self.m.poll(self.t))
        self.m.on_frame(sync_frame(), self.t)
        self.traffic.append(("M", sync_frame()))
        self.to_slaves.append(sync_frame())
        self.run()
        return self.m.take_sample()

    def enable(self, smp, cycles: int = 12):
        for _ in range(cycles):
            hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
            self.send(self.m.setpoint_frames(*hold, smp))
            smp = self.sync()
        return smp

    def sdo_writes(self, node: int) -> list[tuple[int, int]]:
        """(index, sub) of every SDO download the master started to ``node``, in order."""
        return [(f.data[2] << 8 | f.data[1], f.data[3]) for who, f in self.traffic
                if who == "M" and f.arbitration_id == 0x600 + node and f.data[0] & 0xE0 == 0x20]

    def sdo_reads(self, node: int) -> list[tuple[int, int]]:
        return [(f.data[2] << 8 | f.data[1], f.data[3]) for who, f in self.traffic
                if who == "M" and f.arbitration_id == 0x600 + node and f.data[0] == 0x40]


def _plant(simrig, seed=1):
    return RigPlant(simrig.params, np.random.default_rng(seed))


@pytest.fixture()
def pair(simrig):
    return make_pair(_plant(simrig))


def _master(act=None, rig=None) -> MasterCore:
    return MasterCore(act or load_actuation(), (rig or shipped_rig()).plan)


def _preflight(act, pair, rig=None):
    m = _master(act, rig)
    p = Pump(m, pair)
    p.preflight()
    return m, p


def _variant(tmp_path, *, eds_defaults=None, eds_remove=(), canopen=None, signals=None):
    """A rig whose drives' EDS and actuation profile differ from the shipped ones as given."""
    eds = write_eds_variant(tmp_path / "drive.eds", defaults=eds_defaults, remove=eds_remove)
    over = {"canopen": {"eds": str(eds), **(canopen or {})}}
    if signals:
        over["signals"] = signals
    prof = write_profile_variant("actuation.toml", tmp_path / "actuation.toml", over)
    act = load_actuation(prof)
    return act, plan_for(act, prof)


# ------------------------------------------------------------------ boot and preflight


def test_start_sends_nmt_reset_node_to_all():
    m = _master()
    assert m.start(0.0) == [Frame(0x000, bytes([0x81, 0x00]))]


def test_first_sdo_after_every_boot_up_is_identity_upload():
    m = _master()
    m.start(0.0)
    assert m.on_frame(Frame(0x701, b"\x00"), 0.01) == []  # still waiting for node 2
    out = m.on_frame(Frame(0x702, b"\x00"), 0.02)
    # SDO initiate upload of 0x1018:01 to node 1
    assert out == [Frame(0x601, bytes([0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0]))]


def test_preflight_against_simulated_drives_golden_sequence(actuation, pair):
    m, p = _preflight(actuation, pair)
    assert m.preflight_done
    writes = p.sdo_writes(1)
    # node 1, in order: its heartbeat, the PDO mapping procedure of CiA 301 (4 PDOs: 29 writes), then
    # the limits it keeps itself (a master without a safety profile: the actuation's stroke only), each
    # written and read back, the drive's interpolation period, quick stop option, cycle period, and its own
    # reaction to the master's death (consumer heartbeat on the master, abort connection option)
    assert writes[:4] == [(0x1017, 0), (0x1400, 1), (0x1600, 0), (0x1600, 1)]
    assert writes[1:30][-1] == (0x1801, 1)  # TPDO2 enabled: the last of the 29 mapping writes
    assert writes[30:38] == [(0x607D, 1), (0x607D, 2), (0x60C2, 1), (0x60C2, 2), (0x605A, 0), (0x1006, 0),
                             (0x1016, 1), (0x6007, 0)]
    # then the drill: hold the position, CSP, shutdown / switch on / enable operation by SDO, then
    # disable voltage out of the drive's reaction
    assert writes[38:] == [(0x607A, 0), (0x6060, 0), (0x6040, 0), (0x6040, 0), (0x6040, 0), (0x6040, 0)]
    reads = p.sdo_reads(1)
    assert reads[:7] == [(0x1018, 1), (0x1018, 2), (0x1018, 3), (0x1018, 4), (0x1000, 0), (0x6502, 0), (0x2102, 0)]
    assert p.traffic[-1] == ("M", Frame(0x000, bytes([0x01, 0x00])))  # NMT start all
    # the drives now carry the configuration
    n1 = pair.nodes[0]
    assert n1.read(0x1017) == 100
    assert n1.read(0x607D, 2) == round(20.0 * actuation.mechanics.i_total_rad_per_mm * 4096 / (2 * np.pi))
    assert m.drives[1].identity == {"vendor_id": 0xE3A, "product_code": 0x402, "revision": 0x10000, "serial": 0}
    assert pair.stats.syncs == 0  # nothing moved: the drill runs before SYNC


def test_identity_mismatch_is_refused_naming_the_field(actuation, pair):
    pair.nodes[0].own_data[(0x1018, 2)] = struct.pack("<I", 0x999)  # another drive answers at node 1
    with pytest.raises(PreflightError, match=r"node 1 \(EMA 1\): identity 0x1018 vendor 0x00000E3A product "
                                             r"0x00000999 does not match the profile "
                                             r".*canopen.product_code 0x00000402"):
        _preflight(actuation, pair)


def test_gear_ratio_mismatch_is_refused(actuation, pair):
    act = dataclasses.replace(actuation, mechanics=dataclasses.replace(actuation.mechanics, i_total_rad_per_mm=6.0))
    with pytest.raises(PreflightError, match=r"gear ratio 0x2102:00 = 5.026548 rad/mm, profile "
                                             r"mechanics.i_total_rad_per_mm = 6.000000"):
        _preflight(act, pair)


def test_sdo_abort_reported_with_code_and_meaning():
    m = _master()
    m.start(0.0)
    m.on_frame(Frame(0x701, b"\x00"), 0.0)
    m.on_frame(Frame(0x702, b"\x00"), 0.0)
    abort = Frame(0x581, bytes([0x80, 0x18, 0x10, 0x01]) + struct.pack("<I", 0x06020000))
    with pytest.raises(SdoAbortError, match=r"node 1: SDO abort 0x06020000 \(object does not exist"):
        m.on_frame(abort, 0.01)


def test_boot_timeout_at_the_limit_and_just_past_it():
    m = _master()
    m.start(0.0)
    m.on_frame(Frame(0x702, b"\x00"), 0.1)
    m.poll(2.0)  # the boot timeout, 2.0 s: not past it
    with pytest.raises(PreflightError, match=r"node 1 \(EMA 1\): no boot-up within canopen.boot_timeout_s = 2.0 s"):
        m.poll(2.0 + 1e-9)


# ------------------------------------------------------------------ power-up and shutdown


def test_enable_path_golden_controlwords(actuation, pair):
    m, p = _preflight(actuation, pair)
    smp = p.sync()
    assert smp is not None and smp.t_s == pytest.approx(0.002)
    seen = []
    for _ in range(12):
        hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        frames = m.setpoint_frames(*hold, smp)
        seen += [(f.arbitration_id, f.data) for f in frames]
        p.send(frames)
        smp = p.sync()
        if m.all_in(State.OPERATION_ENABLED):
            break
    assert m.all_in(State.OPERATION_ENABLED)
    cw1 = [d[0] | d[1] << 8 for cid, d in seen if cid == 0x201]
    # one CiA 402 transition per exchange: shutdown, switch on, enable operation (then held)
    dedup = [c for k, c in enumerate(cw1) if k == 0 or c != cw1[k - 1]]
    assert dedup == [0x0006, 0x0007, 0x000F]
    # the mode is set once by RPDO2 (event-driven), CSP = 8, before the first RPDO1
    assert seen[0] == (0x301, bytes([8]))
    assert [cid for cid, _ in seen].count(0x301) == 1
    assert pair.stats.rpdos_late == 0


def test_orderly_shutdown_and_quick_stop(actuation, pair, simrig):
    m, p = _preflight(actuation, pair)
    smp = p.enable(p.sync())
    assert m.all_in(State.OPERATION_ENABLED)
    cws = []
    for _ in range(12):
        frames = m.setpoint_frames(OFF, OFF, smp)
        cws += [f.data[0] for f in frames if f.arbitration_id == 0x201]
        p.send(frames)
        smp = p.sync()
    assert m.all_in(State.SWITCH_ON_DISABLED) and m.in_safe_state(p.t)
    dedup = [c for k, c in enumerate(cws) if k == 0 or c != cws[k - 1]]
    assert dedup == [0x07, 0x06, 0x00]  # disable operation, shutdown, disable voltage
    # quick stop on abort: the drive's own quick stop (0x605A = 2) ends in switch on disabled
    m2, p2 = _preflight(actuation, make_pair(_plant(simrig, 2)))
    smp = p2.enable(p2.sync())
    m2.quick_stop = True
    p2.send(m2.setpoint_frames(OFF, OFF, smp))
    p2.sync()
    smp = p2.sync()
    assert m2.state_of(1) is State.QUICK_STOP_ACTIVE
    for _ in range(40):
        p2.send(m2.setpoint_frames(OFF, OFF, smp))
        smp = p2.sync()
    assert m2.all_in(State.SWITCH_ON_DISABLED) and m2.in_safe_state(p2.t)


def test_a_drive_that_stays_in_quick_stop_active_is_disabled_once_it_stands_still(actuation, simrig):
    """0x605A 5..8, or a drive that ignores 0x605A: the master commands disable voltage itself."""
    pair = make_pair(_plant(simrig, 2))
    m, p = _preflight(actuation, pair)
    smp = p.enable(p.sync())
    sm = pair.nodes[0].state_machine
    sm.quick_stop_done = lambda: sm.state  # EMA 1 never leaves QUICK STOP ACTIVE by itself
    m.quick_stop = True
    cws = []
    for _ in range(40):
        frames = m.setpoint_frames(OFF, OFF, smp)
        cws += [f.data[0] for f in frames if f.arbitration_id == 0x201]
        p.send(frames)
        smp = p.sync()
    assert m.all_in(State.SWITCH_ON_DISABLED) and m.in_safe_state(p.t)
    dedup = [c for k, c in enumerate(cws) if k == 0 or c != cws[k - 1]]
    assert dedup == [0x02, 0x00]  # quick stop, held while the drive still moves; then disable voltage
    # disable voltage only once the angle stood still for 10 cycles (the drive holds it: at once)
    first_off = cws.index(0x00)
    assert 10 <= first_off <= 13


def test_a_drive_found_in_fault_at_power_up_gets_a_fault_reset(actuation, simrig):
    pair = make_pair(_plant(simrig, 3))
    m, p = _preflight(actuation, pair)
    sm = pair.nodes[1].state_machine
    sm.fault(0x5000)
    sm.fault_reaction_done()
    smp = p.sync()
    cws = []
    for _ in range(30):
        hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        frames = m.setpoint_frames(*hold, smp)
        cws += [f.data[0] for f in frames if f.arbitration_id == 0x202]
        p.send(frames)
        smp = p.sync()
    assert m.all_in(State.OPERATION_ENABLED)
    assert cws[0] == 0x80  # the fault reset (rising edge of bit 7), then the power-up
    dedup = [c for k, c in enumerate(cws) if k == 0 or c != cws[k - 1]]
    assert dedup == [0x80, 0x06, 0x07, 0x0F]


@pytest.mark.parametrize("attempts", [1, 3])
def test_fault_resets_are_bounded(actuation, simrig, attempts):
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen,
                                                                      fault_reset_attempts=attempts))
    pair = make_pair(_plant(simrig, 3))
    m, p = _preflight(act, pair)
    sm = pair.nodes[1].state_machine
    sm.fault(0x5000)
    sm.fault_reaction_done()
    sm.on_controlword = lambda cw: sm.state  # EMA 2 stays in FAULT whatever it is told
    smp = p.sync()
    cws = []
    with pytest.raises(DriveFault, match=rf"node 2 \(EMA 2\): still in FAULT after {attempts} fault resets "
                                         r"\(canopen.fault_reset_attempts\)"):
        for _ in range(200):
            hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
            frames = m.setpoint_frames(*hold, smp)
            cws += [f.data[0] for f in frames if f.arbitration_id == 0x202]
            p.send(frames)
            smp = p.sync()
    rising = sum(1 for k, c in enumerate(cws) if c == 0x80 and (k == 0 or cws[k - 1] != 0x80))
    assert rising == attempts


def test_a_mode_change_not_confirmed_by_0x6061_in_time_is_a_fault(actuation, simrig):
    pair = make_pair(_plant(simrig, 4))
    m, p = _preflight(actuation, pair)
    pair.nodes[0].mode_written = lambda: None  # EMA 1's 0x6061 does not follow 0x6060 ...
    pair.nodes[0]._mode_display = 0  # ... and shows no mode (the drill had set CSP by SDO)
    smp = p.sync()
    with pytest.raises(DriveFault, match=r"node 1 \(EMA 1\): modes of operation 8 not confirmed by 0x6061 within "
                                         r"canopen.mode_change_timeout_s = 0.1 s \(0x6061 = 0\)"):
        cycles = 0
        while cycles < 60:
            cycles += 1
            hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
            p.send(m.setpoint_frames(*hold, smp))
            smp = p.sync()
    assert cycles == 51  # the mode went out with the first RPDOs; 50 cycles (0.1 s) later it is a fault


def test_a_mode_change_confirmed_within_the_timeout_is_not(actuation, pair):
    m, p = _preflight(actuation, pair)
    p.enable(p.sync(), cycles=60)
    assert m.fault is None and all(d.mode_pending is None and d.mode_display == 8 for d in m.drives.values())


# ------------------------------------------------------------------ faults in the cyclic phase


def test_heartbeat_timeout_and_emcy_raise(actuation, pair, simrig):
    m, p = _preflight(actuation, pair)
    p.sync()
    t_hb = max(d.last_heartbeat_s for d in m.drives.values())
    m.poll(t_hb + 0.148)  # the last SYNC-grid poll before the timeout
    with pytest.raises(HeartbeatLost, match=r"node \d \(EMA \d\): heartbeat lost .*timeout 0.150 s"):
        m.poll(t_hb + 0.150)  # fires on the grid poll at the timeout (within T/2 of it)
    m2, p2 = _preflight(actuation, make_pair(_plant(simrig, 3)))
    p2.sync()
    with pytest.raises(DriveFault, match=r"node 2: EMCY 0x4310 \(drive over temperature\)"):
        m2.on_frame(Frame(0x082, struct.pack("<HB5x", 0x4310, 0x09)), p2.t)


def test_unknown_and_malformed_frames_are_counted_not_fatal(actuation, pair):
    m, p = _preflight(actuation, pair)
    p.sync()
    m.on_frame(Frame(0x123, b"\x01\x02"), p.t)
    m.on_frame(Frame(0x181, b"\x01\x02\x03"), p.t)  # TPDO1 too short
    assert m.unknown_frames == 1 and m.bad_frames == 1
    assert p.sync() is not None


def test_errors_latch_and_force_quick_stop(actuation, pair):
    m, p = _preflight(actuation, pair)
    smp = p.enable(p.sync())
    assert m.fault is None and not m.quick_stop
    with pytest.raises(DriveFault):
        m.on_frame(Frame(0x081, struct.pack("<HB5x", 0x2310, 0x03)), p.t)
    assert isinstance(m.fault, DriveFault) and m.quick_stop
    rpdo1 = [f for f in m.setpoint_frames(OFF, OFF, smp) if f.arbitration_id == 0x201]
    assert rpdo1[0].data[:2] == bytes([0x02, 0x00])  # quick stop


# ------------------------------------------------------------------ the master's heartbeat, the drives' reaction


def test_master_heartbeat_from_the_first_frame_until_nmt_pre_operational():
    m = _master()
    assert m.poll(0.0) == []  # not started: no heartbeat
    assert m.start(0.0) == [Frame(0x000, bytes([0x81, 0x00]))]
    assert m.poll(0.0) == [HB]  # due with the first frame: the first poll sends it
    assert m.poll(0.049) == []
    assert m.poll(0.050) == [HB] and m.poll(0.051) == []
    assert m.poll(0.130) == [HB]  # late (the loop was held): sent now, the schedule kept ...
    assert m.poll(0.150) == [HB]
    assert m.poll(0.420) == [HB] and m.poll(0.450) == []  # ... unless a period behind: from now
    assert m.poll(0.470) == [HB]
    # a frame on its heartbeat's COB-ID that it hears (another node with its id, or an echo of a
    # loop-back interface: SocketCAN never returns its own frames) is counted, never fatal
    assert m.on_frame(HB, 0.48) == [] and m.unknown_frames == 1
    assert m.nmt_frames(NmtCommand.PRE_OPERATIONAL) == [Frame(0x000, bytes([0x80, 0x00]))]
    assert m.poll(0.6) == [] and m.poll(1.5) == []  # the check's last frame was NMT pre-operational


def test_preflight_configures_reads_back_and_drills_the_drives_reaction_to_the_masters_death(actuation, pair):
    m, p = _preflight(actuation, pair)
    reads = p.sdo_reads(2)
    assert reads[reads.index((0x1016, 1)):][:2] == [(0x1016, 1), (0x6007, 0)]  # each read back after its write
    for node in pair.nodes:
        assert node.read(0x1016, 1) == 127 << 16 | 125  # consumer on node 127, 2.5 * 50 ms
        assert node.read(0x6007) == 3 and node.read(0x605A) == 2 and node.read(0x1006) == 2000
        assert node.heartbeat_events and node.heartbeat_events[0][1] == 127  # the drill fired it
        assert node.state_machine.state is State.SWITCH_ON_DISABLED  # and the drive is down again
    for d in m.drives.values():
        rec = d.master_loss
        assert rec.reaction.configured and rec.reaction.problems == () and rec.armed
        drill = rec.drill
        assert drill.outcome is DrillOutcome.REACTED and drill.state_after == "QUICK_STOP_ACTIVE"
        assert 0x8130 in drill.emcy
        # within the consumer time plus two SYNC cycles of the master's last heartbeat
        assert 125.0 <= drill.reaction_ms <= 125.0 + 2 * T * 1e3
    js = m.safe_state_report(p.t)["ema2"]["master_loss"]
    assert js["configured"] is True and js["drill"]["outcome"] == "reacted" and js["drill"]["emcy"] == ["0x8130"]
    assert "verified" not in js  # "verified" claimed nothing it observed: gone


def test_a_drive_that_ignores_the_masters_death_stops_the_preflight_before_any_sync(actuation, simrig):
    pair = make_pair(_plant(simrig, 4))
    pair.nodes[1].connection_lost = lambda: None  # EMA 2 accepts 0x6007 = 3, then does nothing
    with pytest.raises(MasterLossReactionError, match=r"node 2 \(EMA 2\): did not react to the master's death: the "
                       r"master was silent \d+ ms \(its consumer time 0x1016:01 is 125 ms\) and the drive stayed "
                       r"OPERATION ENABLED \(EMCY seen: 0x8130\); the check is not started"):
        _preflight(actuation, pair)
    assert pair.stats.syncs == 0  # nothing was cycled
    assert {n.state_machine.state for n in pair.nodes} == {State.SWITCH_ON_DISABLED}  # both powered down again


def test_the_drill_under_an_external_watchdog_records_no_reaction_and_goes_on(actuation, simrig):
    watchdog = "STO of both drives dropped by the rig's watchdog relay 100 ms after the master's last heartbeat"
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen, external_watchdog=watchdog))
    pair = make_pair(_plant(simrig, 4))
    pair.nodes[1].connection_lost = lambda: None
    m, p = _preflight(act, pair)
    rec = m.drives[2].master_loss
    assert rec.drill.outcome is DrillOutcome.NO_REACTION and rec.drill.reaction_ms is None
    assert rec.armed and rec.external_watchdog == watchdog
    assert m.drives[1].master_loss.drill.outcome is DrillOutcome.REACTED


def test_skipping_the_drill_takes_a_reason_and_the_record_says_it(actuation, pair):
    why = "drives on a test bench without load; the drill is run at the weekly inspection"
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen, skip_master_loss_drill=why))
    m, p = _preflight(act, pair)
    assert (0x6040, 0) not in p.sdo_writes(1)  # no power-up by SDO
    rec = m.drives[1].master_loss
    assert rec.drill.outcome is DrillOutcome.SKIPPED and rec.drill.note == why and rec.armed
    assert rec.reaction.configured  # still configured and read back


def test_drive_without_abort_connection_option_is_refused_by_the_plan_naming_it(tmp_path):
    with pytest.raises(PlanError, match=r"canopen.external_watchdog: 0x6007:00 \(abort connection option code\) at "
                                        r"ema1, ema2: not in drive.eds"):
        _variant(tmp_path, eds_remove=[0x6007])


def test_external_watchdog_lets_a_drive_without_its_own_reaction_run_and_says_so(tmp_path, simrig):
    watchdog = "STO of both drives dropped by the rig's watchdog relay 100 ms after the master's last heartbeat"
    act, rig = _variant(tmp_path, eds_remove=[0x6007], canopen={"external_watchdog": watchdog})
    pair = make_pair(_plant(simrig, 4), rig)
    m, p = _preflight(act, pair, rig)
    assert m.preflight_done
    for d in m.drives.values():
        assert not d.master_loss.reaction.configured and d.master_loss.drill.outcome is DrillOutcome.NOT_CONFIGURED
        assert d.master_loss.armed and d.master_loss.external_watchdog == watchdog
    assert (0x1016, 1) not in p.sdo_writes(1)


def test_refused_or_not_kept_reaction_objects_stop_the_preflight(actuation, simrig):
    refusing = FaultInjector(make_pair(_plant(simrig, 5)), [Fault("sdo_abort", 1, value=float(0x1016))],
                             record_truth=False)
    with pytest.raises(MasterLossReactionError, match=r"node 1 \(EMA 1\): .*0x1016:01 \(consumer heartbeat time 1\): "
                       r"SDO abort 0x08000020"):
        _preflight(actuation, refusing)
    forgetting = make_pair(_plant(simrig, 6))
    forgetting.nodes[1].store.live[(0x6007, 0)] = lambda: 1  # EMA 2 answers 1 whatever was written
    with pytest.raises(MasterLossReactionError, match=r"node 2 \(EMA 2\): .*0x6007:00 \(abort connection option "
                       r"code\) reads back 0x1, not 0x3"):
        _preflight(actuation, forgetting)


# ------------------------------------------------------------------ a drive without CST


def test_a_drive_without_cst_gets_csp_once_by_sdo_and_no_mode_pdo(tmp_path, simrig):
    act, rig = _variant(tmp_path, eds_defaults={(0x6502, 0): "0x00000080"})  # CSP only
    assert {d.force_control for d in rig.plan.drives} == {ForceControl.CSP}
    assert [p.name for p in rig.plan.node("ema1").layout.pdos] == ["RPDO1", "TPDO1", "TPDO2"]
    assert [e.name for e in rig.plan.node("ema1").layout["RPDO1"].entries] == ["controlword", "target_position"]
    pair = make_pair(_plant(simrig, 7), rig)
    m, p = _preflight(act, pair, rig)
    assert (0x6060, 0) in p.sdo_writes(1) and pair.nodes[0].read(0x6060) == 8
    smp = p.enable(p.sync())
    assert m.all_in(State.OPERATION_ENABLED)
    assert not any(f.arbitration_id in (0x301, 0x302) for _, f in p.traffic)
    with pytest.raises(DriveFault, match=r"node 1 \(EMA 1\): a force setpoint for a drive that holds forces in CSP"):
        m.setpoint_frames(Setpoint(DriveMode.FORCE, 100.0), Setpoint(DriveMode.POSITION, smp.phi2_rad), smp)


def test_a_drive_whose_eds_announces_no_csp_is_refused_naming_0x6502(tmp_path):
    with pytest.raises(PlanError, match=r"canopen.eds: 0x6502:00 \(supported drive modes\) at ema1, ema2: drive.eds "
                                        r"announces neither CSP nor CST \(0x6502 = 0x00000060\)"):
        _variant(tmp_path, eds_defaults={(0x6502, 0): "0x00000060"})


@pytest.mark.parametrize("reacts", [True, False])
def test_a_drive_whose_error_behaviour_stops_it_is_read_after_the_drill(actuation, simrig, reacts):
    """0x1029 = stopped: at the heartbeat event the drive stops answering SDO; the master notes it, waits out
    the drill, restores SDO by NMT pre-operational and reads the state the drive is in then."""
    from hil.canopen.nmt import NmtState

    pair = make_pair(_plant(simrig, 8))
    node = pair.nodes[1]
    react = node.connection_lost

    def stopped():
        if reacts:
            react()
        node.nmt_state = NmtState.STOPPED

    node.connection_lost = stopped
    if reacts:
        m, p = _preflight(actuation, pair)
        drill = m.drives[2].master_loss.drill
        assert drill.outcome is DrillOutcome.REACTED and drill.reaction_ms is None
        assert drill.state_after == "QUICK_STOP_ACTIVE" and "NMT stopped" in drill.note
        assert m.drives[1].master_loss.drill.reaction_ms is not None
    else:
        with pytest.raises(MasterLossReactionError, match=r"node 2 \(EMA 2\): did not react"):
            _preflight(actuation, pair)
    assert node.state_machine.state is State.SWITCH_ON_DISABLED


def test_a_drive_that_falls_silent_while_drilled_leaves_the_other_disabled(actuation, simrig):
    """An SDO timeout in the drill (not a soft read) ends the preflight outside its generator: the link's close
    still disables, by SDO, every drive the drill powered up."""
    from hil.canopen.sdo import SdoTimeout
    from hil.master.link import CanopenLink
    from hil.transport import InProcessTransport

    pair = make_pair(_plant(simrig, 9))
    deaf = pair.nodes[1]
    serve = deaf.on_sdo

    def until_enabled(frame, t):  # EMA 2 stops answering SDO once it is enabled
        if deaf.state_machine.state is State.OPERATION_ENABLED:
            return None
        return serve(frame, t)

    deaf.on_sdo = until_enabled
    tr = InProcessTransport(pair, T)
    link = CanopenLink(_master(actuation), tr)
    try:
        with pytest.raises(SdoTimeout, match=r"node 2: SDO timeout"):
            link.first_sample()
        link.close()
    finally:
        tr.close()
    assert pair.nodes[0].state_machine.state is State.SWITCH_ON_DISABLED  # EMA 1: disable voltage by SDO
    final = link.final_states
    assert not final["ema2"]["safe"]  # EMA 2 could not be told: the record says so


def test_the_masters_events_are_typed_and_matched_by_type(actuation, pair):
    """One small frozen class per event (h11's events), typed fields, ``str`` the log line."""
    m, p = _preflight(actuation, pair)
    p.enable(p.sync(), cycles=60)
    events = m.drain_events()
    assert m.drain_events() == []  # drained
    first = events[0]
    assert first == event.NmtSent(0.0, 0, NmtCommand.RESET_NODE) and str(first) == "NMT RESET_NODE to all nodes"
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.node_id = 1
    boots, silent, resumed, emcy, pdo_states, sdo_states = set(), [], [], [], [], []
    for ev in events:
        match ev:
            case event.BootUp(node_id=n):
                boots.add(n)
            case event.MasterFellSilent(last_heartbeat_s=last):
                silent.append(last)
            case event.MasterHeartbeatResumed():
                resumed.append(ev.t_s)
            case event.EmcyReceived(emcy=e):
                emcy.append((ev.node_id, e.code))
            case event.DriveStateChanged(by_sdo=True):
                sdo_states.append((ev.node_id, ev.new))
            case event.DriveStateChanged(old=old, new=new):
                pdo_states.append((ev.node_id, old, new))
    assert boots == {1, 2}
    assert silent == [pytest.approx(0.05)] and len(resumed) == 1 and resumed[0] > silent[0]
    assert emcy == [(1, 0x8130), (2, 0x8130), (1, 0x0000), (2, 0x0000)]  # the drill: heartbeat event, reset
    assert (1, State.QUICK_STOP_ACTIVE) in sdo_states and (2, State.QUICK_STOP_ACTIVE) in sdo_states
    assert pdo_states[-2:] == [(1, State.SWITCHED_ON, State.OPERATION_ENABLED),
                               (2, State.SWITCHED_ON, State.OPERATION_ENABLED)]
    assert str(event.DriveStateChanged(0.0, 1, State.SWITCHED_ON, State.OPERATION_ENABLED, by_sdo=True)) == \
        "SWITCHED_ON -> OPERATION_ENABLED (SDO)"
    assert str(event.CycleIncomplete(0.1, 0, 7)) == "cycle 7: TPDOs incomplete at the next SYNC"
    assert str(event.MasterFellSilent(0.1, 0, 0.05)) == "the master falls silent (last heartbeat at 0.050 s)"
