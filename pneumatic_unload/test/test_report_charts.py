# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The test-line report's control charts read as charts (a C axis with values and its
unit, the parts under the x axis, a scale for one point) and its parts table gives C by
direction when the database holds charges (#55)."""

from __future__ import annotations

import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pneumatic_unload.testline.report import control_chart, nice_ticks

SVG = "{http://www.w3.org/2000/svg}"


def _svg(text: str) -> ET.Element:
    return ET.fromstring(text.replace("<svg ", '<svg xmlns="http://www.w3.org/2000/svg" ', 1))


def _texts(root: ET.Element, cls: str) -> list[str]:
    return [t.text or "" for t in root.iter(f"{SVG}text") if t.get("class") == cls]


def test_a_chart_has_a_c_axis_with_values_and_unit_and_the_parts_labelled():
    pts = [(float(k), c, f"V14-00{k} run{k}.mcap#0") for k, c in
           enumerate([5.00e-9, 5.02e-9, 4.97e-9, 5.05e-9])]
    root = _svg(control_chart(pts, "g14"))
    ticks = [float(v) for v in _texts(root, "y-tick")]
    assert len(ticks) >= 3 and ticks == sorted(ticks)
    assert min(ticks) <= 0.497 and max(ticks) >= 0.505  # the axis covers the points
    assert _texts(root, "y-label") == ["C [dm^3/(s bar)]"]
    assert _texts(root, "x-label") == ["V14-000", "V14-001", "V14-002", "V14-003"]
    assert len([c for c in root.iter(f"{SVG}circle")]) == 4
    assert len([ln for ln in root.iter(f"{SVG}line") if ln.get("class") == "limit"]) == 3
    w, h = float(root.get("width")), float(root.get("height"))
    for t in root.iter(f"{SVG}text"):  # every text inside the drawing
        assert 0 <= float(t.get("x")) <= w and 0 <= float(t.get("y")) <= h, t.text


def test_a_one_point_chart_has_a_scale_and_no_zero_width_limits():
    """One unload: the limits were drawn as 0.3000 .. 0.3000 and the axis had no span."""
    text = control_chart([(0.0, 3e-9, "P-1 a.mcap#0")], "t1")
    assert "0.3000 .. 0.3000" not in text
    assert "no limits (a moving range needs two)" in text
    root = _svg(text)
    ticks = [float(v) for v in _texts(root, "y-tick")]
    assert len(ticks) >= 3 and min(ticks) < 0.3 < max(ticks)
    assert max(ticks) - min(ticks) < 0.1 * 0.3  # a scale that shows the point's digits
    assert not [ln for ln in root.iter(f"{SVG}line") if ln.get("class") == "limit"]
    assert _texts(root, "x-label") == ["P-1"]


def test_nice_ticks_are_round_and_inside():
    import math

    for lo, hi in ((0.294, 0.306), (0.0, 1.0), (4.61, 5.39), (1.2e-3, 9.7e-3), (12.0, 12.5)):
        ticks = nice_ticks(lo, hi)
        assert 3 <= len(ticks) <= 8, (lo, hi, ticks)
        assert all(lo - 1e-12 <= t <= hi + 1e-12 for t in ticks), (lo, hi, ticks)
        step = ticks[1] - ticks[0]
        mant = step / 10.0 ** math.floor(math.log10(step) + 1e-9)
        assert min(abs(mant - m) for m in (1.0, 2.0, 5.0)) < 1e-6, (lo, hi, step)
        assert all(abs(t / step - round(t / step)) < 1e-6 for t in ticks), (lo, hi, ticks)


@pytest.fixture(scope="module")
def two_way_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A discharge bag and a charge bag of one part (the charge's direction only in its
    rig configuration) and a one-unload part, in one batch without a --direction."""
    from pneumatic_unload.analysis.runs import write_simulated_bag
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.testline import InputOptions, run_batch

    d = tmp_path_factory.mktemp("twoway")
    common = {"volume": 1e-3, "conductance": 5e-9, "critical_ratio": 0.45,
              "noise_std": 500.0, "pre_time": 0.3, "effects": ("heat_transfer",)}
    write_simulated_bag(RigConfig(**common, initial_pressure=6e5, duration=3.0, seed=1),
                        d / "V14-009_discharge", analyze_live=False)
    write_simulated_bag(RigConfig(**common, direction="charge", initial_pressure=101325.0,
                                  supply_pressure=6e5, duration=3.0, seed=2),
                        d / "V14-009_charge", analyze_live=False)
    db = d / "both.sqlite"
    run_batch([str(d / "V14-009_discharge"), str(d / "V14-009_charge")],
              InputOptions(part_regex=r"(V14-\d+)"), db_path=db)
    return db


def test_a_batch_of_both_directions_fills_the_charge_columns(two_way_db: Path,
                                                             tmp_path: Path):
    """A charge bag (its direction recorded in the bag's rig configuration) in a batch
    without --direction is analysed as a charge: the charge columns were always '-'."""
    from pneumatic_unload.testline import open_db, unload_rows
    from pneumatic_unload.testline.report import html_report

    con = open_db(two_way_db)
    try:
        rows = unload_rows(con)
    finally:
        con.close()
    assert sorted((r["direction"], r["status"]) for r in rows) == [
        ("charge", "ok"), ("discharge", "ok")]
    out = tmp_path / "r.html"
    html_report(two_way_db, out)
    page = out.read_text()
    parts = page[page.index("id='parts'"):page.index("</table>", page.index("id='parts'"))]
    assert "<th>C charge</th>" in parts
    row = re.search(r"<tr class='[^']*'><td class='l'>V14-009</td>.*?</tr>", parts)
    assert row is not None
    cells = re.findall(r"<td>(.*?)</td>", row.group(0))
    charge = cells[-3:]  # C discharge, C charge, charge - discharge (then verdict, reason)
    assert all(c != "-" for c in charge), cells
    assert charge[1].startswith("0.4") or charge[1].startswith("0.5"), cells


def test_a_discharge_only_report_says_so_instead_of_dash_columns(tmp_path: Path):
    from pneumatic_unload.config import RigConfig
    from pneumatic_unload.estimation import EstimatorSettings, analyze
    from pneumatic_unload.model import simulate
    from pneumatic_unload.testline.live import LiveResults
    from pneumatic_unload.testline.report import html_report

    sim = simulate(RigConfig(volume=1e-3, conductance=3e-9, duration=3.0, pre_time=0.3,
                             noise_std=500.0, seed=4))
    final = next(r for r in analyze(sim.t, sim.measured, EstimatorSettings(volume=1e-3))
                 if r.final)
    db = tmp_path / "one.sqlite"
    LiveResults(db, "estimator").write(final, EstimatorSettings(volume=1e-3), "P-1")
    out = tmp_path / "one.html"
    html_report(db, out)
    page = out.read_text()
    assert "C charge" not in page and "Every unload is a discharge" in page
    assert "no limits (a moving range needs two)" in page
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium (CI installs Debian's chromium; apt install chromium)")
    r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                        f"--user-data-dir={tmp_path / 'chromium'}", "--dump-dom",
                        out.as_uri()], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    dom = r.stdout
    # the browser parsed the chart: its axis values, its unit and the part under it
    assert len(re.findall(r'<text class="y-tick"[^>]*>[0-9.]+</text>', dom)) >= 3, dom[:800]
    assert 'class="y-label"' in dom and "C [dm^3/(s bar)]" in dom
    assert re.search(r'<text class="x-label"[^>]*>P-1</text>', dom)
