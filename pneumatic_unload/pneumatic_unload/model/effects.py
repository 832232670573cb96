# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The registry of real-rig effects (the parametric model built from it:
:mod:`pneumatic_unload.model.parametric`).

One :class:`Effect` record per effect says where it sits in the rig, which parameters it
adds (SI unit, bounds, fitted in log or not, the scale of its fitted coordinate, its centre,
a value that switches it off, starting values), how they map onto
:class:`~pneumatic_unload.config.RigConfig`, and which extra data separate it from its
look-alikes. :class:`~pneumatic_unload.model.parametric.ParametricModel` (the baseline: C,
b, t_open, p10 [, p_atm], plus any effects) turns named parameter values into a
configuration and the model's signal; the estimator's curve fit, its model inversion and the
discrepancy workflow all fit it.

Heat transfer has three laws (:mod:`pneumatic_unload.model.heat`): ``natural`` fits the
multiplier ``heat_scale`` [-] on the natural-convection correlation; ``fixed`` fits the
thermal time constant ``tau_heat`` = m0 c_v/(hA) [s] of a constant hA,
m0 = p10 V/(R T10); ``density`` fits that time constant at the initial density and the
exponent ``heat_exponent`` [-] of hA ~ rho^n; ``natural+turbulent`` fits the scale and, on
the correlation's turbulent branch alone, ``heat_turbulent`` [-] (the published
coefficients differ by 30 %).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import EFFECTS, TankSpec
from pneumatic_unload.model.separation import (  # re-exported: the advice on look-alikes
    DOWNSTREAM_LEAKS,
    PLUGGED_RUN,
    SEPARATING_DATA,
    separating_data,
)
from pneumatic_unload.physics import RHO_N, T_N

FloatArray = NDArray[np.float64]

__all__ = [
    "CANDIDATES",
    "DOWNSTREAM_LEAKS",
    "HOT_START",
    "PLUGGED_RUN",
    "REGISTRY",
    "SEPARATING_DATA",
    "SUBSONIC",
    "Effect",
    "EffectParam",
    "Start",
    "exchange_extremes",
    "separating_data",
]

#: Integrator tolerance of every fit of the parametric model [-]: the model error (~1e-8
#: p10, well under a Pa) stays far below the noise and below the finite-difference steps of
#: the engine (:data:`pneumatic_unload.fit.lsq.DIFF_STEP`, ~1e-4 relative).
FIT_RTOL = 1e-8
#: Step budget of one segment of a fit's model evaluation [-]: a discharge takes hundreds
#: to a few thousand steps; a fit exploring an extreme corner (a critical ratio at its lower
#: bound makes the flow's end a square-root singularity) took up to the simulator's 2 M,
#: 0.2-0.5 s per evaluation and minutes per fit (bench_fuzz: a 3000-sample bag, 124 s of
#: CPU). Past it the evaluation is NaN, which the engine treats as a bad point.
FIT_MAX_STEPS = 50_000


@dataclass(frozen=True)
class Start:
    """Neutral values of the baseline (from the unloading-time estimate).

    Attributes
    ----------
    conductance : float
        C [m^3/(s Pa)].
    critical_ratio : float
        b [-].
    t_open : float
        Valve opening instant [s].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    tau : float
        Unloading time tau_exp [s].
    dt : float
        Sample period [s].
    t_first, t_last : float
        First and last instants of the record [s].
    """

    conductance: float
    critical_ratio: float
    t_open: float
    p10: float
    p_atm: float
    tau: float
    dt: float
    t_first: float
    t_last: float


Values = dict[str, float]


def clamp(x: float, lo: float, hi: float) -> float:
    """x limited to [lo, hi] as a float (np.clip without the array overhead) [unit of x]."""
    return float(min(max(x, lo), hi))


@dataclass(frozen=True)
class EffectParam:
    """A parameter an effect adds.

    Attributes
    ----------
    name, unit, doc : str
        Key, SI unit, meaning.
    log : bool
        Fitted as log(value).
    lo, hi : float
        Bounds [unit].
    centre : callable
        Value [unit] at the centre of the fitted coordinate, from the :class:`Start`.
    scale : float
        One unit of the fitted coordinate [unit, or log units].
    fade : float
        Power p of the value in which the effect fades to nothing at one end (0: none; see
        :class:`~pneumatic_unload.fit.params.Parameter`) [-].
    """

    name: str
    unit: str
    log: bool
    lo: float
    hi: float
    centre: Callable[[Start], float]
    scale: float
    doc: str
    fade: float = 0.0


