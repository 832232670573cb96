# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Bag io (pneumatic_unload.io.bag): round trips, numpy fast paths checked against rosbags,
readability by rosbags and mcap, error classes, and crash recovery after a real kill -9.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_types_from_msg

from pneumatic_unload.io import (
    CONFIG_METADATA_KEY,
    MSGTYPE_ESTIMATE,
    MSGTYPE_PRESSURE,
    MSGTYPE_TEMPERATURE,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_TEMPERATURE,
    TOPIC_VALVE,
    BagError,
    BagFormatError,
    BagNotFoundError,
    BagRecorder,
    BagWriteError,
    TopicNotFoundError,
    UnknownMessageTypeError,
    WrongMessageTypeError,
    bag_summary,
    find_msg_dir,
    make_typestore,
    read_config,
    read_estimates,
    read_pressure,
    read_temperature,
    read_valve,
    recover,
)
from pneumatic_unload.io.bag.cdr import encode_stamped_pair, encode_stamped_pairs
from pneumatic_unload.io.bag.reader import fast_raw_pairs, read_stamped_pairs

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

with warnings.catch_warnings():  # mcap_ros2.reader warns about mcap_ros1 on import
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages

REPO_ROOT = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000_000_000_000  # an epoch time [ns]
MS = 1_000_000  # [ns]
CONFIG = {"name": "rig-A", "volume": 1.2e-3, "p_atm": 101_325.0, "valve": {"ramp": 0.02}}
N_PRESSURE = 2000


def _estimate(i: int) -> dict:
    """An UnloadEstimate as a dict with every key (SI units)."""
    return {
        "header_stamp_ns": T0 + 1500 * MS + i,
        "frame_id": "tank",
        "unload_start_ns": T0 + 200 * MS + i,
        "unload_index": i,
        "status": 0 if i == 0 else 3,
        "status_text": "ok" if i == 0 else "not choked",
        "method": "eq39+isentropic-inversion+curve-fit",
        "quality": 0.93,
        "conductance": 7.3e-9,
        "conductance_std": 4.0e-11,
        "conductance_model": 7.1e-9,
        "conductance_model_std": 1.5e-10,
        "conductance_model_std_type_a": 2.0e-11,
        "conductance_model_std_type_b": 1.4e-10,
        "conductance_model_std_model_form": 0.0,
        "budget_largest": "volume V",
        "heat_law": "natural" if i == 0 else "",
        "critical_ratio": 0.42,
        "critical_ratio_std": float("nan"),
        "subsonic_index": 0.5 if i == 0 else 0.31,
        "subsonic_index_std": 0.144 if i == 0 else 0.02,
        "subsonic_index_fitted": i == 1,
        "pressure_offset": float("nan") if i == 0 else -2400.0,
        "pressure_offset_std": float("nan") if i == 0 else 35.0,
        "tau_exp": 1.234,
        "p10": 6.0e5,
        "p_atm": 101_325.0,
        "p_star": 101_325.0 + 0.368 * (6.0e5 - 101_325.0),
        "initial_temperature": 293.15,
        "volume": 1.2e-3,
        "direction": "discharge" if i == 0 else "charge",
        "supply_pressure": float("nan") if i == 0 else 6.5e5,
    }


