# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Types of the discrepancy workflow: settings, fits, diagnostics, rounds and the result.

SI units throughout: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config import EFFECTS, TankSpec
from pneumatic_unload.config.estimator import MODEL_UNCERTAINTY, supply_gas_temperature
from pneumatic_unload.config.fields import (
    ConfigError,
    choice,
    flag,
    integer,
    names,
    number,
    optional,
    validate,
)

if TYPE_CHECKING:  # annotations only: the settings stay importable without the engine
    from pneumatic_unload.fit.lsq import FitResult
    from pneumatic_unload.fit.noise import NoiseModel
    from pneumatic_unload.fit.profile import Interval
    from pneumatic_unload.model.parametric import ParametricModel

FloatArray = NDArray[np.float64]

#: Ljung-Box p-value below which a residual is called structured [-].
WHITE_P = 0.01
#: Normalised RMS above which a residual is called structured [-].
NRMS_LIMIT = 1.02
#: Candidate effects of the search: the configuration's effects, the hot start (heat
#: transfer with the wall temperature fitted) and the component's subsonic index m (the
#: ISO 6358-1:2013 law's, held at 0.5 in the baseline; :data:`pneumatic_unload.model.
#: effects.CANDIDATES`, spelled here so that the settings stay importable without the
#: engine).
CANDIDATES: tuple[str, ...] = (*EFFECTS, "hot_start", "subsonic_index")
#: How to read a delta-BIC (for reports).
BIC_HELP = ("delta-BIC = BIC(current model) - BIC(current model + candidate), BIC = chi^2 + "
            "k ln(n): positive means the candidate explains the trace better after paying "
            "for its extra parameters. An effect is claimed above 10 and named alone when "
            "the runner-up is more than 10 behind (a variant of the same leak in another "
            "law or place: when its chi^2 is more than 10 above).")


class DiscrepancyError(ValueError):
    """Input the workflow cannot analyse: no unload, non-finite samples, too short..."""


