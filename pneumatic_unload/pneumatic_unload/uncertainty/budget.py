# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Uncertainty budget of a sonic conductance, in the manner of the GUM (ISO 6358-2's test).

A C from a tank discharge depends on what was measured in the record (type A: the noise,
AR(1)-corrected, through the crossing time or the curve fit) and on inputs stated by the
user, each with a standard uncertainty (type B): the tank volume V, the initial gas
temperature T10 (and the wall's, when a heat law was fitted), the pressure transducer
(an offset common to every reading) and a barometer's p_atm. A model-form term carries the
spread of heat laws that fit the record about equally well, and a model-limits term the
model's own simplifications (ideal gas, uniform state; calibrated against the HydDown peer
simulator, ``model_uncertainty``). The combined standard
uncertainty is the root sum of squares (the inputs are independent); the expanded one uses
k = 2 (about 95 %).

Sensitivities are first order and come from the exact isentropic inversion of the choked
discharge (:func:`pneumatic_unload.physics.conductance_isentropic_inversion`), the law that
carries the time scale V/(C sqrt(T10)) of every model of the package:

* V: dC/C = dV/V (the solution depends on t C/V);
* T10: dC/C = -dT10/(2 T10) (and on t C sqrt(T10));
* a transducer offset d moves p10 and the crossing level together (with p_atm measured by
  the same transducer or given, the crossing the estimator finds is the physical p* moved by
  d): dC = (dC/dp_cross + dC/dp10) d;
* p_atm given by a barometer: it moves p* and so the crossing, which the inversion follows
  exactly while the flow is choked (dC = 0); eq 39, whose formula holds p* fixed, moves;
* the wall temperature (heat laws only): given, it has ``temperature_uncertainty``; not
  given, it is assumed = T10 with the uncertainty the record allows (a default, widened
  when T10 is far from a room's temperature or a hot start is fitted:
  :func:`~pneumatic_unload.config.estimator.wall_uncertainty`); the line states
  ``|dC/dTw|``. At the crossing: the model-based inversion with the natural law, the wall moved
  by its uncertainty (:func:`wall_sensitivity`); for the curve fit's C with an assumed wall,
  the chosen law refitted with the wall moved (the fitted heat exchange takes up part of
  the move: :func:`pneumatic_unload.curvefit.fitting.fit_curve`); a wall fitted by a hot-start law
  is in the fit's type A line (the wall line then shows it with 0).

SI units: m^3/(s Pa) for C, m^3, K, Pa, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pneumatic_unload.config.estimator import (
    CHARGE_MODEL_UNCERTAINTY,
    MODEL_UNCERTAINTY,
    EstimatorSettings,
    probe_uncertainty,
    t10_uncertainty,
    wall_uncertainty,
    with_wall,
)
from pneumatic_unload.config.tank import wall_pair
from pneumatic_unload.model.inversion import invert_crossing
from pneumatic_unload.physics import conductance_eq39, conductance_isentropic_inversion

#: Name of the wall temperature's line in a budget.
WALL_TERM = "wall temperature"
#: Name of the model-form line (the heat laws' spread) of a model-based C's budget.
MODEL_FORM_TERM = "model form (heat laws)"
#: Coverage factor of the expanded uncertainty [-] (about 95 % for a normal distribution).
COVERAGE_FACTOR = 2.0
#: Default standard uncertainty of V, relative [-] (volume by water weighing or drawing).
VOLUME_REL_DEFAULT = 0.005
#: Default standard uncertainty of a pressure reading, relative to p10 [-] (0.1 % of
#: reading: an industrial transducer's accuracy class, as a 1-sigma offset).
PRESSURE_REL_DEFAULT = 0.001
#: Settings changes that state the inputs as exactly known and the data as made by the
#: package's own model (a simulation analysed with its own tank and gas): the budget keeps
#: the record's terms and the heat laws' spread only.
EXACT_INPUTS: dict[str, float] = {"volume_uncertainty": 0.0, "temperature_uncertainty": 0.0,
                                  "wall_temperature_uncertainty": 0.0,
                                  "pressure_uncertainty": 0.0, "atmosphere_uncertainty": 0.0,
                                  "charge_model_uncertainty": 0.0,
                                  "model_uncertainty": 0.0}
