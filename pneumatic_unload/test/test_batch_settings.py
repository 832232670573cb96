# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A batch never silently overrides a bag (#55): a setting recorded in a bag wins over the
command line unless ``--override`` (or the specification's per-file settings), and where a
command-line value meets another recorded one the batch says so, per file, in its output
and in the results database."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.testline import InputOptions, discover, open_db, parse_spec, run_batch
from pneumatic_unload.testline.db import file_rows

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

SPEC = {"part_types": {"g14": {"match": "^V14-", "conductance": [4.5e-9, 5.5e-9]}}}


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two short bags recording a 1 L tank (C 5e-9 m^3/(s Pa))."""
    d = tmp_path_factory.mktemp("bags")
    for k in range(2):
        cfg = RigConfig(volume=1e-3, conductance=5e-9, duration=2.5, pre_time=0.3,
                        noise_std=500.0, seed=k)
        write_simulated_bag(cfg, d / f"V14-00{k}", analyze_live=False)
    return d


def _run(bags: Path, db: Path, **kw: object) -> dict[str, tuple[float, str, str]]:
    """Per bag: (recommended C, verdict, settings notes) as the database holds them."""
    res = run_batch(discover([bags]), InputOptions(**kw), db_path=db, workers=1)  # type: ignore[arg-type]
    assert len(res.records) == 2
    con = open_db(db)
    try:
        notes = {Path(r["path"]).name: r["settings_notes"] or "" for r in file_rows(con)}
        with con.engine.connect() as c:
            rows = c.exec_driver_sql(
                "SELECT f.path, u.recommended_conductance, u.verdict FROM unloads u "
                "JOIN files f ON f.id = u.file_id").all()
    finally:
        con.close()
    return {Path(p).name: (c, v, notes[Path(p).name]) for p, c, v in rows}


def test_the_bag_wins_over_the_command_line_and_the_batch_says_so(bags: Path,
                                                                   tmp_path: Path):
    spec = parse_spec(SPEC)
    plain = _run(bags, tmp_path / "a.sqlite", spec=spec)
    given = _run(bags, tmp_path / "b.sqlite", spec=spec, settings={"volume": 4e-3})
    for name in plain:
        assert given[name][0] == pytest.approx(plain[name][0], rel=1e-12)  # the bag's 1 L
        assert given[name][1] == "pass"
        assert "volume: the bag's 0.001 used, not the command line's 0.004" in given[name][2]
        assert plain[name][2] == ""
    over = _run(bags, tmp_path / "c.sqlite", spec=spec, settings={"volume": 4e-3},
                override=True)
    for name in plain:
        assert over[name][0] == pytest.approx(4 * plain[name][0], rel=2e-3)  # C ~ V
        assert over[name][1] == "fail"
        assert "the command line's 0.004 used over the bag's 0.001 (--override)" \
            in over[name][2]


def test_the_specifications_per_file_settings_win(bags: Path, tmp_path: Path):
    spec = parse_spec({**SPEC, "files": {"V14-001": {"volume": 2e-3}}})
    plain = _run(bags, tmp_path / "a.sqlite")
    out = _run(bags, tmp_path / "b.sqlite", spec=spec)
    assert out["V14-000"][0] == pytest.approx(plain["V14-000"][0], rel=1e-12)
    assert out["V14-000"][2] == ""
    assert out["V14-001"][0] == pytest.approx(2 * plain["V14-001"][0], rel=2e-3)
    assert "the specification's files entry 0.002 used over the bag's 0.001" \
        in out["V14-001"][2]


def test_batch_command_prints_the_notes(bags: Path, tmp_path: Path):
    run = [sys.executable, "-m", "pneumatic_unload.app.cli", "batch", str(bags), "--db",
           str(tmp_path / "r.sqlite"), "--workers", "1", "--volume", "4L"]
    r = subprocess.run(run, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("settings: volume: the bag's 0.001 used") == 2, r.stdout
    r = subprocess.run([*run, "--json", "--force"], capture_output=True, text=True,
                       timeout=300)
    files = json.loads(r.stdout)["files"]
    assert all("--override uses the command line's" in f["settings_notes"] for f in files)


def test_batch_hints_name_the_command_line_options(tmp_path: Path):
    """A CSV the batch cannot read gets an error row whose hint names the command line's
    option (``--pressure-column``), not the library's keyword (``pressure_column=``)."""
    csv = tmp_path / "line" / "P-001.csv"
    csv.parent.mkdir()
    csv.write_text("time [s];flow [l/min]\n0;1\n0.001;1\n0.002;1\n", encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "batch",
                        str(csv.parent), "--db", str(tmp_path / "r.sqlite"), "--workers",
                        "1", "--volume", "2L", "--json"],
                       capture_output=True, text=True, timeout=300)
    (row,) = json.loads(r.stdout)["files"]
    assert row["status"] == "error" and "--pressure-column" in row["reason"], row
    assert "pressure_column=" not in row["reason"], row
