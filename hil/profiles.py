"""Load profiles (TOML) from a given path into validated frozen dataclasses.

Three profiles describe a check: the actuation (:class:`hil.config.Actuation`),
the check itself (:class:`hil.config.Check`) and, for dry-runs, the simulated
rig (:class:`sim.params.RigParams`). The defaults ship in the ``profiles``
package. Every error names the file and the dotted field, e.g.
``check.toml: force_fight.amplitude_fraction_of_limit = 0.2 is above the hard
cap 0.15``; unknown keys are refused with the closest known name, which catches
wrong units (``sweep_speed_mm_per_min`` is not ``sweep_speed_mm_per_s``).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
import typing
from dataclasses import dataclass, field
from enum import Enum
from importlib import resources
from pathlib import Path
from typing import Any

from canopen.objectdictionary import datatypes

from hil.config import (
    HARD_FORCE_FIGHT_FRACTION,
    HARD_MAX_FORCE_FIGHT_FRACTION,
    HARD_MAX_FORCE_FRACTION,
    HARD_MAX_FORCE_IMBALANCE_FRACTION,
    Actuation,
    Check,
)
from hil.canopen.errors import InputError
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
from sim import effects as sim_effects
from sim.params import DriveParams, EmaMechanics, RigParams, SensorParams, SurfaceParams, WearParams


def default_profile_path(name: str) -> Path:
    """Path of a profile shipped in the ``profiles`` package (e.g. ``"check.toml"``)."""
    return Path(str(resources.files("profiles").joinpath(name)))


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ProfileError(f"{path}: profile not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{path}: not valid TOML: {exc}") from None


def _check_keys(table: dict, known: list[str], where: str, fname: str) -> None:
    for key in table:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1, cutoff=0.5)
            hint = f" (did you mean '{close[0]}'? units are part of the name)" if close else ""
            raise ProfileError(f"{fname}: unknown field '{where}{key}'{hint}")


def _convert_scalar(value: Any, typ: Any, name: str, fname: str) -> Any:
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ProfileError(f"{fname}: field '{name}' must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ProfileError(f"{fname}: field '{name}' must be finite, got {value!r}")
        return value
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProfileError(f"{fname}: field '{name}' must be an integer, got {value!r}")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise ProfileError(f"{fname}: field '{name}' must be a string, got {value!r}")
        return value
    raise ProfileError(f"{fname}: field '{name}' has an unsupported type {typ!r}")  # pragma: no cover


def _check_range(value: Any, meta: typing.Mapping, name: str, fname: str) -> None:
    lo, hi, hard = meta.get("lo"), meta.get("hi"), meta.get("hard_max")
    if hard is not None and value > hard:
        raise ProfileError(f"{fname}: field '{name}' = {value} is above the hard cap {hard}")
    if lo is not None:
        if meta.get("lo_open") and not value > lo:
            raise ProfileError(f"{fname}: field '{name}' = {value} must be > {lo}")
        if not meta.get("lo_open") and not value >= lo:
            raise ProfileError(f"{fname}: field '{name}' = {value} must be >= {lo}")
    if hi is not None and value > hi:
        raise ProfileError(f"{fname}: field '{name}' = {value} must be <= {hi}")


def build_dataclass(cls: type, table: Any, fname: str, where: str = "",
                    ranges: typing.Mapping[str, tuple] | None = None) -> Any:
    """Build a (nested) frozen dataclass from a TOML table, validating everything.

    Parameters
    ----------
    cls : dataclass type
    table : dict
        The TOML table.
    fname : str
        File name quoted in errors.
    where : str
        Dotted prefix of this table quoted in errors.
    ranges : mapping, optional
        ``{"Class.field": (lo, hi)}`` for classes without range metadata.
    """
    if not isinstance(table, dict):
        raise ProfileError(f"{fname}: '{where.rstrip('.') or 'profile'}' must be a table")
    hints = typing.get_type_hints(cls)
    fields = [f for f in dataclasses.fields(cls) if f.init]
    names = [f.name for f in fields]
    _check_keys(table, names, where, fname)
    kwargs = {}
    for f in fields:
        name = f"{where}{f.name}"
        if f.name not in table:
            if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING:
                continue
            raise ProfileError(f"{fname}: missing field '{name}'")
        typ = hints[f.name]
        value = table[f.name]
        if dataclasses.is_dataclass(typ):
            kwargs[f.name] = build_dataclass(typ, value, fname, name + ".", ranges)
            continue
        value = _convert_scalar(value, typ, name, fname)
        meta = dict(f.metadata)
        if ranges and f"{cls.__name__}.{f.name}" in ranges:
            lo, hi = ranges[f"{cls.__name__}.{f.name}"]
            meta.update(lo=lo, hi=hi, lo_open=False)
        if meta:
            _check_range(value, meta, name, fname)
        kwargs[f.name] = value
    return cls(**kwargs)


# ----------------------------------------------------------------- loaders


def load_actuation(path: str | Path | None = None) -> Actuation:
    """Load and validate an actuation profile (default: the shipped one), its signal map included."""
    path = Path(path) if path is not None else default_profile_path("actuation.toml")
    fname = path.name
    data = _read_toml(path)
    _refuse_moved(data, fname)
    signals = data.pop("signals", None)
    nodes = data.pop("nodes", {})
    co = data.get("canopen")
    cob_ids = co.pop("cob_ids", {}) if isinstance(co, dict) else {}
    act = build_dataclass(Actuation, data, fname)
    c = act.canopen
    if c.node_id_ema1 == c.node_id_ema2:
        raise ProfileError(f"{fname}: fields 'canopen.node_id_ema1' and 'canopen.node_id_ema2' "
                           f"are both {c.node_id_ema1}; the drives need distinct node ids")
    for name in ("node_id_ema1", "node_id_ema2"):
        if getattr(c, name) == c.master_node_id:
            raise ProfileError(f"{fname}: fields 'canopen.master_node_id' and 'canopen.{name}' are both "
                               f"{c.master_node_id}; the master's heartbeat needs a node id of its own")
    consumer_ms = c.master_consumer_time_s * 1000.0
    if not 1.0 <= consumer_ms <= 0xFFFF:
        raise ProfileError(f"{fname}: fields 'canopen.master_heartbeat_consumer_factor' * "
                           f"'canopen.master_heartbeat_period_s' give a consumer heartbeat time of "
                           f"{consumer_ms:g} ms; 0x1016 holds 1..65535 ms")
    if act.history.url:
        from hil.history.errors import HistoryInputError
        from hil.history.url import check_url

        try:
            check_url(act.history.url)
        except HistoryInputError as exc:
            raise ProfileError(f"{fname}: field 'history.url': {exc}") from None
    for name in ("external_watchdog", "skip_master_loss_drill"):
        text = getattr(c, name)
        if text != text.strip() or "\n" in text:
            raise ProfileError(f"{fname}: field 'canopen.{name}' must be one line without "
                               f"leading or trailing blanks (it is quoted in the run folder)")
    return dataclasses.replace(act, signals=load_signal_map(signals, nodes, cob_ids, act, fname))


#: Keys of earlier actuation profiles and where they went.
_MOVED = {("sensors", "resolver_counts_per_rev"): "signals.ema1.motor_angle.counts_per_rev (and ema2)"}


def _refuse_moved(data: dict, fname: str) -> None:
    for (table, key), where in _MOVED.items():
        if isinstance(data.get(table), dict) and key in data[table]:
            raise ProfileError(f"{fname}: field '{table}.{key}' has moved to '{where}' (docs/drives.md)")


def resolve_eds(name: str, profile_path: str | Path | None, key: str = "canopen.eds",
                override: str | Path | None = None) -> Path:
    """Path of an EDS a profile names: ``override`` (``--eds``) if given, else relative to the
    profile, else an absolute path, else a shipped one; ProfileError naming ``key`` if none exists."""
    if override is not None:
        p = Path(override)
        if not p.is_file():
            raise ProfileError(f"--eds {override}: no such file")
        return p
    if profile_path is not None:
        p = Path(profile_path).parent / name
        if p.is_file():
            return p
    p = Path(name)
    if p.is_absolute() and p.is_file():
        return p
    shipped = default_profile_path(name)
    if shipped.is_file():
        return shipped
    raise ProfileError(f"actuation profile: field '{key}' = {name!r}: no such EDS (looked next to the profile "
                       f"and among the shipped profiles; give its path with --eds PATH)")


# ----------------------------------------------------------------- the signal map

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
    v = _convert_scalar(tbl[key], float, f"{where}.{key}", fname)
    if (nonzero or positive) and v == 0.0:
        raise ProfileError(f"{fname}: field '{where}.{key}' = {v:g}: a scaling of zero maps every raw value "
                           f"to the same reading")
    if positive and v < 0.0:
        raise ProfileError(f"{fname}: field '{where}.{key}' = {v:g} must be > 0")
    return v


def _signal_entry(sig: Signal, ema: int, tbl: Any, act: Actuation, fname: str) -> SignalEntry:
    where = f"signals.ema{ema}.{sig.value}"
    tbl = _table(tbl, where, fname)
    _check_keys(tbl, ["object", "node", "type", *_SCALE_KEYS.get(sig, ())], where + ".", fname)
    default = DEFAULT_OBJECTS.get(sig)
    if "object" not in tbl and default is None:
        raise ProfileError(f"{fname}: missing field '{where}.object' (e.g. \"0x6401:01\")")
    try:
        index, sub = parse_object(tbl["object"], f"{where}.object") if "object" in tbl else default
    except InputError as exc:
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
            counts = _convert_scalar(tbl["counts_per_rev"], int, f"{where}.counts_per_rev", fname)
            _check_range(counts, {"lo": 1, "hi": 2**32 - 1}, f"{where}.counts_per_rev", fname)
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
    _check_keys(tbl, known, where + ".", fname)
    for k in known[:-1]:
        if k not in tbl and k != "device_profile":
            raise ProfileError(f"{fname}: missing field '{where}.{k}'")
    nid = _convert_scalar(tbl["node_id"], int, f"{where}.node_id", fname)
    _check_range(nid, {"lo": 1, "hi": 127}, f"{where}.node_id", fname)
    eds = _convert_scalar(tbl["eds"], str, f"{where}.eds", fname)
    ident = []
    for k in ("vendor_id", "product_code", "revision_min"):
        v = _convert_scalar(tbl[k], int, f"{where}.{k}", fname)
        _check_range(v, {"lo": 0, "hi": 0xFFFF_FFFF}, f"{where}.{k}", fname)
        ident.append(v)
    profile = _convert_scalar(tbl.get("device_profile", 401), int, f"{where}.device_profile", fname)
    if profile not in (DeviceProfile.IO, DeviceProfile.MEASURING):
        raise ProfileError(f"{fname}: field '{where}.device_profile' = {profile}: a sensor node is a CiA 401 "
                           f"I/O module (401) or a CiA 404 measuring device (404)")
    hb = act.canopen.heartbeat_period_s
    if "heartbeat_period_s" in tbl:
        hb = _convert_scalar(tbl["heartbeat_period_s"], float, f"{where}.heartbeat_period_s", fname)
        _check_range(hb, {"lo": 0.01, "hi": 10.0}, f"{where}.heartbeat_period_s", fname)
    return NodeSpec(name, NodeRole.SENSORS, nid, eds, *ident, profile, hb, where)


def load_signal_map(signals: Any, nodes: Any, cob_ids: Any, act: Actuation, fname: str) -> SignalMap:
    """``[signals.ema1]``, ``[signals.ema2]``, ``[nodes.NAME]`` and ``canopen.cob_ids`` -> :class:`SignalMap`.

    Every error names the profile field (docs/drives.md describes the tables)."""
    if signals is None:
        raise ProfileError(f"{fname}: missing tables '[signals.ema1]' and '[signals.ema2]': where each signal "
                           f"of the check lives (docs/drives.md)")
    signals = _table(signals, "signals", fname)
    _check_keys(signals, ["ema1", "ema2"], "signals.", fname)
    c = act.canopen
    drives = tuple(NodeSpec(f"ema{k}", NodeRole.DRIVE, nid, c.eds, c.vendor_id, c.product_code, c.revision_min,
                            DeviceProfile.DRIVE, c.heartbeat_period_s, "canopen")
                   for k, nid in ((1, c.node_id_ema1), (2, c.node_id_ema2)))
    extra = tuple(_node_spec(str(n), t, act, fname) for n, t in _table(nodes, "nodes", fname).items())
    seen = {c.master_node_id: "canopen.master_node_id", c.node_id_ema1: "canopen.node_id_ema1",
            c.node_id_ema2: "canopen.node_id_ema2"}
    for n in extra:
        if n.node_id in seen:
            raise ProfileError(f"{fname}: fields '{n.key}.node_id' and '{seen[n.node_id]}' are both {n.node_id}; "
                               f"every node needs a node id of its own")
        seen[n.node_id] = f"{n.key}.node_id"
    names = {n.name for n in drives + extra}
    entries = []
    for ema in (1, 2):
        key = f"ema{ema}"
        if key not in signals:
            raise ProfileError(f"{fname}: missing table '[signals.{key}]'")
        tbl = _table(signals[key], f"signals.{key}", fname)
        _check_keys(tbl, [x.value for x in Signal], f"signals.{key}.", fname)
        for sig in _REQUIRED_SIGNALS:
            if sig.value not in tbl:
                raise ProfileError(f"{fname}: missing field 'signals.{key}.{sig.value}' (where the check reads "
                                   f"EMA {ema}'s {sig.value.replace('_', ' ')}; docs/drives.md)")
        for sig in Signal:
            e = _signal_entry(sig, ema, tbl.get(sig.value, {}), act, fname)
            if e.node not in names:
                raise ProfileError(f"{fname}: field '{e.key}.node' = {e.node!r} is not a node of the rig "
                                   f"(ema1, ema2{''.join(', ' + n.name for n in extra)})")
            entries.append(e)
        # the target position is in the units of the drive's position actual value: the motor angle's scaling
        angle = next(e for e in entries if e.ema == ema and e.signal is Signal.MOTOR_ANGLE)
        k = next(i for i, e in enumerate(entries) if e.ema == ema and e.signal is Signal.TARGET_POSITION)
        entries[k] = dataclasses.replace(entries[k], scale=angle.scale, source=angle.source)
    try:
        fc = ForceControl(c.force_control)
    except ValueError:
        raise ProfileError(f"{fname}: field 'canopen.force_control' = {c.force_control!r}: \"auto\", \"cst\" "
                           f"or \"csp\"") from None
    if c.gear_ratio_object:
        try:
            parse_object(c.gear_ratio_object, "canopen.gear_ratio_object")
        except InputError as exc:
            raise ProfileError(f"{fname}: field {exc}") from None
    cobs = []
    for k, v in _table(cob_ids, "canopen.cob_ids", fname).items():
        m = re.fullmatch(r"([a-z][a-z0-9_]*)\.([TR]PDO)([1-9]\d{0,2})", str(k))
        if m is None or m.group(1) not in names:
            raise ProfileError(f"{fname}: field 'canopen.cob_ids.{k}': a key is NODE.TPDOn or NODE.RPDOn with "
                               f"NODE one of {', '.join(sorted(names))}")
        cob = _convert_scalar(v, int, f"canopen.cob_ids.{k}", fname)
        _check_range(cob, {"lo": 1, "hi": 0x7FF}, f"canopen.cob_ids.{k}", fname)
        cobs.append((m.group(1), m.group(2) + m.group(3), cob))
    return SignalMap(drives + extra, tuple(entries), fc, tuple(cobs))


def gear_ratio_object(act: Actuation) -> tuple[int, int] | None:
    """The drives' gear-ratio object of ``canopen.gear_ratio_object``, None when the profile names none."""
    g = act.canopen.gear_ratio_object
    return parse_object(g, "canopen.gear_ratio_object") if g else None


