"""Tests of the simulated CiA 402 drive pair (sim.drives): golden frames and closed-loop numbers.

Known answers: the EDS defaults (identity, heartbeat, PDO layout), the CiA 301
frame formats (boot-up, heartbeat, EMCY, SDO abort), the CiA 402 statuswords
of hil.canopen.cia402, the sensor model of sim.plant at rest (noise-free LVDT
s_meas = offset, force 0), and the unit conversions of the shipped signal map
(4096 increments per revolution, LVDT 0x2100 in um, force 0x2101 in 0.1 N).
The drives are built from the shipped profile's plan (tests/support/canopen_rig.py);
at power-on their PDOs are the EDS defaults, which are the shipped layout:
RPDO1 = controlword u16, target position i32, target torque i16; RPDO2 = modes of
operation i8; TPDO1 = statusword u16, position i32, modes display i8; TPDO2 =
LVDT i32 [um], force i32 [0.1 N].
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from hil.canopen.cia402 import State, controlword, decode_state, next_command
from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import Frame, sync_frame
from hil.canopen.process import DriveMode
from hil.canopen.sdo import SdoAbortCode, SdoAbortError
from hil.canopen.units import permille_to_force_N
from hil.profile.load import load_actuation
from hil.profile.rig import plan_for
from sim.drives import QUICK_STOP_HOLD_S, TARGET_WINDOW_INC, NmtState, SimDrivePair, error_register_bits
from sim.params import RigParams
from sim.plant import RigPlant
from support.canopen_rig import make_pair, od_factory, shipped_rig
from support.profiles import write_profile_variant
from support.rigs import I_TOTAL, T_S, brief_rig, quiet
from support.sim_bus import Bus

INC_PER_MM = I_TOTAL * 4096 / (2 * math.pi)  # 3276.8 increments per mm of stroke

SW_SOD = 0x0250  # switch on disabled + remote
SW_READY = 0x0231
SW_SWITCHED_ON = 0x0233
SW_OE = 0x0237  # operation enabled, no supported mode
SW_OE_CSP_REACHED = 0x1637  # + drive follows command (12) + target reached (10)
SW_QSA = 0x0217
SW_FRA = 0x021F
SW_FAULT = 0x0218


def make_params() -> RigParams:
    """The default rig of tests/test_sim_plant.py with noise-free LVDTs and load cells."""
    return quiet(brief_rig())


# the shipped PDO layout (the EDS defaults) as a minimal master packs and reads it
def rpdo1(node: int, cw: int, pos: int = 0, torque: int = 0) -> Frame:
    return Frame(0x200 + node, struct.pack("<Hih", cw, pos, torque))


def rpdo2(node: int, mode: int) -> Frame:
    return Frame(0x300 + node, struct.pack("<b", mode))


def tpdo1(frame: Frame) -> tuple[int, int, int]:
    """(statusword, position actual [inc], modes display)"""
    return struct.unpack("<Hib", frame.data)


def tpdo2(frame: Frame) -> tuple[int, int]:
    """(LVDT [um], force [0.1 N])"""
    return struct.unpack("<ii", frame.data)


class Rig(Bus):
    """The shared minimal master (:class:`support.sim_bus.Bus`: time, frames to the pair, SDO
    transfers, NMT), with SYNC cycles of both drives' RPDOs."""

    def __init__(self, pair: SimDrivePair) -> None:
        super().__init__(pair, T_S)

    def sync(self) -> list[Frame]:
        self.t += T_S
        return self.send(sync_frame())

    def sync_by_id(self) -> dict[int, Frame]:
        return {f.arbitration_id: f for f in self.sync()}

    def cycle(self, cw: tuple[int, int], pos: tuple[int, int] = (0, 0),
              torque: tuple[int, int] = (0, 0)) -> dict[int, Frame]:
        """RPDO1 to both drives, then SYNC; returns the SYNC's output by COB-ID."""
        for k, node in enumerate((1, 2)):
            assert self.send(rpdo1(node, cw[k], pos[k], torque[k])) == []
        return self.sync_by_id()

    def enable(self, mode1: int = 8, mode2: int = 8) -> None:
        """Start both nodes, set the modes (RPDO2) and walk both drives to OPERATION_ENABLED."""
        self.nmt(0x01)
        self.send(rpdo2(1, mode1))
        self.send(rpdo2(2, mode2))
        for cw in (0x06, 0x07, 0x0F):
            self.cycle((cw, cw))
        assert all(n.state_machine.state is State.OPERATION_ENABLED for n in self.pair.nodes)


def status(frames: dict[int, Frame], node: int) -> int:
    return tpdo1(frames[0x180 + node])[0]


def position(frames: dict[int, Frame], node: int) -> int:
    return tpdo1(frames[0x180 + node])[1]


@pytest.fixture
def pair() -> SimDrivePair:
    return make_pair(RigPlant(make_params(), np.random.default_rng(0)))


@pytest.fixture
def rig(pair) -> Rig:
    r = Rig(pair)
    r.pair.power_on(0.0)
    return r


# ------------------------------------------------------------------ NMT, heartbeat


def test_power_on_sends_bootup_frames_and_enters_pre_operational(pair):
    assert pair.sample is None
    frames = pair.power_on(0.0)
    assert frames == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00")]
    assert [n.nmt_state for n in pair.nodes] == [NmtState.PRE_OPERATIONAL] * 2
    assert [n.statusword for n in pair.nodes] == [SW_SOD, SW_SOD]
    # one DISABLED plant step at power-on: the current sample is the rig at rest
    assert pair.stats.plant_steps == 1
    assert pair.plant.t_s == pytest.approx(T_S)
    assert pair.sample.s1_mm == pytest.approx(0.3) and pair.sample.s2_mm == pytest.approx(-0.2)


def test_frames_before_power_on_are_ignored(pair):
    assert pair.on_frame(sync_frame(), 0.0) == []
    assert pair.tick(1.0) == []
    assert pair.stats.frames_unpowered == 1 and pair.stats.plant_steps == 0


def test_nmt_reset_node_and_reset_communication(rig):
    rig.write(1, 0x1017, 0, "H", 100)
    rig.write(2, 0x1017, 0, "H", 50)
    assert rig.read(1, 0x1017, 0, "H") == 100
    rig.write(1, 0x6040, 0, "H", 0x06)  # acyclic controlword by SDO: -> READY_TO_SWITCH_ON
    assert rig.pair.nodes[0].statusword == SW_READY

    # reset communication: 0x1000..0x1FFF back to the EDS, the drive state stays
    assert rig.nmt(0x82, 1) == [Frame(0x701, b"\x00")]
    assert rig.read(1, 0x1017, 0, "H") == 0
    assert rig.pair.nodes[0].statusword == SW_READY
    rig.write(1, 0x1017, 0, "H", 100)
    rig.write(1, 0x6072, 0, "H", 5000)

    # reset node: everything back to the EDS, drive SWITCH_ON_DISABLED; node 2 untouched
    assert rig.nmt(0x81, 1) == [Frame(0x701, b"\x00")]
    assert rig.read(1, 0x1017, 0, "H") == 0
    assert rig.read(1, 0x6072, 0, "H") == 10000
    assert rig.pair.nodes[0].statusword == SW_SOD
    assert rig.pair.nodes[0].nmt_state is NmtState.PRE_OPERATIONAL
    assert rig.read(2, 0x1017, 0, "H") == 50

    # reset of all nodes
    assert rig.nmt(0x81, 0) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00")]
    assert rig.read(2, 0x1017, 0, "H") == 0


def test_heartbeat_every_producer_time_with_the_nmt_state(rig):
    rig.write(1, 0x1017, 0, "H", 100)  # at t = 0
    pair = rig.pair
    assert pair.tick(0.05) == []
    assert pair.tick(0.1) == [Frame(0x701, b"\x7F")]  # pre-operational
    rig.t = 0.1
    assert rig.nmt(0x01) == []
    assert pair.tick(0.15) == []
    assert pair.tick(0.2) == [Frame(0x701, b"\x05")]  # operational
    assert pair.tick(0.25) == []
    assert pair.tick(0.3) == [Frame(0x701, b"\x05")]
    rig.t = 0.3
    rig.nmt(0x02, 1)  # stopped: no SDO
    assert rig.send(Frame(0x601, bytes([0x40, 0x17, 0x10, 0, 0, 0, 0, 0]))) == []
    assert pair.tick(0.4) == [Frame(0x701, b"\x04")]
    pair.set_heartbeat_enabled(0, False)
    assert pair.tick(0.5) == []
    pair.set_heartbeat_enabled(0, True)
    assert pair.tick(0.6) == [Frame(0x701, b"\x04")]
    assert pair.stats.heartbeats_sent == 5  # node 2 has 0x1017 = 0: none


