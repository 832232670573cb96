# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The results database on a server (#27): one schema and its Alembic migrations for SQLite
and PostgreSQL, double precision, results/report on a URL, clear errors, and many writers
at once (processes, batches, two estimator nodes over DDS) losing and duplicating nothing.

PostgreSQL is a real server of Debian's package, started for the session (pgserver.py)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import re
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
import sqlalchemy as sa
from dbwriters import open_at, record, write_rounds
from pgserver import BENCH_PASSWORD, PgServer

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.testline import ResultsDBError, open_db, unload_rows
from pneumatic_unload.testline.db import file_rows, write_files
from pneumatic_unload.testline.schema import (
    FILES,
    HEAD,
    MIGRATIONS_DIR,
    REVISIONS,
    SCHEMA_VERSION,
    UNLOADS,
)

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

LEGACY = Path(__file__).parent / "data" / "results_db"
RUN = [sys.executable, "-m", "pneumatic_unload.app.cli"]
#: Values a single-precision (REAL) column would change, and awkward doubles.
DOUBLES = (8.001371402e-9, 0.1 + 0.2, 1.0 / 3.0, 1.7976931348623157e308, -2.2250738585072014e-308)


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Eight short bags of four parts (C 5e-9 .. 6.5e-9 m^3/(s Pa))."""
    d = tmp_path_factory.mktemp("bags")
    for k in range(8):
        cfg = RigConfig(volume=1e-3, conductance=5e-9 + 5e-10 * (k % 4), duration=2.5,
                        pre_time=0.3, noise_std=500.0, seed=k)
        write_simulated_bag(cfg, d / f"V14-00{k % 4}_run{k // 4}", analyze_live=False)
    return d


@pytest.fixture(params=["sqlite", "postgresql"])
def target(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A new results database of each backend."""
    if request.param == "sqlite":
        return str(tmp_path / "r.sqlite")
    return request.getfixturevalue("pg_url")


def _alembic(con: object, action: str, rev: str) -> None:
    from alembic import command
    from alembic.config import Config

    with con.engine.connect() as conn, conn.begin():
        cfg = Config()
        cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
        cfg.attributes["connection"] = conn
        getattr(command, action)(cfg, rev)


# ------------------------------------------------------------------ schema and migrations


@pytest.mark.parametrize("version", [1, 2, 3])
def test_a_sqlite_file_of_the_package_before_alembic_migrates_with_its_rows(
        tmp_path: Path, version: int):
    """A file written by the package's own db.py at schema 1, 2 or 3 (make_legacy.py) opens:
    stamped at its revision, upgraded, its rows and their doubles kept; the old package can
    still read it (user_version in step)."""
    db = tmp_path / "old.sqlite"
    shutil.copy(LEGACY / f"schema{version}.sqlite", db)
    with sqlite3.connect(db) as raw:
        assert raw.execute("PRAGMA user_version").fetchone()[0] == version
        assert raw.execute("SELECT count(*) FROM sqlite_master WHERE name = "
                           "'alembic_version'").fetchone()[0] == 0
    with open_db(db) as con:
        rows = unload_rows(con)
        assert [r["recommended_conductance"] for r in rows] == [8.001371402e-9, 0.1 + 0.2]
        assert [r["part_id"] for r in rows] == ["V14-000", "V14-001"]
        assert rows[0]["tau_exp"] == 0.123456789012345
        assert [r["direction"] for r in rows] == (
            ["discharge", "charge"] if version == 3 else [None, None])
        assert [r["subsonic_index"] for r in rows] == [0.5, 0.5] if version >= 2 else \
            [None, None]
        assert [f["package_version"] for f in file_rows(con)] == [f"schema-{version}"] * 2
        assert write_files(con, [record("new", 7e-9)]) == [True]
    raw = sqlite3.connect(db)
    assert raw.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert raw.execute("SELECT version_num FROM alembic_version").fetchone()[0] == HEAD
    assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert raw.execute("SELECT count(*) FROM unloads").fetchone()[0] == 3
    raw.close()


