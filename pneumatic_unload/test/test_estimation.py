# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Streaming estimator: recovery of known parameters, parity, relative signals, bad input."""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimationError,
    EstimatorSettings,
    StreamingEstimator,
    analyze,
    merge_final,
)
from pneumatic_unload.model import default_duration, simulate
from pneumatic_unload.physics import orifice_conductance, tau_exp_eq38

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
        r = res[0]
        # eq 39 assumes choked flow down to p*: flagged when the assumed b says otherwise
        choked = r.p_star >= cfg.atmosphere / st.critical_ratio
        assert len(res) == 1 and r.status == ("ok" if choked else "ok_subsonic")
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


def test_start_found_when_a_noise_dip_on_a_short_plateau_triggers_before_the_opening():
    """Issue 14's P048_run0445: a 0.3 s plateau at 1 kHz, 800 Pa noise, heat transfer. The
    first plateau check (32 samples: level 2.5 standard errors high, noise 40 % low) takes a
    noise dip 0.2 s before the opening for the step, and the dip's mean confirms it. The
    start fit was searched only before that trigger: pinned there with no falling slope,
    the unload was 'bad_data' (tau_exp without uncertainty). The start is now also
    searched up to the sample 10 % down, and the better fit kept.

    Over draws of the noise (seeds 440-447, the issue's 445 among them): one trigger each,
    never later than the detector's latency allows (a sample trigger_sigma noise deviations
    below the plateau: the noiseless pressure 4 deviations further down, for the trigger
    level of a short plateau's noise estimate and the sample's own noise; measured 18-28 ms
    after the opening, the bound 41 ms); the issue's draw triggers before the opening (on
    the noise dip); every draw's start, tau_exp and C are found all the same."""
    vol, c = 4.629995693504536e-3, 1.1315598134141542e-08
    early = []
    for seed in range(440, 448):
        cfg = RigConfig(volume=vol, conductance=c, pre_time=0.3, noise_std=800.0, seed=seed,
                        rate=1000.0, effects=("heat_transfer",))
        cfg = cfg.replace(duration=4.0 * tau_exp_eq38(7e5, 101325.0, vol, c, 293.15, cfg.gas))
        sim = simulate(cfg)
        settings = settings_for(cfg)
        est = StreamingEstimator(settings)
        res = est.push_block(sim.t, sim.measured) + est.finish()
        (trigger,) = [d.t for d in est.diagnostics if d.message == "unload step detected"]
        down = cfg.initial_pressure - (settings.trigger_sigma + 4.0) * cfg.noise_std
        latest = float(sim.t[np.flatnonzero(sim.pressure < down)[0]])
        assert trigger <= latest, (seed, trigger, latest)
        if trigger < sim.t_open:
            early.append(seed)
        assert [(r.status, r.final) for r in res] == [("ok", False), ("ok", True)], seed
        final = res[1]
        for r in res:
            assert math.isfinite(r.tau_exp_std)
            assert abs(r.t_start - sim.t_open) <= 3.0 * r.tau_exp_std
            assert abs(r.tau_exp / _true_crossing(sim, cfg.atmosphere) - 1.0) < 2e-3
        assert abs(final.conductance_model - c) <= 3.0 * final.conductance_model_std
        assert final.conductance_model == pytest.approx(c, rel=2e-3, abs=0)
    assert 445 in early  # the draw still triggers on its noise dip


def test_heat_transfer_model_based_c_within_2_percent_while_eq39_is_off():
    worst_model, worst_39 = 0.0, 0.0
    for cfg in _random_rigs(4, seed=2, heat=True):
        sim = simulate(cfg)
        res = merge_final(analyze(sim.t, sim.measured, settings_for(cfg)))
        r = res[0]
        b = cfg.critical_ratio  # the final status follows the fitted b
        assert r.final and r.status == ("ok" if r.p_star >= cfg.atmosphere / b else
                                        "ok_subsonic")
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


def _parity_traces():
    """Diverse traces: random rigs, heat transfer, aborted with recovery, two unloads, a
    gap, a NaN, automatic p_atm, a volts signal."""
    for cfg, t, p in _traces():
        yield dataclasses.replace(settings_for(cfg), curve_fit=False), t, p
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=FS_NOISE,
                    seed=31, duration=20.0, valve_close_time=0.8, effects=("heat_transfer",))
    sim = simulate(cfg)
    yield dataclasses.replace(settings_for(cfg), curve_fit=False), sim.t, sim.measured
    cfg, _a, t, p, _ = _two_unloads(0.3)
    yield dataclasses.replace(settings_for(cfg), curve_fit=False), t, p
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2.5e-3), noise_std=FS_NOISE,
                    seed=32, duration=2.0)
    sim = simulate(cfg)
    keep = np.ones(sim.t.size, bool)
    keep[400:430] = False
    p = sim.measured.copy()
    p[700] = np.nan
    st = dataclasses.replace(settings_for(cfg), curve_fit=False, heat_model="adiabatic")
    yield st, sim.t[keep], p[keep]
    yield dataclasses.replace(st, atmosphere=None), sim.t, sim.measured
    yield (dataclasses.replace(st, signal_gain=2.5e5, signal_offset=0.0), sim.t,
           sim.measured / 2.5e5)


