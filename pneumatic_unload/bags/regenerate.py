# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Regenerate the committed reference bags of ``bags/`` and their README (``make bags``).

Each bag is a simulated run written by the package itself (``pneumatic_unload.analysis.runs``, the
same path as ``pneumatic-unload simulate``): rosbag2 directory, MCAP storage, the rig
configuration and the estimator settings stored in it, and the streaming estimator's
results on ``/estimator/estimate`` as the live node publishes them. Seeds are fixed, so a
regeneration reproduces the same samples and estimates.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.io.bag import bag_summary
from pneumatic_unload.physics import orifice_conductance

HERE = Path(__file__).resolve().parent
SENSOR = {"noise_std": 1000.0, "quantization": 10.0, "full_scale": 1.1e6}

#: name -> (description, RigConfig, unloads)
BAGS: dict[str, tuple[str, RigConfig, int]] = {
    "clean_unload": (
        "one adiabatic unload (no real-rig effect): 1 L tank, 2.5 mm orifice, 7 bar abs",
        RigConfig(volume=1e-3, conductance=orifice_conductance(2.5e-3), critical_ratio=0.4,
                  initial_pressure=7e5, pre_time=0.5, duration=4.0, seed=11, **SENSOR), 1),
    "heat_transfer": (
        "one unload with natural-convection wall heat transfer: 2 L tank, 2 mm orifice, "
        "6 bar abs (eq 39 is biased here; the model-based C is not)",
        RigConfig(volume=2e-3, conductance=orifice_conductance(2e-3), critical_ratio=0.35,
                  initial_pressure=6e5, effects=("heat_transfer",), pre_time=0.5,
                  duration=7.0, seed=12, **SENSOR), 1),
    "two_unloads": (
        "two unloads in one run (cycle mode: unload, vent, recharge, settle, unload) with "
        "heat transfer: 1 L tank, 2.5 mm orifice, 7 bar abs",
        RigConfig(volume=1e-3, conductance=orifice_conductance(2.5e-3), critical_ratio=0.4,
                  initial_pressure=7e5, effects=("heat_transfer",), pre_time=0.5,
                  duration=4.0, seed=13, **SENSOR), 2),
}


def _dm3(x: float | None) -> str:
    return "n/a" if x is None else f"{x / 1e-8:.4f}"


def main(argv: list[str] | None = None) -> int:
    """Write every bag (replacing the old one) and README.md into bags/ or ``--out DIR``."""
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=HERE, help="folder of the bags (default bags/)")
    dest = ap.parse_args(argv).out
    dest.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, (desc, cfg, unloads) in BAGS.items():
        out = dest / name
        if out.exists():
            shutil.rmtree(out)
        info = write_simulated_bag(cfg, out, unloads=unloads)
        size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
        print(f"{name}: {info['samples']} samples, {size / 1e3:.0f} kB")
        print(bag_summary(out))
        finals = [r for r in info["results"] if r["final"]] or info["results"]
        est = "; ".join(
            f"#{r['index']}: C(eq 39) {_dm3(r['conductance'])}, model "
            f"{_dm3(r['conductance_model'])} ± {_dm3(r['conductance_model_std'])}, b "
            f"{'n/a' if r['critical_ratio'] is None else format(r['critical_ratio'], '.3f')}"
            for r in finals)
        rows.append(f"| `{name}/` | {desc} | {unloads} | {info['samples']} | "
                    f"{_dm3(cfg.conductance)}, b {cfg.critical_ratio} | {est} | "
                    f"{size / 1e3:.0f} kB |")
    text = (HERE / "README.in.md").read_text().replace("@TABLE@", "\n".join(rows))
    (dest / "README.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
