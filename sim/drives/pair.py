"""The rig's simulated CANopen nodes around one rig plant: two CiA 402 EMA drives and the sensor nodes (sans-IO).

:class:`SimDrivePair` replaces the rig's nodes in dry-runs and tests: the
two EMA drives (:class:`sim.drives.drive.SimDrive`) and every sensor node of
the rig's plan, a CiA 401 I/O module or CiA 404 measuring device
(:class:`sim.drives.sensor_node.SimSensorNode`). Each node is built from the
EDS the master reads (the shipped ``profiles/ema_drive.eds``, a vendor's
file, ``profiles/cia401_io.eds``, through the caller's ``od_factory``) and
the rig's :class:`~hil.canopen.plan.RigPlan`: it serves its EDS with
canopen's SDO server and the measured inputs the signal map puts on it at
the mapped objects, with the mapped data type and scaling
(:mod:`sim.drives.served`). The pair consumes every frame seen on the bus
and returns the frames its nodes transmit; time is passed in. No threads,
no clocks, no bus objects: the caller (an IO shell on a python-can bus, or
a test) moves the frames.

The package, part by part (each module documents its protocol choices):

========================  ====================================================
module                    what
========================  ====================================================
``pair``                  this: the nodes, frame routing, SYNC, the plant
``node``                  :class:`SimNode`, the CANopen slave assembled from
                          the parts below; the SDO write guard
``drive``                 :class:`SimDrive`: a node with the CiA 402 drive
``sensor_node``           :class:`SimSensorNode`: a node with measured inputs
``served``                what each node serves: inputs, own data
``stats``                 the counters the nodes share
``store``                 object dictionary, data store, SDO server (canopen)
``pdo_engine``            PDO mapping and communication, TPDOs, RPDOs
``nmt_slave``             NMT slave, heartbeat, EMCY, error history 0x1003
``cia402_drive``          CiA 402 behaviour, statusword, plant command,
                          live values (position, torque)
========================  ====================================================

Per SYNC (COB-ID of 0x1005, 0x080 by default) the pair, in this order:

1. sends the due synchronous TPDOs of every OPERATIONAL node with the current
   sample (the plant state at this SYNC): the drives', then the sensor
   nodes';
2. applies the synchronous RPDOs latched since the previous SYNC;
3. computes both drives' setpoints and steps the plant once, so that the
   current sample becomes the state at the next SYNC.

A statusword change commanded by a synchronous RPDO therefore shows in the
TPDO of the SYNC after the one that applied it (one cycle of latency, as on
the real bus).

The drives' own cycle when SYNC stops: a real drive's control loop does not
stop with the master (it holds the last target or torque until a reaction
such as 0x6007 takes over), and the rig does not stop either. Once SYNCs
were seen and none came for :data:`FREE_RUN_AFTER_CYCLES` SYNC periods,
:meth:`SimDrivePair.tick` runs the drive cycle itself every plant sample
period, catching up from the last step (heartbeat consumers checked at each
step's time, no TPDOs, latched RPDOs wait for a SYNC): steps 2 and 3 above
on the drives' clock. It does so while a drive's power stage is on
(OPERATION_ENABLED, QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE); with every
drive disabled (holding brakes) the rig is at rest and is not stepped. These
steps are counted in ``stats.free_steps``, not in ``stats.plant_steps``.
The same holds for a late SYNC: one that comes more than half a period after
the period following the last step first lets the drives' own cycle run up
to the period nearest to it (so that its TPDOs carry the rig at that time, as
real drives' would), however short the gap was for :meth:`SimDrivePair.tick`
to notice. The drives' cycle is locked to SYNC as a real drive's is (a phase
lock, :data:`SYNC_PHASE_GAIN`), not re-timed by each SYNC: the periods are
counted on that cycle, so a SYNC that left up to T/2 off its period (the
master's loop-timed SYNC takes the nearest slot,
:meth:`hil.transport.BusTransport.send_sync`) is stepped as the periods the
master's sample times say (issue 37: counted from each SYNC's own time, a
SYNC sent early for its slot and the next sent late for its own made two
periods of motion in one period's sample: the approach at 5 mm/s read over
10 mm/s).

Choices
-------
* Power-on: every node boots (see :mod:`sim.drives.nmt_slave`). At the first
  power-on the plant is stepped once with both drives DISABLED, so the
  current sample is the measured rig at rest; this step counts in
  ``stats.plant_steps`` (``plant_steps == syncs + 1``).
* Time passed to :meth:`SimDrivePair.on_frame` and :meth:`SimDrivePair.tick`
  never runs backwards: a smaller ``t`` than the last one is taken as the last.
* Heartbeats (0x700 + n) go to the heartbeat consumers (0x1016) of the
  nodes that monitor node n; a drive's consumer reacts with EMCY 0x8130 and
  its abort connection option 0x6007, a sensor node's with the EMCY only
  (see :mod:`sim.drives.nmt_slave`).
* The two-drive rig (no sensor node) takes the same path per frame as
  before sensor nodes existed: a sensor node's frames are routed on the
  paths no drive takes (SDO, SYNC of another COB-ID, RPDOs), so a rig
  without one pays one truth test per frame.
* Frames no node consumes (another node's traffic, unknown COB-IDs, NMT for
  other nodes) and malformed ones (NMT not 2 bytes, SYNC over 1 byte, SDO
  request not 8 bytes, unknown NMT command) are counted and ignored.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable

import canopen.objectdictionary as cod

from hil.canopen.cia402 import State
from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import Frame
from hil.canopen.nmt import NmtCommand
from hil.canopen.od import lookup
from hil.canopen.plan import RigPlan
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.canopen.signalmap import NodeRole, ScaleSource, Signal
from hil.canopen.validate import error_code, integer, time_s
from sim.drives.drive import SimDrive
from sim.drives.nmt_slave import TIME_EPS_S
from sim.drives.node import SimNode
from sim.drives.pdo_engine import Pdo
from sim.drives.sensor_node import SimSensorNode
from sim.drives.served import live_inputs, own_data
from sim.drives.stats import PairCounters, SimPairStats
from sim.plant import RigPlant

__all__ = ["FREE_RUN_AFTER_CYCLES", "SYNC_PHASE_GAIN", "SimDrivePair", "SimPairStats"]

#: SYNC periods without a SYNC after which the drives run their cycle on their own clock.
FREE_RUN_AFTER_CYCLES = 5
#: Gain of the drives' SYNC phase lock [1]: each SYNC moves the drives' cycle by this fraction of its
#: offset from the period it belongs to (a first-order loop, time constant 1 / gain = 16 periods).
SYNC_PHASE_GAIN = 1.0 / 16.0
#: CiA 402 states with the power stage on: the drives' own cycle steps the rig while one is in them.
_POWERED = (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)

_MODE_DISABLED = int(DriveMode.DISABLED)
#: Objects a simulated drive needs in its EDS (the CiA 402 objects it acts on).
_SIM_REQUIRED = ((0x6040, 0), (0x6041, 0), (0x6060, 0), (0x6061, 0), (0x6064, 0), (0x607A, 0))


# --------------------------------------------------------------------------- the pair


def _counts(angle) -> float | None:
    """Increments per revolution the map states for a motor angle entry (None: read from the drive)."""
    if angle is None or angle.source is not ScaleSource.PROFILE or angle.scale is None:
        return None
    return abs(angle.scale.units_per_si) * 2.0 * math.pi


def _od(od_factory: Callable[[str, int], cod.ObjectDictionary], name: str, node_id: int) -> cod.ObjectDictionary:
    od = od_factory(name, node_id)
    if not isinstance(od, cod.ObjectDictionary):
        raise CanopenInputError(f"od_factory({name!r}, {node_id}) must return a canopen ObjectDictionary, "
                         f"got {type(od).__name__}")
    return od


class SimDrivePair:
    """The rig's simulated nodes: two CiA 402 EMA drives moving one simulated rig, and its sensor nodes.

    Parameters
    ----------
    plant : sim.plant.RigPlant
        The rig; the drive of EMA 1 (``plan.drives[0]``) moves its EMA 1, that of EMA 2 its EMA 2.
        The pair steps it once per SYNC (and once at the first power-on).
    plan : hil.canopen.plan.RigPlan
        The rig's plan (:func:`hil.profile.rig.plan_for`): node ids, roles, EDS files, the signal map.
    od_factory : callable
        ``od_factory(name, node_id)`` returns a fresh ``canopen.ObjectDictionary`` of the node
        named ``name`` in the plan (``"ema1"``, ``"ema2"``, a sensor node's name), ``$NODEID``
        resolved for ``node_id``; a drive's must hold the CiA 402 objects it acts on (0x6040,
        0x6041, 0x6060, 0x6061, 0x6064, 0x607A).
    serials : tuple of two int, optional
        The drives' serial numbers (identity 0x1018:04, the drive's own data like
        ``counts_per_rev``); default the EDS's.
    counts_per_rev : int, optional
        Encoder increments per motor revolution. None: the EDS's 0x608F
        (else 4096 / 1). Given: written to 0x608F:01 (and 1 to 0x608F:02) as the
        drive's own data at every power-on and reset node.

    Attributes
    ----------
    nodes : tuple of SimDrive
        The two drives, EMA 1's then EMA 2's.
    sensors : tuple of SimSensorNode
        The sensor nodes of the plan (none for a rig whose sensors are wired to the drives).
    all_nodes : tuple
        ``nodes + sensors``.
    plant : RigPlant
        The simulated rig.
    plan : RigPlan
    on_free_step : callable or None
        Called as ``on_free_step(t)`` after each step of the drives' own
        cycle (``t`` [s]: the time of that step), e.g. to record the truth.

    Raises
    ------
    hil.canopen.errors.CanopenInputError
        Wrong plant or plan type, ``counts_per_rev``, ``serials``, an object
        dictionary that lacks what a drive needs, or a measured input a node
        cannot serve.

    Notes
    -----
    Conversions between the plant (rad, mm, N) and the nodes' objects, per
    EMA with :math:`N = \\text{0x608F:01} / \\text{0x608F:02}` increments per
    revolution (or the profile's counts per revolution, or 0x6091/0x6092),
    :math:`T_r = \\text{0x6076} / 1000` N m (or the profile's rated torque) and
    the plant's gear ratio :math:`i` [rad/mm] (also served at the profile's
    ``canopen.gear_ratio_object``, REAL32); a measured input :math:`x` (LVDT
    stroke [mm], force [N], an angle [rad]) at the object the map gives, with
    its scaling :math:`r = k (x - x_0)` (:class:`hil.canopen.signalmap.Scale`)
    rounded and clipped into its data type (e.g. the shipped LVDT at 0x2100 in
    um, :math:`k = 1000`):

    .. math::

        p_{actual} = \\mathrm{round}(\\varphi N / 2\\pi)\\ \\text{[inc]},\\quad
        r = \\mathrm{clip}(\\mathrm{round}(k\\,(x - x_0)))\\ \\text{[raw]},

        \\text{0x6077} = \\mathrm{round}(1000\\, T / T_r)\\ [per mille],\\quad
        \\varphi_{target} = 2\\pi\\,\\mathrm{clip}(p_{target}, p_{min}, p_{max}) / N
        \\ \\text{(CSP)},

        F_{target} = \\mathrm{clip}(\\tau, \\pm\\tau_{max}) / 1000 \\cdot T_r \\cdot 1000\\, i
        \\ \\text{[N] (CST)},

    with :math:`\\varphi` the measured motor angle of that EMA, :math:`T`
    the plant's drive torque [N m], :math:`p_{min}, p_{max}` = 0x607D:01/02,
    :math:`\\tau` = 0x6071 and :math:`\\tau_{max}` = 0x6072 [per mille].
    Commands to the plant per drive state: OPERATION_ENABLED + CSP ->
    POSITION, + CST -> FORCE; QUICK_STOP_ACTIVE -> POSITION at the angle
    measured when the quick stop began, for
    :data:`~sim.drives.cia402_drive.QUICK_STOP_HOLD_S` or, as 0x605A says, until
    disable voltage; anything else ->
    DISABLED (holding brake). See the modules of :mod:`sim.drives` for the
    protocol choices.
    """

    def __init__(self, plant: RigPlant, plan: RigPlan, od_factory: Callable[[str, int], cod.ObjectDictionary], *,
                 counts_per_rev: int | None = None, serials: tuple[int, int] | None = None) -> None:
        if not isinstance(plant, RigPlant):
            raise CanopenInputError(f"plant must be a sim.plant.RigPlant, got {type(plant).__name__}")
        if not isinstance(plan, RigPlan):
            raise CanopenInputError(f"plan must be a hil.canopen.plan.RigPlan, got {type(plan).__name__}")
        if not callable(od_factory):
            raise CanopenInputError("od_factory must be callable as od_factory(node name, node id), "
                                    f"got {od_factory!r}")
        if counts_per_rev is not None:
            counts_per_rev = integer("counts_per_rev", counts_per_rev, 1, 2**32 - 1)  # [increments/rev]
        if serials is not None:
            try:
                serials = tuple(serials)
            except TypeError:
                serials = ()
            if len(serials) != 2:
                raise CanopenInputError(f"serials must be two ints (EMA 1, EMA 2), got {serials!r}")
            serials = tuple(integer(f"serials[{k}]", v, 0, 2**32 - 1) for k, v in enumerate(serials))
        self.plant = plant
        self.plan = plan
        self._counters = PairCounters()
        self._out: list[Frame] = []
        self._powered = False
        self._now = -math.inf
        self._raw_sample: tuple | None = None  # plant.step_raw output; :attr:`sample` builds the Sample
        self._T = float(plant.params.sample_period_s)  # the drives' cycle when SYNC is missing [s]
        self._last_sync_t: float | None = None  # time of the last SYNC (None: none yet)
        self._last_step_t = 0.0  # time of the last drive cycle (SYNC or own clock)
        self.on_free_step: Callable[[float], None] | None = None
        self._sample: Sample | None = None
        params = plant.params
        nodes = []
        for k, dp in enumerate(plan.drives):
            spec = dp.node.spec
            n = spec.node_id
            od = _od(od_factory, spec.name, n)
            missing = [f"0x{i:04X}:{s:02X}" for i, s in _SIM_REQUIRED if lookup(od, i, s) is None]
            if missing:
                raise CanopenInputError(f"node {n} object dictionary lacks objects the simulated drive serves: "
                                 + ", ".join(missing))
            torque = plan.map.entry(dp.ema, Signal.TARGET_TORQUE)
            rated = None
            if torque is not None and torque.source is ScaleSource.PROFILE and torque.scale is not None:
                rated = 1.0 / (torque.scale.units_per_si * params.i_total_rad_per_mm)
            angle = plan.map.entry(dp.ema, Signal.MOTOR_ANGLE)
            nodes.append(SimDrive(n, k, od, gear_ratio_rad_per_mm=params.i_total_rad_per_mm,
                                  counts_per_rev=counts_per_rev, sample_period_s=params.sample_period_s,
                                  counters=self._counters, outbox=self._out,
                                  serial=None if serials is None else serials[k],
                                  inputs=live_inputs(plan, spec),
                                  own_data=own_data(od, spec, dp.force_control, _counts(angle)),
                                  gear_object=plan.gear_ratio_object,
                                  factor_group=angle is not None and angle.source is ScaleSource.FACTOR_GROUP,
                                  rated_torque_Nm=rated, motor_inertia_kg_m2=params.drive.motor_inertia_kg_m2))
        self.nodes: tuple[SimDrive, SimDrive] = (nodes[0], nodes[1])
        for node in self.nodes:
            node.torque_fetch = self._fetch_torque
        sensors = []
        for np_ in plan.nodes:
            spec = np_.spec
            if spec.role is not NodeRole.SENSORS:
                continue
            od = _od(od_factory, spec.name, spec.node_id)
            sensors.append(SimSensorNode(spec.name, spec.node_id, od, counters=self._counters, outbox=self._out,
                                         inputs=live_inputs(plan, spec), own_data=own_data(od, spec)))
        #: the sensor nodes of the plan (CiA 401 / 404), in the plan's order
        self.sensors: tuple[SimSensorNode, ...] = tuple(sensors)
        #: every node: the two drives, then the sensor nodes
        self.all_nodes: tuple[SimNode, ...] = self.nodes + self.sensors
        # sensor nodes: SDO request COB-ID -> node (their frames take the rare paths of on_frame)
        self._sensor_sdo = {s.sdo_request_cob_id: s for s in self.sensors}
        # COB-ID -> ((node, its RPDOs of that COB-ID), ...), valid for the nodes' _rx_by_cob dicts
        self._routes: dict[int, tuple[tuple[SimDrive, list[Pdo]], ...]] = {}
        self._routes_rx: tuple[dict, dict] = (nodes[0].rpdos_by_cob_id, nodes[1].rpdos_by_cob_id)

    # ------------------------------------------------------------------ inspection

    @property
    def stats(self) -> SimPairStats:
        """Snapshot of the counters."""
        return self._counters.snapshot()

    @property
    def sample(self) -> Sample | None:
        """The current sample (plant state at the next SYNC); None before the first power-on."""
        if self._sample is None and self._raw_sample is not None:
            self._sample = Sample(*self._raw_sample)
        return self._sample

    @property
    def powered(self) -> bool:
        """True after :meth:`power_on`."""
        return self._powered

    # ------------------------------------------------------------------ internals

    def _clock(self, t: float) -> float:
        v = time_s(t)
        self._now = max(self._now, v)
        return self._now

    def _drain(self) -> list[Frame]:
        """The frames the nodes queued, handed over (the queue is emptied; no list made when empty)."""
        out = self._out
        if not out:
            return []
        frames = out.copy()
        out.clear()
        return frames

    def _step(self, mode1: int, value1: float, mode2: int, value2: float) -> None:
        """Step the plant with both drives' commands (DriveMode values, rad / N).

        ``plant.step_raw`` is ``plant.step`` without the Setpoint and Sample
        objects; on an error ``plant.step`` is called with the same commands so
        that it raises its own error (the plant validates before it advances).
        The drive torques (0x6077) are read from the plant only when needed
        (:meth:`_fetch_torque`): the pair is the only one stepping its plant.
        """
        plant = self.plant
        try:
            raw = plant.step_raw(mode1, value1, mode2, value2)
        except (CanopenInputError, TypeError):
            plant.step(Setpoint(DriveMode(mode1), value1), Setpoint(DriveMode(mode2), value2))
            raise
        self._raw_sample = raw
        self._sample = None
        n0, n1 = self.nodes
        n0.measure(raw)
        n1.measure(raw)
        if self.sensors:
            for s in self.sensors:
                s.measure(raw)

    def _fetch_torque(self) -> None:
        """Read both drive torques [N m] of the last plant step into the nodes."""
        torque = self.plant.state().torque_Nm
        for node in self.nodes:
            node.torque_value = float(torque[node.ema_index])
            node.torque_stale = False

    def _node_index(self, node_index: int) -> SimDrive:
        if isinstance(node_index, bool):
            raise CanopenInputError("node_index must be 0 or 1 (int), got bool")
        try:
            k = operator.index(node_index)
        except TypeError:
            raise CanopenInputError(f"node_index must be 0 or 1 (int), got {node_index!r}") from None
        if k not in (0, 1):
            raise CanopenInputError(f"node_index = {k} must be 0 (node {self.nodes[0].node_id}) "
                             f"or 1 (node {self.nodes[1].node_id})")
        return self.nodes[k]

    # ------------------------------------------------------------------ the sans-IO interface

    def power_on(self, t: float) -> list[Frame]:
        """Switch every node on (or power-cycle them) at time ``t`` [s].

        Returns
        -------
        list of Frame
            The boot-up frames ``0x700 + n [00]`` of every node (the drives, then the sensor
            nodes); they are then PRE-OPERATIONAL, drives SWITCH_ON_DISABLED.

        Notes
        -----
        The first power-on steps the plant once with both drives DISABLED so
        that the current sample is the measured rig at rest.
        """
        now = self._clock(t)
        if self._raw_sample is None:
            self._step(_MODE_DISABLED, 0.0, _MODE_DISABLED, 0.0)
            self._counters.plant_steps += 1
        self._powered = True
        for node in self.all_nodes:
            node.boot(now, communication_only=False)
        return self._drain()

    def on_frame(self, frame: Frame, t: float) -> list[Frame]:
        """Process one frame seen on the bus at time ``t`` [s]; return the frames to transmit.

        NMT (COB-ID 0, ``[cs, node or 0]``), SYNC (COB-ID of 0x1005), SDO
        requests (0x600 + n) and the RPDOs valid in each node are consumed;
        anything else is counted in ``stats.bad_frames_ignored`` and ignored.
        Never raises for frame contents.

        Raises
        ------
        hil.canopen.errors.CanopenInputError
            ``frame`` is not a :class:`hil.canopen.frame.Frame` or ``t`` not a finite time.
        """
        if frame.__class__ is not Frame and not isinstance(frame, Frame):
            raise CanopenInputError(f"frame must be a hil.canopen.frame.Frame, got {type(frame).__name__}")
        if t.__class__ is float and t - t == 0.0:  # finite float: _clock without the conversions
            now = self._now
            if t > now:
                now = self._now = t
        else:
            now = self._clock(t)
        if not self._powered:
            self._counters.frames_unpowered += 1
            return []
        cob = frame.arbitration_id
        n0, n1 = self.nodes
        if cob == 0:  # NMT_COB_ID
            self._on_nmt(frame, now)
        elif cob == n0.sync_cob_id or cob == n1.sync_cob_id:
            self._on_sync(frame, now)
        elif cob == n0.sdo_request_cob_id or cob == n1.sdo_request_cob_id:
            consumed = False
            for node in (n0, n1):
                if cob == node.sdo_request_cob_id:
                    node.on_sdo(frame, now)
                    consumed = True
                rx = node.rpdos_by_cob_id.get(cob)
                if rx:
                    node.on_rpdo(rx, frame, now)
                    consumed = True
            if not consumed:
                self._counters.bad_frames_ignored += 1
        elif 0x700 < cob <= 0x77F:  # a heartbeat: the nodes' consumers (0x1016)
            used = False
            if len(frame.data) == 1:
                used = n0.on_heartbeat(cob - 0x700, now)
                used = n1.on_heartbeat(cob - 0x700, now) or used
                for s in self.sensors:
                    used = s.on_heartbeat(cob - 0x700, now) or used
            if not used:
                self._counters.bad_frames_ignored += 1
        else:
            # RPDOs (or nothing): the nodes' RPDOs of this COB-ID, looked up once per
            # configuration (a node's RPDO only changes that node's configuration)
            if n0.rpdos_by_cob_id is not self._routes_rx[0] or n1.rpdos_by_cob_id is not self._routes_rx[1]:
                self._routes = {}
                self._routes_rx = (n0.rpdos_by_cob_id, n1.rpdos_by_cob_id)
            route = self._routes.get(cob)
            if route is None:
                route = self._routes[cob] = tuple(
                    (node, node.rpdos_by_cob_id[cob]) for node in (n0, n1) if node.rpdos_by_cob_id.get(cob))
            if route:
                for node, rx in route:
                    node.on_rpdo(rx, frame, now)
            elif not self.sensors or not self._sensor_frame(frame, now):
                self._counters.bad_frames_ignored += 1
        if n0.event_tpdos:
            n0.send_event_tpdos(now)
        if n1.event_tpdos:
            n1.send_event_tpdos(now)
        if self.sensors:
            for s in self.sensors:
                if s.event_tpdos:
                    s.send_event_tpdos(now)
        return self._drain()

    def _sensor_frame(self, frame: Frame, now: float) -> bool:
        """A frame no drive consumes, for the sensor nodes: an SDO request, a SYNC of a sensor node's
        own COB-ID (its TPDOs only), an RPDO. False if none consumes it."""
        cob = frame.arbitration_id
        node = self._sensor_sdo.get(cob)
        if node is not None:
            node.on_sdo(frame, now)
            return True
        used = False
        for s in self.sensors:
            if cob == s.sync_cob_id and len(frame.data) <= 1:
                s.now_s = now
                s.send_sync_tpdos(now)
                used = True
            rx = s.rpdos_by_cob_id.get(cob)
            if rx:
                s.on_rpdo(rx, frame, now)
                used = True
        return used

    def _on_nmt(self, frame: Frame, t: float) -> None:
        if len(frame.data) != 2:
            self._counters.bad_frames_ignored += 1
            return
        cs, target = frame.data
        try:
            NmtCommand(cs)
        except ValueError:
            self._counters.bad_frames_ignored += 1
            return
        targets = [n for n in self.all_nodes if target in (0, n.node_id)]
        if not targets:
            self._counters.bad_frames_ignored += 1
        for node in targets:
            node.on_nmt_command(cs, t)

    def _on_sync(self, frame: Frame, t: float) -> None:
        if len(frame.data) > 1:
            self._counters.bad_frames_ignored += 1
            return
        self._counters.syncs += 1
        step_t = t
        if self._last_sync_t is not None:
            # the drives' cycle is locked to SYNC (module docstring, "late SYNC"): this SYNC is the
            # period after the last step unless it came more than half a period after that period
            # (the master's nearest-slot rule, hil.transport.BusTransport.send_sync, on the same
            # numbers); then the periods passed over ran on the drives' own cycle first
            T = self._T
            late = t - self._last_step_t - T
            if late > 0.5 * T:
                self._free_run(self._last_step_t + int(late / T + 0.5) * T)
            step_t = self._last_step_t + T
            step_t += SYNC_PHASE_GAIN * (t - step_t)
        self._last_sync_t = t
        self._last_step_t = step_t
        cob = frame.arbitration_id
        n0, n1 = self.nodes
        c0 = n0.sync_cob_id == cob
        c1 = n1.sync_cob_id == cob
        if c0:
            n0.now_s = t
            n0.send_sync_tpdos(t)
        if c1:
            n1.now_s = t
            n1.send_sync_tpdos(t)
        if self.sensors:
            for s in self.sensors:
                if s.sync_cob_id == cob:
                    s.now_s = t
                    s.send_sync_tpdos(t)
                    s.apply_latched_rpdos()
        if c0:
            n0.apply_latched_rpdos()
        if c1:
            n1.apply_latched_rpdos()
        mode1, value1 = n0.drive_cycle()
        mode2, value2 = n1.drive_cycle()
        if n0.command_override is not None:
            mode1, value1 = n0.command_override(n0, t, mode1, value1)
        if n1.command_override is not None:
            mode2, value2 = n1.command_override(n1, t, mode2, value2)
        self._step(mode1, value1, mode2, value2)
        self._counters.plant_steps += 1

    def tick(self, t: float) -> list[Frame]:
        """Let time pass to ``t`` [s]: the drives' own cycle while SYNC is missing (module
        docstring), heartbeat consumers, heartbeats (0x1017) and timed event TPDOs that are due.

        A heartbeat is sent at the first tick at or after each multiple of the
        producer time since boot-up (or since 0x1017 was written); if ticks are
        farther apart than the period, one heartbeat is sent and the schedule
        restarts from ``t``.

        Returns
        -------
        list of Frame
            Heartbeats ``0x700 + n [state]`` (0x7F pre-operational, 0x05
            operational, 0x04 stopped) and event TPDOs, node by node.
        """
        if t.__class__ is float and t - t == 0.0:  # finite float: _clock without the conversions
            now = self._now
            if t > now:
                now = self._now = t
        else:
            now = self._clock(t)
        if self._powered:
            last = self._last_sync_t
            if last is not None and now - last > FREE_RUN_AFTER_CYCLES * self._T:
                self._free_run(now)
            for node in self.all_nodes:
                node.nmt_tick(now)
        return self._drain()

    def _free_run(self, now: float) -> None:
        """The drives' own cycle up to ``now`` while SYNC is missing: every sample period from the
        last step, heartbeat consumers at the step's time, then the drive cycle and one plant step."""
        n0, n1 = self.nodes
        T = self._T
        while self._last_step_t + T <= now + TIME_EPS_S:
            if n0.state_machine.state not in _POWERED and n1.state_machine.state not in _POWERED:
                # every power stage off: the rig rests on its brakes (the cycle keeps its phase)
                self._last_step_t += int((now + TIME_EPS_S - self._last_step_t) / T) * T
                return
            tau = self._last_step_t + T
            for node in self.nodes:
                node.now_s = tau
                if node.heartbeat_consumers:
                    node.supervise_heartbeats(tau)
            mode1, value1 = n0.drive_cycle()
            mode2, value2 = n1.drive_cycle()
            if n0.command_override is not None:
                mode1, value1 = n0.command_override(n0, tau, mode1, value1)
            if n1.command_override is not None:
                mode2, value2 = n1.command_override(n1, tau, mode2, value2)
            self._step(mode1, value1, mode2, value2)
            self._counters.free_steps += 1
            self._last_step_t = tau
            if self.on_free_step is not None:
                self.on_free_step(tau)

    # ------------------------------------------------------------------ fault hooks

    def inject_fault(self, node_index: int, emcy_code: int) -> list[Frame]:
        """Make drive ``node_index`` (0 or 1) fault with error code ``emcy_code``.

        The state machine goes to FAULT_REACTION_ACTIVE (FAULT at the next
        SYNC), 0x603F and the error register 0x1001 are set
        (:func:`hil.canopen.emcy.error_register_bits`), the code is pushed into 0x1003.

        Returns
        -------
        list of Frame
            The EMCY ``[code u16, 0x1001, 0, 0, 0, 0, 0]`` (empty if the node is
            STOPPED or 0x1014 is invalid).

        Raises
        ------
        hil.canopen.errors.CanopenInputError
            ``node_index`` not 0/1, ``emcy_code`` not in 0x0001..0xFFFF, or the
            pair is not powered on.
        """
        node = self._node_index(node_index)
        code = error_code(emcy_code, "emcy_code")
        if not self._powered:
            raise CanopenInputError("inject_fault needs a powered pair: call power_on(t) first")
        node.enter_fault(code)
        node.send_event_tpdos(self._now)
        return self._drain()

    def set_heartbeat_enabled(self, node_index: int, enabled: bool) -> None:
        """Fault hook: stop (False) or resume (True) the heartbeat frames of drive ``node_index``."""
        node = self._node_index(node_index)
        if not isinstance(enabled, bool):
            raise CanopenInputError(f"enabled must be a bool, got {enabled!r}")
        node.heartbeat_enabled = enabled
