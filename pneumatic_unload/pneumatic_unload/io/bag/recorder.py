# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Streaming bag writer for the live recorder and simulations (:class:`BagRecorder`).

Crash safety: :class:`BagRecorder` closes its pending MCAP chunk at least every
``flush_interval`` seconds (and whenever it reaches ``chunk_size`` bytes) and hands it to the
operating system, so a ``kill -9`` loses at most about ``flush_interval`` of data;
:func:`~pneumatic_unload.io.bag.recover` repairs what such a writer leaves behind.

Units: pressures in Pa absolute, temperatures in K (written as degrees C, as
``sensor_msgs/Temperature`` wants), valve opening as a fraction [-], timestamps as int
nanoseconds.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, WriterError
from rosbags.typesys import get_types_from_msg

from .cdr import check_t_ns, encode_pair_block, encode_stamped_pair
from .errors import BagWriteError, UnknownMessageTypeError
from .messages import config_json, encode_estimate, make_header
from .records import UINT64_MAX
from .schema import (
    CONFIG_METADATA_KEY,
    MSGTYPE_CONFIG,
    MSGTYPE_ESTIMATE,
    MSGTYPE_PRESSURE,
    MSGTYPE_TEMPERATURE,
    MSGTYPE_VALVE,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_PRESSURE,
    TOPIC_TEMPERATURE,
    TOPIC_VALVE,
    ZERO_CELSIUS,
    find_msg_definition,
    make_typestore,
    missing_types,
)
from .writer import DEFAULT_CHUNK_SIZE, Rosbag2Writer, latched_qos

__all__ = ["BagRecorder"]


