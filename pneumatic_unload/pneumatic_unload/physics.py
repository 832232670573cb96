# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Gas properties, the ISO 6358 flow law and the closed forms of the unloading-time paper.

Everything is SI: pressures in Pa absolute, temperatures in K, volumes in m^3, times in s,
mass flow in kg/s and sonic conductance C in m^3/(s Pa) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa)).
Equation numbers (N) refer to de las Heras, "A new experimental algorithm for the evaluation
of the true sonic conductance of pneumatic components using the characteristic unloading
time"; errata follow ``shared/docs/method.md``.

Examples
--------
>>> round(p_star(7e5, 1e5) / 1e5, 3)  # paper fig. 4
3.208
>>> round(eq39_bias_isentropic(7e5, 101325.0), 3)  # C_eq39 / C_true, adiabatic choked
1.04
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: ISO 8778 reference temperature T_N [K].
T_N = 293.15
#: ISO 8778 reference pressure p_N [Pa].
P_N = 100_000.0
#: ISO 8778 reference density rho_N [kg/m^3] (the density that defines C in ISO 6358).
RHO_N = 1.185
#: Fraction of the pressure change left at p* (paper eq 40: 1 - 0.632).
P_STAR_FRACTION = 0.368
#: Pressure ratio above which the flow law is linearised (laminar end region) [-].
R_LINEAR = 0.999
#: Standard gravity [m/s^2].
G_ACCEL = 9.80665


@dataclass(frozen=True)
class Gas:
    """Ideal-gas properties.

    Attributes
    ----------
    name : str
        Label.
    gas_constant : float
        Specific gas constant R [J/(kg K)].
    gamma : float
        Ratio of specific heats c_p/c_v [-].
    viscosity : float
        Dynamic viscosity mu at about 293 K [Pa s] (natural-convection correlation).
    conductivity : float
        Thermal conductivity k at about 293 K [W/(m K)].
    """

    name: str = "air"
    gas_constant: float = 287.05
    gamma: float = 1.4
    viscosity: float = 1.81e-5
    conductivity: float = 0.0257

    @property
    def cp(self) -> float:
        """Specific heat at constant pressure c_p [J/(kg K)]."""
        return self.gamma * self.gas_constant / (self.gamma - 1.0)

    @property
    def cv(self) -> float:
        """Specific heat at constant volume c_v [J/(kg K)]."""
        return self.gas_constant / (self.gamma - 1.0)

    @property
    def prandtl(self) -> float:
        """Prandtl number Pr = c_p mu / k [-]."""
        return self.cp * self.viscosity / self.conductivity


AIR = Gas()


def flow_function(
    r: ArrayLike, critical_ratio: float, subsonic_index: float = 0.5,
    r_linear: float = R_LINEAR, ellipse_exponent: float = 2.0,
) -> NDArray[np.float64]:
    """ISO 6358 flow function phi(r) of the pressure ratio r = p2/p1 [-].

    phi = 1 for r <= b (choked); [1 - ((r - b)/(1 - b))^q]^m for b < r <= r_linear;
    linear in (1 - r) above r_linear, reaching 0 at r = 1 and going negative (reverse flow)
    for r > 1, so that ODE solvers see a Lipschitz right-hand side.

    Parameters
    ----------
    r : array_like
        Downstream/upstream pressure ratio [-].
    critical_ratio : float
        Critical pressure ratio b [-], 0 <= b < 1.
    subsonic_index : float
        Subsonic index m [-] (0.5 is the paper's eq 7 ellipse).
    r_linear : float
        Start of the linear end region [-].
    ellipse_exponent : float
        q [-]: 2 in ISO 6358-1:2013 (the kernel's ``pu_flow_phi`` alike).

    Returns
    -------
    ndarray
        phi [-].
    """
    r = np.asarray(r, dtype=float)
    b = critical_ratio
    x = np.clip((r - b) / (1.0 - b), 0.0, None)
    q = ellipse_exponent
    xq = x * x if q == 2.0 else np.power(x, q)
    phi = np.where(r <= b, 1.0, np.power(np.clip(1.0 - xq, 0.0, None), subsonic_index))
    xl = (r_linear - b) / (1.0 - b)
    phi_l = (1.0 - (xl * xl if q == 2.0 else xl ** q)) ** subsonic_index
    lin = phi_l * (1.0 - r) / (1.0 - r_linear)
    return np.where(r > r_linear, lin, phi)


