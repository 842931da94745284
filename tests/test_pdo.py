"""PDO layout and codec: golden bytes, round trips, length errors, configuration SDO writes, bus load.

The layout under test is the shipped profile's, planned against the shipped EDS (what the master
configures and the simulated drives serve): the same four PDOs per drive the fixed layout had.
"""

from __future__ import annotations

import math
import struct

import canopen
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.canopen.busload import bus_load, frame_bits
from hil.canopen.errors import CanopenError, CanopenInputError
from hil.canopen.frame import Frame, FrameError, sync_frame
from hil.canopen.od import load_eds
from hil.canopen.pdo import (
    TYPE_RANGE,
    Direction,
    MappedObject,
    PdoError,
    PdoLayout,
    PdoLengthError,
    PdoSpec,
    encode_raw,
    pdo_codec,
    predefined_cob_id,
    raw_encoder,
)
from hil.canopen.sdo import SdoClient, SdoEvent
from hil.canopen.units import (
    force_dN_to_newton,
    force_to_permille,
    increments_per_rad,
    increments_to_rad,
    lvdt_um_to_mm,
    mm_to_lvdt_um,
    newton_to_force_dN,
    permille_to_force_N,
    rad_to_increments,
)
from support.canopen_rig import shipped_rig

I_TOTAL = 2 * math.pi * 4 / 5  # rad/mm, the default actuation (gearbox 4:1, lead 5 mm)

i8 = st.integers(-128, 127)
u16 = st.integers(0, 0xFFFF)
i16 = st.integers(-(2**15), 2**15 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)


def layout(node: int = 1) -> PdoLayout:
    """The shipped layout of drive ``node`` (1 or 2)."""
    return shipped_rig().plan.node(f"ema{node}").layout


def test_the_shipped_layout_is_the_four_pdos_of_each_drive():
    for n in (1, 2):
        lay = layout(n)
        got = [(p.name, p.direction, p.cob_id, p.comm_index, p.mapping_index, p.transmission_type, p.length_bytes,
                struct.calcsize(p.struct_format)) for p in lay.pdos]
        assert got == [
            ("RPDO1", Direction.RX, 0x200 + n, 0x1400, 0x1600, 1, 8, 8),
            ("RPDO2", Direction.RX, 0x300 + n, 0x1401, 0x1601, 255, 1, 1),
            ("TPDO1", Direction.TX, 0x180 + n, 0x1800, 0x1A00, 1, 7, 7),
            ("TPDO2", Direction.TX, 0x280 + n, 0x1801, 0x1A01, 1, 8, 8),
        ]
        assert [(e.index, e.subindex, e.bit_length) for e in lay["TPDO1"].entries] == [
            (0x6041, 0, 16), (0x6064, 0, 32), (0x6061, 0, 8)]
        assert [(e.index, e.subindex, e.bit_length) for e in lay["RPDO1"].entries] == [
            (0x6040, 0, 16), (0x607A, 0, 32), (0x6071, 0, 16)]
        assert [(e.index, e.subindex, e.bit_length) for e in lay["TPDO2"].entries] == [(0x2100, 0, 32), (0x2101, 0, 32)]
        assert lay.disable == ()


def test_predefined_connection_set():
    assert [predefined_cob_id(Direction.TX, k, 5) for k in (1, 2, 3, 4, 5)] == [0x185, 0x285, 0x385, 0x485, None]
    assert [predefined_cob_id(Direction.RX, k, 127) for k in (1, 4)] == [0x27F, 0x57F]


# ---------------------------------------------------------------------------- golden bytes


def test_rpdo1_golden():
    f = layout(1)["RPDO1"].pack((0x000F, 0x00012345, -2))
    assert f == Frame(0x201, bytes.fromhex("0F 00 45 23 01 00 FE FF"))
    assert layout(1)["RPDO1"].unpack(f) == (0x000F, 74565, -2)


def test_tpdo2_golden():
    f = layout(2)["TPDO2"].pack((-12345, 60000))
    assert f == Frame(0x282, bytes.fromhex("C7 CF FF FF 60 EA 00 00"))
    assert layout(2)["TPDO2"].unpack(f) == (-12345, 60000)


