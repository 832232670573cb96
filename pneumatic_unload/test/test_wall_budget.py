# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The wall temperature in the budget of C (issue #11): a wall not given is assumed at T10
with the uncertainty the record allows, and the budget's wall line says so with C's
sensitivity; checked in closed form and on discharges of the independent Newton-cooling
model (``test/foreign/newton_tank.py``) whose wall is not at the gas start temperature.

Coverage measured on that model (``python test/test_wall_budget.py MODE N``; V, T10, p exact
and model_uncertainty 0, so that the wall is what is tested; tau_h 0.5-20 s, V 2-8 L, C
3-12e-9 m^3/(s Pa), b 0.3-0.5, p10 5-8 bar; shares +- their binomial standard error). A
coverage check means something only when the true wall is drawn from what the budget states
for the assumed one (:func:`true_wall`): 2 K about T10 where T10 is within 3.46 K of a room's
20 C, else anywhere between the room's temperature and T10 (RMS distance gap/sqrt(3)).

* Earlier figures (70 % / 100 %, 90 % / 100 % on 30 and 20 trials) came from trials that
  did not: 'settled' drew T10 at 288-300 K and the wall N(T10, 2 K) where the budget stated
  up to 3.9 K (gap/sqrt(3)): 200 trials, 83 +- 3 % / 98 +- 1 %; the 115 where the budget
  stated 2 K: 79 % / 97 %, the other 85: 88 % / 98 %.
* 'settled' (T10 at 293.15 +- 3.46 K, wall N(T10, 2 K)): before (main at d90b0cb) 78 +- 4 %
  within 1 sigma, 98 +- 1 % within 2, |error| worst 1.92 %, median 0.19 % (100 trials; 200:
  76 +- 3 % and 97 +- 1 %); the worst were the constant-hA law's fit collapsing to the weak
  exchange side (C -20 %) so that the natural law won alone (C -1.8 ... -2.0 %, z -13 ...
  -29, 3 in 200). After (branch h11c: the hot start screens a strong exchange, and is taken
  near T10 when it whitens residuals every law with the wall at T10 leaves structured):
  77 +- 4 % and 98 +- 1 %, worst 1.12 %, median 0.14 %, 100/100 within 2 %; b within 0.03 in
  95/100 (the misses, 0.031-0.037, have walls 1.7-3.6 K off T10). The wall line carries the
  error: |z| was 0.97 (quartiles 0.84-1.07) of |Tw - T10| / 2 K over the 200 trials before.
