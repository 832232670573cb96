# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Recorder and replay nodes over real DDS (each node in its own process), and their ROS-free
parts (RecordingSession, ReplayPlan, pace, the bag helpers they use) in process.

The DDS tests start the nodes with ``sys.executable -m pneumatic_unload.nodes.<node>
--ros-args -p ...`` and small publisher/subscriber scripts (``_TOOL`` below), all inheriting
the test run's ROS_DOMAIN_ID from conftest.py. Every process has a deadline and is killed in a
finally block.
"""

import json
import math
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.io.bag import (
    CONFIG_METADATA_KEY,
    MSGTYPE_CONFIG,
    MSGTYPE_ESTIMATE,
    MSGTYPE_PRESSURE,
    MSGTYPE_VALVE,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_SETTINGS,
    TOPIC_VALVE,
    BagRecorder,
    BagWriteError,
    RawMessage,
    TopicNotFoundError,
    UnknownMessageTypeError,
    bag_summary,
    cdr_header_stamp_ns,
    make_typestore,
    read_config,
    read_estimates,
    read_json_topic,
    read_pressure,
    read_raw_messages,
)
from pneumatic_unload.nodes.recorder import RecorderParameterError, RecordingSession
from pneumatic_unload.nodes.replay import ReplayParameterError, ReplayPlan, pace

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

NODE_DEADLINE_S = 30.0  # every process is killed after this
CONFIG = {"volume": 0.005, "conductance": 4.2e-9, "rig": "test"}

# ----------------------------------------------------------------------- helper processes

_TOOL = textwrap.dedent(
    '''
    """pub: publishes a scripted stream; sub: collects /tank/pressure and /rig/config."""
    import json, math, sys, time
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import FluidPressure, Temperature
    from std_msgs.msg import String
    from pneumatic_unload_msgs.msg import UnloadEstimate, ValveState

    from pneumatic_unload.nodes.replay import use_fast_heartbeat

    PROFILE = use_fast_heartbeat()  # quick wait_for_all_acked() for flush() below
    ARGS = json.loads(sys.argv[1])
    DEADLINE = time.monotonic() + ARGS.get("timeout", 25.0)


    def qos(latched=False, depth=1000):
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                          else DurabilityPolicy.VOLATILE)


    def stamp(msg, t_ns):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
        return msg


    def pub_main(node):
        pubs = {
            "p": node.create_publisher(FluidPressure, "/tank/pressure", qos()),
            "T": node.create_publisher(Temperature, "/tank/temperature", qos()),
            "v": node.create_publisher(ValveState, "/tank/valve", qos(True, 10)),
            "e": node.create_publisher(UnloadEstimate, "/estimator/estimate", qos(True, 10)),
            "c": node.create_publisher(String, "/rig/config", qos(True, 1)),
            "x": node.create_publisher(String, "/extra/chatter", qos()),
            # a second configuration publisher for invalid texts (transient local like the
            # convention: a volatile writer does not match the recorder's latched reader)
            "bad": node.create_publisher(String, "/rig/config", qos(True, 1)),
        }
        waited = [p for key, p in pubs.items() if key != "x" or ARGS.get("extra")]
        while any(p.get_subscription_count() < 1 for p in waited):
            if time.monotonic() > DEADLINE:
                print(json.dumps({"error": "recorder did not subscribe"}), flush=True)
                return 3
            time.sleep(0.01)
        time.sleep(0.3)

        def flush(timeout=5.0):
            for p in pubs.values():
                p.wait_for_all_acked(Duration(seconds=timeout))

        report = {}
        if ARGS.get("set_param"):
            report["set_param"] = set_param(node, *ARGS["set_param"])
        sent = {"p": 0, "T": 0, "v": 0, "e": 0, "x": 0}
        if ARGS.get("bad"):
            pubs["bad"].publish(String(data="{not json"))
            pubs["bad"].publish(String(data="[1, 2]"))
            for t_ns, value in ((5_000_000_000, math.nan), (-3_000_000_000, 1.0), (0, 2.0)):
                pubs["p"].publish(stamp(FluidPressure(fluid_pressure=value), t_ns))
                sent["p"] += 1
            flush()
        if ARGS.get("config") is not None:
            pubs["c"].publish(String(data=ARGS["config"]))
            flush()
        events = {int(k): v for k, v in ARGS.get("events", {}).items()}
        n, rate, t0 = ARGS["n"], ARGS["rate"], ARGS["t0_ns"]
        start = time.monotonic()
        k = 0
        stamps = []
        while (n < 0 or k < n) and time.monotonic() < DEADLINE:
            if n < 0 and select_ready():  # continuous mode: until a line on stdin
                break
            due = start + k / rate
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            t_ns = time.time_ns() if t0 == 0 else t0 + int(round(k * 1e9 / rate))
            if k in events:
                flush()
                kind = events[k]
                if kind in ("open", "close"):
                    pubs["v"].publish(stamp(ValveState(open=kind == "open",
                                                       opening=float(kind == "open")), t_ns))
                    sent["v"] += 1
                elif kind == "estimate":  # the next unload's first estimate
                    pubs["e"].publish(stamp(UnloadEstimate(unload_index=sent["e"]), t_ns))
                    sent["e"] += 1
                elif kind == "final":  # a second estimate of the same unload
                    index = max(0, sent["e"] - 1)
                    pubs["e"].publish(stamp(UnloadEstimate(unload_index=index), t_ns))
                flush()
            pubs["p"].publish(stamp(FluidPressure(fluid_pressure=1e5 + k), t_ns))
            sent["p"] += 1
            stamps.append(t_ns)
            if k % 100 == 0:
                pubs["T"].publish(stamp(Temperature(temperature=20.0), t_ns))
                pubs["x"].publish(String(data=f"chatter {k}"))
                sent["T"] += 1
                sent["x"] += 1
            k += 1
        flush(0.0 if n < 0 else 5.0)  # continuous mode: the recorder was killed
        report.update(sent=sent, first=stamps[:1], last=stamps[-1:])
        if n < 0:  # continuous mode: every stamp
            report["stamps"] = stamps
        print(json.dumps(report), flush=True)
        return 0


    def set_param(node, target, name, value):
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        client = node.create_client(SetParameters, f"/{target}/set_parameters")
        if not client.wait_for_service(timeout_sec=10.0):
            return {"error": "no parameter service"}
        request = SetParameters.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg()])
        future = client.call_async(request)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.spin_until_future_complete(future, timeout_sec=10.0)
        ex.remove_node(node)
        result = future.result().results[0]
        return {"successful": result.successful, "reason": result.reason}


    def select_ready():
        import select
        return bool(select.select([sys.stdin], [], [], 0)[0])


    def sub_main(node):
        got, config = [], []
        node.create_subscription(
            FluidPressure, "/tank/pressure",
            lambda m: got.append((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                                  m.fluid_pressure, time.monotonic())), qos())
        node.create_subscription(String, "/rig/config", lambda m: config.append(m.data),
                                 qos(True, 1))
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        print(json.dumps({"ready": True}), flush=True)
        last = time.monotonic()
        while time.monotonic() < DEADLINE and len(got) < ARGS["count"]:
            ex.spin_once(timeout_sec=0.05)
        linger = time.monotonic() + ARGS.get("linger", 0.3)
        while time.monotonic() < linger:
            ex.spin_once(timeout_sec=0.05)
        print(json.dumps({"samples": got, "config": config}), flush=True)
        return 0


    rclpy.init()
    node = rclpy.create_node("tool_" + ARGS["mode"])
    try:
        rc = pub_main(node) if ARGS["mode"] == "pub" else sub_main(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        rc = 130
    node.destroy_node()
    rclpy.try_shutdown()
    if PROFILE is not None:
        PROFILE.unlink(missing_ok=True)
    sys.exit(rc)
    '''
)


@pytest.fixture(scope="module")
def tool(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tool") / "dds_tool.py"
    path.write_text(_TOOL)
    return path


def _spawn(args: list[str], cwd: Path) -> subprocess.Popen:
    """Start ``args`` in ``cwd``, with ``cwd`` its temporary directory too (the Fast DDS
    profile the replay writes lands there: :func:`left_profiles`)."""
    return subprocess.Popen(
        args, cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env={**os.environ, "TMPDIR": str(cwd)})


def left_profiles(cwd: Path) -> list[Path]:
    """The replay's Fast DDS profiles left in ``cwd`` (each process removes its own when it
    ends, also on SIGINT)."""
    return sorted(cwd.glob("pneumatic_unload_replay_*.xml"))


def start_node(node: str, cwd: Path, **params) -> subprocess.Popen:
    """``python -m pneumatic_unload.nodes.<node> --ros-args -p k:=v ...``."""
    cmd = [sys.executable, "-m", f"pneumatic_unload.nodes.{node}", "--ros-args"]
    for key, value in params.items():
        if isinstance(value, bool):
            value = str(value).lower()
        elif isinstance(value, list):
            value = "[" + ",".join(f"'{v}'" for v in value) + "]"
        cmd += ["-p", f"{key}:={value}"]
    return _spawn(cmd, cwd)


def start_tool(tool: Path, cwd: Path, **args) -> subprocess.Popen:
    return _spawn([sys.executable, str(tool), json.dumps(args)], cwd)


def finish(proc: subprocess.Popen, timeout: float = NODE_DEADLINE_S) -> tuple[int, str, str]:
    """Wait for ``proc`` (killing it after ``timeout``); returns (rc, stdout, stderr)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"process did not end within {timeout} s:\n{out}\n{err}")
    return proc.returncode, out, err


