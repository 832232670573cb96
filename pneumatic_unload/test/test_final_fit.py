# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The final fit as one estimator (estimation/final_fit.py): recovery of C, b and m from a
record the package did not make, the typed result, the rule's temperature, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from foreign.heat_laws import GAMMA, NOISE, R_AIR, RATE, PowerDifference, Rig, simulate

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.batch import analyze
from pneumatic_unload.estimation.final_fit import final_fit
from pneumatic_unload.model.candidates import Candidate, default_candidates

#: A 5 L tank through C 8e-9 from 6 bar, b 0.3, m 0.45, Newton cooling with the gas's
#: time constant 4 tau0 (PowerDifference with n = 1: a constant hA), in the foreign
#: generator's own energy balance, 1 kHz, 300 Pa of noise, the opening between samples.
RIG = Rig(5e-3, 8e-9, 0.30, 0.45, 6e5)
T_OPEN = 0.4003


def _record() -> tuple[np.ndarray, np.ndarray]:
    m0cv = RIG.p10 * RIG.volume / (R_AIR * RIG.t10) * R_AIR / (GAMMA - 1.0)
    law = PowerDifference(1.0, m0cv / (4.0 * RIG.tau0))
    t = np.arange(0.0, T_OPEN + 7.0 * RIG.tau0, 1.0 / RATE)
    p = np.full(t.size, RIG.p10)
    after = t >= T_OPEN
    p[after], _temp, _w = simulate(RIG, law, t[after] - T_OPEN)
    return t, p + np.random.default_rng(52).normal(0.0, NOISE, t.size)


def _settings() -> EstimatorSettings:
    return EstimatorSettings(volume=RIG.volume, initial_temperature=RIG.t10,
                             atmosphere=RIG.p_atm)


@pytest.fixture(scope="module")
def fitted():
    t, p = _record()
    cross = next(r for r in analyze(t, p, _settings()) if not r.final)
    return final_fit(t, p, _settings(), t_start=cross.t_start, p10=cross.p10,
                     p_atm=cross.end_pressure, conductance=cross.conductance_model)


def test_a_newton_cooling_discharge_is_recovered_within_its_sigma(fitted):
    c, b, m = fitted.conductance, fitted.critical_ratio, fitted.subsonic_index
    assert b is not None and m is not None
    assert abs(c.mean / RIG.conductance - 1.0) < 0.005
    assert abs(c.mean - RIG.conductance) < 3.0 * c.std
    assert abs(b.mean - RIG.b) < max(3.0 * b.std, 0.01)
    assert abs(m.mean - RIG.m) < max(3.0 * m.std, 0.02)
    # the constant hA is the generator's law: the criterion prefers it (with m fitted)
    assert fitted.best.candidate == Candidate("fixed", True)


def test_the_result_is_typed_and_its_weights_are_the_rule(fitted):
    names = {c.candidate.name for c in fitted.candidates} | set(fitted.failed)
    assert names == {c.name for c in default_candidates()}
    assert sum(c.weight for c in fitted.candidates) == pytest.approx(1.0, rel=1e-12)
    low = min(c.criterion for c in fitted.candidates)
    for c in fitted.candidates:
        ratio = c.weight / fitted.best.weight
        assert ratio == pytest.approx(
            math.exp(-0.5 * (c.criterion - low) / fitted.temperature), rel=1e-9, abs=1e-300)
    # T: the samples per discharge time constant, f V / (gamma p_N C)
    assert fitted.temperature == pytest.approx(
        RATE * RIG.volume / (GAMMA * 1e5 * RIG.conductance), rel=0.01)
    # m's average is over the candidates that fit m
    assert set(fitted.subsonic_index.weights) <= {c.candidate.name for c in
                                                  fitted.candidates if c.candidate.fit_m}
    assert fitted.conductance.variance == pytest.approx(
        fitted.conductance.within + fitted.conductance.between)


def test_bad_input_gets_a_clear_error():
    t, p = _record()
    s = _settings()
    kw = {"t_start": T_OPEN, "p10": RIG.p10, "p_atm": RIG.p_atm, "conductance": 8e-9}
    with pytest.raises(ValueError, match="at least 8 samples"):
        final_fit(t[:5], p[:5], s, **kw)
    with pytest.raises(ValueError, match="matching"):
        final_fit(t, p[:-1], s, **kw)
    with pytest.raises(ValueError, match="temperature must be at least 1"):
        final_fit(t, p, s, temperature=0.5, **kw)
    with pytest.raises(ValueError, match="heat model 'natural'"):
        final_fit(t, p, EstimatorSettings(volume=RIG.volume, heat_model="adiabatic"), **kw)
    with pytest.raises(ValueError, match="unknown heat law 'radiative'"):
        Candidate("radiative")
