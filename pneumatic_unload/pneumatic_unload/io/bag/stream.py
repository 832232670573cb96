# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A bag's pressure topic read in pieces, in memory bounded whatever the bag's length.

:func:`iter_pressure` yields the samples of :func:`~.reader.read_pressure` (``order="write"``)
piece by piece: one MCAP chunk at a time on the numpy fast path, else batches of
:data:`BATCH_MESSAGES` messages through rosbags' reader. Stamps in int nanoseconds,
pressures in Pa absolute.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

from rosbags.interfaces import Connection

from .cdr import NotFastDecodable
from .errors import BagFormatError
from .reader import PressureSeries, decode_pairs, fast_chunk_pairs
from .schema import TOPIC_PRESSURE, pressure_msgtype
from .source import BagSource, open_reader, resolve_bag, topic_connections

#: Messages decoded per piece on the generic (rosbags reader) path [-] (about 100 B each).
BATCH_MESSAGES = 262_144


def iter_pressure(path: str | os.PathLike[str], *, topic: str = TOPIC_PRESSURE,
                  fast: bool = True) -> Iterator[PressureSeries]:
    """The pressure samples of a bag in pieces: ``(t_ns, p)`` per piece.

    Args:
        path: bag directory or single ``.mcap`` file.
        topic: pressure topic (sensor_msgs/msg/FluidPressure; pneumatic_unload_msgs/msg/Voltage
            on ``/tank/pressure_volts``, whose values are volts).
        fast: False forces the generic (rosbags reader) path.

    Returns:
        An iterator of :class:`~.reader.PressureSeries` pieces; concatenated, they are
        ``read_pressure(path, topic=topic, order="write")``: the order the messages were
        written in indexed MCAP files, else log-time order.

    Raises:
        BagNotFoundError, BagFormatError, TopicNotFoundError, WrongMessageTypeError: checked
        before the iterator is returned; BagFormatError while iterating for a chunk that
        does not decode.
    """
    src = resolve_bag(path)
    with open_reader(src) as reader:
        topic_connections(reader, src, topic, pressure_msgtype(topic))
    return _pieces(src, topic, fast)


def _pieces(src: BagSource, topic: str, fast: bool) -> Iterator[PressureSeries]:
    if fast and src.mcap_files:
        gens = [fast_chunk_pairs(f, topic, pressure_msgtype(topic)) for f in src.mcap_files]
        firsts = []
        try:  # every file checked (first chunk decoded) before anything is yielded
            firsts = [next(g, None) for g in gens]
        except NotFastDecodable:
            pass
        else:
            for first, gen in zip(firsts, gens, strict=True):
                if first is None:
                    continue
                yield PressureSeries(first[1], first[2])
                try:
                    for _log, t, p, _var in gen:
                        yield PressureSeries(t, p)
                except NotFastDecodable as err:
                    raise BagFormatError(f"{src.path}: a chunk of {topic} does not decode "
                                         f"({err or 'bad record layout'})") from err
            return
    yield from _generic_pieces(src, topic)


def _generic_pieces(src: BagSource, topic: str) -> Iterator[PressureSeries]:
    """Batches of messages through rosbags' reader (log-time order)."""
    with open_reader(src) as reader:
        conns: list[Connection] = topic_connections(reader, src, topic,
                                                    pressure_msgtype(topic))
        datas: list[bytes] = []
        for _conn, _log, data in reader.messages(connections=conns):
            datas.append(data)
            if len(datas) >= BATCH_MESSAGES:
                t, p, _ = decode_pairs(datas, conns, pressure_msgtype(topic))
                datas = []
                yield PressureSeries(t, p)
        if datas:
            t, p, _ = decode_pairs(datas, conns, pressure_msgtype(topic))
            yield PressureSeries(t, p)