def _same(a, b):
    da, db = a.to_dict(), b.to_dict()
    return da == db


def test_parity_per_sample_blocks_batch_identical_on_many_traces():
    """The batch path (vectorised checks between decisions) gives bit-identical results to
    the per-sample path and to random block sizes, on every kind of trace."""
    rng = np.random.default_rng(1)
    n_results = 0
    for st, t, p in _parity_traces():
        batch = analyze(t, p, st)
        per_est = StreamingEstimator(st)
        per = []
        for a, b in zip(t.tolist(), p.tolist(), strict=True):
            per += per_est.push(a, b)
        per += per_est.finish()
        blk_est = StreamingEstimator(st)
        blk, i = [], 0
        while i < t.size:
            k = int(rng.integers(1, 3000))
            blk += blk_est.push_block(t[i:i + k], p[i:i + k])
            i += k
        blk += blk_est.finish()
        assert len(batch) == len(per) == len(blk) >= 1
        for x, y, z in zip(batch, per, blk, strict=True):
            assert _same(x, y) and _same(x, z), (x, y, z)
        # the running prefix sums are bit-identical too
        assert per_est.buffer.cs == blk_est.buffer.cs and per_est.buffer.cq == blk_est.buffer.cq
        assert [d.message for d in per_est.diagnostics] == \
            [d.message for d in blk_est.diagnostics]
        n_results += len(batch)
    assert n_results >= 12


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
    assert r_v.conductance == pytest.approx(r_pa.conductance, rel=1e-6, abs=0.0)


def _two_unloads(charge_time=0.0):
    """Two unloads in one stream; the second charge is a step or a ramp of charge_time [s]."""
    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=6, duration=4.0)
    a = simulate(cfg)
    b = simulate(cfg.replace(seed=7, initial_pressure=6e5))
    t = np.concatenate([a.t, a.t[-1] + 1e-3 + b.t])
    p = np.concatenate([a.measured, b.measured])
    t_open_b = a.t[-1] + 1e-3 + b.t_open
    if charge_time > 0:
        n_ramp = int(charge_time * cfg.rate)
        i0 = a.t.size
        ramp = np.linspace(a.pressure[-1], 6e5, n_ramp + 2)[1:-1]
        t = np.concatenate([a.t, a.t[-1] + 1e-3 * np.arange(1, n_ramp + 1),
                            a.t[-1] + 1e-3 * (n_ramp + 1) + b.t])
        noise = np.random.default_rng(1).normal(0.0, FS_NOISE, n_ramp)
        p = np.concatenate([a.measured, ramp + noise, b.measured])
        t_open_b = t[i0 + n_ramp] + b.t_open
    return cfg, a, t, p, t_open_b


@pytest.mark.parametrize("charge_time", [0.0, 0.5])
def test_two_unloads_in_one_trace_rearm(charge_time):
    cfg, a, t, p, t_open_b = _two_unloads(charge_time)
    st = dataclasses.replace(settings_for(cfg), heat_model="adiabatic")
    res = merge_final(analyze(t, p, st))
    assert [r.index for r in res] == [0, 1]
    assert all(r.status == "ok" and r.final for r in res)
    assert res[0].p10 == pytest.approx(7e5, rel=0.01)
    assert res[1].p10 == pytest.approx(6e5, rel=0.01)
    assert abs(res[0].t_start - a.t_open) < 1e-3
    assert abs(res[1].t_start - t_open_b) < 1e-3
    # the first unload's curve fit stops before the second charge
    assert res[0].t_end < t_open_b - 0.2
    for r in res:
        assert r.conductance_model == pytest.approx(cfg.conductance, rel=0.01)
    # per-sample and block paths take the same decisions
    est = StreamingEstimator(dataclasses.replace(st, curve_fit=False))
    per = []
    for a_, b_ in zip(t.tolist(), p.tolist(), strict=True):
        per += est.push(a_, b_)
    per += est.finish()
    blk = analyze(t, p, dataclasses.replace(st, curve_fit=False))
    assert [(r.index, r.t_start, r.t_cross, r.i_complete) for r in per] == \
        [(r.index, r.t_start, r.t_cross, r.i_complete) for r in blk]
    assert len(per) == 2


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
    with pytest.raises(EstimationError, match="atmosphere"):  # no atmosphere is 9 bar
        dataclasses.replace(settings_for(cfg), atmosphere=9e5)
    st = dataclasses.replace(settings_for(cfg), atmosphere=1.9e5, heat_model="adiabatic")
    res = analyze(sim.t, 0.25 * sim.measured, st)  # a plateau of 1.75 bar, below p_atm
    assert res and res[0].status == "bad_data" and "not above p_atm" in res[0].status_text


