"""Benchmark: data lost when the recorder is killed with ``kill -9`` (a script, not a test).

Per rate (1 kHz and 10 kHz) and repeat: the simulator node (cycle mode, per-sample
/tank/pressure, plus PressureBlock messages with ``--block``) streams into the recorder
node (default ``flush_interval`` 0.5 s); after ``--seconds`` of streaming the recorder gets
SIGKILL, then ``pneumatic-unload recover BAG`` repairs the bag. Reported: the seconds of
data lost (the instant of the kill minus the last header stamp recovered; the simulator's
stamps are the wall-clock instants at which it publishes, so the last stamp published
before the kill is the kill instant to within its pacing, < 1 ms), the samples recovered
and whether they are contiguous (gaps in the stamps, samples missing between the first and
the last recovered one: lost in delivery to the recorder, not by the crash). Target: at
most 1 s lost.

Run: ``.venv/bin/python bench/bench_crash.py [--repeats 3] [--seconds 4]`` (about 20 s per
run). Prints a markdown table.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneumatic_unload.app.launch import NodeProcess, free_domain_id

RIG = {"volume": 2e-4, "conductance": 8e-9, "noise_std": 1000.0, "quantization": 10.0,
       "seed": 1}
CYCLE = {"mode": "cycle", "settle_time": 0.6, "vent_time": 0.3, "charge_time": 0.3,
         "duration": 1.2}


def crash_once(rate: float, seconds: float, block: int, tmp: Path, k: int
               ) -> dict[str, object]:
    """One recorder kill at ``rate`` [Hz] after ``seconds`` [s] of streaming."""
    bag = tmp / f"crash-{rate:g}-{block}-{k}"
    rec = NodeProcess("recorder", {"output": str(bag)}, tmp)
    sim = NodeProcess("simulator", {**RIG, **CYCLE, "rate": rate, "wait_for_subscribers": 1,
                                    "temperature_rate": 0.0, "block_size": block,
                                    "per_sample": True}, tmp)
    try:
        sim.wait_output("streaming at", 60.0)
        time.sleep(seconds)
        alive = rec.proc.poll() is None
        t_kill_ns = time.time_ns()
        rec.proc.send_signal(signal.SIGKILL)
        rec.proc.wait()
    finally:
        sim.stop()
        rec.stop()
    if not alive:
        return {"rate [Hz]": f"{rate:g}", "run": k, "lost [s]": "recorder died before the kill"}
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "recover", str(bag)],
                         capture_output=True, text=True, timeout=300)
    t_recover = time.perf_counter() - t0
    if out.returncode != 0:
        return {"rate [Hz]": f"{rate:g}", "run": k,
                "lost [s]": f"recover failed: {out.stderr.strip()[-200:]}"}
    from pneumatic_unload.io.bag import read_pressure

    t_ns, _p = read_pressure(bag)
    steps = np.diff(t_ns)
    period_ns = 1e9 / rate
    gaps = int(np.count_nonzero(steps > 1.5 * period_ns))
    missing = int(round((int(t_ns[-1]) - int(t_ns[0])) / period_ns)) + 1 - t_ns.size
    lost = (t_kill_ns - int(t_ns[-1])) / 1e9
    return {"rate [Hz]": f"{rate:g}", "run": k, "samples recovered": t_ns.size,
            "gaps in stamps": gaps, "samples missing in the span": missing,
            "recover [s]": f"{t_recover:.2f}",
            "lost [s]": f"{lost:.3f}", "_lost": lost}


def _table(rows: list[dict[str, object]]) -> str:
    keys = [k for k in rows[0] if not k.startswith("_")]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r.get(k, "")) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def main() -> int:
    """Run the kills and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="kills per rate")
    ap.add_argument("--seconds", type=float, default=4.0,
                    help="streaming time before the kill [s]")
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 10000.0],
                    help="sample rates [Hz]")
    ap.add_argument("--block", type=int, default=0,
                    help="also publish PressureBlock messages of this many samples")
    args = ap.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", str(free_domain_id()))
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory(prefix="bench_crash_") as d:
        for rate in args.rates:
            for k in range(args.repeats):
                rows.append(crash_once(rate, args.seconds, args.block, Path(d), k))
                print(rows[-1], flush=True)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"\n## Recorder killed with kill -9, then `pneumatic-unload recover` "
          f"(flush_interval 0.5 s; load average {load})\n")
    print(_table(rows))
    for rate in args.rates:
        lost = [r["_lost"] for r in rows if r["rate [Hz]"] == f"{rate:g}" and "_lost" in r]
        if lost:
            print(f"\n{rate:g} Hz: lost {min(lost):.3f} .. {max(lost):.3f} s (median "
                  f"{float(np.median(lost)):.3f} s, {len(lost)} runs); target <= 1 s: "
                  f"{'met' if max(lost) <= 1.0 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
