# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""analyze CLI on a data-logger CSV with a gas-temperature column: T10 comes from it."""

import json
import math

import numpy as np
import pytest

from pneumatic_unload.app.cli import main
from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import simulate
from pneumatic_unload.physics import orifice_conductance


def _write_csv(path, t, p_kpa_gauge, temp_c):
    rows = ["Time [s],Pressure [kPa],Temp [C]"]
    rows += [f"{a:.4f},{b:.4f},{c:.3f}" for a, b, c in zip(t, p_kpa_gauge, temp_c, strict=True)]
    path.write_text("\n".join(rows) + "\n")


def _analyze(capsys, path, *extra):
    code = main(["analyze", str(path), "--volume", "0.002", "--gauge", "--atmosphere",
                 "101325", "--heat-model", "adiabatic", "--no-curve-fit", "--json", *extra])
    out = capsys.readouterr().out
    assert code == 0
    return json.loads(out)["unloads"][0]


def test_initial_temperature_from_csv_column_is_used(tmp_path, capsys):
    # hot gas (330 K) in a 330 K tank; the log starts 5 s before the valve opens while
    # the charge heat is still decaying, so row 0 reads hotter than the gas at the start
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(2e-3), noise_std=300.0,
                    seed=3, initial_temperature=330.0, wall_temperature=330.0,
                    pre_time=5.0, rate=100.0)
    sim = simulate(cfg)
    temp = sim.temperature + 8.0 * np.exp(-sim.t / 0.5)  # 338 K at row 0, 330 K at start
    t = sim.t + 1234.5  # the logger clock starts anywhere
    path = tmp_path / "run.csv"
    _write_csv(path, t, (sim.measured - 101325.0) / 1e3, temp - 273.15)

    auto = _analyze(capsys, path)
    assert auto["initial_temperature"] == pytest.approx(330.0, abs=0.05)
    given = _analyze(capsys, path, "--initial-temperature", "330")
    assert auto["conductance"] == pytest.approx(given["conductance"], rel=1e-4)
    assert auto["conductance_model"] == pytest.approx(given["conductance_model"], rel=1e-4)
    # and it matters: assuming 293.15 K changes C by sqrt(330/293.15) (eq 39)
    cold = _analyze(capsys, path, "--initial-temperature", "293.15")
    assert cold["conductance"] / auto["conductance"] == pytest.approx(
        math.sqrt(330.0 / 293.15), rel=2e-3)
    # the isentropic inversion recovers the true C only with the right T10
    assert auto["conductance_model"] == pytest.approx(cfg.conductance, rel=0.01)


def test_plot_of_an_analysis_is_written(tmp_path, capsys):
    """--plot renders the trace, p10, p*, the crossing, tau_exp and the fitted model with
    its residuals (checked by eye once; here: a real PNG of plausible size)."""
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=1000.0,
                    seed=5, rate=200.0, effects=("heat_transfer",))
    sim = simulate(cfg)
    path = tmp_path / "run.csv"
    _write_csv(path, sim.t, (sim.measured - 101325.0) / 1e3,
               sim.temperature - 273.15)
    png = tmp_path / "analysis.png"
    code = main(["analyze", str(path), "--volume", "0.001", "--gauge", "--atmosphere",
                 "101325", "--plot", str(png)])
    assert code == 0
    assert "plot written" in capsys.readouterr().out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
