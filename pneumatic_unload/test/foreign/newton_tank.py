# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""An independent tank-discharge model for validation: it imports nothing from the package.

Ideal gas in a rigid tank, uniform state, wall heat transfer by Newton cooling with a constant
hA (thermal time constant tau_h = m0 c_v / hA) to a wall at a constant temperature (that of
the gas at the start, or another: a gas warm or cool after charging) or, with
``density_exponent`` n, an hA that follows the gas density, hA = hA_0 (rho/rho_0)^n, the
ISO 6358 flow law (choked below the critical ratio b, the elliptic subsonic branch above, a
linear end near r = 1), integrated with scipy's Radau at tight tolerance. Written apart
from ``pneumatic_unload.model`` on purpose: a fit that recovers the parameters of the model
it was written beside proves little. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).

Flow laws (``flow_law``; every one written here, none from the package). The mass flow is
q = C rho_N p1 sqrt(T_N/T1) phi(r), r = p2/p1, with each law's C and phi(r):

* :class:`IsoLaw` (the default, made from ``conductance``, ``b`` and ``subsonic_index``):
  ISO 6358-1:2013, phi = 1 for r <= b, (1 - ((r-b)/(1-b))^2)^m for b < r < r_l = 0.999, and
  linear to 0 at r = 1 from its value at r_l (continued linearly past r = 1: a reverse
  flow, as before). m = 0.5 is the model as it always was (bit for bit).
* :class:`Nozzle`: an isentropic (de Saint-Venant-Wantzel) convergent nozzle of throat area
  A and discharge coefficient Cd: q = Cd A p1 psi(r) / sqrt(R T1), psi = sqrt(2g/(g-1)
  (r^(2/g) - r^((g+1)/g))) above the critical ratio r* = (2/(g+1))^(g/(g-1)) (0.5283 for
  g = 1.4), psi(r*) below. Its ISO C is its choked flow / (rho_N p1 sqrt(T_N/T1)) =
  Cd A psi(r*) / (rho_N sqrt(R T_N)), independent of T1. Its phi has the same linear end
  at r_l = 0.999 as the ISO law (the isentropic phi ~ sqrt(1 - r) has an infinite slope at
  r = 1; the end is 100 Pa wide near 1 bar, a tenth of the bench's noise).
* :class:`Series`: two ISO restrictions in series, solved at every instant for the
  intermediate pressure p_i by mass-flow continuity, C1 phi1(p_i/p1) p1 = C2 phi2(p2/p_i)
  p_i: both elements see the tank's temperature T1 (an ideal gas throttled adiabatically
  keeps its stagnation temperature; the volume between them is taken as nil, so the series
  is quasi-steady, as ISO 6358-3:2014 computes a system). Where both element ratios are
  above 0.999 (every r >= 0.999) each element is in its linear end and so is the series,
  exactly: phi is linear there from its value at 0.999.

:func:`truth` gives each law's (C, b, m) and how well the ISO law fits its phi: exact for
the ISO law; for the nozzle C as above, b = r* (the end of choking), m the least-squares
ISO m with b held at r*; for the series C from the choked flow of the pair, b where the
pair stops being choked (closed forms, :meth:`Series.critical_ratio`), m the least-squares
ISO m with b held there. The least squares are on phi over r uniform on [0.02, 0.999]
(:data:`FIT_GRID`). The free (b, m) least-squares fit is reported beside (``fit_b``,
``fit_m``): the law the record is nearest to if the tail weighted every r alike. Also for
the series, ISO 6358-3's usual closed form for C, 1/C^2 = 1/C1^2 + 1/C2^2 (exact for two
elliptic elements with b1 = 0; an approximation otherwise); the text of ISO 6358-3:2014
itself (a numerical method: the same mass flow through every element of a series, one
stagnation temperature, C from the system's choked flow, b and m fitted to its computed
flow curve) was not available, so C and b here are computed exactly from the pair's flow
and m is fitted, which is that method.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, least_squares

RHO_REF, T_REF = 1.185, 293.15  # ISO 8778 reference density [kg/m^3] and temperature [K]
R_LINEAR = 0.999  # ISO 6358-1:2013: the linear end of the flow law, r_l [-]
END_WIDTH = 0.001  # 1 - r_l, written as the model always had it [-]
#: The pressure ratios on which :func:`truth` fits the ISO law to a law's phi [-].
FIT_GRID = np.linspace(0.02, R_LINEAR, 2000)


