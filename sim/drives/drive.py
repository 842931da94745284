"""One simulated EMA drive: a CANopen slave (:class:`~sim.drives.node.SimNode`) with a CiA 402 drive core.

:class:`SimDrive` is the common slave of :mod:`sim.drives.node` (object
store, SDO server, NMT slave, PDO engine, the SDO guard) with the CiA 402
application :class:`~sim.drives.cia402_drive.Cia402Drive` (mixin): state
machine, plant command, live values, and the validation of writes to its
objects; and the limits it keeps itself (:class:`~sim.drives.limits.DriveLimits`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import canopen.objectdictionary as cod

from hil.canopen.frame import Frame
from hil.canopen.signalmap import Signal
from sim.drives.cia402_drive import Cia402Drive
from sim.drives.limits import DriveLimits
from sim.drives.node import LiveInput, SimNode

if TYPE_CHECKING:
    from sim.drives.stats import PairCounters

__all__ = ["LiveInput", "SimDrive"]


class SimDrive(Cia402Drive, DriveLimits, SimNode):
    """One simulated EMA drive: a CANopen slave (CiA 301) with a CiA 402 drive core.

    Created by :class:`sim.drives.SimDrivePair`; not meant to be built alone
    (it has no plant: the pair feeds it the measured sample and steps the
    plant).

    Parameters
    ----------
    node_id : int
        CANopen node id, 1..127 (checked by the pair).
    ema_index : int
        0 for EMA 1, 1 for EMA 2 of the plant.
    od : canopen.ObjectDictionary
        The node's object dictionary (checked by the pair).
    gear_ratio_rad_per_mm : float
        The plant's gear ratio [rad/mm] (0x2102, CST scaling).
    counts_per_rev : int or None
        The drive's own 0x608F:01 (0x608F:02 = 1), written at every
        power-on and reset node; None keeps the EDS's.
    sample_period_s : float
        The plant's sample period (the SYNC period) [s].
    counters : sim.drives.stats.PairCounters
        The pair's counters, shared by both nodes.
    outbox : list of Frame
        Where the node appends the frames it transmits (the pair drains it).
    serial, inputs, own_data
        As :class:`~sim.drives.node.SimNode`.
    gear_object : (int, int) or None
        The object that reports the plant's gear ratio [rad/mm] (live, REAL32), if the map names one.
    factor_group : bool
        The motor angle is in position user units (0x6091/0x6092 as stored).
    rated_torque_Nm : float or None
        The rated torque the profile states (torque scaling); None: 0x6076 as stored.
    motor_inertia_kg_m2 : float
        The plant's motor inertia [kg m^2]: the gain of the speed limit in CST (:mod:`sim.drives.limits`).

    Attributes
    ----------
    node_id : int
        CANopen node id, 1..127.
    ema_index : int
        0 for EMA 1, 1 for EMA 2 of the plant.
    store : ObjectStore
        Object dictionary and data store, from the EDS.
    sdo : SdoEndpoint
        The SDO server (canopen's ``SdoServer`` on :attr:`store`).
    sdo_request_cob_id, sdo_response_cob_id : int
        0x600 + node id (requests to this node), 0x580 + node id (its responses).
    nmt_state : NmtState
        Current NMT state.
    state_machine : hil.canopen.cia402.DriveStateMachine
        The CiA 402 power drive state machine (remote bit 9 reported).
    heartbeat_enabled : bool
        Fault hook: False suppresses the heartbeat frames (the producer timer
        keeps running, so re-enabling resumes in phase).
    command_override : callable or None
        Fault hook: replaces the plant command of each SYNC, see
        :class:`~sim.drives.cia402_drive.Cia402Drive` (which lists the other fault hooks).

    Raises
    ------
    hil.canopen.errors.CanopenInputError
        A measured input the drive cannot serve.
    """

    def __init__(self, node_id: int, ema_index: int, od: cod.ObjectDictionary, *,
                 gear_ratio_rad_per_mm: float, counts_per_rev: int | None, sample_period_s: float,
                 counters: PairCounters, outbox: list[Frame], serial: int | None = None,
                 inputs: tuple[LiveInput, ...] = (), own_data: dict | None = None,
                 gear_object: tuple[int, int] | None = None, factor_group: bool = False,
                 rated_torque_Nm: float | None = None, motor_inertia_kg_m2: float) -> None:
        self.ema_index = ema_index
        self.gear_object = gear_object
        self.factor_group = factor_group
        angle = next((i for i in inputs if i.signal is Signal.MOTOR_ANGLE and i.key == (0x6064, 0)), None)
        angle_k = angle.scale.units_per_si if angle is not None and angle.scale is not None else None
        SimNode.__init__(self, node_id, od, counters=counters, outbox=outbox, serial=serial, inputs=inputs,
                         own_data=own_data)
        self.init_drive(gear_ratio_rad_per_mm, counts_per_rev, sample_period_s,
                         angle_units_per_rad=angle_k, rated_torque_Nm=rated_torque_Nm)
        self.init_limits(sample_period_s, motor_inertia_kg_m2)
        self.init_comm()
