# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Batch analysis of a whole trace, one result per unload, and why a trace gave none
(SI units: s, Pa absolute)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from pneumatic_unload.charge import charge_p_star
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.decisions import LAG, PERIOD, PLATEAU, block_threshold
from pneumatic_unload.estimation.sparse import analyze_from_start
from pneumatic_unload.estimation.two_way import stream_estimator
from pneumatic_unload.estimation.types import Analysis, Diagnostic, UnloadResult
from pneumatic_unload.physics import p_star


def analyze(
    t: ArrayLike, p: ArrayLike, settings: EstimatorSettings | None = None
) -> Analysis:
    """Batch analysis of a trace: every unload found, in order.

    Parameters
    ----------
    t : array_like
        Sample instants [s], strictly increasing.
    p : array_like
        Pressure [Pa absolute] (or a linear signal with ``signal_gain``/``signal_offset``).
    settings : EstimatorSettings, optional
        Tank and detection settings.

    Returns
    -------
    Analysis
        A list of the results as the streaming estimator emits them (crossing estimates,
        then the curve-fit refinement with ``final=True`` when the unload's end was
        recorded). With ``settings.start_time`` the record begins at the opening: see
        :func:`~pneumatic_unload.estimation.sparse.analyze_from_start`. When it is empty,
        its ``no_unload_reason`` says why (:func:`explain_no_unload`: the reason the CLI
        prints), and what to pass instead where known.

    Raises
    ------
    EstimationError
        Too few samples or mismatched arrays.
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(p, dtype=float)
    if t.shape != p.shape or t.ndim != 1:
        raise EstimationError(f"t and p must be 1-D arrays of equal length, got {t.shape} "
                              f"and {p.shape}")
    if settings is not None and settings.start_time is not None:
        # a record that begins at the opening
        found = analyze_from_start(t, p, settings)
        why = None if found else (
            f"no unload from start_time = {settings.start_time:g} s: the record does not "
            "fall from there (check start_time, atmosphere and initial_pressure)")
        return Analysis(found, no_unload_reason=why)
    if t.size < 16:
        raise EstimationError(f"too few samples ({t.size}); need at least 16 ({START_HINT})")
    est = stream_estimator(settings or EstimatorSettings())
    out = est.push_block(t, p)
    out += est.finish()
    why = None if out else explain_no_unload(t, p, settings, diagnostics=est.diagnostics)
    return Analysis(out, no_unload_reason=why, diagnostics=est.diagnostics)


def merge_final(results: list[UnloadResult]) -> list[UnloadResult]:
    """One result per unload: the final (curve-fit) one where it exists, else the first.

    Parameters
    ----------
    results : list of UnloadResult
        Results as emitted (crossing estimate, then final refinement).
    """
    by_index: dict[int, UnloadResult] = {}
    for r in results:
        if r.index not in by_index or r.final:
            by_index[r.index] = r
    return [by_index[k] for k in sorted(by_index)]


#: A final plateau below this fraction of the stated p_atm means gauge readings [-].
GAUGE_FINAL_FRACTION = 0.5
#: Fewest finite samples beyond ``min_plateau`` that can hold a drop and its crossing [-].
MIN_UNLOAD_SAMPLES = 16
#: What to pass for a record that begins at the valve opening, without a plateau
#: (command line and library).
START_HINT = ("a record that begins at the valve opening, without a plateau before it: pass "
              "--start-time S (the opening), --atmosphere PA and --initial-pressure PA; "
              "library: start_time, atmosphere, initial_pressure")
#: How to fix gauge readings taken as absolute (command line and library).
GAUGE_FIX = ("pass --gauge --atmosphere PA (library: add p_atm [Pa] to the readings, or "
             "signal_offset=p_atm)")


def _finite_pa(t: ArrayLike, p: ArrayLike, s: EstimatorSettings
               ) -> tuple[np.ndarray, np.ndarray]:
    """Finite samples: times [s] and pressures [Pa] (signal converted by gain and offset)."""
    t = np.asarray(t, dtype=float)
    p = np.asarray(p, dtype=float)
    if t.shape != p.shape or t.ndim != 1:
        raise EstimationError(f"t and p must be 1-D arrays of equal length, got {t.shape} "
                              f"and {p.shape}")
    ok = np.isfinite(t) & np.isfinite(p)
    return t[ok], s.signal_offset + s.signal_gain * p[ok]


def _noise_std(pp: np.ndarray) -> float:
    """Robust white-noise standard deviation of pressures [Pa] (MAD of first differences)."""
    if pp.size < 3:
        return 0.0
    d = np.diff(pp)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _final_level(pp: np.ndarray, s: EstimatorSettings) -> float:
    """Median of the last ``min_plateau`` readings [Pa] (the final plateau, if recorded)."""
    return float(np.median(pp[-min(pp.size, s.min_plateau):]))


def gauge_suspicion(t: ArrayLike, p: ArrayLike, settings: EstimatorSettings | None = None
                    ) -> str | None:
    """Why the readings look like gauge pressures taken as absolute, or None.

    A record in Pa absolute never reads at or below 0 Pa, and it ends near p_atm: a final
    plateau below ``GAUGE_FINAL_FRACTION`` of the stated atmosphere, or readings at or below
    zero (more than 0.1 % of them, at least 3), mean that the gauge readings were not
    converted (the CLI's ``--gauge`` was forgotten); C computed from them is wrong.

    Parameters
    ----------
    t : array_like
        Sample instants [s].
    p : array_like
        Pressure [Pa absolute] (or a signal converted by ``signal_gain``/``signal_offset``).
    settings : EstimatorSettings, optional
        ``atmosphere`` [Pa], ``min_plateau`` and the signal conversion.

    Returns
    -------
    str or None
        One line naming the evidence and the fix, or None when the readings look absolute.
    """
    s = settings or EstimatorSettings()
    _tt, pp = _finite_pa(t, p, s)
    if pp.size == 0:
        return None
    return gauge_evidence(_final_level(pp, s), int(np.count_nonzero(pp <= 0.0)), pp.size, s)


def gauge_evidence(final: float, n_low: int, n_finite: int,
                   settings: EstimatorSettings | None = None) -> str | None:
    """:func:`gauge_suspicion` from a record's statistics (for records read in chunks).

    Parameters
    ----------
    final : float
        Median of the last ``min_plateau`` finite readings [Pa].
    n_low : int
        Finite readings at or below 0 Pa [-].
    n_finite : int
        Finite readings [-].
    settings : EstimatorSettings, optional
        ``atmosphere`` [Pa].

    Returns
    -------
    str or None
        One line naming the evidence and the fix, or None when the readings look absolute.
    """
    s = settings or EstimatorSettings()
    if n_finite == 0:
        return None
    evidence = []
    if s.atmosphere is not None and final < GAUGE_FINAL_FRACTION * s.atmosphere:
        evidence.append(f"final plateau {final:.0f} Pa, far below p_atm = "
                        f"{s.atmosphere:.0f} Pa")
    if n_low >= max(3, int(0.001 * n_finite)):
        evidence.append(f"{n_low} of {n_finite} readings at or below 0 Pa")
    if not evidence:
        return None
    return f"readings look like gauge pressures ({'; '.join(evidence)}): {GAUGE_FIX}"


#: Smallest rise of a record, as a fraction of its end level, read as a charge [-].
CHARGE_RISE = 0.05


def charge_reason(pp: np.ndarray, s: EstimatorSettings) -> str | None:
    """Why a record that only rises holds no unload (a charge: the tank filled through the
    component), or None. pp: the finite pressures [Pa]."""
    hi = float(np.max(pp)) if pp.size else 0.0
    threshold = s.trigger_sigma * max(_noise_std(pp), 1e-9 * abs(hi))
    start = float(np.median(pp[:4]))
    end = float(np.median(pp[-max(4, pp.size // 50):]))
    # a charge rises by a good part of its end level (a vacuum fill by nearly all of it)
    if end - start <= max(threshold, CHARGE_RISE * end) or np.any(pp < start - threshold):
        return None
    return (f"the pressure rises from {start:.0f} Pa to {end:.0f} Pa and never falls: a "
            f"charge (the tank filled through the component)? analyse it as one: "
            f"--direction charge (library: direction='charge'; the supply from the final "
            f"plateau or --supply-pressure PA)")


def _no_charge_reason(t: ArrayLike, p: ArrayLike, tt: np.ndarray, pp: np.ndarray,
                      s: EstimatorSettings, diagnostics: Sequence[Diagnostic] | None) -> str:
    """Why a record analysed as a charge holds none (tt [s], pp [Pa]: its finite samples):
    no rise (a discharge?), no plateau before it, a rise that never reaches p*, else the
    estimator's diagnostics."""
    threshold = s.trigger_sigma * max(_noise_std(pp), 1e-9 * float(np.max(np.abs(pp))))
    start = float(np.median(pp[:4]))
    above = np.flatnonzero(pp > start + threshold)
    if above.size == 0:
        fell = float(np.min(pp)) < start - threshold
        return (f"no rise: the pressure never rises {threshold:.3g} Pa (trigger_sigma="
                f"{s.trigger_sigma:g} noise std) above its initial {start:.0f} Pa"
                + (": it falls, a discharge? (--direction discharge)" if fell else
                   "; no charge recorded (or the record starts after it)"))
    i_rise = int(above[0])
    if i_rise < s.min_plateau:
        return (f"no plateau before the rise: the pressure rises from sample {i_rise} "
                f"(t = {tt[i_rise]:.6g} s), but a pre-trigger plateau of at least "
                f"min_plateau={s.min_plateau} samples is needed: record from before the "
                f"valve opens; or, for a record that begins at the opening, pass "
                f"--start-time S and --initial-pressure PA")
    p10 = float(np.median(pp[:i_rise]))
    supply = s.supply_pressure if s.supply_pressure is not None else \
        float(np.median(pp[-max(4, pp.size // 50):]))
    if not supply > p10:
        return (f"the supply ({supply:.0f} Pa) is not above p10 ({p10:.0f} Pa): nothing "
                f"flows into the tank")
    ps = charge_p_star(p10, supply)
    high = float(np.max(pp[i_rise:]))
    if high < ps:
        return (f"the pressure never rose to p* = {ps:.0f} Pa (p10 = {p10:.0f} Pa, supply = "
                f"{supply:.0f} Pa, highest reading {high:.0f} Pa): the valve closed early "
                f"or the record ends too soon")
    return estimator_reason(t, p, s, diagnostics)


def explain_no_unload(t: ArrayLike, p: ArrayLike, settings: EstimatorSettings | None = None,
                      *, diagnostics: Sequence[Diagnostic] | None = None,
                      stride: int = 1) -> str:
    """Why :func:`analyze` found no unload in a trace, in one line.

    Checked in this order: no finite sample; too few samples; time stamps not increasing (a
    reversed record); readings at or below zero or below p_atm throughout, or a final
    plateau far below p_atm (gauge readings taken as absolute); a constant signal; no drop;
    no plateau of ``min_plateau`` samples before the drop (a record that starts at the valve
    opening); a drop that never reaches p* (eq 40); a fall too slow for the detector at the
    sample rate (:func:`too_slow_to_detect`); else the estimator's own diagnostics.

    Parameters
    ----------
    t : array_like
        Sample instants [s].
    p : array_like
        Pressure [Pa absolute] (or a signal converted by ``signal_gain``/``signal_offset``).
    settings : EstimatorSettings, optional
        The settings :func:`analyze` was called with.
    diagnostics : sequence of Diagnostic, optional
        The estimator's diagnostics on this trace with these settings, when known (else
        the estimator runs again on t and p).
    stride : int
        Samples of the record per element of t and p (a decimated overview) [-].

    Returns
    -------
    str
        The reason, with what would fix it where known.
    """
    s = settings or EstimatorSettings()
    n = np.asarray(t).size
    tt, pp = _finite_pa(t, p, s)
    m = tt.size
    if m == 0:
        return f"all {n} samples are non-finite (NaN or inf time stamps or pressures)"
    need = s.min_plateau + MIN_UNLOAD_SAMPLES
    if m < need:
        return (f"too few samples: {m} finite of {n}; a pre-trigger plateau of min_plateau="
                f"{s.min_plateau} samples and the drop need at least {need} (or {START_HINT})")
    dt = np.diff(tt)
    back = int(np.count_nonzero(dt <= 0.0))
    if back > dt.size // 2:
        return (f"time stamps are not increasing ({back} of {dt.size} steps go backwards or "
                f"stand still; a reversed record?): sort the samples by time")
    hi = float(np.max(pp))
    if hi <= 0.0:
        return (f"all readings are at or below 0 Pa (highest {hi:.0f} Pa): gauge pressures "
                f"taken as absolute? {GAUGE_FIX}")
    if s.direction == "both":
        return (f"no step either way: as a discharge, "
                f"{explain_no_unload(t, p, s.one_way('discharge'), stride=stride)}; as a "
                f"charge, {explain_no_unload(t, p, s.one_way('charge'), stride=stride)}")
    if s.charge:
        return _no_charge_reason(t, p, tt, pp, s, diagnostics)
    rise = charge_reason(pp, s)
    if rise is not None:
        return rise
    if s.atmosphere is not None and hi <= s.atmosphere:
        return (f"all readings are at or below p_atm = {s.atmosphere:.0f} Pa (highest "
                f"{hi:.0f} Pa): gauge pressures taken as absolute? {GAUGE_FIX}")
    gauge = gauge_suspicion(tt, pp, _pa_settings(s))
    if gauge is not None:
        return gauge
    sigma = _noise_std(pp)
    threshold = s.trigger_sigma * max(sigma, 1e-9 * abs(hi))
    if float(np.ptp(pp)) <= threshold:
        return (f"the pressure never drops: it stays at {np.median(pp):.0f} Pa (peak to peak "
                f"{float(np.ptp(pp)):.3g} Pa, within trigger_sigma={s.trigger_sigma:g} noise "
                f"std): no unload recorded, or the sensor is stuck")
    start = float(np.median(pp[:4]))
    below = np.flatnonzero(pp < start - threshold)
    if below.size == 0:
        return (f"no drop: the pressure never falls {threshold:.3g} Pa (trigger_sigma="
                f"{s.trigger_sigma:g} noise std) below its initial {start:.0f} Pa; no unload "
                f"recorded (or the record starts after it)")
    i_drop = int(below[0])
    if i_drop < s.min_plateau:
        fix = (f", or pass --min-plateau {i_drop} (min_plateau) if those {i_drop} samples "
               f"are a plateau" if i_drop >= 4 else "")
        return (f"no plateau before the drop: the pressure falls from sample {i_drop} "
                f"(t = {tt[i_drop]:.6g} s), but a pre-trigger plateau of at least min_plateau"
                f"={s.min_plateau} samples is needed (the record starts at the valve "
                f"opening?): record from before the valve opens{fix}; or, for {START_HINT}")
    p10 = float(np.median(pp[:i_drop]))
    p_atm = s.atmosphere if s.atmosphere is not None else _final_level(pp, s)
    ps = p_star(p10, p_atm)
    low = float(np.min(pp[i_drop:]))
    if low > ps:
        return (f"the pressure never fell to p* = {ps:.0f} Pa (p10 = {p10:.0f} Pa, p_atm = "
                f"{p_atm:.0f} Pa, lowest reading {low:.0f} Pa): the valve closed early or "
                f"the record ends too soon")
    if diagnostics is None or not any(d.level != "ok" for d in diagnostics):
        slow = too_slow_to_detect(pp, sigma, stride, p10=p10, low=low)
        if slow is not None:
            return slow
    return estimator_reason(t, p, s, diagnostics)


#: Samples between the centres of the detector's reference window and its newest block [-]
#: (a fall slower than a block threshold over this many samples is never seen).
DETECTOR_SPAN = LAG + PLATEAU // 2 + PERIOD // 2


def too_slow_to_detect(pp: np.ndarray, sigma: float, stride: int = 1, *, p10: float,
                       low: float) -> str | None:
    """Why a record whose pressure does fall to p* gave no unload, when its fall is too slow
    for the detector at its sample rate (None otherwise): the steepest fall over
    :data:`DETECTOR_SPAN` samples (from means over 1/200 of the record, so that the noise
    does not count) is below the block threshold (6 noise std / sqrt(PERIOD)).

    Parameters
    ----------
    pp : ndarray
        Finite pressures [Pa], every ``stride``-th sample of the record.
    sigma : float
        Noise standard deviation of a sample [Pa].
    stride : int
        Samples of the record per element of pp [-].
    p10, low : float
        Initial and lowest pressure [Pa] (for the message).
    """
    n = pp.size
    w = max(1, n // 200)
    if n < 4 * w or sigma <= 0.0:
        return None
    c = np.cumsum(np.concatenate(([0.0], pp)))
    means = (c[w:] - c[:-w]) / w
    rate = float(np.max(means[:-w] - means[w:])) / (w * stride)  # [Pa per sample]
    need = float(block_threshold(sigma))  # [Pa over DETECTOR_SPAN samples]
    fall = rate * DETECTOR_SPAN
    if not (0.0 < fall < need):
        return None
    # averaging k samples: noise / sqrt(k), fall per sample x k, so the ratio gains k^1.5
    k = max(2, math.ceil((need / fall) ** (2.0 / 3.0) * 1.5))
    return (f"the pressure falls from {p10:.0f} to {low:.0f} Pa, but too slowly for the "
            f"detector at this sample rate: {rate:.3g} Pa per sample at most, "
            f"{fall:.3g} Pa over the {DETECTOR_SPAN} samples it compares, where a step must "
            f"fall {need:.3g} Pa (6 noise std of {sigma:.3g} Pa / sqrt({PERIOD})): average "
            f"the record over about {k} samples (a {k} times lower rate) and analyse again")


def _pa_settings(s: EstimatorSettings) -> EstimatorSettings:
    """The settings for readings already converted to Pa (gain 1, offset 0)."""
    return dataclasses.replace(s, signal_gain=1.0, signal_offset=0.0)


def estimator_reason(t: ArrayLike, p: ArrayLike, s: EstimatorSettings,
                     diagnostics: Sequence[Diagnostic] | None = None) -> str:
    """The estimator's warnings and errors on the trace (t [s], p [Pa]; ``diagnostics``:
    those of a run with settings ``s`` already made), or a generic reason."""
    if diagnostics is None:
        est = stream_estimator(s)
        est.push_block(np.asarray(t, dtype=float), np.asarray(p, dtype=float))
        est.finish()
        diagnostics = est.diagnostics
    msgs = list(dict.fromkeys(d.message for d in diagnostics if d.level != "ok"))
    if msgs:
        more = f" (and {len(msgs) - 3} more)" if len(msgs) > 3 else ""
        return "no unload detected: " + "; ".join(msgs[:3]) + more
    return ("no unload detected: no step met the detector's criteria (plateau of min_plateau "
            "samples, a drop of trigger_sigma noise std, confirmation)")
