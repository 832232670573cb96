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
