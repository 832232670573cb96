# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Tail phase: after the crossing, wait for the final plateau (or a new charge), then close
the unload with the full-curve fit; and the skip phase, the rest of an unload already
reported as bad data, which re-arms only once the signal settles on a live plateau or
rises (so that one physical unload gives one result). Values in signal units, times in s,
indices in buffer samples."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.curvefit.offset_offer import OFFSET_MAX_FRACTION
from pneumatic_unload.estimation.buffer import ReadingLog
from pneumatic_unload.estimation.decisions import (
    PERIOD,
    PLATEAU,
    SETTLE_MAX,
    STUCK_RUN,
    TRIM_MIN,
    block_mean,
    check_indices,
    flat,
    rise_threshold,
    rose,
    running_low,
    settled,
    zero_watch,
)
from pneumatic_unload.estimation.endstep import STEP_BACK, TAIL_STEP, settled_step
from pneumatic_unload.estimation.reduction import fit_window, reduce_due, reduce_unload
from pneumatic_unload.estimation.refine import final_curve_fit
from pneumatic_unload.estimation.state import EstimatorState
from pneumatic_unload.estimation.types import STUCK_TEXT, FloatArray, UnloadResult
from pneumatic_unload.estimation.vetting import as_computed, vet
from pneumatic_unload.fit.reduced import Reducer


@dataclass(frozen=True)
class FinalFit:
    """The final curve fit of one unload, as a job: everything it needs, copied out of the
    stream, so that it can run later on another thread (a live node publishes the crossing
    estimate at once and fits on a worker, see ``StreamingEstimator(defer_final_fit=True)``)
    with the same result as inline.

    Attributes
    ----------
    crossing : UnloadResult
        The unload's crossing result (published at the p* crossing).
    t, p : ndarray or None
        The unload's samples from before its plateau to the end of its tail [s], [Pa
        absolute] (copies); None when they were reduced to bins (``reduced``).
    settings : EstimatorSettings
        The estimator settings of the unload.
    noise_std : float
        Sample noise [Pa].
    i_complete : int
        Stream index of the sample that completed the unload [-].
    t_complete : float
        Its stamp [s].
    reduced : Reducer or None
        A long unload's samples reduced to bins (see :mod:`.reduction`), or None.
    temperature : tuple of ndarray or None
        The logged gas temperature's readings over the unload ([s], [K], copies), fitted
        beside the pressure; None without any.
    """

    crossing: UnloadResult
    t: FloatArray | None
    p: FloatArray | None
    settings: EstimatorSettings
    noise_std: float
    i_complete: int
    t_complete: float
    reduced: Reducer | None = None
    temperature: tuple[FloatArray, FloatArray] | None = None

    def window(self) -> tuple[float, float]:
        """The unload's span [s]: its first sample (held or reduced) and the end of its
        tail (the logged temperature fitted beside is the readings within)."""
        t0 = float(self.t[0]) if self.t is not None else \
            self.reduced.t_ref if self.reduced is not None else -math.inf
        return t0, self.t_end

    def with_temperature(self, log: ReadingLog) -> FinalFit:
        """This job with the readings of ``log`` over its :meth:`window` (up to
        :data:`~.buffer.READING_MARGIN` before its end: :meth:`~.buffer.ReadingLog.span`;
        None without any): taken when it is made, and again when a live node runs it."""
        return dataclasses.replace(self, temperature=log.span(*self.window()))

    @property
    def t_end(self) -> float:
        """The last instant of the unload's tail [s]."""
        return float(self.crossing.t_end)

    def run(self) -> UnloadResult | None:
        """The final result (None when the fit fails; see
        :func:`~.refine.final_curve_fit`)."""
        fin = final_curve_fit(self.crossing, self.t, self.p, self.settings,
                              noise_std=self.noise_std, reduced=self.reduced,
                              temperature=self.temperature)
        if fin is not None:
            fin.i_complete, fin.t_complete = self.i_complete, self.t_complete
            vet(fin, self.settings)
        return fin


def _tail_tau(st: EstimatorState, tau: float) -> float:
    """The tail tests' time scale [s]: ``tau``, the crossing's tau_exp, or, when that is
    not finite (a 'bad_data' crossing with no crossing instant), the time from the start to
    the sample that closed the crossing window (0 when unknown)."""
    if math.isfinite(tau):
        return tau
    u = st.unload
    res = u.pending
    tau = res.t_complete - u.t0 if res is not None else 0.0
    return tau if math.isfinite(tau) and tau > 0.0 else 0.0


