"""Discrepancy workflow: find where the discharge model and a measurement disagree, name
the missing effect, add it and show the gap shrink (ROS-free; SI units).

>>> from pneumatic_unload.discrepancy import DiscrepancySettings, find_discrepancy
>>> # res = find_discrepancy(t, p, DiscrepancySettings(volume=2e-3)); res.effect

See :mod:`pneumatic_unload.discrepancy.workflow` for the method,
:mod:`~pneumatic_unload.discrepancy.candidates` for the effects and their parameters,
:mod:`~pneumatic_unload.discrepancy.multirun` for the shared geometric law of several
runs and :mod:`~pneumatic_unload.discrepancy.report` for the engineer's report.
"""

from pneumatic_unload.discrepancy.candidates import EFFECT_PARAMS, GEOMETRY_FACTOR
from pneumatic_unload.discrepancy.noise import NoiseModel, estimate_noise, ljung_box
from pneumatic_unload.discrepancy.workflow import (
    DiscrepancyError,
    DiscrepancyResult,
    DiscrepancySettings,
    find_discrepancy,
    find_discrepancy_runs,
)

__all__ = [
    "EFFECT_PARAMS",
    "GEOMETRY_FACTOR",
    "DiscrepancyError",
    "DiscrepancyResult",
    "DiscrepancySettings",
    "NoiseModel",
    "estimate_noise",
    "find_discrepancy",
    "find_discrepancy_runs",
    "ljung_box",
]
