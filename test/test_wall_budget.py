"""The wall temperature in the budget of C (issue #11): a wall not given is assumed at T10
with the uncertainty the record allows, and the budget's wall line says so with C's
sensitivity; checked in closed form and on discharges of the independent Newton-cooling
model (``test/foreign/newton_tank.py``) whose wall is not at the gas start temperature.

Coverage measured on that model (``python test/test_wall_budget.py room 30`` and
``settled 20``; V, T10, p exact and model_uncertainty 0, so that the wall is what is
tested; tau_h 0.5-20 s; load ~12 on 2 cores, which does not change the numbers):

* 'room' (the wall at 293.15 +- 2 K, the gas starting at 288-318 K; 29 trials, one gave no
  unload): before (main at 4f33df6: the wall line was temperature_uncertainty, 0 here, and
  the hot start was tried only for structured residuals) 48 % within 1 sigma, 62 % within
  2, worst |error| 2.76 % (the density law taking up a wall 9 K away); after 76 % and 93 %,
  worst 1.25 %, 29/29 within 2 %.
* 'settled' (the wall N(0, 2 K) from a gas at 288-300 K; 20 trials): before 20 % and
  50 %; after 70 % and 90 % (one hot-start fit, a wall 4.3 K above T10 at tau_h 0.52 s,
  is 0.19 % off at z 8.3, the same on main: left for the hot start's own issue).
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from foreign.newton_tank import discharge

from pneumatic_unload.budget import EXACT_INPUTS, WALL_TERM
from pneumatic_unload.config.estimator import (
    AMBIENT_TEMPERATURE,
    WALL_ASSUMED_STD,
    wall_uncertainty,
)
from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final

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
        **given: float | None) -> tuple[float, dict, dict]:
    """One Newton-cooling discharge analysed with the wall not given: (C error [-], the
    budget, the curve fit) (SI units). t10 and p10 are the gas's state at the record's
    first sample, where the estimator's model starts too (a gas away from the wall then
    exchanges heat in the closed tank during the 0.2 s plateau, in both models)."""
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    t = np.arange(0.0, 0.2 + 8.0 * tau0, 1e-3)
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=t10,
                  p_atm=101325.0, tau_heat=tau_heat, t_open=0.2, t_wall=t_wall)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    s = EstimatorSettings(volume=volume, initial_temperature=t10,
                          **{**EXACT_BUT_THE_WALL, **given})
    (r,) = merge_final(analyze(t, y, s))
    return r.conductance_model / conductance - 1.0, r.extra["budget"], r.extra["curve_fit"]


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
    of it away), and its stated |dC/dTw| predicts the error (measured: 0.206, 0.277,
    0.298 %/K against 0.200, 0.293, 0.288 %/K)."""
    err, bud, cf = run(t10, t_wall, tau_heat)
    w = wall_line(bud)
    assert "assumed = T10" in w["note"] and w["input_std"] == WALL_ASSUMED_STD
    assert not cf["heat_law"].endswith("+wall")
    c = bud["value"]
    rest = math.sqrt(max(bud["combined_std"] ** 2 - w["std"] ** 2, 0.0))
    assert abs(err) * c <= 2.0 * bud["combined_std"]
    assert abs(err) * c > 5.0 * rest  # the wall line is what covers it
    per_k = w["std"] / (w["input_std"] * c)
    assert 0.7 < abs(err) / (per_k * abs(t_wall - t10)) < 1.3


def test_a_gas_far_from_room_temperature_is_tried_as_a_hot_start():
    """T10 9 K above a room's temperature with white residuals under the density law (the
    hot start was tried only for structured residuals: the density law took up the wall
    with C +2.8 %, sigma 1.7 %): the hot start is tried on that evidence, chosen, and C
    comes back; the wall line shows the fitted wall with 0 (it is in the fit's type A)."""
    err, bud, cf = run(302.3, 293.8, 4.98)
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


def coverage(mode: str, n: int, first: int = 0) -> None:
    """Print seeded trials ``first`` .. n-1 and the shares within 1 and 2 sigma (with
    their binomial standard errors), the worst and median |error| of C and the worst of b.
    Modes (the true wall: :func:`true_wall`): 'settled' (T10 where the default 2 K
    holds, 293.15 +- 3.46 K), 'warm' (T10 at 288-318 K, a gas warmed by the charge) and
    'room' (T10 at 288-318 K, the wall at a room's temperature)."""
    rng = np.random.default_rng(COVERAGE_SEEDS[mode])
    zs, errs, b_errs = [], [], []
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
            err, bud, cf = run(t10, t_wall, tau_heat, volume=volume,
                               conductance=conductance, b=b, p10=p10, seed=k)
        except KeyError as exc:
            print(k, "no curve fit or budget:", exc)
            continue
        z = err * bud["value"] / bud["combined_std"]
        zs.append(z)
        errs.append(abs(100.0 * err))
        b_errs.append(abs(cf["critical_ratio"] - b))  # the subsonic tail is recorded
        w = wall_line(bud)
        print(f"{k:2d} tau_h {tau_heat:5.2f} T10 {t10:6.1f} Tw {t_wall:6.1f} err {100 * err:+.3f} %"
              f" z {z:+.2f} b {cf['critical_ratio'] - b:+.3f}"
              f" {cf['heat_law']:>17s} wall u {w['input_std']:.2g} K,"
              f" {100 * w['std'] / bud['value']:.3f} %; model form"
              f" {100 * bud['model_form_std'] / bud['value']:.3f} %, type A"
              f" {100 * bud['type_a_std'] / bud['value']:.3f} %", flush=True)
    a = np.abs(np.array(zs))
    shares = []
    for k in (1, 2):
        q = float(np.mean(a <= k))
        shares.append(f"within {k} sigma {q:.2f} +- {math.sqrt(q * (1 - q) / a.size):.2f}")
    print(f"{mode}: {a.size} trials, {', '.join(shares)}; |error| worst {max(errs):.3f} %, "
          f"median {float(np.median(errs)):.3f} %, within 2 %: "
          f"{sum(e < 2 for e in errs)}/{len(errs)}; |b error| worst {np.nanmax(b_errs):.3f}, "
          f"within 0.03: {sum(e <= 0.03 for e in b_errs)}/{len(b_errs)}")


if __name__ == "__main__":
    coverage(sys.argv[1], int(sys.argv[2]), *map(int, sys.argv[3:4]))
