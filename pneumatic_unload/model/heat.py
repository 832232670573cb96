"""Wall heat transfer of the tank gas: the one place a heat law lives.

The gas exchanges heat with the wall, Q = hA (T_wall - T) [W]. The wall conductance hA
[W/K] follows one of the laws of :data:`HEAT_LAWS`:

* ``natural`` - natural convection inside a closed cylinder, hA = A_w k/L Nu(Ra) with
  Nu = 0.59 Ra^0.25 (laminar) or 0.10 Ra^(1/3) (turbulent, Ra >= 1e9), Nu >= 1, and
  Ra = g |T_w - T|/T L^3 rho^2 c_p/(mu k); times a dimensionless ``heat_transfer_scale``
  (1: the correlation as published). The scale is what the estimator and the discrepancy
  workflow fit, and what the simulator sets.
* ``fixed`` - a constant hA = ``heat_transfer_coefficient`` [W/K] (Newton cooling).

The formulae are compiled with the right-hand side
(:func:`pneumatic_unload.model.kernel.heat_flow`); this module maps the fields of
:class:`~pneumatic_unload.config.RigConfig` onto them, for the simulator, the estimator's
model inversion and curve fit, and the discrepancy's heat-transfer candidate alike. SI units.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.kernel import HEAT_FIXED, HEAT_NATURAL, HEAT_NONE, heat_flow
from pneumatic_unload.physics import G_ACCEL, tank_geometry

#: Heat laws (values of ``RigConfig.heat_transfer_mode``).
HEAT_LAWS: tuple[str, ...] = ("natural", "fixed")


def heat_parameters(cfg: RigConfig) -> tuple[float, float, float]:
    """The heat law of a configuration as the kernel's (mode, coefficient, Ra constant).

    Parameters
    ----------
    cfg : RigConfig
        Tank (V, L/D), gas, ``heat_transfer_mode`` and its parameter; adiabatic unless
        ``heat_transfer`` is among ``cfg.effects``.

    Returns
    -------
    tuple of float
        (mode: :data:`~pneumatic_unload.model.kernel.HEAT_NONE`, ``HEAT_NATURAL`` or
        ``HEAT_FIXED``; coefficient [W/K]: A_w k/L x scale for the natural law, hA for the
        fixed one; Ra constant g L^3 c_p/(mu k R^2) [K^3/Pa^2 ... such that Ra is
        dimensionless], 0 unless natural), as :func:`~pneumatic_unload.model.kernel.heat_flow`
        takes them.
    """
    if not cfg.has("heat_transfer"):
        return HEAT_NONE, 0.0, 0.0
    if cfg.heat_transfer_mode == "fixed":
        return HEAT_FIXED, float(cfg.heat_transfer_coefficient), 0.0
    gas = cfg.gas
    length, _d, area = tank_geometry(cfg.volume, cfg.length_diameter_ratio)
    # Ra = g |dT|/T L^3 rho^2 c_p / (mu k), rho = p/(R T)
    ra_const = G_ACCEL * length**3 * gas.cp / (gas.viscosity * gas.conductivity
                                                * gas.gas_constant**2)
    hk = area * gas.conductivity / length * cfg.heat_transfer_scale
    return HEAT_NATURAL, hk, ra_const


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
    mode, coeff, ra_const = heat_parameters(cfg)
    if mode == HEAT_NONE:
        return None
    t_wall = cfg.wall

    def q(p: float, t_gas: float) -> float:
        return float(heat_flow(mode, coeff, ra_const, t_wall, p, t_gas))

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
        Gas temperature [K]; hA of the natural law is taken at |T_w - T| = 10 K when the
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
