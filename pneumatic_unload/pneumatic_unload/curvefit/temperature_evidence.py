# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The logged gas temperature as evidence on the final curve fit: does the fitted model's
gas temperature, seen through a thermometer, follow the one the record carries?

:func:`temperature_evidence` takes the fitted model's mean gas temperature (the one
integrator of :mod:`pneumatic_unload.model`, on the fitted configuration), passes it through
the thermometer's model - a first-order lag with its time constant fitted within
:data:`SENSOR_TAU_RANGE` (or given) and an offset - and compares it with the logged values:
the RMS of fitted minus measured against the channel's own noise. It does not move C: the
pressure alone is fitted (the joint fit is the next step); what it says goes to the result
(JSON ``gas_temperature``) and, where no thermometer model makes the model's gas follow the
log within its noise, to the status text.

SI units: s, K.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import RigConfig
from pneumatic_unload.curvefit.curve_fit_result import CurveSpan
from pneumatic_unload.fit.scalar import interval_minimum
from pneumatic_unload.fit.trace import TemperatureChannel
from pneumatic_unload.model import discharge, first_order_lag
from pneumatic_unload.model.parametric import THERMOMETER_TAU_RANGE
from pneumatic_unload.uncertainty.budget import BudgetTerm

FloatArray = NDArray[np.float64]

#: Bounds of the thermometer's fitted time constant [s] (the joint fit's).
SENSOR_TAU_RANGE = THERMOMETER_TAU_RANGE
#: The model's gas follows the log when the RMS of fitted minus measured is at most this
#: many times the channel's noise [-] (with a floor of :data:`RESOLUTION_FLOOR`).
FOLLOW_FACTOR = 2.0
#: A joint fit (the estimator's, the discrepancy workflow's) is made again with the
#: temperature's weight from its own residuals until their RMS is within this factor of
#: the one assumed, at most :data:`TEMPERATURE_PASSES` times [-].
TEMPERATURE_WEIGHT_TOLERANCE = 1.3
TEMPERATURE_PASSES = 3
#: Smallest noise credited to a temperature channel [K] (a logger's 0.1 K resolution:
#: quantisation alone is 0.03 K rms, a probe's accuracy is rarely better than 0.2 K).
RESOLUTION_FLOOR = 0.2
#: Points of the model's temperature between the log's samples (the lag is exact for the
#: piecewise-linear interpolant of its input) [-].
FINE_POINTS = 4000
#: Points of the log-spaced grid over :data:`SENSOR_TAU_RANGE` from which the lag search
#: brackets its minimum (a cell spans a factor of about 2.7) [-].
LAG_GRID = 15


def channel_noise(temp: FloatArray) -> float:
    """Noise of a temperature channel [K]: the median absolute second difference, as a
    standard deviation (x 1.4826) over sqrt(6) (white noise; the median, not the RMS: the
    curvature of the fast cooling after the opening is large at a logger's rate for a few
    readings - a 1 L tank's exact temperature at 10 Hz read 0.72 K by the RMS), at least
    :data:`RESOLUTION_FLOOR`."""
    d2 = np.diff(np.asarray(temp, dtype=float), 2)
    sig = 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0) if d2.size >= 3 \
        else math.nan
    return max(sig, RESOLUTION_FLOOR) if math.isfinite(sig) else RESOLUTION_FLOOR


