# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A live stream whose unload begins at a given opening: the start is not detected.

The estimator node's ``start_time`` mode (a record that begins at the valve opening, as
``analyze --start-time``): the samples from ``settings.start_time`` on are kept; when one
falls to p* the crossing estimate is made by the library's opening-start path
(:func:`~pneumatic_unload.estimation.sparse.analyze_from_start` on the samples so far, no
curve fit); the final estimate is the same path on the samples up to where the record
settles (:func:`~pneumatic_unload.estimation.sparse.settle_index`: the rule the offline
analysis applies, so that live and offline analyse the same samples), or on every sample
received when the stream ends first (:meth:`OpeningStartEstimator.finish`). One unload per
start time: later samples are ignored (a new ``start_time`` starts a new estimator). A
charge (``direction`` 'charge', its ``supply_pressure`` given) rises to its p* and settles
at the supply.

The interface is the one the node uses of
:class:`~pneumatic_unload.estimation.streaming.StreamingEstimator` (push, push_block,
finish, take_final_fits, state, settings, diagnostics). SI units: s, Pa absolute.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload import physics
from pneumatic_unload.charge import charge_p_star
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.buffer import ReadingLog
from pneumatic_unload.estimation.history import DiagnosticLog
from pneumatic_unload.estimation.sparse import (
    SETTLE_FRACTION,
    analyze_from_start,
    initial_pressure,
    settle_scan,
    start_tolerance,
)
from pneumatic_unload.estimation.types import Diagnostic, UnloadResult


@dataclass(frozen=True)
class OpeningFinal:
    """The final estimate of an unload that began at the given opening, as a job (run
    later, e.g. on the node's worker thread): the crossing result and the samples [s],
    [signal units] from which :func:`analyze_from_start` makes it."""

    crossing: UnloadResult
    t: np.ndarray
    p: np.ndarray
    settings: EstimatorSettings
    #: The logged gas temperature's readings over the samples ([s], [K]), or None.
    temperature: tuple[np.ndarray, np.ndarray] | None = None

    def window(self) -> tuple[float, float]:
        """The samples' span [s]."""
        return float(self.t[0]), float(self.t[-1])

    @property
    def t_end(self) -> float:
        """The last sample's instant [s]."""
        return float(self.t[-1])

    def with_temperature(self, log: ReadingLog) -> OpeningFinal:
        """This job with the readings of ``log`` over its :meth:`window` (see
        :meth:`~.buffer.ReadingLog.span`; None without any)."""
        return dataclasses.replace(self, temperature=log.span(*self.window()))

    def run(self) -> UnloadResult | None:
        """The final (curve-fit) result, or None when the fit did not give one."""
        out = analyze_from_start(self.t, self.p, self.settings, temperature=self.temperature)
        return out[-1] if out[-1].final else None


def check_opening_settings(settings: EstimatorSettings) -> None:
    """Refuse settings the opening-start mode cannot use (EstimationError, with what to
    pass)."""
    if settings.start_time is None:
        raise EstimationError("the opening-start mode needs start_time [s, record clock]")
    if settings.direction == "both":
        raise EstimationError("a start time begins one step: give its direction (charge or "
                              "discharge), not 'both'")
    if settings.charge and settings.supply_pressure is None:
        raise EstimationError("start_time with a charge needs the supply (a record that "
                              "begins at the opening need not end on its plateau): set "
                              "supply_pressure [Pa]")
    if settings.atmosphere is None and not settings.charge:
        raise EstimationError("start_time needs the atmosphere (a record that begins at the "
                              "opening need not end on a plateau): set atmosphere [Pa]")


