# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Reading tank-discharge data from bags, without ROS.

Pressure and temperature series go through a numpy fast path (the MCAP summary's chunk
indexes and the per-chunk message indexes, no per-message Python work) or, when that does
not apply, rosbags' raw reader with numpy decoding. Valve states, estimates, the rig
configuration and JSON topics are decoded with the definitions stored in the bag.

Units: pressures in Pa absolute, temperatures in K (the ``sensor_msgs/Temperature``
messages carry degrees C; the conversion happens here), valve opening as a fraction [-],
timestamps as int nanoseconds (``t_ns``).
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader

from .cdr import NotFastDecodable, decode_stamped_pairs, gather
from .errors import BagFormatError, TopicNotFoundError
from .inflate import InflateBudget, inflate
from .records import MSG_HEAD_SIZE, OP_CHUNK, OP_MESSAGE, OP_MESSAGE_INDEX, RECORD_HEAD
from .schema import (
    CONFIG_METADATA_KEY,
    MSGTYPE_CONFIG,
    MSGTYPE_ESTIMATE,
    MSGTYPE_TEMPERATURE,
    MSGTYPE_VALVE,
    NS_PER_S,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_TEMPERATURE,
    TOPIC_VALVE,
    ZERO_CELSIUS,
    field_names,
    pressure_msgtype,
)
from .source import BagSource, bag_typestore, open_reader, resolve_bag, topic_connections

__all__ = [
    "PressureSeries",
    "RawMessage",
    "TemperatureSeries",
    "ValveSeries",
    "decode_pairs",
    "fast_chunk_pairs",
    "fast_raw_pairs",
    "read_config",
    "read_estimates",
    "read_json_topic",
    "read_pressure",
    "read_raw_messages",
    "read_stamped_pairs",
    "read_temperature",
    "read_valve",
]


def fast_chunk_pairs(
    mcap_file: Path, topic: str, msgtype: str
) -> Iterator[tuple[npt.NDArray[np.uint64], npt.NDArray[np.int64], npt.NDArray[np.float64],
                    npt.NDArray[np.float64]]]:
    """:func:`fast_raw_pairs` one MCAP chunk at a time (memory: one chunk), in the order the
    messages were written. Whether the file can take this path (a summary with chunk indexes,
    message indexes that count every message of the topic) is checked before the first chunk
    is yielded (NotFastDecodable then, so that a caller can read the file another way);
    NotFastDecodable later means a chunk that does not decode. Decompression is bounded
    (:mod:`.inflate`): a chunk that claims more than MAX_CHUNK_BYTES, expands past its
    claim, or a file whose chunks exceed its budget raises BagFormatError.
    """
    from mcap.reader import make_reader

    with mcap_file.open("rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception as err:
            raise NotFastDecodable from err
        if summary is None or summary.statistics is None or not summary.chunk_indexes:
            raise NotFastDecodable
        cids = {
            cid
            for cid, ch in summary.channels.items()
            if ch.topic == topic
            and ch.message_encoding == "cdr"
            and ch.schema_id in summary.schemas
            and summary.schemas[ch.schema_id].name == msgtype
        }
        expected = sum(summary.statistics.channel_message_counts.get(c, 0) for c in cids)
        indexes = [(index, [c for c in index.message_index_offsets if c in cids])
                   for index in sorted(summary.chunk_indexes,
                                       key=lambda c: c.chunk_start_offset)]
        indexes = [(index, wanted) for index, wanted in indexes if wanted]
        size = mcap_file.stat().st_size
        if any(index.chunk_start_offset + index.chunk_length + index.message_index_length
               > size for index, _wanted in indexes):
            raise NotFastDecodable  # a damaged index points past the file's end
        counted = 0
        for index, wanted in indexes:  # message index headers only: a few bytes per chunk
            for cid in wanted:
                f.seek(index.message_index_offsets[cid])
                head = f.read(15)
                if len(head) < 15:
                    raise NotFastDecodable
                op, _length = RECORD_HEAD.unpack_from(head, 0)
                mcid, nbytes = struct.unpack_from("<HI", head, 9)
                if op != OP_MESSAGE_INDEX or mcid != cid:
                    raise NotFastDecodable
                counted += nbytes // 16
        if counted != expected:
            raise NotFastDecodable  # message indexes incomplete: let the generic path read it
        budget = InflateBudget(mcap_file, size)
        for index, wanted in indexes:
            f.seek(index.chunk_start_offset)
            blob = f.read(index.chunk_length + index.message_index_length)
            op, _length = RECORD_HEAD.unpack_from(blob, 0)
            if op != OP_CHUNK:
                raise NotFastDecodable
            _start, _end, usize, _crc, clen = struct.unpack_from("<QQQII", blob, 9)
            compression = blob[41 : 41 + clen].decode(errors="replace")
            if compression not in ("", "zstd", "lz4"):
                raise NotFastDecodable
            (dsize,) = struct.unpack_from("<Q", blob, 41 + clen)
            dstart = 49 + clen
            raw = memoryview(blob)[dstart : dstart + dsize]
            # bounded: the claimed size capped, the output never past it (see .inflate)
            records = inflate(compression, raw, usize,
                              f"{mcap_file}: the chunk at byte {index.chunk_start_offset}")
            budget.take(usize)
            buf = np.frombuffer(records, np.uint8)
            for cid in wanted:
                mpos = index.message_index_offsets[cid] - index.chunk_start_offset
                op, _length = RECORD_HEAD.unpack_from(blob, mpos)
                mcid, nbytes = struct.unpack_from("<HI", blob, mpos + 9)
                if op != OP_MESSAGE_INDEX or mcid != cid:
                    raise NotFastDecodable
                entries = np.frombuffer(blob, "<u8", count=nbytes // 8, offset=mpos + 15)
                by_offset = np.argsort(entries[1::2], kind="stable")  # the write order
                log_t = entries[0::2][by_offset]
                off = entries[1::2][by_offset].astype(np.int64)
                if off.size and (off.max() + MSG_HEAD_SIZE > buf.size):
                    raise NotFastDecodable
                if np.any(buf[off] != OP_MESSAGE) or np.any(gather(buf, off + 9, "<u2") != cid):
                    raise NotFastDecodable
                lengths = gather(buf, off + 1, "<u8").astype(np.int64) - 22
                t, a, b = decode_stamped_pairs(buf, off + MSG_HEAD_SIZE, lengths)
                yield log_t.astype(np.uint64), t, a, b


def fast_raw_pairs(
    mcap_file: Path, topic: str, msgtype: str
) -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.int64], npt.NDArray[np.float64],
           npt.NDArray[np.float64]]:
    """Log times and decoded fields of one topic of an indexed MCAP file (numpy, no per-message
    Python work): uses the summary's chunk indexes and the per-chunk message indexes.
    Messages come in the order they were written (chunks and messages by file offset).
    """
    parts = list(fast_chunk_pairs(mcap_file, topic, msgtype))
    if not parts:
        return (np.empty(0, np.uint64), np.empty(0, np.int64), np.empty(0), np.empty(0))
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(4))  # type: ignore[return-value]


