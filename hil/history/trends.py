"""Series per actuator and channel, their steps and wear trends: the document ``emacheck history`` shows.

A *series* is one channel of one installation: the internal backlash of an
actuator (by its 0x1018 vendor, product and serial) at one aircraft and
position, or the external backlash of the pair of actuators there. Real and
simulated checks never share a series. Its points are the maintenance checks
(BLFmaint) that decided something (pass, fail, inconclusive), one per run:
the latest analysis of each run id. A reading without its actuator's identity (0x1018 vendor, product
and serial: a bare recording) is in no series: recorded and listed, never trended with another
(:data:`NO_IDENTITY`). BLFserv readings are listed and plotted
beside them but not fitted (another method, with another bound: a method
bias would look like wear).

Each series is split at its steps down (a repair; :func:`blf.wear.wear_segments`)
and each segment of at least :data:`MIN_POINTS` checks gets a wear line
(:func:`blf.wear.fit_wear`) over flight hours, or over calendar time when a
check in it has no flight hours, and the crossing of B_spec
(:func:`blf.wear.limit_crossing`), as flight hours and, at the utilisation the
checks record (flight hours per day), as a date.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from blf.wear import LimitCrossing, WearFit, fit_wear, limit_crossing, wear_segments
from hil.history.record import rank

CHANNELS = ("int1", "int2", "ext")
#: statuses whose readings enter a trend (an aborted or incomplete check's do not)
DECIDED = ("pass", "fail", "inconclusive")
#: fewest checks in a segment for a trend (two define a line but not its scatter)
MIN_POINTS = 3
_EPOCH = _dt.datetime(1970, 1, 1)
_DAY_S = 86400.0


def days(t: _dt.datetime) -> float:
    """Days since 1970-01-01 (UTC, naive)."""
    return (t - _EPOCH).total_seconds() / _DAY_S


def from_days(d: float) -> _dt.datetime | None:
    """The inverse of :func:`days` (None where not finite or out of range)."""
    if not math.isfinite(d) or abs(d) > 3.6e6:
        return None
    return _EPOCH + _dt.timedelta(days=d)


def iso(t: _dt.datetime | None, *, date_only: bool = False) -> str | None:
    """ISO 8601 UTC text of a naive UTC time."""
    if t is None:
        return None
    return t.date().isoformat() if date_only else t.replace(microsecond=0).isoformat() + "Z"


def fmt_serial(serial: int | None) -> str:
    """A serial number as the profiles write it (``0x5E000101``), "unknown" for None."""
    return "unknown" if serial is None else f"0x{serial:08X}"


@dataclass
class Point:
    """One reading of a series."""

    row: dict  #: the check as :meth:`hil.history.store.HistoryStore.checks` gives it
    backlash_mm: float
    uncertainty_mm: float | None
    verdict: str | None
    x: float = math.nan  #: on the series' axis (flight hours, or days since 1970)
    segment: int = 0

    @property
    def time(self) -> _dt.datetime:
        return self.row["time_utc"]


@dataclass
class Segment:
    """A stretch of a series between steps, with its wear line where it has enough checks."""

    points: list[Point]
    axis: str  #: "flight_hours" or "calendar_days"
    fit: WearFit | None = None
    crossing: LimitCrossing | None = None
    reason: str = ""  #: why there is no trend, or a note on it


@dataclass
class Series:
    """One channel of one installation (see the module docstring)."""

    channel: str
    simulated: bool
    aircraft: str
    position: str
    identity: dict  #: {"ema1": {...} | None, "ema2": {...} | None}: who the series is of
    limit_mm: float | None
    pair: dict = field(default_factory=dict)  #: serial numbers at EMA 1 and EMA 2 at the latest check
    points: list[Point] = field(default_factory=list)  #: the fitted kind (BLFmaint), one per run
    serv_points: list[Point] = field(default_factory=list)  #: BLFserv readings, shown, not fitted
    segments: list[Segment] = field(default_factory=list)
    utilisation_fh_per_day: float | None = None

    @property
    def ema(self) -> str | None:
        return {"int1": "ema1", "int2": "ema2"}.get(self.channel)

    @property
    def serial(self) -> int | None:
        ident = self.identity.get(self.ema) if self.ema else None
        return None if ident is None else ident["serial"]

    def title(self) -> str:
        where = " ".join(x for x in (self.aircraft, self.position) if x) or "installation not recorded"
        if self.ema:
            who = f"actuator {fmt_serial(self.serial)} ({self.ema})"
        else:
            who = ("pair " + " / ".join(fmt_serial((self.identity.get(e) or {}).get("serial"))
                                        for e in ("ema1", "ema2")))
        return f"{who}, {self.channel}, {where}" + (" [simulated]" if self.simulated else "")


def _ident_key(ident: dict | None) -> tuple | None:
    return None if not ident else (ident["vendor_id"], ident["product_code"], ident["serial"])


#: why a reading without its actuator's identity is in no trend (docs/history.md)
NO_IDENTITY = ("the actuator's identity is unknown (no 0x1018 vendor, product and serial: a bare recording, or "
               "drives not read); 'unknown' is not an actuator, so its readings are recorded and listed but never "
               "trended together with another's")


def _who(ident: dict, ch: str) -> tuple:
    """The actuators a channel's reading is of: (EMA 1, EMA 2) for ext, its EMA's for an internal channel."""
    if ch == "ext":
        return (_ident_key(ident.get("ema1")), _ident_key(ident.get("ema2")))
    return (_ident_key(ident.get("ema1" if ch == "int1" else "ema2")),)


def not_trended(r: dict) -> str | None:
    """Why channels of a recorded result are in no trend (:data:`NO_IDENTITY`, naming them), None if each can be."""
    chs = [ch for ch in CHANNELS if (r["readings"].get(ch) or {}).get("backlash_mm") is not None
           and None in _who(r["identity"], ch)]
    return None if not chs else f"{', '.join(chs)}: {NO_IDENTITY}"


def latest_per_run(rows: list[dict]) -> list[dict]:
    """Of several results of one run (a check and its re-analyses), the latest analysed, per kind."""
    best: dict[tuple, dict] = {}
    for r in rows:
        k = (r["run_key"], r["kind"])
        cur = best.get(k)
        if cur is None or rank(r.get("analysed_utc"), r["id"]) > rank(cur.get("analysed_utc"), cur["id"]):
            best[k] = r
    keep = {id(r) for r in best.values()}
    return [r for r in rows if id(r) in keep]


def build_series(rows: list[dict], *, serial: int | None = None) -> list[Series]:
    """Group the checks into series, split them at steps and fit each segment.

    Parameters
    ----------
    rows : list of dict
        Checks from :meth:`hil.history.store.HistoryStore.checks` (time order).
    serial : int, optional
        Keep only the series of this actuator (its internal channel and the external one of its pairs).

    A reading whose actuator's identity is unknown (a bare recording) joins no series: "unknown" is not an
    actuator (:func:`not_trended` says so of its result).
    """
    series: dict[tuple, Series] = {}
    for r in latest_per_run(rows):
        ident = r["identity"]
        for ch in CHANNELS:
            rd = r["readings"].get(ch)
            if rd is None or rd.get("backlash_mm") is None:
                continue
            who = _who(ident, ch)
            if None in who:  # "unknown" is not an actuator: never joined with another's readings (not_trended)
                continue
            emas = ("ema1", "ema2") if ch == "ext" else ("ema1",) if ch == "int1" else ("ema2",)
            sid = {e: ident.get(e) for e in emas}
            key = (bool(r["simulated"]), r["aircraft"], r["position"], ch, who)
            s = series.get(key)
            if s is None:
                s = series[key] = Series(ch, bool(r["simulated"]), r["aircraft"], r["position"], sid, None)
            if rd.get("limit_mm") is not None:
                s.limit_mm = rd["limit_mm"]
            s.pair = {e: (ident.get(e) or {}).get("serial") for e in ("ema1", "ema2")}
            p = Point(r, float(rd["backlash_mm"]), rd.get("uncertainty_mm"), rd.get("verdict"))
            if r["kind"] == "serv":
                s.serv_points.append(p)
            elif r["status"] in DECIDED and p.uncertainty_mm is not None and p.uncertainty_mm > 0:
                s.points.append(p)
    out = list(series.values())
    if serial is not None:
        out = [s for s in out if any((s.identity.get(e) or {}).get("serial") == serial for e in ("ema1", "ema2"))
               and (s.ema is None or s.serial == serial)]
    for s in out:
        _fit_series(s)
    out.sort(key=lambda s: (s.simulated, s.aircraft, s.position, CHANNELS.index(s.channel), s.serial or 0))
    return out


def _utilisation(points: list[Point]) -> float | None:
    """Flight hours per day between the first and last check that record both (None if under a day apart)."""
    pts = [p for p in points if p.row.get("flight_hours") is not None]
    if len(pts) < 2:
        return None
    a, b = min(pts, key=lambda p: p.time), max(pts, key=lambda p: p.time)
    span = (b.time - a.time).total_seconds() / _DAY_S
    dfh = b.row["flight_hours"] - a.row["flight_hours"]
    return dfh / span if span >= 1.0 and dfh > 0 else None


def _fit_series(s: Series) -> None:
    s.utilisation_fh_per_day = _utilisation(s.points + s.serv_points)
    if not s.points:
        return
    s.points.sort(key=lambda p: (p.row.get("flight_hours") is None, p.row.get("flight_hours") or 0.0, p.time))
    # each point on the series' axis: flight hours where every fitted check has them, else days since 1970
    for p in s.points + s.serv_points:
        fh = p.row.get("flight_hours")
        p.x = float(fh) if fh is not None else days(p.time)
    all_fh = all(p.row.get("flight_hours") is not None for p in s.points)
    if not all_fh:  # calendar time for the whole series: flight hours are not comparable with days
        s.points.sort(key=lambda p: p.time)
        for p in s.points + s.serv_points:
            p.x = days(p.time)
    else:  # a serv reading without flight hours has no place on the flight-hour axis
        for p in s.serv_points:
            if p.row.get("flight_hours") is None:
                p.x = math.nan
    x = np.array([p.x for p in s.points])
    y = np.array([p.backlash_mm for p in s.points])
    u = np.array([p.uncertainty_mm for p in s.points])
    axis = "flight_hours" if all_fh else "calendar_days"
    for j, idx in enumerate(wear_segments(x, y, u)):
        seg = Segment([s.points[i] for i in idx], axis)
        for i in idx:
            s.points[i].segment = j
        if not all_fh:
            seg.reason = "over calendar time (a check without flight hours)"
        n = len(seg.points)
        if n < MIN_POINTS:
            seg.reason = f"{n} check(s): a trend needs {MIN_POINTS}"
        elif np.ptp(x[idx]) <= 0:
            seg.reason = "every check of this segment at the same " + ("flight hours" if all_fh else "time")
        else:
            seg.fit = fit_wear(x[idx], y[idx], u[idx])
        s.segments.append(seg)
    for seg in s.segments[:-1]:
        seg.reason = (seg.reason + "; " if seg.reason else "") + "before a step down (repair): no prediction"
    last = s.segments[-1]
    if last.fit is not None and s.limit_mm is not None and s.limit_mm > 0:  # only the current trend predicts
        last.crossing = limit_crossing(last.fit, s.limit_mm)
    for p in s.serv_points:  # a serv reading belongs to the segment it falls after
        p.segment = max([j for j, g in enumerate(s.segments) if g.points and g.points[0].x <= p.x] or [0])


def _finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def trend_dict(s: Series, j: int) -> dict[str, Any]:
    """The JSON of one segment's trend (``trends`` of the history document)."""
    seg = s.segments[j]
    f, c = seg.fit, seg.crossing
    fh_axis = seg.axis == "flight_hours"
    per = 1000.0 if fh_axis else 365.25  # per 1000 FH, or per year
    last = seg.points[-1]
    d: dict[str, Any] = {
        "serial": s.serial, "ema": s.ema, "channel": s.channel, "simulated": s.simulated,
        "pair": dict(s.pair),
        "vendor_id": ((s.identity.get(s.ema or "ema1") or {}).get("vendor_id")),
        "product_code": ((s.identity.get(s.ema or "ema1") or {}).get("product_code")),
        "aircraft": s.aircraft, "position": s.position, "segment": j, "current": j == len(s.segments) - 1,
        "n": len(seg.points), "axis": seg.axis, "first_time_utc": iso(seg.points[0].time),
        "last_time_utc": iso(last.time), "first_fh": seg.points[0].row.get("flight_hours"),
        "last_fh": last.row.get("flight_hours"), "limit_mm": s.limit_mm,
        "rate_mm_per_1000_fh": None, "rate_sigma": None, "rate_interval_95": [None, None],
        "rate_unit": "mm/1000 FH" if fh_axis else "mm/year",
        "rate_mm_per_year": None, "backlash_now_mm": None, "backlash_now_sigma_mm": None,
        "chi2_per_dof": None, "scale": None, "limit_at_fh": None, "limit_at_fh_interval": [None, None],
        "limit_at_fh_sigma_delta": None, "limit_at_date": None, "limit_at_date_interval": [None, None],
        "utilisation_fh_per_day": s.utilisation_fh_per_day, "reason": seg.reason or None,
    }
    if f is None:
        return d
    d.update(rate_sigma=f.rate_sigma * per, chi2_per_dof=_finite(f.chi2_per_dof), scale=f.scale,
             rate_interval_95=[(f.rate - f.quantile * f.rate_sigma) * per, (f.rate + f.quantile * f.rate_sigma) * per],
             backlash_now_mm=float(f.predict(last.x)), backlash_now_sigma_mm=float(f.line_sigma(last.x)))
    if fh_axis:
        d["rate_mm_per_1000_fh"] = f.rate * per
    else:
        d["rate_mm_per_year"] = f.rate * per
    if c is None:
        return d
    lo, hi = c.lo, c.hi
    if fh_axis:
        d.update(limit_at_fh=_finite(c.x), limit_at_fh_interval=[_finite(lo), _finite(hi)],
                 limit_at_fh_sigma_delta=_finite(c.sigma_delta))
        util = s.utilisation_fh_per_day
        fh_last = last.row["flight_hours"]
        if util:
            on = lambda fh: None if fh is None or not math.isfinite(fh) else iso(  # noqa: E731
                from_days(days(last.time) + (fh - fh_last) / util), date_only=True)
            d.update(limit_at_date=on(c.x), limit_at_date_interval=[on(lo), on(hi)])
    else:
        on = lambda x: None if not math.isfinite(x) else iso(from_days(x), date_only=True)  # noqa: E731
        d.update(limit_at_date=on(c.x), limit_at_date_interval=[on(lo), on(hi)])
    return d


