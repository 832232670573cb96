# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The foreign heat laws' generators (``test/foreign/heat_laws.py``) checked against closed
forms, so that the oracle of ``bench/bench_foreign_heat.py`` is itself checked: with the heat
flow off a discharge is isentropic and its choked part is eq 24 of the paper, a charge's
choked part rises linearly at gamma R T_s G / V; with a huge exchange each law approaches
the isothermal closed forms. The draws are reproducible and inside the stated ranges, and
the bench's own Newton-cooling fit recovers a record of its own law. Nothing here imports
the package.
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from foreign.heat_laws import (
    GAMMA,
    LAWS,
    NOISE,
    R_AIR,
    RHO_N,
    T_N,
    DecayingExchange,
    DensityDifference,
    PowerDifference,
    Rig,
    WarmingWall,
    draw,
    parameters,
    simulate,
)

CV = R_AIR / (GAMMA - 1.0)
RIG = Rig(volume=4e-3, conductance=5e-9, b=0.35, m=0.45, p10=7e5)
M0CV = RIG.p10 * RIG.volume / (R_AIR * RIG.t10) * CV
H_REF = M0CV / RIG.tau0  # [W/K]: a thermal time constant of tau0
#: One law of each kind, at a strength of 1e5 x H_REF: the gas held at the wall's temperature.
STRONG = (PowerDifference(1.5, H_REF, 1e5), DensityDifference(1.0, 0.5, H_REF, 1e5),
          WarmingWall(5.0 * M0CV, 0.2, H_REF, 1e5), DecayingExchange(5.0, 1.0, H_REF, 1e5))


def _choked_times(rig: Rig) -> np.ndarray:
    """Times [s] while the discharge is surely choked (p above p_atm / b, 5 % margin)."""
    k = rig.conductance * RHO_N * R_AIR * math.sqrt(T_N * rig.t10) / rig.volume
    t_iso = math.log(rig.p10 * rig.b / (1.05 * rig.p_atm)) / k  # the isothermal's is longest
    return np.linspace(0.0, 0.5 * t_iso, 200)


def test_heat_off_discharge_is_isentropic_and_its_choked_part_is_eq_24() -> None:
    s = np.linspace(0.0, 8.0 * RIG.tau0, 400)
    p, temp, _w = simulate(RIG, None, s)
    # isentropic at every instant, subsonic tail included
    np.testing.assert_allclose(temp, RIG.t10 * (p / RIG.p10) ** ((GAMMA - 1.0) / GAMMA),
                               rtol=1e-7)
    assert p[-1] == pytest.approx(RIG.p_atm, rel=2e-3)  # it empties to the atmosphere
    s = _choked_times(RIG)
    p, _t, _w = simulate(RIG, None, s)
    # eq 24 with p_N = rho_N R T_N (the reference state of the flow law)
    p_n = RHO_N * R_AIR * T_N
    tau = RIG.volume / (p_n * RIG.conductance) * 2.0 / (GAMMA - 1.0) \
        * math.sqrt(T_N / RIG.t10)
    closed = RIG.p10 * (1.0 + s / tau) ** (-2.0 * GAMMA / (GAMMA - 1.0))
    np.testing.assert_allclose(p, closed, rtol=1e-7)


@pytest.mark.parametrize("law", STRONG, ids=lambda law: law.name)
def test_huge_exchange_discharge_approaches_the_isothermal_closed_form(law) -> None:
    s = _choked_times(RIG)
    p, temp, wall = simulate(RIG, law, s)
    k = RIG.conductance * RHO_N * R_AIR * math.sqrt(T_N * RIG.t10) / RIG.volume
    np.testing.assert_allclose(p, RIG.p10 * np.exp(-k * s), rtol=2e-3)
    assert np.max(np.abs(temp - RIG.t10)) < 0.5
    assert np.max(np.abs(wall - RIG.t10)) < 0.5  # a warming wall held by the room's exchange
    # and a weak one is nearly adiabatic: far colder than the strong one
    _p, weak, _w = simulate(RIG, replace(law, strength=1e-4), s)
    isentropic = RIG.t10 * (np.exp(-k * s[-1])) ** ((GAMMA - 1.0) / GAMMA)
    assert weak[-1] < 0.5 * (RIG.t10 + isentropic)


