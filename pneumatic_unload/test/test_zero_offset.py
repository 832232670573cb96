# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A transducer's zero offset, on data the package did not make (the independent model of
``test/foreign/newton_tank.py``, 1 kHz, 0.1 % FS noise): with p_atm given, a record that
settles away from it has the offset fitted and reported; gauge readings work with the final
plateau as the zero (``--gauge --atmosphere-auto``).

Before (main 3d7f6bd): an absolute transducer reading 2.5 kPa low, component m 0.3, b 0.3:
model C +3.99 % (z 2.4), b 0.478. Now (measured here): C +0.02 %, b 0.300, m 0.302, offset
-2516 +- 20 Pa.
"""

from __future__ import annotations

import json
import math
import zlib

import numpy as np
import pytest
from foreign.newton_tank import IsoLaw, discharge

from pneumatic_unload.app.cli import main
from pneumatic_unload.estimation import EstimatorSettings, analyze, merge_final

C, V, P_ATM = 5e-9, 3e-3, 101325.0


def _record(offset: float, seed: int, m: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """The foreign discharge read by a transducer with a zero ``offset`` [Pa]."""
    tau0 = V / (1.4e5 * C)
    t = np.arange(0.0, 0.2 + 9.0 * tau0, 1e-3)
    p = discharge(t, volume=V, p10=7e5, t10=293.15, p_atm=P_ATM, tau_heat=10.0,
                  t_open=0.2, flow_law=IsoLaw(C, 0.3, m))
    return t, p + offset + np.random.default_rng(seed).normal(0.0, 1000.0, t.size)


@pytest.mark.parametrize("offset,seed", [(-2500.0, 1), (3000.0, 2), (-800.0, 3)])
def test_offset_fitted_where_the_record_settles_away_from_the_given_atmosphere(offset, seed):
    t, y = _record(offset, seed)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=V)))
    fit = r.extra["curve_fit"]
    assert fit["offset_source"].startswith("fitted"), fit["offset_source"]
    assert abs(r.pressure_offset - offset) < 500.0
    assert abs(r.pressure_offset - offset) < 3.0 * r.pressure_offset_std
    assert abs(r.conductance_model / C - 1.0) < 0.01
    assert abs(r.conductance_model - C) < 3.0 * r.conductance_model_std
    assert abs(r.critical_ratio - 0.3) < 0.03 and abs(r.subsonic_index - 0.3) < 0.05
    (line,) = [x for x in r.extra["budget"]["terms"] if x["name"].startswith(
        "pressure transducer zero")]
    assert line["value"] == pytest.approx(r.pressure_offset)


def test_an_offset_that_b_and_m_took_up_is_still_found():
    """A random draw of the acceptance's ranges (m 0.5, b 0.36, 8.8 bar, 2.3 L, 398 Hz,
    -2.0 kPa): the chosen fit had m free, its b 0.074 and m 0.62 had taken the offset up,
    and the offset's first-order twin from it gained nothing: not fitted, b off by 0.28
    (1 noise draw in 12 here; the draw of the stress run: b 0.066 at z -21). The record's
    end lies 6 of its standard errors from p_atm: the offset is probed in full, from the
    law's fit with m held too (12 draws in 12: b 0.349-0.362, offset within 120 Pa)."""
    c, v, b, p10, offset = 1.1e-8, 2.2547e-3, 0.3586, 8.8207e5, -2031.0
    t = np.arange(0.0, 2.59 + 8.44 * v / (1.4e5 * c), 1.0 / 397.74)
    p = discharge(t, volume=v, p10=p10, t10=293.15, p_atm=P_ATM, tau_heat=15.07,
                  t_open=2.59, flow_law=IsoLaw(c, b, 0.5))
    y = p + offset + np.random.default_rng(1).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=v)))
    fit = r.extra["curve_fit"]
    assert fit["offset_source"].startswith("fitted"), fit["offset_source"]
    assert abs(r.pressure_offset - offset) < 500.0
    assert abs(r.critical_ratio - b) < 0.03, fit["subsonic_source"]
    assert abs(r.conductance_model / c - 1.0) < 0.01


