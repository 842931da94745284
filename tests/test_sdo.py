"""SDO client: golden frames, segmented transfers, aborts, timeout, interop with canopen's SdoServer."""

from __future__ import annotations

import struct

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from hil.canopen.errors import CanopenError
from hil.canopen.frame import Frame
from hil.canopen.od import load_eds
from hil.canopen.sdo import (
    SdoAbortCode,
    SdoAbortError,
    SdoClient,
    SdoEvent,
    SdoTimeout,
    SdoTransfer,
    SdoUsageError,
    abort_frame,
    describe,
)


def F(can_id: int, hexdata: str) -> Frame:
    return Frame(can_id, bytes.fromhex(hexdata))


# ---------------------------------------------------------------------------- golden frames


def test_expedited_download_golden():
    c = SdoClient(2)
    req = c.start_download(0x1017, 0, struct.pack("<H", 100), t=1.0)
    assert req == F(0x602, "2B 17 10 00 64 00 00 00")
    assert c.busy
    ev = c.on_frame(F(0x582, "60 17 10 00 00 00 00 00"), t=1.004)
    assert ev == SdoEvent(2, SdoTransfer.DOWNLOAD, 0x1017, 0, b"\x64\x00", 1.0, 1.004)
    assert not c.busy


@pytest.mark.parametrize("data,cmd", [(b"\x08", "2F"), (b"\x01\x02", "2B"), (b"\x01\x02\x03", "27"),
                                      (b"\xE8\x03\x00\x00", "23")])
def test_expedited_download_size_bits(data, cmd):
    req = SdoClient(1).start_download(0x6060, 0, data, t=0.0)
    assert req.data == bytes.fromhex(cmd + "60 60 00") + data.ljust(4, b"\x00")
    assert req.arbitration_id == 0x601


def test_expedited_upload_golden():
    c = SdoClient(2)
    assert c.start_upload(0x6041, 0, t=0.0) == F(0x602, "40 41 60 00 00 00 00 00")
    ev = c.on_frame(F(0x582, "4B 41 60 00 37 02 00 00"), t=0.001)
    assert ev.transfer is SdoTransfer.UPLOAD and ev.data == b"\x37\x02"


def test_segmented_upload_golden_toggles():
    c = SdoClient(2)
    assert c.start_upload(0x1008, 0, t=0.0) == F(0x602, "40 08 10 00 00 00 00 00")
    # initiate response: segmented, size indicated = 9
    assert c.on_frame(F(0x582, "41 08 10 00 09 00 00 00"), t=0.001) == F(0x602, "60 00 00 00 00 00 00 00")
    # segment toggle 0, 7 bytes, more to come -> request with toggle 1
    assert c.on_frame(F(0x582, "00 45 4D 41 20 64 72 69"), t=0.002) == F(0x602, "70 00 00 00 00 00 00 00")
    # segment toggle 1, 5 bytes unused, last
    ev = c.on_frame(F(0x582, "1B 76 65 00 00 00 00 00"), t=0.003)
    assert ev.data == b"EMA drive" and (ev.index, ev.subindex) == (0x1008, 0)


def test_segmented_download_golden():
    c = SdoClient(2)
    assert c.start_download(0x2000, 1, b"EMA drive 2", t=0.0) == F(0x602, "21 00 20 01 0B 00 00 00")
    assert c.on_frame(F(0x582, "60 00 20 01 00 00 00 00"), 0.001) == F(0x602, "00 45 4D 41 20 64 72 69")
    assert c.on_frame(F(0x582, "20 00 00 00 00 00 00 00"), 0.002) == F(0x602, "17 76 65 20 32 00 00 00")
    ev = c.on_frame(F(0x582, "30 00 00 00 00 00 00 00"), 0.003)
    assert ev.transfer is SdoTransfer.DOWNLOAD and ev.data == b"EMA drive 2"


# ---------------------------------------------------------------------------- aborts


def test_server_abort_decoded_with_meaning():
    c = SdoClient(2)
    c.start_download(0x607D, 1, struct.pack("<i", 10**9), t=0.0)
    with pytest.raises(SdoAbortError) as exc:
        c.on_frame(F(0x582, "80 7D 60 01 30 00 09 06"), t=0.001)
    e = exc.value
    assert str(e) == "node 2: SDO abort 0x06090030 (value range of parameter exceeded) on 0x607D:01"
    assert e.code is SdoAbortCode.VALUE_RANGE_EXCEEDED and e.abort_frame is None
    assert (e.node_id, e.index, e.subindex) == (2, 0x607D, 1)
    assert isinstance(e, CanopenError) and isinstance(e, IOError)
    assert not c.busy


