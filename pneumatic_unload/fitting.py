"""Model-based sonic conductance from the whole record: the final curve fit.

:func:`fit_curve` fits the estimator's parametric model
(:class:`pneumatic_unload.model.parametric.ParametricModel`: the discharge of
:mod:`pneumatic_unload.model`, with wall heat transfer by the law the data choose, or
adiabatic) through the one engine (:mod:`pneumatic_unload.fit`) for C, b, the start
instant, p10 (and p_atm when it is not given, and the heat exchange when the data carry
it), with the binned likelihood (the model evaluated per bin, so the cost does not grow with
the record), and standard deviations from the Jacobian scaled by the residual and inflated
for structured residuals. The inversion at the crossing is :mod:`pneumatic_unload.inversion`.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import (
    AMBIENT_TEMPERATURE,
    WALL_ASSUMED_STD,
    EstimatorSettings,
    wall_uncertainty,
)
from pneumatic_unload.config.tank import WALL_RANGE
from pneumatic_unload.curve_fit_result import CurveFit, CurveSpan
from pneumatic_unload.fit.likelihood import make_bins
from pneumatic_unload.fit.lsq import numerical_reproducibility
from pneumatic_unload.fit.noise import NoiseModel, ljung_box
from pneumatic_unload.fit.profile import valley_std
from pneumatic_unload.fit.reduced import Reducer
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.fit.uncertainty import (
    WHITENESS_P,
    residual_inflation,
    structure_inflation,
)
from pneumatic_unload.heat_law_offer import (
    DENSITY_LAW_MAX_EXPONENT_SD,
    TURBULENT_MAX_LOG_SD,
    density_law_problem,
    next_law_start,
    turbulent_law_problem,
)
from pneumatic_unload.inversion import estimator_model
from pneumatic_unload.model.effects import Start
from pneumatic_unload.physics import tau_exp_eq38
from pneumatic_unload.wall_moves import law_spread, spread_b, wall_linear

FloatArray = NDArray[np.float64]

#: The heat-scale profile of :func:`fit_curve` runs only when sigma(log h) is at least this
#: [-] (a narrower likelihood is quadratic over +-1.5 sigma).
PROFILE_MIN_SD = 0.1
#: Relative bin width of the curve fit's likelihood [-] (see
#: :func:`pneumatic_unload.fit.likelihood.make_bins`).
CURVE_FIT_RESOLUTION = 0.01
#: Re-exported: the result of :func:`fit_curve`.
__all__ = ["CurveFit", "fit_curve"]


#: The curve fit's noise model: unit (the residual variance is estimated afterwards).
UNIT_NOISE = NoiseModel(sigma=1.0, rho=0.0, n=0, source="unit")


def curve_fit_bins(t: FloatArray, t_start: float) -> NDArray[np.int64]:
    """Bin edges (sample indices) of the curve fit's likelihood for samples t [s]."""
    return make_bins(np.asarray(t, dtype=float), t_start, resolution=CURVE_FIT_RESOLUTION)


def curve_fit_trace(t: FloatArray, p: FloatArray, t_start: float) -> Trace:
    """The curve fit's :class:`Trace` (unit noise: the residual variance is estimated
    afterwards) of samples at relative times t [s] (t[0] = 0), p [Pa], the step near
    t_start [s, relative]."""
    return Trace(t, p, NoiseModel(sigma=1.0, rho=0.0, n=int(t.size), source="unit"),
                 t_start, edges=curve_fit_bins(t, t_start))


#: Laws fitted in turn by :func:`fit_curve` when the natural model is on (the data choose).
CURVE_FIT_LAWS: tuple[str, ...] = ("natural", "fixed", "density", "natural+turbulent")
#: Residual inflation above which, with the wall assumed at T10, the hot-start variants
#: (wall temperature fitted) are tried too [-] (they are also tried when T10 is more than
#: sqrt(3) WALL_ASSUMED_STD from a room's AMBIENT_TEMPERATURE).
HOT_START_INFLATION = 1.5
#: Residual inflation above which a law's fit is repeated with plain (log) stepping and
#: the lower chi^2 kept [-]: the fade stepping reaches the minimum in about half the
#: evaluations, but from a start far off its path can end in a false minimum with
#: structured residuals (Newton-cooling trial "settled 36": inflation 99, t_open 0.1 s
#: early, C -20.5 %; the plain stepping from the same start: C +0.01 %).
FADE_RETRY_INFLATION = 3.0
#: Delta-BIC below which another law counts as fitting about as well [-].
LAW_BIC_THRESHOLD = 10.0
#: Largest wall-temperature uncertainty [K] whose effect on C is taken from the fit's
#: linear response (two model evaluations); above it the chosen law is refitted with the
#: wall moved (the response is not linear over 10-20 K). Measured at 2-5 K: see
#: test_wall_budget.
WALL_LINEAR_MAX = 5.0

