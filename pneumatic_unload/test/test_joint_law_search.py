# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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
thermocouple at 4-7 Hz in 0.1 K steps, empty cells between. Draws 128 and 74 (their own
tests, each with the bench's noise draw): a law the joint fit left out brought back where
the log refutes the pressure's choice; a zero offset the fit does not determine (the
record cut as its tail levels) carried in b's and m's sigma, and the full record followed
on until its zero shows; draw 83: the pressure's choice kept in the joint family;
draw 86: a slow subsonic tail followed to its plateau, where its zero offset shows;
draw 153: where the chosen law has m free, every law is fitted with m free."""

from __future__ import annotations

import json
import zlib

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
#: Draws 128, 74 and 83 exactly as the bench drew them (their values and their noise: a
#: failure that lives in one noise draw is reproduced with it).
DRAWS = {
    128: (8.956707091388347, 24.176618554140806, 4.35270265277728, 3.351614669151276,
          542.3211801148797, 9.924806092828897, 1903.2352872561669, 0.0012160235123667106,
          1.9378241105397314e-09, 0.27234973379804206, 0.37909813097885436,
          490623.48409079236, 11.023170219365282, 0.47368331607127995, 2.9175438074635247),
    74: (23.1069639993806, 23.672454345542874, 4.4860440243954525, 9.367126293626205,
         132.39118561976812, 5.865387130042575, 710.9141362141604, 0.002382406168178757,
         7.830543163535284e-09, 0.49860201949585037, 0.5015753214530072, 554751.1338933613,
         8.715708173276802, 0.34913527071850214, 2.295460106787142),
    83: (24.942176771160028, 12.34172705812201, 0.6817439515194208, 7.588520712333947,
         189.00175044852534, 7.358469091132027, -263.3851421669897, 0.0011395946008155536,
         2.539497530406887e-09, 0.11204616297775291, 0.2832108780021309, 646418.5741988625,
         10.513976563932575, 0.3455613156801205, 2.1251373673603187),
    86: (19.799648295177686, 17.401818544563678, 3.0473116262489754, 5.962867903344267,
         821.5785694631275, 4.706564411252128, -803.4371627049168, 0.0035783572326132055,
         2.508532977845391e-08, 0.18379536478993477, 0.5, 784000.384439735,
         5.61317361486679, 0.4550769134370069, 2.0994283007176318),
    153: (16.804237274987816, 59.48781127121068, 1.6746381122241902, 4.376641867950686,
          594.1251136852741, 8.049486538464816, -438.6863805232488, 0.0037998413007628335,
          1.6683381418003133e-08, 0.24444351472770723, 0.46207712100269704,
          930694.1137976326, 11.161796186434113, 0.4846687687535798, 3.1638596963598515),
}


def _bench_seed(k: int) -> list[int]:
    return [zlib.crc32(f"stressT-{k}".encode()), 0]


def _csv(path, case, seed: int | list[int], with_t: bool = True) -> None:
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
    rows = ["time [s],pressure [kPa]" + (",gas temperature [C]" if with_t else "")]
    for k in range(t.size):
        temp = f"{round((seen[k] - 273.15 + rng.normal(0.0, t_noise)) * 10.0) / 10.0:.1f}" \
            if k % every == 0 else ""
        rows.append(f"{t[k]:.4f},{y[k] / 1e3:.4f}" + (f",{temp}" if with_t else ""))
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
        # a hot start fitted and refused (1-2 K from the log, residuals not white): the
        # record says why, as for every fit made and not offered
        whys = [v for k, v in u["heat_laws"]["not_offered"].items() if "+wall" in k]
        assert any("not claimed" in w and "logged T10" in w for w in whys), u["heat_laws"]


def _analyze(tmp_path, capsys, k: int, with_t: bool = True) -> dict:
    path = tmp_path / "run.csv"
    _csv(path, DRAWS[k], _bench_seed(k), with_t)
    assert main(["analyze", str(path), "--volume", repr(DRAWS[k][7]), "--json"]) == 0
    (u,) = [x for x in json.loads(capsys.readouterr().out)["unloads"] if x["final"]]
    return u


def _assert_the_records(u: dict, k: int, c_tol: float = 0.01) -> None:
    """Draw k's zero fitted within 500 Pa, C within ``c_tol`` and b and m within the
    acceptance (0.03, 0.05), each also within 2 of its sigmas."""
    c, b, m, offset = DRAWS[k][8], DRAWS[k][9], DRAWS[k][10], DRAWS[k][6]
    assert u["pressure_offset"] is not None, u["offset_source"]
    assert abs(u["pressure_offset"] - offset) < 500.0, u["pressure_offset"]
    assert abs(u["conductance_model"] - c) <= min(c_tol * c, 2.0 * u["conductance_model_std"])
    assert abs(u["critical_ratio"] - b) <= min(0.03, 2.0 * u["critical_ratio_std"]), (
        u["critical_ratio"], u["critical_ratio_std"])
    assert abs(u["subsonic_index"] - m) <= min(0.05, 2.0 * u["subsonic_index_std"]), (
        u["subsonic_index"], u["subsonic_index_std"])


def test_a_law_left_out_comes_back_where_the_log_refutes_the_pressures_choice(
        tmp_path, capsys):
    """Draw 128 (constant hA, m 0.38, a +1.9 kPa zero): the pressure alone chose the
    natural law with its wall at 277 K; the joint fit refits only the laws within the log's
    readings' count of that choice, which left out the constant hA (470 behind in BIC).
    The log then put the natural law 550 behind the joint's best, and the natural law with
    m free was read: m 0.424 +- 0.003 for 0.379, b 0.321 +- 0.004 for 0.272 (z 16, 12)."""
    u = _analyze(tmp_path, capsys, 128)
    c, b, m = DRAWS[128][8], DRAWS[128][9], DRAWS[128][10]
    assert u["heat_law"] == "fixed+wall", u["heat_laws"]
    assert abs(u["conductance_model"] - c) <= 2.0 * u["conductance_model_std"]
    assert abs(u["critical_ratio"] - b) <= min(0.03, 2.0 * u["critical_ratio_std"]), (
        u["critical_ratio"], u["critical_ratio_std"])
    assert abs(u["subsonic_index"] - m) <= min(0.03, 2.0 * u["subsonic_index_std"]), (
        u["subsonic_index"], u["subsonic_index_std"])


def test_an_unfitted_zero_is_in_the_sigma_of_b_and_m(tmp_path, capsys):
    """Draw 74 (a +0.7 kPa zero, m 0.50, 132 Hz) with its record cut where its tail levels
    (3.3 tau0 after the opening, 13.03 s): the zero is not determined there (+493 +- 115
    Pa, 8 better in BIC), so the offset is not fitted, and b and m take it up (m 0.59). An
    offset the fit does not determine moves b and m along the fit's valley: the
    transducer's stated uncertainty (0.1 % of p10 by default) times those slopes is a line
    of their budgets, where it was b's first-order move at the transition alone (b^2 d /
    p_atm) and none of m's (m 0.591 +- 0.009, z 10)."""
    path = tmp_path / "run.csv"
    case = (*DRAWS[74][:12], 3.3, *DRAWS[74][13:])
    _csv(path, case, _bench_seed(74))
    assert main(["analyze", str(path), "--volume", repr(case[7]), "--json"]) == 0
    (u,) = [x for x in json.loads(capsys.readouterr().out)["unloads"] if x["final"]]
    b, m = DRAWS[74][9], DRAWS[74][10]
    assert u["pressure_offset"] is None, u["offset_source"]
    lines = [t for t in u["budget_m"]["terms"] if t["name"] == "pressure transducer (offset)"]
    assert len(lines) == 1 and lines[0]["std"] > 0.0, u["budget_m"]["terms"]
    assert abs(u["subsonic_index"] - m) <= 2.0 * u["subsonic_index_std"], (
        u["subsonic_index"], u["subsonic_index_std"])
    assert abs(u["critical_ratio"] - b) <= 2.0 * u["critical_ratio_std"], (
        u["critical_ratio"], u["critical_ratio_std"])


