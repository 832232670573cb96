# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Noise model of a recorded discharge and the likelihood the discrepancy workflow uses.

The sensor noise is modelled as a stationary AR(1) process e_k = rho e_(k-1) + u_k with
marginal standard deviation sigma [Pa] and innovations u of standard deviation
sigma sqrt(1 - rho^2). rho is estimated on the parts of the trace where the tank pressure
does not change (the pre-step plateau and the end plateau) after removing a low-order
trend, so that it does not depend on any model fit. The trend takes the slow part of
correlated noise with it; rho and sigma^2 are therefore matched to the *expected*
moments of detrended AR(1) noise (:func:`pneumatic_unload.fit.ar1.plateau_ar1`), not
to the plain lag-one ratio and the plain mean square, which at rho 0.9 on the harness's
plateaus (a line through 150 pre-step samples, a quartic through the end plateau) read
rho 0.004 and sigma 1.3 % low.

sigma combines that plateau estimate with a *high-pass* estimate over the whole trace:
the residual of a local cubic in consecutive windows of 32 samples (the discharge is
smooth on that scale; the windows at the valve opening and outlying windows are left
out), whose expected sum of squares under AR(1) noise is known exactly given rho. On a
short trace the plateaus hold only about 40 % of the samples, so the plateau sigma
differs from the noise realised on the whole trace by about 1 % (1 sigma, 1500-5000
samples; up to 4 % seen), and a perfect model's normalised RMS then reads above 1.02 in
about 6 % of the harness traces; the high-pass estimate sees almost every noise sample of
the trace and tracks the noise actually realised (scatter of a perfect model's
normalised RMS about 0.3 %). With strongly correlated noise the high-pass window
sees only the fast part of the noise spectrum and leans on rho (d ln sigma^2/d rho about
-10 at rho = 0.9): the two estimates are then weighted by their variances, including
that of rho and the overlap of their samples, and the plateau estimate takes over.

Correlated noise makes a naive (white) likelihood claim effects that are not there: with
rho = 0.9 the information of a trace is about (1 - rho)/(1 + rho) = 1/19 of what the sample
count suggests. :class:`BinnedLikelihood` therefore *prewhitens* the residual
(r_k - rho r_(k-1)), which is white under the AR(1) model, and then sums it in bins
(narrow near the valve opening, wide on slow parts) to keep fits fast. The sum of white
innovations over a bin is again white, so the normalised bin sums are independent unit
normal variables when the model is right and their sum of squares is a chi-square.
For the same reason the normalised RMS that says "within noise" is taken on the
prewhitened residual (:func:`normalised_rms`): the plain rms/sigma of a perfect model
scatters by 2-3 % at rho 0.9 (the variance of a correlated series converges slowly), so
a fixed limit of 1.02 called the true model structured in a third of the harness's
rho 0.9 traces.

SI units: s, Pa.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.ar1 import plateau_ar1

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Minimum number of plateau samples for a plateau-based noise estimate [-].
MIN_PLATEAU_SAMPLES = 40
#: Window of the high-pass (local polynomial) noise estimate [samples].
HIGHPASS_WINDOW = 32
#: Degree of the local polynomial of the high-pass estimate [-].
HIGHPASS_DEGREE = 3
#: Fewest windows the high-pass estimate needs [-].
HIGHPASS_MIN_WINDOWS = 8
#: Tail probability above which a window's sum of squares is an outlier (a kink, a
#: spike) and is left out of the high-pass estimate [-].
HIGHPASS_OUTLIER_P = 1e-4


@dataclass(frozen=True)
class NoiseModel:
    """AR(1) sensor noise.

    Attributes
    ----------
    sigma : float
        Marginal standard deviation of the noise [Pa].
    rho : float
        Lag-one autocorrelation (AR(1) coefficient) [-].
    n : int
        Samples the estimate is based on [-].
    source : str
        Where rho comes from: 'plateaus' (pre-step and end plateau), 'pre-step',
        'end plateau' or 'differences' (second differences of the whole trace: no plateau
        long enough; rho cannot be estimated then and is set to 0).
    sigma_plateau : float
        sigma from the plateaus alone [Pa] (nan when not estimated).
    sigma_highpass : float
        sigma from the local-polynomial residual of the whole trace [Pa] (nan when not
        estimated).
    highpass_weight : float
        Weight of the high-pass estimate in sigma^2 [-] (0: plateaus alone).
    """

    sigma: float
    rho: float
    n: int
    source: str
    sigma_plateau: float = math.nan
    sigma_highpass: float = math.nan
    highpass_weight: float = 0.0

    @property
    def innovation_sigma(self) -> float:
        """Standard deviation of the AR(1) innovations sigma sqrt(1 - rho^2) [Pa]."""
        return self.sigma * math.sqrt(max(1.0 - self.rho * self.rho, 1e-6))

    @property
    def effective_fraction(self) -> float:
        """Effective sample size per sample (1 - rho)/(1 + rho) for a mean [-]."""
        return (1.0 - self.rho) / (1.0 + self.rho)

    def to_dict(self) -> dict[str, float | int | str]:
        """JSON-ready dict (sigma in Pa)."""
        return {"sigma": self.sigma, "rho": self.rho, "n": self.n, "source": self.source,
                "effective_fraction": self.effective_fraction,
                "sigma_plateau": self.sigma_plateau, "sigma_highpass": self.sigma_highpass,
                "highpass_weight": self.highpass_weight}


