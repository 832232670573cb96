"""The cell's PLC's way in: the OPC UA server of the bench (asyncua), ROS-free.

:mod:`.bridge` builds the address space (object ``PneumaticUnload`` in namespace
``urn:pneumatic-unload``: the latest estimate, the state, the methods ``Measure`` and
``StartMeasure``), :mod:`.security` says who may connect and who may measure, :mod:`.calls`
keeps a session alive through a method call of tens of seconds. The ROS node
(:mod:`pneumatic_unload.nodes.opcua`) runs the server in an asyncio loop of its own and
hands it the estimates and the measurements (the estimator's ``~/measure`` action).
"""

try:  # no rosdep key: an optional dependency, named in the error when missing
    import asyncua  # noqa: F401
except ImportError as _exc:
    raise ImportError("the OPC UA bridge needs asyncua, which has no rosdep key: "
                      "pip install asyncua (or pip install 'pneumatic_unload[opcua]'; "
                      "on Ubuntu 24.04 with PIP_BREAK_SYSTEM_PACKAGES=1)") from _exc

from pneumatic_unload.plc.bridge import (
    APPLICATION_URI,
    NAMESPACE,
    OBJECT,
    VARIABLES,
    BridgeServer,
    Estimate,
    MeasureFn,
    Outcome,
)
from pneumatic_unload.plc.security import (
    POLICIES,
    Security,
    SecurityError,
    hash_password,
    load_users,
)

__all__ = ["APPLICATION_URI", "NAMESPACE", "OBJECT", "POLICIES", "VARIABLES", "BridgeServer",
           "Estimate", "MeasureFn", "Outcome", "Security", "SecurityError", "hash_password",
           "load_users"]
