# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Simulator and estimator nodes over real DDS, each node in its own process.

The end-to-end test runs simulator -> estimator -> recorder in three processes; the others
exercise the estimator's action, parameter validation, bad input and shutdown.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from nodeproc import NodeProcess, spin_until

from pneumatic_unload.config import RigConfig
from pneumatic_unload.physics import orifice_conductance

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

rclpy = pytest.importorskip("rclpy")

C_TRUE = orifice_conductance(2.5e-3)  # 8.0e-9 m^3/(s Pa)
RIG = {"volume": 1e-3, "conductance": C_TRUE, "critical_ratio": 0.4,
       "effects": "heat_transfer", "noise_std": 1000.0, "quantization": 10.0,
       "full_scale": 1.1e6, "seed": 3}


#: Wait for a node's service reply [s]: a node answers in milliseconds, but on two cores
#: shared with a bench a reply took over 10 s (test_parameter_validation, a fresh CI run
#: beside the discrepancy bench).
SERVICE_TIMEOUT = 30.0


def _estimates(node: Any) -> list[Any]:
    from pneumatic_unload_msgs.msg import UnloadEstimate

    from pneumatic_unload.nodes.common import LATCHED_QOS

    got: list[Any] = []
    node.create_subscription(UnloadEstimate, "/estimator/estimate", got.append, LATCHED_QOS)
    return got


def _diagnostics(node: Any) -> list[Any]:
    from diagnostic_msgs.msg import DiagnosticArray

    got: list[Any] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", got.append, 100)
    return got


#: Samples per PressureBlock message of the block-fed end-to-end run [-].
BLOCK = 100


