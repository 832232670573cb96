"""Unloading phase: the start (hinge) fit, the stall test, p_atm auto and the p* crossing.

Values in signal units unless stated, times in s, indices in buffer samples.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from pneumatic_unload.estimation import follow, reduction
from pneumatic_unload.estimation.crossing import crossing_estimate, plan_crossing
from pneumatic_unload.estimation.decisions import (
    CONFIRM,
    HINGE_PLATEAU,
    PERIOD,
    STUCK_RUN,
    below,
    check_indices,
    first_below,
    flat,
    flat_window,
    settled_at_end,
    stalled,
)
from pneumatic_unload.estimation.reduction import reduce_due, reduce_unload, window_start
from pneumatic_unload.estimation.refine import end_level_problem, needs_model
from pneumatic_unload.estimation.regression import (
    correlated_noise_factor,
    crossing_window,
    curvature_sigma,
    first_below_in,
    hinge_cov,
    hinge_fit,
    rms_sigma,
    sloped_hinge_fit,
    variance_inflation,
)
from pneumatic_unload.estimation.sse import abort_result, on_abort
from pneumatic_unload.estimation.state import TAIL, EstimatorState, tau_sigma
from pneumatic_unload.estimation.tail import finish_tail
from pneumatic_unload.estimation.types import (
    STUCK_TEXT,
    FloatArray,
    UnloadResult,
    end_fields,
)


def start_unloading(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Confirmed step at index i: p_atm from the settings (or later from the final
    plateau); the start is refined once the drop reaches 10 % of the pressure change."""
    s, u = st.settings, st.unload
    p_plateau = st.plateau_level
    p_atm = s.end_pressure  # a charge's: the supply
    atm_signal = math.nan
    if p_atm is not None:
        atm_signal = (p_atm - s.signal_offset) / s.signal_gain
    u.atm = atm_signal
    guess_atm = (atm_signal if p_atm is not None
                 else (101325.0 - s.signal_offset) / s.signal_gain)
    dp = p_plateau - guess_atm
    u.dp_guess = abs(dp) if math.isfinite(dp) else abs(p_plateau) * 0.5
    u.noisy = st.sigma > 0.0
    if p_atm is not None and (dp <= 0 if s.charge  # mirrored: the signal falls to it
                              else dp * math.copysign(1.0, s.signal_gain) <= 0):
        if s.charge:
            return st.bad(i, f"the supply ({p_atm:.0f} Pa) is not above p10 "
                             f"({st.to_pa(p_plateau):.0f} Pa): nothing to charge")
        return st.bad(i, f"p10 ({st.to_pa(p_plateau):.0f} Pa) is not above p_atm "
                         f"({p_atm:.0f} Pa): nothing to unload")
    u.refined = False
    st.level = p_plateau - 0.1 * u.dp_guess
    st.next_check = i + PERIOD
    return []


#: Fall rate of the samples before the start, as a fraction of the initial fall rate, that
#: makes them no plateau (a continuing unload, not a step) [-].
PLATEAU_FALL_FRACTION = 0.25


def no_plateau(t: FloatArray, p: FloatArray, min_plateau: int, slope0: float,
               fraction: float = PLATEAU_FALL_FRACTION) -> str:
    """Why the samples before a fitted start are no pre-step plateau, or '' when they are:
    they are none when fewer than ``min_plateau`` [-] (p10 is not measured), when their
    straight-line fall rate is both significant (more than 4 standard errors, the noise
    from first differences) and more than ``fraction`` of the initial fall rate ``slope0``
    [signal units/s] (the "step" continues a fall already under way), or when they are too
    few to resolve such a fall (4 standard errors above that fraction, when not 0). ``t`` [s]
    and ``p`` [signal units]: the samples from the plateau's first one up to the start.
    """
    n = p.size
    if n < min_plateau:
        return (f"no plateau before the drop ({n} samples before the start, fewer than "
                f"min_plateau={min_plateau})")
    tc = t - t.mean()
    sxx = float(tc @ tc)
    if not (sxx > 0.0 and slope0 > 0.0):
        return ""
    fall = -float(tc @ (p - p.mean())) / sxx
    se = rms_sigma(p) / math.sqrt(sxx)
    if fall > 4.0 * se and fall > fraction * slope0:
        return (f"no plateau before the drop (the {n} samples before the start fall at "
                f"{fall:.4g} /s, {100.0 * fall / slope0:.0f} % of the initial fall rate)")
    if 0.0 < fraction and 4.0 * se > fraction * slope0:
        # too short to tell: a slow tail joined late looks flat over a few dozen samples
        # and then "drops" (a bogus unload, C tens of % off)
        return (f"no plateau before the drop that can be told from a fall under way (the "
                f"{n} samples before the start resolve a fall rate of {4.0 * se:.4g} /s, "
                f"more than {100 * fraction:.0f} % of the initial "
                f"{slope0:.4g} /s)")
    return ""


