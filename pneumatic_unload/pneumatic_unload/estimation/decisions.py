# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The detector's per-sample decisions, each written once (vectorised over check indices).

Every predicate takes the prefix sums (see :mod:`.buffer`) and a check index ``k``: a
Python int (the per-sample path, one decision at a time) or an int64 array (the block path,
many checks at once). The formulas are the same numpy expressions for both, so both paths
take bit-identical decisions. Values are in the input's signal units (Pa when the gain is
1), times in s, indices and window lengths in samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.estimation.types import FloatArray

#: Index argument: one check index (int) or many (int64 array) [-].
Index = Any
#: Boolean result: a numpy bool or a bool array, matching the index argument.
Flag = Any

#: Samples between periodic checks [-].
PERIOD = 64
#: Samples used for the plateau level and noise [-].
PLATEAU = 1024
#: Samples that must confirm a trigger [-].
CONFIRM = 64
#: Samples between the end of the reference plateau window and now [-].
LAG = 256
#: Most pre-step plateau samples used by the start (hinge) fit [-]: the start's precision on
#: slow discharges is limited by how well p10 is known (see bench/bench_accuracy.py start),
#: and the plateau costs the fit O(1) per candidate.
HINGE_PLATEAU = 16384
#: Recovery samples needed before the first recovery fit [-].
RECOVERY_MIN = 256
#: Samples looked ahead per vectorised scan [-].
SCAN_HORIZON = 16384
#: Idle samples that may be dropped before the buffer is trimmed, whatever it holds [-].
TRIM_MIN = 65536
#: Fewest droppable samples for which the buffer is trimmed when they are at least half
#: of it [-] (the copy of the rest then costs no more than what is dropped; e.g. the
#: previous unload, when waiting on the next plateau): the buffer holds about one unload,
#: not TRIM_MIN samples more (a sawtooth of 2 MiB per minute on a 10 kHz cycling rig).
TRIM_FLOOR = 8 * PLATEAU
#: Samples of a long plateau kept while waiting [-] (at least; see :func:`idle_keep`): a
#: plateau longer than twice this is trimmed to it, so that an idle record of any length
#: holds a bounded buffer (about 32 B per sample kept). No decision of the waiting phase
#: looks further back than PLATEAU + LAG samples; the start (hinge) fit looks back
#: HINGE_PLATEAU samples plus the trigger-to-10 %-drop span, so its result changes only
#: when that span exceeds IDLE_KEEP - HINGE_PLATEAU samples (a start slower than ~1 M
#: samples).
IDLE_KEEP = 1 << 20
#: Sample period assumed while the nominal one is unknown [s].
DT_DEFAULT = 1e-3
#: Identical consecutive samples that mean a stuck sensor where the pressure must fall [-].
STUCK_RUN = 2 * PERIOD
#: A plateau nearer the given end pressure (the atmosphere of a discharge, the supply of a
#: charge) than this fraction of it has nothing to unload: a fall there is the noise's
#: wander, not an unload [-]. (5 % of p_atm is 5 kPa: p* 1.8 kPa from p_atm, no C to
#: measure; wider than a transducer's zero offset of a few kPa. A transducer low-passed
#: below its logging rate wanders by its marginal deviation, which a plateau's first
#: second cannot show: at p_atm after a tail, or an idle stream's start, that gave
#: 'aborted' and 'ok_subsonic' phantoms.)
END_GAP_MIN = 0.05


def check_indices(next_check: int, end: int) -> NDArray[np.int64]:
    """Periodic check indices from ``next_check`` up to (excluding) ``end`` [-]."""
    return np.arange(next_check, end, PERIOD, dtype=np.int64)


def below(p: Any, level: Any) -> Flag:
    """The level trigger: sample(s) p below ``level`` [signal units] call the decision step
    between periodic checks (:meth:`StreamingEstimator.push` inlines this comparison)."""
    return p < level


def first_below(pv: FloatArray, i: int, hi: int, level: float) -> int:
    """First index in [i, hi) whose sample is :func:`below` ``level``, or hi [-]."""
    if hi <= i or level == -math.inf:
        return hi
    hit = np.flatnonzero(below(pv[i:hi], level))
    return i + int(hit[0]) if hit.size else hi


def nominal_period(tv: FloatArray, n: int) -> float:
    """Nominal sample period: median stamp step of the last 256 of n samples [s]."""
    return float(np.median(np.diff(tv[max(0, n - 256):n])))


def block_threshold(sig_eff: Any) -> Any:
    """Drop of a PERIOD-sample mean that counts as a step [signal units] (sig_eff: the
    effective noise deviation [signal units])."""
    return 6.0 * sig_eff / math.sqrt(PERIOD)


