"""Batch analysis of a whole trace, and one result per unload (SI units: s, Pa absolute)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.streaming import StreamingEstimator
from pneumatic_unload.estimation.types import UnloadResult


def analyze(
    t: ArrayLike, p: ArrayLike, settings: EstimatorSettings | None = None
) -> list[UnloadResult]:
    """Batch analysis of a trace: every unload found, in order.

    Parameters
    ----------
    t : array_like
        Sample instants [s], strictly increasing.
    p : array_like
        Pressure [Pa absolute] (or a linear signal with ``signal_gain``/``signal_offset``).
    settings : EstimatorSettings, optional
        Tank and detection settings.

    Returns
    -------
    list of UnloadResult
        Results as the streaming estimator emits them (crossing estimates, then the
        curve-fit refinement with ``final=True`` when the unload's end was recorded).

    Raises
    ------
    EstimationError
        Too few samples or mismatched arrays.
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(p, dtype=float)
    if t.shape != p.shape or t.ndim != 1:
        raise EstimationError(f"t and p must be 1-D arrays of equal length, got {t.shape} "
                              f"and {p.shape}")
    if t.size < 16:
        raise EstimationError(f"too few samples ({t.size}); need at least 16")
    est = StreamingEstimator(settings)
    out = est.push_block(t, p)
    out += est.finish()
    return out


def merge_final(results: list[UnloadResult]) -> list[UnloadResult]:
    """One result per unload: the final (curve-fit) one where it exists, else the first.

    Parameters
    ----------
    results : list of UnloadResult
        Results as emitted (crossing estimate, then final refinement).
    """
    by_index: dict[int, UnloadResult] = {}
    for r in results:
        if r.index not in by_index or r.final:
            by_index[r.index] = r
    return [by_index[k] for k in sorted(by_index)]
