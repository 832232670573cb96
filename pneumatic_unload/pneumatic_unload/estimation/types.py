# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Types of the estimator: statuses, settings, results, diagnostics and its error (SI units).

Everything here is plain data: :class:`EstimatorSettings` (tank, gas and detection settings),
:class:`UnloadResult` (one analysed unload), :class:`Diagnostic` (a state change or an input
problem) and :class:`EstimationError` (input that cannot be analysed). SI units: s, Pa
absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Array of float64 samples (times [s], pressures [Pa] or signal units).
FloatArray = NDArray[np.float64]

#: Opening of every message about a transducer stuck during an unload (its value follows).
STUCK_TEXT = "sensor stuck at"
#: Openings of the 'bad_data' texts that are faults of the transducer or its clock (not of
#: the physics): a model must not be fitted through them.
SENSOR_FAULT_TEXTS = (STUCK_TEXT, "sensor saturated", "clock stepped")

#: Statuses of an :class:`UnloadResult` (same order as the message's STATUS_* constants:
#: a bag stores the index). Their meaning, and whether the result carries a C, is in
#: :data:`STATUS_MEANINGS`.
STATUSES = ("ok", "aborted_sse", "aborted", "ok_subsonic", "bad_data")

#: What each status word says, one line each (the docs' table of statuses is this one).
STATUS_MEANINGS: dict[str, str] = {
    "ok": "a good estimate: the flow stayed choked down to p*, as eq 39 assumes",
    "aborted_sse": "a good estimate: the valve closed before p*; C by the SSE method "
                   "(eq 23) from the pressure recovery after the closing",
    "aborted": "no estimate: the valve closed before p* and the recovery gives no C "
               "(status_text says why)",
    "ok_subsonic": "a good estimate: the flow turned subsonic before p* (p* < p_atm / b), "
                   "which eq 39 does not assume; the model-based C, which models the "
                   "subsonic flow, is the one to report",
    "bad_data": "no estimate: the record cannot be analysed (status_text says why)",
}

#: Former status words and the word that replaced them: a results database written by an
#: older version reads with the new word (``testline.db.unload_rows``; any other reader of
#: stored words calls :func:`canonical_status`). Bags store the index, not the word: they
#: need no alias.
STATUS_ALIASES: dict[str, str] = {"not_choked": "ok_subsonic"}

#: Statuses of a result that carries a C (see :func:`recommended`).
ESTIMATE_STATUSES = ("ok", "aborted_sse", "ok_subsonic")
#: The status of a result that gives no C (unusable data, or a C the record does not
#: determine: :mod:`.vetting`); its status text says why.
NO_RESULT_STATUS = "bad_data"


def canonical_status(word: str) -> str:
    """The current status word for ``word`` (a former word through :data:`STATUS_ALIASES`,
    any other word as it is)."""
    return STATUS_ALIASES.get(word, word)