* 'warm' (T10 at 288-318 K; the wall as stated; 100 trials): before (main's fitting code)
  72 +- 4 % and 95 +- 2 %, worst 1.87 %, median 0.11 %, b within 0.03 in 94/100, two hot
  starts by the natural law at C -1.7 % and -1.1 % with z -28 and -42; after 75 +- 4 % and
  97 +- 2 %, worst 1.87 %, median 0.06 %, 100/100 within 2 %, b within 0.03 in 98/100; 57
  fitted the wall (a hot start): 70 % / 96 %; the other 43: 81 % / 100 %.
* 'room' (the wall at 293.15 +- 2 K whatever T10: the edge of the stated range, a stress
  case, not a draw from it; 100 trials): before 49 +- 5 % and 90 +- 3 %, worst 2.83 %,
  median 0.06 % (with the draws in the earlier order, 65 +- 5 % and 91 +- 3 %; one hot start
  took the natural law at tau_h 0.8 s, C -1.14 %, z -30, the constant-hA fits having
  collapsed to -22 %); after 50 +- 5 % and 91 +- 3 %, worst 1.57 %, median 0.05 %. Below
  the 55 % at 1 sigma, as it must be: the wall sits at the edge of the stated range.
* T10 at the opening (branch h11d): the model's state (p10, T10) is now the gas's at the
  valve opening (before, at the fit window's first sample, 0.1 s into these records: a gas
  far from its wall drifted on the plateau in between), and the trials give the estimator
  T10 at the opening. Warm trial 16 (tau_h 0.63 s, wall 5.1 K above the gas, fitted):
  C +0.140 % at z +6.09 -> +0.017 % at z +0.68.
* b's sigma (branch h11d): before, the curve fit's type A only, which the wall's move of b
  swamped (z up to 14); now b's budget (``budget_b``: C's lines, the wall's from the chosen
  law refitted with the wall moved, to first order). 100 trials per mode, b within 1 / 2
  sigma, before -> after: settled 29 / 51 % -> 78 +- 4 / 98 +- 1 %; warm 44 / 66 % ->
  73 +- 4 / 98 +- 1 %; room 54 / 82 % -> 62 +- 5 / 94 +- 2 %. C in the same runs (T10 at
  the opening): settled 80 +- 4 / 99 +- 1 %, worst 1.15 %, median 0.15 %; warm 76 +- 4 /
  99 +- 1 %, worst 1.91 %; room 51 +- 5 / 92 +- 3 %. b within 0.03: 95, 97, 97 of 100
  (worst 0.037, 0.058, 0.048): every miss has the wall assumed 2-4.5 K from the truth and
  |db/dTw| 0.008-0.023 /K, and lies within 1.8 of b's stated sigma (room trial 90, the
  wall 4.5 K off, 2.1). |db/dTw| over the
  trials with an assumed wall: median 0.0066, 0.0050, 0.0027 /K, 90th percentile 0.016
  /K: a wall unknown by 2 K leaves b uncertain by up to 0.03 (1 sigma) on one trial in
  ten, a physical limit no fit can beat; b within 0.03 at 2 sigma needs the wall known to
  about 1 K there (``wall_temperature`` with ``temperature_uncertainty``).
