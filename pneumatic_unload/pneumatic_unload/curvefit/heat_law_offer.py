# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Which heat laws of the curve fit's family a record can carry: the laws with a second
parameter (the density law's exponent, the natural law's turbulent branch) are offered to
the information criterion only where the record determines that parameter; elsewhere they
are not offered, with the reason (:func:`pneumatic_unload.curvefit.fitting.fit_curve` reports it).
And where the next law's fit starts from the first law's (:func:`next_law_start`).

SI units: s, Pa absolute, K.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.model import discharge
from pneumatic_unload.model.effects import HEAT_FIXED, HEAT_NATURAL
from pneumatic_unload.model.heat import RA_TURBULENT, rayleigh, thermal_time_constant
from pneumatic_unload.uncertainty.budget import BudgetTerm

FloatArray = NDArray[np.float64]

#: The natural law with its turbulent branch fitted apart is offered only when the natural
#: fit's record spends at least this share of its time [-] in each regime (Ra below and
#: above :data:`~pneumatic_unload.model.heat.RA_TURBULENT`) ...
TURBULENT_MIN_SHARE = 0.05
#: ... and keeps it when that multiplier's log is determined within this 1-sigma [-].
TURBULENT_MAX_LOG_SD = 0.2
#: The density law (hA ~ rho^n) is offered only where the record determines the heat
#: exchange (the constant-hA fit's tau_heat within this relative 1-sigma [-]) ...
DENSITY_LAW_MIN_TAU_REL_SD = 0.2
#: ... and its exponent n within this 1-sigma [-] (enough to tell a constant hA, n = 0,
#: from convection's 1/2-2/3).
DENSITY_LAW_MAX_EXPONENT_SD = 0.2


def both_regimes(share: float) -> bool:
    """The record carries the turbulent branch apart: the share of its time after the
    opening with Ra >= RA_TURBULENT [-] leaves at least :data:`TURBULENT_MIN_SHARE` in
    each regime (the rule of the curve fit and of the discrepancy search alike)."""
    return min(share, 1.0 - share) >= TURBULENT_MIN_SHARE


def exchange_determined(tau_heat: float, tau_heat_std: float) -> bool:
    """The record determines the heat exchange: the constant-hA law's tau_heat [s] within
    :data:`DENSITY_LAW_MIN_TAU_REL_SD` (relative 1-sigma; tau_heat_std [s]), as the density
    law needs (the rule of the curve fit and of the discrepancy search alike)."""
    rel = tau_heat_std / tau_heat if tau_heat > 0 else math.nan
    return bool(math.isfinite(rel) and rel <= DENSITY_LAW_MIN_TAU_REL_SD)


def turbulent_law_problem(natural: CurveFit | None, settings: EstimatorSettings,
                          t_last: float) -> str | None:
    """Why the record cannot carry the natural law's turbulent branch apart (None: offer
    it): the natural fit's model must spend :data:`TURBULENT_MIN_SHARE` of the record after
    the opening in each regime (t_last: the record's last instant [s])."""
    if natural is None or not math.isfinite(natural.conductance):
        return "no natural-convection fit to start from"
    t0 = natural.t_start
    tt = np.linspace(0.0, max(t_last - t0, 1e-6), 400)
    try:
        cfg = natural.config(settings)
        pp, tg = discharge(cfg, tt, 0.0)
    except ValueError as exc:
        return f"the natural fit's model could not be integrated ({exc})"
    share = float(np.mean(rayleigh(cfg, pp, tg) >= RA_TURBULENT))
    if not both_regimes(share):
        return (f"the record stays in one regime of the correlation (turbulent share "
                f"{100 * share:.0f} %)")
    return None


def density_law_problem(fixed: CurveFit | None) -> str | None:
    """Why the record cannot carry the density law's exponent, from the constant-hA fit
    (None: offer it): the heat exchange itself must be measured to
    :data:`DENSITY_LAW_MIN_TAU_REL_SD` (an hA the record hardly sees has no measurable
    dependence on density)."""
    if fixed is None:
        return "no constant-hA fit to start from"
    if not exchange_determined(fixed.tau_heat, fixed.tau_heat_std):
        rel = fixed.tau_heat_std / fixed.tau_heat if fixed.tau_heat > 0 else math.nan
        return (f"the record does not determine the heat exchange (tau_heat 1-sigma "
                f"{100 * rel:.3g} % > {100 * DENSITY_LAW_MIN_TAU_REL_SD:g} %)")
    return None


