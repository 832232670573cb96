# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The status words of a result: one table (estimation.types), a word that says what it
means, the message's STATUS_* constants in step with it, and older databases read with
the current words."""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

import pytest

from pneumatic_unload.estimation import (
    ESTIMATE_STATUSES,
    STATUS_ALIASES,
    STATUS_MEANINGS,
    STATUSES,
    canonical_status,
)

REPO = Path(__file__).resolve().parents[2]


def test_a_good_result_has_a_status_word_that_reads_as_good():
    """'not_choked' was the status of a good result (the model C is the one to report) and
    read as an alarm: every status that carries a C starts with 'ok' or says how the C was
    found ('aborted_sse': the SSE method), and every status has its meaning in words."""
    assert "ok_subsonic" in STATUSES and "not_choked" not in STATUSES
    assert STATUSES[:5] == ("ok", "aborted_sse", "aborted", "ok_subsonic", "bad_data")
    assert set(STATUS_MEANINGS) == set(STATUSES) and set(ESTIMATE_STATUSES) <= set(STATUSES)
    for s in ("ok", "aborted_sse", "ok_subsonic"):
        assert s in ESTIMATE_STATUSES and STATUS_MEANINGS[s].startswith("a good estimate"), s
    for s in set(STATUSES) - set(ESTIMATE_STATUSES):
        assert STATUS_MEANINGS[s].startswith("no estimate"), s
    assert canonical_status("not_choked") == "ok_subsonic" == canonical_status("ok_subsonic")
    assert canonical_status("ok") == "ok"


def test_message_constants_follow_the_status_table():
    """UnloadEstimate.msg's STATUS_<WORD> = index of <word> in STATUSES (a bag stores the
    index: an old bag's 3 reads as 'ok_subsonic'); a former name keeps its old value."""
    text = (REPO / "pneumatic_unload_msgs" / "msg" / "UnloadEstimate.msg").read_text()
    consts = {m[1].lower(): int(m[2]) for m in re.finditer(r"^uint8 STATUS_(\w+)=(\d+)", text,
                                                          re.MULTILINE)}
    for word, value in consts.items():
        assert STATUSES[value] == canonical_status(word), (word, value)
    assert set(STATUSES) <= set(consts)


def test_an_older_database_reads_with_the_current_words(tmp_path: Path):
    """A results database holding 'not_choked' (written before the rename) reads as
    'ok_subsonic': the unload counts in its part's C and in the report's control chart."""
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.estimation import EstimatorSettings, analyze
    from pneumatic_unload.model import simulate
    from pneumatic_unload.testline import open_db, part_summary, unload_rows
    from pneumatic_unload.testline.live import LiveResults
    from pneumatic_unload.testline.report import html_report

    cfg = RigConfig(volume=1e-3, conductance=5e-9, duration=2.5, pre_time=0.3,
                    noise_std=500.0, seed=3)
    sim = simulate(cfg)
    final = next(r for r in analyze(sim.t, sim.measured, EstimatorSettings(volume=1e-3))
                 if r.final)
    db = tmp_path / "old.sqlite"
    LiveResults(db, "estimator").write(final, EstimatorSettings(volume=1e-3), "V14-1")
    with sqlite3.connect(db) as con:  # as an older version wrote a subsonic unload
        assert con.execute("UPDATE unloads SET status = 'not_choked'").rowcount == 1
    con = open_db(db)
    try:
        rows = unload_rows(con)
    finally:
        con.close()
    assert [r["status"] for r in rows] == ["ok_subsonic"]
    (part,) = part_summary(rows)
    assert part["n"] == 1 and part["conductance_mean"] == pytest.approx(5e-9, rel=0.02)
    out = tmp_path / "r.html"
    html_report(db, out)
    page = out.read_text()
    assert "ok_subsonic" in page and "not_choked" not in page
    assert "no C to chart" not in page and "<circle" in page


def test_the_docs_list_every_status_with_its_meaning():
    """The generated JSON page has the status table (from STATUS_MEANINGS) and the former
    words."""
    import sys

    sys.path.insert(0, str(REPO / "docs" / "_ext"))
    try:
        import generated_reference
    finally:
        sys.path.pop(0)
    page = generated_reference.json_page()
    for s in STATUSES:
        assert f"``{s}``" in page and generated_reference.esc(STATUS_MEANINGS[s]) in page, s
    for old in STATUS_ALIASES:
        assert f"``{old}`` (now ``{STATUS_ALIASES[old]}``)" in page
