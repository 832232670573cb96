"""Memory and speed of ``analyze`` on long records (issue 13). A script, not a timed test.

    python bench/bench_memory.py                       # 1, 5 and 20 million rows, all cases
    python bench/bench_memory.py --quick               # 1 million rows only
    python bench/bench_memory.py --case long --rows 5  # one case, one length

Cases (``--case``, default all):

* ``csv``: one simulated discharge (:func:`pneumatic_unload.model.simulate`, 10 kHz, the
  default rig of :class:`~pneumatic_unload.config.RigConfig`, about 0.65 M samples) inside a
  long record: an idle pre-step plateau (30 % of the rows) before it and the final plateau
  after it, both with the rig's sensor noise, as a logger left running gives;
* ``bag``: the same record as a rosbag2/MCAP bag (``/tank/pressure``, FluidPressure);
* ``long``: ONE unload that lasts the whole record (a slow discharge through a tiny orifice:
  the rig's conductance scaled so that the discharge takes about 90 % of the rows), CSV; the
  sensor noise is 20 Pa (not 1 kPa): the detector looks for the step over a few hundred
  samples, and at 10 kHz a discharge of 2000 s falls about 0.3 Pa per sample at its start
  (with 1 kPa of noise the 20 M-row one is not detected: "no unload", with the reason).
  The estimator holds the unload from its start to the end of its tail (its final plateau
  judged flat): about 47 % of the rows, the table's "longest unload" column (37 % before
  the final-plateau test scaled its capped windows to half tau; at 50 M rows the tail was
  then judged level about tau after the start and the rest gave a phantom unload); above
  ``REDUCE_FROM`` (4 M) of them its old samples are reduced to bins
  (:mod:`pneumatic_unload.estimation.reduction`).

* ``stream``: the ``long`` discharge, without a file: one child process computes it at 100 Hz
  (noise-free), interpolates it to 10 kHz block by block with 20 Pa of noise and feeds
  :class:`~pneumatic_unload.estimation.StreamingEstimator` (blocks of 1 M samples): the
  estimator's own memory on one unload of any length, without the CSV reader's.

The files are written under a temporary directory (``--dir`` keeps them, and re-uses files
already there).

For each file, ``python -m pneumatic_unload.app.cli analyze FILE --json`` runs as a subprocess;
wall time, rows per second and the child's peak RSS (``ru_maxrss`` of
``resource.getrusage(RUSAGE_CHILDREN)``, one child per measurement process) are printed as a
Markdown table. ``--code DIR`` analyses with another checkout of the package (e.g. the code
before a change), so that before and after are measured on the same files.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1] / "pneumatic_unload"  # the Python package's folder
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


def rig_for(case: str, rows: int, seed: int = 1) -> RigConfig:
    """The rig of a case: the default one, or (``long``) one whose discharge takes about
    90 % of ``rows`` samples (its conductance scaled down) [-]."""
    cfg = RigConfig(rate=RATE, pre_time=1.0, seed=seed)
    if case == "long":
        from pneumatic_unload.model.rig import default_duration

        want = 0.9 * rows / RATE - cfg.pre_time  # [s]
        cfg = dataclasses.replace(cfg, conductance=cfg.conductance
                                  * default_duration(cfg) / want, noise_std=20.0)
    return cfg


def record_blocks(cfg: RigConfig, rows: int, pre_fraction: float,
                  seed: int = 1) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The record in blocks (t [s], p [Pa]): ``pre_fraction`` of the rows of idle plateau,
    the simulated discharge, then the final plateau up to ``rows`` samples."""
    sim = simulate(cfg)
    n_sim = sim.t.size
    n_pre = int(pre_fraction * rows)
    if rows < n_pre + n_sim + 10_000:
        raise SystemExit(f"{rows} rows is shorter than the simulated discharge ({n_sim})")
    n_post = rows - n_pre - n_sim
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE
    p_first = float(np.median(sim.measured[:1000]))
    p_last = float(np.median(sim.measured[-1000:]))
    for k0 in range(0, n_pre, WRITE_BLOCK):
        k1 = min(n_pre, k0 + WRITE_BLOCK)
        yield np.arange(k0, k1) * dt, p_first + cfg.noise_std * rng.standard_normal(k1 - k0)
    for k0 in range(0, n_sim, WRITE_BLOCK):
        yield n_pre * dt + sim.t[k0:k0 + WRITE_BLOCK], sim.measured[k0:k0 + WRITE_BLOCK]
    t_end = n_pre * dt + float(sim.t[-1])
    del sim
    for k0 in range(0, n_post, WRITE_BLOCK):
        k1 = min(n_post, k0 + WRITE_BLOCK)
        yield (t_end + np.arange(k0 + 1, k1 + 1) * dt,
               p_last + cfg.noise_std * rng.standard_normal(k1 - k0))


