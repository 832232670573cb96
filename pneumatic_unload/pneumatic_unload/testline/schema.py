# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The results database's schema, its two backends and its migrations.

Where the database is: a plain path is an embedded SQLite file (WAL mode, the default); a
URL ``postgresql://USER@HOST:PORT/DB`` (or ``postgresql+psycopg://``, ``postgres://``) is a
PostgreSQL server shared by many benches (driver psycopg 3; the password from the URL,
``PGPASSWORD`` or ``~/.pgpass``). One schema for both, written with SQLAlchemy Core
(:data:`FILES`, :data:`UNLOADS`; floats are DOUBLE PRECISION on PostgreSQL), and one chain
of Alembic revisions shipped in ``migrations/versions`` (:data:`REVISIONS`), run by
:func:`migrate` when a database is opened:

* the schema is changed by one opener at a time, in one transaction: PostgreSQL's
  ``pg_advisory_xact_lock`` (two batches starting at once on an empty database would
  otherwise collide creating the same tables), SQLite's write lock (``BEGIN IMMEDIATE``);
* a SQLite file of schema 1, 2 or 3 written before Alembic (``PRAGMA user_version``, no
  ``alembic_version`` table) is stamped at its revision and upgraded with its rows; the
  revisions keep ``user_version`` in step, so the package before Alembic still reads it;
* a database of a newer revision is refused (upgrade the package).