def interrupt(proc: subprocess.Popen, timeout: float = 15.0) -> tuple[int, str, str]:
    """SIGINT (Ctrl-C) to ``proc``, then :func:`finish`."""
    proc.send_signal(signal.SIGINT)
    return finish(proc, timeout)


def last_json(text: str) -> dict:
    lines = [ln for ln in text.splitlines() if ln.startswith("{")]
    assert lines, f"no JSON output in:\n{text}"
    return json.loads(lines[-1])


def wait_for_line(proc: subprocess.Popen, needle: str, timeout: float = 15.0) -> None:
    """Read ``proc``'s stdout until a line containing ``needle``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if needle in line:
            return
        if not line and proc.poll() is not None:
            break
    pytest.fail(f"no {needle!r} from the process")


@pytest.fixture
def procs():
    """Processes to kill at the end of the test, whatever happens."""
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
            p.communicate()


# --------------------------------------------------------------------- recorder over DDS


def test_record_sigint_gives_complete_bag_with_every_message(tool, tmp_path, procs):
    bag = tmp_path / "rec"
    n = 1500
    rec = start_node("recorder", tmp_path, output=str(bag), flush_interval=0.2,
                     topics=["/extra/chatter", "/never/published", "bad name!"])
    procs.append(rec)
    pub = start_tool(tool, tmp_path, mode="pub", n=n, rate=1000.0, t0_ns=1_700_000_000 * 10**9,
                     config=json.dumps(CONFIG), events={"300": "open", "1200": "estimate"},
                     extra=True, set_param=["recorder", "flush_interval", 1.0])
    procs.append(pub)
    rc, out, err = finish(pub)
    assert rc == 0, err
    report = last_json(out)
    sent = report["sent"]
    # a parameter change at run time is rejected with the reason
    assert report["set_param"]["successful"] is False
    assert "restart" in report["set_param"]["reason"]
    assert sent["p"] == n
    assert rec.poll() is None, "the recorder died"
    rc, _, rec_err = interrupt(rec)
    assert rc == 0, rec_err
    assert "bad name!" in rec_err and "invalid name" in rec_err

    # every published sample, in order, with its header stamp and value
    t_ns, p = read_pressure(bag)
    assert t_ns.size == n
    expected_t = 1_700_000_000 * 10**9 + np.round(np.arange(n) * 1e6).astype(np.int64)
    assert np.array_equal(t_ns, expected_t)
    assert np.array_equal(p, 1e5 + np.arange(n))
    assert read_config(bag) == CONFIG
    summary = bag_summary(bag)
    counts = {name: info.count for name, info in summary.topics.items()}
    assert counts["/tank/temperature"] == sent["T"]
    assert counts[TOPIC_VALVE] == sent["v"] == 1
    assert counts[TOPIC_ESTIMATE] == sent["e"] == 1
    assert counts["/extra/chatter"] == sent["x"]
    assert counts[TOPIC_CONFIG] == 1
    assert summary.topics["/extra/chatter"].msgtype == "std_msgs/msg/String"
    assert "/never/published" not in counts

    # the standard readers: rosbags (deserialising everything) and mcap + mcap-ros2-support
    with AnyReader([bag]) as reader:
        decoded = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(decoded) == sum(counts.values())
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as f:
        mcap_reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topics_seen: dict[str, int] = {}
        for _, channel, _, ros_msg in mcap_reader.iter_decoded_messages():
            topics_seen[channel.topic] = topics_seen.get(channel.topic, 0) + 1
            if channel.topic == TOPIC_PRESSURE:
                assert ros_msg.fluid_pressure >= 1e5
    assert topics_seen == counts


def _mcap_chunks(mcap_file: Path) -> list[list[tuple[str, int]]]:
    """The complete chunks of an MCAP file that is being written or whose writer was killed
    (read only; the torn tail is left out): per chunk, the (topic, log time [ns]) of its
    messages in the order written. The recorder hands its data to the operating system one
    chunk per flush, so the chunks on disk are its flushes."""
    from mcap.records import Channel, Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk

    topics: dict[int, str] = {}
    chunks: list[list[tuple[str, int]]] = []
    with mcap_file.open("rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=True).records:
                if not isinstance(record, Chunk):
                    continue
                messages = []
                for inner in breakup_chunk(record, validate_crc=True):
                    if isinstance(inner, Channel):
                        topics[inner.id] = inner.topic
                    elif isinstance(inner, Message):
                        messages.append((topics.get(inner.channel_id, "?"), inner.log_time))
                chunks.append(messages)
        except Exception:  # the torn tail: a record not (yet) complete
            pass
    return chunks


def _pressure_on_disk(bag: Path) -> int:
    """Pressure samples in the complete chunks of the bag being written."""
    files = list(bag.glob("*.mcap"))
    if not files:
        return 0
    return sum(topic == TOPIC_PRESSURE for chunk in _mcap_chunks(files[0]) for topic, _ in chunk)


def test_kill9_loses_at_most_about_one_second_and_recover_repairs(tool, tmp_path, procs):
    """kill -9 of the recorder mid-stream: recover gives back everything on disk, the stream
    without a gap, and what is lost is about flush_interval of the recorder's receptions.

    Measured on the recorder's own clock (the bag's log times are its receive times), not on
    how fast this machine delivers: every chunk (one per flush) holds, but for its last
    message (the one whose write found the interval elapsed), messages received within
    flush_interval of its first one; and no sample lost had been received much more than
    flush_interval before the kill (the first one lost came after the last one on disk and
    after it was published; the margin: 1 s plus the longest pause between receptions seen
    in the run, a loaded machine's scheduling)."""
    flush = 0.5
    bag = tmp_path / "crash"
    rec = start_node("recorder", tmp_path, output=str(bag), flush_interval=flush)
    procs.append(rec)
    pub = start_tool(tool, tmp_path, mode="pub", n=-1, rate=1000.0, t0_ns=0,
                     config=json.dumps(CONFIG))
    procs.append(pub)
    # until the recorder has put 1500 samples on disk by itself, with its periodic flushes (a
    # recorder that writes nothing before it is stopped never gets there)
    deadline = time.monotonic() + 60.0
    on_disk = 0
    while on_disk < 1500:
        assert rec.poll() is None and pub.poll() is None, "the recorder or the publisher died"
        assert time.monotonic() < deadline, f"{on_disk} samples on disk after 60 s"
        time.sleep(0.1)
        on_disk = _pressure_on_disk(bag)
    # the poll has just seen a flush: strike late in the flush cycle, when the most is
    # pending (what this waits for is the phase of the kill, not an event)
    time.sleep(0.8 * flush)
    t_kill_ns = time.time_ns()
    rec.send_signal(signal.SIGKILL)
    rec.communicate()
    pub.stdin.write("stop\n")  # the publisher stops and reports
    pub.stdin.flush()
    rc, out, err = finish(pub)
    assert rc == 0, err
    published = last_json(out)["stamps"]  # [ns, wall clock] of every sample
    assert not (bag / "metadata.yaml").exists()
    (mcap_file,) = bag.glob("*.mcap")
    chunks = _mcap_chunks(mcap_file)  # what the killed recorder left on disk

    result = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "recover", str(bag)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    t_ns, p = read_pressure(bag)
    assert t_ns.size >= on_disk  # everything that was on disk before the kill
    index = np.round(p - 1e5).astype(np.int64)
    assert np.array_equal(index, np.arange(index.size)), "recovered samples have gaps"
    assert read_config(bag) == CONFIG

    # every flush handed over the messages received since the one before, within
    # flush_interval of the first of them (2 ms: wall and monotonic clocks)
    spans = [(c[-2][1] - c[0][1]) / 1e9 for c in chunks if len(c) > 1]
    assert spans and max(spans) < flush + 0.002, spans
    # the kill lost what came after the last flush: about flush_interval of receptions. The
    # first sample lost was received after the last one on disk and after it was published:
    # it was at most this old at the kill [s]
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_PRESSURE]
        received = np.array([log for _, log, _ in reader.messages(conns)], dtype=np.int64)
    assert received.size == t_ns.size
    first_lost = published[t_ns.size] if t_ns.size < len(published) else t_kill_ns
    lost_s = (t_kill_ns - max(int(received[-1]), first_lost)) / 1e9
    pause_s = float(np.diff(received).max()) / 1e9
    assert lost_s <= flush + 1.0 + 2.0 * pause_s, (
        f"a sample received up to {lost_s:.3f} s before the kill was lost (the longest pause "
        f"between receptions: {pause_s:.3f} s)")


