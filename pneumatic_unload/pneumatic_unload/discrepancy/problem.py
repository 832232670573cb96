# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A recorded trace prepared for the discrepancy workflow: start values, noise, likelihood.

The unloading-time estimate (:func:`pneumatic_unload.estimation.analyze`, adiabatic, no
curve fit) gives the neutral start of the baseline; the AR(1) noise model comes from the
plateaus and the whole trace (:func:`pneumatic_unload.fit.noise.estimate_noise`); the fits
run on the engine's :class:`~pneumatic_unload.fit.trace.Trace`. SI units.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.discrepancy.types import DiscrepancyError, DiscrepancySettings, Fit
from pneumatic_unload.estimation import (
    SENSOR_FAULT_TEXTS,
    STUCK_TEXT,
    EstimationError,
    EstimatorSettings,
    StreamingEstimator,
    UnloadResult,
)
from pneumatic_unload.estimation.batch import charge_reason, explain_no_unload
from pneumatic_unload.estimation.crossing import crossing_estimate, plan_crossing
from pneumatic_unload.estimation.record_head import OPENING_HINT
from pneumatic_unload.estimation.refine import CHARGE_SECOND_START
from pneumatic_unload.estimation.sparse import analyze_from_start
from pneumatic_unload.fit.noise import estimate_noise
from pneumatic_unload.fit.trace import TemperatureChannel, Trace
from pneumatic_unload.model.effects import HEAT_VARIANTS, Start
from pneumatic_unload.model.parametric import CHARGE_HEAT_LAWS, ParametricModel

FloatArray = NDArray[np.float64]
Values = dict[str, float]


