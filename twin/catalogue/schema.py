"""The catalogue's one schema (SQLAlchemy Core) and its versioned migrations.

One set of tables serves SQLite (the embedded default) and PostgreSQL (a lab's shared
server): no dialect-specific SQL outside :func:`sqlite_pragmas`. A catalogue records the
schema version it was written with in ``drumtwin_schema``; :data:`MIGRATIONS` lists each
version's change in order, and :func:`migrate` applies the missing ones in one transaction.
A catalogue of a newer version than this release is refused (it might hold columns this
release would drop on write).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import sqlalchemy as sa

metadata = sa.MetaData()

SCHEMA_TABLE = "drumtwin_schema"

schema_info = sa.Table(
    SCHEMA_TABLE, metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("version", sa.Integer, nullable=False),
    sa.Column("app", sa.String(32), nullable=False),
)

runs = sa.Table(
    "runs", metadata,
    sa.Column("id", sa.String(64), primary_key=True),            # the run's uid
    sa.Column("path", sa.Text, nullable=False, unique=True),      # absolute run folder
    sa.Column("rig", sa.String(200), nullable=False),             # the config's name
    sa.Column("rig_hash", sa.String(16), nullable=False),         # hash of its mixer and classes
    sa.Column("started_s", sa.Float, nullable=False),             # unix time
    sa.Column("ended_s", sa.Float),
    sa.Column("duration_s", sa.Float),                            # run time of the last record
    sa.Column("ended", sa.String(16), nullable=False),            # running | clean | failed | killed
    sa.Column("failure", sa.Text),
    sa.Column("mode", sa.String(16), nullable=False),
    sa.Column("objective", sa.String(16)),
    sa.Column("rpm_start", sa.Float),
    sa.Column("rpm_min", sa.Float),
    sa.Column("rpm_max", sa.Float),
    sa.Column("rpm_final", sa.Float),
    sa.Column("mixed", sa.Boolean, nullable=False),
    sa.Column("mixing_time_s", sa.Float),
    sa.Column("plateau_mi", sa.Float),
    sa.Column("final_mi", sa.Float),
    sa.Column("energy_j", sa.Float),
    sa.Column("frames", sa.Integer),
    sa.Column("n_faults", sa.Integer, nullable=False),
    sa.Column("faults", sa.Text, nullable=False),                 # fault names, ';'-separated
    sa.Column("golden", sa.Boolean, nullable=False),
    sa.Column("note", sa.Text, nullable=False),
    sa.Column("pid", sa.Integer),
    sa.Column("host", sa.String(255)),
    sa.Column("proc_start", sa.String(32)),                       # the process's start tick
    sa.Column("indexed_mtime", sa.Float, nullable=False),         # newest file time when indexed
    sa.Index("ix_runs_rig_started", "rig", "started_s"),
    sa.Index("ix_runs_started", "started_s"),
)

tags = sa.Table(
    "tags", metadata,
    sa.Column("run_id", sa.String(64), sa.ForeignKey("runs.id", ondelete="CASCADE"), primary_key=True),
    sa.Column("key", sa.String(200), primary_key=True),
    sa.Column("value", sa.Text, nullable=False),
    sa.Index("ix_tags_key_value", "key", "value"),
)

APP = "drumtwin"
SQLITE_APPLICATION_ID = 0x44545743  # "DTWC": a drumtwin catalogue, seen by `file` and by us

Migration = Callable[[sa.Connection], None]


def _v1(conn: sa.Connection) -> None:
    """Version 1: runs and tags."""
    metadata.create_all(conn, tables=[runs, tags])


MIGRATIONS: Sequence[tuple[int, Migration]] = ((1, _v1),)
"""Each schema version and the change that makes it from the one before, in order."""

SCHEMA_VERSION = MIGRATIONS[-1][0]


def read_version(conn: sa.Connection) -> int | None:
    """The schema version a catalogue holds (None: an empty database, no drumtwin tables)."""
    inspector = sa.inspect(conn)
    if not inspector.has_table(SCHEMA_TABLE):
        return None
    row = conn.execute(sa.select(schema_info.c.version, schema_info.c.app)).first()
    if row is None or row.app != APP:
        return -1
    return int(row.version)


def migrate(conn: sa.Connection, current: int | None, migrations: Sequence[tuple[int, Migration]] = MIGRATIONS) -> int:
    """Apply every migration above ``current`` (None: a new catalogue) and record the version
    reached; the caller holds the transaction, so a failed step leaves the old version."""
    if current is None:
        metadata.create_all(conn, tables=[schema_info])
        conn.execute(schema_info.insert().values(id=1, version=0, app=APP))
        current = 0
    for version, step in migrations:
        if version > current:
            step(conn)
            current = version
    conn.execute(schema_info.update().where(schema_info.c.id == 1).values(version=current))
    return current


def sqlite_pragmas(dbapi_conn: object) -> None:
    """Per-connection settings of an SQLite catalogue: WAL (readers never block the one writer),
    a busy wait for a second run's write, foreign keys."""
    cur = dbapi_conn.cursor()  # type: ignore[attr-defined]
    cur.execute("PRAGMA busy_timeout = 15000")
    cur.execute("PRAGMA journal_mode = WAL")
    cur.execute("PRAGMA synchronous = NORMAL")
    cur.execute("PRAGMA foreign_keys = ON")
    cur.close()
