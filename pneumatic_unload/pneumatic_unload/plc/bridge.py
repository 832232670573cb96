# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The OPC UA server of the bench (asyncua, ROS-free): its address space and methods.

Under ``Objects`` the object ``PneumaticUnload`` (browse names and node ids in the
namespace ``urn:pneumatic-unload``: ``Objects/<i>:PneumaticUnload/<i>:State``, node ids
``ns=<i>;s=PneumaticUnload.<Name>``) holds the variables of :data:`.address.VARIABLES` (the
address-space table: :func:`.address.address_space`) and the methods of
:data:`.address.METHODS`:

``Measure(PartId) -> (Conductance, CriticalRatio, Verdict)``
    runs one measurement and answers when it is done (tens of seconds: the session stays
    alive meanwhile, see :mod:`.calls`; the client's own request timeout must exceed the
    measurement, e.g. asyncua's ``Client(url, timeout=120)``, a PLC's method-call timeout
    likewise); a failed measurement answers a Bad status code, its reason in ``Message``.
    A rig still recharging after its last unload is waited for (the measurement's own
    ``charge_wait``, the ROS node's).
``StartMeasure(PartId) -> ()``
    starts one and answers at once; wait for ``MeasureDone`` True (or ``MeasurementCount``
    to grow), as PLC function blocks do.
``Charge() -> ()``
    asks the rig to recharge (a rig that does not by itself; the node's charge service).
``Abort() -> ()``
    stops the measurement under way (its results Bad, ``Message`` says so).

``Ready`` is True when a ``Measure`` or ``StartMeasure`` would start now (the estimator is
there and no measurement runs; ``State`` 'ready'). After a failed measurement its result
variables hold NaN or '' with the failure's Bad status code (a client reading them gets the
code, never the previous part's value as Good).

One measurement at a time: a call while one runs (from any client) is answered
``BadInvalidState`` at once ("busy"), never queued. A client that disconnects during its
``Measure`` leaves the measurement running to its end; its results are written to the
variables all the same. The measurement itself is the caller's ``measure`` coroutine
function (the ROS node's: the estimator's ``~/measure`` action), run in the server's loop.
"""

from __future__ import annotations

import asyncio
import datetime
import logging
import math
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.crypto import uacrypto
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

from pneumatic_unload.plc import calls
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
    Outcome,
)
from pneumatic_unload.plc.security import (
    MAX_MESSAGE,
    MAX_STRING,
    CallRules,
    Security,
    SecurityError,
    Users,
)

_Double, _String = ua.VariantType.Double, ua.VariantType.String



def _argument(name: str, vtype: ua.VariantType, doc: str) -> ua.Argument:
    arg = ua.Argument()
    arg.Name, arg.DataType, arg.ValueRank = name, ua.NodeId(vtype.value), -1
    arg.Description = ua.LocalizedText(doc)
    return arg


def _bad(code: str, arguments: list[ua.StatusCode] | None = None) -> ua.CallMethodResult:
    res = ua.CallMethodResult()
    res.StatusCode = ua.StatusCode(getattr(ua.StatusCodes, code))
    res.InputArgumentResults = arguments or []
    return res


def _string(arg: Any) -> str | ua.CallMethodResult:
    """A String input argument's value, or the BadInvalidArgument result refusing it (its
    argument's result BadTypeMismatch: not a scalar String; BadOutOfRange: longer than
    :data:`MAX_STRING` characters or a control character in it)."""
    if not isinstance(arg, ua.Variant) or arg.VariantType != _String or arg.is_array:
        return _bad("BadInvalidArgument", [ua.StatusCode(ua.StatusCodes.BadTypeMismatch)])
    text = arg.Value or ""
    if len(text) > MAX_STRING or any(unicodedata.category(ch) == "Cc" for ch in text):
        return _bad("BadInvalidArgument", [ua.StatusCode(ua.StatusCodes.BadOutOfRange)])
    return str(text)


@dataclass
class BridgeServer:
    """The OPC UA server (see the module docstring).

    Parameters
    ----------
    endpoint : str
        ``opc.tcp://HOST:PORT/PATH`` to listen on.
    measure : MeasureFn
        Runs one measurement of a part.
    security : Security
        Policy, certificates, users.
    charge : ChargeFn or None
        The rig's recharge (None: ``Charge`` answers BadNotImplemented).
    abort : AbortFn or None
        Stops the caller's side of a measurement on ``Abort`` (the bridge cancels its own
        wait in any case).
    """

    endpoint: str
    measure: MeasureFn
    security: Security = field(default_factory=Security)
    charge: ChargeFn | None = None
    abort: AbortFn | None = None
    server: Server | None = None
    _nodes: dict[str, Any] = field(default_factory=dict)
    _busy: bool = False
    _estimator: bool = False
    _count: int = 0
    _current: asyncio.Task[Outcome] | None = None
    _aborting: bool = False
    _tasks: set[asyncio.Task[Any]] = field(default_factory=set)
    _users: Users | None = None

    async def start(self) -> None:
        """Build the address space and listen (asyncua's errors raised: a port in use,
        bad certificate files; :class:`SecurityError`: the server's certificate out of its
        validity dates)."""
        calls.install()
        sec = self.security
        self._users = Users(sec.users, sec.allow_anonymous)
        server = Server(user_manager=self._users)
        await server.init()
        server.limits.max_message_size = MAX_MESSAGE
        server.limits.max_chunk_count = -(-MAX_MESSAGE // server.limits.max_recv_buffer)
        server.set_endpoint(self.endpoint)
        server.set_server_name("pneumatic_unload OPC UA bridge")
        await server.set_application_uri(APPLICATION_URI)
        server.set_security_policy(sec.policy_types(), permission_ruleset=CallRules())
        server.set_identity_tokens(sec.identity_tokens())
        if sec.certificate:
            own = await uacrypto.load_certificate(sec.certificate)
            now = datetime.datetime.now(datetime.UTC)
            if not own.not_valid_before_utc <= now <= own.not_valid_after_utc:
                raise SecurityError(
                    f"certificate {sec.certificate} is valid from {own.not_valid_before_utc} "
                    f"to {own.not_valid_after_utc}, not now ({now:%Y-%m-%d %H:%M} UTC)")
            await server.load_certificate(sec.certificate)
            await server.load_private_key(sec.private_key)
        if sec.policy != "None":  # a trust list (Security requires it): every client's
            # certificate validated at its session's creation (calls.ConcurrentCalls)
            store = TrustStore([Path(sec.trusted_certs)],
                               [Path(sec.revoked_certs)] if sec.revoked_certs else [])
            await store.load()
            server.set_certificate_validator(CertificateValidator(
                CertificateValidatorOptions.TRUSTED_VALIDATION
                | CertificateValidatorOptions.PEER_CLIENT, store))
        idx = await server.register_namespace(NAMESPACE)
        obj = await server.nodes.objects.add_object(ua.NodeId(OBJECT, idx),
                                                    ua.QualifiedName(OBJECT, idx))
        for v in VARIABLES:
            var = await obj.add_variable(ua.NodeId(f"{OBJECT}.{v.name}", idx),
                                         ua.QualifiedName(v.name, idx), v.initial, v.vtype)
            await var.write_attribute(ua.AttributeIds.Description, ua.DataValue(
                ua.Variant(ua.LocalizedText(v.doc), ua.VariantType.LocalizedText)))
            if v.unit is not None:  # a standard property: its browse name in namespace 0
                await var.add_property(
                    ua.NodeId(f"{OBJECT}.{v.name}.EngineeringUnits", idx),
                    ua.QualifiedName("EngineeringUnits", 0), v.unit.information(),
                    ua.VariantType.ExtensionObject, ua.NodeId(ua.ObjectIds.EUInformation))
            self._nodes[v.name] = var
        handlers = {"Measure": self._call_measure, "StartMeasure": self._call_start,
                    "Charge": self._call_charge, "Abort": self._call_abort}
        for m in METHODS:
            node = await obj.add_method(
                ua.NodeId(f"{OBJECT}.{m.name}", idx), ua.QualifiedName(m.name, idx),
                handlers[m.name], [_argument(*a) for a in m.inputs],
                [_argument(*a) for a in m.outputs])
            await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(
                ua.Variant(ua.LocalizedText(m.doc), ua.VariantType.LocalizedText)))
        self.server = server
        await server.start()
        await self._write_results(None, ua.StatusCodes.BadWaitingForInitialData)
        await self._refresh()

    async def stop(self) -> None:
        """Stop the measurements under way and the server."""
        for task in list(self._tasks):
            task.cancel()
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.server is not None:
            await self.server.stop()
            self.server = None
        if self._users is not None:
            self._users.close()

    @property
    def port(self) -> int:
        """The TCP port listened on (the endpoint's, or the one given for port 0)."""
        assert self.server is not None and self.server.bserver is not None
        return int(self.server.bserver.port)

    # ------------------------------------------------------------------ from the node
    async def show(self, est: Estimate) -> None:
        """An estimate into the variables (as estimates arrive; a measurement's own with its
        verdict at its end)."""
        await self._write_results(est, ua.StatusCodes.Good)

    async def set_estimator(self, present: bool) -> None:
        """The estimator is there (its ``~/measure`` action server, samples reaching it),
        or not (``State``, ``Ready``)."""
        if present != self._estimator:
            self._estimator = present
            await self._refresh()

    # ------------------------------------------------------------------ methods
    def _part_id(self, args: tuple[Any, ...]) -> str | ua.CallMethodResult:
        """The PartId of a call's input arguments, or the Bad result of a malformed
        call (BadInvalidArgument: not one String, longer than :data:`MAX_STRING`, or a
        control character in it, which would forge a log line)."""
        if not args:
            return _bad("BadArgumentsMissing")
        if len(args) > 1:
            return _bad("BadTooManyArguments")
        return _string(args[0])

    def _refuse(self) -> ua.CallMethodResult | None:
        """The answer of a call that cannot start a measurement now, else None."""
        if self._busy:
            return _bad("BadInvalidState")  # busy: one measurement at a time
        if self.server is None:
            return _bad("BadShutdown")
        return None

    def _admit(self, args: tuple[Any, ...]) -> str | ua.CallMethodResult:
        """The part id of a call that may start a measurement now, else the answer that
        refuses it (a malformed call, busy, shut down)."""
        part = self._part_id(args)
        if isinstance(part, ua.CallMethodResult):
            return part
        refused = self._refuse()
        return part if refused is None else refused

    async def _call_measure(self, _parent: ua.NodeId, *args: Any) -> Any:
        part = self._admit(args)
        if isinstance(part, ua.CallMethodResult):
            return part
        task = await self._begin(part)
        outcome = await asyncio.shield(task)  # a caller gone: the measurement goes on
        if not outcome.ok or outcome.estimate is None:
            return ua.StatusCode(_code(outcome.status))
        e = outcome.estimate
        return [ua.Variant(e.conductance, _Double), ua.Variant(e.critical_ratio, _Double),
                ua.Variant(e.verdict, _String)]

    async def _call_start(self, _parent: ua.NodeId, *args: Any) -> Any:
        part = self._admit(args)
        if isinstance(part, ua.CallMethodResult):
            return part
        await self._begin(part)
        return []

    async def _call_charge(self, _parent: ua.NodeId, *args: Any) -> Any:
        if args:
            return _bad("BadTooManyArguments")
        refused = self._refuse()
        if refused is not None:
            return refused
        if self.charge is None:
            return _bad("BadNotImplemented")
        outcome = await self.charge()
        await self._write(Message=outcome.message)
        return [] if outcome.status == "Good" else ua.StatusCode(_code(outcome.status))

    async def _call_abort(self, _parent: ua.NodeId, *args: Any) -> Any:
        if args:
            return _bad("BadTooManyArguments")
        task = self._current
        if not self._busy or task is None or task.done():
            return _bad("BadInvalidState")  # nothing to abort
        self._aborting = True
        if self.abort is not None:
            self.abort()
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        return []

    async def _begin(self, part: str) -> asyncio.Task[Outcome]:
        """Start a measurement: busy at once (a second call sees it), ``MeasureDone``
        False and ``State`` 'measuring' before the call answers; its task."""
        self._busy = True
        try:
            await self._write(PartId=part, MeasureDone=False, Message="measuring")
            await self._refresh()
        except BaseException:
            self._busy = False
            raise
        task = asyncio.get_running_loop().create_task(self._run(part))
        self._current = task
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def _run(self, part: str) -> Outcome:
        """One measurement: its results into the variables (Good, or Bad with the
        failure's code), then the count and time, ``MeasureDone`` last."""
        try:
            try:
                outcome = await self.measure(part)
            except asyncio.CancelledError:
                if not self._aborting:
                    outcome = Outcome("BadShutdown",
                                      "the bridge stopped during the measurement")
                    raise
                outcome = Outcome("BadRequestCancelledByClient",
                                  "aborted by a client's Abort call")
            except Exception as exc:  # never silent, never fatal
                logging.getLogger(__name__).exception("measurement of %r failed", part)
                outcome = Outcome("BadInternalError", f"{type(exc).__name__}: {exc}")
        finally:
            self._busy, self._aborting = False, False
        if outcome.ok and outcome.estimate is not None:
            await self.show(outcome.estimate)
        else:
            await self._write_results(None, _code(outcome.status))
        self._count += 1
        await self._write(Message=outcome.message, MeasurementCount=self._count,
                          ResultTime=datetime.datetime.now(datetime.UTC))
        await self._refresh()
        await self._write(MeasureDone=True)
        return outcome

    # ------------------------------------------------------------------ variables
    def state(self) -> str:
        """The value of ``State``."""
        if self._busy:
            return "measuring"
        return "ready" if self._estimator else "no estimator"

    async def _refresh(self) -> None:
        state = self.state()
        await self._write(State=state, Ready=state == "ready")

    async def _write(self, **values: Any) -> None:
        types = {v.name: v.vtype for v in VARIABLES}
        for name, value in values.items():
            node = self._nodes.get(name)
            if node is not None:
                await node.write_value(ua.Variant(value, types[name]))

    async def _write_results(self, est: Estimate | None, code: int) -> None:
        """The result variables: an estimate's values (Good), or NaN and '' with the Bad
        ``code`` (no estimate yet, a failed measurement)."""
        values = est.results() if est is not None else {}
        for v in VARIABLES:
            node = self._nodes.get(v.name)
            if not v.result or node is None:
                continue
            value = values.get(v.name, math.nan if v.vtype == _Double else "")
            dv = ua.DataValue(ua.Variant(value, v.vtype), StatusCode=ua.StatusCode(code))
            await node.write_value(dv)


def _code(status: str) -> int:
    """The Bad status code of a failed outcome's status name (BadUnexpectedError for an
    unknown name, or 'Good' without an estimate)."""
    code = getattr(ua.StatusCodes, status, ua.StatusCodes.BadUnexpectedError)
    return int(code) if code != ua.StatusCodes.Good else ua.StatusCodes.BadUnexpectedError
