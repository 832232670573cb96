# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The subsonic index m of ISO 6358-1:2013 on data the package did not make: discharges of
the independent model ``test/foreign/newton_tank.py`` through the ISO law with m != 0.5,
an isentropic nozzle and two restrictions in series (1 kHz, 0.1 % FS noise, the subsonic
tail recorded). The grid with five noise draws is ``bench/bench_foreign_laws.py``.

Before m was fitted (main 4bd69e5, m held at 0.5): on the 20 ISO cases C within 1 % 8/20
(-11.5 % at m 0.25, b 0.3; +11.2 % at m 0.62, b 0.45), b within 0.03 5/20. Measured with
m in the family (bench, 140 traces): C within 1 % 140/140 (ISO, nozzle) and 23/25
(series: 3.8 % at most); |z| <= 2 with the record's sigma alone: ISO C 95 %, b 95 %,
m 97 %.
"""

from __future__ import annotations

import dataclasses
import math
import sqlite3
import zlib
from pathlib import Path

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, Nozzle, Series, Truth, discharge, iso_phi, truth
from scipy.optimize import least_squares

from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.curvefit.shape_reading import (
    iso_reduction,
    reduction_covariance,
    shape_wins,
)
from pneumatic_unload.curvefit.subsonic_offer import SUBSONIC_INDEX_PRIOR_SD, SUBSONIC_TERM
from pneumatic_unload.estimation import EstimatorSettings, UnloadResult, analyze, merge_final
from pneumatic_unload.physics import flow_function
from pneumatic_unload.uncertainty.budget import EXACT_INPUTS

P_ATM, T10, NOISE = 101325.0, 293.15, 1000.0


def _run(law: IsoLaw | Nozzle | Series, volume: float, p10: float, tau_heat: float,
         name: str, *, tail: float = 9.0, exact: bool = False) -> UnloadResult:
    """Analyse the foreign discharge of ``law`` recorded for ``tail`` tau0 after the
    opening (0.2 s plateau before it)."""
    tau0 = volume / (1.4e5 * truth(law).conductance)
    t = np.arange(0.0, 0.2 + tail * tau0, 1e-3)
    p = discharge(t, volume=volume, p10=p10, t10=T10, p_atm=P_ATM, tau_heat=tau_heat,
                  t_open=0.2, flow_law=law)
    y = p + np.random.default_rng(zlib.crc32(name.encode())).normal(0.0, NOISE, t.size)
    given = dict(EXACT_INPUTS) if exact else {}
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume, **given)))
    assert r.final and math.isfinite(r.conductance_model), r.status_text
    return r


def _stress_draw(k: int, law: Series, volume: float, p10: float, tau_heat: float,
                 tail: float, rig: tuple[float, float, float, float] | None = None, *,
                 exact: bool = False) -> UnloadResult:
    """Foreign draw ``k`` of ``bench/bench_random_draws.py`` rebuilt (its noise seeded by
    'stress-k'), analysed with the default settings (``exact``: the inputs stated exact,
    the bench's ``--record-only``); the rig at the defaults, or ``rig``: (T10 [K], wall
    [K], p_atm [Pa abs], the transducer's zero [Pa]) as the bench's ``--drawn-inputs``
    draws them."""
    t10, wall, p_atm, zero = rig or (T10, T10, P_ATM, 0.0)
    tau0 = volume / (1.4e5 * law.conductance)
    t = np.arange(0.0, 0.2 + tail * tau0, 1e-3)
    p = discharge(t, volume=volume, p10=p10, t10=t10, p_atm=p_atm, tau_heat=tau_heat,
                  t_open=0.2, flow_law=law, t_wall=wall)
    seed = [zlib.crc32(f"stress-{k}".encode()), 0]
    y = p + zero + np.random.default_rng(seed).normal(0.0, NOISE, t.size)
    given = dict(EXACT_INPUTS) if exact else {}
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume, **given)))
    return r


def _holds_the_acceptance(r: UnloadResult, tr: Truth) -> None:
    """C within 1 %, b within 0.03 and m within 0.05 of the foreign truth (its curve's
    nearest ISO law), each within 2 sigma."""
    assert abs(r.conductance_model / tr.conductance - 1.0) < 0.01
    for got, std, true, tol in ((r.critical_ratio, r.critical_ratio_std, tr.fit_b, 0.03),
                                (r.subsonic_index, r.subsonic_index_std, tr.fit_m, 0.05)):
        assert abs(got - true) <= min(tol, 2.0 * std), (got, std, true)


@pytest.mark.parametrize("m,b,volume,c,p10,tau_heat", [
    (0.25, 0.3, 2.5e-3, 4e-9, 7e5, 10.0), (0.35, 0.1, 2e-3, 2e-9, 7e5, 5.0),
    (0.62, 0.1, 5e-3, 1.2e-8, 8e5, 5.0), (0.75, 0.45, 10e-3, 2e-8, 8e5, 20.0)])
def test_m_fitted_on_a_foreign_iso_law(m, b, volume, c, p10, tau_heat):
    r = _run(IsoLaw(c, b, m), volume, p10, tau_heat, f"iso-{m}-{b}")
    fit = r.extra["curve_fit"]
    assert fit["subsonic_index_fitted"], fit["subsonic_source"]
    assert abs(r.conductance_model / c - 1.0) < 0.01
    assert abs(r.conductance_model - c) < 3.0 * r.conductance_model_std
    assert abs(r.critical_ratio - b) < 0.03 and abs(r.critical_ratio - b) < 3.0 * \
        r.critical_ratio_std
    assert abs(r.subsonic_index - m) < 0.05 and abs(r.subsonic_index - m) < 3.0 * \
        r.subsonic_index_std
    # m fitted: its lines are in the fit's; the budget of m says so
    assert r.extra["budget_m"]["combined_std"] == pytest.approx(r.subsonic_index_std)
    line = [x for x in r.extra["budget"]["terms"] if x["name"] == SUBSONIC_TERM]
    assert len(line) == 1 and line[0]["std"] == 0.0 and "fitted" in line[0]["note"]


def test_m_found_where_the_first_law_takes_up_the_shape_with_b():
    """m 0.70, b 0.26 with Newton cooling (9.3 bar, 3.7 L; a random draw of the
    acceptance's ranges): the natural law with m held took up the flow's shape with
    b 0.04 and gained nothing from m (m 0.517), so m was held for every law: C +0.65 %,
    b 0.040, m 0.5, residual 5 x the noise. Every law leaving structure with m held, the
    family is fitted with m free: the constant hA law with m 0.703."""
    r = _run(IsoLaw(1.4e-9, 0.2584, 0.7027), 3.675e-3, 9.343e5, 23.28, "m070-b026",
             tail=8.2)
    fit = r.extra["curve_fit"]
    assert fit["subsonic_index_fitted"], fit["subsonic_source"]
    assert not r.extra["model_inadequate"], r.status_text
    assert abs(r.conductance_model / 1.4e-9 - 1.0) < 0.01
    assert abs(r.critical_ratio - 0.2584) < 0.03
    assert abs(r.subsonic_index - 0.7027) < 0.05



def test_a_law_refuted_with_m_held_is_fitted_with_m_free():
    """Foreign draw 308 of ``bench/bench_random_draws.py`` (m 0.43, b 0.17, Newton cooling
    at 357 s, 3.7 L, 8.7 bar), its record and noise as the bench draws them: the constant
    hA law misfit 5.3 with m held, while the natural law, m held, followed the record to
    its noise with b 0.161: m was reported 0.500 +- 0.003 (z 22). m and the heat law trade:
    a law refuted with m held is fitted with m free too, and the constant hA's, 46 better
    in BIC, is the reading."""
    law = IsoLaw(1.2875012192460954e-09, 0.16653387752333396, 0.42534184920365464)
    volume = 0.003651537176062295
    tau0 = volume / (1.4e5 * law.conductance)
    t = np.arange(0.0, 0.2 + 11.642604965137476 * tau0, 1e-3)
    p = discharge(t, volume=volume, p10=865604.6853791203, t10=T10, p_atm=P_ATM,
                  tau_heat=356.80727558052723, t_open=0.2, flow_law=law)
    y = p + np.random.default_rng([zlib.crc32(b"stress-308"), 0]).normal(0.0, NOISE, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=volume)))
    fit = r.extra["curve_fit"]
    assert fit["subsonic_index_fitted"] and fit["heat_law"] == "fixed", fit["subsonic_source"]
    assert abs(r.conductance_model / law.conductance - 1.0) < 0.01
    for got, std, true, tol in ((r.critical_ratio, r.critical_ratio_std, law.b, 0.03),
                                (r.subsonic_index, r.subsonic_index_std, law.m, 0.05)):
        assert abs(got - true) <= min(tol, 2.0 * std), (got, std, true)


def test_a_hot_start_claimed_in_an_inadequate_fit_keeps_the_reading_without_it():
    """Foreign draw 200 of ``bench/bench_random_draws.py``: two restrictions in series
    (2.3e-9, b 0.14, m 0.49 then 1.4e-9, b 0.17, m 0.65), a nearly adiabatic 23 L tank
    (Newton cooling at 1590 s), 9.9 bar, no log. No ISO law makes that flow curve; a hot
    start does bend it (T10 340 K claimed beside a room's wall, the residuals still not
    white), and its C was -8.54 % at z -9.6, where every law without the claim read C
    within 0.1 % (density|m +0.01 %, 180 behind in BIC). The best law without the claim is
    a reading of the record all the same (heat_law_offer.hot_start_terms): the truth
    within 2 sigma."""
    law = Series(IsoLaw(2.2949248420434337e-09, 0.14303529491113368, 0.49130338344121444),
                 IsoLaw(1.3547010256784893e-09, 0.16673738368978694, 0.6543352197308598))
    r = _stress_draw(200, law, 0.02276759347812514, 990879.9636061225, 1590.540436111127,
                     8.920631630181514)
    c = truth(law).conductance
    assert "+wall" in r.extra["curve_fit"]["heat_law"] and r.extra["model_inadequate"]
    (line,) = [x for x in r.extra["budget"]["terms"] if x["name"].startswith("hot start")]
    assert "without the claim" in line["note"]
    assert line["std"] > 0.04 * c
    assert abs(r.conductance_model - c) <= 2.0 * r.conductance_model_std, (
        r.conductance_model / c - 1.0, r.conductance_model_std / c)


def test_a_law_far_from_the_record_is_not_fitted_with_m_free(monkeypatch):
    """bench_engine's record (7.5 L, natural heat exchange, 10 kHz, 100 s: 700 000 samples
    fitted): the constant hA law misfits it 16 times its noise with m held, and its
    first-order twin with m freed stays 54 times the best chi^2, beyond
    M_PROBE_TWIN_RATIO: it is not fitted with m free (that fit, 2e5 worse in BIC than the
    natural law, cost analyze 0.4 s of its 0.6 s)."""
    import pneumatic_unload.curvefit.law_family as law_family
    from pneumatic_unload.analysis.runs import settings_for
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.curvefit.law_search import MISFIT_SEARCH
    from pneumatic_unload.model import simulate

    made: dict[str, float] = {}
    fit = law_family.Family.fit

    def kept(self, key, **kw):
        out = fit(self, key, **kw)
        made[key] = out[0].misfit
        return out

    monkeypatch.setattr(law_family.Family, "fit", kept)
    cfg = RigConfig(volume=0.0075, effects=("heat_transfer",), pre_time=0.2, duration=99.8,
                    seed=1, rate=10000.0)
    sim = simulate(cfg)
    (r,) = merge_final(analyze(sim.t, sim.measured, settings_for(cfg)))
    assert r.extra["curve_fit"]["heat_law"] == "natural"
    assert made["fixed"] > MISFIT_SEARCH, made
    assert "fixed|m" not in made, made


def test_m_held_where_the_law_is_elliptic_and_its_line_is_small():
    """m = 0.5 made: the criterion holds it; the line of holding it is the record's own
    uncertainty of m times C's slope, far below C's sigma. m's own sigma carries the
    unfitted zero's move too."""
    c = 5e-9
    r = _run(IsoLaw(c, 0.4, 0.5), 3e-3, 7e5, 10.0, "iso-0.5")
    fit = r.extra["curve_fit"]
    assert not fit["subsonic_index_fitted"] and r.subsonic_index == 0.5
    assert "the record determines m" in fit["subsonic_source"]
    terms = {x["name"]: x["std"] for x in r.extra["budget_m"]["terms"]}
    assert 0.0 < terms["m held"] < 0.02
    # the transducer's zero (0.1 % of p10 by default, not fitted) moves the m-free fit
    assert terms["pressure transducer (offset)"] > terms["m held"]
    assert r.subsonic_index_std == pytest.approx(math.sqrt(sum(v * v for v in terms.values())))
    (line,) = [x for x in r.extra["budget"]["terms"] if x["name"] == SUBSONIC_TERM]
    assert 0.0 < line["std"] < 0.3 * r.conductance_model_std
    assert abs(r.conductance_model / c - 1.0) < 0.01


def test_m_held_with_a_wide_uncertainty_where_the_tail_is_short():
    """A record that ends soon after the flow turns subsonic hardly determines m (measured:
    m = 0.37 +- 0.09 for a component with m = 0.3; the criterion keeps 0.5): held at 0.5
    with an uncertainty of at least that (its distance from the record's m, or 0.144 for
    the range 0.25-0.75 where the record does not determine it at all), and C's line
    carries what that costs; C within 2 % and 3 sigma."""
    c = 5e-9
    r = _run(IsoLaw(c, 0.3, 0.3), 3e-3, 7e5, 10.0, "iso-short", tail=1.6)
    fit = r.extra["curve_fit"]
    assert not fit["subsonic_index_fitted"] and r.subsonic_index == 0.5
    assert 0.09 <= r.subsonic_index_std <= SUBSONIC_INDEX_PRIOR_SD + 1e-12
    (line,) = [x for x in r.extra["budget"]["terms"] if x["name"] == SUBSONIC_TERM]
    assert line["std"] > 0.0 and line["input_std"] == pytest.approx(r.subsonic_index_std)
    assert abs(r.conductance_model / c - 1.0) < 0.02
    assert abs(r.conductance_model - c) < 3.0 * r.conductance_model_std


def test_isentropic_nozzle_and_two_restrictions_in_series():
    nozzle = Nozzle(math.pi * 2e-3**2 / 4.0, 0.8)
    r = _run(nozzle, 3e-3, 7e5, 5.0, "nozzle")
    tr = truth(nozzle)
    assert abs(r.conductance_model / tr.conductance - 1.0) < 0.01
    assert abs(r.critical_ratio - tr.critical_ratio) < 0.03
    assert abs(r.subsonic_index - tr.subsonic_index) < 0.05
    pair = Series(IsoLaw(1.5e-8, 0.2, 0.4), IsoLaw(6e-9, 0.5, 0.6))
    r = _run(pair, 4e-3, 7e5, 20.0, "series")
    tr = truth(pair)
    assert abs(r.conductance_model / tr.conductance - 1.0) < 0.01
    assert abs(r.critical_ratio - tr.fit_b) < 0.03  # the ISO law nearest the pair's
    assert abs(r.subsonic_index - tr.fit_m) < 0.05


def test_an_elliptic_component_has_b_0_not_a_bound_above_it():
    """A component that is never choked in the ISO sense (b = 0: two elliptic elements in
    series, the exact law q = C p1 sqrt(1 - r^2)): b reaches 0 inside its range. With b
    bounded at 0.01 (main 8e5d52d) this record read b 0.010 +- 0.011 and C -0.14 % (the
    five draws of the bench: -0.14 to -0.26 %; with the noise at 10 Pa, -0.15 % at
    z -3); with the range from 0: b 0.001, C -0.05 %."""
    pair = Series(IsoLaw(1e-8, 0.0, 0.5), IsoLaw(1.2e-8, 0.0, 0.5))
    r = _run(pair, 6e-3, 6e5, 10.0, "series-elliptic-b0", exact=True)
    tr = truth(pair)
    err = r.conductance_model / tr.conductance - 1.0
    assert abs(err) < 1e-3
    assert abs(err) <= 2.0 * r.conductance_model_std / r.conductance_model
    assert 0.0 <= r.critical_ratio < 0.005
    assert abs(r.critical_ratio - tr.critical_ratio) <= 2.0 * r.critical_ratio_std


def test_coverage_of_c_b_and_m_over_an_iso_grid():
    """The record's own sigma (inputs exact, no model-limits line) covers C, b and m on
    the ISO family: 12 cases, m 0.25-0.75, b 0.3-0.6 (bench: 95-97 % within 2 sigma on
    100 traces); at least 10 of 12 within 2 sigma for each (binomial at 95 %:
    P(<= 9 of 12) = 2 %), and every C within 1 %. (b = 0.1 from 6-8 bar is never choked:
    there b, m and the heat exchange can trade, one record fitting b 0.23, m 0.30 with
    white residuals for 0.10, 0.35 adiabatic: b's sigma does not cover it. Left out here,
    said in the bench.)"""
    grid = [(m, b) for m in (0.25, 0.35, 0.62, 0.75) for b in (0.3, 0.45, 0.6)]
    zs: dict[str, list[float]] = {"C": [], "b": [], "m": []}
    vc = ((1e-3, 3e-9), (2.5e-3, 4e-9), (5e-3, 1.2e-8), (10e-3, 2e-8))
    for k, (m, b) in enumerate(grid):
        v, c = vc[k % 4]
        r = _run(IsoLaw(c, b, m), v, (8e5, 7e5, 6e5)[k % 3], (5.0, 10.0, 20.0, 1e4)[k % 4],
                 f"grid-{m}-{b}", exact=True)
        assert abs(r.conductance_model / c - 1.0) < 0.01, (m, b)
        zs["C"].append((r.conductance_model - c) / r.conductance_model_std)
        zs["b"].append((r.critical_ratio - b) / r.critical_ratio_std)
        zs["m"].append((r.subsonic_index - m) / r.subsonic_index_std)
    for name, z in zs.items():
        assert sum(abs(x) <= 2.0 for x in z) >= 10, (name, np.round(z, 2))


def test_results_database_of_schema_1_gains_the_m_columns(tmp_path):
    import shutil

    from pneumatic_unload.testline.db import SCHEMA_VERSION, open_db

    # a file written by the package at schema 1 (test/data/results_db/make_legacy.py)
    path = tmp_path / "old.sqlite"
    shutil.copy(Path(__file__).parent / "data" / "results_db" / "schema1.sqlite", path)
    open_db(path).close()
    con = sqlite3.connect(path)
    cols = {row[1] for row in con.execute("PRAGMA table_info(unloads)")}
    assert {"subsonic_index", "subsonic_index_std", "pressure_offset",
            "pressure_offset_std", "direction", "supply_pressure"} <= cols
    # the upgrade runs every migration: the file ends at the package's current schema
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_held_m_carries_the_heat_laws_spread_of_m():
    """m held at 0.5 where the laws fitted with m disagree about it: the pair whose upstream
    element chokes (ISO-shaped only roughly: the free least-squares ISO law of its flow
    curve has m 0.491) was held at 0.500 +- 0.0024 (the constant-hA law's m-free fit alone;
    the density law fitted with m, 4 in BIC from it, put m at 0.523): 3.8 sigma from the
    free fit's m. Now m's uncertainty is the root mean square of holding 0.5 with the laws'
    spread of m (its budget's model-form line), and C's and b's m lines grow with it."""
    pair = Series(IsoLaw(6e-9, 0.45, 0.5), IsoLaw(1.5e-8, 0.2, 0.5))
    r = _run(pair, 3e-3, 6e5, 5.0, "series-upstream-chokes")
    tr = truth(pair)
    fit = r.extra["curve_fit"]
    assert not fit["subsonic_index_fitted"] and r.subsonic_index == 0.5, fit["subsonic_source"]
    laws = fit["laws"]
    free = laws[fit["heat_law"] + "|m"]
    rms = math.hypot(free["subsonic_index_std"], free["subsonic_index"] - 0.5)
    assert r.subsonic_index_std > 1.5 * rms  # the laws' spread, beyond the chosen law's own
    terms = {x["name"]: x for x in r.extra["budget_m"]["terms"]}
    assert terms["m held"]["std"] == pytest.approx(rms)
    assert terms["model form (heat laws)"]["std"] > rms
    assert abs(r.subsonic_index - tr.fit_m) <= 2.0 * r.subsonic_index_std
    # C's line of m: the held value's uncertainty (the transducer's zero, in m's budget
    # beside it, is C's own offset line)
    (line,) = [x for x in r.extra["budget"]["terms"] if x["name"] == SUBSONIC_TERM]
    assert line["input_std"] == pytest.approx(fit["subsonic_index_std"])
    zero = terms["pressure transducer (offset)"]["std"]
    assert r.subsonic_index_std == pytest.approx(math.hypot(fit["subsonic_index_std"], zero))
    assert abs(r.conductance_model / tr.conductance - 1.0) < 0.01


def test_the_iso_law_nearest_a_curve_of_another_ellipse_exponent():
    """:func:`iso_reduction`: the curve itself at q = 2 and continuous about it; at q = 3
    the least squares of an ISO law written apart from the package (test/foreign's, on its
    own grid from 0.02) within 0.003, and nearer the curve than the (b, m) it was made
    from; the covariance through the Jacobian that of (b, m) where q is exact."""
    assert iso_reduction({"b": 0.3, "m": 0.4, "q": 2.0}, "q") == (0.3, 0.4)
    near = iso_reduction({"b": 0.3, "m": 0.4, "q": 2.001}, "q")
    assert abs(near[0] - 0.3) < 2e-3 and abs(near[1] - 0.4) < 2e-3
    b, m, q = 0.2, 0.45, 3.0
    b_r, m_r = iso_reduction({"b": b, "m": m, "q": q}, "q")
    r = np.linspace(0.02, 0.999, 2000)
    target = flow_function(r, b, m, ellipse_exponent=q)

    def gap(v: np.ndarray) -> np.ndarray:
        return np.array([iso_phi(float(x), float(v[0]), float(v[1])) for x in r]) - target

    other = least_squares(gap, [0.3, 0.5], bounds=([0.0, 0.05], [0.99, 3.0])).x
    assert abs(b_r - other[0]) < 3e-3 and abs(m_r - other[1]) < 3e-3
    assert np.std(flow_function(r, b_r, m_r) - target) < np.std(
        flow_function(r, b, m) - target)
    cov = np.diag([1e-4, 4e-4, 0.0])
    cov_r = reduction_covariance({"b": 0.3, "m": 0.4, "q": 2.0}, "q", cov)
    assert cov_r == pytest.approx(cov[:2, :2], rel=0.02, abs=1e-7)


@pytest.mark.parametrize("first,second", [((1.3e-8, 0.42, 0.52), (1.2e-8, 0.18, 0.30)),
                                          ((5.6e-9, 0.49, 0.69), (4.4e-9, 0.14, 0.37)),
                                          ((2e-9, 0.45, 0.40), (9e-9, 0.30, 0.60))])
def test_the_iso_law_nearest_a_pair_in_series(first, second):
    """:func:`iso_reduction` of a pair in series (the kernel's ISO 6358-3 pair) against
    test/foreign's truth for the same pair (its own pair and least squares, scipy, on its
    own grid from 0.02): within 0.003 in b and m."""
    (c1, b1, m1), (c2, b2, m2) = first, second
    tr = truth(Series(IsoLaw(c1, b1, m1), IsoLaw(c2, b2, m2)))
    b_r, m_r = iso_reduction({"b": b1, "m": m1, "b2": b2, "m2": m2, "kappa": c2 / c1},
                             "series")
    assert abs(b_r - tr.fit_b) < 3e-3 and abs(m_r - tr.fit_m) < 3e-3, (b_r, m_r, tr)


#: Foreign draws of ``bench/bench_random_draws.py`` rebuilt: (draw, upstream and
#: downstream element (C, b, m), volume [m^3], p10 [Pa], tau_h [s], recorded [tau0]),
#: the reading reported and its words in ``shape_source``.
SHAPE_DRAWS = {
    "q": (68, (1.0205487604621236e-08, 0.514122626201049, 0.6065037388207638),
          (2.0600311602371668e-08, 0.25622481505346206, 0.3855516787667509),
          0.03366697224034439, 702677.4921182452, 6626.506880036085, 8.507290577381873,
          "'flow-curve shape: ", "q "),
    "pair": (217, (5.6266658443664135e-09, 0.48974607847006413, 0.6948114167907893),
             (4.359719857827273e-09, 0.14024132326748553, 0.37404763244930495),
             0.005805737460237651, 926013.0930156833, 1536.1571221881482,
             11.464499672635952, "'flow-curve pair: ", "a pair in series: b2")}


@pytest.mark.parametrize("name", list(SHAPE_DRAWS))
def test_a_pair_in_series_reads_the_iso_law_nearest_its_flow_curve(name):
    """Two restrictions in series: their flow curve is not ISO-shaped, and its nearest ISO
    law over r (ISO 6358-3's reduction) is not what the discharge's own weighting reads.

    * 'q', draw 68 (1.02e-8, b 0.51, m 0.61 then 2.06e-8, b 0.26, m 0.39), 34 L, 7 bar,
      nearly adiabatic: the nearest ISO law is b 0.347, m 0.537; the discharge read b
      0.356 with m held at 0.5 (+- 0.02: z -4.6). Fitted again with the ellipse's exponent
      free (q 2.61 +- 0.04) it is clearly better by the criterion.
    * 'pair', draw 217 (5.63e-9, b 0.49, m 0.69 then 4.36e-9, b 0.14, m 0.37), 5.8 L, 9.3
      bar: the nearest ISO law is b 0.162, m 0.470; the discharge read b 0.231, m 0.416,
      the ellipse's exponent freed b 0.199-0.216, m 0.41-0.43 (with the truth's own heat
      law m 0.410 +- 0.005, z -12). Fitted as a pair in series (ISO 6358-3) it is clearly
      better by the criterion (17 on the best q reading).

    The ISO law nearest the better curve is reported: C, b and m within the tolerance and
    2 sigma, and the reading named in ``subsonic_source`` and ``shape_source``."""
    k, first, second, volume, p10, tau_h, tail, reading, words = SHAPE_DRAWS[name]
    law = Series(IsoLaw(*first), IsoLaw(*second))
    r = _stress_draw(k, law, volume, p10, tau_h, tail)
    fit = r.extra["curve_fit"]
    assert fit["subsonic_index_fitted"] and reading in fit["subsonic_source"], fit
    assert fit["shape_source"].startswith(words) or f"; {words}" in fit["shape_source"], \
        fit["shape_source"]
    _holds_the_acceptance(r, truth(law))


def test_a_pair_read_with_every_heat_law_widens_what_the_record_does_not_settle():
    """Foreign draw 111 (a pair, m 0.36 then 0.69, cooled by a constant hA of 29 s), the
    inputs stated exact: the chosen law (natural convection, its turbulent branch free, m
    free) read b 0.026 +- 0.007 for 0.357 (z -47) and m 0.383 +- 0.002 for 0.439, its own
    pair reading alike. Read as a pair with the density law it fits 35 better by the
    criterion (b 0.294 +- 0.052: not settled, so not reported); with the truth's own law,
    b 0.356. The readings of every law enter the heat laws' spread: b and m within 2
    sigma, the spread their largest line."""
    law = Series(IsoLaw(5.6007419141888685e-09, 0.46966758549121435, 0.3551448185169123),
                 IsoLaw(1.3175772268560486e-08, 0.45491745822298313, 0.688657629116457))
    r = _stress_draw(111, law, 0.007848741387684018, 766858.4184192984, 28.783465911893273,
                     10.397964524091819, exact=True)
    tr = truth(law)
    assert abs(r.conductance_model / tr.conductance - 1.0) < 0.01
    assert abs(r.critical_ratio - tr.fit_b) <= 2.0 * r.critical_ratio_std
    assert abs(r.subsonic_index - tr.fit_m) <= 2.0 * r.subsonic_index_std
    for key in ("budget_b", "budget_m"):
        assert r.extra[key]["largest"] == "model form (heat laws)", r.extra[key]


#: Foreign draws of bench/bench_random_draws.py with the rig drawn as the default settings
#: say it is uncertain (--drawn-inputs): (draw, first element, second element, V [m^3],
#: p10 [Pa], the heat exchange's time constant [s], tau0 recorded, (T10 [K], wall [K],
#: p_atm [Pa], zero [Pa]), the budget line of m that covers the rig).
RIG_DRAWS = {
    "zero, m held": (
        77, (1.2496560577910252e-09, 0.29137193813551754, 0.5286633537718832),
        (8.745794814844334e-09, 0.38785963452889405, 0.2642194585510495),
        0.0027194290177234488, 960523.0461367194, 192.58276443242016, 6.031246159249889,
        (288.36233897781585, 287.9626936916278, 101308.51941571366, -239.09648205260248),
        "pressure transducer (offset)"),
    "wall, m fitted": (
        106, (5.43416071302054e-09, 0.23376387719074973, 0.5993874073144964),
        (1.5593446503329466e-09, 0.37037089612885266, 0.7479409157105658),
        0.005777572824415037, 543572.1733429817, 12.617023112061643, 7.1232987193558905,
        (297.51514835586323, 299.44436631484564, 101126.48382906614, -292.8763850034737),
        "wall temperature")}


@pytest.mark.parametrize("name", list(RIG_DRAWS))
def test_the_rig_s_inputs_move_m_within_its_sigma(name):
    """m's budget carries what the rig's stated uncertainties do to m, as b's does.

    * 'zero, m held', draw 77 (a pair, 2.7 L, 9.6 bar, the record ending 6 tau0 after the
      opening): a -239 Pa zero the record's end does not show. m was held at 0.500 +-
      0.004 for 0.529 (z -6.8): the law's fit with m free moves along its valley with the
      zero freed by 1.2e-4 per Pa, and the default 0.1 % of p10 (960 Pa) of zero is now
      m's line.
    * 'wall, m fitted', draw 106 (a pair, m 0.60 then 0.75, 5.8 L, a heat exchange of
      12.6 s): the wall 1.9 K above T10, assumed equal. m read 0.736 +- 0.0016 for 0.746
      (z -6.0): the chosen law refitted with the wall moved by its 2 K moves m by 0.011
      (b's line had it: 0.025).

    m within the tolerance and 2 sigma, the line named in its budget."""
    k, first, second, volume, p10, tau_h, tail, rig, line = RIG_DRAWS[name]
    law = Series(IsoLaw(*first), IsoLaw(*second))
    r = _stress_draw(k, law, volume, p10, tau_h, tail, rig)
    tr = truth(law)
    assert abs(r.subsonic_index - tr.fit_m) <= min(0.05, 2.0 * r.subsonic_index_std), \
        (r.subsonic_index, r.subsonic_index_std, tr.fit_m)
    terms = {x["name"]: x for x in r.extra["budget_m"]["terms"]}
    assert terms[line]["std"] >= 0.5 * abs(r.subsonic_index - tr.fit_m), terms
    # the input's own uncertainty stated: the zero's 0.1 % of p10 [Pa], the wall's 2 K
    assert terms[line]["input_std"] == pytest.approx(1e-3 * p10 if "offset" in line else 2.0,
                                                     rel=1e-3), terms[line]


def test_the_shape_wins_only_over_every_other_reading():
    """:func:`shape_wins`: the curve with q free is reported only where the criterion
    prefers it by its threshold to every fit and reading. Foreign draw 196 with the inputs
    drawn (a pair in series, the gas 3.2 K warmer than its wall, a -0.5 kPa zero): the
    shape's reading was 51 better than the chosen law but 8 worse than an unclaimed warm
    gas's, and reported m 0.492 +- 0.004 for 0.515 (z -4.4); the chosen law read 0.515."""
    entry = (CurveFit(5e-9, 5e-11, 0.3, 0.01, 0.0, 7e5, 1e5, 1.0, 0.1, 1e3, 1000, True,
                      ellipse_exponent=2.6, ellipse_exponent_std=0.04), 0.0, 0)
    shape = {"flow-curve shape: density|m": entry}
    bic = {"density|m": 0.0, "fixed+wall|m": -59.1, "flow-curve shape: density|m": -51.4}
    assert shape_wins(shape, bic) is None
    bic["fixed+wall|m"] = -40.0
    assert shape_wins(shape, bic) == "flow-curve shape: density|m"
    bic["fixed+wall|m"] = -45.0  # within the threshold of it: not clearly better
    assert shape_wins(shape, bic) is None
    assert shape_wins({}, bic) is None
    # q not determined (a 5 Hz record, 30 kPa of noise and a leak: q 1.57 +- 2.29): not
    # reported, however much better it fits
    bic["fixed+wall|m"] = 0.0
    assert shape_wins(shape, bic) == "flow-curve shape: density|m"
    loose = dataclasses.replace(entry[0], ellipse_exponent_std=2.29)
    assert shape_wins({"flow-curve shape: density|m": (loose, 0.0, 0)}, bic) is None
    # a pair in series settles by the reduced b and m it determines (within 0.05); the
    # best shape reading is the one compared with the fits, and only where it settles (a
    # settled pair behind a loose q is not reported: draw 141, b 0.380 for 0.346)
    pair = dataclasses.replace(entry[0], ellipse_exponent_std=math.nan,
                               critical_ratio_std=0.01, subsonic_index_std=0.02)
    both = {"flow-curve shape: density|m": (loose, 0.0, 0),
            "flow-curve pair: density|m": (pair, 0.0, 0)}
    bic = {"density|m": 0.0, "flow-curve shape: density|m": -50.0,
           "flow-curve pair: density|m": -55.0}
    assert shape_wins(both, bic) == "flow-curve pair: density|m"
    bic["flow-curve shape: density|m"] = -60.0
    assert shape_wins(both, bic) is None
    both["flow-curve pair: density|m"] = (dataclasses.replace(pair, critical_ratio_std=0.08),
                                          0.0, 0)
    assert shape_wins(both, bic) is None


def test_the_estimator_model_takes_the_three_shapes_and_refuses_another():
    """``estimator_model``'s flow-curve shapes: the ISO law (b, m), q beside them, a pair
    in series (b2, m2, kappa beside them); another shape is one clear error."""
    from pneumatic_unload.model.effects import Start
    from pneumatic_unload.model.inversion import estimator_model

    settings = EstimatorSettings(volume=2e-3)
    start = Start(conductance=5e-9, critical_ratio=0.3, t_open=0.2, p10=7e5, p_atm=P_ATM,
                  tau=2.0, dt=1e-3, t_first=0.0, t_last=10.0)
    names = {shape: {p.name for p in estimator_model(settings, start, fit_m=True,
                                                     shape=shape).parameters}
             for shape in ("iso", "q", "series")}
    assert names["q"] - names["iso"] == {"q"}
    assert names["series"] - names["iso"] == {"b2", "m2", "kappa"}
    with pytest.raises(ValueError, match="unknown flow-curve shape 'spline'"):
        estimator_model(settings, start, shape="spline")


def test_a_reading_counts_its_own_variance_in_the_spread():
    """``law_spread`` with ``own``: a reading named there adds its own variance beyond the
    chosen law's, weighted as its distance (the model average's variance, closed form);
    without it only the distance counts; one far behind in the criterion adds next to
    nothing (its weight exp(-6))."""
    from pneumatic_unload.curvefit.wall_moves import law_spread

    def entry(b: float, sd: float) -> tuple[CurveFit, float, int]:
        return (CurveFit(5e-9, 5e-11, b, sd, 0.0, 7e5, 1e5, 1.0, 0.1, 1e3, 1000, True),
                0.0, 0)

    fits = {"fixed|m": entry(0.30, 0.01), "flow-curve pair: fixed|m": entry(0.26, 0.05)}
    bic = {"fixed|m": 0.0, "flow-curve pair: fixed|m": 2.0}
    w = math.exp(-1.0)
    plain = law_spread(fits, bic, "fixed|m", "critical_ratio")
    assert plain == pytest.approx(math.sqrt(w * 0.04**2 / (1.0 + w)), rel=1e-12)
    own = law_spread(fits, bic, "fixed|m", "critical_ratio",
                     own=frozenset({"flow-curve pair: fixed|m"}))
    assert own == pytest.approx(math.sqrt(w * (0.04**2 + 0.05**2 - 0.01**2) / (1.0 + w)),
                                rel=1e-12)
    bic["flow-curve pair: fixed|m"] = 12.0
    w = math.exp(-6.0)
    assert law_spread(fits, bic, "fixed|m", "critical_ratio",
                      own=frozenset({"flow-curve pair: fixed|m"})) == pytest.approx(
        math.sqrt(w * (0.04**2 + 0.05**2 - 0.01**2) / (1.0 + w)), rel=1e-12)
