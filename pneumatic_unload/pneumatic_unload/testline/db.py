# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The results database of a test line, the system of record: an embedded SQLite file
(the default) or a PostgreSQL server shared by many benches (see :mod:`~.schema`).

Every analysed input is a row of ``files`` (path, content hash, settings hash, part id and
type, status and reason, the settings, the package version, when, written by whom) and
every unload a row of ``unloads`` (its estimates with their budgets, status and reason,
the verdict against the part's specification). A file's rows are written in one
transaction (a batch writes many files in one, :func:`write_files`): a batch killed at any
instant leaves whole files or nothing, and a rerun skips the files already there (same
content and settings) without duplicates.

Several writers at once (estimator nodes on several benches, batches) lose nothing and
duplicate nothing: an input is inserted only when its (content hash, settings hash) is not
there yet (``INSERT ... ON CONFLICT``, decided by the database's unique key, not by an
earlier read), its unloads in the same transaction. SQLite runs in WAL mode and each write
takes the write lock up front (``BEGIN IMMEDIATE``), waiting for it (:data:`BUSY_TIMEOUT`
s); on PostgreSQL a transaction that the server aborts for a deadlock or a serialization
failure is run again. :func:`open_db` creates or migrates the schema and refuses a newer
one. SI units in every column (m^3/(s Pa), s, Pa).
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import numbers
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pneumatic_unload.estimation.types import canonical_status
from pneumatic_unload.testline.redact import redact
from pneumatic_unload.testline.schema import (
    BUSY_TIMEOUT,
    FILES,
    SCHEMA_VERSION,
    UNLOAD_COLUMNS,
    UNLOADS,
    V1_COLUMNS,
    V2_COLUMNS,
    V3_COLUMNS,
    ResultsDBError,
    database_url,
    hide_password,
    make_engine,
    migrate,
    one_line,
)
from pneumatic_unload.testline.watchdog import ANSWER_TIMEOUT, Watchdog

__all__ = ["ANSWER_TIMEOUT", "BUSY_TIMEOUT", "EXPORT_COLUMNS", "SCHEMA_VERSION",
           "UNLOAD_COLUMNS", "V1_COLUMNS", "V2_COLUMNS", "V3_COLUMNS", "FileRecord",
           "ResultsDB", "ResultsDBError", "export", "file_rows", "has_file",
           "hide_password", "known_contents", "open_db", "unload_rows", "write_file",
           "write_files", "write_table"]

#: SQLSTATEs of a PostgreSQL transaction worth running again: serialization failure,
#: deadlock detected.
RETRY_SQLSTATES = ("40001", "40P01")


@dataclass
class FileRecord:
    """One analysed input and its unloads, written in one transaction.

    Attributes
    ----------
    path : str
        The input (as given).
    content_hash, settings_hash : str
        SHA-256 of the input's bytes and of the settings used (hex).
    part_id : str
        The part the input measured.
    status : str
        'ok' (at least one estimate), 'no_estimate' (read, but no C: the reason says why)
        or 'error' (unreadable: the reason says why).
    reason : str
        Why there is no estimate ('' when ok).
    unloads : list of dict
        Per unload: the result's JSON plus 'verdict' and 'verdict_reason'.
    settings : dict
        The estimator settings used (JSON-ready).
    part_type : str
        The specification's part type ('' when none).
    writer : str
        Who wrote it ('batch', or the estimator node's name).
    package_version : str
        The package version that made the numbers.
    settings_notes : str
        Where a setting given on the command line met another value recorded in the input
        (a bag): which one was used and why, one note per setting joined by '; ' ('' when
        none did).
    """

    path: str
    content_hash: str
    settings_hash: str
    part_id: str
    status: str
    reason: str = ""
    unloads: list[dict[str, Any]] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)
    part_type: str = ""
    writer: str = "batch"
    package_version: str = ""
    settings_notes: str = ""


