# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One heat law's fit of the final curve fit (:func:`fit_law`), for
:func:`pneumatic_unload.curvefit.fitting.fit_curve`, which compares the laws.

The estimator's parametric model (:class:`pneumatic_unload.model.parametric.ParametricModel`)
with one heat law (its wall temperature and the subsonic index m fitted or held) is fitted
through the one engine (:mod:`pneumatic_unload.fit`) to the binned likelihood of the record
(:func:`curve_fit_trace`), with standard deviations from the Jacobian scaled by the residual
and inflated for structured residuals, and a profile over the heat scale where its
likelihood is not quadratic.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.curvefit.curve_fit_result import CurveFit, CurveSpan
from pneumatic_unload.fit.likelihood import make_bins
from pneumatic_unload.fit.noise import NoiseModel, ljung_box
from pneumatic_unload.fit.profile import valley_std
from pneumatic_unload.fit.trace import TemperatureChannel, Trace
from pneumatic_unload.fit.uncertainty import (
    WHITENESS_P,
    misfit_ratio,
    residual_inflation,
    structure_inflation,
)
from pneumatic_unload.model.effects import Start, exchange_extremes
from pneumatic_unload.model.inversion import estimator_model
from pneumatic_unload.model.parametric import ISO_ELLIPSE_EXPONENT, SUBSONIC_INDEX_START
from pneumatic_unload.physics import tau_exp_eq38

FloatArray = NDArray[np.float64]

#: The heat-scale profile of :func:`fit_curve` runs only when sigma(log h) is at least this
#: [-] (a narrower likelihood is quadratic over +-1.5 sigma).
PROFILE_MIN_SD = 0.1
#: Relative bin width of the curve fit's likelihood [-] (see
#: :func:`pneumatic_unload.fit.likelihood.make_bins`).
CURVE_FIT_RESOLUTION = 0.01

#: The curve fit's noise model: unit (the residual variance is estimated afterwards).
UNIT_NOISE = NoiseModel(sigma=1.0, rho=0.0, n=0, source="unit")


#: b within this share of its range from a bound is on the bound [-] (a hot start is not
#: claimed with m's help where it puts b there: ``law_family``).
B_BOUND_TOL = 1e-6

#: b is reported where the fit's 1-sigma of it is at most this [-]; a wider one is no
#: measurement of b (its range is 0-1), and the fit's value is given with the reason.
B_STD_MAX = 0.05


def curve_fit_bins(t: FloatArray, t_start: float) -> NDArray[np.int64]:
    """Bin edges (sample indices) of the curve fit's likelihood for samples t [s]."""
    return make_bins(np.asarray(t, dtype=float), t_start, resolution=CURVE_FIT_RESOLUTION)


def curve_fit_trace(t: FloatArray, p: FloatArray, t_start: float) -> Trace:
    """The curve fit's :class:`Trace` (unit noise: the residual variance is estimated
    afterwards) of samples at relative times t [s] (t[0] = 0), p [Pa], the step near
    t_start [s, relative]."""
    return Trace(t, p, NoiseModel(sigma=1.0, rho=0.0, n=int(t.size), source="unit"),
                 t_start, edges=curve_fit_bins(t, t_start))


#: The critical ratios b screened (with m 0.3 and 0.7) where m is freed [-].
M_START_B = (0.1, 0.3, 0.55)
#: Residual inflation above which a law's fit is repeated with plain (log) stepping and
#: the lower chi^2 kept [-]: the fade stepping reaches the minimum in about half the
#: evaluations, but from a start far off its path can end in a false minimum with
#: structured residuals (Newton-cooling trial "settled 36": inflation 99, t_open 0.1 s
#: early, C -20.5 %; the plain stepping from the same start: C +0.01 %).
FADE_RETRY_INFLATION = 3.0

def heat_of(fit: CurveFit) -> dict[str, float]:
    """The heat-exchange values of a fit [SI] (start of another fit of the same law)."""
    return {"heat_scale": fit.heat_scale, "tau_heat": fit.tau_heat,
            "heat_exponent": fit.heat_exponent, "heat_turbulent": fit.heat_turbulent,
            "t_wall": fit.wall_temperature}


def start_from(fit: CurveFit, t0: float, **heat: float) -> dict[str, float]:
    """Starting values [SI] of another law's fit from ``fit`` (times relative to t0 [s]):
    its C, opening, p10, b and p_atm, and the heat parameters given; non-finite ones left
    out."""
    v = {"C": fit.conductance, "t_open": fit.t_start - t0, "p10": fit.p10,
         "b": fit.critical_ratio, "p_atm": fit.p_atm, "m": fit.subsonic_index,
         "t10": fit.gas_temperature.get("t10", math.nan),
         "tau_thermo": fit.gas_temperature.get("sensor_time_constant", math.nan),
         "t_offset": fit.gas_temperature.get("sensor_offset", math.nan), **heat}
    return {k: x for k, x in v.items() if math.isfinite(x)}


