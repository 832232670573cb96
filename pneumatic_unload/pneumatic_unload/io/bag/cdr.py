# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""CDR encoding and decoding of header-stamped messages with numpy (the fast paths).

FluidPressure and Temperature (``Header header; float64 a; float64 b``) are encoded N at a
time into an (N, L) uint8 array, byte-identical to rosbags' serialiser, and decoded N at a
time from a byte buffer (frame_id lengths may differ per message). Also the validation of
integer nanosecond timestamps [ns] and the header-stamp peek of any header-first message.
"""

from __future__ import annotations

import operator
import struct
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import BagFormatError, BagWriteError
from .schema import INT32_MAX, INT32_MIN, NS_PER_S

__all__ = [
    "NotFastDecodable",
    "cdr_header_stamp_ns",
    "check_t_ns",
    "decode_stamped_pairs",
    "encode_pair_block",
    "encode_stamped_pair",
    "encode_stamped_pairs",
    "gather",
]


def check_t_ns(value: object, what: str = "t_ns") -> int:
    """``value`` as a Python int [ns]; rejects floats (timestamps are integer nanoseconds)."""
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise BagWriteError(
            f"{what} must be an integer number of nanoseconds, got {type(value).__name__} "
            f"{value!r}"
        ) from None


def _split_stamp(t_ns: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], npt.NDArray]:
    """(sec, nanosec) of ROS ``builtin_interfaces/Time`` for stamps ``t_ns`` [ns]."""
    sec, nsec = np.divmod(t_ns, NS_PER_S)
    if sec.size and (sec.min() < INT32_MIN or sec.max() > INT32_MAX):
        raise BagWriteError("header stamp out of the int32 seconds range of ROS Time")
    return sec, nsec


def _stamped_pair_dtype(frame_id: bytes) -> np.dtype:
    """numpy layout of the CDR of ``Header header; float64 a; float64 b`` (FluidPressure,
    Temperature) for a fixed ``frame_id`` (CDR little endian, 8-byte alignment from the body).
    """
    n_str = len(frame_id) + 1  # with the NUL terminator
    pad = (-(12 + n_str)) % 8
    fields: list[tuple[Any, ...]] = [
        ("encap", "u1", (4,)),
        ("sec", "<i4"),
        ("nanosec", "<u4"),
        ("strlen", "<u4"),
        ("frame_id", "u1", (n_str,)),
    ]
    if pad:
        fields.append(("pad", "u1", (pad,)))
    fields += [("a", "<f8"), ("b", "<f8")]
    return np.dtype(fields)


def encode_stamped_pairs(
    t_ns: npt.ArrayLike,
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    *,
    frame_id: str,
) -> npt.NDArray[np.uint8]:
    """CDR payloads of N FluidPressure/Temperature messages, byte-identical to rosbags'.

    Args:
        t_ns: header stamps [ns], integer array of shape (N,).
        a: first float64 field (fluid_pressure [Pa] or temperature [degC]), shape (N,) or scalar.
        b: variance [Pa^2 or K^2], shape (N,) or scalar.
        frame_id: header frame id (same for all N).

    Returns:
        uint8 array of shape (N, L): one serialised message per row.
    """
    stamps = np.asarray(t_ns)
    if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
        raise BagWriteError("t_ns must be a 1-D integer array of nanoseconds")
    stamps = stamps.astype(np.int64, copy=False)
    frame = frame_id.encode()
    if b"\x00" in frame:
        raise BagWriteError("frame_id must not contain NUL characters")
    dtype = _stamped_pair_dtype(frame)
    out = np.zeros(stamps.size, dtype)
    sec, nsec = _split_stamp(stamps)
    out["encap"] = (0, 1, 0, 0)
    out["sec"] = sec
    out["nanosec"] = nsec
    out["strlen"] = len(frame) + 1
    out["frame_id"][:, : len(frame)] = np.frombuffer(frame, np.uint8)
    out["a"] = a
    out["b"] = b
    return out.view(np.uint8).reshape(stamps.size, dtype.itemsize)



def encode_pair_block(
    t_ns: npt.ArrayLike,
    values: npt.ArrayLike,
    variance: npt.ArrayLike,
    *,
    frame_id: str,
    log_time_ns: npt.ArrayLike | None,
) -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.uint8]]:
    """Checked log times and CDR payloads of N FluidPressure/Temperature messages.

    Args:
        t_ns: header stamps [ns], integer array of shape (N,).
        values: first float64 field (fluid_pressure [Pa] or temperature [degC]), shape (N,).
        variance: variance [Pa^2 or K^2], shape (N,) or scalar.
        frame_id: header frame id (same for all N).
        log_time_ns: bag log times [ns], integer array of shape (N,); None: ``t_ns``.

    Returns:
        (log times [ns] as uint64 of shape (N,), payloads as uint8 of shape (N, L)).

    Raises:
        BagWriteError: shapes or types do not match, or a log time is negative.
    """
    stamps = np.asarray(t_ns)
    vals = np.asarray(values, np.float64)
    if stamps.ndim != 1 or vals.shape != stamps.shape:
        raise BagWriteError(
            f"t_ns and values must be 1-D of equal length, got {stamps.shape} and {vals.shape}"
        )
    payloads = encode_stamped_pairs(stamps, vals, variance, frame_id=frame_id)
    logs = stamps if log_time_ns is None else np.asarray(log_time_ns)
    if logs.shape != stamps.shape or not np.issubdtype(logs.dtype, np.integer):
        raise BagWriteError("log_time_ns must be an integer array shaped like t_ns")
    if logs.size and logs.min() < 0:
        raise BagWriteError("log times must be >= 0 ns")
    return logs.astype(np.uint64), payloads


@lru_cache(maxsize=64)
def _stamped_pair_struct(frame_id: str) -> tuple[struct.Struct, bytes]:
    """struct layout of one FluidPressure/Temperature CDR payload for ``frame_id``."""
    frame = frame_id.encode()
    if b"\x00" in frame:
        raise BagWriteError("frame_id must not contain NUL characters")
    n_str = len(frame) + 1
    pad = (-(12 + n_str)) % 8
    return struct.Struct(f"<4siII{n_str}s{pad}xdd"), frame


def encode_stamped_pair(t_ns: int, a: float, b: float, *, frame_id: str) -> bytes:
    """CDR payload of one FluidPressure/Temperature message (stamp [ns], a, variance b)."""
    layout, frame = _stamped_pair_struct(frame_id)
    sec, nsec = divmod(t_ns, NS_PER_S)
    try:
        return layout.pack(b"\x00\x01\x00\x00", sec, nsec, len(frame) + 1, frame, a, b)
    except struct.error as err:
        raise BagWriteError(f"cannot encode stamp {t_ns} ns / values {a}, {b}: {err}") from err


def cdr_header_stamp_ns(data: bytes | bytearray | memoryview) -> int | None:
    """Header stamp [ns] of a serialised message whose first field is ``std_msgs/Header``.

    Reads ``builtin_interfaces/Time`` (int32 sec, uint32 nanosec) right after the 4-byte CDR
    encapsulation header, in the payload's byte order. No other validation: call it only for
    types that start with a header.

    Returns:
        The stamp [ns] (may be negative for a negative ``sec``), or None if the payload is
        too short or not plain CDR.
    """
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        return None
    sec, nsec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return sec * NS_PER_S + nsec


class NotFastDecodable(Exception):
    """The raw messages cannot go through the numpy decoder (e.g. big-endian CDR)."""


def gather(buf: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64], dtype: str) -> np.ndarray:
    """Values of ``dtype`` read at byte positions ``pos`` of ``buf`` (vectorised)."""
    dt = np.dtype(dtype)
    return buf[pos[:, None] + np.arange(dt.itemsize)].view(dt).reshape(-1)


def decode_stamped_pairs(
    buf: npt.NDArray[np.uint8],
    starts: npt.NDArray[np.int64],
    lengths: npt.NDArray[np.int64],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Decode N FluidPressure/Temperature CDR payloads at ``buf[starts[i]:starts[i]+lengths[i]]``.

    frame_id lengths may differ per message: the float offsets are computed per message.

    Returns:
        (header stamps [ns], first float64 field, second float64 field (variance)).

    Raises:
        NotFastDecodable: a payload is not little-endian plain CDR.
        BagFormatError: a payload is too short for the layout.
    """
    if starts.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.float64), np.empty(0, np.float64)
    if np.any(lengths < 4 + 12 + 1 + 16) or np.any(starts + lengths > buf.size):
        raise BagFormatError("message payload too short for a header-stamped message")
    if np.any(buf[starts] != 0) or np.any(buf[starts + 1] != 1):
        raise NotFastDecodable
    sec = gather(buf, starts + 4, "<i4").astype(np.int64)
    nsec = gather(buf, starts + 8, "<u4").astype(np.int64)
    strlen = gather(buf, starts + 12, "<u4").astype(np.int64)
    vpos = starts + 4 + ((12 + strlen + 7) // 8) * 8
    if np.any(vpos + 16 > starts + lengths):
        raise BagFormatError("corrupt message: frame_id length runs past the payload")
    a = gather(buf, vpos, "<f8")
    b = gather(buf, vpos + 8, "<f8")
    return sec * NS_PER_S + nsec, a, b
