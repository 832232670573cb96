# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The streaming estimator's log of a slower channel (a logged gas temperature): bounded,
in order, and sliced by an unload's span as every final fit takes it."""

from __future__ import annotations

import numpy as np

from pneumatic_unload.estimation import StreamingEstimator
from pneumatic_unload.estimation.buffer import ReadingLog


def test_readings_keep_order_drop_repeats_and_stay_bounded():
    log = ReadingLog(capacity=5)
    log.add(np.array([1.0, 2.0, 2.0, 1.5, 3.0]), np.array([10.0, 20.0, 21.0, 15.0, 30.0]))
    log.add(np.array([np.nan, 4.0]), np.array([1.0, np.inf]))  # not finite: dropped
    assert log.t.tolist() == [1.0, 2.0, 3.0] and log.v.tolist() == [10.0, 20.0, 30.0]
    log.add(np.arange(4.0, 10.0), np.arange(4.0, 10.0))
    assert log.t.tolist() == [5.0, 6.0, 7.0, 8.0, 9.0]  # the newest 5
    t, v = log.between(6.0, 8.0)
    assert t.tolist() == [6.0, 7.0, 8.0] and v.tolist() == [6.0, 7.0, 8.0]
    t[0] = -1.0  # a copy: the log is not changed through it
    assert log.t[1] == 6.0


def test_the_estimator_takes_readings_one_by_one_or_in_blocks():
    est = StreamingEstimator()
    est.push_temperature(1.0, 300.0)
    est.push_temperature([2.0, 3.0], [299.0, 298.0])
    assert est.temperature.between(0.0, 10.0)[1].tolist() == [300.0, 299.0, 298.0]
