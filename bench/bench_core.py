"""Speed of the estimation core (issue 3). A script that prints a table, not a timed test.

    python bench/bench_core.py

Rates are samples per second of wall time on one core, best of several repetitions (the
minimum is the least disturbed by other load on the machine):

* batch: :func:`~pneumatic_unload.estimation.analyze` over a whole trace (the streaming
  estimator's block path, which jumps between decisions with vectorised checks), split into
  detection + crossing + eq 39 + isentropic inversion (``heat_model='adiabatic'``,
  ``curve_fit=False``), then what the natural-convection model inversion and the
  full-curve fit add, reported separately;
* streaming: :meth:`StreamingEstimator.push` sample by sample;
* simulation: a 10 s unload at 1 kHz with natural-convection heat transfer, against real
  time.

Before timing, the per-sample, random-block and batch paths are checked to give identical
results on the benchmark traces.
"""

from __future__ import annotations

import os

# one core: keep BLAS from spreading the dot products over threads
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import dataclasses  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402

from pneumatic_unload.analysis.runs import settings_for  # noqa: E402
from pneumatic_unload.config import RigConfig  # noqa: E402
from pneumatic_unload.estimation import (  # noqa: E402
    EstimatorSettings,
    StreamingEstimator,
    UnloadResult,
    analyze,
)
from pneumatic_unload.model import simulate  # noqa: E402
from pneumatic_unload.physics import orifice_conductance  # noqa: E402

NOISE = 1000.0  # 0.1 % of a 1 MPa full-scale transducer [Pa]


def best_time(fn: Callable[..., object], *args: object, repeat: int = 5) -> float:
    """Smallest wall time of ``repeat`` calls fn(*args) [s]."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best


def key(results: list[UnloadResult]) -> list[tuple[object, ...]]:
    return [(r.index, r.status, r.t_start, r.t_cross, r.tau_exp, r.conductance,
             r.conductance_model, r.i_complete) for r in results]


def per_sample(st: EstimatorSettings, t: np.ndarray, p: np.ndarray) -> list[UnloadResult]:
    est = StreamingEstimator(st)
    push = est.push
    out = []
    for a, b in zip(t.tolist(), p.tolist(), strict=True):
        r = push(a, b)
        if r:
            out += r
    return out + est.finish()


def main() -> None:
    traces = {
        "10 s unload, 2 L, 2 mm": RigConfig(
            volume=2e-3, conductance=orifice_conductance(2e-3), noise_std=NOISE, seed=1,
            duration=10.0, effects=("heat_transfer",)),
        "slow unload, 20 L, 1 mm (687 s)": RigConfig(
            volume=20e-3, conductance=orifice_conductance(1e-3), noise_std=NOISE, seed=2,
            effects=("heat_transfer",)),
    }
    rows = []
    rng = np.random.default_rng(0)
    for name, cfg in traces.items():
        sim = simulate(cfg)
        t, p = sim.t + 1.7e9, sim.measured
        n = t.size
        base = dataclasses.replace(settings_for(cfg), heat_model="adiabatic",
                                   curve_fit=False)
        # parity: batch == random blocks == per sample
        ref = key(analyze(t, p, base))
        est = StreamingEstimator(base)
        blk, i = [], 0
        while i < n:
            k = int(rng.integers(1, 20000))
            blk += est.push_block(t[i:i + k], p[i:i + k])
            i += k
        blk += est.finish()
        assert key(blk) == ref, "block path differs from batch"
        t_ps = best_time(per_sample, base, t, p, repeat=2)
        assert key(per_sample(base, t, p)) == ref, "per-sample path differs from batch"

        t_batch = best_time(analyze, t, p, base, repeat=9)
        nat = dataclasses.replace(base, heat_model="natural")
        t_nat = best_time(analyze, t, p, nat, repeat=5)
        fit = dataclasses.replace(base, heat_model="natural", curve_fit=True)
        t_fit = best_time(analyze, t, p, fit, repeat=2)
        rows.append((name, n, t_batch, t_nat, t_fit, t_ps))

    print("estimation core speed (one core, best of repeats)")
    print(f"{'trace':34s} {'samples':>8s} {'batch det+cross':>17s} {'+natural inv.':>14s} "
          f"{'+curve fit':>11s} {'per-sample push':>16s}")
    for name, n, tb, tn, tf, tp in rows:
        print(f"{name:34s} {n:8d} {n / tb / 1e6:9.2f} M/s {1e3 * tb:4.0f}ms"
              f" {1e3 * (tn - tb):+11.0f} ms {1e3 * (tf - tn):+8.0f} ms"
              f" {n / tp / 1e3:10.0f} k/s")

    for label, vol, dia in (("5 L, 1.5 mm (choked throughout)", 5e-3, 1.5e-3),
                            ("1 L, 3 mm (to atmosphere, subsonic end)", 1e-3, 3e-3)):
        cfg = RigConfig(volume=vol, conductance=orifice_conductance(dia), noise_std=NOISE,
                        duration=10.0, pre_time=0.0, effects=("heat_transfer",), seed=3)
        t_sim = best_time(simulate, cfg)
        print(f"simulate 10 s unload at 1 kHz with heat transfer, {label}: "
              f"{1e3 * t_sim:.1f} ms = {10.0 / t_sim:.0f}x real time")
    print("targets: batch >= 5 M samples/s, per-sample >= 500 k samples/s, "
          "simulation >= 100x real time")


if __name__ == "__main__":
    main()
