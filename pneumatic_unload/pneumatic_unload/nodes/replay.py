# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``replay`` node: publishes a bag's topics with their original timing, scaled, or as fast
as the subscribers take them, without loss.

Messages are read serialised (:func:`pneumatic_unload.io.bag.read_raw_messages`) and
published unchanged (``publish(bytes)``): header stamps are the original ones. Pacing uses
the bag's log times on ``time.monotonic`` in a plain loop (an rclpy timer cannot hold 1 kHz).

Parameters:

    * bag (string, required): bag directory or ``.mcap`` file.
    * rate (double, -): time scale factor: 1.0 = original timing (default), 2.0 = twice as
      fast, 0 = as fast as the subscribers acknowledge (flow control: at most
      ``FLOW_WINDOW`` unacknowledged messages per topic; reliable QoS, no loss).
    * topics (string array): topics to replay (default: all in the bag). An unknown topic is
      an error.
    * loop (bool): start again at the end until SIGINT (default false).
    * wait_for_subscribers (bool): before publishing, wait until ``min_subscribers``
      subscribers are matched on ``/tank/pressure`` (or, if it is not replayed, on every
      replayed topic) so that no sample is lost (default true).
    * min_subscribers (int): how many subscribers to wait for (default 1).
    * wait_timeout (double, s): give up waiting after this long and start anyway with a
      warning (default 10.0).
    * publish_clock (bool): also publish ``/clock`` (rosgraph_msgs/Clock) at the log time of
      each replayed message as it goes out (at most one per ``CLOCK_STEP_NS`` of bag time,
      and the last message's time at the end of each pass), so that nodes run with
      ``use_sim_time:=true`` see the bag's time (default false).

QoS: reliable; ``/clock`` keep-last depth 1 volatile (as ``ros2 bag play --clock``);
``/rig/config`` transient local depth 1, ``/estimator/estimate`` transient
local depth 10, everything else volatile depth 1000. The rig configuration (first
``/rig/config`` message of the bag or, without one, the configuration in the bag's metadata)
is published once, latched, before the timed stream and is not paced. Also in paced mode
the publisher waits for acknowledgements every ``FLOW_WINDOW`` messages of a topic, so a
slow subscriber slows the replay down instead of losing messages.

Exit code 0 when done (or after SIGINT/SIGTERM), 2 for invalid parameters or an unreadable
bag.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.io.bag import (
    CONFIG_METADATA_KEY,
    MSGTYPE_CONFIG,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    BagError,
    RawMessage,
    bag_summary,
    make_typestore,
    read_raw_messages,
)

#: Messages of one topic published before waiting for all subscribers' acknowledgements
#: (half the writer history depth of 1000: nothing is overwritten before it is acknowledged).
FLOW_WINDOW = 500
#: Fast DDS heartbeat period of the replay's writers [s] (see :func:`use_fast_heartbeat`).
HEARTBEAT_PERIOD = 0.005
#: Longest single wait for acknowledgements before checking for shutdown [s].
ACK_POLL = 0.5
#: Pause after the subscribers matched, so that they also match the publisher [s].
MATCH_SETTLE = 0.2
#: Time to wait for the last acknowledgements at the end [s].
FINAL_ACK_TIMEOUT = 10.0
#: Interval of bag time with at most one /clock message [ns] (1 ms: a clock of at most
#: 1 kHz at rate 1, finer than any period the estimator's timers use).
CLOCK_STEP_NS = 1_000_000
#: The topic of ROS time for ``use_sim_time`` nodes.
TOPIC_CLOCK = "/clock"


class ReplayParameterError(ValueError):
    """A replay parameter is invalid (the message says which and why)."""


@dataclass(frozen=True)
class ReplayPlan:
    """What to replay, checked against the bag (ROS-free)."""

    bag: Path
    rate: float  #: time scale factor [-]; 0 = flow controlled
    topics: dict[str, str]  #: topic -> message type
    config: RawMessage | None  #: first /rig/config message, published latched first
    loop: bool

    @classmethod
    def from_parameters(
        cls, bag: str, rate: float, topics: Sequence[str], loop: bool
    ) -> ReplayPlan:
        """Validate the parameters against the bag.

        Raises:
            ReplayParameterError: bad rate, missing bag, unknown topics, mixed types.
        """
        if isinstance(rate, bool) or not isinstance(rate, int | float) or not rate >= 0.0:
            raise ReplayParameterError(
                f"rate={rate!r} is invalid: a time scale factor >= 0 (0 = as fast as the "
                "subscribers take the messages)")
        if rate > 1e6:
            raise ReplayParameterError(f"rate={rate!r} is too large (at most 1e6)")
        if not bag:
            raise ReplayParameterError("bag is required: --ros-args -p bag:=PATH")
        try:
            summary = bag_summary(bag)
        except BagError as err:
            raise ReplayParameterError(f"bag={bag!r}: {err}") from err
        available = {name: info.msgtype for name, info in summary.topics.items()}
        meta_config = summary.custom_data.get(CONFIG_METADATA_KEY)
        if TOPIC_CONFIG not in available and meta_config is not None:
            available[TOPIC_CONFIG] = MSGTYPE_CONFIG  # published from the metadata
        wanted = list(topics) if topics else sorted(available)
        unknown = [t for t in wanted if t not in available]
        if unknown:
            raise ReplayParameterError(
                f"topics {unknown} are not in bag {bag}; it has: {', '.join(sorted(available))}")
        mixed = [t for t in wanted if "," in available[t]]
        if mixed:
            raise ReplayParameterError(f"topics {mixed} carry several message types")
        config = None
        if TOPIC_CONFIG in wanted and TOPIC_CONFIG in summary.topics:
            config = next(iter(read_raw_messages(bag, topics=[TOPIC_CONFIG])), None)
        elif TOPIC_CONFIG in wanted and meta_config is not None:
            store = make_typestore()
            data = store.serialize_cdr(store.types[MSGTYPE_CONFIG](data=meta_config),
                                       MSGTYPE_CONFIG)
            config = RawMessage(TOPIC_CONFIG, MSGTYPE_CONFIG, summary.start_ns or 0, bytes(data))
        return cls(Path(bag), float(rate), {t: available[t] for t in wanted}, config, loop)

    def stream(self) -> Iterable[RawMessage]:
        """The timed messages of one pass (everything but /rig/config), in log-time order."""
        timed = [t for t in self.topics if t != TOPIC_CONFIG]
        if not timed:
            return ()
        return read_raw_messages(self.bag, topics=timed)


def pace(
    messages: Iterable[RawMessage],
    rate: float,
    publish: Callable[[RawMessage], None],
    *,
    keep_going: Callable[[], bool] = lambda: True,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> int:
    """Call ``publish`` for each message at its log time scaled by ``1/rate`` (``rate`` 0:
    immediately). The first message goes out at once. Late messages are not skipped.

    Returns:
        The number of messages published.
    """
    n = 0
    t0 = 0.0
    first_ns = 0
    for msg in messages:
        if not keep_going():
            break
        if n == 0:
            t0 = clock()
            first_ns = msg.log_time_ns
        elif rate > 0.0:
            due = t0 + (msg.log_time_ns - first_ns) * 1e-9 / rate
            delay = due - clock()
            if delay > 0.0:
                sleep(delay)
        publish(msg)
        n += 1
    return n


class SimClock:
    """Which replayed log times go out on ``/clock`` (ROS-free): the first message's time in
    each ``CLOCK_STEP_NS`` interval of bag time (so a 1 kHz bag's clock ticks with nearly
    every sample even when the stamps' spacing is a little under 1 ms), a time before the
    last one sent at once (a new pass of a loop), and by :meth:`flush` the last message's
    time at the end of a pass."""

    def __init__(self, send: Callable[[int], None], step_ns: int = CLOCK_STEP_NS) -> None:
        self._send = send
        self._step = step_ns
        self._sent: int | None = None
        self._last: int | None = None

    def tick(self, log_time_ns: int) -> None:
        """Called before the message of ``log_time_ns`` is published."""
        self._last = log_time_ns
        if self._sent is None or log_time_ns < self._sent \
                or log_time_ns // self._step != self._sent // self._step:
            self._send(log_time_ns)
            self._sent = log_time_ns

    def flush(self) -> None:
        """Send the last message's time if it has not gone out."""
        if self._last is not None and self._last != self._sent:
            self._send(self._last)
            self._sent = self._last


_FAST_HEARTBEAT_XML = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="pneumatic_unload_replay" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>{nanosec}</nanosec></heartbeatPeriod>
    </times>
  </data_writer>
</profiles>
"""


def use_fast_heartbeat(period: float = HEARTBEAT_PERIOD) -> Path | None:
    """Make this process's Fast DDS writers send a heartbeat every ``period`` [s].

    Fast DDS's default heartbeat period is 3 s, so ``wait_for_all_acked`` (the replay's flow
    control) would take up to 3 s per call; with 5 ms it returns within about 10 ms. Writes a
    Fast DDS XML profile and points ``FASTRTPS_DEFAULT_PROFILES_FILE`` at it. Call before
    ``rclpy.init``. Does nothing (returns None) if the user set that variable or another RMW
    than Fast DDS is selected.

    Returns:
        The profile file, or None.
    """
    import os
    import tempfile

    if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
        return None
    if os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return None
    nanosec = max(1, min(999_999_999, int(round(period * 1e9))))
    fd, name = tempfile.mkstemp(prefix="pneumatic_unload_replay_", suffix=".xml")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(_FAST_HEARTBEAT_XML.format(nanosec=nanosec))
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = name
    return Path(name)


def _import_msg(msgtype: str) -> Any:
    import importlib

    pkg, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def main(argv: list[str] | None = None) -> int:
    """Run the replay node. Returns the exit code (0 done, 2 bad parameters or bag;
    ``--help``: the parameters, 0, without starting ROS)."""
    code = config_nodes.help_or_none("replay", argv)
    if code is not None:
        return code
    import rclpy
    from rclpy.duration import Duration
    from rclpy.exceptions import ParameterException, ParameterUninitializedException
    from rclpy.executors import ExternalShutdownException
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from pneumatic_unload.nodes import common

    RCLError = rclpy_implementation.RCLError

    profile = use_fast_heartbeat()
    if not common.start_ros(sys.argv if argv is None else argv):
        # SIGINT/SIGTERM during the imports: stopped before it started
        if profile is not None:
            profile.unlink(missing_ok=True)
        return 0
    node = rclpy.create_node("replay")
    log = node.get_logger()
    try:
        try:
            # the one list of parameters (also --help and config/replay.yaml)
            for name, (default, desc) in common.node_parameters("replay").items():
                node.declare_parameter(name, default, desc)
            try:
                topics = list(node.get_parameter("topics").value or [])
            except ParameterUninitializedException:
                topics = []
            wait_timeout = node.get_parameter("wait_timeout").value
            if isinstance(wait_timeout, bool) or not isinstance(wait_timeout, int | float) \
                    or not wait_timeout >= 0.0:
                raise ReplayParameterError(
                    f"wait_timeout={wait_timeout!r} is invalid: a number of seconds >= 0")
            min_subs = int(node.get_parameter("min_subscribers").value)
            if min_subs < 0:
                raise ReplayParameterError(f"min_subscribers={min_subs} must be >= 0")
            plan = ReplayPlan.from_parameters(
                str(node.get_parameter("bag").value), node.get_parameter("rate").value,
                topics, bool(node.get_parameter("loop").value))
        except (ReplayParameterError, ParameterException) as err:
            print(f"replay: invalid parameter: {err}", file=sys.stderr, flush=True)
            return 2

        def qos(topic: str) -> QoSProfile:
            latched = topic in (TOPIC_CONFIG, TOPIC_ESTIMATE)
            depth = 1 if topic == TOPIC_CONFIG else 10 if topic == TOPIC_ESTIMATE else 1000
            return QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=depth,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                else DurabilityPolicy.VOLATILE)

        pubs: dict[str, Any] = {}
        for topic, msgtype in plan.topics.items():
            try:
                pubs[topic] = node.create_publisher(_import_msg(msgtype), topic, qos(topic))
            except Exception as err:
                if topics:  # asked for explicitly
                    print(f"replay: invalid parameter: topic {topic} ({msgtype}) cannot be "
                          f"published: {err}", file=sys.stderr, flush=True)
                    return 2
                log.warning(f"skipping {topic}: no Python message type {msgtype} ({err})")
        if not pubs:
            print(f"replay: bag {plan.bag} has no messages that can be published",
                  file=sys.stderr, flush=True)
            return 2

        # built: a SIGINT/SIGTERM of the start stops the node here (before it publishes); a
        # later one raises KeyboardInterrupt (also out of the pacing's sleeps)
        common.running(keyboard_interrupt=True)
        if node.get_parameter("wait_for_subscribers").value and min_subs > 0:
            watched = [pubs[TOPIC_PRESSURE]] if TOPIC_PRESSURE in pubs else list(pubs.values())
            deadline = time.monotonic() + float(wait_timeout)
            while rclpy.ok() and any(p.get_subscription_count() < min_subs for p in watched):
                if time.monotonic() > deadline:
                    log.warning(f"no {min_subs} subscriber(s) after {wait_timeout} s; "
                                "publishing anyway")
                    break
                time.sleep(0.01)
            else:
                time.sleep(MATCH_SETTLE)

        sent: Counter[str] = Counter()
        unacked: Counter[str] = Counter()
        sim_clock: SimClock | None = None
        if node.get_parameter("publish_clock").value:
            from rosgraph_msgs.msg import Clock

            clock_pub = node.create_publisher(Clock, TOPIC_CLOCK, QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=1,
                reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))

            def send_clock(t_ns: int) -> None:
                msg = Clock()
                msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 1_000_000_000)
                clock_pub.publish(msg)
                sent[TOPIC_CLOCK] += 1

            sim_clock = SimClock(send_clock)

        def wait_acked(topic: str) -> None:
            while rclpy.ok() and not pubs[topic].wait_for_all_acked(
                    Duration(seconds=ACK_POLL)):
                pass
            unacked[topic] = 0

        def publish(msg: RawMessage) -> None:
            pub = pubs.get(msg.topic)
            if pub is None:
                return
            if sim_clock is not None and msg.topic != TOPIC_CONFIG:
                sim_clock.tick(msg.log_time_ns)
            if unacked[msg.topic] >= FLOW_WINDOW:
                wait_acked(msg.topic)
            while True:
                try:
                    pub.publish(msg.data)
                    break
                except RCLError:
                    if not rclpy.ok():
                        raise
                    wait_acked(msg.topic)  # reliable writer full: let the readers catch up
            sent[msg.topic] += 1
            unacked[msg.topic] += 1

        t_start = time.monotonic()
        passes = 0
        try:
            if plan.config is not None and TOPIC_CONFIG in pubs:
                publish(plan.config)
            while rclpy.ok():
                pace(plan.stream(), plan.rate, publish, keep_going=rclpy.ok)
                if sim_clock is not None:
                    sim_clock.flush()
                passes += 1
                if not plan.loop:
                    break
            for topic in pubs:
                if not rclpy.ok():  # interrupted: the context is gone, nothing to wait for
                    break
                pubs[topic].wait_for_all_acked(Duration(seconds=FINAL_ACK_TIMEOUT))
        except (KeyboardInterrupt, ExternalShutdownException):
            log.info("interrupted")
        except RCLError:
            # SIGINT shuts the context down between a check of rclpy.ok() and a call on a
            # publisher (the call then fails with "context is invalid"): an interruption
            if rclpy.ok():
                raise
            log.info("interrupted")
        except BagError as err:
            print(f"replay: cannot read bag {plan.bag}: {err}", file=sys.stderr, flush=True)
            return 2
        elapsed = time.monotonic() - t_start
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(sent.items())) or "none"
        print(f"replay: {passes} pass(es) of {plan.bag} in {elapsed:.3f} s at rate "
              f"{plan.rate:g}; published {counts}", file=sys.stderr, flush=True)
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0  # interrupted before publishing
    finally:
        with contextlib.suppress(Exception):
            node.destroy_node()
        rclpy.try_shutdown()
        if profile is not None:
            profile.unlink(missing_ok=True)


if __name__ == "__main__":
    sys.exit(main())