@dataclass(frozen=True)
class DiscrepancySettings(TankSpec):
    """Settings of :func:`~pneumatic_unload.discrepancy.workflow.find_discrepancy`: the tank
    and gas (:class:`~pneumatic_unload.config.tank.TankSpec`; ``atmosphere`` None: fitted,
    offset and gain then become hard to tell from p_atm and p10) and these.

    Attributes
    ----------
    fit_wall_temperature : bool
        Fit the wall temperature together with the heat transfer (when the gas starts
        warmer or colder than the wall, e.g. just after charging).
    candidates : tuple of str
        Effects tried (default all of :data:`CANDIDATES`: the configuration's effects and
        ``hot_start``; with ``fit_wall_temperature`` the hot start is heat_transfer).
    max_effects : int
        At most this many effects are added (greedy) [-].
    bic_threshold : float
        Delta-BIC needed to claim an effect and to name it alone [-].
    profile : bool
        Check the linear intervals with the profile likelihood.
    resolution : float
        Relative bin width of the likelihood [-] (smaller: slower, a little more power).
    model_uncertainty : float
        Relative standard uncertainty of the model-based C from the discharge model's own
        limits [-], as the estimator's (default
        :data:`~pneumatic_unload.config.estimator.MODEL_UNCERTAINTY`, 0.34 %, the RMS error
        of the model C against the HydDown peer simulator; 0 only for data made by the
        package's own model): in
        :meth:`DiscrepancyResult.conductance_std` and the C range, through the budget's
        model-limits term (:func:`pneumatic_unload.uncertainty.budget.model_limits_term`).
    length_diameter_known : bool
        The tank's L/D (``length_diameter_ratio``) is stated. False (the command line
        without ``--length-diameter-ratio``): the default L/D is a guess, and the natural
        heat laws are also fitted at L/D 1 to 7.6, both in the test of a further effect
        (:func:`~pneumatic_unload.discrepancy.laws.law_refusals`) and for the final
        model (:func:`~pneumatic_unload.discrepancy.laws.length_diameter_choice`): the
        L/D that fits best by the BIC threshold is taken, those within it that give
        another C enter the C range, and stating the L/D is the advice.
    time_limit : float or None
        Wall-clock cap of the fits [s] (None: none); see
        :func:`~pneumatic_unload.discrepancy.workflow.find_discrepancy` for what happens
        when it is reached.
    direction : str
        'discharge' (the tank empties through the component) or 'charge' (it fills from a
        supply at ``supply_pressure``, ``supply_temperature``: the model's charge, with
        the effects a charge takes, :data:`~pneumatic_unload.model.parametric.
        CHARGE_FIT_EFFECTS`; ``atmosphere`` is then the room's).
    supply_pressure : float or None
        A charge's supply pressure p_s [Pa absolute] (None: fitted, as p_atm is when
        ``atmosphere`` is None).
    supply_temperature : float or None
        A charge's supply gas temperature T_s [K] (None: the wall's where given, else
        293.15 K).
    start_time : float or None
        Valve opening instant in the record's clock [s] for a record that begins at the
        opening (no plateau before its fall): the unload is located from there, as
        ``analyze --start-time`` does (:mod:`pneumatic_unload.estimation.sparse`; needs
        ``atmosphere``), not detected (None: detected; a record without a plateau whose
        fall is under way at its first sample is then refused).
    """

    fit_wall_temperature: bool = flag(False, "fit the wall temperature with heat transfer")
    candidates: tuple[str, ...] = names(CANDIDATES, CANDIDATES, "candidate effects tried")
    max_effects: int = integer(3, 1, 3, "at most this many effects are added")
    bic_threshold: float = number(10.0, "-", 0.0, 1e6,
                                  "delta-BIC needed to claim an effect and to name it alone")
    profile: bool = flag(True, "check the linear intervals with profile likelihoods")
    resolution: float = number(0.03, "-", 1e-3, 0.5, "relative bin width of the likelihood")
    model_uncertainty: float = number(
        MODEL_UNCERTAINTY, "-", 0.0, 0.5, "relative standard uncertainty of the "
        "model-based C from the model's own limits (ideal gas, uniform state, heat-law "
        "family)")
    length_diameter_known: bool = flag(True, "the tank's L/D is stated (False: the "
                                       "natural heat law is also fitted at L/D 1-7.6)")
    time_limit: float | None = optional(
        600.0, "s", 1.0, 1e6, "wall-clock cap of the search: the fit under way stops at "
        "its next model evaluation (round 1 unfinished: an error; later: the effects "
        "named so far)",
        none="no cap")
    direction: str = choice("discharge", ("discharge", "charge"),
                            "flow direction: the tank empties (discharge) or fills (charge)")
    supply_pressure: float | None = optional(
        None, "Pa", 1e3, 5e7, "a charge's supply pressure p_s (absolute)", "fitted")
    supply_temperature: float | None = optional(
        None, "K", 150.0, 600.0, "a charge's supply gas temperature T_s",
        "the wall's where given, else 293.15 K")
    start_time: float | None = optional(
        None, "s", -1e10, 1e10, "valve opening instant in the record's clock (its time "
        "stamps), for records that begin at the opening (no plateau): the start is not "
        "detected", "detected")

    def __post_init__(self) -> None:
        """Validate (raises :class:`DiscrepancyError` with the reason)."""
        try:
            validate(self)
        except ConfigError as exc:
            msg = str(exc).replace("unknown candidates", "unknown candidate effect(s)")
            raise DiscrepancyError(msg) from exc
        if self.direction == "discharge" and (self.supply_pressure is not None
                                              or self.supply_temperature is not None):
            raise DiscrepancyError("supply_pressure and supply_temperature are a charge's "
                                   "(direction 'charge')")

    @property
    def charge(self) -> tuple[float | None, float] | None:
        """A charge's supply as the model takes it ((p_s [Pa] or None: fitted, T_s [K]));
        None for a discharge."""
        if self.direction != "charge":
            return None
        return self.supply_pressure, supply_gas_temperature(self.supply_temperature,
                                                            self.wall_temperature)

    @property
    def end_fitted(self) -> bool:
        """The end level the pressure tends to (the room's, a charge's supply) is a
        parameter of the fits: not given."""
        return (self.atmosphere if self.direction == "discharge"
                else self.supply_pressure) is None


