"""Numerical reproducibility of the analysis across machines, measured on one (a script).

Another CPU makes numpy's OpenBLAS pick another kernel and numpy's own loops another SIMD
width: the fit's arithmetic differs in its last bits. This script analyses the same
simulated discharges in subprocesses under other OpenBLAS kernels (``OPENBLAS_CORETYPE``)
and with numpy's SIMD extensions above the baseline switched off
(``NPY_DISABLE_CPU_FEATURES``), and with the samples perturbed by 1e-14 relative in
process, and prints per variant the largest relative change of the final C and b against
the default run, next to what the fit states ('reproducibility'), and how often the
change exceeded the statement.

Usage: ``.venv/bin/python bench/bench_reproducibility.py [--traces 20] [--seed 9]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
#: OpenBLAS kernels tried (those the CPU cannot run are reported as failed).
CORETYPES = ("Prescott", "Nehalem", "Sandybridge", "Haswell", "Zen", "SkylakeX")
#: numpy SIMD extensions switched off in one variant.
NPY_OFF = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX2 FMA3 AVX F16C"


def configs(n: int, seed: int) -> list[dict[str, object]]:
    """Random discharges (as test/test_reproducibility.py draws them), as dicts."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        out.append({
            "volume": float(rng.uniform(0.5e-3, 5e-3)), "d": float(rng.uniform(1.5e-3, 3e-3)),
            "critical_ratio": float(rng.uniform(0.25, 0.5)),
            "initial_pressure": float(rng.uniform(4e5, 8e5)),
            "effects": ["heat_transfer"] if i % 2 else [], "seed": 100 + i,
            "noise_std": float(rng.choice([200.0, 1000.0, 3000.0]))})
    return out


def run(cases: list[dict[str, object]], perturb: float) -> list[dict[str, float]]:
    """Analyse each case [C m^3/(s Pa), b -, stated reproducibility -]."""
    from pneumatic_unload.analysis.runs import settings_for
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.estimation.batch import analyze
    from pneumatic_unload.model.simulate import simulate
    from pneumatic_unload.physics import orifice_conductance

    out = []
    rng = np.random.default_rng(3)
    for c in cases:
        cfg = RigConfig(volume=c["volume"], conductance=orifice_conductance(c["d"]),
                        critical_ratio=c["critical_ratio"],
                        initial_pressure=c["initial_pressure"], effects=tuple(c["effects"]),
                        pre_time=0.5, duration=8.0, seed=c["seed"], noise_std=c["noise_std"],
                        quantization=10.0, full_scale=1.1e6)
        sim = simulate(cfg)
        p = sim.measured * (1.0 + perturb * rng.standard_normal(sim.measured.size))
        finals = [r for r in analyze(sim.t, p, settings_for(cfg)) if r.final]
        if not finals:
            out.append({})
            continue
        r = finals[0]
        cf = r.extra.get("curve_fit", {})
        out.append({"C": r.conductance_model, "b": r.critical_ratio,
                    "rep_C": cf.get("conductance_reproducibility", float("nan")),
                    "rep_b": cf.get("critical_ratio_reproducibility", float("nan"))})
    return out


def child(env: dict[str, str], cases: list[dict[str, object]]) -> list[dict[str, float]] | str:
    """Run the cases in a subprocess with ``env`` added; its results or why it failed."""
    proc = subprocess.run([sys.executable, __file__, "--child"], input=json.dumps(cases),
                          capture_output=True, text=True, env={**os.environ, **env},
                          timeout=1800)
    if proc.returncode != 0:
        return (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1]
    return json.loads(proc.stdout)


def compare(name: str, base: list[dict[str, float]], other: list[dict[str, float]]) -> None:
    """Print the largest relative changes of C and b and the exceedances of the statement."""
    worst = {"C": 0.0, "b": 0.0}
    over = {"C": 0, "b": 0}
    n = 0
    for a, b in zip(base, other, strict=True):
        if not a or not b:
            continue
        n += 1
        for k in ("C", "b"):
            if not (np.isfinite(a[k]) and np.isfinite(b[k])):
                continue
            d = abs(b[k] - a[k]) / abs(a[k])
            worst[k] = max(worst[k], d)
            over[k] += d > max(a[f"rep_{k}"], 1e-13)
    print(f"{name:28s} {n:3d}  C {worst['C']:9.2e} ({over['C']} over)  "
          f"b {worst['b']:9.2e} ({over['b']} over)", flush=True)


def main() -> int:
    """Run every variant and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--traces", type=int, default=20)
    ap.add_argument("--seed", type=int, default=9)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        json.dump(run(json.loads(sys.stdin.read()), 0.0), sys.stdout)
        return 0
    cases = configs(args.traces, args.seed)
    base = child({}, cases)
    if isinstance(base, str):
        print(f"default run failed: {base}")
        return 1
    reps = [r["rep_C"] for r in base if r]
    print(f"{len(cases)} traces (seed {args.seed}); stated C reproducibility: median "
          f"{np.median(reps):.1e}, largest {max(reps):.1e}")
    print(f"{'variant':28s} {'n':>3s}  largest relative change against the default run")
    compare("samples x (1 + 1e-14 N(0,1))", base, run(cases, 1e-14))
    for core in CORETYPES:
        other = child({"OPENBLAS_CORETYPE": core}, cases)
        if isinstance(other, str):
            print(f"{'OPENBLAS_CORETYPE=' + core:28s} failed: {other}")
            continue
        compare("OPENBLAS_CORETYPE=" + core, base, other)
    other = child({"NPY_DISABLE_CPU_FEATURES": NPY_OFF}, cases)
    if isinstance(other, str):
        print(f"{'numpy SIMD off':28s} failed: {other}")
    else:
        compare("numpy SIMD above SSE3 off", base, other)
    return 0


if __name__ == "__main__":
    sys.exit(main())
