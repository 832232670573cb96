# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Phases that hold samples until something happens are bounded: an aborted unload's
recovery, and an unload whose p_atm is to come from its final plateau.

A re-heating that never settles (here a 10 L tank whose recovery time constant is about
20 min) is closed after :data:`~pneumatic_unload.estimation.sse.RECOVERY_MAX` samples, as at
the end of a stream, with the reason: the buffer never holds more. An unload analysed with
p_atm auto holds its samples until its final plateau: past
:data:`~pneumatic_unload.estimation.reduction.AUTO_HOLD_MAX` samples it is closed with the
reason and the fix (give the atmosphere). The bounds are lowered so that the tests run in
seconds; the per-sample and block paths must agree bit for bit. The production bounds are
held to what they are for: the largest tank's recovery and unload end under them at 10 kHz,
and the buffer they allow fits the memory documented for them.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import StreamingEstimator, reduction, sse
from pneumatic_unload.estimation.decisions import PLATEAU
from pneumatic_unload.model import default_duration, simulate
from pneumatic_unload.physics import orifice_conductance

#: Lowered bound [-] (production: 4 M samples).
CAP = 8000


def _slow_recovery():
    cfg = RigConfig(volume=10e-3, conductance=orifice_conductance(2e-3), noise_std=300.0,
                    seed=11, duration=40.0, valve_close_time=2.0, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=0.05)
    return cfg, simulate(cfg)


def _feed_holding(est: StreamingEstimator, sim: Any, state: str) -> tuple[list, float]:
    """Feed ``sim`` in blocks of 1000; the results and the bytes the estimator's buffer
    grows by per sample held while in ``state`` [B]."""
    out, held = [], []
    for k in range(0, sim.t.size, 1000):
        out += est.push_block(sim.t[k:k + 1000], sim.measured[k:k + 1000])
        if est.state == state:
            held.append(_held(est))
    out += est.finish()
    return out, _bytes_per_sample(held)


def test_a_recovery_that_never_settles_is_closed_at_the_bound(monkeypatch):
    monkeypatch.setattr(sse, "RECOVERY_MAX", CAP)
    cfg, sim = _slow_recovery()
    est = StreamingEstimator(settings_for(cfg))
    held, at_abort = 0, None
    out = []
    for k in range(0, sim.t.size, 1000):
        out += est.push_block(sim.t[k:k + 1000], sim.measured[k:k + 1000])
        if est.state == "recovery":
            held = max(held, len(est.buffer))
        if out and at_abort is None:
            at_abort = len(est.buffer)  # the closing: unload and plateau held so far
    # closed while streaming (not by finish()), with the reason, under the unload's index
    # (its SSE extrapolated from the part recorded, as at the end of a stream)
    assert [(r.index, r.final) for r in out] == [(0, False), (0, True)], out
    assert out[0].status == "aborted" and out[1].status in ("aborted", "aborted_sse")
    assert f"followed for {CAP} samples" in out[1].status_text
    assert est.state == "waiting"
    assert est.finish() == []
    assert at_abort is not None and held <= at_abort + CAP + 1000 < sim.t.size
    # per sample: the same results
    one = StreamingEstimator(settings_for(cfg))
    seq = [r for ti, pi in zip(sim.t.tolist(), sim.measured.tolist(), strict=True)
           for r in one.push(ti, pi)]
    assert [(r.status, r.status_text, r.i_complete) for r in seq] == [
        (r.status, r.status_text, r.i_complete) for r in out]


#: The largest tank the package is meant for [m^3] and the highest sample rate it runs at
#: [Hz] (the sizes RECOVERY_MAX and AUTO_HOLD_MAX are documented for: a 50 L tank, 10 kHz).
BIG_TANK, FAST_RATE = 50e-3, 10_000.0
MIB = 1 << 20


def _held(est: StreamingEstimator) -> tuple[int, int]:
    """Samples the estimator's buffer holds [-] and the bytes it takes for them [B]
    (stamps, values and their two prefix sums)."""
    buf = est.buffer
    return len(buf), sum(a.itemsize * len(a) for a in (buf.t, buf.p, buf.cs, buf.cq))


def _bytes_per_sample(held: list[tuple[int, int]]) -> float:
    """Bytes the buffer grows by per sample held [B], from (samples, bytes) pairs."""
    (n0, b0), (n1, b1) = min(held), max(held)
    assert n1 > n0
    return (b1 - b0) / (n1 - n0)