def test_unknown_and_malformed_frames_are_ignored_and_counted(rig):
    before = rig.pair.stats.bad_frames_ignored
    assert rig.send(Frame(0x123, b"\x01\x02")) == []
    assert rig.send(Frame(0x000, b"\x01")) == []  # NMT needs 2 bytes
    assert rig.send(Frame(0x000, b"\x55\x00")) == []  # unknown command specifier
    assert rig.send(Frame(0x601, b"\x40\x00\x10")) == []  # SDO request not 8 bytes
    assert rig.send(Frame(0x181, b"\x50\x02\x00\x00\x00\x00\x00")) == []  # another node's TPDO
    assert rig.pair.stats.bad_frames_ignored == before + 5
    assert [n.nmt_state for n in rig.pair.nodes] == [NmtState.PRE_OPERATIONAL] * 2


# ------------------------------------------------------------------ SDO


def test_sdo_upload_identity_and_segmented_device_name(rig):
    assert rig.read(1, 0x1018, 1, "I") == 0x00000E3A
    assert rig.read(1, 0x1018, 2, "I") == 0x00000402
    assert rig.read(2, 0x1018, 3, "I") == 0x00010000
    assert rig.read(1, 0x1000, 0, "I") == 0x00020192
    assert rig.read(2, 0x1014, 0, "I") == 0x82  # $NODEID + 0x80 resolved per node
    # 9 characters: segmented upload (initiate response 0x41 with the size)
    first = rig.send(Frame(0x601, bytes([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0])))
    assert first == [Frame(0x581, bytes([0x41, 0x08, 0x10, 0x00, 9, 0, 0, 0]))]
    rig.send(Frame(0x601, bytes([0x80, 0x08, 0x10, 0x00, 0, 0, 0, 0])))  # abort it
    assert rig.sdo(1, 0x1008, 0) == b"EMA drive"
    # the drive's own data: gear ratio of the plant as REAL32
    assert struct.unpack("<f", rig.sdo(1, 0x2102, 0))[0] == pytest.approx(I_TOTAL, rel=1e-7)
    # live values at rest
    assert rig.read(1, 0x6041, 0, "H") == SW_SOD
    assert rig.read(1, 0x2100, 0, "i") == 300
    assert rig.read(2, 0x2100, 0, "i") == -200


def test_sdo_download_read_back_and_abort_codes(rig):
    rig.write(2, 0x6072, 0, "H", 5000)
    assert rig.read(2, 0x6072, 0, "H") == 5000
    assert rig.read(1, 0x6072, 0, "H") == 10000

    def abort_code(node: int, index: int, sub: int, data: bytes | None = None) -> int:
        with pytest.raises(SdoAbortError) as info:
            rig.sdo(node, index, sub, data)
        return info.value.code

    assert abort_code(1, 0x2000, 0) == SdoAbortCode.OBJECT_DOES_NOT_EXIST
    assert abort_code(1, 0x1018, 7) == SdoAbortCode.SUBINDEX_DOES_NOT_EXIST
    assert abort_code(1, 0x1018, 1, struct.pack("<I", 1)) == SdoAbortCode.WRITE_OF_READ_ONLY
    assert abort_code(1, 0x1008, 0, b"new name!") == SdoAbortCode.WRITE_OF_READ_ONLY  # segmented
    assert abort_code(1, 0x1017, 0, struct.pack("<I", 1)) == SdoAbortCode.LENGTH_MISMATCH
    assert abort_code(1, 0x607D, 2, struct.pack("<i", -70000)) == SdoAbortCode.MAX_LESS_THAN_MIN
    assert abort_code(1, 0x6060, 0, struct.pack("<b", 3)) == SdoAbortCode.VALUE_RANGE_EXCEEDED
    # golden abort frame: 0x80, index, subindex, code
    assert rig.send(Frame(0x601, bytes([0x40, 0x00, 0x20, 0x00, 0, 0, 0, 0]))) == \
        [Frame(0x581, bytes([0x80, 0x00, 0x20, 0x00, 0x00, 0x00, 0x02, 0x06]))]


def test_pdo_mapping_validation_aborts(rig):
    def abort_code(index: int, sub: int, data: bytes) -> int:
        with pytest.raises(SdoAbortError) as info:
            rig.sdo(1, index, sub, data)
        return info.value.code

    # mapping changed while TPDO2 is valid
    assert abort_code(0x1A01, 0, b"\x00") == SdoAbortCode.PARAMETER_INCOMPATIBILITY
    rig.write(1, 0x1801, 1, "I", 0x8000_0281)  # disable TPDO2
    # entry written while sub-index 0 is not 0
    assert abort_code(0x1A01, 3, struct.pack("<I", 0x60640020)) == SdoAbortCode.PARAMETER_INCOMPATIBILITY
    rig.write(1, 0x1A01, 0, "B", 0)
    assert abort_code(0x1A01, 3, struct.pack("<I", 0x20000020)) == SdoAbortCode.CANNOT_BE_MAPPED  # no object
    assert abort_code(0x1A01, 3, struct.pack("<I", 0x10170010)) == SdoAbortCode.CANNOT_BE_MAPPED  # not mappable
    assert abort_code(0x1A01, 3, struct.pack("<I", 0x60640010)) == SdoAbortCode.CANNOT_BE_MAPPED  # wrong length
    rig.write(1, 0x1A01, 3, "I", 0x60640020)
    # 32 + 32 + 32 bits: too long
    assert abort_code(0x1A01, 0, b"\x03") == SdoAbortCode.EXCEEDS_PDO_LENGTH
    assert abort_code(0x1A01, 0, b"\x09") == SdoAbortCode.EXCEEDS_PDO_LENGTH
    # an RPDO cannot map a read-only object
    rig.write(1, 0x1400, 1, "I", 0x8000_0201)
    rig.write(1, 0x1600, 0, "B", 0)
    assert abort_code(0x1600, 1, struct.pack("<I", 0x60410010)) == SdoAbortCode.CANNOT_BE_MAPPED
    # communication parameters: CAN-ID change while valid, restricted CAN-ID, reserved type
    assert abort_code(0x1800, 1, struct.pack("<I", 0x190)) == SdoAbortCode.VALUE_RANGE_EXCEEDED
    rig.write(1, 0x1800, 1, "I", 0x8000_0181)
    assert abort_code(0x1800, 1, struct.pack("<I", 0x701)) == SdoAbortCode.VALUE_RANGE_EXCEEDED
    assert abort_code(0x1800, 2, b"\xFC") == SdoAbortCode.VALUE_RANGE_EXCEEDED


def test_remapping_tpdo2_by_sdo_swaps_its_bytes(rig):
    rig.nmt(0x01)
    frames = rig.sync_by_id()
    assert frames[0x281].data == bytes.fromhex("2C010000 00000000")  # LVDT 300 um, force 0
    rig.write(1, 0x1801, 1, "I", 0x8000_0281)
    rig.write(1, 0x1A01, 0, "B", 0)
    rig.write(1, 0x1A01, 1, "I", 0x21010020)
    rig.write(1, 0x1A01, 2, "I", 0x21000020)
    rig.write(1, 0x1A01, 0, "B", 2)
    assert 0x281 not in rig.sync_by_id()  # disabled
    rig.write(1, 0x1801, 1, "I", 0x281)
    frames = rig.sync_by_id()
    assert frames[0x281].data == bytes.fromhex("00000000 2C010000")
    assert frames[0x282].data == bytes.fromhex("38FFFFFF 00000000")  # node 2 unchanged
    # one object only, on a new COB-ID, every 2nd SYNC
    rig.write(1, 0x1801, 1, "I", 0x8000_0281)
    rig.write(1, 0x1A01, 0, "B", 1)
    rig.write(1, 0x1801, 2, "B", 2)
    rig.write(1, 0x1801, 1, "I", 0x381)
    sent = [0x381 in rig.sync_by_id() for _ in range(4)]
    assert sent == [False, True, False, True]
    assert rig.sync_by_id().get(0x381) is None
    assert rig.sync_by_id()[0x381].data == bytes.fromhex("00000000")


# ------------------------------------------------------------------ SYNC and PDOs


def test_sync_tpdos_golden_bytes_at_rest(rig):
    # PRE-OPERATIONAL: no PDOs, but the plant steps
    assert rig.sync() == []
    assert rig.nmt(0x01) == []
    frames = rig.sync()
    assert frames == [
        Frame(0x181, bytes.fromhex("5002 00000000 00")),
        Frame(0x281, bytes.fromhex("2C010000 00000000")),
        Frame(0x182, bytes.fromhex("5002 00000000 00")),
        Frame(0x282, bytes.fromhex("38FFFFFF 00000000")),
    ]


