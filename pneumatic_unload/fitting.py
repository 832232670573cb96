"""Model-based sonic conductance: remove the known bias of eq 39.

Two estimators, both built on :mod:`pneumatic_unload.model`:

* :func:`invert_crossing` - the exact inversion of the discharge model at the measured p*
  crossing: the C for which the model (adiabatic, or with natural-convection wall heat
  transfer from the tank's V and L/D) reaches p* at tau_exp. Cheap (a few ms), so the live
  estimator publishes it with the eq 39 value.
* :func:`fit_curve` - a least-squares fit of the whole recorded discharge for C, b, the
  start instant, p10 (and p_atm when it is not given, and the heat-transfer scale when the
  data carry it), with standard deviations from the Jacobian scaled by the residual.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import discharge, sensor_response
from pneumatic_unload.physics import P_STAR_FRACTION

if TYPE_CHECKING:
    from pneumatic_unload.estimation import EstimatorSettings, UnloadResult

FloatArray = NDArray[np.float64]

#: Relative 1-sigma uncertainty assumed for the natural-convection correlation [-].
HEAT_CORRELATION_REL_STD = 0.3


def rig_from_settings(settings: EstimatorSettings, *, conductance: float, p10: float,
                      p_atm: float, critical_ratio: float | None = None,
                      heat_scale: float = 1.0) -> RigConfig:
    """The discharge-model configuration the estimator assumes [SI].

    Parameters
    ----------
    settings : EstimatorSettings
        Tank and gas settings.
    conductance : float
        C [m^3/(s Pa)].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    critical_ratio : float, optional
        b [-]; default the settings' value.
    heat_scale : float
        Multiplier on the natural-convection correlation [-].
    """
    effects = ("heat_transfer",) if settings.heat_model == "natural" else ()
    t10 = settings.initial_temperature
    return RigConfig(
        volume=settings.volume, length_diameter_ratio=settings.length_diameter_ratio,
        conductance=float(np.clip(conductance, 1e-13, 1e-5)),
        critical_ratio=float(np.clip(
            settings.critical_ratio if critical_ratio is None else critical_ratio, 0.0, 0.99)),
        initial_pressure=p10, initial_temperature=t10, atmosphere=p_atm,
        wall_temperature=settings.wall_temperature or t10, gas_constant=settings.gas_constant,
        gamma=settings.gamma, effects=effects, heat_transfer_scale=heat_scale,
        pre_time=0.0, noise_std=0.0)


def model_crossing_time(cfg: RigConfig, p_star: float, t_guess: float, *,
                        rtol: float = 1e-7) -> float:
    """Time for the model's tank pressure to fall from p10 to p_star [s].

    Parameters
    ----------
    cfg : RigConfig
        Model (valve opens at t = 0).
    p_star : float
        Threshold [Pa absolute].
    t_guess : float
        Expected crossing time [s] (sets the output grid: the integration stops at
        1.25 t_guess unless the crossing lies beyond).
    rtol : float
        Integrator relative tolerance [-].
    """
    horizon = 1.25 * t_guess
    for _ in range(8):
        t = np.linspace(0.0, horizon, 129)
        p, _ = discharge(cfg, t, 0.0, rtol=rtol)
        k = np.flatnonzero(p < p_star)
        if k.size:
            j = int(k[0])
            j0 = min(max(j - 1, 1), t.size - 2)
            # quadratic through three points around the crossing, solved for p = p_star
            tt, pp = t[j0 - 1:j0 + 2], p[j0 - 1:j0 + 2]
            c2, c1, c0 = np.polyfit(tt - tt[1], pp, 2)
            disc = c1 * c1 - 4 * c2 * (c0 - p_star)
            if abs(c2) > 0 and disc >= 0:
                r = [(-c1 + s * math.sqrt(disc)) / (2 * c2) for s in (1.0, -1.0)]
                x = min(r, key=lambda v: abs(v - (t[j] - tt[1])))
            else:
                x = (p_star - c0) / c1
            return float(tt[1] + x)
        horizon *= 2.0
    return math.inf


#: Relative tolerance on C of :func:`invert_crossing` (far below any stated uncertainty).
INVERSION_RTOL = 1e-6
#: Integrator tolerance of the inversion: crossing times to about 1e-6 relative [-].
INVERSION_ODE_RTOL = 1e-6


def invert_crossing(
    tau_exp: float, tau_std: float, *, p10: float, p_atm: float, p_star: float,
    settings: EstimatorSettings, c_start: float,
) -> tuple[float, float]:
    """C for which the discharge model crosses p_star at tau_exp, and its 1-sigma [m^3/(s Pa)].

    The model's crossing time is nearly proportional to 1/C (exactly so without heat
    transfer), so a secant iteration on log t(C) - log tau_exp converges in two or three
    integrations (this runs inside the live estimator, at the sample that completes the
    estimate). The standard deviation combines the timing uncertainty and, for the
    natural-convection model, the uncertainty of the heat-transfer correlation
    (:data:`HEAT_CORRELATION_REL_STD`).

    Parameters
    ----------
    tau_exp, tau_std : float
        Measured unloading time and its standard deviation [s].
    p10, p_atm, p_star : float
        Pressures [Pa absolute].
    settings : EstimatorSettings
        Tank and gas settings.
    c_start : float
        Starting value, e.g. the isentropic inversion [m^3/(s Pa)].
    """
    if not (math.isfinite(tau_exp) and tau_exp > 0 and math.isfinite(c_start) and c_start > 0):
        return math.nan, math.nan

    def g(log_c: float) -> float:
        """log(model crossing time / tau_exp) at C = exp(log_c)."""
        cfg = rig_from_settings(settings, conductance=math.exp(log_c), p10=p10, p_atm=p_atm)
        tm = model_crossing_time(cfg, p_star, tau_exp, rtol=INVERSION_ODE_RTOL)
        return math.log(tm / tau_exp) if math.isfinite(tm) and tm > 0 else math.nan

    x0 = math.log(c_start)
    f0 = g(x0)
    if not math.isfinite(f0):
        return math.nan, math.nan
    x1 = x0 + f0  # exact for t proportional to 1/C
    for _ in range(8):
        f1 = g(x1)
        if not math.isfinite(f1):
            return math.nan, math.nan
        if abs(f1) < INVERSION_RTOL:
            break
        slope = (f1 - f0) / (x1 - x0) if x1 != x0 else -1.0
        if not slope < -0.2:  # t(C) falls with C; guard against a flat or noisy secant
            slope = -1.0
        x0, f0, x1 = x1, f1, x1 - f1 / slope
    c = math.exp(x1)
    var = (c * tau_std / tau_exp) ** 2
    if settings.heat_model == "natural":
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm,
                                heat_scale=1.0 + HEAT_CORRELATION_REL_STD)
        tm = model_crossing_time(cfg, p_star, tau_exp, rtol=INVERSION_ODE_RTOL)
        var += (c * (tm / tau_exp - 1.0)) ** 2
    return c, math.sqrt(var)


@dataclass(frozen=True)
class CurveFit:
    """Result of :func:`fit_curve` (SI units; std NaN when not identifiable).

    Attributes
    ----------
    conductance, conductance_std : float
        C and its 1-sigma [m^3/(s Pa)].
    critical_ratio, critical_ratio_std : float
        b and its 1-sigma [-] (NaN when the subsonic tail does not identify it).
    t_start : float
        Valve opening instant [s].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    heat_scale, heat_scale_std : float
        Multiplier on the natural-convection correlation [-] (1 and NaN when not fitted).
    rms : float
        Residual root mean square [Pa].
    n : int
        Samples fitted [-].
    success : bool
        Optimiser convergence.
    inflation : float
        Variance inflation applied for serially correlated residuals [-]
        (:func:`residual_inflation`).
    """

    conductance: float
    conductance_std: float
    critical_ratio: float
    critical_ratio_std: float
    t_start: float
    p10: float
    p_atm: float
    heat_scale: float
    heat_scale_std: float
    rms: float
    n: int
    success: bool
    inflation: float = 1.0


def covariance(jac: FloatArray, s2: float) -> FloatArray:
    """Parameter covariance s2 (J^T J)^-1 computed on column-normalised J [param units^2].

    Normalising the columns first keeps parameters of very different scales (Pa next to
    log-values) from being cut off as "singular" directions, which would report a
    far too small variance; a genuinely unidentifiable direction gets an infinite one.
    """
    jac = np.asarray(jac, dtype=float)
    norm = np.sqrt(np.sum(jac * jac, axis=0))
    npar = jac.shape[1]
    if not np.all(np.isfinite(jac)):
        return np.full((npar, npar), math.nan)
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
    rho near 0 within 2/sqrt(n); a model discrepancy (unmodelled rig effect, wrong heat
    law) or coloured noise leaves runs of same-sign residuals and rho > 0, so the samples
    carry fewer independent pieces of information: the covariance is multiplied by the
    AR(1) effective-sample-size factor (1 + rho)/(1 - rho). rho below 2/sqrt(n) is
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


#: Relative finite-difference step of the curve-fit Jacobians [-] (step = DIFF_STEP
#: max(1, |x|), as scipy's ``diff_step``).
DIFF_STEP = 1e-4
#: The Gauss-Newton polish of :func:`solve_lsq` stops when the next step would lower chi^2
#: by less than this [-] (a chi^2 deficit of 1e-3 is a position error of ~0.05 sigma).
POLISH_CHI2_TOL = 1e-3
#: Largest number of Gauss-Newton polish iterations of :func:`solve_lsq` [-].
POLISH_MAX_ITER = 6


@dataclass(frozen=True)
class LsqSolution:
    """Result of :func:`solve_lsq` (units of the caller's parameters and residuals).

    Attributes
    ----------
    x : ndarray
        Parameters at the minimum.
    fun : ndarray
        Residuals at ``x``.
    jac : ndarray
        Forward-difference Jacobian d fun / d x at (or within the convergence tolerance
        of) ``x``.
    success : bool
        The polish converged (the Gauss-Newton model predicts no further chi^2 drop above
        :data:`POLISH_CHI2_TOL`).
    nfev : int
        Residual evaluations, Jacobian columns included [-].
    """

    x: FloatArray
    fun: FloatArray
    jac: FloatArray
    success: bool
    nfev: int


def forward_jacobian(fun: Callable[[FloatArray], FloatArray], x: FloatArray, f0: FloatArray,
                     lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Forward-difference Jacobian of ``fun`` at ``x`` (steps toward the interior) [fun/x].

    Parameters
    ----------
    fun : callable
        Residual function of the parameter vector.
    x, f0 : ndarray
        Point and ``fun(x)``.
    lo, hi : ndarray
        Bounds of the parameters (a step that would leave them is taken backwards).
    """
    cols = []
    for k in range(x.size):
        h = DIFF_STEP * max(1.0, abs(float(x[k])))
        if x[k] + h > hi[k]:
            h = -h
        xk = np.array(x, dtype=float)
        xk[k] += h
        h = float(xk[k] - x[k])  # the step actually represented in floating point
        cols.append((fun(xk) - f0) / h)
    return np.column_stack(cols)


def solve_lsq(fun: Callable[[FloatArray], FloatArray], x0: FloatArray, lo: FloatArray,
              hi: FloatArray, scale: FloatArray, *, max_nfev: int) -> LsqSolution:
    """Bounded non-linear least squares: scipy's trust-region reflective search, then a
    Gauss-Newton polish to the exact minimum.

    The trust-region search alone stops short of the minimum of these fits: its
    Coleman-Li scaling against the bounds distorts the steps in the long, narrow valley
    of the strongly correlated parameters (C, t0, p10, heat scale), the trust region
    shrinks, and its ftol/xtol tests then fire (xtol is compared with the unscaled norm of
    x, which p10 in Pa dominates) while chi^2 is still ~0.1-0.2 above its minimum. That
    left the estimates ~0.2-0.5 sigma from the least-squares solution at random and made
    the spread of C and b 1.15-1.3 times the stated sigma (bench/bench_accuracy.py
    coverage). Plain Gauss-Newton steps from there converge in one or two iterations
    (the model is smooth and nearly linear over a few sigma).

    Parameters
    ----------
    fun : callable
        Residuals r(x) of equal variance [any unit].
    x0 : ndarray
        Starting point (inside the bounds).
    lo, hi : ndarray
        Bounds.
    scale : ndarray
        Typical parameter scales (``x_scale`` of the search).
    max_nfev : int
        Evaluation budget of the trust-region search [-].
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    sol = least_squares(fun, x0, bounds=(lo, hi), x_scale=scale, method="trf",
                        diff_step=DIFF_STEP, max_nfev=max_nfev)
    # (sol.jac is not always the Jacobian at sol.x: the polish computes its own)
    x, f = np.array(sol.x, dtype=float), np.asarray(sol.fun, dtype=float)
    jac = np.full((f.size, x.size), math.nan)
    nfev = int(sol.nfev) + int(sol.njev or 0) * x.size
    inner_lo = lo + 1e-12 * np.maximum(1.0, np.abs(lo))
    inner_hi = hi - 1e-12 * np.maximum(1.0, np.abs(hi))
    cost = float(f @ f)
    s2 = max(cost / max(f.size - x.size, 1), 1e-300)
    converged = False
    for _ in range(POLISH_MAX_ITER):
        jac = forward_jacobian(fun, x, f, lo, hi)
        nfev += x.size
        if not np.all(np.isfinite(jac)):
            break
        js = jac * scale
        step_s, *_ = np.linalg.lstsq(js, -f, rcond=1e-12)
        step = step_s * scale
        pred = cost - float(np.sum((f + jac @ step) ** 2))
        if pred / s2 < POLISH_CHI2_TOL:
            converged = True
            break
        for _ in range(4):  # step halving: accept only a drop of chi^2
            xn = np.clip(x + step, inner_lo, inner_hi)
            fn = np.asarray(fun(xn), dtype=float)
            nfev += 1
            cn = float(fn @ fn)
            if np.all(np.isfinite(fn)) and cn < cost:
                break
            step = 0.5 * step
        else:
            break
        x, f, cost = xn, fn, cn
    return LsqSolution(x=x, fun=f, jac=np.asarray(jac, dtype=float), success=converged,
                       nfev=nfev)


def _bins(n: int, max_points: int) -> FloatArray:
    """Bin edges (indices) that average n samples into at most max_points bins."""
    k = max(1, math.ceil(n / max_points))
    return np.arange(0, n + k, k).clip(max=n)


def fit_curve(
    t: FloatArray, p: FloatArray, settings: EstimatorSettings, *, t_start: float,
    p10: float, p_atm: float, conductance: float, fit_heat: bool | None = None,
    max_points: int = 3000, profile_heat: bool = True,
) -> CurveFit:
    """Least-squares fit of the discharge model to a recorded unload.

    Parameters
    ----------
    t, p : ndarray
        Samples [s], [Pa absolute] from the pre-step plateau to the end of the record.
    settings : EstimatorSettings
        Tank, gas and heat model (``atmosphere=None`` fits p_atm).
    t_start, p10, p_atm, conductance : float
        Starting values [s], [Pa], [Pa], [m^3/(s Pa)].
    fit_heat : bool, optional
        Fit the heat-transfer scale; default: only when the natural model is on.
    max_points : int
        The model and the data are averaged in the same bins down to this many points.
    profile_heat : bool
        Standard deviations also from a profile of the fit over the heat-transfer scale
        (two more fits), not from the Gauss-Newton covariance alone, which can under-state
        them for this non-linear, strongly correlated parameter.

    Returns
    -------
    CurveFit
        Fitted values with standard deviations.
    """
    t_abs = np.asarray(t, dtype=float)
    t_ref = float(t_abs[0])
    t = t_abs - t_ref  # relative times: absolute stamps (~1.7e9 s) ruin finite differences
    t_start = t_start - t_ref
    p = np.asarray(p, dtype=float)
    edges = _bins(t.size, max_points)
    counts = np.diff(edges)
    pb = np.add.reduceat(p, edges[:-1]) / counts
    natural = settings.heat_model == "natural"
    if fit_heat is None:
        fit_heat = natural
    fit_heat = bool(fit_heat and natural)
    fit_atm = settings.atmosphere is None
    names = ["logC", "b", "t0", "p10"] + (["p_atm"] if fit_atm else []) + (
        ["logh"] if fit_heat else [])
    x0 = [math.log(conductance), settings.critical_ratio, t_start, p10]
    lo = [math.log(1e-13), 0.0, t[0], 0.5 * p10]
    hi = [math.log(1e-5), 0.95, t[-1], 2.0 * p10]
    if fit_atm:
        x0.append(p_atm)
        lo.append(0.5 * p_atm)
        hi.append(1.5 * p_atm)
    if fit_heat:
        x0.append(0.0)
        lo.append(math.log(1e-3))
        hi.append(math.log(1e2))  # RigConfig.heat_transfer_scale allows [0, 100]
    scale = np.array([0.05, 0.05, max((t[1] - t[0]), 1e-6) * 10, 1e-3 * p10]
                     + ([1e-3 * p_atm] if fit_atm else []) + ([0.1] if fit_heat else []))

    def unpack(x: FloatArray) -> dict[str, float]:
        d = dict(zip(names, (float(v) for v in x), strict=True))
        d.setdefault("p_atm", p_atm)
        d.setdefault("logh", 0.0)
        return d

    def residual(x: FloatArray) -> FloatArray:
        d = unpack(x)
        cfg = rig_from_settings(settings, conductance=math.exp(d["logC"]), p10=d["p10"],
                                p_atm=d["p_atm"], critical_ratio=d["b"],
                                heat_scale=math.exp(d["logh"]))
        pm, _ = discharge(cfg, t, d["t0"], rtol=1e-9)
        pm = sensor_response(t, pm, cfg)
        return np.add.reduceat(pm, edges[:-1]) / counts - pb

    x0a = np.clip(np.array(x0), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    sol = solve_lsq(residual, x0a, np.array(lo), np.array(hi), scale, max_nfev=200)
    d = unpack(sol.x)
    # covariance: residuals are bin means with variance sigma^2 / count
    w = np.sqrt(counts)
    jw = sol.jac * w[:, None]
    rw = sol.fun * w
    dof = max(rw.size - len(names), 1)
    s2 = float(rw @ rw) / dof
    inflation = residual_inflation(rw)
    cov = covariance(jw, s2 * inflation)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    sd = dict(zip(names, std, strict=True))
    # The heat scale enters non-linearly and is strongly correlated with C (|rho| ~ 0.95):
    # where the likelihood is not quadratic along it, the Gauss-Newton covariance
    # under-states the spread. Profile the fit over log h at +-1.5 sigma: the rise of
    # chi^2 gives its effective sigma, the shift of the other parameters their slope along
    # the valley; the larger of the two standard deviations is kept for every parameter.
    # (On simulated natural-convection trials the profile is close to quadratic and adds
    # a few per cent; see bench/bench_accuracy.py coverage.)
    chi0 = float(rw @ rw) / s2
    for pname, limit in (("logh", 0.5),):
        if not profile_heat or pname not in names:
            continue
        ip = names.index(pname)
        sdp = float(sd[pname])
        if not (math.isfinite(sdp) and 0 < sdp < limit and np.all(np.isfinite(cov))
                and lo[ip] + 2.0 * sdp < sol.x[ip] < hi[ip] - 2.0 * sdp):
            continue
        free = [k for k in range(len(names)) if k != ip]
        lo_f, hi_f = np.array(lo)[free], np.array(hi)[free]
        delta = 1.5 * sdp
        shifts, rises = [], []
        for sign in (1.0, -1.0):
            xp = float(sol.x[ip]) + sign * delta

            def res_fixed(xf: FloatArray, xp: float = xp, ip: int = ip,
                          free: list[int] = free) -> FloatArray:
                x = np.array(sol.x, dtype=float)
                x[free] = xf
                x[ip] = xp
                return residual(x)

            sub = solve_lsq(res_fixed, np.clip(sol.x[free], lo_f + 1e-12, hi_f - 1e-12),
                            lo_f, hi_f, scale[free], max_nfev=60)
            rises.append(max(float((sub.fun * w) @ (sub.fun * w)) / s2 - chi0, 1e-12))
            shifts.append(sub.x - sol.x[free])
        sd_p = delta / math.sqrt(0.5 * (rises[0] + rises[1]))
        slope = (shifts[0] - shifts[1]) / (2.0 * delta)
        # conditional covariance of the others at fixed p, plus the valley direction
        cf = cov[np.ix_(free, free)] - np.outer(cov[free, ip], cov[ip, free]) / cov[ip, ip]
        cov_p = cf + np.outer(slope, slope) * sd_p**2
        std_p = np.sqrt(np.clip(np.diag(cov_p), 0.0, None))
        for j, k in enumerate(free):
            if names[k] == "logC":  # b keeps its own (Gauss-Newton) standard deviation
                sd[names[k]] = max(float(sd[names[k]]), float(std_p[j]))
        sd[pname] = max(sdp, sd_p)
    c = math.exp(d["logC"])
    b_std = float(sd["b"])
    b = d["b"]
    if not math.isfinite(b_std) or b_std > 0.05 or b_std == 0.0:
        b, b_std = math.nan, math.nan
    c_std = c * float(sd["logC"])
    h_std = math.exp(d["logh"]) * float(sd["logh"]) if fit_heat else math.nan
    return CurveFit(
        conductance=c, conductance_std=c_std, critical_ratio=b, critical_ratio_std=b_std,
        t_start=d["t0"] + t_ref, p10=d["p10"], p_atm=d["p_atm"], heat_scale=math.exp(d["logh"]),
        heat_scale_std=h_std, rms=math.sqrt(s2), n=int(t.size), success=bool(sol.success),
        inflation=inflation)


def fitted_tau_exp(fit: CurveFit, settings: EstimatorSettings, t_guess: float) -> float:
    """tau_exp of the fitted model: its p* crossing (eq 40 with the fitted p10) [s].

    Uses the whole recorded curve rather than the samples near p* and the start, so it is
    less noisy than the measured tau_exp (reported beside it, never instead of it).

    Parameters
    ----------
    fit : CurveFit
        Result of :func:`fit_curve`.
    settings : EstimatorSettings
        Settings of the fit.
    t_guess : float
        Expected crossing time [s] (e.g. the measured tau_exp).
    """
    if not (math.isfinite(t_guess) and t_guess > 0):
        return math.nan
    b = fit.critical_ratio if math.isfinite(fit.critical_ratio) else None
    try:
        cfg = rig_from_settings(settings, conductance=fit.conductance, p10=fit.p10,
                                p_atm=fit.p_atm, critical_ratio=b,
                                heat_scale=fit.heat_scale)
        ps = fit.p_atm + P_STAR_FRACTION * (fit.p10 - fit.p_atm)
        tc = model_crossing_time(cfg, ps, t_guess)
        if not math.isfinite(tc):
            return math.nan
        # refine on a fine grid around the first estimate (cubic interpolation error of
        # the coarse grid is ~1e-5 relative)
        tt = np.concatenate(([0.0], np.linspace(0.98 * tc, 1.02 * tc, 801)))
        pp, _ = discharge(cfg, tt, 0.0, rtol=1e-10)
        k = np.flatnonzero(pp[1:] < ps)
        if k.size == 0 or k[0] == 0:
            return tc
        j = int(k[0]) + 1
        return float(tt[j - 1] + (pp[j - 1] - ps) / (pp[j - 1] - pp[j]) * (tt[j] - tt[j - 1]))
    except ValueError:
        return math.nan


def refine_with_curve_fit(
    res: UnloadResult, t: FloatArray, p: FloatArray, settings: EstimatorSettings,
    *, noise_std: float,
) -> UnloadResult | None:
    """Final result of an unload: the crossing result refined by :func:`fit_curve`.

    Parameters
    ----------
    res : UnloadResult
        The estimate published at the p* crossing.
    t, p : ndarray
        Samples of the unload [s], [Pa absolute], plateau to end.
    settings : EstimatorSettings
        Estimator settings.
    noise_std : float
        Sample noise [Pa] (for the report).

    Returns
    -------
    UnloadResult or None
        A copy with ``final=True`` and the fitted values, or None when the fit failed.
    """
    if res.status not in ("ok", "not_choked") or not math.isfinite(res.conductance_model):
        return None
    try:
        fit = fit_curve(t, p, settings, t_start=res.t_start, p10=res.p10, p_atm=res.p_atm,
                        conductance=res.conductance_model)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return dataclasses.replace(res, final=True, extra={"curve_fit_error": str(exc)})
    c_std = fit.conductance_std
    if settings.heat_model == "natural" and not math.isfinite(fit.heat_scale_std):
        c_std = math.hypot(c_std, res.conductance_model_std)
    extra = {"curve_fit": dataclasses.asdict(fit), "noise_std": noise_std,
             "conductance_crossing_inversion": res.conductance_model}
    return dataclasses.replace(
        res, final=True, conductance_model=fit.conductance, conductance_model_std=c_std,
        t_start_model=fit.t_start, tau_exp_model=fitted_tau_exp(fit, settings, res.tau_exp),
        critical_ratio=fit.critical_ratio, critical_ratio_std=fit.critical_ratio_std,
        method=res.method + "+curve-fit", extra=extra,
        quality=res.quality if fit.success else min(res.quality, 0.5))


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
    a grid over (tau, n) with the linear pair solved exactly finds the basin, a
    least-squares fit of all four refines it, and the 1-sigma of p_inf comes from the
    Jacobian with n free, so that an unfinished recovery is extrapolated with an honest
    uncertainty.

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
    edges = _bins(u.size, max_points)
    counts = np.diff(edges)
    ub = np.add.reduceat(u, edges[:-1]) / counts
    pb = np.add.reduceat(p, edges[:-1]) / counts
    w = np.sqrt(counts)
    span = max(float(u[-1]), 1e-9)
    best = (math.inf, 0.0, 0.0, span, 1.0)
    for n in (RECOVERY_EXPONENT_PRIOR[0],):
        for tau in span * np.logspace(-1.5, 2.5, 41):
            g = _relaxation(ub, 1.0, float(tau), n)
            a = np.column_stack((w, -g * w))
            coef, *_ = np.linalg.lstsq(a, pb * w, rcond=None)
            r = pb * w - a @ coef
            sse = float(r @ r)
            if sse < best[0] and coef[1] >= 0.0:
                best = (sse, float(coef[0]), float(coef[1]), float(tau), n)
    _sse, p_inf0, d00, tau0_, n0 = best
    if not math.isfinite(_sse):  # no rise at all: start from a flat line
        p_inf0, d00 = float(np.mean(pb)), 0.0
        _sse = float(np.sum(counts * (pb - p_inf0) ** 2))
    s2_0 = max(_sse / max(pb.size - 3, 1), 1e-300)
    prior_w = math.sqrt(s2_0) / RECOVERY_EXPONENT_PRIOR[1]

    def residual(x: FloatArray) -> FloatArray:
        with np.errstate(over="ignore", invalid="ignore"):
            r = (x[0] - _relaxation(ub, x[1], math.exp(x[2]), x[3]) - pb) * w
        r = np.nan_to_num(r, nan=1e100, posinf=1e100, neginf=-1e100)
        return np.append(r, prior_w * (x[3] - RECOVERY_EXPONENT_PRIOR[0]))

    scale = max(abs(d00), float(np.std(np.diff(p))), 1e-12)
    big = 1e4 * scale + float(np.max(np.abs(pb)))
    lo = [float(np.min(pb)) - big, 0.0, math.log(1e-3 * span), RECOVERY_EXPONENTS[0]]
    hi = [float(np.max(pb)) + big, 2.0 * big, math.log(1e5 * span), RECOVERY_EXPONENTS[1]]
    x0 = np.clip([p_inf0, d00, math.log(tau0_), n0], np.array(lo) + 1e-9,
                 np.array(hi) - 1e-9)
    sol = least_squares(residual, x0, bounds=(lo, hi), method="trf", max_nfev=400,
                        x_scale=np.array([scale, scale, 0.1, 0.05]))
    dof = max(pb.size - 3, 1)
    s2 = float(sol.fun[:-1] @ sol.fun[:-1]) / dof  # per-sample variance (bins by size)
    cov = covariance(sol.jac, s2 * residual_inflation(sol.fun[:-1]))
    p_inf_std = math.sqrt(max(float(cov[0, 0]), 0.0))
    p_inf, d0, tau, n = float(sol.x[0]), float(sol.x[1]), math.exp(sol.x[2]), float(sol.x[3])
    remaining = float(_relaxation(np.array([span]), d0, tau, n)[0])
    return RecoveryFit(p_inf=p_inf, p_inf_std=p_inf_std, p_close=p_inf - d0, rise=d0,
                       tau=tau, exponent=n, remaining=remaining, rms=math.sqrt(s2),
                       n=int(u.size), success=bool(sol.success))