def load_check(path: str | Path | None = None, actuation: Actuation | None = None) -> Check:
    """Load and validate a check profile; with ``actuation``, also cross-check limits."""
    path = Path(path) if path is not None else default_profile_path("check.toml")
    check = build_dataclass(Check, _read_toml(path), path.name)
    if actuation is not None:
        validate_check(check, actuation, path.name)
    return check


def validate_check(check: Check, act: Actuation, fname: str = "check.toml") -> None:
    """Cross-field checks between a check profile and the actuation it runs on."""
    f_limit = act.mechanics.limit_load_N
    cap = HARD_MAX_FORCE_FRACTION * f_limit
    s = check.safety
    if s.max_force_N > cap:
        raise ProfileError(
            f"{fname}: field 'safety.max_force_N' = {s.max_force_N} is above the hard cap "
            f"{cap:g} N ({HARD_MAX_FORCE_FRACTION:.0%} of limit_load_N)")
    for name, value, frac in (("safety.max_force_fight_N", s.max_force_fight_N, HARD_MAX_FORCE_FIGHT_FRACTION),
                              ("safety.max_force_imbalance_N", s.max_force_imbalance_N,
                               HARD_MAX_FORCE_IMBALANCE_FRACTION)):
        if value > frac * f_limit:
            raise ProfileError(f"{fname}: field '{name}' = {value} is above the hard cap "
                               f"{frac * f_limit:g} N ({frac:.0%} of limit_load_N)")
    ff = check.force_fight.amplitude_fraction_of_limit * f_limit
    if ff >= s.max_force_fight_N:
        raise ProfileError(
            f"{fname}: field 'force_fight.amplitude_fraction_of_limit' gives {ff:g} N, "
            f"not below safety.max_force_fight_N = {s.max_force_fight_N:g} N")
    if ff >= s.max_force_N:
        raise ProfileError(
            f"{fname}: field 'force_fight.amplitude_fraction_of_limit' gives {ff:g} N, "
            f"not below safety.max_force_N = {s.max_force_N:g} N")
    if check.force_fight.amplitude_fraction_of_limit > HARD_FORCE_FIGHT_FRACTION:  # pragma: no cover
        raise ProfileError(f"{fname}: force fight above the hard cap")  # (metadata catches it first)
    if check.calibration.opposing_force_N >= s.max_force_N:
        raise ProfileError(
            f"{fname}: field 'calibration.opposing_force_N' = {check.calibration.opposing_force_N:g} N "
            f"is not below safety.max_force_N = {s.max_force_N:g} N")
    if s.max_stroke_mm > act.mechanics.stroke_limit_mm:
        raise ProfileError(
            f"{fname}: field 'safety.max_stroke_mm' = {s.max_stroke_mm} is above the hard cap "
            f"{act.mechanics.stroke_limit_mm} mm (the actuation's stroke_limit_mm)")
    if check.calibration.sweep_amplitude_mm >= s.max_stroke_mm:
        raise ProfileError(
            f"{fname}: field 'calibration.sweep_amplitude_mm' = {check.calibration.sweep_amplitude_mm} "
            f"must stay below safety.max_stroke_mm = {s.max_stroke_mm}")
    for name, v in (("approach.speed_mm_per_s", check.approach.speed_mm_per_s),
                    ("calibration.sweep_speed_mm_per_s", check.calibration.sweep_speed_mm_per_s)):
        if v >= s.max_velocity_mm_per_s:
            raise ProfileError(f"{fname}: field '{name}' = {v} must stay below "
                               f"safety.max_velocity_mm_per_s = {s.max_velocity_mm_per_s}")


