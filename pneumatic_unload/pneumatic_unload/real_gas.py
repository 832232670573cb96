# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The real gas beside the ideal one of the model: second virial coefficients B(T) of the
gases the package knows, and the compressibility Z = 1 + B p / (R_u T) they give, so that a
record at a pressure where the ideal gas departs from the real one can be flagged.

SI units: Pa absolute, K, m^3/mol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pneumatic_unload.physics import Gas

#: Molar gas constant R_u [J/(mol K)] (CODATA 2018, exact).
R_UNIVERSAL = 8.314462618
#: Reference temperature of the virial coefficients' expansion T_0 [K].
VIRIAL_T0 = 298.15


@dataclass(frozen=True)
class VirialGas:
    """A gas whose second virial coefficient B(T) the package knows: the real gas's
    compressibility Z = p / (rho R T) = 1 + B p / (R_u T) to first order in p.

    B(T) = sum_i a_i (T_0/T - 1)^(i - 1) cm^3/mol, T_0 = 298.15 K: the form and the
    coefficients of the CRC Handbook of Chemistry and Physics, section 6, "Virial
    coefficients of selected gases" (a fit to the compilation of Dymond, Marsh, Wilhoit and
    Wong, Virial Coefficients of Pure Gases, Landolt-Boernstein IV/21A, Springer 2002),
    within a few cm^3/mol over ``t_range``. Air's are the mole-fraction mean of nitrogen's,
    oxygen's and argon's (78.1/21.0/0.9 %; the cross coefficients taken as the means of the
    pure ones): B(293 K) -7.6 cm^3/mol, within about 15 % of air's equation of state.

    Attributes
    ----------
    name : str
        The gas.
    gas_constant : float
        Specific gas constant R [J/(kg K)] (how a :class:`Gas` is matched to it).
    coefficients : tuple of float
        a_1, a_2, ... [cm^3/mol].
    t_range : tuple of float
        The temperatures the fit covers [K].
    """

    name: str
    gas_constant: float
    coefficients: tuple[float, ...]
    t_range: tuple[float, float]

    def second_virial(self, t: float) -> float:
        """B(T) [m^3/mol]."""
        x = VIRIAL_T0 / t - 1.0
        return 1e-6 * sum(a * x ** i for i, a in enumerate(self.coefficients))

    def departure(self, p: float, t: float) -> float:
        """Z - 1 = B p / (R_u T) at pressure p [Pa absolute] and temperature t [K] [-]."""
        return self.second_virial(t) * p / (R_UNIVERSAL * t)

    def pressure_at(self, departure: float, t: float) -> float:
        """The pressure where abs(Z - 1) reaches ``departure`` [-] at t [K] [Pa absolute]
        (inf where B is 0)."""
        b = abs(self.second_virial(t))
        return departure * R_UNIVERSAL * t / b if b > 0.0 else math.inf


#: The gases whose second virial coefficient is known (:class:`VirialGas`), by name.
VIRIAL_GASES: dict[str, VirialGas] = {g.name: g for g in (
    VirialGas("air", 287.05, (-6.6, -57.3, -11.1), (100.0, 700.0)),
    VirialGas("nitrogen", 296.80, (-4.0, -56.0, -12.0), (75.0, 745.0)),
    VirialGas("oxygen", 259.84, (-16.0, -62.0, -8.0, -3.0), (90.0, 400.0)),
    VirialGas("argon", 208.13, (-16.0, -60.0, -10.0), (80.0, 1025.0)),
    VirialGas("helium", 2077.1, (12.0, -1.0), (15.0, 1475.0)),
    VirialGas("hydrogen", 4124.2, (15.0, -9.0, -0.2), (15.0, 400.0)),
    VirialGas("carbon dioxide", 188.92, (-127.0, -288.0, -118.0), (220.0, 1100.0)),
)}
#: A gas matches a :class:`VirialGas` when their specific gas constants agree this closely
#: (relative) [-]: the gases above are 3 % apart at the closest (air and nitrogen), a gas
#: constant given to three digits 0.2 %.
VIRIAL_MATCH = 0.005


def virial_gas(gas: Gas) -> VirialGas | None:
    """The known gas (:data:`VIRIAL_GASES`) whose R matches ``gas``'s within
    :data:`VIRIAL_MATCH`, or None."""
    for v in VIRIAL_GASES.values():
        if abs(gas.gas_constant / v.gas_constant - 1.0) <= VIRIAL_MATCH:
            return v
    return None
