"""Two rigs writing to one history at once lose nothing; a writer killed mid-transaction leaves the
database consistent (SQLite and PostgreSQL; tests/support/history_writer.py is the rig)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import sqlalchemy as sa

from hil.history import schema as S
from hil.history.store import HistoryStore
from support import postgres

#: one xdist group for the modules that use this process's PostgreSQL server (support/postgres.py): one
#: worker starts it once per run, not each worker once (docs/testing.md, "Parallel")
pytestmark = pytest.mark.xdist_group("postgresql")

WRITER = Path(__file__).resolve().parent / "support" / "history_writer.py"


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    """An empty history: an SQLite file, or a new database on the test PostgreSQL server."""
    return postgres.history_url(request.param, tmp_path)


def _writer(url: str, tag: str, n: int, batch: int = 1) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(WRITER), url, tag, str(n), str(batch)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _consistent(url: str) -> dict:
    """Counts, and the invariants: every check has its three readings, no reading without its check."""
    store = HistoryStore.open(url, create=False)
    with store, store._tx(write=False) as conn:
        n_checks = conn.execute(sa.select(sa.func.count()).select_from(S.checks)).scalar_one()
        n_read = conn.execute(sa.select(sa.func.count()).select_from(S.readings)).scalar_one()
        partial = conn.execute(sa.select(S.readings.c.check_id).group_by(S.readings.c.check_id)
                               .having(sa.func.count() != 3)).all()
        orphans = conn.execute(sa.select(sa.func.count()).select_from(
            S.readings.outerjoin(S.checks, S.readings.c.check_id == S.checks.c.id)).where(S.checks.c.id.is_(None))
        ).scalar_one()
        if store.dialect == "sqlite":
            assert conn.exec_driver_sql("PRAGMA integrity_check").scalar() == "ok"
        runs = [r for (r,) in conn.execute(sa.select(S.checks.c.run_id))]
    assert n_read == 3 * n_checks and not partial and orphans == 0, (n_checks, n_read, partial, orphans)
    return {"checks": n_checks, "runs": runs}


@pytest.mark.slow
def test_two_writers_at_once_lose_nothing(url):
    """Two processes, 50 checks each, one transaction per check, on a new database (both migrate)."""
    procs = [_writer(url, tag, 50) for tag in ("rigA", "rigB")]
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert "committed 50" in out
    got = _consistent(url)
    assert got["checks"] == 100
    assert sorted(got["runs"]) == sorted(f"{t}-{k:04d}" for t in ("rigA", "rigB") for k in range(50))


@pytest.mark.slow
def test_sigkill_mid_insert_leaves_the_database_consistent(url):
    """A writer recording transactions of 100 checks is killed (SIGKILL) while one is under way: the
    database holds whole transactions only, at least those it reported committed, and takes new writes."""
    HistoryStore.open(url).close()
    p = _writer(url, "killed", 5000, batch=100)
    committed = 0
    deadline = time.monotonic() + 60
    while committed < 300 and time.monotonic() < deadline:
        line = p.stdout.readline()
        if not line:
            break
        committed = int(line.split()[1])
    assert committed >= 300, p.stderr.read()
    time.sleep(0.05)  # into the next transaction
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    p.stdout.close()
    p.stderr.close()
    got = _consistent(url)
    assert got["checks"] >= committed and got["checks"] % 100 == 0, got["checks"]
    w = _writer(url, "after", 3)
    assert w.wait(timeout=60) == 0
    assert _consistent(url)["checks"] == got["checks"] + 3
