# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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
import contextlib
import errno
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, ClassVar, Final

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk

from .errors import DISK_FULL_ERRNOS, BagDiskFullError, BagWriteError
from .records import MSG_HEAD, OP_CHUNK, OP_MESSAGE, OP_MESSAGE_INDEX, RECORD_HEAD

__all__ = [
    "DEFAULT_CHUNK_SIZE",
    "FlushingMcapWriter",
    "Rosbag2Writer",
    "parse_offered_qos",
]


#: Default MCAP chunk size [bytes] (as rosbags): time-based flushing bounds the loss first.
DEFAULT_CHUNK_SIZE: Final = 1 << 20


@dataclass
class Synced:
    """What an MCAP writer had handed to the operating system at its last flush: the file's
    length [bytes], its chunks, per-channel message counts and time span [ns]; and the
    rosbag2 writer's message counts and time span [ns] then (a bag cut back there, after
    a write that failed, is consistent: :meth:`Rosbag2Writer.rewind`)."""

    end: int
    chunks: int
    channel_stats: dict[int, int] = field(default_factory=dict)
    message_start_time: int = 2**63 - 1
    message_end_time: int = 0
    counts: dict[int, int] = field(default_factory=dict)
    min_timestamp: int = 2**63 - 1
    max_timestamp: int = 0


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
        #: The state at the last flush that reached the operating system (None: none yet).
        self.synced: Synced | None = None

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
        self.synced = Synced(self.bio.tell(), len(self.chunks), dict(self.channel_stats),
                             self.message_start_time, self.message_end_time)

    def rewind(self) -> None:
        """Cut the file back to its last flush (:attr:`synced`) after a write that failed
        (a full disk: the buffered rest may be torn): the chunks, counts and time span
        since are dropped, the pending chunk too, and the file is reopened at that length
        (the old file object's unwritten buffer is discarded, never written later)."""
        synced = self.synced
        if synced is None:
            raise BagWriteError(f"{self.path}: nothing was written before the failure")
        new = self.path.open("r+b")  # opened before the old one is closed: another fd
        old = self.bio
        with contextlib.suppress(OSError, ValueError):
            os.close(old.fileno())
        with contextlib.suppress(OSError, ValueError):
            old.close()  # its flush fails on the closed descriptor: the buffer is dropped
        new.truncate(synced.end)
        new.seek(synced.end)
        self.bio = new
        del self.chunks[synced.chunks:]
        self.channel_stats = {cid: synced.channel_stats.get(cid, 0)
                              for cid in self.channel_stats}
        self.message_start_time = synced.message_start_time
        self.message_end_time = synced.message_end_time
        self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
        self._index = {}

    def close_data_only(self) -> None:
        """Close the file as it is, without a summary (its data section is what a reader
        recovers: ``pneumatic-unload recover``)."""
        self.bio.close()


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
    """rosbags' rosbag2 writer using :class:`FlushingMcapWriter` for MCAP storage; a write
    or flush that runs out of room (:data:`~.errors.DISK_FULL_ERRNOS`) stops it: that one
    and every later one raise :class:`~.errors.BagDiskFullError` (:attr:`full` says why),
    and :meth:`close_cut_back` completes the bag with what reached the disk; its
    metadata.yaml names :data:`ROS_DISTRO`, as rosbag2's does."""

    #: Why the bag stopped growing (a full disk, quota or file-size limit), or None.
    full: str | None = None

    @contextlib.contextmanager
    def _room(self) -> Iterator[None]:
        """Run a write; one that runs out of room stops the bag (see the class doc)."""
        if self.full is not None:
            raise BagDiskFullError(self.full)
        try:
            yield
        except OSError as err:
            if err.errno not in DISK_FULL_ERRNOS:
                raise
            code = errno.errorcode.get(err.errno or 0, str(err.errno))
            self.full = (f"bag {self.path}: {err.strerror or err} (errno {code}): no more "
                         "room, recording stopped")
            raise BagDiskFullError(self.full) from None

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview
              ) -> None:
        """rosbags' write, stopped by a full disk (:meth:`_room`)."""
        with self._room():
            super().write(connection, timestamp, data)

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

    def sync(self, *, fsync: bool = False) -> None:
        """Flush the MCAP file (:meth:`FlushingMcapWriter.flush`) and note the message
        counts and time span it holds then (:meth:`rewind` goes back there)."""
        mcap = self.mcap
        with self._room():
            mcap.flush(fsync=fsync)
        assert mcap.synced is not None
        mcap.synced.counts = dict(self.counts)
        mcap.synced.min_timestamp = self.min_timestamp
        mcap.synced.max_timestamp = self.max_timestamp

    def rewind(self) -> None:
        """Back to the last :meth:`sync` after a write that failed: the file cut there
        (:meth:`FlushingMcapWriter.rewind`), the counts and time span of the metadata
        too, so that a bag closed now is consistent."""
        mcap = self.mcap
        mcap.rewind()
        synced = mcap.synced
        assert synced is not None
        self.counts = {cid: synced.counts.get(cid, 0) for cid in self.counts}
        self.min_timestamp, self.max_timestamp = synced.min_timestamp, synced.max_timestamp

    def close_cut_back(self) -> bool:
        """Close after a write that ran out of room: cut back to the last :meth:`sync`,
        then the MCAP summary and ``metadata.yaml``; when the summary does not fit either,
        cut back again and write ``metadata.yaml`` alone (the data section then is what
        ``pneumatic-unload recover`` reads). Returns whether the summary was written."""
        self.rewind()
        try:
            self.close()
            return True
        except (WriterError, OSError):
            self.rewind()
        self.close_without_summary()
        return False

    def close_without_summary(self) -> None:
        """Write ``metadata.yaml`` and close the MCAP file without its summary (a disk
        with no room for it): the bag's data section and metadata are complete up to
        the last :meth:`sync`."""
        mcap = self.mcap

        def close(_version: int, _metadata: str) -> None:
            mcap.close_data_only()

        mcap.close = close  # type: ignore[method-assign]
        self.close()

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
        with self._room():
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
