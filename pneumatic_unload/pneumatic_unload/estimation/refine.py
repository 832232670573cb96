# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Refinement: model inversion at the crossing, final curve fit, SSE recovery fit.

The only module of the estimator that calls :mod:`pneumatic_unload.curvefit.fitting`,
:mod:`pneumatic_unload.model.inversion` and :mod:`pneumatic_unload.curvefit.recovery` (imported at
load: the compiled model imports in milliseconds, and a first unload must not pay the import
inside its latency budget), so those calls can be re-pointed in one place. SI units: s, Pa
absolute, m^3/(s Pa); the recovery fit works in the input's signal units.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from pneumatic_unload import physics
from pneumatic_unload.config.estimator import (
    WALL_ASSUMED_STD,
    EstimatorSettings,
    probe_uncertainty,
    wall_uncertainty,
)
from pneumatic_unload.config.rig import RigConfig
from pneumatic_unload.config.tank import ATMOSPHERE_RANGE
from pneumatic_unload.curvefit.fitting import CurveFit, fit_curve
from pneumatic_unload.curvefit.heat_law_offer import hot_start_terms
from pneumatic_unload.curvefit.law_family import LAW_BIC_THRESHOLD
from pneumatic_unload.curvefit.recovery import fit_recovery
from pneumatic_unload.curvefit.subsonic_offer import m_budget, offset_terms, subsonic_term
from pneumatic_unload.curvefit.temperature_evidence import temperature_terms
from pneumatic_unload.estimation.endstep import TAIL_STEP
from pneumatic_unload.estimation.types import FloatArray, UnloadResult
from pneumatic_unload.fit.uncertainty import inadequacy, residual_scale
from pneumatic_unload.model.inversion import (
    fitted_tau_exp,
    inversion_table,
    invert_crossing,
    may_turn_subsonic,
)
from pneumatic_unload.uncertainty.budget import (
    WALL_TERM,
    Budget,
    BudgetTerm,
    fitted_wall_term,
    held_wall_term,
    model_budget,
    model_form_term,
    model_limits_term,
    record_term,
    term_std,
    wall_sensitivity,
    wall_term,
)
from pneumatic_unload.uncertainty.budget_b import ratio_budget

#: Quality figure [0, 1] at most of a result whose model does not describe the record at
#: its noise level ("model inadequate" in its status text).
INADEQUATE_QUALITY = 0.7
#: The type A line of the curve fit's C.
FINAL_TYPE_A = "curve fit (noise, AR(1), residual structure)"
#: Initial pressures the discharge model covers [Pa absolute] (RigConfig's bounds).
P10_RANGE: tuple[float, float] = next(
    (float(f.metadata["min"]), float(f.metadata["max"])) for f in dataclasses.fields(RigConfig)
    if f.name == "initial_pressure")
#: Supply pressures the charge's model covers [Pa absolute] (RigConfig's bounds).
SUPPLY_RANGE: tuple[float, float] = next(
    (float(f.metadata["min"]), float(f.metadata["max"])) for f in dataclasses.fields(RigConfig)
    if f.name == "supply_pressure")


def pressure_problem(p10: float, p_atm: float, p_star: float) -> str | None:
    """Why C cannot be computed from these pressures, or None when it can: they must be
    finite and absolute, p10 > p* > p_atm > 0 [Pa absolute] (a signal in other units needs
    ``signal_gain``/``signal_offset``; gauge readings need p_atm added)."""
    if all(math.isfinite(v) for v in (p10, p_atm, p_star)) and p10 > p_star > p_atm > 0:
        if P10_RANGE[0] <= p10 <= P10_RANGE[1]:
            return None
        return (f"p10 = {p10:.6g} Pa is outside [{P10_RANGE[0]:g}, {P10_RANGE[1]:g}] Pa, the "
                f"range of the discharge model: wrong units or signal_gain?")
    return (f"pressures not absolute Pa (p10 = {p10:.6g} Pa, p* = {p_star:.6g} Pa, "
            f"p_atm = {p_atm:.6g} Pa; C needs p10 > p* > p_atm > 0): gauge readings or a "
            f"signal without signal_gain/signal_offset?")


