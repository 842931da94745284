"""One simulated EMA drive: a CANopen slave (CiA 301) with a CiA 402 drive core.

:class:`SimDrive` is assembled from the parts of this package:

* :class:`~sim.drives.store.ObjectStore` (``store``): object dictionary,
  data store, decoded-integer cache;
* :class:`~sim.drives.store.SdoEndpoint` (``sdo``): canopen's SDO server on
  the store;
* :class:`~sim.drives.pdo_engine.PdoEngine` (mixin): PDO mapping, TPDOs,
  RPDOs;
* :class:`~sim.drives.nmt_slave.NmtSlave` (mixin): NMT, heartbeat, EMCY,
  error history 0x1003;
* :class:`~sim.drives.cia402_drive.Cia402Drive` (mixin): CiA 402 behaviour,
  plant command, live values.

The store and the SDO endpoint are separate objects; the three parts on
the per-SYNC path are mixins, so that the hot path reads its state as
plain attributes of the drive (no indirection per frame). Each mixin's
docstring lists the attributes it owns; this class owns the rest:
``node_id``, ``ema_index``, ``store``, ``sdo``, the shared views of the
store (``_data``, ``_icache``, ``_live`` and the bound ``_int``), the
node's clock ``_now``, the pair's counters and outbox.

This module also holds the SDO guard: the write validation the store
calls before it stores an SDO write (:meth:`SimDrive._on_write`,
dispatching to the part that owns the object) and the side effects of
written objects (:meth:`SimDrive._after_write`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import canopen.objectdictionary as cod

from hil.canopen.errors import InputError
from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtState
from hil.canopen.signalmap import Scale, Signal
from sim.drives.cia402_drive import Cia402Drive
from sim.drives.nmt_slave import NmtSlave
from sim.drives.pdo_engine import PdoEngine
from sim.drives.store import ObjectStore, SdoEndpoint

if TYPE_CHECKING:
    from sim.drives.pair import _Counters

__all__ = ["LiveInput", "SimDrive"]


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
        0x6091/0x6092), motor angle only.
    """

    signal: Signal
    ema: int
    key: tuple[int, int]
    data_type: int
    scale: Scale | None