def next_law_start(first: CurveFit, settings: EstimatorSettings, t0: float
                   ) -> dict[str, float]:
    """Starting values [SI] of the next laws' fits from the first law's fit (times relative
    to t0 [s]): its C, opening, p10, b (and p_atm and m when fitted), the heat exchange as the
    thermal time constant of the gas 20 K below the wall; where the natural law's scale
    sits on its lower bound (the record shows no exchange), the constant-hA law's longest
    time constant (no exchange either: it then starts converged in that coordinate)."""
    cfg = first.config(settings)
    start = {"C": first.conductance, "t_open": first.t_start - t0, "p10": first.p10,
             "tau_heat": thermal_time_constant(cfg, first.p10, cfg.wall - 20.0)}
    if first.heat_law == "natural" and first.heat_scale <= 1.001 * HEAT_NATURAL.params[0].lo:
        start["tau_heat"] = HEAT_FIXED.params[0].hi
    if math.isfinite(first.critical_ratio):
        start["b"] = first.critical_ratio
    if settings.end_pressure is None:
        start["p_atm"] = first.p_atm
    if first.subsonic_index_fitted:
        start["m"] = first.subsonic_index
    return start


def hot_start_terms(fit: CurveFit, structure: float, of: str = "C", *,
                    spread_window: float = 0.0) -> tuple[BudgetTerm, ...]:
    """C's (``of`` "C") or b's ("b") budget line of a hot start claimed from the pressure
    alone in a fit the model does not describe; none otherwise.

    A hot start (the chosen law beside a wall, T10 fitted without a log) bends the
    pressure curve as the gas cools; where the residuals stay structured with it (model
    inadequate: ``structure`` > 1, the variance inflation times the residual scale of
    :func:`~pneumatic_unload.fit.uncertainty.inadequacy`), that bend may stand in for a
    flow curve outside the law's family (two restrictions in series: a 47 K warm gas
    claimed in a nearly adiabatic 23 L tank, C -8.5 % at z -9.6, where the laws without it
    read C within 0.1 % at a chi^2 1.4 times the claim's, its structure 2.98). The best
    law without the claim (lowest BIC among the laws without a wall) is then a reading of
    the record all the same where its chi^2 exceeds the claim's by no more than the
    structure the claim leaves unexplained, chi^2 (1 - 1/structure) (a real warm gas
    leaves the laws without it 12-50 times its chi^2, at a structure of 1.1-1.4); the line
    is the gap between the two over sqrt(3) (a rectangle from the reported value to it, as
    the assumed wall's) [m^3/(s Pa)], [-]. A law within ``spread_window`` of the claim's
    BIC is in the heat laws' model-form spread already (``LAW_BIC_THRESHOLD``): no line.
    """
    laws = {k: v for k, v in fit.laws.items() if math.isfinite(v.get("bic", math.nan))}
    if not structure > 1.0 or "+wall" not in fit.heat_law or "rms" in fit.gas_temperature \
            or not laws:
        return ()
    chosen = min(laws, key=lambda k: laws[k]["bic"])
    others = {k: v for k, v in laws.items() if "+wall" not in k}
    if "+wall" not in chosen or not others:
        return ()
    key = min(others, key=lambda k: others[k]["bic"])
    chi2 = laws[chosen]["chi2"]
    if not others[key]["chi2"] - chi2 <= chi2 * (1.0 - 1.0 / structure) \
            or others[key]["bic"] - laws[chosen]["bic"] < spread_window:
        return ()
    field = "conductance" if of == "C" else "critical_ratio"
    own = fit.conductance if of == "C" else fit.critical_ratio
    alt = float(others[key].get(field, math.nan))
    if not (math.isfinite(alt) and math.isfinite(own)):
        return ()
    return (BudgetTerm(
        "hot start (claimed from the pressure, the model inadequate)", "model", math.nan,
        math.nan, "", abs(alt - own) / math.sqrt(3.0),
        f"the best law without the claim ({key}) reads {alt:.4g} at chi^2 "
        f"{others[key]['chi2']:.0f} against the claim's {chi2:.0f} (structure x "
        f"{structure:.2f}): |gap|/sqrt(3)"),)
