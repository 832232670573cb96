# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The estimator's settings: the tank and gas (:class:`~pneumatic_unload.config.tank.TankSpec`)
and how the unloads are detected and refined; declared here with the other settings so that
the model-based fits below the estimator use them without importing it. SI units.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass

from pneumatic_unload.config.fields import (
    ConfigError,
    choice,
    flag,
    integer,
    number,
    optional,
    validate,
)
from pneumatic_unload.config.tank import TankSpec

#: A room's temperature [K] (20 C, the ISO 554 standard atmosphere for testing): a T10 far
#: from it means a gas warmed (or cooled) by the charge, not yet at the wall's temperature.
AMBIENT_TEMPERATURE = 293.15
#: Standard uncertainty of an assumed wall temperature (= T10, not given) when the record
#: carries no evidence of a gap [K]: a tank left to settle after charging, its gas within a
#: few kelvin of the wall.
WALL_ASSUMED_STD = 2.0
#: Standard uncertainty of a temperature probe's reading [K]: T10 given or logged, a given
#: wall (``temperature_uncertainty`` when not stated).
PROBE_STD = 1.0
#: Standard uncertainty of T10 where it was not measured [K] (at its default, a room's
#: :data:`AMBIENT_TEMPERATURE`, with no wall given and no logged temperature): the gas may
#: lie anywhere within the hot-start claim's threshold, 3 x :data:`WALL_ASSUMED_STD` either
#: side of the room's temperature (a gas warm from its charge, a room not at 20 C), without
#: the record claiming it (:mod:`pneumatic_unload.curvefit.law_family`): uniformly, its RMS
#: distance is 6 K / sqrt(3) (GUM 4.3.7). A 5 K warm gas then reads C +0.87 % at z 1.5, not 2.6
#: (bench/bench_temperature_records.py).
T10_UNMEASURED_STD = 3.0 * WALL_ASSUMED_STD / math.sqrt(3.0)


class EstimationError(ValueError):
    """Input that cannot be analysed at all (too few samples, wrong shapes...)."""


#: Default relative standard uncertainty of the model-based C from the model's own limits
#: [-]: the RMS error of the model C against HydDown over the 24-case grid of
#: bench/bench_hyddown.py (0.34 %; branch h11); the committed six of test_hyddown.py test
#: its coverage.
MODEL_UNCERTAINTY = 0.0034
#: Default relative standard uncertainty of a charge's model-based C from the model's own
#: limits [-]: the model-form spread of the charge's model C against HydDown's fills (u-to-h
#: blend removed; 1 kHz, 0.1 % FS noise, 2 seeds, from the opening and from a plateau):
#: the maximum-likelihood u of err ~ N(0, sigma_record^2 + u^2) beside each record's own
#: budget, over the 24-fill grid of bench/bench_hyddown_fill.py and the six committed fills
#: (120 analyses): 0.19 %. Grid: |z| <= 2 in 47/48 from the opening, 46/48 from a plateau
#: (RMS z 0.90, 0.94); the six: 10/12 each (RMS z 1.14, 1.08; the 8 bar, 2 L fill at
#: h = 10 W/(m^2 K) reads -0.4..-0.7 %, z -2.5..-3.2: HydDown's thin wall warms with the
#: gas, the model's stays at its temperature). It was the RMS error itself, 0.26 %, which
#: counts the records' noise twice: 48/48 within 2 sigma from the opening, RMS z 0.71.
CHARGE_MODEL_UNCERTAINTY = 0.0019