def _same(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    return all(
        (isinstance(a[k], float) and np.isnan(a[k]) and np.isnan(b[k])) or a[k] == b[k]
        for k in a
    )


def _pressure_data(n: int = N_PRESSURE) -> tuple[np.ndarray, np.ndarray]:
    t_ns = T0 + np.arange(n, dtype=np.int64) * MS
    p = 6.0e5 - 10.0 * np.arange(n) + 0.125
    return t_ns, p


@pytest.fixture
def full_bag(tmp_path: Path) -> Path:
    """A bag with every topic: 2000 pressures at 1 kHz, temperatures, valve, 2 estimates."""
    path = tmp_path / "full"
    t_ns, p = _pressure_data()
    with BagRecorder(path, config=CONFIG) as rec:
        rec.write_valve(int(t_ns[0]), False, 0.0)
        rec.write_pressures(t_ns[:1000], p[:1000])
        rec.write_valve(int(t_ns[200]), True, 1.0, log_time_ns=int(t_ns[999]))
        for k in range(0, N_PRESSURE, 500):
            rec.write_temperature(int(t_ns[k]), 293.15 - k * 1e-3)
        rec.write_pressures(t_ns[1000:], p[1000:])
        rec.write_estimate(int(t_ns[-1]), _estimate(0))
        rec.write_estimate(int(t_ns[-1]) + 1, _estimate(1))
    return path


def _deserialize_all(path: Path, topic: str) -> list:
    with AnyReader([path], default_typestore=make_typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]


# ----------------------------------------------------------------------- ROS-free, types


def test_io_never_imports_ros(tmp_path):
    code = textwrap.dedent(
        f"""
        import json, sys
        import numpy as np
        from pneumatic_unload.io import BagRecorder, read_pressure, read_estimates
        with BagRecorder({str(tmp_path / "b")!r}, config={{"a": 1}}) as rec:
            rec.write_pressures(np.arange(3, dtype=np.int64), np.ones(3))
            rec.write_estimate(5, {{"conductance": 1e-8}})
        read_pressure({str(tmp_path / "b")!r}); read_estimates({str(tmp_path / "b")!r})
        ros = {{"rclpy", "sensor_msgs", "std_msgs", "builtin_interfaces",
               "pneumatic_unload_msgs", "rosidl_runtime_py"}}
        print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ros)))
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO_ROOT
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_msg_dir_and_typestore():
    msg_dir = find_msg_dir()
    assert (msg_dir / "UnloadEstimate.msg").is_file()
    store = make_typestore()
    for name in ("UnloadEstimate", "ValveState", "PressureBlock"):
        assert f"pneumatic_unload_msgs/msg/{name}" in store.fielddefs
    assert MSGTYPE_PRESSURE in store.fielddefs and MSGTYPE_TEMPERATURE in store.fielddefs
    assert make_typestore() is not store  # fresh stores: registering in one leaks nowhere


@pytest.mark.parametrize("frame_id", ["", "a", "ab", "abc", "tank", "sensor_7", "pt-100_ab", "ü"])
@pytest.mark.parametrize("msgtype", [MSGTYPE_PRESSURE, MSGTYPE_TEMPERATURE])
def test_fast_encoding_is_byte_identical_to_rosbags(frame_id, msgtype):
    store = make_typestore()
    types = store.types
    t_ns = np.array([0, 1, 999_999_999, T0, T0 + 123_456_789, -1_500_000_000], np.int64)
    values = np.array([1e5, -0.0, np.nan, np.inf, 6.02e23, 1e-300])
    variance = np.array([0.0, 1.5, 2.25, 0.0, 1e-9, 7.0])
    rows = encode_stamped_pairs(t_ns, values, variance, frame_id=frame_id)
    field = "fluid_pressure" if msgtype == MSGTYPE_PRESSURE else "temperature"
    for row, t, v, var in zip(rows, t_ns, values, variance, strict=True):
        sec, nsec = divmod(int(t), 1_000_000_000)
        header = types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id
        )
        msg = types[msgtype](header=header, **{field: float(v)}, variance=float(var))
        expected = bytes(store.serialize_cdr(msg, msgtype))
        assert row.tobytes() == expected  # vectorised encoder
        single = encode_stamped_pair(int(t), float(v), float(var), frame_id=frame_id)
        assert single == expected  # per-message struct encoder


# ---------------------------------------------------------------------------- round trip


def test_round_trip_of_every_topic(full_bag):
    t_ns, p = _pressure_data()
    t_read, p_read = read_pressure(full_bag)
    assert t_read.dtype == np.int64 and p_read.dtype == np.float64
    np.testing.assert_array_equal(t_read, t_ns)
    np.testing.assert_array_equal(p_read, p)

    t_temp, temp = read_temperature(full_bag)
    np.testing.assert_array_equal(t_temp, t_ns[::500])
    np.testing.assert_allclose(temp, 293.15 - np.arange(0, N_PRESSURE, 500) * 1e-3, atol=1e-12)

    t_valve, is_open, opening = read_valve(full_bag)
    np.testing.assert_array_equal(t_valve, [t_ns[0], t_ns[200]])
    np.testing.assert_array_equal(is_open, [False, True])
    np.testing.assert_array_equal(opening, [0.0, 1.0])

    estimates = read_estimates(full_bag)
    assert len(estimates) == 2
    assert _same(estimates[0], _estimate(0)) and _same(estimates[1], _estimate(1))

    assert read_config(full_bag) == CONFIG
    meta = yaml.safe_load((full_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert json.loads(meta["custom_data"][CONFIG_METADATA_KEY]) == CONFIG

    summary = bag_summary(full_bag)
    assert {k: v.count for k, v in summary.topics.items()} == {
        TOPIC_CONFIG: 1,
        TOPIC_PRESSURE: N_PRESSURE,
        TOPIC_TEMPERATURE: 4,
        TOPIC_VALVE: 2,
        TOPIC_ESTIMATE: 2,
    }
    assert summary.topics[TOPIC_ESTIMATE].msgtype == MSGTYPE_ESTIMATE
    assert summary.start_ns == T0
    assert summary.duration == pytest.approx((N_PRESSURE - 1) * 1e-3 + 1e-9)
    assert "/tank/pressure" in str(summary)


def test_config_is_the_first_message(full_bag):
    with (full_bag / "full.mcap").open("rb") as f:
        first = next(make_reader(f).iter_messages(log_time_order=False))
    assert first[1].topic == TOPIC_CONFIG
    with AnyReader([full_bag]) as reader:
        first_conn = next(iter(reader.messages()))[0]
    assert first_conn.topic == TOPIC_CONFIG


def test_bag_opens_with_rosbags_and_mcap(full_bag):
    # rosbags' AnyReader with only the definitions embedded in the bag
    with AnyReader([full_bag]) as reader:
        counts: dict[str, int] = {}
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    assert counts[TOPIC_PRESSURE] == N_PRESSURE and counts[TOPIC_ESTIMATE] == 2
    # mcap with chunk CRC validation, and mcap_ros2 which decodes from the embedded schemas only
    with (full_bag / "full.mcap").open("rb") as f:
        n = sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages())
    assert n == sum(counts.values())
    decoded = [m for m in read_ros2_messages(str(full_bag / "full.mcap"), topics=[TOPIC_ESTIMATE])]
    assert [m.schema.name for m in decoded] == [MSGTYPE_ESTIMATE] * 2
    msg = decoded[1].ros_msg
    want = _estimate(1)
    assert msg.unload_index == 1 and msg.status == 3 and msg.status_text == "not choked"
    assert msg.conductance_model == want["conductance_model"] and msg.p_star == want["p_star"]
    assert msg.unload_start.sec * 10**9 + msg.unload_start.nanosec == want["unload_start_ns"]
    assert np.isnan(msg.critical_ratio_std)
    config = next(read_ros2_messages(str(full_bag / "full.mcap"), topics=[TOPIC_CONFIG]))
    assert json.loads(config.ros_msg.data) == CONFIG


def test_read_pressure_matches_rosbags_deserialization(tmp_path):
    """Mixed frame_id lengths, several chunks: fast and generic paths equal rosbags."""
    path = tmp_path / "mixed"
    rng = np.random.default_rng(7)
    frames = ["", "a", "tank", "sensor_long_name", "ü"]
    with BagRecorder(path, chunk_size=4096) as rec:
        t = T0
        for k in range(40):
            n = int(rng.integers(1, 60))
            stamps = t + np.arange(n, dtype=np.int64) * 997
            rec.write_pressures(stamps, rng.normal(3e5, 1e4, n), frame_id=frames[k % 5])
            rec.write_pressure(int(stamps[-1]) + 500, float(rng.normal(3e5, 1e4)),
                               frame_id=frames[(k + 2) % 5], variance=4.0)
            t = int(stamps[-1]) + 1000
    msgs = _deserialize_all(path, TOPIC_PRESSURE)
    ref_t = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs])
    ref_p = np.array([m.fluid_pressure for m in msgs])
    fast = read_pressure(path)
    generic = read_stamped_pairs(path, TOPIC_PRESSURE, MSGTYPE_PRESSURE, fast=False)
    single_file = read_pressure(path / "mixed.mcap")
    for t_ns, p in (fast, generic[:2], single_file):
        np.testing.assert_array_equal(t_ns, ref_t)
        np.testing.assert_array_equal(p, ref_p)
    # the fast path really was taken (no silent fallback)
    _, stamps, _, _ = fast_raw_pairs(path / "mixed.mcap", TOPIC_PRESSURE, MSGTYPE_PRESSURE)
    assert stamps.size == ref_t.size


def test_read_pressure_of_bags_from_other_writers(tmp_path):
    """Plain rosbags writer (zstd chunks, no CRC) and mcap_ros2's writer (lz4 chunks)."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer as McapRos2Writer
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    t_ns, p = _pressure_data(3000)
    store = make_typestore()
    payloads = encode_stamped_pairs(t_ns, p, 0.0, frame_id="tank")
    writer = Writer(tmp_path / "plain", version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection(TOPIC_PRESSURE, MSGTYPE_PRESSURE, typestore=store)
        for stamp, payload in zip(t_ns, payloads, strict=True):
            writer.write(conn, int(stamp), payload.tobytes())
    single = tmp_path / "lz4.mcap"
    with single.open("wb") as f:
        mw = McapRos2Writer(f, compression=CompressionType.LZ4)
        schema = mw.register_msgdef(
            MSGTYPE_PRESSURE, store.generate_msgdef(MSGTYPE_PRESSURE, ros_version=2)[0]
        )
        for stamp, value in zip(t_ns.tolist(), p.tolist(), strict=True):
            stamp_msg = {"sec": stamp // 10**9, "nanosec": stamp % 10**9}
            msg = {"header": {"stamp": stamp_msg, "frame_id": "x"}, "fluid_pressure": value}
            mw.write_message(TOPIC_PRESSURE, schema, msg, log_time=stamp, publish_time=stamp)
        mw.finish()
    for path, mcap_file in ((tmp_path / "plain", tmp_path / "plain" / "plain.mcap"),
                            (single, single)):
        _, stamps, values, _ = fast_raw_pairs(mcap_file, TOPIC_PRESSURE, MSGTYPE_PRESSURE)
        np.testing.assert_array_equal(values, p)
        np.testing.assert_array_equal(stamps, t_ns)  # the fast path handles them
        t_read, p_read = read_pressure(path)
        np.testing.assert_array_equal(t_read, t_ns)
        np.testing.assert_array_equal(p_read, p)


def test_rates_of_the_fast_paths(tmp_path):
    """The fast paths beat the per-message ones of the same data, as ratios in one run.

    write_pressures against the same messages serialised one by one by rosbags and written
    with write_raw (measured 8.5x on a quiet machine); read_pressure against rosbags'
    deserialize of the same bag (measured > 5x). Ratios, not rates: the load of the machine
    slows both sides of each ratio alike.
    """
    n = 50_000
    t_ns, p = _pressure_data(n)
    with BagRecorder(tmp_path / "warm") as rec:  # first-use costs (imports, type store)
        rec.write_pressures(t_ns[:10], p[:10])
    start = time.perf_counter()
    with BagRecorder(tmp_path / "rate") as rec:
        rec.write_pressures(t_ns, p)
    fast_write = time.perf_counter() - start
    store = make_typestore()
    types = store.types
    start = time.perf_counter()
    with BagRecorder(tmp_path / "slow") as rec:
        for t, v in zip(t_ns.tolist(), p.tolist(), strict=True):
            header = types["std_msgs/msg/Header"](stamp=types["builtin_interfaces/msg/Time"](
                sec=t // 1_000_000_000, nanosec=t % 1_000_000_000), frame_id="")
            msg = types[MSGTYPE_PRESSURE](header=header, fluid_pressure=v, variance=0.0)
            rec.write_raw(TOPIC_PRESSURE, MSGTYPE_PRESSURE, t,
                          bytes(store.serialize_cdr(msg, MSGTYPE_PRESSURE)))
    slow_write = time.perf_counter() - start
    assert slow_write / fast_write > 3.0

    start = time.perf_counter()
    t_read, _ = read_pressure(tmp_path / "rate")
    fast = time.perf_counter() - start
    assert t_read.size == n
    assert np.array_equal(t_read, read_pressure(tmp_path / "slow").t_ns)
    with AnyReader([tmp_path / "rate"]) as reader:
        start = time.perf_counter()
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
        slow = time.perf_counter() - start
    assert slow / fast > 3.0


# ------------------------------------------------------------------------ raw and types


def test_write_raw_and_register_type(tmp_path):
    path = tmp_path / "raw"
    store = make_typestore()
    types = store.types
    header = types["std_msgs/msg/Header"](
        stamp=types["builtin_interfaces/msg/Time"](sec=5, nanosec=7), frame_id="x"
    )
    cdr = bytes(store.serialize_cdr(
        types[MSGTYPE_PRESSURE](header=header, fluid_pressure=2.5e5, variance=0.0),
        MSGTYPE_PRESSURE,
    ))
    thing_def = "# custom\nfloat64 x\nstring label\nstd_msgs/Header header\n"
    with BagRecorder(path) as rec:
        rec.write_raw(TOPIC_PRESSURE, MSGTYPE_PRESSURE, 5_000_000_007, cdr)
        with pytest.raises(UnknownMessageTypeError, match="register_type"):
            rec.write_raw("/thing", "my_pkg/msg/Thing", 1, b"\x00\x01\x00\x00")
        rec.register_type("my_pkg/msg/Thing", thing_def)
        thing_store = make_typestore()
        thing_store.register(get_types_from_msg(thing_def, "my_pkg/msg/Thing"))
        thing = thing_store.types["my_pkg/msg/Thing"](x=1.5, label="hi", header=header)
        rec.write_raw("/thing", "my_pkg/msg/Thing", 6_000_000_000,
                      thing_store.serialize_cdr(thing, "my_pkg/msg/Thing"))
        with pytest.raises(BagWriteError, match="cannot register"):
            rec.register_type("my_pkg/msg/Broken", "float64[ x\n")
    assert read_pressure(path).t_ns.tolist() == [5_000_000_007]
    assert read_pressure(path).p.tolist() == [2.5e5]
    with AnyReader([path]) as reader:  # only the embedded definition is known to it
        conn = next(c for c in reader.connections if c.topic == "/thing")
        raw = next(r for _, _, r in reader.messages([conn]))
        assert reader.deserialize(raw, conn.msgtype).label == "hi"
    got = next(read_ros2_messages(str(path / "raw.mcap"), topics=["/thing"])).ros_msg
    assert got.x == 1.5 and got.label == "hi"
    assert read_config(path) is None  # no config given


# -------------------------------------------------------------------------------- errors


def test_reader_errors(full_bag, tmp_path):
    with pytest.raises(BagNotFoundError):
        read_pressure(tmp_path / "nope")
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(BagFormatError, match="neither"):
        read_pressure(text)
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"this is no mcap file" * 10)
    with pytest.raises(BagFormatError) as err:
        read_pressure(garbage)
    assert type(err.value) is BagFormatError and "recover" in str(err.value)
    with pytest.raises(BagFormatError, match=r"no metadata\.yaml"):
        read_pressure(tmp_path)

    killed = tmp_path / "killed"
    killed.mkdir()
    data = (full_bag / "full.mcap").read_bytes()
    (killed / "killed.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError, match="pneumatic-unload recover"):
        read_pressure(killed)
    with pytest.raises(BagFormatError, match="pneumatic-unload recover"):
        read_pressure(killed / "killed.mcap")

    with pytest.raises(TopicNotFoundError) as err:
        read_pressure(full_bag, topic="/nope")
    assert "/tank/pressure" in str(err.value) and "/estimator/estimate" in str(err.value)
    assert err.value.available == sorted(bag_summary(full_bag).topics)
    with pytest.raises(WrongMessageTypeError) as err:
        read_pressure(full_bag, topic=TOPIC_TEMPERATURE)
    assert MSGTYPE_TEMPERATURE in str(err.value) and MSGTYPE_PRESSURE in str(err.value)
    assert isinstance(err.value, BagError)


# issue "Words, not numbers": a metadata.yaml that is not a mapping gave
# "string indices must be integers, not 'str'"
BAD_METADATA = [
    ("just a string", "it is a string ('just a string'), not a mapping"),
    ("[1, 2]", "it is a list ([1, 2]), not a mapping"),
    ("", "it is empty, not a mapping"),
    ("{}", "it has no key 'rosbag2_bagfile_information' (its keys: none)"),
    ("rosbag2_bagfile_information: 3",
     "'rosbag2_bagfile_information' is an integer (3), not a mapping"),
    ("rosbag2_bagfile_information: {}", "'rosbag2_bagfile_information' has no 'version'"),
    ("a: [1, 2", "is not valid YAML (line 1, column 9)"),
]


DELETE = object()  # a value of _bag_with_metadata's changes: remove the key


def _bag_with_metadata(full_bag: Path, text: str | None = None, **changes: object) -> Path:
    """``full_bag`` with its metadata.yaml replaced by ``text`` or with ``changes`` made to
    its rosbag2_bagfile_information mapping (a value DELETE removes the key)."""
    meta = full_bag / "metadata.yaml"
    if text is None:
        doc = yaml.safe_load(meta.read_text())
        info = doc["rosbag2_bagfile_information"]
        for key, value in changes.items():
            if value is DELETE:
                del info[key]
            else:
                info[key] = value
        text = yaml.safe_dump(doc)
    meta.write_text(text)
    return full_bag


@pytest.mark.parametrize(("text", "problem"), BAD_METADATA)
def test_metadata_that_is_not_rosbag2_metadata_is_named_in_words(full_bag, text, problem):
    bag = _bag_with_metadata(full_bag, text)
    for read in (read_pressure, read_config, bag_summary):
        with pytest.raises(BagFormatError) as err:
            read(bag)
        msg = str(err.value)
        assert str(bag / "metadata.yaml") in msg and problem in msg, msg
        assert "must hold a mapping with the key 'rosbag2_bagfile_information'" in msg
        assert "'relative_file_paths'" in msg and "'topics_with_message_count'" in msg
        assert f"pneumatic-unload recover {bag}" in msg and "\n" not in msg
        assert "indices" not in msg and "subscriptable" not in msg


@pytest.mark.parametrize(("changes", "problem"), [
    ({"version": "nine"}, "'version' is a string ('nine'), not an integer 1 to 9"),
    ({"storage_identifier": DELETE}, "'rosbag2_bagfile_information' has no 'storage_identifier'"),
    ({"relative_file_paths": 5}, "'relative_file_paths' is an integer (5), not a list of file"),
    ({"topics_with_message_count": [1]},
     "'topics_with_message_count' entry 1 is an integer (1), not a mapping"),
    ({"message_count": -1}, "'message_count' is an integer (-1), not an integer >= 0"),
    ({"duration": 4.5}, "'duration' is a number (4.5), not a mapping with 'nanoseconds'"),
    ({"starting_time": DELETE}, "'rosbag2_bagfile_information' has no 'starting_time'"),
    ({"compression_mode": None}, "'compression_mode' is empty, not a string"),
    ({"compression_mode": "file"},
     "'compression_mode' is 'file' but 'compression_format' is a string (''), not 'zstd'"),
    ({"custom_data": [1]}, "'custom_data' is a list ([1]), not a mapping"),
    ({"files": {}}, "'files' is a mapping ({}), not a list"),
])
def test_metadata_with_a_field_of_the_wrong_type_is_named_in_words(full_bag, changes, problem):
    bag = _bag_with_metadata(full_bag, **changes)
    with pytest.raises(BagFormatError) as err:
        read_pressure(bag)
    assert f"{bag / 'metadata.yaml'} is not rosbag2 metadata: {problem}" in str(err.value)


def test_metadata_with_a_bad_topic_entry_is_named_in_words(full_bag):
    doc = yaml.safe_load((full_bag / "metadata.yaml").read_text())
    topics = doc["rosbag2_bagfile_information"]["topics_with_message_count"]
    topics[1]["topic_metadata"]["offered_qos_profiles"] = "x"
    bag = _bag_with_metadata(full_bag, yaml.safe_dump(doc))
    with pytest.raises(BagFormatError, match=r"'offered_qos_profiles' of "
                       r"'topics_with_message_count' entry 2 is a string \('x'\), not a list"):
        read_pressure(bag)
    del topics[1]["topic_metadata"]["offered_qos_profiles"]
    del topics[0]["topic_metadata"]["type"]
    bag = _bag_with_metadata(full_bag, yaml.safe_dump(doc))
    with pytest.raises(BagFormatError, match=r"'topic_metadata' of "
                       r"'topics_with_message_count' entry 1 has no 'type' string"):
        read_pressure(bag)


@pytest.mark.parametrize(("text", "problem"), BAD_METADATA[:4])
def test_cli_metadata_that_is_not_a_mapping_is_one_line_exit_2(tmp_path, capsys, text,
                                                               problem):
    from pneumatic_unload.app.cli import main

    bag = tmp_path / "clean_unload"
    shutil.copytree(REPO_ROOT / "bags" / "clean_unload", bag)
    (bag / "metadata.yaml").write_text(text)
    code = main(["analyze", str(bag)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"pneumatic-unload: error: {bag / 'metadata.yaml'} is not rosbag2 "
                          f"metadata: {problem}; a rosbag2 metadata.yaml must hold"), err
    assert "Traceback" not in err and "indices" not in err


def test_recorder_errors_and_context_manager(tmp_path):
    path = tmp_path / "r"
    rec = BagRecorder(path, config={"a": 1})
    with pytest.raises(BagWriteError, match="exists"):
        BagRecorder(path)
    with pytest.raises(BagWriteError, match="integer"):
        rec.write_pressure(1.5, 1e5)
    with pytest.raises(BagWriteError, match="unknown UnloadEstimate fields"):
        rec.write_estimate(1, {"conductance": 1e-8, "C": 2})
    with pytest.raises(BagWriteError, match="equal length"):
        rec.write_pressures(np.arange(3), np.ones(4))
    with pytest.raises(BagWriteError, match="JSON"):
        BagRecorder(tmp_path / "j", config={"x": object()})
    rec.close()
    rec.close()  # idempotent
    with pytest.raises(BagWriteError, match="closed"):
        rec.write_pressure(1, 1e5)
    assert read_config(path) == {"a": 1}  # written at close with log time 0

    # an exception inside the with block still leaves a complete bag
    path2 = tmp_path / "exc"
    with pytest.raises(RuntimeError), BagRecorder(path2) as rec2:
        rec2.write_pressure(T0, 1e5)
        raise RuntimeError("boom")
    assert read_pressure(path2).p.tolist() == [1e5]


# ---------------------------------------------------------------------- crash safety


def _snapshot(src: Path, dst: Path) -> Path:
    """Copy the files of a bag being written, as a kill -9 would leave them."""
    dst.mkdir()
    for f in src.iterdir():
        shutil.copy(f, dst / f"{dst.name}{f.suffix}")
    return dst


def test_flush_interval_puts_data_on_disk(tmp_path):
    t_ns, p = _pressure_data(300)
    rec = BagRecorder(tmp_path / "live", config=CONFIG, flush_interval=0.05)
    rec.write_pressures(t_ns[:200], p[:200])
    time.sleep(0.08)
    rec.write_pressure(int(t_ns[200]), float(p[200]))  # the flush happens on this write
    snap = _snapshot(tmp_path / "live", tmp_path / "snap")
    report = recover(snap)
    assert report.messages[TOPIC_PRESSURE] == 201 and report.messages[TOPIC_CONFIG] == 1
    assert read_config(snap) == CONFIG  # custom_data restored from the /rig/config message

    # without a flush nothing but the MCAP header reaches the disk
    lazy = BagRecorder(tmp_path / "lazy", flush_interval=float("inf"))
    lazy.write_pressures(t_ns, p)
    assert (tmp_path / "lazy" / "lazy.mcap").stat().st_size < 100
    lazy.flush()
    assert (tmp_path / "lazy" / "lazy.mcap").stat().st_size > 300 * 44
    rec.close()
    lazy.close()


def test_recover_truncated_files_at_many_cuts(tmp_path):
    t_ns, p = _pressure_data(3000)
    live = tmp_path / "live"
    rec = BagRecorder(live, config=CONFIG, chunk_size=8192)
    rec.write_pressures(t_ns, p)
    rec.write_estimate(int(t_ns[-1]), _estimate(0))
    rec.flush()
    data = (live / "live.mcap").read_bytes()
    rec.close()

    previous = -1
    for k, cut in enumerate(np.linspace(200, len(data), 11).astype(int)):
        bag = tmp_path / f"cut{k}"
        bag.mkdir()
        (bag / f"cut{k}.mcap").write_bytes(data[:cut])
        report = recover(bag)
        n = report.messages.get(TOPIC_PRESSURE, 0)
        assert n >= previous  # more bytes never give fewer messages
        previous = n
        assert not report.already_complete and report.kept_originals
        with AnyReader([bag]) as reader:
            assert sum(1 for _ in reader.messages()) == report.total
        with (bag / f"cut{k}.mcap").open("rb") as f:
            mcap_count = sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages())
        assert mcap_count == report.total
        if n:
            t_read, p_read = read_pressure(bag)
            np.testing.assert_array_equal(t_read, t_ns[:n])
            np.testing.assert_array_equal(p_read, p[:n])
            assert read_config(bag) == CONFIG
    assert previous == 3000 and report.messages[TOPIC_ESTIMATE] == 1 and report.dropped_bytes == 0
    assert _same(read_estimates(bag)[0], _estimate(0))

    # the intact start of a torn (uncompressed) chunk is kept
    with (live / "live.mcap").open("rb") as f:
        fourth_chunk = make_reader(f).get_summary().chunk_indexes[3].chunk_start_offset
    counts = []
    for name, cut in (("at", fourth_chunk), ("mid", fourth_chunk + 5000)):
        bag = tmp_path / name
        bag.mkdir()
        (bag / f"{name}.mcap").write_bytes(data[:cut])
        counts.append(recover(bag).messages[TOPIC_PRESSURE])
        np.testing.assert_array_equal(read_pressure(bag).p, p[: counts[-1]])
    assert counts[1] >= counts[0] + (5000 - 100) // 75  # 75-byte message records


def test_recover_leaves_complete_bags_alone_and_reports_errors(full_bag, tmp_path):
    before = (full_bag / "full.mcap").read_bytes()
    report = recover(full_bag)
    assert report.already_complete and report.messages[TOPIC_PRESSURE] == N_PRESSURE
    assert (full_bag / "full.mcap").read_bytes() == before
    with pytest.raises(BagNotFoundError):
        recover(tmp_path / "none")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(BagFormatError, match=r"no \.mcap"):
        recover(empty)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "bad.mcap").write_bytes(b"not an mcap")
    with pytest.raises(BagFormatError, match="not an MCAP"):
        recover(bad)


@pytest.mark.parametrize("arg", ["{name}.mcap", ".", "../{name}"])
def test_cli_recover_run_inside_the_bag_directory(tmp_path, arg):
    # issue 13: "recover x.mcap" inside the bag directory ended in a WriterError traceback
    t_ns, p = _pressure_data(3000)
    name = "killed"
    rec = BagRecorder(tmp_path / name, config=CONFIG, chunk_size=8192)
    rec.write_pressures(t_ns, p)
    rec.flush()
    data = (tmp_path / name / f"{name}.mcap").read_bytes()
    rec.close()
    bag = tmp_path / name
    (bag / "metadata.yaml").unlink()
    (bag / f"{name}.mcap").write_bytes(data[: len(data) * 2 // 3])
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "recover",
                           arg.format(name=name)], cwd=bag, capture_output=True, text=True,
                          timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr and f"recovered bag {bag}" in proc.stdout
    assert 0 < len(read_pressure(bag).p) < 3000
    assert not (bag / ".recover-tmp").exists()


def test_cli_recover_errors_are_one_line(tmp_path):
    (tmp_path / "bad.mcap").write_bytes(b"not an mcap")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", "recover",
                           "bad.mcap"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env=env)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "not an MCAP" in proc.stderr


KILL_FLUSH_S = 1.0  # the writer's flush_interval [s]

CHILD = """
import sys, time
from pneumatic_unload.io import BagRecorder
T0 = {t0}
with BagRecorder(sys.argv[1], config={{"test": "kill -9"}}, flush_interval={flush}) as rec:
    start = time.monotonic()
    n = 0
    while True:
        due = int((time.monotonic() - start) * 1000.0) + 1  # 1 kHz, paced in real time
        if n < due:
            print("w", due, flush=True)  # about to write the samples n .. due - 1
            while n < due:
                rec.write_pressure(T0 + n * 1_000_000, 100000.0 + n)
                n += 1
            print("d", n, repr(time.monotonic()), flush=True)  # n written by then [s]
        time.sleep(0.0005)
"""


def test_kill_9_loses_at_most_about_one_second(tmp_path):
    """kill -9 of a writer streaming at 1 kHz: recover gives back, without a gap, every sample
    the writer had written flush_interval (1 s) before its last write, and none it had not
    written. Measured on the writer's own clock (its progress lines: samples written by a
    monotonic instant, all of them still in the pipe after the kill), not on how fast this
    machine runs it.

    After its last write (after the second-to-last progress line) the writer's last flush
    is less than flush_interval old, and a flush hands everything written before it to the
    operating system."""
    bag = tmp_path / "killed"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO_ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD.format(t0=T0, flush=KILL_FLUSH_S), str(bag)],
        stdout=subprocess.PIPE, text=True, cwd=REPO_ROOT, env=env,
    )
    lines: list[str] = []  # the writer's complete output lines

    def collect() -> None:
        for line in proc.stdout:
            if line.endswith("\n"):
                lines.append(line)

    def written() -> int:
        return next((int(ln.split()[1]) for ln in reversed(lines) if ln[0] == "d"), 0)

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    try:
        # until the writer has written 3.5 s of samples (an event, not a duration here): half
        # way between two of its flushes, when the most is pending
        deadline = time.monotonic() + 60.0
        while written() < 3500:
            assert proc.poll() is None, "the writer died"
            assert time.monotonic() < deadline, f"the writer is stuck: {lines[-3:]}"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    reader.join(30.0)  # the rest of what the writer printed before it died
    assert proc.returncode == -signal.SIGKILL
    assert not (bag / "metadata.yaml").exists()
    with pytest.raises(BagFormatError, match="recover"):
        read_pressure(bag)
    intents = [int(ln.split()[1]) for ln in lines if ln[0] == "w"]
    done = [(int(n), float(t)) for _, n, t in (ln.split() for ln in lines if ln[0] == "d")]
    written_max = max(intents)  # at most this many samples were written
    t_before_last = done[-2][1]  # before the last write
    on_disk = max((n for n, t in done if t <= t_before_last - KILL_FLUSH_S), default=0)
    assert on_disk > 0, "no sample was written flush_interval before the last write"

    report = recover(bag)
    n = report.messages.get(TOPIC_PRESSURE, 0)
    assert on_disk <= n <= written_max, (
        f"{n} samples recovered; written: {on_disk} by flush_interval before the last write, "
        f"at most {written_max} in all")
    t_ns, p = read_pressure(bag)
    np.testing.assert_array_equal(t_ns, T0 + np.arange(n, dtype=np.int64) * 1_000_000)
    np.testing.assert_array_equal(p, 100000.0 + np.arange(n))
    assert read_config(bag) == {"test": "kill -9"}
    with AnyReader([bag]) as reader:
        assert reader.message_count == n + 1


def test_iter_pressure_pieces_are_read_pressure_in_write_order(tmp_path, monkeypatch):
    """The bag read in pieces (one MCAP chunk each; the generic path in batches) is
    read_pressure(order="write"), with a stamp stepping back kept where it was written; the
    analysis reads bags this way (memory bounded by a chunk)."""
    from pneumatic_unload.io.bag import iter_pressure, stream

    path = tmp_path / "pieces"
    rng = np.random.default_rng(3)
    with BagRecorder(path, chunk_size=4096) as rec:
        stamps = T0 + np.arange(3000, dtype=np.int64) * 1000
        stamps[2000:] -= 5_000_000  # the clock steps back 5 ms
        rec.write_pressures(stamps, rng.normal(3e5, 1e4, stamps.size))
    whole = read_pressure(path, order="write")
    pieces = list(iter_pressure(path))
    assert len(pieces) > 5 and max(p.t_ns.size for p in pieces) < stamps.size / 5
    np.testing.assert_array_equal(np.concatenate([p.t_ns for p in pieces]), whole.t_ns)
    np.testing.assert_array_equal(np.concatenate([p.p for p in pieces]), whole.p)
    np.testing.assert_array_equal(whole.t_ns, stamps)
    # the generic path (rosbags' reader, log-time order) in batches of 700 messages
    monkeypatch.setattr(stream, "BATCH_MESSAGES", 700)
    generic = list(iter_pressure(path, fast=False))
    assert [p.t_ns.size for p in generic] == [700] * 4 + [200]
    log_order = read_pressure(path)
    np.testing.assert_array_equal(np.concatenate([p.t_ns for p in generic]), log_order.t_ns)
    with pytest.raises(TopicNotFoundError):
        iter_pressure(path, topic="/nope")


def test_a_chunk_index_pointing_past_the_file_is_read_without_the_fast_path(tmp_path):
    """A damaged summary whose chunk index claims a chunk of 2^50 bytes (one flipped byte,
    found by the fuzzer: MemoryError in the fast reader's read of the chunk) is not trusted:
    the samples are read by the generic path, all of them."""
    import struct

    t_ns = 1_700_000_000_000_000_000 + np.arange(3000, dtype=np.int64) * 1_000_000
    p = np.linspace(5e5, 1e5, 3000)
    bag = tmp_path / "bag"
    with BagRecorder(bag, chunk_size=4096) as rec:
        rec.write_pressures(t_ns, p)
    mcap = next(bag.glob("*.mcap"))
    with mcap.open("rb") as f:
        index = make_reader(f).get_summary().chunk_indexes[0]
    data = bytearray(mcap.read_bytes())
    key = struct.pack("<QQ", index.chunk_start_offset, index.chunk_length)
    at = data.rfind(key)  # in the summary's chunk index record
    assert at > index.chunk_start_offset
    data[at + 8:at + 16] = struct.pack("<Q", 1 << 50)
    mcap.write_bytes(bytes(data))
    got = read_pressure(bag)
    assert np.array_equal(got.t_ns, t_ns) and np.array_equal(got.p, p)


def test_the_bag_names_its_ros_distro_and_the_latched_topics_qos(full_bag):
    """As rosbag2 writes them: ``ros_distro: jazzy`` and, for the latched /rig/config and
    /estimator/estimate, a transient-local reliable offered QoS (``ros2 bag play``
    republishes them latched); the sample topics carry none."""
    info = yaml.safe_load((full_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["ros_distro"] == "jazzy"
    qos = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
           for t in info["topics_with_message_count"]}
    for topic in ("/rig/config", "/estimator/estimate"):
        (profile,) = yaml.safe_load(qos[topic]) if isinstance(qos[topic], str) else qos[topic]
        assert (profile["durability"], profile["reliability"]) in (
            (1, 1), ("transient_local", "reliable")), profile
    assert qos["/tank/pressure"] in ("", [], "[]")
    with AnyReader([full_bag], default_typestore=make_typestore()) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert conns["/rig/config"].ext.offered_qos_profiles[0].durability.name == \
            "TRANSIENT_LOCAL"
