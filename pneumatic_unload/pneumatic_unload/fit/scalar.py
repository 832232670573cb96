# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Minimisation of a function of one variable on an interval (numpy and math only).

The estimator's start-time searches and the thermometer's lag search use it; scipy's
``minimize_scalar`` did the latter and cost 0.35 s of import on every ``analyze`` of a
record with a temperature log.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

#: Golden-section ratio (sqrt(5) - 1) / 2 [-].
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def golden_section(f: Callable[[float], float], a: float, b: float, *, tol: float,
                   max_iter: int = 48) -> float:
    """Golden-section search for a minimum of f on [a, b] (units of the variable): the
    bracket shrinks by the golden ratio each step until it is shorter than ``tol`` or
    ``max_iter`` steps are done; returns the bracket's midpoint. f is taken unimodal on
    [a, b]: a caller with several minima brackets the right one first (a grid).
    """
    x1, x2 = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    f1, f2 = f(x1), f(x2)
    for _ in range(max_iter):
        if b - a < tol:
            break
        if f1 <= f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - GOLDEN * (b - a)
            f1 = f(x1)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + GOLDEN * (b - a)
            f2 = f(x2)
    return 0.5 * (a + b)


def interval_minimum(f: Callable[[float], float], a: float, b: float, *, points: int,
                     tol: float) -> float:
    """Minimise f on [a, b]: ``points`` evenly spaced values (ends included), then a
    golden-section search down to ``tol`` in the grid cells either side of the best."""
    grid = np.linspace(a, b, max(points, 2))
    k = int(np.argmin([f(float(x)) for x in grid]))
    return golden_section(f, float(grid[max(k - 1, 0)]), float(grid[min(k + 1, grid.size - 1)]),
                          tol=tol)
