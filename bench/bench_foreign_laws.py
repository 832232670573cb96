"""The model-based C, b and m on flow laws that are not the package's: a script, not a test.

``python bench/bench_foreign_laws.py [--quick] [--jobs N] [--seeds K] [--exact-inputs]
[--family iso|nozzle|series]`` (project venv, ``PYTHONPATH`` at the repo root): discharges
made by the independent model ``pneumatic_unload/test/foreign/newton_tank.py`` (Newton cooling,
Radau at
rtol 1e-10; it imports nothing from the package) through three families of flow law:

* ``iso``: the ISO 6358-1:2013 law with m in {0.25, 0.35, 0.5, 0.62, 0.75} x b in
  {0.1, 0.3, 0.45, 0.6} (20 cases; V 1-10 L, C 2e-9 - 2e-8 m^3/(s Pa), p10 6-8 bar abs,
  tau_h 5, 10, 20 s or 1e4 s, adiabatic-like, cycled over the cases);
* ``nozzle``: an isentropic convergent nozzle (d 1.5, 2, 3 mm; Cd 0.8, 0.8, 0.62);
* ``series``: two ISO restrictions in series, the intermediate pressure solved by mass-flow
  continuity (five pairs: equal, the downstream one choking, the upstream one choking, a
  b = 0.05 element first, two b = 0 elliptic elements).

Each record: 1 kHz, a 0.2 s plateau, then to 9 tau0 (tau0 = V / (1.4e5 C), eq 28) so that
the subsonic tail is recorded, p_atm 101325 Pa, T10 = wall = 293.15 K, white noise of
1000 Pa (0.1 % of a 1 MPa full scale; seeded by the case's name and the seed index). Each
is analysed as ``merge_final(analyze(t, y, EstimatorSettings(volume=V)))`` (with
``--exact-inputs``: V, T10, p, p_atm and the wall stated exact, the model's limits kept,
``EXACT_INPUTS_FOREIGN_MODEL``, as ``bench/bench_hyddown.py``: the default settings'
input uncertainties, 0.5 % of V first, widen sigma on a grid whose inputs are exact).

The truth (``newton_tank.truth``): the ISO law's own C, b, m; the nozzle's C from its choked
flow, b = r* = 0.5283, m the least-squares ISO m with b held (0.498; the free (b, m) fit
is 0.530, 0.499); the series' C from the pair's choked flow and b where it stops being
choked (closed forms), m the least-squares ISO m with b held. Where the pair's curve is
not ISO-shaped the free least-squares (b, m) moves off (the end of choking, m with b held):
b up to 0.05 away (the pair whose upstream element chokes), m up to 0.03; the errors
against the free fit are printed beside, "b err (free)", "m err (free)", and counted in the
summary as "within (free)".

Printed: a Markdown table per trace (truth, C error [%], z = error / sigma(C), b and its
error and z against b's stated sigma, m and its error and z when the package reports m,
"held" when it holds m at 0.5, the heat law, the adequacy flag, CPU s) and a summary per
family: C error mean and max |.|, z mean and SD, the share of |error| <= 2 sigma, the
share within the acceptance (C 1 %, b 0.03, m 0.05), b's and m's errors alike. The
acceptance (the issue): C within 1 %, b within 0.03, m within 0.05, and |error| <= 2
sigma in 90-98 % of trials for each. ``--quick``: a few traces (two ISO, one nozzle, one
series). ``--jobs N``: N processes. ``--seeds K``: each case with K noise draws.

Measured before m was fitted (main at 4bd69e5, m held at 0.5; 2 cores, 11-20 s for the 28
traces):

* ISO law, 20 cases: the five with m = 0.5 exact (|C err| <= 0.03 %, |b err| <= 0.001);
  the fifteen with m != 0.5 all "model inadequate" (Ljung-Box p = 0, residual RMS 1.5-3.6 x
  the noise): C -11.5 % (m 0.25, b 0.3) to +11.2 % (m 0.62, b 0.45), b off by up to 0.49,
  two b NaN (m 0.75, b 0.1 and 0.3); C within 1 %: 8/20, |z_C| <= 2: 13/20 (10/20 with
  the inputs exact), b within 0.03: 5/20. With 5 noise draws: C within 1 % 41/100.
* Nozzle, 3 cases: C within 0.04 %, b 0.529 (r* 0.528), m 0.5 fits (0.498).
* Series, 5 pairs: C within 0.3 % on three, +5.9 % (downstream-chokes, m 0.59 effective)
  and -4.3 % (b005-first); b within 0.03 of the choking end on 3/5, of the free fit on 4/5.

With m in the curve fit's family (``pneumatic_unload.curvefit.subsonic_offer``; 18 s):

* ISO law, 20 cases: C within 1 % 20/20 (max 0.18 %), b within 0.03 19/20 (m 0.25, b 0.45:
  b 0.368, the natural and constant-hA laws 2 apart in BIC with b 0.368 and 0.442; z_b
  -2.1), m within 0.05 20/20 (max 0.029). With 5 draws and ``--record-only`` (the record's
  sigma alone): |z| <= 2 for C 95/100, b 95/100, m 97/100; C within 1 % 100/100.
* Nozzle: unchanged (m held: the criterion keeps 0.5; the nozzle's best ISO m is 0.498).
* Series: C within 1 % 5/5 (max 0.21 %; b005-first was -4.3 % through a hot start with
  the wall on its 150 K bound, which is no longer offered); b within 0.03 of the free ISO
  fit 5/5. With 5 draws, record only: C within 1 % 23/25 (3.8 % at most), |z_C| <= 2 only
  14/25: the pair's curve is not ISO-shaped, and the model-limits line of the default
  settings is what covers it (100 %).
* sigma(C) with the default settings (0.5 % of V, the 0.34 % model-limits line): z SD
  0.09, 100 % within 2 sigma, wider than the 90-98 % the acceptance asks; the record's own
  sigma is what that coverage measures (``--record-only``).
* A held m's uncertainty (session 18): sqrt(sigma^2 + (m - 0.5)^2) of the m-free fit (was
  max of the two) with the heat laws' spread of m among the laws fitted with m (was none:
  the pair whose upstream element chokes, m held at 0.500 +- 0.0024, the density law
  fitted with m 4 in BIC away at 0.523, the free ISO fit's m 0.491). Series, 5 draws,
  record only: |z_m| <= 2 against the free fit 14/25 -> 18/25, |z_C| <= 2 15/25 -> 19/25
  (the held m's line of C); default settings: C 25/25 and b unchanged, ISO and nozzle
  unchanged. What is left: the equal pair (C -0.09 %, z -2.5 to -3.4 with the record's
  sigma of 0.03 %; m held 0.500 +- 0.002 against the free fit's 0.505): a flow curve that
  is not ISO-shaped, which the default settings' model-limits line (0.34 %) covers.
* b's range from 0 (session 19; it was bounded at 0.01): the elliptic pair (b = 0) read
  b 0.010-0.012 and C -0.14 to -0.26 % over the 5 draws (with the noise at 10 Pa still
  -0.15 %, z -3: a bias, not noise); now b 0.000-0.001 and C -0.05 to +0.01 %, the heat
  law the constant hA (the foreign model's Newton cooling) where the density law stood in.
  Every other trace unchanged. The equal pair's -0.09 % stays with the noise at 10 Pa
  (-0.09 %, z -4.5) and with m fitted in full (m 0.501, C -0.08 %): the ISO law's nearest
  curve to the pair's, not a held m; its sigma is the default settings' model-limits line.
* Not covered: b = 0.1 from 6-8 bar is never choked; there b, m and the heat exchange can
  trade (one record, adiabatic, m 0.35: b 0.23 +- 0.01, m 0.30, white residuals).

Session 20 (main 8dc7f2b): every figure above unchanged, in all three modes; the random
draws of the same ranges are ``bench/bench_random_draws.py``.

Session 24 (77a16b9, a zero offset not fitted in b's and m's sigma: the stated d along the
fit's valley): default settings, 5 draws, every value unchanged; |z| <= 2 for b against
the ISO truth 99 -> 100/100 and m 97 -> 100/100 (the default inputs' over-coverage, as
C's), the series' b (the end of choking) 8 -> 21/25 and m 11 -> 18/25, against the free
fit b 24 -> 25/25 and m 18 -> 21/25. Record only (d = 0) unchanged by construction.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import zlib
from dataclasses import dataclass
from itertools import product
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pneumatic_unload" / "test"))
from foreign.newton_tank import IsoLaw, Nozzle, Series, discharge, truth

P_ATM, T10 = 101325.0, 293.15  # [Pa abs], [K]
NOISE = 1000.0  # 0.1 % of a 1 MPa full scale [Pa]
RATE = 1e3  # [Hz]
PLATEAU = 0.2  # [s] before the opening
TAU0_RECORDED = 9.0  # the record's length after the opening, in tau0 = V / (1.4e5 C)
DM3_PER_S_BAR = 1e-3 / 1e5  # 1 dm^3/(s bar) in m^3/(s Pa)
#: The acceptance: C within 1 %, b within 0.03, m within 0.05.
C_TOL, B_TOL, M_TOL = 0.01, 0.03, 0.05

M_GRID = (0.25, 0.35, 0.5, 0.62, 0.75)
B_GRID = (0.1, 0.3, 0.45, 0.6)
#: (V [m^3], C [m^3/(s Pa)]) cycled over the ISO cases: tau0 2.4-7.1 s.
VC = ((1e-3, 3e-9), (2.5e-3, 4e-9), (5e-3, 1.2e-8), (10e-3, 2e-8), (2e-3, 2e-9))
P10S = (8e5, 7e5, 6e5)  # [Pa abs]
TAU_HEAT = (5.0, 10.0, 20.0, 1e4)  # [s]; 1e4: adiabatic-like


@dataclass(frozen=True)
class Case:
    """One discharge: name, family, law, V [m^3], p10 [Pa abs], tau_h [s], seed index, the
    record's length after the opening [tau0]."""

    name: str
    family: str
    law: IsoLaw | Nozzle | Series
    volume: float
    p10: float
    tau_heat: float
    seed: int = 0
    tau0_recorded: float = TAU0_RECORDED  # the record's length after the opening [tau0]
    # the rig as it is where the analysis is told the defaults (bench_random_draws
    # --drawn-inputs): T10 [K], the wall [K] (None: T10), p_atm [Pa abs], the transducer's
    # zero [Pa] and the V the analysis is given [m^3] (None: ``volume``)
    t10: float = T10
    t_wall: float | None = None
    p_atm: float = P_ATM
    offset: float = 0.0
    volume_given: float | None = None