@dataclass(frozen=True)
class EstimatorSettings(TankSpec):
    """Settings of the unloading-time estimator: the tank and gas
    (:class:`~pneumatic_unload.config.tank.TankSpec`: volume, length_diameter_ratio,
    initial_temperature, wall_temperature, atmosphere, gas_constant, gamma) and these.

    Attributes
    ----------
    heat_model : str
        'natural' (natural-convection wall heat transfer) or 'adiabatic' for the model-based C.
    critical_ratio : float
        b [-] assumed at the crossing (the prior mean; its 1-sigma is
        :data:`pneumatic_unload.model.inversion.CRITICAL_RATIO_PRIOR_STD`); the curve fit
        measures b.
    signal_gain : float
        Pressure per unit of input signal [Pa per unit] (1 for an input in Pa).
    signal_offset : float
        Pressure at zero input [Pa] (0 for an input in Pa absolute).
    trigger_sigma : float
        Drop below the plateau that triggers detection, in noise standard deviations [-].
    min_plateau : int
        Samples of pre-step plateau needed before a trigger is accepted [-].
    max_gap_factor : float
        A stamp step larger than this many nominal periods is a gap [-].
    curve_fit : bool
        Run the full-curve least-squares fit (C, b) when the unload ends.
    volume_uncertainty : float or None
        Standard uncertainty of V [m^3] (None: 0.5 % of V) for the budget of C.
    temperature_uncertainty : float or None
        Standard uncertainty of T10 and of a given wall temperature [K] (None:
        :data:`PROBE_STD`, 1 K, for a measured one; T10 not measured - at its default, no
        wall given, no logged temperature - :data:`T10_UNMEASURED_STD`, 3.5 K:
        :func:`t10_uncertainty`).
    wall_temperature_uncertainty : float or None
        Standard uncertainty of the wall temperature when it is not given (assumed = T10)
        [K]: how far the wall may be from the gas at the start. None: from the record
        (:func:`wall_uncertainty`: :data:`WALL_ASSUMED_STD` [K], more when T10 is far from
        a room's :data:`AMBIENT_TEMPERATURE` or a hot start is fitted).
    pressure_uncertainty : float or None
        Standard uncertainty of the pressure transducer, as an offset common to all its
        readings [Pa] (None: 0.1 % of p10).
    atmosphere_uncertainty : float
        Standard uncertainty of a given p_atm [Pa] (a measured one is type A).
    start_time : float or None
        Valve opening instant in the record's clock [s] for a record that begins at the
        opening (a digitised curve, a 1 Hz logger started with the valve): the offline
        analysis then skips detection (:mod:`pneumatic_unload.estimation.sparse`); not for
        the live estimator.
    initial_pressure, initial_pressure_std : float or None
        p10 [Pa absolute] and its standard uncertainty [Pa] when the record does not show
        it (with ``start_time``).
    thermometer_time_constant : float or None
        First-order time constant of the thermometer of a logged gas temperature [s]
        (None: fitted with the pressure, within
        :data:`~pneumatic_unload.model.parametric.THERMOMETER_TAU_RANGE`).
    direction : str
        'discharge' (the tank empties through the component to ``atmosphere``), 'charge'
        (the tank fills through it from a supply at ``supply_pressure``,
        ``supply_temperature``: ISO 6358-2's charge; ``atmosphere`` is then the room's,
        for the leaks alone) or 'both' (charges and discharges of one component in turn, a
        cycle: each step analysed in its direction, :class:`~pneumatic_unload.estimation.
        two_way.TwoWayEstimator`). Inside the estimator and its fits a charge's end level,
        the supply, takes the place of p_atm (:attr:`end_pressure`).
    supply_pressure : float or None
        A charge's supply pressure p_s [Pa absolute] (None: the record's final plateau).
    supply_pressure_uncertainty : float or None
        Standard uncertainty of a given supply pressure [Pa] (None: 0.1 % of it).
    supply_temperature : float or None
        A charge's supply gas temperature T_s [K] (None: the wall's where given, else a
        room's 20 C: :attr:`supply_gas_temperature`).
    charge_model_uncertainty : float
        ``model_uncertainty`` of a charge [-]: default :data:`CHARGE_MODEL_UNCERTAINTY`
        (0.19 %), the model-form spread of the charge's model C against HydDown's fills
        (blend removed) beside each record's own budget, over the 24-fill grid of
        ``bench/bench_hyddown_fill.py`` and the six committed fills, from the opening and
        from a plateau (maximum likelihood).
    model_uncertainty : float
        Relative standard uncertainty of the model-based C from the discharge model's own
        limits [-]: ideal gas (real air, Z = 0.997 at 8 bar), a uniform gas state, a heat
        law from the package's family. Default :data:`MODEL_UNCERTAINTY` (0.34 %): the RMS
        error of the model C against the HydDown peer simulator (real-gas air, its own heat
        transfer) over the 24-case grid of ``bench/bench_hyddown.py``; the six committed
        cases of ``test/test_hyddown.py``, not used for it, test its coverage. 0 only for
        data made by the package's own model.
    """

    heat_model: str = choice("natural", ("natural", "adiabatic"),
                             "heat-transfer model of the model-based C")
    critical_ratio: float = number(0.4, "-", 0.0, 0.99,
                                   "critical pressure ratio b assumed at the crossing")
    signal_gain: float = number(1.0, "Pa/unit", -1e12, 1e12,
                                "pressure per unit of input signal (1: input in Pa)")
    signal_offset: float = number(0.0, "Pa", -1e9, 1e9, "pressure at zero input signal")
    trigger_sigma: float = number(8.0, "-", 1.0, 1000.0,
                                  "trigger drop in noise standard deviations")
    min_plateau: int = integer(32, 4, 1_000_000, "pre-step plateau samples needed")
    max_gap_factor: float = number(5.0, "-", 1.0, 1e6,
                                   "a stamp step above this many periods is a gap")
    curve_fit: bool = flag(True, "full-curve fit (C, b) once the unload's tail is recorded")
    volume_uncertainty: float | None = optional(
        None, "m^3", 0.0, 10.0, "standard uncertainty of V", "0.5 % of V")
    temperature_uncertainty: float | None = optional(
        None, "K", 0.0, 100.0, "standard uncertainty of T10 and of a given wall temperature",
        "1 K where measured (given or logged); T10 not measured: 3.5 K")
    wall_temperature_uncertainty: float | None = optional(
        None, "K", 0.0, 100.0, "standard uncertainty of the wall temperature when it is not "
        "given (assumed = T10)", "from the record: 2 K, more when T10 is far from 20 C or a "
        "hot start is fitted")
    pressure_uncertainty: float | None = optional(
        None, "Pa", 0.0, 1e7, "standard uncertainty of a pressure reading, an offset "
        "common to all", "0.1 % of p10")
    atmosphere_uncertainty: float = number(
        100.0, "Pa", 0.0, 1e5, "standard uncertainty of a given atmosphere (barometer)")
    start_time: float | None = optional(
        None, "s", -1e10, 1e10, "valve opening instant in the record's clock (its time "
        "stamps), for records that begin at the opening (no plateau): the start is not "
        "detected (live: the one unload that begins then)", "detected")
    initial_pressure: float | None = optional(
        None, "Pa", 1e3, 1e8, "initial tank pressure p10 (absolute) when the record does not "
        "show it (with start_time)", "the first sample at start_time")
    initial_pressure_std: float | None = optional(
        None, "Pa", 0.0, 1e7, "standard uncertainty of initial_pressure", "0.1 % of it")
    thermometer_time_constant: float | None = optional(
        None, "s", 1e-4, 120.0, "first-order time constant of the logged gas temperature's "
        "thermometer", "fitted with the pressure")
    direction: str = choice("discharge", ("discharge", "charge", "both"),
                            "flow direction: the tank empties (discharge), fills (charge), "
                            "or both in turn (a cycle)")
    supply_pressure: float | None = optional(
        None, "Pa", 1e3, 5e7, "a charge's supply pressure p_s (absolute)",
        "from the final plateau")
    supply_pressure_uncertainty: float | None = optional(
        None, "Pa", 0.0, 1e7, "standard uncertainty of a given supply pressure",
        "0.1 % of it")
    supply_temperature: float | None = optional(
        None, "K", 150.0, 600.0, "a charge's supply gas temperature T_s",
        "the wall's where given, else 293.15 K")
    charge_model_uncertainty: float = number(
        CHARGE_MODEL_UNCERTAINTY, "-", 0.0, 0.5, "relative standard uncertainty of a "
        "charge's model-based C from the model's own limits")
    model_uncertainty: float = number(
        MODEL_UNCERTAINTY, "-", 0.0, 0.5, "relative standard uncertainty of the "
        "model-based C from the model's own limits (ideal gas, uniform state, heat-law "
        "family)")

    def __post_init__(self) -> None:
        """Validate every field (raises :class:`EstimationError` with the reason)."""
        try:
            validate(self)
        except ConfigError as exc:
            raise EstimationError(str(exc)) from exc
        if self.signal_gain == 0:
            raise EstimationError("signal_gain must be non-zero")
        if self.direction == "discharge" and (self.supply_pressure is not None
                                              or self.supply_temperature is not None):
            raise EstimationError("supply_pressure and supply_temperature are a charge's "
                                  "(direction 'charge')")

    @property
    def charge(self) -> bool:
        """The tank fills through the component (``direction`` 'charge')."""
        return self.direction == "charge"

    def one_way(self, direction: str) -> EstimatorSettings:
        """These settings for one flow direction ('discharge' or 'charge'; a discharge's
        without the supply's fields) [-]: those of a result of that direction (with
        ``direction`` 'both', each step's)."""
        if direction == self.direction:
            return self
        supply = {} if direction == "charge" else {"supply_pressure": None,
                                                   "supply_temperature": None}
        return dataclasses.replace(self, direction=direction, **supply)

    @property
    def end_pressure(self) -> float | None:
        """The level the tank's pressure tends to, where given [Pa absolute]: the
        atmosphere of a discharge, the supply of a charge; None: the final plateau."""
        return self.supply_pressure if self.charge else self.atmosphere

    @property
    def end_uncertainty(self) -> float:
        """Standard uncertainty of a given :attr:`end_pressure` [Pa] (NaN: not given)."""
        if self.end_pressure is None:
            return math.nan
        if not self.charge:
            return self.atmosphere_uncertainty
        return (self.supply_pressure_uncertainty if self.supply_pressure_uncertainty
                is not None else 1e-3 * self.end_pressure)

    @property
    def model_limits(self) -> float:
        """The relative standard uncertainty of the model-based C from the model's own
        limits in use [-]: ``charge_model_uncertainty`` for a charge, else
        ``model_uncertainty``."""
        return self.charge_model_uncertainty if self.charge else self.model_uncertainty

    @property
    def supply_gas_temperature(self) -> float:
        """A charge's supply temperature T_s in use [K]: given, else the wall's (the
        room's) where given, else a room's :data:`AMBIENT_TEMPERATURE` (not T10: the gas
        in the tank may be out of equilibrium - a tank just discharged is cold - while the
        supply is not)."""
        return supply_gas_temperature(self.supply_temperature, self.wall_temperature)


