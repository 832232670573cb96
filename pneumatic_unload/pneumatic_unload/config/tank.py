# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The tank and its gas: declared once, embedded by every settings class.

:class:`TankSpec` holds what is known about the rig's tank and gas (V, L/D, T10, the wall
temperature, p_atm, the gas). The simulated rig (:class:`~pneumatic_unload.config.rig.RigConfig`),
the estimator's settings and the discrepancy workflow's settings inherit its fields, so the
same names, units, ranges and meanings hold everywhere, and the adapters
(:mod:`pneumatic_unload.config.adapters`) turn them into command-line options, ROS parameters
and bag JSON. SI units.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from pneumatic_unload.config.fields import number, optional, validate
from pneumatic_unload.physics import AIR, T_N, Gas

#: Names of the tank fields (what :meth:`TankSpec.of` copies between settings classes).
TANK_FIELDS: tuple[str, ...] = ("volume", "length_diameter_ratio", "initial_temperature",
                                "wall_temperature", "atmosphere", "gas_constant", "gamma")


@dataclass(frozen=True)
class TankSpec:
    """The tank, its initial state and the gas.

    Attributes
    ----------
    volume : float
        Tank volume V [m^3].
    length_diameter_ratio : float
        Tank length over diameter L/D [-] (wall area and natural-convection length).
    initial_temperature : float
        Initial gas temperature T10 [K].
    wall_temperature : float or None
        Tank wall (and room) temperature [K]; None: equal to T10 (the paper's assumption:
        the gas starts in thermal equilibrium with the wall).
    atmosphere : float or None
        Atmospheric pressure p_atm [Pa absolute]; None: from the record's final plateau.
    gas_constant : float
        Specific gas constant R [J/(kg K)].
    gamma : float
        Ratio of specific heats [-].
    """

    volume: float = number(5e-3, "m^3", 1e-7, 10.0, "tank volume V")
    length_diameter_ratio: float = number(2.0, "-", 0.1, 50.0, "tank length/diameter L/D")
    initial_temperature: float = number(T_N, "K", 150.0, 600.0, "initial gas temperature T10")
    wall_temperature: float | None = optional(
        None, "K", 150.0, 600.0, "tank wall (and room) temperature", "equal to T10")
    atmosphere: float | None = optional(
        101325.0, "Pa", 1e3, 2e5, "atmospheric pressure p_atm (absolute)",
        "from the final plateau (auto)")
    gas_constant: float = number(AIR.gas_constant, "J/(kg K)", 100.0, 5000.0,
                                 "specific gas constant R")
    gamma: float = number(AIR.gamma, "-", 1.01, 1.7, "ratio of specific heats")

    def __post_init__(self) -> None:
        """Validate every field against its metadata (raises ConfigError)."""
        validate(self)

    @property
    def gas(self) -> Gas:
        """The gas (:class:`~pneumatic_unload.physics.Gas`)."""
        if self.gas_constant == AIR.gas_constant and self.gamma == AIR.gamma:
            return AIR
        return dataclasses.replace(AIR, name="gas", gas_constant=self.gas_constant,
                                   gamma=self.gamma)

    @property
    def wall(self) -> float:
        """The wall temperature in use [K] (T10 when not given)."""
        return self.initial_temperature if self.wall_temperature is None \
            else self.wall_temperature

    @property
    def tank(self) -> TankSpec:
        """The tank fields alone."""
        return TankSpec(**self.tank_fields())

    def tank_fields(self) -> dict[str, Any]:
        """The tank fields as keyword arguments of any settings class [SI]."""
        return {k: getattr(self, k) for k in TANK_FIELDS}

    @staticmethod
    def fields_of(mapping: dict[str, Any]) -> dict[str, Any]:
        """The tank fields present in a mapping (a bag's JSON, parameters) [SI]."""
        return {k: mapping[k] for k in TANK_FIELDS if k in mapping}


#: The wall temperatures a tank may have [K] (the ``wall_temperature`` field's range).
WALL_RANGE: tuple[float, float] = next(
    (float(f.metadata["min"]), float(f.metadata["max"]))
    for f in dataclasses.fields(TankSpec) if f.name == "wall_temperature")


#: The atmospheric pressures a rig may vent to [Pa absolute] (the ``atmosphere`` field's
#: range).
ATMOSPHERE_RANGE: tuple[float, float] = next(
    (float(f.metadata["min"]), float(f.metadata["max"]))
    for f in dataclasses.fields(TankSpec) if f.name == "atmosphere")


def wall_pair(wall: float, u: float) -> tuple[float, float]:
    """The wall temperature ``wall`` [K] moved up and down by its standard uncertainty u
    [K], each inside :data:`WALL_RANGE`: (upper, lower) [K]. A wall at the edge of the
    range (150 K) is moved one way only: a sensitivity is then the one-sided difference
    over (upper - lower), not over 2 u."""
    lo, hi = WALL_RANGE
    return min(max(wall + u, lo), hi), min(max(wall - u, lo), hi)