def test_a_level_tail_away_from_p_atm_is_followed_until_its_zero_shows(tmp_path, capsys):
    """Draw 74 in full: its tail is level to the flat test at 13.0 s and its record runs
    on to 24.8 s, 0.7 kPa above p_atm. The tail used to end there, 145 samples of its level
    giving the offset +493 +- 115 Pa (8.2 better in BIC, not fitted) and m 0.591 +- 0.060
    for 0.50. A level tail clearly away from the given p_atm is now followed on until its
    gap is determined (decisions.zero_watch): the zero is fitted and C, b and m are the
    record's."""
    _assert_the_records(_analyze(tmp_path, capsys, 74), 74)


def test_the_pressures_choice_is_kept_in_the_joint_family(tmp_path, capsys):
    """Draw 83 (a 25 K warm gas, constant hA, m 0.28, b 0.11 from 6.5 bar, never choked):
    the pressure alone chose the constant hA's hot start with m free, which the joint
    family's search did not reach (its natural law with m free departed from the log by
    1.4 K rms for 0.42 K of noise), so the log was refused and b not reported (0.088 +-
    0.063). Kept in the joint family, it follows the log to its noise."""
    u = _analyze(tmp_path, capsys, 83)
    c, b, m, offset = DRAWS[83][8], DRAWS[83][9], DRAWS[83][10], DRAWS[83][6]
    ev = u["gas_temperature"]
    assert ev["used"] is True and ev["rms"] <= 2.0 * ev["noise"], (ev, u["status_text"])
    assert u["heat_law"] == "fixed+wall", u["heat_laws"]
    assert abs(u["conductance_model"] - c) <= min(0.005 * c, 2.0 * u["conductance_model_std"])
    assert u["critical_ratio"] is not None, u["critical_ratio_source"]
    assert abs(u["critical_ratio"] - b) <= min(0.03, 2.0 * u["critical_ratio_std"]), (
        u["critical_ratio"], u["critical_ratio_std"])
    assert abs(u["subsonic_index"] - m) <= min(0.03, 2.0 * u["subsonic_index_std"]), (
        u["subsonic_index"], u["subsonic_index_std"])
    assert abs(u["pressure_offset"] - offset) < 300.0, u["pressure_offset"]


