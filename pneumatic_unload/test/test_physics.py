# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Closed forms of the paper and the flow law against reference values."""

import math

import numpy as np
import pytest

import pneumatic_unload.model.kernel as kernel
from pneumatic_unload import physics as ph
from pneumatic_unload.config import ConfigError, RigConfig
from pneumatic_unload.model import discharge, heat_flow_function


def test_p_star_paper_fig4():
    assert ph.p_star(7e5, 1e5) / 1e5 == pytest.approx(3.208, abs=5e-4)


@pytest.mark.parametrize(("p10", "expected"), [(7e5, 1.040), (6e5, 1.057)])
def test_eq39_bias_table_of_method_md(p10, expected):
    assert ph.eq39_bias_isentropic(p10, 101325.0) == pytest.approx(expected, abs=1e-3)


def test_eq39_bias_grows_at_low_pressure():
    assert ph.eq39_bias_isentropic(4e5, 101325.0) == pytest.approx(1.12, abs=5e-3)


def test_eq39_inverts_eq38():
    tau = ph.tau_exp_eq38(7e5, 1e5, 5e-3, 3e-9, 300.0)
    assert ph.conductance_eq39(tau, 7e5, 1e5, 5e-3, 300.0) == pytest.approx(3e-9, rel=1e-12,
                                                                            abs=0.0)
    assert tau == pytest.approx(6 / 7 * ph.tau0(5e-3, 3e-9, 300.0), rel=1e-12)


def test_flow_function_shape():
    b, m = 0.4, 0.5
    r = np.array([0.0, 0.4, 0.7, 1.0])
    phi = ph.flow_function(r, b, m)
    assert phi[0] == 1.0 and phi[1] == 1.0
    assert phi[2] == pytest.approx(math.sqrt(1 - (0.3 / 0.6) ** 2))
    assert phi[3] == 0.0
    # continuity at the start of the linear end region
    e = 1e-9
    lo, hi = ph.flow_function([ph.R_LINEAR - e, ph.R_LINEAR + e], b, m)
    assert lo == pytest.approx(hi, rel=1e-5)
    # the compiled scalar twin the right-hand side uses is the same function
    for x in (0.1, 0.3, 0.5, 0.9, 0.9995, 1.001, 1.2):
        for bb, mm in ((b, m), (0.0, 0.5), (0.52, 0.7)):
            assert kernel.flow_phi(x, bb, mm, ph.R_LINEAR) == pytest.approx(
                float(ph.flow_function(x, bb, mm)), rel=1e-14, abs=1e-15)


def test_flow_function_with_another_ellipse_exponent():
    """phi = (1 - x^q)^m: the closed form at q 3, the ISO law bit for bit at q 2, the
    linear end continuous, the compiled twin the same function."""
    b, m, q = 0.3, 0.4, 3.0
    x = (0.65 - b) / (1 - b)
    assert float(ph.flow_function(0.65, b, m, ellipse_exponent=q)) == pytest.approx(
        (1 - x**3) ** m, rel=1e-14)
    r = np.linspace(0.0, 1.1, 57)
    assert np.array_equal(ph.flow_function(r, b, m, ellipse_exponent=2.0),
                          ph.flow_function(r, b, m))
    e = 1e-9
    lo, hi = ph.flow_function([ph.R_LINEAR - e, ph.R_LINEAR + e], b, m, ellipse_exponent=q)
    assert lo == pytest.approx(hi, rel=1e-5)
    for xx in (0.1, 0.5, 0.9, 0.9995, 1.001):
        for qq in (1.3, 2.0, 3.7):
            assert kernel.flow_phi(xx, b, m, ph.R_LINEAR, q=qq) == pytest.approx(
                float(ph.flow_function(xx, b, m, ellipse_exponent=qq)), rel=1e-14, abs=1e-15)
    # a larger q: a flow closer to choked just above b (the curve's knee sharper)
    assert ph.flow_function(0.5, b, m, ellipse_exponent=3.0) > ph.flow_function(0.5, b, m)


def test_simulated_isentropic_discharge_matches_closed_form():
    cfg = RigConfig(volume=2e-3, conductance=5e-9, critical_ratio=0.5, pre_time=0.0,
                    initial_temperature=300.0, noise_std=0.0)
    t = np.linspace(0.0, 2.0, 2001)
    p, temp = discharge(cfg, t, 0.0, rtol=1e-11)
    pc = ph.isentropic_choked_pressure(t, cfg.initial_pressure, cfg.volume, cfg.conductance,
                                       cfg.initial_temperature)
    choked = p > cfg.atmosphere / cfg.critical_ratio
    assert choked.sum() > 500
    assert np.max(np.abs(p[choked] / pc[choked] - 1.0)) < 1e-6
    tc = ph.isentropic_choked_temperature(p[choked], cfg.initial_pressure, 300.0)
    assert np.max(np.abs(temp[choked] / tc - 1.0)) < 1e-6


def test_isentropic_inversion_is_exact_for_adiabatic_model():
    cfg = RigConfig(volume=2e-3, conductance=5e-9, critical_ratio=0.5, pre_time=0.0,
                    noise_std=0.0)
    ps = ph.p_star(cfg.initial_pressure, cfg.atmosphere)
    t_cross = ph.isentropic_crossing_time(ps, cfg.initial_pressure, cfg.volume, 5e-9)
    p, _ = discharge(cfg, np.array([0.0, t_cross]), 0.0, rtol=1e-11)
    assert p[1] == pytest.approx(ps, rel=1e-7)
    c = ph.conductance_isentropic_inversion(t_cross, ps, cfg.initial_pressure, cfg.volume)
    assert c == pytest.approx(5e-9, rel=1e-9, abs=0.0)


def test_sse_eq23_with_recovered_pressure():
    # state at the closing instant of an isentropic choked unload, then isochoric
    # re-heating to T10: the printed exponent (gamma-1)/2 of eq 23 is the right one
    t10, p10, vol, c = 293.15, 7e5, 3e-3, 4e-9
    t_star = 0.8
    p_close = ph.isentropic_choked_pressure(t_star, p10, vol, c, t10, paper_form=True)
    t_close = ph.isentropic_choked_temperature(p_close, p10, t10)
    p_inf = float(p_close * t10 / t_close)
    assert ph.conductance_sse(t_star, p10, p_inf, vol, t10) == pytest.approx(c, rel=1e-9, abs=0.0)


def test_natural_convection_typical_range():
    """The natural law of model.heat gives h of a few W/(m^2 K) in a 5 L tank."""
    cfg = RigConfig(volume=5e-3, effects=("heat_transfer",))
    _l, _d, area = ph.tank_geometry(5e-3, 2.0)
    h = heat_flow_function(cfg)(5e5, 260.0) / (293.15 - 260.0) / area
    assert 3.0 < h < 20.0


def test_orifice_rule_of_thumb():
    assert ph.orifice_conductance(2e-3) == pytest.approx(0.512e-8)


def test_config_rejects_out_of_range_and_unknown_effect():
    with pytest.raises(ConfigError, match="volume"):
        RigConfig(volume=-1.0)
    with pytest.raises(ConfigError, match="unknown effect"):
        RigConfig(effects=("warp_drive",))
    cfg = RigConfig.from_dict(RigConfig(effects=("leak",)).to_dict())
    assert cfg.effects == ("leak",)
