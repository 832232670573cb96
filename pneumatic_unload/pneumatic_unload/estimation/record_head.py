# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The head of an unload: whether the samples before a fitted start are a plateau, and
whether a record without one holds its valve opening.

A record that begins after the opening (cut mid-discharge) falls at its first sample at its
full rate: its own p10 and start would be taken, and C comes out low. :func:`no_plateau`
tells a pre-step plateau from a fall already under way, :func:`first_unload_check` decides
for a stream's first unload (live: skipped with a warning; offline: judged by the caller),
and :func:`opening_in_record` refuses an offline record whose opening is not in it, saying
what to pass instead. Values in signal units unless stated, times in s.
"""

from __future__ import annotations

import math

from pneumatic_unload.estimation.regression import rms_sigma
from pneumatic_unload.estimation.state import EstimatorState
from pneumatic_unload.estimation.types import FloatArray

#: Fall rate of the samples before the start, as a fraction of the initial fall rate, that
#: makes them no plateau (a continuing unload, not a step) [-].
PLATEAU_FALL_FRACTION = 0.25


def no_plateau(t: FloatArray, p: FloatArray, min_plateau: int, slope0: float,
               fraction: float = PLATEAU_FALL_FRACTION) -> str:
    """Why the samples before a fitted start are no pre-step plateau, or '' when they are:
    they are none when fewer than ``min_plateau`` [-] (p10 is not measured), when their
    straight-line fall rate is both significant (more than 4 standard errors, the noise
    from first differences) and more than ``fraction`` of the initial fall rate ``slope0``
    [signal units/s] (the "step" continues a fall already under way), or when they are too
    few to resolve such a fall (4 standard errors above that fraction, when not 0). ``t`` [s]
    and ``p`` [signal units]: the samples from the plateau's first one up to the start.
    """
    n = p.size
    if n < min_plateau:
        return (f"no plateau before the drop ({n} samples before the start, fewer than "
                f"min_plateau={min_plateau})")
    tc = t - t.mean()
    sxx = float(tc @ tc)
    if not (sxx > 0.0 and slope0 > 0.0):
        return ""
    fall = -float(tc @ (p - p.mean())) / sxx
    se = rms_sigma(p) / math.sqrt(sxx)
    if fall > 4.0 * se and fall > fraction * slope0:
        return (f"no plateau before the drop (the {n} samples before the start fall at "
                f"{fall:.4g} /s, {100.0 * fall / slope0:.0f} % of the initial fall rate)")
    if 0.0 < fraction and 4.0 * se > fraction * slope0:
        # too short to tell: a slow tail joined late looks flat over a few dozen samples
        # and then "drops" (a bogus unload, C tens of % off)
        return (f"no plateau before the drop that can be told from a fall under way (the "
                f"{n} samples before the start resolve a fall rate of {4.0 * se:.4g} /s, "
                f"more than {100 * fraction:.0f} % of the initial "
                f"{slope0:.4g} /s)")
    return ""


def first_unload_check(st: EstimatorState, i: int, t: FloatArray, p: FloatArray,
                       slope0: float, drift: float = 0.0) -> tuple[bool, str]:
    """The first unload of a stream, whose plateau began with the stream's first sample:
    (skip, why): skip is True when it is to be skipped (decided at index i [-]; t [s], p
    [signal units]: the samples before its start; slope0: initial fall rate [signal
    units/s]; ``drift``: the plateau's fitted drift [signal units/s], 0 if none: then a
    live stream's first samples falling at all are no plateau, e.g. a 5 L unload joined
    1.2 s in); why is the reason it has no plateau ('' when it has one).

    Without a pre-step plateau (:func:`no_plateau`) a live stream (``live``: a node that
    may start or restart at any time) joined an unload under way: no result for it, a
    warning, and the rest of it is skipped until a plateau. Offline, a record is taken to
    start where its author chose: the caller judges whether the opening is in it
    (:func:`opening_in_record`, once the start's uncertainty is known).
    """
    st.stream_start = False
    why = no_plateau(t, p, st.settings.min_plateau, slope0,
                     0.0 if st.live and drift != 0.0 else PLATEAU_FALL_FRACTION)
    if not why:
        return False, ""
    if st.live:
        st.diag("warn", f"{why}: the stream started during an unload (estimator started or "
                        f"restarted mid-unload): no estimate for this unload; waiting for a "
                        f"plateau before the next one", float(st.buf.t[i]))
        st.to_skip(i)
        return True, why
    return False, why


#: The fitted opening of a record without a plateau must lie at least this many of its
#: standard errors after the record's first sample to be in the record [-]: closer, the
#: record's first samples already fall as the fitted start's neighbourhood does (one-sided
#: 4 sigma: a record that truly begins on a flat stretch fails it with a probability of
#: about 3e-5 for a normal error of the start).
OPENING_IN_RECORD_Z = 4.0


#: The words of a refusal of :func:`opening_in_record` that say what to pass instead (the
#: opening as the start time); a caller that locates unloads with the estimator (the
#: discrepancy workflow) passes such a refusal on.
OPENING_HINT = "give the opening: --start-time"


#: Samples at the head of a record that show whether its fall is still gathering pace [-]:
#: the fewest through which a straight line has a residual (a rate and its noise).
RAMP_SAMPLES = 3


def opening_in_record(t_head: FloatArray, p_head: FloatArray, t0: float, t0_std: float,
                      slope0: float, sigma: float, why: str) -> str:
    """'' when the opening of a record without a plateau (``why``: the reason it has none)
    is in the record; else why the unload is refused, with what to pass instead.

    The opening is in the record when the fitted start t0 [s] lies
    :data:`OPENING_IN_RECORD_Z` standard errors ``t0_std`` [s] or more after its first
    sample (flat samples before it), or when its first samples (``t_head`` [s], ``p_head``
    [signal units]: :data:`RAMP_SAMPLES` of them) fall slower than the start fit's initial
    rate slope0 [signal units/s] by that many standard errors of their rate (sigma [signal
    units]: the start window's noise, :func:`~.regression.curvature_sigma`): the valve's
    opening ramp, the fall gathering pace. A
    record cut after the opening falls at the first sample at its full rate, slowing: its
    own p10 and start would be taken (a 5 L tank's record cut 1 s in: C 4 % low)."""
    lead = t0 - float(t_head[0])
    z = lead / t0_std if t0_std > 0.0 else (math.inf if lead > 0.0 else 0.0)
    if z >= OPENING_IN_RECORD_Z:
        return ""
    tc = t_head - t_head.mean()
    sxx = float(tc @ tc)
    if sxx > 0.0 and sigma > 0.0 and math.isfinite(slope0):
        fall = -float(tc @ (p_head - p_head.mean())) / sxx
        if (slope0 - fall) / (sigma / math.sqrt(sxx)) >= OPENING_IN_RECORD_Z:
            return ""
    t_first = float(t_head[0])
    return (f"{why}, and the pressure already falls at the record's first sample at its "
            f"full rate (the fitted opening lies {lead:.3g} s after it, {z:.1f} standard "
            f"errors of the start, fewer than {OPENING_IN_RECORD_Z:g}; no opening ramp in "
            f"its first {t_head.size} samples): the record begins at or after the valve "
            f"opening, and its p10 and start are not measured. If it begins at the "
            f"opening, {OPENING_HINT} {t_first:.6g} (start_time) with "
            f"--atmosphere PA and, when no sample falls on the opening, --initial-pressure "
            f"PA (docs: Records that begin at the opening); if it begins later, the unload "
            f"cannot be measured from it")
