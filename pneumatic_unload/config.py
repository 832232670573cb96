"""One source of configuration: the rig, its real-rig effects and the pressure sensor.

:class:`RigConfig` is a frozen dataclass whose fields carry their unit, bounds and
description in ``field.metadata``. The simulator node declares its ROS parameters from it
(with ``ParameterDescriptor`` ranges), the ``pneumatic-unload simulate`` command builds its
options from it, and bags store it as JSON so that offline analysis needs no extra
arguments. SI units throughout.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any

from pneumatic_unload.physics import AIR, T_N, Gas, orifice_conductance

#: Names of the switchable real-rig effects of the discharge model.
EFFECTS: tuple[str, ...] = (
    "heat_transfer",
    "valve_opening",
    "sensor_lag",
    "leak",
    "pipe_volume",
    "sensor_offset",
    "sensor_gain",
)


class ConfigError(ValueError):
    """A configuration value is out of range, of the wrong type or unknown."""


def _f(default: float, unit: str, lo: float, hi: float, doc: str) -> Any:
    return field(default=default, metadata={"unit": unit, "min": lo, "max": hi, "doc": doc})


def _s(default: str, choices: tuple[str, ...], doc: str) -> Any:
    return field(default=default, metadata={"unit": "", "choices": choices, "doc": doc})


@dataclass(frozen=True)
class RigConfig:
    """A tank-discharge rig: tank, component, gas, effects and sensor.

    Every numeric field is SI; see ``RigConfig.describe()`` for units, ranges and meaning.
    ``effects`` names the real-rig effects switched on (a subset of :data:`EFFECTS`); the
    parameters of effects that are off are ignored.
    """

    # --- tank and component
    volume: float = _f(5e-3, "m^3", 1e-7, 10.0, "tank volume V")
    length_diameter_ratio: float = _f(2.0, "-", 0.1, 50.0, "tank length/diameter L/D")
    conductance: float = _f(
        orifice_conductance(1.5e-3), "m^3/(s Pa)", 1e-13, 1e-5,
        "sonic conductance C of the component under test")
    critical_ratio: float = _f(0.4, "-", 0.0, 0.99, "critical pressure ratio b")
    subsonic_index: float = _f(0.5, "-", 0.1, 1.0, "ISO 6358 subsonic index m")
    initial_pressure: float = _f(7e5, "Pa", 1e4, 5e7, "initial tank pressure p10 (absolute)")
    initial_temperature: float = _f(
        T_N, "K", 150.0, 600.0, "initial gas temperature T10")
    atmosphere: float = _f(101325.0, "Pa", 1e3, 2e5, "atmospheric pressure p_atm (absolute)")
    wall_temperature: float = _f(T_N, "K", 150.0, 600.0, "tank wall (and room) temperature")
    gas_constant: float = _f(AIR.gas_constant, "J/(kg K)", 100.0, 5000.0, "gas constant R")
    gamma: float = _f(AIR.gamma, "-", 1.01, 1.7, "ratio of specific heats")
    # --- switchable effects
    effects: tuple[str, ...] = field(
        default=(), metadata={"unit": "", "choices": EFFECTS,
                              "doc": "real-rig effects switched on (names)"})
    heat_transfer_mode: str = _s(
        "natural", ("natural", "fixed"),
        "wall heat transfer: natural-convection correlation or fixed h*A")
    heat_transfer_coefficient: float = _f(
        1.0, "W/K", 0.0, 1e4, "wall conductance h*A when heat_transfer_mode is fixed")
    heat_transfer_scale: float = _f(
        1.0, "-", 0.0, 100.0, "multiplier on the natural-convection correlation")
    valve_opening_time: float = _f(
        0.02, "s", 0.0, 10.0, "valve opening: linear ramp of the effective area")
    sensor_lag: float = _f(0.01, "s", 0.0, 10.0, "first-order time constant of the sensor")
    leak_coefficient: float = _f(
        2e-10, "kg/(s Pa)", 0.0, 1e-5, "laminar leak to atmosphere: G = K (p - p_atm)")
    pipe_volume: float = _f(5e-4, "m^3", 0.0, 10.0, "volume between tank and component")
    pipe_conductance: float = _f(
        1e-8, "m^3/(s Pa)", 1e-13, 1e-5, "sonic conductance of the pipe/fittings in series")
    sensor_offset: float = _f(3000.0, "Pa", -1e6, 1e6, "transducer zero offset")
    sensor_gain: float = _f(0.01, "-", -0.5, 0.5, "transducer relative gain error")
    # --- timing and valve schedule
    rate: float = _f(1000.0, "Hz", 1.0, 100_000.0, "sample rate")
    pre_time: float = _f(0.2, "s", 0.0, 3600.0, "time recorded before the valve opens")
    duration: float = _f(
        0.0, "s", 0.0, 36_000.0, "time recorded after the valve opens (0: automatic)")
    valve_close_time: float = _f(
        0.0, "s", 0.0, 36_000.0,
        "close the valve this long after opening: an aborted unload (0: never)")
    # --- sensor imperfections
    noise_std: float = _f(1000.0, "Pa", 0.0, 1e6, "white noise standard deviation")
    noise_ar_rho: float = _f(0.0, "-", 0.0, 0.999, "AR(1) coefficient of correlated noise")
    noise_ar_std: float = _f(0.0, "Pa", 0.0, 1e6, "stationary std of the AR(1) noise")
    quantization: float = _f(0.0, "Pa", 0.0, 1e5, "quantisation step (0: none)")
    full_scale: float = _f(
        0.0, "Pa", 0.0, 1e8, "sensor saturates above this absolute pressure (0: never)")
    transducer_zero: float = _f(0.0, "V", -100.0, 100.0, "transducer output at 0 Pa absolute")
    transducer_sensitivity: float = _f(
        1e-5, "V/Pa", 1e-12, 1.0, "transducer sensitivity (for volts output)")
    seed: int = field(default=0, metadata={"unit": "", "min": 0, "max": 2**31 - 1,
                                           "doc": "random seed of the sensor noise"})

    def __post_init__(self) -> None:
        """Validate ranges and effect names (raises :class:`ConfigError`)."""
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            md = f.metadata
            if f.name == "effects":
                if isinstance(v, str):
                    object.__setattr__(self, "effects", parse_effects(v))
                    v = self.effects
                bad = [e for e in v if e not in EFFECTS]
                if bad:
                    raise ConfigError(
                        f"unknown effect(s) {bad}; known effects: {', '.join(EFFECTS)}")
                object.__setattr__(self, "effects", tuple(dict.fromkeys(v)))
                continue
            if "choices" in md:
                if v not in md["choices"]:
                    raise ConfigError(f"{f.name}={v!r} is not one of {md['choices']}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"{f.name} must be a number, got {v!r}")
            if not math.isfinite(v) or not md["min"] <= v <= md["max"]:
                raise ConfigError(
                    f"{f.name}={v!r} {md['unit']} is outside [{md['min']}, {md['max']}]"
                    f" ({md['doc']})")

    @property
    def gas(self) -> Gas:
        """The gas as a :class:`~pneumatic_unload.physics.Gas`."""
        if self.gas_constant == AIR.gas_constant and self.gamma == AIR.gamma:
            return AIR
        return dataclasses.replace(AIR, name="gas", gas_constant=self.gas_constant,
                                   gamma=self.gamma)

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
            kw["effects"] = parse_effects(kw["effects"])
        if "seed" in kw:
            kw["seed"] = int(kw["seed"])
        return cls(**kw)

    @classmethod
    def describe(cls) -> list[dict[str, Any]]:
        """One dict per field: name, default, unit, min/max or choices, doc."""
        out = []
        for f in dataclasses.fields(cls):
            row = {"name": f.name, "default": f.default, **f.metadata}
            out.append(row)
        return out


def parse_effects(value: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Effect names from a comma-separated string or a sequence ('' or 'none': none)."""
    if isinstance(value, str):
        items = [v.strip() for v in value.split(",")]
    else:
        items = [str(v).strip() for v in value]
    return tuple(v for v in items if v and v != "none")
