# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The wall temperature's and the heat laws' moves of the curve fit's C, b and m, for the
lines of their budgets (:mod:`pneumatic_unload.uncertainty.budget`).

A wall temperature assumed (= T10) or given has a standard uncertainty; the fitted C and b
(and m, where fitted) move with it. :func:`wall_linear` takes the move to first order from
the fit's Jacobian (two model evaluations); the full refit is
:func:`pneumatic_unload.curvefit.fitting.fit_curve`'s.
:func:`law_spread` is a quantity's model-form spread over the heat laws, weighted by the
criterion (:mod:`pneumatic_unload.selection`).

SI units: K, m^3/(s Pa); b is a pressure ratio [-].
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pneumatic_unload.config.estimator import EstimatorSettings, with_wall
from pneumatic_unload.config.tank import WALL_RANGE
from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.model.inversion import estimator_model
from pneumatic_unload.selection.averaging import model_average
from pneumatic_unload.selection.evidence import weights

#: Singular values of the fit's Jacobian below this fraction of the largest are held in
#: the first-order step where the full step leaves the float range [-]: a heat exchange
#: near its faded end (no exchange) is a direction the record does not determine, and its
#: step is undefined (the two refits it took instead walked the flat valley: 148 residual
#: evaluations and C moved 0.3 % by the walk, not by the wall; an adiabatic rig's charge).
NULL_RCOND = 1e-8


def wall_linear(trace: Trace, kept: dict[str, Any], settings: EstimatorSettings,
                u: float, *, law: str) -> tuple[float, float, float]:
    """C's, b's and m's standard uncertainties ([m^3/(s Pa)], [-], [-]) from a wall
    temperature of standard uncertainty u [K]: the curve fit's law refitted with the wall
    moved, to first order, at a cost of two model evaluations instead of two fits
    (``kept``: the fit's FitResult 'result' and model 'model'). With the wall moved by +-u
    the residual at the
    fitted values changes by dr; the refit's parameter shift is the Gauss-Newton step
    -J^+ dr with the fit's Jacobian J (the fitted values are the minimum of the unmoved
    problem, J^T r = 0 there); the moves are root-mean-squared as the refit's are. NaN when
    it cannot be computed, or the step leaves the float range (the response is then not
    linear: the caller refits); b's (m's) NaN also when b (m) was not fitted."""
    fit, model = kept["result"], kept["model"]
    free = list(fit.params.free)
    jac = np.asarray(fit.jac, dtype=float)
    if "C" not in free or jac.shape != (fit.fun.size, len(free)) \
            or not np.all(np.isfinite(jac)):
        return math.nan, math.nan, math.nan
    moves: list[float] = []
    b_moves: list[float] = []
    m_moves: list[float] = []
    lo, hi = fit.params.bounds()
    with np.errstate(all="ignore"):
        live = ~((fit.x - lo < 1e-3 * (hi - lo)) | (hi - fit.x < 1e-3 * (hi - lo)))
        for sign in (1.0, -1.0):
            wall = float(np.clip(settings.wall + sign * u, *WALL_RANGE))
            moved = estimator_model(with_wall(settings, wall),
                                    model.start, heat_law=law,
                                    fit_m=model.subsonic_index is None,
                                    fit_offset="sensor_offset" in model.effects,
                                    thermometer=model.thermometer,
                                    fit_t10=model.fit_initial_temperature)
            try:
                dr = np.asarray(trace.residual(moved)(fit.values), dtype=float) - fit.fun
            except (ValueError, ArithmeticError):
                return math.nan, math.nan, math.nan
            if not np.all(np.isfinite(dr)):
                return math.nan, math.nan, math.nan
            # parameters on a bound of their range (a thermometer's lag at its floor) are
            # held: their flat column would take the step out of the float range
            dx = np.zeros(len(free))
            v = None
            for rcond in (1e-12, NULL_RCOND):
                dx[live], *_ = np.linalg.lstsq(jac[:, live], -dr, rcond=rcond)
                try:  # a step beyond float range (log coordinates): not to first order
                    v = fit.params.to_values(fit.x + dx)
                    break
                except OverflowError:
                    # along a direction the record does not determine (a heat exchange
                    # near its faded end: no exchange) the step is undefined: held
                    continue
            if v is None:
                return math.nan, math.nan, math.nan
            moves.append(v["C"] - fit.values["C"])
            b_moves.append(v["b"] - fit.values["b"] if "b" in free else math.nan)
            m_moves.append(v["m"] - fit.values["m"] if "m" in free else math.nan)
    return rms_moves(moves), rms_moves(b_moves), rms_moves(m_moves)


def rms_moves(moves: list[float]) -> float:
    """The root mean square of the two moves (the wall at +-u) [their unit]; NaN if
    either is."""
    return math.sqrt(sum(d * d for d in moves) / 2.0)


def law_spread(fits: dict[str, tuple[CurveFit, float, int]], bic: dict[str, float],
               best: str, attr: str, empty: float = math.nan,
               own: frozenset[str] = frozenset()) -> float:
    """Model-form 1-sigma of a fitted quantity ``attr`` ('conductance' [m^3/(s Pa)],
    'critical_ratio' [-], 'subsonic_index' [-]) about the chosen law ``best``'s value: the
    weighted spread sqrt(sum_k w_k (x_k - x_best)^2) over the laws of ``fits``, with the
    criterion's weights w_k ~ exp(-(BIC_k - BIC_min)/2) (:mod:`pneumatic_unload.selection`,
    over the laws that carry a finite value); ``empty`` when none does, NaN when the chosen
    law's value is not finite. The fits named in ``own`` add their own variance beyond the
    chosen law's (``attr + '_std'``), weighted alike: the model average's within term (a
    reading that determines the quantity loosely widens it)."""
    v0 = getattr(fits[best][0], attr)
    values = {law: getattr(f[0], attr) for law, f in fits.items()}
    if not any(math.isfinite(v) for v in values.values()):
        return empty
    if not math.isfinite(v0):
        return math.nan
    sd0 = getattr(fits[best][0], attr + "_std") if own else 0.0
    extra = {law: (getattr(fits[law][0], attr + "_std") ** 2 - sd0**2 if law in own else 0.0)
             for law in values}
    extra = {law: v if math.isfinite(v) else 0.0 for law, v in extra.items()}
    avg = model_average(values, weights({law: bic[law] for law in values}), extra)
    return math.sqrt(max(avg.spread_about(v0) ** 2 + avg.within, 0.0))


def spread_b(fits: dict[str, tuple[CurveFit, float, int]], bic: dict[str, float],
             best: str, own: frozenset[str] = frozenset()) -> float:
    """b's model-form 1-sigma [-] (:func:`law_spread` of the critical ratio); NaN when the
    chosen law did not determine b."""
    return law_spread(fits, bic, best, "critical_ratio", own=own)
