# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Accuracy of the estimation core on seeded synthetic discharges (issue 3), a fixed-seed
subset of the sweeps in ``bench/bench_accuracy.py`` (1 kHz, 0.1 % of a 1 MPa full scale
white noise, V 1-20 L, d 1-3 mm with C = 0.128 d^2 dm^3/(s bar), p10 4-8 bar abs,
b 0.2-0.5)."""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import analyze, merge_final
from pneumatic_unload.model import default_duration, discharge, simulate
from pneumatic_unload.physics import P_STAR_FRACTION, orifice_conductance
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS


def exact(settings):
    """The simulation's own tank and gas: inputs exactly known (no type B terms)."""
    return dataclasses.replace(settings, **EXACT_INPUTS)


NOISE = 1000.0  # 0.1 % FS of a 1 MPa transducer [Pa]


def _rigs(n, seed, heat):
    rng = np.random.default_rng(seed)
    for k in range(n):
        yield RigConfig(
            volume=rng.uniform(1e-3, 20e-3),
            conductance=orifice_conductance(rng.uniform(1e-3, 3e-3)),
            initial_pressure=rng.uniform(4e5, 8e5), critical_ratio=rng.uniform(0.2, 0.5),
            noise_std=NOISE, seed=seed * 1000 + k, effects=("heat_transfer",) if heat else ())


def test_model_c_and_b_one_sigma_coverage_with_heat_transfer():
    """12 natural-convection trials: model-based C within 2 % and b within 0.03 of the
    truth, and the stated 1-sigma covering the truth about 68 % of the time (binomial:
    5..11 of 12), never off by more than 3.5 sigma. The 100-trial figure is in the bench."""
    zc, zb = [], []
    for cfg in _rigs(12, seed=7, heat=True):
        sim = simulate(cfg)
        r = merge_final(analyze(sim.t, sim.measured, exact(settings_for(cfg))))[0]
        assert r.final
        # the final status follows the fitted b: eq 39 assumes choked flow down to p*
        b = cfg.critical_ratio
        if r.p_star >= cfg.atmosphere / (b - 0.03):
            assert r.status == "ok"
        elif r.p_star < cfg.atmosphere / (b + 0.03):
            assert r.status == "ok_subsonic"
        assert abs(r.conductance_model / cfg.conductance - 1.0) < 0.02
        assert abs(r.critical_ratio - cfg.critical_ratio) < 0.03
        zc.append((r.conductance_model - cfg.conductance) / r.conductance_model_std)
        zb.append((r.critical_ratio - cfg.critical_ratio) / r.critical_ratio_std)
    zc, zb = np.abs(zc), np.abs(zb)
    assert 5 <= int(np.sum(zc < 1.0)) <= 11, zc
    assert 5 <= int(np.sum(zb < 1.0)) <= 11, zb
    assert zc.max() < 3.5 and zb.max() < 3.5


def _start_crlb(cfg, t, noise=NOISE):
    """Cramer-Rao 1-sigma of the start time [s]: (t0, p10, log C, b) unknown, white noise
    of sigma ``noise`` [Pa]."""
    def signal(x):
        c = cfg.replace(initial_pressure=x[1], conductance=float(np.exp(x[2])),
                        critical_ratio=x[3])
        return discharge(c, t, x[0], rtol=1e-10)[0]

    x0 = np.array([cfg.pre_time, cfg.initial_pressure, math.log(cfg.conductance),
                   cfg.critical_ratio])
    steps = np.array([2e-5, 10.0, 1e-4, 1e-4])
    cols = []
    for k in range(4):
        e = np.zeros(4)
        e[k] = steps[k]
        cols.append((signal(x0 + e) - signal(x0 - e)) / (2 * steps[k]))
    j = np.array(cols).T
    return float(np.sqrt(np.linalg.inv(j.T @ j)[0, 0])) * noise


def _true_tau_exp(cfg):
    """tau_exp of the noise-free discharge [s]: from the opening to the p* crossing."""
    p_star = cfg.atmosphere + P_STAR_FRACTION * (cfg.initial_pressure - cfg.atmosphere)
    t = np.linspace(0.0, default_duration(cfg), 200_001)
    p = discharge(cfg, t, 0.0, rtol=1e-11)[0]
    k = int(np.flatnonzero(p < p_star)[0])
    return float(t[k - 1] + (p[k - 1] - p_star) / (p[k - 1] - p[k]) * (t[k] - t[k - 1]))


@pytest.mark.parametrize(("volume", "diameter", "p10", "rate", "noise"), [
    (1e-3, 3e-3, 7e5, 1000.0, 1000.0), (20e-3, 1e-3, 6e5, 1000.0, 1000.0),
    (5e-3, 2e-3, 8e5, 100.0, 300.0), (2e-3, 1.5e-3, 4e5, 2000.0, 3000.0),
    (10e-3, 2.5e-3, 5e5, 250.0, 1000.0), (15e-3, 1.2e-3, 7e5, 500.0, 200.0)])
