"""A live estimator's final estimates in the results database, judged against a spec.

:class:`LiveResults` is what the estimator node holds when its ``results_db`` parameter is
set: each final estimate becomes one row of ``files`` (path ``live:<node>``, a content
hash made of the node, the unload's start and index: a later estimate of the same unload
replaces the earlier) and one of ``unloads``,
with the part id of the running ``measure`` goal or of the node's ``part_id`` parameter,
and the verdict of the part's type in the specification. The database is shared: batches
and other nodes may write at the same time (see :mod:`~.db`); the database stays open (a
small pool of connections) for the node's life. SI units.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from pneumatic_unload import __version__
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.types import UnloadResult
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

    def write(self, r: UnloadResult, settings: EstimatorSettings, part_id: str
              ) -> tuple[str, str] | None:
        """Write one (final) estimate for ``part_id``; returns its verdict (see
        :meth:`judge`).

        Raises
        ------
        ResultsDBError
            The database cannot be written (busy beyond its timeout, disk full, ...).
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
            and r.status in ("ok", "aborted_sse", "not_choked") else "no_estimate",
            reason="" if r.status == "ok" else f"{r.status}: {r.status_text}",
            unloads=[u], settings=sj, writer=self.writer, package_version=__version__)
        write_file(self.db, rec, replace=True)  # a later estimate of the unload replaces it
        return verdict

    def close(self) -> None:
        """Close the database's connections."""
        self.db.close()
