"""Uncertainty of a least-squares fit: covariance, inflation for structured residuals.

Profiles and intervals refit through :func:`pneumatic_unload.fit.lsq.minimize`
(see :mod:`pneumatic_unload.fit.profile`); this module holds the closed-form pieces.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: chi^2 quantile of a 95 % interval with one parameter [-].
CHI2_95 = 3.841458820694124


def covariance(jac: FloatArray, s2: float) -> FloatArray:
    """Parameter covariance s2 (J^T J)^-1 computed on column-normalised J [param units^2].

    Normalising the columns first keeps parameters of very different scales from being cut
    off as "singular" directions, which would report a far too small variance; a genuinely
    unidentifiable direction gets an infinite one.

    Parameters
    ----------
    jac : ndarray
        Jacobian of the residuals (n x k) [residual unit / parameter unit].
    s2 : float
        Variance of one residual [residual unit^2].
    """
    jac = np.asarray(jac, dtype=float)
    npar = jac.shape[1]
    if not np.all(np.isfinite(jac)):
        return np.full((npar, npar), math.nan)
    norm = np.sqrt(np.sum(jac * jac, axis=0))
    good = norm > 0
    cov = np.full((npar, npar), math.inf)
    if not np.any(good):
        return cov
    jn = jac[:, good] / norm[good]
    _u, sv, vt = np.linalg.svd(jn, full_matrices=False)
    if sv[0] <= 0 or sv[-1] < 1e-10 * sv[0]:
        inv_sv2 = np.where(sv > 1e-10 * sv[0], 1.0 / np.maximum(sv, 1e-300) ** 2, math.inf)
    else:
        inv_sv2 = 1.0 / sv**2
    with np.errstate(invalid="ignore"):
        c = (vt.T * inv_sv2) @ vt
    c = np.where(np.isnan(c), math.inf, c)
    sub = c / np.outer(norm[good], norm[good]) * s2
    idx = np.flatnonzero(good)
    cov[np.ix_(idx, idx)] = sub
    return cov


def residual_inflation(r: FloatArray) -> float:
    """Variance inflation for serially correlated residuals [-] (>= 1).

    White residuals (the model fits and the noise is white) give a lag-1 autocorrelation
    rho near 0 within 2/sqrt(n); a model discrepancy (an unmodelled rig effect, a wrong
    heat law) or coloured noise leaves runs of same-sign residuals and rho > 0, so the
    samples carry fewer independent pieces of information: the covariance is multiplied by
    the AR(1) effective-sample-size factor (1 + rho)/(1 - rho). rho below 2/sqrt(n) is
    treated as white (no inflation).

    Parameters
    ----------
    r : ndarray
        Residuals in time order [any unit], already weighted to equal variance.
    """
    r = np.asarray(r, dtype=float)
    if r.size < 8:
        return 1.0
    r = r - float(np.mean(r))
    den = float(r @ r)
    if den <= 0:
        return 1.0
    rho = float(r[1:] @ r[:-1]) / den
    if rho <= 2.0 / math.sqrt(r.size):
        return 1.0
    rho = min(rho, 0.99)
    return (1.0 + rho) / (1.0 - rho)
