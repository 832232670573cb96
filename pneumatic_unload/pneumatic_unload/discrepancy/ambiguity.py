# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Equal fits, different C: the conductance ambiguity of a discrepancy verdict.

Naming an effect is not enough when models that explain the trace about equally well give
different sonic conductances C: the verdict must then give the C range across them and the
measurement that separates them. Members are collected by these rules (SI units:
m^3/(s Pa)); a member is kept only when its C differs from the final model's by more than
their combined 1-sigma:

* **equal fits**: a model of a round (its base or a candidate) whose BIC is within the
  threshold of that round's best (BICs compare only within a round: a further round may
  use a noise model refitted on the residual);
* **white fits**: a candidate that improves on its round's base (lower BIC) and whose
  residual is white with a normalised RMS <= 1.02 (:data:`~pneumatic_unload.discrepancy.
  types.NRMS_LIMIT`), as is the final model's: both explain the trace within noise,
  whatever their BICs (a candidate no better than its base only spends its parameters on
  a degenerate direction, e.g. a pipe conductance in series trading with C);
* **a winner at a bound**: a round's winner with a parameter at its bound is a stand-in
  for physics it does not quite describe, however far ahead; its runner-up is a member;
* **variants**: the runner-up of a round is the same physics in another place or law (a
  leak upstream / downstream of the valve, laminar / orifice: :data:`VARIANTS`), however
  far behind;
* **the round's ambiguity set**: the candidates the data cannot tell from the round's
  winner (:attr:`~pneumatic_unload.discrepancy.types.Round.ambiguous_with`; a variant of
  the winner with a chi^2 within the threshold of its, whatever its BIC:
  :func:`~pneumatic_unload.discrepancy.search.decide`);
* **a leak in parallel with the component** (:data:`~pneumatic_unload.model.effects.
  DOWNSTREAM_LEAKS`) in the final model: C is confounded with it; the C interval of that
  fit is the range, and a run with the component plugged separates them.

Whatever the verdict, C of the final model is the conductance of everything downstream of
the valve: a leak in parallel with the component that follows the component's own flow
law (an orifice leak with the same b) changes the trace exactly as a larger C does, at any
size (the ISO 6358 flow is linear in C at a fixed b), so no fit can bound it. That is not
what the data allow but what no pressure record can tell: it is stated apart, as its own
field (``parallel_low``: the component's C with such a leak of up to
:data:`PARALLEL_LEAK_MAX` times its own C hidden in it) and sentence (:data:`C_MEANING`,
with the leak test that bounds it: a run with the component plugged), never as the lower
end of the range.

