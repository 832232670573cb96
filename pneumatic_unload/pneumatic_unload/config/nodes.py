# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Every ROS parameter of every node, ROS-free: the one list the nodes declare, ``--help``
prints and ``config/<node>.yaml`` holds (so the three cannot drift apart).

The settings fields come from their metadata (:func:`~.adapters.parameter_specs`), the
node's own parameters are written here once, with their unit and range. SI units: s, Hz,
m^3, Pa absolute, K.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Sequence

from pneumatic_unload.config.adapters import ParameterSpec, parameter_specs
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.config.rig import RigConfig

#: The nodes (``ros2 run pneumatic_unload NODE``) and what each does, for ``--help``.
NODES: dict[str, str] = {
    "estimator": "unloading-time estimator: pressure samples in, UnloadEstimate results out "
                 "(~/estimate), action ~/measure",
    "simulator": "simulated rig: tank pressure (/tank/pressure), temperature, valve state "
                 "and rig configuration; services ~/start_unload and ~/charge",
    "recorder": "records the rig's topics (and extra ones) into MCAP bags",
    "replay": "publishes the messages of a bag again, on their original topics",
    "opcua": "OPC UA server for the cell's PLC: the latest estimate, the state, and the "
             "methods Measure and StartMeasure (the estimator's ~/measure action)",
}


#: Range of the recorder's ``flush_interval`` [s].
FLUSH_INTERVAL_RANGE = (1e-3, 10.0)
#: Largest time scale of the replay [-].
REPLAY_RATE_MAX = 1e6


def _double(name: str, default: float, doc: str, unit: str, lo: float, hi: float, *,
            dynamic: bool = False) -> ParameterSpec:
    """A double parameter in [lo, hi] [unit]; with ``dynamic`` (it also takes an integer)
    the node checks the range itself, with its own message."""
    u = f" [{unit}]" if unit else ""
    rng = (None, None) if dynamic else (lo, hi)
    return ParameterSpec(name, "double", float(default), f"{doc}{u}, range [{lo:g}, {hi:g}]",
                         *rng, dynamic_typing=dynamic)


def _int(name: str, default: int, doc: str, lo: int, hi: int, *, enforce: bool = True
         ) -> ParameterSpec:
    """An integer parameter in [lo, hi] (not ``enforce``: the node checks it itself)."""
    rng = (lo, hi) if enforce else (None, None)
    return ParameterSpec(name, "integer", int(default), f"{doc}, range [{lo}, {hi}]", *rng)


def _str(name: str, default: str, doc: str, choices: Sequence[str] = ()) -> ParameterSpec:
    """A string parameter (one of ``choices`` when given)."""
    if choices:
        doc += f" (one of {', '.join(repr(c) for c in choices)})"
    return ParameterSpec(name, "string", default, doc, choices=tuple(choices))


def _bool(name: str, default: bool, doc: str) -> ParameterSpec:
    return ParameterSpec(name, "bool", bool(default), doc)


def _strings(name: str, doc: str) -> ParameterSpec:
    """A string-array parameter, unset by default."""
    return ParameterSpec(name, "string_array", None, doc)


def _estimator() -> list[ParameterSpec]:
    return [
        *parameter_specs(EstimatorSettings).values(),
        _bool("temperature_from_topic", False,
              "T10 from /tank/temperature (last value before the unload)"),
        _str("pressure_topic", "/tank/pressure", "pressure topic (FluidPressure; input sample)"),
        _str("block_topic", "/tank/pressure_block",
             "pressure block topic (PressureBlock; input block)"),
        _str("input", "sample", "'sample': FluidPressure per sample; 'block': PressureBlock; "
             "'volts': Voltage per sample (an uncalibrated transducer, converted with "
             "signal_gain and signal_offset)", ("sample", "block", "volts")),
        _str("volts_topic", "/tank/pressure_volts", "voltage topic (Voltage; input volts)"),
        _str("qos", "sensor_data", "'sensor_data' (best effort) or 'reliable' (KEEP_ALL: "
             "lossless, e.g. replays)", ("sensor_data", "reliable")),
        _str("frame_id", "", "accept only this header frame_id ('' accepts any)"),
        _str("valve_service", "/simulator/start_unload",
             "std_srvs/Trigger service that opens the valve (action ~/measure)"),
        _double("measure_timeout", 60.0, "default timeout of ~/measure", "s", 0.1, 1e6),
        _str("results_db", "", "results database (a SQLite file, or a PostgreSQL server's "
             "postgresql://USER@HOST:PORT/DB; shared with batch) each unload's last "
             "estimate is written to ('': none)"),
        _str("part_id", "", "part id of the estimates written to results_db (a ~/measure "
             "goal's part_id replaces it while it runs)"),
        _str("spec_file", "", "specification of the part types (YAML): the verdict of each "
             "estimate in the log, results_db and ~/measure ('': none)"),
        _double("diagnostics_period", 1.0, "period of /diagnostics reports", "s", 0.05, 60.0),
        _double("end_timeout", 5.0, "start_time mode: a record that has not settled gets its "
                "final estimate after this long without a sample (the stream ended)", "s",
                0.1, 1e6),
    ]


