# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Model inversion at the p* crossing: the C for which the discharge model reaches p* at the
measured tau_exp, directly (a secant on log t(C)) or from a table of the model's crossing
times built half way to p* (so that the live estimate is a lookup at the crossing sample).

The model is the estimator's :class:`~pneumatic_unload.model.parametric.ParametricModel`
(natural-convection wall heat transfer from the tank's V and L/D, or adiabatic). SI units:
s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import RigConfig
from pneumatic_unload.config.estimator import EstimatorSettings, wall_uncertainty, with_wall
from pneumatic_unload.config.tank import wall_pair
from pneumatic_unload.model import discharge
from pneumatic_unload.model.effects import Start
from pneumatic_unload.model.parametric import (
    FLOW_SHAPES,
    ISO_ELLIPSE_EXPONENT,
    SUBSONIC_INDEX_START,
    ParametricModel,
)
from pneumatic_unload.physics import P_STAR_FRACTION, isentropic_crossing_time

FloatArray = NDArray[np.float64]

#: Relative 1-sigma uncertainty assumed for the natural-convection correlation [-].
HEAT_CORRELATION_REL_STD = 0.3
#: 1-sigma of the critical pressure ratio b about the settings' value at the crossing,
#: where the data do not yet show b [-] (orifices 0.3-0.5, valves 0.2-0.4).
CRITICAL_RATIO_PRIOR_STD = 0.1

def estimator_model(settings: EstimatorSettings, start: Start, *,
                    p_atm: float | None = None, heat_law: str = "natural",
                    fit_wall: bool = False, fit_m: bool = False,
                    fit_offset: bool = False, thermometer: bool = False,
                    fit_t10: bool = False, thermometer_offset: bool = False,
                    shape: str = "iso") -> ParametricModel:
    """The parametric model of the estimator: heat transfer (``heat_law``, and the wall
    temperature as a parameter with ``fit_wall``) or none; the subsonic index m a parameter
    with ``fit_m`` (else held at 0.5); the transducer's zero offset a parameter ('offset'
    [Pa]) with ``fit_offset``; T10 and a thermometer's lag parameters with ``thermometer``
    (a logged gas temperature fitted beside), and its offset [K] with
    ``thermometer_offset``; T10 alone with ``fit_t10``; the flow curve's ``shape``:
    'iso' (ISO 6358-1), 'q' (the ellipse's exponent q a parameter) or 'series' (two ISO
    elements in series, :class:`ParametricModel`'s ``series``)."""
    if shape not in FLOW_SHAPES:
        raise ValueError(f"unknown flow-curve shape {shape!r}; known: {FLOW_SHAPES}")
    effects: tuple[str, ...] = ("heat_transfer",) if settings.heat_model == "natural" else ()
    if fit_offset:
        effects = (*effects, "sensor_offset")
    charge = None
    tank = settings.tank
    if settings.charge:  # p_atm: the end level, the supply's
        charge = (settings.supply_pressure if p_atm is None else p_atm,
                  settings.supply_gas_temperature)
    elif p_atm is not None:
        tank = dataclasses.replace(settings.tank, atmosphere=p_atm)
    return ParametricModel(effects, tank, start, heat_law=heat_law,
                           fit_wall_temperature=fit_wall and bool(effects),
                           subsonic_index=None if fit_m else SUBSONIC_INDEX_START,
                           ellipse_exponent=None if shape == "q" else ISO_ELLIPSE_EXPONENT,
                           series=shape == "series",
                           thermometer=thermometer, fit_initial_temperature=fit_t10,
                           thermometer_offset=thermometer_offset, charge=charge)


def rig_from_settings(settings: EstimatorSettings, *, conductance: float, p10: float,
                      p_atm: float, critical_ratio: float | None = None,
                      heat_scale: float = 1.0) -> RigConfig:
    """The discharge-model configuration the estimator assumes [SI].

    Parameters
    ----------
    settings : EstimatorSettings
        Tank and gas settings.
    conductance : float
        C [m^3/(s Pa)].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    critical_ratio : float, optional
        b [-]; default the settings' value.
    heat_scale : float
        Multiplier on the natural-convection correlation [-].
    """
    b = settings.critical_ratio if critical_ratio is None else critical_ratio
    return _configuring_model(settings, p_atm).config(
        {"C": conductance, "b": b, "t_open": 0.0, "p10": p10, "p_atm": p_atm,
         "heat_scale": heat_scale})


@functools.lru_cache(maxsize=16)
def _configuring_model(settings: EstimatorSettings, p_atm: float) -> ParametricModel:
    """The estimator's model of one settings and p_atm [Pa], kept: its configurations are
    then built by checking only the values that change (an inversion builds dozens)."""
    start = Start(conductance=1e-8, critical_ratio=settings.critical_ratio, t_open=0.0,
                  p10=5e5, p_atm=p_atm, tau=1.0, dt=1e-3, t_first=0.0, t_last=1.0)
    return estimator_model(settings, start, p_atm=p_atm)


def model_crossing_time(cfg: RigConfig, p_star: float, t_guess: float, *,
                        rtol: float = 1e-7) -> float:
    """Time for the model's tank pressure to fall from p10 to p_star [s] (to rise to it,
    for a charge's configuration).

    Parameters
    ----------
    cfg : RigConfig
        Model (valve opens at t = 0).
    p_star : float
        Threshold [Pa absolute].
    t_guess : float
        Expected crossing time [s] (sets the output grid: the integration stops at
        1.25 t_guess unless the crossing lies beyond).
    rtol : float
        Integrator relative tolerance [-].
    """
    horizon = 1.25 * t_guess
    for _ in range(8):
        t = np.linspace(0.0, horizon, 129)
        p, _ = discharge(cfg, t, 0.0, rtol=rtol)
        k = np.flatnonzero(p > p_star if cfg.direction == "charge" else p < p_star)
        if k.size:
            j = int(k[0])
            j0 = min(max(j - 1, 1), t.size - 2)
            # quadratic through three points around the crossing, solved for p = p_star
            tt, pp = t[j0 - 1:j0 + 2], p[j0 - 1:j0 + 2]
            c2, c1, c0 = np.polyfit(tt - tt[1], pp, 2)
            disc = c1 * c1 - 4 * c2 * (c0 - p_star)
            if abs(c2) > 0 and disc >= 0:
                r = [(-c1 + s * math.sqrt(disc)) / (2 * c2) for s in (1.0, -1.0)]
                x = min(r, key=lambda v: abs(v - (t[j] - tt[1])))
            else:
                x = (p_star - c0) / c1
            return float(tt[1] + x)
        horizon *= 2.0
    return math.inf


#: Relative tolerance on C of :func:`invert_crossing` (far below any stated uncertainty).
INVERSION_RTOL = 1e-6


def model_range(name: str) -> tuple[float, float]:
    """Bounds of a :class:`RigConfig` field: the discharge model's range [its unit]."""
    md = next(f for f in dataclasses.fields(RigConfig) if f.name == name).metadata
    return float(md["min"]), float(md["max"])


#: log of the discharge model's range of C [log m^3/(s Pa)]: the inversion answers NaN
#: when the measured tau_exp needs a C outside it.
LOG_C_RANGE = tuple(math.log(v) for v in model_range("conductance"))


def in_model_range(p10: float, p_atm: float, *, charge: bool = False) -> bool:
    """True when the model covers p10 and p_atm [Pa absolute] (a charge's p_atm: its
    supply; it would clip them to its range, and answer for other pressures than those
    measured)."""
    lo, hi = model_range("initial_pressure")
    a_lo, a_hi = model_range("supply_pressure" if charge else "atmosphere")
    return lo <= p10 <= hi and a_lo <= p_atm <= a_hi
#: Integrator tolerance of the inversion: crossing times to about 1e-6 relative [-].
INVERSION_ODE_RTOL = 1e-6


def may_turn_subsonic(settings: EstimatorSettings, p_atm: float, p_star: float) -> bool:
    """True when, for a b within 2 sigma of its prior, the flow turns subsonic before p*.

    The flow is choked while p1 >= p_atm/b: the smaller b, the earlier it turns subsonic.

    Parameters
    ----------
    settings : EstimatorSettings
        Its ``critical_ratio`` is the prior mean of b [-].
    p_atm, p_star : float
        Atmospheric and crossing pressures [Pa absolute].
    """
    b_lo = max(settings.critical_ratio - 2.0 * CRITICAL_RATIO_PRIOR_STD, 0.01)
    return p_star < p_atm / b_lo


def model_conductance(settings: EstimatorSettings, tau_exp: float, *, p10: float,
                      p_atm: float, p_star: float, c_start: float) -> float:
    """C [m^3/(s Pa)] for which the model of the settings (their heat law and direction: a
    charge's p_atm is its supply) reaches p_star at tau_exp [s] after the opening, by a
    secant on log t(C) - log tau_exp from ``c_start`` (pressures [Pa absolute]); NaN when
    the model does not cover the pressures (:func:`in_model_range`) or no C in its range
    (:data:`LOG_C_RANGE`) does."""
    if not (math.isfinite(tau_exp) and tau_exp > 0 and math.isfinite(c_start) and c_start > 0
            and in_model_range(p10, p_atm, charge=settings.charge)):
        return math.nan

    def g(log_c: float) -> float:
        """log(model crossing time / tau_exp) at C = exp(log_c)."""
        cfg = rig_from_settings(settings, conductance=math.exp(log_c), p10=p10, p_atm=p_atm)
        tm = model_crossing_time(cfg, p_star, tau_exp, rtol=INVERSION_ODE_RTOL)
        return math.log(tm / tau_exp) if math.isfinite(tm) and tm > 0 else math.nan

    x0 = math.log(c_start)
    lo, hi = LOG_C_RANGE
    if not lo <= x0 <= hi:
        return math.nan
    f0 = g(x0)
    if not math.isfinite(f0):
        return math.nan
    x1 = x0 + f0  # exact for t proportional to 1/C
    for _ in range(8):
        if not lo <= x1 <= hi:  # the model (which clips C) has no such C
            return math.nan
        f1 = g(x1)
        if not math.isfinite(f1):
            return math.nan
        if abs(f1) < INVERSION_RTOL:
            break
        slope = (f1 - f0) / (x1 - x0) if x1 != x0 else -1.0
        if not slope < -0.2:  # t(C) falls with C; guard against a flat or noisy secant
            slope = -1.0
        x0, f0, x1 = x1, f1, x1 - f1 / slope
    return math.exp(x1)


def invert_crossing(
    tau_exp: float, tau_std: float, *, p10: float, p_atm: float, p_star: float,
    settings: EstimatorSettings, c_start: float,
) -> tuple[float, float]:
    """C for which the discharge model crosses p_star at tau_exp, and its 1-sigma [m^3/(s Pa)].

    The model's crossing time is nearly proportional to 1/C (exactly so without heat
    transfer), so a secant iteration on log t(C) - log tau_exp converges in two or three
    integrations (this runs inside the live estimator, at the sample that completes the
    estimate). The standard deviation combines the timing uncertainty and, for the
    natural-convection model, the uncertainty of the heat-transfer correlation
    (:data:`HEAT_CORRELATION_REL_STD`). (NaN, NaN) when the model does not cover p10 and
    p_atm (:func:`in_model_range`) or no C in its range (:data:`LOG_C_RANGE`) crosses
    p_star at tau_exp.

    Parameters
    ----------
    tau_exp, tau_std : float
        Measured unloading time and its standard deviation [s].
    p10, p_atm, p_star : float
        Pressures [Pa absolute].
    settings : EstimatorSettings
        Tank and gas settings.
    c_start : float
        Starting value, e.g. the isentropic inversion [m^3/(s Pa)].
    """
    c = model_conductance(settings, tau_exp, p10=p10, p_atm=p_atm, p_star=p_star,
                          c_start=c_start)
    if not math.isfinite(c):
        return math.nan, math.nan
    var = (c * tau_std / tau_exp) ** 2
    b0, b_sd = settings.critical_ratio, CRITICAL_RATIO_PRIOR_STD
    if may_turn_subsonic(settings, p_atm, p_star):
        # the flow may turn subsonic before p*, where b matters and is not yet measured:
        # the spread of the model's crossing time over b +- 1 sigma enters the variance
        worst = 0.0
        for b in (b0 - b_sd, b0 + b_sd):
            if 0.0 < b < 0.99:
                cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm,
                                        critical_ratio=b)
                tm = model_crossing_time(cfg, p_star, tau_exp, rtol=INVERSION_ODE_RTOL)
                if math.isfinite(tm):
                    worst = max(worst, abs(tm / tau_exp - 1.0))
        var += (c * worst) ** 2
    if settings.heat_model == "natural":
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm,
                                heat_scale=1.0 + HEAT_CORRELATION_REL_STD)
        tm = model_crossing_time(cfg, p_star, tau_exp, rtol=INVERSION_ODE_RTOL)
        var += (c * (tm / tau_exp - 1.0)) ** 2
    return c, math.sqrt(var)