def test_tpdo1_and_rpdo2_golden():
    assert layout(2)["TPDO1"].pack((0x0237, -65536, 10)).data == bytes.fromhex("37 02 00 00 FF FF 0A")
    assert layout(1)["RPDO2"].pack((8,)) == Frame(0x301, b"\x08")
    assert sync_frame() == Frame(0x080, b"")


# ---------------------------------------------------------------------------- round trips


@given(u16, i32, i16)
def test_rpdo1_round_trip(cw, pos, tq):
    p = layout(1)["RPDO1"]
    f = p.pack((cw, pos, tq))
    assert f.arbitration_id == 0x201 and len(f.data) == 8 and p.unpack(f) == (cw, pos, tq)


@given(u16, i32, i8)
def test_tpdo1_round_trip(sw, pos, mode):
    p = layout(2)["TPDO1"]
    f = p.pack((sw, pos, mode))
    assert f.arbitration_id == 0x182 and len(f.data) == 7 and p.unpack(f) == (sw, pos, mode)


@given(st.floats(-1e6, 1e6, allow_nan=False), i16)
def test_real32_and_integer_entries_pack_together(x, y):
    p = PdoSpec("TPDO3", Direction.TX, 3, 0x383, 1, (MappedObject("a", 0x9130, 1, 0x0008),
                                                        MappedObject("b", 0x6401, 1, 0x0003)))
    a, b = p.unpack(p.pack((x, y)))
    assert b == y and a == pytest.approx(x, rel=1e-7, abs=1e-30)


def test_one_codec_per_mapping_shared_by_every_pdo_of_it():
    # the master's PdoSpec of each drive and any other user of the same struct codes hold one codec
    a, b = layout(1)["TPDO1"], layout(2)["TPDO1"]
    assert a.codec is b.codec is pdo_codec("Hib")
    assert (a.codec.codes, a.codec.size) == ("Hib", 7)
    assert a.codec is not layout(1)["RPDO1"].codec and layout(1)["RPDO1"].codec.codes == "Hih"
    assert a.codec.pack(0x0237, -5, 8) == bytes.fromhex("3702FBFFFFFF08")
    assert a.codec.unpack(bytes.fromhex("3702FBFFFFFF08")) == (0x0237, -5, 8)
    with pytest.raises(struct.error):
        a.codec.unpack(bytes(6))


@pytest.mark.parametrize("x,raw", [(2.5, 2), (3.5, 4), (-2.5, -2), (-0.5, 0), (0.49, 0), (1e12, 2**31 - 1),
                                   (-1e12, -(2**31)), (2**31 - 0.5, 2**31 - 1), (-(2**31) - 0.5, -(2**31))])
def test_encode_raw_rounds_ties_to_even_and_clips_i32(x, raw):
    assert encode_raw(0x0004, x) == raw and raw_encoder(0x0004)(x) == raw
    assert type(encode_raw(0x0004, x)) is int


@pytest.mark.parametrize("data_type", sorted(TYPE_RANGE))
def test_encode_raw_clips_to_each_integer_type(data_type):
    lo, hi = TYPE_RANGE[data_type]
    enc = raw_encoder(data_type)
    assert enc is raw_encoder(data_type)  # built once per type
    assert encode_raw(data_type, lo - 1.0e3) == lo and encode_raw(data_type, hi + 1.0e3) == hi
    assert enc(lo - 0.75) == lo and enc(hi + 0.75) == hi
    assert enc(lo) == lo and enc(hi) == hi and enc(lo + 1) == lo + 1 and enc(hi - 1) == hi - 1
    if hi < 2**53:  # (a float holds these exactly)
        assert enc(lo + 1.4) == lo + 1 and enc(hi - 1.4) == hi - 1 and enc(lo + 0.5) == lo + (lo % 2)


def test_encode_raw_leaves_real32_as_it_is():
    assert encode_raw(0x0008, 2.75) == 2.75 and raw_encoder(0x0008)(-1e30) == -1e30


# ---------------------------------------------------------------------------- errors