def temperature_evidence(cfg: RigConfig, t_open: float, t_log: FloatArray,
                         temp_log: FloatArray, *, sensor_tau: float | None = None
                         ) -> dict[str, Any]:
    """Compare the fitted model's gas temperature with a logged one.

    Parameters
    ----------
    cfg : RigConfig
        The fitted model's configuration (``CurveFit.config``).
    t_open : float
        Its valve opening instant [s, the log's clock].
    t_log, temp_log : ndarray
        The logged gas temperature's instants [s] and values [K] (finite).
    sensor_tau : float, optional
        The thermometer's time constant [s] when known; else fitted.

    Returns
    -------
    dict
        ``used`` (False: compared, not fitted jointly) and ``why``; ``rms`` [K] of fitted
        minus measured, ``noise`` [K] of the channel, ``follows`` (rms within
        :data:`FOLLOW_FACTOR` noises), ``sensor_time_constant`` [s] and whether it sits on
        a bound, ``sensor_offset`` [K], ``samples``; ``rms_without_sensor`` [K]: the model's
        gas against the log with no lag and no offset.
    """
    t_log = np.asarray(t_log, dtype=float)
    temp_log = np.asarray(temp_log, dtype=float)
    ok = np.isfinite(t_log) & np.isfinite(temp_log)
    t_log, temp_log = t_log[ok], temp_log[ok]
    base = {"used": False, "why": "compared with the pressure fit's model (thermometer lag "
            "and offset fitted); the joint fit of both channels is not made yet",
            "samples": int(t_log.size)}
    if t_log.size < 5 or not np.all(np.diff(t_log) > 0):
        return {**base, "why": "fewer than 5 increasing temperature samples"}
    t0 = min(float(t_log[0]), t_open)
    fine = np.union1d(np.linspace(t0, float(t_log[-1]), FINE_POINTS), t_log)
    try:
        _p, gas = discharge(cfg.replace(noise_std=0.0), fine, t_open)
    except (ValueError, ArithmeticError) as exc:
        return {**base, "why": f"the model's temperature could not be computed: {exc}"}
    at_log = np.searchsorted(fine, t_log)
    noise = channel_noise(temp_log)

    def seen(tau: float) -> FloatArray:
        return first_order_lag(fine, gas, tau)[0][at_log]

    def misfit(log_tau: float) -> float:
        r = temp_log - seen(math.exp(log_tau))
        return float(np.sum((r - r.mean()) ** 2))

    lo, hi = (math.log(x) for x in SENSOR_TAU_RANGE)
    if sensor_tau is None:
        tau = math.exp(interval_minimum(misfit, lo, hi, points=LAG_GRID, tol=1e-3))
    else:
        tau = float(sensor_tau)
    r = temp_log - seen(tau)
    offset = float(r.mean())
    rms = float(np.sqrt(np.mean((r - offset) ** 2)))
    raw = temp_log - gas[at_log]
    on_bound = sensor_tau is None and min(abs(math.log(tau) - lo), abs(math.log(tau) - hi)) \
        < 0.01
    return {**base, "rms": rms, "noise": noise, "follows": rms <= FOLLOW_FACTOR * noise,
            "sensor_time_constant": tau, "sensor_time_constant_given": sensor_tau is not None,
            "sensor_time_constant_at_bound": bool(on_bound), "sensor_offset": offset,
            "rms_without_sensor": float(np.sqrt(np.mean(raw * raw)))}


def departure_text(ev: dict[str, Any]) -> str:
    """The status text's words when the model's gas does not follow the log within its
    noise, or follows it within the probe's accuracy only ('' when it follows within its
    noise or was not compared)."""
    if "rms" not in ev or ev.get("follows", True):
        return ""
    if ev.get("used") and "probe" in ev:
        return (f"the logged gas temperature follows the model's within the probe's "
                f"accuracy, not its noise ({ev['rms']:.2g} K rms against {ev['probe']:g} K"
                f" and {ev['noise']:.2g} K; T10 and a thermometer lag of "
                f"{ev['sensor_time_constant']:.3g} s fitted): used, weighted by its misfit")
    how = (f"T10 and a thermometer lag of {ev['sensor_time_constant']:.3g} s fitted"
           if ev.get("used") else
           f"a thermometer lag of {ev['sensor_time_constant']:.3g} s and an offset of "
           f"{ev['sensor_offset']:+.2g} K fitted")
    return (f"the logged gas temperature departs from the model's by {ev['rms']:.2g} K rms "
            f"(channel noise {ev['noise']:.2g} K; {how}): no heat law of the fit follows "
            "it")


#: Fewest readings of a logged temperature inside the fitted span for the joint fit [-].
CHANNEL_MIN_SAMPLES = 5