def cases(quick: bool = False, seeds: int = 1, family: str | None = None) -> list[Case]:
    """The grid (see the module's text); ``quick``: four traces."""
    out = []
    for i, (m, b) in enumerate(product(M_GRID, B_GRID)):
        v, c = VC[i % len(VC)]
        out.append(Case(f"iso-m{m:g}-b{b:g}", "iso", IsoLaw(c, b, m), v, P10S[i % 3],
                        TAU_HEAT[i % 4]))
    for j, (d, cd, v, tau) in enumerate(((1.5e-3, 0.8, 1e-3, 10.0), (2e-3, 0.8, 3e-3, 5.0),
                                         (3e-3, 0.62, 6e-3, 1e4))):
        out.append(Case(f"nozzle-d{1e3 * d:g}mm-cd{cd:g}", "nozzle",
                        Nozzle(math.pi * d * d / 4.0, cd), v, P10S[j % 3], tau))
    pairs = (((1e-8, 0.3, 0.5), (1e-8, 0.3, 0.5), 5e-3, 10.0, "equal"),
             ((1.5e-8, 0.2, 0.4), (6e-9, 0.5, 0.6), 4e-3, 20.0, "downstream-chokes"),
             ((6e-9, 0.45, 0.5), (1.5e-8, 0.2, 0.5), 3e-3, 5.0, "upstream-chokes"),
             ((1e-8, 0.05, 0.5), (1.2e-8, 0.4, 0.5), 5e-3, 1e4, "b005-first"),
             ((1e-8, 0.0, 0.5), (1.2e-8, 0.0, 0.5), 6e-3, 10.0, "elliptic-b0"))
    for k, (e1, e2, v, tau, label) in enumerate(pairs):
        out.append(Case(f"series-{label}", "series", Series(IsoLaw(*e1), IsoLaw(*e2)), v,
                        P10S[k % 3], tau))
    if family:
        out = [c for c in out if c.family == family]
    if quick:
        keep = {"iso-m0.25-b0.3", "iso-m0.75-b0.6", "nozzle-d2mm-cd0.8", "series-equal"}
        out = [c for c in out if c.name in keep]
    return [Case(c.name, c.family, c.law, c.volume, c.p10, c.tau_heat, s)
            for c in out for s in range(seeds)]


