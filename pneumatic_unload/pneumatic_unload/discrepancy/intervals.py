# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Intervals and independent checks of a fitted discrepancy model.

SI units: s, Pa, K.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.fields import ConfigError
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.types import Fit
from pneumatic_unload.fit.profile import Interval, interval

FloatArray = NDArray[np.float64]

#: Extra pseudo-effect: a constant geometric factor on C (the paper's L/D effect).
GEOMETRY_FACTOR = "geometry_factor"


def intervals(prob: Problem, fit: Fit, names: list[str], *, profile: bool = True
              ) -> dict[str, Interval]:
    """95 % intervals of the named parameters of a fit (linear, checked by profiles)."""
    cov = fit.covariance()
    free = fit.result.params.free
    out = {}
    for name in names:
        i = free.index(name)
        se = math.sqrt(cov[i, i]) if cov[i, i] >= 0 else math.nan
        out[name] = interval(prob.trace, fit.model, fit.result, name, se, check=profile)
    return out


def _signal_of(cfg: Any, fit: Fit, t: FloatArray) -> FloatArray:
    """Sensor output [Pa] of a configuration at instants t [s] (valve at the fit's t_open)."""
    from pneumatic_unload.model import integrate, sensor_response

    p = integrate(cfg, t, fit.theta["t_open"], rtol=1e-9, quiet=True)[:, 0]
    return sensor_response(t, p, cfg)


def geometry_factor_check(prob: Problem, fit: Fit) -> dict[str, Any]:
    """Identifiability of a constant geometric factor f on C from this one trace.

    The model depends on f and C only through f C, so the sensitivities of the trace to
    log f and to log C are computed and compared: a correlation of 1 means f is not
    identifiable from one trace (it needs several tank geometries).
    """
    th = dict(fit.theta)
    cfg = fit.model.config(th)
    # a step of 1e-3 in log C and log f, downwards when upwards leaves C's range (a fit
    # at C's upper bound)
    h = 1e-3
    try:
        cfg_f = cfg.replace(conductance=cfg.conductance * math.exp(h))
    except ConfigError:
        h = -h
        cfg_f = cfg.replace(conductance=cfg.conductance * math.exp(h))
    z0 = prob.residuals(fit.model, th)
    dz_c = prob.residuals(fit.model, {**th, "C": th["C"] * math.exp(h)}) - z0
    # the factor f = e^h applied in the flow law: the configuration the model integrates
    # holds only the product f C, so the sensitivity is computed through it (cfg_f)
    dz_f = prob.trace.lik.residuals_at(
        lambda tt: _signal_of(cfg_f, fit, tt), fit.model.events(th)) - z0
    num = float(dz_c @ dz_f)
    den = math.sqrt(float(dz_c @ dz_c) * float(dz_f @ dz_f))
    corr = num / den if den > 0 else math.nan
    return {"name": GEOMETRY_FACTOR, "identifiable": False,
            "sensitivity_correlation_with_C": corr,
            "reason": "a constant factor on C (the paper's L/D effect) changes the trace "
                      "exactly as C does (sensitivity correlation "
                      f"{corr:.6f}): not identifiable from one trace; give several runs "
                      "with different tank geometries (L/D) to identify a shared law"}


#: Agreement tolerance of a logged gas temperature with a model [K]: the calibration of a
#: gas thermocouple (about 2 K) and its lag (seconds), which flattens the fast cooling of the
#: first seconds of a discharge.
TEMPERATURE_TOLERANCE = 5.0


