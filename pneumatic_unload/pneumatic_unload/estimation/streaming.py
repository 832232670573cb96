# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The streaming estimator: samples in (one by one or in blocks), results out.

:class:`StreamingEstimator` is fed pressure samples one at a time (:meth:`push`) or in
blocks (:meth:`push_block`); both paths give bit-identical results, because every decision
is taken at a sample index from the samples up to that index only, with O(1) statistics
from running prefix sums, and each decision is one function of :mod:`.decisions` that the
per-sample path calls with one index and the block path with many, calling the phase's
step only where something happens. Times in s, values in Pa absolute (or the input's
signal units with ``signal_gain``/``signal_offset``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation import decisions, detector, follow, sse, tail, unloading
from pneumatic_unload.estimation.buffer import ReadingLog, SampleBuffer
from pneumatic_unload.estimation.crossing import rehearse_crossing
from pneumatic_unload.estimation.decisions import SCAN_HORIZON
from pneumatic_unload.estimation.history import DiagnosticLog, recent_results
from pneumatic_unload.estimation.regression import block_steps, first_below_in
from pneumatic_unload.estimation.stamps import (
    CLOCK_RESYNC,
    MAX_ABS_STAMP,
    MIN_STAMP_STEP,
    StampChecks,
)
from pneumatic_unload.estimation.state import (
    CONFIRM,
    RECOVERY,
    SKIP,
    TAIL,
    UNLOADING,
    WAITING,
    EstimatorState,
)
from pneumatic_unload.estimation.types import FloatArray, UnloadResult
from pneumatic_unload.estimation.vetting import vet

__all__ = ["CLOCK_RESYNC", "MAX_ABS_STAMP", "MIN_STAMP_STEP", "StreamingEstimator"]

#: Decision step of each phase at one buffer index.
STEPS: dict[str, Callable[[EstimatorState, int], list[UnloadResult]]] = {
    WAITING: detector.step_waiting,
    CONFIRM: detector.step_confirm,
    UNLOADING: unloading.step_unloading,
    TAIL: tail.step_tail,
    RECOVERY: sse.step_recovery,
    SKIP: tail.step_skip,
}


def _check_streaming(settings: EstimatorSettings) -> None:
    """Refuse settings the streaming estimator cannot use (EstimationError)."""
    if settings.start_time is not None:
        raise EstimationError(
            "start_time is for offline records that begin at the valve opening "
            "(analyze, --start-time); the streaming estimator detects each start")
    if settings.direction == "both":
        raise EstimationError(
            "direction 'both' (charges and discharges in one stream) is two streaming "
            "estimators: TwoWayEstimator (analyze and the node use it)")


def _core_settings(settings: EstimatorSettings) -> EstimatorSettings:
    """The settings the core runs on: a charge's with the signal gain negated (its samples
    are fed negated, :class:`StreamingEstimator`)."""
    if not settings.charge:
        return settings
    return dataclasses.replace(settings, signal_gain=-settings.signal_gain)


class StreamingEstimator(StampChecks):
    """Sample-by-sample unloading-time estimator; see the package docstring.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and detection settings.
    live : bool
        A live stream, which may join an unload under way (a node started or restarted at
        any time): the first unload, when it has no pre-step plateau, gets no result, a
        warning and is skipped until a plateau. Offline (default) a record is taken to
        start where its author chose: that unload is analysed, with a warning.
    defer_final_fit : bool
        Do not run an unload's final curve fit (``settings.curve_fit``) inside the call
        that completes the unload: keep it as a :class:`~.tail.FinalFit` job, taken with
        :meth:`take_final_fits` and run by the caller (a live node publishes the crossing
        estimate at once and fits on a worker thread). ``job.run()`` gives the very result
        the inline path returns; it is not added to :attr:`results`.
    diagnostics : DiagnosticLog, optional
        The log to record diagnostics into (default: its own).
    tag : str
        Put before each of its diagnostics' messages (e.g. 'charge: ').

    Examples
    --------
    >>> est = StreamingEstimator(EstimatorSettings(volume=5e-3))
    >>> results = []
    >>> for ti, pi in zip(t, p):  # doctest: +SKIP
    ...     results += est.push(ti, pi)
    >>> results += est.finish()  # doctest: +SKIP
    """

    #: Samples between periodic checks [-].
    PERIOD = decisions.PERIOD
    #: Samples used for the plateau level and noise [-].
    PLATEAU = decisions.PLATEAU
    #: Samples that must confirm a trigger [-].
    CONFIRM = decisions.CONFIRM
    #: Samples between the end of the reference plateau window and now [-].
    LAG = decisions.LAG
    #: Most pre-step plateau samples used by the start (hinge) fit [-].
    HINGE_PLATEAU = decisions.HINGE_PLATEAU
    #: Recovery samples needed before the first recovery fit [-].
    RECOVERY_MIN = decisions.RECOVERY_MIN
    #: Samples looked ahead per vectorised scan [-].
    SCAN_HORIZON = decisions.SCAN_HORIZON

    def __init__(self, settings: EstimatorSettings | None = None, *, live: bool = False,
                 defer_final_fit: bool = False, diagnostics: DiagnosticLog | None = None,
                 tag: str = "") -> None:
        settings = settings or EstimatorSettings()
        _check_streaming(settings)
        self._user_settings = settings
        #: A charge is analysed mirrored: the core sees -signal, with the signal gain
        #: negated, so that a rising step is the falling one it detects and every level it
        #: converts (to_pa) is the pressure again; the physics (the crossing's closed
        #: forms, the curve fit) takes the direction from the settings.
        self._mirror = settings.charge
        if not self._mirror:  # the per-sample hot path without the mirror's extra call
            self.push = self._push  # type: ignore[method-assign]
        self._st = EstimatorState(_core_settings(settings), live=live,
                                  defer_final_fit=defer_final_fit, diagnostics=diagnostics,
                                  tag=tag)
        #: The first and the last diagnostics (a bounded
        #: :class:`~.history.DiagnosticLog`; ``diagnostics.total`` counts all).
        self.diagnostics = self._st.diagnostics
        #: The last :data:`~.history.RESULTS_KEPT` results (each was returned by the call
        #: that completed it): memory stays bounded on an endless stream.
        self.results = recent_results()
        #: Called with each result as soon as it is complete, inside the call that
        #: completes it, before the rest of a block is processed (a live node publishes
        #: the crossing estimate without waiting for the block's last sample); the call
        #: returns it as well. None: results are only returned.
        self.on_result: Callable[[UnloadResult], None] | None = None
        #: A stamp that went back by more than the gap limit [s] (None: none): one sample
        #: out of order, or the first of a clock step; the next stamp decides
        #: (:meth:`_resolve_suspect`).
        self._suspect: float | None = None
        #: After a clock step back: the samples (t [s], p) that have followed one another
        #: on the new clock since (CLOCK_RESYNC of them re-sync the stream on it,
        #: :meth:`_hold`); None: no clock step pending.
        self._held: list[tuple[float, float]] | None = None
        self._suspect_p = math.nan  # the suspect sample's value
        self._append = self._st.buf.append  # hot path (trimming keeps the buffer object)

    # ------------------------------------------------------------------ public API
    @property
    def settings(self) -> EstimatorSettings:
        """The settings in use; a new value applies from the next unload (set it while
        :attr:`state` is 'waiting' to be sure the unload under way is not mixed)."""
        return self._user_settings

    @settings.setter
    def settings(self, value: EstimatorSettings) -> None:
        _check_streaming(value)
        if value.direction != self._user_settings.direction:
            raise EstimationError(
                f"the direction of a stream is fixed ({self._user_settings.direction!r}): "
                f"make a new estimator for {value.direction!r}")
        self._user_settings = value
        self._st.settings = _core_settings(value)

    @property
    def state(self) -> str:
        """'waiting', 'confirming', 'unloading', 'tail', 'recovery' or 'skipping' (the
        rest of an unload reported as bad data, or joined mid-way: no pre-step plateau)."""
        return self._st.mode

    @property
    def n_samples(self) -> int:
        """Valid samples received so far [-]."""
        buf = self._st.buf
        return len(buf) + buf.shift

    @property
    def buffer(self) -> SampleBuffer:
        """The samples held and their prefix sums (read only)."""
        return self._st.buf

    def take_final_fits(self) -> list[tail.FinalFit]:
        """The final-fit jobs of the unloads completed since the last call, in order
        (``defer_final_fit``; else always empty)."""
        jobs = self._st.final_fits
        if not jobs:
            return []
        self._st.final_fits = []
        return jobs

    def push_temperature(self, t: ArrayLike, temp: ArrayLike) -> None:
        """Feed readings of the logged gas temperature: stamps [s, the pressure's clock] and
        values [K] (a slower channel, at its own rate; readings that arrive before the
        unload's final fit is due are fitted beside its pressure; non-finite or repeated
        stamps ignored)."""
        self._st.temperature.add(np.atleast_1d(np.asarray(t, dtype=float)),
                                 np.atleast_1d(np.asarray(temp, dtype=float)))

    @property
    def temperature(self) -> ReadingLog:
        """The logged gas temperature's readings kept ([s], [K]; see
        :meth:`push_temperature`): a deferred final fit takes those of its span when it
        runs (:meth:`~.tail.FinalFit.window`)."""
        return self._st.temperature

    def push(self, t: float, p: float) -> list[UnloadResult]:
        """Feed one sample.

        Parameters
        ----------
        t : float
            Sample instant [s] (strictly increasing).
        p : float
            Pressure [Pa absolute], or the raw signal when ``signal_gain`` converts it.

        Returns
        -------
        list of UnloadResult
            Results completed by this sample (usually empty).
        """
        return self._push(t, -p if self._mirror else p)

    def _push(self, t: float, p: float) -> list[UnloadResult]:
        """:meth:`push` of a sample in the core's sign (a charge's mirrored)."""
        if self._suspect is not None:
            return self._push_after_suspect(t, p)
        if self._held is not None:
            return self._push_after_step(t, p)
        st = self._st
        if not (t - st.last_t >= MIN_STAMP_STEP and abs(t) <= MAX_ABS_STAMP):  # and NaN
            return self._reject(t, p)
        if p != p or p in (math.inf, -math.inf):
            st.diag("warn", f"non-finite pressure sample {p!r} at t={t:.6f} s ignored", t)
            return []
        if t - st.last_t > st.gap_limit:
            self._on_gap(t)
        st.last_t = t
        i = self._append(t, p)
        # a periodic check, or decisions.below(p, level) inlined (the hot path)
        if i == st.next_check or p < st.level:
            out = STEPS[st.mode](st, i)
            if out:
                self._emit(out)
            return out
        return []

    def push_block(self, t: ArrayLike, p: ArrayLike) -> list[UnloadResult]:
        """Feed a block of samples; same results as calling :meth:`push` on each.

        Parameters
        ----------
        t : array_like
            Sample instants [s].
        p : array_like
            Pressures [Pa absolute] (or raw signal, see :meth:`push`).

        Returns
        -------
        list of UnloadResult
            Results completed inside the block.
        """
        p = np.asarray(p, dtype=float).ravel()
        out = self._push_block(np.asarray(t, dtype=float).ravel(), -p if self._mirror else p)
        st = self._st
        if st.live and st.mode == UNLOADING and not out:  # the crossing kept in the caches
            rehearse_crossing(st.unload.plan)
        return out

    def _push_block(self, t: FloatArray, p: FloatArray) -> list[UnloadResult]:
        """:meth:`push_block` of samples in the core's sign (a charge's mirrored)."""
        if t.shape != p.shape:
            raise EstimationError(f"t and p differ in length: {t.size} vs {p.size}")
        if t.size == 0:
            return []
        if self._suspect is not None and t[0] == t[0] and abs(t[0]) <= MAX_ABS_STAMP:
            return self._resolve_suspect(float(t[0])) + self._push_block(t, p)
        if self._held is not None:  # after a clock step: sample by sample until re-synced
            return self._push_slow(t, p)
        st = self._st
        # validity: finite, each stamp at least MIN_STAMP_STEP after the one before (the
        # last accepted stamp for the first): then the steps are the gaps too; one compiled
        # call (on the live crossing's path, where each numpy call after an idle wait pays
        # for cold caches)
        last_t = st.last_t
        shortest, longest, finite, extent = block_steps(t, p, last_t)
        if not (shortest >= MIN_STAMP_STEP and finite  # a NaN step: not >=
                and extent <= MAX_ABS_STAMP):
            return self._push_slow(t, p)
        out: list[UnloadResult] = []
        k, size = 0, t.size
        d: FloatArray | None = None  # the steps, made only for a block with a gap
        while k < size:
            if math.isnan(st.dt_nominal):
                # sample by sample until the nominal period (and so the gap limit) is known
                out += self._push(float(t[k]), float(p[k]))
                k += 1
                continue
            if not longest > st.gap_limit:  # no gap in the block
                out += self._push_fast(t[k:], p[k:])
                break
            if d is None:
                d = np.diff(t, prepend=last_t)
            gaps = np.flatnonzero(d[k:] > st.gap_limit)
            if gaps.size and gaps[0] == 0:
                out += self._push(float(t[k]), float(p[k]))  # diagnoses the gap
                k += 1
                continue
            g = k + int(gaps[0]) if gaps.size else size
            out += self._push_fast(t[k:g], p[k:g])
            k = g
        return out

    def finish(self) -> list[UnloadResult]:
        """End of stream: report an unload still pending (aborted, or crossing not reached).

        Returns
        -------
        list of UnloadResult
            The pending unload's result, if any.
        """
        st = self._st
        if self._suspect is not None:  # the last sample: one out of order
            self._resolve_suspect(math.inf)
        u = st.unload
        n = len(st.buf)
        out: list[UnloadResult] = []
        if st.mode == UNLOADING and follow.lost_at_end(st, n - 1):
            st.to_waiting(n)  # a fall that nothing followed: no unload to report
        if st.mode == RECOVERY:
            out.append(sse.abort_result(st, n - 1, recovered=False))
            out[-1].final = True
        elif st.mode == UNLOADING and unloading.end_plateau_auto(st, n - 1):
            # p_atm from the final samples (short record, e.g. 1 Hz): crossing, then tail
            out += unloading.check_final_plateau_auto(st, n - 1, at_end=True)
            if st.mode == TAIL and st.unload.pending is not None:
                out += tail.finish_tail(st, n - 1, ended=True)
        elif st.mode == UNLOADING:
            auto = u.refined and not math.isfinite(u.pstar)
            text = (f"stream ended before the final plateau: {st.end_unknown()}" if auto
                    else "stream ended before the p* crossing")
            st.diag("warn", text, st.last_t)
            out.append(sse.abort_result(st, n - 1, recovered=False, text=text))
        elif st.mode == TAIL and u.pending is not None:
            out += tail.finish_tail(st, n - 1, ended=True)
        st.to_waiting(n)
        self._emit(out)
        return out

    # ------------------------------------------------------------------ block path
    def _push_fast(self, t: FloatArray, p: FloatArray) -> list[UnloadResult]:
        """Block of finite, increasing samples without gaps: jump between decisions.

        The periodic checks that change nothing but the running statistics are evaluated
        for many check indices at once (:meth:`_scan`), with the same decision functions
        as the phase steps evaluate them one by one; the step runs only where something
        may happen.
        """
        st = self._st
        buf = st.buf
        out: list[UnloadResult] = []
        start = len(buf)
        buf.extend(t, p)
        st.last_t = float(t[-1])
        end = len(buf)
        i = start
        while i < end:
            j = self._scan(i, min(end, i + SCAN_HORIZON))
            if j >= end:
                break
            if j >= i + SCAN_HORIZON:  # horizon reached without a decision
                i = j
                continue
            shift = buf.shift
            done = STEPS[st.mode](st, j)
            if done:
                self._emit(done)
                out += done
            trimmed = buf.shift - shift
            i, end = j + 1 - trimmed, end - trimmed
        return out

    def _emit(self, out: list[UnloadResult]) -> None:
        """Results just completed: vetted (:func:`~.vetting.vet`), kept in
        :attr:`results`, handed to :attr:`on_result`."""
        for r in out:
            vet(r, self._st.settings)
        self.results += out
        if self.on_result is not None:
            for r in out:
                self.on_result(r)

    def _scan(self, i: int, end: int) -> int:
        """Next index in [i, end) where the phase's step must run (end: none).

        Checks before that index that decide nothing have their effect (running
        statistics, next check index) applied by the phase's scan, exactly as its step
        would.
        """
        st = self._st
        mode = st.mode
        if st.next_check < i:
            st.next_check = i  # cannot happen; keeps the scan safe
        if mode == WAITING and not math.isnan(st.dt_nominal):
            return detector.scan_waiting(st, i, end)
        if mode == UNLOADING and (not st.unload.refined or math.isfinite(st.unload.pstar)):
            return unloading.scan_unloading(st, i, end)
        if mode == TAIL:
            return tail.scan_tail(st, i, end)
        if mode == RECOVERY:
            return sse.scan_recovery(st, i, end)
        if mode == SKIP:
            return tail.scan_skip(st, i, end)
        # any other phase: the next periodic check or level trigger
        nc = st.next_check
        j = first_below_in(st.buf.p, i, min(end, nc), st.level)
        if j < min(end, nc):
            return j
        return nc if nc < end else end

    def _push_slow(self, t: FloatArray, p: FloatArray) -> list[UnloadResult]:
        out: list[UnloadResult] = []  # push() records them in self.results
        for ti, pi in zip(t.tolist(), p.tolist(), strict=True):
            out += self._push(ti, pi)
        return out

    def _on_gap(self, t: float) -> None:
        st = self._st
        gap = t - st.last_t
        st.diag("warn", f"gap of {gap:.6f} s in the samples before t={t:.6f} s", t)
        if st.mode in (CONFIRM, UNLOADING):
            st.gap_in_unload = True
