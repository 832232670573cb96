# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Small regressions of the detector: noise from first differences, the start (hinge) fit,
the p* crossing fit (compiled: ``regression.c``) and the closing-instant (corner) fit. Times
in s, pressures in Pa (or the input's signal units: every fit is linear in p)."""

from __future__ import annotations

import ctypes
import math
from array import array
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pneumatic_unload.estimation.types import FloatArray
from pneumatic_unload.fit.ar1 import plateau_ar1
from pneumatic_unload.fit.scalar import golden_section
from pneumatic_unload.model.kernel import build


def rms_sigma(x: FloatArray) -> float:
    """Noise standard deviation from first differences (RMS) [unit of x]."""
    if x.size < 3:
        return 0.0
    return float(np.std(np.diff(x))) / math.sqrt(2.0)


def curvature_sigma(x: FloatArray) -> float:
    """Noise standard deviation from second differences, robustly (the normal-consistent
    median absolute deviation over sqrt(6)) [unit of x]: a smooth fall's trend and curvature
    drop out, and a few samples where the fall bends sharply (a valve's opening ramp) do not
    count; 0 for fewer than 5 samples."""
    if x.size < 5:
        return 0.0
    d2 = np.diff(x, 2)
    return 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)


def noise_correlation(x: FloatArray) -> float:
    """Lag-1 correlation rho of noise ``x`` read as AR(1) noise, 0 where it is not
    significant [-]: rho = 1 + 2 r, r the first differences' own lag-1 correlation (first
    differences of white noise have r = -1/2); 0 unless rho exceeds three of its standard
    errors for white noise (sqrt(2/n)) or fewer than 16 samples are given; at most 0.99.
    A smooth drift of ``x`` (a plateau cooling) hardly moves r."""
    if x.size < 16:
        return 0.0
    d = np.diff(x)
    d = d - float(np.mean(d))
    den = float(np.dot(d, d))
    if not den > 0.0:
        return 0.0
    rho = 1.0 + 2.0 * float(np.dot(d[1:], d[:-1])) / den
    if not rho > 3.0 * math.sqrt(2.0 / d.size):
        return 0.0
    return min(rho, 0.99)


def variance_correlation(x: FloatArray) -> float:
    """Lag-1 correlation rho of noise ``x`` read as AR(1) noise from its variance, 0 where
    it is not significant [-]: 1 - rho = (first differences' variance) / (2 x the
    samples' variance about their straight line), the latter direct where
    :func:`noise_correlation`'s r is not precise (rho near 1: a correlation time of more
    than a few per cent of ``x``); 0 unless rho exceeds three of its standard errors for
    white noise (sqrt(2/n)) or fewer than 16 samples are given; at most 0.999."""
    n = x.size
    if n < 16:
        return 0.0
    d = np.diff(x)
    dd = float(np.dot(d, d)) / (2.0 * (n - 1))
    u = np.arange(n, dtype=float) - 0.5 * (n - 1)
    y = x - float(np.mean(x))
    var = (float(np.dot(y, y)) - float(np.dot(y, u)) ** 2 / float(np.dot(u, u))) / (n - 2)
    if not (var > 0.0 and dd > 0.0):
        return 0.0
    rho = 1.0 - dd / var
    if not rho > 3.0 * math.sqrt(2.0 / n):
        return 0.0
    return min(rho, 0.999)


def noise_rho(x: FloatArray) -> float:
    """Lag-1 correlation of noise x read as AR(1) noise [-]: the larger of
    :func:`noise_correlation` (precise for a short correlation time) and
    :func:`variance_correlation` (for a long one); 0 for white noise."""
    return max(noise_correlation(x), variance_correlation(x))