def mass_flow(
    p1: ArrayLike, t1: ArrayLike, p2: ArrayLike, conductance: float,
    critical_ratio: float, subsonic_index: float = 0.5,
) -> NDArray[np.float64]:
    """ISO 6358 mass flow G = C rho_N p1 sqrt(T_N/T1) phi(p2/p1) [kg/s] (paper eq 15).

    Parameters
    ----------
    p1 : array_like
        Upstream pressure [Pa absolute].
    t1 : array_like
        Upstream temperature [K].
    p2 : array_like
        Downstream pressure [Pa absolute].
    conductance : float
        Sonic conductance C [m^3/(s Pa)].
    critical_ratio : float
        b [-].
    subsonic_index : float
        m [-].
    """
    p1 = np.asarray(p1, dtype=float)
    return (
        conductance * RHO_N * p1 * np.sqrt(T_N / np.asarray(t1, dtype=float))
        * flow_function(np.asarray(p2, dtype=float) / p1, critical_ratio, subsonic_index)
    )


def orifice_conductance(diameter: float) -> float:
    """Rule-of-thumb sonic conductance of a sharp orifice, C = 0.128 d^2 dm^3/(s bar).

    Parameters
    ----------
    diameter : float
        Orifice diameter [m].

    Returns
    -------
    float
        C [m^3/(s Pa)].

    >>> round(orifice_conductance(1e-3) / 1e-8, 3)
    0.128
    """
    d_mm = diameter * 1e3
    return 0.128 * d_mm * d_mm * 1e-8


def ideal_nozzle_conductance(area: float, gas: Gas = AIR) -> float:
    """Sonic conductance of an ideal convergent nozzle of throat area ``area`` [m^2]: its
    choked mass flow A p1 sqrt(gamma / (R T1)) (2 / (gamma + 1))^((gamma + 1) / (2 (gamma -
    1))) written as ISO 6358's C rho_N p1 sqrt(T_N / T1) [m^3/(s Pa)]. A component's
    discharge coefficient is C / ideal_nozzle_conductance(A) [-] (a sharp orifice's: about
    0.6-0.85).

    >>> round(ideal_nozzle_conductance(1e-6) / 1e-9, 4)  # 1 mm^2
    1.9919
    """
    g = gas.gamma
    choked = math.sqrt(g / (gas.gas_constant * T_N)) * (2.0 / (g + 1.0)) ** (
        (g + 1.0) / (2.0 * (g - 1.0)))
    return area * choked / RHO_N


def p_star(p10: float, p_atm: float, fraction: float = P_STAR_FRACTION) -> float:
    """Threshold pressure of the unloading time, p* = p_atm + 0.368 (p10 - p_atm) (eq 40).

    Parameters
    ----------
    p10 : float
        Initial tank pressure [Pa absolute] (or any linear signal).
    p_atm : float
        Final (atmospheric) pressure [Pa absolute] (same scale as p10).
    fraction : float
        Fraction of the change left at p* [-].
    """
    return p_atm + fraction * (p10 - p_atm)


def reference_pressure(gas: Gas = AIR) -> float:
    """The paper's p_N for ``gas`` [Pa]: the term rho_N R T_N of the choked mass flow
    C rho_N p1 sqrt(T_N/T1) written in eqs 22, 28, 38 and 39, which the paper prints as
    p_N for air (0.28 % apart). C is defined with rho_N = 1.185 kg/m^3, the density of the
    ISO 8778 standard reference atmosphere, whatever the gas (ISO 6358-1:2013's sonic
    conductance, :func:`mass_flow`), so another gas keeps rho_N and brings its own R: p_N R
    / R_air, p_N itself for air (a hydrogen tank's p_N 14.4 times air's, helium's 7.2)."""
    return P_N * (gas.gas_constant / AIR.gas_constant)


