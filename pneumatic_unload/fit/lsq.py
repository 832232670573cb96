"""The one bounded least-squares minimiser of the package (the lmfit ``Minimizer`` shape).

:func:`minimize` takes a residual function of named parameter values and a
:class:`~pneumatic_unload.fit.params.Parameters`, screens several starts briefly, runs
scipy's trust-region reflective search from the best one, and polishes with Gauss-Newton
steps to the exact minimum: the trust region alone stops short in the long narrow valleys
of strongly correlated parameters (C, t0, p10, heat scale), its ftol/xtol tests firing while
chi^2 is still 0.1-0.3 above its minimum, which left estimates 0.2-0.5 sigma off at random.
Every caller (the model inversion's fallbacks, the estimator's curve fit, the SSE recovery
fit, the discrepancy candidates and their profiles) fits through here, so information
criteria and profile thresholds always see an optimum.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from pneumatic_unload.fit.params import Parameters
from pneumatic_unload.fit.uncertainty import covariance

FloatArray = NDArray[np.float64]
Residual = Callable[[dict[str, float]], FloatArray]

#: Finite-difference step in scaled coordinates [-]: large enough to stay clear of the
#: integrator's tolerance, small against a one-sigma change.
DIFF_STEP = 1e-3
#: The polish stops when the next Gauss-Newton step would lower chi^2 by less than this [-]
#: (relative to the residual variance: a deficit of 1e-3 is ~0.05 sigma of position).
POLISH_CHI2_TOL = 1e-3
#: Largest number of Gauss-Newton polish iterations [-].
POLISH_MAX_ITER = 6
#: Residual value returned for parameters where the model cannot be evaluated [-].
BAD_RESIDUAL = 1e6


@dataclass
class FitResult:
    """Result of :func:`minimize`.

    Attributes
    ----------
    params : Parameters
        The parameters fitted (bounds, scales, which were free).
    values : dict
        Values at the minimum [units].
    x : ndarray
        Scaled coordinates of the free parameters at the minimum.
    fun : ndarray
        Residuals at the minimum [-].
    jac : ndarray
        Forward-difference Jacobian d fun / d x at the minimum.
    chi2 : float
        Sum of squared residuals [-].
    success : bool
        The polish converged.
    nfev : int
        Residual evaluations, Jacobian columns included [-].
    n_data : int
        Number of data the BIC counts (default: residuals) [-].
    """

    params: Parameters
    values: dict[str, float]
    x: FloatArray
    fun: FloatArray
    jac: FloatArray
    chi2: float
    success: bool
    nfev: int
    n_data: int
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def k(self) -> int:
        """Number of free parameters [-]."""
        return int(self.x.size)

    @property
    def dof(self) -> int:
        """Residuals minus free parameters (at least 1) [-]."""
        return max(self.fun.size - self.k, 1)

    @property
    def bic(self) -> float:
        """Bayesian information criterion chi2 + k ln(n_data) [-]."""
        return self.chi2 + self.k * math.log(max(self.n_data, 2))

    @property
    def aic(self) -> float:
        """Akaike information criterion chi2 + 2 k [-]."""
        return self.chi2 + 2.0 * self.k

    def covariance(self, s2: float = 1.0) -> FloatArray:
        """Covariance of the scaled coordinates for residual variance s2 [x units^2]."""
        return covariance(self.jac, s2)

    def stderr(self, cov: FloatArray) -> dict[str, float]:
        """Standard deviations of the free parameters' values [units] from a covariance."""
        out = {}
        for i, name in enumerate(self.params.free):
            v = float(cov[i, i])
            out[name] = self.params.value_std(name, self.values[name],
                                              math.sqrt(v) if v >= 0 else math.nan)
        return out


def forward_jacobian(fun: Callable[[FloatArray], FloatArray], x: FloatArray, f0: FloatArray,
                     lo: FloatArray, hi: FloatArray, step: float = DIFF_STEP) -> FloatArray:
    """Forward-difference Jacobian of ``fun`` at ``x`` (steps toward the interior).

    Parameters
    ----------
    fun : callable
        Residuals of the scaled coordinates.
    x, f0 : ndarray
        Point and ``fun(x)``.
    lo, hi : ndarray
        Bounds (a step that would leave them is taken backwards).
    step : float
        Step in scaled coordinates [-].
    """
    cols = []
    for k in range(x.size):
        h = step
        if x[k] + h > hi[k]:
            h = -h
        xk = np.array(x, dtype=float)
        xk[k] += h
        h = float(xk[k] - x[k])
        cols.append((fun(xk) - f0) / h)
    return np.column_stack(cols) if cols else np.zeros((f0.size, 0))


def _guarded(residual: Residual, params: Parameters, n_out: list[int]
             ) -> Callable[[FloatArray], FloatArray]:
    """Residuals of scaled coordinates, with failures mapped to a large constant."""

    def fun(x: FloatArray) -> FloatArray:
        try:
            with np.errstate(all="ignore"):
                r = np.asarray(residual(params.to_values(x)), dtype=float)
        except (ValueError, ArithmeticError):
            r = np.full(n_out[0], BAD_RESIDUAL) if n_out[0] else np.array([BAD_RESIDUAL])
        if n_out[0] == 0:
            n_out[0] = r.size
        if r.size != n_out[0] or not np.all(np.isfinite(r)):
            return np.full(n_out[0], BAD_RESIDUAL)
        return np.clip(r, -1e12, 1e12)

    return fun