@dataclass
class Fit:
    """A fitted model: the parametric model and the engine's result.

    Attributes
    ----------
    model : ParametricModel
        Model (effects, heat law, parameters).
    result : FitResult
        The engine's fit (values, chi^2, Jacobian).
    """

    model: ParametricModel
    result: FitResult

    @property
    def effects(self) -> tuple[str, ...]:
        """Effects of the model."""
        return self.model.effects

    @property
    def heat_law(self) -> str | None:
        """Heat-transfer law fitted (a key of
        :data:`~pneumatic_unload.model.effects.HEAT_VARIANTS`, the hot start's too), None
        without heat transfer."""
        return self.model.heat_law if "heat_transfer" in self.model.config_effects else None

    @property
    def theta(self) -> dict[str, float]:
        """Parameter values [SI units]."""
        return self.result.values

    @property
    def chi2(self) -> float:
        """-2 log-likelihood up to a constant [-]."""
        return self.result.chi2

    @property
    def bic(self) -> float:
        """chi2 + k ln(n) [-]."""
        return self.result.bic

    @property
    def k(self) -> int:
        """Free parameters [-]."""
        return self.result.k

    def covariance(self) -> FloatArray:
        """Covariance of the scaled coordinates (inflated by chi2/dof when above 1)."""
        return self.result.covariance(max(1.0, self.result.chi2 / self.result.dof))

    def std(self, name: str) -> float:
        """1-sigma of a free parameter [unit] from :meth:`covariance`."""
        cov = self.covariance()
        i = self.result.params.free.index(name)
        v = float(cov[i, i])
        return self.result.params.value_std(name, self.theta[name],
                                            math.sqrt(v) if v >= 0 else math.nan)


def interval_dict(iv: Interval) -> dict[str, Any]:
    """JSON-ready dict of an interval: an end that is not known (or not finite) is None;
    ``reason`` says in words why a parameter is not identifiable and what would identify
    it ('' when it is); ``computed`` False: no interval could be computed (a failure of
    the computation, not a property of the record)."""
    def f(v: float) -> float | None:
        return v if math.isfinite(v) else None
    return {"value": iv.value, "ci_low": f(iv.low), "ci_high": f(iv.high), "unit": iv.unit,
            "method": iv.method, "identifiable": iv.identifiable, "reason": iv.reason,
            "computed": iv.computed, "doc": iv.doc}


@dataclass
class Diagnostics:
    """How well a model explains the trace.

    Attributes
    ----------
    rms : float
        Root mean square of the residual y - model [Pa].
    nrms : float
        RMS of the prewhitened residual over the innovation sigma
        (:func:`~pneumatic_unload.fit.noise.normalised_rms`; rms / sigma for white noise)
        [-] (1 when the gap is within noise).
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
    base : Fit or None
        The model the candidates were added to, fitted with this round's noise model
        (a further round refits the noise on the residual of the effects named).
    noise_source : str
        Where this round's noise model comes from.
    refused : dict
        Candidates that beat the base but were not claimed -> the reason (a transducer
        effect without evidence a physics effect cannot give).
    """

    base_effects: tuple[str, ...]
    base_bic: float
    fits: dict[str, Fit]
    delta_bic: dict[str, float]
    winner: str
    ambiguous_with: list[str]
    base: Fit | None = None
    noise_source: str = ""
    refused: dict[str, str] = field(default_factory=dict)


