"""Phases that hold samples until something happens are bounded: an aborted unload's
recovery, and an unload whose p_atm is to come from its final plateau.

A re-heating that never settles (here a 10 L tank whose recovery time constant is about
20 min) is closed after :data:`~pneumatic_unload.estimation.sse.RECOVERY_MAX` samples, as at
the end of a stream, with the reason: the buffer never holds more. An unload analysed with
p_atm auto holds its samples until its final plateau: past
:data:`~pneumatic_unload.estimation.reduction.AUTO_HOLD_MAX` samples it is closed with the
reason and the fix (give the atmosphere). The bounds are lowered so that the tests run in
seconds; the per-sample and block paths must agree bit for bit.
"""

from __future__ import annotations

import dataclasses

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import StreamingEstimator, reduction, sse
from pneumatic_unload.model import default_duration, simulate
from pneumatic_unload.physics import orifice_conductance
from pneumatic_unload.runs import settings_for

#: Lowered bound [-] (production: 4 M samples).
CAP = 8000


def _slow_recovery():
    cfg = RigConfig(volume=10e-3, conductance=orifice_conductance(2e-3), noise_std=300.0,
                    seed=11, duration=40.0, valve_close_time=2.0, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=0.05)
    return cfg, simulate(cfg)


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


def test_the_bound_is_above_any_recovery_the_package_measures():
    # 4 M samples: 7 min at 10 kHz (three thermal time constants of a 50 L tank are a few
    # minutes), 128 MiB of buffer at 32 B a sample
    assert sse.RECOVERY_MAX == 1 << 22


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


def test_the_auto_bound_keeps_ordinary_unloads():
    # 8 M samples: 14 min at 10 kHz, 256 MiB of buffer
    assert reduction.AUTO_HOLD_MAX == 1 << 23