def test_one_plant_step_per_sync(rig):
    for _ in range(3):
        rig.sync()
    rig.nmt(0x01)
    for _ in range(7):
        rig.sync()
    stats = rig.pair.stats
    assert stats.syncs == 10
    assert stats.plant_steps == 11  # + the power-on step
    assert rig.pair.plant.t_s == pytest.approx(11 * T_S)
    assert stats.tpdos_sent == 7 * 4


def test_enable_path_statuswords(rig):
    rig.nmt(0x01)
    words = [status(rig.sync_by_id(), 1)]
    for cw in (0x06, 0x07, 0x0F):
        frames = rig.cycle((cw, 0x00))
        words.append(status(frames, 1))
    words.append(status(rig.cycle((0x0F, 0x00)), 1))
    # the TPDO at a SYNC shows the state before that SYNC's RPDO is applied
    assert words == [SW_SOD, SW_SOD, SW_READY, SW_SWITCHED_ON, SW_OE]
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.DISABLED  # no mode of operation yet
    assert rig.pair.nodes[1].statusword == SW_SOD
    # CSP by the event RPDO2: applied on reception, visible at once by SDO
    assert rig.send(rpdo2(1, 8)) == []
    assert rig.read(1, 0x6061, 0, "b") == 8
    rig.cycle((0x0F, 0x00))
    assert status(rig.cycle((0x0F, 0x00)), 1) == SW_OE_CSP_REACHED
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.POSITION
    assert rig.pair.stats.illegal_commands == 0


def test_synchronous_rpdo_is_latched_until_sync_and_late_ones_counted(rig):
    rig.nmt(0x01)
    rig.send(rpdo1(1, 0x06, 0, 0))
    assert rig.read(1, 0x6041, 0, "H") == SW_SOD  # not applied before the SYNC
    rig.send(rpdo1(1, 0x06, 0, 0))  # a second one before the SYNC
    rig.sync()
    assert rig.read(1, 0x6041, 0, "H") == SW_READY
    assert rig.pair.stats.rpdos_late == 1 and rig.pair.stats.rpdos_applied == 1


def test_rpdo_ignored_unless_operational(rig):
    rig.send(rpdo1(1, 0x06, 0, 0))
    rig.sync()
    assert rig.pair.nodes[0].statusword == SW_SOD
    assert rig.pair.stats.rpdos_dropped == 1 and rig.pair.stats.rpdos_applied == 0


def test_rpdo_with_wrong_length_sends_emcy_and_is_not_applied(rig):
    rig.nmt(0x01)
    frames = rig.send(Frame(0x201, b"\x06\x00\x00"))
    assert frames == [Frame(0x081, bytes.fromhex("1082 11 0000000000"))]
    assert rig.read(1, 0x1001, 0, "B") == 0x11
    rig.sync()
    assert status(rig.sync_by_id(), 1) == SW_SOD  # not applied
    assert rig.send(Frame(0x201, b"\x06\x00")) == []  # error still active: no second EMCY
    # a correct RPDO resets the error
    assert rig.send(rpdo1(1, 0x06, 0, 0)) == [Frame(0x081, bytes(8))]
    rig.sync()
    assert rig.pair.nodes[0].statusword == SW_READY
    assert rig.read(1, 0x1003, 1, "I") == 0x8210
    assert rig.pair.stats.rpdos_dropped == 2 and rig.pair.stats.emcys_sent == 2


def test_event_driven_tpdo(rig):
    # TPDO1 event driven (255) with an event timer of 100 ms
    rig.write(1, 0x1800, 1, "I", 0x8000_0181)
    rig.write(1, 0x1800, 2, "B", 255)
    rig.write(1, 0x1800, 5, "H", 100)
    rig.write(1, 0x1800, 1, "I", 0x181)
    out = rig.nmt(0x01)  # sent once on entering OPERATIONAL
    assert out == [Frame(0x181, bytes.fromhex("5002 00000000 00"))]
    assert 0x181 not in rig.sync_by_id()  # nothing changed
    rig.send(rpdo1(1, 0x06, 0, 0))
    frames = rig.sync()
    assert Frame(0x181, bytes.fromhex("3102 00000000 00")) in frames  # statusword changed at this SYNC
    assert rig.pair.tick(0.05) == []
    assert rig.pair.tick(0.1) == []
    assert rig.pair.tick(rig.t + 0.1) == [Frame(0x181, bytes.fromhex("3102 00000000 00"))]  # event timer


# ------------------------------------------------------------------ CiA 402 and the plant


def test_csp_target_moves_the_motor_angle(rig):
    rig.enable()
    target = round(0.5 * INC_PER_MM)  # 1638 increments = 0.5 mm of stroke
    for k in range(100):  # 50 ms ramp, then hold, 0.2 s in all
        p = round(target * min(1.0, (k + 1) / 25))
        frames = rig.cycle((0x0F, 0x0F), (p, p))
    for node in (1, 2):
        assert abs(position(frames, node) - target) <= 3
        assert status(frames, node) == SW_OE_CSP_REACHED
    phi = rig.pair.plant.state().phi_rad
    assert phi == pytest.approx((target * 2 * math.pi / 4096,) * 2, abs=0.005)  # 3 increments
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(target * 2 * math.pi / 4096)


def test_cst_force_follows_torque_against_csp_drive(rig):
    rig.enable(mode1=10, mode2=8)
    assert rig.read(1, 0x6061, 0, "b") == 10
    f1, f2 = [], []
    for k in range(1000):  # torque ramp over 0.5 s to 100 per mille, hold 1.5 s
        frames = rig.cycle((0x0F, 0x0F), torque=(round(100 * min(1.0, k / 250)), 0))
        f1.append(tpdo2(frames[0x281])[1] / 10)
        f2.append(tpdo2(frames[0x282])[1] / 10)
    f_cmd = permille_to_force_N(100, I_TOTAL, 1.0)  # 502.65 N
    assert f_cmd == pytest.approx(502.6548, abs=1e-3)
    # the FORCE-mode EMA rings lightly damped (plant docs): compare the mean over 0.8 s
    assert np.mean(f1[-400:]) == pytest.approx(f_cmd, rel=0.02)
    assert np.mean(f2[-400:]) == pytest.approx(-f_cmd, rel=0.02)
    assert rig.read(1, 0x6077, 0, "h") == 100  # torque actual in per mille
    sp = rig.pair.nodes[0].setpoint
    assert sp.mode is DriveMode.FORCE and sp.value == pytest.approx(f_cmd)
    # torque saturation at 0x6072 (bit 11)
    rig.write(1, 0x6072, 0, "H", 50)
    rig.cycle((0x0F, 0x0F), torque=(100, 0))
    frames = rig.cycle((0x0F, 0x0F), torque=(100, 0))
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(f_cmd / 2)
    assert status(frames, 1) & 0x0800


def test_software_position_limit_clips_target_and_sets_bit_11(rig):
    rig.write(1, 0x607D, 2, "i", 800)
    rig.enable()
    for _ in range(150):
        frames = rig.cycle((0x0F, 0x0F), (2000, 0))
    sw = status(frames, 1)
    assert sw & 0x0800 and sw & 0x0400  # internal limit active, target (clipped) reached
    assert abs(position(frames, 1) - 800) <= TARGET_WINDOW_INC
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(800 * 2 * math.pi / 4096)
    rig.cycle((0x0F, 0x0F), (700, 0))
    frames = rig.cycle((0x0F, 0x0F), (700, 0))
    assert not status(frames, 1) & 0x0800


def test_quick_stop_holds_then_switch_on_disabled(rig):
    rig.enable()
    target = round(0.2 * INC_PER_MM)
    for k in range(50):
        rig.cycle((0x0F, 0x0F), (round(target * min(1.0, (k + 1) / 25)),) * 2)
    phi_before = rig.pair.sample.phi1_rad
    frames = rig.cycle((0x02, 0x0F), (target, target))  # quick stop applied at this SYNC
    assert decode_state(status(frames, 1)) is State.OPERATION_ENABLED
    node = rig.pair.nodes[0]
    assert node.setpoint.mode is DriveMode.POSITION and node.setpoint.value == phi_before
    words = []
    for _ in range(40):
        words.append(status(rig.cycle((0x02, 0x0F), (target, target)), 1))
    hold_cycles = round(QUICK_STOP_HOLD_S / T_S)  # 25
    assert words[:hold_cycles] == [SW_QSA] * hold_cycles
    assert words[hold_cycles:] == [SW_SOD] * (40 - hold_cycles)
    assert node.setpoint.mode is DriveMode.DISABLED
    assert rig.pair.nodes[1].setpoint.mode is DriveMode.POSITION
    assert rig.pair.stats.illegal_commands == 0  # a held quick stop word is a no-op in SOD


def test_illegal_command_leaves_state_unchanged(rig):
    rig.nmt(0x01)
    frames = rig.cycle((0x0F, 0x00))  # enable operation in SWITCH_ON_DISABLED
    frames = rig.cycle((0x0F, 0x00))
    assert status(frames, 1) == SW_SOD
    assert rig.pair.stats.illegal_commands == 2  # the word was applied at both SYNCs
    assert not any(0x81 <= cob <= 0x82 for cob in frames)  # no EMCY
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.DISABLED


