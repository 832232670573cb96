# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The model-based C on discharges simulated by HydDown, a peer code (real-gas air by
CoolProp, its own wall heat transfer, the Yellow Book orifice law), not by the package.

The traces are committed (``test/data/hyddown``, made by ``bench/hyddown_traces.py`` with
hyddown 0.50.0 / CoolProp 8.0.0 in its own venv); this test does not import HydDown. Each is
resampled to 1 kHz, given a 0.2 s plateau at p10 and 0.1 %-of-1-MPa white noise (fixed seed
per case), analysed, and the final model C compared with the orifice's truth C (Cd A and
ideal-gas choked flow, ISO 6358 reference state).

The issue's targets: model C within 2 % of the truth at every grid point; |error| <= 2 sigma
in 90-98 % of trials and <= 1 sigma in 55-80 %. Where a case misses a target it is marked
``xfail(strict=True)`` with the measured numbers:

* 2 %: met by all 6 (-0.10 % ... +0.51 %). (At commit c7e739e the near-isothermal case,
  p10 = 4 bar with h_inner = 50 W/(m^2 K), came out -22.5 %: both heat laws had been fitted
  from the weak-exchange side; the fit now explores strong and weak exchange when every law
  leaves structured residuals, and gives -0.07 % with the constant-hA law.)
