"""The discharge ODE and its one integrator.

The gas in the tank obeys a mass and an energy balance (ideal gas, uniform state):

    dm/dt = -G_out,      d(m c_v T)/dt = -G_out c_p T_up + Q,   p = m R T / V

where G_out is the ISO 6358 flow through the component (times the valve opening fraction)
plus an optional laminar leak, and Q the wall heat flow of :mod:`pneumatic_unload.model.heat`.
With ``pipe_volume`` an isothermal volume and a series conductance sit between the tank and
the component (a third state, the pipe pressure). Without effects the model is the paper's
isentropic discharge (eq 19-24).

:func:`integrate` is the only integrator of the package: LSODA (:func:`scipy.integrate.odeint`)
run in segments between the valve events (opening, end of the opening ramp, closing), so
that a short ramp limits the step size only inside the ramp and a discontinuity is never
stepped over. Output on any increasing grid. SI units: Pa absolute, K, m^3, s, kg/s.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import odeint

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.heat import heat_flow_function
from pneumatic_unload.physics import R_LINEAR, RHO_N, T_N, flow_function_scalar

FloatArray = NDArray[np.float64]

#: Default relative tolerance of :func:`integrate` [-].
RTOL = 1e-8


def valve_events(cfg: RigConfig, t_open: float) -> list[float]:
    """Instants where the valve opening a(t) is not smooth [s]: open, ramp end, close.

    Parameters
    ----------
    cfg : RigConfig
        Valve schedule (``valve_opening`` ramp, ``valve_close_time``).
    t_open : float
        Valve opening instant [s].
    """
    ev = [t_open]
    ramp = opening_ramp(cfg)
    if ramp > 0:
        ev.append(t_open + ramp)
    if cfg.valve_close_time > 0:
        ev.append(t_open + cfg.valve_close_time)
    return sorted(set(ev))


def opening_ramp(cfg: RigConfig) -> float:
    """Duration of the linear opening ramp of the valve [s] (0: a step)."""
    return cfg.valve_opening_time if cfg.has("valve_opening") else 0.0


def opening_fraction(cfg: RigConfig, t_open: float) -> Callable[[float], float]:
    """The valve's effective-area fraction a(t) [0, 1] as a scalar function of t [s].

    Parameters
    ----------
    cfg : RigConfig
        Valve schedule.
    t_open : float
        Valve opening instant [s].
    """
    ramp = opening_ramp(cfg)
    t_close = t_open + cfg.valve_close_time if cfg.valve_close_time > 0 else math.inf

    def opening(t: float) -> float:
        if t < t_open or t >= t_close:
            return 0.0
        if ramp > 0.0 and t < t_open + ramp:
            return (t - t_open) / ramp
        return 1.0

    return opening


def state_size(cfg: RigConfig) -> int:
    """Number of ODE states [-]: (p, T), plus the pipe pressure with ``pipe_volume``."""
    return 3 if cfg.has("pipe_volume") else 2


def initial_state(cfg: RigConfig) -> list[float]:
    """State at the first instant: p10 [Pa], T10 [K] (and the pipe at p10 [Pa])."""
    y0 = [cfg.initial_pressure, cfg.initial_temperature]
    if cfg.has("pipe_volume"):
        y0.append(cfg.initial_pressure)
    return y0


def right_hand_side(cfg: RigConfig, t_open: float
                    ) -> Callable[[float, FloatArray], list[float]]:
    """Right-hand side f(t, y) of the discharge ODE (plain floats for speed).

    Parameters
    ----------
    cfg : RigConfig
        Rig, component and effects.
    t_open : float
        Valve opening instant [s].

    Returns
    -------
    callable
        f(t [s], y = (p [Pa], T [K][, p_pipe [Pa]])) -> dy/dt [Pa/s, K/s[, Pa/s]].
    """
    gas = cfg.gas
    r_gas, gamma = gas.gas_constant, gas.gamma
    cp = gas.cp
    vol = cfg.volume
    p_atm = cfg.atmosphere
    t_wall = cfg.wall
    b, m = cfg.critical_ratio, cfg.subsonic_index
    c_rho = cfg.conductance * RHO_N
    leak = cfg.leak_coefficient if cfg.has("leak") else 0.0
    heat = heat_flow_function(cfg)
    pipe = cfg.has("pipe_volume")
    v2 = cfg.pipe_volume
    cp_rho = cfg.pipe_conductance * RHO_N
    sq_tn = math.sqrt(T_N)
    phi = flow_function_scalar
    r_lin = R_LINEAR
    opening = opening_fraction(cfg, t_open)

    def rhs(t: float, y: FloatArray) -> list[float]:
        p1 = y[0]
        t1 = y[1]
        a = opening(t)
        dp2 = 0.0
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
        q = heat(p1, t1) if heat is not None else 0.0
        t_up = t1 if g_out >= 0.0 else t_wall
        dp1 = (gamma - 1.0) / vol * (q - g_out * cp * t_up)
        dt1 = t1 / p1 * dp1 + r_gas * t1 * t1 / (p1 * vol) * g_out
        if pipe:
            return [dp1, dt1, dp2]
        return [dp1, dt1]

    return rhs


def integrate(cfg: RigConfig, t: FloatArray, t_open: float, *, rtol: float = RTOL,
              quiet: bool = False) -> FloatArray:
    """Integrate the discharge from the state (p10, T10) at t[0] and return it at t.

    Integration runs segment by segment between the valve events of
    :func:`valve_events`; inside the opening ramp the step is limited to a quarter of the
    ramp, elsewhere LSODA chooses it freely. The output grid can be anything increasing
    (every sample, or a few quadrature nodes per bin): the cost depends on the dynamics,
    not on the number of output instants.

    Parameters
    ----------
    cfg : RigConfig
        Rig, component and effects.
    t : ndarray
        Increasing output instants [s] (at least one).
    t_open : float
        Valve opening instant [s].
    rtol : float
        Relative tolerance [-] (absolute tolerances are 1e-2 rtol of p10 and T10).
    quiet : bool
        Silence LSODA's warnings (fits exploring extreme parameters).

    Returns
    -------
    ndarray
        States at t, shape (len(t), :func:`state_size`): p [Pa absolute], T [K]
        (, pipe pressure [Pa absolute]).
    """
    t = np.asarray(t, dtype=float)
    rhs = right_hand_side(cfg, t_open)
    y = np.asarray(initial_state(cfg), dtype=float)
    atol = np.array([cfg.initial_pressure, cfg.initial_temperature]
                    + ([cfg.initial_pressure] if y.size == 3 else [])) * rtol * 1e-2
    out = np.empty((t.size, y.size))
    if t.size == 0:
        return out
    ramp = opening_ramp(cfg)
    cuts = [e for e in valve_events(cfg, t_open) if t[0] < e < t[-1]]
    bounds = [float(t[0]), *cuts, float(t[-1])]
    k = 0
    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore")
        for s in range(len(bounds) - 1):
            a, b = bounds[s], bounds[s + 1]
            last = s == len(bounds) - 2
            j = t.size if last else int(np.searchsorted(t, b, side="left"))
            seg = t[k:j]
            starts_at_a = bool(seg.size) and seg[0] == a
            grid = np.concatenate(([] if starts_at_a else [a], seg, [] if last else [b]))
            in_ramp = ramp > 0 and t_open <= a < t_open + ramp
            if b <= t_open and not any(rhs(a, y)):
                # valve still shut and the gas at rest (no leak, at the wall temperature):
                # the state stays where it is
                ys = np.repeat(y[None, :], grid.size, axis=0)
            elif grid.size > 1:
                ys = odeint(rhs, y, grid, tfirst=True, rtol=rtol, atol=atol, mxstep=200_000,
                            hmax=ramp / 4.0 if in_ramp else 0.0)
            else:
                ys = y[None, :]
            off = 0 if starts_at_a else 1
            out[k:j] = ys[off:off + seg.size]
            y = ys[-1]
            k = j
    return out


def discharge(cfg: RigConfig, t: FloatArray, t_open: float | None = None, *,
              rtol: float = RTOL) -> tuple[FloatArray, FloatArray]:
    """Tank pressure and gas temperature of the discharge at instants t.

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
    y = integrate(cfg, t, t_open, rtol=rtol)
    return y[:, 0].copy(), y[:, 1].copy()
