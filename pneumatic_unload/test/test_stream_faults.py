# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Faults of a live stream the core rides out (issue 54 finding 9, issue 55 item 4): a
clock stepped back by an hour re-syncs after CLOCK_RESYNC samples instead of dropping an
hour of them; a rig restarted before p* (the tank charged again, then opened) has its next
unload measured; a stream that starts on a vented tank says that an unload was missed.
Each on the per-sample and the block path alike (the node tests are in test_node_faults.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import EstimatorSettings, StreamingEstimator
from pneumatic_unload.estimation.streaming import CLOCK_RESYNC
from pneumatic_unload.model import simulate
from pneumatic_unload.physics import orifice_conductance

C_TRUE = orifice_conductance(2.5e-3)
ST = EstimatorSettings(volume=1e-3, curve_fit=False)


def _sim(seed: int, pre_time: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    s = simulate(RigConfig(volume=1e-3, conductance=C_TRUE, pre_time=pre_time,
                           duration=4.0, seed=seed, noise_std=1000.0))
    return s.t, s.measured


def _both_paths(t: np.ndarray, p: np.ndarray, st: EstimatorSettings = ST):
    """(results, diagnostics) per sample, and the results in blocks of 100 (the same)."""
    est = StreamingEstimator(st, live=True)
    per = [r for a, b in zip(t.tolist(), p.tolist(), strict=True) for r in est.push(a, b)]
    per += est.finish()
    blk_est = StreamingEstimator(st, live=True)
    blk = [r for k in range(0, t.size, 100)
           for r in blk_est.push_block(t[k:k + 100], p[k:k + 100])] + blk_est.finish()
    assert [r.to_dict() for r in blk] == [r.to_dict() for r in per]
    return per, list(est.diagnostics.since(0)), est.diagnostics.total


def test_a_clock_stepped_back_an_hour_resyncs_and_the_next_unload_is_measured():
    # before: every sample of the second unload dropped as "going backwards" (5 003
    # diagnostics, one result); after: one warning, a re-sync, both unloads measured
    t1, p1 = _sim(1)
    t2, p2 = _sim(2)
    t = 1e5 + np.concatenate([t1, t1[-1] + 0.011 + t2 - 3600.0])
    res, diags, total = _both_paths(t, np.concatenate([p1, p2]))
    assert [(r.index, r.status) for r in res] == [(0, "ok"), (1, "ok")]
    for r in res:
        assert r.conductance_model == pytest.approx(C_TRUE, rel=0.05)
    warns = [d.message for d in diags if d.level != "ok"]
    assert total < 10 and len(warns) == 1, warns
    assert "clock stepped back 3599.99 s" in warns[0] and f"{CLOCK_RESYNC} samples" in warns[0]
    assert any("re-synced on the stepped clock" in d.message for d in diags)
    # the second unload's stamps are the stepped clock's
    assert res[1].t_start == pytest.approx(t1[-1] + 0.011 + 1e5 - 3600.0 + 1.0, abs=0.01)


def test_samples_on_the_stepped_clock_that_do_not_follow_one_another_do_not_resync():
    # a second source 1 h behind, interleaved with the first (two publishers): never a run
    # of CLOCK_RESYNC on it, so the first source's time base is kept throughout
    t1, p1 = _sim(1)
    t = np.repeat(1e5 + t1, 2)
    t[1::2] -= 3600.0
    est = StreamingEstimator(ST, live=True)
    res = est.push_block(t, np.repeat(p1, 2)) + est.finish()
    assert [r.status for r in res] == ["ok"]
    assert not any("re-synced" in d.message for d in est.diagnostics.since(0))


@pytest.mark.parametrize("cut", [1.3, 1.6])
def test_a_rig_restarted_before_p_star_has_its_next_unload_measured(cut):
    # the valve closes `cut` s into the unload (before p*), the tank is charged back to p10
    # in 0.3 s, stays there 2 s and is opened again; before: the fall from the recharged
    # plateau was taken for the closed valve opening again and skipped (one 'aborted')
    t1, p1 = _sim(1)
    t2, p2 = _sim(2, pre_time=2.0)
    k = int(np.searchsorted(t1, cut))
    ramp = t1[k - 1] + 1e-3 * np.arange(1, 301)
    up = np.linspace(p1[k - 1], p2[0], 300) + np.random.default_rng(0).normal(0, 1e3, 300)
    t = np.concatenate([t1[:k], ramp, ramp[-1] + 1e-3 + t2])
    res, _diags, _ = _both_paths(t, np.concatenate([p1[:k], up, p2]))
    assert [(r.index, r.status) for r in res] == [(0, "aborted"), (0, "aborted"), (1, "ok")]
    assert res[2].conductance_model == pytest.approx(C_TRUE, rel=0.05)
    assert res[2].t_start == pytest.approx(ramp[-1] + 1e-3 + 2.0, abs=0.01)
    assert "rose back to p10" in res[1].status_text


@pytest.mark.parametrize("atmosphere", [None, 101325.0])
def test_a_stream_that_starts_on_a_vented_tank_says_an_unload_was_missed(atmosphere):
    # issue 55: an estimator up after the unload was over printed and published nothing
    t, p = _sim(1)
    k = int(np.searchsorted(t, 4.0))  # 3 s after the opening: the tank at p_atm
    st = dataclasses.replace(ST, atmosphere=atmosphere)
    res, diags, _ = _both_paths(t[k:], p[k:], st)
    assert res == []
    warns = [d for d in diags if d.level == "warn"]
    assert len(warns) == 1 and "missed unload?" in warns[0].message
    assert "already vented" in warns[0].message and warns[0].t < t[k] + 0.1
    # a stream that starts on the charged plateau: nothing missed, nothing said
    res, diags, _ = _both_paths(t, p, st)
    assert [r.status for r in res] == ["ok"]
    assert not [d for d in diags if d.level == "warn"]