def end_level_problem(settings: EstimatorSettings, level: float, p10: float) -> str | None:
    """Why a final plateau at ``level`` [Pa absolute] cannot be the end level the pressure
    tends to (taken from the record: p_atm auto, a charge's supply auto), or None: an
    atmosphere outside :data:`~pneumatic_unload.config.tank.ATMOSPHERE_RANGE` (gauge
    readings, a signal in another unit, a sensor that is not where it seems); a supply not
    above p10 [Pa absolute] or beyond :data:`SUPPLY_RANGE`."""
    if settings.charge:
        if p10 < level <= SUPPLY_RANGE[1]:
            return None
        return (f"the final plateau, taken as the supply (auto), is at {level:.0f} Pa, not "
                f"above p10 ({p10:.0f} Pa): give the supply (--supply-pressure PA) and "
                "check the pressure unit")
    lo, hi = ATMOSPHERE_RANGE
    if lo <= level <= hi:
        return None
    return (f"the final plateau, taken as p_atm (auto), is at {level:.0f} Pa, not an "
            f"atmosphere ({lo:.0f}-{hi:.0f} Pa absolute): gauge readings, another unit, or "
            f"a signal without signal_gain/signal_offset? Give the atmosphere (--atmosphere "
            f"PA) and check the pressure unit")


def needs_model(settings: EstimatorSettings, p_atm: float, p_star: float) -> bool:
    """True when the model-based C needs the discharge model (not the closed form): heat
    transfer, or a flow that may turn subsonic before p* (pressures [Pa absolute])."""

    return settings.heat_model != "adiabatic" or settings.charge or may_turn_subsonic(
        settings, p_atm, p_star)



def final_budget(res: UnloadResult, settings: EstimatorSettings, *, c: float,
                 type_a_std: float, model_form_std: float, heat_law: str,
                 extra_terms: tuple[Any, ...] = (), fit: CurveFit | None = None
                 ) -> dict[str, Any] | None:
    """Uncertainty budget of the final (curve-fit) C. The wall temperature's term (when a
    heat law was fitted): a wall assumed = T10, the curve fit's own (``fit.wall_std``: the
    law refitted with the wall moved by its uncertainty from the record); a wall fitted by a
    hot-start law, a line of 0 (it is in the fit's type A); a given wall, the crossing
    budget's, tabulated before the crossing, scaled to C (without one, two model
    inversions at the crossing: a few milliseconds). None when C is not finite.

    Parameters
    ----------
    res : UnloadResult
        The crossing result (tau, pressures).
    settings : EstimatorSettings
        Inputs and their stated uncertainties.
    c, type_a_std, model_form_std : float
        The fitted C, its 1-sigma from the record (noise, AR(1)-corrected, inflated for
        structured residuals) and the heat laws' spread [m^3/(s Pa)].
    heat_law : str
        The heat law chosen ('natural', 'fixed', 'density', 'natural+turbulent', a
        '+wall' variant, or 'none').
    fit : CurveFit, optional
        The curve fit (its wall: fitted, or assumed with its uncertainty and C's).
    """
    if not (math.isfinite(c) and c > 0):
        return None
    if settings.charge:
        return charge_final_budget(res, settings, c=c, type_a_std=type_a_std,
                                   model_form_std=model_form_std, heat_law=heat_law,
                                   extra_terms=extra_terms, fit=fit)
    wall_std, wall_input = math.nan, None
    if heat_law.endswith("+wall") and fit is not None and math.isfinite(
            fit.wall_temperature_std):
        extra_terms = (*extra_terms, fitted_wall_term(fit.wall_temperature,
                                                      fit.wall_temperature_std, heat_law))
    elif heat_law.endswith("+wall") and fit is not None:  # T10 fitted, the wall a room's
        extra_terms = (*extra_terms, held_wall_term(fit.wall_temperature, WALL_ASSUMED_STD))
    elif heat_law != "none" and fit is not None and math.isfinite(fit.wall_uncertainty):
        wall_std, wall_input = fit.wall_std, (fit.wall_uncertainty, fit.wall_source)
    elif heat_law != "none":
        wall_std = term_std(res.extra.get("budget"), WALL_TERM)
        if not math.isfinite(wall_std):
            wall_std = wall_sensitivity(settings, res.tau_exp, p10=res.p10, p_atm=res.p_atm,
                                        p_star=res.p_star, c_start=c)
        wall_std = wall_std * c / res.conductance_model \
            if math.isfinite(res.conductance_model) and res.conductance_model > 0 \
            else wall_std
    return model_budget(settings, c, type_a_std=type_a_std,
                        type_a_name=FINAL_TYPE_A,
                        model_form_std=model_form_std, tau=res.tau_exp, p10=res.p10,
                        p_atm=res.p_atm, p_star=res.p_star,
                        atmosphere_measured=settings.atmosphere is None,
                        wall_std=wall_std, wall_input=wall_input,
                        extra_terms=extra_terms).to_dict()

