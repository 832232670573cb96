# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Records that begin at the valve opening (issue #11): sparse, uneven, no plateau."""

import json
import subprocess
import sys

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimationError,
    EstimatorSettings,
    StreamingEstimator,
    analyze,
    merge_final,
)
from pneumatic_unload.estimation.sparse import interpolated_crossing
from pneumatic_unload.model import simulate

P_ATM = 101325.0


def _sparse(volume, conductance, step, n, seed, jitter=0.0):
    """n points from the opening on, ``step`` s apart (+- jitter), from a simulated
    discharge with natural-convection heat transfer (1.5 kPa noise)."""
    cfg = RigConfig(volume=volume, conductance=conductance, effects=("heat_transfer",),
                    pre_time=0.0, rate=100.0, duration=step * n + 1.0, noise_std=1500.0,
                    seed=seed)
    sim = simulate(cfg)
    rng = np.random.default_rng(seed)
    k = np.round(np.arange(n) * step * 100 + np.r_[0, rng.uniform(-jitter, jitter, n - 1)]
                 * 100).astype(int)
    return sim.t[k], sim.measured[k], cfg


def test_log_linear_interpolation_is_exact_for_an_exponential_approach():
    t = np.array([0.0, 1.0, 2.5, 4.0, 7.0])
    p = P_ATM + 6e5 * np.exp(-t / 2.0)
    level = P_ATM + 0.368 * 6e5
    tc, err, k = interpolated_crossing(t, p, level, P_ATM)
    assert tc == pytest.approx(-2.0 * np.log(0.368), abs=1e-12) and k == 2
    assert err > 0.01  # linear interpolation in p is measurably off: the stated error


def test_fifteen_digitised_points_from_the_opening_through_the_cli(tmp_path):
    """Before: 'too few samples (15); need at least 16'. After: a C within 2 % of the truth,
    inside 3 of its sigma, with the interpolation named."""
    t, p, cfg = _sparse(0.05, 1e-8, 4.0, 15, seed=4)
    csv = tmp_path / "digitised.csv"
    csv.write_text("time [s],pressure [kPa]\n"
                   + "".join(f"{a:.2f},{b / 1e3:.2f}\n" for a, b in zip(t, p, strict=True)))
    base = [sys.executable, "-m", "pneumatic_unload.app.cli", "analyze", str(csv),
            "--volume", "50L"]
    before = subprocess.run(base, capture_output=True, text=True, timeout=120)
    assert before.returncode != 0 and "--start-time" in before.stderr
    out = subprocess.run([*base, "--start-time", "0", "--atmosphere", "101325", "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    (u,) = json.loads(out.stdout)["unloads"]
    assert u["final"] and u["status"] == "ok"
    c, sd = u["conductance_model"], u["conductance_model_std"]
    assert abs(c / cfg.conductance - 1) < 0.02
    assert abs(c - cfg.conductance) < 3 * sd
    assert "interpolated" in u["status_text"]


def test_uneven_sparse_records_recover_c_with_an_honest_sigma():
    """10 records of 12-20 points over 2-3 unloading times, jittered stamps: every C within
    3 of its sigma and the median error below 1 %."""
    errs, zs = [], []
    rng = np.random.default_rng(11)
    for seed in range(10):
        volume, n = rng.uniform(0.02, 0.1), int(rng.integers(12, 21))
        step = rng.uniform(2.0, 3.0) * 680.0 * volume / n  # tau_exp ~ 680 s/m^3 x V here
        t, p, cfg = _sparse(volume, 1e-8, step, n, seed=100 + seed, jitter=0.3 * step)
        st = EstimatorSettings(volume=cfg.volume, start_time=float(t[0]), atmosphere=P_ATM)
        (r,) = merge_final(analyze(t, p, st))
        errs.append(abs(r.conductance_model / cfg.conductance - 1))
        zs.append(abs(r.conductance_model - cfg.conductance) / r.conductance_model_std)
    assert max(zs) < 3.0, zs
    assert np.median(errs) < 0.01, errs


def test_no_sample_at_the_opening_needs_the_initial_pressure():
    t, p, cfg = _sparse(0.05, 1e-8, 2.0, 20, seed=5)
    st = EstimatorSettings(volume=cfg.volume, start_time=-0.5, atmosphere=P_ATM)
    with pytest.raises(EstimationError, match="initial pressure"):
        analyze(t, p, st)
    st = EstimatorSettings(volume=cfg.volume, start_time=-0.5, atmosphere=P_ATM,
                           initial_pressure=cfg.initial_pressure, initial_pressure_std=2000.0)
    (r,) = merge_final(analyze(t + 0.0, p, st))
    assert r.final
    names = [x["name"] for x in r.extra["budget"]["terms"]]
    assert "initial pressure p10 (given)" in names


def test_what_is_missing_is_named():
    t, p, _cfg = _sparse(0.05, 1e-8, 4.0, 15, seed=6)
    with pytest.raises(EstimationError, match="atmosphere"):
        analyze(t, p, EstimatorSettings(volume=0.05, start_time=0.0, atmosphere=None))
    with pytest.raises(EstimationError, match="need at least 10"):
        analyze(t[:8], p[:8], EstimatorSettings(volume=0.05, start_time=0.0))
    with pytest.raises(EstimationError, match="never falls to p"):
        analyze(t[:10], p[:10] * 0 + 6e5, EstimatorSettings(volume=0.05, start_time=0.0))
    with pytest.raises(EstimationError, match="streaming estimator"):
        StreamingEstimator(EstimatorSettings(volume=0.05, start_time=0.0))


def test_a_held_heat_law_on_few_points_is_a_line_of_the_budget():
    """15 points of the independent Newton-cooling model (82 L, tau_h 27 s: an exchange
    the published correlation does not give): the fit holds the correlation (too few
    points to fit it), C is 3.5 % low, and the final sigma said so nowhere (z -1.9; 60
    such records, bench_sparse_budget: 20 % within 1 sigma, 77 % within 2). The crossing's
    line for a heat exchange not seen stays in the final budget: 83 % and 97 % there."""
    from foreign.newton_tank import discharge

    from pneumatic_unload.estimation.sparse import HEAT_HELD
    from pneumatic_unload.uncertainty.budget import EXACT_INPUTS

    volume, conductance, n = 0.0819, 4.46e-9, 15
    tau0 = volume / (1.4e5 * conductance)
    rng = np.random.default_rng(1)
    t = np.arange(n) * 2.5 * tau0 / n
    t[1:] += rng.uniform(-0.3, 0.3, n - 1) * 2.5 * tau0 / n
    p = discharge(t, volume=volume, conductance=conductance, b=0.4, p10=6.5e5, t10=293.15,
                  p_atm=P_ATM, tau_heat=26.6, t_open=0.0)
    y = p + rng.normal(0.0, 1500.0, n)
    given = {k: v for k, v in EXACT_INPUTS.items() if k != "wall_temperature_uncertainty"}
    st = EstimatorSettings(volume=volume, start_time=0.0, atmosphere=P_ATM, **given)
    (r,) = merge_final(analyze(t, y, st))
    (held,) = [x for x in r.extra["budget"]["terms"] if x["name"] == HEAT_HELD]
    err = r.conductance_model - conductance
    assert abs(err) > 0.02 * conductance  # the held correlation's bias
    assert held["std"] > 0.5 * abs(err)
    assert abs(err) <= 2.0 * r.conductance_model_std