def test_bad_messages_are_recorded_and_do_not_kill_the_recorder(tool, tmp_path, procs):
    bag = tmp_path / "bad"
    rec = start_node("recorder", tmp_path, output=str(bag), log_time="header")
    procs.append(rec)
    t0 = 1_600_000_000 * 10**9
    pub = start_tool(tool, tmp_path, mode="pub", n=200, rate=1000.0, t0_ns=t0, bad=True,
                     config=json.dumps(CONFIG))
    procs.append(pub)
    rc, _, err = finish(pub)
    assert rc == 0, err
    assert rec.poll() is None, "the recorder died from a bad message"
    t_before = time.time_ns()
    rc, _, rec_err = interrupt(rec)
    assert rc == 0, rec_err
    assert "not valid JSON" in rec_err and "not a JSON object" in rec_err

    # all 203 pressure messages are in the bag, the NaN one included
    t_ns, p = read_pressure(bag)
    assert t_ns.size == 203
    assert math.isnan(p[t_ns == 5_000_000_000][0])
    assert read_config(bag) == CONFIG  # the invalid configurations were not stored
    # log_time:=header: log time = header stamp, but receive time for stamps <= 0
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC_PRESSURE]
        logs = {cdr_header_stamp_ns(raw): log for _, log, raw in reader.messages(conns)}
    for k in range(200):
        stamp = t0 + k * 1_000_000
        assert logs[stamp] == stamp
    assert logs[5_000_000_000] == 5_000_000_000
    for stamp in (-3_000_000_000, 0):
        assert t_before - 30 * 10**9 < logs[stamp] <= t_before


