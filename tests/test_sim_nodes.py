"""The simulated sensor node (sim.drives.sensor_node) beside the two drives: boot, SDO, PDOs mapped by the
master's configuration writes, TPDO values and scaling, heartbeat, consumer, and the master reading it.

The rig: the shipped drives and a CiA 401 analog input module (profiles/cia401_io.eds, node 3) carrying
both EMAs' LVDT and load cell (tests/support/sensor_rig.py). Known answers: the EDS (identity, device
type, the default PDOs), the CiA 301 frame formats, and the map's scaling applied to the plant's
sample (raw = round(x / per_unit), clipped to INTEGER16).
"""

from __future__ import annotations

import struct
import tomllib

import numpy as np
import pytest
import tomli_w

from hil.canopen.frame import Frame
from hil.canopen.sdo import SdoAbortCode, SdoAbortError, SdoClient
from hil.profile.load import default_profile_path, load_actuation
from hil.profile.rig import plan_for
from sim.drives import NmtState, SimSensorNode
from sim.faults import Fault, FaultInjector
from sim.plant import RigPlant
from support.canopen_rig import make_pair
from support.profiles import apply_overrides
from support.rigs import T_S, brief_rig, quiet
from support.sensor_rig import FORCE_N_PER_UNIT, IO_NODE, LVDT_MM_PER_UNIT, sensor_profile, sensor_rig
from support.sim_bus import Bus

IO = IO_NODE


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    return sensor_rig(tmp_path_factory.mktemp("sensor-rig") / "actuation.toml")[1]


def _pair(rig, seed: int = 0):
    return make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(seed)), rig)


def _raw(x: float, per_unit: float) -> int:
    return max(-32768, min(32767, round(x / per_unit)))


def _expected_inputs(sample) -> tuple[int, int, int, int]:
    """0x6401:01..04 of the sensor rig for a plant sample: LVDT 1, force 1, LVDT 2, force 2."""
    return (_raw(sample.s1_mm, LVDT_MM_PER_UNIT), _raw(sample.F1_N, FORCE_N_PER_UNIT),
            _raw(sample.s2_mm, LVDT_MM_PER_UNIT), _raw(sample.F2_N, FORCE_N_PER_UNIT))


def _configure(bus: Bus, rig) -> None:
    """What the master's preflight does to every node's PDOs: the plan's configuration writes by SDO."""
    for name, node in (("ema1", 1), ("ema2", 2), ("io", IO)):
        for w in rig.plan.node(name).layout.configuration_writes():
            bus.sdo(node, w.index, w.subindex, w.data)


# ------------------------------------------------------------------ boot and NMT


def test_the_sensor_node_boots_with_the_drives_and_answers_nmt(rig):
    pair = _pair(rig)
    assert len(pair.sensors) == 1 and isinstance(pair.sensors[0], SimSensorNode)
    io = pair.sensors[0]
    assert (io.name, io.node_id) == ("io", IO) and pair.all_nodes == pair.nodes + pair.sensors
    assert pair.power_on(0.0) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00"), Frame(0x703, b"\x00")]
    assert io.nmt_state is NmtState.PRE_OPERATIONAL
    bus = Bus(pair)
    out = bus.send(Frame(0x000, bytes([0x01, IO])))  # start node 3 only: its event TPDOs go out once
    assert [f.arbitration_id for f in out] == [0x283, 0x383]
    assert io.nmt_state is NmtState.OPERATIONAL and pair.nodes[0].nmt_state is NmtState.PRE_OPERATIONAL
    bus.write(IO, 0x1017, 0, "H", 250)
    assert bus.send(Frame(0x000, bytes([0x81, IO]))) == [Frame(0x703, b"\x00")]  # reset node: boot-up
    assert io.nmt_state is NmtState.PRE_OPERATIONAL and bus.read(IO, 0x1017, 0, "H") == 0
    assert bus.send(Frame(0x000, bytes([0x81, 0]))) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00"),
                                                         Frame(0x703, b"\x00")]


# ------------------------------------------------------------------ SDO


