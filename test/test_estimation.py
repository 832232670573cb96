"""Streaming estimator: recovery of known parameters, parity, relative signals, bad input."""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimationError,
    EstimatorSettings,
    StreamingEstimator,
    analyze,
    merge_final,
)
from pneumatic_unload.model import default_duration, simulate
from pneumatic_unload.physics import orifice_conductance
from pneumatic_unload.runs import settings_for

FS_NOISE = 1000.0  # 0.1 % of a 0-10 bar (1 MPa) transducer [Pa]


def _true_crossing(sim, p_atm):
    ps = p_atm + 0.368 * (sim.config.initial_pressure - p_atm)
    j = int(np.flatnonzero(sim.pressure < ps)[0])
    t1, t2, p1, p2 = sim.t[j - 1], sim.t[j], sim.pressure[j - 1], sim.pressure[j]
    return t1 + (p1 - ps) / (p1 - p2) * (t2 - t1) - sim.t_open


def _random_rigs(n, seed, heat=False):
    rng = np.random.default_rng(seed)
    for k in range(n):
        cfg = RigConfig(
            volume=rng.uniform(1e-3, 20e-3), conductance=orifice_conductance(
                rng.uniform(1e-3, 3e-3)), initial_pressure=rng.uniform(4e5, 8e5),
            critical_ratio=rng.uniform(0.2, 0.5), noise_std=FS_NOISE, seed=seed * 1000 + k,
            effects=("heat_transfer",) if heat else ())
        yield cfg


def test_adiabatic_recovery_over_the_range():
    """tau_exp near 0.1 %, start within one sample or 3x its stated uncertainty.

    Measured: median |tau error| 0.02 %, worst 0.11 % (2 sigma of the stated uncertainty, in
    the fastest of these rigs); issue 3's target is 0.1 % for every trace.
    """
    worst_tau, errs = 0.0, []
    for cfg in _random_rigs(10, seed=1):
        cfg = cfg.replace(duration=0.35 * default_duration(cfg))
        sim = simulate(cfg)
        st = dataclasses.replace(settings_for(cfg), heat_model="adiabatic", curve_fit=False)
        res = analyze(sim.t, sim.measured, st)
        assert len(res) == 1 and res[0].status == "ok"
        r = res[0]
        tau_true = _true_crossing(sim, cfg.atmosphere)
        errs.append(abs(r.tau_exp / tau_true - 1.0))
        worst_tau = max(worst_tau, errs[-1])
        assert errs[-1] < 3.0 * r.tau_exp_std / r.tau_exp + 1e-4
        dt0 = abs(r.t_start - sim.t_open)
        assert dt0 <= max(1.0 / cfg.rate, 3.0 * r.tau_exp_std), (cfg, dt0)
        # eq 39 keeps its bias; the isentropic inversion removes it
        if cfg.atmosphere / cfg.critical_ratio < r.p_star:
            assert r.conductance_model == pytest.approx(cfg.conductance, rel=5e-3)
    assert float(np.median(errs)) < 5e-4
    assert worst_tau < 1.5e-3


def test_start_within_one_sample_for_fast_discharge():
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(3e-3), noise_std=FS_NOISE,
                    initial_pressure=6e5, seed=3, duration=1.0)
    sim = simulate(cfg)
    r = analyze(sim.t, sim.measured, dataclasses.replace(settings_for(cfg),
                                                          heat_model="adiabatic"))[0]
    assert abs(r.t_start - sim.t_open) < 1.0 / cfg.rate
    assert r.tau_exp == pytest.approx(_true_crossing(sim, cfg.atmosphere), rel=1e-3)


def test_heat_transfer_model_based_c_within_2_percent_while_eq39_is_off():
    worst_model, worst_39 = 0.0, 0.0
    for cfg in _random_rigs(4, seed=2, heat=True):
        sim = simulate(cfg)
        res = merge_final(analyze(sim.t, sim.measured, settings_for(cfg)))
        r = res[0]
        assert r.final and r.status == "ok"
        worst_model = max(worst_model, abs(r.conductance_model / cfg.conductance - 1))
        worst_39 = max(worst_39, abs(r.conductance / cfg.conductance - 1))
        assert abs(r.critical_ratio - cfg.critical_ratio) < 0.03
    assert worst_model < 0.02
    assert worst_39 > 0.03  # eq 39 is really biased here: the correction matters


def _traces():
    for k, cfg in enumerate(_random_rigs(6, seed=5)):
        cfg = cfg.replace(duration=0.5 * default_duration(cfg),
                          effects=("heat_transfer",) if k % 2 else ())
        sim = simulate(cfg)
        yield cfg, sim.t + 1.7e9, sim.measured


def test_streaming_per_sample_equals_blocks_and_batch():
    rng = np.random.default_rng(0)
    for cfg, t, p in _traces():
        st = dataclasses.replace(settings_for(cfg), curve_fit=False)
        batch = analyze(t, p, st)
        est = StreamingEstimator(st)
        per = []
        for a, b in zip(t.tolist(), p.tolist(), strict=True):
            per += est.push(a, b)
        per += est.finish()
        est2 = StreamingEstimator(st)
        blk, i = [], 0
        while i < t.size:
            k = int(rng.integers(1, 5000))
            blk += est2.push_block(t[i:i + k], p[i:i + k])
            i += k
        blk += est2.finish()
        key = [(r.index, r.status, r.t_start, r.t_cross, r.conductance, r.conductance_model)
               for r in batch]
        assert key == [(r.index, r.status, r.t_start, r.t_cross, r.conductance,
                        r.conductance_model) for r in per]
        assert key == [(r.index, r.status, r.t_start, r.t_cross, r.conductance,
                        r.conductance_model) for r in blk]
        assert len(key) >= 1


