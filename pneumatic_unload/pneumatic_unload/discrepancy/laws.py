# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The heat-law family against further effects, and the tank's L/D when it is not stated.

A further effect must beat the named heat transfer with its law at its best
(:func:`law_refusals`); when the tank's L/D is not stated, the natural laws are also
fitted at other L/D values, in that test and for the final model
(:func:`length_diameter_choice`). SI units; BICs dimensionless.
"""

from __future__ import annotations

import math

from pneumatic_unload.discrepancy.problem import Problem
from pneumatic_unload.discrepancy.types import Fit
from pneumatic_unload.model.effects import HEAT_VARIANTS, HOT_START

#: Effects whose heat law is chosen from the engine's family (heat transfer; the hot
#: start is heat transfer with the wall temperature fitted).
HEAT_EFFECTS: tuple[str, ...] = ("heat_transfer", HOT_START)

#: Tank L/D values [-] at which the natural-convection laws are also fitted when the
#: tank's L/D is not stated (``DiscrepancySettings.length_diameter_known`` False): from 1
#: to 7.6 in steps of 1.5 (the correlation's Rayleigh number, on the tank's length, goes
#: as (L/D)^2, so a step moves where it changes branch, Ra = 1e9, by 2.25 times).
LD_CHOICES: tuple[float, ...] = (1.0, 1.5, 2.25, 3.4, 5.1, 7.6)
#: The laws of the family that depend on the tank's L/D (through the Rayleigh number).
NATURAL_LAWS: tuple[str, ...] = ("natural", "natural+turbulent")


def heat_law_refits(prob: Problem, fit: Fit) -> list[tuple[str, float | None, Fit]]:
    """``fit`` (a model with heat transfer or the hot start) refitted with every other
    law of the family, and, when the tank's L/D is not stated, with the natural laws at
    every L/D of :data:`LD_CHOICES`: (law, L/D or None for the stated one, fit) [-]."""
    lds: tuple[float | None, ...] = (None,) if prob.settings.length_diameter_known \
        else (None, *LD_CHOICES)
    out: list[tuple[str, float | None, Fit]] = []
    for ld in lds:
        if ld is not None and ld == prob.tank.length_diameter_ratio:
            continue
        p = prob if ld is None else prob.with_length_diameter(ld)
        for law in prob.heat_laws:
            rec = HEAT_VARIANTS[law]
            if (ld is None and law == fit.model.heat_law) or (
                    ld is not None and law not in NATURAL_LAWS):
                continue
            model = p.model(fit.effects, heat_law=law)
            centre = {q.name: q.centre(p.start) for q in rec.params}
            try:
                out.append((law, ld, p.fit(model, [dict(fit.theta),
                                                   {**fit.theta, **centre}])))
            except ValueError:
                continue
    return out


def law_refusals(prob: Problem, base: Fit, delta: dict[str, float], threshold: float
                 ) -> dict[str, str]:
    """Further candidates that another heat law of the family explains as well (name ->
    reason); ``delta``: the candidates not refused already -> delta-BIC over ``base``.

    When heat transfer (or the hot start) is among the effects named, a further effect
    must beat them with their heat law at its best, not only with the law its round
    chose: the named model is refitted on ``prob`` (the further round's noise model) with
    every other law of :data:`~pneumatic_unload.model.effects.HEAT_VARIANTS` (and, when
    the tank's L/D is not stated, with the natural laws at every L/D of
    :data:`LD_CHOICES`: :func:`heat_law_refits`), and a candidate that beats the base by
    the BIC threshold but not the best of these refits by it is a look-alike of the heat
    law (its gain is the named effect's law family bending where the chosen law does
    not), not a missing effect. The refits are only evidence against the candidate: the
    named model keeps its law (the hot start is named with at most the wall temperature
    beyond heat transfer's parameters). HydDown v5l (a calc-h 5 L vessel): after
    hot_start (natural+turbulent), a laminar leak of 5.8 % gained 50.6 with C -3.3 %; the
    hot start with the density law gains 48.2 with C -0.00 %. Below the threshold nothing
    is tested (not claimed anyway).
    """
    heat = [e for e in base.effects if e in HEAT_EFFECTS]
    contenders = [k for k, d in delta.items() if d > threshold]
    if not heat or not contenders:
        return {}
    best_law, best_gain = "", -math.inf
    for law, ld, f in heat_law_refits(prob, base):
        if base.bic - f.bic > best_gain:
            best_law = law if ld is None else f"{law} (at L/D {ld:g})"
            best_gain = base.bic - f.bic
    out: dict[str, str] = {}
    for k in contenders:
        if delta[k] - best_gain <= threshold:
            out[k] = (f"{', '.join(heat)} with the {best_law} heat law explains the trace "
                      f"about as well (delta-BIC {best_gain:.1f} against {delta[k]:.1f} for "
                      f"{k}): a look-alike of the heat law's shape, not a missing effect")
    return out


def length_diameter_choice(prob: Problem, fit: Fit, threshold: float
                           ) -> tuple[Fit, list[tuple[Fit, str, float]], str]:
    """The final model's heat law at the tank's L/D the data prefer, when the L/D is not
    stated.

    The natural-convection correlation's Rayleigh number is taken on the tank's length,
    so the L/D decides where the correlation changes branch (Ra = 1e9) and no scale
    factor makes up for a wrong one (HydDown full00, L/D 6 not stated: with the default
    2 the gas never reached the turbulent branch, and a pipe volume of 21 % of V stood in
    for the bend with C +31 %). ``fit`` is refitted with the natural laws at every L/D of
    :data:`LD_CHOICES` (:func:`heat_law_refits`); the best is taken when it beats ``fit``
    by the BIC threshold, and every refit within the threshold of the one taken is
    returned as a C-range member (an L/D the data cannot rule out).

    Returns
    -------
    tuple
        (the fit taken, [(member fit, why, its BIC above the one taken [-])], a note for
        the verdict, '' when the L/D is stated or no heat effect is in ``fit``).
    """
    if prob.settings.length_diameter_known or not any(e in HEAT_EFFECTS
                                                      for e in fit.effects):
        return fit, [], ""
    ld0 = prob.tank.length_diameter_ratio
    tried = [(fit.model.heat_law, ld0, fit), *(
        (law, ld, f) for law, ld, f in heat_law_refits(prob, fit) if ld is not None)]
    best = min(tried, key=lambda x: x[2].bic)
    taken = best if fit.bic - best[2].bic > threshold else tried[0]
    members = [(f, f"the tank's L/D is not stated: at L/D {ld:g} ({law} law) the heat "
                   "transfer fits about as well", f.bic - taken[2].bic)
               for law, ld, f in tried
               if f is not taken[2] and f.bic - taken[2].bic <= threshold]
    note = (f"the tank's L/D is not stated: the natural heat law was fitted at L/D "
            f"{', '.join(f'{x:g}' for x in sorted({ld0, *LD_CHOICES}))}; ")
    if taken is tried[0]:
        note += f"none fits better than the default {ld0:g} by the BIC threshold"
    else:
        note += (f"L/D {taken[1]:g} ({taken[0]} law) fits best, {fit.bic - taken[2].bic:.1f} "
                 f"better than the default {ld0:g}, and is the model reported")
    return taken[2], members, note
