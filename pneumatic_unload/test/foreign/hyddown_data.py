# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""HydDown discharges (``test/data/hyddown/*.npz``, made by ``bench/hyddown_traces.py`` in a
venv with HydDown) turned into records as a transducer would give them. Imports nothing from
the package. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "hyddown"
RATE = 1000.0  # sampling rate [Hz]
PLATEAU = 0.2  # pre-opening plateau at p10 [s]
NOISE = 1000.0  # white noise sigma: 0.1 % of a 1 MPa full scale [Pa]


@dataclass(frozen=True)
class Trace:
    """One HydDown discharge: its name, HydDown's grid t [s], p [Pa abs] and meta (JSON)."""

    name: str
    t: np.ndarray
    p: np.ndarray
    meta: dict[str, Any]


def load(path: Path) -> Trace:
    """Read one ``.npz`` written by ``bench/hyddown_traces.py``."""
    with np.load(path) as d:
        return Trace(path.stem, d["t"].astype(float), d["p"].astype(float),
                     json.loads(str(d["meta"])))


def traces(folder: Path = DATA_DIR) -> list[Trace]:
    """Every trace of a folder, by name."""
    return [load(f) for f in sorted(Path(folder).glob("*.npz"))]


def record(trace: Trace, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The sampled record: p linearly interpolated on a 1 kHz grid over HydDown's span, a
    0.2 s plateau at p10 before it (the valve opens at t = 0.2 s), white noise of sigma
    1000 Pa (``seed``). Returns (t [s], y [Pa abs])."""
    n = int(np.floor(trace.t[-1] * RATE)) + 1
    tu = np.arange(n) / RATE
    pu = np.interp(tu, trace.t, trace.p)
    n0 = int(round(PLATEAU * RATE))
    t = np.concatenate([np.arange(n0) / RATE, PLATEAU + tu])
    p = np.concatenate([np.full(n0, trace.p[0]), pu])
    return t, p + np.random.default_rng(seed).normal(0.0, NOISE, t.size)
