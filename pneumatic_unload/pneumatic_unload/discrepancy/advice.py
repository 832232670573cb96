# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The end of a discrepancy report: what to do next, and which C to report and why.

Written for the test-bench engineer from a :class:`~pneumatic_unload.discrepancy.types.
DiscrepancyResult`: the measurement that separates the candidates the data cannot tell
apart (:func:`~pneumatic_unload.model.separation.separating_data`), what to check or
recalibrate for each effect named and when (a member of an ambiguity gets no action, only
the measurement that separates it), and the conductance to write in the test record: one
value with its sigma when the verdict is unambiguous, the range across the models that fit
about equally when it is not. SI units; C also in dm^3/(s bar).
"""

from __future__ import annotations

import math

from pneumatic_unload.discrepancy.ambiguity import LD_STATED
from pneumatic_unload.discrepancy.types import NRMS_LIMIT, DiscrepancyResult
from pneumatic_unload.model.effects import separating_data

#: Per effect: what to check or recalibrate, and when.
ACTIONS: dict[str, str] = {
    "heat_transfer": "the gas exchanges heat with the wall: report C from the model with "
                     "heat transfer (it is fitted, no action on the rig); to confirm it, "
                     "log the gas temperature on the next run and give the wall "
                     "temperature (--wall-temperature) when it differs from the gas's",
    "valve_opening": "the valve opens over a finite time: no recalibration; record the "
                     "valve's position signal (or use a faster valve) on the next run if "
                     "the opening must be known",
    "sensor_lag": "the transducer (or its tubing) lags: check the tubing length and the "
                  "transducer's bandwidth before the next run; a short, wide connection "
                  "to the tank removes it",
    "leak": "the tank leaks upstream of the valve: leak-test it now (hold it charged with "
            "the valve closed and watch the pressure) and fix the leak before the next "
            "campaign",
    "orifice_leak": "the tank leaks upstream of the valve (sonic leak): leak-test it now "
                    "(valve closed, pressure held from p10 down) and fix it before the "
                    "next campaign",
    "leak_downstream": "a leak opens with the valve (a fixture seal in parallel with the "
                       "component): its flow is in C; before trusting C, run with the "
                       "component removed and its port plugged, and fix the seal",
    "orifice_leak_downstream": "a sonic leak opens with the valve (in parallel with the "
                               "component): its flow is in C; run with the component "
                               "plugged to measure it, and fix the seal",
    "pipe_volume": "a volume sits between the tank and the component: measure it (and the "
                   "pipe's bore) and give it to the model, or shorten the connection; "
                   "check before the next campaign",
    "sensor_offset": "the transducer reads with an offset: take a zero reading at "
                     "atmosphere before the next run and recalibrate the zero; the C "
                     "reported here is already corrected for it",
    "sensor_gain": "the transducer's span is off: calibrate it against a reference at a "
                   "known pressure (about p10) before the next run; the C reported here "
                   "is already corrected for it",
}


def what_next(res: DiscrepancyResult) -> list[str]:
    """Bullet points of the report's "What to do next" (one measurement or check each)."""
    out: list[str] = []
    for rd in res.rounds:
        if rd.winner != "none" and rd.ambiguous_with:
            names = [rd.winner, *rd.ambiguous_with]
            out.append(f"**Separate the candidates** ({', '.join(names)} fit alike): "
                       + "; ".join(separating_data(names)))
    amb = res.conductance_ambiguity
    if amb is not None and amb.separating:
        out.append("**Pin down C**: " + "; ".join(amb.separating))
    heat = [e for e in res.effects if e in ("heat_transfer", "hot_start")]
    if heat and res.settings is not None and not res.settings.length_diameter_known and not (
            amb is not None and LD_STATED in amb.separating):
        out.append("**Tank L/D**: not stated, and the heat transfer's natural-convection "
                   "law depends on it (where its correlation changes branch); "
                   + LD_STATED + ", then rerun")
    # act only on the effects the data name: a member of an ambiguity may not be there
    for e in res.named:
        if e in ACTIONS:
            out.append(f"**{e}**: {ACTIONS[e]}")
    tc = res.temperature_check
    if tc and tc.get("available") and not tc.get("agrees"):
        out.append("**Temperature**: the logged gas temperature does not support the fitted "
                   "model better than the adiabatic one; the wall temperature assumption "
                   "(the wall at the initial gas temperature) is the likely culprit: give "
                   "the measured wall temperature, or fit it (--fit-wall-temperature), and "
                   "check where the sensor sits (in the gas, not on the wall)")
    if res.after.structured:
        how = (f"normalised RMS {res.after.nrms:.3f}" if res.after.nrms > NRMS_LIMIT
               else f"at the noise level (normalised RMS {res.after.nrms:.3f}) but not "
                    "white")
        out.append(f"**Unexplained residual**: the final model's residual is {how} "
                   f"(Ljung-Box p {res.after.ljung_box_p:.3g}): an effect outside the "
                   "candidates, a fault in the record, or noise more correlated than the "
                   "plateaus show; look at the residual plot where it is largest, and "
                   "repeat the run")
    if any("time limit" in n for n in res.notes):
        out.append("**Time limit**: the search stopped early; rerun with a larger "
                   "--time-limit for a complete verdict")
    if res.effect == "none" and not res.before.structured:
        out.append("Nothing to recalibrate: the adiabatic model explains the trace within "
                   "the noise. Repeat the run to check the repeatability of C.")
    return out


