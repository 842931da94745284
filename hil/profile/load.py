"""Load profiles (TOML) from a given path into validated frozen dataclasses.

Three profiles describe a check: the actuation (:class:`hil.profile.config.Actuation`),
the check itself (:class:`hil.profile.config.Check`) and, for dry-runs, the simulated
rig (:class:`sim.params.RigParams`). The defaults ship in the ``profiles``
package. The field checks are :mod:`hil.profile.tables`, the actuation's
signal map :mod:`hil.profile.signals`. Every error names the file and the
dotted field, e.g.
``check.toml: force_fight.amplitude_fraction_of_limit = 0.2 is above the hard
cap 0.15``; unknown keys are refused with the closest known name, which catches
wrong units (``sweep_speed_mm_per_min`` is not ``sweep_speed_mm_per_s``).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from hil.errors import ProfileError
from hil.profile.config import (
    HARD_FORCE_FIGHT_FRACTION,
    HARD_MAX_FORCE_FIGHT_FRACTION,
    HARD_MAX_FORCE_FRACTION,
    HARD_MAX_FORCE_IMBALANCE_FRACTION,
    IDENTITY_MAX_CHARS,
    Actuation,
    Check,
)
from hil.profile.signals import LEGACY_SIGNALS, NO_SIGNALS, gear_ratio_object, load_signal_map, signal_tables
from hil.profile.tables import (
    Problems,
    build_dataclass,
    check_keys,
    check_range,
    convert_scalar,
    read_toml,
    snapshot,
)
from sim import effects as sim_effects
from sim.params import DriveParams, EmaMechanics, RigParams, SensorParams, SurfaceParams, WearParams

__all__ = ["SimRigProfile", "actuation_from_snapshot", "actuation_from_tables", "actuation_tables",
           "build_dataclass", "default_profile_path", "gear_ratio_object", "load_actuation", "load_check",
           "load_simrig", "resolve_eds", "snapshot", "validate_check"]


def default_profile_path(name: str) -> Path:
    """Path of a profile shipped in the ``profiles`` package (e.g. ``"check.toml"``)."""
    return Path(str(resources.files("profiles").joinpath(name)))


# ----------------------------------------------------------------- loaders


def load_actuation(path: str | Path | None = None) -> Actuation:
    """Load and validate an actuation profile (default: the shipped one), its signal map included."""
    path = Path(path) if path is not None else default_profile_path("actuation.toml")
    return actuation_from_tables(read_toml(path), path.name)


def actuation_from_tables(data: dict, fname: str) -> Actuation:
    """An actuation profile from its parsed tables (a TOML file, or meta.json's snapshot of one).

    Every problem is named at once (:class:`hil.profile.tables.Problems`): the fields, the cross-field
    rules and the signal map; the map is checked only when the rest gave an actuation to check it against.
    """
    problems = Problems()
    data = copy.deepcopy(data)
    with problems.collect():
        _refuse_moved(data, fname)
    signals = data.pop("signals", None)
    nodes = data.pop("nodes", {})
    co = data.get("canopen")
    cob_ids = co.pop("cob_ids", {}) if isinstance(co, dict) else {}
    act = None
    with problems.collect():
        act = build_dataclass(Actuation, data, fname)
    if act is None:
        if signals is None:
            problems.add(NO_SIGNALS.format(fname=fname))
        problems.raise_any()
    for rule in (_distinct_node_ids, _consumer_time, _history_url, _one_line_texts, _stiffness_ranges):
        with problems.collect():
            rule(act, fname)
    smap = None
    with problems.collect():
        smap = load_signal_map(signals, nodes, cob_ids, act, fname)
    problems.raise_any()
    return dataclasses.replace(act, signals=smap)


def _distinct_node_ids(act: Actuation, fname: str) -> None:
    c = act.canopen
    if c.node_id_ema1 == c.node_id_ema2:
        raise ProfileError(f"{fname}: fields 'canopen.node_id_ema1' and 'canopen.node_id_ema2' "
                           f"are both {c.node_id_ema1}; the drives need distinct node ids")
    for name in ("node_id_ema1", "node_id_ema2"):
        if getattr(c, name) == c.master_node_id:
            raise ProfileError(f"{fname}: fields 'canopen.master_node_id' and 'canopen.{name}' are both "
                               f"{c.master_node_id}; the master's heartbeat needs a node id of its own")


def _consumer_time(act: Actuation, fname: str) -> None:
    consumer_ms = act.canopen.master_consumer_time_s * 1000.0
    if not 1.0 <= consumer_ms <= 0xFFFF:
        raise ProfileError(f"{fname}: fields 'canopen.master_heartbeat_consumer_factor' * "
                           f"'canopen.master_heartbeat_period_s' give a consumer heartbeat time of "
                           f"{consumer_ms:g} ms; 0x1016 holds 1..65535 ms")


def _history_url(act: Actuation, fname: str) -> None:
    if act.history.url:
        from hil.errors import HistoryInputError
        from hil.profile.history_url import check_url

        try:
            check_url(act.history.url)
        except HistoryInputError as exc:
            raise ProfileError(f"{fname}: field 'history.url': {exc}") from None


def _one_line_texts(act: Actuation, fname: str) -> None:
    problems = Problems()
    for name in ("aircraft", "position", "rig"):
        text = getattr(act.history, name)
        if len(text) > IDENTITY_MAX_CHARS:
            problems.add(f"{fname}: field 'history.{name}' is {len(text)} characters long; an identity text is at "
                         f"most {IDENTITY_MAX_CHARS} (docs/report.md, Identity texts)")
    for name in ("external_watchdog", "skip_master_loss_drill"):
        text = getattr(act.canopen, name)
        if text != text.strip() or "\n" in text:
            problems.add(f"{fname}: field 'canopen.{name}' must be one line without "
                         f"leading or trailing blanks (it is quoted in the run folder)")
    problems.raise_any()


def _stiffness_ranges(act: Actuation, fname: str) -> None:
    """A stated stiffness range is stated whole (both bounds) and not empty."""
    m, problems = act.mechanics, Problems()
    for part in ("int", "ext"):
        lo, hi = getattr(m, f"stiffness_{part}_min_N_per_mm"), getattr(m, f"stiffness_{part}_max_N_per_mm")
        if bool(lo) != bool(hi):
            problems.add(f"{fname}: fields 'mechanics.stiffness_{part}_min_N_per_mm' and "
                         f"'mechanics.stiffness_{part}_max_N_per_mm': give both or neither (0: derived)")
        elif lo and lo >= hi:
            problems.add(f"{fname}: field 'mechanics.stiffness_{part}_min_N_per_mm' = {lo:g} is not below "
                         f"'mechanics.stiffness_{part}_max_N_per_mm' = {hi:g}")
    problems.raise_any()


#: Keys of earlier actuation profiles and where they went.
_MOVED = {("sensors", "resolver_counts_per_rev"): "signals.ema1.motor_angle.counts_per_rev (and ema2)"}


def _refuse_moved(data: dict, fname: str) -> None:
    """Keys of earlier profiles refused, each saying where it went (and taken out of ``data``, so that
    the rest of the profile is still checked: every problem at once)."""
    problems = Problems()
    for (table, key), where in _MOVED.items():
        if isinstance(data.get(table), dict) and key in data[table]:
            del data[table][key]
            problems.add(f"{fname}: field '{table}.{key}' has moved to '{where}' (docs/drives.md)")
    problems.raise_any()


def resolve_eds(name: str, profile_path: str | Path | None, key: str = "canopen.eds",
                override: str | Path | None = None) -> Path:
    """Path of an EDS a profile names: ``override`` (``--eds``) if given, else relative to the
    profile, else an absolute path, else a shipped one; ProfileError naming ``key`` if none exists."""
    if override is not None:
        p = Path(override)
        if p.is_dir():
            raise ProfileError(f"--eds {override}: a folder, not an EDS file")
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
    where = f"actuation profile {profile_path}" if profile_path is not None else "actuation profile"
    raise ProfileError(f"{where}: field '{key}' = {name!r}: no such EDS (looked next to the profile "
                       f"and among the shipped profiles; give its path with --eds PATH)")


def actuation_tables(act: Actuation) -> dict:
    """The profile tables of ``act`` (what :func:`actuation_from_tables` reads back): meta.json's snapshot."""
    data = snapshot(dataclasses.replace(act, signals=None))
    del data["signals"]
    if act.signals is not None:
        t = signal_tables(act)
        data["signals"], data["nodes"] = t["signals"], t["nodes"]
        if t["cob_ids"]:
            data["canopen"]["cob_ids"] = t["cob_ids"]
    return data


def actuation_from_snapshot(snap: dict, fname: str = "meta.json (actuation snapshot)") -> Actuation:
    """The actuation a run used, from meta.json's snapshot (also one written before the signal map:
    its drive's fixed objects are taken)."""
    snap = copy.deepcopy(snap)
    if "signals" not in snap:
        counts = (snap.get("sensors") or {}).pop("resolver_counts_per_rev", 4096)
        snap["signals"] = copy.deepcopy(LEGACY_SIGNALS)
        for k in ("ema1", "ema2"):
            snap["signals"][k]["motor_angle"]["counts_per_rev"] = counts
    return actuation_from_tables(snap, fname)


def actuation_of_recording(path: str | Path | None, snapshot: dict | None) -> Actuation:
    """The actuation profile a recording is analysed with: ``path`` (``--profile``), else its run's snapshot
    (meta.json: what the run used), else the shipped one."""
    if path is not None:
        return load_actuation(path)
    return actuation_from_snapshot(snapshot) if snapshot is not None else load_actuation(None)


def profiles_from(path: str | Path | None, actuation_snapshot: dict | None,
                  check_snapshot: dict | None) -> tuple[Actuation, Check]:
    """The actuation and check profiles a recording is analysed with: the actuation ``path`` (``--profile``),
    else meta.json's snapshot, else the shipped one; the check profile of meta.json's snapshot, else the
    shipped one (an old or foreign snapshot that no longer loads: the shipped one too)."""
    act = actuation_of_recording(path, actuation_snapshot)
    if check_snapshot is not None:
        try:
            return act, build_dataclass(Check, check_snapshot, "meta.json (check snapshot)")
        except ProfileError:
            pass
    return act, load_check(None, act)


def load_check(path: str | Path | None = None, actuation: Actuation | None = None,
               actuation_path: str | Path | None = None) -> Check:
    """Load and validate a check profile; with ``actuation`` (read from ``actuation_path``, None: the
    shipped one), also cross-check limits."""
    path = Path(path) if path is not None else default_profile_path("check.toml")
    check = build_dataclass(Check, read_toml(path), path.name)
    if actuation is not None:
        act_name = Path(actuation_path).name if actuation_path is not None else "the shipped actuation.toml"
        validate_check(check, actuation, path.name, act_name)
    return check


def validate_check(check: Check, act: Actuation, fname: str = "check.toml",
                   act_name: str = "the actuation profile") -> None:
    """Cross-field checks between a check profile and the actuation it runs on (``act_name``, named where
    a bound comes from it): every problem at once."""
    problems = Problems()
    f_limit = act.mechanics.limit_load_N
    of_limit = f"mechanics.limit_load_N = {f_limit:g} N in {act_name}"
    cap = HARD_MAX_FORCE_FRACTION * f_limit
    s = check.safety
    if s.max_force_N > cap:
        problems.add(
            f"{fname}: field 'safety.max_force_N' = {s.max_force_N} is above the hard cap "
            f"{cap:g} N ({HARD_MAX_FORCE_FRACTION:.0%} of {of_limit})")
    for name, value, frac in (("safety.max_force_fight_N", s.max_force_fight_N, HARD_MAX_FORCE_FIGHT_FRACTION),
                              ("safety.max_force_imbalance_N", s.max_force_imbalance_N,
                               HARD_MAX_FORCE_IMBALANCE_FRACTION)):
        if value > frac * f_limit:
            problems.add(f"{fname}: field '{name}' = {value} is above the hard cap "
                               f"{frac * f_limit:g} N ({frac:.0%} of {of_limit})")
    ff = check.force_fight.amplitude_fraction_of_limit * f_limit
    ff_from = (f"{fname}: field 'force_fight.amplitude_fraction_of_limit' = "
               f"{check.force_fight.amplitude_fraction_of_limit:g} of {of_limit} gives {ff:g} N")
    if ff >= s.max_force_fight_N:
        problems.add(f"{ff_from}, not below safety.max_force_fight_N = {s.max_force_fight_N:g} N")
    if ff >= s.max_force_N:
        problems.add(f"{ff_from}, not below safety.max_force_N = {s.max_force_N:g} N")
    if check.force_fight.amplitude_fraction_of_limit > HARD_FORCE_FIGHT_FRACTION:  # pragma: no cover
        problems.add(f"{fname}: force fight above the hard cap")  # (metadata catches it first)
    if check.calibration.opposing_force_N >= s.max_force_N:
        problems.add(
            f"{fname}: field 'calibration.opposing_force_N' = {check.calibration.opposing_force_N:g} N "
            f"is not below safety.max_force_N = {s.max_force_N:g} N")
    if s.max_stroke_mm > act.mechanics.stroke_limit_mm:
        problems.add(
            f"{fname}: field 'safety.max_stroke_mm' = {s.max_stroke_mm} is above the hard cap "
            f"{act.mechanics.stroke_limit_mm} mm (mechanics.stroke_limit_mm in {act_name})")
    if check.calibration.sweep_amplitude_mm >= s.max_stroke_mm:
        problems.add(
            f"{fname}: field 'calibration.sweep_amplitude_mm' = {check.calibration.sweep_amplitude_mm} "
            f"must stay below safety.max_stroke_mm = {s.max_stroke_mm}")
    for name, v in (("approach.speed_mm_per_s", check.approach.speed_mm_per_s),
                    ("calibration.sweep_speed_mm_per_s", check.calibration.sweep_speed_mm_per_s)):
        if v >= s.max_velocity_mm_per_s:
            problems.add(f"{fname}: field '{name}' = {v} must stay below "
                               f"safety.max_velocity_mm_per_s = {s.max_velocity_mm_per_s}")
    problems.raise_any()


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
    #: ``actuation = "FILE"``: the actuation profile the simulated rig is built as (its nodes, EDS files, signal
    #: map and scalings), resolved next to this profile, else as given, else among the shipped ones; None: not
    #: named (the shipped actuation profile). Used by ``commission --simulate --sim`` and by ``sim-serve``
    #: without ``--profile`` (docs/commission.md, *A rehearsal*).
    actuation: Path | None = None


@dataclass(frozen=True)
class SimIdentity:
    """``[identity]`` of a simulated-rig profile: what the simulated drives report as their serial numbers."""

    serial_ema1: int = field(metadata={"lo": 0, "hi": 0xFFFF_FFFF})
    serial_ema2: int = field(metadata={"lo": 0, "hi": 0xFFFF_FFFF})


def load_simrig(path: str | Path | None = None) -> SimRigProfile:
    """Load and validate a simulated-rig profile (default: the shipped one): every problem at once."""
    path = Path(path) if path is not None else default_profile_path("simrig.toml")
    fname = path.name
    data = read_toml(path)
    required = ["seed", "rig", "ema1", "ema2", "drive", "surface", "sensors1", "sensors2"]
    problems = Problems()
    with problems.collect():
        check_keys(data, required + ["actuation", "effects", "faults", "identity", "wear"], "", fname)
    for key in required:
        if key not in data:
            problems.add(f"{fname}: missing {'field' if key == 'seed' else 'table'} '{key}'")
    actuation = None
    with problems.collect():
        actuation = _sim_actuation(data.get("actuation"), path)
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        problems.add(f"{fname}: field 'seed' must be a non-negative integer, got {seed!r}")
    rig = parts = effects = faults = ident = wear = None
    with problems.collect():
        rig = _sim_rig_table(data.get("rig", {}), fname)
    with problems.collect():
        parts = _sim_parts(data, fname)
    with problems.collect():
        effects = tuple(_load_effect(tbl, i, fname) for i, tbl in enumerate(data.get("effects", [])))
    with problems.collect():
        faults = _load_faults(data.get("faults", []), fname)
    with problems.collect():
        if "identity" in data:
            ident = build_dataclass(SimIdentity, data["identity"], fname, "identity.")
    with problems.collect():
        if "wear" in data:
            wear = build_dataclass(WearParams, data["wear"], fname, "wear.", _SIM_RANGES)
    problems.raise_any()
    params = RigParams(**rig, effects=effects, **parts)
    serials = (ident.serial_ema1, ident.serial_ema2) if ident is not None else None
    return SimRigProfile(params=params, seed=seed, faults=faults, serials=serials, wear=wear, actuation=actuation)


def _sim_actuation(name: Any, path: Path) -> Path | None:
    """``actuation = "FILE"`` of a simulated-rig profile at ``path``: the file, next to the profile first (as an
    EDS is found), else the path as given, else a shipped profile of that name; None where the key is absent."""
    if name is None:
        return None
    if not isinstance(name, str) or not name.strip():
        raise ProfileError(f"{path.name}: field 'actuation' must be the file name of an actuation profile, "
                           f"got {name!r}")
    for p in (path.parent / name, Path(name), default_profile_path(name)):
        if p.is_file():
            return p
    raise ProfileError(f"{path.name}: field 'actuation' = {name!r}: no such file (looked next to {path} and among "
                       f"the shipped profiles)")


def _sim_rig_table(rig: Any, fname: str) -> dict:
    """``[rig]`` of a simulated-rig profile: RigParams' scalars, each checked."""
    if not isinstance(rig, dict):
        raise ProfileError(f"{fname}: 'rig' must be a table")
    fields = {"i_total_rad_per_mm": (float, {"lo": 0.0, "lo_open": True, "hi": 1e4}),
              "stroke_limit_mm": (float, {"lo": 0.0, "lo_open": True, "hi": 500.0}),
              "sample_period_s": (float, {"lo": 1e-4, "hi": 0.1}),
              "substeps": (int, {"lo": 1, "hi": 1000})}
    problems = Problems()
    with problems.collect():
        check_keys(rig, list(fields), "rig.", fname)
    out = {}
    for k, (typ, rng) in fields.items():
        with problems.collect():
            if k not in rig:
                raise ProfileError(f"{fname}: missing field 'rig.{k}'")
            out[k] = convert_scalar(rig[k], typ, f"rig.{k}", fname)
            check_range(out[k], rng, f"rig.{k}", fname)
    problems.raise_any()
    return out


def _sim_parts(data: dict, fname: str) -> dict:
    """The EMAs, drive, surface and sensors tables of a simulated-rig profile; every problem at once."""
    problems = Problems()
    parts = {}
    for key, cls in (("ema1", EmaMechanics), ("ema2", EmaMechanics), ("drive", DriveParams),
                     ("surface", SurfaceParams), ("sensors1", SensorParams), ("sensors2", SensorParams)):
        if key in data:
            with problems.collect():
                parts[key] = build_dataclass(cls, data[key], fname, key + ".", _SIM_RANGES)
    problems.raise_any()
    return parts


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
        check_keys(tbl, ["kind", "ema", "start_s", "duration_s", "value"], where + ".", fname)
        kind = tbl.get("kind")
        kinds = [x.value for x in FaultKind]
        if kind not in kinds:
            close = difflib.get_close_matches(str(kind), kinds, n=1, cutoff=0.5)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ProfileError(f"{fname}: field '{where}.kind' = {kind!r} is not a known fault{hint}; "
                               f"known: {', '.join(kinds)}")
        kw: dict[str, Any] = {"kind": kind}
        if "ema" in tbl:
            kw["ema"] = convert_scalar(tbl["ema"], int, where + ".ema", fname)
            check_range(kw["ema"], {"lo": 1, "hi": 2}, where + ".ema", fname)
        for name in ("start_s", "duration_s", "value"):
            if name in tbl:
                kw[name] = convert_scalar(tbl[name], float, f"{where}.{name}", fname)
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
    return {re.sub(r"(?<!^)(?=[A-Z])", "_", c.__name__).lower(): c for c in sim_effects.EFFECTS.values()}


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