def record(case: Case) -> tuple[np.ndarray, np.ndarray]:
    """The case's noisy record: t [s], p [Pa abs]."""
    tau0 = case.volume / (1.4e5 * case.law.conductance)
    t = np.arange(0.0, PLATEAU + case.tau0_recorded * tau0, 1.0 / RATE)
    p = discharge(t, volume=case.volume, p10=case.p10, t10=case.t10, p_atm=case.p_atm,
                  tau_heat=case.tau_heat, t_open=PLATEAU, flow_law=case.law,
                  t_wall=case.t_wall)
    rng = np.random.default_rng([zlib.crc32(case.name.encode()), case.seed])
    return t, p + case.offset + rng.normal(0.0, NOISE, t.size)


def _finite(*values: object) -> float:
    """The first finite number of ``values`` (NaN if none)."""
    for v in values:
        if isinstance(v, int | float) and math.isfinite(v):
            return float(v)
    return math.nan


def run(job: tuple[Case, bool | str]) -> dict:
    """Analyse one case; the numbers of its row (``error``: why there are none)."""
    case, exact = job
    from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final

    tr = truth(case.law)
    out = {"case": case, "truth": tr}
    t, y = record(case)
    given = {}
    if exact == "record":
        from pneumatic_unload.uncertainty.budget import EXACT_INPUTS
        given = dict(EXACT_INPUTS)
    elif exact:
        from pneumatic_unload.uncertainty.budget import EXACT_INPUTS_FOREIGN_MODEL
        given = dict(EXACT_INPUTS_FOREIGN_MODEL)
    start = time.process_time()
    try:
        volume = case.volume if case.volume_given is None else case.volume_given
        results = merge_final(analyze(t, y, EstimatorSettings(volume=volume, **given)))
    except Exception as exc:  # a bench reports, it does not stop
        return {**out, "error": f"{type(exc).__name__}: {exc}"[:120]}
    out["cpu"] = time.process_time() - start
    if len(results) != 1 or not results[0].final:
        return {**out, "error": f"no single final result ({len(results)})"}
    r = results[0]
    extra = r.extra or {}
    fit = extra.get("curve_fit", {})
    m_value = _finite(getattr(r, "subsonic_index", None), fit.get("subsonic_index"))
    fitted = fit.get("subsonic_index_fitted")
    out.update(
        c=r.conductance_model, c_std=r.conductance_model_std,
        b=r.critical_ratio,
        b_std=_finite(getattr(r, "critical_ratio_std", None),
                      extra.get("budget_b", {}).get("combined_std"),
                      fit.get("critical_ratio_std")),
        m=m_value if math.isfinite(m_value) else 0.5,
        m_std=_finite(getattr(r, "subsonic_index_std", None),
                      extra.get("budget_m", {}).get("combined_std"),
                      fit.get("subsonic_index_std")),
        m_reported=math.isfinite(m_value), m_fitted=bool(fitted),
        heat_law=fit.get("heat_law", "-"),
        inadequate=bool(extra.get("model_inadequate")),
        b_note=fit.get("critical_ratio_source", ""),
        largest={q: (extra.get(k) or {}).get("largest", "")
                 for q, k in (("C", "budget"), ("b", "budget_b"), ("m", "budget_m"))})
    return out


