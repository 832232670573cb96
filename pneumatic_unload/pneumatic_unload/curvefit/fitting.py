# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Model-based sonic conductance from the whole record: the final curve fit.

:func:`fit_curve` fits the estimator's parametric model
(:class:`pneumatic_unload.model.parametric.ParametricModel`: the discharge of
:mod:`pneumatic_unload.model`, with wall heat transfer by the law the data choose, or
adiabatic) through the one engine (:mod:`pneumatic_unload.fit`) for C, b, the start
instant, p10 (and p_atm when it is not given, and the heat exchange when the data carry
it), with the binned likelihood (the model evaluated per bin, so the cost does not grow with
the record), and standard deviations from the Jacobian scaled by the residual and inflated
for structured residuals. The inversion at the crossing is :mod:`pneumatic_unload.model.inversion`.

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import (
    EstimatorSettings,
    wall_uncertainty,
    with_wall,
)
from pneumatic_unload.config.tank import WALL_RANGE
from pneumatic_unload.curvefit.curve_fit_result import CurveFit, CurveSpan
from pneumatic_unload.curvefit.joint_family import with_temperature
from pneumatic_unload.curvefit.law_family import (
    HOT_START_INFLATION,
    LAW_BIC_THRESHOLD,
    Family,
    best_key,
    criterion,
    criterion_unit,
)
from pneumatic_unload.curvefit.law_fit import (
    CURVE_FIT_RESOLUTION,
    UNIT_NOISE,
    curve_fit_bins,
    curve_fit_trace,
    fit_law,
    start_from,
)
from pneumatic_unload.curvefit.law_search import choose_laws
from pneumatic_unload.curvefit.offset_offer import (
    OFFSET_GAP_NOISE,
    OFFSET_GAP_Z,
    OFFSET_READING,
    keep_probe,
    offer_offset,
    offset_verdict,
    unfitted_offset_lines,
)
from pneumatic_unload.curvefit.plateau import plateau_bend, plateau_drift
from pneumatic_unload.curvefit.shape_reading import read_shapes, shape_wins
from pneumatic_unload.curvefit.subsonic_offer import (
    M_SUFFIX,
    held_lines,
    held_spread,
    split_key,
    subsonic_index_problem,
    twin_lines,
)
from pneumatic_unload.curvefit.wall_moves import law_spread, rms_moves, spread_b, wall_linear
from pneumatic_unload.fit.lsq import numerical_reproducibility
from pneumatic_unload.fit.reduced import Reducer
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.model.parametric import CHARGE_HEAT_LAWS

FloatArray = NDArray[np.float64]

#: Re-exported: the result of :func:`fit_curve`, and the trace of its likelihood.
__all__ = ["CURVE_FIT_RESOLUTION", "HOT_START_INFLATION", "CurveFit", "curve_fit_bins",
           "curve_fit_trace", "fit_curve"]

