# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The search of the discrepancy workflow: diagnostics, candidate rounds, the BIC decision.

SI units: s, Pa.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.curvefit.heat_law_offer import both_regimes, exchange_determined
from pneumatic_unload.discrepancy.ambiguity import VARIANTS, at_bounds, same_physics
from pneumatic_unload.discrepancy.laws import HEAT_EFFECTS
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.types import NRMS_LIMIT, WHITE_P, Diagnostics, Fit
from pneumatic_unload.fit.noise import NoiseModel, ljung_box, normalised_rms
from pneumatic_unload.fit.trace import Trace
from pneumatic_unload.model.effects import HEAT_VARIANTS, HOT_START
from pneumatic_unload.model.heat import RA_TURBULENT, rayleigh
from pneumatic_unload.model.parametric import ParametricModel

#: Nested extensions of an effect (extension -> the effect it extends by one parameter).
NESTED: dict[str, str] = {HOT_START: "heat_transfer"}
#: Two-parameter heat laws of the engine's family -> the one-parameter law each extends
#: and the value of the second parameter that gives that law back (heat_turbulent 1:
#: the natural law; heat_exponent 0: a constant hA) [-].
HEAT_EXTENSIONS: dict[str, tuple[str, Values]] = {
    "natural+turbulent": ("natural", {"heat_turbulent": 1.0}),
    "density": ("fixed", {"heat_exponent": 0.0})}
#: Largest delta-BIC by which a contender may trail its round's best and still be fitted
#: out from every start when its fit may not be optimal (:func:`refit_contenders`) [-]:
#: ten BIC thresholds, about five times the most a refit moved a candidate (23).
REFIT_MARGIN = 100.0
#: Transducer effects: claimed only with evidence no physics effect can give.
SENSOR_EFFECTS: tuple[str, ...] = ("sensor_offset", "sensor_gain")
#: The end of the discharge: where the physics model's pressure is within this fraction
#: of p10 - p_atm above p_atm [-].
END_FRACTION = 0.05
#: Fewest samples of the end of the discharge for evidence on the end level [-].
END_SAMPLES = 30
#: Standard errors by which the end level must disagree with every physics model before
#: a transducer effect is claimed [-].
END_Z = 4.0

FloatArray = NDArray[np.float64]
Values = dict[str, float]


def diagnose(prob: Problem, fit: Fit) -> tuple[Diagnostics, FloatArray]:
    """Diagnostics of a fitted model and its noise-free signal at every sample [Pa].

    Parameters
    ----------
    prob : Problem
        The trace.
    fit : Fit
        The fitted model.
    """
    th = fit.theta
    m = fit.model.signal(th, prob.t)
    r = prob.y - m
    sigma = prob.noise.sigma
    rms = float(np.sqrt(np.mean(r * r)))
    z = prob.lik.residuals(m)
    _, p_lb = ljung_box(z)
    # phases from the model's true pressure
    cfg = fit.model.config(th)
    p_true = m if not fit.effects else fit.model.states(th, prob.t)[:, 0]
    end, b, p10 = cfg.end_pressure, cfg.critical_ratio, cfg.initial_pressure
    pre = prob.t < th["t_open"]
    # the end plateau: the room's (a discharge), the supply's (a charge); choked while the
    # downstream pressure is below b times the upstream's
    plateau = ~pre & (np.abs(p_true - end) < 0.002 * abs(p10 - end))
    up, down = (end, p_true) if cfg.direction == "charge" else (p_true, end)
    choked = ~pre & ~plateau & (up * b >= down)
    subsonic = ~pre & ~plateau & ~choked
    phases = {}
    for name, sel in (("pre-step", pre), ("choked", choked), ("subsonic", subsonic),
                      ("plateau", plateau)):
        k = int(np.count_nonzero(sel))
        if k:
            rr = r[sel]
            phases[name] = {"samples": k, "mean": float(np.mean(rr)),
                            "rms": float(np.sqrt(np.mean(rr * rr))),
                            "nrms": float(np.sqrt(np.mean(rr * rr)) / sigma)}
    # correlation of the binned residual with pressure and rate
    e = prob.lik.edges
    cnt = prob.lik.counts
    rb = np.add.reduceat(r, e[:-1]) / cnt
    pb = np.add.reduceat(m, e[:-1]) / cnt
    tb = np.add.reduceat(prob.t, e[:-1]) / cnt
    rate = np.gradient(pb, tb) if pb.size > 2 else np.zeros_like(pb)

    def corr(a: FloatArray, b_: FloatArray) -> float:
        if a.size < 3 or np.std(a) == 0 or np.std(b_) == 0:
            return math.nan
        return float(np.corrcoef(a, b_)[0, 1])

    d = Diagnostics(rms=rms, nrms=normalised_rms(r, prob.noise), ljung_box_p=p_lb,
                    white=bool(math.isfinite(p_lb) and p_lb >= WHITE_P), phases=phases,
                    corr_pressure=corr(rb, pb), corr_rate=corr(rb, rate))
    return d, m


