# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Text and JSON output of the analysis: one result, the inputs used, the budget.

Used by the command line (``analyze``); SI units in JSON, trade units (dm^3/(s bar))
alongside in the text.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pneumatic_unload.estimation import UnloadResult, recommended
from pneumatic_unload.uncertainty.budget import format_budget

#: Exit statuses of ``analyze`` (also in its --help and the README).
EXIT_STATUS = {0: "at least one unload gives C (a finite recommended C, status not bad_data)",
               1: "no estimate: no unload found, every unload failed (e.g. all bad_data), "
                  "or gauge readings taken as absolute; the reason on stderr and in --json",
               2: "unreadable input or bad options (one line on stderr)"}

#: The object ``analyze --json`` prints (:func:`pneumatic_unload.app.cli.cmd_analyze`): each key
#: and its meaning (the documentation site's JSON reference is generated from this).
ANALYZE_JSON_KEYS: dict[str, str] = {
    "source": "the input PATH as given",
    "samples": "number of pressure samples read",
    "settings": "the estimator settings used (EstimatorSettings' fields, SI): the command "
                "line's, else those recorded in the bag, else the defaults",
    "inputs": "every input the analysis used, with where it came from (the command line, "
              "the record, a default)",
    "unloads": "one object per unload found (see below): its final (curve-fit) result "
               "where it exists, else its crossing estimate",
    "published": "every result the streaming estimator published, in order (the crossing "
                 "estimate, then the final one, of each unload), as a live node would",
    "no_unload_reason": "why no unload was found, with what would fix it where known; null "
                        "when one was found",
    "no_estimate_reason": "why no unload gives C; null when at least one does",
    "input_problem": "a problem of the input that voids the analysis (e.g. gauge readings "
                     "taken as absolute); null when none",
    "exit_status": "the command's exit status (EXIT_STATUS)",
    "input_warnings": "what was assumed about the input (also printed as warnings on "
                      "stderr)",
}
#: The fields of :class:`~pneumatic_unload.estimation.UnloadResult` that
#: :func:`unload_json` leaves out (their parts it keeps are in :data:`UNLOAD_JSON_KEYS`).
UNLOAD_JSON_DROPPED = ("extra",)
#: The keys :func:`unload_json` adds to a result's fields, and their meaning (keys marked
#: "when known" are present only when the result carries them).
UNLOAD_JSON_KEYS: dict[str, str] = {
    "budget": "when known: the uncertainty budget of conductance_model (GUM): value, "
              "combined_std, expanded (k = 2), type_a_std, type_b_std, model_form_std, the "
              "largest line and the terms, each with its standard uncertainty "
              "[m^3/(s Pa)] (pneumatic_unload.uncertainty.budget)",
    "budget_eq39": "when known: the same budget for eq 39's conductance",
    "budget_b": "when known (final results): the budget of the critical ratio b [-], with "
                "C's lines",
    "budget_m": "when known (final results): the budget of the subsonic index m [-]",
    "heat_law": "heat law of the final (curve-fit) C: 'natural', 'fixed' (constant hA), "
                "'none' (adiabatic), ...; '' for a crossing estimate",
    "heat_laws": "final results: the heat laws offered to the fit with their C and BIC "
                 "('offered'), those not offered with the reason ('not_offered'), and the "
                 "chosen law's heat_scale, tau_heat [s], heat_exponent, heat_turbulent, "
                 "wall_temperature [K] and wall_temperature_std [K]",
    "reproducibility": "the fit's numerical reproducibility of C ('conductance_model') and "
                       "b ('critical_ratio') [-, relative]: what another machine's last bits "
                       "may change; null when there is no curve fit",
    "subsonic_index_fitted": "the subsonic index m was fitted (true) or held at 0.5 (false)",
    "subsonic_source": "why m was fitted or held, in words ('' without a curve fit)",
    "critical_ratio_source": "final results: why b is not reported (null), with the fit's "
                             "value and 1-sigma, in words; '' when it is",
    "offset_source": "why the transducer's zero offset was fitted or not, in words",
    "shape_source": "final results: the flow curve's shape beyond the ISO 6358-1 law, in "
                    "words: the ellipse's exponent q fitted and the ISO (b, m) nearest that "
                    "curve over r (in the model form's spread of b and m), or why not read",
    "gas_temperature": "final results in 'unloads': the evidence of the record's gas "
                       "temperature: 'used' (false, with 'why', when the record carries "
                       "none); when used, the fitted readings' rms and the channel's noise "
                       "[K], whether the model 'follows' the log (within its noise; "
                       "'probe' [K] where used within the probe's accuracy only), the "
                       "thermometer's time "
                       "constant [s] and offset [K] and t10 [K], each with its 1-sigma",
    "model_inadequate": "why the model does not describe the record, or '' when it does",
    "recommended": "the C to report: conductance, std, expanded (k = 2) [m^3/(s Pa)], "
                   "coverage_factor and its source (model-based C, or eq 39's when there "
                   "is none; null for a result that gives no C, status 'bad_data')",
}


