# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``simulator`` node: a simulated tank-discharge rig publishing at rig rates.

Publishes
    /tank/pressure (sensor_msgs/FluidPressure, Pa absolute, header stamp = sample instant)
        at ``rate`` from a paced loop on the monotonic clock (an rclpy timer cannot hold
        1 kHz); optionally also blocks of samples on /tank/pressure_block
        (pneumatic_unload_msgs/PressureBlock) when ``block_size`` > 0.
    /tank/temperature (sensor_msgs/Temperature, degrees C)
        at ``temperature_rate``.
    /tank/valve (pneumatic_unload_msgs/ValveState)
        on every change (latched).
    /rig/config (std_msgs/String, JSON of the RigConfig; latched)
        so a recorder stores it.
Services
    ~/start_unload (std_srvs/Trigger)
        open the valve (the tank must be charged).
    ~/charge (std_srvs/Trigger)
        recharge to p10 after an unload.
Parameters
    Every RigConfig field (tank, component, effects, sensor; see ``RigConfig.describe()``),
    with ranges (``direction`` 'charge': the tank filled through the component from
    ``supply_pressure``); plus ``mode`` ('service', 'cycle', or 'alternate': a cycle whose
    steps go in turn the other way, a charge then a discharge of the same component from
    where the last left the tank, :meth:`~pneumatic_unload.model.rig.RigStream.reverse`),
    ``start_delay`` [s] (open once by
    itself after this delay; < 0: never), ``settle_time`` [s], ``vent_time`` [s],
    ``charge_time`` [s], ``cycles`` (0: forever), ``auto_charge``, ``temperature_rate`` [Hz],
    ``block_size``, ``frame_id``, ``output_volts`` (publish the transducer's volts, as an
    uncalibrated rig does, on /tank/pressure_volts (pneumatic_unload_msgs/Voltage) instead
    of Pa on /tank/pressure; blocks then carry volts too; the estimator converts with
    ``input:=volts`` and signal_gain/offset).
    Load them from ``share/pneumatic_unload/config/simulator.yaml``
    with ``--ros-args --params-file``. Rig changes at run time apply from the next unload;
    out-of-range values are rejected with the reason.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import FluidPressure, Temperature
from std_msgs.msg import String
from std_srvs.srv import Trigger

from pneumatic_unload.config import ConfigError, RigConfig
from pneumatic_unload.config import nodes as config_nodes
from pneumatic_unload.model.rig import RigStream
from pneumatic_unload.nodes import common

MODES = ("service", "cycle", "alternate")
#: The calibrated pressure topic [Pa absolute] (sensor_msgs/FluidPressure).
TOPIC_PRESSURE = "/tank/pressure"
#: The transducer's output voltage with ``output_volts`` (pneumatic_unload_msgs/Voltage).
TOPIC_VOLTS = "/tank/pressure_volts"


#: Above this sample rate [Hz] the node publishes blocks by default and advises the block
#: input (single FluidPressure messages outrun a 2-core machine's receiver at 10 kHz).
BLOCK_ADVICE_RATE = 2000.0
#: Samples per block published by default above :data:`BLOCK_ADVICE_RATE` [-].
AUTO_BLOCK = 100
#: Longest wait [s], once the subscriber nodes are discovered, for the publishers to match
#: every subscription discovered on their topics (a subscription whose QoS never matches
#: is not waited for longer).
MATCH_WAIT = 5.0