def fit_curve(
    t: FloatArray, p: FloatArray, settings: EstimatorSettings, *, t_start: float,
    p10: float, p_atm: float, conductance: float, fit_heat: bool | None = None,
    profile_heat: bool = True, laws: tuple[str, ...] | None = None,
    hold: tuple[str, ...] = (), reduced: Reducer | None = None,
) -> CurveFit:
    """Least-squares fit of the discharge model to a recorded unload, with the heat law
    chosen by the data.

    With the natural model on, every law of ``laws`` (default :data:`CURVE_FIT_LAWS`: the
    natural-convection correlation with a fitted scale, and a constant hA with a fitted
    thermal time constant) is fitted; the lowest BIC wins. A law within
    :data:`LAW_BIC_THRESHOLD` of it fits about as well: its weight exp(-dBIC/2) times the
    square of its C's distance from the winner's enters the variance of C (the model-form
    term, never hidden).

    Parameters
    ----------
    t, p : ndarray
        Samples [s], [Pa absolute] from the pre-step plateau to the end of the record.
    settings : EstimatorSettings
        Tank, gas and heat model (``atmosphere=None`` fits p_atm).
    t_start, p10, p_atm, conductance : float
        Starting values [s], [Pa], [Pa], [m^3/(s Pa)].
    fit_heat : bool, optional
        Fit the heat transfer; default: only when the natural model is on (False holds the
        natural correlation as published).
    profile_heat : bool
        Standard deviations also from a profile of the fit over the heat-transfer scale
        where its likelihood is not quadratic.
    laws : tuple of str, optional
        Heat laws to try (see above).
    hold : tuple of str
        Values held at what was given instead of fitted: 't_open' (the valve opening at
        t_start: a record that begins at the opening) and/or 'p10' (a given initial
        pressure).
    reduced : Reducer, optional
        The samples already reduced to bins (an unload too long to hold, see
        :mod:`pneumatic_unload.fit.reduced`), used instead of t and p (None).

    Returns
    -------
    CurveFit
        The chosen law's fitted values with standard deviations.
    """
    natural = settings.heat_model == "natural"
    if fit_heat is None:
        fit_heat = natural
    tried = (laws or CURVE_FIT_LAWS) if (natural and fit_heat) else ("natural",)
    fits: dict[str, tuple[CurveFit, float, int]] = {}
    start: dict[str, float] | None = None
    if reduced is not None:
        bins = reduced.bins()
        trace = Trace.from_stats(bins, UNIT_NOISE)  # the same for every law
        last = float(bins.t_last[-1])
        span = CurveSpan(reduced.t_ref, reduced.t_ref + last, last, bins.n, reduced.dt)
    else:
        t = np.asarray(t, dtype=float)
        tr = t - t[0]
        trace = curve_fit_trace(tr, np.asarray(p, dtype=float), t_start - float(t[0]))
        dt = float(np.median(np.diff(tr[:100_001]))) if t.size > 1 else 1.0
        span = CurveSpan(float(t[0]), float(t[-1]), float(tr[-1]), int(t.size), dt)
    not_offered: dict[str, str] = {}
    raw: dict[str, dict[str, Any]] = {}  # each law's FitResult and model (the wall term)
    for law in tried:
        law_start, nfev = start, (200 if not fits else 32)
        if law == "density":
            why = density_law_problem(fits.get("fixed", (None,))[0])
            if why is not None:
                not_offered[law] = why
                continue
            # from the constant-hA fit (n = 0), the exponent moved towards convection's
            fx = fits["fixed"][0]
            law_start = _start_from(fx, span.t_ref, tau_heat=fx.tau_heat,
                                    heat_exponent=0.3)
            nfev = 80
        if law == "natural+turbulent":
            why = turbulent_law_problem(fits.get("natural", (None,))[0], settings,
                                        span.t_last)
            if why is not None:
                not_offered[law] = why
                continue
            nt = fits["natural"][0]
            law_start = _start_from(nt, span.t_ref, heat_scale=nt.heat_scale,
                                    heat_turbulent=1.0)
            nfev = 80
        fits[law] = _fit_law(span, settings, t_start=t_start, p10=p10, p_atm=p_atm,
                             conductance=conductance, fit_heat=bool(fit_heat and natural),
                             profile_heat=profile_heat, law=law, start=law_start,
                             max_nfev=nfev, trace=trace, hold=hold,
                             keep=raw.setdefault(law, {}))
        if law == "density":
            sd = fits[law][0].heat_exponent_std
            if not (math.isfinite(sd) and sd <= DENSITY_LAW_MAX_EXPONENT_SD):
                del fits[law]
                not_offered[law] = (f"the record does not determine the exponent n "
                                    f"(1-sigma {sd:.2g} > {DENSITY_LAW_MAX_EXPONENT_SD:g})")
                continue
        if law == "natural+turbulent":
            tf = fits[law][0]
            sd = tf.heat_turbulent_std / tf.heat_turbulent if tf.heat_turbulent > 0 \
                else math.nan
            if not (math.isfinite(sd) and sd <= TURBULENT_MAX_LOG_SD):
                del fits[law]
                not_offered[law] = (f"the record does not determine the turbulent branch "
                                    f"(relative 1-sigma {sd:.2g} > {TURBULENT_MAX_LOG_SD:g})")
                continue
        first = fits[law][0]
        if start is None and first.inflation < 2.0 and math.isfinite(first.conductance):
            # the next law starts from this fit when it is close (white residuals);
            # otherwise from the neutral values, with a second start screened
            start = next_law_start(first, settings, span.t_ref)
    if min(f[0].inflation for f in fits.values()) > 2.0:
        # structured residuals under every law: a basin may have been missed (e.g. a
        # nearly isothermal discharge fitted from the weak-exchange side); explore strong
        # and weak heat exchange from the neutral values and keep what fits better
        for law in list(fits):
            kept: dict[str, Any] = {}
            again = _fit_law(span, settings, t_start=t_start, p10=p10, p_atm=p_atm,
                             conductance=conductance, fit_heat=bool(fit_heat and natural),
                             profile_heat=profile_heat, law=law, explore=True,
                             trace=trace, hold=hold, keep=kept)
            if again[1] < fits[law][1]:
                fits[law] = again
                raw[law] = kept
    if (natural and fit_heat and settings.wall_temperature is None
            and (min(f[0].inflation for f in fits.values()) > HOT_START_INFLATION
                 or abs(settings.initial_temperature - AMBIENT_TEMPERATURE)
                 > math.sqrt(3.0) * WALL_ASSUMED_STD)):
        # the wall assumed at T10 and every law leaves structure, or T10 far from a room's
        # temperature (a gas warmed or cooled by the charge: the density law can take up a
        # wall away from T10 with white residuals and C several % off): a hot (or cold)
        # start is a model of its own, the wall fitted from each one-parameter law's fit (a
        # wall and an exponent are not told apart on one discharge); the criterion decides
        least_inflation = min(f[0].inflation for f in fits.values())
        for law in [k for k in ("natural", "fixed") if k in fits]:
            base = fits[law][0]
            if not math.isfinite(base.conductance):
                continue
            start_w = {"C": base.conductance, "t_open": base.t_start - span.t_ref,
                       "p10": base.p10, "heat_scale": base.heat_scale,
                       "tau_heat": base.tau_heat, "b": base.critical_ratio}
            hot = _fit_law(
                span, settings, t_start=t_start, p10=p10, p_atm=p_atm,
                conductance=conductance, fit_heat=True, profile_heat=False, law=law,
                start={k: v for k, v in start_w.items() if math.isfinite(v)},
                max_nfev=120, trace=trace, hold=hold, fit_wall=True,
                keep=raw.setdefault(f"{law}+wall", {}))
            # a hot start is a claim about the rig: a wall clearly away from T10 (3 of the
            # temperature's uncertainties, at least 3 K) makes it, or one nearer that turns
            # the structure every law with the wall at T10 leaves into white residuals; else
            # it absorbs other model error (HydDown: a wall 2.4 K off moved C by +0.25 %)
            gap = abs(hot[0].wall_temperature - settings.initial_temperature)
            if gap > 3.0 * max(settings.temperature_uncertainty, 1.0) or \
                    least_inflation > HOT_START_INFLATION >= hot[0].inflation:
                fits[f"{law}+wall"] = hot
    # information criterion on residuals normalised by the best law's residual variance
    # (inflated when structured: correlated residuals carry less information)
    lowest = min(fits, key=lambda k: fits[k][1])
    ref = fits[lowest][0]
    unit = max(ref.rms**2 * ref.inflation, 1e-300)  # [Pa^2] per residual
    log_n = math.log(max(span.n, 2))
    bic = {law: chi2 / unit + k * log_n for law, (_cf, chi2, k) in fits.items()}
    best = min(bic, key=lambda k: bic[k])
    cf = fits[best][0]
    mf = law_spread(fits, bic, best, LAW_BIC_THRESHOLD, "conductance", empty=0.0)
    mf_b = spread_b(fits, bic, best, LAW_BIC_THRESHOLD)
    table = {law: {"conductance": f[0].conductance, "critical_ratio": f[0].critical_ratio,
                   "bic": bic[law], "chi2": f[1] / unit,
                   **({"wall_temperature": f[0].wall_temperature,
                       "wall_temperature_std": f[0].wall_temperature_std}
                      if law.endswith("+wall") else {})} for law, f in fits.items()}
    out = dataclasses.replace(
        cf, conductance_std=math.hypot(cf.conductance_std, mf), model_form_std=mf,
        model_form_std_b=mf_b, laws=table, heat_law=best if natural else "none",
        not_offered=not_offered)
    if raw.get(best):  # the fit's own numerical reproducibility (another machine's bits)
        rep = numerical_reproducibility(trace.residual(raw[best]["model"]),
                                        raw[best]["result"], fade=bool(raw[best]["fade"]))
        out = dataclasses.replace(out, conductance_reproducibility=rep.get("C", math.nan),
                                  critical_ratio_reproducibility=rep.get("b", 0.0))
    if natural and not best.endswith("+wall"):
        # the wall assumed = T10: its uncertainty from the record (the walls of the hot
        # starts that fit about as well as the chosen law are evidence of a gap), C's and
        # b's from the chosen law refitted with the wall moved; a given wall: b's only (C's
        # wall line is the crossing's)
        u, why = wall_uncertainty(settings, hot_walls=[
            f[0].wall_temperature for k, f in fits.items()
            if k.endswith("+wall") and bic[k] - bic[best] < LAW_BIC_THRESHOLD])
        if u == 0.0:
            wall_std = wall_std_b = 0.0
        elif (u <= WALL_LINEAR_MAX or settings.wall_temperature is not None) \
                and raw.get(best):
            wall_std, wall_std_b = wall_linear(trace, raw[best], settings, u, law=best)
            if not math.isfinite(wall_std) and settings.wall_temperature is None:
                # not linear (or not computable) to first order: the two refits
                wall_std, wall_std_b = _wall_refit(trace, out, settings, u, law=best,
                                                   fit_heat=bool(fit_heat), hold=hold,
                                                   span=span)
        else:
            wall_std, wall_std_b = _wall_refit(trace, out, settings, u, law=best,
                                               fit_heat=bool(fit_heat), hold=hold, span=span)
        out = dataclasses.replace(out, wall_std_b=wall_std_b)
        if settings.wall_temperature is None:
            out = dataclasses.replace(out, wall_uncertainty=u, wall_source=why,
                                      wall_std=wall_std)
    return out