#: Laws fitted in turn by :func:`fit_curve` when the natural model is on (the data choose).
CURVE_FIT_LAWS: tuple[str, ...] = ("natural", "fixed", "density", "natural+turbulent")
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
    temperature: tuple[FloatArray, FloatArray] | None = None,
) -> CurveFit:
    """Least-squares fit of the discharge model to a recorded unload, with the heat law
    chosen by the data.

    With the natural model on, every law of ``laws`` (default :data:`CURVE_FIT_LAWS`: the
    natural-convection correlation with a fitted scale, and a constant hA with a fitted
    thermal time constant) is fitted; the lowest BIC wins. Every law's weight
    exp(-dBIC/2) times the square of its C's distance from the winner's enters the variance
    of C (the model-form term, never hidden: :mod:`pneumatic_unload.selection`).

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
    temperature : tuple of ndarray, optional
        A logged gas temperature, instants [s, the clock of t] and values [K]: fitted
        jointly with the pressure (:func:`_with_temperature`) where the span holds enough
        readings; the result's ``gas_temperature`` says how (empty when not used).

    Returns
    -------
    CurveFit
        The chosen law's fitted values with standard deviations.
    """
    natural = settings.heat_model == "natural"
    if fit_heat is None:
        fit_heat = natural
    tried = (laws or CURVE_FIT_LAWS) if (natural and fit_heat) else ("natural",)
    if settings.charge and laws is None:  # a charge's laws: CHARGE_HEAT_LAWS's reason
        tried = tuple(law for law in tried if law in CHARGE_HEAT_LAWS)
    if reduced is not None:
        bins = reduced.bins()
        trace = Trace.from_stats(bins, UNIT_NOISE)  # the same for every law
        last = float(bins.t_last[-1])
        span = CurveSpan(reduced.t_ref, reduced.t_ref + last, last, bins.n, reduced.dt)
        settled = float(bins.y_sum[-1] / bins.count[-1])
        settled_se = settled_sd = math.nan
    else:
        t = np.asarray(t, dtype=float)
        tr = t - t[0]
        trace = curve_fit_trace(tr, np.asarray(p, dtype=float), t_start - float(t[0]))
        dt = float(np.median(np.diff(tr[:100_001]))) if t.size > 1 else 1.0
        span = CurveSpan(float(t[0]), float(t[-1]), float(tr[-1]), int(t.size), dt)
        tail = np.asarray(p, dtype=float)[tr >= 0.98 * tr[-1]]
        settled = float(np.mean(tail))
        settled_sd = float(np.std(tail))
        settled_se = settled_sd / math.sqrt(tail.size) if tail.size > 1 else math.nan
    common = dict(t_start=t_start, p10=p10, p_atm=p_atm, conductance=conductance,
                  fit_heat=bool(fit_heat and natural), trace=trace, hold=hold)
    drifts, bends = (plateau_drift(tr, np.asarray(p, dtype=float), t_start - float(t[0])),
                     plateau_bend(tr, np.asarray(p, dtype=float), t_start - float(t[0]))) \
        if reduced is None else (0.0, 0.0)
    logged = temperature is not None
    fam, best = choose_laws(Family(span, settings, common, profile_heat,
                               plateau_drift_z=drifts, t10_logged=logged,
                               plateau_bend_z=bends), tried)
    offset_why = ""
    offset_reading: dict[str, Any] = {}
    if settings.end_pressure is not None:
        # p_atm given: a record that settles away from it (a transducer's zero offset)
        # has the offset fitted, the family fitted again with it, where the criterion
        # clearly prefers it (by LAW_BIC_THRESHOLD; an offset it does not determine is not
        # offered); else it is said not to be
        gap = settled - settings.end_pressure
        clear = abs(gap) > max(OFFSET_GAP_Z * settled_se, OFFSET_GAP_NOISE * settled_sd)
        probed: dict[str, Any] = {}
        offset_why = offer_offset(fam, best, gap, clear, probed)
        if offset_why is None or clear:
            alt = choose_laws(Family(span, settings, common, profile_heat, offset=True,
                                 plateau_drift_z=drifts, t10_logged=logged,
                                 plateau_bend_z=bends), tried)
            if keep_probe(alt[0], probed):
                alt = alt[0], best_key(alt[0].fits, span.n)
            if offset_why is not None and offset_verdict(
                    fam, fam.fits[best], alt[0].fits[alt[1]], gap) is None:
                # the end clearly away from p_atm, the chosen law's probe refusing it: the
                # whole family with the offset decides, its hot starts with it (a gas 30 K
                # warm and a -3 kPa zero: each alone gains little, the warm gas's fit
                # without the offset went to the 600 K bound, C +1.8 %)
                offset_why = None
        if offset_why is None:
            fam, best = alt
            cf0 = fam.fits[best][0]
            offset_why = (f"fitted: the record settles {cf0.pressure_offset:+.0f} +- "
                          f"{cf0.pressure_offset_std:.0f} Pa from the given p_atm")
        elif clear and temperature is None:
            # the end clearly away from p_atm and the offset not preferred: the family's
            # best with it is a reading of the record all the same, counted by the
            # criterion in the model-form spread as the laws are (a +0.7 kPa zero taken up
            # as m 0.833 +- 0.004 and a warm wall, where the constant hA with the offset
            # read m 0.689 for 0.692, 6 worse by the criterion)
            offset_reading = {OFFSET_READING + alt[1]: alt[0].fits[alt[1]]}
            r0 = alt[0].fits[alt[1]][0]
            offset_why += (f"; with the offset ({r0.pressure_offset:+.0f} Pa) the family's "
                           f"best ({alt[1]}) reads C {r0.conductance:.4g}, b "
                           f"{r0.critical_ratio:.3f}, m {r0.subsonic_index:.3f}: in the model "
                           "form's spread")
    temp_why: dict[str, Any] = {}
    if temperature is not None:
        fam, best, trace, temp_why = with_temperature(fam, best, temperature, tried)
        t10 = fam.fits[best][0].gas_temperature.get("t10", math.nan)
        if math.isfinite(t10):  # the wall's lines about the fitted T10
            settings = dataclasses.replace(settings, initial_temperature=t10)
    fits, raw = fam.fits, fam.raw  # raw: each fit's FitResult and model (the wall term)
    bic = criterion(fits, span.n)
    cf = fits[best][0]
    if best.endswith(M_SUFFIX):
        m_c, m_b, m_u, m_why = 0.0, 0.0, cf.subsonic_index_std, (
            f"m fitted: {cf.subsonic_index:.3f} +- {cf.subsonic_index_std:.3f}")
    else:
        free_key = best + M_SUFFIX
        if raw.get(free_key, {}).get("fit") is not None:
            m_c, m_b, m_u, m_why = held_lines(raw[free_key], raw[free_key]["fit"],
                                              free_key in fits)
        else:  # not worth a fit: the first-order twin's slopes and m
            m_c, m_b, m_u, m_why = twin_lines(fam.twin(best, "m"))
    # the heat laws' model form among the laws with m as the chosen one's (m held: the
    # subsonic index line carries m's part)
    same = {k: f for k, f in fits.items() if k.endswith(M_SUFFIX) == best.endswith(M_SUFFIX)}
    held = {k: f for k, f in fits.items() if not k.endswith(M_SUFFIX)}
    ref_law = best if len(same) > 1 else min(held, key=lambda k: bic[k])
    pool = same if len(same) > 1 else held
    spread_bic = bic
    # the flow curve's shape beyond the ISO law: the ISO (b, m) nearest the curve fitted
    # with q free (every law with m) or as a pair in series (the chosen law), readings as
    # the others (a pair in series read b 0.347 by the discharge's own weighting where its
    # curve's is 0.210)
    shape, shape_why = read_shapes(fam, best) if temperature is None else ({}, "")
    readings = {**fam.unclaimed, **offset_reading, **shape}
    if readings:
        # a warm gas the record neither claims (within a room's spread, its plateau
        # straight) nor rules out: its hot start's C is a reading of the record all the
        # same, counted by the criterion as the laws are (a 5-8 K warm gas in a large tank
        # reads C 2-5 % high, z to 2.6, when left out); so is a zero offset's
        pool = {**pool, **readings}
        spread_bic = criterion({**fits, **readings}, span.n)
    with_m = {k: f for k, f in readings.items() if k.endswith(M_SUFFIX)}
    own = frozenset(shape)  # the shape's readings: their own variance counts
    mf = law_spread(pool, spread_bic, ref_law, "conductance", empty=0.0, own=own)
    mf_b = spread_b(pool, spread_bic, ref_law, own=own)
    if best.endswith(M_SUFFIX):
        mf_m = law_spread({**same, **with_m}, spread_bic, best, "subsonic_index", own=own)
    elif best + M_SUFFIX in fits:  # m held, the laws fitted with m too: their spread of m
        mf_m = law_spread({**{k: f for k, f in fits.items() if k.endswith(M_SUFFIX)},
                           **with_m}, spread_bic, best + M_SUFFIX, "subsonic_index",
                          own=own)
        m_c, m_b, m_u = held_spread(m_c, m_b, m_u, mf_m)
    else:
        mf_m = math.nan
    if ref_law != best:  # relative spreads carried over to the chosen law's values
        mf *= cf.conductance / fits[ref_law][0].conductance
    if (won := shape_wins(shape, spread_bic)) is not None:
        # the curve with q free clearly better: the ISO (b, m) nearest it reported, the
        # spreads kept about the discharge's own ISO fit: the move is their model-form
        # line (q is one shape among many; a pair in series, 46 L: b 0.265 and m 0.547 by
        # the discharge's weighting, 0.253 and 0.570 from the curve, for 0.250 and 0.575,
        # with the curve's own sigma 0.002 and 0.003 covering m at z -2.1 only)
        got = shape[won][0]
        cf = dataclasses.replace(cf, critical_ratio=got.critical_ratio,
                                 critical_ratio_std=got.critical_ratio_std,
                                 critical_ratio_source="", subsonic_index_fitted=True,
                                 subsonic_index=got.subsonic_index)
        m_c, m_b, m_u = 0.0, 0.0, got.subsonic_index_std
        m_why = (f"m fitted: the ISO law nearest the flow curve of the reading '{won}' "
                 f"({shape_why})")
    table = {law: {"conductance": f[0].conductance, "critical_ratio": f[0].critical_ratio,
                   "bic": bic[law], "chi2": f[1] / criterion_unit(fits),
                   **({"subsonic_index": f[0].subsonic_index,
                       "subsonic_index_std": f[0].subsonic_index_std}
                      if law.endswith(M_SUFFIX) else {}),
                   **({"wall_temperature": f[0].wall_temperature,
                       "wall_temperature_std": f[0].wall_temperature_std}
                      if "+wall" in law else {})} for law, f in fits.items()}
    out = dataclasses.replace(
        cf, conductance_std=math.hypot(cf.conductance_std, mf), model_form_std=mf,
        model_form_std_b=mf_b, laws=table,
        heat_law=best.removesuffix(M_SUFFIX) if natural else "none",
        not_offered=_refusals(fam), subsonic_std=m_c, subsonic_std_b=m_b,
        subsonic_index_std=m_u, subsonic_source=m_why, model_form_std_m=mf_m,
        offset_source=offset_why, shape_source=shape_why,
        gas_temperature=cf.gas_temperature or temp_why)
    if settings.end_pressure is not None and not settings.charge and not fam.offset:
        out = dataclasses.replace(out, unfitted_offset=unfitted_offset_lines(fam, best))
    if raw.get(best):  # the fit's own numerical reproducibility (another machine's bits)
        rep = numerical_reproducibility(trace.residual(raw[best]["model"]),
                                        raw[best]["result"], fade=bool(raw[best]["fade"]))
        out = dataclasses.replace(out, conductance_reproducibility=rep.get("C", math.nan),
                                  critical_ratio_reproducibility=rep.get("b", 0.0))
    law_b, wall_b, fit_m = split_key(best)
    if natural and not wall_b:
        # the wall assumed = T10: its uncertainty from the record (the walls of the hot
        # starts that fit about as well as the chosen law are evidence of a gap), C's and
        # b's from the chosen law refitted with the wall moved; a given wall: b's only (C's
        # wall line is the crossing's)
        # (a hot start that fitted T10 beside a wall at the room's: its gap from T10)
        u, why = wall_uncertainty(settings, hot_walls=[
            f[0].wall_temperature + settings.initial_temperature
            - f[0].gas_temperature.get("t10", settings.initial_temperature)
            for k, f in fits.items()
            if "+wall" in k and bic[k] - bic[best] < LAW_BIC_THRESHOLD])
        if u == 0.0:
            wall_std = wall_std_b = wall_std_m = 0.0
        elif (u <= WALL_LINEAR_MAX or settings.wall_temperature is not None) \
                and raw.get(best):
            wall_std, wall_std_b, wall_std_m = wall_linear(trace, raw[best], settings, u,
                                                           law=law_b)
            if not math.isfinite(wall_std) and settings.wall_temperature is None:
                # not linear (or not computable) to first order: the two refits
                wall_std, wall_std_b, wall_std_m = _wall_refit(
                    trace, fits[best][0], settings, u, law=law_b, fit_heat=bool(fit_heat),
                    hold=hold, span=span, fit_m=fit_m)
        else:
            wall_std, wall_std_b, wall_std_m = _wall_refit(
                trace, fits[best][0], settings, u, law=law_b, fit_heat=bool(fit_heat),
                hold=hold, span=span, fit_m=fit_m)
        out = dataclasses.replace(out, wall_std_b=wall_std_b,
                                  wall_std_m=wall_std_m if fit_m else math.nan)
        if settings.wall_temperature is None:
            out = dataclasses.replace(out, wall_uncertainty=u, wall_source=why,
                                      wall_std=wall_std)
    return out


