# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discrepancy workflow: where do simulation and measurement disagree, and why?

Steps (SI units throughout: s, Pa absolute, K, m^3, m^3/(s Pa)):

0. **Noise model.** The AR(1) coefficient rho from the pre-step and end plateaus, sigma
   from the plateaus combined with a high-pass (local cubic residual) estimate over the
   whole trace, so that short traces are normalised by the noise they actually carry
   (:func:`~pneumatic_unload.fit.noise.estimate_noise`); the likelihood prewhitens
   the residual so that correlated noise does not count as information. Every fit runs
   on the package's one engine (:mod:`pneumatic_unload.fit`) and model
   (:mod:`pneumatic_unload.model`): this module only orchestrates.
1. **Baseline.** Multi-start least-squares fit of the adiabatic discharge (C, b, t_open,
   p10 [, p_atm]); diagnostics: normalised RMS, Ljung-Box whiteness, residual per phase
   (pre-step, choked, subsonic, plateau).
2. **Candidates.** For each effect, the whole model is refitted with the effect added,
   from several starts: from the baseline fit *and* from the neutral (unloading-time)
   values of the baseline parameters, each with small and large effect sizes. Heat
   transfer (and the hot start) is fitted with the engine's whole law family, the
   two-parameter laws where the record carries their second parameter, and the law with
   the lowest BIC kept (:func:`~pneumatic_unload.discrepancy.search.fit_candidate`), so
   that a further effect is tested against the best heat law, not one of them; the hot
   start is fitted with the one-parameter laws and heat transfer's law, no other
   two-parameter one (it extends heat transfer by the wall temperature alone).
3. **Decision** by BIC = chi^2 + k ln(n): an effect is claimed only if it beats the
   current model by more than ``bic_threshold`` (10); it is named alone only if the
   runner-up is more than 10 behind, otherwise the ambiguity set is reported with the
   extra data that would separate its members; a variant of the winner (the same leak in
   another law or place) whose chi^2 is within 10 of the winner's is in the set whatever
   its BIC (the laws are not nested: its extra parameter's ln n is no evidence between
   them). A nested extension (the hot start: heat
   transfer with the wall temperature fitted) must beat the effect it extends by 10. A
   transducer effect (offset, gain) is claimed only with evidence no physics effect can
   give: the end level disagreeing with every physics model of the round
   (:func:`~pneumatic_unload.discrepancy.search.sensor_refusals`).
4. **C range.** Models that fit about equally but give different C (BIC window, white
   fits, a winner at a bound, a placement or law variant, a leak in parallel with the
   component) are reported as a C ambiguity, the range spanning their 3-sigma intervals;
   whatever the verdict, the component's C with a hidden parallel leak, which no record
   bounds, is stated apart (:mod:`~pneumatic_unload.discrepancy.ambiguity`).
5. **Gap.** RMS before and after, the effect's parameters with 95 % intervals (linear from
   the Jacobian, replaced by the profile likelihood when the linear one is unreliable); an
   interval that does not close within the parameter range means "not identifiable".
6. **Greedy.** While the residual is still structured, a further effect is added the same
   way (at most ``max_effects``), tested against the model with the effects named and the
   noise model refitted on its residual; when the effects named leave a residual at the
   noise level that is only not white, a further effect must also leave it white (else it
   fits the model's limits and the residual is reported as unexplained:
   :func:`~pneumatic_unload.discrepancy.search.structure_refusals`); a further effect that
   beats them only with a parameter of its own at a bound of its range is refused too
   (:func:`~pneumatic_unload.discrepancy.search.bound_refusals`), and so is one that the
   named heat transfer with another law of its family explains about as well
   (:func:`~pneumatic_unload.discrepancy.laws.law_refusals`); the effects named and
   their look-alikes (the same physics in another law or place, the round's ambiguity
   set) are not tried again.
   A candidate that beats its round's model by the threshold but whose fit ran out of
   iterations, or ended with a parameter of its own at a bound, is fitted out from every
   start first (:func:`~pneumatic_unload.discrepancy.search.refit_contenders`). When the
   tank's L/D is not stated, the final model's natural heat law is also fitted at other
   L/D values (:func:`~pneumatic_unload.discrepancy.laws.length_diameter_choice`).
