# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""What the streaming estimator keeps of its past stays bounded on an endless stream.

Counts of retained objects (results, diagnostics, buffered samples), never timings: a
cycling rig at 10 kHz (the soak benchmark's cycle, bench/bench_soak.py) fed in blocks as
the node receives them, and a flood of bad samples.
"""

from __future__ import annotations

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    DiagnosticLog,
    EstimatorSettings,
    StreamingEstimator,
    decisions,
    history,
)
from pneumatic_unload.model.rig import run_cycles

RATE = 10_000.0
CYCLE_S = 2.4  # unload 1.2 s, vented 0.3 s, charge 0.3 s, plateau 0.6 s
UNLOADS = 12


@pytest.fixture(scope="module")
def cycling_run():
    cfg = RigConfig(volume=2e-4, conductance=8e-9, noise_std=1000.0, quantization=10.0,
                    seed=1, duration=1.2, pre_time=0.6, rate=RATE)
    return run_cycles(cfg, UNLOADS, settle_time=0.6, vent_time=0.3, charge_time=0.3)


def _feed(run, *, block: int = 100):
    """Feed the run in blocks; returns (estimator, results returned, diagnostics seen by
    a reader polling ``since`` after every block, largest buffer held [samples])."""
    est = StreamingEstimator(EstimatorSettings(volume=2e-4, curve_fit=False), live=True)
    out, seen, n_seen, longest = [], [], 0, 0
    for k in range(0, run.t.size, block):
        out += est.push_block(run.t[k:k + block] + 1.7e9, run.measured[k:k + block])
        seen += est.diagnostics.since(n_seen)
        n_seen = est.diagnostics.total
        longest = max(longest, len(est.buffer))
    out += est.finish()
    seen += est.diagnostics.since(n_seen)
    return est, out, seen, longest


def test_retained_state_is_bounded_and_a_poller_loses_nothing(cycling_run, monkeypatch):
    monkeypatch.setattr(history, "RESULTS_KEPT", 5)
    monkeypatch.setattr(history, "FIRST_DIAGNOSTICS", 2)
    monkeypatch.setattr(history, "LAST_DIAGNOSTICS", 3)
    est, out, seen, longest = _feed(cycling_run)
    assert sum(r.status == "ok" for r in out) >= UNLOADS - 1  # the first may be skipped
    # results: the last RESULTS_KEPT kept, every one returned once
    assert len(est.results) == 5 and list(est.results) == out[-5:]
    # diagnostics: first 2 and last 3 held, all counted, a poller saw each exactly once
    assert est.diagnostics.total == len(seen) > 5
    assert len(est.diagnostics) == 5 and est.diagnostics.dropped == len(seen) - 5
    assert list(est.diagnostics) == seen[:2] + seen[-3:]
    # samples: about one cycle held (the previous unload is dropped on the next plateau),
    # not TRIM_MIN more
    cycle = int(CYCLE_S * RATE)
    assert longest < 1.5 * cycle < decisions.TRIM_MIN
    assert est.n_samples == cycling_run.t.size


def test_trimming_early_changes_no_result(cycling_run, monkeypatch):
    """The buffer trimmed after every unload gives the results of one trimmed only past
    TRIM_MIN idle samples (the behaviour before TRIM_FLOOR)."""
    _, early, _, short = _feed(cycling_run)
    monkeypatch.setattr(decisions, "TRIM_FLOOR", 10**12)
    _, late, _, long_ = _feed(cycling_run)
    assert long_ > decisions.TRIM_MIN > short
    assert [r.to_dict() for r in early] == [r.to_dict() for r in late]


def test_a_flood_of_bad_samples_keeps_few_diagnostics():
    """50 000 NaN pressures: each is diagnosed (counted), the log holds the first and the
    last ones only."""
    est = StreamingEstimator(EstimatorSettings(volume=1e-3))
    n = 50_000
    t = np.arange(n) * 1e-3
    est.push_block(t, np.full(n, np.nan))
    d = est.diagnostics
    assert d.total == n
    assert len(d) == history.FIRST_DIAGNOSTICS + history.LAST_DIAGNOSTICS
    assert "t=0.000000" in d[0].message and f"t={t[-1]:.6f}" in d[-1].message
    assert not est.results and len(est.buffer) == 0


def test_diagnostic_log_reads_like_a_list():
    log = DiagnosticLog(first=1, last=2)
    items = [f"d{k}" for k in range(5)]
    for x in items:
        log.append(x)  # type: ignore[arg-type]
    assert list(log) == ["d0", "d3", "d4"] and log == ["d0", "d3", "d4"]
    assert log[-1] == "d4" and log[:2] == ["d0", "d3"] and len(log) == 3
    assert list(reversed(log)) == ["d4", "d3", "d0"]
    assert log.since(0) == ["d0", "d3", "d4"] and log.since(3) == ["d3", "d4"]
    assert log.since(4) == ["d4"] and log.since(5) == [] and log.dropped == 2