def iso_phi(r: float, b: float, m: float = 0.5) -> float:
    """ISO 6358-1:2013's flow function phi(r) [-]: 1 when choked, the subsonic branch with
    index m, linear to 0 at r = 1 from r_l (and on past it: a reverse flow for r > 1)."""
    if r <= b:
        return 1.0
    if r < R_LINEAR:
        x = (r - b) / (1.0 - b)
        y = max(1.0 - x * x, 0.0)
        return math.sqrt(y) if m == 0.5 else y ** m
    x = (R_LINEAR - b) / (1.0 - b)
    y = 1.0 - x * x
    return (math.sqrt(y) if m == 0.5 else y ** m) * (1.0 - r) / END_WIDTH


def iso_phi_inverse(phi: float, b: float, m: float = 0.5) -> float:
    """The ratio r in [b, r_l] at which the ISO subsonic branch equals phi (0 < phi <= 1)."""
    return b + (1.0 - b) * math.sqrt(max(1.0 - phi ** (1.0 / m), 0.0))


@dataclass(frozen=True)
class IsoLaw:
    """ISO 6358-1:2013 law: sonic conductance [m^3/(s Pa)], critical ratio b [-], subsonic
    index m [-]."""

    conductance: float
    b: float
    m: float = 0.5

    def phi(self, r: float) -> float:
        return iso_phi(r, self.b, self.m)


@dataclass(frozen=True)
class Nozzle:
    """An isentropic convergent nozzle: throat area [m^2], discharge coefficient [-], gas
    constant [J/(kg K)] and heat capacity ratio [-]."""

    area: float
    cd: float = 1.0
    r_gas: float = 287.05
    gamma: float = 1.4

    @property
    def critical_ratio(self) -> float:
        g = self.gamma
        return (2.0 / (g + 1.0)) ** (g / (g - 1.0))

    def psi(self, r: float) -> float:
        """sqrt(R T1) q / (Cd A p1) [-], the choked value below the critical ratio."""
        g = self.gamma
        r = max(r, self.critical_ratio)
        return math.sqrt(max(2.0 * g / (g - 1.0) * (r ** (2.0 / g) - r ** ((g + 1.0) / g)),
                             0.0))

    @property
    def conductance(self) -> float:
        """The ISO C of the nozzle [m^3/(s Pa)]: choked flow / (rho_N p1 sqrt(T_N/T1))."""
        return self.cd * self.area * self.psi(0.0) / (RHO_REF * math.sqrt(self.r_gas * T_REF))

    def phi(self, r: float) -> float:
        if r < R_LINEAR:
            return self.psi(r) / self.psi(0.0)
        return self.psi(R_LINEAR) / self.psi(0.0) * (1.0 - r) / END_WIDTH


