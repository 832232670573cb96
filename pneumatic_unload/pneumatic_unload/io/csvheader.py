# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Header of a data-logger CSV file: columns, units, separator; the errors of the reader.

:func:`resolve_layout` finds the time, pressure and (optional) gas-temperature columns of a
header row and resolves their units from the caller, the bracketed unit of the header
(``Time [s]``, ``Pressure [kPa]``, ``Temp [C]``) or the default (s, Pa, C); where each unit
came from is recorded in :class:`CsvSource` (``"argument"``, ``"header"`` or
``"default"``), a defaulted unit gives a warning in ``CsvSource.warnings``, and an explicit
unit that contradicts the header is an error rather than a silent factor of 1000. The rows
are read by :mod:`pneumatic_unload.io.csvlog`. SI units: s, Pa absolute, K.

Every hint names the reader's options in one wording, chosen by the caller (``hints``):
the library's keyword arguments (``pressure_column=``) or the command line's options
(``--pressure-column NAME``), from :mod:`pneumatic_unload.io.csvnames`, which also holds the
column-name rules; what the time column holds is decided by
:mod:`pneumatic_unload.io.csvtime`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

from pneumatic_unload.io.csvnames import (
    ARGUMENT,
    OPTION_WORDS,
    HintWords,
    is_date,
    is_pressure,
    is_temperature,
    is_time,
    named,
    said,
    say,
)
from pneumatic_unload.io.csvtime import TimeForm, detect_form, epoch_iso, epoch_unit

__all__ = [
    "OPTION_WORDS",
    "PRESSURE_UNITS",
    "TEMPERATURE_UNITS",
    "TIME_UNITS",
    "CsvError",
    "CsvFormatError",
    "CsvLayout",
    "CsvOptionError",
    "CsvSource",
    "HintWords",
    "UnitSource",
    "named",
    "resolve_layout",
    "said",
    "say",
    "sniff_delimiter",
]

#: Pressure units accepted (case-insensitive) and their size [Pa].
PRESSURE_UNITS: Final[dict[str, float]] = {
    "Pa": 1.0,
    "hPa": 1e2,
    "kPa": 1e3,
    "MPa": 1e6,
    "mbar": 1e2,
    "bar": 1e5,
    "psi": 6894.757293168361,
}
#: Temperature units accepted: offset added to get K.
TEMPERATURE_UNITS: Final[dict[str, float]] = {"C": 273.15, "K": 0.0}
#: Time units accepted and their size [s].
TIME_UNITS: Final[dict[str, float]] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0, "h": 3600.0}

#: Where a unit came from: the caller, the header's bracket, the default, or the column's
#: values (epoch stamps told by their magnitude; date-times, in s by themselves).
UnitSource = Literal["argument", "header", "default", "values"]
def check_words(hints: object) -> HintWords:
    """``hints`` if it is a :data:`HintWords` value; raises CsvOptionError otherwise."""
    if hints not in ("library", "cli"):
        raise CsvOptionError(f"hints={hints!r} is not 'library' or 'cli'")
    return hints  # type: ignore[return-value]

_HEADER_RE = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]\s*$")
_GAUGE_SUFFIXES: Final = (
    ("gauge", True),
    ("g", True),
    ("absolute", False),
    ("abs", False),
    ("a", False),
)


class CsvError(Exception):
    """Base class of the errors of the CSV reader."""


class CsvFormatError(CsvError):
    """The file cannot be read as a trace (empty, missing column, non-numeric cell, ...)."""


class CsvOptionError(CsvError, ValueError):
    """The reader's options are inconsistent (e.g. gauge without atmosphere)."""


