# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Tank discharges and charges under heat laws outside the package's family: an oracle.

Written apart from ``pneumatic_unload`` on purpose (it imports nothing from it): a fit that
recovers the parameters of the model it was written beside proves little. The package's
curve fit compares a constant hA (Newton cooling), hA ~ rho^n, natural convection
(Nu ~ Ra^(1/4) or Ra^(1/3): a heat flow ~ rho^(1/2) |dT|^(5/4) or rho^(2/3) |dT|^(4/3)),
each with a wall held at a constant temperature. The laws here are none of those:

* :class:`PowerDifference` - q = k |T_w - T|^n sign(T_w - T), the gas-wall difference
  alone, no density dependence, n drawn 1.3-1.6.
* :class:`DensityDifference` - q = k (rho/rho_0)^a |dT|^c dT, density and difference with
  exponents outside the family (a 0.8-1.2, c 0.4-0.7).
* :class:`WarmingWall` - Newton cooling to a wall of finite heat capacity C_w [J/K]: the
  wall temperature is a state, C_w dT_w/dt = -hA (T_w - T) + hA_out (T_amb - T_w), the wall
  also exchanging with the room through hA_out.
* :class:`DecayingExchange` - an exchange that changes with time: hA(s) = hA_nat +
  (hA_jet - hA_nat) exp(-s / tau_decay), s the time since the opening (the jet-driven
  mixing at the opening decaying toward natural convection).

The gas: ideal, uniform state, a rigid tank of volume V, c_v = R/(gamma - 1); state
(mass m, internal energy U = m c_v T, wall temperature T_w). Discharge: dm/dt = -G,
dU/dt = -G c_p T + Q; charge from a supply at (p_s, T_s): dm/dt = G, dU/dt = G c_p T_s + Q
(Q: heat into the gas [W]). The flow: ISO 6358-1:2013, G = C rho_N p_up sqrt(T_N/T_up)
phi(r), r = p_down/p_up, phi = 1 for r <= b, (1 - ((r-b)/(1-b))^2)^m for b < r < 0.999,
linear to 0 at r = 1 from its value at 0.999. Integrated with scipy's Radau at rtol 1e-10
from the opening (the tank at rest before it: every law starts with the gas at the wall's
temperature). Sensor: white Gaussian noise, seeded.

:func:`draw` makes a record's parameters from a seed as issue 52 states the ranges:
V 1-20 L and C 1e-9..2e-8 m^3/(s Pa) log-uniform (tau0 = V/(1.4e5 C), eq 28, limited
to 0.3-12 s so that a 1 kHz record stays below about 10^5 samples), p10 3-9 bar abs, b
0.2-0.5, m 0.35-0.65, the gas's largest cooling (a charge: heating) 3-25 K (the exchange's
strength solved for it), 300 Pa noise, 1 kHz, the opening between two samples, 6-9 tau0
recorded after a 0.3-1 s plateau. SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

RHO_N, T_N = 1.185, 293.15  # ISO 8778 reference density [kg/m^3] and temperature [K]
R_LINEAR = 0.999  # ISO 6358-1:2013: the flow law is linear from here to r = 1 [-]
R_AIR, GAMMA = 287.05, 1.4  # [J/(kg K)], [-]
P_ATM, T_ROOM = 101325.0, 293.15  # [Pa abs], [K]
NOISE = 300.0  # sensor noise, standard deviation [Pa]
RATE = 1e3  # sampling rate [Hz]
#: The difference at which each law's coefficient is stated as a conductance [K].
REFERENCE_DIFFERENCE = 10.0


