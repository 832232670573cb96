# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The compiled model kernel: its integrator against an independent one, its build rules."""

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pneumatic_unload.model.kernel as kernel
from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import integrate, right_hand_side, valve_events
from pneumatic_unload.model.ode import kernel_parameters

CASES = {
    "adiabatic": RigConfig(volume=2e-3, conductance=5e-9, pre_time=0.2),
    "heat, natural": RigConfig(volume=5e-3, conductance=8e-9, effects=("heat_transfer",),
                               pre_time=0.2, heat_transfer_scale=3.0),
    "heat fixed, leak, ramp": RigConfig(
        volume=1e-3, conductance=3e-9, effects=("heat_transfer", "leak", "valve_opening"),
        heat_transfer_mode="fixed", heat_transfer_coefficient=0.5, leak_coefficient=2e-11,
        valve_opening_time=0.02, pre_time=0.2),
    "heat density": RigConfig(volume=3e-3, conductance=6e-9, effects=("heat_transfer",),
                              heat_transfer_mode="density", heat_transfer_coefficient=0.4,
                              heat_transfer_exponent=0.7, pre_time=0.2),
    "heat natural, turbulent branch": RigConfig(
        volume=20e-3, conductance=2e-8, effects=("heat_transfer",), pre_time=0.2,
        heat_transfer_turbulent_ratio=1.3),
    "pipe, closing": RigConfig(volume=2e-3, conductance=6e-9, effects=("pipe_volume",),
                               pipe_volume=2e-4, pipe_conductance=1.2e-8, pre_time=0.2,
                               valve_close_time=1.0),
}


@pytest.mark.parametrize("name", list(CASES))
def test_integrator_agrees_with_scipy_dop853(name):
    """Against scipy's 8th-order DOP853 at tight tolerance, segment by segment."""
    cfg = CASES[name]
    t_open = 0.2
    t = np.linspace(0.0, 3.0, 1201)
    ours = integrate(cfg, t, t_open, rtol=1e-10)
    default = integrate(cfg, t, t_open)
    f = right_hand_side(cfg, t_open)
    y = ours[0]
    ref = [ours[0]]
    cuts = [0.0, *[e for e in valve_events(cfg, t_open) if 0 < e < 3.0], 3.0]
    for a, b in itertools.pairwise(cuts):
        sel = t[(t > a) & (t <= b)]
        sol = solve_ivp(f, (a, b), y, method="DOP853", rtol=1e-13, atol=1e-9 * np.abs(y),
                        t_eval=np.concatenate((sel, [b])) if sel[-1] != b else sel,
                        dense_output=True)
        ref += list(sol.sol(sel).T)
        y = sol.sol(b)
    ref = np.asarray(ref)
    # converges to the reference as the tolerance tightens; the global error at the
    # default tolerance (1e-8, local) stays below 1e-6 relative (0.7 Pa at 7 bar)
    rel = np.max(np.abs(ours - ref) / np.abs(ref), axis=0)
    assert rel.max() < 1e-7, rel
    assert np.max(np.abs(default - ref) / np.abs(ref)) < 1e-6


def test_dense_output_equals_the_steps():
    """Outputs on a dense grid and on a sparse one agree at the common instants."""
    cfg = CASES["heat, natural"]
    dense = np.linspace(0.0, 3.0, 30_001)
    sparse = dense[::1000]
    a = integrate(cfg, dense, 0.2)[::1000]
    b = integrate(cfg, sparse, 0.2)
    assert np.max(np.abs(a - b) / b) < 1e-8


def test_step_budget_and_bad_arrays_are_reported():
    cfg = CASES["adiabatic"]
    prm = kernel_parameters(cfg, 0.0)
    y0 = np.array([cfg.initial_pressure, cfg.initial_temperature])
    t_out = np.linspace(0.0, 2.0, 11)
    out = np.empty((11, 2))
    status, done = kernel.dopri5(y0, 0.0, 2.0, t_out, prm, 1e-10, y0 * 1e-12, 0.0, 3, out)
    assert status == kernel.TOO_MANY_STEPS and 1 <= done < 11
    with pytest.raises(ValueError, match="inconsistent"):
        kernel.dopri5(y0, 0.0, 2.0, t_out, prm, 1e-8, y0, 0.0, 100, np.empty((10, 2)))


def test_library_name_follows_the_source(tmp_path, monkeypatch):
    """An edited kernel.c gets a new library: a stale build is never loaded."""
    src = tmp_path / "kernel.c"
    src.write_text(kernel.SOURCE.read_text())
    monkeypatch.setattr(kernel, "SOURCE", src)
    first = kernel.library_name()
    src.write_text(kernel.SOURCE.read_text() + "\n/* edited */\n")
    assert kernel.library_name() != first
    built = kernel.build(tmp_path / "lib")
    assert built.name == kernel.library_name() and built.exists()
    assert kernel.build(tmp_path / "lib") == built  # second call: nothing to do


