"""The history's tables (SQLAlchemy Core) and their versioned migrations.

Three tables, prefixed ``emacheck_`` so that a station's PostgreSQL database
can hold other things too, and a version table:

* ``emacheck_actuators``: one row per actuator, identified by its 0x1018
  vendor id, product code and serial number;
* ``emacheck_checks``: one row per result recorded (a maintenance check's
  result.json or a BLFserv serv.json), with when, where (aircraft, position,
  rig), who, the flight hours and cycles, the actuators at EMA 1 and EMA 2,
  the LVDT calibration, the status and where the files are; unique by the
  SHA-256 of the result, so that recording the same result twice records it
  once;
* ``emacheck_readings``: per result and channel (int1, int2, ext) the
  backlash with its uncertainty, the limit and verdict, the stiffness;
* ``emacheck_schema``: the migrations applied (version, description, when).

Migrations are a small versioned list (:data:`MIGRATIONS`), applied in one
transaction under a lock (``BEGIN IMMEDIATE`` on SQLite, an advisory lock on
PostgreSQL) by :meth:`hil.history.store.HistoryStore.open`; alembic would
bring a script directory, an env.py and Mako templates for what is one
table-creating step so far. A migration is never edited once released: a
change of the tables is a new migration that alters them (SQLAlchemy DDL
constructs, dialect-neutral), and :data:`LATEST` follows it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import sqlalchemy as sa

from hil.history.record import rank

METADATA = sa.MetaData()

#: the channels of a check, as in result.json
CHANNELS = ("int1", "int2", "ext")

schema_versions = sa.Table(
    "emacheck_schema", METADATA,
    sa.Column("version", sa.Integer, primary_key=True, autoincrement=False),
    sa.Column("description", sa.String(200), nullable=False),
    sa.Column("applied_utc", sa.DateTime, nullable=False),
    sa.Column("software", sa.String(40), nullable=False),
)

actuators = sa.Table(
    "emacheck_actuators", METADATA,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("vendor_id", sa.BigInteger, nullable=False),  # 0x1018:01 (uint32: BIGINT on PostgreSQL)
    sa.Column("product_code", sa.BigInteger, nullable=False),  # 0x1018:02
    sa.Column("serial", sa.BigInteger, nullable=False),  # 0x1018:04
    sa.UniqueConstraint("vendor_id", "product_code", "serial", name="uq_emacheck_actuator"),
)
sa.Index("ix_emacheck_actuators_serial", actuators.c.serial)


def _ema_columns(k: int) -> list[sa.Column]:
    """Per EMA: the actuator, its revision and node as the drive reported them, the LVDT calibration."""
    return [
        sa.Column(f"ema{k}_actuator_id", sa.Integer, sa.ForeignKey("emacheck_actuators.id"), nullable=True),
        sa.Column(f"ema{k}_revision", sa.BigInteger, nullable=True),  # 0x1018:03
        sa.Column(f"ema{k}_node", sa.Integer, nullable=True),
        sa.Column(f"ema{k}_lvdt_pitch", sa.Float, nullable=True),
        sa.Column(f"ema{k}_lvdt_offset_mm", sa.Float, nullable=True),
        sa.Column(f"ema{k}_lvdt_nonlinearity_mm", sa.Float, nullable=True),
        sa.Column(f"ema{k}_lvdt_rmse_mm", sa.Float, nullable=True),
    ]


checks = sa.Table(
    "emacheck_checks", METADATA,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("result_sha256", sa.String(64), nullable=False),  # of the result's canonical JSON
    sa.Column("run_key", sa.String(96), nullable=False),  # the run id, else "recording:<sha256>"
    sa.Column("run_id", sa.String(64), nullable=True),
    sa.Column("kind", sa.String(8), nullable=False),  # "maint" (result.json) or "serv" (serv.json)
    sa.Column("simulated", sa.Boolean, nullable=False),
    sa.Column("mode", sa.String(32), nullable=True),  # run, dry-run, simulate, simulate-scenario, None (bare)
    sa.Column("time_utc", sa.DateTime, nullable=False),  # when the check started (UTC)
    sa.Column("analysed_utc", sa.DateTime, nullable=True),
    sa.Column("recorded_utc", sa.DateTime, nullable=False),
    sa.Column("aircraft", sa.String(40), nullable=False),
    sa.Column("position", sa.String(80), nullable=False),
    sa.Column("rig", sa.String(80), nullable=False),
    sa.Column("operator", sa.String(120), nullable=True),
    sa.Column("work_order", sa.String(120), nullable=True),
    sa.Column("flight_hours", sa.Float, nullable=True),
    sa.Column("flight_cycles", sa.Integer, nullable=True),
    sa.Column("status", sa.String(16), nullable=False),  # pass, fail, inconclusive, aborted, incomplete
    sa.Column("software_version", sa.String(40), nullable=True),
    sa.Column("check_software_version", sa.String(40), nullable=True),
    sa.Column("limit_int_mm", sa.Float, nullable=True),
    sa.Column("limit_ext_mm", sa.Float, nullable=True),
    *_ema_columns(1),
    *_ema_columns(2),
    sa.Column("calibration_source", sa.Text, nullable=True),  # serv: where the LVDT calibration came from
    sa.Column("run_folder", sa.Text, nullable=True),
    sa.Column("result_path", sa.Text, nullable=True),
    sa.Column("recording", sa.Text, nullable=True),
    # (version 2) the result of the same run and kind this one supersedes: the one ranked just before it
    # by analysis time when it was recorded; both stay, the latest is the run's current result
    sa.Column("supersedes_id", sa.Integer, nullable=True),
    sa.UniqueConstraint("result_sha256", name="uq_emacheck_checks_result"),
)
sa.Index("ix_emacheck_checks_ema1", checks.c.ema1_actuator_id)
sa.Index("ix_emacheck_checks_ema2", checks.c.ema2_actuator_id)
sa.Index("ix_emacheck_checks_aircraft", checks.c.aircraft)
sa.Index("ix_emacheck_checks_run_key", checks.c.run_key)

readings = sa.Table(
    "emacheck_readings", METADATA,
    sa.Column("check_id", sa.Integer, sa.ForeignKey("emacheck_checks.id", ondelete="CASCADE"), primary_key=True),
    sa.Column("channel", sa.String(4), primary_key=True),  # int1, int2, ext
    sa.Column("backlash_mm", sa.Float, nullable=True),  # None: not measured / not traversed
    sa.Column("uncertainty_mm", sa.Float, nullable=True),  # expanded, k = 2
    sa.Column("backlash_sigma_mm", sa.Float, nullable=True),  # the regression's own (statistical)
    sa.Column("limit_mm", sa.Float, nullable=True),
    sa.Column("margin_mm", sa.Float, nullable=True),
    sa.Column("verdict", sa.String(16), nullable=True),  # pass, fail, inconclusive, not_traversed
    sa.Column("reason", sa.Text, nullable=True),
    sa.Column("stiffness_left_N_per_mm", sa.Float, nullable=True),
    sa.Column("stiffness_right_N_per_mm", sa.Float, nullable=True),
    sa.Column("stiffness_left_sigma_N_per_mm", sa.Float, nullable=True),
    sa.Column("stiffness_right_sigma_N_per_mm", sa.Float, nullable=True),
    sa.Column("traversals", sa.Integer, nullable=True),  # serv: counted backlash traversals
)


@dataclass(frozen=True)
class Migration:
    """One step of the schema: ``apply(connection)`` inside the migration transaction."""

    version: int
    description: str
    apply: Callable[[sa.Connection], None]


def _v1(conn: sa.Connection) -> None:
    """Version 1: actuators, checks, readings and their indexes."""
    METADATA.create_all(conn, tables=[actuators, checks, readings])


def _v2(conn: sa.Connection) -> None:
    """Version 2: ``emacheck_checks.supersedes_id`` (a database made at version 2 has it from version 1's
    tables already), filled in for the runs recorded before it: each result supersedes the one ranked
    before it among the results of its run and kind."""
    have = {c["name"] for c in sa.inspect(conn).get_columns(checks.name)}
    if "supersedes_id" not in have:
        col = sa.schema.CreateColumn(checks.c.supersedes_id).compile(dialect=conn.dialect)
        conn.execute(sa.text(f"ALTER TABLE {checks.name} ADD COLUMN {col}"))
    runs: dict[tuple, list] = {}
    for r in conn.execute(sa.select(checks.c.id, checks.c.run_key, checks.c.kind, checks.c.analysed_utc)):
        runs.setdefault((r.run_key, r.kind), []).append(r)
    for rows in runs.values():
        rows.sort(key=lambda r: rank(r.analysed_utc, r.id))  # (hil.history.record.rank)
        for before, r in zip(rows, rows[1:], strict=False):
            conn.execute(sa.update(checks).where(checks.c.id == r.id).values(supersedes_id=before.id))


#: every migration in order; a database at version n gets those above n
MIGRATIONS: tuple[Migration, ...] = (
    Migration(1, "actuators, checks and readings", _v1),
    Migration(2, "checks.supersedes_id: a re-analysis keeps the result it supersedes", _v2),
)
#: the schema version this emacheck writes
LATEST = MIGRATIONS[-1].version
