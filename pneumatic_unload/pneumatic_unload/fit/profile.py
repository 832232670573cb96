# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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

from pneumatic_unload.fit.lsq import BAD_RESIDUAL, DIFF_STEP, FitResult
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
        Estimate and ends [unit]. An end that is not known is NaN: every end of a parameter
        that is not identifiable except a profile end that closes inside the range (the
        other end does not close, or the linear interval rests on a singular or too flat
        covariance); :attr:`reason` says what is known instead, in words.
    unit : str
        SI unit.
    method : str
        'linear' (from the covariance, checked by two profile points) or 'profile'.
    identifiable : bool
        False when an end does not close inside the parameter's range, or the covariance
        gives no finite linear interval (or one wider than a factor of about 50 either
        side of a log parameter's estimate).
    doc : str
        Meaning.
    reason : str
        For a parameter that is not identifiable, in words: what is known (the values over
        which the likelihood is flat, or that the fit could not compute a sensitivity)
        and what would identify it; '' when it is identifiable.
    computed : bool
        False when no interval could be computed (the model could not be evaluated next
        to the fit, or the covariance is singular in a direction the parameter is not
        part of): :attr:`identifiable` is then False for want of an interval, which says
        nothing about what the record holds.
    """

    value: float
    low: float
    high: float
    unit: str
    method: str
    identifiable: bool
    doc: str
    reason: str = ""
    computed: bool = True

    def describe(self) -> str:
        """The interval for text output: '95 % [low, high] (method)' when the parameter is
        identifiable, else :attr:`reason` (words, never an open or overflowed end as a
        number)."""
        if self.identifiable:
            return f"95 % [{self.low:.4g}, {self.high:.4g}] ({self.method})"
        return self.reason or "not identifiable from this record (no 95 % interval closes)"


def interval(trace: Trace, model: FittableModel, fit: FitResult, name: str,
             x_std: float, *, check: bool = True) -> Interval:
    """95 % interval of a free parameter of a fit.

    The linear interval x +- 1.96 sd (scaled coordinates) is checked by refitting with
    the parameter held at each end: when the chi^2 rise there is not within [0.6, 1.5]
    of 3.84, the profile-likelihood interval is computed instead; an end that does not
    close inside the range makes the parameter not identifiable. So does a linear interval
    without a finite standard error (a direction of the parameters the trace does not
    change along; or, ``computed`` False, a model that could not be evaluated next to the
    fit, or a singular direction the parameter is not part of) or, for a log parameter, one
    wider than a factor of about 50 either side. Its unknown ends are NaN and ``reason``
    says in words what is known and what would identify it.

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
    closed = [True, True]

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
            ends, closed = [], []
            for sgn in (-1.0, 1.0):
                e, c = _profile_end(chi_at, x0, sgn, se, lo, hi)
                ends.append(e)
                closed.append(c)
            ident = all(closed)
    value = fit.values[name]
    computed = True
    if method == "profile":
        low, high = _value(p, ends[0]), _value(p, ends[1])
        reason = "" if ident else _open_profile_reason(p, value, ends, closed, lo, hi)
        if not closed[0]:
            low = math.nan
        if not closed[1]:
            high = math.nan
    elif not (math.isfinite(se) and se > 0):
        ident, low, high = False, math.nan, math.nan
        reason, computed = _singular_reason(fit, name)
    elif p.log and se * p.scale > 2.0:
        ident, low, high = False, math.nan, math.nan
        reason = _flat_linear_reason(p, se)
    else:
        low, high, reason = _value(p, ends[0]), _value(p, ends[1]), ""
    return Interval(value=value, low=low, high=high, unit=p.unit, method=method,
                    identifiable=ident, doc=p.doc, reason=reason, computed=computed)


#: A record's information on a parameter, in words: what would identify one that is not.
_MORE_INFORMATION = ("a record in which its effect on the pressure is larger (a longer "
                     "discharge, less noise) or a separate measurement of it")


def _fmt_value(v: float, unit: str) -> str:
    """``v`` [unit] for a sentence (no unit for dimensionless '-')."""
    return f"{v:.4g}{(' ' + unit) if unit and unit != '-' else ''}"


def _open_profile_reason(p: Parameter, value: float, ends: list[float], closed: list[bool],
                         lo: float, hi: float) -> str:
    """Words for a profile interval with an open end: over which values of ``p`` the
    likelihood stays within the 95 % level, and what would close it."""
    parts = ["not identifiable from this record"]
    for k, (side, limit, bound) in enumerate((("lower", lo, p.lo), ("upper", hi, p.hi))):
        if closed[k]:
            parts.append(f"its 95 % {side} end is {_fmt_value(_value(p, ends[k]), p.unit)}")
        elif math.isfinite(ends[k]) and abs(ends[k] - limit) < 1e-3 * max(hi - lo, 1.0):
            parts.append(f"the likelihood is flat in {p.name} (chi^2 within 3.84 of its "
                         f"minimum) from the estimate {_fmt_value(value, p.unit)} to the "
                         f"{side} end of its range, {_fmt_value(bound, p.unit)}")
        else:
            end = _value(p, ends[k]) if math.isfinite(ends[k]) else math.nan
            parts.append(f"the likelihood is flat in {p.name} (chi^2 within 3.84 of its "
                         f"minimum) from the estimate {_fmt_value(value, p.unit)} "
                         f"{'down' if k == 0 else 'up'} to {_fmt_value(end, p.unit)} at "
                         "least (the profile search stopped there)")
    return ": ".join(parts[:2]) + "".join(f"; {x}" for x in parts[2:]) + \
        f"; what would identify it: {_MORE_INFORMATION}"


def _flat_linear_reason(p: Parameter, se: float) -> str:
    """Words for a log parameter whose linear interval spans more than a factor e^3.92
    (about 50) either side of its estimate."""
    factor = math.exp(min(1.96 * se * p.scale, 700.0))
    span = (f"a factor of {factor:.3g}" if factor < 1e6 else "more than a factor of a "
            "million")
    return (f"not identifiable from this record: the likelihood is nearly flat in "
            f"{p.name}: its linear 95 % range spans {span} "
            f"either side of the estimate (no profile was computed); what would identify "
            f"it: {_MORE_INFORMATION}")


def _failed_steps(fit: FitResult) -> list[str]:
    """Free parameters whose finite-difference step at the minimum could not be evaluated
    (the Jacobian column is that of :data:`~pneumatic_unload.fit.lsq.BAD_RESIDUAL`)."""
    jac, f0 = np.asarray(fit.jac, dtype=float), np.asarray(fit.fun, dtype=float)
    if jac.ndim != 2 or jac.shape[0] != f0.size or f0.size == 0:
        return []
    out = []
    for k, name in enumerate(fit.params.free[:jac.shape[1]]):
        for h in (DIFF_STEP, -DIFF_STEP):
            if np.allclose(f0 + h * jac[:, k], BAD_RESIDUAL, rtol=1e-6, atol=0.0):
                out.append(name)
                break
    return out


def _singular_reason(fit: FitResult, name: str) -> tuple[str, bool]:
    """Words for a parameter whose linear standard error is not finite (a model that could
    not be evaluated next to the minimum, a parameter the trace does not depend on, or a
    direction of the parameters along which the trace does not change), and whether that
    is a property of the record (True) or a failure of the computation (False)."""
    failed = _failed_steps(fit)
    if failed:
        whose = (f"the trace's sensitivity to {name} is unknown" if name in failed else
                 f"the fit's covariance, and with it a linear interval of {name}, is "
                 "unknown")
        return (f"uncertainty not known: the model could not be evaluated next to the "
                f"fit (a small step of {', '.join(failed)} made the integration fail), so "
                f"{whose} (a failure of the computation, not a property of the record); "
                "what would give one: a profile-likelihood interval (it refits instead of "
                "differentiating)"), False
    jac = np.asarray(fit.jac, dtype=float)
    free = list(fit.params.free)
    if jac.ndim != 2 or jac.shape[1] != len(free) or not np.all(np.isfinite(jac)):
        return ("uncertainty not known: the fit's sensitivities are not finite; what "
                "would give one: a profile-likelihood interval"), False
    norm = np.sqrt(np.sum(jac * jac, axis=0))
    i = free.index(name)
    if not norm[i] > 0:
        return (f"not identifiable from this record: the trace does not change with "
                f"{name} (zero sensitivity): the record holds no information on it; what "
                f"would identify it: {_MORE_INFORMATION}"), True
    good = norm > 0
    jn = jac[:, good] / norm[good]
    names = [q for q, g in zip(free, good, strict=True) if g]
    _u, sv, vt = np.linalg.svd(jn, full_matrices=False)
    null = [vt[j] for j in range(sv.size) if sv[j] <= 1e-10 * sv[0]]
    k = names.index(name)
    mine = [v for v in null if abs(v[k]) >= 0.1 * float(np.max(np.abs(v)))]
    if mine:
        v = mine[0]
        partners = [q for q, c in zip(names, v, strict=True)
                    if q != name and abs(c) >= 0.1 * float(np.max(np.abs(v)))]
        with_ = ", ".join(partners) or "the other free parameters"
        return (f"not identifiable from this record: the trace changes with {name} "
                f"exactly as with a combination of {with_} "
                f"(the likelihood is flat along that direction): the record cannot tell "
                f"them apart; what would identify it: {name} or {with_} fixed by a "
                "separate measurement, or a record in which their effects differ"), True
    involved = sorted({q for v in null for q, c in zip(names, v, strict=True)
                       if abs(c) >= 0.1 * float(np.max(np.abs(v)))})
    return (f"uncertainty not known: the fit cannot tell "
            f"{', '.join(involved) or 'some free parameters'} apart, and the covariance "
            f"inverts that singular direction for every parameter; what would give one: "
            "a profile-likelihood interval, or those parameters fixed by a separate "
            "measurement"), False


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