#: The stated inputs exact, the model's limits kept: a peer simulation (HydDown) analysed
#: with its own tank and gas.
EXACT_INPUTS_FOREIGN_MODEL: dict[str, float] = {
    **EXACT_INPUTS, "model_uncertainty": MODEL_UNCERTAINTY,
    "charge_model_uncertainty": CHARGE_MODEL_UNCERTAINTY}


@dataclass(frozen=True)
class BudgetTerm:
    """One line of the budget.

    Attributes
    ----------
    name : str
        What the term is (e.g. 'volume V').
    kind : str
        'A' (from the record), 'B' (a stated input) or 'model' (model form).
    value : float
        The input's value used [unit] (NaN for type A and model terms).
    input_std : float
        Its standard uncertainty [unit] (NaN for type A and model terms).
    unit : str
        Unit of value and input_std.
    std : float
        Standard uncertainty it contributes to C [m^3/(s Pa)].
    note : str
        Where the input came from, or how the term was computed.
    """

    name: str
    kind: str
    value: float
    input_std: float
    unit: str
    std: float
    note: str = ""


@dataclass(frozen=True)
class Budget:
    """The uncertainty budget of one C.

    Attributes
    ----------
    value : float
        The C it belongs to [m^3/(s Pa)].
    terms : tuple of BudgetTerm
        The lines, in order: type A, type B, model form.
    """

    value: float
    terms: tuple[BudgetTerm, ...]

    @property
    def combined_std(self) -> float:
        """Combined standard uncertainty [m^3/(s Pa)] (root sum of squares)."""
        return math.sqrt(sum(t.std**2 for t in self.terms if math.isfinite(t.std)))

    def part_std(self, kind: str) -> float:
        """Root sum of squares of the terms of one kind ('A', 'B', 'model') [m^3/(s Pa)]."""
        return math.sqrt(sum(t.std**2 for t in self.terms
                             if t.kind == kind and math.isfinite(t.std)))

    @property
    def expanded(self) -> float:
        """Expanded uncertainty, k = :data:`COVERAGE_FACTOR` [m^3/(s Pa)]."""
        return COVERAGE_FACTOR * self.combined_std

    @property
    def largest(self) -> BudgetTerm:
        """The term contributing most."""
        return max(self.terms, key=lambda t: t.std if math.isfinite(t.std) else -1.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: value, combined, expanded (k), parts, largest term, the lines (NaN,
        not applicable, as None). One pass over the terms, the sums in the order of
        :attr:`combined_std` and :meth:`part_std` (it is on the live crossing's path)."""
        return _budget_dict(self.value, [(t.name, t.kind, t.std, _line(t))
                                         for t in self.terms])


def _line(t: BudgetTerm) -> dict[str, Any]:
    """A budget line as :meth:`Budget.to_dict` gives it (NaN as None)."""
    isfinite = math.isfinite
    value, input_std, std = t.value, t.input_std, t.std
    return {"name": t.name, "kind": t.kind,
            "value": value if not isinstance(value, float) or isfinite(value) else None,
            "input_std": input_std if isfinite(input_std) else None,
            "unit": t.unit, "std": std if isfinite(std) else None, "note": t.note}


def _budget_dict(value: float, rows: list[tuple[str, str, float, dict[str, Any]]]
                 ) -> dict[str, Any]:
    """:meth:`Budget.to_dict` of the lines ``rows`` (name, kind, std [m^3/(s Pa)], the
    line's dict) of the budget of C = ``value`` [m^3/(s Pa)]."""
    isfinite = math.isfinite
    total, parts = 0.0, {"A": 0.0, "B": 0.0, "model": 0.0}
    largest, big = "", -math.inf
    for name, kind, std, _d in rows:
        if isfinite(std):
            v = std**2
            total += v
            parts[kind] = parts.get(kind, 0.0) + v
            key = std
        else:
            key = -1.0
        if key > big:
            largest, big = name, key
    combined = math.sqrt(total)
    out = {"value": value, "combined_std": combined,
           "expanded": COVERAGE_FACTOR * combined, "coverage_factor": COVERAGE_FACTOR,
           "type_a_std": math.sqrt(parts["A"]), "type_b_std": math.sqrt(parts["B"]),
           "model_form_std": math.sqrt(parts["model"]), "largest": largest,
           "terms": [r[3] for r in rows]}
    for k in ("value", "combined_std", "expanded", "type_a_std", "type_b_std",
              "model_form_std"):
        if not isfinite(out[k]):
            out[k] = None
    return out


@dataclass(frozen=True)
class ScaledBudget:
    """A budget prepared before its C is known, for a C that differs only in scale.

    At fixed pressures (p10, p_atm, p*) every type B and model-limits line of a crossing's
    budget is proportional to C: the sensitivities come from eq 39 and the isentropic
    inversion, both exactly C = f(p10, p_atm, p*, V, T10) / tau, so that a relative
    sensitivity does not depend on tau. The live estimator computes the budget once, half
    way to p* (:func:`input_terms` at a reference C), and scales it at the crossing: a few
    microseconds instead of the formulae's hundred (issue #10's crossing latency).

    Attributes
    ----------
    ref : Budget
        The budget computed at the reference C (``ref.value``) [m^3/(s Pa)].
    free : tuple of str
        Names of the lines that are not proportional to C, given at :meth:`dict_at` (the
        type A line, the wall temperature's line).
    """

    ref: Budget
    free: tuple[str, ...]

    def __post_init__(self) -> None:
        # the reference's lines: name, kind, std, whether free, and the dict copied and
        # scaled by :meth:`dict_at`
        object.__setattr__(self, "_rows", [(t.name, t.kind, t.std, t.name in self.free,
                                            _line(t)) for t in self.ref.terms])

    def dict_at(self, c: float, given: dict[str, BudgetTerm | None]) -> dict[str, Any]:
        """The budget of ``c`` [m^3/(s Pa)] as :meth:`Budget.to_dict`: the proportional lines
        scaled from the reference, the free ones as ``given`` (None or absent: the line is
        left out); the lines' dicts copied from the reference's (the live crossing's path)."""
        k = abs(c) / abs(self.ref.value)
        rows = []
        for name, kind, std, free, template in self._rows:  # type: ignore[attr-defined]
            if free:
                g = given.get(name)
                if g is not None:
                    rows.append((g.name, g.kind, g.std, _line(g)))
            else:
                std = std * k
                line = template.copy()
                line["std"] = std if math.isfinite(std) else None
                rows.append((name, kind, std, line))
        return _budget_dict(c, rows)


def with_terms(d: dict[str, Any], terms: list[BudgetTerm]) -> dict[str, Any]:
    """A budget given as :meth:`Budget.to_dict` with further lines (e.g. one known only
    after the fit that produced it), its combined values recomputed."""
    old = [BudgetTerm(**{k: (math.nan if v is None and k in ("value", "input_std", "std")
                             else v) for k, v in t.items()}) for t in d["terms"]]
    return Budget(d["value"], tuple(old + list(terms))).to_dict()


def format_budget(d: dict[str, Any], unit: float = 1e-9,
                  unit_name: str = "1e-9 m^3/(s Pa)", symbol: str = "C") -> list[str]:
    """Text lines of a budget given as :meth:`Budget.to_dict`: one per term (its share of
    the variance, the input and its uncertainty), then the combined and expanded values."""
    var = d["combined_std"] ** 2 or 1.0
    out = []
    for t in d["terms"]:
        std = t["std"] if t["std"] is not None and math.isfinite(t["std"]) else 0.0
        value = "" if t["value"] is None else f"{t['value']:.6g} "
        given = "" if t["input_std"] is None or not math.isfinite(t["input_std"]) else \
            f"; {value}+- {t['input_std']:.3g} {t['unit']}"
        note = f" ({t['note']})" if t["note"] else ""
        out.append(f"    {t['kind']:5s} {t['name']:46s} {std / unit:9.4f}"
                   f"  {100 * std**2 / var:5.1f} %{given}{note}")
    rel = 100 * d["combined_std"] / d["value"] if d["value"] else math.nan
    out.append(f"    combined u({symbol}) = {d['combined_std'] / unit:.4f} {unit_name}"
               f" ({rel:.2f} %),"
               f" expanded U (k = {d['coverage_factor']:g}) = {d['expanded'] / unit:.4f};"
               f" largest: {d['largest']}")
    return out


def input_uncertainties(settings: EstimatorSettings, p10: float) -> dict[str, float]:
    """The stated (or default) standard uncertainties of the inputs [SI].

    Returns
    -------
    dict
        volume [m^3], temperature [K] (a probe's), initial_temperature [K] (T10's:
        ``t10_uncertainty``), pressure [Pa], atmosphere [Pa].
    """
    s = settings
    return {
        "volume": s.volume_uncertainty if s.volume_uncertainty is not None
        else VOLUME_REL_DEFAULT * s.volume,
        "temperature": probe_uncertainty(s),
        "initial_temperature": t10_uncertainty(s)[0],
        "pressure": s.pressure_uncertainty if s.pressure_uncertainty is not None
        else PRESSURE_REL_DEFAULT * p10,
        "atmosphere": s.atmosphere_uncertainty,
    }


def _isentropic(settings: EstimatorSettings, tau: float, p_cross: float, p10: float,
                t10: float | None = None, volume: float | None = None) -> float:
    return conductance_isentropic_inversion(
        tau, p_cross, p10, settings.volume if volume is None else volume,
        settings.initial_temperature if t10 is None else t10, settings.gas)


def input_terms(settings: EstimatorSettings, c: float, *, tau: float, p10: float,
                p_atm: float, p_star: float, atmosphere_measured: bool,
                wall_std: float = math.nan, eq39: bool = False,
                wall_input: tuple[float, str] | None = None) -> list[BudgetTerm]:
    """The type B lines of the budget of a C.

    Parameters
    ----------
    settings : EstimatorSettings
        The inputs (V, T10, wall temperature, p_atm) and their uncertainties.
    c : float
        The C whose budget this is [m^3/(s Pa)].
    tau : float
        Time from the start to the p* crossing [s].
    p10, p_atm, p_star : float
        Initial, atmospheric and crossing pressures [Pa absolute].
    atmosphere_measured : bool
        p_atm came from the record (its uncertainty is then type A, already counted).
    wall_std : float
        C's standard uncertainty from the wall temperature [m^3/(s Pa)] (see
        :func:`wall_sensitivity`); NaN: no heat law fitted, no term.
    eq39 : bool
        The budget of eq 39's C (its formula's own sensitivities) instead of the model's.
    wall_input : tuple, optional
        The wall temperature's standard uncertainty [K] that ``wall_std`` is for and where
        it comes from; default :func:`~pneumatic_unload.config.estimator.wall_uncertainty`.
    """
    s = settings
    u = input_uncertainties(s, p10)
    gas = s.gas
    terms = [BudgetTerm("volume V", "B", s.volume, u["volume"], "m^3",
                        abs(c) * u["volume"] / s.volume,
                        "stated" if s.volume_uncertainty is not None
                        else f"default {100 * VOLUME_REL_DEFAULT:g} % of V"),
             BudgetTerm("initial temperature T10", "B", s.initial_temperature,
                        u["initial_temperature"], "K",
                        abs(c) * 0.5 * u["initial_temperature"] / s.initial_temperature,
                        t10_uncertainty(s)[1])]
    d = u["pressure"]
    if eq39:
        def c39(dp10: float, datm: float) -> float:
            return conductance_eq39(tau, p10 + dp10, p_atm + datm, s.volume,
                                    s.initial_temperature, gas)
        # an offset moves p10 and p_atm (measured) alike; a given p_atm stays
        dm = d if atmosphere_measured else 0.0
        std_p = abs(c39(d, dm) - c39(-d, -dm)) / 2.0
    else:
        std_p = abs(_isentropic(s, tau, p_star + d, p10 + d)
                    - _isentropic(s, tau, p_star - d, p10 - d)) / 2.0 \
            * abs(c) / max(_isentropic(s, tau, p_star, p10), 1e-300)
    terms.append(BudgetTerm("pressure transducer (offset)", "B", p10, d, "Pa", std_p,
                            "stated" if s.pressure_uncertainty is not None else
                            f"default {100 * PRESSURE_REL_DEFAULT:g} % of p10"))
    if not atmosphere_measured:
        ua = u["atmosphere"]
        if eq39:
            # p* moves by 0.632 dp_atm, and the crossing with it: for the same C the
            # closed form reaches p* + 0.632 dp_atm at tau X(p* + ...)/X(p*)
            moved = tau * _isentropic(s, tau, p_star + (1.0 - 0.368) * ua, p10) \
                / _isentropic(s, tau, p_star, p10)
            std_a = abs(conductance_eq39(moved, p10, p_atm + ua, s.volume,
                                         s.initial_temperature, gas) - c)
        else:
            std_a = 0.0  # the inversion follows the moved crossing exactly (choked)
        terms.append(BudgetTerm("atmosphere p_atm (given)", "B", p_atm, ua, "Pa", std_a,
                                "atmosphere_uncertainty"))
    if math.isfinite(wall_std):
        terms.append(wall_term(s, c, wall_std, *(wall_input or wall_uncertainty(s))))
    return terms


def wall_term(settings: EstimatorSettings, c: float, std: float, u: float,
              why: str) -> BudgetTerm:
    """The wall temperature's line of the budget of C [m^3/(s Pa)]: C's standard
    uncertainty ``std`` [m^3/(s Pa)] from the wall moved by its uncertainty ``u`` [K]
    (``why``: where u comes from, :func:`~pneumatic_unload.config.estimator.
    wall_uncertainty`); the note states the sensitivity dC/dTw [%/K] and, for an assumed
    wall, that it was assumed."""
    per_k = 100.0 * std / (u * abs(c)) if u > 0 and c else math.nan
    sens = f"|dC/dTw| = {per_k:.3g} %/K" if math.isfinite(per_k) else "u = 0"
    return BudgetTerm(WALL_TERM, "B", settings.wall, u, "K", std, f"{why}; {sens}")


def fitted_wall_term(wall: float, wall_std: float, law: str) -> BudgetTerm:
    """The wall temperature's line when the chosen heat law fitted it (a hot start,
    ``law`` 'natural+wall' or 'fixed+wall'; ``wall``, ``wall_std`` [K]): its uncertainty is
    the fit's, already in the type A line (0 here: not counted twice)."""
    return BudgetTerm(WALL_TERM, "B", wall, wall_std, "K", 0.0,
                      f"fitted ({law}, a hot start): in the curve fit's line")


def held_wall_term(wall: float, u: float) -> BudgetTerm:
    """The wall temperature's line of a hot start whose T10 was not measured (the wall
    held at a room's ``wall`` [K], T10 fitted beside it): the room's uncertainty u [K]
    moves wall and T10 together, which is the T10 line's (0 here: not counted twice)."""
    return BudgetTerm(WALL_TERM, "B", wall, u, "K", 0.0,
                      "a room's, held (a hot start: T10 fitted beside it); its move is "
                      "T10's, in the T10 line")


def term_std(budget: dict[str, Any] | None, name: str) -> float:
    """The standard uncertainty [m^3/(s Pa)] of the line ``name`` of a budget given as
    :meth:`Budget.to_dict`; NaN when there is no budget or no such line."""
    for t in (budget or {}).get("terms", ()):
        if t["name"] == name:
            v = t["std"]
            return float(v) if v is not None else math.nan
    return math.nan


def wall_sensitivity(settings: EstimatorSettings, tau: float, *, p10: float, p_atm: float,
                     p_star: float, c_start: float) -> float:
    """C's standard uncertainty from the wall temperature [m^3/(s Pa)]: the model-based
    inversion at the crossing (natural heat law) with the wall moved by +-u [K]
    (:func:`~pneumatic_unload.config.estimator.wall_uncertainty`); NaN when it cannot be
    computed."""
    u = wall_uncertainty(settings)[0]
    walls = wall_pair(settings.wall, u)
    if walls[0] == walls[1]:
        return 0.0
    out = []
    for wall in walls:
        moved = with_wall(settings, wall, heat_model="natural")
        try:
            c, _sd = invert_crossing(tau, 0.0, p10=p10, p_atm=p_atm, p_star=p_star,
                                     settings=moved, c_start=c_start)
        except (ValueError, ArithmeticError):
            return math.nan
        out.append(c)
    # the slope over the (possibly one-sided, at the range's edge) pair, times u
    return abs(out[0] - out[1]) / (walls[0] - walls[1]) * u


def record_term(name: str, std: float) -> BudgetTerm:
    """The type A line of a model-based C: its standard uncertainty from the record
    ``std`` [m^3/(s Pa)] (``name``: how it was obtained)."""
    return BudgetTerm(name, "A", math.nan, math.nan, "", std)


def model_form_term(std: float, note: str = "") -> BudgetTerm:
    """The model-form line of a model-based C: the spread of the heat laws the record cannot
    tell apart [m^3/(s Pa)] (``note``: which laws and how)."""
    return BudgetTerm(MODEL_FORM_TERM, "model", math.nan, math.nan, "", std, note)


def tau_term(c: float, tau: float, tau_std: float) -> BudgetTerm:
    """The type A line of eq 39's C [m^3/(s Pa)]: the unloading time tau [s] and its
    1-sigma from the record [s] (C is proportional to 1/tau)."""
    return BudgetTerm("unloading time (noise)", "A", tau, tau_std, "s",
                      abs(c) * tau_std / tau if tau > 0 else math.nan)


def model_budget(settings: EstimatorSettings, c: float, *, type_a_std: float,
                 type_a_name: str, model_form_std: float, tau: float, p10: float,
                 p_atm: float, p_star: float, atmosphere_measured: bool,
                 wall_std: float = math.nan, wall_input: tuple[float, str] | None = None,
                 extra_terms: tuple[BudgetTerm, ...] = ()) -> Budget:
    """The budget of a model-based C (crossing inversion or curve fit).

    Parameters
    ----------
    settings : EstimatorSettings
        Inputs and their uncertainties.
    c : float
        The model-based C [m^3/(s Pa)].
    type_a_std : float
        Its standard uncertainty from the record [m^3/(s Pa)].
    type_a_name : str
        What that is (e.g. 'curve fit (noise, AR(1))').
    model_form_std : float
        Spread of the heat laws that fit about equally well [m^3/(s Pa)].
    tau, p10, p_atm, p_star, atmosphere_measured, wall_std, wall_input
        See :func:`input_terms`.
    extra_terms : tuple of BudgetTerm
        Further type B lines (e.g. a given initial pressure's, a fitted wall's).
    """
    terms = [record_term(type_a_name, type_a_std)]
    terms += input_terms(settings, c, tau=tau, p10=p10, p_atm=p_atm, p_star=p_star,
                         atmosphere_measured=atmosphere_measured, wall_std=wall_std,
                         wall_input=wall_input)
    terms += list(extra_terms)
    terms.append(model_form_term(model_form_std))
    terms.append(model_limits_term(c, settings.model_uncertainty))
    return Budget(c, tuple(terms))


def model_limits_term(c: float, model_uncertainty: float) -> BudgetTerm:
    """The model-limits line of a model-based C: ``model_uncertainty`` [-] (relative
    standard uncertainty from the discharge model's own limits: ideal gas, uniform state,
    heat-law family; see :class:`~pneumatic_unload.config.estimator.EstimatorSettings`)
    times ``|c|`` [m^3/(s Pa)]."""
    return BudgetTerm("model limits (ideal gas, uniform state)", "model", math.nan,
                      math.nan, "", abs(c) * model_uncertainty,
                      f"model_uncertainty {100 * model_uncertainty:g} %")


def eq39_budget(settings: EstimatorSettings, c: float, *, tau: float, tau_std: float,
                p10: float, p_atm: float, p_star: float,
                atmosphere_measured: bool) -> Budget:
    """The budget of eq 39's C (its bias by design is not an uncertainty: see
    :func:`pneumatic_unload.physics.eq39_bias_isentropic`).

    Parameters
    ----------
    settings : EstimatorSettings
        Inputs and their uncertainties.
    c : float
        eq 39's C [m^3/(s Pa)].
    tau, tau_std : float
        Unloading time and its standard deviation from the record [s].
    p10, p_atm, p_star, atmosphere_measured
        See :func:`input_terms`.
    """
    terms = [tau_term(c, tau, tau_std)]
    terms += input_terms(settings, c, tau=tau, p10=p10, p_atm=p_atm, p_star=p_star,
                         atmosphere_measured=atmosphere_measured, eq39=True)
    return Budget(c, tuple(terms))

