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
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from pneumatic_unload.config import RigConfig
from pneumatic_unload.model import discharge, sensor_response

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


def model_crossing_time(cfg: RigConfig, p_star: float, t_guess: float) -> float:
    """Time for the model's tank pressure to fall from p10 to p_star [s].

    Parameters
    ----------
    cfg : RigConfig
        Model (valve opens at t = 0).
    p_star : float
        Threshold [Pa absolute].
    t_guess : float
        Expected crossing time [s] (sets the output grid).
    """
    horizon = 2.0 * t_guess
    for _ in range(6):
        t = np.linspace(0.0, horizon, 257)
        p, _ = discharge(cfg, t, 0.0, rtol=1e-7)
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
        horizon *= 3.0
    return math.inf


def invert_crossing(
    tau_exp: float, tau_std: float, *, p10: float, p_atm: float, p_star: float,
    settings: EstimatorSettings, c_start: float,
) -> tuple[float, float]:
    """C for which the discharge model crosses p_star at tau_exp, and its 1-sigma [m^3/(s Pa)].

    The crossing time of the model is nearly proportional to 1/C, so the fixed-point
    iteration C <- C t_model(C)/tau_exp converges in a few steps. The standard deviation
    combines the timing uncertainty and, for the natural-convection model, the uncertainty
    of the heat-transfer correlation (:data:`HEAT_CORRELATION_REL_STD`).

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
    c = c_start
    for _ in range(8):
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm)
        tm = model_crossing_time(cfg, p_star, tau_exp)
        if not math.isfinite(tm):
            return math.nan, math.nan
        c_new = c * tm / tau_exp
        done = abs(c_new / c - 1.0) < 1e-6
        c = c_new
        if done:
            break
    var = (c * tau_std / tau_exp) ** 2
    if settings.heat_model == "natural":
        cfg = rig_from_settings(settings, conductance=c, p10=p10, p_atm=p_atm,
                                heat_scale=1.0 + HEAT_CORRELATION_REL_STD)
        tm = model_crossing_time(cfg, p_star, tau_exp)
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


def _bins(n: int, max_points: int) -> FloatArray:
    """Bin edges (indices) that average n samples into at most max_points bins."""
    k = max(1, math.ceil(n / max_points))
    return np.arange(0, n + k, k).clip(max=n)


def fit_curve(
    t: FloatArray, p: FloatArray, settings: EstimatorSettings, *, t_start: float,
    p10: float, p_atm: float, conductance: float, fit_heat: bool | None = None,
    max_points: int = 3000,
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
        hi.append(math.log(1e3))
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
    sol = least_squares(residual, x0a, bounds=(lo, hi), x_scale=scale, method="trf",
                        diff_step=1e-4, max_nfev=200)
    d = unpack(sol.x)
    # covariance: residuals are bin means with variance sigma^2 / count
    w = np.sqrt(counts)
    jw = sol.jac * w[:, None]
    rw = sol.fun * w
    dof = max(rw.size - len(names), 1)
    s2 = float(rw @ rw) / dof
    try:
        cov = np.linalg.pinv(jw.T @ jw) * s2
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(len(names), np.nan)
    sd = dict(zip(names, std, strict=True))
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
        heat_scale_std=h_std, rms=math.sqrt(s2), n=int(t.size), success=bool(sol.success))


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
        critical_ratio=fit.critical_ratio, critical_ratio_std=fit.critical_ratio_std,
        method=res.method + "+curve-fit", extra=extra,
        quality=res.quality if fit.success else min(res.quality, 0.5))
