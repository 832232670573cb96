"""Bad input gets a typed, specific status or diagnostic: never a crash or a wrong number."""

import dataclasses
import math

import numpy as np
import pytest

from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import STATUSES, StreamingEstimator, analyze
from pneumatic_unload.model import simulate
from pneumatic_unload.physics import orifice_conductance
from pneumatic_unload.runs import settings_for

FS_NOISE = 1000.0  # 0.1 % of a 1 MPa full-scale transducer [Pa]


def _rig(**kw):
    base = {"volume": 1e-3, "conductance": orifice_conductance(2e-3), "noise_std": FS_NOISE,
            "seed": 21, "duration": 2.0}
    base.update(kw)
    cfg = RigConfig(**base)
    st = dataclasses.replace(settings_for(cfg), heat_model="adiabatic", curve_fit=False)
    return cfg, simulate(cfg), st


def _run(t, p, st):
    est = StreamingEstimator(st)
    res = est.push_block(t, p) + est.finish()
    return res, " | ".join(d.message for d in est.diagnostics)


def test_statuses_order_is_the_message_constants():
    assert STATUSES[:5] == ("ok", "aborted_sse", "aborted", "not_choked", "bad_data")


def test_inf_values_and_nan_stamps_are_skipped_with_a_diagnostic():
    _cfg, sim, st = _rig()
    clean = analyze(sim.t, sim.measured, st)[0]
    t, p = sim.t.copy(), sim.measured.copy()
    p[100], p[400] = np.inf, -np.inf
    t[120] = np.nan
    res, msgs = _run(t, p, st)
    assert "non-finite pressure" in msgs and "NaN stamp" in msgs
    assert res[0].status == "ok"
    assert res[0].tau_exp == pytest.approx(clean.tau_exp, rel=1e-3)


def test_gap_during_the_unload_is_flagged_and_lowers_quality():
    _cfg, sim, st = _rig()
    keep = np.ones(sim.t.size, bool)
    i0 = int(np.searchsorted(sim.t, sim.t_open + 0.1))
    keep[i0:i0 + 50] = False  # 50 ms of samples lost while the pressure falls
    res, msgs = _run(sim.t[keep], sim.measured[keep], st)
    assert "gap of 0.05" in msgs
    assert res[0].status == "ok" and "gap" in res[0].status_text
    assert res[0].quality <= 0.5


def test_start_never_choked_is_not_choked():
    # p10 = 1.6 bar abs < p_atm / b = 2.03 bar: the flow is subsonic from the start
    _cfg, sim, st = _rig(initial_pressure=1.6e5, critical_ratio=0.5)
    st = dataclasses.replace(st, critical_ratio=0.5)
    res, _ = _run(sim.t, sim.measured, st)
    assert len(res) == 1 and res[0].status == "not_choked"
    assert "subsonic" in res[0].status_text
    assert res[0].quality < 1.0


def test_stuck_sensor_constant_signal():
    t = np.arange(20_000) * 1e-3
    p = np.full(t.size, 5.5e5)
    res, msgs = _run(t, p, _rig()[2])
    assert res == []
    assert "sensor stuck" in msgs


def test_sensor_freezing_during_the_unload_is_bad_data():
    _cfg, sim, st = _rig(duration=3.0)
    p = sim.measured.copy()
    i0 = int(np.searchsorted(sim.t, sim.t_open + 0.2))
    p[i0:] = p[i0]  # the transducer output freezes while the tank is still discharging
    res, _ = _run(sim.t, p, st)
    assert len(res) == 1 and res[0].status == "bad_data"
    assert "stuck" in res[0].status_text
    assert not math.isfinite(res[0].conductance)


def test_saturated_sensor_plateau_is_bad_data():
    _cfg, sim, st = _rig(full_scale=6.5e5)
    res, _ = _run(sim.t, sim.measured, st)
    assert res and res[0].status == "bad_data" and "saturated" in res[0].status_text