def _slow_raw_pairs(
    reader: Reader, conns: list[Connection], msgtype: str
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Header stamps and the two float fields via rosbags' raw reader + numpy decoding."""
    datas = [data for _, _, data in reader.messages(connections=conns)]
    return decode_pairs(datas, conns, msgtype)


def decode_pairs(
    datas: list[bytes], conns: list[Connection], msgtype: str
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Header stamps [ns] and the two float fields of serialised messages of ``msgtype``
    (numpy decoding, or the bag's typestore when that does not apply)."""
    if not datas:
        return np.empty(0, np.int64), np.empty(0), np.empty(0)
    lengths = np.fromiter((len(d) for d in datas), np.int64, len(datas))
    starts = np.zeros(len(datas), np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    buf = np.frombuffer(b"".join(datas), np.uint8)
    try:
        return decode_stamped_pairs(buf, starts, lengths)
    except NotFastDecodable:
        store = bag_typestore(conns)
        msgs = [store.deserialize_cdr(d, msgtype) for d in datas]
        t = np.array([m.header.stamp.sec * NS_PER_S + m.header.stamp.nanosec for m in msgs])
        first = field_names(store, msgtype)[1]
        a = np.array([getattr(m, first) for m in msgs], np.float64)
        b = np.array([m.variance for m in msgs], np.float64)
        return t.astype(np.int64), a, b


def read_stamped_pairs(
    path: str | os.PathLike[str], topic: str, msgtype: str, *, fast: bool = True,
    order: str = "log",
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(header stamps [ns], first float field, variance) of a FluidPressure/Temperature topic,
    in log-time order, or with ``order="write"`` in the order the messages were written
    (indexed MCAP files; other storage: log-time order). The write order shows what the log
    order may hide: header stamps that step back while log times (e.g. equal to the stamps)
    do not tell. ``fast=False`` forces the generic (rosbags raw reader) path.
    """
    if order not in ("log", "write"):
        raise ValueError(f"order must be 'log' or 'write', not {order!r}")
    src = resolve_bag(path)
    with open_reader(src) as reader:
        conns = topic_connections(reader, src, topic, msgtype)
        if fast and src.mcap_files:
            try:
                parts = [fast_raw_pairs(f, topic, msgtype) for f in src.mcap_files]
            except NotFastDecodable:
                parts = []
            else:
                logs = np.concatenate([p[0] for p in parts])
                t = np.concatenate([p[1] for p in parts])
                a = np.concatenate([p[2] for p in parts])
                b = np.concatenate([p[3] for p in parts])
                if order == "write":
                    return t, a, b
                by_log = np.argsort(logs, kind="stable")
                return t[by_log], a[by_log], b[by_log]
        return _slow_raw_pairs(reader, conns, msgtype)


class PressureSeries(NamedTuple):
    """Tank pressure samples; unpacks as ``t_ns, p = read_pressure(bag)``."""

    t_ns: npt.NDArray[np.int64]  #: header stamps [ns]
    p: npt.NDArray[np.float64]  #: pressures [Pa absolute]


class TemperatureSeries(NamedTuple):
    """Gas temperature samples; unpacks as ``t_ns, temperature = read_temperature(bag)``."""

    t_ns: npt.NDArray[np.int64]  #: header stamps [ns]
    temperature: npt.NDArray[np.float64]  #: temperatures [K]


class ValveSeries(NamedTuple):
    """Valve states; unpacks as ``t_ns, open, opening = read_valve(bag)``."""

    t_ns: npt.NDArray[np.int64]  #: header stamps [ns]
    open: npt.NDArray[np.bool_]  #: commanded open
    opening: npt.NDArray[np.float64]  #: effective opening fraction [-]


def read_pressure(
    path: str | os.PathLike[str], *, topic: str = TOPIC_PRESSURE, order: str = "log"
) -> PressureSeries:
    """Read all pressure samples of a bag (numpy bulk decoding of FluidPressure).

    Args:
        path: bag directory or single ``.mcap`` file.
        topic: pressure topic (sensor_msgs/msg/FluidPressure; pneumatic_unload_msgs/msg/Voltage
            on ``/tank/pressure_volts``, whose values are volts).
        order: ``"log"`` (log-time order) or ``"write"`` (the order the messages were
            written, see :func:`read_stamped_pairs`; the analysis uses it, so that a clock
            stepping back in the header stamps is seen).

    Returns:
        ``(t_ns, p)``: header stamps [ns] (int64) and pressures [Pa absolute] (float64), in
        the requested order.

    Raises:
        BagNotFoundError, BagFormatError, TopicNotFoundError, WrongMessageTypeError.
    """
    t, p, _ = read_stamped_pairs(path, topic, pressure_msgtype(topic), order=order)
    return PressureSeries(t, p)


def read_temperature(
    path: str | os.PathLike[str], *, topic: str = TOPIC_TEMPERATURE
) -> TemperatureSeries:
    """Read all gas temperature samples of a bag.

    Args:
        path: bag directory or single ``.mcap`` file.
        topic: temperature topic (sensor_msgs/msg/Temperature, degrees C in the message).

    Returns:
        ``(t_ns, temperature)``: header stamps [ns] and temperatures [K], in log-time order.
    """
    t, celsius, _ = read_stamped_pairs(path, topic, MSGTYPE_TEMPERATURE)
    return TemperatureSeries(t, celsius + ZERO_CELSIUS)


def _deserialized(
    path: str | os.PathLike[str], topic: str, msgtype: str, *, required: bool = True
) -> Iterator[tuple[int, Any, list[str]]]:
    """(log time [ns], message, field names) of ``topic``, decoded with the bag's own
    definitions.
    """
    src = resolve_bag(path)
    with open_reader(src) as reader:
        try:
            conns = topic_connections(reader, src, topic, msgtype)
        except TopicNotFoundError:
            if required:
                raise
            return
        store = bag_typestore(conns)
        names = field_names(store, msgtype)
        for _, log_time, data in reader.messages(connections=conns):
            yield log_time, store.deserialize_cdr(data, msgtype), names


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def read_valve(path: str | os.PathLike[str], *, topic: str = TOPIC_VALVE) -> ValveSeries:
    """Read all valve states of a bag.

    Returns:
        ``(t_ns, open, opening)``: header stamps [ns], commanded-open flags, opening
        fraction [-].
    """
    rows = [(_stamp_ns(m.header.stamp), m.open, m.opening)
            for _, m, _ in _deserialized(path, topic, MSGTYPE_VALVE)]
    return ValveSeries(
        np.array([r[0] for r in rows], np.int64),
        np.array([r[1] for r in rows], np.bool_),
        np.array([r[2] for r in rows], np.float64),
    )


def read_estimates(
    path: str | os.PathLike[str], *, topic: str = TOPIC_ESTIMATE
) -> list[dict[str, Any]]:
    """Read all UnloadEstimate messages of a bag as dicts.

    Keys are those of :meth:`BagRecorder.write_estimate`: ``header_stamp_ns`` [ns],
    ``frame_id``, ``unload_start_ns`` [ns] and the remaining message fields by name (SI units:
    conductances m^3/(s Pa), pressures Pa absolute, tau_exp s, initial_temperature K, volume
    m^3). Decoded with the definition stored in the bag.
    """
    out: list[dict[str, Any]] = []
    for _, msg, names in _deserialized(path, topic, MSGTYPE_ESTIMATE):
        row: dict[str, Any] = {
            "header_stamp_ns": _stamp_ns(msg.header.stamp),
            "frame_id": msg.header.frame_id,
            "unload_start_ns": _stamp_ns(msg.unload_start),
        }
        for name in names:
            if name not in ("header", "unload_start"):
                row[name] = getattr(msg, name)
        out.append(row)
    return out


def read_config(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The rig configuration of a bag: the metadata custom_data (where :class:`BagRecorder`
    stores the text of its first ``/rig/config`` message), else the first ``/rig/config``
    message (a bag whose metadata lacks it: no scan of the messages when it is there).

    Returns:
        The configuration dict (SI units as stored), or None if the bag has none.

    Raises:
        BagFormatError: the stored configuration is not a JSON object.
    """
    src = resolve_bag(path)
    text: str | None = src.custom_data.get(CONFIG_METADATA_KEY)
    if text is None:
        for _, msg, _ in _deserialized(path, TOPIC_CONFIG, MSGTYPE_CONFIG, required=False):
            text = msg.data
            break
    if text is None:
        return None
    try:
        config = json.loads(text)
    except ValueError as err:
        raise BagFormatError(
            f"the rig configuration in {src.path} is not valid JSON: {err}"
        ) from err
    if not isinstance(config, dict):
        raise BagFormatError(f"the rig configuration in {src.path} is not a JSON object")
    return config


class RawMessage(NamedTuple):
    """One serialised message of a bag, as :func:`read_raw_messages` yields it."""

    topic: str
    msgtype: str  #: e.g. 'sensor_msgs/msg/FluidPressure'
    log_time_ns: int  #: bag log time [ns]
    data: bytes  #: the CDR payload with its 4-byte encapsulation header


def _raw_messages(src: BagSource, topics: frozenset[str] | None) -> Iterator[RawMessage]:
    with open_reader(src) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        if not conns:
            return
        for conn, log_time, data in reader.messages(connections=conns):
            yield RawMessage(conn.topic, conn.msgtype, int(log_time), bytes(data))


def read_raw_messages(
    path: str | os.PathLike[str], *, topics: Collection[str] | None = None
) -> Iterator[RawMessage]:
    """Serialised messages of a bag in log-time order (no deserialisation), e.g. for replay.

    Args:
        path: bag directory or single ``.mcap`` file.
        topics: only these topics (all when None).

    Returns:
        An iterator of :class:`RawMessage` (topic, type, log time [ns], CDR bytes).

    Raises:
        BagNotFoundError, BagFormatError: checked before the iterator is returned.
        TopicNotFoundError: a requested topic is not in the bag.
    """
    src = resolve_bag(path)
    wanted = None if topics is None else frozenset(topics)
    with open_reader(src) as reader:
        have = sorted({c.topic for c in reader.connections})
    for topic in sorted(wanted or ()):
        if topic not in have:
            raise TopicNotFoundError(topic, have, src.path)
    return _raw_messages(src, wanted)


def read_json_topic(path: str | os.PathLike[str], topic: str) -> dict[str, Any] | None:
    """The last JSON object published on a std_msgs/String topic of a bag (None if absent).

    Used for ``/estimator/settings``: the settings in force when the last message was sent.

    Raises:
        BagFormatError: the message is not a JSON object.
        WrongMessageTypeError: the topic is not std_msgs/String.
    """
    text: str | None = None
    for _, msg, _ in _deserialized(path, topic, MSGTYPE_CONFIG, required=False):
        text = msg.data
    if text is None:
        return None
    try:
        value = json.loads(text)
    except ValueError as err:
        raise BagFormatError(f"{topic} in {path} is not valid JSON: {err}") from err
    if not isinstance(value, dict):
        raise BagFormatError(f"{topic} in {path} is not a JSON object")
    return value