def test_unsupported_mode_by_rpdo_disables_the_drive(rig):
    rig.enable()
    rig.send(rpdo2(1, 1))  # profile position: not supported
    rig.cycle((0x0F, 0x0F))
    frames = rig.cycle((0x0F, 0x0F))
    assert status(frames, 1) == SW_OE  # bit 12 clear, display unchanged
    assert tpdo1(frames[0x181])[2] == 8
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.DISABLED


def test_injected_fault_emcy_and_fault_reset(rig):
    rig.enable()
    assert error_register_bits(0x2310) == 0x03
    out = rig.pair.inject_fault(0, 0x2310)
    assert out == [Frame(0x081, bytes.fromhex("1023 03 0000000000"))]
    assert status(rig.cycle((0x0F, 0x0F)), 1) == SW_FRA
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.DISABLED
    assert status(rig.cycle((0x0F, 0x0F)), 1) == SW_FAULT
    assert rig.read(1, 0x603F, 0, "H") == 0x2310
    assert rig.read(1, 0x1001, 0, "B") == 0x03
    assert rig.read(1, 0x1003, 0, "B") == 1 and rig.read(1, 0x1003, 1, "I") == 0x2310
    frames = rig.sync()  # controlword 0x0F repeated in FAULT: illegal, counted
    assert rig.pair.stats.illegal_commands >= 1
    frames = rig.send(rpdo1(1, 0x80, 0, 0))
    frames = rig.sync()
    assert Frame(0x081, bytes(8)) in frames  # EMCY "no error" on the fault reset
    assert status(rig.sync_by_id(), 1) == SW_SOD
    assert rig.read(1, 0x1001, 0, "B") == 0 and rig.read(1, 0x603F, 0, "H") == 0
    rig.write(1, 0x1003, 0, "B", 0)  # clear the error history
    assert rig.read(1, 0x1003, 0, "B") == 0
    assert rig.pair.nodes[1].statusword == SW_OE_CSP_REACHED


# ------------------------------------------------------------------ the whole loop


def test_round_trip_master_configures_enables_and_follows_a_csp_ramp(rig):
    pair = rig.pair
    nodes = (1, 2)
    plan = shipped_rig().plan
    for n, name in zip(nodes, ("ema1", "ema2"), strict=True):
        layout = plan.node(name).layout
        writes = layout.configuration_writes()
        # per PDO: disable, clear, count, type, enable + entries; plus the unused PDOs disabled
        assert len(writes) == 4 * 5 + 9 + len(layout.disable)
        for w in writes:
            rig.sdo(n, w.index, w.subindex, w.data)
    assert rig.nmt(0x01) == []
    for n in nodes:
        rig.send(rpdo2(n, 8))

    end_inc = round(0.2 * INC_PER_MM)  # ramp 0 -> 0.2 mm (655 increments) in 1 s
    state = {n: State.SWITCH_ON_DISABLED for n in nodes}
    cw = {n: 0 for n in nodes}
    target = {n: 0 for n in nodes}
    applied = None  # targets sent before the previous SYNC: the plant state now reflects them
    ramp_start = None
    errors = {n: [] for n in nodes}
    for k in range(600):
        if ramp_start is None and all(s is State.OPERATION_ENABLED for s in state.values()):
            ramp_start = k
        for n in nodes:
            cmd = next_command(state[n], State.OPERATION_ENABLED)
            if cmd is not None:
                cw[n] = controlword(cmd)
            if ramp_start is not None:
                target[n] = round(end_inc * min(1.0, (k - ramp_start) * T_S))
            rig.send(rpdo1(n, cw[n], target[n], 0))
        frames = rig.sync_by_id()
        for n in nodes:
            sw, pos, _ = tpdo1(frames[0x180 + n])
            state[n] = decode_state(sw)
            if applied is not None:
                errors[n].append(pos - applied[n])
        applied = dict(target) if ramp_start is not None else None

    # 3 steps x 2 SYNCs: the TPDO at SYNC k shows the state before SYNC k applied the
    # controlword, so the master repeats each word once (a no-op) before it sees the new state
    assert ramp_start == 6
    for n in nodes:
        assert len(errors[n]) == 600 - ramp_start - 1
        assert max(abs(e) for e in errors[n]) <= 4  # measured: 2 increments (0.6 um)
        assert position(frames, n) == pytest.approx(end_inc, abs=3)
        assert status(frames, n) == SW_OE_CSP_REACHED
    # LVDT of EMA 1 (0.3 mm + 1.075 s) follows the stroke within the backlash
    assert tpdo2(frames[0x281])[0] / 1000 == pytest.approx(0.3 + 1.075 * 0.2, abs=0.1)
    stats = pair.stats
    assert stats.syncs == 600 and stats.plant_steps == 601
    assert stats.rpdos_late == 0 and stats.rpdos_dropped == 0 and stats.illegal_commands == 0
    assert stats.tpdos_sent == 600 * 4


def test_sdo_protocol_errors_are_aborted(rig):
    def abort_of(request: bytes) -> tuple[int, int, int]:
        out = rig.send(Frame(0x601, request))
        assert len(out) == 1 and out[0].arbitration_id == 0x581 and out[0].data[0] == 0x80
        return struct.unpack_from("<HBI", out[0].data, 1)

    # upload segment request without a segmented upload in progress
    assert abort_of(bytes([0x60, 0, 0, 0, 0, 0, 0, 0]))[2] == SdoAbortCode.COMMAND_SPECIFIER_INVALID
    # block download initiate: not supported
    assert abort_of(bytes([0xC6, 0x17, 0x10, 0x00, 2, 0, 0, 0])) == \
        (0x1017, 0, SdoAbortCode.COMMAND_SPECIFIER_INVALID)
    # segmented download: a segment with the wrong toggle bit
    assert rig.send(Frame(0x601, bytes([0x21, 0x17, 0x10, 0x00, 2, 0, 0, 0]))) == \
        [Frame(0x581, bytes([0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0]))]
    assert abort_of(bytes([0x1B, 0x64, 0x00, 0, 0, 0, 0, 0]))[2] == SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED
    assert rig.read(1, 0x1017, 0, "H") == 0
    # a segmented download of 2 bytes works
    assert rig.send(Frame(0x601, bytes([0x21, 0x17, 0x10, 0x00, 2, 0, 0, 0])))[0].data[0] == 0x60
    assert rig.send(Frame(0x601, bytes([0x0B, 0x64, 0x00, 0, 0, 0, 0, 0]))) == \
        [Frame(0x581, bytes([0x20, 0, 0, 0, 0, 0, 0, 0]))]
    assert rig.read(1, 0x1017, 0, "H") == 100


def test_random_frames_never_raise_and_the_pair_recovers(rig):
    rnd = np.random.default_rng(7)
    cobs = [0x000, 0x080, 0x081, 0x181, 0x201, 0x202, 0x301, 0x302, 0x601, 0x602, 0x123, 0x701]
    rig.nmt(0x01)
    for _ in range(3000):
        rig.t += 0.001
        cob = int(rnd.choice(cobs))
        data = bytes(rnd.integers(0, 256, size=int(rnd.integers(0, 9)), dtype=np.uint8))
        if cob == 0x000:
            data = bytes([int(rnd.choice([0x01, 0x01, 0x02, 0x80, 0x82, 0x7])), int(rnd.integers(0, 3))])
        elif cob == 0x080:
            data = data[:int(rnd.integers(0, 2))]
        elif cob in (0x601, 0x602) and rnd.random() < 0.9:  # 8 bytes with an existing index
            index = int(rnd.choice([0x1003, 0x1008, 0x1017, 0x1400, 0x1600, 0x1801, 0x1A01, 0x6040,
                                    0x6060, 0x607D, 0x6076]))
            data = bytes([data[0] if data else 0]) + struct.pack("<HB", index, int(rnd.integers(0, 4))) + \
                bytes(rnd.integers(0, 256, size=4, dtype=np.uint8))
        for frame in rig.send(Frame(cob, data)) + rig.pair.tick(rig.t):
            assert isinstance(frame, Frame)
    assert rig.pair.stats.sdo_requests > 100 and rig.pair.stats.syncs > 100
    # afterwards the drives still answer and can be reset to a known state
    assert rig.nmt(0x81) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00")]
    assert rig.read(1, 0x1018, 1, "I") == 0x0E3A
    rig.nmt(0x01)
    assert rig.sync_by_id()[0x181].data[:2] == bytes.fromhex("5002")


# ------------------------------------------------------------------ input validation


