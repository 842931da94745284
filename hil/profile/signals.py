"""The signal map of an actuation profile: ``[signals.ema1]``, ``[signals.ema2]``, ``[nodes.NAME]``,
``canopen.cob_ids`` into :class:`hil.canopen.signalmap.SignalMap`, and back (meta.json's snapshot).

docs/drives.md describes the tables for a rig engineer; every error names the profile field.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from typing import Any

from canopen.objectdictionary import datatypes

from hil.canopen.errors import CanopenInputError
from hil.canopen.signalmap import (
    DEFAULT_OBJECTS,
    DRIVE_ROLE,
    DeviceProfile,
    ForceControl,
    NodeRole,
    NodeSpec,
    Scale,
    ScaleSource,
    Signal,
    SignalEntry,
    SignalMap,
    angle_scale_counts,
    parse_object,
    torque_scale,
)
from hil.errors import ProfileError
from hil.profile.config import Actuation
from hil.profile.tables import Problems, check_keys, check_range, convert_scalar

__all__ = ["LEGACY_SIGNALS", "NO_SIGNALS", "gear_ratio_object", "load_signal_map", "signal_tables"]


#: Keys of a signal's table besides ``object``, ``node`` and ``type``, per signal.
_SCALE_KEYS = {
    Signal.MOTOR_ANGLE: ("counts_per_rev", "rad_per_unit", "units"),
    Signal.LVDT: ("mm_per_unit", "offset_mm"),
    Signal.FORCE: ("N_per_unit", "offset_N"),
    Signal.TARGET_TORQUE: ("rated_torque_Nm",),
}
#: The signals a profile must place (the others default to the drive's CiA 402 objects).
_REQUIRED_SIGNALS = (Signal.MOTOR_ANGLE, Signal.LVDT, Signal.FORCE)
_TYPES = {k: v for k, v in vars(datatypes).items() if k.isupper() and isinstance(v, int) and k != "SIGNED_TYPES"}
_ANGLE_UNITS = {"0x608F": ScaleSource.ENCODER, "0x6091/0x6092": ScaleSource.FACTOR_GROUP}
_NODE_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")


def _table(value: Any, where: str, fname: str) -> dict:
    if not isinstance(value, dict):
        raise ProfileError(f"{fname}: '{where}' must be a table")
    return value


def _number(tbl: dict, key: str, where: str, fname: str, *, nonzero: bool = False, positive: bool = False,
            default: float | None = None) -> float | None:
    if key not in tbl:
        return default
    v = convert_scalar(tbl[key], float, f"{where}.{key}", fname)
    if (nonzero or positive) and v == 0.0:
        raise ProfileError(f"{fname}: field '{where}.{key}' = {v:g}: a scaling of zero maps every raw value "
                           f"to the same reading")
    if positive and v < 0.0:
        raise ProfileError(f"{fname}: field '{where}.{key}' = {v:g} must be > 0")
    return v


def _signal_entry(sig: Signal, ema: int, tbl: Any, act: Actuation, fname: str) -> SignalEntry:
    where = f"signals.ema{ema}.{sig.value}"
    tbl = _table(tbl, where, fname)
    check_keys(tbl, ["object", "node", "type", *_SCALE_KEYS.get(sig, ())], where + ".", fname)
    default = DEFAULT_OBJECTS.get(sig)
    if "object" not in tbl and default is None:
        raise ProfileError(f"{fname}: missing field '{where}.object' (e.g. \"0x6401:01\")")
    try:
        index, sub = parse_object(tbl["object"], f"{where}.object") if "object" in tbl else default
    except CanopenInputError as exc:
        raise ProfileError(f"{fname}: field {exc}") from None
    node = tbl.get("node", f"ema{ema}")
    if not isinstance(node, str):
        raise ProfileError(f"{fname}: field '{where}.node' must be a node name, got {node!r}")
    data_type = None
    if "type" in tbl:
        t = tbl["type"]
        if t not in _TYPES:
            close = difflib.get_close_matches(str(t), list(_TYPES), n=1, cutoff=0.5)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ProfileError(f"{fname}: field '{where}.type' = {t!r} is not a CiA 301 data type{hint}")
        data_type = _TYPES[t]
    scale, source = None, ScaleSource.PROFILE
    if sig is Signal.MOTOR_ANGLE:
        given = [k for k in _SCALE_KEYS[sig] if k in tbl]
        if len(given) != 1:
            raise ProfileError(f"{fname}: '{where}' needs exactly one of counts_per_rev (increments per motor "
                               f"revolution), rad_per_unit, units = \"0x608F\" or \"0x6091/0x6092\" "
                               f"(as read from the drive); got {given or 'none'}")
        if "counts_per_rev" in tbl:
            counts = convert_scalar(tbl["counts_per_rev"], int, f"{where}.counts_per_rev", fname)
            check_range(counts, {"lo": 1, "hi": 2**32 - 1}, f"{where}.counts_per_rev", fname)
            scale = angle_scale_counts(counts)
        elif "rad_per_unit" in tbl:
            scale = Scale.per_unit(_number(tbl, "rad_per_unit", where, fname, nonzero=True))
        else:
            units = tbl["units"]
            if units not in _ANGLE_UNITS:
                raise ProfileError(f"{fname}: field '{where}.units' = {units!r}: \"0x608F\" (increments per "
                                   f"revolution as read) or \"0x6091/0x6092\" (user units as read)")
            source = _ANGLE_UNITS[units]
    elif sig is Signal.LVDT:
        if "mm_per_unit" not in tbl:
            raise ProfileError(f"{fname}: missing field '{where}.mm_per_unit' (mm of stroke per raw unit)")
        scale = Scale.per_unit(_number(tbl, "mm_per_unit", where, fname, nonzero=True),
                               _number(tbl, "offset_mm", where, fname, default=0.0))
    elif sig is Signal.FORCE:
        if "N_per_unit" not in tbl:
            raise ProfileError(f"{fname}: missing field '{where}.N_per_unit' (N of force per raw unit)")
        scale = Scale.per_unit(_number(tbl, "N_per_unit", where, fname, nonzero=True),
                               _number(tbl, "offset_N", where, fname, default=0.0))
    elif sig is Signal.TARGET_TORQUE:
        rated = _number(tbl, "rated_torque_Nm", where, fname, positive=True)
        if rated is None:
            source = ScaleSource.RATED_TORQUE
        else:
            scale = torque_scale(rated, act.mechanics.i_total_rad_per_mm)
    return SignalEntry(sig, ema, node, index, sub, data_type, scale, source, where)


def _node_spec(name: str, tbl: Any, act: Actuation, fname: str) -> NodeSpec:
    where = f"nodes.{name}"
    if not _NODE_NAME.match(name) or name in DRIVE_ROLE:
        raise ProfileError(f"{fname}: table '{where}': a node name is lower-case letters, digits and _ "
                           f"(ema1 and ema2 are the drives)")
    tbl = _table(tbl, where, fname)
    known = ["node_id", "eds", "vendor_id", "product_code", "revision_min", "device_profile", "heartbeat_period_s"]
    check_keys(tbl, known, where + ".", fname)
    for k in known[:-1]:
        if k not in tbl and k != "device_profile":
            raise ProfileError(f"{fname}: missing field '{where}.{k}'")
    nid = convert_scalar(tbl["node_id"], int, f"{where}.node_id", fname)
    check_range(nid, {"lo": 1, "hi": 127}, f"{where}.node_id", fname)
    eds = convert_scalar(tbl["eds"], str, f"{where}.eds", fname)
    ident = []
    for k in ("vendor_id", "product_code", "revision_min"):
        v = convert_scalar(tbl[k], int, f"{where}.{k}", fname)
        check_range(v, {"lo": 0, "hi": 0xFFFF_FFFF}, f"{where}.{k}", fname)
        ident.append(v)
    profile = convert_scalar(tbl.get("device_profile", 401), int, f"{where}.device_profile", fname)
    if profile not in (DeviceProfile.IO, DeviceProfile.MEASURING):
        raise ProfileError(f"{fname}: field '{where}.device_profile' = {profile}: a sensor node is a CiA 401 "
                           f"I/O module (401) or a CiA 404 measuring device (404)")
    hb = act.canopen.heartbeat_period_s
    if "heartbeat_period_s" in tbl:
        hb = convert_scalar(tbl["heartbeat_period_s"], float, f"{where}.heartbeat_period_s", fname)
        check_range(hb, {"lo": 0.01, "hi": 10.0}, f"{where}.heartbeat_period_s", fname)
    return NodeSpec(name, NodeRole.SENSORS, nid, eds, *ident, profile, hb, where)


#: The message for a profile without a signal map (``fname`` to fill in).
NO_SIGNALS = ("{fname}: missing tables '[signals.ema1]' and '[signals.ema2]': where each signal of the check "
              "lives (docs/drives.md)")


def load_signal_map(signals: Any, nodes: Any, cob_ids: Any, act: Actuation, fname: str) -> SignalMap:
    """``[signals.ema1]``, ``[signals.ema2]``, ``[nodes.NAME]`` and ``canopen.cob_ids`` -> :class:`SignalMap`.

    Every error names the profile field (docs/drives.md describes the tables); every problem is named
    at once (one :class:`~hil.errors.ProfileError` holding them all)."""
    if signals is None:
        raise ProfileError(NO_SIGNALS.format(fname=fname))
    problems = Problems()
    signals = _table(signals, "signals", fname)
    with problems.collect():
        check_keys(signals, ["ema1", "ema2"], "signals.", fname)
    c = act.canopen
    drives = tuple(NodeSpec(f"ema{k}", NodeRole.DRIVE, nid, c.eds, c.vendor_id, c.product_code, c.revision_min,
                            DeviceProfile.DRIVE, c.heartbeat_period_s, "canopen")
                   for k, nid in ((1, c.node_id_ema1), (2, c.node_id_ema2)))
    extra = _sensor_nodes(nodes, act, fname, problems)
    names = {n.name for n in drives + extra}
    entries = []
    for ema in (1, 2):
        with problems.collect():
            entries += _ema_entries(signals, ema, act, fname, names, problems)
    try:
        fc = ForceControl(c.force_control)
    except ValueError:
        fc = None
        problems.add(f"{fname}: field 'canopen.force_control' = {c.force_control!r}: \"auto\", \"cst\" or \"csp\"")
    if c.gear_ratio_object:
        try:
            parse_object(c.gear_ratio_object, "canopen.gear_ratio_object")
        except CanopenInputError as exc:
            problems.add(f"{fname}: field {exc}")
    cobs = []
    with problems.collect():
        cobs = _cob_ids(cob_ids, names, fname, problems)
    problems.raise_any()
    return SignalMap(drives + extra, tuple(entries), fc, tuple(cobs))


def _sensor_nodes(nodes: Any, act: Actuation, fname: str, problems: Problems) -> tuple[NodeSpec, ...]:
    """The ``[nodes.NAME]`` tables, each with a node id of its own; problems collected."""
    c = act.canopen
    extra = []
    with problems.collect():
        for n, t in _table(nodes, "nodes", fname).items():
            with problems.collect():
                extra.append(_node_spec(str(n), t, act, fname))
    seen = {c.master_node_id: "canopen.master_node_id", c.node_id_ema1: "canopen.node_id_ema1",
            c.node_id_ema2: "canopen.node_id_ema2"}
    for n in extra:
        if n.node_id in seen:
            problems.add(f"{fname}: fields '{n.key}.node_id' and '{seen[n.node_id]}' are both {n.node_id}; "
                         f"every node needs a node id of its own")
        seen[n.node_id] = f"{n.key}.node_id"
    return tuple(extra)


def _ema_entries(signals: dict, ema: int, act: Actuation, fname: str, names: set[str],
                 problems: Problems) -> list[SignalEntry]:
    """One EMA's signal entries (the target position in the motor angle's scaling); problems collected."""
    key = f"ema{ema}"
    if key not in signals:
        raise ProfileError(f"{fname}: missing table '[signals.{key}]'")
    tbl = _table(signals[key], f"signals.{key}", fname)
    with problems.collect():
        check_keys(tbl, [x.value for x in Signal], f"signals.{key}.", fname)
    for sig in _REQUIRED_SIGNALS:
        if sig.value not in tbl:
            problems.add(f"{fname}: missing field 'signals.{key}.{sig.value}' (where the check reads "
                         f"EMA {ema}'s {sig.value.replace('_', ' ')}; docs/drives.md)")
    entries = []
    for sig in Signal:
        if sig in _REQUIRED_SIGNALS and sig.value not in tbl:
            continue
        with problems.collect():
            e = _signal_entry(sig, ema, tbl.get(sig.value, {}), act, fname)
            if e.node not in names:
                raise ProfileError(f"{fname}: field '{e.key}.node' = {e.node!r} is not a node of the rig "
                                   f"(ema1, ema2{''.join(', ' + n for n in sorted(names - set(DRIVE_ROLE)))})")
            entries.append(e)
    # the target position is in the units of the drive's position actual value: the motor angle's scaling
    angle = next((e for e in entries if e.signal is Signal.MOTOR_ANGLE), None)
    k = next((i for i, e in enumerate(entries) if e.signal is Signal.TARGET_POSITION), None)
    if angle is not None and k is not None:
        entries[k] = dataclasses.replace(entries[k], scale=angle.scale, source=angle.source)
    return entries


def _cob_ids(cob_ids: Any, names: set[str], fname: str, problems: Problems) -> list[tuple[str, str, int]]:
    """``canopen.cob_ids``: NODE.TPDOn / NODE.RPDOn -> COB-ID; problems collected."""
    cobs = []
    for k, v in _table(cob_ids, "canopen.cob_ids", fname).items():
        with problems.collect():
            m = re.fullmatch(r"([a-z][a-z0-9_]*)\.([TR]PDO)([1-9]\d{0,2})", str(k))
            if m is None or m.group(1) not in names:
                raise ProfileError(f"{fname}: field 'canopen.cob_ids.{k}': a key is NODE.TPDOn or NODE.RPDOn with "
                                   f"NODE one of {', '.join(sorted(names))}")
            cob = convert_scalar(v, int, f"canopen.cob_ids.{k}", fname)
            check_range(cob, {"lo": 1, "hi": 0x7FF}, f"canopen.cob_ids.{k}", fname)
            cobs.append((m.group(1), m.group(2) + m.group(3), cob))
    return cobs


#: The signal tables of an actuation snapshot written before the signal map existed: the one drive
#: emacheck knew (0x6064 in 4096 increments per revolution, LVDT 0x2100 in um, force 0x2101 in 0.1 N).
LEGACY_SIGNALS = {f"ema{k}": {"motor_angle": {"object": "0x6064:00", "counts_per_rev": 4096},
                               "lvdt": {"object": "0x2100:00", "mm_per_unit": 0.001},
                               "force": {"object": "0x2101:00", "N_per_unit": 0.1},
                               "target_torque": {"object": "0x6071:00"}} for k in (1, 2)}


def gear_ratio_object(act: Actuation) -> tuple[int, int] | None:
    """The drives' gear-ratio object of ``canopen.gear_ratio_object``, None when the profile names none."""
    g = act.canopen.gear_ratio_object
    return parse_object(g, "canopen.gear_ratio_object") if g else None