7. **Temperature.** A logged gas temperature is fitted with the final model (T10 and the
   thermometer's lag: :func:`~pneumatic_unload.discrepancy.thermo.joint_fit`, the
   estimator's joint fit and rule), which is reported with it where its gas follows the
   log; each member of C's range is fitted with it too, and those the log rules out leave
   the range (:func:`~pneumatic_unload.discrepancy.thermo.temperature_words`). A final
   model whose gas contradicts the log is flagged with the likely reason (e.g. the wall
   temperature).

**Time bound.** A run is bounded in evaluations: at most ``max_effects`` (3) rounds of at
most 11 candidates, each fitted from at most 10 starts (two one-parameter heat laws x 5,
and two starts for each of the two two-parameter laws) screened for at most 12
Levenberg-Marquardt iterations and one full search per law of at most 100, an iteration
costing at most (free parameters + 12) model evaluations, each evaluation bounded by the
integrator's step budget (:data:`pneumatic_unload.model.ode.MAX_STEPS` per segment); the
profiles add a fixed number of constrained fits per reported parameter. In seconds, the
wall-clock cap ``settings.time_limit`` (default 600 s) stops the fit under way at its next
evaluation: in the baseline or the first round that is a :class:`DiscrepancyError` (no
verdict), later the greedy search ends with the effects named so far (said in the notes)
and the intervals are linear. Typical runs take seconds
(``bench/bench_discrepancy_speed.py``).

A constant geometric factor on C (the paper's L/D effect) enters the model only through
the product f C, so it is reported as not identifiable from one trace; several runs with
different tank geometries identify it (:mod:`pneumatic_unload.discrepancy.multirun`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.discrepancy.ambiguity import (
    C_MEANING,
    C_MEANING_CHARGE,
    conductance_ambiguity,
    describe,
)
from pneumatic_unload.discrepancy.intervals import (
    geometry_factor_check,
    intervals,
    temperature_check,
)
from pneumatic_unload.discrepancy.laws import law_refusals, length_diameter_choice
from pneumatic_unload.discrepancy.multirun import GeometryLaw, fit_geometry_law
from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.search import (
    bound_refusals,
    decide,
    diagnose,
    fit_quality,
    look_alikes,
    residual_noise,
    run_round,
    sensor_refusals,
    structure_refusals,
)
from pneumatic_unload.discrepancy.thermo import joint_fit, judge, readings, temperature_words
from pneumatic_unload.discrepancy.types import (
    Diagnostics,
    DiscrepancyError,
    DiscrepancyResult,
    DiscrepancySettings,
    Fit,
    Round,
)
from pneumatic_unload.fit.profile import Interval
from pneumatic_unload.fit.trace import FitTimeout
from pneumatic_unload.model.effects import HOT_START, separating_data
from pneumatic_unload.model.parametric import CHARGE_FIT_EFFECTS

FloatArray = NDArray[np.float64]


def find_discrepancy(t: FloatArray, p: FloatArray, settings: DiscrepancySettings, *,
                     temperature: tuple[FloatArray, FloatArray] | None = None,
                     progress: Callable[[str], None] | None = None
                     ) -> DiscrepancyResult:
    """Run the discrepancy workflow on one recorded discharge (or, with ``settings.direction``
    'charge', one charge).

    Parameters
    ----------
    t : ndarray
        Sample instants [s] (any origin).
    p : ndarray
        Measured pressure [Pa absolute].
    settings : DiscrepancySettings
        Rig data and options.
    temperature : tuple of ndarray, optional
        Measured gas temperature (instants [s] on the same clock as t, values [K]): not
        in the search of effects; fitted with the final model and the models of C's range
        (step 7).
    progress : callable, optional
        Called with one line per step (baseline, each candidate of each round, intervals,
        end), e.g. ``"discrepancy: round 1, candidate 3/10 sensor_lag 0.4 s"``.

    Returns
    -------
    DiscrepancyResult
        The named effect(s), the ambiguity set, the gap before and after, intervals.

    Raises
    ------
    DiscrepancyError
        No unload, non-finite samples, too short a trace; the time limit reached before
        the first round ended.
    """
    t_wall0 = time.perf_counter()
    say = progress if progress is not None else (lambda _msg: None)
    prob = Problem(t, p, settings)
    if settings.time_limit is not None:
        prob.trace.deadline = time.monotonic() + settings.time_limit - (
            time.perf_counter() - t_wall0)
    thr = settings.bic_threshold
    # 1. baseline, multi-start over b
    neutral = [*prob.neutral_thetas(0.3), *prob.neutral_thetas(0.5)]
    try:
        base = prob.fit(prob.model(()), neutral)
    except FitTimeout as exc:
        raise _timeout(settings, "during the baseline fit") from exc
    say(f"discrepancy: baseline {time.perf_counter() - t_wall0:.1f} s "
        f"({prob.lik.n} samples, {prob.lik.n_bins} bins)")
    before, m_before = diagnose(prob, base)
    # 2-5. greedy rounds
    current = base
    current_diag = before
    claimed: list[str] = []
    rounds: list[Round] = []
    first_effect, first_amb = "none", []
    remaining = [c for c in settings.candidates
                 if not (c == HOT_START and settings.fit_wall_temperature)]
    untried = [c for c in remaining if settings.charge and c not in CHARGE_FIT_EFFECTS]
    remaining = [c for c in remaining if c not in untried]
    neutral_cur = prob.neutral_thetas(0.4)
    prob_k, prob_final = prob, prob
    timed_out = ""
    while remaining and len(claimed) < settings.max_effects:
        if claimed and not current_diag.structured:
            break
        k_round = len(rounds) + 1

        def step(i: int, n: int, cand: str, dt: float, k: int = k_round) -> None:
            say(f"discrepancy: round {k}, candidate {i}/{n} {cand} {dt:.1f} s")

        try:
            base_k = current
            if claimed:
                # a further effect must earn its place against the effects named, with the
                # noise model refitted on their residual
                prob_k = residual_noise(prob, current)
                base_k = prob_k.fit(current.model, [dict(current.theta)], max_nfev=60)
            fits = run_round(prob_k, base_k, neutral_cur, remaining, progress=step)
        except FitTimeout as exc:
            if not rounds:
                raise _timeout(settings, "during the first round of candidates") from exc
            timed_out = (f"time limit of {settings.time_limit:g} s reached in round "
                         f"{k_round}: the greedy search stopped there (the effects named "
                         "before it stand; intervals linear)")
            break
        refused = sensor_refusals(prob_k, base_k, fits, thr)
        if claimed:
            # a further effect must explain the structure the named effects leave
            delta, _, _ = decide(base_k, fits, thr, refused)
            refused.update(structure_refusals(prob, current_diag, {
                k: f for k, f in fits.items() if k not in refused}, delta, thr))
            # ... and with parameters of its own inside their range
            refused.update(bound_refusals(base_k, {
                k: f for k, f in fits.items() if k not in refused}, delta, thr))
            # ... and against the named heat transfer with its law at its best
            try:
                refused.update(law_refusals(prob_k, base_k, {
                    k: d for k, d in delta.items() if k not in refused}, thr))
            except FitTimeout:
                timed_out = (f"time limit of {settings.time_limit:g} s reached in round "
                             f"{k_round} (refitting the heat law): the greedy search "
                             "stopped there (the effects named before it stand; "
                             "intervals linear)")
                break
        delta, win, amb = decide(base_k, fits, thr, refused)
        rounds.append(Round(base_effects=current.effects, base_bic=base_k.bic, fits=fits,
                            delta_bic=delta, winner=win, ambiguous_with=amb, base=base_k,
                            noise_source=prob_k.noise.source, refused=refused))
        if win == "none":
            break
        if not claimed:
            first_effect, first_amb = win, amb
        claimed.append(win)
        current, prob_final = fits[win], prob_k
        # neutral starts of the next round: neutral baseline + this round's winner values
        neutral_cur = [{**th, **{k: v for k, v in current.theta.items() if k not in th}}
                       for th in neutral_cur]
        drop = look_alikes(win, amb, remaining)
        remaining = [c for c in remaining if c not in drop]
        current_diag, _ = diagnose(prob, current)
    # the tank's L/D not stated: the natural heat law at the L/D the data prefer
    try:
        current, ld_members, ld_note = length_diameter_choice(prob_final, current, thr)
    except FitTimeout:
        ld_members, ld_note = [], ("the tank's L/D is not stated and the time limit passed "
                                   "while the natural heat law was refitted at other L/D "
                                   "values: the default L/D is kept, unchecked")
        timed_out = timed_out or f"time limit of {settings.time_limit:g} s reached"
    # the logged gas temperature: the final model fitted with it (T10 and the
    # thermometer's lag), reported when its gas follows the log, as the estimator does
    joint_final: dict[str, Any] = {}
    got = readings(prob_final, temperature) if temperature is not None else "no log"
    if not isinstance(got, str):
        say("discrepancy: the final model fitted with the logged gas temperature")
        joint_final = joint_fit(prob_final, current, *got)
        if joint_final.get("follows"):
            current = joint_final["fit"]
            prob_final = prob_final.with_channel(joint_final["channel"])
    after, m_after = diagnose(prob, current)
    names = [q for q in current.result.params.free if q not in base.result.params.names]
    t_iv = time.perf_counter()
    try:
        params = intervals(prob_final, current, names,
                           profile=settings.profile and not timed_out) if names else {}
    except FitTimeout:
        params = intervals(prob_final, current, names, profile=False)
        timed_out = timed_out or (f"time limit of {settings.time_limit:g} s reached in the "
                                  "profile checks: the intervals are linear")
    for q in {prob, prob_final}:
        q.trace.deadline = None  # what follows is a fixed, small number of evaluations
    params.update(intervals(prob_final, current, ["C"], profile=False))
    say(f"discrepancy: intervals {time.perf_counter() - t_iv:.1f} s")
    extra = separating_data([first_effect, *first_amb]) if first_amb else []
    geo = geometry_factor_check(prob_final.with_channel(None), current)
    notes = [C_MEANING_CHARGE if settings.charge else C_MEANING] + (
        [timed_out] if timed_out else []) + ([ld_note] if ld_note else [])
    if untried:
        notes.append(f"a charge: {', '.join(untried)} not tried (the charge's model takes "
                     f"{', '.join(CHARGE_FIT_EFFECTS)})")
    if prob.noise.source == "differences":
        notes.append("no plateau long enough for the noise model: sigma from second "
                     "differences of the whole trace, rho assumed 0")
    notes += [f"{k} not claimed: {why}" for r in rounds for k, why in r.refused.items()]
    verdict = _verdict(first_effect, first_amb, claimed, before, after, params)
    if timed_out:
        verdict += f"; {timed_out}"
    quality: dict[int, Diagnostics] = {}

    def fit_quality_of(f: Fit) -> Diagnostics:
        if id(f) not in quality:
            quality[id(f)] = after if f is current else fit_quality(prob, f)
        return quality[id(f)]

    c_amb = conductance_ambiguity(base, rounds, current, thr, fit_quality_of,
                                  settings.model_uncertainty, ld_members)
    joint = None
    if temperature is not None:
        say("discrepancy: the logged gas temperature fitted with each model of C's range")
        joint = judge(prob, [current, *c_amb.fits[1:]], temperature,
                      final=joint_final or None)
        verdict += temperature_words(joint, c_amb)
    if c_amb.ambiguous:
        verdict += "; " + describe(c_amb)
        extra += [x for x in c_amb.separating if x not in extra]
    res = DiscrepancyResult(
        effect=first_effect, ambiguous_with=first_amb, effects=claimed, verdict=verdict,
        parameters=params, noise=prob.noise, baseline=base, final=current, rounds=rounds,
        before=before, after=after, extra_data=extra, geometry_factor=geo, t=prob.t,
        y=prob.y, model_before=m_before, model_after=m_after, t_ref=prob.t_ref,
        n_samples=prob.lik.n, n_bins=prob.lik.n_bins, elapsed=0.0, settings=settings,
        notes=notes, conductance_ambiguity=c_amb, temperature_joint=joint)
    if temperature is not None:
        res.t_temperature = np.asarray(temperature[0], dtype=float) - prob.t_ref
        res.temperature = np.asarray(temperature[1], dtype=float)
        tc = temperature_check(prob, base, current, res.t_temperature, res.temperature,
                               joint_final)
        res.temperature_check = tc
        if tc.get("contradicts"):
            res.verdict += (f"; the logged gas temperature contradicts the fitted model "
                            f"(rms {tc['final']['rms']:.1f} K): likely "
                            f"{tc['likely_reason']}")
            res.extra_data.append(f"gas temperature: {tc['measure_next']}")
    res.elapsed = time.perf_counter() - t_wall0
    say(f"discrepancy: done in {res.elapsed:.1f} s")
    return res


def _timeout(settings: DiscrepancySettings, where: str) -> DiscrepancyError:
    """The error of a run whose time limit passed before any verdict was possible."""
    return DiscrepancyError(
        f"time limit of {settings.time_limit:g} s reached {where}: no verdict (raise "
        "--time-limit, or shorten the record around the unload)")


def _verdict(effect: str, amb: list[str], claimed: list[str], before: Diagnostics,
             after: Diagnostics, params: dict[str, Interval]) -> str:
    if effect == "none":
        if before.structured:
            return ("the baseline leaves a structured residual but no candidate effect "
                    "explains it better by the BIC threshold")
        return "no discrepancy: the baseline model explains the trace within noise"
    txt = f"missing effect: {effect}" if not amb else \
        f"missing effect: one of {', '.join([effect, *amb])} (the data cannot tell them apart)"
    if len(claimed) > 1:
        txt += f"; added greedily: {', '.join(claimed)}"
    txt += (f"; RMS {before.rms:.4g} Pa -> {after.rms:.4g} Pa "
            f"(normalised {before.nrms:.3f} -> {after.nrms:.3f})")
    bad = [k for k, v in params.items() if not v.identifiable and v.computed]
    if bad:
        txt += f"; not identifiable: {', '.join(bad)}"
    unknown = [k for k, v in params.items() if not v.computed]
    if unknown:
        txt += f"; uncertainty not computed: {', '.join(unknown)}"
    return txt


def find_discrepancy_runs(traces: list[tuple[FloatArray, FloatArray]],
                          settings: list[DiscrepancySettings]) -> tuple[
                              list[DiscrepancyResult], GeometryLaw]:
    """Run the workflow on several runs and fit the shared geometry law of C.

    Parameters
    ----------
    traces : list of (t [s], p [Pa absolute])
        One trace per run.
    settings : list of DiscrepancySettings
        One per run (their ``length_diameter_ratio`` are the tank geometries).

    Returns
    -------
    tuple
        (per-run results, :class:`~pneumatic_unload.discrepancy.multirun.GeometryLaw`).
    """
    if len(traces) != len(settings) or not traces:
        raise DiscrepancyError("one settings object per trace is needed")
    results = [find_discrepancy(t, p, s) for (t, p), s in zip(traces, settings, strict=True)]
    law = fit_geometry_law([s.length_diameter_ratio for s in settings],
                           [r.conductance for r in results],
                           [r.conductance_std() for r in results])
    return results, law
