# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Input records of the offline analysis: a CSV log read in chunks, or a bag.

:func:`open_record` resolves the input (a CSV header is read and checked at once) and
returns a :class:`Record` whose :meth:`Record.chunks` yields the samples in pieces (a CSV:
one pass over the file per call, memory bounded by the chunk; a bag: its arrays, read
whole); :func:`analyze_record` runs the estimator over them
(:func:`~pneumatic_unload.estimation.chunked.analyze_chunks`). Every input problem is a
:class:`RecordError` with a one-line message. SI units: s, Pa absolute, K.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pneumatic_unload.config import ConfigError, TankSpec, adapters
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.curvefit.temperature_evidence import (
    channel_evidence,
    departure_text,
    temperature_evidence,
)
from pneumatic_unload.estimation.batch import merge_final
from pneumatic_unload.estimation.chunked import ChunkedAnalysis, analyze_chunks
from pneumatic_unload.estimation.types import FloatArray
from pneumatic_unload.io.csvlog import CHUNK_BYTES, CsvError, CsvStream


class RecordError(Exception):
    """The input cannot be read (a one-line message naming the file)."""


#: Key of a record's ``cfg``: its samples are volts with no recorded calibration (the
#: settings must then give signal_gain).
VOLTS_KEY = "pressure_in_volts"


def _naming(path: Path, exc: BaseException) -> str:
    """The message of ``exc``, prefixed with ``path`` unless it names the file already."""
    text = str(exc)
    return text if str(path) in text else f"{path}: {text}"


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
    def notes(self) -> tuple[str, ...]:
        """What the last pass over a CSV's rows found beyond :attr:`warnings` (a time
        counter unwrapped); empty for a bag or before a pass."""
        return self.stream.notes if self.stream is not None else ()

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
                ok = np.isfinite(c.p)  # rows of a slower channel alone (multi-rate logs)
                if ok.all():
                    yield c.t, c.p
                elif ok.any():
                    yield c.t[ok], c.p[ok]
        except (CsvError, OSError) as exc:
            raise RecordError(_naming(self.path, exc)) from exc

    def temperature_series(self) -> tuple[FloatArray, FloatArray] | None:
        """The gas temperature the record carries: (t [s], T [K]) at its own rate (a CSV's
        empty cells skipped, a bag's temperature topic), or None without one. One pass."""
        if self.bag_topic is not None:
            from pneumatic_unload.io.bag import BagError, read_temperature

            try:
                t_ns, temp = read_temperature(self.path)
            except BagError as exc:
                raise RecordError(str(exc)) from exc
            if len(temp) == 0:
                return None
            return np.asarray(t_ns, dtype=np.int64) * 1e-9, np.asarray(temp, float)
        if not self.has_temperature:
            return None
        assert self.stream is not None
        ts, vs = [], []
        try:
            for c in self.stream:
                assert c.temperature is not None
                ok = np.isfinite(c.temperature)
                ts.append(c.t[ok])
                vs.append(c.temperature[ok])
        except (CsvError, OSError) as exc:
            raise RecordError(_naming(self.path, exc)) from exc
        return (np.concatenate(ts), np.concatenate(vs)) if ts else None

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
                ok = np.isfinite(c.temperature)  # empty cells: a slower channel
                ct, cv = c.t[ok], c.temperature[ok]
                if ct.size and t <= ct[-1]:
                    return float(np.interp(t, np.concatenate((prev_t, ct)),
                                           np.concatenate((prev_v, cv))))
                if ct.size:
                    prev_t, prev_v = ct[-1:], cv[-1:]
        except (CsvError, OSError) as exc:
            raise RecordError(_naming(self.path, exc)) from exc
        return float(prev_v[-1]) if prev_v.size else float("nan")


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
                for chunk in stream:  # the first temperature logged (maybe rows later)
                    assert chunk.temperature is not None
                    ok = np.flatnonzero(np.isfinite(chunk.temperature))
                    if ok.size:
                        cfg["measured_initial_temperature"] = float(chunk.temperature[ok[0]])
                        break
        except (CsvError, ValueError, OSError) as exc:
            raise RecordError(_naming(p, exc)) from exc
        return Record(path=p, cfg=cfg, warnings=stream.layout.source.warnings, stream=stream)
    from pneumatic_unload.io.bag import (
        TOPIC_PRESSURE,
        TOPIC_SETTINGS,
        TOPIC_VOLTS,
        BagError,
        TopicNotFoundError,
        bag_summary,
        iter_pressure,
        read_config,
        read_json_topic,
    )

    try:
        # write order (iter_pressure): a clock that steps back in the header stamps stays
        # visible to the estimator (log-time order may sort it away when log times are the
        # stamps); the topic is checked here, read in pieces by Record.chunks
        try:
            iter_pressure(p, topic=topic)
        except TopicNotFoundError:
            # an uncalibrated rig's bag: its volts on a topic of their own, converted with
            # the signal_gain/signal_offset given or recorded (the live estimator's settings)
            if topic != TOPIC_PRESSURE or TOPIC_VOLTS not in bag_summary(p).topics:
                raise
            topic = TOPIC_VOLTS
            iter_pressure(p, topic=topic)
        cfg = read_config(p) or {}
        live = read_json_topic(p, TOPIC_SETTINGS)
    except BagError as exc:
        raise RecordError(str(exc)) from exc
    if live is not None:
        cfg = {**cfg, "estimator_settings": live}
    if topic == TOPIC_VOLTS and "signal_gain" not in (live or {}):
        cfg = {**cfg, VOLTS_KEY: True}
    return Record(path=p, cfg=cfg, bag_topic=topic)