def _flat_tail(st: EstimatorState, cs: np.ndarray, k: int | np.ndarray, tau: float
               ) -> np.bool_ | np.ndarray:
    """:func:`~.decisions.flat` with the current unload's start, p10 and noise, at the
    time scale :func:`_tail_tau` [s]."""
    u = st.unload
    return flat(cs, k, i0=u.i0, tau=_tail_tau(st, tau), dt_nominal=st.dt_nominal,
                p10=u.p10, sigma=st.sigma)


def _watch_zero(st: EstimatorState, cs: np.ndarray, i: int, tau: float) -> bool:
    """A tail level at index i whose end lies clearly away from the given p_atm, by no more
    than a zero offset fitted can be (OFFSET_MAX_FRACTION of the drop), is followed on
    (:func:`~.decisions.zero_watch`; not where p_atm is the plateau's own mean): sets
    the unload's ``zero_until`` and says so; False where it ends here."""
    u = st.unload
    if u.atm_var != 0.0 or not math.isfinite(u.atm):
        return False
    extra, gap = zero_watch(cs, i, tau=_tail_tau(st, tau), dt_nominal=st.dt_nominal, atm=u.atm,
                            sigma=st.sigma, max_gap=OFFSET_MAX_FRACTION * abs(u.p10 - u.atm))
    if extra <= 0:
        return False
    u.zero_until = i + st.buf.shift + extra
    st.diag("ok", f"tail level {gap * st.settings.signal_gain:+.0f} Pa from the given p_atm:"
            f" followed {extra} samples more for the gap", float(st.buf.t[i]))
    return True