def variance_inflation(x: FloatArray) -> float:
    """How many times a white-noise formula understates the variance of a mean or a fit
    over many correlation times of noise x [-]: (1 + rho)/(1 - rho), rho its AR(1)
    correlation matched on x about its straight line (:func:`pneumatic_unload.fit.ar1.plateau_ar1`:
    the samples' own lag-1 products, precise near rho = 1 where the inflation is steep,
    unlike :func:`noise_rho`); 1 unless rho exceeds three of its standard errors for white
    noise (1/sqrt(n)) or fewer than 16 samples are given."""
    n = x.size
    if n < 16:
        return 1.0
    u = np.arange(n, dtype=float) - 0.5 * (n - 1)
    y = x - float(np.mean(x))
    e = y - u * (float(np.dot(y, u)) / float(np.dot(u, u)))
    rho, _ = plateau_ar1([(e, 1)])
    return (1.0 + rho) / (1.0 - rho) if rho > 3.0 / math.sqrt(n) else 1.0


def correlated_noise_factor(x: FloatArray) -> float:
    """How much :func:`rms_sigma` understates the standard deviation of noise ``x`` whose
    samples are correlated [-]: 1/sqrt(1 - rho) for AR(1) noise of lag-1 correlation rho
    (:func:`noise_correlation`; 1 for white noise)."""
    return 1.0 / math.sqrt(1.0 - noise_correlation(x))


def solve3(m: tuple[tuple[float, float, float], ...], r: tuple[float, float, float]
            ) -> tuple[float, float, float] | None:
    """Solve a 3x3 linear system by Cramer's rule (None when singular) [-]."""
    (a, b, c), (d, e, f), (g, h, k) = m
    c1, c2, c3 = e * k - f * h, f * g - d * k, d * h - e * g
    det = a * c1 + b * c2 + c * c3
    if det == 0.0 or not math.isfinite(det):
        return None
    x = (r[0] * c1 + b * (f * r[2] - r[1] * k) + c * (r[1] * h - e * r[2])) / det
    y = (a * (r[1] * k - f * r[2]) + r[0] * c2 + c * (d * r[2] - r[1] * g)) / det
    z = (a * (e * r[2] - r[1] * h) + b * (r[1] * g - d * r[2]) + r[0] * c3) / det
    return x, y, z


def grid_then_golden(f: Callable[[float], float], t: FloatArray, t_lo: float, t_hi: float,
                     *, n_grid: int, rel_tol: float) -> float:
    """Minimise f(x) over [t_lo, t_hi] [s]: at most ``n_grid`` sample instants of ``t`` in
    the interval, then a golden-section search around the best one, down to ``rel_tol``
    times the grid step."""
    cand = t[(t >= t_lo) & (t <= t_hi)]
    if cand.size == 0:
        cand = np.array([0.5 * (t_lo + t_hi)])
    if cand.size > n_grid:
        cand = cand[np.linspace(0, cand.size - 1, n_grid).astype(int)]
    vals = [f(float(c)) for c in cand]
    k = int(np.argmin(vals))
    step = float(cand[1] - cand[0]) if cand.size > 1 else t_hi - t_lo
    return golden_section(f, max(t_lo, float(cand[k]) - step),
                          min(t_hi, float(cand[k]) + step), tol=rel_tol * max(step, 1e-12))


def power_shape(s: float, c: float, exponent: float, u_max: float
                ) -> tuple[float, float] | None:
    """The power-law fall p10 - A (1 - (1 + beta u)^-k) with the initial slope ``s``
    [Pa/s] and curvature ``c`` [Pa/s^2] of p10 - s u + c u^2 (k = ``exponent`` [-]):
    (A [Pa], beta [1/s]), or None where it does not apply (no finite exponent, no fall,
    no convex curvature, or beta u beyond 10 on the window of ``u_max`` [s]).

    A choked discharge from a tank falls as (1 + beta u)^(-2 gamma/(gamma - 1)) at first
    (adiabatic; faster heat exchange makes it more exponential, k -> inf: the cubic's share
    moves from 3/4 to 2/3 of c^2/s): its terms beyond the quadratic are the start fit's
    model form, which leaves a bias of up to two sigmas in the start where few samples
    span a large part of the drop (a fast discharge at a low sample rate).
    """
    if not (math.isfinite(exponent) and exponent > 0.0 and s > 0.0 and c > 0.0):
        return None
    beta = 2.0 * c / (s * (exponent + 1.0))
    if not (math.isfinite(beta) and beta * u_max <= 10.0):
        return None
    return s / (exponent * beta), beta


