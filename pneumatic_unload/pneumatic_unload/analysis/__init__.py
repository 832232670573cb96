# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The offline analysis behind the command line and the test line: a record read and
analysed, its result as text, JSON and plots, and simulated runs written as bags.

* :mod:`~pneumatic_unload.analysis.records` - the input records: a CSV log read in chunks,
  or a bag, run through the estimator;
* :mod:`~pneumatic_unload.analysis.output` - the text and JSON output (one result, the inputs
  used, the budget) and the exit status;
* :mod:`~pneumatic_unload.analysis.plotting` - plots for engineers (matplotlib, Agg);
* :mod:`~pneumatic_unload.analysis.runs` - simulated runs written as bags (the simulator's
  samples and the streaming estimator's results).

SI units: s, Pa absolute, K (trade units, dm^3/(s bar), alongside in the text).
"""