def test_an_offset_not_preferred_over_a_law_that_took_it_up_is_in_the_spread():
    """Foreign draw 51 of ``bench/bench_random_draws.py --drawn-inputs``: the ISO law with
    m 0.69, b 0.31, Newton cooling at 21 s, 0.76 L, 8.0 bar; the rig off the defaults as
    a real one is (T10 3.7 K above 20 C, the wall 2.4 K below the gas, a +723 Pa zero,
    V 0.8 % off). The natural law with a warm wall and m free takes the zero up: m 0.833
    +- 0.004 (z 34). The record's end is clearly away from p_atm; the family fitted with
    the offset reads the constant hA law, m 0.689, +727 Pa, within the criterion's window
    of it but not clearly better. That reading joins the model-form spread (as an
    unclaimed warm gas does): m and C within 2 sigma."""
    law = IsoLaw(2.023634945832152e-09, 0.3093185868914723, 0.6920142914500458)
    volume, p10, t10 = 0.0007581419141216393, 800823.5611874256, 296.8896841472037
    tau0 = volume / (1.4e5 * law.conductance)
    t = np.arange(0.0, 0.2 + 7.831626597496463 * tau0, 1e-3)
    p = discharge(t, volume=volume, p10=p10, t10=t10, p_atm=101308.0998083986,
                  tau_heat=21.278167954611437, t_open=0.2, flow_law=law,
                  t_wall=294.451266232445)
    y = p + 723.13503972797 + np.random.default_rng(
        [zlib.crc32(b"stress-51"), 0]).normal(0.0, 1000.0, t.size)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=0.0007643871198298615)))
    fit = r.extra["curve_fit"]
    assert fit["offset_source"].startswith("not fitted"), fit["offset_source"]
    assert "with the offset" in fit["offset_source"]
    assert abs(r.subsonic_index - law.m) <= 2.0 * r.subsonic_index_std, (
        r.subsonic_index, r.subsonic_index_std)
    assert abs(r.conductance_model - law.conductance) <= 2.0 * r.conductance_model_std
    assert abs(r.critical_ratio - law.b) <= 2.0 * r.critical_ratio_std


def test_no_offset_is_fitted_where_the_record_settles_at_the_given_atmosphere():
    t, y = _record(0.0, 4, m=0.5)
    (r,) = merge_final(analyze(t, y, EstimatorSettings(volume=V)))
    fit = r.extra["curve_fit"]
    assert fit["offset_source"].startswith("not fitted"), fit["offset_source"]
    assert math.isnan(r.pressure_offset) and math.isnan(r.pressure_offset_std)
    assert abs(r.conductance_model / C - 1.0) < 0.01


def test_gauge_readings_with_the_final_plateau_as_the_zero(tmp_path, capsys):
    """A gauge transducer whose zero reads -2.4 kPa (the AeroLab logs settle there), the
    barometer unknown: ``--gauge --atmosphere-auto`` adds the standard atmosphere, fits
    p_atm from the final plateau and carries the assumed barometer's 2 kPa in C's budget."""
    t, y = _record(-2400.0, 5)
    path = tmp_path / "gauge.csv"
    np.savetxt(path, np.column_stack([t, (y - P_ATM) / 1e3]), delimiter=",",
               header="time [s],pressure [kPa g]", comments="")
    assert main([
        "analyze", str(path), "--gauge", "--atmosphere-auto", "--volume", str(V),
        "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (u,) = [x for x in out["unloads"] if x["final"]]
    assert abs(u["conductance_model"] / C - 1.0) < 0.02
    assert abs(u["conductance_model"] - C) < 3.0 * u["conductance_model_std"]
    assert u["p_atm"] == pytest.approx(P_ATM - 2400.0, abs=300.0)
    (line,) = [x for x in u["budget"]["terms"] if x["name"].startswith(
        "pressure transducer (offset)")]
    assert line["input_std"] == pytest.approx(2000.0)


def test_gauge_needs_a_barometer_or_the_final_plateau(tmp_path, capsys):
    t, y = _record(0.0, 6)
    path = tmp_path / "gauge.csv"
    np.savetxt(path, np.column_stack([t, (y - P_ATM) / 1e3]), delimiter=",",
               header="time [s],pressure [kPa g]", comments="")
    assert main(["analyze", str(path), "--gauge", "--volume", str(V)]) == 2
    err = capsys.readouterr().err
    assert "--gauge needs --atmosphere PA" in err and "--atmosphere-auto" in err