class BagRecorder:
    """Streaming writer of a rosbag2 bag (MCAP storage) for the live recorder and simulations.

    Use as a context manager; the bag is completed (summary, ``metadata.yaml``) on ``close()``
    or when the ``with`` block ends, also when it ends with an exception. Thread safe.

    Example::

        with BagRecorder(path, config={"volume": 1e-3}) as rec:
            rec.write_pressures(t_ns, p_pa)          # int64 [ns], float64 [Pa absolute]
            rec.write_temperature(t_ns[0], 293.15)   # [K]
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        config: Mapping[str, Any] | None = None,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        flush_interval: float = 1.0,
        fsync: bool = False,
        config_stamp_ns: int | None = None,
    ) -> None:
        """Create the bag directory ``path`` (it must not exist) and open it for writing.

        Args:
            path: new bag directory; the MCAP file is ``<path>/<name>.mcap``.
            config: rig configuration (JSON-serialisable mapping). Written as the first
                message on ``/rig/config`` and into the metadata ``custom_data`` under
                :data:`CONFIG_METADATA_KEY`.
            chunk_size: MCAP chunk size limit [bytes] (>= 1024).
            flush_interval: maximal age of unwritten data [s]: on each write, the pending
                chunk is closed and handed to the OS if the last flush is this long ago
                (``math.inf``: only by size). A writer that may go idle should also call
                :meth:`flush` from a timer.
            fsync: also ``fsync`` at each flush (survives power loss, not only ``kill -9``).
            config_stamp_ns: log time of the ``/rig/config`` message [ns]; by default the log
                time of the first other message written (or 0 for a bag with no messages).

        Raises:
            BagWriteError: the path exists or cannot be created, or an option is invalid.
        """
        if chunk_size < 1024:
            raise BagWriteError(f"chunk_size must be >= 1024 bytes, got {chunk_size}")
        if not flush_interval >= 0.0:
            raise BagWriteError(f"flush_interval must be >= 0 s, got {flush_interval}")
        self.path = Path(path)
        self.flush_interval = float(flush_interval)
        self.fsync = fsync
        self._typestore = make_typestore()
        self._lock = threading.RLock()
        self._connections: dict[tuple[str, str], Connection] = {}
        self._config_text: str | None = None
        if config is not None:
            self._config_text = config_json(config)
        self._config_stamp_ns = (
            None if config_stamp_ns is None else check_t_ns(config_stamp_ns, "config_stamp_ns")
        )
        try:
            self._writer = Rosbag2Writer(
                self.path, version=9, storage_plugin=StoragePlugin.MCAP
            )
            self._writer.open()
        except (WriterError, OSError) as err:
            raise BagWriteError(f"cannot create bag {self.path}: {err}") from err
        self._writer.mcap.chunk_size = int(chunk_size)
        #: False once a bag that ran out of room was closed without its MCAP summary
        #: (``metadata.yaml`` alone: ``pneumatic-unload recover`` makes it readable).
        self.summary_written = True
        try:
            self._writer.sync()  # MCAP magic and header are on disk from the start
        except OSError as err:  # a full disk's: BagDiskFullError
            raise BagWriteError(f"cannot create bag {self.path}: {err}") from err
        if self._config_text is not None:
            self._writer.set_custom_data(CONFIG_METADATA_KEY, self._config_text)
        self._config_pending = self._config_text is not None
        self._last_flush = time.monotonic()
        self._closed = False
        if self._config_pending and self._config_stamp_ns is not None:
            with self._lock:
                self._write_config(self._config_stamp_ns)

    # ------------------------------------------------------------------ context manager

    def __enter__(self) -> BagRecorder:
        """Return the open recorder."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]:
        """Close the bag (also after an exception, keeping what was written)."""
        self.close()
        return False

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._closed

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        with self._lock:
            return self._writer.topic_counts

    # ------------------------------------------------------------------------ internals

    def _check_open(self) -> None:
        if self._closed:
            raise BagWriteError(f"bag {self.path} is already closed")

    def _connection(self, topic: str, msgtype: str) -> Connection:
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            if msgtype not in self._typestore.fielddefs:
                raise UnknownMessageTypeError(msgtype)
            # the latched topics' offered QoS, as rosbag2 records it (ros2 bag play latches)
            qos = latched_qos() if topic in (TOPIC_CONFIG, TOPIC_ESTIMATE) else ()
            conn = self._writer.add_connection(topic, msgtype, typestore=self._typestore,
                                               offered_qos_profiles=qos)
            self._connections[key] = conn
        return conn

    def _write_config(self, log_time: int) -> None:
        assert self._config_text is not None
        self._config_pending = False
        string_t = self._typestore.types[MSGTYPE_CONFIG]
        data = self._typestore.serialize_cdr(string_t(data=self._config_text), MSGTYPE_CONFIG)
        self._writer.write(self._connection(TOPIC_CONFIG, MSGTYPE_CONFIG), log_time, data)

    def _before_write(self, log_time: int) -> None:
        self._check_open()
        if not 0 <= log_time <= UINT64_MAX:
            raise BagWriteError(f"log time must be within [0, 2^64) ns, got {log_time}")
        if self._config_pending:
            self._write_config(log_time if self._config_stamp_ns is None else self._config_stamp_ns)

    def _after_write(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval:
            self._writer.sync(fsync=self.fsync)
            self._last_flush = now

    def _write(self, topic: str, msgtype: str, log_time: int, data: bytes | memoryview) -> None:
        with self._lock:
            self._before_write(log_time)
            self._writer.write(self._connection(topic, msgtype), log_time, data)
            self._after_write()

    def _serialize(self, msgtype: str, msg: object) -> memoryview:
        return self._typestore.serialize_cdr(msg, msgtype)

    # ------------------------------------------------------------------------ public API

    def register_type(self, msgtype: str, msgdef_text: str) -> None:
        """Make ``msgtype`` (e.g. 'pkg/msg/Name') writable from its ``.msg`` definition text.

        ``msgdef_text`` may be a plain ``.msg`` file or the concatenated rosbag2/MCAP form
        (``====`` separated ``MSG: pkg/Name`` sections for the dependencies).

        Raises:
            BagWriteError: the definition cannot be parsed or conflicts with a known type.
        """
        with self._lock:
            try:
                self._typestore.register(get_types_from_msg(msgdef_text, msgtype))
            except Exception as err:
                raise BagWriteError(f"cannot register {msgtype!r}: {err}") from err

    def has_type(self, msgtype: str) -> bool:
        """True when ``msgtype`` and every type it uses are known (writable)."""
        with self._lock:
            return not missing_types(self._typestore, msgtype)

    def ensure_type(self, msgtype: str) -> None:
        """Make ``msgtype`` writable, loading its (and its dependencies') ``.msg`` definitions
        from installed interface packages (see :func:`find_msg_definition`) when needed.

        Raises:
            UnknownMessageTypeError: a needed definition is not installed.
            BagWriteError: a definition cannot be parsed.
        """
        with self._lock:
            for _ in range(1000):  # bound: each pass registers at least one type
                missing = missing_types(self._typestore, msgtype)
                if not missing:
                    return
                name = missing[0]
                text = find_msg_definition(name)
                if text is None:
                    raise UnknownMessageTypeError(name)
                self.register_type(name, text)
            raise BagWriteError(f"cannot resolve the definition of {msgtype!r}")

    @property
    def config_text(self) -> str | None:
        """The rig configuration (JSON text) of this bag, or None if it has none yet."""
        return self._config_text

    def set_config(
        self, config: Mapping[str, Any] | str, *, config_stamp_ns: int | None = None
    ) -> None:
        """Store the rig configuration after opening (e.g. when it arrives on ``/rig/config``).

        Writes a ``/rig/config`` message and sets the metadata ``custom_data`` entry (the
        latest configuration wins there; :func:`read_config` returns the first message).

        Args:
            config: JSON-serialisable mapping, or JSON text of an object.
            config_stamp_ns: log time of the message [ns]; default: the latest log time
                written so far, or, in an empty bag, that of the next message written.

        Raises:
            BagWriteError: closed recorder, or ``config`` is not a JSON object.
        """
        if isinstance(config, str):
            try:
                parsed = json.loads(config)
            except ValueError as err:
                raise BagWriteError(f"config is not valid JSON: {err}") from err
            if not isinstance(parsed, dict):
                raise BagWriteError("config must be a JSON object")
            text = config
        else:
            text = config_json(config)
        stamp = (
            None if config_stamp_ns is None else check_t_ns(config_stamp_ns, "config_stamp_ns")
        )
        with self._lock:
            self._check_open()
            self._config_text = text
            self._writer.set_custom_data(CONFIG_METADATA_KEY, text)
            empty = self._writer.is_empty
            last = self._writer.last_log_time
            if stamp is None and empty:  # stamp it like the next message written
                self._config_stamp_ns = None
                self._config_pending = True
                return
            self._config_pending = False
            self._write_config(last if stamp is None else stamp)
            self._after_write()

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        timestamp_ns: int,
        cdr_bytes: bytes | bytearray | memoryview,
    ) -> None:
        """Write one already serialised message (CDR, e.g. from rclpy with ``raw=True``).

        Args:
            topic: topic name; its connection is created on first use.
            msgtype: message type, e.g. 'sensor_msgs/msg/FluidPressure'.
            timestamp_ns: log (receive) time [ns].
            cdr_bytes: the serialised message, CDR with its 4-byte encapsulation header.

        Raises:
            UnknownMessageTypeError: ``msgtype`` is not known (see :meth:`register_type`).
            BagWriteError: closed recorder, bad timestamp or payload.
        """
        log_time = check_t_ns(timestamp_ns, "timestamp_ns")
        if len(cdr_bytes) < 4:
            raise BagWriteError(f"CDR payload of {len(cdr_bytes)} bytes is too short")
        self._write(topic, msgtype, log_time, bytes(cdr_bytes))

    def write_pressure(
        self,
        t_ns: int,
        p_pa: float,
        *,
        frame_id: str = "tank",
        variance: float = 0.0,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one tank pressure sample on ``/tank/pressure``.

        Args:
            t_ns: sample instant (header stamp) [ns].
            p_pa: pressure [Pa absolute].
            frame_id: header frame id of the sensor.
            variance: pressure variance [Pa^2] (0 = unknown).
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else check_t_ns(log_time_ns, "log_time_ns")
        payload = encode_stamped_pair(stamp, float(p_pa), float(variance), frame_id=frame_id)
        self._write(TOPIC_PRESSURE, MSGTYPE_PRESSURE, log_time, payload)

    def write_pressures(
        self,
        t_ns: npt.ArrayLike,
        p_pa: npt.ArrayLike,
        *,
        frame_id: str = "tank",
        variance: npt.ArrayLike = 0.0,
        log_time_ns: npt.ArrayLike | None = None,
    ) -> None:
        """Write N pressure samples on ``/tank/pressure`` at once (vectorised fast path).

        Args:
            t_ns: sample instants (header stamps) [ns], integer array of shape (N,).
            p_pa: pressures [Pa absolute], shape (N,).
            frame_id: header frame id of the sensor.
            variance: pressure variance [Pa^2], scalar or shape (N,).
            log_time_ns: bag log times [ns], shape (N,); default ``t_ns``.
        """
        self._write_pair_block(
            TOPIC_PRESSURE, MSGTYPE_PRESSURE, t_ns, p_pa, variance, frame_id, log_time_ns
        )

    def write_temperature(
        self,
        t_ns: int,
        temperature_k: float,
        *,
        frame_id: str = "tank",
        variance: float = 0.0,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one gas temperature sample on ``/tank/temperature``.

        Args:
            t_ns: sample instant (header stamp) [ns].
            temperature_k: temperature [K] (stored in the message as degrees C).
            frame_id: header frame id of the sensor.
            variance: temperature variance [K^2] (0 = unknown).
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else check_t_ns(log_time_ns, "log_time_ns")
        payload = encode_stamped_pair(
            stamp, float(temperature_k) - ZERO_CELSIUS, float(variance), frame_id=frame_id
        )
        self._write(TOPIC_TEMPERATURE, MSGTYPE_TEMPERATURE, log_time, payload)

    def write_temperatures(
        self,
        t_ns: npt.ArrayLike,
        temperature_k: npt.ArrayLike,
        *,
        frame_id: str = "tank",
        variance: npt.ArrayLike = 0.0,
        log_time_ns: npt.ArrayLike | None = None,
    ) -> None:
        """Write N temperature samples [K] at instants ``t_ns`` [ns] (vectorised)."""
        celsius = np.asarray(temperature_k, np.float64) - ZERO_CELSIUS
        self._write_pair_block(
            TOPIC_TEMPERATURE, MSGTYPE_TEMPERATURE, t_ns, celsius, variance, frame_id, log_time_ns
        )

    def _write_pair_block(
        self,
        topic: str,
        msgtype: str,
        t_ns: npt.ArrayLike,
        values: npt.ArrayLike,
        variance: npt.ArrayLike,
        frame_id: str,
        log_time_ns: npt.ArrayLike | None,
    ) -> None:
        logs_u, payloads = encode_pair_block(
            t_ns, values, variance, frame_id=frame_id, log_time_ns=log_time_ns
        )
        if logs_u.size == 0:
            return
        with self._lock:
            self._before_write(int(logs_u.min()))
            self._writer.write_block(self._connection(topic, msgtype), logs_u, payloads)
            self._after_write()

    def write_valve(
        self,
        t_ns: int,
        open: bool,
        opening: float,
        *,
        frame_id: str = "valve",
        log_time_ns: int | None = None,
    ) -> None:
        """Write the discharge valve state on ``/tank/valve``.

        Args:
            t_ns: instant of the state (header stamp) [ns].
            open: True when the valve is commanded open.
            opening: effective opening fraction of the valve area [-], in [0, 1].
            frame_id: header frame id.
            log_time_ns: bag log time [ns]; default ``t_ns``.
        """
        stamp = check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else check_t_ns(log_time_ns, "log_time_ns")
        msg = self._typestore.types[MSGTYPE_VALVE](
            header=make_header(self._typestore, stamp, frame_id),
            open=bool(open),
            opening=float(opening),
        )
        self._write(TOPIC_VALVE, MSGTYPE_VALVE, log_time, self._serialize(MSGTYPE_VALVE, msg))

    def write_estimate(
        self,
        t_ns: int,
        fields: Mapping[str, Any],
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """Write one sonic-conductance estimate on ``/estimator/estimate``.

        Args:
            t_ns: log time [ns] (and the header stamp unless ``header_stamp_ns`` is given).
            fields: UnloadEstimate field values by name (SI units: conductances in
                m^3/(s Pa), pressures in Pa absolute, tau_exp in s, initial_temperature in K,
                volume in m^3), plus ``header_stamp_ns`` [ns], ``frame_id`` and
                ``unload_start_ns`` [ns] for the two time fields. Missing float64 fields are
                written as NaN ("not known"), missing integers as 0, strings as ''.
            log_time_ns: bag log time [ns]; default ``t_ns``.

        Raises:
            BagWriteError: unknown field names or values of the wrong kind.
        """
        stamp = check_t_ns(t_ns)
        log_time = stamp if log_time_ns is None else check_t_ns(log_time_ns, "log_time_ns")
        data = encode_estimate(self._typestore, stamp, fields)
        self._write(TOPIC_ESTIMATE, MSGTYPE_ESTIMATE, log_time, data)

    def flush(self) -> None:
        """Write the pending chunk now (a live node may call this from an idle timer)."""
        with self._lock:
            self._check_open()
            self._writer.sync(fsync=self.fsync)
            self._last_flush = time.monotonic()

    def close(self) -> None:
        """Complete the bag: last chunk, MCAP summary and footer, ``metadata.yaml``.

        Idempotent.
        """
        with self._lock:
            if self._closed:
                return
            if self._writer.full is not None:  # cut back to the last flush, completed
                self._closed = True
                try:
                    self.summary_written = self._writer.close_cut_back()
                except (WriterError, OSError) as err:
                    raise BagWriteError(f"cannot close bag {self.path} after it ran out "
                                        f"of room: {err}") from err
                return
            try:
                if self._config_pending:
                    self._write_config(
                        self._config_stamp_ns
                        if self._config_stamp_ns is not None
                        else (0 if self._writer.is_empty else self._writer.first_log_time)
                    )
                self._writer.close()
            except (WriterError, OSError) as err:
                raise BagWriteError(f"cannot close bag {self.path}: {err}") from err
            finally:
                self._closed = True
