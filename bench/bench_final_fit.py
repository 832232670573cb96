"""Cost of the final curve fit (#10: the live final estimate at 10 kHz within 50 ms p99),
measured in-process and deterministically.

The traces are those of the live benchmark (``bench/bench_engine.py --part live``): the
simulator's cycle mode (:func:`pneumatic_unload.model.rig.run_cycles`) with ``bench_nodes.RIG``
(0.2 L, C 8e-9 m^3/(s Pa), 7 bar, no heat transfer simulated, 1 kPa noise, 10 kHz) and the
bench's cycle timing, fed in blocks of 100 to a live
:class:`~pneumatic_unload.estimation.StreamingEstimator` with the node's settings and
deferred final fits, as the node runs them. A second rig is slow: a 5 L tank with wall heat
transfer simulated (``--slow``; 1 kHz, C 2e-8, 60 s per unload). ``--charge N``: the bench
rig charged from a 7 bar supply (``bench_engine.py --direction charge``), at 1 and 10 kHz.

For every final fit it records the residual evaluations (calls of the binned likelihood,
load-independent: the primary figure) per heat law and in all, the CPU time of the fit
(:func:`time.process_time`, the least of ``--repeat`` runs of each fit; secondary: it
depends on the load, printed with the load average), the chosen law, C and its sigma, and
every law's raw chi^2. ``--json FILE`` writes them; ``--compare FILE`` checks a run against
one written before (same traces): the chosen law, C and sigma (relative change) and every
law's raw chi^2 (in residual variances).

Run::

    PYTHONPATH=. .venv/bin/python bench/bench_final_fit.py [--unloads 60] [--slow N]
        [--charge N] [--repeat 3] [--json out.json] [--compare before.json]

Measured (2 cores, session 17), residual evaluations per final fit, p50 / max, ``--charge``:

* main fa421fb, 20 charges: 1 kHz 92 / 146, 10 kHz 69.5 / 163 (the constant-hA law up to
  100-108 walking the flat valley of an exchange the record does not show);
* the constant-hA law's budget 12 where the natural law leaves the exchange undetermined
  (``law_family.FLAT_EXCHANGE_NFEV``): 89.5 / 127, 69.5 / 132; C within 6e-4 relative, no
  law changed (a budget of 6: chi^2 up to 3.6 residual variances worse, 3 laws changed);
* the reproducibility restart on the minimum's Jacobian: 73.5 / 117, 64.5 / 127, every C,
  sigma and chi^2 identical;
* 80 charges: 10 kHz max 277 (two wall refits that walked the valley, and moved T_s with
  the wall) -> 137 with ``config.estimator.with_wall`` and ``wall_moves.NULL_RCOND``;
  CPU p99 32.8 -> 26.8 ms; C identical, sigma -13 % median (T_s no longer counted twice).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import collections  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from pneumatic_unload.config import RigConfig  # noqa: E402
from pneumatic_unload.curvefit import fitting, law_family, law_fit  # noqa: E402
from pneumatic_unload.estimation import EstimatorSettings, StreamingEstimator  # noqa: E402
from pneumatic_unload.fit.likelihood import BinnedLikelihood  # noqa: E402
from pneumatic_unload.model.rig import run_cycles  # noqa: E402

#: bench_engine's live cycle timing [s].
CYCLE = {"settle_time": 0.6, "vent_time": 0.3, "charge_time": 0.3}


class Counter:
    """Counts residual evaluations, attributed to the law being fitted."""

    def __init__(self) -> None:
        self.label = "other"
        self.by_label: collections.Counter[str] = collections.Counter()
        #: each law's raw chi^2 and residual variance (the last fit of that law) [Pa^2]
        self.chi2: dict[str, tuple[float, float]] = {}

    def install(self) -> None:
        orig_res = BinnedLikelihood.residuals_at
        orig_law = law_family.fit_law
        orig_valley = law_fit.valley_std
        counter = self

        def residuals_at(lik: Any, *a: Any, **k: Any) -> Any:
            counter.by_label[counter.label] += 1
            return orig_res(lik, *a, **k)

        def fit_law(*a: Any, **k: Any) -> Any:
            prev = counter.label
            law = k.get("law", "natural")
            tag = law + ("+wall" if k.get("fit_wall") else "") \
                + ("|m" if k.get("fit_m") else "") + ("+offset" if k.get("fit_offset") else "") \
                + (" explore" if k.get("explore") else "")
            counter.label = tag if prev == "other" else prev
            try:
                out = orig_law(*a, **k)
                if prev == "other":
                    counter.chi2[tag] = (float(out[1]), float(out[0].rms) ** 2)
                return out
            finally:
                counter.label = prev

        def valley(*a: Any, **k: Any) -> Any:
            prev = counter.label
            counter.label = prev + " profile"
            try:
                return orig_valley(*a, **k)
            finally:
                counter.label = prev

        BinnedLikelihood.residuals_at = residuals_at  # type: ignore[method-assign]
        fitting.fit_law = fit_law  # the wall's refits
        law_family.fit_law = fit_law  # the laws'
        law_fit.valley_std = valley


def jobs_of(cfg: RigConfig, settings: EstimatorSettings, unloads: int) -> list[Any]:
    """The deferred final fits of a cycling run, fed in blocks of 100 samples."""
    run = run_cycles(cfg, unloads, **CYCLE)
    est = StreamingEstimator(settings, live=True, defer_final_fit=True)
    jobs = []
    for k in range(0, run.t.size, 100):
        est.push_block(run.t[k:k + 100], run.measured[k:k + 100])
        jobs += est.take_final_fits()
    est.finish()
    jobs += est.take_final_fits()
    return jobs


def measure(name: str, cfg: RigConfig, settings: EstimatorSettings, unloads: int,
            counter: Counter, repeat: int = 1) -> list[dict[str, Any]]:
    jobs = jobs_of(cfg, settings, unloads)
    if jobs:
        jobs[0].run()  # untimed: lazy imports and first-call set-up (the node warms up too)
    rows = []
    for job in jobs:
        cpu = math.inf
        for _ in range(repeat):  # the least disturbed of the repeats (same result each)
            counter.by_label.clear()
            counter.chi2.clear()
            c0 = time.process_time()
            r = job.run()
            cpu = min(cpu, time.process_time() - c0)
        cf = (r.extra.get("curve_fit") or {}) if r is not None else {}
        laws = cf.get("laws") or {}
        best = cf.get("heat_law", "")
        rows.append({"trace": name, "unload": job.crossing.index, "cpu_ms": 1e3 * cpu,
                     "nfev": sum(counter.by_label.values()),
                     "nfev_by": dict(counter.by_label), "law": best,
                     "raw_chi2": dict(counter.chi2),
                     "C": r.conductance_model if r is not None else math.nan,
                     "C_std": r.conductance_model_std if r is not None else math.nan,
                     "chi2": laws.get(best, {}).get("chi2", math.nan),
                     "laws": {k: {"bic": v["bic"], "chi2": v["chi2"],
                                  "C": v["conductance"]} for k, v in laws.items()},
                     "not_offered": sorted(cf.get("not_offered") or {})})
    return rows


def _pct(x: list[float]) -> str:
    a = np.asarray(x, dtype=float)
    return f"{np.percentile(a, 50):.1f} / {np.percentile(a, 99):.1f} / {a.max():.1f}"


def report(rows: list[dict[str, Any]]) -> None:
    for name in dict.fromkeys(r["trace"] for r in rows):
        rs = [r for r in rows if r["trace"] == name]
        print(f"\n## {name}: {len(rs)} final fits")
        print(f"nfev per final fit p50 / p99 / max: {_pct([r['nfev'] for r in rs])}")
        print(f"CPU per final fit [ms] p50 / p99 / max: {_pct([r['cpu_ms'] for r in rs])}")
        labels = sorted({k for r in rs for k in r["nfev_by"]})
        print("nfev by part (median / max over fits; 0 where absent):")
        for lab in labels:
            v = [r["nfev_by"].get(lab, 0) for r in rs]
            print(f"  {lab:32s} {np.median(v):6.1f} / {max(v)}")
        print("chosen law:", dict(collections.Counter(r["law"] for r in rs)))
        print("laws not offered:", dict(collections.Counter(
            k for r in rs for k in r["not_offered"])))
    print(f"\nload average: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


def compare(rows: list[dict[str, Any]], before: list[dict[str, Any]]) -> None:
    old = {(r["trace"], r["unload"]): r for r in before}
    worse, moved, law_changed, drops = [], [], [], []
    for r in rows:
        o = old.get((r["trace"], r["unload"]))
        if o is None:
            continue
        if r["law"] != o["law"]:
            law_changed.append((r["trace"], r["unload"], o["law"], r["law"]))
        dc = abs(r["C"] / o["C"] - 1.0)
        ds = abs(r["C_std"] / o["C_std"] - 1.0)
        moved.append((dc, ds))
        # the laws' table normalises chi^2 by the best law's residual variance: compare
        # the raw chi^2 of every law fitted in both, in residual variances of that law
        for law, (c2, s2) in r["raw_chi2"].items():
            if law in o["raw_chi2"]:
                d = (c2 - o["raw_chi2"][law][0]) / s2
                drops.append(d)
                if d > 1e-3:
                    worse.append((r["trace"], r["unload"], law, round(d, 5)))
    if moved:
        dc, ds = np.array(moved).T
        print(f"\nvs before ({len(moved)} fits): |dC/C| max {dc.max():.2e} median "
              f"{np.median(dc):.2e}; |d sigma/sigma| max {ds.max():.2e} median "
              f"{np.median(ds):.2e}")
    print(f"chosen law changed: {len(law_changed)} {law_changed[:5]}")
    if drops:
        d = np.asarray(drops)
        print(f"raw chi2 after - before, in residual variances, over {d.size} law fits: "
              f"min {d.min():.4f}, median {np.median(d):.2e}, max {d.max():.4f}; lower in "
              f"{np.sum(d < -1e-9)}, equal in {np.sum(np.abs(d) <= 1e-9)}, higher in "
              f"{np.sum(d > 1e-9)}")
    print(f"a law's chi2 higher than before by > 1e-3 residual variances: {len(worse)} "
          f"{worse[:8]}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unloads", type=int, default=60)
    ap.add_argument("--slow", type=int, default=0, help="unloads of the slow 5 L rig")
    ap.add_argument("--charge", type=int, default=0,
                    help="charges of the bench rig (bench_engine's --direction charge: 7 "
                         "bar abs into 1 bar, the supply given), at 1 kHz and at 10 kHz")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run each fit this many times, CPU the least of them (load)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--compare", type=Path)
    args = ap.parse_args()
    from bench_nodes import RIG

    counter = Counter()
    counter.install()
    rows = []
    if args.unloads:
        cfg = RigConfig(rate=10_000.0, pre_time=0.2, duration=1.2, **RIG)
        rows += measure("bench rig 0.2 L, 10 kHz", cfg, EstimatorSettings(volume=RIG["volume"]),
                        args.unloads, counter, args.repeat)
    if args.slow:
        cfg = RigConfig(rate=1000.0, volume=5e-3, conductance=2e-8, pre_time=1.0,
                        duration=60.0, noise_std=1000.0, quantization=10.0, seed=2,
                        effects=("heat_transfer",))
        rows += measure("slow rig 5 L heat transfer, 1 kHz", cfg,
                        EstimatorSettings(volume=5e-3), args.slow, counter, args.repeat)
    if args.charge:
        from bench_engine import CHARGE

        settings = EstimatorSettings(volume=RIG["volume"], direction="charge",
                                     supply_pressure=CHARGE["supply_pressure"])
        for rate in (1000.0, 10_000.0):
            cfg = RigConfig(rate=rate, pre_time=0.2, duration=1.2, **RIG, **CHARGE)
            rows += measure(f"bench rig 0.2 L charge, {rate:g} Hz", cfg, settings,
                            args.charge, counter, args.repeat)
    report(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.compare:
        compare(rows, json.loads(args.compare.read_text()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
