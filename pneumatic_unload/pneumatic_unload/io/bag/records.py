# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""MCAP record layout used where this package reads or writes records itself.

The file magic, the Chunk, Message Index and Message opcodes and the fixed record heads
(little endian, see the MCAP specification), shared by the block writer
(:mod:`.writer`), the numpy fast reader (:mod:`.reader`) and the recovery
(:mod:`.recover`). Everything else goes through the ``mcap`` and ``rosbags`` libraries.
"""

from __future__ import annotations

import struct
from typing import Final

__all__ = [
    "MCAP_MAGIC",
    "MSG_HEAD",
    "MSG_HEAD_SIZE",
    "OP_CHUNK",
    "OP_MESSAGE",
    "OP_MESSAGE_INDEX",
    "RECORD_HEAD",
    "UINT64_MAX",
]


#: Largest MCAP log time [ns] (uint64).
UINT64_MAX: Final = 2**64 - 1
MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
OP_CHUNK, OP_MESSAGE_INDEX, OP_MESSAGE = 0x06, 0x07, 0x05
MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
MSG_HEAD_SIZE: Final = MSG_HEAD.size  # 31 bytes; the CDR payload follows
RECORD_HEAD = struct.Struct("<BQ")
