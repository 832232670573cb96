# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One bad input is one error row of a batch, serial or on Dask: a crafted bag (a chunk
claiming 1 TiB) among good ones, and an analysis that fails unexpectedly."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from bagbombs import make_bomb

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.testline import InputOptions, discover, open_db, run_batch
from pneumatic_unload.testline.db import file_rows

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six short bags, the third crafted: its chunk claims 1 TiB and its frame states no
    size (a reader that trusts the claim allocates 1 TiB: MemoryError)."""
    d = tmp_path_factory.mktemp("inputs")
    for k in range(6):
        cfg = RigConfig(volume=1e-3, conductance=5e-9, duration=2.5, pre_time=0.3,
                        noise_std=500.0, seed=k)
        write_simulated_bag(cfg, d / f"V14-00{k}", analyze_live=False)
    make_bomb(d / "V14-002", extra=1 << 20, claim=1 << 40, frame_size=False)
    return d


def _files(db: Path) -> dict[str, dict]:
    con = open_db(db)
    try:
        return {Path(r["path"]).name: r for r in file_rows(con)}
    finally:
        con.close()


@pytest.mark.parametrize("workers", [1, 2])
def test_a_bomb_among_six_inputs_is_one_error_row(inputs: Path, tmp_path: Path,
                                                  workers: int):
    db = tmp_path / "r.sqlite"
    res = run_batch(discover([inputs]), InputOptions(), db_path=db, workers=workers)
    assert len(res.records) == 6
    rows = _files(db)
    assert sorted(rows) == [f"V14-00{k}" for k in range(6)]
    bad = rows.pop("V14-002")
    assert bad["status"] == "error" and "MAX_CHUNK_BYTES" in bad["reason"], bad
    assert all(r["status"] == "ok" for r in rows.values()), rows


def test_an_analysis_that_raises_is_one_error_row(inputs: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch):
    """Whatever an input's analysis raises, the batch records it and goes on."""
    from pneumatic_unload.testline import job

    real = job.analyze_input

    def flaky(rec, settings):  # type: ignore[no-untyped-def]
        if rec.path.name == "V14-004":
            raise RuntimeError("an unforeseen fault")
        return real(rec, settings)

    monkeypatch.setattr(job, "analyze_input", flaky)
    good = tmp_path / "good"
    shutil.copytree(inputs, good, ignore=shutil.ignore_patterns("V14-002"))
    db = tmp_path / "r.sqlite"
    run_batch(discover([good]), InputOptions(), db_path=db, workers=1)
    rows = _files(db)
    assert len(rows) == 5
    assert rows["V14-004"]["status"] == "error"
    assert "the analysis failed: RuntimeError: an unforeseen fault" in rows["V14-004"]["reason"]
    assert sum(r["status"] == "ok" for r in rows.values()) == 4


def test_batch_command_records_every_input_and_names_the_bomb(inputs: Path, tmp_path: Path):
    db = tmp_path / "r.sqlite"
    r = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "batch", str(inputs),
                        "--db", str(db), "--workers", "1"], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "V14-002" in r.stderr and "MAX_CHUNK_BYTES" in r.stderr, r.stderr
    assert len(_files(db)) == 6
