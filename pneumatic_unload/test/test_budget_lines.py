# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The GUM budget of the final C, line by line: every input's line is there with its
closed-form sensitivity, and the combined uncertainty is their root sum of squares.

A dropped line must fail a test of its own (the mutation check of the issue "Tests that can
fail for the reason they are named": with the model-limits line dropped, only a coverage
test over six HydDown cases failed).
"""

from __future__ import annotations

import math

import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.config.estimator import MODEL_UNCERTAINTY
from pneumatic_unload.estimation import analyze
from pneumatic_unload.model import simulate
from pneumatic_unload.uncertainty.budget import PRESSURE_REL_DEFAULT, VOLUME_REL_DEFAULT


@pytest.fixture(scope="module")
def final():
    """The final result of a heat-transfer discharge analysed with default uncertainties."""
    cfg = RigConfig(volume=2e-3, conductance=8e-9, initial_pressure=6e5, pre_time=0.5,
                    duration=6.0, effects=("heat_transfer",), seed=31)
    sim = simulate(cfg)
    s = settings_for(cfg)
    (r,) = [x for x in analyze(sim.t, sim.measured, s) if x.final]
    return r, s


def _line(budget: dict, start: str) -> dict:
    (term,) = [t for t in budget["terms"] if t["name"].startswith(start)]
    return term


def test_every_input_has_its_line_with_its_sensitivity(final):
    r, s = final
    b = r.extra["budget"]
    c = r.conductance_model
    assert b["value"] == c
    # C ~ V (the volume scales the time base): the line is C u(V)/V
    assert _line(b, "volume V")["std"] == pytest.approx(c * VOLUME_REL_DEFAULT, rel=1e-9)
    # C ~ sqrt(T10): half the relative temperature uncertainty
    t = _line(b, "initial temperature T10")
    assert t["std"] == pytest.approx(0.5 * c * t["input_std"] / s.initial_temperature,
                                     rel=1e-9)
    p = _line(b, "pressure transducer")
    assert p["input_std"] == pytest.approx(PRESSURE_REL_DEFAULT * r.p10, rel=1e-6)
    assert 0.0 <= p["std"] < 0.01 * c
    assert _line(b, "model limits")["std"] == pytest.approx(MODEL_UNCERTAINTY * c, rel=1e-9)
    assert _line(b, "wall temperature")["std"] >= 0.0
    record = [t for t in b["terms"] if t["kind"] == "A"]
    assert len(record) == 1 and record[0]["std"] > 0.0


def test_the_combined_uncertainty_is_the_root_sum_of_squares_of_the_lines(final):
    r, _s = final
    b = r.extra["budget"]
    rss = math.sqrt(sum(t["std"] ** 2 for t in b["terms"]))
    assert b["combined_std"] == pytest.approx(rss, rel=1e-12)
    assert r.conductance_model_std == pytest.approx(rss, rel=1e-12)
    assert b["expanded"] == pytest.approx(2.0 * rss, rel=1e-12)


def test_a_hot_start_claimed_in_an_inadequate_fit_has_the_best_law_without_it_as_a_line():
    """heat_law_offer.hot_start_terms, closed forms: the line is |C_alt - C|/sqrt(3) with
    C_alt the lowest-BIC law without a wall, where its chi^2 exceeds the claim's by no more
    than the structure the claim leaves (chi^2 (1 - 1/structure); the numbers of a foreign
    record's fit); none where the fit is adequate (structure 1), where a real warm gas leaves
    the laws without it far behind (50 x the chi^2 at structure 1.37),
    where no hot start is claimed, where a log was used, or where the reading lacks b."""
    from types import SimpleNamespace

    from pneumatic_unload.curvefit.heat_law_offer import hot_start_terms

    laws = {"fixed+wall|m": {"conductance": 0.915, "critical_ratio": 0.115, "bic": 545.7,
                             "chi2": 450.4},
            "density|m": {"conductance": 1.0001, "critical_ratio": 0.136, "bic": 726.2,
                          "chi2": 631.0},
            "fixed|m": {"conductance": 1.0006, "critical_ratio": 0.146, "bic": 739.2,
                        "chi2": 657.5},
            "natural": {"conductance": 1.023, "critical_ratio": math.nan, "bic": 1.8e6,
                        "chi2": 1.8e6}}

    def fit(**kw):
        base = dict(heat_law="fixed+wall", laws=laws, gas_temperature={"t10": 339.9},
                    conductance=0.915, critical_ratio=0.115)
        return SimpleNamespace(**{**base, **kw})

    (c_line,) = hot_start_terms(fit(), 2.98)
    assert c_line.std == pytest.approx((1.0001 - 0.915) / math.sqrt(3.0))
    assert "(density|m)" in c_line.note
    (b_line,) = hot_start_terms(fit(), 2.98, "b")
    assert b_line.std == pytest.approx((0.136 - 0.115) / math.sqrt(3.0))
    assert hot_start_terms(fit(), 1.0) == ()
    # 631 - 450.4 = 180.6 against 450.4 (1 - 1/S): at S 1.66 just in, at 1.65 out
    assert hot_start_terms(fit(), 1.67) != () and hot_start_terms(fit(), 1.65) == ()
    warm = {**laws, "density|m": {**laws["density|m"], "chi2": 50 * 450.4, "bic": 2.3e4},
            "fixed|m": {**laws["fixed|m"], "chi2": 50 * 450.4, "bic": 2.3e4}}
    assert hot_start_terms(fit(laws=warm), 1.37) == ()
    assert hot_start_terms(fit(heat_law="fixed"), 2.98) == ()
    assert hot_start_terms(fit(gas_temperature={"t10": 339.9, "rms": 0.4}), 2.98) == ()
    assert hot_start_terms(fit(critical_ratio=math.nan), 2.98, "b") == ()
    # a law within the model-form spread's window (AeroLab 0.094 in: density|m at chi^2 74
    # against the claim's 73) is in that spread already: no second line
    assert hot_start_terms(fit(), 2.98, spread_window=181.0) == ()
    assert hot_start_terms(fit(), 2.98, spread_window=10.0) != ()
