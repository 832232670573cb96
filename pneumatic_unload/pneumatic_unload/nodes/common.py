# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Shared plumbing of the ROS 2 nodes: QoS profiles, parameters from RigConfig, start,
spinning and stop.

Nodes stay thin: they convert messages, hold parameters and call the ROS-free core. Every node
starts ROS with :func:`start_ros`, calls :func:`running` once it is built and runs while
:func:`ok`: SIGINT and SIGTERM stop a node at any moment, its start included (see
:mod:`pneumatic_unload.nodes`).
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.signals import SignalHandlerOptions

from pneumatic_unload.config import ConfigError, RigConfig, adapters
from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.config.adapters import ParameterSpec
from pneumatic_unload.nodes import HELD_SIGNALS, held_signal, hold_signals

#: Pressure samples: reliable, deep history (the subscriber's callback is the bottleneck).
PRESSURE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
#: Lossless input: reliable and KEEP_ALL, so that a burst (a replay at full speed) waits
#: in the reader's cache until the callback takes it instead of being overwritten.
LOSSLESS_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)
#: Sensor-data QoS of a subscriber: best effort (matches reliable and best-effort
#: publishers), with a deep queue so that bursts are not dropped.
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
#: Latched results and configuration: a late subscriber gets the last ones.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

STAMP_SCALE = 1_000_000_000


def stamp_to_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * STAMP_SCALE + int(stamp.nanosec)


def ns_to_stamp(ns: int, stamp: Any) -> Any:
    """Write integer nanoseconds into a builtin_interfaces/Time (in place) and return it."""
    stamp.sec, stamp.nanosec = divmod(int(ns), STAMP_SCALE)
    return stamp


def ns_to_seconds(ns: int) -> float:
    """Integer nanoseconds -> float seconds, exactly as the offline analysis does [s]."""
    return ns * 1e-9


# --------------------------------------------------------------------------- parameters
def descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """ParameterDescriptor of a settings field (its range, unit and meaning)."""
    kinds = {"double": ParameterType.PARAMETER_DOUBLE, "integer": ParameterType.PARAMETER_INTEGER,
             "string": ParameterType.PARAMETER_STRING, "bool": ParameterType.PARAMETER_BOOL,
             "string_array": ParameterType.PARAMETER_STRING_ARRAY}
    d = ParameterDescriptor(name=spec.name, type=kinds[spec.kind], description=spec.description,
                            dynamic_typing=spec.dynamic_typing)
    if spec.kind == "double" and spec.lo is not None and spec.hi is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo),
                                                     to_value=float(spec.hi), step=0.0)]
    elif spec.kind == "integer" and spec.lo is not None and spec.hi is not None:
        d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=1)]
    return d


def settings_parameters(cls: type, **kw: Any) -> dict[str, tuple[Any, ParameterDescriptor]]:
    """ROS parameter (default, descriptor) of every field of a settings class
    (:func:`pneumatic_unload.config.adapters.parameter_specs`; ``kw`` as there)."""
    return {n: (s.default, descriptor(s)) for n, s in adapters.parameter_specs(cls, **kw).items()}


def node_parameters(node: str) -> dict[str, tuple[Any, ParameterDescriptor]]:
    """ROS parameter (default, descriptor) of every parameter of ``node``
    (:func:`pneumatic_unload.config.nodes.node_parameters`: the same list as its ``--help``
    and ``config/<node>.yaml``); an unset string array's default is its type."""
    from rclpy.parameter import Parameter

    return {n: (Parameter.Type.STRING_ARRAY if s.kind == "string_array" else s.default,
                descriptor(s)) for n, s in config_nodes.node_parameters(node).items()}


def rig_parameter_descriptors() -> dict[str, tuple[Any, ParameterDescriptor]]:
    """ROS parameter (default, descriptor) of every RigConfig field."""
    return settings_parameters(RigConfig)


def double_param(description: str, lo: float, hi: float) -> ParameterDescriptor:
    """Descriptor of a double parameter with a range."""
    return ParameterDescriptor(
        type=ParameterType.PARAMETER_DOUBLE, description=description,
        floating_point_range=[FloatingPointRange(from_value=lo, to_value=hi, step=0.0)])


def int_param(description: str, lo: int, hi: int) -> ParameterDescriptor:
    """Descriptor of an integer parameter with a range."""
    return ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER, description=description,
        integer_range=[IntegerRange(from_value=lo, to_value=hi, step=1)])


def str_param(description: str) -> ParameterDescriptor:
    """Descriptor of a string parameter."""
    return ParameterDescriptor(type=ParameterType.PARAMETER_STRING, description=description)


def bool_param(description: str) -> ParameterDescriptor:
    """Descriptor of a bool parameter."""
    return ParameterDescriptor(type=ParameterType.PARAMETER_BOOL, description=description)


def rig_config_from(values: dict[str, Any]) -> RigConfig:
    """RigConfig from ROS parameter values (raises ConfigError with the reason)."""
    return RigConfig(**adapters.from_parameters(RigConfig, values))


