"""The results database of a test line: one embedded SQLite file, the system of record.

Every analysed input is a row of ``files`` (path, content hash, settings hash, part id and
type, status and reason, the settings, the package version, when, written by whom) and
every unload a row of ``unloads`` (its estimates with their budgets, status and reason,
the verdict against the part's specification). A file's rows are written in one
transaction (a batch writes many files in one, :func:`write_files`): a batch killed at any
instant leaves whole files or nothing, and a rerun skips the files already there (same
content and settings) without duplicates.

Several writers at once (two estimator nodes, a batch) lose nothing: the database runs in
WAL mode, each write takes the write lock up front (``BEGIN IMMEDIATE``) and waits for it
(:data:`BUSY_TIMEOUT` s) instead of failing. The schema carries its version
(``PRAGMA user_version``); :func:`open_db` migrates an older file in place
(:data:`MIGRATIONS`) and refuses a newer one. SI units in every column (m^3/(s Pa), s, Pa).
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import sqlite3
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Schema version written by this package [-].
SCHEMA_VERSION = 3
#: How long a writer waits for the write lock before giving up [s].
BUSY_TIMEOUT = 60.0

#: Columns of ``unloads`` of schema version 1, taken from a result's JSON
#: (:func:`~pneumatic_unload.output.unload_json`), with their SQL types; units SI.
V1_COLUMNS: tuple[tuple[str, str], ...] = (
    ("status", "TEXT"), ("status_text", "TEXT"), ("final", "INTEGER"),
    ("t_start", "REAL"), ("tau_exp", "REAL"), ("tau_exp_std", "REAL"),
    ("p10", "REAL"), ("p_atm", "REAL"), ("p_star", "REAL"),
    ("initial_temperature", "REAL"), ("volume", "REAL"),
    ("conductance", "REAL"), ("conductance_std", "REAL"),
    ("conductance_model", "REAL"), ("conductance_model_std", "REAL"),
    ("critical_ratio", "REAL"), ("critical_ratio_std", "REAL"),
    ("recommended_conductance", "REAL"), ("recommended_std", "REAL"),
    ("heat_law", "TEXT"), ("method", "TEXT"), ("quality", "REAL"),
)
#: Columns added by version 2: the ISO 6358-1:2013 subsonic index m and its uncertainty [-],
#: the transducer's fitted zero offset and its uncertainty [Pa].
V2_COLUMNS: tuple[tuple[str, str], ...] = (
    ("subsonic_index", "REAL"), ("subsonic_index_std", "REAL"),
    ("pressure_offset", "REAL"), ("pressure_offset_std", "REAL"),
)
#: Columns added by version 3: the flow's direction ('discharge' or 'charge'; NULL in rows
#: of older versions: discharges) and a charge's supply pressure [Pa absolute].
V3_COLUMNS: tuple[tuple[str, str], ...] = (("direction", "TEXT"), ("supply_pressure", "REAL"))
#: Every column of ``unloads`` taken from a result's JSON.
UNLOAD_COLUMNS = V1_COLUMNS + V2_COLUMNS + V3_COLUMNS

_V1 = f"""
CREATE TABLE files (
    id INTEGER PRIMARY KEY,
    path TEXT NOT NULL,
    content_hash TEXT NOT NULL,
    settings_hash TEXT NOT NULL,
    part_id TEXT NOT NULL,
    part_type TEXT,
    status TEXT NOT NULL,
    reason TEXT,
    n_unloads INTEGER NOT NULL,
    settings_json TEXT,
    package_version TEXT NOT NULL,
    analysed_at TEXT NOT NULL,
    writer TEXT NOT NULL,
    UNIQUE (content_hash, settings_hash)
);
CREATE TABLE unloads (
    id INTEGER PRIMARY KEY,
    file_id INTEGER NOT NULL REFERENCES files(id) ON DELETE CASCADE,
    unload_index INTEGER NOT NULL,
    part_id TEXT NOT NULL,
    {", ".join(f"{n} {t}" for n, t in V1_COLUMNS)},
    verdict TEXT,
    verdict_reason TEXT,
    budget_json TEXT,
    curve_json TEXT,
    result_json TEXT NOT NULL,
    UNIQUE (file_id, unload_index)
);
CREATE INDEX unloads_part ON unloads (part_id);
CREATE INDEX files_part ON files (part_id);
"""

#: Schema steps: MIGRATIONS[k] takes a database from version k to k + 1.
_V2 = ";\n".join(f"ALTER TABLE unloads ADD COLUMN {n} {t}" for n, t in V2_COLUMNS)
_V3 = ";\n".join(f"ALTER TABLE unloads ADD COLUMN {n} {t}" for n, t in V3_COLUMNS)
MIGRATIONS: tuple[str, ...] = (_V1, _V2, _V3)


class ResultsDBError(Exception):
    """The results database cannot be opened or written (a one-line message)."""


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


def _connect(path: Path) -> sqlite3.Connection:
    con = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT, isolation_level=None)
    con.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT * 1000)}")
    con.execute("PRAGMA foreign_keys = ON")
    return con


def open_db(path: str | Path) -> sqlite3.Connection:
    """Open (creating or migrating) the results database at ``path``.

    Raises
    ------
    ResultsDBError
        The file is not a database, is from a newer package version, or its folder is
        missing or not writable.
    """
    p = Path(path)
    if not p.parent.is_dir():
        raise ResultsDBError(f"results database {p}: folder {p.parent} does not exist")
    try:
        con = _connect(p)
        mode = con.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise ResultsDBError(f"results database {p}: WAL mode refused ({mode})")
        _migrate(con, p)
    except sqlite3.DatabaseError as exc:
        raise ResultsDBError(f"results database {p}: {exc}") from exc
    return con


def _migrate(con: sqlite3.Connection, p: Path) -> None:
    version = int(con.execute("PRAGMA user_version").fetchone()[0])
    if version > SCHEMA_VERSION:
        raise ResultsDBError(
            f"results database {p} has schema version {version}, newer than this package's "
            f"{SCHEMA_VERSION}: upgrade pneumatic_unload to read it")
    while version < SCHEMA_VERSION:
        _write(con, lambda c, v=version: _apply(c, MIGRATIONS[v], v + 1))
        version = int(con.execute("PRAGMA user_version").fetchone()[0])


def _apply(con: sqlite3.Connection, script: str, version: int) -> None:
    # inside the caller's transaction: statement by statement (executescript would commit)
    current = int(con.execute("PRAGMA user_version").fetchone()[0])
    if current >= version:  # another writer migrated first
        return
    for stmt in script.split(";"):
        if stmt.strip():
            con.execute(stmt)
    con.execute(f"PRAGMA user_version = {version}")


def _write(con: sqlite3.Connection, body: Any) -> Any:
    """Run ``body(con)`` in one write transaction (the write lock taken up front), retrying
    while another writer holds the lock, up to :data:`BUSY_TIMEOUT` s."""
    deadline = time.monotonic() + BUSY_TIMEOUT
    while True:
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            if "locked" in str(exc) and time.monotonic() < deadline:
                time.sleep(0.05)
                continue
            raise ResultsDBError(f"results database busy for {BUSY_TIMEOUT:g} s: {exc}"
                                 ) from exc
        try:
            out = body(con)
        except BaseException:
            con.execute("ROLLBACK")
            raise
        con.execute("COMMIT")
        return out


def has_file(con: sqlite3.Connection, content_hash: str, settings_hash: str) -> bool:
    """True when an input of this content was analysed with these settings."""
    row = con.execute("SELECT 1 FROM files WHERE content_hash = ? AND settings_hash = ?",
                      (content_hash, settings_hash)).fetchone()
    return row is not None


def known_contents(con: sqlite3.Connection, settings_hash: str) -> frozenset[str]:
    """Content hashes of the inputs analysed with these settings (one query: what a batch
    skips, decided where each input is hashed)."""
    rows = con.execute("SELECT content_hash FROM files WHERE settings_hash = ?",
                       (settings_hash,)).fetchall()
    return frozenset(r[0] for r in rows)


def _num(x: Any) -> Any:
    if isinstance(x, bool):
        return int(x)
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _insert(c: sqlite3.Connection, rec: FileRecord, now: str, replace: bool) -> bool:
    """One input and its unloads, inside the caller's transaction (see :func:`write_files`)."""
    old = c.execute("SELECT id FROM files WHERE content_hash = ? AND settings_hash = ?",
                    (rec.content_hash, rec.settings_hash)).fetchone()
    if old is not None:
        if not replace:
            return False
        c.execute("DELETE FROM unloads WHERE file_id = ?", (old[0],))
        c.execute("DELETE FROM files WHERE id = ?", (old[0],))
    cur = c.execute(
        "INSERT INTO files (path, content_hash, settings_hash, part_id, part_type, "
        "status, reason, n_unloads, settings_json, package_version, analysed_at, "
        "writer) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        (rec.path, rec.content_hash, rec.settings_hash, rec.part_id, rec.part_type,
         rec.status, rec.reason, len(rec.unloads),
         json.dumps(rec.settings, sort_keys=True, default=str), rec.package_version,
         now, rec.writer))
    fid = cur.lastrowid
    names = [n for n, _t in UNLOAD_COLUMNS]
    sql = (f"INSERT INTO unloads (file_id, unload_index, part_id, {', '.join(names)}, "
           "verdict, verdict_reason, budget_json, curve_json, result_json) VALUES "
           f"({', '.join('?' * (len(names) + 8))})")
    c.executemany(sql, [
        (fid, k, rec.part_id, *[_num(u.get(n)) for n in names],
         u.get("verdict"), u.get("verdict_reason"),
         json.dumps(u.get("budget")) if u.get("budget") else None,
         json.dumps(u["curve"]) if u.get("curve") else None,
         json.dumps({key: v for key, v in u.items() if key != "curve"}, sort_keys=True))
        for k, u in enumerate(rec.unloads)])
    return True


