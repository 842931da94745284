"""A re-analysis supersedes a result in the history, and both stay (issue 34, part 1): the latest of a
run is ``current``, each later one names the one it ``supersedes``; a version-1 database is migrated
with its rows kept and the marker filled in."""

from __future__ import annotations

import copy
import datetime as _dt
import json

import pytest

from hil.cli import main
from hil.cli.args import ExitCode
from hil.history.record import record_from_result
from hil.history.store import HistoryStore
from support import postgres
from support.wear import wear_results

#: one xdist group for the modules that use this process's PostgreSQL server (support/postgres.py): one
#: worker starts it once per run, not each worker once (docs/testing.md, "Parallel")
pytestmark = pytest.mark.xdist_group("postgresql")


def _results():
    first = wear_results(n=1, simulated=False)[0]
    again = copy.deepcopy(first)  # the same run analysed again an hour later, another reading
    t = _dt.datetime.fromisoformat(first["trace"]["analysed_utc"]) + _dt.timedelta(hours=1)
    again["trace"]["analysed_utc"] = t.isoformat()
    again["backlash_mm"]["int1"] += 0.001
    return first, again


def _doc(url, capsys) -> dict:
    capsys.readouterr()
    assert main(["history", "--history", url, "--json"]) == ExitCode.PASS
    return json.loads(capsys.readouterr().out)


def test_a_re_analysis_keeps_both_and_the_latest_is_current(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    first, again = _results()
    for name, r in (("b.result.json", again), ("a.result.json", first)):  # recorded out of order
        (tmp_path / name).write_text(json.dumps(r))
    assert main(["history", "sync", str(tmp_path / "b.result.json"), "--history", url]) == ExitCode.PASS
    assert main(["history", "sync", str(tmp_path / "a.result.json"), "--history", url]) == ExitCode.PASS
    checks = _doc(url, capsys)["checks"]
    assert len(checks) == 2
    by_int1 = {round(c["backlash_mm"]["int1"], 6): c for c in checks}
    old, new = by_int1[round(first["backlash_mm"]["int1"], 6)], by_int1[round(again["backlash_mm"]["int1"], 6)]
    assert (old["current"], new["current"]) == (False, True)
    assert (old["in_trend"], new["in_trend"]) == (False, True)
    # the later analysis was recorded first: the earlier one, recorded after it, supersedes nothing
    assert new["supersedes"] is None and old["supersedes"] is None
    # a third analysis, the latest: it supersedes the current one
    third = copy.deepcopy(again)
    third["trace"]["analysed_utc"] = (_dt.datetime.fromisoformat(again["trace"]["analysed_utc"])
                                      + _dt.timedelta(hours=1)).isoformat()
    third["backlash_mm"]["int1"] += 0.001
    (tmp_path / "c.result.json").write_text(json.dumps(third))
    assert main(["history", "sync", str(tmp_path / "c.result.json"), "--history", url]) == ExitCode.PASS
    checks = _doc(url, capsys)["checks"]
    cur = [c for c in checks if c["current"]]
    assert len(checks) == 3 and len(cur) == 1 and cur[0]["supersedes"] == new["id"]
    assert main(["history", "--history", url]) == ExitCode.PASS
    assert "3 result(s), 2 superseded by a later analysis of the same run (kept; the latest is current)" in \
        " ".join(capsys.readouterr().out.split())


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    return postgres.history_url(request.param, tmp_path)


def test_a_version_1_database_is_migrated_keeping_its_rows(url, capsys):
    import sqlalchemy as sa

    first, again = _results()
    with HistoryStore.open(url) as store:
        assert [store.add(record_from_result(r)) for r in (first, again)] == [True, True]
    engine = sa.create_engine(url.replace("sqlite://", "sqlite+pysqlite://").replace(
        "postgresql://", "postgresql+psycopg://"))
    with engine.begin() as conn:  # back to what version 1 wrote: no supersedes_id, no version 2
        conn.execute(sa.text("ALTER TABLE emacheck_checks DROP COLUMN supersedes_id"))
        conn.execute(sa.text("DELETE FROM emacheck_schema WHERE version = 2"))
    engine.dispose()
    with HistoryStore.open(url) as store:
        assert store.schema_version() == 2
        rows = store.checks()
    assert len(rows) == 2
    assert [r["supersedes_id"] for r in rows] == [None, rows[0]["id"]]
    checks = _doc(url, capsys)["checks"]
    assert [c["current"] for c in checks] == [False, True]
