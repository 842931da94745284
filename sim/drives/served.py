"""What each simulated node serves: the measured inputs the rig's map puts on it, and its own data.

A simulated node is built from the EDS the master reads (a vendor's file
included) and the rig's :class:`~hil.canopen.plan.RigPlan`:

* :func:`live_inputs`: the measured values (motor angle, LVDT, force of
  either EMA) the signal map places at the node's objects, with the map's
  data type and scaling (:class:`~sim.drives.node.LiveInput`);
* :func:`own_data`: what a real device would hold where its EDS gives no
  default (an EDS describes a family; the device knows its own identity,
  modes and ratings), restored at power-on and reset node.

Own data (only where the EDS has no default, or a zero default where zero
cannot be the device's value)
--------------------------------------------------------------------------
* identity 0x1018:01..03: the profile's vendor id, product code and lowest
  accepted revision (also over a zero default);
* device type 0x1000: the profile's CiA device profile (402 servo drive
  0x00020192, 401 analog input module 0x00040191, 404 measuring device
  0x00000194);
* a drive's supported modes 0x6502: CSP, and CST where the rig uses it;
  rated torque 0x6076 = 1000 mN m (also over a zero default); max torque
  0x6072 = 10000 per mille (also over a zero default); encoder resolution
  0x608F = the profile's counts per revolution (else 4096) increments / 1
  revolution in its EDS data type (UNSIGNED32, or INTEGER32 as Nanotec
  types it); position factors 0x6091, 0x6092 = 1/1
  (also over zero defaults).

Any other object without a value reads as its data type's zero
(:class:`~sim.drives.store.ObjectStore`).
"""

from __future__ import annotations

import struct

import canopen.objectdictionary as cod

from hil.canopen.od import lookup
from hil.canopen.plan import CSP_BIT, CST_BIT, RigPlan
from hil.canopen.signalmap import ForceControl, NodeRole, NodeSpec, ScaleSource, Signal
from sim.drives.node import LiveInput
from sim.drives.store import INT_CODES, STRUCT_CODES

__all__ = ["DEVICE_TYPE", "live_inputs", "own_data"]

#: Device type 0x1000 of a simulated node whose EDS gives none: CiA 402 servo drive, CiA 401 analog
#: input module, CiA 404 measuring device.
DEVICE_TYPE = {402: 0x00020192, 401: 0x00040191, 404: 0x00000194}
_MEASURED = (Signal.MOTOR_ANGLE, Signal.LVDT, Signal.FORCE)


def live_inputs(plan: RigPlan, spec: NodeSpec) -> tuple[LiveInput, ...]:
    """The measured inputs the rig's map puts on node ``spec``, with the scaling the profile states
    (None where the scaling is read from a drive: its own position units)."""
    out = []
    for e in plan.map.entries:
        if e.node != spec.name or e.signal not in _MEASURED:
            continue
        scale = e.scale if e.source is ScaleSource.PROFILE else None
        out.append(LiveInput(e.signal, e.ema, e.object, e.data_type, scale))
    return tuple(out)


def own_data(od: cod.ObjectDictionary, spec: NodeSpec, force_control: ForceControl | None = None,
             counts_per_rev: float | None = None) -> dict[tuple[int, int], bytes]:
    """A simulated node's own data where its EDS gives no default (module docstring):
    ``(index, sub) -> bytes`` in each object's data type; ``counts_per_rev`` the encoder resolution
    the profile states for a drive (its 0x608F:01, rounded), default 4096."""
    own: dict[tuple[int, int], bytes] = {}

    def put(index: int, sub: int, value: int, *, zero_too: bool = False) -> None:
        var = lookup(od, index, sub)
        if var is None or (var.default is not None and not (zero_too and var.default == 0)):
            return
        code = STRUCT_CODES.get(var.data_type)
        if code in INT_CODES:
            own[(index, sub)] = struct.pack("<" + code, value)

    put(0x1000, 0, DEVICE_TYPE.get(spec.device_profile, spec.device_profile))
    put(0x1018, 1, spec.vendor_id, zero_too=True)
    put(0x1018, 2, spec.product_code, zero_too=True)
    put(0x1018, 3, spec.revision_min, zero_too=True)
    if spec.role is NodeRole.DRIVE:
        put(0x6502, 0, 1 << CSP_BIT | (1 << CST_BIT if force_control is ForceControl.CST else 0))
        put(0x6076, 0, 1000, zero_too=True)
        put(0x6072, 0, 10000, zero_too=True)
        put(0x608F, 1, 4096 if counts_per_rev is None else max(1, round(counts_per_rev)))
        put(0x608F, 2, 1)
        for index in (0x6091, 0x6092):
            for sub in (1, 2):
                put(index, sub, 1, zero_too=True)
    return own


