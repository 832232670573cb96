"""Data-logger CSV files of tank discharges: time, pressure and (optionally) gas temperature.

Units: the returned time is in s (starting wherever the logger clock starts), pressures in
Pa absolute, temperatures in K. Input units come from the caller or from the bracketed unit
of the column header (``Time [s]``, ``Pressure [kPa]``, ``Temp [C]``); where each unit came
from is recorded in :class:`CsvSource` (``"argument"``, ``"header"`` or ``"default"``), an
assumed (default) unit is named in ``CsvSource.warnings``, and an explicit unit that
contradicts the header is an error rather than a silent factor of 1000 (see
:mod:`pneumatic_unload.io.csvheader`).

Files of any length are read in chunks of about ``chunk_bytes`` (:class:`CsvStream`, one
pass over the file per iteration, memory bounded by the chunk); :func:`read_csv_trace`
gathers the chunks into whole arrays (16-24 B per row). Separators: ',', ';' or tab; with
';' or tab, decimal commas are read (``0,5;700,3``). A row with more fields than the header
is an error naming its line (with ',' separators: decimal commas, the usual cause).

Example (the AeroLab file: gauge kPa, degrees C)::

    trace = read_csv_trace("orifice_0.094in.csv", gauge=True, atmosphere=101_500.0)
    trace.t[0], trace.p[0], trace.temperature[0]    # 28.0 s, 439290.0 Pa, 321.79 K
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import BinaryIO, Final

import numpy as np
import numpy.typing as npt

from pneumatic_unload.io.csvheader import (
    PRESSURE_UNITS,
    TEMPERATURE_UNITS,
    TIME_UNITS,
    CsvError,
    CsvFormatError,
    CsvLayout,
    CsvOptionError,
    CsvSource,
    resolve_layout,
    sniff_delimiter,
)

__all__ = [
    "CHUNK_BYTES",
    "PRESSURE_UNITS",
    "TEMPERATURE_UNITS",
    "TIME_UNITS",
    "CsvChunk",
    "CsvError",
    "CsvFormatError",
    "CsvOptionError",
    "CsvSource",
    "CsvStream",
    "CsvTrace",
    "read_csv_trace",
]

#: Bytes of text read per chunk [B] (about 200 k rows of 'time,pressure'; parsing takes about 12 B
#: of memory per byte of text).
CHUNK_BYTES: Final = 4 << 20

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class CsvTrace:
    """A tank-discharge trace read from a CSV file (rows in file order; a multi-rate log's
    empty cells are NaN: ``p[np.isfinite(p)]`` is the pressure channel, likewise the
    temperature's)."""

    t: FloatArray  #: sample times [s], from the logger clock (not shifted to 0)
    p: FloatArray  #: tank pressure [Pa absolute] (NaN: an empty cell)
    temperature: FloatArray | None  #: gas temperature [K] (NaN: empty), None if not logged
    source: CsvSource

    @property
    def t_ns(self) -> npt.NDArray[np.int64]:
        """Sample times as integer nanoseconds [ns] (for bags)."""
        return np.round(self.t * 1e9).astype(np.int64)


@dataclass(frozen=True)
class CsvChunk:
    """Consecutive rows of a CSV file, converted: t [s], p [Pa absolute], temperature [K];
    NaN where a pressure or temperature cell is empty (a multi-rate logger writes a slower
    channel's cells only at its own samples; rows with a time stamp alone are dropped)."""

    t: FloatArray
    p: FloatArray
    temperature: FloatArray | None
    first_row: int  #: data-row number of the first row (1-based) [-]


def _open(file: Path) -> BinaryIO:
    try:
        return file.open("rb")
    except FileNotFoundError:
        raise CsvFormatError(f"CSV file {file} does not exist") from None
    except OSError as err:
        raise CsvFormatError(f"cannot read CSV file {file}: {err}") from err


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


class CsvStream:
    """A CSV trace read in chunks; each iteration is one pass over the file.

    The header is read and resolved at construction (errors in it are raised there); the
    rows are checked as they are read: a row with fewer cells than the columns used or more
    non-empty fields than the header, a non-numeric or non-finite cell, time not increasing
    and a pressure not positive once absolute are :class:`CsvFormatError` naming the line.

    Args:
        path: the CSV file.
        chunk_bytes: text read per chunk [B] (whole lines; at least one line).
        **options: as :func:`read_csv_trace` (columns, units, gauge, atmosphere [Pa],
            delimiter).

    Attributes:
        layout: the resolved header (:class:`~pneumatic_unload.io.csvheader.CsvLayout`).
        rows: data rows read by the last complete pass [-] (0 before one).
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_bytes: int = CHUNK_BYTES,
                 delimiter: str | None = None, **options: object) -> None:
        self.path = Path(path)
        self.chunk_bytes = max(1, int(chunk_bytes))
        self.rows = 0
        with _open(self.path) as fh:
            line_no = 0
            while True:
                raw = fh.readline()
                if not raw:
                    raise CsvFormatError(f"CSV file {self.path} is empty")
                line_no += 1
                text = _decode(raw).strip("\r\n")
                if text.strip() and not text.lstrip().startswith("#"):
                    break
            self._data_offset = fh.tell()
        self._header_line = line_no  # 1-based line number of the header
        delim = delimiter if delimiter is not None else sniff_delimiter(text)
        try:
            header = [cell.strip() for cell in next(csv.reader([text], delimiter=delim))]
        except csv.Error as err:  # e.g. a lone carriage return inside the line
            raise CsvFormatError(f"CSV file {self.path}: header (line {line_no}) cannot be "
                                 f"split into columns: {err}") from err
        self.header = header
        self.layout: CsvLayout = resolve_layout(self.path, header, delim,
                                                **options)  # type: ignore[arg-type]

    @property
    def source(self) -> CsvSource:
        """The source metadata, with the row count of the last complete pass."""
        return replace(self.layout.source, rows=self.rows)

    # ------------------------------------------------------------------ reading
    def __iter__(self) -> Iterator[CsvChunk]:
        """Chunks of converted rows, in file order (one pass)."""
        n_rows = n_pressures = 0
        line = self._header_line  # lines consumed so far
        last_t = -math.inf
        with _open(self.path) as fh:
            fh.seek(self._data_offset)
            while True:
                raw = fh.read(self.chunk_bytes)
                if not raw:
                    break
                if not raw.endswith(b"\n"):
                    raw += fh.readline()  # whole lines only
                # data are numeric (ASCII): latin-1 never fails and keeps line numbers
                lines = raw.decode("latin-1").splitlines()
                del raw
                vals = self._parse(lines, line, n_rows)
                line += len(lines)
                if vals.shape[0] == 0:
                    continue
                chunk = self._convert(vals, n_rows, last_t)
                n_rows += vals.shape[0]
                if chunk.t.size == 0:
                    continue  # time stamps alone
                n_pressures += int(np.count_nonzero(np.isfinite(chunk.p)))
                last_t = float(chunk.t[-1])
                yield chunk
        if n_rows == 0:
            raise CsvFormatError(f"CSV file {self.path} has a header but no data rows")
        if n_pressures == 0:
            raise CsvFormatError(f"CSV file {self.path}: every cell of the pressure column "
                                 f"{self.layout.source.pressure_column!r} is empty")
        self.rows = n_rows

    def _parse(self, lines: list[str], line0: int, row0: int) -> FloatArray:
        """Cells used of the rows in ``lines`` (line0: lines before them; row0: data rows
        before them), shape (rows, columns used), in the file's units."""
        lay = self.layout
        d = lay.source.delimiter
        cols = lay.columns
        # fast path: every line has the header's number of fields and all cells parse
        if lines and all(lines):
            fast = [ln.replace(",", ".") for ln in lines] if d != "," else lines
            if sum(ln.count(d) for ln in fast) == len(fast) * (len(self.header) - 1):
                try:
                    vals = np.loadtxt(fast, delimiter=d, usecols=cols, dtype=float,
                                      comments=None, ndmin=2, quotechar='"')
                except ValueError:
                    vals = None
                if (vals is not None and vals.shape == (len(lines), len(cols))
                        and np.isfinite(vals).all()):
                    return vals
        return self._parse_slow(lines, line0, row0)

    def _parse_slow(self, lines: list[str], line0: int, row0: int) -> FloatArray:
        """Row by row, with the message of the first bad row."""
        lay = self.layout
        d = lay.source.delimiter
        cols = lay.columns
        kinds = ("time", "pressure", "temperature")
        width = max(cols) + 1
        n_head = len(self.header)
        out: list[list[float]] = []
        for k, row in enumerate(csv.reader(lines, delimiter=d)):
            line = line0 + k + 1
            if not any(cell.strip() for cell in row):
                continue
            if len(row) > n_head and any(cell.strip() for cell in row[n_head:]):
                raise CsvFormatError(self._too_many(line, len(row)))
            if len(row) < width:
                raise CsvFormatError(
                    f"{self.path}:{line}: row has {len(row)} fields, expected {n_head}")
            vals = []
            for i, kind in zip(cols, kinds, strict=False):
                cell = row[i].strip()
                if not cell and kind != "time":
                    # a multi-rate logger leaves a slower channel's cells empty between
                    # its samples: NaN, skipped by the readers of that channel
                    vals.append(math.nan)
                    continue
                try:
                    value = float(cell.replace(",", ".") if d != "," else cell)
                except ValueError:
                    what = "an empty cell" if not cell else f"non-numeric value {cell!r}"
                    raise CsvFormatError(
                        f"{self.path}:{line} (data row {row0 + len(out) + 1}): {what} in "
                        f"column {self.header[i]!r} ({kind})") from None
                if not math.isfinite(value):
                    raise CsvFormatError(
                        f"{self.path}:{line} (data row {row0 + len(out) + 1}): non-finite "
                        f"value {cell!r} in column {self.header[i]!r} ({kind})")
                vals.append(value)
            out.append(vals)
        return np.asarray(out, dtype=float).reshape(len(out), len(cols))

    def _too_many(self, line: int, n: int) -> str:
        """Message for a row of n fields, more than the header's."""
        n_head = len(self.header)
        msg = (f"{self.path}:{line}: row has {n} fields, more than the {n_head} of the header "
               f"{self.header!r}")
        if self.layout.source.delimiter == ",":
            return (msg + ": decimal commas with ',' as the field separator? ('0,5,700,3' "
                    "is read as 4 fields). Save the file with ';' as the separator (decimal "
                    "commas are then read) or with decimal points")
        return msg + ": a missing header cell or a stray separator?"

    def _convert(self, vals: FloatArray, row0: int, last_t: float) -> CsvChunk:
        """SI values of parsed rows, checked (row0: data rows before them; last_t: time of
        the row before them [s])."""
        lay = self.layout
        vals = vals[~np.all(np.isnan(vals[:, 1:]), axis=1)]  # rows of a time stamp alone
        t = vals[:, 0] * lay.time_scale
        steps = np.diff(t, prepend=last_t)
        if np.any(steps <= 0.0):
            bad = row0 + int(np.argmax(steps <= 0.0)) + 1
            raise CsvFormatError(f"{self.path}: time does not increase at data row {bad} (a "
                                 f"reversed or merged record? sort the rows by time)")
        p = vals[:, 1] * lay.pressure_scale
        if lay.source.gauge:
            p = p + lay.pressure_offset
        if np.any(p <= 0.0):
            k = int(np.argmax(p <= 0.0))
            hint = "" if lay.source.gauge else (
                " (gauge readings? pass gauge=True, atmosphere=p_atm [Pa]; command line: "
                "--gauge --atmosphere PA)")
            raise CsvFormatError(f"{self.path}: absolute pressure {p[k]:.6g} Pa <= 0 at data "
                                 f"row {row0 + k + 1}{hint}")
        temperature = None
        if lay.i_temp is not None:
            temperature = vals[:, 2] + lay.temperature_offset
            if np.any(temperature <= 0.0):
                k = int(np.argmax(temperature <= 0.0))
                raise CsvFormatError(
                    f"{self.path}: temperature {temperature[k]:.6g} K <= 0 at data row "
                    f"{row0 + k + 1} (wrong temperature_unit?)")
        return CsvChunk(t=np.ascontiguousarray(t), p=np.ascontiguousarray(p),
                        temperature=temperature if temperature is None
                        else np.ascontiguousarray(temperature), first_row=row0 + 1)


def read_csv_trace(
    path: str | os.PathLike[str],
    *,
    time_column: str | None = None,
    pressure_column: str | None = None,
    temperature_column: str | None = None,
    pressure_unit: str | None = None,
    temperature_unit: str | None = None,
    time_unit: str | None = None,
    gauge: bool | None = None,
    atmosphere: float | None = None,
    delimiter: str | None = None,
    chunk_bytes: int = CHUNK_BYTES,
) -> CsvTrace:
    """Read a data-logger CSV file (header row, then one numeric row per sample).

    Columns are found by header name unless given (time: 'time...', 't'; pressure:
    '...pressure...', 'p'; temperature: 'temp...'; the temperature column is optional).
    Units: an explicit argument, else the bracketed unit in the column header
    ('Pressure [kPa]', 'Temp [C]', 'Time [ms]', gauge markers like '[kPa g]', '[psig]',
    '[bar(a)]'), else the default (Pa, C, s; named in ``source.warnings``). An argument
    that contradicts the header is an error. Lines before the header that start with '#'
    and blank lines are skipped.

    Args:
        path: the CSV file.
        time_column: header of the time column (full text or name without unit).
        pressure_column: header of the pressure column.
        temperature_column: header of the gas temperature column.
        pressure_unit: unit of the pressure column: Pa, hPa, kPa, MPa, mbar, bar or psi.
        temperature_unit: unit of the temperature column: C or K.
        time_unit: unit of the time column: s, ms, us, min or h.
        gauge: True if the pressures are gauge readings (relative to ``atmosphere``);
            None: from a gauge/absolute marker in the header, else absolute.
        atmosphere: atmospheric pressure added to gauge readings [Pa absolute]; required
            with gauge pressures, ignored with absolute ones (``source.atmosphere`` is None).
        delimiter: field separator; default: sniffed from the header (',', ';' or tab).
            With ';' or tab, decimal commas are read as decimal points.
        chunk_bytes: text parsed at a time [B] (the result does not depend on it).

    Returns:
        The trace: t [s], p [Pa absolute], temperature [K] or None, and its source metadata.

    Raises:
        CsvFormatError: empty file, missing or ambiguous column (the available ones are
            listed), non-numeric or non-finite cell or a row with more fields than the
            header (with its line number), time not increasing, unknown unit in a header,
            pressure not positive once absolute.
        CsvOptionError: unknown unit argument, unit or gauge flag contradicting the header,
            gauge without atmosphere.
    """
    stream = CsvStream(path, chunk_bytes=chunk_bytes, delimiter=delimiter,
                       time_column=time_column, pressure_column=pressure_column,
                       temperature_column=temperature_column, pressure_unit=pressure_unit,
                       temperature_unit=temperature_unit, time_unit=time_unit, gauge=gauge,
                       atmosphere=atmosphere)
    chunks = list(stream)
    t = np.concatenate([c.t for c in chunks])
    p = np.concatenate([c.p for c in chunks])
    temperature = None
    if stream.layout.i_temp is not None:
        temperature = np.concatenate([c.temperature for c in chunks
                                      if c.temperature is not None])
    return CsvTrace(t=t, p=p, temperature=temperature, source=stream.source)
