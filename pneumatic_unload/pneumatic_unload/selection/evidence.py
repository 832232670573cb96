# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The information criterion of a fitted candidate model and the weights it gives.

BIC_k = chi^2_k + k_k ln n (Schwarz's criterion: -2 log-likelihood at the fit plus the
penalty of k_k free parameters over n samples), and the weights
w_k ~ exp(-(BIC_k - BIC_min) / 2), normalised over the candidates compared. The formula
and its reading are in :mod:`pneumatic_unload.selection`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping


def information_criterion(chi2: float, k: int, n: int) -> float:
    """Schwarz's Bayesian information criterion, chi^2 + k ln n [-].

    Parameters
    ----------
    chi2 : float
        -2 log-likelihood of the fit up to a constant shared by the candidates: the sum of
        squared residuals in units of one residual variance common to them [-].
    k : int
        Free parameters of the candidate [-].
    n : int
        Samples (or bins) the fit weighs [-]; at least 2.

    Returns
    -------
    float
        The criterion; NaN where chi^2 is not finite.

    Raises
    ------
    ValueError
        k negative or n below 2 (ln n would not penalise a parameter).
    """
    if k < 0 or n < 2:
        raise ValueError(f"information criterion needs k >= 0 and n >= 2 (got k {k}, n {n})")
    if not math.isfinite(chi2):
        return math.nan
    return float(chi2) + k * math.log(n)


def weights(criteria: Mapping[str, float], temperature: float = 1.0) -> dict[str, float]:
    """The candidates' weights exp(-(BIC_k - BIC_min) / (2 T)), normalised to sum to 1 [-].

    A candidate whose criterion is not finite (a fit that failed) has weight 0. The
    differences are taken from the lowest criterion, so no weight overflows or
    underflows to a 0/0.

    Parameters
    ----------
    criteria : mapping of str to float
        Each candidate's :func:`information_criterion`.
    temperature : float
        T >= 1, the samples per independent look at the misfit the candidates differ by
        (the criterion counted on n / T effective samples: a misfit correlated over T
        samples carries a T-th of the evidence white residuals would); 1: white residuals.

    Returns
    -------
    dict of str to float
        The weights, in the order of ``criteria``.

    Raises
    ------
    ValueError
        No candidate has a finite criterion.
    """
    if not temperature >= 1.0:
        raise ValueError(f"the weights' temperature must be at least 1 (got {temperature})")
    finite = {k: v for k, v in criteria.items() if math.isfinite(v)}
    if not finite:
        raise ValueError("no candidate model has a finite information criterion "
                         f"(candidates: {', '.join(criteria) or 'none'})")
    low = min(finite.values())
    raw = {k: math.exp(-0.5 * (v - low) / temperature) if k in finite else 0.0
           for k, v in criteria.items()}
    total = sum(raw.values())  # >= 1: the lowest's own term
    return {k: v / total for k, v in raw.items()}