def test_aborted_unload_is_reported():
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=FS_NOISE,
                    seed=9, duration=6.0, valve_close_time=0.8)
    sim = simulate(cfg)
    res = analyze(sim.t, sim.measured, dataclasses.replace(settings_for(cfg),
                                                            heat_model="adiabatic"))
    assert res and res[0].status.startswith("aborted")
    assert not math.isfinite(res[0].tau_exp)


def test_aborted_unload_with_slow_recovery_extrapolates_sse():
    """Recovery time constant ~200 s, 40 s recorded (14 % of the re-heating): p1_inf is
    extrapolated by the relaxation fit; measured: SSE 6.8 % low with a stated 4.2 %."""
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=200.0,
                    seed=10, duration=40.0, valve_close_time=0.8, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=0.05)
    sim = simulate(cfg)
    res = analyze(sim.t, sim.measured, settings_for(cfg))
    assert [(r.status, r.final) for r in res] == [("aborted", False), ("aborted_sse", True)]
    (r,) = merge_final(res)
    assert r.conductance == pytest.approx(cfg.conductance, rel=0.1)
    assert abs(r.conductance - cfg.conductance) < 3.0 * r.extra["sse_std"]
    assert r.extra["t_star"] == pytest.approx(0.8, abs=2e-3)
    # the model inversion at the closing instant does not need the recovery
    assert r.conductance_model == pytest.approx(cfg.conductance, rel=0.02)


@pytest.mark.parametrize(("volume", "diameter", "close"), [(2e-3, 1.5e-3, 0.8),
                                                          (1e-3, 1e-3, 1.0)])
def test_aborted_unload_recovery_plateau_sse_within_1_5_percent(volume, diameter, close):
    """Natural convection, the re-heating recorded to its plateau: eq 23 (printed exponent,
    recovered pressure) within 1.5 % of the true C (measured 1.0 % and 0.1 %), published
    while streaming (before the end of the record), not only at finish()."""
    cfg = RigConfig(volume=volume, conductance=orifice_conductance(diameter),
                    noise_std=FS_NOISE, seed=12, duration=60.0, valve_close_time=close,
                    effects=("heat_transfer",))
    sim = simulate(cfg)
    est = StreamingEstimator(settings_for(cfg))
    res = est.push_block(sim.t, sim.measured)
    # reported at once as aborted, then the SSE value under the same index
    assert [(r.index, r.status, r.final) for r in res] == [(0, "aborted", False),
                                                          (0, "aborted_sse", True)], res
    assert "waiting for the pressure recovery" in res[0].status_text
    r = res[1]
    assert r.conductance == pytest.approx(cfg.conductance, rel=0.015)
    assert r.conductance_model == pytest.approx(cfg.conductance, rel=0.01)
    assert r.extra["recovered_fraction"] > 0.9
    assert est.state == "waiting"


def test_aborted_unload_too_slow_recovery_gives_no_sse():
    """10 L tank, recovery time constant ~20 min, 40 s recorded: p1_inf cannot be
    extrapolated, so no SSE number (status aborted), but the model value at closing."""
    cfg = RigConfig(volume=10e-3, conductance=orifice_conductance(2e-3), noise_std=FS_NOISE,
                    seed=11, duration=40.0, valve_close_time=2.0, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=0.05)
    sim = simulate(cfg)
    res = merge_final(analyze(sim.t, sim.measured, settings_for(cfg)))
    assert len(res) == 1 and res[0].status == "aborted"
    assert "too uncertain" in res[0].status_text
    assert not math.isfinite(res[0].conductance)


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


@pytest.mark.parametrize(("duration_factor", "ok"), [(1.0, True), (0.5, False)])
def test_auto_atmosphere_on_a_short_low_rate_record(duration_factor, ok):
    """2 Hz log, p_atm from the final plateau: the plateau windows of the live path are too
    long for ~300 post-start samples, so finish() takes p_atm from the end of the record
    when that is level; a record that ends before the plateau says so (no number)."""
    cfg = RigConfig(volume=20e-3, conductance=orifice_conductance(1.5e-3), noise_std=300.0,
                    seed=5, rate=2.0, pre_time=40.0)
    cfg = cfg.replace(duration=duration_factor * default_duration(cfg))
    sim = simulate(cfg)
    st = dataclasses.replace(settings_for(cfg), atmosphere=None, heat_model="adiabatic",
                             curve_fit=False, min_plateau=16)
    r = analyze(sim.t, sim.measured, st)[0]
    if ok:
        assert r.status == "ok"
        assert r.p_atm == pytest.approx(cfg.atmosphere, abs=300.0)
        assert r.conductance_model == pytest.approx(cfg.conductance, rel=0.01)
    else:
        assert r.status == "aborted" and "p_atm unknown" in r.status_text
        assert not math.isfinite(r.conductance)


