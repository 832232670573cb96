# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A logged gas temperature as evidence for the models a discrepancy verdict weighs.

The search names effects on the pressure alone; where the record carries the gas
temperature, each model the verdict weighs (the final one and the members of C's
ambiguity, :mod:`~pneumatic_unload.discrepancy.ambiguity`) is fitted once more with the
log beside the pressure, by the engine's joint fit and the estimator's rule
(:mod:`pneumatic_unload.curvefit.temperature_evidence`): T10 and the thermometer's first-order lag
fitted, the readings weighted by the larger of their noise and their misfit (iterated
until the two agree), and the model *follows* the log when the readings' rms is within
:data:`~pneumatic_unload.curvefit.temperature_evidence.FOLLOW_FACTOR` of the channel's noise.

Where some of the models follow the log and others do not, those that do not are ruled
out by it: they leave C's range, and a final model the log rules out while another
follows it is said so in the verdict. Where none follows (a stratified tank whose
thermocouple reads local gas: the real AeroLab runs), the log rules nothing out and its
departure is reported. SI units: K, s, Pa, m^3/(s Pa).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.curvefit.temperature_evidence import (
    CHANNEL_MIN_SAMPLES,
    FOLLOW_FACTOR,
    channel,
    channel_noise,
    offset_identified,
    temperature_evidence,
    weighted_passes,
)
from pneumatic_unload.discrepancy.ambiguity import ConductanceAmbiguity, conductance_std
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.types import Fit
from pneumatic_unload.model.parametric import ParametricModel

FloatArray = NDArray[np.float64]

#: Evaluations of each pass of a model's joint fit, started from its fit to the pressure
#: (a few Levenberg-Marquardt iterations: the pressure's parameters barely move) [-].
JOINT_NFEV = 80


def readings(prob: Problem, series: tuple[FloatArray, FloatArray]
             ) -> tuple[FloatArray, FloatArray] | str:
    """The logged readings (instants [s] on the trace's clock, values [K]) inside the
    fitted trace, at its relative times, or why there are too few (finite, increasing)."""
    t, temp = (np.asarray(x, dtype=float) for x in series)
    t = t - prob.t_ref
    ok = np.isfinite(t) & np.isfinite(temp) & (t >= prob.t[0]) & (t <= prob.t[-1])
    t, temp = t[ok], temp[ok]
    if t.size and not np.all(np.diff(t) > 0):
        return "its instants do not increase"
    if t.size < CHANNEL_MIN_SAMPLES:
        return (f"{t.size} reading(s) inside the trace; the joint fit needs "
                f"{CHANNEL_MIN_SAMPLES}")
    return t, temp


def joint_fit(prob: Problem, fit: Fit, t: FloatArray, temp: FloatArray) -> dict[str, Any]:
    """``fit``'s model fitted again with the readings ``temp`` [K] at relative instants
    t [s] beside the pressure.

    Returns
    -------
    dict
        ``follows`` (the readings' rms within FOLLOW_FACTOR of the channel's ``noise``),
        ``rms`` [K], ``noise`` [K], ``t10`` [K], ``sensor_time_constant`` [s] and
        ``sensor_offset`` [K] fitted (the offset where the wall is given, else 0),
        ``conductance`` and ``conductance_std`` [m^3/(s Pa)] of the joint fit against the
        pressure fit's ``conductance_pressure``, ``pressure_rms_ratio`` (the joint fit's
        pressure residual rms over the pressure fit's) [-], ``passes``; or ``why`` it
        could not be fitted.
    """
    m = fit.model
    offset = offset_identified(m.tank.wall_temperature is not None)
    model = ParametricModel(m.effects, m.tank, m.start, heat_law=m.heat_law,
                            fit_wall_temperature=m.fit_wall_temperature,
                            subsonic_index=m.subsonic_index, thermometer=True,
                            thermometer_offset=offset)
    p_alone = prob.trace.residual(m)(fit.theta)
    n_p = p_alone.size
    s_p = float(np.sqrt(np.mean(p_alone * p_alone)))
    noise = channel_noise(temp)
    ev = temperature_evidence(m.config(fit.theta), fit.theta["t_open"], t, temp)
    sigma = max(noise, float(ev.get("rms", noise)))
    if not (math.isfinite(s_p) and s_p > 0.0 and math.isfinite(sigma)):
        return {"why": "the pressure fit's residual is not finite"}
    start = {**fit.theta, "t10": float(m.tank.initial_temperature)}
    lag = float(ev.get("sensor_time_constant", math.nan))
    if math.isfinite(lag):
        start["tau_thermo"] = lag
    out: dict[str, Any] = {}

    def attempt(sigma_t: float, k: int) -> float:
        if k:  # the later passes start from the previous pass's fit
            start.update(out["fit"].theta)
        joint = prob.trace.with_channel(channel(t, temp, s_p, sigma_t,
                                                lag if ev.get("follows") else math.nan,
                                                offset=offset))
        res = joint.fit(model, start=start, max_nfev=JOINT_NFEV)
        r = joint.residual(model)(res.values)
        ch = joint.channel
        assert ch is not None
        rt = r[n_p:] / ch.weight
        rms = float(np.sqrt(np.mean(rt * rt)))
        j = Fit(model=model, result=res)
        out.update({"rms": rms, "noise": noise, "follows": rms <= FOLLOW_FACTOR * noise,
               "t10": res.values["t10"],
               "sensor_time_constant": res.values.get("tau_thermo", ch.lag),
               "sensor_offset": res.values.get("t_offset", 0.0),
               "conductance": res.values["C"], "conductance_std": conductance_std(j),
               "conductance_pressure": fit.theta["C"],
               "pressure_rms_ratio": float(np.sqrt(np.mean(r[:n_p] ** 2))) / s_p,
               "samples": int(temp.size), "passes": k + 1, "fit": j, "channel": ch})
        return rms

    try:
        weighted_passes(attempt, sigma, noise)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return {"why": f"the joint fit failed: {exc}"}
    return out