@dataclass
class UnloadResult:
    """One unload analysed by the unloading-time method (all SI; NaN when unknown).

    ``conductance`` is the paper's eq 39 value, always reported as it is;
    ``conductance_model`` removes its known bias by inverting the discharge model at the
    measured crossing (``final=False``), or comes from the full-curve fit once the unload has
    ended (``final=True``).
    """

    #: Sequence number of this unload in the record or since the estimator started (0, 1,
    #: ...).
    index: int
    #: One of :data:`STATUSES` ('ok', 'aborted_sse', 'aborted', 'ok_subsonic', 'bad_data':
    #: :data:`STATUS_MEANINGS`); ``status_text`` gives the reason.
    status: str
    #: Why the status, in words (and what else was noticed: a gap in the samples, ...).
    status_text: str
    #: Detected start of the unload step (the valve opening) [s, the record's clock].
    t_start: float
    #: Instant of the p* crossing, where tau_exp ends [s, the record's clock].
    t_cross: float
    #: Experimental unloading time: from the unload's start to the p* crossing [s].
    tau_exp: float
    #: Standard uncertainty of ``tau_exp`` [s].
    tau_exp_std: float
    #: Initial tank pressure before the step [Pa absolute].
    p10: float
    #: Atmospheric (final) pressure [Pa absolute].
    p_atm: float
    #: Threshold p* = p_atm + 0.368 (p10 - p_atm) (eq 40) [Pa absolute].
    p_star: float
    #: Initial gas temperature T10 [K].
    initial_temperature: float
    #: Tank volume [m^3].
    volume: float
    #: Sonic conductance by the paper's eq 39 from tau_exp [m^3/(s Pa)] (biased by design).
    conductance: float
    #: Model-based sonic conductance, eq 39's bias removed [m^3/(s Pa)]: the value to report.
    conductance_model: float
    #: Combined standard uncertainty of ``conductance_model`` (GUM) [m^3/(s Pa)].
    conductance_model_std: float
    #: One standard deviation of ``conductance`` (eq 39) from the record and the stated
    #: inputs [m^3/(s Pa)]; eq 39's bias by design is not in it.
    conductance_std: float = math.nan
    #: Critical pressure ratio b [-]; NaN when not identifiable.
    critical_ratio: float = math.nan
    #: Standard deviation of ``critical_ratio`` [-].
    critical_ratio_std: float = math.nan
    #: C that makes the isentropic choked closed form (eq 22) reach p* at the measured
    #: crossing [m^3/(s Pa)].
    conductance_isentropic: float = math.nan
    #: Quality figure in [0, 1]: 1 = clean crossing, well-identified fit; 0 = unusable.
    quality: float = 0.0
    #: Method text, e.g. "eq39+isentropic-inversion+curve-fit".
    method: str = ""
    #: True for the final result (the full-curve fit, once the unload's tail is recorded);
    #: False for the estimate at the p* crossing.
    final: bool = False
    #: Standard deviation of the pressure noise before the step [Pa].
    noise_std: float = math.nan
    #: Index of the unload's first sample in the record (-1: not known).
    i_start: int = -1
    #: Index of the first sample at or after the p* crossing (-1: not known).
    i_cross: int = -1
    #: Index of the sample at which the crossing estimate was complete (-1: not known).
    i_complete: int = -1
    #: Time of that sample [s, the record's clock].
    t_complete: float = math.nan
    #: Time of the last sample of the unload's tail, where its final fit ends [s, the
    #: record's clock]; NaN before the tail is recorded.
    t_end: float = math.nan
    #: Details by name: the uncertainty budgets, the curve fit's results, the logged
    #: temperature's evidence (the JSON output takes some of them as keys of their own).
    extra: dict[str, Any] = field(default_factory=dict)
    #: Start instant of the fitted discharge model [s] (final results; NaN otherwise).
    t_start_model: float = math.nan
    #: tau_exp of the fitted model, its p* crossing from its start [s]: uses the whole curve,
    #: so it is less noisy than ``tau_exp`` (the paper's measurement, which it never replaces).
    tau_exp_model: float = math.nan
    #: ISO 6358-1:2013 subsonic index m of the final fit and its standard uncertainty [-]
    #: (fitted where the record determines it, else held at 0.5 with the uncertainty of the
    #: components' range; NaN before the final fit).
    subsonic_index: float = math.nan
    #: Standard uncertainty of ``subsonic_index`` [-].
    subsonic_index_std: float = math.nan
    #: The pressure transducer's zero offset fitted by the final fit and its 1-sigma [Pa]
    #: (NaN when not fitted: the record settles at the given p_atm, or p_atm was fitted).
    pressure_offset: float = math.nan
    #: Standard uncertainty (1-sigma) of ``pressure_offset`` [Pa].
    pressure_offset_std: float = math.nan
    #: 'discharge' (the tank emptied through the component) or 'charge' (it filled
    #: through it from a supply: ``p_atm`` is then the room's, NaN when not given).
    direction: str = "discharge"
    #: A charge's supply pressure p_s, given or its final plateau [Pa absolute] (NaN for
    #: a discharge).
    supply_pressure: float = math.nan

    @property
    def end_pressure(self) -> float:
        """The level the tank's pressure tends to [Pa absolute]: p_atm of a discharge,
        the supply of a charge."""
        return self.supply_pressure if self.direction == "charge" else self.p_atm

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


class Analysis(list[UnloadResult]):
    """The results of :func:`~pneumatic_unload.estimation.analyze`: a list of
    :class:`UnloadResult` in order, which also says why it is empty.

    Attributes
    ----------
    no_unload_reason : str or None
        Why the record gave no unload, with what would fix it where known (the words of
        ``pneumatic-unload analyze``; :func:`~pneumatic_unload.estimation.explain_no_unload`);
        None when an unload was found.
    diagnostics : list of Diagnostic
        The estimator's diagnostics on the record (dropped samples, warnings, errors).
    """

    def __init__(self, results: list[UnloadResult], *, no_unload_reason: str | None = None,
                 diagnostics: list[Diagnostic] | None = None) -> None:
        super().__init__(results)
        self.no_unload_reason = no_unload_reason
        self.diagnostics = list(diagnostics or [])


