"""Benchmark of the live nodes over real DDS (a script, not a timed test).

1. Simulator at 1 kHz and 10 kHz: rate delivered to a subscriber in another process, loss
   (samples received vs published), latency (arrival - header stamp) and inter-arrival
   jitter, p50/p99.
2. Estimator fed by the simulator in cycle mode (many short unloads): latency from the
   arrival of the sample that completes an estimate to its publication, p50/p99 (measured
   inside the estimator node, reported on /diagnostics), and samples lost at 10 kHz
   (estimator's received count vs simulator's published count), for per-sample
   FluidPressure and for PressureBlock input.
3. ``pneumatic-unload simulate`` (no ROS): a 60 s run written as a bag, times real time.

Run: ``.venv/bin/python bench/bench_nodes.py`` (about 2-3 minutes). Prints markdown tables.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneumatic_unload.app.launch import NodeProcess, free_domain_id

RIG = {"volume": 2e-4, "conductance": 8e-9, "noise_std": 1000.0, "quantization": 10.0,
       "seed": 1}


def subscriber(seconds: float, out: str, block: bool) -> int:
    """Subscriber side: record (header stamp, arrival) of every sample for ``seconds``."""
    import rclpy
    from rclpy.experimental import EventsExecutor
    from sensor_msgs.msg import FluidPressure

    from pneumatic_unload.nodes.common import PRESSURE_QOS, stamp_to_ns

    rclpy.init()
    node = rclpy.create_node("bench_subscriber")
    stamps: list[int] = []
    arrivals: list[int] = []

    def on_msg(msg: FluidPressure) -> None:
        arrivals.append(time.time_ns())
        stamps.append(stamp_to_ns(msg.header.stamp))

    def on_block(msg: object) -> None:
        now = time.time_ns()
        ns0 = stamp_to_ns(msg.header.stamp)  # type: ignore[attr-defined]
        n = len(msg.pressure)  # type: ignore[attr-defined]
        period = msg.sample_period  # type: ignore[attr-defined]
        stamps.extend(ns0 + round(k * period * 1e9) for k in range(n))
        arrivals.extend([now] * n)

    if block:
        from pneumatic_unload_msgs.msg import PressureBlock

        node.create_subscription(PressureBlock, "/tank/pressure_block", on_block, PRESSURE_QOS)
    else:
        node.create_subscription(FluidPressure, "/tank/pressure", on_msg, PRESSURE_QOS)
    ex = EventsExecutor()
    ex.add_node(node)
    # until the stream has ended (no sample for 2 s) or ``seconds`` at most
    end = time.monotonic() + seconds
    last_n, last_change = 0, time.monotonic()
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.1)
        if len(stamps) != last_n:
            last_n, last_change = len(stamps), time.monotonic()
        elif last_n and time.monotonic() - last_change > 2.0:
            break
    np.save(out, np.array([stamps, arrivals], dtype=np.int64))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def bench_simulator(rate: float, seconds: float, block: int, tmp: Path) -> dict[str, object]:
    """Simulator -> subscriber process: rate, loss, latency and jitter."""
    out = tmp / f"sub-{rate:g}-{block}.npy"
    sub = subprocess.Popen([sys.executable, __file__, "--subscriber", str(seconds + 60.0),
                            str(out)] + (["--block"] if block else []))
    sim = NodeProcess("simulator", {**RIG, "rate": rate, "wait_for_subscribers": 1,
                                    "temperature_rate": 0.0, "block_size": block,
                                    "per_sample": not block}, tmp)
    sim.wait_output("streaming at", 30.0)
    time.sleep(seconds)
    sim.stop()
    sub.wait(timeout=30)
    published = int(re.search(r"published (\d+) pressure samples", sim.output()).group(1))
    stamps, arrivals = np.load(out)
    n = stamps.size
    lat = (arrivals - stamps) / 1e6
    span = (stamps[-1] - stamps[0]) / 1e9 if n > 1 else float("nan")
    gaps = np.diff(arrivals) / 1e6 - (1e3 / rate if not block else 0.0)
    return {
        "rate [Hz]": f"{rate:g}" + (f" (blocks of {block})" if block else ""),
        "published": published, "received": n,
        "lost": published - n if published >= n else f"{published - n} (late start)",
        "delivered [samples/s]": f"{(n - 1) / span:.0f}" if n > 1 else "-",
        "latency p50/p99 [ms]": f"{np.percentile(lat, 50):.3f} / {np.percentile(lat, 99):.3f}",
        "arrival jitter p50/p99 [ms]": (f"{np.percentile(np.abs(gaps), 50):.3f} / "
                                        f"{np.percentile(np.abs(gaps), 99):.3f}")
        if not block else "-",
    }


def bench_estimator(rate: float, seconds: float, block: int, tmp: Path) -> dict[str, object]:
    """Simulator (cycle mode) -> estimator: latency of the estimates and loss."""
    est = NodeProcess("estimator", {"volume": RIG["volume"], "diagnostics_period": 0.5,
                                    "input": "block" if block else "sample",
                                    "qos": "reliable" if block else "sensor_data",
                                    "curve_fit": True},
                      tmp)
    sim = NodeProcess("simulator", {**RIG, "rate": rate, "mode": "cycle", "settle_time": 0.6,
                                    "vent_time": 0.3, "charge_time": 0.3, "duration": 1.2,
                                    "wait_for_subscribers": 1, "temperature_rate": 0.0,
                                    "block_size": block, "per_sample": not block}, tmp)
    sim.wait_output("streaming at", 30.0)
    time.sleep(seconds)
    sim.stop()
    time.sleep(1.5)  # the estimator drains its queue
    est.stop()
    published = int(re.search(r"published (\d+) pressure samples", sim.output()).group(1))
    text = est.output()
    m = re.findall(r"stats (\{.*\})", text)
    stats = json.loads(m[-1]) if m else {}
    lat = np.asarray(stats.get("latencies_ms", []))
    fin = np.asarray(stats.get("final_latencies_ms", []))
    results = len(re.findall(r"\] \[estimator\]: unload \d+:", text))
    return {
        "input": f"{rate:g} Hz " + (f"PressureBlock x{block}" if block else "FluidPressure"),
        "published": published, "analysed": stats.get("received", "?"),
        "lost": published - int(stats.get("received", 0)),
        "estimates": results,
        "crossing estimate latency p50/p99/max [ms]": _pct(lat),
        "final (curve-fit) latency p50/p99/max [ms]": _pct(fin),
    }


def bench_simulate_cli(tmp: Path) -> dict[str, object]:
    """``pneumatic-unload simulate``: a 60 s run at 1 kHz with heat transfer into a bag."""
    from pneumatic_unload.analysis.runs import write_simulated_bag
    from pneumatic_unload.config import RigConfig

    cfg = RigConfig(volume=5e-3, effects=("heat_transfer",), pre_time=1.0, duration=59.0,
                    noise_std=1000.0, seed=2)
    t0 = time.perf_counter()
    info = write_simulated_bag(cfg, tmp / "sim60", analyze_live=False)
    wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    write_simulated_bag(cfg, tmp / "sim60b", analyze_live=True)
    wall_est = time.perf_counter() - t1
    return {"run": "60 s at 1 kHz, heat transfer", "samples": info["samples"],
            "simulate + write bag [s]": f"{wall:.3f}",
            "x real time": f"{info['duration'] / wall:.0f}",
            "with live estimator too [s]": f"{wall_est:.3f}",
            "x real time (with estimator)": f"{info['duration'] / wall_est:.0f}"}


def _pct(x: np.ndarray) -> str:
    if not x.size:
        return "-"
    return (f"{np.percentile(x, 50):.2f} / {np.percentile(x, 99):.2f} / {x.max():.2f} "
            f"(n={x.size})")


def _table(rows: list[dict[str, object]]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def main() -> int:
    """Run the benchmark and print the tables."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--subscriber", nargs=2, metavar=("SECONDS", "OUT"))
    ap.add_argument("--block", action="store_true")
    ap.add_argument("--seconds", type=float, default=8.0)
    args = ap.parse_args()
    if args.subscriber:
        return subscriber(float(args.subscriber[0]), args.subscriber[1], args.block)
    os.environ.setdefault("ROS_DOMAIN_ID", str(free_domain_id()))
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows = [bench_simulator(r, args.seconds, 0, tmp) for r in (1000.0, 10000.0)]
        rows.append(bench_simulator(10000.0, args.seconds, 100, tmp))
        print("## Simulator -> subscriber in another process\n")
        print(_table(rows))
        rows = [bench_estimator(1000.0, 4 * args.seconds, 0, tmp),
                bench_estimator(10000.0, 2 * args.seconds, 0, tmp),
                bench_estimator(10000.0, 2 * args.seconds, 100, tmp)]
        print("\n## Simulator (cycle mode) -> estimator\n")
        print(_table(rows))
        print("\n## Offline `pneumatic-unload simulate` (no ROS)\n")
        print(_table([bench_simulate_cli(tmp)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