def test_split_unload_gives_one_bag_per_unload(tool, tmp_path, procs):
    out = tmp_path / "unloads"
    rec = start_node("recorder", tmp_path, output=str(out), split="unload")
    procs.append(rec)
    # unload 1: open at 100, estimate at 300 (valve still open), close at 400;
    # unload 2: open at 500, close at 650, estimate at 700 (valve already closed), its final
    # estimate at 750 (after the split: it goes to the bag of its unload)
    events = {"100": "open", "300": "estimate", "400": "close", "500": "open",
              "650": "close", "700": "estimate", "750": "final"}
    pub = start_tool(tool, tmp_path, mode="pub", n=900, rate=2000.0, t0_ns=10**18,
                     config=json.dumps(CONFIG), events=events)
    procs.append(pub)
    rc, _, err = finish(pub)
    assert rc == 0, err
    rc, _, rec_err = interrupt(rec)
    assert rc == 0, rec_err

    bags = sorted(p for p in out.iterdir() if p.is_dir())
    assert [b.name for b in bags] == ["unload-000", "unload-001", "unload-002"]
    first_index = []
    for b in bags:
        assert read_config(b) == CONFIG
        _, p = read_pressure(b)
        index = np.round(p - 1e5).astype(int)
        assert np.array_equal(index, np.arange(index[0], index[0] + index.size))
        first_index.append(int(index[0]))
    # a new bag starts at the valve close after the estimate, or right after the estimate
    assert first_index == [0, 400, 700]
    assert [[e["unload_index"] for e in read_estimates(b)] for b in bags[:2]] == [[0], [1, 1]]
    assert TOPIC_ESTIMATE not in bag_summary(bags[2]).topics
    assert bag_summary(bags[1]).topics[TOPIC_VALVE].count == 3  # close, open, close


