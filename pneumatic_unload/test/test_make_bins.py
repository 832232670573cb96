# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The binned likelihood's edges (:func:`pneumatic_unload.fit.likelihood.make_bins`),
computed with the widths at once, are those of the rule stated bin by bin."""

from __future__ import annotations

import numpy as np
import pytest

from pneumatic_unload.fit.likelihood import make_bins


def _rule(t, t_open, resolution, max_bins_linear):
    """The rule one bin at a time: a bin starting (or, before the opening, ending) at
    sample k is int(min(max(1, resolution d / dt), n // max_bins_linear)) samples wide, d
    the distance of sample k (before the opening: of sample k - 1) from the opening."""
    n = t.size
    dt = float(np.median(np.diff(t[:100_001]))) if n > 1 else 1.0
    wmax = max(1, n // max_bins_linear)
    k_open = int(np.clip(np.searchsorted(t, t_open), 0, n))
    edges, k = [k_open], k_open
    while k > 0:
        k = max(0, k - int(min(max(1, resolution * (t_open - float(t[k - 1])) / dt), wmax)))
        edges.append(k)
    edges.reverse()
    k = k_open
    while k < n:
        k = min(n, k + int(min(max(1, resolution * (float(t[k]) - t_open) / dt), wmax)))
        edges.append(k)
    out = np.unique(np.asarray(edges, dtype=np.int64))
    return out if out[0] == 0 else np.concatenate(([0], out))


@pytest.mark.parametrize("seed", range(4))
def test_edges_follow_the_rule_on_regular_and_irregular_stamps(seed):
    rng = np.random.default_rng(seed)
    for _ in range(150):
        n = int(rng.choice([1, 2, 5, 40, 301, 2000, 9000]))
        kind = rng.integers(0, 3)
        t = (np.arange(n) * 1e-4 + 1.7e9 if kind == 0 else
             np.cumsum(rng.exponential(1e-3, n)) if kind == 1 else
             np.sort(rng.uniform(0.0, 10.0, n)))
        t_open = float(rng.choice([t[0], t[-1], t[0] - 1.0, t[-1] + 1.0,
                                   rng.uniform(t[0], t[-1]) if n > 1 else t[0]]))
        res = float(rng.choice([0.01, 0.03, 0.5]))
        mbl = int(rng.choice([1, 30, 300]))
        np.testing.assert_array_equal(make_bins(t, t_open, resolution=res,
                                                max_bins_linear=mbl),
                                      _rule(t, t_open, res, mbl))
