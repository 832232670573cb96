# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The one likelihood of the package: adaptive bins, AR(1) prewhitening, model per bin.

A trace of N samples is cut into bins (:func:`make_bins`) that are narrow near the valve
opening and widen with the distance from it, so that their number grows with the logarithm
of the record length. The residual y - m is prewhitened under an AR(1) noise model
(e_k - rho e_(k-1) is white) and summed per bin; the normalised bin sums
z_b = S_b / (sigma_u sqrt(n_b)) are independent unit normal variables when the model is
right, and chi^2 = sum z_b^2 is -2 log-likelihood up to a constant.

The data's bin sums are computed once. The model's are computed from the model evaluated at
a few *quadrature nodes* per bin (its first, middle and last sample): the quadratic through
them is averaged exactly over the bin's sample instants (weights from the bin's moments of
t), which integrates cubics exactly for evenly spaced samples. Bins that contain a valve
event (a kink of the model) are evaluated at every one of their samples. So one evaluation
costs O(bins), not O(N): a 1 M-sample record costs what a 10 k one does.

SI units: s, Pa.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.noise import NoiseModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Bins of at most this many samples are evaluated at every sample [-].
EXACT_BIN = 3


def make_bins(t: FloatArray, t_open: float, *, resolution: float = 0.03,
              max_bins_linear: int = 300) -> IntArray:
    """Bin edges (sample indices) fine near the valve opening, coarse elsewhere.

    A bin at a distance d from the opening is about ``resolution`` d wide (at least one
    sample) and at most n / ``max_bins_linear`` samples wide, so the number of bins grows
    only with the logarithm of the record length.

    Parameters
    ----------
    t : ndarray
        Sample instants [s].
    t_open : float
        Valve opening instant [s].
    resolution : float
        Relative width of a bin [-].
    max_bins_linear : int
        Bins of the widest size that fit in the record [-].

    Returns
    -------
    ndarray
        Increasing edge indices from 0 to n.
    """
    n = t.size
    # the median sample period of the first 100 000 intervals (O(1) on long records)
    dt = float(np.median(np.diff(t[:100_001]))) if n > 1 else 1.0
    wmax = max(1, n // max_bins_linear)
    k_open = int(np.clip(np.searchsorted(t, t_open), 0, n))
    # the width at a sample, int(min(max(1, resolution d / dt), wmax)) at its distance d
    # from the opening, computed at once (the same doubles: one difference, product and
    # quotient; fmax/fmin keep max/min's answer on a NaN) over the samples nearer than
    # where the width is surely wmax (t increases: beyond, every bin is wmax wide, added
    # as a range); the edges are then followed from the opening
    span = (wmax + 1.0) * dt / resolution if resolution > 0 else math.inf
    with np.errstate(all="ignore"):
        k_hi = int(np.searchsorted(t, t_open + span, side="right")) + 1
        k_lo = max(int(np.searchsorted(t, t_open - span, side="left")) - 1, 0)
        fwd = np.fmin(np.fmax(1.0, resolution * (t[k_open:k_hi] - t_open) / dt),
                      wmax).astype(np.int64).item
        back = np.fmin(np.fmax(1.0, resolution * (t_open - t[k_lo:k_open]) / dt),
                       wmax).astype(np.int64).item
    m_fwd = max(min(k_hi, n) - k_open, 0)
    edges = [k_open]
    k = k_open
    while k > 0:  # backwards over the pre-step: the width at the sample before k
        if k - 1 < k_lo:
            edges.extend(range(k - wmax, 0, -wmax))
            edges.append(0)
            break
        k = max(0, k - back(k - 1 - k_lo))
        edges.append(k)
    edges.reverse()
    k = k_open
    while k < n:
        if k - k_open >= m_fwd:
            edges.extend(range(k + wmax, n, wmax))
            edges.append(n)
            break
        k = min(n, k + fwd(k - k_open))
        edges.append(k)
    out = np.unique(np.asarray(edges, dtype=np.int64))
    if out[0] != 0:
        out = np.concatenate(([0], out))
    return out


def uniform_bins(n: int, max_bins: int) -> IntArray:
    """Edges of at most ``max_bins`` bins of (nearly) equal sample counts [indices]."""
    m = max(1, min(n, max_bins))
    return np.unique(np.round(np.linspace(0, n, m + 1)).astype(np.int64))


@dataclass(frozen=True)
class BinStats:
    """What the binned likelihood needs of each bin of a trace (one element per bin, in time
    order; times relative to any origin [s], values [Pa]): a trace can be reduced to these
    while it streams (:mod:`pneumatic_unload.fit.reduced`) and fitted without its samples.

    Attributes
    ----------
    count : ndarray
        Samples [-].
    y_sum, y_first, y_last : ndarray
        Sum of the signal, its first and its last sample [Pa].
    t_first, t_mid, t_last : ndarray
        Instants of the first sample, of one near the middle and of the last [s] (the
        quadrature nodes; a bin of at most EXACT_BIN samples has all its samples there).
    t_mean, t_var : ndarray
        Mean [s] and variance [s^2] of the bin's sample instants.
    """

    count: IntArray
    y_sum: FloatArray
    y_first: FloatArray
    y_last: FloatArray
    t_first: FloatArray
    t_mid: FloatArray
    t_last: FloatArray
    t_mean: FloatArray
    t_var: FloatArray

    @property
    def n(self) -> int:
        """Samples [-]."""
        return int(np.sum(self.count))

    @staticmethod
    def concat(parts: Sequence[BinStats]) -> BinStats:
        """The bins of consecutive pieces of a trace, in order."""
        return BinStats(*(np.concatenate([getattr(p, f.name) for p in parts])
                          for f in fields(BinStats)))


def bin_stats(t: FloatArray, y: FloatArray, edges: IntArray) -> BinStats:
    """:class:`BinStats` of samples t [s], y [Pa] over bins with edges (strictly increasing
    sample indices from 0 to n; the middle node is sample (i0 + i1 - 1) // 2)."""
    e = np.asarray(edges, dtype=np.int64)
    t, y = t[e[0]:e[-1]], y[e[0]:e[-1]]
    e = e - e[0]
    i0, i1 = e[:-1], e[1:]
    cnt = i1 - i0
    tc = np.add.reduceat(t, i0) / cnt
    dev = t - np.repeat(tc, cnt)
    m2 = np.add.reduceat(dev * dev, i0) / cnt
    return BinStats(cnt, np.add.reduceat(y, i0), y[i0], y[i1 - 1], t[i0],
                    t[(i0 + i1 - 1) // 2], t[i1 - 1], tc, m2)


ModelAt = Callable[[FloatArray], FloatArray]


class BinnedLikelihood:
    """Prewhitened, binned Gaussian likelihood of a trace under an AR(1) noise model.

    Parameters
    ----------
    t, y : ndarray
        Sample instants [s] and measured signal [Pa].
    noise : NoiseModel
        AR(1) noise (sigma [Pa], rho [-]); sigma 1 gives unnormalised sums (for fits whose
        residual variance is estimated afterwards).
    edges : ndarray
        Bin edges (sample indices from 0 to n).
    """

    def __init__(self, t: FloatArray, y: FloatArray, noise: NoiseModel, edges: IntArray
                 ) -> None:
        self.t = np.asarray(t, dtype=float)
        self.y = np.asarray(y, dtype=float)
        self.noise = noise
        self.edges = np.asarray(edges, dtype=np.int64)
        self.counts = np.diff(self.edges).astype(float)
        self.rho = noise.rho
        self._first = math.sqrt(max(1.0 - self.rho**2, 1e-6))
        self._norm = noise.innovation_sigma * np.sqrt(self.counts)
        self._n = int(self.y.size)
        self._sy = self.binsum(self.whiten(self.y))
        self._setup_nodes()

    @classmethod
    def from_stats(cls, stats: BinStats, noise: NoiseModel) -> BinnedLikelihood:
        """The likelihood of a trace given by its bins' :class:`BinStats` (no sample held:
        the model is evaluated at the bins' nodes only, also in a wide bin holding a valve
        event; the sample-level methods are not available)."""
        self = cls.__new__(cls)
        self.t = self.y = None
        self.noise = noise
        cnt = np.asarray(stats.count, dtype=np.int64)
        self.edges = np.concatenate(([0], np.cumsum(cnt))).astype(np.int64)
        self.counts = cnt.astype(float)
        self._n = int(self.edges[-1])
        self.rho = noise.rho
        self._first = math.sqrt(max(1.0 - self.rho**2, 1e-6))
        self._norm = noise.innovation_sigma * np.sqrt(self.counts)
        y_sum = np.asarray(stats.y_sum, dtype=float)
        self._sy = self._whitened(y_sum, np.asarray(stats.y_first, dtype=float),
                                  np.asarray(stats.y_last, dtype=float))
        # nodes of each bin: its first, middle (3 samples or more) and last (2 or more)
        take = np.column_stack((np.ones(cnt.size, bool), cnt >= 3, cnt >= 2))
        node_t = np.column_stack((stats.t_first, stats.t_mid, stats.t_last))[take]
        per = take.sum(axis=1)
        self.node_index = None
        self.node_t = node_t
        self._pos_last = np.cumsum(per).astype(np.int64) - 1
        self._pos_first = self._pos_last - per + 1
        vals = np.ones((cnt.size, 3))
        wb = np.flatnonzero(cnt > EXACT_BIN)
        ta, tm, tb = stats.t_first[wb], stats.t_mid[wb], stats.t_last[wb]
        mu, var, nw = stats.t_mean[wb], stats.t_var[wb], cnt[wb].astype(float)
        vals[wb] = np.column_stack([(var + (mu - u) * (mu - v)) / ((tj - u) * (tj - v)) * nw
                                    for tj, u, v in ((ta, tm, tb), (tm, ta, tb),
                                                     (tb, ta, tm))])
        self._q_rows = np.repeat(np.arange(cnt.size, dtype=np.int64), per)
        self._q_cols = np.arange(node_t.size, dtype=np.int64)
        self._q_vals = vals[take]
        return self

    @property
    def n(self) -> int:
        """Samples in the trace [-]."""
        return self._n

    @property
    def n_bins(self) -> int:
        """Bins [-]."""
        return int(self.counts.size)

    # sample-level operations --------------------------------------------------------
    def whiten(self, x: FloatArray) -> FloatArray:
        """Prewhitened series x_k - rho x_(k-1) (first sample scaled) [unit of x]."""
        w = np.empty_like(x)
        w[0] = x[0] * self._first
        w[1:] = x[1:] - self.rho * x[:-1]
        return w

    def binsum(self, x: FloatArray) -> FloatArray:
        """Sums of a sample series over the bins [unit of x]."""
        return np.add.reduceat(x, self.edges[:-1])

    def residuals(self, model: FloatArray) -> FloatArray:
        """Normalised prewhitened bin sums of y - model, model given at every sample [-]."""
        return (self._sy - self.binsum(self.whiten(model))) / self._norm

    def sample_whitened(self, model: FloatArray) -> FloatArray:
        """Prewhitened full-rate residual divided by the innovation sigma [-]."""
        return self.whiten(self.y - model) / self.noise.innovation_sigma

    # quadrature ----------------------------------------------------------------------
    def _setup_nodes(self) -> None:
        """Quadrature nodes and weights of every bin (see the module docstring)."""
        e = self.edges
        i0, i1 = e[:-1], e[1:]
        cnt = i1 - i0
        wide = cnt > EXACT_BIN
        mid = (i0 + i1 - 1) // 2
        last = i1 - 1
        # node sample indices: every sample of narrow bins, first/middle/last of wide ones
        bin_of = np.repeat(np.arange(cnt.size), cnt)
        narrow_idx = np.flatnonzero(~wide[bin_of])
        nodes = np.unique(np.concatenate((narrow_idx, i0[wide], mid[wide], last[wide],
                                          i0, last)).astype(np.int64))
        self.node_index = nodes
        self.node_t = self.t[nodes]
        # weights: bin mean of the quadratic through (t_a, t_m, t_b), exact over the samples
        t = self.t
        tc = np.add.reduceat(t, i0) / cnt  # bin mean time
        dev = t - np.repeat(tc, cnt)
        m2 = np.add.reduceat(dev * dev, i0) / cnt  # bin variance of t
        wb = np.flatnonzero(wide)
        ta, tm, tb = t[i0[wb]], t[mid[wb]], t[last[wb]]
        mu, var, nw = tc[wb], m2[wb], cnt[wb].astype(float)
        # mean over samples of L_j(t) = (t - u)(t - v)/((tj - u)(tj - v)):
        # E[(t-u)(t-v)] = var + (mu - u)(mu - v)
        w = np.column_stack([(var + (mu - u) * (mu - v)) / ((tj - u) * (tj - v)) * nw
                             for tj, u, v in ((ta, tm, tb), (tm, ta, tb), (tb, ta, tm))])
        k_wide = np.column_stack((i0[wb], mid[wb], last[wb]))
        rows = np.concatenate((bin_of[narrow_idx], np.repeat(wb, 3)))
        cols = np.searchsorted(nodes, np.concatenate((narrow_idx, k_wide.ravel())))
        vals = np.concatenate((np.ones(narrow_idx.size), w.ravel()))
        order = np.argsort(rows, kind="stable")  # bin by bin, as the sums accumulate
        self._q_rows = rows[order].astype(np.int64)
        self._q_cols = cols[order].astype(np.int64)
        self._q_vals = vals[order]
        self._pos_first = np.searchsorted(nodes, i0).astype(np.int64)
        self._pos_last = np.searchsorted(nodes, last).astype(np.int64)

    def model_binsums(self, model_at: ModelAt, events: Sequence[float] = ()) -> FloatArray:
        """Prewhitened bin sums of a model given as a function of time [unit of model].

        Parameters
        ----------
        model_at : callable
            ``model_at(times)`` -> model values at increasing instants [s].
        events : sequence of float
            Instants where the model is not smooth [s]; bins containing one are evaluated
            at every sample.
        """
        t = self.t
        e = self.edges
        ev_bins: set[int] = set()
        if t is None:  # from BinStats: the nodes only
            mv = np.asarray(model_at(self.node_t), dtype=float)
            sums = np.bincount(self._q_rows, weights=self._q_vals * mv[self._q_cols],
                               minlength=self.n_bins)
            return self._whitened(sums, mv[self._pos_first], mv[self._pos_last])
        for ev in events:
            if t[0] < ev <= t[-1]:
                k = int(np.searchsorted(t, ev))  # first sample at or after ev
                b = int(np.searchsorted(e, k, side="right")) - 1
                for bb in (b - 1, b):  # the bin holding k and the one before (ev between)
                    if 0 <= bb < self.n_bins and self.counts[bb] > EXACT_BIN:
                        ev_bins.add(bb)
        if ev_bins:
            # the nodes with every sample of the event bins spliced in (sorted by
            # construction: no set operation over all the nodes at every evaluation)
            nodes = self.node_index
            parts, k = [], 0
            for b in sorted(ev_bins):
                lo, hi = np.searchsorted(nodes, (e[b], e[b + 1]))
                parts += [nodes[k:lo], np.arange(e[b], e[b + 1], dtype=nodes.dtype)]
                k = int(hi)
            parts.append(nodes[k:])
            idx = np.concatenate(parts)
        else:
            idx = self.node_index
        vals = np.asarray(model_at(t[idx]), dtype=float)
        if idx is self.node_index:
            mv = vals
        else:
            mv = vals[np.searchsorted(idx, self.node_index)]
        sums = np.bincount(self._q_rows, weights=self._q_vals * mv[self._q_cols],
                           minlength=self.n_bins)
        for b in ev_bins:
            j0, j1 = np.searchsorted(idx, [e[b], e[b + 1]])
            sums[b] = float(np.sum(vals[j0:j1]))
        return self._whitened(sums, mv[self._pos_first], mv[self._pos_last])

    def _whitened(self, sums: FloatArray, m_first: FloatArray, m_last: FloatArray
                  ) -> FloatArray:
        """Prewhitened bin sums from the plain bin sums of a series and its first and last
        value in each bin [unit of the series]."""
        if self.rho == 0.0 and self._first == 1.0:
            return sums
        prev_last = np.concatenate(([0.0], m_last[:-1]))
        lagged = sums - m_last + prev_last  # sum over the bin of m_(k-1)
        out = sums - self.rho * lagged
        out[0] = self._first * m_first[0] + (sums[0] - m_first[0]) \
            - self.rho * (sums[0] - m_last[0])
        return out

    def residuals_at(self, model_at: ModelAt, events: Sequence[float] = ()) -> FloatArray:
        """Normalised prewhitened bin residuals of a model given as a function of time [-].

        Parameters
        ----------
        model_at : callable
            ``model_at(times)`` -> model values at increasing instants [s].
        events : sequence of float
            Instants where the model is not smooth [s].
        """
        return (self._sy - self.model_binsums(model_at, events)) / self._norm
