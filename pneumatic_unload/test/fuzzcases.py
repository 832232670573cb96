# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Property-based fuzzing of the package's input boundary (issue #13): hypothesis strategies
and the properties every input must satisfy, shared by ``test/test_fuzz.py`` (a short
profile in ``make test``) and ``bench/bench_fuzz.py`` (the long run). This module: the
analysis and the settings; :mod:`fuzzio`: the readers, the CLI and the discrepancy workflow.

A *failure* is any exception other than the package's typed errors (the ones the command
line turns into a one-line message), a hang (each example is bounded by :func:`time_limit`),
or a result with status "ok" whose C, tau_exp or a sigma is non-finite or not positive.

Inputs are realistic-but-wild: simulated discharges (:func:`pneumatic_unload.model.simulate`
of a random :class:`~pneumatic_unload.config.RigConfig`) with random corruption (NaN, inf,
spikes, reversed or duplicate stamps, clock steps, clipping, stuck sensor, huge or tiny
values, gauge-like offsets, ...), next to plain random arrays, which never get past the
detector. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import signal
from collections.abc import Iterator
from typing import Any

import numpy as np
from hypothesis import strategies as st

from pneumatic_unload.config import EFFECTS, RigConfig
from pneumatic_unload.config.fields import describe
from pneumatic_unload.estimation import (
    STATUSES,
    EstimationError,
    EstimatorSettings,
    UnloadResult,
    analyze,
    estimate_fields,
    explain_no_unload,
    gauge_suspicion,
    merge_final,
)
from pneumatic_unload.model import simulate

P_ATM = 101325.0  # [Pa]


class FuzzFailure(AssertionError):
    """A property of the input boundary does not hold (the fuzz run's failure)."""