def effective_sigma(sigma: Any, plateau: Any) -> Any:
    """Noise deviation with a floor of 1e-4 of the plateau (quantised or stuck signals)
    [signal units]."""
    return np.maximum(sigma, 1e-4 * np.abs(plateau) + 1e-12)


@dataclass(frozen=True)
class PlateauCheck:
    """Outcome of the waiting state's periodic check(s) (arrays or scalars alike).

    Attributes
    ----------
    level, sigma, trigger_level : float or ndarray
        Plateau mean, its noise deviation and the single-sample trigger level
        [signal units].
    lo, hi : int or ndarray
        Plateau window [lo, hi) [-].
    rise : bool or ndarray
        The last PERIOD samples rose above the plateau (a charge): re-arm.
    trigger : bool or ndarray
        The check sample is below the trigger level, or the block mean dropped.
    stuck : bool or ndarray
        The plateau window has no noise at all (identical samples).
    stuck_change : bool or ndarray
        The stuck-sensor report changes state here.
    trim : bool or ndarray
        The buffer is due for trimming.
    event : bool or ndarray
        Anything but the running statistics changes at this check.
    """

    level: Any
    sigma: Any
    trigger_level: Any
    lo: Any
    hi: Any
    rise: Flag
    trigger: Flag
    stuck: Flag
    stuck_change: Flag
    trim: Flag
    event: Flag


def idle_keep(min_plateau: int) -> int:
    """Samples of a long plateau kept while waiting [-]: IDLE_KEEP, or more when
    ``min_plateau`` [-] asks for a longer plateau (so that trimming never shortens one)."""
    return max(IDLE_KEEP, 2 * min_plateau + 4 * PLATEAU)


def trim_keep(n: Index, arm: int, keep_idle: int = IDLE_KEEP) -> Index:
    """Samples that may be dropped from the buffer's start with n samples held [-]: those
    before the current plateau (``arm``), keeping 4 PLATEAU samples; and on a plateau
    longer than 2 ``keep_idle`` samples, all but its last ``keep_idle`` [-]."""
    long = np.where(n > 2 * keep_idle, n - keep_idle, 0)
    return np.maximum(np.minimum(n - 4 * PLATEAU, arm), long)


def trim_due(keep: Index, n: Index) -> Flag:
    """The buffer of n samples is trimmed when ``keep`` [-] of them may be dropped
    (:func:`trim_keep`): more than TRIM_MIN, or more than TRIM_FLOOR and at least half."""
    return (keep > TRIM_MIN) | ((keep > TRIM_FLOOR) & (2 * keep >= n))


def creeping(cs: FloatArray, k: int, sigma: float) -> bool:
    """The PLATEAU samples ending LAG before a trigger at index k (the current plateau and
    what precedes it in the buffer) fall: the mean of their first half exceeds that of their
    second by more than 3 standard errors (sigma: noise deviation [signal units])."""
    hi = k + 1 - LAG
    lo = max(0, hi - PLATEAU)
    h = (hi - lo) // 2
    if h < PERIOD or not sigma > 0.0:
        return False
    first = (cs[lo + h] - cs[lo]) / h
    second = (cs[hi] - cs[hi - h]) / h
    return bool(first - second > 3.0 * sigma * math.sqrt(2.0 / h))


def noise_scales(rho: float, n: int) -> tuple[float, float]:
    """How much the first differences' noise deviation (:func:`plateau_check`'s sigma)
    understates the deviation of one sample and that of a PERIOD-sample mean tested
    against the mean of an n-sample plateau [-], for AR(1) noise of lag-1 correlation rho
    [-] (:func:`~.regression.noise_rho`); both 1 for white noise.

    1/sqrt(1 - rho) and sqrt(1 + rho)/(1 - rho), the latter at most sqrt(PERIOD) times the
    former (a mean is never noisier than one sample) and times sqrt(1 + PERIOD / n) (the
    plateau's mean is as uncertain on a short plateau). A transducer low-passed well below
    the sampling rate gives such noise (100 Hz sampled at 10 kHz: rho 0.94): read as white,
    an idle stream at rho 0.8-0.99 triggered dozens of phantom unloads a minute.
    """
    if rho == 0.0:
        return 1.0, 1.0
    one = 1.0 / math.sqrt(1.0 - rho)
    block = min(math.sqrt(1.0 + rho) / (1.0 - rho), math.sqrt(PERIOD) * one)
    return one, block * math.sqrt(1.0 + PERIOD / max(n, 1))


