# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Several runs, one shared law: the chamber-geometry factor on C (the paper's fig. 6).

On a single trace a constant factor f on the sonic conductance is exactly collinear with
C (see :func:`~pneumatic_unload.discrepancy.workflow.geometry_factor_check`). With runs
on tanks of different L/D it becomes identifiable as a law shared by all runs. The paper
finds that C grows with L/D toward an asymptote (the steady-flow value); the law used
here is the simplest such curve with two parameters,

    C(L/D) = C_inf (1 - a / (L/D)),      f(L/D) = C(L/D) / C_inf,

linear in (C_inf, C_inf a) and therefore fitted exactly by weighted least squares on the
per-run conductances (each run fitted with its own p10, t_open, b and effects). SI units:
C in m^3/(s Pa), L/D dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from pneumatic_unload.discrepancy.types import DiscrepancyError


@dataclass(frozen=True)
class GeometryLaw:
    """C(L/D) = C_inf (1 - a/(L/D)) shared by several runs.

    Attributes
    ----------
    identifiable : bool
        False with fewer than two distinct L/D values.
    c_inf, c_inf_std : float
        Asymptotic sonic conductance and its 1-sigma [m^3/(s Pa)].
    a, a_std : float
        Geometry coefficient and its 1-sigma [-].
    chi2 : float
        Weighted residual sum of squares of the per-run C about the law [-].
    dof : int
        Runs minus 2 [-].
    p_value : float
        Goodness of fit (NaN when dof = 0) [-].
    runs : list of dict
        Per run: L/D, C and its std, factor f = C / C_inf.
    reason : str
        Why not identifiable, or a one-line summary.
    """

    identifiable: bool
    c_inf: float
    c_inf_std: float
    a: float
    a_std: float
    chi2: float
    dof: int
    p_value: float
    runs: list[dict[str, float]]
    reason: str

    def predict(self, ld: float) -> float:
        """C at a given L/D [m^3/(s Pa)]."""
        return self.c_inf * (1.0 - self.a / ld)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (non-finite as None)."""
        def f(v: float) -> float | None:
            return v if math.isfinite(v) else None
        return {"law": "C(L/D) = C_inf (1 - a/(L/D))", "identifiable": self.identifiable,
                "c_inf": f(self.c_inf), "c_inf_std": f(self.c_inf_std), "a": f(self.a),
                "a_std": f(self.a_std), "chi2": f(self.chi2), "dof": self.dof,
                "p_value": f(self.p_value), "runs": self.runs, "reason": self.reason}


def fit_geometry_law(length_diameter: list[float], conductance: list[float],
                     conductance_std: list[float]) -> GeometryLaw:
    """Fit the shared geometry law to per-run conductances.

    Parameters
    ----------
    length_diameter : list of float
        Tank L/D of each run [-].
    conductance : list of float
        C fitted on each run [m^3/(s Pa)].
    conductance_std : list of float
        1-sigma of each C [m^3/(s Pa)].

    Returns
    -------
    GeometryLaw
        Not identifiable (with the reason) when fewer than two distinct L/D are given.
    """
    x = np.asarray(length_diameter, dtype=float)
    c = np.asarray(conductance, dtype=float)
    s = np.asarray(conductance_std, dtype=float)
    if not (x.size == c.size == s.size) or x.size == 0:
        raise DiscrepancyError("one L/D, one C and one std per run are needed")
    if np.any(x <= 0) or not np.all(np.isfinite(c)):
        raise DiscrepancyError("L/D must be positive and every C finite")
    s = np.where(np.isfinite(s) & (s > 0), s, np.maximum(1e-3 * np.abs(c), 1e-30))
    if np.unique(np.round(x, 9)).size < 2:
        runs = [{"length_diameter_ratio": float(a), "conductance": float(b),
                 "conductance_std": float(d), "factor": math.nan}
                for a, b, d in zip(x, c, s, strict=True)]
        return GeometryLaw(False, math.nan, math.nan, math.nan, math.nan, math.nan, 0,
                           math.nan, runs,
                           "not identifiable: a geometric factor on C needs runs on at least "
                           "two different tank geometries (L/D); on one geometry it is "
                           "collinear with C")
    a_mat = np.column_stack((np.ones_like(x), 1.0 / x)) / s[:, None]
    rhs = c / s
    coef, *_ = np.linalg.lstsq(a_mat, rhs, rcond=None)
    cov = np.linalg.inv(a_mat.T @ a_mat)
    r = rhs - a_mat @ coef
    chi2 = float(r @ r)
    dof = int(x.size - 2)
    if dof > 0:
        cov = cov * max(1.0, chi2 / dof)
    c_inf, b = float(coef[0]), float(coef[1])
    a = -b / c_inf
    # delta method for a = -b / c_inf
    g = np.array([b / c_inf**2, -1.0 / c_inf])
    a_std = math.sqrt(max(float(g @ cov @ g), 0.0))
    c_std = math.sqrt(max(float(cov[0, 0]), 0.0))
    p = float(chi2_dist.sf(chi2, dof)) if dof > 0 else math.nan
    runs = [{"length_diameter_ratio": float(xi), "conductance": float(ci),
             "conductance_std": float(si), "factor": float(ci / c_inf)}
            for xi, ci, si in zip(x, c, s, strict=True)]
    return GeometryLaw(True, c_inf, c_std, a, a_std, chi2, dof, p, runs,
                       f"C_inf = {c_inf:.4g} +- {c_std:.2g} m^3/(s Pa), a = {a:.4g} +- "
                       f"{a_std:.2g} from {x.size} runs")
