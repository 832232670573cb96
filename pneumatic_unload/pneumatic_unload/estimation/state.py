# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Mutable state of the streaming estimator, shared by its phase modules.

:class:`UnloadState` holds what one unload has established (start, p10, p*, the pending
crossing result, the closing instant of an aborted unload...), :class:`EstimatorState`
the detector's state across unloads (phase, next check, trigger level, plateau and noise,
buffer, counters) with the small helpers every phase uses. Values are in the input's
signal units unless stated (Pa when ``signal_gain`` is 1), times in s, indices in samples
of the buffer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.buffer import ReadingLog, SampleBuffer
from pneumatic_unload.estimation.decisions import (
    DT_DEFAULT,
    PERIOD,
    effective_sigma,
    idle_keep,
    stuck_run,
    trim_due,
    trim_keep,
)
from pneumatic_unload.estimation.history import DiagnosticLog
from pneumatic_unload.estimation.types import Diagnostic, FloatArray, UnloadResult
from pneumatic_unload.physics import P_STAR_FRACTION

#: Phases of the detector (SKIP: the rest of an unload already reported as bad data).
WAITING, CONFIRM, UNLOADING, TAIL, RECOVERY, SKIP = (
    "waiting", "confirming", "unloading", "tail", "recovery", "skipping")


#: Most samples in the crossing fit's window [-] (2 half-widths at the expected slope at
#: p*): a window of 0.05 (p10 - p_atm) either side of p* spans 0.27 tau, millions of
#: samples on a discharge of hours; 2^20 samples (105 s at 10 kHz) already give the
#: crossing time to a few parts per million of tau, and bound what is held before the
#: crossing (issue #13: memory bounded whatever the length of one unload).
CROSSING_WINDOW_MAX = 1 << 20
#: The slope at p* taken as this fraction of the initial slope when bounding the window
#: [-]: P_STAR_FRACTION of it for an exponential fall, halved for the slower fall of a
#: flow turning subsonic (a lower bound of the slope: a bound on the samples).
SLOPE_AT_PSTAR = 0.5 * P_STAR_FRACTION
#: The crossing window's half-width at most this fraction of p*'s height above the end
#: pressure [-]: the window's lower edge, whose first sample closes it, then lies above the
#: end pressure that every unload reaches (a noise read from a start fit that missed the
#: record would put it below, and the unload would wait for a level it never reaches).
CROSSING_HALF_MAX = 0.5


def crossing_half_width(drop: float, sigma: float, slope0: float, dt: float) -> float:
    """Half-width of the crossing window about p* [signal units]: 5 % of the drop
    ``drop`` = p10 - p_atm, at least 6 noise sigmas ``sigma`` (a sample below p* - half is
    then no noise excursion); at most what :data:`CROSSING_WINDOW_MAX` samples span at the
    slope expected at p* (``slope0``: initial fall rate [signal units/s]; ``dt``: sample
    period [s]; not applied while either is unknown). The noise floor wins over the sample
    bound, but never binds on an unload the detector sees: its trigger needs the mean of
    the last PERIOD samples a block threshold (3/4 of a sigma) below a plateau that ends
    LAG samples earlier, a fall of at least 0.0026 sigma per sample at the start, so that
    12 sigmas span at most 12 / (0.184 x 0.0026) = 25 k samples at p*. Whatever the noise,
    at most :data:`CROSSING_HALF_MAX` of p*'s height above the end pressure."""
    half = 0.05 * drop
    cap = 0.5 * CROSSING_WINDOW_MAX * dt * SLOPE_AT_PSTAR * slope0
    if math.isfinite(cap) and cap > 0:
        half = min(half, cap)
    return min(max(6.0 * sigma, half), CROSSING_HALF_MAX * P_STAR_FRACTION * drop)


