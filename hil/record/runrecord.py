"""The run record: what a run folder's meta.json holds, as frozen dataclasses, and its one writer.

A run's record is built once (:func:`start_record`: a new run id, this software, the start time,
status ``running``, the profiles' snapshot), changed only by :func:`dataclasses.replace` or the
record's named methods (each returns a new record), written only by :class:`hil.record.runfolder.MetaWriter`
(the one owner of ``meta.json`` and of the run folder's :class:`~hil.record.runfolder.DiskSync`) and read
back only by :func:`hil.record.runfolder.read_record` / :meth:`RunRecord.from_json` (``analyze``, ``serv``,
``diagnose``, the report, the result's trace). This module does no IO.

JSON: :meth:`RunRecord.as_json` gives the keys in the order of :class:`RunRecord`'s fields, a field
that is None absent (parts spread flat: :class:`Bus`, :class:`Attribution`, :class:`Installation`),
with two placements kept from the format's history: ``identity`` sits where it was recorded (with
the preflight after ``master_loss``; else, for a run stopped before it, last, with the CAN
statistics; else after ``files_sha256``: ``simulate``, as the simulated drives would report it), and
``loop_page_faults`` sits in ``can`` once a CANopen run has its CAN statistics. The reader takes
the partial record of a killed run (``status`` still ``running``, no end) and any subset of the
fields (a folder made by hand); a field of the wrong type or value is a :class:`RunRecordError`
naming it; keys it does not know are ignored. Profile snapshots, the simulated rig, the truth,
faults, the process image and each drive's master-loss record stay the JSON their producers
wrote (read-only by convention: the record never changes them).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from hil.record.cycletiming import Distribution, TimingSummary, Worst
from hil.record.driveparts import IDENTITY_KEYS as IDENTITY_KEYS
from hil.record.driveparts import DriveFinal as DriveFinal
from hil.record.driveparts import DriveLast as DriveLast
from hil.record.driveparts import Identity as Identity
from hil.record.driveparts import KeptLimit as KeptLimit
from hil.record.recordjson import KINDS, Fields, Part, member, only, opt, req, show
from hil.record.recordjson import part_keys as part_keys

#: the record's file in a run folder (written by :class:`hil.record.runfolder.MetaWriter` only)
META_NAME = "meta.json"


class RunStatus(StrEnum):
    """Where a run is: ``running`` until its loop ends (a folder still saying so was cut off)."""

    RUNNING = "running"
    DONE = "done"
    ABORTED = "aborted"


class RunMode(StrEnum):
    """The command that made the run."""

    DRY_RUN = "dry-run"
    RUN = "run"
    SIMULATE = "simulate"
    SIMULATE_SCENARIO = "simulate-scenario"


def utc_now_iso() -> str:
    """The current UTC time, ISO 8601 to the second (``started_utc``, ``ended_utc``)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


# ------------------------------------------------------------------ the parts with a fixed shape
# (read with hil.record.recordjson; the drives' parts are in hil.record.driveparts)

@dataclass(frozen=True)
class Software(Part):
    """The software that made the run."""

    name: str = req("text")
    version: str = req("text")


@dataclass(frozen=True)
class Profiles(Part):
    """The snapshots of the profiles the run used (:func:`hil.profile.load.actuation_tables`, ``snapshot``)."""

    actuation: dict | None = None
    check: dict | None = None

    def as_json(self) -> dict:
        return {k: v for k, v in (("actuation", self.actuation), ("check", self.check)) if v is not None}

    @classmethod
    def read(cls, f: Fields) -> Profiles:
        return cls(f.get("actuation", "object"), f.get("check", "object"))


@dataclass(frozen=True)
class StepTime:
    """When a step of the check began and ended (check time [s]); ``t_end_s`` None: the last one, open."""

    name: str
    t_start_s: float
    t_end_s: float | None = None

    def as_json(self) -> list:
        return [self.t_start_s] if self.t_end_s is None else [self.t_start_s, self.t_end_s]


