# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The address space of the bench's OPC UA server (ROS-free): its object's variables and
methods as data (:data:`VARIABLES`, :data:`METHODS`; :func:`address_space` is the table of
the docs), their units, and what a measurement hands the server (:class:`Estimate`,
:class:`Outcome`). :mod:`.bridge` builds the nodes from them."""

from __future__ import annotations

import datetime
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from asyncua import ua

from pneumatic_unload.plc.security import MAX_STRING
from pneumatic_unload.uncertainty.budget import COVERAGE_FACTOR

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
_UInt32, _DateTime = ua.VariantType.UInt32, ua.VariantType.DateTime
#: OPC UA's null DateTime (no measurement has ended yet).
NEVER = datetime.datetime(1601, 1, 1, tzinfo=datetime.UTC)


@dataclass(frozen=True)
class Unit:
    """EngineeringUnits of a variable: its UNECE Recommendation 20 common code, symbol and
    meaning."""

    code: str
    symbol: str
    description: str

    def information(self) -> ua.EUInformation:
        """The EUInformation (UnitId of a code: its characters as bytes, big-endian, as
        OPC 10000-8 maps UNECE codes)."""
        eu = ua.EUInformation()
        eu.NamespaceUri = CEFACT
        eu.UnitId = int.from_bytes(self.code.encode(), "big")
        eu.DisplayName = ua.LocalizedText(self.symbol)
        eu.Description = ua.LocalizedText(self.description)
        return eu


CONDUCTANCE_UNIT = Unit("N45", "m³/(s·Pa)", "cubic metre per second pascal (sonic "
                        "conductance C, ISO 6358)")
SECOND = Unit("SEC", "s", "second")
PASCAL = Unit("PAL", "Pa", "pascal (absolute pressure)")
ONE = Unit("C62", "1", "one (a dimensionless ratio)")


@dataclass(frozen=True)
class Variable:
    """A variable of the object.

    Attributes
    ----------
    name : str
        Its browse name (and node id ``PneumaticUnload.<name>``).
    vtype : ua.VariantType
        Its data type.
    initial : Any
        Its value before the first estimate.
    unit : Unit or None
        Its EngineeringUnits property (None: text, a flag or a count).
    doc : str
        Its meaning (the node's Description).
    result : bool
        A measurement's result: Bad (NaN or '') after a failed measurement.
    """

    name: str
    vtype: ua.VariantType
    initial: Any
    unit: Unit | None
    doc: str
    result: bool = False


#: The variables of the object (the address-space table of the docs: :func:`address_space`).
VARIABLES: tuple[Variable, ...] = (
    Variable("State", _String, "starting", None, "no estimator (its ~/measure action is "
             "not there, or no samples reach it), ready (Measure starts now), measuring"),
    Variable("Ready", _Boolean, False, None, "True when a Measure or StartMeasure would "
             "start now (State 'ready'); a rig still recharging is waited for by the "
             "measurement itself"),
    Variable("MeasureDone", _Boolean, False, None, "the measurement started last is over "
             "(False while it runs)"),
    Variable("MeasurementCount", _UInt32, 0, None, "measurements ended (with a result or "
             "failed) since the bridge started: it grows when MeasureDone turns True"),
    Variable("ResultTime", _DateTime, NEVER, None, "when the last measurement ended (UTC; "
             "1601-01-01: none yet)"),
    Variable("PartId", _String, "", None, "the part of the measurement started last"),
    Variable("Message", _String, "", None, "ok, or why the last measurement failed"),
    Variable("Conductance", _Double, math.nan, CONDUCTANCE_UNIT,
             "the recommended sonic conductance C of the last estimate (the model's, else "
             "eq 39's)", True),
    Variable("ConductanceStd", _Double, math.nan, CONDUCTANCE_UNIT,
             "its combined standard uncertainty u(C)", True),
    Variable("ConductanceExpanded", _Double, math.nan, CONDUCTANCE_UNIT,
             f"its expanded uncertainty U = k u(C), k = {COVERAGE_FACTOR:g}", True),
    Variable("ConductanceEq39", _Double, math.nan, CONDUCTANCE_UNIT,
             "C of the paper's eq 39 (tau_exp, V, p*)", True),
    Variable("CriticalRatio", _Double, math.nan, ONE, "critical pressure ratio b "
             "(dimensionless)", True),
    Variable("SubsonicIndex", _Double, math.nan, ONE, "ISO 6358-1 subsonic index m "
             "(dimensionless)", True),
    Variable("TauExp", _Double, math.nan, SECOND, "experimental unloading time tau_exp",
             True),
    Variable("InitialPressure", _Double, math.nan, PASCAL, "p10, the tank's pressure "
             "before the opening", True),
    Variable("CriticalPressure", _Double, math.nan, PASCAL, "p*, the pressure of the "
             "unloading time's crossing", True),
    Variable("AtmosphericPressure", _Double, math.nan, PASCAL, "p_atm, the downstream "
             "pressure", True),
    Variable("Status", _String, "", None, "the estimate's status word (ok, ok_subsonic, "
             "aborted_sse, aborted, bad_data)", True),
    Variable("StatusText", _String, "", None, "what the status means for this estimate",
             True),
    Variable("Verdict", _String, "", None, "pass or fail against the part's specification "
             "('' none, or an estimate not of a measurement)", True),
    Variable("VerdictReason", _String, "", None, "why (the specification's limit)", True),
)


@dataclass(frozen=True)
class Method:
    """A method of the object: its name, input and output arguments (name, type,
    meaning) and what it does."""

    name: str
    inputs: tuple[tuple[str, ua.VariantType, str], ...]
    outputs: tuple[tuple[str, ua.VariantType, str], ...]
    doc: str


_PART = ("PartId", _String, f"the part measured (results database, specification), at "
         f"most {MAX_STRING} characters, no control characters")
#: The methods of the object.
METHODS: tuple[Method, ...] = (
    Method("Measure", (_PART,), (
        ("Conductance", _Double, "the recommended C [m^3/(s Pa)]"),
        ("CriticalRatio", _Double, "b [-]"), ("Verdict", _String, "pass, fail or ''")),
        "one measurement, answered when it is done (a Bad status code when it failed, "
        "the reason in Message)"),
    Method("StartMeasure", (_PART,), (), "starts one measurement and answers at once "
           "(wait for MeasureDone)"),
    Method("Charge", (), (), "asks the rig to recharge (its charge service); Bad when it "
           "refuses"),
    Method("Abort", (), (), "stops the measurement under way (BadInvalidState when none "
           "runs)"),
)


def address_space() -> list[tuple[str, str, str, str]]:
    """The object's nodes: (browse path under ``Objects``, node class and type, unit,
    meaning), variables then methods; ``2:`` stands for the namespace index of
    ``urn:pneumatic-unload`` (the server's first own namespace)."""
    rows = [(f"2:{OBJECT}", "Object", "", "the bench")]
    for v in VARIABLES:
        unit = f"{v.unit.symbol} ({v.unit.code})" if v.unit is not None else ""
        rows.append((f"2:{OBJECT}/2:{v.name}", f"Variable {v.vtype.name}", unit,
                     v.doc + (" (Bad after a failed measurement)" if v.result else "")))
    for m in METHODS:
        sig = ", ".join(f"{n}: {t.name}" for n, t, _ in m.inputs)
        out = ", ".join(f"{n}: {t.name}" for n, t, _ in m.outputs)
        rows.append((f"2:{OBJECT}/2:{m.name}", f"Method ({sig}) -> ({out})", "", m.doc))
    return rows


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
        'ok', 'aborted_sse', 'aborted', 'ok_subsonic' or 'bad_data', and why.
    conductance, conductance_std : float
        The recommended C and its combined standard uncertainty [m^3/(s Pa)].
    critical_ratio, subsonic_index : float
        b and m [-].
    tau_exp : float
        The experimental unloading time [s].
    verdict, verdict_reason : str
        'pass', 'fail' or '' against the part's specification, and why.
    conductance_eq39 : float
        C of the paper's eq 39 [m^3/(s Pa)].
    p10, p_star, p_atm : float
        The initial, crossing and downstream pressures [Pa absolute].
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
    conductance_eq39: float = math.nan
    p10: float = math.nan
    p_star: float = math.nan
    p_atm: float = math.nan

    def results(self) -> dict[str, Any]:
        """The result variables' values (:data:`VARIABLES` whose ``result`` is set)."""
        return {"Conductance": self.conductance, "ConductanceStd": self.conductance_std,
                "ConductanceExpanded": COVERAGE_FACTOR * self.conductance_std,
                "ConductanceEq39": self.conductance_eq39,
                "CriticalRatio": self.critical_ratio, "SubsonicIndex": self.subsonic_index,
                "TauExp": self.tau_exp, "InitialPressure": self.p10,
                "CriticalPressure": self.p_star, "AtmosphericPressure": self.p_atm,
                "Status": self.status, "StatusText": self.status_text,
                "Verdict": self.verdict, "VerdictReason": self.verdict_reason}


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
#: The rig's recharge (``Charge``): the caller's coroutine function, its Outcome without an
#: estimate ('Good' when the rig charges or is charged).
ChargeFn = Callable[[], Awaitable[Outcome]]
#: Stops the caller's side of the measurement under way (``Abort``; the ROS node cancels
#: its goal), called in the server's loop.
AbortFn = Callable[[], None]