def signal_tables(act: Actuation) -> dict:
    """``{"signals": ..., "nodes": ..., "cob_ids": ...}``: the tables :func:`load_signal_map` reads back."""
    smap = act.signals
    i_total = act.mechanics.i_total_rad_per_mm
    sig: dict[str, dict] = {"ema1": {}, "ema2": {}}
    inverse = {v: k for k, v in _TYPES.items()}
    for e in smap.entries:
        t: dict[str, Any] = {"object": f"0x{e.index:04X}:{e.subindex:02X}"}
        if e.node != f"ema{e.ema}":
            t["node"] = e.node
        if e.data_type is not None:
            t["type"] = inverse.get(e.data_type, str(e.data_type))
        sc = e.scale
        if e.signal is Signal.MOTOR_ANGLE:
            if e.source is ScaleSource.PROFILE:
                counts = sc.units_per_si * 2.0 * math.pi
                if abs(counts - round(counts)) < 1e-6 * counts:
                    t["counts_per_rev"] = int(round(counts))
                else:
                    t["rad_per_unit"] = sc.si_per_unit
            else:
                t["units"] = e.source.value
        elif e.signal is Signal.LVDT:
            t.update(mm_per_unit=sc.si_per_unit, offset_mm=sc.offset)
        elif e.signal is Signal.FORCE:
            t.update(N_per_unit=sc.si_per_unit, offset_N=sc.offset)
        elif e.signal is Signal.TARGET_TORQUE and e.source is ScaleSource.PROFILE:
            t["rated_torque_Nm"] = 1.0 / (sc.units_per_si * i_total)
        sig[f"ema{e.ema}"][e.signal.value] = t
    nodes = {n.name: {"node_id": n.node_id, "eds": n.eds, "vendor_id": n.vendor_id,
                              "product_code": n.product_code, "revision_min": n.revision_min,
                              "device_profile": n.device_profile, "heartbeat_period_s": n.heartbeat_period_s}
                     for n in smap.nodes if n.role is NodeRole.SENSORS}
    return {"signals": sig, "nodes": nodes, "cob_ids": {f"{n}.{p}": c for n, p, c in smap.cob_ids}}
