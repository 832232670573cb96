"""Small regressions of the detector: noise from first differences, the start (hinge) fit,
the p* crossing fit and the closing-instant (corner) fit. Times in s, pressures in Pa (or
the input's signal units: every fit is linear in p)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pneumatic_unload.estimation.types import FloatArray


def rms_sigma(x: FloatArray) -> float:
    """Noise standard deviation from first differences (RMS) [unit of x]."""
    if x.size < 3:
        return 0.0
    return float(np.std(np.diff(x))) / math.sqrt(2.0)


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
    a_, b_ = max(t_lo, float(cand[k]) - step), min(t_hi, float(cand[k]) + step)
    gr = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = b_ - gr * (b_ - a_), a_ + gr * (b_ - a_)
    f1, f2 = f(x1), f(x2)
    for _ in range(48):
        if b_ - a_ < rel_tol * max(step, 1e-12):
            break
        if f1 <= f2:
            b_, x2, f2 = x2, x1, f1
            x1 = b_ - gr * (b_ - a_)
            f1 = f(x1)
        else:
            a_, x1, f1 = x1, x2, f2
            x2 = a_ + gr * (b_ - a_)
            f2 = f(x2)
    return 0.5 * (a_ + b_)


def hinge_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float
              ) -> tuple[float, float, float, float, float]:
    """Fit p = p10 (t < t0), p10 - s u + c u^2 (u = t - t0 >= 0) with t0 in [t_lo, t_hi].

    Sub-sample t0 by minimising the profiled sum of squares (linear in p10, s, c for each
    t0) with a bracketed golden-section search after a grid search on the sample instants.

    Parameters
    ----------
    t, p : ndarray
        Window of samples [s], [Pa].
    t_lo, t_hi : float
        Search interval for t0 [s].

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
    sq_all, s_all = float(q @ q), float(np.sum(q))

    def solve(t0: float) -> tuple[float, FloatArray]:
        # normal equations of [1, -u, u^2] from sums over the post-t0 samples (u > 0)
        k = int(np.searchsorted(tc, t0 - t[0], side="right"))
        u = (tc[k:] - (t0 - t[0])) / scale_t
        qk = q[k:]
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

    t0 = grid_then_golden(lambda x: solve(x)[0], t, t_lo, t_hi, n_grid=64, rel_tol=1e-3)
    sse0, coef = solve(t0)
    rms = math.sqrt(sse0 / max(p.size - 4, 1))
    return t0, float(coef[0]), float(coef[1]) / scale_t, float(coef[2]) / scale_t**2, rms


def crossing_fit(t: FloatArray, p: FloatArray, level: float
                 ) -> tuple[float, float, float]:
    """Sub-sample time at which a local quadratic regression of p(t) crosses ``level``.

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
    if t.size == 0:
        return math.nan, math.inf, 0.0
    tm = float(t.sum()) / t.size  # np.mean's dispatch costs more than the sum here
    # normal equations of [1, u, u^2] in the centred, scaled time u = x / w and the
    # centred pressure (well conditioned; 3x3 by Cramer's rule: a crossing is published
    # at the sample that completes it, so no LAPACK call overhead here; the moments from
    # one product of the 3 x n design matrix with itself and with q)
    t_first, t_last = float(t[0]), float(t[-1])
    # the half-width: at an end for sorted stamps (a NaN stamp gives NaN, refused below)
    w = max(tm - t_first, t_last - tm) if t_last >= t_first \
        else float(np.abs(t - tm).max())
    p_ref = float(p.sum()) / p.size
    if not (w > 1e-12 * max(1.0, abs(tm)) and math.isfinite(w) and math.isfinite(p_ref)):
        # a window of no duration (stamps closer than a picosecond, or than the float
        # resolution of the stamps): no slope, no crossing
        return math.nan, math.inf, 0.0
    a = np.empty((3, t.size))
    a[0] = 1.0
    np.subtract(t, tm, out=a[1])
    a[1] /= w
    np.multiply(a[1], a[1], out=a[2])
    q = p - p_ref
    mm = (a @ a.T).tolist()
    b = (a @ q).tolist()
    m = ((mm[0][0], mm[0][1], mm[0][2]), (mm[1][0], mm[1][1], mm[1][2]),
         (mm[2][0], mm[2][1], mm[2][2]))
    sol = solve3(m, (b[0], b[1], b[2]))
    if sol is None:  # fewer than three distinct instants: no curve through them
        return math.nan, math.inf, 0.0
    r = q - np.array(sol) @ a
    dof = max(p.size - 3, 1)
    s2 = float(r @ r) / dof
    x_first, x_last = t_first - tm, t_last - tm
    c0, c1, c2 = sol[0] + p_ref, sol[1] / w, sol[2] / (w * w)
    # root of c2 x^2 + c1 x + (c0 - level) nearest the window centre
    if c1 == 0.0 and c2 == 0.0:  # flat (stuck or degenerate samples): no crossing
        return math.nan, math.inf, 0.0
    if abs(c2) < 1e-30 or abs(c2 * (x_last - x_first) ** 2) < 1e-12 * abs(
            c1 * (x_last - x_first)):
        xr = (level - c0) / c1 if c1 != 0.0 else math.nan
    else:
        disc = c1 * c1 - 4.0 * c2 * (c0 - level)
        if disc < 0:
            xr = (level - c0) / c1 if c1 != 0.0 else math.nan
        else:
            sq = math.sqrt(disc)
            r1, r2 = (-c1 + sq) / (2 * c2), (-c1 - sq) / (2 * c2)
            xr = r1 if abs(r1) < abs(r2) else r2
    slope = c1 + 2.0 * c2 * xr
    # delta method: var(f(xr)) / slope^2 with f = c0 + c1 x + c2 x^2, var = s2 g' M^-1 g
    ur = xr / w
    g = (1.0, ur, ur * ur)
    mg = solve3(m, g)
    var_f = s2 * (g[0] * mg[0] + g[1] * mg[1] + g[2] * mg[2]) if mg is not None else math.inf
    std = math.sqrt(max(var_f, 0.0)) / abs(slope) if slope != 0 else math.inf
    return tm + xr, std, slope


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
