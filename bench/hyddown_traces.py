"""Tank discharges simulated by HydDown, a peer code the package did not write.

HydDown (PyPI ``hyddown``, MIT, A. Andreasen) integrates the mass and energy balances of a
vessel with real-gas air (CoolProp HEOS), wall heat transfer (natural convection inside with
``h_inner: calc``, or a fixed ``h_inner``; the wall is a lumped steel shell) and the Yellow
Book orifice law. Each discharge of air to atmosphere (back pressure 101325 Pa) is written
to ``<out>/<name>.npz`` with

* ``t`` [s]: HydDown's own time grid (explicit Euler, step ``time_step``), float64,
* ``p`` [Pa absolute]: the vessel pressure on that grid, float64,
* ``meta``: a JSON string (vessel length/diameter [m], volume [m^3], L/D [-], wall, orifice
  diameter [m], Cd [-], p10 [Pa], T10 [K], heat-transfer settings, time step [s], the truth
  C [m^3/(s Pa)], tau0 [s] and the hyddown/CoolProp/numpy versions).

The truth is C = Cd A sqrt(gamma/R (2/(gamma+1))^((gamma+1)/(gamma-1))) / (rho_N sqrt(T_N)),
rho_N = 1.185 kg/m^3, T_N = 293.15 K, gamma = 1.4, R = 287.05 J/(kg K): HydDown's choked
mass flow Cd A sqrt(rho p k (2/(k+1))^((k+1)/(k-1))) in the ISO form C p rho_N sqrt(T_N/T)
for an ideal gas (CoolProp's Z of air at 8 bar and 293 K is 0.997, so the real-gas flow is
about 0.1 % above it).

Time step: HydDown steps by explicit Euler, whose decay rate is high by about dt/(2 tau);
dt = tau0 / 1000 (tau0 = V / (gamma C rho_N R T_N)) keeps that below 0.05 % of C. The run
lasts 8 tau0 (8000 steps, under ~130 kB per file; about 6 s of HydDown per run).

Runs ONLY in a venv with HydDown (it must not import pneumatic_unload)::

    python3 -m venv /tmp/hyd-venv && /tmp/hyd-venv/bin/pip install hyddown==0.50.0
    /tmp/hyd-venv/bin/python bench/hyddown_traces.py --grid small   # -> test/data/hyddown
    /tmp/hyd-venv/bin/python bench/hyddown_traces.py --grid full --out /tmp/hyd-full

Made with hyddown 0.50.0, CoolProp 8.0.0, numpy 2.4.6, scipy 1.17.1 on Python 3.11.7.
Without hyddown importable (e.g. ``make bench`` in the project venv) it says how to run it
and exits 0.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

GAMMA = 1.4  # air, ideal [-]
R_AIR = 287.05  # [J/(kg K)]
RHO_N = 1.185  # ISO 6358 reference density [kg/m^3]
T_N = 293.15  # ISO 6358 reference temperature [K]
P_BACK = 101325.0  # atmosphere [Pa abs]
STEPS_PER_TAU = 1000  # Euler steps per tau0 [-]
TAUS = 8.0  # run length in tau0 [-]
#: Steel wall: thickness [m], heat capacity [J/(kg K)], density [kg/m^3].
WALL = {"thickness": 0.005, "heat_capacity": 500.0, "density": 7800.0}
H_OUTER = 10.0  # outside wall to room [W/(m^2 K)]
SMALL_DIR = Path(__file__).resolve().parents[1] / "pneumatic_unload" / "test" / "data" / "hyddown"


@dataclass(frozen=True)
class Case:
    """One discharge: V [m^3], L/D [-], orifice d [m], Cd [-], p10 [Pa], T10 [K] and
    h_inner ('calc' or [W/(m^2 K)])."""

    name: str
    volume: float
    length_diameter_ratio: float
    orifice_diameter: float
    discharge_coef: float
    p10: float
    t10: float
    h_inner: str | float


def truth_conductance(orifice_diameter: float, discharge_coef: float) -> float:
    """Sonic conductance C of the orifice [m^3/(s Pa)] (ideal-gas choked flow, ISO 6358)."""
    area = math.pi * orifice_diameter**2 / 4.0
    g = GAMMA
    psi = math.sqrt(g / R_AIR * (2.0 / (g + 1.0)) ** ((g + 1.0) / (g - 1.0)))
    return discharge_coef * area * psi / (RHO_N * math.sqrt(T_N))


def tau0(case: Case) -> float:
    """Adiabatic-start time constant V / (gamma C rho_N R T_N) [s]."""
    c = truth_conductance(case.orifice_diameter, case.discharge_coef)
    return case.volume / (GAMMA * c * RHO_N * R_AIR * T_N)


def small_grid() -> list[Case]:
    """The six committed cases: 1-50 L, L/D 1-6, d 1-3 mm, Cd 0.6-0.9, p10 4-8 bar abs,
    three with ``calc`` and three with a fixed h_inner (2, 10, 50 W/(m^2 K))."""
    return [
        Case("v1l_ld1_d1_calc", 1e-3, 1.0, 1.0e-3, 0.60, 6e5, 293.15, "calc"),
        Case("v2l_ld4_d2_h2", 2e-3, 4.0, 2.0e-3, 0.80, 8e5, 293.15, 2.0),
        Case("v50l_ld3_d3_calc", 50e-3, 3.0, 3.0e-3, 0.90, 8e5, 293.15, "calc"),
        Case("v10l_ld6_d2p5_h50", 10e-3, 6.0, 2.5e-3, 0.70, 4e5, 293.15, 50.0),
        Case("v20l_ld2_d3_h10", 20e-3, 2.0, 3.0e-3, 0.75, 5e5, 293.15, 10.0),
        Case("v5l_ld1p5_d1p5_calc_t303", 5e-3, 1.5, 1.5e-3, 0.85, 7e5, 303.15, "calc"),
    ]


def full_grid(n: int = 24, seed: int = 20240611, tau_max: float = 60.0) -> list[Case]:
    """``n`` cases drawn (fixed seed) over V 1-50 L (log), L/D 1-6, d 1-3 mm, Cd 0.6-0.9,
    p10 4-8 bar abs, T10 293.15 K; even cases ``calc``, odd ones h_inner 2-50 W/(m^2 K)
    (log). Draws with tau0 > ``tau_max`` [s] are redrawn (a 50 L tank on a 1 mm orifice
    lasts ~3000 s, 3 million samples at 1 kHz)."""
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    while len(cases) < n:
        k = len(cases)
        h: str | float = "calc" if k % 2 == 0 else round(float(math.exp(
            rng.uniform(math.log(2.0), math.log(50.0)))), 2)
        case = Case(
            name=f"full{k:02d}",
            volume=round(float(math.exp(rng.uniform(math.log(1e-3), math.log(50e-3)))), 6),
            length_diameter_ratio=round(float(rng.uniform(1.0, 6.0)), 2),
            orifice_diameter=round(float(rng.uniform(1e-3, 3e-3)), 6),
            discharge_coef=round(float(rng.uniform(0.6, 0.9)), 3),
            p10=round(float(rng.uniform(4e5, 8e5)), -2),
            t10=293.15,
            h_inner=h,
        )
        if tau0(case) <= tau_max:
            cases.append(case)
    return cases


def config(case: Case) -> tuple[dict, float, float, float]:
    """HydDown input dict, vessel length [m], diameter [m] and time step [s] of a case."""
    diameter = (4.0 * case.volume / (math.pi * case.length_diameter_ratio)) ** (1.0 / 3.0)
    length = case.length_diameter_ratio * diameter
    dt = tau0(case) / STEPS_PER_TAU
    cfg = {
        "vessel": {"length": length, "diameter": diameter, **WALL,
                   "orientation": "vertical"},  # Nusselt on the length, as the package
        "initial": {"temperature": case.t10, "pressure": case.p10, "fluid": "air"},
        "calculation": {"type": "energybalance", "time_step": dt,
                        "end_time": TAUS * STEPS_PER_TAU * dt},
        "valve": {"flow": "discharge", "type": "orifice", "diameter": case.orifice_diameter,
                  "discharge_coef": case.discharge_coef, "back_pressure": P_BACK},
        "heat_transfer": {"type": "specified_h", "temp_ambient": case.t10,
                          "h_outer": H_OUTER, "h_inner": case.h_inner},
    }
    return cfg, length, diameter, dt


def versions() -> dict[str, str]:
    """Installed versions of the simulator's stack."""
    return {m: importlib.metadata.version(m) for m in ("hyddown", "CoolProp", "numpy")}


