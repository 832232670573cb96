"""The unloading-time method as a streaming estimator (live node and offline analysis).

:class:`StreamingEstimator` is fed pressure samples one at a time (:meth:`push`) or in
blocks (:meth:`push_block`); both paths give bit-identical results, because every
decision is taken at a sample index from the samples up to that index only, with O(1)
statistics from running prefix sums (of p and of squared first differences), and the block
path evaluates the periodic checks that decide nothing for many indices at once with the
same formulas, calling the per-sample decision code only where something happens.
:func:`analyze` is the batch function over arrays (the block path on the whole trace).

Per unload it: detects the start of the step (trigger, confirmation, then a sub-sample
hinge fit of the valve-opening instant); takes p10 from the pre-step plateau and p_atm from
a parameter or the final plateau; computes p* (eq 40); finds the p* crossing by a local
quadratic regression (noise-robust, sub-sample); returns tau_exp and C by eq 39, plus the
model-based C that removes eq 39's known bias (exact inversion of the discharge model at
the crossing, then a full-curve fit once the unload has ended); reports an aborted unload
(valve closed before p*) and, when the re-heating after the closing is recorded (fitted
and, if unfinished, extrapolated with its uncertainty), the SSE value (eq 23); ends the
unload's tail when the tank is charged again and re-arms for the next unload.

Only relative values matter for tau_exp: the input may be any linear signal (volts) when
``signal_gain``/``signal_offset`` convert it, or when only tau_exp is wanted; p10, p_atm and
T10 must be absolute for C. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pneumatic_unload import physics
from pneumatic_unload.physics import AIR, P_STAR_FRACTION, T_N

FloatArray = NDArray[np.float64]

#: Statuses of an :class:`UnloadResult` (same order as the message's STATUS_* constants).
STATUSES = ("ok", "aborted_sse", "aborted", "not_choked", "bad_data")


#: Relative 1-sigma of eq 23 itself [-]: it assumes an isentropic unload (wall heat flow
#: during the unload shifts it by up to ~0.5 %) and writes p_N for rho_N R T_N (0.28 %).
SSE_MODEL_REL_STD = 0.01


class EstimationError(ValueError):
    """Input that cannot be analysed at all (too few samples, wrong shapes...)."""


@dataclass(frozen=True)
class EstimatorSettings:
    """Settings of the unloading-time estimator.

    Attributes
    ----------
    volume : float
        Tank volume V [m^3].
    initial_temperature : float
        Initial gas temperature T10 [K].
    atmosphere : float or None
        Atmospheric pressure [Pa absolute]; None: from the final plateau (auto).
    length_diameter_ratio : float
        Tank L/D [-] (natural-convection model of the model-based C).
    wall_temperature : float or None
        Wall temperature [K]; None: equal to T10.
    heat_model : str
        'natural' (natural-convection wall heat transfer) or 'adiabatic' for the model-based C.
    critical_ratio : float
        b [-] assumed by the model-based inversion at the crossing (the curve fit refines it).
    signal_gain : float
        Pressure per unit of input signal [Pa per unit] (1 for an input in Pa).
    signal_offset : float
        Pressure at zero input [Pa] (0 for an input in Pa absolute).
    trigger_sigma : float
        Drop below the plateau that triggers detection, in noise standard deviations [-].
    min_plateau : int
        Samples of pre-step plateau needed before a trigger is accepted [-].
    max_gap_factor : float
        A stamp step larger than this many nominal periods is a gap [-].
    curve_fit : bool
        Run the full-curve least-squares fit (C, b) when the unload ends.
    gas_constant, gamma : float
        Gas properties [J/(kg K)], [-].
    """

    volume: float = 5e-3
    initial_temperature: float = T_N
    atmosphere: float | None = 101325.0
    length_diameter_ratio: float = 2.0
    wall_temperature: float | None = None
    heat_model: str = "natural"
    critical_ratio: float = 0.5
    signal_gain: float = 1.0
    signal_offset: float = 0.0
    trigger_sigma: float = 8.0
    min_plateau: int = 32
    max_gap_factor: float = 5.0
    curve_fit: bool = True
    gas_constant: float = AIR.gas_constant
    gamma: float = AIR.gamma

    def __post_init__(self) -> None:
        """Validate (raises :class:`EstimationError`)."""
        checks = [
            (self.volume > 0, "volume must be > 0 m^3"),
            (self.initial_temperature > 0, "initial_temperature must be > 0 K"),
            (self.atmosphere is None or self.atmosphere > 0, "atmosphere must be > 0 Pa"),
            (self.heat_model in ("natural", "adiabatic"),
             "heat_model must be 'natural' or 'adiabatic'"),
            (0.0 <= self.critical_ratio < 1.0, "critical_ratio must be in [0, 1)"),
            (self.signal_gain != 0 and math.isfinite(self.signal_gain),
             "signal_gain must be finite and non-zero"),
            (self.trigger_sigma > 0, "trigger_sigma must be > 0"),
            (self.min_plateau >= 4, "min_plateau must be >= 4 samples"),
        ]
        for ok, msg in checks:
            if not ok:
                raise EstimationError(msg)

    @property
    def gas(self) -> physics.Gas:
        """Gas properties."""
        return physics.Gas(gas_constant=self.gas_constant, gamma=self.gamma)


@dataclass
class UnloadResult:
    """One unload analysed by the unloading-time method (all SI; NaN when unknown).

    ``conductance`` is the paper's eq 39 value, always reported as it is;
    ``conductance_model`` removes its known bias by inverting the discharge model at the
    measured crossing (``final=False``), or comes from the full-curve fit once the unload has
    ended (``final=True``).
    """

    index: int
    status: str
    status_text: str
    t_start: float
    t_cross: float
    tau_exp: float
    tau_exp_std: float
    p10: float
    p_atm: float
    p_star: float
    initial_temperature: float
    volume: float
    conductance: float
    conductance_model: float
    conductance_model_std: float
    critical_ratio: float = math.nan
    critical_ratio_std: float = math.nan
    conductance_isentropic: float = math.nan
    quality: float = 0.0
    method: str = ""
    final: bool = False
    noise_std: float = math.nan
    i_start: int = -1
    i_cross: int = -1
    i_complete: int = -1
    t_complete: float = math.nan
    t_end: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)
    #: Start instant of the fitted discharge model [s] (final results; NaN otherwise).
    t_start_model: float = math.nan
    #: tau_exp of the fitted model, its p* crossing from its start [s]: uses the whole curve,
    #: so it is less noisy than ``tau_exp`` (the paper's measurement, which it never replaces).
    tau_exp_model: float = math.nan

    @property
    def bias(self) -> float:
        """Relative difference conductance/conductance_model - 1 [-]."""
        return self.conductance / self.conductance_model - 1.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN mapped to None) with the CLI's key names."""
        d = asdict(self)
        out: dict[str, Any] = {}
        for k, v in d.items():
            if isinstance(v, float) and not math.isfinite(v):
                v = None
            out[k] = v
        return out


@dataclass(frozen=True)
class Diagnostic:
    """A state change or an input problem, for /diagnostics and logs.

    Attributes
    ----------
    level : str
        'ok', 'warn' or 'error'.
    state : str
        Estimator state after the event.
    message : str
        What happened, specifically.
    t : float
        Sample time [s] (NaN when the sample had no valid time).
    """

    level: str
    state: str
    message: str
    t: float


# --------------------------------------------------------------------------- helpers
def _robust_sigma(x: FloatArray) -> float:
    """Noise standard deviation from first differences (MAD, drift-insensitive) [unit of x]."""
    if x.size < 3:
        return 0.0
    d = np.diff(x)
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / math.sqrt(2.0)


def _rms_sigma(x: FloatArray) -> float:
    """Noise standard deviation from first differences (RMS) [unit of x]."""
    if x.size < 3:
        return 0.0
    return float(np.std(np.diff(x))) / math.sqrt(2.0)


