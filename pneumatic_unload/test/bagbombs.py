# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Crafted bags whose compressed chunks expand far beyond what they hold (decompression
bombs) or lie about their size, for the bounded-reading tests.

:func:`make_bomb` rewrites a good bag's MCAP file with every record in one compressed
chunk (or several, ``chunk_size``) whose compressed data is the chunk's records followed
by ``extra`` zero bytes; the chunk then truly decompresses to ``records + extra`` bytes.
``claim`` sets the uncompressed size the chunk record and its chunk index declare:
``"true"`` (the real size), ``"records"`` (only the records: the chunk lies small) or a
number of bytes (e.g. 1 TiB). By default the compressed frame carries its content size,
as a one-shot compressor writes it, so that a decompressor trusting the frame allocates
it whole.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import zstandard
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

#: Zero bytes fed to the compressor per call [B].
_PIECE = 1 << 20


def _zstd_bomb(records: bytes, extra: int, frame_size: bool = True) -> bytes:
    size = len(records) + extra if frame_size else -1
    cobj = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    out = [cobj.compress(records)]
    zeros = bytes(_PIECE)
    left = extra
    while left > 0:
        n = min(left, _PIECE)
        out.append(cobj.compress(zeros if n == _PIECE else bytes(n)))
        left -= n
    out.append(cobj.flush())
    return b"".join(out)


def _lz4_bomb(records: bytes, extra: int, frame_size: bool = True) -> bytes:
    import lz4.frame

    comp = lz4.frame.LZ4FrameCompressor(compression_level=0)
    out = [comp.begin(source_size=len(records) + extra if frame_size else 0),
           comp.compress(records)]
    zeros = bytes(_PIECE)
    left = extra
    while left > 0:
        n = min(left, _PIECE)
        out.append(comp.compress(zeros if n == _PIECE else bytes(n)))
        left -= n
    out.append(comp.flush())
    return b"".join(out)


class _Shim:
    """Stands in for the compression module mcap's writer calls: appends the zeros."""

    def __init__(self, fn: Any, extra: int, frame_size: bool) -> None:
        self.fn, self.extra, self.frame_size = fn, extra, frame_size
        self.sizes: list[int] = []

    def compress(self, data: bytes) -> bytes:
        self.sizes.append(len(data))
        return self.fn(bytes(data), self.extra, self.frame_size)


def _patch_usize(path: Path, claims: list[int]) -> None:
    """Set the uncompressed sizes of the chunk records and chunk indexes of ``path`` (in
    file order)."""
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        starts = sorted(c.chunk_start_offset for c in summary.chunk_indexes)
    blob = bytearray(path.read_bytes())
    by_start = dict(zip(starts, claims, strict=True))
    for start, claim in by_start.items():
        struct.pack_into("<Q", blob, start + 9 + 16, claim)
    # chunk index records (opcode 0x08) of the summary: uncompressed size is their last field
    (summary_start,) = struct.unpack_from("<Q", blob, len(blob) - 8 - 20)
    pos = summary_start
    while pos < len(blob) - 8 - 29:
        op, length = struct.unpack_from("<BQ", blob, pos)
        if op == 0x08:
            (start,) = struct.unpack_from("<Q", blob, pos + 9 + 16)
            struct.pack_into("<Q", blob, pos + 9 + length - 8, by_start[start])
        if op == 0x02:  # footer
            break
        pos += 9 + length
    path.write_bytes(bytes(blob))


def make_bomb(bag: Path, *, extra: int, compression: str = "zstd",
              claim: str | int = "true", frame_size: bool = True,
              chunk_size: int = 1 << 40) -> Path:
    """Rewrite the MCAP file of the bag directory ``bag`` as described in the module doc
    (``frame_size`` False: the compressed frame does not state its content size, so that a
    decompressor allocates what the chunk claims; ``chunk_size``: the records cut into
    chunks of about that many bytes, each followed by ``extra`` zeros); returns the MCAP
    file."""
    (mcap_file,) = sorted(bag.glob("*.mcap"))
    with mcap_file.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas, channels = summary.schemas, summary.channels
        msgs = [(m.channel_id, m.log_time, m.publish_time, m.sequence, m.data)
                for _s, _c, m in reader.iter_messages(log_time_order=False)]
    import mcap.writer as mw

    fn = _zstd_bomb if compression == "zstd" else _lz4_bomb
    shim = _Shim(fn, extra, frame_size)
    saved = (mw.zstandard, getattr(mw, "lz4", None))
    try:
        if compression == "zstd":
            mw.zstandard = shim  # type: ignore[assignment]
            kind = CompressionType.ZSTD
        else:
            mw.lz4 = type("lz4shim", (), {"frame": shim})  # type: ignore[attr-defined]
            kind = CompressionType.LZ4
        with mcap_file.open("wb") as f:
            w = Writer(f, chunk_size=chunk_size, compression=kind, enable_crcs=False)
            w.start(profile="ros2")
            sid = {k: w.register_schema(s.name, s.encoding, s.data) for k, s in schemas.items()}
            cid = {k: w.register_channel(c.topic, c.message_encoding, sid[c.schema_id],
                                         c.metadata) for k, c in channels.items()}
            for ch, log, pub, seq, data in msgs:
                w.add_message(cid[ch], log, data, pub, seq)
            w.finish()
    finally:
        mw.zstandard = saved[0]  # type: ignore[assignment]
        if saved[1] is not None:
            mw.lz4 = saved[1]  # type: ignore[attr-defined]
    if claim == "true":
        claims = [n + extra for n in shim.sizes]
    elif claim == "records":
        claims = list(shim.sizes)
    else:
        claims = [int(claim)] * len(shim.sizes)
    _patch_usize(mcap_file, claims)
    return mcap_file