def fit_quality(prob: Problem, fit: Fit) -> Diagnostics:
    """Normalised RMS and residual whiteness of a fit (no phases, no correlations) [-]."""
    m = fit.model.signal(fit.theta, prob.t)
    r = prob.y - m
    rms = float(np.sqrt(np.mean(r * r)))
    _, p_lb = ljung_box(prob.lik.residuals(m))
    return Diagnostics(rms=rms, nrms=normalised_rms(r, prob.noise), ljung_box_p=p_lb,
                       white=bool(math.isfinite(p_lb) and p_lb >= WHITE_P), phases={},
                       corr_pressure=math.nan, corr_rate=math.nan)


def fit_candidate(prob: Problem, base: Fit, neutral: list[Values], cand: str,
                  heat_law: str | None = None) -> Fit:
    """The current model with ``cand`` added, fitted from several starts.

    Starts: the current fit and the neutral baseline values, each with a small and a large
    effect, and the nested start (the current fit with the effect almost off), so that the
    extended fit never ends worse than the model it extends. Heat transfer (and the hot
    start) is fitted with the engine's whole law family
    (:data:`~pneumatic_unload.model.effects.HEAT_VARIANTS`): each one-parameter law, then
    each two-parameter law of :data:`HEAT_EXTENSIONS` where the record carries its second
    parameter (:func:`extension_offered`), from the fit of the law it extends (nested:
    never worse than it) and with the second parameter at its centre; the law
    with the lowest BIC is kept (chi^2 + k ln n: a second parameter must pay for itself).
    ``heat_law`` given (the hot start, with heat transfer's law): the one-parameter laws
    and that one, no other two-parameter law, so that the hot start never has more than
    the wall temperature beyond heat transfer's parameters (:data:`NESTED`).
    """
    effects = (*base.effects, cand)
    if cand not in ("heat_transfer", HOT_START):
        return _fit_law(prob, base, neutral, effects, cand, base.model.heat_law)
    laws = prob.heat_laws  # a charge's without the density law
    by_law = {law: _fit_law(prob, base, neutral, effects, cand, law)
              for law in laws if len(HEAT_VARIANTS[law].params) == 1}
    for law, (sub, nested) in HEAT_EXTENSIONS.items():
        if law not in laws:
            continue
        f1 = by_law.get(sub)
        offered = law == heat_law if heat_law is not None else \
            f1 is not None and extension_offered(prob, f1, law)
        if f1 is not None and offered:
            model = prob.model(effects, heat_law=law)
            centre = {q.name: q.centre(prob.start) for q in HEAT_VARIANTS[law].params
                      if q.name in nested}
            by_law[law] = prob.fit(model, [{**f1.theta, **nested}, {**f1.theta, **centre}])
    return min(by_law.values(), key=lambda f: f.bic)


def _fit_law(prob: Problem, base: Fit, neutral: list[Values], effects: tuple[str, ...],
             cand: str, law: str) -> Fit:
    """``cand`` added to ``base`` with the heat law ``law``, multi-start [-]."""
    model = prob.model(effects, heat_law=law)
    return prob.fit(model, _starts(prob, base, neutral, model, cand))


def _starts(prob: Problem, base: Fit, neutral: list[Values], model: ParametricModel,
            cand: str) -> list[Values]:
    """Starts of ``cand`` added to ``base``: the base fit and the neutral values, each
    with the effect's small and large starts, and the nested start (the effect almost
    off) [SI units]."""
    starts = prob.starts_for(model, [dict(base.theta), *neutral], (cand,))
    if cand not in SENSOR_EFFECTS:
        starts.append({**base.theta, **model.off_values(cand)})
    return starts


