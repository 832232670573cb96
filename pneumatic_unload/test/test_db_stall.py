# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A results database server that stalls, and passwords in messages: a stopped PostgreSQL
(SIGSTOP: its kernel still acknowledges every packet) ends each operation with a clear
error within the timeout; no message shows a URL's password, whatever the URL's form.

PostgreSQL is a real server of Debian's package (pgserver.py): the session's, and for the
stopped server one of its own."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from dbwriters import record
from pgserver import BENCH_PASSWORD, PgServer, start_server

from pneumatic_unload.testline import ResultsDBError, open_db
from pneumatic_unload.testline.db import write_files
from pneumatic_unload.testline.redact import redact, secrets_of
from pneumatic_unload.testline.schema import FILES, hide_password
from pneumatic_unload.testline.watchdog import LIBPQ_MIN_CONNECT

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

RUN = [sys.executable, "-m", "pneumatic_unload.app.cli"]
#: The deadline the tests give an operation [s].
TIMEOUT = 3.0
#: Longest a test waits for an operation that should fail within TIMEOUT before calling it
#: a hang [s]. Without the deadline the operation never returns.
HANG = 60.0
#: How far past its deadline (at least libpq's 2 s for a new connection) an operation may
#: return [s]: the timer's thread and the error's path on a loaded machine.
LATE = 2.0


def _family(pid: int) -> list[int]:
    """``pid`` and its descendants (the postmaster and its backends)."""
    out = [pid]
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            out += _family(int(child))
    return out


@pytest.fixture()
def own_server() -> Iterator[PgServer]:
    server = start_server()
    if isinstance(server, str):
        pytest.skip(server)
    try:
        yield server
    finally:
        pid = int((server.root / "data" / "postmaster.pid").read_text().split()[0])
        for p in _family(pid):
            try:
                os.kill(p, signal.SIGCONT)
            except ProcessLookupError:
                pass
        server.stop()


def _stop(server: PgServer) -> list[int]:
    pid = int((server.root / "data" / "postmaster.pid").read_text().split()[0])
    pids = _family(pid)
    for p in pids:
        os.kill(p, signal.SIGSTOP)
    return pids


def _outcome(fn: object, deadline: float = TIMEOUT) -> BaseException | None:
    """What ``fn()`` raised (None: it returned); fails the test if it hangs past HANG or
    returns more than LATE s after ``deadline`` [s] (or libpq's shortest connect wait)."""
    box: list[BaseException | None] = []
    start = time.monotonic()

    def run() -> None:
        try:
            fn()  # type: ignore[operator]
            box.append(None)
        except BaseException as exc:
            box.append(exc)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(HANG)
    assert box, f"hung for more than {HANG} s"
    took = time.monotonic() - start
    assert took < max(deadline, LIBPQ_MIN_CONNECT) + LATE, f"{took:.1f} s for {deadline} s"
    return box[0]


def test_a_stopped_server_fails_each_operation_within_the_timeout(own_server: PgServer):
    own_server.sql("CREATE DATABASE r")
    con = open_db(own_server.url("r"), timeout=TIMEOUT)
    assert write_files(con, [record("a", 5e-9)]) == [True]  # a pooled connection
    _stop(own_server)
    for what, fn in (("writing", lambda: write_files(con, [record("b", 5e-9)])),
                     ("reading", lambda: con.rows(sa.select(FILES.c.path)))):
        exc = _outcome(fn)
        assert isinstance(exc, ResultsDBError), exc
        assert f"no answer from the server within {TIMEOUT:g} s while {what}" in str(exc)
        assert "\n" not in str(exc)
    # a caller's own deadline (a node's callback): a write that gives up in 1 s
    exc = _outcome(lambda: write_files(con, [record("c", 5e-9)], timeout=1.0), 1.0)
    assert isinstance(exc, ResultsDBError), exc
    exc = _outcome(lambda: open_db(own_server.url("r"), timeout=TIMEOUT))
    assert isinstance(exc, ResultsDBError) and "while opening" in str(exc), exc
    con.close()


def test_statement_timeout_and_keepalives_are_set(pg_url: str):
    con = open_db(pg_url)
    try:
        with con.engine.connect() as c:
            assert c.exec_driver_sql("SHOW statement_timeout").scalar() == "30s"
            opts = c.connection.dbapi_connection.info.get_parameters()  # psycopg's conninfo
            assert opts["keepalives"] == "1" and opts["keepalives_idle"] == "10", opts
            assert opts["keepalives_count"] == "3" and opts["tcp_user_timeout"] == "25000"
    finally:
        con.close()


SECRET = "Zq9-secret"


def test_no_password_in_any_message(pg_server: PgServer, tmp_path: Path):
    port = pg_server.port
    urls = [
        f"postgresql://bench:{SECRET}@127.0.0.1:{port}/postgres",  # wrong password
        f"postgresql://bench@127.0.0.1:{port}/postgres?password={SECRET}",
        f"postgresql://bench@127.0.0.1:{port}/postgres?sslmode=disable&PASSWORD={SECRET}",
        f"postgresql://bench:pre@{SECRET}@127.0.0.1:{port}/postgres",  # a raw @
        f"postgresql://bench:{SECRET}@127.0.0.1:notaport/postgres",
        f"postgres://bench:{SECRET}@127.0.0.1:{port}",  # no database
        f"mysql://bench:{SECRET}@127.0.0.1/x",
    ]
    for url in urls:
        with pytest.raises(ResultsDBError) as err:
            open_db(url, timeout=TIMEOUT)
        msg = str(err.value)
        assert SECRET not in msg and "secret" not in msg, msg
        assert "\n" not in msg
        assert SECRET not in hide_password(url)
        r = subprocess.run([*RUN, "results", "parts", "--db", url], capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert "secret" not in r.stderr and "secret" not in r.stdout, r.stderr
    # the right password in the query form connects (a server without results tables:
    # refused after the login), and neither the message nor the label shows it
    good = f"postgresql://bench@127.0.0.1:{port}/postgres?password={BENCH_PASSWORD}"
    with pytest.raises(ResultsDBError, match="no results there yet") as err:
        open_db(good, create=False)
    assert BENCH_PASSWORD not in str(err.value) and "password=***" in str(err.value)


def test_redact_masks_every_reading_of_the_password():
    url = "postgresql://u:p@ss-Word@db.example:5432/r?password=Q%40z"
    assert set(secrets_of(url)) == {"p@ss-Word", "Q%40z", "Q@z"}
    text = ('could not translate host name "ss-Word@db.example" to address; '
            "postgresql://u:p@ss-Word@db.example:5432/r?password=Q%40z; password Q@z")
    out = redact(text, url)
    assert "ss-Word" not in out and "Q@z" not in out and "Q%40z" not in out, out
    assert out.startswith('could not translate host name "***@db.example"'), out
    assert "postgresql://u:***@db.example:5432/r?password=***" in out, out
    assert redact("nothing secret", "/a/results.sqlite") == "nothing secret"
