"""The OPC UA server of the bench (asyncua, ROS-free): its address space and methods.

Under ``Objects`` the object ``PneumaticUnload`` (namespace ``urn:pneumatic-unload``, node
ids ``ns=<i>;s=PneumaticUnload.<Name>``) holds the variables of :data:`VARIABLES` (C and its
standard uncertainty [m^3/(s Pa)] with their EngineeringUnits, b and m [-], tau_exp [s] with
its EngineeringUnits, the verdict, the part, the state) and two ways to measure:

``Measure(PartId) -> (Conductance, CriticalRatio, Verdict)``
    runs one measurement and answers when it is done (tens of seconds: the session stays
    alive meanwhile, see :mod:`.calls`; the client's own request timeout must exceed the
    measurement, e.g. asyncua's ``Client(url, timeout=120)``, a PLC's method-call timeout
    likewise); a failed measurement answers a Bad status code, its reason in ``Message``.
``StartMeasure(PartId) -> ()``
    starts one and answers at once; poll ``MeasureDone`` (False while it runs, True when
    its results and ``State`` 'done' or 'failed' are written), as PLC function blocks do.

One measurement at a time: a call while one runs (from any client) is answered
``BadInvalidState`` at once ("busy"), never queued. A client that disconnects during its
``Measure`` leaves the measurement running to its end; its results are written to the
variables all the same. The measurement itself is the caller's ``measure`` coroutine
function (the ROS node's: the estimator's ``~/measure`` action), run in the server's loop.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

from pneumatic_unload.plc import calls
from pneumatic_unload.plc.security import CallRules, Security, Users

#: The namespace of the bridge's nodes.
NAMESPACE = "urn:pneumatic-unload"
#: The object under Objects.
OBJECT = "PneumaticUnload"
#: The server's application URI (a certificate's subjectAltName URI should be it).
APPLICATION_URI = "urn:pneumatic-unload:opcua"
#: UNECE units of OPC UA's EngineeringUnits (OPC 10000-8, EUInformation).
CEFACT = "http://www.opcfoundation.org/UA/units/un/cefact"
_Double, _String, _Boolean = ua.VariantType.Double, ua.VariantType.String, \
    ua.VariantType.Boolean


@dataclass(frozen=True)
class Unit:
    """EngineeringUnits of a variable: its UNECE common code (UnitId -1 and this package's
    namespace when UNECE has none), symbol and meaning."""

    code: str
    symbol: str
    description: str

    def information(self) -> ua.EUInformation:
        """The EUInformation (UnitId of a code: its characters as bytes, big-endian)."""
        eu = ua.EUInformation()
        eu.NamespaceUri = CEFACT if self.code else NAMESPACE
        eu.UnitId = int.from_bytes(self.code.encode(), "big") if self.code else -1
        eu.DisplayName = ua.LocalizedText(self.symbol)
        eu.Description = ua.LocalizedText(self.description)
        return eu


CONDUCTANCE_UNIT = Unit("", "m³/(s·Pa)", "cubic metre per second per pascal (sonic "
                        "conductance C, ISO 6358)")
SECOND = Unit("SEC", "s", "second")

#: The variables of the object: name, type, initial value, unit, meaning.
VARIABLES: tuple[tuple[str, ua.VariantType, Any, Unit | None, str], ...] = (
    ("State", _String, "starting", None, "no estimator (its ~/measure action is not "
     "there, or no samples reach it), ready, measuring, done (the last measurement gave "
     "C), failed (see Message)"),
    ("Conductance", _Double, math.nan, CONDUCTANCE_UNIT,
     "the recommended sonic conductance C of the last estimate"),
    ("ConductanceStd", _Double, math.nan, CONDUCTANCE_UNIT,
     "its combined standard uncertainty"),
    ("CriticalRatio", _Double, math.nan, None, "critical pressure ratio b [-]"),
    ("SubsonicIndex", _Double, math.nan, None, "ISO 6358-1 subsonic index m [-]"),
    ("TauExp", _Double, math.nan, SECOND, "experimental unloading time tau_exp"),
    ("Verdict", _String, "", None, "pass or fail against the part's specification ('' "
     "none, or an estimate not of a measurement)"),
    ("PartId", _String, "", None, "the part of the measurement started last"),
    ("MeasureDone", _Boolean, False, None, "the measurement started last is over (False "
     "while it runs)"),
    ("Message", _String, "", None, "ok, or why the last measurement failed"),
)


@dataclass(frozen=True)
class Estimate:
    """What the PLC sees of one estimate (SI units; NaN where unknown).

    Attributes
    ----------
    unload_index : int
        The estimator's unload index [-].
    final : bool
        The full-curve fit's estimate (else the p* crossing's).
    status, status_text : str
        'ok', 'aborted_sse', 'aborted', 'not_choked' or 'bad_data', and why.
    conductance, conductance_std : float
        The recommended C and its combined standard uncertainty [m^3/(s Pa)].
    critical_ratio, subsonic_index : float
        b and m [-].
    tau_exp : float
        The experimental unloading time [s].
    verdict, verdict_reason : str
        'pass', 'fail' or '' against the part's specification, and why.
    """

    unload_index: int
    final: bool
    status: str
    status_text: str
    conductance: float
    conductance_std: float
    critical_ratio: float
    subsonic_index: float
    tau_exp: float
    verdict: str = ""
    verdict_reason: str = ""


@dataclass(frozen=True)
class Outcome:
    """The end of a measurement: ``status`` 'Good' or the name of a Bad status code
    (``asyncua.ua.StatusCodes``), ``message`` 'ok' or why, and its estimate."""

    status: str
    message: str
    estimate: Estimate | None = None

    @property
    def ok(self) -> bool:
        """The measurement gave its estimate."""
        return self.status == "Good" and self.estimate is not None


#: A measurement of a part (its id): the caller's coroutine function, run in the server's
#: event loop.
MeasureFn = Callable[[str], Awaitable[Outcome]]


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
    """

    endpoint: str
    measure: MeasureFn
    security: Security = field(default_factory=Security)
    server: Server | None = None
    _nodes: dict[str, Any] = field(default_factory=dict)
    _busy: bool = False
    _estimator: bool = False
    _last: Outcome | None = None
    _tasks: set[asyncio.Task[Any]] = field(default_factory=set)

    async def start(self) -> None:
        """Build the address space and listen (asyncua's errors raised: a port in use,
        bad certificate files)."""
        calls.install()
        sec = self.security
        server = Server(user_manager=Users(sec.users))
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name("pneumatic_unload OPC UA bridge")
        await server.set_application_uri(APPLICATION_URI)
        server.set_security_policy(sec.policy_types(),
                                   permission_ruleset=CallRules(bool(sec.users)))
        server.set_identity_tokens(sec.identity_tokens())
        if sec.certificate:
            await server.load_certificate(sec.certificate)
            await server.load_private_key(sec.private_key)
        if sec.trusted_certs:
            store = TrustStore([Path(sec.trusted_certs)], [])
            await store.load()
            server.set_certificate_validator(CertificateValidator(
                CertificateValidatorOptions.TRUSTED_VALIDATION
                | CertificateValidatorOptions.PEER_CLIENT, store))
        idx = await server.register_namespace(NAMESPACE)
        obj = await server.nodes.objects.add_object(ua.NodeId(OBJECT, idx), OBJECT)
        for name, vtype, value, unit, doc in VARIABLES:
            var = await obj.add_variable(ua.NodeId(f"{OBJECT}.{name}", idx), name, value,
                                         vtype)
            await var.write_attribute(ua.AttributeIds.Description, ua.DataValue(
                ua.Variant(ua.LocalizedText(doc), ua.VariantType.LocalizedText)))
            if unit is not None:
                await var.add_property(
                    ua.NodeId(f"{OBJECT}.{name}.EngineeringUnits", idx),
                    ua.QualifiedName("EngineeringUnits", 0), unit.information(),
                    ua.VariantType.ExtensionObject, ua.NodeId(ua.ObjectIds.EUInformation))
            self._nodes[name] = var
        part = _argument("PartId", _String, "the part measured (results database, "
                                            "specification)")
        await obj.add_method(ua.NodeId(f"{OBJECT}.Measure", idx), "Measure",
                             self._call_measure, [part], [
                                 _argument("Conductance", _Double,
                                           "the recommended C [m^3/(s Pa)]"),
                                 _argument("CriticalRatio", _Double, "b [-]"),
                                 _argument("Verdict", _String, "pass, fail or ''")])
        await obj.add_method(ua.NodeId(f"{OBJECT}.StartMeasure", idx), "StartMeasure",
                             self._call_start, [part], [])
        self.server = server
        await server.start()
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

    @property
    def port(self) -> int:
        """The TCP port listened on (the endpoint's, or the one given for port 0)."""
        assert self.server is not None and self.server.bserver is not None
        return int(self.server.bserver.port)

    # ------------------------------------------------------------------ from the node
    async def show(self, est: Estimate) -> None:
        """An estimate into the variables (as estimates arrive; a measurement's own with its
        verdict at its end)."""
        await self._write(Conductance=est.conductance, ConductanceStd=est.conductance_std,
                          CriticalRatio=est.critical_ratio,
                          SubsonicIndex=est.subsonic_index, TauExp=est.tau_exp,
                          Verdict=est.verdict)

    async def set_estimator(self, present: bool) -> None:
        """The estimator is there (its ``~/measure`` action server, samples reaching it),
        or not (``State``)."""
        if present != self._estimator:
            self._estimator = present
            await self._refresh()

    # ------------------------------------------------------------------ methods
    def _part_id(self, args: tuple[Any, ...]) -> str | ua.CallMethodResult:
        """The PartId of a call's input arguments, or the Bad result of a malformed
        call."""
        if not args:
            return _bad("BadArgumentsMissing")
        if len(args) > 1:
            return _bad("BadTooManyArguments")
        arg = args[0]
        if not isinstance(arg, ua.Variant) or arg.VariantType != _String \
                or arg.is_array:
            return _bad("BadInvalidArgument",
                        [ua.StatusCode(ua.StatusCodes.BadTypeMismatch)])
        return arg.Value or ""

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
            code = getattr(ua.StatusCodes, outcome.status, ua.StatusCodes.BadUnexpectedError)
            return ua.StatusCode(code if code != ua.StatusCodes.Good
                                 else ua.StatusCodes.BadUnexpectedError)
        e = outcome.estimate
        return [ua.Variant(e.conductance, _Double), ua.Variant(e.critical_ratio, _Double),
                ua.Variant(e.verdict, _String)]

    async def _call_start(self, _parent: ua.NodeId, *args: Any) -> Any:
        part = self._admit(args)
        if isinstance(part, ua.CallMethodResult):
            return part
        await self._begin(part)
        return []

    async def _begin(self, part: str) -> asyncio.Task[Outcome]:
        """Start a measurement: busy at once (a second call sees it), ``MeasureDone``
        False and ``State`` 'measuring' before the call answers; its task."""
        self._busy = True
        try:
            await self._write(PartId=part, MeasureDone=False, Message="measuring",
                              Verdict="")
            await self._refresh()
        except BaseException:
            self._busy = False
            raise
        task = asyncio.get_running_loop().create_task(self._run(part))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def _run(self, part: str) -> Outcome:
        """One measurement: its results into the variables (``MeasureDone`` last)."""
        try:
            try:
                outcome = await self.measure(part)
            except asyncio.CancelledError:
                outcome = Outcome("BadShutdown", "the bridge stopped during the measurement")
                raise
            except Exception as exc:  # never silent, never fatal
                logging.getLogger(__name__).exception("measurement of %r failed", part)
                outcome = Outcome("BadInternalError", f"{type(exc).__name__}: {exc}")
            if outcome.estimate is not None:
                await self.show(outcome.estimate)
        finally:
            self._busy = False
        self._last = outcome
        await self._write(Message=outcome.message)
        await self._refresh()
        await self._write(MeasureDone=True)
        return outcome

    # ------------------------------------------------------------------ variables
    def state(self) -> str:
        """The value of ``State``."""
        if self._busy:
            return "measuring"
        if not self._estimator:
            return "no estimator"
        if self._last is None:
            return "ready"
        return "done" if self._last.ok else "failed"

    async def _refresh(self) -> None:
        await self._write(State=self.state())

    async def _write(self, **values: Any) -> None:
        types = {name: vtype for name, vtype, *_ in VARIABLES}
        for name, value in values.items():
            node = self._nodes.get(name)
            if node is not None:
                await node.write_value(ua.Variant(value, types[name]))
