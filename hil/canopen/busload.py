"""CAN bus load of the cyclic CANopen traffic (frame lengths with and without bit stuffing).

The master refuses a profile whose worst-case load reaches 50 %
(:mod:`hil.cli.common`). Sans-IO.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

from hil.canopen.errors import InputError
from hil.canopen.pdo import PdoLayout
from hil.canopen.validate import finite, integer, positive

FRAME_OVERHEAD_BITS = 47
"""Bits of a standard (11-bit) data frame besides the data field, including the
3-bit interframe space: SOF 1 + identifier 11 + RTR 1 + IDE 1 + r0 1 + DLC 4 +
CRC 15 + CRC delimiter 1 + ACK slot 1 + ACK delimiter 1 + EOF 7 + IFS 3."""


def frame_bits(n_bytes: int, *, worst_case: bool) -> int:
    """Bits on the bus of one standard data frame with ``n_bytes`` data bytes.

    Notes
    -----
    Nominal :math:`47 + 8n`; worst case adds the maximum number of stuff bits,
    which can occur in the 34 + 8n bits from SOF to the end of the CRC:
    :math:`\\lfloor (34 + 8n - 1) / 4 \\rfloor`. 8 bytes: 111 / 135 bits.
    """
    n = integer("n_bytes", n_bytes, 0, 8)
    bits = FRAME_OVERHEAD_BITS + 8 * n
    if worst_case:
        bits += (34 + 8 * n - 1) // 4
    return bits


@dataclass(frozen=True, slots=True)
class BusLoadItem:
    """One kind of frame in the bus load.

    ``frames_per_cycle`` may be fractional (heartbeats) or 0 (event-driven PDOs).
    """

    name: str
    data_bytes: int
    frames_per_cycle: float
    bits_per_frame_nominal: int
    bits_per_frame_worst: int


@dataclass(frozen=True, slots=True)
class BusLoad:
    """Bus load of one SYNC cycle.

    Attributes
    ----------
    items : tuple of BusLoadItem
        SYNC, every PDO of the layout (all drives together) and the heartbeats.
    bits_per_cycle_nominal, bits_per_cycle_worst : float
        Sum of ``frames_per_cycle * bits_per_frame`` without / with worst-case stuffing.
    load_nominal, load_worst : float
        Fraction of the bit rate: bits per cycle / (bit rate * SYNC period).
    event_bits_worst : float
        Worst-case bits of sending every event-driven PDO once to every drive
        (the cycle in which the master changes the mode of both drives); not
        included in ``bits_per_cycle_*``.
    """

    bitrate_bps: float
    sync_period_s: float
    n_drives: int
    items: tuple[BusLoadItem, ...]
    bits_per_cycle_nominal: float
    bits_per_cycle_worst: float
    load_nominal: float
    load_worst: float
    event_bits_worst: float


def bus_load(
    layout: PdoLayout,
    n_drives: int,
    bitrate_bps: float,
    sync_period_s: float,
    heartbeat_period_s: float,
    *,
    heartbeat_producers: int | None = None,
    master_heartbeat_period_s: float | None = None,
) -> BusLoad:
    """Bits per SYNC cycle and bus load of the cyclic CANopen traffic.

    Parameters
    ----------
    layout : PdoLayout
        PDO layout of every drive.
    n_drives : int
        Number of drives, >= 1.
    bitrate_bps : float
        CAN bit rate [bit/s], > 0.
    sync_period_s : float
        SYNC (communication cycle) period [s], > 0.
    heartbeat_period_s : float
        Heartbeat producer time [s], > 0, or 0 for no heartbeats.
    heartbeat_producers : int, optional
        Number of heartbeat producers at ``heartbeat_period_s``; default
        ``n_drives + 1`` (every drive and the master, whose heartbeat the
        drives consume via 0x1016), or ``n_drives`` when the master's own
        period is given.
    master_heartbeat_period_s : float, optional
        The master's heartbeat producer time [s], > 0: one more producer at
        its own period (item ``"master heartbeat"``). None: the master is
        counted among ``heartbeat_producers`` at ``heartbeat_period_s``.

    Returns
    -------
    BusLoad

    Notes
    -----
    Per cycle: one SYNC (0 bytes), for every drive one frame of every
    synchronous PDO with transmission type ``k`` every ``k`` SYNCs,
    ``producers * T_sync / T_hb`` heartbeats (1 byte) and, with the master's
    own period :math:`T_m`, ``T_sync / T_m`` master heartbeats. Event-driven PDOs
    (type >= 241) are listed with 0 frames per cycle. Frame lengths as in
    :func:`frame_bits`:

    .. math:: b = 47 + 8n \\;(+\\lfloor (34 + 8n - 1)/4 \\rfloor \\text{ worst case}),
              \\qquad U = \\frac{\\sum_i f_i \\, b_i}{R \\, T_{sync}}

    SDO traffic (configuration before the cyclic phase) is not included.
    """
    if not isinstance(layout, PdoLayout):
        raise InputError(f"layout must be a PdoLayout, got {type(layout).__name__}")
    nd = operator.index(n_drives)
    if nd < 1:
        raise InputError(f"n_drives = {nd} must be >= 1")
    rate = positive("bitrate_bps", bitrate_bps, "bit/s")
    t_sync = positive("sync_period_s", sync_period_s, "s")
    t_hb = finite("heartbeat_period_s", heartbeat_period_s, "s")
    if t_hb < 0.0:
        raise InputError(f"heartbeat_period_s = {t_hb} [s] must be >= 0 (0 = no heartbeat)")
    t_master = None
    if master_heartbeat_period_s is not None:
        t_master = positive("master_heartbeat_period_s", master_heartbeat_period_s, "s")
    default_producers = nd + 1 if t_master is None else nd
    producers = default_producers if heartbeat_producers is None else operator.index(heartbeat_producers)
    if producers < 0:
        raise InputError(f"heartbeat_producers = {producers} must be >= 0")

    def item(name: str, n_bytes: int, per_cycle: float) -> BusLoadItem:
        return BusLoadItem(name, n_bytes, per_cycle,
                           frame_bits(n_bytes, worst_case=False), frame_bits(n_bytes, worst_case=True))

    items = [item("SYNC", 0, 1.0)]
    event_bits = 0.0
    for p in layout.pdos:
        if p.is_synchronous:
            items.append(item(p.name, p.length_bytes, nd / p.transmission_type))
        else:
            it = item(p.name, p.length_bytes, 0.0)
            items.append(it)
            event_bits += nd * it.bits_per_frame_worst
    hb_per_cycle = producers * t_sync / t_hb if t_hb > 0.0 else 0.0
    items.append(item("heartbeat", 1, hb_per_cycle))
    if t_master is not None:
        items.append(item("master heartbeat", 1, t_sync / t_master))

    nominal = sum(i.frames_per_cycle * i.bits_per_frame_nominal for i in items)
    worst = sum(i.frames_per_cycle * i.bits_per_frame_worst for i in items)
    capacity = rate * t_sync
    return BusLoad(rate, t_sync, nd, tuple(items), nominal, worst, nominal / capacity, worst / capacity,
                   event_bits)