def test_unknown_abort_code():
    assert describe(0x0F00_0001) == "unknown abort code"
    e = SdoAbortError(3, 0x2100, 0, 0x0F00_0001)
    assert e.code == 0x0F00_0001 and "0x0F000001 (unknown abort code) on 0x2100:00" in str(e)


def test_toggle_error_aborts_to_server():
    c = SdoClient(2)
    c.start_upload(0x1008, 0, t=0.0)
    c.on_frame(F(0x582, "41 08 10 00 09 00 00 00"), t=0.001)
    with pytest.raises(SdoAbortError) as exc:
        c.on_frame(F(0x582, "10 45 4D 41 20 64 72 69"), t=0.002)  # toggle 1, expected 0
    e = exc.value
    assert e.code is SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED
    assert e.abort_frame == F(0x602, "80 08 10 00 00 00 03 05")
    assert "toggle bit not alternated" in str(e) and "aborted by the client" in str(e)
    assert not c.busy


def test_wrong_multiplexer_and_command_specifier():
    c = SdoClient(2)
    c.start_upload(0x6041, 0, t=0.0)
    with pytest.raises(SdoAbortError, match="0x6064:00, expected 0x6041:00") as exc:
        c.on_frame(F(0x582, "4B 64 60 00 00 00 00 00"), t=0.001)
    assert exc.value.code is SdoAbortCode.GENERAL_ERROR
    c.start_upload(0x6041, 0, t=0.0)
    with pytest.raises(SdoAbortError) as exc:
        c.on_frame(F(0x582, "60 41 60 00 00 00 00 00"), t=0.001)  # download response to an upload
    assert exc.value.abort_frame == F(0x602, "80 41 60 00 01 00 04 05")


def test_segmented_upload_longer_than_indicated():
    c = SdoClient(2)
    c.start_upload(0x1008, 0, t=0.0)
    c.on_frame(F(0x582, "41 08 10 00 03 00 00 00"), t=0.0)
    with pytest.raises(SdoAbortError) as exc:
        c.on_frame(F(0x582, "01 45 4D 41 20 64 72 69"), t=0.0)
    assert exc.value.code is SdoAbortCode.LENGTH_TOO_HIGH


def test_client_abort_and_abort_frame():
    assert abort_frame(2, 0x1017, 0, SdoAbortCode.GENERAL_ERROR) == F(0x602, "80 17 10 00 00 00 00 08")
    c = SdoClient(5)
    c.start_upload(0x1000, 0, t=0.0)
    assert c.abort(SdoAbortCode.CANNOT_TRANSFER_DEVICE_STATE) == F(0x605, "80 00 10 00 22 00 00 08")
    assert not c.busy
    with pytest.raises(SdoUsageError):
        c.abort()


def test_abort_codes_complete():
    codes = [0x05030000, 0x05040000, 0x05040001, 0x05040002, 0x05040003, 0x05040004, 0x05040005,
             0x06010000, 0x06010001, 0x06010002, 0x06020000, 0x06040041, 0x06040042, 0x06040043,
             0x06040047, 0x06060000, 0x06070010, 0x06070012, 0x06070013, 0x06090011, 0x06090030,
             0x06090031, 0x06090032, 0x06090036, 0x060A0023, 0x08000000, 0x08000020, 0x08000021,
             0x08000022, 0x08000023, 0x08000024]
    assert sorted(int(c) for c in SdoAbortCode) == codes
    assert set(codes) == set(SdoAbortedError.CODES)  # the same list as canopen's
    assert SdoAbortCode(0x06010002).meaning == "attempt to write a read only object"
    assert SdoAbortCode(0x06020000).meaning == "object does not exist in the object dictionary"
    assert SdoAbortCode(0x05040000).meaning == "SDO protocol timed out"
    assert all(describe(c) == SdoAbortCode(c).meaning for c in codes)


# ---------------------------------------------------------------------------- timing, filtering


def test_timeout_with_explicit_time():
    c = SdoClient(2, timeout_s=0.5)
    c.start_upload(0x1008, 0, t=10.0)
    c.poll(10.499)
    assert c.busy
    with pytest.raises(SdoTimeout) as exc:
        c.poll(10.5)
    e = exc.value
    assert e.abort_frame == F(0x602, "80 08 10 00 00 00 04 05")
    assert str(e) == "node 2: SDO timeout, no response within 0.5 s on 0x1008:00"
    assert isinstance(e, TimeoutError) and isinstance(e, CanopenError)
    assert not c.busy
    assert c.on_frame(F(0x582, "41 08 10 00 09 00 00 00"), t=10.6) is None  # late answer dropped


