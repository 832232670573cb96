# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Wall heat transfer of the tank gas: the one place a heat law lives.

The gas exchanges heat with the wall, Q = hA (T_wall - T) [W]. The wall conductance hA
[W/K] follows one of the laws of :data:`HEAT_LAWS`:

* ``natural`` - natural convection inside a closed cylinder, hA = A_w k/L Nu(Ra) with
  Nu = 0.59 Ra^0.25 (laminar) or 0.10 Ra^(1/3) (turbulent, Ra >= 1e9), Nu >= 1, and
  Ra = g |T_w - T|/T L^3 rho^2 c_p/(mu k); times a dimensionless ``heat_transfer_scale``
  (1: the correlation as published). The scale is what the estimator and the discrepancy
  workflow fit, and what the simulator sets. The turbulent branch's coefficient differs
  between the published correlations (0.10 in Churchill's and Incropera's tables, 0.13 in
  McAdams' and Geankoplis', which HydDown uses): ``heat_transfer_turbulent_ratio`` [-]
  multiplies it alone, fitted where a record spans both regimes (:func:`rayleigh`).
* ``fixed`` - a constant hA = ``heat_transfer_coefficient`` [W/K] (Newton cooling).
* a charge's ``natural`` law adds the forced convection of the incoming jet (the mixed
  law of HydDown's fills): hA_jet = A_w k/L 0.56 Re^0.67, Re = 4 |G_in| / (mu pi D) on the
  tank's diameter D, times ``heat_transfer_jet_scale`` [-] (:func:`jet_coefficient`; 0:
  none, as in a discharge, whose outflow drives no jet inside the tank).
* ``time`` - hA = hA_0 exp(g1 u + g2 u^2), u = ln(1 + s/tau_t), s the time since the
  opening: ``heat_transfer_coefficient`` hA_0 [W/K] at the opening,
  ``heat_transfer_time_slope`` g1 and ``heat_transfer_time_curvature`` g2 [-], the time
  scale ``heat_transfer_time_constant`` tau_t [s] (an exchange that changes as the
  discharge goes on - a jet's stirring that fades, a wall that cools with the gas - whatever
  drives it; g1 = g2 = 0 is ``fixed``).
* ``density`` - hA = hA_0 (rho/rho_0)^n: ``heat_transfer_coefficient`` hA_0 [W/K] at the
  initial density rho_0 = p10/(R T10), the exponent n = ``heat_transfer_exponent`` [-]
  (convection whose h follows the gas density: n = 0 is ``fixed``; laminar natural
  convection, Nu ~ Ra^(1/4), has n = 1/2, turbulent, Nu ~ Ra^(1/3), n = 2/3).

The formulae are compiled with the right-hand side
(:func:`pneumatic_unload.model.kernel.heat_flow`); this module maps the fields of
:class:`~pneumatic_unload.config.RigConfig` onto them, for the simulator, the estimator's
model inversion and curve fit, and the discrepancy's heat-transfer candidate alike. SI units.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.kernel import (
    HEAT_DENSITY,
    HEAT_FIXED,
    HEAT_NATURAL,
    HEAT_NONE,
    HEAT_TIME,
    JET_EXPONENT,
    heat_flow,
)
from pneumatic_unload.physics import G_ACCEL, tank_geometry

FloatArray = NDArray[np.float64]

#: Heat laws (values of ``RigConfig.heat_transfer_mode``).
HEAT_LAWS: tuple[str, ...] = ("natural", "fixed", "density", "time")


#: Rayleigh number where the natural-convection correlation turns turbulent [-].
RA_TURBULENT = 1e9


def heat_parameters(cfg: RigConfig) -> tuple[float, float, float, float]:
    """The heat law of a configuration as the kernel's (mode, coefficient, shape constant,
    turbulent ratio).

    Parameters
    ----------
    cfg : RigConfig
        Tank (V, L/D), gas, ``heat_transfer_mode`` and its parameter; adiabatic unless
        ``heat_transfer`` is among ``cfg.effects``.

    Returns
    -------
    tuple of float
        (mode: :data:`~pneumatic_unload.model.kernel.HEAT_NONE`, ``HEAT_NATURAL``,
        ``HEAT_FIXED``, ``HEAT_DENSITY`` or ``HEAT_TIME``; coefficient: A_w k/L x scale for
        the natural law [W/K], hA for the fixed one and the time law's at the opening
        [W/K], hA_0 (T10/p10)^n for the density law
        [W/K / (Pa/K)^n]; shape constant: for the natural law the Ra constant
        g L^3 c_p/(mu k R^2) [K^3/Pa^2, such that Ra is dimensionless], for the density law
        the exponent n [-], else 0; the multiplier on the natural law's turbulent branch
        [-], 1 for the other laws), as :func:`~pneumatic_unload.model.kernel.heat_flow`
        takes them.
    """
    if not cfg.has("heat_transfer"):
        return HEAT_NONE, 0.0, 0.0, 1.0
    if cfg.heat_transfer_mode == "fixed":
        return HEAT_FIXED, float(cfg.heat_transfer_coefficient), 0.0, 1.0
    if cfg.heat_transfer_mode == "time":  # hA at the opening; time_parameters: its change
        return HEAT_TIME, float(cfg.heat_transfer_coefficient), 0.0, 1.0
    if cfg.heat_transfer_mode == "density":
        n = float(cfg.heat_transfer_exponent)
        # (rho/rho_0)^n = ((p/T)/(p10/T10))^n: the reference folded into the coefficient
        ref = cfg.initial_temperature / cfg.initial_pressure
        return HEAT_DENSITY, float(cfg.heat_transfer_coefficient) * ref**n, n, 1.0
    gas = cfg.gas
    length, _d, area = tank_geometry(cfg.volume, cfg.length_diameter_ratio)
    ra_const = _rayleigh_constant(cfg)
    hk = area * gas.conductivity / length * cfg.heat_transfer_scale
    return HEAT_NATURAL, hk, ra_const, float(cfg.heat_transfer_turbulent_ratio)


