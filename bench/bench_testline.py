"""Benchmark of the test line (#14): many generated bags through ``batch``.

``python bench/bench_testline.py [--n 1000 | --quick] [--dir DIR] [--workers 2]
[--repeat R]`` (project venv, ``PYTHONPATH`` at the repo root). Makes ``n`` bags (or
reuses those in ``DIR``): 45 % clean discharges, 45 % with wall heat transfer (tanks
1-5 L, C 2e-9 .. 2e-8 m^3/(s Pa), parts of 3 runs each), 10 % bad inputs (a CSV log
without settings, a bag truncated as by a killed writer); then runs ``batch`` serially
(``--workers 1``) and on a local Dask cluster (``--workers``), each into a fresh database,
in one run, and prints:
files/s of each (the workers' with and without the local cluster's start and close), the
speed-up (target >= 1.7x on 2 cores), whether the two databases hold the same numbers, the
peak RSS of each worker process of the batch, the time headless chromium takes to open the
report of the database (``--dump-dom``, page loaded and its script run), and the load
average (the machine may be shared: each ratio comes from one serial / workers pair run
back to back; ``--repeat`` pairs). For each pair it also prints the accounting of
:mod:`pneumatic_unload.testline.accounting`: the CPU seconds per 1000 inputs by component
(the analysis; the workers' start and housekeeping; the client's main thread and Dask
event loop), serial and on the workers, each worker's idle time (before its first task,
between tasks, after its last), and the speed-up those CPU seconds allow on this machine's
cores. CPU seconds depend less on the load than wall time does, but not nothing: at a load
of 11-13 the CPU time of the same 60 analyses varied by up to 30 % from one minute to the
next; read the ratios from a quiet machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.physics import tau_exp_eq38
from pneumatic_unload.testline import (
    BatchResult,
    InputOptions,
    discover,
    open_db,
    run_batch,
    unload_rows,
)
from pneumatic_unload.testline.report import html_report

SPEC = {"part_types": {"valves": {"match": "^P", "conductance": [1e-9, 3e-8]}}}


def make_inputs(folder: Path, n: int) -> None:
    """``n`` inputs in ``folder`` (see the module doc); existing ones are kept."""
    rng = np.random.default_rng(0)
    for k in range(n):
        kind = k % 20
        part = f"P{k // 3 % 100:03d}"
        name = folder / f"{part}_run{k:04d}"
        if name.exists() or name.with_suffix(".csv").exists():
            continue
        if kind == 18:  # a CSV log without settings: no volume known
            name.with_suffix(".csv").write_text("t,p\n" + "".join(
                f"{i * 1e-3},{7e5 - i}\n" for i in range(50)))
            continue
        vol = float(rng.uniform(1e-3, 5e-3))
        c = float(10 ** rng.uniform(np.log10(2e-9), np.log10(2e-8)))
        tau = tau_exp_eq38(7e5, 101325.0, vol, c, 293.15, RigConfig(volume=vol).gas)
        cfg = RigConfig(volume=vol, conductance=c, duration=4.0 * tau, pre_time=0.3,
                        noise_std=800.0, seed=k, rate=min(1000.0, 4000.0 / tau),
                        effects=("heat_transfer",) if kind % 2 else ())
        write_simulated_bag(cfg, name, analyze_live=False)
        if kind == 19:  # a bag cut short: the writer killed, the file truncated
            mcap = next(name.glob("*.mcap"))
            data = mcap.read_bytes()
            mcap.write_bytes(data[: len(data) // 3])


def load() -> str:
    """The 1-minute load average of the machine (shared: say what it was)."""
    return f"{os.getloadavg()[0]:.1f}"


def same_numbers(db_a: Path, db_b: Path) -> bool:
    """The two databases hold the same unload rows (but for ids and times)."""
    def rows(db: Path) -> list[dict[str, object]]:
        con = open_db(db)
        try:
            return [{k: v for k, v in u.items() if k not in ("id", "file_id", "analysed_at")}
                    for u in sorted(unload_rows(con), key=lambda u: u["path"])]
        finally:
            con.close()
    return rows(db_a) == rows(db_b)


def accounting_table(serial: BatchResult, par: BatchResult, n: int, workers: int) -> None:
    """Print where the CPU seconds of a serial / workers pair went and the workers' idle
    time, per 1000 inputs [s] (CPU time: what the machine's load does not change much)."""
    scale = 1000.0 / n
    cs, cw = serial.accounting.components(), par.accounting.components()
    names = {"analysis": "analysis (the per-input job: hash, read, fit, judge)",
             "worker start": "workers' start (spawn, imports, until the first task)",
             "worker rest": "workers' event loop, comms, (de)serialisation, monitors",
             "client main thread": "client main thread (database writes, waiting)",
             "client event loop": "client Dask loop (cluster start, scheduler, nannies)",
             "client other threads": "client other threads",
             "total": "**total**"}
    print(f"\n| CPU per 1000 inputs [s] | serial | {workers} workers | extra |\n|---|---|---|---|")
    for key, label in names.items():
        a, b = cs[key] * scale, cw[key] * scale
        print(f"| {label} | {a:.1f} | {b:.1f} | {b - a:+.1f} |")
    idle = par.accounting.idle()
    print("\n| worker (pid) | tasks | busy [s] | idle before first / between / after last "
          "task [s] |\n|---|---|---|---|")
    for pid, i in idle.items():
        k = sum(t.pid == pid for t in par.accounting.tasks)
        print(f"| {pid} | {k} | {i['busy']:.1f} | {i['before']:.1f} / {i['between']:.1f} / "
              f"{i['after']:.1f} |")
    idle_s = sum(i["before"] + i["between"] + i["after"] for i in idle.values())
    print(f"\nanalysis CPU on the workers / in serial: {cw['analysis'] / cs['analysis']:.3f}; "
          f"cluster CPU / serial CPU: {cw['total'] / cs['total']:.3f}; the speed-up these "
          f"CPU seconds allow on {os.cpu_count()} cores (serial CPU / ((cluster CPU + workers' "
          f"idle) / cores)): {cs['total'] / ((cw['total'] + idle_s) / (os.cpu_count() or 1)):.2f}x")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, help="inputs (default 1000; --quick: 120)")
    ap.add_argument("--quick", action="store_true", help="a smaller run (120 inputs)")
    ap.add_argument("--dir", help="folder of the generated inputs (kept); default: a temp")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1,
                    help="serial / workers pairs measured (each ratio from one pair)")
    args = ap.parse_args(argv)
    from pneumatic_unload.testline.spec import parse_spec

    n = args.n or (120 if args.quick else 1000)
    tmp = Path(tempfile.mkdtemp(prefix="bench-testline-"))
    folder = Path(args.dir) if args.dir else tmp / "inputs"
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    make_inputs(folder, n)
    paths = discover([folder])[:n]
    print(f"{len(paths)} inputs in {folder} ({time.perf_counter() - t0:.0f} s to make); "
          f"{os.cpu_count()} cores\n")
    opts = InputOptions(part_regex=r"(P\d+)_", spec=parse_spec(SPEC))
    pairs = []
    for rep in range(args.repeat):
        runs = []
        for workers in (1, args.workers):
            db = tmp / f"r{rep}w{workers}.sqlite"
            la = load()
            t1 = time.perf_counter()
            res = run_batch(paths, opts, db_path=db, workers=workers)
            wall = time.perf_counter() - t1
            runs.append((wall, res, db))
            print(f"run {rep}, workers {workers}: {wall:.1f} s ({res.cluster_seconds:.1f} s "
                  f"starting and closing the cluster), {len(paths) / wall:.2f} files/s; "
                  f"{sum(r.status == 'ok' for r in res.records)} ok, "
                  f"{sum(r.status != 'ok' for r in res.records)} without C; "
                  f"load {la} -> {load()}")
        (w1, r1, db1), (w2, r2, db2) = runs
        pairs.append((w1, w2, w2 - r2.cluster_seconds, r2, same_numbers(db1, db2)))
        accounting_table(r1, r2, len(paths), args.workers)
        print()
    db = tmp / f"r{args.repeat - 1}w{args.workers}.sqlite"
    report = tmp / "report.html"
    t2 = time.perf_counter()
    html_report(db, report)
    t_write = time.perf_counter() - t2
    browser = shutil.which("chromium")
    t_open = float("nan")
    if browser:
        t3 = time.perf_counter()
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                        f"--user-data-dir={tmp / 'chr'}", "--dump-dom", report.as_uri()],
                       capture_output=True, timeout=300, check=True)
        t_open = time.perf_counter() - t3
    n_rows = sqlite3.connect(db).execute("SELECT count(*) FROM unloads").fetchone()[0]
    k = len(paths)
    print("\n| measure | value |\n|---|---|")
    print(f"| inputs | {k} ({n_rows} unloads) |")
    for rep, (w1, w2, w2x, r2, same) in enumerate(pairs):
        tag = f" (run {rep})" if len(pairs) > 1 else ""
        print(f"| serial{tag} | {k / w1:.2f} files/s |")
        print(f"| {args.workers} workers{tag}, with / without the cluster's start and close "
              f"| {k / w2:.2f} / {k / w2x:.2f} files/s |")
        print(f"| speed-up{tag}, with / without the cluster's start and close | "
              f"{w1 / w2:.2f}x / {w1 / w2x:.2f}x (target >= 1.7x) |")
        print(f"| same numbers serial / workers{tag} | {same} |")
        print(f"| peak RSS per worker{tag} | "
              + ", ".join(f"{v:.0f} MiB" for v in r2.worker_peak_rss.values()) + " |")
    print(f"| report: write / open in chromium | {t_write:.1f} s / {t_open:.1f} s "
          f"({report.stat().st_size / 2**20:.1f} MiB) |")
    print(f"| load average (1 min) at the end | {load()} |")
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
