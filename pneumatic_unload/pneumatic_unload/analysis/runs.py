# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Simulated runs written as bags: what ``pneumatic-unload simulate`` and the demo do.

The simulator's samples go to ``/tank/pressure`` (header stamp = sample instant), the gas
temperature to ``/tank/temperature`` at 10 Hz, the valve state to ``/tank/valve`` and, unless
switched off, the streaming estimator's results to ``/estimator/estimate`` at the instant
the live estimator would have published them. The rig configuration is stored in the bag.
SI units; bag stamps in integer nanoseconds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pneumatic_unload.config import RigConfig, adapters
from pneumatic_unload.estimation import (
    EstimatorSettings,
    UnloadResult,
    estimate_fields,
    stream_estimator,
)
from pneumatic_unload.model import simulate

#: Rate of the temperature topic [Hz].
TEMPERATURE_RATE = 10.0


def settings_for(cfg: RigConfig) -> EstimatorSettings:
    """Estimator settings matching a rig configuration: its tank and gas (what an operator
    would enter), the estimator's defaults otherwise."""
    return EstimatorSettings(**cfg.tank_fields())


def write_simulated_bag(cfg: RigConfig, out: Path, *, analyze_live: bool = True,
                        t_offset: float = 1_700_000_000.0, unloads: int = 1,
                        settle_time: float = 2.0) -> dict[str, Any]:
    """Simulate ``cfg`` and write the run as a rosbag2/MCAP bag directory ``out``.

    Parameters
    ----------
    cfg : RigConfig
        Rig, effects and sensor.
    out : Path
        Bag directory to create (must not exist).
    analyze_live : bool
        Also run the streaming estimator and record its results.
    t_offset : float
        Wall-clock time of the first sample [s since the epoch].
    unloads : int
        Number of unloads in the run [-]; more than one runs the simulator node's cycle
        (:func:`pneumatic_unload.model.rig.run_cycles`: unload, vent 1 s, recharge 1 s, settle).
    settle_time : float
        Plateau before each further unload [s].

    Returns
    -------
    dict
        Summary: path, samples, duration [s], results (list of dicts).
    """
    from pneumatic_unload.io.bag import ZERO_CELSIUS, BagRecorder

    if out.exists():
        raise FileExistsError(f"{out} exists already; choose a new --out")
    if unloads == 1:
        sim = simulate(cfg)
        t, measured, temperature, opening = sim.t, sim.measured, sim.temperature, sim.opening
    else:
        from pneumatic_unload.model.rig import run_cycles

        run = run_cycles(cfg, unloads, settle_time=settle_time)
        t, measured, temperature, opening = run.t, run.measured, run.temperature, run.opening
    t_abs = t + t_offset
    t_ns = np.round(t_abs * 1e9).astype(np.int64)
    results: list[UnloadResult] = []
    settings = settings_for(cfg)
    step = max(1, int(round(cfg.rate / TEMPERATURE_RATE)))
    if analyze_live:
        est = stream_estimator(settings)
        # the stamps and temperatures as a subscriber or the bag reader sees them: integer
        # ns -> s, K -> degrees C -> K
        t_seen = t_ns * 1e-9
        est.push_temperature(t_seen[::step], (temperature[::step] - ZERO_CELSIUS)
                             + ZERO_CELSIUS)
        results = est.push_block(t_seen, measured) + est.finish()
    out.parent.mkdir(parents=True, exist_ok=True)
    with BagRecorder(out, config=cfg.to_dict()) as rec:
        rec.write_pressures(t_ns, measured)
        rec.write_temperatures(t_ns[::step], temperature[::step])
        rec.write_valve(int(t_ns[0]), False, 0.0)
        is_open = opening > 0
        for k in np.flatnonzero(is_open[1:] != is_open[:-1]) + 1:
            rec.write_valve(int(t_ns[k]), bool(is_open[k]), float(opening[k]))
        if analyze_live:
            from pneumatic_unload.io.bag import MSGTYPE_CONFIG, TOPIC_SETTINGS, make_typestore

            store = make_typestore()
            text = store.types[MSGTYPE_CONFIG](data=adapters.to_json(settings))
            rec.write_raw(TOPIC_SETTINGS, MSGTYPE_CONFIG, int(t_ns[0]),
                          store.serialize_cdr(text, MSGTYPE_CONFIG))
        for r in results:
            rec.write_estimate(int(round(r.t_complete * 1e9)), estimate_fields(r))
    return {"path": str(out), "samples": int(t.size), "duration": float(t[-1] - t[0]),
            "results": [r.to_dict() for r in results]}
