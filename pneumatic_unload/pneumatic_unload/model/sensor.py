# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The pressure-sensor chain: one implementation, batch and stateful.

True tank pressure -> first-order lag (``sensor_lag``) -> gain (``sensor_gain``) -> offset
(``sensor_offset``) -> white and AR(1) noise -> quantisation -> saturation. The
deterministic part (:func:`sensor_response`) is what fits compare with data; the whole chain
(:class:`SensorChain`) is what the simulator publishes. A :class:`SensorChain` keeps the lag
and noise state across calls, so that the simulator's stream of blocks equals one call on the
whole record (same seed, same numbers). SI units: s, Pa.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

import pneumatic_unload.model.kernel as kernel
from pneumatic_unload.config import RigConfig

FloatArray = NDArray[np.float64]


def _lag_coefficients(h: float, tau: float) -> tuple[float, float, float]:
    """(a, b0, b1) of the exact lag of a linear ramp over a step h [s] (tau [s])."""
    a = math.exp(-h / tau)
    k = tau / h * (1.0 - a)
    return a, 1.0 - k, k - a


def first_order_lag(t: FloatArray, u: FloatArray, tau: float,
                    state: tuple[float, float, float] | None = None
                    ) -> tuple[FloatArray, tuple[float, float, float]]:
    """Exact first-order lag y' = (u - y)/tau of the piecewise-linear interpolant of u.

    Parameters
    ----------
    t : ndarray
        Sample instants [s] (increasing).
    u : ndarray
        Input samples [any unit].
    tau : float
        Time constant [s] (> 0).
    state : tuple, optional
        (t, u, y) of the previous sample [s, unit, unit]; None starts in steady state,
        y(t0) = u(t0).

    Returns
    -------
    tuple
        (lagged samples [unit of u], state after the last sample).
    """
    u = np.asarray(u, dtype=float)
    t = np.asarray(t, dtype=float)
    if u.size == 0:
        return u.copy(), state if state is not None else (math.nan, math.nan, math.nan)
    if state is None:
        state = (float(t[0]), float(u[0]), float(u[0]))
        t_prev, u_prev, y_prev = state
        first_h = 0.0
    else:
        t_prev, u_prev, y_prev = state
        first_h = float(t[0]) - t_prev
    dt = np.diff(t)
    h = float(np.median(dt)) if dt.size else first_h
    uniform = h > 0 and (dt.size == 0 or np.allclose(dt, h, rtol=1e-6, atol=0.0)) and (
        first_h == 0.0 or abs(first_h - h) <= 1e-6 * h)
    if uniform:
        a, b0, b1 = _lag_coefficients(h, tau)
        if first_h == 0.0:  # steady state at the first sample
            zi = np.array([(1.0 - b0) * float(u[0])])
        else:
            zi = np.array([a * y_prev + b1 * u_prev])
        from scipy.signal import lfilter  # local: scipy.signal costs ~0.8 s to import

        y, _ = lfilter([b0, b1], [1.0, -a], u, zi=zi)
    else:  # uneven grid (a fit's quadrature nodes): the compiled loop
        y = kernel.lag(t, u, tau, (t_prev, u_prev, y_prev), first_h == 0.0)
    return y, (float(t[-1]), float(u[-1]), float(y[-1]))


def sensor_response(t: FloatArray, p: FloatArray, cfg: RigConfig) -> FloatArray:
    """Deterministic sensor chain: lag, then gain and offset [Pa as indicated].

    Parameters
    ----------
    t : ndarray
        Sample instants [s].
    p : ndarray
        True pressure [Pa absolute].
    cfg : RigConfig
        Sensor effects switched on in ``cfg.effects``.
    """
    if not any(cfg.has(e) for e in ("sensor_lag", "sensor_gain", "sensor_offset")):
        return np.array(p, dtype=float)  # an ideal sensor (a fit's hot path: no chain)
    return _deterministic(t, p, cfg, None)[0]


def _deterministic(t: FloatArray, p: FloatArray, cfg: RigConfig,
                   lag: tuple[float, float, float] | None
                   ) -> tuple[FloatArray, tuple[float, float, float] | None]:
    """Lag (from state ``lag``), gain and offset of true pressures p [Pa] at t [s]; returns
    (indicated pressure [Pa], lag state after the last sample)."""
    y = np.asarray(p, dtype=float)
    if cfg.has("sensor_lag") and cfg.sensor_lag > 0 and y.size > 0:
        y, lag = first_order_lag(t, y, cfg.sensor_lag, lag)
    if cfg.has("sensor_gain"):
        y = y * (1.0 + cfg.sensor_gain)
    if cfg.has("sensor_offset"):
        y = y + cfg.sensor_offset
    return np.array(y, dtype=float), lag


def digitise(y: FloatArray, cfg: RigConfig) -> FloatArray:
    """Quantisation and saturation of the sensor output [Pa as indicated]."""
    if cfg.quantization > 0:
        y = np.round(y / cfg.quantization) * cfg.quantization
    if cfg.full_scale > 0:
        y = np.clip(y, 0.0, cfg.full_scale)
    return y


class SensorChain:
    """The sensor chain with its state (lag, AR(1) noise, random generator).

    Parameters
    ----------
    seed : int
        Seed of the noise generator [-].
    """

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self._lag: tuple[float, float, float] | None = None
        self._ar = math.nan

    def deterministic(self, t: FloatArray, p: FloatArray, cfg: RigConfig) -> FloatArray:
        """Lag, gain and offset of a block of true pressures [Pa as indicated].

        Parameters
        ----------
        t, p : ndarray
            Sample instants [s] and true pressure [Pa absolute].
        cfg : RigConfig
            Sensor effects.
        """
        y, self._lag = _deterministic(t, p, cfg, self._lag)
        return y

    def noise(self, n: int, cfg: RigConfig) -> FloatArray:
        """White plus stationary AR(1) noise for the next n samples [Pa]."""
        e = np.zeros(n)
        if n == 0:
            return e
        if cfg.noise_std > 0:
            e += self.rng.normal(0.0, cfg.noise_std, n)
        if cfg.noise_ar_std > 0:
            rho = cfg.noise_ar_rho
            w = self.rng.normal(0.0, cfg.noise_ar_std * math.sqrt(1.0 - rho * rho), n)
            if math.isnan(self._ar):  # stationary start
                self._ar = float(self.rng.normal(0.0, cfg.noise_ar_std))
                w[0] = self._ar
                zi = np.zeros(1)
            else:
                zi = np.array([rho * self._ar])
            from scipy.signal import lfilter  # local: scipy.signal costs ~0.8 s to import

            ar, _ = lfilter([1.0], [1.0, -rho], w, zi=zi)
            self._ar = float(ar[-1])
            e += ar
        return e

    def apply(self, t: FloatArray, p: FloatArray, cfg: RigConfig) -> FloatArray:
        """The whole chain on the next block of samples [Pa as indicated].

        Parameters
        ----------
        t, p : ndarray
            Sample instants [s] and true pressure [Pa absolute].
        cfg : RigConfig
            Sensor effects and imperfections.
        """
        y = self.deterministic(t, p, cfg)
        return digitise(y + self.noise(y.size, cfg), cfg)
