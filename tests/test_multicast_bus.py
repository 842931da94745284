"""udp_multicast's hop limit (``--multicast-hops``): by default the frames stay on this host.

python-can's default hop limit (1) sends every frame out of the network card as well as to the local
sockets; in a virtual machine each frame was a transmit to its host, and those sends held both loops for
milliseconds (docs/performance.md). emacheck opens udp_multicast with hop limit 0 unless told otherwise:
Linux loops a hop-limit-0 datagram back to this host's members and sends it nowhere else.
"""

from __future__ import annotations

import socket

import pytest

from hil.cli import main
from hil.cli.bus import MULTICAST_HOPS_DEFAULT, open_bus
from hil.errors import InterfaceError
from support.run_flags import assert_run_flag

can = pytest.importorskip("can")
pytest.importorskip("msgpack", reason="python-can's udp_multicast needs msgpack (a dependency of emacheck)")
# one multicast test at a time on this host (docs/testing.md, "Parallel")
pytestmark = pytest.mark.xdist_group("udp_multicast")

GROUP_V4 = "239.74.201.9"
GROUP_V6 = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173"


def _pair(group: str, hops: int | None):
    try:
        return open_bus("udp_multicast", group, 500_000, multicast_hops=hops), \
            open_bus("udp_multicast", group, 500_000, multicast_hops=hops)
    except InterfaceError as exc:
        pytest.skip(f"udp_multicast cannot be opened on this host (no multicast route?): {exc}")


def _hops(bus, group: str) -> int:
    sock = bus._multicast._socket  # python-can's GeneralPurposeUdpMulticastBus: the socket it sends with
    if ":" in group:
        return sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS)
    return sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL)


@pytest.mark.parametrize("group", [GROUP_V4, GROUP_V6])
@pytest.mark.parametrize("hops,expected", [(None, 0), (0, 0), (1, 1), (255, 255)])
def test_the_hop_limit_is_the_one_asked_for_and_0_by_default(group, hops, expected):
    """The socket's hop limit as Linux reports it; a frame sent still reaches another bus on this host."""
    assert MULTICAST_HOPS_DEFAULT == 0
    a, b = _pair(group, hops)
    try:
        assert _hops(a, group) == expected and _hops(b, group) == expected
        a.send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
        got = b.recv(2.0)
        assert got is not None and got.arbitration_id == 0x80
    finally:
        a.shutdown()
        b.shutdown()


def test_a_hop_limit_for_another_interface_is_refused_naming_the_flag():
    with pytest.raises(InterfaceError, match=r"--multicast-hops 1: applies to --interface udp_multicast only "
                                             r"\(not 'virtual'\)"):
        open_bus("virtual", "x", 500_000, multicast_hops=1)


@pytest.mark.parametrize("command,module", [(["run", "--arm"], "hil.cli.run"), (["sim-serve"], "hil.cli.sim_serve")])
@pytest.mark.parametrize("flag,expected", [([], None), (["--multicast-hops", "7"], 7)])
def test_both_commands_pass_the_flag_to_the_bus(command, module, flag, expected, monkeypatch, capsys):
    """The value given (None when not) reaches open_bus; the spy then refuses the bus (exit 3, one line)."""
    import importlib

    seen = []

    def spy(interface, channel, bitrate, **kw):
        seen.append(kw.get("multicast_hops"))
        raise InterfaceError("spy: no bus")

    monkeypatch.setattr(importlib.import_module(module), "open_bus", spy)
    rc = main([*command, "--interface", "udp_multicast", "--channel", GROUP_V4, *flag])
    out = capsys.readouterr()
    assert rc == 3 and seen == [expected]
    assert "spy: no bus" in out.out + out.err and "Traceback" not in out.out + out.err


@pytest.mark.parametrize("value,ok", [("0", True), ("255", True), ("-1", False), ("256", False), ("1.5", False)])
def test_the_flag_takes_0_to_255(value, ok, capsys):
    """On its boundaries: 0 and 255 are taken, -1, 256 and 1.5 refused with the flag named (exit 3, no
    traceback). (Without --arm, run refuses to move anything after parsing: exit 3 either way, so the
    message tells which.)"""
    assert_run_flag(["run", "--interface", "udp_multicast", "--channel", GROUP_V4, "--multicast-hops", value],
                    "--multicast-hops", ok, capsys)


