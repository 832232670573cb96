# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discharge ODE and its one integrator.

The gas in the tank obeys a mass and an energy balance (ideal gas, uniform state):

    dm/dt = -G_out,      d(m c_v T)/dt = -G_out c_p T_up + Q,   p = m R T / V

where G_out is the ISO 6358 flow through the component (times the valve opening fraction)
plus the optional leaks (upstream of the valve: always open; downstream, in parallel with
the component: times the opening fraction; each laminar or orifice-law), and Q the wall
heat flow of :mod:`pneumatic_unload.model.heat`.
With ``pipe_volume`` an isothermal volume and a series conductance sit between the tank and
the component (a third state, the pipe pressure). Without effects the model is the paper's
isentropic discharge (eq 19-24).

:func:`integrate` is the only integrator of the package: the compiled Dormand-Prince 5(4) of
:mod:`pneumatic_unload.model.kernel` (which also holds the right-hand side) run in segments
between the valve events (opening, end of the opening ramp, closing), so that a short ramp
limits the step size only inside the ramp and a discontinuity is never stepped over. Output
on any increasing grid; this module packs a ``RigConfig`` into the kernel's parameters.
SI units: Pa absolute, K, m^3, s, kg/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

import pneumatic_unload.model.kernel as kernel
from pneumatic_unload.config import RigConfig
from pneumatic_unload.model.heat import heat_parameters, jet_coefficient, time_parameters
from pneumatic_unload.physics import R_LINEAR, RHO_N, T_N

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
    prm = kernel_parameters(cfg, t_open)

    def fraction(t: float) -> float:
        return float(kernel.opening(t, prm[kernel.T_OPEN], prm[kernel.RAMP],
                                    prm[kernel.T_CLOSE]))

    return fraction


def state_size(cfg: RigConfig) -> int:
    """Number of ODE states [-]: (p, T), plus the pipe pressure with ``pipe_volume``."""
    return 3 if cfg.has("pipe_volume") else 2


def initial_state(cfg: RigConfig) -> list[float]:
    """State at the first instant: p10 [Pa], T10 [K] (and the pipe at p10 [Pa])."""
    y0 = [cfg.initial_pressure, cfg.initial_temperature]
    if cfg.has("pipe_volume"):
        y0.append(cfg.initial_pressure)
    return y0