def settings_for(cfg: dict[str, Any], given: dict[str, Any]) -> EstimatorSettings:
    """Estimator settings of a record: the values ``given`` first [SI], then the live
    estimator's settings recorded in a bag (so that the analysis reproduces what it
    published), then the bag's rig configuration (tank, gas and the flow's direction; a
    CSV's temperature column for T10), then the defaults of
    :class:`~pneumatic_unload.config.estimator.EstimatorSettings`.

    Raises
    ------
    RecordError
        The settings stored in a bag are invalid, or the volume is neither given nor stored.
    EstimationError, ConfigError
        A value out of range.
    """
    if cfg.get(VOLTS_KEY) and "signal_gain" not in given:
        raise RecordError(
            "the bag's pressure is a transducer's volts (/tank/pressure_volts) and it holds "
            "no estimator settings to convert them: give the calibration, signal_gain "
            "[Pa/V] and signal_offset [Pa] (--signal-gain, --signal-offset)")
    live = cfg.get("estimator_settings")
    if live is not None:
        try:
            base = EstimatorSettings(**adapters.from_mapping(EstimatorSettings, live,
                                                             strict=False))
        except (TypeError, ConfigError, EstimationError) as exc:
            raise RecordError(f"the estimator settings stored in the bag are invalid: {exc}"
                              ) from exc
        return dataclasses.replace(base, **given)
    kw = TankSpec.fields_of(cfg)  # the bag's rig: tank and gas, and the flow's direction
    if cfg.get("direction") in ("discharge", "charge"):
        kw["direction"] = cfg["direction"]
    if "initial_temperature" not in kw and "measured_initial_temperature" in cfg:
        kw["initial_temperature"] = cfg["measured_initial_temperature"]
    kw.update(given)
    if "volume" not in kw:
        raise RecordError("--volume M3 is required (the input carries no rig configuration)")
    return EstimatorSettings(**kw)


def analyze_record(record: Record, settings: EstimatorSettings) -> ChunkedAnalysis:
    """The estimator over a record, chunk by chunk (see
    :func:`~pneumatic_unload.estimation.chunked.analyze_chunks`).

    Raises
    ------
    RecordError
        A bad row of a CSV (named by its line), too few samples.
    """
    try:
        temperature = record.temperature_series()
    except RecordError:  # optional evidence: the pressure's analysis stands without it
        temperature = None
    try:
        return analyze_chunks(record.chunks(), settings, temperature=temperature)
    except EstimationError as exc:
        raise RecordError(f"{record.path}: {exc}") from exc


