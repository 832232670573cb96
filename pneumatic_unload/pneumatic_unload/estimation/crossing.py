# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The p* crossing's estimate from the crossing time, prepared before the crossing.

Everything of the crossing estimate but the crossing time tau_exp is known once p10, p_atm
and p* are: the check of the pressures, whether the flow may turn subsonic before p*, the
model inversion's table t(C) (a few model integrations) and the budgets' lines, which are
proportional to C at fixed pressures (:class:`~pneumatic_unload.uncertainty.budget.ScaledBudget`).
:func:`plan_crossing` prepares all of it when the pressure is half way to p*;
:func:`crossing_estimate` turns (tau_exp, its 1-sigma) into the numbers at the sample that
completes the crossing: eq 39 and the isentropic inversion (closed forms), a table lookup
and a few multiplications (issue #10: the crossing published within a millisecond of its
sample). Where no plan was made in time (p_atm found from the final plateau; a start given
on a sparse record) the same functions run at the crossing: the same numbers, later.

SI units: s, Pa absolute, m^3/(s Pa), K.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from pneumatic_unload import physics
from pneumatic_unload.config.estimator import EstimatorSettings, wall_uncertainty
from pneumatic_unload.estimation.charge_crossing import (
    ChargePlan,
    charge_crossing_estimate,
    plan_charge,
)
from pneumatic_unload.estimation.refine import (
    crossing_inversion,
    prepare_inversion,
    pressure_problem,
)
from pneumatic_unload.estimation.types import CrossingEstimate, combined_std_of
from pneumatic_unload.model.inversion import may_turn_subsonic
from pneumatic_unload.uncertainty.budget import (
    MODEL_FORM_TERM,
    WALL_TERM,
    BudgetTerm,
    ScaledBudget,
    eq39_budget,
    model_budget,
    model_form_term,
    record_term,
    tau_term,
    wall_term,
)

#: The type A line of the crossing's model-based C.
MODEL_TYPE_A = "crossing time (noise), b prior, heat correlation"
#: What the crossing's model-form line stands for.
HEAT_NOT_SEEN = ("heat law not yet seen: the exchange before p* taken uniform between none "
                 "(adiabatic) and twice the correlation's, +-|C - C_adiabatic|/sqrt 3")


@dataclass(frozen=True)
class CrossingPlan:
    """What the crossing estimate needs besides the crossing time.

    Attributes
    ----------
    settings : EstimatorSettings
        The settings it was prepared with.
    p10, p_atm, p_star : float
        Initial, atmospheric and crossing pressures [Pa absolute].
    problem : str or None
        Why no C can come from these pressures (see
        :func:`~pneumatic_unload.estimation.refine.pressure_problem`), or None.
    subsonic : str or None
        The status text when the flow turns subsonic before p* (eq 39 assumes it choked).
    table : InversionTable or None
        The model's crossing times around the expected C (None: the inversion iterates).
    eq39, model : ScaledBudget or None
        eq 39's and the model C's budgets at a reference C, scaled at the crossing.
    wall : tuple
        The wall temperature's standard uncertainty [K] and where it comes from.
    adiabatic : Any
        With a heat law: how the adiabatic C is found at the crossing, for the model-form
        line ('isentropic': the closed form, the flow choked to p*; an InversionTable of
        the adiabatic model; None: its inversion iterates at the crossing); '' without.
    adiabatic_settings : EstimatorSettings or None
        The settings without the heat law, for that inversion (made here: validating
        settings costs more than the rest of the crossing estimate).
    eq39_factors : tuple of float
        eq 39 as C = a / (b tau) (:func:`~pneumatic_unload.physics.eq39_factors`; NaN
        when p10 is 0: the formula then runs at the crossing) [m^3], [Pa].
    isentropic_factor : float
        The isentropic inversion as C = k / tau (:func:`~pneumatic_unload.physics.
        isentropic_factor`; NaN when the pressures have a problem) [m^3/Pa].
    charge : ChargePlan or None
        A charge's plan (:func:`~.charge_crossing.plan_charge`; p_atm is its supply).
    tau_ref : float
        The crossing time the budgets were prepared at [s] (NaN: none), inside the
        inversion table: :func:`rehearse_crossing`'s.
    """

    settings: EstimatorSettings
    p10: float
    p_atm: float
    p_star: float
    problem: str | None
    subsonic: str | None
    table: Any
    eq39: ScaledBudget | None
    model: ScaledBudget | None
    wall: tuple[float, str]
    adiabatic: Any = ""
    adiabatic_settings: EstimatorSettings | None = None
    eq39_factors: tuple[float, float] = (math.nan, math.nan)
    isentropic_factor: float = math.nan
    charge: ChargePlan | None = None
    tau_ref: float = math.nan