class Hang(FuzzFailure):
    """One example ran longer than its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise :class:`Hang` in the main thread if the block runs longer than ``seconds`` [s]."""
    def on_alarm(_sig: int, _frame: object) -> None:
        raise Hang(f"example ran longer than {seconds:g} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


# ------------------------------------------------------------------------------- checks
def check_results(results: list[UnloadResult], where: str = "analyze") -> None:
    """Every result has a known status; an 'ok' one has finite, positive C, tau_exp and
    sigmas; every result is JSON-ready (the CLI's ``--json``)."""
    for r in results:
        if r.status not in STATUSES:
            raise FuzzFailure(f"{where}: unknown status {r.status!r}")
        d = r.to_dict()
        d.pop("extra", None)
        json.dumps(d, allow_nan=False)
        estimate_fields(r)  # what the estimator node publishes
        if r.status != "ok":
            continue
        must = {"conductance": r.conductance, "tau_exp": r.tau_exp, "p10": r.p10,
                "p_atm": r.p_atm}
        maybe = {"conductance_model": r.conductance_model, "tau_exp_model": r.tau_exp_model,
                 "critical_ratio": r.critical_ratio}
        sigmas = {"tau_exp_std": r.tau_exp_std, "conductance_model_std":
                  r.conductance_model_std, "critical_ratio_std": r.critical_ratio_std,
                  "noise_std": r.noise_std}
        bad = [f"{k}={v!r}" for k, v in must.items() if not (math.isfinite(v) and v > 0)]
        bad += [f"{k}={v!r}" for k, v in maybe.items() if not (math.isnan(v) or
                                                             (math.isfinite(v) and v > 0))]
        bad += [f"{k}={v!r}" for k, v in sigmas.items() if not (math.isnan(v) or
                                                              (math.isfinite(v) and v >= 0))]
        if not r.tau_exp_std > 0:
            bad.append(f"tau_exp_std={r.tau_exp_std!r}")
        if bad:
            raise FuzzFailure(f"{where}: status ok (final={r.final}) with " + ", ".join(bad))


def run_analyze(t: np.ndarray, p: np.ndarray, s: EstimatorSettings) -> list[UnloadResult]:
    """The library path of ``pneumatic-unload analyze``: analyze, merge, explain, gauge
    check; only :class:`EstimationError` may be raised."""
    try:
        published = analyze(t, p, s)
    except EstimationError:
        return []
    check_results(published)
    unloads = merge_final(published)
    why = None if unloads else explain_no_unload(t, p, s)
    if not unloads and not (isinstance(why, str) and why):
        raise FuzzFailure(f"no unload and no reason: {why!r}")
    gauge_suspicion(t, p, s)
    return published


# --------------------------------------------------------------------------- strategies
def _field_value(f: dict[str, Any]) -> st.SearchStrategy[Any]:
    """A valid value of one settings field from its metadata (bounds included)."""
    kind = f["kind"]
    if kind == "flag":
        return st.booleans()
    if kind == "choice":
        return st.sampled_from(f["choices"])
    if kind == "integer":
        return st.one_of(st.integers(f["min"], min(f["max"], 4096)),
                         st.sampled_from([f["min"], f["max"]]))
    lo, hi = f["min"], f["max"]
    vals = st.floats(lo, hi, allow_nan=False)
    if lo > 0:
        vals = st.one_of(vals, st.floats(math.log10(lo), math.log10(hi)).map(
            lambda e: min(hi, max(lo, 10 ** e))))
    if kind == "optional":
        return st.one_of(st.none(), vals)
    return vals


@st.composite
def estimator_settings(draw: st.DrawFn, near: EstimatorSettings | None = None
                       ) -> EstimatorSettings:
    """Estimator settings: some fields drawn anywhere in their range, the others those of
    ``near`` (the rig's own) or the defaults."""
    base = dataclasses.asdict(near or EstimatorSettings())
    for f in describe(EstimatorSettings):
        if draw(st.integers(0, 4)) == 0:
            base[f["name"]] = draw(_field_value(f))
    if base["signal_gain"] == 0:
        base["signal_gain"] = 1.0
    if base["direction"] == "discharge":  # a supply is a charge's
        base.update(supply_pressure=None, supply_temperature=None)
    return EstimatorSettings(**base)


@st.composite
def rig_configs(draw: st.DrawFn, *, max_samples: int = 6000) -> RigConfig:
    """A simulated rig: tank, component, sensor and effects drawn over wide ranges, with a
    record of at most ``max_samples`` samples."""
    kw: dict[str, Any] = {
        "volume": 10 ** draw(st.floats(-4.5, -1.5)),
        "conductance": 10 ** draw(st.floats(-10.0, -7.5)),
        "initial_pressure": draw(st.sampled_from([1.5e5, 3e5, 7e5, 1.2e6, 5e6])),
        "critical_ratio": draw(st.floats(0.1, 0.6)),
        "noise_std": draw(st.sampled_from([0.0, 10.0, 300.0, 1000.0, 3e4])),
        "seed": draw(st.integers(0, 2**31 - 1)),
        "pre_time": draw(st.sampled_from([0.0, 0.01, 0.1, 0.3, 1.0])),
        "initial_temperature": draw(st.floats(250.0, 350.0)),
        "length_diameter_ratio": draw(st.floats(0.5, 10.0)),
    }
    if draw(st.booleans()):
        kw["effects"] = tuple(draw(st.sets(st.sampled_from(EFFECTS), max_size=3)))
    if draw(st.integers(0, 5)) == 0:
        kw["valve_close_time"] = draw(st.floats(0.01, 2.0))
    if draw(st.integers(0, 5)) == 0:
        kw["quantization"] = draw(st.sampled_from([100.0, 1000.0, 2e4]))
    if draw(st.integers(0, 5)) == 0:
        kw["noise_ar_rho"], kw["noise_ar_std"] = draw(st.floats(0.0, 0.99)), 500.0
    cfg = RigConfig(**kw)
    tau = cfg.volume / (cfg.conductance * 287.0 * 293.15) * 2.0  # rough discharge time [s]
    duration = draw(st.floats(0.5, 8.0)) * tau
    rate = draw(st.sampled_from([50.0, 200.0, 1000.0, 5000.0]))
    duration = min(duration, 30_000.0)
    rate = min(rate, max_samples / (cfg.pre_time + duration + 1e-3))
    if rate < 1.0:
        duration, rate = max_samples - 1.0, 1.0
    return cfg.replace(duration=duration, rate=rate)


CORRUPTIONS = ("nan", "inf", "nan_t", "spikes", "reverse", "reverse_block", "duplicate",
               "clock_back", "clip", "stuck", "huge", "tiny", "gauge", "negative", "drop",
               "quantize", "time_scale", "time_offset", "truncate", "repeat", "constant",
               "zero", "denormal", "ramp")


def corrupt(draw: st.DrawFn, t: np.ndarray, p: np.ndarray, what: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """Apply one corruption ``what`` (of :data:`CORRUPTIONS`) at drawn places."""
    n = t.size
    t, p = t.copy(), p.copy()
    i = draw(st.integers(0, max(n - 1, 0)))
    j = min(n, i + draw(st.integers(1, max(1, n // 4))))
    idx = draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=20)) if n else []
    if what == "nan":
        p[idx] = np.nan
    elif what == "inf":
        p[idx] = draw(st.sampled_from([np.inf, -np.inf]))
    elif what == "nan_t":
        t[idx] = draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    elif what == "spikes":
        p[idx] += draw(st.sampled_from([-1e6, -1e5, 1e5, 1e7, 1e12]))
    elif what == "reverse":
        t = t[::-1].copy()
    elif what == "reverse_block":
        t[i:j] = t[i:j][::-1]
    elif what == "duplicate":
        t[i:j] = t[i]
    elif what == "clock_back":
        t[i:] -= draw(st.sampled_from([1e-3, 0.1, 10.0, 1e6]))
    elif what == "clip":
        lo, hi = float(np.nanmin(p)), float(np.nanmax(p))
        p = np.minimum(p, lo + draw(st.floats(0.0, 1.0)) * (hi - lo))
    elif what == "stuck":
        p[i:j] = p[i]
    elif what == "huge":
        p *= draw(st.sampled_from([1e30, 1e100, 1e300, -1e300]))
    elif what == "tiny":
        p *= draw(st.sampled_from([1e-30, 1e-300, 1e-320]))
    elif what == "gauge":
        p -= draw(st.sampled_from([P_ATM, 1e5, 2 * P_ATM]))
    elif what == "negative":
        p = -p
    elif what == "drop":
        keep = np.ones(n, bool)
        keep[i:j] = False
        t, p = t[keep], p[keep]
    elif what == "quantize":
        q = draw(st.sampled_from([1e3, 1e5, 1e6]))
        p = np.round(p / q) * q
    elif what == "time_scale":
        t *= draw(st.sampled_from([1e-9, 1e-3, 1e3, 1e9]))
    elif what == "time_offset":
        t += draw(st.sampled_from([-1e9, 1.7e9, 1e15, 1e300]))
    elif what == "truncate":
        t, p = t[i:j], p[i:j]
    elif what == "repeat":
        t = np.concatenate([t, t[-1] + (t - t[0]) + (t[1] - t[0] if n > 1 else 1.0)])
        p = np.concatenate([p, p])
    elif what == "constant":
        p[:] = draw(st.sampled_from([0.0, 1.0, P_ATM, 7e5]))
    elif what == "zero":
        p[i:j] = 0.0
    elif what == "denormal":
        p[idx] = 5e-324
    elif what == "ramp":
        p += np.linspace(0.0, draw(st.sampled_from([-1e6, -1e4, 1e4, 1e6])), n)
    return t, p


@st.composite
def wild_discharges(draw: st.DrawFn, *, max_samples: int = 6000
                    ) -> tuple[np.ndarray, np.ndarray, RigConfig]:
    """A simulated discharge (t [s], measured p [Pa]) with 0-3 random corruptions."""
    cfg = draw(rig_configs(max_samples=max_samples))
    sim = simulate(cfg)
    t, p = sim.t, sim.measured
    for what in draw(st.lists(st.sampled_from(CORRUPTIONS), max_size=3)):
        t, p = corrupt(draw, t, p, what)
    return t, p, cfg


@st.composite
def random_traces(draw: st.DrawFn, *, max_samples: int = 400
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Plain random arrays: stamps (regular, jittered, random, constant) and values (any
    float, steps, levels)."""
    n = draw(st.integers(0, max_samples))
    kind = draw(st.sampled_from(["regular", "jitter", "random", "constant"]))
    if kind == "regular":
        dt = 10 ** draw(st.floats(-12.0, 300.0))
        t = draw(st.floats(-1e12, 1e12)) + dt * np.arange(n, dtype=float)
    elif kind == "jitter":
        t = np.cumsum(np.abs(np.asarray(draw(st.lists(st.floats(-1.0, 10.0), min_size=n,
                                                            max_size=n)), float)))
    elif kind == "random":
        t = np.asarray(draw(st.lists(st.floats(), min_size=n, max_size=n)), float)
    else:
        t = np.full(n, draw(st.floats(allow_nan=False)))
    vals = st.one_of(st.floats(), st.floats(-1e7, 1e7), st.sampled_from([0.0, P_ATM, 7e5]))
    if draw(st.booleans()):
        p = np.asarray(draw(st.lists(vals, min_size=n, max_size=n)), float)
    else:  # piecewise levels: a plateau, a drop, a plateau
        a, b = draw(vals), draw(vals)
        k = draw(st.integers(0, n))
        p = np.where(np.arange(n) < k, a, b).astype(float)
        p += np.asarray(draw(st.lists(st.floats(-1e3, 1e3), min_size=n, max_size=n)), float)
    return t, p


# ------------------------------------------------------------------------- settings
JUNK = st.one_of(st.none(), st.booleans(), st.integers(-10, 10**20), st.floats(),
                 st.text(max_size=8), st.lists(st.integers(), max_size=3),
                 st.dictionaries(st.text(max_size=4), st.integers(), max_size=2))


def prop_settings(kw: dict[str, Any]) -> None:
    """Settings from any keyword values: valid, or refused with the settings class's
    typed error."""
    from pneumatic_unload.discrepancy import DiscrepancyError, DiscrepancySettings

    for cls, err in ((EstimatorSettings, EstimationError),
                     (DiscrepancySettings, DiscrepancyError)):
        known = {f.name for f in dataclasses.fields(cls)}
        with contextlib.suppress(err):
            cls(**{k: v for k, v in kw.items() if k in known})


def settings_keywords() -> st.SearchStrategy[dict[str, Any]]:
    """Keyword arguments for the settings classes: any field, any junk value."""
    from pneumatic_unload.discrepancy import DiscrepancySettings

    names = sorted({f.name for c in (EstimatorSettings, DiscrepancySettings)
                    for f in dataclasses.fields(c)})
    return st.dictionaries(st.sampled_from(names), JUNK, max_size=4)


# --------------------------------------------------------------- clean examples (@example)
def clean_discharge(rate: float = 500.0) -> tuple[np.ndarray, np.ndarray, RigConfig]:
    """One plain simulated discharge (1 L tank, 2 mm orifice, 4 s at ``rate`` [Hz]): the
    example that reaches every stage of the analysis."""
    from pneumatic_unload.physics import orifice_conductance

    cfg = RigConfig(volume=1e-3, conductance=orifice_conductance(2e-3), noise_std=300.0,
                    seed=3, duration=4.0, pre_time=0.3, rate=rate)
    sim = simulate(cfg)
    return sim.t, sim.measured, cfg