#: Degree of the polynomial removed from the end plateau [-]: a quartic, so that the slow
#: tail of a discharge that is still settling (the gas warming back on the wall) is not
#: taken for correlated noise (a quadratic left it in: rho 0.17 and sigma +10 % on white
#: noise, 10 s record with heat transfer); on flat plateaus and on AR(1) noise (rho 0.5,
#: 0.9) the estimates move by less than 0.002 in rho.
END_DEGREE = 4


def _detrended(y: FloatArray, degree: int) -> FloatArray:
    """Residual of a least-squares polynomial of the given degree over the index [unit of y]."""
    x = np.linspace(-1.0, 1.0, y.size)
    coef = np.polynomial.polynomial.polyfit(x, y, degree)
    return y - np.polynomial.polynomial.polyval(x, coef)


@dataclass(frozen=True)
class HighPassEstimate:
    """sigma^2 from local-polynomial residuals, with what its weighting needs.

    Attributes
    ----------
    variance : float
        Estimate of sigma^2 [Pa^2].
    windows : int
        Windows used [-].
    samples : int
        Samples in the windows used [-].
    rel_var : float
        Sampling variance of variance/sigma^2 for a known rho [-].
    dlog_drho : float
        d ln(E[window sum of squares])/d rho: sensitivity to an error in rho [-].
    rel_cov_per_sample : float
        Covariance of variance/sigma^2 with the mean square of the noise over any subset
        of the samples used (e.g. a plateau), times ``samples`` [-].
    """

    variance: float
    windows: int
    samples: int
    rel_var: float
    dlog_drho: float
    rel_cov_per_sample: float


def _ar1_corr(rho: float, w: int) -> FloatArray:
    """AR(1) correlation matrix rho^|i - j| of w consecutive samples [-]."""
    i = np.arange(w)
    return np.power(rho, np.abs(i[:, None] - i[None, :])) if rho > 0 else np.eye(w)


def highpass_noise(y: FloatArray, rho: float, k_open: int, *,
                   window: int = HIGHPASS_WINDOW, degree: int = HIGHPASS_DEGREE
                   ) -> HighPassEstimate | None:
    """sigma^2 from the residual of a local polynomial in consecutive windows.

    Under AR(1) noise of marginal variance sigma^2 the residual e' M e of a window (M the
    projection off the polynomials) has mean sigma^2 tr(M R) (R the AR(1) correlation
    matrix), and the smooth discharge leaves almost nothing in it. The windows touching
    the valve opening (a kink) are left out, and so are windows whose sum of squares is
    an outlier of its (scaled chi-square) distribution.

    Parameters
    ----------
    y : ndarray
        Measured pressure [Pa].
    rho : float
        AR(1) coefficient of the noise [-].
    k_open : int
        Sample index of the valve opening [-].
    window, degree : int
        Window length [samples] and polynomial degree [-].

    Returns
    -------
    HighPassEstimate or None
        None when fewer than :data:`HIGHPASS_MIN_WINDOWS` windows remain.
    """
    nw = y.size // window
    if nw < HIGHPASS_MIN_WINDOWS:
        return None
    x = np.linspace(-1.0, 1.0, window)
    q, _ = np.linalg.qr(np.vander(x, degree + 1))
    m = np.eye(window) - q @ q.T

    def trace_mr(r: float) -> float:
        return float(np.trace(m @ _ar1_corr(r, window)))

    corr = _ar1_corr(rho, window)
    mr = m @ corr
    tr = float(np.trace(mr))
    tr2 = float(np.trace(mr @ mr))
    dof = tr * tr / tr2  # effective degrees of freedom of a window's sum of squares
    seg = np.asarray(y[: nw * window], dtype=float).reshape(nw, window)
    rss = np.einsum("ij,jk,ik->i", seg, m, seg)
    first = np.arange(nw) * window
    keep = (first > k_open + window) | (first + window < k_open - window)
    from scipy.special import gammainccinv  # local: ~0.3 s to import, the estimator needs none

    limit = float(2.0 * gammainccinv(0.5 * dof, HIGHPASS_OUTLIER_P)) / dof
    for _ in range(10):
        if np.count_nonzero(keep) < HIGHPASS_MIN_WINDOWS:
            return None
        s2 = float(np.sum(rss[keep])) / (np.count_nonzero(keep) * tr)
        new = keep & (rss <= limit * s2 * tr)
        if np.count_nonzero(new) == np.count_nonzero(keep):
            break
        keep = new
    k = int(np.count_nonzero(keep))
    if k < HIGHPASS_MIN_WINDOWS or not s2 > 0:
        return None
    h = 1e-4
    r_lo, r_hi = max(rho - h, 0.0), min(rho + h, 0.999)
    dlog = (math.log(trace_mr(r_hi)) - math.log(trace_mr(r_lo))) / (r_hi - r_lo)
    return HighPassEstimate(
        variance=s2, windows=k, samples=k * window, rel_var=2.0 * tr2 / (k * tr * tr),
        dlog_drho=dlog, rel_cov_per_sample=2.0 * float(np.trace(mr @ corr)) / tr)


