# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Aborted unload and SSE (eq 23): closing instant, pressure recovery, SSE result.

When the valve closes before p*, the closing instant comes from a corner fit, the abort is
reported at once, and the isochoric re-heating that follows is fitted as it grows; its
plateau p1_inf (recorded or extrapolated) gives the SSE value of eq 23 under the same
unload index. Values in signal units unless stated, times in s, indices in buffer samples.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pneumatic_unload import physics
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation.decisions import (
    LAG,
    PERIOD,
    PLATEAU,
    block_mean,
    check_indices,
    recovery_due,
    stall_window,
)
from pneumatic_unload.estimation.refine import model_inversion, recovery_fit
from pneumatic_unload.estimation.regression import corner_fit
from pneumatic_unload.estimation.state import RECOVERY, SKIP, EstimatorState
from pneumatic_unload.estimation.types import STUCK_TEXT, UnloadResult
from pneumatic_unload.model.heat import thermal_time_constant

#: Relative 1-sigma of eq 23 itself [-]: it assumes an isentropic unload (wall heat flow
#: during the unload shifts it by up to ~0.5 %) and writes p_N for rho_N R T_N (0.28 %).
SSE_MODEL_REL_STD = 0.01
#: Most samples a recovery is followed for after the closing [-] (the buffer holds them, 32 B
#: each: 128 MiB; 7 min at 10 kHz, 70 min at 1 kHz, several thermal time constants of any
#: tank this package is meant for). A re-heating still not settled then is closed as at the
#: end of a stream (its SSE extrapolated when the fit allows), so that memory stays bounded
#: whatever the record.
RECOVERY_MAX = 1 << 22


