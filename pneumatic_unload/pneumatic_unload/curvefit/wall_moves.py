# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The wall temperature's and the heat laws' moves of the curve fit's C, b and m, for the
lines of their budgets (:mod:`pneumatic_unload.uncertainty.budget`).

A wall temperature assumed (= T10) or given has a standard uncertainty; the fitted C and b
(and m, where fitted) move with it. :func:`wall_linear` takes the move to first order from
the fit's Jacobian (two model evaluations); the full refit is
:func:`pneumatic_unload.curvefit.fitting.fit_curve`'s.
:func:`spread_b` is b's model-form spread over the heat laws that fit about equally well
(C's is computed beside the BIC table in :mod:`pneumatic_unload.curvefit.fitting`).

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
               best: str, threshold: float, attr: str, empty: float = math.nan,
               own: frozenset[str] = frozenset()) -> float:
    """Model-form 1-sigma of a fitted quantity ``attr`` ('conductance' [m^3/(s Pa)],
    'critical_ratio' [-]): the spread of its values over the laws within ``threshold`` in
    BIC (the curve fit's LAW_BIC_THRESHOLD) of ``best`` about the best law's value,
    weighted exp(-dBIC/2); ``empty`` when no law carries a finite value, NaN when the
    chosen law's value is not finite. The fits named in ``own`` add their own variance
    beyond the chosen law's (``attr + '_std'``), weighted alike: the model average's
    variance (a reading that determines the quantity loosely widens it)."""
    v0 = getattr(fits[best][0], attr)
    var, w_sum = 0.0, 0.0
    near = {law: bic[law] - bic[best] for law, f in fits.items()
            if bic[law] - bic[best] < threshold and math.isfinite(getattr(f[0], attr))}
    # the weights relative to the lowest BIC among them (a reading that fits far better
    # than ``best``, e.g. an unclaimed warm gas, must not overflow exp)
    d_min = min(near.values(), default=0.0)
    for law, d in near.items():
        w = math.exp(-0.5 * (d - d_min))
        w_sum += w
        var += w * (getattr(fits[law][0], attr) - v0) ** 2
        if law in own:
            extra = getattr(fits[law][0], attr + "_std") ** 2 \
                - getattr(fits[best][0], attr + "_std") ** 2
            var += w * extra if math.isfinite(extra) else 0.0
    if not w_sum > 0:
        return empty
    return math.sqrt(max(var, 0.0) / w_sum) if math.isfinite(v0) else math.nan


def spread_b(fits: dict[str, tuple[CurveFit, float, int]], bic: dict[str, float],
             best: str, threshold: float = 10.0, own: frozenset[str] = frozenset()) -> float:
    """b's model-form 1-sigma [-] (:func:`law_spread` of the critical ratio); NaN when the
    chosen law did not determine b."""
    return law_spread(fits, bic, best, threshold, "critical_ratio", own=own)
