# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""pneumatic_unload: sonic conductance of pneumatic components from a tank discharge or
charge.

The ROS-free core never imports rclpy. Its parts, lowest first (``test/test_layout.py``'s
``LAYERS`` enforces the order): ``physics`` and ``charge`` (closed forms), ``config``,
``io`` and ``fit`` (the fitting engine), ``model``, ``uncertainty`` (the budgets),
``curvefit`` (the model-based C, b, m), ``estimation`` (streaming and batch),
``discrepancy``, ``analysis`` and ``testline``, then ``app`` (CLI, demo, launcher) and
``plc`` (OPC UA). The ROS 2 nodes live in ``pneumatic_unload.nodes``. SI units
everywhere: pressures in Pa absolute, temperatures in K, volumes in m^3, times in s, sonic
conductance C in m^3/(s Pa) (1 dm^3/(s bar) = 1e-8 m^3/(s Pa)).
"""

import os

__version__ = "0.1.0"

#: The environment variables that cap the threads of numpy's BLAS (OpenBLAS, MKL) and of
#: OpenMP; they are read once, when numpy is first imported.
BLAS_THREAD_VARIABLES: tuple[str, ...] = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                          "OMP_NUM_THREADS")


def single_threaded_blas() -> None:
    """Run numpy's BLAS on one thread in this program (and the processes it starts): each
    of :data:`BLAS_THREAD_VARIABLES` set to 1 unless the environment sets it already.

    Called by the programs (the nodes, :mod:`pneumatic_unload.app`) before numpy is
    imported; a library import leaves the user's numpy alone. Why: the fit's matrices are
    small (a few parameters by hundreds of bins), so a second BLAS thread buys nothing,
    and on a 2-core machine whose other core serves DDS, it waits for that core: the live
    final fit's CPU p99 went 65 -> 22 ms at 10 kHz (``bench/bench_engine.py --part
    live``). One thread everywhere also makes the live node and the offline analysis do
    the same arithmetic by construction (live = offline exact).
    """
    for var in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(var, "1")
