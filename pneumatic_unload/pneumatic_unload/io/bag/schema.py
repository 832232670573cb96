# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Topics, message types and the rosbags typestore of the tank-discharge bags.

Topics (see the ``TOPIC_*`` / ``MSGTYPE_*`` constants): ``/tank/pressure``
(sensor_msgs/msg/FluidPressure) or an uncalibrated rig's ``/tank/pressure_volts``
(pneumatic_unload_msgs/msg/Voltage), ``/tank/temperature`` (sensor_msgs/msg/Temperature),
``/tank/valve`` (pneumatic_unload_msgs/msg/ValveState), ``/estimator/estimate``
(pneumatic_unload_msgs/msg/UnloadEstimate) and ``/rig/config`` (std_msgs/msg/String holding
the JSON rig configuration; the first message of every bag written by
:class:`~pneumatic_unload.io.bag.BagRecorder`).

Message definitions come from rosbags' own typestore (ROS 2 Jazzy types) plus the
``pneumatic_unload_msgs`` types read from their ``.msg`` files, never from a ROS message
package. Also the units shared by the package: 0 degrees C in K, nanoseconds per second and
the int32 seconds range of ROS ``builtin_interfaces/Time``.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path
from typing import Any, Final

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from .errors import BagError

__all__ = [
    "CONFIG_METADATA_KEY",
    "INT32_MAX",
    "INT32_MIN",
    "MSGTYPE_CONFIG",
    "MSGTYPE_ESTIMATE",
    "MSGTYPE_PRESSURE",
    "MSGTYPE_TEMPERATURE",
    "MSGTYPE_VALVE",
    "MSGTYPE_VOLTAGE",
    "MSG_PACKAGE",
    "NS_PER_S",
    "TOPIC_CONFIG",
    "TOPIC_ESTIMATE",
    "TOPIC_PRESSURE",
    "TOPIC_SETTINGS",
    "TOPIC_TEMPERATURE",
    "TOPIC_VALVE",
    "TOPIC_VOLTS",
    "ZERO_CELSIUS",
    "field_names",
    "find_msg_definition",
    "find_msg_dir",
    "make_typestore",
    "missing_types",
    "pressure_msgtype",
]


TOPIC_PRESSURE: Final = "/tank/pressure"
#: An uncalibrated transducer's output [V] (pneumatic_unload_msgs/msg/Voltage): the
#: estimator converts it with signal_gain/signal_offset. Bags made before this topic carry
#: such volts in a FluidPressure on /tank/pressure, and read as before.
TOPIC_VOLTS: Final = "/tank/pressure_volts"
TOPIC_TEMPERATURE: Final = "/tank/temperature"
TOPIC_VALVE: Final = "/tank/valve"
TOPIC_ESTIMATE: Final = "/estimator/estimate"
TOPIC_CONFIG: Final = "/rig/config"
#: The live estimator's settings (std_msgs/String JSON, latched): analysis reuses them.
TOPIC_SETTINGS: Final = "/estimator/settings"

MSG_PACKAGE: Final = "pneumatic_unload_msgs"
MSGTYPE_PRESSURE: Final = "sensor_msgs/msg/FluidPressure"
MSGTYPE_TEMPERATURE: Final = "sensor_msgs/msg/Temperature"
MSGTYPE_VALVE: Final = f"{MSG_PACKAGE}/msg/ValveState"
MSGTYPE_ESTIMATE: Final = f"{MSG_PACKAGE}/msg/UnloadEstimate"
MSGTYPE_CONFIG: Final = "std_msgs/msg/String"
MSGTYPE_VOLTAGE: Final = f"{MSG_PACKAGE}/msg/Voltage"


def pressure_msgtype(topic: str) -> str:
    """The message type of a pressure input topic: Voltage on :data:`TOPIC_VOLTS`, else
    FluidPressure (both ``Header header; float64 value; float64 variance``)."""
    return MSGTYPE_VOLTAGE if topic == TOPIC_VOLTS else MSGTYPE_PRESSURE

#: Key of the JSON rig configuration in the rosbag2 metadata ``custom_data``.
CONFIG_METADATA_KEY: Final = "pneumatic_unload.config"

