# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Stamps that do not follow: a sample out of order, a duplicate, a clock stepped back.

:class:`StampChecks` is the part of :class:`~.streaming.StreamingEstimator` that decides
what a sample whose stamp is not after the last accepted one is: one sample out of order
(dropped alone), or the first of a clock step back (the unload under way reported, the
samples on the new clock held until CLOCK_RESYNC of them follow one another, then the
stream re-synced on that clock). Times in s, values in the core's signal units.
"""

from __future__ import annotations

import math

from pneumatic_unload.estimation import sse, tail
from pneumatic_unload.estimation.buffer import ReadingLog
from pneumatic_unload.estimation.decisions import PERIOD
from pneumatic_unload.estimation.state import (
    CONFIRM,
    RECOVERY,
    SKIP,
    TAIL,
    UNLOADING,
    WAITING,
    EstimatorState,
)
from pneumatic_unload.estimation.types import UnloadResult

#: Largest stamp magnitude accepted [s]: a stamp must fit ROS's int64 nanoseconds (year
#: 2262); larger ones (a clock in ns or us read as s, garbage) are ignored with a diagnostic.
MAX_ABS_STAMP = 9.2e9
#: Smallest stamp step accepted [s] (ROS stamps are whole nanoseconds): a closer stamp is
#: a duplicate (and the estimator's rates 1/dt stay finite).
MIN_STAMP_STEP = 0.5e-9
#: Consecutive samples after a clock step back that must follow one another on the new
#: clock (each one stamp step of at least MIN_STAMP_STEP and at most the gap limit after
#: the one before) before the stream re-syncs on that clock [-]. A transport that reorders
#: (best effort, two publishers) displaces a sample or a few, never hundreds in a row on
#: one time base; 256 samples are a quarter of a second at 1 kHz, so that a clock stepped
#: back (NTP, a PLC's clock set) costs that and not the whole step (an hour of samples
#: dropped for a 1 h step).
CLOCK_RESYNC = 256


class StampChecks:
    """The stamp checks of the streaming estimator (see the module docstring); the
    estimator provides :attr:`_st`, :meth:`_push` and :meth:`_emit`."""

    _st: EstimatorState
    #: A stamp that went back by more than the gap limit [s] (None: none), and its value.
    _suspect: float | None
    _suspect_p: float
    #: After a clock step back: the samples (t [s], p) on the new clock (None: none).
    _held: list[tuple[float, float]] | None

    def _push(self, t: float, p: float) -> list[UnloadResult]:
        raise NotImplementedError  # the estimator's

    def _emit(self, out: list[UnloadResult]) -> None:
        raise NotImplementedError  # the estimator's

    def _reject(self, t: float, p: float) -> list[UnloadResult]:
        """A sample whose stamp t [s] is NaN or not after the last one: ignored; a step back
        of more than the gap limit is a clock step (:meth:`_on_clock_step`)."""
        st = self._st
        if t != t:
            st.diag("warn", "sample with a NaN stamp ignored", t)
        elif not abs(t) <= MAX_ABS_STAMP:
            st.diag("warn", f"stamp t={t!r} s beyond +-{MAX_ABS_STAMP:g} s ignored (a clock "
                    "in ns or us read as s?)", math.nan)
        elif abs(t - st.last_t) < MIN_STAMP_STEP:
            st.diag("warn", f"duplicate stamp t={t:.9f} s ignored", t)
        elif self._held is not None:
            return self._hold(t, p)
        else:
            accepted = len(st.buf) + st.buf.shift
            if st.last_t - t > st.gap_limit and accepted != st.clock_step_at:
                # one sample out of order, or a clock step: the next decides
                self._suspect, self._suspect_p = t, p
                return []
            st.diag("warn", f"stamp going backwards ({t:.9f} s after {st.last_t:.9f} s)"
                    " ignored", t)
        return []

    def _push_after_suspect(self, t: float, p: float) -> list[UnloadResult]:
        """:meth:`push` of the sample after a suspect stamp: the suspect resolved first
        (a NaN or out-of-range stamp decides nothing: rejected, the suspect kept)."""
        if t != t or not abs(t) <= MAX_ABS_STAMP:
            return self._reject(t, p)
        out = self._resolve_suspect(t)
        return out + self._push(t, p)

    def _resolve_suspect(self, t: float) -> list[UnloadResult]:
        """Decide what the suspect stamp was, from the next stamp t [s] (inf: the stream
        ended). A next stamp after the last accepted one continues the time base: the
        suspect was one sample out of order (a best-effort transport, two publishers), and
        dropping it costs that sample alone. A next stamp behind it too: the clock stepped
        back (:meth:`_on_clock_step`)."""
        st = self._st
        ts = self._suspect
        assert ts is not None
        self._suspect = None
        if t - st.last_t >= MIN_STAMP_STEP:
            st.diag("warn", f"one sample out of order dropped: its stamp goes backwards "
                    f"{st.last_t - ts:.6g} s (t={ts:.9f} s after {st.last_t:.9f} s), the "
                    "next stamp continues the time base", ts)
            return []
        st.clock_step_at = len(st.buf) + st.buf.shift
        # the step: from the expected next stamp (one nominal period on) to ts
        out = self._on_clock_step(st.last_t + st.dt_nominal - ts, ts)
        self._emit(out)
        self._held = [(ts, self._suspect_p)]  # the new clock's first sample
        return out

    def _push_after_step(self, t: float, p: float) -> list[UnloadResult]:
        """:meth:`push` of a sample after a clock step back: a stamp past the last accepted
        one (the clock came back to the old time base) is taken as usual, the samples
        held on the new clock dropped; an earlier one is held (:meth:`_hold`)."""
        st = self._st
        if t == t and abs(t) <= MAX_ABS_STAMP and t - st.last_t >= MIN_STAMP_STEP:
            held = self._held
            self._held = None
            if held:
                st.diag("warn", f"the clock came back past {st.last_t:.6f} s: the "
                        f"{len(held)} samples held on the stepped clock are dropped", t)
            return self._push(t, p)
        return self._reject(t, p)

    def _hold(self, t: float, p: float) -> list[UnloadResult]:
        """A sample (valid stamp t [s], behind the last accepted one) after a clock step
        back: held while the samples follow one another on the new clock; CLOCK_RESYNC of
        them re-sync the stream on it (:meth:`_resync`). A stamp that does not follow the
        one before starts the run again (no warning each: the step was reported once)."""
        held = self._held
        assert held is not None
        if not MIN_STAMP_STEP <= t - held[-1][0] <= self._st.gap_limit:
            held.clear()
        held.append((t, p))
        return self._resync() if len(held) >= CLOCK_RESYNC else []

    def _resync(self) -> list[UnloadResult]:
        """CLOCK_RESYNC samples have followed one another on the stepped clock: the stream
        goes on on that clock. The old time base's samples are dropped (no decision
        spans the step); the rest of an unload reported at the step is skipped, else the
        estimator waits for a new plateau as at a stream's start (live: an unload it joins
        mid-way is skipped); then the held samples are fed."""
        st = self._st
        held = self._held
        assert held is not None
        self._held = None
        t_new = held[0][0]
        st.diag("ok", f"re-synced on the stepped clock: {len(held)} samples follow one "
                f"another from t={t_new:.6f} s (the last before the step: "
                f"{st.last_t:.6f} s); the stream goes on from there", t_new)
        st.buf.trim(len(st.buf))
        st.temperature = ReadingLog()  # its stamps are the old time base's
        if st.mode == SKIP:
            # the unload under way at the step was reported (its result names the step):
            # the rest of it is skipped on the new clock as it was on the old one
            u = st.unload
            u.trigger = u.skip_since = 0
            st.next_check = PERIOD - 1
        else:
            st.to_waiting(0)
            st.stream_start = True  # live: an unload joined mid-way is skipped
            st.start_checked = not st.live
        st.last_t = t_new - st.dt  # the first held sample is no gap
        st.clock_step_at = -1
        out: list[UnloadResult] = []
        for ti, pi in held:
            out += self._push(ti, pi)
        return out

    def _on_clock_step(self, step: float, t: float) -> list[UnloadResult]:
        """The clock stepped back by ``step`` [s] (new stamp t [s]): the samples until it
        passes the last accepted stamp again are dropped, so the unload in progress has a
        hidden hole in its time base. Before its crossing it gets a 'bad_data' result; after
        it, the tail ends at the last good sample; then the rest of it is skipped."""
        st = self._st
        last = len(st.buf) - 1
        where = f"clock stepped back {step:.6g} s at t={st.last_t:.6f} s (next stamp {t:.6f} s)"
        st.diag("warn", f"{where}: the stream re-syncs on the new clock once "
                f"{CLOCK_RESYNC} samples follow one another on it (those are kept; the "
                f"clock passing {st.last_t:.6f} s again ends the wait)", t)
        mode = st.mode
        if mode in (CONFIRM, UNLOADING):
            return st.bad(last, f"{where} during the unload: its time base has a hole, "
                                "no estimate")
        if mode == TAIL:
            return tail.end_tail_and_skip(st, last, last, where + " in the tail: the tail "
                                          "ends there")
        if mode == RECOVERY:
            res = sse.abort_result(st, last, recovered=False, text=(
                f"valve closed before p*; {where} during the recovery: no SSE value"))
            res.final = True
            st.to_skip(last)
            return [res]
        if mode == WAITING:
            st.to_waiting(len(st.buf))  # the plateau starts again after the step
        return []