def test_constructor_and_call_validation(pair):
    plant = pair.plant
    rig = shipped_rig()
    with pytest.raises(CanopenInputError, match="plant"):
        SimDrivePair("plant", rig.plan, od_factory(rig))
    with pytest.raises(CanopenInputError, match="plan"):
        SimDrivePair(plant, "plan", od_factory(rig))
    with pytest.raises(CanopenInputError, match="od_factory"):
        SimDrivePair(plant, rig.plan, "profiles/ema_drive.eds")
    with pytest.raises(CanopenInputError, match=r"od_factory\('ema1', 1\) must return"):
        SimDrivePair(plant, rig.plan, lambda name, node_id: None)
    with pytest.raises(CanopenInputError, match="counts_per_rev"):
        make_pair(plant, counts_per_rev=0)
    with pytest.raises(CanopenInputError, match="frame"):
        pair.on_frame(b"\x01\x00", 0.0)
    with pytest.raises(CanopenInputError, match="t ="):
        pair.tick(float("nan"))
    with pytest.raises(CanopenInputError, match="power_on"):
        pair.inject_fault(0, 0x2310)
    pair.power_on(0.0)
    with pytest.raises(CanopenInputError, match="emcy_code"):
        pair.inject_fault(1, 0)
    with pytest.raises(CanopenInputError, match="node_index"):
        pair.inject_fault(2, 0x2310)


def test_node_ids_of_the_profile_and_counts_per_rev_option(tmp_path):
    path = write_profile_variant("actuation.toml", tmp_path / "actuation.toml",
                                 {"canopen": {"node_id_ema1": 5, "node_id_ema2": 9}})
    rig5 = plan_for(load_actuation(path), path)
    plant = RigPlant(make_params(), np.random.default_rng(0))
    pair = make_pair(plant, rig5, counts_per_rev=8192)
    rig = Rig(pair)
    assert pair.power_on(0.0) == [Frame(0x705, b"\x00"), Frame(0x709, b"\x00")]
    assert rig.read(9, 0x608F, 1, "I") == 8192
    assert rig.read(9, 0x1400, 1, "I") == 0x209
    rig.nmt(0x01)
    frames = rig.sync_by_id()
    assert set(frames) == {0x185, 0x285, 0x189, 0x289}
    assert pair.nodes[1].ema_index == 1 and pair.nodes[1].node_id == 9


# ------------------------------------------------------------------ cached values stay in step with the OD


def test_emcy_cob_id_written_by_sdo_takes_effect(rig):
    # the write check of 0x1014 reads the old value: the new one must still win
    rig.write(1, 0x1014, 0, "I", 0x8000_0081)  # EMCY of node 1 not sent
    assert rig.read(1, 0x1014, 0, "I") == 0x8000_0081
    assert rig.pair.inject_fault(0, 0x2310) == []
    assert rig.pair.inject_fault(1, 0x2310) == [Frame(0x082, bytes.fromhex("1023 03 0000000000"))]
    assert rig.pair.stats.emcys_sent == 1
    rig.write(1, 0x1014, 0, "I", 0x0000_0095)  # valid again, on another CAN-ID
    rig.nmt(0x01)
    # PDO length error: error register = fault bits 0x03 | communication 0x11
    assert rig.send(Frame(0x201, b"\x06")) == [Frame(0x095, bytes.fromhex("1082 13 0000000000"))]


def test_counts_per_rev_written_by_sdo_rescales_position_and_target_at_once(rig):
    rig.enable()
    for k in range(100):  # 50 ms ramp to 1024 increments (a quarter turn), then hold
        p = round(1024 * min(1.0, (k + 1) / 25))
        rig.cycle((0x0F, 0x0F), (p, p))
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(1024 * 2 * math.pi / 4096, rel=1e-12)
    rig.write(1, 0x608F, 1, "I", 8192)  # node 1 only
    phi1, phi2 = rig.pair.sample.phi1_rad, rig.pair.sample.phi2_rad
    assert rig.pair.nodes[0].position_inc == round(phi1 * 8192 / (2 * math.pi))
    frames = rig.cycle((0x0F, 0x0F), (1024, 1024))
    assert position(frames, 1) == round(phi1 * 8192 / (2 * math.pi))  # the sample of this SYNC
    assert position(frames, 2) == round(phi2 * 4096 / (2 * math.pi))
    assert abs(position(frames, 1) - 2048) <= 2 * TARGET_WINDOW_INC  # at the target, twice the counts
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(1024 * 2 * math.pi / 8192, rel=1e-12)
    assert rig.pair.nodes[1].setpoint.value == pytest.approx(1024 * 2 * math.pi / 4096, rel=1e-12)
    rig.write(1, 0x608F, 2, "I", 2)  # 4096 increments per revolution again
    rig.cycle((0x0F, 0x0F), (1024, 1024))
    assert rig.pair.nodes[0].setpoint.value == pytest.approx(1024 * 2 * math.pi / 4096, rel=1e-12)


def test_repeated_controlword_counts_as_illegal_in_every_state_that_refuses_it(rig):
    rig.enable()
    for _ in range(5):  # 0x0F repeated in OPERATION_ENABLED: no-op
        rig.cycle((0x0F, 0x0F))
    assert rig.pair.stats.illegal_commands == 0
    rig.pair.inject_fault(0, 0x8611)
    counts = []
    for _ in range(4):  # the same word in FAULT_REACTION_ACTIVE, then FAULT: refused every cycle
        assert status(rig.cycle((0x0F, 0x0F)), 2) == SW_OE_CSP_REACHED
        counts.append(rig.pair.stats.illegal_commands)
    assert counts == [1, 2, 3, 4]
    for cw in (0x00, 0x80, 0x06, 0x07, 0x0F, 0x0F, 0x0F):  # fault reset and enable again
        rig.cycle((cw, 0x0F))
    assert rig.pair.nodes[0].state_machine.state is State.OPERATION_ENABLED
    assert rig.pair.stats.illegal_commands == 5  # + disable voltage (0x00) refused in FAULT


def test_tpdo_with_a_stored_object_and_an_event_rpdo_with_two_side_effects(rig):
    # TPDO2 of node 1: max torque 0x6072 (a stored object), statusword, position
    rig.write(1, 0x1801, 1, "I", 0x8000_0281)
    rig.write(1, 0x1A01, 0, "B", 0)
    for k, entry in enumerate((0x60720010, 0x60410010, 0x60640020), start=1):
        rig.write(1, 0x1A01, k, "I", entry)
    rig.write(1, 0x1A01, 0, "B", 3)
    rig.write(1, 0x1801, 1, "I", 0x281)
    # RPDO2 of node 1 (event driven): modes of operation, then controlword
    rig.write(1, 0x1401, 1, "I", 0x8000_0301)
    rig.write(1, 0x1601, 0, "B", 0)
    rig.write(1, 0x1601, 1, "I", 0x60600008)
    rig.write(1, 0x1601, 2, "I", 0x60400010)
    rig.write(1, 0x1601, 0, "B", 2)
    rig.write(1, 0x1401, 1, "I", 0x301)
    rig.nmt(0x01)
    assert rig.sync_by_id()[0x281].data == bytes.fromhex("1027 5002 00000000")  # 10000 per mille, SOD
    rig.write(1, 0x6072, 0, "H", 500)
    assert rig.send(Frame(0x301, bytes.fromhex("08 0600"))) == []  # applied on reception
    assert rig.read(1, 0x6061, 0, "b") == 8 and rig.read(1, 0x6041, 0, "H") == SW_READY
    assert rig.sync_by_id()[0x281].data == bytes.fromhex("F401 3102 00000000")
    assert rig.pair.stats.rpdos_applied == 1


# ------------------------------------------------------------------ the master's death: consumer, 0x6007


MASTER = 0x7F  # the master's node id: its heartbeat is 0x77F
HB_EMCY = Frame(0x081, bytes.fromhex("3081 11 0000000000"))  # 0x8130 heartbeat error, register 0x11


def _watch_master(rig: Rig, node: int, consumer_ms: int, option: int) -> None:
    """Node ``node`` consumes the master's heartbeat (0x1016:01) and reacts with ``option`` (0x6007)."""
    rig.write(node, 0x1016, 1, "I", MASTER << 16 | consumer_ms)
    rig.write(node, 0x6007, 0, "h", option)
    assert rig.read(node, 0x1016, 1, "I") == 0x007F0000 | consumer_ms
    assert rig.read(node, 0x6007, 0, "h") == option


