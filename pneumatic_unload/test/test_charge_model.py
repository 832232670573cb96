# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The kernel's charge: a tank filled through the component from a supply (closed forms).

The same right-hand side as the discharge with the flow's direction: the component's
upstream side is the supply (p_s, T_s), its inflow carries the supply's enthalpy c_p T_s.
Checked against what the balances give in closed form: the choked rise of an adiabatic
charge is a straight line, an adiabatic fill ends at the temperature its energy balance
gives, and a wall at constant hA brings the gas back to the wall's temperature.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import kernel
from pneumatic_unload.model.ode import kernel_parameters

GAMMA, R = 1.4, 287.05
RHO_N, T_N = 1.185, 293.15
V, C, B = 0.01, 1e-8, 0.4


def _charge(p0: float, t0: float, p_s: float, t_s: float, t_end: float, *,
            heat_a: float = 0.0, t_wall: float = 293.15, points: int = 4001):
    cfg = RigConfig(volume=V, conductance=C, critical_ratio=B, initial_pressure=7e5,
                    initial_temperature=t0)
    prm = kernel_parameters(cfg, 0.0)
    prm[kernel.CHARGE], prm[kernel.P_SUPPLY], prm[kernel.T_SUPPLY] = 1.0, p_s, t_s
    prm[kernel.HEAT_MODE] = kernel.HEAT_FIXED if heat_a > 0.0 else kernel.HEAT_NONE
    prm[kernel.HEAT_A], prm[kernel.T_WALL] = heat_a, t_wall
    t = np.linspace(0.0, t_end, points)
    out = np.zeros((t.size, 2))
    status, rows, _, _ = kernel.integrate(np.array([p0, t0]), np.array([0.0, t_end]), t, prm,
                                          1e-10, np.array([1e-6, 1e-9]), 0.0, 0.0, 200_000,
                                          out)
    assert status == kernel.OK and rows == t.size
    return t, out[:, 0], out[:, 1]


@pytest.mark.parametrize("t_s", [293.15, 330.0])
def test_an_adiabatic_choked_charge_rises_along_a_straight_line(t_s):
    """While p <= b p_s the inflow G = C rho_N p_s sqrt(T_N/T_s) is constant and the tank's
    energy balance gives dp/dt = gamma R T_s G / V whatever the gas's temperature."""
    p_s = 7e5
    t, p, _ = _charge(1e5, 293.15, p_s, t_s, 5.0)
    g = C * RHO_N * p_s * math.sqrt(T_N / t_s)
    slope = GAMMA * R * t_s * g / V
    choked = p <= B * p_s
    assert np.count_nonzero(choked) > 100
    assert np.max(np.abs(p[choked] - (1e5 + slope * t[choked]))) < 1e-6 * p_s


def test_an_adiabatic_fill_ends_where_its_energy_balance_says():
    """From p0, T0 to the supply's p_s the gas gains (p_s - p0) V / (gamma R T_s) of mass
    at c_p T_s: T_f = p_s V / (R m_f); from a near vacuum T_f -> gamma T_s."""
    p0, t0, p_s, t_s = 3000.0, 293.15, 1.0e5, 293.15
    _, p, temp = _charge(p0, t0, p_s, t_s, 400.0)
    m_f = p0 * V / (R * t0) + (p_s - p0) * V / (GAMMA * R * t_s)
    assert p[-1] == pytest.approx(p_s, rel=1e-7)
    assert temp[-1] == pytest.approx(p_s * V / (R * m_f), rel=1e-6)
    assert temp[-1] > 0.98 * GAMMA * t_s


def test_a_wall_brings_the_filled_gas_back_to_its_temperature():
    """The gas heated by the fill cools at a constant hA toward the wall: the tank ends at
    the supply's pressure and the wall's temperature."""
    _, p, temp = _charge(1e5, 293.15, 6e5, 293.15, 1500.0, heat_a=2.0, t_wall=293.15)
    assert np.max(temp) > 330.0
    assert temp[-1] == pytest.approx(293.15, abs=0.01)
    assert p[-1] == pytest.approx(6e5, rel=1e-6)


