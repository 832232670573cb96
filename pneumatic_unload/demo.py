"""``make demo``: a simulated rig, one unload, C and tau_exp printed, a bag written.

The embedded default: a 5 L tank (L/D = 2) at 7 bar absolute discharging through a 1.5 mm
orifice (C = 0.288 dm^3/(s bar), b = 0.4) with natural-convection wall heat transfer and a
0-10 bar transducer with 0.1 % full-scale noise, sampled at 1 kHz. The run is written as a
rosbag2/MCAP bag under ``runs/`` and read back with rosbags to check it.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from pneumatic_unload.cli import format_result
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import UnloadResult

#: The embedded default rig of the demo.
DEMO_RIG = RigConfig(volume=5e-3, length_diameter_ratio=2.0, initial_pressure=7e5,
                     effects=("heat_transfer",), noise_std=1000.0, quantization=10.0,
                     full_scale=1.1e6, seed=7)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the demo; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=None, help="bag directory (default runs/demo-<time>)")
    args = ap.parse_args(argv)
    from pneumatic_unload.io.bag import bag_summary
    from pneumatic_unload.runs import write_simulated_bag

    out = Path(args.out or f"runs/demo-{time.strftime('%Y%m%d-%H%M%S')}")
    cfg = DEMO_RIG
    print(f"simulated rig: V = {cfg.volume * 1e3:g} L, p10 = {cfg.initial_pressure / 1e5:g} "
          f"bar abs, true C = {cfg.conductance / 1e-8:.4f} dm^3/(s bar), b = "
          f"{cfg.critical_ratio}, effects: {', '.join(cfg.effects) or 'none'}")
    t0 = time.perf_counter()
    info = write_simulated_bag(cfg, out)
    elapsed = time.perf_counter() - t0
    results = [UnloadResult(**{k: (float("nan") if v is None else v) for k, v in r.items()})
               for r in info["results"]]
    for r in results:
        print(format_result(r) + ("   (final: curve fit)" if r.final else
                                   "   (published at the p* crossing)"))
    summary = bag_summary(out)
    print(f"bag written: {out} ({info['samples']} samples, {info['duration']:.2f} s simulated "
          f"in {elapsed:.2f} s); read back by rosbags: {summary}")
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