The range states what the data allow: it spans the C values of the final model and of the
members (the models that fit about equally) with their 3-sigma intervals (C +- 3 sigma,
clipped at zero; sigma the noise's and the model limits' combined, the budget's term
:func:`~pneumatic_unload.uncertainty.budget.model_limits_term`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pneumatic_unload.discrepancy.types import NRMS_LIMIT, Diagnostics, Fit, Round
from pneumatic_unload.model.effects import (
    DOWNSTREAM_LEAKS,
    HOT_START,
    PLUGGED_RUN,
    separating_data,
)
from pneumatic_unload.uncertainty.budget import model_limits_term

#: Pairs of candidates that are the same physics in another law or place, neither nested
#: in the other: the runner-up of such a pair is a C-ambiguity member however far behind.
VARIANTS: tuple[frozenset[str], ...] = (
    frozenset({"leak", "orifice_leak"}),
    frozenset({"leak_downstream", "orifice_leak_downstream"}),
    frozenset({"leak", "leak_downstream"}),
    frozenset({"orifice_leak", "orifice_leak_downstream"}),
    frozenset({"leak", "orifice_leak_downstream"}),
    frozenset({"orifice_leak", "leak_downstream"}),
)
#: Pairs of the same physics: the variants and the nested pair heat transfer / hot start
#: (the hot start adds the wall temperature; the data judge it by the BIC like any effect).
SAME_PHYSICS: tuple[frozenset[str], ...] = (*VARIANTS, frozenset({"heat_transfer",
                                                                    HOT_START}))
#: Coverage factor of the members' C intervals in the range [-]: the 3-sigma interval by
#: which a reported C is judged (a C more than 3 sigma off with no range is "confidently
#: wrong"); 2 sigma would miss the truth in 1 of 20 verdicts by noise alone.
K_RANGE = 3.0
#: Largest leak in parallel with the component the range allows, relative to the
#: component's own C [-]: a leak carrying more than the component is a second outlet (a
#: plumbing error), not a leaky seal.
PARALLEL_LEAK_MAX = 1.0
#: Relative C difference below which two models do not make an ambiguity [-]: far below
#: every other term of C's budget (volume, temperature: about 1 %); without it, a candidate
#: fitted at almost nothing on effect-free data (C 0.01 % apart, sigma 0.006 %) was called
#: one.
C_NEGLIGIBLE = 1e-3
#: How close to a bound (in units of the parameter's fitted scale) counts as at it [-].
AT_BOUND = 1e-3


#: The measurement that separates the final model at L/D values the data cannot rule out.
LD_STATED = ("the tank's L/D stated (--length-diameter-ratio: its length over its inner "
             "diameter): the natural-convection correlation changes branch at a Rayleigh "
             "number taken on the tank's length")


def same_physics(a: str, b: str) -> bool:
    """True when candidates a and b are the same physics in another law or place."""
    return frozenset({a, b}) in SAME_PHYSICS


@dataclass
class ConductanceAmbiguity:
    """Models that fit about equally with different C, and the C range across them.

    Attributes
    ----------
    members : list of dict
        Per model: 'effects' (names), 'conductance' [m^3/(s Pa)], 'conductance_std'
        [m^3/(s Pa)], 'delta_bic' (BIC above the best model of its round) [-], 'why'.
        Empty when no other model competes (C is then not ambiguous).
    low, high : float
        C range the data allow: the final model's and the members' 3-sigma intervals
        [m^3/(s Pa)].
    parallel_low : float
        Component's C if a leak in parallel with it of :data:`PARALLEL_LEAK_MAX` times
        its C were hidden in the final model's C (lower 3-sigma end) [m^3/(s Pa)]: what no
        pressure record can exclude (a leak test bounds it), not part of the range.
    separating : list of str
        Measurements that would separate them.
    fits : list of Fit
        The fits of :attr:`members`, in their order (not in the JSON).
    ruled_out : list of dict
        Members a logged gas temperature rules out (:meth:`rule_out`): as in
        :attr:`members`, with 'why'; no longer in the range.
    """

    members: list[dict[str, Any]] = field(default_factory=list)
    low: float = math.nan
    high: float = math.nan
    parallel_low: float = math.nan
    separating: list[str] = field(default_factory=list)
    fits: list[Fit] = field(default_factory=list)
    ruled_out: list[dict[str, Any]] = field(default_factory=list)
    #: The final model's C and its total 1-sigma [m^3/(s Pa)] (the range's own ends).
    final_conductance: tuple[float, float] = (math.nan, math.nan)

    def rule_out(self, which: dict[int, str]) -> None:
        """Take the members at the indices of ``which`` (into :attr:`members`; the
        reported model, index 0, stays) out of the range, each with its reason, and span
        the range anew over the final model and the members left (none left but the
        final model: C is no longer ambiguous, unless a downstream leak is in it)."""
        gone = {i for i in which if 0 < i < len(self.members)}
        if not gone:
            return
        self.ruled_out += [{**self.members[i], "why": which[i]} for i in sorted(gone)]
        keep = [i for i in range(len(self.members)) if i not in gone]
        self.members = [self.members[i] for i in keep]
        self.fits = [self.fits[i] for i in keep if i < len(self.fits)]
        c0, s0 = self.final_conductance
        self.low, self.high = max(c0 - K_RANGE * s0, 0.0), c0 + K_RANGE * s0
        for m in self.members:
            c, s = m["conductance"], m["conductance_std"]
            self.low = min(self.low, max(c - K_RANGE * s, 0.0))
            self.high = max(self.high, c + K_RANGE * s)
        if len(self.members) == 1 and not any(e in DOWNSTREAM_LEAKS
                                              for e in self.members[0]["effects"]):
            self.members, self.fits = [], []

    @property
    def ambiguous(self) -> bool:
        """True when another model competes (or a downstream leak is in the final one)."""
        return bool(self.members)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the ``conductance_range`` of the JSON output)."""
        return {"low": self.low, "high": self.high, "unit": "m^3/(s Pa)",
                "ambiguous": self.ambiguous, "members": self.members,
                "ruled_out_by_temperature": self.ruled_out,
                "parallel_leak_low": self.parallel_low,
                "parallel_leak_max": PARALLEL_LEAK_MAX, "separating": self.separating}


def conductance_std(f: Fit) -> float:
    """1-sigma of C of a fit [m^3/(s Pa)] (NaN where its covariance is not usable)."""
    try:
        s = f.std("C")
    except (ValueError, IndexError, ZeroDivisionError, ArithmeticError):
        return math.nan
    return s if math.isfinite(s) and s >= 0 else math.nan


def at_bounds(f: Fit) -> list[str]:
    """Free parameters of a fit at (within :data:`AT_BOUND` of) a bound."""
    params = f.result.params
    lo, hi = params.bounds()
    x = params.to_x(f.theta)
    return [n for n, xi, a, b in zip(params.free, x, lo, hi, strict=True)
            if xi - a < AT_BOUND or b - xi < AT_BOUND]


def _within_noise(d: Diagnostics | None) -> bool:
    return d is not None and d.white and d.nrms <= NRMS_LIMIT


def conductance_ambiguity(base: Fit, rounds: list[Round], final: Fit, threshold: float,
                          quality: Callable[[Fit], Diagnostics] | None = None,
                          model_uncertainty: float = 0.0,
                          length_diameter: list[tuple[Fit, str, float]] | None = None
                          ) -> ConductanceAmbiguity:
    """Collect the models whose C competes with the final model's.

    Parameters
    ----------
    base : Fit
        The baseline fit (the base of the first round).
    rounds : list of Round
        The greedy rounds (every candidate fit).
    final : Fit
        The model the verdict reports.
    threshold : float
        Delta-BIC within which two models fit "about equally" [-].
    quality : callable, optional
        Diagnostics of a fit (residual whiteness and normalised RMS); without it the
        white-fits rule is not applied.
    model_uncertainty : float
        Relative standard uncertainty of C from the model's own limits [-]: it widens the
        range's 3-sigma ends (the budget's model-limits term), not the comparison of
        members, which share the model's limits.
    length_diameter : list, optional
        The final model refitted at tank L/D values the data cannot rule out when the L/D
        is not stated (fit, why, BIC above the final model [-]:
        :func:`~pneumatic_unload.discrepancy.laws.length_diameter_choice`): members
        when their C differs; stating the L/D (:data:`LD_STATED`) separates them.
    """
    c0, s0 = final.theta["C"], conductance_std(final)
    members: dict[tuple[str, ...], tuple[Fit, str, float]] = {}

    def differs(f: Fit) -> bool:
        c, s = f.theta["C"], conductance_std(f)
        comb = math.hypot(s0 if math.isfinite(s0) else 0.0, s if math.isfinite(s) else 0.0)
        return abs(c - c0) > max(comb, C_NEGLIGIBLE * c0)

    def add(f: Fit, why: str, dbic: float, key: tuple[str, ...] | None = None) -> None:
        if f is not final and (key is not None or f.effects != final.effects) and differs(f):
            members.setdefault(key or f.effects, (f, why, dbic))

    for f, why, dbic in length_diameter or []:
        add(f, why, dbic, (*f.effects, f"L/D {f.model.tank.length_diameter_ratio:g}"))
    by_ld = bool(members)

    final_white = quality is not None and _within_noise(quality(final))
    round_base = base
    for r in rounds:
        round_base = r.base if r.base is not None else round_base
        # a refused candidate (a transducer effect without evidence of its own) competes
        # with nothing: a physics model explains what it would
        pool = [round_base, *(f for k, f in r.fits.items() if k not in r.refused)]
        best = min(f.bic for f in pool if math.isfinite(f.bic))
        for f in pool:
            if f.bic - best <= threshold:
                add(f, f"fits about as well (delta-BIC within {threshold:g} of the best)",
                    f.bic - best)
            elif final_white and quality is not None and f is not round_base \
                    and f.bic < round_base.bic and differs(f) and _within_noise(quality(f)):
                add(f, "explains the trace within noise too (white, normalised RMS <= "
                       f"{NRMS_LIMIT:g})", f.bic - best)
        order = [k for k in sorted(r.delta_bic, key=lambda k: -r.delta_bic[k])
                 if k not in r.refused]
        if r.winner != "none" and len(order) > 1:
            runner = r.fits[order[1]]
            bound = at_bounds(r.fits[r.winner])
            if bound:
                add(runner, f"runner-up of {r.winner}, whose {', '.join(bound)} sit(s) at "
                            "a bound (a stand-in for physics it does not quite describe)",
                    runner.bic - best)
            if frozenset({r.winner, order[1]}) in VARIANTS:
                add(runner, f"the same physics as {r.winner} in another place or law",
                    runner.bic - best)
        for k in r.ambiguous_with if r.winner != "none" else ():
            add(r.fits[k], f"the data cannot tell it from {r.winner} (same physics, "
                           "fits as well but for the penalty of its parameters)",
                r.fits[k].bic - best)
        if r.winner != "none":
            round_base = r.fits[r.winner]
    down = [e for e in final.effects if e in DOWNSTREAM_LEAKS]
    out = ConductanceAmbiguity()

    def total(c: float, s: float) -> float:
        return math.hypot(s if math.isfinite(s) else 0.0,
                          model_limits_term(c, model_uncertainty).std)

    s0_ = total(c0, s0)
    out.final_conductance = (c0, s0_)
    out.parallel_low = max(c0 - K_RANGE * s0_, 0.0) / (1.0 + PARALLEL_LEAK_MAX)
    out.low, out.high = max(c0 - K_RANGE * s0_, 0.0), c0 + K_RANGE * s0_
    plugged = f"C vs a leak in parallel with the component: {PLUGGED_RUN}"
    if not members and not down:
        out.separating.append(plugged)
        return out
    why_final = "the reported model" + (
        f": {', '.join(down)} is in parallel with the component, so C is confounded "
        "with the leak" if down else "")
    rows = [(final, why_final, 0.0), *members.values()]
    for f, why, dbic in rows:
        c, s = f.theta["C"], conductance_std(f)
        s = total(c, s)
        out.low = min(out.low, max(c - K_RANGE * s, 0.0))
        out.high = max(out.high, c + K_RANGE * s)
        out.members.append({"effects": list(f.effects), "conductance": c,
                            "conductance_std": s, "delta_bic": dbic, "why": why})
        out.fits.append(f)
    names = sorted({e for f, _, _ in rows for e in f.effects})
    effs = [e for e in names if e not in final.effects] + list(final.effects)
    specific = separating_data(effs[:4]) if len(effs) > 1 else []
    if down or any(e in DOWNSTREAM_LEAKS for e in names):
        out.separating = [plugged, *specific]
    else:
        out.separating = [*specific, plugged]
    if by_ld:
        out.separating.insert(0, LD_STATED)
    return out


def describe(amb: ConductanceAmbiguity) -> str:
    """One sentence for the verdict: the C range and what separates the members (call it
    when :attr:`ConductanceAmbiguity.ambiguous`)."""
    who = "; ".join(f"{_fmt(m['effects'])}: C = {m['conductance']:.4g}" for m in amb.members)
    txt = (f"C is ambiguous: {amb.low:.4g} to {amb.high:.4g} m^3/(s Pa) across "
           f"{len(amb.members)} model(s) ({who})")
    if amb.separating:
        txt += f"; to separate: {amb.separating[0]}"
    return txt


#: What the reported C means whatever the verdict (a leak in parallel with the component
#: opens with it; a sonic one changes the trace exactly as a larger C does).
C_MEANING = ("C is the conductance of everything downstream of the shut-off valve: a leak "
             "in parallel with the component adds to it (an orifice-law one with the same "
             "b is indistinguishable from a larger C, at any size), so no pressure record "
             "bounds it; the bound of one of up to "
             f"{PARALLEL_LEAK_MAX:g} times the component's own C is stated apart "
             "(parallel_leak_low), not in the C range; to exclude one: " + PLUGGED_RUN)
#: :data:`C_MEANING` of a charge (the supply fills the tank through the component).
C_MEANING_CHARGE = (
    "C is the conductance of everything between the supply and the tank once the valve "
    "opens: a path in parallel with the component (a bypass, a leaking seal of the "
    "fixture) adds to it and no pressure record bounds it; the bound of one of up to "
    f"{PARALLEL_LEAK_MAX:g} times the component's own C is stated apart "
    "(parallel_leak_low), not in the C range; to exclude one: a charge with the component "
    "removed and its port plugged (any rise is the parallel path)")


def _fmt(effects: list[str]) -> str:
    return ", ".join(effects) if effects else "baseline"