def test_heartbeat_consumer_and_abort_connection_entries_are_validated(rig):
    assert rig.read(1, 0x1016, 0, "B") == 4  # four consumer entries
    assert rig.read(1, 0x6007, 0, "h") == 1  # CiA 402 default: fault signal
    for bad in (0x01_7F_0064, 0x00_80_0064):  # reserved bits 24..31, node id 128
        with pytest.raises(SdoAbortError) as exc:
            rig.write(1, 0x1016, 1, "I", bad)
        assert exc.value.code is SdoAbortCode.VALUE_RANGE_EXCEEDED
    rig.write(1, 0x1016, 1, "I", 0x7F_0064)
    with pytest.raises(SdoAbortError) as exc:  # one entry per producer
        rig.write(1, 0x1016, 2, "I", 0x7F_00C8)
    assert exc.value.code is SdoAbortCode.PARAMETER_INCOMPATIBILITY
    rig.write(1, 0x1016, 2, "I", 0x7F_0000)  # time 0: unused, allowed
    rig.write(1, 0x1016, 3, "I", 0x05_0064)
    assert rig.pair.nodes[0].heartbeat_consumers == {0x7F: [0.1, None, False], 5: [0.1, None, False]}
    with pytest.raises(SdoAbortError) as exc:
        rig.write(1, 0x1016, 0, "B", 2)
    assert exc.value.code is SdoAbortCode.WRITE_OF_READ_ONLY
    for bad in (4, -1):
        with pytest.raises(SdoAbortError) as exc:
            rig.write(1, 0x6007, 0, "h", bad)
        assert exc.value.code is SdoAbortCode.VALUE_RANGE_EXCEEDED
    rig.nmt(0x81, 1)  # reset node: the consumer is off again (EDS default 0)
    assert rig.read(1, 0x1016, 1, "I") == 0 and rig.pair.nodes[0].heartbeat_consumers == {}


def test_hung_master_heartbeat_event_quick_stop_then_switch_on_disabled(rig):
    """SYNC goes on (a kernel-timed SYNC outlives a hung master), the master's heartbeat stops:
    EMCY 0x8130 at the first tick past the consumer time, quick stop (0x6007 = 3), the hold,
    then switch on disabled; the other drive (no consumer) is untouched."""
    _watch_master(rig, 1, 100, 3)
    rig.enable()
    pair, node = rig.pair, rig.pair.nodes[0]
    t_hb = rig.t
    assert rig.send(Frame(0x77F, b"\x05")) == []  # the master's last heartbeat: monitoring starts
    words, event_t = [], None
    for _ in range(100):
        out = pair.tick(rig.t + T_S)
        if HB_EMCY in out:
            event_t = rig.t + T_S
        words.append(status(rig.sync_by_id(), 1))
    assert event_t == pytest.approx(t_hb + 0.1 + T_S)  # first tick with more than 100 ms since it
    assert node.heartbeat_events == [(pytest.approx(event_t), MASTER)]
    k = round((event_t - t_hb) / T_S) - 1  # the SYNC at the event's tick shows the quick stop
    hold = round(QUICK_STOP_HOLD_S / T_S)  # drive cycles of the hold: SYNCs k .. k + hold - 1
    assert words[:k] == [SW_OE_CSP_REACHED] * k
    # (QSA shows from SYNC k, before that SYNC's drive cycle, to SYNC k + hold, before the
    # cycle that ends the hold: switch on disabled 50 ms after the event)
    assert words[k:k + hold + 1] == [SW_QSA] * (hold + 1)
    assert set(words[k + hold + 1:]) == {SW_SOD}
    assert rig.read(1, 0x1001, 0, "B") == 0x11 and rig.read(1, 0x1003, 1, "I") == 0x8130
    assert rig.pair.nodes[1].statusword == SW_OE_CSP_REACHED
    # the master comes back: the event ends (EMCY 0x0000), the drive stays switch on disabled
    assert rig.send(Frame(0x77F, b"\x05")) == [Frame(0x081, bytes(8))]
    assert rig.read(1, 0x1001, 0, "B") == 0 and node.statusword == SW_SOD


@pytest.mark.parametrize("option,first,final", [
    (0, State.OPERATION_ENABLED, State.OPERATION_ENABLED),
    (1, State.FAULT, State.FAULT),  # (the fault reaction ends at the drive cycle of the event's step)
    (2, State.SWITCH_ON_DISABLED, State.SWITCH_ON_DISABLED),
    (3, State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED),
])
def test_dead_master_abort_connection_options_on_the_drives_own_clock(rig, option, first, final):
    """The master dies: no SYNC, no RPDO, no heartbeat. The drives' cycle runs on their own clock
    (from FREE_RUN_AFTER_CYCLES SYNC periods after the last SYNC, caught up from it), the
    consumer fires after its time and 0x6007 acts through the CiA 402 table."""
    for n in (1, 2):
        _watch_master(rig, n, 50, option)
    rig.enable()
    pair = rig.pair
    rig.send(Frame(0x77F, b"\x05"))
    t_last, steps0 = rig.t, pair.stats.plant_steps
    seen: list[float] = []
    pair.on_free_step = seen.append
    states, emcys = [], []
    for k in range(1, 60):
        t = t_last + k * T_S
        emcys += [(t, f) for f in pair.tick(t) if f.arbitration_id in (0x81, 0x82)]
        states.append(pair.nodes[0].state_machine.state)
    # own clock: nothing before 5 silent SYNC periods, then one step per period from the last SYNC
    assert seen[0] == pytest.approx(t_last + T_S) and np.allclose(np.diff(seen), T_S)
    assert pair.stats.plant_steps == steps0 and pair.stats.syncs == 3  # no SYNC-driven step
    t_event = t_last + 0.05 + T_S
    assert [round(t, 6) for t, _ in emcys] == [round(t_event, 6)] * 2
    assert {f.data[:2] for _, f in emcys} == {bytes.fromhex("3081")}
    assert states[round(0.05 / T_S)] is first  # at the event's tick
    assert states[-1] is final and pair.nodes[1].state_machine.state is final
    if final is State.OPERATION_ENABLED:
        assert len(seen) == 59  # option 0: the drives hold their command, the rig keeps moving
    else:  # every power stage off: the rig rests on its brakes, no more steps
        t_off = seen[-1]
        assert t_off <= t_event + QUICK_STOP_HOLD_S + 2 * T_S + 1e-9
        pair.tick(t_last + 0.2)
        assert seen[-1] == t_off
    if option == 1:
        assert rig.read(1, 0x603F, 0, "H") == 0x8130


def test_drive_cycle_on_its_own_clock_stops_at_the_next_sync(rig):
    rig.enable()
    pair = rig.pair
    t_last = rig.t
    assert pair.tick(t_last + 5 * T_S) == [] and pair.stats.free_steps == 0  # SYNC only late
    pair.tick(t_last + 6 * T_S + 1e-4)  # lost: caught up from the last SYNC
    assert pair.stats.free_steps == 6
    assert pair.plant.t_s == pytest.approx((pair.stats.plant_steps + 6) * T_S)
    rig.t = t_last + 6.2 * T_S
    # SYNC back 1.2 periods after the last own step (within half a period of the next: no own step
    # before it, hil.canopen.cycle.SyncSchedule's rule): TPDOs and one step as usual, no more own steps
    frames = rig.sync_by_id()
    assert decode_state(status(frames, 1)) is State.OPERATION_ENABLED
    pair.tick(rig.t + 4 * T_S)
    assert pair.stats.free_steps == 6


def test_serial_numbers_are_the_drives_own_data():
    """``serials`` are what 0x1018:04 reports, restored at power-on and after reset node."""
    pair = make_pair(RigPlant(make_params(), np.random.default_rng(0)), serials=(0x5E000101, 0x5E000102))
    pair.power_on(0.0)
    assert [n.read(0x1018, 4) for n in pair.nodes] == [0x5E000101, 0x5E000102]
    pair.on_frame(Frame(0x000, bytes([0x81, 0])), 0.01)  # NMT reset node, all nodes
    assert [n.read(0x1018, 4) for n in pair.nodes] == [0x5E000101, 0x5E000102]
    with pytest.raises(CanopenInputError, match="serials"):
        make_pair(RigPlant(make_params(), np.random.default_rng(0)), serials=(1,))


# ------------------------------------------------------------------ quick stop option code 0x605A


def _quick_stop_words(rig: Rig, option: int, n: int = 40) -> list[int]:
    """Drive 1 enabled, 0x605A = ``option``, quick stop at a SYNC; its statuswords over ``n`` SYNCs."""
    rig.write(1, 0x605A, 0, "h", option)
    rig.enable()
    for _ in range(5):
        rig.cycle((0x0F, 0x0F))
    rig.cycle((0x02, 0x0F))  # quick stop applied at this SYNC
    return [status(rig.cycle((0x02, 0x0F)), 1) for _ in range(n)]


@pytest.mark.parametrize("option", [1, 2, 3, 4])
def test_quick_stop_options_1_to_4_hold_then_switch_on_disabled(rig, option):
    hold = round(QUICK_STOP_HOLD_S / T_S)
    assert _quick_stop_words(rig, option) == [SW_QSA] * hold + [SW_SOD] * (40 - hold)