_TALKING = (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


class SimDrive(PdoEngine, NmtSlave, Cia402Drive):
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
    counters : sim.drives.pair._Counters
        The pair's counters, shared by both nodes.
    outbox : list of Frame
        Where the node appends the frames it transmits (the pair drains it).

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
        :class:`~sim.drives.cia402_drive.Cia402Drive`.

    Raises
    ------
    hil.canopen.errors.InputError
        The EDS's default PDO mapping is not valid for this drive.
    """

    def __init__(self, node_id: int, ema_index: int, od: cod.ObjectDictionary, *,
                 gear_ratio_rad_per_mm: float, counts_per_rev: int | None, sample_period_s: float,
                 counters: _Counters, outbox: list[Frame], serial: int | None = None,
                 inputs: tuple[LiveInput, ...] = (), own_data: dict | None = None,
                 gear_object: tuple[int, int] | None = None, factor_group: bool = False,
                 rated_torque_Nm: float | None = None) -> None:
        self.node_id = node_id
        self.ema_index = ema_index
        self._counters = counters
        self._out = outbox
        self._now = 0.0
        self.store_od = od
        self._inputs = tuple(inputs)
        self._gear_object = gear_object
        self._factor_group = factor_group
        #: the drive's own data where its EDS gives no default, (index, sub) -> bytes (restored at reset)
        self.own_data = dict(own_data or {})
        self._memo: list = [None] * len(self._inputs)  # (the input getters share this list, never rebound)
        angle = next((i for i in self._inputs if i.signal is Signal.MOTOR_ANGLE and i.key == (0x6064, 0)), None)
        angle_k = angle.scale.units_per_si if angle is not None and angle.scale is not None else None

        self._live = self._live_objects()
        self.store = ObjectStore(od, self._live, self._on_write)
        self._data = self.store.data  # (the same dicts, never rebound: no indirection on the hot path)
        self._icache = self.store.icache
        self._int = self.store.int_value
        self.sdo = SdoEndpoint(node_id, self.store)
        self.sdo_request_cob_id = self.sdo.request_cob_id  #: requests to this node
        self.sdo_response_cob_id = self.sdo.response_cob_id  #: its responses

        self._init_drive(gear_ratio_rad_per_mm, counts_per_rev, sample_period_s, serial,
                         angle_units_per_rad=angle_k, rated_torque_Nm=rated_torque_Nm)
        self._init_nmt()
        self._init_pdos()
        problems = self._default_mapping_problems()
        if problems:
            raise InputError(f"node {node_id} object dictionary: default PDO mapping invalid: "
                             + "; ".join(problems))
        self._refresh_comm(restart_heartbeat=False)

    # ------------------------------------------------------------------ OD access

    def read(self, index: int, subindex: int = 0) -> int | float | str | bytes:
        """Decoded value of ``index:subindex`` as an SDO upload would return it.

        Raises
        ------
        hil.canopen.errors.InputError
            The object does not exist in this node's object dictionary.
        """
        var = self.store.var(index, subindex)
        if var is None:
            raise InputError(f"index:subindex 0x{index:04X}:{subindex:02X} is not in the object "
                             f"dictionary of node {self.node_id}")
        return var.decode_raw(self.store.get_data(index, subindex))

    def _store(self, index: int, subindex: int, data: bytes) -> None:
        """Store ``data`` (the drive's own writes, RPDO entries of the generic path)."""
        self.store.put(index, subindex, data)
        if index == 0x608F:
            self._cpr_changed()

    # ------------------------------------------------------------------ SDO

    def _on_sdo(self, frame: Frame, t: float) -> None:
        """Serve one SDO request (expedited and segmented; block transfers are refused).

        Only in PRE-OPERATIONAL and OPERATIONAL, only 8-byte requests (else
        counted in ``bad_frames_ignored``); see :class:`~sim.drives.store.SdoEndpoint`.
        """
        self._now = t
        if self.nmt_state not in _TALKING:
            self._counters.bad_frames_ignored += 1
            return
        data = frame.data
        if len(data) != 8:
            self._counters.bad_frames_ignored += 1
            return
        self._counters.sdo_requests += 1
        written = self.store.written
        written.clear()
        self.sdo.serve(data, t, self._out)
        if written:
            # the decoded-value cache is invalidated once the values are stored (a
            # write callback may have read the old value of the object it checks)
            for key in written:
                self._icache.pop(key, None)
                if key[0] == 0x608F:
                    self._cpr_changed()
            self._after_write(sorted(written))
            written.clear()

    def _on_write(self, index: int, subindex: int, od: cod.ODVariable, data: bytes) -> None:
        """Validate an SDO write (raise SdoAbortedError to refuse); called by the store before storing."""
        value = od.decode_raw(bytes(data)) if od.data_type in cod.NUMBER_TYPES else None
        self._icache.pop((index, subindex), None)
        pdo = self._pdo_by_index(index)
        if pdo is not None:
            self._check_pdo_write(pdo, index, subindex, value)
        elif index in (0x1005, 0x1014, 0x1003, 0x1016):
            self._check_comm_object_write(index, subindex, value)
        else:
            self._check_drive_write(index, subindex, value)

    def _after_write(self, written: list[tuple[int, int]] | tuple[tuple[int, int], ...]) -> None:
        """Side effects of objects just written (by SDO or RPDO), after they are stored."""
        comm = False
        restart_hb = False
        for index, subindex in written:
            if index == 0x6040:
                self._controlword()
            elif index == 0x6060:
                self._mode_written()
            elif index == 0x1003 and subindex == 0:
                self._clear_error_history()
            elif 0x1000 <= index <= 0x1FFF:
                comm = True
                restart_hb |= index == 0x1017
        if comm:
            self._refresh_comm(restart_heartbeat=restart_hb)