def test_a_simulated_charge_rises_at_the_mirrored_eq38_slope():
    """``RigConfig(direction='charge')`` through ``simulate``: the choked rise is the
    straight line of slope gamma R T_s C rho_N p_s sqrt(T_N/T_s) / V, which is (p_s - p10)
    / tau with tau eq 38 mirrored (supply upstream: p_s, T_s in the place of p10, T10; the
    tank's p10 in the place of p_atm) up to eq 38's p_N for rho_N R T_N (ISO 8778's
    rho_N = 1.185 kg/m^3 is 0.28 % below p_N / (R T_N), as for the discharge)."""
    from pneumatic_unload.model import simulate
    from pneumatic_unload.physics import tau_exp_eq38

    cfg = RigConfig(direction="charge", volume=V, conductance=C, critical_ratio=B,
                    initial_pressure=1e5, supply_pressure=7e5, supply_temperature=310.0,
                    noise_std=0.0, rate=200.0)
    sim = simulate(cfg)
    slope = GAMMA * R * 310.0 * C * RHO_N * 7e5 * math.sqrt(T_N / 310.0) / V
    tau = tau_exp_eq38(7e5, 1e5, V, C, 310.0)
    assert (7e5 - 1e5) / tau / slope == pytest.approx(1e5 / (RHO_N * R * T_N), rel=1e-12)
    choked = (sim.t >= sim.t_open) & (sim.pressure <= B * 7e5)
    line = 1e5 + slope * (sim.t[choked] - sim.t_open)
    assert np.count_nonzero(choked) > 50
    assert np.max(np.abs(sim.pressure[choked] - line)) < 1e-5 * 7e5
    assert sim.pressure[-1] == pytest.approx(7e5, rel=2e-3)  # the record reaches the supply


@pytest.mark.parametrize("kw,words", [
    ({"supply_pressure": 1e5}, "a charge needs its supply above the tank"),
    ({"effects": ("pipe_volume",)}, "pipe_volume not modelled for a charge"),
])
def test_a_charge_the_model_cannot_make_is_refused_with_the_reason(kw, words):
    from pneumatic_unload.config import ConfigError

    with pytest.raises(ConfigError, match=words):
        RigConfig(direction="charge", initial_pressure=1e5, **kw)