def refit_contenders(prob: Problem, base: Fit, neutral: list[Values],
                     fits: dict[str, Fit], threshold: float) -> None:
    """Fit out in full, from every start, the contenders whose fit may not be optimal
    (``fits`` updated in place with the best of each).

    A contender beats ``base`` by the BIC threshold and trails the round's best by at
    most :data:`REFIT_MARGIN`. Its fit may not be optimal when its search ran out of
    iterations, or when a parameter of its own ends at a bound of its range, where the
    effect degenerates (a pipe conductance at its largest makes the pipe volume just more
    tank): the multi-start screening takes the start that looks best after a few
    iterations, which may only have drifted there first. Synthetic pipe volumes (harness
    seed 1000: at the bound, 9 behind a downstream leak with C -38 %; fresh seed 101004:
    in a slow valley, 15 behind it, named alone with a C range missing the truth): fitted
    out, the pipe volume led by 14 and trailed by 8 (an ambiguity whose C range holds the
    truth). Heat transfer and the hot start choose among their laws instead
    (:func:`fit_candidate`).
    """
    gain = {k: base.bic - f.bic for k, f in fits.items()}
    if not gain:
        return
    best = max(gain.values())
    for k, f in fits.items():
        if k in HEAT_EFFECTS or gain[k] <= threshold or best - gain[k] > REFIT_MARGIN:
            continue
        if f.result.success and not any(q not in base.theta for q in at_bounds(f)):
            continue
        starts = _starts(prob, base, neutral, f.model, k)
        fits[k] = min([f, *(prob.fit(f.model, [s]) for s in starts)], key=lambda g: g.bic)


def extension_offered(prob: Problem, fit: Fit, law: str) -> bool:
    """Whether the record carries the second parameter of the two-parameter heat law
    ``law``, judged on ``fit`` (the fit of the one-parameter law it extends), by the
    curve fit's own rules (:mod:`pneumatic_unload.curvefit.heat_law_offer`): the natural law's
    turbulent branch only when the fitted gas spends at least
    :data:`~pneumatic_unload.curvefit.heat_law_offer.TURBULENT_MIN_SHARE` of the record after the
    opening on each side of Ra = 1e9; the density law only when the constant-hA fit
    determines tau_heat to :data:`~pneumatic_unload.curvefit.heat_law_offer.
    DENSITY_LAW_MIN_TAU_REL_SD` (1-sigma, relative)."""
    th = fit.theta
    if law == "natural+turbulent":
        tt = np.linspace(th["t_open"], float(prob.t[-1]), 400)
        try:
            st = fit.model.states(th, tt)
        except ValueError:
            return False
        share = float(np.mean(rayleigh(fit.model.config(th), st[:, 0], st[:, 1])
                              >= RA_TURBULENT))
        return both_regimes(share)
    if law == "density":
        return "tau_heat" in fit.result.params.free and \
            exchange_determined(th["tau_heat"], fit.std("tau_heat"))
    return False


def run_round(prob: Problem, base: Fit, neutral: list[Values], candidates: list[str],
              progress: Callable[[int, int, str, float], None] | None = None
              ) -> dict[str, Fit]:
    """Fit every candidate added to ``base`` (multi-start) [-]; the hot start with the
    one-parameter heat laws and the law chosen for heat transfer when both are candidates.

    Parameters
    ----------
    prob : Problem
        The trace.
    base : Fit
        Current model.
    neutral : list of dict
        Neutral starting values of the current model's parameters [SI units].
    candidates : list of str
        Effects to try.
    progress : callable, optional
        Called after each candidate with (its number from 1, how many, name, seconds).
    """
    out: dict[str, Fit] = {}
    # heat transfer first: the hot start takes its law or a one-parameter one (at most one
    # parameter more, the wall)
    order = sorted(candidates, key=lambda c: c == HOT_START)
    for i, cand in enumerate(order):
        t0 = time.perf_counter()
        law = out["heat_transfer"].model.heat_law if (
            cand == HOT_START and "heat_transfer" in out) else None
        out[cand] = fit_candidate(prob, base, neutral, cand, law)
        if progress is not None:
            progress(i + 1, len(candidates), cand, time.perf_counter() - t0)
    refit_contenders(prob, base, neutral, out, prob.settings.bic_threshold)
    return out


