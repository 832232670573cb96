"""Records with the gas temperature logged, a zero offset and a flow law whose m is not
0.5, made by the independent model of ``test/foreign/newton_tank.py`` (Newton cooling at a
constant hA, the law the package calls 'fixed'): draws 48 and 46 of
``bench/bench_random_draws.py temperature``. The reading that fits both channels to their
noise is the constant-hA hot start with m and the offset fitted; two greedy steps of the
law search used to miss it, the natural law with m free was chosen and no heat law
followed the log:

* draw 48: the offset's probe fitted that reading, but its fit was dropped when the
  family was fitted again with the offset (which fits m for its best law only): the
  natural law's, 36 worse in BIC, was chosen, the log 11 K rms from it (0.48 K noise);
* draw 46: the gas is 2 K warm at the opening, so the constant-hA hot start was offered
  only if it turned the residuals white with m held at 0.5, which m 0.67 does not allow:
  C -1.0 %, b 0.08 for 0.31, the log 11 K away (every noise draw tried).

Each record as the bench writes it: pressure at 500-600 Hz with 1000 Pa noise, the
thermocouple at 4-7 Hz in 0.1 K steps, empty cells between."""

from __future__ import annotations

import json

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge, thermocouple

from pneumatic_unload.app.cli import main

P_ATM, WALL, NOISE = 101325.0, 293.15, 1000.0

# dT [K], tau_heat [s], lag [s], T rate, p rate [Hz], plateau [s], offset [Pa], V [m^3],
# C [m^3/(s Pa)], b, m, p10 [Pa], tau0 recorded, T noise [K], thermocouple behind [K]
CASES = {
    "the offset probe's fit kept (draw 48)": (
        23.14, 5.622, 1.308, 4.07, 595.2, 9.958, -1404.8, 4.2835e-3, 2.5574e-8, 0.3119,
        0.4022, 786923.0, 5.823, 0.367, 3.68),
    "a hot start white with m free (draw 46)": (
        4.03, 11.77, 4.189, 7.163, 498.8, 7.896, 2800.3, 6.7728e-4, 1.3022e-9, 0.3055,
        0.6654, 861530.0, 5.147, 0.410, 2.82),
}


def _csv(path, case, seed: int) -> None:
    (dt, tau_h, lag, t_rate, p_rate, plateau, offset, v, c, b, m, p10, n_tau0, t_noise,
     behind) = case
    tau0 = v / (1.4e5 * c)
    t = np.arange(0.0, plateau + n_tau0 * tau0, 1.0 / p_rate)
    gas = np.empty_like(t)
    p = discharge(t, volume=v, p10=p10, t10=WALL + dt, p_atm=P_ATM, tau_heat=tau_h,
                  t_open=plateau, flow_law=IsoLaw(c, b, m), t_wall=WALL,
                  temperature_out=gas)
    rng = np.random.default_rng(seed)
    y = p + offset + rng.normal(0.0, NOISE, t.size)
    seen = thermocouple(t, gas, lag, gas[0] - behind)
    every = round(p_rate / t_rate)
    rows = ["time [s],pressure [kPa],gas temperature [C]"]
    for k in range(t.size):
        temp = f"{round((seen[k] - 273.15 + rng.normal(0.0, t_noise)) * 10.0) / 10.0:.1f}" \
            if k % every == 0 else ""
        rows.append(f"{t[k]:.4f},{y[k] / 1e3:.4f},{temp}")
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("name", list(CASES))
def test_the_reading_that_fits_both_channels_is_found(name, tmp_path, capsys):
    case = CASES[name]
    path = tmp_path / "run.csv"
    _csv(path, case, seed=3)
    assert main(["analyze", str(path), "--volume", repr(case[7]), "--json"]) == 0
    (u,) = [x for x in json.loads(capsys.readouterr().out)["unloads"] if x["final"]]
    c, b, m, offset = case[8], case[9], case[10], case[6]
    ev = u["gas_temperature"]
    assert ev["used"] is True and ev["rms"] <= 2.0 * ev["noise"], (ev, u["status_text"])
    assert u["heat_law"] == "fixed+wall", u["heat_law"]
    assert abs(u["conductance_model"] / c - 1.0) < 0.005, u["conductance_model"] / c - 1
    assert abs(u["critical_ratio"] - b) < 0.03, u["critical_ratio"]
    assert abs(u["subsonic_index"] - m) < 0.03, u["subsonic_index"]
    assert abs(u["pressure_offset"] - offset) < 300.0, u["pressure_offset"]
    assert abs(u["conductance_model"] - c) <= 2.0 * u["conductance_model_std"]
    if "draw 46" in name:
        # the natural law's hot start is fitted and refused (1-2 K from the log, residuals
        # not white): the record says why, as for every fit made and not offered
        why = u["heat_laws"]["not_offered"].get("natural+wall", "")
        assert "not claimed" in why and "logged T10" in why, u["heat_laws"]
