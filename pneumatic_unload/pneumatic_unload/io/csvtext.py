# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The text of a data-logger CSV file: its encoding, its lines, where its rows end.

:func:`open_text` finds the encoding from the first bytes (a byte-order mark: UTF-8, UTF-16
LE/BE, UTF-32 LE/BE; UTF-16 without one by its zero bytes; else ASCII-compatible: each
header line UTF-8, else latin-1) and the end of the last complete line: a last line without
a line end is kept where it has the shape of the line before it (:func:`row_shape`: a file
that merely lacks its final line end) and otherwise left out (a file still being written, its
last number cut: ``10`` for ``10.3``), with :attr:`CsvText.torn_tail` holding it for the
reader's note. Every pass over the
rows reads the bytes up to that end, so that passes over a file that is still growing read
the same rows.
"""

from __future__ import annotations

import codecs
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Final

__all__ = ["CsvText", "TextFormat", "detect_format", "open_text"]

#: Bytes read at a time while looking for a line end (the header's, the file's last) [B].
_BLOCK: Final = 1 << 16
#: Bytes sampled to tell UTF-16 without a byte-order mark by its zero bytes [B].
_SNIFF: Final = 256
#: Characters of a left-out last line quoted in the note [-].
_QUOTE: Final = 60


_DIGITS = re.compile(r"\d+")


def row_shape(line: str) -> str:
    """A row's shape: every run of digits one ``D`` but the last, which keeps its length as
    as many ``9``, and every other character itself. Loggers write a column with a fixed
    number of decimals, so a row cut inside its last number (``10`` or ``10.`` for
    ``10.31``) has another shape than the row before it, while values that gain an integer
    digit (``9.50`` to ``10.50``) keep their shape.

    >>> row_shape("12,10.31") == row_shape("13,9.05") != row_shape("14,10.3")
    True
    """
    text = line.strip()
    runs = list(_DIGITS.finditer(text))
    if not runs:
        return text
    last = runs[-1]
    return (_DIGITS.sub("D", text[:last.start()]) + "9" * (last.end() - last.start())
            + text[last.end():])


def _previous_line(fh: BinaryIO, fmt: TextFormat, data_end: int) -> str:
    """The last complete line before ``data_end`` (without its line end), read back at most
    :data:`_BLOCK` bytes; '' where none is found within them."""
    lo = max(fmt.bom, data_end - _BLOCK)
    lo -= lo % fmt.unit  # a code-unit boundary (the mark's length is one)
    fh.seek(lo)
    lines = fmt.decode_rows(fh.read(data_end - lo)).rstrip("\r\n").rsplit("\n", 1)
    return lines[-1] if len(lines) == 2 or lo == fmt.bom else ""


class CsvTextError(Exception):
    """The file cannot be read as text (unreadable, an encoding that does not decode)."""


@dataclass(frozen=True)
class TextFormat:
    """How a file's bytes are text."""

    name: str  #: as said to the user: 'UTF-8', 'UTF-16 LE (with BOM)', ...
    codec: str  #: Python codec of the rows ('latin-1' for ASCII-compatible files)
    unit: int  #: bytes per code unit: 1, 2 or 4 [B]
    bom: int  #: bytes of the byte-order mark at the start [B]

    @property
    def newline(self) -> bytes:
        """The line end's code unit (``\\n``) in this encoding."""
        return "\n".encode(self.codec)

    def decode_header(self, raw: bytes) -> str:
        """A line before the rows: UTF-8, else latin-1 in an ASCII-compatible file (a
        latin-1 header such as ``T_Gas [°C]`` keeps its degree sign); the file's codec
        otherwise."""
        if self.unit == 1:
            try:
                return raw.decode("utf-8")
            except UnicodeDecodeError:
                return raw.decode("latin-1")
        try:
            return raw.decode(self.codec)
        except UnicodeDecodeError as err:
            raise CsvTextError(f"does not decode as {self.name}: {err}") from err

    def decode_rows(self, raw: bytes) -> str:
        """Rows of numbers: latin-1 in an ASCII-compatible file (never fails, one character
        per byte), the file's codec otherwise (a character that does not decode becomes
        U+FFFD, which the row's check names)."""
        return raw.decode(self.codec, errors="replace") if self.unit > 1 else \
            raw.decode("latin-1")


_BOMS: Final = (  # longest first: UTF-32 LE begins with UTF-16 LE's mark
    (codecs.BOM_UTF32_LE, TextFormat("UTF-32 LE (with BOM)", "utf-32-le", 4, 4)),
    (codecs.BOM_UTF32_BE, TextFormat("UTF-32 BE (with BOM)", "utf-32-be", 4, 4)),
    (codecs.BOM_UTF8, TextFormat("UTF-8 (with BOM)", "latin-1", 1, 3)),
    (codecs.BOM_UTF16_LE, TextFormat("UTF-16 LE (with BOM)", "utf-16-le", 2, 2)),
    (codecs.BOM_UTF16_BE, TextFormat("UTF-16 BE (with BOM)", "utf-16-be", 2, 2)),
)
_PLAIN: Final = TextFormat("UTF-8 or latin-1", "latin-1", 1, 0)


