# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The charge test's closed forms: the unloading-time method mirrored, and its bias.

A tank at p10 filled through the component from a supply held at p_s, T_s (ISO 6358-2's
charge): the component's upstream side is the supply, so the ISO 6358 law takes p1 = p_s,
T1 = T_s, r = p / p_s. Its mass flow C rho_N p_s sqrt(T_N/T_s) phi(r) does not depend on
the tank's gas, and with no heat exchange the tank's energy balance,
V/(gamma - 1) dp/dt = c_p T_s G, closes on p alone:

    dp/dt = (p_s - p10) / tau_c * phi(p / p_s),
    tau_c = ((p_s - p10) / p_s) V sqrt(T_N/T_s) / (gamma p_N C)

(eq 38 with the supply in the place of p10 and T10, p10 in the place of p_atm:
:func:`~pneumatic_unload.physics.tau_exp_eq38`; rho_N R T_N for p_N, as the paper
writes). While choked (p <= b p_s) the rise is a straight line of slope (p_s - p10) /
tau_c.

**The mirrored method.** The characteristic charging time tau_exp is the time from the
opening to p* = p10 + 0.632 (p_s - p10), 63.2 % of the rise; eq 39 mirrored takes it for
tau_c:

    C = ((p_s - p10) / p_s) sqrt(T_N/T_s) V / (gamma p_N tau_exp)

(:func:`~pneumatic_unload.physics.conductance_eq39` of (tau_exp, p_s, p10, V, T_s)).

**Its bias.** With x = (p - p10)/(p_s - p10) the adiabatic charge obeys
dx/dt = phi(r0 + (1 - r0) x) / tau_c, r0 = p10/p_s, so the crossing comes at

    tau_exp = tau_c * I,   I = integral from 0 to 0.632 of dx / phi(r0 + (1 - r0) x),

and C_eq39 / C = 1 / I (:func:`charge_eq39_bias`). I >= 0.632 always (phi <= 1): the
mirrored eq 39 over-reads C by up to 1/0.632 = 1.58 when the flow is still choked at p*
(b >= 0.632 + 0.368 r0), less where the subsonic tail slows the rise before p*. Unlike the
discharge's bias (:func:`~pneumatic_unload.physics.eq39_bias_isentropic`, 1.040 at 7
bar), it depends on b and m - which the charge's model-based C fits. Heat exchange cools
the gas the inflow heats (by up to (gamma - 1) T_s on a vacuum fill), which lowers p and
delays p*: a real tank's ratio lies below the adiabatic one, as the discharge's does.

SI units: Pa absolute, K, s, m^3/(s Pa).
"""

from __future__ import annotations

import math

import numpy as np

from pneumatic_unload.physics import (
    AIR,
    P_STAR_FRACTION,
    R_LINEAR,
    Gas,
    conductance_eq39,
    flow_function,
)

#: Points of the Gauss-Legendre rule of :func:`charge_eq39_bias` on each side of the
#: choked end [-] (phi is smooth there: the integral is exact to ~1e-12).
QUADRATURE_POINTS = 64


def charge_p_star(p10: float, p_s: float, fraction: float = P_STAR_FRACTION) -> float:
    """The charge's threshold p* = p10 + (1 - fraction) (p_s - p10) [Pa absolute]: 63.2 %
    of the rise from p10 to the supply's p_s (the discharge's eq 40 mirrored, ``fraction``
    0.368 of the way still to go)."""
    return p10 + (1.0 - fraction) * (p_s - p10)


def charge_rise_integral(r0: float, critical_ratio: float, subsonic_index: float = 0.5,
                         to: float = 1.0 - P_STAR_FRACTION) -> float:
    """I = integral from 0 to ``to`` of dx / phi(r0 + (1 - r0) x) [-]: the adiabatic
    charge's time to the fraction ``to`` of its rise, in units of tau_c (r0 = p10/p_s [-],
    phi the ISO 6358 law of b = ``critical_ratio``, m = ``subsonic_index``).

    Raises ValueError unless 0 <= r0 < 1 and 0 < to < 1 (the flow stops at r = 1)."""
    if not (0.0 <= r0 < 1.0 and 0.0 < to < 1.0):
        raise ValueError(f"need 0 <= p10/p_s < 1 and 0 < to < 1, got {r0!r}, {to!r}")
    # the choked part is exact: phi = 1 up to x_b
    x_b = min(max((critical_ratio - r0) / (1.0 - r0), 0.0), to)
    if x_b >= to:
        return to
    nodes, weights = np.polynomial.legendre.leggauss(QUADRATURE_POINTS)
    x = x_b + (to - x_b) * 0.5 * (nodes + 1.0)
    phi = flow_function(r0 + (1.0 - r0) * x, critical_ratio, subsonic_index, R_LINEAR)
    return float(x_b + 0.5 * (to - x_b) * np.sum(weights / phi))


def charge_eq39_bias(p10: float, p_s: float, critical_ratio: float,
                     subsonic_index: float = 0.5) -> float:
    """C_eq39 / C of the mirrored eq 39 on an adiabatic charge from p10 to p_s [-] (both
    Pa absolute), through a component of b = ``critical_ratio``, m = ``subsonic_index``:
    1 / :func:`charge_rise_integral` (see the module's note; 1/0.632 = 1.582 while choked
    at p*)."""
    return 1.0 / charge_rise_integral(p10 / p_s, critical_ratio, subsonic_index)


def charge_conductance_adiabatic(tau: float, p_cross: float, p10: float, p_s: float,
                                 volume: float, t_supply: float, critical_ratio: float,
                                 subsonic_index: float = 0.5, gas: Gas = AIR) -> float:
    """C [m^3/(s Pa)] of the adiabatic charge from p10 that reaches ``p_cross`` at ``tau``
    [s] after the opening (pressures Pa absolute, V [m^3], T_s [K], b and m of the
    component [-]): the closed form of the module's note, C = eq 39 mirrored times
    I(p10/p_s, x) with x = (p_cross - p10)/(p_s - p10) (the charge's counterpart of the
    discharge's isentropic inversion, exact for any b and m). NaN unless
    p10 < p_cross < p_s and tau > 0."""
    if not (0.0 <= p10 < p_cross < p_s and tau > 0.0):
        return math.nan
    x = (p_cross - p10) / (p_s - p10)
    integral = charge_rise_integral(p10 / p_s, critical_ratio, subsonic_index, to=x)
    return conductance_eq39(tau, p_s, p10, volume, t_supply, gas) * integral