@pytest.mark.parametrize("interface,channel,flag,expected", [
    ("udp_multicast", GROUP_V4, [], MULTICAST_HOPS_DEFAULT),
    ("udp_multicast", GROUP_V4, ["--multicast-hops", "1"], 1),
    ("virtual", "emacheck-hops-record", [], None),
])
def test_run_records_the_hop_limit_it_opened_the_bus_with(interface, channel, flag, expected, monkeypatch, capsys,
                                                          tmp_path):
    """meta.json's bus part says which hop limit the frames had (udp_multicast only; another interface has
    no such key). A spy takes the record's bus part and ends the run there (exit 3)."""
    import hil.record.runrecord

    seen = []

    def spy(*args, bus=None, **kw):
        seen.append(bus)
        raise InterfaceError("spy: stop after the record's bus part")

    monkeypatch.setattr(hil.record.runrecord, "start_record", spy)
    rc = main(["run", "--arm", "--interface", interface, "--channel", channel, "--out", str(tmp_path / "r"), *flag])
    capsys.readouterr()
    assert rc == 3 and len(seen) == 1
    assert seen[0].multicast_hops == expected
    assert ("multicast_hops" in seen[0].as_json()) is (expected is not None)


# --- two buses on two groups on one host: no frame crosses (IP_MULTICAST_ALL off) ---

OTHER_V4 = "239.74.201.10"
OTHER_V6 = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6174"


def _multicast_all(bus, group: str) -> int:
    sock = bus._multicast._socket
    if ":" in group:
        return sock.getsockopt(socket.IPPROTO_IPV6, 29)  # IPV6_MULTICAST_ALL
    return sock.getsockopt(socket.IPPROTO_IP, 49)  # IP_MULTICAST_ALL


@pytest.mark.skipif(not hasattr(socket, "AF_NETLINK"), reason="IP_MULTICAST_ALL is Linux's")
@pytest.mark.parametrize("group,other", [(GROUP_V4, OTHER_V4), (GROUP_V6, OTHER_V6)])
def test_two_buses_on_two_groups_do_not_hear_each_other(group, other):
    """Each bus hears its own group (a second bus on it gets the frame) and nothing of the other group;
    python-can alone (the option left on) delivers the other group's frames too (checked first, so the
    test shows the host would leak)."""
    try:
        raw = can.Bus(interface="udp_multicast", channel=other, hop_limit=0)
    except Exception as exc:  # noqa: BLE001 - a host without multicast routes
        pytest.skip(f"udp_multicast cannot be opened on this host: {exc}")
    a, a2 = _pair(group, None)
    b = open_bus("udp_multicast", other, 500_000)
    try:
        assert _multicast_all(a, group) == 0 and _multicast_all(b, other) == 0 and _multicast_all(raw, other) == 1
        for k in range(20):
            a.send(can.Message(arbitration_id=0x100 + k, data=bytes([k]), is_extended_id=False))
        got_own = [a2.recv(1.0) for _ in range(20)]
        assert [m.arbitration_id for m in got_own if m is not None] == [0x100 + k for k in range(20)]
        leaked = raw.recv(0.5)
        assert leaked is not None and leaked.arbitration_id == 0x100  # the host does deliver across groups
        assert b.recv(0.5) is None  # emacheck's bus on the other group: nothing crosses
        b.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))
        heard = [m.arbitration_id for bus in (a, a2) for m in iter(lambda bus=bus: bus.recv(0.3), None)]
        assert 0x7FF not in heard  # what a and a2 still hold: a's own echoes of its 20 frames, nothing of b
        assert sorted(set(heard)) == [0x100 + k for k in range(20)]
    finally:
        for bus in (a, a2, b, raw):
            bus.shutdown()


def test_a_bus_that_cannot_be_isolated_is_closed_and_refused(monkeypatch):
    """Fail closed: if python-can's socket cannot be reached, the bus is shut down and open_bus refuses it."""
    closed = []

    class Opaque:
        def shutdown(self):
            closed.append(True)

    monkeypatch.setattr(can, "Bus", lambda **kw: Opaque())
    monkeypatch.setattr("sys.platform", "linux")
    with pytest.raises(InterfaceError, match=r"udp_multicast group '239\.74\.201\.9': cannot make the bus hear its "
                                             r"own group only \(AttributeError"):
        open_bus("udp_multicast", GROUP_V4, 500_000)
    assert closed == [True]
