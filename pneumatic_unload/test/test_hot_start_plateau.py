# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A hot start: gas charged seconds before the opening cools toward the wall, and the
closed tank's plateau decays. Made by the independent model of ``test/foreign/newton_tank.py``
(T10 320 K, wall 293 K, thermal time constant 8 s, 10 L, 5e-9 m^3/(s Pa), a 2 s plateau,
1 kHz, 0.1 % FS noise), no temperature channel.

Before (main 4bd69e5 and this session's start): the trigger fired on the drift 0.16 s into
the record, the start's hinge (a flat plateau) found no fall, and 2 of 3 seeds gave
``bad_data: the start fit found no falling slope``, no C. Now the start is refitted with
the plateau's slope where the flat hinge finds no fall (measured: starts 2.004 and 2.009 s
for 2.0; the third seed's start 1.19 s, on the drift, is taken by the flat hinge), and the
final fit's hot start gives C -0.94 % (z -1.5) on each."""

from __future__ import annotations

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge

from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final

C, V = 5e-9, 10e-3


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_decaying_plateau_gives_c(seed):
    t = np.arange(0.0, 2.0 + 8.0 * V / (1.4e5 * C), 1e-3)
    p = discharge(t, volume=V, p10=7e5, t10=320.0, p_atm=101325.0, tau_heat=8.0,
                  t_open=2.0, flow_law=IsoLaw(C, 0.4, 0.5), t_wall=293.15)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    res = analyze(t, y, EstimatorSettings(volume=V, initial_temperature=320.0))
    assert all(r.status != "bad_data" for r in res), [r.status_text for r in res]
    (r,) = merge_final(res)
    assert r.final
    assert abs(r.conductance_model / C - 1.0) < 0.02
    assert abs(r.conductance_model - C) < 3.0 * r.conductance_model_std


def _long_plateau(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Gas charged 20 K warm (T10 313.15 K, wall 293.15 K, thermal time constant 10 s)
    cooling for 10 s on the plateau before the opening, 100 Hz, 5 L, 3e-9 m^3/(s Pa),
    b 0.3, 6 bar abs: the plateau falls 4 % before the opening, as an unload would."""
    v, c = 5e-3, 3e-9
    t = np.arange(0.0, 10.0 + 6.0 * v / (1.4e5 * c), 1e-2)
    p = discharge(t, volume=v, p10=6e5, t10=313.15, p_atm=101325.0, tau_heat=10.0,
                  t_open=10.0, flow_law=IsoLaw(c, 0.3, 0.5), t_wall=293.15)
    return t, p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)


@pytest.mark.parametrize("seed", [4, 5])
def test_a_long_decaying_plateau_finds_the_opening_and_reads_t10(seed):
    """Before: the flat hinge put the start at the record's first sample (the whole 10 s
    of drift taken for the fall), the final fit started there: C -17 %, "model
    inadequate". Now the opening is found on the shortest window that shows a plateau
    before a fall steeper than the drift (within 20 ms of 10 s), and with T10 not given
    the hot start is fitted as a gas warm from its charge beside a wall at the room's
    293.15 K: C within 1 % and 2 sigma, T10 above the room's (measured: C +0.14 %, T10
    300-301 K for 313.15: the pressure tells the gap's sign, hardly its size; C moves
    little along that valley, which the heat exchange takes up)."""
    t, y = _long_plateau(seed)
    est = analyze(t, y, EstimatorSettings(volume=5e-3, curve_fit=True))
    (r,) = merge_final(est)
    assert abs(r.t_start - 10.0) < 0.02, r.t_start
    law = r.extra["curve_fit"]["heat_law"]
    assert r.final and law.endswith("+wall"), (law, r.status_text)
    assert abs(r.conductance_model / 3e-9 - 1.0) < 0.01
    assert abs(r.conductance_model - 3e-9) < 2.0 * r.conductance_model_std
    assert 293.15 + 3.0 < r.initial_temperature < 330.0
    (wall,) = [b for b in r.extra["budget"]["terms"] if b["name"].startswith("wall")]
    assert "a room's, held" in wall["note"]


@pytest.mark.parametrize("seed", [0, 1])
def test_a_small_warm_gas_not_measured_does_not_bend_b_and_m(seed):
    """A 5 K warm gas (T10 298.15 K, wall 293.15 K, thermal time constant 20 s, a 5 s
    plateau, 100 Hz, 5 L, 3e-9 m^3/(s Pa), b 0.3, m 0.5), T10 not given and no temperature
    log (bench_temperature_records' c07-hot5): the hot start was claimed only with m free,
    and there b went to its bound: b 0.010 +- 0.036 and m 0.428 +- 0.007 (z -8 and -11).
    Such a claim is no longer offered: b and m within 2 sigma, C within 2 %."""
    volume, c = 5e-3, 3e-9
    t = np.arange(0.0, 5.0 + 9.0 * volume / (1.4e5 * c), 1e-2)
    p = discharge(t, volume=volume, p10=5e5, t10=298.15, p_atm=101325.0, tau_heat=20.0,
                  t_open=5.0, flow_law=IsoLaw(c, 0.3, 0.5), t_wall=293.15)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    assert r.final
    assert abs(r.critical_ratio - 0.3) <= 2.0 * r.critical_ratio_std, \
        (r.critical_ratio, r.critical_ratio_std)
    assert abs(r.subsonic_index - 0.5) <= 2.0 * r.subsonic_index_std, \
        (r.subsonic_index, r.subsonic_index_std)
    assert abs(r.conductance_model / c - 1.0) < 0.02
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std


@pytest.mark.parametrize("seed", [1, 25])
def test_a_warm_gas_is_judged_by_the_hot_start_that_fits_best(seed):
    """A 6 K warm gas, 3.2 K at the opening after a 9.5 s plateau (thermal time constant
    14.6 s, 450 Hz, 7.3 L, 2.36e-9 m^3/(s Pa), b 0.59, 4 bar, a -2.1 kPa zero; a random
    draw of the acceptance's ranges), T10 not given. The constant-hA hot start (the
    record's own law, 3.2 K) was not claimed, within a room's spread, while the natural
    law's, which needs a larger gap for the same decay, was: C -2.9 % at z -3.9 on both
    draws. Judged on the hot start that fits best: none claimed where the plateau is
    straight within 2 sigma (draw 1: C +1.9 %, z 1.4, T10's line), the constant-hA one
    where it bends (draw 25: C +0.01 %)."""
    v, c = 7.2605e-3, 2.361e-9
    t = np.arange(0.0, 9.517 + 8.08 * v / (1.4e5 * c), 1.0 / 450.88)
    p = discharge(t, volume=v, p10=4.0118e5, t10=293.15 + 6.0, p_atm=101325.0,
                  tau_heat=14.61, t_open=9.517, flow_law=IsoLaw(c, 0.59, 0.5),
                  t_wall=293.15)
    y = p - 2091.0 + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=v)))
    assert r.extra["curve_fit"]["heat_law"] != "natural+wall"
    assert abs(r.conductance_model / c - 1.0) < 0.03
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std, \
        (r.conductance_model / c - 1.0, r.conductance_model_std / c)


def test_a_plateau_bending_toward_the_wall_claims_a_small_warm_gas():
    """8 K warm, 2.9 K at the opening after a 10 s plateau (thermal time constant 10 s,
    100 Hz, 5 L, 3e-9 m^3/(s Pa), b 0.3, 6 bar), T10 not given: within a room's spread
    the warm gas was not claimed, C +1.9 %. The plateau bends toward a level as a gas
    reaching the wall's temperature does (a leak's decay is straight over it), by more
    than PLATEAU_BEND_Z (2) of its sigmas: the hot start is claimed, C -0.1 to +0.0 %."""
    v, c = 5e-3, 3e-9
    t = np.arange(0.0, 10.0 + 8.0 * v / (1.4e5 * c), 1e-2)
    p = discharge(t, volume=v, p10=6e5, t10=301.15, p_atm=101325.0, tau_heat=10.0,
                  t_open=10.0, flow_law=IsoLaw(c, 0.3, 0.5), t_wall=293.15)
    y = p + np.random.default_rng(2).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=v)))
    assert r.extra["curve_fit"]["heat_law"].endswith("+wall"), r.extra["curve_fit"]
    assert abs(r.conductance_model / c - 1.0) < 0.01
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std


@pytest.mark.parametrize("seed", [1, 3])
def test_the_opening_is_found_where_the_trigger_fired_on_the_drift(seed):
    """10 K warm, thermal time constant 8 s, a 10 s plateau at 200 Hz (5 L, 3e-9, b 0.3,
    6 bar), T10 not given: the plateau falls 14 kPa before the opening, the trigger fired
    on that drift at 0.8 s and the start's hinge, searched before the trigger, was put at
    0.5 s with no fall (its residual 4.4 x the noise): C -10.5 % and -11.0 %. A hinge that
    misses the window by more than HINGE_MISFIT x its noise has the drifting plateau's
    start fitted: the opening within 10 ms, C within 0.2 %."""
    v, c = 5e-3, 3e-9
    t = np.arange(0.0, 10.0 + 8.0 * v / (1.4e5 * c), 5e-3)
    p = discharge(t, volume=v, p10=6e5, t10=303.15, p_atm=101325.0, tau_heat=8.0,
                  t_open=10.0, flow_law=IsoLaw(c, 0.3, 0.5), t_wall=293.15)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=v)))
    assert abs(r.t_start - 10.0) < 0.01, r.t_start
    assert abs(r.conductance_model / c - 1.0) < 0.01
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std


def test_a_warm_gas_far_from_the_room_is_found_from_the_pressure_alone():
    """30 K warm at the record's start, 11 K at the opening after a 10 s plateau (thermal
    time constant 10 s, 1 kHz, 2 L, 1.5e-8 m^3/(s Pa), b 0.4, 7 bar, a -3 kPa zero; the
    temperature grid's c11-hot30 without its log): without the offset the warm gas's fit
    went to 412 K and to the 600 K bound, neither claimed, and the offset's probe on the
    chosen law (no hot start) gained nothing: the record missed by 3 x its noise, the
    offset not found, b not determined, C +1.8 %. The record's end clearly away from p_atm,
    the whole family is fitted with the offset, its hot starts with it: T10 304 K, C, b and
    the offset found (4 noise draws of 4)."""
    v, c = 2e-3, 1.5e-8
    t = np.arange(0.0, 10.0 + 7.0 * v / (1.4e5 * c), 1e-3)
    p = discharge(t, volume=v, p10=7e5, t10=323.15, p_atm=101325.0, tau_heat=10.0,
                  t_open=10.0, flow_law=IsoLaw(c, 0.4, 0.5), t_wall=293.15)
    y = p - 3000.0 + np.random.default_rng(11).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=v)))
    assert r.extra["curve_fit"]["heat_law"].endswith("+wall"), r.status_text
    assert abs(r.conductance_model / c - 1.0) < 0.01
    assert abs(r.critical_ratio - 0.4) < 0.03
    assert abs(r.pressure_offset + 3000.0) < 500.0
    assert 300.0 < r.initial_temperature < 310.0


@pytest.mark.parametrize("dt,tau_heat,rate,plateau,offset,volume,c,b,p10", [
    (6.8, 30.2, 862.0, 6.2, 748.0, 7.8e-3, 1.13e-9, 0.38, 8.1e5),
    (5.4, 31.8, 631.0, 2.2, -2513.0, 40e-3, 1.66e-9, 0.45, 4.3e5)])
def test_a_warm_gas_not_claimed_is_in_the_sigma(dt, tau_heat, rate, plateau, offset, volume,
                                                c, b, p10):
    """A gas 5-7 K warm in a large tank (random draws 67 and 159 of
    ``bench/bench_random_draws.py temperature``), T10 not given, p_atm not given, no log:
    within a room's spread and on a plateau that does not bend, the record cannot tell the
    warm gas from none, and none is claimed. The hot start that fits best was dropped and
    C read 2.9 and 3.8 % high at z 2.5 and 2.6 (main 968cd85). Its C is now a reading of
    the model-form spread, as a heat law's is: z 0.9 on both (C unchanged: the record
    does not say which)."""
    t = np.arange(0.0, plateau + 6.0 * volume / (1.4e5 * c), 1.0 / rate)
    p = discharge(t, volume=volume, p10=p10, t10=293.15 + dt, p_atm=101325.0,
                  tau_heat=tau_heat, t_open=plateau, flow_law=IsoLaw(c, b, 0.5),
                  t_wall=293.15)
    y = p + offset + np.random.default_rng(1).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    fit = r.extra["curve_fit"]
    assert "+wall" not in fit["heat_law"]
    assert any(k.startswith("T10 not measured") for k in fit["not_offered"].values())
    assert abs(r.conductance_model / c - 1.0) < 0.05
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std, \
        (r.conductance_model / c - 1.0, r.conductance_model_std / c)


def test_the_noise_a_hinge_is_judged_against_counts_its_correlation():
    """correlated_noise_factor: rms_sigma (first differences) reads AR(1) noise of lag-1
    correlation rho as sqrt(1 - rho) of its standard deviation; the factor gives it back
    (rho 0.9: 3.16), and is 1 for white noise and for white noise on a cooling plateau."""
    from pneumatic_unload.estimation.regression import correlated_noise_factor, rms_sigma

    rng = np.random.default_rng(3)
    n, rho = 20000, 0.9
    e = rng.normal(0.0, 1.0, n)
    x = np.empty(n)
    x[0] = e[0]
    for k in range(1, n):
        x[k] = rho * x[k - 1] + np.sqrt(1.0 - rho**2) * e[k]
    # rho's estimate from n samples (its SE about 0.005 here) moves the factor by 16 x as
    # much at rho 0.9
    assert correlated_noise_factor(x) == pytest.approx(1.0 / np.sqrt(1.0 - rho), rel=0.1)
    assert rms_sigma(x) * correlated_noise_factor(x) == pytest.approx(np.std(x), rel=0.1)
    white = rng.normal(0.0, 1.0, 2000)
    assert correlated_noise_factor(white) == 1.0
    cooling = 40.0 * np.exp(-np.arange(2000) / 800.0) + white
    assert correlated_noise_factor(cooling) == 1.0
    assert correlated_noise_factor(x[:15]) == 1.0


def test_a_slow_unload_under_correlated_noise_is_not_read_as_a_drift():
    """bench_discrepancy's effect-free trial 106076 (AR(1) noise, rho 0.9, 1 kPa; 3.7 L,
    5.1 bar, tau0 24 s): the start's hinge missed its window by 3 times the noise of the
    first differences, which AR(1) 0.9 noise is everywhere; the drifting plateau's start
    put the opening wrong and every unload was aborted ('no complete unload', fe9b0c6 on).
    Judged against the plateau's noise, correlation counted, the unload is found and C
    holds."""
    from pneumatic_unload.discrepancy.synthetic import draw_case

    case = draw_case("none", 106076, rho=0.9)
    cfg = case.config
    sim = case.simulate()
    res = analyze(sim.t, sim.measured, EstimatorSettings(
        volume=cfg.volume, initial_temperature=cfg.initial_temperature,
        atmosphere=cfg.atmosphere))
    first = next(r for r in res if r.final)
    assert first.status == "ok", first.status_text
    assert first.t_start == pytest.approx(0.2, abs=0.02)
    # the tail's noise at p_atm is no new unload (before decisions.noise_scales: eleven
    # phantom starts after 70 s, each 'aborted')
    assert {r.t_start for r in res} == {first.t_start}, [(r.t_start, r.status) for r in res]
    assert abs(first.conductance_model / cfg.conductance - 1.0) < 0.01
    assert abs(first.conductance_model - cfg.conductance) < 2.0 * first.conductance_model_std
