# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Whether a record carries the subsonic index m of ISO 6358-1:2013, and what holding it
costs (and the line of a fitted transducer zero offset).

The curve fit (:func:`pneumatic_unload.curvefit.fitting.fit_curve`) fits its chosen heat law once
more with m free. That variant is offered to the information criterion (the rule the heat
laws use: lowest BIC wins) only where the record determines m
(:func:`subsonic_index_problem`: the subsonic tail recorded, m within
:data:`SUBSONIC_INDEX_MAX_SD`). Where m stays held at 0.5, what that costs C and b is a line
of their budgets (:func:`held_lines`): their sensitivity to m along the m-free fit's valley
times m's standard uncertainty (the fit's own where the record determines m, else that of
the components' range, :data:`SUBSONIC_INDEX_PRIOR_SD`).

SI units: m^3/(s Pa); b and m are dimensionless.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.curvefit.linear_twin import Twin, valley_slopes
from pneumatic_unload.model.parametric import SUBSONIC_INDEX_START
from pneumatic_unload.uncertainty.budget import (
    WALL_TERM,
    Budget,
    BudgetTerm,
    model_form_term,
    record_term,
)

#: Name of m's line in the budgets of C and b.
SUBSONIC_TERM = "subsonic index m"
#: Reason when the m-free fit could not be made.
FAILED = "m held at 0.5; the fit with m free failed"
#: Key suffix of a law's variant with m fitted (in the curve fit's BIC table).
M_SUFFIX = "|m"
#: The m-free variant is offered only when the record determines m within this 1-sigma [-]
#: (enough to tell a silencer's 0.3 from the elliptic 0.5).
SUBSONIC_INDEX_MAX_SD = 0.1
#: Standard uncertainty of a held m where the record does not determine it [-]: m of valves,
#: nozzles, tubes and silencers lies within about 0.25-0.75 (a uniform law: 0.5/sqrt(12)).
SUBSONIC_INDEX_PRIOR_SD = 0.5 / math.sqrt(12.0)


def split_key(key: str) -> tuple[str, bool, bool]:
    """A curve-fit table key ('fixed', 'natural+wall', 'density|m', ...) as (heat law,
    wall fitted, m fitted)."""
    fit_m = key.endswith(M_SUFFIX)
    base = key.removesuffix(M_SUFFIX)
    fit_wall = base.endswith("+wall")
    return base.removesuffix("+wall"), fit_wall, fit_m


def subsonic_index_problem(fit: CurveFit) -> str | None:
    """Why the m-free fit is not offered to the criterion (None: offer it): C finite and m
    determined within :data:`SUBSONIC_INDEX_MAX_SD` (b need not be: a flow that is never
    choked determines m and C, not where choking would begin)."""
    sd = fit.subsonic_index_std
    if not math.isfinite(fit.conductance):
        return "the fit with m free did not converge"
    if not (math.isfinite(sd) and sd <= SUBSONIC_INDEX_MAX_SD):
        return (f"the record does not determine m (1-sigma {sd:.2g} > "
                f"{SUBSONIC_INDEX_MAX_SD:g})")
    return None


def held_lines(kept: dict[str, Any] | None, free: CurveFit | None, offered: bool
               ) -> tuple[float, float, float, str]:
    """C's [m^3/(s Pa)] and b's [-] standard uncertainty from m held at 0.5, m's standard
    uncertainty [-] and the reason in words: the slopes dC/dm and db/dm along the m-free
    fit's valley (``kept``: its FitResult 'result' and covariance scale 's2'; ``free``: its
    CurveFit) times m's uncertainty: the root mean square of holding 0.5, sqrt(sigma^2 +
    (m - 0.5)^2) of the m-free fit's m and 1-sigma, where the record determines m
    (``offered``), else :data:`SUBSONIC_INDEX_PRIOR_SD`. NaN when
    there is no m-free fit to take the slopes from."""
    if kept is None or free is None or "result" not in kept:
        return math.nan, math.nan, SUBSONIC_INDEX_PRIOR_SD, FAILED
    res = kept["result"]
    names = list(res.params.free)
    if "m" not in names or "C" not in names:
        return math.nan, math.nan, SUBSONIC_INDEX_PRIOR_SD, FAILED
    cov = np.asarray(res.covariance(kept["s2"]), dtype=float)
    slopes = valley_slopes(cov, names, res.params, free.conductance, names.index("m"),
                           res.params["m"].scale) if np.all(np.isfinite(cov)) else None
    if slopes is None:
        return (math.nan, math.nan, SUBSONIC_INDEX_PRIOR_SD,
                "m held at 0.5; the slopes of C and b along m are not determined")
    return twin_lines(Twin("m", math.nan, free.subsonic_index, free.subsonic_index_std,
                           *slopes), determined=offered, how="the criterion keeps 0.5")