@pytest.mark.parametrize("with_t", [True, False], ids=["with the log", "without it"])
def test_a_slow_subsonic_tail_is_followed_to_its_plateau(tmp_path, capsys, with_t):
    """Draw 86 (b 0.18, m 0.5, 7.8 bar, a -0.8 kPa zero, a 20 K warm gas): subsonic from
    5.5 bar on, the tail creeps to its plateau. The final-plateau test took it for level
    at 0.2 % of the drop per half tau, 0.9 kPa above its plateau, so the zero was not
    seen: with the log, m 0.600 +- 0.010 (z 10) and a wall at 270 K; without it, C -4.2 %
    at z -3.9. Followed to 0.05 %, the zero is fitted and C, b and m are the record's."""
    _assert_the_records(_analyze(tmp_path, capsys, 86, with_t), 86,
                        0.01 if with_t else 0.02)


def test_where_the_chosen_law_has_m_free_every_law_is_tried_with_m_free(tmp_path, capsys):
    """Draw 153 (constant hA, m 0.46, b 0.24, a -0.44 kPa zero, a 17 K warm gas, slow
    heat exchange): the search freed m for its best law only, the natural hot start, 9
    better in BIC with m free than held; the constant hA's hot start with m free, 14
    better still, was never fitted. With its zero fitted, b's and m's sigma no longer
    carried the offset's line: b 0.258 +- 0.004 (z 3.2) and m 0.485 +- 0.003 (z 6.6).
    Where the chosen law has m free, the whole family is fitted with m free."""
    u = _analyze(tmp_path, capsys, 153)
    assert u["heat_law"] == "fixed+wall", u["heat_laws"]
    _assert_the_records(u, 153)
