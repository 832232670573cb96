# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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

from typing import Any

from pneumatic_unload.discrepancy.types import (
    DiscrepancyError,
    DiscrepancyResult,
    DiscrepancySettings,
)

#: Names loaded on first use (PEP 562): the workflow pulls in the fitting engine, which
#: the command line does not need to build its options.
_LAZY = {"GEOMETRY_FACTOR": "pneumatic_unload.discrepancy.intervals",
         "find_discrepancy": "pneumatic_unload.discrepancy.workflow",
         "find_discrepancy_runs": "pneumatic_unload.discrepancy.workflow"}


def __getattr__(name: str) -> Any:
    """Load the workflow's names on first use."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "GEOMETRY_FACTOR",
    "DiscrepancyError",
    "DiscrepancyResult",
    "DiscrepancySettings",
    "find_discrepancy",
    "find_discrepancy_runs",
]
