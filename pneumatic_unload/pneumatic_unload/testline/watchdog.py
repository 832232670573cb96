# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A deadline on a database server's answers: the connections of an engine and a timer
that shuts their sockets down when one operation outlives it, so that a call blocked on a
PostgreSQL server that does not answer (stopped processes, a frozen virtual machine, a
network gone) returns with a clear error instead of hanging the batch or the node.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import threading
import time
import weakref
from collections.abc import Iterator
from typing import Any

import sqlalchemy as sa

from pneumatic_unload.testline.redact import redact
from pneumatic_unload.testline.schema import ResultsDBError, one_line

#: Longest one operation of :class:`~.db.ResultsDB` (a query, a write with its retries) waits for a
#: PostgreSQL server's answers [s] before it fails with a ResultsDBError (a new connection's wait
#: included, at least :data:`LIBPQ_MIN_CONNECT` s). A server whose processes are stopped (SIGSTOP, a
#: frozen virtual machine) never answers while its host's kernel still acknowledges every packet, so
#: neither TCP keepalives nor ``statement_timeout`` end the wait: this deadline does, by shutting
#: the connections' sockets down. Above :data:`BUSY_TIMEOUT` (a write's retries) and the server's
#: STATEMENT_TIMEOUT.
ANSWER_TIMEOUT = 90.0
#: The shortest connect_timeout libpq takes [s] (it counts whole seconds, 1 read as 2): a
#: new connection within a deadline waits what is left of it, rounded up, but not less.
LIBPQ_MIN_CONNECT = 2


class Watchdog:
    """The DBAPI connections of an engine (each registered as it connects) and a deadline
    that shuts their sockets down when an operation outlives it: a call blocked on a
    server that does not answer then returns with an error."""

    def __init__(self, engine: sa.Engine) -> None:
        self.conns: weakref.WeakSet[Any] = weakref.WeakSet()
        self.lock = threading.Lock()
        #: The calling thread's deadline [s, monotonic] while it runs a block of
        #: :meth:`deadline`.
        self._ends = threading.local()
        if engine.dialect.name == "postgresql":
            sa.event.listen(engine, "connect", self._on_connect)
            sa.event.listen(engine, "do_connect", self._on_do_connect)

    def _on_do_connect(self, _dialect: Any, _record: Any, _cargs: Any,
                       cparams: dict[str, Any]) -> None:
        """A connection made within a deadline waits what is left of it (its socket is
        not registered, so not shut down, until it has connected); none is tried past it
        (a write's retry after the deadline shut its connection down)."""
        end = getattr(self._ends, "end", None)
        if end is None:
            return
        left = end - time.monotonic()
        if left <= 0.0:
            raise TimeoutError("the deadline passed before a new connection")
        cparams["connect_timeout"] = max(LIBPQ_MIN_CONNECT, min(
            int(cparams.get("connect_timeout", math.ceil(left))), math.ceil(left)))

    def _on_connect(self, dbapi_con: Any, _record: Any) -> None:
        with self.lock:
            self.conns.add(dbapi_con)

    def _shut_down(self) -> None:
        with self.lock:
            conns = list(self.conns)
        for c in conns:
            with contextlib.suppress(Exception):  # closed meanwhile: nothing to wake
                fd = os.dup(c.fileno())
                with socket.socket(fileno=fd) as sock:
                    sock.shutdown(socket.SHUT_RDWR)

    @contextlib.contextmanager
    def deadline(self, seconds: float | None, label: str, what: str,
                 target: str) -> Iterator[None]:
        """Run the block within ``seconds`` (None: no deadline); past it, a ResultsDBError
        saying that the server did not answer (``target``'s password masked)."""
        if seconds is None:
            yield
            return
        fired = threading.Event()
        end = time.monotonic() + seconds
        outer = getattr(self._ends, "end", None)
        self._ends.end = end if outer is None else min(end, outer)

        def fire() -> None:
            fired.set()
            self._shut_down()

        timer = threading.Timer(seconds, fire)
        timer.daemon = True
        timer.start()
        try:
            yield
        except Exception as exc:
            # past the deadline (a connection that waited what was left of it may fail
            # just before the timer's thread has fired)
            if fired.is_set() or time.monotonic() >= end:
                raise ResultsDBError(redact(
                    f"results database {label}: no answer from the server within "
                    f"{seconds:g} s while {what} (the server stopped, or the network to it "
                    f"is gone): {one_line(exc)}", target)) from exc
            raise
        finally:
            timer.cancel()
            self._ends.end = outer
