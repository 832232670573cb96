# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Decisions of the streaming estimator: one function per decision, the same answer for one
index (the per-sample path) and for many (the block path), and bit-identical results of
push, push_block (random block sizes) and analyze on many seeded traces of every kind."""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import StreamingEstimator, analyze
from pneumatic_unload.estimation import decisions as dec
from pneumatic_unload.estimation.buffer import SampleBuffer
from pneumatic_unload.model import default_duration, simulate
from pneumatic_unload.model.rig import run_cycles
from pneumatic_unload.physics import orifice_conductance

FS_NOISE = 1000.0  # 0.1 % of a 1 MPa full-scale transducer [Pa]
KINDS = ("clean", "heat", "aborted", "two_unloads", "auto_atm", "volts", "bad_stamps",
         "spike_and_stuck", "stuck_in_unload", "saturated", "clock_step", "mid_unload",
         "zero_offset")


def _rig(rng, seed, **kw):
    base = {"volume": rng.uniform(1e-3, 6e-3), "conductance": orifice_conductance(
        rng.uniform(1.2e-3, 3e-3)), "initial_pressure": rng.uniform(4e5, 8e5),
        "noise_std": FS_NOISE, "seed": seed}
    base.update(kw)
    cfg = RigConfig(**base)
    if "duration" not in kw:
        cfg = cfg.replace(duration=0.6 * default_duration(cfg))
    return cfg


def _trace(kind, seed):
    """(settings, t [s], p [Pa or V]) of one seeded trace of the given kind."""
    rng = np.random.default_rng(seed)
    if kind == "heat":
        cfg = _rig(rng, seed, effects=("heat_transfer",))
        sim = simulate(cfg)
        return settings_for(cfg), sim.t + 1.7e9, sim.measured  # with the curve fit
    if kind == "aborted":
        cfg = _rig(rng, seed, duration=rng.uniform(8.0, 20.0),
                   valve_close_time=rng.uniform(0.2, 0.8), effects=("heat_transfer",))
        sim = simulate(cfg)
        return dataclasses.replace(settings_for(cfg), curve_fit=False), sim.t, sim.measured
    if kind == "two_unloads":
        cfg = _rig(rng, seed, pre_time=0.5)
        cfg = cfg.replace(duration=1.5 * default_duration(cfg))
        a, b = simulate(cfg), simulate(cfg.replace(seed=seed + 1, initial_pressure=6e5))
        n_ramp = int(rng.integers(0, 800))
        ramp = np.linspace(a.pressure[-1], 6e5, n_ramp + 2)[1:-1]
        ramp = ramp + rng.normal(0.0, FS_NOISE, n_ramp)
        t = np.concatenate([a.t, a.t[-1] + 1e-3 * np.arange(1, n_ramp + 1),
                            a.t[-1] + 1e-3 * (n_ramp + 1) + b.t])
        p = np.concatenate([a.measured, ramp, b.measured])
        return dataclasses.replace(settings_for(cfg), curve_fit=False), t, p
    if kind == "stuck_in_unload":
        # stuck for 1 s somewhere in the unload (before or after the crossing), then a second
        # clean unload: the skip phase after the bad_data result, then re-arming
        cfg = _rig(rng, seed, pre_time=0.5)
        cfg = cfg.replace(duration=1.2 * default_duration(cfg))
        a, b = simulate(cfg), simulate(cfg.replace(seed=seed + 1))
        p = a.measured.copy()
        k = int(np.searchsorted(a.t, a.t_open + rng.uniform(0.02, 3.0)))
        p[k:k + 1000] = p[k]
        ramp = np.linspace(a.pressure[-1], b.pressure[0], 300)
        t = np.concatenate([a.t, a.t[-1] + 1e-3 * np.arange(1, 301), a.t[-1] + 0.301 + b.t])
        p = np.concatenate([p, ramp + rng.normal(0.0, FS_NOISE, 300), b.measured])
        st = dataclasses.replace(settings_for(cfg), curve_fit=seed % 2 == 0)
        return (dataclasses.replace(st, atmosphere=None) if seed == 13 else st), t, p
    if kind == "mid_unload":
        # a stream that joins a cycling rig part way into an unload (an estimator restarted
        # mid-unload): the skip of that unload, then the next ones
        cfg = _rig(rng, seed, pre_time=0.5, duration=1.2)
        b = run_cycles(cfg, 2, settle_time=0.6, vent_time=0.3, charge_time=0.3)
        k = int(np.flatnonzero(b.opening > 0)[0]) + int(rng.integers(5, 800))
        return dataclasses.replace(settings_for(cfg), curve_fit=seed % 2 == 0), b.t[k:], \
            b.measured[k:]
    if kind == "zero_offset":
        # a transducer zero 0.3-3 kPa either way, the record long past its tail: the level
        # tail followed on for its gap to p_atm (decisions.zero_watch), then a new charge
        cfg = _rig(rng, seed, effects=("sensor_offset",), pre_time=0.5,
                   sensor_offset=float(rng.choice([-1.0, 1.0]) * rng.uniform(300.0, 3000.0)))
        cfg = cfg.replace(duration=1.5 * default_duration(cfg))
        a = simulate(cfg)
        ramp = np.linspace(a.measured[-1], 6e5, 300) + rng.normal(0.0, FS_NOISE, 300)
        t = np.concatenate([a.t, a.t[-1] + 1e-3 * np.arange(1, 301)])
        return dataclasses.replace(settings_for(cfg), curve_fit=False), t, \
            np.concatenate([a.measured, ramp])
    if kind == "saturated":
        cfg = _rig(rng, seed, full_scale=0.9 * rng.uniform(4e5, 8e5), initial_pressure=8e5)
        sim = simulate(cfg)
        return dataclasses.replace(settings_for(cfg), curve_fit=False), sim.t, sim.measured
    cfg = _rig(rng, seed, pre_time=3.0 if kind == "spike_and_stuck" else 0.2)
    sim = simulate(cfg)
    st = dataclasses.replace(settings_for(cfg), curve_fit=False,
                             heat_model=("adiabatic", "natural")[seed % 2])
    t, p = sim.t.copy(), sim.measured.copy()
    if kind == "auto_atm":
        return dataclasses.replace(st, atmosphere=None), t, p
    if kind == "volts":
        gain, offset = 2.5e5, -1.0e5
        return dataclasses.replace(st, signal_gain=gain, signal_offset=offset), t, \
            (p - offset) / gain
    if kind == "bad_stamps":
        keep = np.ones(t.size, bool)
        g = int(rng.integers(300, t.size // 2))
        keep[g:g + int(rng.integers(10, 60))] = False  # a gap
        p[int(rng.integers(100, t.size - 1))] = np.nan
        t[int(rng.integers(100, t.size - 1))] = t[0]  # a stamp going backwards
        return st, t[keep], p[keep]
    if kind == "clock_step":
        # the clock steps back 0.5..3 s somewhere in the record (unload, tail or plateau)
        k = int(rng.integers(100, t.size - 100))
        t[k:] -= rng.uniform(0.5, 3.0)
        return st, t, p
    if kind == "spike_and_stuck":
        j = int(rng.integers(300, 500))
        p[j] -= 40.0 * FS_NOISE  # a spike: a trigger that is not confirmed
        k = int(rng.integers(j + 200, j + 400))
        p[k:k + 1500] = p[k]  # a stuck stretch on the plateau (longer than PLATEAU)
        return st, t, p
    return st, t, p  # clean


def _blocks(est, t, p, rng, max_block):
    out, i = [], 0
    while i < t.size:
        k = int(rng.integers(1, max_block))
        out += est.push_block(t[i:i + k], p[i:i + k])
        i += k
    return out + est.finish()


def _exact(results):
    """The results' fields as text: a float's repr is its exact value, and two NaNs (a
    budget's line not computed) compare equal, which ``==`` on dicts holding distinct NaN
    objects does not."""
    return [repr(r.to_dict()) for r in results]


@pytest.mark.parametrize("kind", KINDS)
def test_push_blocks_and_batch_bit_identical_on_seeded_traces(kind):
    rng = np.random.default_rng(KINDS.index(kind))
    n_results = 0
    for seed in (11, 12, 13):
        st, t, p = _trace(kind, seed)
        batch = analyze(t, p, st)
        per_est = StreamingEstimator(st)
        per = []
        for a, b in zip(t.tolist(), p.tolist(), strict=True):
            per += per_est.push(a, b)
        per += per_est.finish()
        blk_est = StreamingEstimator(st)
        blk = _blocks(blk_est, t, p, rng, int(rng.choice([50, 700, 20000])))
        assert _exact(per) == _exact(batch), (kind, seed)
        assert _exact(blk) == _exact(batch), (kind, seed)
        assert list(per_est.results) == per and list(blk_est.results) == blk
        assert per_est.diagnostics == blk_est.diagnostics
        assert per_est.buffer.cs == blk_est.buffer.cs and per_est.buffer.cq == blk_est.buffer.cq
        assert per_est.state == blk_est.state
        n_results += len(batch)
    assert n_results >= 3


def _same(scalar, vector):
    """Bitwise equality of a scalar result and one element of a vector result."""
    a, b = np.float64(scalar), np.float64(vector)
    return a.tobytes() == b.tobytes() or (math.isnan(a) and math.isnan(b))


def _buffer(seed):
    rng = np.random.default_rng(seed)
    cfg = _rig(rng, seed, effects=("heat_transfer",) if seed % 2 else (),
               valve_close_time=0.5 if seed % 3 == 0 else 0.0, duration=3.0)
    sim = simulate(cfg)
    buf = SampleBuffer()
    buf.extend(sim.t, sim.measured)
    return buf, rng


def _check_one_against_many(buf, rng):
    cs, cq = buf.sums()
    tv, pv = buf.views()
    n = len(buf)
    arm = int(rng.integers(0, 400))
    i0 = int(rng.integers(arm + 40, 2000))
    ks = np.arange(arm + 40 + int(rng.integers(0, 64)), n - 1, 7, dtype=np.int64)
    sigma, slope0 = float(rng.uniform(100.0, 3000.0)), float(rng.uniform(-1e3, 1e6))
    p10, tau = float(pv[arm]), float(rng.uniform(0.01, 1.0))
    low, thr = float(rng.uniform(1e5, 8e5)), float(rng.uniform(10.0, 1e4))
    span = int(rng.integers(0, 3000))
    for stuck in (False, True):
        kw = {"arm": arm, "min_plateau": 32, "trigger_sigma": 8.0, "stuck_reported": stuck}
        vec = dec.plateau_check(cs, cq, pv, ks, **kw)
        for j in range(0, ks.size, 5):
            one = dec.plateau_check(buf.cs, buf.cq, buf.p, int(ks[j]), **kw)
            for f in dataclasses.fields(one):
                assert _same(getattr(one, f.name), getattr(vec, f.name)[j]), f.name
    checks = {
        "confirmed": lambda k, c, t: dec.confirmed(c, arm, k, p10, sigma),
        "stalled": lambda k, c, t: dec.stalled(c, t, k, i0=i0, sigma=sigma, slope0=slope0),
        "flat": lambda k, c, t: dec.flat(c, k, i0=i0, tau=tau, dt_nominal=1e-3, p10=p10,
                                         sigma=sigma),
        "block_mean": lambda k, c, t: dec.block_mean(c, k),
        "rose": lambda k, c, t: dec.rose(dec.block_mean(c, k), low, thr),
        "recovery_due": lambda k, c, t: dec.recovery_due(k, i0, span),
    }
    kt = ks[ks > arm + 1]
    for name, fn in checks.items():
        r_vec = fn(kt, cs, tv)
        for j in range(0, kt.size, 3):
            assert _same(fn(int(kt[j]), buf.cs, buf.t), r_vec[j]), name
    # the running lowest block mean is the scalar min-update of step_tail
    kb = ks[ks >= dec.PERIOD]
    lows, lo = dec.running_low(low, dec.block_mean(cs, kb)), low
    for j in range(kb.size):
        assert _same(lo, lows[j])
        lo = min(lo, dec.block_mean(buf.cs, int(kb[j])))


@pytest.mark.parametrize("seed", range(6))
def test_each_decision_gives_the_same_answer_for_one_index_and_for_many(seed):
    """The per-sample path calls each decision with an int index on the array.array
    buffers, the block path with an int64 array on numpy views: bitwise the same."""
    buf, rng = _buffer(seed)
    for _ in range(4):
        _check_one_against_many(buf, rng)


def test_sample_buffer_grows_while_a_view_of_it_is_alive():
    """A view held elsewhere (a sampling profiler's frame, as on a Dask worker) must not
    stop the buffer from growing (it raised BufferError), and the sums stay the same."""
    from pneumatic_unload.estimation.buffer import SampleBuffer

    rng = np.random.default_rng(0)
    t, p = np.arange(300) * 1e-3, 7e5 + rng.normal(0, 1e3, 300)
    ref, buf = SampleBuffer(), SampleBuffer()
    for k in range(100):
        ref.append(float(t[k]), float(p[k]))
    ref.extend(t[100:200], p[100:200])
    for k in range(200, 300):
        ref.append(float(t[k]), float(p[k]))
    held = []
    for k in range(100):
        held.append(buf.views())  # views of every array, kept alive
        held.append(buf.sums())
        buf.append(float(t[k]), float(p[k]))
    held.append(buf.views())
    buf.extend(t[100:200], p[100:200])
    for k in range(200, 300):
        held.append(buf.sums())
        buf.append(float(t[k]), float(p[k]))
    for name in ("t", "p", "cs", "cq"):
        assert getattr(buf, name).tobytes() == getattr(ref, name).tobytes(), name