def test_migrations_on_both_backends(target: str):
    """A new database is at HEAD with the package's tables; down to schema 1 with a row and
    up again on open keeps the row; a newer revision is refused."""
    assert REVISIONS[SCHEMA_VERSION - 1] == HEAD
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    script = ScriptDirectory.from_config(cfg)
    assert script.get_current_head() == HEAD
    assert [r.revision for r in reversed(list(script.walk_revisions()))] == list(REVISIONS)
    con = open_db(target)
    insp = sa.inspect(con.engine)
    for table in (FILES, UNLOADS):  # the migrated tables are the package's schema
        cols = {c["name"]: c["type"] for c in insp.get_columns(table.name)}
        assert list(cols) == [c.name for c in table.columns]
    # floats are double precision (on PostgreSQL: DOUBLE PRECISION, not REAL)
    ctype = {c["name"]: c["type"] for c in insp.get_columns("unloads")}
    assert isinstance(ctype["recommended_conductance"], sa.Double)
    if con.backend == "postgresql":
        assert ctype["supply_pressure"].compile(dialect=con.engine.dialect) == \
            "DOUBLE PRECISION"
    _alembic(con, "downgrade", "0001")
    assert "subsonic_index" not in {c["name"] for c in sa.inspect(con.engine).get_columns(
        "unloads")}
    with con.engine.begin() as conn:  # a row written at schema 1
        fid = conn.execute(sa.text(
            "INSERT INTO files (path, content_hash, settings_hash, part_id, status, "
            "n_unloads, package_version, analysed_at, writer) VALUES ('old', 'h1', 's', "
            "'P', 'ok', 1, 'v1', 'then', 'batch') RETURNING id")).scalar()
        conn.execute(sa.text(
            "INSERT INTO unloads (file_id, unload_index, part_id, recommended_conductance, "
            "result_json) VALUES (:f, 0, 'P', :c, '{}')"), {"f": fid, "c": DOUBLES[0]})
    con.close()
    with open_db(target) as con:  # upgraded when opened, the row kept
        (row,) = unload_rows(con)
        assert row["recommended_conductance"] == DOUBLES[0] and row["direction"] is None
        with con.engine.begin() as conn:
            conn.execute(sa.text("UPDATE alembic_version SET version_num = '9999'"))
    with pytest.raises(ResultsDBError, match="newer than this package"):
        open_db(target)


def test_doubles_round_trip_exactly(target: str):
    with open_db(target) as con:
        assert write_files(con, [record(f"k{k}", c, tau_exp=c) for k, c in
                                 enumerate(DOUBLES)]) == [True] * len(DOUBLES)
        rows = unload_rows(con)
    assert [r["recommended_conductance"] for r in rows] == list(DOUBLES)
    assert [r["tau_exp"] for r in rows] == list(DOUBLES)
    assert rows[1]["recommended_conductance"] == 0.30000000000000004


# ------------------------------------------------------------------------ commands, errors