def tau0(volume: float, conductance: float, t10: float = T_N, gas: Gas = AIR) -> float:
    """Initial characteristic time tau0 = V sqrt(T_N/T10) / (gamma p_N C) [s] (eq 28),
    p_N the gas's (:func:`reference_pressure`).

    Parameters
    ----------
    volume : float
        Tank volume V [m^3].
    conductance : float
        C [m^3/(s Pa)].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    """
    return volume * math.sqrt(T_N / t10) / (gas.gamma * reference_pressure(gas) * conductance)


def tau_exp_eq38(
    p10: float, p_atm: float, volume: float, conductance: float, t10: float = T_N,
    gas: Gas = AIR,
) -> float:
    """Predicted unloading time tau_exp = ((p10 - p_atm)/p10) tau0 [s] (eq 38).

    A charge mirrors it: the component's upstream side is the supply, so its initial-slope
    time constant is this function of (p_s, p10, V, C, T_s) - the supply in the place of
    p10 and T10, the tank's initial pressure in the place of p_atm (the choked inflow
    C rho_N p_s sqrt(T_N/T_s) raises p at gamma R T_s / V times it).

    Parameters
    ----------
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    volume : float
        V [m^3].
    conductance : float
        C [m^3/(s Pa)].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    """
    return (p10 - p_atm) / p10 * tau0(volume, conductance, t10, gas)


def conductance_eq39(
    tau_exp: float, p10: float, p_atm: float, volume: float, t10: float = T_N,
    gas: Gas = AIR,
) -> float:
    """Sonic conductance from the unloading time, the paper's eq 39 [m^3/(s Pa)].

    C = ((p10 - p_atm)/p10) sqrt(T_N/T10) V / (gamma p_N tau_exp), p_N the gas's
    (:func:`reference_pressure`: the paper's p_N for air). Biased by design: see
    :func:`eq39_bias_isentropic` and ``method.md``.

    Parameters
    ----------
    tau_exp : float
        Time from the start of the unload to the p* crossing [s].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    volume : float
        V [m^3].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    """
    a, b = eq39_factors(p10, p_atm, volume, t10, gas)
    return a / (b * tau_exp)


def eq39_factors(p10: float, p_atm: float, volume: float, t10: float = T_N,
                 gas: Gas = AIR) -> tuple[float, float]:
    """eq 39 as C = a / (b tau_exp) (:func:`conductance_eq39`, the same doubles): a =
    ((p10 - p_atm)/p10) sqrt(T_N/T10) V [m^3] and b = gamma p_N [Pa] (p_N the gas's,
    :func:`reference_pressure`), which do not depend on tau_exp (prepared before the live
    crossing). Pressures [Pa absolute], V [m^3], T10 [K]."""
    return ((p10 - p_atm) / p10 * math.sqrt(T_N / t10) * volume,
            gas.gamma * reference_pressure(gas))


def choked_time_constant(
    volume: float, conductance: float, t10: float = T_N, gas: Gas = AIR,
    paper_form: bool = False,
) -> float:
    """Time scale Theta of the isentropic choked discharge (eq 22/24) [s].

    p1/p10 = (1 + t/Theta)^(-2 gamma/(gamma - 1)) with
    Theta = 2 V / ((gamma - 1) C rho_N R sqrt(T_N T10)), which is exact for the ISO 6358 flow
    law with rho_N = 1.185 kg/m^3. The paper writes p_N in place of rho_N R T_N (eq 22);
    ``paper_form=True`` gives that version with the gas's p_N (:func:`reference_pressure`;
    0.28 % apart for air).

    Parameters
    ----------
    volume : float
        V [m^3].
    conductance : float
        C [m^3/(s Pa)].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    paper_form : bool
        Use p_N as printed in eq 22 instead of rho_N R T_N.
    """
    k = gas.gamma - 1.0
    if paper_form:
        return volume / (reference_pressure(gas) * conductance) * (2.0 / k) * math.sqrt(
            T_N / t10)
    return 2.0 * volume / (k * conductance * RHO_N * gas.gas_constant * math.sqrt(T_N * t10))