def power_remainder(u: FloatArray, shape: tuple[float, float], exponent: float
                    ) -> FloatArray:
    """The power-law fall's terms beyond the quadratic at u >= 0 [s] (:func:`power_shape`)
    [Pa]: A ((1 + beta u)^-k - 1 + k beta u - k (k + 1) (beta u)^2 / 2)."""
    a, beta = shape
    x = beta * u
    k = exponent
    return a * (np.expm1(-k * np.log1p(x)) + k * x - 0.5 * k * (k + 1.0) * x * x)


def hinge_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float, *,
              exponent: float = math.inf) -> tuple[float, float, float, float, float]:
    """Fit p = p10 (t < t0), p10 - s u + c u^2 + R(u) (u = t - t0 >= 0) with t0 in
    [t_lo, t_hi].

    Sub-sample t0 by minimising the profiled sum of squares (linear in p10, s, c for each
    t0) with a bracketed golden-section search after a grid search on the sample instants.
    R is the power-law fall's remainder beyond the quadratic (:func:`power_remainder`,
    exponent k): the quadratic is fitted first (R = 0), then twice more with R made from
    the previous pass's s and c (without a finite exponent, or where the power law does not
    apply, R = 0 and one pass).

    Parameters
    ----------
    t, p : ndarray
        Window of samples [s], [Pa].
    t_lo, t_hi : float
        Search interval for t0 [s].
    exponent : float
        k of the power-law fall [-] (2 gamma/(gamma - 1) for a choked discharge).

    Returns
    -------
    tuple
        (t0 [s], p10 [Pa], s [Pa/s], c [Pa/s^2], residual rms [Pa]).
    """
    tc = t - t[0]
    scale_t = max(tc[-1], 1e-12)
    p_ref = float(np.mean(p))
    q = p - p_ref
    n_all = float(q.size)

    def solve(t0: float, shape: tuple[float, float] | None) -> tuple[float, FloatArray]:
        # normal equations of [1, -u, u^2] from sums over the post-t0 samples (u > 0)
        k = int(np.searchsorted(tc, t0 - t[0], side="right"))
        u = (tc[k:] - (t0 - t[0])) / scale_t
        if shape is None:
            qk = q[k:]
            sq_all, s_all = sq0, s0
        else:
            rem = power_remainder(u * scale_t, shape, exponent)
            qk = q[k:] - rem
            # the sums over all samples with the post-t0 ones corrected
            sq_all = sq0 - float(q[k:] @ q[k:]) + float(qk @ qk)
            s_all = s0 - float(rem.sum())
        u2 = u * u
        su, su2, su3, su4 = float(u.sum()), float(u2.sum()), float(u2.dot(u)), \
            float(u2.dot(u2))
        squ, squ2 = float(qk.dot(u)), float(qk.dot(u2))
        m = ((n_all, -su, su2), (-su, su2, -su3), (su2, -su3, su4))
        rhs = (s_all, -squ, squ2)
        coef = solve3(m, rhs)
        if coef is None:
            sol = np.linalg.lstsq(np.array(m), np.array(rhs), rcond=None)[0]
            coef = (float(sol[0]), float(sol[1]), float(sol[2]))
        sse = max(sq_all - (coef[0] * rhs[0] + coef[1] * rhs[1] + coef[2] * rhs[2]), 0.0)
        return sse, np.array((coef[0] + p_ref, coef[1], coef[2]))

    sq0, s0 = float(q @ q), float(np.sum(q))
    shape: tuple[float, float] | None = None
    for _pass in range(3):
        t0 = grid_then_golden(lambda x, sh=shape: solve(x, sh)[0], t, t_lo, t_hi, n_grid=64,
                              rel_tol=1e-3)
        sse0, coef = solve(t0, shape)
        slope, curv = float(coef[1]) / scale_t, float(coef[2]) / scale_t**2
        shape = power_shape(slope, curv, exponent, float(t[-1]) - t0)
        if shape is None:
            break
    rms = math.sqrt(sse0 / max(p.size - 4, 1))
    return t0, float(coef[0]), slope, curv, rms


