# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The independent discharge model's flow laws (``test/foreign/newton_tank.py``) checked
against closed forms: the generator of the foreign-law bench (``bench/bench_foreign_laws.py``)
must itself be right before the package is judged on it. Nothing here runs the package.

Every law's choked phase against the closed forms of a tank emptying through a choked
restriction (adiabatic: p = p10 (1 + (g-1) k t / (2g))^(-2g/(g-1)); isothermal:
p = p10 exp(-k t)); the nozzle's flow function at and about its critical ratio; the series
against one restriction when the other is huge, and against the exact series law of two
elliptic b = 0 elements (1/C^2 = 1/C1^2 + 1/C2^2, phi = sqrt(1 - r^2)).
"""

import math

import numpy as np
import pytest
from foreign.newton_tank import (
    FIT_GRID,
    RHO_REF,
    T_REF,
    IsoLaw,
    Nozzle,
    Series,
    discharge,
    iso_phi,
    truth,
)

R_GAS, GAMMA, P_ATM, T10, P10, V = 287.05, 1.4, 101325.0, 293.15, 8e5, 3e-3

LAWS = {
    "iso m 0.25": IsoLaw(5e-9, 0.3, 0.25),
    "iso m 0.75": IsoLaw(8e-9, 0.55, 0.75),
    "nozzle": Nozzle(math.pi * 2e-3 ** 2 / 4, 0.8),
    "series, downstream chokes": Series(IsoLaw(1e-8, 0.3, 0.5), IsoLaw(1e-8, 0.3, 0.5)),
    "series, upstream chokes": Series(IsoLaw(6e-9, 0.45, 0.5), IsoLaw(1.5e-8, 0.2, 0.5)),
}


def _run(law, tau_heat: float, t_end: float, step: float = 1e-3) -> tuple[np.ndarray, ...]:
    t = np.arange(0.0, t_end, step)
    return t, discharge(t, volume=V, p10=P10, t10=T10, p_atm=P_ATM, tau_heat=tau_heat,
                        t_open=0.0, flow_law=law)


def _k_adiabatic(c: float) -> float:
    """k [1/s] of the adiabatic choked discharge: dp/dt = -k p (p/p10)^((g-1)/(2g))."""
    return GAMMA * R_GAS * c * RHO_REF * math.sqrt(T_REF * T10) / V


@pytest.mark.parametrize("name", LAWS)
def test_choked_phase_matches_the_adiabatic_closed_form(name):
    """No heat exchange (tau_h 1e9 s): the isentropic choked discharge, with the law's
    equivalent C, to 1e-7 of p over the whole choked phase, and the initial slope
    -g R T10 q0 / V."""
    law = LAWS[name]
    tr = truth(law)
    k = _k_adiabatic(tr.conductance)
    t, p = _run(law, 1e9, 2.0 / k)
    s = 1.0 + (GAMMA - 1.0) * k * t / (2.0 * GAMMA)
    closed = P10 * s ** (-2.0 * GAMMA / (GAMMA - 1.0))
    choked = P_ATM / p < tr.critical_ratio * 0.999
    assert choked.sum() > 100
    assert np.max(np.abs(p[choked] / closed[choked] - 1.0)) < 1e-7
    # the first instants: dp/dt = -g R T10 q0 / V, q0 = C rho_N p10 sqrt(T_N/T10)
    h = 1e-5
    _, p_start = _run(law, 1e9, 3 * h, h)
    q0 = tr.conductance * RHO_REF * P10 * math.sqrt(T_REF / T10)
    slope = (-3.0 * p_start[0] + 4.0 * p_start[1] - p_start[2]) / (2.0 * h)
    assert slope == pytest.approx(-GAMMA * R_GAS * T10 * q0 / V, rel=1e-5)


@pytest.mark.parametrize("name", ["iso m 0.25", "nozzle", "series, upstream chokes"])
def test_choked_phase_matches_the_isothermal_closed_form(name):
    """A wall exchange far faster than the discharge (tau_h 1e-4 s): p = p10 exp(-k t),
    k = R T10 C rho_N sqrt(T_N/T10) / V, to 1e-4."""
    law = LAWS[name]
    tr = truth(law)
    k = R_GAS * T10 * tr.conductance * RHO_REF * math.sqrt(T_REF / T10) / V
    t, p = _run(law, 1e-4, 1.5 / k)
    choked = P_ATM / p < tr.critical_ratio * 0.999
    assert choked.sum() > 100
    assert np.max(np.abs(p[choked] / (P10 * np.exp(-k * t[choked])) - 1.0)) < 1e-4


def test_default_law_is_the_iso_law_with_m_one_half():
    """``conductance``, ``b`` (m 0.5 by default) and ``flow_law=IsoLaw(C, b)`` make the same
    record, bit for bit; another m keeps the choked phase and changes the tail."""
    t = np.arange(0.0, 20.0, 1e-3)
    kw = dict(volume=V, p10=P10, t10=T10, p_atm=P_ATM, tau_heat=10.0, t_open=0.2)
    a = discharge(t, conductance=5e-9, b=0.4, **kw)
    assert np.array_equal(a, discharge(t, flow_law=IsoLaw(5e-9, 0.4), **kw))
    assert np.array_equal(a, discharge(t, conductance=5e-9, b=0.4, subsonic_index=0.5, **kw))
    c = discharge(t, conductance=5e-9, b=0.4, subsonic_index=0.75, **kw)
    choked = P_ATM / a < 0.4
    # (the same to the solver's tolerance: its steps differ near the end of choking)
    assert np.max(np.abs(c[choked] / a[choked] - 1.0)) < 1e-8
    assert np.max(np.abs(a - c)) > 1e3  # Pa: the tail differs
    with pytest.raises(ValueError):
        discharge(t, conductance=5e-9, b=0.4, flow_law=IsoLaw(5e-9, 0.4), **kw)


@pytest.mark.parametrize("m", [0.25, 0.35, 0.62, 0.75])
def test_iso_phi_is_continuous_and_falls(m):
    b = 0.3
    assert iso_phi(b + 1e-12, b, m) == pytest.approx(1.0, abs=1e-9)
    assert iso_phi(0.999 - 1e-13, b, m) == pytest.approx(iso_phi(0.999, b, m), rel=1e-6)
    phi = np.array([iso_phi(float(r), b, m) for r in FIT_GRID])
    assert np.all(np.diff(phi) <= 0.0) and iso_phi(1.0, b, m) == 0.0


def test_nozzle_phi_and_conductance():
    """phi(r*) = 1 at r* = 0.5283, continuous there and at the linear end, falling above;
    the ISO C reproduces the textbook choked flow Cd A p1 sqrt(g/(R T1)) (2/(g+1))^((g+1)/
    (2(g-1))) at any T1; the best ISO fit is b = r*, m ~ 0.5."""
    n = LAWS["nozzle"]
    rc = n.critical_ratio
    assert rc == pytest.approx(0.52828, abs=1e-5)
    assert n.phi(rc) == 1.0 and n.phi(0.1) == 1.0
    assert n.phi(rc + 1e-9) == pytest.approx(1.0, abs=1e-12)
    assert n.phi(0.999 - 1e-13) == pytest.approx(n.phi(0.999), rel=1e-6)
    phi = np.array([n.phi(float(r)) for r in FIT_GRID[FIT_GRID > rc]])
    assert np.all(np.diff(phi) < 0.0)
    for t1 in (250.0, 293.15, 330.0):
        textbook = n.cd * n.area * P10 * math.sqrt(GAMMA / (R_GAS * t1)) * \
            (2.0 / (GAMMA + 1.0)) ** ((GAMMA + 1.0) / (2.0 * (GAMMA - 1.0)))
        iso = n.conductance * RHO_REF * P10 * math.sqrt(T_REF / t1)
        assert iso == pytest.approx(textbook, rel=1e-12)
    tr = truth(n)
    assert tr.critical_ratio == rc and abs(tr.subsonic_index - 0.5) < 0.01 and tr.rms < 1e-3
    assert abs(tr.fit_b - rc) < 0.01 and abs(tr.fit_m - 0.5) < 0.01


@pytest.mark.parametrize("huge_first", [False, True])
def test_series_reduces_to_one_restriction_when_the_other_is_huge(huge_first):
    """The other restriction 1e4 times larger: the pair's C, b, phi and record are the
    single restriction's (C and phi to 1e-5, b to 1e-4, p to 1 Pa)."""
    one = IsoLaw(5e-9, 0.35, 0.62)
    huge = IsoLaw(5e-5, 0.3, 0.5)
    pair = Series(huge, one) if huge_first else Series(one, huge)
    assert pair.conductance == pytest.approx(one.conductance, rel=1e-5)
    assert pair.critical_ratio == pytest.approx(one.b, abs=1e-4)
    for r in FIT_GRID[::10]:
        assert pair.phi(float(r)) == pytest.approx(one.phi(float(r)), abs=1e-5)
    t = np.arange(0.0, 20.0, 1e-3)
    kw = dict(volume=V, p10=P10, t10=T10, p_atm=P_ATM, tau_heat=10.0, t_open=0.2)
    assert np.max(np.abs(discharge(t, flow_law=pair, **kw)
                         - discharge(t, flow_law=one, **kw))) < 1.0