def write_files(con: sqlite3.Connection, recs: Sequence[FileRecord], *,
                replace: bool = False) -> list[bool]:
    """Write inputs with their unloads, in the order given, in one transaction: each input
    whole or not at all, and one commit (one sync to disk) for many inputs.

    Returns
    -------
    list of bool
        Per input: True when written; False when the same content and settings are
        already there and ``replace`` is False (nothing changed).

    Raises
    ------
    ResultsDBError
        The database cannot be written (busy beyond :data:`BUSY_TIMEOUT`, disk full, ...).
    """
    if not recs:
        return []
    now = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    try:
        return list(_write(con, lambda c: [_insert(c, r, now, replace) for r in recs]))
    except sqlite3.DatabaseError as exc:
        raise ResultsDBError(f"results database: writing {recs[0].path}"
                             + (f" and {len(recs) - 1} more" if len(recs) > 1 else "")
                             + f": {exc}") from exc


def write_file(con: sqlite3.Connection, rec: FileRecord, *, replace: bool = False) -> bool:
    """Write one input with its unloads in one transaction (see :func:`write_files`).

    Returns
    -------
    bool
        True when written; False when the same content and settings are already there
        and ``replace`` is False (nothing changed).
    """
    return write_files(con, [rec], replace=replace)[0]


