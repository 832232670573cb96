# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Choosing among candidate models and averaging over them: the one rule.

Every path that weighs fitted models against each other (the final curve fit's heat laws,
its readings of the flow curve's shape and of a transducer's zero, the discrepancy
workflow's candidate effects) scores them by one information criterion and turns the
scores into weights by one formula:

.. math::

   \\mathrm{BIC}_k = \\chi^2_k + k_k \\ln n, \\qquad
   w_k = \\frac{\\exp(-\\Delta_k / 2T)}{\\sum_j \\exp(-\\Delta_j / 2T)}, \\quad
   \\Delta_k = \\mathrm{BIC}_k - \\min_j \\mathrm{BIC}_j

(chi^2 in units of one residual variance common to the candidates, k_k free parameters,
n samples): at T = 1, w_k approximates the posterior probability of candidate k under
equal prior odds (Schwarz 1978; Kass and Raftery 1995). T >= 1 is the number of samples
per independent look at the misfit by which the candidates differ: where every candidate
is wrong in a way that is smooth in time, a difference in chi^2 accumulated over n samples
holds n / T looks' worth of evidence between them (the generalised, or tempered,
posterior with learning rate 1/T of Grunwald and van Ommen 2017, for misspecified models).
The caller states T: the final fit's is
:func:`pneumatic_unload.estimation.final_fit.misfit_looks`. A fitted quantity x is then
reported as the model average, with the law of total variance for its uncertainty:

.. math::

   \\bar x = \\sum_k w_k x_k, \\qquad
   u^2(\\bar x) = \\underbrace{\\sum_k w_k u_k^2}_{\\text{within}}
   + \\underbrace{\\sum_k w_k (x_k - \\bar x)^2}_{\\text{between: model form}}

(Hoeting et al. 1999, eq 1-2; Burnham and Anderson 2002, sec. 4.3.2). Where a path reports
one candidate's value x_c instead of the mean (a candidate the record chose, whose
parameters feed the rest of the analysis), its model-form component is the weighted
spread about x_c, sum_k w_k (x_k - x_c)^2, which is the between term plus the square of
x_c's distance from the mean: never smaller.

* :mod:`~pneumatic_unload.selection.evidence` - the criterion and the weights;
* :mod:`~pneumatic_unload.selection.averaging` - the model average of one quantity.

No constant of this room is tuned: the criterion has none, and the weights take T from
their caller.
"""