def decide(base: Fit, fits: dict[str, Fit], threshold: float,
           refused: dict[str, str] | None = None
           ) -> tuple[dict[str, float], str, list[str]]:
    """Delta-BIC per candidate, winner ('none' if no claim) and its ambiguity set.

    Candidates in ``refused`` (name -> reason) are never the winner nor in its set. A
    nested extension (:data:`NESTED`: the hot start is heat transfer plus the wall
    temperature) is named only when it beats the effect it extends by the threshold;
    within it, the simpler effect is named and the extension is no ambiguity.

    A variant of the winner (the same leak in another law or place:
    :data:`~pneumatic_unload.discrepancy.ambiguity.VARIANTS`) is in the set when its
    chi^2 is within the threshold of the winner's, whatever its BIC: the two are not
    nested, so the ln(n) per extra parameter is no evidence between the laws (at n >
    e^10 = 22 k samples one extra parameter alone costs more than the threshold, and an
    orifice-law leak fitting as well as a laminar one would never be in the set).
    """
    delta = {k: base.bic - f.bic for k, f in fits.items()}
    order = [k for k in sorted(delta, key=lambda k: -delta[k]) if k not in (refused or {})]
    for ext, sub in NESTED.items():
        if ext in order and sub in order and delta[ext] - delta[sub] <= threshold:
            order.remove(ext)
    if not order or delta[order[0]] <= threshold:
        return delta, "none", []
    win = order[0]
    amb = [k for k in order[1:] if delta[win] - delta[k] <= threshold or (
        frozenset({win, k}) in VARIANTS and fits[k].chi2 - fits[win].chi2 <= threshold)]
    return delta, win, amb


def end_level_evidence(prob: Problem, base: Fit, fits: dict[str, Fit]) -> tuple[float, str]:
    """How far the measured end of the unload sits from every physics model [-].

    A transducer offset or gain shifts the end level (p_atm, stated; a charge's supply,
    stated) where no physics effect can: a leak, heat transfer or a pipe volume all end at
    p_atm (a charge's heat exchange at the supply). The best model of the round without a
    transducer effect (the base or a physics candidate) is compared with the samples where
    its pressure is within :data:`END_FRACTION` of abs(p10 - end) of the end level: z =
    mean residual / its standard error (AR(1) noise).

    Returns
    -------
    tuple
        (|z| [-], a sentence saying what was compared); z is 0 when the trace has no end to
        compare.
    """
    physics = [f for f in (base, *(f for k, f in fits.items() if k not in SENSOR_EFFECTS))
               if not any(e in SENSOR_EFFECTS for e in f.effects)]
    if not physics:
        return 0.0, "every model of the round has a transducer effect already"
    best = min(physics, key=lambda f: f.bic)
    cfg = best.model.config(best.theta)
    m = best.model.signal(best.theta, prob.t)
    level, p10 = cfg.end_pressure, cfg.initial_pressure
    end = (prob.t > best.theta["t_open"]) & (
        np.abs(m - level) < END_FRACTION * abs(p10 - level))
    n = int(np.count_nonzero(end))
    label = ", ".join(best.effects) or "the baseline"
    what = "charge" if cfg.direction == "charge" else "discharge"
    if n < END_SAMPLES:
        return 0.0, f"the record does not reach the end of the {what} ({n} samples)"
    r = prob.y[end] - m[end]
    rho = prob.noise.rho
    se = prob.noise.sigma * math.sqrt((1.0 + rho) / max(1.0 - rho, 1e-6) / n)
    z = abs(float(np.mean(r))) / se
    return z, (f"end level {float(np.mean(r)):+.4g} Pa from {label} over {n} samples "
               f"({z:.1f} standard errors; {'the supply' if what == 'charge' else 'p_atm'} "
               f"{'fitted' if prob.settings.end_fitted else 'stated'})")


def sensor_refusals(prob: Problem, base: Fit, fits: dict[str, Fit], threshold: float
                    ) -> dict[str, str]:
    """Transducer candidates that would be named (the winner or in its set) but lack
    evidence a physics effect cannot give (name -> reason): the end level must disagree
    with every physics model by more than :data:`END_Z` standard errors."""
    _, win, amb = decide(base, fits, threshold)
    cands = [k for k in (win, *amb) if k in SENSOR_EFFECTS]
    if not cands:
        return {}
    z, what = end_level_evidence(prob, base, fits)
    if z > END_Z:
        return {}
    return {k: f"no evidence a physics effect cannot give: {what}" for k in cands}


def look_alikes(named: str, ambiguous_with: list[str], remaining: list[str]) -> list[str]:
    """Candidates not to add once ``named`` is in the model: the same physics in another
    law or place, and those the data could not tell from it in its round (within the BIC
    threshold): either would describe the signature already explained."""
    return [c for c in remaining if c == named or c in ambiguous_with or same_physics(c, named)]


