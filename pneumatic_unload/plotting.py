"""Plots for engineers: the trace, p10, p*, the crossing, tau_exp and the fitted model.

Uses matplotlib's non-interactive Agg backend; no display needed. SI units on the axes
(pressure shown in bar absolute for readability).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.estimation import EstimatorSettings, UnloadResult


def plot_analysis(t: NDArray[np.float64], p: NDArray[np.float64],
                  results: list[UnloadResult], settings: EstimatorSettings,
                  path: str | Path) -> None:
    """Write a PNG of a trace with each unload's analysis.

    Parameters
    ----------
    t, p : ndarray
        Samples [s], [Pa absolute].
    results : list of UnloadResult
        One per unload (e.g. :func:`~pneumatic_unload.estimation.merge_final`).
    settings : EstimatorSettings
        The settings used (for the model curve).
    path : str or Path
        Output PNG file.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pneumatic_unload.fitting import rig_from_settings
    from pneumatic_unload.model import discharge

    fig, ax = plt.subplots(figsize=(10, 5.5), dpi=100)
    t0 = float(t[0])
    ax.plot(t - t0, p / 1e5, lw=0.8, color="0.3", label="measured")
    for r in results:
        if not math.isfinite(r.tau_exp):
            continue
        ax.axhline(r.p10 / 1e5, color="tab:blue", lw=0.8, ls="--")
        ax.axhline(r.p_star / 1e5, color="tab:orange", lw=0.8, ls="--")
        ax.axvline(r.t_start - t0, color="tab:green", lw=0.8)
        ax.plot([r.t_cross - t0], [r.p_star / 1e5], "o", color="tab:red")
        ax.annotate("", xy=(r.t_cross - t0, r.p_star / 1e5),
                    xytext=(r.t_start - t0, r.p_star / 1e5),
                    arrowprops={"arrowstyle": "<->", "color": "tab:red"})
        ax.text(0.5 * (r.t_start + r.t_cross) - t0, r.p_star / 1e5,
                f" tau_exp = {r.tau_exp:.4g} s", va="bottom", ha="center", color="tab:red")
        if math.isfinite(r.conductance_model):
            b = r.critical_ratio if math.isfinite(r.critical_ratio) else None
            cfg = rig_from_settings(settings, conductance=r.conductance_model, p10=r.p10,
                                    p_atm=r.p_atm, critical_ratio=b)
            sel = (t >= r.t_start) & (t <= (r.t_end if math.isfinite(r.t_end) else t[-1]))
            if np.count_nonzero(sel) > 2:
                pm, _ = discharge(cfg, t[sel], r.t_start)
                ax.plot(t[sel] - t0, pm / 1e5, color="tab:purple", lw=1.2,
                        label=f"model, C = {r.conductance_model / 1e-8:.4g} dm^3/(s bar)")
        ax.text(0.99, 0.97 - 0.06 * r.index,
                f"unload {r.index}: C eq39 = {r.conductance / 1e-8:.4g}, model = "
                f"{r.conductance_model / 1e-8:.4g} dm^3/(s bar) [{r.status}]",
                transform=ax.transAxes, ha="right", va="top", fontsize=9)
    ax.set_xlabel(f"time since {t0:.3f} s [s]")
    ax.set_ylabel("pressure [bar absolute]")
    ax.grid(alpha=0.3)
    ax.legend(loc="center right", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