def _read_steps(f: Fields) -> tuple[StepTime, ...]:
    out = []
    for name, span in f.obj.items():
        if not (isinstance(span, list) and 1 <= len(span) <= 2 and all(KINDS["number"][0](t) for t in span)):
            raise f.error(name, f"expected [t_start, t_end] or [t_start] in s, got {show(span)}")
        out.append(StepTime(name, *span))
    return tuple(out)


@dataclass(frozen=True)
class Bus(Part):
    """The CAN interface of a run on real drives (``emacheck run``)."""

    interface: str = req("text")
    channel: str = req("text")
    bitrate_bps: int = req("int")
    #: udp_multicast's IP hop limit (0: the frames stayed on this host); None (not written) for other interfaces
    multicast_hops: int | None = opt("int")

    def as_json(self) -> dict:
        out = super().as_json()
        if self.multicast_hops is None:
            del out["multicast_hops"]
        return out


@dataclass(frozen=True)
class BusLoad(Part):
    """The planned bus load (fractions of the bit rate)."""

    nominal: float = req("number")
    worst: float = req("number")


@dataclass(frozen=True)
class Attribution(Part):
    """Who made the check and for which work order (None where nobody said)."""

    operator: str | None = opt("text")
    work_order: str | None = opt("text")


@dataclass(frozen=True)
class Installation(Part):
    """Where and when in the aircraft's life (the wear history's keys; None where nobody said)."""

    aircraft: str | None = opt("text")
    position: str | None = opt("text")
    rig: str | None = opt("text")
    flight_hours: float | None = opt("number")
    flight_cycles: int | None = opt("int")


#: the JSON keys of :class:`Installation`, in order
INSTALLATION_KEYS = tuple(f.name for f in dataclasses.fields(Installation))


@dataclass(frozen=True)
class Wear(Part):
    """The simulated rig worn to ``flight_hours`` (``sim.truth.apply_wear``): its ``[wear]`` table and
    each channel's backlash on the wear line [mm]."""

    flight_hours: float = req("number")
    params: dict = req("object")
    line_mm: dict = req("object")


def shared_serial(identity: Mapping | None) -> str | None:
    """What is wrong when EMA 1 and EMA 2 of an identity block (JSON form: ``{"ema1": {"node", "vendor_id",
    "product_code", "serial", ...} | None, "ema2": ...}``) report one actuator identity (vendor, product and
    a serial other than 0), as a sentence naming both nodes and the serial; None when they differ or a
    serial is missing (0: none set)."""
    one, two = ((identity or {}).get(k) or {} for k in ("ema1", "ema2"))
    keys = [tuple(d.get(f) for f in ("vendor_id", "product_code", "serial")) for d in (one, two)]
    serial = keys[0][2]
    if not isinstance(serial, int) or isinstance(serial, bool) or serial == 0 or keys[0] != keys[1]:
        return None
    return (f"EMA 1 (node {one.get('node')}) and EMA 2 (node {two.get('node')}) report the same serial number "
            f"0x{serial:08X}: two actuators of one serial cannot be traced")


@dataclass(frozen=True)
class SafetyViolation(Part):
    """The supervisor's latched violation (:class:`hil.check.supervisor.Violation`): the limit, its value in
    force, the measured value (the limit's unit) and when [s, check time]."""

    limit: str = req("text")
    detail: str = req("text")
    t_s: float = req("number")
    value: float = req("number")
    threshold: float = req("number")

    @classmethod
    def of(cls, viol) -> SafetyViolation:
        return cls(viol.limit, viol.detail, viol.t_s, viol.value, viol.threshold)