* branch h11g (main at 38a1474 plus tau_exp's sigma; 100 trials per mode, load ~4): C
  within 1 / 2 sigma settled 79 +- 4 / 98 +- 1 %, warm 75 +- 4 / 98 +- 1 %, room 51 +- 5 /
  92 +- 3 %; worst |error| 20.45 % (settled trial 36, tau_h 1.11 s) and 21.63 % (warm
  trial 24, tau_h 0.71 s): a regression since h11d, from the curve fit's fade stepping
  (commit ccb32c0): every law ended in a false minimum (t_open 0.1 s early, inflation 99).
* main after the fix (a law's fit with structured residuals repeated with plain steps,
  ``fitting.FADE_RETRY_INFLATION``; main a95eedf, 100 trials per mode): C within 1 / 2
  sigma settled 80 +- 4 / 99 +- 1 %, warm 76 +- 4 / 99 +- 1 %, room 51 +- 5 / 92 +- 3 %;
  worst |error| 1.15, 1.91, 1.60 %, median 0.146, 0.053, 0.040 %; within 2 % 100/100 in
  each mode; b within 0.03: 95, 97, 97. The budget's largest line: settled the wall 76 /
  curve fit 24; warm curve fit 50 / wall 43 / model form 7; room curve fit 73 / wall 22 /
  model form 5.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from foreign.newton_tank import discharge

from pneumatic_unload.config.estimator import (
    AMBIENT_TEMPERATURE,
    WALL_ASSUMED_STD,
    wall_uncertainty,
)
from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS, WALL_TERM

#: Inputs exact (V, T10, p), the model's limits 0 (the Newton model is ideal gas, uniform
#: state, a heat law of the family): the wall, not given, keeps its default.
EXACT_BUT_THE_WALL = {k: v for k, v in EXACT_INPUTS.items()
                      if k != "wall_temperature_uncertainty"}


def test_wall_uncertainty_in_closed_form():
    room = EstimatorSettings(volume=1e-3)  # T10 = 293.15 K
    assert wall_uncertainty(room)[0] == WALL_ASSUMED_STD
    given = EstimatorSettings(volume=1e-3, wall_temperature=300.0, temperature_uncertainty=0.7)
    assert wall_uncertainty(given) == (0.7, "given; temperature_uncertainty")
    stated = EstimatorSettings(volume=1e-3, initial_temperature=330.0,
                               wall_temperature_uncertainty=5.0)
    assert wall_uncertainty(stated)[0] == 5.0  # the operator's statement wins
    hot = EstimatorSettings(volume=1e-3, initial_temperature=327.5)
    u, why = wall_uncertainty(hot)
    assert u == pytest.approx((327.5 - AMBIENT_TEMPERATURE) / math.sqrt(3.0), rel=1e-12)
    assert "assumed" in why and "room" in why
    assert wall_uncertainty(room, hot_walls=[283.15])[0] == pytest.approx(
        10.0 / math.sqrt(3.0), rel=1e-12)
    assert wall_uncertainty(room, hot_walls=[294.0, math.nan])[0] == WALL_ASSUMED_STD


def run(t10: float, t_wall: float, tau_heat: float, *, volume: float = 4e-3,
        conductance: float = 5e-9, b: float = 0.4, p10: float = 7e5, seed: int = 1,
        t10_at: str = "opening",
        **given: float | None) -> tuple[float, dict, dict, tuple[float, float, float]]:
    """One Newton-cooling discharge analysed with the wall not given: (C error [-], the
    budget, the curve fit, (b error [-], b's stated standard uncertainty [-], its wall
    line's |db/dTw| [1/K], NaN without one)) (SI
    units). t10 and p10 are the gas's state at the record's first sample in the Newton
    model; a gas away from the wall exchanges heat in the closed tank during the 0.2 s
    plateau. The estimator is given T10 as it defines it, the gas temperature at the
    opening (``t10_at`` 'opening', exact for a constant hA: the gap to the wall decays as
    exp(-t/tau_h)), or, to measure what that changes, the record's first ('record')."""
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    t = np.arange(0.0, 0.2 + 8.0 * tau0, 1e-3)
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=t10,
                  p_atm=101325.0, tau_heat=tau_heat, t_open=0.2, t_wall=t_wall)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    t10_given = t10 if t10_at == "record" else \
        t_wall + (t10 - t_wall) * math.exp(-0.2 / tau_heat)
    s = EstimatorSettings(volume=volume, initial_temperature=t10_given,
                          **{**EXACT_BUT_THE_WALL, **given})
    (r,) = merge_final(analyze(t, y, s))
    walls = [x for x in r.extra.get("budget_b", {}).get("terms", ()) if x["name"] == WALL_TERM
             and x["input_std"] and x["std"] is not None]
    per_k = walls[0]["std"] / walls[0]["input_std"] if walls else math.nan
    return (r.conductance_model / conductance - 1.0, r.extra["budget"], r.extra["curve_fit"],
            (r.critical_ratio - b, r.critical_ratio_std, per_k))


def wall_line(budget: dict) -> dict:
    (line,) = [x for x in budget["terms"] if x["name"] == WALL_TERM]
    return line


@pytest.mark.parametrize("t10,t_wall,tau_heat", [
    (293.15, 290.15, 10.0), (294.0, 297.0, 6.0), (293.15, 291.15, 3.0)])
def test_an_assumed_wall_off_by_1p5_of_its_sigma_is_covered_by_the_wall_line(t10, t_wall,
                                                                             tau_heat):
    """The wall 3 K from the gas start, T10 near a room's temperature (no evidence of a gap:
    the default 2 K), a heat exchange too weak for a hot start to be found: C is 0.5-0.9 %
    off, which the wall line covers (the rest of the budget is 0.02-0.04 %: the truth 15-25
    of it away), and its stated |dC/dTw| predicts the error (measured, with T10 at the
    opening: 0.203, 0.299, 0.299 % per K of the wall's offset; before, with T10 at the
    fit window's first sample, 0.206, 0.277, 0.298 %/K against 0.200, 0.293, 0.288 %/K
    stated); b's budget likewise."""
    err, bud, cf, (b_err, b_std, b_per_k) = run(t10, t_wall, tau_heat)
    w = wall_line(bud)
    assert "assumed = T10" in w["note"] and w["input_std"] == WALL_ASSUMED_STD
    assert not cf["heat_law"].endswith("+wall")
    c = bud["value"]
    rest = math.sqrt(max(bud["combined_std"] ** 2 - w["std"] ** 2, 0.0))
    assert abs(err) * c <= 2.0 * bud["combined_std"]
    assert abs(err) * c > 5.0 * rest  # the wall line is what covers it
    per_k = w["std"] / (w["input_std"] * c)
    assert 0.7 < abs(err) / (per_k * abs(t_wall - t10)) < 1.3
    # b moves with the wall too, by what its budget's wall line states (measured: b off by
    # -0.0135, +0.0283, -0.0233 against |db/dTw| x the wall's offset of 0.0148, 0.0258,
    # 0.0260; stated
    # sigma 0.0099, 0.0173, 0.0261: a wall unknown by 2 K leaves b uncertain by more than
    # the 0.03 / 2 on two of the three)
    assert abs(b_err) <= 2.0 * b_std
    assert 0.7 < abs(b_err) / (b_per_k * abs(t_wall - t10)) < 1.3