class ResultsDB:
    """An open results database (returned by :func:`open_db`; close it, or use it in a
    ``with``): its engine and its name in messages (a URL's password hidden).

    Every operation on a PostgreSQL server ends within :attr:`timeout` seconds (see
    :data:`ANSWER_TIMEOUT`; SQLite: :data:`BUSY_TIMEOUT` for a lock), and every message
    goes through :func:`~.redact.redact` with the URL it was opened with.

    Attributes
    ----------
    engine : sqlalchemy.Engine
        The connections (a small pool).
    label : str
        The file's path, or the server's URL without its password.
    timeout : float or None
        Longest an operation waits for a PostgreSQL server [s] (None: no limit).
    """

    def __init__(self, engine: sa.Engine, label: str, *, target: str | Path = "",
                 timeout: float | None = ANSWER_TIMEOUT,
                 watchdog: Watchdog | None = None) -> None:
        self.engine = engine
        self.label = label
        self.target = str(target)
        self.timeout = timeout if engine.dialect.name == "postgresql" else None
        self.watchdog = watchdog or Watchdog(engine)

    def error(self, text: str) -> ResultsDBError:
        """A ResultsDBError of ``text``, the URL's password masked."""
        return ResultsDBError(redact(text, self.target))

    def _deadline(self, what: str, timeout: float | None = None) -> Any:
        return self.watchdog.deadline(self.timeout if timeout is None else timeout,
                                      self.label, what, self.target)

    @property
    def backend(self) -> str:
        """'sqlite' or 'postgresql'."""
        return self.engine.dialect.name

    def close(self) -> None:
        """Close every connection."""
        self.engine.dispose()

    def __enter__(self) -> ResultsDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def rows(self, stmt: Any) -> list[dict[str, Any]]:
        """The rows of a query (a read transaction; SQLite's WAL readers never wait)."""
        with self._deadline("reading"):
            try:
                with self.engine.connect() as conn:
                    return [dict(r._mapping) for r in conn.execute(stmt)]
            except sa.exc.SQLAlchemyError as exc:
                raise self.error(f"results database {self.label}: {one_line(exc)}") from exc

    def column(self, stmt: Any) -> list[Any]:
        """The first column of a query's rows (see :meth:`rows`)."""
        with self._deadline("reading"):
            try:
                with self.engine.connect() as conn:
                    return list(conn.execute(stmt).scalars())
            except sa.exc.SQLAlchemyError as exc:
                raise self.error(f"results database {self.label}: {one_line(exc)}") from exc

    def write(self, body: Callable[[sa.Connection], Any], *,
              timeout: float | None = None) -> Any:
        """Run ``body(connection)`` in one write transaction (SQLite: the write lock taken
        up front), again while SQLite is locked or PostgreSQL aborted it for a deadlock or
        a serialization failure, up to :data:`BUSY_TIMEOUT` s; returns its value. On
        PostgreSQL the whole ends within ``timeout`` s (None: :attr:`timeout`), else a
        ResultsDBError (the transaction is not committed)."""
        with self._deadline("writing", timeout):
            return self._write(body)

    def _write(self, body: Callable[[sa.Connection], Any]) -> Any:
        deadline = time.monotonic() + BUSY_TIMEOUT
        while True:
            try:
                with self.engine.connect() as conn:
                    conn.execution_options(write=True)
                    with conn.begin():
                        return body(conn)
            except sa.exc.DBAPIError as exc:
                again = ("locked" in str(exc.orig) if self.backend == "sqlite" else
                         getattr(exc.orig, "sqlstate", None) in RETRY_SQLSTATES)
                if not again or time.monotonic() >= deadline:
                    raise
                time.sleep(0.05)


