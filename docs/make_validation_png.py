"""Remake the validation page's figures, ``docs/_static/validation_hyddown.png`` and
``docs/_static/validation_hyddown_fill.png``: the model C of HydDown's committed discharges
and fills (``pneumatic_unload/test/data/hyddown``, ``pneumatic_unload/test/data/hyddown_fill``),
each error drawn with its
2-sigma bar by the benches themselves::

    .venv/bin/python docs/make_validation_png.py

It runs ``bench/bench_hyddown.py test/data/hyddown --plot ...`` and
``bench/bench_hyddown_fill.py --plot ...`` (the six fills, two noise draws each, from the
opening) with the interpreter that runs it; a few minutes on 2 cores.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / "docs" / "_static"
#: (bench script, its arguments) per figure.
FIGURES: tuple[tuple[str, list[str]], ...] = (
    ("bench_hyddown.py", [str(ROOT / "pneumatic_unload" / "test" / "data" / "hyddown"),
                          "--plot", str(STATIC / "validation_hyddown.png")]),
    ("bench_hyddown_fill.py", ["--plot", str(STATIC / "validation_hyddown_fill.png")]),
)


def run() -> int:
    """Run each bench with its ``--plot``; the first failure's exit status, else 0."""
    for script, args in FIGURES:
        done = subprocess.run([sys.executable, str(ROOT / "bench" / script), *args],
                              cwd=ROOT, check=False)
        if done.returncode:
            return done.returncode
    return 0


if __name__ == "__main__":
    sys.exit(run())
