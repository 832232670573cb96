"""Sparse records that begin at the valve opening, on the independent Newton-cooling model
(``pneumatic_unload/test/foreign/newton_tank.py``): a script, not a test.

    python bench/bench_sparse_budget.py [N [SEED]]

Each trial: V 10-100 L, C 3-12e-9 m^3/(s Pa), b 0.3-0.5, p10 5-8 bar abs, thermal time
constant 0.5-20 s x (V / 10 L) (a large tank exchanges slowly), the wall N(T10, 2 K) and
not given (assumed = T10 with its default 2 K), 12-20 points from the opening over 2-3
unloading times with uneven stamps (+-30 % of the step), 1.5 kPa white noise; analysed
with ``start_time`` at the first point (the opening), V, T10 and p_atm exact. Prints one
row per trial (C error, z = error / sigma, the budget's largest line) and then the worst
and median |C error|, the shares within 1 and 2 sigma (55-80 %, 90-98 % wanted) and how
often each line is the budget's largest.

Measured (branch h11g, 60 trials, seed 5), before the held law's line: |C error| worst
14.1 %, median 6.4 %; within 1 sigma 20 +- 5 %, within 2 sigma 77 +- 5 %: the coverage
missed. The error follows the
thermal time constant (-10 % at tau_h 2 s, -3.5 % at 27 s, +4 to +9.5 % at 50-180 s):
with 12-20 points the fit holds the natural correlation as published (heat scale 1, not
fitted; one law, so the heat laws' model-form line is 0), and no line of the budget says
so. With tau_h >= 20 s (h of a few W/(m^2 K) on these tanks; 21 trials): 52 / 95 %,
median |error| 3.5 %; below 20 s (an exchange stronger than natural convection gives
here; 39 trials): 3 / 67 %. The budget's largest line: the curve fit's type A 55 of 60,
the fit-vs-crossing model form 3, the wall 2. After (the crossing's line for a heat
exchange not seen, uniform between none and twice the correlation's, kept in the final
budget when the law is held): 83 +- 5 % within 1 sigma, 97 +- 2 % within 2; tau_h >= 20 s
100 / 100 % (too wide there: the uniform spread is wider than those exchanges), below
74 / 95 %; the held law's line is the largest on 59 of 60.

SI units: s, Pa, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pneumatic_unload" / "test"))
from foreign.newton_tank import discharge

from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS

P_ATM = 101325.0
#: The wall not given: its default uncertainty stays; V, T10 and p exact.
EXACT_BUT_THE_WALL = {k: v for k, v in EXACT_INPUTS.items()
                      if k != "wall_temperature_uncertainty"}


def trial(rng: np.random.Generator, k: int) -> dict[str, object]:
    """One sparse record and its analysis."""
    volume = float(rng.uniform(0.01, 0.1))
    conductance = float(rng.uniform(3e-9, 1.2e-8))
    b, p10 = float(rng.uniform(0.3, 0.5)), float(rng.uniform(5e5, 8e5))
    tau_heat = float(np.exp(rng.uniform(math.log(0.5), math.log(20.0)))) * volume / 0.01
    t10 = 293.15
    t_wall = t10 + float(rng.normal(0.0, 2.0))
    n = int(rng.integers(12, 21))
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    step = float(rng.uniform(2.0, 3.0)) * tau0 / n
    t = np.arange(n) * step
    t[1:] += rng.uniform(-0.3, 0.3, n - 1) * step
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=t10,
                  p_atm=P_ATM, tau_heat=tau_heat, t_open=0.0, t_wall=t_wall)
    y = p + rng.normal(0.0, 1500.0, n)
    s = EstimatorSettings(volume=volume, initial_temperature=t10, atmosphere=P_ATM,
                          start_time=float(t[0]), **EXACT_BUT_THE_WALL)
    out = merge_final(analyze(t, y, s))
    if len(out) != 1 or not math.isfinite(out[0].conductance_model):
        return {"k": k, "why": f"{len(out)} result(s)"}
    (r,) = out
    bud = r.extra["budget"]
    terms = [x for x in bud["terms"] if x["std"] is not None and math.isfinite(x["std"])]
    top = max(terms, key=lambda x: x["std"])
    err = r.conductance_model / conductance - 1.0
    return {"k": k, "V": volume, "n": n, "tau_h": tau_heat, "err": err,
            "z": (r.conductance_model - conductance) / r.conductance_model_std,
            "top": top["name"], "top_share": top["std"] / r.conductance_model_std,
            "law": r.extra.get("curve_fit", {}).get("heat_law", "")}


def main(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    rows = []
    cpu = time.process_time()
    for k in range(n):
        row = trial(rng, k)
        rows.append(row)
        if "err" not in row:
            print(f"{k:3d} {row['why']}", flush=True)
            continue
        print(f"{k:3d} V {row['V'] * 1e3:5.1f} L {row['n']:2d} points tau_h {row['tau_h']:6.1f}"
              f" s: C error {100 * row['err']:+.3f} % z {row['z']:+.2f} {row['law']:>14s};"
              f" largest: {row['top']} ({100 * row['top_share']:.0f} % of sigma)", flush=True)
    ok = [r for r in rows if "err" in r]
    e = np.abs([100 * r["err"] for r in ok])
    z = np.abs([r["z"] for r in ok])
    tops: dict[str, int] = {}
    for r in ok:
        tops[str(r["top"])] = tops.get(str(r["top"]), 0) + 1
    q1, q2 = float(np.mean(z <= 1)), float(np.mean(z <= 2))
    print(f"{len(ok)}/{n} analysed (seed {seed}): |C error| worst {e.max():.3f} %, median "
          f"{float(np.median(e)):.3f} %; within 1 sigma {100 * q1:.0f} +- "
          f"{100 * math.sqrt(q1 * (1 - q1) / z.size):.0f} %, within 2 sigma {100 * q2:.0f} +- "
          f"{100 * math.sqrt(q2 * (1 - q2) / z.size):.0f} %; largest line: "
          + ", ".join(f"{k} {v}" for k, v in sorted(tops.items(), key=lambda x: -x[1]))
          + f"; CPU {time.process_time() - cpu:.0f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 40,
         int(sys.argv[2]) if len(sys.argv) > 2 else 5)