def _refusals(fam: Family) -> dict[str, str]:
    """``fam.not_offered`` with the hot starts fitted with T10 logged and refused without a
    reason there (the wall within 3 of its uncertainty of T10 [K] and the residuals not
    white, with m held or free, or m free and not determined): every fit made and not
    offered says why. Named here, once the choice is made, not where the family drops
    them: ``offset_offer.keep_probe`` reads a key in ``not_offered`` as a refusal, and
    could then drop a probe's fit it is there to keep (draw 48 of the temperature draws is
    of that kind)."""
    out = dict(fam.not_offered)
    for key, kept in fam.raw.items() if fam.t10_logged else ():
        got = kept.get("fit")
        if "+wall" in key and key not in fam.fits and key not in out and got is not None:
            gap = got.wall_temperature - got.gas_temperature.get(
                "t10", fam.settings.initial_temperature)
            # (with m free, one whose m the record does not determine says so)
            m_why = subsonic_index_problem(got) if key.endswith(M_SUFFIX) else None
            out[key] = (f"not claimed: the wall {gap:+.1f} K from the logged T10 (within 3 "
                        f"of its uncertainty) and " + (
                            m_why or "no structure of the laws without it made white"))
    return out


def _wall_refit(trace: Trace, fit: CurveFit, settings: EstimatorSettings, u: float, *,
                law: str, fit_heat: bool, hold: tuple[str, ...],
                span: CurveSpan, fit_m: bool = False) -> tuple[float, float, float]:
    """C's, b's and m's standard uncertainties ([m^3/(s Pa)], [-], [-]) from an assumed wall
    temperature of standard uncertainty u [K]: ``law`` refitted (from ``fit``, the chosen
    law's own fit: a shape reading's reported b and m are not a fit's) with the wall
    at T10 + u and T10 - u, the root mean square of the two moves (the fitted heat exchange
    takes up part of a move, which the crossing's inversion with the correlation held does
    not, and may take it up unevenly: the response is not linear over u of 10-20 K); NaN
    when a refit fails (b's: also when b is not determined; m's: also with m held)."""
    out = []
    for sign in (1.0, -1.0):
        wall = float(np.clip(settings.wall + sign * u, *WALL_RANGE))
        moved = with_wall(settings, wall)
        start = start_from(fit, span.t_ref, heat_scale=fit.heat_scale,
                            tau_heat=fit.tau_heat, heat_exponent=fit.heat_exponent,
                            heat_turbulent=fit.heat_turbulent)
        try:
            again = fit_law(span, moved, t_start=fit.t_start, p10=fit.p10, p_atm=fit.p_atm,
                             conductance=fit.conductance, fit_heat=fit_heat,
                             profile_heat=False, law=law, start=start, max_nfev=60,
                             trace=trace, hold=hold, fit_m=fit_m,
                             fit_offset=math.isfinite(fit.pressure_offset_std))[0]
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return math.nan, math.nan, math.nan
        out.append((again.conductance, again.critical_ratio,
                    again.subsonic_index if fit_m else math.nan))
    c_std = rms_moves([c - fit.conductance for c, _b, _m in out]) \
        if all(math.isfinite(c) for c, _b, _m in out) else math.nan
    return (c_std, rms_moves([b - fit.critical_ratio for _c, b, _m in out]),
            rms_moves([m - fit.subsonic_index for _c, _b, m in out]))
