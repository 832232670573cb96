# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The thermometer's sensor model: its offset fitted where the wall is given, its lag given.

Multi-rate CSV logs (pressure at 1 kHz, a thermocouple at 5 Hz, empty cells between) of
discharges made by the independent model ``foreign/newton_tank.py`` (Newton cooling to a
wall at 293.15 K), read through a thermocouple of 1.5 s lag whose readings are off by a
calibration offset. Where the wall's temperature is given the gas relaxes toward a known
temperature and the readings show the offset: it is fitted with T10 and the lag. Where it
is not, T10 and the offset move the readings alike: the offset is held at 0 and the
probe's accuracy is T10's line of the budget.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge, thermocouple

from pneumatic_unload.app.cli import main

V, C, WALL, LAG = 5e-3, 6e-9, 293.15, 1.5


def _log(path, offset: float, dt_hot: float) -> float:
    """Write the log; return the gas temperature at the opening [K]."""
    t = np.arange(0.0, 32.0, 1e-3)
    gas = np.empty_like(t)
    p = discharge(t, volume=V, p10=6e5, t10=WALL + dt_hot, p_atm=101325.0, tau_heat=20.0,
                  t_open=2.0, flow_law=IsoLaw(C, 0.3), t_wall=WALL, temperature_out=gas)
    rng = np.random.default_rng(5)
    y = p + rng.normal(0.0, 1000.0, t.size)
    read = thermocouple(t, gas, LAG, float(gas[0])) + offset
    k = np.arange(0, t.size, 200)
    temp = np.full(t.size, np.nan)
    temp[k] = np.round((read[k] - 273.15 + rng.normal(0.0, 0.2, k.size)) * 10.0) / 10.0
    rows = [f"{a:.4f},{b / 1e3:.4f}," + ("" if math.isnan(c) else f"{c:.1f}")
            for a, b, c in zip(t, y, temp, strict=True)]
    path.write_text("time [s],pressure [kPa],gas temperature [C]\n" + "\n".join(rows) + "\n")
    return float(np.interp(2.0, t, gas))


def _analyze(path, capsys, *extra: str) -> dict:
    assert main(["analyze", str(path), "--volume", repr(V), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)["unloads"][-1]


@pytest.mark.parametrize("offset,dt_hot", [(2.0, 0.0), (-3.0, 10.0)])
def test_the_offset_is_fitted_where_the_wall_is_given(tmp_path, capsys, offset, dt_hot):
    path = tmp_path / "log.csv"
    t_open_gas = _log(path, offset, dt_hot)
    u = _analyze(path, capsys, "--wall-temperature", repr(WALL))
    g = u["gas_temperature"]
    assert g["used"] and g["follows"]
    assert abs(g["sensor_offset"] - offset) <= max(0.5, 3.0 * g["sensor_offset_std"])
    assert g["sensor_offset_std"] < 0.5
    assert g["t10"] == pytest.approx(t_open_gas, abs=0.5)
    assert g["sensor_time_constant"] == pytest.approx(LAG, abs=0.2)
    assert u["conductance_model"] == pytest.approx(C, rel=5e-3)


def test_without_the_wall_the_offset_is_held_and_t10_carries_it(tmp_path, capsys):
    """A 2 K offset read as a gas 2 K warmer: the fit cannot tell, sigma(C) covers it (T10's
    line), and the JSON says the offset was held (0 +- 0)."""
    path = tmp_path / "log.csv"
    t_open_gas = _log(path, 2.0, 0.0)
    u = _analyze(path, capsys)
    g = u["gas_temperature"]
    assert g["used"] and (g["sensor_offset"], g["sensor_offset_std"]) == (0.0, 0.0)
    assert g["t10"] == pytest.approx(t_open_gas + 2.0, abs=0.5)
    err = u["conductance_model"] - C
    assert abs(err) <= 2.0 * u["conductance_model_std"]
    t10_line = next(t for t in u["budget"]["terms"] if t["name"] == "initial temperature T10")
    assert t10_line["input_std"] == 1.0


def test_a_given_thermometer_lag_is_held(tmp_path, capsys):
    """The probe's lag given (its data sheet): held at it; a wrong one (0.3 s for 1.5)
    leaves the model's gas off the log: not used, and why."""
    path = tmp_path / "log.csv"
    _log(path, 0.0, 10.0)
    g = _analyze(path, capsys, "--thermometer-time-constant", "1.5")["gas_temperature"]
    assert g["used"] and g["follows"] and g["sensor_time_constant"] == 1.5
    g = _analyze(path, capsys, "--thermometer-time-constant", "0.3")["gas_temperature"]
    assert not g["used"] and "departs" in g["why"]