def test_series_of_two_elliptic_b0_elements_is_the_closed_form():
    """Two b = 0, m = 0.5 elements: p1^2 - pi^2 = (q/C1)^2 and pi^2 - p2^2 = (q/C2)^2 add
    to q = C p1 sqrt(1 - r^2), 1/C^2 = 1/C1^2 + 1/C2^2 (ISO 6358-3's series formula, exact
    here); below the linear end, phi to 1e-9."""
    pair = Series(IsoLaw(1e-8, 0.0), IsoLaw(1.2e-8, 0.0))
    assert pair.conductance == pytest.approx(pair.conductance_iso6358_3, rel=1e-12)
    for r in np.linspace(0.01, 0.99, 50):
        assert pair.phi(float(r)) == pytest.approx(math.sqrt(1.0 - r * r), abs=1e-9)
    tr = truth(pair)
    assert tr.critical_ratio == 0.0 and abs(tr.subsonic_index - 0.5) < 1e-3


@pytest.mark.parametrize("name", ["series, downstream chokes", "series, upstream chokes"])
def test_series_chokes_up_to_its_critical_ratio(name):
    """phi = 1 up to the closed-form b of the pair and below 1 past it; the pair's C is
    below either element's, and the choked flow passes both (C1 phi1(x0) = C2 x0 phi2)."""
    pair = LAWS[name]
    b = pair.critical_ratio
    assert pair.phi(b - 1e-6) == pytest.approx(1.0, abs=1e-12)
    assert pair.phi(b + 1e-2) < 1.0 - 1e-7
    assert pair.conductance < min(pair.first.conductance, pair.second.conductance) + 1e-24
    x0 = pair.intermediate(0.5 * b)
    assert pair.first.conductance * pair.first.phi(x0) == pytest.approx(
        pair.second.conductance * x0 * pair.second.phi(0.5 * b / x0), rel=1e-12)
    assert pair.first.conductance * pair.first.phi(x0) == pytest.approx(pair.conductance,
                                                                        rel=1e-12)
