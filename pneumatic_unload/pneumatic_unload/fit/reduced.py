# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A record reduced to bins while it streams, and the fit's bins made from them at its end.

A streaming estimator cannot keep every sample of an unload of any length for its final
fit. :class:`Reducer` turns the samples, as they come, into *micro-bins*
(:class:`~pneumatic_unload.fit.likelihood.BinStats`): one sample each up to the valve
opening, then ``MICRO_FACTOR`` times narrower than the bins of
:func:`~pneumatic_unload.fit.likelihood.make_bins` (resolution / MICRO_FACTOR of the
distance from the opening) and at most k // (MICRO_FACTOR max_bins_linear) samples wide at
window sample k: a quarter of the widest bin make_bins cuts in any record of k samples or
more. At the end, :func:`merge_bins` groups them into the bins make_bins cuts in the whole
record, each edge moved to the nearest micro-bin edge (near the opening, where micro-bins
hold one sample, the bins are exactly make_bins's), and the likelihood is built from those
(:meth:`~pneumatic_unload.fit.likelihood.BinnedLikelihood.from_stats`).

Memory: about 1200 ln(N / 1200) micro-bins of 9 numbers (13 k, 1 MiB, for 50 M samples).
SI units: s (times relative to the record's first sample), Pa.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pneumatic_unload.fit.likelihood import (
    BinStats,
    FloatArray,
    IntArray,
    bin_stats,
)

#: Micro-bins per bin of make_bins (in width) [-].
MICRO_FACTOR = 4
#: make_bins's default ``max_bins_linear`` [-].
MAX_BINS_LINEAR = 300


def micro_edges(t: FloatArray, k0: int, *, t_open: float, k_open: int, dt: float,
                resolution: float, final: bool) -> IntArray:
    """Edges of the micro-bins of samples t [s] (window samples k0, k0 + 1, ...; k0 is a
    micro-bin edge), as indices into t: up to the end of the last complete micro-bin, or
    (``final``) to t.size. ``t_open`` [s] and ``k_open`` [-]: the valve opening and the
    first window sample at or after it; ``dt``: sample period [s]; ``resolution``: relative
    width of the fit's bins [-]."""
    n = t.size
    edges = [0]
    k = 0
    at = t.item
    res = resolution / MICRO_FACTOR
    div = MICRO_FACTOR * MAX_BINS_LINEAR
    while k < n:
        kw = k0 + k
        w = 1 if kw < k_open else int(min(max(1.0, res * (at(k) - t_open) / dt),
                                          max(1, kw // div)))
        if k + w > n:
            if final:
                edges.append(n)
            break
        k += w
        edges.append(k)
    return np.asarray(edges, dtype=np.int64)


def _nearest_edge(starts: IntArray, target: int, lo: int, hi: int) -> int:
    """Index j in [lo, hi] of the micro edge starts[j] nearest to sample ``target`` [-]."""
    j = int(np.clip(np.searchsorted(starts, target), lo, hi))
    if j > lo and target - starts[j - 1] < starts[j] - target:
        j -= 1
    return j


def merge_bins(micro: BinStats, *, t_open: float, k_open: int, dt: float,
               resolution: float) -> BinStats:
    """The bins :func:`~pneumatic_unload.fit.likelihood.make_bins` cuts in the record,
    from its micro-bins (times [s] relative to its first sample, ``k_open``: a micro edge,
    the first sample at or after the opening ``t_open`` [s]; ``dt`` [s]; ``resolution``
    [-]): the same sweeps, each edge moved to the nearest micro-bin edge."""
    cnt = np.asarray(micro.count, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(cnt)))
    m = cnt.size
    wmax = max(1, int(starts[-1]) // MAX_BINS_LINEAR)
    j_open = int(np.searchsorted(starts, k_open))
    cuts = [j_open]
    j = j_open
    while j < m:  # forwards, as make_bins
        w = int(min(max(1, resolution * (micro.t_first[j] - t_open) / dt), wmax))
        j = _nearest_edge(starts, int(starts[j]) + w, j + 1, m)
        cuts.append(j)
    j = j_open
    while j > 0:  # backwards over the pre-step
        w = int(min(max(1, resolution * (t_open - micro.t_last[j - 1]) / dt), wmax))
        j = _nearest_edge(starts, max(0, int(starts[j]) - w), 0, j - 1)
        cuts.append(j)
    g_edges = np.unique(np.asarray(cuts, dtype=np.int64))
    g = np.searchsorted(g_edges, np.arange(m), side="right") - 1
    j0, j1 = g_edges[:-1], g_edges[1:] - 1  # first and last micro-bin of each bin
    count = np.bincount(g, weights=cnt).astype(np.int64)
    nf = count.astype(float)
    mean = np.bincount(g, weights=cnt * micro.t_mean) / nf
    var = np.bincount(g, weights=cnt * (micro.t_var + (micro.t_mean - mean[g]) ** 2)) / nf
    # middle node: of the nodes of the micro-bin holding the bin's middle sample, the one
    # nearest to it strictly inside the bin (a bin of 3 samples or fewer has them all)
    s0, s1 = starts[j0], starts[j0] + count - 1
    mid = (s0 + s1) // 2
    jm = np.searchsorted(starts, mid, side="right") - 1
    a, b = starts[jm], starts[jm + 1] - 1
    cand_k = np.column_stack((a, (a + b) // 2, b))
    cand_t = np.column_stack((micro.t_first[jm], micro.t_mid[jm], micro.t_last[jm]))
    inside = (cand_k > s0[:, None]) & (cand_k < s1[:, None])
    dist = np.where(inside, np.abs(cand_k - mid[:, None]), np.iinfo(np.int64).max)
    pick = np.argmin(dist, axis=1)
    t_mid = np.where(count >= 3, cand_t[np.arange(count.size), pick], micro.t_first[j0])
    if not np.all(inside[np.arange(count.size), pick] | (count < 3)):
        raise ValueError("merge_bins: a bin without a middle node (micro-bins not nested)")
    return BinStats(count, np.bincount(g, weights=micro.y_sum), micro.y_first[j0],
                    micro.y_last[j1], micro.t_first[j0], t_mid, micro.t_last[j1], mean, var)


@dataclass
class Reducer:
    """The samples of one record reduced to micro-bins as they come (see the module).

    Parameters
    ----------
    t_ref : float
        Instant of the record's first sample [s] (times are kept relative to it).
    t_open : float
        Valve opening [s, relative].
    k_open : int
        First sample at or after the opening [-].
    dt : float
        Sample period (median of the first 100 000 intervals, as make_bins) [s].
    resolution : float
        Relative width of the fit's bins [-].
    """

    t_ref: float
    t_open: float
    k_open: int
    dt: float
    resolution: float
    parts: list[BinStats] = field(default_factory=list)
    #: Samples reduced so far [-] (the next sample's index in the record).
    done: int = 0

    def add(self, t: FloatArray, y: FloatArray, *, final: bool = False) -> int:
        """Reduce the samples t [s, absolute], y [Pa] that follow those already reduced:
        every complete micro-bin (``final``: all); returns the samples reduced [-]."""
        tr = np.asarray(t, dtype=float) - self.t_ref
        e = micro_edges(tr, self.done, t_open=self.t_open, k_open=self.k_open, dt=self.dt,
                        resolution=self.resolution, final=final)
        if e.size > 1:
            self.parts = [BinStats.concat([*self.parts, bin_stats(tr, np.asarray(
                y, dtype=float), e)])]
        used = int(e[-1])
        self.done += used
        return used

    def bins(self) -> BinStats:
        """The fit's bins of everything reduced (:func:`merge_bins`)."""
        micro = BinStats.concat(self.parts)
        return merge_bins(micro, t_open=self.t_open, k_open=self.k_open, dt=self.dt,
                          resolution=self.resolution)
