"""The validation benches' picture: each case's model-C error with its 2-sigma bar.

Used by ``bench/bench_hyddown.py --plot PNG`` and ``bench/bench_hyddown_fill.py --plot
PNG`` (``docs/make_validation_png.py`` remakes the documentation's figures with both, on
the committed traces). Errors and sigmas are relative [-], drawn in %.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path


def error_bars(path: Path, title: str, names: Sequence[str], errors: Sequence[float],
               sigmas: Sequence[float], tolerance: float) -> None:
    """Write a PNG to ``path``: per case (``names``) the relative error of C (``errors``
    [-]) with a bar of +- 2 ``sigmas`` [-], the band +- ``tolerance`` [-] shaded, and in the
    title how many cases lie within 2 sigma and within the tolerance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [math.isfinite(e) and math.isfinite(s) for e, s in zip(errors, sigmas, strict=True)]
    n = len(names)
    within2 = sum(1 for e, s, g in zip(errors, sigmas, ok, strict=True)
                  if g and abs(e) <= 2.0 * s)
    within_tol = sum(1 for e, g in zip(errors, ok, strict=True) if g and abs(e) <= tolerance)
    fig, ax = plt.subplots(figsize=(7.5, 0.35 * n + 1.6), dpi=110)
    y = list(range(n))
    ax.axvspan(-100 * tolerance, 100 * tolerance, color="0.92", zorder=0,
               label=f"+- {100 * tolerance:g} % (acceptance)")
    ax.axvline(0.0, color="0.4", lw=0.8)
    ax.errorbar([100 * e if g else math.nan for e, g in zip(errors, ok, strict=True)], y,
                xerr=[200 * s if g else 0.0 for s, g in zip(sigmas, ok, strict=True)],
                fmt="o", ms=4, capsize=3, color="C0", label="model C, +- 2 sigma")
    ax.set_yticks(y, names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("C error against the truth [%]")
    ax.set_title(f"{title}\nwithin 2 sigma {within2}/{n}, within "
                 f"{100 * tolerance:g} % {within_tol}/{n}", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