def isentropic_choked_pressure(
    t: ArrayLike, p10: float, volume: float, conductance: float, t10: float = T_N,
    gas: Gas = AIR, paper_form: bool = False,
) -> NDArray[np.float64]:
    """Tank pressure of an isentropic choked discharge, eq 24 [Pa absolute].

    Valid while p1 > p_atm / b (the flow stays choked).

    Parameters
    ----------
    t : array_like
        Time since the valve opened [s] (>= 0).
    p10 : float
        Initial pressure [Pa absolute].
    volume : float
        V [m^3].
    conductance : float
        C [m^3/(s Pa)].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    paper_form : bool
        See :func:`choked_time_constant`.
    """
    theta = choked_time_constant(volume, conductance, t10, gas, paper_form)
    expo = -2.0 * gas.gamma / (gas.gamma - 1.0)
    return p10 * np.power(1.0 + np.asarray(t, dtype=float) / theta, expo)


def isentropic_choked_temperature(p1: ArrayLike, p10: float, t10: float, gas: Gas = AIR
                                  ) -> NDArray[np.float64]:
    """Gas temperature of an isentropic expansion, T = T10 (p1/p10)^((gamma-1)/gamma) [K] (eq 19).

    Parameters
    ----------
    p1 : array_like
        Tank pressure [Pa absolute].
    p10 : float
        Initial pressure [Pa absolute].
    t10 : float
        Initial temperature [K].
    gas : Gas
        Gas properties.
    """
    return t10 * np.power(np.asarray(p1, dtype=float) / p10, (gas.gamma - 1.0) / gas.gamma)


def isentropic_crossing_time(
    p_cross: float, p10: float, volume: float, conductance: float, t10: float = T_N,
    gas: Gas = AIR, paper_form: bool = False,
) -> float:
    """Time for the isentropic choked discharge to reach p_cross, inverse of eq 24 [s].

    Parameters
    ----------
    p_cross : float
        Pressure reached [Pa absolute], above p_atm / b for the result to be exact.
    p10 : float
        Initial pressure [Pa absolute] (NaN is returned unless p10 / p_cross > 0).
    volume, conductance, t10, gas, paper_form
        As in :func:`choked_time_constant` [m^3], [m^3/(s Pa)], [K].
    """
    ratio = p10 / p_cross
    if not ratio > 0:  # not absolute pressures: a real power would be complex
        return math.nan
    theta = choked_time_constant(volume, conductance, t10, gas, paper_form)
    return theta * (ratio ** ((gas.gamma - 1.0) / (2.0 * gas.gamma)) - 1.0)


def conductance_isentropic_inversion(
    t_cross: float, p_cross: float, p10: float, volume: float, t10: float = T_N,
    gas: Gas = AIR, paper_form: bool = False,
) -> float:
    """C that makes the isentropic choked closed form reach p_cross at t_cross [m^3/(s Pa)].

    The exact inversion of eq 22 at the p* crossing: removes the bias of eq 39 for an
    adiabatic discharge (valid while the flow is choked at p_cross, p_cross >= p_atm/b).

    Parameters
    ----------
    t_cross : float
        Time from the valve opening to the crossing [s].
    p_cross : float
        Pressure at the crossing [Pa absolute].
    p10 : float
        Initial pressure [Pa absolute] (NaN is returned unless p10 / p_cross > 0).
    volume : float
        V [m^3].
    t10 : float
        Initial gas temperature [K].
    gas : Gas
        Gas properties.
    paper_form : bool
        See :func:`choked_time_constant`.
    """
    if not p10 / p_cross > 0:  # not absolute pressures: a real power would be complex
        return math.nan
    return isentropic_factor(p_cross, p10, volume, t10, gas, paper_form) / t_cross


