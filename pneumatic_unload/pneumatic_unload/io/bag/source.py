# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Opening a bag for reading: path checks, rosbags' Reader with its errors mapped.

A bag is a rosbag2 directory (``metadata.yaml`` plus storage files) or a single ``.mcap``
(or ``.db3``) file. Library errors become :class:`~.errors.BagFormatError`; a directory
without ``metadata.yaml`` but with an MCAP file gets the hint to recover it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any, Final

import yaml
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from .errors import (
    RECOVER_HINT,
    BagError,
    BagFormatError,
    BagNotFoundError,
    TopicNotFoundError,
    WrongMessageTypeError,
)
from .inflate import (
    ChunkSizeError,
    check_compressed_file,
    check_mcap_file,
    install_rosbags_bounds,
)
from .schema import make_typestore

# rosbags' MCAP reader decompresses through the bounded inflate (see .inflate)
install_rosbags_bounds()

__all__ = [
    "METADATA_LAYOUT",
    "BagSource",
    "bag_typestore",
    "open_reader",
    "read_metadata",
    "resolve_bag",
    "topic_connections",
]


@dataclass(frozen=True)
class BagSource:
    """A bag resolved on disk."""

    path: Path  # as given by the caller
    reader_path: Path  # what rosbags' Reader opens (directory or single file)
    mcap_files: tuple[Path, ...]  # MCAP files for the numpy fast path (may be empty)
    custom_data: dict[str, str]
    storage_files: tuple[Path, ...] = ()  # every storage file of the bag


def resolve_bag(path: str | os.PathLike[str]) -> BagSource:
    """Check ``path`` (bag directory or single ``.mcap``) and list its storage files."""
    bag = Path(path)
    if not bag.exists():
        raise BagNotFoundError(f"bag {bag} does not exist")
    if bag.is_file():
        if bag.suffix == ".mcap":
            return BagSource(bag, bag, (bag,), {}, (bag,))
        if bag.suffix == ".db3":
            return BagSource(bag, bag, (), {})
        raise BagFormatError(f"{bag} is neither a rosbag2 directory nor an .mcap file")
    meta_path = bag / "metadata.yaml"
    if not meta_path.is_file():
        if any(bag.glob("*.mcap")):
            raise BagFormatError(
                f"bag {bag} has no metadata.yaml: its writer was probably killed before "
                f"closing it; {RECOVER_HINT}"
            )
        raise BagFormatError(f"{bag} is not a rosbag2 bag directory (no metadata.yaml)")
    info = read_metadata(meta_path)
    files = [bag / PurePath(x).name for x in info["relative_file_paths"]]
    compression = str(info.get("compression_mode") or "").lower()
    custom = {str(k): str(v) for k, v in (info.get("custom_data") or {}).items()}
    fast = () if compression not in ("", "none") else tuple(f for f in files if f.suffix == ".mcap")
    return BagSource(bag, bag, fast, custom, tuple(files))


#: What a rosbag2 ``metadata.yaml`` must hold (the keys rosbags' Reader and this package use).
METADATA_LAYOUT: Final = (
    "a rosbag2 metadata.yaml must hold a mapping with the key 'rosbag2_bagfile_information' "
    "whose mapping holds 'version' (an integer 1 to 9), 'storage_identifier' ('mcap' or "
    "'sqlite3'), 'relative_file_paths' (a list of file names), 'topics_with_message_count' "
    "(a list of mappings, each with 'message_count' and 'topic_metadata': a mapping with "
    "'name', 'type' and 'serialization_format': 'cdr'), 'message_count' (an integer), "
    "'duration' (a mapping with 'nanoseconds') and 'starting_time' (a mapping with "
    "'nanoseconds_since_epoch'); optional: 'compression_mode' and 'compression_format' "
    "(strings), 'custom_data' (a mapping), 'files' (a list)"
)

_STORAGES: Final = ("mcap", "sqlite3")