def charge_final_budget(res: UnloadResult, settings: EstimatorSettings, *, c: float,
                        type_a_std: float, model_form_std: float, heat_law: str,
                        extra_terms: tuple[Any, ...], fit: CurveFit | None
                        ) -> dict[str, Any]:
    """A charge's budget of the final C [m^3/(s Pa)]: the fit's type A line; the
    crossing budget's stated inputs (V, T_s, the transducer's offset, a given supply: at
    fixed pressures each is proportional to C) scaled to ``c``; the wall's (fitted by a
    hot-start law: in the type A line; assumed: the fit's refits with the wall moved);
    ``extra_terms``; the heat laws' spread and the model's limits."""
    ref = res.extra.get("budget") or {}
    k = c / ref["value"] if ref.get("value") else math.nan
    terms = [record_term(FINAL_TYPE_A, type_a_std)]
    for t in ref.get("terms", ()):
        if t["kind"] == "B" and t["name"] != WALL_TERM:
            terms.append(BudgetTerm(t["name"], "B", math.nan if t["value"] is None
                                    else t["value"], math.nan if t["input_std"] is None
                                    else t["input_std"], t["unit"],
                                    math.nan if t["std"] is None else t["std"] * k,
                                    t["note"]))
    if heat_law.endswith("+wall") and fit is not None:
        terms.append(fitted_wall_term(fit.wall_temperature, fit.wall_temperature_std,
                                      heat_law))
    elif heat_law != "none" and fit is not None and math.isfinite(fit.wall_uncertainty):
        terms.append(wall_term(settings, c, fit.wall_std, fit.wall_uncertainty,
                               fit.wall_source))
    terms += [*extra_terms, model_form_term(model_form_std),
              model_limits_term(c, settings.model_limits)]
    return Budget(c, tuple(terms)).to_dict()


def b_budget(fit: CurveFit, settings: EstimatorSettings,
             res: UnloadResult, *, hot: tuple[BudgetTerm, ...] = ()) -> dict[str, Any]:
    """The budget of the curve fit's b [-]
    (:func:`~pneumatic_unload.uncertainty.budget_b.ratio_budget`) as
    :meth:`~pneumatic_unload.uncertainty.budget.Budget.to_dict`: the fit's type A, the inputs'
    lines, the wall's (assumed or given: ``fit.wall_std_b``), the heat laws' spread and,
    ``hot``, the line of a hot start claimed in a fit the model does not describe
    (:func:`~pneumatic_unload.curvefit.heat_law_offer.hot_start_terms`)."""
    law = fit.heat_law
    wall = None
    if law != "none" and not law.endswith("+wall"):
        u, why = (fit.wall_uncertainty, fit.wall_source) \
            if math.isfinite(fit.wall_uncertainty) else wall_uncertainty(settings)
        wall = (fit.wall_std_b, u, why)
    return ratio_budget(settings, fit.critical_ratio, type_a_std=fit.critical_ratio_std,
                        model_form_std=fit.model_form_std_b, p10=fit.p10, p_atm=fit.p_atm,
                        atmosphere_measured=settings.end_pressure is None, wall=wall,
                        wall_fitted=law.endswith("+wall"),
                        extra_terms=(subsonic_term(fit, "b"), *temperature_terms(fit, "b"),
                                     *hot),
                        offset_valley=fit.unfitted_offset.get("b", math.nan)).to_dict()