def test_charge_rises_linearly_in_its_choked_part_adiabatic_and_isothermal() -> None:
    rig = Rig(volume=4e-3, conductance=5e-9, b=0.35, m=0.45, p10=101325.0,
              direction="charge", p_supply=8e5)
    g = rig.conductance * RHO_N * rig.p_supply * math.sqrt(T_N / rig.t_supply)  # [kg/s]
    t_end = 0.5 * (rig.b * rig.p_supply - rig.p10) * rig.volume / (GAMMA * R_AIR
                                                                     * rig.t_supply * g)
    s = np.linspace(0.0, t_end, 100)
    p, temp, _w = simulate(rig, None, s)
    np.testing.assert_allclose(p, rig.p10 + GAMMA * R_AIR * rig.t_supply * g * s
                               / rig.volume, rtol=1e-8)
    assert temp[-1] > rig.t10 + 5.0  # the filled gas warms
    p, temp, _w = simulate(rig, PowerDifference(1.5, H_REF, 1e5), s)
    np.testing.assert_allclose(p, rig.p10 + R_AIR * rig.t10 * g * s / rig.volume, rtol=2e-3)
    assert np.max(np.abs(temp - rig.t10)) < 0.5


@pytest.mark.parametrize("name", LAWS)
def test_draws_are_in_the_stated_ranges(name: str) -> None:
    d = parameters(name, 0)
    rig = d.rig
    assert 1e-3 <= rig.volume <= 20e-3 and 1e-9 <= rig.conductance <= 2e-8
    assert 3e5 <= rig.p10 <= 9e5 and 0.2 <= rig.b <= 0.5 and 0.35 <= rig.m <= 0.65
    assert d.law.name == name
    assert 0.0 < (d.t_open * 1e3) % 1.0 < 1.0  # the opening falls between two samples
    s = np.linspace(0.0, d.t_end - d.t_open, 300)
    _p, temp, _w = simulate(rig, d.law, s, rtol=1e-7)
    assert 2.9 <= np.max(rig.t10 - temp) <= 25.1  # cooled by the drawn 3-25 K


def test_a_record_is_reproducible_with_its_noise_and_opening() -> None:
    a = draw("warming-wall", 0)
    d = parameters("warming-wall", 0)  # the same draw again: the same parameters
    assert (d.rig, d.law, d.t_open) == (a.rig, a.law, a.t_open)
    assert not np.any(a.t == a.t_open) and a.t[0] < a.t_open < a.t[-1]
    before = a.t < a.t_open
    assert np.all(a.p_true[before] == a.rig.p10)
    assert np.std(a.p - a.p_true) == pytest.approx(NOISE, rel=0.05)
    assert 2.9 <= a.cooling <= 25.1


def test_the_bench_newton_fit_recovers_a_record_of_its_own_law() -> None:
    """The scipy fit the bench sets beside the package is sound on its own model (a
    constant hA: the decaying exchange with no jet), so a miss on a foreign law is the law's."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
    from bench_foreign_heat import newton_fit

    rig = Rig(volume=2e-3, conductance=8e-9, b=0.35, m=0.45, p10=6e5)
    law = DecayingExchange(1.0, 1.0, rig.p10 * rig.volume / (R_AIR * rig.t10) * CV / 3.0)
    t = np.arange(0.0, 0.3 + 6.0 * rig.tau0, 2e-3)
    t_open = 0.3007
    after = t >= t_open
    p = np.full(t.size, rig.p10)
    p[after], _temp, _w = simulate(rig, law, t[after] - t_open)
    y = p + np.random.default_rng(5).normal(0.0, NOISE, t.size)
    fit = newton_fit(t, y, rig.volume)
    assert fit["rms"] == pytest.approx(NOISE, rel=0.1)
    for key, truth in (("c", rig.conductance), ("b", rig.b), ("m", rig.m)):
        assert abs(fit[key] - truth) < 4.0 * fit[f"{key}_std"], (key, fit[key], truth)
    assert fit["c"] == pytest.approx(rig.conductance, rel=2e-3)
