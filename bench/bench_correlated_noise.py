"""Correlated (AR(1)) noise: phantom unloads on an idle stream, and tau_exp's sigma.

``python bench/bench_correlated_noise.py [--seeds N] [--draws N]`` (project venv,
``PYTHONPATH`` at the repo root). A transducer low-passed below its logging rate gives
AR(1) noise of lag-1 correlation rho = exp(-2 pi f_c / f_s). Two measurements:

* ``idle``: N one-minute streams at 1 kHz of AR(1) noise (300 Pa) on p_atm per rho
  (rho 0 to 0.99; :func:`analyze`, block input): the results reported (every one a
  phantom), in the first 2 s (the stream's first plateau, whose few samples cannot show
  the correlation) and after them; and the same on a charged plateau (6 bar), in all.
* ``discharge``: N noise draws (seeds 0..N-1) of one discharge (2 L, 8e-9 m^3/(s Pa),
  b 0.4, 6 bar, 9.1 s recorded, the package's simulator, AR(1) noise of 1 kPa; no curve
  fit) per rho: the spread of tau_exp over the draws against its mean reported sigma (1
  when the sigma is honest), and the phantom unloads started on the tail's noise after it.

Measured (session 28, 2 cores; 10 seeds, 30 draws). Before (8ee2ada): idle minutes gave
6-89 phantoms each at rho 0.8-0.99 (3 seeds), the 30 discharges 2, 44, 69 and 80
phantoms after their tails at rho 0.5, 0.8, 0.9 and 0.95, and tau_exp's spread was 4.28
times its sigma at rho 0.9 (1.10 for white noise). After (the detector testing each
event with the plateau's correlation, tau_exp's variance inflated), the table below:
what remains lies in a plateau's first second (a stream's start, or just after a
tail), whose few samples cannot show the correlation. On 1ff2a83 (12 s; 10 idle
minutes, 30 discharges)::

    | rho | idle: first 2 s / after | tau_exp spread / sigma | phantoms after the tail |
    |---|---|---|---|
    | 0 | 0 / 0 | 1.10 | 0 |
    | 0.5 | 0 / 0 | 1.09 | 2 |
    | 0.8 | 2 / 0 | 1.04 | 3 |
    | 0.9 | 6 / 0 | 0.98 | 1 |
    | 0.95 | 4 / 0 | 0.85 | 3 |
    | 0.99 | 5 / 1 | 1.08 | 4 |

Then a plateau within 5 % of the given end pressure has nothing to unload
(``decisions.END_GAP_MIN``, session 29; 7 s): 0 / 0 idle and 0 after the tail at every
rho, tau_exp's column unchanged.

On a charged plateau (6 bar; session 30) the first second's phantom could not be vetoed
so: before ``estimation.follow``, 1, 2, 2 and 0 of 10 idle minutes at rho 0.8, 0.9, 0.95
and 0.99 (0 at rho 0 and 0.5) ended with an ``aborted`` unload that nothing had
followed. After it (13 s): 0 at every rho, the other columns unchanged.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.signal import lfilter

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import EstimatorSettings, analyze
from pneumatic_unload.model.simulate import simulate

P_ATM = 101325.0


def ar1(n: int, rho: float, sd: float, seed: int) -> np.ndarray:
    """n samples of stationary AR(1) noise (lag-1 correlation rho, deviation sd [Pa])."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, sd * np.sqrt(1.0 - rho**2), n)
    return lfilter([1.0], [1.0, -rho], e, zi=[rho * rng.normal(0.0, sd)])[0]


def idle(rho: float, seeds: int, level: float = P_ATM) -> tuple[int, int]:
    """Results reported on ``seeds`` idle minutes at ``level`` [Pa]: (within the first 2 s,
    after them)."""
    early = late = 0
    t = np.arange(60_000) * 1e-3
    for seed in range(seeds):
        res = analyze(t, level + ar1(t.size, rho, 300.0, seed), EstimatorSettings(volume=2e-3))
        late += sum(1 for r in res if not r.t_start < 2.0)
        early += sum(1 for r in res if r.t_start < 2.0)
    return early, late


def discharges(rho: float, draws: int) -> tuple[float, int]:
    """On ``draws`` noise draws of the discharge: (spread of tau_exp / its mean reported
    sigma [-], phantom unloads after the discharge's tail [-])."""
    taus, stds, phantoms = [], [], 0
    for seed in range(draws):
        noise = ({"noise_std": 0.0, "noise_ar_rho": rho, "noise_ar_std": 1000.0} if rho > 0
                 else {"noise_std": 1000.0})
        cfg = RigConfig(volume=2e-3, conductance=8e-9, critical_ratio=0.4,
                        initial_pressure=6e5, seed=seed, **noise)
        sim = simulate(cfg)
        res = analyze(sim.t, sim.measured, EstimatorSettings(volume=cfg.volume,
                                                             curve_fit=False))
        taus.append(res[0].tau_exp)
        stds.append(res[0].tau_exp_std)
        phantoms += len({r.t_start for r in res}) - 1
    return float(np.std(taus, ddof=1) / np.mean(stds)), phantoms


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--draws", type=int, default=30)
    a = ap.parse_args(argv)
    print(f"{a.seeds} idle minutes, {a.draws} discharges\n")
    print("| rho | idle: first 2 s / after | idle at 6 bar | tau_exp spread / sigma | "
          "phantoms after the tail |")
    print("|---|---|---|---|---|")
    for rho in (0.0, 0.5, 0.8, 0.9, 0.95, 0.99):
        early, late = idle(rho, a.seeds)
        charged = sum(idle(rho, a.seeds, 6e5))
        ratio, phantoms = discharges(rho, a.draws)
        print(f"| {rho:g} | {early} / {late} | {charged} | {ratio:.2f} | {phantoms} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
