# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Rosbag2 bags (MCAP storage) of tank discharges, read and written without ROS.

This package never imports rclpy or a ROS message package: messages are (de)serialised with
rosbags' own typestore (ROS 2 Jazzy types plus the ``pneumatic_unload_msgs`` types read from
their ``.msg`` files), and the bulk pressure stream has a numpy fast path in both directions.

Units at this API: pressures in Pa absolute, temperatures in K (the ``sensor_msgs/Temperature``
messages carry degrees C; the conversion happens here), valve opening as a fraction [-],
durations in s, timestamps as int nanoseconds (``t_ns``).

Topics (see the ``TOPIC_*`` / ``MSGTYPE_*`` constants): ``/tank/pressure``
(sensor_msgs/msg/FluidPressure) or an uncalibrated rig's ``/tank/pressure_volts``
(pneumatic_unload_msgs/msg/Voltage), ``/tank/temperature`` (sensor_msgs/msg/Temperature),
``/tank/valve`` (pneumatic_unload_msgs/msg/ValveState), ``/estimator/estimate``
(pneumatic_unload_msgs/msg/UnloadEstimate) and ``/rig/config`` (std_msgs/msg/String holding
the JSON rig configuration; the first message of every bag written by :class:`BagRecorder`).

Crash safety: :class:`BagRecorder` closes its pending MCAP chunk at least every
``flush_interval`` seconds (and whenever it reaches ``chunk_size`` bytes) and hands it to the
operating system, so a ``kill -9`` loses at most about ``flush_interval`` of data.
:func:`recover` turns the directory such a writer leaves behind (no ``metadata.yaml``, an MCAP
file without summary or footer, maybe a torn last chunk) into a complete bag again.

Modules, each importing only those above it:

- :mod:`.errors`: :class:`BagError` and its subclasses, :data:`RECOVER_HINT`.
- :mod:`.schema`: topic and message-type constants, units, the typestore and ``.msg`` lookup.
- :mod:`.records`: the MCAP record layout this package reads and writes itself.
- :mod:`.cdr`: numpy CDR encoding/decoding of header-stamped pairs, timestamp checks.
- :mod:`.inflate`: bounded chunk decompression (a cap per chunk and per file), also
  installed in rosbags' MCAP reader's table of decompressors.
- :mod:`.writer`: rosbags' rosbag2/MCAP writer extended (the only module using rosbags
  internals and subclassing its classes).
- :mod:`.source`: opening a bag for reading (path checks, rosbags' Reader, error mapping).
- :mod:`.reader`: ``read_pressure``, ``read_temperature``, ``read_valve``,
  ``read_estimates``, ``read_config``, ``read_json_topic``, ``read_raw_messages``.
- :mod:`.stream`: :func:`iter_pressure` (the pressure topic in pieces: bounded memory).
- :mod:`.summary`: :func:`bag_summary`.
- :mod:`.messages`: rig configuration JSON, Header and UnloadEstimate built for writing.
- :mod:`.recorder`: :class:`BagRecorder`.
- :mod:`.recover`: :func:`recover`.
"""

from __future__ import annotations

from .cdr import cdr_header_stamp_ns
from .errors import (
    RECOVER_HINT,
    BagError,
    BagFormatError,
    BagNotFoundError,
    BagWriteError,
    TopicNotFoundError,
    UnknownMessageTypeError,
    WrongMessageTypeError,
)
from .reader import (
    PressureSeries,
    RawMessage,
    TemperatureSeries,
    ValveSeries,
    read_config,
    read_estimates,
    read_pressure,
    read_raw_messages,
    read_temperature,
    read_valve,
)
from .reader import read_json_topic as read_json_topic
from .recorder import BagRecorder
from .recover import RecoverReport, recover
from .schema import (
    CONFIG_METADATA_KEY,
    MSG_PACKAGE,
    MSGTYPE_CONFIG,
    MSGTYPE_ESTIMATE,
    MSGTYPE_PRESSURE,
    MSGTYPE_TEMPERATURE,
    MSGTYPE_VALVE,
    MSGTYPE_VOLTAGE,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_TEMPERATURE,
    TOPIC_VALVE,
    TOPIC_VOLTS,
    ZERO_CELSIUS,
    find_msg_definition,
    find_msg_dir,
    make_typestore,
)
from .schema import TOPIC_SETTINGS as TOPIC_SETTINGS
from .stream import iter_pressure
from .summary import BagSummary, TopicSummary, bag_summary
from .writer import DEFAULT_CHUNK_SIZE

# ``read_json_topic`` and ``TOPIC_SETTINGS`` (imported ``X as X`` above) are public too but, as
# before the split, not listed here.
__all__ = [
    "CONFIG_METADATA_KEY",
    "DEFAULT_CHUNK_SIZE",
    "MSGTYPE_CONFIG",
    "MSGTYPE_ESTIMATE",
    "MSGTYPE_PRESSURE",
    "MSGTYPE_TEMPERATURE",
    "MSGTYPE_VALVE",
    "MSGTYPE_VOLTAGE",
    "MSG_PACKAGE",
    "RECOVER_HINT",
    "TOPIC_CONFIG",
    "TOPIC_ESTIMATE",
    "TOPIC_PRESSURE",
    "TOPIC_TEMPERATURE",
    "TOPIC_VALVE",
    "TOPIC_VOLTS",
    "ZERO_CELSIUS",
    "BagError",
    "BagFormatError",
    "BagNotFoundError",
    "BagRecorder",
    "BagSummary",
    "BagWriteError",
    "PressureSeries",
    "RawMessage",
    "RecoverReport",
    "TemperatureSeries",
    "TopicNotFoundError",
    "TopicSummary",
    "UnknownMessageTypeError",
    "ValveSeries",
    "WrongMessageTypeError",
    "bag_summary",
    "cdr_header_stamp_ns",
    "find_msg_definition",
    "find_msg_dir",
    "iter_pressure",
    "make_typestore",
    "read_config",
    "read_estimates",
    "read_pressure",
    "read_raw_messages",
    "read_temperature",
    "read_valve",
    "recover",
]
