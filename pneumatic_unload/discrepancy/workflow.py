"""The discrepancy workflow: where do simulation and measurement disagree, and why?

Steps (SI units throughout: s, Pa absolute, K, m^3, m^3/(s Pa)):

0. **Noise model.** The AR(1) coefficient rho from the pre-step and end plateaus, sigma
   from the plateaus combined with a high-pass (local cubic residual) estimate over the
   whole trace, so that short traces are normalised by the noise they actually carry
   (:func:`~pneumatic_unload.discrepancy.noise.estimate_noise`); the likelihood prewhitens
   the residual so that correlated noise does not count as information.
1. **Baseline.** Multi-start least-squares fit of the adiabatic discharge (C, b, t_open,
   p10 [, p_atm]); diagnostics: normalised RMS, Ljung-Box whiteness, residual per phase
   (pre-step, choked, subsonic, plateau).
2. **Candidates.** For each effect, the whole model is refitted with the effect added,
   from several starts: from the baseline fit *and* from the neutral (unloading-time)
   values of the baseline parameters, each with small and large effect sizes.
3. **Decision** by BIC = chi^2 + k ln(n): an effect is claimed only if it beats the
   current model by more than ``bic_threshold`` (10); it is named alone only if the
   runner-up is more than 10 behind, otherwise the ambiguity set is reported with the
   extra data that would separate its members.
4. **Gap.** RMS before and after, the effect's parameters with 95 % intervals (linear from
   the Jacobian, replaced by the profile likelihood when the linear one is unreliable); an
   interval that does not close within the parameter range means "not identifiable".
5. **Greedy.** While the residual is still structured, a further effect is added the same
   way (at most ``max_effects``).

A constant geometric factor on C (the paper's L/D effect) enters the model only through
the product f C, so it is reported as not identifiable from one trace; several runs with
different tank geometries identify it (:mod:`pneumatic_unload.discrepancy.multirun`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from pneumatic_unload.config import EFFECTS
from pneumatic_unload.discrepancy.candidates import (
    GEOMETRY_FACTOR,
    ModelSpec,
    RigInfo,
    Start,
    separating_data,
)
from pneumatic_unload.discrepancy.noise import (
    BinnedLikelihood,
    NoiseModel,
    estimate_noise,
    ljung_box,
    make_bins,
)
from pneumatic_unload.estimation import EstimationError, EstimatorSettings, analyze
from pneumatic_unload.physics import AIR, T_N, Gas

FloatArray = NDArray[np.float64]

#: chi^2 quantile of a 95 % interval with one parameter [-].
CHI2_95 = 3.841458820694124
#: Ljung-Box p-value below which a residual is called structured [-].
WHITE_P = 0.01
#: Normalised RMS above which a residual is called structured [-].
NRMS_LIMIT = 1.02
#: How to read a delta-BIC (for reports).
BIC_HELP = ("delta-BIC = BIC(current model) - BIC(current model + candidate), BIC = chi^2 + "
            "k ln(n): positive means the candidate explains the trace better after paying "
            "for its extra parameters. An effect is claimed above 10 and named alone when "
            "the runner-up is more than 10 behind.")
#: Finite-difference step in scaled coordinates: large enough to stay clear of the
#: integrator's tolerance (a 1e-5 step gave noisy Jacobians and stalled fits) [-].
DIFF_STEP = 1e-3


class DiscrepancyError(ValueError):
    """Input the workflow cannot analyse: no unload, non-finite samples, too short..."""


@dataclass(frozen=True)
class DiscrepancySettings:
    """Settings of :func:`find_discrepancy`.

    Attributes
    ----------
    volume : float
        Tank volume V [m^3].
    initial_temperature : float
        Initial gas temperature T10 [K].
    atmosphere : float or None
        Atmospheric pressure [Pa absolute]; None: fitted (offset and gain then become
        hard to tell from p_atm and p10).
    length_diameter_ratio : float
        Tank L/D [-].
    wall_temperature : float or None
        Wall temperature [K]; None: equal to T10.
    fit_wall_temperature : bool
        Fit the wall temperature together with the heat-transfer time constant (when the
        gas starts warmer or colder than the wall, e.g. just after charging).
    candidates : tuple of str
        Effects tried (default all of :data:`pneumatic_unload.config.EFFECTS`).
    max_effects : int
        At most this many effects are added (greedy) [-].
    bic_threshold : float
        Delta-BIC needed to claim an effect and to name it alone [-].
    profile : bool
        Check the linear intervals with the profile likelihood.
    resolution : float
        Relative bin width of the likelihood [-] (smaller: slower, a little more power).
    gas_constant, gamma : float
        Gas [J/(kg K)], [-].
    """

    volume: float
    initial_temperature: float = T_N
    atmosphere: float | None = 101325.0
    length_diameter_ratio: float = 2.0
    wall_temperature: float | None = None
    fit_wall_temperature: bool = False
    candidates: tuple[str, ...] = EFFECTS
    max_effects: int = 3
    bic_threshold: float = 10.0
    profile: bool = True
    resolution: float = 0.03
    gas_constant: float = AIR.gas_constant
    gamma: float = AIR.gamma

    def __post_init__(self) -> None:
        """Validate (raises :class:`DiscrepancyError`)."""
        if not (self.volume > 0 and math.isfinite(self.volume)):
            raise DiscrepancyError("volume must be a positive number of m^3")
        if not self.initial_temperature > 0:
            raise DiscrepancyError("initial_temperature must be > 0 K")
        if self.atmosphere is not None and not self.atmosphere > 0:
            raise DiscrepancyError("atmosphere must be > 0 Pa")
        bad = [c for c in self.candidates if c not in EFFECTS]
        if bad:
            raise DiscrepancyError(f"unknown candidate effect(s) {bad}; known: {EFFECTS}")
        if not 1 <= self.max_effects <= 3:
            raise DiscrepancyError("max_effects must be 1, 2 or 3")

    @classmethod
    def from_estimator(cls, s: EstimatorSettings, **kw: Any) -> DiscrepancySettings:
        """Settings matching an :class:`EstimatorSettings` (the ``analyze`` options)."""
        return cls(volume=s.volume, initial_temperature=s.initial_temperature,
                   atmosphere=s.atmosphere, length_diameter_ratio=s.length_diameter_ratio,
                   wall_temperature=s.wall_temperature, gas_constant=s.gas_constant,
                   gamma=s.gamma, **kw)


@dataclass
class Fit:
    """A fitted model.

    Attributes
    ----------
    spec : ModelSpec
        Model (effects and parameters).
    x : ndarray
        Scaled coordinates of the optimum.
    theta : dict
        Parameters [SI units].
    chi2 : float
        -2 log-likelihood up to a constant [-].
    bic : float
        chi2 + k ln(n) [-].
    jac : ndarray
        Jacobian of the normalised residuals in scaled coordinates.
    success : bool
        Optimiser status.
    nfev : int
        Model evaluations used [-].
    """

    spec: ModelSpec
    x: FloatArray
    theta: dict[str, float]
    chi2: float
    bic: float
    jac: FloatArray
    success: bool
    nfev: int

    @property
    def effects(self) -> tuple[str, ...]:
        """Effects of the model."""
        return self.spec.effects


@dataclass
class Interval:
    """A fitted parameter with its 95 % interval.

    Attributes
    ----------
    value, low, high : float
        Estimate and interval ends [unit]; an open end is +-inf (or the range limit).
    unit : str
        SI unit.
    method : str
        'linear' (Jacobian) or 'profile' (profile likelihood).
    identifiable : bool
        False when the interval does not close within the parameter's range.
    doc : str
        Meaning.
    """

    value: float
    low: float
    high: float
    unit: str
    method: str
    identifiable: bool
    doc: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (infinite ends as None)."""
        def f(v: float) -> float | None:
            return v if math.isfinite(v) else None
        return {"value": self.value, "ci_low": f(self.low), "ci_high": f(self.high),
                "unit": self.unit, "method": self.method, "identifiable": self.identifiable,
                "doc": self.doc}