def supply_gas_temperature(supply: float | None, wall: float | None) -> float:
    """A charge's supply temperature T_s [K] from the given one ``supply`` [K] and the
    given wall's ``wall`` [K] (None: not given): the supply's, else the wall's, else
    :data:`AMBIENT_TEMPERATURE` (never T10: see
    :attr:`EstimatorSettings.supply_gas_temperature`)."""
    if supply is not None:
        return supply
    return AMBIENT_TEMPERATURE if wall is None else wall


def with_wall(settings: EstimatorSettings, wall: float, **changes: object
              ) -> EstimatorSettings:
    """``settings`` with the wall temperature set to ``wall`` [K] (and ``changes``), a
    charge's supply temperature kept where it was: T_s defaults to the wall's only where
    the wall is given, so an assumed wall's move (a budget's wall line, a hot start's
    room) is not the supply's (it moved C by T_s's 0.34 % for 2 K; T_s has its own
    line)."""
    if settings.charge and settings.supply_temperature is None \
            and settings.wall_temperature is None:
        changes = {"supply_temperature": settings.supply_gas_temperature, **changes}
    return dataclasses.replace(settings, wall_temperature=wall, **changes)  # type: ignore[arg-type]


def supply_temperature_uncertainty(settings: EstimatorSettings) -> tuple[float, str]:
    """Standard uncertainty of a charge's supply temperature T_s [K] and where it comes
    from: the stated ``temperature_uncertainty``; T_s given, or the wall's given,
    :data:`PROBE_STD`; else (a room's 20 C assumed) a room's :data:`WALL_ASSUMED_STD`."""
    s = settings
    return _temperature_std(s, s.supply_temperature is not None
                            or s.wall_temperature is not None, WALL_ASSUMED_STD,
                            f"+- {WALL_ASSUMED_STD:g} K")


