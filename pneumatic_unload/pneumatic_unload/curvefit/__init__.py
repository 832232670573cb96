# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The model-based curve fits of a record: an unload's final curve fit, and the re-heating.

The final curve fit gives C, b, the start, p10 and the heat law the data choose, with what
feeds their uncertainty budgets; the re-heating after an aborted unload gives eq 23's p1_inf.

* :mod:`~pneumatic_unload.curvefit.fitting` - :func:`~pneumatic_unload.curvefit.fitting.fit_curve`,
  the final curve fit;
* :mod:`~pneumatic_unload.curvefit.curve_fit_result` - its result (fitted values, laws
  compared) and where the fitted samples lie;
* :mod:`~pneumatic_unload.curvefit.law_fit` - one heat law's fit;
* :mod:`~pneumatic_unload.curvefit.law_family` - the laws compared (hot starts, m held or
  fitted) and the information criterion;
* :mod:`~pneumatic_unload.curvefit.heat_law_offer` - which heat laws a record can carry;
* :mod:`~pneumatic_unload.curvefit.subsonic_offer` - whether a record carries the subsonic
  index m, and the budget line of holding it;
* :mod:`~pneumatic_unload.curvefit.shape_reading` - the flow curve's shape beyond the ISO
  law (the ellipse's exponent q freed, or two ISO elements in series) and the ISO (b, m)
  nearest it over r;
* :mod:`~pneumatic_unload.curvefit.linear_twin` - a fit's twin with one parameter more, to
  first order;
* :mod:`~pneumatic_unload.curvefit.temperature_evidence` - the logged gas temperature
  against the fitted model;
* :mod:`~pneumatic_unload.curvefit.wall_moves` - the wall's and the heat laws' moves of the
  fitted C and b (lines of their budgets);
* :mod:`~pneumatic_unload.curvefit.recovery` - SSE: the fit of the isochoric re-heating after
  an aborted unload (eq 23's p1_inf).

Every fit runs through the one engine, :mod:`pneumatic_unload.fit`. SI units: s, Pa
absolute, K, m^3, m^3/(s Pa).
"""