class OpeningStartEstimator:
    """Live estimator of the unload that begins at ``settings.start_time`` (see the module
    docstring)."""

    def __init__(self, settings: EstimatorSettings) -> None:
        check_opening_settings(settings)
        self._settings = settings
        self._t = np.empty(1024)
        self._p = np.empty(1024)
        self._n = 0
        self._mode = "waiting"
        self._p10 = math.nan
        self._p_star = math.nan
        self._crossing: UnloadResult | None = None
        self._run = 0  # consecutive settled samples after the crossing
        self._jobs: list[OpeningFinal] = []
        #: The logged gas temperature's readings ([s], [K]; :meth:`push_temperature`).
        self.temperature = ReadingLog()
        #: Diagnostics (a bounded :class:`~.history.DiagnosticLog`).
        self.diagnostics = DiagnosticLog()

    @property
    def settings(self) -> EstimatorSettings:
        """The settings in use (a change takes a new estimator: one unload per start)."""
        return self._settings

    @settings.setter
    def settings(self, value: EstimatorSettings) -> None:
        check_opening_settings(value)
        if value.start_time != self._settings.start_time or self._mode != "waiting":
            raise EstimationError("a new start_time (or settings during an unload) takes a "
                                  "new OpeningStartEstimator")
        self._settings = value

    @property
    def state(self) -> str:
        """'waiting' (before the start time), 'unloading' (before p*), 'tail' (after the
        crossing, until the record settles), 'done' or 'error'."""
        return self._mode

    def take_final_fits(self) -> list[OpeningFinal]:
        """The final-estimate jobs made since the last call (at most one)."""
        jobs, self._jobs = self._jobs, []
        return jobs

    def push_temperature(self, t: ArrayLike, temp: ArrayLike) -> None:
        """Feed readings of the logged gas temperature (stamps [s, record clock], values
        [K]): fitted beside the pressure by the final fit."""
        self.temperature.add(np.atleast_1d(np.asarray(t, dtype=float)),
                             np.atleast_1d(np.asarray(temp, dtype=float)))

    def push(self, t: float, p: float) -> list[UnloadResult]:
        """Feed one sample (t [s, record clock], p [signal units]); the crossing result
        when this sample completes it."""
        return self.push_block(np.array([t], dtype=float), np.array([p], dtype=float))

    def push_block(self, t: ArrayLike, p: ArrayLike) -> list[UnloadResult]:
        """Feed samples (t [s], p [signal units]); the crossing result when they complete
        it (the final one is a job: :meth:`take_final_fits`)."""
        if self._mode in ("done", "error"):
            return []
        s = self._settings
        t = np.asarray(t, dtype=float).ravel()
        p = np.asarray(p, dtype=float).ravel()
        start = float(s.start_time)  # type: ignore[arg-type]
        keep = t >= start - start_tolerance(start)
        if not np.any(keep):
            return []
        first = self._n
        self._append(t[keep], p[keep])
        if self._mode == "waiting":
            self._mode = "unloading"
        pa = s.signal_offset + s.signal_gain * self._p[first:self._n]
        ok = np.isfinite(pa) & np.isfinite(self._t[first:self._n])
        out: list[UnloadResult] = []
        if self._crossing is None:
            if not math.isfinite(self._p10) and not self._find_p10():
                return []
            # p* reached: fallen to it (a discharge), risen to it (a charge)
            sign = -1.0 if s.charge else 1.0
            below = np.flatnonzero(ok & (sign * pa <= sign * self._p_star))
            if below.size == 0:
                return []
            try:
                (res,) = analyze_from_start(self._t[:self._n], self._p[:self._n],
                                            dataclasses.replace(s, curve_fit=False))
            except EstimationError as exc:
                return self._fail(f"no estimate from the start time: {exc}")
            self._crossing = res
            self._mode = "tail"
            out.append(res)
            after = first + int(below[0]) + 1  # the settle rule counts after the crossing
            pa, ok = pa[after - first:], ok[after - first:]
            first = after
        end = float(s.end_pressure)  # type: ignore[arg-type]
        idx = np.flatnonzero(ok)
        hit, self._run = settle_scan(pa[idx], SETTLE_FRACTION * abs(self._p10 - end), end,
                                     self._run)
        if hit is not None:
            self._close(first + int(idx[hit]) + 1)
        return out

    def finish(self) -> list[UnloadResult]:
        """End of stream: an unload past its crossing that has not settled gets its final
        job on every sample received; one that never reached p* is reported."""
        if self._mode == "tail":
            self._close(self._n)
        elif self._mode == "unloading":
            how = "rose" if self._settings.charge else "fell"
            self._diagnose("warn", f"the stream ended before the record {how} to p* "
                                   f"({self._p_star:.0f} Pa): no estimate")
            self._mode = "done"
        return []

    # ------------------------------------------------------------------ internals
    def _append(self, t: np.ndarray, p: np.ndarray) -> None:
        need = self._n + t.size
        if need > self._t.size:
            size = max(need, 2 * self._t.size)
            self._t = np.resize(self._t, size)
            self._p = np.resize(self._p, size)
        self._t[self._n:need] = t
        self._p[self._n:need] = p
        self._n = need

    def _find_p10(self) -> bool:
        """p10 and p* from the settings or the sample at the start time; False (and the
        error reported) when neither is there."""
        s = self._settings
        pa = s.signal_offset + s.signal_gain * self._p[:self._n]
        ok = np.isfinite(pa) & np.isfinite(self._t[:self._n])
        try:
            p10 = initial_pressure(self._t[:self._n][ok], pa[ok], s)[0]
        except EstimationError as exc:
            self._fail(str(exc))
            return False
        end = float(s.end_pressure)  # type: ignore[arg-type]
        if s.charge and not end > p10:
            self._fail(f"the supply ({end:.0f} Pa) is not above p10 ({p10:.0f} Pa): nothing "
                       "to charge")
            return False
        if not s.charge and not p10 > end:
            self._fail(f"p10 ({p10:.0f} Pa) is not above p_atm ({end:.0f} Pa)")
            return False
        self._p10 = p10
        self._p_star = charge_p_star(p10, end) if s.charge else physics.p_star(p10, end)
        return True

    def _close(self, n: int) -> None:
        """The final job on the first n samples."""
        assert self._crossing is not None
        if self._settings.curve_fit:
            job = OpeningFinal(self._crossing, self._t[:n].copy(), self._p[:n].copy(),
                               self._settings)
            self._jobs.append(job.with_temperature(self.temperature))
        self._mode = "done"

    def _fail(self, message: str) -> list[UnloadResult]:
        self._diagnose("error", message)
        self._mode = "error"
        return []

    def _diagnose(self, level: str, message: str) -> None:
        t = float(self._t[self._n - 1]) if self._n else math.nan
        self.diagnostics.append(Diagnostic(level=level, state=self._mode, message=message,
                                           t=t))
