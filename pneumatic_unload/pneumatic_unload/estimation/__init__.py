# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The unloading-time method as a streaming estimator (live node and offline analysis).

:class:`StreamingEstimator` is fed pressure samples one at a time (:meth:`push`) or in
blocks (:meth:`push_block`); both paths give bit-identical results, because every
decision is taken at a sample index from the samples up to that index only, with O(1)
statistics from running prefix sums (of p and of squared first differences), and the block
path evaluates the periodic checks that decide nothing for many indices at once with the
same decision functions (:mod:`.decisions`), calling a phase's step only where something
happens.
:func:`analyze` is the batch function over arrays (the block path on the whole trace).

Per unload it: detects the start of the step (trigger, confirmation, then a sub-sample
hinge fit of the valve-opening instant); takes p10 from the pre-step plateau and p_atm from
a parameter or the final plateau; computes p* (eq 40); finds the p* crossing by a local
quadratic regression (noise-robust, sub-sample); returns tau_exp and C by eq 39, plus the
model-based C that removes eq 39's known bias (exact inversion of the discharge model at
the crossing, then a full-curve fit once the unload has ended); reports an aborted unload
(valve closed before p*) and, when the re-heating after the closing is recorded (fitted
and, if unfinished, extrapolated with its uncertainty), the SSE value (eq 23); ends the
unload's tail when the tank is charged again and re-arms for the next unload.

Only relative values matter for tau_exp: the input may be any linear signal (volts) when
``signal_gain``/``signal_offset`` convert it, or when only tau_exp is wanted; p10, p_atm and
T10 must be absolute for C. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).

Modules (each one role): :mod:`.types` (settings, results, statuses, errors),
:mod:`.buffer` (samples and prefix sums), :mod:`.history` (the bounded diagnostics and
results kept), :mod:`.decisions` (each per-sample decision, once,
vectorised over check indices), :mod:`.state` (detector and per-unload state),
:mod:`.detector` (plateau, trigger, confirmation), :mod:`.unloading` (start fit, stall,
crossing), :mod:`.tail` (final plateau, curve fit), :mod:`.sse` (aborted unload, recovery,
eq 23), :mod:`.refine` (every call into :mod:`pneumatic_unload.curvefit.fitting`),
:mod:`.regression` (hinge, crossing and corner fits), :mod:`.streaming`
(:class:`StreamingEstimator`), :mod:`.batch` (:func:`analyze`, :func:`merge_final`) and
:mod:`.chunked` (:func:`analyze_chunks`: a record of any length, read in pieces) and
:mod:`.loss` (:class:`LossCounter`: samples missing from a live stream, from its stamps).
"""

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.batch import (
    analyze,
    explain_no_unload,
    gauge_evidence,
    gauge_suspicion,
    merge_final,
)
from pneumatic_unload.estimation.chunked import ChunkedAnalysis, analyze_chunks
from pneumatic_unload.estimation.history import RESULTS_KEPT, DiagnosticLog
from pneumatic_unload.estimation.loss import LossCounter
from pneumatic_unload.estimation.opening import OpeningFinal, OpeningStartEstimator
from pneumatic_unload.estimation.regression import corner_fit, crossing_fit, hinge_fit
from pneumatic_unload.estimation.sse import SSE_MODEL_REL_STD
from pneumatic_unload.estimation.streaming import StreamingEstimator
from pneumatic_unload.estimation.tail import FinalFit
from pneumatic_unload.estimation.two_way import TwoWayEstimator, stream_estimator
from pneumatic_unload.estimation.types import (
    ESTIMATE_STATUSES,
    SENSOR_FAULT_TEXTS,
    STATUS_ALIASES,
    STATUS_MEANINGS,
    STATUSES,
    STUCK_TEXT,
    Analysis,
    Diagnostic,
    FloatArray,
    UnloadResult,
    canonical_status,
    estimate_fields,
    recommended,
)

__all__ = [
    "ESTIMATE_STATUSES",
    "RESULTS_KEPT",
    "SENSOR_FAULT_TEXTS",
    "SSE_MODEL_REL_STD",
    "STATUSES",
    "STATUS_ALIASES",
    "STATUS_MEANINGS",
    "STUCK_TEXT",
    "Analysis",
    "ChunkedAnalysis",
    "Diagnostic",
    "DiagnosticLog",
    "EstimationError",
    "EstimatorSettings",
    "FinalFit",
    "FloatArray",
    "LossCounter",
    "OpeningFinal",
    "OpeningStartEstimator",
    "StreamingEstimator",
    "TwoWayEstimator",
    "UnloadResult",
    "analyze",
    "analyze_chunks",
    "canonical_status",
    "corner_fit",
    "crossing_fit",
    "estimate_fields",
    "explain_no_unload",
    "gauge_evidence",
    "gauge_suspicion",
    "hinge_fit",
    "merge_final",
    "recommended",
    "stream_estimator",
]
