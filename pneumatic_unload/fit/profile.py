"""Profile likelihood: intervals and curvature checks that refit through the one engine.

A profile holds one parameter at a value and refits the others
(:meth:`pneumatic_unload.fit.trace.Trace.fit` with ``fixed``); the rise of chi^2 over the
optimum gives likelihood-ratio intervals that stay honest where the likelihood is not
quadratic. Units: those of the parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.fit.lsq import FitResult
from pneumatic_unload.fit.params import Parameter
from pneumatic_unload.fit.trace import FittableModel, Trace
from pneumatic_unload.fit.uncertainty import CHI2_95

FloatArray = NDArray[np.float64]


def profile_chi2(trace: Trace, model: FittableModel, fit: FitResult, name: str,
                 value: float, *, max_nfev: int = 40) -> tuple[float, FitResult]:
    """chi^2 with ``name`` held at ``value`` [unit], the other free parameters refitted.

    Returns
    -------
    tuple
        (chi^2 [-], the constrained fit).
    """
    start = {k: v for k, v in fit.values.items() if k != name}
    sub = trace.fit(model, fixed={name: value}, start=start, max_nfev=max_nfev)
    return sub.chi2, sub


@dataclass(frozen=True)
class Interval:
    """A 95 % interval of one parameter.

    Attributes
    ----------
    value, low, high : float
        Estimate and ends [unit]; an open end is 0 (log parameters), -inf or +inf.
    unit : str
        SI unit.
    method : str
        'linear' (from the covariance, checked by two profile points) or 'profile'.
    identifiable : bool
        False when an end does not close inside the parameter's range.
    doc : str
        Meaning.
    """

    value: float
    low: float
    high: float
    unit: str
    method: str
    identifiable: bool
    doc: str


def interval(trace: Trace, model: FittableModel, fit: FitResult, name: str,
             x_std: float, *, check: bool = True) -> Interval:
    """95 % interval of a free parameter of a fit.

    The linear interval x +- 1.96 sd (scaled coordinates) is checked by refitting with
    the parameter held at each end: when the chi^2 rise there is not within [0.6, 1.5]
    of 3.84, the profile-likelihood interval is computed instead; an end that does not
    close inside the range makes the parameter not identifiable.

    Parameters
    ----------
    trace, model, fit :
        The trace, the model and its fit.
    name : str
        Parameter.
    x_std : float
        Standard deviation of its scaled coordinate [-].
    check : bool
        Check (and if needed replace) the linear interval by profiles.
    """
    params = fit.params
    p = params[name]
    i = params.free.index(name)
    lo_b, hi_b = params.bounds()
    lo, hi = float(lo_b[i]), float(hi_b[i])
    x0 = float(fit.x[i])
    se = x_std
    ends = [x0 - 1.96 * se, x0 + 1.96 * se]
    method, ident = "linear", True

    def chi_at(xe: float) -> float:
        return profile_chi2(trace, model, fit, name, _value(p, xe))[0] - fit.chi2

    if check and fit.k > 1:
        ok = math.isfinite(se) and se > 0
        for xe in ends:
            if not ok:
                break
            if not lo < xe < hi:
                ok = False
                break
            d = chi_at(xe)
            ok = 0.6 * CHI2_95 <= d <= 1.5 * CHI2_95
        if not ok:
            method = "profile"
            ends = []
            for sgn in (-1.0, 1.0):
                e, closed = _profile_end(chi_at, x0, sgn, se, lo, hi)
                ends.append(e)
                ident = ident and closed
    low, high = _value(p, ends[0]), _value(p, ends[1])
    if method == "profile" and not ident:
        if not math.isfinite(ends[0]) or ends[0] <= lo + 1e-9:
            low = 0.0 if p.log else -math.inf
        if not math.isfinite(ends[1]) or ends[1] >= hi - 1e-9:
            high = math.inf
    if method == "linear" and p.log and se * p.scale > 2.0:
        ident = False
    return Interval(value=fit.values[name], low=low, high=high, unit=p.unit, method=method,
                    identifiable=ident, doc=p.doc)


def _value(p: Parameter, x: float) -> float:
    """Value [unit] of a scaled coordinate of parameter p."""
    g = p.g_centre + p.scale * x
    if p.log:
        return math.exp(min(g, 700.0))
    return float(g)


def _profile_end(chi_at: object, x0: float, sgn: float, se: float, lo: float, hi: float
                 ) -> tuple[float, bool]:
    """Profile-likelihood interval end on one side: (scaled value, closed?)."""
    step = 1.96 * se if (math.isfinite(se) and se > 0) else 0.5
    step = float(np.clip(step, 0.05, 5.0))
    inside = x0
    outside = math.nan
    limit = hi if sgn > 0 else lo
    for _ in range(8):
        xe = x0 + sgn * step
        if (xe - limit) * sgn >= 0:
            xe = limit - sgn * 1e-6 * abs(hi - lo)
            if chi_at(xe) < CHI2_95:  # type: ignore[operator]
                return xe, False
            outside = xe
            break
        if chi_at(xe) >= CHI2_95:  # type: ignore[operator]
            outside = xe
            break
        inside = xe
        step *= 2.0
    if not math.isfinite(outside):
        return inside, False
    for _ in range(5):  # bisection
        mid = 0.5 * (inside + outside)
        if chi_at(mid) >= CHI2_95:  # type: ignore[operator]
            outside = mid
        else:
            inside = mid
    return 0.5 * (inside + outside), True


def valley_std(trace: Trace, model: FittableModel, fit: FitResult, name: str,
               cov: FloatArray, s2: float, *, delta_sd: float = 1.5
               ) -> tuple[float, FloatArray] | None:
    """Effective sigma of ``name`` and the others' slope along its valley, from profiles.

    Where a parameter enters non-linearly and is strongly correlated with others, the
    Gauss-Newton covariance under-states the spread. Refitting with ``name`` held at
    +-``delta_sd`` sigma gives its effective sigma from the chi^2 rise and the others'
    shifts along the valley; the caller combines them.

    Parameters
    ----------
    trace, model, fit :
        The trace, the model and its fit.
    name : str
        Parameter profiled.
    cov : ndarray
        Covariance of the scaled coordinates.
    s2 : float
        Residual variance the chi^2 is divided by [-].
    delta_sd : float
        Profile points in sigma [-].

    Returns
    -------
    tuple or None
        (sigma of the scaled coordinate, slope d x_other / d x_name of the other free
        coordinates) or None when the profile cannot be taken.
    """
    params = fit.params
    i = params.free.index(name)
    sd = math.sqrt(cov[i, i]) if cov[i, i] >= 0 else math.nan
    lo, hi = params.bounds()
    x0 = float(fit.x[i])
    if not (math.isfinite(sd) and sd > 0 and lo[i] + 2 * sd < x0 < hi[i] - 2 * sd):
        return None
    delta = delta_sd * sd
    rises, shifts = [], []
    others = [k for k in range(fit.k) if k != i]
    for sgn in (1.0, -1.0):
        xe = x0 + sgn * delta
        chi, sub = profile_chi2(trace, model, fit, name, _value(params[name], xe),
                                max_nfev=60)
        rises.append(max((chi - fit.chi2) / s2, 1e-12))
        xs = fit.params.to_x(sub.values)
        shifts.append(xs[others] - fit.x[others])
    sd_p = delta / math.sqrt(0.5 * (rises[0] + rises[1]))
    slope = (shifts[0] - shifts[1]) / (2.0 * delta)
    return max(sd, sd_p), slope