@pytest.mark.parametrize("name,n,expected", [("RPDO1", 7, 8), ("RPDO1", 0, 8), ("RPDO2", 2, 1), ("TPDO1", 8, 7),
                                             ("TPDO2", 4, 8)])
def test_length_errors_name_cob_id(name, n, expected):
    p = layout(2)[name]
    with pytest.raises(PdoLengthError, match=f"{name} COB-ID 0x{p.cob_id:03X}: expected {expected} data bytes, "
                                             f"got {n}"):
        p.unpack(Frame(p.cob_id, bytes(n)))


def test_error_types():
    assert issubclass(PdoLengthError, CanopenError) and issubclass(PdoLengthError, ValueError)
    with pytest.raises(PdoError, match=r"RPDO1 COB-ID 0x201: cannot encode \(65536, 0, 0\)"):
        layout(1)["RPDO1"].pack((0x10000, 0, 0))
    with pytest.raises(PdoError, match=r"cannot encode \(0, 0, 32768\)"):
        layout(1)["RPDO1"].pack((0, 0, 32768))
    with pytest.raises(CanopenInputError, match="72 mapped bits exceed the 64 of a CAN frame"):
        PdoSpec("TPDO1", Direction.TX, 1, 0x181, 1, tuple(MappedObject(f"x{k}", 0x6401, k, 0x0003) for k in range(1, 5))
                + (MappedObject("y", 0x6000, 1, 0x0005),))
    with pytest.raises(CanopenInputError, match="data type 0x0009 cannot be mapped"):
        MappedObject("name", 0x1008, 0, 0x0009)
    with pytest.raises(CanopenInputError, match="COB-ID 0x800 is not an 11-bit identifier"):
        PdoSpec("TPDO1", Direction.TX, 1, 0x800, 1, ())
    with pytest.raises(FrameError):
        Frame(0x800, b"")
    with pytest.raises(FrameError, match="9 data bytes"):
        Frame(0x201, bytes(9))
    assert Frame(0x201, bytearray(b"\x01")).data == b"\x01"


# ---------------------------------------------------------------------------- configuration writes


CONFIG_NODE2 = [  # (index, subindex, data) for node 2, the CiA 301 mapping procedure per PDO
    (0x1400, 1, "02 02 00 80"), (0x1600, 0, "00"), (0x1600, 1, "10 00 40 60"), (0x1600, 2, "20 00 7A 60"),
    (0x1600, 3, "10 00 71 60"), (0x1600, 0, "03"), (0x1400, 2, "01"), (0x1400, 1, "02 02 00 00"),
    (0x1401, 1, "02 03 00 80"), (0x1601, 0, "00"), (0x1601, 1, "08 00 60 60"), (0x1601, 0, "01"),
    (0x1401, 2, "FF"), (0x1401, 1, "02 03 00 00"),
    (0x1800, 1, "82 01 00 80"), (0x1A00, 0, "00"), (0x1A00, 1, "10 00 41 60"), (0x1A00, 2, "20 00 64 60"),
    (0x1A00, 3, "08 00 61 60"), (0x1A00, 0, "03"), (0x1800, 2, "01"), (0x1800, 1, "82 01 00 00"),
    (0x1801, 1, "82 02 00 80"), (0x1A01, 0, "00"), (0x1A01, 1, "20 00 00 21"), (0x1A01, 2, "20 00 01 21"),
    (0x1A01, 0, "02"), (0x1801, 2, "01"), (0x1801, 1, "82 02 00 00"),
]


def test_configuration_writes_golden():
    writes = layout(2).configuration_writes()
    assert [(w.index, w.subindex, w.data.hex(" ").upper()) for w in writes] == CONFIG_NODE2
    assert writes[0].what == "RPDO1 disable" and writes[-1].what == "TPDO2 enable"


