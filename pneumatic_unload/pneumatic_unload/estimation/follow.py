# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A confirmed fall that nothing follows: back to waiting, or no unload at the stream's end.

Correlated noise (a transducer low-passed below its logging rate) wanders on a plateau; in
the plateau's first second its 32-sample window cannot show the correlation, so a wander
can pass the trigger and its confirmation (6 bar, AR(1) rho 0.8-0.95, 300 Pa: 5 of 40 idle
minutes). The unload then waited for a drop of 10 % of the pressure change that never
came: its samples were never trimmed (an idle hour at 10 kHz holds 36 M of them) and the
stream's end reported it as 'aborted'. Here the samples since the confirmation are tested
for a fall at doubling spans (so the cost per sample stays constant), and at the stream's
end. Indices in buffer samples, values in signal units.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.estimation.decisions import PERIOD
from pneumatic_unload.estimation.regression import variance_inflation
from pneumatic_unload.estimation.state import EstimatorState
from pneumatic_unload.estimation.types import UnloadResult

#: Fewest samples after the confirmation that can show no fall followed it [-] (at 1 kHz
#: 4 s; the fall a real unload continues with is then tens of standard errors).
FOLLOW_MIN = 64 * PERIOD


#: Samples the noise's correlation is read from [-] (the inflation is the noise's, not the
#: span's: a longer window costs time and tells nothing more).
CORRELATION_WINDOW = 4096


def no_fall(x: NDArray[np.float64], before: NDArray[np.float64]) -> bool:
    """The samples x [signal units] do not fall and sit at the level of the samples
    ``before`` them: their straight line's drop over them is less than 3 standard errors,
    and their mean is within 3 standard errors of that of ``before`` (the noise's
    correlation included: :func:`~.regression.variance_inflation`, on the last
    CORRELATION_WINDOW samples of each). A valve opened and closed again leaves the
    pressure lower: that unload stopped, it did not vanish. A mean farther from
    ``before``'s than 3 of the samples' own deviations (a mean's standard error is never
    more, however correlated the noise) is no level: decided without the correlation, as
    an unload under way always is (its fitting cost 1.5 s of a 1 M-sample record's
    ``analyze``)."""
    v = np.arange(x.size, dtype=float) - 0.5 * (x.size - 1)
    mx, mb = float(np.mean(x)), float(np.mean(before))
    y = x - mx
    vv = float(v @ v)
    slope = float(y @ v) / vv
    e = y - slope * v
    sx2, sb2 = float(e @ e) / (x.size - 2), float(np.var(before, ddof=1))
    if not abs(mx - mb) < 3.0 * math.sqrt(sx2 + sb2):
        return False
    ix = variance_inflation(x[-CORRELATION_WINDOW:])
    ib = variance_inflation(before[-CORRELATION_WINDOW:])
    se = math.sqrt(sx2 / vv * ix)
    return -slope < 3.0 * se and abs(mx - mb) < 3.0 * math.sqrt(
        sx2 / x.size * ix + sb2 / before.size * ib)


def not_followed(st: EstimatorState, k: int) -> bool:
    """At index k: the unload's start not yet fitted (its drop short of 10 % of the pressure
    change) and its FOLLOW_MIN or more samples since the confirmation neither fall nor
    left the plateau's level (:func:`no_fall` against the plateau's last FOLLOW_MIN samples
    before the trigger, at least PERIOD of them)."""
    u = st.unload
    lo = u.trigger + PERIOD
    first = max(st.arm_index, u.trigger - FOLLOW_MIN)
    if u.refined or k + 1 - lo < FOLLOW_MIN or u.trigger - first < PERIOD:
        return False
    pv = np.frombuffer(st.buf.p, dtype=float)
    return no_fall(pv[lo:k + 1], pv[first:u.trigger])


def due(trigger: int, k: int | NDArray[np.int64]) -> bool | NDArray[np.bool_]:
    """Check index k [-] is one where the test runs while unloading: k - trigger a power of
    two times PERIOD, at least FOLLOW_MIN + PERIOD (the checks fall PERIOD apart from the
    trigger on: :func:`~.unloading.start_unloading`)."""
    m = (np.asarray(k) - trigger) // PERIOD
    ok = (m * PERIOD >= FOLLOW_MIN + PERIOD) & ((m & (m - 1)) == 0)
    return bool(ok) if np.ndim(ok) == 0 else ok


def wait_again(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Nothing followed the fall confirmed before index i: a diagnostic, and waiting again
    on the plateau the trigger came from (its first sample and the stream-start flag kept,
    so that a real opening later is fitted against that plateau and trimming resumes)."""
    t0 = float(st.buf.t[st.unload.trigger])
    arm, first = st.arm_index, st.stream_start
    st.diag("ok", f"the fall confirmed at {t0:.3f} s was not followed (the "
            f"{float(st.buf.t[i]) - t0:.3g} s since show none): not an unload, waiting "
            "again", float(st.buf.t[i]))
    st.to_waiting(arm)
    st.stream_start = first
    st.next_check = i + PERIOD
    return []


def lost_at_end(st: EstimatorState, k: int) -> bool:
    """At the stream's end (index k): the pending unload is such a fall (:func:`not_followed`)
    and a diagnostic says so; True when there is no unload to report."""
    if not not_followed(st, k):
        return False
    t0 = float(st.buf.t[st.unload.trigger])
    st.diag("ok", f"the fall confirmed at {t0:.3f} s was not followed: the stream ended "
            f"{float(st.buf.t[k]) - t0:.3g} s later with no fall since: no unload", st.last_t)
    return True
