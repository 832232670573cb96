# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A live estimator's final estimates in the results database, judged against a spec.

:class:`LiveResults` is what the estimator node holds when its ``results_db`` parameter is
set: each final estimate becomes one row of ``files`` (path ``live:<node>``, a content
hash made of the node, the unload's start and index: a later estimate of the same unload
replaces the earlier) and one of ``unloads``,
with the part id of the running ``measure`` goal or of the node's ``part_id`` parameter,
and the verdict of the part's type in the specification. The database is shared: batches
and other nodes may write at the same time (see :mod:`~.db`); the database stays open (a
small pool of connections) for the node's life. SI units. :class:`ResultWriter` makes
the writes on a thread of their own (the node's callbacks never wait for the database).
"""

from __future__ import annotations

import hashlib
import json
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pneumatic_unload import __version__
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.types import ESTIMATE_STATUSES, UnloadResult
from pneumatic_unload.testline.db import FileRecord, open_db, write_file
from pneumatic_unload.testline.job import result_row, settings_json
from pneumatic_unload.testline.spec import Spec


class LiveResults:
    """The results database of a live estimator (see the module doc).

    Parameters
    ----------
    db_path : str or Path
        The results database: a SQLite file (created when missing) or a PostgreSQL URL.
    writer : str
        Who writes (the node's name).
    spec : Spec, optional
        Specification of the part types (None: no verdicts).

    Raises
    ------
    ResultsDBError
        The database cannot be used.
    """

    def __init__(self, db_path: str | Path, writer: str, spec: Spec | None = None) -> None:
        self.db_path = str(db_path)  # a URL is no Path (its // would be lost)
        self.writer = writer
        self.spec = spec
        self.db = open_db(self.db_path)  # created (or migrated) now: errors at start-up

    def judge(self, r: UnloadResult, part_id: str) -> tuple[str, str] | None:
        """('pass' | 'fail', reason) of a result for ``part_id``; None without a spec or a
        part type for it."""
        if self.spec is None:
            return None
        return self.spec.judge(part_id, result_row(r))

    def write(self, r: UnloadResult, settings: EstimatorSettings, part_id: str, *,
              timeout: float | None = None) -> tuple[str, str] | None:
        """Write one (final) estimate for ``part_id``; returns its verdict (see
        :meth:`judge`). On a PostgreSQL server it returns or fails within ``timeout`` s
        (None: the database's ``ANSWER_TIMEOUT``), plus at most the connect timeout.

        Raises
        ------
        ResultsDBError
            The database cannot be written (busy beyond its timeout, disk full, a server
            that does not answer within ``timeout``, ...).
        """
        u = result_row(r)
        verdict = self.judge(r, part_id)
        u["verdict"], u["verdict_reason"] = verdict if verdict is not None else (None, None)
        sj = settings_json(settings)
        key = f"live:{self.writer}:{r.t_start!r}:{r.index}"
        rec = FileRecord(
            path=f"live:{self.writer}", content_hash=hashlib.sha256(key.encode()).hexdigest(),
            settings_hash=hashlib.sha256(json.dumps(
                {"settings": sj, "version": __version__}, sort_keys=True,
                default=str).encode()).hexdigest(),
            part_id=part_id or "unnamed",
            part_type=self.spec.part_type(part_id) if self.spec is not None else "",
            status="ok" if u["recommended_conductance"] is not None
            and r.status in ESTIMATE_STATUSES else "no_estimate",
            reason="" if r.status == "ok" else f"{r.status}: {r.status_text}",
            unloads=[u], settings=sj, writer=self.writer, package_version=__version__)
        # a later estimate of the unload replaces it
        write_file(self.db, rec, replace=True, timeout=timeout)
        return verdict

    def close(self) -> None:
        """Close the database's connections."""
        self.db.close()


@dataclass
class PendingWrite:
    """One estimate waiting for the results database (:class:`ResultWriter`)."""

    result: UnloadResult
    settings: EstimatorSettings
    part_id: str
    #: The unload's last estimate (its verdict is reported); False: a crossing estimate
    #: that its final estimate replaces.
    last: bool = True


class ResultWriter:
    """The writes of a :class:`LiveResults` on a thread of their own, in order, so that a
    database that is slow or hangs (a locked SQLite file, a stalled server) never holds up
    the caller (a live node's callbacks and fits); :meth:`close` waits for the queue a
    bounded time.

    Parameters
    ----------
    results : LiveResults
        The database the estimates go to.
    on_written : callable
        Called on the writer's thread with each write done and its verdict (None: none).
    on_error : callable
        Called on the writer's thread with each write that failed and the exception (a
        :class:`ResultsDBError`, or anything else the write raised: never fatal).
    """

    def __init__(self, results: LiveResults,
                 on_written: Callable[[PendingWrite, tuple[str, str] | None], None],
                 on_error: Callable[[PendingWrite, Exception], None]) -> None:
        self.results = results
        self._on_written = on_written
        self._on_error = on_error
        self._queue: queue.Queue[PendingWrite | None] = queue.Queue()
        self._busy: PendingWrite | None = None  # the write under way
        self._thread = threading.Thread(target=self._run, name="results_db", daemon=True)
        self._thread.start()

    def submit(self, write: PendingWrite) -> None:
        """Queue one write (returns at once)."""
        self._queue.put(write)

    @property
    def pending(self) -> int:
        """Writes queued or under way [-]."""
        return self._queue.qsize() + (self._busy is not None)

    def _run(self) -> None:
        while True:
            w = self._queue.get()
            if w is None:
                return
            self._busy = w
            try:
                verdict = self.results.write(w.result, w.settings, w.part_id)
            except Exception as exc:  # never fatal: reported, the next write goes on
                self._busy = None
                self._on_error(w, exc)
                continue
            self._busy = None
            self._on_written(w, verdict)

    def close(self, timeout: float) -> list[PendingWrite]:
        """Write what is queued, waiting at most ``timeout`` [s]; returns the writes not
        done by then (the one under way, a database that hangs, and those queued behind
        it, which are dropped), in order. The database's connections are closed when the
        thread has ended."""
        self._queue.put(None)
        self._thread.join(timeout=max(timeout, 0.0))
        if self._thread.is_alive():
            left = [] if self._busy is None else [self._busy]
            while True:
                try:
                    w = self._queue.get_nowait()
                except queue.Empty:
                    break
                if w is not None:
                    left.append(w)
            self._queue.put(None)  # the write under way, if it ever ends, ends the thread
            return left
        self.results.close()
        return []