@dataclass(frozen=True)
class CsvSource:
    """Where a CSV trace came from and how its columns were interpreted."""

    path: Path
    rows: int  #: number of data rows
    delimiter: str
    columns: tuple[str, ...]  #: header cells as in the file
    time_column: str
    pressure_column: str
    temperature_column: str | None
    time_unit: str
    time_unit_from: UnitSource
    pressure_unit: str
    pressure_unit_from: UnitSource
    gauge: bool  #: the file holds gauge pressures (atmosphere was added)
    gauge_from: UnitSource
    atmosphere: float | None  #: atmospheric pressure added to gauge readings [Pa]
    temperature_unit: str | None
    temperature_unit_from: UnitSource | None
    #: decimal commas are read as decimal points (the separator is not ',')
    decimal_comma: bool = False
    #: what was assumed without being stated (a unit not in the header nor given), and
    #: what the reading found (a last line left out, a counter unwrapped)
    warnings: tuple[str, ...] = ()
    #: what the time column holds: 'number' (a clock, kept as it is), 'epoch' (stamps since
    #: 1970), 'date-time' or 'time of day' (the last three counted from the first row)
    time_form: str = "number"
    #: the first row's instant as written (ISO 8601; epoch stamps in UTC), None for a clock
    time_origin: str | None = None
    #: the date column read with a time of day, None without one
    date_column: str | None = None
    encoding: str = "UTF-8 or latin-1"  #: the file's encoding as detected


#: The form of a time column of numbers.
_NUMBER_FORM: Final = TimeForm("number")


@dataclass(frozen=True)
class CsvLayout:
    """The resolved header of a CSV file: which cells to read and how to convert them.

    ``source`` holds everything but the row count (0 until the rows are read).
    """

    source: CsvSource
    i_time: int  #: index of the time cell in a row [-]
    i_press: int  #: index of the pressure cell [-]
    i_temp: int | None  #: index of the temperature cell, None without one [-]
    time_scale: float  #: size of the time unit [s]
    pressure_scale: float  #: size of the pressure unit [Pa]
    pressure_offset: float  #: added to scaled pressures: p_atm for gauge readings [Pa]
    temperature_offset: float  #: added to temperatures: 273.15 for C [K]
    #: what the time column holds (numbers; date-times and times of day are text)
    time_form: TimeForm = _NUMBER_FORM
    from_first_row: bool = False  #: times are counted from the first row (epoch, date-time)
    i_date: int | None = None  #: index of the date cell read with a time of day [-]
    hints: HintWords = "library"  #: whose words the row errors' hints use

    @property
    def columns(self) -> tuple[int, ...]:
        """Indices of the cells read, in the order time, pressure[, temperature] [-]."""
        cols = (self.i_time, self.i_press)
        return cols if self.i_temp is None else (*cols, self.i_temp)


# ------------------------------------------------------------------------------ helpers


def _split_header(cell: str) -> tuple[str, str | None]:
    """('Pressure', 'kPa') for 'Pressure [kPa]' or 'Pressure (kPa)'; ('pressure', 'kPa')
    for 'pressure_kPa' (a known unit after the last underscore of a name of 3 or more
    characters, as loggers write column names: 'gas_temperature_c', 'time_s'); (cell,
    None) without a unit."""
    match = _HEADER_RE.match(cell.strip())
    if match and match.group("name"):
        return match.group("name").strip(), match.group("unit").strip()
    name, sep, tail = cell.strip().rpartition("_")
    if sep and len(name) >= 3 and (
            _pressure_unit(tail) is not None or _lookup(tail, TIME_UNITS) is not None
            or _lookup(tail, TEMPERATURE_UNITS) is not None):
        return name, tail
    # 'p_bar', 't_ms': a one-letter name with a unit of its own kind
    if sep and ((name.lower() == "p" and _pressure_unit(tail) is not None)
                or (name.lower() == "t" and _lookup(tail, TIME_UNITS) is not None)):
        return name, tail
    return cell.strip(), None


def _norm(unit: str) -> str:
    return unit.replace("°", "").replace("deg", "").replace(" ", "").lower()


def _lookup(unit: str, table: dict[str, float]) -> str | None:
    """Canonical spelling of ``unit`` in ``table`` (case-insensitive), or None."""
    key = _norm(unit)
    return next((name for name in table if name.lower() == key), None)


def _pressure_unit(text: str) -> tuple[str, bool | None] | None:
    """('kPa', True) for 'kPa g' / 'kPag' / 'kPa(gauge)'; None if not a pressure unit."""
    if (unit := _lookup(text, PRESSURE_UNITS)) is not None:
        return unit, None
    key = _norm(text).replace("(", "").replace(")", "")
    for suffix, is_gauge in _GAUGE_SUFFIXES:
        if key.endswith(suffix) and (unit := _lookup(key[: -len(suffix)], PRESSURE_UNITS)):
            return unit, is_gauge
    return None