class Problem:
    """A trace prepared for fitting: relative times, noise model, likelihood, neutral start.

    Parameters
    ----------
    t, y : ndarray
        Sample instants [s] and measured pressure [Pa absolute].
    settings : DiscrepancySettings
        Rig data and workflow options.
    """

    def __init__(self, t: FloatArray, y: FloatArray, settings: DiscrepancySettings) -> None:
        t = np.asarray(t, dtype=float)
        y = np.asarray(y, dtype=float)
        if t.ndim != 1 or t.shape != y.shape:
            raise DiscrepancyError(f"t and p must be 1-D arrays of equal length, got "
                                   f"{t.shape} and {y.shape}")
        if t.size < 20:
            raise DiscrepancyError(f"too few samples ({t.size}); need at least 20")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
            k = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(y)))[0])
            raise DiscrepancyError(f"non-finite sample at index {k}; remove or interpolate "
                                   "it before the analysis")
        if np.any(np.diff(t) <= 0):
            raise DiscrepancyError("time stamps must increase strictly")
        self.settings = settings
        self.t_ref = float(t[0])
        t = t - self.t_ref
        # a given opening in the record's clock is one on the shifted stamps
        start = None if settings.start_time is None else settings.start_time - self.t_ref
        est = EstimatorSettings(**settings.tank_fields(), heat_model="adiabatic",
                                curve_fit=False, direction=settings.direction,
                                supply_pressure=settings.supply_pressure,
                                supply_temperature=settings.supply_temperature,
                                start_time=start)
        every = _unloads(t, y, est)
        # the estimator's results locate the unload and give the fit its starting values;
        # one it called bad data for a reason of its own timing (e.g. a start it could not
        # time on a leaking plateau), not a sensor fault, still locates it
        results = [r for r in every if r.status in ("ok", "ok_subsonic") or (
            r.status == "bad_data" and not r.status_text.startswith(SENSOR_FAULT_TEXTS)
            and all(math.isfinite(x) and x > 0 for x in (
                r.tau_exp, r.p10, r.p_atm, r.conductance)) and math.isfinite(r.t_start))]
        if not results:
            _refuse_bad_data(every, math.inf)
            # the estimator refused a record whose opening it does not show: its words,
            # with the start time to give, not a generic "no unload"
            refused = [r for r in every if OPENING_HINT in r.status_text]
            if refused:
                raise DiscrepancyError(refused[0].status_text)
            if not est.charge and charge_reason(y[np.isfinite(y)], est) is not None:
                raise DiscrepancyError(
                    "the pressure rises and never falls: a charge; give the direction "
                    "(--direction charge; the supply with --supply-pressure, else fitted)")
            if est.charge:
                raise DiscrepancyError(f"no complete charge found in the trace: "
                                       f"{explain_no_unload(t, y, est)}")
            raise DiscrepancyError("no complete unload found in the trace (the pressure "
                                   "must fall from a plateau through p*)")
        r = results[0]
        # keep one unload: cut before the next one starts
        later = [q.t_start for q in results[1:] if q.t_start > r.t_cross]
        t_cut = math.inf
        if later:
            t_cut = later[0] - 0.1 * (later[0] - r.t_cross)
            keep = t < t_cut
            t, y = t[keep], y[keep]
        _refuse_bad_data(every, t_cut)
        dt = float(np.median(np.diff(t)))
        c0 = r.conductance_isentropic if math.isfinite(r.conductance_isentropic) \
            else r.conductance
        # p_atm of the start and of the fits is the end level: a charge's supply
        self.start = Start(conductance=float(c0), critical_ratio=0.4, t_open=float(r.t_start),
                           p10=float(r.p10), p_atm=float(r.end_pressure),
                           tau=float(r.tau_exp),
                           dt=dt, t_first=float(t[0]), t_last=float(t[-1]))
        try:
            self.noise = estimate_noise(t, y, r.t_start, r.tau_exp)
        except ValueError as exc:
            raise DiscrepancyError(str(exc)) from exc
        #: the neutral Cs of the fits [m^3/(s Pa)]: the adiabatic crossing's, and for a
        #: charge also the heat correlation's and the isothermal one (gamma times the
        #: adiabatic: a fill whose gas stays at the wall's temperature rises as an
        #: adiabatic one through C / gamma), each where it differs from those before by
        #: more than CHARGE_SECOND_START. A charge's heat moves C by up to gamma and each
        #: C has its own basin: HydDown's vacuum fills read -27 % to -12 % from the
        #: adiabatic C alone, as the estimator's curve fit did (refine's second start).
        self.conductances = [float(c0)]
        if est.charge:
            for c1 in (_correlation_conductance(est, r), settings.gas.gamma * c0):
                if math.isfinite(c1) and c1 > 0 and all(
                        abs(c1 / c - 1.0) > CHARGE_SECOND_START for c in self.conductances):
                    self.conductances.append(float(c1))
        self.t, self.y = t, y
        self.trace = Trace(t, y, self.noise, r.t_start, resolution=settings.resolution)
        self.lik = self.trace.lik
        self.tank = settings.tank

    def model(self, effects: tuple[str, ...], heat_law: str = "natural") -> ParametricModel:
        """The parametric model with these effects."""
        return ParametricModel(effects, self.tank, self.start, heat_law=heat_law,
                               fit_wall_temperature=self.settings.fit_wall_temperature,
                               charge=self.settings.charge)

    @property
    def heat_laws(self) -> tuple[str, ...]:
        """The heat laws this record's direction is fitted with (a charge's:
        :data:`~pneumatic_unload.model.parametric.CHARGE_HEAT_LAWS`)."""
        return CHARGE_HEAT_LAWS if self.settings.charge else tuple(HEAT_VARIANTS)

    def with_channel(self, channel: TemperatureChannel | None) -> Problem:
        """The same trace and noise with a logged gas temperature fitted beside the
        pressure (:meth:`~pneumatic_unload.fit.trace.Trace.with_channel`)."""
        out = copy.copy(self)
        out.trace = self.trace.with_channel(channel)
        return out

    def with_length_diameter(self, ratio: float) -> Problem:
        """The same trace and noise with the tank's L/D set to ``ratio`` [-] (the natural
        heat law's Rayleigh number is taken on the tank's length)."""
        out = copy.copy(self)
        out.tank = dataclasses.replace(self.tank, length_diameter_ratio=float(ratio))
        return out

    def fit(self, model: ParametricModel, starts: list[Values], *, screen_nfev: int = 12,
            max_nfev: int = 200) -> Fit:
        """Multi-start fit through the engine: screen every start, fit and polish the best.

        Parameters
        ----------
        model : ParametricModel
            Model.
        starts : list of dict
            Starting values [SI units] (missing names: the model's neutral values).
        screen_nfev, max_nfev : int
            Evaluations for screening each start and for the full fit [-].
        """
        first, *rest = starts
        res = self.trace.fit(model, start=first, starts=rest, screen_nfev=screen_nfev,
                             max_nfev=max_nfev)
        return Fit(model=model, result=res)

    def residuals(self, model: ParametricModel, values: Values) -> FloatArray:
        """Normalised prewhitened binned residuals at parameter values [-]."""
        return self.trace.residual(model)(values)

    # starting points ----------------------------------------------------------------
    def neutral_theta(self, b: float = 0.4) -> Values:
        """Baseline parameters from the unloading-time estimate [SI units]."""
        s = self.start
        th = {"C": s.conductance, "b": b, "t_open": s.t_open, "p10": s.p10}
        if self.settings.end_fitted:
            th["p_atm"] = s.p_atm
        return th

    def neutral_thetas(self, b: float = 0.4) -> list[Values]:
        """:meth:`neutral_theta` at each of :attr:`conductances` [SI units] (one for a
        discharge)."""
        th = self.neutral_theta(b)
        return [{**th, "C": c} for c in self.conductances]

    def starts_for(self, model: ParametricModel, bases: list[Values],
                   new_effects: tuple[str, ...]) -> list[Values]:
        """Starting values: each base combined with each start of the new effects."""
        combos: list[Values] = [{}]
        for e in new_effects:
            combos = [{**c, **d} for c in combos for d in model.effect_starts(e)]
        return [{**base, **c} for base in bases for c in combos]


