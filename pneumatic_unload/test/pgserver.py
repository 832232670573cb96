# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A throw-away PostgreSQL server for the tests, from Debian's ``postgresql`` package.

:func:`pg_server` (session fixture, registered in conftest.py) installs the package when
``initdb``/``pg_ctl`` are missing (``apt-get install -y -qq postgresql``; root needed), makes
a cluster in a temporary folder owned by the ``postgres`` user (PostgreSQL refuses to run as
root: its commands run through ``runuser -u postgres``), starts it on a free port of
127.0.0.1 with its unix socket in that folder, and stops and removes it at the end. Trust
authentication, except the role ``bench`` (password :data:`BENCH_PASSWORD`) over TCP, which
needs its password. No durability (fsync off): a test server. The tests that need it skip,
with the reason, only where it cannot be installed or started. :func:`pg_url` gives each
test a new empty database.
"""

from __future__ import annotations

import glob
import itertools
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

#: Password of the role ``bench`` (scram-sha-256 over TCP).
BENCH_PASSWORD = "bench-secret"
_HBA = """\
local all all trust
host all bench 127.0.0.1/32 scram-sha-256
host all all 127.0.0.1/32 trust
"""


def _bin_dir() -> Path | None:
    """The folder of initdb and pg_ctl (the newest of /usr/lib/postgresql/*/bin)."""
    found = shutil.which("pg_ctl")
    if found and shutil.which("initdb"):
        return Path(found).resolve().parent
    cands = glob.glob("/usr/lib/postgresql/*/bin/pg_ctl")
    cands.sort(key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    return Path(cands[-1]).parent if cands else None


#: The environment variable that lets the tests install Debian's postgresql (``1``): set
#: by ``make test`` and ``.ci/run``; without it (``colcon test``, a user's container) no
#: system package is installed and the PostgreSQL tests are skipped with the reason.
INSTALL_ENV = "PNEUMATIC_UNLOAD_TEST_INSTALL_POSTGRES"


def _install() -> str:
    """Install Debian's postgresql when :data:`INSTALL_ENV` asks; '' on success, else why
    not."""
    if os.environ.get(INSTALL_ENV) != "1":
        return (f"PostgreSQL is not installed (set {INSTALL_ENV}=1 to let the tests "
                "install Debian's postgresql with apt-get)")
    if os.geteuid() != 0:
        return "PostgreSQL is not installed and installing it needs root (apt-get)"
    if not shutil.which("apt-get"):
        return "PostgreSQL is not installed and there is no apt-get to install it"
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    cmd = ["apt-get", "install", "-y", "-qq", "postgresql"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    if r.returncode != 0:  # a fresh machine: the package lists first
        subprocess.run(["apt-get", "update", "-qq"], capture_output=True, env=env, timeout=600)
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    if r.returncode != 0:
        return f"apt-get install postgresql failed: {(r.stderr or r.stdout).strip()[-300:]}"
    return ""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class PgServer:
    """A running throw-away cluster (see the module doc)."""

    root: Path
    bin: Path
    port: int
    as_postgres: list[str]

    def url(self, db: str, user: str = "postgres", password: str = "") -> str:
        """``postgresql://USER[:PASSWORD]@127.0.0.1:PORT/DB``."""
        auth = f"{user}:{password}" if password else user
        return f"postgresql://{auth}@127.0.0.1:{self.port}/{db}"

    def sql(self, statement: str, db: str = "postgres") -> list[tuple]:
        """Run one statement as the superuser (autocommit); its rows."""
        import psycopg

        with psycopg.connect(host="127.0.0.1", port=self.port, user="postgres", dbname=db,
                             autocommit=True) as con:
            cur = con.execute(statement)
            return cur.fetchall() if cur.description else []

    def stop(self) -> None:
        subprocess.run([*self.as_postgres, str(self.bin / "pg_ctl"), "-D",
                        str(self.root / "data"), "-m", "immediate", "-w", "stop"],
                       capture_output=True, timeout=60)
        shutil.rmtree(self.root, ignore_errors=True)


def start_server() -> PgServer | str:
    """A new cluster, started; or why it cannot be."""
    bindir = _bin_dir()
    if bindir is None:
        why = _install()
        if why:
            return why
        bindir = _bin_dir()
        if bindir is None:
            return "apt-get installed postgresql but no initdb/pg_ctl was found"
    as_postgres: list[str] = []
    root = Path(tempfile.mkdtemp(prefix="pu-pg-"))
    if os.geteuid() == 0:
        try:
            import pwd

            pw = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(root)
            return "no 'postgres' user to run the server as (PostgreSQL refuses root)"
        os.chown(root, pw.pw_uid, pw.pw_gid)
        as_postgres = ["runuser", "-u", "postgres", "--"]
    os.chmod(root, 0o700)
    data, port = root / "data", _free_port()
    r = subprocess.run([*as_postgres, str(bindir / "initdb"), "-D", str(data), "-U",
                        "postgres", "--auth=trust", "--no-sync", "-E", "UTF8", "--no-locale"],
                       capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        shutil.rmtree(root, ignore_errors=True)
        return f"initdb failed: {(r.stderr or r.stdout).strip()[-300:]}"
    (data / "pg_hba.conf").write_text(_HBA)
    opts = (f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off "
            "-c synchronous_commit=off -c full_page_writes=off -c max_connections=200")
    r = subprocess.run([*as_postgres, str(bindir / "pg_ctl"), "-D", str(data), "-l",
                        str(root / "server.log"), "-w", "-t", "60", "-o", opts, "start"],
                       capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        log = (root / "server.log").read_text(errors="replace") \
            if (root / "server.log").exists() else ""
        shutil.rmtree(root, ignore_errors=True)
        return f"PostgreSQL did not start: {(r.stderr + log).strip()[-300:]}"
    server = PgServer(root, bindir, port, as_postgres)
    server.sql(f"CREATE ROLE bench LOGIN PASSWORD '{BENCH_PASSWORD}'")
    return server


@pytest.fixture(scope="session")
def pg_server() -> Iterator[PgServer]:
    """The test session's PostgreSQL server (skips with the reason when there is none)."""
    server = start_server()
    if isinstance(server, str):
        pytest.skip(server)
    try:
        yield server
    finally:
        server.stop()


_DB_NUMBERS = itertools.count()


@pytest.fixture()
def pg_url(pg_server: PgServer) -> str:
    """The URL of a new, empty database on the session's server (owner postgres)."""
    name = f"t{os.getpid()}_{next(_DB_NUMBERS)}"
    pg_server.sql(f"CREATE DATABASE {name}")
    return pg_server.url(name)