def make_record(case: str, path: Path, rows: int, seed: int = 1) -> RigConfig:
    """Write the record of a case (see the module docstring); returns its rig."""
    cfg = rig_for(case, rows, seed)
    blocks = record_blocks(cfg, rows, 0.0 if case == "long" else 0.3, seed)
    if case == "bag":
        from pneumatic_unload.io.bag import BagRecorder

        with BagRecorder(path) as rec:
            for t, p in blocks:
                rec.write_pressures(np.round((1.7e9 + t) * 1e9).astype(np.int64), p)
        return cfg
    with path.open("w") as fh:
        fh.write("time [s],pressure [Pa]\n")
        for t, p in blocks:
            _write_rows(fh, t, p)
    return cfg


def file_size(path: Path) -> int:
    """Size of a file or of a directory's files [B]."""
    if path.is_dir():
        return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    return path.stat().st_size


_CHILD = """
import json, resource, subprocess, sys, time
t0 = time.perf_counter()
proc = subprocess.run(sys.argv[1:], capture_output=True, text=True)
wall = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
print(json.dumps({"wall": wall, "rss": rss, "code": proc.returncode,
                  "stdout": proc.stdout, "stderr": proc.stderr[-2000:]}))
"""


_STREAM = """
import dataclasses, json, resource, sys, time
import numpy as np
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import EstimatorSettings, StreamingEstimator
from pneumatic_unload.model import simulate
from pneumatic_unload.model.rig import default_duration
rows, rate, noise = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
if len(sys.argv) > 4:  # --reduce-from: the reduction's thresholds (code that has them)
    from pneumatic_unload.estimation import reduction
    reduction.REDUCE_FROM, reduction.KEEP_RAW = int(sys.argv[4]), int(sys.argv[4]) // 4
cfg = RigConfig(rate=100.0, pre_time=1.0, seed=1, noise_std=0.0)
want = 0.9 * rows / rate - cfg.pre_time
cfg = dataclasses.replace(cfg, conductance=cfg.conductance * default_duration(cfg) / want)
sim = simulate(cfg)
est = StreamingEstimator(EstimatorSettings(volume=cfg.volume, atmosphere=cfg.atmosphere))
rng = np.random.default_rng(1)
out, held, c0 = [], 0, time.process_time()
for k0 in range(0, rows, 1_000_000):
    t = np.arange(k0, min(rows, k0 + 1_000_000)) / rate
    p = np.interp(t, sim.t, sim.measured) + noise * rng.standard_normal(t.size)
    out += est.push_block(1.7e9 + t, p)
    held = max(held, len(est.buffer))
out += est.finish()
print(json.dumps({"cpu": time.process_time() - c0, "held": held,
                  "rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
                  "unloads": [{"status": r.status, "conductance_model": r.conductance_model,
                               "i_start": r.i_start, "i_complete": r.i_complete}
                              for r in out if r.final], "rig_c": cfg.conductance}))
"""


def measure_stream(rows: int, code: Path, noise: float = 20.0,
                   reduce_from: int | None = None) -> dict[str, object]:
    """The ``stream`` case in a fresh process: CPU time [s], peak RSS [B], samples held."""
    env = dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1",
               OMP_NUM_THREADS="1")
    extra = [] if reduce_from is None else [str(reduce_from)]
    out = subprocess.run([sys.executable, "-c", _STREAM, str(rows), str(RATE), str(noise),
                          *extra],
                         capture_output=True, text=True, env=env, check=True, cwd=code)
    return json.loads(out.stdout)