@dataclass
class DiscrepancyResult:
    """Outcome of the workflow on one trace (SI units).

    ``effect`` is the first effect claimed ('none' when the baseline explains the trace
    within noise), ``ambiguous_with`` the effects the data cannot tell from it, and
    ``effects`` all effects added greedily (the final model's: of a round whose candidates
    the data cannot tell apart, the best one, which stands for the set only so that the
    search can go on); :attr:`named` the effects the data name, each told apart from every
    other candidate of its round. ``before``/``after`` are the diagnostics of the baseline
    and of the final model.
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
    #: The logged gas temperature's verdict on the final model and C's ambiguity
    #: members, each fitted jointly with it
    #: (:func:`~pneumatic_unload.discrepancy.thermo.judge`); None without a log.
    temperature_joint: dict[str, Any] | None = None
    settings: DiscrepancySettings | None = None
    notes: list[str] = field(default_factory=list)
    #: The C range: models that fit about equally with different C (and, apart, the bound
    #: of a leak in parallel with the component); a
    #: :class:`~pneumatic_unload.discrepancy.ambiguity.ConductanceAmbiguity` (its
    #: ``ambiguous`` says whether another model competes). None only when not computed.
    conductance_ambiguity: Any = None

    @property
    def conductance_range(self) -> tuple[float, float] | None:
        """Range of C the data allow [m^3/(s Pa)]: the 3-sigma intervals of the final
        model and of the models that fit about equally (None only when not computed). A
        leak in parallel with the component, which no record bounds, is stated apart
        (``conductance_ambiguity.parallel_low``)."""
        a = self.conductance_ambiguity
        return None if a is None else (a.low, a.high)

    @property
    def named(self) -> list[str]:
        """Effects claimed: the winner of each round whose runner-up is more than the BIC
        threshold behind. A round that ends in an ambiguity names none of its members (the
        verdict lists them, with the measurement that separates them); its best member is
        in :attr:`effects` and the final model only to stand for the set."""
        return [r.winner for r in self.rounds if r.winner != "none" and not r.ambiguous_with]

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
        """1-sigma of C of the final model [m^3/(s Pa)]: the noise's (from the Jacobian,
        :meth:`conductance_std_noise`) and the model limits' (the budget's term,
        ``settings.model_uncertainty`` times C) combined."""
        from pneumatic_unload.uncertainty.budget import model_limits_term  # the settings stay light

        u = self.settings.model_uncertainty if self.settings is not None else 0.0
        return math.hypot(self.conductance_std_noise(),
                          model_limits_term(self.conductance, u).std)

    def conductance_std_noise(self) -> float:
        """1-sigma of C of the final model from the noise alone (Jacobian) [m^3/(s Pa)]."""
        return self.final.std("C")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the ``--json`` output)."""
        def theta(f: Fit) -> dict[str, Any]:
            return {"effects": list(f.effects), "heat_law": f.heat_law,
                    "parameters": dict(f.theta), "chi2": f.chi2, "bic": f.bic, "k": f.k}

        charge = self.settings is not None and self.settings.charge is not None
        return finite_json({
            "direction": "charge" if charge else "discharge",
            "supply_pressure": self.final.model.config(self.final.theta).supply_pressure
            if charge else None,
            "effect": self.effect, "ambiguous_with": list(self.ambiguous_with),
            "effects": list(self.effects), "named": self.named, "verdict": self.verdict,
            "parameters": {k: interval_dict(v) for k, v in self.parameters.items()},
            "rms_before": self.rms_before, "rms_after": self.rms_after,
            "nrms_before": self.before.nrms, "nrms_after": self.after.nrms,
            "white_before": self.before.white, "white_after": self.after.white,
            "delta_bic": self.delta_bic,
            "rounds": [{"base_effects": list(r.base_effects), "delta_bic": r.delta_bic,
                        "winner": r.winner, "ambiguous_with": r.ambiguous_with,
                        "noise_source": r.noise_source, "refused": r.refused}
                       for r in self.rounds],
            "noise": self.noise.to_dict(),
            "baseline": theta(self.baseline), "final_model": theta(self.final),
            "conductance": self.conductance, "conductance_std": self.conductance_std(),
            "conductance_std_noise": self.conductance_std_noise(),
            "conductance_range": None if self.conductance_ambiguity is None
            else self.conductance_ambiguity.to_dict(),
            "diagnostics_before": self.before.to_dict(),
            "diagnostics_after": self.after.to_dict(),
            "extra_data": self.extra_data, "geometry_factor": self.geometry_factor,
            "temperature_check": self.temperature_check,
            "temperature_joint": self.temperature_joint,
            "samples": self.n_samples, "bins": self.n_bins, "elapsed_s": self.elapsed,
            "notes": self.notes,
        })


def finite_json(o: Any) -> Any:
    """Replace non-finite floats by None, recursively (strict JSON)."""
    if isinstance(o, dict):
        return {k: finite_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [finite_json(v) for v in o]
    if isinstance(o, (float, np.floating)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, (np.integer, np.bool_)):
        return o.item()
    return o
