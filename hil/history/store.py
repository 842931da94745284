"""The history database: open (and migrate), add a check, read the checks back.

One class, :class:`HistoryStore`, over SQLAlchemy Core for both SQLite (the
default, one file) and PostgreSQL (psycopg 3, a station's shared server).
Every write is one transaction: a check and its readings are recorded
together or not at all, two rigs writing at once both land (SQLite takes its
write lock at ``BEGIN IMMEDIATE`` and waits up to the busy timeout;
PostgreSQL serialises the unique result key), and a writer killed mid-insert
leaves the database as it was before that check. A result already recorded
(same SHA-256) is not recorded again.

Errors come out as :class:`hil.errors.HistoryInputError` (exit 3: a
corrupt or foreign SQLite file, a refused login, a schema newer than this
emacheck) or :class:`hil.errors.HistoryUnavailableError` (exit 2:
server down or unreachable, SQLite file locked), each one line naming the
database with its password hidden.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import time
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa
from sqlalchemy import exc as sa_exc

from hil import __version__
from hil.errors import HistoryError, HistoryInputError, HistoryUnavailableError
from hil.history import guard
from hil.history import schema as S
from hil.history.record import rank
from hil.profile.history_url import check_url, dialect, masked, sqlite_path

if TYPE_CHECKING:  # (record imports no store)
    from hil.history.record import CheckRecord

#: how long a write waits for another writer's lock (SQLite busy timeout) or a server to answer [s]
DEFAULT_TIMEOUT_S = 10.0
#: PostgreSQL advisory lock key held while migrating (any constant; "emacheck" in ASCII)
_PG_LOCK_KEY = 0x656D6163686563
_CHUNK = 500  # ids per IN (...) list


def _utcnow() -> _dt.datetime:
    return _dt.datetime.now(_dt.UTC).replace(tzinfo=None, microsecond=0)


class HistoryStore:
    """An open history database.

    Parameters
    ----------
    url : str
        ``sqlite:///PATH`` or ``postgresql://...`` (:func:`hil.profile.history_url.check_url`).
    timeout_s : float, optional
        SQLite busy timeout and PostgreSQL connect timeout [s], unless the URL
        sets its own (``?timeout=`` for SQLite, ``?connect_timeout=`` for PostgreSQL).

    Use :meth:`open` (which also migrates); close with :meth:`close` or ``with``.
    """

    def __init__(self, url: str, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        self.url = check_url(url)
        self.dialect = dialect(self.url)
        self.shown = masked(self.url)
        self.timeout_s = float(timeout_s)
        self._engine = self._make_engine()

    # ------------------------------------------------------------------ opening

    @classmethod
    def open(cls, url: str, *, create: bool = True, timeout_s: float = DEFAULT_TIMEOUT_S) -> HistoryStore | None:
        """Connect and bring the schema to :data:`hil.history.schema.LATEST`.

        A database that is not emacheck's is refused (:class:`HistoryInputError`) and left as it was:
        an SQLite file holding other tables and no ``emacheck_schema`` (:mod:`hil.history.guard`, before
        any connection), a database holding ``emacheck_`` tables without their version. With
        ``create=False`` (a read: ``emacheck history``) nothing is made or changed where nothing was
        recorded yet: an SQLite file that does not exist or is empty, a server database without
        emacheck's tables; None is returned.
        """
        url = check_url(url)
        if dialect(url) == "sqlite":
            path = sqlite_path(url)
            kind = guard.refuse_foreign(url)
            if kind in (guard.MISSING, guard.EMPTY) and not create:
                return None
            if kind == guard.MISSING:
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise HistoryInputError(f"history {masked(url)}: cannot create the folder {path.parent}: "
                                            f"{exc.strerror or exc}") from None
        store = cls(url, timeout_s=timeout_s)
        try:
            if not create and store.schema_version() == 0:
                store.close()
                return None
            store.migrate()
        except BaseException:
            store.close()
            raise
        return store

    def _make_engine(self) -> sa.Engine:
        from sqlalchemy.pool import NullPool

        u = sa.engine.make_url(self.url)
        if self.dialect == "sqlite":
            u = u.set(drivername="sqlite+pysqlite")
            if "timeout" in u.query:  # the URL's own busy timeout
                raw = u.query["timeout"]
                try:
                    t = float(raw if isinstance(raw, str) else raw[-1])
                except (TypeError, ValueError, IndexError):
                    t = float("nan")
                if not (0.0 <= t < float("inf")):
                    raise HistoryInputError(f"history {self.shown}: timeout={raw!r} in the URL is not a number of "
                                            f"seconds >= 0")
                self.timeout_s = t
            args = {"timeout": self.timeout_s}
            engine = sa.create_engine(u, connect_args=args, poolclass=NullPool)
            _sqlite_events(engine)
            return engine
        u = u.set(drivername="postgresql+psycopg")
        args = {} if "connect_timeout" in u.query else {"connect_timeout": max(1, int(round(self.timeout_s)))}
        try:
            return sa.create_engine(u, connect_args=args, poolclass=NullPool)
        except ImportError as exc:  # pragma: no cover - psycopg is a dependency
            raise HistoryInputError(f"history {self.shown}: PostgreSQL needs psycopg ({exc})") from None

    def close(self) -> None:
        """Release the connections."""
        self._engine.dispose()

    def __enter__(self) -> HistoryStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------ transactions

    @contextlib.contextmanager
    def _tx(self, write: bool) -> Iterator[sa.Connection]:
        """One transaction (a write one takes SQLite's write lock at once); errors translated."""
        with self.translated():
            conn, tx = self._begin(write)
            with conn, tx:
                yield conn

    def _begin(self, write: bool) -> tuple[sa.Connection, sa.RootTransaction]:
        """A connection and its begun transaction, before any statement of the transaction's body.

        SQLite's busy timeout does not cover every lock a new connection meets: switching the file to
        WAL, or the WAL recovery after another process closed the last connection, can answer "database
        is locked" at once. Those are retried here, backing off, for up to the busy timeout; nothing of
        the body has run yet, so a retry repeats nothing. Other errors, and PostgreSQL's, go through."""
        deadline = time.monotonic() + self.timeout_s
        delay_s = 0.005
        while True:
            conn = None
            try:
                conn = self._engine.connect().execution_options(emacheck_write=write)
                return conn, conn.begin()
            except sa_exc.OperationalError as exc:
                if conn is not None:
                    conn.close()
                text = str(getattr(exc, "orig", exc)).lower()
                if self.dialect != "sqlite" or not ("locked" in text or "busy" in text) \
                        or time.monotonic() + delay_s > deadline:
                    raise
            time.sleep(delay_s)
            delay_s = min(2.0 * delay_s, 0.1)

    @contextlib.contextmanager
    def translated(self) -> Iterator[None]:
        """Turn a database library's error into one line: :class:`HistoryInputError` or
        :class:`HistoryUnavailableError` (docs/history.md, "When the database is not there")."""
        try:
            yield
        except HistoryError:
            raise
        except (sa_exc.DBAPIError, sa_exc.ArgumentError, sa_exc.NoSuchModuleError) as exc:
            raise self._error(exc) from None

    def _error(self, exc: Exception) -> HistoryError:
        orig = getattr(exc, "orig", None) or exc
        text = " ".join(str(orig).split())
        low = text.lower()
        where = f"history {self.shown}"
        if self.dialect == "sqlite":
            if "locked" in low or "busy" in low:
                return HistoryUnavailableError(f"{where}: the database is locked by another program (waited "
                                               f"{self.timeout_s:g} s); try again when it is done")
            if "not a database" in low or "malformed" in low or "corrupt" in low:
                return HistoryInputError(f"{where}: not an SQLite database or corrupt ({text}); move the file "
                                         f"aside or give another --history")
            if "unable to open" in low or "readonly" in low or "read-only" in low:
                return HistoryInputError(f"{where}: cannot open or write the file ({text})")
            return HistoryUnavailableError(f"{where}: {text}")
        refused = ("password authentication failed", "authentication failed", "role \"", "no pg_hba.conf entry",
                   "permission denied", "does not exist", "no password supplied")
        if any(k in low for k in refused):
            return HistoryInputError(f"{where}: login refused ({_first_line(text)}); check the user, password "
                                     f"and database in --history or the profile's history.url")
        return HistoryUnavailableError(f"{where}: cannot reach the database server ({_first_line(text)})")

    # ------------------------------------------------------------- migrations

    def schema_version(self) -> int:
        """The schema version of the database (0: no emacheck tables yet)."""
        with self._tx(write=False) as conn:
            return _version(conn)

    def migrate(self) -> int:
        """Apply the migrations the database lacks, in one locked transaction; returns the version.

        Raises :class:`HistoryInputError` for a database written by a newer emacheck.
        """
        with self._tx(write=False) as conn:  # the usual case: already current, no write lock needed
            v = _version(conn)
        if v == S.LATEST:
            return v
        with self._tx(write=True) as conn:
            if self.dialect == "postgresql":
                conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PG_LOCK_KEY})
            v = _version(conn)
            if v == 0:
                _refuse_unversioned(conn, self.shown)
            if v > S.LATEST:
                raise HistoryInputError(f"history {self.shown}: schema version {v} was written by a newer emacheck "
                                        f"(this one knows up to {S.LATEST}); upgrade emacheck")
            for m in S.MIGRATIONS:
                if m.version > v:
                    if m.version == 1:
                        S.schema_versions.create(conn, checkfirst=True)
                    m.apply(conn)
                    conn.execute(sa.insert(S.schema_versions).values(
                        version=m.version, description=m.description, applied_utc=_utcnow(),
                        software=f"emacheck {__version__}"))
            return S.LATEST

    # ------------------------------------------------------------------ writing

    def add(self, record: CheckRecord) -> bool:
        """Record one result with its readings in one transaction.

        Parameters
        ----------
        record : hil.history.record.CheckRecord
            ``check`` (column -> value of ``emacheck_checks``, without the actuator ids),
            ``identity`` (``{"ema1": (vendor_id, product_code, serial) | None, ...}``) and
            ``readings`` (a list of column -> value of ``emacheck_readings``, without ``check_id``).

        Returns
        -------
        bool
            True if recorded, False if this result (same SHA-256) was recorded before.
        """
        with self._tx(write=True) as conn:
            return self._add(conn, record)

    def add_many(self, records: Sequence[CheckRecord]) -> int:
        """Record several results in one transaction; returns how many were new."""
        with self._tx(write=True) as conn:
            return sum(self._add(conn, r) for r in records)

    def _insert(self):
        if self.dialect == "sqlite":
            from sqlalchemy.dialects.sqlite import insert
        else:
            from sqlalchemy.dialects.postgresql import insert
        return insert

    def _actuator_id(self, conn: sa.Connection, key: tuple[int, int, int]) -> int:
        vendor, product, serial = (int(v) for v in key)
        a = S.actuators
        found = conn.execute(sa.select(a.c.id).where(a.c.serial == serial, a.c.vendor_id == vendor,
                                                     a.c.product_code == product)).scalar()
        if found is not None:
            return int(found)
        conn.execute(self._insert()(a).values(vendor_id=vendor, product_code=product, serial=serial)
                     .on_conflict_do_nothing(index_elements=["vendor_id", "product_code", "serial"]))
        return int(conn.execute(sa.select(a.c.id).where(a.c.serial == serial, a.c.vendor_id == vendor,
                                                        a.c.product_code == product)).scalar_one())

    def _superseded(self, conn: sa.Connection, row: dict) -> int | None:
        """The result of the same run and kind ranked just before ``row`` (:func:`hil.history.record.rank`):
        the one ``row`` supersedes (both stay; None: the run's first)."""
        c = S.checks
        before = [r for r in conn.execute(sa.select(c.c.id, c.c.analysed_utc).where(
            c.c.run_key == row["run_key"], c.c.kind == row["kind"], c.c.result_sha256 != row["result_sha256"]))
            if rank(r.analysed_utc, r.id) <= rank(row.get("analysed_utc"), 1 << 62)]
        return max(before, key=lambda r: rank(r.analysed_utc, r.id)).id if before else None

    def _add(self, conn: sa.Connection, record) -> bool:
        row = dict(record.check)
        for ema in ("ema1", "ema2"):
            key = record.identity.get(ema)
            row[f"{ema}_actuator_id"] = None if key is None else self._actuator_id(conn, key)
        row.setdefault("recorded_utc", _utcnow())
        row["supersedes_id"] = self._superseded(conn, row)
        stmt = (self._insert()(S.checks).values(**row)
                .on_conflict_do_nothing(index_elements=["result_sha256"]).returning(S.checks.c.id))
        cid = conn.execute(stmt).scalar()
        if cid is None:
            return False
        if record.readings:
            conn.execute(sa.insert(S.readings), [{**r, "check_id": cid} for r in record.readings])
        return True

    # ------------------------------------------------------------------ reading

    def count(self) -> int:
        """How many results are recorded."""
        with self._tx(write=False) as conn:
            return int(conn.execute(sa.select(sa.func.count()).select_from(S.checks)).scalar_one())

    def checks(self, *, serial: int | None = None, aircraft: str | None = None) -> list[dict[str, Any]]:
        """The recorded results in time order, each a dict of its columns plus ``identity``
        (``{"ema1": {"vendor_id", "product_code", "revision", "serial", "node"} | None, ...}``) and
        ``readings`` (``{channel: {column: value}}``).

        Parameters
        ----------
        serial : int, optional
            Only checks with this actuator (0x1018 serial number) at EMA 1 or EMA 2.
        aircraft : str, optional
            Only checks on this aircraft (registration).
        """
        c, a = S.checks, S.actuators
        a1, a2 = a.alias("a1"), a.alias("a2")
        cols = [c] + [x.c[f].label(f"{e}_{f}") for e, x in (("ema1", a1), ("ema2", a2))
                      for f in ("vendor_id", "product_code", "serial")]
        q = sa.select(*cols).select_from(c.outerjoin(a1, c.c.ema1_actuator_id == a1.c.id)
                                         .outerjoin(a2, c.c.ema2_actuator_id == a2.c.id))
        with self._tx(write=False) as conn:
            if serial is not None:
                ids = list(conn.execute(sa.select(a.c.id).where(a.c.serial == int(serial))).scalars())
                if not ids:
                    return []
                q = q.where(sa.or_(c.c.ema1_actuator_id.in_(ids), c.c.ema2_actuator_id.in_(ids)))
            if aircraft is not None:
                q = q.where(c.c.aircraft == aircraft)
            rows = [dict(r) for r in conn.execute(q.order_by(c.c.time_utc, c.c.id)).mappings()]
            by_id = {r["id"]: r for r in rows}
            for r in rows:
                r["readings"] = {}
                r["identity"] = {}
                for e in ("ema1", "ema2"):
                    s = r.pop(f"{e}_serial")
                    vid, pc = r.pop(f"{e}_vendor_id"), r.pop(f"{e}_product_code")
                    r["identity"][e] = None if s is None else {
                        "vendor_id": int(vid), "product_code": int(pc), "revision": r.get(f"{e}_revision"),
                        "serial": int(s), "node": r.get(f"{e}_node")}
            ids = list(by_id)
            for k in range(0, len(ids), _CHUNK):
                for rd in conn.execute(sa.select(S.readings).where(S.readings.c.check_id.in_(ids[k:k + _CHUNK]))
                                       ).mappings():
                    rd = dict(rd)
                    by_id[rd.pop("check_id")]["readings"][rd["channel"]] = rd
        return rows