def detect_format(head: bytes) -> TextFormat:
    """The encoding of a file from its first bytes: a byte-order mark, else UTF-16 when
    every second byte of the first ones is zero (ASCII text in UTF-16 without a mark), else
    ASCII-compatible (UTF-8 or latin-1)."""
    for bom, fmt in _BOMS:
        if head.startswith(bom):
            return fmt
    sample = head[: min(len(head), _SNIFF) // 2 * 2]
    if len(sample) >= 4:
        even, odd = sample[0::2], sample[1::2]
        if not odd.strip(b"\0") and b"\0" not in even:
            return TextFormat("UTF-16 LE (no BOM)", "utf-16-le", 2, 0)
        if not even.strip(b"\0") and b"\0" not in odd:
            return TextFormat("UTF-16 BE (no BOM)", "utf-16-be", 2, 0)
    return _PLAIN


def _last_line_end(raw: bytes, newline: bytes, unit: int, base: int) -> int:
    """Index just past the last line end in ``raw`` whose first byte lies on a code-unit
    boundary of the file (``raw`` begins at file offset ``base``); -1 if none."""
    i = raw.rfind(newline)
    while i >= 0 and (base + i) % unit:
        i = raw.rfind(newline, 0, i + len(newline) - 1)
    return -1 if i < 0 else i + len(newline)


@dataclass
class CsvText:
    """An open CSV file's text: the lines before the rows (read with :meth:`next_line`) and
    the rows (:meth:`row_chunks`, up to :attr:`data_end`)."""

    path: Path
    format: TextFormat
    size: int  #: the file's size when opened [B]
    data_end: int  #: just past the last line end [B]; the rows are read up to here
    torn_tail: str  #: the last line when it has no line end (left out), else ''
    _fh: BinaryIO
    _pos: int

    def next_line(self) -> tuple[str, bool] | None:
        """The next line before the rows, decoded, without its line end, and whether it had
        one; None at the end of the file."""
        fmt, nl = self.format, self.format.newline
        self._fh.seek(self._pos)
        buf = b""
        while True:
            block = self._fh.read(_BLOCK)
            if not block:
                if not buf:
                    return None
                self._pos += len(buf)
                return fmt.decode_header(buf).rstrip("\r"), False
            start = len(buf)
            buf += block
            i = buf.find(nl, max(0, start - len(nl) + 1))
            while i >= 0 and (self._pos + i) % fmt.unit:
                i = buf.find(nl, i + 1)
            if i >= 0:
                self._pos += i + len(nl)
                return fmt.decode_header(buf[:i]).rstrip("\r"), True

    @property
    def offset(self) -> int:
        """File offset just past the lines read by :meth:`next_line` [B]."""
        return self._pos

    def close(self) -> None:
        """Close the file."""
        self._fh.close()

    def row_chunks(self, start: int, chunk_bytes: int) -> Iterator[list[bytes]]:
        """The bytes from file offset ``start`` to :attr:`data_end` in pieces of about
        ``chunk_bytes`` that each end at a line end (whole lines), each as a one-item list
        that the caller empties (so that no reference to a piece stays here while it is
        parsed; decode it with :meth:`TextFormat.decode_rows`). Opens the file anew (one
        pass)."""
        fmt, nl = self.format, self.format.newline
        size = max(fmt.unit, chunk_bytes // fmt.unit * fmt.unit)
        with _open(self.path) as fh:
            fh.seek(start)
            pos, carry = start, b""
            while pos < self.data_end:
                raw = fh.read(min(size, self.data_end - pos))
                if not raw:
                    break
                base = pos - len(carry)
                pos += len(raw)
                raw = carry + raw
                cut = _last_line_end(raw, nl, fmt.unit, base)
                if cut < 0:
                    carry = raw  # no line end yet: a line longer than the chunk
                    continue
                box, carry = [raw[:cut]], raw[cut:]
                del raw
                yield box
            if carry:
                yield [carry]


def _open(path: Path) -> BinaryIO:
    try:
        return path.open("rb")
    except FileNotFoundError:
        raise CsvTextError(f"CSV file {path} does not exist") from None
    except OSError as err:
        raise CsvTextError(f"cannot read CSV file {path}: {err}") from err


def open_text(path: Path) -> CsvText:
    """Open ``path``: its encoding, its size now, the end of its last complete line.

    Raises:
        CsvTextError: the file does not exist or cannot be read.
    """
    fh = _open(path)
    try:
        head = fh.read(_SNIFF)
        fmt = detect_format(head)
        fh.seek(0, 2)
        size = fh.tell()
        nl = fmt.newline
        end, scan_to = -1, size
        while scan_to > fmt.bom and end < 0:  # the last line end, block by block back
            lo = max(fmt.bom, scan_to - _BLOCK)
            lo -= lo % fmt.unit  # a code-unit boundary (the mark's length is one)
            fh.seek(lo)
            cut = _last_line_end(fh.read(scan_to - lo), nl, fmt.unit, lo)
            if cut >= 0:
                end = lo + cut
            scan_to = lo
        data_end = end if end >= 0 else fmt.bom
        torn = ""
        if data_end < size:
            fh.seek(data_end)
            tail = fh.read(min(size - data_end, _BLOCK))
            torn = fmt.decode_rows(tail[: len(tail) // fmt.unit * fmt.unit]).strip()
            whole = size - data_end <= _BLOCK and (size - data_end) % fmt.unit == 0
            if whole and torn and row_shape(torn) == row_shape(
                    _previous_line(fh, fmt, data_end)):
                data_end, torn = size, ""
            elif len(torn) > _QUOTE:
                torn = torn[:_QUOTE] + "..."
    except OSError as err:
        fh.close()
        raise CsvTextError(f"cannot read CSV file {path}: {err}") from err
    except BaseException:
        fh.close()
        raise
    return CsvText(path=path, format=fmt, size=size, data_end=data_end, torn_tail=torn,
                   _fh=fh, _pos=fmt.bom)