@dataclass(frozen=True)
class Effect:
    """One real-rig effect: where it sits, its parameters and how they enter the model.

    Attributes
    ----------
    name : str
        Key (one of :data:`pneumatic_unload.config.EFFECTS`).
    where : str
        Where in the rig it sits and what it does.
    params : tuple of EffectParam
        Parameters it adds.
    off : callable
        Parameter values that make it negligible (the nested baseline) [SI].
    starts : callable
        Starting values, small and large [SI].
    apply : callable
        ``apply(values, tank)`` -> RigConfig keyword changes.
    """

    name: str
    where: str
    params: tuple[EffectParam, ...]
    off: Callable[[Start], Values]
    starts: Callable[[Start], list[Values]]
    apply: Callable[[Values, TankSpec], dict[str, object]]


def _fast(s: Start) -> list[float]:
    return [max(3.0 * s.dt, 0.01 * s.tau), max(10.0 * s.dt, 0.1 * s.tau)]


def _small(s: Start) -> float:
    return max(s.tau * 0.01, 3 * s.dt)


def _heat_fixed(v: Values, tank: TankSpec) -> dict[str, object]:
    g = tank.gas
    h_a = v["p10"] * tank.volume / ((g.gamma - 1.0) * tank.initial_temperature * v["tau_heat"])
    return {"heat_transfer_mode": "fixed",
            "heat_transfer_coefficient": clamp(h_a, 0.0, 1e4)}


def _heat_density(v: Values, tank: TankSpec) -> dict[str, object]:
    return {**_heat_fixed(v, tank), "heat_transfer_mode": "density",
            "heat_transfer_exponent": clamp(v["heat_exponent"], -2.0, 4.0)}


def laminar_coefficient(fraction: float, v: Values, tank: TankSpec) -> float:
    """Laminar leak coefficient K [kg/(s Pa)] whose flow K (p10 - p_atm) at p10 is
    ``fraction`` [-] of the component's choked flow C rho_n p10 sqrt(T_N/T10) [kg/s]."""
    p_atm = v.get("p_atm", tank.atmosphere or 101325.0)
    g0 = v["C"] * RHO_N * v["p10"] * math.sqrt(T_N / tank.initial_temperature)
    return clamp(fraction * g0 / max(v["p10"] - p_atm, 1.0), 0.0, 1e-5)


def parallel_starts(s: Start, name: str, sizes: tuple[float, ...],
                    extra: Values | None = None) -> list[Values]:
    """Starts of a leak in parallel with the component: the leak takes ``sizes`` [-] of
    the flow the baseline gave C, so C starts at C_start/(1 + size) [m^3/(s Pa)] (the
    total flow, which the trace fixes, stays where it was)."""
    return [{name: f, "C": s.conductance / (1.0 + f), **(extra or {})} for f in sizes]


def _leak(v: Values, tank: TankSpec) -> dict[str, object]:
    return {"leak_coefficient": laminar_coefficient(v["leak_fraction"], v, tank)}


def _leak_down(v: Values, tank: TankSpec) -> dict[str, object]:
    return {"leak_downstream_coefficient":
            laminar_coefficient(v["leak_downstream_fraction"], v, tank)}


def _orifice(prefix: str, ratio: str, b: str) -> Callable[[Values, TankSpec],
                                                          dict[str, object]]:
    def apply(v: Values, tank: TankSpec) -> dict[str, object]:
        return {f"{prefix}_conductance": clamp(v[ratio] * v["C"], 1e-13, 1e-5),
                f"{prefix}_critical_ratio": clamp(v[b], 0.0, 0.99)}
    return apply


