# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Errors of :mod:`pneumatic_unload.io.bag`, and the hint for a bag left unclosed.

The lowest module of the package: it imports nothing from it. Every error derives from
:class:`BagError`; some also from the matching built-in (FileNotFoundError, KeyError,
TypeError) so that generic handlers keep working.
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Final

__all__ = [
    "DISK_FULL_ERRNOS",
    "RECOVER_HINT",
    "BagDiskFullError",
    "BagError",
    "BagFormatError",
    "BagNotFoundError",
    "BagWriteError",
    "TopicNotFoundError",
    "UnknownMessageTypeError",
    "WrongMessageTypeError",
]


#: What to tell a user whose bag was not closed properly.
RECOVER_HINT: Final = "run `pneumatic-unload recover BAG` to repair it"


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


#: OS errors that mean no more room: the disk or the quota is full, or the file reached
#: the process's file-size limit (RLIMIT_FSIZE).
DISK_FULL_ERRNOS: Final = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


class BagDiskFullError(BagWriteError):
    """The bag cannot grow (:data:`DISK_FULL_ERRNOS`): its writer stopped writing; closing
    it completes the bag with what reached the disk at its last flush."""
