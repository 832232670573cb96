# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Writers of the results database in their own processes (multiprocessing spawn targets of
test_results_db.py: a light module, so that each child imports little before it starts)."""

from __future__ import annotations

import time
from typing import Any

from pneumatic_unload.testline.db import FileRecord, open_db, write_files


def record(key: str, c: float, writer: str = "batch", **u: float) -> FileRecord:
    """An input ``key`` with one unload of recommended C ``c`` (and the fields ``u``)."""
    return FileRecord(path=f"in/{key}", content_hash=key, settings_hash="s", part_id="P",
                      status="ok", writer=writer,
                      unloads=[{"status": "ok", "recommended_conductance": c, **u}])


def open_at(url: str, t0: float) -> None:
    """Open (creating the schema of) ``url`` at the wall-clock instant ``t0``."""
    time.sleep(max(0.0, t0 - time.time()))
    open_db(url).close()


def write_rounds(url: str, who: int, rounds: list[list[str]], t0: float, step: float,
                 out: Any) -> None:
    """Write round ``i``'s inputs in one transaction (one INSERT of many rows) at the
    wall-clock instant ``t0 + i step``, as the other writers write theirs; put the number
    this writer wrote (not found there) on the queue ``out``."""
    con = open_db(url)
    written = 0
    for i, keys in enumerate(rounds):
        time.sleep(max(0.0, t0 + i * step - time.time()))
        written += sum(write_files(con, [record(key, 5e-9, writer=f"w{who}")
                                         for key in keys]))
    con.close()
    out.put(written)
