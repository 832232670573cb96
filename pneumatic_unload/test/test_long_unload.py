# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One unload longer than the buffer may hold: its old samples reduced to bins on the fly.

The thresholds of :mod:`pneumatic_unload.estimation.reduction` are lowered so that a
discharge of ~0.2 M samples is reduced several times; the results must equal those of the
unreduced estimator (the crossing bit for bit, the final fit's C and sigma within a tiny
fraction), the per-sample, block and batch paths must agree bit for bit, and the buffer
must stay bounded.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimatorSettings,
    StreamingEstimator,
    analyze,
    decisions,
    reduction,
    state,
)
from pneumatic_unload.fit.likelihood import BinnedLikelihood, bin_stats, make_bins
from pneumatic_unload.fit.noise import NoiseModel
from pneumatic_unload.fit.reduced import Reducer
from pneumatic_unload.model import simulate
from pneumatic_unload.model.rig import default_duration

#: Lowered thresholds [-]: above every decision's look-back (the test below checks it).
REDUCE_FROM, KEEP_RAW = 1 << 16, 50_000


@pytest.fixture(scope="module")
def slow_unload():
    """A 30 s discharge at 5 kHz (the rig's conductance scaled down), ~0.16 M samples."""
    cfg = RigConfig(rate=5000.0, pre_time=1.0, seed=4, noise_std=300.0)
    cfg = dataclasses.replace(cfg, conductance=cfg.conductance * default_duration(cfg) / 30.0)
    sim = simulate(cfg)
    settings = EstimatorSettings(volume=cfg.volume, atmosphere=cfg.atmosphere)
    return sim.t + 1.7e9, sim.measured, settings, cfg


def _lowered(monkeypatch):
    monkeypatch.setattr(reduction, "REDUCE_FROM", REDUCE_FROM)
    monkeypatch.setattr(reduction, "KEEP_RAW", KEEP_RAW)


def test_keep_raw_covers_every_look_back():
    # the abort's corner fit (6 stall windows), the final-plateau and settling tests (two
    # windows), the skip's trim: production and the lowered test value alike
    need = max(6 * 8192, 2 * 16384 + 1, 2 * decisions.SETTLE_MAX + 4 * decisions.PLATEAU)
    assert reduction.KEEP_RAW > need and KEEP_RAW > need
    assert reduction.REDUCE_FROM > reduction.KEEP_RAW


def test_reduced_unload_gives_the_unreduced_result(slow_unload, monkeypatch):
    t, p, settings, cfg = slow_unload
    full = analyze(t, p, settings)
    _lowered(monkeypatch)
    est = StreamingEstimator(settings)
    red, held = [], 0
    for k in range(0, t.size, 5000):
        red += est.push_block(t[k:k + 5000], p[k:k + 5000])
        held = max(held, len(est.buffer))
    red += est.finish()
    # the unload (all but the first second of the record) was never held whole
    assert held <= REDUCE_FROM + 2 * 5000 < 0.5 * t.size
    assert [r.status for r in red] == [r.status for r in full] == ["ok", "ok"]
    cross, final = red
    assert cross.to_dict() == full[0].to_dict()  # the crossing: bit for bit
    f0 = full[1]
    assert final.final and "curve-fit" in final.method
    # the final fit on merged micro-bins: C within 1e-3 of its sigma, sigma within 1 %
    sd = f0.conductance_model_std
    assert abs(final.conductance_model - f0.conductance_model) < 1e-3 * sd
    assert final.conductance_model_std == pytest.approx(sd, rel=0.01, abs=0.0)
    assert final.conductance_model == pytest.approx(cfg.conductance, rel=0.01, abs=0.0)
    assert final.critical_ratio == pytest.approx(f0.critical_ratio, abs=1e-3)


def test_reduction_keeps_the_paths_bit_identical(slow_unload, monkeypatch):
    t, p, settings, _cfg = slow_unload
    _lowered(monkeypatch)
    batch = analyze(t, p, settings)
    est = StreamingEstimator(settings)
    per_sample = []
    for ti, pi in zip(t.tolist(), p.tolist(), strict=True):
        per_sample += est.push(ti, pi)
    per_sample += est.finish()
    est = StreamingEstimator(settings)
    blocks = []
    for k in range(0, t.size, 3331):  # cut anywhere
        blocks += est.push_block(t[k:k + 3331], p[k:k + 3331])
    blocks += est.finish()
    assert len(batch) == len(per_sample) == len(blocks) == 2
    for x, y, z in zip(batch, per_sample, blocks, strict=True):
        assert x.to_dict() == y.to_dict() == z.to_dict()