def test_timeout_runs_per_request():
    c = SdoClient(2, timeout_s=0.5)
    c.start_upload(0x1008, 0, t=0.0)
    c.on_frame(F(0x582, "41 08 10 00 09 00 00 00"), t=0.4)  # segment request sent at 0.4
    c.poll(0.8)
    with pytest.raises(SdoTimeout):
        c.poll(0.9)


def test_one_transfer_at_a_time_and_foreign_frames():
    c = SdoClient(2)
    assert c.on_frame(F(0x582, "60 17 10 00 00 00 00 00"), 0.0) is None  # idle: dropped
    c.start_upload(0x1000, 0, t=0.0)
    with pytest.raises(SdoUsageError, match="0x1000:00 still in progress"):
        c.start_download(0x1017, 0, b"\x64\x00", t=0.0)
    assert c.on_frame(F(0x583, "43 00 10 00 92 01 02 00"), 0.0) is None  # other node
    assert c.on_frame(F(0x182, "50 02 00 00 00 00 08"), 0.0) is None  # a PDO
    assert c.busy


# ---------------------------------------------------------------------------- interop with canopen


class CollectingBus:
    """Stands in for a python-can bus: collects what the server sends, no threads."""

    def __init__(self) -> None:
        self.sent: list = []

    def send(self, msg) -> None:
        self.sent.append(msg)


@pytest.fixture(scope="module")
def od():
    return load_eds(node_id=2)


@pytest.fixture()
def server(od):
    bus = CollectingBus()
    network = canopen.Network(bus)
    node = canopen.LocalNode(2, od)
    network.add_node(node)
    return network, bus, node


def transfer(server, client: SdoClient, first: Frame) -> SdoEvent:
    """Feed the client's frames to the server and the replies back, until the transfer ends."""
    network, bus, _ = server
    frame, t = first, 0.0
    for _ in range(64):
        network.notify(frame.arbitration_id, bytearray(frame.data), t)
        replies, bus.sent = bus.sent, []
        assert len(replies) == 1
        t += 0.001
        out = client.on_frame(Frame(replies[0].arbitration_id, bytes(replies[0].data)), t)
        if isinstance(out, SdoEvent):
            return out
        assert isinstance(out, Frame)
        frame = out
    raise AssertionError("transfer did not end")


def test_interop_expedited_download_and_upload(server):
    c = SdoClient(2)
    ev = transfer(server, c, c.start_download(0x1006, 0, struct.pack("<I", 2000), 0.0))
    assert ev.transfer is SdoTransfer.DOWNLOAD
    ev = transfer(server, c, c.start_download(0x6060, 0, struct.pack("<b", 10), 0.0))
    assert server[2].data_store[0x6060][0] == b"\x0a"
    ev = transfer(server, c, c.start_upload(0x6060, 0, 0.0))
    assert ev.data == b"\x0a"
    ev = transfer(server, c, c.start_upload(0x1018, 1, 0.0))
    assert struct.unpack("<I", ev.data)[0] == 0x00000E3A


def test_interop_segmented_upload_of_device_name(server):
    c = SdoClient(2)
    ev = transfer(server, c, c.start_upload(0x1008, 0, 0.0))
    assert ev.data == b"EMA drive"


@pytest.mark.parametrize("index,sub,data,code", [
    (0x5000, 0, None, SdoAbortCode.OBJECT_DOES_NOT_EXIST),
    (0x1018, 7, None, SdoAbortCode.SUBINDEX_DOES_NOT_EXIST),
    (0x6041, 0, b"\x06\x00", SdoAbortCode.WRITE_OF_READ_ONLY),
    (0x1017, 0, b"\x64\x00\x00\x00", SdoAbortCode.LENGTH_MISMATCH),  # u16 written as 4 bytes
    (0x1006, 0, b"\x01\x02\x03\x04\x05", SdoAbortCode.LENGTH_MISMATCH),  # segmented, aborted at the end
])
def test_interop_aborts(server, index, sub, data, code):
    c = SdoClient(2)
    first = c.start_upload(index, sub, 0.0) if data is None else c.start_download(index, sub, data, 0.0)
    with pytest.raises(SdoAbortError) as exc:
        transfer(server, c, first)
    assert exc.value.code is code and exc.value.abort_frame is None
    assert f"on 0x{index:04X}:{sub:02X}" in str(exc.value)
    assert not c.busy
