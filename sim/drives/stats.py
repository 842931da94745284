"""The counters of the simulated nodes (:class:`sim.drives.SimDrivePair` shares one set among them)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SimPairStats"]


@dataclass(frozen=True, slots=True)
class SimPairStats:
    """Counters of a :class:`~sim.drives.SimDrivePair` (a snapshot; all its nodes together).

    Attributes
    ----------
    syncs : int
        SYNC frames processed.
    plant_steps : int
        Calls of ``plant.step`` on a SYNC (one per SYNC plus one at the first power-on).
    free_steps : int
        Calls of ``plant.step`` by the drives' own cycle while SYNC is missing.
    tpdos_sent : int
        TPDO frames transmitted.
    rpdos_applied : int
        RPDOs written into a data store (synchronous ones at their SYNC).
    rpdos_late : int
        Latched synchronous RPDOs overwritten by a newer one before their
        SYNC (the older one missed its cycle).
    rpdos_dropped : int
        RPDOs not processed: node not OPERATIONAL, or wrong length.
    bad_frames_ignored : int
        Frames no node consumes (unknown COB-ID, another node's traffic,
        NMT for other nodes) or that are malformed (NMT not 2 bytes, SYNC
        over 1 byte, SDO request not 8 bytes, unknown NMT command).
    frames_unpowered : int
        Frames received before :meth:`SimDrivePair.power_on`.
    sdo_requests : int
        SDO request frames served.
    illegal_commands : int
        Controlwords refused by the CiA 402 state machine.
    emcys_sent, heartbeats_sent : int
        EMCY and heartbeat frames transmitted (boot-up frames excluded).
    """

    syncs: int = 0
    plant_steps: int = 0
    free_steps: int = 0
    tpdos_sent: int = 0
    rpdos_applied: int = 0
    rpdos_late: int = 0
    rpdos_dropped: int = 0
    bad_frames_ignored: int = 0
    frames_unpowered: int = 0
    sdo_requests: int = 0
    illegal_commands: int = 0
    emcys_sent: int = 0
    heartbeats_sent: int = 0


class PairCounters:
    """Mutable counters shared by the pair and its nodes."""

    __slots__ = SimPairStats.__slots__

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def snapshot(self) -> SimPairStats:
        return SimPairStats(**{name: getattr(self, name) for name in self.__slots__})
