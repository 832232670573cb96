"""Soak benchmark: simulator -> estimator -> recorder at 10 kHz for minutes (a script).

The simulator node runs in cycle mode (an unload every 2.4 s: 0.6 s plateau, 1.2 s
unload, 0.3 s vented, 0.3 s charge) at ``--rate`` (default 10 kHz), the estimator and the
recorder nodes subscribe, each node in its own process. Reported, per input path
(per-sample FluidPressure, or PressureBlock of ``--block-size`` samples):

* samples published (simulator), recorded in the bag (read back after the run) and
  analysed by the estimator (its ``stats`` line at shutdown); target: none lost;
* RSS of each node (``VmRSS`` of /proc/PID/status every ``--every`` seconds): at the end of
  the first minute, at the end, the highest, and the growth after the first minute
  (highest later value over the value at one minute; target: at most 5 %), and the median
  trend (median of the last half minute over that of the second half of the first one);
* the estimator's latencies (arrival of the sample completing an estimate to its
  publication), p50/p99/max for the first and last third of the estimates; target: steady;
* the unloads estimated and their model C (the rig's C is 8e-9 m^3/(s Pa)).

Run: ``.venv/bin/python bench/bench_soak.py [--minutes 10] [--input block|sample|both]``;
``--quick``: 1 minute (the RSS baseline is then taken at 20 s). Prints markdown tables.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
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
NODES = ("simulator", "estimator", "recorder")


def rss_bytes(pid: int) -> int:
    """Resident set size of a process [B] (0 when it has ended)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    m = re.search(r"^VmRSS:\s+(\d+)\s+kB", text, re.M)
    return int(m.group(1)) * 1024 if m else 0


def bag_samples(bag: Path, block: bool) -> tuple[int, int]:
    """(samples, gaps) of the pressure in a bag: per-sample /tank/pressure, or the samples
    of the /tank/pressure_block messages; gaps: stamp steps over 1.5 periods [-]."""
    if not block:
        from pneumatic_unload.io.bag import read_pressure

        t_ns = read_pressure(bag)[0]
        steps = np.diff(t_ns)
        return t_ns.size, int(np.count_nonzero(steps > 1.5 * np.median(steps)))
    from pneumatic_unload.io.bag import make_typestore, read_raw_messages

    store = make_typestore()
    n, starts, period = 0, [], 0.0
    for m in read_raw_messages(bag, topics=["/tank/pressure_block"]):
        msg = store.deserialize_cdr(m.data, m.msgtype)
        k = len(msg.pressure)
        starts.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, k))
        period = msg.sample_period
        n += k
    starts.sort()
    gaps = sum(1 for (a, ka), (b, _) in itertools.pairwise(starts)
               if b - a > (ka + 0.5) * period * 1e9)
    return n, gaps


def soak(minutes: float, rate: float, block: int, tmp: Path, every: float, baseline: float
         ) -> dict[str, object]:
    """One soak run; returns the figures (see the module docstring)."""
    bag = tmp / f"soak-{block}"
    est = NodeProcess("estimator", {"volume": RIG["volume"], "diagnostics_period": 1.0,
                                    "input": "block" if block else "sample",
                                    "qos": "reliable" if block else "sensor_data",
                                    "curve_fit": True}, tmp)
    rec = NodeProcess("recorder", {"output": str(bag)}, tmp)
    sim = NodeProcess("simulator", {**RIG, **CYCLE, "rate": rate, "wait_for_subscribers": 2,
                                    "temperature_rate": 0.0, "block_size": block,
                                    "per_sample": not block}, tmp)
    procs = {"simulator": sim, "estimator": est, "recorder": rec}
    series: list[tuple[float, dict[str, int]]] = []
    loads: list[float] = []
    try:
        sim.wait_output("streaming at", 60.0)
        t0 = time.monotonic()
        end = t0 + 60.0 * minutes
        while time.monotonic() < end:
            if any(p.proc.poll() is not None for p in procs.values()):
                break
            series.append((time.monotonic() - t0,
                           {n: rss_bytes(p.proc.pid) for n, p in procs.items()}))
            loads.append(os.getloadavg()[0])
            time.sleep(min(every, max(0.0, end - time.monotonic())))
        series.append((time.monotonic() - t0,
                       {n: rss_bytes(p.proc.pid) for n, p in procs.items()}))
        died = [n for n, p in procs.items() if p.proc.poll() is not None]
    finally:
        sim.stop()
        time.sleep(2.0)  # the estimator drains its queue, the recorder writes the rest
        est.stop()
        rec.stop()
    published = int(re.search(r"published (\d+) pressure samples", sim.output()).group(1))
    text = est.output()
    m = re.findall(r"stats (\{.*\})", text)
    stats = json.loads(m[-1]) if m else {}
    analysed = int(stats.get("received", 0))
    recorded, gaps = bag_samples(bag, bool(block))
    lat = np.asarray(stats.get("latencies_ms", []), dtype=float)
    fin = np.asarray(stats.get("final_latencies_ms", []), dtype=float)
    c_model = [float(x) for x in re.findall(
        r"\] \[estimator\]: unload \d+: C=\S+ m\^3/\(s Pa\) \(eq 39\), model (\S+),"
        r".*\(final\)", text)]
    errors = re.findall(r"\] \[estimator\]: unload \d+: (?!C=)(\w+)", text)
    return {"input": f"PressureBlock x{block}" if block else "FluidPressure",
            "minutes": (series[-1][0] if series else 0.0) / 60.0, "died": died,
            "published": published, "recorded": recorded, "bag gaps": gaps,
            "analysed": analysed, "series": series, "baseline": baseline,
            "lat": lat, "fin": fin, "c_model": c_model, "errors": errors,
            "load": (min(loads), float(np.mean(loads)), max(loads)) if loads else None}


