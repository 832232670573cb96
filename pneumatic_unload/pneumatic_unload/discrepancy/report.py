# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The discrepancy workflow's report: Markdown with PNG plots, and one self-contained HTML page.

Written for a test-bench engineer: what the model misses (by name), how sure the
workflow is, the fitted size of the effect with its 95 % interval, the gap before and
after, and which extra measurement would settle an ambiguity; it ends with "What to do
next" and "Which C to report, and why" (:mod:`~pneumatic_unload.discrepancy.advice`).
``report.html`` is the same text with the plots embedded
(:mod:`~pneumatic_unload.discrepancy.html`). Plots use matplotlib's Agg backend; pressures
are shown in bar absolute, residuals in kPa, times in s.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.discrepancy.advice import what_next, which_c
from pneumatic_unload.discrepancy.html import markdown_to_html
from pneumatic_unload.discrepancy.multirun import GeometryLaw
from pneumatic_unload.discrepancy.types import BIC_HELP, DiscrepancyResult

if TYPE_CHECKING:  # annotations only
    from pneumatic_unload.fit.profile import Interval

FloatArray = NDArray[np.float64]


def _binned(x: FloatArray, edges: NDArray[np.int64]) -> FloatArray:
    return np.add.reduceat(x, edges[:-1]) / np.diff(edges)


