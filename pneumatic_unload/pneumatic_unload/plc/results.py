# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""An estimate as the PLC sees it, and its verdict (ROS-free: the node hands over a
message's fields)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from pneumatic_unload.estimation import STATUSES
from pneumatic_unload.plc.address import Estimate

if TYPE_CHECKING:  # the node loads a specification only when it is given one
    from pneumatic_unload.testline.spec import Spec

#: The UnloadEstimate fields :func:`estimate_from_fields` reads.
FIELDS = ("unload_index", "status", "status_text", "method", "conductance",
          "conductance_std", "conductance_model", "conductance_model_std", "critical_ratio",
          "subsonic_index", "tau_exp", "p10", "p_star", "p_atm")


def is_final(fields: Mapping[str, Any]) -> bool:
    """The estimate is an unload's final one (the full-curve fit's: its method ends with
    '+curve-fit'); the p* crossing's is not."""
    return str(fields["method"]).endswith("+curve-fit")


def estimate_from_fields(fields: Mapping[str, Any]) -> Estimate:
    """The :class:`~.bridge.Estimate` of an UnloadEstimate's fields (:data:`FIELDS`): the
    recommended C is the model-based one when known, else eq 39's (as
    :func:`pneumatic_unload.estimation.recommended` chooses) [m^3/(s Pa)]."""
    status = int(fields["status"])
    model = float(fields["conductance_model"])
    if math.isfinite(model):
        c, sd = model, float(fields["conductance_model_std"])
    else:
        c, sd = float(fields["conductance"]), float(fields["conductance_std"])
    return Estimate(
        unload_index=int(fields["unload_index"]), final=is_final(fields),
        status=STATUSES[status] if 0 <= status < len(STATUSES) else f"status {status}",
        status_text=str(fields["status_text"]), conductance=c, conductance_std=sd,
        critical_ratio=float(fields["critical_ratio"]),
        subsonic_index=float(fields["subsonic_index"]), tau_exp=float(fields["tau_exp"]),
        conductance_eq39=float(fields["conductance"]), p10=float(fields["p10"]),
        p_star=float(fields["p_star"]), p_atm=float(fields["p_atm"]))


def judged(est: Estimate, spec: Spec | None, part_id: str) -> Estimate:
    """``est`` with its verdict against the part's type in ``spec`` ('' without a spec or
    a type for the part)."""
    if spec is None:
        return est

    def num(x: float) -> float | None:
        return x if math.isfinite(x) else None

    row = {"status": est.status, "status_text": est.status_text,
           "recommended_conductance": num(est.conductance),
           "recommended_std": num(est.conductance_std),
           "critical_ratio": num(est.critical_ratio)}
    v = spec.judge(part_id, row)
    if v is None:
        return est
    return replace(est, verdict=v[0], verdict_reason=v[1])
