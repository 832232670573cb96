# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The final fit as one estimator: candidate models fitted in turn, weighed by one rule.

:func:`final_fit` fits every :class:`~pneumatic_unload.model.candidates.Candidate` to the
record through the one engine (each candidate's fit is
:func:`~pneumatic_unload.curvefit.law_fit.fit_law`), scores them by the information
criterion and reports C, b and m as model averages (:mod:`pneumatic_unload.selection`):

    BIC_k = chi^2_k / s^2 + k_k ln n,   w_k ~ exp(-(BIC_k - BIC_min) / (2 T)),
    x = sum_k w_k x_k,   u^2(x) = sum_k w_k u_k^2 + sum_k w_k (x_k - x)^2,

s^2 the residual variance of the lowest-chi^2 candidate (inflated where its residual is
structured, as each candidate's covariance is), n the samples, u_k each candidate's
standard deviation from its covariance. T is the number of samples per independent look at
the misfit by which the candidates differ: the heat exchange's misfit is a smooth function
of time on the scale of the discharge's own time constant tau0 = V / (gamma p_N C), so a
record sampled at f holds one look per f tau0 samples, T = f tau0 (:func:`misfit_looks`),
and the criterion's differences count n / T looks, not n samples. T enters the weights
alone: each candidate's covariance is its own residual's, white within the noise, so the
within term is not scaled. There is no other rule and no threshold: a candidate that fails
to fit, or that does not determine b (or m), is left out of that quantity's average and
says why.

This is the estimator built beside the curve fit of :mod:`pneumatic_unload.curvefit`
(its offers, readings and twins); ``bench/bench_final_fit_rule.py`` compares the two on
records the package did not make. SI units: s, Pa absolute, K, m^3/(s Pa).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.curvefit.curve_fit_result import CurveFit, CurveSpan
from pneumatic_unload.curvefit.law_family import criterion
from pneumatic_unload.curvefit.law_fit import curve_fit_trace, fit_law, heat_of, start_from
from pneumatic_unload.model.candidates import Candidate, default_candidates
from pneumatic_unload.selection.averaging import ModelAverage, model_average
from pneumatic_unload.selection.evidence import weights

FloatArray = NDArray[np.float64]

#: Evaluation budget of one candidate's fit [-] (the curve fit's first fits' budget).
CANDIDATE_NFEV = 200


@dataclass(frozen=True)
class CandidateFit:
    """One candidate's fit and its place in the average.

    Attributes
    ----------
    candidate : Candidate
    fit : CurveFit
        Its fitted values and standard deviations.
    chi2 : float
        Its sum of squared residuals [Pa^2].
    k : int
        Its free parameters [-].
    criterion : float
        Its BIC [-] (chi^2 in units of the common residual variance).
    weight : float
        Its weight w_k [-].
    """

    candidate: Candidate
    fit: CurveFit
    chi2: float
    k: int
    criterion: float
    weight: float


@dataclass(frozen=True)
class FinalFit:
    """The final fit: the candidates, the rule's temperature and the model averages.

    Attributes
    ----------
    candidates : tuple of CandidateFit
        Every candidate fitted, in the order tried.
    failed : mapping of str to str
        Candidates that could not be fitted: name -> why.
    temperature : float
        The rule's T [-].
    conductance : ModelAverage
        C [m^3/(s Pa)].
    critical_ratio : ModelAverage or None
        b [-]; None where no candidate determines it.
    subsonic_index : ModelAverage or None
        m [-] over the candidates that fit it; None where none does.
    """

    candidates: tuple[CandidateFit, ...]
    failed: Mapping[str, str]
    temperature: float
    conductance: ModelAverage
    critical_ratio: ModelAverage | None
    subsonic_index: ModelAverage | None

    @property
    def best(self) -> CandidateFit:
        """The candidate of largest weight (lowest criterion)."""
        return max(self.candidates, key=lambda c: c.weight)


def misfit_looks(rate: float, volume: float, conductance: float, gamma: float) -> float:
    """The rule's T [samples]: the samples per discharge time constant, f tau0 with tau0 =
    V / (gamma p_N C) (p_N = 1e5 Pa, eq 28's starting time constant at T_N), at least 1.

    Parameters
    ----------
    rate : float
        Sampling rate f [Hz].
    volume, conductance, gamma : float
        V [m^3], C [m^3/(s Pa)], the gas's gamma [-].
    """
    tau0 = volume / (gamma * 1e5 * conductance)
    return max(1.0, rate * tau0)


def final_fit(t: FloatArray, p: FloatArray, settings: EstimatorSettings, *, t_start: float,
              p10: float, p_atm: float, conductance: float,
              candidates: tuple[Candidate, ...] | None = None,
              temperature: float | None = None, hold: tuple[str, ...] = ()) -> FinalFit:
    """Fit every candidate to the record and average C, b and m over them.

    Parameters
    ----------
    t, p : ndarray
        Samples [s], [Pa absolute] from the plateau before the opening to the record's
        end.
    settings : EstimatorSettings
        Tank, gas and inputs (the heat model 'natural': the candidates' heat laws fitted).
    t_start, p10, p_atm, conductance : float
        Starting values [s], [Pa], [Pa], [m^3/(s Pa)] (the crossing's).
    candidates : tuple of Candidate, optional
        The candidate models (default:
        :func:`~pneumatic_unload.model.candidates.default_candidates`). A candidate
        with m fitted starts from the same law's fit with m held where that was fitted
        before it.
    temperature : float, optional
        The rule's T >= 1 (default :func:`misfit_looks` at the record's rate and the
        lowest-chi^2 candidate's C; 1 counts every sample as an independent look).
    hold : tuple of str
        't_open' and/or 'p10' held at what was given (a record that begins at the
        opening; a given initial pressure).

    Returns
    -------
    FinalFit

    Raises
    ------
    ValueError
        Fewer than 8 samples, mismatched arrays, T below 1, or no candidate could be fitted
        (the message gives each one's reason).
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(p, dtype=float)
    if t.shape != p.shape or t.ndim != 1 or t.size < 8:
        raise ValueError(f"the final fit needs matching 1-d arrays of at least 8 samples "
                         f"(got t {t.shape}, p {p.shape})")
    if temperature is not None and not temperature >= 1.0:
        raise ValueError(f"the rule's temperature must be at least 1 (got {temperature})")
    if settings.heat_model != "natural":
        raise ValueError("the final fit's candidates are heat laws: it needs the heat "
                         f"model 'natural' (got {settings.heat_model!r})")
    cands = default_candidates() if candidates is None else candidates
    tr = t - t[0]
    trace = curve_fit_trace(tr, p, t_start - float(t[0]))
    dt = float(np.median(np.diff(tr[:100_001])))
    span = CurveSpan(float(t[0]), float(t[-1]), float(tr[-1]), int(t.size), dt)
    common = {"t_start": t_start, "p10": p10, "p_atm": p_atm, "conductance": conductance,
              "fit_heat": True, "trace": trace, "hold": hold}
    made: dict[Candidate, tuple[CurveFit, float, int]] = {}
    failed: dict[str, str] = {}
    for cand in sorted(cands, key=lambda c: c.fit_m):  # m held first: the m-free starts
        held = made.get(Candidate(cand.heat_law, False, cand.fit_wall, cand.fit_offset))
        start = start_from(held[0], span.t_ref, **heat_of(held[0])) \
            if cand.fit_m and held is not None else None
        try:
            got = fit_law(span, settings, law=cand.heat_law, fit_m=cand.fit_m,
                          fit_wall=cand.fit_wall, fit_offset=cand.fit_offset, start=start,
                          explore=start is None, max_nfev=CANDIDATE_NFEV, **common)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            failed[cand.name] = str(exc)
            continue
        if not (math.isfinite(got[1]) and math.isfinite(got[0].conductance)):
            failed[cand.name] = "the fit did not converge to finite values"
            continue
        made[cand] = got
    if not made:
        raise ValueError("no candidate model could be fitted to the record: " + "; ".join(
            f"{k}: {v}" for k, v in failed.items()))
    ref = min(made.values(), key=lambda f: f[1])[0]
    by_name = criterion({c.name: f for c, f in made.items()}, span.n)
    crit = {c: by_name[c.name] for c in made}
    if temperature is None:
        temperature = misfit_looks(1.0 / dt, settings.volume, ref.conductance,
                                   settings.gas.gamma)
    w = weights({c.name: v for c, v in crit.items()}, temperature)
    fits = tuple(CandidateFit(c, f[0], f[1], f[2], crit[c], w[c.name])
                 for c, f in made.items())
    return FinalFit(fits, failed, temperature, _average(fits, "conductance"),
                    _average_or_none(fits, "critical_ratio"),
                    _average_or_none(tuple(f for f in fits if f.candidate.fit_m),
                                     "subsonic_index"))


def _average(fits: tuple[CandidateFit, ...], attr: str) -> ModelAverage:
    values = {f.candidate.name: getattr(f.fit, attr) for f in fits}
    variances = {f.candidate.name: getattr(f.fit, attr + "_std") ** 2 for f in fits}
    return model_average(values, {f.candidate.name: f.weight for f in fits}, variances)


def _average_or_none(fits: tuple[CandidateFit, ...], attr: str) -> ModelAverage | None:
    if not any(math.isfinite(getattr(f.fit, attr)) and f.weight > 0.0 for f in fits):
        return None
    return _average(fits, attr)