def test_sdo_identity_device_type_and_the_inputs_scaled_from_the_plant(rig):
    pair = _pair(rig)
    pair.power_on(0.0)
    bus = Bus(pair)
    assert [bus.read(IO, 0x1018, k, "I") for k in (1, 2, 3)] == [0x0E3A, 0x0401, 0x00010000]
    assert bus.read(IO, 0x1000, 0, "I") == 0x00040191  # CiA 401, analog inputs
    assert bus.read(IO, 0x1014, 0, "I") == 0x83  # $NODEID + 0x80 resolved for node 3
    assert bus.sdo(IO, 0x1008, 0) == b"emacheck AI8"  # segmented upload
    # the map's inputs: the plant at rest (noise-free: LVDT 1 = 0.3 mm, LVDT 2 = -0.2 mm, forces 0)
    got = tuple(bus.read(IO, 0x6401, k, "h") for k in (1, 2, 3, 4))
    assert got == _expected_inputs(pair.sample) == (480, 0, -320, 0)
    assert bus.read(IO, 0x6401, 5, "h") == 0  # a channel the map does not use
    assert bus.read(IO, 0x6401, 0, "B") == 8
    for index, sub, data, code in ((0x2100, 0, None, SdoAbortCode.OBJECT_DOES_NOT_EXIST),
                                   (0x6401, 9, None, SdoAbortCode.SUBINDEX_DOES_NOT_EXIST),
                                   (0x6401, 1, b"\x01\x00", SdoAbortCode.WRITE_OF_READ_ONLY),
                                   (0x1017, 0, b"\x01", SdoAbortCode.LENGTH_MISMATCH)):
        with pytest.raises(SdoAbortError) as exc:
            bus.sdo(IO, index, sub, data)
        assert exc.value.code == code
    bus.write(IO, 0x2001, 0, "H", 5)  # a manufacturer object: stored as written
    assert bus.read(IO, 0x2001, 0, "H") == 5


# ------------------------------------------------------------------ PDOs


def test_pdos_configured_by_the_master_carry_the_scaled_inputs_on_every_sync(rig):
    pair = _pair(rig, seed=3)
    pair.power_on(0.0)
    bus = Bus(pair)
    _configure(bus, rig)
    spec = rig.plan.node("io").layout.pdos[0]
    assert (spec.name, spec.cob_id, spec.transmission_type) == ("TPDO1", 0x183, 1)
    assert bus.read(IO, 0x1A00, 0, "B") == 4
    assert [bus.read(IO, 0x1A00, k, "I") for k in (1, 2, 3, 4)] == [0x64010110, 0x64010210, 0x64010310, 0x64010410]
    assert bus.read(IO, 0x1800, 1, "I") == 0x183 and bus.read(IO, 0x1800, 2, "B") == 1
    assert bus.read(IO, 0x1801, 1, "I") & 0x8000_0000  # the default TPDO2 disabled by the master
    assert bus.send(Frame(0x000, bytes([0x01, 0]))) == []
    for _ in range(20):
        before = pair.sample  # the plant state this SYNC's TPDOs carry
        frames = bus.sync()
        assert set(frames) == {0x181, 0x182, 0x183}  # the drives' TPDO1, the I/O module's TPDO1
        assert struct.unpack("<hhhh", frames[0x183].data) == _expected_inputs(before)
    assert pair.stats.tpdos_sent == 60


def test_default_pdos_of_the_eds_before_the_master_maps_them(rig):
    """Unconfigured, the I/O module sends its EDS default: TPDO2 (inputs 1..4) and TPDO3 (5..8) event
    driven (255): once on entering OPERATIONAL, then whenever their payload changes."""
    pair = make_pair(RigPlant(brief_rig(), np.random.default_rng(0)), rig)  # with sensor noise
    pair.power_on(0.0)
    bus = Bus(pair)
    out = bus.send(Frame(0x000, bytes([0x01, IO])))  # operational: the event TPDOs go out once
    assert [f.arbitration_id for f in out] == [0x283, 0x383]
    assert struct.unpack("<hhhh", out[0].data) == _expected_inputs(pair.sample)
    assert out[1].data == bytes(8)  # inputs 5..8: not wired
    for _ in range(5):  # the noisy sample changes at every step: TPDO2 with the new one, TPDO3 unchanged
        frames = bus.sync()
        assert set(frames) == {0x283}
        assert struct.unpack("<hhhh", frames[0x283].data) == _expected_inputs(pair.sample)
    assert bus.send(Frame(0x123, b"")) == []  # an event without a change: nothing


