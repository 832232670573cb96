# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Samples missing from a stream, counted from its stamps (SI units: s; stamps in ns).

A live pressure stream at kHz rates loses messages where its transport or its receiver does
not keep up (best-effort DDS, a queue that overflows); nothing in a message says so. The
stamps do: a sampler with a nominal period writes one stamp per period, so a step of k
periods between two consecutive stamps means k - 1 samples missing. :class:`LossCounter`
learns the nominal period from the first steps (their median) and counts the missing
samples of every later step.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

#: Steps whose median is the nominal period [-].
LEARN_STEPS = 64
#: A step longer than this many nominal periods counts samples missing [-].
MISSING_FACTOR = 1.5


class LossCounter:
    """Count the samples missing from a stream of stamps.

    Attributes
    ----------
    missing : int
        Samples missing so far [-] (0 until the nominal period is known).
    received : int
        Stamps seen [-].
    period : float
        Nominal sample period [s] (NaN until :data:`LEARN_STEPS` steps were seen).
    """

    def __init__(self) -> None:
        self.missing = 0
        self.received = 0
        self.period = math.nan
        self._last_ns: int | None = None
        self._learn: list[np.ndarray] = []

    @property
    def fraction(self) -> float:
        """Missing samples over those that should have arrived [-] (0 before any)."""
        total = self.received + self.missing
        return self.missing / total if total else 0.0

    def update(self, stamps_ns: ArrayLike) -> int:
        """Take the next stamps [ns] (in arrival order); return the samples found missing
        among them [-]. Stamps that go backwards or stand still count nothing (the
        estimator reports those), and steps are taken from the latest stamp so far."""
        ns = np.asarray(stamps_ns, dtype=np.int64).ravel()
        if ns.size == 0:
            return 0
        self.received += int(ns.size)
        # steps of the latest stamp so far: a stamp out of order neither counts nor
        # makes the next one look late
        first = self._last_ns is None
        latest = np.maximum.accumulate(ns if first else np.concatenate(([self._last_ns], ns)))
        steps = np.diff(latest)
        self._last_ns = int(latest[-1])
        if math.isnan(self.period):
            # the first LEARN_STEPS forward steps, whatever the pieces they came in
            have = sum(a.size for a in self._learn)
            self._learn.append(steps[steps > 0][:LEARN_STEPS - have])
            if have + self._learn[-1].size < LEARN_STEPS:
                return 0
            self.period = float(np.median(np.concatenate(self._learn))) * 1e-9
            self._learn = []
        period_ns = self.period * 1e9
        long = steps[steps > MISSING_FACTOR * period_ns]
        found = int(np.sum(np.rint(long / period_ns).astype(np.int64) - 1)) if long.size else 0
        self.missing += found
        return found
