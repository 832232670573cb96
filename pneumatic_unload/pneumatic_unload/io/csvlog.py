# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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

import contextlib
import csv
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final

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
    HintWords,
    check_words,
    named,
    resolve_layout,
    say,
    sniff_delimiter,
)
from pneumatic_unload.io.csvtext import CsvText, CsvTextError, open_text
from pneumatic_unload.io.csvtime import ClockParser, TimeAxis, TimeError, detect_form

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


class CsvStream:
    """A CSV trace read in chunks; each iteration is one pass over the file.

    The header is read and resolved at construction (errors in it are raised there), with
    the first data row (what the time column holds: numbers, epoch stamps, date-times or
    times of day, :mod:`~pneumatic_unload.io.csvtime`) and the file's encoding (UTF-8 or
    latin-1, UTF-8, UTF-16 or UTF-32 with a byte-order mark, UTF-16 without one; see
    :mod:`~pneumatic_unload.io.csvtext`). The rows are read up to the last line end the file
    had then: a last line without one (a file still being written) is left out, named in
    ``source.warnings``. The rows are checked as they are read: a row with fewer cells than
    the columns used or more non-empty fields than the header, a non-numeric or non-finite
    cell, a time cell unlike the first row's, time not increasing (a counter that wraps is
    unwrapped first, named in :attr:`notes`) and a pressure not positive once absolute are
    :class:`CsvFormatError` naming the line.

    Args:
        path: the CSV file.
        chunk_bytes: text read per chunk [B] (whole lines; at least one line).
        **options: as :func:`read_csv_trace` (columns, units, gauge, atmosphere [Pa],
            delimiter, hints).

    Attributes:
        layout: the resolved header (:class:`~pneumatic_unload.io.csvheader.CsvLayout`).
        rows: data rows read by the last complete pass [-] (0 before one).
        notes: what the last pass found beyond the header's warnings (a counter unwrapped).
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_bytes: int = CHUNK_BYTES,
                 delimiter: str | None = None, hints: HintWords = "library",
                 **options: object) -> None:
        self.path = Path(path)
        self.chunk_bytes = max(1, int(chunk_bytes))
        self.rows = 0
        self.notes: tuple[str, ...] = ()
        words = check_words(hints)
        try:
            text = open_text(self.path)
        except CsvTextError as err:
            raise CsvFormatError(str(err)) from None
        self._text = text
        try:
            header_text, line_no = self._header(text)
            self._data_offset = text.offset
            first_text = self._first_row_text(text)
        except CsvTextError as err:
            raise CsvFormatError(f"CSV file {self.path}: {err}") from None
        finally:
            text.close()
        self._header_line = line_no  # 1-based line number of the header
        delim = delimiter if delimiter is not None else sniff_delimiter(header_text)
        header = self._split(header_text, delim, line_no)
        first = None
        if first_text is not None:
            with contextlib.suppress(csv.Error):
                first = [cell.strip() for cell in next(csv.reader([first_text],
                                                                  delimiter=delim))]
        self.header = header
        layout = resolve_layout(self.path, header, delim, first_row=first, hints=words,
                                **options)  # type: ignore[arg-type]
        extra: tuple[str, ...] = ()
        if text.torn_tail and text.data_end >= self._data_offset:
            extra = (f"the last line has no line end (a file still being written?): left "
                     f"out: {text.torn_tail!r}; a complete file ends with a line end",)
        self.layout: CsvLayout = replace(layout, source=replace(
            layout.source, warnings=layout.source.warnings + extra,
            encoding=text.format.name))
        self._rows_at: tuple[int, int, dict[int, int] | None] = (0, 0, None)

    def _header(self, text: CsvText) -> tuple[str, int]:
        """The header line (the first that is neither blank nor a '#' comment) and its
        1-based line number."""
        line_no = 0
        while True:
            got = text.next_line()
            if got is None:
                raise CsvFormatError(f"CSV file {self.path} is empty")
            line_no += 1
            line = got[0].lstrip("\ufeff")
            if line.strip() and not line.lstrip().startswith("#"):
                return line, line_no

    def _first_row_text(self, text: CsvText) -> str | None:
        """The first data row that is not blank (its time cell tells the column's form),
        None without one before the rows' end."""
        while text.offset < text.data_end:
            got = text.next_line()
            if got is None:
                return None
            if got[0].strip():
                return got[0]
        return None

    def _split(self, line: str, delim: str, line_no: int) -> list[str]:
        """The header's cells."""
        if "\r" in line:
            raise CsvFormatError(
                f"CSV file {self.path}: header (line {line_no}) cannot be split into "
                "columns: it holds a lone carriage return (lines ended with CR alone, as on "
                "old Macs? save the file with LF or CRLF line ends)")
        if "\0" in line:
            raise CsvFormatError(
                f"CSV file {self.path}: header (line {line_no}) cannot be split into "
                "columns: it holds NUL characters (not a text file, or an encoding not "
                "told by a byte-order mark: save it as UTF-8)")
        try:
            return [cell.strip() for cell in next(csv.reader([line], delimiter=delim))]
        except csv.Error as err:
            raise CsvFormatError(f"CSV file {self.path}: header (line {line_no}) cannot be "
                                 f"split into columns: {err}") from err

    @property
    def source(self) -> CsvSource:
        """The source metadata, with the row count and the notes of the last complete
        pass."""
        return replace(self.layout.source, rows=self.rows,
                       warnings=self.layout.source.warnings + self.notes)

    # ------------------------------------------------------------------ reading
    def _where(self, k: int) -> str:
        """Names data row k (1-based, of the chunk being read) in messages, with its line."""
        row0, line0, line_of = self._rows_at
        line = line_of.get(k) if line_of is not None else line0 + k - row0
        return f"{self.path}:{line} (data row {k})" if line else f"{self.path} (data row {k})"

    def __iter__(self) -> Iterator[CsvChunk]:
        """Chunks of converted rows, in file order (one pass)."""
        n_rows = n_pressures = 0
        line = self._header_line  # lines consumed so far
        lay = self.layout
        self._clock = ClockParser(lay.time_form, self._where)
        axis = TimeAxis(lay.time_form, lay.time_scale, from_first_row=lay.from_first_row,
                        where=self._where)
        try:
            fmt = self._text.format
            for box in self._text.row_chunks(self._data_offset, self.chunk_bytes):
                lines = fmt.decode_rows(box.pop()).splitlines()
                vals = self._parse(lines, line, n_rows)
                line += len(lines)
                if vals.shape[0] == 0:
                    continue
                chunk = self._convert(vals, n_rows, axis)
                n_rows += vals.shape[0]
                if chunk.t.size == 0:
                    continue  # time stamps alone
                n_pressures += int(np.count_nonzero(np.isfinite(chunk.p)))
                yield chunk
        except CsvTextError as err:
            raise CsvFormatError(str(err)) from None
        if n_rows == 0:
            torn = (" (its last line, without a line end, is left out: a file still being "
                    "written?)" if self._text.torn_tail
                    and self._text.data_end >= self._data_offset else "")
            raise CsvFormatError(f"CSV file {self.path} has a header but no data rows{torn}")
        if n_pressures == 0:
            raise CsvFormatError(f"CSV file {self.path}: every cell of the pressure column "
                                 f"{self.layout.source.pressure_column!r} is empty")
        self.rows = n_rows
        self.notes = ()
        if axis.wraps and lay.time_form.kind == "time of day":
            self.notes = (f"the times of day in {lay.source.time_column!r} pass midnight "
                          f"{axis.wraps} time(s), first at data row {axis.first_wrap_row}: "
                          "read as the next day",)
        elif axis.wraps:
            self.notes = (f"the time column {lay.source.time_column!r} is a counter that "
                          f"wraps at {axis.modulus:.0f}: unwrapped {axis.wraps} time(s), "
                          f"first at data row {axis.first_wrap_row}",)

    def _parse(self, lines: list[str], line0: int, row0: int) -> FloatArray:
        """Cells used of the rows in ``lines`` (line0: lines before them; row0: data rows
        before them), shape (rows, columns used), in the file's units (a text time column:
        in s from :class:`~pneumatic_unload.io.csvtime.ClockParser`)."""
        lay = self.layout
        d = lay.source.delimiter
        cols = lay.columns
        # fast path: every line has the header's number of fields and all cells parse
        self._rows_at = (row0, line0, None)
        if lines and all(lines) and lay.time_form.text:
            vals = self._parse_text_fast(lines)
            if vals is not None:
                return vals
        if lines and all(lines) and not lay.time_form.text:
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

    def _parse_text_fast(self, lines: list[str]) -> FloatArray | None:
        """Rows of a text time column, all at once: every line with the header's number of
        fields, no quotes, the time cells laid out alike and the other cells numbers; None
        otherwise (the rows are then read one by one, with the message of a bad one)."""
        lay = self.layout
        d = lay.source.delimiter
        n = len(self.header)
        if any('"' in ln for ln in lines):
            return None
        rows = [ln.split(d) for ln in lines]
        if any(len(r) != n for r in rows):
            return None
        date_cells = [r[lay.i_date] for r in rows] if lay.i_date is not None else None
        t = self._clock.parse_many([r[lay.i_time] for r in rows], date_cells)
        if t is None:
            return None
        others = lay.columns[1:]
        fast = [ln.replace(",", ".") for ln in lines] if d != "," else lines
        try:
            vals = np.loadtxt(fast, delimiter=d, usecols=others, dtype=float,
                              comments=None, ndmin=2)
        except ValueError:
            return None
        if vals.shape != (len(lines), len(others)) or not np.isfinite(vals).all():
            return None
        return np.column_stack((t, vals))

    def _parse_slow(self, lines: list[str], line0: int, row0: int) -> FloatArray:
        """Row by row, with the message of the first bad row."""
        lay = self.layout
        d = lay.source.delimiter
        cols = lay.columns
        kinds = ("time", "pressure", "temperature")
        width = max((*cols, lay.i_date if lay.i_date is not None else 0)) + 1
        n_head = len(self.header)
        text_time = lay.time_form.text
        clock = self._clock
        line_of: dict[int, int] = {}  # data row -> line, for messages
        self._rows_at = (row0, line0, line_of)
        out: list[list[float]] = []
        for k, row in enumerate(csv.reader(lines, delimiter=d)):
            line = line0 + k + 1
            if not any(cell.strip() for cell in row):
                continue
            line_of[row0 + len(out) + 1] = line
            if len(row) > n_head and any(cell.strip() for cell in row[n_head:]):
                raise CsvFormatError(self._too_many(line, len(row)))
            if len(row) < width:
                raise CsvFormatError(
                    f"{self.path}:{line}: row has {len(row)} fields, expected {n_head}")
            vals = []
            for i, kind in zip(cols, kinds, strict=False):
                cell = row[i].strip()
                if kind == "time" and text_time:
                    try:
                        vals.append(clock.parse(
                            cell, row[lay.i_date] if lay.i_date is not None else None,
                            row0 + len(out) + 1))
                    except TimeError as err:
                        raise CsvFormatError(f"{err} (column {self.header[i]!r})") from None
                    continue
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
                        f"column {self.header[i]!r} ({kind}{self._form_hint(kind, cell)})"
                    ) from None
                if not math.isfinite(value):
                    raise CsvFormatError(
                        f"{self.path}:{line} (data row {row0 + len(out) + 1}): non-finite "
                        f"value {cell!r} in column {self.header[i]!r} ({kind})")
                vals.append(value)
            out.append(vals)
        return np.asarray(out, dtype=float).reshape(len(out), len(cols))

    def _form_hint(self, kind: str, cell: str) -> str:
        """What a time cell that is not a number should be."""
        if kind != "time" or not cell:
            return ""
        if detect_form(cell, None, decimal_comma=False).text:
            return (f": a {detect_form(cell, None, decimal_comma=False).kind} after the "
                    f"first row's number {self.layout.time_form.example!r}: the column "
                    "mixes forms")
        return ("; time cells are numbers, ISO 8601 date-times (2026-03-04 10:15:02.125, "
                "with or without a zone), a date and a time of day, or times of day")

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

    def _convert(self, vals: FloatArray, row0: int, axis: TimeAxis) -> CsvChunk:
        """SI values of parsed rows, checked (row0: data rows before them; axis: the time
        column's state across chunks)."""
        lay = self.layout
        words = lay.hints
        keep = ~np.all(np.isnan(vals[:, 1:]), axis=1)  # rows of a time stamp alone
        kept = np.flatnonzero(keep)
        vals = vals[keep]
        try:
            t = axis.seconds(vals[:, 0], kept + row0 + 1)
        except TimeError as err:
            raise CsvFormatError(str(err)) from None
        p = vals[:, 1] * lay.pressure_scale
        if lay.source.gauge:
            p = p + lay.pressure_offset
        if np.any(p <= 0.0):
            k = int(np.argmax(p <= 0.0))
            hint = "" if lay.source.gauge else (
                f" (gauge readings? pass {say('gauge', words)}"
                + (", atmosphere=p_atm [Pa])" if words == "library" else " --atmosphere PA)"))
            raise CsvFormatError(f"{self.path}: absolute pressure {p[k]:.6g} Pa <= 0 at data "
                                 f"row {int(kept[k]) + row0 + 1}{hint}")
        temperature = None
        if lay.i_temp is not None:
            temperature = vals[:, 2] + lay.temperature_offset
            if np.any(temperature <= 0.0):
                k = int(np.argmax(temperature <= 0.0))
                raise CsvFormatError(
                    f"{self.path}: temperature {temperature[k]:.6g} K <= 0 at data row "
                    f"{int(kept[k]) + row0 + 1} (wrong {named('temperature_unit', words)}?)")
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
    hints: HintWords = "library",
) -> CsvTrace:
    """Read a data-logger CSV file (header row, then one numeric row per sample).

    Columns are found by header name unless given (time: 'time...', 't', 'timestamp',
    'zeit...', 'Date/Time'; with a time of day, a 'date' or 'datum' column is its date;
    pressure: 'p', 'p1', ``P_...``, '...pressure...', '...druck...', not 'p_atm', 'P_amb';
    temperature: 'temp...', 'T_Gas'; the temperature column is optional; several columns
    that fit are an error listing them). The time column holds numbers in a time unit,
    epoch seconds or milliseconds (told by their magnitude,
    :data:`~pneumatic_unload.io.csvtime.EPOCH_RANGE_S`), ISO 8601 date-times with or
    without a zone, a logger's date and time (04.03.2026 10:15:02,125) or times of day; a
    counter that wraps (16, 24 or 32 bits) is unwrapped.
    Units: an explicit argument, else the unit in brackets or parentheses in the column
    header ('Pressure [kPa]', 'P_Tank (bar)', 'Temp [C]', 'Time [ms]', gauge markers like
    '[kPa g]', '[psig]', '[bar(a)]'), else the default (Pa, C, s; named in
    ``source.warnings``). An argument that contradicts the header is an error. Lines before
    the header that start with '#' and blank lines are skipped.

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
        hints: whose words the hints of errors and warnings use: "library"
            (``pressure_column=``) or "cli" (``--pressure-column NAME``).

    Returns:
        The trace: t [s], p [Pa absolute], temperature [K] or None, and its source metadata.

    Raises:
        CsvFormatError: empty file, missing or ambiguous column (the available ones are
            listed), non-numeric or non-finite cell or a row with more fields than the
            header (with its line number), time not increasing (with its likely cause), a
            time cell unlike the first row's (named by its row), unknown unit in a header,
            pressure not positive once absolute.
        CsvOptionError: unknown unit argument, unit or gauge flag contradicting the header,
            gauge without atmosphere, a time unit given for date-times.
    """
    stream = CsvStream(path, chunk_bytes=chunk_bytes, delimiter=delimiter,
                       time_column=time_column, pressure_column=pressure_column,
                       temperature_column=temperature_column, pressure_unit=pressure_unit,
                       temperature_unit=temperature_unit, time_unit=time_unit, gauge=gauge,
                       atmosphere=atmosphere, hints=hints)
    chunks = list(stream)
    t = np.concatenate([c.t for c in chunks])
    p = np.concatenate([c.p for c in chunks])
    temperature = None
    if stream.layout.i_temp is not None:
        temperature = np.concatenate([c.temperature for c in chunks
                                      if c.temperature is not None])
    return CsvTrace(t=t, p=p, temperature=temperature, source=stream.source)