def _wall_refit(trace: Trace, fit: CurveFit, settings: EstimatorSettings, u: float, *,
                law: str, fit_heat: bool, hold: tuple[str, ...],
                span: CurveSpan) -> tuple[float, float]:
    """C's and b's standard uncertainties ([m^3/(s Pa)], [-]) from an assumed wall
    temperature of standard uncertainty u [K]: ``law`` refitted (from ``fit``) with the wall
    at T10 + u and T10 - u, the root mean square of the two moves (the fitted heat exchange
    takes up part of a move, which the crossing's inversion with the correlation held does
    not, and may take it up unevenly: the response is not linear over u of 10-20 K); NaN
    when a refit fails (b's: also when b is not determined)."""
    out = []
    for sign in (1.0, -1.0):
        wall = float(np.clip(settings.wall + sign * u, *WALL_RANGE))
        moved = dataclasses.replace(settings, wall_temperature=wall)
        start = _start_from(fit, span.t_ref, heat_scale=fit.heat_scale,
                            tau_heat=fit.tau_heat, heat_exponent=fit.heat_exponent,
                            heat_turbulent=fit.heat_turbulent)
        try:
            again = _fit_law(span, moved, t_start=fit.t_start, p10=fit.p10, p_atm=fit.p_atm,
                             conductance=fit.conductance, fit_heat=fit_heat,
                             profile_heat=False, law=law, start=start, max_nfev=60,
                             trace=trace, hold=hold)[0]
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return math.nan, math.nan
        out.append((again.conductance, again.critical_ratio))
    c_std = math.sqrt(sum((c - fit.conductance) ** 2 for c, _b in out) / 2.0) \
        if all(math.isfinite(c) for c, _b in out) else math.nan
    b_std = math.sqrt(sum((b - fit.critical_ratio) ** 2 for _c, b in out) / 2.0)
    return c_std, b_std


