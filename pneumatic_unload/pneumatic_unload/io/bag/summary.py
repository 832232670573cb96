# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Overview of a bag: topics, message types, counts and time span [s]."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from .schema import NS_PER_S
from .source import open_reader, resolve_bag

__all__ = [
    "BagSummary",
    "TopicSummary",
    "bag_summary",
]


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
    src = resolve_bag(path)
    with open_reader(src) as reader:
        topics: dict[str, TopicSummary] = {}
        for name, info in reader.topics.items():
            types = sorted({c.msgtype for c in info.connections})
            topics[name] = TopicSummary(", ".join(types), int(info.msgcount))
        count = int(reader.message_count)
        start = int(reader.start_time) if count else None
        end = int(reader.end_time) - 1 if count else None
    duration = (end - start) / NS_PER_S if start is not None and end is not None else 0.0
    return BagSummary(src.path, topics, count, start, end, duration, dict(src.custom_data))