# ----------------------------------------------------------------------- replay over DDS


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sim") / "run"
    write_simulated_bag(RigConfig(pre_time=0.1, duration=0.9, seed=3), path)
    return path


@pytest.mark.parametrize("rate", [2.0, 0.5, 0.0])
def test_replay_delivers_every_sample_with_original_stamps(tool, sim_bag, tmp_path, procs,
                                                           rate):
    """Every sample, once, in order, with its stamp; paced (rate > 0) with the bag's timing
    scaled by 1/rate, as ratios of durations on the receiver's clock (this machine's speed
    only ever makes a paced replay late, never early): at no sample is the replay ahead of
    its pace by more than a fifth of the paced duration (a replay that ignores the pace or
    the rate is: unpaced, or at rate 1 or 2 instead of 0.5, by half of it or more), and at
    rate 0.5 (500 samples/s, which any machine keeps up with) it is not late by half."""
    t_ref, p_ref = read_pressure(sim_bag)
    sub = start_tool(tool, tmp_path, mode="sub", count=int(t_ref.size), linger=0.3)
    procs.append(sub)
    wait_for_line(sub, "ready")
    rep = start_node("replay", tmp_path, bag=str(sim_bag), rate=rate)
    procs.append(rep)
    rc, _, rep_err = finish(rep)
    assert rc == 0, rep_err
    rc, out, err = finish(sub)
    assert rc == 0, err
    assert not left_profiles(tmp_path)
    got = last_json(out)
    samples = np.array(got["samples"])
    assert samples.shape[0] == t_ref.size, "samples lost or duplicated"
    assert np.array_equal(samples[:, 0].astype(np.int64), t_ref)
    assert np.array_equal(samples[:, 1], p_ref)
    assert [json.loads(c) for c in got["config"]] == [read_config(sim_bag)]
    span_bag = (t_ref[-1] - t_ref[0]) / 1e9
    received = samples[:, 2] - samples[0, 2]  # [s] after the first sample
    if rate > 0:
        paced = (t_ref - t_ref[0]) / 1e9 / rate  # [s] after the first sample, by the pace
        ahead = float(np.max(paced - received)) / paced[-1]
        late = float(np.max(received - paced)) / paced[-1]
        assert ahead < 0.2, (f"ahead of the pace by {ahead:.0%} of its duration (late by "
                             f"{late:.0%})")
        if rate <= 1.0:
            assert late < 0.5, f"late by {late:.0%} of the paced duration"
    else:
        assert received[-1] < span_bag  # faster than real time, and lossless (above)