def test_start_within_twice_its_cramer_rao_bound_and_tau_exp_within_3_sigma(
        volume, diameter, p10, rate, noise):
    """The issue's core target over its ranges (V 1-20 L, d 1-3 mm, p10 4-8 bar) and
    several sample rates (100 Hz-2 kHz) and noise levels (200-3000 Pa): the start of the
    final result (the curve fit's, t_start_model) within max(1 sample, 2 x its Cramer-Rao
    bound), and the measured tau_exp within 3 of its stated sigma of the noise-free
    discharge's. The curve fit's start is efficient: over 16 and 30 seeds of two of these
    rigs its RMS error was 1.05 and 1.07 x the bound (so 2 x the bound is a ~95 % limit);
    the crossing detector's start (which tau_exp uses) 1.3-1.7 x."""
    cfg = RigConfig(volume=volume, conductance=orifice_conductance(diameter), rate=rate,
                    noise_std=noise, seed=43, initial_pressure=p10, critical_ratio=0.4)
    cfg = cfg.replace(duration=0.35 * default_duration(cfg))
    sim = simulate(cfg)
    st = dataclasses.replace(exact(settings_for(cfg)), heat_model="adiabatic")
    (r,) = merge_final(analyze(sim.t, sim.measured, st))
    bound = _start_crlb(cfg, sim.t, noise)
    err = abs(r.t_start_model - sim.t_open)
    assert err <= max(1.0 / rate, 2.0 * bound), (err * rate, bound * rate)
    z_tau = (r.tau_exp - _true_tau_exp(cfg)) / r.tau_exp_std
    print(f"start {err * rate:.2f} samples, bound {bound * rate:.2f}, z_tau {z_tau:+.2f}")
    assert abs(z_tau) <= 3.0, z_tau


@pytest.mark.parametrize(("volume", "diameter"), [(1e-3, 3e-3), (5e-3, 2e-3), (20e-3, 1e-3)])
def test_start_time_against_cramer_rao_bound(volume, diameter):
    """The start is within one sample where the information allows it (fast discharge),
    and within 4 Cramer-Rao sigmas everywhere: for the slowest rig with a 0.2 s plateau the
    bound itself is several samples (p10 is known only to sigma/sqrt(200)), so "within one
    sample" is not reachable by any estimator there."""
    cfg = RigConfig(volume=volume, conductance=orifice_conductance(diameter), noise_std=NOISE,
                    seed=41, initial_pressure=6e5)
    cfg = cfg.replace(duration=0.35 * default_duration(cfg))
    sim = simulate(cfg)
    st = dataclasses.replace(exact(settings_for(cfg)), heat_model="adiabatic", curve_fit=False)
    r = analyze(sim.t, sim.measured, st)[0]
    bound = _start_crlb(cfg, sim.t)
    err = abs(r.t_start - sim.t_open)
    assert err <= max(1.0 / cfg.rate, 4.0 * bound), (err * cfg.rate, bound * cfg.rate)
    if bound < 0.25 / cfg.rate:
        assert err < 1.0 / cfg.rate
    if volume == 20e-3:
        assert bound > 1.0 / cfg.rate  # information-limited: demonstrated, not assumed


def test_curve_fit_reaches_the_least_squares_minimum():
    """Regression for the coverage shortfall of issue 3: scipy's bounded trust-region
    search alone stopped ~0.15 chi^2 above the minimum on this slow rig and noise draw
    (C off by ~0.4 sigma from the least-squares solution). After the fit, a Gauss-Newton
    step with a fresh Jacobian must predict essentially no further chi^2 drop, and the
    estimate must agree with the ideal linearised estimator (true Jacobian, same bins)."""
    from pneumatic_unload.curvefit.fitting import curve_fit_bins, fit_curve
    from pneumatic_unload.model.inversion import rig_from_settings

    cfg = RigConfig(volume=12e-3, conductance=orifice_conductance(1.5e-3),
                    initial_pressure=7.5e5, critical_ratio=0.31, noise_std=NOISE,
                    effects=("heat_transfer",))
    st = exact(settings_for(cfg))
    t = np.arange(math.floor(0.6 * (cfg.pre_time + default_duration(cfg)) * cfg.rate)) \
        / cfg.rate
    x_true = np.array([math.log(cfg.conductance), cfg.critical_ratio, cfg.pre_time,
                       cfg.initial_pressure, 0.0])

    def model(x):
        c = rig_from_settings(st, conductance=math.exp(x[0]), p10=x[3], p_atm=cfg.atmosphere,
                              critical_ratio=x[1], heat_scale=math.exp(x[4]))
        return discharge(c, t, x[2], rtol=1e-9)[0]

    y = model(x_true) + np.random.default_rng(104).normal(0.0, NOISE, t.size)
    fit = fit_curve(t, y, st, t_start=cfg.pre_time + 0.003, p10=cfg.initial_pressure + 200,
                    p_atm=cfg.atmosphere, conductance=1.005 * cfg.conductance,
                    profile_heat=False)
    x = np.array([math.log(fit.conductance), fit.critical_ratio, fit.t_start, fit.p10,
                  math.log(fit.heat_scale)])
    edges = curve_fit_bins(t, cfg.pre_time + 0.003)
    counts = np.diff(edges)

    def binned(v):
        return np.add.reduceat(v, edges[:-1], axis=0) / (
            counts if v.ndim == 1 else counts[:, None])

    def jac(x0):
        f0 = model(x0)
        cols = []
        for k in range(5):
            e = np.zeros(5)
            e[k] = 1e-4 * max(1.0, abs(x0[k]))
            cols.append((model(x0 + e) - f0) / e[k])
        return binned(np.array(cols).T)

    r = binned(model(x) - y)
    j = jac(x)
    step = np.linalg.lstsq(j, -r, rcond=None)[0]
    drop = float(counts @ (r * r) - counts @ ((r + j @ step) ** 2)) / NOISE**2
    assert drop < 0.01, drop  # chi^2 units; the trust-region search alone left ~0.15
    jt = jac(x_true)
    sw = np.sqrt(counts)[:, None]  # bins of unequal size: weighted least squares
    dx = np.linalg.lstsq(jt * sw, binned(y - model(x_true)) * sw[:, 0], rcond=None)[0]
    sd = np.sqrt(np.diag(np.linalg.inv((jt * counts[:, None]).T @ jt))) * NOISE
    assert abs((x[0] - x_true[0]) - dx[0]) < 0.1 * sd[0], ((x - x_true - dx) / sd)
    assert abs(fit.conductance_std / fit.conductance / sd[0] - 1.0) < 0.05