def _simulator() -> list[ParameterSpec]:
    return [
        *parameter_specs(RigConfig).values(),
        _str("mode", "service", "'service': unload on ~/start_unload; 'cycle': charge, "
             "settle, unload, repeat; 'alternate': a cycle of steps in turn the other way "
             "(a charge through the component, then its discharge)",
             ("service", "cycle", "alternate")),
        _double("start_delay", -1.0, "open the valve once by itself after this delay "
                "(< 0: never)", "s", -1.0, 1e6),
        _double("settle_time", 2.0, "cycle mode: plateau before each unload", "s", 0.05, 1e5),
        _double("vent_time", 1.0, "time vented at atmosphere after an unload before "
                "recharging", "s", 0.0, 1e5),
        _double("charge_time", 1.0, "recharge duration", "s", 0.01, 1e5),
        _int("cycles", 0, "cycle mode: number of unloads (0: forever)", 0, 1_000_000),
        _bool("auto_charge", True, "service mode: recharge by itself vent_time after an "
              "unload"),
        _double("temperature_rate", 10.0, "rate of /tank/temperature (0: off)", "Hz", 0.0,
                1000.0),
        _int("block_size", -1, "samples per /tank/pressure_block message (0: no blocks; "
             "-1: 100 above 2 kHz, where the estimator should run on them with "
             "input:=block: single messages are lost on a small machine; none below)", -1,
             100_000),
        _bool("per_sample", True, "publish every sample as a FluidPressure on "
              "/tank/pressure"),
        _str("frame_id", "tank", "frame_id of the published headers"),
        _bool("output_volts", False, "publish the transducer's output in volts "
              "(transducer_zero + transducer_sensitivity * p), an uncalibrated rig: as "
              "pneumatic_unload_msgs/Voltage on /tank/pressure_volts instead of a "
              "FluidPressure on /tank/pressure (blocks carry the volts too; estimator: "
              "input:=volts)"),
        _int("wait_for_subscribers", 0, "start streaming only when this many nodes "
             "subscribe to the pressure topics published (/tank/pressure or, with "
             "output_volts, /tank/pressure_volts, and /tank/pressure_block; a node on "
             "both counts once)", 0, 100),
    ]


def _recorder() -> list[ParameterSpec]:
    return [
        _str("output", "", "bag directory (split=run) or parent of the bags "
             "(split=unload); '': runs/rec-<UTC time>"),
        _str("split", "run", "'run': one bag; 'unload': one bag per unload",
             ("run", "unload")),
        _double("flush_interval", 0.5, "maximal age of data not yet on disk", "s",
                *FLUSH_INTERVAL_RANGE, dynamic=True),
        _str("log_time", "receive", "bag log time: 'receive' or 'header' (header stamp)",
             ("receive", "header")),
        _strings("topics", "extra topics to record (types from the graph)"),
        _bool("fsync", False, "fsync at each flush"),
    ]


def _replay() -> list[ParameterSpec]:
    return [
        _str("bag", "", "bag directory or .mcap file (required)"),
        _double("rate", 1.0, "time scale factor; 0 = as fast as the subscribers take them",
                "", 0.0, REPLAY_RATE_MAX, dynamic=True),
        _strings("topics", "topics to replay (unset: all)"),
        _bool("loop", False, "repeat until SIGINT"),
        _bool("wait_for_subscribers", True, "wait for matched subscribers before publishing"),
        _int("min_subscribers", 1, "subscribers to wait for", 0, 1_000_000, enforce=False),
        _double("wait_timeout", 10.0, "longest wait for subscribers", "s", 0.0, 1e6,
                dynamic=True),
        _bool("publish_clock", False, "publish /clock (rosgraph_msgs/Clock) at the bag's log "
              "times as they are replayed, for nodes run with use_sim_time"),
    ]


