"""Input records of the offline analysis: a CSV log read in chunks, or a bag.

:func:`open_record` resolves the input (a CSV header is read and checked at once) and
returns a :class:`Record` whose :meth:`Record.chunks` yields the samples in pieces (a CSV:
one pass over the file per call, memory bounded by the chunk; a bag: its arrays, read
whole); :func:`analyze_record` runs the estimator over them
(:func:`~pneumatic_unload.estimation.chunked.analyze_chunks`). Every input problem is a
:class:`RecordError` with a one-line message. SI units: s, Pa absolute, K.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.chunked import ChunkedAnalysis, analyze_chunks
from pneumatic_unload.estimation.types import FloatArray
from pneumatic_unload.io.csvlog import CHUNK_BYTES, CsvError, CsvStream


class RecordError(Exception):
    """The input cannot be read (a one-line message naming the file)."""


@dataclass
class Record:
    """An input record: samples in chunks, and what the input says about the rig.

    Attributes
    ----------
    path : Path
        The input.
    cfg : dict
        Stored rig configuration and estimator settings (a bag), or the gas temperature of
        the first row (``measured_initial_temperature`` [K], a CSV with a temperature
        column); empty otherwise.
    warnings : tuple of str
        What was assumed about the input (e.g. a CSV unit not stated).
    stream : CsvStream or None
        The CSV reader (None for a bag).
    bag_topic : str or None
        A bag's pressure topic, read in pieces (:func:`pneumatic_unload.io.bag.iter_pressure`)
        by :meth:`chunks` (None for a CSV).
    """

    path: Path
    cfg: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    stream: CsvStream | None = None
    bag_topic: str | None = None

    @property
    def has_temperature(self) -> bool:
        """The record holds a gas-temperature column."""
        return self.stream is not None and self.stream.layout.i_temp is not None

    def chunks(self) -> Iterator[tuple[FloatArray, FloatArray]]:
        """The samples in file order: (t [s], p [Pa absolute]) pieces."""
        if self.bag_topic is not None:
            from pneumatic_unload.io.bag import BagError, iter_pressure

            try:
                for t_ns, p in iter_pressure(self.path, topic=self.bag_topic):
                    yield np.asarray(t_ns, dtype=np.int64) * 1e-9, np.asarray(p, float)
            except BagError as exc:
                raise RecordError(str(exc)) from exc
            return
        assert self.stream is not None
        try:
            for c in self.stream:
                yield c.t, c.p
        except (CsvError, OSError) as exc:
            raise RecordError(f"{self.path}: {exc}") from exc

    def temperature_at(self, t: float) -> float:
        """Gas temperature at instant t [s] (linear between rows, the end rows beyond)
        [K]; NaN without a temperature column. One pass over the file."""
        if not self.has_temperature:
            return float("nan")
        assert self.stream is not None
        prev_t, prev_v = np.empty(0), np.empty(0)
        try:
            for c in self.stream:
                assert c.temperature is not None
                if t <= c.t[-1]:
                    return float(np.interp(t, np.concatenate((prev_t, c.t)),
                                           np.concatenate((prev_v, c.temperature))))
                prev_t, prev_v = c.t[-1:], c.temperature[-1:]
        except (CsvError, OSError) as exc:
            raise RecordError(f"{self.path}: {exc}") from exc
        return float(prev_v[-1])


def open_record(path: str | Path, *, topic: str = "/tank/pressure",
                chunk_bytes: int = CHUNK_BYTES, **csv_options: Any) -> Record:
    """Open an input: a ``.csv``/``.txt`` log (header checked now, rows read in chunks
    later) or a bag (directory or ``.mcap``, its pressure topic read in pieces later: checked
    now).

    Parameters
    ----------
    path : str or Path
        The input.
    topic : str
        Pressure topic of a bag.
    chunk_bytes : int
        CSV text read per chunk [B].
    **csv_options
        :class:`~pneumatic_unload.io.csvlog.CsvStream` options (columns, units, gauge,
        atmosphere [Pa]); None values are left out.

    Raises
    ------
    RecordError
        Missing file, unreadable header or bag, inconsistent options.
    """
    p = Path(path)
    if not p.exists():
        raise RecordError(f"{p}: no such file or directory")
    if p.suffix.lower() in (".csv", ".txt"):
        opts = {k: v for k, v in csv_options.items() if v is not None}
        try:
            stream = CsvStream(p, chunk_bytes=chunk_bytes, **opts)
            cfg: dict[str, Any] = {}
            if stream.layout.i_temp is not None:
                first = next(iter(stream))
                assert first.temperature is not None
                cfg["measured_initial_temperature"] = float(first.temperature[0])
        except (CsvError, ValueError, OSError) as exc:
            raise RecordError(f"{p}: {exc}") from exc
        return Record(path=p, cfg=cfg, warnings=stream.layout.source.warnings, stream=stream)
    from pneumatic_unload.io.bag import (
        TOPIC_SETTINGS,
        BagError,
        iter_pressure,
        read_config,
        read_json_topic,
    )

    try:
        # write order (iter_pressure): a clock that steps back in the header stamps stays
        # visible to the estimator (log-time order may sort it away when log times are the
        # stamps); the topic is checked here, read in pieces by Record.chunks
        iter_pressure(p, topic=topic)
        cfg = read_config(p) or {}
        live = read_json_topic(p, TOPIC_SETTINGS)
    except BagError as exc:
        raise RecordError(str(exc)) from exc
    if live is not None:
        cfg = {**cfg, "estimator_settings": live}
    return Record(path=p, cfg=cfg, bag_topic=topic)


def analyze_record(record: Record, settings: EstimatorSettings) -> ChunkedAnalysis:
    """The estimator over a record, chunk by chunk (see
    :func:`~pneumatic_unload.estimation.chunked.analyze_chunks`).

    Raises
    ------
    RecordError
        A bad row of a CSV (named by its line), too few samples.
    """
    try:
        return analyze_chunks(record.chunks(), settings)
    except EstimationError as exc:
        raise RecordError(f"{record.path}: {exc}") from exc
