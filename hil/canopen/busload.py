"""CAN bus load of the cyclic CANopen traffic (frame lengths with and without bit stuffing).

The master refuses a profile whose worst-case load reaches 50 %
(:mod:`hil.cli.bus`). Sans-IO.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from hil.canopen.errors import CanopenInputError
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
        SYNC, every PDO of every node and the heartbeats.
    bits_per_cycle_nominal, bits_per_cycle_worst : float
        Sum of ``frames_per_cycle * bits_per_frame`` without / with worst-case stuffing.
    load_nominal, load_worst : float
        Fraction of the bit rate: bits per cycle / (bit rate * SYNC period).
    event_bits_worst : float
        Worst-case bits of sending every event-driven PDO once (the cycle in
        which the master changes the mode of both drives); not included in
        ``bits_per_cycle_*``.
    n_nodes : int
        Nodes with a PDO layout.
    """

    bitrate_bps: float
    sync_period_s: float
    n_nodes: int
    items: tuple[BusLoadItem, ...]
    bits_per_cycle_nominal: float
    bits_per_cycle_worst: float
    load_nominal: float
    load_worst: float
    event_bits_worst: float


def bus_load(
    layouts: Sequence[PdoLayout],
    bitrate_bps: float,
    sync_period_s: float,
    heartbeat_periods_s: Sequence[float],
    *,
    master_heartbeat_period_s: float | None = None,
) -> BusLoad:
    """Bits per SYNC cycle and bus load of the cyclic CANopen traffic.

    Parameters
    ----------
    layouts : sequence of PdoLayout
        The PDO layout of every node (the drives and the sensor nodes).
    bitrate_bps : float
        CAN bit rate [bit/s], > 0.
    sync_period_s : float
        SYNC (communication cycle) period [s], > 0.
    heartbeat_periods_s : sequence of float
        Heartbeat producer time of every node [s], each > 0 or 0 for none.
    master_heartbeat_period_s : float, optional
        The master's heartbeat producer time [s], > 0 (item ``"master heartbeat"``); None: no
        master heartbeat.

    Returns
    -------
    BusLoad

    Notes
    -----
    Per cycle: one SYNC (0 bytes), one frame of every synchronous PDO with
    transmission type ``k`` every ``k`` SYNCs, :math:`T_{sync}/T_{hb}`
    heartbeats (1 byte) per node and :math:`T_{sync}/T_m` master heartbeats.
    Event-driven PDOs (type >= 241) are listed with 0 frames per cycle. Frame
    lengths as in :func:`frame_bits`:

    .. math:: b = 47 + 8n \\;(+\\lfloor (34 + 8n - 1)/4 \\rfloor \\text{ worst case}),
              \\qquad U = \\frac{\\sum_i f_i \\, b_i}{R \\, T_{sync}}

    SDO traffic (configuration before the cyclic phase) is not included.
    """
    layouts = tuple(layouts)
    if not layouts or not all(isinstance(x, PdoLayout) for x in layouts):
        raise CanopenInputError(f"layouts must be a non-empty sequence of PdoLayout, got {layouts!r}")
    rate = positive("bitrate_bps", bitrate_bps, "bit/s")
    t_sync = positive("sync_period_s", sync_period_s, "s")
    periods = []
    for k, p in enumerate(heartbeat_periods_s):
        t_hb = finite(f"heartbeat_periods_s[{k}]", p, "s")
        if t_hb < 0.0:
            raise CanopenInputError(f"heartbeat_periods_s[{k}] = {t_hb} [s] must be >= 0 (0 = no heartbeat)")
        periods.append(t_hb)
    t_master = None
    if master_heartbeat_period_s is not None:
        t_master = positive("master_heartbeat_period_s", master_heartbeat_period_s, "s")

    def item(name: str, n_bytes: int, per_cycle: float) -> BusLoadItem:
        return BusLoadItem(name, n_bytes, per_cycle,
                           frame_bits(n_bytes, worst_case=False), frame_bits(n_bytes, worst_case=True))

    items = [item("SYNC", 0, 1.0)]
    event_bits = 0.0
    for layout in layouts:
        for p in layout.pdos:
            name = f"{p.name} node {layout.node_id}"
            if p.is_synchronous:
                items.append(item(name, p.length_bytes, 1.0 / p.transmission_type))
            else:
                it = item(name, p.length_bytes, 0.0)
                items.append(it)
                event_bits += it.bits_per_frame_worst
    hb_per_cycle = sum(t_sync / t for t in periods if t > 0.0)
    items.append(item("heartbeat", 1, hb_per_cycle))
    if t_master is not None:
        items.append(item("master heartbeat", 1, t_sync / t_master))

    nominal = sum(i.frames_per_cycle * i.bits_per_frame_nominal for i in items)
    worst = sum(i.frames_per_cycle * i.bits_per_frame_worst for i in items)
    capacity = rate * t_sync
    return BusLoad(rate, t_sync, len(layouts), tuple(items), nominal, worst, nominal / capacity,
                   worst / capacity, event_bits)