def _version(conn: sa.Connection) -> int:
    if not sa.inspect(conn).has_table(S.schema_versions.name):
        return 0
    v = conn.execute(sa.select(sa.func.max(S.schema_versions.c.version))).scalar()
    return int(v or 0)


def _refuse_unversioned(conn: sa.Connection, shown: str) -> None:
    """A database with ``emacheck_`` tables but no schema version is not one emacheck made: refused."""
    found = sorted(n for n in sa.inspect(conn).get_table_names() if n.startswith("emacheck_"))
    if found:
        raise HistoryInputError(f"history {shown}: holds {', '.join(found)} but no {S.schema_versions.name}: not "
                                f"made by emacheck (or damaged); emacheck writes only to its own database")


def _first_line(text: str) -> str:
    text = text.replace("(Background on this error at:", "").strip()
    return text[:300]


def _sqlite_events(engine: sa.Engine) -> None:
    """SQLite as a database two rigs may write at once: the driver's own transaction handling off,
    ``BEGIN IMMEDIATE`` for writes (the write lock at the start, waiting up to the busy timeout,
    never failing halfway), ``BEGIN`` for reads; WAL journal (readers do not block the writer),
    foreign keys on. The documented SQLAlchemy recipe for pysqlite."""

    @sa.event.listens_for(engine, "connect")
    def _connect(dbapi_conn, _record) -> None:
        dbapi_conn.isolation_level = None
        cur = dbapi_conn.cursor()
        try:
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=FULL")  # a commit is on disk when it returns
            cur.execute("PRAGMA foreign_keys=ON")
        finally:
            cur.close()

    @sa.event.listens_for(engine, "begin")
    def _begin(conn: sa.Connection) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("emacheck_write") else "BEGIN")