def check_dict(r: dict, in_trend: set[int], current: set[int] | None = None) -> dict[str, Any]:
    """The JSON of one recorded result (``checks`` of the history document); ``current``: the ids of the
    latest result of each run (a result superseded by a re-analysis stays, marked not current)."""
    rd = r["readings"]
    ident = {e: (None if v is None else {k: v[k] for k in ("vendor_id", "product_code", "revision", "serial")})
             for e, v in r["identity"].items()}
    return {
        "run_id": r["run_id"], "run_key": r["run_key"], "kind": r["kind"], "time_utc": iso(r["time_utc"]),
        "analysed_utc": iso(r.get("analysed_utc")), "simulated": bool(r["simulated"]), "mode": r["mode"],
        "aircraft": r["aircraft"], "position": r["position"], "rig": r["rig"], "operator": r["operator"],
        "work_order": r["work_order"], "flight_hours": r["flight_hours"], "flight_cycles": r["flight_cycles"],
        "identity": ident, "status": r["status"],
        "backlash_mm": {ch: (rd.get(ch) or {}).get("backlash_mm") for ch in CHANNELS},
        "uncertainty_mm": {ch: (rd.get(ch) or {}).get("uncertainty_mm") for ch in CHANNELS},
        "verdict": {ch: (rd.get(ch) or {}).get("verdict") for ch in CHANNELS},
        "stiffness_N_per_mm": {ch: {"left": (rd.get(ch) or {}).get("stiffness_left_N_per_mm"),
                                    "right": (rd.get(ch) or {}).get("stiffness_right_N_per_mm")} for ch in CHANNELS},
        "calibration": {e: {"pitch": r.get(f"{e}_lvdt_pitch"), "offset_mm": r.get(f"{e}_lvdt_offset_mm"),
                            "nonlinearity_mm": r.get(f"{e}_lvdt_nonlinearity_mm"),
                            "rmse_mm": r.get(f"{e}_lvdt_rmse_mm")} for e in ("ema1", "ema2")},
        "software_version": r["software_version"], "run_folder": r["run_folder"], "result_path": r["result_path"],
        "in_trend": r["id"] in in_trend, "not_trended": not_trended(r), "recording": r.get("recording"),
        "id": r["id"], "supersedes": r.get("supersedes_id"),
        "current": current is None or r["id"] in current,
    }


def history_document(rows: list[dict], series: list[Series], *, url: str, filters: dict) -> dict[str, Any]:
    """The document of ``emacheck history --json`` (schema ``hil/schemas/history.schema.json``)."""
    in_trend = {p.row["id"] for s in series for p in s.points}
    trends = [trend_dict(s, j) for s in series for j in range(len(s.segments))]
    current = {r["id"] for r in latest_per_run(rows)}
    return {"history": url, "filters": filters, "checks": [check_dict(r, in_trend, current) for r in rows],
            "trends": trends}
