"""Noise model of a recorded discharge and the likelihood the discrepancy workflow uses.

The sensor noise is modelled as a stationary AR(1) process e_k = rho e_(k-1) + u_k with
marginal standard deviation sigma [Pa] and innovations u of standard deviation
sigma sqrt(1 - rho^2). sigma and rho are estimated on the parts of the trace where the
tank pressure does not change (the pre-step plateau and the end plateau) after removing a
low-order trend, so that they do not depend on any model fit.

Correlated noise makes a naive (white) likelihood claim effects that are not there: with
rho = 0.9 the information of a trace is about (1 - rho)/(1 + rho) = 1/19 of what the sample
count suggests. :class:`BinnedLikelihood` therefore *prewhitens* the residual
(r_k - rho r_(k-1)), which is white under the AR(1) model, and then sums it in bins
(narrow near the valve opening, wide on slow parts) to keep fits fast. The sum of white
innovations over a bin is again white, so the normalised bin sums are independent unit
normal variables when the model is right and their sum of squares is a chi-square.

SI units: s, Pa.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2 as chi2_dist

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Minimum number of plateau samples for a plateau-based noise estimate [-].
MIN_PLATEAU_SAMPLES = 40


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
        'plateaus' (pre-step and end plateau), 'pre-step', 'end plateau' or
        'differences' (second differences of the whole trace: no plateau long enough;
        rho cannot be estimated then and is set to 0).
    """

    sigma: float
    rho: float
    n: int
    source: str

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
                "effective_fraction": self.effective_fraction}


def _detrended(y: FloatArray, degree: int) -> FloatArray:
    """Residual of a least-squares polynomial of the given degree over the index [unit of y]."""
    x = np.linspace(-1.0, 1.0, y.size)
    coef = np.polynomial.polynomial.polyfit(x, y, degree)
    return y - np.polynomial.polynomial.polyval(x, coef)


def _ar1_moments(e: FloatArray) -> tuple[float, float, int]:
    """Sum of squares, lag-one cross products and count of a zero-mean segment."""
    return float(e @ e), float(e[1:] @ e[:-1]), int(e.size)


