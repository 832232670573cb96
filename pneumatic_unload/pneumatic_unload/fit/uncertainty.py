# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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


def misfit_ratio(r: FloatArray) -> float:
    """Residual RMS over the white noise's [-], the noise estimated from successive
    differences (von Neumann: a misfit smooth on the scale of a sample hardly changes
    them): about 1 for white residuals and for a model that misses by less than the
    noise, whatever the structure's correlation; above 1.5 the model misses the record by
    more than its noise (a wrong basin of the fit, not a model-form nuance). NaN for
    fewer than 8 residuals.

    Parameters
    ----------
    r : ndarray
        Residuals in time order [any unit], already weighted to equal variance.
    """
    r = np.asarray(r, dtype=float)
    if r.size < 8:
        return math.nan
    d = np.diff(r)
    white = float(d @ d) / (2.0 * d.size)
    return math.sqrt(float(r @ r) / r.size / white) if white > 0.0 else math.inf


#: Ljung-Box p-value below which residuals count as structured (not white) [-]: white
#: residuals fall below it once in a thousand records.
WHITENESS_P = 1e-3
#: Residual RMS over the noise's above which the model misses more than the noise [-]
#: (white residuals of a few hundred bins stay within a few per cent of 1).
ADEQUATE_NRMS = 1.1


def structure_inflation(r: FloatArray, lags: int = 20) -> float:
    """Variance inflation for residuals with structure at any lag [-] (>= 1): the
    effective-sample-size factor 1 + 2 sum_k rho_k over the first ``lags`` autocorrelations
    (Bartlett). Noisy for white residuals (sum of ``lags`` estimates): apply it only where
    a whiteness test rejected them (:data:`WHITENESS_P`).

    Parameters
    ----------
    r : ndarray
        Residuals in time order [any unit], already weighted to equal variance.
    lags : int
        Autocorrelation lags summed [-].
    """
    r = np.asarray(r, dtype=float)
    r = r - float(np.mean(r)) if r.size else r
    den = float(r @ r)
    h = int(min(lags, max(r.size // 5, 1)))
    if r.size < 8 or den <= 0:
        return 1.0
    rho = np.array([float(r[k:] @ r[:-k]) / den for k in range(1, h + 1)])
    return float(min(max(1.0 + 2.0 * float(np.sum(rho)), 1.0), 1e4))


def residual_scale(nrms: float) -> float:
    """The residual variance's scale over the noise's, at least 1 [-] (1 where the noise is
    unknown: ``nrms`` NaN), as :func:`inadequacy` states it."""
    return max(nrms, 1.0) ** 2 if math.isfinite(nrms) else 1.0


def inadequacy(nrms: float, whiteness_p: float, inflation: float) -> str | None:
    """Why a fitted model does not describe a record at its noise level, or None.

    Parameters
    ----------
    nrms : float
        Residual RMS over the noise standard deviation [-] (NaN: noise unknown).
    whiteness_p : float
        Ljung-Box p-value of the residuals in time order [-].
    inflation : float
        Variance inflation applied to the fit's covariance for the structure [-].
    """
    why = []
    if math.isfinite(whiteness_p) and whiteness_p < WHITENESS_P:
        why.append(f"residual not white (Ljung-Box p = {whiteness_p:.2g})")
    if math.isfinite(nrms) and nrms > ADEQUATE_NRMS:
        why.append(f"residual RMS {nrms:.2f} x the noise")
    if not why:
        return None
    return (", ".join(why) + f"; sigma(C) from the record inflated (variance x {inflation:.2f}"
            f", residual scale x {residual_scale(nrms):.2f})")