def _choose(
    kind: str, names: list[tuple[str, str | None]], header: list[str],
    test: Callable[[str], bool], words: HintWords, file: Path,
) -> int | None:
    """Index of the one column whose name passes ``test``; None if no column does."""
    hits = [i for i, (name, _) in enumerate(names) if test(name.lower())]
    if len(hits) > 1:
        cands = ", ".join(repr(header[i]) for i in hits)
        raise CsvFormatError(
            f"{file}: several columns look like {kind}: {cands}; pass "
            f"{say(kind + '_column', words)} to choose"
        )
    return hits[0] if hits else None


def _find(column: str, names: list[tuple[str, str | None]], header: list[str]) -> int | None:
    """Index of an explicitly named column (full header text or name without unit)."""
    for i, cell in enumerate(header):
        if cell.strip() == column.strip():
            return i
    hits = [i for i, (name, _) in enumerate(names) if name.lower() == column.strip().lower()]
    return hits[0] if len(hits) == 1 else None


def _unit(
    what: str,
    given: str | None,
    header_unit: str | None,
    table: dict[str, float],
    default: str,
    column: str,
    words: HintWords,
) -> tuple[str, UnitSource]:
    """Resolve a (non-pressure) unit from the argument, the header bracket, or the default."""
    option = f"{what}_unit"
    from_header = _lookup(header_unit, table) if header_unit else None
    if header_unit and from_header is None and given is None:
        raise CsvFormatError(
            f"column {column!r} has unit {header_unit!r}, not a known {what} unit "
            f"({', '.join(table)}); pass {say(option, words)}"
        )
    if given is None:
        return (from_header, "header") if from_header else (default, "default")
    unit = _lookup(given, table)
    if unit is None:
        raise CsvOptionError(f"{said(option, words, given)} is not one of {', '.join(table)}")
    if from_header and from_header != unit:
        raise CsvOptionError(
            f"{said(option, words, given)} contradicts the header of column {column!r} "
            f"({header_unit!r}); fix the header or the {ARGUMENT[words]}"
        )
    return unit, "argument"


#: The unit of each kind shown in a hint's example header.
_EXAMPLE_UNIT: Final = {"time": "s", "pressure": "kPa", "temperature": "C"}


def default_unit_warning(kind: str, column: str, unit: str,
                         words: HintWords = "library") -> str:
    """One line: the ``kind`` column ``column`` had no unit, ``unit`` was assumed, and how
    to state it (the header or the option, in the caller's ``words``)."""
    return (f"column {column!r} ({kind}) has no unit in the header: {unit} assumed; state "
            f"it in the header ('{column} [{_EXAMPLE_UNIT[kind]}]') or with "
            f"{say(kind + '_unit', words)}")


def sniff_delimiter(header_line: str) -> str:
    """The field separator of a header line: the most frequent of ',', ';' and tab (',' when
    none occurs)."""
    counts = {d: header_line.count(d) for d in (",", ";", "\t")}
    return max(counts, key=lambda d: counts[d]) if any(counts.values()) else ","


