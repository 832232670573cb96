# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The time law of the wall heat exchange, hA = hA_0 exp(g1 u + g2 u^2), u = ln(1 + s/tau_t):
the kernel against the closed form of a gas relaxing to its wall in a closed tank, and the
parametric model's candidate built on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.effects import FIT_HEAT_LAWS, HEAT_VARIANTS
from pneumatic_unload.model.heat import time_parameters
from pneumatic_unload.model.ode import integrate

#: A 5 L tank at 5 bar, the gas at 320 K, the wall at 293.15 K, hA_0 0.5 W/K, tau_t 2 s;
#: the valve shut a microsecond after it opens (no flow: the gas's mass is fixed).
CLOSED = dict(volume=5e-3, conductance=1e-9, initial_pressure=5e5, initial_temperature=320.0,
              wall_temperature=293.15, effects=("heat_transfer",), pre_time=0.0,
              noise_std=0.0, valve_close_time=1e-6, heat_transfer_mode="time",
              heat_transfer_coefficient=0.5, heat_transfer_time_constant=2.0)


@pytest.mark.parametrize("g1", [0.0, 0.8, -0.6])
def test_a_closed_tank_relaxes_to_its_wall_as_the_closed_form_says(g1):
    """m c_v dT/dt = hA_0 (1 + s/tau_t)^g1 (T_w - T) (g2 = 0): T = T_w + (T10 - T_w)
    exp(-I/(m c_v)), I = hA_0 tau_t / (g1 + 1) ((1 + s/tau_t)^(g1 + 1) - 1)."""
    cfg = RigConfig(**CLOSED, heat_transfer_time_slope=g1)
    t = np.linspace(0.0, 20.0, 201)
    temp = integrate(cfg, t, 0.0, rtol=1e-10)[:, 1]
    gas = cfg.gas
    m_cv = 5e5 * 5e-3 / (gas.gas_constant * 320.0) * gas.gas_constant / (gas.gamma - 1.0)
    integral = 0.5 * 2.0 / (g1 + 1.0) * ((1.0 + t / 2.0) ** (g1 + 1.0) - 1.0)
    expect = 293.15 + (320.0 - 293.15) * np.exp(-integral / m_cv)
    assert np.max(np.abs(temp - expect)) < 1e-5
    assert abs(temp[-1] - 293.15) > 1.0  # the exchange is under way, not over


def test_the_curvature_enters_as_u_squared():
    """g2 alone: hA_0 exp(g2 u^2); against g1 = g2 (a different function), the gas
    relaxes differently, and g1 = g2 = 0 is the constant hA exactly."""
    t = np.linspace(0.0, 20.0, 41)
    fixed = integrate(RigConfig(**{**CLOSED, "heat_transfer_mode": "fixed"}), t, 0.0,
                      rtol=1e-10)[:, 1]
    zero = integrate(RigConfig(**CLOSED), t, 0.0, rtol=1e-10)[:, 1]
    curved = integrate(RigConfig(**CLOSED, heat_transfer_time_curvature=0.5), t, 0.0,
                       rtol=1e-10)[:, 1]
    sloped = integrate(RigConfig(**CLOSED, heat_transfer_time_slope=0.5), t, 0.0,
                       rtol=1e-10)[:, 1]
    assert np.array_equal(fixed, zero)
    assert np.all(curved[1:] < fixed[1:]) and np.max(np.abs(curved - sloped)) > 0.05
    assert time_parameters(RigConfig(**CLOSED, heat_transfer_time_curvature=0.5)) == (
        0.0, 0.5, 2.0)
    assert time_parameters(RigConfig(**{**CLOSED, "heat_transfer_mode": "fixed"})) == (
        0.0, 0.0, 1.0)


def test_the_time_laws_are_candidates_of_the_final_fit_not_of_the_discrepancy_search():
    assert {"time", "time2"} <= set(FIT_HEAT_LAWS)
    assert not {"time", "time2"} & set(HEAT_VARIANTS)
    assert [q.name for q in FIT_HEAT_LAWS["time2"].params] == [
        "tau_heat", "heat_time_slope", "heat_time_curvature"]
    assert math.isclose(FIT_HEAT_LAWS["time"].off(_start())["heat_time_slope"], 0.0)


def _start():
    from pneumatic_unload.model.effects import Start
    return Start(8e-9, 0.3, 0.5, 6e5, 101325.0, 2.0, 1e-3, 0.0, 20.0)
