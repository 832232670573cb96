"""Benchmark of the test line (#14): many generated bags through ``batch``.

``python bench/bench_testline.py [--n 1000] [--dir DIR] [--workers 2]`` (project venv,
``PYTHONPATH`` at the repo root). Makes ``n`` bags (or reuses those in ``DIR``): 45 %
clean discharges, 45 % with wall heat transfer (tanks 1-5 L, C 2e-9 .. 2e-8 m^3/(s Pa),
parts of 3 runs each), 10 % bad inputs (a CSV log without settings, a bag truncated as
by a killed writer); then runs ``batch`` serially (``--workers 1``) and on a
local Dask cluster (``--workers``), each into a fresh database, in one run, and prints:
files/s of each, the speed-up (target >= 1.7x on 2 cores), whether the two databases hold
the same numbers, the peak RSS of each worker process, and the time headless chromium
takes to open the report of the database (``--dump-dom``, page loaded and its script run).
"""

from __future__ import annotations

import argparse
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneumatic_unload.config import RigConfig
from pneumatic_unload.physics import tau_exp_eq38
from pneumatic_unload.runs import write_simulated_bag
from pneumatic_unload.testline import InputOptions, discover, open_db, run_batch, unload_rows
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


def peak_rss_mib() -> float:
    """Peak RSS of this process [MiB] (ru_maxrss is in KiB on Linux)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--dir", help="folder of the generated inputs (kept); default: a temp")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from pneumatic_unload.testline.spec import parse_spec

    tmp = Path(tempfile.mkdtemp(prefix="bench-testline-"))
    folder = Path(args.dir) if args.dir else tmp / "inputs"
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    make_inputs(folder, args.n)
    paths = discover([folder])[: args.n]
    print(f"{len(paths)} inputs in {folder} ({time.perf_counter() - t0:.0f} s to make)\n")
    opts = InputOptions(part_regex=r"(P\d+)_", spec=parse_spec(SPEC))
    rows = []
    for workers in (1, args.workers):
        db = tmp / f"w{workers}.sqlite"
        t1 = time.perf_counter()
        res = run_batch(paths, opts, db_path=db, workers=workers)
        wall = time.perf_counter() - t1
        rows.append((workers, wall, res, db))
        print(f"workers {workers}: {wall:.1f} s, {len(paths) / wall:.2f} files/s, "
              f"{sum(r.status == 'ok' for r in res.records)} ok, "
              f"{sum(r.status != 'ok' for r in res.records)} without C")
    speed_up = rows[0][1] / rows[1][1]
    same = [{k: v for k, v in u.items() if k not in ("id", "file_id", "analysed_at")}
            for u in sorted(unload_rows(open_db(rows[0][3])), key=lambda u: u["path"])] == \
        [{k: v for k, v in u.items() if k not in ("id", "file_id", "analysed_at")}
         for u in sorted(unload_rows(open_db(rows[1][3])), key=lambda u: u["path"])]
    # peak RSS of the workers: a fresh cluster analysing a sample of the inputs
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                      dashboard_address=None, silence_logs=40) as cluster, \
            Client(cluster) as client:
        from pneumatic_unload.testline.job import analyze_file

        client.gather([client.submit(analyze_file, p, opts, pure=False)
                       for p in paths[: min(len(paths), 100)]])
        rss = client.run(peak_rss_mib)
    report = tmp / "report.html"
    t2 = time.perf_counter()
    html_report(rows[1][3], report)
    t_write = time.perf_counter() - t2
    browser = shutil.which("chromium")
    t_open = float("nan")
    if browser:
        t3 = time.perf_counter()
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                        f"--user-data-dir={tmp / 'chr'}", "--dump-dom", report.as_uri()],
                       capture_output=True, timeout=300, check=True)
        t_open = time.perf_counter() - t3
    n_rows = sqlite3.connect(rows[1][3]).execute("SELECT count(*) FROM unloads").fetchone()[0]
    print("\n| measure | value |\n|---|---|")
    print(f"| inputs | {len(paths)} ({n_rows} unloads) |")
    print(f"| serial | {len(paths) / rows[0][1]:.2f} files/s |")
    print(f"| {args.workers} workers | {len(paths) / rows[1][1]:.2f} files/s |")
    print(f"| speed-up | {speed_up:.2f}x (target >= 1.7x) |")
    print(f"| same numbers serial / workers | {same} |")
    print("| peak RSS per worker | " + ", ".join(f"{v:.0f} MiB" for v in rss.values()) + " |")
    print(f"| report: write / open in chromium | {t_write:.1f} s / {t_open:.1f} s "
          f"({report.stat().st_size / 2**20:.1f} MiB) |")
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
