"""Opening a bag for reading: path checks, rosbags' Reader with its errors mapped.

A bag is a rosbag2 directory (``metadata.yaml`` plus storage files) or a single ``.mcap``
(or ``.db3``) file. Library errors become :class:`~.errors.BagFormatError`; a directory
without ``metadata.yaml`` but with an MCAP file gets the hint to recover it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePath

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
from .schema import make_typestore

__all__ = [
    "BagSource",
    "bag_typestore",
    "open_reader",
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


def resolve_bag(path: str | os.PathLike[str]) -> BagSource:
    """Check ``path`` (bag directory or single ``.mcap``) and list its storage files."""
    bag = Path(path)
    if not bag.exists():
        raise BagNotFoundError(f"bag {bag} does not exist")
    if bag.is_file():
        if bag.suffix == ".mcap":
            return BagSource(bag, bag, (bag,), {})
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
    try:
        info = yaml.safe_load(meta_path.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        files = [bag / PurePath(x).name for x in info["relative_file_paths"]]
        compression = str(info.get("compression_mode") or "").lower()
        custom = {str(k): str(v) for k, v in (info.get("custom_data") or {}).items()}
    except Exception as err:
        raise BagFormatError(f"bag {bag} has an unreadable metadata.yaml: {err}") from err
    fast = () if compression not in ("", "none") else tuple(f for f in files if f.suffix == ".mcap")
    return BagSource(bag, bag, fast, custom)


@contextlib.contextmanager
def open_reader(src: BagSource) -> Iterator[Reader]:
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