def plateau_check(cs: FloatArray, cq: FloatArray, pv: FloatArray, k: Index, *, arm: int,
                  min_plateau: int, trigger_sigma: float, stuck_reported: bool,
                  scales: tuple[float, float] = (1.0, 1.0)) -> PlateauCheck:
    """Periodic plateau update with a block-mean test at check index k.

    The reference level comes from a window that ends LAG samples ago, so a slow discharge
    cannot drag it along; the mean of the last PERIOD samples is tested against it
    (sensitive to slow drops), and the check sample against ``trigger_sigma`` noise
    deviations. ``arm``: first sample of the current plateau [-]. ``scales``: the noise
    deviation's factors for one sample and for a block mean (:func:`noise_scales`; the
    white noise's (1, 1) finds every candidate event, the detector then tests it with the
    plateau's own).
    """
    n = k + 1
    lag = np.minimum(LAG, np.maximum(n - arm - min_plateau, 0))
    hi = n - lag
    lo = np.maximum(arm, hi - PLATEAU)
    # plateau: mean of the window; noise: rms of its first differences / sqrt 2
    plat = (cs[hi] - cs[lo]) / (hi - lo)
    sig = np.sqrt(np.maximum(cq[hi] - cq[lo + 1], 0.0) / (hi - lo - 1) / 2.0)
    sig_eff = effective_sigma(sig, plat)
    level = plat - trigger_sigma * sig_eff * scales[0]
    blo = np.maximum(arm, n - PERIOD)
    bmean = (cs[n] - cs[blo]) / (n - blo)
    bthr = block_threshold(sig_eff * scales[1])
    rise = (lag >= min_plateau) & (n - blo == PERIOD) & (bmean > plat + 2.0 * bthr)
    mean_low = (lag >= PERIOD) & (bmean < plat - bthr)
    trigger = mean_low | below(pv[k], level)
    stuck = (sig == 0.0) & (hi - lo >= 2 * min_plateau)
    stuck_change = (sig > 0.0) if stuck_reported else stuck
    trim = trim_due(trim_keep(n, arm, idle_keep(min_plateau)), n)
    event = rise | trigger | stuck_change | trim
    return PlateauCheck(plat, sig, level, lo, hi, rise, trigger, stuck, stuck_change, trim,
                        event)


def confirmed(cs: FloatArray, trigger: int, k: Index, plateau: float, sigma: float,
              block_scale: float = 1.0) -> Flag:
    """The mean since the trigger (up to index k) stays a block threshold below the
    plateau: the step is real, not a spike (``block_scale``: :func:`noise_scales`'s
    second)."""
    n = k + 1
    mean = (cs[n] - cs[trigger + 1]) / (n - trigger - 1)
    return mean < plateau - block_threshold(effective_sigma(sigma, plateau) * block_scale)


def _imax(a: Index, b: Index) -> Index:
    """np.maximum of indices; the builtin on Python ints (one check index: the per-sample
    path and a block's few checks, where numpy's per-call cost exceeds the arithmetic)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.maximum(a, b)
    return max(a, b)


def _imin(a: Index, b: Index) -> Index:
    """np.minimum of indices; the builtin on Python ints (see :func:`_imax`)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.minimum(a, b)
    return min(a, b)


