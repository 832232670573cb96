# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One model, one engine: every path gives the same C (issue #10's consistency test).

Over seeded traces of several kinds (adiabatic, natural-convection heat transfer, a flow
that turns subsonic before p*, three gases), the crossing inversion, the final curve fit and
the discrepancy workflow's fit of the same effect set agree within their combined sigma and
each holds the truth within 3.5 of its own sigma; and ``discrepancy`` on clean
``simulate --effects heat_transfer`` runs names heat transfer alone with a C interval that
holds the truth (several seeds and tank sizes).
"""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.discrepancy import DiscrepancySettings, find_discrepancy
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.estimation import analyze
from pneumatic_unload.model import simulate
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS


def exact(settings):
    """The simulation's own tank and gas: inputs exactly known (no type B terms)."""
    return dataclasses.replace(settings, **EXACT_INPUTS)


GASES = {"air": (287.05, 1.4), "nitrogen": (296.8, 1.4), "co2": (188.92, 1.289),
         "helium": (2077.1, 1.66)}


def _case(kind: str, seed: int, gas: str) -> RigConfig:
    rng = np.random.default_rng(seed)
    r_gas, gamma = GASES[gas]
    # a similar discharge time for every gas: dp/dt scales with R
    c = math.exp(rng.uniform(math.log(5e-9), math.log(2e-8))) * 287.05 / r_gas
    p10 = rng.uniform(2.5e5, 3.2e5) if kind == "subsonic" else rng.uniform(5.5e5, 8e5)
    return RigConfig(volume=rng.uniform(1e-3, 5e-3), conductance=c,
                     critical_ratio=rng.uniform(0.3, 0.5), initial_pressure=p10,
                     effects=("heat_transfer",) if kind == "heat" else (),
                     gas_constant=r_gas, gamma=gamma, noise_std=500.0, seed=seed)


CASES = [(k, s, "air") for k in ("adiabatic", "heat", "subsonic") for s in (1, 2)] + [
    ("heat", 3, "nitrogen"), ("adiabatic", 4, "co2"), ("heat", 5, "helium")]


@pytest.mark.parametrize("kind,seed,gas", CASES)
def test_crossing_final_and_discrepancy_fits_agree(kind, seed, gas):
    cfg = _case(kind, seed, gas)
    sim = simulate(cfg)
    st = exact(settings_for(cfg))
    if kind != "heat":
        st = st.__class__(**{**st.tank_fields(), "heat_model": "adiabatic"})
    res = analyze(sim.t, sim.measured, st)
    cross = next(r for r in res if not r.final)
    final = next(r for r in res if r.final)
    prob = Problem(sim.t, sim.measured, DiscrepancySettings(**st.tank_fields()))
    effects = ("heat_transfer",) if kind == "heat" else ()
    fit = prob.fit(prob.model(effects), [prob.neutral_theta(0.3), prob.neutral_theta(0.5)])
    est = {"crossing": (cross.conductance_model, cross.conductance_model_std),
           "final": (final.conductance_model, final.conductance_model_std),
           "discrepancy": (fit.theta["C"], fit.std("C"))}
    for name, (c, sd) in est.items():
        assert math.isfinite(c) and sd > 0, name
        assert abs(c - cfg.conductance) < 3.5 * sd, (name, c / cfg.conductance - 1, sd)
    names = list(est)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            (ca, sa), (cb, sb) = est[a], est[b]
            assert abs(ca - cb) <= math.hypot(sa, sb), (a, b, (ca - cb) / math.hypot(sa, sb))


@pytest.mark.parametrize("volume,conductance,seed", [(2e-3, 5e-9, 0), (8e-3, 1e-8, 1),
                                                     (1e-3, 2e-9, 2)])
def test_discrepancy_names_heat_transfer_alone_on_simulated_heat_transfer(volume, conductance,
                                                                         seed):
    """Before the engine: heat transfer named, then sensor gain/offset or pipe volume added
    that were never simulated, with C 26-28 % off and intervals excluding the truth."""
    cfg = RigConfig(volume=volume, conductance=conductance, effects=("heat_transfer",),
                    seed=seed)
    sim = simulate(cfg)
    res = find_discrepancy(sim.t, sim.measured,
                           DiscrepancySettings(volume=volume, profile=False))
    assert res.effects == ["heat_transfer"] and res.ambiguous_with == []
    iv = res.parameters["C"]
    assert iv.low <= conductance <= iv.high
    assert abs(res.conductance / conductance - 1) < 3.0 * res.conductance_std() / conductance
    assert res.after.nrms < 1.02 and res.after.white
