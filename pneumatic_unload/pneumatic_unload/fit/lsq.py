# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The one bounded least-squares minimiser of the package (the lmfit ``Minimizer`` shape).

:func:`minimize` takes a residual function of named parameter values and a
:class:`~pneumatic_unload.fit.params.Parameters`, screens several starts briefly and runs a
bounded Levenberg-Marquardt search (numpy only) from the best one until the Gauss-Newton
step predicts no further chi^2 drop: the exact minimum, not a tolerance short of it
(scipy's trust-region search stopped 0.1-0.3 chi^2 short in the long narrow valleys of the
strongly correlated parameters C, t0, p10 and heat scale, which left estimates 0.2-0.5 sigma
off at random; it also cost 0.65 s of import). Every caller (the estimator's curve fit,
the SSE recovery fit, the discrepancy candidates and their profiles) fits through here, so
information criteria and profile thresholds always see an optimum.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.params import Parameters
from pneumatic_unload.fit.uncertainty import covariance

FloatArray = NDArray[np.float64]
Residual = Callable[[dict[str, float]], FloatArray]

#: Finite-difference step in scaled coordinates [-]: large enough to stay clear of the
#: integrator's tolerance, small against a one-sigma change.
DIFF_STEP = 1e-3
#: The fit stops when the next Gauss-Newton step would lower chi^2 by less than this [-]
#: (relative to the residual variance: a deficit of 1e-3 is ~0.05 sigma of position).
POLISH_CHI2_TOL = 1e-3
#: Below this predicted chi^2 drop [residual variances] the fit ends with one undamped
#: Gauss-Newton step (its error is second order: measured, the next iteration predicts
#: < 1e-2 of this) instead of iterating to :data:`POLISH_CHI2_TOL` [-].
FINAL_STEP_CHI2 = 0.1
#: Distance [-, scaled coordinates] within which ``hold_outward`` counts a coordinate as
#: on its bound (a start put there sits a hair inside, see :func:`minimize`).
ON_BOUND = 1e-6
#: Displacement of the restart of :func:`restart_spread` [-, scaled coordinates of order
#: one]: about 1e5 machine epsilons, standing in for the last-bit differences (another
#: BLAS kernel, another summation order) that the search's path amplifies.
RESTART_DISPLACEMENT = 1e-11
#: Evaluation budget of that restart [-]: two iterations (a well-conditioned minimum is
#: back within rounding after one; the live final fit's latency bounds the rest).
RESTART_NFEV = 4
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
        The search converged (the Gauss-Newton step predicts no further chi^2 drop).
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
    """Residuals of scaled coordinates, with failures mapped to a large constant (called
    under ``np.errstate(all="ignore")``, set once by :func:`minimize`)."""

    def fun(x: FloatArray) -> FloatArray:
        try:
            r = np.asarray(residual(params.to_values(x)), dtype=float)
        except (ValueError, ArithmeticError):
            r = np.full(n_out[0], BAD_RESIDUAL) if n_out[0] else np.array([BAD_RESIDUAL])
        if n_out[0] == 0:
            n_out[0] = r.size
        if r.size != n_out[0] or not np.all(np.isfinite(r)):
            return np.full(n_out[0], BAD_RESIDUAL)
        return np.clip(r, -1e12, 1e12)

    return fun