def _first_number(cell: str, decimal_comma: bool) -> float | None:
    """The first row's time cell as a number, or None if it is not one."""
    try:
        value = float(cell.replace(",", ".") if decimal_comma else cell)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def resolve_layout(
    file: Path,
    header: list[str],
    delimiter: str,
    *,
    time_column: str | None = None,
    pressure_column: str | None = None,
    temperature_column: str | None = None,
    pressure_unit: str | None = None,
    temperature_unit: str | None = None,
    time_unit: str | None = None,
    gauge: bool | None = None,
    atmosphere: float | None = None,
    first_row: Sequence[str] | None = None,
    hints: HintWords = "library",
) -> CsvLayout:
    """Columns and units of a CSV file from its header cells and the caller's options.

    Args:
        file: the CSV file (for messages).
        header: the header cells, stripped.
        delimiter: the field separator.
        time_column, pressure_column, temperature_column, pressure_unit, temperature_unit,
            time_unit, gauge, atmosphere: as :func:`pneumatic_unload.io.read_csv_trace`
            (atmosphere in Pa absolute).
        first_row: the cells of the first data row: what the time column holds (numbers,
            epoch stamps, date-times, times of day; see :mod:`pneumatic_unload.io.csvtime`);
            None: numbers.
        hints: whose words the hints use: the library's ('pressure_column=') or the
            command line's ('--pressure-column NAME').

    Returns:
        The layout; its ``source.rows`` is 0.

    Raises:
        CsvFormatError: missing or ambiguous column, unknown unit in a header.
        CsvOptionError: unknown unit argument, unit or gauge flag contradicting the header,
            gauge without atmosphere, the same column for two quantities, a time unit
            given for date-times.
    """
    words = check_words(hints)
    names = [_split_header(cell) for cell in header]
    available = ", ".join(repr(h) for h in header)

    def locate(kind: str, given: str | None, test: Callable[[str], bool],
               required: bool) -> int | None:
        option = f"{kind}_column"
        if given is not None:
            idx = _find(given, names, header)
            if idx is None:
                raise CsvFormatError(
                    f"{file} has no column {given!r} ({said(option, words, given)}); "
                    f"columns: {available}"
                )
            return idx
        idx = _choose(kind, names, header, test, words, file)
        if idx is None and required:
            raise CsvFormatError(
                f"{file}: no {kind} column found by name; columns: {available}; "
                f"pass {say(option, words)}"
            )
        return idx

    dates = [i for i, (name, _) in enumerate(names) if is_date(name.lower())]
    i_date = dates[0] if len(dates) == 1 else None
    try:
        i_time = locate("time", time_column, is_time, True)
    except CsvFormatError:
        if i_date is None or first_row is None or len(first_row) <= i_date or \
                detect_form(first_row[i_date], None, decimal_comma=False).kind != \
                "date-time":
            raise
        i_time, i_date = i_date, None  # a 'Date' column holding whole date-times
    i_press = locate("pressure", pressure_column, is_pressure, True)
    i_temp = locate("temperature", temperature_column, is_temperature, False)
    assert i_time is not None and i_press is not None
    used = [i for i in (i_time, i_press, i_temp) if i is not None]
    if len(set(used)) < len(used):
        raise CsvOptionError("time, pressure and temperature must be different columns")

    # the time column's form -------------------------------------------------------------
    decimal_comma = delimiter != ","
    cell = first_row[i_time] if first_row is not None and len(first_row) > i_time else ""
    date_cell = (first_row[i_date] if first_row is not None and i_date is not None
                 and len(first_row) > i_date and i_date not in used else None)
    form = detect_form(cell, date_cell, decimal_comma=decimal_comma)
    notes: list[str] = []
    origin: str | None = None
    from_first = False
    t_unit: str
    t_from: UnitSource
    if form.text:
        if time_unit is not None:
            raise CsvOptionError(
                f"{said('time_unit', words, time_unit)} given, but column "
                f"{header[i_time]!r} holds {form.kind}s ({form.example!r}), read in s by "
                f"themselves; leave {named('time_unit', words)} out")
        t_unit, t_from, from_first, origin = "s", "values", True, form.example
        if not form.with_date_column:
            i_date = None
        if form.kind == "time of day" and i_date is None:
            notes.append(f"column {header[i_time]!r} holds times of day without a date: "
                         "a step back of more than 12 h is read as midnight (the next day)")
    else:
        i_date = None
        t_unit, t_from = _unit("time", time_unit, names[i_time][1], TIME_UNITS, "s",
                               header[i_time], words)
        first = _first_number(cell, decimal_comma)
        stated = None if t_from == "default" else t_unit
        epoch = epoch_unit(first, stated) if first is not None else None
        if epoch is not None:
            form = TimeForm("epoch", example=cell.strip())
            from_first, origin = True, epoch_iso(first * TIME_UNITS[epoch])  # type: ignore[arg-type]
            if t_from == "default":
                t_unit, t_from = epoch, "values"
            told = t_from == "values"
            how = f"; {epoch} told by the magnitude of {cell.strip()}" if told else ""
            notes.append(
                f"column {header[i_time]!r} holds epoch stamps in {epoch} (since "
                f"1970-01-01 UTC{how}): the first row is {origin}, times are counted from it"
                + (f"; if this is wrong, state the unit with {say('time_unit', words)}"
                   if told else ""))

    # units ----------------------------------------------------------------------------
    p_header = names[i_press][1]
    parsed = _pressure_unit(p_header) if p_header else None
    if p_header and parsed is None and pressure_unit is None:
        raise CsvFormatError(
            f"column {header[i_press]!r} has unit {p_header!r}, not a known pressure unit "
            f"({', '.join(PRESSURE_UNITS)}); pass {say('pressure_unit', words)}"
        )
    header_p_unit, header_gauge = parsed if parsed else (None, None)
    if pressure_unit is None:
        p_unit, p_from = (header_p_unit, "header") if header_p_unit else ("Pa", "default")
    else:
        given = _pressure_unit(pressure_unit)
        if given is None or given[1] is not None:
            raise CsvOptionError(
                f"{said('pressure_unit', words, pressure_unit)} is not one of "
                f"{', '.join(PRESSURE_UNITS)} (say {say('gauge', words)} for gauge readings)"
            )
        p_unit, p_from = given[0], "argument"
        if header_p_unit and header_p_unit != p_unit:
            raise CsvOptionError(
                f"{said('pressure_unit', words, pressure_unit)} contradicts the header of "
                f"column {header[i_press]!r} ({p_header!r}); fix the header or the "
                f"{ARGUMENT[words]}"
            )
    g_from: UnitSource
    if gauge is None:
        if header_gauge is not None:
            is_gauge, g_from = header_gauge, "header"
        else:
            is_gauge, g_from = False, "default"
    else:
        if header_gauge is not None and header_gauge != gauge:
            flag = said("gauge", words, gauge) if gauge or words == "cli" else "gauge=False"
            raise CsvOptionError(
                f"{flag} contradicts the header of column {header[i_press]!r} "
                f"({p_header!r})"
            )
        is_gauge, g_from = bool(gauge), "argument"
    if is_gauge:
        if atmosphere is None:
            raise CsvOptionError(
                f"gauge pressures need {say('atmosphere', words)} (the atmospheric pressure "
                "[Pa absolute], e.g. 101325.0) to become absolute"
            )
        if not (math.isfinite(atmosphere) and atmosphere > 0.0):
            raise CsvOptionError(
                f"{named('atmosphere', words)} must be a positive pressure [Pa], got "
                f"{atmosphere}")
    temp_unit: str | None = None
    temp_from: UnitSource | None = None
    if i_temp is not None:
        temp_unit, temp_from = _unit(
            "temperature", temperature_unit, names[i_temp][1], TEMPERATURE_UNITS, "C",
            header[i_temp], words,
        )

    warnings = []
    for kind, idx, unit, src in (("time", i_time, t_unit, t_from),
                                 ("pressure", i_press, p_unit, p_from),
                                 ("temperature", i_temp, temp_unit, temp_from)):
        if idx is not None and unit is not None and src == "default":
            warnings.append(default_unit_warning(kind, header[idx], unit, words))
    warnings.extend(notes)
    source = CsvSource(
        path=file,
        rows=0,
        delimiter=delimiter,
        columns=tuple(header),
        time_column=header[i_time],
        pressure_column=header[i_press],
        temperature_column=None if i_temp is None else header[i_temp],
        time_unit=t_unit,
        time_unit_from=t_from,
        pressure_unit=p_unit,
        pressure_unit_from=p_from,
        gauge=is_gauge,
        gauge_from=g_from,
        atmosphere=float(atmosphere) if is_gauge and atmosphere is not None else None,
        temperature_unit=temp_unit,
        temperature_unit_from=temp_from,
        decimal_comma=decimal_comma,
        warnings=tuple(warnings),
        time_form=form.kind,
        time_origin=origin,
        date_column=None if i_date is None else header[i_date],
    )
    return CsvLayout(
        source=source, i_time=i_time, i_press=i_press, i_temp=i_temp,
        time_scale=TIME_UNITS[t_unit], pressure_scale=PRESSURE_UNITS[p_unit],
        pressure_offset=float(atmosphere) if is_gauge and atmosphere is not None else 0.0,
        temperature_offset=TEMPERATURE_UNITS[temp_unit] if temp_unit is not None else 0.0,
        time_form=form, from_first_row=from_first, i_date=i_date, hints=words)

