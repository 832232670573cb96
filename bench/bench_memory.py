"""Memory and speed of ``analyze`` on long CSV logs (issue 13). A script, not a timed test.

    python bench/bench_memory.py            # 1, 5 and 20 million rows
    python bench/bench_memory.py --quick    # 1 million rows only

Each CSV is one simulated discharge (:func:`pneumatic_unload.model.simulate`, 10 kHz, the
default rig of :class:`~pneumatic_unload.config.RigConfig`) inside a long record: an idle
pre-step plateau (30 % of the rows) before it and the final plateau after it, both with the
rig's sensor noise, as a logger left running gives. The files are written under a temporary
directory (``--dir`` keeps them, and re-uses files already there).

For each file, ``python -m pneumatic_unload.cli analyze FILE --json`` runs as a subprocess;
wall time, rows per second and the child's peak RSS (``ru_maxrss`` of
``resource.getrusage(RUSAGE_CHILDREN)``, one child per measurement process) are printed as a
Markdown table. ``--code DIR`` analyses with another checkout of the package (e.g. the code
before a change), so that before and after are measured on the same files.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pneumatic_unload.config import RigConfig  # noqa: E402
from pneumatic_unload.model import simulate  # noqa: E402

#: Sample rate of the benchmark records [Hz].
RATE = 10_000.0
#: Rows written per formatting block (bounds the generator's memory) [-].
WRITE_BLOCK = 500_000


def _write_rows(fh: object, t: np.ndarray, p: np.ndarray) -> None:
    """Append rows 'time,pressure' (t [s], p [Pa]) to an open text file."""
    for k in range(0, t.size, WRITE_BLOCK):
        tt, pp = t[k:k + WRITE_BLOCK], p[k:k + WRITE_BLOCK]
        fh.write("".join(f"{a:.4f},{b:.1f}\n" for a, b in zip(tt.tolist(), pp.tolist(),
                                                                strict=True)))


def make_csv(path: Path, rows: int, seed: int = 1) -> RigConfig:
    """Write a record of ``rows`` samples holding one simulated discharge; returns its rig."""
    cfg = RigConfig(rate=RATE, pre_time=1.0, seed=seed)
    sim = simulate(cfg)
    n_sim = sim.t.size
    if rows < n_sim + 20_000:
        raise SystemExit(f"{rows} rows is shorter than the simulated discharge ({n_sim})")
    n_pre = int(0.3 * rows)
    n_post = rows - n_pre - n_sim
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE
    p_first = float(np.median(sim.measured[:1000]))
    p_last = float(np.median(sim.measured[-1000:]))
    with path.open("w") as fh:
        fh.write("time [s],pressure [Pa]\n")
        for k0 in range(0, n_pre, WRITE_BLOCK):
            k1 = min(n_pre, k0 + WRITE_BLOCK)
            _write_rows(fh, np.arange(k0, k1) * dt,
                        p_first + cfg.noise_std * rng.standard_normal(k1 - k0))
        _write_rows(fh, n_pre * dt + sim.t, sim.measured)
        t_end = n_pre * dt + float(sim.t[-1])
        for k0 in range(0, n_post, WRITE_BLOCK):
            k1 = min(n_post, k0 + WRITE_BLOCK)
            _write_rows(fh, t_end + np.arange(k0 + 1, k1 + 1) * dt,
                        p_last + cfg.noise_std * rng.standard_normal(k1 - k0))
    return cfg


_CHILD = """
import json, resource, subprocess, sys, time
t0 = time.perf_counter()
proc = subprocess.run(sys.argv[1:], capture_output=True, text=True)
wall = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
print(json.dumps({"wall": wall, "rss": rss, "code": proc.returncode,
                  "stdout": proc.stdout, "stderr": proc.stderr[-2000:]}))
"""


def measure(path: Path, cfg: RigConfig, code: Path) -> dict[str, object]:
    """Run the CLI on one file in a fresh measuring process: wall [s], peak RSS [B]."""
    cmd = [sys.executable, "-m", "pneumatic_unload.cli", "analyze", str(path), "--json",
           "--volume", repr(cfg.volume), "--atmosphere", repr(cfg.atmosphere)]
    env = dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1",
               OMP_NUM_THREADS="1")
    # cwd: `python -m` puts the working directory first on sys.path
    out = subprocess.run([sys.executable, "-c", _CHILD, *cmd], capture_output=True,
                         text=True, env=env, check=True, cwd=code)
    return json.loads(out.stdout)


def main() -> int:
    """Generate the records, analyse each, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 million rows only")
    ap.add_argument("--rows", type=float, nargs="+", default=None,
                    help="record lengths in millions of rows (default 1 5 20)")
    ap.add_argument("--dir", type=Path, default=None,
                    help="keep the CSV files here (default: a temporary directory)")
    ap.add_argument("--code", type=Path, default=ROOT,
                    help="checkout of the package to analyse with (default: this one)")
    args = ap.parse_args()
    millions = [1.0] if args.quick else (args.rows or [1.0, 5.0, 20.0])
    tmp = None if args.dir else tempfile.TemporaryDirectory(prefix="bench_memory_")
    folder = args.dir or Path(tmp.name)  # type: ignore[union-attr]
    folder.mkdir(parents=True, exist_ok=True)
    print(f"code: {args.code}\n")
    print("| rows | file [MiB] | wall [s] | rows/s | peak RSS [MiB] | unloads | C [m^3/(s Pa)] |")
    print("|---:|---:|---:|---:|---:|---:|---|")
    try:
        for m in millions:
            rows = int(m * 1e6)
            path = folder / f"discharge_{rows}.csv"
            cfg = RigConfig(rate=RATE, pre_time=1.0, seed=1)
            if not path.exists():
                cfg = make_csv(path, rows)
            res = measure(path, cfg, args.code)
            if res["code"] not in (0, 1):
                print(f"| {rows:,} | analyze failed (exit {res['code']}): "
                      f"{str(res['stderr']).strip().splitlines()[-1:]} |")
                continue
            doc = json.loads(str(res["stdout"]))
            cs = ", ".join(f"{u['conductance_model']:.5g}" for u in doc["unloads"])
            wall = float(res["wall"])  # type: ignore[arg-type]
            print(f"| {rows:,} | {path.stat().st_size / 2**20:.0f} | {wall:.1f} | "
                  f"{rows / wall:,.0f} | {int(res['rss']) / 2**20:.0f} | "  # type: ignore[call-overload]
                  f"{len(doc['unloads'])} | {cs} |", flush=True)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