A new revision: copy the last file of ``migrations/versions``, set ``revision`` and
``down_revision``, raise :data:`SCHEMA_VERSION` and append to :data:`REVISIONS`.
"""

from __future__ import annotations

import re
import threading
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pneumatic_unload.testline.redact import redact

#: The oldest SQLAlchemy the results database runs on (``sa.URL``, ``sa.Double``, 2.0
#: style Core). The module imports with 1.4 (Ubuntu
#: 24.04's python3-sqlalchemy): a node with no results database starts; opening one
#: with an older SQLAlchemy is refused with :func:`check_sqlalchemy`'s message.
SQLALCHEMY_FLOOR = (2, 0)
#: An IEEE double column: DOUBLE PRECISION on PostgreSQL, REAL on SQLite (``sa.Double``
#: of SQLAlchemy 2; ``Float(53)``, the same column, where it is missing).
DOUBLE: Any = getattr(sa, "Double", None) or sa.Float(precision=53)


def sqlalchemy_version(text: str = sa.__version__) -> tuple[int, int]:
    """(major, minor) of a SQLAlchemy version text ('2.0.36', '1.4.50', '2.1.0b1')."""
    parts = re.findall(r"\d+", text)[:2]
    return (int(parts[0]), int(parts[1]) if len(parts) > 1 else 0)


def check_sqlalchemy(text: str = sa.__version__) -> None:
    """Refuse an SQLAlchemy older than :data:`SQLALCHEMY_FLOOR` with a message saying what
    to install.

    Raises
    ------
    ResultsDBError
        SQLAlchemy ``text`` is older than the floor."""
    if sqlalchemy_version(text) < SQLALCHEMY_FLOOR:
        floor = ".".join(map(str, SQLALCHEMY_FLOOR))
        raise ResultsDBError(f"the results database needs SQLAlchemy >= {floor}, this "
                             f"Python has {text}: pip install 'SQLAlchemy>={floor}' "
                             "(or run without a results database)")

#: Schema version written by this package [-] (SQLite's ``PRAGMA user_version``).
SCHEMA_VERSION = 4
#: Alembic revision of each schema version: REVISIONS[k - 1] is version k.
REVISIONS: tuple[str, ...] = ("0001", "0002", "0003", "0004")
#: The revision this package writes and reads.
HEAD = REVISIONS[-1]
#: Where the revisions are (a folder of the package, not a Python package itself).
MIGRATIONS_DIR = Path(__file__).resolve().with_name("migrations")
#: How long a writer waits for a lock before giving up [s].
BUSY_TIMEOUT = 60.0
#: How long a connection to a PostgreSQL server may take [s].
CONNECT_TIMEOUT = 10
#: Longest a statement may run on a PostgreSQL server, lock waits included [s]
#: (``statement_timeout``, set for every connection): the server ends it with an error.
STATEMENT_TIMEOUT = 30
#: TCP keepalives of a PostgreSQL connection (libpq's ``keepalives_idle``,
#: ``keepalives_interval``, ``keepalives_count``): probes after 10 s without traffic, every
#: 5 s; 3 unanswered probes drop the connection (a host gone from the network: an error
#: within 25 s), and data unacknowledged for :data:`TCP_USER_TIMEOUT` s drop it as well.
KEEPALIVE_IDLE, KEEPALIVE_INTERVAL, KEEPALIVE_COUNT = 10, 5, 3
#: Longest sent data may stay unacknowledged before the connection is dropped [s]
#: (libpq's ``tcp_user_timeout``).
TCP_USER_TIMEOUT = 25
#: Key of the PostgreSQL advisory lock held while the schema is checked and migrated [-].
SCHEMA_LOCK_KEY = 0x706E_756E_6C6F_6164  # "pnunload"
#: URL schemes of a PostgreSQL server (all through psycopg 3).
POSTGRES_SCHEMES = ("postgresql", "postgresql+psycopg", "postgres")

#: Columns of ``unloads`` of schema version 1, taken from a result's JSON
#: (:func:`~pneumatic_unload.analysis.output.unload_json`), with their types; units SI.
V1_COLUMNS: tuple[tuple[str, Any], ...] = (
    ("status", sa.Text), ("status_text", sa.Text), ("final", sa.Integer),
    ("t_start", DOUBLE), ("tau_exp", DOUBLE), ("tau_exp_std", DOUBLE),
    ("p10", DOUBLE), ("p_atm", DOUBLE), ("p_star", DOUBLE),
    ("initial_temperature", DOUBLE), ("volume", DOUBLE),
    ("conductance", DOUBLE), ("conductance_std", DOUBLE),
    ("conductance_model", DOUBLE), ("conductance_model_std", DOUBLE),
    ("critical_ratio", DOUBLE), ("critical_ratio_std", DOUBLE),
    ("recommended_conductance", DOUBLE), ("recommended_std", DOUBLE),
    ("heat_law", sa.Text), ("method", sa.Text), ("quality", DOUBLE),
)
#: Columns added by version 2: the ISO 6358-1:2013 subsonic index m and its uncertainty [-],
#: the transducer's fitted zero offset and its uncertainty [Pa].
V2_COLUMNS: tuple[tuple[str, Any], ...] = (
    ("subsonic_index", DOUBLE), ("subsonic_index_std", DOUBLE),
    ("pressure_offset", DOUBLE), ("pressure_offset_std", DOUBLE),
)
#: Columns added by version 3: the flow's direction ('discharge' or 'charge'; NULL in rows
#: of older versions: discharges) and a charge's supply pressure [Pa absolute].
V3_COLUMNS: tuple[tuple[str, Any], ...] = (("direction", sa.Text),
                                           ("supply_pressure", DOUBLE))
#: Every column of ``unloads`` taken from a result's JSON.
UNLOAD_COLUMNS = V1_COLUMNS + V2_COLUMNS + V3_COLUMNS

METADATA = sa.MetaData()
#: One row per analysed input; (content_hash, settings_hash) is the key a rerun skips on.
FILES = sa.Table(
    "files", METADATA,
    sa.Column("id", sa.Integer, primary_key=True),
    *[sa.Column(n, sa.Text, nullable=False) for n in (
        "path", "content_hash", "settings_hash", "part_id")],
    sa.Column("part_type", sa.Text),
    sa.Column("status", sa.Text, nullable=False),
    sa.Column("reason", sa.Text),
    sa.Column("n_unloads", sa.Integer, nullable=False),
    sa.Column("settings_json", sa.Text),
    *[sa.Column(n, sa.Text, nullable=False) for n in (
        "package_version", "analysed_at", "writer")],
    # schema 4: where a setting given met another recorded in the input (see FileRecord)
    sa.Column("settings_notes", sa.Text),
    sa.UniqueConstraint("content_hash", "settings_hash"),
)
#: One row per unload of an input; (file_id, unload_index) is unique.
UNLOADS = sa.Table(
    "unloads", METADATA,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("file_id", sa.Integer, sa.ForeignKey("files.id", ondelete="CASCADE"),
              nullable=False),
    sa.Column("unload_index", sa.Integer, nullable=False),
    sa.Column("part_id", sa.Text, nullable=False),
    *[sa.Column(n, t) for n, t in V1_COLUMNS],
    *[sa.Column(n, sa.Text) for n in ("verdict", "verdict_reason", "budget_json",
                                      "curve_json")],
    sa.Column("result_json", sa.Text, nullable=False),
    *[sa.Column(n, t) for n, t in V2_COLUMNS + V3_COLUMNS],
    sa.UniqueConstraint("file_id", "unload_index"),
)


class ResultsDBError(Exception):
    """The results database cannot be opened or written (a one-line message)."""


def one_line(exc: BaseException) -> str:
    """A driver's error as one line (psycopg's run over several, indented)."""
    orig = getattr(exc, "orig", None) or exc
    text = " ".join(part.strip() for part in str(orig).splitlines() if part.strip())
    return text or type(orig).__name__


def database_url(target: str | Path) -> sa.URL:
    """The URL of ``target``: a PostgreSQL URL as given (driver psycopg), a plain path (or
    ``sqlite:///PATH``) as a SQLite file.

    Raises
    ------
    ResultsDBError
        An unknown scheme or a URL that cannot be parsed; SQLAlchemy older than
        :data:`SQLALCHEMY_FLOOR`.
    """
    check_sqlalchemy()
    s = str(target)
    if "://" not in s:
        return sa.URL.create("sqlite", database=s)
    scheme = s.split("://", 1)[0].lower()
    try:
        url = sa.make_url(s)
    except (sa.exc.ArgumentError, ValueError) as exc:
        raise ResultsDBError(redact(f"results database {s}: not a database URL "
                                    f"({one_line(exc)})", s)) from exc
    if scheme == "sqlite":
        if not url.database or url.database == ":memory:":
            raise ResultsDBError(f"results database {s}: give the SQLite file's path "
                                 "(sqlite:///PATH, or the plain path)")
        return sa.URL.create("sqlite", database=url.database)
    if scheme not in POSTGRES_SCHEMES:
        raise ResultsDBError(f"results database {hide_password(s)}: unknown scheme "
                             f"{scheme!r}: give a file path (SQLite) or "
                             "postgresql://USER@HOST:PORT/DB")
    if not url.database:
        raise ResultsDBError(f"results database {hide_password(s)}: no database name "
                             "(postgresql://USER@HOST:PORT/DB)")
    return url.set(drivername="postgresql+psycopg")


def hide_password(target: str | Path) -> str:
    """``target`` as shown in messages and reports: a URL's password as *** whatever the
    URL's form (:func:`~.redact.redact`)."""
    return redact(str(target), target)


def make_engine(url: sa.URL) -> sa.Engine:
    """An engine of ``url`` (see :func:`database_url`): SQLite with the write lock taken up
    front for a connection with the execution option ``write`` (``BEGIN IMMEDIATE``),
    foreign keys on and :data:`BUSY_TIMEOUT`; PostgreSQL with :data:`CONNECT_TIMEOUT`,
    :data:`STATEMENT_TIMEOUT` and TCP keepalives (:data:`KEEPALIVE_IDLE`,
    :data:`TCP_USER_TIMEOUT`).

    Raises
    ------
    ResultsDBError
        The PostgreSQL driver (psycopg) is not installed.
    """
    if url.get_backend_name() != "sqlite":
        try:
            return sa.create_engine(url, pool_pre_ping=True, connect_args={
                "connect_timeout": CONNECT_TIMEOUT, "application_name": "pneumatic_unload",
                "keepalives": 1, "keepalives_idle": KEEPALIVE_IDLE,
                "keepalives_interval": KEEPALIVE_INTERVAL,
                "keepalives_count": KEEPALIVE_COUNT,
                "tcp_user_timeout": TCP_USER_TIMEOUT * 1000,
                "options": f"-c statement_timeout={STATEMENT_TIMEOUT * 1000}"})
        except ImportError as exc:
            shown = hide_password(url.render_as_string(hide_password=False))
            raise ResultsDBError(f"results database {shown}: the PostgreSQL driver is "
                                 f"missing ({exc}): pip install 'psycopg[binary]'") from exc
    eng = sa.create_engine(url, connect_args={"timeout": BUSY_TIMEOUT,
                                              "check_same_thread": False})

    @sa.event.listens_for(eng, "connect")
    def _on_connect(dbapi_con: Any, _record: Any) -> None:
        dbapi_con.isolation_level = None  # the transactions are begun below, not by sqlite3
        cur = dbapi_con.cursor()
        cur.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT * 1000)}")
        cur.execute("PRAGMA foreign_keys = ON")
        cur.close()

    @sa.event.listens_for(eng, "begin")
    def _on_begin(conn: sa.Connection) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("write")
                             else "BEGIN")

    return eng


