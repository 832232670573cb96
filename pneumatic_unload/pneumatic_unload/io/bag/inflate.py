# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Bounded decompression of MCAP chunks: a crafted bag cannot make a reader allocate or
churn through more than a fixed budget.

An MCAP chunk states its uncompressed size, and a compressed frame may state its content
size; neither is trusted. :func:`inflate` refuses a chunk that claims more than
:data:`MAX_CHUNK_BYTES` before anything is allocated, and decompresses with a bounded
output (zstd's stream reader read to the claimed size plus one byte, lz4's frame
decompressor with ``max_length``), so a chunk that expands past its claim is refused after
at most that many bytes. :class:`InflateBudget` bounds the whole bag's decompressed bytes:
:data:`MAX_INFLATION` times the file's size (at least :data:`MAX_CHUNK_BYTES`).
:func:`check_mcap_file` applies both to the chunk sizes a file declares (summary chunk
indexes, else the chunk records) before rosbags' reader opens it, and
:func:`install_rosbags_bounds` has rosbags' MCAP reader decompress through :func:`inflate`
(rosbags itself decompresses a chunk whole, trusting the frame). Every refusal is a
:class:`~.errors.BagFormatError` naming the file, the chunk and the limit.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Final

from .errors import BagFormatError
from .records import MCAP_MAGIC, OP_CHUNK, RECORD_HEAD

__all__ = [
    "MAX_CHUNK_BYTES",
    "MAX_INFLATION",
    "ChunkSizeError",
    "InflateBudget",
    "bag_budget",
    "check_compressed_file",
    "check_mcap_file",
    "inflate",
    "install_rosbags_bounds",
]

#: Largest uncompressed size of one MCAP chunk this package reads [B]. rosbag2's MCAP
#: storage, rosbags and this package's recorder write chunks of about 1 MiB (the
#: recorder's ``chunk_size``); 64 times that leaves room for any writer configured for
#: larger chunks, while a chunk that claims more is a corrupt or crafted file.
MAX_CHUNK_BYTES: Final = 64 * 2**20

#: Largest ratio of a bag file's decompressed chunk bytes to its size on disk [-]. The
#: most compressible recording there is, a constant pressure with the same frame id in
#: every message, compresses about 115 to 1 with zstd at its highest level (86 at
#: rosbag2's default); ordinary recordings 2.5 (lz4) to 5 (zstd). 1024 is an order of
#: magnitude above any recording; a decompression bomb (zeros: about 14 000 to 1 with
#: zstd) is far above it.
MAX_INFLATION: Final = 1024


def bag_budget(file_size: int) -> int:
    """The most decompressed chunk bytes a file of ``file_size`` bytes may hold [B]."""
    return max(MAX_CHUNK_BYTES, MAX_INFLATION * file_size)


class InflateBudget:
    """The decompressed bytes left to a file's reader (see :func:`bag_budget`)."""

    def __init__(self, path: Path, file_size: int) -> None:
        """Budget of the file ``path`` of ``file_size`` bytes."""
        self.path, self.limit, self.used = path, bag_budget(file_size), 0

    def take(self, nbytes: int) -> None:
        """Count ``nbytes`` more.

        Raises:
            BagFormatError: the file's chunks decompress to more than its budget.
        """
        self.used += nbytes
        if self.used > self.limit:
            raise BagFormatError(
                f"{self.path}: its chunks decompress to more than {self.limit} bytes "
                f"({MAX_INFLATION} times the file's size; a real recording compresses "
                "far less): a corrupt or crafted file, not read"
            )


class ChunkSizeError(BagFormatError):
    """A chunk that claims too much, expands past its claim or does not decompress."""


def _too_big(where: str, claimed: int) -> ChunkSizeError:
    return ChunkSizeError(
        f"{where} claims {claimed} bytes uncompressed, more than the "
        f"{MAX_CHUNK_BYTES} bytes (MAX_CHUNK_BYTES) a chunk may hold: a corrupt or crafted "
        "file, not read"
    )