def run_case(case: Case, out: Path) -> Path:
    """Run HydDown for one case and write ``out/<name>.npz`` (t [s], p [Pa abs], meta)."""
    from hyddown import HydDown

    cfg, length, diameter, dt = config(case)
    hd = HydDown(cfg)
    start = time.perf_counter()
    hd.run(disable_pbar=True)
    seconds = time.perf_counter() - start
    t = np.asarray(hd.time_array, dtype=np.float64)
    p = np.asarray(hd.P, dtype=np.float64)
    meta = {
        **asdict(case),
        "vessel_length": length, "vessel_diameter": diameter, "volume_hyddown": float(hd.vol),
        "wall": WALL, "heat_transfer": cfg["heat_transfer"], "time_step": dt,
        "end_time": cfg["calculation"]["end_time"], "back_pressure": P_BACK,
        "truth_conductance": truth_conductance(case.orifice_diameter, case.discharge_coef),
        "tau0": tau0(case), "t_gas_min": float(np.min(hd.T_fluid)),
        "t_wall_min": float(np.min(hd.T_vessel)), "p_end": float(p[-1]),
        "run_seconds": round(seconds, 2), "versions": versions(),
    }
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{case.name}.npz"
    np.savez_compressed(path, t=t, p=p, meta=json.dumps(meta))
    print(f"{case.name}: tau0 {meta['tau0']:.3g} s, {t.size} steps, {seconds:.1f} s, "
          f"p_end {p[-1]:.0f} Pa, T_gas min {meta['t_gas_min']:.1f} K, "
          f"{path.stat().st_size / 1e3:.0f} kB", flush=True)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--grid small|full`` and ``--out DIR``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", choices=("small", "full"), default="small")
    ap.add_argument("--out", type=Path, default=None,
                    help="output folder (small: test/data/hyddown; full: a temp dir)")
    args = ap.parse_args(argv)
    try:
        import hyddown  # noqa: F401
    except ImportError:
        print("hyddown is not installed here; run it in its own venv:\n"
              "  python3 -m venv /tmp/hyd-venv && /tmp/hyd-venv/bin/pip install hyddown==0.50.0\n"
              "  /tmp/hyd-venv/bin/python bench/hyddown_traces.py --grid small")
        return 0
    if args.out is not None:
        out = args.out
    elif args.grid == "small":
        out = SMALL_DIR
    else:
        out = Path(tempfile.mkdtemp(prefix="hyddown-full-"))
    cases = small_grid() if args.grid == "small" else full_grid()
    for case in cases:
        run_case(case, out)
    print(f"{len(cases)} traces in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