def _orifice_record(name: str, where: str, ratio: str, b: str) -> Effect:
    return Effect(
        name, where,
        (EffectParam(ratio, "-", True, 1e-5, 10.0, lambda s: 0.05, 1.0,
                     "sonic conductance of the leak C_leak relative to C (its choked flow "
                     "relative to the component's at the same pressure)"),
         EffectParam(b, "-", False, 0.02, 0.95, lambda s: 0.3, 0.1,
                     "critical pressure ratio b_leak of the leak")),
        lambda s: {ratio: 1e-5, b: 0.3},
        (lambda s: [{ratio: 0.03, b: 0.3}, *parallel_starts(s, ratio, (0.2, 0.6), {b: 0.4})])
        if name in DOWNSTREAM_LEAKS else lambda s: [{ratio: 0.03, b: 0.3}, {ratio: 0.2, b: 0.5}],
        _orifice(name, ratio, b))


HEAT_NATURAL = Effect(
    "heat_transfer",
    "the tank wall: heat flows from the wall into the cooling gas by natural convection; "
    "heat_scale multiplies the published correlation",
    (EffectParam("heat_scale", "-", True, 1e-4, 100.0, lambda s: 1.0, 0.3,
                 "multiplier on the natural-convection correlation", fade=1.0),),
    lambda s: {"heat_scale": 1e-4},
    lambda s: [{"heat_scale": 0.3}, {"heat_scale": 3.0}],
    lambda v, tank: {"heat_transfer_mode": "natural",
                     "heat_transfer_scale": float(min(v["heat_scale"], 100.0))},
)
HEAT_FIXED = Effect(
    "heat_transfer",
    "the tank wall: heat flows from the wall into the gas through a constant hA (Newton "
    "cooling); tau_heat = m0 c_v/(hA) is the gas's thermal time constant",
    (EffectParam("tau_heat", "s", True, 1e-3, 1e5, lambda s: s.tau, 1.0,
                 "thermal time constant m0 c_v/(h A) of the gas-wall exchange", fade=-1.0),),
    lambda s: {"tau_heat": 1e3 * s.tau},
    lambda s: [{"tau_heat": 0.7 * s.tau}, {"tau_heat": 7.0 * s.tau}],
    _heat_fixed,
)

HEAT_NATURAL_TURBULENT = Effect(
    "heat_transfer",
    "the tank wall: natural convection as in 'natural', the correlation's turbulent branch "
    "(Ra >= 1e9) scaled by heat_turbulent on its own",
    (HEAT_NATURAL.params[0],
     EffectParam("heat_turbulent", "-", True, 0.2, 5.0, lambda s: 1.0, 0.3,
                 "multiplier on the turbulent branch, Nu = 0.10 Ra^(1/3), of the "
                 "correlation (1.3: McAdams' 0.13)")),
    lambda s: {"heat_scale": 1e-4, "heat_turbulent": 1.0},
    lambda s: [{"heat_scale": 0.3, "heat_turbulent": 1.0},
               {"heat_scale": 3.0, "heat_turbulent": 1.0}],
    lambda v, tank: {"heat_transfer_mode": "natural",
                     "heat_transfer_scale": float(min(v["heat_scale"], 100.0)),
                     "heat_transfer_turbulent_ratio": clamp(v["heat_turbulent"], 0.0, 10.0)},
)
HEAT_DENSITY = Effect(
    "heat_transfer",
    "the tank wall: heat flows from the wall into the gas through an hA that varies as the "
    "gas density to a power n (hA ~ rho^n); tau_heat = m0 c_v/(hA_0) is the gas's thermal "
    "time constant at the start",
    (HEAT_FIXED.params[0],
     EffectParam("heat_exponent", "-", False, -1.0, 3.0, lambda s: 0.5, 0.1,
                 "exponent n of hA ~ rho^n (0: constant hA; 1/2 laminar, 2/3 turbulent "
                 "natural convection)")),
    lambda s: {"tau_heat": 1e3 * s.tau, "heat_exponent": 0.5},
    lambda s: [{"tau_heat": 0.7 * s.tau, "heat_exponent": 0.5},
               {"tau_heat": 7.0 * s.tau, "heat_exponent": 0.5}],
    _heat_density,
)

#: The time law's slope g1 and curvature g2 [-]: hA = hA_0 exp(g1 u + g2 u^2), u = ln(1 +
#: s/tau_t) over the 5-10 tau_t of a record spans 0-2.4, so |g| up to 5 moves hA by e^12:
#: beyond any wall exchange a record can follow.
HEAT_TIME_SLOPE = EffectParam("heat_time_slope", "-", False, -5.0, 5.0, lambda s: 0.0, 0.3,
                              "slope g1 of log hA in u = ln(1 + s/tau_t), s the time since "
                              "the opening")