def test_a_gas_far_from_room_temperature_is_tried_as_a_hot_start():
    """T10 9 K above a room's temperature with white residuals under the density law (the
    hot start was tried only for structured residuals: the density law took up the wall
    with C +2.8 %, sigma 1.7 %): the hot start is tried on that evidence, chosen, and C
    comes back; the wall line shows the fitted wall with 0 (it is in the fit's type A)."""
    err, bud, cf, _b = run(302.3, 293.8, 4.98)
    assert cf["heat_law"] == "fixed+wall", cf["laws"]
    assert abs(cf["wall_temperature"] - 293.8) < 3.0 * cf["wall_temperature_std"] + 0.2
    assert abs(err) < 0.002
    w = wall_line(bud)
    assert w["std"] == 0.0 and "fitted" in w["note"]


#: Seeds of the coverage modes (fixed: the trials are reproducible).
COVERAGE_SEEDS = {"settled": 7, "warm": 11, "room": 2026}


def true_wall(mode: str, t10: float, rng: np.random.Generator) -> float:
    """The trial's true wall temperature [K] for a gas starting at t10 [K].

    'settled' and 'warm' draw it from what the budget states for an assumed wall (GUM: a
    coverage check is meaningful only when the truth follows the stated distribution):
    within :data:`WALL_ASSUMED_STD` of T10 (normal) where that default holds (T10 within
    sqrt(3) x 2 K of a room's 20 C), else anywhere between a room's temperature and T10
    (uniform: the wall left at the room's or warmed with the gas; RMS distance from T10
    the gap over sqrt(3), the stated uncertainty). 'room' is the edge of that range, not
    a draw from it: the wall at a room's 293.15 +- 2 K whatever T10 (a stress case).
    """
    gap = abs(t10 - AMBIENT_TEMPERATURE)
    if mode == "room":
        return AMBIENT_TEMPERATURE + float(rng.normal(0.0, WALL_ASSUMED_STD))
    if gap <= math.sqrt(3.0) * WALL_ASSUMED_STD:
        return t10 + float(rng.normal(0.0, WALL_ASSUMED_STD))
    return float(rng.uniform(min(t10, AMBIENT_TEMPERATURE), max(t10, AMBIENT_TEMPERATURE)))


