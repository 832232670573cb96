"""The discrepancy search against the engine's whole heat-law family, the further-effect
bound rule and the model-limits term of the reported C (issue 12).

HydDown full16 (9 L, L/D 1.5) crosses Ra = 1e9 during the discharge, where HydDown's
Nusselt correlation changes branch: the one-parameter laws left C +2.9 % off; the natural
law with its turbulent branch scaled apart gives +1.0 % (``bench/bench_hyddown.py
--discrepancy``). Here the same shape is made by the package's own simulator (turbulent
branch 1.3 times the package's, as McAdams' 0.13 against 0.10), about 20 k samples.
"""

from __future__ import annotations

import math

import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.discrepancy import DiscrepancySettings
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.model import simulate

V, LD, C = 9e-3, 1.5, 2e-8


def _heat_fit(**heat):
    from pneumatic_unload.discrepancy.search import run_round

    cfg = RigConfig(volume=V, length_diameter_ratio=LD, conductance=C, critical_ratio=0.45,
                    initial_pressure=7e5, effects=("heat_transfer",), noise_std=1000.0,
                    rate=1000.0, pre_time=0.2, seed=3, **heat)
    sim = simulate(cfg)
    prob = Problem(sim.t, sim.measured, DiscrepancySettings(
        volume=V, length_diameter_ratio=LD, atmosphere=101325.0))
    neutral = [prob.neutral_theta(0.4)]
    base = prob.fit(prob.model(()), neutral)
    fits = run_round(prob, base, neutral, ["hot_start", "heat_transfer"])
    # the hot start extends heat transfer by the wall temperature alone: heat transfer's
    # law or a one-parameter one
    assert fits["hot_start"].model.heat_law in (fits["heat_transfer"].model.heat_law,
                                                "natural", "fixed")
    return fits["heat_transfer"]


def test_heat_transfer_is_fitted_with_the_law_the_record_carries():
    # both regimes of the correlation, the turbulent branch 1.3 times the package's: the
    # one-parameter natural law cannot follow it, the family's turbulent law can
    f = _heat_fit(heat_transfer_mode="natural", heat_transfer_turbulent_ratio=1.3)
    assert f.heat_law == "natural+turbulent"
    assert f.theta["heat_turbulent"] == pytest.approx(1.3, rel=0.05)
    assert f.theta["C"] == pytest.approx(C, rel=2e-3)
    # a constant hA: the density law (hA ~ rho^n, n = 0 here) must pay for its exponent
    f = _heat_fit(heat_transfer_mode="fixed", heat_transfer_coefficient=3.0)
    assert f.heat_law == "fixed"
    assert f.theta["C"] == pytest.approx(C, rel=2e-3)


class _Fit:
    """A fitted model as the bound rule sees it: effects, values, parameters with bounds."""

    def __init__(self, effects, values, bounds):
        from pneumatic_unload.fit.params import Parameter, Parameters

        self.effects = tuple(effects)
        self.theta = dict(values)
        self.result = type("R", (), {"params": Parameters([
            Parameter(k, v, *bounds[k], scale=0.1) for k, v in values.items()])})()


def test_a_further_effect_with_its_own_parameter_at_a_bound_is_refused():
    from pneumatic_unload.discrepancy.search import bound_refusals, decide

    bounds = {"C": (1e-9, 1e-7), "b": (0.01, 0.95), "ratio": (1e-5, 1.0),
              "leak_b": (0.02, 0.95)}
    # the effects named: C and b, b itself at its lower bound (not the candidate's)
    base = _Fit((), {"C": 1e-8, "b": 0.01}, bounds)
    at = _Fit(("orifice_leak",), {"C": 1e-8, "b": 0.01, "ratio": 0.1, "leak_b": 0.02},
              bounds)
    inside = _Fit(("orifice_leak",), {"C": 1e-8, "b": 0.01, "ratio": 0.1, "leak_b": 0.3},
                  bounds)
    delta = {"orifice_leak": 12.0}
    why = bound_refusals(base, {"orifice_leak": at}, delta, 10.0)
    assert list(why) == ["orifice_leak"] and "leak_b = 0.02" in why["orifice_leak"]
    assert bound_refusals(base, {"orifice_leak": inside}, delta, 10.0) == {}
    # below the threshold nothing is judged (it is not claimed anyway)
    assert bound_refusals(base, {"orifice_leak": at}, {"orifice_leak": 9.0}, 10.0) == {}
    # refused: the round names nothing
    base.bic = 100.0
    at.bic = 88.0
    assert decide(base, {"orifice_leak": at}, 10.0, why)[1] == "none"


def test_the_c_range_carries_the_budget_model_limits_term():
    from pneumatic_unload.budget import model_limits_term
    from pneumatic_unload.discrepancy.ambiguity import K_RANGE, conductance_ambiguity

    assert model_limits_term(2e-8, 0.003).std == pytest.approx(6e-11)
    assert model_limits_term(2e-8, 0.0).std == 0.0

    class Fit:
        def __init__(self):
            self.effects = ("heat_transfer",)
            self.theta = {"C": 1e-8}
            self.bic = 10.0

        def std(self, name):
            return 1e-11

    f = Fit()
    for u in (0.0, 0.003):
        amb = conductance_ambiguity(f, [], f, 10.0, model_uncertainty=u)
        s = math.hypot(1e-11, u * 1e-8)
        assert amb.high == pytest.approx(1e-8 + K_RANGE * s)
        assert not amb.ambiguous
    with pytest.raises(ValueError):
        DiscrepancySettings(volume=V, model_uncertainty=-0.1)