def test_quick_stop_option_0_disables_the_drive_at_once(rig):
    words = _quick_stop_words(rig, 0, 5)
    assert words == [SW_SOD] * 5  # switch on disabled in the drive cycle of the quick stop itself
    assert rig.pair.nodes[0].setpoint.mode is DriveMode.DISABLED


@pytest.mark.parametrize("option", [5, 6, 7, 8])
def test_quick_stop_options_5_to_8_stay_until_disable_voltage(rig, option):
    words = _quick_stop_words(rig, option, 100)  # 0.2 s, four times the hold
    assert words == [SW_QSA] * 100
    node = rig.pair.nodes[0]
    held = node.setpoint
    assert held.mode is DriveMode.POSITION  # holding the angle where the quick stop began
    rig.cycle((0x0F, 0x0F))  # enable operation: transition 16 (only with these option codes)
    assert node.state_machine.state is State.OPERATION_ENABLED and node.state_machine.last_transition == 16
    assert rig.pair.stats.illegal_commands == 0
    rig.cycle((0x02, 0x0F))  # quick stop again: it stays there
    assert node.state_machine.state is State.QUICK_STOP_ACTIVE
    rig.cycle((0x00, 0x0F))  # disable voltage: transition 12
    assert status(rig.cycle((0x00, 0x0F)), 1) == SW_SOD
    assert node.setpoint.mode is DriveMode.DISABLED


def test_quick_stop_option_values_are_validated_and_a_drive_without_605a_takes_2(rig):
    for bad in (9, -1):
        with pytest.raises(SdoAbortError) as exc:
            rig.write(1, 0x605A, 0, "h", bad)
        assert exc.value.code is SdoAbortCode.VALUE_RANGE_EXCEEDED
    assert rig.read(1, 0x605A, 0, "h") == 2  # the shipped EDS's default
    node = rig.pair.nodes[0]
    del node.store.object_dictionary[0x605A]  # a drive whose EDS has no 0x605A
    hold = round(QUICK_STOP_HOLD_S / T_S)
    rig.enable()
    rig.cycle((0x02, 0x0F))
    words = [status(rig.cycle((0x02, 0x0F)), 1) for _ in range(hold + 3)]
    assert words == [SW_QSA] * hold + [SW_SOD] * 3


# ------------------------------------------------------------------ NMT slave pinned by mutation (issue 26)
# sim/drives/nmt_slave.py: what its objects' absence, defaults and rewrites do, each observed at the
# pair's frames and by SDO. Node 1 of _custom_pair gets an edited object dictionary (an EDS of
# another vendor: optional objects present or absent, consumer and producer set by default).

HB_EMCY_DATA = bytes.fromhex("3081 11 0000000000")  # EMCY 0x8130, error register bits 0 and 4


def _add(od, name: str, index: int, data_type: int, default: int) -> None:
    import canopen.objectdictionary as cod

    var = cod.ODVariable(name, index, 0)
    var.data_type, var.access_type, var.default = data_type, "rw", default
    od.add_object(var)


def _custom_pair(edit) -> SimDrivePair:
    """The shipped pair with node 1's object dictionary edited by ``edit(od)`` (not powered on)."""
    rig = shipped_rig()
    factory = od_factory(rig)

    def make(name, node_id):
        od = factory(name, node_id)
        if node_id == 1:
            edit(od)
        return od

    return SimDrivePair(RigPlant(make_params(), np.random.default_rng(0)), rig.plan, make)


def _abort_code(rig: Rig, node: int, index: int, sub: int, fmt: str, value: int):
    with pytest.raises(SdoAbortError) as exc:
        rig.write(node, index, sub, fmt, value)
    return exc.value.code


def test_before_power_on_nodes_are_initialising_without_errors(pair):
    assert [n.nmt_state for n in pair.nodes] == [NmtState.INITIALISING] * 2
    assert [n.error_register for n in pair.nodes] == [0, 0]


def test_an_eds_with_a_default_producer_and_consumer_and_without_0x1014():
    """0x1017 = 100 ms and 0x1016:01 = master 0x7F, 100 ms by default, no EMCY COB-ID object (EMCY
    on 0x80 + node id) and no SYNC COB-ID object (SYNC on 0x80): the heartbeat runs from power-on and
    from each reset, the consumer watches the master from its first heartbeat, without a write."""
    def edit(od):
        od[0x1017].default = 100
        od[0x1016][1].default = 0x7F_0064
        del od[0x1014]
        del od[0x1005]
    pair = _custom_pair(edit)
    assert pair.power_on(0.5) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00")]
    assert pair.tick(0.55) == []
    assert pair.tick(0.6) == [Frame(0x701, b"\x7f")]
    assert pair.on_frame(Frame(0x77F, b"\x05"), 0.6) == []
    out = pair.tick(0.7 + 2e-9)
    assert Frame(0x081, HB_EMCY_DATA) in out and pair.nodes[0].heartbeat_events == [(0.7 + 2e-9, 0x7F)]
    assert pair.nodes[0].error_register & 0x11 == 0x11
    rig = Rig(pair)
    rig.t = 0.75
    assert rig.nmt(0x82, 1) == [Frame(0x701, b"\x00")]  # reset communication: the schedule restarts
    assert pair.nodes[0].nmt_state is NmtState.PRE_OPERATIONAL
    assert pair.tick(0.8) == [] and pair.tick(0.85) == [Frame(0x701, b"\x7f")]
    rig.t = 0.9
    assert rig.nmt(0x81, 1) == [Frame(0x701, b"\x00")]  # reset node: the same
    assert pair.tick(0.95) == [] and pair.tick(1.0) == [Frame(0x701, b"\x7f")]
    assert pair.tick(2.0) == [Frame(0x701, b"\x7f")]  # the consumer waits for the master again
    assert pair.nodes[0].heartbeat_events == [(0.7 + 2e-9, 0x7F)]
    rig.t = 2.0
    rig.nmt(0x01)
    assert 0x181 in rig.sync_by_id()


def test_an_eds_without_0x1016():
    pair = _custom_pair(lambda od: od.__delitem__(0x1016))
    pair.power_on(0.0)
    rig = Rig(pair)
    rig.write(1, 0x1017, 0, "H", 100)  # the producer works without a consumer object
    before = pair.stats.bad_frames_ignored
    assert pair.on_frame(Frame(0x77F, b"\x05"), 0.0) == []  # nobody consumes the master's heartbeat
    assert pair.stats.bad_frames_ignored == before + 1
    assert pair.tick(0.1) == [Frame(0x701, b"\x7f")] and pair.tick(5.0) == [Frame(0x701, b"\x7f")]
    assert pair.nodes[0].heartbeat_events == []


def test_an_eds_without_0x1017():
    pair = _custom_pair(lambda od: od.__delitem__(0x1017))
    pair.power_on(0.0)
    assert pair.tick(0.001) == [] and pair.tick(1.0) == []  # no producer time: no heartbeat


def test_after_boot_at_power_on_and_reset_node_not_at_reset_communication(rig):
    """A drive that boots into FAULT says so by EMCY after its boot-up frame: at reset node (the
    application restarts), not at reset communication (it keeps its state)."""
    rig.pair.nodes[0].boot_fault = 0x5000
    emcy = Frame(0x081, bytes.fromhex("0050 01 0000000000"))
    assert rig.nmt(0x81, 1) == [Frame(0x701, b"\x00"), emcy]
    assert rig.pair.nodes[0].state_machine.state is State.FAULT
    assert rig.nmt(0x82, 1) == [Frame(0x701, b"\x00")]
    assert rig.pair.nodes[0].state_machine.state is State.FAULT


def test_the_consumer_entries_read_are_the_ones_sub_index_0_counts_and_the_ones_present():
    def count_1(od):  # entry 2 beyond the count: not an entry
        od[0x1016][0].default = 1
        od[0x1016][2].default = 0x7F_0064
    pair = _custom_pair(count_1)
    pair.power_on(0.0)
    pair.on_frame(Frame(0x77F, b"\x05"), 0.0)
    assert pair.tick(1.0) == [] and pair.nodes[0].heartbeat_events == []
    rig = Rig(pair)
    rig.write(1, 0x1016, 1, "I", 0x7F_00C8)  # entry 2 is no entry: no duplicate

    def no_entry_1(od):  # entry 1 absent, entry 2 watches the master
        del od[0x1016].subindices[1]
        od[0x1016][2].default = 0x7F_0064
    pair = _custom_pair(no_entry_1)
    pair.power_on(0.0)
    pair.on_frame(Frame(0x77F, b"\x05"), 0.0)
    assert Frame(0x081, HB_EMCY_DATA) in pair.tick(0.2) and pair.nodes[0].heartbeat_events == [(0.2, 0x7F)]