def test_budget_covers_the_truth_when_the_inputs_are_off_by_their_stated_uncertainty():
    """The GUM budget (issue #11): 20 trials whose true V, T10 and transducer offset differ
    from what the operator states by draws of their stated standard uncertainties (0.5 %
    of V, 1 K, 0.1 % of p10); the combined sigma covers the truth at 1 sigma in 9..19 of
    20 (68 %, binomial) and at 2 sigma in 17..20 (95 %); the type A part alone would not
    (the inputs dominate), and the budget names an input as its largest term."""
    rng = np.random.default_rng(2026)
    z, z_a, largest = [], [], []
    for k in range(20):
        v_true = rng.uniform(2e-3, 8e-3)
        p10 = rng.uniform(5e5, 7e5)
        cfg = RigConfig(volume=v_true, conductance=orifice_conductance(rng.uniform(1.5e-3, 2.5e-3)),
                        initial_pressure=p10, initial_temperature=293.15 + rng.normal(0, 1.0),
                        wall_temperature=293.15, noise_std=NOISE, seed=500 + k)
        sim = simulate(cfg)
        offset = rng.normal(0.0, 1e-3 * p10)  # the transducer's zero error
        stated = dataclasses.replace(settings_for(cfg), volume=v_true * (1 + rng.normal(0, 0.005)),
                                     initial_temperature=293.15, heat_model="adiabatic")
        r = merge_final(analyze(sim.t, sim.measured + offset, stated))[0]
        err = r.conductance_model - cfg.conductance
        z.append(err / r.conductance_model_std)
        z_a.append(err / r.extra["budget"]["type_a_std"])
        largest.append(r.extra["budget"]["largest"])
    z, z_a = np.abs(z), np.abs(z_a)
    assert 9 <= int(np.sum(z < 1.0)) <= 19, z
    assert int(np.sum(z < 2.0)) >= 17, z
    assert int(np.sum(z_a < 2.0)) < 10, z_a  # noise alone: the truth far outside
    assert set(largest) <= {"volume V", "initial temperature T10",
                            "pressure transducer (offset)"}, largest


@pytest.mark.parametrize("seed", [1, 2])
def test_a_gas_hot_after_charging_is_fitted_as_a_hot_start(seed):
    """T10 = 45 C in a tank whose wall is at 20 C, the wall not given (assumed = T10): the
    laws with the wall at T10 are 6.6-7.5 % off; the hot-start variant fits the wall
    (within 2 K) and C (within 0.5 %, inside 3 sigma), and the information criterion
    chooses it. A wall fitted close to T10 is not claimed (see the HydDown tests)."""
    cfg = RigConfig(volume=5e-3, conductance=5e-9, effects=("heat_transfer",),
                    initial_temperature=318.15, wall_temperature=293.15, noise_std=500.0,
                    heat_transfer_scale=2.0, seed=seed)
    sim = simulate(cfg)
    st = exact(settings_for(cfg))
    st = dataclasses.replace(st, wall_temperature=None)  # the wall not given
    r = merge_final(analyze(sim.t, sim.measured, st))[0]
    cf = r.extra["curve_fit"]
    assert cf["heat_law"].endswith("+wall"), cf["laws"]
    assert abs(cf["wall_temperature"] - 293.15) < 2.0
    assert min(abs(v["conductance"] / 5e-9 - 1) for k, v in cf["laws"].items()
               if "+wall" not in k) > 0.05
    assert abs(r.conductance_model / 5e-9 - 1) < 0.005
    assert abs(r.conductance_model - 5e-9) < 3 * r.conductance_model_std