def test_a_pdo_the_eds_fixes_is_not_written_and_unused_ones_are_disabled():
    fixed = PdoSpec("TPDO2", Direction.TX, 2, 0x283, 1, (MappedObject("lvdt", 0x6401, 1, 0x0003),),
                    write_mapping=False, write_cob_id=False, write_transmission=True)
    lay = PdoLayout(3, (fixed,), disable=((0x1800, 0x8000_0183),))
    w = [(x.index, x.subindex, x.data.hex()) for x in lay.configuration_writes()]
    assert w == [(0x1800, 1, "83010080"), (0x1801, 2, "01")]
    no_rtr = PdoSpec("TPDO1", Direction.TX, 1, 0x181, 1, (MappedObject("sw", 0x6041, 0, 0x0006),), rtr_bit=0x4000_0000)
    assert [x.data.hex() for x in no_rtr.configuration_writes() if x.index == 0x1800 and x.subindex == 1] == [
        "810100c0", "81010040"]


class CollectingBus:
    def __init__(self) -> None:
        self.sent: list = []

    def send(self, msg) -> None:
        self.sent.append(msg)


def test_configuration_writes_accepted_by_the_eds_drive():
    """Every write goes through canopen's SdoServer on the shipped EDS (access, lengths)."""
    bus = CollectingBus()
    network = canopen.Network(bus)
    drive = canopen.LocalNode(1, load_eds(node_id=1))
    network.add_node(drive)
    client = SdoClient(1)
    for w in layout(1).configuration_writes():
        frame = client.start_download(w.index, w.subindex, w.data, 0.0)
        network.notify(frame.arbitration_id, bytearray(frame.data), 0.0)
        (reply,), bus.sent = bus.sent, []
        assert isinstance(client.on_frame(Frame(reply.arbitration_id, bytes(reply.data)), 0.0), SdoEvent)
    assert drive.data_store[0x1A00] == {0: b"\x03", 1: bytes.fromhex("10004160"),
                                         2: bytes.fromhex("20006460"), 3: bytes.fromhex("08006160")}
    assert drive.data_store[0x1801][1] == bytes.fromhex("81020000")


# ---------------------------------------------------------------------------- scaling


def test_position_scaling():
    assert increments_per_rad(4096) == pytest.approx(651.8986469044033, rel=1e-15)
    assert rad_to_increments(2 * math.pi, 4096) == 4096
    assert rad_to_increments(-20 * I_TOTAL, 4096) == -65536  # -20 mm stroke = -16 motor turns
    assert increments_to_rad(2048, 4096) == pytest.approx(math.pi, rel=1e-15)
    assert rad_to_increments(1e12, 4096) == 2**31 - 1
    with pytest.raises(CanopenInputError, match="counts_per_rev = 0"):
        increments_per_rad(0)


def test_force_scaling():
    # T = 10000 N / (5.0265 rad/mm * 1000) = 1.98944 N m -> 1989.4 per mille of 1 N m
    assert force_to_permille(10_000.0, I_TOTAL, 1.0) == 1989
    assert force_to_permille(-40_000.0, I_TOTAL, 1.0) == -7958
    assert force_to_permille(10_000.0, I_TOTAL, 2.0) == 995
    assert force_to_permille(1e9, I_TOTAL, 1.0) == 32767 and force_to_permille(-1e9, I_TOTAL, 1.0) == -32768
    assert permille_to_force_N(1000, I_TOTAL, 1.0) == pytest.approx(5026.548245743669, rel=1e-12)
    for F in (-6000.0, -3.0, 0.0, 2.4, 6000.0):
        back = permille_to_force_N(force_to_permille(F, I_TOTAL, 1.0), I_TOTAL, 1.0)
        assert abs(back - F) <= 0.5 * I_TOTAL + 1e-9  # half a per mille = 2.51 N
    with pytest.raises(CanopenInputError, match="F_N"):
        force_to_permille(float("nan"), I_TOTAL, 1.0)
    with pytest.raises(CanopenInputError, match=r"i_total_rad_per_mm = -1.0 \[rad/mm\] must be > 0"):
        force_to_permille(1.0, -1.0, 1.0)


def test_sensor_scaling():
    assert mm_to_lvdt_um(-12.345) == -12345 and lvdt_um_to_mm(-12345) == pytest.approx(-12.345, abs=1e-15)
    assert newton_to_force_dN(6000.04) == 60000 and force_dN_to_newton(60000) == 6000.0


# ---------------------------------------------------------------------------- bus load


def _layouts():
    return (layout(1), layout(2))


