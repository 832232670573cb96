# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A fit's twin with one parameter more, to first order: what freeing it would gain.

Freeing the subsonic index m or a transducer's zero offset costs a fit of its own (hundreds
of model evaluations); most records do not ask for it. :func:`linear_twin` takes the
fitted model's Jacobian, adds the new parameter's column (one more model evaluation, a
forward difference), and solves the augmented Gauss-Newton problem at the fit's minimum:
the chi^2 the twin would gain (the score test), the parameter's value and 1-sigma, and the
slopes of C and b along it (the lines of holding it in their budgets). The full twin is
fitted only where that gain is worth it (:mod:`pneumatic_unload.curvefit.law_family`).

SI units: m^3/(s Pa); the new parameter's own (m [-], offset [Pa]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pneumatic_unload.fit.params import Parameters
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.model.parametric import ParametricModel

#: Forward-difference step of the new parameter's column, in its scaled coordinate [-].
STEP = 1e-2


@dataclass(frozen=True)
class Twin:
    """The first-order twin of a fit with parameter ``name`` freed.

    Attributes
    ----------
    name : str
        The parameter freed.
    gain : float
        chi^2 drop predicted [Pa^2, the fit's residual units].
    value, std : float
        The parameter's value at the twin's minimum and its 1-sigma [its unit].
    slope_c, slope_b : float
        dC/d(parameter) [m^3/(s Pa) per unit] and db/d(parameter) [- per unit] along the
        twin's valley (NaN for b when b is not fitted).
    chi2, dof : float, int
        The fit's chi^2 [Pa^2] and the twin's degrees of freedom [-].
    slope_m : float
        dm/d(parameter) [- per unit] along the twin's valley (NaN when m is not fitted).
    """

    name: str
    gain: float
    value: float
    std: float
    slope_c: float
    slope_b: float
    chi2: float = math.nan
    dof: int = 1
    slope_m: float = math.nan


def linear_twin(trace: Trace, kept: dict[str, Any], twin: ParametricModel, name: str,
                start: float) -> Twin | None:
    """The first-order twin of the fit ``kept`` ('result': its FitResult, 's2': the
    covariance scale [Pa^2]) in ``twin``, the same model with parameter ``name`` free (held
    at ``start`` in the fit). None when it cannot be computed (a non-finite column or
    Jacobian)."""
    fit = kept.get("result")
    if fit is None or "s2" not in kept:
        return None
    p = twin.parameters[name]
    jac = np.asarray(fit.jac, dtype=float)
    if jac.shape != (fit.fun.size, fit.k) or not np.all(np.isfinite(jac)):
        return None
    values = {**fit.values, name: start}
    fun = trace.residual(twin)
    try:
        with np.errstate(all="ignore"):
            r0 = np.asarray(fun(values), dtype=float)
            r1 = np.asarray(fun({**values, name: start + STEP * p.scale}), dtype=float)
    except (ValueError, ArithmeticError):
        return None
    col = (r1 - r0) / STEP
    if not (np.all(np.isfinite(col)) and np.all(np.isfinite(r0))):
        return None
    aug = np.column_stack([jac, col])
    dx, *_ = np.linalg.lstsq(aug, -r0, rcond=1e-12)
    gain = float(r0 @ r0 - np.sum((r0 + aug @ dx) ** 2))
    try:
        cov = np.linalg.inv(aug.T @ aug) * float(kept["s2"])
    except np.linalg.LinAlgError:
        return None
    names = list(fit.params.free)
    slopes = valley_slopes(cov, names, fit.params, fit.values["C"], len(names), p.scale)
    if slopes is None:
        return None
    slope_m = float(cov[names.index("m"), -1] / cov[-1, -1]) * fit.params["m"].scale \
        / p.scale if "m" in names else math.nan
    return Twin(name, gain, start + float(dx[-1]) * p.scale,
                math.sqrt(float(cov[-1, -1])) * p.scale, *slopes, float(r0 @ r0),
                r0.size - fit.k - 1, slope_m)


def valley_slopes(cov: np.ndarray, names: list[str], params: Parameters, conductance: float,
                  j: int, scale: float) -> tuple[float, float] | None:
    """dC/dq [m^3/(s Pa) per unit] and db/dq [- per unit] along the valley of a parameter
    q fitted linearly with ``scale`` [its unit]: its column ``j`` of a covariance ``cov``
    in scaled coordinates whose other columns are ``names`` (C fitted as its log, b
    linearly, scales from ``params``; C's value ``conductance``); b's NaN when b is not
    fitted. None when q's variance is not positive."""
    var = float(cov[j, j])
    if not var > 0:
        return None
    ic = names.index("C")
    slope_c = cov[ic, j] / var * params["C"].scale * conductance / scale
    slope_b = cov[names.index("b"), j] / var * params["b"].scale / scale \
        if "b" in names else math.nan
    return float(slope_c), float(slope_b)
