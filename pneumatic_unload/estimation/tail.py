"""Tail phase: after the crossing, wait for the final plateau (or a new charge), then close
the unload with the full-curve fit. Values in signal units, times in s, indices in buffer
samples."""

from __future__ import annotations

import numpy as np

from pneumatic_unload.estimation.decisions import (
    PERIOD,
    PLATEAU,
    block_mean,
    check_indices,
    flat,
    rise_threshold,
    rose,
    running_low,
)
from pneumatic_unload.estimation.refine import final_curve_fit
from pneumatic_unload.estimation.state import EstimatorState
from pneumatic_unload.estimation.types import UnloadResult


def _flat_tail(st: EstimatorState, cs: np.ndarray, k: int | np.ndarray, tau: float
               ) -> np.bool_ | np.ndarray:
    """:func:`~.decisions.flat` with the current unload's start, p10 and noise."""
    u = st.unload
    return flat(cs, k, i0=u.i0, tau=tau, dt_nominal=st.dt_nominal, p10=u.p10,
                sigma=st.sigma)


def step_tail(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Periodic tail check at index i: a new charge ends the tail two periods back (before
    the rise began, see :func:`~.decisions.rose`); a settled plateau ends it here."""
    if i != st.next_check:
        return []
    st.next_check = i + PERIOD
    u = st.unload
    res = u.pending
    cs = st.buf.cs
    m = block_mean(cs, i)
    rising = rose(m, u.tail_low, rise_threshold(st.sigma, u.p10, u.atm))
    if m < u.tail_low:
        u.tail_low = m
    if rising:
        # the tank is being charged again: the tail ended before the rise; re-arm now
        st.diag("ok", "pressure rising again after the unload: tail ended, re-armed",
                float(st.buf.t[i]))
        out = finish_tail(st, max(i - 2 * PERIOD, u.i0 + 1), ended=False, decided=i)
        st.next_check = i + PERIOD
        return out
    if res is not None and _flat_tail(st, np.frombuffer(cs, dtype=float), i, res.tau_exp):
        return finish_tail(st, i, ended=False)
    return []


def scan_tail(st: EstimatorState, i: int, end: int) -> int:
    """Next index in [i, end) where :func:`step_tail` decides something (end: none); the
    running lowest block mean of the checks before it is applied here."""
    ks = check_indices(st.next_check, end)
    if ks.size == 0:
        return end
    u = st.unload
    cs, _cq = st.buf.sums()
    m = block_mean(cs, ks)
    low_prev = running_low(u.tail_low, m)
    event = rose(m, low_prev, rise_threshold(st.sigma, u.p10, u.atm))
    if u.pending is not None:
        event |= _flat_tail(st, cs, ks, u.pending.tau_exp)
    hit = np.flatnonzero(event)
    k = int(hit[0]) if hit.size else ks.size
    if k > 0:
        u.tail_low = float(min(low_prev[k - 1], m[k - 1]))
        st.next_check = int(ks[k - 1]) + PERIOD
    return int(ks[k]) if k < ks.size else end


def finish_tail(st: EstimatorState, i: int, ended: bool, decided: int | None = None
                ) -> list[UnloadResult]:
    """Close the unload at index i (last sample of its tail): the final curve-fit result
    when enabled; ``decided``: the index at which that was decided (default i);
    ``ended``: the stream ended (informative)."""
    dec = i if decided is None else decided
    u = st.unload
    res = u.pending
    u.pending = None
    out: list[UnloadResult] = []
    if res is not None:
        res.t_end = float(st.buf.t[i])
        s = st.settings
        if s.curve_fit:
            tv, pv = st.buf.views(i + 1)
            lo = max(st.arm_index, u.i0 - 2 * PLATEAU)
            fin = final_curve_fit(res, tv[lo:i + 1], st.to_pa_array(pv[lo:i + 1]), s,
                                  noise_std=abs(st.sigma * s.signal_gain))
            if fin is not None:
                fin.i_complete, fin.t_complete = dec + st.buf.shift, float(st.buf.t[dec])
                out.append(fin)
    st.to_waiting(i + 1)
    return out