def iso_phi(r: float, b: float, m: float) -> float:
    """ISO 6358-1:2013's phi(r) [-]: 1 when choked, (1 - x^2)^m with x = (r-b)/(1-b) up to
    r = 0.999, then linear to 0 at r = 1 (0 beyond: no reverse flow through the law)."""
    if r <= b:
        return 1.0
    if r < R_LINEAR:
        x = (r - b) / (1.0 - b)
        return max(1.0 - x * x, 0.0) ** m
    if r >= 1.0:
        return 0.0
    x = (R_LINEAR - b) / (1.0 - b)
    return (1.0 - x * x) ** m * (1.0 - r) / (1.0 - R_LINEAR)


# --- the heat laws: heat into the gas [W] from (time since opening s [s], rho/rho_0 [-],
# gas temperature [K], wall temperature [K]); ``strength`` multiplies every conductance.

@dataclass(frozen=True)
class PowerDifference:
    """q = k |dT|^n sign(dT), dT = T_w - T; k = strength hA_ref dT_ref^(1-n) [W/K^n]."""

    n: float
    h_ref: float = 1.0  # the conductance at REFERENCE_DIFFERENCE [W/K]
    strength: float = 1.0
    name: str = "power-difference"

    def heat(self, s: float, rho_ratio: float, temp: float, wall: float) -> float:
        d = wall - temp
        k = self.strength * self.h_ref * REFERENCE_DIFFERENCE ** (1.0 - self.n)
        return math.copysign(k * abs(d) ** self.n, d)

    def wall_rate(self, q: float, wall: float) -> float:
        return 0.0


@dataclass(frozen=True)
class DensityDifference:
    """q = k (rho/rho_0)^a |dT|^c dT; k = strength hA_ref dT_ref^(-c)."""

    a: float
    c: float
    h_ref: float = 1.0
    strength: float = 1.0
    name: str = "density-difference"

    def heat(self, s: float, rho_ratio: float, temp: float, wall: float) -> float:
        d = wall - temp
        k = self.strength * self.h_ref * REFERENCE_DIFFERENCE ** (-self.c)
        return k * max(rho_ratio, 0.0) ** self.a * abs(d) ** self.c * d

    def wall_rate(self, q: float, wall: float) -> float:
        return 0.0


@dataclass(frozen=True)
class WarmingWall:
    """Newton cooling hA (T_w - T) to a wall of heat capacity ``capacity`` [J/K] that also
    exchanges with the room (T_ROOM) through ``outer`` x hA."""

    capacity: float
    outer: float
    h_ref: float = 1.0
    strength: float = 1.0
    name: str = "warming-wall"

    def heat(self, s: float, rho_ratio: float, temp: float, wall: float) -> float:
        return self.strength * self.h_ref * (wall - temp)

    def wall_rate(self, q: float, wall: float) -> float:
        """dT_w/dt [K/s] given the heat q [W] the gas takes from the wall."""
        room = self.strength * self.h_ref * self.outer * (T_ROOM - wall)
        return (room - q) / self.capacity


@dataclass(frozen=True)
class DecayingExchange:
    """hA(s) = hA_nat + (hA_jet - hA_nat) exp(-s / tau_decay), s the time since the
    opening; hA_nat = strength hA_ref, hA_jet = ``jet`` hA_nat."""

    jet: float
    tau_decay: float
    h_ref: float = 1.0
    strength: float = 1.0
    name: str = "decaying-exchange"

    def heat(self, s: float, rho_ratio: float, temp: float, wall: float) -> float:
        h_nat = self.strength * self.h_ref
        h = h_nat * (1.0 + (self.jet - 1.0) * math.exp(-max(s, 0.0) / self.tau_decay))
        return h * (wall - temp)

    def wall_rate(self, q: float, wall: float) -> float:
        return 0.0


HeatLaw = PowerDifference | DensityDifference | WarmingWall | DecayingExchange
LAWS: tuple[str, ...] = ("power-difference", "density-difference", "warming-wall",
                         "decaying-exchange")


