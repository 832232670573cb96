"""Equal fits, different C: the conductance ambiguity of a discrepancy verdict.

Naming an effect is not enough when models that explain the trace about equally well give
different sonic conductances C: the verdict must then give the C range across them and the
measurement that separates them. Three cases are collected (SI units: m^3/(s Pa)):

* **equal fits**: every fitted model (baseline, every candidate of every round) whose BIC
  is within the threshold of the best, and whose C differs from the final model's by more
  than their combined 1-sigma;
* **placement variants**: the runner-up of a round is the same physics placed elsewhere in
  the rig (a leak upstream or downstream of the valve), however far behind;
* **a leak in parallel with the component** (:data:`~pneumatic_unload.model.effects.
  DOWNSTREAM_LEAKS`) in the final model: it opens with the valve as the component does, so
  C is confounded with it; the C interval of that fit is reported as the range, and the
  measurement that separates them is a run with the component plugged.

The range spans the members' C values and their 95 % intervals (C +- 2 sigma, clipped at
zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pneumatic_unload.discrepancy.types import Fit, Round
from pneumatic_unload.model.effects import DOWNSTREAM_LEAKS, PLUGGED_RUN, separating_data

#: Effects that are the same physics placed upstream / downstream of the valve.
PLACEMENT_VARIANTS: dict[str, str] = {
    "leak": "leak_downstream", "leak_downstream": "leak",
    "orifice_leak": "orifice_leak_downstream", "orifice_leak_downstream": "orifice_leak",
}
#: Coverage factor of the members' C intervals in the range [-].
K_RANGE = 2.0


@dataclass
class ConductanceAmbiguity:
    """Models that fit about equally with different C, and the C range across them.

    Attributes
    ----------
    members : list of dict
        Per model: 'effects' (names), 'conductance' [m^3/(s Pa)], 'conductance_std'
        [m^3/(s Pa)], 'delta_bic' (BIC above the best model) [-], 'why'.
    low, high : float
        C range across the members, their 95 % intervals included [m^3/(s Pa)].
    separating : list of str
        Measurements that would separate them.
    """

    members: list[dict[str, Any]] = field(default_factory=list)
    low: float = math.nan
    high: float = math.nan
    separating: list[str] = field(default_factory=list)

    @property
    def ambiguous(self) -> bool:
        """True when more than the final model is a member (or a downstream leak is)."""
        return bool(self.members)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the ``conductance_range`` of the JSON output)."""
        return {"low": self.low, "high": self.high, "unit": "m^3/(s Pa)",
                "members": self.members, "separating": self.separating}


def _std(f: Fit) -> float:
    """1-sigma of C of a fit [m^3/(s Pa)] (nan when the covariance is not usable)."""
    try:
        s = f.std("C")
    except (ValueError, IndexError, ZeroDivisionError, ArithmeticError):
        return math.nan
    return s if math.isfinite(s) and s >= 0 else math.nan


def _label(f: Fit) -> str:
    return ", ".join(f.effects) if f.effects else "baseline (no effect)"


def conductance_ambiguity(base: Fit, rounds: list[Round], final: Fit, threshold: float
                          ) -> ConductanceAmbiguity:
    """Collect the models whose C competes with the final model's.

    Parameters
    ----------
    base : Fit
        The baseline fit.
    rounds : list of Round
        The greedy rounds (every candidate fit).
    final : Fit
        The model the verdict reports.
    threshold : float
        Delta-BIC within which two models fit "about equally" [-].
    """
    fits: list[Fit] = [base] + [f for r in rounds for f in r.fits.values()]
    best_bic = min(f.bic for f in fits if math.isfinite(f.bic))
    c0, s0 = final.theta["C"], _std(final)
    members: dict[tuple[str, ...], tuple[Fit, str]] = {}

    def differs(f: Fit) -> bool:
        c, s = f.theta["C"], _std(f)
        comb = math.hypot(s0 if math.isfinite(s0) else 0.0, s if math.isfinite(s) else 0.0)
        return abs(c - c0) > max(comb, 1e-12 * c0)

    for f in fits:
        if f is final or f.effects == final.effects:
            continue
        if f.bic - best_bic <= threshold and differs(f):
            members[f.effects] = (f, "fits about as well (delta-BIC within "
                                     f"{threshold:g} of the best)")
    for r in rounds:
        order = sorted(r.delta_bic, key=lambda k: -r.delta_bic[k])
        if r.winner == "none" or len(order) < 2:
            continue
        runner = order[1]
        if PLACEMENT_VARIANTS.get(r.winner) == runner and r.delta_bic[runner] > threshold:
            f = r.fits[runner]
            if f.effects != final.effects and differs(f):
                members.setdefault(f.effects, (f, f"placement variant of {r.winner} "
                                                  "(the same leak on the other side of "
                                                  "the valve)"))
    down = [e for e in final.effects if e in DOWNSTREAM_LEAKS]
    out = ConductanceAmbiguity()
    if not members and not down:
        return out
    why_final = "the reported model" + (
        f": {', '.join(down)} is in parallel with the component, so C is confounded "
        "with the leak" if down else "")
    rows = [(final, why_final), *members.values()]
    lows, highs = [], []
    for f, why in rows:
        c, s = f.theta["C"], _std(f)
        s = s if math.isfinite(s) else 0.0
        lows.append(max(c - K_RANGE * s, 0.0))
        highs.append(c + K_RANGE * s)
        out.members.append({"effects": list(f.effects), "conductance": c,
                            "conductance_std": s, "delta_bic": f.bic - best_bic,
                            "why": why})
    out.low, out.high = min(lows), max(highs)
    names = sorted({e for f, _ in rows for e in f.effects} | set(down))
    if down or any(e in DOWNSTREAM_LEAKS for f, _ in rows for e in f.effects):
        out.separating.append(f"C vs a leak in parallel with the component: {PLUGGED_RUN}")
    effs = [e for e in names if e not in final.effects] + list(final.effects)
    if len(effs) > 1:
        out.separating += separating_data(effs[:4])
    return out


def describe(amb: ConductanceAmbiguity) -> str:
    """One sentence for the verdict: the C range and what separates the members."""
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
             "b is indistinguishable from a larger C); to exclude one: " + PLUGGED_RUN)


def _fmt(effects: list[str]) -> str:
    return ", ".join(effects) if effects else "baseline"
