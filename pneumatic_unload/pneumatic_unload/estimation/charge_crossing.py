# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The p* crossing's estimate of a charge: the unloading-time method mirrored.

A tank filled from p10 toward the supply's p_s reaches p* = p10 + 0.632 (p_s - p10) at
tau_exp after the opening (:func:`~pneumatic_unload.charge.charge_p_star`). From it:

* **eq 39 mirrored** (the supply upstream): C = ((p_s - p10)/p_s) sqrt(T_N/T_s) V /
  (gamma p_N tau_exp), biased by design by 1/I (1.34-1.58,
  :func:`~pneumatic_unload.charge.charge_eq39_bias`); reported as it is, with its budget;
* **the adiabatic closed form** (the charge's counterpart of the discharge's isentropic
  inversion): eq 39 mirrored times I(p10/p_s, b, m) with b the settings' prior and m 0.5
  (:func:`~pneumatic_unload.charge.charge_conductance_adiabatic`);
* **the model-based C**: the one model in the charge direction (the settings' heat law,
  the incoming jet's convection with it) inverted at the crossing from a table of its
  crossing times, prepared half way (:class:`ChargePlan`), or by the discharge's secant
  (:func:`~pneumatic_unload.model.inversion.model_conductance`); its budget states
  the crossing time, the prior of b (one sigma either side), the heat correlation (+-30 %),
  the heat not yet seen (uniform between none and the correlation's), V, T_s, the
  transducer's offset and a given supply. The curve fit that follows the charge's end
  measures b, m and the heat exchange.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pneumatic_unload import physics
from pneumatic_unload.charge import charge_conductance_adiabatic
from pneumatic_unload.config.estimator import EstimatorSettings, supply_temperature_uncertainty
from pneumatic_unload.estimation.types import CrossingEstimate, combined_std_of
from pneumatic_unload.model.inversion import (
    CRITICAL_RATIO_PRIOR_STD,
    HEAT_CORRELATION_REL_STD,
    model_conductance,
    model_crossing_time,
    rig_from_settings,
)
from pneumatic_unload.uncertainty.budget import (
    VOLUME_REL_DEFAULT,
    Budget,
    BudgetTerm,
    ScaledBudget,
    input_uncertainties,
    model_form_term,
    model_limits_term,
    record_term,
    tau_term,
)

#: The type A line of a charge's crossing model C.
CHARGE_TYPE_A = "crossing time (noise), b prior, heat correlation"


def charge_pressure_problem(p10: float, p_s: float, p_star: float) -> str | None:
    """Why no C can come from a charge's pressures, or None: they must be finite and
    absolute, 0 <= p10 < p* < p_s [Pa absolute]."""
    if all(math.isfinite(v) for v in (p10, p_s, p_star)) and 0.0 <= p10 < p_star < p_s:
        return None
    return (f"the charge's pressures do not allow a C (p10 = {p10:.6g} Pa, p* = "
            f"{p_star:.6g} Pa, supply = {p_s:.6g} Pa; a charge needs 0 <= p10 < p* < "
            "supply): gauge readings, or a supply below the tank?")


@dataclass(frozen=True)
class ChargePlan:
    """A charge's crossing estimate prepared before the crossing (half way to p*, off the
    crossing's latency): at fixed pressures eq 39 mirrored and the adiabatic closed form
    are exactly proportional to 1/tau, so are their input lines, and the model's
    crossing time is tabulated around the expected C.

    Attributes
    ----------
    settings : EstimatorSettings
        The settings it was made with.
    p10, p_s, p_star : float
        Initial, supply and crossing pressures [Pa absolute].
    supply_measured : bool
        p_s is the record's final plateau.
    problem : str or None
        Why no C can come from these pressures.
    tau_ref : float
        The reference crossing time [s].
    c39_ref, c_adi_ref : float
        eq 39 mirrored and the adiabatic closed form at tau_ref [m^3/(s Pa)].
    eq39, adiabatic : ScaledBudget or None
        Their budgets at the reference, the stated inputs' lines proportional to C, scaled
        at the crossing; free: eq 39's crossing-time line, the model C's type A, model
        form and model-limits lines (None with a ``problem``).
    b_rel : float
        The b prior's line relative to C [-].
    table : tuple of float or None
        log C = a + b log t + c (log t)^2 of the model's crossing time t [s] over
        (t_lo, t_hi) [s]: (a, b, c, t_lo, t_hi); None without a heat law.
    """

    settings: EstimatorSettings
    p10: float
    p_s: float
    p_star: float
    supply_measured: bool
    problem: str | None
    tau_ref: float = math.nan
    c39_ref: float = math.nan
    c_adi_ref: float = math.nan
    eq39: ScaledBudget | None = None
    adiabatic: ScaledBudget | None = None
    b_rel: float = math.nan
    table: tuple[float, float, float, float, float] | None = None


#: C of the model tabulated about the expected C [-] (the crossing within +-25 %).
TABLE_FACTORS = (0.7, 1.0, 1.4)


def plan_charge(settings: EstimatorSettings, *, p10: float, p_s: float, p_star: float,
                supply_measured: bool, tau_ref: float = math.nan, t_mid: float = math.nan,
                p_mid: float = math.nan) -> ChargePlan:
    """Prepare a charge's crossing estimate at a reference crossing time ``tau_ref`` [s],
    or, from the time t_mid [s] and pressure p_mid [Pa absolute] half way to p*, at the
    crossing the adiabatic closed form expects (pressures [Pa absolute])."""
    s = settings
    problem = charge_pressure_problem(p10, p_s, p_star)
    if problem is not None:
        return ChargePlan(s, p10, p_s, p_star, supply_measured, problem)
    t_s, gas, b = s.supply_gas_temperature, s.gas, s.critical_ratio

    def adiabatic(tau: float, p10_: float = p10, p_s_: float = p_s, p_cross: float = p_star,
                  b_: float = b) -> float:
        return charge_conductance_adiabatic(tau, p_cross, p10_, p_s_, s.volume, t_s, b_, 0.5,
                                            gas)
    if not (math.isfinite(tau_ref) and tau_ref > 0):
        c_mid = charge_conductance_adiabatic(t_mid, p_mid, p10, p_s, s.volume, t_s, b, 0.5,
                                             gas)
        tau_ref = adiabatic(1.0) / c_mid if math.isfinite(c_mid) and c_mid > 0 else 1.0
    c39 = physics.conductance_eq39(tau_ref, p_s, p10, s.volume, t_s, gas)
    c_adi = adiabatic(tau_ref)
    u = input_uncertainties(s, max(p_s, p10))
    u_ts, ts_why = supply_temperature_uncertainty(s)
    d = u["pressure"]
    ds = d if supply_measured else 0.0

    def inputs(c: float, closed: Any) -> tuple[BudgetTerm, ...]:
        """The stated inputs' lines of a C [m^3/(s Pa)] of the closed form ``closed``."""
        base = closed(p10, p_s, p_star)
        out = [BudgetTerm("volume V", "B", s.volume, u["volume"], "m^3",
                          abs(c) * u["volume"] / s.volume,
                          "stated" if s.volume_uncertainty is not None
                          else f"default {100 * VOLUME_REL_DEFAULT:g} % of V"),
               BudgetTerm("supply temperature T_s", "B", t_s, u_ts, "K",
                          abs(c) * 0.5 * u_ts / t_s, ts_why)]
        # an offset moves every reading: p10, the crossing and a measured supply
        moved = [closed(p10 + e, p_s + e * (ds / d if d else 0.0), p_star + e)
                 for e in (d, -d)]
        out.append(BudgetTerm("pressure transducer (offset)", "B", p10, d, "Pa",
                              abs(moved[0] - moved[1]) / 2.0 * abs(c) / base,
                              "stated" if s.pressure_uncertainty is not None
                              else "default 0.1 % of the supply"))
        if not supply_measured:
            ua = s.end_uncertainty
            given = [closed(p10, p_s + e, p_star + 0.632 * e) for e in (ua, -ua)]
            out.append(BudgetTerm("supply pressure p_s (given)", "B", p_s, ua, "Pa",
                                  abs(given[0] - given[1]) / 2.0 * abs(c) / base,
                                  "supply_pressure_uncertainty"))
        return tuple(out)

    lines39 = inputs(c39, lambda a, p, _x: physics.conductance_eq39(tau_ref, p, a, s.volume,
                                                                     t_s, gas))
    lines_adi = inputs(c_adi, lambda a, p, x: adiabatic(tau_ref, a, p, x))
    # the prior of b moves the closed form's integral (the flow turns subsonic before p*)
    b_lo, b_hi = max(b - CRITICAL_RATIO_PRIOR_STD, 0.01), min(b + CRITICAL_RATIO_PRIOR_STD,
                                                              0.99)
    b_rel = abs(adiabatic(tau_ref, b_=b_hi) - adiabatic(tau_ref, b_=b_lo)) / 2.0 / c_adi
    table = None
    if s.heat_model == "natural" and math.isfinite(c_adi):
        logs = []
        for k in TABLE_FACTORS:
            cfg = rig_from_settings(s, conductance=k * c_adi, p10=p10, p_atm=p_s)
            t_k = model_crossing_time(cfg, p_star, tau_ref / k)
            if not (math.isfinite(t_k) and t_k > 0):
                break
            logs.append((math.log(t_k), math.log(k * c_adi)))
        if len(logs) == len(TABLE_FACTORS):
            x = np.array([v[0] for v in logs])
            coef = np.polyfit(x, np.array([v[1] for v in logs]), 2)
            table = (float(coef[2]), float(coef[1]), float(coef[0]),
                     float(math.exp(x.min())), float(math.exp(x.max())))
    tau_line = tau_term(c39, tau_ref, 0.0)
    eq39 = ScaledBudget(Budget(c39, (tau_line, *lines39)), free=(tau_line.name,))
    free = (record_term(CHARGE_TYPE_A, 0.0), model_form_term(0.0, ""),
            model_limits_term(c_adi, s.model_limits))
    model = ScaledBudget(Budget(c_adi, (free[0], *lines_adi, *free[1:])),
                         free=tuple(t.name for t in free))
    return ChargePlan(s, p10, p_s, p_star, supply_measured, None, tau_ref, c39, c_adi,
                      eq39, model, b_rel, table)


def charge_crossing_estimate(plan: ChargePlan, tau: float, tau_std: float
                             ) -> CrossingEstimate:
    """eq 39 mirrored, the adiabatic closed form and the model-based C of a charge with
    their budgets, for the crossing time tau [s] and its 1-sigma tau_std [s], from the
    plan (:func:`plan_charge`): a few multiplications and the table's lookup; the model
    inverted by its secant (a few integrations) only where the crossing lies outside the
    table."""
    s = plan.settings
    problem = plan.problem
    if problem is None and not (math.isfinite(tau) and tau > 0):
        problem = f"no p* crossing time after the opening (tau_exp = {tau:.6g} s)"
    if problem is None and not math.isfinite(tau_std):
        problem = "tau_exp has no uncertainty: the opening of the charge is undetermined"
    if problem is not None:
        c39 = physics.conductance_eq39(tau, plan.p_s, plan.p10, s.volume,
                                       s.supply_gas_temperature, s.gas) \
            if plan.p_s > 0 and tau > 0 else math.nan
        return CrossingEstimate(problem, c39, math.nan, math.nan, math.nan, math.nan,
                                "eq39-charge", {})
    k = plan.tau_ref / tau  # both closed forms are C ~ 1/tau at fixed pressures
    c39, c_adi = plan.c39_ref * k, plan.c_adi_ref * k
    a = tau_term(c39, tau, tau_std)
    budget39 = plan.eq39.dict_at(c39, {a.name: a})  # type: ignore[union-attr]
    extra: dict[str, Any] = {"budget_eq39": budget39, "direction": "charge"}
    c_model, method = c_adi, "adiabatic-charge"
    form = model_form_term(0.0, "no heat law")
    heat_std = 0.0
    if s.heat_model == "natural" and math.isfinite(c_adi):
        t = plan.table
        if t is not None and t[3] <= tau <= t[4]:
            x = math.log(tau)
            c_heat = math.exp(t[0] + t[1] * x + t[2] * x * x)
        else:
            c_heat = model_conductance(s, tau, p10=plan.p10, p_atm=plan.p_s,
                                       p_star=plan.p_star, c_start=c_adi)
        if math.isfinite(c_heat):
            c_model, method = c_heat, "model-inversion-charge"
            form = model_form_term(abs(c_heat - c_adi) / math.sqrt(3.0),
                                   "heat law not yet seen: uniform between none "
                                   "(adiabatic) and the correlation's")
            heat_std = HEAT_CORRELATION_REL_STD * abs(c_heat - c_adi)
    b_std = plan.b_rel * c_model
    type_a = math.sqrt((c_model * tau_std / tau) ** 2 + b_std**2 + heat_std**2)
    given = [record_term(CHARGE_TYPE_A, type_a), form,
             model_limits_term(c_model, s.model_limits)]
    bm = plan.adiabatic.dict_at(c_model, {t.name: t for t in given})  # type: ignore[union-attr]
    extra["budget"] = bm
    return CrossingEstimate(None, c39, combined_std_of(budget39), c_adi, c_model,
                            combined_std_of(bm), method, extra)
