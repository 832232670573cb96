# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A simulated discharge as a rig records it: the ODE on the sample grid, then the sensor.

SI units: s, Pa absolute, K.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.ode import integrate, opening_ramp
from pneumatic_unload.model.sensor import SensorChain, sensor_response
from pneumatic_unload.physics import tau_exp_eq38

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Simulation:
    """A simulated discharge, sampled at the sensor instants.

    Attributes
    ----------
    t : ndarray
        Sample instants [s]; the valve opens at ``t_open``.
    pressure : ndarray
        True tank pressure [Pa absolute].
    temperature : ndarray
        True mean gas temperature [K].
    measured : ndarray
        Sensor output [Pa absolute as indicated]: lag, gain, offset, noise, quantisation and
        saturation applied as configured.
    opening : ndarray
        Valve effective-area fraction [0, 1].
    t_open : float
        Valve opening instant [s].
    config : RigConfig
        The configuration simulated.
    """

    t: FloatArray
    pressure: FloatArray
    temperature: FloatArray
    measured: FloatArray
    opening: FloatArray
    t_open: float
    config: RigConfig

    def volts(self) -> FloatArray:
        """Transducer output [V] for the measured signal (affine: zero + sensitivity p)."""
        c = self.config
        return c.transducer_zero + c.transducer_sensitivity * self.measured

    def __iter__(self) -> Any:
        """Unpack as ``t, measured = simulation``."""
        return iter((self.t, self.measured))


def default_duration(cfg: RigConfig) -> float:
    """Automatic record length after the valve opens: 6 tau_exp (eq 38) [s]; a charge's
    from the supply (:func:`~pneumatic_unload.physics.tau_exp_eq38` mirrored), 4 of them
    (within 0.1 % of the supply at their end: its rise is linear while choked)."""
    if cfg.direction == "charge":
        tau = tau_exp_eq38(cfg.supply_pressure, cfg.initial_pressure, cfg.volume,
                           cfg.conductance, cfg.supply_temperature, cfg.gas)
        return 4.0 * tau * (1.2 if cfg.has("heat_transfer") else 1.0) + opening_ramp(cfg)
    tau = tau_exp_eq38(cfg.initial_pressure, cfg.atmosphere, cfg.volume, cfg.conductance,
                       cfg.initial_temperature, cfg.gas)
    if cfg.has("pipe_volume"):
        tau *= 1.0 + cfg.pipe_volume / cfg.volume + cfg.conductance / cfg.pipe_conductance
    if cfg.has("heat_transfer"):
        tau *= 1.2
    return 6.0 * tau + opening_ramp(cfg)


def time_grid(cfg: RigConfig) -> FloatArray:
    """Sample instants t_k = k / rate from 0 to pre_time + duration [s]."""
    dur = cfg.duration if cfg.duration > 0 else default_duration(cfg)
    n = math.floor((cfg.pre_time + dur) * cfg.rate) + 1
    return np.arange(n, dtype=float) / cfg.rate


def valve_opening(t: FloatArray, cfg: RigConfig, t_open: float) -> FloatArray:
    """Valve effective-area fraction a(t) [0, 1] at instants t [s]."""
    t = np.asarray(t, dtype=float)
    ramp = opening_ramp(cfg)
    if ramp > 0:
        a = np.clip((t - t_open) / ramp, 0.0, 1.0)
    else:
        a = (t >= t_open).astype(float)
    if cfg.valve_close_time > 0:
        a = np.where(t >= t_open + cfg.valve_close_time, 0.0, a)
    return a


def model_signal(cfg: RigConfig, t: FloatArray, t_open: float, *, rtol: float = 1e-7
                 ) -> FloatArray:
    """Noise-free measured signal of the model: discharge then sensor chain [Pa].

    Parameters
    ----------
    cfg : RigConfig
        Model configuration (effects included).
    t : ndarray
        Sample instants [s].
    t_open : float
        Valve opening instant [s].
    rtol : float
        Integrator relative tolerance [-].
    """
    p = integrate(cfg, t, t_open, rtol=rtol)[:, 0]
    return sensor_response(t, p, cfg)


def simulate(cfg: RigConfig, t: FloatArray | None = None, *, rtol: float = 1e-8
             ) -> Simulation:
    """Simulate a discharge as a rig records it.

    Parameters
    ----------
    cfg : RigConfig
        Rig, effects and sensor; ``cfg.seed`` seeds the noise.
    t : ndarray, optional
        Sample instants [s]; default :func:`time_grid`.
    rtol : float
        Integrator relative tolerance [-].

    Returns
    -------
    Simulation
        True and measured signals.
    """
    if t is None:
        t = time_grid(cfg)
    t = np.asarray(t, dtype=float)
    t_open = float(t[0]) + cfg.pre_time
    y = integrate(cfg, t, t_open, rtol=rtol)
    p, temp = y[:, 0].copy(), y[:, 1].copy()
    measured = SensorChain(cfg.seed).apply(t, p, cfg)
    return Simulation(t=t, pressure=p, temperature=temp, measured=measured,
                      opening=valve_opening(t, cfg, t_open), t_open=t_open, config=cfg)