def plan_crossing(settings: EstimatorSettings, *, p10: float, p_atm: float, p_star: float,
                  t_mid: float = math.nan, p_mid: float = math.nan,
                  tau_ref: float = math.nan) -> CrossingPlan:
    """Prepare a crossing estimate.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas, heat model and the inputs' uncertainties.
    p10, p_atm, p_star : float
        Pressures [Pa absolute] (a charge's: p_atm the supply's; its plan holds the
        pressures alone, :func:`crossing_estimate` computes the charge's closed forms,
        :mod:`.charge_crossing`).
    t_mid, p_mid : float
        Time from the start [s] and pressure [Pa absolute] half way to p*: the expected C
        for the inversion table (NaN: no table).
    tau_ref : float
        A crossing time for the budgets' reference [s] (NaN: the table's middle, else
        t_mid); the lines are proportional to C whatever it is.
    """
    s = settings
    if s.charge:  # p_atm: the supply (charge_crossing)
        cp = plan_charge(s, p10=p10, p_s=p_atm, p_star=p_star,
                         supply_measured=s.supply_pressure is None, tau_ref=tau_ref,
                         t_mid=t_mid, p_mid=p_mid)
        return CrossingPlan(s, p10, p_atm, p_star, cp.problem, None, None, None, None,
                            wall_uncertainty(s), charge=cp, tau_ref=cp.tau_ref)
    problem = pressure_problem(p10, p_atm, p_star)
    subsonic = None
    if s.critical_ratio > 0 and p_star < p_atm / s.critical_ratio:
        subsonic = (f"flow subsonic before p* (p* = {p_star:.0f} Pa < p_atm/b = "
                    f"{p_atm / s.critical_ratio:.0f} Pa): eq 39 assumes choked flow")
    table = None
    if problem is None and math.isfinite(t_mid) and math.isfinite(p_mid):
        table = prepare_inversion(s, t_mid, p_mid, p10, p_atm, p_star)
    adiabatic: Any = ""
    if problem is None and s.heat_model != "adiabatic":
        if not may_turn_subsonic(s, p_atm, p_star):
            adiabatic = "isentropic"
        elif math.isfinite(t_mid) and math.isfinite(p_mid):
            adiabatic = prepare_inversion(_adiabatic(s), t_mid, p_mid, p10, p_atm, p_star)
        else:
            adiabatic = None
    if not (math.isfinite(tau_ref) and tau_ref > 0):
        tau_ref = math.exp(float(table.log_t[table.log_t.size // 2])) if table is not None \
            else t_mid
    eq39 = model = None
    wall = wall_uncertainty(s)
    if problem is None and math.isfinite(tau_ref) and tau_ref > 0:
        gas = s.gas
        measured = s.atmosphere is None
        c39 = physics.conductance_eq39(tau_ref, p10, p_atm, s.volume, s.initial_temperature,
                                       gas)
        c_isen = physics.conductance_isentropic_inversion(
            tau_ref, p_star, p10, s.volume, s.initial_temperature, gas)
        if math.isfinite(c39) and c39 > 0:
            eq39 = ScaledBudget(eq39_budget(s, c39, tau=tau_ref, tau_std=0.0, p10=p10,
                                            p_atm=p_atm, p_star=p_star,
                                            atmosphere_measured=measured),
                                free=(tau_term(c39, tau_ref, 0.0).name,))
        if math.isfinite(c_isen) and c_isen > 0:
            # the wall's line is a placeholder here: its value comes from the table
            model = ScaledBudget(model_budget(
                s, c_isen, type_a_std=0.0, type_a_name=MODEL_TYPE_A, model_form_std=0.0,
                tau=tau_ref, p10=p10, p_atm=p_atm, p_star=p_star,
                atmosphere_measured=measured,
                wall_std=0.0 if s.heat_model == "natural" else math.nan),
                free=(MODEL_TYPE_A, WALL_TERM, MODEL_FORM_TERM))
    return CrossingPlan(s, p10, p_atm, p_star, problem, subsonic, table, eq39, model, wall,
                        adiabatic, _adiabatic(s) if adiabatic not in ("", "isentropic")
                        else None,
                        physics.eq39_factors(p10, p_atm, s.volume, s.initial_temperature,
                                             s.gas) if p10 != 0 else (math.nan, math.nan),
                        physics.isentropic_factor(p_star, p10, s.volume,
                                                  s.initial_temperature, s.gas)
                        if problem is None else math.nan, tau_ref=tau_ref)


def crossing_estimate(plan: CrossingPlan, tau: float, tau_std: float) -> CrossingEstimate:
    """eq 39, the isentropic and the model-based C with their budgets for a crossing time
    tau [s] and its 1-sigma tau_std [s] (see :func:`plan_crossing`)."""
    s = plan.settings
    p10, p_atm, p_star = plan.p10, plan.p_atm, plan.p_star
    if s.charge:
        cp = plan.charge if plan.charge is not None else plan_charge(
            s, p10=p10, p_s=p_atm, p_star=p_star, supply_measured=s.supply_pressure is None,
            tau_ref=tau)
        return charge_crossing_estimate(cp, tau, tau_std)
    a39, b39 = plan.eq39_factors  # physics.conductance_eq39, prepared
    c39 = a39 / (b39 * tau) if a39 == a39 else physics.conductance_eq39(
        tau, p10, p_atm, s.volume, s.initial_temperature, s.gas)
    problem = plan.problem
    if problem is None and not math.isfinite(tau):
        problem = "no p* crossing time: the samples around p* are flat or degenerate"
    elif problem is None and not math.isfinite(tau_std):
        problem = ("tau_exp has no uncertainty (the start fit found no falling slope): the "
                   "start of the unload is undetermined")
    elif problem is None and not tau > 0:
        problem = (f"p* crossed {tau:.6g} s after the start: time runs backwards in the "
                   f"unload (a clock step or unsorted stamps?)")
    extra: dict[str, Any] = {}
    c39_std = math.nan
    if problem is not None:
        # no model of C from such numbers: eq 39 as it is
        if math.isfinite(c39) and c39 > 0 and math.isfinite(tau_std):
            c39_std = _eq39(plan, c39, tau, tau_std, extra)
        return CrossingEstimate(problem, c39, c39_std, math.nan, math.nan, math.nan, "eq39",
                                extra)
    # physics.conductance_isentropic_inversion, prepared (p10 > p* > 0: no problem)
    c_isen = plan.isentropic_factor / tau
    c_model, c_model_std, method, wall_std = crossing_inversion(
        s, tau, tau_std, p10, p_atm, p_star, c_isen, table=plan.table)
    if math.isfinite(c39) and c39 > 0 and math.isfinite(tau_std):
        c39_std = _eq39(plan, c39, tau, tau_std, extra)
    if math.isfinite(c_model) and c_model > 0 and math.isfinite(c_model_std):
        wall = wall_term(s, c_model, wall_std, *plan.wall) if math.isfinite(wall_std) \
            else None
        form = _heat_not_seen(plan, tau, c_isen, c_model)
        given: dict[str, BudgetTerm | None] = {
            MODEL_TYPE_A: record_term(MODEL_TYPE_A, c_model_std), WALL_TERM: wall,
            MODEL_FORM_TERM: form}
        bm = plan.model.dict_at(c_model, given) if plan.model is not None else model_budget(
            s, c_model, type_a_std=c_model_std, type_a_name=MODEL_TYPE_A,
            model_form_std=form.std, tau=tau, p10=p10, p_atm=p_atm, p_star=p_star,
            atmosphere_measured=s.atmosphere is None, wall_std=wall_std).to_dict()
        extra["budget"] = bm
        c_model_std = combined_std_of(bm)
    else:  # said in the result's status text (vetting.vet)
        extra["model_c_missing"] = (
            f"{method} gave C = {c_model:.3g} +- {c_model_std:.3g} m^3/(s Pa) at tau_exp = "
            f"{tau:.6g} s, p10 = {p10:.6g} Pa, p* = {p_star:.6g} Pa")
    return CrossingEstimate(None, c39, c39_std, c_isen, c_model, c_model_std, method, extra)


#: The relative 1-sigma of tau of a rehearsal (:func:`rehearse_crossing`) [-].
REHEARSAL_STD = 1e-3


def rehearse_crossing(plan: CrossingPlan | None) -> None:
    """The crossing estimate made at the plan's reference crossing time and discarded.

    The live estimator does this after each block of an unload whose crossing is
    prepared: the estimate runs once per unload, so without it its code and data have left
    the CPU's caches by the time the crossing comes (after the idle wait of 10 ms per block
    on a KVM guest: the core's push of the crossing's block p50 0.27 ms live without it,
    0.21-0.24 ms with it; its p99 within the runs' spread). Nothing is kept: the estimate
    is a function of the plan and tau alone. Made only where it is table lookups and
    closed forms (:func:`_lookups_only`): never an integration per block."""
    if plan is not None and plan.problem is None and plan.tau_ref > 0 \
            and _lookups_only(plan, plan.tau_ref):
        crossing_estimate(plan, plan.tau_ref, REHEARSAL_STD * plan.tau_ref)


def _lookups_only(plan: CrossingPlan, tau: float) -> bool:
    """Whether :func:`crossing_estimate` at the crossing time tau [s] is the plan's table
    lookups and closed forms (no model integration: a table covers tau, or none is needed)."""
    s = plan.settings
    if plan.charge is not None:
        t = plan.charge.table
        return s.heat_model != "natural" or (t is not None and t[3] <= tau <= t[4])
    closed = s.heat_model == "adiabatic" and not may_turn_subsonic(s, plan.p_atm,
                                                                   plan.p_star)
    if not (closed or (plan.table is not None and plan.table.covers(tau))):
        return False
    a = plan.adiabatic
    return isinstance(a, str) or (a is not None and a.covers(tau))


def _eq39(plan: CrossingPlan, c39: float, tau: float, tau_std: float,
          extra: dict[str, Any]) -> float:
    """eq 39's budget into ``extra``; its combined 1-sigma [m^3/(s Pa)]."""
    s = plan.settings
    a = tau_term(c39, tau, tau_std)
    b = plan.eq39.dict_at(c39, {a.name: a}) if plan.eq39 is not None else eq39_budget(
        s, c39, tau=tau, tau_std=tau_std, p10=plan.p10, p_atm=plan.p_atm,
        p_star=plan.p_star, atmosphere_measured=s.atmosphere is None).to_dict()
    extra["budget_eq39"] = b
    return combined_std_of(b)


def _adiabatic(settings: EstimatorSettings) -> EstimatorSettings:
    """The settings without the heat law [-]."""
    return dataclasses.replace(settings, heat_model="adiabatic")


def _heat_not_seen(plan: CrossingPlan, tau: float, c_isen: float, c_model: float
                   ) -> BudgetTerm:
    """The crossing's model-form line [m^3/(s Pa)]: up to p* the record has not shown how
    much heat the wall gives the gas (the curve fit sees it later), so the model C made
    with the correlation has the adiabatic C as a plausible neighbour. On a fast discharge
    the two agree (a line of ~0); on a slow one the correlation's heat moves C by tens of
    per cent, which the correlation's +-30 % in the type A line does not span."""
    a = plan.adiabatic
    if isinstance(a, str):
        if a == "":
            return model_form_term(0.0, "no heat law")
        c_adi = c_isen  # 'isentropic'
    elif a is not None and a.covers(tau):
        # the adiabatic model's table (made where the flow may turn subsonic before p*:
        # crossing_inversion's lookup, without its checks)
        c_adi = a.lookup(tau, 0.0)[0]
    else:
        c_adi, _sd, _m, _w = crossing_inversion(
            plan.adiabatic_settings or _adiabatic(plan.settings), tau, 0.0, plan.p10,
            plan.p_atm, plan.p_star, c_isen, table=a, wall=False)
    if not (math.isfinite(c_adi) and c_adi > 0):
        return model_form_term(math.nan, "adiabatic C not found")
    return model_form_term(abs(c_model - c_adi) / math.sqrt(3.0), HEAT_NOT_SEEN)
