"""The wear history (hil/history, `emacheck history`): the same tests on SQLite and on a real PostgreSQL
server started here (tests/support/postgres.py; skipped with the reason where none can be started).

The wear scenario: 12 simulated checks of one pair over 3000 flight hours (tests/support/wear.py: the
simulated rig's wear line and scatter, readings with the uncertainty BLFmaint states) recorded from
their run folders; `emacheck history --json` must find each channel's rate within its interval and
the crossing of B_spec within its interval. The same through the plant and BLFmaint, 20 seeds:
tests/bench/bench_history.py.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
from pathlib import Path

import jsonschema
import pytest

from hil.cli import main
from hil.history.record import record_from_result
from hil.history.store import HistoryStore
from hil.profile.config import Actuation
from hil.profile.load import load_actuation
from support import postgres
from support.ci import skip_or_fail
from support.wear import SERIALS, true_crossing_fh, wear_results

#: one xdist group for the modules that use this process's PostgreSQL server (support/postgres.py): one
#: worker starts it once per run, not each worker once (docs/testing.md, "Parallel")
pytestmark = pytest.mark.xdist_group("postgresql")

SCHEMA = json.loads((Path(__file__).resolve().parents[1] / "hil" / "schemas" / "history.schema.json").read_text())


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    """An empty history: an SQLite file, or a new database on the test PostgreSQL server."""
    return postgres.history_url(request.param, tmp_path)


def write_runs(tmp_path: Path, results: list[dict], name: str = "run") -> list[Path]:
    """Each result as a run folder (meta.json with its run id, result.json)."""
    out = []
    for k, r in enumerate(results):
        d = tmp_path / f"{name}{k:02d}"
        d.mkdir(parents=True)
        (d / "meta.json").write_text(json.dumps({"run_id": r["trace"]["run_id"], "status": "done"}))
        (d / "result.json").write_text(json.dumps(r))
        out.append(d)
    return out


def history_json(capsys, url: str, *args: str) -> dict:
    capsys.readouterr()
    assert main(["history", "--history", url, "--json", *args]) == 0
    doc = json.loads(capsys.readouterr().out)
    jsonschema.validate(doc, SCHEMA)
    return doc


def trend(doc: dict, channel: str, *, current: bool = True) -> dict:
    [t] = [t for t in doc["trends"] if t["channel"] == channel and t["current"] == current]
    return t


def test_wear_scenario_rate_and_crossing_within_their_intervals(url, tmp_path, capsys):
    """12 simulated checks of one pair over 3000 FH, recorded with `history sync`, then `history --json`."""
    runs = write_runs(tmp_path, wear_results(n=12, fh_max=3000.0, seed=1))
    assert main(["history", "sync", *map(str, runs), "--history", url]) == 0
    doc = history_json(capsys, url, "--actuator", f"0x{SERIALS[0]:08X}")
    assert len(doc["checks"]) == 12 and all(c["simulated"] and c["in_trend"] for c in doc["checks"])
    assert [c["flight_hours"] for c in doc["checks"]] == sorted(c["flight_hours"] for c in doc["checks"])
    c0 = doc["checks"][0]
    assert c0["identity"]["ema1"]["serial"] == SERIALS[0] and c0["identity"]["ema2"]["serial"] == SERIALS[1]
    assert set(c0["backlash_mm"]) == {"int1", "int2", "ext"} and c0["uncertainty_mm"]["int1"] == 0.0058
    assert {t["channel"] for t in doc["trends"]} == {"int1", "ext"}  # EMA 1's own channel and its pair's
    for ch, rate in (("int1", 0.025), ("ext", 0.010)):
        t = trend(doc, ch)
        assert t["simulated"] and t["n"] == 12 and t["axis"] == "flight_hours" and t["limit_mm"] == 0.2
        lo, hi = t["rate_interval_95"]
        assert lo <= rate <= hi, (ch, t)
        assert hi - lo < 0.6 * rate  # and it says something
        flo, fhi = t["limit_at_fh_interval"]
        assert flo <= true_crossing_fh(ch, 0.2) <= fhi, (ch, t)
        assert flo < t["limit_at_fh"] < fhi and t["limit_at_fh"] > 3000.0
        # the date at the recorded utilisation: 3000 FH over 330 days
        assert t["utilisation_fh_per_day"] == pytest.approx(3000.0 / 330.0)
        assert t["limit_at_date_interval"][0] <= t["limit_at_date"] <= t["limit_at_date_interval"][1]
    assert trend(doc, "int1")["pair"] == {"ema1": SERIALS[0], "ema2": SERIALS[1]}
    assert main(["history", "--history", url]) == 0
    out = capsys.readouterr().out
    assert "D-AXYZ, left aileron [simulated]" in out and "0x5E000102" in out and "mm/1000 FH" in out


def test_every_result_kept_once_and_one_reading_per_run(url, tmp_path, capsys):
    """Sync is idempotent (by the result's hash); a re-analysis of a run is kept, but the trend takes the
    latest analysis of each run once; the record holds what the issue lists."""
    results = wear_results(n=4, fh_max=900.0, seed=2, simulated=False)
    runs = write_runs(tmp_path, results)
    assert main(["history", "sync", *map(str, runs), "--history", url]) == 0
    assert "4 result(s) recorded, 0 already there" in capsys.readouterr().out
    assert main(["history", "sync", *map(str, runs), "--history", url]) == 0
    assert "0 result(s) recorded, 4 already there" in capsys.readouterr().out
    again = dict(results[3], trace=dict(results[3]["trace"], analysed_utc="2026-01-01T00:00:00+00:00"))
    again["backlash_mm"] = dict(again["backlash_mm"], int1=again["backlash_mm"]["int1"] + 0.001)
    sub = runs[3] / "analysis-20260101T000000Z"
    sub.mkdir()
    (sub / "result.json").write_text(json.dumps(again))
    assert main(["history", "sync", str(runs[3]), "--history", url]) == 0
    assert "1 result(s) recorded, 1 already there" in capsys.readouterr().out
    doc = history_json(capsys, url)
    assert len(doc["checks"]) == 5 and sum(c["in_trend"] for c in doc["checks"]) == 4
    assert trend(doc, "int1")["n"] == 4 and not trend(doc, "int1")["simulated"]
    latest = [c for c in doc["checks"] if c["run_id"] == results[3]["trace"]["run_id"] and c["in_trend"]]
    assert latest[0]["backlash_mm"]["int1"] == pytest.approx(results[3]["backlash_mm"]["int1"] + 0.001)
    with HistoryStore.open(url) as store:
        first = str((runs[0] / "result.json").resolve())
        [row] = [r for r in store.checks(aircraft="D-AXYZ") if r["result_path"] == first]
    assert row["run_folder"] == str(runs[0].resolve()) and row["operator"] == "A. Inspector"
    assert row["work_order"] == "WO-4700" and row["flight_cycles"] == 0 and row["rig"] == "rig-1"
    assert row["position"] == "left aileron" and row["ema1_lvdt_pitch"] == 1.075 and row["software_version"] == "0.1.0"
    assert row["readings"]["int1"]["stiffness_left_N_per_mm"] == 8.0e4 and row["readings"]["ext"]["verdict"] == "pass"
    assert row["identity"]["ema2"]["revision"] == load_actuation().canopen.revision_min


def test_a_repair_and_a_new_actuator_start_new_trends(url, tmp_path, capsys):
    """Backlash drops (EMA 1 repaired at 1500 FH) or another serial at the position (EMA 2 replaced)."""
    before = wear_results(n=6, fh_max=1500.0, seed=3, simulated=False)
    after = wear_results(n=5, fh0=1800.0, fh_max=3000.0, seed=4, simulated=False, serials=(SERIALS[0], 0x5E0009FF),
                         start=before[-1] and __import__("datetime").datetime(2025, 8, 1))
    for r in after:  # the repaired EMA 1 starts again near the new-part backlash
        r["backlash_mm"]["int1"] -= 0.045
        r["verdict"]["int1"]["backlash_mm"] = r["backlash_mm"]["int1"]
    with HistoryStore.open(url) as store:
        assert store.add_many([record_from_result(r) for r in before + after]) == 11
    doc = history_json(capsys, url)
    int1 = [t for t in doc["trends"] if t["channel"] == "int1"]
    assert [(t["segment"], t["n"], t["current"]) for t in int1] == [(0, 6, False), (1, 5, True)]
    assert int1[0]["limit_at_fh"] is None and "repair" in int1[0]["reason"] and int1[1]["limit_at_fh"] > 3000
    int2 = {t["serial"]: t for t in doc["trends"] if t["channel"] == "int2"}
    assert set(int2) == {SERIALS[1], 0x5E0009FF} and int2[0x5E0009FF]["n"] == 5
    ext = [t for t in doc["trends"] if t["channel"] == "ext"]
    assert sorted(t["pair"]["ema2"] for t in ext) == sorted([SERIALS[1], 0x5E0009FF])


def test_simulated_checks_never_mix_into_a_real_trend(url, capsys):
    real = wear_results(n=4, fh_max=1200.0, seed=5, simulated=False)
    sim = wear_results(n=4, fh_max=1200.0, seed=6, simulated=True)
    with HistoryStore.open(url) as store:
        store.add_many([record_from_result(r) for r in real + sim])
    doc = history_json(capsys, url, "--actuator", str(SERIALS[0]))
    t = [x for x in doc["trends"] if x["channel"] == "int1"]
    assert sorted((x["simulated"], x["n"]) for x in t) == [(False, 4), (True, 4)]


def test_calendar_time_where_flight_hours_are_missing(url, capsys):
    results = wear_results(n=5, fh_max=1200.0, seed=7, simulated=False)
    for r in results[2:]:
        r["trace"]["flight_hours"] = None
    with HistoryStore.open(url) as store:
        store.add_many([record_from_result(r) for r in results])
    t = trend(history_json(capsys, url), "int1")
    assert t["axis"] == "calendar_days" and t["rate_mm_per_1000_fh"] is None and t["rate_unit"] == "mm/year"
    assert t["rate_mm_per_year"] > 0 and t["limit_at_date"] and t["limit_at_fh"] is None
    assert "calendar" in t["reason"]


def test_history_page_and_console(url, tmp_path, capsys):
    with HistoryStore.open(url) as store:
        store.add_many([record_from_result(r) for r in wear_results(n=6, fh_max=1500.0, seed=8, simulated=False)])
    assert main(["history", "--history", url, "--aircraft", "D-AXYZ", "--out", str(tmp_path / "h")]) == 0
    out = capsys.readouterr().out
    assert "Wear trends" in out and "0x5E000101" in out and "mm/1000 FH" in out and "history.html" in out
    page = (tmp_path / "h" / "history.html").read_text()
    assert page.count("<img src='data:image/png;base64,") == 3  # int1, int2, ext of the pair
    assert "B_spec [mm]" in page and "backlash [mm]" in page and "history.json" in page
    jsonschema.validate(json.loads((tmp_path / "h" / "history.json").read_text()), SCHEMA)


def test_an_empty_or_missing_history_is_no_error(tmp_path, capsys):
    url = f"sqlite:///{tmp_path}/none.sqlite"
    assert main(["history", "--history", url]) == 0
    assert "no checks recorded yet" in capsys.readouterr().out and not (tmp_path / "none.sqlite").exists()
    assert history_json(capsys, url)["checks"] == []


# ----------------------------------------------------------------------------- when the database is not there


def test_corrupt_sqlite_file_is_one_line_exit_3(tmp_path, capsys):
    bad = tmp_path / "h.sqlite"
    bad.write_bytes(b"this is not an SQLite database, just text " * 100)
    assert main(["history", "--history", f"sqlite:///{bad}"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "not an SQLite database or corrupt" in err and str(bad) in err


def test_locked_sqlite_file_is_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "h.sqlite"
    run = write_runs(tmp_path, wear_results(n=1, seed=9, simulated=False))[0]
    HistoryStore.open(f"sqlite:///{path}").close()
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")  # another program holds the write lock
    try:
        assert main(["history", "sync", str(run), "--history", f"sqlite:///{path}?timeout=0.2"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "locked by another program" in err
        assert main(["history", "--history", f"sqlite:///{path}?timeout=0.2"]) == 0  # readers still read (WAL)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert main(["history", "sync", str(run), "--history", f"sqlite:///{path}"]) == 0


def test_refused_postgresql_login_and_unreachable_server(tmp_path, capsys):
    try:
        srv = postgres.server()
    except postgres.Unavailable as exc:
        skip_or_fail(f"PostgreSQL server not available: {exc}")
    bad = srv.url("postgres", password="wrong-password")
    assert main(["history", "--history", bad]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "login refused" in err and "wrong-password" not in err and ":***@" in err
    down = f"postgresql://emacheck:pw@/emacheck?host={tmp_path}"  # no server on this socket
    assert main(["history", "--history", down]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "cannot reach the database server" in err


@pytest.mark.parametrize("arg, words", [
    ("history.sqlite", "is not a database URL"), ("sqlite://", "needs a file"), ("mysql://h/db", "unknown database"),
    ("postgresql://host", "name the database")])
def test_bad_history_url_is_exit_3_before_anything(arg, words, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "--interface", "virtual", "--channel", "x", "--arm", "--history", arg])
    assert exc.value.code == 3 and words in capsys.readouterr().err


def test_a_newer_schema_is_refused(tmp_path, capsys):
    path = tmp_path / "h.sqlite"
    HistoryStore.open(f"sqlite:///{path}").close()
    with sqlite3.connect(path) as db:
        db.execute("INSERT INTO emacheck_schema VALUES (99, 'future', '2030-01-01 00:00:00', 'emacheck 9')")
    assert main(["history", "--history", f"sqlite:///{path}"]) == 3
    assert "schema version 99 was written by a newer emacheck" in capsys.readouterr().err


def test_recording_after_a_check_never_changes_its_outcome_and_sync_records_it_later(url, tmp_path, capsys):
    """The hook the commands call after writing a result: a database that is down prints one line; the
    result stays; `history sync` records it exactly once. A simulated result is recorded only when asked."""
    from hil.cli.console import make_console
    from hil.cli.history_glue import record_history

    real, sim = wear_results(n=1, seed=10, simulated=False)[0], wear_results(n=1, seed=11)[0]
    [run_real, run_sim] = write_runs(tmp_path, [real]) + write_runs(tmp_path, [sim], name="sim")
    act = load_actuation()
    console = make_console()
    down = f"postgresql://emacheck:pw@/emacheck?host={tmp_path}"
    ns = argparse.Namespace(history=down, no_history=False)
    record_history(console, ns, act, run_real / "result.json", run_folder=run_real)
    out = capsys.readouterr().out
    assert "NOT recorded in the history" in out and f"emacheck history sync {run_real}" in out
    record_history(console, argparse.Namespace(history=url, no_history=True), act, run_real / "result.json",
                   run_folder=run_real)
    record_history(console, argparse.Namespace(history=None), _with_url(act, url), run_sim / "result.json",
                   run_folder=run_sim)  # simulated, no --history: not recorded
    assert capsys.readouterr().out == ""
    record_history(console, argparse.Namespace(history=True), _with_url(act, url), run_sim / "result.json",
                   run_folder=run_sim)  # --history alone: the profile's history.url
    assert "recorded in the history" in capsys.readouterr().out
    assert main(["history", "sync", str(run_real), str(run_sim), "--history", url]) == 0
    assert "1 result(s) recorded, 1 already there" in capsys.readouterr().out
    with HistoryStore.open(url) as store:
        assert store.count() == 2


def _with_url(act: Actuation, url: str) -> Actuation:
    import dataclasses

    return dataclasses.replace(act, history=dataclasses.replace(act.history, url=url))


def test_profile_history_fields_are_validated(tmp_path):
    from hil.errors import ProfileError
    from support.profiles import write_profile_variant

    p = write_profile_variant("actuation.toml", tmp_path / "a.toml", {"history": {"url": "mysql://x/y"}})
    with pytest.raises(ProfileError, match=r"a.toml: field 'history.url': 'mysql://x/y': unknown database scheme"):
        load_actuation(p)
    p = write_profile_variant("actuation.toml", tmp_path / "b.toml", {"history": {"aircraft": "D-AXYZ"}})
    assert load_actuation(p).history.aircraft == "D-AXYZ"


def test_a_lock_the_busy_timeout_does_not_cover_is_retried_within_it(tmp_path):
    # switching a new file to WAL, or WAL recovery after another process closed the last connection,
    # can answer "database is locked" at once; the store retries such a start within the busy timeout
    import sqlalchemy as sa

    path = tmp_path / "h.sqlite"
    store = HistoryStore.open(f"sqlite:///{path}")
    refusals = {"left": 3, "seen": 0}

    @sa.event.listens_for(store._engine, "connect")
    def _refuse(dbapi_conn, _record):
        if refusals["left"] > 0:
            refusals["left"] -= 1
            refusals["seen"] += 1
            raise sqlite3.OperationalError("database is locked")

    try:
        assert store.schema_version() >= 1
        assert refusals == {"left": 0, "seen": 3}
    finally:
        store.close()
    # always refused: given up after the URL's own busy timeout, as one HistoryUnavailableError
    from hil.errors import HistoryUnavailableError
    store = HistoryStore.open(f"sqlite:///{path}?timeout=0.3")
    assert store.timeout_s == 0.3
    sa.event.listen(store._engine, "connect",
                    lambda *_: (_ for _ in ()).throw(sqlite3.OperationalError("database is locked")))
    try:
        with pytest.raises(HistoryUnavailableError, match="waited 0.3 s"):
            store.schema_version()
    finally:
        store.close()


def test_a_timeout_in_the_url_that_is_not_seconds_is_exit_3(tmp_path, capsys):
    HistoryStore.open(f"sqlite:///{tmp_path / 'h.sqlite'}").close()
    assert main(["history", "--history", f"sqlite:///{tmp_path / 'h.sqlite'}?timeout=soon"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "timeout='soon'" in err