@dataclass(frozen=True)
class CanStats(Part):
    """The CAN side of a CANopen run: frames logged, SYNC cycles without a complete sample, frames the
    master refused or did not know, its largest lag behind the bus [ms] and the page faults of the
    check (``emacheck run``)."""

    frames_logged: int
    missing_cycles: int
    bad_frames: int
    unknown_frames: int
    max_lag_ms: float | None = None
    page_faults: int | None = None

    def as_json(self) -> dict:
        out = {"frames_logged": self.frames_logged, "missing_cycles": self.missing_cycles,
               "bad_frames": self.bad_frames, "unknown_frames": self.unknown_frames}
        if self.max_lag_ms is not None:
            out["max_lag_ms"] = self.max_lag_ms
        if self.page_faults is not None:
            out["page_faults"] = self.page_faults
        return out

    @classmethod
    def read(cls, f: Fields) -> CanStats:
        return cls(*(f.get(k, "int", required=True) for k in ("frames_logged", "missing_cycles", "bad_frames",
                                                                "unknown_frames")),
                   max_lag_ms=f.get("max_lag_ms", "number"), page_faults=f.get("page_faults", "int"))


@dataclass(frozen=True)
class Stalls(Part):
    """The master's stalls in a CANopen check (:class:`hil.master.stalls.StallWatch`): how many, the longest [ms],
    each one's begin [s, check time] and length [ms]; the limit they were held to [ms] and its profile key;
    in a dry-run with ``--master-stall-ms``, the injection (``stall_ms``, ``every_s``, ``count``)."""

    count: int = req("int")
    longest_ms: float = req("number")
    at: list = req("list")
    limit_ms: float = req("number")
    limit: str = req("text")
    injected: dict | None = opt("object")

    def as_json(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return out if self.injected is not None else {k: v for k, v in out.items() if k != "injected"}


def _read_distribution(f: Fields, histogram: bool) -> Distribution:
    """A :class:`hil.record.cycletiming.Distribution` from its JSON (``histogram`` False: none was recorded)."""
    nums = [f.get(k, "number", required=True) for k in ("p50_ms", "p90_ms", "p99_ms", "p99.9_ms", "max_ms", "mean_ms")]
    worst = tuple(Worst(g.get("ms", "number", required=True), g.get("t_s", "number", required=True),
                        g.get("cycle", "int", required=True))
                  for g in (Fields(w, f"{f.name('worst')}[{i}]", f.source)
                            for i, w in enumerate(f.get("worst", "list", required=True))))
    bin_ms, bins = 0.0, ()
    if histogram:
        f.get("histogram", "object", required=True)
        h = f.sub("histogram")
        bin_ms = h.get("bin_ms", "number", required=True)
        bins = tuple(tuple(b) for b in h.get("bins", "list", required=True))
        if not all(len(b) == 2 and KINDS["number"][0](b[0]) and KINDS["int"][0](b[1]) for b in bins):
            raise h.error("bins", "expected [[lower edge ms, count], ...]")
    return Distribution(f.get("n", "int", required=True), *nums, f.get("over_period", "int", required=True),
                        worst, bin_ms, bins)


@dataclass(frozen=True)
class Timing(Part):
    """The master's loop per SYNC cycle on a real bus (:class:`hil.record.cycletiming.TimingSummary`), with the
    SYNC's source and its lateness. The CPU time's histogram is not recorded (as
    :meth:`~hil.record.cycletiming.TimingSummary.as_json` leaves it out): ``summary.work_cpu`` holds none."""

    summary: TimingSummary
    t0_unix_s: float  #: the wall clock at the check's time 0 [s since the epoch]
    sync: str  #: "loop-timed" or "periodic task"
    sync_skipped: int  #: SYNCs the loop-timed source skipped
    sync_late_max_ms: float  #: the latest SYNC behind its schedule [ms]
    #: SYNC periods the master saw pass without a SYNC (:class:`hil.canopen.cycle.SyncSchedule`); None:
    #: a record from before it was kept
    sync_periods_skipped: int | None = None

    def __post_init__(self) -> None:
        cpu = self.summary.work_cpu
        if cpu.histogram or cpu.bin_ms:
            cpu = dataclasses.replace(cpu, bin_ms=0.0, histogram=())
            object.__setattr__(self, "summary", dataclasses.replace(self.summary, work_cpu=cpu))

    def as_json(self) -> dict:
        return {**self.summary.as_json(), "t0_unix_s": self.t0_unix_s, "sync": self.sync,
                "sync_skipped": self.sync_skipped, "sync_late_max_ms": self.sync_late_max_ms,
                **({} if self.sync_periods_skipped is None else {"sync_periods_skipped": self.sync_periods_skipped})}

    @classmethod
    def read(cls, f: Fields) -> Timing:
        for k in ("reaction", "work", "work_cpu", "gap"):
            f.get(k, "object", required=True)
        summary = TimingSummary(f.get("period_ms", "number", required=True), f.get("cycles", "int", required=True),
                                *(_read_distribution(f.sub(k), histogram=k != "work_cpu")
                                  for k in ("reaction", "work", "work_cpu", "gap")),
                                *(f.get(k, "int", required=True) for k in ("syncs_missing", "unanswered", "late")))
        return cls(summary, f.get("t0_unix_s", "number", required=True), f.get("sync", "text", required=True),
                   f.get("sync_skipped", "int", required=True), f.get("sync_late_max_ms", "number", required=True),
                   f.get("sync_periods_skipped", "int"))


def _ema_map(f: Fields, key: str, part: type, nullable: bool = False) -> dict | None:
    """``{"ema1": part, ...}`` of the object at ``key`` (entries may be null if ``nullable``); None if absent."""
    if f.get(key, "object") is None:
        return None
    g = f.sub(key)
    return {k: None if (v is None and nullable) else part.read(g.sub(k)) for k, v in g.obj.items()}


# ------------------------------------------------------------------ the record

@dataclass(frozen=True)
class RunRecord:
    """What a run folder's meta.json holds; None: the key is absent. Fields in the JSON's order.

    Built by :func:`start_record`; the fields after ``wear`` are added as the run goes: the preflight
    (``process_image``, ``master_loss``, ``identity``), the loop (``steps``, ``safety``, ``drives_final``,
    ``drives_last``, ``stop_errors``, ``loop_page_faults``, ``stalls``, ``reason`` ... ``duration_s``), the
    command after it (``wall_s``, ``can``, ``timing``).
    """

    run_id: str | None = None
    software: Software | None = None
    started_utc: str | None = None
    status: RunStatus | None = None
    profiles: Profiles | None = None
    steps: tuple[StepTime, ...] | None = None
    mode: RunMode | None = None
    scenario: str | None = None  #: the normal-operation scenario (``simulate --scenario``)
    seed: int | None = None
    realtime: bool | None = None
    bus: Bus | None = None
    simrig: dict | None = None  #: the simulated rig's parameters (snapshot)
    truth: dict | None = None  #: the simulator's truth, in result.json's shape
    faults: tuple[dict, ...] | None = None  #: the injected faults (snapshots)
    bus_load: BusLoad | None = None
    eds: str | None = None  #: the drives' EDS file
    eds_nodes: dict[str, str] | None = None  #: node name -> its EDS file
    plan_notes: tuple[str, ...] | None = None
    force_control: dict[str, str] | None = None  #: EMA -> "cst" or "csp"
    attribution: Attribution | None = None
    installation: Installation | None = None
    files_sha256: dict[str, str] | None = None  #: file name -> SHA-256
    recording_sha256: dict[str, str] | None = None  #: signals.csv, can.log -> SHA-256 when the check ended
    wear: Wear | None = None
    process_image: dict | None = None  #: :func:`hil.canopen.cycle.image_of`
    master_loss: dict[str, dict] | None = None  #: EMA -> :meth:`hil.master.drill.MasterLossRecord.as_json`
    identity: dict[str, Identity | None] | None = None  #: EMA -> identity (None: not read)
    safety: SafetyViolation | None = None
    drives_final: dict[str, DriveFinal] | None = None  #: EMA -> its final state
    drives_last: dict[str, DriveLast] | None = None  #: EMA -> where it was last seen (position, force, EMCYs)
    stop_errors: tuple[str, ...] | None = None  #: errors met while stopping the drives (at most 10)
    loop_page_faults: int | None = None  #: page faults of this process inside the cyclic loop
    stalls: Stalls | None = None  #: the master's stalls (a CANopen check)
    reason: str | None = None  #: why it stopped ("" when it ran to the end)
    ended_utc: str | None = None
    samples: int | None = None
    duration_s: float | None = None  #: rig time of the check [s]
    wall_s: float | None = None  #: wall time of the check loop [s]
    can: CanStats | None = None
    timing: Timing | None = None

    def __post_init__(self) -> None:  # an illegal status or mode is refused, as in from_json
        if self.status is not None and not isinstance(self.status, RunStatus):
            object.__setattr__(self, "status", member(RunStatus, self.status, "status", "run record"))
        if self.mode is not None and not isinstance(self.mode, RunMode):
            object.__setattr__(self, "mode", member(RunMode, self.mode, "mode", "run record"))

    # -------------------------------------------------------------- changes (each a new record)

    def with_step(self, name: str, t_s: float) -> RunRecord:
        """Step ``name`` began at ``t_s``: the open step ends there, ``name`` is added unless it ran before."""
        steps = tuple(s if s.t_end_s is not None else dataclasses.replace(s, t_end_s=t_s) for s in self.steps or ())
        if all(s.name != name for s in steps):
            steps += (StepTime(name, t_s),)
        return dataclasses.replace(self, steps=steps)

    def with_preflight(self, preflight: Mapping) -> RunRecord:
        """``process_image``, ``master_loss`` and ``identity`` from the link's preflight record (JSON,
        :meth:`hil.master.link.CanopenLink.preflight_record`), read and checked as meta.json is."""
        only(preflight, ("process_image", "master_loss", "identity"), "", "preflight record")
        for k, v in (preflight.get("identity") or {}).items():
            only(v or {}, IDENTITY_KEYS, f"identity.{k}", "preflight record")
        got = RunRecord.from_json(preflight, "preflight record")
        return dataclasses.replace(self, process_image=got.process_image, master_loss=got.master_loss,
                                   identity=got.identity)

    def with_final_states(self, final: Mapping, errors: list[str] | None) -> RunRecord:
        """``drives_final`` from the link's report after it closed (JSON,
        :meth:`hil.master.core.MasterCore.safe_state_report`) and the first 10 ``errors`` met while stopping."""
        for k, v in final.items():
            only(v, part_keys(DriveFinal), f"drives_final.{k}", "final states")
        got = RunRecord.from_json({"drives_final": final}, "final states")
        more = {"stop_errors": tuple(errors[:10])} if errors else {}
        return dataclasses.replace(self, drives_final=got.drives_final, **more)

    def ended(self, status: RunStatus, reason: str, samples: int, duration_s: float, **more) -> RunRecord:
        """The loop's end: status, why, the time now, samples and rig time (``more``: other fields)."""
        return dataclasses.replace(self, status=status, reason=reason, ended_utc=utc_now_iso(),
                                   samples=samples, duration_s=duration_s, **more)

    # -------------------------------------------------------------- JSON

    def as_json(self) -> dict:
        """meta.json's content (see the module's docstring for the layout)."""
        out: dict[str, Any] = {}
        can_json = self.can.as_json() if self.can is not None else None
        if can_json is not None and self.loop_page_faults is not None:
            can_json["loop_page_faults"] = self.loop_page_faults
        # identity where it was recorded: with the preflight, else after the loop with the CAN
        # statistics (a run that stopped before its preflight), else at the start (simulate)
        ident_after = ("master_loss" if self.process_image is not None else
                       "timing" if self.can is not None else "files_sha256")
        for f in dataclasses.fields(self):
            v = can_json if f.name == "can" else getattr(self, f.name)
            skip = f.name == "identity" or (f.name == "loop_page_faults" and can_json is not None)
            if v is not None and not skip:
                out.update(_json_of(f.name, v))
            if f.name == ident_after and self.identity is not None:
                out.update(_json_of("identity", self.identity))
        return out

    @classmethod
    def from_json(cls, obj: Any, source: str = META_NAME) -> RunRecord:
        """The record of meta.json's content ``obj``: any subset of the fields (a killed run's, a folder
        made by hand); a malformed field raises :class:`RunRecordError` naming it (``source`` first)."""
        f = Fields(obj, "", source)
        parts = {name: part.read(f.sub(name)) for name, part in _PARTS.items() if f.get(name, "object") is not None}
        flat = {name: part.read(f) for name, part in _FLAT_PARTS.items() if f.has(*part_keys(part))}
        fields = {name: f.get(name, kind) for name, kind in _PLAIN.items()}
        can = f.obj.get("can")
        lpf = f.sub("can").get("loop_page_faults", "int") if isinstance(can, dict) else None
        return cls(**fields, **parts, **flat,
                   status=f.enum("status", RunStatus), mode=f.enum("mode", RunMode),
                   steps=_read_steps(f.sub("steps")) if f.get("steps", "object") is not None else None,
                   faults=_tuple(f.get("faults", "list")), plan_notes=_tuple(f.get("plan_notes", "texts")),
                   stop_errors=_tuple(f.get("stop_errors", "texts")),
                   loop_page_faults=lpf if lpf is not None else f.get("loop_page_faults", "int"),
                   identity=_ema_map(f, "identity", Identity, nullable=True),
                   drives_final=_ema_map(f, "drives_final", DriveFinal),
                   drives_last=_ema_map(f, "drives_last", DriveLast))


def _tuple(v: list | None) -> tuple | None:
    return None if v is None else tuple(v)


#: parts under a key of their own / spread flat / plain fields (JSON types as they are)
_PARTS = {"software": Software, "profiles": Profiles, "bus_load": BusLoad, "wear": Wear,
          "safety": SafetyViolation, "can": CanStats, "timing": Timing, "stalls": Stalls}
_FLAT_PARTS = {"bus": Bus, "attribution": Attribution, "installation": Installation}
_PLAIN = {"run_id": "text", "started_utc": "text", "scenario": "text", "seed": "int", "realtime": "bool",
          "simrig": "object", "truth": "object", "eds": "text", "eds_nodes": "text map", "force_control": "text map",
          "files_sha256": "text map", "recording_sha256": "text map", "process_image": "object",
          "master_loss": "object", "reason": "text", "ended_utc": "text", "samples": "int", "duration_s": "number",
          "wall_s": "number"}


def _json_of(name: str, v: Any) -> dict:
    """The JSON key(s) of field ``name`` holding ``v`` (not None)."""
    if name in _FLAT_PARTS:
        return v.as_json()
    if name == "steps":
        return {name: {s.name: s.as_json() for s in v}}
    if name in ("identity", "drives_final", "drives_last"):
        return {name: {k: None if p is None else p.as_json() for k, p in v.items()}}
    if isinstance(v, StrEnum):
        return {name: v.value}
    if isinstance(v, tuple):
        return {name: list(v)}
    return {name: v.as_json() if hasattr(v, "as_json") else v}


def start_record(act, check, **fields) -> RunRecord:
    """A new run's record: a new run id, this software, the time now, status ``running``, the snapshots
    of ``act`` and ``check``, no steps yet; ``fields``: the other :class:`RunRecord` fields (``status``
    too: a recording made whole at once is ``done``)."""
    from hil import __version__
    from hil.profile.load import actuation_tables, snapshot

    base = {"run_id": uuid.uuid4().hex, "software": Software("emacheck", __version__),
            "started_utc": utc_now_iso(), "status": RunStatus.RUNNING,
            "profiles": Profiles(actuation_tables(act), snapshot(check)), "steps": ()}
    return RunRecord(**{**base, **fields})
