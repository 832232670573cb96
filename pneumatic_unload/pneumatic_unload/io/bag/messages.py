# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Message contents built from Python values for writing.

The rig configuration as JSON text (for ``/rig/config`` and the metadata ``custom_data``),
and, serialised with a rosbags typestore, ``std_msgs/Header`` from a stamp [ns] and
``pneumatic_unload_msgs/UnloadEstimate`` from a mapping of field values in SI units (see
:meth:`~pneumatic_unload.io.bag.BagRecorder.write_estimate`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import operator
import struct
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from .cdr import check_t_ns
from .errors import BagWriteError
from .schema import INT32_MAX, INT32_MIN, MSGTYPE_ESTIMATE, NS_PER_S, field_names

__all__ = ["config_json", "encode_estimate", "make_header"]


def _json_default(obj: object) -> object:
    """JSON fallback for numpy values, paths and dataclasses in a rig configuration."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def config_json(config: Mapping[str, Any]) -> str:
    """JSON text of a rig configuration (numpy values, paths and dataclasses converted).

    Raises:
        BagWriteError: ``config`` is not a mapping or not JSON serialisable.
    """
    try:
        return json.dumps(dict(config), default=_json_default)
    except (TypeError, ValueError) as err:
        raise BagWriteError(f"config is not JSON serialisable: {err}") from err


def make_header(store: Typestore, stamp_ns: int, frame_id: str) -> object:
    """A ``std_msgs/Header`` of ``store`` with stamp ``stamp_ns`` [ns] and ``frame_id``.

    Raises:
        BagWriteError: the stamp is outside the int32 seconds range of ROS Time.
    """
    types = store.types
    sec, nsec = divmod(stamp_ns, NS_PER_S)
    if not INT32_MIN <= sec <= INT32_MAX:
        raise BagWriteError(f"header stamp {stamp_ns} ns is out of the int32 seconds range")
    stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def encode_estimate(store: Typestore, stamp_ns: int, fields: Mapping[str, Any]) -> memoryview:
    """CDR payload of one UnloadEstimate from ``fields``.

    Args:
        store: typestore holding the UnloadEstimate definition.
        stamp_ns: header stamp [ns] unless ``fields`` has ``header_stamp_ns``.
        fields: field values by name, SI units, as for
            :meth:`~pneumatic_unload.io.bag.BagRecorder.write_estimate` (missing float64
            fields become NaN, integers 0, strings '').

    Raises:
        BagWriteError: unknown field names or values of the wrong kind.
    """
    names = field_names(store, MSGTYPE_ESTIMATE)
    allowed = {"header_stamp_ns", "frame_id", "unload_start_ns"}
    allowed |= set(names) - {"header", "unload_start"}
    if unknown := sorted(set(fields) - allowed):
        raise BagWriteError(
            f"unknown UnloadEstimate fields {unknown}; valid keys: {sorted(allowed)}"
        )
    values: dict[str, Any] = {}
    try:
        for name, (_, (_kind, spec)) in zip(
            names, store.fielddefs[MSGTYPE_ESTIMATE][1], strict=True
        ):
            if name == "header":
                header_ns = check_t_ns(fields.get("header_stamp_ns", stamp_ns), "header_stamp_ns")
                values[name] = make_header(store, header_ns, str(fields.get("frame_id", "")))
            elif name == "unload_start":
                start_ns = check_t_ns(fields.get("unload_start_ns", 0), "unload_start_ns")
                sec, nsec = divmod(start_ns, NS_PER_S)
                values[name] = store.types["builtin_interfaces/msg/Time"](
                    sec=sec, nanosec=nsec
                )
            else:
                base = spec[0] if isinstance(spec, tuple) else spec
                if base in ("float64", "float32"):
                    values[name] = float(fields.get(name, math.nan))
                elif base == "string":
                    values[name] = str(fields.get(name, ""))
                elif base == "bool":
                    values[name] = bool(fields.get(name, False))
                else:
                    values[name] = operator.index(fields.get(name, 0))
        msg = store.types[MSGTYPE_ESTIMATE](**values)
        data = store.serialize_cdr(msg, MSGTYPE_ESTIMATE)
    except (TypeError, ValueError, OverflowError, struct.error) as err:
        raise BagWriteError(f"invalid UnloadEstimate value: {err}") from err
    return data