def crossing_wall_std(settings: EstimatorSettings, table: Any, tau: float, *,
                      p10: float, p_atm: float, p_star: float, c: float) -> float:
    """The model C's standard uncertainty from the wall temperature at the crossing
    [m^3/(s Pa)]: a lookup in the inversion table when it covers tau [s]; else two model
    inversions with the wall moved by +-u(T); NaN without a heat law (adiabatic).

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas, heat model and ``temperature_uncertainty``.
    table : InversionTable or None
        The table of :func:`prepare_inversion`.
    tau : float
        Crossing time [s].
    p10, p_atm, p_star : float
        Pressures [Pa absolute].
    c : float
        The model C [m^3/(s Pa)].
    """
    if settings.heat_model != "natural" or not (math.isfinite(c) and c > 0):
        return math.nan
    if table is not None and table.covers(tau):
        return float(table.wall_std(tau))
    return wall_sensitivity(settings, tau, p10=p10, p_atm=p_atm, p_star=p_star, c_start=c)


def prepare_inversion(settings: EstimatorSettings, t_mid: float, p_mid: float, p10: float,
                      p_atm: float, p_star: float) -> Any:
    """The inversion table, built when the pressure is half way to p* (a few model
    integrations, so that the crossing itself is a lookup); None when it cannot be built.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and heat-model settings.
    t_mid : float
        Time from the start to the half-way pressure [s].
    p_mid, p10, p_atm, p_star : float
        Half-way, initial, atmospheric and crossing pressures [Pa absolute].
    """

    if pressure_problem(p10, p_atm, p_star) is not None or not p10 > p_mid > p_star:
        return None
    c_guess = physics.conductance_isentropic_inversion(
        t_mid, p_mid, p10, settings.volume, settings.initial_temperature, settings.gas)
    try:
        return inversion_table(settings, p10=p10, p_atm=p_atm, p_star=p_star,
                               c_guess=c_guess)
    except (ValueError, ArithmeticError):
        return None


def model_inversion(settings: EstimatorSettings, tau: float, tau_std: float, p10: float,
                    p_atm: float, p_star: float, c_isen: float, table: Any = None
                    ) -> tuple[float, float, str]:
    """Model-based C: exact inversion of the discharge model at the crossing.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and heat-model settings.
    tau, tau_std : float
        Time from the start to the crossing of ``p_star`` and its 1-sigma [s].
    p10, p_atm, p_star : float
        Initial, atmospheric and crossing pressures [Pa absolute].
    c_isen : float
        Isentropic-inversion C, the start value [m^3/(s Pa)].
    table : InversionTable, optional
        Crossing times tabulated before the crossing: a lookup when it covers tau.

    Returns
    -------
    tuple
        (C [m^3/(s Pa)], its 1-sigma [m^3/(s Pa)], method name).
    """
    c, std, method, _wall = crossing_inversion(settings, tau, tau_std, p10, p_atm, p_star,
                                               c_isen, table=table, wall=False)
    return c, std, method