def fit_law(
    span: CurveSpan, settings: EstimatorSettings, *, t_start: float,
    p10: float, p_atm: float, conductance: float, fit_heat: bool | None = None,
    profile_heat: bool = True, law: str = "natural", start: dict[str, float] | None = None,
    max_nfev: int = 200, explore: bool = False, trace: Trace,
    hold: tuple[str, ...] = (), fit_wall: bool = False, fit_m: bool = False,
    fit_offset: bool = False, fit_t10: bool = False, shape: str = "iso",
    keep: dict[str, Any] | None = None,
) -> tuple[CurveFit, float, int]:
    """One law's fit for :func:`~pneumatic_unload.curvefit.fitting.fit_curve`; returns (fit,
    chi^2 [Pa^2: residuals are bin sums over sqrt(count)], free parameters [-]).

    Parameters
    ----------
    span : CurveSpan
        Where the samples lie (pre-step plateau to the end of the record).
    settings : EstimatorSettings
        Tank, gas and heat model (``atmosphere=None`` fits p_atm).
    t_start, p10, p_atm, conductance : float
        Starting values [s], [Pa], [Pa], [m^3/(s Pa)].
    fit_heat : bool
        Fit the heat exchange (False holds the natural correlation as published).
    profile_heat : bool
        Standard deviations also from a profile of the fit over the heat-transfer scale
        (two more fits), not from the Gauss-Newton covariance alone, which can under-state
        them for this non-linear, strongly correlated parameter.

    law : str
        Heat-transfer law ('natural', 'fixed' or 'density').
    start : dict, optional
        Starting values [SI] (e.g. another law's fit); without it the fixed law also
        screens a slow-exchange start.
    max_nfev : int
        Evaluation budget [-] (a second law that has not converged within a few iterations
        from the first law's fit is not the better law).
    explore : bool
        Screen starts of strong and weak heat exchange too.
    trace : Trace
        :func:`curve_fit_trace` of the samples (shared by the laws of one fit).
    hold : tuple of str
        See :func:`fit_curve`.
    fit_wall : bool
        Fit the wall temperature too (hot-start variant; starts screened 10 and 30 K below
        T10 and, with a constant hA, a strong exchange from 10 K below and 5 K above).
    fit_offset : bool
        Fit the transducer's zero offset too (a reading = pressure + offset; p_atm given).
    fit_m : bool
        Fit the subsonic index m too (else held at 0.5).
    fit_t10 : bool
        Fit T10 too (a hot start whose T10 was not measured: the wall as in ``settings``).
    shape : str
        The flow curve: 'iso' (ISO 6358-1), 'q' (the exponent q of the subsonic branch's
        ellipse fitted too) or 'series' (two ISO elements in series, their second's b2, m2
        and C2/C1 fitted too); see :mod:`pneumatic_unload.curvefit.shape_reading`.
    keep : dict, optional
        Receives the fit's :class:`~pneumatic_unload.fit.lsq.FitResult` ('result') and
        model ('model'), for :func:`~pneumatic_unload.curvefit.wall_moves.wall_linear`.
    """
    t_ref = span.t_ref  # relative times: absolute stamps (~1.7e9 s) ruin finite differences
    t_start = t_start - t_ref
    natural = settings.heat_model == "natural"
    dt = span.dt
    tau = tau_exp_eq38(p_atm, p10, settings.volume, conductance,
                       settings.supply_gas_temperature, settings.gas) if settings.charge \
        else tau_exp_eq38(p10, p_atm, settings.volume, conductance,
                          settings.initial_temperature, settings.gas)  # supply upstream
    neutral = Start(conductance=conductance, critical_ratio=settings.critical_ratio,
                  t_open=float(np.clip(t_start, 0.0, span.duration)), p10=p10, p_atm=p_atm,
                  tau=tau, dt=dt, t_first=0.0, t_last=span.duration)
    ch = trace.channel
    model = estimator_model(settings, neutral, heat_law=law, fit_wall=fit_wall, fit_m=fit_m,
                            fit_offset=fit_offset, thermometer=ch is not None,
                            fit_t10=fit_t10, shape=shape,
                            thermometer_offset=ch is not None and ch.offset)
    fixed = {"heat_scale": 1.0} if natural and not fit_heat else {}
    if ch is not None and ch.lag is not None:
        fixed["tau_thermo"] = ch.lag
    if "t_open" in hold:
        fixed["t_open"] = float(t_start)
    if "p10" in hold:
        fixed["p10"] = float(p10)
    starts = [{"tau_heat": 5.0 * tau}] if law != "natural" and start is None else None
    if fit_wall:
        t10 = settings.initial_temperature
        starts = [{"t_wall": t10 - 10.0}, {"t_wall": t10 - 30.0}] + ([] if law == "natural" else [
            {"t_wall": t10 + d, "tau_heat": 0.1 * tau} for d in (-10.0, 5.0)])  # strong
    if explore and natural and fit_heat:
        starts = exchange_extremes(law, tau)
    if fit_m and (start or {}).get("m", SUBSONIC_INDEX_START) == SUBSONIC_INDEX_START:
        # m freed from a fit with m held: b and m trade along a curved valley (a flow never
        # choked: b 0.23, m 0.30 for 0.10, 0.35), so the search starts screen its far ends
        starts = (starts or []) + [{"b": b0, "m": m0} for b0 in M_START_B for m0 in (0.3, 0.7)]
    if start is not None:
        lo_t, hi_t = 0.0, math.inf
        if "tau_heat" in model.parameters:
            lo_t, hi_t = model.parameters["tau_heat"].lo, model.parameters["tau_heat"].hi
        # a time constant inside its bounds (one at the upper bound, no exchange, stays)
        start = {k: (float(np.clip(v, 1.001 * lo_t, 0.999 * hi_t)) if k == "tau_heat"
                     and v < hi_t else v) for k, v in start.items() if math.isfinite(v)}
    # the heat exchange stepped along hA (fade): a law whose exchange the record does not
    # show walks to none in one or two steps, not a factor e per step along its log
    fit = trace.fit(model, fixed=fixed, start=start, starts=starts, screen_nfev=9,
                    max_nfev=max_nfev, fade=True)
    plain = None
    if residual_inflation(fit.fun) > FADE_RETRY_INFLATION:
        # structured residuals: a false minimum of the fade path, or a model that does not
        # fit; the plain stepping decides (never a worse chi^2)
        plain = trace.fit(model, fixed=fixed, start=start, starts=starts, screen_nfev=9,
                          max_nfev=max_nfev, fade=False)
        if plain.chi2 < fit.chi2:
            fit = plain
    if keep is not None:
        keep.update(result=fit, model=model, fade=fit is not plain)
    v = fit.values
    # residuals are bin sums / sqrt(count): their variance is the per-sample variance (a
    # temperature channel's weighted residuals have the same by its weight)
    s2 = fit.chi2 / fit.dof
    r_p = fit.fun if ch is None else fit.fun[:fit.fun.size - ch.n]  # the pressure's
    inflation = residual_inflation(r_p)
    whiteness_p = ljung_box(r_p)[1]
    if whiteness_p < WHITENESS_P:  # structure beyond lag 1 too
        inflation = max(inflation, structure_inflation(r_p))
    cov = fit.covariance(s2 * inflation)
    if keep is not None:
        keep["s2"] = s2 * inflation
    free = list(fit.params.free)
    sd_x = {k: math.sqrt(cov[i, i]) if cov[i, i] >= 0 else math.nan
            for i, k in enumerate(free)}
    sd_log_h = sd_x.get("heat_scale", math.nan) * fit.params["heat_scale"].scale \
        if "heat_scale" in free else math.nan
    if profile_heat and np.all(np.isfinite(cov)) and PROFILE_MIN_SD <= sd_log_h < 0.5:
        # the heat scale enters non-linearly and is strongly correlated with C
        # (|rho| ~ 0.95): combine the conditional covariance of the others with the valley
        # found by profiling it at +-1.5 sigma; keep the larger sigma of C. Below
        # PROFILE_MIN_SD the likelihood is quadratic over that span (measured: the profile
        # changed sigma(C) by < 0.5 %), and the two extra fits are skipped.
        ip = free.index("heat_scale")
        prof = valley_std(trace, model, fit, "heat_scale", cov, s2)
        if prof is not None:
            sd_p, slope = prof
            others = [k for k in range(len(free)) if k != ip]
            cf = cov[np.ix_(others, others)] - np.outer(cov[others, ip], cov[ip, others]) \
                / cov[ip, ip]
            cov_p = cf + np.outer(slope, slope) * sd_p**2
            j = others.index(free.index("C"))
            sd_x["C"] = max(sd_x["C"], math.sqrt(max(cov_p[j, j], 0.0)))
            sd_x["heat_scale"] = max(sd_x["heat_scale"], sd_p)
    std = {k: fit.params.value_std(k, v[k], sd_x[k]) for k in free}
    c = v["C"]
    b, b_std = v["b"], float(std["b"])
    m, m_std = v.get("m", SUBSONIC_INDEX_START), float(std.get("m", math.nan))
    pb = fit.params["b"]
    on_bound = min(b - pb.lo, pb.hi - b) <= B_BOUND_TOL * (pb.hi - pb.lo)
    b_why = ""
    if not math.isfinite(b_std) or b_std > B_STD_MAX or b_std == 0.0:
        # (m may be determined without b: a flow never choked)
        cause = ("m fitted beside it, the two trade" if fit_m else
                 "the flow hardly choked, or the subsonic tail is short or noisy")
        b_why = (f"not determined: the fit's {b:.3f} +- {b_std:.3f} (1-sigma above "
                 f"{B_STD_MAX:g}: {cause})" if math.isfinite(b_std) and b_std > 0.0 else
                 f"not determined: the fit's {b:.3f} has no 1-sigma (the record "
                 "does not bound it)")
        b, b_std = math.nan, math.nan
    h = v.get("heat_scale", 1.0)
    h_std = float(std["heat_scale"]) if "heat_scale" in free else math.nan
    cf = CurveFit(
        conductance=c, conductance_std=float(std["C"]), critical_ratio=b,
        critical_ratio_std=b_std, critical_ratio_on_bound=bool(on_bound),
        critical_ratio_source=b_why, misfit=misfit_ratio(r_p),
        t_start=v["t_open"] + t_ref, p10=v["p10"],
        p_atm=v.get("p_atm", p_atm) if settings.end_pressure is None else p_atm,
        heat_scale=h, heat_scale_std=h_std, rms=math.sqrt(s2), n=span.n,
        success=bool(fit.success), inflation=inflation,
        heat_law=f"{law}+wall" if fit_wall else law,
        wall_temperature=v.get("t_wall", settings.wall if fit_t10 else math.nan),
        wall_temperature_std=float(std["t_wall"]) if "t_wall" in free else math.nan,
        tau_heat=v.get("tau_heat", math.nan),
        tau_heat_std=float(std["tau_heat"]) if "tau_heat" in free else math.nan,
        heat_exponent=v.get("heat_exponent", math.nan),
        heat_exponent_std=float(std["heat_exponent"]) if "heat_exponent" in free
        else math.nan,
        whiteness_p=whiteness_p, heat_turbulent=v.get("heat_turbulent", 1.0),
        heat_turbulent_std=float(std["heat_turbulent"]) if "heat_turbulent" in free
        else math.nan, subsonic_index=m, subsonic_index_std=m_std, subsonic_index_fitted=fit_m,
        ellipse_exponent=v.get("q", ISO_ELLIPSE_EXPONENT),
        ellipse_exponent_std=float(std["q"]) if "q" in free else math.nan,
        pressure_offset=v.get("offset", 0.0),
        pressure_offset_std=float(std["offset"]) if "offset" in free else math.nan,
        gas_temperature=channel_summary(ch, fit.fun, v, std) if ch is not None else
        {"t10": v["t10"], "t10_std": float(std["t10"])} if "t10" in free else {})
    if ch is not None:  # the pressure's residual RMS (the temperature's is in K)
        cf = dataclasses.replace(cf, rms=math.sqrt(float(np.sum(r_p * r_p)) / max(
            r_p.size - fit.k, 1)))
    return cf, fit.chi2, fit.k


def channel_summary(ch: TemperatureChannel, fun: FloatArray, v: dict[str, float],
                    std: dict[str, float]) -> dict[str, float]:
    """A fit's temperature channel in SI units (the :class:`CurveFit` field
    ``gas_temperature``): T10, the thermometer's time constant and offset with their
    1-sigma [K], [s], [K] (the offset 0 +- 0 when held), the RMS of fitted minus measured
    readings [K], readings and weight [-], [Pa/K]."""
    r_t = fun[fun.size - ch.n:] / ch.weight
    return {"t10": v["t10"], "t10_std": float(std.get("t10", math.nan)),
            "sensor_time_constant": v["tau_thermo"],
            "sensor_time_constant_std": float(std.get("tau_thermo", math.nan)),
            "sensor_offset": float(v.get("t_offset", 0.0)),
            "sensor_offset_std": float(std.get("t_offset", math.nan)) if ch.offset else 0.0,
            "rms": float(np.sqrt(np.mean(r_t * r_t))), "samples": float(ch.temp.size),
            "weight": ch.weight}