def test_values_beyond_the_data_type_are_clipped(tmp_path):
    path = sensor_profile(tmp_path / "actuation.toml")
    data = tomllib.loads(path.read_text())
    apply_overrides(data, {"signals": {"ema1": {"lvdt": {"mm_per_unit": 5e-6}}}})  # 0.3 mm = 60000 units
    path.write_text(tomli_w.dumps(data))
    pair = _pair(plan_for(load_actuation(path), path))
    pair.power_on(0.0)
    bus = Bus(pair)
    assert bus.read(IO, 0x6401, 1, "h") == 32767
    assert bus.read(IO, 0x6401, 3, "h") == -320


# ------------------------------------------------------------------ heartbeat and consumer


def test_heartbeat_and_consumer_of_the_sensor_node(rig):
    pair = _pair(rig)
    pair.power_on(0.0)
    bus = Bus(pair)
    bus.write(IO, 0x1017, 0, "H", 100)
    assert pair.tick(0.05) == []
    assert pair.tick(0.1) == [Frame(0x703, b"\x7F")]
    bus.t = 0.1
    bus.send(Frame(0x000, bytes([0x01, 0])))
    assert pair.tick(0.2) == [Frame(0x703, b"\x05")]
    # the node consumes the master's heartbeat (0x1016:01 = node 127, 150 ms): EMCY 0x8130 on its loss
    bus.write(IO, 0x1016, 1, "I", 0x7F << 16 | 150)
    bus.t = 0.2
    bus.send(Frame(0x77F, b"\x05"))
    assert pair.tick(0.3) == [Frame(0x703, b"\x05")]
    assert pair.tick(0.35) == []
    assert pair.tick(0.3501) == [Frame(0x083, bytes.fromhex("3081 11 0000000000"))]
    io = pair.sensors[0]
    assert io.heartbeat_events == [(pytest.approx(0.3501), 0x7F)]
    assert io.nmt_state is NmtState.OPERATIONAL  # no outputs to stop: it goes on measuring
    assert bus.read(IO, 0x1001, 0, "B") == 0x11
    bus.t = 0.36
    assert bus.send(Frame(0x77F, b"\x05")) == [Frame(0x083, bytes(8))]  # the event ends
    assert pair.tick(0.4) == [Frame(0x703, b"\x05")]


def test_sensor_node_silent_fault_drops_everything_it_sends(rig):
    """sensor_node_silent (check time axis): from its onset no TPDO, heartbeat, EMCY or SDO reply of node 3."""
    pair = _pair(rig)
    inj = FaultInjector(pair, [Fault("sensor_node_silent", start_s=10 * T_S)], record_truth=False)
    inj.power_on(0.0)
    bus = Bus(inj)
    _configure(bus, rig)
    bus.write(IO, 0x1017, 0, "H", 10)
    bus.send(Frame(0x000, bytes([0x01, 0])))
    seen = []
    for _ in range(20):
        seen.append(set(bus.sync()) | {f.arbitration_id for f in inj.tick(bus.t + T_S / 2)})
    assert all({0x181, 0x182, 0x183} <= s for s in seen[:9])
    assert any(0x703 in s for s in seen[:9])
    assert all(0x183 not in s and 0x703 not in s for s in seen[10:])
    assert all({0x181, 0x182} <= s for s in seen[10:])  # the drives go on
    assert inj.onset_s == {"sensor_node_silent": pytest.approx(10 * T_S)}
    assert bus.send(SdoClient(IO).start_upload(0x1000, 0, bus.t)) == []  # no SDO reply either
    with pytest.raises(ValueError, match="no sensor node"):
        FaultInjector(make_pair(RigPlant(quiet(brief_rig()), np.random.default_rng(0))),
                      [Fault("sensor_node_silent")])
    with pytest.raises(ValueError, match="value = 9 is not a sensor node of the rig"):
        FaultInjector(_pair(rig), [Fault("sensor_node_silent", value=9.0)])