def validating_callback(check: Callable[[dict[str, Any]], str]
                        ) -> Callable[[list[Any]], SetParametersResult]:
    """An on-set-parameters callback that rejects a change when ``check`` says why.

    ``check`` receives {name: new value} and returns '' to accept or the reason.
    """
    def callback(params: list[Any]) -> SetParametersResult:
        try:
            reason = check({p.name: p.value for p in params})
        except ConfigError as exc:
            reason = str(exc)
        return SetParametersResult(successful=not reason, reason=reason)

    return callback


# --------------------------------------------------------------------------- spinning
def make_executor(kind: str = "events") -> Any:
    """'events' (rclpy.experimental.EventsExecutor: the one that holds 10 kHz) or 'single'.
    An rclpy without ``rclpy.experimental`` (before 7.1.4) gets the SingleThreadedExecutor,
    with a warning that it may drop samples above about 1 kHz."""
    if kind == "events":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError as exc:
            import warnings

            warnings.warn(f"this rclpy has no EventsExecutor ({exc}; rclpy 7.1.4 or later "
                          "has it): the SingleThreadedExecutor runs the node, which may drop "
                          "samples above about 1 kHz", RuntimeWarning, stacklevel=2)
            return rclpy.executors.SingleThreadedExecutor()
        return EventsExecutor()
    return rclpy.executors.SingleThreadedExecutor()


def start_ros(args: Sequence[str] | None = None) -> bool:
    """Start ROS for a node: ``rclpy.init`` without rclpy's signal handlers, SIGINT and SIGTERM
    held (recorded, not acted upon; see :mod:`pneumatic_unload.nodes`), so that the node is
    built whole. Returns False, without starting ROS, when a signal came already (during the
    imports): the node stops before it starts.

    rclpy's handlers are never installed: they shut the context down from a thread of their
    own, at any instant, also while an EventsExecutor registers the node's callbacks (it
    needs the context for that); the executor then keeps callbacks it no longer knows of and
    aborts the process when it is destroyed (exit status -6). A node's loop ends on
    :func:`ok` instead, and the context is shut down after the executor.
    """
    hold_signals()
    if held_signal() is not None:
        return False
    rclpy.init(args=list(args) if args is not None else sys.argv,
               signal_handler_options=SignalHandlerOptions.NO)
    return True


def stopping() -> bool:
    """True once a SIGINT or SIGTERM came (during the start or since)."""
    return held_signal() is not None


def ok() -> bool:
    """Go on running: ROS is up and no SIGINT or SIGTERM came."""
    return rclpy.ok() and not stopping()


def running(*, keyboard_interrupt: bool = False) -> None:
    """The node is built and about to run: raises KeyboardInterrupt when a SIGINT or SIGTERM
    came during the start, so that the node stops here through its usual path (``close()``,
    executor shutdown, destroy, ``rclpy`` shutdown; exit status 0). Main thread.

    From now on SIGINT and SIGTERM stay recorded and the node's loop ends on :func:`ok`
    (:func:`run`, the recorder): no KeyboardInterrupt breaks into a callback or into the
    executor's own work. ``keyboard_interrupt``: they raise KeyboardInterrupt in the main
    thread instead (a node that sleeps or waits outside an executor: the replay).
    """
    if keyboard_interrupt:
        for sig in HELD_SIGNALS:
            signal.signal(sig, signal.default_int_handler)
    if stopping():
        raise KeyboardInterrupt


def run(node_factory: Callable[[], Node], args: Sequence[str] | None = None,
        executor: str = "events") -> int:
    """Init rclpy, build the node, spin until SIGINT/SIGTERM, clean up; exit code 0.

    A node's ``close()`` (if it has one) runs before the node is destroyed, so that files
    are completed on SIGINT and SIGTERM, also when they come during the start
    (:func:`start_ros`, :func:`running`); the executor is shut down before the node is
    destroyed, and ROS after both.
    """
    if not start_ros(args):
        return 0
    node: Node | None = None
    ex: Any = None
    code = 0
    try:
        node = node_factory()
        ex = make_executor(executor)
        ex.add_node(node)
        running()
        # spin() of the EventsExecutor does not return on shutdown: poll
        while ok():
            try:
                ex.spin_once(timeout_sec=0.1)
            except RuntimeError:
                # an event taken by the EventsExecutor in the instant the context is shut
                # down (from outside) cannot be handed to Python ("Unable to convert call
                # argument"): that is the shutdown, not a fault
                if rclpy.ok():
                    raise
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f"[{exc.node}] error: {exc}", file=sys.stderr)
        code = 2
    except (ParameterException, ConfigError) as exc:
        print(f"error: invalid parameter: {exc}", file=sys.stderr)
        code = 2
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            if ex is not None:
                # before the node is destroyed and ROS shut down: the executor takes back
                # the node's callbacks (it needs the context for that)
                with contextlib.suppress(Exception):
                    ex.shutdown(timeout_sec=1.0)
            node.destroy_node()
        rclpy.try_shutdown()
    return code


class StartupError(RuntimeError):
    """A node cannot start (bad parameters, missing file): one clear line, exit code 2."""

    def __init__(self, node: str, message: str) -> None:
        super().__init__(message)
        self.node = node
