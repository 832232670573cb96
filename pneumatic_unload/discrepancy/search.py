"""The search of the discrepancy workflow: diagnostics, candidate rounds, the BIC decision.

SI units: s, Pa.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.types import WHITE_P, Diagnostics, Fit
from pneumatic_unload.fit.noise import ljung_box
from pneumatic_unload.model.effects import HEAT_VARIANTS

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
    p_atm, b, p10 = cfg.atmosphere, cfg.critical_ratio, cfg.initial_pressure
    pre = prob.t < th["t_open"]
    plateau = ~pre & (p_true - p_atm < 0.002 * (p10 - p_atm))
    choked = ~pre & ~plateau & (p_true * b >= p_atm)
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

    d = Diagnostics(rms=rms, nrms=rms / sigma, ljung_box_p=p_lb,
                    white=bool(math.isfinite(p_lb) and p_lb >= WHITE_P), phases=phases,
                    corr_pressure=corr(rb, pb), corr_rate=corr(rb, rate))
    return d, m


def fit_candidate(prob: Problem, base: Fit, neutral: list[Values], cand: str) -> Fit:
    """The current model with ``cand`` added, fitted from several starts.

    Starts: the current fit and the neutral baseline values, each with a small and a large
    effect, and the nested start (the current fit with the effect almost off), so that the
    extended fit never ends worse than the model it extends. Heat transfer is fitted with
    each one-parameter law of :data:`~pneumatic_unload.model.effects.HEAT_VARIANTS` (the
    same number of parameters, so chi^2 compares them) and the better one kept.
    """
    effects = (*base.effects, cand)
    laws = [base.model.heat_law] if cand != "heat_transfer" else \
        [k for k, e in HEAT_VARIANTS.items() if len(e.params) == 1]
    best: Fit | None = None
    for law in laws:
        model = prob.model(effects, heat_law=law)
        bases = [dict(base.theta), *neutral]
        starts = prob.starts_for(model, bases, (cand,))
        if cand not in ("sensor_offset", "sensor_gain"):
            starts.append({**base.theta, **model.off_values(cand)})
        f = prob.fit(model, starts)
        if best is None or f.chi2 < best.chi2:
            best = f
    assert best is not None
    return best


def run_round(prob: Problem, base: Fit, neutral: list[Values], candidates: list[str],
              progress: Callable[[int, int, str, float], None] | None = None
              ) -> dict[str, Fit]:
    """Fit every candidate added to ``base`` (multi-start) [-].

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
    for i, cand in enumerate(candidates):
        t0 = time.perf_counter()
        out[cand] = fit_candidate(prob, base, neutral, cand)
        if progress is not None:
            progress(i + 1, len(candidates), cand, time.perf_counter() - t0)
    return out


def decide(base: Fit, fits: dict[str, Fit], threshold: float
           ) -> tuple[dict[str, float], str, list[str]]:
    """Delta-BIC per candidate, winner ('none' if no claim) and its ambiguity set."""
    delta = {k: base.bic - f.bic for k, f in fits.items()}
    if not delta:
        return delta, "none", []
    order = sorted(delta, key=lambda k: -delta[k])
    win = order[0]
    if delta[win] <= threshold:
        return delta, "none", []
    amb = [k for k in order[1:] if delta[win] - delta[k] <= threshold]
    return delta, win, amb
