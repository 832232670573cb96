# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The compiled p* crossing fit (``estimation/regression.c``) against references written here
with numpy: the quadratic regression's crossing, slope and delta-method sigma (np.polyfit
and np.linalg on the same window), the estimator's two-pass window (the first window, then
one symmetric in time about its estimate), the gap flag, and the degenerate windows."""

from __future__ import annotations

import math
from array import array

import numpy as np
import pytest

from pneumatic_unload.estimation.regression import crossing_fit, crossing_window


def _reference_fit(t: np.ndarray, p: np.ndarray, level: float) -> tuple[float, float, float]:
    """Crossing of a least-squares quadratic (np.polyfit in the centred time), the root
    nearest the centre, its sigma by the delta method with the residual variance."""
    tm = t.mean()
    x = t - tm
    coef = np.polyfit(x, p, 2)
    c2, c1, c0 = coef
    roots = np.roots([c2, c1, c0 - level])
    roots = roots[np.isreal(roots)].real
    xr = float(roots[np.argmin(np.abs(roots))])
    slope = c1 + 2.0 * c2 * xr
    a = np.column_stack([np.ones_like(x), x, x * x])
    s2 = float(np.sum((p - a @ coef[::-1]) ** 2)) / max(t.size - 3, 1)
    g = np.array([1.0, xr, xr * xr])
    var = s2 * g @ np.linalg.solve(a.T @ a, g)
    return tm + xr, math.sqrt(var) / abs(slope), float(slope)


@pytest.mark.parametrize("seed", range(40))
def test_crossing_fit_equals_a_polyfit_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 3000))
    dt = float(rng.uniform(1e-4, 1.0))
    t = float(rng.uniform(-1e4, 1e6)) + dt * np.arange(n) \
        + (rng.uniform(-0.3, 0.3, n) * dt if seed % 2 else 0.0)
    tc = float(t[n // 2]) + float(rng.uniform(-0.2, 0.2)) * dt * n
    slope = -float(rng.uniform(1e2, 1e7))
    curv = float(rng.uniform(-0.3, 0.3)) * abs(slope) / (dt * n)
    level = float(rng.uniform(2e5, 6e5))
    p = level + slope * (t - tc) + curv * (t - tc) ** 2 \
        + rng.normal(0.0, float(rng.uniform(0.0, 3.0)) * abs(slope) * dt, n)
    got = crossing_fit(t, p, level)
    want = _reference_fit(t, p, level)
    span = float(t[-1] - t[0])
    assert got[0] == pytest.approx(want[0], abs=1e-9 * span + 1e-9 * abs(want[0]) * 1e-6)
    assert got[1] == pytest.approx(want[1], rel=1e-6, abs=1e-12 * span)
    assert got[2] == pytest.approx(want[2], rel=1e-7)


def test_degenerate_windows_give_no_crossing() -> None:
    t = np.arange(10.0)
    assert np.isnan(crossing_fit(t, np.full(10, 5.0), 4.0)[0])  # flat: no slope
    assert crossing_fit(t[:0], t[:0], 1.0)[1] == math.inf  # empty
    assert np.isnan(crossing_fit(np.full(6, 3.0), np.arange(6.0), 2.0)[0])  # no duration
    two = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])  # two distinct instants: no quadratic
    assert np.isnan(crossing_fit(two, 5.0 - two, 4.5)[0])
    assert crossing_fit(t, 10.0 - t, 4.5) == pytest.approx((5.5, 0.0, -1.0), abs=1e-12)
    with pytest.raises(ValueError, match="differ in length"):
        crossing_fit(t, t[:5], 1.0)


def _reference_window(t: np.ndarray, p: np.ndarray, i0: int, n: int, upper: float,
                      fallback: int, level: float, gap_limit: float
                      ) -> tuple[float, float, float, bool, int]:
    """The window and the two passes as the estimator wrote them in numpy before they
    were compiled (the window's start from a scan of the whole unload)."""
    tv, pv = t[:n], p[:n]
    hit = np.flatnonzero(pv[i0:n] > upper)
    lo = max(i0 + int(hit[-1]) if hit.size else -1, i0)
    if n - lo < 5:
        lo = max(fallback, n - 5)
        lo = max(lo + n, 0) if lo < 0 else lo  # as a slice's start
    tw = tv[lo:n]
    t_cross, t_std, slope = crossing_fit(tw, pv[lo:n], level)
    h = float(tv[n - 1]) - t_cross
    if h > 0:
        k0 = int(np.searchsorted(tv, t_cross - h))
        if n - k0 >= 5:
            t_cross, t_std, slope = crossing_fit(tv[k0:n], pv[k0:n], level)
    gap = bool(np.any(np.diff(tw) > gap_limit)) if tw.size > 1 else False
    return t_cross, t_std, slope, gap, lo


@pytest.mark.parametrize("seed", range(40))
def test_crossing_window_is_the_two_pass_fit_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    total = int(rng.integers(20, 4000))
    dt = 1e-3
    t = 5.0 + dt * np.arange(total)
    if seed % 3 == 0:  # a gap in the window
        t[total // 2:] += 0.05
    p = 4e5 * np.exp(-(t - 5.0) / (dt * total * 0.5)) + rng.normal(0, 500.0, total)
    n = int(rng.integers(10, total + 1))
    i0 = int(rng.integers(0, n - 5))
    level = float(p[(i0 + n) // 2])
    # an upper level inside the window, above every sample (no window: the fallback), or
    # just above the last samples (a window of fewer than 5)
    upper = (level + abs(float(rng.normal(0, 3e3))), float(p.max()) + 1.0,
             float(p[n - 3:n].max()) - 1e-9)[seed % 3]
    fallback = (-3, 0, int(rng.integers(-n - 5, n)))[seed % 3 if seed % 2 else 2]
    got = crossing_window(array("d", t), array("d", p), i0, n, upper, fallback, level, 0.01)
    want = _reference_window(t, p, i0, n, upper, fallback, level, 0.01)
    assert got[3:] == want[3:]
    assert got[:3] == want[:3] or (math.isnan(got[0]) and math.isnan(want[0]))


def test_crossing_window_refuses_a_window_outside_the_samples() -> None:
    t = array("d", [0.0, 1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="outside"):
        crossing_window(t, t, 2, 9, 1.0, 0, 1.0, 1.0)
    with pytest.raises(ValueError, match="outside"):
        crossing_window(t, t, 3, 3, 1.0, 0, 1.0, 1.0)