def channel_samples(series: tuple[FloatArray, FloatArray], span: CurveSpan
                    ) -> tuple[FloatArray, FloatArray] | str:
    """The readings of a logged gas temperature (instants [s, absolute], values [K]) that
    lie in the curve fit's span, at the span's relative times [s], or why there are too
    few (finite, increasing instants only)."""
    t, temp = (np.asarray(x, dtype=float) for x in series)
    ok = np.isfinite(t) & np.isfinite(temp) & (t >= span.t_ref) & (t <= span.t_last)
    t, temp = t[ok] - span.t_ref, temp[ok]
    if t.size and not np.all(np.diff(t) > 0):
        keep = np.concatenate(([True], np.diff(t) > 0))  # repeated stamps: the first
        t, temp = t[keep], temp[keep]
        if not np.all(np.diff(t) > 0):
            return "its instants go backwards inside the unload"
    if t.size < CHANNEL_MIN_SAMPLES:
        return (f"{t.size} reading(s) inside the unload's span; the joint fit needs "
                f"{CHANNEL_MIN_SAMPLES}")
    return t, temp


#: A thermometer lag below this fraction of the readings' median spacing is not resolved
#: by them: the joint fit holds it at the floor of its range (a flat direction would make
#: the fit's last bits, and C's, depend on the machine: 5e-6 relative on a simulator's
#: exact temperature) [-].
UNRESOLVED_LAG = 0.05


def channel(t: FloatArray, temp: FloatArray, pressure_rms: float, sigma: float,
            lag_seen: float = math.nan, *, lag_given: float | None = None,
            offset: bool = False) -> TemperatureChannel:
    """The channel of readings ``temp`` [K] at relative instants t [s] whose residuals
    have the standard deviation ``sigma`` [K], weighted to the pressure residuals'
    ``pressure_rms`` [Pa]; its lag held at ``lag_given`` [s], else at the floor of
    :data:`SENSOR_TAU_RANGE` where ``lag_seen`` [s] (the comparison's) is below
    :data:`UNRESOLVED_LAG` of the spacing, else fitted; its offset fitted with ``offset``
    (:func:`offset_identified`)."""
    spacing = float(np.median(np.diff(t))) if t.size > 1 else math.inf
    held = lag_given if lag_given is not None else \
        SENSOR_TAU_RANGE[0] if lag_seen < UNRESOLVED_LAG * spacing else None
    return TemperatureChannel(t, temp, float(pressure_rms / sigma), held, offset)


def weighted_passes(attempt: Callable[[float, int], float], sigma: float,
                    noise: float) -> None:
    """The joint fit's weight iterated (the estimator's and the discrepancy workflow's
    rule): ``attempt(sigma, k)`` fits with the readings' residuals taken to have the
    standard deviation sigma [K] (pass k) and returns their rms [K]; it is called again
    with the larger of ``noise`` [K] and that rms until the two agree within
    :data:`TEMPERATURE_WEIGHT_TOLERANCE`, at most :data:`TEMPERATURE_PASSES` times."""
    for k in range(TEMPERATURE_PASSES):
        now = max(noise, attempt(sigma, k))
        if abs(math.log(now / sigma)) <= math.log(TEMPERATURE_WEIGHT_TOLERANCE):
            return
        sigma = now


def offset_identified(wall_given: bool) -> bool:
    """Whether the thermometer's offset is fitted: where the wall's temperature is given.
    The gas then relaxes toward a known temperature, which the readings show through the
    offset; otherwise T10 and the offset move the readings alike (the pressure fixes only
    C sqrt(T10), and a wall assumed at T10 or fitted moves with it): the offset is held at
    0 and the probe's accuracy is T10's line of the budget (``temperature_uncertainty``)."""
    return wall_given