def estimate_fields(r: UnloadResult, frame_id: str = "tank") -> dict[str, Any]:
    """UnloadEstimate message fields of a result (stamps in ns, NaN kept)."""
    budget = r.extra.get("budget", {})

    def num(x: float | None) -> float:
        return math.nan if x is None else float(x)

    return {
        "header_stamp_ns": int(round(r.t_cross * 1e9)) if math.isfinite(r.t_cross)
        else int(round(r.t_complete * 1e9)),
        "frame_id": frame_id,
        "unload_start_ns": int(round(r.t_start * 1e9)) if math.isfinite(r.t_start) else 0,
        "unload_index": r.index, "status": STATUSES.index(r.status),
        "status_text": r.status_text, "method": r.method, "quality": r.quality,
        "conductance": r.conductance, "conductance_std": r.conductance_std,
        "conductance_model": r.conductance_model,
        "conductance_model_std": r.conductance_model_std,
        "conductance_model_std_type_a": num(budget.get("type_a_std")),
        "conductance_model_std_type_b": num(budget.get("type_b_std")),
        "conductance_model_std_model_form": num(budget.get("model_form_std")),
        "budget_largest": budget.get("largest", ""),
        "heat_law": r.extra.get("curve_fit", {}).get("heat_law", "") if r.final else "",
        "critical_ratio": r.critical_ratio, "critical_ratio_std": r.critical_ratio_std,
        "subsonic_index": r.subsonic_index, "subsonic_index_std": r.subsonic_index_std,
        "subsonic_index_fitted": bool(r.extra.get("curve_fit", {}).get(
            "subsonic_index_fitted", False)) if r.final else False,
        "pressure_offset": r.pressure_offset, "pressure_offset_std": r.pressure_offset_std,
        "tau_exp": r.tau_exp, "p10": r.p10, "p_atm": r.p_atm, "p_star": r.p_star,
        "direction": r.direction, "supply_pressure": r.supply_pressure,
        "initial_temperature": r.initial_temperature, "volume": r.volume,
    }


def end_fields(settings: Any, end: float) -> dict[str, Any]:
    """The fields of an :class:`UnloadResult` that the level ``end`` [Pa absolute] the
    pressure tends to fills: p_atm (a discharge), or the supply with the direction and the
    room's p_atm (``settings.atmosphere``, NaN when not given) for a charge."""
    if getattr(settings, "direction", "discharge") != "charge":
        return {"p_atm": end}
    room = settings.atmosphere
    return {"p_atm": math.nan if room is None else float(room), "supply_pressure": end,
            "direction": "charge"}


def recommended(r: UnloadResult) -> dict[str, Any]:
    """The one C to report for a result, with its combined and expanded (k = 2)
    uncertainty [m^3/(s Pa)] and where it comes from: the model-based C (curve fit or
    crossing inversion) when known, else eq 39's (biased by design: said so); none (NaN)
    for a result that gives no C (:data:`NO_RESULT_STATUS`)."""
    if r.status == NO_RESULT_STATUS:
        return {"conductance": math.nan, "std": math.nan, "expanded": math.nan,
                "coverage_factor": 2.0, "source": "no result (see the status text)"}
    if math.isfinite(r.conductance_model):
        source = "model-based C, full-curve fit" if r.final and not (
            r.extra or {}).get("curve_fit_error") else \
            "model-based C, inversion at the p* crossing"
        c, sd = r.conductance_model, r.conductance_model_std
    else:
        source = "eq 39 (no model-based value; eq 39 is biased by design, see method.md)"
        c, sd = r.conductance, r.conductance_std
    return {"conductance": c, "std": sd, "expanded": 2.0 * sd, "coverage_factor": 2.0,
            "source": source}


def combined_std_of(d: dict[str, Any]) -> float:
    """The combined standard uncertainty [m^3/(s Pa)] of a budget given as
    :meth:`~pneumatic_unload.uncertainty.budget.Budget.to_dict` (its None, not finite, as NaN)."""
    v = d["combined_std"]
    return math.nan if v is None else v


@dataclass(frozen=True)
class CrossingEstimate:
    """The numbers of a crossing estimate (see :func:`crossing_estimate`).

    Attributes
    ----------
    problem : str or None
        Why there is no model C (bad pressures, no crossing time, time running backwards).
    conductance, conductance_std : float
        eq 39's C and its combined 1-sigma [m^3/(s Pa)].
    conductance_isentropic : float
        The isentropic inversion's C [m^3/(s Pa)].
    conductance_model, conductance_model_std : float
        The model-based C and its combined 1-sigma [m^3/(s Pa)].
    method : str
        How the model-based C was computed.
    extra : dict
        The budgets ('budget', 'budget_eq39'), as
        :meth:`~pneumatic_unload.uncertainty.budget.Budget.to_dict`.
    """

    problem: str | None
    conductance: float
    conductance_std: float
    conductance_isentropic: float
    conductance_model: float
    conductance_model_std: float
    method: str
    extra: dict[str, Any]
