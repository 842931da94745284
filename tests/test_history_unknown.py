"""Results without an identity are never trended together (issue 47): eight bare CSVs analysed and recorded
under actuator "unknown" were trended as one actuator ("-0.0001 +- 479 mm/year"). Now a reading whose
actuator's identity is unknown is recorded and listed, in no series, and `emacheck history` says why."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

from hil.cli import main
from hil.history.record import record_from_result, unidentified
from hil.history.store import HistoryStore
from hil.history.trends import MIN_POINTS, NO_IDENTITY, build_series, history_document
from support.wear import wear_results

SCHEMA = json.loads((Path(__file__).resolve().parents[1] / "hil" / "schemas" / "history.schema.json").read_text())


def _bare(results: list[dict], keep: tuple[str, ...] = ()) -> list[dict]:
    """The results as analyses of bare recordings: no run id, each its own recording, identity only of ``keep``."""
    for k, r in enumerate(results):
        t = r["trace"]
        t["run_id"], t["recording"], t["mode"] = None, f"flight{k}.csv", None
        t["identity"] = {e: v for e, v in t["identity"].items() if e in keep}
    return results


def _record(url: str, results: list[dict]) -> list[dict]:
    with HistoryStore.open(url) as store:
        for k, r in enumerate(results):
            assert store.add(record_from_result(r, recording_sha256=f"{k:064x}"))
        return store.checks()


def test_eight_bare_csvs_give_no_trend_and_the_history_says_why(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    results = _bare(wear_results(n=8, simulated=False))
    assert all(unidentified(r) == ["ema1", "ema2"] for r in results)
    rows = _record(url, results)
    assert len(rows) == 8 and all(r["status"] in ("pass", "fail", "inconclusive") for r in rows)
    assert build_series(rows) == []
    doc = history_document(rows, build_series(rows), url=url, filters={})
    jsonschema.validate(doc, SCHEMA)
    assert doc["trends"] == [] and not any(c["in_trend"] for c in doc["checks"])
    assert all(c["not_trended"] == f"int1, int2, ext: {NO_IDENTITY}" for c in doc["checks"])
    assert main(["history", "--history", url]) == 0
    out = capsys.readouterr().out.replace("\n", " ")
    assert "8 result(s) in no trend: the actuator's identity is unknown" in out
    assert "'unknown' is not an actuator" in out and "flight7.csv" in out
    # history.html says it too: a table of the results in no trend, each with its recording and why
    assert main(["history", "--history", url, "--out", str(tmp_path / "h")]) == 0
    html = (tmp_path / "h" / "history.html").read_text()
    assert "<h2>In no trend</h2><p>8 result(s): the actuator&#x27;s identity is unknown" in html
    assert all(f"flight{k}.csv" in html for k in range(8)) and html.count("int1, int2, ext: the actuator") == 8


def test_a_known_actuator_is_trended_and_its_unknown_partner_is_not(tmp_path):
    """EMA 1's identity read, EMA 2's not: int1 is EMA 1's trend; int2 and ext (which need EMA 2) are in none."""
    rows = _record(f"sqlite:///{tmp_path / 'h.sqlite'}", _bare(wear_results(n=8, simulated=False), keep=("ema1",)))
    series = build_series(rows)
    assert [(s.channel, s.serial, len(s.points)) for s in series] == [("int1", 0x5E000101, 8)]
    assert series[0].segments[-1].fit is not None
    doc = history_document(rows, series, url="x", filters={})
    assert all(c["in_trend"] and c["not_trended"] == f"int2, ext: {NO_IDENTITY}" for c in doc["checks"])


@pytest.mark.parametrize("n", [MIN_POINTS, 8])
def test_the_same_results_with_their_identity_are_trended(tmp_path, n):
    """The control: the same results with both serials give a trend per channel (so the rule above, not too
    few points, is what keeps the bare ones out)."""
    results = wear_results(n=n, simulated=False)
    for k, r in enumerate(results):
        r["trace"]["run_id"] = None
        r["trace"]["recording"] = f"flight{k}.csv"
    series = build_series(_record(f"sqlite:///{tmp_path / 'h.sqlite'}", results))
    assert sorted(s.channel for s in series) == ["ext", "int1", "int2"]
    assert all(len(s.points) == n and s.segments[-1].fit is not None for s in series)


def test_recording_a_bare_result_says_it_joins_no_trend(tmp_path):
    from hil.history.sync import record_after_check

    [res] = _bare(wear_results(n=1, simulated=False))
    path = tmp_path / "flight0.result.json"
    path.write_text(json.dumps(res))
    said = []
    assert record_after_check(f"sqlite:///{tmp_path / 'h.sqlite'}", path, run_folder=None, recording=None,
                              say=said.append)
    assert said == [f"recorded in the history sqlite:///{tmp_path / 'h.sqlite'}; in no trend: the identity of ema1 "
                    "and ema2 is unknown (not an actuator)"]


@pytest.mark.slow
def test_bare_csvs_analysed_and_recorded_give_no_trend_end_to_end(dry_run, tmp_path, capsys):
    """The issue's way: copies of a check's signals.csv analysed as bare files into one history (each its own
    recording: one sample's last digit changed) at growing flight hours: recorded, listed, no trend."""
    run, _ = dry_run
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    lines = (run / "signals.csv").read_text().splitlines()
    for k in range(MIN_POINTS):
        csv = tmp_path / f"flight{k}.csv"
        row, f2 = lines[100].split(","), lines[0].split(",").index("F2")
        row[f2] = row[f2][:-1] + str(k)  # F2's last digit: another file, the same check to within 0.01 N
        csv.write_text("\n".join(lines[:100] + [",".join(row)] + lines[101:]) + "\n")
        assert main(["analyze", str(csv), "--history", url, "--flight-hours", str(1000 * (k + 1))]) == 0
        assert "in no trend: the identity of ema1 and ema2 is unknown" in capsys.readouterr().out
    assert main(["history", "--history", url, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["checks"]) == MIN_POINTS and doc["trends"] == []
    assert all(c["not_trended"] == f"int1, int2, ext: {NO_IDENTITY}" and not c["in_trend"] for c in doc["checks"])