HEAT_TIME_CURVATURE = EffectParam("heat_time_curvature", "-", False, -5.0, 5.0,
                                  lambda s: 0.0, 0.3, "curvature g2 of log hA in u")
#: The key of the values that carries the time law's time scale tau_t [s] to ``apply`` (not
#: a parameter: :class:`~pneumatic_unload.model.parametric.ParametricModel` holds it at its
#: start's unloading time, the record's own scale).
HEAT_TIME_SCALE = "heat_time_scale"


def _heat_time(v: Values, tank: TankSpec) -> dict[str, object]:
    return {**_heat_fixed(v, tank), "heat_transfer_mode": "time",
            "heat_transfer_time_slope": clamp(v["heat_time_slope"], -10.0, 10.0),
            "heat_transfer_time_curvature": clamp(v.get("heat_time_curvature", 0.0),
                                                  -10.0, 10.0),
            "heat_transfer_time_constant": clamp(v[HEAT_TIME_SCALE], 1e-4, 1e6)}


HEAT_TIME = Effect(
    "heat_transfer",
    "the tank wall: heat flows from the wall into the gas through an hA that changes with "
    "the time since the opening, log hA = log hA_0 + g1 u, u = ln(1 + s/tau_t) (a stirring "
    "that fades, a wall that cools with the gas); tau_heat = m0 c_v/(hA_0)",
    (HEAT_FIXED.params[0], HEAT_TIME_SLOPE),
    lambda s: {"tau_heat": 1e3 * s.tau, "heat_time_slope": 0.0},
    lambda s: [{"tau_heat": 0.7 * s.tau, "heat_time_slope": 0.0},
               {"tau_heat": 7.0 * s.tau, "heat_time_slope": 0.0}],
    _heat_time,
)
HEAT_TIME2 = Effect(
    "heat_transfer",
    "the tank wall: as 'time', log hA = log hA_0 + g1 u + g2 u^2 (an exchange that rises "
    "then falls, or the reverse)",
    (HEAT_FIXED.params[0], HEAT_TIME_SLOPE, HEAT_TIME_CURVATURE),
    lambda s: {"tau_heat": 1e3 * s.tau, "heat_time_slope": 0.0, "heat_time_curvature": 0.0},
    lambda s: [{"tau_heat": 0.7 * s.tau, "heat_time_slope": 0.0, "heat_time_curvature": 0.0},
               {"tau_heat": 7.0 * s.tau, "heat_time_slope": 0.0, "heat_time_curvature": 0.0}],
    _heat_time,
)


def exchange_extremes(law: str, tau: float, isothermal: bool = False
                      ) -> list[dict[str, float]]:
    """Starts of a heat law's own parameter at a strong and at a weak exchange, for a
    search that must not miss either basin (the curve fit's explore, a charge's
    discrepancy): the natural laws' multiplier 30 and 0.1 [-], the time constant of the
    others 0.05 and 20 times the unload's ``tau`` [s]. ``isothermal``: a nearly
    isothermal exchange too (the multiplier 100, the time constant 0.002 tau): an
    evacuated tank filled slowly stays near the wall's temperature, and its record is an
    adiabatic fill's with C / gamma (only the transition between the two shows)."""
    if law.startswith("natural"):
        return [{"heat_scale": 30.0}, {"heat_scale": 0.1}] + (
            [{"heat_scale": 100.0}] if isothermal else [])
    return [{"tau_heat": 0.05 * tau}, {"tau_heat": 20.0 * tau}] + (
        [{"tau_heat": 0.002 * tau}] if isothermal else [])