#: 0 degrees C in K.
ZERO_CELSIUS: Final = 273.15
#: Nanoseconds per second.
NS_PER_S: Final = 1_000_000_000
#: Range of the int32 seconds of ROS ``builtin_interfaces/Time``.
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def find_msg_dir() -> Path:
    """Directory holding the ``pneumatic_unload_msgs`` ``.msg`` files, found without rclpy.

    Search order: the source tree (``<repo>/pneumatic_unload_msgs/msg``), then
    ``share/pneumatic_unload_msgs/msg`` under ``sys.prefix`` and under each entry of
    ``AMENT_PREFIX_PATH`` (colcon install or ament index).

    Returns:
        The directory [path].

    Raises:
        BagError: No candidate directory holds the message files.
    """
    candidates = [Path(__file__).resolve().parents[4] / "pneumatic_unload_msgs" / "msg"]
    share = Path("share") / MSG_PACKAGE / "msg"
    prefixes = [sys.prefix, sys.base_prefix]
    prefixes += [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    candidates += [Path(p) / share for p in prefixes]
    for cand in candidates:
        if (cand / "UnloadEstimate.msg").is_file():
            return cand
    tried = ", ".join(str(c) for c in candidates)
    raise BagError(f"cannot find the {MSG_PACKAGE} .msg files; looked in: {tried}")


@lru_cache(maxsize=1)
def _package_types() -> dict[str, Any]:
    """Parsed definitions of all ``pneumatic_unload_msgs`` messages (rosbags Typesdict)."""
    types: dict[str, Any] = {}
    for msg_file in sorted(find_msg_dir().glob("*.msg")):
        name = f"{MSG_PACKAGE}/msg/{msg_file.stem}"
        types.update(get_types_from_msg(msg_file.read_text(encoding="utf-8"), name))
    return types


def make_typestore() -> Typestore:
    """A fresh rosbags typestore: ROS 2 Jazzy types plus the ``pneumatic_unload_msgs`` types.

    Returns:
        A new typestore (callers may register more types in it without side effects).
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(_package_types())
    return store


def find_msg_definition(msgtype: str) -> str | None:
    """The ``.msg`` text of ``msgtype`` ('pkg/msg/Name') from an installed interface package.

    Looks for ``share/<pkg>/msg/<Name>.msg`` under ``sys.prefix`` and each entry of
    ``AMENT_PREFIX_PATH`` (and the source tree for ``pneumatic_unload_msgs``).

    Returns:
        The definition text, or None if no installed package provides it.
    """
    parts = msgtype.split("/")
    if len(parts) == 2:  # 'pkg/Name' (ROS 1 style, used inside .msg files)
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or parts[1] != "msg" or not all(parts):
        return None
    pkg, _, name = parts
    prefixes = [sys.prefix, sys.base_prefix]
    prefixes += [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    candidates = [Path(p) / "share" / pkg / "msg" / f"{name}.msg" for p in prefixes]
    if pkg == MSG_PACKAGE:
        with contextlib.suppress(BagError):
            candidates.insert(0, find_msg_dir() / f"{name}.msg")
    for cand in candidates:
        if cand.is_file():
            return cand.read_text(encoding="utf-8")
    return None


def _referenced_types(spec: Any) -> Iterator[str]:
    """Message type names referenced by one rosbags field type spec (recursively)."""
    kind, detail = spec
    if kind == Nodetype.NAME:
        yield detail
    elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        yield from _referenced_types(detail[0])


def missing_types(store: Typestore, msgtype: str) -> list[str]:
    """Types that ``msgtype`` needs (itself included) and ``store`` does not define."""
    missing: list[str] = []
    seen: set[str] = set()
    todo = [msgtype]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        if name not in store.fielddefs:
            missing.append(name)
            continue
        for _, spec in store.fielddefs[name][1]:
            todo.extend(_referenced_types(spec))
    return missing


def field_names(store: Typestore, msgtype: str) -> list[str]:
    """Field names of ``msgtype`` in definition order (constants excluded)."""
    return [name for name, _ in store.fielddefs[msgtype][1]]