def polish(fun: Callable[[FloatArray], FloatArray], x: FloatArray, f: FloatArray,
           lo: FloatArray, hi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, bool, int]:
    """Gauss-Newton steps to the exact minimum inside the bounds.

    Returns
    -------
    tuple
        (x, residuals, Jacobian at x, converged, evaluations).
    """
    inner_lo = lo + 1e-12 * np.maximum(1.0, np.abs(lo))
    inner_hi = hi - 1e-12 * np.maximum(1.0, np.abs(hi))
    cost = float(f @ f)
    s2 = max(cost / max(f.size - x.size, 1), 1e-300)
    nfev = 0
    jac = np.full((f.size, x.size), math.nan)
    for _ in range(POLISH_MAX_ITER):
        jac = forward_jacobian(fun, x, f, lo, hi)
        nfev += x.size
        if not np.all(np.isfinite(jac)):
            return x, f, jac, False, nfev
        step, *_ = np.linalg.lstsq(jac, -f, rcond=1e-12)
        pred = cost - float(np.sum((f + jac @ step) ** 2))
        if pred / s2 < POLISH_CHI2_TOL:
            return x, f, jac, True, nfev
        x_new = np.clip(x + step, inner_lo, inner_hi)
        f_new = fun(x_new)
        nfev += 1
        c_new = float(f_new @ f_new)
        if not c_new < cost:
            x_half = np.clip(x + 0.5 * step, inner_lo, inner_hi)  # one halving, then stop
            f_half = fun(x_half)
            nfev += 1
            c_half = float(f_half @ f_half)
            if not c_half < cost:
                return x, f, jac, True, nfev
            x_new, f_new, c_new = x_half, f_half, c_half
        x, f, cost = x_new, f_new, c_new
    jac = forward_jacobian(fun, x, f, lo, hi)
    return x, f, jac, False, nfev + x.size


def minimize(residual: Residual, params: Parameters, *,
             starts: list[dict[str, float]] | None = None, screen_nfev: int = 12,
             max_nfev: int = 200, n_data: int | None = None) -> FitResult:
    """Bounded non-linear least squares over named parameters.

    Parameters
    ----------
    residual : callable
        ``residual(values)`` -> residuals of unit variance under the model [-], for a dict
        of all parameter values [units]. A ValueError/ArithmeticError or a non-finite
        result marks an infeasible point.
    params : Parameters
        Parameters with bounds and starting values; the non-varying ones are held.
    starts : list of dict, optional
        Further starting values (missing names take ``params``' values); each is screened
        with ``screen_nfev`` evaluations and the best is fitted in full.
    screen_nfev, max_nfev : int
        Evaluation budgets of the screening and of the full search [-].
    n_data : int, optional
        Number of data for the BIC [-] (default: the number of residuals).

    Returns
    -------
    FitResult
        The minimum with its Jacobian.
    """
    lo, hi = params.bounds()
    eps = 1e-9 * np.maximum(hi - lo, 1e-300)
    eps = np.where(np.isfinite(eps), eps, 1e-9)
    n_out = [0]
    fun = _guarded(residual, params, n_out)
    pts = [params.to_x()] + [params.to_x(s) for s in (starts or [])]
    pts = [np.clip(p, lo + eps, hi - eps) for p in pts]
    nfev = 0
    if not params.free:
        f0 = fun(np.zeros(0))
        return FitResult(params=params, values=params.to_values(np.zeros(0)), x=np.zeros(0),
                         fun=f0, jac=np.zeros((f0.size, 0)), chi2=float(f0 @ f0), success=True,
                         nfev=1, n_data=n_data or f0.size)
    if len(pts) > 1:
        scored = []
        for x0 in pts:
            sol = least_squares(fun, x0, bounds=(lo, hi), method="trf", diff_step=DIFF_STEP,
                                max_nfev=screen_nfev, x_scale=1.0)
            nfev += int(sol.nfev) * (x0.size + 1)
            scored.append((float(sol.cost), np.asarray(sol.x)))
        scored.sort(key=lambda c: c[0])
        x0 = scored[0][1]
    else:
        x0 = pts[0]
    sol = least_squares(fun, x0, bounds=(lo, hi), method="trf", diff_step=DIFF_STEP,
                        max_nfev=max_nfev,
                        x_scale=1.0)
    nfev += int(sol.nfev) + int(sol.njev or 0) * x0.size
    x, f = np.asarray(sol.x, dtype=float), np.asarray(sol.fun, dtype=float)
    x, f, jac, ok, n_pol = polish(fun, x, f, lo, hi)
    nfev += n_pol
    return FitResult(params=params, values=params.to_values(x), x=x, fun=f, jac=jac,
                     chi2=float(f @ f), success=bool(ok), nfev=nfev,
                     n_data=n_data if n_data is not None else f.size)
