"""An estimator started (or restarted) part way into an unload: no result for that unload,
a warning that says why, and correct results from the next unload on (the core; the node
test is in test_nodes.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimatorSettings,
    StreamingEstimator,
    analyze,
    explain_no_unload,
)
from pneumatic_unload.rig import run_cycles

C_TRUE = 8e-9  # [m^3/(s Pa)]
RIG = {"volume": 2e-4, "conductance": C_TRUE, "noise_std": 1000.0, "quantization": 10.0}
CYCLE = {"settle_time": 0.6, "vent_time": 0.3, "charge_time": 0.3}


def _cycles(rate: float, seed: int, unloads: int = 3):
    cfg = RigConfig(rate=rate, pre_time=0.6, duration=1.2, seed=seed, **RIG)
    b = run_cycles(cfg, unloads, **CYCLE)
    opens = np.flatnonzero(np.diff((b.opening > 0).astype(int)) == 1) + 1
    return b.t, b.measured, opens


@pytest.mark.parametrize("rate", [1000.0, 10000.0])
@pytest.mark.parametrize("frac", [0.003, 0.02, 0.1, 0.3, 0.6])
def test_joined_mid_unload_gives_no_result_for_it_and_the_next_ones_are_right(rate, frac):
    t, p, opens = _cycles(rate, seed=int(frac * 1000))
    st = EstimatorSettings(volume=RIG["volume"], curve_fit=False)
    full = analyze(t, p, st)
    assert [r.status for r in full] == ["ok"] * 3
    k = opens[0] + int(frac * 1.2 * rate)  # the stream starts frac of the way into unload 0
    est = StreamingEstimator(st)
    got = est.push_block(t[k:], p[k:]) + est.finish()
    # before the fix: an 'ok' result 1-2 % off, or 'not_choked', for the partial unload
    assert [r.status for r in got] == ["ok", "ok"]
    assert [r.t_start for r in got] == pytest.approx([full[1].t_start, full[2].t_start],
                                                     abs=1e-3)
    for r, ref in zip(got, full[1:], strict=True):
        assert r.conductance_model == pytest.approx(ref.conductance_model, rel=1e-6)
        assert r.conductance_model == pytest.approx(C_TRUE, rel=0.02)
    warn = [d for d in est.diagnostics if d.level == "warn"]
    if frac > 0.5:  # joined in the slow end of the unload: no trigger, nothing to say
        assert not warn
        return
    assert warn and "no plateau before the drop" in warn[0].message
    assert "mid-unload" in warn[0].message and "waiting for a plateau" in warn[0].message
    assert warn[0].t < t[opens[1]]  # said before the next unload starts


def test_per_sample_and_batch_agree_when_joined_mid_unload():
    t, p, opens = _cycles(1000.0, seed=5, unloads=2)
    k = opens[0] + 100
    st = EstimatorSettings(volume=RIG["volume"], curve_fit=True)
    est = StreamingEstimator(st)
    per = []
    for a, b in zip(t[k:].tolist(), p[k:].tolist(), strict=True):
        per += est.push(a, b)
    per += est.finish()
    assert [r.to_dict() for r in per] == [r.to_dict() for r in analyze(t[k:], p[k:], st)]
    assert len({r.index for r in per}) == 1 and all(r.status == "ok" for r in per)


def test_a_plateau_of_min_plateau_samples_still_gives_a_result():
    t, p, opens = _cycles(10000.0, seed=2, unloads=1)
    st = EstimatorSettings(volume=RIG["volume"], curve_fit=False)
    k = opens[0] - 40  # 40 samples of plateau (min_plateau 32)
    got = analyze(t[k:], p[k:], st)
    assert [r.status for r in got] == ["ok"]
    assert got[0].conductance_model == pytest.approx(C_TRUE, rel=0.02)
    # fewer than min_plateau: refused, and the library says why
    k = opens[0] - 10
    assert analyze(t[k:], p[k:], st) == []
    assert "no plateau before the drop" in explain_no_unload(t[k:], p[k:], st)
    # ... unless min_plateau allows that short a plateau
    short = dataclasses.replace(st, min_plateau=8)
    assert [r.status for r in analyze(t[k:], p[k:], short)] == ["ok"]
