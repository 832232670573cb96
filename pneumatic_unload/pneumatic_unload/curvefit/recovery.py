# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""SSE recovery: the isochoric re-heating after an aborted unload (the paper's eq 23).

When the valve closes early (t*), the gas re-heats at constant mass on the wall and the
pressure recovers to p1_inf, which eq 23 needs. The recovery is fitted through the one
engine (:func:`pneumatic_unload.fit.lsq.minimize`), and an unfinished recovery is
extrapolated with an honest uncertainty. SI units: s, Pa (or any linear signal unit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.likelihood import uniform_bins
from pneumatic_unload.fit.lsq import minimize
from pneumatic_unload.fit.params import Parameter, Parameters
from pneumatic_unload.fit.uncertainty import covariance, residual_inflation

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RecoveryFit:
    """Pressure recovery after the valve closed (aborted unload), see :func:`fit_recovery`.

    Attributes
    ----------
    p_inf, p_inf_std : float
        Asymptotic (re-equilibrated) pressure and its 1-sigma [Pa, or signal units].
    p_close : float
        Pressure at the closing instant, p_inf - D0 [same unit].
    rise : float
        Total rise D0 = p_inf - p_close [same unit].
    tau : float
        Initial relaxation time D0 / (dp/dt at closing) [s].
    exponent : float
        Relaxation exponent n of dD/dt = -(D0/tau) (D/D0)^n [-] (1: constant h A,
        1.25: laminar natural convection).
    remaining : float
        Fitted rise still to come at the last sample, D(t_end) [same unit].
    rms : float
        Residual rms of the samples [same unit].
    n : int
        Samples fitted [-].
    success : bool
        Optimiser convergence.
    """

    p_inf: float
    p_inf_std: float
    p_close: float
    rise: float
    tau: float
    exponent: float
    remaining: float
    rms: float
    n: int
    success: bool


def _relaxation(u: FloatArray, d0: float, tau: float, n: float) -> FloatArray:
    """D(u) solving dD/du = -(D0/tau) (D/D0)^n, D(0) = D0 [unit of d0]."""
    x = u / tau
    if abs(n - 1.0) < 1e-9:
        return d0 * np.exp(-x)
    # n < 1 reaches D = 0 in finite time: clip there
    return d0 * np.exp(-np.log1p(np.maximum((n - 1.0) * x, -1.0 + 1e-12)) / (n - 1.0))


#: Relaxation exponent of the recovery: prior mean and 1-sigma [-]. 1.25 is laminar
#: natural convection (h ~ dT^0.25); the 1-sigma of 0.12 admits a constant h A (n = 1)
#: and turbulent convection (n = 4/3) at about 2 sigma. The data override it when the
#: recovery is recorded long enough to show its shape.
RECOVERY_EXPONENT_PRIOR = (1.25, 0.12)
#: Bounds of the fitted relaxation exponent [-].
RECOVERY_EXPONENTS = (0.9, 1.7)


def fit_recovery(t: FloatArray, p: FloatArray, t_close: float, *, max_points: int = 2000
                 ) -> RecoveryFit:
    """Fit the isochoric re-heating after an aborted unload: p = p_inf - D(t - t_close).

    At constant gas mass the pressure is proportional to the mean gas temperature, and the
    wall heat flow h A (T_w - T) makes the deficit D = p_inf - p relax as
    dD/dt = -(D0/tau) (D/D0)^n: n = 1 for a constant h A, n = 1.25 for laminar natural
    convection (h proportional to dT^0.25), n = 4/3 turbulent. p_inf and D0 enter linearly:
    a grid over tau with the linear pair solved exactly finds the basin, the engine's
    least squares (:func:`pneumatic_unload.fit.lsq.minimize`, to the exact minimum) refines all
    four, and the 1-sigma of p_inf comes from the Jacobian with n free (under its prior),
    so that an unfinished recovery is extrapolated with an honest uncertainty.

    Parameters
    ----------
    t, p : ndarray
        Samples from the closing instant on [s], [Pa] (or any linear signal unit).
    t_close : float
        Closing instant [s].
    max_points : int
        Samples are averaged in bins down to this many points.

    Returns
    -------
    RecoveryFit
        p_inf with its 1-sigma from the Jacobian scaled by the residual.
    """
    u = np.asarray(t, dtype=float) - t_close
    p = np.asarray(p, dtype=float)
    if u.size < 8:
        raise ValueError(f"too few recovery samples ({u.size}) to fit")
    edges = uniform_bins(u.size, max_points)
    counts = np.diff(edges)
    ub = np.add.reduceat(u, edges[:-1]) / counts
    pb = np.add.reduceat(p, edges[:-1]) / counts
    w = np.sqrt(counts)
    span = max(float(u[-1]), 1e-9)
    best = (math.inf, 0.0, 0.0, span, 1.0)
    n_prior, n_sd = RECOVERY_EXPONENT_PRIOR
    for tau in span * np.logspace(-1.5, 2.5, 41):
        g = _relaxation(ub, 1.0, float(tau), n_prior)
        a = np.column_stack((w, -g * w))
        coef, *_ = np.linalg.lstsq(a, pb * w, rcond=None)
        r = pb * w - a @ coef
        sse = float(r @ r)
        if sse < best[0] and coef[1] >= 0.0:
            best = (sse, float(coef[0]), float(coef[1]), float(tau), n_prior)
    sse0, p_inf0, d00, tau0_, n0 = best
    if not math.isfinite(sse0):  # no rise at all: start from a flat line
        p_inf0, d00 = float(np.mean(pb)), 0.0
        sse0 = float(np.sum(counts * (pb - p_inf0) ** 2))
    s2_0 = max(sse0 / max(pb.size - 3, 1), 1e-300)
    sig0 = math.sqrt(s2_0)
    prior_w = 1.0 / n_sd
    scale = max(abs(d00), float(np.std(np.diff(p))), 1e-12)
    big = 1e4 * scale + float(np.max(np.abs(pb)))
    lo_tau, hi_tau = 1e-3 * span, 1e5 * span
    params = Parameters([
        Parameter("p_inf", p_inf0, float(np.min(pb)) - big, float(np.max(pb)) + big,
                  "Pa", scale=scale, doc="asymptotic pressure"),
        Parameter("d0", max(d00, 1e-9 * scale), 0.0, 2.0 * big, "Pa", scale=scale,
                  doc="total rise"),
        Parameter("tau", float(np.clip(tau0_, lo_tau * 1.001, hi_tau * 0.999)), lo_tau,
                  hi_tau, "s", log=True, scale=0.1, doc="initial relaxation time"),
        Parameter("n", float(np.clip(n0, *RECOVERY_EXPONENTS)), *RECOVERY_EXPONENTS, "-",
                  scale=0.05, doc="relaxation exponent"),
    ])

    def residual(v: dict[str, float]) -> FloatArray:
        r = (v["p_inf"] - _relaxation(ub, v["d0"], v["tau"], v["n"]) - pb) * w / sig0
        return np.append(r, prior_w * (v["n"] - n_prior))

    fit = minimize(residual, params, max_nfev=400)
    v = fit.values
    rb = fit.fun[:-1] * sig0
    dof = max(pb.size - 3, 1)
    s2 = float(rb @ rb) / dof  # per-sample variance (bins by size)
    # the prior row is in units of its own sigma: scale the data rows to unit variance
    jac = fit.jac.copy()
    jac[:-1] *= sig0 / math.sqrt(s2) if s2 > 0 else 1.0
    cov = covariance(jac, residual_inflation(rb))
    p_inf_std = fit.params.value_std("p_inf", v["p_inf"], math.sqrt(max(float(cov[0, 0]), 0.0)))
    p_inf, d0, tau, n = v["p_inf"], v["d0"], v["tau"], v["n"]
    remaining = float(_relaxation(np.array([span]), d0, tau, n)[0])
    return RecoveryFit(p_inf=p_inf, p_inf_std=p_inf_std, p_close=p_inf - d0, rise=d0,
                       tau=tau, exponent=n, remaining=remaining, rms=math.sqrt(s2),
                       n=int(u.size), success=bool(fit.success))