def first_unload_check(st: EstimatorState, i: int, t: FloatArray, p: FloatArray,
                       slope0: float, drift: float = 0.0) -> tuple[bool, str]:
    """The first unload of a stream, whose plateau began with the stream's first sample:
    (skip, why): skip is True when it is to be skipped (decided at index i [-]; t [s], p
    [signal units]: the samples before its start; slope0: initial fall rate [signal
    units/s]; ``drift``: the plateau's fitted drift [signal units/s], 0 if none: then a
    live stream's first samples falling at all are no plateau, e.g. a 5 L unload joined
    1.2 s in); why is the reason it has no plateau ('' when it has one).

    Without a pre-step plateau (:func:`no_plateau`) a live stream (``live``: a node that
    may start or restart at any time) joined an unload under way: no result for it, a
    warning, and the rest of it is skipped until a plateau. Offline, a record is taken to
    start where its author chose: the caller judges whether the opening is in it
    (:func:`opening_in_record`, once the start's uncertainty is known).
    """
    st.stream_start = False
    why = no_plateau(t, p, st.settings.min_plateau, slope0,
                     0.0 if st.live and drift != 0.0 else PLATEAU_FALL_FRACTION)
    if not why:
        return False, ""
    if st.live:
        st.diag("warn", f"{why}: the stream started during an unload (estimator started or "
                        f"restarted mid-unload): no estimate for this unload; waiting for a "
                        f"plateau before the next one", float(st.buf.t[i]))
        st.to_skip(i)
        return True, why
    return False, why


#: The fitted opening of a record without a plateau must lie at least this many of its
#: standard errors after the record's first sample to be in the record [-]: closer, the
#: record's first samples already fall as the fitted start's neighbourhood does (one-sided
#: 4 sigma: a record that truly begins on a flat stretch fails it with a probability of
#: about 3e-5 for a normal error of the start).
OPENING_IN_RECORD_Z = 4.0


#: The words of a refusal of :func:`opening_in_record` that say what to pass instead (the
#: opening as the start time); a caller that locates unloads with the estimator (the
#: discrepancy workflow) passes such a refusal on.
OPENING_HINT = "give the opening: --start-time"


#: Samples at the head of a record that show whether its fall is still gathering pace [-]:
#: the fewest through which a straight line has a residual (a rate and its noise).
RAMP_SAMPLES = 3


