# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The uncertainty budget of a sonic conductance C and of a critical pressure ratio b.

In the manner of the GUM: type A (the record's noise), type B (the inputs' stated standard
uncertainties: V, T10, the wall temperature, the transducer, p_atm), model form and model
limits, combined by root sum of squares and expanded with k = 2.

* :mod:`~pneumatic_unload.uncertainty.budget` - C's budget: its lines, their sensitivities
  (first order, from the exact isentropic inversion and the model's inversion at the
  crossing), the combined and expanded uncertainty, its text;
* :mod:`~pneumatic_unload.uncertainty.budget_b` - b's budget, with the lines of C's.

SI units: m^3/(s Pa), Pa, K, m^3; b is a pressure ratio [-].
"""