def _kind(value: object) -> str:
    """What a YAML value is, in words (for the messages of :func:`read_metadata`)."""
    if value is None:
        return "empty"
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
             list: "a list", dict: "a mapping"}
    for typ, name in names.items():
        if type(value) is typ:
            text = repr(value)
            return f"{name} ({text[:40]}...)" if len(text) > 43 else f"{name} ({text})"
    return type(value).__name__


def _metadata_problem(doc: object) -> str | None:
    """The first way ``doc`` (a loaded ``metadata.yaml``) departs from
    :data:`METADATA_LAYOUT`, in words; None if it has the layout."""
    key = "rosbag2_bagfile_information"
    if not isinstance(doc, dict):
        return f"it is {_kind(doc)}, not a mapping"
    if key not in doc:
        return f"it has no key '{key}' (its keys: {', '.join(map(str, doc)) or 'none'})"
    info = doc[key]
    if not isinstance(info, dict):
        return f"'{key}' is {_kind(info)}, not a mapping"

    def count(value: object) -> bool:
        return type(value) is int and value >= 0

    def mapping_with(name: str, sub: str) -> str | None:
        if name not in info:
            return f"'{key}' has no '{name}'"
        value = info[name]
        if not isinstance(value, dict) or not count(value.get(sub)):
            return (f"'{name}' is {_kind(value)}, not a mapping with '{sub}' (an integer "
                    "number of nanoseconds >= 0)")
        return None

    checks: list[tuple[str, Callable[[Any], bool]]] = [
        ("version", lambda v: type(v) is int and 1 <= v <= 9),
        ("storage_identifier", lambda v: v in _STORAGES),
        ("relative_file_paths",
         lambda v: isinstance(v, list) and all(isinstance(x, str) and x for x in v)),
        ("topics_with_message_count", lambda v: isinstance(v, list)),
        ("message_count", count),
    ]
    wanted = {"version": "an integer 1 to 9", "storage_identifier": "'mcap' or 'sqlite3'",
              "relative_file_paths": "a list of file names",
              "topics_with_message_count": "a list", "message_count": "an integer >= 0"}
    for name, ok in checks:
        if name not in info:
            return f"'{key}' has no '{name}'"
        if not ok(info[name]):
            return f"'{name}' is {_kind(info[name])}, not {wanted[name]}"
    for i, topic in enumerate(info["topics_with_message_count"]):
        where = f"'topics_with_message_count' entry {i + 1}"
        if not isinstance(topic, dict):
            return f"{where} is {_kind(topic)}, not a mapping"
        if not count(topic.get("message_count")):
            return f"{where} has no 'message_count' integer >= 0"
        meta = topic.get("topic_metadata")
        if not isinstance(meta, dict):
            return f"{where} has no 'topic_metadata' mapping"
        for field in ("name", "type", "serialization_format"):
            if not isinstance(meta.get(field), str):
                return f"'topic_metadata' of {where} has no '{field}' string"
        if meta["serialization_format"] != "cdr":
            return (f"'serialization_format' of {where} is {meta['serialization_format']!r}; "
                    "rosbag2 bags this package reads are 'cdr'")
        qos = meta.get("offered_qos_profiles") or []
        if isinstance(qos, str):  # rosbag2 before version 9: the profiles as YAML text
            with contextlib.suppress(yaml.YAMLError):
                qos = yaml.safe_load(qos) or []
        if not isinstance(qos, list) or not all(isinstance(x, dict) for x in qos):
            return (f"'offered_qos_profiles' of {where} is {_kind(qos)}, not a list of "
                    "mappings")
    for name, sub in (("duration", "nanoseconds"), ("starting_time", "nanoseconds_since_epoch")):
        if (problem := mapping_with(name, sub)) is not None:
            return problem
    if not isinstance(info.get("compression_mode", ""), str):
        return f"'compression_mode' is {_kind(info['compression_mode'])}, not a string"
    if not isinstance(info.get("compression_format") or "", str):
        return f"'compression_format' is {_kind(info['compression_format'])}, not a string"
    mode = info.get("compression_mode", "").lower()
    if mode not in ("", "none", "file", "message"):
        return (f"'compression_mode' is {info['compression_mode']!r}, not '', 'none', 'file' "
                "or 'message'")
    if mode in ("file", "message") and info.get("compression_format") != "zstd":
        return (f"'compression_mode' is {mode!r} but 'compression_format' is "
                f"{_kind(info.get('compression_format'))}, not 'zstd'")
    if not isinstance(info.get("custom_data") or {}, dict):
        return f"'custom_data' is {_kind(info['custom_data'])}, not a mapping"
    if not isinstance(info.get("files", []), list):
        return f"'files' is {_kind(info['files'])}, not a list"
    return None