# ------------------------------------------------------------------ with the master


class _Recorder:
    """The pair with every frame it sends recorded (the transport's view of the simulated nodes)."""

    def __init__(self, pair) -> None:
        self.pair = pair
        self.sent: list[Frame] = []

    def __getattr__(self, name):
        return getattr(self.pair, name)

    def _keep(self, frames: list[Frame]) -> list[Frame]:
        self.sent += frames
        return frames

    def power_on(self, t):
        return self._keep(self.pair.power_on(t))

    def on_frame(self, frame, t):
        return self._keep(self.pair.on_frame(frame, t))

    def tick(self, t):
        return self._keep(self.pair.tick(t))


def test_the_master_configures_and_reads_the_sensor_node_on_the_same_sync(tmp_path):
    """The master (preflight with the drill, cyclic) with the sensor node: it identifies and configures
    node 3, and its sample holds the I/O module's last TPDO scaled back to mm and N."""
    from hil.master.core import MasterCore
    from hil.master.link import CanopenLink
    from hil.transport import InProcessTransport

    act, rig = sensor_rig(tmp_path / "actuation.toml")
    rec = _Recorder(_pair(rig, seed=5))
    tr = InProcessTransport(rec, act.timing.sync_period_s)
    try:
        smp = CanopenLink(MasterCore(act, rig.plan), tr).first_sample()
    finally:
        tr.close()
    io = rec.pair.sensors[0]
    assert io.nmt_state is NmtState.OPERATIONAL
    assert io.read(0x1017, 0) == round(act.canopen.heartbeat_period_s * 1000)  # set by the master
    assert io.read(0x1800, 1) == 0x183 and io.read(0x1A00, 0) == 4
    tpdos = [f for f in rec.sent if f.arbitration_id == 0x183]
    assert len(tpdos) >= 2 and all(len(f.data) == 8 for f in tpdos)
    lvdt1, f1, lvdt2, f2 = struct.unpack("<hhhh", tpdos[-1].data)
    assert smp.s1_mm == pytest.approx(lvdt1 * LVDT_MM_PER_UNIT, rel=1e-12)
    assert smp.F1_N == pytest.approx(f1 * FORCE_N_PER_UNIT, rel=1e-12, abs=1e-12)
    assert smp.s2_mm == pytest.approx(lvdt2 * LVDT_MM_PER_UNIT, rel=1e-12)
    assert smp.F2_N == pytest.approx(f2 * FORCE_N_PER_UNIT, rel=1e-12, abs=1e-12)
    assert abs(smp.s1_mm - 0.3) < 0.01 and abs(smp.s2_mm + 0.2) < 0.01  # the rig at rest
    assert any(f.arbitration_id == 0x703 for f in rec.sent)  # its heartbeat, which the master watches