#: Ranges of the simulated-rig parameters (sim/params.py holds only values).
_SIM_RANGES: dict[str, tuple] = {
    "EmaMechanics.backlash_int_mm": (0.0, 5.0),
    "EmaMechanics.stiffness_compression_N_per_mm": (1.0, 1e7),
    "EmaMechanics.stiffness_tension_N_per_mm": (1.0, 1e7),
    "EmaMechanics.bearing_backlash_mm": (0.0, 5.0),
    "EmaMechanics.bearing_stiffness_N_per_mm": (1.0, 1e8),
    "EmaMechanics.housing_stiffness_N_per_mm": (1.0, 1e8),
    "DriveParams.motor_inertia_kg_m2": (1e-7, 10.0),
    "DriveParams.motor_viscous_Nm_s_per_rad": (0.0, 10.0),
    "DriveParams.torque_limit_Nm": (1e-3, 1e4),
    "DriveParams.position_bandwidth_rad_s": (1.0, 2000.0),
    "DriveParams.position_damping": (0.05, 5.0),
    "DriveParams.position_integral_time_s": (0.0, 100.0),
    "SurfaceParams.mass_kg": (1e-3, 1e6),
    "SurfaceParams.damping_N_s_per_mm": (0.0, 1e6),
    "SurfaceParams.load_stiffness_N_per_mm": (0.0, 1e7),
    "SensorParams.lvdt_gain": (0.5, 2.0),
    "SensorParams.lvdt_offset_mm": (-50.0, 50.0),
    "SensorParams.lvdt_nonlinearity_mm": (-5.0, 5.0),
    "SensorParams.lvdt_full_scale_mm": (1e-3, 500.0),
    "SensorParams.lvdt_noise_pp_mm": (0.0, 5.0),
    "SensorParams.loadcell_gain": (0.5, 2.0),
    "SensorParams.loadcell_noise_std_N": (0.0, 1e4),
    "SensorParams.resolver_bits": (4, 24),
    "WearParams.backlash_int1_mm_per_1000_fh": (-1.0, 1.0),
    "WearParams.backlash_int2_mm_per_1000_fh": (-1.0, 1.0),
    "WearParams.backlash_ext_mm_per_1000_fh": (-1.0, 1.0),
    "WearParams.scatter_mm": (0.0, 0.5),
    "WearParams.reference_flight_hours": (0.0, 1e6),
}