def crossing_inversion(settings: EstimatorSettings, tau: float, tau_std: float, p10: float,
                       p_atm: float, p_star: float, c_isen: float, table: Any = None,
                       wall: bool = True) -> tuple[float, float, str, float]:
    """:func:`model_inversion` and, with ``wall``, C's standard uncertainty from the wall
    temperature (:func:`crossing_wall_std`; NaN without a heat law) [m^3/(s Pa)]: one
    table lookup for both when the table covers tau [s].

    Returns
    -------
    tuple
        (C, its 1-sigma, method name, the wall's standard uncertainty) [m^3/(s Pa)].
    """
    if settings.heat_model == "adiabatic" and not may_turn_subsonic(settings, p_atm, p_star):
        # choked up to p*: the isentropic closed form is the adiabatic model's exact inverse
        c = c_isen
        std = c * tau_std / tau
        return c, std, "eq39+isentropic-inversion", math.nan
    law = "natural-convection" if settings.heat_model == "natural" else "adiabatic"
    method = f"eq39+model-inversion({law})"
    if table is not None and table.covers(tau):
        c, std, wall_std = table.lookup(tau, tau_std)
        if not (wall and settings.heat_model == "natural" and math.isfinite(c) and c > 0):
            wall_std = math.nan
        return c, std, method, wall_std
    c, std = invert_crossing(tau, tau_std, p10=p10, p_atm=p_atm, p_star=p_star,
                             settings=settings, c_start=c_isen)
    wall_std = crossing_wall_std(settings, None, tau, p10=p10, p_atm=p_atm, p_star=p_star,
                                 c=c) if wall else math.nan
    return c, std, method, wall_std


def final_curve_fit(res: UnloadResult, t: FloatArray | None, p: FloatArray | None,
                    settings: EstimatorSettings, *, noise_std: float,
                    reduced: Any = None, temperature: Any = None) -> UnloadResult | None:
    """Final result of an unload from the full-curve fit (None when it fails): the
    crossing result ``res``, the unload's samples t [s], p [Pa absolute] from its plateau
    to its tail's end (or ``reduced`` to bins), the sample noise [Pa] and a logged gas
    temperature ([s], [K]) fitted beside; see :func:`refine_with_curve_fit`."""
    return refine_with_curve_fit(res, t, p, settings, noise_std=noise_std, reduced=reduced,
                                 temperature=temperature)


def recovery_fit(t: FloatArray, p: FloatArray, t_close: float) -> Any:
    """Fit of the isochoric re-heating after the closing instant t_close [s] (samples t [s],
    p [signal units]); None when the fit fails."""
    try:
        return fit_recovery(t, p, t_close)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return None


#: A charge's curve fit is made from a second start, the adiabatic closed form's C, where
#: that differs from the crossing's model C by more than this [-] (closer, both starts
#: fell into one basin on the HydDown grid and the independent model's fills; the live
#: bench's fast 0.2 L tank, 4.7 % apart, then pays one fit, not two).
CHARGE_SECOND_START = 0.1


def _residual(fit: CurveFit) -> float:
    """The pressure's residual RMS of a curve fit [Pa] (inf when unknown)."""
    return fit.rms if math.isfinite(fit.rms) else math.inf


def crossing_stands(res: UnloadResult, why: str) -> UnloadResult:
    """The final result where the full-curve fit gave none: the crossing's, its status
    text saying so (never silent) and ``extra['curve_fit_error']`` why."""
    step = "".join(f"; {res.extra[k]}" for k in (TAIL_STEP,) if k in res.extra)
    return dataclasses.replace(res, final=True, extra={**res.extra, "curve_fit_error": why},
                               status_text=f"{res.status_text}; no full-curve fit ({why}): "
                                           f"C is the crossing's model inversion{step}")


