# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``estimator`` node: the streaming unloading-time estimator on a live pressure topic.

Subscribes
    /tank/pressure (sensor_msgs/FluidPressure; parameter ``pressure_topic``), sensor-data QoS
        (best effort, deep queue) or reliable (``qos``); or blocks of samples
        (pneumatic_unload_msgs/PressureBlock) when ``input`` is 'block'; or an uncalibrated
        transducer's volts, /tank/pressure_volts (pneumatic_unload_msgs/Voltage; parameter
        ``volts_topic``) when ``input`` is 'volts' (converted with signal_gain [Pa/V] and
        signal_offset [Pa]).
    /tank/temperature (sensor_msgs/Temperature), when ``temperature_from_topic``: T10 is
        the gas temperature last received before the unload starts.
Publishes
    ~/estimate (pneumatic_unload_msgs/UnloadEstimate; reliable, transient local): the
        crossing estimate of each unload as soon as p* is crossed, then the final
        (full-curve fit) estimate once the unload's tail is recorded.
    ~/settings (std_msgs/String JSON, latched): the estimator settings in force, so that a
        recording reproduces the live estimates offline (``pneumatic-unload analyze``).
    /diagnostics (diagnostic_msgs/DiagnosticArray): state (waiting, unloading, done, error)
        and why, input problems (NaN, stamps going backwards, gaps, wrong frame), latency.
Start-time mode
    With ``start_time`` (the valve opening in the record's clock: the message stamps [s])
    and ``atmosphere`` set, the start is not detected: the node analyses the one unload that
    begins at start_time with the library's opening-start path (the one ``analyze
    --start-time`` and bag re-analysis use, so that live and offline give the same numbers;
    :class:`~pneumatic_unload.estimation.OpeningStartEstimator`). The crossing estimate is
    published when a sample falls to p*; the final estimate when the record settles (10
    consecutive samples within 0.5 % of p10 - p_atm from p_atm: the rule the offline
    analysis applies, on the same samples), or, when it never settles, once no sample has
    arrived for ``end_timeout`` s (the stream ended; also at shutdown). Later samples are
    ignored: a new start_time (a parameter change) analyses the next unload.
Action
    ~/measure (pneumatic_unload_msgs/action/Measure)
        arm, optionally open the valve through a std_srvs/Trigger service, report progress,
        return the estimate or fail clearly.