def open_db(target: str | Path, *, create: bool = True,
            timeout: float | None = ANSWER_TIMEOUT) -> ResultsDB:
    """Open (creating or migrating) the results database ``target``: a file path (SQLite)
    or a URL ``postgresql://USER@HOST:PORT/DB`` (see :mod:`~.schema`).

    Parameters
    ----------
    target : str or Path
        Where the database is.
    create : bool
        Create a missing SQLite file or the tables on an empty server (False: refuse).
    timeout : float or None
        Longest one operation (this opening, then each query or write) waits for a
        PostgreSQL server's answers [s] (:data:`ANSWER_TIMEOUT`; None: no limit).

    Raises
    ------
    ResultsDBError
        The file is not a database, is from a newer package version, or its folder is
        missing or not writable; the server cannot be reached, refuses the user or has no
        such database, or does not answer within ``timeout``; an unknown scheme or a bad
        URL; the driver is missing. No message shows the URL's password.
    """
    url = database_url(target)
    if url.get_backend_name() == "sqlite":
        p = Path(url.database or "")
        label = str(p)
        if not p.parent.is_dir():
            raise ResultsDBError(f"results database {p}: folder {p.parent} does not exist")
        if not create and not p.is_file():
            raise ResultsDBError(f"results database {p}: no such file")
    else:
        label = hide_password(target)  # as given (postgresql://...), without a password
    engine = make_engine(url)
    watchdog = Watchdog(engine)
    pg_timeout = timeout if url.get_backend_name() != "sqlite" else None
    try:
        with watchdog.deadline(pg_timeout, label, "opening", str(target)):
            _prepare(engine, url, label, create)
    except ResultsDBError as exc:
        engine.dispose()
        raise ResultsDBError(redact(str(exc), target)) from exc
    except (sa.exc.SQLAlchemyError, engine.dialect.loaded_dbapi.Error, OSError) as exc:
        engine.dispose()
        orig = getattr(exc, "orig", None)
        raise ResultsDBError(redact(f"results database {label}: {one_line(orig or exc)}",
                                    target)) from exc
    return ResultsDB(engine, label, target=target, timeout=timeout, watchdog=watchdog)


def _prepare(engine: sa.Engine, url: sa.URL, label: str, create: bool) -> None:
    """SQLite's WAL mode, then the schema created or migrated (see :func:`open_db`)."""
    if url.get_backend_name() == "sqlite":
        p = Path(url.database or "")
        raw = engine.raw_connection()  # outside a transaction, as WAL mode needs
        try:
            mode = raw.cursor().execute("PRAGMA journal_mode = WAL").fetchone()[0]
        finally:
            raw.close()
        if str(mode).lower() != "wal":
            raise ResultsDBError(f"results database {p}: WAL mode refused ({mode})")
    migrate(engine, label, create)


def has_file(con: ResultsDB, content_hash: str, settings_hash: str) -> bool:
    """True when an input of this content was analysed with these settings."""
    return bool(con.column(sa.select(FILES.c.id).where(
        FILES.c.content_hash == content_hash, FILES.c.settings_hash == settings_hash)))


def known_contents(con: ResultsDB, settings_hash: str) -> frozenset[str]:
    """Content hashes of the inputs analysed with these settings (one query: what a batch
    skips, decided where each input is hashed)."""
    return frozenset(con.column(sa.select(FILES.c.content_hash).where(
        FILES.c.settings_hash == settings_hash)))


def _num(x: Any) -> Any:
    if isinstance(x, bool):
        return int(x)
    if isinstance(x, numbers.Integral):
        return int(x)
    if isinstance(x, numbers.Real):
        v = float(x)
        return v if math.isfinite(v) else None
    return x


_KEY = ("content_hash", "settings_hash")
_NAMES = [n for n, _t in UNLOAD_COLUMNS]
#: Most inputs in one INSERT statement [-] (SQLite's limit of bound values is far above).
INSERT_ROWS = 200