def refine_with_curve_fit(
    res: UnloadResult, t: FloatArray, p: FloatArray, settings: EstimatorSettings,
    *, noise_std: float, hold: tuple[str, ...] = (), extra_terms: tuple[Any, ...] = (),
    fit_heat: bool | None = None, reduced: Any = None, temperature: Any = None,
) -> UnloadResult | None:
    """Final result of an unload: the crossing result refined by :func:`fit_curve`
    (``hold``: values held, and ``fit_heat``, see there; ``extra_terms``: further lines of
    the budget, :class:`~pneumatic_unload.uncertainty.budget.BudgetTerm`, e.g. a given p10's).

    Parameters
    ----------
    res : UnloadResult
        The estimate published at the p* crossing.
    t, p : ndarray
        Samples of the unload [s], [Pa absolute], plateau to end.
    settings : EstimatorSettings
        Estimator settings.
    noise_std : float
        Sample noise [Pa] (for the report).

    Returns
    -------
    UnloadResult or None
        A copy with ``final=True`` and the fitted values, or None when the fit failed.
    """
    if res.status not in ("ok", "ok_subsonic") or not math.isfinite(res.conductance_model):
        return None

    try:
        fit = fit_curve(t, p, settings, t_start=res.t_start, p10=res.p10,
                        p_atm=res.end_pressure,
                        conductance=res.conductance_model, hold=hold, fit_heat=fit_heat,
                        reduced=reduced, temperature=temperature)
        c_adi = res.conductance_isentropic
        if settings.charge and math.isfinite(c_adi) and abs(
                c_adi / res.conductance_model - 1.0) > CHARGE_SECOND_START:
            # a charge's fit again from the adiabatic closed form's C, the low end (heat
            # exchange only slows a fill): the rise fits a near-isothermal fill with C up
            # to gamma times higher about as well as the truth, and each start has its
            # basin (from the correlation's C a vacuum fill read +37 %, from the adiabatic
            # one a strongly cooled fill -27 %); the smaller residual decides (each fit's
            # criterion is scaled within its own family: not comparable across the two)
            low = fit_curve(t, p, settings, t_start=res.t_start, p10=res.p10,
                            p_atm=res.end_pressure, conductance=c_adi, hold=hold,
                            fit_heat=fit_heat, reduced=reduced, temperature=temperature)
            if _residual(low) < _residual(fit):
                fit = low
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return crossing_stands(res, str(exc))
    mf = fit.model_form_std if math.isfinite(fit.model_form_std) else 0.0
    c_std = math.sqrt(max(fit.conductance_std**2 - mf**2, 0.0))  # the record's part
    if fit.heat_law == "natural" and not math.isfinite(fit.heat_scale_std):
        c_std = math.hypot(c_std, res.extra.get("budget", {}).get(
            "type_a_std", res.conductance_model_std))
    if not (math.isfinite(fit.conductance) and fit.conductance > 0 and math.isfinite(c_std)):
        # a fit that does not determine C (flat or degenerate trace): the crossing stands
        return crossing_stands(res, f"the fit did not determine C ({fit.conductance:.3g}"
                                    f" +- {c_std:.3g} m^3/(s Pa))")
    lo, hi = (res.p10, SUPPLY_RANGE[1]) if settings.charge else ATMOSPHERE_RANGE
    if settings.charge and not lo < fit.p_atm <= hi:
        return crossing_stands(res, f"the fit moved the supply to {fit.p_atm:.0f} Pa, not "
                                    f"above p10 ({lo:.0f} Pa): give it (--supply PA)")
    if not settings.charge and not lo <= fit.p_atm <= hi:
        # p_atm fitted (not given) beyond any atmosphere: the fit describes something else
        return crossing_stands(res, f"the fit moved p_atm to {fit.p_atm:.0f} Pa, not an "
                                    f"atmosphere ({lo:.0f}-{hi:.0f} Pa): give it "
                                    "(--atmosphere PA)")
    t10 = fit.gas_temperature.get("t10", math.nan)
    if math.isfinite(t10):
        # T10 fitted with the logged temperature (its statistical part in the fit's line,
        # the probe's accuracy the T10 line), or by a hot start beside a wall at a room's
        # temperature (that room's uncertainty the T10 line: law_family.Family.t10_assumed)
        settings = dataclasses.replace(settings, initial_temperature=t10, temperature_uncertainty=(
            probe_uncertainty(settings) if "rms" in fit.gas_temperature else WALL_ASSUMED_STD))
    tau_model = fitted_tau_exp(fit.config(settings), res.tau_exp)
    if not (math.isfinite(tau_model) and tau_model > 0):
        tau_model = math.nan
    extra = {"curve_fit": dataclasses.asdict(fit), "noise_std": noise_std,
             "conductance_crossing_inversion": res.conductance_model}
    if "budget_eq39" in res.extra:
        extra["budget_eq39"] = res.extra["budget_eq39"]
    nrms = fit.rms / noise_std if math.isfinite(noise_std) and noise_std > 0 else math.nan
    why = inadequacy(nrms, fit.whiteness_p, fit.inflation)
    # the structure the fit leaves unexplained (1: none): variance inflation x residual scale
    structure = 1.0 if why is None else fit.inflation * residual_scale(nrms)
    hot = {of: hot_start_terms(fit, structure, of, spread_window=LAW_BIC_THRESHOLD)
           for of in ("C", "b")}
    budget = final_budget(res, settings, c=fit.conductance, type_a_std=c_std,
                          model_form_std=mf, heat_law=fit.heat_law,
                          extra_terms=(*extra_terms, subsonic_term(fit, "C"),
                                       *offset_terms(fit), *temperature_terms(fit),
                                       *hot["C"]), fit=fit)
    if budget is not None:
        extra["budget"] = budget
        c_std = budget["combined_std"]
    else:
        c_std = math.hypot(c_std, mf)
    b_std = fit.critical_ratio_std
    if math.isfinite(fit.critical_ratio):
        extra["budget_b"] = b_budget(fit, settings, res, hot=hot["b"])
        b_std = extra["budget_b"]["combined_std"]
    if math.isfinite(fit.critical_ratio) or fit.subsonic_index_fitted:  # (m without b: unchoked)
        u_w = fit.wall_uncertainty  # [K] the wall's, assumed (from the record) or given
        extra["budget_m"] = m_budget(fit, u_w if math.isfinite(u_w) else
                                     wall_uncertainty(settings)[0]).to_dict()
    status, text = res.status, res.status_text
    quality = res.quality if fit.success else min(res.quality, 0.5)
    extra["model_inadequate"] = why or ""
    b = fit.critical_ratio
    if settings.charge:
        if math.isfinite(b) and b > 0:
            ratio = res.p_star / res.end_pressure
            text = (f"{text}; {'choked' if ratio <= b else 'subsonic'} at p* with the "
                    f"fitted b = {b:.3f} (p*/p_s = {ratio:.3f})")
    elif math.isfinite(b) and b > 0:
        # the fit measured b: whether the flow stayed choked down to p* is now known
        limit = res.p_atm / b
        if res.p_star >= limit and status == "ok_subsonic":
            status, text = "ok", (f"choked down to p* with the fitted b = {b:.3f} (p* = "
                                  f"{res.p_star:.0f} Pa >= p_atm/b = {limit:.0f} Pa)")
        elif res.p_star < limit and status == "ok":
            status, text = "ok_subsonic", (
                f"flow subsonic before p* with the fitted b = {b:.3f} (p* = {res.p_star:.0f}"
                f" Pa < p_atm/b = {limit:.0f} Pa): eq 39 assumes choked flow")
    if why is not None:  # never silent: the status text carries it to every output
        text = f"{text}; model inadequate: {why}"
    if TAIL_STEP in res.extra:  # (the crossing's own text may have been replaced above)
        text = f"{text}; {res.extra[TAIL_STEP]}"

    return dataclasses.replace(
        res, final=True, status=status, status_text=text, conductance_model=fit.conductance,
        initial_temperature=settings.initial_temperature,
        conductance_model_std=c_std,
        t_start_model=fit.t_start, tau_exp_model=tau_model,
        critical_ratio=fit.critical_ratio, critical_ratio_std=b_std,
        subsonic_index=fit.subsonic_index if "budget_m" in extra else math.nan,
        subsonic_index_std=extra["budget_m"]["combined_std"] if "budget_m" in extra
        else math.nan,
        pressure_offset=fit.pressure_offset if math.isfinite(fit.pressure_offset_std)
        else math.nan, pressure_offset_std=fit.pressure_offset_std,
        method=res.method + "+curve-fit", extra=extra,
        quality=quality if why is None else min(quality, INADEQUATE_QUALITY))
