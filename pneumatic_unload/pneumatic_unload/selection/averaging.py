# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The model average of one fitted quantity over weighted candidate models.

x_bar = sum_k w_k x_k, with u^2 = within + between: within = sum_k w_k u_k^2 (each
candidate's own variance), between = sum_k w_k (x_k - x_bar)^2 (the model form); about a
reported candidate's value x_c, the model-form component is sum_k w_k (x_k - x_c)^2. See
:mod:`pneumatic_unload.selection` for the formula's source and reading.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class ModelAverage:
    """One quantity averaged over candidate models.

    Attributes
    ----------
    mean : float
        The weighted mean sum_k w_k x_k [unit of x].
    within : float
        sum_k w_k u_k^2, the candidates' own variances weighted [unit^2]; NaN where a
        candidate of positive weight gave none.
    between : float
        sum_k w_k (x_k - mean)^2, the model-form variance [unit^2].
    weights : mapping of str to float
        The weights of the candidates that carry the quantity, renormalised over them [-].
    values : mapping of str to float
        Each candidate's x_k [unit].
    """

    mean: float
    within: float
    between: float
    weights: Mapping[str, float]
    values: Mapping[str, float]

    @property
    def variance(self) -> float:
        """within + between [unit^2]: the law of total variance."""
        return self.within + self.between

    @property
    def std(self) -> float:
        """sqrt(within + between) [unit]."""
        return math.sqrt(self.variance)

    def spread_about(self, reference: float) -> float:
        """The model-form standard uncertainty of a reported value ``reference`` [unit]:
        sqrt(sum_k w_k (x_k - reference)^2) = sqrt(between + (mean - reference)^2)."""
        return math.sqrt(self.between + (self.mean - reference) ** 2)


def model_average(values: Mapping[str, float], weights: Mapping[str, float],
                  variances: Mapping[str, float] | None = None) -> ModelAverage:
    """The model average of a quantity (see :class:`ModelAverage`).

    Parameters
    ----------
    values : mapping of str to float
        x_k of each candidate [unit]; a candidate whose value is not finite does not carry
        the quantity and is left out, the others' weights renormalised.
    weights : mapping of str to float
        w_k [-] (:func:`pneumatic_unload.selection.evidence.weights`); a candidate missing
        here has weight 0.
    variances : mapping of str to float, optional
        u_k^2 [unit^2]; without them ``within`` is 0 (the caller carries each candidate's
        own variance elsewhere).

    Returns
    -------
    ModelAverage

    Raises
    ------
    ValueError
        No candidate of positive weight carries a finite value.
    """
    carried = {k: float(v) for k, v in values.items()
               if math.isfinite(v) and weights.get(k, 0.0) > 0.0}
    total = sum(weights[k] for k in carried)
    if not carried or not total > 0.0:
        raise ValueError("no candidate model of positive weight carries the quantity "
                         f"(candidates: {', '.join(values) or 'none'})")
    w = {k: weights[k] / total for k in carried}
    mean = sum(w[k] * x for k, x in carried.items())
    between = sum(w[k] * (x - mean) ** 2 for k, x in carried.items())
    within = 0.0 if variances is None else sum(
        w[k] * variances.get(k, math.nan) for k in carried)
    return ModelAverage(mean, within, between, w, carried)
