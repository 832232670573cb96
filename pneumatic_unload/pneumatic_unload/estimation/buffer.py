# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Sample storage of the streaming estimator: stamps, values and running prefix sums.

The prefix sums make every periodic statistic O(1): ``cs[k]`` is the sum of the samples
0..k-1 and ``cq[k]`` the sum of their squared first differences (``cq[k+1] - cq[k] =
(p[k] - p[k-1])^2``, 0 for k = 0). Both the per-sample and the block path append through
this class, so the sums are bit-identical whichever path fed them. Stamps in s, values in
the input's signal units (Pa when ``signal_gain`` is 1).
"""

from __future__ import annotations

from array import array

import numpy as np

from pneumatic_unload.estimation.regression import append_sums
from pneumatic_unload.estimation.types import FloatArray


def _extended(a: array, x: bytes) -> array:
    """``a`` with the float64 values of the bytes x appended: in place, or on a copy of
    ``a`` when a view of it is alive (an array that exports its buffer cannot grow: e.g. a
    sampling profiler, as Dask workers run, holding a frame whose locals view it)."""
    try:
        a.frombytes(x)
        return a
    except BufferError:
        b = array("d", a.tobytes())
        b.frombytes(x)
        return b


#: Zero bytes of the usual block sizes, by samples [-] (bounded: blocks of a few sizes).
_ZEROS: dict[int, bytes] = {}


def _zeros(n: int) -> bytes:
    """8 n zero bytes: n float64 zeros to grow an array by [-]."""
    z = _ZEROS.get(n)
    if z is None:
        if len(_ZEROS) > 16:
            _ZEROS.clear()
        z = _ZEROS[n] = bytes(8 * n)
    return z


class SampleBuffer:
    """Growing buffer of samples with prefix sums, trimmed from the start when idle.

    Attributes
    ----------
    t, p : array.array
        Sample instants [s] and values [signal units] kept in memory.
    cs, cq : array.array
        Prefix sums of p [signal units] and of its squared first differences
        [signal units^2], one element longer than ``p``.
    shift : int
        Samples trimmed from the start so far [-] (buffer index + shift = sample number).
    """

    def __init__(self) -> None:
        self.t = array("d")
        self.p = array("d")
        self.cs = array("d", [0.0])
        self.cq = array("d", [0.0])
        self.shift = 0

    def __len__(self) -> int:
        """Samples held [-]."""
        return len(self.p)

    def append(self, t: float, p: float) -> int:
        """Store one sample (t [s], p [signal units]); returns its buffer index [-]."""
        pa = self.p
        if pa:
            d = p - pa[-1]
            vq = self.cq[-1] + d * d
        else:
            vq = self.cq[-1]
        vs = self.cs[-1] + p
        try:
            self.cq.append(vq)
            self.cs.append(vs)
            self.t.append(t)
            pa.append(p)
        except BufferError:  # a view of an array is alive: continue on copies
            n = len(self.p)  # p is appended last: not yet
            self._unshare()
            if len(self.cq) == n + 1:
                self.cq.append(vq)
            if len(self.cs) == n + 1:
                self.cs.append(vs)
            if len(self.t) == n:
                self.t.append(t)
            self.p.append(p)
        return len(self.p) - 1

    def extend(self, t: FloatArray, p: FloatArray) -> None:
        """Store a block of samples (t [s], p [signal units]) with the same sums as
        :meth:`append` one by one (each sum one addition at a time, in sample order).

        The arrays grow by the block (zeros), then one compiled call copies it and
        continues the sums (:func:`~.regression.append_sums`: the live block's path, where
        each numpy call pays for cold caches after the idle wait between blocks)."""
        t = np.ascontiguousarray(t, dtype=np.float64)
        p = np.ascontiguousarray(p, dtype=np.float64)
        n = p.size
        if n == 0:
            return
        prev = self.p[-1] if self.p else float(p[0])
        old = len(self.p)
        zeros = _zeros(n)
        self.t = _extended(self.t, zeros)
        self.p = _extended(self.p, zeros)
        self.cs = _extended(self.cs, zeros)
        self.cq = _extended(self.cq, zeros)
        at = 8 * old  # the byte offset of the block (of the sums' last value held)
        append_sums(t, p, prev, (self.t.buffer_info()[0] + at, self.p.buffer_info()[0] + at,
                                 self.cs.buffer_info()[0] + at,
                                 self.cq.buffer_info()[0] + at))

    def _unshare(self) -> None:
        """Replace the arrays by copies (views held elsewhere keep the old ones alive)."""
        for name in ("t", "p", "cs", "cq"):
            setattr(self, name, array("d", getattr(self, name).tobytes()))

    def views(self, n: int | None = None) -> tuple[FloatArray, FloatArray]:
        """Views of the stamps [s] and values [signal units] up to (excluding) index n."""
        tv = np.frombuffer(self.t, dtype=float)[:n]
        pv = np.frombuffer(self.p, dtype=float)[:n]
        return tv, pv

    def sums(self) -> tuple[FloatArray, FloatArray]:
        """Views of the prefix sums cs [signal units] and cq [signal units^2]."""
        return np.frombuffer(self.cs, dtype=float), np.frombuffer(self.cq, dtype=float)

    def mean(self, lo: int, hi: int) -> float:
        """Mean of samples [lo, hi) from the prefix sums [signal units]."""
        cs = self.cs
        return (cs[hi] - cs[lo]) / (hi - lo)

    def trim(self, keep: int) -> None:
        """Drop the first ``keep`` samples [-] (new arrays, not in-place deletion: views
        held by callers stay valid)."""
        self.t = array("d", self.t[keep:])
        self.p = array("d", self.p[keep:])
        self.cs = array("d", self.cs[keep:])
        self.cq = array("d", self.cq[keep:])
        self.shift += keep


#: Readings a :class:`ReadingLog` keeps (the newest) [-]: a logged temperature at 10 Hz
#: for 2.7 h.
READING_LOG_CAPACITY = 100_000
#: A final fit takes the slower channel's readings up to this long before the end of its
#: tail [s]: a live node has them all when the tail's last sample arrives (a topic's
#: readings travel apart from the pressure's), so that it runs at once and takes what the
#: record's analysis takes (the settled end of a tail adds little).
READING_MARGIN = 0.5


class ReadingLog:
    """A slower channel's readings beside the pressure (a logged gas temperature): stamps
    [s] and values [unit of the channel], bounded (the oldest dropped beyond
    :data:`READING_LOG_CAPACITY`); non-finite values and stamps that do not increase are
    not kept."""

    def __init__(self, capacity: int = READING_LOG_CAPACITY) -> None:
        self.capacity = capacity
        self.t = np.empty(0)
        self.v = np.empty(0)

    def add(self, t: FloatArray, v: FloatArray) -> None:
        """Append readings v at stamps t (arrays of one length) [s], [unit]."""
        t = np.asarray(t, dtype=float).ravel()
        v = np.asarray(v, dtype=float).ravel()
        ok = np.isfinite(t) & np.isfinite(v)
        t, v = t[ok], v[ok]
        if t.size == 0:
            return
        last = self.t[-1] if self.t.size else -np.inf
        keep = t > np.maximum.accumulate(np.concatenate(([last], t)))[:-1]
        self.t = np.concatenate((self.t, t[keep]))[-self.capacity:]
        self.v = np.concatenate((self.v, v[keep]))[-self.capacity:]

    def span(self, t0: float, t_end: float) -> tuple[FloatArray, FloatArray] | None:
        """The readings a final fit of an unload from t0 to t_end [s] takes: those with t0
        <= t <= t_end - :data:`READING_MARGIN` (copies; None without any)."""
        got = self.between(t0, t_end - READING_MARGIN)
        return got if got[0].size else None

    def complete(self, t_end: float) -> bool:
        """Every reading :meth:`span` takes for a tail ending at t_end [s] is in: one at or
        after t_end - :data:`READING_MARGIN` has arrived."""
        return bool(self.t.size and self.t[-1] >= t_end - READING_MARGIN)

    def between(self, t0: float, t1: float) -> tuple[FloatArray, FloatArray]:
        """Copies of the readings with t0 <= t <= t1 [s]: (stamps [s], values [unit])."""
        lo = int(np.searchsorted(self.t, t0, side="left"))
        hi = int(np.searchsorted(self.t, t1, side="right"))
        return self.t[lo:hi].copy(), self.v[lo:hi].copy()