def test_random_frames_never_raise_and_the_rig_with_its_sensor_node_recovers(rig):
    rnd = np.random.default_rng(11)
    pair = _pair(rig)
    pair.power_on(0.0)
    bus = Bus(pair)
    cobs = [0x000, 0x080, 0x083, 0x183, 0x203, 0x283, 0x603, 0x601, 0x703, 0x77F, 0x123]
    bus.send(Frame(0x000, bytes([0x01, 0])))
    for _ in range(3000):
        bus.t += 0.001
        cob = int(rnd.choice(cobs))
        data = bytes(rnd.integers(0, 256, size=int(rnd.integers(0, 9)), dtype=np.uint8))
        if cob == 0x000:
            data = bytes([int(rnd.choice([0x01, 0x02, 0x80, 0x81, 0x82])), int(rnd.choice([0, 3]))])
        elif cob == 0x080:
            data = data[:int(rnd.integers(0, 2))]
        elif cob == 0x603 and rnd.random() < 0.9:  # 8 bytes with an index of the I/O module
            index = int(rnd.choice([0x1016, 0x1017, 0x1800, 0x1801, 0x1A00, 0x1A01, 0x2001, 0x6401, 0x6423]))
            data = bytes([data[0] if data else 0]) + struct.pack("<HB", index, int(rnd.integers(0, 9))) + \
                bytes(rnd.integers(0, 256, size=4, dtype=np.uint8))
        for frame in bus.send(Frame(cob, data)) + pair.tick(bus.t):
            assert isinstance(frame, Frame)
    assert pair.stats.sdo_requests > 100
    assert bus.send(Frame(0x000, bytes([0x81, 0]))) == [Frame(0x701, b"\x00"), Frame(0x702, b"\x00"),
                                                         Frame(0x703, b"\x00")]
    assert bus.read(IO, 0x1018, 1, "I") == 0x0E3A
    _configure(bus, rig)
    bus.send(Frame(0x000, bytes([0x01, 0])))
    before = pair.sample
    frames = bus.sync()
    assert struct.unpack("<hhhh", frames[0x183].data) == _expected_inputs(before)


def _cia404_eds(dest) -> None:
    """A CiA 404 measuring device derived from the shipped CiA 401 EDS: device type 0x00000194, the
    eight inputs as REAL32 process values 0x9130:01..08 (in the unit the profile scales), mapped two by
    two by default (8 bytes each)."""
    import re

    text = (default_profile_path("cia401_io.eds").read_text()
            .replace("DefaultValue=0x00040191", "DefaultValue=0x00000194")
            .replace("[6401", "[9130").replace("=0x6401", "=0x9130")
            .replace("Read analog input 16-bit", "AI process value").replace("Analog input ", "AI process value "))
    text = re.sub(r"(\[9130sub[1-8]\]\nParameterName=[^\n]*\nObjectType=0x7\nDataType=)0x0003", r"\g<1>0x0008", text)
    text = re.sub(r"DefaultValue=0x9130(0[1-8])10", r"DefaultValue=0x9130\g<1>20", text)
    for rec in ("1A01", "1A02"):
        text = text.replace(f"[{rec}sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\n"
                            "AccessType=rw\nDefaultValue=4", f"[{rec}sub0]\nParameterName=Number of mapped objects\n"
                            "ObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=2")
    assert text.count("DataType=0x0008") == 8 and "DefaultValue=0x91300120" in text
    dest.write_text(text)


def test_cia404_node_with_real32_inputs_over_two_tpdos(tmp_path):
    path = sensor_profile(tmp_path / "actuation.toml", eds="meas404.eds", device_profile=404)
    _cia404_eds(tmp_path / "meas404.eds")
    data = tomllib.loads(path.read_text())
    for ema, (lvdt, force) in ((1, ("0x9130:01", "0x9130:02")), (2, ("0x9130:03", "0x9130:04"))):
        apply_overrides(data, {"signals": {f"ema{ema}": {"lvdt": {"object": lvdt, "mm_per_unit": 1.0},
                                                         "force": {"object": force, "N_per_unit": 1000.0}}}})
    path.write_text(tomli_w.dumps(data))  # LVDT in mm, load cell in kN, as REAL32
    rig = plan_for(load_actuation(path), path)
    io = rig.plan.node("io")
    assert [(p.name, len(p.entries)) for p in io.layout.pdos] == [("TPDO1", 2), ("TPDO2", 2)]
    pair = make_pair(RigPlant(brief_rig(), np.random.default_rng(4)), rig)
    pair.power_on(0.0)
    bus = Bus(pair)
    assert bus.read(IO, 0x1000, 0, "I") == 0x00000194
    _configure(bus, rig)
    bus.send(Frame(0x000, bytes([0x01, 0])))
    for _ in range(5):
        s = pair.sample
        frames = bus.sync()
        got = struct.unpack("<ff", frames[0x183].data) + struct.unpack("<ff", frames[0x283].data)
        want = (s.s1_mm, s.F1_N / 1000.0, s.s2_mm, s.F2_N / 1000.0)
        np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)  # REAL32: no rounding but float32