def sloped_hinge_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float
                     ) -> tuple[float, float, float, float, float, float]:
    """Fit p = p10 + d (t - t0) (t < t0), p10 - s u + c u^2 (u = t - t0 >= 0) with t0 in
    [t_lo, t_hi]: the hinge of :func:`hinge_fit` on a plateau that drifts (a gas warmer or
    cooler than the wall relaxing toward it before the opening). Linear least squares in
    (p10, d, s, c) for each t0, minimised over t0 as :func:`hinge_fit` does.

    Returns
    -------
    tuple
        (t0 [s], p10 [Pa], s [Pa/s], c [Pa/s^2], residual rms [Pa], d [Pa/s]).
    """
    tc = t - t[0]
    scale_t = max(float(tc[-1]), 1e-12)
    p_ref = float(np.mean(p))
    q = p - p_ref

    def solve(t0: float) -> tuple[float, FloatArray]:
        x = (tc - (t0 - t[0])) / scale_t
        pre = x < 0.0
        a = np.column_stack([np.ones_like(x), np.where(pre, x, 0.0),
                             np.where(pre, 0.0, -x), np.where(pre, 0.0, x * x)])
        coef, *_ = np.linalg.lstsq(a, q, rcond=None)
        r = q - a @ coef
        return float(r @ r), coef

    t0 = grid_then_golden(lambda x: solve(x)[0], t, t_lo, t_hi, n_grid=64, rel_tol=1e-3)
    sse, coef = solve(t0)
    rms = math.sqrt(sse / max(p.size - 5, 1))
    return (t0, float(coef[0]) + p_ref, float(coef[2]) / scale_t,
            float(coef[3]) / scale_t**2, rms, float(coef[1]) / scale_t)


def hinge_cov(t: FloatArray, t0: float, slope: float, curv: float, rms: float, *,
              exponent: float = math.inf) -> tuple[float, float, float]:
    """Covariance of the hinge fit's start and plateau (:func:`hinge_fit`) from its Fisher
    information at the fitted values: the model's Jacobian over the window's instants in
    (t0, p10, and the fall's two shape parameters), times the residual variance.

    The curvature after the start and the continuity at it are part of the model: the
    start's sigma from a straight line after the start (endpoint variance 4/n) is too
    narrow when the curvature is free (about 9/n), and the start and the plateau errors
    are correlated (a plateau fitted low meets the fall later).

    Parameters
    ----------
    t : ndarray
        The window's instants [s].
    t0, slope, curv, rms : float
        The fit's start [s], initial fall rate [Pa/s], curvature [Pa/s^2] and residual
        rms [Pa].
    exponent : float
        The power-law fall's k (as given to :func:`hinge_fit`) [-].

    Returns
    -------
    tuple
        (var t0 [s^2], cov(t0, p10) [s Pa], var p10 [Pa^2]); infinite variances when the
        information is singular.
    """
    tc = t - t0
    post = tc > 0.0
    scale_t = max(float(t[-1] - t[0]), 1e-12)
    u = np.where(post, tc, 0.0) / scale_t
    shape = power_shape(slope, curv, exponent, float(t[-1]) - t0)
    # columns: d/dt0 (times scale_t), d/dp10, then the fall's shape parameters (scaled)
    j = np.empty((4, t.size))
    j[1] = 1.0
    if shape is None:  # p10 - s u + c u^2: d/d(s scale_t), d/d(c scale_t^2)
        j[0] = np.where(post, slope * scale_t - 2.0 * curv * scale_t**2 * u, 0.0)
        j[2] = -u
        j[3] = u * u
    else:  # p10 - A (1 - (1 + beta u)^-k): d/dA, d/d(beta scale_t)
        a, beta = shape
        x = beta * scale_t * u
        g = np.exp(-(exponent + 1.0) * np.log1p(x))
        j[0] = np.where(post, a * exponent * beta * scale_t * g, 0.0)
        j[2] = np.expm1(-exponent * np.log1p(x))
        j[3] = -a * exponent * u * g
    info = j @ j.T
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return math.inf, 0.0, math.inf
    s2 = rms * rms
    v_t0, c_tp, v_p = float(cov[0, 0]) * s2, float(cov[0, 1]) * s2, float(cov[1, 1]) * s2
    if not (v_t0 >= 0.0 and v_p >= 0.0 and math.isfinite(v_t0) and math.isfinite(v_p)):
        return math.inf, 0.0, math.inf
    return v_t0 * scale_t**2, c_tp * scale_t, v_p


