"""The cell's PLC's way in: the OPC UA server of the bench (asyncua), ROS-free.

:mod:`.bridge` builds the address space (object ``PneumaticUnload`` in namespace
``urn:pneumatic-unload``: the latest estimate, the state, the methods ``Measure`` and
``StartMeasure``), :mod:`.security` says who may connect and who may measure, :mod:`.calls`
keeps a session alive through a method call of tens of seconds. The ROS node
(:mod:`pneumatic_unload.nodes.opcua`) runs the server in an asyncio loop of its own and
hands it the estimates and the measurements (the estimator's ``~/measure`` action).
"""

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