def which_c(res: DiscrepancyResult) -> list[str]:
    """Paragraphs of the report's "Which C to report, and why" (Markdown blocks)."""
    c = res.conductance
    s = res.conductance_std()
    base_c = res.baseline.theta["C"]
    model = ", ".join(res.effects) if res.effects else "the adiabatic baseline"
    amb = res.conductance_ambiguity
    dm3 = 1e-8  # m^3/(s Pa) per dm^3/(s bar)
    if amb is not None and amb.ambiguous:
        members = [f"- {', '.join(m['effects']) or 'baseline'}: C = {m['conductance']:.4g} "
                   f"+- {m['conductance_std']:.2g} m^3/(s Pa) ({m['why']})"
                   for m in amb.members]
        lines = [f"**Report the range C = {amb.low:.4g} to {amb.high:.4g} m^3/(s Pa) "
                 f"({amb.low / dm3:.4g} to {amb.high / dm3:.4g} dm^3/(s bar))**, not one "
                 "value: models that explain the trace about equally well give different C "
                 "(or a leak in parallel with the component is counted in it):",
                 "\n".join(members),
                 f"The named model ({model}) gives C = {c:.5g} m^3/(s Pa); it is not "
                 "more credible than the others until the measurement under 'What to do "
                 "next' is made."]
        return lines
    if c > 0 and math.isfinite(s):
        lines = [f"**Report C = {c:.5g} m^3/(s Pa) = {c / dm3:.4g} dm^3/(s bar), sigma "
                 f"{s:.2g} m^3/(s Pa) ({100 * s / c:.2g} %)**, from {model}."]
    else:
        iv = res.parameters.get("C")
        why = iv.describe() if iv is not None and not iv.identifiable else \
            "the fit gives no finite standard error of C"
        lines = [f"**Report C = {c:.5g} m^3/(s Pa) = {c / dm3:.4g} dm^3/(s bar)**, from "
                 f"{model}, **without a sigma**: {why}."]
    if res.effect == "none":
        lines.append("Why: no candidate effect improves the fit by the BIC threshold, so "
                     "the unloading-time model itself is the one to report.")
    else:
        off = 100.0 * (base_c / c - 1.0) if c > 0 else math.nan
        lines.append(f"Why: {model} explains the trace (normalised RMS "
                     f"{res.before.nrms:.3f} -> {res.after.nrms:.3f}); the adiabatic "
                     f"baseline's C = {base_c:.5g} m^3/(s Pa) is {off:+.2g} % off it "
                     "because it fits the missing effect into C. No other model fits about "
                     "as well with a different C.")
    lines.append("The sigma is the fit's (noise only, inflated when the fit is worse than "
                 "the noise); for the test record, combine it with the input uncertainties "
                 "(volume, temperature, transducer) as the estimator's budget does "
                 "(pneumatic-unload analyze).")
    if res.after.structured:
        lines.append("Caution: the final model leaves a structured residual, so this sigma "
                     "understates the uncertainty of C.")
    if amb is not None and math.isfinite(amb.parallel_low):
        lines.append(f"A leak in parallel with the component (a fixture seal downstream of "
                     f"the valve) would be counted in this C and no trace shows it: if one "
                     f"cannot be excluded, the component's C may be as low as "
                     f"{amb.parallel_low:.4g} m^3/(s Pa) (a run with the component plugged "
                     "measures the leak).")
    return lines
