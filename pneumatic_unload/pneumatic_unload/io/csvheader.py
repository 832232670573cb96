"""Header of a data-logger CSV file: columns, units, separator; the errors of the reader.

:func:`resolve_layout` finds the time, pressure and (optional) gas-temperature columns of a
header row and resolves their units from the caller, the bracketed unit of the header
(``Time [s]``, ``Pressure [kPa]``, ``Temp [C]``) or the default (s, Pa, C); where each unit
came from is recorded in :class:`CsvSource` (``"argument"``, ``"header"`` or
``"default"``), a defaulted unit gives a warning in ``CsvSource.warnings``, and an explicit
unit that contradicts the header is an error rather than a silent factor of 1000. The rows
are read by :mod:`pneumatic_unload.io.csvlog`. SI units: s, Pa absolute, K.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

__all__ = [
    "PRESSURE_UNITS",
    "TEMPERATURE_UNITS",
    "TIME_UNITS",
    "CsvError",
    "CsvFormatError",
    "CsvLayout",
    "CsvOptionError",
    "CsvSource",
    "UnitSource",
    "resolve_layout",
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

UnitSource = Literal["argument", "header", "default"]

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
    #: what was assumed without being stated (a unit not in the header nor given)
    warnings: tuple[str, ...] = ()


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
    kind: str, names: list[tuple[str, str | None]], header: list[str], test: object
) -> int | None:
    """Index of the one column whose name passes ``test``; None if no column does."""
    hits = [i for i, (name, _) in enumerate(names) if test(name.lower())]  # type: ignore[operator]
    if len(hits) > 1:
        cands = ", ".join(repr(header[i]) for i in hits)
        raise CsvFormatError(
            f"several columns look like {kind}: {cands}; pass {kind}_column= to choose"
        )
    return hits[0] if hits else None


def _find(column: str, names: list[tuple[str, str | None]], header: list[str]) -> int | None:
    """Index of an explicitly named column (full header text or name without unit)."""
    for i, cell in enumerate(header):
        if cell.strip() == column.strip():
            return i
    hits = [i for i, (name, _) in enumerate(names) if name.lower() == column.strip().lower()]
    return hits[0] if len(hits) == 1 else None


def _is_time(name: str) -> bool:
    return name in ("t", "time", "timestamp", "elapsed", "seconds") or name.startswith("time")


def _is_pressure(name: str) -> bool:
    return name in ("p", "pres", "press") or "pressure" in name


def _is_temperature(name: str) -> bool:
    """A gas-temperature column by its name: 'temp...', 't_gas', or any name with
    'temperature' in it that is not the wall's, the room's or the ambient's."""
    other = any(w in name for w in ("wall", "room", "ambient", "amb_", "outside"))
    return (name.startswith("temp") or name in ("t_gas", "gas temperature")
            or "temperature" in name) and not other


def _unit(
    what: str,
    given: str | None,
    header_unit: str | None,
    table: dict[str, float],
    default: str,
    column: str,
) -> tuple[str, UnitSource]:
    """Resolve a (non-pressure) unit from the argument, the header bracket, or the default."""
    from_header = _lookup(header_unit, table) if header_unit else None
    if header_unit and from_header is None and given is None:
        raise CsvFormatError(
            f"column {column!r} has unit {header_unit!r}, not a known {what} unit "
            f"({', '.join(table)}); pass {what}_unit="
        )
    if given is None:
        return (from_header, "header") if from_header else (default, "default")
    unit = _lookup(given, table)
    if unit is None:
        raise CsvOptionError(f"{what}_unit={given!r} is not one of {', '.join(table)}")
    if from_header and from_header != unit:
        raise CsvOptionError(
            f"{what}_unit={given!r} contradicts the header of column {column!r} "
            f"({header_unit!r}); fix the header or the argument"
        )
    return unit, "argument"




#: How to state each column's unit (a warning names it when the unit was assumed).
_HOW_TO_STATE: Final = {
    "time": "time_unit= (command line: --time-unit)",
    "pressure": "pressure_unit= (command line: --pressure-unit)",
    "temperature": "temperature_unit= (command line: --temperature-unit)",
}


def default_unit_warning(kind: str, column: str, unit: str) -> str:
    """One line: the ``kind`` column ``column`` had no unit, ``unit`` was assumed, and how
    to state it (the header or the argument)."""
    example = {"time": "s", "pressure": "kPa", "temperature": "C"}[kind]
    return (f"column {column!r} ({kind}) has no unit in the header: {unit} assumed; state "
            f"it in the header ('{column} [{example}]') or with {_HOW_TO_STATE[kind]}")


