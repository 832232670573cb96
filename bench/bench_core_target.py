"""The core target of issue #11 ("start time within max(1 sample, 2x its Cramer-Rao bound)
and tau_exp within 3 of its stated sigma, on every trace over that issue's ranges") swept
over random traces: a script, not a test (the test, ``test_accuracy.py``, checks 6 rigs).

    python bench/bench_core_target.py [N [SEED]]

Each trace draws V 1-20 L, d 1-3 mm (C = 0.128 d^2 dm^3/(s bar)), p10 4-8 bar abs,
b 0.2-0.5, a sample rate 100 Hz-2 kHz and white noise 200-3000 Pa (both log-uniform);
adiabatic discharges analysed with the adiabatic model and the inputs exact (as the test),
the record cut at 0.35 of the default duration. The start checked is the final result's
(the curve fit's ``t_start_model``), its bound from the Fisher information of (t0, p10,
log C, b) at the sample instants (``bench_accuracy.crlb`` scaled to the trace's noise);
tau_exp against the noise-free discharge's on a dense grid. Prints one row per trace, then
how many pass each part and both.

Measured (branch h11d, seed 11, 300 traces): start 292/300, tau_exp 296/300, both 288/300.
The start misses are at 1.02-1.29 x (2 x CRLB) on slow, noisy traces; the fit's start is
efficient (RMS error / CRLB 0.96), so 2 x the bound is a ~95 % limit and "every trace" is
not reachable by any unbiased estimator (an efficient one misses on 4.6 % of traces; here
2.7 %).

tau_exp's sigma (branch h11g; seed 11, 300 traces, before -> after): z RMS 1.112 -> 1.110,
within 1 / 2 / 3 sigma 66.3 / 92.0 / 98.7 -> 63.3 / 93.0 / 99.3 %, beyond 3 sigma 4 -> 2
(0.8 expected); tau_exp within 3 sigma 296 -> 298/300, both parts 288 -> 290/300, start
292/300 unchanged. The start's share was too narrow (its own z RMS 1.30 -> 1.04 over 900
traces of seeds 11-13, beyond 3 sigma 24 -> 5): its sigma ignored the curvature of the
start fit and the errors of t0 and p10 are correlated, and p* = f(p10) moves the crossing
(now the start fit's covariance, :func:`~pneumatic_unload.estimation.regression.hinge_cov`,
through tau = t_cross(p*) - t0); the quadratic's model form left biases of up to 1.9 sigma
on fast discharges at low rates (now a power-law remainder, 0.29 sigma at most). What is
left on seed 11 is the crossing fit's own noise draws: its z RMS is 1.096 here, 1.033 and
1.004 on seeds 12 and 13, a fit on a window fixed about the true crossing gives 1.08 on the
same samples, and 20 000 noise draws on four of these rigs give RMS 0.999 with 99.77 %
within 3 sigma: the crossing's sigma is right and seed 11's draws are on the wide side.
Over seeds 11-13 (900 traces) tau_exp's z RMS is 1.048, within 1 / 2 / 3 sigma 68.4 /
93.6 / 99.3 % (before 1.023, 70.0 / 94.3 / 99.3 %: the two omissions had roughly offset).

SI units: s, Pa, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time

import numpy as np
from bench_accuracy import NOISE, crlb

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import analyze, merge_final
from pneumatic_unload.model import default_duration, discharge, simulate
from pneumatic_unload.physics import P_STAR_FRACTION, orifice_conductance
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS


def true_tau_exp(cfg: RigConfig) -> float:
    """tau_exp of the noise-free discharge [s]: from the opening to the p* crossing, on a
    grid of 200 000 intervals."""
    p_star = cfg.atmosphere + P_STAR_FRACTION * (cfg.initial_pressure - cfg.atmosphere)
    t = np.linspace(0.0, default_duration(cfg), 200_001)
    p = discharge(cfg, t, 0.0, rtol=1e-11)[0]
    k = int(np.flatnonzero(p < p_star)[0])
    return float(t[k - 1] + (p[k - 1] - p_star) / (p[k - 1] - p[k]) * (t[k] - t[k - 1]))


def trace(rng: np.random.Generator, seed: int) -> dict[str, float]:
    """One random trace: its draws and the two checks."""
    rate = float(np.exp(rng.uniform(math.log(100.0), math.log(2000.0))))
    noise = float(np.exp(rng.uniform(math.log(200.0), math.log(3000.0))))
    cfg = RigConfig(volume=float(rng.uniform(1e-3, 20e-3)),
                    conductance=orifice_conductance(float(rng.uniform(1e-3, 3e-3))),
                    initial_pressure=float(rng.uniform(4e5, 8e5)),
                    critical_ratio=float(rng.uniform(0.2, 0.5)), rate=rate, noise_std=noise,
                    seed=seed)
    cfg = cfg.replace(duration=0.35 * default_duration(cfg))
    sim = simulate(cfg)
    st = dataclasses.replace(settings_for(cfg), **EXACT_INPUTS, heat_model="adiabatic")
    out = merge_final(analyze(sim.t, sim.measured, st))
    row = {"V_L": cfg.volume * 1e3, "C": cfg.conductance, "p10": cfg.initial_pressure,
           "rate": rate, "noise": noise, "n_results": len(out)}
    if len(out) != 1:
        return {**row, "start_ok": False, "tau_ok": False, "why": f"{len(out)} unloads"}
    (r,) = out
    bound = crlb(cfg, sim.t)[0] * noise / NOISE
    err = abs(r.t_start_model - sim.t_open)
    z_tau = (r.tau_exp - true_tau_exp(cfg)) / r.tau_exp_std
    return {**row, "start_samples": err * rate, "bound_samples": bound * rate,
            "z_tau": z_tau, "start_ok": bool(err <= max(1.0 / rate, 2.0 * bound)),
            "tau_ok": bool(abs(z_tau) <= 3.0), "why": r.status}


def main(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rows = []
    cpu = time.process_time()
    for k in range(n):
        row = trace(rng, seed * 1000 + k)
        rows.append(row)
        print(f"{k:3d} V {row['V_L']:5.1f} L C {row['C']:.3g} p10 {row['p10'] / 1e5:.2f} bar "
              f"{row['rate']:6.0f} Hz noise {row['noise']:5.0f} Pa: start "
              f"{row.get('start_samples', math.nan):6.2f} samples (2 x bound "
              f"{2 * row.get('bound_samples', math.nan):6.2f}) "
              f"{'ok ' if row['start_ok'] else 'MISS'}; z_tau "
              f"{row.get('z_tau', math.nan):+5.2f} {'ok' if row['tau_ok'] else 'MISS'}"
              f" [{row['why']}]", flush=True)
    s_ok = sum(r["start_ok"] for r in rows)
    t_ok = sum(r["tau_ok"] for r in rows)
    both = sum(r["start_ok"] and r["tau_ok"] for r in rows)
    ratio = np.array([r["start_samples"] / r["bound_samples"] for r in rows
                      if "start_samples" in r and r["bound_samples"] > 0])
    big = np.array([r["start_samples"] / r["bound_samples"] for r in rows
                    if "start_samples" in r and r["bound_samples"] > 0.5])
    print(f"start error / CRLB: RMS {math.sqrt(float(np.mean(ratio**2))):.2f} over "
          f"{ratio.size} traces ({math.sqrt(float(np.mean(big**2))):.2f} over the {big.size} "
          f"whose bound exceeds half a sample, where '1 sample' does not decide); an "
          f"efficient estimator (RMS 1.00) exceeds 2 x its bound on 4.6 % of traces")
    z = np.array([r["z_tau"] for r in rows if "z_tau" in r])
    print(f"tau_exp z over {z.size} traces: RMS {math.sqrt(float(np.mean(z**2))):.3f}, "
          f"mean {float(np.mean(z)):+.3f}; within 1 / 2 / 3 sigma "
          f"{100 * np.mean(abs(z) <= 1):.1f} / {100 * np.mean(abs(z) <= 2):.1f} / "
          f"{100 * np.mean(abs(z) <= 3):.1f} % (68.3 / 95.4 / 99.7 expected); beyond 3: "
          f"{int(np.sum(abs(z) > 3))} ({0.0027 * z.size:.1f} expected)")
    print(f"{n} traces (seed {seed}): start within max(1 sample, 2 x CRLB) {s_ok}/{n}, "
          f"tau_exp within 3 sigma {t_ok}/{n}, both {both}/{n}; CPU "
          f"{time.process_time() - cpu:.0f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 60,
         int(sys.argv[2]) if len(sys.argv) > 2 else 11)