def test_missing_compiler_is_one_clear_error(tmp_path, monkeypatch):
    src = tmp_path / "kernel.c"
    src.write_text(kernel.SOURCE.read_text() + "\n/* not built yet */\n")
    monkeypatch.setattr(kernel, "SOURCE", src)
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path))  # neither cc nor gcc on it
    with pytest.raises(kernel.KernelBuildError, match="no C compiler"):
        kernel.build(tmp_path / "lib")
    assert not list(Path(tmp_path).glob("lib/*.so"))


# ------------------------------------------------------------------- leaks (issue 12)
def _phi(r, b, m=0.5, r_lin=0.999):
    """ISO 6358 phi(r), written here independently of the kernel (r_lin: linear end)."""
    from pneumatic_unload.physics import R_LINEAR

    r_lin = R_LINEAR
    if r <= b:
        return 1.0
    if r > r_lin:
        xl = (r_lin - b) / (1 - b)
        return (1 - xl * xl) ** m * (1 - r) / (1 - r_lin)
    x = (r - b) / (1 - b)
    return (1 - x * x) ** m


def _reference_rhs(cfg, t_open):
    """The tank balance with every leak, in plain Python from the formulae of issue 12:
    upstream leaks always flow, downstream ones flow with the valve, times its opening."""
    from pneumatic_unload.physics import RHO_N, T_N

    g = cfg.gas
    p_atm, vol, ramp = cfg.atmosphere, cfg.volume, cfg.valve_opening_time
    on = cfg.has

    def f(t, y):
        p, temp = y
        a = 0.0 if t < t_open else min(1.0, (t - t_open) / ramp) if on("valve_opening") \
            else 1.0
        rho = RHO_N * p * np.sqrt(T_N / temp)
        valve = cfg.conductance * rho * _phi(p_atm / p, cfg.critical_ratio,
                                             cfg.subsonic_index)
        if on("leak_downstream"):
            valve += cfg.leak_downstream_coefficient * (p - p_atm)
        if on("orifice_leak_downstream"):
            valve += cfg.orifice_leak_downstream_conductance * rho * _phi(
                p_atm / p, cfg.orifice_leak_downstream_critical_ratio)
        out = a * valve
        if on("leak"):
            out += cfg.leak_coefficient * (p - p_atm)
        if on("orifice_leak"):
            out += cfg.orifice_leak_conductance * rho * _phi(
                p_atm / p, cfg.orifice_leak_critical_ratio)
        # adiabatic: d(m cv T) = -G cp T dt, p = m R T / V
        dp = -(g.gamma - 1.0) / vol * out * g.cp * temp
        dtemp = temp / p * dp + g.gas_constant * temp * temp / (p * vol) * out
        return [dp, dtemp]

    return f


LEAK_CASES = {
    "downstream orifice leak": dict(effects=("orifice_leak_downstream",),
                                    orifice_leak_downstream_conductance=2e-9,
                                    orifice_leak_downstream_critical_ratio=0.25),
    "downstream laminar leak, ramp": dict(effects=("leak_downstream", "valve_opening"),
                                          leak_downstream_coefficient=3e-10,
                                          valve_opening_time=0.05),
    "upstream orifice + laminar leaks": dict(effects=("orifice_leak", "leak"),
                                             orifice_leak_conductance=8e-10,
                                             orifice_leak_critical_ratio=0.45,
                                             leak_coefficient=5e-11),
}


@pytest.mark.parametrize("name", list(LEAK_CASES))
def test_leaks_agree_with_an_independent_reference(name):
    """Each leak in the compiled RHS against the balance written out in the test and
    solved by scipy's DOP853, segment by segment between the valve events."""
    cfg = RigConfig(volume=2e-3, conductance=5e-9, critical_ratio=0.4, pre_time=0.2,
                    **LEAK_CASES[name])
    t_open = 0.2
    t = np.linspace(0.0, 2.5, 501)
    ours = integrate(cfg, t, t_open, rtol=1e-10)
    f = _reference_rhs(cfg, t_open)
    y = np.array([cfg.initial_pressure, cfg.initial_temperature])
    ref = [y]
    cuts = [0.0, *[e for e in valve_events(cfg, t_open) if 0 < e < 2.5], 2.5]
    for a, b in itertools.pairwise(cuts):
        sel = t[(t > a) & (t <= b)]
        sol = solve_ivp(f, (a, b), y, method="DOP853", rtol=1e-13, atol=1e-10 * y,
                        dense_output=True)
        ref += list(sol.sol(sel).T)
        y = sol.sol(b)
    ref = np.asarray(ref)
    assert np.max(np.abs(ours - ref) / ref) < 1e-7
    # the leak changes the discharge (the reference is not just the leak-free model)
    plain = integrate(cfg.replace(effects=tuple(e for e in cfg.effects
                                                if e == "valve_opening")), t, t_open)
    assert np.max(np.abs(plain[:, 0] - ours[:, 0])) > 5e3
    # where it sits: an upstream leak drains the plateau, a downstream one does not
    pre = t < t_open
    upstream = any(e in cfg.effects for e in ("leak", "orifice_leak"))
    assert (ours[pre, 0][-1] < cfg.initial_pressure - 1e3) == upstream


