"""Rosbag2 bags (MCAP storage) of tank discharges, read and written without ROS.

This module never imports rclpy or a ROS message package: messages are (de)serialised with
rosbags' own typestore (ROS 2 Jazzy types plus the ``pneumatic_unload_msgs`` types read from
their ``.msg`` files), and the bulk pressure stream has a numpy fast path in both directions.

Units at this API: pressures in Pa absolute, temperatures in K (the ``sensor_msgs/Temperature``
messages carry degrees C; the conversion happens here), valve opening as a fraction [-],
durations in s, timestamps as int nanoseconds (``t_ns``).

Topics (see the ``TOPIC_*`` / ``MSGTYPE_*`` constants): ``/tank/pressure``
(sensor_msgs/msg/FluidPressure), ``/tank/temperature`` (sensor_msgs/msg/Temperature),
``/tank/valve`` (pneumatic_unload_msgs/msg/ValveState), ``/estimator/estimate``
(pneumatic_unload_msgs/msg/UnloadEstimate) and ``/rig/config`` (std_msgs/msg/String holding
the JSON rig configuration; the first message of every bag written by :class:`BagRecorder`).

Crash safety: :class:`BagRecorder` closes its pending MCAP chunk at least every
``flush_interval`` seconds (and whenever it reaches ``chunk_size`` bytes) and hands it to the
operating system, so a ``kill -9`` loses at most about ``flush_interval`` of data.
:func:`recover` turns the directory such a writer leaves behind (no ``metadata.yaml``, an MCAP
file without summary or footer, maybe a torn last chunk) into a complete bag again.
"""

from __future__ import annotations

import array
import contextlib
import dataclasses
import json
import math
import operator
import os
import shutil
import struct
import sys
import threading
import time
import zlib
from collections import defaultdict
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache
from io import BytesIO
from pathlib import Path, PurePath
from types import TracebackType
from typing import Any, ClassVar, Final, Literal, NamedTuple

import numpy as np
import numpy.typing as npt
import yaml
from mcap.records import Channel as McapChannel
from mcap.records import Chunk as McapChunk
from mcap.records import Message as McapMessage
from mcap.records import Schema as McapSchema
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.interfaces import Connection, MessageDefinitionFormat, Nodetype
from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

__all__ = [
    "CONFIG_METADATA_KEY",
    "DEFAULT_CHUNK_SIZE",
    "MSGTYPE_CONFIG",
    "MSGTYPE_ESTIMATE",
    "MSGTYPE_PRESSURE",
    "MSGTYPE_TEMPERATURE",
    "MSGTYPE_VALVE",
    "MSG_PACKAGE",
    "RECOVER_HINT",
    "TOPIC_CONFIG",
    "TOPIC_ESTIMATE",
    "TOPIC_PRESSURE",
    "TOPIC_TEMPERATURE",
    "TOPIC_VALVE",
    "ZERO_CELSIUS",
    "BagError",
    "BagFormatError",
    "BagNotFoundError",
    "BagRecorder",
    "BagSummary",
    "BagWriteError",
    "PressureSeries",
    "RawMessage",
    "RecoverReport",
    "TemperatureSeries",
    "TopicNotFoundError",
    "TopicSummary",
    "UnknownMessageTypeError",
    "ValveSeries",
    "WrongMessageTypeError",
    "bag_summary",
    "cdr_header_stamp_ns",
    "find_msg_definition",
    "find_msg_dir",
    "make_typestore",
    "read_config",
    "read_estimates",
    "read_pressure",
    "read_raw_messages",
    "read_temperature",
    "read_valve",
    "recover",
]

# ----------------------------------------------------------------------------- constants

TOPIC_PRESSURE: Final = "/tank/pressure"
TOPIC_TEMPERATURE: Final = "/tank/temperature"
TOPIC_VALVE: Final = "/tank/valve"
TOPIC_ESTIMATE: Final = "/estimator/estimate"
TOPIC_CONFIG: Final = "/rig/config"
#: The live estimator's settings (std_msgs/String JSON, latched): analysis reuses them.
TOPIC_SETTINGS: Final = "/estimator/settings"

MSG_PACKAGE: Final = "pneumatic_unload_msgs"
MSGTYPE_PRESSURE: Final = "sensor_msgs/msg/FluidPressure"
MSGTYPE_TEMPERATURE: Final = "sensor_msgs/msg/Temperature"
MSGTYPE_VALVE: Final = f"{MSG_PACKAGE}/msg/ValveState"
MSGTYPE_ESTIMATE: Final = f"{MSG_PACKAGE}/msg/UnloadEstimate"
MSGTYPE_CONFIG: Final = "std_msgs/msg/String"

#: Key of the JSON rig configuration in the rosbag2 metadata ``custom_data``.
CONFIG_METADATA_KEY: Final = "pneumatic_unload.config"
#: What to tell a user whose bag was not closed properly.
RECOVER_HINT: Final = "run `pneumatic-unload recover BAG` to repair it"
#: 0 degrees C in K.
ZERO_CELSIUS: Final = 273.15
#: Default MCAP chunk size [bytes] (as rosbags): time-based flushing bounds the loss first.
DEFAULT_CHUNK_SIZE: Final = 1 << 20

_NS_PER_S: Final = 1_000_000_000
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_UINT64_MAX: Final = 2**64 - 1
_MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
_OP_CHUNK, _OP_MESSAGE_INDEX, _OP_MESSAGE = 0x06, 0x07, 0x05
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MSG_HEAD_SIZE: Final = _MSG_HEAD.size  # 31 bytes; the CDR payload follows
_RECORD_HEAD = struct.Struct("<BQ")
_PLACEHOLDER_RIHS01: Final = "RIHS01_" + "0" * 64


# -------------------------------------------------------------------------------- errors


class BagError(Exception):
    """Base class of every error raised by :mod:`pneumatic_unload.io.bag`."""


class BagNotFoundError(BagError, FileNotFoundError):
    """The bag directory or ``.mcap`` file does not exist."""


class BagFormatError(BagError):
    """The path is not a readable rosbag2/MCAP bag (wrong format, truncated, corrupt)."""


class BagWriteError(BagError):
    """A bag cannot be written (path exists, recorder closed, invalid value)."""


class UnknownMessageTypeError(BagError, KeyError):
    """A message type has no definition in the typestore: register it first."""

    def __init__(self, msgtype: str) -> None:
        """Build the message for ``msgtype`` (e.g. 'pkg/msg/Name')."""
        self.msgtype = msgtype
        super().__init__(
            f"message type {msgtype!r} is unknown: call register_type({msgtype!r}, msgdef_text) "
            "with its .msg definition first"
        )

    def __str__(self) -> str:
        """The message, without KeyError's quoting."""
        return str(self.args[0])


class TopicNotFoundError(BagError, KeyError):
    """The bag has no such topic; ``available`` lists the topics it has."""

    def __init__(self, topic: str, available: list[str], path: Path) -> None:
        """Build the message for ``topic`` missing in the bag at ``path``."""
        self.topic = topic
        self.available = available
        self.path = path
        have = ", ".join(available) if available else "(none)"
        super().__init__(f"bag {path} has no topic {topic!r}; topics in the bag: {have}")

    def __str__(self) -> str:
        """The message, without KeyError's quoting."""
        return str(self.args[0])


class WrongMessageTypeError(BagError, TypeError):
    """The topic exists but carries another message type than the one asked for."""

    def __init__(self, topic: str, expected: str, found: list[str], path: Path) -> None:
        """Build the message naming the ``expected`` and the ``found`` type(s)."""
        self.topic = topic
        self.expected = expected
        self.found = found
        self.path = path
        super().__init__(
            f"topic {topic!r} in bag {path} has type {', '.join(found)}, expected {expected}"
        )


# ------------------------------------------------------------------------ message types