#: Grid of the inversion table: points and half-width in log C around the guess [-].
TABLE_POINTS, TABLE_SPAN = 7, 0.7


@dataclass(frozen=True)
class InversionTable:
    """The model's crossing time t(C) tabulated before the crossing, so that the inversion
    at the crossing is a lookup (the live estimator publishes it at that sample).

    Built when the pressure is half way to p* (:func:`inversion_table`): V, T10, p10, p_atm
    and p* are known then, and the time so far gives C to within the bias of eq 39 (a few
    tens of per cent), which a grid of :data:`TABLE_POINTS` values of C over
    exp(+-:data:`TABLE_SPAN`) around it covers. log C is interpolated as a cubic in
    log t through the four nearest points (the curve is nearly a line of slope -1: exactly
    so without heat transfer), which reproduces the iterative inversion to ~1e-7.

    Attributes
    ----------
    log_c, log_t : ndarray
        Grid: log C [log m^3/(s Pa)] and log of the model's crossing time [log s]
        (decreasing).
    rel_heat : ndarray
        Relative change of the crossing time when the natural-convection correlation is
        :data:`HEAT_CORRELATION_REL_STD` stronger [-] at the first, middle and last grid
        points (zeros when adiabatic); interpolated linearly in log C.
    rel_b : float
        Largest relative change of the crossing time for b one prior sigma either way [-]
        (0 when the flow stays choked to p* for every plausible b).
    rel_wall : float
        Relative change of the crossing time per the wall temperature moved by its
        uncertainty (half the change from -u to +u, u of
        :func:`~pneumatic_unload.config.estimator.wall_uncertainty`) at
        the middle grid point [-]; NaN when adiabatic (no heat law, no wall term).
    """

    log_c: FloatArray
    log_t: FloatArray
    rel_heat: FloatArray
    rel_b: float
    rel_wall: float = math.nan

    def __post_init__(self) -> None:
        # the grid as Python floats: the lookup runs inside the live crossing's latency,
        # where numpy's per-call cost on 7 points exceeds the arithmetic
        ys = [float(v) for v in self.log_t]
        xs = [float(v) for v in self.log_c]
        object.__setattr__(self, "_ys", ys)
        object.__setattr__(self, "_neg", [-v for v in ys])  # ascending
        # each window of four nodes' Lagrange terms: (x_a, the other three y, the
        # denominator), the very products the interpolation would form at the crossing
        windows = []
        for j in range(max(len(ys) - 3, 0)):
            w = ys[j:j + 4]
            terms = []
            for a in range(4):
                o = [w[b] for b in range(4) if b != a]
                terms.append((xs[j + a], o[0], o[1], o[2],
                              (w[a] - o[0]) * (w[a] - o[1]) * (w[a] - o[2])))
            windows.append(terms)
        object.__setattr__(self, "_windows", windows)
        ends = self.log_c[[0, self.log_c.size // 2, -1]] if self.log_c.size else ()
        object.__setattr__(self, "_heat", ([float(v) for v in ends],
                                           [float(v) for v in self.rel_heat]))

    def covers(self, tau: float) -> bool:
        """True when tau [s] lies inside the tabulated range."""
        return bool(math.isfinite(tau) and tau > 0
                    and self._ys[-1] <= math.log(tau) <= self._ys[0])

    def _interpolate(self, tau: float) -> tuple[float, float]:
        """log C and d log C / d log t at the crossing time tau [s] (Lagrange cubic)."""
        y = math.log(tau)
        k = bisect.bisect_left(self._neg, -y)  # type: ignore[attr-defined]
        j = min(max(k - 2, 0), len(self._ys) - 4)  # type: ignore[attr-defined]
        x, dxdy = 0.0, 0.0
        for xa, o0, o1, o2, den in self._windows[j]:  # type: ignore[attr-defined]
            # the Lagrange cubic x(y) and its derivative
            d0, d1, d2 = y - o0, y - o1, y - o2
            x += xa * (d0 * d1 * d2) / den
            dxdy += xa * (d1 * d2 + d0 * d2 + d0 * d1) / den
        return x, dxdy

    def lookup(self, tau: float, tau_std: float) -> tuple[float, float, float]:
        """C, its 1-sigma and its standard uncertainty from the wall temperature (NaN when
        adiabatic) [m^3/(s Pa)] for a measured tau_exp and its 1-sigma [s]: one
        interpolation for the three (see :meth:`invert` and :meth:`wall_std`)."""
        x, dxdy = self._interpolate(tau)
        if not (math.isfinite(x) and abs(x) < 700.0):  # no C of a tank there
            return math.nan, math.nan, math.nan
        c = math.exp(x)
        ends, heat = self._heat  # type: ignore[attr-defined]
        rel_heat = _interp(x, ends, heat)
        var = (c * dxdy * tau_std / tau) ** 2 + (c * self.rel_b) ** 2 + (c * rel_heat) ** 2
        wall = c * abs(dxdy) * self.rel_wall if math.isfinite(self.rel_wall) else math.nan
        return c, math.sqrt(var), wall

    def invert(self, tau: float, tau_std: float) -> tuple[float, float]:
        """C and its 1-sigma [m^3/(s Pa)] for a measured tau_exp and its 1-sigma [s]."""
        c, std, _wall = self.lookup(tau, tau_std)
        return c, std

    def wall_std(self, tau: float) -> float:
        """C's standard uncertainty from the wall temperature [m^3/(s Pa)] at the crossing
        time tau [s]: the crossing time's relative change (:attr:`rel_wall`) through the
        slope of log C in log t; NaN when adiabatic."""
        return self.lookup(tau, 0.0)[2]


def _interp(x: float, xs: list[float], ys: list[float]) -> float:
    """Piecewise-linear interpolation of (xs ascending, ys) at x, held constant beyond the
    ends (numpy's interp on a few Python floats, without its per-call cost) [unit of ys]."""
    if not xs:
        return math.nan
    if not x > xs[0]:
        return ys[0] if x == x else math.nan
    for k in range(1, len(xs)):
        if x <= xs[k]:
            x0, x1 = xs[k - 1], xs[k]
            return ys[k - 1] + (ys[k] - ys[k - 1]) * ((x - x0) / (x1 - x0)) if x1 > x0 \
                else ys[k]
    return ys[-1]


def inversion_table(settings: EstimatorSettings, *, p10: float, p_atm: float, p_star: float,
                    c_guess: float) -> InversionTable | None:
    """Tabulate the model's crossing time around ``c_guess`` (see :class:`InversionTable`).

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and heat model.
    p10, p_atm, p_star : float
        Pressures [Pa absolute].
    c_guess : float
        Expected C [m^3/(s Pa)] (e.g. the isentropic inversion half way to p*).

    Returns
    -------
    InversionTable or None
        None when a crossing time cannot be computed (the model never reaches p*, or does
        not cover p10 and p_atm).
    """
    if not (math.isfinite(c_guess) and c_guess > 0 and in_model_range(p10, p_atm)):
        return None
    gas, vol, t10 = settings.gas, settings.volume, settings.initial_temperature
    log_c = math.log(c_guess) + np.linspace(-TABLE_SPAN, TABLE_SPAN, TABLE_POINTS)
    times = []
    for lc in log_c:
        c = math.exp(lc)
        guess = isentropic_crossing_time(p_star, p10, vol, c, t10, gas)
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm)
        tm = model_crossing_time(cfg, p_star, guess, rtol=INVERSION_ODE_RTOL)
        if not (math.isfinite(tm) and tm > 0):
            return None
        times.append(tm)
    log_t = np.log(np.array(times))
    # the time falls about as 1/C (slope -1 in log-log): a grid where it falls far less
    # (a model pinned at the end of its range, e.g. a 0.1 mL tank at 150 K) cannot be
    # interpolated (near-equal nodes blow the cubic up): no table, the inversion iterates
    if not np.all(np.diff(log_t) < -0.25 * (log_c[1] - log_c[0])):
        return None
    t_mid = times[TABLE_POINTS // 2]
    rel_b = 0.0
    rel_heat = np.zeros(3)
    if settings.heat_model == "natural":
        for j, g in enumerate((0, TABLE_POINTS // 2, TABLE_POINTS - 1)):
            cfg = rig_from_settings(settings, conductance=math.exp(log_c[g]), p10=p10,
                                    p_atm=p_atm, heat_scale=1.0 + HEAT_CORRELATION_REL_STD)
            tm = model_crossing_time(cfg, p_star, times[g], rtol=INVERSION_ODE_RTOL)
            rel_heat[j] = abs(tm / times[g] - 1.0) if math.isfinite(tm) else math.inf
    if may_turn_subsonic(settings, p_atm, p_star):
        b0, b_sd = settings.critical_ratio, CRITICAL_RATIO_PRIOR_STD
        for b in (b0 - b_sd, b0 + b_sd):
            if 0.0 < b < 0.99:
                cfg = rig_from_settings(settings, conductance=c_guess, p10=p10,
                                        p_atm=p_atm, critical_ratio=b)
                tm = model_crossing_time(cfg, p_star, t_mid, rtol=INVERSION_ODE_RTOL)
                if math.isfinite(tm):
                    rel_b = max(rel_b, abs(tm / t_mid - 1.0))
    rel_wall = math.nan
    if settings.heat_model == "natural":
        # the wall temperature's term of the budget, tabulated here so that the crossing
        # (and the final fit's budget) need no model run for it
        u = wall_uncertainty(settings)[0]
        walls = wall_pair(settings.wall, u)
        tw = []
        for wall in walls:
            moved = with_wall(settings, wall)
            cfg = rig_from_settings(moved, conductance=math.exp(log_c[TABLE_POINTS // 2]),
                                    p10=p10, p_atm=p_atm)
            tw.append(model_crossing_time(cfg, p_star, t_mid, rtol=INVERSION_ODE_RTOL))
        if all(math.isfinite(x) for x in tw):
            # the slope over the (possibly one-sided) pair, times u
            rel_wall = 0.0 if walls[0] == walls[1] else \
                abs(tw[0] - tw[1]) / (walls[0] - walls[1]) * u / t_mid
    return InversionTable(log_c=np.asarray(log_c), log_t=log_t, rel_heat=rel_heat,
                          rel_b=rel_b, rel_wall=rel_wall)


def fitted_tau_exp(cfg: RigConfig, t_guess: float) -> float:
    """tau_exp of a fitted model: its p* crossing (eq 40 with its p10, p_atm; a charge's
    with its p10 and supply) [s].

    Uses the whole recorded curve rather than the samples near p* and the start, so it is
    less noisy than the measured tau_exp (reported beside it, never instead of it).

    Parameters
    ----------
    cfg : RigConfig
        The fitted model (valve opening at t = 0), e.g.
        :meth:`pneumatic_unload.curvefit.fitting.CurveFit.config`.
    t_guess : float
        Expected crossing time [s] (e.g. the measured tau_exp).
    """
    if not (math.isfinite(t_guess) and t_guess > 0):
        return math.nan
    try:
        rising = cfg.direction == "charge"  # toward the supply
        p10, p_end = cfg.initial_pressure, cfg.supply_pressure if rising else cfg.atmosphere
        ps = p_end + P_STAR_FRACTION * (p10 - p_end)
        tc = model_crossing_time(cfg, ps, t_guess)
        if not math.isfinite(tc):
            return math.nan
        # refine on a fine grid around the first estimate (cubic interpolation error of
        # the coarse grid is ~1e-5 relative)
        tt = np.concatenate(([0.0], np.linspace(0.98 * tc, 1.02 * tc, 801)))
        try:
            pp, _ = discharge(cfg, tt, 0.0, rtol=1e-10)
        except ArithmeticError:  # the integrator's step budget at the fine tolerance
            return tc
        k = np.flatnonzero(pp[1:] > ps if rising else pp[1:] < ps)
        if k.size == 0 or k[0] == 0:
            return tc
        j = int(k[0]) + 1
        return float(tt[j - 1] + (pp[j - 1] - ps) / (pp[j - 1] - pp[j]) * (tt[j] - tt[j - 1]))
    except (ValueError, ArithmeticError):  # no crossing of the fitted model computable
        return math.nan