def _opcua() -> list[ParameterSpec]:
    return [
        _str("endpoint", "opc.tcp://127.0.0.1:4840/pneumatic_unload/",
             "OPC UA endpoint the server listens on (opc.tcp://HOST:PORT/PATH; HOST "
             "127.0.0.1: this machine only, 0.0.0.0: every interface)"),
        _str("estimator", "/estimator", "the estimator node: its ~/measure action and "
             "~/estimate topic"),
        _double("measure_timeout", 60.0, "a measurement's timeout (the ~/measure goal's); "
                "an OPC UA client's call timeout must exceed it plus final_timeout and "
                "charge_wait", "s",
                0.1, 1e6),
        _bool("trigger_valve", True, "a measurement opens the valve (the estimator's "
              "valve_service); false: it waits for an unload started otherwise"),
        _double("final_timeout", 30.0, "longest wait for the final (full-curve fit) "
                "estimate after the p* crossing; then Measure returns the crossing's", "s",
                0.0, 1e6),
        _double("estimator_wait", 10.0, "a measurement waits this long for the "
                "estimator (its ~/measure action server, and pressure samples reaching it: "
                "its /diagnostics reports)", "s", 0.0, 1e6),
        _double("charge_wait", 30.0, "a measurement whose valve is refused because the "
                "tank is not charged (the rig recharging after its last unload) tries again "
                "for this long", "s", 0.0, 1e6),
        _str("charge_service", "/simulator/charge", "std_srvs/Trigger service that "
             "recharges the rig (the OPC UA Charge method; '': none)"),
        _str("spec_file", "", "specification of the part types (YAML; the estimator's "
             "file): the Verdict of a measurement's final estimate ('': none)"),
        _str("security_policy", "None", "'None' (a lab bench) or 'Basic256Sha256' "
             "(SignAndEncrypt; needs certificate and private_key)", ("None", "Basic256Sha256")),
        _str("certificate", "", "the server's certificate file (DER or PEM)"),
        _str("private_key", "", "the server's private key file (PEM)"),
        _str("users_file", "", "users who may call the methods: 'name:HASH' lines (python "
             "-m pneumatic_unload.plc.security NAME; needs Basic256Sha256); '': none"),
        _bool("allow_anonymous", False, "anonymous sessions may call the methods (a lab "
              "bench: whoever reaches the endpoint can open the valve); false: they may "
              "browse, read and subscribe only"),
        _str("trusted_certs", "", "folder of the trusted client certificates or their CAs "
             "(DER or PEM); required by Basic256Sha256"),
        _str("revoked_certs", "", "folder of certificate revocation lists (DER or PEM; '' "
             "none)"),
    ]


_SPECS: dict[str, Callable[[], list[ParameterSpec]]] = {
    "estimator": _estimator, "simulator": _simulator, "recorder": _recorder,
    "replay": _replay, "opcua": _opcua,
}


def node_parameters(node: str) -> dict[str, ParameterSpec]:
    """Every parameter of ``node`` ('estimator', 'simulator', 'recorder', 'replay',
    'opcua'), in declaration order."""
    if node not in _SPECS:
        raise KeyError(f"unknown node {node!r}; nodes: {', '.join(_SPECS)}")
    return {s.name: s for s in _SPECS[node]()}


def wants_help(argv: Sequence[str]) -> bool:
    """The command line asks for help (``-h``/``--help`` anywhere, also after
    ``--ros-args``): print it and exit 0 without starting ROS."""
    return any(a in ("-h", "--help") for a in list(argv)[1:])


def help_or_none(node: str, args: Sequence[str] | None) -> int | None:
    """Print the node's ``--help`` and return 0 (its exit code) when the command line
    (``sys.argv`` when ``args`` is None) asks for it, also after ``--ros-args``, without
    starting ROS; else None."""
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(help_text(node))
        return 0
    return None


def _type_name(s: ParameterSpec) -> str:
    return {"string_array": "string[]"}.get(s.kind, s.kind)


def help_text(node: str) -> str:
    """``--help`` of a node: usage, what it does, and every parameter with its type,
    default, unit and range."""
    specs = node_parameters(node)
    lines = [f"usage: ros2 run pneumatic_unload {node} [--ros-args -p NAME:=VALUE ... "
             f"| --params-file config/{node}.yaml]",
             "", f"{node}: {NODES[node]}", "", "parameters (SI units):"]
    for s in specs.values():
        default = "unset" if s.default is None else json.dumps(s.default)
        lines.append(f"  {s.name} ({_type_name(s)}, default {default})")
        lines.append(f"      {s.description}")
    return "\n".join(lines)


def _yaml_value(s: ParameterSpec) -> str:
    if s.kind == "string_array":
        return "[]"
    if s.kind == "double":
        # 12 significant digits; a mantissa with a point, so that the ROS parameter file
        # parser reads a double ("2.0e-10", not "2e-10")
        text = repr(float(f"{float(s.default):.12g}"))
        mant, _, exp = text.partition("e")
        if "." not in mant and mant.lstrip("-").isdigit():
            mant += ".0"
        return mant + ("e" + exp if exp else "")
    return json.dumps(s.default)


def yaml_text(node: str) -> str:
    """The ``config/<node>.yaml`` parameter file of a node: every parameter at its default,
    with its meaning, unit and range in a comment, under ``/**`` (any node name, as a
    renamed or namespaced node is launched)."""
    lines = [f"# Parameters of the {node} node, generated from the package's field metadata",
             "# (pneumatic_unload.config.nodes; a test checks this file against it):",
             f"#   ros2 run pneumatic_unload {node} --ros-args --params-file "
             f"share/pneumatic_unload/config/{node}.yaml",
             f"# '{node} --help' lists the same. SI units. Keyed by '/**' (every node",
             "# name and namespace: a node launched under another name reads it too).",
             "/**:", "  ros__parameters:"]
    for s in node_parameters(node).values():
        value = _yaml_value(s)
        if s.kind == "string_array":
            # an empty list has no type in a parameter file: leave it out (unset)
            lines.append(f"    # {s.name}: [\"/a\", \"/b\"]  # ({_type_name(s)}) {s.description}")
            continue
        lines.append(f"    {s.name}: {value}  # ({_type_name(s)}) {s.description}")
    return "\n".join(lines) + "\n"
