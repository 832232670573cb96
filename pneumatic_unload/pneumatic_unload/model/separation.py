# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Which extra measurement separates two real-rig effects that fit a trace alike.

Advice only (text): the discrepancy workflow quotes it when its ambiguity set holds
several effects, or when C is confounded with a leak in parallel with the component.
"""

from __future__ import annotations

from pneumatic_unload.config import EFFECTS

#: Which extra measurement separates two confusable effects.
SEPARATING_DATA: dict[frozenset[str], str] = {
    frozenset({"valve_opening", "sensor_lag"}):
        "a valve position signal (or a faster discharge: a bigger component or a smaller "
        "tank makes the valve ramp and the sensor lag distort different parts of the curve)",
    frozenset({"sensor_offset", "sensor_gain"}):
        "a zero reading at atmosphere and a reference reading at a known pressure (a "
        "calibrated manometer at p10)",
    frozenset({"heat_transfer", "pipe_volume"}):
        "a gas temperature measurement, or a run with the pipe shortened",
    frozenset({"heat_transfer", "leak"}):
        "a leak test: hold the charged tank closed and watch the pressure",
    frozenset({"leak", "pipe_volume"}):
        "a leak test (closed tank held at p10) or a run with the pipe shortened",
    frozenset({"sensor_offset", "leak"}):
        "a zero reading at atmosphere, or a leak test (closed tank held at p10)",
    frozenset({"sensor_gain", "leak"}):
        "a leak test (closed tank held at p10) and a calibration of the transducer",
    frozenset({"leak", "orifice_leak"}):
        "a longer leak test (closed tank held from p10 down to near p_atm: a laminar leak "
        "decays exponentially, a sonic one linearly in p until p_atm/b_leak)",
    frozenset({"leak_downstream", "orifice_leak_downstream"}):
        "a run with the component removed and its port plugged (the downstream leak "
        "alone, to measure its law)",
}
#: Effects in parallel with the component (downstream of the valve): C is confounded with
#: them, and a run with the component plugged separates them.
DOWNSTREAM_LEAKS: tuple[str, ...] = ("leak_downstream", "orifice_leak_downstream")
#: The measurement that separates C from a downstream leak.
PLUGGED_RUN = ("a run with the component removed and its port plugged (the downstream "
               "leak alone), or a leak test with the valve open and the outlet capped")
for _a in DOWNSTREAM_LEAKS:
    for _b in EFFECTS:
        if _b != _a:
            SEPARATING_DATA.setdefault(frozenset({_a, _b}), PLUGGED_RUN)
for _a, _b in (("leak", "orifice_leak_downstream"), ("orifice_leak", "leak_downstream"),
               ("leak", "leak_downstream"), ("orifice_leak", "orifice_leak_downstream")):
    SEPARATING_DATA[frozenset({_a, _b})] = (
        "a leak test with the valve closed (an upstream leak makes the held pressure "
        "decay) and " + PLUGGED_RUN)
for _b in ("heat_transfer", "pipe_volume", "sensor_offset", "sensor_gain"):
    SEPARATING_DATA.setdefault(frozenset({"orifice_leak", _b}),
                               SEPARATING_DATA[frozenset({"leak", _b})])

#: The hot start (heat transfer with the gas warmer than the wall) and its look-alikes: a
#: hot gas cooling in the closed tank makes the plateau decay as an upstream leak does.
_HOT_TEMPERATURE = ("a gas temperature measurement from before the valve opens (a hot gas "
                    "cooling toward the wall), or the wall (room) temperature stated")
SEPARATING_DATA[frozenset({"hot_start", "heat_transfer"})] = _HOT_TEMPERATURE
for _b in ("leak", "orifice_leak"):
    SEPARATING_DATA[frozenset({"hot_start", _b})] = (
        _HOT_TEMPERATURE + "; or a leak test once the gas has settled to room temperature "
        "(a closed tank held at p10: a leak keeps its pressure falling, a cooling gas stops)")
for _b in EFFECTS:
    SEPARATING_DATA.setdefault(frozenset({"hot_start", _b}), _HOT_TEMPERATURE)
#: The heat exchange and the component's subsonic index m (ISO 6358-1:2013) both bend the
#: curve; the gas's temperature tells them apart (a nearly isothermal fill and an
#: adiabatic one through C / gamma with m moved differ by about 100 K in the gas).
for _a in ("heat_transfer", "hot_start"):
    SEPARATING_DATA[frozenset({_a, "subsonic_index"})] = (
        "a gas temperature measurement during the run (the heat exchange sets the gas's "
        "temperature, m does not), or a run from another initial pressure (m shapes only "
        "the subsonic part)")


def separating_data(names: list[str]) -> list[str]:
    """Advice: which extra data would separate each pair of confusable effects."""
    out: list[str] = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            hint = SEPARATING_DATA.get(frozenset({a, b}))
            out.append(f"{a} vs {b}: " + (hint or "a second run with a different tank "
                                           "volume or initial pressure"))
    return out
