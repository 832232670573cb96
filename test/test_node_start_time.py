"""The estimator node's start-time mode (issue #11): a record that begins at a given opening,
analysed live with the library's opening-start path, equals ``analyze --start-time`` on
the same bag; and the core of that mode (:class:`OpeningStartEstimator`) equals the offline
analysis, whether the record settles or the stream ends first.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import (
    EstimationError,
    EstimatorSettings,
    OpeningStartEstimator,
    analyze,
)
from pneumatic_unload.model import simulate

#: Keys that must agree to the last bits between live and offline results.
KEYS = ("conductance", "conductance_model", "conductance_model_std", "tau_exp", "p10",
        "p_star", "critical_ratio", "critical_ratio_std")
P_ATM = 101325.0
#: The record's clock: absolute stamps, as a bag's [s].
T0 = 1.7e9


def _record(duration: float = 4.0, seed: int = 3) -> tuple[np.ndarray, np.ndarray, float]:
    """A 1 L tank, C 8e-9 m^3/(s Pa), natural convection, 1 kHz, 1 kPa noise: 0.5 s before
    the opening, then the unload; stamps on the bag's clock [s], pressures [Pa], the
    opening [s]."""
    cfg = RigConfig(volume=1e-3, conductance=8e-9, effects=("heat_transfer",), pre_time=0.5,
                    rate=1000.0, duration=duration, noise_std=1000.0, seed=seed)
    sim = simulate(cfg)
    t = np.round((T0 + sim.t) * 1e9) * 1e-9
    return t, sim.measured, float(t[np.argmin(np.abs(sim.t - 0.5))])


def _settings(start: float) -> EstimatorSettings:
    return EstimatorSettings(volume=1e-3, atmosphere=P_ATM, start_time=start,
                             initial_pressure=7e5)


def _live(t: np.ndarray, p: np.ndarray, s: EstimatorSettings, block: int) -> list[Any]:
    est = OpeningStartEstimator(s)
    out: list[Any] = []
    for k in range(0, t.size, block):
        out += est.push_block(t[k:k + block], p[k:k + block])
        out += [j.run() for j in est.take_final_fits()]
    est.finish()
    return out + [j.run() for j in est.take_final_fits()]


def _same(live: Any, off: Any) -> None:
    for key in KEYS:
        a, b = getattr(live, key), getattr(off, key)
        assert a == b or (math.isnan(a) and math.isnan(b)), (key, a, b)


@pytest.mark.parametrize("block,duration", [(1, 4.0), (250, 4.0), (250, 2.0)])
def test_opening_start_core_equals_the_offline_analysis(block: int, duration: float) -> None:
    """Sample by sample or in blocks; the record settles (4 s: the final is made on the
    samples up to where it settles, as offline) or ends first (2 s: on every sample, at
    the end of the stream)."""
    t, p, start = _record(duration)
    s = _settings(start)
    off = analyze(t, p, s)
    live = _live(t, p, s, block)
    assert [r.final for r in live] == [r.final for r in off] == [False, True]
    for a, b in zip(live, off, strict=True):
        _same(a, b)
    assert off[1].conductance_model == pytest.approx(8e-9, rel=0.02)
    settled = off[1].i_complete + 1 < np.count_nonzero(t >= start)
    assert settled == (duration == 4.0)


def test_opening_start_core_refuses_what_it_cannot_use() -> None:
    with pytest.raises(EstimationError, match="atmosphere"):
        OpeningStartEstimator(EstimatorSettings(volume=1e-3, start_time=1.0, atmosphere=None))
    t, p, start = _record(2.0)
    est = OpeningStartEstimator(EstimatorSettings(volume=1e-3, atmosphere=P_ATM,
                                                  start_time=start + 0.0005))
    assert est.push_block(t, p) == [] and est.state == "error"
    assert "give the initial pressure" in est.diagnostics[-1].message


rclpy = pytest.importorskip("rclpy")


def test_start_time_mode_over_dds_equals_analyze_on_the_bag(tmp_path: Path,
                                                            venv_python: Path) -> None:
    """Two processes over real DDS: the replay node publishes a bag, the estimator in
    start-time mode (reliable input) publishes the crossing estimate and the final one when
    the record settles; both equal ``analyze --start-time`` on the bag."""
    from nodeproc import NodeProcess, spin_until
    from pneumatic_unload_msgs.msg import UnloadEstimate
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from pneumatic_unload.io.bag import BagRecorder
    from pneumatic_unload.nodes.common import LATCHED_QOS

    t, p, start = _record()
    bag = tmp_path / "opening"
    with BagRecorder(bag) as rec:
        rec.write_pressures(np.round(t * 1e9).astype(np.int64), p)
    cli = [str(venv_python), "-m", "pneumatic_unload.cli", "analyze", str(bag), "--json",
           "--volume", "1e-3", "--atmosphere", str(P_ATM), "--start-time", repr(start),
           "--initial-pressure", "7e5"]
    out = subprocess.run(cli, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    offline = json.loads(out.stdout)["published"]
    assert [r["final"] for r in offline] == [False, True]

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(f"observer_{time.time_ns()}", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    got: list[Any] = []
    node.create_subscription(UnloadEstimate, "/estimator/estimate", got.append, LATCHED_QOS)
    est = NodeProcess("estimator", {"volume": 1e-3, "atmosphere": P_ATM, "start_time": start,
                                    "initial_pressure": 7e5, "qos": "reliable"}, tmp_path)
    try:
        est.wait_output("start-time mode", 20.0)
        rep = NodeProcess("replay", {"bag": str(bag), "rate": 0.0,
                                     "topics": ["/tank/pressure"]}, tmp_path)
        try:
            assert spin_until(node, ex, lambda: len(got) >= 2, 60.0), (
                f"{len(got)} estimate(s); estimator said:\n{est.output()[-2000:]}")
            assert rep.proc.wait(timeout=30) == 0
        finally:
            rep.stop()
    finally:
        code = est.stop()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert code == 0
    assert len(got) == 2 and "curve-fit" in got[1].method and "given-start" in got[0].method
    for live, off in zip(got, offline, strict=True):
        for key in KEYS:
            a, b = getattr(live, key), off[key]
            assert (b is None and math.isnan(a)) or a == pytest.approx(b, rel=1e-9, abs=0.0), \
                key
    assert got[1].conductance_model == pytest.approx(8e-9, rel=0.02)


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
