# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A step at the end of an unload's tail, after the record had settled: not the discharge.

A real bench's record may go on after the tank has emptied, and something other than the
discharge then moves the reading: a valve closed or switched, the transducer's supply or
range changed, the logger's channel re-zeroed. The AeroLab rig's two runs
(``../shared/real-data/aerolab``) sit level at +0.5 kPa gauge for 10 s, then step to
-2.4 kPa within 2 s and stay there to the record's end. A discharge cannot do that: once
its tail is level, the flow that moves the pressure has stopped. Fitted with the rest, that
step read as a transducer zero offset of -3.9 kPa (and moved C by 2 %).

:func:`settled_step` finds such a step in the last samples of a tail; the tail then ends
on the level before it (see :func:`~pneumatic_unload.estimation.tail.finish_tail`).
Values in the input's signal units, indices in samples.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.estimation.types import FloatArray

#: The key of ``UnloadResult.extra`` that says where and by how much the tail stepped (the
#: final status text carries it) [-].
TAIL_STEP = "tail_step"
#: Fewest samples of the level before the step [-] (the record had settled).
STEP_LEVEL = 5
#: Fewest samples after the step, its transition excluded [-].
STEP_AFTER = 2
#: Most samples the step's transition may take [-].
STEP_GAP = 3
#: Least size of the step, in the levels' noise [-] (a discharge's tail, level over
#: STEP_LEVEL samples, moves by about its noise over STEP_LEVEL + STEP_GAP more).
STEP_NOISES = 20.0
#: The level must hold within this many of its noise deviations [-].
STEP_FLAT = 5.0
#: The step is looked for among the tail's last this many samples [-].
STEP_BACK = 256
#: Least share of the samples after the transition that sit on the new level [-] (a glitch
#: of one sample there does not hide the step).
STEP_HOLD = 0.75


def _noise(d: FloatArray, floor: float, level: float) -> float:
    """The noise deviation of two levels from their successive differences ``d`` [signal
    units]: their median absolute value scaled to a Gaussian's deviation, at least
    ``floor`` (see :func:`_near_noise`) and 1e-12 of the ``level`` (a noiseless one)."""
    sd = 1.4826 * float(np.median(np.abs(d))) / np.sqrt(2.0)
    return max(sd, floor, 1e-12 * abs(level))


def _near_noise(y: FloatArray, js: NDArray[np.int64], quantum: float) -> FloatArray:
    """For each index j of ``js``, the noise of the 2 STEP_LEVEL samples up to j from their
    second differences (a decay's slope cancels, its curvature over a sample is small), at
    least ``quantum`` [signal units]: a floor to the two levels' own noise, which a few
    samples may underrate by chance."""
    d2 = np.abs(np.diff(y, 2))
    k = 2 * STEP_LEVEL - 2  # the second differences within 2 STEP_LEVEL samples
    out = np.empty(js.size)
    full = js >= k + 1
    if full.any():
        out[full] = np.median(np.lib.stride_tricks.sliding_window_view(d2, k)[
            js[full] - k - 1], axis=1)
    for i in np.flatnonzero(~full):  # the record's first samples (a short record)
        out[i] = np.median(d2[: max(int(js[i]) - 1, 1)])
    return np.maximum(1.4826 * out / np.sqrt(6.0), quantum)


def _suffix_medians(y: FloatArray, starts: NDArray[np.int64]) -> FloatArray:
    """The median of ``y[start:]`` for each of ``starts`` (each before the last sample)
    [signal units]."""
    rows = np.where(np.arange(y.size)[None, :] >= starts[:, None], y[None, :], np.inf)
    rows.sort(axis=1)
    count = y.size - starts
    r = np.arange(starts.size)
    return 0.5 * (rows[r, (count - 1) // 2] + rows[r, count // 2])


def settled_step(y: FloatArray) -> tuple[int, float] | None:
    """(j, step): the index in ``y`` of the last sample before a step that follows a level
    and the step's size (the new level's median less the old's) [signal units], or None.

    ``y``: the last samples of a tail [signal units]. A step is found at index j where the
    STEP_LEVEL samples up to j are level (each within STEP_FLAT noise deviations of their
    median; the noise from :func:`_noise` of both levels, at least that of the 2 STEP_LEVEL
    samples up to j from their second differences), and the samples after a transition of
    at most STEP_GAP samples sit on another level more than STEP_NOISES deviations away
    (within STEP_FLAT deviations or a tenth of the step of their median): the first
    STEP_LEVEL of them all (the step is abrupt), and STEP_HOLD of them in all (at least
    STEP_AFTER). The latest such j among the last STEP_BACK samples is returned. A
    discharge never steps: where its tail is level over STEP_LEVEL samples, it moves by a
    few of its per-sample changes over the next STEP_GAP + STEP_LEVEL; where a slow one
    looks level over a few noisy samples, it reaches its end level gradually, not at once.
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n < STEP_LEVEL + STEP_AFTER + 1:
        return None
    lo = max(STEP_LEVEL - 1, n - STEP_BACK)
    d = np.abs(np.diff(y[max(lo - 2 * STEP_LEVEL + 1, 0):]))
    nz = d[d > 0.0]
    quantum = float(nz.min()) if nz.size else 0.0
    js = np.arange(n - 1 - STEP_AFTER, lo - 1, -1)
    floors = _near_noise(y, js, quantum)
    starts = js + 1 + np.minimum(STEP_GAP, n - 1 - js - STEP_AFTER)
    a_all = _suffix_medians(y, starts)
    b_all = np.median(np.lib.stride_tricks.sliding_window_view(y, STEP_LEVEL)[
        js - STEP_LEVEL + 1], axis=1)
    # the exact test below takes a noise of at least the floor: a step no larger than
    # STEP_NOISES floors is none (most of a settled tail's candidates, screened at once)
    for k in np.flatnonzero(np.abs(a_all - b_all) > STEP_NOISES * floors):
        j, a, b = int(js[k]), float(a_all[k]), float(b_all[k])
        w, level = y[j - STEP_LEVEL + 1: j + 1], y[int(starts[k]):]
        s = _noise(np.concatenate([np.diff(w), np.diff(level)]), float(floors[k]), b)
        if np.max(np.abs(w - b)) > STEP_FLAT * s:
            continue
        step = abs(a - b)
        if step <= STEP_NOISES * s:
            continue
        on = np.abs(level - a) <= max(STEP_FLAT * s, 0.1 * step)
        if on[:STEP_LEVEL].all() and np.count_nonzero(on) >= STEP_HOLD * level.size:
            return j, a - b
    return None
