# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The candidate models of the final fit as typed values.

A :class:`Candidate` names what the discharge model adds beyond C, b, the opening and p10:
the wall heat law (a key of :data:`~pneumatic_unload.model.effects.FIT_HEAT_LAWS`), the
subsonic index m fitted or held at 0.5, the wall temperature fitted (a gas that starts
warmer or cooler than its wall), the transducer's zero offset fitted. The final fit
(:mod:`pneumatic_unload.estimation.final_fit`) fits each through the one engine and weighs
them by the one rule (:mod:`pneumatic_unload.selection`).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

from pneumatic_unload.model.effects import FIT_HEAT_LAWS


@dataclass(frozen=True)
class Candidate:
    """One candidate model of the final fit.

    Attributes
    ----------
    heat_law : str
        The wall heat law, a key of :data:`~pneumatic_unload.model.effects.FIT_HEAT_LAWS`.
    fit_m : bool
        The subsonic index m fitted (else held at 0.5, the elliptic law).
    fit_wall : bool
        The wall temperature fitted (the gas starts away from its wall's temperature).
    fit_offset : bool
        The transducer's zero offset fitted (p_atm given).
    """

    heat_law: str
    fit_m: bool = True
    fit_wall: bool = False
    fit_offset: bool = False

    def __post_init__(self) -> None:
        if self.heat_law not in FIT_HEAT_LAWS:
            raise ValueError(f"unknown heat law {self.heat_law!r}; one of "
                             f"{', '.join(FIT_HEAT_LAWS)}")

    @property
    def name(self) -> str:
        """A short name: the heat law, then ``+wall``, ``+offset`` and ``|m`` as fitted
        (the keys of the curve fit's law table)."""
        return (self.heat_law + ("+wall" if self.fit_wall else "")
                + ("+offset" if self.fit_offset else "") + ("|m" if self.fit_m else ""))


#: The heat laws of the default candidate set: a constant hA (Newton cooling), an hA that
#: follows the gas density to a fitted power, natural convection with a fitted scale, and an
#: hA that changes with the time since the opening with one and with two parameters.
DEFAULT_HEAT_LAWS: tuple[str, ...] = ("fixed", "density", "natural", "time", "time2")


def default_candidates(*, fit_m: tuple[bool, ...] = (False, True),
                       heat_laws: tuple[str, ...] = DEFAULT_HEAT_LAWS
                       ) -> tuple[Candidate, ...]:
    """Every heat law of ``heat_laws`` with m held and fitted (the default set)."""
    return tuple(Candidate(law, m) for law, m in product(heat_laws, fit_m))