def coverage(mode: str, n: int, first: int = 0, t10_at: str = "opening") -> None:
    """Print seeded trials ``first`` .. n-1 and the shares within 1 and 2 sigma (with
    their binomial standard errors), the worst and median |error| of C and the worst of b.
    Modes (the true wall: :func:`true_wall`): 'settled' (T10 where the default 2 K
    holds, 293.15 +- 3.46 K), 'warm' (T10 at 288-318 K, a gas warmed by the charge) and
    'room' (T10 at 288-318 K, the wall at a room's temperature)."""
    rng = np.random.default_rng(COVERAGE_SEEDS[mode])
    zs, errs, b_errs, b_zs, b_slopes, b_sigmas = [], [], [], [], [], []
    tops: dict[str, int] = {}
    for k in range(n):
        tau_heat = float(np.exp(rng.uniform(np.log(0.5), np.log(20.0))))
        volume, conductance = float(rng.uniform(2e-3, 8e-3)), float(rng.uniform(3e-9, 1.2e-8))
        b, p10 = float(rng.uniform(0.3, 0.5)), float(rng.uniform(5e5, 8e5))
        half = math.sqrt(3.0) * WALL_ASSUMED_STD
        t10 = float(rng.uniform(AMBIENT_TEMPERATURE - half, AMBIENT_TEMPERATURE + half)
                    if mode == "settled" else rng.uniform(288.0, 318.0))
        t_wall = true_wall(mode, t10, rng)
        if k < first:
            continue
        try:
            err, bud, cf, (b_err, b_std, b_per_k) = run(
                t10, t_wall, tau_heat, volume=volume, conductance=conductance, b=b, p10=p10,
                seed=k, t10_at=t10_at)
        except KeyError as exc:
            print(k, "no curve fit or budget:", exc)
            continue
        z = err * bud["value"] / bud["combined_std"]
        zs.append(z)
        errs.append(abs(100.0 * err))
        b_errs.append(abs(b_err))  # the subsonic tail is recorded
        b_zs.append(b_err / b_std if b_std > 0 else math.inf)
        b_slopes.append(b_per_k)
        b_sigmas.append(b_std)
        w = wall_line(bud)
        top = largest_term(bud)
        tops[top] = tops.get(top, 0) + 1
        print(f"{k:2d} tau_h {tau_heat:5.2f} T10 {t10:6.1f} Tw {t_wall:6.1f} err {100 * err:+.3f} %"
              f" z {z:+.2f} b {b_err:+.3f} +- {b_std:.3f} (z {b_zs[-1]:+.2f},"
              f" |db/dTw| {b_per_k:.4f} /K)"
              f" {cf['heat_law']:>17s} wall u {w['input_std']:.2g} K,"
              f" {100 * w['std'] / bud['value']:.3f} %; model form"
              f" {100 * bud['model_form_std'] / bud['value']:.3f} %, type A"
              f" {100 * bud['type_a_std'] / bud['value']:.3f} %; largest: {top}", flush=True)
    a = np.abs(np.array(zs))
    shares, b_shares = [], []
    ab = np.abs(np.array(b_zs))
    for k in (1, 2):
        q = float(np.mean(a <= k))
        shares.append(f"within {k} sigma {q:.2f} +- {math.sqrt(q * (1 - q) / a.size):.2f}")
        q = float(np.mean(ab <= k))
        b_shares.append(f"{q:.2f} +- {math.sqrt(q * (1 - q) / ab.size):.2f}")
    print(f"{mode}: {a.size} trials, {', '.join(shares)}; |error| worst {max(errs):.3f} %, "
          f"median {float(np.median(errs)):.3f} %, within 2 %: "
          f"{sum(e < 2 for e in errs)}/{len(errs)}; |b error| worst {np.nanmax(b_errs):.3f}, "
          f"within 0.03: {sum(e <= 0.03 for e in b_errs)}/{len(b_errs)}; b within 1 / 2 "
          f"sigma {b_shares[0]} / {b_shares[1]}; |db/dTw| [1/K] median "
          f"{np.nanmedian(b_slopes):.4f}, 90th percentile "
          f"{np.nanpercentile(b_slopes, 90):.4f} over {int(np.sum(np.isfinite(b_slopes)))}"
          f" trials with an assumed wall; b's stated sigma median "
          f"{float(np.nanmedian(b_sigmas)):.4f}; the budget's largest term: "
          + ", ".join(f"{name} {m}" for name, m in sorted(tops.items(), key=lambda x: -x[1])))


def largest_term(budget: dict) -> str:
    """The name of a budget's largest line (a Budget's ``to_dict``) [-]."""
    terms = [x for x in budget["terms"] if x["std"] is not None and math.isfinite(x["std"])]
    return max(terms, key=lambda x: x["std"])["name"] if terms else "none"


if __name__ == "__main__":
    coverage(sys.argv[1], int(sys.argv[2]), *map(int, sys.argv[3:4]), *sys.argv[4:5])
