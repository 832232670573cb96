# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Memory bounded whatever the length of one unload: its old samples reduced to bins.

The final curve fit of an unload needs its samples from the pre-step plateau to the end of
its tail; the decisions need only the last few tens of thousands. Once an unload's fit window
holds more than :data:`REDUCE_FROM` samples in the buffer, all but the last
:data:`KEEP_RAW` of them are reduced to micro-bins (:class:`~pneumatic_unload.fit.reduced.
Reducer`) and dropped from the buffer; the final fit then runs on the bins
(:func:`~pneumatic_unload.curvefit.fitting.fit_curve` with ``reduced``), whose cost and memory do
not grow with the unload. A shorter unload keeps every sample and is fitted exactly as before.

Before the p* crossing (p_atm given) the reduction stops once the pressure comes within
:data:`APPROACH` crossing half-widths of p*: the crossing fit needs the samples of its window
and as many before it (its symmetric second pass). With p_atm found from the final plateau
(``atmosphere`` None) the crossing is found only at the end: nothing is reduced before it.

Both the per-sample and the block path reduce at the same check indices (the block path's
scans stop there, see :func:`reduce_due`), and a micro-bin's sums depend on its samples
only, so both give bit-identical results. Values in signal units (the bins in Pa), indices in
buffer samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pneumatic_unload.curvefit.fitting import CURVE_FIT_RESOLUTION
from pneumatic_unload.estimation.decisions import PLATEAU, block_mean
from pneumatic_unload.estimation.state import UNLOADING, EstimatorState
from pneumatic_unload.estimation.types import FloatArray
from pneumatic_unload.fit.reduced import Reducer

#: Fit-window samples held in the buffer above which the older ones are reduced [-]
#: (32 B each in the buffer: 128 MiB).
REDUCE_FROM = 1 << 22
#: Newest samples always kept when reducing [-]: more than any decision looks back (the
#: abort's corner fit 6 x 8192, the final-plateau test 2 x 16384).
KEEP_RAW = 1 << 20
#: Most samples of one unload held while p_atm is to come from its final plateau
#: (``atmosphere`` None) [-]: the crossing can be found only then, so nothing is reduced
#: before it; 32 B each in the buffer: 256 MiB (14 min at 10 kHz). A longer unload without
#: a final plateau is closed with the reason (give the atmospheric pressure), see
#: :func:`~.unloading.step_unloading`.
AUTO_HOLD_MAX = 1 << 23
#: Crossing half-widths above p* below which nothing more is reduced before the crossing [-]
#: (an exponential fall takes longer from p* + 5 half to p* + half than through the window).
APPROACH = 5.0


def window_start(st: EstimatorState) -> int:
    """First buffer index of the current unload's fit window (the pre-step plateau's last
    2 PLATEAU samples) [-]; 0 once the window has been reduced (the buffer then starts at
    its first sample not reduced)."""
    if st.unload.reduced is not None:
        return 0
    return max(st.arm_index, st.unload.i0 - 2 * PLATEAU)


def reduce_due(st: EstimatorState, k: Any) -> Any:
    """At check index (or indices) k: the fit window holds more than REDUCE_FROM samples,
    and (before the crossing) the pressure's last PERIOD samples are still APPROACH
    half-widths above p* (never while p* is unknown)."""
    u = st.unload
    due = (k + 1 - window_start(st)) > REDUCE_FROM
    if st.mode == UNLOADING:
        # one index: the buffer itself (the same doubles, no view made)
        cs = st.buf.sums()[0] if isinstance(k, np.ndarray) else st.buf.cs
        due = due & (block_mean(cs, k) > u.pstar + APPROACH * u.half)
    return due


def reduce_unload(st: EstimatorState, k: int) -> int:
    """Reduce the fit window's samples up to KEEP_RAW before index k and drop them (with
    any sample before the window) from the buffer, shifting the indices held; returns the
    samples dropped [-] (index k is now k minus that)."""
    u = st.unload
    buf = st.buf
    start = window_start(st)
    tv, pv = buf.views(k + 1 - KEEP_RAW)
    if u.reduced is None:
        t_ref = float(tv[start])
        tr = tv[start:] - t_ref
        t_open = u.t0 - t_ref
        u.reduced = Reducer(t_ref=t_ref, t_open=t_open,
                            k_open=int(np.searchsorted(tr, t_open)),
                            dt=float(np.median(np.diff(tr[:100_001]))),
                            resolution=CURVE_FIT_RESOLUTION)
    drop = start + u.reduced.add(tv[start:], st.to_pa_array(pv[start:]))
    buf.trim(drop)
    st.next_check -= drop
    st.arm_index -= drop
    u.trigger -= drop
    u.i0 -= drop
    return drop


def fit_window(st: EstimatorState, i: int) -> tuple[FloatArray | None, FloatArray | None,
                                                       Reducer | None]:
    """The final fit's samples up to index i: (t [s], p [Pa], None) when held, or (None,
    None, reducer) with every sample up to i reduced."""
    tv, pv = st.buf.views(i + 1)
    red = st.unload.reduced
    if red is None:
        lo = window_start(st)
        return tv[lo:], st.to_pa_array(pv[lo:]), None
    red.add(tv, st.to_pa_array(pv), final=True)
    return None, None, red