def _plot_edges(n: int, k_open: int, max_points: int = 1500) -> NDArray[np.int64]:
    """Bins for plotting: every sample near the opening, averages elsewhere."""
    w = max(1, n // max_points)
    left = np.arange(0, max(k_open - 50, 0), w)
    mid = np.arange(max(k_open - 50, 0), min(k_open + 200, n))
    right = np.arange(min(k_open + 200, n), n, w)
    return np.unique(np.concatenate((left, mid, right, [n]))).astype(np.int64)


def write_plots(res: DiscrepancyResult, out: Path) -> dict[str, str]:
    """Write the report's PNG plots into ``out``; returns {label: file name}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    t, y = res.t, res.y
    k_open = int(np.searchsorted(t, res.final.theta["t_open"]))
    e = _plot_edges(t.size, k_open)
    tb = _binned(t, e)
    n_b = np.diff(e).astype(float)
    after_label = "extended model (" + (", ".join(res.effects) or "none") + ")"

    # 1. measured vs baseline vs extended
    fig, ax = plt.subplots(figsize=(9, 5), dpi=100)
    ax.plot(tb, _binned(y, e) / 1e5, ".", ms=2.5, color="0.4", label="measured")
    ax.plot(tb, _binned(res.model_before, e) / 1e5, "-", lw=1.2, color="tab:red",
            label="baseline (adiabatic)")
    ax.plot(tb, _binned(res.model_after, e) / 1e5, "--", lw=1.2, color="tab:blue",
            label=after_label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pressure [bar absolute]")
    ax.set_title(f"Measured {res.settings.direction} and the fitted models")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "models.png")
    plt.close(fig)
    files["models"] = "models.png"

    # 2. residuals before / after (bin means, with the +-2 sigma band of a bin mean)
    sigma = res.noise.sigma * math.sqrt((1 + res.noise.rho) / (1 - res.noise.rho))
    band = 2.0 * sigma / np.sqrt(n_b) / 1e3
    fig, axs = plt.subplots(2, 1, figsize=(9, 6.5), dpi=100, sharex=True)
    for ax, m, label, col in ((axs[0], res.model_before, "baseline", "tab:red"),
                              (axs[1], res.model_after, after_label, "tab:blue")):
        rb = _binned(y - m, e) / 1e3
        ax.fill_between(tb, -band, band, color="0.85", label="noise band (2 sigma)")
        ax.plot(tb, rb, ".", ms=2.5, color=col, label=f"residual, {label}")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel("measured - model [kPa]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axs[1].set_xlabel("time [s]")
    axs[0].set_title("Residuals before and after adding the effect")
    fig.tight_layout()
    fig.savefig(out / "residuals.png")
    plt.close(fig)
    files["residuals"] = "residuals.png"

    # 3. residual against pressure and its rate (baseline and final)
    fig, axs = plt.subplots(1, 2, figsize=(10, 4), dpi=100)
    pb = _binned(res.model_before, e)
    rate = np.gradient(pb, tb) if pb.size > 2 else np.zeros_like(pb)
    for m, label, col in ((res.model_before, "baseline", "tab:red"),
                          (res.model_after, "extended", "tab:blue")):
        rb = _binned(y - m, e) / 1e3
        axs[0].plot(pb / 1e5, rb, ".", ms=2.5, color=col, label=label)
        axs[1].plot(rate / 1e5, rb, ".", ms=2.5, color=col, label=label)
    axs[0].set_xlabel("model pressure [bar absolute]")
    axs[1].set_xlabel("model pressure rate [bar/s]")
    for ax in axs:
        ax.set_ylabel("residual [kPa]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "residual_vs_state.png")
    plt.close(fig)
    files["residual_vs_state"] = "residual_vs_state.png"

    # 4. candidate ranking
    if res.rounds:
        fig, axs = plt.subplots(1, len(res.rounds), figsize=(4.5 * len(res.rounds) + 1, 4),
                                dpi=100, squeeze=False)
        for ax, rd in zip(axs[0], res.rounds, strict=True):
            names = sorted(rd.delta_bic, key=lambda k: -rd.delta_bic[k])
            vals = [rd.delta_bic[k] for k in names]
            cols = ["tab:green" if k == rd.winner else
                    ("tab:orange" if k in rd.ambiguous_with else "0.6") for k in names]
            ax.barh(names[::-1], vals[::-1], color=cols[::-1])
            ax.axvline(10.0, color="tab:red", lw=1, ls="--", label="claim threshold 10")
            ax.set_xscale("symlog", linthresh=10.0)
            ax.set_xlabel("delta-BIC vs " + ("+".join(rd.base_effects) or "baseline"))
            ax.grid(alpha=0.3, axis="x")
            ax.legend(fontsize=8, loc="lower right")
        fig.tight_layout()
        fig.savefig(out / "ranking.png")
        plt.close(fig)
        files["ranking"] = "ranking.png"

    # 5. measured gas temperature, if any
    if res.temperature is not None and res.t_temperature is not None:
        tt = res.t_temperature
        sel = (tt >= t[0]) & (tt <= t[-1])
        if np.count_nonzero(sel) > 2:
            fig, ax = plt.subplots(figsize=(9, 4.5), dpi=100)
            ax.plot(tt[sel], res.temperature[sel] - 273.15, ".", ms=3, color="0.3",
                    label="measured gas temperature")
            for f, label, col in ((res.baseline, "baseline (adiabatic)", "tab:red"),
                                  (res.final, after_label, "tab:blue")):
                ax.plot(tt[sel], f.model.temperature(f.theta, tt[sel]) - 273.15, "-",
                        color=col, label=label)
            ax.set_xlabel("time [s]")
            ax.set_ylabel("gas temperature [degC]")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
            fig.tight_layout()
            fig.savefig(out / "temperature.png")
            plt.close(fig)
            files["temperature"] = "temperature.png"
    return files


def _fmt(v: float | None, unit: str = "") -> str:
    if v is None or not math.isfinite(v):
        return "unbounded"
    return f"{v:.4g}{(' ' + unit) if unit and unit != '-' else ''}"


def _identifiable(iv: Interval) -> str:
    """The identifiable column of the parameter table: yes, NO, or 'not computed' (no
    interval could be computed, which says nothing about the record)."""
    return "yes" if iv.identifiable else "NO" if iv.computed else "not computed"


def _sigma_sources(nz: dict[str, Any]) -> str:
    """How sigma [Pa] was made from the plateau and whole-trace (high-pass) estimates."""
    sp, sh, w = nz.get("sigma_plateau"), nz.get("sigma_highpass"), nz.get("highpass_weight")
    if sp is None or sh is None or w is None:
        return ""
    return (f"; sigma weights the plateau estimate {sp:.4g} Pa and the whole-trace "
            f"high-pass estimate {sh:.4g} Pa (weight {w:.2f})")


def _joint_lines(res: DiscrepancyResult) -> list[str]:
    """The table of the models fitted with the logged gas temperature (T10 and the
    thermometer's lag fitted): which follow it and which it rules out of C's range."""
    j = res.temperature_joint
    if not j:
        return []
    if not j.get("available"):
        return [f"Not fitted with the models: {j.get('why', '')}.", ""]
    gone = set(j["rules_out"])
    out = ["Each model of C's range fitted again with the log beside the pressure (T10 "
           "and the thermometer's lag fitted; a model follows the log when its readings' "
           "rms is within 2 of the channel's noise):", "",
           "| model | follows | rms [K] | noise [K] | T10 [K] | lag [s] | C [dm^3/(s bar)] "
           "| |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for i, m in enumerate(j["models"]):
        name = ", ".join(m["effects"]) or "baseline"
        if "rms" not in m:
            out.append(f"| {name} | - | | | | | | {m.get('why', '')} |")
            continue
        note = "reported" if i == 0 else "ruled out" if i in gone else ""
        out.append(f"| {name} | {'yes' if m['follows'] else 'no'} | {m['rms']:.2g} | "
                   f"{m['noise']:.2g} | {m['t10']:.1f} | {m['sensor_time_constant']:.2g} | "
                   f"{m['conductance'] / 1e-8:.4g} | {note} |")
    return [*out, ""]


def markdown(res: DiscrepancyResult, files: dict[str, str], title: str = "") -> str:
    """The report's Markdown text (plots referenced by relative file names)."""
    d: dict[str, Any] = res.to_dict()
    lines = [f"# Discrepancy report{': ' + title if title else ''}", ""]
    lines += ["## Verdict", "", f"**{res.verdict}**", ""]
    if res.effect != "none":
        lines.append(f"- Missing effect named: **{res.effect}** (named alone: the runner-up "
                     "is more than 10 BIC behind)" if not res.ambiguous_with else
                     f"- Missing effect: one of **{', '.join([res.effect, *res.ambiguous_with])}"
                     f"** (the data cannot tell them apart; none is claimed, {res.effect} "
                     "stands for them in the final model)")
        if len(res.effects) > 1:
            lines.append(f"- Effects added greedily, in order: {', '.join(res.effects)} "
                         f"(named: {', '.join(res.named) or 'none'})")
    lines += [f"- Gap: RMS {res.rms_before:.4g} Pa before, {res.rms_after:.4g} Pa after; "
              f"normalised by the noise {res.before.nrms:.3f} -> {res.after.nrms:.3f} "
              "(1.0 = the noise level; prewhitened RMS over the AR(1) innovation sigma)",
              f"- Residual white (Ljung-Box p >= 0.01): before {res.before.white} "
              f"(p = {res.before.ljung_box_p:.3g}), after {res.after.white} "
              f"(p = {res.after.ljung_box_p:.3g})",
              f"- Sonic conductance of the final model: C = {res.conductance:.5g} m^3/(s Pa) "
              f"= {res.conductance / 1e-8:.4g} dm^3/(s bar) (baseline: "
              f"{res.baseline.theta['C'] / 1e-8:.4g} dm^3/(s bar))", ""]
    if res.extra_data:
        lines += ["### Extra data that would separate the candidates", ""]
        lines += [f"- {x}" for x in res.extra_data] + [""]
    lines += ["## Fitted effect parameters (95 % intervals)", "",
              "| parameter | value | interval | method | identifiable | meaning |",
              "| --- | --- | --- | --- | --- | --- |"]
    for k, v in res.parameters.items():
        span = f"[{_fmt(v.low)}, {_fmt(v.high)}]" if v.identifiable else "none (see below)"
        lines.append(f"| {k} | {_fmt(v.value, v.unit)} | {span} "
                     f"| {v.method} | {_identifiable(v)} | {v.doc} |")
    lines += ["", "An interval that does not close inside the parameter's range means the "
              "trace cannot pin the parameter down (reported as not identifiable).", ""]
    unknown = [(k, v) for k, v in res.parameters.items() if not v.identifiable]
    if unknown:
        lines += [f"- **{k}**: {v.describe()}" for k, v in unknown] + [""]
    if "models" in files:
        lines += ["## Measured vs models", "", f"![models]({files['models']})", ""]
    if "residuals" in files:
        lines += ["## Residuals before and after", "", f"![residuals]({files['residuals']})",
                  "", "Grey: the band a residual of pure noise stays in (2 sigma of each "
                  "plotted average).", ""]
    lines += ["## Candidate ranking", "", BIC_HELP, ""]
    for i, rd in enumerate(res.rounds):
        lines += [f"Round {i + 1}: candidates added to "
                  f"{'+'.join(rd.base_effects) or 'the baseline'} "
                  f"(winner: {rd.winner})", "", "| candidate | delta-BIC |", "| --- | --- |"]
        for k in sorted(rd.delta_bic, key=lambda q: -rd.delta_bic[q]):
            lines.append(f"| {k} | {rd.delta_bic[k]:.1f} |")
        lines.append("")
    if "ranking" in files:
        lines += [f"![ranking]({files['ranking']})", ""]
    lines += ["## Where the baseline disagrees (per phase)", "",
              "| phase | samples | mean before [Pa] | rms before [Pa] | rms after [Pa] |",
              "| --- | --- | --- | --- | --- |"]
    for ph, v in res.before.phases.items():
        a = res.after.phases.get(ph, {})
        lines.append(f"| {ph} | {v['samples']} | {v['mean']:.4g} | {v['rms']:.4g} | "
                     f"{a.get('rms', math.nan):.4g} |")
    lines += ["", f"Correlation of the baseline residual with pressure "
              f"{res.before.corr_pressure:.2f}, with its rate {res.before.corr_rate:.2f}.", ""]
    if "residual_vs_state" in files:
        lines += [f"![residual vs state]({files['residual_vs_state']})", ""]
    nz = d["noise"]
    lines += ["## Noise model", "",
              f"sigma = {nz['sigma']:.4g} Pa, AR(1) rho = {nz['rho']:.3f} "
              f"(from {nz['source']}, {nz['n']} samples)" + _sigma_sources(nz) + ". "
              "Correlated noise carries less "
              "information than its sample count: the likelihood prewhitens the residual, "
              "so a slow wiggle of the noise is not mistaken for an effect.", ""]
    g = res.geometry_factor
    lines += ["## Chamber geometry factor (L/D)", "", g["reason"] + ".", ""]
    if res.temperature_check is not None:
        tc = res.temperature_check
        lines += ["## Independent evidence: measured gas temperature", ""]
        if tc.get("available"):
            lines += [tc["summary"] + ".", ""]
            if "temperature" in files:
                lines += [f"![temperature]({files['temperature']})", ""]
        else:
            lines += [tc.get("reason", "not available"), ""]
        lines += _joint_lines(res)
    if res.notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in res.notes] + [""]
    lines += ["## Method", "",
              "1. Noise correlation from the plateaus before the valve opens and after the "
              "tank has emptied; sigma from those plateaus weighted with the residual of a "
              "local cubic over the whole trace. 2. Baseline (paper's adiabatic discharge, or "
              "the adiabatic charge from the supply: C, b, "
              "opening instant, p10) fitted by least squares from several starts. 3. Each "
              "candidate effect added and the whole model refitted from several starts "
              "(including the neutral values of the baseline). 4. Decision by BIC. 5. "
              "Greedy: while the residual is still structured, one more effect (at most "
              "three).", "",
              f"Samples {res.n_samples}, likelihood bins {res.n_bins}, "
              f"run time {res.elapsed:.1f} s.", ""]
    lines += ["## What to do next", ""] + [f"- {x}" for x in what_next(res)] + [""]
    lines += ["## Which C to report, and why", ""]
    for block in which_c(res):
        lines += [block, ""]
    return "\n".join(lines)


def write_report(res: DiscrepancyResult, out: str | Path, *, title: str = "") -> Path:
    """Write ``report.md`` with its PNG plots, and ``report.html`` (the same text, the plots
    embedded: one file that opens offline) into the directory ``out``.

    Parameters
    ----------
    res : DiscrepancyResult
        Workflow result.
    out : str or Path
        Directory (created).
    title : str
        Title suffix (e.g. the input file name).

    Returns
    -------
    Path
        The Markdown file.
    """
    out = Path(out)
    files = write_plots(res, out)
    path = out / "report.md"
    text = markdown(res, files, title)
    path.write_text(text, encoding="utf-8")
    page = markdown_to_html(text, out, "Discrepancy report" + (f": {title}" if title else ""))
    (out / "report.html").write_text(page, encoding="utf-8")
    return path


def write_law_report(law: GeometryLaw, out: str | Path, names: list[str]) -> Path:
    """Markdown section and plot of the shared geometry law of several runs (and the same
    as a self-contained ``geometry_law.html``).

    Parameters
    ----------
    law : GeometryLaw
        The fitted law.
    out : str or Path
        Directory (created).
    names : list of str
        Run labels, in the order of ``law.runs``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Shared geometry law from several runs", "", law.reason + ".", "",
             "| run | L/D | C [dm^3/(s bar)] | factor C/C_inf |", "| --- | --- | --- | --- |"]
    for name, r in zip(names, law.runs, strict=True):
        lines.append(f"| {name} | {r['length_diameter_ratio']:.3g} | "
                     f"{r['conductance'] / 1e-8:.4g} +- {r['conductance_std'] / 1e-8:.2g} | "
                     f"{r['factor']:.4g} |")
    if law.identifiable:
        x = np.array([r["length_diameter_ratio"] for r in law.runs])
        c = np.array([r["conductance"] for r in law.runs])
        s = np.array([r["conductance_std"] for r in law.runs])
        xs = np.linspace(0.8 * x.min(), 1.2 * x.max(), 100)
        fig, ax = plt.subplots(figsize=(7, 4.5), dpi=100)
        ax.errorbar(x, c / 1e-8, yerr=2 * s / 1e-8, fmt="o", label="runs (2 sigma)")
        ax.plot(xs, [law.predict(v) / 1e-8 for v in xs], "-", label="shared law")
        ax.axhline(law.c_inf / 1e-8, ls="--", color="0.5", label="C_inf")
        ax.set_xlabel("tank L/D [-]")
        ax.set_ylabel("C [dm^3/(s bar)]")
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "geometry_law.png")
        plt.close(fig)
        lines += ["", "![geometry law](geometry_law.png)"]
    path = out / "geometry_law.md"
    text = "\n".join(lines) + "\n"
    path.write_text(text, encoding="utf-8")
    (out / "geometry_law.html").write_text(
        markdown_to_html(text, out, "Shared geometry law from several runs"), encoding="utf-8")
    return path