@dataclass(frozen=True)
class Rig:
    """A tank and its component: V [m^3], C [m^3/(s Pa)], b [-], m [-], the initial state
    (p10 [Pa abs], T10 [K], also the wall's), the far side (p_atm for a discharge, the
    supply p_s, T_s for a charge) and the direction."""

    volume: float
    conductance: float
    b: float
    m: float
    p10: float
    t10: float = T_ROOM
    p_atm: float = P_ATM
    direction: str = "discharge"
    p_supply: float = 0.0
    t_supply: float = T_ROOM

    @property
    def tau0(self) -> float:
        """eq 28's starting time constant V/(gamma p_N C) sqrt(T_N/T10) [s] (p_N 1e5)."""
        return self.volume / (GAMMA * 1e5 * self.conductance) * math.sqrt(T_N / self.t10)


def simulate(rig: Rig, law: HeatLaw | None, s: np.ndarray, *, rtol: float = 1e-10,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pressure [Pa abs], gas temperature [K] and wall temperature [K] at the times s >= 0
    [s] after the opening (``law`` None: adiabatic)."""
    cv = R_AIR / (GAMMA - 1.0)
    cp = cv + R_AIR
    m0 = rig.p10 * rig.volume / (R_AIR * rig.t10)
    charge = rig.direction == "charge"

    def rhs(t: float, y: np.ndarray) -> list[float]:
        mass, u, wall = y
        temp = u / (mass * cv)
        p = mass * R_AIR * temp / rig.volume
        if charge:
            g = rig.conductance * RHO_N * rig.p_supply * math.sqrt(T_N / rig.t_supply) \
                * iso_phi(p / rig.p_supply, rig.b, rig.m)
            h_flow = g * cp * rig.t_supply
        else:
            g = -rig.conductance * RHO_N * p * math.sqrt(T_N / temp) \
                * iso_phi(rig.p_atm / p, rig.b, rig.m)
            h_flow = g * cp * temp
        if law is None:
            return [g, h_flow, 0.0]
        q = law.heat(t, mass / m0, temp, wall)
        return [g, h_flow + q, law.wall_rate(q, wall)]

    y0 = [m0, m0 * cv * rig.t10, rig.t10]
    atol = [m0 * 1e-12, m0 * cv * rig.t10 * 1e-12, 1e-9]
    sol = solve_ivp(rhs, (0.0, float(s[-1])), y0, method="Radau", t_eval=s, rtol=rtol,
                    atol=atol)
    if not sol.success:
        raise RuntimeError(f"integration failed: {sol.message}")
    mass, u, wall = sol.y
    temp = u / (mass * cv)
    return mass * R_AIR * temp / rig.volume, temp, wall


@dataclass(frozen=True)
class Record:
    """One drawn record: the rig, the heat law (its strength solved for the cooling), the
    times [s], the noisy pressure [Pa abs], the noiseless one and the gas temperature [K],
    the opening instant [s], the largest |T - T10| [K], the draw's name."""

    name: str
    rig: Rig
    law: HeatLaw
    t: np.ndarray
    p: np.ndarray
    p_true: np.ndarray
    temperature: np.ndarray
    t_open: float
    cooling: float


def _largest_change(rig: Rig, law: HeatLaw, span: float) -> float:
    """The gas's largest |T - T10| [K] over ``span`` [s] after the opening (coarse)."""
    s = np.linspace(0.0, span, 600)
    _p, temp, _w = simulate(rig, law, s, rtol=1e-7)
    return float(np.max(np.abs(temp - rig.t10)))


def with_change(rig: Rig, law: HeatLaw, target: float, span: float) -> HeatLaw | None:
    """``law`` with the strength at which the gas's largest |T - T10| is ``target`` [K]
    (None when no strength in 1e-3..1e4 reaches it)."""

    def gap(log_f: float) -> float:
        return _largest_change(rig, replace(law, strength=math.exp(log_f)), span) - target

    lo, hi = math.log(1e-3), math.log(1e4)
    if gap(lo) < 0.0 or gap(hi) > 0.0:
        return None
    return replace(law, strength=math.exp(brentq(gap, lo, hi, xtol=1e-4)))


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _law(name: str, rng: np.random.Generator, h_ref: float, tau0: float,
         m0cv: float) -> HeatLaw:
    if name == "power-difference":
        return PowerDifference(float(rng.uniform(1.3, 1.6)), h_ref)
    if name == "density-difference":
        return DensityDifference(float(rng.uniform(0.8, 1.2)), float(rng.uniform(0.4, 0.7)),
                                 h_ref)
    if name == "warming-wall":
        return WarmingWall(_log_uniform(rng, 2.0, 20.0) * m0cv, _log_uniform(rng, 0.05, 0.5),
                           h_ref)
    if name == "decaying-exchange":
        return DecayingExchange(_log_uniform(rng, 3.0, 10.0), float(rng.uniform(0.1, 1.0))
                                * tau0, h_ref)
    raise ValueError(f"unknown heat law {name!r}; one of {', '.join(LAWS)}")


@dataclass(frozen=True)
class Drawn:
    """A draw's parameters: the rig, the heat law (its strength solved for the cooling),
    the opening instant [s] and the record's end [s]."""

    rig: Rig
    law: HeatLaw
    t_open: float
    t_end: float


def parameters(law_name: str, k: int, direction: str = "discharge") -> Drawn:
    """The parameters of draw ``k`` of ``law_name`` (seeded by both and the direction): see
    the module's text for the ranges. A draw whose tau0 is out of range or whose cooling no
    strength reaches is drawn again from the same generator (reproducible)."""
    rng = np.random.default_rng([zlib.crc32(f"{law_name}/{direction}".encode()), k])
    while True:
        volume = _log_uniform(rng, 1e-3, 20e-3)
        conductance = _log_uniform(rng, 1e-9, 2e-8)
        pressure = float(rng.uniform(3e5, 9e5))
        b, m = float(rng.uniform(0.2, 0.5)), float(rng.uniform(0.35, 0.65))
        change = float(rng.uniform(3.0, 25.0))
        recorded = float(rng.uniform(6.0, 9.0))
        plateau = float(rng.uniform(0.3, 1.0))
        if direction == "charge":
            rig = Rig(volume, conductance, b, m, P_ATM, direction="charge",
                      p_supply=pressure)
        else:
            rig = Rig(volume, conductance, b, m, pressure)
        tau0 = Rig(volume, conductance, b, m, pressure).tau0
        if not 0.3 <= tau0 <= 12.0:
            continue
        cv = R_AIR / (GAMMA - 1.0)
        m0cv = rig.p10 * volume / (R_AIR * rig.t10) * cv
        law = with_change(rig, _law(law_name, rng, m0cv / tau0, tau0, m0cv), change,
                          recorded * tau0)
        if law is not None:
            break
    # the opening between two samples: a fraction of a period after the plateau's end
    t_open = plateau + float(rng.uniform(0.0, 1.0)) / RATE
    return Drawn(rig, law, t_open, t_open + recorded * tau0)


def draw(law_name: str, k: int, direction: str = "discharge") -> Record:
    """Draw ``k`` of ``law_name``: :func:`parameters`, the record at 1 kHz and its noise."""
    d = parameters(law_name, k, direction)
    rig, law, t_open = d.rig, d.law, d.t_open
    t = np.arange(0.0, d.t_end, 1.0 / RATE)
    after = t >= t_open
    p_true = np.full(t.size, rig.p10)
    temp = np.full(t.size, rig.t10)
    p_true[after], temp[after], _w = simulate(rig, law, t[after] - t_open)
    noise = np.random.default_rng([zlib.crc32(f"noise/{law_name}/{direction}".encode()), k])
    p = p_true + noise.normal(0.0, NOISE, t.size)
    return Record(f"{law_name}-{direction}-{k}", rig, law, t, p, p_true, temp, t_open,
                  float(np.max(np.abs(temp - rig.t10))))