def kernel_parameters(cfg: RigConfig, t_open: float) -> FloatArray:
    """The parameter vector of :func:`pneumatic_unload.model.kernel.rhs` for a configuration.

    Parameters
    ----------
    cfg : RigConfig
        Rig, component and effects.
    t_open : float
        Valve opening instant [s].

    Returns
    -------
    ndarray
        The kernel's slots (gas, tank, component, leak, heat law, pipe, valve schedule), SI.
    """
    gas = cfg.gas
    prm = np.zeros(kernel.N_PARAMETERS)
    prm[kernel.GAMMA] = gas.gamma
    prm[kernel.R_GAS] = gas.gas_constant
    prm[kernel.CP] = gas.cp
    prm[kernel.VOLUME] = cfg.volume
    prm[kernel.P_ATM] = cfg.atmosphere
    prm[kernel.T_WALL] = cfg.wall
    prm[kernel.B_RATIO] = cfg.critical_ratio
    prm[kernel.M_INDEX] = cfg.subsonic_index
    prm[kernel.Q_EXPONENT] = cfg.ellipse_exponent
    prm[kernel.SERIES_KAPPA] = cfg.series_conductance_ratio
    prm[kernel.SERIES_B] = cfg.series_critical_ratio
    prm[kernel.SERIES_M] = cfg.series_subsonic_index
    if cfg.series_conductance_ratio > 0.0:
        prm[kernel.SERIES_X0] = kernel.series_choked(
            cfg.critical_ratio, cfg.subsonic_index, cfg.series_conductance_ratio, R_LINEAR)
    prm[kernel.C_RHO] = cfg.conductance * RHO_N
    prm[kernel.LEAK] = cfg.leak_coefficient if cfg.has("leak") else 0.0
    if cfg.has("leak_downstream"):
        prm[kernel.LEAK_DOWN] = cfg.leak_downstream_coefficient
    if cfg.has("orifice_leak"):
        prm[kernel.OLEAK_C_RHO] = cfg.orifice_leak_conductance * RHO_N
        prm[kernel.OLEAK_B] = cfg.orifice_leak_critical_ratio
    if cfg.has("orifice_leak_downstream"):
        prm[kernel.OLEAK_DOWN_C_RHO] = cfg.orifice_leak_downstream_conductance * RHO_N
        prm[kernel.OLEAK_DOWN_B] = cfg.orifice_leak_downstream_critical_ratio
    (prm[kernel.HEAT_MODE], prm[kernel.HEAT_A], prm[kernel.HEAT_RA],
     prm[kernel.HEAT_TURB]) = heat_parameters(cfg)
    prm[kernel.HEAT_G1], prm[kernel.HEAT_G2], prm[kernel.HEAT_TREF] = time_parameters(cfg)
    if cfg.has("pipe_volume"):
        prm[kernel.PIPE] = 1.0
        prm[kernel.PIPE_VOLUME] = cfg.pipe_volume
        prm[kernel.PIPE_C_RHO] = cfg.pipe_conductance * RHO_N
    prm[kernel.T_OPEN] = t_open
    prm[kernel.RAMP] = opening_ramp(cfg)
    prm[kernel.T_CLOSE] = t_open + cfg.valve_close_time if cfg.valve_close_time > 0 \
        else math.inf
    prm[kernel.R_LIN] = R_LINEAR
    prm[kernel.SQRT_TN] = math.sqrt(T_N)
    if cfg.direction == "charge":
        prm[kernel.CHARGE] = 1.0
        prm[kernel.P_SUPPLY] = cfg.supply_pressure
        prm[kernel.T_SUPPLY] = cfg.supply_temperature
        prm[kernel.HEAT_JET] = jet_coefficient(cfg)
    return prm


