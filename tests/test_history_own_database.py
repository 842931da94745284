"""The history writes only to its own database (issue 34, part 2).

Another program's SQLite file stays byte-identical (SHA-256) whatever emacheck is asked to do with it:
``history`` (a read) and ``analyze`` / ``history sync`` (writers) refuse it with exit 3 naming it. A
missing or empty file is made into a history only by a command that records, never by ``history``.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3

import pytest

from hil.cli import main
from hil.cli.args import ExitCode
from hil.errors import HistoryInputError
from hil.history.store import HistoryStore
from support.wear import wear_results


def sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture()
def foreign(tmp_path):
    """Another program's SQLite database (one table, one row)."""
    path = tmp_path / "other.db"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE invoices (id INTEGER PRIMARY KEY, amount REAL)")
    conn.execute("INSERT INTO invoices (amount) VALUES (12.5)")
    conn.commit()
    conn.close()
    return path


@pytest.fixture()
def result_file(tmp_path):
    path = tmp_path / "r.result.json"
    path.write_text(json.dumps(wear_results(n=1, simulated=False)[0]))
    return path


def test_history_of_a_foreign_database_is_refused_and_leaves_it_byte_identical(foreign, tmp_path, capsys):
    before = sha(foreign)
    rc = main(["history", "--history", f"sqlite:///{foreign}"])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and sha(foreign) == before
    assert f"{foreign} holds another program's tables (invoices) and no emacheck_schema" in err
    assert err.count("\n") == 1
    assert sorted(os.listdir(tmp_path)) == ["other.db"]  # no journal, no -wal, no -shm beside it


def test_a_writer_refuses_a_foreign_database_before_it_writes_anything(foreign, result_file, tmp_path, capsys):
    before = sha(foreign)
    url = f"sqlite:///{foreign}"
    assert main(["history", "sync", str(result_file), "--history", url]) == ExitCode.INPUT
    assert "another program's tables" in capsys.readouterr().err and sha(foreign) == before
    # analyze is refused before the analysis: nothing written beside the recording either
    csv = tmp_path / "flight.csv"
    csv.write_text("t,phi1,phi2,s1,s2,F1,F2\n0.002,0,0,0,0,0,0\n0.004,0,0,0,0,0,0\n")
    rc = main(["analyze", str(csv), "--history", url])
    err = capsys.readouterr().err
    assert rc == ExitCode.INPUT and sha(foreign) == before and "another program's tables" in err
    assert sorted(os.listdir(tmp_path)) == ["flight.csv", "other.db", "r.result.json"]
    with pytest.raises(HistoryInputError, match="not an emacheck history"):
        HistoryStore.open(url)
    assert sha(foreign) == before


def test_history_never_creates_a_missing_or_empty_file_a_writer_does(result_file, tmp_path, capsys):
    missing = tmp_path / "sub" / "h.sqlite"
    assert main(["history", "--history", f"sqlite:///{missing}"]) == ExitCode.PASS
    assert "no checks recorded yet" in capsys.readouterr().out and not missing.parent.exists()
    empty = tmp_path / "empty.sqlite"
    empty.write_bytes(b"")  # the boundary: an empty file is not a foreign database, and not written by a read
    assert main(["history", "--history", f"sqlite:///{empty}"]) == ExitCode.PASS
    assert empty.read_bytes() == b"" and sorted(os.listdir(tmp_path)) == ["empty.sqlite", "r.result.json"]
    assert main(["history", "sync", str(result_file), "--history", f"sqlite:///{empty}"]) == ExitCode.PASS
    with HistoryStore.open(f"sqlite:///{empty}", create=False) as store:
        assert store.count() == 1


def test_an_emacheck_table_without_its_version_is_not_ours(tmp_path):
    path = tmp_path / "half.db"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE emacheck_checks (id INTEGER PRIMARY KEY)")
    conn.commit()
    conn.close()
    before = sha(path)
    with pytest.raises(HistoryInputError, match=r"holds another program's tables \(emacheck_checks\)"):
        HistoryStore.open(f"sqlite:///{path}")
    assert sha(path) == before