def test_heat_laws_against_their_formulae():
    """The density law hA_0 (rho/rho_0)^n and the natural law's turbulent branch, written
    out here from their definitions (model/heat.py)."""
    from pneumatic_unload.model.heat import RA_TURBULENT, heat_flow_function, rayleigh

    cfg = RigConfig(volume=3e-3, effects=("heat_transfer",), heat_transfer_mode="density",
                    heat_transfer_coefficient=0.4, heat_transfer_exponent=0.7,
                    initial_pressure=7e5, initial_temperature=293.15)
    q = heat_flow_function(cfg)
    rho0 = 7e5 / (cfg.gas.gas_constant * 293.15)
    for p, t in ((7e5, 293.15 - 1e-6), (3e5, 250.0), (1.2e5, 270.0)):
        rho = p / (cfg.gas.gas_constant * t)
        assert q(p, t) == pytest.approx(0.4 * (rho / rho0) ** 0.7 * (293.15 - t), rel=1e-12)
    base = RigConfig(volume=20e-3, effects=("heat_transfer",), initial_pressure=7e5)
    q1 = heat_flow_function(base)
    q13 = heat_flow_function(base.replace(heat_transfer_turbulent_ratio=1.3))
    for p, t in ((7e5, 250.0), (1.1e5, 285.0)):
        ra = float(rayleigh(base, np.array([p]), np.array([t]))[0])
        assert q13(p, t) / q1(p, t) == pytest.approx(1.3 if ra >= RA_TURBULENT else 1.0)
    assert rayleigh(base, np.array([7e5]), np.array([250.0]))[0] >= RA_TURBULENT
    assert rayleigh(base, np.array([1.1e5]), np.array([285.0]))[0] < RA_TURBULENT


#: Pairs in series (upstream (C1, b1, m1), downstream (C2, b2, m2)): the downstream element
#: choking first, the upstream one (C1 <= b1 C2), nearly equal, far apart in m.
SERIES_PAIRS = [((1.3e-8, 0.42, 0.52), (1.2e-8, 0.18, 0.30)),
                ((2e-9, 0.45, 0.40), (9e-9, 0.30, 0.60)),
                ((5e-9, 0.30, 0.50), (5e-9, 0.30, 0.50)),
                ((5.6e-9, 0.49, 0.69), (4.4e-9, 0.14, 0.37))]


@pytest.mark.parametrize("pair", SERIES_PAIRS)
def test_a_pair_in_series_agrees_with_an_independent_one(pair):
    """``pu_series_phi`` (two ISO elements in series, ISO 6358-3's computation) against
    test/foreign's pair, written apart with scipy's brentq: within 1e-10 over r from
    choking to reverse flow; choked exactly 1 below the pair's critical ratio, linear
    above r_l as the ISO law, and a discharge of the simulator through the pair within
    0.5 Pa of the foreign model's (Newton cooling, 10 bar)."""
    from foreign.newton_tank import IsoLaw, Series, discharge

    (c1, b1, m1), (c2, b2, m2) = pair
    law = Series(IsoLaw(c1, b1, m1), IsoLaw(c2, b2, m2))
    r = np.linspace(0.001, 1.02, 800)
    ours = kernel.component_phi(r, b1, m1, 0.999, series=(b2, m2, c2 / c1))
    theirs = np.array([law.phi(float(x)) for x in r])
    assert np.max(np.abs(ours - theirs)) < 1e-10
    assert np.all(ours[r < law.critical_ratio * (1 - 1e-9)] == 1.0)
    assert not np.any(ours[r > law.critical_ratio * (1 + 1e-6)] == 1.0)
    end = kernel.series_phi(0.999, b1, m1, b2, m2, c2 / c1, 0.999)
    assert kernel.series_phi(0.9995, b1, m1, b2, m2, c2 / c1, 0.999) == pytest.approx(
        end / 2, rel=1e-12)
    # the simulator's discharge through the pair (its conductance the pair's)
    volume, p10, tau_h = 2e-3, 1e6, 20.0
    t = np.linspace(0.0, 3.0 * volume / (1.4e5 * law.conductance), 400)
    ref = discharge(t, volume=volume, p10=p10, t10=293.15, p_atm=101325.0, tau_heat=tau_h,
                    t_open=0.0, flow_law=law)
    hA = p10 * volume / 293.15 / 0.4 / tau_h  # m0 c_v / tau_h, c_v = R/(gamma - 1)
    cfg = RigConfig(volume=volume, conductance=law.conductance, critical_ratio=b1,
                    subsonic_index=m1, series_conductance_ratio=c2 / c1,
                    series_critical_ratio=b2, series_subsonic_index=m2,
                    initial_pressure=p10, effects=("heat_transfer",),
                    heat_transfer_mode="fixed", heat_transfer_coefficient=hA,
                    gas_constant=287.05)
    ours_p = integrate(cfg, t, 0.0, rtol=1e-10)[:, 0]
    assert np.max(np.abs(ours_p - ref)) < 0.5
    alone = integrate(cfg.replace(series_conductance_ratio=0.0), t, 0.0, rtol=1e-10)[:, 0]
    assert np.max(np.abs(alone - ref)) > 1e3  # the second element matters