_CLOCK_TOOL = textwrap.dedent(
    '''
    """Subscribes to /tank/pressure (so that the replay starts) and /clock, in a node run
    with use_sim_time; prints the /clock times and the node's own time at the end."""
    import json, sys, time
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import FluidPressure

    ARGS = json.loads(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node("clock_tool", parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    clocks, stamps = [], []
    node.create_subscription(
        Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec),
        QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(
        FluidPressure, "/tank/pressure",
        lambda m: stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    print("ready", flush=True)
    deadline = time.monotonic() + 25.0
    while time.monotonic() < deadline and len(stamps) < ARGS["count"]:
        ex.spin_once(timeout_sec=0.05)
    linger = time.monotonic() + 0.5
    while time.monotonic() < linger:
        ex.spin_once(timeout_sec=0.05)
    print(json.dumps({"clocks": clocks, "samples": len(stamps),
                      "now": node.get_clock().now().nanoseconds}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    '''
)


def test_replay_publishes_the_bags_time_on_clock(sim_bag, tmp_path, procs):
    """With publish_clock, a use_sim_time subscriber's /clock follows the bag's log times
    as they are replayed: from the first to the last message, never backwards, each a
    message's log time, and the node's ROS time is the bag's last time. (A keep-last
    depth-1 clock writer may overwrite ticks a slow reader has not taken: their spacing is
    covered by test_sim_clock_steps_follow_the_log_times.)"""
    logs = np.array([m.log_time_ns for m in read_raw_messages(sim_bag)
                     if m.topic != TOPIC_CONFIG], np.int64)
    t_ref, _ = read_pressure(sim_bag)
    script = tmp_path / "clock_tool.py"
    script.write_text(_CLOCK_TOOL)
    sub = start_tool(script, tmp_path, count=int(t_ref.size))
    procs.append(sub)
    wait_for_line(sub, "ready")
    rep = start_node("replay", tmp_path, bag=str(sim_bag), rate=2.0, publish_clock=True)
    procs.append(rep)
    rc, _, rep_err = finish(rep)
    assert rc == 0, rep_err
    rc, out, err = finish(sub)
    assert rc == 0, err
    got = last_json(out)
    clocks = np.array(got["clocks"], np.int64)
    assert got["samples"] == t_ref.size
    assert clocks.size > 1, "no /clock published"
    assert clocks[0] == logs.min() and clocks[-1] == logs.max()
    assert np.all(np.diff(clocks) >= 0), "/clock went backwards"
    assert np.all(np.isin(clocks, logs)), "a /clock time that no message of the bag has"
    assert got["now"] == logs.max()


