"""From a result file to a history record (recording it into a store: :mod:`hil.history.sync`).

A record is what :meth:`hil.history.store.HistoryStore.add` writes: the
check's columns (when, where, who, flight hours, status, calibration, files),
the actuators at EMA 1 and EMA 2 (0x1018 vendor, product, serial) and one
reading per channel. Everything comes from the result itself (result.json or
serv.json, whose ``trace`` carries identity, aircraft, position, rig, flight
hours and cycles), so a result that could not be recorded when it was made is
recorded later from its run folder exactly as it would have been.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hil.record.runrecord import shared_serial
from hil.record.seal import sha256_file

#: modes of simulated checks (meta.json ``mode``): never mixed into a real actuator's trend
SIMULATED_MODES = ("dry-run", "simulate", "simulate-scenario")
CHANNELS = ("int1", "int2", "ext")


@dataclass(frozen=True)
class CheckRecord:
    """One result as the history stores it (see :mod:`hil.history.schema`)."""

    check: dict  #: column -> value of ``emacheck_checks`` (without the actuator ids)
    identity: dict  #: ``{"ema1": (vendor_id, product_code, serial) | None, "ema2": ...}``
    readings: list = field(default_factory=list)  #: column -> value of ``emacheck_readings`` per channel


def rank(analysed_utc: _dt.datetime | None, check_id: int) -> tuple:
    """The order of the results of one run and kind (a check and its re-analyses): by analysis time (none:
    first), then as recorded. The last is the run's current result; each supersedes the one before."""
    return (analysed_utc or _dt.datetime.min, check_id)