def crossing_fit(t: FloatArray, p: FloatArray, level: float
                 ) -> tuple[float, float, float]:
    """Sub-sample time at which a local quadratic regression of p(t) crosses ``level``.

    The regression is ``pu_crossing_fit`` of ``regression.c`` (compiled, the one
    implementation: the estimator's crossing window, :func:`crossing_window`, runs the same
    code): the normal equations of [1, u, u^2] in the centred, scaled time u = (t - tm)/w
    and the centred pressure, by Cramer's rule; the root nearest the window centre; its
    standard deviation by the delta method with the residual variance.

    Parameters
    ----------
    t, p : ndarray
        Samples around the crossing [s], [Pa]; p decreasing overall.
    level : float
        Threshold [Pa].

    Returns
    -------
    tuple
        (crossing time [s], its standard deviation [s], slope at the crossing [Pa/s]);
        (NaN, inf, 0) when the fit is flat (no crossing).
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    p = np.ascontiguousarray(p, dtype=np.float64)
    if t.shape != p.shape:
        raise ValueError(f"t and p differ in length: {t.size} vs {p.size}")
    out = np.empty(3)
    _LIB.pu_crossing_fit(t.size, t.ctypes.data, p.ctypes.data, float(level),
                         out.ctypes.data)
    return float(out[0]), float(out[1]), float(out[2])


def crossing_window(t: array, p: array, i0: int, n: int, upper: float, fallback: int,
                    level: float, gap_limit: float) -> tuple[float, float, float, bool, int]:
    """The streaming estimator's p* crossing, its window closed at index n - 1.

    The first window starts after the last sample above ``upper`` in [i0, n) (at i0 when
    there is none), or at ``fallback`` when that leaves fewer than 5 samples;
    :func:`crossing_fit` on it, then again on a window symmetric in time about that first
    estimate (the ends of the first were chosen by noisy sample values, which biases the
    fit), in one compiled call (``pu_crossing_window``: the crossing estimate is published
    at the sample that completes it).

    Parameters
    ----------
    t, p : array.array of float64
        The estimator's buffer: stamps [s] and samples [Pa or signal units] from index 0.
    i0, n : int
        The unload's first index and the end of the window (0 <= i0 < n <= len(t)) [-].
    upper : float
        The window's upper level, p* + half [Pa or signal units].
    fallback : int
        The start of a window of too few samples (a slice start: negative counts back
        from n) [-].
    level : float
        The crossing level p* [Pa or signal units].
    gap_limit : float
        Largest stamp step that is not a gap [s].

    Returns
    -------
    tuple
        (crossing time [s], its standard deviation [s], slope at the crossing [Pa/s or
        signal units/s], whether a stamp step of the first window exceeds ``gap_limit``,
        the first window's start [-]).
    """
    if not 0 <= i0 < n <= min(len(t), len(p)):
        raise ValueError(f"crossing window [{i0}, {n}) outside the {len(t)} samples")
    out = array("d", _OUT_BYTES)
    _LIB.pu_crossing_window(t.buffer_info()[0], p.buffer_info()[0], i0, n, upper, fallback,
                            level, gap_limit, out.buffer_info()[0])
    return out[0], out[1], out[2], out[3] != 0.0, int(out[4])


def _load() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(build(source=Path(__file__).with_name("regression.c"))))
    dbl, i64, ptr = ctypes.c_double, ctypes.c_long, ctypes.c_void_p
    lib.pu_crossing_fit.restype = None
    lib.pu_crossing_fit.argtypes = [i64, ptr, ptr, dbl, ptr]
    lib.pu_crossing_window.restype = None
    lib.pu_crossing_window.argtypes = [ptr, ptr, i64, i64, dbl, i64, dbl, dbl, ptr]
    lib.pu_block_steps.restype = None
    lib.pu_block_steps.argtypes = [ptr, ptr, i64, dbl, ptr]
    lib.pu_append.restype = None
    lib.pu_append.argtypes = [ptr, ptr, i64, dbl, ptr, ptr, ptr, ptr]
    lib.pu_first_below.restype = i64
    lib.pu_first_below.argtypes = [ptr, i64, i64, dbl]
    return lib


_LIB = _load()
#: Initial bytes of :func:`crossing_window`'s output (five doubles).
_OUT_BYTES = bytes(40)


def block_steps(t: FloatArray, p: FloatArray, last_t: float
                ) -> tuple[float, float, bool, float]:
    """The checks of a block before the streaming estimator takes it (``pu_block_steps``:
    one compiled call on the live path).

    Parameters
    ----------
    t, p : ndarray
        The block's stamps [s] and values, C-contiguous float64 of one length >= 1.
    last_t : float
        The last stamp taken before the block [s].

    Returns
    -------
    tuple
        (shortest stamp step [s], longest [s], both NaN when a step is NaN; whether every
        value is finite; the larger of the first and the last stamp's magnitude [s]).
    """
    out = array("d", _OUT_BYTES)
    _LIB.pu_block_steps(_address(t), _address(p), t.size, last_t, out.buffer_info()[0])
    return out[0], out[1], out[2] != 0.0, out[3]


def append_sums(t: FloatArray, p: FloatArray, prev: float, dest: tuple[int, int, int, int]
                ) -> None:
    """Copy a block (stamps t [s], values p: C-contiguous float64 of one length) to the
    addresses ``dest`` of the buffer's stamps, values, prefix sums and squared-difference
    sums (each sum's address at its last element held) and continue the sums
    (``pu_append``; ``prev``: the value before the block)."""
    _LIB.pu_append(_address(t), _address(p), p.size, prev, *dest)


def _address(a: FloatArray) -> int:
    """The address of an array's first element (``a.ctypes.data`` without its Python-level
    ctypes object, on the live block's path)."""
    return a.__array_interface__["data"][0]


def first_below_in(p: array, i: int, hi: int, level: float) -> int:
    """:func:`~.decisions.first_below` on the buffer's values ``p`` (array.array of float64)
    in one compiled call: the first index in [i, hi) whose value is below ``level``, or
    hi [-]."""
    top = min(hi, len(p))
    if top <= i or level == -math.inf:
        return hi
    k = _LIB.pu_first_below(p.buffer_info()[0], i, top, level)
    return k if k < top else hi


def corner_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float
               ) -> tuple[float, float, float]:
    """Sub-sample instant of a slope change: p = c0 + quadratic in u- and in u+.

    u- = min(t - tc, 0) and u+ = max(t - tc, 0); tc in [t_lo, t_hi] minimises the profiled
    sum of squares (grid on the sample instants, then golden section). Used for the
    closing instant of an aborted unload.

    Parameters
    ----------
    t, p : ndarray
        Window of samples [s], [Pa].
    t_lo, t_hi : float
        Search interval [s].

    Returns
    -------
    tuple
        (tc [s], p(tc) [Pa], residual rms [Pa]).
    """
    tm = t - t[0]
    sc = max(float(tm[-1]), 1e-12)

    def solve(tc: float) -> tuple[float, FloatArray]:
        u = (tm - (tc - t[0])) / sc
        um, up = np.minimum(u, 0.0), np.maximum(u, 0.0)
        a = np.column_stack((np.ones_like(u), um, um * um, up, up * up))
        coef, *_ = np.linalg.lstsq(a, p, rcond=None)
        r = p - a @ coef
        return float(r @ r), coef

    tc = grid_then_golden(lambda x: solve(x)[0], t, t_lo, t_hi, n_grid=96, rel_tol=1e-6)
    sse0, coef = solve(tc)
    return tc, float(coef[0]), math.sqrt(sse0 / max(p.size - 6, 1))