def _z(err: float, std: float) -> float:
    return err / std if std > 0.0 and math.isfinite(std) else math.nan


def row(res: dict) -> tuple[str, dict]:
    """One Markdown row and the numbers the summary needs."""
    case, tr = res["case"], res["truth"]
    head = (f"| {case.name}{'' if not case.seed else f' #{case.seed}'} | "
            f"{1e3 * case.volume:.3g} | {case.p10 / 1e5:.0f} | {case.tau_heat:g} | "
            f"{tr.conductance / DM3_PER_S_BAR:.4f} | {tr.critical_ratio:.3f} | "
            f"{tr.subsonic_index:.3f} |")
    if "error" in res:
        return head + f" {res['error']} |" + " |" * 14, {"family": case.family, "ok": False}
    ce = res["c"] / tr.conductance - 1.0
    be = res["b"] - tr.critical_ratio
    be_free = res["b"] - tr.fit_b
    me = res["m"] - tr.subsonic_index
    me_free = res["m"] - tr.fit_m
    stats = {"family": case.family, "ok": True, "c_err": ce,
             "c_z": _z(res["c"] - tr.conductance, res["c_std"]), "b_err": be,
             "b_z": _z(be, res["b_std"]), "b_err_free": be_free, "m_err": me,
             "m_err_free": me_free, "b_z_free": _z(be_free, res["b_std"]),
             "m_z": _z(me, res["m_std"]) if res["m_fitted"] or res["m_reported"] else math.nan,
             "m_z_free": _z(me_free, res["m_std"]) if res["m_fitted"] or res["m_reported"]
             else math.nan,
             "m_held": not res["m_fitted"]}
    m_text = f"{res['m']:.3f}" + ("" if res["m_fitted"] else " held")
    m_z = f"{stats['m_z']:+.2f}" if math.isfinite(stats["m_z"]) else "-"
    return (head + f" {100 * ce:+.3f} | {stats['c_z']:+.2f} | {res['b']:.3f} | {be:+.3f} | "
            f"{stats['b_z']:+.2f} | {be_free:+.3f} | {m_text} | {me:+.3f} | {m_z} | "
            f"{me_free:+.3f} | "
            f"{res['heat_law']} | {'inadequate' if res['inadequate'] else 'ok'} | "
            f"{res['cpu']:.1f} |"), stats


