"""One simulated sensor node: a CiA 401 I/O module or CiA 404 measuring device with the rig's sensors.

:class:`SimSensorNode` is the common CANopen slave of :mod:`sim.drives.node`
(NMT slave, heartbeat and EMCY producer, heartbeat consumer, SDO server on
its EDS, PDO engine) whose application is a set of measured inputs: the
LVDTs, load cells (or encoders) the rig's signal map wires to it, served at
the mapped objects (e.g. CiA 401 analog inputs 0x6401:01..) with the map's
data type and scaling from the plant's sample of each SYNC, exactly as the
drives serve theirs. It never moves the rig.

Choices (CiA 401 / 404 leave them open or this node restricts them)
------------------------------------------------------------------
* The inputs are sampled at the SYNC, like the drives': a synchronous TPDO
  carries the plant's state at that SYNC; an SDO upload of an input gives
  the same value until the next SYNC.
* Objects of the EDS that are not measured inputs (filters, interrupt
  enables, further channels) are stored as written and do nothing; an input
  channel the map does not use reads 0.
* A heartbeat consumer event (0x1016, if the master configures one) sends
  EMCY 0x8130 and does nothing else: the node has no outputs to put into an
  error state (CiA 401 0x6206 and the like are not simulated).
* Error register 0x1001: bits 0 and 4 while a communication error (PDO
  length, heartbeat event) stands; the node has no fault of its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import canopen.objectdictionary as cod

from hil.canopen.frame import Frame
from sim.drives.node import LiveInput, SimNode

if TYPE_CHECKING:
    from sim.drives.stats import PairCounters

__all__ = ["SimSensorNode"]


class SimSensorNode(SimNode):
    """A simulated sensor node (CiA 401 / 404): a CANopen slave serving measured inputs.

    Created by :class:`sim.drives.SimDrivePair` for every sensor node of the
    rig's plan; not meant to be built alone (the pair feeds it each sample).

    Parameters
    ----------
    name : str
        The node's name in the profile (``[nodes.NAME]``).
    node_id : int
        CANopen node id, 1..127.
    od : canopen.ObjectDictionary
        The node's object dictionary (its EDS, ``$NODEID`` resolved).
    counters, outbox, serial, inputs, own_data
        As :class:`~sim.drives.node.SimNode`; every input needs the scaling the profile states.

    Attributes
    ----------
    name : str
    node_id : int
    nmt_state : NmtState
    heartbeat_enabled : bool
        Fault hook: False suppresses the heartbeat frames.
    heartbeat_events : list of (float, int)
        Time [s] and producer node id of every heartbeat consumer event.

    Raises
    ------
    hil.canopen.errors.CanopenInputError
        An input without a scaling.
    """

    def __init__(self, name: str, node_id: int, od: cod.ObjectDictionary, *, counters: PairCounters,
                 outbox: list[Frame], serial: int | None = None, inputs: tuple[LiveInput, ...] = (),
                 own_data: dict | None = None) -> None:
        self.name = name
        super().__init__(node_id, od, counters=counters, outbox=outbox, serial=serial, inputs=inputs,
                         own_data=own_data)
        self.init_comm()

    def __repr__(self) -> str:
        return f"SimSensorNode({self.name!r}, node {self.node_id}, {len(self.inputs)} inputs)"

    def value(self, k: int) -> int | float:
        """Raw value of input ``k`` (of :attr:`inputs`) in the current sample, as a TPDO carries it."""
        return self.live_objects[self.inputs[k].key]()
