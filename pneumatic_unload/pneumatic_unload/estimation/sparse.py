# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Records that begin at the valve opening: sparse, irregular, without a plateau.

Labs publish discharges as they were logged or digitised: a 1 Hz logger started with the
valve, fifteen points read off a plotted curve. Such a record has no pre-step plateau to
detect the start on, so the start is given (``EstimatorSettings.start_time`` [s], the
opening in the record's clock) and p10 is the first sample at that instant or given
(``initial_pressure`` [Pa absolute], with ``initial_pressure_std``). p_atm must be given:
the record need not end on a plateau.

* The p* crossing is interpolated between the two samples that bracket it, linearly in
  log(p - p_atm) (exact for an exponential approach to p_atm, and for the isentropic
  discharge to within the curvature of log p over one interval). Its error is taken as
  the difference from linear interpolation in p (the two bracket the truth for a convex
  curve), and stated.
* eq 39, the isentropic and the model inversion then follow as for a detected start.
* The curve fit uses every point with the opening and p10 held where they were given or
  read; p10's uncertainty is a line of the budget (stated: type B; read off the first
  sample: its noise, the fit's residual RMS, type A). The fit's own sigma comes from the
  residual variance of the points themselves. Below :data:`FEW_POINTS` points, and
  without a logged gas temperature to pin it, the heat exchange is not fitted (the
  published correlation, with its 30 % uncertainty, as the crossing inversion does: fitted
  on 12-20 points it traded against C, errors up to 9 %), and the spread between the fit
  and the crossing inversion is a model-form line.
* A charge (``direction`` 'charge') is the same with the supply for p_atm: given, or the
  mean of the record's final plateau (:func:`supply_level`); the crossing's C by
  :mod:`~pneumatic_unload.estimation.charge_crossing`.

SI units: s, Pa absolute, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload import physics
from pneumatic_unload.charge import charge_conductance_adiabatic, charge_p_star
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.crossing import HEAT_NOT_SEEN, crossing_estimate, plan_crossing
from pneumatic_unload.estimation.refine import refine_with_curve_fit
from pneumatic_unload.estimation.types import FloatArray, UnloadResult, end_fields
from pneumatic_unload.estimation.vetting import vet
from pneumatic_unload.uncertainty.budget import MODEL_FORM_TERM, BudgetTerm, with_terms

#: Fewest samples from the opening on [-].
MIN_POINTS = 10
#: Below this many points the fit-vs-inversion spread is a line of the budget [-].
FEW_POINTS = 50
#: The budget line of a heat law held on few points [-].
HEAT_HELD = "model form (heat law held, not fitted)"
#: Default standard uncertainty of a given initial pressure, relative [-].
P10_REL_DEFAULT = 0.001
#: The record has settled (the unload ends) at the first sample after the p* crossing that
#: closes a run of this many consecutive samples within :data:`SETTLE_FRACTION` of
#: (p10 - p_atm) from p_atm [-]; later samples are not analysed (offline and live alike).
SETTLE_POINTS = 10
#: Half-width of the settled band about p_atm, relative to p10 - p_atm [-].
SETTLE_FRACTION = 0.005


def start_tolerance(t_open: float) -> float:
    """How far a sample may lie from the start time ``t_open`` [s] and still be the sample
    at the opening [s]: 1 ns plus the rounding of an absolute clock held in seconds (a bag's
    stamps near 1.7e9 s: 2e-7 s), not a share of the clock's value."""
    return 1e-9 + 1e-15 * abs(t_open)


def settle_scan(p: np.ndarray, band: float, p_atm: float, run: int = 0
                ) -> tuple[int | None, int]:
    """The settle rule over samples p [Pa absolute, finite] that follow ``run``
    consecutive samples already within ``band`` [Pa] of p_atm [Pa]: (index into p of the
    sample that closes :data:`SETTLE_POINTS` consecutive samples within the band, or None;
    the run at p's end) [-]. One scan for the record at once (:func:`settle_index`) and
    for the samples as they come (a live start-time estimator carries the run)."""
    w = np.abs(np.asarray(p, dtype=float) - p_atm) <= band
    if w.size == 0:
        return None, run
    pos = np.arange(w.size)
    last_out = np.maximum.accumulate(np.where(w, -1, pos))  # last sample outside, -1: none
    runs = pos - last_out + np.where(last_out < 0, run, 0)
    hit = np.flatnonzero(runs >= SETTLE_POINTS)
    return (int(hit[0]) if hit.size else None), int(runs[-1])


def settle_index(p: np.ndarray, k: int, p10: float, p_atm: float) -> int | None:
    """Index of the sample where the record settles: the first after the crossing sample
    ``k`` that closes :data:`SETTLE_POINTS` consecutive samples within
    :data:`SETTLE_FRACTION` (p10 - p_atm) of p_atm (p [Pa absolute], finite); None when it
    does not."""
    hit, _run = settle_scan(np.asarray(p[k + 1:], dtype=float),
                            SETTLE_FRACTION * abs(p10 - p_atm), p_atm)
    return None if hit is None else k + 1 + hit


def initial_pressure(ts: np.ndarray, ps: np.ndarray, s: EstimatorSettings
                     ) -> tuple[float, float, str]:
    """p10 of a record that begins at the opening ``s.start_time`` (samples from it on: ts
    [s], ps [Pa absolute]): given (``initial_pressure``, with its standard uncertainty) or
    the sample at the start time (uncertainty NaN: the fit's residual RMS later); with where
    it came from ([Pa], [Pa], text).

    Raises
    ------
    EstimationError
        No sample at the start time and no initial pressure given.
    """
    t_open = float(s.start_time if s.start_time is not None else math.nan)
    eps = start_tolerance(t_open)
    if s.initial_pressure is not None:
        p10 = float(s.initial_pressure)
        return (p10, s.initial_pressure_std if s.initial_pressure_std is not None
                else P10_REL_DEFAULT * p10, "given (initial_pressure)")
    if ts.size and abs(ts[0] - t_open) <= eps:
        return float(ps[0]), math.nan, "the sample at the start time"
    first = f"{ts[0]:g} s" if ts.size else "none"
    raise EstimationError(f"no sample at the start time {t_open:g} s (the first is at "
                          f"{first}): give the initial pressure (--initial-pressure)")


#: A charge's supply from the final plateau: the trailing samples within this fraction of
#: the rise from the last one [-] ...
PLATEAU_BAND = 0.01
#: ... at least this many of them [-].
PLATEAU_POINTS = 3


def supply_level(ts: np.ndarray, ps: np.ndarray, p10: float, s: EstimatorSettings
                 ) -> tuple[float, float, str]:
    """A charge's supply pressure p_s [Pa absolute], its standard uncertainty [Pa] and
    where it comes from: given (``supply_pressure``), or the mean of the record's final
    plateau (the trailing samples ts [s], ps [Pa absolute] within :data:`PLATEAU_BAND` of
    the rise from the last one, whose straight line moves by less than half that band
    over them: a record still rising is no plateau; its standard error, type A).

    Raises
    ------
    EstimationError
        No supply given and no final plateau of :data:`PLATEAU_POINTS` samples."""
    if s.supply_pressure is not None:
        return float(s.supply_pressure), s.end_uncertainty, "given (supply_pressure)"
    last = float(ps[-1])
    band = PLATEAU_BAND * abs(last - p10)
    off = np.flatnonzero(np.abs(ps - last) > band)
    first = int(off[-1]) + 1 if off.size else 0
    tail, tt = ps[first:], ts[first:]
    moves = abs(float(np.polyfit(tt - tt[0], tail, 1)[0]) * float(tt[-1] - tt[0])) \
        if tail.size >= PLATEAU_POINTS else math.inf
    if not moves < 0.5 * band:
        raise EstimationError(
            f"the record does not end on a plateau ({tail.size} sample(s) within "
            f"{100 * PLATEAU_BAND:g} % of the rise of the last"
            + (f", rising {moves:.3g} Pa over them" if math.isfinite(moves) else "")
            + f"; need {PLATEAU_POINTS}, flat): give the supply pressure "
            "(--supply-pressure PA)")
    std = float(np.std(tail, ddof=1) / math.sqrt(tail.size))
    return float(np.mean(tail)), std, f"the final plateau ({tail.size} samples)"


def interpolated_crossing(t: np.ndarray, p: np.ndarray, p_star: float, p_atm: float
                          ) -> tuple[float, float, int]:
    """Instant where the samples (t [s], p [Pa]) first fall to p_star [Pa], interpolated
    linearly in log(p - p_atm) between the bracketing samples; with its interpolation error
    [s] (against linear interpolation in p) and the index of the first sample at or below.
    With p_atm above p_star (a charge's end level, the supply) the samples rise to p_star,
    interpolated in log(p_atm - p).

    Raises
    ------
    EstimationError
        The record never falls to p*, or starts below it.
    """
    rising = p_atm > p_star  # a charge: p_atm is the end level, the supply
    sign = -1.0 if rising else 1.0
    below = np.flatnonzero(sign * p <= sign * p_star)
    if below.size == 0:
        extreme = float(np.max(p) if rising else np.min(p))
        raise EstimationError(
            f"the record never {'rises' if rising else 'falls'} to p* = {p_star:.0f} Pa "
            f"({'highest' if rising else 'lowest'} {extreme:.0f} Pa): record longer, or "
            f"check {'the supply' if rising else 'p_atm'}")
    k = int(below[0])
    if k == 0:
        raise EstimationError(f"the first sample ({p[0]:.0f} Pa) is already at or "
                              f"{'above' if rising else 'below'} p* = {p_star:.0f} Pa: "
                              "check start_time and initial_pressure")
    t0, t1, p0, p1 = float(t[k - 1]), float(t[k]), float(p[k - 1]), float(p[k])
    lin = t0 + (t1 - t0) * (p0 - p_star) / (p0 - p1) if p0 != p1 else t1
    y0, y1, ys = (math.log(max(sign * (x - p_atm), 1e-9)) for x in (p0, p1, p_star))
    log = t0 + (t1 - t0) * (y0 - ys) / (y0 - y1) if y0 != y1 else lin
    return log, abs(log - lin), k


def analyze_from_start(t: ArrayLike, p: ArrayLike, settings: EstimatorSettings, *,
                       temperature: tuple[FloatArray, FloatArray] | None = None
                       ) -> list[UnloadResult]:
    """The unload of a record that begins at the given opening ``settings.start_time``.

    Parameters
    ----------
    t : array_like
        Sample instants [s], increasing (uneven spacing is fine).
    p : array_like
        Pressures [Pa absolute] (or a signal converted by signal_gain/signal_offset).
    settings : EstimatorSettings
        With ``start_time``, ``atmosphere`` and the tank; ``initial_pressure`` when the
        record has no sample at the opening.

    Returns
    -------
    list of UnloadResult
        The crossing result, then the final curve-fit result (``final=True``) when it
        succeeds: as :func:`~pneumatic_unload.estimation.analyze` returns them.

    Raises
    ------
    EstimationError
        What is missing or wrong, and what to pass instead.
    """
    s = settings
    if s.start_time is None:
        raise EstimationError("analyze_from_start needs settings.start_time [s]")
    if s.direction == "both":
        raise EstimationError("a record that begins at the opening holds one step: give its "
                              "direction (--direction charge or discharge), not 'both'")
    if s.atmosphere is None and not s.charge:
        raise EstimationError("a record analysed from a given start time needs the "
                              "atmosphere (--atmosphere): it need not end on a plateau")
    t = np.asarray(t, dtype=float).ravel()
    sig = np.asarray(p, dtype=float).ravel()
    if t.shape != sig.shape:
        raise EstimationError(f"t and p differ in length: {t.size} vs {sig.size}")
    pa = s.signal_offset + s.signal_gain * sig
    ok = np.isfinite(t) & np.isfinite(pa)
    t, pa = t[ok], pa[ok]
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise EstimationError("time stamps must increase strictly")
    t_open = float(s.start_time)
    eps = start_tolerance(t_open)
    keep = t >= t_open - eps
    ts, ps = t[keep], pa[keep]
    if ts.size < MIN_POINTS:
        raise EstimationError(f"{ts.size} sample(s) from the start time {t_open:g} s on; "
                              f"need at least {MIN_POINTS}")
    p10, p10_std, p10_note = initial_pressure(ts, ps, s)
    extra_note: dict[str, object] = {}
    if s.charge:  # p_atm: the end level, the supply's
        p_atm, supply_std, where = supply_level(ts, ps, p10, s)
        extra_note = {"supply_source": where, "supply_pressure_std": supply_std}
        if not p_atm > p10:
            raise EstimationError(
                f"the supply ({p_atm:.0f} Pa, {where}) is not above p10 ({p10:.0f} Pa): "
                "nothing flows into the tank (a supply below the tank, or a tank already "
                "at the supply)")
        p_star = charge_p_star(p10, p_atm)
    else:
        p_atm = float(s.atmosphere)  # type: ignore[arg-type]
        if not p10 > p_atm:
            raise EstimationError(f"p10 ({p10:.0f} Pa) is not above p_atm ({p_atm:.0f} "
                                  "Pa): gauge readings? (--gauge)")
        p_star = physics.p_star(p10, p_atm)
    if s.initial_pressure is not None and not (abs(ts[0] - t_open) <= eps):
        ts, ps = np.concatenate(([t_open], ts)), np.concatenate(([p10], ps))
    t_cross, interp_err, k = interpolated_crossing(ts, ps, p_star, p_atm)
    end = settle_index(ps, k, p10, p_atm)
    if end is not None:  # the unload ends where the record settles (the live node's rule)
        ts, ps = ts[:end + 1], ps[:end + 1]
    tau = t_cross - t_open
    tau_std = max(interp_err, 1e-9 * tau)
    res = _crossing(s, tau=tau, tau_std=tau_std, p10=p10, p_atm=p_atm, p_star=p_star,
                    t_open=t_open, t_cross=t_cross, n=ts.size, k=k, interp_err=interp_err)
    res.extra.update(extra_note)
    out = [res]
    if s.curve_fit and math.isfinite(res.conductance_model):
        terms: tuple[BudgetTerm, ...] = ()
        if math.isfinite(p10_std) and p10_std > 0:
            terms = (_p10_term(s, ts, ps, p10, p10_std, p_atm, t_open, res),)
        # the opening and p10 are held where they were given or read; p10's uncertainty
        # (stated, or the sample's noise: the fit's residual RMS) is a line of the budget
        # few points hold the heat law, unless a logged gas temperature pins it
        few = ts.size < FEW_POINTS and temperature is None
        final = refine_with_curve_fit(res, ts, ps, s, noise_std=math.nan,
                                      hold=("t_open", "p10"), extra_terms=terms,
                                      fit_heat=None if not few else False,
                                      temperature=temperature)
        if ts.size < FEW_POINTS and not few and final is not None and "rms" not in (
                final.extra.get("curve_fit", {}).get("gas_temperature") or {}):
            # the log followed by no heat law pins nothing: the few points hold the law
            # (the log stays the evidence of the budget's departure line)
            few = True
            final = refine_with_curve_fit(res, ts, ps, s, noise_std=math.nan,
                                          hold=("t_open", "p10"), extra_terms=terms,
                                          fit_heat=False, temperature=temperature)
        if final is not None:
            extra = {**final.extra, "p10_source": p10_note}
            rms = float(extra.get("curve_fit", {}).get("rms", math.nan))
            std = final.conductance_model_std
            more = []
            if not terms and math.isfinite(rms) and rms > 0:
                more.append(_p10_term(s, ts, ps, p10, rms, p_atm, t_open, res))
            if few:
                # few points leave the fitted heat exchange and C loosely tied: the fit and
                # the inversion with the published correlation are both plausible, and
                # their difference enters as a model-form line (measured: without it the
                # fit's sigma missed the truth by 3.6 sigma on 12 points)
                more.append(BudgetTerm(
                    "model form (fit vs crossing inversion)", "model", math.nan, math.nan,
                    "", abs(final.conductance_model - res.conductance_model),
                    f"{ts.size} points"))
                # and the heat law is held (the correlation as published, not fitted): the
                # crossing's line for a heat exchange not seen (uniform between none and
                # twice the correlation's) stays, scaled to the fit's C
                seen = [x for x in res.extra.get("budget", {}).get("terms", ())
                        if x["name"] == MODEL_FORM_TERM and x["std"]]
                if seen:
                    more.append(BudgetTerm(
                        HEAT_HELD, "model", math.nan, math.nan, "",
                        seen[0]["std"] * final.conductance_model / res.conductance_model,
                        f"{ts.size} points: {HEAT_NOT_SEEN}"))
            if more and "budget" in extra:
                extra["budget"] = with_terms(extra["budget"], more)
                std = extra["budget"]["combined_std"]
            out.append(dataclasses.replace(final, extra=extra, conductance_model_std=std))
    for r in out:
        vet(r, s)
    return out


def _crossing(s: EstimatorSettings, *, tau: float, tau_std: float, p10: float,
              p_atm: float, p_star: float, t_open: float, t_cross: float, n: int, k: int,
              interp_err: float) -> UnloadResult:
    status, text = "ok", (f"start given; p* crossing interpolated log-linearly between "
                          f"samples {k - 1} and {k} (interpolation error {interp_err:.3g} s)")
    plan = plan_crossing(s, p10=p10, p_atm=p_atm, p_star=p_star, tau_ref=tau)
    est = crossing_estimate(plan, tau, tau_std)
    if s.charge and est.problem is not None:
        status, text = "bad_data", est.problem
    if plan.subsonic is not None:
        status, text = "ok_subsonic", text + "; " + plan.subsonic
    c39, c_isen, c_model = est.conductance, est.conductance_isentropic, \
        est.conductance_model
    c39_std, c_model_std, budgets, method = est.conductance_std, \
        est.conductance_model_std, est.extra, est.method
    return UnloadResult(
        index=0, status=status, status_text=text, t_start=t_open, t_cross=t_cross,
        tau_exp=tau, tau_exp_std=tau_std, p10=p10, **end_fields(s, p_atm), p_star=p_star,
        initial_temperature=s.initial_temperature, volume=s.volume, conductance=c39,
        conductance_model=c_model, conductance_model_std=c_model_std,
        conductance_std=c39_std, conductance_isentropic=c_isen,
        quality=1.0 if status == "ok" else 0.5, method=method + "+given-start",
        i_start=0, i_cross=k, i_complete=n - 1, t_complete=t_cross,
        extra={**budgets, "interpolation": "log-linear in (p - p_atm)",
               "interpolation_error_s": interp_err})


def _p10_term(s: EstimatorSettings, ts: np.ndarray, ps: np.ndarray, p10: float,
              p10_std: float, p_atm: float, t_open: float, res: UnloadResult) -> BudgetTerm:
    """The given p10's line of the budget: the crossing interpolated again with p10 moved
    by +-its uncertainty (p* moves with it), C by the isentropic inversion."""
    cs = []
    for d in (p10_std, -p10_std):
        pp = ps.copy()
        pp[0] = p10 + d
        level = charge_p_star(p10 + d, p_atm) if s.charge else physics.p_star(p10 + d,
                                                                                p_atm)
        try:
            tc, _e, _k = interpolated_crossing(ts, pp, level, p_atm)
        except EstimationError:
            return BudgetTerm("initial pressure p10 (given)", "B", p10, p10_std, "Pa",
                              math.nan, "crossing lost when p10 moves")
        if s.charge:
            cs.append(charge_conductance_adiabatic(
                tc - t_open, level, p10 + d, p_atm, s.volume, s.supply_gas_temperature,
                s.critical_ratio, 0.5, s.gas))
        else:
            cs.append(physics.conductance_isentropic_inversion(
                tc - t_open, level, p10 + d, s.volume, s.initial_temperature, s.gas))
    std = abs(cs[0] - cs[1]) / 2.0 * res.conductance_model / res.conductance_isentropic
    if s.initial_pressure is None:
        return BudgetTerm("initial pressure p10 (first sample)", "A", p10, p10_std, "Pa",
                          std, "the sample's noise: the fit's residual RMS")
    return BudgetTerm("initial pressure p10 (given)", "B", p10, p10_std, "Pa", std,
                      "initial_pressure_std" if s.initial_pressure_std is not None
                      else f"default {100 * P10_REL_DEFAULT:g} % of p10")