def step_tail(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Periodic tail check at index i: a new charge ends the tail two periods back (before
    the rise began, see :func:`~.decisions.rose`); a settled plateau ends it here."""
    if i != st.next_check:
        return []
    st.next_check = i + PERIOD
    if reduce_due(st, i):  # a long tail: its old samples to bins
        i -= reduce_unload(st, i)
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
    if st.stuck(i):
        return on_tail_stuck(st, i)
    if res is None:
        return []
    if u.zero_until is not None:
        level = i + st.buf.shift >= u.zero_until
    else:
        sums = np.frombuffer(cs, dtype=float)
        level = bool(_flat_tail(st, sums, i, res.tau_exp)) and \
            not _watch_zero(st, sums, i, res.tau_exp)
    if level:
        # level to the flat test (and followed on for the gap to a given p_atm), maybe
        # still falling slowly: a next unload needs a charge or a level plateau (the valve
        # closed, then opened again), see step_waiting
        floor = u.tail_low + rise_threshold(st.sigma, u.p10, u.atm)
        out = finish_tail(st, i, ended=False)
        st.rearm_floor, st.rearm_noted = floor, False
        return out
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
    event |= st.stuck(ks) | reduce_due(st, ks)
    if u.pending is not None:
        event |= (ks + st.buf.shift >= u.zero_until) if u.zero_until is not None else \
            _flat_tail(st, cs, ks, u.pending.tau_exp)
    hit = np.flatnonzero(event)
    k = int(hit[0]) if hit.size else ks.size
    if k > 0:
        u.tail_low = float(min(low_prev[k - 1], m[k - 1]))
        st.next_check = int(ks[k - 1]) + PERIOD
    return int(ks[k]) if k < ks.size else end


def on_tail_stuck(st: EstimatorState, i: int) -> list[UnloadResult]:
    """The sensor stuck after the crossing (STUCK_RUN identical samples up to index i): the
    tail ends where the run began (the curve fit uses the samples before it), and the rest
    of the unload is skipped (no phantom unload from the stuck stretch)."""
    u = st.unload
    lo = i - STUCK_RUN + 1
    value = st.to_pa(float(st.buf.p[i]))
    t_lo = float(st.buf.t[lo])
    text = (f"{STUCK_TEXT} {value:.0f} Pa from t={t_lo:.6f} s after the p* crossing: "
            "the tail ends there")
    st.diag("warn", text, float(st.buf.t[i]))
    return end_tail_and_skip(st, max(lo - 1, u.i0 + 1), i, text)


def end_tail_and_skip(st: EstimatorState, i_end: int, i: int, text: str
                      ) -> list[UnloadResult]:
    """Close the unload's tail at index i_end (its final fit uses the samples up to there,
    its text gets ``text``), decided at index i, then skip the rest of the unload [-]."""
    u = st.unload
    sigma, level = st.sigma, st.plateau_level
    out = finish_tail(st, i_end, ended=False, decided=i)
    for r in out:
        r.status_text += "; " + text
    st.unload, st.sigma, st.plateau_level = u, sigma, level
    st.to_skip(i)
    return out


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
    last = i
    if res is not None:
        i = _before_step(st, i, res)
        res.t_end = float(st.buf.t[i])
        s = st.settings
        if s.curve_fit:
            t, p, reduced = fit_window(st, i)
            job = FinalFit(as_computed(res), None if t is None else np.array(t), p, s,
                           abs(st.sigma * s.signal_gain), dec + st.buf.shift,
                           float(st.buf.t[dec]), reduced)
            job = job.with_temperature(st.temperature)
            if st.defer_final_fit:
                st.final_fits.append(job)
            else:
                fin = job.run()
                if fin is not None:
                    out.append(fin)
    st.to_waiting(last + 1)
    return out


def _before_step(st: EstimatorState, i: int, res: UnloadResult) -> int:
    """The tail's last sample, index i, or the last before a step that follows its level
    (:func:`~.endstep.settled_step`: not the discharge, e.g. a valve or the transducer
    after the tank emptied), the crossing result ``res``'s ``extra[TAIL_STEP]`` then
    saying so (the final status text carries it) [-]."""
    u = st.unload
    # the tail after the p* crossing (a stream index; the tail's level lies below p*)
    lo = max(u.i0 + 1, res.i_cross - st.buf.shift + 1, i + 1 - STEP_BACK)
    found = settled_step(st.buf.p[lo:i + 1])
    if found is None:
        return i
    k = lo + found[0]
    step = found[1] * st.settings.signal_gain  # [Pa]
    text = (f"the record steps by {step:+.0f} Pa at t={float(st.buf.t[k + 1]):.6f} s, "
            "after its tail had settled: not the discharge, the tail ends before it")
    res.extra[TAIL_STEP] = text
    st.diag("warn", text, float(st.buf.t[i]))
    return k


def _skip_drop(st: EstimatorState) -> float:
    """Expected drop of the skipped unload, 0 when unknown [signal units]."""
    dp = st.unload.dp_guess
    return dp if math.isfinite(dp) else 0.0


def _skip_trim_keep(k: int | np.ndarray) -> int | np.ndarray:
    """Samples that may be dropped while skipping at index k: all but the widest settling
    test's two windows and 4 PLATEAU [-] (bounds the memory on a signal that never
    settles)."""
    return k + 1 - 2 * SETTLE_MAX - 4 * PLATEAU


def _skip_events(st: EstimatorState, k: int | np.ndarray, low: float | np.ndarray
                 ) -> tuple[np.bool_ | np.ndarray, np.bool_ | np.ndarray]:
    """(rise, settled) at check index k, ``low``: lowest earlier block mean."""
    u = st.unload
    cs, cq = st.buf.sums()
    m = block_mean(cs, k)
    rise = rose(m, low, u.skip_rise)
    calm = settled(cs, cq, k, origin=u.trigger, since=u.skip_since, drop=_skip_drop(st))
    return rise, calm


def step_skip(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Periodic check while skipping a bad unload (index i): a rise re-arms two periods
    back (before it began), a live plateau re-arms here; no result either way."""
    if i != st.next_check:
        return []
    st.next_check = i + PERIOD
    u = st.unload
    rise, calm = _skip_events(st, i, u.tail_low)
    m = float(block_mean(st.buf.sums()[0], i))
    if m < u.tail_low:
        u.tail_low = m
    t = float(st.buf.t[i])
    if rise:
        st.diag("ok", "pressure rising again after the bad unload: re-armed", t)
        st.to_waiting(max(i - 2 * PERIOD, u.skip_since) + 1)
        st.next_check = i + PERIOD
        return []
    if calm:
        st.diag("ok", "signal settled after the bad unload: re-armed", t)
        st.to_waiting(i + 1)
        return []
    keep = int(_skip_trim_keep(i))
    if keep > TRIM_MIN:
        st.buf.trim(keep)
        st.next_check -= keep
        u.skip_since -= keep
        u.trigger -= keep
    return []


def scan_skip(st: EstimatorState, i: int, end: int) -> int:
    """Next index in [i, end) where :func:`step_skip` decides something (end: none); the
    running lowest block mean of the checks before it is applied here."""
    ks = check_indices(st.next_check, end)
    if ks.size == 0:
        return end
    u = st.unload
    m = block_mean(st.buf.sums()[0], ks)
    low_prev = running_low(u.tail_low, m)
    rise, calm = _skip_events(st, ks, low_prev)
    event = rise | calm | (_skip_trim_keep(ks) > TRIM_MIN)
    hit = np.flatnonzero(event)
    k = int(hit[0]) if hit.size else ks.size
    if k > 0:
        u.tail_low = float(min(low_prev[k - 1], m[k - 1]))
        st.next_check = int(ks[k - 1]) + PERIOD
    return int(ks[k]) if k < ks.size else end