@pytest.mark.parametrize("estimator_input", ["sample", "block"])
def test_simulator_estimator_recorder_end_to_end(tmp_path: Path, ros_node: Any,
                                                 venv_python: Path,
                                                 estimator_input: str) -> None:
    """Three processes: the estimate matches C, the bag holds every sample, analyze agrees
    (the estimator fed FluidPressure samples, or the simulator's PressureBlock messages of
    the same samples while the recorder records the per-sample topic)."""
    node, ex = ros_node
    got = _estimates(node)
    diags = _diagnostics(node)
    bag = tmp_path / "run"
    rec = NodeProcess("recorder", {"output": str(bag)}, tmp_path,
                      extra=["-p", "topics:=['/estimator/settings']"])
    est = NodeProcess("estimator", {"volume": RIG["volume"], "qos": "reliable",
                                    "input": estimator_input}, tmp_path)

    def estimator_states() -> list[str]:
        return [st.message.split(":")[0] for d in diags for st in d.status
                if st.name.endswith("estimator")]

    # the 1 Hz "waiting" report must reach this subscriber before the unload starts: DDS
    # discovery of a new process can take seconds, so the rig starts once it has
    spin_until(node, ex, lambda: "waiting" in estimator_states(), 30.0)
    # the simulator starts streaming once the estimator and the recorder are subscribed: it
    # counts the nodes subscribed to the pressure topics it publishes, the recorder (which
    # reads both /tank/pressure and /tank/pressure_block) once (counted by subscriptions,
    # the recorder alone started the stream and, under load, a block-fed estimator matched
    # ~1.3 s late: it lost the first blocks and its live C differed from the bag's)
    block = estimator_input == "block"
    blocks = {"block_size": BLOCK, "per_sample": True} if block else {"block_size": BLOCK}
    sim = NodeProcess("simulator", {**RIG, "start_delay": 1.5, "wait_for_subscribers": 2,
                                    "duration": 5.0, "auto_charge": False, **blocks}, tmp_path)
    try:
        assert spin_until(node, ex, lambda: any("curve-fit" in m.method for m in got), 40.0), (
            f"no final estimate; estimator said:\n{est.output()[-2000:]}\n"
            f"simulator said:\n{sim.output()[-2000:]}")
        spin_until(node, ex, lambda: False, 0.5)
    finally:
        codes = {p.name: p.stop() for p in (sim, est, rec)}
    assert codes == {"simulator": 0, "estimator": 0, "recorder": 0}, codes
    states = estimator_states()
    for state in ("waiting", "unloading", "done"):  # reported on /diagnostics, in order
        assert state in states, states
    assert states.index("waiting") < states.index("unloading") < states.index("done")
    first, final = got[0], [m for m in got if "curve-fit" in m.method][-1]
    assert first.status == 0 and final.status == 0
    # accuracy of the core issue: model-based C within 2 %, b within 0.03
    assert final.conductance_model == pytest.approx(C_TRUE, rel=0.02)
    assert final.critical_ratio == pytest.approx(RIG["critical_ratio"], abs=0.03)
    assert first.conductance_model == pytest.approx(C_TRUE, rel=0.05)
    assert final.conductance != pytest.approx(C_TRUE, rel=0.005)  # eq 39 keeps its bias
    # every published sample is in the bag
    n_pub = int(sim.wait_output(r"published (\d+) pressure samples", 5.0).group(1))
    from pneumatic_unload.io.bag import read_config, read_estimates, read_pressure

    t_ns, p = read_pressure(bag)[:2]
    assert len(p) == n_pub > 5000
    if block:  # ... and every block reached the estimator (the last partial one is not sent;
        # blocks are fed on arrival, single samples by a worker that may still hold some)
        stats = json.loads(est.wait_output(r"stats (\{.*\})", 5.0).group(1))
        assert stats["received"] == n_pub - n_pub % BLOCK, stats
    assert np.all(np.diff(t_ns) > 0)
    assert RigConfig.from_dict(read_config(bag)).conductance == pytest.approx(C_TRUE)
    recorded = read_estimates(bag)
    assert len(recorded) == len(got)
    # offline analysis of the recording reproduces the live estimates
    out = subprocess.run([str(venv_python), "-m", "pneumatic_unload.app.cli", "analyze", str(bag),
                          "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    offline = json.loads(out.stdout)["published"]
    assert len(offline) == len(recorded)
    for live, off in zip(recorded, offline, strict=True):
        for key in ("conductance", "conductance_model", "tau_exp", "p10", "p_star"):
            # the same machine: bit for bit (said in full when not: which estimate, and
            # what the estimator reported, e.g. a temperature log short of its span)
            assert off[key] == live[key], (
                f"{key} of {live.get('method')}: offline {off[key]!r}, live {live[key]!r}; "
                f"estimator said:\n{est.output()[-3000:]}")


def test_measure_action(tmp_path: Path, ros_node: Any) -> None:
    """~/measure opens the valve, reports progress and returns the estimate; fails clearly."""
    from pneumatic_unload_msgs.action import Measure
    from rclpy.action import ActionClient

    node, ex = ros_node
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"part_types:\n  g:\n    match: '^V-'\n    conductance: "
                    f"[{0.95 * C_TRUE}, {1.05 * C_TRUE}]\n")
    db = tmp_path / "results.sqlite"
    sim = NodeProcess("simulator", {**RIG, "duration": 3.0}, tmp_path)
    est = NodeProcess("estimator", {"volume": RIG["volume"], "curve_fit": False,
                                    "results_db": str(db), "spec_file": str(spec),
                                    "part_id": "bench"}, tmp_path)
    client = ActionClient(node, Measure, "/estimator/measure")

    def run_goal(goal: Any, timeout: float) -> tuple[Any, list[Any]]:
        feedback: list[Any] = []
        fut = client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(
            m.feedback))
        assert spin_until(node, ex, fut.done, SERVICE_TIMEOUT)
        handle = fut.result()
        assert handle.accepted
        res = handle.get_result_async()
        assert spin_until(node, ex, res.done, timeout)
        return res.result().result, feedback

    try:
        assert client.wait_for_server(timeout_sec=15.0)
        time.sleep(1.5)  # a pre-step plateau for the estimator
        result, feedback = run_goal(Measure.Goal(timeout=20.0, trigger_valve=True,
                                                 part_id="V-17"), 25.0)
        assert result.success, result.message
        assert result.estimate.conductance_model == pytest.approx(C_TRUE, rel=0.05)
        assert (result.verdict, result.verdict_reason) == ("pass", "within specification")
        assert feedback and {f.state for f in feedback} & {"unloading"}
        assert all(0 < f.pressure < 1.2e6 for f in feedback if math.isfinite(f.pressure))
        result, _ = run_goal(Measure.Goal(timeout=0.5, trigger_valve=False), 10.0)
        assert not result.success and result.message.startswith("timeout after 0.5 s")
        result, _ = run_goal(Measure.Goal(timeout=0.5, trigger_valve=True,
                                          valve_service="/no/such/valve"), 15.0)
        assert not result.success and "/no/such/valve not available" in result.message
        # a late subscriber still gets the last estimate (reliable, transient local)
        late = _estimates(node)
        assert spin_until(node, ex, lambda: len(late) >= 1, 10.0)
        assert late[-1].conductance_model == pytest.approx(C_TRUE, rel=0.05)
        # an aborted unload (valve closed before p*) fails the goal at once, clearly
        (r,) = _set_params(node, ex, "simulator", valve_close_time=0.15)
        assert r.successful, r.reason
        assert _wait_charged(node, ex, 20.0)
        time.sleep(1.5)  # plateau before the next unload
        result, _ = run_goal(Measure.Goal(timeout=20.0, trigger_valve=True), 25.0)
        assert not result.success and result.message.startswith("aborted: valve closed")
        assert result.estimate.status == 2  # STATUS_ABORTED
        assert result.verdict == ""  # no part type for the node's part_id
    finally:
        codes = [p.stop() for p in (sim, est)]
    assert codes == [0, 0]
    # each unload's estimate in the results database, under the goal's or the node's part
    from pneumatic_unload.testline import open_db, unload_rows

    con = open_db(db)
    rows = unload_rows(con)
    con.close()
    assert [(r["part_id"], r["verdict"], r["writer"]) for r in rows] == [
        ("V-17", "pass", "estimator"), ("bench", None, "estimator")]
    assert rows[0]["status"] == "ok" and rows[1]["status"] in ("aborted", "aborted_sse")