def _prepared(rec: FileRecord, now: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The row of ``files`` and the rows of ``unloads`` (without their file_id) of an input,
    made before the transaction (no JSON encoding while SQLite's write lock is held)."""
    return ({"path": rec.path, "content_hash": rec.content_hash,
             "settings_hash": rec.settings_hash, "part_id": rec.part_id,
             "part_type": rec.part_type, "status": rec.status, "reason": rec.reason,
             "n_unloads": len(rec.unloads),
             "settings_json": json.dumps(rec.settings, sort_keys=True, default=str),
             "package_version": rec.package_version, "analysed_at": now,
             "writer": rec.writer, "settings_notes": rec.settings_notes or None},
            [{"unload_index": k, "part_id": rec.part_id,
              **{n: _num(u.get(n)) for n in _NAMES},
              "verdict": u.get("verdict"), "verdict_reason": u.get("verdict_reason"),
              "budget_json": json.dumps(u.get("budget")) if u.get("budget") else None,
              "curve_json": json.dumps(u["curve"]) if u.get("curve") else None,
              "result_json": json.dumps({key: v for key, v in u.items() if key != "curve"},
                                        sort_keys=True)}
             for k, u in enumerate(rec.unloads)])


def _dialect_insert(c: sa.Connection) -> Any:
    if c.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    else:
        from sqlalchemy.dialects.sqlite import insert
    return insert


def _insert_new(c: sa.Connection, prepared: list[tuple[dict[str, Any], list[dict[str, Any]]]]
                ) -> list[bool]:
    """Inputs and their unloads, inside the caller's transaction (see :func:`write_files`),
    :data:`INSERT_ROWS` inputs per statement: an input is inserted when its key is new,
    else skipped (False). The database's unique key decides (``ON CONFLICT DO NOTHING``), so
    two writers of the same input at once write it once, whoever commits first."""
    insert = _dialect_insert(c)
    out: list[bool] = []
    for j in range(0, len(prepared), INSERT_ROWS):
        part = prepared[j:j + INSERT_ROWS]
        stmt = insert(FILES).values([f for f, _u in part]).on_conflict_do_nothing(
            index_elements=list(_KEY)).returning(FILES.c.id, *[FILES.c[k] for k in _KEY])
        ids = {(h, s): i for i, h, s in c.execute(stmt)}
        rows: list[dict[str, Any]] = []
        for f, us in part:
            fid = ids.pop((f["content_hash"], f["settings_hash"]), None)  # a twin: False
            out.append(fid is not None)
            if fid is not None:
                rows += [{**u, "file_id": fid} for u in us]
        if rows:
            c.execute(UNLOADS.insert(), rows)
    return out


def _replace(c: sa.Connection, prepared: list[tuple[dict[str, Any], list[dict[str, Any]]]]
             ) -> list[bool]:
    """Inputs written whether there or not, one by one: the row of ``files`` inserted or
    updated in place (``ON CONFLICT DO UPDATE``: a writer replacing it at the same time
    waits for the row), its unloads written anew."""
    insert = _dialect_insert(c)
    for f, us in prepared:
        ins = insert(FILES).values(f)
        fid = c.execute(ins.on_conflict_do_update(index_elements=list(_KEY), set_={
            k: ins.excluded[k] for k in f if k not in _KEY}).returning(FILES.c.id)).scalar()
        c.execute(UNLOADS.delete().where(UNLOADS.c.file_id == fid))
        if us:
            c.execute(UNLOADS.insert(), [{**u, "file_id": fid} for u in us])
    return [True] * len(prepared)


def write_files(con: ResultsDB, recs: Sequence[FileRecord], *,
                replace: bool = False, timeout: float | None = None) -> list[bool]:
    """Write inputs with their unloads, in the order given, in one transaction: each input
    whole or not at all, and one commit (one sync to disk) for many inputs. On PostgreSQL
    it returns or fails within ``timeout`` s (None: the database's
    :attr:`ResultsDB.timeout`; a new connection's wait included, at least libpq's 2 s): a
    caller that must not block (a node's callback) passes its own.

    Returns
    -------
    list of bool
        Per input: True when written; False when the same content and settings are
        already there (or earlier in ``recs``) and ``replace`` is False (nothing changed).

    Raises
    ------
    ResultsDBError
        The database cannot be written (busy beyond :data:`BUSY_TIMEOUT`, disk full, the
        server gone, ...).
    """
    if not recs:
        return []
    now = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    prepared = [_prepared(r, now) for r in recs]
    try:
        return list(con.write(lambda c: (_replace if replace else _insert_new)(c, prepared),
                              timeout=timeout))
    except sa.exc.SQLAlchemyError as exc:
        raise con.error(f"results database {con.label}: writing {recs[0].path}"
                        + (f" and {len(recs) - 1} more" if len(recs) > 1 else "")
                        + f": {one_line(exc)}") from exc


def write_file(con: ResultsDB, rec: FileRecord, *, replace: bool = False,
               timeout: float | None = None) -> bool:
    """Write one input with its unloads in one transaction (see :func:`write_files`).

    Returns
    -------
    bool
        True when written; False when the same content and settings are already there
        and ``replace`` is False (nothing changed).
    """
    return write_files(con, [rec], replace=replace, timeout=timeout)[0]


def unload_rows(con: ResultsDB, part_id: str | None = None) -> list[dict[str, Any]]:
    """Every unload (with its file's path, hashes and time), in the order written."""
    f = FILES.c
    q = sa.select(UNLOADS, f.path, f.content_hash, f.settings_hash, f.part_type,
                  f.analysed_at, f.package_version, f.writer).join_from(
        UNLOADS, FILES, UNLOADS.c.file_id == f.id)
    if part_id is not None:
        q = q.where(UNLOADS.c.part_id == part_id)
    rows = con.rows(q.order_by(f.id, UNLOADS.c.unload_index))
    for r in rows:  # a database written by an older version: its status words read as now
        r["status"] = canonical_status(r["status"])
    return rows


def file_rows(con: ResultsDB) -> list[dict[str, Any]]:
    """Every input (analysed or failed), in the order written."""
    return con.rows(sa.select(FILES).order_by(FILES.c.id))


EXPORT_COLUMNS: tuple[str, ...] = (
    "part_id", "path", "unload_index", *[n for n, _t in UNLOAD_COLUMNS], "verdict",
    "verdict_reason", "content_hash", "settings_hash", "part_type", "analysed_at",
    "package_version", "writer")


def export(con: ResultsDB, out: str | Path) -> int:
    """Write every unload to ``out`` (.csv or .parquet, by its suffix); returns the rows.

    Raises
    ------
    ResultsDBError
        Unknown suffix, or the folder does not exist.
    """
    p = Path(out)
    if not p.parent.is_dir():
        raise ResultsDBError(f"{p}: folder {p.parent} does not exist")
    rows = unload_rows(con)
    table = [{k: r.get(k) for k in EXPORT_COLUMNS} for r in rows]
    write_table(table, p, EXPORT_COLUMNS)
    return len(table)


def write_table(rows: Sequence[dict[str, Any]], out: Path, columns: Iterable[str]) -> None:
    """Rows as a CSV or Parquet file (by ``out``'s suffix).

    Raises
    ------
    ResultsDBError
        A suffix other than .csv or .parquet.
    """
    cols = list(columns)
    suffix = out.suffix.lower()
    if suffix == ".csv":
        with out.open("w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=cols)
            w.writeheader()
            for r in rows:
                w.writerow({k: r.get(k) for k in cols})
    elif suffix == ".parquet":
        import pyarrow as pa  # local: pyarrow costs ~0.3 s to import
        import pyarrow.parquet as pq

        pq.write_table(pa.Table.from_pylist([{k: r.get(k) for k in cols} for r in rows]),
                       str(out))
    else:
        raise ResultsDBError(f"{out}: write .csv or .parquet (got {out.suffix or 'none'!r})")
