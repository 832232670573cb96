# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Repair of a bag whose writer was killed (:func:`recover`).

Such a writer leaves a directory without ``metadata.yaml`` and an MCAP file without summary
or footer, maybe with a torn last chunk. The intact records are read with mcap's stream
reader and written again as a complete bag.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from mcap.records import Channel as McapChannel
from mcap.records import Chunk as McapChunk
from mcap.records import Message as McapMessage
from mcap.records import Schema as McapSchema
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, WriterError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from .errors import BagError, BagFormatError, BagNotFoundError
from .inflate import InflateBudget, inflate
from .records import MCAP_MAGIC, OP_CHUNK, OP_MESSAGE, RECORD_HEAD
from .schema import CONFIG_METADATA_KEY, MSGTYPE_CONFIG, TOPIC_CONFIG, make_typestore
from .summary import bag_summary
from .writer import Rosbag2Writer, parse_offered_qos

__all__ = [
    "RecoverReport",
    "recover",
]


_PLACEHOLDER_RIHS01: Final = "RIHS01_" + "0" * 64


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
    #: chunks dropped: failing their CRC, not decompressing, or claiming or expanding past
    #: the limits of :mod:`.inflate`
    dropped_chunks: int = 0

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
        if self.dropped_chunks:
            lines.append(f"  dropped {self.dropped_chunks} corrupt or oversized chunks")
        if self.skipped_messages:
            lines.append(f"  skipped {self.skipped_messages} messages without channel/schema")
        if self.kept_originals:
            lines.append("  originals kept as: " + ", ".join(str(p) for p in self.kept_originals))
        return "\n".join(lines)


#: Opcodes of the records an MCAP chunk may hold (schema, channel, message).
_CHUNK_OPS: Final = (0x03, 0x04, OP_MESSAGE)


def _chunk_records(data: bytes) -> list[Any]:
    """Schema/Channel/Message records of a chunk's uncompressed records, up to the first
    torn record or one that a chunk may not hold (the rest of the chunk is not trusted:
    zeros, for one, would be millions of empty records)."""
    out: list[Any] = []
    pos = 0
    while pos + 9 <= len(data):
        op, length = RECORD_HEAD.unpack_from(data, pos)
        end = pos + 9 + length
        if op not in _CHUNK_OPS or end > len(data):
            break
        body = data[pos + 9 : end]
        try:
            if op == OP_MESSAGE:
                if length < 22:
                    break
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
            else:  # schema, channel: mcap's own parser
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


def _salvage_torn_chunk(tail: bytes) -> list[Any]:
    """Intact Schema/Channel/Message records at the start of a torn uncompressed chunk.

    ``tail`` holds the file bytes after the last complete record. A kill during a chunk
    write leaves a prefix of the chunk; its complete inner records are still good.
    """
    if len(tail) < 41 or tail[0] != OP_CHUNK:
        return []
    (clen,) = struct.unpack_from("<I", tail, 37)
    if clen != 0:  # compressed: a prefix cannot be decompressed
        return []
    return _chunk_records(tail[49:])


@dataclass
class _Reading:
    """What reading one file's records found besides the records."""

    good_end: int = 0  #: end of the last complete record [byte]
    bad_chunks: int = 0  #: chunks dropped: corrupt, or too large (see .inflate)


def _expand_record(record: Any, budget: InflateBudget, state: _Reading, where: str
                   ) -> list[Any]:
    """Schema/Channel/Message records of one complete stream record (chunks decompressed
    with a bounded output, see :mod:`.inflate`, and CRC-checked)."""
    if isinstance(record, McapChunk):
        try:
            data = inflate(record.compression, record.data, record.uncompressed_size, where)
        except BagFormatError:
            state.bad_chunks += 1
            return []  # corrupt chunk, or one claiming or expanding past the limit: skip it
        budget.take(len(data))
        if record.uncompressed_crc and zlib.crc32(data) != record.uncompressed_crc:
            state.bad_chunks += 1
            return []
        return _chunk_records(data)
    if isinstance(record, McapSchema | McapChannel | McapMessage):
        return [record]
    return []


def _mcap_records(mcap_file: Path) -> tuple[Iterator[Any], _Reading, Callable[[], int]]:
    """Intact inner records of a possibly truncated MCAP file, what was dropped, and a
    function giving the size of the torn tail [bytes] (after the last complete record)
    once the iterator is exhausted.

    mcap's stream reader yields only records whose full declared length was read, so every
    record it yields is complete; the torn tail ends the iteration with an exception. The
    chunks' decompressed bytes together stay within the file's budget (:mod:`.inflate`:
    BagFormatError past it).
    """
    size = mcap_file.stat().st_size
    state = _Reading()
    budget = InflateBudget(mcap_file, size)

    def gen() -> Iterator[Any]:
        with mcap_file.open("rb") as f:
            if f.read(8) != MCAP_MAGIC:
                raise BagFormatError(f"{mcap_file} is not an MCAP file (bad magic)")
            f.seek(0)
            state.good_end = 8
            reader = StreamReader(f, emit_chunks=True, record_size_limit=1 << 32)
            try:
                for record in reader.records:
                    end = f.tell()
                    where = f"{mcap_file}: the chunk ending at byte {end}"
                    yield from _expand_record(record, budget, state, where)
                    state.good_end = end
            except BagFormatError:
                raise
            except Exception:  # torn tail: EndOfFile, struct.error, ... from the library
                f.seek(state.good_end)
                yield from _salvage_torn_chunk(f.read())
                return
            state.good_end = size

    return gen(), state, lambda: max(0, size - state.good_end)


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
    # absolute: "x.mcap" run inside the bag directory has the parent "." (no name)
    bag = bag.resolve()
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
    bad_chunks = 0
    try:
        try:
            writer = Rosbag2Writer(tmp_root / bag.name, version=9,
                                   storage_plugin=StoragePlugin.MCAP)
            writer.open()
        except WriterError as exc:
            raise BagFormatError(f"cannot write the recovered bag {bag}: {exc}") from exc
        by_key: dict[tuple[str, str, str], Connection] = {}
        config_text: str | None = None
        try:
            for mcap_file in mcaps:
                records, reading, tail = _mcap_records(mcap_file)
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
                                qos = parse_offered_qos(
                                    rec.metadata.get("offered_qos_profiles", "[]")
                                )
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
                bad_chunks += reading.bad_chunks
            if config_text is not None:
                writer.set_custom_data(CONFIG_METADATA_KEY, config_text)
            writer.close()
        except BaseException as exc:
            with contextlib.suppress(Exception):
                writer.abort()
            if isinstance(exc, WriterError):
                raise BagFormatError(f"cannot write the recovered bag {bag}: {exc}") from exc
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
    return RecoverReport(bag, counts, False, dropped, skipped, tuple(kept), bad_chunks)