def _wait_charged(node: Any, ex: Any, timeout: float) -> bool:
    """Poll the simulator's ~/charge service until it says the tank is already charged."""
    from std_srvs.srv import Trigger

    cli = node.create_client(Trigger, "/simulator/charge")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        fut = cli.call_async(Trigger.Request())
        if spin_until(node, ex, fut.done, 5.0) and "already charged" in fut.result().message:
            return True
        spin_until(node, ex, lambda: False, 0.3)
    return False


def _set_params(node: Any, ex: Any, target: str, **values: Any) -> Any:
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    cli = node.create_client(SetParameters, f"/{target}/set_parameters")
    assert cli.wait_for_service(timeout_sec=15.0)
    req = SetParameters.Request(
        parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
    fut = cli.call_async(req)
    assert spin_until(node, ex, fut.done, SERVICE_TIMEOUT)
    return fut.result().results


def test_parameter_validation(tmp_path: Path, ros_node: Any, venv_python: Path) -> None:
    """Out-of-range values are rejected with the reason, at run time and at start."""
    node, ex = ros_node
    sim = NodeProcess("simulator", {}, tmp_path)
    est = NodeProcess("estimator", {}, tmp_path)
    try:
        (r,) = _set_params(node, ex, "simulator", volume=-1.0)
        assert not r.successful and "volume" in r.reason and "range" in r.reason
        (r,) = _set_params(node, ex, "simulator", effects="heat_transfer,warp_drive")
        assert not r.successful and "warp_drive" in r.reason
        (r,) = _set_params(node, ex, "simulator", conductance=5e-9)
        assert r.successful, r.reason
        (r,) = _set_params(node, ex, "estimator", heat_model="magic")
        assert not r.successful and "heat_model" in r.reason
        (r,) = _set_params(node, ex, "estimator", volume=0.002)
        assert r.successful, r.reason
    finally:
        codes = [p.stop() for p in (sim, est)]
    assert codes == [0, 0]
    bad = subprocess.run([str(venv_python), "-m", "pneumatic_unload.nodes.simulator",
                          "--ros-args", "-p", "critical_ratio:=1.5"],
                         capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "critical_ratio" in bad.stderr


def test_yaml_parameter_files_match_the_nodes(repo_root: Path, tmp_path: Path) -> None:
    """config/*.yaml name every parameter the nodes declare, and the nodes start with them."""
    import dataclasses

    sim = yaml.safe_load((repo_root / "config/simulator.yaml").read_text())
    sim_keys = set(sim["/**"]["ros__parameters"])
    assert {f.name for f in dataclasses.fields(RigConfig)} <= sim_keys
    # ROS parameter semantics (0 of an optional number: None), as the node reads them
    from pneumatic_unload.config import adapters

    RigConfig(**adapters.from_parameters(RigConfig, sim["/**"]["ros__parameters"]))
    procs = [NodeProcess(name, {}, tmp_path,
                         extra=["--params-file", str(repo_root / f"config/{name}.yaml")])
             for name in ("simulator", "estimator")]
    try:
        for p in procs:
            p.wait_output(r"\] \[(simulator|estimator)\]: (rig at|estimating on)", 20.0)
    finally:
        codes = [p.stop() for p in procs]
    assert codes == [0, 0]


def test_estimator_survives_bad_messages(tmp_path: Path, ros_node: Any) -> None:
    """NaN, a sample out of order and a wrong frame are reported; 7 samples never sent are
    counted as missing on /diagnostics; estimates still come."""
    from sensor_msgs.msg import FluidPressure

    from pneumatic_unload.model import simulate
    from pneumatic_unload.nodes.common import LOSSLESS_INPUT_QOS, ns_to_stamp

    node, ex = ros_node
    got = _estimates(node)
    diags = _diagnostics(node)
    est = NodeProcess("estimator", {"volume": 1e-3, "qos": "reliable", "frame_id": "tank",
                                    "curve_fit": False}, tmp_path)
    # KEEP_ALL: the burst waits for the reader instead of overwriting what it has not taken
    # (a KEEP_LAST 1000 writer lost a sample under CI's load: 8 missing counted, not 7)
    pub = node.create_publisher(FluidPressure, "/tank/pressure", LOSSLESS_INPUT_QOS)
    try:
        assert spin_until(node, ex, lambda: pub.get_subscription_count() > 0, 15.0)
        spin_until(node, ex, lambda: False, 0.5)
        sim = simulate(RigConfig(volume=1e-3, conductance=C_TRUE, pre_time=1.0,
                                 duration=2.0, seed=5))
        t0 = 1_800_000_000 * 10**9
        bad_at = {100: ("nan", math.nan), 200: ("back", None), 300: ("frame", None)}
        for k, (t, p) in enumerate(zip(sim.t, sim.measured, strict=True)):
            if 400 <= k < 407:
                continue  # lost on the way
            m = FluidPressure()
            m.header.frame_id = "tank"
            ns = t0 + round(t * 1e9)
            if k in bad_at:
                kind, _ = bad_at[k]
                if kind == "nan":
                    m.fluid_pressure = math.nan
                    ns_to_stamp(ns, m.header.stamp)
                elif kind == "back":
                    m.fluid_pressure = float(p)
                    ns_to_stamp(ns - 50_000_000, m.header.stamp)
                else:
                    m.header.frame_id = "elsewhere"
                    m.fluid_pressure = float(p)
                    ns_to_stamp(ns, m.header.stamp)
                pub.publish(m)
            ns_to_stamp(ns, m.header.stamp)
            m.header.frame_id = "tank"
            m.fluid_pressure = float(p)
            pub.publish(m)
            if k % 200 == 0:
                ex.spin_once(timeout_sec=0.001)
        assert spin_until(node, ex, lambda: len(got) >= 1, 20.0), est.output()[-2000:]
        spin_until(node, ex, lambda: False, 1.0)
    finally:
        code = est.stop()
    assert code == 0
    assert got[0].status == 0
    assert got[0].conductance_model == pytest.approx(C_TRUE, rel=0.05)
    text = " | ".join(s.message for d in diags for s in d.status)
    assert "non-finite pressure" in text
    assert "out of order" in text  # 50 ms back, the next stamp on time: one sample dropped
    assert "frame_id 'elsewhere' ignored" in text
    assert "7 samples missing from the stream" in text and "input:=block" in text
    missing = [kv.value for d in diags for s in d.status for kv in s.values
               if kv.key == "samples_missing"]
    assert missing and missing[-1] == "7"


def test_replay_of_reference_bag_into_live_estimator(tmp_path: Path, ros_node: Any,
                                                     repo_root: Path) -> None:
    """Replaying bags/two_unloads (pressure and gas temperature) into a live estimator
    reproduces analyze's estimates, the final fits with the logged temperature beside.

    The estimator starts with a wrong tank volume, which is then corrected at run time
    (as ``ros2 param set /estimator volume ...``): the estimates must be the recorded ones,
    so a parameter change reaches the core."""
    from pneumatic_unload.io.bag import read_config

    node, ex = ros_node
    got = _estimates(node)
    bag = repo_root / "bags" / "two_unloads"
    cfg = read_config(bag)
    out = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "analyze", str(bag),
                          "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    recorded = json.loads(out.stdout)["published"]
    est = NodeProcess("estimator", {"volume": 2.0 * cfg["volume"], "qos": "reliable"},
                      tmp_path)
    est.wait_output("estimating on", 20.0)
    (r,) = _set_params(node, ex, "estimator", volume=float(cfg["volume"]))
    assert r.successful, r.reason
    # the gas temperature too: the final fits take it beside the pressure, live as offline
    rep = NodeProcess("replay", {"bag": str(bag), "rate": 0.0,
                                 "topics": ["/tank/pressure", "/tank/temperature"]}, tmp_path)
    try:
        assert spin_until(node, ex, lambda: len(got) >= len(recorded), 60.0), (
            f"{len(got)} of {len(recorded)} estimates; estimator:\n{est.output()[-2000:]}"
            f"\nreplay:\n{rep.output()[-2000:]}")
        assert rep.proc.wait(timeout=30) == 0
    finally:
        codes = [p.stop() for p in (rep, est)]
    assert codes == [0, 0]
    assert len(got) == len(recorded) == 4
    for live, ref in zip(got, recorded, strict=True):
        assert live.unload_index == ref["index"] and live.method == ref["method"]
        for key in ("conductance", "conductance_model", "tau_exp", "p10", "p_star"):
            assert getattr(live, key) == ref[key], key  # the same machine: bit for bit


def test_uncalibrated_volts_input(tmp_path: Path, ros_node: Any) -> None:
    """A rig publishing transducer volts does so on /tank/pressure_volts as Voltage
    messages (none in pascals' FluidPressure), and the estimator (input:=volts) measures
    through signal_gain/signal_offset."""
    from pneumatic_unload_msgs.msg import Voltage
    from sensor_msgs.msg import FluidPressure

    from pneumatic_unload.nodes.common import PRESSURE_QOS

    node, ex = ros_node
    got = _estimates(node)
    volts: list[float] = []
    pascals: list[float] = []
    node.create_subscription(Voltage, "/tank/pressure_volts",
                             lambda m: volts.append(m.voltage), PRESSURE_QOS)
    node.create_subscription(FluidPressure, "/tank/pressure",
                             lambda m: pascals.append(m.fluid_pressure), PRESSURE_QOS)
    zero, sens = 0.5, 1e-5  # V, V/Pa
    est = NodeProcess("estimator", {"input": "volts", "volume": RIG["volume"],
                                    "signal_gain": 1.0 / sens,
                                    "signal_offset": -zero / sens, "curve_fit": False},
                      tmp_path)
    sim = NodeProcess("simulator", {**RIG, "output_volts": True, "transducer_zero": zero,
                                    "transducer_sensitivity": sens, "start_delay": 1.5,
                                    "wait_for_subscribers": 2, "duration": 3.0}, tmp_path)
    try:
        assert spin_until(node, ex, lambda: len(got) >= 1, 40.0), est.output()[-2000:]
    finally:
        codes = [p.stop() for p in (sim, est)]
    assert codes == [0, 0]
    assert got[0].status == 0
    assert got[0].p10 == pytest.approx(7e5, rel=0.005)  # absolute Pa from volts
    assert volts and not pascals
    assert max(volts) == pytest.approx(zero + sens * 7e5, rel=0.01)  # [V]
    assert got[0].conductance_model == pytest.approx(C_TRUE, rel=0.05)


def test_sigterm_and_sigint_exit_zero(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT) and SIGTERM end each node with exit code 0."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        procs = [NodeProcess(n, {}, tmp_path) for n in ("simulator", "estimator")]
        for p in procs:
            p.wait_output(r"(rig at|estimating on)", 20.0)
        assert [p.stop(sig) for p in procs] == [0, 0]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-v"]))


def test_estimator_killed_mid_unload_and_restarted(tmp_path: Path, ros_node: Any) -> None:
    """kill -9 of the estimator mid-unload, a new one started while the rig keeps cycling:
    the new one says it joined an unload under way (log and /diagnostics) and publishes no
    estimate for it, then a correct estimate for the next unload.

    Whether the new node joined the unload under way in its falling part depends on how long
    its start takes (about 1-3 s; more on a loaded machine): the test looks at what happened
    (when the node said it was estimating, against the valve opening's stamp) and, if it came
    too late, kills it in the next unload and starts another, as often as it takes."""
    import re

    from pneumatic_unload_msgs.msg import ValveState

    from pneumatic_unload.nodes.common import LATCHED_QOS

    # up within this time of the valve opening [s], the restarted node joins the falling part
    # of a 5 L unload (tau_exp ~ 3.7 s; one joining up to ~7 s in, discovery included, sees
    # the fall; later, the tail looks like a plateau)
    join_in_time_s = 5.0
    node, ex = ros_node
    got = _estimates(node)
    diags = _diagnostics(node)
    opened: list[int] = []  # stamps of the valve openings [ns, wall clock]
    node.create_subscription(
        ValveState, "/tank/valve", lambda m: opened.append(
            m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec) if m.open else None,
        LATCHED_QOS)
    # a 5 L tank: slow unloads (tau_exp ~ 3.7 s), 8 s each, then 1.6 s to the next
    rig = {**RIG, "volume": 5e-3}
    params = {"volume": rig["volume"], "qos": "reliable", "curve_fit": False}
    est = NodeProcess("estimator", params, tmp_path)
    sim = NodeProcess("simulator", {**rig, "mode": "cycle", "settle_time": 1.0,
                                    "duration": 8.0, "vent_time": 0.3, "charge_time": 0.3,
                                    "wait_for_subscribers": 1}, tmp_path)
    started: list[NodeProcess] = [est]
    late: list[float] = []  # [s] after the valve opening, of each restart that came too late

    def analysing(proc: NodeProcess, after_ns: int) -> bool:
        """``proc`` detected the step of an unload whose valve opened after ``after_ns``."""
        t_open = min((t for t in opened if t > after_ns), default=None)
        return t_open is not None and any(
            int(s) * 1_000_000_000 + int(ns.ljust(9, "0")) > t_open for s, ns in re.findall(
                r"\[(\d+)\.(\d+)\] \[estimator\]: unload step detected", proc.output()))

    try:
        after = 0
        while True:
            # kill it once it analyses an unload (for a restarted node, one it saw begin)
            assert spin_until(node, ex, lambda e=est, t=after: analysing(e, t), 60.0), (
                est.output()[-3000:])
            est.proc.kill()  # SIGKILL, mid-unload
            est.proc.wait()
            t_kill = time.time_ns()
            t_open = max(t for t in opened if t <= t_kill)  # of the unload under way
            n_got, n_diags = len(got), len(diags)
            est = NodeProcess("estimator", params, tmp_path)
            started.append(est)
            assert spin_until(node, ex, lambda e=est: "estimating on" in e.output(), 60.0), (
                est.output()[-3000:])
            after = time.time_ns()
            up_s = (after - t_open) / 1e9
            if up_s <= join_in_time_s:
                break  # up in the falling part of the unload under way: what is tested
            late.append(up_s)
            assert len(late) < 6, (f"every restarted estimator came too late for the unload "
                                   f"under way, {late} s after the valve opened")
        # until a result for the next unload (spinning: the /diagnostics reports come in)
        spin_until(node, ex, lambda: "unload 0: C=" in est.output(), 60.0)
        spin_until(node, ex, lambda: len(got) > n_got, 5.0)
    finally:
        codes = [p.stop() for p in (sim, est)]
        for p in started:
            p.stop()
    assert codes == [0, 0], codes
    log = est.output()
    warn = log.find("no plateau before the drop")
    assert warn >= 0, (f"the restarted estimator did not say it joined mid-unload (it was up "
                       f"{up_s:.1f} s after the valve opened):\n{log[-3000:]}")
    assert "mid-unload" in log[warn:warn + 400] and "waiting for a plateau" in log[warn:]
    assert warn < log.find("] [estimator]: unload 0: C=")  # the first result comes after it
    texts = [s.message for d in diags[n_diags:] for s in d.status
             if s.name.endswith("estimator")]
    # the state reported (also periodically, so a late subscriber sees it) says why
    assert any(m.startswith("waiting: skipping the unload under way: no plateau before the "
                            "drop") and "mid-unload" in m for m in texts), texts
    new = got[n_got:]
    assert new and new[0].unload_index == 0 and new[0].status == 0
    assert new[0].conductance_model == pytest.approx(C_TRUE, rel=0.05)
