# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Samples missing from a live stream, counted from its stamps (estimation.loss)."""

from __future__ import annotations

import numpy as np
import pytest

from pneumatic_unload.estimation import LossCounter


def _stream(n: int, period_ns: int, drop: float, seed: int) -> tuple[np.ndarray, int]:
    """Stamps [ns] of n periods with jitter of 5 % of a period, a fraction ``drop`` of them
    removed after the first 100; returns the stamps kept and how many were removed."""
    rng = np.random.default_rng(seed)
    ns = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * period_ns
    ns += rng.integers(-period_ns // 20, period_ns // 20, n)
    keep = np.ones(n, dtype=bool)
    keep[100:] = rng.random(n - 100) >= drop
    return ns[keep], int(n - keep.sum())


@pytest.mark.parametrize("drop", [0.0, 0.001, 0.08, 0.3])
def test_missing_samples_counted_exactly_whatever_the_pieces(drop: float) -> None:
    ns, removed = _stream(50_000, 100_000, drop, seed=int(drop * 1000))  # 10 kHz
    whole = LossCounter()
    assert whole.update(ns) == removed == whole.missing
    assert whole.period == pytest.approx(1e-4, rel=0.02)
    pieces = LossCounter()
    rng = np.random.default_rng(1)
    cuts = np.sort(rng.choice(np.arange(1, ns.size), 300, replace=False))
    found = sum(pieces.update(part) for part in np.split(ns, cuts))
    found += sum(LossCounter().update(ns[:1]) for _ in range(1))  # a lone stamp: nothing
    assert found == removed and pieces.missing == removed
    assert pieces.received == ns.size
    assert pieces.fraction == pytest.approx(removed / (ns.size + removed))


def test_single_samples_and_steps_back_count_nothing_but_the_missing() -> None:
    c = LossCounter()
    ns = [int(1e9) + k * 1_000_000 for k in range(200)]  # 1 kHz
    for x in ns[:150]:
        c.update(x)
    assert c.missing == 0
    c.update(ns[150] - 5_000_000)  # a stamp 5 ms back: the estimator's business
    assert c.missing == 0
    c.update(ns[150])  # the time base goes on: nothing missing
    assert c.missing == 0
    c.update([ns[151], ns[160]])  # 8 samples missing
    assert c.missing == 8
    assert LossCounter().update([]) == 0