@dataclass(frozen=True)
class SimRigProfile:
    """A simulated-rig profile: the rig parameters and the seed recorded with it."""

    params: RigParams
    seed: int
    faults: tuple = ()  #: sim.faults.Fault schedule of ``[[faults]]`` (none by default)
    #: the simulated drives' serial numbers (0x1018:04) from ``[identity]``; None: the EDS's default
    serials: tuple[int, int] | None = None
    #: backlash growth with flight hours from ``[wear]`` (applied by ``--flight-hours``); None: no wear
    wear: WearParams | None = None


@dataclass(frozen=True)
class SimIdentity:
    """``[identity]`` of a simulated-rig profile: what the simulated drives report as their serial numbers."""

    serial_ema1: int = field(metadata={"lo": 0, "hi": 0xFFFF_FFFF})
    serial_ema2: int = field(metadata={"lo": 0, "hi": 0xFFFF_FFFF})


def load_simrig(path: str | Path | None = None) -> SimRigProfile:
    """Load and validate a simulated-rig profile (default: the shipped one)."""
    path = Path(path) if path is not None else default_profile_path("simrig.toml")
    fname = path.name
    data = _read_toml(path)
    required = ["seed", "rig", "ema1", "ema2", "drive", "surface", "sensors1", "sensors2"]
    known = required + ["effects", "faults", "identity", "wear"]
    _check_keys(data, known, "", fname)
    for key in required:
        if key not in data:
            raise ProfileError(f"{fname}: missing {'field' if key == 'seed' else 'table'} '{key}'")
    seed = data["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ProfileError(f"{fname}: field 'seed' must be a non-negative integer, got {seed!r}")
    rig = data["rig"]
    if not isinstance(rig, dict):
        raise ProfileError(f"{fname}: 'rig' must be a table")
    rig_known = ["i_total_rad_per_mm", "stroke_limit_mm", "sample_period_s", "substeps"]
    _check_keys(rig, rig_known, "rig.", fname)
    for k in rig_known:
        if k not in rig:
            raise ProfileError(f"{fname}: missing field 'rig.{k}'")
    i_total = _convert_scalar(rig["i_total_rad_per_mm"], float, "rig.i_total_rad_per_mm", fname)
    stroke = _convert_scalar(rig["stroke_limit_mm"], float, "rig.stroke_limit_mm", fname)
    period = _convert_scalar(rig["sample_period_s"], float, "rig.sample_period_s", fname)
    substeps = _convert_scalar(rig["substeps"], int, "rig.substeps", fname)
    _check_range(i_total, {"lo": 0.0, "lo_open": True, "hi": 1e4}, "rig.i_total_rad_per_mm", fname)
    _check_range(stroke, {"lo": 0.0, "lo_open": True, "hi": 500.0}, "rig.stroke_limit_mm", fname)
    _check_range(period, {"lo": 1e-4, "hi": 0.1}, "rig.sample_period_s", fname)
    _check_range(substeps, {"lo": 1, "hi": 1000}, "rig.substeps", fname)
    parts = {}
    for key, cls in (("ema1", EmaMechanics), ("ema2", EmaMechanics), ("drive", DriveParams),
                     ("surface", SurfaceParams), ("sensors1", SensorParams), ("sensors2", SensorParams)):
        parts[key] = build_dataclass(cls, data[key], fname, key + ".", _SIM_RANGES)
    effects = tuple(_load_effect(tbl, i, fname) for i, tbl in enumerate(data.get("effects", [])))
    params = RigParams(i_total_rad_per_mm=i_total, stroke_limit_mm=stroke, sample_period_s=period,
                       substeps=substeps, effects=effects, **parts)
    faults = _load_faults(data.get("faults", []), fname)
    serials = None
    if "identity" in data:
        ident = build_dataclass(SimIdentity, data["identity"], fname, "identity.")
        serials = (ident.serial_ema1, ident.serial_ema2)
    wear = build_dataclass(WearParams, data["wear"], fname, "wear.", _SIM_RANGES) if "wear" in data else None
    return SimRigProfile(params=params, seed=seed, faults=faults, serials=serials, wear=wear)


def _load_faults(tables: Any, fname: str) -> tuple:
    """``[[faults]]`` tables of a simulated-rig profile -> a :class:`sim.faults.Fault` schedule."""
    from sim.faults import Fault, FaultKind

    if not isinstance(tables, list):
        raise ProfileError(f"{fname}: 'faults' must be an array of tables ([[faults]])")
    out = []
    for k, tbl in enumerate(tables):
        where = f"faults[{k}]"
        if not isinstance(tbl, dict):
            raise ProfileError(f"{fname}: '{where}' must be a table")
        _check_keys(tbl, ["kind", "ema", "start_s", "duration_s", "value"], where + ".", fname)
        kind = tbl.get("kind")
        kinds = [x.value for x in FaultKind]
        if kind not in kinds:
            close = difflib.get_close_matches(str(kind), kinds, n=1, cutoff=0.5)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ProfileError(f"{fname}: field '{where}.kind' = {kind!r} is not a known fault{hint}; "
                               f"known: {', '.join(kinds)}")
        kw: dict[str, Any] = {"kind": kind}
        if "ema" in tbl:
            kw["ema"] = _convert_scalar(tbl["ema"], int, where + ".ema", fname)
            _check_range(kw["ema"], {"lo": 1, "hi": 2}, where + ".ema", fname)
        for name in ("start_s", "duration_s", "value"):
            if name in tbl:
                kw[name] = _convert_scalar(tbl[name], float, f"{where}.{name}", fname)
        if kw.get("start_s", 0.0) < 0:
            raise ProfileError(f"{fname}: field '{where}.start_s' = {kw['start_s']} must be >= 0")
        if "duration_s" in kw and not kw["duration_s"] > 0:
            raise ProfileError(f"{fname}: field '{where}.duration_s' = {kw['duration_s']} must be > 0")
        out.append(Fault(**kw))
    return tuple(out)


def effect_registry() -> dict[str, type]:
    """Machine name (as in profiles and diagnosis.json) -> effect class of :mod:`sim.effects`."""
    reg = getattr(sim_effects, "EFFECTS", None)
    if reg is not None:
        return dict(reg)
    import re
    return {re.sub(r"(?<!^)(?=[A-Z])", "_", c.__name__).lower(): c for c in sim_effects._KNOWN}


def _load_effect(tbl: Any, index: int, fname: str) -> Any:
    where = f"effects[{index}]"
    if not isinstance(tbl, dict):
        raise ProfileError(f"{fname}: '{where}' must be a table")
    name = tbl.get("name")
    registry = effect_registry()
    if name not in registry:
        close = difflib.get_close_matches(str(name), list(registry), n=1, cutoff=0.5)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ProfileError(f"{fname}: field '{where}.name' = {name!r} is not a known effect{hint}; "
                           f"known: {', '.join(sorted(registry))}")
    body = {k: v for k, v in tbl.items() if k != "name"}
    try:
        return build_dataclass(registry[name], body, fname, where + ".")
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ProfileError):
            raise
        raise ProfileError(f"{fname}: '{where}': {exc}") from None


def snapshot(obj: Any) -> Any:
    """A JSON-serialisable snapshot of a profile dataclass (for meta.json)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out = {f.name: snapshot(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
        if hasattr(obj, "name") and isinstance(getattr(type(obj), "NAME", None), str):
            out["name"] = type(obj).NAME
        return out
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, (tuple, list)):
        return [snapshot(x) for x in obj]
    if isinstance(obj, dict):
        return {str(k): snapshot(v) for k, v in obj.items()}
    return obj
