"""The reference of a dual-EMA check from the wear history, and the serial rule of any reference (issue 35).

``emacheck diagnose RUN --reference history``: the last check recorded in the wear history (hil/history)
before RUN, made with the same actuators (0x1018 vendor, product and serial at EMA 1 and at EMA 2, as
RUN's result.json ``trace.identity`` reports them), simulated or not as RUN is, whose run folder is still
there. A reference whose actuators differ from RUN's (one replaced, or swapped between the positions) is
refused (:class:`hil.errors.RecordingError`, exit 3) unless ``--allow-other-serials``: a change against
another actuator is not wear. The same rule holds for a run folder given as ``--reference``. Nothing here
writes.
"""

from __future__ import annotations

from pathlib import Path

from hil.errors import RecordingError

EMAS = ("ema1", "ema2")


def fmt_identity(ident: dict) -> str:
    """``ema1 0x5E000101, ema2 0x5E000102`` (serials as the profiles write them; "unknown" where not read)."""
    from hil.history.trends import fmt_serial
    return ", ".join(f"{e} {fmt_serial(None if ident.get(e) is None else ident[e][2])}" for e in EMAS)


def run_identity(path: Path) -> dict | None:
    """{ema: (vendor_id, product_code, serial) or None} of a run folder's result.json; None without one."""
    from hil.history.record import load_result, record_from_result
    res = Path(path) / "result.json"
    if not Path(path).is_dir() or not res.is_file():
        return None
    return record_from_result(load_result(res), result_path=res, run_folder=Path(path)).identity


def refuse_other_serials(new: Path, ref: Path, allow: bool) -> dict:
    """The serial rule of an explicit ``--reference``: both run folders with the actuators' serials read
    and differing are refused (exit 3) unless ``allow``. Returns diagnosis.json's ``serials`` entry."""
    a, b = run_identity(new), run_identity(ref)
    if a is None or b is None or any(a.get(e) is None or b.get(e) is None for e in EMAS):
        return {"checked": False, "words": "the actuators' serials are not known for both recordings: not compared"}
    same = all(a[e] == b[e] for e in EMAS)
    if not same and not allow:
        raise RecordingError(f"--reference {ref}: another actuator: its serials {fmt_identity(b)}, this check's "
                             f"{fmt_identity(a)} (--allow-other-serials to compare them anyway)")
    return {"checked": True, "same": same, "recording": fmt_identity(a), "reference": fmt_identity(b),
            "words": "the same actuators" if same else "other actuators, compared as --allow-other-serials says"}


def _key(row: dict, e: str):
    i = row["identity"].get(e)
    return None if i is None else (i["vendor_id"], i["product_code"], i["serial"])


def _earlier(new: Path, url: str) -> tuple:
    """(RUN's history record, the earlier maintenance checks of either of its actuators in time order, the
    masked url); :class:`RecordingError` as :func:`reference_from_history` says."""
    from hil.history.record import load_result, record_from_result
    from hil.history.store import HistoryStore
    from hil.profile.history_url import masked
    res = Path(new) / "result.json"
    if not Path(new).is_dir() or not res.is_file():
        raise RecordingError(f"--reference history: {new} is not a run folder with a result.json (the actuators' "
                             "serials are read from it)")
    me = record_from_result(load_result(res), result_path=res, run_folder=Path(new))
    if any(me.identity.get(e) is None for e in EMAS):
        raise RecordingError(f"--reference history: {res}: the actuators' serials were not read "
                             f"({fmt_identity(me.identity)}); give the reference recording instead")
    store = HistoryStore.open(url, create=False)
    if store is None:
        raise RecordingError(f"--reference history: no wear history at {masked(url)}")
    with store:
        rows = {r["id"]: r for e in EMAS for r in store.checks(serial=me.identity[e][2])}.values()
    here = Path(new).resolve()
    rows = sorted((r for r in rows if r["kind"] == "maint" and bool(r["simulated"]) == bool(me.check["simulated"])
                   and r["run_key"] != me.check["run_key"] and r["time_utc"] < me.check["time_utc"]
                   and r["run_folder"] and Path(r["run_folder"]).resolve() != here
                   and any(_key(r, e) == me.identity[e] for e in EMAS)),
                  key=lambda r: (r["time_utc"], r["id"]))
    if not rows:
        raise RecordingError(f"--reference history: no earlier check of the actuators {fmt_identity(me.identity)} "
                             f"in {masked(url)}")
    return me, rows, masked(url)


def reference_from_history(new: Path, url: str, allow: bool) -> tuple[Path, dict]:
    """(run folder, diagnosis.json's ``reference_history`` entry) of ``--reference history``.

    Raises
    ------
    hil.errors.RecordingError
        RUN is not a run folder with a result.json naming both actuators' serials; no history database;
        no earlier check of either actuator there (or its run folder is gone); the last one's actuators
        differ from RUN's and not ``allow``.
    """
    me, rows, shown = _earlier(new, url)
    last = rows[-1]
    theirs = {e: _key(last, e) for e in EMAS}
    same = all(theirs[e] == me.identity[e] for e in EMAS)
    if not same and not allow:
        raise RecordingError(
            f"--reference history: the last check of these actuators ({last['run_folder']}, "
            f"{last['time_utc']:%Y-%m-%d %H:%M} UTC) had {fmt_identity(theirs)}, this check "
            f"{fmt_identity(me.identity)} (--allow-other-serials to take it anyway)")
    folder = Path(last["run_folder"])
    if not folder.is_dir():
        raise RecordingError(f"--reference history: the run folder of the last check of these actuators is gone: "
                             f"{folder}")
    return folder, {"history": shown, "run_folder": str(folder), "run_id": last["run_id"],
                    "time_utc": last["time_utc"].isoformat(), "serials": fmt_identity(theirs), "same_serials": same,
                    "words": f"the last check of {fmt_identity(me.identity)} before this one in the wear history"
                             + ("" if same else " (other serials, taken as --allow-other-serials says)")}


#: at most this many of the latest healthy checks measure the floors (their pairs: 6)
HEALTHY_MOST = 4


def healthy_checks(new: Path, url: str, most: int = HEALTHY_MOST) -> list:
    """The run folders of the latest earlier checks (at most ``most``) in the wear history that passed
    (``status`` pass) with the same actuators as RUN at both positions and whose run folders are still there,
    oldest first: the healthy checks whose spread measures the floors of ``--reference history``
    (:func:`hil.analysis.diagnose.coverage.dual_floors_from_checks`). Raises as :func:`reference_from_history`."""
    me, rows, _ = _earlier(new, url)
    ok = [Path(r["run_folder"]) for r in rows if r["status"] == "pass"
          and all(_key(r, e) == me.identity[e] for e in EMAS) and Path(r["run_folder"]).is_dir()]
    return ok[-most:]
