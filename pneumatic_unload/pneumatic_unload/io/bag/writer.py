"""rosbag2 writing with MCAP storage: rosbags' writer with chunks closed by size or on
demand (flush), CRC-checked, each followed by its message indexes, and a vectorised block
write for N equal-size messages.

This is the only module of the package that subclasses rosbags classes or uses rosbags
internals (``rosbags.rosbag2.storage_mcap.McapWriter`` and ``PendingChunk``,
``Writer.STORAGE_PLUGINS`` and the writer's message counters and time span,
``rosbags.rosbag2.metadata.parse_qos``); the other modules reach them through
:class:`Rosbag2Writer` and :func:`parse_offered_qos` and otherwise use rosbags' public API.
"""

from __future__ import annotations

import array
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Mapping
from io import BytesIO
from pathlib import Path
from typing import Any, ClassVar, Final

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk

from .errors import BagWriteError
from .records import MSG_HEAD, OP_CHUNK, OP_MESSAGE, OP_MESSAGE_INDEX, RECORD_HEAD

__all__ = [
    "DEFAULT_CHUNK_SIZE",
    "FlushingMcapWriter",
    "Rosbag2Writer",
    "parse_offered_qos",
]


#: Default MCAP chunk size [bytes] (as rosbags): time-based flushing bounds the loss first.
DEFAULT_CHUNK_SIZE: Final = 1 << 20


class FlushingMcapWriter(McapWriter):
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
        bio.write(MSG_HEAD.pack(OP_MESSAGE, 22 + len(data), cid, 0, timestamp, timestamp))
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
            recs["op"] = OP_MESSAGE
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
        out.write(RECORD_HEAD.pack(OP_CHUNK, len(head) + len(compressed)))
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
            out.write(RECORD_HEAD.pack(OP_MESSAGE_INDEX, len(body)))
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


#: The ROS distribution a bag's metadata.yaml names (rosbag2 writes the distribution it
#: was built for; rosbags writes 'rosbags').
ROS_DISTRO = "jazzy"
#: The offered QoS of a latched topic as rosbag2 records it (reliable, transient local,
#: keep last 10: nodes/common.py's LATCHED_QOS): ``ros2 bag play`` republishes the topic
#: latched, so a late subscriber still gets the rig's configuration and the estimate.
LATCHED_QOS_PROFILE: Final = {
    "history": 1, "depth": 10, "reliability": 1, "durability": 1,
    "deadline": {"sec": 0, "nsec": 0}, "lifespan": {"sec": 0, "nsec": 0},
    "liveliness": 1, "liveliness_lease_duration": {"sec": 0, "nsec": 0},
    "avoid_ros_namespace_conventions": False,
}


def latched_qos() -> Any:
    """rosbags' QoS profiles of a latched topic (:data:`LATCHED_QOS_PROFILE`), for
    ``Writer.add_connection(offered_qos_profiles=...)``."""
    return parse_qos([dict(LATCHED_QOS_PROFILE)])


class Rosbag2Writer(Writer):
    """rosbags' rosbag2 writer using :class:`FlushingMcapWriter` for MCAP storage; its
    metadata.yaml names :data:`ROS_DISTRO`, as rosbag2's does."""

    def close(self) -> None:
        """Close the storage and write metadata.yaml (``ros_distro``: :data:`ROS_DISTRO`)."""
        super().close()
        meta = Path(self.path) / "metadata.yaml"
        if meta.is_file():
            text = meta.read_text(encoding="utf-8")
            fixed = text.replace("ros_distro: rosbags\n", f"ros_distro: {ROS_DISTRO}\n", 1)
            if fixed != text:
                meta.write_text(fixed, encoding="utf-8")

    STORAGE_PLUGINS: ClassVar[Mapping[StoragePlugin, Any]] = {
        **Writer.STORAGE_PLUGINS,
        StoragePlugin.MCAP: FlushingMcapWriter,
    }

    @property
    def mcap(self) -> FlushingMcapWriter:
        """The open MCAP storage writer."""
        storage = self.storage
        if not isinstance(storage, FlushingMcapWriter):
            raise BagWriteError(f"bag {self.path} is not open")
        return storage

    @property
    def topic_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        counts: dict[str, int] = {}
        for conn in self.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + self.counts[conn.id]
        return counts

    @property
    def is_empty(self) -> bool:
        """True while no message has been written (rosbags' time span is still unset)."""
        return self.min_timestamp == 2**63 - 1

    @property
    def first_log_time(self) -> int:
        """Smallest log time written so far [ns] (2^63 - 1 while :attr:`is_empty`)."""
        return self.min_timestamp

    @property
    def last_log_time(self) -> int:
        """Largest log time written so far [ns] (0 while :attr:`is_empty`)."""
        return self.max_timestamp

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


def parse_offered_qos(text: str) -> Any:
    """rosbags' QoS profiles from an ``offered_qos_profiles`` text (rosbag2 YAML), e.g. of an
    MCAP channel's metadata, for ``Writer.add_connection``.

    Raises:
        Exception: whatever rosbags raises for text it cannot parse.
    """
    return parse_qos(text)