@dataclass
class UnloadState:
    """What the current unload has established so far (signal units, s, buffer indices).

    Attributes
    ----------
    trigger : int
        Index of the sample that triggered the detection [-].
    dp_guess : float
        Expected drop p10 - p_atm before the start fit [signal units].
    refined : bool
        The start (hinge) fit has run: t0, i0, p10, slope0 are known.
    t0, t0_std : float
        Start instant and its standard deviation [s].
    p10_var, t0_p10_cov : float
        The start fit's variance of p10 [signal units^2] and covariance of t0 with p10
        [s signal units] (p* moves with p10, so the crossing moves with it).
    i0 : int
        First sample at or after t0 [-].
    p10 : float
        Pre-step plateau [signal units].
    slope0 : float
        Initial fall rate [signal units/s].
    atm, pstar, half : float
        p_atm, p* and the half-width of the crossing window [signal units] (NaN until
        known).
    atm_var : float
        Variance of p_atm when it is the final plateau's mean [signal units^2]; 0 when
        given.
    inflation : float
        Variance inflation of correlated noise, (1 + rho)/(1 - rho) of the pre-step
        plateau's AR(1) rho (:func:`~.regression.variance_inflation`), by which the start,
        the crossing and p_atm's white-noise variances are multiplied [-]; 1 for white
        noise.
    pending : UnloadResult or None
        Crossing result waiting for the end of the tail (curve fit).
    tail_low : float
        Lowest PERIOD-sample mean of the tail so far [signal units].
    t_close, p_close : float
        Closing instant [s] and pressure [signal units] of an aborted unload.
    i_close : int
        First sample at or after the closing instant [-].
    rec_span : int
        Samples covered by the last recovery fit [-].
    rec_fit : Any
        Last recovery fit (:func:`pneumatic_unload.curvefit.recovery.fit_recovery`), or None.
    mid_pending : bool
        The inversion table is still to be built, when the pressure is half way to p*.
    plan : Any
        The crossing estimate prepared half way to p* (the model's crossing times
        tabulated, the budgets scaled to C: :class:`.crossing.CrossingPlan`), or None.
    noisy : bool
        The pre-step plateau had noise (so identical samples later mean a stuck sensor).
    skip_since : int
        Index where the rest of a bad unload started being skipped [-] (may go negative
        when the buffer is trimmed, like ``trigger``).
    skip_rise : float
        Rise of the block mean over its lowest value that ends the skip (a new charge)
        [signal units].
    rec_high : float
        Highest PERIOD-sample mean of the recovery so far [signal units].
    reduced : Any
        The fit window's samples already reduced to bins and dropped from the buffer (a
        long unload, see :mod:`.reduction`; :class:`pneumatic_unload.fit.reduced.Reducer`),
        or None.
    zero_until : int or None
        Stream index up to which a level tail is followed on for its gap to the given
        p_atm (:func:`~.decisions.zero_watch`), or None [-].
    """

    trigger: int
    dp_guess: float = math.nan
    refined: bool = False
    t0: float = math.nan
    t0_std: float = math.nan
    p10_var: float = math.nan
    t0_p10_cov: float = math.nan
    i0: int = -1
    p10: float = math.nan
    slope0: float = math.nan
    atm: float = math.nan
    pstar: float = math.nan
    half: float = math.nan
    atm_var: float = 0.0
    inflation: float = 1.0
    pending: UnloadResult | None = None
    tail_low: float = math.inf
    t_close: float = math.nan
    p_close: float = math.nan
    i_close: int = -1
    rec_span: int = 0
    rec_fit: Any = None
    mid_pending: bool = False
    plan: Any = None
    noisy: bool = False
    skip_since: int = -1
    skip_rise: float = math.nan
    rec_high: float = -math.inf
    reduced: Any = None
    zero_until: int | None = None


def tau_sigma(u: UnloadState, t_std: float, slope: float) -> float:
    """1-sigma of tau_exp = t_cross - t0 [s] from the crossing fit's t_std [s] and its
    slope at p* [signal units/s], with the start fit's (co)variance of (t0, p10).

    p* = p_atm + P_STAR_FRACTION (p10 - p_atm) is made from the fitted p10 (and p_atm
    when it is the final plateau's mean), so the crossing moves by dp*/slope with them;
    a plateau fitted low also starts the fall later (t0 and p10 are correlated), which
    offsets part of that move: tau's variance is the gradient (-1, f/slope) through
    the start fit's covariance, not the sum of the two sigmas in quadrature. The crossing
    fit's variance (a white-noise formula) is times ``u.inflation`` (correlated noise; the
    start's and p_atm's are already).
    """
    t_std = t_std * math.sqrt(u.inflation)
    if not (slope != 0.0 and math.isfinite(slope)):
        return math.hypot(t_std, u.t0_std)
    a = P_STAR_FRACTION / slope
    var = (t_std * t_std + u.t0_std * u.t0_std - 2.0 * a * u.t0_p10_cov
           + a * a * u.p10_var + ((1.0 - P_STAR_FRACTION) / slope) ** 2 * u.atm_var)
    return math.sqrt(var) if var >= 0.0 else math.hypot(t_std, u.t0_std)