def stall_window(span: Index) -> Index:
    """Window of the stall test: a quarter of the unload's span, 32..8192 [-]."""
    return _imin(_imax(32, span // 4), 8192)


def stalled(cs: FloatArray, tv: FloatArray, k: Index, *, i0: int, sigma: float,
            slope0: float) -> Flag:
    """The pressure has stopped falling well above p* (valve closed) at index k.

    Compares the means of the last two windows of w samples (w a quarter of the unload,
    32..8192) with 5 % of the initial fall over that time and with 4 noise deviations.
    ``i0``: start index [-], ``sigma``: noise [signal units], ``slope0``: initial fall rate
    [signal units/s].
    """
    span = k - i0
    w = stall_window(span)
    ok = (slope0 > 0) & (span >= 2 * w)
    mid = _imax(k - w + 1, 0)
    a = (cs[mid] - cs[_imax(k - 2 * w + 1, 0)]) / w
    b = (cs[k + 1] - cs[mid]) / w
    dt = tv[k] - tv[_imax(k - w, 0)]
    drop = a - b
    # w >= 32: math.sqrt and np.sqrt are both correctly rounded
    se = sigma * (np.sqrt(2.0 / w) if isinstance(w, np.ndarray) else math.sqrt(2.0 / w))
    return ok & (drop < 0.05 * slope0 * dt) & (drop < 4.0 * se)


#: Widest window of the final-plateau test [-] (see :func:`flat_window`).
FLAT_MAX = 16384
#: Change between the final-plateau test's two windows, as a fraction of the drop from
#: p10, below which the tail counts as level (beside 4 noise deviations) [-]. It sets how
#: near its asymptote the final fit's span ends: about 2.5 x this fraction of the drop is
#: left on an exponential tail. At 0.2 % (until session 25) a slow subsonic tail (b 0.18,
#: m 0.5, 7.8 bar) ended 0.9 kPa above its plateau, so a -0.8 kPa transducer zero was not
#: seen and was read as m 0.600 +- 0.010 (z 10) with a wall at 270 K, or, without the
#: logged temperature, as C -4.2 % at z -3.9.
FLAT_FRACTION = 0.0005


def flat_window(tau: float, dt_nominal: float) -> int:
    """Window of the final-plateau test: half the time scale tau [s], 128..FLAT_MAX [-]."""
    dt = dt_nominal if math.isfinite(dt_nominal) else DT_DEFAULT
    return int(min(max(128, 0.5 * tau / dt), FLAT_MAX))


def flat(cs: FloatArray, k: Index, *, i0: int, tau: float, dt_nominal: float,
         p10: float, sigma: float) -> Flag:
    """The signal has settled on its final plateau at index k (tau: time scale [s]).

    The means of the last two windows differ by less than 4 noise deviations or
    FLAT_FRACTION (0.05 %) of the drop from p10 [signal units]; the unload must be older
    than tau plus two windows. When half of tau is longer than FLAT_MAX samples, the
    windows stay FLAT_MAX long and their change is scaled to half tau
    (``tau / (2 dt FLAT_MAX)``, the slope projected over the window the test is defined
    on) before the FLAT_FRACTION limit: the test does not depend on the sample rate.
    Without the scaling a slow discharge (tau of 10^6 samples and more) passed for level
    about tau after its start, and the rest of it gave a phantom second unload
    (bench/bench_memory.py, stream case).
    """
    dt = dt_nominal if math.isfinite(dt_nominal) else DT_DEFAULT
    w = flat_window(tau, dt_nominal)
    ok = k - i0 >= 2 * w + int(tau / dt)
    a = (cs[np.maximum(k - w + 1, 0)] - cs[np.maximum(k - 2 * w + 1, 0)]) / w
    b = (cs[k + 1] - cs[np.maximum(k - w + 1, 0)]) / w
    dp_total = np.abs(p10 - b)
    change = np.abs(a - b)
    se = sigma * math.sqrt(2.0 / w)
    half = 0.5 * tau / dt  # [-]
    scale = half / w if half > FLAT_MAX else 1.0
    return ok & (change < np.maximum(4.0 * se, FLAT_FRACTION * dp_total / scale))


#: A tail level to :func:`flat` whose last window lies more than this many of its standard
#: errors from the given p_atm (a transducer's zero, or a tail not yet at its plateau) is
#: followed on (:func:`zero_watch`) [-].
ZERO_GAP_Z = 4.0
#: ... for (ZERO_Z sigma / gap)^2 samples past the flat decision, enough to put the gap's
#: mean to within 1 / ZERO_Z of itself [-]: a +0.7 kPa zero at 132 Hz (1 kPa noise) was level 12 s
#: before its record ended, its flat window's 145 samples gave the offset +- 115 Pa, 8.2
#: better in BIC than none (below the threshold of 10), so the zero was not fitted.
ZERO_Z = 10.0
#: ... at most this many flat windows past the flat decision (two time scales) [-].
ZERO_EXTRA_MAX = 4


def zero_watch(cs: FloatArray, k: int, *, tau: float, dt_nominal: float, atm: float,
               sigma: float, max_gap: float = math.inf) -> tuple[int, float]:
    """Samples to follow a tail on past index k, where :func:`flat` found it level, so
    that its settled end determines the gap to the given p_atm ``atm`` [signal units]
    (``sigma``: the sample noise [signal units]; ``tau`` [s] as for :func:`flat`): 0 where
    the last flat window lies within ZERO_GAP_Z of its standard errors of ``atm``, or
    farther than ``max_gap`` [signal units] (no zero offset: a level that far is something
    else); else (ZERO_Z sigma / gap)^2 samples, at most ZERO_EXTRA_MAX windows [-]; and
    the gap, the last window's mean less ``atm`` [signal units]."""
    w = flat_window(tau, dt_nominal)
    level = (cs[k + 1] - cs[max(k - w + 1, 0)]) / w
    gap = abs(level - atm)
    if not (math.isfinite(gap) and sigma > 0.0 and ZERO_GAP_Z * sigma / math.sqrt(w) < gap
            <= max_gap):
        return 0, level - atm
    need = (ZERO_Z * sigma / gap) ** 2
    return int(min(math.ceil(need), ZERO_EXTRA_MAX * w)), level - atm


def settled_at_end(cs: FloatArray, i: int, *, i0: int, p10: float, dp_guess: float) -> bool:
    """p_atm auto at the end of the stream: the last eighth of the unload (at least 8
    samples, up to index i) is level to 0.5 % of the drop, with the drop > 50 % of the
    expected one ``dp_guess`` [signal units]."""
    w = (i - i0) // 8
    if w < 8:
        return False
    a = (cs[i - w + 1] - cs[i - 2 * w + 1]) / w
    b = (cs[i + 1] - cs[i - w + 1]) / w
    drop = p10 - b
    return bool(abs(drop) > 0.5 * dp_guess and abs(a - b) < 0.005 * abs(drop))


def stuck_run(cq: FloatArray, k: Index, *, first: int) -> Flag:
    """The STUCK_RUN samples ending at index k are identical (no first difference at all,
    from the prefix sums cq [signal units^2]): a stuck transducer, when the signal had noise
    before. ``first``: the earliest index the run may start at (the trigger) [-]."""
    lo = k - STUCK_RUN + 1
    return (lo >= first) & (cq[k + 1] - cq[_imax(lo + 1, 0)] == 0.0)


def settle_window(k: Index, origin: int) -> Index:
    """Window of the settling test at index k: an eighth of the samples since ``origin``
    (the unload's trigger), 128..16384 [-]."""
    return np.minimum(np.maximum(128, (k - origin) // 8), SETTLE_MAX)


def settled(cs: FloatArray, cq: FloatArray, k: Index, *, origin: int, since: int,
            drop: float) -> Flag:
    """After a bad unload, the signal has settled on a live plateau at index k.

    The means of the last two windows of w samples (:func:`settle_window`: an eighth of the
    time since ``origin``, so an exponential fall must be ~7 time constants old) differ by
    less than 4 standard errors of their own noise (rms of first differences / sqrt 2) or
    0.2 % of ``drop`` [signal units]; both windows vary (a stuck stretch is no plateau)
    and lie after index ``since`` [-].
    """
    w = settle_window(k, origin)
    ok = k - since >= 2 * w
    mid = np.maximum(k - w + 1, 0)
    lo = np.maximum(k - 2 * w + 1, 0)
    a = (cs[mid] - cs[lo]) / w
    b = (cs[k + 1] - cs[mid]) / w
    qa = cq[mid] - cq[np.minimum(lo + 1, mid)]
    qb = cq[k + 1] - cq[mid + 1]
    sig = np.sqrt(np.maximum(qa + qb, 0.0) / (2 * w - 2) / 2.0)
    se = sig * np.sqrt(2.0 / w)
    return ok & (qa > 0.0) & (qb > 0.0) & (np.abs(a - b) < np.maximum(4.0 * se,
                                                                      0.002 * abs(drop)))


#: Widest settling window, see :func:`settle_window` [-].
SETTLE_MAX = 16384


def block_mean(cs: FloatArray, k: Index) -> Any:
    """Mean of the PERIOD samples ending at index k [signal units]."""
    return (cs[k + 1] - cs[k - PERIOD + 1]) / PERIOD


def rise_threshold(sigma: float, p10: float, atm: float) -> float:
    """Rise of the block mean over its lowest value that ends a tail: max(10 sigma /
    sqrt(PERIOD), 2 % of p10 - p_atm) [signal units]."""
    return max(10.0 * sigma / math.sqrt(PERIOD), 0.02 * abs(p10 - atm))


def running_low(low: float, m: FloatArray) -> FloatArray:
    """Lowest block mean before each of the means m, starting from ``low`` [signal units]."""
    return np.minimum.accumulate(np.concatenate(([low], m)))[:-1]


def rose(m: Any, low: Any, thr: float) -> Flag:
    """The block mean m rose more than thr over the lowest earlier one (the tank is being
    charged again) [signal units]."""
    return (m >= low) & (m - low > thr)


def recovery_due(k: Index, i_close: int, fitted_span: int) -> Flag:
    """A recovery (re)fit is due at index k: RECOVERY_MIN samples since the closing and 25 %
    more than the last fit covered (``fitted_span`` samples) [-]."""
    span = k - i_close
    return (span >= RECOVERY_MIN) & (span >= 1.25 * fitted_span)