def test_deferred_final_fit_gives_the_inline_result():
    """A live node publishes the crossing estimate at once and runs the final curve fit on a
    worker (``defer_final_fit``): the jobs give, field by field, the final results the
    inline path returns, and the crossing results are the same objects' values."""
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=FS_NOISE,
                    seed=41, effects=("heat_transfer",))
    cfg2, _a, t, p, _ = _two_unloads(0.3)
    for c, (tt, pp) in ((cfg, (lambda s: (s.t, s.measured))(simulate(cfg))), (cfg2, (t, p))):
        st = dataclasses.replace(settings_for(c), curve_fit=True)
        inline = StreamingEstimator(st, live=True)
        res_inline = inline.push_block(tt, pp) + inline.finish()
        assert inline.take_final_fits() == []
        deferred = StreamingEstimator(st, live=True, defer_final_fit=True)
        res_def, jobs = [], []
        for k in range(0, tt.size, 100):  # blocks, as a node receives them
            res_def += deferred.push_block(tt[k:k + 100], pp[k:k + 100])
            jobs += deferred.take_final_fits()
        res_def += deferred.finish()
        jobs += deferred.take_final_fits()
        assert not any(r.final for r in res_def)
        finals = [r for r in (job.run() for job in jobs) if r is not None]
        assert finals and all(r.final for r in finals)
        assert [r.to_dict() for r in res_inline] == \
            [r.to_dict() for r in sorted(res_def + finals, key=lambda r: (r.index, r.final))]


def test_settings_changed_between_unloads_apply_to_the_next():
    """A node's parameter change (e.g. ``ros2 param set /estimator volume``) sets the
    streaming estimator's settings: the next unload is analysed with them (C scales with
    the volume in eq 39)."""
    cfg = RigConfig(volume=2e-3, conductance=orifice_conductance(1.5e-3), noise_std=FS_NOISE,
                    seed=42)
    sim = simulate(cfg)
    st = dataclasses.replace(settings_for(cfg), curve_fit=False)
    est = StreamingEstimator(st)
    first = est.push_block(sim.t, sim.measured)
    assert est.state == "waiting" or est.state == "tail"
    est.finish()
    est.settings = dataclasses.replace(st, volume=4e-3)
    assert est.settings.volume == 4e-3
    second = est.push_block(sim.t + sim.t[-1] + 1.0, sim.measured) + est.finish()
    assert first[0].volume == 2e-3 and second[0].volume == 4e-3
    assert second[0].conductance == pytest.approx(2 * first[0].conductance, rel=1e-9, abs=0)
    with pytest.raises(EstimationError, match="start_time"):
        est.settings = dataclasses.replace(st, start_time=0.0)


@pytest.mark.parametrize("settle", [0.3, 0.9])
def test_an_unload_soon_after_a_step_charge_has_its_plateau_from_after_the_rise(settle):
    """A charge valve that fills the vented tank within a sample or two, then the discharge
    valve opened 0.3-0.9 s later (a PLC's cycle, as over OPC UA after an Abort): the
    plateau begins after the block that rose. With the rise's block in the plateau the
    start fit took vented samples as p10's (p10 -2 %, its misfit read as the noise: a
    crossing window below p_atm, never closed, the unload 'unloading' until the record
    ended)."""
    from pneumatic_unload.model.rig import run_cycles

    cfg = RigConfig(volume=1e-3, conductance=8e-9, initial_pressure=7e5, critical_ratio=0.4,
                    noise_std=FS_NOISE, seed=7, pre_time=1.0)
    cfg = cfg.replace(duration=1.2 * default_duration(cfg))
    run = run_cycles(cfg, 3, settle_time=settle, vent_time=1.5, charge_time=0.002)
    st = dataclasses.replace(settings_for(cfg), curve_fit=False)
    res = analyze(run.t, run.measured, st)
    assert [r.status for r in res] == ["ok"] * 3, [r.status_text for r in res]
    for r in res:
        assert r.p10 == pytest.approx(7e5, abs=4 * FS_NOISE)
        assert r.conductance == pytest.approx(res[0].conductance, rel=0.01)
