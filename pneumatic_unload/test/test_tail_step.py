# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A step at the end of a record, after its tail had settled, is not the discharge
(:mod:`pneumatic_unload.estimation.endstep`).

The AeroLab rig's runs sit level at +0.5 kPa gauge for 10 s, then step to -2.4 kPa within
2 s. Fitted with the rest, the 0.094 in run's step read as a zero offset of -3861 +- 622 Pa
(main 968cd85: the whole law family fitted with the offset), C 8.18e-9 with m held at 0.5,
and its discharge coefficient 2.1 combined sigma from the 0.125 in run's. The tail now ends
before the step: no offset, m 0.298, C 8.35e-9.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge
from hypothesis import given, settings
from hypothesis import strategies as st
from realdata import aerolab_json

from pneumatic_unload.estimation.endstep import STEP_BACK, settled_step

P_ATM = 101325.0


def _tail(rate: float, tau: float, noise: float, seed: int, quantum: float = 0.0,
          n: int = 300) -> np.ndarray:
    """The last n samples (at most) of a foreign discharge's tail after its p* crossing,
    the part of a record the step is looked for in, at ``rate`` [Hz] (time scale tau [s],
    m 0.3), with Gaussian ``noise`` [Pa] and a reading quantised to ``quantum`` [Pa]."""
    c, v = 5e-9, 5e-9 * 1.4e5 * tau
    t = np.arange(0.0, 1.0 + 6.0 * tau, 1.0 / rate)
    p = discharge(t, volume=v, p10=7e5, t10=293.15, p_atm=P_ATM, tau_heat=10.0, t_open=1.0,
                  flow_law=IsoLaw(c, 0.3, 0.3))
    tail = p < P_ATM + math.exp(-1.0) * (7e5 - P_ATM)
    p = p + np.random.default_rng(seed).normal(0.0, noise, t.size)
    if quantum > 0.0:
        p = np.round(p / quantum) * quantum
    return p[tail][-n:]


@settings(max_examples=60, deadline=None)
@given(rate=st.sampled_from([1.0, 2.0, 10.0, 100.0, 1000.0]),
       tau=st.floats(2.0, 120.0), noise=st.sampled_from([0.0, 10.0, 100.0, 700.0]),
       quantum=st.sampled_from([0.0, 10.0, 100.0]), seed=st.integers(0, 2**32 - 1))
def test_a_discharge_tail_never_steps(rate, tau, noise, quantum, seed):
    """No step in a discharge's tail, at any rate, time scale, noise or quantisation: the
    last STEP_BACK samples, and every shorter end of them (a stream cut anywhere)."""
    y = _tail(rate, tau, noise, seed, quantum)
    for end in range(y.size, y.size - STEP_BACK, -7):
        assert settled_step(y[:end]) is None, end


@pytest.mark.parametrize("rate,noise,step,after", [
    (1.0, 30.0, -2900.0, 8), (1.0, 30.0, -2900.0, 3), (10.0, 100.0, 4000.0, 40),
    (1000.0, 700.0, -20000.0, 100)])
def test_a_step_after_the_level_is_found_where_it_begins(rate, noise, step, after):
    """A level of the settled tail, then a step of 20 and more noise deviations within 2
    samples: found, at the level's last sample, with its size."""
    y = _tail(rate, 20.0, noise, 3)
    tail = np.full(12 + after, P_ATM) + np.random.default_rng(4).normal(
        0.0, noise, 12 + after)
    tail[12] += 0.3 * step
    tail[13:] += step
    got = settled_step(np.concatenate([y, tail]))
    assert got is not None
    assert got[0] == y.size + 11
    assert got[1] == pytest.approx(step, abs=0.05 * abs(step) + 3.0 * noise)


def test_too_few_samples_on_either_side_are_not_a_step():
    """Four level samples before it, or one after it, are not enough (a glitch)."""
    level = P_ATM + np.array([0.0, 20.0, -10.0, 10.0])
    assert settled_step(np.concatenate([level, [P_ATM - 3000.0] * 6])) is None
    ok = np.concatenate([[P_ATM + 5.0], level, [P_ATM - 3000.0] * 3])
    assert settled_step(ok) is not None
    assert settled_step(np.concatenate([[P_ATM] * 20, [P_ATM - 3000.0]])) is None


def _aerolab(name: str) -> dict:
    (u,) = [x for x in aerolab_json(name)["unloads"] if x["final"]]
    return u


@pytest.mark.parametrize("name,t_step", [("orifice_0.125in.csv", 151.0)])
def test_real_aerolab_tail_ends_before_its_step(name, t_step):
    """The tail ends on the +0.5 kPa level, the step said (-2.9 kPa), no zero offset fitted
    from it. (The 0.094 in run begins after its opening: analysed from ``--start-time``,
    its unload ends where the record settles, and no offset is fitted:
    test_cli.py's real-data tests.)"""
    u = _aerolab(name)
    assert u["t_end"] == pytest.approx(t_step - 1.0)
    assert "steps by -29" in u["status_text"] and f"t={t_step:.6f} s" in u["status_text"]
    assert u["pressure_offset"] is None or not math.isfinite(u["pressure_offset"])
    assert u["offset_source"].startswith("not fitted"), u["offset_source"]