def on_abort(st: EstimatorState, i: int) -> list[UnloadResult]:
    """The unload stalled above p* at index i: find the closing instant, report the abort
    and wait for the recovery (or report a stuck sensor)."""
    u = st.unload
    tv, pv = st.buf.views(i + 1)
    tail = pv[max(u.i0, i - 2 * PERIOD + 1):i + 1]
    if tail.size >= 2 * PERIOD and float(np.ptp(tail)) == 0.0:
        return st.bad(i, f"{STUCK_TEXT} {float(tail[0])!r} during the unload "
                         f"({tail.size} identical samples, no noise): no estimate")
    st.diag("warn", "unload stopped before p*: valve closed (aborted unload)", float(tv[i]))
    # closing instant: a corner fit (quadratic before and after the closing instant)
    # on a wide window, then again on a window local to the first estimate
    span = i - u.i0
    w = int(stall_window(span))
    lo = max(u.i0 + 1, i - 6 * w)
    t_c, p_c, _rms = corner_fit(tv[lo:i + 1], pv[lo:i + 1], float(tv[lo + 8]),
                                float(tv[i - 8]))
    j = int(np.searchsorted(tv, t_c))
    half = max(64, (j - u.i0) // 5)
    lo2, hi2 = max(u.i0 + 1, j - half, 0), min(i + 1, j + half)  # 0: see .reduction
    if hi2 - lo2 >= 24:
        t_c, p_c, _rms = corner_fit(tv[lo2:hi2], pv[lo2:hi2], float(tv[lo2 + 4]),
                                    float(tv[hi2 - 5]))
    u.t_close, u.p_close = t_c, p_c
    u.i_close = min(int(np.searchsorted(tv, u.t_close)), i)
    u.rec_span = 0
    u.rec_high = -math.inf
    u.rec_fit = None
    st.mode = RECOVERY
    st.level = -math.inf
    st.next_check = i + PERIOD
    # report the abort at once (a live node must not stay silent through a recovery
    # that may take minutes); the SSE result follows under the same index, final=True
    t_star = u.t_close - u.t0
    res = st.empty_result(
        "aborted", f"valve closed {t_star:.4f} s after the start, before p*: aborted "
        "unload; waiting for the pressure recovery (SSE, eq 23)", i, count=False)
    if u.refined:
        res.p10, res.t_start = st.to_pa(u.p10), u.t0
        res.i_start = u.i0 + st.buf.shift
    return [res]


def fit_recovery_to(st: EstimatorState, i: int) -> Any:
    """Fit the recovery from the closing instant to index i (None when it fails); a
    successful call records the fit and its span."""
    u = st.unload
    tv, pv = st.buf.views(i + 1)
    j = u.i_close
    fit = recovery_fit(tv[j:i + 1], pv[j:i + 1], u.t_close)
    if fit is None:
        return None
    u.rec_fit, u.rec_span = fit, i - j
    return fit


def expected_recovery_time(st: EstimatorState) -> float:
    """Initial thermal time constant m c_v / (h A) of the closed tank [s], with h from
    the natural-convection law of :mod:`pneumatic_unload.model.heat` (scale 1) at the
    closing state (the recovery is not declared over before three of these, however flat
    it looks: a slow re-heating is indistinguishable from a plateau over a short record)."""
    s, u = st.settings, st.unload
    gas = s.gas
    p10 = st.to_pa(u.p10)
    p_c = st.to_pa(u.p_close)
    t10 = s.initial_temperature
    ratio = max(p_c / p10, 1e-3) if p10 > 0 else 1.0
    t_gas = t10 * ratio ** ((gas.gamma - 1.0) / gas.gamma)
    tank = RigConfig(volume=s.volume, length_diameter_ratio=s.length_diameter_ratio,
                     initial_temperature=t10, wall_temperature=s.wall_temperature,
                     gas_constant=gas.gas_constant, gamma=gas.gamma,
                     atmosphere=101325.0, effects=("heat_transfer",))
    return thermal_time_constant(tank, p_c, t_gas)


def recovery_significant(fit: Any, sigma: float) -> bool:
    """True when the fitted re-heating rise is clearly above the noise sigma [signal
    units]."""
    if fit is None or not fit.success or not math.isfinite(fit.p_inf_std):
        return False
    seen = fit.rise - fit.remaining  # rise observed so far [signal units]
    return bool(abs(seen) > 8.0 * sigma / math.sqrt(max(fit.n / 4, 1)))


def recovery_events(st: EstimatorState, k: Any, high: Any) -> tuple[Any, Any, Any]:
    """(fell, charged, m) at check index (or indices) k of the recovery [-]: the block mean
    m [signal units] fell more than a rise threshold below the highest earlier one
    ``high`` (the valve is open again: a re-heating never falls; e.g. a stall taken for a
    closing), or rose more than two above p10 (the tank is being charged again: a
    re-heating stays below p10). Either ends the recovery without an SSE value, so that a
    cycling rig is never followed as one endless recovery."""
    u = st.unload
    m = block_mean(st.buf.sums()[0], k)
    dp = u.dp_guess if math.isfinite(u.dp_guess) else 0.0
    thr = max(10.0 * st.sigma / math.sqrt(PERIOD), 0.02 * dp)
    fell = m < high - thr
    charged = (m > u.p10 + 2.0 * thr) if u.refined else np.zeros_like(fell)
    return fell, charged, m


def recharged_at(st: EstimatorState, i: int) -> int:
    """First index [-] after the closing where the block mean is back at p10 (within the
    recovery's rise threshold, :func:`recovery_events`), up to index i; -1 when it never
    is. An isochoric re-heating stays below p10 (gas has left the tank): a pressure back
    at p10 is a tank charged again (a rig restarted mid-unload), and a fall from there is
    a new unload from that plateau."""
    u = st.unload
    if not u.refined:
        return -1
    first = u.i_close + PERIOD - 1
    if i < first:
        return -1
    cs = st.buf.sums()[0]
    ks = np.arange(first, i + 1)
    dp = u.dp_guess if math.isfinite(u.dp_guess) else 0.0
    thr = max(10.0 * st.sigma / math.sqrt(PERIOD), 0.02 * dp)
    back = np.flatnonzero(block_mean(cs, ks) >= u.p10 - thr)
    return int(ks[back[0]]) - PERIOD + 1 if back.size else -1


def interrupt_recovery(st: EstimatorState, i: int, fell: bool) -> list[UnloadResult]:
    """End the recovery at index i [-] without an SSE value: the pressure fell again
    (``fell``: skip the rest of that unload, unless it fell from a plateau back at p10,
    :func:`recharged_at`: the tank was charged again, the fall is the next unload, re-arm
    on that plateau) or the tank is being charged (re-arm)."""
    u = st.unload
    back = recharged_at(st, i) if fell else -1
    if back >= 0 and i - back - LAG >= st.settings.min_plateau:
        why = ("the pressure rose back to p10 (the tank charged again: a rig restarted "
               "mid-unload?) and fell again")
        text = f"valve closed before p*; {why}: no SSE value; the fall is the next unload"
        st.diag("warn", text, float(st.buf.t[i]))
        st.mode = SKIP  # abort_result: no recovery fit over the interrupted record
        res = abort_result(st, i, recovered=False, text=text)
        res.final = True
        # the plateau from where the pressure was back at p10: the waiting phase's next
        # check (the next index) finds the fall below it and starts the next unload
        st.to_waiting(back)
        st.next_check = i + 1
        return [res]
    why = ("the pressure fell again (valve open again, or the stall was no closing)"
           if fell else "the tank is being charged again")
    text = f"valve closed before p*; {why} during the recovery: no SSE value"
    st.diag("warn", text, float(st.buf.t[i]))
    st.mode = SKIP  # abort_result: no recovery fit over the interrupted record
    res = abort_result(st, i, recovered=False, text=text)
    res.final = True
    if fell:
        st.to_skip(i)
    else:
        st.to_waiting(max(i - 2 * PERIOD, u.i_close) + 1)
        st.next_check = i + PERIOD
    return [res]


def step_recovery(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Periodic recovery check: refit as the record grows (each 25 % longer); the
    recovery is over when the fitted remaining rise is below 5 % of the total (the
    fit extrapolates the rest), p1_inf is known to 2 % of the rise, and the record
    covers 3 expected and 4 fitted thermal time constants."""
    if i != st.next_check:
        return []
    st.next_check = i + PERIOD
    u = st.unload
    fell, charged, m = recovery_events(st, i, u.rec_high)
    u.rec_high = max(u.rec_high, float(m))
    if fell or charged:
        return interrupt_recovery(st, i, bool(fell))
    if i - u.i_close >= RECOVERY_MAX:
        return _recovery_too_long(st, i)
    if not recovery_due(i, u.i_close, u.rec_span):
        return []
    span = i - u.i_close
    fit = fit_recovery_to(st, i)
    dt = st.dt
    if fit is None:
        if span * dt > max(20.0 * (u.t_close - u.t0), 2.0) and span >= 4 * PLATEAU:
            # a recovery no fit describes must not be followed for ever (the buffer grows)
            st.mode = SKIP  # abort_result: no further recovery fit
            return _end_without_sse(st, i, "valve closed before p*; the pressure after the "
                                           "closing fits no recovery: no SSE value")
        return []
    if (recovery_significant(fit, st.sigma) and fit.remaining <= 0.05 * fit.rise
            and fit.p_inf_std < 0.02 * fit.rise
            and span * dt >= 3.0 * expected_recovery_time(st)
            and span * dt >= 4.0 * fit.tau):
        res = abort_result(st, i, recovered=True)
        res.final = True
        st.to_waiting(i + 1)
        return [res]
    t_star = u.t_close - u.t0
    if not recovery_significant(fit, st.sigma) and span * dt > max(20.0 * t_star, 2.0) \
            and span >= 4 * PLATEAU:
        return _end_without_sse(st, i, "valve closed before p*; no pressure recovery after "
                                       "closing (no re-heating seen), so no SSE value")
    return []


def _recovery_too_long(st: EstimatorState, i: int) -> list[UnloadResult]:
    """The recovery has lasted RECOVERY_MAX samples at index i: close the aborted unload as
    at the end of a stream (SSE extrapolated when the fit allows, see
    :func:`abort_result`), with the reason, and wait for the next unload."""
    u = st.unload
    secs = float(st.buf.t[i]) - u.t_close
    text = (f"valve closed before p*; the recovery was followed for {RECOVERY_MAX} samples "
            f"({secs:.1f} s, the memory bound) without settling")
    st.diag("warn", text, float(st.buf.t[i]))
    res = abort_result(st, i, recovered=False, text=text)
    if text not in res.status_text:  # an extrapolated SSE value: say why it was taken
        res.status_text += "; " + text[len("valve closed before p*; "):]
    res.final = True
    st.to_waiting(i + 1)
    return [res]


def _end_without_sse(st: EstimatorState, i: int, text: str) -> list[UnloadResult]:
    """Close an aborted unload at index i with its final result and no SSE value
    (``text``: why), and wait for the next unload."""
    res = abort_result(st, i, recovered=False, text=text)
    res.final = True
    st.to_waiting(i + 1)
    return [res]


def scan_recovery(st: EstimatorState, i: int, end: int) -> int:
    """Next index in [i, end) where :func:`step_recovery` refits (end: none)."""
    ks = check_indices(st.next_check, end)
    if ks.size == 0:
        return end
    u = st.unload
    m = block_mean(st.buf.sums()[0], ks)
    high_prev = np.maximum.accumulate(np.concatenate(([u.rec_high], m)))[:-1]
    fell, charged, _m = recovery_events(st, ks, high_prev)
    hit = np.flatnonzero(recovery_due(ks, u.i_close, u.rec_span) | fell | charged
                         | (ks - u.i_close >= RECOVERY_MAX))
    k = int(hit[0]) if hit.size else ks.size
    if k > 0:
        u.rec_high = float(max(high_prev[k - 1], m[k - 1]))
        st.next_check = int(ks[k - 1]) + PERIOD
    return int(ks[k]) if k < ks.size else end


def sse_pressure_problem(p10: float, p1_inf: float) -> str:
    """Why eq 23 gives no C for the initial pressure p10 and the recovered pressure p1_inf
    [Pa absolute] whatever their uncertainty, or '' when it may: both must be absolute
    pressures (> 0; a fractional power of a negative ratio is complex). Without a given
    p_atm nothing checks the pressures before the recovery: gauge readings, or a signal
    without ``signal_gain``/``signal_offset``, get this far. (p1_inf >= p10, C <= 0, is
    the caller's: an extrapolated p1_inf may land there, an uncertain fit.)"""
    if not (p10 > 0.0 and p1_inf > 0.0):
        return (f"pressures not absolute Pa (p10 = {p10:.6g} Pa, p1_inf = {p1_inf:.6g} Pa; "
                f"eq 23 needs p10 > p1_inf > 0): gauge readings or a signal without "
                f"signal_gain/signal_offset?")
    return ""


def abort_result(st: EstimatorState, i: int, recovered: bool, text: str = "") -> UnloadResult:
    """Result of an aborted unload at index i; with ``recovered`` (or a recovery fit good
    enough to extrapolate at the end of the stream), the SSE value of eq 23."""
    s, u = st.settings, st.unload
    res = st.empty_result("aborted", text or "valve closed before p*; no recovery "
                          "plateau recorded (SSE needs it)", i)
    if not u.refined:
        return res
    p10 = st.to_pa(u.p10)
    res.p10, res.t_start = p10, u.t0
    res.i_start = u.i0 + st.buf.shift
    if st.mode != RECOVERY:
        return res
    if s.charge:  # eq 23 is the discharge's: its isochoric re-heating after a closing
        res.status_text += "; no SSE value for a charge (eq 23 is a discharge's)"
        return res
    fit = u.rec_fit
    if not recovered and i - u.i_close >= 16 and i - u.i_close != u.rec_span:
        fit = fit_recovery_to(st, i)
    if not recovery_significant(fit, st.sigma):
        return res
    gain = abs(s.signal_gain)
    p_inf = st.to_pa(fit.p_inf)
    p_inf_std = gain * fit.p_inf_std
    p_close = st.to_pa(u.p_close)
    t_star = u.t_close - u.t0
    t_star_std = u.t0_std
    gas, t10, vol = s.gas, s.initial_temperature, s.volume
    why = sse_pressure_problem(p10, p_inf)
    if why:
        res.status_text += f"; no SSE value: {why}"
        return res
    c = physics.conductance_sse(t_star, p10, p_inf, vol, t10, gas)
    c_hi = physics.conductance_sse(t_star, p10, p_inf + p_inf_std, vol, t10, gas)
    # p1_inf one sigma higher: at or above p10 (C <= 0 there) the SSE sigma is at least C
    dc_dp = c_hi - c if p_inf + p_inf_std < p10 else math.inf
    c_std = math.hypot(dc_dp, c * t_star_std / t_star, c * SSE_MODEL_REL_STD)
    if not (math.isfinite(c) and c > 0 and c_std < 0.25 * c):
        reach = ""
        if p_inf >= p10:  # an extrapolation beyond p10: C <= 0
            reach = f", not below p10 = {p10:.0f} Pa"
        elif math.isinf(dc_dp):
            reach = f", its 1-sigma band reaching p10 = {p10:.0f} Pa"
        res.status_text += (f"; recovery fit too uncertain for SSE (p_inf = {p_inf:.0f} "
                            f"+- {p_inf_std:.0f} Pa{reach})")
        return res
    done = 1.0 - fit.remaining / fit.rise
    how = ("recovery plateau" if recovered else
           f"recovery extrapolated from {100 * done:.0f} % of the re-heating")
    res.status = "aborted_sse"
    res.status_text = (f"valve closed after {t_star:.4f} s before p*; SSE (eq 23) from "
                       f"the {how}, p1_inf = {p_inf:.0f} +- {p_inf_std:.0f} Pa")
    res.conductance = c
    # model-based: the discharge model inverted at the closing instant and pressure
    c_isen = physics.conductance_isentropic_inversion(t_star, p_close, p10, vol, t10, gas)
    atm = s.atmosphere if s.atmosphere is not None else 101325.0
    c_model, c_model_std, method = model_inversion(s, t_star, t_star_std, p10, atm, p_close,
                                                   c_isen)
    res.conductance_model = c_model
    res.conductance_model_std = c_model_std
    res.conductance_isentropic = c_isen
    res.quality = 0.7 if recovered else 0.5
    res.method = "sse-eq23;" + method.replace("eq39+", "") + "-at-closing"
    res.extra = {"t_star": t_star, "t_close": u.t_close, "p1_inf": p_inf,
                 "p1_inf_std": p_inf_std, "p_close": p_close, "sse_std": c_std,
                 "recovered_fraction": done, "recovery_tau": fit.tau,
                 "recovery_exponent": fit.exponent}
    return res