def _solve3(m: tuple[tuple[float, float, float], ...], r: tuple[float, float, float]
            ) -> tuple[float, float, float] | None:
    """Solve a 3x3 linear system by Cramer's rule (None when singular) [-]."""
    (a, b, c), (d, e, f), (g, h, k) = m
    c1, c2, c3 = e * k - f * h, f * g - d * k, d * h - e * g
    det = a * c1 + b * c2 + c * c3
    if det == 0.0 or not math.isfinite(det):
        return None
    x = (r[0] * c1 + b * (f * r[2] - r[1] * k) + c * (r[1] * h - e * r[2])) / det
    y = (a * (r[1] * k - f * r[2]) + r[0] * c2 + c * (d * r[2] - r[1] * g)) / det
    z = (a * (e * r[2] - r[1] * h) + b * (r[1] * g - d * r[2]) + r[0] * c3) / det
    return x, y, z


def _grid_then_golden(f: Any, t: FloatArray, t_lo: float, t_hi: float, *, n_grid: int,
                      rel_tol: float) -> float:
    """Minimise f(x) over [t_lo, t_hi] [s]: at most ``n_grid`` sample instants of ``t`` in
    the interval, then a golden-section search around the best one, down to ``rel_tol``
    times the grid step."""
    cand = t[(t >= t_lo) & (t <= t_hi)]
    if cand.size == 0:
        cand = np.array([0.5 * (t_lo + t_hi)])
    if cand.size > n_grid:
        cand = cand[np.linspace(0, cand.size - 1, n_grid).astype(int)]
    vals = [f(float(c)) for c in cand]
    k = int(np.argmin(vals))
    step = float(cand[1] - cand[0]) if cand.size > 1 else t_hi - t_lo
    a_, b_ = max(t_lo, float(cand[k]) - step), min(t_hi, float(cand[k]) + step)
    gr = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = b_ - gr * (b_ - a_), a_ + gr * (b_ - a_)
    f1, f2 = f(x1), f(x2)
    for _ in range(48):
        if b_ - a_ < rel_tol * max(step, 1e-12):
            break
        if f1 <= f2:
            b_, x2, f2 = x2, x1, f1
            x1 = b_ - gr * (b_ - a_)
            f1 = f(x1)
        else:
            a_, x1, f1 = x1, x2, f2
            x2 = a_ + gr * (b_ - a_)
            f2 = f(x2)
    return 0.5 * (a_ + b_)


def hinge_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float
              ) -> tuple[float, float, float, float, float]:
    """Fit p = p10 (t < t0), p10 - s u + c u^2 (u = t - t0 >= 0) with t0 in [t_lo, t_hi].

    Sub-sample t0 by minimising the profiled sum of squares (linear in p10, s, c for each
    t0) with a bracketed golden-section search after a grid search on the sample instants.

    Parameters
    ----------
    t, p : ndarray
        Window of samples [s], [Pa].
    t_lo, t_hi : float
        Search interval for t0 [s].

    Returns
    -------
    tuple
        (t0 [s], p10 [Pa], s [Pa/s], c [Pa/s^2], residual rms [Pa]).
    """
    tc = t - t[0]
    scale_t = max(tc[-1], 1e-12)
    p_ref = float(np.mean(p))
    q = p - p_ref
    n_all = float(q.size)
    sq_all, s_all = float(q @ q), float(np.sum(q))

    def solve(t0: float) -> tuple[float, FloatArray]:
        # normal equations of [1, -u, u^2] from sums over the post-t0 samples (u > 0)
        k = int(np.searchsorted(tc, t0 - t[0], side="right"))
        u = (tc[k:] - (t0 - t[0])) / scale_t
        qk = q[k:]
        u2 = u * u
        su, su2, su3, su4 = float(u.sum()), float(u2.sum()), float(u2.dot(u)), \
            float(u2.dot(u2))
        squ, squ2 = float(qk.dot(u)), float(qk.dot(u2))
        m = ((n_all, -su, su2), (-su, su2, -su3), (su2, -su3, su4))
        rhs = (s_all, -squ, squ2)
        coef = _solve3(m, rhs)
        if coef is None:
            sol = np.linalg.lstsq(np.array(m), np.array(rhs), rcond=None)[0]
            coef = (float(sol[0]), float(sol[1]), float(sol[2]))
        sse = max(sq_all - (coef[0] * rhs[0] + coef[1] * rhs[1] + coef[2] * rhs[2]), 0.0)
        return sse, np.array((coef[0] + p_ref, coef[1], coef[2]))

    t0 = _grid_then_golden(lambda x: solve(x)[0], t, t_lo, t_hi, n_grid=64, rel_tol=1e-3)
    sse0, coef = solve(t0)
    rms = math.sqrt(sse0 / max(p.size - 4, 1))
    return t0, float(coef[0]), float(coef[1]) / scale_t, float(coef[2]) / scale_t**2, rms


def crossing_fit(t: FloatArray, p: FloatArray, level: float
                 ) -> tuple[float, float, float]:
    """Sub-sample time at which a local quadratic regression of p(t) crosses ``level``.

    Parameters
    ----------
    t, p : ndarray
        Samples around the crossing [s], [Pa]; p decreasing overall.
    level : float
        Threshold [Pa].

    Returns
    -------
    tuple
        (crossing time [s], its standard deviation [s], slope at the crossing [Pa/s]).
    """
    tm = float(np.mean(t))
    x = t - tm
    a = np.column_stack((np.ones_like(x), x, x * x))
    coef, *_ = np.linalg.lstsq(a, p, rcond=None)
    r = p - a @ coef
    dof = max(p.size - 3, 1)
    s2 = float(r @ r) / dof
    c0, c1, c2 = (float(v) for v in coef)
    # root of c2 x^2 + c1 x + (c0 - level) nearest the window centre
    if abs(c2) < 1e-30 or abs(c2 * (x[-1] - x[0]) ** 2) < 1e-12 * abs(c1 * (x[-1] - x[0])):
        xr = (level - c0) / c1
    else:
        disc = c1 * c1 - 4.0 * c2 * (c0 - level)
        if disc < 0:
            xr = (level - c0) / c1
        else:
            sq = math.sqrt(disc)
            r1, r2 = (-c1 + sq) / (2 * c2), (-c1 - sq) / (2 * c2)
            xr = r1 if abs(r1) < abs(r2) else r2
    slope = c1 + 2.0 * c2 * xr
    # delta method: var(f(xr)) / slope^2 with f = c0 + c1 x + c2 x^2
    try:
        cov = s2 * np.linalg.inv(a.T @ a)
        g = np.array([1.0, xr, xr * xr])
        var_f = float(g @ cov @ g)
    except np.linalg.LinAlgError:
        var_f = math.inf
    std = math.sqrt(max(var_f, 0.0)) / abs(slope) if slope != 0 else math.inf
    return tm + xr, std, slope


def corner_fit(t: FloatArray, p: FloatArray, t_lo: float, t_hi: float
               ) -> tuple[float, float, float]:
    """Sub-sample instant of a slope change: p = c0 + quadratic in u- and in u+.

    u- = min(t - tc, 0) and u+ = max(t - tc, 0); tc in [t_lo, t_hi] minimises the profiled
    sum of squares (grid on the sample instants, then golden section). Used for the
    closing instant of an aborted unload.

    Parameters
    ----------
    t, p : ndarray
        Window of samples [s], [Pa].
    t_lo, t_hi : float
        Search interval [s].

    Returns
    -------
    tuple
        (tc [s], p(tc) [Pa], residual rms [Pa]).
    """
    tm = t - t[0]
    sc = max(float(tm[-1]), 1e-12)

    def solve(tc: float) -> tuple[float, FloatArray]:
        u = (tm - (tc - t[0])) / sc
        um, up = np.minimum(u, 0.0), np.maximum(u, 0.0)
        a = np.column_stack((np.ones_like(u), um, um * um, up, up * up))
        coef, *_ = np.linalg.lstsq(a, p, rcond=None)
        r = p - a @ coef
        return float(r @ r), coef

    tc = _grid_then_golden(lambda x: solve(x)[0], t, t_lo, t_hi, n_grid=96, rel_tol=1e-6)
    sse0, coef = solve(tc)
    return tc, float(coef[0]), math.sqrt(sse0 / max(p.size - 6, 1))


