# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Waiting and confirming phases: the pre-step plateau, the trigger and its confirmation.

:func:`step_waiting` takes the waiting phase's decision at one index, :func:`scan_waiting`
finds the next index where a decision happens among many (applying what the checks before
it do), both from the same :func:`~.decisions.plateau_check`. Values in signal units,
times in s, indices in buffer samples.
"""

from __future__ import annotations

import math

import numpy as np

from pneumatic_unload.estimation.decisions import (
    END_GAP_MIN,
    PERIOD,
    below,
    check_indices,
    confirmed,
    creeping,
    first_below,
    noise_scales,
    nominal_period,
    plateau_check,
)
from pneumatic_unload.estimation.regression import noise_rho
from pneumatic_unload.estimation.state import (
    CONFIRM,
    UNLOADING,
    WAITING,
    EstimatorState,
    UnloadState,
)
from pneumatic_unload.estimation.types import UnloadResult
from pneumatic_unload.estimation.unloading import start_unloading

#: Absolute pressures that an ambient atmosphere takes anywhere a rig stands [Pa]: from
#: 50 kPa (about 5.5 km above sea level) to 110 kPa (above the highest sea-level pressure
#: recorded, 108.4 kPa). A discharge's live stream whose first plateau lies in this band,
#: with p_atm not given, starts on a tank that is already vented.
AMBIENT_RANGE = (50e3, 110e3)


def check_stream_start(st: EstimatorState, i: int) -> None:
    """A live stream's first periodic check (index i [-]): its first samples' mean on the
    end pressure (within END_GAP_MIN of a given p_atm or supply; for a discharge with p_atm
    not given, within :data:`AMBIENT_RANGE`) means the tank was already unloaded when the
    stream began: an unload before it (a node started after the valve opened) was missed,
    or the tank is not charged yet; that is said once, not left to silence."""
    st.start_checked = True
    s = st.settings
    level = st.to_pa(st.buf.mean(0, i + 1))
    end = s.end_pressure
    if end is not None:
        near = abs(level - end) < END_GAP_MIN * end
        where = (f"within {END_GAP_MIN:.0%} of the {'supply' if s.charge else 'atmosphere'}"
                 f" ({end:.0f} Pa)")
    elif not s.charge:
        near = AMBIENT_RANGE[0] <= level <= AMBIENT_RANGE[1]
        where = (f"an ambient pressure ({AMBIENT_RANGE[0] / 1e3:.0f}-"
                 f"{AMBIENT_RANGE[1] / 1e3:.0f} kPa absolute)")
    else:
        return
    if near:
        what = "charged" if s.charge else "vented"
        st.diag("warn", f"missed unload? the stream starts at {level:.0f} Pa, {where}: the "
                f"tank is already {what}: an unload that began before the estimator "
                "started was missed (analyse its record offline, e.g. pneumatic-unload "
                "analyze BAG --start-time T), or the tank is not charged yet; waiting for "
                "the next unload", float(st.buf.t[i]))


def step_waiting(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Periodic plateau update with a block-mean test at a check, or a single-sample
    trigger between checks (see :func:`~.decisions.plateau_check`)."""
    n = i + 1
    buf, s = st.buf, st.settings
    if math.isnan(st.dt_nominal) and n >= 8:
        st.set_period(nominal_period(buf.views(n)[0], n))
    if i == st.next_check and not st.start_checked:
        check_stream_start(st, i)
    if i == st.next_check:
        st.next_check = i + PERIOD
        c = plateau_check(buf.cs, buf.cq, buf.p, i, arm=st.arm_index,
                          min_plateau=s.min_plateau, trigger_sigma=s.trigger_sigma,
                          stuck_reported=st.stuck_reported)
        st.plateau_window, st.scales, st.scaled = (int(c.lo), int(c.hi)), (1.0, 1.0), False
        if c.rise or c.trigger:  # an event for white noise: tested with the plateau's own
            st.scales, st.scaled = _scales(st, i), True
            if st.scales != (1.0, 1.0):
                c = plateau_check(buf.cs, buf.cq, buf.p, i, arm=st.arm_index,
                                  min_plateau=s.min_plateau, trigger_sigma=s.trigger_sigma,
                                  stuck_reported=st.stuck_reported, scales=st.scales)
        st.plateau_level = float(c.level)
        sig = float(c.sigma)
        if c.stuck:
            if not st.stuck_reported:
                st.stuck_reported = True
                st.diag("warn", f"sensor stuck? {c.hi - c.lo} identical samples "
                        f"({float(buf.p[c.lo])!r}): no noise at all", float(buf.t[i]))
        elif sig > 0.0:
            st.stuck_reported = False
        st.sigma = sig
        st.level = float(c.trigger_level)
        if c.rise:
            # the signal rose (the tank is being charged): the plateau starts again after
            # the block that rose (its samples hold the rise, not the plateau)
            st.arm_index = n
            st.stream_start = False
            st.level = -math.inf
            st.rearm_floor = -math.inf
            return []
        if not c.trigger:
            st.trim(n)
            return []
    elif st.level == -math.inf:
        return []
    elif not st.scaled:  # below the white noise's level: tested against the plateau's own
        st.scales, st.scaled = _scales(st, i), True
        st.level = st.plateau_level - (st.plateau_level - st.level) * st.scales[0]
        if not buf.p[i] < st.level:
            return []
    # trigger
    if i - st.arm_index < s.min_plateau:
        return []
    if st.plateau_level < st.rearm_floor and creeping(buf.cs, i, st.sigma * st.scales[1]):
        # not charged since the last unload's tail ended on a level, and falling before
        # the trigger: the same slow discharge creeping on (its tail counted as level), not
        # a new unload (a valve opened again from a level plateau is one)
        if not st.rearm_noted:
            st.rearm_noted = True
            st.diag("ok", "pressure still falling after the unload's final plateau, no "
                    "charge since: not a new unload", float(buf.t[i]))
        st.level = -math.inf
        return []
    end = s.end_pressure
    if end is not None and abs(st.to_pa(st.plateau_level) - end) < END_GAP_MIN * end:
        # a fall on a plateau at the end pressure: nothing to unload, the noise's wander
        if not st.end_noted:
            st.end_noted = True
            st.diag("ok", f"a fall on a plateau at {st.to_pa(st.plateau_level):.0f} Pa, "
                    f"within {END_GAP_MIN:.0%} of the "
                    f"{'supply' if s.charge else 'atmosphere'} ({end:.0f} Pa): nothing "
                    "to unload, not an unload", float(buf.t[i]))
        st.level = -math.inf
        return []
    st.unload = UnloadState(trigger=i)
    st.mode = CONFIRM
    st.next_check = i + PERIOD
    st.level = -math.inf
    return []


