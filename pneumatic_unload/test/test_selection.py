# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The one rule among candidate models: the criterion, its weights and the model average
(closed forms, and properties over random candidates)."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pneumatic_unload.selection.averaging import model_average
from pneumatic_unload.selection.evidence import information_criterion, weights


def test_the_criterion_is_chi2_plus_k_log_n():
    assert information_criterion(120.0, 3, 1000) == pytest.approx(120.0 + 3 * math.log(1000))
    assert math.isnan(information_criterion(math.inf, 3, 1000))
    with pytest.raises(ValueError, match="n >= 2"):
        information_criterion(1.0, 1, 1)
    with pytest.raises(ValueError, match="k >= 0"):
        information_criterion(1.0, -1, 10)


def test_weights_of_two_candidates_two_apart_in_the_criterion():
    """Delta 2: odds e^-1 (the evidence ratio of Kass and Raftery's table, 'positive')."""
    w = weights({"a": 100.0, "b": 102.0})
    assert w["b"] / w["a"] == pytest.approx(math.exp(-1.0), rel=1e-15)
    assert w["a"] + w["b"] == pytest.approx(1.0, rel=1e-15)


def test_weights_neither_overflow_nor_count_failed_fits():
    w = weights({"a": 1e6, "b": 1e6 + 3000.0, "failed": math.nan})
    assert w == {"a": 1.0, "b": 0.0, "failed": 0.0}
    with pytest.raises(ValueError, match="no candidate model has a finite"):
        weights({"x": math.nan})


def test_the_model_average_is_the_law_of_total_variance():
    """Two candidates of equal weight at 1 and 3 with variances 0.25 and 1: mean 2,
    within 0.625, between 1 (Hoeting et al.'s eq 1-2)."""
    avg = model_average({"a": 1.0, "b": 3.0}, {"a": 0.5, "b": 0.5}, {"a": 0.25, "b": 1.0})
    assert avg.mean == pytest.approx(2.0)
    assert avg.within == pytest.approx(0.625)
    assert avg.between == pytest.approx(1.0)
    assert avg.std == pytest.approx(math.sqrt(1.625))
    # about candidate a's value: sum w (x - 1)^2 = 0.5 * 4 = 2 = between + (2 - 1)^2
    assert avg.spread_about(1.0) == pytest.approx(math.sqrt(2.0))


def test_a_candidate_without_the_quantity_is_left_out_and_the_rest_renormalised():
    avg = model_average({"a": 1.0, "b": math.nan, "c": 2.0}, {"a": 0.25, "b": 0.5, "c": 0.25})
    assert dict(avg.weights) == {"a": 0.5, "c": 0.5}
    assert avg.mean == pytest.approx(1.5)
    assert avg.within == 0.0
    with pytest.raises(ValueError, match="no candidate model of positive weight"):
        model_average({"a": math.nan}, {"a": 1.0})


candidates = st.dictionaries(
    st.sampled_from("abcdefgh"),
    st.tuples(st.floats(-1e3, 1e3), st.floats(0.0, 60.0), st.floats(0.0, 10.0)),
    min_size=1)


@settings(max_examples=200, deadline=None)
@given(candidates)
def test_the_average_lies_among_the_candidates_and_its_spread_about_any_is_no_smaller(c):
    """For any candidates: the weights sum to 1, the mean lies within the values' range,
    within lies within the variances' range, and the spread about a candidate's value is
    at least the spread about the mean."""
    w = weights({k: v[1] for k, v in c.items()})
    assert sum(w.values()) == pytest.approx(1.0, rel=1e-12)
    avg = model_average({k: v[0] for k, v in c.items()}, w, {k: v[2] for k, v in c.items()})
    xs = [v[0] for k, v in c.items() if avg.weights.get(k, 0.0) > 0.0]
    us = [v[2] for k, v in c.items() if avg.weights.get(k, 0.0) > 0.0]
    tol = 1e-9 * (1.0 + max(abs(x) for x in xs))
    assert min(xs) - tol <= avg.mean <= max(xs) + tol
    assert min(us) - 1e-9 <= avg.within <= max(us) + 1e-9
    for x in xs:
        assert avg.spread_about(x) >= math.sqrt(avg.between) * (1.0 - 1e-12)