def channel_evidence(summary: dict[str, float]) -> dict[str, Any]:
    """JSON ``gas_temperature`` of a joint fit (the curve fit's ``gas_temperature``
    summary): ``used`` true, the fitted readings' ``rms`` [K] against the channel's
    ``noise`` [K] and whether the model ``follows`` the log (within :data:`FOLLOW_FACTOR`
    noises; where not, the summary's ``probe`` [K] says it was used within the probe's
    accuracy), the thermometer's ``sensor_time_constant`` [s] and ``sensor_offset`` [K] (0
    +- 0 where held: :func:`offset_identified`) and the fitted ``t10`` [K], each with its
    1-sigma."""
    rms, noise = summary["rms"], summary["noise"]
    follows = rms <= FOLLOW_FACTOR * noise
    probe = summary.get("probe", math.nan)
    return {"used": True, "why": "fitted jointly with the pressure (the thermometer's lag "
            "fitted, T10 from the log)" + ("" if follows else
            f"; within the probe's accuracy ({probe:g} K), not its noise, the pressure's "
            "residual kept: weighted by its own misfit" if math.isfinite(probe) else
            "; weighted by its own misfit: no heat law follows it within its noise"),
            "samples": int(summary["samples"]), "rms": rms, "noise": noise,
            "follows": follows, "sensor_time_constant": summary["sensor_time_constant"],
            "sensor_time_constant_std": summary["sensor_time_constant_std"],
            "t10": summary["t10"], "t10_std": summary["t10_std"],
            "sensor_offset": summary.get("sensor_offset", 0.0),
            "sensor_offset_std": summary.get("sensor_offset_std", 0.0),
            "passes": int(summary.get("passes", 1)),
            **({"probe": probe} if math.isfinite(probe) else {})}


def temperature_terms(fit: Any, of: str = "C") -> tuple[BudgetTerm, ...]:
    """The line of C's (``of`` "C") or b's ("b") budget where a logged gas temperature
    departs from every heat law (a :class:`~pneumatic_unload.curvefit.curve_fit_result.CurveFit`
    whose ``gas_temperature`` has the pressure fit's ``departure_rms`` [K] from the log, its
    thermometer's lag and offset fitted); none otherwise.

    C's: the gas temperature the model assumes is uncertain by that much, and C from a
    pressure curve goes as 1/sqrt(T) (the flow C rho_N p sqrt(T_N/T) empties the tank at a
    rate that goes as C sqrt(T)): C rms / (2 T10). Where the joint fit followed the log
    within the probe's accuracy and was refused only for the pressure's residual grown
    (:data:`~pneumatic_unload.curvefit.joint_family.PRESSURE_KEPT`), the record has two
    readings, each preferred by one channel, and which describes the gas is not known:
    the line is at least the gap between them over sqrt(3) (a rectangle from the reported
    value to the joint one, as the wall's assumed gap), for C and for b [m^3/(s Pa)], [-].
    """
    g = fit.gas_temperature
    rms = g.get("departure_rms", math.nan)
    if not math.isfinite(rms):
        return ()
    own, joint = ((fit.conductance, g.get("joint_conductance", math.nan)) if of == "C" else
                  (fit.critical_ratio, g.get("joint_critical_ratio", math.nan)))
    gap = abs(joint - own) / math.sqrt(3.0) if g.get("joint_within_probe") else math.nan
    why = (f"the joint fit's reading {joint:.4g} (the log followed to {g['joint_rms']:.2g} K, "
           f"within the probe's {g['probe']:g} K; the pressure's residual "
           f"{g['joint_pressure_rms']:.4g} Pa rms against {g['pressure_rms']:.4g}): "
           "|gap|/sqrt(3)") if math.isfinite(gap) else ""
    name = "gas temperature (the log departs from every heat law)"
    if of != "C":
        return (BudgetTerm(name, "model", math.nan, rms, "K", gap, why),) \
            if math.isfinite(gap) else ()
    t10 = g["t10_assumed"]
    std = fit.conductance * rms / (2.0 * t10)
    note = (f"the model's gas {rms:.2g} K rms from the log (noise {g['noise']:.2g} K; lag "
            f"and offset fitted); C goes as 1/sqrt(T): C rms/(2 T10)")
    if math.isfinite(gap) and gap > std:
        std, note = gap, why
    return (BudgetTerm(name, "model", math.nan, rms, "K", std, note),)
