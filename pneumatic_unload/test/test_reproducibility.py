# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Numerical reproducibility of the final curve fit: last-bit changes of the input move C and
b by no more than the fit says (JSON 'reproducibility'), and C by at most 1e-10.

Another CPU runs another OpenBLAS kernel and numpy another summation order: the inputs of
the fit's arithmetic differ in their last bits. Perturbing the samples by 1e-14 relative
stands in for that here (bench/bench_reproducibility.py also runs the analysis under other
OpenBLAS kernels in subprocesses).
"""

from __future__ import annotations

import numpy as np
import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation.batch import analyze
from pneumatic_unload.model.simulate import simulate
from pneumatic_unload.physics import orifice_conductance

#: The issue's target for C [-, relative].
C_TARGET = 1e-10


def _configs(n: int, seed: int) -> list[RigConfig]:
    """Random discharges: 0.5-5 L, 1.5-3 mm orifices, b 0.25-0.5, 4-8 bar, noise 200-3000
    Pa; every second one with natural-convection heat transfer."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        out.append(RigConfig(
            volume=float(rng.uniform(0.5e-3, 5e-3)),
            conductance=orifice_conductance(float(rng.uniform(1.5e-3, 3e-3))),
            critical_ratio=float(rng.uniform(0.25, 0.5)),
            initial_pressure=float(rng.uniform(4e5, 8e5)),
            effects=("heat_transfer",) if i % 2 else (), pre_time=0.5, duration=8.0,
            seed=100 + i, noise_std=float(rng.choice([200.0, 1000.0, 3000.0])),
            quantization=10.0, full_scale=1.1e6))
    return out


@pytest.mark.parametrize("cfg", _configs(6, seed=21), ids=lambda c: f"V{c.volume * 1e3:.2f}L"
                         + ("-heat" if c.effects else ""))
def test_last_bits_move_c_and_b_within_the_stated_reproducibility(cfg: RigConfig) -> None:
    """Two 1e-14 perturbations of the samples: C within 1e-10 and within the stated
    reproducibility, b within its stated reproducibility; the statement is finite."""
    sim = simulate(cfg)
    s = settings_for(cfg)
    (base,) = [r for r in analyze(sim.t, sim.measured, s) if r.final]
    cf = base.extra["curve_fit"]
    rep_c, rep_b = cf["conductance_reproducibility"], cf["critical_ratio_reproducibility"]
    assert 0.0 < rep_c < 1e-2 and 0.0 <= rep_b < 1e-1, (rep_c, rep_b)
    rng = np.random.default_rng(7)
    for _ in range(2):
        p = sim.measured * (1.0 + 1e-14 * rng.standard_normal(sim.measured.size))
        (other,) = [r for r in analyze(sim.t, p, s) if r.final]
        d_c = abs(other.conductance_model - base.conductance_model) / base.conductance_model
        assert d_c <= C_TARGET and d_c <= max(rep_c, 1e-13), (d_c, rep_c)
        if np.isfinite(base.critical_ratio):
            d_b = abs(other.critical_ratio - base.critical_ratio) / base.critical_ratio
            assert d_b <= max(rep_b, 1e-13), (d_b, rep_b)
