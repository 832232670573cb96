"""A live cycle of charges and discharges of one component over DDS: a script, not a test.

Why: issue #26's acceptance asks that a cycle of 20 alternating charges and discharges give
both directions' C within their sigma of the rig's. ``pneumatic_unload/test/test_nodes_two_way.py``
runs four
steps; this runs as many as asked (20 by default, about 7 minutes at the default timing).

What: the simulator in mode 'alternate' (a 1 L tank, C 8e-9 m^3/(s Pa), b 0.45, natural
heat exchange, a charge from the room's pressure through the component from a 6 bar abs
supply, then its discharge to the room from where the charge left the tank, in turn; each
step ``--duration`` s with the valve open, ``--settle`` s before the next), the estimator
with direction 'both' (the rig's 10 Hz temperature topic fitted beside each step's
pressure), and a subscriber in this process collecting the final estimates. Prints one row
per step (direction, C, its sigma, z = (C - C_rig)/sigma, b) and per direction the count
within 1 and 2 sigma, the mean error and the RMS z.

Run from the repo root with the project venv::

    python bench/bench_cycle.py [--steps 20] [--duration 20] [--settle 1.5]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

C_RIG, B_RIG, V = 8e-9, 0.45, 1e-3


def main() -> int:
    """Run the cycle and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20, help="steps (charges and discharges)")
    ap.add_argument("--duration", type=float, default=20.0, help="each step's length [s]")
    ap.add_argument("--settle", type=float, default=1.5, help="plateau before a step [s]")
    args = ap.parse_args()
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    from pneumatic_unload.app.launch import NodeProcess, free_domain_id

    os.environ.setdefault("ROS_DOMAIN_ID", str(free_domain_id()))
    import rclpy
    from pneumatic_unload_msgs.msg import UnloadEstimate

    from pneumatic_unload.nodes.common import LATCHED_QOS

    rclpy.init()
    node = rclpy.create_node(f"bench_cycle_{os.getpid()}")
    got: list[Any] = []
    node.create_subscription(UnloadEstimate, "/estimator/estimate", got.append, LATCHED_QOS)
    with tempfile.TemporaryDirectory(prefix="bench_cycle_") as d:
        tmp = Path(d)
        est = NodeProcess("estimator", {"volume": V, "qos": "reliable", "direction": "both"},
                          tmp)
        sim = NodeProcess("simulator", {
            "direction": "charge", "volume": V, "conductance": C_RIG,
            "critical_ratio": B_RIG, "initial_pressure": 101325.0, "supply_pressure": 6e5,
            "effects": "heat_transfer", "noise_std": 600.0, "seed": 7,
            "duration": args.duration, "mode": "alternate", "cycles": args.steps,
            "settle_time": args.settle, "vent_time": 0.0, "wait_for_subscribers": 1}, tmp)
        limit = 60.0 + args.steps * (args.duration + args.settle) * 1.5
        t0 = time.monotonic()
        try:
            while time.monotonic() - t0 < limit:
                rclpy.spin_once(node, timeout_sec=0.2)
                if len([m for m in got if "curve-fit" in m.method]) >= args.steps:
                    break
                if est.proc.poll() is not None or sim.proc.poll() is not None:
                    break
        finally:
            sim.stop()
            est.stop()
    node.destroy_node()
    rclpy.shutdown()
    finals = [m for m in got if "curve-fit" in m.method]
    print(f"# Live cycle: {len(finals)} of {args.steps} steps with a final estimate in "
          f"{time.monotonic() - t0:.0f} s (rig C {C_RIG:g} m^3/(s Pa), b {B_RIG})\n")
    print("| step | direction | C [1e-9] | sigma [1e-9] | C err [%] | z | b | status |")
    print("|---|---|---|---|---|---|---|---|")
    for m in finals:
        z = (m.conductance_model - C_RIG) / m.conductance_model_std
        print(f"| {m.unload_index} | {m.direction} | {m.conductance_model * 1e9:.4f} | "
              f"{m.conductance_model_std * 1e9:.4f} | "
              f"{100 * (m.conductance_model / C_RIG - 1):+.3f} | {z:+.2f} | "
              f"{m.critical_ratio:.3f} | {m.status} |")
    print()
    for direction in ("charge", "discharge"):
        ms = [m for m in finals if m.direction == direction]
        if not ms:
            print(f"{direction}: none")
            continue
        zs = [(m.conductance_model - C_RIG) / m.conductance_model_std for m in ms]
        errs = [100 * (m.conductance_model / C_RIG - 1) for m in ms]
        print(f"{direction}: {len(ms)} steps, within 1 sigma {sum(abs(z) <= 1 for z in zs)}, "
              f"within 2 sigma {sum(abs(z) <= 2 for z in zs)}, mean C error "
              f"{sum(errs) / len(errs):+.3f} %, RMS z "
              f"{math.sqrt(sum(z * z for z in zs) / len(zs)):.2f}")
    return 0 if len(finals) >= args.steps else 1


if __name__ == "__main__":
    sys.exit(main())
