"""Remake ``docs/_static/measurement.png``, the README's picture of one measurement.

A simulated discharge with heat transfer, analysed and plotted by the package's own command
line (``simulate``, then ``analyze --plot``)::

    .venv/bin/python docs/make_measurement_png.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from pneumatic_unload.app.cli import main

OUT = Path(__file__).resolve().parent / "_static" / "measurement.png"


def run() -> int:
    """Simulate one discharge into a temporary bag, analyse it and write the plot to OUT."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = str(Path(tmp) / "sim1")
        if main(["simulate", "--out", bag, "--volume", "0.002", "--conductance", "5e-9",
                 "--effects", "heat_transfer", "--seed", "1"]) != 0:
            return 1
        return main(["analyze", bag, "--plot", str(OUT)])


if __name__ == "__main__":
    sys.exit(run())