def gives_c(r: UnloadResult) -> bool:
    """The result carries an estimate of C: its recommended C (:func:`recommended`) is
    finite and positive and its status is not 'bad_data' (e.g. 'ok', 'aborted_sse', or
    'ok_subsonic' with its curve-fit C)."""
    c = recommended(r)["conductance"]
    return r.status != "bad_data" and math.isfinite(c) and c > 0


def unload_json(r: UnloadResult) -> dict[str, Any]:
    """JSON of one result: its fields, the budgets, the heat law (with the laws offered,
    their C and BIC, and those not offered with the reason), the fit's numerical
    reproducibility of C and b ('reproducibility': relative, what another machine's last
    bits may change; null when no curve fit), whether the model describes the record
    ('model_inadequate': the reason, or '') and the C to report."""
    d = r.to_dict()
    extra = d.pop("extra", None) or {}  # UNLOAD_JSON_DROPPED
    for key in ("budget", "budget_eq39", "budget_b", "budget_m"):
        if key in extra:
            d[key] = extra[key]
    cf = extra.get("curve_fit", {}) if r.final else {}
    d["heat_law"] = cf.get("heat_law", "")
    if cf:
        d["heat_laws"] = {"offered": cf.get("laws", {}), "not_offered": cf.get("not_offered", {}),
                          "heat_scale": cf.get("heat_scale"), "tau_heat": cf.get("tau_heat"),
                          "heat_exponent": cf.get("heat_exponent"),
                          "heat_turbulent": cf.get("heat_turbulent"),
                          "wall_temperature": cf.get("wall_temperature"),
                          "wall_temperature_std": cf.get("wall_temperature_std")}
    d["reproducibility"] = {
        "conductance_model": cf.get("conductance_reproducibility"),
        "critical_ratio": cf.get("critical_ratio_reproducibility")} if cf else None
    d["subsonic_index_fitted"] = bool(cf.get("subsonic_index_fitted", False))
    d["subsonic_source"] = cf.get("subsonic_source", "")
    d["critical_ratio_source"] = cf.get("critical_ratio_source", "")
    d["offset_source"] = cf.get("offset_source", "")
    d["shape_source"] = cf.get("shape_source", "")
    if "gas_temperature" in extra:
        d["gas_temperature"] = extra["gas_temperature"]
    d["model_inadequate"] = extra.get("model_inadequate", "")
    d["recommended"] = recommended(r)
    return finite_or_none(d)


