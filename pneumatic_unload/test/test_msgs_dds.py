# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Messages over real DDS between separate processes (rclpy + Fast DDS, loopback).

Each test writes small node scripts into tmp_path and runs them with the venv python. The
processes inherit ROS_DOMAIN_ID from conftest.py and use a topic unique to the test, every
script has its own deadline, and every process is killed in a finally block.
"""

import json
import math
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

PROCESS_TIMEOUT_S = 20.0  # each script gives up on its own after this
WAIT_S = PROCESS_TIMEOUT_S + 20.0  # the test's own bound on waiting for a process

_COMMON = textwrap.dedent(
    """
    import json, math, select, sys, time
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    ARGS = json.loads(sys.argv[1])
    DEADLINE = time.monotonic() + ARGS["timeout"]


    def qos(durability):
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=ARGS["depth"],
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy[durability])


    def set_path(msg, path, value):
        *parents, leaf = path.split(".")
        for name in parents:
            msg = getattr(msg, name)
        setattr(msg, leaf, value)


    def get_path(msg, path):
        for name in path.split("."):
            msg = getattr(msg, name)
        return msg


    def stdin_closed(wait_s):
        # The test closes our stdin when it is done with us (also when it dies).
        return bool(select.select([sys.stdin], [], [], wait_s)[0])


    def run(body):
        context = rclpy.Context()
        rclpy.init(context=context)
        node = None
        try:
            node = rclpy.create_node(ARGS["node"], context=context)
            return body(node, context)
        except (KeyboardInterrupt, ExternalShutdownException):
            return 130
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown(context=context)


    def spin_until(node, context, done):
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            while not done() and context.ok() and time.monotonic() < DEADLINE:
                executor.spin_once(timeout_sec=0.05)
        finally:
            executor.shutdown(timeout_sec=1.0)
    """
)

_ESTIMATE_PUB = textwrap.dedent(
    """
    from pneumatic_unload_msgs.msg import UnloadEstimate

    def body(node, context):
        pub = node.create_publisher(UnloadEstimate, ARGS["topic"], qos("TRANSIENT_LOCAL"))
        msg = UnloadEstimate()
        for path, value in ARGS["values"].items():
            set_path(msg, path, value)
        sent = 0
        while context.ok() and time.monotonic() < DEADLINE:
            pub.publish(msg)
            sent += 1
            if stdin_closed(0.05):
                break
        print(json.dumps({"sent": sent, "subscribers": pub.get_subscription_count()}))
        return 0

    sys.exit(run(body))
    """
)

_ESTIMATE_SUB = textwrap.dedent(
    """
    from pneumatic_unload_msgs.msg import UnloadEstimate

    def body(node, context):
        got = []
        node.create_subscription(UnloadEstimate, ARGS["topic"], got.append,
                                 qos("TRANSIENT_LOCAL"))
        spin_until(node, context, lambda: got)
        if not got:
            print(json.dumps({"error": "no UnloadEstimate before the deadline"}))
            return 2
        print(json.dumps({path: get_path(got[0], path) for path in ARGS["paths"]}))
        return 0

    sys.exit(run(body))
    """
)

_PRESSURE_SUB = textwrap.dedent(
    """
    from sensor_msgs.msg import FluidPressure

    def body(node, context):
        got = []
        node.create_subscription(FluidPressure, ARGS["topic"], got.append, qos("VOLATILE"))
        spin_until(node, context, lambda: len(got) >= ARGS["count"])
        linger = time.monotonic() + 0.3  # catch duplicates or extras, if any
        spin_until(node, context, lambda: time.monotonic() > linger)
        print(json.dumps({
            "pressure": [m.fluid_pressure for m in got],
            "variance": [m.variance for m in got],
            "stamp": [[m.header.stamp.sec, m.header.stamp.nanosec] for m in got],
        }))
        return 0

    sys.exit(run(body))
    """
)

_PRESSURE_PUB = textwrap.dedent(
    """
    from sensor_msgs.msg import FluidPressure

    def body(node, context):
        pub = node.create_publisher(FluidPressure, ARGS["topic"], qos("VOLATILE"))
        while pub.get_subscription_count() < 1:
            if time.monotonic() > DEADLINE or stdin_closed(0.01):
                print(json.dumps({"error": "no subscriber matched"}))
                return 2
        period = 1.0 / ARGS["rate_hz"]
        msg = FluidPressure()
        msg.header.frame_id = "tank"
        t0 = time.monotonic()
        for i in range(ARGS["count"]):
            while (wait := t0 + i * period - time.monotonic()) > 0:  # paced, monotonic clock
                time.sleep(wait)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(i * 1_000_000, 10**9)
            msg.fluid_pressure = ARGS["p0"] + i
            msg.variance = float(i)
            pub.publish(msg)
        elapsed = time.monotonic() - t0
        # Reliable data still in flight is lost if the writer goes away: wait for the acks.
        acked = pub.wait_for_all_acked(Duration(seconds=5))
        print(json.dumps({"elapsed": elapsed, "acked": acked}))
        return 0

    sys.exit(run(body))
    """
)


class _Node:
    """One node process; stdout/stderr go to files (no pipe to fill up and block)."""

    def __init__(self, tmp_path: Path, name: str, script: str, args: dict) -> None:
        self.name = name
        path = tmp_path / f"{name}.py"
        path.write_text(_COMMON + script)
        self.out, self.err = tmp_path / f"{name}.out", tmp_path / f"{name}.err"
        args = {"node": name, "timeout": PROCESS_TIMEOUT_S, **args}
        with self.out.open("w") as out, self.err.open("w") as err:
            self.proc = subprocess.Popen(
                [sys.executable, str(path), json.dumps(args)],
                stdin=subprocess.PIPE, stdout=out, stderr=err,
            )  # fmt: skip

    def finish(self, timeout: float = WAIT_S) -> dict:
        """Close stdin, wait for the exit, check rc 0, return the last stdout line as JSON."""
        try:
            self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError(
                f"{self.name} still running after {timeout} s: {self.log()}"
            ) from None
        assert self.proc.returncode == 0, f"{self.name} rc={self.proc.returncode}: {self.log()}"
        lines = self.out.read_text().strip().splitlines()
        assert lines, f"{self.name} printed nothing: {self.log()}"
        return json.loads(lines[-1])

    def log(self) -> str:
        return f"\n--- stdout\n{self.out.read_text()}\n--- stderr\n{self.err.read_text()}"

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)


def _topic(name: str) -> str:
    return f"/pneumatic_unload_test_{uuid.uuid4().hex[:12]}/{name}"


ESTIMATE_VALUES = {
    "header.stamp.sec": 1_700_000_123,
    "header.stamp.nanosec": 456_789_012,
    "header.frame_id": "tank_pressure_sensor",
    "unload_start.sec": 1_700_000_121,
    "unload_start.nanosec": 999_999_999,
    "unload_index": 4_000_000_000,
    "status": 0,
    "status_text": "ok",
    "method": "eq39+isentropic-inversion+curve-fit",
    "quality": 0.875,
    "conductance": 1.234e-8,
    "conductance_model": 1.1987654321e-8,
    "conductance_model_std": 3.3e-11,
    "critical_ratio": math.nan,
    "critical_ratio_std": math.nan,
    "tau_exp": 0.567,
    "p10": 600_000.125,
    "p_atm": 101_325.0,
    "p_star": 284_818.123456789,
    "initial_temperature": 293.15,
    "volume": 1e-3 / 3,
}


def test_unload_estimate_round_trip(tmp_path):
    topic = _topic("estimate")
    common = {"topic": topic, "depth": 10}
    nodes = []
    try:
        # Publisher first: transient_local must also serve the late-joining subscriber.
        nodes.append(pub := _Node(tmp_path, "estimate_pub", _ESTIMATE_PUB,
                                  {**common, "values": ESTIMATE_VALUES}))  # fmt: skip
        nodes.append(sub := _Node(tmp_path, "estimate_sub", _ESTIMATE_SUB,
                                  {**common, "paths": list(ESTIMATE_VALUES)}))  # fmt: skip
        received = sub.finish()
        published = pub.finish()
    finally:
        for node in nodes:
            node.kill()
    assert published["sent"] >= 1
    for path, expected in ESTIMATE_VALUES.items():
        got = received[path]
        if isinstance(expected, float) and math.isnan(expected):
            assert isinstance(got, float) and math.isnan(got), (path, got)
        else:
            assert got == expected and type(got) is type(expected), (path, got, expected)


def test_fluid_pressure_1khz_none_lost(tmp_path):
    count, p0 = 200, 100_000.0
    common = {"topic": _topic("pressure"), "depth": 1000, "count": count}
    nodes = []
    try:
        nodes.append(sub := _Node(tmp_path, "pressure_sub", _PRESSURE_SUB, common))
        nodes.append(pub := _Node(tmp_path, "pressure_pub", _PRESSURE_PUB,
                                  {**common, "rate_hz": 1000.0, "p0": p0}))  # fmt: skip
        received = sub.finish()
        published = pub.finish()  # closing the publisher's stdin earlier would stop it
    finally:
        for node in nodes:
            node.kill()
    assert published["acked"], published
    assert received["pressure"] == [p0 + i for i in range(count)], (
        f"{len(received['pressure'])}/{count} received in {published['elapsed']:.3f} s"
    )
    assert received["variance"] == [float(i) for i in range(count)]
    assert received["stamp"] == [list(divmod(i * 1_000_000, 10**9)) for i in range(count)]