def inflate(compression: str, data: bytes | memoryview, size: int, where: str) -> bytes:
    """The uncompressed bytes of a chunk that claims ``size`` bytes.

    Args:
        compression: the chunk's compression ('', 'zstd' or 'lz4').
        data: the chunk's (compressed) records.
        size: the uncompressed size the chunk claims [B].
        where: the chunk for the messages (e.g. "FILE: the chunk at byte N").

    Raises:
        BagFormatError: ``size`` is above :data:`MAX_CHUNK_BYTES`, the data expand to more
            or fewer bytes than ``size``, do not decompress, or the compression is unknown.
    """
    if size > MAX_CHUNK_BYTES or size < 0:
        raise _too_big(where, size)
    try:
        if compression == "":
            out = bytes(data)
        elif compression == "zstd":
            import zstandard

            parts: list[bytes] = []
            got = 0
            with zstandard.ZstdDecompressor().stream_reader(data, read_across_frames=True
                                                            ) as reader:
                while got <= size:  # read() may return less than asked
                    more = reader.read(size + 1 - got)
                    if not more:
                        break
                    parts.append(more)
                    got += len(more)
            out = b"".join(parts)
        elif compression == "lz4":
            import lz4.frame

            dec = lz4.frame.LZ4FrameDecompressor()
            parts = [dec.decompress(bytes(data), max_length=size + 1)]
            got = len(parts[0])
            while got <= size and not dec.eof and not dec.needs_input:
                more = dec.decompress(b"", max_length=size + 1 - got)
                if not more:
                    break
                parts.append(more)
                got += len(more)
            out = b"".join(parts)
        else:
            raise ChunkSizeError(f"{where} has an unknown compression {compression!r}")
    except BagFormatError:
        raise
    except Exception as exc:  # zstandard.ZstdError, RuntimeError of lz4: corrupt data
        raise ChunkSizeError(f"{where} ({compression}) does not decompress: {exc}"
                             ) from exc
    if len(out) > size:
        raise ChunkSizeError(
            f"{where} expands to more than the {size} bytes it claims "
            "(a corrupt or crafted file, not read)"
        )
    if len(out) < size:
        raise ChunkSizeError(
            f"{where} expands to {len(out)} bytes, not the {size} it claims"
        )
    return out


def _declared_from_summary(mcap_file: Path) -> list[int] | None:
    """Uncompressed sizes the summary's chunk indexes declare (None: no usable summary)."""
    from mcap.reader import make_reader

    try:
        with mcap_file.open("rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:
        return None
    if summary is None or not summary.chunk_indexes:
        return None
    return [int(c.uncompressed_size) for c in summary.chunk_indexes]


def _declared_from_records(mcap_file: Path) -> list[int]:
    """Uncompressed sizes the chunk records of the data section declare (a file without a
    summary, as rosbags' reader then scans it); stops at the first torn record."""
    out: list[int] = []
    size = mcap_file.stat().st_size
    with mcap_file.open("rb") as f:
        if f.read(8) != MCAP_MAGIC:
            return out
        pos = 8
        while pos + 9 <= size:
            f.seek(pos)
            head = f.read(9 + 24)
            if len(head) < 9:
                break
            op, length = RECORD_HEAD.unpack_from(head, 0)
            if op == OP_CHUNK and len(head) >= 33:
                out.append(struct.unpack_from("<Q", head, 25)[0])
            pos += 9 + length
    return out


def check_mcap_file(mcap_file: Path) -> None:
    """Check the chunk sizes an MCAP file declares against :data:`MAX_CHUNK_BYTES` and the
    file's budget (:func:`bag_budget`), before a reader decompresses anything.

    Raises:
        BagFormatError: a chunk or the chunks together claim more.
    """
    sizes = _declared_from_summary(mcap_file)
    if sizes is None:
        sizes = _declared_from_records(mcap_file)
    budget = InflateBudget(mcap_file, mcap_file.stat().st_size)
    for claimed in sizes:
        if claimed > MAX_CHUNK_BYTES:
            raise _too_big(f"{mcap_file}: a chunk", claimed)
        budget.take(claimed)


def _bounded(compression: str):  # type: ignore[no-untyped-def]
    def decompress(data: bytes, size: int) -> bytes:
        return inflate(compression, data, size, "a chunk")
    return decompress


def install_rosbags_bounds() -> None:
    """Have rosbags' MCAP reader decompress chunks through :func:`inflate` (its table of
    decompressors, called with the chunk's claimed size): the same bytes for every
    well-formed chunk, a :class:`~.errors.BagFormatError` instead of an unbounded
    allocation for a chunk that claims more than :data:`MAX_CHUNK_BYTES` or expands past
    its claim."""
    from rosbags.rosbag2 import storage_mcap

    table = storage_mcap.DECOMPRESSORS
    for name in ("zstd", "lz4"):
        table[name] = _bounded(name)


#: Bytes read per step when a compressed storage file is measured [B].
_STEP: Final = 1 << 20


def check_compressed_file(path: Path) -> None:
    """Check that a zstd-compressed storage file (rosbag2's ``compression_mode: file``,
    which rosbags' reader decompresses whole to a temporary file) expands to no more than
    its budget (:func:`bag_budget`), by decompressing it in steps of 1 MiB.

    Raises:
        BagFormatError: it expands to more, or does not decompress.
    """
    import zstandard

    budget = InflateBudget(path, path.stat().st_size)
    try:
        with path.open("rb") as f, zstandard.ZstdDecompressor().stream_reader(
                f, read_across_frames=True) as reader:
            while piece := reader.read(_STEP):
                budget.take(len(piece))
    except zstandard.ZstdError as exc:
        raise BagFormatError(f"{path}: does not decompress (zstd): {exc}") from exc