def right_hand_side(cfg: RigConfig, t_open: float) -> Callable[[float, FloatArray], FloatArray]:
    """Right-hand side f(t, y) of the discharge ODE (the compiled kernel, callable).

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
    prm = kernel_parameters(cfg, t_open)

    def f(t: float, y: FloatArray) -> FloatArray:
        dy = np.empty(len(y))
        kernel.rhs(float(t), np.asarray(y, dtype=float), prm, dy)
        return dy

    return f


#: Step budget of one segment of :func:`integrate` [-].
MAX_STEPS = 2_000_000


class IntegrationError(ArithmeticError):
    """The integrator could not reach the end of a segment (budget, step size, NaN)."""


def integrate(cfg: RigConfig, t: FloatArray, t_open: float, *, rtol: float = RTOL,
              quiet: bool = False, max_steps: int | None = None) -> FloatArray:
    """Integrate the discharge whose state at the valve opening is (p10, T10) and return it
    at t.

    The state holds at t[0] when t[0] is at or after the opening, or when the gas is at the
    wall's temperature (nothing moves in the closed tank). A gas away from its wall
    exchanges heat in the closed tank before the opening: from an earlier t[0] the
    integration starts from the closed-tank state that reaches (p10, T10) at the opening
    (:func:`_state_before_opening`), so that T10 means the same whatever the record shows
    before the opening.

    Integration runs segment by segment between the valve events of
    :func:`valve_events` with the compiled Dormand-Prince 5(4) of
    :func:`pneumatic_unload.model.kernel.dopri5`, all segments in one call of
    :func:`pneumatic_unload.model.kernel.integrate`; inside the opening ramp the step is
    limited to a quarter of the ramp, elsewhere it follows the dynamics. The output grid
    can be anything increasing (every sample, or a few quadrature nodes per bin): the cost
    depends on the dynamics, not on the number of output instants.

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
        A segment that cannot be integrated (fits exploring extreme parameters) leaves NaN
        from where it stopped instead of raising :class:`IntegrationError`.
    max_steps : int, optional
        Step budget of one segment [-] (default :data:`MAX_STEPS`).

    Returns
    -------
    ndarray
        States at t, shape (len(t), :func:`state_size`): p [Pa absolute], T [K]
        (, pipe pressure [Pa absolute]).
    """
    t = np.asarray(t, dtype=float)
    prm = kernel_parameters(cfg, t_open)
    y = np.asarray(initial_state(cfg), dtype=float)
    atol = y * rtol * 1e-2
    if t.size == 0:
        return np.full((0, y.size), np.nan)
    budget = MAX_STEPS if max_steps is None else int(max_steps)
    if t[0] < t_open and cfg.wall != cfg.initial_temperature and cfg.has("heat_transfer"):
        y = _state_before_opening(y, float(t[0]), t_open, prm, rtol, atol, budget)
    out = np.empty((t.size, y.size))
    ramp = opening_ramp(cfg)
    cuts = [e for e in valve_events(cfg, t_open) if t[0] < e < t[-1]]
    bounds = np.array([float(t[0]), *cuts, float(t[-1])])
    status, done, seg, y_seg = kernel.integrate(y, bounds, t, prm, rtol, atol, t_open, ramp,
                                                budget, out)
    if status != kernel.OK:
        if not quiet:
            why = f"more than {budget:,} steps" if status == kernel.TOO_MANY_STEPS \
                else _FAILURES[status]
            raise IntegrationError(
                f"the discharge ODE could not be integrated from t = {bounds[seg]:g} s to "
                f"{bounds[seg + 1]:g} s ({why}); state at the start {y_seg.tolist()}")
        out[done:] = np.nan
    return out


#: Iterations [-] and tolerance [K] of :func:`_state_before_opening`.
BACK_ITERATIONS, BACK_TOL = 6, 1e-7


def _state_before_opening(y_open: FloatArray, t0: float, t_open: float, prm: FloatArray,
                          rtol: float, atol: FloatArray, max_steps: int) -> FloatArray:
    """The closed tank's state at t0 [s] from which it reaches ``y_open`` (p10 [Pa], T10
    [K], ...) at the opening t_open [s]: the mass is held (p / T constant, and a pipe at the
    tank's pressure), T(t0) found by secant steps on the forward closed-tank integration
    (the heat law is monotonic in T - Tw: the map T(t0) -> T(t_open) is increasing and
    near-linear; exact for a constant hA after one step). A failed integration leaves the
    state at the opening (as before)."""
    t10 = float(y_open[1])
    bounds = np.array([t0, t_open])
    out = np.empty((2, y_open.size))

    def forward(temp: float) -> float:
        y = y_open.copy()
        y[0], y[1] = y_open[0] * temp / t10, temp
        if y.size > 2:
            y[2] = y[0]
        status, *_ = kernel.integrate(y, bounds, bounds, prm, rtol, atol, t_open, 0.0,
                                      max_steps, out)
        return float(out[1, 1]) if status == kernel.OK else math.nan

    a, fa = t10, forward(t10)
    if not math.isfinite(fa):
        return y_open
    wall = float(prm[kernel.T_WALL])
    # first step: the gap to the wall scales (exact for a constant hA)
    b = wall + (t10 - wall) * (a - wall) / (fa - wall) if fa != wall else a
    for _ in range(BACK_ITERATIONS):
        fb = forward(b)
        if not math.isfinite(fb):
            return y_open
        if abs(fb - t10) < BACK_TOL or fb == fa:
            break
        a, fa, b = b, fb, b + (t10 - fb) * (b - a) / (fb - fa)
    y = y_open.copy()
    y[0] = y_open[0] * b / t10
    y[1] = b
    if y.size > 2:
        y[2] = y[0]
    return y


_FAILURES = {kernel.TOO_MANY_STEPS: f"more than {MAX_STEPS:,} steps",
             kernel.STEP_TOO_SMALL: "step size underflow",
             kernel.NOT_FINITE: "non-finite state"}


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