@dataclass(frozen=True)
class Series:
    """Two ISO restrictions in series, ``first`` upstream (the tank side)."""

    first: IsoLaw
    second: IsoLaw
    _cache: dict = field(default_factory=dict, compare=False, repr=False, init=False)

    def _choked_intermediate(self) -> float:
        """x0 = p_i/p1 when the pair is choked (the downstream element choked, or the
        upstream one when C1 <= b1 C2): C1 phi1(x0) = C2 x0."""
        c1, c2, b1 = self.first.conductance, self.second.conductance, self.first.b
        if c1 <= b1 * c2:
            return c1 / c2
        return brentq(lambda x: c1 * self.first.phi(x) - c2 * x, b1, 1.0, xtol=1e-15,
                      rtol=4.0 * np.finfo(float).eps)

    @property
    def conductance(self) -> float:
        """The pair's C [m^3/(s Pa)], from its choked flow: C1 phi1(x0) (= C2 x0)."""
        if "c" not in self._cache:
            self._cache["c"] = self.first.conductance * self.first.phi(
                self._choked_intermediate())
        return self._cache["c"]

    @property
    def critical_ratio(self) -> float:
        """The largest r at which the pair is choked [-]: b2 x0 when the downstream element
        chokes (C1 > b1 C2); else (the upstream one chokes) the r at which the downstream
        element, fed at b1 p1, passes C1 p1: C2 b1 phi2(r/b1) = C1."""
        c1, c2, b1 = self.first.conductance, self.second.conductance, self.first.b
        if c1 > b1 * c2:
            return self.second.b * self._choked_intermediate()
        return b1 * iso_phi_inverse(c1 / (c2 * b1), self.second.b, self.second.m)

    @property
    def conductance_iso6358_3(self) -> float:
        """ISO 6358-3's usual series formula, 1/C^2 = 1/C1^2 + 1/C2^2 [m^3/(s Pa)]."""
        return 1.0 / math.hypot(1.0 / self.first.conductance, 1.0 / self.second.conductance)

    def intermediate(self, r: float) -> float:
        """p_i/p1 at r = p2/p1 < 1: the root of C1 phi1(x) = C2 x phi2(r/x) on [r, 1] (the
        left side falls with x, the right one rises: one root)."""
        c1, c2 = self.first.conductance, self.second.conductance

        def gap(x: float) -> float:
            return c1 * self.first.phi(x) - c2 * x * self.second.phi(r / x)

        return brentq(gap, r, 1.0, xtol=1e-15, rtol=4.0 * np.finfo(float).eps)

    def phi(self, r: float) -> float:
        if r < R_LINEAR:
            return self.first.conductance * self.first.phi(self.intermediate(r)) \
                / self.conductance
        if "end" not in self._cache:
            self._cache["end"] = self.phi(R_LINEAR - 1e-15)
        return self._cache["end"] * (1.0 - r) / END_WIDTH


FlowLaw = IsoLaw | Nozzle | Series


@dataclass(frozen=True)
class Truth:
    """What a fit of the ISO law to a record of ``law`` should recover (:func:`truth`):
    C [m^3/(s Pa)], b [-] (the end of choking), m [-] (least squares with b held), the free
    (b, m) least-squares fit and the RMS of phi's misfit for each [-]; ``note``: how."""

    conductance: float
    critical_ratio: float
    subsonic_index: float
    rms: float
    fit_b: float
    fit_m: float
    fit_rms: float
    note: str


def _fit_m(law: FlowLaw, b: float) -> tuple[float, float]:
    target = np.array([law.phi(float(r)) for r in FIT_GRID])

    def res(v: np.ndarray) -> np.ndarray:
        return np.array([iso_phi(float(r), b, float(v[0])) for r in FIT_GRID]) - target

    sol = least_squares(res, [0.5], bounds=([0.05], [3.0]), xtol=1e-12, ftol=1e-12)
    return float(sol.x[0]), float(np.sqrt(np.mean(sol.fun ** 2)))


def _fit_b_m(law: FlowLaw, b0: float, m0: float) -> tuple[float, float, float]:
    target = np.array([law.phi(float(r)) for r in FIT_GRID])

    def res(v: np.ndarray) -> np.ndarray:
        return np.array([iso_phi(float(r), float(v[0]), float(v[1])) for r in FIT_GRID]) \
            - target

    sol = least_squares(res, [b0, m0], bounds=([0.0, 0.05], [0.99, 3.0]), xtol=1e-12,
                        ftol=1e-12)
    return float(sol.x[0]), float(sol.x[1]), float(np.sqrt(np.mean(sol.fun ** 2)))


def truth(law: FlowLaw) -> Truth:
    """The (C, b, m) of ``law`` as a fit of the ISO 6358-1 law should find them (see the
    module's text): exact for :class:`IsoLaw`; C and b exact and m fitted with b held for
    :class:`Nozzle` and :class:`Series`."""
    if isinstance(law, IsoLaw):
        return Truth(law.conductance, law.b, law.m, 0.0, law.b, law.m, 0.0,
                     "ISO 6358-1 law: exact")
    b = law.critical_ratio
    m, rms = _fit_m(law, b)
    fb, fm, frms = _fit_b_m(law, b, m)
    note = ("isentropic nozzle: C from the choked flow, b = r*, m least squares with b held"
            if isinstance(law, Nozzle) else
            "series: C from the pair's choked flow, b where it stops being choked, m least "
            f"squares with b held; 1/C^2 = sum 1/Ci^2 gives {law.conductance_iso6358_3:.4e}")
    return Truth(law.conductance, b, m, rms, fb, fm, frms, note)


