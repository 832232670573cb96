# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Bounded histories of the streaming estimator: its diagnostics and its results.

A live estimator runs for days and a record may hold millions of bad samples (each a
diagnostic): what it keeps of its past must not grow with the stream. Every result is
returned by the call that completed it (and published by the node, recorded in the bag),
every diagnostic is seen by whoever polls :meth:`DiagnosticLog.since`; the histories only
keep enough for a late reader and for explaining a record without unload: the first
:data:`FIRST_DIAGNOSTICS` diagnostics (the first problems of a record are usually its
cause) and the last :data:`LAST_DIAGNOSTICS`, and the last :data:`RESULTS_KEPT` results (a
crossing and a final result per unload).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Sequence
from typing import Any, overload

from pneumatic_unload.estimation.types import Diagnostic, UnloadResult

#: Diagnostics kept from the start of the stream [-].
FIRST_DIAGNOSTICS = 100
#: Most recent diagnostics kept [-] (about 300 B each: at most about 0.3 MiB in all).
LAST_DIAGNOSTICS = 1000
#: Most recent results kept by :class:`~.streaming.StreamingEstimator` and the node [-]
#: (about 5 KiB each with their uncertainty budgets: at most about 0.5 MiB; 1000 of them
#: were 6 % of the node's RSS, which a 10 kHz cycling rig fills in 20 minutes).
RESULTS_KEPT = 100


def recent_results() -> deque[UnloadResult]:
    """An empty ring of the last :data:`RESULTS_KEPT` results."""
    return deque(maxlen=RESULTS_KEPT)


class DiagnosticLog(Sequence[Diagnostic]):
    """The first ``first`` and the last ``last`` diagnostics of a stream, and their count.

    Iterating, indexing and ``len`` see the diagnostics held, in order; :attr:`total`
    counts all ever appended, :attr:`dropped` those no longer held (between the first and
    the last ones).

    Parameters
    ----------
    first, last : int, optional
        Diagnostics kept from the start, and most recent ones kept [-] (default
        :data:`FIRST_DIAGNOSTICS`, :data:`LAST_DIAGNOSTICS`).
    """

    def __init__(self, first: int | None = None, last: int | None = None) -> None:
        self._first_max = max(0, int(FIRST_DIAGNOSTICS if first is None else first))
        self._first: list[Diagnostic] = []
        self._last: deque[Diagnostic] = deque(
            maxlen=max(1, int(LAST_DIAGNOSTICS if last is None else last)))
        self.total = 0

    def append(self, d: Diagnostic) -> None:
        """Record one diagnostic."""
        self.total += 1
        if len(self._first) < self._first_max:
            self._first.append(d)
        else:
            self._last.append(d)

    @property
    def dropped(self) -> int:
        """Diagnostics appended but no longer held [-]."""
        return self.total - len(self)

    def since(self, seen: int) -> list[Diagnostic]:
        """The diagnostics appended after the first ``seen`` ones that are still held (all
        of them when the reader polls at least every ``last`` diagnostics)."""
        out = [d for k, d in enumerate(self._first) if k >= seen]
        start = self.total - len(self._last)  # appended index of self._last[0]
        skip = max(0, seen - start)
        out += list(self._last)[skip:]
        return out

    def __len__(self) -> int:
        return len(self._first) + len(self._last)

    def __iter__(self) -> Iterator[Diagnostic]:
        yield from self._first
        yield from self._last

    def __reversed__(self) -> Iterator[Diagnostic]:
        yield from reversed(self._last)
        yield from reversed(self._first)

    @overload
    def __getitem__(self, i: int) -> Diagnostic: ...

    @overload
    def __getitem__(self, i: slice) -> list[Diagnostic]: ...

    def __getitem__(self, i: int | slice) -> Diagnostic | list[Diagnostic]:
        return list(self)[i]

    def __eq__(self, other: Any) -> bool:
        if isinstance(other, DiagnosticLog | list | tuple):
            return list(self) == list(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"DiagnosticLog(held={len(self)}, total={self.total})"
