# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Randomised synthetic discharges with hidden effects: the acceptance harness's cases.

Conditions (issue #5): 1 kHz, white noise 0.1 % of a 1 MPa full scale (sigma = 1 kPa),
V 1-5 L, p10 4-8 bar abs, C 1e-9..5e-8 m^3/(s Pa) (log-uniform), b 0.3-0.5, 0.2 s of
pre-step samples, record length the simulator's automatic 6 tau_exp. Effect sizes:

* heat_transfer: thermal time constant tau_heat = m0 c_v/(h A) 0.5-5 s (fixed h A);
* hot_start: the same heat transfer, the gas starting 10-40 K above the wall (T_N); the
  workflow is told the gas's T10, not the wall temperature;
* valve_opening: 10-100 ms; sensor_lag: 5-50 ms;
* leak: 2-20 % of the choked flow at p10 (K (p10 - p_atm) = f G_choked(p10));
* leak_downstream (opens with the valve): 5-50 % of the choked flow at p10;
* orifice_leak: C_leak 2-20 % of C, b_leak 0.2-0.5; orifice_leak_downstream: C_leak
  5-50 % of C, b_leak 0.2-0.5;
* pipe_volume: 5-30 % of V, pipe conductance 2-10 times C;
* sensor_offset: 1-10 kPa, sensor_gain: 0.2-2 % (random sign);
* subsonic_index: m 0.25-0.4 or 0.62-0.8 (the ISO 6358-1:2013 law's; 0.5 in the baseline).

The parameter names and mappings are those of
:mod:`pneumatic_unload.model.effects`, so a fitted value compares directly with
the truth. SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import Simulation, simulate
from pneumatic_unload.physics import RHO_N, T_N

#: White-noise standard deviation of the harness: 0.1 % of a 1 MPa full scale [Pa].
NOISE_STD = 1000.0


@dataclass(frozen=True)
class Case:
    """A synthetic trial.

    Attributes
    ----------
    effect : str
        Hidden effect ('none' for effect-free data).
    truth : dict
        True values of the effect's parameters [SI units, see
        :data:`pneumatic_unload.model.effects.REGISTRY`].
    config : RigConfig
        Configuration simulated (noise included).
    seed : int
        Seed of the draw.
    """

    effect: str
    truth: dict[str, float]
    config: RigConfig
    seed: int

    def simulate(self) -> Simulation:
        """The noisy recorded trace."""
        return simulate(self.config)

    def noise_free(self) -> Simulation:
        """The same trace without noise."""
        return simulate(self.config.replace(noise_std=0.0, noise_ar_std=0.0))


def draw_case(effect: str, seed: int, *, rho: float = 0.0, noise_std: float = NOISE_STD
              ) -> Case:
    """Draw a randomised rig with one hidden effect.

    Parameters
    ----------
    effect : str
        Effect name or 'none'.
    seed : int
        Seed (the draw and the noise).
    rho : float
        AR(1) coefficient of the noise; when > 0 the noise is pure AR(1) with marginal
        standard deviation ``noise_std`` [-].
    noise_std : float
        Noise standard deviation [Pa].
    """
    rng = np.random.default_rng(seed)
    vol = rng.uniform(1e-3, 5e-3)
    p10 = rng.uniform(4e5, 8e5)
    c = math.exp(rng.uniform(math.log(1e-9), math.log(5e-8)))
    b = rng.uniform(0.3, 0.5)
    t10 = T_N
    kw: dict[str, object] = {}
    truth: dict[str, float] = {}
    gamma = 1.4
    t_wall = T_N
    sim_effects: tuple[str, ...] = () if effect == "none" else (effect,)
    if effect in ("heat_transfer", "hot_start"):
        tau = rng.uniform(0.5, 5.0)
        truth["tau_heat"] = tau
        if effect == "hot_start":
            t10 = T_N + rng.uniform(10.0, 40.0)
            truth["t_wall"] = t_wall
            sim_effects = ("heat_transfer",)
        kw.update(heat_transfer_mode="fixed",
                  heat_transfer_coefficient=p10 * vol / ((gamma - 1.0) * t10 * tau))
    elif effect == "valve_opening":
        truth["t_ramp"] = rng.uniform(0.01, 0.1)
        kw["valve_opening_time"] = truth["t_ramp"]
    elif effect == "sensor_lag":
        truth["tau_sensor"] = rng.uniform(0.005, 0.05)
        kw["sensor_lag"] = truth["tau_sensor"]
    elif effect == "leak":
        f = rng.uniform(0.02, 0.2)
        truth["leak_fraction"] = f
        g0 = c * RHO_N * p10 * math.sqrt(T_N / t10)
        kw["leak_coefficient"] = f * g0 / (p10 - 101325.0)
    elif effect == "leak_downstream":
        f = rng.uniform(0.05, 0.5)
        truth["leak_downstream_fraction"] = f
        g0 = c * RHO_N * p10 * math.sqrt(T_N / t10)
        kw["leak_downstream_coefficient"] = f * g0 / (p10 - 101325.0)
    elif effect in ("orifice_leak", "orifice_leak_downstream"):
        ratio = rng.uniform(0.02, 0.2) if effect == "orifice_leak" else rng.uniform(0.05, 0.5)
        truth[f"{effect}_ratio"] = ratio
        truth[f"{effect}_b"] = rng.uniform(0.2, 0.5)
        kw[f"{effect}_conductance"] = ratio * c
        kw[f"{effect}_critical_ratio"] = truth[f"{effect}_b"]
    elif effect == "pipe_volume":
        truth["pipe_volume_ratio"] = rng.uniform(0.05, 0.3)
        truth["pipe_conductance_ratio"] = rng.uniform(2.0, 10.0)
        kw["pipe_volume"] = truth["pipe_volume_ratio"] * vol
        kw["pipe_conductance"] = truth["pipe_conductance_ratio"] * c
    elif effect == "sensor_offset":
        truth["offset"] = rng.uniform(1e3, 1e4) * rng.choice([-1.0, 1.0])
        kw["sensor_offset"] = truth["offset"]
    elif effect == "sensor_gain":
        truth["gain"] = rng.uniform(0.002, 0.02) * rng.choice([-1.0, 1.0])
        kw["sensor_gain"] = truth["gain"]
    elif effect == "subsonic_index":
        truth["m"] = rng.choice([rng.uniform(0.25, 0.4), rng.uniform(0.62, 0.8)])
        kw["subsonic_index"] = truth["m"]
        sim_effects = ()  # a field of the configuration, no effect of the simulator
    elif effect != "none":
        raise ValueError(f"unknown effect {effect!r}")
    noise: dict[str, float] = {"noise_std": noise_std}
    if rho > 0:
        noise = {"noise_std": 0.0, "noise_ar_std": noise_std, "noise_ar_rho": rho}
    cfg = RigConfig(volume=vol, conductance=c, critical_ratio=b, initial_pressure=p10,
                    initial_temperature=t10, wall_temperature=t_wall, rate=1000.0,
                    pre_time=0.2, effects=sim_effects,
                    seed=int(rng.integers(0, 2**31 - 1)), **noise, **kw)  # type: ignore[arg-type]
    return Case(effect=effect, truth=truth, config=cfg, seed=seed)