def t10_measured(settings: EstimatorSettings, logged: bool = False) -> bool:
    """Whether T10 was measured [-]: given away from its default (a room's
    :data:`AMBIENT_TEMPERATURE`), a wall given beside it, or a logged gas temperature
    (``logged``). A T10 given as exactly 293.15 K with no wall and no log reads as not
    measured (its line then the wider :data:`T10_UNMEASURED_STD`: on the safe side)."""
    return logged or settings.wall_temperature is not None \
        or settings.initial_temperature != AMBIENT_TEMPERATURE


def probe_uncertainty(settings: EstimatorSettings) -> float:
    """Standard uncertainty of a temperature probe's reading [K]: the stated
    ``temperature_uncertainty``, else :data:`PROBE_STD`."""
    u = settings.temperature_uncertainty
    return PROBE_STD if u is None else u


def t10_uncertainty(settings: EstimatorSettings) -> tuple[float, str]:
    """Standard uncertainty of T10 [K] and where it comes from: the stated
    ``temperature_uncertainty``; else measured (:func:`t10_measured`) :data:`PROBE_STD`, not
    measured :data:`T10_UNMEASURED_STD`."""
    return _temperature_std(settings, t10_measured(settings), T10_UNMEASURED_STD,
                            f"+- 3 x {WALL_ASSUMED_STD:g} K (a gas warm from its charge that "
                            "the record does not show, a room not at 20 C)/sqrt(3)")