def sniff_delimiter(header_line: str) -> str:
    """The field separator of a header line: the most frequent of ',', ';' and tab (',' when
    none occurs)."""
    counts = {d: header_line.count(d) for d in (",", ";", "\t")}
    return max(counts, key=lambda d: counts[d]) if any(counts.values()) else ","


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
) -> CsvLayout:
    """Columns and units of a CSV file from its header cells and the caller's options.

    Args:
        file: the CSV file (for messages).
        header: the header cells, stripped.
        delimiter: the field separator.
        time_column, pressure_column, temperature_column, pressure_unit, temperature_unit,
            time_unit, gauge, atmosphere: as :func:`pneumatic_unload.io.read_csv_trace`
            (atmosphere in Pa absolute).

    Returns:
        The layout; its ``source.rows`` is 0.

    Raises:
        CsvFormatError: missing or ambiguous column, unknown unit in a header.
        CsvOptionError: unknown unit argument, unit or gauge flag contradicting the header,
            gauge without atmosphere, the same column for two quantities.
    """
    names = [_split_header(cell) for cell in header]
    available = ", ".join(repr(h) for h in header)

    def locate(kind: str, given: str | None, test: object, required: bool) -> int | None:
        if given is not None:
            idx = _find(given, names, header)
            if idx is None:
                raise CsvFormatError(
                    f"{file} has no column {given!r} ({kind}_column); columns: {available}"
                )
            return idx
        idx = _choose(kind, names, header, test)
        if idx is None and required:
            raise CsvFormatError(
                f"{file}: no {kind} column found by name; columns: {available}; "
                f"pass {kind}_column="
            )
        return idx

    i_time = locate("time", time_column, _is_time, True)
    i_press = locate("pressure", pressure_column, _is_pressure, True)
    i_temp = locate("temperature", temperature_column, _is_temperature, False)
    assert i_time is not None and i_press is not None
    used = [i for i in (i_time, i_press, i_temp) if i is not None]
    if len(set(used)) < len(used):
        raise CsvOptionError("time, pressure and temperature must be different columns")

    # units ----------------------------------------------------------------------------
    t_unit, t_from = _unit("time", time_unit, names[i_time][1], TIME_UNITS, "s", header[i_time])
    p_header = names[i_press][1]
    parsed = _pressure_unit(p_header) if p_header else None
    if p_header and parsed is None and pressure_unit is None:
        raise CsvFormatError(
            f"column {header[i_press]!r} has unit {p_header!r}, not a known pressure unit "
            f"({', '.join(PRESSURE_UNITS)}); pass pressure_unit="
        )
    header_p_unit, header_gauge = parsed if parsed else (None, None)
    if pressure_unit is None:
        p_unit, p_from = (header_p_unit, "header") if header_p_unit else ("Pa", "default")
    else:
        given = _pressure_unit(pressure_unit)
        if given is None or given[1] is not None:
            raise CsvOptionError(
                f"pressure_unit={pressure_unit!r} is not one of {', '.join(PRESSURE_UNITS)} "
                "(say gauge=True for gauge readings)"
            )
        p_unit, p_from = given[0], "argument"
        if header_p_unit and header_p_unit != p_unit:
            raise CsvOptionError(
                f"pressure_unit={pressure_unit!r} contradicts the header of column "
                f"{header[i_press]!r} ({p_header!r}); fix the header or the argument"
            )
    g_from: UnitSource
    if gauge is None:
        if header_gauge is not None:
            is_gauge, g_from = header_gauge, "header"
        else:
            is_gauge, g_from = False, "default"
    else:
        if header_gauge is not None and header_gauge != gauge:
            raise CsvOptionError(
                f"gauge={gauge} contradicts the header of column {header[i_press]!r} "
                f"({p_header!r})"
            )
        is_gauge, g_from = bool(gauge), "argument"
    if is_gauge:
        if atmosphere is None:
            raise CsvOptionError(
                "gauge pressures need atmosphere= (the atmospheric pressure [Pa absolute], "
                "e.g. 101325.0) to become absolute"
            )
        if not (math.isfinite(atmosphere) and atmosphere > 0.0):
            raise CsvOptionError(f"atmosphere must be a positive pressure [Pa], got {atmosphere}")
    temp_unit: str | None = None
    temp_from: UnitSource | None = None
    if i_temp is not None:
        temp_unit, temp_from = _unit(
            "temperature", temperature_unit, names[i_temp][1], TEMPERATURE_UNITS, "C",
            header[i_temp],
        )

    warnings = []
    for kind, idx, unit, src in (("time", i_time, t_unit, t_from),
                                 ("pressure", i_press, p_unit, p_from),
                                 ("temperature", i_temp, temp_unit, temp_from)):
        if idx is not None and unit is not None and src == "default":
            warnings.append(default_unit_warning(kind, header[idx], unit))
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
        decimal_comma=delimiter != ",",
        warnings=tuple(warnings),
    )
    return CsvLayout(
        source=source, i_time=i_time, i_press=i_press, i_temp=i_temp,
        time_scale=TIME_UNITS[t_unit], pressure_scale=PRESSURE_UNITS[p_unit],
        pressure_offset=float(atmosphere) if is_gauge and atmosphere is not None else 0.0,
        temperature_offset=TEMPERATURE_UNITS[temp_unit] if temp_unit is not None else 0.0)