def unload_rows(con: sqlite3.Connection, part_id: str | None = None
                ) -> list[dict[str, Any]]:
    """Every unload (with its file's path, hashes and time), in the order written."""
    q = ("SELECT u.*, f.path, f.content_hash, f.settings_hash, f.part_type, "
         "f.analysed_at, f.package_version, f.writer FROM unloads u JOIN files f "
         "ON u.file_id = f.id")
    args: tuple[Any, ...] = ()
    if part_id is not None:
        q += " WHERE u.part_id = ?"
        args = (part_id,)
    cur = con.execute(q + " ORDER BY f.id, u.unload_index", args)
    cols = [d[0] for d in cur.description]
    return [dict(zip(cols, row, strict=True)) for row in cur.fetchall()]


def file_rows(con: sqlite3.Connection) -> list[dict[str, Any]]:
    """Every input (analysed or failed), in the order written."""
    cur = con.execute("SELECT * FROM files ORDER BY id")
    cols = [d[0] for d in cur.description]
    return [dict(zip(cols, row, strict=True)) for row in cur.fetchall()]


EXPORT_COLUMNS: tuple[str, ...] = (
    "part_id", "path", "unload_index", *[n for n, _t in UNLOAD_COLUMNS], "verdict",
    "verdict_reason", "content_hash", "settings_hash", "part_type", "analysed_at",
    "package_version", "writer")


def export(con: sqlite3.Connection, out: str | Path) -> int:
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
