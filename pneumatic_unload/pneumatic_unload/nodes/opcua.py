# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``opcua`` node: the bench's OPC UA server for the cell's PLC (issue #27).

The server (:mod:`pneumatic_unload.plc`: asyncua, ROS-free) runs in an asyncio event loop
of its own thread; this node is the ROS side: an action client of the estimator's
``~/measure`` and a subscription to its ``~/estimate``, in the executor's thread.

Subscribes
    <estimator>/estimate (pneumatic_unload_msgs/UnloadEstimate; reliable, transient local):
        each estimate into the server's variables as it arrives.
    /diagnostics (diagnostic_msgs/DiagnosticArray): the estimator's reports; a measurement
        starts (``State`` 'ready') only once its count of samples received grows: an
        estimator that joins the rig's stream after the valve opened skips that unload
        (no plateau before the drop) and the goal would wait for its timeout. With several
        estimators on one ROS domain any of their reports counts (the status name is the
        same).
Action client
    <estimator>/measure (pneumatic_unload_msgs/action/Measure): one goal per OPC UA
        ``Measure``/``StartMeasure`` call; its crossing estimate is followed by the unload's
        final (full-curve fit) estimate on the topic, which the call returns (after
        ``final_timeout`` s without it: the crossing's, said so in ``Message``). A goal
        refused because the tank is not charged (the rig recharging after its last
        unload) is sent again every :data:`RETRY_PERIOD` s for ``charge_wait`` s; ``Abort``
        cancels the goal.
Service client
    ``charge_service`` (std_srvs/Trigger): the OPC UA ``Charge`` method.

Between the threads. The server's methods await :meth:`OpcUaNode.measure` in the asyncio
loop: it queues the request and wakes the executor through a guard condition (the one
rclpy call made from that thread); the executor's thread sends the goal, follows it with
callbacks and a timer, and hands the outcome back with ``loop.call_soon_threadsafe``.
Estimates go to the server with ``asyncio.run_coroutine_threadsafe``, not waited for. The
state of the one measurement under way lives in the executor's thread only.

Status codes of a failed measurement (its reason in ``Message`` and the log):
``BadNoCommunication`` (no estimator's action server, or no samples reaching the estimator,
within ``estimator_wait`` s),
``BadInvalidState`` (the estimator refused the goal: a measurement is running there),
``BadTimeout`` (the goal's timeout, or no answer from the estimator), ``BadDeviceFailure``
(the measurement failed: the valve service, an aborted unload, bad data).
"""

from __future__ import annotations

import asyncio
import math
import sys
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action import ActionClient
from rclpy.node import Node

from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.nodes import common
from pneumatic_unload.plc import BridgeServer, Estimate, Outcome, Security, SecurityError
from pneumatic_unload.plc.results import FIELDS, estimate_from_fields, is_final, judged
from pneumatic_unload.plc.security import load_users

#: Longest start of the OPC UA server (its standard address space) [s].
START_TIMEOUT = 60.0
#: Slack over the goal's own timeout before the bridge gives up on the estimator [s].
RESULT_SLACK = 10.0
#: Estimates kept per unload key, to find a final that came before the goal's result [-].
KEPT = 32
#: The name of the estimator's status on /diagnostics (its "samples" value: received).
ESTIMATOR_DIAGNOSTICS = "pneumatic_unload: estimator"
#: Oldest estimator report that still tells it hears the rig [s] (it reports each
#: diagnostics_period, 1 s by default).
REPORT_AGE = 5.0
#: Period of a measurement's new goal while the rig recharges [s].
RETRY_PERIOD = 0.5
#: What the rig's valve service says when the tank is not charged (model.rig.RigStream).
NOT_CHARGED = "not charged"
#: Longest wait for the charge service's answer [s].
CHARGE_TIMEOUT = 10.0
#: Longest wait for an aborted goal's end before the next measurement's goal is sent [s]
#: (the estimator checks a cancel request every few tens of ms).
CANCEL_WAIT = 5.0


class _AnswerPending:
    """The draining mark of an aborted measurement whose goal was sent and not yet
    answered: not done until the answer comes (:meth:`OpcUaNode._on_goal_response` puts the
    goal's result in its place, or ends the wait if the goal was refused)."""

    @staticmethod
    def done() -> bool:
        return False


@dataclass
class _Measurement:
    """The one measurement under way (executor thread only)."""

    part: str
    finish: Callable[[Outcome], None]
    t0: float
    sent: bool = False
    key: tuple[int, int] | None = None  # (unload start [ns], unload index) of its unload
    crossing: Estimate | None = None
    final_deadline: float = math.inf
    handle: Any = None  # the goal's handle, once accepted
    sent_at: float = 0.0  # the last goal sent [s, monotonic]
    result: Any = None  # the goal's result future, once accepted
    retry_at: float = 0.0  # a goal refused for the charge: the next one not before [s]


class OpcUaNode(Node):
    """The OPC UA bridge (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("opcua", **kwargs)
        from pneumatic_unload_msgs.action import Measure
        from pneumatic_unload_msgs.msg import UnloadEstimate

        self._Measure = Measure
        for name, (default, desc) in common.node_parameters("opcua").items():
            self.declare_parameter(name, default, desc)
        self.add_on_set_parameters_callback(common.validating_callback(self._check))
        p = self._p
        try:
            security = Security(
                policy=p("security_policy"), certificate=p("certificate"),
                private_key=p("private_key"),
                users=load_users(p("users_file")) if p("users_file") else None,
                allow_anonymous=p("allow_anonymous"), trusted_certs=p("trusted_certs"),
                revoked_certs=p("revoked_certs"))
        except SecurityError as exc:
            raise common.StartupError("opcua", str(exc)) from exc
        self._spec = None
        if p("spec_file"):
            from pneumatic_unload.testline import SpecError, load_spec

            try:
                self._spec = load_spec(p("spec_file"))
            except SpecError as exc:
                raise common.StartupError("opcua", str(exc)) from exc
        estimator = p("estimator").rstrip("/") or "/estimator"
        self._action = f"{estimator}/measure"
        self._client = ActionClient(self, Measure, self._action)
        self.create_subscription(
            UnloadEstimate, f"{estimator}/estimate",
            lambda msg: self._guarded("estimate", self._on_estimate, msg), common.LATCHED_QOS)
        #: Estimates by unload key, the latest last (executor thread).
        self._seen: OrderedDict[tuple[int, int], Estimate] = OrderedDict()
        self._requests: deque[tuple[str, Callable[[Outcome], None]]] = deque()
        self._charges: deque[Callable[[Outcome], None]] = deque()
        #: Charge service calls awaiting their answer: (future, start [s], finish, name).
        self._pending_charges: list[tuple[Any, float, Callable[[Outcome], None], str]] = []
        self._abort_requested = False
        #: An aborted goal's result future and the longest wait for it [s, monotonic]: the
        #: estimator refuses a new goal until the cancelled one has ended.
        self._draining: tuple[Any, float] | None = None
        self._current: _Measurement | None = None
        self._estimator_present = False
        #: The estimator's reports of its samples received: (count [-], arrival [s,
        #: monotonic]) of the last one, and whether the count grew since the one before.
        self._samples: tuple[int, float] | None = None
        self._hearing = False
        self.create_subscription(DiagnosticArray, "/diagnostics",
                                 lambda msg: self._guarded("diagnostics", self._on_diag, msg),
                                 10)
        self._wake = self.create_guard_condition(
            lambda: self._guarded("request", self._take_requests))
        self.create_timer(0.2, lambda: self._guarded("timer", self._tick))
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="opcua",
                                        daemon=True)
        self._thread.start()
        self._bridge = BridgeServer(p("endpoint"), self.measure, security,
                                    charge=self.charge if p("charge_service") else None,
                                    abort=self.abort)
        try:
            asyncio.run_coroutine_threadsafe(self._bridge.start(), self._loop).result(
                START_TIMEOUT)
        except SecurityError as exc:
            self._stop_loop()
            raise common.StartupError("opcua", str(exc)) from exc
        except Exception as exc:
            self._stop_loop()
            raise common.StartupError(
                "opcua", f"cannot serve {p('endpoint')}: {type(exc).__name__}: {exc}"
            ) from exc
        users = len(security.users or {})
        who = ("anonymous sessions may measure (allow_anonymous)" if security.allow_anonymous
               else f"{users} user(s) may measure, anonymous sessions may only read" if users
               else "nobody may measure (set allow_anonymous on a lab bench, or users_file)")
        self.get_logger().info(
            f"OPC UA server on {p('endpoint')} (port {self._bridge.port}), security "
            f"{security.policy}, {who}; measurements through {self._action}")

    def _p(self, name: str) -> Any:
        return self.get_parameter(name).value

    @staticmethod
    def _check(changes: dict[str, Any]) -> str:
        """The timeouts and trigger_valve change at run time (the next measurement takes
        them); the server's and security's parameters do not."""
        fixed = set(changes) - {"measure_timeout", "trigger_valve", "final_timeout",
                                "estimator_wait", "charge_wait"}
        return f"{', '.join(sorted(fixed))} cannot change at run time (restart the node)" \
            if fixed else ""

    # ------------------------------------------------------------------ asyncio side
    async def measure(self, part: str) -> Outcome:
        """One measurement of ``part`` (the server's :data:`~pneumatic_unload.plc.MeasureFn`,
        in its event loop): handed to the executor's thread, its outcome awaited."""
        loop = asyncio.get_running_loop()
        done: asyncio.Future[Outcome] = loop.create_future()

        def finish(outcome: Outcome) -> None:  # from the executor's thread
            def settle() -> None:
                if not done.done():
                    done.set_result(outcome)
            loop.call_soon_threadsafe(settle)

        self._requests.append((part, finish))
        self._wake.trigger()
        return await done

    async def charge(self) -> Outcome:
        """The rig's recharge (the server's ``Charge``, in its event loop): the charge
        service called from the executor's thread, its answer awaited."""
        loop = asyncio.get_running_loop()
        done: asyncio.Future[Outcome] = loop.create_future()

        def finish(outcome: Outcome) -> None:  # from the executor's thread
            loop.call_soon_threadsafe(lambda: done.done() or done.set_result(outcome))

        self._charges.append(finish)
        self._wake.trigger()
        return await done

    def abort(self) -> None:
        """Stop the measurement under way (the server's ``Abort``, in its event loop): its
        goal cancelled in the executor's thread."""
        self._abort_requested = True
        self._wake.trigger()

    def _to_server(self, coro: Any) -> None:
        """Run a coroutine of the server in its loop (not waited for)."""
        if self._loop.is_running():
            asyncio.run_coroutine_threadsafe(coro, self._loop)
        else:
            coro.close()

    # ------------------------------------------------------------------ executor side
    def _on_estimate(self, msg: Any) -> None:
        fields = {k: getattr(msg, k) for k in FIELDS}
        est = estimate_from_fields(fields)
        key = (common.stamp_to_ns(msg.unload_start), est.unload_index)
        self._seen[key] = est
        self._seen.move_to_end(key)
        while len(self._seen) > KEPT:
            self._seen.popitem(last=False)
        m = self._current
        if m is not None and m.key == key and is_final(fields):
            self._done(Outcome("Good", "ok", judged(est, self._spec, m.part)))
        else:
            self._to_server(self._bridge.show(est))

    def _on_diag(self, msg: Any) -> None:
        """The estimator's /diagnostics report: its samples received grow (it hears the
        rig: a measurement's unload will have its plateau before the valve opens)."""
        for st in msg.status:
            if st.name != ESTIMATOR_DIAGNOSTICS:
                continue
            count = next((int(kv.value) for kv in st.values
                          if kv.key == "samples" and kv.value.isdigit()), None)
            if count is None:
                continue
            self._hearing = self._samples is not None and count > self._samples[0]
            self._samples = (count, time.monotonic())

    def _ready(self) -> str:
        """'' when a measurement can start: the estimator's action server is there and the
        estimator receives the rig's samples (its reports within the last
        :data:`REPORT_AGE` s say so); else why not."""
        if not self._client.server_is_ready():
            return f"the estimator's action {self._action} is not available"
        if not (self._hearing and self._samples is not None
                and time.monotonic() - self._samples[1] < REPORT_AGE):
            return (f"the estimator receives no pressure samples (its {ESTIMATOR_DIAGNOSTICS!r}"
                    " reports on /diagnostics)")
        return ""

    def _take_requests(self) -> None:
        if self._abort_requested:  # before the requests: a Measure after an Abort starts
            self._abort_requested = False
            aborted = Outcome("BadRequestCancelledByClient", "aborted by a client's Abort "
                              "call")
            while self._requests:  # the aborted measurement, not taken yet
                self.get_logger().warn(f"part {self._requests[0][0]!r}: aborted")
                self._requests.popleft()[1](aborted)
            m = self._current
            if m is not None:
                if m.handle is not None:  # the next goal waits for this one's end
                    m.handle.cancel_goal_async()
                    self._draining = (m.result, time.monotonic() + CANCEL_WAIT)
                elif m.sent:  # and for its answer, which is cancelled when it comes
                    self._draining = (_AnswerPending(), time.monotonic() + CANCEL_WAIT)
                self._done(Outcome("BadRequestCancelledByClient", "aborted by a client's "
                                   "Abort call"))
        while self._charges:
            self._charge(self._charges.popleft())
        while self._requests:
            part, finish = self._requests.popleft()
            if self._current is not None:  # the server allows one: never here
                finish(Outcome("BadInvalidState", "a measurement is running"))
                continue
            self._current = _Measurement(part, finish, time.monotonic())
            self._tick()

    def _tick(self) -> None:
        """Estimator presence (``State``), and the deadlines of the measurement and of the
        charge service's answers."""
        for call in list(self._pending_charges):
            fut, t0, finish, service = call
            if fut.done():
                self._pending_charges.remove(call)
            elif time.monotonic() - t0 > CHARGE_TIMEOUT:
                self._pending_charges.remove(call)
                fut.cancel()
                finish(Outcome("BadTimeout", f"no answer from {service} within "
                               f"{CHARGE_TIMEOUT:g} s"))
        why = self._ready()
        if (not why) != self._estimator_present:
            self._estimator_present = not why
            self._to_server(self._bridge.set_estimator(not why))
        m = self._current
        if m is None:
            return
        now = time.monotonic()
        if self._draining is not None and (self._draining[0].done()
                                           or now > self._draining[1]):
            self._draining = None
        if not m.sent:
            if not why and now >= m.retry_at and self._draining is None:
                self._send(m)
            elif now - m.t0 > self._p("estimator_wait"):
                self._done(Outcome("BadNoCommunication", f"{why} (waited "
                                   f"{self._p('estimator_wait'):g} s)"))
        elif m.crossing is not None and now > m.final_deadline:
            self._done(Outcome("Good", f"ok (no final estimate within "
                               f"{self._p('final_timeout'):g} s: the p* crossing's)",
                               judged(m.crossing, self._spec, m.part)))
        elif m.crossing is None and \
                now - m.sent_at > self._p("measure_timeout") + RESULT_SLACK:
            self._done(Outcome("BadTimeout", f"no answer from {self._action} within "
                               f"{self._p('measure_timeout') + RESULT_SLACK:g} s"))

    def _send(self, m: _Measurement) -> None:
        m.sent, m.sent_at = True, time.monotonic()
        goal = self._Measure.Goal(timeout=float(self._p("measure_timeout")),
                                  trigger_valve=bool(self._p("trigger_valve")),
                                  part_id=m.part)
        if m.retry_at == 0.0:  # its first goal (a retry while the rig recharges is quiet)
            self.get_logger().info(f"measuring part {m.part!r} through {self._action}")
        self._client.send_goal_async(goal).add_done_callback(
            lambda fut: self._guarded("goal response", self._on_goal_response, m, fut))

    def _charge(self, finish: Callable[[Outcome], None]) -> None:
        """Call the charge service; its answer to ``finish`` (not waited for here)."""
        from std_srvs.srv import Trigger

        service = self._p("charge_service")
        client = self.create_client(Trigger, service)
        if not client.wait_for_service(timeout_sec=0.5):
            self.destroy_client(client)
            finish(Outcome("BadNoCommunication", f"charge service {service} not available"))
            return
        fut = client.call_async(Trigger.Request())
        t0 = time.monotonic()

        def answered(f: Any) -> None:
            self.destroy_client(client)
            resp = f.result()
            if resp.success or "already charged" in resp.message:
                finish(Outcome("Good", f"charge: {resp.message}"))
            else:
                finish(Outcome("BadDeviceFailure", f"charge service {service} refused: "
                               f"{resp.message}"))

        fut.add_done_callback(lambda f: self._guarded("charge", answered, f)
                              if not f.cancelled() else None)
        self._pending_charges.append((fut, t0, finish, service))

    def _on_goal_response(self, m: _Measurement, fut: Any) -> None:
        handle = fut.result()
        if m is not self._current:  # aborted (or shut down) before its goal's answer
            if handle is not None and handle.accepted:
                handle.cancel_goal_async()
                self._draining = (handle.get_result_async(),
                                  time.monotonic() + CANCEL_WAIT)
            elif self._draining is not None and isinstance(self._draining[0], _AnswerPending):
                self._draining = None  # refused: nothing runs there
            return
        if handle is None or not handle.accepted:
            self._done(Outcome("BadInvalidState", f"{self._action} refused the goal (a "
                               "measurement is running there)"))
            return
        m.handle = handle
        m.result = handle.get_result_async()
        m.result.add_done_callback(
            lambda f: self._guarded("goal result", self._on_result, m, f))

    def _on_result(self, m: _Measurement, fut: Any) -> None:
        if m is not self._current:
            return
        res = fut.result().result
        if not res.success and NOT_CHARGED in res.message and \
                time.monotonic() - m.t0 < self._p("charge_wait"):
            # the rig recharging after its last unload: the goal again, a little later
            m.sent, m.handle = False, None
            m.retry_at = time.monotonic() + RETRY_PERIOD
            return
        if not res.success:
            code = "BadTimeout" if res.message.startswith("timeout") else "BadDeviceFailure"
            self._done(Outcome(code, res.message))
            return
        est = estimate_from_fields({k: getattr(res.estimate, k) for k in FIELDS})
        m.key = (common.stamp_to_ns(res.estimate.unload_start), est.unload_index)
        final = self._seen.get(m.key)
        if est.final or (final is not None and final.final):
            self._done(Outcome("Good", "ok", judged(final if final is not None and
                                                     final.final else est,
                                                     self._spec, m.part)))
            return
        m.crossing = est
        m.final_deadline = time.monotonic() + self._p("final_timeout")

    def _done(self, outcome: Outcome) -> None:
        m, self._current = self._current, None
        if m is None:
            return
        e = outcome.estimate
        text = f"part {m.part!r}: {outcome.status}: {outcome.message}" + (
            f"; C={e.conductance:.5g} m^3/(s Pa), b={e.critical_ratio:.4g}"
            f"{', ' + e.verdict if e.verdict else ''}" if e is not None else "")
        if outcome.ok:
            self.get_logger().info(text)
        else:
            self.get_logger().warn(text)
        m.finish(outcome)

    def _guarded(self, what: str, fn: Callable[..., None], *args: Any) -> None:
        """Run a callback's work; an error ends the measurement under way
        (BadInternalError) and is logged, never fatal to the node."""
        try:
            fn(*args)
        except Exception as exc:
            self.get_logger().error(f"{what}: {type(exc).__name__}: {exc}")
            self._done(Outcome("BadInternalError", f"{what}: {type(exc).__name__}: {exc}"))

    # ------------------------------------------------------------------ shutdown
    def close(self) -> None:
        """Stop the OPC UA server (a measurement under way answered BadShutdown) and its
        loop."""
        if self._current is not None:
            self._done(Outcome("BadShutdown", "the bridge stopped"))
        if self._loop.is_running():
            try:
                asyncio.run_coroutine_threadsafe(self._bridge.stop(), self._loop).result(10.0)
            except Exception as exc:  # stopping anyway
                self.get_logger().warn(f"OPC UA server stop: {type(exc).__name__}: {exc}")
        self._stop_loop()

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5.0)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run pneumatic_unload opcua`` (``--help``: the parameters,
    exit 0 without starting ROS)."""
    code = config_nodes.help_or_none("opcua", args)
    return code if code is not None else common.run(OpcUaNode, args, executor="single")


if __name__ == "__main__":
    sys.exit(main())