def time_parameters(cfg: RigConfig) -> tuple[float, float, float]:
    """The time law's change of hA as the kernel's (g1 [-], g2 [-], tau_t [s]): hA = hA_0
    exp(g1 u + g2 u^2), u = ln(1 + s/tau_t), s the time since the opening; (0, 0, 1) for the
    other laws (hA a function of the state alone)."""
    if not cfg.has("heat_transfer") or cfg.heat_transfer_mode != "time":
        return 0.0, 0.0, 1.0
    return (float(cfg.heat_transfer_time_slope), float(cfg.heat_transfer_time_curvature),
            float(cfg.heat_transfer_time_constant))


#: Forced-convection correlation of a charge's jet, Nu = JET_NU Re^JET_EXPONENT [-].
JET_NU = 0.56


def jet_coefficient(cfg: RigConfig) -> float:
    """The coefficient K of a charge's jet-driven convection, hA = K |G_in|^0.67
    [W/K / (kg/s)^0.67]: A_w k/L 0.56 (4 / (mu pi D))^0.67 times
    ``heat_transfer_jet_scale`` and the natural law's ``heat_transfer_scale`` (the law's one
    multiplier scales all of it: a fit's law reaches no exchange, an adiabatic rig's charge
    at 1 kHz was otherwise read with the jet's full cooling, C +3.4 % at z 4.5); 0 unless a
    charge with the natural heat law on."""
    if not (cfg.direction == "charge" and cfg.has("heat_transfer")
            and cfg.heat_transfer_mode == "natural"):
        return 0.0
    gas = cfg.gas
    length, diameter, area = tank_geometry(cfg.volume, cfg.length_diameter_ratio)
    re_per_flow = 4.0 / (gas.viscosity * math.pi * diameter)  # Re per kg/s [s/kg]
    return (area * gas.conductivity / length * JET_NU * re_per_flow**JET_EXPONENT
            * cfg.heat_transfer_jet_scale * cfg.heat_transfer_scale)


def _rayleigh_constant(cfg: RigConfig) -> float:
    # Ra = g |dT|/T L^3 rho^2 c_p / (mu k), rho = p/(R T): the factor of |dT|/T (p/T)^2
    gas = cfg.gas
    length, _d, _area = tank_geometry(cfg.volume, cfg.length_diameter_ratio)
    return G_ACCEL * length**3 * gas.cp / (gas.viscosity * gas.conductivity
                                           * gas.gas_constant**2)


def rayleigh(cfg: RigConfig, p: FloatArray, t_gas: FloatArray) -> FloatArray:
    """Rayleigh number of the natural-convection law [-] at gas pressures p [Pa absolute]
    and temperatures t_gas [K] (the wall at ``cfg.wall``; |T_w - T| at least 1 K: the
    exchange a discharge drives), whatever law ``cfg`` selects."""
    ra_const = _rayleigh_constant(cfg)
    t = np.asarray(t_gas, dtype=float)
    dt = np.maximum(np.abs(cfg.wall - t), 1.0)
    return ra_const * dt / t * (np.asarray(p, dtype=float) / t) ** 2


def heat_flow_function(cfg: RigConfig) -> Callable[[float, float], float] | None:
    """The wall heat flow Q(p, T) [W] of a configuration, or None when adiabatic.

    Parameters
    ----------
    cfg : RigConfig
        Tank (V, L/D), gas, wall temperature, ``heat_transfer_mode`` and its parameter;
        adiabatic unless ``heat_transfer`` is among ``cfg.effects``.

    Returns
    -------
    callable or None
        ``q(p, t_gas)``: heat flow into the gas [W] at gas pressure p [Pa absolute] and
        mean gas temperature t_gas [K] (the compiled law the integrator uses).
    """
    mode, coeff, ra_const, turb = heat_parameters(cfg)
    if mode == HEAT_NONE:
        return None
    t_wall = cfg.wall

    def q(p: float, t_gas: float) -> float:
        return float(heat_flow(mode, coeff, ra_const, t_wall, p, t_gas, turb))

    return q


def thermal_time_constant(cfg: RigConfig, p: float, t_gas: float) -> float:
    """Gas-wall thermal time constant m c_v / hA at a state [s] (inf when adiabatic).

    Parameters
    ----------
    cfg : RigConfig
        Configuration (heat law as in :func:`heat_flow_function`).
    p : float
        Gas pressure [Pa absolute].
    t_gas : float
        Gas temperature [K]; hA of the natural law is taken at \\|T_w - T\\| = 10 K when the
        two are equal.
    """
    q = heat_flow_function(cfg)
    if q is None:
        return math.inf
    dt = cfg.wall - t_gas
    probe = t_gas if abs(dt) > 1e-9 else cfg.wall - 10.0
    h_a = q(p, probe) / (cfg.wall - probe)
    gas = cfg.gas
    m_cv = p * cfg.volume / (gas.gas_constant * t_gas) * gas.gas_constant / (gas.gamma - 1.0)
    return m_cv / h_a if h_a > 0 else math.inf