def _share(x: np.ndarray, limit: float) -> str:
    """How many of x are within +-limit, of all (a NaN counts as outside)."""
    if not x.size or not np.any(np.isfinite(x)):
        return "-"
    k = int(np.sum(np.abs(x[np.isfinite(x)]) <= limit))
    return f"{k}/{x.size} ({100 * k / x.size:.0f} %)"


def _max_abs(x: np.ndarray, digits: int, scale: float = 1.0) -> str:
    """max |x| over the finite values, with the NaN count."""
    bad = int(np.sum(~np.isfinite(x)))
    text = f"{scale * np.nanmax(np.abs(x)):.{digits}f}" if bad < x.size else "-"
    return text + (f" ({bad} NaN)" if bad else "")


def summary(stats: list[dict]) -> list[str]:
    """The summary table: one line per family and one for all."""
    lines = ["| family | n | C err mean [%] | max abs C err [%] | z_C mean | z_C SD | "
             "abs z_C <= 2 | C within 1 % | b err mean | max abs b err | abs z_b <= 2 | "
             "b within 0.03 | b within 0.03 (free) | m err mean | max abs m err | "
             "abs z_m <= 2 | m within 0.05 | m within 0.05 (free) | abs z_b <= 2 (free) | "
             "abs z_m <= 2 (free) |",
             "|---" * 20 + "|"]
    families = sorted({s["family"] for s in stats}, key=["iso", "nozzle", "series"].index)
    for fam in [*families, "all"]:
        group = [s for s in stats if s["ok"] and fam in ("all", s["family"])]
        failed = sum(1 for s in stats if not s["ok"] and fam in ("all", s["family"]))
        if not group:
            lines.append(f"| {fam} | 0 (+{failed} no result) |" + " - |" * 18)
            continue
        c, cz, b, bz, bf, m, mz, mf, bzf, mzf = (
            np.array([s[k] for s in group], dtype=float)
            for k in ("c_err", "c_z", "b_err", "b_z", "b_err_free", "m_err", "m_z",
                      "m_err_free", "b_z_free", "m_z_free"))
        held = all(s["m_held"] for s in group)
        lines.append(
            f"| {fam} | {len(group)}{f' (+{failed} no result)' if failed else ''} | "
            f"{100 * np.mean(c):+.3f} | {_max_abs(c, 3, 100.0)} | "
            f"{np.nanmean(cz):+.2f} | {np.nanstd(cz):.2f} | {_share(cz, 2.0)} | "
            f"{_share(c, C_TOL)} | {np.nanmean(b):+.4f} | {_max_abs(b, 4)} | "
            f"{_share(bz, 2.0)} | {_share(b, B_TOL)} | {_share(bf, B_TOL)} | "
            f"{np.mean(m):+.3f}{' (held)' if held else ''} | {_max_abs(m, 3)} | "
            f"{_share(mz, 2.0)} | {_share(m, M_TOL)} | {_share(mf, M_TOL)} | "
            f"{_share(bzf, 2.0)} | {_share(mzf, 2.0)} |")
    return lines


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few traces")
    ap.add_argument("--jobs", type=int, default=1, help="processes (default 1)")
    ap.add_argument("--seeds", type=int, default=1, help="noise draws per case (default 1)")
    ap.add_argument("--exact-inputs", action="store_true",
                    help="V, T10, p, p_atm and the wall stated exact (the model's limits kept)")
    ap.add_argument("--record-only", action="store_true",
                    help="every input exact and no model-limits line: sigma from the record "
                         "and the model form alone (the coverage of the fit itself)")
    ap.add_argument("--family", choices=("iso", "nozzle", "series"), help="one family only")
    args = ap.parse_args(argv)
    grid = cases(args.quick, args.seeds, args.family)
    mode = ("record only (inputs exact, no model-limits line)" if args.record_only else
            "inputs exact (model limits kept)" if args.exact_inputs else "default settings")
    print(f"Foreign flow laws: {len(grid)} traces, 1 kHz, {NOISE:g} Pa noise, "
          f"{TAU0_RECORDED:g} tau0 recorded, {mode}\n")
    print("| case | V [L] | p10 [bar] | tau_h [s] | C [dm^3/(s bar)] | b | m | C err [%] | "
          "z_C | b fit | b err | z_b | b err (free) | m fit | m err | z_m | m err (free) | "
          "heat law | model | CPU [s] |")
    print("|---" * 20 + "|")
    jobs = [(c, "record" if args.record_only else args.exact_inputs) for c in grid]
    start = time.perf_counter()
    stats = []
    if args.jobs > 1:
        with Pool(args.jobs) as pool:
            results = pool.imap(run, jobs)
            for res in results:
                line, s = row(res)
                print(line, flush=True)
                stats.append(s)
    else:
        for job in jobs:
            line, s = row(run(job))
            print(line, flush=True)
            stats.append(s)
    print(f"\n{len(grid)} traces in {time.perf_counter() - start:.0f} s (wall)\n")
    print("\n".join(summary(stats)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