def isentropic_factor(p_cross: float, p10: float, volume: float, t10: float = T_N,
                      gas: Gas = AIR, paper_form: bool = False) -> float:
    """The isentropic inversion as C = k / t_cross (:func:`conductance_isentropic_inversion`,
    the same doubles): k = Theta(C = 1) X [m^3/Pa], which does not depend on the crossing
    time (prepared before the live crossing); NaN unless p10 / p_cross > 0. Pressures
    [Pa absolute], V [m^3], T10 [K]."""
    # t = Theta(C) * X with Theta proportional to 1/C
    ratio = p10 / p_cross
    if not ratio > 0:  # not absolute pressures: a real power would be complex
        return math.nan
    theta_1 = choked_time_constant(volume, 1.0, t10, gas, paper_form)
    x = ratio ** ((gas.gamma - 1.0) / (2.0 * gas.gamma)) - 1.0
    return theta_1 * x


def eq39_bias_isentropic(p10: float, p_atm: float, gas: Gas = AIR) -> float:
    """Ratio C_eq39 / C_true for an ideal isentropic choked discharge [-].

    Computed from the paper's own closed form (eq 22 with p_N), so only the method's
    approximation remains: 1.040 at p10 = 7 bar abs and 1.057 at 6 bar abs with
    p_atm = 1.01325 bar. Exact only while the flow is choked at p* (p* >= p_atm / b).

    Parameters
    ----------
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    gas : Gas
        Gas properties.
    """
    ps = p_star(p10, p_atm)
    t_cross = isentropic_crossing_time(ps, p10, 1.0, 1.0, T_N, gas, paper_form=True)
    return conductance_eq39(t_cross, p10, p_atm, 1.0, T_N, gas) / 1.0


def conductance_sse(
    t_star: float, p10: float, p1_inf: float, volume: float, t10: float = T_N,
    gas: Gas = AIR,
) -> float:
    """Sonic conductance by the SSE method after an aborted unload, eq 23 [m^3/(s Pa)].

    After an isentropic choked unload of duration t* stopped by closing the valve, the gas
    re-heats at constant volume to T10 and the pressure settles at p1_inf. The mass left is
    m*/m0 = p1_inf/p10, so the pressure at the instant of closing was
    p(t*) = p10 (p1_inf/p10)^gamma and eq 22 gives
    C = Theta_1 [(p10/p1_inf)^((gamma-1)/2) - 1] / t*, with Theta_1 the eq 22 time scale
    for C = 1. The printed exponent (gamma-1)/2 of eq 23 is therefore right for the
    *recovered* pressure; (gamma-1)/(2 gamma), the erratum suggested in ``method.md``,
    belongs to the pressure at the instant of closing (use
    :func:`conductance_isentropic_inversion` for that). ``test_physics`` checks this
    against the simulated isentropic state.

    Parameters
    ----------
    t_star : float
        Duration of the unload [s].
    p10 : float
        Initial pressure [Pa absolute].
    p1_inf : float
        Recovered pressure after re-equilibration to T10 [Pa absolute]. NaN is returned
        unless p10 > 0 and p1_inf > 0 (absolute pressures: otherwise the fractional power
        is complex, or p1_inf = 0 divides by zero); C <= 0 when p1_inf >= p10 (no mass
        left the tank), which the caller must refuse.
    volume : float
        V [m^3].
    t10 : float
        Initial (and final) gas temperature [K].
    gas : Gas
        Gas properties.
    """
    if not (p10 > 0.0 and p1_inf > 0.0):  # not absolute pressures (or NaN): no real C
        return math.nan
    theta_1 = choked_time_constant(volume, 1.0, t10, gas, paper_form=True)
    x = (p10 / p1_inf) ** ((gas.gamma - 1.0) / 2.0) - 1.0
    return theta_1 * x / t_star


def tank_geometry(volume: float, length_diameter_ratio: float) -> tuple[float, float, float]:
    """Cylinder dimensions from its volume and L/D.

    Parameters
    ----------
    volume : float
        V [m^3].
    length_diameter_ratio : float
        L/D [-].

    Returns
    -------
    tuple
        (length L [m], diameter D [m], inner wall area A_w [m^2]).
    """
    d = (4.0 * volume / (math.pi * length_diameter_ratio)) ** (1.0 / 3.0)
    length = length_diameter_ratio * d
    area = math.pi * d * length + 0.5 * math.pi * d * d
    return length, d, area
