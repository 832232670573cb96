# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``recorder`` node: the rig's topics into rosbag2 bags (MCAP storage), crash-safe.

Records ``/tank/pressure``, ``/tank/pressure_volts`` (an uncalibrated rig's volts),
``/tank/pressure_block``, ``/tank/temperature``, ``/tank/valve``, ``/estimator/estimate``,
``/estimator/settings``, ``/diagnostics`` and ``/rig/config`` (the package's topics; see
:data:`PACKAGE_TOPICS` for their QoS) plus any extra topics named in the
``topics`` parameter (their types are discovered from the ROS graph; the recorder waits for
them to appear). Messages are received serialised (``raw=True``) and written to the bag as
they came, through :class:`pneumatic_unload.io.bag.BagRecorder`: no per-message
deserialisation.

Parameters:

    * output (string): bag directory (``split:=run``) or parent directory of the bags
      (``split:=unload``); default ``runs/rec-<UTC time>`` relative to the working directory.
      Must not exist yet.
    * split (string): ``run`` = one bag for the whole recording; ``unload`` = one bag per unload
      in ``<output>/unload-000``, ``unload-001``, ...: after an estimate arrives on
      ``/estimator/estimate`` the next bag starts with the first message received while
      the valve is closed (usually the ``/tank/valve`` close message; right away if the
      valve was already closed or never reported). The previous bag stays open until the
      valve opens again (or an estimate of another unload arrives), and receives the later
      estimates with the same ``unload_index`` (the estimator's final, curve-fit
      estimate follows its crossing estimate). Each bag thus holds the pre-unload
      plateau, the discharge and its estimates; the rig configuration and the last
      ``/estimator/settings`` are repeated at the start of every bag. In both modes a
      *different* rig
      configuration on ``/rig/config`` starts a new bag (``run``: ``<output>-001``, ...).
    * flush_interval (double, s): maximal age of data not yet handed to the operating system
      (default 0.5, range (0, 10]). After ``kill -9`` at most about this much is lost;
      ``pneumatic-unload recover BAG`` makes what is on disk readable again.
    * log_time (string): bag log time of each message: ``receive`` (default: the recorder's
      wall-clock receive time [ns], as ``ros2 bag record``) or ``header`` (the header stamp
      for messages that start with a ``std_msgs/Header`` and have a positive stamp; receive
      time otherwise). The header stamps, which analysis uses, are in the payloads either
      way (``read_pressure`` etc. return them).
    * topics (string array): extra topics to record (default none).
    * fsync (bool): also ``fsync`` at each flush (survives power loss; default false).

The rig configuration (``/rig/config``, std_msgs/String JSON, latched) is stored in every
bag (first ``/rig/config`` message and metadata ``custom_data``), so that
``pneumatic-unload analyze BAG`` needs no extra arguments. A configuration message that is
not a JSON object is reported and not stored.

Shutdown: SIGINT or SIGTERM ends the node with exit code 0 and a complete bag
(``metadata.yaml`` written), at any moment, its start included (stopped before it made its
bag, it leaves none). A bad message or a bad topic never ends the node: it is logged
and counted. Invalid parameters end it at start with exit code 2 and the reason. A disk
with no room left (ENOSPC, EDQUOT, or EFBIG at a file-size limit) stops the recording at
the first write that fails: the bag is completed with what reached the disk at its last
flush (``metadata.yaml`` written; when even the MCAP summary does not fit, the line says
to run ``pneumatic-unload recover``) and the node exits 1 with one line that says so.
"""

from __future__ import annotations

import contextlib
import json
import signal
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.io.bag import (
    MSGTYPE_CONFIG,
    MSGTYPE_ESTIMATE,
    MSGTYPE_PRESSURE,
    MSGTYPE_TEMPERATURE,
    MSGTYPE_VALVE,
    MSGTYPE_VOLTAGE,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_SETTINGS,
    TOPIC_TEMPERATURE,
    TOPIC_VALVE,
    TOPIC_VOLTS,
    BagError,
    BagRecorder,
    cdr_header_stamp_ns,
    make_typestore,
)
from pneumatic_unload.io.bag.errors import DISK_FULL_ERRNOS, BagDiskFullError

TOPIC_DIAGNOSTICS = "/diagnostics"
MSGTYPE_DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
TOPIC_PRESSURE_BLOCK = "/tank/pressure_block"
MSGTYPE_PRESSURE_BLOCK = "pneumatic_unload_msgs/msg/PressureBlock"

#: The package's topics: name -> (message type, QoS durability, QoS depth). All reliable.
#: Latched (transient local) where the publishers are latched: a transient-local reader
#: gets the last messages published before the recorder started (and does not match a
#: volatile writer, so publishers of these topics must be latched).
PACKAGE_TOPICS: dict[str, tuple[str, str, int]] = {
    TOPIC_PRESSURE: (MSGTYPE_PRESSURE, "volatile", 1000),
    TOPIC_VOLTS: (MSGTYPE_VOLTAGE, "volatile", 1000),
    TOPIC_PRESSURE_BLOCK: (MSGTYPE_PRESSURE_BLOCK, "volatile", 1000),
    TOPIC_TEMPERATURE: (MSGTYPE_TEMPERATURE, "volatile", 1000),
    TOPIC_VALVE: (MSGTYPE_VALVE, "transient_local", 10),
    TOPIC_ESTIMATE: (MSGTYPE_ESTIMATE, "transient_local", 10),
    TOPIC_SETTINGS: (MSGTYPE_CONFIG, "transient_local", 10),
    TOPIC_DIAGNOSTICS: (MSGTYPE_DIAGNOSTICS, "volatile", 1000),
    TOPIC_CONFIG: (MSGTYPE_CONFIG, "transient_local", 10),
}
#: Topics whose last message is state that every bag needs: repeated at the start of each
#: new bag (the rig configuration is handled separately, see RecordingSession).
CARRIED_TOPICS = frozenset({TOPIC_SETTINGS})
SPLIT_MODES = ("run", "unload")
LOG_TIME_MODES = ("receive", "header")
#: Range of ``flush_interval`` [s] (with the parameter's declaration).
FLUSH_INTERVAL_RANGE = config_nodes.FLUSH_INTERVAL_RANGE
#: How often pending extra topics are looked up in the ROS graph [s].
GRAPH_POLL_INTERVAL = 0.5


class RecorderParameterError(ValueError):
    """A recorder parameter is invalid (the message says which and why)."""


def default_output(now: datetime | None = None) -> Path:
    """``runs/rec-<UTC time>`` (e.g. ``runs/rec-20260101T120000Z``)."""
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("runs") / f"rec-{stamp}"


class RecordingSession:
    """What the recorder does with each received message, without ROS (testable alone).

    Owns the open :class:`BagRecorder`, the bag split policy (see the module docstring) and
    the rig configuration. :meth:`on_message` never raises: errors are counted in
    :attr:`errors` and passed to ``report``.
    """

    def __init__(
        self,
        output: Path,
        *,
        split: str = "run",
        flush_interval: float = 0.5,
        log_time: str = "receive",
        fsync: bool = False,
        report: Callable[[str], None] | None = None,
    ) -> None:
        """Validate the options and open the first bag.

        Args:
            output: bag directory (``run``) or parent directory of the bags (``unload``);
                must not exist.
            split: ``run`` or ``unload``.
            flush_interval: maximal age of unwritten data [s].
            log_time: ``receive`` or ``header``.
            fsync: fsync at each flush.
            report: called with a text for each problem (default: print to stderr).

        Raises:
            RecorderParameterError: an option is invalid or ``output`` exists.
        """
        if split not in SPLIT_MODES:
            raise RecorderParameterError(
                f"split={split!r} is invalid: use one of {', '.join(SPLIT_MODES)}"
            )
        if log_time not in LOG_TIME_MODES:
            raise RecorderParameterError(
                f"log_time={log_time!r} is invalid: use one of {', '.join(LOG_TIME_MODES)}"
            )
        lo, hi = FLUSH_INTERVAL_RANGE
        if not lo <= flush_interval <= hi:
            raise RecorderParameterError(
                f"flush_interval={flush_interval!r} s is outside [{lo}, {hi}] s"
            )
        if not str(output):
            raise RecorderParameterError("output must not be empty")
        if output.exists():
            raise RecorderParameterError(f"output {output} exists already; choose a new one")
        self.output = output
        self.split = split
        self.flush_interval = float(flush_interval)
        self.log_time = log_time
        self.fsync = fsync
        self._report = report or (lambda text: print(text, file=sys.stderr, flush=True))
        self._store = make_typestore()  # decodes the few messages the policy looks at
        self.bags: list[Path] = []
        self.counts: Counter[str] = Counter()
        self.errors = 0
        self._runs = 0  # number of the last bag started after the first one
        self._extra_types: set[str] = set()
        self._config_text: str | None = None
        self._valve_open: bool | None = None
        self._armed: int | None = None  # unload_index of the estimate in the current bag
        # split=unload: the previous bag stays open for late estimates of its unload
        self._prev: BagRecorder | None = None
        self._prev_index: int | None = None
        self._carried: dict[str, tuple[str, bytes]] = {}  # topic -> (type, last message)
        self._closed = False
        #: Why recording stopped (the disk, a quota or the file-size limit is full), or
        #: None: the node then closes its bags and exits (:func:`main`).
        self.stopped: str | None = None
        self._rec = self._open_bag()

    # ------------------------------------------------------------------ bag handling

    def _next_path(self) -> Path:
        """The next bag directory (skipping names that exist: never overwrite)."""
        if not self.bags:
            return self.output / "unload-000" if self.split == "unload" else self.output
        while True:
            self._runs += 1
            if self.split == "unload":
                path = self.output / f"unload-{self._runs:03d}"
            else:
                path = self.output.with_name(f"{self.output.name}-{self._runs:03d}")
            if not path.exists():
                return path

    def _open_bag(self) -> BagRecorder:
        path = self._next_path()
        if self.split == "unload":
            self.output.mkdir(parents=True, exist_ok=True)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
        rec = BagRecorder(path, flush_interval=self.flush_interval, fsync=self.fsync)
        if self._config_text is not None:
            rec.set_config(self._config_text)  # first message of the bag
        for msgtype in sorted(self._extra_types):
            with contextlib.suppress(Exception):  # reported when the type was added
                rec.ensure_type(msgtype)
        self.bags.append(path)
        return rec

    def _close_prev(self) -> None:
        prev, self._prev, self._prev_index = self._prev, None, None
        if prev is not None:
            prev.close()

    def _rotate(self, log_ns: int, *, linger: bool = False) -> None:
        """Start a new bag; with ``linger`` the old one stays open for late estimates.

        The new bag is opened first: if that fails, recording goes on in the old one.
        """
        new = self._open_bag()
        old, self._rec = self._rec, new
        self._close_prev()
        if linger:
            self._prev, self._prev_index = old, self._armed
        else:
            old.close()
        self._armed = None
        for topic, (msgtype, data) in self._carried.items():
            self._rec.write_raw(topic, msgtype, log_ns, data)
            self.counts[topic] += 1

    def summary_written(self) -> bool:
        """The current bag, closed, has its MCAP summary (see
        :attr:`BagRecorder.summary_written`)."""
        return self._rec.summary_written

    def bag_counts(self) -> dict[str, int]:
        """Messages per topic in the current bag (after a stop for lack of room: those
        that reached the disk, not those received)."""
        return self._rec.message_counts

    @property
    def current_bag(self) -> Path:
        """Directory of the bag being written."""
        return self.bags[-1]

    def add_type(self, msgtype: str) -> None:
        """Make an extra topic's type writable (loads its ``.msg`` definition if needed).

        Raises:
            pneumatic_unload.io.bag.BagError: the definition is not installed or invalid.
        """
        self._rec.ensure_type(msgtype)
        self._extra_types.add(msgtype)

    # -------------------------------------------------------------------- messages

    def on_message(
        self, topic: str, msgtype: str, data: bytes, recv_ns: int, has_header: bool
    ) -> None:
        """Record one serialised message (CDR) received at ``recv_ns`` [ns, wall clock].

        ``has_header``: the type's first field is a ``std_msgs/Header`` (for
        ``log_time:=header``). Never raises.
        """
        try:
            self._on_message(topic, msgtype, data, recv_ns, has_header)
        except Exception as err:
            if self._out_of_room(err):
                return
            self.errors += 1
            if self.errors <= 20 or self.errors % 1000 == 0:
                self._report(
                    f"recorder: message on {topic} not recorded ({type(err).__name__}: {err}); "
                    f"{self.errors} error(s) so far"
                )

    def _out_of_room(self, err: Exception) -> bool:
        """True when ``err`` means the disk is full (:data:`DISK_FULL_ERRNOS`): recording
        stops (:attr:`stopped`, reported once), later messages are dropped uncounted."""
        if not (isinstance(err, BagDiskFullError)
                or (isinstance(err, OSError) and err.errno in DISK_FULL_ERRNOS)):
            return False
        if self.stopped is None:
            self.stopped = str(err)
            self._report(f"recorder: {err}")
        return True

    def _on_message(
        self, topic: str, msgtype: str, data: bytes, recv_ns: int, has_header: bool
    ) -> None:
        if self._closed or self.stopped is not None:
            return
        log_ns = recv_ns
        if self.log_time == "header" and has_header:
            stamp = cdr_header_stamp_ns(data)
            if stamp is not None and stamp > 0:
                log_ns = stamp
        if topic == TOPIC_CONFIG and msgtype == MSGTYPE_CONFIG:
            self._on_config(data, log_ns)
            return
        index: int | None = None
        if self.split == "unload":
            if topic == TOPIC_VALVE and msgtype == MSGTYPE_VALVE:
                try:
                    self._valve_open = bool(self._store.deserialize_cdr(data, msgtype).open)
                except Exception as err:  # still recorded below
                    self._report(f"recorder: cannot decode a {msgtype} message: {err}")
                if self._valve_open:
                    self._close_prev()  # the next unload starts
            elif topic == TOPIC_ESTIMATE and msgtype == MSGTYPE_ESTIMATE:
                try:
                    index = int(self._store.deserialize_cdr(data, msgtype).unload_index)
                except Exception as err:  # still recorded below
                    self._report(f"recorder: cannot decode a {msgtype} message: {err}")
                    index = -1
                if self._prev is not None:
                    if index == self._prev_index:  # e.g. the final (curve-fit) estimate
                        self._prev.write_raw(topic, msgtype, log_ns, data)
                        self.counts[topic] += 1
                        return
                    self._close_prev()
            if self._armed is not None and self._valve_open is not True:
                self._rotate(log_ns, linger=True)
        self._rec.write_raw(topic, msgtype, log_ns, data)
        self.counts[topic] += 1
        if topic in CARRIED_TOPICS:
            self._carried[topic] = (msgtype, data)
        if index is not None:
            self._armed = index

    def _on_config(self, data: bytes, log_ns: int) -> None:
        text = self._store.deserialize_cdr(data, MSGTYPE_CONFIG).data
        try:
            parsed = json.loads(text)
        except ValueError as err:
            raise ValueError(f"rig configuration is not valid JSON ({err}); not stored") from None
        if not isinstance(parsed, dict):
            raise ValueError("rig configuration is not a JSON object; not stored")
        if text == self._config_text:
            return  # the same configuration again (e.g. a second latched delivery)
        if self._config_text is None:
            self._config_text = text
            empty = not any(self._rec.message_counts.values())
            self._rec.set_config(text, config_stamp_ns=None if empty else log_ns)
        else:
            self._report(f"recorder: new rig configuration: starting a new bag after "
                         f"{self.current_bag}")
            self._config_text = text
            self._rotate(log_ns)
        self.counts[TOPIC_CONFIG] += 1

    # ------------------------------------------------------------------- lifecycle

    def flush(self) -> None:
        """Hand pending data to the operating system (call at least every flush_interval)."""
        if self._closed or self.stopped is not None:
            return
        for rec in (self._rec, self._prev):
            if rec is None:
                continue
            try:
                rec.flush()
            except Exception as err:
                if self._out_of_room(err):
                    return
                self.errors += 1
                self._report(f"recorder: flush failed: {err}")

    def close(self) -> None:
        """Complete the open bag(s) (summary, ``metadata.yaml``). Idempotent."""
        if not self._closed:
            self._closed = True
            try:
                self._close_prev()
            finally:
                self._rec.close()


# ============================================================================ ROS node


def _import_msg(msgtype: str) -> Any:
    """The rclpy message class of ``msgtype`` ('pkg/msg/Name')."""
    import importlib

    pkg, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def _has_header(msg_class: Any) -> bool:
    fields = list(msg_class.get_fields_and_field_types().items())
    return bool(fields) and fields[0][1] == "std_msgs/Header"


def _make_node() -> Any:
    """Build the recorder node class (rclpy imported only here and in :func:`main`)."""
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.exceptions import ParameterUninitializedException
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from pneumatic_unload.nodes.common import node_parameters

    class Recorder(Node):
        """ROS side of the recorder: parameters, subscriptions, graph discovery."""

        def __init__(self) -> None:
            super().__init__("recorder")
            # the one list of parameters (also --help and config/recorder.yaml)
            for name, (default, desc) in node_parameters("recorder").items():
                self.declare_parameter(name, default, desc)
            self.add_on_set_parameters_callback(self._reject_changes)

            flush = self.get_parameter("flush_interval").value
            if isinstance(flush, bool) or not isinstance(flush, int | float):
                raise RecorderParameterError(
                    f"flush_interval must be a number of seconds, got {flush!r}")
            try:
                extra: Sequence[str] = list(self.get_parameter("topics").value or [])
            except ParameterUninitializedException:
                extra = []
            out = str(self.get_parameter("output").value) or str(default_output())
            self.session = RecordingSession(
                Path(out),
                split=str(self.get_parameter("split").value),
                flush_interval=float(flush),
                log_time=str(self.get_parameter("log_time").value),
                fsync=bool(self.get_parameter("fsync").value),
                report=lambda text: self.get_logger().warning(text),
            )
            self._subs: list[Any] = []
            try:
                for topic, (msgtype, durability, depth) in PACKAGE_TOPICS.items():
                    self._subscribe(topic, msgtype, _import_msg(msgtype),
                                    self._qos(True, durability == "transient_local", depth))
            except BaseException:
                self.session.close()
                raise
            self._pending: dict[str, str] = {}  # resolved name -> name as given
            for name in extra:
                try:
                    resolved = self.resolve_topic_name(str(name))
                except Exception as err:
                    self.get_logger().error(f"topic {name!r} ignored: invalid name ({err})")
                    continue
                if resolved not in PACKAGE_TOPICS:
                    self._pending[resolved] = str(name)
            if self._pending:
                self.get_logger().info(
                    "waiting for extra topics to appear: " + ", ".join(sorted(self._pending)))
            self.get_logger().info(
                f"recording to {self.session.current_bag} (split={self.session.split}, "
                f"flush_interval={self.session.flush_interval} s, "
                f"log_time={self.session.log_time})")

        @staticmethod
        def _qos(reliable: bool, transient_local: bool, depth: int) -> QoSProfile:
            return QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=depth,
                reliability=ReliabilityPolicy.RELIABLE if reliable
                else ReliabilityPolicy.BEST_EFFORT,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local
                else DurabilityPolicy.VOLATILE)

        def _subscribe(self, topic: str, msgtype: str, msg_class: Any, qos: QoSProfile) -> None:
            has_header = _has_header(msg_class)
            session = self.session

            def callback(data: bytes) -> None:
                session.on_message(topic, msgtype, data, time.time_ns(), has_header)

            self._subs.append(self.create_subscription(msg_class, topic, callback, qos, raw=True))

        def _reject_changes(self, params: list[Parameter]) -> SetParametersResult:
            names = ", ".join(p.name for p in params)
            return SetParametersResult(
                successful=False,
                reason=f"recorder parameters are read at start ({names}): restart the node "
                "to change them")

        def poll_graph(self) -> None:
            """Subscribe to the pending extra topics that have appeared in the graph."""
            if not self._pending:
                return
            graph = dict(self.get_topic_names_and_types())
            for topic in [t for t in self._pending if t in graph]:
                given = self._pending.pop(topic)
                types = graph[topic]
                msgtype = types[0]
                if len(types) > 1:
                    self.get_logger().warning(
                        f"topic {topic} has several types {types}; recording {msgtype}")
                try:
                    msg_class = _import_msg(msgtype)
                    self.session.add_type(msgtype)
                except Exception as err:
                    self.get_logger().error(
                        f"topic {given!r} ({msgtype}) cannot be recorded: {err}")
                    continue
                pubs = self.get_publishers_info_by_topic(topic)
                reliable = all(
                    p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in pubs)
                latched = bool(pubs) and all(
                    p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in pubs)
                self._subscribe(topic, msgtype, msg_class, self._qos(reliable, latched, 1000))
                self.get_logger().info(f"recording extra topic {topic} ({msgtype})")

    return Recorder


def main(argv: list[str] | None = None) -> int:
    """Run the recorder node until SIGINT/SIGTERM. Returns the exit code (0, or 2 for bad
    parameters)."""
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException

    from pneumatic_unload.nodes import common

    code = config_nodes.help_or_none("recorder", argv)
    if code is not None:
        return code
    if not common.start_ros(sys.argv if argv is None else argv):
        return 0  # SIGINT/SIGTERM during the imports: stopped before it started, no bag
    node = None
    try:
        try:
            node = _make_node()()
        except (RecorderParameterError, ParameterException) as err:
            print(f"recorder: invalid parameter: {err}", file=sys.stderr, flush=True)
            return 2
        except (BagError, OSError) as err:
            print(f"recorder: cannot create the bag: {err}", file=sys.stderr, flush=True)
            return 2
        session = node.session
        # The EventsExecutor keeps up with 10 kHz; its spin() ignores SIGINT and its timers
        # do not fire in this rclpy, so the loop below drives it and does the periodic work.
        executor = common.make_executor("events")
        executor.add_node(node)
        next_flush = time.monotonic() + session.flush_interval
        next_poll = 0.0
        try:
            # a SIGINT/SIGTERM of the start stops the node here: the bag is completed below
            common.running()
            while common.ok() and session.stopped is None:
                executor.spin_once(timeout_sec=min(0.05, session.flush_interval / 2))
                now = time.monotonic()
                if now >= next_flush:
                    session.flush()
                    next_flush = now + session.flush_interval
                if now >= next_poll:
                    node.poll_graph()
                    next_poll = now + GRAPH_POLL_INTERVAL
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            # Completing the bag must not be interrupted by a second Ctrl-C.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            try:
                session.close()
                closed = ""
            except BagError as err:  # said in one line below, no traceback
                closed = str(err)
            with contextlib.suppress(Exception):
                executor.shutdown(timeout_sec=1.0)
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(session.counts.items())) or "none"
        print(f"recorder: wrote {len(session.bags)} bag(s) ({', '.join(map(str, session.bags))});"
              f" messages {counts}; errors {session.errors}", file=sys.stderr, flush=True)
        if session.stopped is not None:
            held = ", ".join(f"{t}: {n}" for t, n in sorted(session.bag_counts().items()))
            done = (f"could not be completed: {closed}" if closed else
                    "completed with what reached the disk at its last flush (metadata.yaml "
                    f"written; it holds {held or 'no message'})")
            if not closed and not session.summary_written():
                done += ("; no room for its MCAP summary either: run `pneumatic-unload "
                         f"recover {session.current_bag}` before reading it")
            print(f"recorder: error: recording stopped, no room left: {session.stopped}; "
                  f"{session.current_bag} {done}; messages received after the stop were "
                  "not recorded. Free space (or raise the quota) and start a new recording",
                  file=sys.stderr, flush=True)
            return 1
        if closed:
            print(f"recorder: error: {closed}", file=sys.stderr, flush=True)
            return 1
        return 0
    finally:
        if node is not None:
            with contextlib.suppress(Exception):
                node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
