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
  the incoming jet's convection with it) inverted at the crossing by a secant on
  log t(C) (:func:`~pneumatic_unload.inversion.model_crossing_time`); its budget states
  the crossing time, the prior of b (one sigma either side), the heat correlation (+-30 %),
  the heat not yet seen (uniform between none and the correlation's), V, T_s, the
  transducer's offset and a given supply. The curve fit that follows the charge's end
  measures b, m and the heat exchange.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from typing import Any

from pneumatic_unload import physics
from pneumatic_unload.budget import (
    VOLUME_REL_DEFAULT,
    Budget,
    BudgetTerm,
    input_uncertainties,
    model_form_term,
    model_limits_term,
    record_term,
    tau_term,
)
from pneumatic_unload.charge import charge_conductance_adiabatic
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.types import CrossingEstimate
from pneumatic_unload.inversion import (
    CRITICAL_RATIO_PRIOR_STD,
    HEAT_CORRELATION_REL_STD,
    model_crossing_time,
    rig_from_settings,
)

#: The type A line of a charge's crossing model C.
CHARGE_TYPE_A = "crossing time (noise), b prior, heat correlation"
#: Secant steps of the charge's crossing inversion [-] (t(C) is nearly 1/C: two suffice
#: to ~1e-5).
SECANT_STEPS = 4
#: Relative tolerance of the inversion on C [-].
SECANT_RTOL = 1e-6


def charge_pressure_problem(p10: float, p_s: float, p_star: float) -> str | None:
    """Why no C can come from a charge's pressures, or None: they must be finite and
    absolute, 0 <= p10 < p* < p_s [Pa absolute]."""
    if all(math.isfinite(v) for v in (p10, p_s, p_star)) and 0.0 <= p10 < p_star < p_s:
        return None
    return (f"the charge's pressures do not allow a C (p10 = {p10:.6g} Pa, p* = "
            f"{p_star:.6g} Pa, supply = {p_s:.6g} Pa; a charge needs 0 <= p10 < p* < "
            "supply): gauge readings, or a supply below the tank?")


def charge_model_inversion(settings: EstimatorSettings, tau: float, p10: float,
                           p_s: float, p_star: float, c_start: float,
                           critical_ratio: float | None = None,
                           heat_scale: float = 1.0) -> float:
    """C [m^3/(s Pa)] for which the one model in the charge direction (the settings' heat
    law times ``heat_scale``, b = ``critical_ratio`` or the settings') rises from p10 to
    p_star at tau [s] (pressures Pa absolute; secant on log t against log C from
    ``c_start``); NaN when it does not converge."""
    def log_t(c: float) -> float:
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_s,
                                critical_ratio=critical_ratio, heat_scale=heat_scale)
        return math.log(model_crossing_time(cfg, p_star, tau))
    x0, y0 = math.log(c_start), log_t(c_start) - math.log(tau)
    x1 = x0 + y0  # t ~ 1/C
    for _ in range(SECANT_STEPS):
        y1 = log_t(math.exp(x1)) - math.log(tau)
        if not math.isfinite(y1):
            return math.nan
        if abs(y1) < SECANT_RTOL:
            return math.exp(x1)
        slope = (y1 - y0) / (x1 - x0) if x1 != x0 else -1.0
        x0, y0, x1 = x1, y1, x1 - y1 / (slope if slope < 0 else -1.0)
    return math.exp(x1) if abs(y0) < 1e-3 else math.nan


