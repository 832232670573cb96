"""Discrepancy workflow: find where the discharge model and a measurement disagree, name
the missing effect, add it and show the gap shrink (ROS-free; SI units).

>>> from pneumatic_unload.discrepancy import DiscrepancySettings, find_discrepancy
>>> # res = find_discrepancy(t, p, DiscrepancySettings(volume=2e-3)); res.effect

Modules: :mod:`~pneumatic_unload.discrepancy.types` (settings, fits, result),
:mod:`~pneumatic_unload.discrepancy.problem` (the trace prepared for the engine),
:mod:`~pneumatic_unload.discrepancy.search` (rounds, BIC decision, diagnostics),
:mod:`~pneumatic_unload.discrepancy.intervals` (profile intervals, independent checks),
:mod:`~pneumatic_unload.discrepancy.workflow` (orchestration),
:mod:`~pneumatic_unload.discrepancy.multirun` (the shared geometric law of several runs)
and :mod:`~pneumatic_unload.discrepancy.report` (the engineer's report). The effects and
their parameters are the model's registry, :mod:`pneumatic_unload.model.effects`.
"""

from pneumatic_unload.discrepancy.intervals import GEOMETRY_FACTOR
from pneumatic_unload.discrepancy.types import (
    DiscrepancyError,
    DiscrepancyResult,
    DiscrepancySettings,
)
from pneumatic_unload.discrepancy.workflow import find_discrepancy, find_discrepancy_runs

__all__ = [
    "GEOMETRY_FACTOR",
    "DiscrepancyError",
    "DiscrepancyResult",
    "DiscrepancySettings",
    "find_discrepancy",
    "find_discrepancy_runs",
]
