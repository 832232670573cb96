"""Bag benchmarks (a script, not a test): prints tables.

1. Offline read of a 1-million-sample ``/tank/pressure`` bag: ``read_pressure`` (bulk numpy
   decoding of the fixed FluidPressure CDR layout) against rosbags reading and deserialising
   every message of the same bag (stamp and pressure extracted), in the same run; optionally
   the ``mcap`` reader with mcap-ros2-support (``--mcap``, slow).
2. The ``recorder`` node over DDS: a publisher process sends FluidPressure at 1 kHz and
   10 kHz (reliable, depth 1000) for a few seconds, the recorder (its own process) writes the
   bag; then SIGINT and the samples in the bag are counted (loss = not in the bag).

Usage: ``.venv/bin/python bench/bench_bag.py [--samples N] [--seconds S] [--rates 1000,10000]
[--mcap] [--no-dds]``. Uses its own ROS_DOMAIN_ID (random 150..199 unless set).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

from pneumatic_unload.io.bag import (
    MSGTYPE_PRESSURE,
    TOPIC_PRESSURE,
    BagRecorder,
    make_typestore,
    read_pressure,
)

_PUBLISHER = textwrap.dedent(
    """
    import json, struct, sys, time
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import FluidPressure

    rate, seconds = float(sys.argv[1]), float(sys.argv[2])
    rclpy.init()
    node = rclpy.create_node("bench_publisher")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    pub = node.create_publisher(FluidPressure, "/tank/pressure", qos)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.5)
    layout = struct.Struct("<4siII5s7xdd")  # CDR of FluidPressure with frame_id "tank"
    n = int(rate * seconds)
    start = time.monotonic()
    t0 = time.time_ns()
    errors = 0
    for k in range(n):
        due = start + k / rate
        while time.monotonic() < due:  # paced loop; sleep when far ahead
            if due - time.monotonic() > 0.002:
                time.sleep(0.001)
        sec, nsec = divmod(t0 + int(k * 1e9 / rate), 1_000_000_000)
        try:
            pub.publish(layout.pack(b"\\x00\\x01\\x00\\x00", sec, nsec, 5, b"tank",
                                    1e5 + k, 0.0))
        except Exception:
            errors += 1
    elapsed = time.monotonic() - start
    time.sleep(1.0)  # let the last samples be delivered
    print(json.dumps({"sent": n - errors, "errors": errors, "elapsed": elapsed}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    """
)


def make_bag(path: Path, n: int) -> None:
    """A bag of ``n`` pressure samples at 1 kHz (vectorised writer)."""
    t_ns = 1_700_000_000 * 10**9 + np.arange(n, dtype=np.int64) * 1_000_000
    p = 1e5 + np.random.default_rng(0).normal(0.0, 1e3, n)
    with BagRecorder(path, config={"bench": True}) as rec:
        rec.write_pressures(t_ns, p)


def read_with_rosbags(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """rosbags: read every message and deserialise it (the per-message reference)."""
    from rosbags.rosbag2 import Reader

    store = make_typestore()
    stamps: list[int] = []
    values: list[float] = []
    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_PRESSURE]
        for _, _, raw in reader.messages(connections=conns):
            msg = store.deserialize_cdr(raw, MSGTYPE_PRESSURE)
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            values.append(msg.fluid_pressure)
    return np.array(stamps, np.int64), np.array(values)


def read_with_mcap(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """mcap + mcap-ros2-support decoding every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    stamps: list[int] = []
    values: list[float] = []
    (mcap_file,) = path.glob("*.mcap")
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=[TOPIC_PRESSURE]):
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            values.append(msg.fluid_pressure)
    return np.array(stamps, np.int64), np.array(values)


def timed(fn, *args, repeat: int = 1):
    """(best wall time [s], result of the last call)."""
    best = float("inf")
    result = None
    for _ in range(repeat):
        t = time.perf_counter()
        result = fn(*args)
        best = min(best, time.perf_counter() - t)
    return best, result


def bench_offline(n: int, with_mcap: bool, workdir: Path) -> None:
    bag = workdir / "million"
    t_write, _ = timed(make_bag, bag, n)
    size_mb = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
    print(f"\n## Offline read of a {n:,}-sample bag ({size_mb:.1f} MB, written in {t_write:.2f} s)")
    t_ours, (t_a, p_a) = timed(read_pressure, bag, repeat=3)
    t_ref, (t_b, p_b) = timed(read_with_rosbags, bag)
    assert np.array_equal(t_a, t_b) and np.array_equal(p_a, p_b), "readers disagree"
    rows = [("read_pressure (numpy bulk decode)", t_ours),
            ("rosbags Reader + deserialize_cdr", t_ref)]
    if with_mcap:
        t_mc, (t_c, p_c) = timed(read_with_mcap, bag)
        assert np.array_equal(t_a, t_c) and np.array_equal(p_a, p_c), "mcap disagrees"
        rows.append(("mcap + mcap-ros2-support decode", t_mc))
    print(f"| {'reader':<36} | {'time [s]':>8} | {'messages/s':>12} | {'vs rosbags':>10} |")
    print(f"|{'-' * 38}|{'-' * 10}|{'-' * 14}|{'-' * 12}|")
    for name, t in rows:
        print(f"| {name:<36} | {t:8.3f} | {n / t:12,.0f} | {t_ref / t:9.1f}x |")


def bench_recorder(rates: list[float], seconds: float, workdir: Path) -> None:
    env = dict(os.environ)
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(150, 199)))
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    script = workdir / "publisher.py"
    script.write_text(_PUBLISHER)
    print(f"\n## recorder node over DDS ({seconds:g} s per rate, ROS_DOMAIN_ID="
          f"{env['ROS_DOMAIN_ID']})")
    print(f"| {'rate [Hz]':>9} | {'published':>9} | {'in bag':>9} | {'loss':>7} | "
          f"{'pub rate [Hz]':>13} |")
    print(f"|{'-' * 11}|{'-' * 11}|{'-' * 11}|{'-' * 9}|{'-' * 15}|")
    for rate in rates:
        bag = workdir / f"rec-{int(rate)}"
        rec = subprocess.Popen(
            [sys.executable, "-m", "pneumatic_unload.nodes.recorder", "--ros-args",
             "-p", f"output:={bag}"], env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True)
        pub = subprocess.Popen([sys.executable, str(script), str(rate), str(seconds)],
                               env=env, stdout=subprocess.PIPE, text=True)
        try:
            out, _ = pub.communicate(timeout=seconds + 60)
            info = json.loads(out.strip().splitlines()[-1])
        finally:
            rec.send_signal(signal.SIGINT)
            _, err = rec.communicate(timeout=60)
        if rec.returncode != 0:
            print(f"recorder failed ({rec.returncode}): {err}")
            continue
        got = read_pressure(bag).t_ns.size
        sent = info["sent"]
        loss = 1.0 - got / sent if sent else float("nan")
        print(f"| {rate:9.0f} | {sent:9d} | {got:9d} | {loss:7.2%} | "
              f"{sent / info['elapsed']:13.0f} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--rates", default="1000,10000")
    ap.add_argument("--mcap", action="store_true", help="also time the mcap reader (slow)")
    ap.add_argument("--no-dds", action="store_true", help="skip the recorder benchmark")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_bag_") as tmp:
        workdir = Path(tmp)
        bench_offline(args.samples, args.mcap, workdir)
        if not args.no_dds:
            bench_recorder([float(r) for r in args.rates.split(",")], args.seconds, workdir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