def discharge(t: np.ndarray, *, volume: float, conductance: float | None = None,
              b: float | None = None, p10: float, t10: float, p_atm: float, tau_heat: float,
              t_open: float, r_gas: float = 287.05, gamma: float = 1.4,
              density_exponent: float = 0.0, t_wall: float | None = None,
              subsonic_index: float = 0.5, flow_law: FlowLaw | None = None,
              temperature_out: np.ndarray | None = None) -> np.ndarray:
    """Tank pressure [Pa absolute] at instants t [s] (valve opens at t_open [s]; tau_heat
    [s] at the initial density; density_exponent n [-]: hA ~ rho^n; t_wall [K]: the wall
    temperature, held constant, default t10: a gas that starts at the wall's
    temperature). The state is (p10, t10) at t[0]; a gas away from the wall exchanges heat
    with it before the opening too (the closed tank's pressure follows its temperature).
    The flow: the ISO law of ``conductance``, ``b`` and ``subsonic_index`` m, or
    ``flow_law`` (:class:`IsoLaw`, :class:`Nozzle`, :class:`Series`; then neither
    ``conductance`` nor ``b``). ``temperature_out``: an array of t's size that receives the
    gas temperature [K] at t."""
    if flow_law is None:
        if conductance is None or b is None:
            raise ValueError("give conductance and b, or a flow_law")
        flow_law = IsoLaw(conductance, b, subsonic_index)
    elif conductance is not None or b is not None or subsonic_index != 0.5:
        raise ValueError("a flow_law carries its own C, b and m")
    law_c, law_phi = flow_law.conductance, flow_law.phi
    wall = t10 if t_wall is None else t_wall
    cv = r_gas / (gamma - 1.0)
    m0 = p10 * volume / (r_gas * t10)
    h_a = m0 * cv / tau_heat  # [W/K]

    def flow(p1: float, temp: float) -> float:
        return law_c * RHO_REF * p1 * math.sqrt(T_REF / temp) * law_phi(p_atm / p1)

    def rhs(_t: float, y: np.ndarray, valve: float = 1.0) -> list[float]:
        m, u = y  # gas mass [kg] and internal energy [J]
        temp = u / (m * cv)
        p1 = m * r_gas * temp / volume
        g = valve * flow(p1, temp)
        h_out = cv * temp + r_gas * temp  # specific enthalpy leaving [J/kg]
        h_now = h_a * (m / m0) ** density_exponent  # rho/rho_0 = m/m0 in a rigid tank
        return [-g, -g * h_out + h_now * (wall - temp)]

    return _integrate(rhs, t, t_open, p10, t10, cv, volume, r_gas,
                      closed=wall != t10 and t[0] < t_open, temperature_out=temperature_out)


def thermocouple(t: np.ndarray, gas: np.ndarray, lag: float, y0: float) -> np.ndarray:
    """A thermocouple's reading: the first-order lag y' = (u - y) / lag [s] of the
    piecewise-linear gas temperature u = ``gas`` [K] at instants t [s], from y0 [K]:
    y1 = u1 - s lag + (y0 - u0 + s lag) exp(-h / lag), s = (u1 - u0) / h, on each step."""
    y = np.empty_like(gas)
    y[0] = y0
    h = np.diff(t)
    a = np.exp(-h / lag)
    s_lag = np.diff(gas) / h * lag
    for k in range(t.size - 1):
        y[k + 1] = gas[k + 1] - s_lag[k] + (y[k] - gas[k] + s_lag[k]) * a[k]
    return y