def read_metadata(meta_path: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag's ``metadata.yaml``, checked
    against :data:`METADATA_LAYOUT` (so that rosbags' Reader and this package find every
    key they use with the expected type).

    Raises:
        BagFormatError: the file is unreadable, not YAML, or lacks that layout; the message
            names the file, what is wrong, what the file must hold and how to rewrite it.
    """
    bag = meta_path.parent
    fix = f"if its storage files are intact, `pneumatic-unload recover {bag}` rewrites it"
    try:
        doc = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise BagFormatError(f"cannot read {meta_path}: {err}") from err
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        what = getattr(err, "problem", None) or "a YAML syntax error"
        raise BagFormatError(
            f"{meta_path} is not valid YAML{where}: {what}; {METADATA_LAYOUT}; {fix}"
        ) from err
    problem = _metadata_problem(doc)
    if problem is not None:
        raise BagFormatError(
            f"{meta_path} is not rosbag2 metadata: {problem}; {METADATA_LAYOUT}; {fix}"
        )
    assert isinstance(doc, dict)  # checked by _metadata_problem
    info: dict[str, Any] = doc["rosbag2_bagfile_information"]
    return info


@contextlib.contextmanager
def open_reader(src: BagSource) -> Iterator[Reader]:
    """rosbags' Reader on ``src``; every library error becomes a :class:`BagFormatError`.
    The chunk sizes its MCAP files declare are checked first (:func:`.inflate.
    check_mcap_file`; a compressed file's expansion: :func:`.inflate.
    check_compressed_file`), and rosbags decompresses with a bounded output."""
    for storage in src.storage_files:
        if storage.suffix == ".mcap" and storage.is_file():
            check_mcap_file(storage)
        elif storage.suffix == ".zstd" and storage.is_file():
            check_compressed_file(storage)
    try:
        reader = Reader(src.reader_path)
        reader.open()
    except ChunkSizeError as err:
        raise BagFormatError(f"cannot read bag {src.path}: {err}") from err
    except BagError:
        raise
    except Exception as err:
        raise BagFormatError(
            f"cannot read bag {src.path}: {str(err).rstrip('.')}. If its writer did not "
            f"finish, {RECOVER_HINT}"
        ) from err
    try:
        yield reader
    except ChunkSizeError as err:  # raised inside rosbags: name the bag
        raise BagFormatError(f"cannot read bag {src.path}: {err}") from err
    except BagError:
        raise
    except Exception as err:
        raise BagFormatError(f"cannot read bag {src.path}: {err}") from err
    finally:
        with contextlib.suppress(Exception):
            reader.close()


def topic_connections(reader: Reader, src: BagSource, topic: str, msgtype: str) -> list[Connection]:
    """Connections of ``topic``; checks the topic exists and carries ``msgtype``."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise TopicNotFoundError(topic, sorted({c.topic for c in reader.connections}), src.path)
    found = sorted({c.msgtype for c in conns})
    if found != [msgtype]:
        raise WrongMessageTypeError(topic, msgtype, found, src.path)
    return conns


def bag_typestore(connections: list[Connection]) -> Typestore:
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