def residual_noise(prob: Problem, fit: Fit) -> Problem:
    """The trace with its noise model refitted on the residual of ``fit``.

    The AR(1) sigma and rho of the sample residual y - model [Pa, -], never below the
    trace's own noise model: what the named effects leave unexplained counts as noise
    when a further effect is tested, so that it must explain more than that structure to
    earn its place. Same samples and bins; SI units.
    """
    m = fit.model.signal(fit.theta, prob.t)
    r = prob.y - m
    r = r - float(np.mean(r))
    ss = float(r @ r)
    rho_r = float(np.clip(r[1:] @ r[:-1] / ss, 0.0, 0.99)) if ss > 0 else 0.0
    sig_r = math.sqrt(ss / max(r.size - 1, 1))
    base = prob.noise
    noise = NoiseModel(sigma=max(base.sigma, sig_r), rho=max(base.rho, rho_r), n=int(r.size),
                       source=f"residual of ({', '.join(fit.effects)})",
                       sigma_plateau=base.sigma_plateau, sigma_highpass=base.sigma_highpass,
                       highpass_weight=base.highpass_weight)
    out = copy.copy(prob)
    out.noise = noise
    out.trace = Trace(prob.t, prob.y, noise, prob.start.t_open, edges=prob.lik.edges)
    out.trace.deadline = prob.trace.deadline  # the run's time limit holds here too
    out.lik = out.trace.lik
    return out


def structure_refusals(prob: Problem, named: Diagnostics, fits: dict[str, Fit],
                       delta: dict[str, float], threshold: float) -> dict[str, str]:
    """Further candidates that fit model error, not a missing effect (name -> reason).

    Applies when the effects already named leave a residual at the noise level in size
    (normalised RMS ``named.nrms`` <= :data:`~pneumatic_unload.discrepancy.types.
    NRMS_LIMIT`) and the search goes on only because it is not white: a further effect
    then earns its place only by explaining that structure, i.e. by leaving a white
    residual (Ljung-Box on ``prob``'s own noise model). A candidate that beats the model
    by the BIC threshold but leaves the residual as structured is chipping at the model's
    own limits (on a long record, a heat law that does not quite follow the gas: every
    leak and volume candidate then gains about alike, each moving C its own way); the
    remaining structure is reported as unexplained instead. Below the threshold nothing
    is tested (not claimed anyway).
    """
    if named.nrms > NRMS_LIMIT:
        return {}
    out: dict[str, str] = {}
    for k, f in fits.items():
        if delta[k] <= threshold:
            continue
        q = fit_quality(prob, f)
        if not q.white:
            out[k] = (f"the effects named already explain the trace at the noise level "
                      f"(normalised RMS {named.nrms:.4f}) and {k} leaves the residual "
                      f"structured (normalised RMS {q.nrms:.4f}, Ljung-Box p "
                      f"{q.ljung_box_p:.2g}): it fits the model's limits, not a missing "
                      "effect")
    return out


def bound_refusals(base: Fit, fits: dict[str, Fit], delta: dict[str, float],
                   threshold: float) -> dict[str, str]:
    """Further candidates whose own parameters sit at a bound of their range (name ->
    reason).

    A further effect is added to effects already named; one that beats them by the BIC
    threshold only with a parameter of its own pinned at a bound (within
    :data:`~pneumatic_unload.discrepancy.ambiguity.AT_BOUND` of it: an orifice leak's b at
    0.02, a pipe conductance at its largest) is not describing physics of its kind: its
    optimum lies outside what the effect can be, so it is fitting what the named model
    leaves (the model's limits), and its C would move with that. It is refused with the
    reason; the first round's candidates are not judged by this (a winner at a bound there
    makes a C ambiguity: :mod:`~pneumatic_unload.discrepancy.ambiguity`). Below the
    threshold nothing is tested (not claimed anyway).
    """
    out: dict[str, str] = {}
    for k, f in fits.items():
        if delta[k] <= threshold:
            continue
        own = [q for q in at_bounds(f) if q not in base.theta]
        if own:
            vals = ", ".join(f"{q} = {f.theta[q]:.4g}" for q in own)
            out[k] = (f"its fit beats the effects named (delta-BIC {delta[k]:.1f}) only with "
                      f"{vals} at the bound of its range: it fits the model's limits, not "
                      "a missing effect of its kind")
    return out