#: Every effect by name (heat transfer with its default law, natural convection).
REGISTRY: dict[str, Effect] = {e.name: e for e in (
    HEAT_NATURAL,
    Effect("valve_opening",
           "the shut-off valve: its effective area opens along a linear ramp of t_ramp",
           (EffectParam("t_ramp", "s", True, 1e-5, 10.0, _small, 1.0,
                        "valve opening time (linear ramp of the effective area)"),),
           lambda s: {"t_ramp": 0.3 * s.dt},
           lambda s: [{"t_ramp": v} for v in _fast(s)],
           lambda v, tank: {"valve_opening_time": float(min(v["t_ramp"], 10.0))}),
    Effect("sensor_lag",
           "the pressure transducer and its tubing: a first-order lag of tau_sensor",
           (EffectParam("tau_sensor", "s", True, 1e-6, 10.0, _small, 1.0,
                        "first-order time constant of the pressure sensor"),),
           lambda s: {"tau_sensor": 0.1 * s.dt},
           lambda s: [{"tau_sensor": v} for v in _fast(s)],
           lambda v, tank: {"sensor_lag": float(min(v["tau_sensor"], 10.0))}),
    Effect("leak",
           "the tank and its fittings: a laminar leak to atmosphere, active whenever the "
           "tank is above p_atm (the plateau decays)",
           (EffectParam("leak_fraction", "-", True, 1e-5, 10.0, lambda s: 0.05, 1.0,
                        "leak flow at p10 relative to the choked flow at p10"),),
           lambda s: {"leak_fraction": 1e-4},
           lambda s: [{"leak_fraction": 0.03}, {"leak_fraction": 0.2}],
           _leak),
    Effect("leak_downstream",
           "downstream of the shut-off valve, in parallel with the component (a leaky "
           "fixture seal): a laminar leak to atmosphere G = a(t) K (p - p_atm) that opens "
           "and closes with the valve (the plateau stays flat); its flow adds to the "
           "component's, so C is confounded with it",
           (EffectParam("leak_downstream_fraction", "-", True, 1e-5, 10.0,
                        lambda s: 0.05, 1.0,
                        "leak flow at p10 relative to the component's choked flow at p10"),),
           lambda s: {"leak_downstream_fraction": 1e-4},
           lambda s: [{"leak_downstream_fraction": 0.03},
                      *parallel_starts(s, "leak_downstream_fraction", (0.2, 0.6))],
           _leak_down),
    _orifice_record(
        "orifice_leak",
        "the tank and its fittings, upstream of the valve: a leak through a small orifice "
        "(ISO 6358 law, own C_leak and b_leak, m = 0.5; often sonic), active whenever the "
        "tank is above p_atm (the plateau decays)",
        "orifice_leak_ratio", "orifice_leak_b"),
    _orifice_record(
        "orifice_leak_downstream",
        "downstream of the shut-off valve, in parallel with the component: a leak through "
        "a small orifice (ISO 6358 law, own C_leak and b_leak, m = 0.5) that opens with "
        "the valve; C of the component and C_leak are nearly indistinguishable from one "
        "trace (both choked until p_atm/b)",
        "orifice_leak_downstream_ratio", "orifice_leak_downstream_b"),
    Effect("pipe_volume",
           "between the tank and the component: a pipe volume and the series conductance "
           "of the fittings (a system C is measured)",
           (EffectParam("pipe_volume_ratio", "-", True, 1e-4, 20.0, lambda s: 0.1, 1.0,
                        "volume between tank and component, relative to V"),
            EffectParam("pipe_conductance_ratio", "-", True, 1e-2, 1e4, lambda s: 5.0, 1.0,
                        "sonic conductance of the pipe relative to C")),
           lambda s: {"pipe_volume_ratio": 2e-4, "pipe_conductance_ratio": 5e3},
           lambda s: [{"pipe_volume_ratio": 0.1, "pipe_conductance_ratio": 5.0},
                      {"pipe_volume_ratio": 0.3, "pipe_conductance_ratio": 1.5}],
           lambda v, tank: {
               "pipe_volume": float(min(v["pipe_volume_ratio"] * tank.volume, 10.0)),
               "pipe_conductance": clamp(v["pipe_conductance_ratio"] * v["C"],
                                         1e-13, 1e-5)}),
    Effect("sensor_offset",
           "the pressure transducer: a zero offset added to every reading",
           (EffectParam("offset", "Pa", False, -1e6, 1e6, lambda s: 0.0, 1000.0,
                        "transducer zero offset"),),
           lambda s: {"offset": 0.0},
           lambda s: [{"offset": 0.0}],
           lambda v, tank: {"sensor_offset": v["offset"]}),
    Effect("sensor_gain",
           "the pressure transducer: a relative gain error on every reading",
           (EffectParam("gain", "-", False, -0.5, 0.5, lambda s: 0.0, 0.01,
                        "transducer relative gain error"),),
           lambda s: {"gain": 0.0},
           lambda s: [{"gain": 0.0}],
           lambda v, tank: {"sensor_gain": clamp(v["gain"], -0.5, 0.5)}),
)}
#: The heat-transfer laws a fit can choose from.
HEAT_VARIANTS: dict[str, Effect] = {"natural": HEAT_NATURAL, "fixed": HEAT_FIXED,
                                     "density": HEAT_DENSITY,
                                     "natural+turbulent": HEAT_NATURAL_TURBULENT}

