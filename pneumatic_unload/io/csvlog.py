"""Data-logger CSV files of tank discharges: time, pressure and (optionally) gas temperature.

Units: the returned time is in s (starting wherever the logger clock starts), pressures in
Pa absolute, temperatures in K. Input units come from the caller or from the bracketed unit
of the column header (``Time [s]``, ``Pressure [kPa]``, ``Temp [C]``); where each unit came
from is recorded in :class:`CsvSource` (``"argument"``, ``"header"`` or ``"default"``), and an
explicit unit that contradicts the header is an error rather than a silent factor of 1000.

Example (the AeroLab file: gauge kPa, degrees C)::

    trace = read_csv_trace("orifice_0.094in.csv", gauge=True, atmosphere=101_500.0)
    trace.t[0], trace.p[0], trace.temperature[0]    # 28.0 s, 439290.0 Pa, 321.79 K
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

__all__ = [
    "PRESSURE_UNITS",
    "TEMPERATURE_UNITS",
    "TIME_UNITS",
    "CsvError",
    "CsvFormatError",
    "CsvOptionError",
    "CsvSource",
    "CsvTrace",
    "read_csv_trace",
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
    """Base class of the errors of :mod:`pneumatic_unload.io.csvlog`."""


class CsvFormatError(CsvError):
    """The file cannot be read as a trace (empty, missing column, non-numeric cell, ...)."""


class CsvOptionError(CsvError, ValueError):
    """The options of :func:`read_csv_trace` are inconsistent (e.g. gauge without atmosphere)."""


@dataclass(frozen=True)
class CsvSource:
    """Where a :class:`CsvTrace` came from and how its columns were interpreted."""

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


@dataclass(frozen=True)
class CsvTrace:
    """A tank-discharge trace read from a CSV file."""

    t: npt.NDArray[np.float64]  #: sample times [s], from the logger clock (not shifted to 0)
    p: npt.NDArray[np.float64]  #: tank pressure [Pa absolute]
    temperature: npt.NDArray[np.float64] | None  #: gas temperature [K], None if not logged
    source: CsvSource

    @property
    def t_ns(self) -> npt.NDArray[np.int64]:
        """Sample times as integer nanoseconds [ns] (for bags)."""
        return np.round(self.t * 1e9).astype(np.int64)


# ------------------------------------------------------------------------------ helpers


def _split_header(cell: str) -> tuple[str, str | None]:
    """('Pressure', 'kPa') for 'Pressure [kPa]'; (cell, None) without a bracketed unit."""
    match = _HEADER_RE.match(cell.strip())
    if match and match.group("name"):
        return match.group("name").strip(), match.group("unit").strip()
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
    return name.startswith("temp") or name in ("t_gas", "gas temperature")


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


def _read_lines(path: Path) -> list[str]:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise CsvFormatError(f"CSV file {path} does not exist") from None
    except OSError as err:
        raise CsvFormatError(f"cannot read CSV file {path}: {err}") from err
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.splitlines()


# ------------------------------------------------------------------------------- reader


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
) -> CsvTrace:
    """Read a data-logger CSV file (header row, then one numeric row per sample).

    Columns are found by header name unless given (time: 'time...', 't'; pressure:
    '...pressure...', 'p'; temperature: 'temp...'; the temperature column is optional).
    Units: an explicit argument, else the bracketed unit in the column header
    ('Pressure [kPa]', 'Temp [C]', 'Time [ms]', gauge markers like '[kPa g]', '[psig]',
    '[bar(a)]'), else the default (Pa, C, s). An argument that contradicts the header is an
    error. Lines before the header that start with '#' and blank lines are skipped.

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

    Returns:
        The trace: t [s], p [Pa absolute], temperature [K] or None, and its source metadata.

    Raises:
        CsvFormatError: empty file, missing or ambiguous column (the available ones are
            listed), non-numeric or non-finite cell (with its line number), time not
            increasing, unknown unit in a header, pressure not positive once absolute.
        CsvOptionError: unknown unit argument, unit or gauge flag contradicting the header,
            gauge without atmosphere.
    """
    file = Path(path)
    lines = _read_lines(file)
    first = next(
        (i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None
    )
    if first is None:
        raise CsvFormatError(f"CSV file {file} is empty")
    if delimiter is None:
        counts = {d: lines[first].count(d) for d in (",", ";", "\t")}
        delimiter = max(counts, key=lambda d: counts[d]) if any(counts.values()) else ","
    rows = list(csv.reader(lines[first:], delimiter=delimiter))
    header = [cell.strip() for cell in rows[0]]
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

    # values ---------------------------------------------------------------------------
    wanted = [(i_time, "time"), (i_press, "pressure")]
    if i_temp is not None:
        wanted.append((i_temp, "temperature"))
    values: list[list[float]] = [[] for _ in wanted]
    width = max(i for i, _ in wanted) + 1
    n_rows = 0
    for k, row in enumerate(rows[1:], start=1):
        line = first + k + 1  # 1-based line number in the file
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < width:
            raise CsvFormatError(
                f"{file}:{line}: row has {len(row)} fields, expected {len(header)}"
            )
        for j, (i, kind) in enumerate(wanted):
            cell = row[i].strip()
            try:
                value = float(cell)
            except ValueError:
                what = "an empty cell" if not cell else f"non-numeric value {cell!r}"
                raise CsvFormatError(
                    f"{file}:{line} (data row {n_rows + 1}): {what} in column "
                    f"{header[i]!r} ({kind})"
                ) from None
            if not math.isfinite(value):
                raise CsvFormatError(
                    f"{file}:{line} (data row {n_rows + 1}): non-finite value {cell!r} in "
                    f"column {header[i]!r} ({kind})"
                )
            values[j].append(value)
        n_rows += 1
    if n_rows == 0:
        raise CsvFormatError(f"CSV file {file} has a header but no data rows")

    t = np.asarray(values[0]) * TIME_UNITS[t_unit]
    if n_rows > 1 and np.any(np.diff(t) <= 0.0):
        bad = int(np.argmax(np.diff(t) <= 0.0)) + 2
        raise CsvFormatError(f"{file}: time does not increase at data row {bad} (a reversed "
                             f"or merged record? sort the rows by time)")
    p = np.asarray(values[1]) * PRESSURE_UNITS[p_unit]
    if is_gauge:
        assert atmosphere is not None
        p = p + atmosphere
    if np.any(p <= 0.0):
        bad = int(np.argmax(p <= 0.0)) + 1
        hint = "" if is_gauge else (" (gauge readings? pass gauge=True, atmosphere=p_atm [Pa];"
                                    " command line: --gauge --atmosphere PA)")
        raise CsvFormatError(
            f"{file}: absolute pressure {p[bad - 1]:.6g} Pa <= 0 at data row {bad}{hint}"
        )
    temperature = None
    if i_temp is not None:
        assert temp_unit is not None
        temperature = np.asarray(values[2]) + TEMPERATURE_UNITS[temp_unit]
        if np.any(temperature <= 0.0):
            bad = int(np.argmax(temperature <= 0.0)) + 1
            raise CsvFormatError(
                f"{file}: temperature {temperature[bad - 1]:.6g} K <= 0 at data row {bad} "
                "(wrong temperature_unit?)"
            )

    source = CsvSource(
        path=file,
        rows=n_rows,
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
    )
    return CsvTrace(t=t, p=p, temperature=temperature, source=source)
