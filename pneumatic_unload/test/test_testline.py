# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The test line (#14): batch on Dask = serial, the results database (resume, concurrent
writers, schema), specifications, the batch and results commands."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.testline import (
    FileRecord,
    InputOptions,
    ResultsDBError,
    SpecError,
    discover,
    load_spec,
    open_db,
    parse_spec,
    part_summary,
    run_batch,
    unload_rows,
    write_file,
)
from pneumatic_unload.testline.batch import (
    CHUNK_MAX,
    NOT_IN_WORKER_ENV,
    WORKER_ENV,
    chunks,
    start_client,
)
from pneumatic_unload.testline.db import SCHEMA_VERSION, file_rows

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

SPEC = {"part_types": {"g14": {"match": "^V14-", "conductance": [4.5e-9, 5.5e-9],
                               "max_relative_std": 0.05}}}
# columns that depend on when and where a row was written, not on the numbers
VOLATILE = {"id", "file_id", "analysed_at"}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four short bags of two parts (C 5e-9 and 6e-9 m^3/(s Pa)) and a bad CSV."""
    d = tmp_path_factory.mktemp("inputs")
    for k, (part, c) in enumerate([("V14-001", 5e-9), ("V14-002", 6e-9)] * 2):
        cfg = RigConfig(volume=1e-3, conductance=c, duration=2.5, pre_time=0.3,
                        noise_std=500.0, seed=k)
        write_simulated_bag(cfg, d / f"{part}_run{k // 2}", analyze_live=False)
    (d / "broken.csv").write_text("t,p\n0,1\n")
    return d


def _options() -> InputOptions:
    return InputOptions(part_regex=r"(V14-\d+)", spec=parse_spec(SPEC))


def _rows(db: Path) -> list[dict]:
    con = open_db(db)
    try:
        return [{k: v for k, v in r.items() if k not in VOLATILE}
                for r in sorted(unload_rows(con), key=lambda r: (r["path"], r["unload_index"]))]
    finally:
        con.close()


def test_batch_on_a_local_cluster_equals_the_serial_batch(inputs: Path, tmp_path: Path):
    paths = discover([inputs])
    assert [Path(p).name for p in paths] == ["V14-001_run0", "V14-001_run1", "V14-002_run0",
                                             "V14-002_run1", "broken.csv"]
    serial = run_batch(paths, _options(), db_path=tmp_path / "s.sqlite", workers=1)
    dask = run_batch(paths, _options(), db_path=tmp_path / "d.sqlite", workers=2)
    assert dask.workers == 2
    assert [r.path for r in serial.records] == [r.path for r in dask.records] == paths
    assert [r.unloads for r in serial.records] == [r.unloads for r in dask.records]
    assert _rows(tmp_path / "s.sqlite") == _rows(tmp_path / "d.sqlite")
    for db in ("s.sqlite", "d.sqlite"):  # written in the order given, whatever completed first
        con = open_db(tmp_path / db)
        assert [f["path"] for f in file_rows(con)] == paths
        con.close()
    assert len(dask.worker_peak_rss) == 2 and dask.cluster_seconds > 0
    # the accounting: every task stamped where it ran, every worker's CPU by thread
    acc, ser = dask.accounting, serial.accounting
    assert sum(t.n for t in acc.tasks) == sum(t.n for t in ser.tasks) == len(paths)
    assert {t.pid for t in acc.tasks} <= set(acc.workers) and len(acc.workers) == 2
    assert os.getpid() not in acc.workers and {t.pid for t in ser.tasks} == {os.getpid()}
    cw, cs = acc.components(), ser.components()
    assert 0 < cw["analysis"] < cw["total"] and cw["worker start"] > 0
    # per-thread CPU times come in clock ticks (10 ms): the process's total may read a few
    # ticks under the analysis timed by the task itself
    assert cs["worker start"] == cs["worker rest"] == 0 and 0 < cs["analysis"]
    assert cs["total"] > cs["analysis"] - 0.05
    assert cw["total"] == pytest.approx(sum(v for k, v in cw.items() if k != "total"))
    for idle in acc.idle().values():
        assert idle["busy"] > 0 and min(idle.values()) >= 0
    # a rerun on the cluster: each input hashed on a worker, found, skipped
    again = run_batch(paths, _options(), db_path=tmp_path / "d.sqlite", workers=2)
    assert again.skipped == paths and not again.records
    # a bad file is a row with its reason, never the end of the batch
    bad = serial.records[-1]
    assert bad.status == "error" and "--volume" in bad.reason
    parts = {p["part_id"]: p for p in part_summary(_rows(tmp_path / "s.sqlite"))}
    assert parts["V14-001"]["verdict"] == "pass" and parts["V14-001"]["n"] == 2
    assert parts["V14-002"]["verdict"] == "fail"
    assert "outside" in parts["V14-002"]["verdict_reason"]
    assert parts["V14-001"]["conductance_mean"] == pytest.approx(5e-9, rel=0.02)
    assert parts["V14-001"]["conductance_std"] > 0


def test_local_cluster_workers_run_one_thread_each_and_tasks_are_chunks():
    client, cluster = start_client(1, "")
    try:
        assert list(client.nthreads().values()) == [1]
        env = client.run(lambda: {k: os.environ.get(k) for k in (*WORKER_ENV,
                                                                  *NOT_IN_WORKER_ENV)})
        assert list(env.values()) == [{**{k: str(v) for k, v in WORKER_ENV.items()},
                                       **dict.fromkeys(NOT_IN_WORKER_ENV)}]
        # the batch's own cluster: no profiler, the monitors slowed (CLUSTER_CONFIG)
        pcs = client.run(lambda dask_worker: {
            k: pc.callback_time for k, pc in dask_worker.periodic_callbacks.items()})
        (pc,) = pcs.values()
        assert "profile" not in pc and pc["tick"] >= 1000 and pc["memory_monitor"] >= 1000
    finally:
        client.close()
        cluster.close()
    items = [(k, f"f{k}") for k in range(1000)]
    cut = chunks(items, 2)
    assert [x for c in cut for x in c] == items and max(len(c) for c in cut) == CHUNK_MAX
    sizes = [len(c) for c in cut]  # large first, one input each at the end: a short tail
    assert sizes == sorted(sizes, reverse=True) and sizes[-4:] == [1] * 4
    assert len(chunks(items[:5], 2)) == 5  # a few inputs: one task each


def test_rerun_skips_what_is_done_and_force_replaces(inputs: Path, tmp_path: Path):
    paths = discover([inputs])
    db = tmp_path / "r.sqlite"
    first = run_batch(paths[:2], _options(), db_path=db)
    again = run_batch(paths, _options(), db_path=db)
    assert len(first.records) == 2 and again.skipped == paths[:2]
    assert len(again.records) == 3
    forced = run_batch(paths[:1], _options(), db_path=db, force=True)
    assert len(forced.records) == 1 and not forced.skipped
    con = open_db(db)
    n_files = len(file_rows(con))
    con.close()
    assert n_files == len(paths)
    assert len(_rows(db)) == 4  # one unload per bag, none twice


def test_a_killed_batch_resumes_without_duplicates(inputs: Path, tmp_path: Path):
    """A batch killed (SIGKILL, no cleanup) after it wrote some inputs and before it wrote
    them all: the rerun skips exactly the inputs written before the kill, analyses the
    rest, and the database holds each input and each unload once."""
    db = tmp_path / "k.sqlite"
    paths = discover([inputs])
    cmd = [sys.executable, "-m", "pneumatic_unload.app.cli", "batch", str(inputs), "--db",
           str(db), "--workers", "1", "--part-regex", r"(V14-\d+)"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    n = 0
    while time.monotonic() < deadline and proc.poll() is None:
        if db.exists():
            try:
                con = sqlite3.connect(db, timeout=1)
                n = con.execute("SELECT count(*) FROM files").fetchone()[0]
                con.close()
            except sqlite3.DatabaseError:
                n = 0
            if n >= 1:
                break
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL  # killed, not finished before the signal
    # what the killed batch left: some inputs, not all (the kill landed mid-batch)
    con = open_db(db)
    before = {f["path"]: (f["id"], f["analysed_at"]) for f in file_rows(con)}
    con.close()
    assert 1 <= len(before) < len(paths), sorted(before)
    out = subprocess.run([*cmd, "--json"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 1, out.stderr  # the broken CSV
    summary = json.loads(out.stdout)
    # the inputs written before the kill are skipped, the others analysed now
    assert sorted(summary["skipped"]) == sorted(before)
    assert summary["analysed"] == len(paths) - len(before)
    con = open_db(db)
    files = file_rows(con)
    con.close()
    assert sorted(f["path"] for f in files) == sorted(paths)  # each input once
    # the rows written before the kill are kept as they were, not rewritten
    assert {f["path"]: (f["id"], f["analysed_at"]) for f in files
            if f["path"] in before} == before
    rows = _rows(db)
    assert len(rows) == 4 and len({(r["path"], r["unload_index"]) for r in rows}) == 4


def _writer(db: str, who: int, n: int) -> None:
    con = open_db(db)
    for k in range(n):
        rec = FileRecord(path=f"w{who}-{k}", content_hash=f"{who}-{k}", settings_hash="s",
                         part_id=f"P{who}", status="ok",
                         unloads=[{"status": "ok", "recommended_conductance": 5e-9,
                                   "tau_exp": 1.0}])
        assert write_file(con, rec)
    con.close()


def test_two_writers_at_once_lose_nothing(tmp_path: Path):
    db = str(tmp_path / "w.sqlite")
    open_db(db).close()
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(db, w, 60)) for w in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    con = open_db(db)
    assert len(file_rows(con)) == 120 and len(unload_rows(con)) == 120
    con.close()
    with sqlite3.connect(db) as raw:  # the file itself (open_db's handle is backend-neutral)
        assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_schema_is_versioned_and_a_newer_one_is_refused(tmp_path: Path):
    db = tmp_path / "v.sqlite"
    open_db(db).close()
    raw = sqlite3.connect(db)  # the file itself (open_db's handle is backend-neutral)
    assert raw.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    raw.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    raw.commit()
    raw.close()
    with pytest.raises(ResultsDBError, match="newer"):
        open_db(db)
    (tmp_path / "junk.sqlite").write_text("not a database " * 100)
    with pytest.raises(ResultsDBError, match=r"junk\.sqlite"):
        open_db(tmp_path / "junk.sqlite")
    with pytest.raises(ResultsDBError, match="does not exist"):
        open_db(tmp_path / "missing" / "x.sqlite")


def test_spec_judges_and_rejects_bad_files():
    spec = parse_spec(SPEC)
    ok = {"status": "ok", "recommended_conductance": 5e-9, "recommended_std": 5e-11}
    assert spec.judge("V14-7", ok) == ("pass", "within specification")
    verdict, why = spec.judge("V14-7", {**ok, "recommended_conductance": 6e-9})
    assert verdict == "fail" and "0.6 dm^3/(s bar) outside [0.45, 0.55]" in why
    verdict, why = spec.judge("V14-7", {**ok, "recommended_std": 5e-10})
    assert verdict == "fail" and "sigma(C)/C 10.00 %" in why
    verdict, why = spec.judge("V14-7", {"status": "bad_data", "status_text": "stuck",
                                        "recommended_conductance": None})
    assert verdict == "fail" and "stuck" in why
    assert spec.judge("other", ok) is None
    for bad, msg in [({"part_types": {"x": {"conductance": [0.4, 0.6]}}}, "m\\^3/\\(s Pa\\)"),
                     ({"part_types": {"x": {}}}, "required"),
                     ({"part_types": {"x": {"conductance": [6e-9, 5e-9]}}}, "not a range"),
                     ({"part_types": {"x": {"conductance": [5e-9, 6e-9], "typo": 1}}},
                      "unknown keys"),
                     ({"types": {}}, "part_types")]:
        with pytest.raises(SpecError, match=msg):
            parse_spec(bad)


def test_batch_and_results_commands(inputs: Path, tmp_path: Path):
    spec = tmp_path / "spec.yaml"
    spec.write_text("part_types:\n  g14:\n    match: '^V14-'\n"
                    "    conductance: [4.5e-9, 5.5e-9]\n")
    db = tmp_path / "c.sqlite"
    run = [sys.executable, "-m", "pneumatic_unload.app.cli"]
    out = subprocess.run([*run, "batch", str(inputs / "V14-001_run0"),
                                str(inputs / "V14-001_run1"), "--db", str(db), "--spec",
                                str(spec), "--part-regex", r"(V14-\d+)", "--workers", "1",
                                "--out", str(tmp_path / "u.csv")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "V14-001" in out.stdout and "pass" in out.stdout
    assert (tmp_path / "u.csv").read_text().count("\n") == 3
    assert "pass" in (tmp_path / "u_parts.csv").read_text()
    out = subprocess.run([*run, "batch", str(inputs), "--db", str(db), "--spec", str(spec),
                                "--part-regex", r"(V14-\d+)", "--workers", "1"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 1  # a part out of spec and a broken file
    assert "2 already in" in out.stdout and "broken.csv: error" in out.stderr
    exp = subprocess.run([*run, "results", "export", "--db", str(db), "--out",
                                str(tmp_path / "all.parquet")],
                         capture_output=True, text=True, timeout=120)
    assert exp.returncode == 0, exp.stderr
    import pyarrow.parquet as pq

    t = pq.read_table(tmp_path / "all.parquet")
    assert t.num_rows == 4 and "recommended_conductance" in t.column_names
    for bad in (["batch", str(tmp_path / "nope")], ["results", "export", "--db", str(db)],
                ["batch", str(inputs), "--spec", str(tmp_path / "u.csv")]):
        r = subprocess.run([*run, *bad], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.startswith("pneumatic-unload: error:")


def _chromium() -> str | None:
    import shutil

    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_report_is_one_self_contained_page_that_a_browser_opens(inputs: Path,
                                                                  tmp_path: Path):
    from pneumatic_unload.testline.report import html_report

    db = tmp_path / "rep.sqlite"
    run_batch(discover([inputs]), _options(), db_path=db)
    out = tmp_path / "report.html"
    counts = html_report(db, out, title="line 3")
    assert counts == {"files": 5, "unloads": 4, "parts": 3, "failing_parts": 1}
    text = out.read_text()
    for needed in ("id='parts'", "id='unloads'", "class=\"chart\"", "Repeatability",
                   "broken.csv: error", "outside [0.45, 0.55]"):
        assert needed in text, needed
    # self-contained: nothing fetched from anywhere (no src/href to files or the network)
    assert "http://" not in text and "https://" not in text
    assert " src=" not in text and "href=" not in text
    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium (CI installs Debian's chromium; apt install chromium)")
    for frag, want in (("", 'data-ready="4"'), ("#unload=2", 'id="curve-svg"')):
        r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                            "--enable-logging=stderr", "--v=0",
                            f"--user-data-dir={tmp_path / 'chromium'}", "--dump-dom",
                            out.as_uri() + frag],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        assert want in r.stdout, (frag, r.stdout[:500])
        assert "V14-002" in r.stdout
        errors = [ln for ln in r.stderr.splitlines() if "Uncaught" in ln
                  or ("CONSOLE" in ln and "error" in ln.lower())]
        assert errors == [], errors


def _msg_fields(path: Path) -> set[str]:
    """Field names of a .msg file (constants and comments left out)."""
    out = set()
    for line in path.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line and "=" not in line:
            out.add(line.split()[1])
    return out


def test_foxglove_layout_plots_fields_the_nodes_publish():
    """Every path of the installed Foxglove layout names a topic the nodes publish and a
    field of its message; every panel of the layout tree is configured."""
    repo = Path(__file__).resolve().parents[1]
    layout = json.loads((repo / "foxglove" / "pneumatic_unload.json").read_text())
    fields = {"/tank/pressure": {"header", "fluid_pressure", "variance"},
              "/estimator/estimate": _msg_fields(repo.parent / "pneumatic_unload_msgs" / "msg" /
                                                 "UnloadEstimate.msg")}
    assert {"p_star", "conductance_model", "tau_exp"} <= fields["/estimator/estimate"]
    plotted = []
    for pid, cfg in layout["configById"].items():
        for path in cfg.get("paths", []):
            topic, _, field = path["value"].partition(".")
            assert field in fields[topic], (pid, path["value"])
            plotted.append(path["value"])
    assert "/tank/pressure.fluid_pressure" in plotted
    assert "/estimator/estimate.p_star" in plotted  # at its header stamp: the crossing

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + \
            leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(layout["configById"])


def test_live_results_keep_one_row_per_unload_with_its_verdict(tmp_path: Path):
    from pneumatic_unload.estimation import EstimatorSettings, analyze
    from pneumatic_unload.model import simulate
    from pneumatic_unload.testline.live import LiveResults

    spec = tmp_path / "spec.yaml"
    spec.write_text("part_types:\n  g14:\n    match: '^V14-'\n"
                    "    conductance: [4.5e-9, 5.5e-9]\n")
    cfg = RigConfig(volume=1e-3, conductance=5e-9, duration=2.5, pre_time=0.3,
                    noise_std=500.0, seed=3)
    sim = simulate(cfg)
    settings = EstimatorSettings(volume=1e-3)
    final = next(r for r in analyze(sim.t, sim.measured, settings) if r.final)
    live = LiveResults(tmp_path / "live.sqlite", "estimator", load_spec(spec))
    assert live.write(final, settings, "V14-9") == ("pass", "within specification")
    assert live.write(final, settings, "V14-9") == ("pass", "within specification")
    con = open_db(tmp_path / "live.sqlite")
    rows = unload_rows(con)
    con.close()
    assert [(r["part_id"], r["verdict"], r["writer"]) for r in rows] == \
        [("V14-9", "pass", "estimator")]  # the same unload is one row
    assert live.write(final, settings, "X-1") is None  # no part type: no verdict
    con = open_db(tmp_path / "live.sqlite")
    rows = unload_rows(con)
    con.close()
    assert [(r["part_id"], r["verdict"]) for r in rows] == [("X-1", None)]  # replaced
    assert rows[0]["recommended_conductance"] == pytest.approx(5e-9, rel=0.02)
    with pytest.raises(SpecError):
        load_spec(tmp_path / "missing.yaml")
    with pytest.raises(ResultsDBError):
        LiveResults(tmp_path / "no" / "l2.sqlite", "estimator")


def test_a_part_measured_both_ways_is_reported_side_by_side(tmp_path: Path):
    """A charge bag and a discharge bag of one part, two batches (each with its direction)
    into one database: the rows carry the direction, the report's parts table gives each
    direction's C and their difference in combined sigma (#26)."""
    from pneumatic_unload.testline.report import html_report

    d = tmp_path / "in"
    c_true = 5e-9
    common = {"volume": 1e-3, "conductance": c_true, "critical_ratio": 0.45,
              "noise_std": 500.0, "pre_time": 0.3, "effects": ("heat_transfer",)}
    write_simulated_bag(RigConfig(**common, initial_pressure=6e5, duration=3.0, seed=1),
                        d / "V14-009_discharge", analyze_live=False)
    write_simulated_bag(RigConfig(**common, direction="charge", initial_pressure=101325.0,
                                  supply_pressure=6e5, duration=3.0, seed=2),
                        d / "V14-009_charge", analyze_live=False)
    db = tmp_path / "both.sqlite"
    for direction in ("discharge", "charge"):
        run_batch([str(d / f"V14-009_{direction}")], InputOptions(
            part_regex=r"(V14-\d+)", settings={"direction": direction}), db_path=db)
    rows = _rows(db)
    assert sorted((r["direction"], r["status"]) for r in rows) == [
        ("charge", "ok"), ("discharge", "ok")]
    charge = next(r for r in rows if r["direction"] == "charge")
    assert charge["supply_pressure"] == pytest.approx(6e5, rel=3e-3)
    (part,) = part_summary(rows)
    both = part["by_direction"]
    assert set(both) == {"discharge", "charge"}
    for x in both.values():
        assert x["conductance"] == pytest.approx(c_true, rel=0.01)
    out = tmp_path / "report.html"
    html_report(db, out)
    page = out.read_text()
    assert "C charge" in page and "charge - discharge" in page and "&sigma;)" in page