def _unloads(t: FloatArray, y: FloatArray, est: EstimatorSettings) -> list[UnloadResult]:
    """Every unload result of the trace (t [s], y [Pa]), with the estimator's stuck-sensor
    findings as ``bad_data`` results (a stuck stretch after the p* crossing is only a
    warning for the estimator, whose crossing stands; a fit would take it for data)."""
    if est.start_time is not None:  # a record that begins at the given opening
        try:
            return list(analyze_from_start(t, y, est))
        except EstimationError as exc:
            raise DiscrepancyError(str(exc)) from exc
    try:
        se = StreamingEstimator(est)
        out = se.push_block(t, y) + se.finish()
    except EstimationError as exc:
        raise DiscrepancyError(str(exc)) from exc
    for d in se.diagnostics:
        if d.level != "ok" and d.message.startswith(STUCK_TEXT) and not any(
                r.status_text == d.message for r in out):
            out.append(UnloadResult(
                index=-1, status="bad_data", status_text=d.message, t_start=math.nan,
                t_cross=math.nan, tau_exp=math.nan, tau_exp_std=math.nan, p10=math.nan,
                p_atm=math.nan, p_star=math.nan, initial_temperature=math.nan,
                volume=math.nan, conductance=math.nan, conductance_model=math.nan,
                conductance_model_std=math.nan, t_complete=d.t))
    return out


def _correlation_conductance(est: EstimatorSettings, r: UnloadResult) -> float:
    """The model C of the crossing of ``r`` (located with the adiabatic ``est``) with the
    estimator's heat correlation [m^3/(s Pa)]: the streaming core's crossing estimate
    (:func:`~pneumatic_unload.estimation.crossing.crossing_estimate`) at its tau_exp (NaN
    where it gives none)."""
    with_heat = dataclasses.replace(est, heat_model=EstimatorSettings().heat_model)
    try:
        plan = plan_crossing(with_heat, p10=r.p10, p_atm=r.end_pressure, p_star=r.p_star,
                             tau_ref=r.tau_exp)
        return float(crossing_estimate(plan, r.tau_exp, r.tau_exp_std).conductance_model)
    except (EstimationError, ValueError, ArithmeticError):
        return math.nan


def _refuse_bad_data(results: list[UnloadResult], t_cut: float) -> None:
    """Raise when the kept part of the trace (before t_cut [s]) holds a sensor fault (a
    stuck or saturated transducer, a clock step): the finding is the bad data, not a model
    effect to fit. Other 'bad_data' verdicts of the estimator (e.g. a start it could not
    time on a leaking plateau) are left to the workflow's own fit."""
    bad = [r for r in results if r.status == "bad_data" and r.t_complete < t_cut
           and r.status_text.startswith(SENSOR_FAULT_TEXTS)]
    if bad:
        raise DiscrepancyError(f"bad data, not fitted: {bad[0].status_text} (at t = "
                               f"{bad[0].t_complete:.6g} s)")