def opening_in_record(t_head: FloatArray, p_head: FloatArray, t0: float, t0_std: float,
                      slope0: float, sigma: float, why: str) -> str:
    """'' when the opening of a record without a plateau (``why``: the reason it has none)
    is in the record; else why the unload is refused, with what to pass instead.

    The opening is in the record when the fitted start t0 [s] lies
    :data:`OPENING_IN_RECORD_Z` standard errors ``t0_std`` [s] or more after its first
    sample (flat samples before it), or when its first samples (``t_head`` [s], ``p_head``
    [signal units]: :data:`RAMP_SAMPLES` of them) fall slower than the start fit's initial
    rate slope0 [signal units/s] by that many standard errors of their rate (sigma [signal
    units]: the start window's noise, :func:`~.regression.curvature_sigma`): the valve's
    opening ramp, the fall gathering pace. A
    record cut after the opening falls at the first sample at its full rate, slowing: its
    own p10 and start would be taken (a 5 L tank's record cut 1 s in: C 4 % low)."""
    lead = t0 - float(t_head[0])
    z = lead / t0_std if t0_std > 0.0 else (math.inf if lead > 0.0 else 0.0)
    if z >= OPENING_IN_RECORD_Z:
        return ""
    tc = t_head - t_head.mean()
    sxx = float(tc @ tc)
    if sxx > 0.0 and sigma > 0.0 and math.isfinite(slope0):
        fall = -float(tc @ (p_head - p_head.mean())) / sxx
        if (slope0 - fall) / (sigma / math.sqrt(sxx)) >= OPENING_IN_RECORD_Z:
            return ""
    t_first = float(t_head[0])
    return (f"{why}, and the pressure already falls at the record's first sample at its "
            f"full rate (the fitted opening lies {lead:.3g} s after it, {z:.1f} standard "
            f"errors of the start, fewer than {OPENING_IN_RECORD_Z:g}; no opening ramp in "
            f"its first {t_head.size} samples): the record begins at or after the valve "
            f"opening, and its p10 and start are not measured. If it begins at the "
            f"opening, {OPENING_HINT} {t_first:.6g} (start_time) with "
            f"--atmosphere PA and, when no sample falls on the opening, --initial-pressure "
            f"PA (docs: Records that begin at the opening); if it begins later, the unload "
            f"cannot be measured from it")


def fall_exponent(gamma: float) -> float:
    """k of a choked adiabatic discharge's first fall, p ~ (1 + beta u)^-k: 2 gamma/(gamma
    - 1) [-] (7 for air; the start fit's shape beyond its quadratic, see
    :func:`~.regression.hinge_fit`)."""
    return 2.0 * gamma / (gamma - 1.0)


#: A drifting plateau's fall: its initial rate at least this many times the drift's [-].
DRIFT_FALL_RATIO = 3.0


#: A start's hinge whose residual RMS exceeds this many of the window's noise (from first
#: differences) has missed the fall (the trigger fired on a drift): the drifting plateau's
#: start is fitted as well [-].
HINGE_MISFIT = 2.0


def drifting_start(tv: FloatArray, pv: FloatArray, lo: int, i: int, min_plateau: int
                   ) -> tuple[tuple[float, ...] | None, int]:
    """The start of a fall after a plateau that drifts (:func:`sloped_hinge_fit`), found
    on the shortest window ending at sample i (10 % down) that holds a plateau of
    ``min_plateau`` samples before the start and a fall (the fitted fall's mean rate from the
    start to sample i) clearly steeper than the drift (:data:`DRIFT_FALL_RATIO`, against the fitted
    drift and the mean fall from sample ``lo`` to the start): a long drifting plateau is
    curved (the gas cools exponentially) and a straight drift over all of it misplaces the
    start. Windows of 2, 4, 8 ... plateaus, the last from sample ``lo``. Returns the fit
    (t0 [s], p10, s, c, rms, drift [signal units, /s, /s^2]) and its first sample [-], or
    (None, lo)."""
    n_w = 2 * min_plateau
    while True:
        a = max(lo, i + 1 - n_w)
        tw, pw = tv[a:i + 1], pv[a:i + 1]
        if tw.size >= 8:
            hot = sloped_hinge_fit(tw, pw, float(tw[0]), float(tv[i]))
            before = int(np.searchsorted(tw, hot[0]))
            # the fall clearly steeper than the drift, here and over all of the record
            # before it (a stream joined part way into an unload falls as fast before)
            head = pv[lo:lo + min_plateau]
            t_head = float(np.mean(tv[lo:lo + min_plateau]))
            mean_rate = abs(float(np.mean(head)) - hot[1]) / max(hot[0] - t_head, 1e-12)
            fall = hot[2] - hot[3] * (float(tv[i]) - hot[0])  # the fitted fall's mean rate
            if before >= min_plateau and hot[2] > 0.0 and fall > DRIFT_FALL_RATIO * max(
                    abs(hot[5]), mean_rate):
                return hot, a
        if a <= lo:
            return None, lo
        n_w *= 2