def stream_row(rows: int, code: Path, noise: float = 20.0,
               reduce_from: int | None = None) -> str:
    """The table row of the ``stream`` case (time: the child's CPU time; ``noise`` [Pa])."""
    st = measure_stream(rows, code, noise, reduce_from)
    units: list[dict[str, float]] = st["unloads"]  # type: ignore[assignment]
    cpu, rss, held = float(st["cpu"]), int(st["rss"]), int(st["held"])  # type: ignore[arg-type, call-overload]
    span = max((int(u["i_complete"] - u["i_start"]) for u in units), default=0)
    cs = ", ".join(f"{u['conductance_model']:.5g}" for u in units)
    return (f"| stream | {rows:,} | - | {cpu:.1f} (CPU) | {rows / cpu:,.0f} | "
            f"{rss / 2**20:.0f} | {len(units)} | {span:,} (held at most {held:,}) | {cs} | "
            f"{float(st['rig_c']):.5g} |")  # type: ignore[arg-type]


def measure(path: Path, cfg: RigConfig, code: Path) -> dict[str, object]:
    """Run the CLI on one file in a fresh measuring process: wall [s], peak RSS [B]."""
    cmd = [sys.executable, "-m", "pneumatic_unload.app.cli", "analyze", str(path), "--json",
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
    ap.add_argument("--case", choices=("csv", "bag", "long", "stream"), nargs="+",
                    default=["csv", "bag", "long"], help="records to analyse (default all)")
    ap.add_argument("--stream-noise", type=float, default=20.0,
                    help="sensor noise of the stream case [Pa] (a slower discharge needs "
                         "less to be detected: 2 Pa at 100 M rows)")
    ap.add_argument("--reduce-from", type=int, default=None,
                    help="stream case: REDUCE_FROM of estimation.reduction (KEEP_RAW a "
                         "quarter of it) instead of the code's")
    args = ap.parse_args()
    millions = [1.0] if args.quick else (args.rows or [1.0, 5.0, 20.0])
    tmp = None if args.dir else tempfile.TemporaryDirectory(prefix="bench_memory_")
    folder = args.dir or Path(tmp.name)  # type: ignore[union-attr]
    folder.mkdir(parents=True, exist_ok=True)
    print(f"code: {args.code}, load average at start {os.getloadavg()[0]:.2f} "
          f"({os.cpu_count()} cores)\n")
    print("| case | rows | file [MiB] | wall [s] | rows/s | peak RSS [MiB] | unloads | "
          "longest unload [samples] | C model [m^3/(s Pa)] | rig C |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|---|")
    try:
        for case in args.case:
            for m in millions:
                rows = int(m * 1e6)
                if case == "stream":
                    print(stream_row(rows, args.code, args.stream_noise, args.reduce_from),
                          flush=True)
                    continue
                name = {"csv": "discharge", "bag": "discharge", "long": "long"}[case]
                path = folder / f"{name}_{rows}{'' if case == 'bag' else '.csv'}"
                cfg = rig_for(case, rows)
                if not path.exists():
                    cfg = make_record(case, path, rows)
                res = measure(path, cfg, args.code)
                if res["code"] not in (0, 1):
                    print(f"| {case} | {rows:,} | analyze failed (exit {res['code']}): "
                          f"{str(res['stderr']).strip().splitlines()[-1:]} |", flush=True)
                    continue
                doc = json.loads(str(res["stdout"]))
                cs = ", ".join(f"{u['conductance_model']:.5g}" if u["conductance_model"]
                               else str(u["status"]) for u in doc["unloads"])
                # the longest unload, start to the end of its tail (what one unload holds)
                span = max((u["i_complete"] - u["i_start"] for u in doc["unloads"]
                            if u.get("i_complete") is not None
                            and u.get("i_start") is not None), default=0)
                wall = float(res["wall"])  # type: ignore[arg-type]
                print(f"| {case} | {rows:,} | {file_size(path) / 2**20:.0f} | {wall:.1f} | "
                      f"{rows / wall:,.0f} | {int(res['rss']) / 2**20:.0f} | "  # type: ignore[call-overload]
                      f"{len(doc['unloads'])} | {span:,} | {cs} | {cfg.conductance:.5g} |",
                      flush=True)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
