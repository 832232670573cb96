# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The applications: the ``pneumatic-unload`` command line, the demo and the process
launcher, each run as a program (no other part of the package imports them).

* :mod:`~pneumatic_unload.app.cli` - ``pneumatic-unload``: analyze, simulate, recover,
  discrepancy (the console script's ``main``);
* :mod:`~pneumatic_unload.app.batch_cli` - its test-line commands: batch, results, report;
* :mod:`~pneumatic_unload.app.demo` - ``make demo``: simulator, estimator and recorder as
  processes over DDS;
* :mod:`~pneumatic_unload.app.launch` - a minimal process launcher for the nodes
  (``python -m pneumatic_unload.app.launch pneumatic_unload/launch/bench.launch.yaml``; ROS-free).
"""

from pneumatic_unload import single_threaded_blas

single_threaded_blas()  # before numpy: every program here (and its Dask workers)