@dataclass
class InputAnalysis:
    """The analysis of one input, as ``pneumatic-unload analyze`` and a batch report it.

    Attributes
    ----------
    record : Record
        The input.
    settings : EstimatorSettings
        The settings used (T10 from a temperature column at the unload's start when the
        input has one and T10 was not given).
    run : ChunkedAnalysis
        The estimator's run (every published result, the overview, diagnostics).
    unloads : list of UnloadResult
        One result per unload (the final one when there is one); all 'bad_data' when the
        readings look like gauge pressures taken as absolute.
    t10_column : bool
        T10 was read from the input's temperature column.
    no_unload : str or None
        Why no unload was found (None when one was).
    input_problem : str or None
        Why the readings cannot be absolute pressures (None when they can).
    """

    record: Record
    settings: EstimatorSettings
    run: ChunkedAnalysis
    unloads: list[Any]
    t10_column: bool
    no_unload: str | None
    input_problem: str | None


def analyze_input(record: Record, given: dict[str, Any]) -> InputAnalysis:
    """Analyse an opened input with the settings ``given`` [SI] over what it stores (see
    :func:`settings_for`): the estimator over its chunks, one result per unload, T10 from
    a temperature column at the first unload's start (when not given: the input is then
    analysed again with it), and the gauge-pressure check.

    Raises
    ------
    RecordError
        Unreadable rows, invalid stored settings, no volume.
    EstimationError, ConfigError
        A value out of range.
    """
    settings = settings_for(record.cfg, given)
    t10_column = False
    if record.has_temperature and "initial_temperature" not in given:
        # T10 from the temperature column: the gas temperature at the start of the unload
        # (the first row may be logged long before, during the charge), found by the
        # detector alone (the final fits are made once, with it)
        first = merge_final(analyze_record(record, dataclasses.replace(
            settings, curve_fit=False)).published)
        if first and math.isfinite(first[0].t_start):
            t10 = record.temperature_at(first[0].t_start)
            t10_column = True
            if abs(t10 - settings.initial_temperature) > 1e-3:
                settings = dataclasses.replace(settings, initial_temperature=t10)
    run = analyze_record(record, settings)
    unloads = merge_final(run.published)
    unloads = with_temperature_evidence(record, settings, unloads)
    why = None if unloads else run.explain_no_unload()
    problem = run.gauge_suspicion()
    if problem is not None:
        # C from gauge readings taken as absolute is wrong: no unload may say "ok"
        unloads = [dataclasses.replace(r, status="bad_data", status_text=problem)
                   for r in unloads]
    return InputAnalysis(record, settings, run, unloads, t10_column, why, problem)


def with_temperature_evidence(record: Record, settings: EstimatorSettings,
                              unloads: list[Any]) -> list[Any]:
    """The final results with the record's gas temperature as evidence
    (:func:`~pneumatic_unload.curvefit.temperature_evidence.temperature_evidence`: ``extra
    ['gas_temperature']``, and the status text when the model's gas does not follow it);
    ``gas_temperature`` says so where the record carries none."""
    if not any(r.final and "curve_fit" in r.extra for r in unloads):
        return unloads
    try:
        series = record.temperature_series()
    except RecordError:  # optional evidence: the pressure's analysis stands without it
        series = None
    out = []
    for r in unloads:
        cf = r.extra.get("curve_fit") if r.final else None
        if cf is None:
            out.append(r)
            continue
        joint = cf.get("gas_temperature") or {}
        if series is None:
            ev: dict[str, Any] = {"used": False, "why": "the record carries no gas "
                                  "temperature (CSV: --temperature-column NAME)"}
        elif "rms" in joint:  # fitted jointly
            ev = channel_evidence(joint)
        else:
            fit = CurveFit(**cf)
            ev = temperature_evidence(fit.config(settings.one_way(r.direction)), fit.t_start,
                                      *series)
            if joint.get("why"):
                ev["why"] = f"compared, {joint['why']}"
        text = departure_text(ev)
        out.append(dataclasses.replace(
            r, extra={**r.extra, "gas_temperature": ev},
            status_text=f"{r.status_text}; {text}" if text else r.status_text))
    return out


def measured_temperature(path: str | Path, **csv_options: Any
                         ) -> tuple[FloatArray, FloatArray] | None:
    """The gas temperature an input carries (:meth:`Record.temperature_series` of the input
    opened with ``csv_options`` as :func:`open_record`), or None when it carries fewer than
    3 values or cannot be read (the temperature is optional evidence: a run never fails on
    it)."""
    try:
        got = open_record(path, **csv_options).temperature_series()
        return got if got is not None and got[1].size >= 3 else None
    except Exception:
        return None