def levenberg_marquardt(fun: Callable[[FloatArray], FloatArray], x: FloatArray,
                        f: FloatArray, lo: FloatArray, hi: FloatArray, *, max_iter: int,
                        move: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
                        hold_outward: bool = False, jac0: FloatArray | None = None
                        ) -> tuple[FloatArray, FloatArray, FloatArray, bool, int]:
    """Bounded Levenberg-Marquardt to the exact minimum (scaled coordinates of order one).

    Each iteration takes a forward-difference Jacobian at x, solves the damped normal
    equations (J^T J + lam diag(J^T J)) d = -J^T r over the coordinates not held by a bound
    they are pushed against, projects x + d into the box and accepts it only if chi^2 falls
    (lam shrinks), else retries with more damping. It stops when the undamped Gauss-Newton
    step predicts a chi^2 drop below :data:`POLISH_CHI2_TOL` residual variances: the
    minimum, not a tolerance short of it (the Jacobian returned is the one at that x);
    or, when it predicts less than :data:`FINAL_STEP_CHI2`, after taking that step (the
    Jacobian returned is the one before it); or,
    in a flat valley of an ill-determined combination, after three accepted steps that
    each lowered chi^2 by less than that. ``move(x, d)`` takes a step d from x (default
    x + d; :meth:`~pneumatic_unload.fit.params.Parameters.step` for fading effects);
    ``hold_outward`` also holds a coordinate on a bound that the Gauss-Newton step pushes
    outward (not only the gradient). ``jac0``: the Jacobian of the first iteration, where
    the caller has it for a point within rounding of x (a restart from a minimum).

    Returns
    -------
    tuple
        (x, residuals, Jacobian at x, converged, evaluations).
    """
    inner_lo = lo + 1e-12 * np.maximum(1.0, np.abs(lo))
    inner_hi = hi - 1e-12 * np.maximum(1.0, np.abs(hi))
    x = np.clip(x, inner_lo, inner_hi)
    if move is None:
        def move(x0: FloatArray, d: FloatArray) -> FloatArray:
            return x0 + d
    cost = float(f @ f)
    nfev = 0
    lam = 1e-3
    stalls = 0
    jac = np.full((f.size, x.size), math.nan)
    for it in range(max_iter):
        if it == 0 and jac0 is not None and jac0.shape == (f.size, x.size):
            jac = jac0
        else:
            jac = forward_jacobian(fun, x, f, lo, hi)
            nfev += x.size
        if not np.all(np.isfinite(jac)):
            return x, f, jac, False, nfev
        g = jac.T @ f
        # coordinates at a bound with the gradient pushing outward stay there
        held = ((x <= inner_lo) & (g > 0)) | ((x >= inner_hi) & (g < 0))
        free = ~held
        s2 = max(cost / max(f.size - x.size, 1), 1e-300)
        jf = jac[:, free]
        gn, *_ = np.linalg.lstsq(jf, -f, rcond=1e-12)
        if hold_outward:
            # and those the Gauss-Newton step pushes outward (a faded effect on its bound:
            # its column is ~0, the gradient's sign is noise, and a step computed with it
            # free moves the others to compensate a move the bound does not allow)
            out = np.zeros_like(held)
            out[free] = ((x[free] <= lo[free] + ON_BOUND) & (gn < 0)) \
                | ((x[free] >= hi[free] - ON_BOUND) & (gn > 0))
            if np.any(out):
                held |= out
                free = ~held
                jf = jac[:, free]
                gn, *_ = np.linalg.lstsq(jf, -f, rcond=1e-12)
        pred = cost - float(np.sum((f + jf @ gn) ** 2))
        if pred / s2 < POLISH_CHI2_TOL:
            return x, f, jac, True, nfev
        if pred / s2 < FINAL_STEP_CHI2:
            # in the quadratic basin of the minimum: the undamped Gauss-Newton step lands
            # on it (what is left is of the order of pred^2); take it and stop, without a
            # Jacobian more (the one returned is this one, a fraction of a sigma away)
            step = np.zeros_like(x)
            step[free] = gn
            x_new = np.clip(move(x, step), inner_lo, inner_hi)
            f_new = fun(x_new)
            nfev += 1
            # kept unless chi^2 rises by more than its tolerance: a strict comparison of
            # two chi^2 values this close decides on their last bits
            if float(f_new @ f_new) <= cost + POLISH_CHI2_TOL * s2:
                return x_new, f_new, jac, True, nfev
        h = jf.T @ jf
        dg = np.maximum(np.diag(h), 1e-12 * max(float(np.max(np.diag(h))), 1e-300))
        accepted = False
        for _ in range(12):
            try:
                d = np.linalg.solve(h + lam * np.diag(dg), -g[free])
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            step = np.zeros_like(x)
            step[free] = d
            x_new = np.clip(move(x, step), inner_lo, inner_hi)
            f_new = fun(x_new)
            nfev += 1
            c_new = float(f_new @ f_new)
            if c_new < cost:
                # a flat valley (an ill-determined combination): chi^2 within the
                # tolerance of its minimum along it is the minimum for every purpose
                stalls = stalls + 1 if (cost - c_new) / s2 < POLISH_CHI2_TOL else 0
                x, f, cost = x_new, f_new, c_new
                lam = max(lam / 3.0, 1e-9)
                accepted = True
                break
            lam *= 4.0
        if not accepted:  # no damping lowers chi^2: x is the minimum to machine precision
            return x, f, jac, True, nfev
        if stalls >= 3:
            jac = forward_jacobian(fun, x, f, lo, hi)
            return x, f, jac, True, nfev + x.size
    jac = forward_jacobian(fun, x, f, lo, hi)
    return x, f, jac, False, nfev + x.size


