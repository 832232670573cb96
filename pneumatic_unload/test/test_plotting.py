# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The analysis plot shows the uncertainty budget line by line and the C to report, as the
text output does (issue #11)."""

import dataclasses

import matplotlib
import pytest

from pneumatic_unload.analysis.output import format_result
from pneumatic_unload.analysis.plotting import analysis_figure, figure_text, plot_analysis
from pneumatic_unload.analysis.runs import settings_for
from pneumatic_unload.config import RigConfig
from pneumatic_unload.estimation import analyze, merge_final
from pneumatic_unload.model import simulate

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def analysed():
    cfg = RigConfig(volume=3e-3, conductance=4e-9, effects=("heat_transfer",),
                    noise_std=1000.0, seed=5)
    sim = simulate(cfg)
    st = dataclasses.replace(settings_for(cfg), volume_uncertainty=2e-5)
    return sim, merge_final(analyze(sim.t, sim.measured, st)), st


def test_the_figure_shows_every_budget_line_and_the_recommended_c(analysed, tmp_path):
    import matplotlib.pyplot as plt

    sim, results, st = analysed
    (r,) = results
    fig = analysis_figure(sim.t, sim.measured, results, st)
    try:
        shown = figure_text(fig)
    finally:
        plt.close(fig)
    text = format_result(r).splitlines()
    budget = [s for s in text if s.startswith("    ")]  # the budget's lines
    assert len(budget) >= 7 and any("volume V" in s for s in budget)
    report = [s for s in text if "REPORT C" in s]
    assert len(report) == 1
    flat = " ".join(shown.split())
    for line in [*budget, *report]:
        assert " ".join(line.split()) in flat, line
    plot_analysis(sim.t, sim.measured, results, st, tmp_path / "a.png")
    assert (tmp_path / "a.png").stat().st_size > 10_000
