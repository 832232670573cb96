# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The logged gas temperature as evidence on the final fit (JSON ``gas_temperature``): a
multi-rate CSV (pressure at 1 kHz, a thermocouple at 5 Hz in the same file, empty cells
between) made by the independent model of ``test/foreign/newton_tank.py``. The fitted
model's gas, seen through a fitted first-order lag and offset, follows a log that the same
physics made, within the channel's noise; a log the pressure's physics did not make is
said to depart, in the status text. A log the model follows is fitted jointly with the
pressure (``used``: T10 and the thermometer's lag fitted); one it does not follow is not
used, and the joint fit's C is a line of the budget."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from foreign.newton_tank import discharge

from pneumatic_unload.app.cli import main
from pneumatic_unload.model import first_order_lag

V, C, P_ATM, T10 = 5e-3, 8e-9, 101325.0, 293.15


def _csv(path, *, tau_heat_log: float, lag: float, seed: int) -> None:
    """A 1 kHz pressure and a 5 Hz thermocouple (time constant ``lag`` [s], 0.3 K noise)
    of the gas of a discharge whose heat exchange has the thermal time constant
    ``tau_heat_log`` [s] (the pressure's: 8 s)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 12.0, 1e-3)
    p = discharge(t, volume=V, conductance=C, b=0.4, p10=7e5, t10=T10, p_atm=P_ATM,
                  tau_heat=8.0, t_open=0.5)
    gas = np.empty_like(t)
    discharge(t, volume=V, conductance=C, b=0.4, p10=7e5, t10=T10, p_atm=P_ATM,
              tau_heat=tau_heat_log, t_open=0.5, temperature_out=gas)
    seen = first_order_lag(t, gas, lag)[0]
    rows = ["time [s],pressure [kPa],gas temperature [C]"]
    y = (p + rng.normal(0.0, 700.0, t.size)) / 1e3
    for k in range(t.size):
        temp = f"{seen[k] - 273.15 + rng.normal(0.0, 0.3):.3f}" if k % 200 == 0 else ""
        rows.append(f"{t[k]:.4f},{y[k]:.4f},{temp}")
    path.write_text("\n".join(rows) + "\n")


def _analyze(path, capsys) -> dict:
    assert main(["analyze", str(path), "--volume", str(V), "--json"]) == 0
    (u,) = [x for x in json.loads(capsys.readouterr().out)["unloads"] if x["final"]]
    return u


def test_a_log_of_the_same_physics_is_followed_within_its_noise(tmp_path, capsys):
    path = tmp_path / "run.csv"
    _csv(path, tau_heat_log=8.0, lag=2.0, seed=1)
    u = _analyze(path, capsys)
    ev = u["gas_temperature"]
    assert ev["used"] is True and "jointly" in ev["why"], ev
    assert 55 <= ev["samples"] <= 60  # 5 Hz for 12 s, those of the last 0.5 s left out
    assert ev["follows"] and ev["rms"] <= 2.0 * ev["noise"], ev
    # the thermocouple's 2 s lag and the gas's 293.15 K, each within 3 of its sigmas
    assert abs(ev["sensor_time_constant"] - 2.0) < 3.0 * ev["sensor_time_constant_std"] + 0.05
    assert abs(ev["t10"] - T10) < 3.0 * ev["t10_std"] + 0.05, ev
    assert "departs" not in u["status_text"]
    assert abs(u["conductance_model"] / C - 1.0) < 0.01
    assert not any("the log departs" in b["name"] for b in u["budget"]["terms"])


def test_a_log_the_pressure_did_not_make_departs_and_the_status_says_so(tmp_path, capsys):
    """The thermocouple saw a gas that exchanged heat eight times faster (tau 1 s) than the
    pressure shows (8 s): no lag and offset make the fitted model follow it."""
    path = tmp_path / "run.csv"
    _csv(path, tau_heat_log=1.0, lag=1.0, seed=2)
    u = _analyze(path, capsys)
    ev = u["gas_temperature"]
    assert ev["used"] is False and "no heat law follows it" in ev["why"], ev
    assert not ev["follows"] and ev["rms"] > 2.0 * ev["noise"], ev
    assert "the logged gas temperature departs from the model's" in u["status_text"]
    (line,) = [b for b in u["budget"]["terms"] if "the log departs" in b["name"]]
    # C rms / (2 T10): the model's gas is uncertain by the departure
    assert abs(line["std"] / u["conductance_model"] - ev["rms"] / (2.0 * T10)) < 1e-3
    # the pressure alone is fitted: C as without the log, its sigma wider by the line
    assert abs(u["conductance_model"] / C - 1.0) < 0.01
    assert u["conductance_model_std"] >= line["std"]


def test_a_record_without_temperature_says_so(tmp_path, capsys):
    t = np.arange(0.0, 12.0, 1e-3)
    p = discharge(t, volume=V, conductance=C, b=0.4, p10=7e5, t10=T10, p_atm=P_ATM,
                  tau_heat=8.0, t_open=0.5)
    path = tmp_path / "p.csv"
    np.savetxt(path, np.column_stack([t, p + np.random.default_rng(3).normal(0, 700, t.size)]),
               delimiter=",", header="time [s],pressure [Pa]", comments="")
    ev = _analyze(path, capsys)["gas_temperature"]
    assert ev["used"] is False and "carries no gas temperature" in ev["why"]


def test_a_hot_start_through_a_slow_thermocouple_gives_t10_and_c(tmp_path, capsys):
    """Gas charged 25 K warm (318.15 K, wall 293.15 K, tau 20 s), a 2 s plateau, a
    thermocouple of 3 s lag that lagged the charge (3 K behind at the first row), 0.3 K
    noise at 2 Hz beside 500 Hz pressure. Its reading at the opening is not T10 (it lags a
    gas cooling at 1 K/s); fitted jointly, T10 and the lag come out of the log: T10 within
    1 K (3 of its sigmas at least), the lag within 0.5 s, C within 1 % (with the reading
    at the opening as T10 it was +0.6 % .. +1.5 % on the bench's 10-30 K hot starts)."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 14.0, 2e-3)
    gas = np.empty_like(t)
    p = discharge(t, volume=V, conductance=C, b=0.4, p10=7e5, t10=318.15, p_atm=P_ATM,
                  tau_heat=20.0, t_open=2.0, t_wall=T10, temperature_out=gas)
    seen = first_order_lag(t, gas, 3.0, (float(t[0]), float(gas[0]), float(gas[0]) - 3.0))[0]
    rows = ["time [s],pressure [kPa],gas temperature [C]"]
    y = (p + rng.normal(0.0, 1000.0, t.size)) / 1e3
    for k in range(t.size):
        temp = f"{seen[k] - 273.15 + rng.normal(0.0, 0.3):.2f}" if k % 250 == 0 else ""
        rows.append(f"{t[k]:.4f},{y[k]:.4f},{temp}")
    path = tmp_path / "hot.csv"
    path.write_text("\n".join(rows) + "\n")
    u = _analyze(path, capsys)
    ev = u["gas_temperature"]
    assert ev["used"] is True and ev["follows"], ev
    t10 = float(gas[np.searchsorted(t, 2.0)])  # T10 is the gas at the opening (315.8 K)
    assert abs(ev["t10"] - t10) < max(1.0, 3.0 * ev["t10_std"]), (ev, t10)
    assert abs(ev["sensor_time_constant"] - 3.0) < 0.5, ev
    assert abs(u["conductance_model"] / C - 1.0) < 0.01
    assert u["initial_temperature"] == ev["t10"]


def _fit_with(**g):
    from types import SimpleNamespace
    base = {"departure_rms": 3.2, "noise": 0.2, "t10_assumed": 321.8, "joint_rms": 0.66,
            "probe": 1.0, "joint_within_probe": True, "joint_pressure_rms": 723.0,
            "pressure_rms": 562.0, "joint_conductance": 9.14e-9, "joint_critical_ratio": 0.50}
    return SimpleNamespace(conductance=8.35e-9, critical_ratio=0.57,
                           gas_temperature={**base, **g})


def test_a_log_followed_only_at_the_pressures_cost_puts_its_reading_in_the_budget():
    """Two readings of one record (AeroLab's 0.094 in run: the pressure alone, C 8.35e-9
    with the log 3.2 K away after its lag and offset; fitted jointly, the log followed to
    0.66 K within the probe's 1 K, the pressure's residual 723 Pa rms against 562, C
    9.14e-9): which describes the gas is not known, so the line is the gap over sqrt(3),
    not the departure's C rms / (2 T10) (0.5 %, which left the joint reading 3 sigma
    away); b's line likewise. A joint fit that did not follow the log within the probe is
    no reading: the departure's line alone, and none for b."""
    from pneumatic_unload.curvefit.temperature_evidence import temperature_terms

    (c_line,) = temperature_terms(_fit_with())
    assert c_line.std == pytest.approx((9.14e-9 - 8.35e-9) / 3**0.5)
    assert "joint fit's reading" in c_line.note and "0.66 K" in c_line.note
    (b_line,) = temperature_terms(_fit_with(), "b")
    assert b_line.std == pytest.approx(0.07 / 3**0.5)
    # not within the probe: the departure's own line; no reading of b
    (c_only,) = temperature_terms(_fit_with(joint_within_probe=False))
    assert c_only.std == pytest.approx(8.35e-9 * 3.2 / (2.0 * 321.8))
    assert temperature_terms(_fit_with(joint_within_probe=False), "b") == ()
    # a joint reading without b (not determined there): no b line
    assert temperature_terms(_fit_with(joint_critical_ratio=math.nan), "b") == ()
    # a joint reading nearer than the departure's line: that line stays
    (near,) = temperature_terms(_fit_with(joint_conductance=8.36e-9))
    assert near.std == pytest.approx(8.35e-9 * 3.2 / (2.0 * 321.8))
    # no departure: no line
    assert temperature_terms(_fit_with(departure_rms=math.nan)) == ()