* sigma: with the noise alone sigma(C) was 0.01-0.07 % of C and no case was within 2 sigma
  (|z| 2.8-27). The budget (issue #11) adds the model's own limits (``model_uncertainty``:
  ideal gas against real-gas air, HydDown's explicit Euler step, its Yellow Book subsonic
  law, a heat law from the package's family); the inputs are HydDown's own, so their terms
  are 0. The term is calibrated on other cases than these: 0.34 %, the RMS error over the
  24-case grid of ``bench/bench_hyddown.py`` (it was 0.3 %, the RMS over these same six:
  calibrated and tested on one set). These six test its coverage only, as a coverage: at
  least 5 of 6 within 2 sigma (all six have probability 0.74 at a true 95 %; five, 0.97)
  and 4 of 6 within 1 sigma; no single case is pinned to a side of a 2-sigma line (a strict
  xfail on the case at z = 2.18 made an improvement of 0.18 sigma fail the suite). The
  constant-h case v2l_ld4_d2_h2 is the far one: the density law n = 0.20 +- 0.03 (delta-BIC
  37 against constant hA) gives C +0.66 %; all three laws are off the same way (+0.51,
  +0.59, +0.66 %): the common offset of the ideal-gas model against HydDown, the
  model-limits term's, not a spread between laws.
* The wall: HydDown's wall starts at T10 (its ``temp_ambient``), an input as exact as V, so
  ``EXACT_INPUTS_FOREIGN_MODEL`` states its uncertainty as 0; with the wall assumed
  instead see ``bench/bench_hyddown.py --wall-assumed``.
"""

import math
import zlib
from functools import cache

import pytest
from foreign.hyddown_data import DATA_DIR, load, record

from pneumatic_unload.config.estimator import MODEL_UNCERTAINTY
from pneumatic_unload.estimation import EstimatorSettings, UnloadResult, analyze, merge_final
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS_FOREIGN_MODEL

CASES = ["v1l_ld1_d1_calc", "v2l_ld4_d2_h2", "v50l_ld3_d3_calc", "v10l_ld6_d2p5_h50",
         "v20l_ld2_d3_h10", "v5l_ld1p5_d1p5_calc_t303"]
TOLERANCE = 0.02  # model C against the truth [-]

#: Cases missing the 2 % target, with the measured numbers.
MISSES_2PCT: dict[str, str] = {}


def _marked(misses: dict[str, str]) -> list:
    return [pytest.param(c, marks=pytest.mark.xfail(strict=True, reason=misses[c]))
            if c in misses else c for c in CASES]


@cache
def result(name: str) -> tuple[UnloadResult, float]:
    """The final result of one case's record and the truth C [m^3/(s Pa)]."""
    trace = load(DATA_DIR / f"{name}.npz")
    m = trace.meta
    t, y = record(trace, zlib.crc32(name.encode()))
    # the inputs are HydDown's own (exact); the model's limits stay in the budget
    settings = EstimatorSettings(volume=m["volume"],
                                 length_diameter_ratio=m["length_diameter_ratio"],
                                 initial_temperature=m["t10"], **EXACT_INPUTS_FOREIGN_MODEL)
    (r,) = merge_final(analyze(t, y, settings))
    return r, m["truth_conductance"]


def test_the_committed_grid_spans_the_issue_ranges():
    metas = [load(DATA_DIR / f"{c}.npz").meta for c in CASES]
    assert sorted(p.stem for p in DATA_DIR.glob("*.npz")) == sorted(CASES)
    assert sum(m["h_inner"] == "calc" for m in metas) >= 2
    assert sum(m["h_inner"] != "calc" for m in metas) >= 2
    assert max(m["volume"] for m in metas) >= 0.05 - 1e-9
    assert min(m["volume"] for m in metas) <= 2e-3 + 1e-9
    assert sum((DATA_DIR / f"{c}.npz").stat().st_size for c in CASES) < 1_000_000
    for m in metas:
        assert m["versions"]["hyddown"] == "0.50.0"
        assert 4e5 <= m["p10"] <= 8e5 and 1.0 <= m["length_diameter_ratio"] <= 6.0


@pytest.mark.parametrize("name", _marked(MISSES_2PCT))
def test_model_c_within_2_percent_of_hyddown(name):
    r, truth = result(name)
    assert r.final and math.isfinite(r.conductance_model)
    error = r.conductance_model / truth - 1.0
    z = (r.conductance_model - truth) / r.conductance_model_std
    print(f"{name}: error {100 * error:+.3f} %, z {z:+.2f}, "
          f"law {r.extra['curve_fit']['heat_law']}")
    assert abs(error) < TOLERANCE


def test_sigma_coverage_over_the_grid():
    """The sigma calibrated on the bench's 24-case grid covers these six as it claims."""
    for name in CASES:
        r, _ = result(name)
        assert r.final and r.conductance_model_std > 0.0, name
        assert r.extra["budget"]["terms"] and any(  # the calibrated term is in the budget
            x["name"].startswith("model limits") and x["std"] == pytest.approx(
                MODEL_UNCERTAINTY * r.conductance_model, rel=1e-9)
            for x in r.extra["budget"]["terms"]), name
    z = [(r.conductance_model - c) / r.conductance_model_std
         for r, c in (result(n) for n in CASES)]
    within2 = sum(abs(v) <= 2.0 for v in z) / len(z)
    within1 = sum(abs(v) <= 1.0 for v in z) / len(z)
    # 6 cases cannot resolve the upper bounds (98 %, 80 %) nor the lower ones exactly: at
    # least 5 of 6 within 2 sigma (binomial, see the module note), 4 of 6 within 1
    assert within2 >= 5 / 6 - 1e-9 and within1 >= 0.55


# ------------------------------------------------------- the discrepancy workflow (#12)
#: Verdicts that are heat transfer: the hot start is heat transfer with the wall
#: temperature fitted (HydDown's lumped wall cools during the discharge).
HEAT = ("heat_transfer", "hot_start")
#: Committed cases run through the discrepancy workflow (about 20 s of CPU together): the
#: 50 L one is the case whose second round once added a pipe volume at its bound (C +16 %);
#: the 2 L one has a constant h. Measured (linear intervals, ``bench/bench_hyddown.py
#: --discrepancy``, which runs any grid): v50l hot_start alone, C -0.01 %; v2l
#: heat_transfer alone, +0.64 % (the other four: v1l, v10l, v20l -0.10 % ... +0.52 %; v5l
#: hot_start alone, -0.08 %, since a leak that the density law explains as well is refused:
#: ``test_discrepancy_laws.py``).
DISCREPANCY_CASES = ["v50l_ld3_d3_calc", "v2l_ld4_d2_h2"]

@pytest.mark.parametrize("name", DISCREPANCY_CASES)
def test_discrepancy_names_heat_transfer_on_hyddown_with_c_within_2_percent(name):
    """The issue's peer line: a HydDown discharge comes out as heat transfer (or an
    ambiguity containing it), no other effect named, and the reported C within 2 %."""
    from pneumatic_unload.discrepancy import DiscrepancySettings, find_discrepancy

    trace = load(DATA_DIR / f"{name}.npz")
    m = trace.meta
    t, y = record(trace, zlib.crc32(name.encode()))
    res = find_discrepancy(t, y, DiscrepancySettings(
        volume=m["volume"], length_diameter_ratio=m["length_diameter_ratio"],
        initial_temperature=m["t10"], atmosphere=101325.0, profile=False))
    print(f"{name}: {res.verdict}")
    assert any(e in HEAT for e in [res.effect, *res.ambiguous_with]), res.verdict
    assert all(e in HEAT for e in res.named) and all(e in HEAT for e in res.effects), \
        res.verdict
    assert abs(res.conductance / m["truth_conductance"] - 1.0) < TOLERANCE
    # the range's ends are C -+ 3 sigma, sigma the noise's and the model limits' (0.34 %
    # by default, the budget's term): two-sided about the truth
    lo, hi = res.conductance_range
    assert lo <= m["truth_conductance"] <= hi, (lo, hi)