@pytest.mark.parametrize("length_diameter_ratio", [0.5, 4.0])
def test_the_recovery_bound_outlasts_a_big_tanks_recovery_within_its_memory(
        length_diameter_ratio):
    """What RECOVERY_MAX is for, both ways. The recovery of the largest tank meant for
    (50 L from 10 bar, natural convection, the valve closed 15 s into an unload of tau_exp
    about 2 min) is declared over from its plateau (SSE) before the bound at 10 kHz: its
    tests are in seconds (3 expected and 4 fitted thermal time constants, refits each 25 %
    longer) and more samples only make its plateau surer, so a record at 200 Hz (the bound
    not reached) gives the duration, whose samples at 10 kHz are counted (measured: 206 and
    257 s, 2.1 and 2.6 M samples). And what the bound lets the buffer hold of a recovery
    fits in 128 MiB, at the bytes the buffer grows by per sample held."""
    cfg = RigConfig(volume=BIG_TANK, length_diameter_ratio=length_diameter_ratio,
                    initial_pressure=1e6, conductance=orifice_conductance(1.5e-3),
                    noise_std=300.0, seed=3, rate=200.0, duration=815.0,
                    valve_close_time=15.0, effects=("heat_transfer",))
    sim = simulate(cfg)
    out, per_sample = _feed_holding(StreamingEstimator(settings_for(cfg)), sim, "recovery")
    (final,) = [r for r in out if r.final]
    assert final.status == "aborted_sse" and "from the recovery plateau" in \
        final.status_text, final.status_text
    followed = final.t_complete - final.extra["t_close"]  # the recovery, closing to end [s]
    assert followed * FAST_RATE < sse.RECOVERY_MAX, followed
    assert sse.RECOVERY_MAX * per_sample <= 128 * MIB, per_sample


def test_an_unload_without_final_plateau_is_closed_at_the_auto_bound(monkeypatch):
    # p_atm from the final plateau (atmosphere None): the unload is held until that
    # plateau; one that lasts longer than the bound is closed with the reason and the fix
    monkeypatch.setattr(reduction, "AUTO_HOLD_MAX", 50_000)
    cfg = RigConfig(rate=5000.0, pre_time=1.0, seed=4, noise_std=300.0)
    cfg = dataclasses.replace(cfg, conductance=cfg.conductance * default_duration(cfg) / 30.0)
    sim = simulate(cfg)
    settings = dataclasses.replace(settings_for(cfg), atmosphere=None)
    est = StreamingEstimator(settings)
    out, held = [], 0
    for k in range(0, sim.t.size, 1000):
        out += est.push_block(sim.t[k:k + 1000], sim.measured[k:k + 1000])
        held = max(held, len(est.buffer))
    out += est.finish()
    assert [(r.index, r.status, r.final) for r in out] == [(0, "aborted", True)], out
    assert "p_atm unknown within the memory bound" in out[0].status_text
    assert "--atmosphere" in out[0].status_text
    assert held < 50_000 + 3 * 16384 + 1000 < sim.t.size
    one = StreamingEstimator(settings)
    seq = [r for ti, pi in zip(sim.t.tolist(), sim.measured.tolist(), strict=True)
           for r in one.push(ti, pi)] + one.finish()
    assert [(r.status, r.status_text, r.i_complete) for r in seq] == [
        (r.status, r.status_text, r.i_complete) for r in out]


def test_the_auto_bound_keeps_a_big_tanks_unload_within_its_memory():
    """What AUTO_HOLD_MAX is for, both ways. An ordinary unload of the largest tank meant
    for (50 L from 10 bar through the rig's default 1.5 mm orifice, heat transfer), p_atm
    auto, finds its final plateau, p_atm and the crossing before the bound at 10 kHz: the
    final-plateau test does not depend on the sample rate (its windows are in time), so a
    record at 100 Hz gives the samples held until then at 10 kHz (measured: 565 s, 5.7 M
    samples; at 10 kHz itself 476 s). And what the bound lets the buffer hold fits in
    256 MiB, at the bytes the buffer grows by per sample held."""
    cfg = RigConfig(volume=BIG_TANK, initial_pressure=1e6,
                    conductance=orifice_conductance(1.5e-3), noise_std=300.0, seed=3,
                    rate=100.0, pre_time=1.0, effects=("heat_transfer",))
    cfg = dataclasses.replace(cfg, duration=1.5 * default_duration(cfg))
    sim = simulate(cfg)
    out, per_sample = _feed_holding(
        StreamingEstimator(dataclasses.replace(settings_for(cfg), atmosphere=None)), sim,
        "unloading")
    assert [(r.index, r.status, r.final) for r in out] == [(0, "ok", False), (0, "ok", True)]
    crossing = out[0]
    assert abs(crossing.p_atm - cfg.atmosphere) < 500.0
    assert abs(crossing.conductance_model / cfg.conductance - 1.0) < 0.05
    # held until the final plateau: the unload to the decision and the window's plateau
    until = (crossing.t_complete - crossing.t_start) * FAST_RATE + 2 * PLATEAU
    assert until < reduction.AUTO_HOLD_MAX, until
    assert reduction.AUTO_HOLD_MAX * per_sample <= 256 * MIB, per_sample
