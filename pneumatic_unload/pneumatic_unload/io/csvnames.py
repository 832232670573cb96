# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The names in a data-logger CSV file and in the reader's hints.

Which header names are the time, date, pressure and gas-temperature columns (the unit,
in brackets, parentheses or after an underscore, set aside by
:mod:`pneumatic_unload.io.csvheader`), and how a hint names each reader option: in the
library's words (``pressure_column=``) or the command line's (``--pressure-column NAME``),
as the caller chooses (:data:`HintWords`); :data:`OPTION_WORDS` holds both.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal

__all__ = [
    "ARGUMENT",
    "OPTION_WORDS",
    "OTHER_PRESSURE_WORDS",
    "TIME_NAMES",
    "HintWords",
    "OptionWords",
    "is_date",
    "is_pressure",
    "is_temperature",
    "is_time",
    "named",
    "said",
    "say",
    "unit_spelling",
]

#: Whose words a hint uses: the library's keyword arguments or the command line's options.
HintWords = Literal["library", "cli"]


@dataclass(frozen=True)
class OptionWords:
    """How one reader option is named in hints."""

    keyword: str  #: the library's keyword argument
    flag: str  #: the command line's option
    metavar: str  #: the command line's value placeholder ('' for a flag alone)


#: Every reader option as the library and the command line name it.
OPTION_WORDS: Final[dict[str, OptionWords]] = {
    "time_column": OptionWords("time_column", "--time-column", "NAME"),
    "pressure_column": OptionWords("pressure_column", "--pressure-column", "NAME"),
    "temperature_column": OptionWords("temperature_column", "--temperature-column", "NAME"),
    "time_unit": OptionWords("time_unit", "--time-unit", "UNIT"),
    "pressure_unit": OptionWords("pressure_unit", "--pressure-unit", "UNIT"),
    "temperature_unit": OptionWords("temperature_unit", "--temperature-unit", "UNIT"),
    "gauge": OptionWords("gauge", "--gauge", ""),
    "atmosphere": OptionWords("atmosphere", "--atmosphere", "PA"),
}


def say(name: str, words: HintWords) -> str:
    """How to pass option ``name`` in a hint: 'pressure_column=' (library) or
    '--pressure-column NAME' (command line); 'gauge=True' or '--gauge'."""
    w = OPTION_WORDS[name]
    if words == "cli":
        return f"{w.flag} {w.metavar}" if w.metavar else w.flag
    return f"{w.keyword}=True" if not w.metavar else f"{w.keyword}="


def said(name: str, words: HintWords, value: object) -> str:
    """Option ``name`` as given with ``value``: "pressure_unit='torr'" (library) or
    '--pressure-unit torr' (command line); a flag: 'gauge=True' or '--gauge'."""
    w = OPTION_WORDS[name]
    if words == "cli":
        return f"{w.flag} {value}" if w.metavar else w.flag
    return f"{w.keyword}={value!r}"


def named(name: str, words: HintWords) -> str:
    """Option ``name`` alone: 'time_unit' (library) or '--time-unit' (command line)."""
    w = OPTION_WORDS[name]
    return w.flag if words == "cli" else w.keyword


#: What the caller's settings are called in a hint.
ARGUMENT: Final[dict[str, str]] = {"library": "argument", "cli": "option"}

#: Words of a pressure column's name that make it another pressure than the tank's.
OTHER_PRESSURE_WORDS: Final = ("atm", "amb", "baro", "umgeb", "luftdruck", "setpoint",
                                "soll")
#: Names of a time column that holds date-times (besides names beginning 'time' or 'zeit').
TIME_NAMES: Final = frozenset((
    "t", "time", "timestamp", "elapsed", "seconds", "datetime", "date time", "date/time",
    "date_time", "date-time", "date & time", "uhrzeit", "datum/uhrzeit", "datum uhrzeit",
    "datum_uhrzeit", "datum/zeit", "datum zeit", "datum_zeit", "zeitstempel"))


def is_time(name: str) -> bool:
    """A time column by its name: 't', 'time...', 'timestamp', 'elapsed', 'zeit...',
    'datetime', 'Date/Time', 'Datum/Uhrzeit'."""
    return name in TIME_NAMES or name.startswith(("time", "zeit"))


def is_date(name: str) -> bool:
    """A date column (read with a time of day) by its name: 'date', 'datum'."""
    return name in ("date", "datum", "day")


def is_pressure(name: str) -> bool:
    """A pressure column by its name: 'p', 'p1', 'P_Tank', 'p tank', '...pressure...',
    '...druck...' (Druck, Tankdruck), not the atmosphere's, a barometer's or a set
    point's ('p_atm', 'P_amb', 'Luftdruck')."""
    if any(w in name for w in OTHER_PRESSURE_WORDS):
        return False
    return (name in ("p", "pres", "press") or re.fullmatch(r"p\d+", name) is not None
            or name.startswith(("p_", "p-", "p ", "p.")) or "pressure" in name
            or "druck" in name or "pression" in name)


def is_temperature(name: str) -> bool:
    """A gas-temperature column by its name: 'temp...', 't_gas', or any name with
    'temperature' in it that is not the wall's, the room's or the ambient's."""
    other = any(w in name for w in ("wall", "room", "ambient", "amb_", "outside"))
    return (name.startswith("temp") or name in ("t_gas", "gas temperature")
            or "temperatur" in name) and not other


def unit_spelling(table: dict[str, float]) -> Callable[[str], str]:
    """An option type: a unit of ``table`` in the table's spelling, case-insensitive ('kpa'
    -> 'kPa', 'MBAR' -> 'mbar'); another word is left as given for the choices to refuse."""
    def spelled(text: str) -> str:
        return next((u for u in table if u.lower() == text.strip().lower()), text)
    return spelled
