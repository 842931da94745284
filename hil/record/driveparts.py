"""The drives in the run record: each drive's identity (0x1018) as it reported it, the limits it keeps, its
final CiA 402 state after the check (:class:`DriveFinal`) and where it was last seen (:class:`DriveLast`:
position, force, the EMCYs it sent). Parts of :class:`hil.record.runrecord.RunRecord`; this module does no IO.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from hil.errors import RunRecordError
from hil.record.recordjson import RECORD, Fields, Part, only, part_keys, req, show


@dataclass(frozen=True)
class Identity(Part):
    """A drive's identity object 0x1018 as it reported it, with its node id. ``product_code``, ``revision``,
    ``serial`` None: the read was refused or not answered (optional sub-indices, CiA 301); ``serial_listed``
    False: no serial was asked for (a record from before issue 36 of a drive whose EDS has no 0x1018:04;
    no ``serial`` key in the JSON)."""

    node: int
    vendor_id: int
    product_code: int | None
    revision: int | None
    serial: int | None = None
    serial_listed: bool = True

    def as_json(self) -> dict:
        out = {"node": self.node, "vendor_id": self.vendor_id, "product_code": self.product_code,
               "revision": self.revision}
        if self.serial_listed:
            out["serial"] = self.serial
        return out

    @classmethod
    def read(cls, f: Fields) -> Identity:
        return cls(*(f.get(k, "int", required=True) for k in ("node", "vendor_id")),
                   *(f.get(k, "int") for k in ("product_code", "revision")),
                   serial=f.get("serial", "int"), serial_listed=f.has("serial"))

    @classmethod
    def of(cls, node: int, read: Mapping) -> Identity | None:
        """From what the preflight read of 0x1018 (:attr:`hil.master.preflight.Preflight.identities`); None
        if nothing."""
        if not read:
            return None
        only(read, IDENTITY_KEYS, f"identity (node {node})", "preflight")
        return cls.from_json({"node": node, **read}, f"identity (node {node})", "preflight")


#: the JSON keys of :class:`Identity`
IDENTITY_KEYS = ("node", "vendor_id", "product_code", "revision", "serial")

@dataclass(frozen=True)
class KeptLimit(Part):
    """A limit of one drive (:class:`hil.canopen.drivelimits.DriveLimit`): its value in the drive's unit,
    the profile's limit it stands for, and who keeps it: ``drive`` (written to ``object`` and read back)
    or ``master`` (the drive's EDS has no such object: only the master's supervisor keeps it)."""

    limit: str = req("text")
    object: str = req("text")
    value: int = req("int")
    unit: str = req("text")
    si_value: float = req("number")
    si_unit: str = req("text")
    kept_by: str = req("text")

    def __post_init__(self) -> None:
        if self.kept_by not in ("drive", "master"):
            raise RunRecordError("kept_by", f"{show(self.kept_by)} is not one of drive, master", RECORD)


@dataclass(frozen=True)
class DriveFinal(Part):
    """A drive's final CiA 402 state after the check (:meth:`hil.master.core.MasterCore.safe_state_report`):
    the last state seen (None: its statusword never read) and when (``seen_t_s``, the master's time),
    reachable (heartbeat), confirmed (read by SDO after the safe stop's last command), safe (Switch on
    disabled, confirmed), ``seen`` in words ("read after the stop at t = ...", "statusword stale since
    t = ... (why)", "statusword never read (why)"), and its protection against the master's death (the
    preflight's record, JSON; ``{}`` if none). A record from before issue 36 has no ``seen_t_s``/``seen``."""

    node: int
    state: str | None
    reachable: bool
    confirmed: bool
    safe: bool
    master_loss: dict = dataclasses.field(default_factory=dict)
    #: the limits the drive keeps itself, and those only the master keeps (the preflight's; () if none)
    drive_limits: tuple[KeptLimit, ...] = ()
    seen_t_s: float | None = None
    seen: str = ""

    def as_json(self) -> dict:
        return {"node": self.node, "state": self.state, "seen_t_s": self.seen_t_s, "seen": self.seen,
                "reachable": self.reachable, "confirmed": self.confirmed,
                "safe": self.safe, "master_loss": self.master_loss,
                "drive_limits": [lim.as_json() for lim in self.drive_limits]}

    @classmethod
    def read(cls, f: Fields) -> DriveFinal:
        lims = f.get("drive_limits", "list") or []
        return cls(f.get("node", "int", required=True), f.get("state", "text"),
                   *(f.get(k, "bool", required=True) for k in ("reachable", "confirmed", "safe")),
                   master_loss=f.get("master_loss", "object") or {},
                   drive_limits=tuple(KeptLimit.from_json(v, f.name(f"drive_limits[{j}]"), f.source)
                                      for j, v in enumerate(lims)),
                   seen_t_s=f.get("seen_t_s", "number"), seen=f.get("seen", "text") or "")

    def unsafe_note(self, ema: str) -> str:
        """``EMA 2 (node 2) unreachable (heartbeat lost), statusword stale since t = 1.204 s (...), last seen
        FAULT``: for the abort reason, in words of what was seen."""
        head = f"EMA {ema[-1]} (node {self.node}) " + ("unreachable (heartbeat lost), " if not self.reachable else "")
        if self.confirmed:
            return head + f"in {self.state}"
        seen = self.seen or ("state not confirmed" if self.state is not None else "statusword never read")
        return head + seen + (f", last seen {self.state}" if self.state is not None else "")


#: the EMCYs a drive's :class:`DriveLast` keeps: the last ones (a drive in a fault loop may send one per cycle)
EMCY_KEPT = 8


@dataclass(frozen=True)
class EmcySeen(Part):
    """An EMCY a drive sent during the check or its stop (CiA 301): when [s, check time; to the SYNC period it
    arrived in], its error code and error register, and the code in words."""

    t_s: float = req("number")
    code: int = req("int")
    error_register: int = req("int")
    text: str = req("text")

    def words(self) -> str:
        """``EMCY 0x8130 (heartbeat or life guard error) at t = 52.104 s``."""
        return f"EMCY 0x{self.code:04X} ({self.text}) at t = {self.t_s:.3f} s"


@dataclass(frozen=True)
class DriveLast(Part):
    """Where a drive was last seen: the time of the last complete sample [s, check time], the ram's position
    from the motor angle (phi / i_total) [mm], the LVDT's stroke [mm] and the load cell's force [N] in it; the
    EMCYs the drive sent from the start of the check to the end of its stop (the last :data:`EMCY_KEPT` of
    them) and how many it sent in all. Its CiA 402 state is :class:`DriveFinal`'s."""

    t_s: float = req("number")
    position_mm: float = req("number")
    stroke_mm: float = req("number")
    force_N: float = req("number")
    emcy: tuple[EmcySeen, ...] = ()
    emcy_count: int = 0

    def as_json(self) -> dict:
        return {"t_s": self.t_s, "position_mm": self.position_mm, "stroke_mm": self.stroke_mm,
                "force_N": self.force_N, "emcy": [e.as_json() for e in self.emcy], "emcy_count": self.emcy_count}

    @classmethod
    def read(cls, f: Fields) -> DriveLast:
        emcy = f.get("emcy", "list") or []
        return cls(*(f.get(k, "number", required=True) for k in ("t_s", "position_mm", "stroke_mm", "force_N")),
                   emcy=tuple(EmcySeen.from_json(v, f.name(f"emcy[{j}]"), f.source) for j, v in enumerate(emcy)),
                   emcy_count=f.get("emcy_count", "int") or len(emcy))

    @classmethod
    def of(cls, sample, t0_s: float, i_total_rad_per_mm: float, emcys: Mapping | None = None) -> dict[str, DriveLast]:
        """Per EMA, from the last complete sample (:class:`hil.canopen.process.Sample`, its time and the EMCYs'
        less ``t0_s``, the check's start) and the EMCYs each drive sent (``{"ema1": [{"t_s", "code",
        "error_register", "text"}, ...]}``, :meth:`hil.master.core.MasterCore.emcy_report`; None: no CAN)."""
        out = {}
        for k in (1, 2):
            seen = list((emcys or {}).get(f"ema{k}") or [])
            for e in seen:
                only(e, part_keys(EmcySeen), f"emcy of EMA {k}", "the master")
            kept = tuple(EmcySeen.from_json({**e, "t_s": round(e["t_s"] - t0_s, 6)}, f"emcy of EMA {k}", "the master")
                         for e in seen[-EMCY_KEPT:])
            phi = getattr(sample, f"phi{k}_rad")
            out[f"ema{k}"] = cls(round(sample.t_s - t0_s, 6), phi / i_total_rad_per_mm, getattr(sample, f"s{k}_mm"),
                                 getattr(sample, f"F{k}_N"), kept, len(seen))
        return out


def last_known(final: Mapping[str, DriveFinal] | None, last: Mapping[str, DriveLast] | None) -> dict:
    """result.json's ``trace.drives_last``: per EMA what the record knows of where its drive was left, its
    CiA 402 state (:class:`DriveFinal`: ``node``, ``state``, ``safe``, ``confirmed``, ``reachable``, ``seen``;
    null where the run had no CANopen drives) and its last sample with its EMCYs (:class:`DriveLast`: ``t_s``,
    ``position_mm``, ``stroke_mm``, ``force_N``, ``emcy``, ``emcy_count``; absent where none was taken)."""
    out = {}
    for k in sorted(set(final or {}) | set(last or {})):
        fin, seen = (final or {}).get(k), (last or {}).get(k)
        out[k] = {"node": None if fin is None else fin.node, "state": None if fin is None else fin.state,
                  **{f: None if fin is None else getattr(fin, f) for f in ("safe", "confirmed", "reachable")},
                  "seen": "" if fin is None else fin.seen, **({} if seen is None else seen.as_json())}
    return out
