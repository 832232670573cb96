"""Records that carry a logged gas temperature, analysed with and without it: a script, not a test.

``python bench/bench_temperature_records.py [--quick] [--jobs N] [--seeds K] [--atmosphere]
[--record-only]``
(project venv, ``PYTHONPATH`` at the repo root): multi-rate CSV logs (``time [s]``,
``pressure [kPa]`` at every row, ``gas temperature [C]`` at every k-th row, empty cells
between) of discharges made by the independent model
``pneumatic_unload/test/foreign/newton_tank.py``
(Newton cooling, Radau at rtol 1e-10; it imports nothing from the package), each analysed
as a bench user would, ``pneumatic-unload analyze log.csv --volume V --json`` (T10 and the
wall not given), twice: with the temperature column and without it (the same pressure
readings, the column dropped). ``--atmosphere``: ``--atmosphere 101325`` passed as well
(the transducer's zero offset is fitted only when p_atm is given; without it the offset
cases measure what an unstated barometer costs).

The grid (the issue's acceptance text; 24 cases, the factors cycled over them, not their
product; every draw seeded by the case's name and the seed index):

* hot starts: T10 = wall + dT, dT 0, 5, 10, 20, 30 K (the wall the room, 293.15 K; half the
  cases dT = 0); on a hot start the independent model cools the closed tank from the
  record's first instant, so the plateau before the opening decays;
* tau_heat 5, 10, 20, 40, 60 s; ISO law C 3e-9 - 1.5e-8 m^3/(s Pa), b 0.2-0.5, m 0.5;
  V 2-20 L (tau0 = V / (1.4e5 C) 1-14 s); p10 5-8 bar abs; p_atm 101325 Pa;
* plateau 1, 2, 5, 10 s before the opening; records to 6-9 tau0 after it;
* pressure at 100-1000 Hz, white noise 1000 Pa (0.1 % of a 1 MPa full scale), a transducer
  zero offset 0 to +-3 kPa (it reads p + offset), written in kPa to 0.1 Pa;
* the thermocouple (written here, not the package's): a first-order lag of 0.5-5 s (the
  exact update for a piecewise-linear gas temperature on the pressure's grid), starting at
  the gas temperature of the first instant, or on hot starts 2-4 K below it (it lagged
  during the charge), Gaussian noise 0.2-0.5 K, quantised to the logger's 0.1 K, logged at
  1, 2, 5 or 10 Hz.

Printed: a Markdown table with a row per analysis (truth, C error [%] and z = error /
sigma(C), b error and z_b, the offset fitted and its error, the temperature evidence
(rms / noise, ``follows``, the fitted sensor lag), status, CPU s of ``analyze`` in the
worker), a summary per family (with / without the temperature, hot / not hot) and the
worst analyses with their status text. The acceptance: C within 1 % with the temperature
(2 % without), |z_C| <= 2 in 90-98 % of trials, b within 0.03 and |z_b| <= 2,
``gas_temperature.rms`` <= 2 x its noise, the offset within 500 Pa (a NaN offset, not
fitted, is a miss when |true offset| > 500 Pa, a hit otherwise). ``--quick``: four traces.
``--jobs N``: N processes. ``--seeds K``: each case with K noise draws.

Measured on main b62d749 (2 cores, ``--jobs 2``: 106 s wall for the 24 traces, 48
analyses; with ``--atmosphere`` 125 s and every number the same: the grid's p_atm is
analyze's default, and the offset was fitted without it too):

* Not hot (12 traces): with and without the temperature alike, C within 1 % 12/12 (max
  0.26 %), b within 0.03 12/12 (max 0.008), offsets within 500 Pa 12/12, the temperature
  followed (rms <= 2 x noise) 12/12, sensor lags recovered (0.5-5 s); z_C SD 0.06-0.07:
  |z_C| <= 2 in 100 %, sigma(C) much wider than the 90-98 % asks.
* Hot starts with the temperature (12): C within 1 % 10/12, |z_C| <= 2 11/12, b within
  0.03 9/12, rms <= 2 x noise 8/12, offset 11/12. Failures: c11-hot30 (30 K, tau_h 10 s,
  10 s plateau, tau0 1 s) C -82.5 %, b NaN, residual RMS 500 x noise, the temperature
  departs by 36 K; c21-hot20 (20 K, tau_h 10 s, 10 s plateau) C -19.8 %, b NaN,
  "model inadequate", the temperature departs by 38 K (lag 0.05 s, offset +56 K fitted);
  c03-hot30 (30 K, tau_h 40 s) C -0.03 % but b 0.091 for 0.2 (z_b -7), the temperature
  departs (15 x noise); c13-hot20 (1 Hz temperature) follows only to 3.6 x noise.
* Hot starts without the temperature (12): C within 2 % 6/12, |z_C| <= 2 4/12 (z_C mean
  +2.3, SD 3.6): C biased high, +0.6-0.9 % (5 K), +1.4-1.6 % (10 K), +2.1-5.7 % (20-30 K;
  z up to 7.7), the two long-plateau failures as above (-82 %, -17 %); the temperature
  column removes the bias (the same traces with it: within 0.62 %).
* CPU per analysis: 2.6 s mean (max 6.4) with the temperature, 1.2 s (3.1) without, not
  hot; 4.0 (8.2) and 2.1 (3.8) on hot starts. Status: ok_subsonic 15/24, ok 9/24 either
  way (ok_subsonic: 15 of the 16 cases with b 0.2-0.3, p* below p_atm / b).

Measured after the joint fit (the gas temperature fitted with the pressure: T10 and the
thermometer's lag parameters), the start found on a drifting plateau and a hot start read
as a warm gas where T10 is not measured (main d99a694; 105 s wall):

* With the temperature, all 24: C within 1 % 24/24 (max 0.13 %), |z_C| <= 2 24/24, b
  within 0.03 24/24 (max 0.012), |z_b| <= 2 24/24, the temperature followed 24/24 (rms <=
  2 x its noise; c03-hot30: lag 0.90 s for 1, T10 322.1 K at the opening for about 321.7),
  offsets within 500 Pa 24/24; the long-plateau starts found (c11-hot30 -82.5 % -> -0.01 %,
  c21-hot20 -19.8 % -> -0.02 %). z_C SD 0.09: sigma(C) with the default inputs is wider
  than 90-98 % asks (``--record-only`` for the record's own).
* Without the temperature, hot (12): C within 2 % 10/12 (6/12 before), |z_C| <= 2 11/12
  (4/12). c13-hot20 +5.74 % (z +7.7): a 1 s plateau at 100 Hz whose drift is 3.5 of its
  sigmas (5 are needed to offer the hot start): the record does not show the gas is warm.
  c15-hot5 +2.05 % (z +1.6): a 5 K warm gas is within a room's spread (3 x 2 K), not
  claimed. Not hot: unchanged, 12/12.
* CPU per analysis with the temperature: 2.8 s mean (6.2 max) not hot, 10.0 s (20.1) hot
  starts (the joint family, up to 3 passes of its weight); without: 1.4 (3.5), 2.3 (4.5).

Measured after the hot start's first-order screen (main 17a3af2; the same figures at
42704bd, where a cold gas needs a plateau rising by 5 sigma): a plateau's drift from 2 of
its sigmas, and where T10 is not measured the warm gas's twin on every record; the
thermometer's offset fitted where the wall is given (not here); ``--record-only``
dropping T10's line with the column:

* Default inputs (24 traces, 98 s wall): unchanged with the temperature (C, b, rms,
  offsets 24/24; z_C SD 0.09); without it, hot: C within 2 % 11/12 (10/12 before), |z_C|
  <= 2 12/12 (11/12): c13-hot20 +5.74 % (z 7.7) -> -1.11 % (z -0.5), T10 316.6 K read
  for 313; c15-hot5 +2.05 % (z 1.6), its 5 K within a room's spread, remains.
* ``--record-only --seeds 2`` (48 traces, 156 s): with the temperature C within 1 % 48/48,
  |z_C| <= 2 45/48 (94 %, z_C SD 0.81: the record's own sigma honest once T10's line
  goes with the probe's exactness), b 48/48, temperature followed 48/48, offsets 48/48;
  without it, not hot 24/24; hot C within 2 % 23/24 (21/24 before), |z_C| <= 2 21/24
  (88 %; 19/24 before): c13-hot20's second draw, whose drift is under 2 sigma, +5.71 %
  (z 17.9) -> -0.37 %; c23-hot5 (+0.87 %, z 2.6 and 2.1) and c15-hot5 remain, 5 K of
  warm gas within a room's spread.

Measured after T10's line for a T10 not measured (main 817d0b3: 3.5 K, the hot-start
claim's threshold 3 x 2 K either side of a room's over sqrt(3), where T10 is at its default
with no wall and no log; 1 K where measured), ``--record-only --seeds 2`` (48 traces, 255 s
wall on a loaded machine): with the temperature unchanged (45/48, T10 logged is measured);
without it, not hot 24/24 (z_C SD 0.07: the grid's T10 is the room's exactly, which a real
bench's is not), hot |z_C| <= 2 **24/24** (21/24 before: c23-hot5 +0.87 %, z 2.6 -> 1.3 and
2.1 -> 1.2; z_C SD 0.72), C within 2 % 23/24 (c15-hot5 +2.05 %, z 1.7, unchanged).

Session 18 (a hot start claimed with m free no longer put b on its bound: c07-hot5 without
T had b 0.010 +- 0.036 for 0.3 and m 0.428 +- 0.007 for 0.5; now the constant-hA law, b
0.288 +- 0.039, m held 0.5 +- 0.044, C +0.35 % -> +1.7 %, z 1.45): without T, hot, b
within 0.03 19/24 -> 21/24 (max |error| 0.290 -> 0.033), |z_b| <= 2 21/24 -> 23/24; C
unchanged (within 2 % 23/24, |z_C| <= 2 24/24); with T, and the foreign flow laws, every
figure identical.

Session 20 (main 8dc7f2b; the whole family fitted with the offset where the record's end
lies clearly away from p_atm, the warm gas judged on the best-fitting hot start, a plateau
bending 2 sigma toward a level as its evidence): with the temperature unchanged (24/24 in
every column); without it, hot starts C within 2 % 11/12 -> 12/12 (max 1.82 -> 1.70 %),
b within 0.03 11/12 -> 12/12, offsets 11/12 -> 12/12: c15-hot5 +2.05 % -> +0.01 % (its
plateau bends 2.3 sigma), c11-hot30 +1.82 % (b not determined, the -3 kPa zero missed,
the warm gas's fit at the 600 K bound) -> +0.01 %, offset -2895 Pa.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import tempfile
import time
import zlib
from dataclasses import dataclass
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pneumatic_unload" / "test"))
from foreign.newton_tank import IsoLaw, discharge, thermocouple

P_ATM, WALL = 101325.0, 293.15  # [Pa abs], [K]: the room, the tank's wall
NOISE = 1000.0  # pressure noise, 0.1 % of a 1 MPa full scale [Pa]
DM3_PER_S_BAR = 1e-3 / 1e5  # 1 dm^3/(s bar) in m^3/(s Pa)
#: The acceptance: C within 1 % (with the temperature) or 2 % (without), b within 0.03,
#: the offset within 500 Pa, the temperature's rms within 2 x its noise.
C_TOL_WITH, C_TOL_WITHOUT, B_TOL, OFFSET_TOL, RMS_FACTOR = 0.01, 0.02, 0.03, 500.0, 2.0

N_CASES = 24
DT_HOT = (0.0, 10.0, 0.0, 30.0, 0.0, 20.0, 0.0, 5.0)  # T10 - wall [K]
TAU_HEAT = (5.0, 10.0, 20.0, 40.0, 60.0)  # [s]
LAG = (0.5, 1.0, 2.0, 3.5, 5.0)  # thermocouple time constant [s]
T_RATE = (1.0, 2.0, 5.0, 10.0)  # temperature rate [Hz]
PLATEAU = (1.0, 2.0, 5.0, 10.0)  # [s] before the opening
OFFSET = (0.0, 3000.0, -1200.0, 400.0, -3000.0, 1800.0, 0.0)  # transducer zero [Pa]
#: (V [m^3], C [m^3/(s Pa)], pressure rate [Hz]): tau0 1-14 s; the slow ones logged slower.
VCR = ((2e-3, 3e-9, 1000.0), (5e-3, 6e-9, 500.0), (10e-3, 1.5e-8, 1000.0),
       (20e-3, 1.5e-8, 250.0), (2e-3, 1.5e-8, 1000.0), (10e-3, 8e-9, 250.0),
       (20e-3, 1e-8, 100.0), (5e-3, 3e-9, 100.0))
B = (0.2, 0.3, 0.4, 0.5)
P10 = (8e5, 7e5, 6e5, 5e5)  # [Pa abs]
TAU0_RECORDED = (6.0, 7.0, 8.0, 9.0)
T_NOISE = (0.2, 0.3, 0.5)  # [K]
TC_BEHIND = (2.0, 3.0, 4.0)  # [K]: a hot start's thermocouple below the gas at t[0]


@dataclass(frozen=True)
class Case:
    """One discharge and how it was logged (SI units; ``seed``: the noise draw)."""

    name: str
    dt_hot: float
    tau_heat: float
    lag: float
    t_rate: float
    p_rate: float
    plateau: float
    offset: float
    volume: float
    conductance: float
    b: float
    p10: float
    tau0_recorded: float
    t_noise: float
    tc_behind: float
    seed: int = 0
    m: float = 0.5  # the component's subsonic index (the grid's: 0.5)

    @property
    def tau0(self) -> float:
        return self.volume / (1.4e5 * self.conductance)


def cases(quick: bool = False, seeds: int = 1) -> list[Case]:
    """The grid (see the module's text); ``quick``: four traces (two hot, two offset)."""
    out = []
    for i in range(N_CASES):
        v, c, rate = VCR[(i + i // 8) % len(VCR)]
        dt = DT_HOT[i % len(DT_HOT)]
        out.append(Case(
            f"c{i:02d}{'-hot' + format(dt, 'g') if dt else ''}", dt, TAU_HEAT[i % 5],
            LAG[(i // 2) % 5], T_RATE[(i // 2) % 4], rate, PLATEAU[(i // 3) % 4],
            OFFSET[i % 7], v, c, B[(i // 4) % 4], P10[(i // 2) % 4],
            TAU0_RECORDED[(i // 5) % 4], T_NOISE[i % 3], TC_BEHIND[i % 3]))
    if quick:
        out = [out[k] for k in (0, 1, 4, 11)]
    return [Case(**{**c.__dict__, "seed": s}) for c in out for s in range(seeds)]


def record(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t [s], the pressure read [Pa abs] and the logged temperature [degC] (NaN between the
    thermocouple's samples)."""
    t = np.arange(0.0, case.plateau + case.tau0_recorded * case.tau0, 1.0 / case.p_rate)
    gas = np.empty_like(t)
    t10 = WALL + case.dt_hot
    p = discharge(t, volume=case.volume, p10=case.p10, t10=t10, p_atm=P_ATM,
                  tau_heat=case.tau_heat, t_open=case.plateau,
                  flow_law=IsoLaw(case.conductance, case.b, case.m), t_wall=WALL,
                  temperature_out=gas)
    rng = np.random.default_rng([zlib.crc32(case.name.encode()), case.seed])
    y = p + case.offset + rng.normal(0.0, NOISE, t.size)
    tc = thermocouple(t, gas, case.lag, gas[0] - (case.tc_behind if case.dt_hot else 0.0))
    every = round(case.p_rate / case.t_rate)
    logged = np.full(t.size, np.nan)
    idx = np.arange(0, t.size, every)
    logged[idx] = np.round((tc[idx] - 273.15 + rng.normal(0.0, case.t_noise, idx.size)) * 10.0
                           ) / 10.0
    return t, y, logged


def write_csv(path: Path, t: np.ndarray, y: np.ndarray, temp: np.ndarray | None) -> None:
    """The logger's CSV: kPa to 0.1 Pa, degC to 0.1 K, empty cells where nothing was logged."""
    cols = [np.char.mod("%.4f", t), np.char.mod("%.4f", y / 1e3)]
    head = "time [s],pressure [kPa]"
    if temp is not None:
        head += ",gas temperature [C]"
        cols.append(np.where(np.isfinite(temp), np.char.mod("%.1f", temp), ""))
    body = cols[0]
    for c in cols[1:]:
        body = np.char.add(np.char.add(body, ","), c)
    path.write_text(head + "\n" + "\n".join(body.tolist()) + "\n")


#: ``--record-only``: the stated inputs exact and no model-limits line, so that sigma(C) is
#: the record's own; T10's line is kept without the column (T10 is not measured) and
#: dropped with it (T10 is fitted from the log, and this grid's thermocouple has no offset:
#: the probe is exact, as V is).
RECORD_ONLY = ["--volume-uncertainty", "0", "--pressure-uncertainty", "0",
               "--atmosphere-uncertainty", "0", "--model-uncertainty", "0"]
PROBE_EXACT = ["--temperature-uncertainty", "0"]


def _analyze(path: Path, volume: float, atmosphere: bool, record_only: bool = False,
             with_t: bool = False) -> dict:
    """``analyze --json`` on the file; the final unload (or ``error``) and the CPU s."""
    from pneumatic_unload.app.cli import main

    argv = ["analyze", str(path), "--volume", repr(volume), "--json",
            *(RECORD_ONLY if record_only else []),
            *(PROBE_EXACT if record_only and with_t else [])]
    if atmosphere:
        argv += ["--atmosphere", repr(P_ATM)]
    out, err = io.StringIO(), io.StringIO()
    start = time.process_time()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except (Exception, SystemExit) as exc:  # a bench reports, it does not stop
        return {"error": f"{type(exc).__name__}: {exc} {err.getvalue()}"[:160]}
    cpu = time.process_time() - start
    try:
        unloads = json.loads(out.getvalue())["unloads"]
    except (ValueError, KeyError):
        return {"error": f"exit {code}, no JSON: {err.getvalue()}"[:160], "cpu": cpu}
    final = [u for u in unloads if u.get("final")]
    if len(final) != 1:
        return {"error": f"exit {code}, {len(final)} final of {len(unloads)} unloads",
                "cpu": cpu, "status_text": " / ".join(u.get("status_text", "") for u in unloads)}
    return {"unload": final[0], "cpu": cpu}


def run(job: tuple[Case, bool, bool], kinds: tuple[bool, ...] = (True, False)) -> list[dict]:
    """The case's record analysed with (``kinds`` True) and without (False) its temperature
    column."""
    case, atmosphere, record_only = job
    t, y, temp = record(case)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for with_t in kinds:
            path = Path(tmp) / f"{case.name}-{'T' if with_t else 'p'}.csv"
            write_csv(path, t, y, temp if with_t else None)
            out.append({"case": case, "with_t": with_t,
                        **_analyze(path, case.volume, atmosphere, record_only, with_t)})
    return out


def _num(x: object) -> float:
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) else math.nan


def _z(err: float, std: float) -> float:
    return err / std if std > 0.0 and math.isfinite(std) else math.nan


def _f(x: float, fmt: str) -> str:
    return format(x, fmt) if math.isfinite(x) else "-"


def row(res: dict) -> tuple[str, dict]:
    """One Markdown row and the numbers the summary needs."""
    case, with_t = res["case"], res["with_t"]
    head = (f"| {case.name}{f' #{case.seed}' if case.seed else ''} | "
            f"{'T' if with_t else '-'} | {case.dt_hot:g} | {case.tau_heat:g} | {case.lag:g} | "
            f"{case.t_rate:g}/{case.p_rate:g} | {case.plateau:g} | {case.offset:+g} | "
            f"{1e3 * case.volume:g} | {case.conductance / DM3_PER_S_BAR:.4f} | {case.b:g} | "
            f"{case.p10 / 1e5:g} | {case.tau0:.1f} |")
    stats = {"with_t": with_t, "hot": case.dt_hot > 0, "name": case.name, "seed": case.seed,
             "ok": False, "cpu": res.get("cpu", math.nan), "status": "error",
             "status_text": res.get("error", "") + " " + res.get("status_text", "")}
    if "unload" not in res:
        return head + f" {res['error']} |" + " |" * 11, stats
    u = res["unload"]
    c, c_std = _num(u.get("conductance_model")), _num(u.get("conductance_model_std"))
    b, b_std = _num(u.get("critical_ratio")), _num(u.get("critical_ratio_std"))
    m, m_std = _num(u.get("subsonic_index")), _num(u.get("subsonic_index_std"))
    off, off_std = _num(u.get("pressure_offset")), _num(u.get("pressure_offset_std"))
    ce = c / case.conductance - 1.0
    be = b - case.b
    oe = off - case.offset
    off_hit = abs(oe) <= OFFSET_TOL if math.isfinite(off) else abs(case.offset) <= OFFSET_TOL
    ev = u.get("gas_temperature") or {}
    rms, noise = _num(ev.get("rms")), _num(ev.get("noise"))
    ratio = rms / noise if noise > 0 else math.nan
    stats.update(ok=True, c_err=ce, c_z=_z(c - case.conductance, c_std), b_err=be,
                 b_z=_z(be, b_std), m_err=m - case.m, m_z=_z(m - case.m, m_std),
                 off_hit=off_hit, off_err=oe, t_ratio=ratio,
                 b_note=u.get("critical_ratio_source") or "",
                 largest={q: (u.get(k) or {}).get("largest", "")
                          for q, k in (("C", "budget"), ("b", "budget_b"), ("m", "budget_m"))},
                 status=u.get("status", "?"), status_text=u.get("status_text", ""))
    used = "used" if ev.get("used") else "not used"
    follows = {True: "follows", False: "departs"}.get(ev.get("follows"), "")
    tau_s = _num(ev.get("sensor_time_constant"))
    ev_text = (f"{_f(ratio, '.2f')} {follows} lag {_f(tau_s, '.2f')}" if math.isfinite(rms)
               else used)
    return (head + f" {100 * ce:+.3f} | {_f(stats['c_z'], '+.2f')} | {b:.3f} | {be:+.3f} | "
            f"{_f(stats['b_z'], '+.2f')} | {_f(off, '+.0f')} +- {_f(off_std, '.0f')} | "
            f"{_f(oe, '+.0f')} | {ev_text} | {stats['status']} | {_f(stats['cpu'], '.1f')} |"
            ), stats


def _share(x: np.ndarray, limit: float) -> str:
    """How many of x are within +-limit, of all (a NaN counts as outside)."""
    if not x.size:
        return "-"
    k = int(np.sum(np.abs(x[np.isfinite(x)]) <= limit))
    return f"{k}/{x.size} ({100 * k / x.size:.0f} %)"


def _count(flags: list[bool]) -> str:
    k = sum(flags)
    return f"{k}/{len(flags)} ({100 * k / len(flags):.0f} %)" if flags else "-"


def summary(stats: list[dict]) -> list[str]:
    """The summary: with / without the temperature, hot / not hot, and each of the two."""
    lines = ["| family | n | C err mean [%] | max abs C err [%] | z_C mean | z_C SD | "
             "abs z_C <= 2 | C within tol | b err mean | max abs b err | b within 0.03 | "
             "abs z_b <= 2 | T rms <= 2 noise | offset within 500 Pa | status | "
             "CPU mean / max [s] |", "|---" * 16 + "|"]
    groups = [("with T, not hot", True, False), ("with T, hot", True, True),
              ("with T, all", True, None), ("without T, not hot", False, False),
              ("without T, hot", False, True), ("without T, all", False, None)]
    for label, with_t, hot in groups:
        sel = [s for s in stats if s["with_t"] == with_t and hot in (None, s["hot"])]
        good = [s for s in sel if s["ok"]]
        failed = len(sel) - len(good)
        statuses: dict[str, int] = {}
        for s in sel:
            statuses[s["status"]] = statuses.get(s["status"], 0) + 1
        status = ", ".join(f"{k} {v}" for k, v in sorted(statuses.items()))
        cpu = np.array([s["cpu"] for s in sel], dtype=float)
        cpu_text = (f"{np.nanmean(cpu):.1f} / {np.nanmax(cpu):.1f}"
                    if np.any(np.isfinite(cpu)) else "-")
        if not good:
            lines.append(f"| {label} | 0 (+{failed} no result) |" + " - |" * 12
                         + f" {status} | {cpu_text} |")
            continue
        # a trace with no result is a miss of every share: pad with NaN
        c, cz, b, bz, tr = (np.array([s[k] for s in good] + [math.nan] * failed, dtype=float)
                            for k in ("c_err", "c_z", "b_err", "b_z", "t_ratio"))
        tol = C_TOL_WITH if with_t else C_TOL_WITHOUT
        finite_c = c[np.isfinite(c)]
        lines.append(
            f"| {label} | {len(good)}{f' (+{failed} no result)' if failed else ''} | "
            f"{100 * np.mean(finite_c):+.3f} | {100 * np.max(np.abs(finite_c)):.3f} | "
            f"{np.nanmean(cz):+.2f} | {np.nanstd(cz):.2f} | {_share(cz, 2.0)} | "
            f"{_share(c, tol)} ({100 * tol:g} %) | {np.nanmean(b):+.4f} | "
            f"{np.nanmax(np.abs(b)):.4f} | {_share(b, B_TOL)} | {_share(bz, 2.0)} | "
            f"{_share(tr, RMS_FACTOR) if with_t else '-'} | "
            f"{_count([s['off_hit'] for s in good] + [False] * failed)} | {status} | "
            f"{cpu_text} |")
    return lines


def worst(stats: list[dict], k: int = 8) -> list[str]:
    """The k worst analyses (no result first, then by |z_C| and |C err| / tol), with their
    status text."""
    def badness(s: dict) -> float:
        if not s["ok"] or not math.isfinite(s["c_err"]):
            return math.inf
        tol = C_TOL_WITH if s["with_t"] else C_TOL_WITHOUT
        z = abs(s["c_z"]) if math.isfinite(s["c_z"]) else 10.0
        return max(z / 2.0, abs(s["c_err"]) / tol, abs(s["b_err"]) / B_TOL)

    out = []
    for s in sorted(stats, key=badness, reverse=True)[:k]:
        what = (f"C {100 * s['c_err']:+.2f} % (z {s['c_z']:+.1f}), b {s['b_err']:+.3f}"
                if s["ok"] else "no result")
        seed = f" #{s['seed']}" if s["seed"] else ""
        out.append(f"* {s['name']}{seed} "
                   f"({'with' if s['with_t'] else 'without'} T): {what}; {s['status']}: "
                   f"{s['status_text'].strip()}")
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="four traces")
    ap.add_argument("--jobs", type=int, default=1, help="processes (default 1)")
    ap.add_argument("--seeds", type=int, default=1, help="noise draws per case (default 1)")
    ap.add_argument("--atmosphere", action="store_true",
                    help=f"pass --atmosphere {P_ATM:g} to analyze (the offset is fitted only "
                         "when p_atm is given)")
    ap.add_argument("--record-only", action="store_true",
                    help="V, p and p_atm exact and no model-limits line: sigma(C) the "
                         "record's own (the coverage the acceptance asks)")
    args = ap.parse_args(argv)
    grid = cases(args.quick, args.seeds)
    print(f"Temperature records: {len(grid)} traces x (with, without the temperature column), "
          f"{NOISE:g} Pa noise, p_atm {'given' if args.atmosphere else 'not given'}"
          f"{', record only' if args.record_only else ''}\n")
    print("| case | T | dT hot [K] | tau_h [s] | lag [s] | T/p rate [Hz] | plateau [s] | "
          "offset [Pa] | V [L] | C [dm^3/(s bar)] | b | p10 [bar] | tau0 [s] | C err [%] | "
          "z_C | b fit | b err | z_b | offset fit [Pa] | offset err [Pa] | "
          "T rms/noise, lag | status | CPU [s] |")
    print("|---" * 23 + "|")
    jobs = [(c, args.atmosphere, args.record_only) for c in grid]
    start = time.perf_counter()
    stats = []
    with contextlib.ExitStack() as stack:
        if args.jobs > 1:
            pool = stack.enter_context(Pool(args.jobs))
            results = pool.imap(run, jobs)
        else:
            results = map(run, jobs)
        for pair in results:
            for res in pair:
                line, s = row(res)
                print(line, flush=True)
                stats.append(s)
    print(f"\n{len(grid)} traces, {len(stats)} analyses in {time.perf_counter() - start:.0f} s "
          "(wall)\n")
    print("\n".join(summary(stats)))
    print("\nWorst analyses:\n")
    print("\n".join(worst(stats)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
