# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The time column of a data-logger CSV file: numbers, epoch stamps, date-times, times of day.

A time column holds one of

* numbers in a time unit (s, ms, ...: the logger's clock, kept as it is);
* epoch stamps (seconds or milliseconds since 1970-01-01 UTC), told from a clock's numbers by
  their magnitude (:data:`EPOCH_RANGE_S`): read as seconds from the first row;
* date-times in one cell: ISO 8601 with or without a zone (``2026-03-04 10:15:02.125``,
  ``2026-03-04T10:15:02.125+01:00``, ``...Z``) or a logger's date followed by its time
  (``04.03.2026 10:15:02,125``, ``03/04/2026 10:15:02 AM``); read as seconds from the first
  row (a zone is taken into account, so a change of daylight-saving time is no step);
* times of day (``10:15:02.125``), with the date in a column of its own (``Date``,
  ``Datum``) or without one (midnight is then a new day: a step back of more than
  :data:`MIDNIGHT_MIN_STEP_S`).

A counter that wraps (16 or 32 bits: 65535 -> 0) is unwrapped (:class:`TimeAxis`); any other
step back is an error whose hint names the likely cause, never a sort (sorting a record of
two appended runs or of a wrapped counter gives a record that begins mid-discharge).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

__all__ = [
    "EPOCH_RANGE_S",
    "MIDNIGHT_MIN_STEP_S",
    "WRAP_MODULI",
    "WRAP_STEP_FACTOR",
    "ClockParser",
    "TimeAxis",
    "TimeError",
    "TimeForm",
    "detect_form",
    "epoch_iso",
    "epoch_unit",
]

FloatArray = npt.NDArray[np.float64]

#: Epoch seconds that a time column's first value may hold to be read as an epoch stamp
#: [s]: 2000-01-01 to 2100-01-01 UTC. No logger clock counts 30 years of seconds since its
#: start, so a first value in this range (or 1000 times it: milliseconds, 1e6: us) is a
#: stamp since 1970; the decision is named in the reader's warnings.
EPOCH_RANGE_S: Final = (946_684_800.0, 4_102_444_800.0)
#: Moduli a wrapping integer time counter may have (16, 24 and 32 bits) [counts].
WRAP_MODULI: Final = (1 << 16, 1 << 24, 1 << 32)
#: Largest step across a wrap, in typical (median) steps of the counter [-]: a counter
#: that wraps steps from near its top to near 0 by about one sample period; a step back
#: that would be more than this many periods across the wrap is not a wrap (a record
#: appended, a clock set back).
WRAP_STEP_FACTOR: Final = 10.0
#: A time of day without a date that steps back by more than this is the next day
#: (midnight) [s]: a clock set back by half a day is not a logger's fault mode.
MIDNIGHT_MIN_STEP_S: Final = 43_200.0

Kind = Literal["number", "epoch", "date-time", "time of day"]


class TimeError(ValueError):
    """A time cell or step that cannot be read (the message names the data row)."""


@dataclass(frozen=True)
class TimeForm:
    """What a time column holds."""

    kind: Kind
    #: date order of a date written with '/' or '-' and the year last: 'dmy', 'mdy' or ''
    #: (not known from the first row; decided by the first row that tells)
    order: str = ""
    zoned: bool = False  #: the date-times carry a zone (every row must)
    with_date_column: bool = False  #: a time of day with the date in a column of its own
    example: str = ""  #: the first row's cell, quoted in messages

    @property
    def text(self) -> bool:
        """The cells are text (date-times or times of day), not numbers."""
        return self.kind in ("date-time", "time of day")


# ------------------------------------------------------------------------- date and clock
_CLOCK = r"(?P<h>\d{1,2}):(?P<mi>\d{2}):(?P<s>\d{2})(?:[.,](?P<f>\d+))?(?:\s*(?P<ampm>[AaPp][Mm]))?"
_ZONE = r"(?:\s*(?P<z>Z|UTC|GMT|[+-]\d{2}(?::?\d{2})?))?"
_DATE = (r"(?P<date>(?P<y1>\d{4})[-/.](?P<m1>\d{1,2})[-/.](?P<d1>\d{1,2})"  # year first
         r"|(?P<a>\d{1,2})(?P<sep>[./-])(?P<b>\d{1,2})(?P=sep)(?P<y2>\d{4}|\d{2}))")
_DATE_RE: Final = re.compile(rf"^\s*{_DATE}\s*$")
_CLOCK_RE: Final = re.compile(rf"^\s*{_CLOCK}{_ZONE}\s*$")
_DATETIME_RE: Final = re.compile(rf"^\s*{_DATE}(?:[Tt]|\s+){_CLOCK}{_ZONE}\s*$")


def _zone_seconds(z: str | None) -> float:
    """Offset of a zone from UTC [s] ('Z', 'UTC', '+01:00', '-0530', '+02')."""
    if not z or z in ("Z", "UTC", "GMT"):
        return 0.0
    sign = -1.0 if z[0] == "-" else 1.0
    digits = z[1:].replace(":", "")
    return sign * (int(digits[:2]) * 3600.0 + (int(digits[2:4]) * 60.0 if digits[2:] else 0.0))


def _clock_seconds(m: re.Match[str]) -> float:
    """Seconds since midnight of a matched clock; raises ValueError when out of range."""
    h, mi, s = int(m["h"]), int(m["mi"]), int(m["s"])
    if m["ampm"]:
        if not 1 <= h <= 12:
            raise ValueError(f"hour {h} with {m['ampm']}")
        h = h % 12 + (12 if m["ampm"].lower() == "pm" else 0)
    if h > 23 or mi > 59 or s > 60:
        raise ValueError(f"{h:02d}:{mi:02d}:{s:02d} is not a time of day")
    frac = float("0." + m["f"]) if m["f"] else 0.0
    return h * 3600.0 + mi * 60.0 + s + frac


def _date_order(m: re.Match[str]) -> str:
    """The date order a matched date implies by itself: 'ymd', 'dmy' (a dot: day first,
    as in 04.03.2026, or a first number above 12), 'mdy' (a second number above 12) or
    '' (03/04/2026: either)."""
    if m["y1"]:
        return "ymd"
    a, b = int(m["a"]), int(m["b"])
    if m["sep"] == "." or a > 12:
        return "dmy"
    if b > 12:
        return "mdy"
    return ""


def _ordinal(m: re.Match[str], order: str) -> int:
    """Day number of a matched date read in ``order``; raises ValueError if no such day."""
    if m["y1"]:
        y, mo, d = int(m["y1"]), int(m["m1"]), int(m["d1"])
    else:
        y = int(m["y2"])
        y += 2000 if y < 100 else 0
        a, b = int(m["a"]), int(m["b"])
        d, mo = (a, b) if order == "dmy" else (b, a)
    return _dt.date(y, mo, d).toordinal()


def detect_form(cell: str, date_cell: str | None, *, decimal_comma: bool) -> TimeForm:
    """The form of a time column from its first cell (and the first cell of a date column,
    if the header has one): a number, a date-time or a time of day. A cell that is none of
    these is taken as a number (the row check then names it)."""
    text = cell.strip()
    m = _DATETIME_RE.match(text)
    if m:
        return TimeForm("date-time", order=_date_order(m), zoned=m["z"] is not None,
                        example=text)
    m = _CLOCK_RE.match(text)
    if m:
        order, with_date = "", False
        if date_cell is not None and (d := _DATE_RE.match(date_cell)):
            order, with_date = _date_order(d), True
        return TimeForm("time of day", order=order, zoned=m["z"] is not None,
                        with_date_column=with_date, example=text)
    return TimeForm("number", example=text)


def epoch_unit(first: float, unit: str | None) -> str | None:
    """The unit in which ``first`` (a time column's first number) is an epoch stamp: 's',
    'ms' or 'us' by its magnitude (:data:`EPOCH_RANGE_S`), only that of a ``unit`` stated
    (None: not stated); None when it is not an epoch stamp."""
    lo, hi = EPOCH_RANGE_S
    for name, scale in (("s", 1.0), ("ms", 1e3), ("us", 1e6)):
        if lo * scale <= first <= hi * scale and unit in (None, name):
            return name
    return None


def epoch_iso(seconds: float) -> str:
    """An epoch stamp [s since 1970-01-01 UTC] as ISO 8601 UTC, to the millisecond."""
    try:
        when = _dt.datetime.fromtimestamp(seconds, tz=_dt.UTC)
    except (OverflowError, OSError, ValueError):
        return f"{seconds:.6g} s since 1970-01-01 UTC"
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


class ClockParser:
    """Date-time and time-of-day cells to seconds, row by row in file order: seconds since
    midnight of the first row's date (in the first row's zone, or UTC for zoned cells),
    or since midnight for a time of day without a date.

    Args:
        form: the column's form (:func:`detect_form`).
        where: ``where(k)`` names data row k (1-based) in messages.
    """

    def __init__(self, form: TimeForm, where: Callable[[int], str]) -> None:
        self.form = form
        self._where = where
        self._row = 0
        self._order = form.order
        self._day0: int | None = None  # ordinal of the first row's date
        self._first_date: str | None = None
        self._days: dict[str, int] = {}  # date text -> days after the first row's date
        self._pattern = _DATETIME_RE if form.kind == "date-time" else _CLOCK_RE

    def _fail(self, why: str) -> TimeError:
        return TimeError(f"{self._where(self._row)}: {why}")

    def _day(self, date: re.Match[str], text: str) -> int:
        """Days of ``date`` after the first row's date."""
        if text in self._days:
            return self._days[text]
        own = _date_order(date)
        if self._order and own and own != self._order:
            raise self._fail(f"the date {text!r} is not written as the first row's "
                             f"{self._first_date!r} ({self._order_name(self._order)})")
        if not self._order and own:
            self._order = own
        if self._first_date is None:
            if self._order:
                self._day0 = self._checked_ordinal(date, self._order, text)
            self._first_date = text
            self._days[text] = 0
            return 0
        if not self._order:
            # 03/04/2026 then 03/05/2026: the order under which the date is the next day
            first = _DATE_RE.match(self._first_date)
            assert first is not None
            fits = []
            for order in ("dmy", "mdy"):
                try:
                    if _ordinal(date, order) - _ordinal(first, order) == 1:
                        fits.append(order)
                except ValueError:
                    pass
            if len(fits) != 1:
                raise self._fail(
                    f"the date {text!r} after {self._first_date!r}: day/month or month/day "
                    "cannot be told from these dates; write the dates as ISO 8601 "
                    "(2026-03-04)")
            self._order = fits[0]
        if self._day0 is None:
            first = _DATE_RE.match(self._first_date)
            assert first is not None
            self._day0 = self._checked_ordinal(first, self._order, self._first_date)
        days = self._checked_ordinal(date, self._order, text) - self._day0
        self._days[text] = days
        return days

    @staticmethod
    def _order_name(order: str) -> str:
        return {"ymd": "year-month-day", "dmy": "day.month.year or day/month/year",
                "mdy": "month/day/year"}[order]

    def _checked_ordinal(self, date: re.Match[str], order: str, text: str) -> int:
        try:
            return _ordinal(date, order)
        except ValueError as err:
            raise self._fail(f"{text!r} is not a date ({err})") from None

    def parse(self, cell: str, date_cell: str | None, row: int) -> float:
        """Seconds of data row ``row``'s time cell (and date cell) [s].

        Raises:
            TimeError: a cell not in the column's form, a date or time that does not
                exist, a zone missing or present unlike the first row's.
        """
        self._row = row
        m = self._pattern.match(cell)
        if m is None:
            raise self._fail(self._not_like(cell))
        if (m["z"] is not None) != self.form.zoned:
            raise self._fail(
                f"{cell.strip()!r} {'has a zone' if m['z'] else 'has no zone'} unlike the "
                f"first row's {self.form.example!r}: local and zoned times cannot be "
                "ordered; write every row with its zone (or none)")
        try:
            secs = _clock_seconds(m) - _zone_seconds(m["z"])
        except ValueError as err:
            raise self._fail(f"{cell.strip()!r}: {err}") from None
        if self.form.kind == "date-time":
            return self._day(m, m["date"]) * 86_400.0 + secs
        if self.form.with_date_column:
            text = (date_cell or "").strip()
            d = _DATE_RE.match(text)
            if d is None:
                raise self._fail(f"{text!r} in the date column is not a date like the "
                                 "first row's")
            return self._day(d, text) * 86_400.0 + secs
        return secs

    def parse_many(self, cells: list[str], date_cells: list[str] | None
                   ) -> FloatArray | None:
        """Seconds of consecutive rows' time cells (and date cells) [s], all at once, when
        every cell is laid out as the first one (the same length, its digits where the
        first one has digits, its other characters the same: a logger's fixed-width stamps);
        None otherwise (:meth:`parse` then reads them row by row, with its messages)."""
        if not cells:
            return np.empty(0)
        template = cells[0]
        m = self._pattern.match(template)
        if m is None or m["ampm"] or (m["z"] is not None) != self.form.zoned:
            return None
        width = len(template)
        try:
            raw = "".join(cells).encode("ascii")
        except UnicodeEncodeError:
            return None
        if len(raw) != width * len(cells):
            return None
        arr = np.frombuffer(raw, dtype=np.uint8).reshape(len(cells), width)
        digit = np.frombuffer(template.encode("ascii"), dtype=np.uint8)
        is_digit = (digit >= 48) & (digit <= 57)
        if m["z"] is not None:  # a zone's digits are the zone: the same in every row
            is_digit[m.start("z"):] = False
        if not (np.all(arr[:, ~is_digit] == digit[~is_digit])
                and np.all(arr[:, is_digit] - 48 <= 9)):
            return None
        d = arr.astype(np.int64) - 48

        def number(group: str) -> npt.NDArray[np.int64]:
            lo, hi = m.span(group)
            out = np.zeros(len(cells), dtype=np.int64)
            for k in range(lo, hi):
                out = out * 10 + d[:, k]
            return out

        h, mi, sec = number("h"), number("mi"), number("s")
        if np.any(h > 23) or np.any(mi > 59) or np.any(sec > 60):
            return None
        secs = h * 3600.0 + mi * 60.0 + sec
        if m["f"]:
            if len(m["f"]) > 15:
                return None
            secs = secs + number("f") / 10.0 ** len(m["f"])
        secs = secs - _zone_seconds(m["z"])
        if self.form.kind == "date-time":
            lo, hi = m.span("date")
            dates = np.ascontiguousarray(arr[:, lo:hi]).view(f"S{hi - lo}").ravel()
        elif self.form.with_date_column:
            if date_cells is None:
                return None
            dates = np.asarray([c.strip() for c in date_cells])
        else:
            return secs
        uniq, first, inverse = np.unique(dates, return_index=True, return_inverse=True)
        days = np.zeros(uniq.size)
        state = (self._order, self._day0, self._first_date, dict(self._days))
        for j in np.argsort(first, kind="stable"):  # in the order of the rows
            text = uniq[j].decode("ascii") if isinstance(uniq[j], bytes) else str(uniq[j])
            dm = _DATE_RE.match(text)
            try:
                if dm is None:
                    raise TimeError(text)
                days[j] = self._day(dm, text)
            except TimeError:
                # the row-by-row pass, from the state before these rows, names the row
                self._order, self._day0, self._first_date, self._days = state
                return None
        return days[inverse.ravel()] * 86_400.0 + secs

    def _not_like(self, cell: str) -> str:
        what = "an empty cell" if not cell.strip() else repr(cell.strip())
        return (f"{what} in the time column is not a {self.form.kind} like the first "
                f"row's {self.form.example!r}")


# ------------------------------------------------------------------------------ the axis
class TimeAxis:
    """Times of consecutive chunks of rows, in s, checked to increase: a counter that
    wraps is unwrapped; epoch stamps and date-times are counted from the first row.

    Args:
        form: the column's form.
        scale: size of the column's unit [s] (1 for date-times, already in s).
        from_first_row: times are counted from the first row (epoch stamps, date-times).
        where: ``where(k)`` names data row k (1-based) in messages.
    """

    def __init__(self, form: TimeForm, scale: float, *, from_first_row: bool,
                 where: Callable[[int], str]) -> None:
        self.form = form
        self.scale = scale
        self.from_first_row = from_first_row
        self._where = where
        self._origin: float | None = None
        self._offset = 0.0  # added to the raw values: the wraps so far [file units]
        self._last_raw = math.nan
        self._last = -math.inf  # the last unwrapped value [file units]
        self._typical = math.nan  # median step of the counter [file units]
        self._max_abs = 0.0
        self.wraps = 0
        self.first_wrap_row = 0
        self.modulus = 0.0

    def seconds(self, raw: FloatArray, rows: npt.NDArray[np.int64]) -> FloatArray:
        """Times [s] of the rows ``raw`` (file units), data rows ``rows`` (1-based, for
        messages).

        Raises:
            TimeError: time does not increase (with the likely cause).
        """
        x = raw + self._offset
        steps = np.diff(x, prepend=self._last)
        pos = steps[steps > 0]
        if pos.size:
            self._typical = float(np.median(pos))
        integer = self.form.kind == "number" and bool(np.all(raw == np.round(raw)))
        if raw.size:
            self._max_abs = max(self._max_abs, float(np.max(np.abs(raw))))
        while True:
            bad = np.flatnonzero(steps <= 0.0)
            if bad.size == 0:
                break
            k = int(bad[0])
            prev_raw = float(raw[k - 1]) if k else self._last_raw
            modulus = self._wrap(prev_raw, float(raw[k]), integer)
            if modulus is None:
                raise TimeError(self._why(x, steps, k, int(rows[k])))
            x[k:] += modulus
            self._offset += modulus
            self.wraps += 1
            self.first_wrap_row = self.first_wrap_row or int(rows[k])
            self.modulus = modulus
            steps[k] = x[k] - (x[k - 1] if k else self._last)
        if x.size:
            self._last = float(x[-1])
            self._last_raw = float(raw[-1])
            if self._origin is None:
                self._origin = float(x[0]) if self.from_first_row else 0.0
        origin = self._origin or 0.0
        return (x - origin) * self.scale

    def _wrap(self, prev: float, cur: float, integer: bool) -> float | None:
        """The modulus by which the step ``prev`` -> ``cur`` is a wrap, or None."""
        if self.form.kind == "time of day" and not self.form.with_date_column:
            # midnight: 23:59:59.9 -> 00:00:00.0
            return 86_400.0 if prev - cur > MIDNIGHT_MIN_STEP_S else None
        if not integer or not math.isfinite(self._typical) or not math.isfinite(prev):
            return None
        for modulus in WRAP_MODULI:
            if self._max_abs < modulus:
                across = cur - prev + modulus
                if 0.0 < across <= WRAP_STEP_FACTOR * self._typical:
                    return float(modulus)
                return None
        return None

    def _why(self, x: FloatArray, steps: FloatArray, k: int, row: int) -> str:
        """The message of a step that is not an increase (at data row ``row``, the k-th of
        the chunk), with its likely cause."""
        prev = x[k - 1] if k else self._last
        head = f"{self._where(row)}: time does not increase at data row {row}"
        if steps[k] == 0.0:
            return (f"{head} (the time of the row before repeats: a repeated row, or a "
                    "clock coarser than the sample rate; log with more decimals)")
        back = f"steps back by {(prev - x[k]) * self.scale:.6g} s"
        after = steps[k + 1: k + 4]
        if after.size >= 2 and np.all(after < 0):
            return (f"{head} ({back}, and so do the next rows: rows written newest first? "
                    "reverse their order)")
        if self.form.kind == "time of day" or (self.form.kind == "date-time"
                                                and not self.form.zoned):
            return (f"{head} ({back}: a local clock set back, e.g. at the end of "
                    "daylight-saving time? write the times with their zone (ISO 8601, "
                    "+01:00) or in UTC; or two records appended: split the file at this "
                    "row)")
        wrap = ""
        if self.form.kind == "number":
            wrap = ("; a counter that wraps at 2^16, 2^24 or 2^32 is unwrapped by itself, "
                    "this step is not such a wrap")
        return (f"{head} ({back}: two records appended (split the file at this row and "
                f"analyse each part) or a clock set back{wrap})")
