# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discrepancy workflow weighs its models with a logged gas temperature.

Traces from the independent model ``foreign/newton_tank.py`` (Newton cooling toward a wall
at the room's temperature, the gas warm from its charge: a hot start), a thermocouple of
0.3 s lag read at 10 Hz with 0.2 K noise and 0.1 K resolution, pressure at 1 kHz with
1 kPa noise. The workflow names the effects on the pressure; the log then fits the final
model's T10 and the thermometer's lag (its C reported when its gas follows the log) and
rules out the members of C's range whose gas does not follow it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge, thermocouple

from pneumatic_unload.discrepancy import DiscrepancySettings
from pneumatic_unload.discrepancy.ambiguity import ConductanceAmbiguity
from pneumatic_unload.discrepancy.workflow import find_discrepancy

V, C, B = 2e-3, 2e-8, 0.4
WALL, P_ATM = 293.15, 101325.0
LAG = 0.3  # the thermocouple's time constant [s]


def _record(dt_hot: float, tau_heat: float, plateau: float, seed: int = 3):
    """t [s], pressure [Pa], (log instants [s], log [K]) and the gas at the opening [K]."""
    t = np.arange(0.0, plateau + 6.0, 1e-3)
    gas = np.empty_like(t)
    p = discharge(t, volume=V, p10=7e5, t10=WALL + dt_hot, p_atm=P_ATM, tau_heat=tau_heat,
                  t_open=plateau, flow_law=IsoLaw(C, B), t_wall=WALL, temperature_out=gas)
    rng = np.random.default_rng(seed)
    y = p + rng.normal(0.0, 1000.0, t.size)
    read = thermocouple(t, gas, LAG, float(gas[0]))
    k = np.arange(0, t.size, 100)
    log = np.round((read[k] + rng.normal(0.0, 0.2, k.size)) * 10.0) / 10.0
    return t, y, (t[k], log), float(np.interp(plateau, t, gas))


def _settings(log: np.ndarray) -> DiscrepancySettings:
    # T10 as a bench takes it without the joint fit: the log's first reading
    return DiscrepancySettings(volume=V, initial_temperature=float(log[0]), atmosphere=P_ATM)


def test_the_log_rules_out_the_leaks_that_mimic_a_cooling_plateau():
    """A gas 15 K warm cooling slowly (tau 60 s) on a 3 s plateau: on the pressure alone a
    leak explains the plateau's decay as well as the hot start (C's range spans three
    models); the log, fitted with each, follows the hot start only: the leaks leave the
    range, C is the joint fit's, within 0.3 %, T10 at the opening and the lag recovered."""
    t, y, (tl, log), t_open_gas = _record(15.0, 60.0, 3.0)
    alone = find_discrepancy(t, y, _settings(log))
    assert alone.effect == "hot_start"
    assert {tuple(m["effects"]) for m in alone.conductance_ambiguity.members} >= {
        ("hot_start",), ("leak",)}
    res = find_discrepancy(t, y, _settings(log), temperature=(tl, log))
    assert res.effect == "hot_start"
    joint = res.temperature_joint
    assert joint is not None and joint["available"]
    final = joint["models"][0]
    assert final["follows"] and final["rms"] <= 2.0 * final["noise"]
    assert final["t10"] == pytest.approx(t_open_gas, abs=1.5)
    assert final["sensor_time_constant"] == pytest.approx(LAG, abs=0.1)
    assert res.conductance == pytest.approx(C, rel=3e-3)
    assert res.conductance == final["conductance"]
    amb = res.conductance_ambiguity
    gone = {tuple(m["effects"]) for m in amb.ruled_out}
    assert ("leak",) in gone
    assert all(tuple(m["effects"]) not in gone for m in amb.members)
    assert "rules out" in res.verdict and "supports the reported model" in res.verdict
    assert amb.high - amb.low < alone.conductance_ambiguity.high \
        - alone.conductance_ambiguity.low
    d = res.to_dict()
    assert d["conductance_range"]["ruled_out_by_temperature"]
    assert d["temperature_joint"]["models"][0]["follows"] is True
    assert not d["temperature_check"]["contradicts"]


def test_a_hot_start_fitted_with_its_log_gives_c_the_pressure_alone_misses():
    """A 20 K warm gas (tau 5 s, 2 s plateau): the pressure-only hot start misplaces the
    wall (C about -1 %); with the log the gas at the opening, the lag and C come back."""
    t, y, (tl, log), t_open_gas = _record(20.0, 5.0, 2.0)
    alone = find_discrepancy(t, y, _settings(log))
    res = find_discrepancy(t, y, _settings(log), temperature=(tl, log))
    assert abs(res.conductance / C - 1.0) < 3e-3 < abs(alone.conductance / C - 1.0)
    sigma = res.conductance_std()
    assert math.isfinite(sigma) and abs(res.conductance - C) <= 3.0 * sigma
    final = res.temperature_joint["models"][0]
    assert final["t10"] == pytest.approx(t_open_gas, abs=1.5)


def test_a_log_no_model_follows_rules_nothing_out():
    """A thermocouple in a stratified corner (its reading swings 3 K with a 4 s period
    that no uniform gas makes): no model follows it, the pressure's C stands, nothing is
    ruled out, the verdict says so."""
    t, y, (tl, log), _ = _record(15.0, 60.0, 3.0)
    odd = log + 3.0 * np.sin(2.0 * np.pi * tl / 4.0)
    alone = find_discrepancy(t, y, _settings(log))
    res = find_discrepancy(t, y, _settings(log), temperature=(tl, odd))
    assert res.conductance == alone.conductance
    assert not res.conductance_ambiguity.ruled_out
    assert not any(m.get("follows") for m in res.temperature_joint["models"])
    assert "no model follows the logged gas temperature" in res.verdict


def test_too_few_readings_are_said_not_fitted():
    t, y, (tl, log), _ = _record(15.0, 60.0, 3.0)
    res = find_discrepancy(t, y, _settings(log), temperature=(tl[:3], log[:3]))
    assert res.temperature_joint == {
        "available": False, "why": "3 reading(s) inside the trace; the joint fit needs 5"}


def test_rule_out_spans_the_range_anew():
    """The range is the 3-sigma span of the final model and the members left; with none
    left C is no longer ambiguous."""
    amb = ConductanceAmbiguity(
        members=[{"effects": ["hot_start"], "conductance": 2.0, "conductance_std": 0.01},
                 {"effects": ["leak"], "conductance": 1.9, "conductance_std": 0.01},
                 {"effects": ["orifice_leak"], "conductance": 2.2, "conductance_std": 0.02}],
        low=1.87, high=2.26, final_conductance=(2.0, 0.01))
    amb.rule_out({2: "departs"})
    assert amb.low == pytest.approx(1.87) and amb.high == pytest.approx(2.03)
    assert amb.ruled_out == [{"effects": ["orifice_leak"], "conductance": 2.2,
                              "conductance_std": 0.02, "why": "departs"}]
    amb.rule_out({0: "the reported model stays", 1: "departs"})
    assert not amb.ambiguous and amb.members == []
    assert (amb.low, amb.high) == pytest.approx((1.97, 2.03))