def _temperature_std(s: EstimatorSettings, measured: bool, unmeasured: float,
                     spread: str) -> tuple[float, str]:
    """A temperature's standard uncertainty [K] and its source: the stated
    ``temperature_uncertainty``; else a probe's :data:`PROBE_STD` where ``measured``; else
    ``unmeasured`` [K], a room's temperature assumed with that ``spread`` (in words)."""
    if s.temperature_uncertainty is not None:
        return s.temperature_uncertainty, "temperature_uncertainty"
    if measured:
        return PROBE_STD, f"measured; default {PROBE_STD:g} K (a probe)"
    return unmeasured, f"not measured: a room's {AMBIENT_TEMPERATURE:g} K assumed, {spread}"


def wall_uncertainty(settings: EstimatorSettings,
                     hot_walls: Iterable[float] = ()) -> tuple[float, str]:
    """Standard uncertainty of the wall temperature used by the model [K], and where it
    comes from.

    * given (``wall_temperature``): ``temperature_uncertainty``;
    * assumed = T10 with ``wall_temperature_uncertainty`` stated: that;
    * assumed, from the record: the largest of :data:`WALL_ASSUMED_STD`, and, for each gap
      the record shows between the gas at the start and where the wall may be, the gap over
      sqrt(3) (the wall anywhere between T10 and the other temperature, uniformly: its
      root-mean-square distance from the assumed T10 is the gap over sqrt(3), GUM 4.3.7):
      T10 against a room's :data:`AMBIENT_TEMPERATURE`, and T10 against the walls fitted by
      the hot-start variants of the curve fit (``hot_walls`` [K]).
    """
    s = settings
    if s.wall_temperature is not None:
        return probe_uncertainty(s), "given; temperature_uncertainty"
    if s.wall_temperature_uncertainty is not None:
        return s.wall_temperature_uncertainty, "assumed = T10; wall_temperature_uncertainty"
    t10 = s.initial_temperature
    u, why = WALL_ASSUMED_STD, f"assumed = T10; default {WALL_ASSUMED_STD:g} K"
    gap = abs(t10 - AMBIENT_TEMPERATURE)
    if gap / math.sqrt(3.0) > u:
        u, why = gap / math.sqrt(3.0), (f"assumed = T10; T10 is {gap:.1f} K from a room's "
                                        f"{AMBIENT_TEMPERATURE:g} K: gap/sqrt(3)")
    for tw in hot_walls:
        gap = abs(t10 - tw)
        if math.isfinite(gap) and gap / math.sqrt(3.0) > u:
            u, why = gap / math.sqrt(3.0), (f"assumed = T10; a hot start fitted the wall "
                                            f"{gap:.1f} K from T10: gap/sqrt(3)")
    return u, why