def minimize(residual: Residual, params: Parameters, *,
             starts: list[dict[str, float]] | None = None, screen_nfev: int = 12,
             max_nfev: int = 200, n_data: int | None = None, fade: bool = False
             ) -> FitResult:
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
        Budgets of the screening (iterations per start) and of the full search (half as
        many iterations) [-]; an iteration costs one evaluation per free parameter plus one.
    n_data : int, optional
        Number of data for the BIC [-] (default: the number of residuals).
    fade : bool
        Step the parameters with a ``fade`` power along it
        (:meth:`~pneumatic_unload.fit.params.Parameters.step`) instead of along their log,
        and hold a coordinate on its bound when the Gauss-Newton step pushes it outward.

    Returns
    -------
    FitResult
        The minimum with its Jacobian.
    """
    with np.errstate(all="ignore"):  # once per fit: per evaluation it cost ~0.1 ms
        lo, hi = params.bounds()
        eps = 1e-9 * np.maximum(hi - lo, 1e-300)
        eps = np.where(np.isfinite(eps), eps, 1e-9)
        n_out = [0]
        fun = _guarded(residual, params, n_out)
        fading = fade and any(p.fade and p.vary for p in params)
        move = params.step if fading else None
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
                f0 = fun(x0)
                xs, fs, _j, _ok, n = levenberg_marquardt(fun, x0, f0, lo, hi,
                                                         max_iter=max(1, screen_nfev),
                                                         move=move, hold_outward=fading)
                nfev += n + 1
                scored.append((float(fs @ fs), xs, fs))
            scored.sort(key=lambda c: c[0])
            _, x0, f0 = scored[0]
        else:
            x0 = pts[0]
            f0 = fun(x0)
            nfev += 1
        x, f, jac, ok, n_lm = levenberg_marquardt(fun, x0, f0, lo, hi,
                                                  max_iter=max(2, max_nfev // 2), move=move,
                                                  hold_outward=fading)
        nfev += n_lm
        return FitResult(params=params, values=params.to_values(x), x=x, fun=f, jac=jac,
                         chi2=float(f @ f), success=bool(ok), nfev=nfev,
                         n_data=n_data if n_data is not None else f.size)


def restart_spread(residual: Residual, result: FitResult, *, fade: bool = False,
                   displacement: float = RESTART_DISPLACEMENT,
                   max_nfev: int = RESTART_NFEV) -> dict[str, float]:
    """Numerical reproducibility of a minimum, measured: the search restarted from it
    displaced by ``displacement`` (alternating signs over the scaled coordinates).

    Where the residuals are smooth in the parameters and the minimum well conditioned,
    the restart lands within rounding of the first minimum; in a flat valley (a faded
    effect, an ill-determined combination) the search stops wherever chi^2 stops falling
    measurably, and the restart shows how far that is. Last-bit differences of the inputs
    or of the arithmetic (another machine) move the minimum by about as much.

    Parameters
    ----------
    residual : callable
        The residual function the result was fitted with.
    result : FitResult
        The minimum.
    fade : bool
        As given to :func:`minimize`.
    displacement : float
        Start displacement [-, scaled coordinates].
    max_nfev : int
        Evaluation budget of the restart (half as many iterations) [-]: a restart that
        has not converged within it has moved at least as far as it reports (the live
        final fit's latency bounds it).

    Returns
    -------
    dict
        Relative change of each free parameter's value [-] (NaN where the restart's
        residuals or Jacobian were not finite).
    """
    params = result.params
    if not params.free:
        return {}
    with np.errstate(all="ignore"):
        lo, hi = params.bounds()
        fun = _guarded(residual, params, [int(result.fun.size)])
        fading = fade and any(p.fade and p.vary for p in params)
        signs = np.where(np.arange(result.x.size) % 2 == 0, 1.0, -1.0)
        x0 = np.clip(result.x + displacement * signs, lo, hi)
        # the first iteration takes the minimum's Jacobian: the start is 1e-11 away in
        # scaled coordinates, a thousandth of the forward difference's own step
        x, f, jac, _ok, _n = levenberg_marquardt(
            fun, x0, fun(x0), lo, hi, max_iter=max(2, max_nfev // 2),
            move=params.step if fading else None, hold_outward=fading, jac0=result.jac)
    failed = not (np.all(np.isfinite(f)) and np.all(np.isfinite(jac)))
    values = params.to_values(x)
    return {name: math.nan if failed else (abs(values[name] - result.values[name])
                                           / max(abs(result.values[name]), 1e-300))
            for name in params.free}


def numerical_reproducibility(residual: Residual, result: FitResult, *, fade: bool = False
                              ) -> dict[str, float]:
    """The numerical reproducibility of each free parameter of a fit [-, relative]: the
    larger of its :func:`restart_spread` and sqrt(n eps) of its relative standard deviation
    (n residuals: chi^2 is known to about n eps residual variances, so a minimum that the
    search locates by comparing chi^2 values is known to about sqrt(n eps) of a standard
    deviation along an ill-determined direction; measured with 1e-14 perturbations of the
    samples and under other OpenBLAS kernels: bench/bench_reproducibility.py). The
    parameters are those of :func:`restart_spread`.
    """
    spread = restart_spread(residual, result, fade=fade)
    s2 = result.chi2 / result.dof
    std = result.stderr(result.covariance(s2)) if result.x.size else {}
    floor = math.sqrt(result.fun.size * float(np.finfo(float).eps))
    out = {}
    for name, moved in spread.items():
        value, sd = result.values[name], std.get(name, math.nan)
        rel = abs(sd / value) if value != 0.0 and math.isfinite(sd) else 0.0
        out[name] = max(moved, floor * rel)
    return out
