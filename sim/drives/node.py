"""One simulated CANopen slave (CiA 301), the common part of the drives and the sensor nodes.

:class:`SimNode` is assembled from the parts of this package:

* :class:`~sim.drives.store.ObjectStore` (``store``): object dictionary,
  data store, decoded-integer cache;
* :class:`~sim.drives.store.SdoEndpoint` (``sdo``): canopen's SDO server on
  the store;
* :class:`~sim.drives.pdo_engine.PdoEngine` (mixin): PDO mapping, TPDOs,
  RPDOs;
* :class:`~sim.drives.nmt_slave.NmtSlave` (mixin): NMT, heartbeat, EMCY,
  error history 0x1003.

What the node does with its data is its application, a subclass:
:class:`sim.drives.drive.SimDrive` (CiA 402, with
:class:`~sim.drives.cia402_drive.Cia402Drive`) or
:class:`sim.drives.sensor_node.SimSensorNode` (CiA 401 / 404). The parts on
the per-SYNC path are mixins, so that the hot path reads its state as plain
attributes of the node (no indirection per frame). Each mixin's docstring
lists the attributes it owns; this class owns the rest: ``node_id``,
``store``, ``sdo``, the shared views of the store (``object_data``, ``int_cache``,
``live_objects`` and the bound ``int_value``), the node's clock ``now_s``, its own data,
the measured inputs it serves (``inputs``, ``raw_sample``, ``input_memo``), the pair's
counters and outbox.

The application hooks (overridden by the subclasses; no-ops here):
``build_live_objects`` (the objects computed when read), ``reset_application``
(power-on, reset node), ``after_boot`` (after the boot-up frame),
``connection_lost`` (a heartbeat consumer event), ``app_error_bits``
(error register bits of the application), ``check_app_write`` (SDO write
validation of application objects), ``controlword_written``, ``mode_written`` and
``cpr_changed`` (side effects of written objects).

This module also holds the SDO guard: the write validation the store calls
before it stores an SDO write (:meth:`SimNode._on_write`, dispatching to
the part that owns the object) and the side effects of written objects
(:meth:`SimNode.after_write`).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import canopen.objectdictionary as cod

from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtState
from hil.canopen.od import lookup
from hil.canopen.pdo import raw_encoder
from hil.canopen.signalmap import Scale, Signal
from sim.drives.nmt_slave import NmtSlave
from sim.drives.pdo_engine import PdoEngine
from sim.drives.store import ObjectStore, SdoEndpoint

if TYPE_CHECKING:
    from sim.drives.stats import PairCounters

__all__ = ["SAMPLE_SLOT", "LiveInput", "SimNode"]

#: Index of each measured signal of EMA 1 in a plant sample ``(t_s, phi1, phi2, s1, s2, F1, F2)``;
#: EMA 2's is the next one.
SAMPLE_SLOT = {Signal.MOTOR_ANGLE: 1, Signal.LVDT: 3, Signal.FORCE: 5}


@dataclass(frozen=True, slots=True)
class LiveInput:
    """A measured value a simulated node serves at one of its objects (from the rig's plan).

    Attributes
    ----------
    signal : Signal
        MOTOR_ANGLE, LVDT or FORCE.
    ema : int
        Whose value of the plant's sample (1 or 2).
    key : (int, int)
        The object (index, sub-index).
    data_type : int
        Its CiA 301 data type: the value is rounded and clipped into it.
    scale : Scale or None
        SI -> raw as the profile states it; None: the drive's own position units (0x608F,
        0x6091/0x6092), motor angle of the drive's own EMA only.
    """

    signal: Signal
    ema: int
    key: tuple[int, int]
    data_type: int
    scale: Scale | None

_TALKING = (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


class SimNode(PdoEngine, NmtSlave):
    """One simulated CANopen slave (CiA 301); the application is a subclass.

    Created by :class:`sim.drives.SimDrivePair`; not meant to be built alone
    (it has no plant: the pair feeds it the measured sample).

    Parameters
    ----------
    node_id : int
        CANopen node id, 1..127 (checked by the pair).
    od : canopen.ObjectDictionary
        The node's object dictionary (checked by the pair).
    counters : sim.drives.stats.PairCounters
        The pair's counters, shared by all nodes.
    outbox : list of Frame
        Where the node appends the frames it transmits (the pair drains it).
    serial : int or None
        Its serial number 0x1018:04 (own data); None keeps the EDS's.
    inputs : tuple of LiveInput
        The measured values the rig's map puts on this node.
    own_data : dict
        ``(index, sub) -> bytes``: its own data where the EDS gives no default (restored at
        power-on and reset node).

    Attributes
    ----------
    node_id : int
    store : ObjectStore
        Object dictionary and data store, from the EDS.
    sdo : SdoEndpoint
        The SDO server (canopen's ``SdoServer`` on :attr:`store`).
    sdo_request_cob_id, sdo_response_cob_id : int
        0x600 + node id (requests to this node), 0x580 + node id (its responses).
    nmt_state : NmtState
        Current NMT state.
    heartbeat_enabled : bool
        Fault hook: False suppresses the heartbeat frames.
    own_data : dict
        As the parameter.

    Raises
    ------
    hil.canopen.errors.CanopenInputError
        A measured input the node cannot serve.
    """

    def __init__(self, node_id: int, od: cod.ObjectDictionary, *, counters: PairCounters, outbox: list[Frame],
                 serial: int | None = None, inputs: tuple[LiveInput, ...] = (),
                 own_data: dict | None = None) -> None:
        self.node_id = node_id
        self.counters = counters
        self.outbox = outbox
        self.now_s = 0.0
        self.store_od = od
        self._inputs = tuple(inputs)
        self._serial = serial
        #: the node's own data where its EDS gives no default, (index, sub) -> bytes (restored at reset)
        self.own_data = dict(own_data or {})
        if serial is not None and lookup(od, 0x1018, 4) is not None:
            self.own_data[(0x1018, 4)] = struct.pack("<I", serial)
        self.input_memo: list = [None] * len(self._inputs)  # (the input getters share this list, never rebound)
        self.raw_sample: tuple = (0.0,) * 7  # the plant sample the inputs are served from

        self.live_objects = self.build_live_objects()
        self.store = ObjectStore(od, self.live_objects, self._on_write)
        self.object_data = self.store.data  # (the same dicts, never rebound: no indirection on the hot path)
        self.int_cache = self.store.icache
        self.int_value = self.store.int_value
        for (index, sub), data in self.own_data.items():  # before the application reads its objects
            self.store.put(index, sub, data)
        self.sdo = SdoEndpoint(node_id, self.store)
        self.sdo_request_cob_id = self.sdo.request_cob_id  #: requests to this node
        self.sdo_response_cob_id = self.sdo.response_cob_id  #: its responses

    @property
    def inputs(self) -> tuple[LiveInput, ...]:
        """The measured inputs this node serves."""
        return self._inputs

    def init_comm(self) -> None:
        """NMT and PDOs (after the application's own initialisation)."""
        self.init_nmt()
        self.init_pdos()
        self.refresh_comm(restart_heartbeat=False)

    # ------------------------------------------------------------------ measured inputs

    def input_getter(self, k: int, inp: LiveInput) -> Callable[[], int | float]:
        """Getter of measured input ``k``: the plant's value, scaled and rounded into its data type."""
        if inp.scale is None:
            raise CanopenInputError(f"node {self.node_id}: {inp.signal.value} of EMA {inp.ema} at "
                             f"0x{inp.key[0]:04X}:{inp.key[1]:02X} needs a scaling the profile states")
        slot = SAMPLE_SLOT[inp.signal] + inp.ema - 1
        units, off, encode = inp.scale.units_per_si, inp.scale.offset, raw_encoder(inp.data_type)
        memo = self.input_memo

        def get() -> int | float:
            v = memo[k]
            if v is None:
                x = self.raw_sample[slot]
                v = memo[k] = encode((x - off) * units if off else x * units)
            return v

        return get

    def measure(self, raw: tuple) -> None:
        """Take a plant sample ``(t_s, phi1, phi2, s1, s2, F1, F2)``: the inputs are computed anew."""
        self.raw_sample = raw
        memo = self.input_memo
        memo[:] = (None,) * len(memo)  # (the same list: the input getters share it)

    # ------------------------------------------------------------------ application hooks

    def build_live_objects(self) -> dict[tuple[int, int], Callable[[], int | float]]:
        """The objects computed when read: the error register and the measured inputs."""
        live: dict[tuple[int, int], Callable[[], int | float]] = {(0x1001, 0): lambda: self.error_register}
        for k, inp in enumerate(self._inputs):
            live[inp.key] = self.input_getter(k, inp)
        return live

    def apply_own_data(self) -> None:
        """The node's own data, restored at power-on and reset node (what its EDS leaves open)."""
        for (index, sub), data in self.own_data.items():
            self.write_object(index, sub, data)

    def reset_application(self) -> None:
        """Power-on / reset node: the application's initial state."""

    def after_boot(self) -> None:
        """After the boot-up frame of a power-on or reset node (e.g. an EMCY of a fault found at boot)."""

    def connection_lost(self) -> None:
        """A heartbeat consumer event (CiA 402: the abort connection option 0x6007)."""

    def app_error_bits(self) -> int:
        """Error register bits of the application (a latched fault)."""
        return 0

    def check_app_write(self, index: int, subindex: int, value: float | None) -> None:
        """Validate an SDO write of an application object (raise SdoAbortedError to refuse)."""

    def controlword_written(self) -> None:
        """0x6040 written (a drive acts on it)."""

    def mode_written(self) -> None:
        """0x6060 written (a drive acts on it)."""

    def cpr_changed(self) -> None:
        """0x608F (may have) changed (a drive rescales its positions)."""

    # ------------------------------------------------------------------ OD access

    def read(self, index: int, subindex: int = 0) -> int | float | str | bytes:
        """Decoded value of ``index:subindex`` as an SDO upload would return it.

        Raises
        ------
        hil.canopen.errors.CanopenInputError
            The object does not exist in this node's object dictionary.
        """
        var = self.store.var(index, subindex)
        if var is None:
            raise CanopenInputError(f"index:subindex 0x{index:04X}:{subindex:02X} is not in the object "
                             f"dictionary of node {self.node_id}")
        return var.decode_raw(self.store.get_data(index, subindex))

    def write_object(self, index: int, subindex: int, data: bytes) -> None:
        """Store ``data`` (the node's own writes, RPDO entries of the generic path)."""
        self.store.put(index, subindex, data)
        if index == 0x608F:
            self.cpr_changed()

    # ------------------------------------------------------------------ SDO

    def on_sdo(self, frame: Frame, t: float) -> None:
        """Serve one SDO request (expedited and segmented; block transfers are refused).

        Only in PRE-OPERATIONAL and OPERATIONAL, only 8-byte requests (else
        counted in ``bad_frames_ignored``); see :class:`~sim.drives.store.SdoEndpoint`.
        """
        self.now_s = t
        if self.nmt_state not in _TALKING:
            self.counters.bad_frames_ignored += 1
            return
        data = frame.data
        if len(data) != 8:
            self.counters.bad_frames_ignored += 1
            return
        self.counters.sdo_requests += 1
        written = self.store.written
        written.clear()
        self.sdo.serve(data, t, self.outbox)
        if written:
            # the decoded-value cache is invalidated once the values are stored (a
            # write callback may have read the old value of the object it checks)
            for key in written:
                self.int_cache.pop(key, None)
                if key[0] == 0x608F:
                    self.cpr_changed()
            self.after_write(sorted(written))
            written.clear()

    def _on_write(self, index: int, subindex: int, od: cod.ODVariable, data: bytes) -> None:
        """Validate an SDO write (raise SdoAbortedError to refuse); called by the store before storing."""
        value = od.decode_raw(bytes(data)) if od.data_type in cod.NUMBER_TYPES else None
        self.int_cache.pop((index, subindex), None)
        pdo = self.pdo_by_index(index)
        if pdo is not None:
            self.check_pdo_write(pdo, index, subindex, value)
        elif index in (0x1005, 0x1014, 0x1003, 0x1016):
            self.check_comm_object_write(index, subindex, value)
        else:
            self.check_app_write(index, subindex, value)

    def after_write(self, written: list[tuple[int, int]] | tuple[tuple[int, int], ...]) -> None:
        """Side effects of objects just written (by SDO or RPDO), after they are stored."""
        comm = False
        restart_hb = False
        for index, subindex in written:
            if index == 0x6040:
                self.controlword_written()
            elif index == 0x6060:
                self.mode_written()
            elif index == 0x1003 and subindex == 0:
                self.clear_error_history()
            elif 0x1000 <= index <= 0x1FFF:
                comm = True
                restart_hb |= index == 0x1017
        if comm:
            self.refresh_comm(restart_heartbeat=restart_hb)