def estimate_noise(t: FloatArray, y: FloatArray, t_open: float, tau: float) -> NoiseModel:
    """Estimate sigma and rho from the pre-step plateau and the end plateau.

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
    segments: list[tuple[str, FloatArray]] = []
    # pre-step: drop the quarter next to the (estimated) opening: a slow valve ramp or a
    # late detection would otherwise leak the start of the discharge into the estimate
    pre_end = t_open - 0.25 * (t_open - t[0])
    pre = y[t < pre_end]
    if pre.size >= 16:
        segments.append(("pre-step", _detrended(pre, 1)))
    span = t[-1] - t_open
    if span > 3.0 * tau:
        start = t_open + max(0.6 * span, 3.0 * tau)
        end = y[t >= start]
        if end.size >= 16:
            segments.append(("end plateau", _detrended(end, 2)))
    n_tot = sum(e.size for _, e in segments)
    if n_tot >= MIN_PLATEAU_SAMPLES:
        ss = cp = 0.0
        n = 0
        for _, e in segments:
            a, b, k = _ar1_moments(e)
            ss, cp, n = ss + a, cp + b, n + k
        rho = float(np.clip(cp / ss, 0.0, 0.99)) if ss > 0 else 0.0
        sigma = math.sqrt(ss / max(n - 2 * len(segments), 1))
        source = "plateaus" if len(segments) == 2 else segments[0][0]
        return NoiseModel(sigma=max(sigma, 1e-9), rho=rho, n=n, source=source)
    # fallback: second differences of the whole trace (robust MAD), white assumed
    d2 = np.diff(y, 2)
    if d2.size < 8:
        raise ValueError(f"too few samples ({y.size}) to estimate the noise")
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    sigma = 1.4826 * mad / math.sqrt(6.0)
    if sigma <= 0:
        sigma = float(np.std(d2)) / math.sqrt(6.0)
    return NoiseModel(sigma=max(sigma, 1e-9), rho=0.0, n=int(d2.size), source="differences")


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
    return q, float(chi2_dist.sf(q, h))


def make_bins(t: FloatArray, t_open: float, *, resolution: float = 0.03,
              max_bins_linear: int = 300) -> IntArray:
    """Bin edges (sample indices) fine near the valve opening, coarse elsewhere.

    A bin at a distance d from the opening is about ``resolution`` d wide (at least one
    sample) and at most n / ``max_bins_linear`` samples wide, so the number of bins grows
    only with the logarithm of the record length.

    Parameters
    ----------
    t : ndarray
        Sample instants [s].
    t_open : float
        Valve opening instant [s].
    resolution : float
        Relative width of a bin [-].
    max_bins_linear : int
        Bins of the widest size that fit in the record [-].

    Returns
    -------
    ndarray
        Increasing edge indices from 0 to n.
    """
    n = t.size
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    wmax = max(1, n // max_bins_linear)
    k_open = int(np.searchsorted(t, t_open))
    edges = [k_open]
    k = k_open
    while k > 0:  # backwards over the pre-step
        w = int(min(max(1, resolution * (t_open - t[max(k - 1, 0)]) / dt), wmax))
        k = max(0, k - w)
        edges.append(k)
    edges.reverse()
    k = k_open
    while k < n:
        w = int(min(max(1, resolution * (t[k] - t_open) / dt), wmax))
        k = min(n, k + w)
        edges.append(k)
    out = np.unique(np.asarray(edges, dtype=np.int64))
    if out[0] != 0:
        out = np.concatenate(([0], out))
    return out


class BinnedLikelihood:
    """Prewhitened, binned Gaussian likelihood of a trace under an AR(1) noise model.

    ``residuals(model)`` returns z_b = S_b / (sigma_u sqrt(n_b)), S_b the bin sum of the
    prewhitened residual (y - model); chi^2 = sum z_b^2 is -2 log-likelihood up to a
    constant, and is what information criteria use.

    Parameters
    ----------
    t, y : ndarray
        Sample instants [s] and measured pressure [Pa].
    noise : NoiseModel
        The AR(1) noise model.
    edges : ndarray
        Bin edges from :func:`make_bins`.
    """

    def __init__(self, t: FloatArray, y: FloatArray, noise: NoiseModel, edges: IntArray
                 ) -> None:
        self.t = np.asarray(t, dtype=float)
        self.y = np.asarray(y, dtype=float)
        self.noise = noise
        self.edges = np.asarray(edges, dtype=np.int64)
        self.counts = np.diff(self.edges).astype(float)
        self.rho = noise.rho
        self._first = math.sqrt(max(1.0 - self.rho**2, 1e-6))
        self._norm = noise.innovation_sigma * np.sqrt(self.counts)
        self._sy = self._binsum(self.whiten(self.y))

    @property
    def n(self) -> int:
        """Samples in the trace [-]."""
        return int(self.y.size)

    @property
    def n_bins(self) -> int:
        """Bins [-]."""
        return int(self.counts.size)

    def whiten(self, x: FloatArray) -> FloatArray:
        """Prewhitened series x_k - rho x_(k-1) (first sample scaled) [unit of x]."""
        w = np.empty_like(x)
        w[0] = x[0] * self._first
        w[1:] = x[1:] - self.rho * x[:-1]
        return w

    def _binsum(self, x: FloatArray) -> FloatArray:
        return np.add.reduceat(x, self.edges[:-1])

    def residuals(self, model: FloatArray) -> FloatArray:
        """Normalised prewhitened bin sums of y - model [-] (unit normal if model is right)."""
        return (self._sy - self._binsum(self.whiten(model))) / self._norm

    def sample_whitened(self, model: FloatArray) -> FloatArray:
        """Prewhitened full-rate residual divided by the innovation sigma [-]."""
        return self.whiten(self.y - model) / self.noise.innovation_sigma