def test_uncalibrated_volts_signal_gives_same_tau():
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=4, transducer_zero=0.5, transducer_sensitivity=4.0 / 1e6)
    sim = simulate(cfg.replace(duration=0.5 * default_duration(cfg)))
    st = dataclasses.replace(settings_for(cfg), curve_fit=False, heat_model="adiabatic")
    r_pa = analyze(sim.t, sim.measured, st)[0]
    st_v = dataclasses.replace(st, signal_gain=1.0 / cfg.transducer_sensitivity,
                               signal_offset=-cfg.transducer_zero / cfg.transducer_sensitivity)
    r_v = analyze(sim.t, sim.volts(), st_v)[0]
    assert r_v.tau_exp == pytest.approx(r_pa.tau_exp, rel=1e-6)
    assert r_v.conductance == pytest.approx(r_pa.conductance, rel=1e-6)


@pytest.mark.xfail(strict=True, reason="open defect: re-arming after the first unload's "
                   "tail does not yet detect a second unload appended this way (issue 3)")
def test_two_unloads_in_one_trace_rearm():
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=6, duration=4.0)
    a = simulate(cfg)
    b = simulate(cfg.replace(seed=7, initial_pressure=6e5))
    t = np.concatenate([a.t, a.t[-1] + 1e-3 + b.t])
    p = np.concatenate([a.measured, b.measured])
    res = merge_final(analyze(t, p, dataclasses.replace(settings_for(cfg),
                                                        heat_model="adiabatic")))
    assert [r.index for r in res] == [0, 1]
    assert all(r.status == "ok" for r in res)
    assert res[1].p10 == pytest.approx(6e5, rel=0.01)


# ------------------------------------------------------------------- bad input
def _simple():
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=8, duration=2.0)
    return cfg, simulate(cfg)


def test_nan_and_backward_stamps_are_diagnosed_not_fatal():
    cfg, sim = _simple()
    st = dataclasses.replace(settings_for(cfg), heat_model="adiabatic", curve_fit=False)
    clean = analyze(sim.t, sim.measured, st)
    t, p = sim.t.copy(), sim.measured.copy()
    p[50] = np.nan
    t[60] = t[59]  # duplicate
    t[70] = t[10]  # backwards
    est = StreamingEstimator(st)
    res = est.push_block(t, p) + est.finish()
    msgs = " | ".join(d.message for d in est.diagnostics)
    assert "non-finite" in msgs and "duplicate" in msgs and "backwards" in msgs
    assert res[0].tau_exp == pytest.approx(clean[0].tau_exp, rel=1e-3)


def test_no_unload_returns_nothing():
    t = np.arange(5000) * 1e-3
    p = 7e5 + np.random.default_rng(0).normal(0, 1000, t.size)
    assert analyze(t, p, EstimatorSettings(volume=1e-3)) == []


def test_p10_below_atmosphere_is_bad_data():
    cfg, sim = _simple()
    st = dataclasses.replace(settings_for(cfg), atmosphere=9e5, heat_model="adiabatic")
    res = analyze(sim.t, sim.measured, st)
    assert res and res[0].status == "bad_data" and "not above p_atm" in res[0].status_text


def test_aborted_unload_is_reported():
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=FS_NOISE,
                    seed=9, duration=6.0, valve_close_time=0.8)
    sim = simulate(cfg)
    res = analyze(sim.t, sim.measured, dataclasses.replace(settings_for(cfg),
                                                            heat_model="adiabatic"))
    assert res and res[0].status.startswith("aborted")
    assert not math.isfinite(res[0].tau_exp)


@pytest.mark.xfail(strict=True, reason="open defect: the recovery plateau is declared "
                   "before the re-heating ends, so the SSE value is ~30 % high (issue 3)")
def test_aborted_unload_with_recovery_gives_sse():
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=200.0,
                    seed=10, duration=40.0, valve_close_time=0.8, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=0.05)
    sim = simulate(cfg)
    res = analyze(sim.t, sim.measured, settings_for(cfg))
    assert res and res[0].status == "aborted_sse", res
    assert res[0].conductance == pytest.approx(cfg.conductance, rel=0.1)


def test_saturated_plateau_is_bad_data():
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=11, duration=2.0, full_scale=6.5e5)
    sim = simulate(cfg)
    res = analyze(sim.t, sim.measured, dataclasses.replace(settings_for(cfg),
                                                            heat_model="adiabatic"))
    assert res and res[0].status == "bad_data" and "saturated" in res[0].status_text


def test_too_few_samples_and_mismatched_arrays():
    with pytest.raises(EstimationError, match="too few"):
        analyze(np.arange(5.0), np.ones(5))
    with pytest.raises(EstimationError, match="equal length"):
        analyze(np.arange(50.0), np.ones(40))
    with pytest.raises(EstimationError, match="volume"):
        EstimatorSettings(volume=0.0)