def test_sim_clock_steps_follow_the_log_times():
    """Which log times go out on /clock (ROS-free): the first of each CLOCK_STEP_NS
    interval, also at a spacing a little under the step, a step back (a loop's new pass)
    at once, and the last one of a pass by flush()."""
    from pneumatic_unload.nodes.replay import CLOCK_STEP_NS, SimClock

    sent: list[int] = []
    clock = SimClock(sent.append)
    clock.flush()
    assert sent == []
    step = CLOCK_STEP_NS
    for t in (0, step // 4, step // 2, step, step + 1, 2 * step, 2 * step + step // 2):
        clock.tick(t)
    clock.flush()
    assert sent == [0, step, 2 * step, 2 * step + step // 2]
    clock.tick(step // 4)  # the next pass of a loop
    clock.flush()
    assert sent[-1] == step // 4
    sent.clear()
    for k in range(1, 11):  # a 1 kHz stream whose stamps are 64 ns short of 1 ms apart
        clock.tick(10 * step + k * (step - 64))
    assert len(sent) == 10


def test_replay_loop_until_sigint(tool, sim_bag, tmp_path, procs):
    n = read_pressure(sim_bag).t_ns.size
    sub = start_tool(tool, tmp_path, mode="sub", count=3 * n, linger=0.0)
    procs.append(sub)
    wait_for_line(sub, "ready")
    rep = start_node("replay", tmp_path, bag=str(sim_bag), rate=0.0, loop=True,
                     topics=[TOPIC_PRESSURE])
    procs.append(rep)
    rc, out, err = finish(sub)
    assert rc == 0, err
    assert len(last_json(out)["samples"]) >= 3 * n
    assert rep.poll() is None, "replay with loop:=true ended by itself"
    rc, _, rep_err = interrupt(rep)
    assert rc == 0, rep_err
    assert not left_profiles(tmp_path)


def test_bad_parameters_are_rejected_with_the_reason(tmp_path, sim_bag, procs):
    existing = tmp_path / "exists"
    existing.mkdir()
    cases = [
        ("recorder", {"split": "bogus"}, "split"),
        ("recorder", {"flush_interval": "abc"}, "flush_interval"),
        ("recorder", {"output": str(existing)}, "exists"),
        ("replay", {"bag": str(tmp_path / "missing")}, "does not exist"),
        ("replay", {"bag": str(sim_bag), "rate": -1.0}, "rate"),
        ("replay", {"bag": str(sim_bag), "topics": ["/nope"]}, "/nope"),
    ]
    started = [(start_node(node, tmp_path, **params), needle) for node, params, needle in cases]
    procs.extend(p for p, _ in started)
    for proc, needle in started:
        rc, _, err = finish(proc)
        assert rc == 2, err
        assert "invalid parameter" in err and needle in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exists"]  # nothing half-written


# ------------------------------------------------------------------- ROS-free parts


def _pressure_cdr(store, t_ns: int, value: float) -> bytes:
    msg = store.types[MSGTYPE_PRESSURE](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](
                sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="tank"),
        fluid_pressure=value, variance=0.0)
    return bytes(store.serialize_cdr(msg, MSGTYPE_PRESSURE))


def _valve_cdr(store, is_open: bool) -> bytes:
    msg = store.types[MSGTYPE_VALVE](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="v"),
        open=is_open, opening=float(is_open))
    return bytes(store.serialize_cdr(msg, MSGTYPE_VALVE))


def _config_cdr(store, text: str) -> bytes:
    return bytes(store.serialize_cdr(store.types[MSGTYPE_CONFIG](data=text), MSGTYPE_CONFIG))


def test_session_split_policy_without_ros(tmp_path):
    store = make_typestore()
    reports: list[str] = []
    session = RecordingSession(tmp_path / "s", split="unload", report=reports.append)
    with BagRecorder(tmp_path / "tmp") as tmp:
        tmp.write_estimate(1, {"unload_index": 0})
    est = next(iter(read_raw_messages(tmp_path / "tmp", topics=[TOPIC_ESTIMATE]))).data

    clock = iter(range(1000, 2000))

    def on(topic, msgtype, data, _t):  # receive times: increasing
        session.on_message(topic, msgtype, data, next(clock), topic != TOPIC_CONFIG)

    on(TOPIC_CONFIG, MSGTYPE_CONFIG, _config_cdr(store, json.dumps(CONFIG)), 5)
    on(TOPIC_CONFIG, MSGTYPE_CONFIG, _config_cdr(store, "nope"), 6)  # reported, not stored
    on(TOPIC_SETTINGS, MSGTYPE_CONFIG, _config_cdr(store, '{"volume": 1}'), 7)
    for k in range(10):
        on(TOPIC_PRESSURE, MSGTYPE_PRESSURE, _pressure_cdr(store, 10 + k, 1e5 + k), 10 + k)
        if k == 2:
            on(TOPIC_VALVE, MSGTYPE_VALVE, _valve_cdr(store, True), 100)
        if k == 4:
            on(TOPIC_ESTIMATE, MSGTYPE_ESTIMATE, est, 101)
        if k == 5:
            on(TOPIC_VALVE, MSGTYPE_VALVE, _valve_cdr(store, True), 102)  # still open: no split
        if k == 6:
            on(TOPIC_VALVE, MSGTYPE_VALVE, _valve_cdr(store, False), 103)  # split before it
        if k == 7:
            on(TOPIC_ESTIMATE, MSGTYPE_ESTIMATE, est, 104)  # late: to the first bag
        if k == 8:
            on(TOPIC_VALVE, MSGTYPE_VALVE, _valve_cdr(store, True), 105)  # next unload
            on(TOPIC_ESTIMATE, MSGTYPE_ESTIMATE, est, 106)  # unload 0 again: first bag closed
    on(TOPIC_PRESSURE, "bad/msg/Type", b"\x00\x01\x00\x00", 200)  # unknown type: reported
    session.close()
    assert session.errors == 2
    assert any("not valid JSON" in r for r in reports)
    assert any("bad/msg/Type" in r for r in reports)
    assert [b.name for b in session.bags] == ["unload-000", "unload-001"]
    first, second = session.bags
    assert read_pressure(first).p.tolist() == [1e5 + k for k in range(7)]
    assert read_pressure(second).p.tolist() == [1e5 + k for k in range(7, 10)]
    assert read_config(first) == read_config(second) == CONFIG
    assert [e["unload_index"] for e in read_estimates(first)] == [0, 0]
    assert [e["unload_index"] for e in read_estimates(second)] == [0]
    assert [m.topic for m in read_raw_messages(second)][:3] == [
        TOPIC_CONFIG, TOPIC_SETTINGS, TOPIC_VALVE]  # settings repeated in the new bag
    assert read_json_topic(second, TOPIC_SETTINGS) == {"volume": 1}

    # a new configuration starts a new bag also in run mode (never over an existing one)
    run = RecordingSession(tmp_path / "r", split="run")
    (tmp_path / "r-001").mkdir()
    run.on_message(TOPIC_PRESSURE, MSGTYPE_PRESSURE, _pressure_cdr(store, 1, 1.0), 1, True)
    run.on_message(TOPIC_CONFIG, MSGTYPE_CONFIG, _config_cdr(store, '{"a": 1}'), 2, False)
    run.on_message(TOPIC_CONFIG, MSGTYPE_CONFIG, _config_cdr(store, '{"a": 1}'), 3, False)
    run.on_message(TOPIC_CONFIG, MSGTYPE_CONFIG, _config_cdr(store, '{"a": 2}'), 4, False)
    run.on_message(TOPIC_PRESSURE, MSGTYPE_PRESSURE, _pressure_cdr(store, 5, 2.0), 5, True)
    run.close()
    assert [b.name for b in run.bags] == ["r", "r-002"]
    assert read_config(run.bags[0]) == {"a": 1} and read_config(run.bags[1]) == {"a": 2}
    assert bag_summary(run.bags[0]).topics[TOPIC_CONFIG].count == 1


def test_session_rejects_bad_options(tmp_path):
    for kwargs, needle in (({"split": "x"}, "split"), ({"flush_interval": 0.0}, "flush"),
                           ({"log_time": "x"}, "log_time")):
        with pytest.raises(RecorderParameterError, match=needle):
            RecordingSession(tmp_path / "x", **kwargs)
    assert not (tmp_path / "x").exists()


def test_bag_helpers_for_the_nodes(tmp_path):
    store = make_typestore()
    data = _pressure_cdr(store, 1_234_567_890_123, 1.0)
    assert cdr_header_stamp_ns(data) == 1_234_567_890_123
    assert cdr_header_stamp_ns(b"\x00\x01") is None
    big = b"\x00\x00\x00\x00" + struct.pack(">iI", 3, 4) + data[12:]
    assert cdr_header_stamp_ns(big) == 3_000_000_004

    with BagRecorder(tmp_path / "b") as rec:
        assert rec.config_text is None
        assert rec.has_type("std_msgs/msg/String")
        assert not rec.has_type("nope_msgs/msg/Nothing")
        with pytest.raises(UnknownMessageTypeError):
            rec.ensure_type("nope_msgs/msg/Nothing")
        rec.ensure_type(MSGTYPE_ESTIMATE)
        with pytest.raises(BagWriteError):
            rec.set_config("[1, 2]")
        rec.write_raw(TOPIC_PRESSURE, MSGTYPE_PRESSURE, 50, data)
        rec.set_config({"v": 1})  # stamped at the latest log time
        rec.write_raw(TOPIC_PRESSURE, MSGTYPE_PRESSURE, 40, data)
        assert rec.config_text == '{"v": 1}'
    msgs = list(read_raw_messages(tmp_path / "b"))
    assert [(m.topic, m.log_time_ns) for m in msgs] == [
        (TOPIC_PRESSURE, 40), (TOPIC_PRESSURE, 50), (TOPIC_CONFIG, 50)]
    assert msgs[0].data == data
    assert read_config(tmp_path / "b") == {"v": 1}
    with pytest.raises(TopicNotFoundError):
        read_raw_messages(tmp_path / "b", topics=["/nope"])


def test_replay_plan_and_pacing(sim_bag, tmp_path):
    plan = ReplayPlan.from_parameters(str(sim_bag), 2, [], False)
    assert plan.config is not None and plan.config.topic == TOPIC_CONFIG
    assert TOPIC_CONFIG not in {m.topic for m in plan.stream()}
    # a bag (by another writer) with its configuration only in the metadata
    store = make_typestore()
    with Writer(tmp_path / "meta", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(TOPIC_PRESSURE, MSGTYPE_PRESSURE, typestore=store)
        writer.write(conn, 10**9, _pressure_cdr(store, 10**9, 1e5))
        writer.set_custom_data(CONFIG_METADATA_KEY, json.dumps({"v": 2}))
    meta_plan = ReplayPlan.from_parameters(str(tmp_path / "meta"), 1.0, [], False)
    assert TOPIC_CONFIG in meta_plan.topics
    assert meta_plan.config is not None
    assert store.deserialize_cdr(meta_plan.config.data, MSGTYPE_CONFIG).data == '{"v": 2}'
    assert [m.topic for m in meta_plan.stream()] == [TOPIC_PRESSURE]
    with pytest.raises(ReplayParameterError, match="rate"):
        ReplayPlan.from_parameters(str(sim_bag), math.nan, [], False)
    with pytest.raises(ReplayParameterError, match="not in bag"):
        ReplayPlan.from_parameters(str(sim_bag), 1.0, ["/x"], False)

    now = [100.0]
    sleeps: list[float] = []

    def sleep(dt):
        sleeps.append(dt)
        now[0] += dt

    msgs = [RawMessage("/t", "x", t, b"") for t in (10**9, 2 * 10**9, 2 * 10**9, 4 * 10**9)]
    published: list[float] = []
    n = pace(msgs, 2.0, lambda m: published.append(now[0]), clock=lambda: now[0], sleep=sleep)
    assert n == 4
    assert published == pytest.approx([100.0, 100.5, 100.5, 101.5])
    published.clear()
    pace(msgs, 0.0, lambda m: published.append(now[0]), clock=lambda: now[0], sleep=sleep)
    assert published == pytest.approx([101.5] * 4)
    assert os.environ.get("ROS_DOMAIN_ID")  # conftest isolates the DDS tests
