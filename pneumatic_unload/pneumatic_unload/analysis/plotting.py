# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Plots for engineers: the trace, p10, p*, the crossing, tau_exp and the fitted model.

Uses matplotlib's non-interactive Agg backend; no display needed. SI units on the axes
(pressure shown in bar absolute for readability, residuals in kPa).
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.analysis.output import budget_lines, c_dm3, report_line
from pneumatic_unload.estimation import EstimatorSettings, UnloadResult


def _model_curve(t: NDArray[np.float64], r: UnloadResult, settings: EstimatorSettings
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Model pressure [Pa] over the unload of r (fitted values when the curve fit ran)."""
    from pneumatic_unload.curvefit.fitting import CurveFit
    from pneumatic_unload.model import discharge
    from pneumatic_unload.model.inversion import rig_from_settings

    if not math.isfinite(r.conductance_model) or r.conductance_model <= 0:
        return None
    fit: dict[str, Any] = r.extra.get("curve_fit", {}) if r.extra else {}
    t0 = float(fit.get("t_start", r.t_start))
    p10 = float(fit.get("p10", r.p10))
    p_atm = float(fit.get("p_atm", r.end_pressure))  # a charge's: the supply
    settings = settings.one_way(r.direction)
    if not (math.isfinite(t0) and math.isfinite(p10) and math.isfinite(p_atm)):
        return None
    if fit:
        cfg = CurveFit(**fit).config(settings)
    else:
        b = r.critical_ratio if math.isfinite(r.critical_ratio) else None
        cfg = rig_from_settings(settings, conductance=r.conductance_model, p10=p10,
                                p_atm=p_atm, critical_ratio=b)
    t_end = r.t_end if math.isfinite(r.t_end) else float(t[-1])
    lo = max(float(t[0]), t0 - 0.05 * (t_end - t0))
    sel = (t >= lo) & (t <= t_end)
    if np.count_nonzero(sel) < 3:
        return None
    pm, _ = discharge(cfg, t[sel], t0)
    return sel, pm


def plot_analysis(t: NDArray[np.float64], p: NDArray[np.float64],
                  results: list[UnloadResult], settings: EstimatorSettings,
                  path: str | Path) -> None:
    """Write the PNG of :func:`analysis_figure` to ``path`` (str or Path)."""
    import matplotlib.pyplot as plt

    fig = analysis_figure(t, p, results, settings)
    fig.savefig(path)
    plt.close(fig)


def figure_text(fig: Any) -> str:
    """Every text a figure shows (its own and its axes'), one per line."""
    out = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        out += [t.get_text() for t in ax.texts]
    return "\n".join(out)


def analysis_figure(t: NDArray[np.float64], p: NDArray[np.float64],
                    results: list[UnloadResult], settings: EstimatorSettings) -> Any:
    """The matplotlib figure of a trace with each unload's analysis (close it after use).

    Top: the measured trace, p10 and p* (dashed), the start of the unload (green), the p*
    crossing (red dot) with the tau_exp arrow, and the fitted discharge model (purple);
    each unload's eq 39 and model-based C in a box. Bottom: measured minus model [kPa].
    Right: each unload's uncertainty budget line by line and the C to report (as the text
    output gives them), and "model inadequate" when the status says so.

    Parameters
    ----------
    t, p : ndarray
        Samples [s], [Pa absolute].
    results : list of UnloadResult
        One per unload (e.g. :func:`~pneumatic_unload.estimation.merge_final`).
    settings : EstimatorSettings
        The settings used (for the model curve).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=float)
    p = np.asarray(p, dtype=float)
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(19, 7), dpi=100, sharex=True,
                                  gridspec_kw={"height_ratios": [3, 1]})
    budget: list[str] = []
    t0 = float(t[0])
    ax.plot(t - t0, p / 1e5, lw=0.7, color="0.45", label="measured")
    lines = []
    for k, r in enumerate(results):
        first = k == 0
        if math.isfinite(r.p10):
            ax.axhline(r.p10 / 1e5, color="tab:blue", lw=0.9, ls="--",
                       label="p10" if first else None)
        if math.isfinite(r.t_start):
            ax.axvline(r.t_start - t0, color="tab:green", lw=0.9,
                       label="start of unload" if first else None)
        if math.isfinite(r.tau_exp):
            ax.axhline(r.p_star / 1e5, color="tab:orange", lw=0.9, ls="--",
                       label="p* (eq 40)" if first else None)
            ax.plot([r.t_cross - t0], [r.p_star / 1e5], "o", color="tab:red", ms=6,
                    label="p* crossing" if first else None)
            ax.annotate("", xy=(r.t_cross - t0, r.p_star / 1e5),
                        xytext=(r.t_start - t0, r.p_star / 1e5),
                        arrowprops={"arrowstyle": "<->", "color": "tab:red", "lw": 1.2})
            ax.text(0.5 * (r.t_start + r.t_cross) - t0, r.p_star / 1e5,
                    f"tau_exp = {r.tau_exp:.4g} s\n", va="bottom", ha="center",
                    color="tab:red", fontsize=9)
        curve = _model_curve(t, r, settings)
        if curve is not None:
            sel, pm = curve
            ax.plot(t[sel] - t0, pm / 1e5, color="tab:purple", lw=1.3, ls="-",
                    label="fitted model" if first else None)
            axr.plot(t[sel] - t0, (p[sel] - pm) / 1e3, lw=0.6, color="tab:purple")
        c39 = c_dm3(r.conductance)
        cm = (f"{c_dm3(r.conductance_model)} +- {r.conductance_model_std / 1e-8:.2g}"
              if math.isfinite(r.conductance_model) else "n/a")
        b = (f", b = {r.critical_ratio:.3f}" if math.isfinite(r.critical_ratio) else "")
        diff = (f" ({100 * r.bias:+.1f} %)" if math.isfinite(r.conductance)
                and math.isfinite(r.conductance_model) else "")
        lines.append(f"unload {r.index} [{r.status}]: C eq39 = {c39}{diff}, "
                     f"model = {cm} dm^3/(s bar){b}")
        why = r.extra.get("model_inadequate", "") if r.extra else ""
        budget += [f"unload {r.index}" + (f": model inadequate: {why}" if why else ""),
                   *budget_lines(r), *report_line(r), ""]
    if lines:
        ax.text(0.99, 0.80, "\n".join(lines), transform=ax.transAxes, ha="right", va="top",
                fontsize=9, bbox={"boxstyle": "round", "fc": "white", "ec": "0.7",
                                  "alpha": 0.9})
    ax.set_ylabel("pressure [bar absolute]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    axr.axhline(0.0, color="0.3", lw=0.6)
    axr.set_ylabel("measured - model\n[kPa]")
    axr.set_xlabel(f"time since {t0:.3f} s [s]")
    axr.grid(alpha=0.3)
    fig.tight_layout(rect=(0.0, 0.0, 0.56, 1.0))
    if budget:
        fig.text(0.57, 0.98, "\n".join(textwrap.fill(s, 112, subsequent_indent="      ")
                                        for s in budget),
                 ha="left", va="top", fontsize=7, family="monospace")
    return fig