@dataclass
class Diagnostics:
    """How well a model explains the trace.

    Attributes
    ----------
    rms : float
        Root mean square of the residual y - model [Pa].
    nrms : float
        rms / sigma [-] (1 when the gap is within noise).
    ljung_box_p : float
        Ljung-Box p-value of the normalised binned residual [-].
    white : bool
        ljung_box_p >= WHITE_P.
    phases : dict
        Per phase ('pre-step', 'choked', 'subsonic', 'plateau'): samples, mean [Pa],
        rms [Pa], nrms [-].
    corr_pressure, corr_rate : float
        Correlation of the binned residual with the pressure and with its rate [-].
    """

    rms: float
    nrms: float
    ljung_box_p: float
    white: bool
    phases: dict[str, dict[str, float]]
    corr_pressure: float
    corr_rate: float

    @property
    def structured(self) -> bool:
        """True when the residual is more than noise (not white or nrms above the limit)."""
        return (not self.white) or self.nrms > NRMS_LIMIT

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {"rms": self.rms, "nrms": self.nrms, "ljung_box_p": self.ljung_box_p,
                "white": self.white, "structured": self.structured, "phases": self.phases,
                "corr_pressure": self.corr_pressure, "corr_rate": self.corr_rate}


@dataclass
class Round:
    """One greedy round: every remaining candidate added to the current model.

    Attributes
    ----------
    base_effects : tuple of str
        Effects of the model the candidates were added to.
    base_bic : float
        BIC of that model [-].
    fits : dict
        Candidate name -> fit.
    delta_bic : dict
        Candidate name -> BIC(base) - BIC(candidate) [-] (positive: candidate better).
    winner : str
        Best candidate ('none' when none beats the base by the threshold).
    ambiguous_with : list of str
        Candidates within the threshold of the winner.
    """

    base_effects: tuple[str, ...]
    base_bic: float
    fits: dict[str, Fit]
    delta_bic: dict[str, float]
    winner: str
    ambiguous_with: list[str]


