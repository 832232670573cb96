# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Charges and discharges of one component in one stream (direction 'both', #26).

The rig's alternate cycle (:func:`pneumatic_unload.model.rig.run_cycles` with ``alternate``: a
charge through the component from a 6 bar supply, then its discharge to the room from
where the charge left the tank, no recharge between) analysed by the two-way estimator.
A discharge that follows a charge within seconds starts from a gas the charge warmed (a
hot start the plateau does not show: the rig holds the tank at the supply); the logged gas
temperature, which the rig records, is what gives its T10.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation import (
    StreamingEstimator,
    TwoWayEstimator,
    analyze,
    merge_final,
    stream_estimator,
)
from pneumatic_unload.model.rig import RigStream, run_cycles

C, B, V = 8e-9, 0.45, 1e-3


def _cycle(steps: int = 4, duration: float = 20.0):
    cfg = RigConfig(direction="charge", volume=V, conductance=C, critical_ratio=B,
                    initial_pressure=101325.0, supply_pressure=6e5, noise_std=600.0,
                    pre_time=0.5, effects=("heat_transfer",), seed=3, duration=duration)
    return run_cycles(cfg, steps, settle_time=1.0, alternate=True)


def test_a_cycle_gives_both_directions_in_turn_with_the_rig_s_c_and_b() -> None:
    run = _cycle()
    est = stream_estimator(EstimatorSettings(direction="both", volume=V))
    assert isinstance(est, TwoWayEstimator)
    est.push_temperature(run.t[::100], run.temperature[::100])  # the rig's 10 Hz log
    res = merge_final(est.push_block(run.t, run.measured) + est.finish())
    assert [r.direction for r in res] == ["charge", "discharge"] * 2
    assert [r.index for r in res] == [0, 1, 2, 3]
    assert all(r.final and r.status == "ok" for r in res), [r.status_text for r in res]
    for r in res:
        assert r.conductance_model == pytest.approx(C, rel=0.01)
        assert abs(r.conductance_model - C) < 2.0 * r.conductance_model_std
        assert r.critical_ratio == pytest.approx(B, abs=0.03)
    # the discharges start from the gas the charges warmed, read from the log
    assert all(r.initial_temperature > 297.0 for r in res if r.direction == "discharge")
    charges = [r for r in res if r.direction == "charge"]
    assert all(r.supply_pressure == pytest.approx(6e5, rel=3e-3) for r in charges)
    assert all(r.p_atm == 101325.0 for r in res)


def test_without_the_log_the_warm_discharge_is_biased_as_said() -> None:
    """The same cycle from its pressure alone: the discharge's T10 is the settings' room
    temperature, 7 K below the gas's; its C is high by ~1.5 % (C goes as sqrt(T10)), the
    charges' are unaffected (their time scale is the supply's temperature)."""
    run = _cycle()
    res = merge_final(analyze(run.t, run.measured, EstimatorSettings(direction="both",
                                                                      volume=V)))
    d = [r.conductance_model / C - 1.0 for r in res if r.direction == "discharge"]
    c = [r.conductance_model / C - 1.0 for r in res if r.direction == "charge"]
    assert all(0.005 < x < 0.03 for x in d) and all(abs(x) < 0.01 for x in c)


def test_per_sample_and_block_numbering_agree() -> None:
    run = _cycle(steps=3, duration=12.0)
    s = EstimatorSettings(direction="both", volume=V, curve_fit=False)
    one = TwoWayEstimator(s)
    a = [r for k in range(run.t.size) for r in one.push(float(run.t[k]),
                                                         float(run.measured[k]))]
    blk = TwoWayEstimator(s)
    b = [r for k in range(0, run.t.size, 777)
         for r in blk.push_block(run.t[k:k + 777], run.measured[k:k + 777])]
    assert a == b and [r.direction for r in a] == ["charge", "discharge", "charge"]
    # one log: the charge's estimator's diagnostics marked
    msgs = [d.message for d in one.diagnostics]
    assert any(m.startswith("charge: ") for m in msgs)
    assert any(not m.startswith("charge: ") for m in msgs)


def test_two_way_settings_and_the_rig_s_turn() -> None:
    with pytest.raises(EstimationError, match="TwoWayEstimator"):
        StreamingEstimator(EstimatorSettings(direction="both"))
    est = TwoWayEstimator(EstimatorSettings(direction="both"))
    with pytest.raises(EstimationError, match="fixed"):
        est.settings = EstimatorSettings(direction="charge")
    with pytest.raises(EstimationError, match="one step"):
        analyze(np.arange(20.0), np.full(20, 1e5),
                EstimatorSettings(direction="both", start_time=0.0))
    # the rig turns only after a step, from where the step left the tank
    rs = RigStream(RigConfig(direction="charge", volume=V, conductance=C,
                             initial_pressure=101325.0, supply_pressure=6e5, duration=5.0))
    assert "after a step" in rs.reverse()
    rs.open_valve()
    rs.next_block(6000)
    assert rs.phase == "vented" and rs.reverse() == ""
    assert rs.cfg.direction == "discharge"
    assert rs.cfg.initial_pressure == pytest.approx(6e5, rel=0.01)
    assert math.isclose(rs.cfg.wall_temperature, 293.15)