def combine_sigma2(s2_plateau: float, n_plateau: int, rho: float, hp: HighPassEstimate
                   ) -> tuple[float, float]:
    """Minimum-variance combination of the plateau and high-pass sigma^2 [Pa^2].

    Variances relative to sigma^4: plateau 2 (1 + rho^2)/((1 - rho^2) n_p); high-pass
    its sampling variance plus (d ln/d rho)^2 var(rho), var(rho) = (1 - rho^2)/n_p; the
    two share the plateau samples (covariance from the window residual's overlap with
    the plain sum of squares).

    Parameters
    ----------
    s2_plateau : float
        sigma^2 from the plateaus [Pa^2].
    n_plateau : int
        Plateau samples [-].
    rho : float
        AR(1) coefficient (from the plateaus) [-].
    hp : HighPassEstimate
        The whole-trace estimate.

    Returns
    -------
    tuple
        (combined sigma^2 [Pa^2], weight of the high-pass estimate [-]).
    """
    one = max(1.0 - rho * rho, 1e-6)
    v_p = 2.0 * (1.0 + rho * rho) / (one * n_plateau)
    v_h = hp.rel_var + hp.dlog_drho**2 * one / n_plateau
    cov = hp.rel_cov_per_sample / hp.samples
    den = v_h + v_p - 2.0 * cov
    w_p = float(np.clip((v_h - cov) / den, 0.0, 1.0)) if den > 0 else 1.0
    return w_p * s2_plateau + (1.0 - w_p) * hp.variance, 1.0 - w_p


def estimate_noise(t: FloatArray, y: FloatArray, t_open: float, tau: float) -> NoiseModel:
    """Estimate sigma and rho from the plateaus and sigma also from the whole trace.

    rho comes from the pre-step plateau and the end plateau; sigma is the variance-weighted
    combination of the plateau estimate and :func:`highpass_noise` (see the module).

    Parameters
    ----------
    t : ndarray
        Sample instants [s].
    y : ndarray
        Measured pressure [Pa].
    t_open : float
        Estimated valve opening instant [s].
    tau : float
        Unloading time scale tau_exp [s] (sets where the end plateau begins).

    Returns
    -------
    NoiseModel
        The pooled AR(1) estimate; 'differences' when neither plateau is long enough.
    """
    segments: list[tuple[str, FloatArray, int]] = []
    # pre-step: drop the quarter next to the (estimated) opening: a slow valve ramp or a
    # late detection would otherwise leak the start of the discharge into the estimate
    pre_end = t_open - 0.25 * (t_open - t[0])
    pre = y[t < pre_end]
    if pre.size >= 16:
        segments.append(("pre-step", _detrended(pre, 1), 1))
    span = t[-1] - t_open
    if span > 3.0 * tau:
        start = t_open + max(0.6 * span, 3.0 * tau)
        end = y[t >= start]
        if end.size >= 16:
            segments.append(("end plateau", _detrended(end, END_DEGREE), END_DEGREE))
    n = sum(e.size for _, e, _ in segments)
    if n >= MIN_PLATEAU_SAMPLES:
        rho, s2_p = plateau_ar1([(e, d) for _, e, d in segments])
        source = "plateaus" if len(segments) == 2 else segments[0][0]
        hp = highpass_noise(np.asarray(y, dtype=float), rho, int(np.searchsorted(t, t_open)))
        if hp is None:
            s2, w_h, s_h = s2_p, 0.0, math.nan
        else:
            s2, w_h = combine_sigma2(s2_p, n, rho, hp)
            s_h = math.sqrt(hp.variance)
        return NoiseModel(sigma=max(math.sqrt(s2), 1e-9), rho=rho, n=n, source=source,
                          sigma_plateau=math.sqrt(s2_p), sigma_highpass=s_h,
                          highpass_weight=w_h)
    # fallback: second differences of the whole trace (robust MAD), white assumed
    d2 = np.diff(y, 2)
    if d2.size < 8:
        raise ValueError(f"too few samples ({y.size}) to estimate the noise")
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    sigma = 1.4826 * mad / math.sqrt(6.0)
    if sigma <= 0:
        sigma = float(np.std(d2)) / math.sqrt(6.0)
    return NoiseModel(sigma=max(sigma, 1e-9), rho=0.0, n=int(d2.size), source="differences")