def judge(prob: Problem, fits: list[Fit], series: tuple[FloatArray, FloatArray], *,
          final: dict[str, Any] | None = None) -> dict[str, Any]:
    """The log's verdict on ``fits`` (the final model first, then the members of C's
    ambiguity; ``final``: the first one's :func:`joint_fit` when made already): per model
    its :func:`joint_fit` (without the fit object and channel), and which
    models the log ``rules_out`` (indices into ``fits``: those that do not follow it while
    another does); ``available`` False with ``why`` when the log has too few readings."""
    got = readings(prob, series)
    if isinstance(got, str):
        return {"available": False, "why": got}
    t, temp = got
    models = []
    for i, f in enumerate(fits):
        j = dict(final) if i == 0 and final else joint_fit(prob, f, t, temp)
        j.pop("fit", None)
        j.pop("channel", None)
        models.append({"effects": list(f.effects), **j})
    follow = [bool(j.get("follows")) for j in models]
    out = [i for i, ok in enumerate(follow) if not ok and "rms" in models[i]] \
        if any(follow) else []
    return {"available": True, "samples": int(temp.size), "models": models,
            "rules_out": out, "any_follows": any(follow)}


def _name(effects: list[str]) -> str:
    return ", ".join(effects) if effects else "baseline"


def temperature_words(joint: dict[str, Any], amb: ConductanceAmbiguity) -> str:
    """Apply the log's verdict (:func:`judge` of the final model and ``amb``'s members, in
    ``amb``'s order) to C's range (:meth:`ConductanceAmbiguity.rule_out`) and say it, as a
    clause of the verdict ('; ...'; '' when the log has too few readings)."""
    if not joint.get("available"):
        return ""
    models = joint["models"]
    final = models[0]
    if "rms" not in final:
        return f"; the logged gas temperature was not fitted: {final.get('why', '')}"
    follow = [i for i, j in enumerate(models) if j.get("follows")]
    if not follow:
        best = min((j for j in models if "rms" in j), key=lambda j: j["rms"])
        return (f"; no model follows the logged gas temperature when fitted with it (best "
                f"{best['rms']:.2g} K rms for {_name(best['effects'])}, channel noise "
                f"{best['noise']:.2g} K; T10 and the thermometer's lag fitted): it rules "
                "none out")
    lead = models[follow[0]]
    amb.rule_out({i: (f"the logged gas temperature departs from its gas by "
                      f"{models[i]['rms']:.2g} K rms (noise {models[i]['noise']:.2g} K) "
                      f"when fitted with it, while {_name(lead['effects'])}'s follows it")
                  for i in joint["rules_out"]})
    gone = len(joint["rules_out"]) - (0 in joint["rules_out"])
    out = ""
    if final.get("follows"):
        out = (f"; the logged gas temperature supports the reported model (fitted with it: "
               f"{final['rms']:.2g} K rms, noise {final['noise']:.2g} K, T10 "
               f"{final['t10']:.1f} K, thermometer lag {final['sensor_time_constant']:.2g} "
               f"s; C {final['conductance']:.4g} m^3/(s Pa))")
    else:
        out = (f"; the logged gas temperature departs from the reported model "
               f"({final['rms']:.2g} K rms, noise {final['noise']:.2g} K, fitted with it) "
               f"and follows {_name(lead['effects'])} (C {lead['conductance']:.4g} m^3/(s "
               f"Pa) fitted with it)")
    if gone:
        names = "; ".join(_name(models[i]["effects"]) for i in joint["rules_out"] if i)
        out += f"; it rules out {gone} model(s) of C's range ({names})"
    return out
