"""An independent tank-discharge model for validation: it imports nothing from the package.

Ideal gas in a rigid tank, uniform state, wall heat transfer by Newton cooling with a constant
hA (thermal time constant tau_h = m0 c_v / hA) to a wall at a constant temperature (that of
the gas at the start, or another: a gas warm or cool after charging) or, with
``density_exponent`` n, an hA that follows the gas density, hA = hA_0 (rho/rho_0)^n, the
ISO 6358 flow law (choked below the critical ratio b, the elliptic subsonic branch above, a
linear end near r = 1), integrated with scipy's Radau at tight tolerance. Written apart
from ``pneumatic_unload.model`` on purpose: a fit that recovers the parameters of the model
it was written beside proves little. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

RHO_REF, T_REF = 1.185, 293.15  # ISO 8778 reference density [kg/m^3] and temperature [K]


def discharge(t: np.ndarray, *, volume: float, conductance: float, b: float, p10: float,
              t10: float, p_atm: float, tau_heat: float, t_open: float,
              r_gas: float = 287.05, gamma: float = 1.4,
              density_exponent: float = 0.0, t_wall: float | None = None) -> np.ndarray:
    """Tank pressure [Pa absolute] at instants t [s] (valve opens at t_open [s]; tau_heat
    [s] at the initial density; density_exponent n [-]: hA ~ rho^n; t_wall [K]: the wall
    temperature, held constant, default t10: a gas that starts at the wall's
    temperature). The state is (p10, t10) at t[0]; a gas away from the wall exchanges heat
    with it before the opening too (the closed tank's pressure follows its temperature)."""
    wall = t10 if t_wall is None else t_wall
    cv = r_gas / (gamma - 1.0)
    m0 = p10 * volume / (r_gas * t10)
    h_a = m0 * cv / tau_heat  # [W/K]

    def flow(p1: float, temp: float) -> float:
        r = p_atm / p1
        if r <= b:
            phi = 1.0
        elif r < 0.999:
            x = (r - b) / (1.0 - b)
            phi = math.sqrt(max(1.0 - x * x, 0.0))
        else:
            x = (0.999 - b) / (1.0 - b)
            phi = math.sqrt(1.0 - x * x) * (1.0 - r) / 0.001
        return conductance * RHO_REF * p1 * math.sqrt(T_REF / temp) * phi

    def rhs(_t: float, y: np.ndarray, valve: float = 1.0) -> list[float]:
        m, u = y  # gas mass [kg] and internal energy [J]
        temp = u / (m * cv)
        p1 = m * r_gas * temp / volume
        g = valve * flow(p1, temp)
        h_out = cv * temp + r_gas * temp  # specific enthalpy leaving [J/kg]
        h_now = h_a * (m / m0) ** density_exponent  # rho/rho_0 = m/m0 in a rigid tank
        return [-g, -g * h_out + h_now * (wall - temp)]

    y0 = [m0, m0 * cv * t10]
    out = np.full(t.size, p10)
    atol = [m0 * 1e-12, m0 * cv * t10 * 1e-12]
    before = t < t_open
    if wall != t10 and t[0] < t_open:
        # the closed tank: no flow, heat exchange only, from t[0] to the opening
        grid = np.append(t[before], t_open)
        sol = solve_ivp(lambda tt, y: rhs(tt, y, 0.0), (float(t[0]), t_open), y0,
                        method="Radau", t_eval=grid, rtol=1e-10, atol=atol)
        m, u = sol.y
        out[before] = (m * r_gas * (u / (m * cv)) / volume)[:-1]
        y0 = [float(m[-1]), float(u[-1])]
    after = t >= t_open
    if np.any(after):
        ts = t[after] - t_open
        sol = solve_ivp(rhs, (0.0, float(ts[-1])), y0, method="Radau", t_eval=ts,
                        rtol=1e-10, atol=atol)
        m, u = sol.y
        out[after] = m * r_gas * (u / (m * cv)) / volume
    return out
