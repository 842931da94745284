"""Protocol tests of the sans-IO CANopen master core: golden frames, preflight, errors.

A tiny synchronous pump in the test connects MasterCore and SimDrivePair
frame by frame (no bus, no threads, no sleeps).
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from hil.canopen.cia402 import State
from hil.canopen.frame import Frame, sync_frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.od import load_eds
from hil.canopen.process import DriveMode, Setpoint
from hil.canopen.sdo import SdoAbortError
from hil.master import DriveFault, HeartbeatLost, MasterCore, MasterLossReactionError, PreflightError
from sim.drives import SimDrivePair
from sim.faults import Fault, FaultInjector
from sim.plant import RigPlant


class Pump:
    """Master <-> simulated pair, delivering frames in order; records all traffic."""

    def __init__(self, master: MasterCore, pair: SimDrivePair | None) -> None:
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

    def sync(self):
        self.t += self.m.T
        if self.pair is not None:
            self.to_master += self.pair.tick(self.t)
        self.m.on_frame(sync_frame(), self.t)
        self.traffic.append(("M", sync_frame()))
        self.to_slaves.append(sync_frame())
        self.run()
        return self.m.take_sample()


@pytest.fixture()
def pair(simrig):
    plant = RigPlant(simrig.params, np.random.default_rng(1))
    return SimDrivePair(plant, lambda node_id=None: load_eds(None, node_id=node_id))


def _preflight(actuation, pair):
    m = MasterCore(actuation)
    p = Pump(m, pair)
    p.send(m.start(0.0))
    p.run()
    return m, p


def test_start_sends_nmt_reset_node_to_all(actuation):
    m = MasterCore(actuation)
    assert m.start(0.0) == [Frame(0x000, bytes([0x81, 0x00]))]


def test_first_sdo_after_both_boot_ups_is_identity_upload(actuation):
    m = MasterCore(actuation)
    m.start(0.0)
    assert m.on_frame(Frame(0x701, b"\x00"), 0.01) == []  # still waiting for node 2
    out = m.on_frame(Frame(0x702, b"\x00"), 0.02)
    # SDO initiate upload of 0x1018:01 to node 1
    assert out == [Frame(0x601, bytes([0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0]))]


def test_preflight_against_simulated_drives_golden_sequence(actuation, pair):
    m, p = _preflight(actuation, pair)
    assert m.preflight_done
    writes = [(f.data[2] << 8 | f.data[1], f.data[3]) for who, f in p.traffic
              if who == "M" and f.arbitration_id == 0x601 and f.data[0] & 0xE0 == 0x20]
    # configuration of node 1, in order: heartbeat, interpolation period, position limits,
    # quick stop option, cycle period, then the PDO mapping procedure of CiA 301
    assert writes[:7] == [(0x1017, 0), (0x60C2, 1), (0x60C2, 2), (0x607D, 1), (0x607D, 2), (0x605A, 0), (0x1006, 0)]
    assert writes[7:10] == [(0x1400, 1), (0x1600, 0), (0x1600, 1)]
    # then, after the 29 writes of the PDO mapping, the drive's own reaction to the master's
    # death: consumer heartbeat on the master, abort connection option (each read back)
    assert writes[36:] == [(0x1016, 1), (0x6007, 0)]
    assert len(writes) == 7 + 29 + 2
    assert p.traffic[-1] == ("M", Frame(0x000, bytes([0x01, 0x00])))  # NMT start all
    # the drives now carry the configuration
    n1 = pair.nodes[0]
    assert n1.read(0x1017) == 100
    assert n1.read(0x607D, 2) == round(20.0 * actuation.mechanics.i_total_rad_per_mm * 4096 / (2 * np.pi))
    assert m.drives[1].identity == {"vendor_id": 0xE3A, "product_code": 0x402, "revision": 0x10000, "serial": 0}


def test_identity_mismatch_is_refused_naming_the_field(actuation, pair):
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen, product_code=0x999))
    with pytest.raises(PreflightError, match=r"node 1 \(EMA 1\): identity 0x1018 .*canopen.product_code"):
        _preflight(act, pair)


def test_gear_ratio_mismatch_is_refused(actuation, pair):
    act = dataclasses.replace(actuation, mechanics=dataclasses.replace(actuation.mechanics, i_total_rad_per_mm=6.0))
    with pytest.raises(PreflightError, match=r"gear ratio 0x2102 = 5.026548 rad/mm, profile mechanics.i_total_rad_per_mm"):
        _preflight(act, pair)


def test_sdo_abort_reported_with_code_and_meaning(actuation):
    m = MasterCore(actuation)
    m.start(0.0)
    m.on_frame(Frame(0x701, b"\x00"), 0.0)
    m.on_frame(Frame(0x702, b"\x00"), 0.0)
    abort = Frame(0x581, bytes([0x80, 0x18, 0x10, 0x01]) + struct.pack("<I", 0x06020000))
    with pytest.raises(SdoAbortError, match=r"node 1: SDO abort 0x06020000 \(object does not exist"):
        m.on_frame(abort, 0.01)


def test_boot_timeout(actuation):
    m = MasterCore(actuation)
    m.start(0.0)
    m.on_frame(Frame(0x702, b"\x00"), 0.1)
    m.poll(1.9)
    with pytest.raises(PreflightError, match=r"node\(s\) \[1\]: no boot-up within canopen.boot_timeout_s = 2.0 s"):
        m.poll(2.01)


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


def test_orderly_shutdown_and_quick_stop(actuation, pair):
    m, p = _preflight(actuation, pair)
    smp = p.sync()
    for _ in range(12):
        hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        p.send(m.setpoint_frames(*hold, smp))
        smp = p.sync()
    assert m.all_in(State.OPERATION_ENABLED)
    off = Setpoint(DriveMode.DISABLED, 0.0)
    cws = []
    for _ in range(12):
        frames = m.setpoint_frames(off, off, smp)
        cws += [f.data[0] for f in frames if f.arbitration_id == 0x201]
        p.send(frames)
        smp = p.sync()
    assert m.all_in(State.SWITCH_ON_DISABLED)
    dedup = [c for k, c in enumerate(cws) if k == 0 or c != cws[k - 1]]
    assert dedup == [0x07, 0x06, 0x00]  # disable operation, shutdown, disable voltage
    # quick stop on abort
    m2, p2 = _preflight(actuation, SimDrivePair(RigPlant(pair.plant.params, np.random.default_rng(2)),
                                                 lambda node_id=None: load_eds(None, node_id=node_id)))
    smp = p2.sync()
    for _ in range(12):
        hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        p2.send(m2.setpoint_frames(*hold, smp))
        smp = p2.sync()
    m2.quick_stop = True
    p2.send(m2.setpoint_frames(off, off, smp))
    p2.sync()
    smp = p2.sync()
    assert m2.state_of(1) is State.QUICK_STOP_ACTIVE
    for _ in range(40):
        p2.send(m2.setpoint_frames(off, off, smp))
        smp = p2.sync()
    assert m2.all_in(State.SWITCH_ON_DISABLED)


def test_heartbeat_timeout_and_emcy_raise(actuation, pair):
    m, p = _preflight(actuation, pair)
    p.sync()
    t_hb = max(d.last_heartbeat_s for d in m.drives.values())
    m.poll(t_hb + 0.148)  # the last SYNC-grid poll before the timeout
    with pytest.raises(HeartbeatLost, match=r"node \d \(EMA \d\): heartbeat lost .*timeout 0.150 s"):
        m.poll(t_hb + 0.150)  # fires on the grid poll at the timeout (within T/2 of it)
    m2, p2 = _preflight(actuation, SimDrivePair(RigPlant(pair.plant.params, np.random.default_rng(3)),
                                                 lambda node_id=None: load_eds(None, node_id=node_id)))
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
    smp = p.sync()
    for _ in range(12):
        hold = (Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad))
        p.send(m.setpoint_frames(*hold, smp))
        smp = p.sync()
    assert m.fault is None and not m.quick_stop
    with pytest.raises(DriveFault):
        m.on_frame(Frame(0x081, struct.pack("<HB5x", 0x2310, 0x03)), p.t)
    assert isinstance(m.fault, DriveFault) and m.quick_stop
    off = Setpoint(DriveMode.DISABLED, 0.0)
    rpdo1 = [f for f in m.setpoint_frames(off, off, smp) if f.arbitration_id == 0x201]
    assert rpdo1[0].data[:2] == bytes([0x02, 0x00])  # quick stop


# ------------------------------------------------------------------ the master's heartbeat, the drives' reaction


HB = Frame(0x77F, b"\x05")  # the master's heartbeat: node 127, operational


def test_master_heartbeat_from_the_first_frame_until_nmt_pre_operational(actuation):
    m = MasterCore(actuation)
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


def test_preflight_configures_and_reads_back_the_drives_reaction_to_the_masters_death(actuation, pair):
    m, p = _preflight(actuation, pair)
    reads = [(f.data[2] << 8 | f.data[1], f.data[3]) for who, f in p.traffic
             if who == "M" and f.arbitration_id == 0x602 and f.data[0] == 0x40]
    assert reads[-4:] == [(0x1016, 1), (0x6007, 0), (0x605A, 0), (0x1006, 0)]  # after the writes
    for node in pair.nodes:
        assert node.read(0x1016, 1) == 127 << 16 | 125  # consumer on node 127, 2.5 * 50 ms
        assert node.read(0x6007) == 3 and node.read(0x605A) == 2 and node.read(0x1006) == 2000
        assert node._hb_consumers == {127: [0.125, None, False]}  # armed by the next heartbeat
    assert m.drives[2].master_loss == {"consumer_heartbeat_ms": 125, "master_node_id": 127,
                                       "abort_connection_option": 3, "verified": True, "problems": [],
                                       "external_watchdog": ""}


def _without_6007(node_id=None):
    od = load_eds(None, node_id=node_id)
    if node_id == 2:
        del od[0x6007]  # EMA 2's drive has no abort connection option
    return od


def test_drive_without_abort_connection_option_stops_the_preflight_naming_it(actuation, simrig):
    pair = SimDrivePair(RigPlant(simrig.params, np.random.default_rng(4)), _without_6007)
    with pytest.raises(MasterLossReactionError, match=r"node 2 \(EMA 2\): its reaction to the master's death is "
                       r"not in place: 0x6007:00 \(abort connection option code\): SDO abort 0x06020000 \(object "
                       r"does not exist in the object dictionary\).*canopen.external_watchdog") as exc:
        _preflight(actuation, pair)
    assert isinstance(exc.value, PreflightError) and isinstance(exc.value, RuntimeError)
    assert pair.nodes[0].read(0x6007) == 3  # EMA 1 was configured; nothing was enabled
    assert pair.stats.syncs == 0 and {n.state_machine.state for n in pair.nodes} == {State.SWITCH_ON_DISABLED}


def test_external_watchdog_stated_in_the_profile_lets_such_a_drive_run_and_says_so(actuation, simrig):
    watchdog = "STO of both drives dropped by the rig's watchdog relay 100 ms after the master's last heartbeat"
    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen, external_watchdog=watchdog))
    pair = SimDrivePair(RigPlant(simrig.params, np.random.default_rng(4)), _without_6007)
    m, p = _preflight(act, pair)
    assert m.preflight_done
    ml = m.safe_state_report(p.t)["ema2"]["master_loss"]
    assert ml["verified"] is False and ml["external_watchdog"] == watchdog
    assert ml["problems"] == [("0x6007:00 (abort connection option code): SDO abort 0x06020000 "
                               "(object does not exist in the object dictionary)")]
    assert m.drives[1].master_loss["verified"] is True


def test_refused_or_not_kept_reaction_objects_stop_the_preflight(actuation, simrig):
    plant = RigPlant(simrig.params, np.random.default_rng(5))
    refusing = FaultInjector(SimDrivePair(plant, lambda node_id=None: load_eds(None, node_id=node_id)),
                             [Fault("sdo_abort", 1, value=float(0x1016))], record_truth=False)
    with pytest.raises(MasterLossReactionError, match=r"node 1 \(EMA 1\): .*0x1016:01 \(consumer heartbeat time 1\): "
                       r"SDO abort 0x08000020"):
        _preflight(actuation, refusing)
    forgetting = SimDrivePair(RigPlant(simrig.params, np.random.default_rng(6)),
                              lambda node_id=None: load_eds(None, node_id=node_id))
    forgetting.nodes[1].store.live[(0x6007, 0)] = lambda: 1  # EMA 2 answers 1 whatever was written
    with pytest.raises(MasterLossReactionError, match=r"node 2 \(EMA 2\): .*0x6007:00 \(abort connection option "
                       r"code\) reads back 0x1, not 0x3"):
        _preflight(actuation, forgetting)
