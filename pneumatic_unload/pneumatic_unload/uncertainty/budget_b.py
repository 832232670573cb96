# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Uncertainty budget of the critical pressure ratio b of the final curve fit, with the
lines of C's (:mod:`pneumatic_unload.uncertainty.budget`: the same :class:`Budget`, type A, type
B and model form), so that b's sigma carries what the inputs' stated uncertainties do to it.

SI units: Pa, K, m^3; b is a pressure ratio [-].
"""

from __future__ import annotations

import math

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.uncertainty.budget import (
    WALL_TERM,
    Budget,
    BudgetTerm,
    input_uncertainties,
    model_form_term,
    record_term,
)


def ratio_budget(settings: EstimatorSettings, b: float, *, type_a_std: float,
                 model_form_std: float, p10: float, p_atm: float, atmosphere_measured: bool,
                 wall: tuple[float, float, str] | None, wall_fitted: bool = False,
                 extra_terms: tuple[BudgetTerm, ...] = (), offset_valley: float = math.nan
                 ) -> Budget:
    """The budget of the curve fit's critical pressure ratio b [-], line by line as C's.

    b is where the fitted flow turns subsonic, p_atm / p1 there; its sensitivities:

    * V: none (the discharge depends on t C/V: V moves C, not b);
    * T10: none when the wall is assumed = T10 or fitted (the gas-wall gap does not move;
      the time scale t C sqrt(T10) does not move b); with a wall given, T10's uncertainty
      moves the gap as the wall's does (the wall line's move);
    * a transducer offset d: with p_atm measured by the same transducer, both ends of the
      ratio move, db = d b (1 - b) / p_atm; with p_atm given, db = b^2 d / p_atm (first
      order at the transition), or, where larger, the fit's own move along its valley with
      the offset freed (``offset_valley`` [-]: b and m take up an offset the record's end
      does not show);
    * p_atm given by a barometer: db = b u(p_atm) / p_atm;
    * the wall temperature (a heat law fitted, the wall assumed or given): the chosen law
      refitted with the wall moved by its uncertainty, to first order
      (:func:`pneumatic_unload.curvefit.wall_moves.wall_linear`); a fitted wall is in the type A
      line;
    * model form: the spread of the b of the heat laws that fit about equally well.

    Parameters
    ----------
    settings : EstimatorSettings
        Inputs and their uncertainties.
    b : float
        The fitted b [-].
    type_a_std, model_form_std : float
        b's 1-sigma from the record and the heat laws' spread [-] (NaN: 0).
    p10, p_atm : float
        Initial and atmospheric pressures [Pa absolute] (a charge's: p_atm the supply's,
        b = p2/p_s at the transition, an offset moving the tank's p2).
    atmosphere_measured : bool
        p_atm (a charge's supply) came from the record.
    wall : tuple, optional
        (b's standard uncertainty from the wall [-], the wall's standard uncertainty [K],
        where it comes from); None without a heat law.
    wall_fitted : bool
        The chosen law fitted the wall (a hot start).
    extra_terms : tuple of BudgetTerm
        Further lines (the subsonic index m's, [-]).
    offset_valley : float
        b's standard uncertainty from the unfitted offset along the fit's valley [-]
        (:func:`~pneumatic_unload.curvefit.offset_offer.unfitted_offset_lines`; NaN: none).
    """
    s = settings
    u = input_uncertainties(s, p10)
    terms = [record_term("curve fit (noise, AR(1), residual structure)", type_a_std),
             BudgetTerm("volume V", "B", s.volume, u["volume"], "m^3", 0.0,
                        "b does not depend on V (the discharge depends on t C/V)")]
    gap_moves = wall is not None and s.wall_temperature is not None and not wall_fitted
    terms.append(BudgetTerm(
        "initial temperature T10", "B", s.initial_temperature, u["initial_temperature"], "K",
        wall[0] * u["initial_temperature"] / wall[1] if gap_moves and wall[1] > 0 else 0.0,
        "moves the gas-wall gap as the given wall's uncertainty does" if gap_moves else
        "the wall moves with T10 (or is fitted); the time scale does not move b"))
    d = u["pressure"]
    if s.charge:  # b = p2/p_s at the transition: the tank's pressure p2 moves
        terms.append(BudgetTerm(
            "pressure transducer (offset)", "B", p10, d, "Pa",
            abs(d * (1.0 - b) / p_atm) if atmosphere_measured else abs(d / p_atm),
            "first order at the transition: p2 " + ("and p_s move" if atmosphere_measured
                                                    else "moves, p_s given")))
    elif atmosphere_measured or not offset_valley > abs(d * b * b / p_atm):
        terms.append(BudgetTerm(
            "pressure transducer (offset)", "B", p10, d, "Pa",
            abs(d * b * (1.0 - b) / p_atm) if atmosphere_measured else abs(d * b * b / p_atm),
            "first order at the transition: p_atm " + ("and p1 move" if atmosphere_measured
                                                       else "given, p1 moves")))
    else:
        terms.append(BudgetTerm(
            "pressure transducer (offset)", "B", p10, d, "Pa", offset_valley,
            "not fitted: the fit's move along its valley with the zero freed, to first "
            "order (b and m take up an offset the record's end does not show)"))
    if not atmosphere_measured:
        ua = s.end_uncertainty
        terms.append(BudgetTerm("supply p_s (given)" if s.charge else
                                "atmosphere p_atm (given)", "B", p_atm, ua, "Pa",
                                abs(b * ua / p_atm), "supply_pressure_uncertainty"
                                if s.charge else "atmosphere_uncertainty"))
    if wall_fitted:
        terms.append(BudgetTerm(WALL_TERM, "B", s.wall, math.nan, "K", 0.0,
                                "fitted (a hot start): in the curve fit's line"))
    elif wall is not None:
        std, uw, why = wall
        per_k = std / uw if uw > 0 and math.isfinite(std) else math.nan
        terms.append(BudgetTerm(WALL_TERM, "B", s.wall, uw, "K", std,
                                f"{why}; |db/dTw| = {per_k:.3g} /K" if math.isfinite(per_k)
                                else why))
    terms.extend(extra_terms)
    terms.append(model_form_term(model_form_std if math.isfinite(model_form_std) else 0.0))
    return Budget(b, tuple(terms))
