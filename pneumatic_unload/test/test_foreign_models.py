# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The model-based C on data the package did not make: an independent discharge model with
Newton cooling (constant hA) and the ISO flow law (``test/foreign/newton_tank.py``, which
imports nothing from the package's model).

Before the heat-law family (natural-convection scale only) the model C was 22 % low at a
thermal time constant of 0.5-2 s and 3-4 % at 4 s, with a sigma that excluded the truth.
With hA ~ rho^n in the same independent model (n 0.8, 0.5, 0.67; tau_h 1.5, 3, 10 s), the
family without the density law gave C +1.10 %, -0.43 %, +2.88 % (z 4.2), each through a
spurious hot start ('natural+wall'); with it: +0.05 %, -0.01 %, +0.01 %, n 0.790 +- 0.009,
0.499 +- 0.005, 0.674 +- 0.010 (and n = 0, a constant hA, keeps the 'fixed' law: the density
law 9.7 behind in BIC).
"""

import math

import numpy as np
import pytest
from foreign.newton_tank import discharge

from pneumatic_unload.curvefit.fitting import LAW_BIC_THRESHOLD
from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final


@pytest.mark.parametrize("tau_heat,volume,conductance,b,seed", [
    (0.5, 4e-3, 5e-9, 0.40, 1), (2.0, 2e-3, 4e-9, 0.30, 2), (4.0, 4e-3, 5e-9, 0.45, 3),
    (10.0, 8e-3, 1.2e-8, 0.35, 4), (20.0, 3e-3, 3e-9, 0.50, 5)])
def test_model_c_and_b_on_an_independent_newton_cooling_model(tau_heat, volume, conductance,
                                                              b, seed):
    p10, p_atm = 8e5, 101325.0
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    t = np.arange(0.0, 0.2 + 8.0 * tau0, 1e-3)
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=293.15,
                  p_atm=p_atm, tau_heat=tau_heat, t_open=0.2)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)  # 0.1 % of 1 MPa
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    assert r.final and math.isfinite(r.conductance_model)
    assert abs(r.conductance_model / conductance - 1.0) < 0.02
    assert abs(r.conductance_model - conductance) < 3.0 * r.conductance_model_std
    assert abs(r.critical_ratio - b) < 0.03  # the subsonic tail is recorded
    fit = r.extra["curve_fit"]
    assert fit["heat_law"] == "fixed" or fit["laws"]["fixed"]["bic"] - \
        fit["laws"][fit["heat_law"]]["bic"] < 10.0


@pytest.mark.parametrize("exponent,tau_heat,volume,conductance,seed", [
    (0.8, 1.5, 4e-3, 5e-9, 11), (0.5, 3.0, 6e-3, 8e-9, 12)])
def test_density_exponent_law_recovered_from_an_independent_model(exponent, tau_heat, volume,
                                                                  conductance, seed):
    """An hA ~ rho^n made by the independent model (not the package's kernel): the curve
    fit offers the density law and the data choose it, every other law more than
    LAW_BIC_THRESHOLD behind (measured: 5703 and 1669 behind; not a case the data leave
    open); n, tau_h and C come back within 3 sigma of the truth (measured z: n -1.0 and
    -0.2, tau_h -1.5 and +0.6, C +0.05 and -0.01) and C within 2 %."""
    p10, p_atm, b = 8e5, 101325.0, 0.4
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    t = np.arange(0.0, 0.2 + 8.0 * tau0, 1e-3)
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=293.15,
                  p_atm=p_atm, tau_heat=tau_heat, t_open=0.2, density_exponent=exponent)
    y = p + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    fit = r.extra["curve_fit"]
    assert "density" in fit["laws"], fit["not_offered"]
    assert fit["heat_law"] == "density", fit["laws"]
    bic = {law: v["bic"] for law, v in fit["laws"].items()}
    # every other heat law behind (the density law with m fitted is the same heat law)
    assert all(v - bic["density"] > LAW_BIC_THRESHOLD for law, v in bic.items()
               if law.removesuffix("|m") != "density"), bic
    assert not fit["subsonic_index_fitted"]  # m = 0.5 made: the criterion holds it
    n, n_std = fit["heat_exponent"], fit["heat_exponent_std"]
    assert 0.0 < n_std < 0.05 and abs(n - exponent) < 3.0 * n_std, (n, n_std)
    assert 0.0 < fit["tau_heat_std"] < 0.1 * tau_heat
    assert abs(fit["tau_heat"] - tau_heat) < 3.0 * fit["tau_heat_std"]
    assert abs(r.conductance_model / conductance - 1.0) < 0.02
    assert abs(r.conductance_model - conductance) < 3.0 * r.conductance_model_std


def test_laws_that_fit_about_as_well_enter_the_budget_as_its_model_form_line():
    """Laws within delta-BIC 10 of the chosen one whose C differ are never hidden: the
    budget's 'model form (heat laws)' line is their spread about the chosen C, each law
    weighted by exp(-delta-BIC / 2), recomputed here from the result's own table of laws
    (measured: constant hA chosen, +0.06 %; the density law 7.0 behind, -0.05 %: a line
    of 0.02 %; the natural laws, 2-3 % off, are hundreds behind and do not enter)."""
    volume, conductance, b, p10 = 7.08e-3, 8.76e-9, 0.448, 5.27e5
    tau0 = volume / (1.4 * 1e5 * conductance)  # eq 28 [s]
    t = np.arange(0.0, 0.2 + 8.0 * tau0, 1e-3)
    p = discharge(t, volume=volume, conductance=conductance, b=b, p10=p10, t10=293.15,
                  p_atm=101325.0, tau_heat=3.28, t_open=0.2)
    y = p + np.random.default_rng(6).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    fit, budget = r.extra["curve_fit"], r.extra["budget"]
    best = fit["laws"][fit["heat_law"]]
    near = [v for v in fit["laws"].values() if v["bic"] - best["bic"] < 10.0]
    assert len(near) >= 2, fit["laws"]
    w = [math.exp(-0.5 * (v["bic"] - best["bic"])) for v in near]
    spread = math.sqrt(sum(wi * (v["conductance"] - best["conductance"]) ** 2
                           for wi, v in zip(w, near, strict=True)) / sum(w))
    (line,) = [x for x in budget["terms"] if x["name"] == "model form (heat laws)"]
    assert spread > 1e-5 * conductance
    assert line["std"] == pytest.approx(spread, rel=1e-6)
    assert abs(r.conductance_model - conductance) < 2.0 * r.conductance_model_std