def refine_start(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Hinge fit of the valve-opening instant, p10 and the initial slope (index i: first
    sample 10 % down); sets p* when p_atm is given."""
    n = i + 1
    u = st.unload
    tv, pv = st.buf.views(n)
    trig = u.trigger
    back = i - trig + 4 * CONFIRM
    lo = max(st.arm_index, trig - back - HINGE_PLATEAU)
    t_lo = float(tv[max(st.arm_index, trig - back)])
    t_hi = float(tv[trig])
    k = fall_exponent(st.settings.gamma)
    tw, pw = tv[lo:n], pv[lo:n]
    t0, p10, slope, curv, rms = hinge_fit(tw, pw, t_lo, t_hi, exponent=k)
    drift = 0.0  # the plateau's drift [signal units/s], fitted where it drifts
    if trig < i and (t_hi - t0 < 0.01 * (t_hi - float(tv[trig - 1])) or not slope > 0.0):
        # the start pinned at the trigger (within 1 % of a sample) or no fall found before
        # it: the trigger came before the opening (a noise dip confirmed against a plateau
        # of a few samples, whose level and noise are then off). The start is searched up
        # to the sample 10 % down, and taken from there only when it lies after the
        # trigger and fits better.
        alt = hinge_fit(tw, pw, t_lo, float(tv[i]), exponent=k)
        if alt[0] > t_hi and alt[4] < rms:
            t0, p10, slope, curv, rms = alt
    # fewer samples before the start than a plateau needs: no plateau was found before it
    at_first = int(np.searchsorted(tw, t0)) < 2 * st.settings.min_plateau
    # the hinge misses the window by more than its noise (correlated too: AR(1) 0.9 read as
    # a miss refused a slow unload): the trigger fired on a drift the hinge cannot follow (a
    # gas 10 K warm cooling over a 10 s plateau at 200 Hz: the start 0.3 s early, C -10 %)
    missed = rms > HINGE_MISFIT * rms_sigma(pw) * correlated_noise_factor(pv[lo:trig])
    if trig < i and (not slope > 0.0 or at_first or missed):
        # still no fall, or a fall from the window's first samples (no plateau before it),
        # or a hinge that misses: a plateau that drifts (a gas hot from the charge cooling
        # toward the wall: the trigger fired on the drift) has its slope fitted with the
        # start
        hot, a = drifting_start(tv, pv, lo, i, st.settings.min_plateau)
        if hot is not None and (a > lo or hot[4] < rms):
            t0, p10, slope, curv, rms, drift = hot
            lo = a
            st.diag("ok", f"the plateau before the opening drifts by {drift:.4g} /s (a gas "
                    f"warmer or cooler than the wall): fitted with the start",
                    float(tv[i]))
    pre = pv[lo:int(np.searchsorted(tv, t0))]
    sig_pre = rms_sigma(pre) if pre.size > 3 else rms
    if pre.size >= 8:
        # clipped: most of the plateau's second half (its first may hold the charge's end)
        # at exactly its highest value, with no noise, or only the noise's few dips below
        last = pre[pre.size // 2:]
        vmax = float(np.max(last))
        frac_at_max = float(np.mean(last == vmax))
        if frac_at_max > 0.5 and (sig_pre == 0.0 or frac_at_max > 0.9) and rms > 0.0:
            return st.bad(
                i, f"sensor saturated on the pre-step plateau at {vmax!r}: p10 unknown")
    u.t0 = t0
    u.i0 = int(np.searchsorted(tv, t0))
    # the first unload of a stream: judged on its whole plateau since the stream began (a
    # slow tail joined late looks flat over the hinge's window, not over seconds)
    first = min(lo, st.arm_index)
    no_plateau_why = ""
    if st.stream_start:
        skip, no_plateau_why = first_unload_check(st, i, tv[first:u.i0], pv[first:u.i0],
                                                  slope, drift)
        if skip:
            return []
    # the start's and p10's (co)variance from the hinge model's information (its curvature
    # and continuity included; p* moves with p10, see crossing_result)
    u.inflation = variance_inflation(pre)  # correlated noise (tau_sigma and p_atm's too)
    v_t0, u.t0_p10_cov, u.p10_var = [u.inflation * x for x in hinge_cov(
        tv[lo:n], t0, slope, curv, rms, exponent=k)] if slope > 0 else (math.inf, 0.0, math.inf)
    u.t0_std = math.sqrt(v_t0)
    if no_plateau_why:  # offline: a record without a plateau
        head = slice(first, min(first + RAMP_SAMPLES, n))
        refused = opening_in_record(tv[head], pv[head], t0, u.t0_std, slope,
                                    curvature_sigma(pw), no_plateau_why)
        if refused:
            return st.bad(i, refused)
        st.diag("warn", f"{no_plateau_why}: the record starts at or after the valve "
                        f"opening; p10 and the start come from its first samples (the "
                        f"estimate may be biased)", float(st.buf.t[i]))
    u.p10 = p10
    u.slope0 = slope
    st.sigma = max(rms, 1e-12)
    u.refined = True
    if st.settings.end_pressure is not None:
        st.set_pstar(u.atm)
        if needs_model(st.settings, st.to_pa(u.atm), st.to_pa(u.pstar)):
            # first stop half way to p*: tabulate the model there, so that the crossing
            # estimate is a lookup when its sample arrives
            u.mid_pending = True
            st.level = u.p10 - 0.5 * (u.p10 - u.pstar)
    else:
        u.pstar = math.nan
        st.level = -math.inf
    st.next_check = i + PERIOD
    return []


def prepare_crossing(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Half way to p* (index i): prepare the crossing estimate (the model's crossing time
    tabulated, the budgets scaled to C: :mod:`.crossing`), then wait for p*."""
    u = st.unload
    u.mid_pending = False
    t_mid = float(st.buf.t[i]) - u.t0
    u.plan = plan_crossing(st.settings, p10=st.to_pa(u.p10), p_atm=st.to_pa(u.atm),
                           p_star=st.to_pa(u.pstar), t_mid=t_mid,
                           p_mid=st.to_pa(float(st.buf.p[i])))
    st.level = u.pstar - u.half
    return []


def stalled_at(st: EstimatorState, k: int | np.ndarray) -> np.bool_ | np.ndarray:
    """:func:`~.decisions.stalled` with the current unload's start, noise and slope."""
    u = st.unload
    buf = st.buf
    if isinstance(k, np.ndarray):
        tv, cs = buf.views()[0], buf.sums()[0]
    else:  # one index: the buffers themselves (the same doubles, no views made)
        tv, cs = buf.t, buf.cs
    return stalled(cs, tv, k, i0=u.i0, sigma=st.sigma, slope0=u.slope0)


def on_stuck(st: EstimatorState, i: int) -> list[UnloadResult]:
    """The sensor stuck while the pressure must fall (a charge's: rise) (index i): one
    'bad_data' result, and the rest of the unload is skipped."""
    return st.bad(i, f"{STUCK_TEXT} {st.to_pa(float(st.buf.p[i])):.0f} Pa during the "
                     f"unload ({STUCK_RUN} identical samples, no noise, while the pressure "
                     f"must {'rise' if st.settings.charge else 'fall'}): no estimate")


def step_unloading(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Decision at index i: the start fit, the p* crossing, p_atm auto, a stuck sensor or
    an abort."""
    u = st.unload
    p = st.buf.p[i]
    if not u.refined:
        if below(p, st.level):
            return refine_start(st, i)
        if i == st.next_check:
            st.next_check = i + PERIOD  # the stall test needs the start fit
            if st.stuck(i):
                return on_stuck(st, i)
            if follow.due(u.trigger, i) and follow.not_followed(st, i):
                return follow.wait_again(st, i)
        return []
    if below(p, st.level) and math.isfinite(u.pstar):
        if u.mid_pending:
            return prepare_crossing(st, i)
        return complete_crossing(st, i)
    if i == st.next_check:
        st.next_check = i + PERIOD
        if reduce_due(st, i):  # a long unload: its old samples to bins
            i -= reduce_unload(st, i)
        if st.stuck(i):
            return on_stuck(st, i)
        if not math.isfinite(u.pstar):
            if i + 1 - window_start(st) > reduction.AUTO_HOLD_MAX:
                return auto_too_long(st, i)
            return check_final_plateau_auto(st, i)
        if stalled_at(st, i):
            return on_abort(st, i)
    return []


#: Most check indices of a scan taken one at a time (a live block of 100 samples holds one
#: or two; numpy's per-call cost on so few exceeds the arithmetic) [-].
FEW_CHECKS = 4


def scan_unloading(st: EstimatorState, i: int, end: int) -> int:
    """Next index in [i, end) where :func:`step_unloading` decides something (end: none);
    only while p* is known or the start not yet refined."""
    j = first_below_in(st.buf.p, i, end, st.level)
    checks = range(st.next_check, min(j, end), PERIOD)
    if len(checks) == 0:
        return j
    u = st.unload
    if len(checks) <= FEW_CHECKS:  # one at a time, as the step takes them
        refined = u.refined
        for k in checks:
            if st.stuck(k) or (refined and (stalled_at(st, k) or reduce_due(st, k))) or (
                    not refined and follow.due(u.trigger, k) and follow.not_followed(st, k)):
                st.next_check = k
                return k
        st.next_check = checks[-1] + PERIOD
        return j
    ks = check_indices(st.next_check, min(j, end))
    event = st.stuck(ks)
    if u.refined:
        event = event | stalled_at(st, ks) | reduce_due(st, ks)
    else:  # the few checks where the fall's follow-up is tested
        for h in np.flatnonzero(follow.due(u.trigger, ks)):
            event[h] |= follow.not_followed(st, int(ks[h]))
    hit = np.flatnonzero(event)
    if hit.size:
        st.next_check = int(ks[int(hit[0])])
        return st.next_check
    st.next_check = int(ks[-1]) + PERIOD
    return j


def end_plateau_auto(st: EstimatorState, i: int) -> bool:
    """p_atm auto at the end of the stream (index i): see
    :func:`~.decisions.settled_at_end`."""
    u = st.unload
    if not u.refined or math.isfinite(u.pstar):
        return False
    return settled_at_end(st.buf.cs, i, i0=u.i0, p10=u.p10, dp_guess=u.dp_guess)


def auto_too_long(st: EstimatorState, i: int) -> list[UnloadResult]:
    """p_atm auto: the unload holds AUTO_HOLD_MAX samples at index i and has no final
    plateau yet (memory bound): close it as aborted with the reason and the fix, and skip
    the rest of it (one physical unload, one result)."""
    n = reduction.AUTO_HOLD_MAX
    text = (f"no final plateau after {n} samples of the unload ({st.dt * n:.0f} s): "
            f"{st.end_unknown(' within the memory bound')}")
    st.diag("warn", text, float(st.buf.t[i]))
    res = abort_result(st, i, recovered=False, text=text)
    res.final = True
    st.to_skip(i)
    return [res]


def check_final_plateau_auto(st: EstimatorState, i: int, at_end: bool = False
                             ) -> list[UnloadResult]:
    """p_atm auto: once the final plateau is reached, set p* and find the crossing
    (``at_end``: the stream ended on a plateau judged by :func:`end_plateau_auto`)."""
    u = st.unload
    tv, pv = st.buf.views(i + 1)
    tau_guess = (float(tv[i]) - u.t0) / 4.0
    if at_end:
        w = max((i - u.i0) // 8, 8)
        level = st.buf.mean(i - w + 1, i + 1)
        if (why := end_level_problem(st.settings, st.to_pa(level),
                                     st.to_pa(st.unload.p10))) is not None:
            return st.bad(i, why)
        st.set_pstar(level)
        u.atm_var = st.sigma**2 / w * u.inflation
        j = first_below(pv, u.i0, i + 1, st.level)
        if j > i:
            return []
        return complete_crossing(st, j)
    if not flat(st.buf.cs, i, i0=u.i0, tau=tau_guess, dt_nominal=st.dt_nominal, p10=u.p10,
                sigma=st.sigma):
        return []
    w = flat_window(tau_guess, st.dt_nominal)
    level = float(np.mean(pv[i - w + 1:i + 1]))
    drop = u.p10 - level
    if drop < 0.5 * u.dp_guess:
        return on_abort(st, i)
    if (why := end_level_problem(st.settings, st.to_pa(level),
                                 st.to_pa(st.unload.p10))) is not None:
        return st.bad(i, why)
    st.set_pstar(level)
    u.atm_var = st.sigma**2 / w * u.inflation
    j = first_below(pv, u.i0, i + 1, st.level)
    if j > i:
        return on_abort(st, i)
    return complete_crossing(st, j, settle_index=i)


def complete_crossing(st: EstimatorState, i: int, settle_index: int | None = None
                      ) -> list[UnloadResult]:
    """Crossing window closed at index i (first sample below p* - half): the crossing
    result, then the tail (``settle_index``: the tail already settled there)."""
    n = i + 1
    u = st.unload
    buf = st.buf
    # from the last sample above p* + half (u.i0 negative: the unload's first samples were
    # reduced, .reduction), fitted, then again on a window symmetric in time about the
    # estimate (the ends of the first window were chosen by noisy sample values), compiled
    t_cross, t_std, slope, gap, _lo = crossing_window(
        buf.t, buf.p, max(u.i0, 0), n, u.pstar + u.half, u.i0, u.pstar, st.gap_limit)
    k = i if settle_index is None else settle_index
    res = crossing_result(st, k, t_cross, tau_sigma(u, t_std, slope), gap)
    u.pending = res
    st.mode = TAIL
    u.tail_low = math.inf
    st.level = -math.inf
    st.next_check = k + PERIOD
    if settle_index is not None:
        return [res, *finish_tail(st, k, ended=False)]
    return [res]


def crossing_result(st: EstimatorState, i: int, t_cross: float, tau_std: float,
                    gap: bool) -> UnloadResult:
    """Result of an unload from its crossing instant t_cross [s] and tau_exp's 1-sigma
    tau_std [s] (:func:`tau_sigma`): eq 39, the isentropic inversion and the model
    inversion with their budgets (prepared half way to p*, :mod:`.crossing`); completed
    at index i."""
    s, u = st.settings, st.unload
    plan = u.plan
    if plan is None:  # p* found late (p_atm from the final plateau): prepared now
        plan = plan_crossing(s, p10=st.to_pa(u.p10), p_atm=st.to_pa(u.atm),
                             p_star=st.to_pa(u.pstar), tau_ref=t_cross - u.t0)
    p10, p_atm, p_star = plan.p10, plan.p_atm, plan.p_star
    tau = t_cross - u.t0
    est = crossing_estimate(plan, tau, tau_std)
    status, text, quality = "ok", "p* crossing found", 1.0
    if est.problem is not None:
        st.diag("error", est.problem, t_cross)
        status, text, quality = "bad_data", est.problem, 0.0
    elif plan.subsonic is not None:
        status, text, quality = "ok_subsonic", plan.subsonic, 0.5
    if gap or st.gap_in_unload:
        text += "; gap in the samples during the unload"
        quality = min(quality, 0.5)
    if est.problem is None and not tau_std <= 0.01 * tau:
        quality = min(quality, 0.5)
    c39, c_model = est.conductance, est.conductance_model
    shift = st.buf.shift
    res = UnloadResult(
        index=st.n_unloads, status=status, status_text=text, t_start=u.t0,
        t_cross=t_cross, tau_exp=tau, tau_exp_std=tau_std, p10=p10,
        **end_fields(s, p_atm), p_star=p_star,
        initial_temperature=plan.settings.initial_temperature,
        volume=plan.settings.volume, conductance=c39, conductance_model=c_model,
        conductance_model_std=est.conductance_model_std,
        conductance_std=est.conductance_std, extra=est.extra,
        conductance_isentropic=est.conductance_isentropic, quality=quality,
        method=est.method,
        noise_std=abs(st.sigma * s.signal_gain), i_start=u.i0 + shift,
        i_cross=shift + (bisect.bisect_left(st.buf.t, t_cross, 0, i + 1)
                         if t_cross == t_cross else i + 1),  # NaN sorts last
        i_complete=i + shift, t_complete=float(st.buf.t[i]))
    st.n_unloads += 1
    return res
