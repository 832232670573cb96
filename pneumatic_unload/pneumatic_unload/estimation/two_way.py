# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Charges and discharges of one component in one stream (``direction`` 'both').

A cycle that fills a tank through the component from a supply and empties it through the
same component to the room (ISO 6358-2 measures a component both ways) is one stream with
steps in both directions. :class:`TwoWayEstimator` feeds every sample to two streaming
estimators, one per direction (:meth:`~pneumatic_unload.config.estimator.
EstimatorSettings.one_way`): each detects its own steps (a discharge's estimator takes a
rise for a new plateau, a charge's a fall) and analyses them as the one-way estimator does,
so each step's numbers are those of a one-way stream. Their results are numbered in one
sequence, in the order they first appear (a step's crossing and final results share its
number); their diagnostics go into one log, the charge's estimator's marked 'charge: '
(an input problem, which both see, is said by each). Times in s, pressures in Pa absolute.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

from numpy.typing import ArrayLike

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.buffer import ReadingLog
from pneumatic_unload.estimation.history import DiagnosticLog
from pneumatic_unload.estimation.streaming import StreamingEstimator
from pneumatic_unload.estimation.tail import FinalFit
from pneumatic_unload.estimation.types import UnloadResult

#: The flow directions, in the order their estimators see each sample.
DIRECTIONS = ("discharge", "charge")
#: Put before the charge's estimator's diagnostics.
CHARGE_TAG = "charge: "


class TwoWayEstimator:
    """The streaming estimator of a stream of charges and discharges (see the module).

    Parameters
    ----------
    settings : EstimatorSettings
        With ``direction`` 'both'; the supply's fields are the charges'.
    live, defer_final_fit : bool
        As :class:`~pneumatic_unload.estimation.streaming.StreamingEstimator`'s.
    """

    def __init__(self, settings: EstimatorSettings, *, live: bool = False,
                 defer_final_fit: bool = False) -> None:
        if settings.direction != "both":
            raise EstimationError(f"TwoWayEstimator is for direction 'both', got "
                                  f"{settings.direction!r}")
        self._settings = settings
        #: The diagnostics of both directions (a bounded log; the charge's marked).
        self.diagnostics = DiagnosticLog()
        self._one = {d: StreamingEstimator(settings.one_way(d), live=live,
                                           defer_final_fit=defer_final_fit,
                                           diagnostics=self.diagnostics,
                                           tag=CHARGE_TAG if d == "charge" else "")
                     for d in DIRECTIONS}
        for d, est in self._one.items():
            est.on_result = self._forwarder(d)
            # both ways in turn: a stream may start at either end pressure (no unload
            # missed: the other direction's comes next)
            est._st.start_checked = True
        self._number: dict[tuple[str, int], int] = {}
        #: Called with each result as soon as it is complete (see the one-way estimator's).
        self.on_result: Callable[[UnloadResult], None] | None = None

    # ------------------------------------------------------------------ public API
    @property
    def settings(self) -> EstimatorSettings:
        """The settings in use (direction 'both'); a new value applies from each
        direction's next step."""
        return self._settings

    @settings.setter
    def settings(self, value: EstimatorSettings) -> None:
        if value.direction != "both":
            raise EstimationError(f"the direction of a stream is fixed ('both'): make a new "
                                  f"estimator for {value.direction!r}")
        for d, est in self._one.items():
            est.settings = value.one_way(d)
        self._settings = value

    @property
    def state(self) -> str:
        """The state of the direction with a step under way, else 'waiting'."""
        busy = [e.state for e in self._one.values() if e.state != "waiting"]
        return busy[0] if busy else "waiting"

    @property
    def n_samples(self) -> int:
        """Valid samples received so far [-]."""
        return self._one["discharge"].n_samples

    @property
    def temperature(self) -> ReadingLog:
        """The logged gas temperature's readings kept ([s], [K])."""
        return self._one["discharge"].temperature

    def push_temperature(self, t: ArrayLike, temp: ArrayLike) -> None:
        """Feed readings of the logged gas temperature (stamps [s], values [K])."""
        for est in self._one.values():
            est.push_temperature(t, temp)

    def push(self, t: float, p: float) -> list[UnloadResult]:
        """Feed one sample (t [s], p [Pa absolute or signal]); the results it completes."""
        return self._in_order([(d, r) for d, est in self._one.items() for r in est.push(t, p)])

    def push_block(self, t: ArrayLike, p: ArrayLike) -> list[UnloadResult]:
        """Feed a block of samples; the results completed inside it (both directions', in
        the order of their steps' starts)."""
        return self._in_order([(d, r) for d, est in self._one.items()
                               for r in est.push_block(t, p)])

    def finish(self) -> list[UnloadResult]:
        """End of stream: each direction's step still pending."""
        return self._in_order([(d, r) for d, est in self._one.items() for r in est.finish()])

    def take_final_fits(self) -> list[FinalFit]:
        """The final-fit jobs of both directions, their crossings numbered as published."""
        return [dataclasses.replace(job, crossing=self._numbered(d, job.crossing))
                for d, est in self._one.items() for job in est.take_final_fits()]

    # ------------------------------------------------------------------ numbering
    def _in_order(self, got: list[tuple[str, UnloadResult]]) -> list[UnloadResult]:
        """Results of both directions completed in one call, numbered: steps not seen
        before in the order of their starts (a step without one last), so that a block
        holding several steps numbers them as the samples one by one do."""
        got.sort(key=lambda x: (x[1].t_start if x[1].t_start == x[1].t_start else math.inf,
                                x[1].t_complete))
        return [self._numbered(d, r) for d, r in got]

    def _numbered(self, direction: str, r: UnloadResult) -> UnloadResult:
        """``r`` with its number in the stream's one sequence."""
        key = (direction, r.index)
        if key not in self._number:
            self._number[key] = len(self._number)
        return dataclasses.replace(r, index=self._number[key])

    def _forwarder(self, direction: str) -> Callable[[UnloadResult], None]:
        def forward(r: UnloadResult) -> None:
            if self.on_result is not None:
                self.on_result(self._numbered(direction, r))
        return forward


def stream_estimator(settings: EstimatorSettings, *, live: bool = False,
                     defer_final_fit: bool = False) -> StreamingEstimator | TwoWayEstimator:
    """The streaming estimator of ``settings``: one-way, or :class:`TwoWayEstimator` for
    ``direction`` 'both' (what :func:`~pneumatic_unload.estimation.analyze`, the chunked
    analysis and the estimator node make)."""
    if settings.direction == "both":
        return TwoWayEstimator(settings, live=live, defer_final_fit=defer_final_fit)
    return StreamingEstimator(settings, live=live, defer_final_fit=defer_final_fit)
