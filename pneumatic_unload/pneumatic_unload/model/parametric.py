# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discharge model with effects as a function of named parameter values: what every
fit evaluates (the curve fit, the crossing inversion, the discrepancy search).

:class:`ParametricModel` turns values of the parameters of the effect records of
:mod:`~pneumatic_unload.model.effects` into a :class:`~pneumatic_unload.config.RigConfig`
(building only the fields that change) and evaluates the one integrator and sensor chain on
it. SI units: Pa absolute, K, s, m^3/(s Pa).
"""

from __future__ import annotations

import numpy as np

from pneumatic_unload.config import RigConfig, TankSpec
from pneumatic_unload.config.fields import with_changes
from pneumatic_unload.fit.params import Parameter, Parameters
from pneumatic_unload.model.effects import (
    CANDIDATES,
    FIT_HEAT_LAWS,
    FIT_MAX_STEPS,
    FIT_RTOL,
    HEAT_TIME_SCALE,
    HEAT_VARIANTS,
    HOT_START,
    HOT_START_DROPS,
    HOT_START_RECORD,
    REGISTRY,
    SUBSONIC,
    SUBSONIC_RECORD,
    WALL_TEMPERATURE,
    Effect,
    FloatArray,
    Start,
    Values,
    clamp,
    exchange_extremes,
)
from pneumatic_unload.model.ode import integrate, valve_events
from pneumatic_unload.model.sensor import first_order_lag, sensor_response

#: The subsonic index m of the ISO 6358-1:2013 flow law held when it is not fitted, and
#: the start of its fit [-] (0.5: the elliptic law of ISO 6358:1989).
SUBSONIC_INDEX_START = 0.5
#: Bounds of a fitted m [-] (the simulator's range).
SUBSONIC_INDEX_RANGE = (0.1, 1.0)
#: The exponent q of the subsonic branch's ellipse in ISO 6358-1:2013 [-].
ISO_ELLIPSE_EXPONENT = 2.0
#: Bounds of a fitted q [-] (those of the configuration's ``ellipse_exponent``).
ELLIPSE_EXPONENT_RANGE = (1.0, 6.0)
#: The flow-curve shapes of the estimator's model [-]: the ISO 6358-1 law, the law with
#: its ellipse's exponent q free, two ISO elements in series.
FLOW_SHAPES = ("iso", "q", "series")
#: Bounds of a fitted pair in series' C2/C1 [-] (a second element from 20 times narrower
#: to 20 times wider than the first; beyond, the pair is one element to the record).
SERIES_RATIO_RANGE = (0.05, 20.0)
#: Bounds of a fitted downstream element's b [-] (the component's b's).
SERIES_B_RANGE = (0.0, 0.95)
#: Bounds of a thermometer's fitted time constant [s] (a reading as good as instantaneous
#: - a simulator's, or a probe far faster than the logger - to a sheathed probe in a
#: thermowell) and its start.
THERMOMETER_TAU_RANGE = (1e-4, 120.0)
THERMOMETER_TAU_START = 1.0
#: Bounds of a thermometer's fitted offset [K] (a probe's calibration, a few K).
THERMOMETER_OFFSET_RANGE = (-20.0, 20.0)
#: Initial pressures a fit's configuration takes [Pa absolute] (RigConfig's: an evacuated
#: tank of a charge from 1 kPa).
P10_BOUNDS = (1e3, 5e7)
#: The effects a charge's model takes (the others' records are written for a discharge).
CHARGE_FIT_EFFECTS = ("heat_transfer", "hot_start", "sensor_offset", "subsonic_index")
#: The heat laws a charge is fitted with (:data:`HEAT_VARIANTS` but the density law: its
#: time constant is set at the initial density, which an evacuated tank's is a twentieth
#: of the end's; a room-into-vacuum fill of the independent model (constant hA) took it at
#: tau_heat 0.02 s, C +37 % at a 0.5 % sigma).
CHARGE_HEAT_LAWS: tuple[str, ...] = tuple(law for law in HEAT_VARIANTS if law != "density")
#: Points of the model's gas temperature between a thermometer's first and last reading
#: (geometric from the opening; the lag is exact for the piecewise-linear interpolant of
#: its input) [-].
THERMOMETER_GRID = 400


class ParametricModel:
    """The baseline discharge plus effects, as a function of named parameter values.

    Parameters
    ----------
    effects : tuple of str
        Effects switched on (names of :data:`REGISTRY`).
    tank : TankSpec
        Known tank and gas data (``atmosphere`` None: p_atm is fitted).
    start : Start
        Neutral values (centres of the fitted coordinates, bounds of t_open).
    heat_law : str
        Law of the heat-transfer effect: 'natural', 'fixed', 'density',
        'natural+turbulent' (:data:`HEAT_VARIANTS`), 'time' or 'time2' (an hA that changes
        with the time since the opening, on the scale of the start's unloading time:
        :data:`FIT_HEAT_LAWS`).
    fit_wall_temperature : bool
        Fit the wall temperature with the heat-transfer effect (start: ``tank.wall``).
        ``hot_start`` in ``effects`` is the heat-transfer effect with the wall temperature
        always fitted (start: below T10, :data:`HOT_START_DROPS`).
    subsonic_index : float or None
        The component's ISO 6358-1 subsonic index m [-] held at this value; None: m is a
        parameter ('m', start :data:`SUBSONIC_INDEX_START`, bounds
        :data:`SUBSONIC_INDEX_RANGE`).
    ellipse_exponent : float or None
        The exponent q of the component's subsonic ellipse, phi = (1 - x^q)^m [-], held at
        this value (2: ISO 6358-1:2013); None: q is a parameter ('q', start 2, bounds
        :data:`ELLIPSE_EXPONENT_RANGE`): a flow curve that is not ISO-shaped (two
        restrictions in series), read by
        :mod:`pneumatic_unload.curvefit.shape_reading`.
    series : bool
        The component as two ISO 6358-1 elements in series (ISO 6358-3): 'C' the pair's
        conductance, 'b' and 'm' the upstream element's, and parameters for the downstream
        one: 'b2' [-], 'm2' [-] and its conductance over the upstream one's, 'kappa' [-]
        (:data:`SERIES_RATIO_RANGE`).
    thermometer : bool
        A logged gas temperature is fitted beside the pressure: T10 (the gas temperature at
        the opening, 't10' [K], start ``tank.initial_temperature``) and the thermometer's
        first-order time constant ('tau_thermo' [s], :data:`THERMOMETER_TAU_RANGE`) are
        parameters, and :meth:`seen` is what the thermometer shows. A wall not given
        follows the fitted T10.
    fit_initial_temperature : bool
        T10 ('t10') is a parameter without a thermometer (a hot start whose T10 was not
        measured, the wall held at a room's temperature).
    charge : tuple of (float or None, float), optional
        The tank fills through the component (ISO 6358-2's charge, the one model's
        ``direction`` 'charge'): (the supply pressure p_s [Pa absolute], None: fitted; the
        supply temperature T_s [K]). The end level the pressure tends to, 'p_atm' of the
        parameters and of :class:`Start`, is then the supply's; ``tank.atmosphere`` is the
        room's. Effects other than the heat exchange and the transducer's offset are
        refused (their records are written for a discharge).
    """

    def __init__(self, effects: tuple[str, ...], tank: TankSpec, start: Start, *,
                 heat_law: str = "natural", fit_wall_temperature: bool = False,
                 subsonic_index: float | None = SUBSONIC_INDEX_START,
                 ellipse_exponent: float | None = ISO_ELLIPSE_EXPONENT,
                 series: bool = False, thermometer: bool = False,
                 fit_initial_temperature: bool = False, thermometer_offset: bool = False,
                 charge: tuple[float | None, float] | None = None) -> None:
        bad = [e for e in effects if e not in CANDIDATES]
        if bad:
            raise ValueError(f"unknown effect(s) {bad}; known: {', '.join(CANDIDATES)}")
        if charge is not None and (bad := [e for e in effects if e not in CHARGE_FIT_EFFECTS]):
            raise ValueError(f"effect(s) {bad} not modelled for a charge; a charge takes "
                             f"{', '.join(CHARGE_FIT_EFFECTS)}")
        self.charge = charge
        if HOT_START in effects and "heat_transfer" in effects:
            raise ValueError("hot_start is heat_transfer with the wall temperature fitted: "
                             "give one of them")
        if heat_law not in FIT_HEAT_LAWS:
            raise ValueError(f"unknown heat law {heat_law!r}; known: {list(FIT_HEAT_LAWS)}")
        self.effects = tuple(effects)
        self.tank = tank
        self.start = start
        self.heat_law = heat_law
        self.hot_start = HOT_START in effects
        self.fit_wall_temperature = fit_wall_temperature or self.hot_start
        self.subsonic_index = subsonic_index
        self.ellipse_exponent = ellipse_exponent
        self.series = series
        self.thermometer = thermometer
        self.thermometer_offset = thermometer and thermometer_offset
        self.fit_initial_temperature = fit_initial_temperature or thermometer
        #: effects of the configuration (the hot start is heat transfer in the simulator)
        self.config_effects = tuple("heat_transfer" if e == HOT_START else e
                                    for e in self.effects if e != SUBSONIC)
        self.records = tuple(self._record(e) for e in self.effects)
        self.parameters = self._parameters()
        self._last_config: tuple[tuple[tuple[str, float], ...], RigConfig] | None = None
        self._base_config: RigConfig | None = None

    def _parameters(self) -> Parameters:
        s = self.start
        p = s.p10
        ps = [
            Parameter("C", s.conductance, 1e-13, 1e-5, "m^3/(s Pa)", log=True, scale=0.1,
                      doc="sonic conductance"),
            # b from 0: a component that never chokes in the ISO sense (elliptic, b = 0)
            # lies inside the range (a bound at 0.01 cost such a pair 0.15-0.26 % in C)
            Parameter("b", clamp(s.critical_ratio, 0.02, 0.94), 0.0, 0.95, "-",
                      scale=0.1, doc="critical pressure ratio"),
            Parameter("t_open", s.t_open, s.t_first,
                      max(min(s.t_last, s.t_open + 0.5 * s.tau), s.t_open + s.dt), "s",
                      scale=max(10.0 * s.dt, 1e-3 * s.tau), doc="valve opening instant"),
            Parameter("p10", p, 0.3 * p, 3.0 * p, "Pa", scale=1e-3 * p,
                      doc="initial pressure (absolute)"),
        ]
        if self.subsonic_index is None and SUBSONIC not in self.effects:
            lo, hi = SUBSONIC_INDEX_RANGE
            ps.append(Parameter("m", SUBSONIC_INDEX_START, lo, hi, "-", scale=0.1,
                                doc="ISO 6358-1 subsonic index"))
        if self.ellipse_exponent is None:
            lo, hi = ELLIPSE_EXPONENT_RANGE
            ps.append(Parameter("q", ISO_ELLIPSE_EXPONENT, lo, hi, "-", scale=0.2,
                                doc="exponent of the subsonic branch's ellipse"))
        if self.series:
            ps += [Parameter("b2", 0.3, *SERIES_B_RANGE, "-", scale=0.1,
                             doc="downstream element's critical pressure ratio"),
                   Parameter("m2", SUBSONIC_INDEX_START, *SUBSONIC_INDEX_RANGE, "-",
                             scale=0.1, doc="downstream element's subsonic index"),
                   Parameter("kappa", 1.0, *SERIES_RATIO_RANGE, "-", log=True, scale=0.1,
                             doc="downstream element's conductance over the upstream one's")]
        if self.fit_initial_temperature:
            ps.append(Parameter("t10", self.tank.initial_temperature, 150.0, 600.0, "K",
                                scale=2.0, doc="gas temperature at the valve opening"))
        if self.thermometer:
            lo, hi = THERMOMETER_TAU_RANGE
            ps.append(Parameter("tau_thermo", THERMOMETER_TAU_START, lo, hi, "s", log=True,
                                scale=1.0, doc="thermometer's first-order time constant"))
        if self.thermometer_offset:
            lo, hi = THERMOMETER_OFFSET_RANGE
            ps.append(Parameter("t_offset", 0.0, lo, hi, "K", scale=0.5,
                                doc="thermometer's offset (its reading minus the gas's)"))
        if (self.tank.atmosphere if self.charge is None else self.charge[0]) is None:
            ps.append(Parameter("p_atm", s.p_atm, 0.3 * s.p_atm, 3.0 * s.p_atm, "Pa",
                                scale=1e-3 * s.p_atm, doc="atmospheric pressure (absolute)"
                                if self.charge is None else "supply pressure (absolute)"))
        for rec in self.records:
            for q in rec.params:
                c = q.centre(s)
                ps.append(Parameter(q.name, c, q.lo, q.hi, q.unit, log=q.log, scale=q.scale,
                                    doc=q.doc, fade=q.fade))
            if rec.name == "heat_transfer" and self.fit_wall_temperature:
                q = WALL_TEMPERATURE
                ps.append(Parameter(q.name, self.tank.wall, q.lo, q.hi, q.unit,
                                    scale=q.scale, doc=q.doc))
        return Parameters(ps)

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in order."""
        return self.parameters.names

    def off_values(self, effect: str) -> Values:
        """Values that switch ``effect`` (almost) off [SI]."""
        rec = self._record(effect)
        out = dict(rec.off(self.start))
        if effect in ("heat_transfer", HOT_START) and self.fit_wall_temperature:
            out["t_wall"] = self.tank.wall
        return out

    def effect_starts(self, effect: str) -> list[Values]:
        """Starting values of an effect's parameters (small and large) [SI]."""
        rec = self._record(effect)
        out = rec.starts(self.start)
        if self.charge is not None and effect in ("heat_transfer", HOT_START):
            # a charge's exchange spans decades (an evacuated tank's tau_heat, on its
            # initial mass, is a twentieth of a discharge's): its strong and weak ends too
            out = out + [{**out[0], **d} for d in exchange_extremes(
                self.heat_law, self.start.tau, isothermal=True)]
        if effect == HOT_START:
            t10 = self.tank.initial_temperature
            out = [{**d, "t_wall": clamp(t10 - dt, WALL_TEMPERATURE.lo, WALL_TEMPERATURE.hi)}
                   for d in out for dt in HOT_START_DROPS]
        elif effect == "heat_transfer" and self.fit_wall_temperature:
            out = [{**d, "t_wall": self.tank.wall} for d in out]
        return out

    def _record(self, effect: str) -> Effect:
        """The record whose parameters the effect adds (the heat law's for the hot start:
        its wall temperature is added with the heat-transfer record's parameters)."""
        if effect in ("heat_transfer", HOT_START):
            return FIT_HEAT_LAWS[self.heat_law]
        if effect == SUBSONIC:
            return SUBSONIC_RECORD
        return REGISTRY[effect]

    def config(self, v: Values) -> RigConfig:
        """The :class:`RigConfig` of parameter values (valve opens at ``v['t_open']``).

        The last one is kept: a fit asks for the events and the signal of the same values.
        """
        key = tuple(v.items())
        last = self._last_config
        if last is not None and last[0] == key:
            return last[1]
        cfg = self._build_config(v)
        self._last_config = (key, cfg)
        return cfg

    def _build_config(self, v: Values) -> RigConfig:
        tank = self.tank
        c = clamp(v["C"], 1e-13, 1e-5)
        vv = {**v, "C": c, HEAT_TIME_SCALE: self.start.tau}  # the time laws' scale
        room = tank.atmosphere if tank.atmosphere is not None else 101325.0
        kw: dict[str, object] = {
            "conductance": c, "critical_ratio": clamp(v["b"], 0.0, 0.99),
            "initial_pressure": clamp(v["p10"], *P10_BOUNDS),
            "subsonic_index": clamp(v.get("m", self.subsonic_index or SUBSONIC_INDEX_START),
                                    *SUBSONIC_INDEX_RANGE),
            "ellipse_exponent": clamp(v.get("q", self.ellipse_exponent or
                                            ISO_ELLIPSE_EXPONENT), *ELLIPSE_EXPONENT_RANGE),
            **({"series_conductance_ratio": clamp(v["kappa"], *SERIES_RATIO_RANGE),
                "series_critical_ratio": clamp(v["b2"], *SERIES_B_RANGE),
                "series_subsonic_index": clamp(v["m2"], *SUBSONIC_INDEX_RANGE)}
               if self.series else {}),
            "wall_temperature": float(v.get("t_wall", tank.wall if "t10" not in v or
                                            tank.wall_temperature is not None
                                            else clamp(v["t10"], 150.0, 600.0)))}
        if self.charge is None:
            kw["atmosphere"] = clamp(v.get("p_atm", room), 1e3, 2e5)
        else:  # the end level is the supply's (above p10: a fit may step past it)
            supply = v.get("p_atm", self.charge[0] if self.charge[0] is not None else room)
            kw["supply_pressure"] = clamp(supply, 1.0001 * kw["initial_pressure"], 5e7)
        if "t10" in v:
            kw["initial_temperature"] = clamp(v["t10"], 150.0, 600.0)
        for rec in self.records:
            kw.update(rec.apply(vv, tank))
        if self.hot_start:
            kw.update(HOT_START_RECORD.apply(vv, tank))
        if self._base_config is None:
            gas = tank.gas
            kw.setdefault("initial_temperature", tank.initial_temperature)
            if self.charge is not None:
                kw.update(direction="charge", atmosphere=room,
                          supply_temperature=self.charge[1])
            self._base_config = RigConfig(
                volume=tank.volume, length_diameter_ratio=tank.length_diameter_ratio,
                gas_constant=gas.gas_constant, gamma=gas.gamma, effects=self.config_effects,
                pre_time=0.0, noise_std=0.0, **kw)  # type: ignore[arg-type]
            return self._base_config
        # the tank, gas and effects are fixed: only the fitted fields are checked again
        return with_changes(self._base_config, kw)

    def events(self, v: Values) -> list[float]:
        """Instants where the model's signal is not smooth [s]."""
        return valve_events(self.config(v), v["t_open"])

    def states(self, v: Values, t: FloatArray) -> FloatArray:
        """ODE states at instants t (p [Pa], T [K], ...) for parameter values v."""
        return integrate(self.config(v), np.asarray(t, dtype=float), v["t_open"],
                         rtol=FIT_RTOL, quiet=True, max_steps=FIT_MAX_STEPS)

    def signal(self, v: Values, t: FloatArray) -> FloatArray:
        """Noise-free sensor output of the model at instants t [Pa]."""
        cfg = self.config(v)
        t = np.asarray(t, dtype=float)
        p = integrate(cfg, t, v["t_open"], rtol=FIT_RTOL, quiet=True,
                      max_steps=FIT_MAX_STEPS)[:, 0]
        return sensor_response(t, p, cfg)

    def temperature(self, v: Values, t: FloatArray) -> FloatArray:
        """Mean gas temperature of the model at instants t [K]."""
        return self.states(v, t)[:, 1]

    def thermometer_grid(self, v: Values, t: FloatArray) -> FloatArray:
        """The instants [s] at which the gas temperature is taken for a thermometer read at
        t [s]: t and :data:`THERMOMETER_GRID` more, geometric from the opening."""
        t = np.asarray(t, dtype=float)
        after, t1 = max(float(v["t_open"]), float(t[0])), float(t[-1])
        if t1 <= after:
            return t
        dense = after + (t1 - after) * np.geomspace(1e-4, 1.0, THERMOMETER_GRID)
        return np.union1d(t, np.concatenate(([after], dense)))

    def signal_and_temperature(self, v: Values, t: FloatArray, grid: FloatArray
                               ) -> tuple[FloatArray, FloatArray]:
        """The sensor output at instants t [Pa] and the mean gas temperature at ``grid``
        [K] from one integration (over both sets of instants [s])."""
        cfg = self.config(v)
        t = np.asarray(t, dtype=float)
        both = np.union1d(t, grid)
        st = integrate(cfg, both, v["t_open"], rtol=FIT_RTOL, quiet=True,
                       max_steps=FIT_MAX_STEPS)
        p = st[np.searchsorted(both, t), 0]
        return sensor_response(t, p, cfg), st[np.searchsorted(both, grid), 1]

    @staticmethod
    def seen(v: Values, grid: FloatArray, gas: FloatArray, t: FloatArray, first: float
             ) -> FloatArray:
        """The thermometer's readings [K] at t [s] (a subset of ``grid`` [s], where the gas
        temperature is ``gas`` [K]) from ``first`` [K] at t[0]: the lagged gas temperature
        plus the offset 't_offset' [K] (0 when not a parameter)."""
        off = float(v.get("t_offset", 0.0))
        lag = first_order_lag(grid[1:], gas[1:], float(v["tau_thermo"]),
                              (float(grid[0]), float(gas[0]), float(first) - off))[0]
        return np.concatenate(([float(first)], lag + off))[np.searchsorted(grid, t)]
