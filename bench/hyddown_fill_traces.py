"""Tank fills (charges) simulated by HydDown, a peer code the package did not write.

HydDown (PyPI ``hyddown``, MIT, A. Andreasen) integrates the mass and energy balances of a
vessel with real-gas air (CoolProp HEOS), wall heat transfer and the Yellow Book orifice
law; with ``valve: {flow: filling, back_pressure: p_s}`` the orifice feeds the vessel from a
reservoir held at p_s and at the vessel's initial temperature (HydDown builds that state at
(back_pressure, T0), hdclass.py:389-392, so T_s = T10 here). Two supply regimes: a supply
of 3-8 bar abs into a tank at 1 bar (p10 = 1e5 Pa), and the room (p_s = 101325 Pa) into a
tank at 2-10 kPa. Two heat-transfer kinds: ``h_inner: calc``, which for a fill is HydDown's
mixed law driven by the incoming jet (hdclass.py:1241-1264, transport.py:189-228:
h = (Nu_free + 0.56 Re^0.67) k/L, Re = 4 |mdot|/(mu pi D) on the vessel diameter D: the
``D_throat`` it reads, hdclass.py:289-292, is passed nowhere, and its Grashof number takes
the wall at t = 0, ``T_inner_wall[i - i]``, hdclass.py:1260), or a fixed h_inner
[W/(m^2 K)] (hdclass.py:1393; Q = h A_inner (T_wall - T), hdclass.py:1427-1431); the
wall is a lumped 5 mm steel shell (h_outer 10 W/(m^2 K) to a room at T10). ``--heat
adiabatic`` replaces either by ``specified_Q`` with Q_fix = 0 (no wall exchange: the flow
law and the gas alone). Each fill is written to ``<out>/<name>.npz`` with

* ``t`` [s]: HydDown's own time grid (explicit Euler, step ``time_step``), float64,
* ``p`` [Pa absolute]: the vessel pressure on that grid, float64,
* ``T`` [K]: the mean gas temperature on that grid, float64,
* ``T_wall`` [K], ``h_inner`` [W/(m^2 K)] (HydDown's inside coefficient, 0 at t = 0 and
  when adiabatic) and ``mdot`` [kg/s] (into the vessel) on that grid, float64,
* ``meta``: a JSON string (vessel length/diameter [m], volume [m^3], inner wall area
  [m^2], L/D [-], wall, orifice diameter [m], Cd [-], p10 [Pa], T10 [K], supply p_s [Pa]
  and T_s [K], regime, heat-transfer settings and h_inner A_inner [W/K] when fixed, time
  step [s], the truth C [m^3/(s Pa)], tau0 [s], t63 [s] (p reaches p10 + 0.632 (p_s -
  p10)), ``blend`` ("shipped" or "removed"), the flow work the blend left out [J], and the
  hyddown/CoolProp/numpy versions).

The truth is C = Cd A sqrt(gamma/R (2/(gamma+1))^((gamma+1)/(gamma-1))) / (rho_N sqrt(T_N)),
rho_N = 1.185 kg/m^3, T_N = 293.15 K, gamma = 1.4, R = 287.05 J/(kg K), as in
``bench/hyddown_traces.py``: HydDown's choked mass flow Cd A sqrt(rho_s p_s k
(2/(k+1))^((k+1)/(k-1))) (transport.py:718-775, rho_s, k of the supply) in the ISO form
C p_s rho_N sqrt(T_N/T_s) for an ideal gas (CoolProp's Z of air at 8 bar and 293 K is
0.997, so the real-gas flow is about 0.1 % above it). Its subsonic factor is the
isentropic nozzle's, b = (2/(k+1))^(k/(k-1)) = 0.528; the ISO ellipse with b = 0.528 and
m = 0.5 is within 0.0015 of it over b < r < 1 (least squares: m = 0.498).

The u-to-h blend: HydDown 0.50 lets the inflow carry x h_s + (1 - x) u_s with
x = 1 - exp(-t)^0.66 = 1 - exp(-0.66 t), t in seconds (hdclass.py:2327-2334, "Smooting
finction for very early times /numerical trick"), so for the first seconds of a fill the
flow work p_s/rho_s is left out and the gas heats less than it should. ``--blend removed``
takes it out without touching HydDown's files: after ``HydDown(cfg)`` has built the
supply state ``hd.res_fluid`` (a CoolProp AbstractState, hdclass.py:389-392), it is
wrapped in a proxy whose ``umass()`` returns the supply's ``hmass()`` and which delegates
every other attribute; ``res_fluid.umass()`` is read nowhere else (hdclass.py:2334 only),
so h_in = x h_s + (1 - x) h_s = h_s at every step. Check: the energy residual
U - U0 - (m - m0) h_s - sum Q dt stays below 2e-9 J (round-off) with it removed
(``energy_residual_max`` in the meta), and an adiabatic fill (1 L, 1 mm, 6 bar) with it
removed equals HydDown's own non-equilibrium branch (which uses h_s with no blend,
hdclass.py:2551-2552) to 5 digits in T_end and t63. ``--blend shipped`` runs HydDown as
installed; the meta records the flow work it left out.

Time step: HydDown steps by explicit Euler. While the orifice is choked the inflow is the
supply's alone, constant, and Euler integrates mass and (adiabatic) energy exactly; in the
subsonic end and through the wall exchange its rates are off by about dt/(2 tau) as in a
discharge, so dt = tau0 / 1000 (tau0 = V / (gamma C rho_N R T_N)) keeps that below 0.05 %
of C. Measured on the small grid (blend removed): t63 moves by 0.002-0.015 % from
dt = tau0/1000 to tau0/4000 (``--steps-per-tau 4000``). The run lasts 4 tau0 (4000 steps,
under ~160 kB per file; an adiabatic fill is over by about 1.3 tau0; 0.6-0.8 s of HydDown
per run, ~5 s for the small grid and ~16 s for the full one).

Runs ONLY in a venv with HydDown (it must not import pneumatic_unload)::

    python3 -m venv /tmp/hyd-venv && /tmp/hyd-venv/bin/pip install hyddown==0.50.0
    /tmp/hyd-venv/bin/python bench/hyddown_fill_traces.py --grid small --blend removed \\
        --out test/data/hyddown_fill     # the six fills test/test_hyddown_fill.py reads
    /tmp/hyd-venv/bin/python bench/hyddown_fill_traces.py --grid small --blend shipped \\
        --out /tmp/hyd-fill-small-shipped
    /tmp/hyd-venv/bin/python bench/hyddown_fill_traces.py --grid full --blend removed \\
        --out /tmp/hyd-fill-full-removed

Made with hyddown 0.50.0, CoolProp 8.0.0, numpy 2.4.6, scipy 1.17.1 on Python 3.11.7.
Without hyddown importable (e.g. ``make bench`` in the project venv) it says how to run it
and exits 0.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run from anywhere
# the discharge script's constants (air, ISO 6358's reference, the steel wall) and its truth C
from hyddown_traces import (
    GAMMA,
    H_OUTER,
    R_AIR,
    RHO_N,
    T_N,
    WALL,
    truth_conductance,
    versions,
)

P_ROOM = 101325.0  # the room as a supply [Pa abs]
P_TANK_1BAR = 1e5  # a tank at 1 bar [Pa abs]
STEPS_PER_TAU = 1000  # Euler steps per tau0 [-]
TAUS = 4.0  # run length in tau0 [-]
RISE_FRACTION = 0.632  # t63: p = p10 + 0.632 (p_s - p10)
BLENDS = ("shipped", "removed")


@dataclass(frozen=True)
class Case:
    """One fill: V [m^3], L/D [-], orifice d [m], Cd [-], p10 [Pa], T10 [K] (= T_s and the
    room's), supply p_s [Pa] and h_inner ('calc', 'adiabatic' or [W/(m^2 K)])."""

    name: str
    volume: float
    length_diameter_ratio: float
    orifice_diameter: float
    discharge_coef: float
    p10: float
    t10: float
    supply_pressure: float
    h_inner: str | float


def tau0(case: Case) -> float:
    """Time constant V / (gamma C rho_N R T_N) [s] (a choked fill from T_s = T_N raises p
    at p_s / tau0)."""
    c = truth_conductance(case.orifice_diameter, case.discharge_coef)
    return case.volume / (GAMMA * c * RHO_N * R_AIR * T_N)


def regime(case: Case) -> str:
    """'room' (the room into an evacuated tank) or 'supply' (a supply into a tank at 1
    bar)."""
    return "room" if case.supply_pressure == P_ROOM else "supply"


def small_grid() -> list[Case]:
    """Six cases: 1-50 L, L/D 1-6, d 1-3 mm, Cd 0.6-0.9; three from a 3-8 bar supply into
    1 bar, three from the room into 2-10 kPa; three ``calc`` (jet-driven mixed convection),
    three with a fixed h_inner (2, 10, 50 W/(m^2 K)); one at T10 = T_s = 303.15 K."""
    return [
        Case("v1l_ld1_d1_s6bar_calc", 1e-3, 1.0, 1.0e-3, 0.60, P_TANK_1BAR, 293.15, 6e5,
             "calc"),
        Case("v2l_ld4_d2_s8bar_h10", 2e-3, 4.0, 2.0e-3, 0.80, P_TANK_1BAR, 293.15, 8e5,
             10.0),
        Case("v50l_ld3_d3_room2k_calc", 50e-3, 3.0, 3.0e-3, 0.90, 2e3, 293.15, P_ROOM,
             "calc"),
        Case("v10l_ld6_d2p5_room5k_h50", 10e-3, 6.0, 2.5e-3, 0.70, 5e3, 293.15, P_ROOM,
             50.0),
        Case("v20l_ld2_d3_s3bar_h2", 20e-3, 2.0, 3.0e-3, 0.75, P_TANK_1BAR, 293.15, 3e5,
             2.0),
        Case("v5l_ld1p5_d1p5_room10k_calc_t303", 5e-3, 1.5, 1.5e-3, 0.85, 1e4, 303.15,
             P_ROOM, "calc"),
    ]


def full_grid(n: int = 24, seed: int = 20240612, tau_max: float = 60.0) -> list[Case]:
    """``n`` cases drawn (fixed seed) over V 1-50 L (log), L/D 1-6, d 1-3 mm, Cd 0.6-0.9,
    T10 = T_s = 293.15 K; case k: k % 4 in (0, 1) a supply of 3-8 bar abs into 1 bar, in
    (2, 3) the room into 2-10 kPa; even k ``calc``, odd k h_inner 2-50 W/(m^2 K) (log).
    Draws with tau0 > ``tau_max`` [s] are redrawn (as ``bench/hyddown_traces.py``: a 50 L
    tank on a 1 mm orifice fills in ~500 s, half a million samples at 1 kHz)."""
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    while len(cases) < n:
        k = len(cases)
        h: str | float = "calc" if k % 2 == 0 else round(float(math.exp(
            rng.uniform(math.log(2.0), math.log(50.0)))), 2)
        volume = round(float(math.exp(rng.uniform(math.log(1e-3), math.log(50e-3)))), 6)
        ld = round(float(rng.uniform(1.0, 6.0)), 2)
        d = round(float(rng.uniform(1e-3, 3e-3)), 6)
        cd = round(float(rng.uniform(0.6, 0.9)), 3)
        if k % 4 < 2:
            p10, p_s = P_TANK_1BAR, round(float(rng.uniform(3e5, 8e5)), -2)
        else:
            p10, p_s = round(float(rng.uniform(2e3, 10e3)), 0), P_ROOM
        case = Case(name=f"full{k:02d}", volume=volume, length_diameter_ratio=ld,
                    orifice_diameter=d, discharge_coef=cd, p10=p10, t10=293.15,
                    supply_pressure=p_s, h_inner=h)
        if tau0(case) <= tau_max:
            cases.append(case)
    return cases


def adiabatic(case: Case) -> Case:
    """The case with no wall exchange (``specified_Q``, Q_fix = 0), named ``<name>_adiab``."""
    d = asdict(case)
    d.update(name=f"{case.name}_adiab", h_inner="adiabatic")
    return Case(**d)


def config(case: Case, steps_per_tau: int = STEPS_PER_TAU) -> tuple[dict, float, float,
                                                                      float]:
    """HydDown input dict, vessel length [m], diameter [m] and time step [s] of a case."""
    diameter = (4.0 * case.volume / (math.pi * case.length_diameter_ratio)) ** (1.0 / 3.0)
    length = case.length_diameter_ratio * diameter
    dt = tau0(case) / steps_per_tau
    if case.h_inner == "adiabatic":
        heat: dict[str, Any] = {"type": "specified_Q", "Q_fix": 0.0}
    else:
        heat = {"type": "specified_h", "temp_ambient": case.t10, "h_outer": H_OUTER,
                "h_inner": case.h_inner}
    cfg = {
        "vessel": {"length": length, "diameter": diameter, **WALL,
                   "orientation": "vertical"},  # Nusselt on the length, as the package
        "initial": {"temperature": case.t10, "pressure": case.p10, "fluid": "air"},
        "calculation": {"type": "energybalance", "time_step": dt,
                        "end_time": TAUS * steps_per_tau * dt},
        "valve": {"flow": "filling", "type": "orifice", "diameter": case.orifice_diameter,
                  "discharge_coef": case.discharge_coef,
                  "back_pressure": case.supply_pressure},
        "heat_transfer": heat,
    }
    return cfg, length, diameter, dt


class FullEnthalpySupply:
    """HydDown's supply state (a CoolProp AbstractState) whose ``umass()`` answers the
    ``hmass()``: HydDown's inflow enthalpy x h + (1 - x) u (hdclass.py:2334) becomes h at
    every step. Every other attribute is the wrapped state's."""

    def __init__(self, state: Any) -> None:
        self._state = state

    def __getattr__(self, name: str) -> Any:
        return getattr(self._state, name)

    def umass(self) -> float:
        """The supply's specific enthalpy [J/kg] in the place of its internal energy."""
        return float(self._state.hmass())


def rise_time(t: np.ndarray, p: np.ndarray, p10: float, p_s: float,
              fraction: float = RISE_FRACTION) -> float:
    """First instant [s] at which p reaches p10 + fraction (p_s - p10) (linear between
    steps; nan if it never does)."""
    target = p10 + fraction * (p_s - p10)
    above = np.nonzero(p >= target)[0]
    if above.size == 0 or above[0] == 0:
        return float("nan")
    k = int(above[0])
    return float(np.interp(target, [p[k - 1], p[k]], [t[k - 1], t[k]]))


def run_case(case: Case, out: Path, blend: str, steps_per_tau: int = STEPS_PER_TAU
             ) -> Path:
    """Run HydDown for one fill and write ``out/<name>.npz`` (t, p, T, T_wall, h_inner,
    mdot, meta)."""
    from hyddown import HydDown

    cfg, length, diameter, dt = config(case, steps_per_tau)
    hd = HydDown(cfg)  # builds hd.res_fluid, the supply at (p_s, T10)
    if blend == "removed":
        hd.res_fluid = FullEnthalpySupply(hd.res_fluid)
    start = time.perf_counter()
    hd.run(disable_pbar=True)
    seconds = time.perf_counter() - start
    t = np.asarray(hd.time_array, dtype=np.float64)
    p = np.asarray(hd.P, dtype=np.float64)
    temp = np.asarray(hd.T_fluid, dtype=np.float64)
    mass = np.asarray(hd.mass_fluid, dtype=np.float64)
    h_s, u_s = float(hd.res_fluid.hmass()), float(hd.res_fluid._state.umass()
                                                  if blend == "removed"
                                                  else hd.res_fluid.umass())
    # energy the gas lacks against a full-enthalpy inflow: 0 with the blend removed
    heat_in = np.cumsum(dt * (np.asarray(hd.Q_inner) + np.asarray(hd.Q_inner_wetted)))
    residual = hd.U_mass * mass - hd.U_mass[0] * mass[0] - (mass - mass[0]) * h_s - heat_in
    area = float(hd.surf_area_inner)
    fixed = isinstance(case.h_inner, (int, float))
    t63 = rise_time(t, p, case.p10, case.supply_pressure)
    h_trace = np.asarray(hd.h_inside, dtype=np.float64)
    upto63 = (t > 0) & (t <= t63) if math.isfinite(t63) else t > 0
    meta = {
        **asdict(case),
        "supply_temperature": case.t10, "regime": regime(case),
        "vessel_length": length, "vessel_diameter": diameter,
        "volume_hyddown": float(hd.vol), "inner_area": area,
        "wall": WALL, "heat_transfer": cfg["heat_transfer"],
        "h_inner_area": float(case.h_inner) * area if fixed else None,
        "h_inner_mean_to_t63": float(np.mean(h_trace[upto63]))
        if case.h_inner == "calc" else None,
        "time_step": dt, "steps_per_tau": steps_per_tau,
        "end_time": cfg["calculation"]["end_time"],
        "truth_conductance": truth_conductance(case.orifice_diameter, case.discharge_coef),
        "tau0": tau0(case), "t63": t63, "blend": blend,
        "blend_patch": ("hd.res_fluid wrapped after HydDown(cfg): umass() returns hmass() "
                        "(inflow carries h_s at every step)") if blend == "removed" else
                       "none (hdclass.py:2329-2334 as installed: x h_s + (1-x) u_s, "
                       "x = 1 - exp(-0.66 t))",
        "supply_h": h_s, "supply_u": u_s,
        "flow_work_total": float((mass[-1] - mass[0]) * (h_s - u_s)),
        "flow_work_missing": float(-residual[-1]),
        "energy_residual_max": float(np.max(np.abs(residual))),
        "t_gas_max": float(np.max(temp)), "t_gas_min": float(np.min(temp)),
        "t_wall_max": float(np.max(hd.T_vessel)), "t_wall_min": float(np.min(hd.T_vessel)),
        "p_end": float(p[-1]), "run_seconds": round(seconds, 2), "versions": versions(),
    }
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{case.name}.npz"
    np.savez_compressed(path, t=t, p=p, T=temp,
                        T_wall=np.asarray(hd.T_vessel, dtype=np.float64), h_inner=h_trace,
                        mdot=-np.asarray(hd.mass_rate, dtype=np.float64),
                        meta=json.dumps(meta))
    print(f"{case.name} [{blend}]: tau0 {meta['tau0']:.3g} s, {t.size} steps, "
          f"{seconds:.1f} s, t63 {t63:.4g} s, p_end {p[-1]:.0f} Pa, T_gas max "
          f"{meta['t_gas_max']:.1f} K, flow work left out {meta['flow_work_missing']:.3g} "
          f"of {meta['flow_work_total']:.3g} J, {path.stat().st_size / 1e3:.0f} kB",
          flush=True)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--grid small|full``, ``--blend shipped|removed``, ``--heat
    grid|adiabatic``, ``--steps-per-tau N`` and ``--out DIR``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", choices=("small", "full"), default="small")
    ap.add_argument("--blend", choices=BLENDS, default="removed",
                    help="HydDown's u-to-h inflow blend as installed, or taken out")
    ap.add_argument("--heat", choices=("grid", "adiabatic"), default="grid",
                    help="the grid's heat transfer, or none (Q_fix = 0) on every case")
    ap.add_argument("--steps-per-tau", type=int, default=STEPS_PER_TAU,
                    help="Euler steps per tau0 (time-step check)")
    ap.add_argument("--out", type=Path, default=None, help="output folder (a temp dir)")
    args = ap.parse_args(argv)
    try:
        import hyddown  # noqa: F401
    except ImportError:
        print("hyddown is not installed here; run it in its own venv:\n"
              "  python3 -m venv /tmp/hyd-venv && /tmp/hyd-venv/bin/pip install hyddown==0.50.0\n"
              "  /tmp/hyd-venv/bin/python bench/hyddown_fill_traces.py --grid small "
              "--blend removed --out /tmp/hyd-fill-small-removed")
        return 0
    out = args.out if args.out is not None else Path(
        tempfile.mkdtemp(prefix=f"hyddown-fill-{args.grid}-{args.blend}-"))
    cases = small_grid() if args.grid == "small" else full_grid()
    if args.heat == "adiabatic":
        cases = [adiabatic(c) for c in cases]
    start = time.perf_counter()
    for case in cases:
        run_case(case, out, args.blend, args.steps_per_tau)
    print(f"{len(cases)} traces in {out} ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