def _state(conn: sa.Connection) -> tuple[str | None, int, bool]:
    """(Alembic revision or None, SQLite's user_version (0 on PostgreSQL), files table)."""
    insp = sa.inspect(conn)
    rev = (conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar()
           if insp.has_table("alembic_version") else None)
    uv = int(conn.exec_driver_sql("PRAGMA user_version").scalar() or 0) \
        if conn.dialect.name == "sqlite" else 0
    return rev, uv, insp.has_table("files")


def _check_newer(label: str, rev: str | None, uv: int) -> None:
    if uv > SCHEMA_VERSION or (rev is not None and rev not in REVISIONS):
        found = f"schema version {uv}" if uv > SCHEMA_VERSION else f"schema revision {rev}"
        raise ResultsDBError(
            f"results database {label} has {found}, newer than this package's "
            f"{SCHEMA_VERSION} ({HEAD}): upgrade pneumatic_unload to read it")


#: Alembic's context is process-global: one migration at a time in this process.
_ALEMBIC_LOCK = threading.Lock()


def migrate(engine: sa.Engine, label: str, create: bool = True) -> None:
    """Bring the database to :data:`HEAD` (see the module doc): nothing to do is one read;
    otherwise the schema lock, a second look, and the revisions missing, in one transaction.

    Raises
    ------
    ResultsDBError
        A newer schema; no schema and ``create`` False; the driver's errors are the
        caller's (sqlalchemy.exc.DBAPIError).
    """
    with engine.connect() as conn:
        rev, uv, _files = _state(conn)
        conn.rollback()
    _check_newer(label, rev, uv)
    if rev == HEAD:
        return
    with _ALEMBIC_LOCK, engine.connect() as conn:
        conn.execution_options(write=True)
        with conn.begin():
            if conn.dialect.name == "postgresql":
                conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"),
                             {"k": SCHEMA_LOCK_KEY})
            rev, uv, files = _state(conn)  # another opener may have migrated meanwhile
            _check_newer(label, rev, uv)
            if rev == HEAD:
                return
            if not files and not create:
                raise ResultsDBError(f"results database {label}: no results there yet (a "
                                     "batch or an estimator node creates the tables)")
            from alembic import command  # local: only when the schema changes
            from alembic.config import Config

            cfg = Config()
            cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
            cfg.attributes["connection"] = conn
            if rev is None and files and 1 <= uv <= SCHEMA_VERSION:
                command.stamp(cfg, REVISIONS[uv - 1])  # a file of the package before Alembic
            command.upgrade(cfg, HEAD)