def charge(t: np.ndarray, *, volume: float, p10: float, t10: float, p_supply: float,
           t_supply: float, tau_heat: float, t_open: float, conductance: float | None = None,
           b: float | None = None, subsonic_index: float = 0.5,
           flow_law: FlowLaw | None = None, t_wall: float | None = None,
           r_gas: float = 287.05, gamma: float = 1.4,
           temperature_out: np.ndarray | None = None, droop: float = 0.0) -> np.ndarray:
    """Tank pressure [Pa absolute] at instants t [s] of a charge: the tank at (p10, t10)
    at t[0] is filled through the component from a supply held at p_supply [Pa absolute],
    t_supply [K] once the valve opens at t_open [s]. The component's upstream side is the
    supply: mass flow C rho_ref p_supply sqrt(T_ref/t_supply) phi(p / p_supply), carrying
    the supply's enthalpy c_p t_supply into the tank (a reverse flow, p above the supply,
    would carry the tank's). Newton cooling at a constant hA = m0 c_v / tau_heat to a wall
    at ``t_wall`` (default t10; tau_heat inf: none). The flow law as :func:`discharge`'s.
    ``temperature_out`` receives the gas temperature [K] at t. ``droop`` [-]: a regulated
    supply that sags with its flow, p_s = p_supply (1 - droop g / g_choked) (a pressure
    regulator's droop: ``droop`` below its set point at the choked flow, back at it when
    the flow stops)."""
    if flow_law is None:
        if conductance is None or b is None:
            raise ValueError("give conductance and b, or a flow_law")
        flow_law = IsoLaw(conductance, b, subsonic_index)
    law_c, law_phi = flow_law.conductance, flow_law.phi
    wall = t10 if t_wall is None else t_wall
    cv = r_gas / (gamma - 1.0)
    cp = cv + r_gas
    m0 = p10 * volume / (r_gas * t10)
    h_a = 0.0 if math.isinf(tau_heat) else m0 * cv / tau_heat  # [W/K]
    g_choked = law_c * RHO_REF * p_supply * math.sqrt(T_REF / t_supply)  # [kg/s]

    def rhs(_t: float, y: np.ndarray, valve: float = 1.0) -> list[float]:
        m, u = y  # gas mass [kg] and internal energy [J]
        temp = u / (m * cv)
        p = m * r_gas * temp / volume
        g = valve * g_choked * law_phi(p / p_supply)  # into the tank [kg/s]
        for _ in range(6 if droop else 0):  # the sagging supply: a fixed point in g
            p_s = p_supply * (1.0 - droop * g / g_choked)
            g = valve * g_choked * p_s / p_supply * law_phi(min(p / p_s, 1.0))
        h = cp * (t_supply if g >= 0.0 else temp)
        return [g, g * h + h_a * (wall - temp)]

    return _integrate(rhs, t, t_open, p10, t10, cv, volume, r_gas,
                      closed=wall != t10 and h_a > 0.0 and t[0] < t_open,
                      temperature_out=temperature_out)


def _integrate(rhs: Callable[..., list[float]], t: np.ndarray, t_open: float, p10: float,
               t10: float, cv: float, volume: float, r_gas: float, *, closed: bool,
               temperature_out: np.ndarray | None) -> np.ndarray:
    """The tank's pressure [Pa] at t [s] from (p10 [Pa], t10 [K]) at t[0]: with ``closed``
    the shut tank first (``rhs(t, y, 0.0)``: heat exchange only) up to the opening t_open
    [s], then ``rhs`` (y = gas mass [kg], internal energy [J]), Radau at rtol 1e-10;
    ``temperature_out`` receives the gas temperature [K]."""
    m0 = p10 * volume / (r_gas * t10)
    y0 = [m0, m0 * cv * t10]
    out = np.full(t.size, p10)
    temps = np.full(t.size, float(t10))
    atol = [m0 * 1e-12, m0 * cv * t10 * 1e-12]
    before = t < t_open
    if closed:
        # the closed tank: no flow, heat exchange only, from t[0] to the opening
        grid = np.append(t[before], t_open)
        sol = solve_ivp(lambda tt, y: rhs(tt, y, 0.0), (float(t[0]), t_open), y0,
                        method="Radau", t_eval=grid, rtol=1e-10, atol=atol)
        m, u = sol.y
        out[before] = (m * r_gas * (u / (m * cv)) / volume)[:-1]
        temps[before] = (u / (m * cv))[:-1]
        y0 = [float(m[-1]), float(u[-1])]
    after = t >= t_open
    if np.any(after):
        ts = t[after] - t_open
        sol = solve_ivp(rhs, (0.0, float(ts[-1])), y0, method="Radau", t_eval=ts,
                        rtol=1e-10, atol=atol)
        m, u = sol.y
        out[after] = m * r_gas * (u / (m * cv)) / volume
        temps[after] = u / (m * cv)
    if temperature_out is not None:
        temperature_out[:] = temps
    return out