def _start_from(fit: CurveFit, t0: float, **heat: float) -> dict[str, float]:
    """Starting values [SI] of another law's fit from ``fit`` (times relative to t0 [s]):
    its C, opening, p10, b and p_atm, and the heat parameters given; non-finite ones left
    out."""
    v = {"C": fit.conductance, "t_open": fit.t_start - t0, "p10": fit.p10,
         "b": fit.critical_ratio, "p_atm": fit.p_atm, **heat}
    return {k: x for k, x in v.items() if math.isfinite(x)}


def _fit_law(
    span: CurveSpan, settings: EstimatorSettings, *, t_start: float,
    p10: float, p_atm: float, conductance: float, fit_heat: bool | None = None,
    profile_heat: bool = True, law: str = "natural", start: dict[str, float] | None = None,
    max_nfev: int = 200, explore: bool = False, trace: Trace,
    hold: tuple[str, ...] = (), fit_wall: bool = False,
    keep: dict[str, Any] | None = None,
) -> tuple[CurveFit, float, int]:
    """One law's fit for :func:`fit_curve`; returns (fit, chi^2 [Pa^2: residuals are bin
    sums over sqrt(count)], free parameters [-]).

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
    keep : dict, optional
        Receives the fit's :class:`~pneumatic_unload.fit.lsq.FitResult` ('result') and
        model ('model'), for :func:`~pneumatic_unload.wall_moves.wall_linear`.
    """
    t_ref = span.t_ref  # relative times: absolute stamps (~1.7e9 s) ruin finite differences
    t_start = t_start - t_ref
    natural = settings.heat_model == "natural"
    dt = span.dt
    tau = tau_exp_eq38(p10, p_atm, settings.volume, conductance, settings.initial_temperature,
                       settings.gas)
    neutral = Start(conductance=conductance, critical_ratio=settings.critical_ratio,
                  t_open=float(np.clip(t_start, 0.0, span.duration)), p10=p10, p_atm=p_atm,
                  tau=tau, dt=dt, t_first=0.0, t_last=span.duration)
    model = estimator_model(settings, neutral, heat_law=law, fit_wall=fit_wall)
    fixed = {"heat_scale": 1.0} if natural and not fit_heat else {}
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
        starts = ([{"heat_scale": 30.0}, {"heat_scale": 0.1}] if law.startswith("natural") else
                  [{"tau_heat": 0.05 * tau}, {"tau_heat": 20.0 * tau}])
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
    # residuals are bin sums / sqrt(count): their variance is the per-sample variance
    s2 = fit.chi2 / fit.dof
    inflation = residual_inflation(fit.fun)
    whiteness_p = ljung_box(fit.fun)[1]
    if whiteness_p < WHITENESS_P:  # structure beyond lag 1 too
        inflation = max(inflation, structure_inflation(fit.fun))
    cov = fit.covariance(s2 * inflation)
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
    if not math.isfinite(b_std) or b_std > 0.05 or b_std == 0.0:
        b, b_std = math.nan, math.nan
    h = v.get("heat_scale", 1.0)
    h_std = float(std["heat_scale"]) if "heat_scale" in free else math.nan
    cf = CurveFit(
        conductance=c, conductance_std=float(std["C"]), critical_ratio=b,
        critical_ratio_std=b_std, t_start=v["t_open"] + t_ref, p10=v["p10"],
        p_atm=v.get("p_atm", p_atm) if settings.atmosphere is None else p_atm,
        heat_scale=h, heat_scale_std=h_std, rms=math.sqrt(s2), n=span.n,
        success=bool(fit.success), inflation=inflation,
        heat_law=f"{law}+wall" if fit_wall else law,
        wall_temperature=v.get("t_wall", math.nan),
        wall_temperature_std=float(std["t_wall"]) if "t_wall" in free else math.nan,
        tau_heat=v.get("tau_heat", math.nan),
        tau_heat_std=float(std["tau_heat"]) if "tau_heat" in free else math.nan,
        heat_exponent=v.get("heat_exponent", math.nan),
        heat_exponent_std=float(std["heat_exponent"]) if "heat_exponent" in free
        else math.nan,
        whiteness_p=whiteness_p, heat_turbulent=v.get("heat_turbulent", 1.0),
        heat_turbulent_std=float(std["heat_turbulent"]) if "heat_turbulent" in free
        else math.nan)
    return cf, fit.chi2, fit.k