#: The heat laws of the final fit's candidates (:mod:`pneumatic_unload.model.candidates`):
#: :data:`HEAT_VARIANTS` and the time laws, an hA that changes with the time since the
#: opening with one or two parameters.
FIT_HEAT_LAWS: dict[str, Effect] = {**HEAT_VARIANTS, "time": HEAT_TIME, "time2": HEAT_TIME2}

WALL_TEMPERATURE = EffectParam("t_wall", "K", False, 150.0, 600.0, lambda s: math.nan, 5.0,
                               "wall temperature")

assert set(REGISTRY) == set(EFFECTS), "every effect of the configuration needs a record"

#: Name of the hot-start effect: heat transfer with the wall temperature as a parameter.
HOT_START = "hot_start"
#: The hot start's record. It is the heat-transfer effect (its law, either of
#: :data:`HEAT_VARIANTS`, and its parameter) plus the wall temperature t_wall [K]
#: (:data:`WALL_TEMPERATURE`, the curve fit's "+wall" variants): the configuration it
#: builds switches ``heat_transfer`` on with ``wall_temperature`` = t_wall, so the
#: simulator needs no effect of its own.
HOT_START_RECORD = Effect(
    HOT_START,
    "the gas at the valve opening: warmer (or colder) than the tank wall, e.g. hot just "
    "after charging; it exchanges heat with the wall by the heat-transfer law and relaxes "
    "toward t_wall, the wall (room) temperature; T10 stays the gas's own initial "
    "temperature",
    (WALL_TEMPERATURE,),
    lambda s: {},  # the wall at T10 (ParametricModel.off_values)
    lambda s: [],  # below T10 (ParametricModel.effect_starts, HOT_START_DROPS)
    lambda v, tank: {"wall_temperature": clamp(v["t_wall"], WALL_TEMPERATURE.lo,
                                               WALL_TEMPERATURE.hi)},
)


#: Name of the subsonic-index candidate: the component's ISO 6358-1:2013 m freed.
SUBSONIC = "subsonic_index"
#: The subsonic index's record: m, held at 0.5 (the elliptic law) in the baseline, is a
#: parameter; the configuration's ``subsonic_index`` field, no effect of the simulator.
SUBSONIC_RECORD = Effect(
    SUBSONIC,
    "the component: its flow law's subsonic index m (ISO 6358-1:2013) away from the 0.5 "
    "of the elliptic law (silencers, tubes and many orifices): the shape of the subsonic "
    "tail",
    (EffectParam("m", "-", False, 0.1, 1.0, lambda s: 0.5, 0.1,
                 "ISO 6358-1:2013 subsonic index m of the component"),),
    lambda s: {"m": 0.5},
    lambda s: [{"m": 0.3}, {"m": 0.7}],
    lambda v, tank: {"subsonic_index": clamp(v["m"], 0.1, 1.0)},
)


def effect_record(name: str) -> Effect:
    """The record of a candidate effect (where it sits, its parameters) by name."""
    return {HOT_START: HOT_START_RECORD, SUBSONIC: SUBSONIC_RECORD}.get(name) or REGISTRY[name]


#: Every candidate effect of a discrepancy search: the configuration's effects, the hot
#: start and the subsonic index.
CANDIDATES: tuple[str, ...] = (*EFFECTS, HOT_START, SUBSONIC)
#: Wall temperature starts of a hot start, below T10 [K].
HOT_START_DROPS: tuple[float, ...] = (12.0, 35.0)