class SimulatorNode(Node):
    """Simulated rig (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("simulator", **kwargs)
        from pneumatic_unload_msgs.msg import PressureBlock, ValveState, Voltage

        self._ValveState = ValveState
        self._PressureBlock = PressureBlock
        # the one list of parameters (also --help and config/simulator.yaml)
        for name, (default, desc) in common.node_parameters("simulator").items():
            self.declare_parameter(name, default, desc)
        try:
            self._cfg = self._config_from_params({})
        except ConfigError as exc:
            raise common.StartupError("simulator", f"invalid rig parameters: {exc}") from exc
        self._mode = self._p("mode")
        if self._mode not in MODES:
            raise common.StartupError(
                "simulator", f"mode must be one of {MODES}, got {self._mode!r}")
        self.add_on_set_parameters_callback(common.validating_callback(self._check))
        self._lock = threading.Lock()
        self._stream = RigStream(self._cfg, charge_time=self._p("charge_time"))
        self._frame = self._p("frame_id")
        # an uncalibrated rig's volts go on a topic and type of their own (FluidPressure is
        # pascals by its definition)
        self._Sample = Voltage if self._p("output_volts") else FluidPressure
        self._pub_p = self.create_publisher(
            self._Sample, TOPIC_VOLTS if self._p("output_volts") else TOPIC_PRESSURE,
            common.PRESSURE_QOS)
        self._pub_block = self.create_publisher(PressureBlock, "/tank/pressure_block",
                                                common.PRESSURE_QOS)
        self._pub_t = self.create_publisher(Temperature, "/tank/temperature", 10)
        self._pub_valve = self.create_publisher(ValveState, "/tank/valve", common.LATCHED_QOS)
        self._pub_cfg = self.create_publisher(String, "/rig/config", common.LATCHED_QOS)
        self.create_service(Trigger, "~/start_unload", self._on_start)
        self.create_service(Trigger, "~/charge", self._on_charge)
        self._publish_config()
        self._valve_open = False
        self._publish_valve(self.get_clock().now().nanoseconds, 0.0)
        self._stop = threading.Event()
        self.published = 0
        self._thread = threading.Thread(target=self._loop, name="rig-loop", daemon=True)
        self._thread.start()
        self.get_logger().info(
            f"rig at {self._cfg.rate:g} Hz, V={self._cfg.volume:g} m^3, "
            f"C={self._cfg.conductance:.4g} m^3/(s Pa), b={self._cfg.critical_ratio:g}, "
            f"p10={self._cfg.initial_pressure:.0f} Pa, effects={list(self._cfg.effects)}, "
            f"mode={self._mode}")

    # ------------------------------------------------------------------ parameters
    def _p(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _config_from_params(self, changes: dict[str, Any]) -> RigConfig:
        values = {name: self._p(name) for name in common.rig_parameter_descriptors()}
        values.update({k: v for k, v in changes.items() if k in values})
        return common.rig_config_from(values)

    def _check(self, changes: dict[str, Any]) -> str:
        if "rate" in changes and changes["rate"] != self._cfg.rate:
            return "rate cannot change while the simulator runs (restart the node)"
        if "mode" in changes and changes["mode"] not in MODES:
            return f"mode must be one of {MODES}"
        if "frame_id" in changes or "output_volts" in changes:
            return "frame_id and output_volts cannot change while the simulator runs"
        cfg = self._config_from_params(changes)  # ConfigError -> rejected with its reason
        if any(k in common.rig_parameter_descriptors() for k in changes):
            self._cfg = cfg
            with self._lock:
                self._stream.reconfigure(cfg)
            self._publish_config()
        if "charge_time" in changes:
            with self._lock:
                self._stream.charge_time = float(changes["charge_time"])
        if "mode" in changes:
            self._mode = changes["mode"]
        return ""

    def _publish_config(self) -> None:
        self._pub_cfg.publish(String(data=self._cfg.to_json()))

    # ------------------------------------------------------------------ services
    def _on_start(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        with self._lock:
            why = self._stream.open_valve()
        resp.success = not why
        resp.message = why or "valve opened"
        return resp

    def _on_charge(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        with self._lock:
            why = self._stream.charge()
        resp.success = not why
        resp.message = why or "charging"
        return resp

    # ------------------------------------------------------------------ paced loop
    def _loop(self) -> None:
        """Publish every sample when its instant has come (monotonic clock)."""
        try:
            self._run_loop()
        except Exception as exc:  # a dead loop must be visible, not silent
            self.get_logger().error(f"rig loop stopped: {type(exc).__name__}: {exc}")

    def _subscriber_nodes(self, pubs: list[Any]) -> int:
        """Distinct nodes subscribed to any of the publishers' topics [-] (a recorder that
        takes both pressure topics counts once)."""
        nodes = {(info.node_namespace, info.node_name) for pub in pubs
                 for info in self.get_subscriptions_info_by_topic(pub.topic_name)}
        return len(nodes)

    def _block_size(self, rate: float) -> int:
        """Samples per PressureBlock [-] at ``rate`` [Hz]: the parameter, or with -1 (the
        default) :data:`AUTO_BLOCK` above :data:`BLOCK_ADVICE_RATE`, else none."""
        size = int(self._p("block_size"))
        if size >= 0:
            return size
        return AUTO_BLOCK if rate > BLOCK_ADVICE_RATE else 0

    def _matched(self, pubs: list[Any]) -> bool:
        """Every subscription discovered on the publishers' topics is matched by its
        publisher (DDS reader-writer matching done: it receives every sample from now)."""
        return all(pub.get_subscription_count()
                   >= len(self.get_subscriptions_info_by_topic(pub.topic_name)) for pub in pubs)

    def _run_loop(self) -> None:
        rate = self._cfg.rate
        need = int(self._p("wait_for_subscribers"))
        if need:
            # the pressure topics published: per-sample, blocks, or both
            pubs = ([self._pub_p] if self._p("per_sample") else []) \
                + ([self._pub_block] if self._block_size(rate) or not self._p("per_sample")
                   else [])
            names = " + ".join(p.topic_name for p in pubs)
            self.get_logger().info(f"waiting for {need} subscriber node(s) of {names}")
            while self._subscriber_nodes(pubs) < need and not self._stop.is_set():
                time.sleep(0.01)
            # discovered is not yet matched: a reader the writer has not matched loses the
            # first samples (a per-sample estimator under load missed the start of the
            # plateau the recorder has: its fit window, and its C, differed from the bag's)
            until = time.monotonic() + MATCH_WAIT
            while not self._matched(pubs) and time.monotonic() < until \
                    and not self._stop.is_set():
                time.sleep(0.01)
            time.sleep(0.2)  # let the matched readers finish discovery of each other too
        self.get_logger().info(f"streaming at {rate:g} Hz")
        if rate > BLOCK_ADVICE_RATE and self._p("per_sample"):
            advice = (f"blocks of {self._block_size(rate)} samples on /tank/pressure_block: "
                      "run the estimator with input:=block" if self._block_size(rate) else
                      "set block_size (e.g. 100) and run the estimator with input:=block")
            self.get_logger().info(
                f"at {rate:g} Hz single FluidPressure messages outrun a small machine's "
                f"receiver (7.9 % lost at 10 kHz on 2 cores): {advice}")
        wall0 = self.get_clock().now().nanoseconds  # the node's clock (use_sim_time: /clock)
        mono0 = time.monotonic()
        t_step = max(1, round(rate / self._p("temperature_rate"))) \
            if self._p("temperature_rate") > 0 else 0
        block_size = self._block_size(rate)
        per_sample = bool(self._p("per_sample"))
        volts = bool(self._p("output_volts"))
        pending: list[tuple[int, float]] = []
        start_delay = float(self._p("start_delay"))
        phase_since = 0.0
        last_phase = self._stream.phase
        unloads_done = 0
        max_burst = max(1, int(rate * 0.05))
        msg = self._Sample()
        msg.header.frame_id = self._frame
        msg.variance = (self._cfg.noise_std
                        * (self._cfg.transducer_sensitivity if volts else 1.0)) ** 2
        while not self._stop.is_set() and self.context.ok():
            now = time.monotonic() - mono0
            due = math.floor(now * rate) + 1
            k0 = self._stream.next_index
            if due > k0:
                with self._lock:
                    block = self._stream.next_block(min(due - k0, max_burst))
                    phase = self._stream.phase
                values = block.measured
                if volts:
                    values = self._cfg.transducer_zero + self._cfg.transducer_sensitivity * values
                for k, y in zip(block.index.tolist(), values.tolist(), strict=True):
                    if block_size:
                        # the stamp a PressureBlock receiver reconstructs (block header +
                        # round(j T 1e9)): both pressure topics carry the same stamps, so a
                        # block-fed estimator and the recorded per-sample topic agree exactly
                        kb = k - k % block_size
                        ns = wall0 + round(kb * 1e9 / rate) + round((k - kb) * (1.0 / rate)
                                                                    * 1e9)
                    else:
                        ns = wall0 + round(k * 1e9 / rate)
                    if per_sample:
                        common.ns_to_stamp(ns, msg.header.stamp)
                        if volts:
                            msg.voltage = y
                        else:
                            msg.fluid_pressure = y
                        self.published += self._publish(self._pub_p, msg)
                    if block_size:
                        pending.append((ns, y))
                        if len(pending) >= block_size:
                            sent = self._publish_block(pending, rate)
                            self.published += 0 if per_sample else sent
                            pending = []
                    if t_step and k % t_step == 0:
                        tm = Temperature()
                        tm.header.frame_id = self._frame
                        common.ns_to_stamp(ns, tm.header.stamp)
                        tm.temperature = float(block.temperature[k - k0]) - 273.15
                        self._publish(self._pub_t, tm)
                is_open = block.opening > 0
                for j in np.flatnonzero(is_open != np.concatenate(
                        ([self._valve_open], is_open[:-1]))):
                    self._valve_open = bool(is_open[j])
                    self._publish_valve(wall0 + round(int(block.index[j]) * 1e9 / rate),
                                        float(block.opening[j]))
                t_now = float(block.t[-1])
                if phase != last_phase:
                    if phase == "vented":
                        unloads_done += 1
                    last_phase, phase_since = phase, t_now
                self._schedule(phase, t_now - phase_since, t_now, start_delay, unloads_done)
                if start_delay >= 0 and t_now >= start_delay:
                    start_delay = -1.0
                continue
            time.sleep(max(0.0, (k0 / rate) - (time.monotonic() - mono0)))

    def _schedule(self, phase: str, in_phase: float, t_now: float, start_delay: float,
                  unloads_done: int) -> None:
        """Automatic valve and charge actions of the modes."""
        cycles = int(self._p("cycles"))
        with self._lock:
            auto = self._mode in ("cycle", "alternate")
            if phase == "charged":
                if auto and in_phase >= self._p("settle_time") and (
                        cycles == 0 or unloads_done < cycles):
                    self._stream.open_valve()
                elif 0 <= start_delay <= t_now:
                    self._stream.open_valve()
            elif phase == "vented" and in_phase >= self._p("vent_time") and (
                    auto or self._p("auto_charge")):
                if auto and cycles and unloads_done >= cycles:
                    return
                if self._mode == "alternate":  # the other direction from where it is
                    # (/rig/config stays the cycle's: a recorder starts a new bag on a new
                    # configuration, and the cycle is one recording)
                    why = self._stream.reverse()
                    if why:
                        self.get_logger().error(why, throttle_duration_sec=5.0)
                    return
                self._stream.charge()

    def _publish(self, pub: Any, msg: Any) -> bool:
        try:
            pub.publish(msg)
        except Exception as exc:  # RCLError when a reliable reader is too slow: keep going
            if self.context.ok():
                self.get_logger().warn(f"publish failed: {exc}", throttle_duration_sec=1.0)
            return False
        return True

    def _publish_block(self, pending: list[tuple[int, float]], rate: float) -> int:
        """Publish a PressureBlock; return the number of samples sent (0 on failure)."""
        m = self._PressureBlock()
        m.header.frame_id = self._frame
        common.ns_to_stamp(pending[0][0], m.header.stamp)
        m.sample_period = 1.0 / rate
        m.pressure = [y for _, y in pending]
        ok = self._publish(self._pub_block, m)
        return len(pending) if ok else 0

    def _publish_valve(self, ns: int, opening: float) -> None:
        m = self._ValveState()
        m.header.frame_id = self._frame
        common.ns_to_stamp(ns, m.header.stamp)
        m.open = opening > 0
        m.opening = opening
        self._publish(self._pub_valve, m)

    def close(self) -> None:
        """Stop the paced loop and report how many samples were published."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.get_logger().info(f"published {self.published} pressure samples")


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run pneumatic_unload simulator`` (``--help``: the parameters,
    exit 0 without starting ROS)."""
    code = config_nodes.help_or_none("simulator", args)
    return code if code is not None else common.run(SimulatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