def charge_crossing_estimate(settings: EstimatorSettings, tau: float, tau_std: float, *,
                             p10: float, p_s: float, p_star: float,
                             supply_measured: bool) -> CrossingEstimate:
    """eq 39 mirrored, the adiabatic closed form and the model-based C of a charge with
    their budgets, for the crossing time tau [s] and its 1-sigma tau_std [s] (p10, p_s,
    p* [Pa absolute]; ``supply_measured``: p_s is the record's final plateau, moved by a
    transducer's offset with p10)."""
    s = settings
    t_s = s.supply_gas_temperature
    gas = s.gas
    problem = charge_pressure_problem(p10, p_s, p_star)
    if problem is None and not (math.isfinite(tau) and tau > 0):
        problem = f"no p* crossing time after the opening (tau_exp = {tau:.6g} s)"
    if problem is None and not math.isfinite(tau_std):
        problem = "tau_exp has no uncertainty: the opening of the charge is undetermined"
    if problem is not None:
        c39 = physics.conductance_eq39(tau, p_s, p10, s.volume, t_s, gas) \
            if p_s > 0 and tau > 0 else math.nan
        return CrossingEstimate(problem, c39, math.nan, math.nan, math.nan, math.nan,
                                "eq39-charge", {})
    b = s.critical_ratio

    def adiabatic(tau_: float = tau, p10_: float = p10, p_s_: float = p_s,
                  p_cross: float = p_star, b_: float = b, vol: float = s.volume,
                  ts: float = t_s) -> float:
        return charge_conductance_adiabatic(tau_, p_cross, p10_, p_s_, vol, ts, b_, 0.5, gas)

    c39 = physics.conductance_eq39(tau, p_s, p10, s.volume, t_s, gas)
    c_adi = adiabatic()
    u = input_uncertainties(s, max(p_s, p10))
    d = u["pressure"]
    ds = d if supply_measured else 0.0

    def inputs(c: float, closed: Any) -> list[BudgetTerm]:
        """The type B lines of a C [m^3/(s Pa)] by the closed form ``closed``."""
        out = [BudgetTerm("volume V", "B", s.volume, u["volume"], "m^3",
                          abs(c) * u["volume"] / s.volume,
                          "stated" if s.volume_uncertainty is not None
                          else f"default {100 * VOLUME_REL_DEFAULT:g} % of V"),
               BudgetTerm("supply temperature T_s", "B", t_s, u["temperature"], "K",
                          abs(c) * 0.5 * u["temperature"] / t_s,
                          "temperature_uncertainty")]
        # an offset moves every reading: p10, the crossing and a measured supply
        moved = [closed(p10 + e, p_s + e * (ds / d if d else 0.0), p_star + e)
                 for e in (d, -d)]
        out.append(BudgetTerm("pressure transducer (offset)", "B", p10, d, "Pa",
                              abs(moved[0] - moved[1]) / 2.0 * abs(c) / closed(
                                  p10, p_s, p_star),
                              "stated" if s.pressure_uncertainty is not None
                              else "default 0.1 % of the supply"))
        if not supply_measured:
            ua = s.end_uncertainty
            given = [closed(p10, p_s + e, p_star + 0.632 * e) for e in (ua, -ua)]
            out.append(BudgetTerm("supply pressure p_s (given)", "B", p_s, ua, "Pa",
                                  abs(given[0] - given[1]) / 2.0 * abs(c) / closed(
                                      p10, p_s, p_star), "supply_pressure_uncertainty"))
        return out

    def eq39_of(p10_: float, p_s_: float, _p: float) -> float:
        return physics.conductance_eq39(tau, p_s_, p10_, s.volume, t_s, gas)

    def adi_of(p10_: float, p_s_: float, p_cross: float) -> float:
        return adiabatic(p10_=p10_, p_s_=p_s_, p_cross=p_cross)

    budget39 = Budget(c39, (tau_term(c39, tau, tau_std), *inputs(c39, eq39_of)))
    extra: dict[str, Any] = {"budget_eq39": budget39.to_dict(), "direction": "charge"}
    c_model, method = c_adi, "adiabatic-charge"
    form = model_form_term(0.0, "no heat law")
    heat_std = 0.0
    if s.heat_model == "natural" and math.isfinite(c_adi):
        c_heat = charge_model_inversion(s, tau, p10, p_s, p_star, c_adi)
        if math.isfinite(c_heat):
            c_model, method = c_heat, "model-inversion-charge"
            form = model_form_term(abs(c_heat - c_adi) / math.sqrt(3.0),
                                   "heat law not yet seen: uniform between none "
                                   "(adiabatic) and the correlation's")
            heat_std = HEAT_CORRELATION_REL_STD * abs(c_heat - c_adi)
    # the prior of b moves the closed form's integral (the flow turns subsonic before p*)
    b_lo, b_hi = max(b - CRITICAL_RATIO_PRIOR_STD, 0.01), min(b + CRITICAL_RATIO_PRIOR_STD,
                                                              0.99)
    b_std = abs(adiabatic(b_=b_hi) - adiabatic(b_=b_lo)) / 2.0 * c_model / c_adi
    type_a = math.sqrt((c_model * tau_std / tau) ** 2 + b_std**2 + heat_std**2)
    bm = Budget(c_model, (record_term(CHARGE_TYPE_A, type_a), *inputs(c_model, adi_of),
                          form, model_limits_term(c_model, s.model_limits)))
    extra["budget"] = bm.to_dict()
    return CrossingEstimate(None, c39, budget39.combined_std, c_adi, c_model,
                            bm.combined_std, method, extra)