def _mib(x: float) -> str:
    return f"{x / 2**20:.1f}"


def _pct(x: np.ndarray) -> str:
    if not x.size:
        return "-"
    return f"{np.percentile(x, 50):.2f} / {np.percentile(x, 99):.2f} / {x.max():.2f}"


def _table(rows: list[dict[str, object]]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def report(r: dict[str, object]) -> None:
    """Print the tables of one run."""
    what = r["input"]
    pub, rec, ana = r["published"], r["recorded"], r["analysed"]
    print(f"\n## {what}: {r['minutes']:.1f} min at 10 kHz"
          + (f" (node(s) died: {', '.join(r['died'])})" if r["died"] else ""))
    if r["load"]:
        print(f"\nLoad average (1 min) during the run: min {r['load'][0]:.2f}, mean "
              f"{r['load'][1]:.2f}, max {r['load'][2]:.2f} ({os.cpu_count()} cores).")
    print("\n### Samples\n")
    print(_table([{"published": f"{pub:,}", "recorded in the bag": f"{rec:,}",
                   "lost by the recorder": f"{pub - rec:,}", "gaps in the bag": r["bag gaps"],
                   "analysed by the estimator": f"{ana:,}",
                   "lost by the estimator": f"{pub - ana:,}",
                   "target": "0 lost",
                   "": "met" if pub == rec == ana and not r["bag gaps"] else "NOT met"}]))
    series = r["series"]
    base_t = r["baseline"]
    print(f"\n### RSS [MiB] (growth: highest value after {base_t:g} s over the value at "
          f"{base_t:g} s; target <= 5 %)\n")
    rows = []
    for name in NODES:
        vals = np.array([s[name] for _, s in series], dtype=float)
        times = np.array([t for t, _ in series])
        if not vals.size or not vals.any():
            continue
        j = int(np.searchsorted(times, base_t))
        j = min(j, vals.size - 1)
        later = vals[j:]
        growth = (later.max() - vals[j]) / vals[j] * 100.0
        # medians of the baseline's window and of the last one (the same length): the
        # trend without the sawtooth of a buffer filled and trimmed every unload
        first = vals[(times >= base_t / 2) & (times <= base_t)]
        last = vals[times >= times[-1] - base_t / 2]
        trend = (np.median(last) - np.median(first)) / np.median(first) * 100.0 \
            if first.size and last.size else float("nan")
        rows.append({"node": name, "start": _mib(vals[0]), f"at {base_t:g} s": _mib(vals[j]),
                     "end": _mib(vals[-1]), "max": _mib(vals.max()),
                     "growth after baseline [%]": f"{growth:.1f}",
                     "end vs baseline [%]": f"{(vals[-1] - vals[j]) / vals[j] * 100.0:+.1f}",
                     "median trend [%]": f"{trend:+.1f}",
                     "": "met" if growth <= 5.0 else "NOT met"})
    print(_table(rows))
    step = max(1, len(series) // 10)
    print("\nRSS over time [MiB]:\n")
    print(_table([{"t [s]": f"{t:.0f}", **{n: _mib(s[n]) for n in NODES}}
                  for t, s in series[::step] + ([series[-1]] if len(series) % step != 1
                                                else [])]))
    lat, fin = r["lat"], r["fin"]
    print("\n### Estimator latencies [ms] (p50 / p99 / max), first vs last third\n")
    rows = []
    for name, x in (("crossing estimate", lat), ("final curve fit", fin)):
        k = x.size // 3
        rows.append({"latency": name, "n": x.size, "all": _pct(x),
                     "first third": _pct(x[:k]) if k else "-",
                     "last third": _pct(x[-k:]) if k else "-"})
    print(_table(rows))
    c = np.asarray(r["c_model"])
    if c.size:
        print(f"\nFinal estimates: {c.size}, model C mean {c.mean():.4g} m^3/(s Pa), "
              f"relative spread (std/mean) {c.std() / c.mean() * 100:.2f} %, range "
              f"{c.min():.4g} .. {c.max():.4g} (rig: {RIG['conductance']:.4g}).")
    if r["errors"]:
        print(f"Non-ok results: {len(r['errors'])} ({', '.join(sorted(set(r['errors'])))}).")


def main() -> int:
    """Run the soak(s) and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="run length [min]")
    ap.add_argument("--quick", action="store_true", help="1 minute")
    ap.add_argument("--input", choices=("block", "sample", "both"), default="block",
                    help="estimator input: PressureBlock, per-sample FluidPressure or both")
    ap.add_argument("--block-size", type=int, default=100, help="samples per PressureBlock")
    ap.add_argument("--rate", type=float, default=10000.0, help="sample rate [Hz]")
    ap.add_argument("--every", type=float, default=5.0, help="RSS sampling period [s]")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep the node logs and the bag in this folder (default: deleted)")
    args = ap.parse_args()
    minutes = 1.0 if args.quick else args.minutes
    baseline = 60.0 if minutes > 1.5 else 20.0
    os.environ.setdefault("ROS_DOMAIN_ID", str(free_domain_id()))
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    blocks = {"block": [args.block_size], "sample": [0],
              "both": [args.block_size, 0]}[args.input]
    print(f"# Soak: simulator -> estimator -> recorder, {minutes:g} min at {args.rate:g} Hz "
          f"(ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}, {os.cpu_count()} cores, load "
          f"average at start {os.getloadavg()[0]:.2f})")
    with tempfile.TemporaryDirectory(prefix="bench_soak_") as d:
        folder = args.keep or Path(d)
        for block in blocks:
            report(soak(minutes, args.rate, block, folder, args.every, baseline))
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