def test_frame_bits():
    assert [frame_bits(n, worst_case=False) for n in (0, 1, 7, 8)] == [47, 55, 103, 111]
    assert [frame_bits(n, worst_case=True) for n in (0, 1, 7, 8)] == [55, 65, 125, 135]


def test_bus_load_two_drives_1mbit_2ms():
    load = bus_load(_layouts(), 1_000_000, 0.002, [0.1, 0.1, 0.1])  # the master counted at 100 ms too
    per_cycle = {}
    for i in load.items:
        name = i.name.split(" node")[0]
        per_cycle[name] = per_cycle.get(name, 0) + i.frames_per_cycle
    assert per_cycle == {"SYNC": 1, "RPDO1": 2, "RPDO2": 0, "TPDO1": 2, "TPDO2": 2,
                         "heartbeat": pytest.approx(0.06)}
    # nominal: 47 + 2*111 + 2*103 + 2*111 + 3 * 55 * 0.02 = 700.3 bits of 2000
    assert load.bits_per_cycle_nominal == pytest.approx(700.3)
    assert load.load_nominal == pytest.approx(0.35015)
    # worst case stuffing: 55 + 2*135 + 2*125 + 2*135 + 3 * 65 * 0.02 = 848.9 bits -> 42.4 %
    assert load.bits_per_cycle_worst == pytest.approx(848.9)
    assert load.load_worst == pytest.approx(0.42445)
    assert load.load_worst < 0.50
    # a cycle in which both drives also get a mode change (2 RPDO2): 978.9 bits, still < 50 %
    assert load.event_bits_worst == 130
    assert (load.bits_per_cycle_worst + load.event_bits_worst) / 2000 == pytest.approx(0.48945)


def test_bus_load_with_the_masters_own_heartbeat_period(actuation):
    """The shipped profile: drives' heartbeats every 100 ms, the master's every 50 ms (its own
    period, item "master heartbeat"); still inside the 50 % budget in the worst cycle; the plan
    computes the same."""
    c = actuation.canopen
    load = bus_load(_layouts(), c.bitrate_bps, actuation.timing.sync_period_s, [c.heartbeat_period_s] * 2,
                    master_heartbeat_period_s=c.master_heartbeat_period_s)
    per_cycle = {i.name: i.frames_per_cycle for i in load.items}
    assert per_cycle["heartbeat"] == pytest.approx(2 * 0.002 / 0.1)  # the two drives only
    assert per_cycle["master heartbeat"] == pytest.approx(0.002 / 0.05)
    # nominal: 700.3 - 55 * 0.02 (the master at 100 ms) + 55 * 0.04 (at 50 ms) = 701.4 bits of 2000
    assert load.bits_per_cycle_nominal == pytest.approx(701.4)
    assert load.load_nominal == pytest.approx(0.3507)
    # worst case: 848.9 - 65 * 0.02 + 65 * 0.04 = 850.2 bits -> 42.5 %; with both mode changes 49.0 %
    assert load.bits_per_cycle_worst == pytest.approx(850.2)
    assert load.load_worst == pytest.approx(0.4251) and load.load_worst < 0.5
    mode_change = (load.bits_per_cycle_worst + load.event_bits_worst) / 2000
    assert mode_change == pytest.approx(0.4901) and mode_change < 0.5
    assert shipped_rig().plan.load == load
    with pytest.raises(CanopenInputError, match="master_heartbeat_period_s"):
        bus_load(_layouts(), 1e6, 0.002, [0.1, 0.1], master_heartbeat_period_s=0.0)


def test_bus_load_inputs():
    assert bus_load(_layouts(), 500_000, 0.002, [0.0, 0.0]).load_worst == pytest.approx(845 / 1000)
    with pytest.raises(CanopenInputError, match="sync_period_s"):
        bus_load(_layouts(), 1e6, 0.0, [0.1])
    with pytest.raises(CanopenInputError, match="layouts must be a non-empty sequence of PdoLayout"):
        bus_load((), 1e6, 0.002, [0.1])
    with pytest.raises(CanopenInputError, match=r"heartbeat_periods_s\[1\] = -0.1"):
        bus_load(_layouts(), 1e6, 0.002, [0.1, -0.1])
