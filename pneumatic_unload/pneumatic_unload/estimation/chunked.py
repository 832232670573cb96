# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Analysis of a record read in chunks, in memory bounded whatever its length.

:func:`analyze_chunks` feeds each chunk to one :class:`StreamingEstimator` (its block path
gives the same results however the record is cut, so the results equal those of
:func:`~pneumatic_unload.estimation.analyze` on the whole arrays) and keeps, besides the
results, only bounded summaries: the statistics of the gauge check (exact), and an
*overview* of the record for the explanation of a record without unload and for plots: every
sample while the record has at most ``overview_samples`` of them (so that both are exactly
what the whole arrays give), else every ``stride``-th sample (the stride doubles whenever
the overview fills up).

Memory: the chunk, the overview (at most 2 ``overview_samples`` x 16 B) and the estimator's
buffer, which holds an idle plateau's last ``IDLE_KEEP`` samples
(:data:`~pneumatic_unload.estimation.decisions.IDLE_KEEP`) and an unload's samples from its
plateau to the end of its tail (32 B per sample, plus the final curve fit's work arrays over
them) up to ``REDUCE_FROM`` of them: a longer unload's older samples are reduced to bins as
they come (:mod:`~pneumatic_unload.estimation.reduction`), except, before its p* crossing,
those from p* + 5 crossing half-widths on (the crossing fit's window), and all of them before
the crossing when p_atm is found from the final plateau (``atmosphere`` None).

SI units: s, Pa absolute (or the input's signal units with ``signal_gain``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.batch import explain_no_unload, gauge_evidence
from pneumatic_unload.estimation.sparse import analyze_from_start
from pneumatic_unload.estimation.two_way import stream_estimator
from pneumatic_unload.estimation.types import Diagnostic, FloatArray, UnloadResult

#: Samples kept in full for the explanation and plots [-] (a longer record is decimated).
OVERVIEW_SAMPLES = 1 << 21


class Overview:
    """Every ``stride``-th sample of a stream, at most 2 ``capacity`` of them; the stride
    doubles (keeping every other sample held) whenever more than ``capacity`` are held.

    Parameters
    ----------
    capacity : int
        Samples held after a halving [-].
    """

    def __init__(self, capacity: int = OVERVIEW_SAMPLES) -> None:
        self.capacity = max(1, int(capacity))
        self.stride = 1
        self.seen = 0
        self._t: list[FloatArray] = []
        self._p: list[FloatArray] = []
        self._held = 0

    def add(self, t: FloatArray, p: FloatArray) -> None:
        """Append a chunk of stamps [s] and values [signal units]."""
        off = (-self.seen) % self.stride
        self._t.append(np.array(t[off::self.stride]))
        self._p.append(np.array(p[off::self.stride]))
        self._held += self._t[-1].size
        self.seen += t.size
        while self._held > 2 * self.capacity:
            tt, pp = self.arrays()
            self._t, self._p = [tt[::2].copy()], [pp[::2].copy()]
            self._held = self._t[0].size
            self.stride *= 2

    def arrays(self) -> tuple[FloatArray, FloatArray]:
        """The samples held: stamps [s] and values [signal units]."""
        if len(self._t) != 1:
            self._t = [np.concatenate(self._t) if self._t else np.empty(0)]
            self._p = [np.concatenate(self._p) if self._p else np.empty(0)]
        return self._t[0], self._p[0]


@dataclass
class ChunkedAnalysis:
    """Results and bounded summaries of a record analysed in chunks.

    Attributes
    ----------
    published : list of UnloadResult
        Results as :func:`~pneumatic_unload.estimation.analyze` returns them.
    samples : int
        Samples fed [-].
    settings : EstimatorSettings
        The settings used.
    diagnostics : list of Diagnostic
        The estimator's diagnostics.
    overview : Overview
        The record, decimated beyond ``OVERVIEW_SAMPLES`` (see the module docstring).
    final_level : float
        Median of the last ``min_plateau`` finite readings [Pa].
    n_low, n_finite : int
        Finite readings at or below 0 Pa, and all finite readings [-].
    """

    published: list[UnloadResult]
    samples: int
    settings: EstimatorSettings
    diagnostics: list[Diagnostic] = field(default_factory=list)
    overview: Overview = field(default_factory=Overview)
    final_level: float = float("nan")
    n_low: int = 0
    n_finite: int = 0

    def gauge_suspicion(self) -> str | None:
        """:func:`~pneumatic_unload.estimation.gauge_suspicion` of the whole record."""
        return gauge_evidence(self.final_level, self.n_low, self.n_finite, self.settings)

    def explain_no_unload(self) -> str:
        """:func:`~pneumatic_unload.estimation.explain_no_unload` of the record (from the
        overview when it is decimated: its counts are then the overview's, as said)."""
        t, p = self.overview.arrays()
        why = explain_no_unload(t, p, self.settings, diagnostics=self.diagnostics,
                                stride=self.overview.stride)
        if self.overview.stride == 1 or why.startswith("no unload detected"):
            return why  # exact, or the estimator's own diagnostics on the whole record
        return (f"{why} [checked on every {self.overview.stride}th of the "
                f"{self.samples} samples]")


def analyze_chunks(chunks: Iterable[tuple[ArrayLike, ArrayLike]],
                   settings: EstimatorSettings | None = None, *,
                   overview_samples: int = OVERVIEW_SAMPLES,
                   temperature: tuple[ArrayLike, ArrayLike] | None = None) -> ChunkedAnalysis:
    """:func:`~pneumatic_unload.estimation.analyze` over a record given in chunks.

    Parameters
    ----------
    chunks : iterable of tuple of array_like
        Consecutive pieces of the record, each (t, p): sample instants [s] and pressures
        [Pa absolute] (or a signal converted by ``signal_gain``/``signal_offset``).
    settings : EstimatorSettings, optional
        Tank and detection settings.
    overview_samples : int
        Samples kept in full for the explanation and plots [-].
    temperature : tuple of array_like, optional
        The record's logged gas temperature, stamps [s] and values [K], fitted beside the
        pressure by the final fits (:meth:`StreamingEstimator.push_temperature`).

    Returns
    -------
    ChunkedAnalysis
        The results (equal to :func:`~pneumatic_unload.estimation.analyze` on the whole
        arrays) and the record's summaries.

    Raises
    ------
    EstimationError
        Mismatched arrays in a chunk, or fewer than 16 samples in all.
    """
    s = settings or EstimatorSettings()
    sparse = s.start_time is not None  # begins at the opening: small, analysed whole
    est = None if sparse else stream_estimator(s)
    if est is not None and temperature is not None:
        est.push_temperature(*temperature)
    run = ChunkedAnalysis(published=[], samples=0, settings=s,
                          overview=Overview(overview_samples))
    tail = np.empty(0)
    keep = s.min_plateau
    held: list[tuple[np.ndarray, np.ndarray]] = []
    for t_in, p_in in chunks:
        t = np.asarray(t_in, dtype=float)
        p = np.asarray(p_in, dtype=float)
        if t.shape != p.shape or t.ndim != 1:
            raise EstimationError(f"t and p must be 1-D arrays of equal length, got "
                                  f"{t.shape} and {p.shape}")
        if t.size == 0:
            continue
        if sparse:
            held.append((t, p))
        elif est is not None:
            run.published += est.push_block(t, p)
        run.overview.add(t, p)
        run.samples += t.size
        ok = np.isfinite(t) & np.isfinite(p)
        pp = s.signal_offset + s.signal_gain * p[ok]
        run.n_finite += pp.size
        run.n_low += int(np.count_nonzero(pp <= 0.0))
        tail = np.concatenate((tail, pp[-keep:]))[-keep:]
    if sparse:
        run.published = analyze_from_start(np.concatenate([h[0] for h in held] or [[]]),
                                           np.concatenate([h[1] for h in held] or [[]]), s,
                                           temperature=None if temperature is None else (
                                               np.asarray(temperature[0], dtype=float),
                                               np.asarray(temperature[1], dtype=float)))
        if tail.size:
            run.final_level = float(np.median(tail))
        return run
    if run.samples < 16 or est is None:
        raise EstimationError(f"too few samples ({run.samples}); need at least 16 (a record "
                              "that begins at the valve opening, without a plateau: pass "
                              "--start-time S and --atmosphere PA)")
    run.published += est.finish()
    run.diagnostics = est.diagnostics
    if tail.size:
        run.final_level = float(np.median(tail))
    return run