def finite_or_none(x: Any) -> Any:
    """x with every non-finite float (NaN: unknown) replaced by None, recursively."""
    if isinstance(x, dict):
        return {k: finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_none(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def json_default(o: object) -> object:
    """``json.dumps`` default: non-finite floats as null, numpy scalars as Python ones."""
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


#: m^3/(s Pa) per dm^3/(s bar) (1 dm^3 = 1e-3 m^3, 1 bar = 1e5 Pa).
DM3_PER_S_BAR = 1e-8
#: Significant digits of a printed C: four (0.02 % steps at C's first digit's 1), finer
#: than any C's uncertainty and coarse enough to read.
C_DIGITS = 4


def c_si(c: float) -> str:
    """C [m^3/(s Pa)] in SI with :data:`C_DIGITS` significant digits ('3.012e-09',
    '3.000e-09'; trailing zeros kept); 'n/a' when not finite."""
    return f"{c:.{C_DIGITS - 1}e}" if math.isfinite(c) else "n/a"


def c_dm3(c: float) -> str:
    """C [m^3/(s Pa)] in dm^3/(s bar) with :data:`C_DIGITS` significant digits ('0.3012',
    '0.8000', '12.34'), without the unit; 'n/a' when not finite."""
    if not math.isfinite(c):
        return "n/a"
    return f"{c / DM3_PER_S_BAR:#.{C_DIGITS}g}".rstrip(".")


def two_digits(x: float) -> str:
    """An uncertainty with two significant digits, in fixed point where that is short
    ('0.0021', '0.000052', '12'); 'n/a' when not finite."""
    if not math.isfinite(x):
        return "n/a"
    if x == 0 or not 1e-6 <= abs(x) < 1e4:
        return f"{x:.2g}"
    return f"{x:.{max(0, 1 - math.floor(math.log10(abs(x))))}f}"


def c_both(c: float, std: float = math.nan, note: str = "") -> str:
    """C in SI and in dm^3/(s bar), each with :data:`C_DIGITS` significant digits and
    with ``std`` (two significant digits; words when not known): '3.012e-09 +- 2.1e-11
    m^3/(s Pa) = 0.3012 +- 0.0021 dm^3/(s bar)'. ``note`` follows the SI unit (e.g.
    ' (k = 2)')."""
    if not math.isfinite(c):
        return "n/a"
    if math.isfinite(std):
        return (f"{c_si(c)} +- {std:.1e} m^3/(s Pa){note} = {c_dm3(c)} +- "
                f"{two_digits(std / DM3_PER_S_BAR)} dm^3/(s bar)")
    return f"{c_si(c)} m^3/(s Pa) (uncertainty not known) = {c_dm3(c)} dm^3/(s bar)"


def with_uncertainty(value: str, std: float, unit: str = "", fmt: str = ".2g") -> str:
    """'value +- std unit' for a finite standard uncertainty, else 'value unit (uncertainty
    not known)': an uncertainty that is not known is never printed as nan or inf."""
    u = f" {unit}" if unit else ""
    if math.isfinite(std):
        return f"{value} +- {std:{fmt}}{u}"
    return f"{value}{u} (uncertainty not known)"


def format_result(r: UnloadResult) -> str:
    """Human-readable summary of one unload (trade units alongside SI; C with
    :data:`C_DIGITS` significant digits in both)."""
    lines = [f"unload {r.index}: {r.status} ({r.status_text})"]
    if math.isfinite(r.tau_exp):
        tau_u = f"+- {r.tau_exp_std:.2g} s" if math.isfinite(r.tau_exp_std) else \
            "uncertainty not known"
        lines.append(f"  tau_exp        = {r.tau_exp:.6f} s  ({tau_u})")
        lines.append(f"  p10 / p_atm / p* = {r.p10:.0f} / {r.p_atm:.0f} / {r.p_star:.0f} Pa")
    lines.append(f"  C (eq 39)      = {c_si(r.conductance)} m^3/(s Pa) = "
                 f"{c_dm3(r.conductance)} dm^3/(s bar)")
    if math.isfinite(r.conductance_model):
        lines.append(f"  C (model)      = {c_both(r.conductance_model, r.conductance_model_std)}"
                     f"  [{r.method}]")
        lines.append(f"  eq 39 - model  = {100 * r.bias:+.2f} %")
    cf = r.extra.get("curve_fit", {})
    if math.isfinite(r.critical_ratio):
        lines.append("  b              = "
                     + with_uncertainty(f"{r.critical_ratio:.3f}", r.critical_ratio_std,
                                        fmt=".3f"))
    elif r.final:
        lines.append("  b              = " + (cf.get("critical_ratio_source") or (
            "not identifiable from this record (the flow stayed choked, or the subsonic "
            "tail is too short or too noisy)")))
    if math.isfinite(r.subsonic_index):
        m_text = with_uncertainty(f"{r.subsonic_index:.3f}", r.subsonic_index_std, fmt=".3f")
        lines.append("  m              = " + (
            f"{m_text} (fitted)" if cf.get("subsonic_index_fitted")
            else f"{m_text} ({cf.get('subsonic_source') or 'held at 0.5'})"))
    elif r.final:
        lines.append("  m              = not determined (" + (
            cf.get("subsonic_source") or "no subsonic tail to fit it from") + ")")
    lines += budget_lines(r)
    if math.isfinite(r.conductance_std):
        lines.append(f"  C (eq 39) u    = {r.conductance_std:.2g} m^3/(s Pa) (record and inputs;"
                     " its bias by design is not an uncertainty)")
    lines += report_line(r)
    return "\n".join(lines)


def budget_lines(r: UnloadResult) -> list[str]:
    """The budgets of the model-based C and of b, line by line (none when there is none)."""
    out: list[str] = []
    if "budget" in r.extra:
        law = r.extra.get("curve_fit", {}).get("heat_law", "")
        out += ["  uncertainty budget of C (model), 1e-9 m^3/(s Pa), share of variance"
                + (f"; heat law: {law}" if law else "") + ":",
                *format_budget(r.extra["budget"])]
    if "budget_b" in r.extra:
        out += ["  uncertainty budget of b [-], share of variance:",
                *format_budget(r.extra["budget_b"], unit=1.0, unit_name="-", symbol="b")]
    return out


def report_line(r: UnloadResult) -> list[str]:
    """The one C to report with its expanded uncertainty (none when no C is known)."""
    rec = recommended(r)
    if not math.isfinite(rec["conductance"]):
        return []
    c = c_both(rec["conductance"], rec["expanded"], " (k = 2)")
    return [f"  REPORT C       = {c}  [{rec['source']}]"]


def format_inputs(inputs: dict[str, Any]) -> str:
    """The inputs used and where they came from, one line each."""
    out = ["inputs used:"]
    for name in ("volume", "initial_temperature", "wall_temperature", "atmosphere"):
        v = inputs[name]
        val = "auto" if v["value"] is None else f"{v['value']:.6g} {v['unit']}"
        out.append(f"  {name:20s} = {val}  ({v['source']})")
    out.append(f"  heat model           = {inputs['heat_model']}")
    return "\n".join(out)


def no_estimate_reason(unloads: Sequence[UnloadResult]) -> str | None:
    """Why unloads were found but none gives an estimate of C (None when one does, or
    when there is no unload: that has its own reason)."""
    if not unloads or any(gives_c(r) for r in unloads):
        return None
    each = [f"unload {r.index}: {r.status}: {r.status_text}" for r in unloads[:3]]
    more = f" (and {len(unloads) - 3} more)" if len(unloads) > 3 else ""
    return (f"no estimate: none of the {len(unloads)} unload(s) found gives C; "
            + "; ".join(each) + more)


def exit_status(unloads: Sequence[UnloadResult], problem: str | None) -> int:
    """Exit status of ``analyze`` (:data:`EXIT_STATUS`)."""
    ok = problem is None and any(gives_c(r) for r in unloads)
    return 0 if ok else 1