# --------------------------------------------------------------------------- estimator
_WAITING, _CONFIRM, _UNLOADING, _TAIL, _RECOVERY = (
    "waiting", "confirming", "unloading", "tail", "recovery")


class StreamingEstimator:
    """Sample-by-sample unloading-time estimator; see the module docstring.

    Parameters
    ----------
    settings : EstimatorSettings
        Tank, gas and detection settings.

    Examples
    --------
    >>> est = StreamingEstimator(EstimatorSettings(volume=5e-3))
    >>> results = []
    >>> for ti, pi in zip(t, p):  # doctest: +SKIP
    ...     results += est.push(ti, pi)
    >>> results += est.finish()  # doctest: +SKIP
    """

    #: Samples between periodic checks [-].
    PERIOD = 64
    #: Samples used for the plateau level and noise [-].
    PLATEAU = 1024
    #: Samples that must confirm a trigger [-].
    CONFIRM = 64
    #: Samples between the end of the reference plateau window and now [-].
    LAG = 256
    #: Most pre-step plateau samples used by the start (hinge) fit [-]: the start's
    #: precision on slow discharges is limited by how well p10 is known (see
    #: bench/bench_accuracy.py start), and the plateau costs the fit O(1) per candidate.
    HINGE_PLATEAU = 16384

    def __init__(self, settings: EstimatorSettings | None = None) -> None:
        self.settings = settings or EstimatorSettings()
        self._t = array("d")
        self._p = array("d")
        # prefix sums (index k holds the sum over samples 0..k-1): of p, and of the squared
        # first differences (cq[k+1] - cq[k] = (p[k] - p[k-1])^2, 0 for k = 0), so that
        # every periodic decision is O(1) and the block path can evaluate many at once
        self._cs = array("d", [0.0])
        self._cq = array("d", [0.0])
        self.diagnostics: list[Diagnostic] = []
        self.results: list[UnloadResult] = []
        self._n_unloads = 0
        self._last_t = -math.inf
        self._dt_nominal = math.nan
        self._shift = 0  # samples trimmed from the buffer's start
        self._stuck_reported = False
        self._to_waiting(0)

    # ------------------------------------------------------------------ public API
    @property
    def state(self) -> str:
        """'waiting', 'confirming', 'unloading', 'tail' or 'recovery'."""
        return self._state

    @property
    def n_samples(self) -> int:
        """Valid samples received so far [-]."""
        return len(self._p) + self._shift

    def push(self, t: float, p: float) -> list[UnloadResult]:
        """Feed one sample.

        Parameters
        ----------
        t : float
            Sample instant [s] (strictly increasing).
        p : float
            Pressure [Pa absolute], or the raw signal when ``signal_gain`` converts it.

        Returns
        -------
        list of UnloadResult
            Results completed by this sample (usually empty).
        """
        if not t > self._last_t:  # also catches NaN stamps
            self._reject(t, p)
            return []
        if p != p or p in (math.inf, -math.inf):
            self._diag("warn", f"non-finite pressure sample {p!r} at t={t:.6f} s ignored", t)
            return []
        if t - self._last_t > self._gap_limit:
            self._on_gap(t)
        self._last_t = t
        if self._p:
            d = p - self._p[-1]
            self._cq.append(self._cq[-1] + d * d)
        else:
            self._cq.append(self._cq[-1])
        self._cs.append(self._cs[-1] + p)
        self._t.append(t)
        self._p.append(p)
        i = len(self._p) - 1
        if i == self._next_check or (p < self._level if self._below else p > self._level):
            out = self._step(i)
            if out:
                self.results += out
            return out
        return []

    def push_block(self, t: ArrayLike, p: ArrayLike) -> list[UnloadResult]:
        """Feed a block of samples; same results as calling :meth:`push` on each.

        Parameters
        ----------
        t : array_like
            Sample instants [s].
        p : array_like
            Pressures [Pa absolute] (or raw signal, see :meth:`push`).

        Returns
        -------
        list of UnloadResult
            Results completed inside the block.
        """
        t = np.asarray(t, dtype=float).ravel()
        p = np.asarray(p, dtype=float).ravel()
        if t.shape != p.shape:
            raise EstimationError(f"t and p differ in length: {t.size} vs {p.size}")
        if t.size == 0:
            return []
        # vectorised validity: finite, strictly increasing against the last accepted stamp
        fin_p = np.isfinite(p)
        prev_max = np.maximum.accumulate(np.concatenate(([self._last_t], t[:-1])))
        ok_t = (t > prev_max) & np.isfinite(t)
        if not (ok_t.all() and fin_p.all()):
            return self._push_slow(t, p)
        out: list[UnloadResult] = []
        k, size = 0, t.size
        while k < size:
            if math.isnan(self._dt_nominal):
                # sample by sample until the nominal period (and so the gap limit) is known
                out += self.push(float(t[k]), float(p[k]))
                k += 1
                continue
            prev = np.concatenate(([self._last_t], t[k:size - 1]))
            gaps = np.flatnonzero(t[k:] - prev > self._gap_limit)
            if gaps.size and gaps[0] == 0:
                out += self.push(float(t[k]), float(p[k]))  # diagnoses the gap
                k += 1
                continue
            g = k + int(gaps[0]) if gaps.size else size
            out += self._push_fast(t[k:g], p[k:g])
            k = g
        return out

    def _push_fast(self, t: FloatArray, p: FloatArray) -> list[UnloadResult]:
        """Block of finite, increasing samples without gaps: jump between decisions.

        The periodic checks that change nothing but the running statistics are evaluated
        for many check indices at once (:meth:`_scan`), with the same prefix-sum formulas
        and in the same floating-point order as :meth:`_step` evaluates them one by one;
        :meth:`_step` runs only where something may happen.
        """
        out: list[UnloadResult] = []
        start = len(self._p)
        prev = self._p[-1] if start else float(p[0])
        d = np.diff(np.concatenate(([prev], p)))
        # frombytes: a memcpy (array.extend would iterate element by element)
        self._cq.frombytes(np.cumsum(np.concatenate(([self._cq[-1]], d * d)))[1:].tobytes())
        self._cs.frombytes(np.cumsum(np.concatenate(([self._cs[-1]], p)))[1:].tobytes())
        self._t.frombytes(np.ascontiguousarray(t, dtype=np.float64).tobytes())
        self._p.frombytes(np.ascontiguousarray(p, dtype=np.float64).tobytes())
        self._last_t = float(t[-1])
        end = len(self._p)
        i = start
        while i < end:
            j = self._scan(i, min(end, i + self.SCAN_HORIZON))
            if j >= end:
                break
            if j >= i + self.SCAN_HORIZON:  # horizon reached without a decision
                i = j
                continue
            shift = self._shift
            out += self._step(j)
            trimmed = self._shift - shift
            i, end = j + 1 - trimmed, end - trimmed
        self.results += out
        return out

    #: Samples looked ahead per vectorised scan [-].
    SCAN_HORIZON = 16384

    def _scan(self, i: int, end: int) -> int:
        """Next index in [i, end) where :meth:`_step` must run (end: none).

        Checks before that index that decide nothing have their effect (running
        statistics, next check index) applied here, exactly as :meth:`_step` would.
        """
        state = self._state
        if self._next_check < i:
            self._next_check = i  # cannot happen; keeps the scan safe
        if state == _WAITING and not math.isnan(self._dt_nominal):
            return self._scan_waiting(i, end)
        if state == _UNLOADING and (not self._refined
                                    or math.isfinite(self._pstar_signal)):
            return self._scan_unloading(i, end)
        if state == _TAIL:
            return self._scan_tail(i, end)
        if state == _RECOVERY:
            return self._scan_recovery(i, end)
        return self._scan_generic(i, end)

    def _level_hit(self, i: int, hi: int) -> int:
        """First index in [i, hi) meeting the level condition, or hi."""
        if hi <= i or self._level == -math.inf:
            return hi
        pv = np.frombuffer(self._p, dtype=float)[i:hi]
        hit = np.flatnonzero(pv < self._level if self._below else pv > self._level)
        return i + int(hit[0]) if hit.size else hi

    def _scan_generic(self, i: int, end: int) -> int:
        nc = self._next_check
        j = self._level_hit(i, min(end, nc))
        if j < min(end, nc):
            return j
        return nc if nc < end else end

    def _checks(self, i: int, end: int) -> NDArray[np.int64]:
        """Periodic check indices in [i, end)."""
        return np.arange(self._next_check, end, self.PERIOD, dtype=np.int64)

    def _scan_waiting(self, i: int, end: int) -> int:
        nc = self._next_check
        j = self._level_hit(i, min(end, nc))
        if j < min(end, nc):
            return j
        ks = self._checks(i, end)
        if ks.size == 0:
            return end
        s = self.settings
        per, arm = self.PERIOD, self._arm_index
        cs = np.frombuffer(self._cs, dtype=float)
        cq = np.frombuffer(self._cq, dtype=float)
        pv = np.frombuffer(self._p, dtype=float)
        n = ks + 1
        lag = np.minimum(self.LAG, np.maximum(n - arm - s.min_plateau, 0))
        hi = n - lag
        lo = np.maximum(arm, hi - self.PLATEAU)
        plat = (cs[hi] - cs[lo]) / (hi - lo)
        sig = np.sqrt(np.maximum(cq[hi] - cq[lo + 1], 0.0) / (hi - lo - 1) / 2.0)
        sig_eff = np.maximum(sig, 1e-4 * np.abs(plat) + 1e-12)
        level = plat - s.trigger_sigma * sig_eff
        blo = np.maximum(arm, n - per)
        bmean = (cs[n] - cs[blo]) / (n - blo)
        bthr = 6.0 * sig_eff / math.sqrt(per)
        event = (lag >= s.min_plateau) & (n - blo == per) & (bmean > plat + 2.0 * bthr)
        event |= (lag >= per) & (bmean < plat - bthr)
        event |= pv[ks] < level
        if self._stuck_reported:
            event |= sig > 0.0
        else:
            event |= (sig == 0.0) & (hi - lo >= 2 * s.min_plateau)
        event |= np.minimum(n - 4 * self.PLATEAU, arm) > 65536  # buffer trim
        # samples between checks against the level of the check before them
        seg = pv[ks[0]:end]
        below = seg < np.repeat(level, per)[:seg.size]
        below[::per] = False
        below[::per] = event[:(seg.size + per - 1) // per]
        hits = np.flatnonzero(below)
        if hits.size == 0:
            k, j = ks.size, end
        else:
            j = int(ks[0]) + int(hits[0])
            k = (j - int(ks[0])) // per  # the check at or before j
            if not event[k] or j != ks[k]:
                k += 1  # between-check hit: check k ran without a decision
        if k > 0:  # state after the last check that decided nothing
            self._plateau_level = float(plat[k - 1])
            self._sigma = float(sig[k - 1])
            self._level = float(level[k - 1])
            self._next_check = int(ks[k - 1]) + per
        return j

    def _scan_unloading(self, i: int, end: int) -> int:
        nc = self._next_check
        j = self._level_hit(i, end)
        ks = self._checks(i, min(j, end))
        if ks.size == 0:
            return j
        if self._refined and self._slope0 > 0:
            stalled = self._stalled_many(ks)
            hit = np.flatnonzero(stalled)
            if hit.size:
                k = int(hit[0])
                self._next_check = int(ks[k]) if k > 0 else nc
                return int(ks[k])
        self._next_check = int(ks[-1]) + self.PERIOD
        return j

    def _stalled_many(self, ks: NDArray[np.int64]) -> NDArray[np.bool_]:
        """:meth:`_stalled` at many check indices (same formulas)."""
        cs = np.frombuffer(self._cs, dtype=float)
        tv = np.frombuffer(self._t, dtype=float)
        span = ks - self._i0
        w = np.minimum(np.maximum(32, span // 4), 8192)
        ok = span >= 2 * w
        a = (cs[np.maximum(ks - w + 1, 0)] - cs[np.maximum(ks - 2 * w + 1, 0)]) / w
        b = (cs[ks + 1] - cs[np.maximum(ks - w + 1, 0)]) / w
        dt = tv[ks] - tv[np.maximum(ks - w, 0)]
        drop = a - b
        se = self._sigma * np.sqrt(2.0 / w)
        return ok & (drop < 0.05 * self._slope0 * dt) & (drop < 4.0 * se)

    def _scan_tail(self, i: int, end: int) -> int:
        ks = self._checks(i, end)
        if ks.size == 0:
            return end
        per = self.PERIOD
        cs = np.frombuffer(self._cs, dtype=float)
        m = (cs[ks + 1] - cs[ks - per + 1]) / per
        low_prev = np.minimum.accumulate(np.concatenate(([self._tail_low], m)))[:-1]
        dp = abs(self._p10_signal - self._atm_signal)
        thr = max(10.0 * self._sigma / math.sqrt(per), 0.02 * dp)
        event = (m >= low_prev) & (m - low_prev > thr)
        res = self._pending
        if res is not None:
            event |= self._flat_many(ks, res.tau_exp)
        hit = np.flatnonzero(event)
        k = int(hit[0]) if hit.size else ks.size
        if k > 0:
            self._tail_low = float(min(low_prev[k - 1], m[k - 1]))
            self._next_check = int(ks[k - 1]) + per
        return int(ks[k]) if k < ks.size else end

    def _flat_many(self, ks: NDArray[np.int64], tau: float) -> NDArray[np.bool_]:
        """:meth:`_flat` at many check indices (same formulas)."""
        dt = self._dt_nominal if math.isfinite(self._dt_nominal) else 1e-3
        w = self._flat_window(tau)
        ok = ks - self._i0 >= 2 * w + int(tau / dt)
        ka = np.maximum(ks - 2 * w + 1, 0)
        cs = np.frombuffer(self._cs, dtype=float)
        a = (cs[np.maximum(ks - w + 1, 0)] - cs[ka]) / w
        b = (cs[ks + 1] - cs[np.maximum(ks - w + 1, 0)]) / w
        dp_total = np.abs(self._p10_signal - b)
        change = np.abs(a - b)
        se = self._sigma * math.sqrt(2.0 / w)
        return ok & (change < np.maximum(4.0 * se, 0.002 * dp_total))

    def _scan_recovery(self, i: int, end: int) -> int:
        ks = self._checks(i, end)
        if ks.size == 0:
            return end
        span = ks - self._i_close
        hit = np.flatnonzero((span >= self.RECOVERY_MIN) & (span >= 1.25 * self._rec_span))
        k = int(hit[0]) if hit.size else ks.size
        if k > 0:
            self._next_check = int(ks[k - 1]) + self.PERIOD
        return int(ks[k]) if k < ks.size else end

    def finish(self) -> list[UnloadResult]:
        """End of stream: report an unload still pending (aborted, or crossing not reached).

        Returns
        -------
        list of UnloadResult
            The pending unload's result, if any.
        """
        n = len(self._p)
        out: list[UnloadResult] = []
        if self._state == _RECOVERY:
            out.append(self._abort_result(n - 1, recovered=False))
            out[-1].final = True
        elif self._state == _UNLOADING and self._end_plateau_auto(n - 1):
            # p_atm from the final samples (short record, e.g. 1 Hz): crossing, then tail
            out += self._check_final_plateau_auto(n - 1, at_end=True)
            if self._state == _TAIL and self._pending is not None:
                out += self._finish_tail(n - 1, ended=True)
        elif self._state == _UNLOADING:
            auto = getattr(self, "_refined", False) and not math.isfinite(self._pstar_signal)
            text = ("stream ended before the final plateau: p_atm unknown (give the "
                    "atmospheric pressure)" if auto else "stream ended before the p* crossing")
            self._diag("warn", text, self._last_t)
            out.append(self._abort_result(n - 1, recovered=False, text=text))
        elif self._state == _TAIL and self._pending is not None:
            out += self._finish_tail(n - 1, ended=True)
        self._to_waiting(n)
        self.results += out
        return out

    # ------------------------------------------------------------------ internals
    @property
    def _gap_limit(self) -> float:
        if math.isnan(self._dt_nominal):
            return math.inf
        return self.settings.max_gap_factor * self._dt_nominal

    def _reject(self, t: float, p: float) -> None:
        if t != t:
            self._diag("warn", "sample with a NaN stamp ignored", t)
        elif t == self._last_t:
            self._diag("warn", f"duplicate stamp t={t:.9f} s ignored", t)
        else:
            self._diag("warn", f"stamp going backwards ({t:.9f} s after {self._last_t:.9f} s)"
                       " ignored", t)

    def _push_slow(self, t: FloatArray, p: FloatArray) -> list[UnloadResult]:
        out: list[UnloadResult] = []  # push() records them in self.results
        for ti, pi in zip(t.tolist(), p.tolist(), strict=True):
            out += self.push(ti, pi)
        return out

    def _diag(self, level: str, message: str, t: float) -> None:
        self.diagnostics.append(Diagnostic(level, self._state, message, t))

    def _on_gap(self, t: float) -> None:
        gap = t - self._last_t
        self._diag("warn", f"gap of {gap:.6f} s in the samples before t={t:.6f} s", t)
        if self._state in (_CONFIRM, _UNLOADING):
            self._gap_in_unload = True

    def _arrays(self, n: int) -> tuple[FloatArray, FloatArray]:
        """Buffer views up to (excluding) index n."""
        tv = np.frombuffer(self._t, dtype=float)[:n]
        pv = np.frombuffer(self._p, dtype=float)[:n]
        return tv, pv

    def _to_waiting(self, n: int) -> None:
        self._state = _WAITING
        self._below = True
        self._level = -math.inf
        self._next_check = n + self.settings.min_plateau - 1
        self._arm_index = n
        self._pending: UnloadResult | None = None
        self._gap_in_unload = False
        self._plateau_level = math.nan
        self._sigma = math.nan

    def _trim(self, n: int) -> None:
        """Drop samples that no later decision can need (keeps memory bounded)."""
        keep = min(n - 4 * self.PLATEAU, self._arm_index)
        if keep > 65536 and self._state == _WAITING:
            # new arrays (not in-place deletion): views held by callers stay valid
            self._t = array("d", self._t[keep:])
            self._p = array("d", self._p[keep:])
            self._cs = array("d", self._cs[keep:])
            self._cq = array("d", self._cq[keep:])
            self._next_check -= keep
            self._arm_index -= keep
            self._shift += keep

    def _step(self, i: int) -> list[UnloadResult]:
        """Decision at buffer index i (a periodic check or a level condition)."""
        state = self._state
        if state == _WAITING:
            return self._step_waiting(i)
        if state == _CONFIRM:
            return self._step_confirm(i)
        if state == _UNLOADING:
            return self._step_unloading(i)
        if state == _TAIL:
            return self._step_tail(i)
        return self._step_recovery(i)

    # waiting: plateau level and trigger
    def _step_waiting(self, i: int) -> list[UnloadResult]:
        """Periodic plateau update with a block-mean test, or a single-sample trigger.

        The reference level comes from a window that ends LAG samples ago, so a slow
        discharge cannot drag it along; the mean of the last PERIOD samples is tested
        against it (sensitive to slow drops), and each sample against ``trigger_sigma``
        noise deviations (fast drops, no waiting for the period).
        """
        n = i + 1
        tv, pv = self._arrays(n)
        if math.isnan(self._dt_nominal) and n >= 8:
            self._dt_nominal = float(np.median(np.diff(tv[max(0, n - 256):n])))
        if i == self._next_check:
            self._next_check = i + self.PERIOD
            avail = n - self._arm_index
            lag = min(self.LAG, max(avail - self.settings.min_plateau, 0))
            hi = n - lag
            lo = max(self._arm_index, hi - self.PLATEAU)
            # plateau: mean of the window; noise: rms of its first differences / sqrt 2
            self._plateau_level = self._mean(lo, hi)
            sig = self._diff_sigma(lo, hi)
            if sig == 0.0 and hi - lo >= 2 * self.settings.min_plateau:
                if not self._stuck_reported:
                    self._stuck_reported = True
                    self._diag("warn", f"sensor stuck? {hi - lo} identical samples "
                               f"({float(pv[lo])!r}): no noise at all", float(tv[i]))
            elif sig > 0.0:
                self._stuck_reported = False
            self._sigma = sig
            sig_eff = max(sig, 1e-4 * abs(self._plateau_level) + 1e-12)
            self._level = self._plateau_level - self.settings.trigger_sigma * sig_eff
            blo = max(self._arm_index, n - self.PERIOD)
            block_mean = self._mean(blo, n)
            if (lag >= self.settings.min_plateau and n - blo == self.PERIOD
                    and block_mean > self._plateau_level + 2.0 * self._block_threshold()):
                # the signal rose (the tank is being charged): the plateau starts again
                self._arm_index = n - self.PERIOD
                self._level = -math.inf
                del tv, pv
                return []
            mean_low = (lag >= self.PERIOD and
                        block_mean < self._plateau_level - self._block_threshold())
            if pv[i] >= self._level and not mean_low:
                del tv, pv  # release the buffer views before trimming
                self._trim(n)
                return []
        elif self._level == -math.inf:
            return []
        # trigger
        if i - self._arm_index < self.settings.min_plateau:
            return []
        self._trigger = i
        self._state = _CONFIRM
        self._next_check = i + self.PERIOD
        self._below, self._level = True, -math.inf
        return []

    def _mean(self, lo: int, hi: int) -> float:
        """Mean of samples [lo, hi) from the prefix sums [signal units]."""
        cs = self._cs
        return (cs[hi] - cs[lo]) / (hi - lo)

    def _diff_sigma(self, lo: int, hi: int) -> float:
        """Noise standard deviation of samples [lo, hi): rms of the first differences
        / sqrt(2), from the prefix sums (drift-insensitive) [signal units]."""
        cq = self._cq
        return math.sqrt(max(cq[hi] - cq[lo + 1], 0.0) / (hi - lo - 1) / 2.0)

    def _block_threshold(self) -> float:
        """Drop of a PERIOD-sample mean that counts as a step [signal units]."""
        sig_eff = max(self._sigma, 1e-4 * abs(self._plateau_level) + 1e-12)
        return 6.0 * sig_eff / math.sqrt(self.PERIOD)

    def _step_confirm(self, i: int) -> list[UnloadResult]:
        n = i + 1
        if self._mean(self._trigger + 1, n) < self._plateau_level - self._block_threshold():
            self._state = _UNLOADING
            self._diag("ok", "unload step detected", float(self._t[self._trigger]))
            return self._start_unloading(i)
        self._diag("warn", "trigger not confirmed (spike or noise); still waiting",
                   float(self._t[self._trigger]))
        self._state = _WAITING
        self._below, self._level = True, -math.inf
        self._next_check = i + 1
        return []

    def _start_unloading(self, i: int) -> list[UnloadResult]:
        s = self.settings
        p_plateau = self._plateau_level
        p_atm = s.atmosphere
        atm_signal = math.nan
        if p_atm is not None:
            atm_signal = (p_atm - s.signal_offset) / s.signal_gain
        self._atm_signal = atm_signal
        guess_atm = (atm_signal if p_atm is not None
                     else (101325.0 - s.signal_offset) / s.signal_gain)
        dp = p_plateau - guess_atm
        if p_atm is not None and dp * math.copysign(1.0, s.signal_gain) <= 0:
            return self._bad(i, f"p10 ({self._to_pa(p_plateau):.0f} Pa) is not above p_atm "
                                f"({p_atm:.0f} Pa): nothing to unload")
        self._dp_guess = abs(dp) if math.isfinite(dp) else abs(p_plateau) * 0.5
        # refine the start once the drop reaches 10 % of the pressure change
        self._refined = False
        self._below = True
        self._level = p_plateau - 0.1 * self._dp_guess
        self._next_check = i + self.PERIOD
        return []

    def _to_pa(self, x: float) -> float:
        return self.settings.signal_offset + self.settings.signal_gain * x

    def _bad(self, i: int, text: str) -> list[UnloadResult]:
        self._diag("error", text, float(self._t[i]))
        res = self._empty_result("bad_data", text, i)
        self._to_waiting(i + 1)
        return [res]

    def _empty_result(self, status: str, text: str, i: int, *, count: bool = True
                      ) -> UnloadResult:
        s = self.settings
        nan = math.nan
        res = UnloadResult(
            index=self._n_unloads, status=status, status_text=text, t_start=nan, t_cross=nan,
            tau_exp=nan, tau_exp_std=nan, p10=nan, p_atm=s.atmosphere or nan, p_star=nan,
            initial_temperature=s.initial_temperature, volume=s.volume, conductance=nan,
            conductance_model=nan, conductance_model_std=nan, quality=0.0,
            method="unloading-time", i_complete=i + self._shift, t_complete=float(self._t[i]))
        if count:
            self._n_unloads += 1
        return res

    def _step_unloading(self, i: int) -> list[UnloadResult]:
        n = i + 1
        _tv, pv = self._arrays(n)
        if not self._refined:
            if pv[i] < self._level:
                return self._refine_start(i)
            if i == self._next_check:
                self._next_check = i + self.PERIOD
                if self._stalled(i):
                    return self._on_abort(i)
            return []
        if pv[i] < self._level and math.isfinite(self._pstar_signal):
            return self._complete_crossing(i)
        if i == self._next_check:
            self._next_check = i + self.PERIOD
            if not math.isfinite(self._pstar_signal):
                return self._check_final_plateau_auto(i)
            if self._stalled(i):
                return self._on_abort(i)
        return []

    def _end_plateau_auto(self, i: int) -> bool:
        """p_atm auto at the end of the stream: True when the last eighth of the unload
        (at least 8 samples) is level to 0.5 % of the drop, with the drop > 50 %."""
        if not getattr(self, "_refined", False) or math.isfinite(self._pstar_signal):
            return False
        w = (i - self._i0) // 8
        if w < 8:
            return False
        a = self._mean(i - 2 * w + 1, i - w + 1)
        b = self._mean(i - w + 1, i + 1)
        drop = self._p10_signal - b
        return bool(abs(drop) > 0.5 * self._dp_guess and abs(a - b) < 0.005 * abs(drop))

    def _check_final_plateau_auto(self, i: int, at_end: bool = False) -> list[UnloadResult]:
        """p_atm auto: once the final plateau is reached, set p* and find the crossing
        (``at_end``: the stream ended on a plateau judged by :meth:`_end_plateau_auto`)."""
        tv, pv = self._arrays(i + 1)
        tau_guess = (float(tv[i]) - self._t0) / 4.0
        if at_end:
            w = max((i - self._i0) // 8, 8)
            level = self._mean(i - w + 1, i + 1)
            self._set_pstar(level)
            below = np.flatnonzero(pv[self._i0:i + 1] < self._pstar_signal - self._half)
            if below.size == 0:
                return []
            return self._complete_crossing(self._i0 + int(below[0]))
        if not self._flat(i, tau_guess):
            return []
        w = self._flat_window(tau_guess)
        level = float(np.mean(pv[i - w + 1:i + 1]))
        drop = self._p10_signal - level
        if drop < 0.5 * self._dp_guess:
            return self._on_abort(i)
        self._set_pstar(level)
        below = np.flatnonzero(pv[self._i0:i + 1] < self._pstar_signal - self._half)
        if below.size == 0:
            return self._on_abort(i)
        return self._complete_crossing(self._i0 + int(below[0]), settle_index=i)

    def _refine_start(self, i: int) -> list[UnloadResult]:
        n = i + 1
        tv, pv = self._arrays(n)
        trig = self._trigger
        back = i - trig + 4 * self.CONFIRM
        lo = max(self._arm_index, trig - back - self.HINGE_PLATEAU)
        t_lo = float(tv[max(self._arm_index, trig - back)])
        t0, p10, slope, _curv, rms = hinge_fit(tv[lo:n], pv[lo:n], t_lo, float(tv[trig]))
        pre = pv[lo:int(np.searchsorted(tv, t0))]
        sig_pre = _rms_sigma(pre) if pre.size > 3 else rms
        if pre.size >= 8:
            vmax = float(np.max(pre))
            frac_at_max = float(np.mean(pre == vmax))
            if frac_at_max > 0.5 and sig_pre == 0.0 and rms > 0.0:
                return self._bad(
                    i, f"sensor saturated on the pre-step plateau at {vmax!r}: p10 unknown")
        self._t0 = t0
        self._i0 = int(np.searchsorted(tv, t0))
        n_pre, n_post = max(self._i0 - lo, 1), max(n - self._i0, 1)
        self._t0_sd = (rms / slope * math.sqrt(1.0 / n_pre + 4.0 / n_post)
                       if slope > 0 else math.inf)
        self._p10_signal = p10
        self._slope0 = slope
        self._sigma = max(rms, 1e-12)
        self._refined = True
        s = self.settings
        if s.atmosphere is not None:
            self._set_pstar(self._atm_signal)
        else:
            self._pstar_signal = math.nan
            self._below, self._level = True, -math.inf
        self._next_check = i + self.PERIOD
        return []

    def _set_pstar(self, atm_signal: float) -> None:
        self._atm_signal = atm_signal
        dp = self._p10_signal - atm_signal
        self._pstar_signal = atm_signal + P_STAR_FRACTION * dp
        self._half = max(6.0 * self._sigma, 0.05 * abs(dp))
        self._below = True
        self._level = self._pstar_signal - self._half

    def _stalled(self, i: int) -> bool:
        """True when the pressure has stopped falling well above p* (valve closed)."""
        if not self._refined or self._slope0 <= 0:
            return False
        span = i - self._i0
        w = int(min(max(32, span // 4), 8192))
        if span < 2 * w:
            return False
        cs = self._cs
        a = (cs[i - w + 1] - cs[i - 2 * w + 1]) / w
        b = (cs[i + 1] - cs[i - w + 1]) / w
        dt = self._t[i] - self._t[i - w]
        drop = a - b
        se = self._sigma * math.sqrt(2.0 / w)
        return drop < 0.05 * self._slope0 * dt and drop < 4.0 * se

    def _complete_crossing(self, i: int, settle_index: int | None = None
                           ) -> list[UnloadResult]:
        """Crossing window closed at index i (first sample below p* - half)."""
        n = i + 1
        tv, pv = self._arrays(n)
        lvl_hi = self._pstar_signal + self._half
        # last sample above the upper bound before i
        above = np.flatnonzero(pv[self._i0:n] > lvl_hi)
        j_lo = self._i0 + (int(above[-1]) if above.size else 0)
        tw, pw = tv[j_lo:n], pv[j_lo:n]
        if tw.size < 5:
            tw, pw = tv[max(self._i0, n - 5):n], pv[max(self._i0, n - 5):n]
        t_cross, t_std, _slope = crossing_fit(tw, pw, self._pstar_signal)
        # second pass on a window symmetric in time about the first estimate: the ends of
        # the first window were chosen by noisy sample values, which biases the fit
        h = float(tv[n - 1]) - t_cross
        if h > 0:
            k0 = int(np.searchsorted(tv, t_cross - h))
            if n - k0 >= 5:
                t_cross, t_std, _slope = crossing_fit(tv[k0:n], pv[k0:n], self._pstar_signal)
        gap = bool(np.any(np.diff(tw) > self._gap_limit)) if tw.size > 1 else False
        k = i if settle_index is None else settle_index
        res = self._make_result(k, t_cross, t_std, gap)
        self._pending = res
        self._state = _TAIL
        self._tail_low = math.inf
        self._below, self._level = True, -math.inf
        self._next_check = k + self.PERIOD
        if settle_index is not None:
            return [res, *self._finish_tail(k, ended=False)]
        return [res]

    def _make_result(self, i: int, t_cross: float, t_std: float, gap: bool) -> UnloadResult:
        s = self.settings
        gas = s.gas
        p10 = self._to_pa(self._p10_signal)
        p_atm = self._to_pa(self._atm_signal)
        p_star = self._to_pa(self._pstar_signal)
        tau = t_cross - self._t0
        t0_std = self._t0_std()
        tau_std = math.hypot(t_std, t0_std)
        status, text, quality = "ok", "p* crossing found", 1.0
        c39 = physics.conductance_eq39(tau, p10, p_atm, s.volume, s.initial_temperature, gas)
        c_isen = physics.conductance_isentropic_inversion(
            tau, p_star, p10, s.volume, s.initial_temperature, gas)
        if s.critical_ratio > 0 and p_star < p_atm / s.critical_ratio:
            status, text = "not_choked", (
                f"flow subsonic before p* (p* = {p_star:.0f} Pa < p_atm/b = "
                f"{p_atm / s.critical_ratio:.0f} Pa): eq 39 assumes choked flow")
            quality = 0.5
        c_model, c_model_std, method = self._model_inversion(tau, tau_std, p10, p_atm, p_star,
                                                             c_isen)
        if gap or self._gap_in_unload:
            text += "; gap in the samples during the unload"
            quality = min(quality, 0.5)
        if tau_std / tau > 0.01:
            quality = min(quality, 0.5)
        res = UnloadResult(
            index=self._n_unloads, status=status, status_text=text, t_start=self._t0,
            t_cross=t_cross, tau_exp=tau, tau_exp_std=tau_std, p10=p10, p_atm=p_atm,
            p_star=p_star, initial_temperature=s.initial_temperature, volume=s.volume,
            conductance=c39, conductance_model=c_model, conductance_model_std=c_model_std,
            conductance_isentropic=c_isen, quality=quality, method=method,
            noise_std=abs(self._sigma * s.signal_gain), i_start=self._i0 + self._shift,
            i_cross=self._shift + int(np.searchsorted(
                np.frombuffer(self._t, dtype=float)[:i + 1], t_cross)),
            i_complete=i + self._shift, t_complete=float(self._t[i]))
        self._n_unloads += 1
        return res

    def _t0_std(self) -> float:
        """Standard deviation of the start time [s]: noise over the initial slope, with the
        plateau (p10) and post-start samples of the hinge fit."""
        return self._t0_sd

    def _model_inversion(self, tau: float, tau_std: float, p10: float, p_atm: float,
                         p_star: float, c_isen: float) -> tuple[float, float, str]:
        """Model-based C: exact inversion of the discharge model at the crossing."""
        s = self.settings
        if s.heat_model == "adiabatic":
            c = c_isen
            std = c * tau_std / tau
            return c, std, "eq39+isentropic-inversion"
        from pneumatic_unload.fitting import invert_crossing  # local: keeps import light

        c, std = invert_crossing(
            tau, tau_std, p10=p10, p_atm=p_atm, p_star=p_star, settings=s, c_start=c_isen)
        return c, std, "eq39+model-inversion(natural-convection)"

    def _step_tail(self, i: int) -> list[UnloadResult]:
        if i != self._next_check:
            return []
        self._next_check = i + self.PERIOD
        res = self._pending
        k = self._tail_rise(i)
        if k >= 0:
            # the tank is being charged again: the tail ended before the rise; re-arm now
            self._diag("ok", "pressure rising again after the unload: tail ended, re-armed",
                       float(self._t[i]))
            out = self._finish_tail(k, ended=False, decided=i)
            self._next_check = i + self.PERIOD
            return out
        if res is not None and self._flat(i, res.tau_exp):
            return self._finish_tail(i, ended=False)
        return []

    def _tail_rise(self, i: int) -> int:
        """Index where the tail ends because the signal rises again (a new charge), or -1.

        The mean of the last PERIOD samples is compared with the lowest such mean seen in
        the tail; a rise of more than max(10 sigma/sqrt(PERIOD), 2 % of p10 - p_atm) ends
        the tail two periods back (before the rise began).
        """
        cs = self._cs
        m = (cs[i + 1] - cs[i - self.PERIOD + 1]) / self.PERIOD
        if m < self._tail_low:
            self._tail_low = m
            return -1
        dp = abs(self._p10_signal - self._atm_signal)
        thr = max(10.0 * self._sigma / math.sqrt(self.PERIOD), 0.02 * dp)
        if m - self._tail_low > thr:
            return max(i - 2 * self.PERIOD, self._i0 + 1)
        return -1

    def _flat_window(self, tau: float) -> int:
        dt = self._dt_nominal if math.isfinite(self._dt_nominal) else 1e-3
        return int(min(max(128, 0.5 * tau / dt), 16384))

    def _flat(self, i: int, tau: float) -> bool:
        """True when the signal has settled on its final plateau (tau: time scale [s])."""
        dt = self._dt_nominal if math.isfinite(self._dt_nominal) else 1e-3
        w = self._flat_window(tau)
        if i - self._i0 < 2 * w + int(tau / dt):
            return False
        cs = self._cs
        a = (cs[max(i - w + 1, 0)] - cs[max(i - 2 * w + 1, 0)]) / w
        b = (cs[i + 1] - cs[max(i - w + 1, 0)]) / w
        dp_total = abs(self._p10_signal - b)
        change = abs(a - b)
        se = self._sigma * math.sqrt(2.0 / w)
        return change < max(4.0 * se, 0.002 * dp_total)

    def _finish_tail(self, i: int, ended: bool, decided: int | None = None
                     ) -> list[UnloadResult]:
        """Close the unload at index i (last sample of its tail); ``decided``: the index
        at which that was decided (default i)."""
        dec = i if decided is None else decided
        res = self._pending
        self._pending = None
        out: list[UnloadResult] = []
        if res is not None:
            res.t_end = float(self._t[i])
            if self.settings.curve_fit:
                from pneumatic_unload.fitting import refine_with_curve_fit

                tv, pv = self._arrays(i + 1)
                lo = max(self._arm_index, self._i0 - 2 * self.PLATEAU)
                fin = refine_with_curve_fit(
                    res, tv[lo:i + 1], self._to_pa_array(pv[lo:i + 1]), self.settings,
                    noise_std=abs(self._sigma * self.settings.signal_gain))
                if fin is not None:
                    fin.i_complete, fin.t_complete = dec + self._shift, float(self._t[dec])
                    out.append(fin)
        self._to_waiting(i + 1)
        return out

    def _to_pa_array(self, x: FloatArray) -> FloatArray:
        s = self.settings
        return s.signal_offset + s.signal_gain * x

    # aborted unload and SSE
    def _on_abort(self, i: int) -> list[UnloadResult]:
        tv, pv = self._arrays(i + 1)
        tail = pv[max(self._i0, i - 2 * self.PERIOD + 1):i + 1]
        if tail.size >= 2 * self.PERIOD and float(np.ptp(tail)) == 0.0:
            return self._bad(i, f"sensor stuck at {float(tail[0])!r} during the unload "
                                f"({tail.size} identical samples, no noise): no estimate")
        self._diag("warn", "unload stopped before p*: valve closed (aborted unload)",
                   float(tv[i]))
        # closing instant: a corner fit (quadratic before and after the closing instant)
        # on a wide window, then again on a window local to the first estimate
        span = i - self._i0
        w = int(min(max(32, span // 4), 8192))
        lo = max(self._i0 + 1, i - 6 * w)
        t_c, p_c, _rms = corner_fit(tv[lo:i + 1], pv[lo:i + 1], float(tv[lo + 8]),
                                    float(tv[i - 8]))
        j = int(np.searchsorted(tv, t_c))
        half = max(64, (j - self._i0) // 5)
        lo2, hi2 = max(self._i0 + 1, j - half), min(i + 1, j + half)
        if hi2 - lo2 >= 24:
            t_c, p_c, _rms = corner_fit(tv[lo2:hi2], pv[lo2:hi2], float(tv[lo2 + 4]),
                                        float(tv[hi2 - 5]))
        self._t_close, self._p_close_signal = t_c, p_c
        self._i_close = min(int(np.searchsorted(tv, self._t_close)), i)
        self._rec_span = 0
        self._rec_fit: Any = None
        self._state = _RECOVERY
        self._below, self._level = True, -math.inf
        self._next_check = i + self.PERIOD
        # report the abort at once (a live node must not stay silent through a recovery
        # that may take minutes); the SSE result follows under the same index, final=True
        t_star = self._t_close - self._t0
        res = self._empty_result(
            "aborted", f"valve closed {t_star:.4f} s after the start, before p*: aborted "
            "unload; waiting for the pressure recovery (SSE, eq 23)", i, count=False)
        if getattr(self, "_refined", False):
            res.p10, res.t_start = self._to_pa(self._p10_signal), self._t0
            res.i_start = self._i0 + self._shift
        return [res]

    #: Recovery samples needed before the first recovery fit [-].
    RECOVERY_MIN = 256

    def _fit_recovery(self, i: int) -> Any:
        """Fit the recovery from the closing instant to index i (None when it fails)."""
        from pneumatic_unload.recovery import fit_recovery

        tv, pv = self._arrays(i + 1)
        j = self._i_close
        try:
            fit = fit_recovery(tv[j:i + 1], pv[j:i + 1], self._t_close)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            return None
        self._rec_fit, self._rec_span = fit, i - j
        return fit

    def _expected_recovery_time(self) -> float:
        """Initial thermal time constant m c_v / (h A) of the closed tank [s], with h from
        the natural-convection correlation at the closing state (the recovery is not
        declared over before three of these, however flat it looks: a slow re-heating
        is indistinguishable from a plateau over a short record)."""
        s = self.settings
        gas = s.gas
        p10 = self._to_pa(self._p10_signal)
        p_c = self._to_pa(self._p_close_signal)
        t10 = s.initial_temperature
        t_w = s.wall_temperature or t10
        ratio = max(p_c / p10, 1e-3) if p10 > 0 else 1.0
        t_gas = t10 * ratio ** ((gas.gamma - 1.0) / gas.gamma)
        length, _d, area = physics.tank_geometry(s.volume, s.length_diameter_ratio)
        h = physics.natural_convection_h(p_c, t_gas, t_w if abs(t_w - t_gas) > 0.1
                                         else t_gas + 0.1, length, gas)
        mass = p_c * s.volume / (gas.gas_constant * t_gas)
        return mass * gas.cv / (h * area)

    def _recovery_significant(self, fit: Any) -> bool:
        """True when the fitted re-heating rise is clearly above the noise."""
        if fit is None or not fit.success or not math.isfinite(fit.p_inf_std):
            return False
        seen = fit.rise - fit.remaining  # rise observed so far [signal units]
        return bool(abs(seen) > 8.0 * self._sigma / math.sqrt(max(fit.n / 4, 1)))

    def _step_recovery(self, i: int) -> list[UnloadResult]:
        """Periodic recovery check: refit as the record grows (each 25 % longer); the
        recovery is over when the fitted remaining rise is below 5 % of the total (the
        fit extrapolates the rest), p1_inf is known to 2 % of the rise, and the record
        covers 3 expected and 4 fitted thermal time constants."""
        if i != self._next_check:
            return []
        self._next_check = i + self.PERIOD
        span = i - self._i_close
        if span < self.RECOVERY_MIN or span < 1.25 * self._rec_span:
            return []
        fit = self._fit_recovery(i)
        if fit is None:
            return []
        dt = self._dt_nominal if math.isfinite(self._dt_nominal) else 1e-3
        if (self._recovery_significant(fit) and fit.remaining <= 0.05 * fit.rise
                and fit.p_inf_std < 0.02 * fit.rise
                and span * dt >= 3.0 * self._expected_recovery_time()
                and span * dt >= 4.0 * fit.tau):
            res = self._abort_result(i, recovered=True)
            res.final = True
            self._to_waiting(i + 1)
            return [res]
        t_star = self._t_close - self._t0
        if not self._recovery_significant(fit) and span * dt > max(20.0 * t_star, 2.0) \
                and span >= 4 * self.PLATEAU:
            res = self._abort_result(i, recovered=False, text=(
                "valve closed before p*; no pressure recovery after closing (no re-heating "
                "seen), so no SSE value"))
            res.final = True
            self._to_waiting(i + 1)
            return [res]
        return []

    def _abort_result(self, i: int, recovered: bool, text: str = "") -> UnloadResult:
        """Result of an aborted unload; with ``recovered`` (or a recovery fit good enough
        to extrapolate at the end of the stream), the SSE value of eq 23."""
        s = self.settings
        res = self._empty_result("aborted", text or "valve closed before p*; no recovery "
                                 "plateau recorded (SSE needs it)", i)
        if not getattr(self, "_refined", False):
            return res
        p10 = self._to_pa(self._p10_signal)
        res.p10, res.t_start = p10, self._t0
        res.i_start = self._i0 + self._shift
        if self._state != _RECOVERY:
            return res
        fit = self._rec_fit
        if not recovered and i - self._i_close >= 16 and i - self._i_close != self._rec_span:
            fit = self._fit_recovery(i)
        if not self._recovery_significant(fit):
            return res
        gain = abs(s.signal_gain)
        p_inf = self._to_pa(fit.p_inf)
        p_inf_std = gain * fit.p_inf_std
        p_close = self._to_pa(self._p_close_signal)
        t_star = self._t_close - self._t0
        t_star_std = self._t0_std()
        gas, t10, vol = s.gas, s.initial_temperature, s.volume
        c = physics.conductance_sse(t_star, p10, p_inf, vol, t10, gas)
        dc_dp = (physics.conductance_sse(t_star, p10, p_inf + p_inf_std, vol, t10, gas) - c)
        c_std = math.hypot(dc_dp, c * t_star_std / t_star, c * SSE_MODEL_REL_STD)
        if not (math.isfinite(c) and c > 0 and c_std < 0.25 * c):
            res.status_text += (f"; recovery fit too uncertain for SSE (p_inf = {p_inf:.0f} "
                                f"+- {p_inf_std:.0f} Pa)")
            return res
        done = 1.0 - fit.remaining / fit.rise
        how = ("recovery plateau" if recovered else
               f"recovery extrapolated from {100 * done:.0f} % of the re-heating")
        res.status = "aborted_sse"
        res.status_text = (f"valve closed after {t_star:.4f} s before p*; SSE (eq 23) from "
                           f"the {how}, p1_inf = {p_inf:.0f} +- {p_inf_std:.0f} Pa")
        res.conductance = c
        # model-based: the discharge model inverted at the closing instant and pressure
        c_isen = physics.conductance_isentropic_inversion(t_star, p_close, p10, vol, t10, gas)
        atm = s.atmosphere if s.atmosphere is not None else 101325.0
        c_model, c_model_std, method = self._model_inversion(
            t_star, t_star_std, p10, atm, p_close, c_isen)
        res.conductance_model = c_model
        res.conductance_model_std = c_model_std
        res.conductance_isentropic = c_isen
        res.quality = 0.7 if recovered else 0.5
        res.method = "sse-eq23;" + method.replace("eq39+", "") + "-at-closing"
        res.extra = {"t_star": t_star, "t_close": self._t_close, "p1_inf": p_inf,
                     "p1_inf_std": p_inf_std, "p_close": p_close, "sse_std": c_std,
                     "recovered_fraction": done, "recovery_tau": fit.tau,
                     "recovery_exponent": fit.exponent}
        return res


def analyze(
    t: ArrayLike, p: ArrayLike, settings: EstimatorSettings | None = None
) -> list[UnloadResult]:
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
    list of UnloadResult
        Results as the streaming estimator emits them (crossing estimates, then the
        curve-fit refinement with ``final=True`` when the unload's end was recorded).

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
    if t.size < 16:
        raise EstimationError(f"too few samples ({t.size}); need at least 16")
    est = StreamingEstimator(settings)
    out = est.push_block(t, p)
    out += est.finish()
    return out


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