class EstimatorState:
    """Detector state across unloads and the helpers the phases share.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and detection settings.
    live : bool
        The stream may join an unload under way (see
        :func:`~.record_head.first_unload_check`).
    defer_final_fit : bool
        Keep each unload's final curve fit as a job in :attr:`final_fits` instead of
        running it inside the call that completes the unload.
    """

    def __init__(self, settings: EstimatorSettings, *, live: bool = False,
                 defer_final_fit: bool = False, diagnostics: DiagnosticLog | None = None,
                 tag: str = "") -> None:
        self.settings = settings
        #: Put before every diagnostic's message (a stream's two estimators, one per flow
        #: direction, share one log: :class:`~.two_way.TwoWayEstimator`).
        self.tag = tag
        self.live = live
        self.defer_final_fit = defer_final_fit
        #: Final-fit jobs not yet taken (``defer_final_fit``; :class:`~.tail.FinalFit`).
        self.final_fits: list[Any] = []
        self.buf = SampleBuffer()
        #: The logged gas temperature [s], [K] fitted beside the pressure by the final fits.
        self.temperature = ReadingLog()
        #: The first and the last diagnostics (bounded, see :mod:`.history`).
        self.diagnostics = DiagnosticLog() if diagnostics is None else diagnostics
        self.n_unloads = 0
        self.last_t = -math.inf  # last accepted stamp [s]
        self.dt_nominal = math.nan  # nominal sample period [s]
        self.gap_limit = math.inf  # stamp step that counts as a gap [s]
        self.stuck_reported = False
        self.clock_step_at = -1  # samples accepted when the last clock step was handled
        #: After an unload whose tail ended on a level plateau: the plateau level a trigger
        #: needs (a charge since), else it is the same discharge going on [signal units].
        self.rearm_floor = -math.inf
        self.rearm_noted = False  # said once that a trigger below the floor was ignored
        self.unload = UnloadState(trigger=-1)
        self.to_waiting(0)
        #: The current plateau began with the stream's first sample (no re-arm yet).
        self.stream_start = True
        #: A live stream's first plateau was checked for a tank already unloaded (a node
        #: that started after the opening: :func:`~.detector.check_stream_start`).
        self.start_checked = not live

    # -------------------------------------------------------------- transitions
    def to_waiting(self, n: int) -> None:
        """Re-arm: wait for a new plateau starting at index n [-]."""
        self.mode = WAITING
        self.stream_start = False
        self.level = -math.inf  # a sample below this level calls the step [signal units]
        self.next_check = n + self.settings.min_plateau - 1  # next periodic check [-]
        self.arm_index = n  # first sample of the current plateau [-]
        self.unload = UnloadState(trigger=-1)
        self.gap_in_unload = False
        self.plateau_level = math.nan  # [signal units]
        self.sigma = math.nan  # noise standard deviation [signal units]
        #: The last check's plateau window [lo, hi) [-], and the noise's factors on it for
        #: one sample and a block mean (decisions.noise_scales), computed (``scaled``)
        #: only where the white noise's thresholds see an event.
        self.plateau_window = (0, 0)
        self.scales = (1.0, 1.0)
        self.scaled = False
        self.end_noted = False  # said once that this plateau is at the end pressure

    def set_pstar(self, atm: float) -> None:
        """Set p_atm (and so p* and the crossing window) [signal units]."""
        u = self.unload
        u.atm = atm
        dp = u.p10 - atm
        u.pstar = atm + P_STAR_FRACTION * dp
        u.half = crossing_half_width(abs(dp), self.sigma, u.slope0, self.dt_nominal)
        self.level = u.pstar - u.half

    def trim(self, n: int) -> None:
        """Drop samples that no later decision can need (keeps memory bounded while
        waiting, see :data:`~.decisions.IDLE_KEEP`); n: samples held [-]. A plateau trimmed
        from its start begins at the buffer's first sample."""
        keep = int(trim_keep(n, self.arm_index, idle_keep(self.settings.min_plateau)))
        if trim_due(keep, n) and self.mode == WAITING:
            self.buf.trim(keep)
            self.next_check -= keep
            self.arm_index = max(self.arm_index - keep, 0)
            lo, hi = self.plateau_window
            self.plateau_window = (max(lo - keep, 0), max(hi - keep, 0))

    # -------------------------------------------------------------- helpers
    def set_period(self, dt_nominal: float) -> None:
        """Set the nominal sample period [s], and so the gap limit ``max_gap_factor``
        periods [s] (inf while the period is unknown)."""
        self.dt_nominal = dt_nominal
        self.gap_limit = (math.inf if math.isnan(dt_nominal)
                          else self.settings.max_gap_factor * dt_nominal)

    @property
    def dt(self) -> float:
        """Nominal sample period, DT_DEFAULT while unknown [s]."""
        return self.dt_nominal if math.isfinite(self.dt_nominal) else DT_DEFAULT

    def stuck(self, k: Any) -> Any:
        """:func:`~.decisions.stuck_run` at index (or indices) k during the current unload,
        whose pressure keeps changing until its final plateau and whose plateaus are as
        noisy as its pre-step one; only when that plateau had noise (a noiseless, quantised
        signal may repeat a value)."""
        u = self.unload
        cq = self.buf.sums()[1] if isinstance(k, np.ndarray) else self.buf.cq
        return stuck_run(cq, k, first=u.trigger) & u.noisy

    def end_unknown(self, where: str = "") -> str:
        """What is unknown without a final plateau (``where``: said after it), and what
        to give."""
        if self.settings.charge:
            return (f"the supply unknown{where} (give the supply pressure, "
                    "--supply-pressure PA)")
        return f"p_atm unknown{where} (give the atmospheric pressure, --atmosphere PA)"

    def diag(self, level: str, message: str, t: float) -> None:
        """Record a diagnostic ('ok', 'warn', 'error') at sample time t [s]."""
        self.diagnostics.append(Diagnostic(level, self.mode, f"{self.tag}{message}", t))

    def to_pa(self, x: float) -> float:
        """Signal value to pressure [Pa]."""
        return self.settings.signal_offset + self.settings.signal_gain * x

    def to_pa_array(self, x: FloatArray) -> FloatArray:
        """Signal values to pressures [Pa]."""
        s = self.settings
        return s.signal_offset + s.signal_gain * x

    def empty_result(self, status: str, text: str, i: int, *, count: bool = True
                     ) -> UnloadResult:
        """A result without estimates, completed at index i [-]; ``count``: it takes a new
        unload index."""
        s = self.settings
        nan = math.nan
        res = UnloadResult(
            index=self.n_unloads, status=status, status_text=text, t_start=nan, t_cross=nan,
            tau_exp=nan, tau_exp_std=nan, p10=nan, p_atm=s.atmosphere or nan, p_star=nan,
            direction=s.direction, supply_pressure=s.supply_pressure or nan,
            initial_temperature=s.initial_temperature, volume=s.volume, conductance=nan,
            conductance_model=nan, conductance_model_std=nan, quality=0.0,
            method="unloading-time", i_complete=i + self.buf.shift,
            t_complete=float(self.buf.t[i]))
        if count:
            self.n_unloads += 1
        return res

    def bad(self, i: int, text: str) -> list[UnloadResult]:
        """Unusable data at index i: a 'bad_data' result, then skip the rest of this
        unload (:meth:`to_skip`): one physical unload gives one result."""
        self.diag("error", text, float(self.buf.t[i]))
        res = self.empty_result("bad_data", text, i)
        self.to_skip(i)
        return [res]

    def to_skip(self, i: int) -> None:
        """Skip the rest of the unload reported bad at index i [-]: no re-arming until the
        signal settles on a live plateau or rises (a new charge), see
        :func:`pneumatic_unload.estimation.tail.step_skip`."""
        u = self.unload
        u.trigger = max(u.trigger, 0)
        u.skip_since = i
        sig = float(effective_sigma(self.sigma, self.plateau_level))
        dp = u.dp_guess if math.isfinite(u.dp_guess) else 0.0
        u.skip_rise = max(10.0 * sig / PERIOD ** 0.5 if math.isfinite(sig) else 0.0,
                          0.02 * dp)
        u.tail_low = math.inf
        self.mode = SKIP
        self.level = -math.inf
        self.next_check = i + PERIOD