@dataclass
class DiscrepancyResult:
    """Outcome of the workflow on one trace (SI units).

    ``effect`` is the first effect claimed ('none' when the baseline explains the trace
    within noise), ``ambiguous_with`` the effects the data cannot tell from it, and
    ``effects`` all effects added greedily. ``before``/``after`` are the diagnostics of
    the baseline and of the final model.
    """

    effect: str
    ambiguous_with: list[str]
    effects: list[str]
    verdict: str
    parameters: dict[str, Interval]
    noise: NoiseModel
    baseline: Fit
    final: Fit
    rounds: list[Round]
    before: Diagnostics
    after: Diagnostics
    extra_data: list[str]
    geometry_factor: dict[str, Any]
    t: FloatArray
    y: FloatArray
    model_before: FloatArray
    model_after: FloatArray
    t_ref: float
    n_samples: int
    n_bins: int
    elapsed: float
    temperature_check: dict[str, Any] | None = None
    t_temperature: FloatArray | None = None
    temperature: FloatArray | None = None
    settings: DiscrepancySettings | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def rms_before(self) -> float:
        """RMS of the baseline residual [Pa]."""
        return self.before.rms

    @property
    def rms_after(self) -> float:
        """RMS of the final model's residual [Pa]."""
        return self.after.rms

    @property
    def delta_bic(self) -> dict[str, float]:
        """First round: candidate -> BIC(baseline) - BIC(baseline + candidate) [-]."""
        return dict(self.rounds[0].delta_bic) if self.rounds else {}

    @property
    def conductance(self) -> float:
        """C of the final model [m^3/(s Pa)]."""
        return self.final.theta["C"]

    def conductance_std(self) -> float:
        """1-sigma of C of the final model from the Jacobian [m^3/(s Pa)]."""
        cov = _covariance(self.final)
        i = self.final.spec.names.index("C")
        return float(self.conductance * self.final.spec.scale[i] * math.sqrt(max(cov[i, i], 0)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the ``--json`` output)."""
        def theta(f: Fit) -> dict[str, Any]:
            return {"effects": list(f.effects), "parameters": dict(f.theta), "chi2": f.chi2,
                    "bic": f.bic, "k": f.spec.k}

        return _finite({
            "effect": self.effect, "ambiguous_with": list(self.ambiguous_with),
            "effects": list(self.effects), "verdict": self.verdict,
            "parameters": {k: v.to_dict() for k, v in self.parameters.items()},
            "rms_before": self.rms_before, "rms_after": self.rms_after,
            "nrms_before": self.before.nrms, "nrms_after": self.after.nrms,
            "white_before": self.before.white, "white_after": self.after.white,
            "delta_bic": self.delta_bic,
            "rounds": [{"base_effects": list(r.base_effects), "delta_bic": r.delta_bic,
                        "winner": r.winner, "ambiguous_with": r.ambiguous_with}
                       for r in self.rounds],
            "noise": self.noise.to_dict(),
            "baseline": theta(self.baseline), "final_model": theta(self.final),
            "conductance": self.conductance, "conductance_std": self.conductance_std(),
            "diagnostics_before": self.before.to_dict(),
            "diagnostics_after": self.after.to_dict(),
            "extra_data": self.extra_data, "geometry_factor": self.geometry_factor,
            "temperature_check": self.temperature_check,
            "samples": self.n_samples, "bins": self.n_bins, "elapsed_s": self.elapsed,
            "notes": self.notes,
        })


def _finite(o: Any) -> Any:
    """Replace non-finite floats by None, recursively (strict JSON)."""
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, (float, np.floating)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, (np.integer, np.bool_)):
        return o.item()
    return o


# ------------------------------------------------------------------------------ fitting
class Problem:
    """A trace prepared for fitting: relative times, noise model, likelihood, neutral start.

    Parameters
    ----------
    t, y : ndarray
        Sample instants [s] and measured pressure [Pa absolute].
    settings : DiscrepancySettings
        Rig data and workflow options.
    """

    def __init__(self, t: FloatArray, y: FloatArray, settings: DiscrepancySettings) -> None:
        t = np.asarray(t, dtype=float)
        y = np.asarray(y, dtype=float)
        if t.ndim != 1 or t.shape != y.shape:
            raise DiscrepancyError(f"t and p must be 1-D arrays of equal length, got "
                                   f"{t.shape} and {y.shape}")
        if t.size < 20:
            raise DiscrepancyError(f"too few samples ({t.size}); need at least 20")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
            k = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(y)))[0])
            raise DiscrepancyError(f"non-finite sample at index {k}; remove or interpolate "
                                   "it before the analysis")
        if np.any(np.diff(t) <= 0):
            raise DiscrepancyError("time stamps must increase strictly")
        self.settings = settings
        self.t_ref = float(t[0])
        t = t - self.t_ref
        est = EstimatorSettings(
            volume=settings.volume, initial_temperature=settings.initial_temperature,
            atmosphere=settings.atmosphere, length_diameter_ratio=settings.length_diameter_ratio,
            heat_model="adiabatic", curve_fit=False, gas_constant=settings.gas_constant,
            gamma=settings.gamma)
        try:
            results = [r for r in analyze(t, y, est) if r.status in ("ok", "not_choked")]
        except EstimationError as exc:
            raise DiscrepancyError(str(exc)) from exc
        if not results:
            raise DiscrepancyError("no complete unload found in the trace (the pressure "
                                   "must fall from a plateau through p*)")
        r = results[0]
        # keep one unload: cut before the next one starts
        later = [q.t_start for q in results[1:] if q.t_start > r.t_cross]
        if later:
            keep = t < later[0] - 0.1 * (later[0] - r.t_cross)
            t, y = t[keep], y[keep]
        dt = float(np.median(np.diff(t)))
        c0 = r.conductance_isentropic if math.isfinite(r.conductance_isentropic) \
            else r.conductance
        self.start = Start(conductance=float(c0), critical_ratio=0.4, t_open=float(r.t_start),
                           p10=float(r.p10), p_atm=float(r.p_atm), tau=float(r.tau_exp),
                           dt=dt)
        try:
            self.noise = estimate_noise(t, y, r.t_start, r.tau_exp)
        except ValueError as exc:
            raise DiscrepancyError(str(exc)) from exc
        self.t, self.y = t, y
        self.lik = BinnedLikelihood(t, y, self.noise,
                                    make_bins(t, r.t_start, resolution=settings.resolution))
        self.log_n = math.log(t.size)
        wall = settings.wall_temperature or settings.initial_temperature
        self.rig = RigInfo(volume=settings.volume,
                           initial_temperature=settings.initial_temperature,
                           wall_temperature=wall,
                           length_diameter_ratio=settings.length_diameter_ratio,
                           atmosphere=settings.atmosphere,
                           gas=Gas(gas_constant=settings.gas_constant, gamma=settings.gamma),
                           fit_wall_temperature=settings.fit_wall_temperature)

    def spec(self, effects: tuple[str, ...]) -> ModelSpec:
        """Model spec with these effects."""
        return ModelSpec(effects, self.rig, self.start)

    def residuals(self, spec: ModelSpec, x: FloatArray) -> FloatArray:
        """Normalised prewhitened binned residuals at scaled coordinates x [-]."""
        try:
            m = spec.signal(spec.to_theta(x), self.t)
        except (ValueError, ArithmeticError):
            return np.full(self.lik.n_bins, 1e6)
        z = self.lik.residuals(m)
        if not np.all(np.isfinite(z)) or float(np.max(np.abs(z))) > 1e12:
            return np.full(self.lik.n_bins, 1e6)
        return z

    def fit(self, spec: ModelSpec, starts: list[FloatArray], *, screen_nfev: int = 12,
            max_nfev: int = 200, fixed: dict[int, float] | None = None) -> Fit:
        """Multi-start least squares: screen every start briefly, polish the best.

        Parameters
        ----------
        spec : ModelSpec
            Model.
        starts : list of ndarray
            Starting scaled coordinates.
        screen_nfev, max_nfev : int
            Evaluations for screening each start and for polishing the best [-].
        fixed : dict, optional
            Coordinates held fixed (index -> scaled value), for profiles.
        """
        lo, hi = spec.bounds(float(self.t[0]), float(self.t[-1]))
        fixed = fixed or {}
        free = np.array([i for i in range(spec.k) if i not in fixed], dtype=int)

        def full(xf: FloatArray) -> FloatArray:
            x = np.empty(spec.k)
            x[free] = xf
            for i, v in fixed.items():
                x[i] = v
            return x

        def fun(xf: FloatArray) -> FloatArray:
            return self.residuals(spec, full(xf))

        eps = 1e-9 * (hi - lo)
        lo_f, hi_f = lo[free] + 0 * eps[free], hi[free]
        best = None
        nfev = 0
        cands = []
        for x0 in starts:
            x0 = np.clip(np.asarray(x0, dtype=float), lo + eps, hi - eps)[free]
            if len(starts) > 1:
                sol = least_squares(fun, x0, bounds=(lo_f, hi_f), method="trf",
                                    diff_step=DIFF_STEP, max_nfev=screen_nfev, x_scale=1.0)
                nfev += sol.nfev * (free.size + 1)
                cands.append((float(sol.cost), sol.x))
            else:
                cands.append((math.inf, x0))
        cands.sort(key=lambda c: c[0])
        sol = least_squares(fun, cands[0][1], bounds=(lo_f, hi_f), method="trf",
                            diff_step=DIFF_STEP, max_nfev=max_nfev, x_scale=1.0)
        nfev += sol.nfev * (free.size + 1)
        best = sol
        x = full(best.x)
        chi2 = float(2.0 * best.cost)
        jac = np.zeros((best.jac.shape[0], spec.k))
        jac[:, free] = best.jac
        return Fit(spec=spec, x=x, theta=spec.to_theta(x), chi2=chi2,
                   bic=chi2 + spec.k * self.log_n, jac=jac, success=bool(best.success),
                   nfev=nfev)

    # starting points ----------------------------------------------------------------
    def null_start(self, effect: str) -> dict[str, float]:
        """Effect parameters that make the effect negligible (the nested baseline) [SI]."""
        s = self.start
        table = {
            "heat_transfer": {"tau_heat": 1e3 * s.tau},
            "valve_opening": {"t_ramp": 0.3 * s.dt},
            "sensor_lag": {"tau_sensor": 0.1 * s.dt},
            "leak": {"leak_fraction": 1e-4},
            "pipe_volume": {"pipe_volume_ratio": 2e-4, "pipe_conductance_ratio": 5e3},
            "sensor_offset": {"offset": 0.0},
            "sensor_gain": {"gain": 0.0},
        }
        out = dict(table[effect])
        if effect == "heat_transfer" and self.rig.fit_wall_temperature:
            out["t_wall"] = self.rig.wall_temperature
        return out

    def effect_starts(self, effect: str) -> list[dict[str, float]]:
        """Starting values of an effect's parameters (small and large) [SI units]."""
        s = self.start
        fast = [max(3.0 * s.dt, 0.01 * s.tau), max(10.0 * s.dt, 0.1 * s.tau)]
        table: dict[str, list[dict[str, float]]] = {
            "heat_transfer": [{"tau_heat": 0.7 * s.tau}, {"tau_heat": 7.0 * s.tau}],
            "valve_opening": [{"t_ramp": v} for v in fast],
            "sensor_lag": [{"tau_sensor": v} for v in fast],
            "leak": [{"leak_fraction": 0.03}, {"leak_fraction": 0.2}],
            "pipe_volume": [{"pipe_volume_ratio": 0.1, "pipe_conductance_ratio": 5.0},
                            {"pipe_volume_ratio": 0.3, "pipe_conductance_ratio": 1.5}],
            "sensor_offset": [{"offset": 0.0}],
            "sensor_gain": [{"gain": 0.0}],
        }
        out = table[effect]
        if effect == "heat_transfer" and self.rig.fit_wall_temperature:
            out = [{**d, "t_wall": self.rig.wall_temperature} for d in out]
        return out

    def neutral_theta(self, b: float = 0.4) -> dict[str, float]:
        """Baseline parameters from the unloading-time estimate [SI units]."""
        s = self.start
        th = {"C": s.conductance, "b": b, "t_open": s.t_open, "p10": s.p10}
        if self.rig.atmosphere is None:
            th["p_atm"] = s.p_atm
        return th

    def starts_for(self, spec: ModelSpec, bases: list[dict[str, float]],
                   new_effects: tuple[str, ...]) -> list[FloatArray]:
        """Starting coordinates: each base combined with each start of the new effects."""
        combos: list[dict[str, float]] = [{}]
        for e in new_effects:
            combos = [{**c, **d} for c in combos for d in self.effect_starts(e)]
        out = []
        for base in bases:
            for c in combos:
                th = {**base, **c}
                out.append(spec.to_x(th))
        return out


def _covariance(fit: Fit) -> FloatArray:
    """Covariance of the scaled coordinates (inflated by chi2/dof when above 1)."""
    j = fit.jac
    dof = max(j.shape[0] - fit.spec.k, 1)
    s2 = max(1.0, fit.chi2 / dof)
    return np.linalg.pinv(j.T @ j) * s2


# ------------------------------------------------------------------------- diagnostics
def diagnose(prob: Problem, fit: Fit) -> tuple[Diagnostics, FloatArray]:
    """Diagnostics of a fitted model and its noise-free signal [Pa].

    Parameters
    ----------
    prob : Problem
        The trace.
    fit : Fit
        The fitted model.
    """
    th = fit.theta
    m = fit.spec.signal(th, prob.t)
    r = prob.y - m
    sigma = prob.noise.sigma
    rms = float(np.sqrt(np.mean(r * r)))
    z = prob.lik.residuals(m)
    _, p_lb = ljung_box(z)
    # phases from the model's true pressure
    cfg = fit.spec.config(th)
    p_true = m if not fit.spec.effects else None
    if p_true is None:
        from pneumatic_unload.discrepancy.candidates import fast_discharge

        p_true = fast_discharge(cfg, prob.t, th["t_open"])[0]
    p_atm, b, p10 = cfg.atmosphere, cfg.critical_ratio, cfg.initial_pressure
    pre = prob.t < th["t_open"]
    plateau = ~pre & (p_true - p_atm < 0.002 * (p10 - p_atm))
    choked = ~pre & ~plateau & (p_true * b >= p_atm)
    subsonic = ~pre & ~plateau & ~choked
    phases = {}
    for name, sel in (("pre-step", pre), ("choked", choked), ("subsonic", subsonic),
                      ("plateau", plateau)):
        k = int(np.count_nonzero(sel))
        if k:
            rr = r[sel]
            phases[name] = {"samples": k, "mean": float(np.mean(rr)),
                            "rms": float(np.sqrt(np.mean(rr * rr))),
                            "nrms": float(np.sqrt(np.mean(rr * rr)) / sigma)}
    # correlation of the binned residual with pressure and rate
    e = prob.lik.edges
    cnt = prob.lik.counts
    rb = np.add.reduceat(r, e[:-1]) / cnt
    pb = np.add.reduceat(m, e[:-1]) / cnt
    tb = np.add.reduceat(prob.t, e[:-1]) / cnt
    rate = np.gradient(pb, tb) if pb.size > 2 else np.zeros_like(pb)

    def corr(a: FloatArray, b_: FloatArray) -> float:
        if a.size < 3 or np.std(a) == 0 or np.std(b_) == 0:
            return math.nan
        return float(np.corrcoef(a, b_)[0, 1])

    d = Diagnostics(rms=rms, nrms=rms / sigma, ljung_box_p=p_lb,
                    white=bool(math.isfinite(p_lb) and p_lb >= WHITE_P), phases=phases,
                    corr_pressure=corr(rb, pb), corr_rate=corr(rb, rate))
    return d, m


# ------------------------------------------------------------------------------ rounds
def run_round(prob: Problem, base: Fit, neutral: list[dict[str, float]],
              candidates: list[str]) -> dict[str, Fit]:
    """Fit every candidate added to ``base`` (multi-start) [-].

    Parameters
    ----------
    prob : Problem
        The trace.
    base : Fit
        Current model.
    neutral : list of dict
        Neutral starting values of the current model's parameters [SI units].
    candidates : list of str
        Effects to try.
    """
    out = {}
    for cand in candidates:
        effects = (*base.effects, cand)
        spec = prob.spec(effects)
        bases = [dict(base.theta), *neutral]
        starts = prob.starts_for(spec, bases, (cand,))
        if cand not in ("sensor_offset", "sensor_gain"):
            # the nested start: the current fit with the effect switched (almost) off, so
            # that the extended fit can never end worse than the model it extends
            starts.append(spec.to_x({**base.theta, **prob.null_start(cand)}))
        out[cand] = prob.fit(spec, starts)
    return out


def decide(base: Fit, fits: dict[str, Fit], threshold: float
           ) -> tuple[dict[str, float], str, list[str]]:
    """Delta-BIC per candidate, winner ('none' if no claim) and its ambiguity set."""
    delta = {k: base.bic - f.bic for k, f in fits.items()}
    if not delta:
        return delta, "none", []
    order = sorted(delta, key=lambda k: -delta[k])
    win = order[0]
    if delta[win] <= threshold:
        return delta, "none", []
    amb = [k for k in order[1:] if delta[win] - delta[k] <= threshold]
    return delta, win, amb


# ------------------------------------------------------------------------------ intervals
def intervals(prob: Problem, fit: Fit, names: list[str], *, profile: bool = True
              ) -> dict[str, Interval]:
    """95 % intervals of the named parameters of a fit.

    The linear (Jacobian) interval is checked by refitting with the parameter held at
    each end: when the chi^2 increase there is not close to 3.84, the profile likelihood
    interval is computed instead. An end that does not close inside the parameter's range
    makes the parameter not identifiable.
    """
    spec = fit.spec
    cov = _covariance(fit)
    lo_b, hi_b = spec.bounds(float(prob.t[0]), float(prob.t[-1]))
    out = {}
    for name in names:
        i = spec.names.index(name)
        q = spec.params[i]
        se = math.sqrt(max(cov[i, i], 0.0))
        x0 = fit.x[i]
        ends = [x0 - 1.96 * se, x0 + 1.96 * se]
        method = "linear"
        ident = True
        if profile and spec.k > 1:
            ok = True
            for xe in ends:
                if not (lo_b[i] < xe < hi_b[i]) or se == 0 or not math.isfinite(se):
                    ok = False
                    break
                d = _profile_chi2(prob, fit, i, xe) - fit.chi2
                if not 0.6 * CHI2_95 <= d <= 1.5 * CHI2_95:
                    ok = False
                    break
            if not ok:
                method = "profile"
                ends = []
                for sgn in (-1.0, 1.0):
                    e, closed = _profile_end(prob, fit, i, sgn, se, lo_b[i], hi_b[i])
                    ends.append(e)
                    ident = ident and closed
        g = spec.centre[i] + spec.scale[i] * np.array(ends)
        vals = np.exp(g) if q.log else g
        value = fit.theta[name]
        low, high = float(vals[0]), float(vals[1])
        if method == "profile" and not ident:
            # an open end: report it as unbounded
            if not math.isfinite(ends[0]) or ends[0] <= lo_b[i] + 1e-9:
                low = 0.0 if q.log else -math.inf
            if not math.isfinite(ends[1]) or ends[1] >= hi_b[i] - 1e-9:
                high = math.inf
        if method == "linear" and q.log and se > 2.0:
            ident = False
        out[name] = Interval(value=value, low=low, high=high, unit=q.unit, method=method,
                             identifiable=ident, doc=q.doc)
    return out


def _profile_chi2(prob: Problem, fit: Fit, i: int, xi: float) -> float:
    """chi^2 of the fit with coordinate i held at xi, the others refitted [-]."""
    f = prob.fit(fit.spec, [fit.x], fixed={i: xi}, max_nfev=40)
    return f.chi2


def _profile_end(prob: Problem, fit: Fit, i: int, sgn: float, se: float, lo: float,
                 hi: float) -> tuple[float, bool]:
    """Profile-likelihood interval end on one side: (scaled value, closed?)."""
    x0 = fit.x[i]
    step = 1.96 * se if (math.isfinite(se) and se > 0) else 0.5
    step = float(np.clip(step, 0.05, 5.0))
    inside = x0
    outside = math.nan
    for _ in range(8):
        xe = x0 + sgn * step
        limit = hi if sgn > 0 else lo
        if (xe - limit) * sgn >= 0:
            xe = limit - sgn * 1e-6 * abs(hi - lo)
            d = _profile_chi2(prob, fit, i, xe) - fit.chi2
            if d < CHI2_95:
                return xe, False
            outside = xe
            break
        d = _profile_chi2(prob, fit, i, xe) - fit.chi2
        if d >= CHI2_95:
            outside = xe
            break
        inside = xe
        step *= 2.0
    if not math.isfinite(outside):
        return inside, False
    for _ in range(5):  # bisection
        mid = 0.5 * (inside + outside)
        d = _profile_chi2(prob, fit, i, mid) - fit.chi2
        if d >= CHI2_95:
            outside = mid
        else:
            inside = mid
    return 0.5 * (inside + outside), True


def geometry_factor_check(prob: Problem, fit: Fit) -> dict[str, Any]:
    """Identifiability of a constant geometric factor f on C from this one trace.

    The model depends on f and C only through f C, so the sensitivities of the trace to
    log f and to log C are computed and compared: a correlation of 1 means f is not
    identifiable from one trace (it needs several tank geometries).
    """
    spec = fit.spec
    i = spec.names.index("C")
    h = 1e-3
    z0 = prob.residuals(spec, fit.x)
    xc = fit.x.copy()
    xc[i] += h / spec.scale[i]
    dz_c = prob.residuals(spec, xc) - z0
    th = dict(fit.theta)
    th["C"] = th["C"] * math.exp(h)  # the factor f = e^h applied to C in the flow law
    dz_f = prob.lik.residuals(spec.signal(th, prob.t)) - z0
    num = float(dz_c @ dz_f)
    den = math.sqrt(float(dz_c @ dz_c) * float(dz_f @ dz_f))
    corr = num / den if den > 0 else math.nan
    return {"name": GEOMETRY_FACTOR, "identifiable": False,
            "sensitivity_correlation_with_C": corr,
            "reason": "a constant factor on C (the paper's L/D effect) changes the trace "
                      "exactly as C does (sensitivity correlation "
                      f"{corr:.6f}): not identifiable from one trace; give several runs "
                      "with different tank geometries (L/D) to identify a shared law"}


# ------------------------------------------------------------------------------ workflow
def find_discrepancy(t: FloatArray, p: FloatArray, settings: DiscrepancySettings, *,
                     temperature: tuple[FloatArray, FloatArray] | None = None
                     ) -> DiscrepancyResult:
    """Run the discrepancy workflow on one recorded discharge.

    Parameters
    ----------
    t : ndarray
        Sample instants [s] (any origin).
    p : ndarray
        Measured pressure [Pa absolute].
    settings : DiscrepancySettings
        Rig data and options.
    temperature : tuple of ndarray, optional
        Measured gas temperature (instants [s] on the same clock as t, values [K]): used
        as independent evidence for the heat-transfer effect, never in the fit.

    Returns
    -------
    DiscrepancyResult
        The named effect(s), the ambiguity set, the gap before and after, intervals.

    Raises
    ------
    DiscrepancyError
        No unload, non-finite samples, too short a trace.
    """
    t_wall0 = time.perf_counter()
    prob = Problem(t, p, settings)
    thr = settings.bic_threshold
    # 1. baseline, multi-start over b
    spec0 = prob.spec(())
    neutral = [prob.neutral_theta(0.3), prob.neutral_theta(0.5)]
    base = prob.fit(spec0, [spec0.to_x(th) for th in neutral])
    before, m_before = diagnose(prob, base)
    # 2-5. greedy rounds
    current = base
    current_diag = before
    claimed: list[str] = []
    rounds: list[Round] = []
    first_effect, first_amb = "none", []
    remaining = [c for c in settings.candidates]
    neutral_cur = [prob.neutral_theta(0.4)]
    while remaining and len(claimed) < settings.max_effects:
        if claimed and not current_diag.structured:
            break
        fits = run_round(prob, current, neutral_cur, remaining)
        delta, win, amb = decide(current, fits, thr)
        rounds.append(Round(base_effects=current.effects, base_bic=current.bic, fits=fits,
                            delta_bic=delta, winner=win, ambiguous_with=amb))
        if win == "none":
            break
        if not claimed:
            first_effect, first_amb = win, amb
        claimed.append(win)
        current = fits[win]
        # neutral starts of the next round: neutral baseline + this round's winner values
        neutral_cur = [{**th, **{k: v for k, v in current.theta.items() if k not in th}}
                       for th in neutral_cur]
        remaining = [c for c in remaining if c != win]
        current_diag, _ = diagnose(prob, current)
    after, m_after = diagnose(prob, current)
    names = [q.name for q in current.spec.params if q.name not in base.spec.names]
    params = intervals(prob, current, names, profile=settings.profile) if names else {}
    params.update(intervals(prob, current, ["C"], profile=False))
    extra = separating_data([first_effect, *first_amb]) if first_amb else []
    geo = geometry_factor_check(prob, current)
    notes = []
    if prob.noise.source == "differences":
        notes.append("no plateau long enough for the noise model: sigma from second "
                     "differences of the whole trace, rho assumed 0")
    verdict = _verdict(first_effect, first_amb, claimed, before, after, params)
    res = DiscrepancyResult(
        effect=first_effect, ambiguous_with=first_amb, effects=claimed, verdict=verdict,
        parameters=params, noise=prob.noise, baseline=base, final=current, rounds=rounds,
        before=before, after=after, extra_data=extra, geometry_factor=geo, t=prob.t,
        y=prob.y, model_before=m_before, model_after=m_after, t_ref=prob.t_ref,
        n_samples=prob.lik.n, n_bins=prob.lik.n_bins, elapsed=0.0, settings=settings,
        notes=notes)
    if temperature is not None:
        res.t_temperature = np.asarray(temperature[0], dtype=float) - prob.t_ref
        res.temperature = np.asarray(temperature[1], dtype=float)
        res.temperature_check = temperature_check(prob, base, current, res.t_temperature,
                                                  res.temperature)
    res.elapsed = time.perf_counter() - t_wall0
    return res


def _verdict(effect: str, amb: list[str], claimed: list[str], before: Diagnostics,
             after: Diagnostics, params: dict[str, Interval]) -> str:
    if effect == "none":
        if before.structured:
            return ("the baseline leaves a structured residual but no candidate effect "
                    "explains it better by the BIC threshold")
        return "no discrepancy: the baseline model explains the trace within noise"
    txt = f"missing effect: {effect}" if not amb else \
        f"missing effect: one of {', '.join([effect, *amb])} (the data cannot tell them apart)"
    if len(claimed) > 1:
        txt += f"; added greedily: {', '.join(claimed)}"
    txt += (f"; RMS {before.rms:.4g} Pa -> {after.rms:.4g} Pa "
            f"(normalised {before.nrms:.3f} -> {after.nrms:.3f})")
    bad = [k for k, v in params.items() if not v.identifiable]
    if bad:
        txt += f"; not identifiable: {', '.join(bad)}"
    return txt


def temperature_check(prob: Problem, base: Fit, final: Fit, t_meas: FloatArray,
                      temp_meas: FloatArray) -> dict[str, Any]:
    """Compare a measured gas temperature with the baseline and final models [K].

    The measured temperature is not used in any fit, so agreement is independent evidence
    for (or against) the heat-transfer effect fitted on the pressure alone.
    """
    sel = (t_meas >= prob.t[0]) & (t_meas <= prob.t[-1])
    if np.count_nonzero(sel) < 3:
        return {"available": False, "reason": "no temperature samples inside the trace"}
    tm, Tm = t_meas[sel], temp_meas[sel]
    out: dict[str, Any] = {"available": True, "samples": int(tm.size),
                           "measured_min": float(np.min(Tm)),
                           "measured_start": float(Tm[0])}
    for label, f in (("baseline", base), ("final", final)):
        Tmod = f.spec.temperature(f.theta, tm)
        d = Tmod - Tm
        out[label] = {"rms": float(np.sqrt(np.mean(d * d))), "mean": float(np.mean(d)),
                      "min_model": float(np.min(Tmod))}
    heat = "heat_transfer" in final.effects
    better = out["final"]["rms"] < out["baseline"]["rms"]
    out["heat_transfer_fitted"] = heat
    out["agrees"] = bool(heat and better)
    out["summary"] = (
        ("the measured gas temperature is closer to the model with the fitted heat "
         "transfer" if better else "the measured gas temperature does NOT support the "
         "fitted model better than the adiabatic baseline")
        + f" (rms {out['baseline']['rms']:.2f} K adiabatic vs {out['final']['rms']:.2f} K "
          f"final model; measured minimum {out['measured_min']:.1f} K, adiabatic model "
          f"minimum {out['baseline']['min_model']:.1f} K, final model minimum "
          f"{out['final']['min_model']:.1f} K)")
    return out


def find_discrepancy_runs(traces: list[tuple[FloatArray, FloatArray]],
                          settings: list[DiscrepancySettings]) -> tuple[
                              list[DiscrepancyResult], Any]:
    """Run the workflow on several runs and fit the shared geometry law of C.

    Parameters
    ----------
    traces : list of (t [s], p [Pa absolute])
        One trace per run.
    settings : list of DiscrepancySettings
        One per run (their ``length_diameter_ratio`` are the tank geometries).

    Returns
    -------
    tuple
        (per-run results, :class:`~pneumatic_unload.discrepancy.multirun.GeometryLaw`).
    """
    from pneumatic_unload.discrepancy.multirun import fit_geometry_law

    if len(traces) != len(settings) or not traces:
        raise DiscrepancyError("one settings object per trace is needed")
    results = [find_discrepancy(t, p, s) for (t, p), s in zip(traces, settings, strict=True)]
    law = fit_geometry_law([s.length_diameter_ratio for s in settings],
                           [r.conductance for r in results],
                           [r.conductance_std() for r in results])
    return results, law
