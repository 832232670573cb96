"""Acceptance harness of the discrepancy workflow (issue #5): randomised hidden effects.

Run: ``.venv/bin/python bench/bench_discrepancy.py [--per-effect N] [--null N] [--ar N]
[--workers 2]``. Prints a markdown table with every acceptance line, measured vs target.
Data: :func:`pneumatic_unload.discrepancy.synthetic.draw_case` (fixed seeds), the workflow is
not told which effect is on. "Noise-free misfit" is the chi^2 of the baseline fitted to the
noise-free trace with the true noise model (sigma = 1 kPa); detection is scored on trials
with a misfit >= 50. Intervals are linear here (``profile=False``) to keep the run short;
the speed line runs the full workflow with profiles. "Claimed" is an effect the data name
(``DiscrepancyResult.named``: its round's runner-up more than the BIC threshold behind);
a member of an ambiguity is reported, not claimed. ``--seed-offset`` draws fresh trials
(seeds not used while the decision rules were written); ``--effects`` runs a subset;
``--score FILE ...`` scores the ``--rows`` of earlier runs, pooled. Every rate is printed
with its one-sided 95 % Clopper-Pearson bound: a rate meets its target on the trials run,
the bound shows it (e.g. 0 claims in 59 trials bound a rate at 5 %, in 149 at 2 %).

Measured on branch h12g (main 38a1474 with the law-variant rule of ``search.decide``), one
pooled run: fixed seeds (``--per-effect 10``, 150 white, 80 per AR level) and fresh ones
(``--seed-offset 100000``, the same counts), 840 trials: confident wrong name (winner > 10
ahead, truth not in the reported set) 0/220 (<= 1.4 %; the raw count 1/220 is fresh seed
101001, its truth now in the set; 1/55 on main); one name, no ambiguity, wrong 0/220;
confident wrong C 0/840; claimed not simulated 0/840 (<= 0.4 %); claims on effect-free data
white 0/300 (<= 1.0 %), AR(1) 0.5 and 0.9 0/160 each (<= 1.9 %); named right alone or an
ambiguity whose C range holds the truth: every leak, the hot start and the pipe volume
100 %; named exactly right alone: leak 17/20 and pipe_volume 7/19 (below 90 / 80 %: the
rest are BIC-window ambiguities with the hot start / the downstream leak, truth in the set).

Session 27 (main 561198a), the fixed seeds alone (``--per-effect 10``, 150 white, 80 per AR
level), 430 trials in 357 s: confident wrong name 0/120, confident wrong C 0/430, claimed
not simulated 0/430, claims on effect-free data 0/150 white and 0/80 at each AR level,
detection 101/101; named exactly right alone: leak 8/10, pipe_volume 3/10. The C range
misses the truth on 10 trials, every one a hidden orifice leak (9 downstream; misfit 0-4):
since b5af6a7 the range holds the total conductance and the parallel-leak bound, stated
apart, the component's (which no pressure record can tell apart; the bench counted these
against the range alone until session 27): missing both 0/430.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from multiprocessing import Pool

import numpy as np

from pneumatic_unload.config import RigConfig
from pneumatic_unload.discrepancy import DiscrepancySettings, find_discrepancy
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.synthetic import NOISE_STD, draw_case
from pneumatic_unload.discrepancy.types import CANDIDATES as EFFECTS
from pneumatic_unload.fit.noise import NoiseModel
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.model import simulate

ONE_PARAM = {"heat_transfer": "tau_heat", "valve_opening": "t_ramp",
             "sensor_lag": "tau_sensor", "leak": "leak_fraction",
             "leak_downstream": "leak_downstream_fraction", "sensor_offset": "offset",
             "sensor_gain": "gain"}
#: Candidates of issue 12 (leaks in both places, the hot start): named right, or an
#: ambiguity whose C range holds the true C (the line is printed for pipe_volume too: a
#: pipe volume and a downstream leak are look-alikes at the harness's sizes).
LEAKS = ("leak", "leak_downstream", "orifice_leak", "orifice_leak_downstream", "hot_start")
#: Effects present in a trial's simulation besides its own (the hot start is heat
#: transfer with the gas warmer than the wall).
ALSO_SIMULATED = {"hot_start": ("heat_transfer",)}


def noise_free_misfit(case, settings) -> float:
    """chi^2 of the baseline fitted to the noise-free trace (true noise model)."""
    sim = case.simulate()
    clean = case.noise_free()
    prob = Problem(sim.t, sim.measured, settings)
    n = prob.t.size
    rho = case.config.noise_ar_rho if case.config.noise_ar_std > 0 else 0.0
    prob.y = clean.measured[:n]
    prob.trace = Trace(prob.t, prob.y, NoiseModel(NOISE_STD, rho, n, "true"), 0.0,
                       edges=prob.lik.edges)
    prob.lik = prob.trace.lik
    fit = prob.fit(prob.model(()), [prob.neutral_theta(0.3), prob.neutral_theta(0.5)])
    return fit.chi2


def trial(job: tuple[str, int, float]) -> dict:
    effect, seed, rho = job
    case = draw_case(effect, seed, rho=rho)
    cfg = case.config
    sim = case.simulate()
    # data made by the package's own model: no model-limits term in C's sigma
    s = DiscrepancySettings(volume=cfg.volume, initial_temperature=cfg.initial_temperature,
                            atmosphere=cfg.atmosphere, profile=False, model_uncertainty=0.0)
    t0 = time.perf_counter()
    try:
        res = find_discrepancy(sim.t, sim.measured, s)
    except Exception as exc:  # a crash is a failed trial, never a dead harness
        return {"effect": effect, "seed": seed, "rho": rho, "error": repr(exc)}
    el = time.perf_counter() - t0
    out = {"effect": effect, "seed": seed, "rho": rho, "claimed": res.effect,
           "amb": list(res.ambiguous_with), "delta": res.delta_bic, "n": sim.t.size,
           "nrms_after": res.after.nrms, "white_after": res.after.white,
           "nrms_before": res.before.nrms, "elapsed": el, "error": None,
           "effects": list(res.effects), "named": list(res.named),
           "c": res.conductance, "c_std": res.conductance_std(),
           "c_true": cfg.conductance, "c_range": getattr(res, "conductance_range", None),
           "c_amb": bool(getattr(res.conductance_ambiguity, "ambiguous", False)),
           "c_parallel_low": getattr(res.conductance_ambiguity, "parallel_low", math.nan)}
    if effect != "none":
        out["misfit"] = noise_free_misfit(case, s)
        par = ONE_PARAM.get(effect)
        if par and res.effect == effect and par in res.parameters:
            tv = case.truth[par]
            out["param_err"] = abs(res.parameters[par].value / tv - 1.0)
    return out


def speed() -> tuple[float, int]:
    """Full workflow (all candidates, profiles) on one 10 s trace at 1 kHz [s]."""
    cfg = RigConfig(volume=2e-3, conductance=7.5e-9, critical_ratio=0.4,
                    initial_pressure=7e5, rate=1000.0, pre_time=0.2, duration=9.8,
                    noise_std=NOISE_STD, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=3.0, seed=1)
    sim = simulate(cfg)
    t0 = time.perf_counter()
    find_discrepancy(sim.t, sim.measured, DiscrepancySettings(volume=cfg.volume))
    return time.perf_counter() - t0, sim.t.size


def pct(k: int, n: int) -> str:
    return f"{100.0 * k / n:.1f} % ({k}/{n})" if n else "n/a (0 trials)"


def clopper_pearson(k: int, n: int, upper: bool, level: float = 0.95) -> float:
    """One-sided Clopper-Pearson bound on a rate from k of n trials (exact binomial):
    the upper bound when ``upper`` (rates that must stay low), else the lower [-]."""
    from scipy.stats import beta

    if n == 0:
        return math.nan
    if upper:
        return 1.0 if k == n else float(beta.ppf(level, k + 1, n - k))
    return 0.0 if k == 0 else float(beta.ppf(1.0 - level, k, n - k + 1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-effect", type=int, default=25)
    # null trials: 0 claims in 150 bound the rate at 2 %, 0 in 80 at 3.7 % (one-sided 95 %)
    ap.add_argument("--null", type=int, default=150, help="white-noise null trials")
    ap.add_argument("--ar", type=int, default=80, help="null trials per AR(1) rho")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows", metavar="FILE", help="write every trial's row as JSON lines")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="added to every seed (fresh trials: e.g. 100000)")
    ap.add_argument("--effects", nargs="*", default=None, choices=EFFECTS,
                    help="only these hidden effects (default: all)")
    ap.add_argument("--score", nargs="+", metavar="FILE",
                    help="score the rows of earlier runs (--rows files, pooled; a trial "
                         "in several files counts once) instead of running trials")
    args = ap.parse_args(argv)
    if args.score:
        pooled: dict[tuple, dict] = {}
        for name in args.score:
            with open(name, encoding="utf-8") as fh:
                for text in fh:
                    r = json.loads(text)
                    pooled[(r["effect"], r["seed"], r["rho"])] = r
        return score(list(pooled.values()), None, args.workers, 0.0)
    so = args.seed_offset
    jobs = [(e, so + 1000 + k, 0.0) for e in (args.effects or EFFECTS)
            for k in range(args.per_effect)]
    jobs += [("none", so + 5000 + k, 0.0) for k in range(args.null)]
    jobs += [("none", so + 6000 + k, r) for r in (0.5, 0.9) for k in range(args.ar)]
    t0 = time.perf_counter()
    # rows are written as they arrive (a run stopped early keeps its trials), then sorted
    partial = open(args.rows, "w", encoding="utf-8") if args.rows else None
    with Pool(args.workers) as pool:
        rows = []
        for i, r in enumerate(pool.imap_unordered(trial, jobs, chunksize=1)):
            rows.append(r)
            if partial is not None:
                partial.write(json.dumps(r, default=float) + "\n")
                partial.flush()
            if (i + 1) % 20 == 0:
                print(f"  {i + 1}/{len(jobs)} trials, {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr, flush=True)
    wall = time.perf_counter() - t0
    if partial is not None:
        partial.close()
        with open(args.rows, "w", encoding="utf-8") as fh:
            for r in sorted(rows, key=lambda r: (r["effect"], r["rho"], r["seed"])):
                fh.write(json.dumps(r, default=float) + "\n")
    return score(rows, speed(), args.workers, wall)


def score(rows: list[dict], sp_n: tuple[float, int] | None, workers: int, wall: float
          ) -> int:
    """Print the acceptance table of trial rows (and the speed line when measured)."""
    errors = [r for r in rows if r["error"]]
    ok = [r for r in rows if not r["error"]]
    eff = [r for r in ok if r["effect"] != "none"]
    big = [r for r in eff if r["misfit"] >= 50.0]
    lines = ["| acceptance line | measured | one-sided 95 % bound (Clopper-Pearson) | target "
             "| met (rate / bound) |", "| --- | --- | --- | --- | --- |"]

    def line(name: str, k: int, n: int, target: float, geq: bool = True) -> None:
        v = k / n if n else math.nan
        met = (v >= target if geq else v <= target) if n else False
        bound = clopper_pearson(k, n, upper=not geq)
        shown = (bound >= target if geq else bound <= target) if n else False
        lines.append(f"| {name} | {pct(k, n)} | {'>=' if geq else '<='} "
                     f"{100 * bound:.1f} % | {'>=' if geq else '<='} {100 * target:.0f} % | "
                     f"{'yes' if met else 'NO'} / {'yes' if shown else 'no'} |")

    line("detection (misfit >= 50): effect claimed", sum(r["claimed"] != "none" for r in big),
         len(big), 0.95)
    for e, target in (("heat_transfer", 0.9), ("leak", 0.9), ("sensor_offset", 0.9),
                      ("pipe_volume", 0.8)):
        sel = [r for r in big if r["effect"] == e]
        line(f"named exactly right (alone): {e}", sum(
            r["claimed"] == e and not r["amb"] for r in sel), len(sel), target)
    for e in ("valve_opening", "sensor_lag", "sensor_offset", "sensor_gain"):
        sel = [r for r in big if r["effect"] == e]
        line(f"truth inside reported set: {e}", sum(
            e in [r["claimed"], *r["amb"]] for r in sel), len(sel), 0.95)
    # the winner more than 10 ahead of the truth: confident when the verdict does not list
    # the truth in its ambiguity set (a law variant fitting as well but for the penalty of
    # its parameters is listed: search.decide); the raw count is printed too
    ahead = [r for r in eff if r["claimed"] not in ("none", r["effect"])
             and r["delta"][r["claimed"]] - r["delta"][r["effect"]] > 10.0]
    line("confident wrong name (winner > 10 ahead of truth, truth not in the reported set), "
         "all effect trials", sum(r["effect"] not in r["amb"] for r in ahead), len(eff), 0.02,
         geq=False)
    lines.append("| (information) winner > 10 ahead of truth, truth in the reported set or "
                 f"not, all effect trials | {pct(len(ahead), len(eff))} | | | |")
    line("confident wrong name (one name, no ambiguity, wrong), all effect trials",
         sum(r["claimed"] not in ("none", r["effect"]) and not r["amb"] for r in eff),
         len(eff), 0.02, geq=False)
    errs = [r["param_err"] for r in eff if "param_err" in r]
    if errs:
        med, p90 = float(np.median(errs)), float(np.percentile(errs, 90))
        lines.append(f"| parameter error, one-parameter effects named right (n = {len(errs)})"
                     f" | median {100 * med:.2f} %, p90 {100 * p90:.2f} % | | <= 5 %, <= 20 % "
                     f"| {'yes' if med <= 0.05 and p90 <= 0.2 else 'NO'} |")
        for e, par in ONE_PARAM.items():
            ee = [r["param_err"] for r in eff if "param_err" in r and r["effect"] == e]
            if ee:
                lines.append(f"| - {par} ({e}, n = {len(ee)}) | median "
                             f"{100 * float(np.median(ee)):.2f} %, p90 "
                             f"{100 * float(np.percentile(ee, 90)):.2f} % | | | |")
    def c_in_range(r: dict) -> bool:
        return r["c_range"] is not None and r["c_range"][0] <= r["c_true"] <= r["c_range"][1]

    def held_by_bound(r: dict) -> bool:
        """The truth below the range, within the parallel-leak bound: the component's C
        when a leak in parallel follows its flow law, which no pressure record can tell
        from C (stated apart from the range since b5af6a7, with the leak test that bounds
        it; the hidden downstream orifice leak)."""
        low = r.get("c_parallel_low", math.nan)
        return (r["c_range"] is not None and math.isfinite(low)
                and low <= r["c_true"] <= r["c_range"][1])

    for e in (e for e in (*LEAKS, "pipe_volume") if e in EFFECTS):
        sel = [r for r in big if r["effect"] == e]
        line(f"named right alone, or ambiguity with C range holding the truth: {e}", sum(
            (r["claimed"] == e and not r["amb"] and abs(r["c"] - r["c_true"])
             <= 3 * r["c_std"]) or (e in [r["claimed"], *r["amb"]] and c_in_range(r))
            for r in sel), len(sel), 0.9)
    allr = ok
    line("confident wrong C (|C - truth| > 3 sigma, no ambiguity, no C range), all trials",
         sum(abs(r["c"] - r["c_true"]) > 3 * r["c_std"] and not r["amb"]
             and r["c_range"] is None for r in allr), len(allr), 0.02, geq=False)
    line("C range reported but missing the truth, the parallel-leak bound too, all trials",
         sum(r["c_range"] is not None and not c_in_range(r) and not held_by_bound(r)
             for r in allr), len(allr), 0.02, geq=False)
    off = [r for r in allr if abs(r["c"] - r["c_true"]) > 3 * r["c_std"]]
    line("C off by > 3 sigma, truth held only by the parallel-leak bound (no competing "
         "model), all trials", sum(held_by_bound(r) and not c_in_range(r)
                                   and not r.get("c_amb", False) for r in off),
         len(allr), 1.0, geq=False)
    ranges = [(r["c_range"][1] - r["c_range"][0]) / r["c"] for r in allr
              if r["c_range"] is not None]
    if ranges:
        lines.append(f"| C range width / C (n = {len(ranges)}) | median "
                     f"{100 * float(np.median(ranges)):.0f} %, p90 "
                     f"{100 * float(np.percentile(ranges, 90)):.0f} % | | (information) | |")

    def simulated(r: dict) -> tuple[str, ...]:
        return () if r["effect"] == "none" else (r["effect"],
                                                 *ALSO_SIMULATED.get(r["effect"], ()))

    # claimed = named by the data (:attr:`DiscrepancyResult.named`); a member of an
    # ambiguity is reported, not claimed, though the best one stands for the set in the
    # final model (the next line, for information)
    line("an effect claimed that was not simulated, all trials", sum(
        any(x not in simulated(r) for x in r["named"]) for r in allr), len(allr), 0.02,
        geq=False)
    lines.append("| (information) an effect in the final model that was not simulated, an "
                 "ambiguity's stand-in included, all trials | " + pct(sum(
                     any(x not in simulated(r) for x in r["effects"]) for r in allr),
                     len(allr)) + " | | | |")
    claimed_ok = [r for r in big if r["claimed"] != "none"]
    line("after the effect: nrms <= 1.02 and white (claimed trials)", sum(
        r["nrms_after"] <= 1.02 and r["white_after"] for r in claimed_ok), len(claimed_ok),
        0.95)
    for rho, target, label in ((0.0, 0.02, "white"), (0.5, 0.05, "AR(1) rho 0.5"),
                               (0.9, 0.05, "AR(1) rho 0.9")):
        sel = [r for r in ok if r["effect"] == "none" and r["rho"] == rho]
        line(f"effect claimed on effect-free data, {label}",
             sum(r["claimed"] != "none" for r in sel), len(sel), target, geq=False)
    sel = [r for r in ok if r["effect"] == "none"]
    line("effect-free: nrms <= 1.02 and white", sum(
        r["nrms_after"] <= 1.02 and r["white_after"] for r in sel), len(sel), 0.95)
    for rho, label in ((0.0, "white"), (0.5, "AR(1) rho 0.5"), (0.9, "AR(1) rho 0.9")):
        sel = [r for r in ok if r["effect"] == "none" and r["rho"] == rho]
        line(f"- effect-free, {label}: nrms <= 1.02 and white", sum(
            r["nrms_after"] <= 1.02 and r["white_after"] for r in sel), len(sel), 0.95)
    if sp_n is not None:
        sp, n = sp_n
        lines.append(f"| speed: one 10 s trace ({n} samples) through all candidates, profiles "
                     f"on | {sp:.1f} s | | <= 30 s | {'yes' if sp <= 30 else 'NO'} |")
    print(f"\n{len(rows)} trials ({len(errors)} crashed), {len(big)} effect trials with "
          f"misfit >= 50 of {len(eff)}; wall time {wall:.0f} s with {workers} workers; "
          f"mean workflow time per trial "
          f"{np.mean([r['elapsed'] for r in ok]):.1f} s\n")
    print("\n".join(lines))
    print("\nper effect (all trials): claimed / in set / misfit >= 50")
    for e in EFFECTS:
        sel = [r for r in eff if r["effect"] == e]
        print(f"- {e}: claimed {sum(r['claimed'] != 'none' for r in sel)}/{len(sel)}, truth in "
              f"set {sum(e in [r['claimed'], *r['amb']] for r in sel)}, detectable "
              f"{sum(r['misfit'] >= 50 for r in sel)}; wrong names: "
              f"{sorted({r['claimed'] for r in sel} - {e, 'none'})}")
    print("\nconfident wrong C by effect (|C - truth| > 3 sigma, no ambiguity, no C range):")
    for e in (*EFFECTS, "none"):
        sel = [r for r in ok if r["effect"] == e]
        bad = [r for r in sel if abs(r["c"] - r["c_true"]) > 3 * r["c_std"] and not r["amb"]
               and r["c_range"] is None]
        print(f"- {e}: {len(bad)}/{len(sel)}" + (" (C errors " + ", ".join(
            f"{100 * (r['c'] / r['c_true'] - 1):+.1f} %" for r in bad) + ")" if bad else ""))
    for r in errors:
        print(f"- crashed: {r['effect']} seed {r['seed']} rho {r['rho']}: {r['error']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