def test_heartbeats_of_a_producer_nobody_consumes_are_counted_as_ignored(rig):
    before = rig.pair.stats.bad_frames_ignored
    assert rig.send(Frame(0x77F, b"\x05")) == []
    assert rig.pair.stats.bad_frames_ignored == before + 1
    rig.write(1, 0x1016, 1, "I", 0x7F_0064)
    assert rig.send(Frame(0x77F, b"\x05")) == []
    assert rig.pair.stats.bad_frames_ignored == before + 1  # consumed by node 1


def test_a_consumer_in_a_later_entry_and_rewrites_of_other_entries_keep_the_monitoring(rig):
    rig.write(1, 0x1016, 3, "I", 0x7F_0064)  # entries 1 and 2 unused
    rig.send(Frame(0x77F, b"\x05"))  # t = 0: monitoring starts
    rig.t = 0.05
    rig.write(1, 0x1016, 2, "I", 0x05_0064)  # another producer: entry 3 keeps its last heartbeat
    rig.write(1, 0x1016, 3, "I", 0x7F_0064)  # the same value again: unchanged
    out = rig.pair.tick(0.1 + 2e-9)
    assert Frame(0x081, HB_EMCY_DATA) in out and rig.pair.nodes[0].heartbeat_events == [(0.1 + 2e-9, 0x7F)]


def test_a_changed_consumer_time_waits_for_the_producer_again(rig):
    rig.write(1, 0x1016, 1, "I", 0x7F_0064)
    rig.send(Frame(0x77F, b"\x05"))
    rig.write(1, 0x1016, 1, "I", 0x7F_00C8)  # 200 ms: a new entry
    assert rig.pair.tick(1.0) == [] and rig.pair.nodes[0].heartbeat_events == []


def test_consumer_entries_one_per_producer_in_any_entry(rig):
    rig.write(1, 0x1016, 2, "I", 0x7F_0000)  # time 0: unused, does not count
    rig.write(1, 0x1016, 1, "I", 0x7F_0064)
    rig.write(1, 0x1016, 1, "I", 0x7F_00C8)  # its own entry rewritten
    rig.write(1, 0x1016, 2, "I", 0x7E_0000)
    for used, other in ((2, 1), (3, 1), (4, 1), (4, 3)):
        for k in (1, 2, 3, 4):
            rig.write(1, 0x1016, k, "I", 0)
        rig.write(1, 0x1016, used, "I", 0x7F_0064)
        assert _abort_code(rig, 1, 0x1016, other, "I", 0x7F_00C8) is SdoAbortCode.PARAMETER_INCOMPATIBILITY, \
            (used, other)
        rig.write(1, 0x1016, other, "I", 0x7E_00C8)  # another producer: fine


def _optional_comm_objects(od):
    _add(od, "Inhibit time EMCY", 0x1015, 0x0006, 0)


def test_sync_cob_id_0x1005_written_and_refused():
    pair = _custom_pair(_optional_comm_objects)
    rig = Rig(pair)
    pair.power_on(0.0)
    rig.nmt(0x01)
    assert 0x181 in rig.sync_by_id()
    for bad in (0x4000_0080, 0x2000_0080, 0x1000_0080, 0x0000_0880, 0x6000_0080):
        assert _abort_code(rig, 1, 0x1005, 0, "I", bad) is SdoAbortCode.VALUE_RANGE_EXCEEDED, hex(bad)
    rig.write(1, 0x1005, 0, "I", 0x8000_0085)  # bit 31 is "don't care"
    rig.write(1, 0x1006, 0, "I", 2000)  # 0x1006 is not checked as a COB-ID
    rig.write(1, 0x1015, 0, "H", 10)  # nor 0x1015
    assert rig.read(1, 0x1005, 0, "I") == 0x8000_0085
    rig.t += T_S
    by_id = {f.arbitration_id: f for f in rig.send(Frame(0x085, b""))}
    assert 0x181 in by_id and 0x182 not in by_id  # node 1 on 0x85 now
    by_id = rig.sync_by_id()
    assert 0x182 in by_id and 0x181 not in by_id


def test_emcy_cob_id_0x1014_refusals(rig):
    for bad in (0x2000_0081, 0x0000_0881, 0x1000_0081):
        assert _abort_code(rig, 1, 0x1014, 0, "I", bad) is SdoAbortCode.VALUE_RANGE_EXCEEDED, hex(bad)
    rig.write(1, 0x1014, 0, "I", 0x0000_0081)  # valid, the same CAN-ID: accepted
    for other in (0x0000_0095, 0x0000_0002):  # valid, another CAN-ID while valid: refused
        assert _abort_code(rig, 1, 0x1014, 0, "I", other) is SdoAbortCode.VALUE_RANGE_EXCEEDED, hex(other)
    rig.write(1, 0x1014, 0, "I", 0x8000_0081)
    rig.write(1, 0x1014, 0, "I", 0x8000_0002)  # invalid: the CAN-ID may change
    rig.write(1, 0x1014, 0, "I", 0x0000_0002)
    assert rig.pair.inject_fault(0, 0x2310) == [Frame(0x002, bytes.fromhex("1023 03 0000000000"))]


def test_error_history_0x1003_keeps_the_last_four_newest_first_and_0_clears_it(rig):
    def history():
        return [rig.read(1, 0x1003, 0, "B")] + [rig.read(1, 0x1003, k, "I") for k in (1, 2, 3, 4)]
    codes = (0x2310, 0x3210, 0x4210, 0x5530, 0x6320)
    seen = []
    for code in codes:
        rig.pair.inject_fault(0, code)
        rig.sync()
        rig.write(1, 0x6040, 0, "H", 0x00)
        rig.write(1, 0x6040, 0, "H", 0x80)  # fault reset: EMCY 0000 is not recorded
        seen.append(history())
    assert seen == [[1, 0x2310, 0, 0, 0], [2, 0x3210, 0x2310, 0, 0], [3, 0x4210, 0x3210, 0x2310, 0],
                    [4, 0x5530, 0x4210, 0x3210, 0x2310], [4, 0x6320, 0x5530, 0x4210, 0x3210]]
    for k in (1, 2, 3, 4):
        assert _abort_code(rig, 1, 0x1003, k, "I", 0) is SdoAbortCode.WRITE_OF_READ_ONLY
    assert _abort_code(rig, 1, 0x1003, 0, "B", 1) is SdoAbortCode.VALUE_RANGE_EXCEEDED
    rig.write(1, 0x1003, 0, "B", 0)
    assert history() == [0, 0, 0, 0, 0]
    rig.pair.inject_fault(0, 0x7300)
    assert history() == [1, 0x7300, 0, 0, 0]


def test_clearing_the_error_history_leaves_0_whatever_the_eds_default():
    def edit(od):
        od[0x1003][0].default = 1
    pair = _custom_pair(edit)
    pair.power_on(0.0)
    rig = Rig(pair)
    assert rig.read(1, 0x1003, 0, "B") == 1
    rig.write(1, 0x1003, 0, "B", 0)
    assert rig.read(1, 0x1003, 0, "B") == 0


def test_reset_communication_keeps_the_application_objects_and_restarts_the_producer(rig):
    rig.write(1, 0x6072, 0, "H", 5000)
    rig.write(1, 0x1017, 0, "H", 100)
    rig.t = 0.05
    assert rig.nmt(0x82, 1) == [Frame(0x701, b"\x00")]
    assert rig.read(1, 0x6072, 0, "H") == 5000 and rig.read(1, 0x1017, 0, "H") == 0
    assert rig.pair.tick(0.1) == [] and rig.pair.tick(0.2) == []  # the EDS's 0: no heartbeat


def test_nmt_enter_pre_operational(rig):
    rig.nmt(0x01)
    assert [n.nmt_state for n in rig.pair.nodes] == [NmtState.OPERATIONAL] * 2
    rig.nmt(0x80, 2)
    assert [n.nmt_state for n in rig.pair.nodes] == [NmtState.OPERATIONAL, NmtState.PRE_OPERATIONAL]
    assert rig.read(2, 0x1017, 0, "H") == 0  # SDO served in PRE-OPERATIONAL


def test_heartbeat_producer_of_1_ms_and_ticks_off_the_schedule(rig):
    rig.write(1, 0x1017, 0, "H", 100)  # at t = 0
    rig.write(2, 0x1017, 0, "H", 1)
    assert rig.pair.tick(0.001) == [Frame(0x702, b"\x7f")]
    hb = Frame(0x701, b"\x7f")

    def node_1(t):
        return [f for f in rig.pair.tick(t) if f.arbitration_id == 0x701]
    assert [node_1(t) for t in (0.13, 0.19, 0.2)] == [[hb], [], [hb]]  # the schedule is kept: 0.1, 0.2, ...
    # a tick a whole period late: one heartbeat, the schedule restarts from that tick
    assert node_1(0.4) == [hb] and node_1(0.4) == [] and node_1(0.45) == [] and node_1(0.5) == [hb]