A PressureBlock is fed to the core's
:class:`~pneumatic_unload.estimation.StreamingEstimator` by the subscription callback at
once, which publishes the crossing estimate the moment the core completes it, before the
block's later samples are scanned (:attr:`~pneumatic_unload.estimation.StreamingEstimator.
on_result`; no hand-over to another thread on that path). Single FluidPressure samples (10
kHz: one message each) are only queued by the callback and fed by the worker thread, so
that the receiving thread keeps up with the message rate. The final curve fit of each
unload (tens of ms) is taken off the stream as a job (``defer_final_fit``) and run by the
worker, so it never blocks the reception of samples (none is dropped at 10 kHz with the
EventsExecutor) and gives the result the offline analysis gives.

Results database (``results_db``): each result is written by a thread of its own
(:class:`~pneumatic_unload.testline.live.ResultWriter`: a database that hangs stalls
neither the callbacks nor the fits), a crossing estimate at once (its final estimate
replaces it: a node killed before its final fit leaves the crossing's numbers).
Shutdown (SIGINT, SIGTERM, an error that ends the node): the queued samples are fed, an
unload under way is closed as at the end of a record (its final fit on the tail so far;
before p*, an 'aborted' result), published and written, marked as closed at shutdown;
what is not done within :data:`SHUTDOWN_WAIT` s is logged with its numbers.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import re
import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import FluidPressure, Temperature
from std_msgs.msg import String
from std_srvs.srv import Trigger

from pneumatic_unload.config import adapters
from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.estimation import (
    RESULTS_KEPT,
    EstimationError,
    EstimatorSettings,
    FinalFit,
    LossCounter,
    OpeningFinal,
    OpeningStartEstimator,
    StreamingEstimator,
    TwoWayEstimator,
    UnloadResult,
    estimate_fields,
    stream_estimator,
)
from pneumatic_unload.nodes import common
from pneumatic_unload.testline import ResultsDBError, SpecError, load_spec
from pneumatic_unload.testline.job import result_row
from pneumatic_unload.testline.live import LiveResults, PendingWrite, ResultWriter

#: Values of the ``input`` parameter: FluidPressure per sample, PressureBlock, Voltage.
INPUTS = ("sample", "block", "volts")
#: Node states reported on /diagnostics and in the action's feedback.
STATES = ("waiting", "unloading", "done", "error")
#: The start of the reason reported while the core skips the unload under way.
SKIPPING = "skipping the unload under way"
#: Most queued single samples fed to the core as one block [-] (the queue is drained in
#: such blocks; a block is the same decisions as its samples one by one).
MAX_BATCH = 4096
#: Longest wait [s] of a final fit, from its last sample's arrival, for the gas
#: temperature readings of its span (a slower topic; a topic that stopped is not waited
#: for longer) [s].
TEMPERATURE_WAIT = 2.0
#: Longest wait at shutdown [s] for the queued samples, the final fits (of the unload under
#: way, closed as at the end of a record, included) and the results database's writes:
#: what is not done by then is logged with its numbers. Within the 5 s ros2 launch gives a
#: node between SIGINT/SIGTERM and SIGKILL on two cores shared with a bench.
SHUTDOWN_WAIT = 4.0
#: A warning of one kind (its text's start, numbers aside) is logged at most once per this
#: interval [s] (every one goes on /diagnostics); another kind is logged at once.
LOG_THROTTLE = 1.0
#: Digits of a message (its kind, for LOG_THROTTLE, is its text without them).
_DIGITS = re.compile(r"\d+")
#: Note of a crossing estimate in the results database when a final estimate (its curve
#: fit) follows and replaces it: a node that dies before leaves the crossing's numbers.
CROSSING_NOTE = "crossing estimate (the final curve fit follows and replaces it)"
#: Note of a crossing estimate in the results database whose final fit was not done when
#: the node stopped (SHUTDOWN_WAIT).
UNFITTED_NOTE = ("crossing estimate: the final curve fit was not done at the estimator's "
                 "shutdown")
#: Note of an estimate in the results database whose unload was closed at the node's
#: shutdown (its tail, or its fall before p*, cut there).
STOPPED_NOTE = "closed at the estimator's shutdown (SIGINT/SIGTERM): the record ends there"

_OK, _WARN, _ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
#: The node's estimator: a stream's (one way, or both ways in turn) or a start time's.
Core = StreamingEstimator | TwoWayEstimator | OpeningStartEstimator


def fill_estimate(msg: Any, r: UnloadResult, frame_id: str) -> Any:
    """Fill an UnloadEstimate message from a result (NaN where unknown)."""
    f = estimate_fields(r, frame_id)
    common.ns_to_stamp(f.pop("header_stamp_ns"), msg.header.stamp)
    msg.header.frame_id = f.pop("frame_id")
    common.ns_to_stamp(f.pop("unload_start_ns"), msg.unload_start)
    for k, v in f.items():
        setattr(msg, k, v)
    return msg


def _warm_up(settings: EstimatorSettings) -> None:
    """Run the estimator once on a short synthetic unload, curve fit included, so that the
    first live estimate does not pay for lazy imports (the fit's whiteness test imports
    scipy.special: ~0.3 s) and first-call set-up."""
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.estimation import analyze
    from pneumatic_unload.model import simulate

    sim = simulate(RigConfig(volume=1e-3, conductance=2e-8, pre_time=0.3, duration=1.0,
                             noise_std=500.0, seed=0))
    analyze(sim.t, sim.measured, dataclasses.replace(
        settings, volume=1e-3, signal_gain=1.0, signal_offset=0.0, atmosphere=101325.0,
        initial_temperature=293.15, curve_fit=True, start_time=None, initial_pressure=None,
        direction="discharge", supply_pressure=None, supply_temperature=None))


class EstimatorNode(Node):
    """Live unloading-time estimator (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("estimator", **kwargs)
        from pneumatic_unload_msgs.action import Measure
        from pneumatic_unload_msgs.msg import PressureBlock, UnloadEstimate, Voltage

        self._Measure = Measure
        self._UnloadEstimate = UnloadEstimate
        # the one list of parameters (also --help and config/estimator.yaml)
        for name, (default, desc) in common.node_parameters("estimator").items():
            self.declare_parameter(name, default, desc)
        try:
            self._settings = self._settings_from({})
        except EstimationError as exc:
            raise common.StartupError("estimator", f"invalid parameters: {exc}") from exc
        for name, allowed in (("input", INPUTS),
                              ("qos", ("sensor_data", "reliable"))):
            if self._p(name) not in allowed:
                raise common.StartupError(
                    "estimator", f"{name} must be one of {allowed}, got {self._p(name)!r}")
        if self._p("input") == "volts" and self._settings.signal_gain == 1.0 \
                and self._settings.signal_offset == 0.0:
            # gain 1, offset 0 is the Pa input: volts taken as pascals give a wrong C
            raise common.StartupError(
                "estimator", "input:=volts needs the transducer's calibration: signal_gain "
                "[Pa/V] and signal_offset [Pa] (e.g. -p signal_gain:=1e5 -p signal_offset:=0.0 "
                "for 0-10 V over 0-10 bar absolute)")
        self.add_on_set_parameters_callback(common.validating_callback(self._check))
        # the test line: verdicts against a specification, estimates into a results database
        try:
            self._spec = load_spec(self._p("spec_file")) if self._p("spec_file") else None
            self._results_db = LiveResults(self._p("results_db"), self.get_name(),
                                           self._spec) if self._p("results_db") else None
        except (SpecError, ResultsDBError) as exc:
            raise common.StartupError("estimator", str(exc)) from exc
        #: The database's writes, off the callback and fit threads (a database that hangs
        #: stalls no estimate); drained at shutdown within SHUTDOWN_WAIT.
        self._writer = None if self._results_db is None else ResultWriter(
            self._results_db, self._written, self._write_failed)
        #: Warning texts' starts -> when last logged [s, monotonic] (LOG_THROTTLE).
        self._logged: dict[str, float] = {}
        #: Publishers on the pressure topic when last counted, and when [s, monotonic].
        self._pub_count: tuple[int, list[str]] = (0, [])
        self._pub_count_at = -math.inf
        #: The node is stopping with an unload under way (closed there: STOPPED_NOTE).
        self._stopping = False
        #: The final fit the worker runs now (None: none).
        self._fitting: FinalFit | OpeningFinal | None = None
        self._goal_part = ""  # the part id of the running ~/measure goal
        self._unload_parts: dict[int, str] = {}  # unload index -> a goal's part id
        if not common.stopping():  # a node stopped during its start does not warm up
            _warm_up(self._settings)
        # everything allocated so far (modules, the warm-up) is long-lived: out of the
        # collector's sight, so a full collection during an unload scans only what the run
        # allocates (a full scan of numpy/scipy/rclpy's objects took ~10 ms at a crossing)
        gc.collect()
        gc.freeze()
        # live: a node (re)started mid-unload skips that unload (no bogus estimate)
        self._arrived = self._pushed = time.monotonic()  # of the message being fed [s]
        #: Arrival of each queued single sample being fed [s], and the stream index of the
        #: first of them [-] (None, -1: a block is being fed).
        self._arrivals: list[float] | None = None
        self._base = -1
        try:
            self._est = self._new_core()
        except EstimationError as exc:
            raise common.StartupError("estimator", f"invalid parameters: {exc}") from exc
        self._lock = threading.Lock()  # the core (executor thread, parameter changes)
        self._pub_lock = threading.Lock()  # the published results (executor and fit worker)
        #: Final curve fits to run, with the arrival [s, monotonic] of the completing sample.
        self._fits: deque[tuple[FinalFit | OpeningFinal, float]] = deque()
        #: Arrival of the last sample [s, monotonic] (start-time mode: the stream's end).
        self._last_arrival = time.monotonic()
        #: Single samples (FluidPressure input) for the worker: stamp [ns], pressure [Pa],
        #: arrival [s, monotonic].
        self._samples: deque[tuple[int, float, float]] = deque()
        #: Stamp offsets of a PressureBlock [ns] by (size, sample period [s]).
        self._offsets: dict[tuple[int, float], np.ndarray] = {}
        #: A fresh UnloadEstimate made ahead of the next publication.
        self._spare = [UnloadEstimate()]
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._frame = self._p("frame_id")
        self._temperature = math.nan
        #: A gas temperature reading was received: final fits wait for the readings of
        #: their span (up to TEMPERATURE_WAIT s) before they run.
        self._temperature_seen = False
        self._state = "waiting"
        self._why = "no unload yet"
        #: The core skips the unload under way (no result for it): every reason reported
        #: while it waits says so, the periodic reports' too (a late subscriber's only ones).
        self._skipping = False
        self._last: UnloadResult | None = None
        self._last_pressure = math.nan
        self._n_diag = 0
        self._rejected = 0
        #: Samples missing from the input stream, counted from the stamps (a transport or a
        #: queue that did not keep up), and the count at the last report [-].
        self._loss = LossCounter()
        self._missing_reported = 0
        # [s] from the arrival of the completing sample to the publication: crossing
        # estimates, and final (curve-fit) estimates
        self.latencies: deque[float] = deque(maxlen=100_000)
        self.final_latencies: deque[float] = deque(maxlen=100_000)
        #: [s] CPU time of the fit worker's thread for each final fit (against its share of
        #: the latency: what the fit costs, and what waiting for the CPU or the GIL adds)
        self.fit_cpu: deque[float] = deque(maxlen=100_000)
        #: [s] the core's share of each crossing latency: from the start of the push (of
        #: the block) that completed it to the hand-over of the estimate
        self.crossing_push: deque[float] = deque(maxlen=100_000)
        #: [s] the node's share before that push (the message's arrival to the push: its
        #: conversion, the core's lock); the rest is the message fill and publication
        self.crossing_pre: deque[float] = deque(maxlen=100_000)
        self.received = 0
        #: The last RESULTS_KEPT results published (all are in ~/estimate and the bag):
        #: bounded, a node runs for days.
        self.results: deque[UnloadResult] = deque(maxlen=RESULTS_KEPT)
        self.n_results = 0  # results published [-]
        self._n_unloads = 0  # distinct unload indices published [-]
        qos = common.SENSOR_QOS if self._p("qos") == "sensor_data" \
            else common.LOSSLESS_INPUT_QOS
        if self._p("input") == "block":
            self.create_subscription(PressureBlock, self._p("block_topic"),
                                     self._on_block, qos)
        elif self._p("input") == "volts":
            self.create_subscription(Voltage, self._p("volts_topic"), self._on_volts, qos)
        else:
            self.create_subscription(FluidPressure, self._p("pressure_topic"),
                                     self._on_pressure, qos)
        # the gas temperature with the pressure's QoS: every reading of an unload's span
        # is fitted, a reader history of 10 would drop readings of a fast replay
        self.create_subscription(Temperature, "/tank/temperature", self._on_temperature, qos)
        self._pub_est = self.create_publisher(UnloadEstimate, "~/estimate", common.LATCHED_QOS)
        self._pub_settings = self.create_publisher(String, "~/settings", common.LATCHED_QOS)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pub_settings.publish(String(data=adapters.to_json(self._settings)))
        self._valve_client = None
        self._goal_lock = threading.Lock()
        self._active_goal = False
        ActionServer(self, Measure, "~/measure", execute_callback=self._execute,
                     goal_callback=self._on_goal, cancel_callback=lambda _g: CancelResponse.ACCEPT)
        self.create_timer(self._p("diagnostics_period"), self._report)
        # The receiving thread and the fit worker share the GIL: with the default 5 ms
        # switch interval the receiving thread could wait that long for it while a fit
        # runs; 0.5 ms keeps the reception (and a crossing during a fit) prompt at 10 kHz.
        sys.setswitchinterval(5e-4)
        self._worker = threading.Thread(target=self._work, name="estimator", daemon=True)
        self._worker.start()
        topic = self._input_topic()
        self.get_logger().info(
            f"estimating on {topic}"
            f" ({self._p('input')}, {self._p('qos')}):"
            f" V={self._settings.volume:g} m^3, T10={self._settings.initial_temperature:g} K,"
            f" p_atm={'auto' if self._settings.atmosphere is None else self._settings.atmosphere}"
            + ("" if self._settings.start_time is None else
               f"; start-time mode: the unload that begins at {self._settings.start_time!r} s"))

    # ------------------------------------------------------------------ parameters
    def _p(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _settings_from(self, changes: dict[str, Any]) -> EstimatorSettings:
        names = adapters.parameter_specs(EstimatorSettings)
        v = {n: self._p(n) for n in names}
        v.update({k: val for k, val in changes.items() if k in v})
        return EstimatorSettings(**adapters.from_parameters(EstimatorSettings, v))

    def _check(self, changes: dict[str, Any]) -> str:
        fixed = {"pressure_topic", "block_topic", "volts_topic", "input", "qos", "frame_id",
                 "diagnostics_period"}
        if fixed & set(changes):
            return f"{', '.join(sorted(fixed & set(changes)))} cannot change at run time"
        try:
            new = self._settings_from(changes)
        except EstimationError as exc:
            return str(exc)
        if new != self._settings:
            # start-time mode: one estimator per start time; a new direction: a new stream
            opening = new.start_time is not None or self._settings.start_time is not None \
                or new.direction != self._settings.direction
            with self._lock:
                idle = ("waiting", "done", "error") if opening else ("waiting",)
                if self._est.state not in idle:
                    return "an unload is being analysed; change settings when it is done"
                old = self._settings
                self._settings = new
                try:
                    self._est = self._new_core() if opening else self._est
                except EstimationError as exc:
                    self._settings = old
                    return str(exc)
                self._est.settings = new
                self._n_diag = 0 if opening else self._n_diag
            self._pub_settings.publish(String(data=adapters.to_json(new)))
        return ""

    # ------------------------------------------------------------------ input
    def _frame_ok(self, frame: str) -> bool:
        if self._frame and frame != self._frame:
            self._rejected += 1
            self._diagnose(_WARN, f"sample with frame_id {frame!r} ignored "
                           f"(expected {self._frame!r})")
            return False
        return True

    def _on_pressure(self, msg: FluidPressure) -> None:
        arrived = time.monotonic()
        if not self._frame_ok(msg.header.frame_id):
            return
        self._samples.append((common.stamp_to_ns(msg.header.stamp), msg.fluid_pressure,
                              arrived))
        self._wake.set()

    def _on_volts(self, msg: Any) -> None:
        """A Voltage sample [V]: the core converts it with signal_gain/signal_offset."""
        arrived = time.monotonic()
        if not self._frame_ok(msg.header.frame_id):
            return
        self._samples.append((common.stamp_to_ns(msg.header.stamp), msg.voltage, arrived))
        self._wake.set()

    def _input_topic(self) -> str:
        """The topic of the pressure input (``input``: sample, block or volts)."""
        return str(self._p({"block": "block_topic", "volts": "volts_topic"}.get(
            self._p("input"), "pressure_topic")))

    def _on_block(self, msg: Any) -> None:
        collect = gc.isenabled()  # no collection on the way to the push (see _feed)
        if collect:
            gc.disable()
        try:
            self._take_block(msg)
        finally:
            if collect:
                gc.enable()

    def _take_block(self, msg: Any) -> None:
        """A PressureBlock's samples into the core (:meth:`_feed`)."""
        if not self._frame_ok(msg.header.frame_id):
            return
        now = time.monotonic()
        ns0 = common.stamp_to_ns(msg.header.stamp)
        period = msg.sample_period
        if not (period > 0 and math.isfinite(period)):
            self._rejected += 1
            self._diagnose(_WARN, f"pressure block with sample_period {period!r} ignored")
            return
        p = np.asarray(msg.pressure, dtype=float)
        # the stamps of the per-sample path, ns0 + round(k T 1e9), for the whole block (the
        # offsets kept for the next block of the same size and period)
        key = (p.size, period)
        offsets = self._offsets.get(key)
        if offsets is None:
            if len(self._offsets) > 8:
                self._offsets.clear()
            offsets = self._offsets[key] = np.round(
                np.arange(p.size) * period * 1e9).astype(np.int64)
        self._feed(ns0 + offsets, p, now)  # the core takes the block vectorised

    def _on_temperature(self, msg: Temperature) -> None:
        t = msg.temperature + 273.15
        if not (math.isfinite(t) and t > 0):
            self._diagnose(_WARN, f"temperature {msg.temperature!r} degC ignored")
            return
        self._temperature = t
        stamp = common.ns_to_seconds(common.stamp_to_ns(msg.header.stamp))
        with self._lock:  # every reading is evidence for the final fits (the pressure's clock)
            self._est.push_temperature(stamp, t)
            self._temperature_seen = True
        if self._p("temperature_from_topic"):
            with self._lock:
                if self._est.state == "waiting" and abs(
                        t - self._settings.initial_temperature) > 1e-6:
                    self._settings = dataclasses.replace(self._settings, initial_temperature=t)
                    self._est.settings = self._settings
                    self._pub_settings.publish(String(data=adapters.to_json(self._settings)))

    # ------------------------------------------------------------------ the core
    def _feed(self, ns: Any, p: Any, arrived: float,
              arrivals: list[float] | None = None) -> None:
        """Samples into the core (stamps ``ns`` [ns], pressures ``p`` [Pa]: one sample, or
        arrays for a block), the results published at once, final fits to the worker.
        ``arrived``: monotonic arrival of the message [s]; ``arrivals``: each sample's
        [s] when the arrays are single samples queued by the callback (a result's latency
        is then counted from the arrival of the sample that completed it)."""
        est = self._est
        # no garbage collection inside the push: a crossing estimate published there pays
        # for none (a collection of the young objects, now and then an older generation);
        # the first allocation after it takes the collection due, off the latency
        collect = gc.isenabled()
        if collect:
            gc.disable()
        try:
            return self._push(est, ns, p, arrived, arrivals)
        finally:
            if collect:
                gc.enable()

    def _push(self, est: Core, ns: Any, p: Any,
              arrived: float, arrivals: list[float] | None) -> None:
        """:meth:`_feed` with the collector off."""
        try:
            with self._lock:
                prev = est.state
                self._arrived = arrived
                self._arrivals = arrivals
                self._base = -1 if isinstance(est, OpeningStartEstimator) else est.n_samples
                self._pushed = time.monotonic()
                if isinstance(p, np.ndarray):  # a PressureBlock
                    if not p.size:
                        return
                    out = est.push_block(ns * 1e-9, p)  # = common.ns_to_seconds per sample
                    self.received += p.size
                    p = float(p[-1])
                else:
                    out = est.push(common.ns_to_seconds(ns), p)
                    self.received += 1
                state = est.state
                jobs = est.take_final_fits()
        except Exception as exc:  # never silent, never fatal: report and start afresh
            self._restart_core(exc)
            return
        self._loss.update(ns)  # after the push: off the crossing estimate's latency
        self._last_pressure = p
        self._last_arrival = arrived if arrivals is None else arrivals[-1]
        if isinstance(est, OpeningStartEstimator):
            # start-time mode: its results are returned only (the streaming core's are
            # published at their hand-over, _on_core_result)
            for r in out:
                if not r.final:
                    self.crossing_push.append(time.monotonic() - self._pushed)
                    self.crossing_pre.append(self._pushed - arrived)
                self._publish_result(r, arrived)
        if not out and state != prev:
            self._on_state(state)
        if jobs:
            self._fits.extend((job, self._arrival_of(getattr(job, "i_complete", None)))
                              for job in jobs)
            self._wake.set()
        if est.diagnostics.total > self._n_diag:
            for dg in est.diagnostics.since(self._n_diag):
                level = {"ok": _OK, "warn": _WARN}.get(dg.level, _ERROR)
                message = dg.message
                if level != _OK:
                    self._rejected += 1
                    if "going backwards" in message or "out of order" in message:
                        message += self._sources_note()
                    if self._state == "waiting":  # the periodic report says it too
                        self._why = (f"{SKIPPING}: {message}" if self._skipping
                                     else message)
                self._diagnose(level, message)
            self._n_diag = est.diagnostics.total

    def _new_core(self) -> Core:
        """A streaming estimator with the node's settings: live (a stream joined mid-unload
        skips that unload), its final fits handed to the worker, each result published
        the moment it is complete (:meth:`_on_core_result`); with ``start_time``, the
        estimator of the unload that begins then (start-time mode)."""
        if self._settings.start_time is not None:
            return OpeningStartEstimator(self._settings)
        est = stream_estimator(self._settings, live=True, defer_final_fit=True)
        est.on_result = self._on_core_result
        return est

    def _on_core_result(self, r: UnloadResult) -> None:
        """A result completed inside the core's push (the block's later samples not yet
        processed): published now; the core's time to it into :attr:`crossing_push`."""
        arrived = self._arrival_of(r.i_complete)
        if not r.final:
            self.crossing_push.append(time.monotonic() - self._pushed)
            self.crossing_pre.append(self._pushed - arrived)
        try:
            self._publish_result(r, arrived)
        except Exception as exc:  # the core's push goes on: report, never fatal
            self._diagnose(_ERROR, f"could not publish unload {r.index}'s result: "
                                   f"{type(exc).__name__}: {exc}")

    def _arrival_of(self, index: int | None) -> float:
        """Monotonic arrival [s] of the sample of stream index ``index`` [-] in the samples
        being fed: the message's for a block; for queued single samples their own (a
        sample ignored as invalid shifts the count: the arrival taken is then an earlier
        one, never a later one; no index: the first sample's)."""
        arrivals = self._arrivals
        if arrivals is None or self._base < 0 or index is None:
            return self._arrived
        return arrivals[min(max(index - self._base, 0), len(arrivals) - 1)]

    def _count_publishers(self) -> tuple[int, list[str]]:
        """(publishers on the pressure topic, their node names), counted at most once a
        second (a graph query; the stamps' warnings come per sample)."""
        now = time.monotonic()
        if now - self._pub_count_at >= 1.0:
            self._pub_count_at = now
            topic = self._input_topic()
            try:
                infos = self.get_publishers_info_by_topic(topic)
                names = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                               for i in infos)
                self._pub_count = (len(infos), names)
            except Exception:  # the graph is advisory: keep the last count
                pass
        return self._pub_count

    def _sources_note(self) -> str:
        """What a stamp going backwards means when more than one node publishes the
        pressure topic ('' when one does)."""
        n, names = self._count_publishers()
        if n <= 1:
            return ""
        topic = self._input_topic()
        return (f"; {n} publishers on {topic} ({', '.join(names)}): two sources interleave "
                "their stamps (e.g. a simulator or a replay beside the rig); stop all but "
                "one")

    def _end_of_stream(self) -> None:
        """Start-time mode: an unload past p* that has not settled is closed (its final job
        queued) once no sample has arrived for ``end_timeout`` s, or at shutdown."""
        with self._lock:
            est = self._est
            if not isinstance(est, OpeningStartEstimator) or est.state != "tail":
                return
            est.finish()
            jobs = est.take_final_fits()
        if jobs:
            self._fits.extend((job, time.monotonic()) for job in jobs)
            self._wake.set()

    def _finish_stream(self) -> None:
        """Shutdown of a streaming estimator with an unload under way: it is closed as a
        record's end closes it (the crossing's final fit queued on the tail so far; before
        p*, an 'aborted' result), published and written, and said in the log."""
        with self._lock:
            est = self._est
            if isinstance(est, OpeningStartEstimator) or est.state in ("waiting",
                                                                        "skipping"):
                return
            state = est.state
            self._stopping = True
            self.get_logger().warn(f"stopping with an unload under way ({state}): it is "
                                   "closed as at the end of a record")
            try:
                est.finish()  # its results published through on_result
                jobs = est.take_final_fits()
            except Exception as exc:  # never lose the shutdown to it
                self.get_logger().error(f"stopping: the unload under way could not be "
                                        f"closed: {type(exc).__name__}: {exc}")
                return
        if jobs:
            self._fits.extend((job, time.monotonic()) for job in jobs)
            self._wake.set()

    def _restart_core(self, exc: Exception) -> None:
        """An internal error of the core: say so and go on with a fresh estimator, which
        skips the unload under way (live) and analyses the next ones."""
        self._diagnose(_ERROR, f"estimator error, restarted (the unload under way is "
                               f"skipped): {type(exc).__name__}: {exc}")
        self._state, self._why = "error", f"internal error: {exc}"
        with self._lock:
            self._est = self._new_core()
            self._n_diag = 0

    def _work(self) -> None:
        """The worker: feeds the queued single samples, and runs the final curve fits in
        order and publishes them (the samples first: a fit waits for a queue drained)."""
        samples = self._samples
        while True:
            if samples:
                # the queued samples as one block: push_block takes the decisions push
                # takes sample by sample (bit-identical), at a fraction of the cost
                batch = [samples.popleft() for _ in range(min(len(samples), MAX_BATCH))]
                try:
                    if len(batch) == 1:
                        self._feed(*batch[0])
                        continue
                    ns, p, arrivals = zip(*batch, strict=True)
                    self._feed(np.array(ns, dtype=np.int64), np.array(p, dtype=float),
                               arrivals[0], list(arrivals))
                except Exception as exc:  # after the core's push: report, the worker lives
                    self._diagnose(_ERROR, f"could not hand on the results of "
                                           f"{len(batch)} sample(s): "
                                           f"{type(exc).__name__}: {exc}")
                continue
            if not self._fits:
                if self._stop.is_set():
                    return
                self._wake.wait(0.1)
                self._wake.clear()
                continue
            job, arrived = self._fits[0]
            if not self._temperature_ready(job, arrived):
                self._wake.wait(0.01)  # the slower topic's readings of its span: not yet
                self._wake.clear()
                continue
            job, arrived = self._fits.popleft()  # with the readings of its span
            self._fitting = job
            try:
                cpu = time.thread_time()
                r = job.run()
                self.fit_cpu.append(time.thread_time() - cpu)
            except Exception as exc:  # never silent: report and keep the node alive
                self._diagnose(_ERROR, f"final curve fit of unload {job.crossing.index} "
                                       f"failed: {type(exc).__name__}: {exc}")
                continue
            finally:
                self._fitting = None
            if r is not None:
                self._publish_result(r, arrived)

    def _temperature_ready(self, job: Any, arrived: float) -> bool:
        """A final fit may run: no gas temperature is received, or every reading of its
        span has come in (:meth:`~.buffer.ReadingLog.complete`: they end half a second
        before its tail's, so they are in when the tail's last sample arrives; or
        TEMPERATURE_WAIT s passed since that arrival: a topic that stopped); the job then
        takes the readings of its span (as an analysis of the record takes them: live =
        offline)."""
        if not self._temperature_seen:
            return True
        with self._lock:
            log = self._est.temperature
            complete = log.complete(job.t_end)
            if not complete and time.monotonic() - arrived <= TEMPERATURE_WAIT:
                return False
            self._fits[0] = (job.with_temperature(log), arrived)
        if not complete:
            last = f"{log.t[-1]:.3f} s" if log.t.size else "none"
            self._diagnose(_WARN, f"unload {job.crossing.index}: the gas temperature's last "
                                  f"reading ({last}) is short of the end of its span "
                                  f"({job.t_end:.3f} s) after {TEMPERATURE_WAIT:g} s: its "
                                  "final fit takes the readings there are")
        return True

    def _on_state(self, core_state: str) -> None:
        if core_state == "waiting":
            return
        if core_state == "skipping":
            # no result for this unload (e.g. the node started mid-unload): say why
            why = next((d.message for d in reversed(self._est.diagnostics)
                        if d.level != "ok"), "no estimate for the unload under way")
            self._state, self._why, self._skipping = "waiting", f"{SKIPPING}: {why}", True
            self._report()
            return
        self._skipping = False
        self._state, self._why = "unloading", f"unload in progress ({core_state})"
        self._report()

    def _publish_result(self, r: UnloadResult, arrived: float) -> None:
        try:  # a message made ahead: its construction is not on the estimate's latency
            msg = self._spare.pop()
        except IndexError:
            msg = self._UnloadEstimate()
        fill_estimate(msg, r, self._frame or "tank")
        try:
            self._pub_est.publish(msg)
        except Exception as exc:
            self._diagnose(_ERROR, f"could not publish the estimate: {exc}")
        (self.final_latencies if r.final else self.latencies).append(
            time.monotonic() - arrived)
        self._spare.append(self._UnloadEstimate())
        self._keep(r)
        if r.status in ("ok", "aborted_sse"):
            why = (f"unload {r.index}: C={r.conductance:.4g} m^3/(s Pa) (eq 39), "
                   f"model {r.conductance_model:.4g}, tau_exp={r.tau_exp:.5g} s"
                   f"{' (final)' if r.final else ''}")
        else:
            why = f"unload {r.index}: {r.status}: {r.status_text}"
        with self._pub_lock:
            if self._last is None or r.index != self._last.index:
                self._n_unloads += 1
            self.results.append(r)
            self.n_results += 1
            self._last = r
            self._why = why
            if r.status not in ("ok", "aborted_sse"):
                self._state = "error"
            else:
                self._state = "done" if self._est.state in ("waiting", "done") \
                    else "unloading"
        self.get_logger().info(why)
        self._report()

    def _keep(self, r: UnloadResult) -> None:
        """An unload's last estimate (the final fit's; the crossing's without a curve fit;
        an aborted or bad unload's only result) into the results database, with its
        verdict; a failing database is reported, never fatal (the estimate is published)."""
        last = r.final or not self._settings.curve_fit or r.status in (
            "aborted", "aborted_sse", "bad_data")
        if self._writer is None:
            return
        if last:
            part = self._unload_parts.pop(r.index, "")
        else:
            # a crossing estimate, replaced by its final one: written at once, so that a
            # node that dies before its final fit leaves the crossing's numbers
            part = self._unload_parts.get(r.index, "")
            r = dataclasses.replace(r, status_text=f"{r.status_text}; {CROSSING_NOTE}")
        if self._stopping:
            r = dataclasses.replace(r, status_text=f"{r.status_text}; {STOPPED_NOTE}")
        part = part or self._goal_part or self._p("part_id")
        self._writer.submit(PendingWrite(r, self._settings, part, last))

    def _written(self, w: PendingWrite, verdict: tuple[str, str] | None) -> None:
        """A results database write done (the writer's thread): its verdict logged."""
        if verdict is not None and w.last:
            self.get_logger().info(f"unload {w.result.index} of part {w.part_id}: "
                                   f"{verdict[0]} ({verdict[1]})")

    def _write_failed(self, w: PendingWrite, exc: Exception) -> None:
        """A results database write failed (the writer's thread): reported, never fatal
        (the estimate is published; the message names the database, a URL without its
        password)."""
        why = str(exc) if isinstance(exc, ResultsDBError) else f"{type(exc).__name__}: {exc}"
        self._diagnose(_ERROR, f"results_db: estimate of unload {w.result.index} not "
                               f"written: {why}; {self._numbers(w.result)}")

    @staticmethod
    def _numbers(r: UnloadResult) -> str:
        """A result's numbers in one line (a log keeps what a database did not take)."""
        return (f"unload {r.index} ({'final' if r.final else 'crossing'}): status "
                f"{r.status}, C={r.conductance:.6g} m^3/(s Pa) (eq 39), model "
                f"{r.conductance_model:.6g} +- {r.conductance_model_std:.3g}, "
                f"tau_exp={r.tau_exp:.6g} s, p10={r.p10:.6g} Pa, t_start={r.t_start!r} s")

    # ------------------------------------------------------------------ diagnostics
    def _diagnose(self, level: bytes, message: str) -> None:
        if level == _OK:
            self.get_logger().info(message)
        else:
            # a repeated warning (one per sample) at most once a LOG_THROTTLE, another
            # at once (rclpy's throttle is one for the call site: it hid a second kind)
            key, now = _DIGITS.sub("#", message)[:48], time.monotonic()
            if now - self._logged.get(key, -math.inf) >= LOG_THROTTLE:
                if len(self._logged) > 256:
                    self._logged.clear()
                self._logged[key] = now
                self.get_logger().warn(message)
        self._send(level, message)

    def _report(self) -> None:
        if self._settings.start_time is not None and \
                time.monotonic() - self._last_arrival > self._p("end_timeout"):
            self._end_of_stream()
        loss = self._loss
        if loss.missing > self._missing_reported:
            new = loss.missing - self._missing_reported
            self._missing_reported = loss.missing
            fix = (": single FluidPressure messages do not keep up at this rate; publish "
                   "PressureBlock messages (simulator: block_size) and set input:=block"
                   if self._p("input") == "sample" else ": blocks lost in transport (qos "
                   "reliable keeps them)")
            self._diagnose(_WARN, f"{new} samples missing from the stream since the last "
                                  f"report ({loss.missing} of {loss.received + loss.missing}"
                                  f", {100 * loss.fraction:.2f} %, counted from the stamps)"
                                  f"{fix}")
        level = {"error": _ERROR}.get(self._state, _OK)
        self._send(level, f"{self._state}: {self._why}")

    def _send(self, level: bytes, message: str) -> None:
        lat = np.asarray(self.latencies) * 1e3
        values = {
            "state": self._state, "core_state": self._est.state,
            "samples": str(self.received), "queued": str(len(self._samples)),
            "fits_queued": str(len(self._fits)),
            "rejected": str(self._rejected),
            "publishers": str(self._pub_count[0]),
            "samples_missing": str(self._loss.missing),
            "unloads": str(self._n_unloads),
            "latency_p50_ms": f"{np.percentile(lat, 50):.3f}" if lat.size else "",
            "latency_p99_ms": f"{np.percentile(lat, 99):.3f}" if lat.size else "",
        }
        if self._last is not None:
            values.update({"conductance": repr(float(self._last.conductance)),
                           "conductance_model": repr(float(self._last.conductance_model)),
                           "tau_exp": repr(float(self._last.tau_exp)),
                           "status": self._last.status})
        st = DiagnosticStatus(level=level, name="pneumatic_unload: estimator",
                              message=message, hardware_id=self._frame or "tank",
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.get_clock().now().to_msg()
        try:
            self._pub_diag.publish(arr)
        except Exception:  # diagnostics must never take the node down
            pass

    # ------------------------------------------------------------------ action
    def _on_goal(self, _goal: Any) -> GoalResponse:
        with self._goal_lock:
            if self._active_goal:
                self.get_logger().warn("~/measure rejected: a measurement is running")
                return GoalResponse.REJECT
            self._active_goal = True
        return GoalResponse.ACCEPT

    async def _execute(self, goal_handle: Any) -> Any:
        Measure = self._Measure
        result = Measure.Result()
        try:
            return await self._measure(goal_handle, result)
        finally:
            with self._goal_lock:
                self._active_goal = False

    async def _sleep(self, seconds: float) -> None:
        fut = Future()
        timer = None

        def done() -> None:
            if not fut.done():
                fut.set_result(True)

        timer = self.create_timer(seconds, done)
        try:
            await fut
        finally:
            self.destroy_timer(timer)

    async def _measure(self, goal_handle: Any, result: Any) -> Any:
        goal = goal_handle.request
        self._goal_part = goal.part_id
        try:
            return await self._measure_part(goal_handle, result)
        finally:
            self._goal_part = ""

    async def _measure_part(self, goal_handle: Any, result: Any) -> Any:
        goal = goal_handle.request
        timeout = goal.timeout if goal.timeout > 0 else self._p("measure_timeout")
        n_before = self.n_results
        with self._pub_lock:
            unloads_before = {r.index for r in self.results}
        t0 = time.monotonic()
        fb = self._Measure.Feedback()
        if goal.direction and goal.direction != self._settings.direction:
            # the direction of this measurement: the parameter set, as a user would (the
            # estimator switched when it is idle; else refused, with the reason)
            why = "" if goal.direction in ("discharge", "charge") else (
                f"direction {goal.direction!r} is neither 'discharge' nor 'charge'")
            if not why:
                done = self.set_parameters([Parameter("direction", value=goal.direction)])
                why = "" if done[0].successful else done[0].reason
            if why:
                goal_handle.abort()
                result.success, result.message = False, f"direction not set: {why}"
                return result
            # a new stream (its indices from 0): any of its results answers the goal
            n_before, unloads_before = self.n_results, set()
        # an unload already under way is not ours: only a new unload index answers the goal
        if goal.trigger_valve:
            service = goal.valve_service or self._p("valve_service")
            client = self.create_client(Trigger, service)
            try:
                while not client.service_is_ready():
                    if time.monotonic() - t0 > min(timeout, 5.0):
                        goal_handle.abort()
                        result.success, result.message = False, (
                            f"valve service {service} not available")
                        return result
                    await self._sleep(0.05)
                resp = await client.call_async(Trigger.Request())
            finally:
                self.destroy_client(client)
            if not resp.success:
                goal_handle.abort()
                result.success = False
                result.message = f"valve service {service} refused: {resp.message}"
                return result
        while True:
            elapsed = time.monotonic() - t0
            with self._pub_lock:
                fresh = list(self.results)[len(self.results) - (self.n_results - n_before):]
            new = [r for r in fresh if r.index not in unloads_before]
            if new:
                r = new[0]
                if goal.part_id:  # its final estimate comes after the goal has returned
                    self._unload_parts[r.index] = goal.part_id
                    while len(self._unload_parts) > 100:
                        self._unload_parts.pop(next(iter(self._unload_parts)))
                fill_estimate(result.estimate, r, self._frame or "tank")
                if self._spec is not None:
                    v = self._spec.judge(goal.part_id or self._p("part_id"), result_row(r))
                    result.verdict, result.verdict_reason = v if v is not None else ("", "")
                if r.status == "ok":
                    goal_handle.succeed()
                    result.success, result.message = True, "ok"
                else:
                    goal_handle.abort()
                    result.success = False
                    result.message = f"{r.status}: {r.status_text}"
                return result
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                result.success, result.message = False, "canceled"
                return result
            if elapsed > timeout:
                goal_handle.abort()
                result.success = False
                result.message = (f"timeout after {timeout:g} s in state {self._state} "
                                  f"({self._why})")
                return result
            fb.state = "armed" if self._state in ("waiting", "done") else self._state
            fb.pressure = float(self._last_pressure) * self._settings.signal_gain \
                + self._settings.signal_offset
            fb.elapsed = elapsed
            goal_handle.publish_feedback(fb)
            await self._sleep(0.1)

    # ------------------------------------------------------------------ shutdown
    def close(self) -> None:
        """Shutdown (SIGINT, SIGTERM, or an error that ends the node): feed the samples
        queued, close the unload under way as at the end of a record (its final fit
        queued; before p*: an 'aborted' result), run the final fits queued and write the
        results database's queue, within SHUTDOWN_WAIT s in all; an estimate that could
        not be finished or written by then is logged with its numbers."""
        deadline = time.monotonic() + SHUTDOWN_WAIT
        while self._samples and self._worker.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)  # the worker feeds them
        self._end_of_stream()
        self._finish_stream()
        self._stop.set()
        self._wake.set()
        self._worker.join(timeout=max(deadline - time.monotonic(), 0.0))
        if self._worker.is_alive():
            fitting = self._fitting
            for job in ([] if fitting is None else [fitting]) + [j for j, _a in self._fits]:
                r = job.crossing
                self.get_logger().error(
                    f"stopping: the final fit of unload {r.index} was not done within "
                    f"{SHUTDOWN_WAIT:g} s; its crossing estimate stands: {self._numbers(r)}")
                if self._writer is not None:  # the crossing's row, marked as such
                    part = self._unload_parts.pop(r.index, "") or self._goal_part \
                        or self._p("part_id")
                    self._writer.submit(PendingWrite(dataclasses.replace(
                        r, status_text=f"{r.status_text}; {UNFITTED_NOTE}"),
                        self._settings, part))
        if self._writer is not None:
            for w in self._writer.close(max(deadline - time.monotonic(), 0.5)):
                self.get_logger().error(
                    f"stopping: results_db did not take this estimate within "
                    f"{SHUTDOWN_WAIT:g} s (not written): {self._numbers(w.result)}")
        stats = {"received": self.received, "rejected": self._rejected,
                 "missing": self._loss.missing,
                 "results": self.n_results,
                 "latencies_ms": [round(x * 1e3, 4) for x in self.latencies],
                 "final_latencies_ms": [round(x * 1e3, 4) for x in self.final_latencies],
                 "final_fit_cpu_ms": [round(x * 1e3, 4) for x in self.fit_cpu],
                 "crossing_push_ms": [round(x * 1e3, 4) for x in self.crossing_push],
                 "crossing_pre_ms": [round(x * 1e3, 4) for x in self.crossing_pre]}
        self.get_logger().info(f"stats {json.dumps(stats)}")


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run pneumatic_unload estimator`` (``--help``: the parameters,
    exit 0 without starting ROS)."""
    code = config_nodes.help_or_none("estimator", args)
    return code if code is not None else common.run(EstimatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