def scan_waiting(st: EstimatorState, i: int, end: int) -> int:
    """Next index in [i, end) where :func:`step_waiting` decides something (end: none);
    the checks before it that decide nothing are applied here."""
    s = st.settings
    nc = st.next_check
    pv = np.frombuffer(st.buf.p, dtype=float)
    j = first_below(pv, i, min(end, nc), st.level)
    if j < min(end, nc):
        return j
    if not st.start_checked:  # a live stream's first check: a step (check_stream_start)
        return nc if nc < end else end
    ks = check_indices(nc, end)
    if ks.size == 0:
        return end
    cs, cq = st.buf.sums()
    c = plateau_check(cs, cq, pv, ks, arm=st.arm_index, min_plateau=s.min_plateau,
                      trigger_sigma=s.trigger_sigma, stuck_reported=st.stuck_reported)
    event = c.event
    # samples between checks against the trigger level of the check before them
    seg = pv[ks[0]:end]
    hit = below(seg, np.repeat(c.trigger_level, PERIOD)[:seg.size])
    hit[::PERIOD] = event[:(seg.size + PERIOD - 1) // PERIOD]
    hits = np.flatnonzero(hit)
    if hits.size == 0:
        k, j = ks.size, end
    else:
        j = int(ks[0]) + int(hits[0])
        k = (j - int(ks[0])) // PERIOD  # the check at or before j
        if not event[k] or j != ks[k]:
            k += 1  # between-check hit: check k ran without a decision
    if k > 0:  # state after the last check that decided nothing
        st.plateau_window = (int(c.lo[k - 1]), int(c.hi[k - 1]))
        st.scales, st.scaled = (1.0, 1.0), False
        st.plateau_level = float(c.level[k - 1])
        st.sigma = float(c.sigma[k - 1])
        st.level = float(c.trigger_level[k - 1])
        st.next_check = int(ks[k - 1]) + PERIOD
    return j


def step_confirm(st: EstimatorState, i: int) -> list[UnloadResult]:
    """Confirmation PERIOD samples after the trigger: start the unload, or wait again."""
    u, t = st.unload, st.buf.t
    if confirmed(st.buf.cs, u.trigger, i, st.plateau_level, st.sigma, st.scales[1]):
        # a new unload: the floor of the last one's creeping tail goes (kept through an
        # unconfirmed trigger, which a creeping tail's noise gives; else the next one
        # would start a phantom unload)
        st.rearm_floor = -math.inf
        st.mode = UNLOADING
        st.diag("ok", "unload step detected", float(t[u.trigger]))
        return start_unloading(st, i)
    st.diag("warn", "trigger not confirmed (spike or noise); still waiting",
            float(t[u.trigger]))
    st.mode = WAITING
    st.level = -math.inf
    st.next_check = i + 1
    return []


def _scales(st: EstimatorState, i: int) -> tuple[float, float]:
    """:func:`~.decisions.noise_scales` on the last check's plateau window, for an event
    at index i; white noise's where the window holds sample i (a plateau's first check:
    its window holds the event, whose fall would read as the noise's correlation)."""
    lo, hi = st.plateau_window
    if hi > i:
        return 1.0, 1.0
    return noise_scales(noise_rho(np.frombuffer(st.buf.p, dtype=float)[lo:hi]),
                        hi - lo)