def twin_lines(tw: Twin | None, *, determined: bool | None = None,
               how: str = "to first order, too close to 0.5 to be fitted"
               ) -> tuple[float, float, float, str]:
    """As :func:`held_lines`, from m's twin of the held fit (the first-order one of
    :func:`~pneumatic_unload.curvefit.linear_twin.linear_twin`, or the m-free fit's): where the
    record determines m (``determined``; default: within :data:`SUBSONIC_INDEX_MAX_SD`),
    m's uncertainty is the root mean square of holding 0.5, sqrt(sigma^2 + (m - 0.5)^2)
    (it was max(sigma, |m - 0.5|): a held m 0.009 from the truth stated +- 0.0024), else
    :data:`SUBSONIC_INDEX_PRIOR_SD`; ``how``: why m is held all the same."""
    if tw is None:
        return math.nan, math.nan, SUBSONIC_INDEX_PRIOR_SD, FAILED
    if determined is None:
        determined = tw.std <= SUBSONIC_INDEX_MAX_SD
    if determined:
        u = math.hypot(tw.std, tw.value - SUBSONIC_INDEX_START)
        why = f"m held at 0.5: the record determines m = {tw.value:.3f} +- {tw.std:.3f}, {how}"
    else:
        u = SUBSONIC_INDEX_PRIOR_SD
        why = (f"m held at 0.5 (+- {u:.3f}, the range of components): the record does not "
               "determine it")
    b = abs(tw.slope_b) * u if math.isfinite(tw.slope_b) else 0.0
    return abs(tw.slope_c) * u, b, u, why


def subsonic_term(fit: CurveFit, quantity: str) -> BudgetTerm:
    """The budget line of m for C (``quantity`` 'C', std [m^3/(s Pa)]) or b ('b', [-]):
    with m held, the move of holding it (:func:`held_lines`); fitted, 0 (its uncertainty is
    in the curve fit's line)."""
    std = fit.subsonic_std if quantity == "C" else fit.subsonic_std_b
    note = fit.subsonic_source + ("; in the curve fit's line" if fit.subsonic_index_fitted
                                  else "")
    return BudgetTerm(SUBSONIC_TERM, "B", fit.subsonic_index, fit.subsonic_index_std, "-",
                      0.0 if fit.subsonic_index_fitted else std, note)


def m_budget(fit: CurveFit, wall_input: float = math.nan) -> Budget:
    """The budget of m [-]: fitted, the curve fit's line, the wall temperature's (the chosen
    law refitted with the wall moved, ``fit.wall_std_m``: a 2 K wall moved m by 0.010 where
    its fit said +- 0.001), the transducer's zero where it was not fitted
    (``fit.unfitted_offset``: its move along the fit's valley) and the heat laws' spread of
    the laws fitted with m (``fit.model_form_std_m``); held, the held value's uncertainty
    (:func:`held_lines`), the zero's move of the law's m-free fit, and, where the laws were
    fitted with m too, their spread of m (``fit.model_form_std_m``, folded into
    ``fit.subsonic_index_std``)."""
    mf = fit.model_form_std_m if math.isfinite(fit.model_form_std_m) else 0.0
    off = fit.unfitted_offset
    zero = (BudgetTerm("pressure transducer (offset)", "B", fit.p10, off["input_std"],
                       "Pa", off["m"], "not fitted: the fit's move along its valley with "
                       "the zero freed, to first order" + (
                           "" if fit.subsonic_index_fitted else " (the law's fit with m "
                           "free)")),) \
        if math.isfinite(off.get("m", math.nan)) else ()
    if fit.subsonic_index_fitted:
        wall = (BudgetTerm(WALL_TERM, "B", math.nan, wall_input, "K",
                           fit.wall_std_m, "the chosen law refitted with the wall moved, "
                           "to first order"),) if math.isfinite(fit.wall_std_m) else ()
        return Budget(fit.subsonic_index, (
            record_term("curve fit (noise, AR(1), residual structure)",
                        fit.subsonic_index_std), *wall, *zero, model_form_term(mf)))
    held = math.sqrt(max(fit.subsonic_index_std**2 - mf**2, 0.0))
    return Budget(fit.subsonic_index, (
        BudgetTerm("m held", "B", fit.subsonic_index, held, "-", held, fit.subsonic_source),
        *zero, *((model_form_term(mf),) if mf > 0.0 else ())))


def held_spread(m_c: float, m_b: float, m_u: float, spread: float
                ) -> tuple[float, float, float]:
    """A held m's lines of C [m^3/(s Pa)] and b [-] and its uncertainty [-] (those of
    :func:`held_lines`) widened by the heat laws' spread of m among the laws fitted with m
    (``spread`` [-], NaN or 0: none): m's uncertainty sqrt(m_u^2 + spread^2), the lines
    along the same slopes."""
    if not (math.isfinite(spread) and spread > 0.0 and m_u > 0.0):
        return m_c, m_b, m_u
    u = math.hypot(m_u, spread)
    return m_c * u / m_u, m_b * u / m_u, u


def offset_terms(fit: CurveFit) -> tuple[BudgetTerm, ...]:
    """The fitted zero offset's line of C's budget (none when it was not fitted): its value
    and 1-sigma [Pa], 0 in the budget (its uncertainty is in the curve fit's line)."""
    if not math.isfinite(fit.pressure_offset_std):
        return ()
    return (BudgetTerm("pressure transducer zero (fitted)", "A", fit.pressure_offset,
                       fit.pressure_offset_std, "Pa", 0.0,
                       f"{fit.offset_source}; in the curve fit's line"),)