def test_batch_results_and_report_on_a_url(bags: Path, pg_url: str, tmp_path: Path):
    two = [str(bags / "V14-000_run0"), str(bags / "V14-001_run0")]
    r = subprocess.run([*RUN, "batch", *two, "--db", pg_url, "--workers", "1",
                        "--part-regex", r"(V14-\d+)", "--json"],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["analysed"] == 2
    r = subprocess.run([*RUN, "results", "parts", "--db", pg_url, "--json"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    parts = {p["part_id"]: p for p in json.loads(r.stdout)}
    assert set(parts) == {"V14-000", "V14-001"}
    assert parts["V14-001"]["conductance_mean"] == pytest.approx(5.5e-9, rel=0.02)
    r = subprocess.run([*RUN, "results", "export", "--db", pg_url, "--out",
                        str(tmp_path / "u.csv")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "u.csv").read_text().count("\n") == 3
    r = subprocess.run([*RUN, "report", "--db", pg_url, "--out", str(tmp_path / "r.html")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "2 unload(s) from 2 input(s)" in r.stdout
    assert "V14-001" in (tmp_path / "r.html").read_text()


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_bad_databases_are_one_line_errors(pg_server: PgServer, pg_url: str, bags: Path,
                                           tmp_path: Path):
    """Nothing listening, an unknown scheme, a bad URL, a wrong password, no such database,
    no such file, no driver, a server without results: one line each, the password never
    shown; the commands exit 2 without a traceback."""
    dead = f"postgresql://postgres@127.0.0.1:{_free_port()}/results"
    wrong = pg_server.url("postgres", "bench", "wrong-secret")
    cases = {
        dead: "Connection refused",
        "mysql://u@localhost/results": "unknown scheme 'mysql'",
        "postgresql://u@localhost:notaport/results": "not a database URL",
        "postgresql://u@localhost:5432": "no database name",
        wrong: 'password authentication failed for user "bench"',
        pg_server.url("no_such_db"): 'database "no_such_db" does not exist',
        str(tmp_path / "missing" / "r.sqlite"): "does not exist",
    }
    for url, why in cases.items():
        with pytest.raises(ResultsDBError) as err:
            open_db(url)
        msg = str(err.value)
        assert why in msg and "\n" not in msg and "wrong-secret" not in msg, msg
    # the right password opens it (a database the role owns: its tables made there)
    pg_server.sql(f"CREATE DATABASE bench_{_free_port()} OWNER bench")
    name = pg_server.sql("SELECT datname FROM pg_database WHERE datname LIKE 'bench_%'")[0][0]
    with open_db(pg_server.url(name, "bench", BENCH_PASSWORD)) as con:
        assert write_files(con, [record("k", 5e-9)]) == [True]
        assert "bench-secret" not in con.label and "***" in con.label
    # a server without the tables is no results database for the reading commands
    with pytest.raises(ResultsDBError, match="no results there yet"):
        open_db(pg_url, create=False)
    for args, why in (
            (["results", "parts", "--db", dead], "Connection refused"),
            (["report", "--db", wrong, "--out", str(tmp_path / "r.html")],
             "password authentication failed"),
            (["batch", str(bags), "--db", "mysql://u@h/db"], "unknown scheme"),
            (["results", "parts", "--db", str(tmp_path / "none.sqlite")],
             "no such database")):
        r = subprocess.run([*RUN, *args], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.startswith("pneumatic-unload: error:") and why in r.stderr, r.stderr
        assert r.stderr.count("\n") == 1 and "wrong-secret" not in r.stderr, r.stderr
    # without the driver (psycopg not installed): the reason and what to install
    code = ("import sys; sys.modules['psycopg'] = None; "
            "from pneumatic_unload.testline import open_db, ResultsDBError\n"
            f"try: open_db({pg_url!r})\nexcept ResultsDBError as e: print(e)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60)
    assert "PostgreSQL driver is missing" in r.stdout and "psycopg[binary]" in r.stdout, r


# ----------------------------------------------------------------- many writers at once


def test_openers_at_once_create_the_schema_once(pg_url: str):
    """Six processes open an empty database at the same instant: each succeeds (the
    advisory lock: CREATE TABLE of two transactions at once collides on pg_type)."""
    ctx = mp.get_context("spawn")
    t0 = time.time() + 2.0  # every process imported and waiting by then
    procs = [ctx.Process(target=open_at, args=(pg_url, t0)) for _ in range(6)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0] * 6
    with open_db(pg_url) as con, con.engine.connect() as conn:
        assert conn.execute(sa.text("SELECT version_num FROM alembic_version")).all() == \
            [(HEAD,)]


def test_writers_at_once_lose_nothing_and_duplicate_nothing(target: str):
    """Four processes write, at the same instants, ten rounds of 40 shared inputs (in
    different orders: on PostgreSQL two transactions then wait for each other's rows and
    the server aborts one as a deadlock, which is run again) and 5 of their own each: every
    input once with its unload, and the writers' "written" answers add up to the inputs."""
    open_db(target).close()
    shared = [f"{k:02d}" for k in range(40)]
    orders = [shared, shared[::-1], shared[20:] + shared[:20], shared[::2] + shared[1::2]]
    rounds = [[[f"r{i}-{k}" for k in orders[w]] + [f"own-{w}-{i}-{k}" for k in range(5)]
               for i in range(10)] for w in range(4)]
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    t0 = time.time() + 2.0  # every process imported and waiting by then
    procs = [ctx.Process(target=write_rounds, args=(target, w, rounds[w], t0, 0.05, out))
             for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0] * 4
    expected = {key for r in rounds for keys in r for key in keys}
    assert len(expected) == 10 * (40 + 4 * 5)
    assert sum(out.get(timeout=10) for _ in procs) == len(expected)
    with open_db(target) as con:
        files, rows = file_rows(con), unload_rows(con)
    assert sorted(f["content_hash"] for f in files) == sorted(expected)
    assert len(rows) == len(files) and {r["file_id"] for r in rows} == {f["id"] for f in files}


def test_two_batches_at_once_on_an_empty_database(bags: Path, pg_url: str):
    """Two batches of the same eight inputs start at once on an empty database: both
    succeed, the schema is made once, every input is there once (analysed by one batch,
    skipped by the other)."""
    cmd = [*RUN, "batch", str(bags), "--db", pg_url, "--workers", "1", "--part-regex",
           r"(V14-\d+)", "--json"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [e for _o, e in outs]
    summaries = [json.loads(o) for o, _e in outs]
    assert sum(s["analysed"] for s in summaries) == 8
    assert all(s["analysed"] + len(s["skipped"]) == 8 for s in summaries)
    with open_db(pg_url) as con:
        files, rows = file_rows(con), unload_rows(con)
    assert sorted(Path(f["path"]).name for f in files) == sorted(
        p.name for p in bags.iterdir())
    assert len(rows) == 8 and len({(r["file_id"], r["unload_index"]) for r in rows}) == 8


def test_two_benches_and_a_batch_write_at_once(bags: Path, pg_url: str, tmp_path: Path):
    """Done means (#27): two estimator nodes (real ROS 2 nodes over DDS, fed by one
    simulator's cycles) with results_db on the same PostgreSQL, and a batch, write at once:
    every unload once, none lost."""
    pytest.importorskip("rclpy")
    from nodeproc import NodeProcess

    cycles = 3
    sim = NodeProcess("simulator", {
        "volume": 1e-3, "conductance": 8e-9, "critical_ratio": 0.4, "noise_std": 1000.0,
        "seed": 3, "mode": "cycle", "cycles": cycles, "settle_time": 1.0, "duration": 2.5,
        "vent_time": 0.3, "charge_time": 0.3, "wait_for_subscribers": 2}, tmp_path)
    benches = {name: NodeProcess("estimator", {
        "volume": 1e-3, "curve_fit": False, "results_db": pg_url, "part_id": f"P-{name}"},
        tmp_path, extra=["-r", f"__node:={name}"]) for name in ("bench_a", "bench_b")}
    cmd = [*RUN, "batch", str(bags), "--db", pg_url, "--workers", "1", "--json"]
    batches: list[subprocess.Popen] = []
    try:
        for est in benches.values():
            est.wait_output(r"estimating on", 60.0)
        sim.wait_output(r"streaming at", 60.0)
        # batches write all along: the first analyses the inputs, the next ones (--force)
        # write them again, replacing them, until both benches have measured every cycle
        batches.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True))
        deadline = time.monotonic() + 120.0
        while not all(re.search(rf"\[{name}\]: unload {cycles - 1}: ", est.output())
                      for name, est in benches.items()):
            assert time.monotonic() < deadline, [e.output()[-2000:] for e in benches.values()]
            assert all(e.proc.poll() is None for e in benches.values())
            if batches[-1].poll() is not None:
                batches.append(subprocess.Popen([*cmd, "--force"], stdout=subprocess.PIPE,
                                                stderr=subprocess.PIPE, text=True))
            time.sleep(0.1)
        outs = [b.communicate(timeout=300) for b in batches]
    finally:
        for b in batches:
            if b.poll() is None:
                b.kill()
        codes = [p.stop() for p in (sim, *benches.values())]
    assert codes == [0, 0, 0], codes
    assert [b.returncode for b in batches] == [0] * len(batches), [e for _o, e in outs]
    assert [json.loads(o)["analysed"] for o, _e in outs] == [8] * len(batches)
    with open_db(pg_url) as con:
        files, rows = file_rows(con), unload_rows(con)
    for name, est in benches.items():
        log = est.output()
        assert "not written" not in log, log[-3000:]
        logged = {int(k) for k in re.findall(rf"\[{name}\]: unload (\d+): ", log)}
        assert logged == set(range(cycles)), log[-3000:]
        mine = [r for r in rows if r["writer"] == name]
        # every unload the bench analysed is there once, under the bench's part id
        assert sorted(json.loads(r["result_json"])["index"] for r in mine) == \
            sorted(logged)
        assert {r["part_id"] for r in mine} == {f"P-{name}"}
        assert all(r["recommended_conductance"] == pytest.approx(8e-9, rel=0.1) for r in mine)
    batch_files = [f for f in files if f["writer"] == "batch"]
    assert sorted(Path(f["path"]).name for f in batch_files) == sorted(
        p.name for p in bags.iterdir())
    assert len(rows) == 2 * cycles + 8 == len(files)


@pytest.mark.parametrize(("version", "refused"), [("1.4.54", True), ("1.3.24", True),
                                                  ("2.0.0", False), ("2.1.0b1", False)])
def test_an_sqlalchemy_below_the_floor_is_refused_with_what_to_install(
        version: str, refused: bool) -> None:
    """Ubuntu 24.04's python3-sqlalchemy is 1.4: the schema module imports (a node with
    no results database starts), opening a database says which SQLAlchemy it needs."""
    from pneumatic_unload.testline import schema

    if refused:
        with pytest.raises(schema.ResultsDBError, match=r"SQLAlchemy >= 2\.0.*pip install"):
            schema.check_sqlalchemy(version)
    else:
        schema.check_sqlalchemy(version)


def test_the_schema_imports_with_sqlalchemy_1_4(tmp_path: Path) -> None:
    """The results layer imports under SQLAlchemy 1.4 (no ``sa.Double`` there): a stand-in
    ``sqlalchemy`` module of the real one without ``Double`` and with ``__version__``
    1.4.54; opening a database is refused with the floor's message."""
    shim = tmp_path / "shim"
    (shim / "sqlalchemy").mkdir(parents=True)
    # the real package's modules under the stand-in name: only Double and the version differ
    import sqlalchemy

    real = Path(sqlalchemy.__file__).parent
    (shim / "sqlalchemy" / "__init__.py").write_text(
        f"__path__ = [{str(real)!r}]\n"
        f"exec(compile(open({str(real / '__init__.py')!r}).read(), 'sqlalchemy', 'exec'))\n"
        "del Double\n__version__ = '1.4.54'\n")
    code = ("import pneumatic_unload.testline, pneumatic_unload.testline.live\n"
            "from pneumatic_unload.testline.schema import ResultsDBError, database_url\n"
            "try:\n    database_url('x.db')\nexcept ResultsDBError as e:\n    print(e)\n")
    root = Path(__file__).resolve().parents[1]
    env = {"PYTHONPATH": f"{shim}{os.pathsep}{root}", "PATH": os.environ.get("PATH", "")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "needs SQLAlchemy >= 2.0, this Python has 1.4.54" in out.stdout
