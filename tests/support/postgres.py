"""A throwaway PostgreSQL server for the tests and the benchmark: initdb in a temporary directory,
pg_ctl on a Unix socket, password login; one per process, stopped at exit.

Debian's ``postgresql`` package (``.ci/run`` installs it) puts the programs in
``/usr/lib/postgresql/<version>/bin``. initdb and the server refuse to run as
root: as root they run as the ``postgres`` system user (the package creates
it), else ``nobody``, in a directory under /tmp made for them (pytest's own
temporary directories are private to root). Where no server can be started,
:func:`server` raises :class:`Unavailable` with the reason, for a skip that
says it.
"""

from __future__ import annotations

import atexit
import glob
import os
import pwd
import secrets
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = ["PgServer", "Unavailable", "server", "find_bindir"]


class Unavailable(RuntimeError):
    """No PostgreSQL server could be started here (the message says why)."""


def find_bindir() -> Path | None:
    """The directory of initdb and pg_ctl: Debian's newest /usr/lib/postgresql/*/bin, else PATH."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                   key=lambda p: [int(x) if x.isdigit() else 0 for x in Path(p).parts[-3].split(".")])
    if found:
        return Path(found[-1]).parent
    which = shutil.which("initdb")
    return Path(which).parent if which else None


def _run_as() -> tuple[str | None, int | None, int | None]:
    """(user, uid, gid) to run the server as: None when not root (run as oneself)."""
    if os.geteuid() != 0:
        return None, None, None
    for name in ("postgres", "nobody"):
        try:
            pw = pwd.getpwnam(name)
        except KeyError:
            continue
        return name, pw.pw_uid, pw.pw_gid
    raise Unavailable("running as root and neither a 'postgres' nor a 'nobody' user exists to run initdb as")


@dataclass
class PgServer:
    """A running server: ``url(database)`` gives a ``postgresql://`` URL over its Unix socket."""

    base: Path
    bindir: Path
    user: str | None
    password: str
    role: str = "emacheck"

    def url(self, database: str = "postgres", password: str | None = None) -> str:
        pw = self.password if password is None else password
        return f"postgresql://{self.role}:{pw}@/{database}?host={self.base}"

    def _run(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run([str(self.bindir / args[0]), *args[1:]], capture_output=True, text=True,
                              timeout=timeout, user=self.user, cwd=self.base)

    def new_database(self, name: str | None = None) -> str:
        """Create an empty database; returns its URL."""
        import psycopg

        name = name or f"t_{secrets.token_hex(6)}"
        with psycopg.connect(host=str(self.base), user=self.role, password=self.password, dbname="postgres",
                             autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def stop(self) -> None:
        try:
            self._run("pg_ctl", "-D", str(self.base / "data"), "-m", "immediate", "-w", "stop", timeout=30)
        finally:
            shutil.rmtree(self.base, ignore_errors=True)


def start(*, durable: bool = False) -> PgServer:
    """Start a new server (``durable``: fsync on, as a station runs it; else off, for speed)."""
    bindir = find_bindir()
    if bindir is None or not (bindir / "pg_ctl").exists():
        raise Unavailable("PostgreSQL's initdb/pg_ctl not found (Debian: apt-get install postgresql)")
    try:
        import psycopg  # noqa: F401
    except ImportError as exc:
        raise Unavailable(f"psycopg is not installed ({exc})") from None
    user, uid, gid = _run_as()
    base = Path(tempfile.mkdtemp(prefix="emacheck-pg-", dir="/tmp"))
    password = secrets.token_hex(12)
    srv = PgServer(base, bindir, user, password)
    try:
        (base / "pw").write_text(password + "\n")
        if uid is not None:
            os.chown(base, uid, gid)
            os.chown(base / "pw", uid, gid)
        r = srv._run("initdb", "-D", str(base / "data"), "-U", srv.role, "--auth-local=scram-sha-256",
                     "--auth-host=scram-sha-256", "--pwfile", str(base / "pw"), "-E", "UTF8", "--no-sync")
        if r.returncode != 0:
            raise Unavailable(f"initdb failed (as {user or 'this user'}): {(r.stderr or r.stdout).strip()[-400:]}")
        opts = f"-k {base} -c listen_addresses='' -c max_connections=60"
        if not durable:
            opts += " -c fsync=off -c synchronous_commit=off -c full_page_writes=off"
        r = srv._run("pg_ctl", "-D", str(base / "data"), "-l", str(base / "log"), "-w", "-t", "60", "-o", opts,
                     "start", timeout=90)
        if r.returncode != 0:
            log = (base / "log").read_text()[-400:] if (base / "log").exists() else ""
            raise Unavailable(f"pg_ctl start failed: {(r.stderr or r.stdout).strip()[-300:]} {log}")
    except (Unavailable, OSError, subprocess.SubprocessError) as exc:
        shutil.rmtree(base, ignore_errors=True)
        if isinstance(exc, Unavailable):
            raise
        raise Unavailable(f"PostgreSQL could not be started: {type(exc).__name__}: {exc}") from None
    return srv


_SERVER: PgServer | None = None
_FAILED: str | None = None


def server() -> PgServer:
    """This process's test server, started on first use and stopped at exit; :class:`Unavailable`
    (with the reason) where none can be started."""
    global _SERVER, _FAILED
    if _SERVER is None and _FAILED is None:
        try:
            _SERVER = start()
            atexit.register(_SERVER.stop)
        except Unavailable as exc:
            _FAILED = str(exc)
    if _SERVER is None:
        raise Unavailable(_FAILED)
    return _SERVER


def history_url(kind: str, tmp_path: Path) -> str:
    """An empty history for a test: ``kind`` "sqlite" (a file in ``tmp_path``) or "postgresql" (a new
    database on the test server; the test is skipped with the reason where none can be started)."""
    if kind == "sqlite":
        return f"sqlite:///{tmp_path}/history.sqlite"
    from support.ci import skip_or_fail

    try:
        return server().new_database()
    except Unavailable as exc:
        skip_or_fail(f"PostgreSQL server not available: {exc}")