def temperature_check(prob: Problem, base: Fit, final: Fit, t_meas: FloatArray,
                      temp_meas: FloatArray, joint: dict[str, Any] | None = None
                      ) -> dict[str, Any]:
    """Compare a measured gas temperature with the baseline and final models [K].

    The models' gas is compared as it is, with no thermometer: agreement is evidence for
    (or against) the heat-transfer effect fitted on the pressure alone. A final model
    whose temperature differs from the log by more than :data:`TEMPERATURE_TOLERANCE` (rms)
    is flagged ('contradicts') with the likely reason and what to measure next - unless
    the final model was fitted with the log and follows it through its thermometer
    (``joint``: :func:`~pneumatic_unload.discrepancy.thermo.joint_fit`'s result, whose
    ``rms`` [K] is then the final model's departure).
    """
    sel = (t_meas >= prob.t[0]) & (t_meas <= prob.t[-1])
    if np.count_nonzero(sel) < 3:
        return {"available": False, "reason": "no temperature samples inside the trace"}
    tm, Tm = t_meas[sel], temp_meas[sel]
    out: dict[str, Any] = {"available": True, "samples": int(tm.size),
                           "measured_min": float(np.min(Tm)),
                           "measured_start": float(Tm[0]), "measured_end": float(Tm[-1]),
                           "tolerance": TEMPERATURE_TOLERANCE}
    diffs = {}
    for label, f in (("baseline", base), ("final", final)):
        Tmod = f.model.temperature(f.theta, tm)
        d = Tmod - Tm
        diffs[label] = d
        out[label] = {"rms": float(np.sqrt(np.mean(d * d))), "mean": float(np.mean(d)),
                      "min_model": float(np.min(Tmod)), "end_model": float(Tmod[-1])}
    heat = any(e in ("heat_transfer", "hot_start") for e in final.effects)
    better = out["final"]["rms"] < out["baseline"]["rms"]
    follows = bool(joint and joint.get("follows"))
    if follows:
        assert joint is not None
        out["final"]["rms_gas"] = out["final"]["rms"]
        out["final"]["rms"] = float(joint["rms"])
    contradicts = out["final"]["rms"] > TEMPERATURE_TOLERANCE
    out["heat_transfer_fitted"] = heat
    out["contradicts"] = contradicts
    out["agrees"] = bool(heat and better and not contradicts)
    reason, next_ = _temperature_reason(prob, final, diffs["final"], Tm) if contradicts \
        else ("", "")
    out["likely_reason"], out["measure_next"] = reason, next_
    head = ("the measured gas temperature is closer to the model with the fitted heat "
            "transfer" if better else "the measured gas temperature does NOT support the "
            "fitted model better than the adiabatic baseline")
    if contradicts:
        head = (f"the logged gas temperature CONTRADICTS the final model (rms "
                f"{out['final']['rms']:.1f} K > {TEMPERATURE_TOLERANCE:g} K; mean "
                f"{out['final']['mean']:+.1f} K); likely: {reason}; next: {next_}; "
                + ("it is still closer than the adiabatic baseline" if better else
                   "it is not even closer than the adiabatic baseline"))
    if follows:
        assert joint is not None
        head = (f"the final model, fitted with the logged gas temperature, follows it "
                f"through its thermometer ({joint['rms']:.2g} K rms, noise "
                f"{joint['noise']:.2g} K; lag {joint['sensor_time_constant']:.2g} s)")
    out["summary"] = (
        head + f" (rms {out['baseline']['rms']:.2f} K adiabatic vs {out['final']['rms']:.2f} K "
        f"final model; measured minimum {out['measured_min']:.1f} K, end "
        f"{out['measured_end']:.1f} K; adiabatic model minimum "
        f"{out['baseline']['min_model']:.1f} K, final model minimum "
        f"{out['final']['min_model']:.1f} K, end {out['final']['end_model']:.1f} K)")
    return out


def _temperature_reason(prob: Problem, final: Fit, d: FloatArray, temp: FloatArray
                        ) -> tuple[str, str]:
    """Likely reason a model's gas temperature contradicts the log, and what to measure.

    d = model - measured [K] at the logged instants, temp the logged values [K].
    """
    tank = prob.tank
    cfg = final.model.config(final.theta)
    t_wall, t10 = cfg.wall, tank.initial_temperature
    src = ("fitted" if "t_wall" in final.theta else "assumed equal to T10"
           if tank.wall_temperature is None else "stated")
    late = d[-max(d.size // 3, 1):]
    late_mean = float(np.mean(late))
    t_end = float(temp[-1])
    heat = any(e in ("heat_transfer", "hot_start") for e in final.effects)
    tol = TEMPERATURE_TOLERANCE
    wall_next = ("log the wall (room) temperature and state it (--wall-temperature); "
                 "a gas that starts hot after charging relaxes toward the wall, not toward "
                 "T10")
    if late_mean > tol and heat and t_wall > t_end + tol:
        return (f"the wall temperature assumption: the model's wall is at {t_wall:.1f} K "
                f"({src}; T10 {t10:.1f} K) while the logged gas ends at {t_end:.1f} K, so "
                "the model heats the gas back toward a wall that is colder in the rig"
                ), wall_next
    if late_mean > tol:
        return ("the model's gas stays too warm late in the discharge: heat transfer too "
                "strong in the model, or the temperature sensor reads low"), \
            "check the temperature sensor against the room before the run; " + wall_next
    if late_mean < -tol:
        return ("the model's gas stays too cold late in the discharge: the rig's wall "
                "supplies more heat than the model (a larger wall area, a warmer wall), or "
                "the heat-transfer effect is missing"), wall_next
    return ("the early swing differs: a gas thermocouple lags (seconds) and flattens the "
            "fast cooling, or the heat-transfer law differs"), \
        "a faster temperature sensor (fine-wire thermocouple) or its time constant"