def test_the_cli_simulates_a_charge_from_below_the_atmosphere(tmp_path, capsys):
    """`simulate --direction charge` from an evacuated tank (3 kPa) to the room: written
    (the discharge's check that p10 is above p_atm does not apply), the tank's pressure in
    the bag rising to the supply's."""
    import json

    from pneumatic_unload.analysis.records import open_record
    from pneumatic_unload.app.cli import main

    out = tmp_path / "charge"
    assert main(["simulate", "--direction", "charge", "--initial-pressure", "3000",
                 "--supply-pressure", "101325", "--volume", "0.016", "--noise-std", "100",
                 "--rate", "100", "--no-estimate", "--json", "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["samples"] > 1000
    p = np.concatenate([c[1] for c in open_record(out).chunks()])
    assert p[0] == pytest.approx(3000.0, abs=500.0)
    assert p[-1] == pytest.approx(101325.0, rel=2e-3)


@pytest.mark.parametrize("p10,p_s,b,m", [(1e5, 7e5, 0.3, 0.5), (3000.0, 101325.0, 0.5, 0.5),
                                         (2e5, 6e5, 0.2, 0.7), (1e5, 5e5, 0.7, 0.5)])
def test_the_mirrored_eq39_bias_is_the_adiabatic_charges_crossing(p10, p_s, b, m):
    """The charge's p* (63.2 % of the rise) comes at tau_c times the rise integral in the
    simulated adiabatic charge (the package's model: tau_c from its own slope, rho_N R for
    eq 38's p_N), and eq 39 mirrored reads C times 1/I (p_N/(rho_N R T_N) apart)."""
    from pneumatic_unload.charge import charge_eq39_bias, charge_p_star, charge_rise_integral
    from pneumatic_unload.model import simulate
    from pneumatic_unload.physics import conductance_eq39

    cfg = RigConfig(direction="charge", volume=V, conductance=C, critical_ratio=b,
                    subsonic_index=m, initial_pressure=p10, supply_pressure=p_s,
                    noise_std=0.0, rate=2000.0, pre_time=0.0)
    sim = simulate(cfg)
    target = charge_p_star(p10, p_s)
    k = int(np.argmax(sim.pressure >= target))
    t_cross = float(np.interp(target, sim.pressure[k - 1:k + 1], sim.t[k - 1:k + 1]))
    slope = GAMMA * R * 293.15 * C * RHO_N * p_s / V  # T_s = T_N
    tau_c = (p_s - p10) / slope
    assert t_cross == pytest.approx(tau_c * charge_rise_integral(p10 / p_s, b, m), rel=2e-5)
    c_eq39 = conductance_eq39(t_cross, p_s, p10, V, 293.15)
    ratio = 1e5 / (RHO_N * R * T_N)
    assert c_eq39 / C == pytest.approx(charge_eq39_bias(p10, p_s, b, m) / ratio, rel=2e-5)


def test_the_bias_is_1_over_0632_while_choked_at_p_star():
    from pneumatic_unload.charge import charge_eq39_bias, charge_rise_integral

    assert charge_eq39_bias(1e5, 5e5, 0.75) == pytest.approx(1.0 / 0.632, rel=1e-12)
    assert charge_rise_integral(0.2, 0.3, 0.5) > 0.632
    with pytest.raises(ValueError, match="p10/p_s < 1"):
        charge_rise_integral(1.0, 0.3)


@pytest.mark.parametrize("p10,p_s,t_s,tau_heat,m", [
    (1e5, 7e5, 293.15, math.inf, 0.5),     # adiabatic
    (1e5, 6e5, 310.0, 8.0, 0.5),           # a warmer supply, the wall cooling the gas
    (3000.0, 101325.0, 293.15, 20.0, 0.62),  # the room into an evacuated tank
])
def test_the_charge_agrees_with_an_independent_model(p10, p_s, t_s, tau_heat, m):
    """The package's charge (its kernel, through ``simulate``) against
    ``foreign/newton_tank.charge`` (mass and internal energy, Radau; written apart): the
    same tank, component and constant hA give the same pressure and gas temperature."""
    from foreign.newton_tank import charge

    from pneumatic_unload.model import simulate

    cv = R / (GAMMA - 1.0)
    h_a = 0.0 if math.isinf(tau_heat) else p10 * V / (R * 293.15) * cv / tau_heat
    cfg = RigConfig(direction="charge", volume=V, conductance=C, critical_ratio=B,
                    subsonic_index=m, initial_pressure=p10, initial_temperature=293.15,
                    supply_pressure=p_s, supply_temperature=t_s, noise_std=0.0, rate=100.0,
                    pre_time=0.5, effects=("heat_transfer",) if h_a else (),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=h_a or 1.0)
    sim = simulate(cfg, rtol=1e-10)
    gas = np.empty_like(sim.t)
    p = charge(sim.t, volume=V, p10=p10, t10=293.15, p_supply=p_s, t_supply=t_s,
               tau_heat=tau_heat, t_open=sim.t_open, conductance=C, b=B, subsonic_index=m,
               temperature_out=gas)
    assert np.max(np.abs(sim.pressure - p)) < 2e-6 * p_s
    assert np.max(np.abs(sim.temperature - gas)) < 1e-4


@pytest.mark.parametrize("p10,p_s", [(1e5, 6e5), (3000.0, 101325.0)])
def test_a_charge_given_to_analyze_is_said_to_be_one(p10, p_s):
    """A rising record holds no unload; the library says why in words (a charge, from and
    to which pressure), not "no drop" nor a gauge reading (a vacuum fill ends at p_atm)."""
    from pneumatic_unload.estimation import EstimatorSettings, analyze, explain_no_unload
    from pneumatic_unload.model import simulate

    sim = simulate(RigConfig(direction="charge", volume=V, conductance=C, critical_ratio=B,
                             initial_pressure=p10, supply_pressure=p_s, noise_std=200.0,
                             rate=200.0))
    s = EstimatorSettings(volume=V, atmosphere=101325.0)
    assert not [r for r in analyze(sim.t, sim.measured, s) if r.status == "ok"]
    why = explain_no_unload(sim.t, sim.measured, s)
    got = re.match(r"the pressure rises from (\S+) Pa to (\S+) Pa and never falls: a charge",
                   why)
    assert got, why
    assert float(got[1]) == pytest.approx(p10, abs=500.0)
    assert float(got[2]) == pytest.approx(p_s, rel=5e-3)


def test_a_charge_through_a_pair_in_series_agrees_with_an_independent_model():
    """A charge through two ISO elements in series (the supply side upstream: the kernel's
    ``pu_series_phi`` in the supply's branch) against ``foreign/newton_tank.charge`` with
    test/foreign's pair (written apart): the same pressure and gas temperature, and not
    those of the upstream element alone."""
    from foreign.newton_tank import IsoLaw, Series, charge

    from pneumatic_unload.model import simulate

    law = Series(IsoLaw(1.3e-8, 0.42, 0.52), IsoLaw(1.2e-8, 0.18, 0.30))
    p10, p_s, t_s, tau_heat = 1e5, 6e5, 310.0, 8.0
    h_a = p10 * V / (R * 293.15) * R / (GAMMA - 1.0) / tau_heat
    cfg = RigConfig(direction="charge", volume=V, conductance=law.conductance,
                    critical_ratio=0.42, subsonic_index=0.52,
                    series_conductance_ratio=1.2 / 1.3, series_critical_ratio=0.18,
                    series_subsonic_index=0.30, initial_pressure=p10,
                    initial_temperature=293.15, supply_pressure=p_s, supply_temperature=t_s,
                    noise_std=0.0, rate=100.0, pre_time=0.5, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=h_a)
    sim = simulate(cfg, rtol=1e-10)
    gas = np.empty_like(sim.t)
    p = charge(sim.t, volume=V, p10=p10, t10=293.15, p_supply=p_s, t_supply=t_s,
               tau_heat=tau_heat, t_open=sim.t_open, flow_law=law, temperature_out=gas)
    assert np.max(np.abs(sim.pressure - p)) < 2e-6 * p_s
    assert np.max(np.abs(sim.temperature - gas)) < 1e-4
    alone = simulate(cfg.replace(series_conductance_ratio=0.0), rtol=1e-10)
    assert np.max(np.abs(alone.pressure - p)) > 1e-3 * p_s
