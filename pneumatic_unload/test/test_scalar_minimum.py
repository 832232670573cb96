# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The one-variable minimiser (fit.scalar): closed-form minima, the grid's bracket."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from pneumatic_unload.fit.scalar import golden_section, interval_minimum


@settings(max_examples=60, deadline=None)
@given(st.floats(-5.0, 5.0), st.floats(0.1, 10.0))
def test_golden_section_finds_a_parabola_vertex(x0: float, width: float) -> None:
    """(x - x0)^2 on a bracket around x0: the vertex within the tolerance."""
    x = golden_section(lambda v: (v - x0) ** 2, x0 - width, x0 + 0.7 * width, tol=1e-6)
    assert abs(x - x0) < 1e-6


def test_golden_section_ends_on_the_bound_of_a_monotone_function() -> None:
    assert golden_section(lambda v: v, 2.0, 3.0, tol=1e-8) < 2.0 + 1e-8


def test_interval_minimum_takes_the_deeper_of_two_wells() -> None:
    """Two minima, the deeper one far from the bracket's golden points: the grid finds it
    where a golden search alone from [a, b] falls into the shallow one."""
    def f(v: float) -> float:
        return -2.0 * math.exp(-((v - 1.0) / 0.3) ** 2) - math.exp(-((v - 6.0) / 0.5) ** 2)

    assert abs(golden_section(f, 0.0, 10.0, tol=1e-6) - 1.0) > 1.0
    assert abs(interval_minimum(f, 0.0, 10.0, points=41, tol=1e-6) - 1.0) < 1e-5
