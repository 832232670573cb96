# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The simulated rig: the tank (:class:`~pneumatic_unload.config.tank.TankSpec`), the
component, the real-rig effects and the pressure sensor.

:class:`RigConfig` is a frozen dataclass whose fields carry their unit, bounds and
description in ``field.metadata``. The simulator node declares its ROS parameters from it,
the ``pneumatic-unload simulate`` command builds its options from it (both through
:mod:`pneumatic_unload.config.adapters`), and bags store it as JSON so that offline analysis
needs no extra arguments. SI units throughout.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from pneumatic_unload.config.fields import (
    ConfigError,
    choice,
    describe,
    integer,
    names,
    number,
    parse_names,
    validate,
)
from pneumatic_unload.config.tank import TankSpec
from pneumatic_unload.physics import orifice_conductance

#: Names of the switchable real-rig effects of the discharge model.
EFFECTS: tuple[str, ...] = (
    "heat_transfer",
    "valve_opening",
    "sensor_lag",
    "leak",
    "leak_downstream",
    "orifice_leak",
    "orifice_leak_downstream",
    "pipe_volume",
    "sensor_offset",
    "sensor_gain",
)


#: Effects of a discharge the charge does not model (the pipe between tank and component,
#: the leaks in parallel with the component downstream of the valve).
CHARGE_WITHOUT: tuple[str, ...] = ("pipe_volume", "leak_downstream", "orifice_leak_downstream")
#: Effects a charge takes.
CHARGE_EFFECTS: tuple[str, ...] = tuple(e for e in EFFECTS if e not in CHARGE_WITHOUT)