def test_merged_bins_are_make_bins_bins():
    """Micro-bins merged at the end: samples and sums conserved, the bins near the opening
    exactly make_bins's, the likelihood of a model within 1e-6 of the samples' one."""
    rng = np.random.default_rng(0)
    n = 300_000
    t = np.arange(n) * 1e-4 + rng.normal(0.0, 1e-7, n)
    t_open = float(t[2048]) + 0.5e-4
    y = np.where(t < t_open, 6e5, 1e5 + 5e5 * np.exp(-(t - t_open) / 5.0))
    y = y + rng.normal(0.0, 100.0, n)
    edges = make_bins(t, t_open, resolution=0.01)
    unit = NoiseModel(sigma=1.0, rho=0.0, n=n, source="unit")
    exact = BinnedLikelihood(t, y, unit, edges)
    # the same bins given as statistics: the very same residuals
    same = BinnedLikelihood.from_stats(bin_stats(t, y, edges), unit)
    model = lambda tt: np.where(tt < t_open, 6e5, 1e5 + 5e5 * np.exp(-(tt - t_open) / 5.1))  # noqa: E731
    assert np.array_equal(exact.residuals_at(model), same.residuals_at(model))
    red = Reducer(t_ref=0.0, t_open=t_open, k_open=int(np.searchsorted(t, t_open)),
                  dt=float(np.median(np.diff(t[:100_001]))), resolution=0.01)
    k = 0
    for cut in (3000, 50_000, 123_456):
        k += red.add(t[k:cut], y[k:cut])
    red.add(t[k:], y[k:], final=True)
    bins = red.bins()
    assert bins.n == n and bins.y_sum.sum() == pytest.approx(y.sum(), rel=1e-12)
    assert abs(bins.count.size - (edges.size - 1)) < 0.02 * edges.size
    merged = np.concatenate(([0], np.cumsum(bins.count)))
    near = edges[edges <= 2800]  # the pre-step (2049 samples) and 750 after the opening
    assert np.array_equal(merged[:near.size], near)
    chi2 = np.sum(exact.residuals_at(model) ** 2)
    chi2_red = np.sum(BinnedLikelihood.from_stats(bins, unit).residuals_at(model) ** 2)
    assert chi2_red == pytest.approx(chi2, rel=1e-6)


def test_crossing_half_width_closed_form():
    cap_samples = state.CROSSING_WINDOW_MAX
    # an ordinary discharge: 5 % of the drop, the cap far away
    assert state.crossing_half_width(6e5, 500.0, 1e6, 1e-4) == pytest.approx(3e4)
    # six noise sigmas win over 5 % of a small drop
    assert state.crossing_half_width(1e4, 300.0, 1e6, 1e-4) == pytest.approx(1800.0)
    # an hours-long discharge: the window at the slope bound spans CROSSING_WINDOW_MAX
    slope0, dt = 50.0, 1e-4
    half = state.crossing_half_width(6e5, 20.0, slope0, dt)
    assert half < 3e4
    assert 2.0 * half / (state.SLOPE_AT_PSTAR * slope0 * dt) == pytest.approx(cap_samples)
    # ...but never below six sigmas (a sample below p* - half is no noise excursion)
    assert state.crossing_half_width(6e5, 1e3, slope0, dt) == pytest.approx(6e3)
    # unknown period or slope: no cap
    assert state.crossing_half_width(6e5, 20.0, math.nan, dt) == pytest.approx(3e4)
    assert state.crossing_half_width(6e5, 20.0, slope0, math.nan) == pytest.approx(3e4)


def test_capped_crossing_window_keeps_the_crossing(slow_unload, monkeypatch):
    # the window capped at 4096 samples (about 0.3 of its natural 13 k at this rate): the
    # crossing window spans at most that many samples at the true slope at p*, the
    # crossing agrees with the uncapped one within its sigma, the paths stay bit-identical
    t, p, settings, cfg = slow_unload
    full = analyze(t, p, settings)
    monkeypatch.setattr(state, "CROSSING_WINDOW_MAX", 4096)
    halves: list[float] = []
    width = state.crossing_half_width

    def recorded(*args: float) -> float:
        halves.append(width(*args))
        return halves[-1]

    monkeypatch.setattr(state, "crossing_half_width", recorded)
    est = StreamingEstimator(settings)
    capped = []
    for k in range(0, t.size, 5000):
        capped += est.push_block(t[k:k + 5000], p[k:k + 5000])
    capped += est.finish()
    assert [r.to_dict() for r in analyze(t, p, settings)] == [r.to_dict() for r in capped]
    c_full, c_cap = full[0], capped[0]
    assert c_full.status == c_cap.status == "ok"
    assert c_cap.t_cross != c_full.t_cross  # the window did change
    both = math.hypot(c_full.tau_exp_std, c_cap.tau_exp_std)
    assert abs(c_cap.tau_exp - c_full.tau_exp) < 3.0 * both
    sd = min(c_full.conductance_model_std, c_cap.conductance_model_std)
    assert abs(c_cap.conductance_model - c_full.conductance_model) < 0.1 * sd
    # the window's samples at the true slope at p*: the pressure falls 2 half through it
    sim = simulate(cfg)
    k = int(np.searchsorted(-sim.pressure, -c_cap.p_star))
    slope = abs(float(np.gradient(sim.pressure, sim.t)[k]))
    half = halves[-1]
    assert half < 0.05 * (c_cap.p10 - c_cap.p_atm)  # the cap binds
    assert 2.0 * half / (slope / cfg.rate) <= 4096
