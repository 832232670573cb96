# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The cell's PLC's way in: the OPC UA server of the bench (asyncua), ROS-free.

:mod:`.address` declares the address space (object ``PneumaticUnload`` in namespace
``urn:pneumatic-unload``: the latest estimate, the state, the methods ``Measure``,
``StartMeasure``, ``Charge`` and ``Abort``; :func:`address_space` lists its nodes) and
:mod:`.bridge` serves it, :mod:`.security` says who may connect and who may measure,
:mod:`.calls` keeps a session alive through a method call of tens of seconds and checks
certificates and logins. The ROS node (:mod:`pneumatic_unload.nodes.opcua`) runs the
server in an asyncio loop of its own thread and hands it the estimates and the
measurements (the estimator's ``~/measure`` action).
"""

try:  # no rosdep key: an optional dependency, named in the error when missing
    import asyncua  # noqa: F401
except ImportError as _exc:
    raise ImportError("the OPC UA bridge needs asyncua, which has no rosdep key: "
                      "pip install asyncua (or pip install 'pneumatic_unload[opcua]'; "
                      "on Ubuntu 24.04 with PIP_BREAK_SYSTEM_PACKAGES=1)") from _exc

from pneumatic_unload.plc.address import (
    APPLICATION_URI,
    METHODS,
    NAMESPACE,
    OBJECT,
    VARIABLES,
    AbortFn,
    ChargeFn,
    Estimate,
    MeasureFn,
    Method,
    Outcome,
    Variable,
    address_space,
)
from pneumatic_unload.plc.bridge import BridgeServer
from pneumatic_unload.plc.security import (
    POLICIES,
    Security,
    SecurityError,
    hash_password,
    load_users,
)

__all__ = ["APPLICATION_URI", "METHODS", "NAMESPACE", "OBJECT", "POLICIES", "VARIABLES",
           "AbortFn", "BridgeServer", "ChargeFn", "Estimate", "MeasureFn", "Method", "Outcome",
           "Security", "SecurityError", "Variable", "address_space", "hash_password",
           "load_users"]
