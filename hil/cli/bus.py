"""The CAN bus of a command: a python-can bus opened with a message that says what to check, and
udp_multicast kept to its own group on this host.
"""

from __future__ import annotations

import sys

#: udp_multicast's hop limit when --multicast-hops is not given: the frames never leave this host. With
#: python-can's default (1) every frame also went out of the network card: in a virtual machine each
#: was a transmit to its host, and the sends held both loops for milliseconds (docs/performance.md)
MULTICAST_HOPS_DEFAULT = 0


def multicast_hops_for(interface: str, multicast_hops: int | None) -> int | None:
    """The IP hop limit a bus on ``interface`` is opened with: udp_multicast's (``multicast_hops``, else
    :data:`MULTICAST_HOPS_DEFAULT`), None for any other interface (where ``--multicast-hops`` is refused)."""
    if interface == "udp_multicast":
        return MULTICAST_HOPS_DEFAULT if multicast_hops is None else multicast_hops
    return None


def open_bus(interface: str, channel: str, bitrate: int, *, receive_own_messages: bool = False,
             multicast_hops: int | None = None):
    """A python-can bus, or :class:`hil.errors.InterfaceError` saying what to check (exit status 3).

    ``multicast_hops``: udp_multicast's IP hop limit (default :data:`MULTICAST_HOPS_DEFAULT`: this host
    only); given for another interface, it is refused.
    """
    import can

    from hil.errors import InterfaceError

    kwargs = {"interface": interface, "channel": channel}
    if interface not in ("virtual", "socketcan", "udp_multicast"):
        kwargs["bitrate"] = bitrate
    if receive_own_messages:
        kwargs["receive_own_messages"] = True
    if interface == "udp_multicast":
        kwargs["hop_limit"] = multicast_hops_for(interface, multicast_hops)
    elif multicast_hops is not None:
        raise InterfaceError(f"--multicast-hops {multicast_hops}: applies to --interface udp_multicast only "
                             f"(not {interface!r})")
    try:
        bus = can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        hint = ("check that the interface exists and is up (`ip link show {ch}`; "
                "`sudo ip link set {ch} up type can bitrate {br}`)" if interface == "socketcan" else
                "check that the adapter is connected, its driver installed and the channel name right")
        known = ", ".join(sorted(getattr(can, "VALID_INTERFACES", ()))) or "see python-can"
        raise InterfaceError(
            f"cannot open CAN interface {interface!r} channel {channel!r}: {type(exc).__name__}: {exc}; "
            + hint.format(ch=channel, br=bitrate) + f"; --interface must be one python-can knows ({known})"
        ) from None
    if interface == "udp_multicast":
        _hear_own_group_only(bus, channel)
    return bus


#: Linux's socket options that make a socket bound to a port on every address receive only the multicast
#: groups it joined itself (linux/in.h IP_MULTICAST_ALL, linux/in6.h IPV6_MULTICAST_ALL; default 1: every
#: group joined by any socket on the host)
_IP_MULTICAST_ALL = 49


_IPV6_MULTICAST_ALL = 29


def _hear_own_group_only(bus, channel: str) -> None:
    """Make a udp_multicast bus receive its own group only (Linux), or close it and refuse (fail closed).

    python-can binds the port on every address; on Linux such a socket receives every group joined on the
    host (IP_MULTICAST_ALL defaults to on), so two emacheck buses on two groups would hear each other: a
    check took another job's SDO answer. Turning the option off leaves exactly the group the bus joined.
    Other systems are left as python-can opens them (not verified there; docs/vcan.md).
    """
    import socket

    from hil.errors import InterfaceError

    if not sys.platform.startswith("linux"):
        return
    try:
        sock = bus._multicast._socket  # python-can's GeneralPurposeUdpMulticastBus: its one socket
        if ":" in channel:
            sock.setsockopt(socket.IPPROTO_IPV6, _IPV6_MULTICAST_ALL, 0)
        else:
            sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
    except (AttributeError, OSError) as exc:
        bus.shutdown()
        raise InterfaceError(
            f"udp_multicast group {channel!r}: cannot make the bus hear its own group only "
            f"({type(exc).__name__}: {exc}); without it, it would receive every group joined on this host"
        ) from None