def result_sha256(result: dict) -> str:
    """SHA-256 of a result's canonical JSON (sorted keys, no blanks): the same result, the same key."""
    from hil.record.runfolder import json_default

    text = json.dumps(result, sort_keys=True, separators=(",", ":"), default=json_default, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def parse_utc(text: Any) -> _dt.datetime | None:
    """An ISO 8601 time as a naive UTC datetime (None if absent or unreadable)."""
    if not text or not isinstance(text, str):
        return None
    try:
        t = _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return None
    if t.tzinfo is not None:
        t = t.astimezone(_dt.UTC).replace(tzinfo=None)
    return t


def kind_of(result: dict) -> str:
    """``"serv"`` for a serv.json, ``"maint"`` for a maintenance check's result.json."""
    return "serv" if ("traversals" in result or "jumps" in result) and "stiffness_N_per_mm" not in result else "maint"


def is_simulated(result: dict) -> bool:
    """True for a result of simulated data (a simulated mode, or the simulator's truth beside it)."""
    trace = result.get("trace") or {}
    return trace.get("mode") in SIMULATED_MODES or isinstance(result.get("truth"), dict)


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else None


def _int(x: Any) -> int | None:
    return int(x) if isinstance(x, int) and not isinstance(x, bool) else None


def _text(x: Any, n: int) -> str | None:
    return None if x is None else str(x)[:n]


def record_from_result(result: dict, *, result_path: Path | None = None, run_folder: Path | None = None,
                       recording_sha256: str | None = None) -> CheckRecord:
    """The history record of a result (result.json or serv.json content).

    Parameters
    ----------
    result : dict
        The result as written (with its ``trace``).
    result_path, run_folder : Path, optional
        Where the result and its run folder are (stored so the history points to the files).
    recording_sha256 : str, optional
        SHA-256 of the recording, for a result without a run id (a bare recording): the check's key,
        so that analysing the same recording twice is one check in the trend.
    """
    trace = result.get("trace") or {}
    clash = shared_serial(trace.get("identity"))
    if clash is not None:
        from hil.errors import HistoryInputError

        raise HistoryInputError(f"{result_path or 'the result'}: {clash}; not recorded (the history would "
                                f"mix two actuators' readings in one trend)")
    kind = kind_of(result)
    sha = result_sha256(result)
    run_id = trace.get("run_id") or None
    if run_id:
        run_key = str(run_id)
    elif recording_sha256:
        run_key = f"recording:{recording_sha256}"
    else:
        rec = trace.get("recording")
        h = sha256_file(Path(rec)) if rec else None
        run_key = f"recording:{h}" if h else f"result:{sha}"
    t = (parse_utc(trace.get("started_utc")) or parse_utc(trace.get("analysed_utc"))
         or _dt.datetime.now(_dt.UTC).replace(tzinfo=None, microsecond=0))
    sw = trace.get("software") or {}
    spec = result.get("spec") or {}
    verdict = result.get("verdict") or {}
    limits = {ch: _num((verdict.get(ch) or {}).get("limit_mm")) for ch in CHANNELS}
    check: dict[str, Any] = {
        "result_sha256": sha, "run_key": run_key[:96], "run_id": _text(run_id, 64), "kind": kind,
        "simulated": is_simulated(result), "mode": _text(trace.get("mode"), 32), "time_utc": t,
        "analysed_utc": parse_utc(trace.get("analysed_utc")),
        "aircraft": str(trace.get("aircraft") or "")[:40], "position": str(trace.get("position") or "")[:80],
        "rig": str(trace.get("rig") or "")[:80], "operator": _text(trace.get("operator"), 120),
        "work_order": _text(trace.get("work_order"), 120), "flight_hours": _num(trace.get("flight_hours")),
        "flight_cycles": _int(trace.get("flight_cycles")), "status": str(result.get("status") or "unknown")[:16],
        "software_version": _text(sw.get("version"), 40), "check_software_version": _text(sw.get("check_run_with"), 40),
        "limit_int_mm": _num(spec.get("backlash_int_mm")) or limits["int1"] or limits["int2"],
        "limit_ext_mm": _num(spec.get("backlash_ext_mm")) or limits["ext"],
        "run_folder": None if run_folder is None else str(Path(run_folder).resolve()),
        "result_path": None if result_path is None else str(Path(result_path).resolve()),
        "recording": _text(trace.get("recording") or result.get("recording"), 2000),
    }
    identity: dict[str, tuple[int, int, int] | None] = {}
    for k, ema in ((1, "ema1"), (2, "ema2")):
        ident = (trace.get("identity") or {}).get(ema) or {}
        keys = [_int(ident.get(f)) for f in ("vendor_id", "product_code", "serial")]
        identity[ema] = None if any(v is None for v in keys) else tuple(keys)
        check[f"ema{k}_revision"] = _int(ident.get("revision"))
        check[f"ema{k}_node"] = _int(ident.get("node"))
        cal = (result.get("calibration") or {}).get(ema) or {}
        check[f"ema{k}_lvdt_pitch"] = _num(cal.get("pitch"))
        check[f"ema{k}_lvdt_offset_mm"] = _num(cal.get("offset_mm"))
        check[f"ema{k}_lvdt_nonlinearity_mm"] = _num(cal.get("nonlinearity_mm"))
        check[f"ema{k}_lvdt_rmse_mm"] = _num(cal.get("rmse_mm"))
    check["calibration_source"] = _text((result.get("calibration") or {}).get("source"), 2000)
    readings = []
    backlash = result.get("backlash_mm") or {}
    sigma = result.get("backlash_sigma_mm") or {}
    stiff = result.get("stiffness_N_per_mm") or {}
    stiff_s = result.get("stiffness_sigma_N_per_mm") or {}
    trav = result.get("traversals") or {}
    for ch in CHANNELS:
        v = verdict.get(ch) or {}
        if ch not in backlash and not v:
            continue
        st, ss = stiff.get(ch) or {}, stiff_s.get(ch) or {}
        readings.append({
            "channel": ch, "backlash_mm": _num(backlash.get(ch, v.get("backlash_mm"))),
            "uncertainty_mm": _num(v.get("uncertainty_mm")), "backlash_sigma_mm": _num(sigma.get(ch)),
            "limit_mm": _num(v.get("limit_mm")), "margin_mm": _num(v.get("margin_mm")),
            "verdict": _text(v.get("status"), 16), "reason": _text(v.get("reason"), 4000),
            "stiffness_left_N_per_mm": _num(st.get("left")), "stiffness_right_N_per_mm": _num(st.get("right")),
            "stiffness_left_sigma_N_per_mm": _num(ss.get("left")),
            "stiffness_right_sigma_N_per_mm": _num(ss.get("right")), "traversals": _int(trav.get(ch)),
        })
    return CheckRecord(check=check, identity=identity, readings=readings)


def unidentified(result: dict) -> list[str]:
    """The EMAs of a result whose identity (0x1018 vendor, product, serial) it does not carry: a bare
    recording's are unknown, and its readings are never trended with another's (:mod:`hil.history.trends`)."""
    ident = (result.get("trace") or {}).get("identity") or {}
    return [e for e in ("ema1", "ema2")
            if any(_int((ident.get(e) or {}).get(f)) is None for f in ("vendor_id", "product_code", "serial"))]


def load_result(path: Path) -> dict:
    """A result.json / serv.json, or :class:`hil.errors.RecordingError` naming the file."""
    from hil.errors import RecordingError
    from hil.record.runfolder import read_json

    data = read_json(path)
    if not isinstance(data, dict) or "status" not in data:
        raise RecordingError(f"{path}: not an emacheck result (no status)")
    return data


