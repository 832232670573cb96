# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The last look at a result before it is published: no 'ok' that is not.

Every result of the estimator (crossing and final, streaming, deferred or from a given
start) passes :func:`vet` once it is complete. A result that gives C (status in
:data:`~.types.ESTIMATE_STATUSES`) is

* flagged when its tank's pressure lies where the real gas departs from the model's ideal
  gas by more than :data:`REAL_GAS_DEPARTURE` (a second virial estimate of the gas,
  :data:`~pneumatic_unload.real_gas.VIRIAL_GASES`): a note in its status text and a line in
  its budgets (:data:`REAL_GAS_TERM`);
* told why it has no model-based C when it has none (:data:`NO_MODEL_C_TEXT`: the C to
  report is then eq 39's, biased by design);
* no result (status :data:`~.types.NO_RESULT_STATUS`, :data:`UNCERTAIN_TEXT`) when the standard
  uncertainty of the C to report is larger than that C, or not known.

The status words and the openings of the texts are the named constants of this module, in
one place.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from pneumatic_unload import real_gas
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.estimation.types import (
    ESTIMATE_STATUSES,
    NO_RESULT_STATUS,
    UnloadResult,
    recommended,
)
from pneumatic_unload.uncertainty.budget import BudgetTerm, with_terms

#: Opening of the status text of a result whose standard uncertainty leaves no C.
UNCERTAIN_TEXT = "no result: the standard uncertainty of C"
#: Opening of the note of a result that has no model-based C.
NO_MODEL_C_TEXT = "no model-based C"
#: Opening of the note of a record where the ideal gas departs from the real one.
REAL_GAS_TEXT = "real gas"
#: Name of the real gas's line in a budget.
REAL_GAS_TERM = "real gas (the model's ideal gas)"
#: The compressibility's departure abs(Z - 1) at the tank's highest pressure above which a
#: record is flagged [-]: the ideal gas's density, and with it the tank's capacity, is then
#: off by more than 1 %.
REAL_GAS_DEPARTURE = 0.01
#: Key of ``extra`` under which :func:`vet` keeps a result's (status, status text,
#: quality) when it makes the result no result (:func:`as_computed` reads it).
AS_COMPUTED = "as_computed"
#: Why a model-based C is missing when nothing more specific is known.
NO_MODEL_C_DEFAULT = ("the model inversion at the p* crossing found no C for this record "
                      "(its crossing lies outside the model's reach)")


def vet(r: UnloadResult, settings: EstimatorSettings) -> UnloadResult:
    """``r`` vetted in place (and returned): the real gas flagged, a missing model C
    explained, an uncertainty larger than C (or not known) made no result. Applying it
    twice changes nothing more. ``settings``: the gas and the tank."""
    if r.status not in ESTIMATE_STATUSES:
        return r
    _real_gas(r, settings)
    if not (math.isfinite(r.conductance_model) and r.conductance_model > 0) \
            and NO_MODEL_C_TEXT not in r.status_text:
        why = (r.extra or {}).get("model_c_missing") or (r.extra or {}).get(
            "curve_fit_error") or NO_MODEL_C_DEFAULT
        r.status_text = (f"{r.status_text}; {NO_MODEL_C_TEXT} ({why}): the C to report is "
                         f"eq 39's, biased by design")
    rec = recommended(r)
    c, sd = rec["conductance"], rec["std"]
    if math.isfinite(c) and c > 0 and not (math.isfinite(sd) and sd <= c):
        key = "budget" if math.isfinite(r.conductance_model) else "budget_eq39"
        largest = (r.extra or {}).get(key, {}).get("largest") or "not known"
        size = (f"{sd:.3g} m^3/(s Pa), {sd / c:.3g} times C = {c:.4g} m^3/(s Pa)"
                if math.isfinite(sd) else f"not known, for C = {c:.4g} m^3/(s Pa)")
        r.extra = {**r.extra, AS_COMPUTED: (r.status, r.status_text, r.quality)}
        r.status = NO_RESULT_STATUS
        r.status_text = (f"{UNCERTAIN_TEXT} ({rec['source']}) is {size} (largest line: "
                         f"{largest}): the record does not determine C; {r.status_text}")
        r.quality = 0.0
    return r


def as_computed(r: UnloadResult) -> UnloadResult:
    """``r`` as the estimator computed it, before :func:`vet` made it no result for its
    uncertainty (``r`` itself when it did not): the vetting judges what is published, not
    how the estimator goes on. A crossing result whose C the crossing does not determine
    still starts its unload's full-curve fit, whose result is vetted on its own (the whole
    curve may determine C where the samples about p* do not)."""
    kept = r.extra.get(AS_COMPUTED)
    if kept is None:
        return r
    status, text, quality = kept
    extra = {k: v for k, v in r.extra.items() if k != AS_COMPUTED}
    return dataclasses.replace(r, status=status, status_text=text, quality=quality,
                               extra=extra)


def real_gas_departure(r: UnloadResult, settings: EstimatorSettings
                       ) -> tuple[float, float, str] | None:
    """The real gas at the tank's highest pressure (p10 of a discharge, the supply of a
    charge) and T10: (Z - 1 [-], the pressure where abs(Z - 1) reaches
    :data:`REAL_GAS_DEPARTURE` [Pa absolute], the gas's name); None when the gas is not
    one of :data:`~pneumatic_unload.real_gas.VIRIAL_GASES` or the state is not known."""
    gas = real_gas.virial_gas(settings.gas)
    p = max(x for x in (r.p10, r.supply_pressure, -math.inf) if x == x)
    t = r.initial_temperature
    if gas is None or not (math.isfinite(p) and math.isfinite(t) and t > 0):
        return None
    return gas.departure(p, t), gas.pressure_at(REAL_GAS_DEPARTURE, t), gas.name


def real_gas_term(c: float, departure: float, name: str) -> BudgetTerm:
    """The budget line of the real gas for C = c [m^3/(s Pa)], the compressibility's
    departure Z - 1 [-] at the tank's highest pressure: rectangular, of half-width
    2 abs(Z - 1) C (to first order the tank's capacity d(rho)/dp moves by 2 (Z - 1) and the
    choked flow by (Z - 1)/2 there, less further down the discharge)."""
    return BudgetTerm(REAL_GAS_TERM, "model", departure, math.nan, "-",
                      2.0 * abs(departure) * abs(c) / math.sqrt(3.0),
                      f"Z - 1 = {departure:+.3f} at the tank's highest pressure and T10 "
                      f"({name}, second virial coefficient): 2 |Z - 1| C / sqrt(3)")


def _real_gas(r: UnloadResult, settings: EstimatorSettings) -> None:
    """Flag ``r`` (its text and budgets) where the real gas departs by more than
    :data:`REAL_GAS_DEPARTURE`; once (a final result keeps its crossing's text, not its
    budgets)."""
    found = real_gas_departure(r, settings)
    if found is None:
        return
    z1, p_limit, name = found
    if abs(z1) <= REAL_GAS_DEPARTURE:
        return
    extra: dict[str, Any] = r.extra
    u_rel = 2.0 * abs(z1) / math.sqrt(3.0)
    for key, c_attr, std_attr in (("budget", "conductance_model", "conductance_model_std"),
                                  ("budget_eq39", "conductance", "conductance_std")):
        c = getattr(r, c_attr)
        if key in extra and math.isfinite(c) and not any(
                t["name"] == REAL_GAS_TERM for t in extra[key]["terms"]):
            extra[key] = with_terms(extra[key], [real_gas_term(c, z1, name)])
            combined = extra[key]["combined_std"]
            setattr(r, std_attr, math.nan if combined is None else combined)
    if REAL_GAS_TEXT + ":" in r.status_text:
        return
    r.status_text = (f"{r.status_text}; {REAL_GAS_TEXT}: Z = {1.0 + z1:.3f} for {name} at "
                     f"the tank's highest pressure and T10; above {p_limit:.3g} Pa the "
                     f"model's ideal gas departs from it by more than "
                     f"{100 * REAL_GAS_DEPARTURE:g} %: C carries a line of "
                     f"{100 * u_rel:.2g} % for it")