def normalised_rms(residual: FloatArray, noise: NoiseModel) -> float:
    """Normalised RMS of a residual: its prewhitened RMS over the innovation sigma [-].

    Under the AR(1) noise model the prewhitened residual r_k - rho r_(k-1) (the first
    sample scaled by sqrt(1 - rho^2)) of a right model is the white innovation series, so
    this is 1 within about 1/sqrt(2 n) plus the error of the noise estimate. The plain
    rms(r)/sigma has the same mean but the sampling spread of a correlated series'
    variance, sqrt((1 + rho^2)/((1 - rho^2) 2 n)): at rho 0.9 on a 5000-sample trace
    3 % (a fixed limit of 1.02 then fails a perfect model in about a quarter of the
    traces), against 1 % here. With rho = 0 the two are the same number.

    Parameters
    ----------
    residual : ndarray
        Measured minus model at every sample [Pa].
    noise : NoiseModel
        The trace's noise model.
    """
    r = np.asarray(residual, dtype=float)
    if r.size == 0:
        return math.nan
    w = np.empty_like(r)
    w[0] = r[0] * math.sqrt(max(1.0 - noise.rho * noise.rho, 1e-6))
    w[1:] = r[1:] - noise.rho * r[:-1]
    return float(np.sqrt(np.mean(w * w))) / noise.innovation_sigma


def ljung_box(x: FloatArray, lags: int = 20) -> tuple[float, float]:
    """Ljung-Box portmanteau test of whiteness.

    Parameters
    ----------
    x : ndarray
        Series [any unit].
    lags : int
        Number of autocorrelation lags h [-].

    Returns
    -------
    tuple
        (statistic Q [-], p-value [-]); small p-values mean structure is left.
    """
    x = np.asarray(x, dtype=float) - float(np.mean(x))
    n = x.size
    h = int(min(lags, max(n // 5, 1)))
    den = float(x @ x)
    if n < 8 or den <= 0:
        return math.nan, math.nan
    r = np.array([float(x[k:] @ x[:-k]) / den for k in range(1, h + 1)])
    q = n * (n + 2) * float(np.sum(r * r / (n - np.arange(1, h + 1))))
    return q, chi2_sf(q, h)


def chi2_sf(x: float, dof: int) -> float:
    """Survival function P(X > x) of the chi-square distribution with an integer number of
    degrees of freedom ``dof`` [-] at x [-].

    The closed form of the regularised upper incomplete gamma function Q(dof/2, x/2) for
    integer and half-integer orders (scipy.special.gammaincc's value, to ~1e-14, without
    its import: about 0.2 s of every ``analyze`` run): e^-y sum_k<m y^k/k! for dof = 2m,
    erfc(sqrt y) + e^-y sum_k<m y^(k+1/2)/Gamma(k+3/2) for dof = 2m+1 (y = x/2), each
    term in logarithms (no overflow for large x).
    """
    if dof < 1 or x != x:
        return math.nan
    if x <= 0.0:
        return 1.0
    if x == math.inf:
        return 0.0
    y = 0.5 * x
    log_y = math.log(y)
    if dof % 2 == 0:
        total = sum(math.exp(-y + k * log_y - math.lgamma(k + 1.0)) for k in range(dof // 2))
    else:
        total = math.erfc(math.sqrt(y)) + sum(
            math.exp(-y + (k + 0.5) * log_y - math.lgamma(k + 1.5))
            for k in range((dof - 1) // 2))
    return min(total, 1.0)