def find_msg_dir() -> Path:
    """Directory holding the ``pneumatic_unload_msgs`` ``.msg`` files, found without rclpy.

    Search order: the source tree (``<repo>/msg_defs/msg``), then ``share/pneumatic_unload_msgs
    /msg`` under ``sys.prefix`` and under each entry of ``AMENT_PREFIX_PATH`` (colcon install
    or ament index).

    Returns:
        The directory [path].

    Raises:
        BagError: No candidate directory holds the message files.
    """
    candidates = [Path(__file__).resolve().parents[2] / "msg_defs" / "msg"]
    share = Path("share") / MSG_PACKAGE / "msg"
    prefixes = [sys.prefix, sys.base_prefix]
    prefixes += [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    candidates += [Path(p) / share for p in prefixes]
    for cand in candidates:
        if (cand / "UnloadEstimate.msg").is_file():
            return cand
    tried = ", ".join(str(c) for c in candidates)
    raise BagError(f"cannot find the {MSG_PACKAGE} .msg files; looked in: {tried}")


@lru_cache(maxsize=1)
def _package_types() -> dict[str, Any]:
    """Parsed definitions of all ``pneumatic_unload_msgs`` messages (rosbags Typesdict)."""
    types: dict[str, Any] = {}
    for msg_file in sorted(find_msg_dir().glob("*.msg")):
        name = f"{MSG_PACKAGE}/msg/{msg_file.stem}"
        types.update(get_types_from_msg(msg_file.read_text(encoding="utf-8"), name))
    return types


def make_typestore() -> Typestore:
    """A fresh rosbags typestore: ROS 2 Jazzy types plus the ``pneumatic_unload_msgs`` types.

    Returns:
        A new typestore (callers may register more types in it without side effects).
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(_package_types())
    return store


def find_msg_definition(msgtype: str) -> str | None:
    """The ``.msg`` text of ``msgtype`` ('pkg/msg/Name') from an installed interface package.

    Looks for ``share/<pkg>/msg/<Name>.msg`` under ``sys.prefix`` and each entry of
    ``AMENT_PREFIX_PATH`` (and the source tree for ``pneumatic_unload_msgs``).

    Returns:
        The definition text, or None if no installed package provides it.
    """
    parts = msgtype.split("/")
    if len(parts) == 2:  # 'pkg/Name' (ROS 1 style, used inside .msg files)
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or parts[1] != "msg" or not all(parts):
        return None
    pkg, _, name = parts
    prefixes = [sys.prefix, sys.base_prefix]
    prefixes += [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    candidates = [Path(p) / "share" / pkg / "msg" / f"{name}.msg" for p in prefixes]
    if pkg == MSG_PACKAGE:
        with contextlib.suppress(BagError):
            candidates.insert(0, find_msg_dir() / f"{name}.msg")
    for cand in candidates:
        if cand.is_file():
            return cand.read_text(encoding="utf-8")
    return None


def _referenced_types(spec: Any) -> Iterator[str]:
    """Message type names referenced by one rosbags field type spec (recursively)."""
    kind, detail = spec
    if kind == Nodetype.NAME:
        yield detail
    elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        yield from _referenced_types(detail[0])


def _missing_types(store: Typestore, msgtype: str) -> list[str]:
    """Types that ``msgtype`` needs (itself included) and ``store`` does not define."""
    missing: list[str] = []
    seen: set[str] = set()
    todo = [msgtype]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        if name not in store.fielddefs:
            missing.append(name)
            continue
        for _, spec in store.fielddefs[name][1]:
            todo.extend(_referenced_types(spec))
    return missing


def _field_names(store: Typestore, msgtype: str) -> list[str]:
    """Field names of ``msgtype`` in definition order (constants excluded)."""
    return [name for name, _ in store.fielddefs[msgtype][1]]


# ------------------------------------------------------------------- CDR fast path (numpy)


def _check_t_ns(value: object, what: str = "t_ns") -> int:
    """``value`` as a Python int [ns]; rejects floats (timestamps are integer nanoseconds)."""
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise BagWriteError(
            f"{what} must be an integer number of nanoseconds, got {type(value).__name__} "
            f"{value!r}"
        ) from None


def _split_stamp(t_ns: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], npt.NDArray]:
    """(sec, nanosec) of ROS ``builtin_interfaces/Time`` for stamps ``t_ns`` [ns]."""
    sec, nsec = np.divmod(t_ns, _NS_PER_S)
    if sec.size and (sec.min() < _INT32_MIN or sec.max() > _INT32_MAX):
        raise BagWriteError("header stamp out of the int32 seconds range of ROS Time")
    return sec, nsec


def _stamped_pair_dtype(frame_id: bytes) -> np.dtype:
    """numpy layout of the CDR of ``Header header; float64 a; float64 b`` (FluidPressure,
    Temperature) for a fixed ``frame_id`` (CDR little endian, 8-byte alignment from the body).
    """
    n_str = len(frame_id) + 1  # with the NUL terminator
    pad = (-(12 + n_str)) % 8
    fields: list[tuple[Any, ...]] = [
        ("encap", "u1", (4,)),
        ("sec", "<i4"),
        ("nanosec", "<u4"),
        ("strlen", "<u4"),
        ("frame_id", "u1", (n_str,)),
    ]
    if pad:
        fields.append(("pad", "u1", (pad,)))
    fields += [("a", "<f8"), ("b", "<f8")]
    return np.dtype(fields)


def _encode_stamped_pairs(
    t_ns: npt.ArrayLike,
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    *,
    frame_id: str,
) -> npt.NDArray[np.uint8]:
    """CDR payloads of N FluidPressure/Temperature messages, byte-identical to rosbags'.

    Args:
        t_ns: header stamps [ns], integer array of shape (N,).
        a: first float64 field (fluid_pressure [Pa] or temperature [degC]), shape (N,) or scalar.
        b: variance [Pa^2 or K^2], shape (N,) or scalar.
        frame_id: header frame id (same for all N).

    Returns:
        uint8 array of shape (N, L): one serialised message per row.
    """
    stamps = np.asarray(t_ns)
    if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
        raise BagWriteError("t_ns must be a 1-D integer array of nanoseconds")
    stamps = stamps.astype(np.int64, copy=False)
    frame = frame_id.encode()
    if b"\x00" in frame:
        raise BagWriteError("frame_id must not contain NUL characters")
    dtype = _stamped_pair_dtype(frame)
    out = np.zeros(stamps.size, dtype)
    sec, nsec = _split_stamp(stamps)
    out["encap"] = (0, 1, 0, 0)
    out["sec"] = sec
    out["nanosec"] = nsec
    out["strlen"] = len(frame) + 1
    out["frame_id"][:, : len(frame)] = np.frombuffer(frame, np.uint8)
    out["a"] = a
    out["b"] = b
    return out.view(np.uint8).reshape(stamps.size, dtype.itemsize)


@lru_cache(maxsize=64)
def _stamped_pair_struct(frame_id: str) -> tuple[struct.Struct, bytes]:
    """struct layout of one FluidPressure/Temperature CDR payload for ``frame_id``."""
    frame = frame_id.encode()
    if b"\x00" in frame:
        raise BagWriteError("frame_id must not contain NUL characters")
    n_str = len(frame) + 1
    pad = (-(12 + n_str)) % 8
    return struct.Struct(f"<4siII{n_str}s{pad}xdd"), frame


def _encode_stamped_pair(t_ns: int, a: float, b: float, *, frame_id: str) -> bytes:
    """CDR payload of one FluidPressure/Temperature message (stamp [ns], a, variance b)."""
    layout, frame = _stamped_pair_struct(frame_id)
    sec, nsec = divmod(t_ns, _NS_PER_S)
    try:
        return layout.pack(b"\x00\x01\x00\x00", sec, nsec, len(frame) + 1, frame, a, b)
    except struct.error as err:
        raise BagWriteError(f"cannot encode stamp {t_ns} ns / values {a}, {b}: {err}") from err


def cdr_header_stamp_ns(data: bytes | bytearray | memoryview) -> int | None:
    """Header stamp [ns] of a serialised message whose first field is ``std_msgs/Header``.

    Reads ``builtin_interfaces/Time`` (int32 sec, uint32 nanosec) right after the 4-byte CDR
    encapsulation header, in the payload's byte order. No other validation: call it only for
    types that start with a header.

    Returns:
        The stamp [ns] (may be negative for a negative ``sec``), or None if the payload is
        too short or not plain CDR.
    """
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        return None
    sec, nsec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return sec * _NS_PER_S + nsec


class _NotFastDecodable(Exception):
    """The raw messages cannot go through the numpy decoder (e.g. big-endian CDR)."""


def _gather(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64], dtype: str) -> np.ndarray:
    """Values of ``dtype`` read at byte positions ``pos`` of ``buf`` (vectorised)."""
    dt = np.dtype(dtype)
    return buf[pos[:, None] + np.arange(dt.itemsize)].view(dt).reshape(-1)


def _decode_stamped_pairs(
    buf: npt.NDArray[np.uint8],
    starts: npt.NDArray[np.int64],
    lengths: npt.NDArray[np.int64],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Decode N FluidPressure/Temperature CDR payloads at ``buf[starts[i]:starts[i]+lengths[i]]``.

    frame_id lengths may differ per message: the float offsets are computed per message.

    Returns:
        (header stamps [ns], first float64 field, second float64 field (variance)).

    Raises:
        _NotFastDecodable: a payload is not little-endian plain CDR.
        BagFormatError: a payload is too short for the layout.
    """
    if starts.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.float64), np.empty(0, np.float64)
    if np.any(lengths < 4 + 12 + 1 + 16) or np.any(starts + lengths > buf.size):
        raise BagFormatError("message payload too short for a header-stamped message")
    if np.any(buf[starts] != 0) or np.any(buf[starts + 1] != 1):
        raise _NotFastDecodable
    sec = _gather(buf, starts + 4, "<i4").astype(np.int64)
    nsec = _gather(buf, starts + 8, "<u4").astype(np.int64)
    strlen = _gather(buf, starts + 12, "<u4").astype(np.int64)
    vpos = starts + 4 + ((12 + strlen + 7) // 8) * 8
    if np.any(vpos + 16 > starts + lengths):
        raise BagFormatError("corrupt message: frame_id length runs past the payload")
    a = _gather(buf, vpos, "<f8")
    b = _gather(buf, vpos + 8, "<f8")
    return sec * _NS_PER_S + nsec, a, b


# ----------------------------------------------------------------------------- writing


class _FlushingMcapWriter(McapWriter):
    """rosbags' MCAP storage writer with a byte-size chunk limit, flushes and block writes.

    Chunks carry a CRC and their message indexes are sorted by log time. Each closed chunk is
    followed by its message index records, so the file is a valid (unfinished) MCAP data
    section at every flush.
    """

    chunk_size: int = DEFAULT_CHUNK_SIZE

    def __init__(self, path: Path, compression: Any) -> None:
        """Open ``<path>/<path.name>.mcap`` and write the MCAP header (see McapWriter)."""
        super().__init__(path, compression)
        self._index: dict[int, tuple[array.array, array.array]] = {}

    def _add_index(self, cid: int) -> tuple[array.array, array.array]:
        entry = self._index.get(cid)
        if entry is None:
            entry = self._index[cid] = (array.array("Q"), array.array("Q"))
        return entry

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        """Append one message record [timestamp in ns] to the pending chunk."""
        cid = connection.id
        bio = self.chunk.bio
        offset = bio.tell()
        bio.write(_MSG_HEAD.pack(_OP_MESSAGE, 22 + len(data), cid, 0, timestamp, timestamp))
        bio.write(data)
        times, offsets = self._add_index(cid)
        times.append(timestamp)
        offsets.append(offset)
        self.channel_stats[cid] += 1
        if timestamp < self.message_start_time:
            self.message_start_time = timestamp
        if timestamp > self.message_end_time:
            self.message_end_time = timestamp
        chunk = self.chunk
        if timestamp < chunk.message_start_time:
            chunk.message_start_time = timestamp
        if timestamp > chunk.message_end_time:
            chunk.message_end_time = timestamp
        if bio.tell() >= self.chunk_size:
            self.close_chunk()

    def write_block(
        self,
        cid: int,
        log_times: npt.NDArray[np.uint64],
        payloads: npt.NDArray[np.uint8],
    ) -> None:
        """Append N message records of equal payload size in a few vectorised steps.

        Args:
            cid: connection (channel) id.
            log_times: log times [ns], shape (N,).
            payloads: serialised messages, uint8 array of shape (N, L).
        """
        n, size = payloads.shape
        if n == 0:
            return
        rec_dtype = np.dtype(
            [
                ("op", "u1"),
                ("length", "<u8"),
                ("channel", "<u2"),
                ("sequence", "<u4"),
                ("log_time", "<u8"),
                ("publish_time", "<u8"),
                ("data", "u1", (size,)),
            ]
        )
        itemsize = rec_dtype.itemsize
        self.channel_stats[cid] += n
        self.message_start_time = min(self.message_start_time, int(log_times.min()))
        self.message_end_time = max(self.message_end_time, int(log_times.max()))
        done = 0
        while done < n:
            bio = self.chunk.bio
            room = max(1, (self.chunk_size - bio.tell()) // itemsize)
            stop = min(n, done + room)
            part_times = log_times[done:stop]
            recs = np.zeros(stop - done, rec_dtype)
            recs["op"] = _OP_MESSAGE
            recs["length"] = 22 + size
            recs["channel"] = cid
            recs["log_time"] = part_times
            recs["publish_time"] = part_times
            recs["data"] = payloads[done:stop]
            start = bio.tell()
            bio.write(recs.tobytes())
            times, offsets = self._add_index(cid)
            times.frombytes(part_times.astype(np.uint64).tobytes())
            offsets.frombytes(
                (start + itemsize * np.arange(stop - done, dtype=np.uint64)).tobytes()
            )
            chunk = self.chunk
            chunk.message_start_time = min(chunk.message_start_time, int(part_times.min()))
            chunk.message_end_time = max(chunk.message_end_time, int(part_times.max()))
            done = stop
            if bio.tell() >= self.chunk_size:
                self.close_chunk()

    def close_chunk(self) -> None:
        """Write the pending chunk, its message indexes, and remember its chunk index."""
        data = self.chunk.bio.getbuffer()
        compressed = self.compressor(bytes(data)) if self.compression else data
        has_messages = bool(self._index)
        start_time = self.chunk.message_start_time if has_messages else 0
        end_time = self.chunk.message_end_time if has_messages else 0
        compression = self.compression.encode()
        head = struct.pack("<QQQI", start_time, end_time, len(data), zlib.crc32(data))
        head += struct.pack("<I", len(compression)) + compression
        head += struct.pack("<Q", len(compressed))

        out = self.bio
        chunk_start = out.tell()
        out.write(_RECORD_HEAD.pack(_OP_CHUNK, len(head) + len(compressed)))
        out.write(head)
        out.write(compressed)
        chunk_end = out.tell()

        index_offsets: list[tuple[int, int]] = []
        for cid in sorted(self._index):
            times_arr, offsets_arr = self._index[cid]
            times = np.frombuffer(times_arr, np.uint64)
            offsets = np.frombuffer(offsets_arr, np.uint64)
            order = np.argsort(times, kind="stable")
            entries = np.empty((times.size, 2), "<u8")
            entries[:, 0] = times[order]
            entries[:, 1] = offsets[order]
            body = struct.pack("<HI", cid, entries.nbytes) + entries.tobytes()
            index_offsets.append((cid, out.tell()))
            out.write(_RECORD_HEAD.pack(_OP_MESSAGE_INDEX, len(body)))
            out.write(body)

        rec = BytesIO()
        rec.write(struct.pack("<QQQQI", start_time, end_time, chunk_start,
                              chunk_end - chunk_start, len(index_offsets) * 10))
        for cid, offset in index_offsets:
            rec.write(struct.pack("<HQ", cid, offset))
        rec.write(struct.pack("<Q", out.tell() - chunk_end))
        rec.write(struct.pack("<I", len(compression)) + compression)
        rec.write(struct.pack("<QQ", len(compressed), self.chunk.bio.tell()))
        self.chunks.append(rec)

        self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
        self._index = {}

    def flush(self, *, fsync: bool = False) -> None:
        """Close the pending chunk if it holds messages and hand the file to the OS."""
        if self._index:
            self.close_chunk()
        self.bio.flush()
        if fsync:
            os.fsync(self.bio.fileno())


class _Rosbag2Writer(Writer):
    """rosbags' rosbag2 writer using :class:`_FlushingMcapWriter` for MCAP storage."""

    STORAGE_PLUGINS: ClassVar[Mapping[StoragePlugin, Any]] = {
        **Writer.STORAGE_PLUGINS,
        StoragePlugin.MCAP: _FlushingMcapWriter,
    }

    @property
    def mcap(self) -> _FlushingMcapWriter:
        """The open MCAP storage writer."""
        storage = self.storage
        if not isinstance(storage, _FlushingMcapWriter):
            raise BagWriteError(f"bag {self.path} is not open")
        return storage

    def write_block(
        self,
        connection: Connection,
        log_times: npt.NDArray[np.uint64],
        payloads: npt.NDArray[np.uint8],
    ) -> None:
        """Write N equal-size messages [log times in ns] to ``connection``."""
        if log_times.size == 0:
            return
        self.mcap.write_block(connection.id, log_times, payloads)
        self.counts[connection.id] += int(log_times.size)
        self.min_timestamp = min(self.min_timestamp, int(log_times.min()))
        self.max_timestamp = max(self.max_timestamp, int(log_times.max()))


def _json_default(obj: object) -> object:
    """JSON fallback for numpy values, paths and dataclasses in a rig configuration."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


class BagRecorder:
    """Streaming writer of a rosbag2 bag (MCAP storage) for the live recorder and simulations.

    Use as a context manager; the bag is completed (summary, ``metadata.yaml``) on ``close()``
    or when the ``with`` block ends, also when it ends with an exception. Thread safe.

    Example::

        with BagRecorder(path, config={"volume": 1e-3}) as rec:
            rec.write_pressures(t_ns, p_pa)          # int64 [ns], float64 [Pa absolute]
            rec.write_temperature(t_ns[0], 293.15)   # [K]
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        config: Mapping[str, Any] | None = None,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        flush_interval: float = 1.0,
        fsync: bool = False,
        config_stamp_ns: int | None = None,
    ) -> None:
        """Create the bag directory ``path`` (it must not exist) and open it for writing.

        Args:
            path: new bag directory; the MCAP file is ``<path>/<name>.mcap``.
            config: rig configuration (JSON-serialisable mapping). Written as the first
                message on ``/rig/config`` and into the metadata ``custom_data`` under
                :data:`CONFIG_METADATA_KEY`.
            chunk_size: MCAP chunk size limit [bytes] (>= 1024).
            flush_interval: maximal age of unwritten data [s]: on each write, the pending
                chunk is closed and handed to the OS if the last flush is this long ago
                (``math.inf``: only by size). A writer that may go idle should also call
                :meth:`flush` from a timer.
            fsync: also ``fsync`` at each flush (survives power loss, not only ``kill -9``).
            config_stamp_ns: log time of the ``/rig/config`` message [ns]; by default the log
                time of the first other message written (or 0 for a bag with no messages).

        Raises:
            BagWriteError: the path exists or cannot be created, or an option is invalid.
        """
        if chunk_size < 1024:
            raise BagWriteError(f"chunk_size must be >= 1024 bytes, got {chunk_size}")
        if not flush_interval >= 0.0:
            raise BagWriteError(f"flush_interval must be >= 0 s, got {flush_interval}")
        self.path = Path(path)
        self.flush_interval = float(flush_interval)
        self.fsync = fsync
        self._typestore = make_typestore()
        self._lock = threading.RLock()
        self._connections: dict[tuple[str, str], Connection] = {}
        self._config_text: str | None = None
        if config is not None:
            try:
                self._config_text = json.dumps(dict(config), default=_json_default)
            except (TypeError, ValueError) as err:
                raise BagWriteError(f"config is not JSON serialisable: {err}") from err
        self._config_stamp_ns = (
            None if config_stamp_ns is None else _check_t_ns(config_stamp_ns, "config_stamp_ns")
        )
        try:
            self._writer = _Rosbag2Writer(
                self.path, version=9, storage_plugin=StoragePlugin.MCAP
            )
            self._writer.open()
        except (WriterError, OSError) as err:
            raise BagWriteError(f"cannot create bag {self.path}: {err}") from err
        self._writer.mcap.chunk_size = int(chunk_size)
        self._writer.mcap.flush()  # MCAP magic and header are on disk from the start
        if self._config_text is not None:
            self._writer.set_custom_data(CONFIG_METADATA_KEY, self._config_text)
        self._config_pending = self._config_text is not None
        self._last_flush = time.monotonic()
        self._closed = False
        if self._config_pending and self._config_stamp_ns is not None:
            with self._lock:
                self._write_config(self._config_stamp_ns)

    # ------------------------------------------------------------------ context manager

    def __enter__(self) -> BagRecorder:
        """Return the open recorder."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]:
        """Close the bag (also after an exception, keeping what was written)."""
        self.close()
        return False

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._closed

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        with self._lock:
            counts: dict[str, int] = {}
            for conn in self._writer.connections:
                counts[conn.topic] = counts.get(conn.topic, 0) + self._writer.counts[conn.id]
            return counts

    # ------------------------------------------------------------------------ internals

    def _check_open(self) -> None:
        if self._closed:
            raise BagWriteError(f"bag {self.path} is already closed")

    def _connection(self, topic: str, msgtype: str) -> Connection:
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            if msgtype not in self._typestore.fielddefs:
                raise UnknownMessageTypeError(msgtype)
            conn = self._writer.add_connection(topic, msgtype, typestore=self._typestore)
            self._connections[key] = conn
        return conn

    def _write_config(self, log_time: int) -> None:
        assert self._config_text is not None
        self._config_pending = False
        string_t = self._typestore.types[MSGTYPE_CONFIG]
        data = self._typestore.serialize_cdr(string_t(data=self._config_text), MSGTYPE_CONFIG)
        self._writer.write(self._connection(TOPIC_CONFIG, MSGTYPE_CONFIG), log_time, data)

    def _before_write(self, log_time: int) -> None:
        self._check_open()
        if not 0 <= log_time <= _UINT64_MAX:
            raise BagWriteError(f"log time must be within [0, 2^64) ns, got {log_time}")
        if self._config_pending:
            self._write_config(log_time if self._config_stamp_ns is None else self._config_stamp_ns)

    def _after_write(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval:
            self._writer.mcap.flush(fsync=self.fsync)
            self._last_flush = now

    def _write(self, topic: str, msgtype: str, log_time: int, data: bytes | memoryview) -> None:
        with self._lock:
            self._before_write(log_time)
            self._writer.write(self._connection(topic, msgtype), log_time, data)
            self._after_write()

    def _serialize(self, msgtype: str, msg: object) -> memoryview:
        return self._typestore.serialize_cdr(msg, msgtype)

    def _header(self, stamp_ns: int, frame_id: str) -> object:
        types = self._typestore.types
        sec, nsec = divmod(stamp_ns, _NS_PER_S)
        if not _INT32_MIN <= sec <= _INT32_MAX:
            raise BagWriteError(f"header stamp {stamp_ns} ns is out of the int32 seconds range")
        stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    # ------------------------------------------------------------------------ public API

    def register_type(self, msgtype: str, msgdef_text: str) -> None:
        """Make ``msgtype`` (e.g. 'pkg/msg/Name') writable from its ``.msg`` definition text.

        ``msgdef_text`` may be a plain ``.msg`` file or the concatenated rosbag2/MCAP form
        (``====`` separated ``MSG: pkg/Name`` sections for the dependencies).

        Raises:
            BagWriteError: the definition cannot be parsed or conflicts with a known type.
        """
        with self._lock:
            try:
                self._typestore.register(get_types_from_msg(msgdef_text, msgtype))
            except Exception as err:
                raise BagWriteError(f"cannot register {msgtype!r}: {err}") from err

    def has_type(self, msgtype: str) -> bool:
        """True when ``msgtype`` and every type it uses are known (writable)."""
        with self._lock:
            return not _missing_types(self._typestore, msgtype)

    def ensure_type(self, msgtype: str) -> None:
        """Make ``msgtype`` writable, loading its (and its dependencies') ``.msg`` definitions
        from installed interface packages (see :func:`find_msg_definition`) when needed.

        Raises:
            UnknownMessageTypeError: a needed definition is not installed.
            BagWriteError: a definition cannot be parsed.
        """
        with self._lock:
            for _ in range(1000):  # bound: each pass registers at least one type
                missing = _missing_types(self._typestore, msgtype)
                if not missing:
                    return
                name = missing[0]
                text = find_msg_definition(name)
                if text is None:
                    raise UnknownMessageTypeError(name)
                self.register_type(name, text)
            raise BagWriteError(f"cannot resolve the definition of {msgtype!r}")

    @property
    def config_text(self) -> str | None:
        """The rig configuration (JSON text) of this bag, or None if it has none yet."""
        return self._config_text

    def set_config(
        self, config: Mapping[str, Any] | str, *, config_stamp_ns: int | None = None
    ) -> None:
        """Store the rig configuration after opening (e.g. when it arrives on ``/rig/config``).

        Writes a ``/rig/config`` message and sets the metadata ``custom_data`` entry (the
        latest configuration wins there; :func:`read_config` returns the first message).

        Args:
            config: JSON-serialisable mapping, or JSON text of an object.
            config_stamp_ns: log time of the message [ns]; default: the latest log time
                written so far, or, in an empty bag, that of the next message written.

        Raises:
            BagWriteError: closed recorder, or ``config`` is not a JSON object.
        """
        if isinstance(config, str):
            try:
                parsed = json.loads(config)
            except ValueError as err:
                raise BagWriteError(f"config is not valid JSON: {err}") from err
            if not isinstance(parsed, dict):
                raise BagWriteError("config must be a JSON object")
            text = config
        else:
            try:
                text = json.dumps(dict(config), default=_json_default)
            except (TypeError, ValueError) as err:
                raise BagWriteError(f"config is not JSON serialisable: {err}") from err
        stamp = (
            None if config_stamp_ns is None else _check_t_ns(config_stamp_ns, "config_stamp_ns")
        )
        with self._lock:
            self._check_open()
            self._config_text = text
            self._writer.set_custom_data(CONFIG_METADATA_KEY, text)
            empty = self._writer.min_timestamp == 2**63 - 1
            last = self._writer.max_timestamp
            if stamp is None and empty:  # stamp it like the next message written
                self._config_stamp_ns = None
                self._config_pending = True
                return
            self._config_pending = False
            self._write_config(last if stamp is None else stamp)
            self._after_write()

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        timestamp_ns: int,
        cdr_bytes: bytes | bytearray | memoryview,
    ) -> None:
        """Write one already serialised message (CDR, e.g. from rclpy with ``raw=True``).

        Args:
            topic: topic name; its connection is created on first use.
            msgtype: message type, e.g. 'sensor_msgs/msg/FluidPressure'.
            timestamp_ns: log (receive) time [ns].
            cdr_bytes: the serialised message, CDR with its 4-byte encapsulation header.

        Raises:
            UnknownMessageTypeError: ``msgtype`` is not known (see :meth:`register_type`).
            BagWriteError: closed recorder, bad timestamp or payload.
        """
        log_time = _check_t_ns(timestamp_ns, "timestamp_ns")
        if len(cdr_bytes) < 4:
            raise BagWriteError(f"CDR payload of {len(cdr_bytes)} bytes is too short")
        self._write(topic, msgtype, log_time, bytes(cdr_bytes))

    def write_pressure(
        self,
        t_ns: int,
        p_pa: float,
        *,
        frame_id: str = "tank",
        variance: float = 0.0,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one tank pressure sample on ``/tank/pressure``.

        Args:
            t_ns: sample instant (header stamp) [ns].
            p_pa: pressure [Pa absolute].
            frame_id: header frame id of the sensor.
            variance: pressure variance [Pa^2] (0 = unknown).
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = _check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else _check_t_ns(log_time_ns, "log_time_ns")
        payload = _encode_stamped_pair(stamp, float(p_pa), float(variance), frame_id=frame_id)
        self._write(TOPIC_PRESSURE, MSGTYPE_PRESSURE, log_time, payload)

    def write_pressures(
        self,
        t_ns: npt.ArrayLike,
        p_pa: npt.ArrayLike,
        *,
        frame_id: str = "tank",
        variance: npt.ArrayLike = 0.0,
        log_time_ns: npt.ArrayLike | None = None,
    ) -> None:
        """Write N pressure samples on ``/tank/pressure`` at once (vectorised fast path).

        Args:
            t_ns: sample instants (header stamps) [ns], integer array of shape (N,).
            p_pa: pressures [Pa absolute], shape (N,).
            frame_id: header frame id of the sensor.
            variance: pressure variance [Pa^2], scalar or shape (N,).
            log_time_ns: bag log times [ns], shape (N,); default ``t_ns``.
        """
        self._write_pair_block(
            TOPIC_PRESSURE, MSGTYPE_PRESSURE, t_ns, p_pa, variance, frame_id, log_time_ns
        )

    def write_temperature(
        self,
        t_ns: int,
        temperature_k: float,
        *,
        frame_id: str = "tank",
        variance: float = 0.0,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one gas temperature sample on ``/tank/temperature``.

        Args:
            t_ns: sample instant (header stamp) [ns].
            temperature_k: temperature [K] (stored in the message as degrees C).
            frame_id: header frame id of the sensor.
            variance: temperature variance [K^2] (0 = unknown).
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = _check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else _check_t_ns(log_time_ns, "log_time_ns")
        payload = _encode_stamped_pair(
            stamp, float(temperature_k) - ZERO_CELSIUS, float(variance), frame_id=frame_id
        )
        self._write(TOPIC_TEMPERATURE, MSGTYPE_TEMPERATURE, log_time, payload)

    def write_temperatures(
        self,
        t_ns: npt.ArrayLike,
        temperature_k: npt.ArrayLike,
        *,
        frame_id: str = "tank",
        variance: npt.ArrayLike = 0.0,
        log_time_ns: npt.ArrayLike | None = None,
    ) -> None:
        """Write N temperature samples [K] at instants ``t_ns`` [ns] (vectorised)."""
        celsius = np.asarray(temperature_k, np.float64) - ZERO_CELSIUS
        self._write_pair_block(
            TOPIC_TEMPERATURE, MSGTYPE_TEMPERATURE, t_ns, celsius, variance, frame_id, log_time_ns
        )

    def _write_pair_block(
        self,
        topic: str,
        msgtype: str,
        t_ns: npt.ArrayLike,
        values: npt.ArrayLike,
        variance: npt.ArrayLike,
        frame_id: str,
        log_time_ns: npt.ArrayLike | None,
    ) -> None:
        stamps = np.asarray(t_ns)
        vals = np.asarray(values, np.float64)
        if stamps.ndim != 1 or vals.shape != stamps.shape:
            raise BagWriteError(
                f"t_ns and values must be 1-D of equal length, got {stamps.shape} and {vals.shape}"
            )
        payloads = _encode_stamped_pairs(stamps, vals, variance, frame_id=frame_id)
        logs = stamps if log_time_ns is None else np.asarray(log_time_ns)
        if logs.shape != stamps.shape or not np.issubdtype(logs.dtype, np.integer):
            raise BagWriteError("log_time_ns must be an integer array shaped like t_ns")
        if logs.size == 0:
            return
        if logs.min() < 0:
            raise BagWriteError("log times must be >= 0 ns")
        logs_u = logs.astype(np.uint64)
        with self._lock:
            self._before_write(int(logs.min()))
            self._writer.write_block(self._connection(topic, msgtype), logs_u, payloads)
            self._after_write()

    def write_valve(
        self,
        t_ns: int,
        open: bool,
        opening: float,
        *,
        frame_id: str = "valve",
        log_time_ns: int | None = None,
    ) -> None:
        """Write the discharge valve state on ``/tank/valve``.

        Args:
            t_ns: instant of the state (header stamp) [ns].
            open: True when the valve is commanded open.
            opening: effective opening fraction of the valve area [-], in [0, 1].
            frame_id: header frame id.
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = _check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else _check_t_ns(log_time_ns, "log_time_ns")
        msg = self._typestore.types[MSGTYPE_VALVE](
            header=self._header(stamp, frame_id), open=bool(open), opening=float(opening)
        )
        self._write(TOPIC_VALVE, MSGTYPE_VALVE, log_time, self._serialize(MSGTYPE_VALVE, msg))

    def write_estimate(
        self,
        t_ns: int,
        fields: Mapping[str, Any],
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one sonic-conductance estimate on ``/estimator/estimate``.

        Args:
            t_ns: log time [ns] (and the header stamp unless ``header_stamp_ns`` is given).
            fields: UnloadEstimate field values by name (SI units: conductances in
                m^3/(s Pa), pressures in Pa absolute, tau_exp in s, initial_temperature in K,
                volume in m^3), plus ``header_stamp_ns`` [ns], ``frame_id`` and
                ``unload_start_ns`` [ns] for the two time fields. Missing float64 fields are
                written as NaN ("not known"), missing integers as 0, strings as ''.
            log_time_ns: bag log time [ns]; default ``t_ns``.

        Raises:
            BagWriteError: unknown field names or values of the wrong kind.
        """
        stamp = _check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else _check_t_ns(log_time_ns, "log_time_ns")
        store = self._typestore
        names = _field_names(store, MSGTYPE_ESTIMATE)
        allowed = {"header_stamp_ns", "frame_id", "unload_start_ns"}
        allowed |= set(names) - {"header", "unload_start"}
        if unknown := sorted(set(fields) - allowed):
            raise BagWriteError(
                f"unknown UnloadEstimate fields {unknown}; valid keys: {sorted(allowed)}"
            )
        values: dict[str, Any] = {}
        try:
            for name, (_, (_kind, spec)) in zip(
                names, store.fielddefs[MSGTYPE_ESTIMATE][1], strict=True
            ):
                if name == "header":
                    header_ns = _check_t_ns(fields.get("header_stamp_ns", stamp), "header_stamp_ns")
                    values[name] = self._header(header_ns, str(fields.get("frame_id", "")))
                elif name == "unload_start":
                    start_ns = _check_t_ns(fields.get("unload_start_ns", 0), "unload_start_ns")
                    sec, nsec = divmod(start_ns, _NS_PER_S)
                    values[name] = store.types["builtin_interfaces/msg/Time"](
                        sec=sec, nanosec=nsec
                    )
                else:
                    base = spec[0] if isinstance(spec, tuple) else spec
                    if base in ("float64", "float32"):
                        values[name] = float(fields.get(name, math.nan))
                    elif base == "string":
                        values[name] = str(fields.get(name, ""))
                    elif base == "bool":
                        values[name] = bool(fields.get(name, False))
                    else:
                        values[name] = operator.index(fields.get(name, 0))
            msg = store.types[MSGTYPE_ESTIMATE](**values)
            data = self._serialize(MSGTYPE_ESTIMATE, msg)
        except (TypeError, ValueError, OverflowError, struct.error) as err:
            raise BagWriteError(f"invalid UnloadEstimate value: {err}") from err
        self._write(TOPIC_ESTIMATE, MSGTYPE_ESTIMATE, log_time, data)

    def flush(self) -> None:
        """Write the pending chunk now (a live node may call this from an idle timer)."""
        with self._lock:
            self._check_open()
            self._writer.mcap.flush(fsync=self.fsync)
            self._last_flush = time.monotonic()

    def close(self) -> None:
        """Complete the bag: last chunk, MCAP summary and footer, ``metadata.yaml``.

        Idempotent.
        """
        with self._lock:
            if self._closed:
                return
            try:
                if self._config_pending:
                    first = self._writer.min_timestamp
                    self._write_config(
                        self._config_stamp_ns
                        if self._config_stamp_ns is not None
                        else (first if first < 2**63 - 1 else 0)
                    )
                self._writer.close()
            except (WriterError, OSError) as err:
                raise BagWriteError(f"cannot close bag {self.path}: {err}") from err
            finally:
                self._closed = True


# ----------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class _Source:
    """A bag resolved on disk."""

    path: Path  # as given by the caller
    reader_path: Path  # what rosbags' Reader opens (directory or single file)
    mcap_files: tuple[Path, ...]  # MCAP files for the numpy fast path (may be empty)
    custom_data: dict[str, str]


def _resolve(path: str | os.PathLike[str]) -> _Source:
    """Check ``path`` (bag directory or single ``.mcap``) and list its storage files."""
    bag = Path(path)
    if not bag.exists():
        raise BagNotFoundError(f"bag {bag} does not exist")
    if bag.is_file():
        if bag.suffix == ".mcap":
            return _Source(bag, bag, (bag,), {})
        if bag.suffix == ".db3":
            return _Source(bag, bag, (), {})
        raise BagFormatError(f"{bag} is neither a rosbag2 directory nor an .mcap file")
    meta_path = bag / "metadata.yaml"
    if not meta_path.is_file():
        if any(bag.glob("*.mcap")):
            raise BagFormatError(
                f"bag {bag} has no metadata.yaml: its writer was probably killed before "
                f"closing it; {RECOVER_HINT}"
            )
        raise BagFormatError(f"{bag} is not a rosbag2 bag directory (no metadata.yaml)")
    try:
        info = yaml.safe_load(meta_path.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        files = [bag / PurePath(x).name for x in info["relative_file_paths"]]
        compression = str(info.get("compression_mode") or "").lower()
        custom = {str(k): str(v) for k, v in (info.get("custom_data") or {}).items()}
    except Exception as err:
        raise BagFormatError(f"bag {bag} has an unreadable metadata.yaml: {err}") from err
    fast = () if compression not in ("", "none") else tuple(f for f in files if f.suffix == ".mcap")
    return _Source(bag, bag, fast, custom)


@contextlib.contextmanager
def _open_reader(src: _Source) -> Iterator[Reader]:
    """rosbags' Reader on ``src``; every library error becomes a :class:`BagFormatError`."""
    try:
        reader = Reader(src.reader_path)
        reader.open()
    except BagError:
        raise
    except Exception as err:
        raise BagFormatError(
            f"cannot read bag {src.path}: {err}. If its writer did not finish, {RECOVER_HINT}"
        ) from err
    try:
        yield reader
    except BagError:
        raise
    except Exception as err:
        raise BagFormatError(f"cannot read bag {src.path}: {err}") from err
    finally:
        with contextlib.suppress(Exception):
            reader.close()


def _topic_connections(reader: Reader, src: _Source, topic: str, msgtype: str) -> list[Connection]:
    """Connections of ``topic``; checks the topic exists and carries ``msgtype``."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise TopicNotFoundError(topic, sorted({c.topic for c in reader.connections}), src.path)
    found = sorted({c.msgtype for c in conns})
    if found != [msgtype]:
        raise WrongMessageTypeError(topic, msgtype, found, src.path)
    return conns


def _bag_typestore(connections: list[Connection]) -> Typestore:
    """Typestore with the bag's own embedded definitions (fallback: the package types)."""
    base = make_typestore()
    store = get_typestore(Stores.EMPTY)
    for conn in connections:
        if conn.msgdef.format != MessageDefinitionFormat.MSG or not conn.msgdef.data:
            continue
        with contextlib.suppress(Exception):
            store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
    missing = {c.msgtype for c in connections} - set(store.fielddefs)
    if missing:
        return base
    return store


def _decompressor(compression: str) -> Callable[[bytes, int], bytes]:
    if compression == "":
        return lambda data, _size: data
    if compression == "zstd":
        import zstandard

        return lambda data, size: zstandard.ZstdDecompressor().decompress(data, size)
    if compression == "lz4":
        import lz4.frame

        return lambda data, _size: lz4.frame.decompress(data)
    raise _NotFastDecodable


def _fast_raw_pairs(
    mcap_file: Path, topic: str, msgtype: str
) -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.int64], npt.NDArray[np.float64],
           npt.NDArray[np.float64]]:
    """Log times and decoded fields of one topic of an indexed MCAP file (numpy, no per-message
    Python work): uses the summary's chunk indexes and the per-chunk message indexes.
    """
    from mcap.reader import make_reader

    logs, stamps, avals, bvals = [], [], [], []
    with mcap_file.open("rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception as err:
            raise _NotFastDecodable from err
        if summary is None or summary.statistics is None or not summary.chunk_indexes:
            raise _NotFastDecodable
        cids = {
            cid
            for cid, ch in summary.channels.items()
            if ch.topic == topic
            and ch.message_encoding == "cdr"
            and ch.schema_id in summary.schemas
            and summary.schemas[ch.schema_id].name == msgtype
        }
        expected = sum(summary.statistics.channel_message_counts.get(c, 0) for c in cids)
        for index in summary.chunk_indexes:
            wanted = [c for c in index.message_index_offsets if c in cids]
            if not wanted:
                continue
            f.seek(index.chunk_start_offset)
            blob = f.read(index.chunk_length + index.message_index_length)
            op, _length = _RECORD_HEAD.unpack_from(blob, 0)
            if op != _OP_CHUNK:
                raise _NotFastDecodable
            _start, _end, usize, _crc, clen = struct.unpack_from("<QQQII", blob, 9)
            compression = blob[41 : 41 + clen].decode()
            (dsize,) = struct.unpack_from("<Q", blob, 41 + clen)
            dstart = 49 + clen
            raw = blob[dstart : dstart + dsize]
            records = _decompressor(compression)(raw, usize)
            if len(records) != usize:
                raise _NotFastDecodable
            buf = np.frombuffer(records, np.uint8)
            for cid in wanted:
                mpos = index.message_index_offsets[cid] - index.chunk_start_offset
                op, _length = _RECORD_HEAD.unpack_from(blob, mpos)
                mcid, nbytes = struct.unpack_from("<HI", blob, mpos + 9)
                if op != _OP_MESSAGE_INDEX or mcid != cid:
                    raise _NotFastDecodable
                entries = np.frombuffer(blob, "<u8", count=nbytes // 8, offset=mpos + 15)
                log_t = entries[0::2]
                off = entries[1::2].astype(np.int64)
                if off.size and (off.max() + _MSG_HEAD_SIZE > buf.size):
                    raise _NotFastDecodable
                if np.any(buf[off] != _OP_MESSAGE) or np.any(_gather(buf, off + 9, "<u2") != cid):
                    raise _NotFastDecodable
                lengths = _gather(buf, off + 1, "<u8").astype(np.int64) - 22
                t, a, b = _decode_stamped_pairs(buf, off + _MSG_HEAD_SIZE, lengths)
                logs.append(log_t.astype(np.uint64))
                stamps.append(t)
                avals.append(a)
                bvals.append(b)
    if sum(x.size for x in logs) != expected:
        raise _NotFastDecodable  # message indexes incomplete: let the generic path read it
    if not logs:
        return (np.empty(0, np.uint64), np.empty(0, np.int64), np.empty(0), np.empty(0))
    return (
        np.concatenate(logs),
        np.concatenate(stamps),
        np.concatenate(avals),
        np.concatenate(bvals),
    )


def _slow_raw_pairs(
    reader: Reader, conns: list[Connection], msgtype: str
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Header stamps and the two float fields via rosbags' raw reader + numpy decoding."""
    datas = [data for _, _, data in reader.messages(connections=conns)]
    if not datas:
        return np.empty(0, np.int64), np.empty(0), np.empty(0)
    lengths = np.fromiter((len(d) for d in datas), np.int64, len(datas))
    starts = np.zeros(len(datas), np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    buf = np.frombuffer(b"".join(datas), np.uint8)
    try:
        return _decode_stamped_pairs(buf, starts, lengths)
    except _NotFastDecodable:
        store = _bag_typestore(conns)
        msgs = [store.deserialize_cdr(d, msgtype) for d in datas]
        t = np.array([m.header.stamp.sec * _NS_PER_S + m.header.stamp.nanosec for m in msgs])
        first = _field_names(store, msgtype)[1]
        a = np.array([getattr(m, first) for m in msgs], np.float64)
        b = np.array([m.variance for m in msgs], np.float64)
        return t.astype(np.int64), a, b


def _read_stamped_pairs(
    path: str | os.PathLike[str], topic: str, msgtype: str, *, fast: bool = True
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(header stamps [ns], first float field, variance) of a FluidPressure/Temperature topic,
    in log-time order. ``fast=False`` forces the generic (rosbags raw reader) path.
    """
    src = _resolve(path)
    with _open_reader(src) as reader:
        conns = _topic_connections(reader, src, topic, msgtype)
        if fast and src.mcap_files:
            try:
                parts = [_fast_raw_pairs(f, topic, msgtype) for f in src.mcap_files]
            except _NotFastDecodable:
                parts = []
            else:
                logs = np.concatenate([p[0] for p in parts])
                order = np.argsort(logs, kind="stable")
                t = np.concatenate([p[1] for p in parts])[order]
                a = np.concatenate([p[2] for p in parts])[order]
                b = np.concatenate([p[3] for p in parts])[order]
                return t, a, b
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
    path: str | os.PathLike[str], *, topic: str = TOPIC_PRESSURE
) -> PressureSeries:
    """Read all pressure samples of a bag (numpy bulk decoding of FluidPressure).

    Args:
        path: bag directory or single ``.mcap`` file.
        topic: pressure topic (sensor_msgs/msg/FluidPressure).

    Returns:
        ``(t_ns, p)``: header stamps [ns] (int64) and pressures [Pa absolute] (float64), in
        log-time order.

    Raises:
        BagNotFoundError, BagFormatError, TopicNotFoundError, WrongMessageTypeError.
    """
    t, p, _ = _read_stamped_pairs(path, topic, MSGTYPE_PRESSURE)
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
    t, celsius, _ = _read_stamped_pairs(path, topic, MSGTYPE_TEMPERATURE)
    return TemperatureSeries(t, celsius + ZERO_CELSIUS)


def _deserialized(
    path: str | os.PathLike[str], topic: str, msgtype: str, *, required: bool = True
) -> Iterator[tuple[int, Any, list[str]]]:
    """(log time [ns], message, field names) of ``topic``, decoded with the bag's own
    definitions.
    """
    src = _resolve(path)
    with _open_reader(src) as reader:
        try:
            conns = _topic_connections(reader, src, topic, msgtype)
        except TopicNotFoundError:
            if required:
                raise
            return
        store = _bag_typestore(conns)
        names = _field_names(store, msgtype)
        for _, log_time, data in reader.messages(connections=conns):
            yield log_time, store.deserialize_cdr(data, msgtype), names


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * _NS_PER_S + int(stamp.nanosec)


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
    """The rig configuration of a bag: first ``/rig/config`` message, else metadata custom_data.

    Returns:
        The configuration dict (SI units as stored), or None if the bag has none.

    Raises:
        BagFormatError: the stored configuration is not a JSON object.
    """
    src = _resolve(path)
    text: str | None = None
    for _, msg, _ in _deserialized(path, TOPIC_CONFIG, MSGTYPE_CONFIG, required=False):
        text = msg.data
        break
    if text is None:
        text = src.custom_data.get(CONFIG_METADATA_KEY)
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


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag."""

    msgtype: str  #: message type (several joined by ', ' if the topic mixes types)
    count: int  #: number of messages


@dataclass(frozen=True)
class BagSummary:
    """Overview of a bag: topics, counts and time span."""

    path: Path
    topics: dict[str, TopicSummary]
    message_count: int
    start_ns: int | None  #: log time of the first message [ns]
    end_ns: int | None  #: log time of the last message [ns]
    duration: float  #: end - start [s]
    custom_data: dict[str, str]

    def __str__(self) -> str:
        """Human-readable multi-line summary."""
        lines = [f"bag {self.path}: {self.message_count} messages, {self.duration:.3f} s"]
        width = max((len(t) for t in self.topics), default=0)
        for name, info in sorted(self.topics.items()):
            lines.append(f"  {name:<{width}}  {info.count:>9}  {info.msgtype}")
        return "\n".join(lines)


def bag_summary(path: str | os.PathLike[str]) -> BagSummary:
    """Topics, message types, counts and duration [s] of a bag (directory or ``.mcap``)."""
    src = _resolve(path)
    with _open_reader(src) as reader:
        topics: dict[str, TopicSummary] = {}
        for name, info in reader.topics.items():
            types = sorted({c.msgtype for c in info.connections})
            topics[name] = TopicSummary(", ".join(types), int(info.msgcount))
        count = int(reader.message_count)
        start = int(reader.start_time) if count else None
        end = int(reader.end_time) - 1 if count else None
    duration = (end - start) / _NS_PER_S if start is not None and end is not None else 0.0
    return BagSummary(src.path, topics, count, start, end, duration, dict(src.custom_data))


class RawMessage(NamedTuple):
    """One serialised message of a bag, as :func:`read_raw_messages` yields it."""

    topic: str
    msgtype: str  #: e.g. 'sensor_msgs/msg/FluidPressure'
    log_time_ns: int  #: bag log time [ns]
    data: bytes  #: the CDR payload with its 4-byte encapsulation header


def _raw_messages(src: _Source, topics: frozenset[str] | None) -> Iterator[RawMessage]:
    with _open_reader(src) as reader:
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
    src = _resolve(path)
    wanted = None if topics is None else frozenset(topics)
    with _open_reader(src) as reader:
        have = sorted({c.topic for c in reader.connections})
    for topic in sorted(wanted or ()):
        if topic not in have:
            raise TopicNotFoundError(topic, have, src.path)
    return _raw_messages(src, wanted)


# ---------------------------------------------------------------------------- recovery


@dataclass(frozen=True)
class RecoverReport:
    """Outcome of :func:`recover`."""

    path: Path  #: the bag directory
    messages: dict[str, int]  #: messages in the repaired bag per topic
    already_complete: bool  #: the bag was readable: nothing was changed
    #: size of the torn tail after the last complete MCAP record [bytes] (complete messages
    #: inside a torn uncompressed chunk are still recovered)
    dropped_bytes: int
    skipped_messages: int  #: intact messages dropped (channel or schema record lost)
    kept_originals: tuple[Path, ...]  #: where the original files were moved

    @property
    def total(self) -> int:
        """Messages in the repaired bag."""
        return sum(self.messages.values())

    def __str__(self) -> str:
        """Human-readable report."""
        if self.already_complete:
            head = f"bag {self.path} is complete; nothing to recover ({self.total} messages)"
        else:
            head = f"recovered bag {self.path}: {self.total} messages"
            if self.dropped_bytes:
                head += (
                    f" (torn tail of {self.dropped_bytes} bytes after the last complete "
                    "record; its intact messages were kept)"
                )
        lines = [head] + [f"  {t}: {n}" for t, n in sorted(self.messages.items())]
        if self.skipped_messages:
            lines.append(f"  skipped {self.skipped_messages} messages without channel/schema")
        if self.kept_originals:
            lines.append("  originals kept as: " + ", ".join(str(p) for p in self.kept_originals))
        return "\n".join(lines)


def _salvage_torn_chunk(tail: bytes) -> list[Any]:
    """Intact Schema/Channel/Message records at the start of a torn uncompressed chunk.

    ``tail`` holds the file bytes after the last complete record. A kill during a chunk
    write leaves a prefix of the chunk; its complete inner records are still good.
    """
    out: list[Any] = []
    if len(tail) < 41 or tail[0] != _OP_CHUNK:
        return out
    (clen,) = struct.unpack_from("<I", tail, 37)
    if clen != 0:  # compressed: a prefix cannot be decompressed
        return out
    data = tail[49:]
    pos = 0
    while pos + 9 <= len(data):
        op, length = _RECORD_HEAD.unpack_from(data, pos)
        end = pos + 9 + length
        if end > len(data):
            break
        body = data[pos + 9 : end]
        try:
            if op == _OP_MESSAGE and length >= 22:
                cid, seq, log_time, pub_time = struct.unpack_from("<HIQQ", body, 0)
                out.append(
                    McapMessage(
                        channel_id=cid,
                        sequence=seq,
                        log_time=log_time,
                        publish_time=pub_time,
                        data=body[22:],
                    )
                )
            elif op in (0x03, 0x04):  # schema, channel
                sub = McapChunk(
                    compression="",
                    data=data[pos:end],
                    message_end_time=0,
                    message_start_time=0,
                    uncompressed_crc=0,
                    uncompressed_size=end - pos,
                )
                out.extend(breakup_chunk(sub))
        except Exception:
            break
        pos = end
    return out


def _expand_record(record: Any) -> list[Any]:
    """Schema/Channel/Message records of one complete stream record (chunks CRC-checked)."""
    if isinstance(record, McapChunk):
        try:
            return list(breakup_chunk(record, validate_crc=True))
        except Exception:
            return []  # corrupt chunk: skip it
    if isinstance(record, McapSchema | McapChannel | McapMessage):
        return [record]
    return []


def _mcap_records(mcap_file: Path) -> tuple[Iterator[Any], Callable[[], int]]:
    """Intact inner records of a possibly truncated MCAP file, and a function giving the size
    of the torn tail [bytes] (after the last complete record) once the iterator is exhausted.

    mcap's stream reader yields only records whose full declared length was read, so every
    record it yields is complete; the torn tail ends the iteration with an exception.
    """
    size = mcap_file.stat().st_size
    state = {"good_end": 0}

    def gen() -> Iterator[Any]:
        with mcap_file.open("rb") as f:
            if f.read(8) != _MCAP_MAGIC:
                raise BagFormatError(f"{mcap_file} is not an MCAP file (bad magic)")
            f.seek(0)
            state["good_end"] = 8
            reader = StreamReader(f, emit_chunks=True, record_size_limit=1 << 32)
            try:
                for record in reader.records:
                    end = f.tell()
                    yield from _expand_record(record)
                    state["good_end"] = end
            except Exception:  # torn tail: EndOfFile, struct.error, ... from the library
                f.seek(state["good_end"])
                yield from _salvage_torn_chunk(f.read())
                return
            state["good_end"] = size

    return gen(), lambda: max(0, size - state["good_end"])


def _rihs01(msgtype: str, msgdef: str, fallback: Typestore) -> str:
    """RIHS01 type hash of ``msgtype`` from its embedded definition (or the package store)."""
    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(msgdef, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception:
        try:
            return fallback.hash_rihs01(msgtype)
        except Exception:
            return _PLACEHOLDER_RIHS01


def _bag_is_readable(bag: Path) -> dict[str, int] | None:
    """Messages per topic if rosbags can open the bag, else None."""
    if not (bag / "metadata.yaml").is_file():
        return None
    try:
        summary = bag_summary(bag)
    except BagError:
        return None
    return {name: info.count for name, info in summary.topics.items()}


def recover(path: str | os.PathLike[str], *, keep_original: bool = True) -> RecoverReport:
    """Repair a bag directory whose writer was killed (``kill -9``, power loss).

    Reads the intact records of its ``.mcap`` file(s) with mcap's stream reader (the torn
    tail and chunks failing their CRC are dropped; the intact start of a torn uncompressed
    chunk is kept), writes a complete MCAP file with summary and footer plus
    ``metadata.yaml`` (with the rig configuration in custom_data if the bag has a
    ``/rig/config`` message), and replaces the old files. A bag that already opens is left
    unchanged. Do not run it on a bag that a live process is still writing.

    Args:
        path: the bag directory (or an ``.mcap`` file in it).
        keep_original: keep the old files as ``<name>.truncated`` (otherwise delete them).

    Returns:
        A report with the messages recovered per topic.

    Raises:
        BagNotFoundError: no such directory.
        BagFormatError: no MCAP file, or not an MCAP file.
    """
    bag = Path(path)
    if not bag.exists():
        raise BagNotFoundError(f"bag {bag} does not exist")
    if bag.is_file():
        bag = bag.parent
    if (counts := _bag_is_readable(bag)) is not None:
        return RecoverReport(bag, counts, True, 0, 0, ())
    mcaps = sorted(bag.glob("*.mcap"))
    if not mcaps:
        raise BagFormatError(f"{bag} holds no .mcap file to recover")

    tmp_root = bag / ".recover-tmp"
    if tmp_root.exists():
        shutil.rmtree(tmp_root)
    tmp_root.mkdir()
    fallback = make_typestore()
    dropped = 0
    skipped = 0
    try:
        writer = _Rosbag2Writer(tmp_root / bag.name, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        by_key: dict[tuple[str, str, str], Connection] = {}
        config_text: str | None = None
        try:
            for mcap_file in mcaps:
                records, tail = _mcap_records(mcap_file)
                schemas: dict[int, McapSchema] = {}
                channels: dict[int, Connection] = {}
                for rec in records:
                    if isinstance(rec, McapSchema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, McapChannel):
                        schema = schemas.get(rec.schema_id)
                        if schema is None:
                            continue
                        msgdef = schema.data.decode("utf-8", errors="replace")
                        key = (rec.topic, schema.name, rec.message_encoding)
                        conn = by_key.get(key)
                        if conn is None:
                            qos: Any = ()
                            with contextlib.suppress(Exception):
                                qos = parse_qos(rec.metadata.get("offered_qos_profiles", "[]"))
                            conn = writer.add_connection(
                                rec.topic,
                                schema.name,
                                msgdef=msgdef,
                                rihs01=_rihs01(schema.name, msgdef, fallback),
                                serialization_format=rec.message_encoding,
                                offered_qos_profiles=qos or (),
                            )
                            by_key[key] = conn
                        channels[rec.id] = conn
                    elif isinstance(rec, McapMessage):
                        conn = channels.get(rec.channel_id)
                        if conn is None:
                            skipped += 1
                            continue
                        writer.write(conn, rec.log_time, rec.data)
                        if config_text is None and conn.topic == TOPIC_CONFIG:
                            with contextlib.suppress(Exception):
                                msg = fallback.deserialize_cdr(rec.data, MSGTYPE_CONFIG)
                                config_text = msg.data
                dropped += tail()
            if config_text is not None:
                writer.set_custom_data(CONFIG_METADATA_KEY, config_text)
            writer.close()
        except BaseException:
            with contextlib.suppress(Exception):
                writer.abort()
            raise

        kept: list[Path] = []
        for old in [*mcaps, bag / "metadata.yaml"]:
            if not old.exists():
                continue
            if keep_original:
                target = old.with_name(old.name + ".truncated")
                n = 1
                while target.exists():
                    target = old.with_name(f"{old.name}.truncated.{n}")
                    n += 1
                old.rename(target)
                kept.append(target)
            else:
                old.unlink()
        new_dir = tmp_root / bag.name
        (new_dir / f"{bag.name}.mcap").rename(bag / f"{bag.name}.mcap")
        (new_dir / "metadata.yaml").rename(bag / "metadata.yaml")
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)

    counts = _bag_is_readable(bag)
    if counts is None:  # pragma: no cover - would be a bug in the writer above
        raise BagFormatError(f"recovered bag {bag} does not open")
    return RecoverReport(bag, counts, False, dropped, skipped, tuple(kept))


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