@dataclass(frozen=True)
class RigConfig(TankSpec):
    """A tank rig: tank, component, gas, effects and sensor; the component discharges the
    tank to p_atm or (``direction`` 'charge') fills it from a supply at p_s, T_s.

    Every numeric field is SI; see ``RigConfig.describe()`` for units, ranges and meaning.
    ``effects`` names the real-rig effects switched on (a subset of :data:`EFFECTS`); the
    parameters of effects that are off are ignored.
    """

    # --- tank and component
    conductance: float = number(
        orifice_conductance(1.5e-3), "m^3/(s Pa)", 1e-13, 1e-5,
        "sonic conductance C of the component under test")
    critical_ratio: float = number(0.4, "-", 0.0, 0.99, "critical pressure ratio b")
    subsonic_index: float = number(0.5, "-", 0.1, 1.0, "ISO 6358 subsonic index m")
    ellipse_exponent: float = number(
        2.0, "-", 1.0, 6.0, "exponent q of the subsonic branch, phi = (1 - x^q)^m, x = (r - "
        "b)/(1 - b): 2 in ISO 6358-1:2013; another q is a flow curve that is not ISO-shaped "
        "(two restrictions in series)")
    series_conductance_ratio: float = number(
        0.0, "-", 0.0, 100.0, "a second ISO 6358-1 element in series downstream of the "
        "component (ISO 6358-3: one mass flow, no volume between them): its conductance over "
        "the upstream element's, C2/C1; 0: none. With it, conductance is the pair's and "
        "critical_ratio, subsonic_index the upstream element's")
    series_critical_ratio: float = number(
        0.5, "-", 0.0, 0.99, "critical pressure ratio b2 of the downstream element in series")
    series_subsonic_index: float = number(
        0.5, "-", 0.1, 1.0, "subsonic index m2 of the downstream element in series")
    initial_pressure: float = number(
        7e5, "Pa", 1e3, 5e7, "initial tank pressure p10 (absolute; a charge's starting "
        "pressure, e.g. an evacuated tank's few kPa)")
    direction: str = choice(
        "discharge", ("discharge", "charge"),
        "flow through the component: out of the tank to p_atm (a discharge) or into it from "
        "the supply (a charge)")
    supply_pressure: float = number(
        7e5, "Pa", 1e3, 5e7, "a charge's supply pressure p_s (absolute, held; above p10)")
    supply_temperature: float = number(
        293.15, "K", 150.0, 600.0, "a charge's supply gas temperature T_s")
    # --- switchable effects
    effects: tuple[str, ...] = names((), EFFECTS, "real-rig effects switched on (names)")
    heat_transfer_mode: str = choice(
        "natural", ("natural", "fixed", "density", "time"),
        "wall heat transfer: natural-convection correlation, fixed h*A, h*A varying as "
        "the gas density to the power heat_transfer_exponent, or h*A varying with the time "
        "since the opening (heat_transfer_time_slope, _curvature, _constant)")
    heat_transfer_coefficient: float = number(
        1.0, "W/K", 0.0, 1e4, "wall conductance h*A when heat_transfer_mode is fixed (at the "
        "initial gas density p10/(R T10) when it is density)")
    heat_transfer_exponent: float = number(
        0.5, "-", -2.0, 4.0, "exponent n of h*A = h*A_0 (rho/rho_0)^n when "
        "heat_transfer_mode is density")
    heat_transfer_time_slope: float = number(
        0.0, "-", -10.0, 10.0, "g1 of h*A = h*A_0 exp(g1 u + g2 u^2), u = ln(1 + s/tau_t), s "
        "the time since the opening, when heat_transfer_mode is time (h*A_0: "
        "heat_transfer_coefficient)")
    heat_transfer_time_curvature: float = number(
        0.0, "-", -10.0, 10.0, "g2 of the time law's h*A (heat_transfer_time_slope)")
    heat_transfer_time_constant: float = number(
        1.0, "s", 1e-4, 1e6, "tau_t, the time scale of the time law's h*A "
        "(heat_transfer_time_slope)")
    heat_transfer_scale: float = number(
        1.0, "-", 0.0, 100.0, "multiplier on the natural-convection correlation")
    heat_transfer_turbulent_ratio: float = number(
        1.0, "-", 0.0, 10.0, "further multiplier on the turbulent branch (Ra >= 1e9) of the "
        "natural-convection correlation, Nu = 0.10 Ra^(1/3) (1.3: McAdams' 0.13)")
    heat_transfer_jet_scale: float = number(
        1.0, "-", 0.0, 100.0, "a charge's natural law: multiplier on the incoming jet's "
        "forced convection, Nu = 0.56 Re^0.67 on the tank's diameter (0: none)")
    valve_opening_time: float = number(
        0.02, "s", 0.0, 10.0, "valve opening: linear ramp of the effective area")
    sensor_lag: float = number(0.01, "s", 0.0, 10.0, "first-order time constant of the sensor")
    leak_coefficient: float = number(
        2e-10, "kg/(s Pa)", 0.0, 1e-5,
        "upstream laminar leak (tank side, always open): G = K (p - p_atm)")
    leak_downstream_coefficient: float = number(
        2e-10, "kg/(s Pa)", 0.0, 1e-5,
        "downstream laminar leak (parallel to the component, opens with the valve): "
        "G = a(t) K (p - p_atm)")
    orifice_leak_conductance: float = number(
        5e-10, "m^3/(s Pa)", 1e-13, 1e-5,
        "upstream orifice-law leak (always open): its sonic conductance C_leak")
    orifice_leak_critical_ratio: float = number(
        0.3, "-", 0.0, 0.99, "upstream orifice-law leak: its critical pressure ratio b_leak")
    orifice_leak_downstream_conductance: float = number(
        5e-10, "m^3/(s Pa)", 1e-13, 1e-5,
        "downstream orifice-law leak (parallel to the component, opens with the valve): "
        "its sonic conductance C_leak")
    orifice_leak_downstream_critical_ratio: float = number(
        0.3, "-", 0.0, 0.99,
        "downstream orifice-law leak: its critical pressure ratio b_leak")
    pipe_volume: float = number(5e-4, "m^3", 0.0, 10.0, "volume between tank and component")
    pipe_conductance: float = number(
        1e-8, "m^3/(s Pa)", 1e-13, 1e-5, "sonic conductance of the pipe/fittings in series")
    sensor_offset: float = number(3000.0, "Pa", -1e6, 1e6, "transducer zero offset")
    sensor_gain: float = number(0.01, "-", -0.5, 0.5, "transducer relative gain error")
    # --- timing and valve schedule
    rate: float = number(1000.0, "Hz", 1.0, 100_000.0, "sample rate")
    pre_time: float = number(0.2, "s", 0.0, 3600.0, "time recorded before the valve opens")
    duration: float = number(
        0.0, "s", 0.0, 36_000.0, "time recorded after the valve opens (0: automatic)")
    valve_close_time: float = number(
        0.0, "s", 0.0, 36_000.0,
        "close the valve this long after opening: an aborted unload (0: never)")
    # --- sensor imperfections
    noise_std: float = number(1000.0, "Pa", 0.0, 1e6, "white noise standard deviation")
    noise_ar_rho: float = number(0.0, "-", 0.0, 0.999, "AR(1) coefficient of correlated noise")
    noise_ar_std: float = number(0.0, "Pa", 0.0, 1e6, "stationary std of the AR(1) noise")
    quantization: float = number(0.0, "Pa", 0.0, 1e5, "quantisation step (0: none)")
    full_scale: float = number(
        0.0, "Pa", 0.0, 1e8, "sensor saturates above this absolute pressure (0: never)")
    transducer_zero: float = number(0.0, "V", -100.0, 100.0, "transducer output at 0 Pa absolute")
    transducer_sensitivity: float = number(
        1e-5, "V/Pa", 1e-12, 1.0, "transducer sensitivity (for volts output)")
    seed: int = integer(0, 0, 2**31 - 1, "random seed of the sensor noise")

    def __post_init__(self) -> None:
        """Validate ranges and effect names (raises :class:`ConfigError`)."""
        validate(self)
        if self.atmosphere is None:
            raise ConfigError("a simulated rig needs its atmosphere [Pa absolute]")
        if self.direction == "charge":
            if self.supply_pressure <= self.initial_pressure:
                raise ConfigError(
                    f"a charge needs its supply above the tank: supply_pressure "
                    f"{self.supply_pressure:g} Pa <= initial_pressure "
                    f"{self.initial_pressure:g} Pa")
            off = [e for e in self.effects if e in CHARGE_WITHOUT]
            if off:
                raise ConfigError(f"effect(s) {', '.join(off)} not modelled for a charge "
                                  f"(a charge takes {', '.join(CHARGE_EFFECTS)})")

    @property
    def end_pressure(self) -> float:
        """The level the tank's pressure tends to [Pa absolute]: the room's
        (``atmosphere``) for a discharge, the supply's for a charge."""
        return self.supply_pressure if self.direction == "charge" else float(self.atmosphere)

    def has(self, effect: str) -> bool:
        """True when ``effect`` is switched on."""
        return effect in self.effects

    def replace(self, **changes: Any) -> RigConfig:
        """A copy with ``changes`` applied (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (JSON-ready; effects as a list)."""
        d = dataclasses.asdict(self)
        d["effects"] = list(self.effects)
        return d

    def to_json(self) -> str:
        """JSON text of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, strict: bool = True) -> RigConfig:
        """Build from a dict; unknown keys raise :class:`ConfigError` when ``strict``."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown and strict:
            raise ConfigError(f"unknown configuration key(s): {', '.join(unknown)}")
        kw = {k: v for k, v in d.items() if k in names}
        if "effects" in kw:
            kw["effects"] = parse_names(kw["effects"])
        if "seed" in kw:
            kw["seed"] = int(kw["seed"])
        return cls(**kw)

    @classmethod
    def describe(cls) -> list[dict[str, Any]]:
        """One dict per field: name, default, kind, unit, min/max or choices, doc."""
        return describe(cls)


def parse_effects(value: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Effect names from a comma-separated string or a sequence ('' or 'none': none)."""
    return parse_names(value)
