"""Lumped tank-discharge model with switchable real-rig effects, and the sensor chain.

The gas in the tank obeys a mass and an energy balance (ideal gas, uniform state):

    dm/dt = -G_out,      d(m c_v T)/dt = -G_out c_p T_up + Q,   p = m R T / V

where G_out is the ISO 6358 flow through the component (times the valve opening fraction)
plus an optional laminar leak, and Q = h A_w (T_wall - T) the wall heat flow. Effects
(:data:`pneumatic_unload.config.EFFECTS`) switch on: ``heat_transfer`` (natural convection
from the tank's V and L/D, or a fixed h*A), ``valve_opening`` (linear ramp of the effective
area), ``leak``, ``pipe_volume`` (an isothermal volume and a series conductance between tank
and component), and on the measured signal ``sensor_lag`` (first order), ``sensor_gain``
and ``sensor_offset``. The sensor chain then adds white and AR(1) noise, quantisation and
saturation. Without effects the model is the paper's isentropic discharge (eq 19-24).

The ODE is integrated with :func:`scipy.integrate.odeint` (LSODA) with the valve events as
critical times. SI units: Pa absolute, K, m^3, s, kg/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import odeint
from scipy.signal import lfilter, lfilter_zi

from pneumatic_unload.config import RigConfig
from pneumatic_unload.physics import (
    G_ACCEL,
    R_LINEAR,
    RHO_N,
    T_N,
    flow_function_scalar,
    tank_geometry,
    tau_exp_eq38,
)

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
    """Automatic record length after the valve opens: 6 tau_exp (eq 38) [s]."""
    tau = tau_exp_eq38(cfg.initial_pressure, cfg.atmosphere, cfg.volume, cfg.conductance,
                       cfg.initial_temperature, cfg.gas)
    if cfg.has("pipe_volume"):
        tau *= 1.0 + cfg.pipe_volume / cfg.volume + cfg.conductance / cfg.pipe_conductance
    if cfg.has("heat_transfer"):
        tau *= 1.2
    return 6.0 * tau + (cfg.valve_opening_time if cfg.has("valve_opening") else 0.0)


def time_grid(cfg: RigConfig) -> FloatArray:
    """Sample instants t_k = k / rate from 0 to pre_time + duration [s]."""
    dur = cfg.duration if cfg.duration > 0 else default_duration(cfg)
    n = math.floor((cfg.pre_time + dur) * cfg.rate) + 1
    return np.arange(n, dtype=float) / cfg.rate


def valve_opening(t: FloatArray, cfg: RigConfig, t_open: float) -> FloatArray:
    """Valve effective-area fraction a(t) [0, 1] at instants t [s]."""
    t = np.asarray(t, dtype=float)
    ramp = cfg.valve_opening_time if cfg.has("valve_opening") else 0.0
    if ramp > 0:
        a = np.clip((t - t_open) / ramp, 0.0, 1.0)
    else:
        a = (t >= t_open).astype(float)
    if cfg.valve_close_time > 0:
        a = np.where(t >= t_open + cfg.valve_close_time, 0.0, a)
    return a


def _make_rhs(cfg: RigConfig, t_open: float) -> Any:
    """Right-hand side f(t, y) of the discharge ODE (plain floats for speed)."""
    gas = cfg.gas
    r_gas, gamma = gas.gas_constant, gas.gamma
    cp = gas.cp
    vol = cfg.volume
    p_atm = cfg.atmosphere
    t_wall = cfg.wall_temperature
    b, m = cfg.critical_ratio, cfg.subsonic_index
    c_rho = cfg.conductance * RHO_N
    ramp = cfg.valve_opening_time if cfg.has("valve_opening") else 0.0
    t_close = t_open + cfg.valve_close_time if cfg.valve_close_time > 0 else math.inf
    leak = cfg.leak_coefficient if cfg.has("leak") else 0.0
    heat = cfg.has("heat_transfer")
    natural = cfg.heat_transfer_mode == "natural"
    h_a_fixed = cfg.heat_transfer_coefficient
    length, _d, area = tank_geometry(vol, cfg.length_diameter_ratio)
    # natural convection: h A = A k/L 0.59 Ra^0.25, Ra = g |dT|/T L^3 rho^2 c_p/(mu k)
    ra_const = G_ACCEL * length**3 * cp / (gas.viscosity * gas.conductivity * r_gas**2)
    hk = area * gas.conductivity / length * cfg.heat_transfer_scale
    pipe = cfg.has("pipe_volume")
    v2 = cfg.pipe_volume
    cp_rho = cfg.pipe_conductance * RHO_N
    sq_tn = math.sqrt(T_N)
    phi = flow_function_scalar
    r_lin = R_LINEAR

    def opening(t: float) -> float:
        if t < t_open or t >= t_close:
            return 0.0
        if ramp > 0.0 and t < t_open + ramp:
            return (t - t_open) / ramp
        return 1.0

    def rhs(t: float, y: FloatArray) -> list[float]:
        p1 = y[0]
        t1 = y[1]
        a = opening(t)
        if pipe:
            p2 = y[2]
            g1 = cp_rho * p1 * sq_tn / math.sqrt(t1) * phi(p2 / p1, 0.5, 0.5, r_lin)
            g2 = a * c_rho * p2 * sq_tn / math.sqrt(t_wall) * phi(p_atm / p2, b, m, r_lin) \
                if a > 0.0 else 0.0
            dp2 = r_gas * t_wall / v2 * (g1 - g2)
        else:
            g1 = a * c_rho * p1 * sq_tn / math.sqrt(t1) * phi(p_atm / p1, b, m, r_lin) \
                if a > 0.0 else 0.0
        g_out = g1 + leak * (p1 - p_atm)
        q = 0.0
        if heat:
            dt_w = t_wall - t1
            if natural:
                ra = ra_const * abs(dt_w) / t1 * (p1 / t1) ** 2
                nu = 0.59 * ra**0.25 if ra < 1e9 else 0.10 * ra ** (1.0 / 3.0)
                q = hk * (nu if nu > 1.0 else 1.0) * dt_w
            else:
                q = h_a_fixed * dt_w
        t_up = t1 if g_out >= 0.0 else t_wall
        dp1 = (gamma - 1.0) / vol * (q - g_out * cp * t_up)
        dt1 = t1 / p1 * dp1 + r_gas * t1 * t1 / (p1 * vol) * g_out
        if pipe:
            return [dp1, dt1, dp2]
        return [dp1, dt1]

    return rhs, opening


def discharge(
    cfg: RigConfig, t: FloatArray, t_open: float | None = None, *, rtol: float = 1e-8,
) -> tuple[FloatArray, FloatArray]:
    """Integrate the tank discharge at instants t.

    Parameters
    ----------
    cfg : RigConfig
        Rig, component and effects.
    t : ndarray
        Increasing output instants [s]; the state at t[0] is (p10, T10).
    t_open : float, optional
        Valve opening instant [s]; default ``t[0] + cfg.pre_time``.
    rtol : float
        Relative tolerance of the integrator [-].

    Returns
    -------
    tuple of ndarray
        (tank pressure [Pa absolute], gas temperature [K]) at t.
    """
    t = np.asarray(t, dtype=float)
    if t_open is None:
        t_open = float(t[0]) + cfg.pre_time
    rhs, _ = _make_rhs(cfg, t_open)
    y0 = [cfg.initial_pressure, cfg.initial_temperature]
    atol = [cfg.initial_pressure * rtol * 1e-2, cfg.initial_temperature * rtol * 1e-2]
    if cfg.has("pipe_volume"):
        y0.append(cfg.initial_pressure)
        atol.append(atol[0])
    crit = [t_open]
    if cfg.has("valve_opening") and cfg.valve_opening_time > 0:
        crit.append(t_open + cfg.valve_opening_time)
    if cfg.valve_close_time > 0:
        crit.append(t_open + cfg.valve_close_time)
    tcrit = np.array(sorted(c for c in crit if t[0] <= c <= t[-1]), dtype=float)
    y = odeint(rhs, y0, t, tfirst=True, rtol=rtol, atol=atol, mxstep=200_000,
               tcrit=tcrit if tcrit.size else None, hmax=_hmax(cfg))
    return y[:, 0].copy(), y[:, 1].copy()


def _hmax(cfg: RigConfig) -> float:
    """Largest integrator step [s]: small enough not to step over a short valve ramp."""
    h = 0.0
    if cfg.has("valve_opening") and cfg.valve_opening_time > 0:
        h = cfg.valve_opening_time / 4.0
    return h


def first_order_lag(t: FloatArray, u: FloatArray, tau: float) -> FloatArray:
    """Exact first-order lag y' = (u - y)/tau of a piecewise-linear input, y(t0) = u(t0).

    Parameters
    ----------
    t : ndarray
        Sample instants [s] (increasing).
    u : ndarray
        Input samples [any unit].
    tau : float
        Time constant [s] (0 returns u).

    Returns
    -------
    ndarray
        Lagged samples [same unit as u].
    """
    u = np.asarray(u, dtype=float)
    if tau <= 0 or u.size < 2:
        return u.copy()
    dt = np.diff(t)
    h = float(np.median(dt))
    if np.allclose(dt, h, rtol=1e-6, atol=0.0):
        a = math.exp(-h / tau)
        k = tau / h * (1.0 - a)
        b0, b1 = 1.0 - k, k - a
        zi = lfilter_zi([b0, b1], [1.0, -a]) * u[0]
        y, _ = lfilter([b0, b1], [1.0, -a], u, zi=zi)
        return y
    y = np.empty_like(u)
    y[0] = u[0]
    for i in range(1, u.size):
        hi = dt[i - 1]
        a = math.exp(-hi / tau)
        k = tau / hi * (1.0 - a)
        y[i] = a * y[i - 1] + (1.0 - k) * u[i] + (k - a) * u[i - 1]
    return y


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
    y = first_order_lag(t, p, cfg.sensor_lag) if cfg.has("sensor_lag") else np.asarray(p)
    if cfg.has("sensor_gain"):
        y = y * (1.0 + cfg.sensor_gain)
    if cfg.has("sensor_offset"):
        y = y + cfg.sensor_offset
    return np.asarray(y, dtype=float)


def sensor_noise(n: int, cfg: RigConfig, rng: np.random.Generator) -> FloatArray:
    """White plus stationary AR(1) noise samples [Pa]."""
    e = np.zeros(n)
    if cfg.noise_std > 0:
        e += rng.normal(0.0, cfg.noise_std, n)
    if cfg.noise_ar_std > 0:
        rho = cfg.noise_ar_rho
        w = rng.normal(0.0, cfg.noise_ar_std * math.sqrt(1.0 - rho * rho), n)
        w[0] = rng.normal(0.0, cfg.noise_ar_std)
        e += lfilter([1.0], [1.0, -rho], w)
    return e


def digitise(y: FloatArray, cfg: RigConfig) -> FloatArray:
    """Quantisation and saturation of the sensor output [Pa as indicated]."""
    if cfg.quantization > 0:
        y = np.round(y / cfg.quantization) * cfg.quantization
    if cfg.full_scale > 0:
        y = np.clip(y, 0.0, cfg.full_scale)
    return y


def model_signal(cfg: RigConfig, t: FloatArray, t_open: float, *, rtol: float = 1e-7
                 ) -> FloatArray:
    """Noise-free measured signal of the model: discharge then sensor chain [Pa].

    This is what fits compare with data.

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
    p, _ = discharge(cfg, t, t_open, rtol=rtol)
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
    p, temp = discharge(cfg, t, t_open, rtol=rtol)
    y = sensor_response(t, p, cfg)
    rng = np.random.default_rng(cfg.seed)
    y = digitise(y + sensor_noise(t.size, cfg, rng), cfg)
    return Simulation(t=t, pressure=p, temperature=temp, measured=y,
                      opening=valve_opening(t, cfg, t_open), t_open=t_open, config=cfg)
