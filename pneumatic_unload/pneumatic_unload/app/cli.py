# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""``pneumatic-unload``: offline analysis, simulation and bag repair.

Sub-commands
------------
analyze PATH     unloading-time analysis of a bag (directory or .mcap) or a CSV log
simulate --out   write a simulated run as a rosbag2/MCAP bag, no ROS needed
recover BAG      make a bag whose writer was killed readable again

Exit status of ``analyze`` (:data:`pneumatic_unload.analysis.output.EXIT_STATUS`): 0 when at
least one unload gives C (a finite recommended C and a status other than 'bad_data': 'ok',
'aborted_sse', 'ok_subsonic' with its curve-fit C; other unloads of the record may have
failed, each says why); 1 when the record gives no estimate: no unload
found, every unload failed (e.g. all 'bad_data': a stuck or saturated sensor, a clock step),
or the readings look like gauge pressures taken as absolute; the reason is on stderr and in
``--json`` (``no_unload_reason``, ``no_estimate_reason``, ``input_problem``); 2 on unreadable
input or bad options, with one line on stderr (no prefix matching of options: an unknown one is
answered with the nearest known one).
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pneumatic_unload.analysis.output import (
    EXIT_STATUS,
    exit_status,
    format_inputs,
    format_result,
    json_default,
    no_estimate_reason,
    unload_json,
)
from pneumatic_unload.analysis.records import (
    Record,
    RecordError,
    analyze_input,
    measured_temperature,
    open_record,
    settings_for,
)
from pneumatic_unload.app import batch_cli
from pneumatic_unload.config import TANK_FIELDS, ConfigError, RigConfig, TankSpec, adapters
from pneumatic_unload.config.estimator import t10_uncertainty, wall_uncertainty
from pneumatic_unload.discrepancy.types import DiscrepancyError, DiscrepancySettings
from pneumatic_unload.estimation import (
    EstimationError,
    EstimatorSettings,
)
from pneumatic_unload.io.csvheader import PRESSURE_UNITS, TEMPERATURE_UNITS, TIME_UNITS
from pneumatic_unload.io.csvnames import unit_spelling


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse without prefix matching (``allow_abbrev=False``, also for the sub-commands,
    which are made with the parent's class) whose errors are one line on stderr, exit 2."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> Any:  # argparse's signature: NoReturn
        """Print ``prog: error: message`` (one line, no usage) and exit with status 2; an
        unknown choice (a sub-command) gets the nearest known one."""
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            near = difflib.get_close_matches(m.group(1), re.findall(r"'([^']*)'", m.group(2)),
                                             n=1)
            if near:
                message += f"; did you mean {near[0]}?"
        self.exit(2, f"{self.prog}: error: {message}\n")


def _option_strings(parser: argparse.ArgumentParser) -> list[str]:
    return [o for a in parser._actions for o in a.option_strings if o.startswith("--")]


def unrecognized_message(parser: argparse.ArgumentParser, extra: Sequence[str]) -> str:
    """'unrecognized argument --volum; did you mean --volume?' for the first unknown option
    of ``extra`` (the nearest of ``parser``'s options), or the unknown arguments."""
    for word in extra:
        if word.startswith("-"):
            name = word.split("=", 1)[0]
            near = difflib.get_close_matches(name, _option_strings(parser), n=1)
            hint = f"; did you mean {near[0]}?" if near else f" (see {parser.prog} --help)"
            return f"unrecognized argument {name}{hint}"
    return f"unrecognized argument(s): {' '.join(extra)}"


# --------------------------------------------------------------------------- input
def load_trace(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Time [s], pressure [Pa absolute] and stored rig configuration of the input PATH, as
    whole arrays (what was assumed about the input is printed as warnings on stderr)."""
    rec = open_input(args)
    try:
        parts = list(rec.chunks())
    except RecordError as exc:
        raise CliError(str(exc)) from exc
    return (np.concatenate([c[0] for c in parts]), np.concatenate([c[1] for c in parts]),
            rec.cfg)


def settings_from(args: argparse.Namespace, cfg: dict[str, Any]) -> EstimatorSettings:
    """Estimator settings: command-line values first, then the live estimator's settings
    recorded in the bag (so that the analysis reproduces what it published), then the bag's
    rig configuration (tank and gas), then the defaults of
    :class:`~pneumatic_unload.estimation.EstimatorSettings`."""
    given = adapters.given_options(args, EstimatorSettings)
    gauge_atmosphere(args, given)
    try:
        return settings_for(cfg, given)
    except (RecordError, EstimationError, ConfigError) as exc:
        raise CliError(str(exc)) from exc


def input_sources(args: argparse.Namespace, cfg: dict[str, Any], settings: EstimatorSettings,
                  t10_column: bool) -> dict[str, Any]:
    """Every input the analysis used, with where it came from (echoed in the output)."""
    given = adapters.given_options(args, EstimatorSettings)
    rig = TankSpec.fields_of(cfg)

    def source(name: str) -> str:
        if name in given:
            return "command line"
        if name in (cfg.get("estimator_settings") or {}):
            return "bag (the live estimator's settings)"
        if name in rig:
            return "bag (rig configuration)"
        return "default"

    s = settings
    t10_src = "temperature column at the unload start" if t10_column else \
        source("initial_temperature")
    if t10_src == "default" and "measured_initial_temperature" in cfg:
        t10_src = "temperature column (first row)"
    return {
        "volume": {"value": s.volume, "unit": "m^3", "source": source("volume")},
        "initial_temperature": {"value": s.initial_temperature, "unit": "K",
                                "source": t10_src},
        "wall_temperature": {"value": s.wall, "unit": "K",
                             "source": source("wall_temperature")
                             if s.wall_temperature is not None else
                             f"assumed = T10 (+- {wall_uncertainty(s)[0]:.3g} K, more if a "
                             "hot start is found; a hot-start law fits it instead: see the "
                             "budget's wall line)"},
        "atmosphere": {"value": s.atmosphere, "unit": "Pa",
                       "source": source("atmosphere") if s.atmosphere is not None
                       else "measured: the final plateau (auto)"},
        "gas": {"gas_constant": s.gas_constant, "gamma": s.gamma},
        "heat_model": s.heat_model,
        "uncertainties": {"volume_m3": s.volume_uncertainty, "temperature_K":
                          t10_uncertainty(s)[0], "wall_temperature_K":
                          s.wall_temperature_uncertainty, "pressure_Pa": s.pressure_uncertainty,
                          "atmosphere_Pa": s.atmosphere_uncertainty,
                          "defaults": "volume 0.5 % of V, pressure 0.1 % of p10, an assumed "
                          "wall's from the record (the budget's wall line)"},
    }


def csv_options(args: argparse.Namespace) -> dict[str, Any]:
    """How to read a CSV input: its columns, units and gauge zero, hints in the command
    line's words (see :func:`~pneumatic_unload.io.csvlog.read_csv_trace`)."""
    return {k: getattr(args, k) for k in (
        "time_column", "pressure_column", "temperature_column", "pressure_unit",
        "time_unit", "temperature_unit")} | {"gauge": args.gauge or None,
                                             "atmosphere": gauge_atmosphere(args),
                                             "hints": "cli"}


def gauge_atmosphere(args: argparse.Namespace, given: dict[str, Any] | None = None
                     ) -> float | None:
    """The atmosphere [Pa] added to gauge readings (``--gauge``): the barometer's reading
    ``--atmosphere``, or with ``--atmosphere-auto`` the standard one (the final plateau is
    the zero; :func:`~pneumatic_unload.config.adapters.gauge_inputs` completes ``given``
    settings); None for absolute readings."""
    try:
        return adapters.gauge_inputs(bool(getattr(args, "gauge", False)),
                                     getattr(args, "atmosphere", None),
                                     bool(getattr(args, "atmosphere_auto", False)),
                                     given if given is not None else {})
    except ConfigError as exc:
        raise CliError(str(exc)) from exc


def open_input(args: argparse.Namespace) -> Record:
    """The input PATH of ``analyze`` as a :class:`~pneumatic_unload.analysis.records.Record` (a
    CSV is read in chunks later); what was assumed about it is printed as warnings on stderr."""
    try:
        rec = open_record(args.path, topic=args.topic, **csv_options(args))
    except RecordError as exc:
        raise CliError(str(exc)) from exc
    for w in rec.warnings:
        print(f"pneumatic-unload: warning: {args.path}: {w}", file=sys.stderr)
    return rec


def cmd_analyze(args: argparse.Namespace) -> int:
    """Run the unloading-time analysis and print the estimates (exit status 1 when no unload
    was found, with the reason, or when the readings look like gauge pressures). A CSV log
    is read in chunks and streamed through the estimator: memory bounded by the chunk, the
    overview of the record and the longest unload (see
    :mod:`pneumatic_unload.estimation.chunked`)."""
    if args.plot:
        folder = Path(args.plot).parent
        if not folder.is_dir():
            raise CliError(f"--plot {args.plot}: folder {folder} does not exist")
    rec = open_input(args)
    given = adapters.given_options(args, EstimatorSettings)
    gauge_atmosphere(args, given)
    try:
        ana = analyze_input(rec, given)
    except (RecordError, EstimationError, ConfigError) as exc:
        raise CliError(str(exc)) from exc
    for w in rec.notes:  # what reading the rows found (a time counter unwrapped)
        print(f"pneumatic-unload: warning: {args.path}: {w}", file=sys.stderr)
    run, settings, unloads, t10_column = ana.run, ana.settings, ana.unloads, ana.t10_column
    published, why, problem = run.published, ana.no_unload, ana.input_problem
    no_estimate = None if problem is not None else no_estimate_reason(unloads)
    inputs = input_sources(args, rec.cfg, settings, t10_column)
    if args.json:
        out = {"source": str(args.path), "samples": run.samples,
               "settings": dict(vars(settings)), "inputs": inputs,
               "unloads": [unload_json(r) for r in unloads],
               "published": [unload_json(r) for r in published],
               "no_unload_reason": why, "no_estimate_reason": no_estimate,
               "input_problem": problem, "exit_status": exit_status(unloads, problem),
               "input_warnings": [*rec.warnings, *rec.notes]}
        print(json.dumps(out, indent=2, allow_nan=False, default=json_default))
    else:
        print(f"{args.path}: {run.samples} samples, {len(unloads)} unload(s)")
        print(format_inputs(inputs))
        for r in unloads:
            print(format_result(r))
    if why is not None:
        print(f"pneumatic-unload: no unload: {why}", file=sys.stderr)
    elif problem is not None:
        print(f"pneumatic-unload: {problem}", file=sys.stderr)
    elif no_estimate is not None:
        print(f"pneumatic-unload: {no_estimate}", file=sys.stderr)
    if args.plot:
        from pneumatic_unload.analysis.plotting import plot_analysis

        t, p = run.overview.arrays()
        try:
            plot_analysis(t, p, unloads, settings, args.plot)
        except OSError as exc:
            raise CliError(f"--plot {args.plot}: {exc}") from exc
        if not args.json:
            print(f"plot written to {args.plot}")
    return exit_status(unloads, problem)


def cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate a run and write it as a bag."""
    from pneumatic_unload.analysis.runs import write_simulated_bag
    from pneumatic_unload.io.bag import BagError

    try:
        cfg = config_from_args(args)
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    if cfg.direction == "discharge" and cfg.atmosphere is not None \
            and cfg.initial_pressure <= cfg.atmosphere:
        raise CliError(f"initial_pressure={cfg.initial_pressure:g} Pa is not above the "
                       f"atmosphere {cfg.atmosphere:g} Pa: nothing would flow out (pressures "
                       f"are absolute: 6 bar gauge is --initial-pressure 7.01325bar)")
    try:
        info = write_simulated_bag(cfg, Path(args.out), analyze_live=not args.no_estimate)
    except (BagError, FileExistsError) as exc:
        raise CliError(str(exc)) from exc
    print(json.dumps(info, indent=2, default=json_default) if args.json else
          f"wrote {info['samples']} samples to {args.out}")
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    """Recover a bag whose writer died."""
    from pneumatic_unload.io.bag import TOPIC_PRESSURE, BagError, recover

    try:
        report = recover(Path(args.bag))
    except BagError as exc:
        raise CliError(str(exc)) from exc
    except OSError as exc:
        raise CliError(f"recover {args.bag}: {exc}") from exc
    print(report)
    if not report.messages.get(TOPIC_PRESSURE):
        raise CliError(f"recover {args.bag}: no pressure sample ({TOPIC_PRESSURE}) is left in "
                       "the bag: there is nothing to analyse")
    return 0


# --------------------------------------------------------------------------- discrepancy
def _progress_printer(args: argparse.Namespace, path: str, n_paths: int
                      ) -> Callable[[str], None] | None:
    """Progress lines to stderr (--progress, or stderr a terminal), else None."""
    on = args.progress if args.progress is not None else sys.stderr.isatty()
    if not on:
        return None
    prefix = f"{Path(path).name}: " if n_paths > 1 else ""

    def say(msg: str) -> None:
        print(prefix + msg, file=sys.stderr, flush=True)

    return say


def cmd_discrepancy(args: argparse.Namespace) -> int:
    """Name the effect the discharge model misses, with evidence (one or several runs)."""
    from pneumatic_unload.discrepancy.multirun import fit_geometry_law
    from pneumatic_unload.discrepancy.report import write_law_report, write_report
    from pneumatic_unload.discrepancy.workflow import find_discrepancy

    lds = args.length_diameter_ratio or [None]
    if len(lds) not in (1, len(args.paths)):
        raise CliError("give one --length-diameter-ratio for all runs or one per PATH")
    own = adapters.given_options(args, DiscrepancySettings, exclude=TANK_FIELDS)
    results, names, settings = [], [], []
    for i, path in enumerate(args.paths):
        ns = argparse.Namespace(**vars(args))
        ns.path = path
        ns.length_diameter_ratio = lds[i] if len(lds) > 1 else lds[0]
        t, p, cfg = load_trace(ns)
        cfg.pop("estimator_settings", None)  # the tank and gas only: the fit is its own
        try:
            tank = settings_from(ns, cfg).tank
            # an L/D neither given nor in the recording is a guess (the default)
            known = ns.length_diameter_ratio is not None or \
                "length_diameter_ratio" in TankSpec.fields_of(cfg)
            ds = DiscrepancySettings(**tank.tank_fields(), **own,
                                     length_diameter_known=known)
            res = find_discrepancy(t, p, ds, temperature=measured_temperature(
                ns.path, **csv_options(ns)),
                                   progress=_progress_printer(args, path, len(args.paths)))
        except DiscrepancyError as exc:
            raise CliError(f"{path}: {exc}") from exc
        results.append(res)
        names.append(Path(path).name)
        settings.append(ds)
    law = None
    if len(results) > 1:
        try:
            law = fit_geometry_law([s.length_diameter_ratio for s in settings],
                                   [r.conductance for r in results],
                                   [r.conductance_std() for r in results])
        except DiscrepancyError as exc:
            raise CliError(str(exc)) from exc
    if args.report:
        out = Path(args.report)
        for name, res in zip(names, results, strict=True):
            write_report(res, out if len(results) == 1 else out / Path(name).stem,
                         title=name)
        if law is not None:
            write_law_report(law, out, names)
    if args.json:
        docs = [dict(res.to_dict(), source=str(p)) for res, p in
                zip(results, args.paths, strict=True)]
        out_json: dict[str, Any] = docs[0] if len(docs) == 1 else {
            "runs": docs, "geometry_law": law.to_dict() if law else None}
        print(json.dumps(out_json, indent=2, allow_nan=False, default=json_default))
    else:
        for name, res in zip(names, results, strict=True):
            print(f"{name}: {res.verdict}")
            for k, v in res.parameters.items():
                print(f"  {k} = {v.value:.5g} {v.unit}  {v.describe()}")
            print(f"  noise sigma = {res.noise.sigma:.4g} Pa, rho = {res.noise.rho:.3f}")
        if law is not None:
            print(f"geometry law: {law.reason}")
        if args.report:
            print(f"report written to {args.report}")
    return 0


def add_discrepancy_parser(sub: Any) -> None:
    """The ``discrepancy`` sub-command (input options as ``analyze``)."""
    dc = sub.add_parser(
        "discrepancy",
        help="name the effect the model misses, with evidence (a discharge or a charge)",
        description="Name the effect the model misses, with evidence (a discharge; a "
                    "charge with --direction charge). Time "
                    "bound: every run ends; its work is bounded in model evaluations (at "
                    "most 3 greedy rounds of at most 12 candidates, at most 10 starts "
                    "each, capped Levenberg-Marquardt iterations, an integrator step "
                    "budget per evaluation), and in seconds by --time-limit (default 600 "
                    "s): past it the fit under way stops; in the baseline or the first "
                    "round that is an error (exit 2, no verdict), later the effects named "
                    "so far are reported with linear intervals and a note. A 10 s record "
                    "at 1 kHz takes a few seconds.")
    dc.add_argument("paths", nargs="+", metavar="PATH",
                    help="rosbag2 directory, .mcap file or .csv log (several: one shared "
                         "geometry law of C)")
    adapters.add_options(dc, TankSpec, exclude=("length_diameter_ratio",))
    dc.add_argument("--length-diameter-ratio", nargs="+",
                    type=adapters.option_type(adapters.field_of(TankSpec,
                                                                "length_diameter_ratio")),
                    help="tank L/D [-], one for all runs or one per PATH; not given "
                         "(and not in the recording): the natural heat law is also fitted "
                         "at L/D 1 to 7.6, an L/D the data cannot rule out widens the C "
                         "range, and stating it is advised")
    adapters.add_options(dc, DiscrepancySettings,
                         only=("fit_wall_temperature", "profile", "bic_threshold",
                               "resolution", "candidates", "time_limit",
                               "model_uncertainty", "direction", "supply_pressure",
                               "supply_temperature", "start_time"))
    dc.add_argument("--max-effects", type=int, default=None, choices=(1, 2, 3),
                    help="add at most this many effects (greedy), default 3")
    add_input_options(dc)
    dc.add_argument("--report", metavar="DIR",
                    help="write report.md (with PNG plots beside it) and report.html (one "
                         "self-contained page, plots inside) into DIR")
    dc.add_argument("--progress", default=None, action=argparse.BooleanOptionalAction,
                    help="one line per step on stderr (baseline, each candidate, "
                         "intervals); default: on when stderr is a terminal")
    dc.set_defaults(func=cmd_discrepancy)


# --------------------------------------------------------------------------- parser
def add_config_options(parser: argparse.ArgumentParser) -> None:
    """One option per :class:`RigConfig` field (name with dashes), with unit and range."""
    adapters.add_options(parser, RigConfig)


def config_from_args(args: argparse.Namespace) -> RigConfig:
    """RigConfig from the options of :func:`add_config_options` (unset: defaults)."""
    return RigConfig(**adapters.given_options(args, RigConfig))


def add_input_options(parser: argparse.ArgumentParser) -> None:
    """Options that say how to read the input (bag topic, CSV columns and units)."""
    parser.add_argument("--atmosphere-auto", action="store_true",
                        help="take p_atm from the final plateau (as --atmosphere 0 would not: "
                             "0 is a value)")
    parser.add_argument("--topic", default="/tank/pressure", help="pressure topic of a bag")
    parser.add_argument("--time-column", help="CSV time column (default: by its name, e.g. "
                        "'Time [s]', 'Timestamp'): numbers, epoch s or ms, ISO 8601 date-times, "
                        "a date and a time of day")
    parser.add_argument("--pressure-column", help="CSV pressure column (default: by its name, "
                        "e.g. 'P_Tank [bar]', 'p_tank', 'Druck (bar)')")
    parser.add_argument("--temperature-column",
                        help="CSV gas-temperature column (default: found by its name, e.g. "
                             "'Temp [C]', 'gas_temperature_c'; its value at the unload start "
                             "is T10)")
    parser.add_argument("--pressure-unit", choices=tuple(PRESSURE_UNITS), default=None,
                        type=unit_spelling(PRESSURE_UNITS),
                        help="CSV pressure unit (default: from the header, else Pa)")
    parser.add_argument("--time-unit", choices=tuple(TIME_UNITS), default=None,
                        type=unit_spelling(TIME_UNITS),
                        help="CSV time unit (default: from the header; epoch stamps by "
                             "their magnitude; else s)")
    parser.add_argument("--temperature-unit", choices=tuple(TEMPERATURE_UNITS), default=None,
                        type=unit_spelling(TEMPERATURE_UNITS),
                        help="CSV gas-temperature unit (default: from the header, else C)")
    parser.add_argument("--gauge", action="store_true",
                        help="CSV pressures are gauge: add --atmosphere to every reading")
    parser.add_argument("--json", action="store_true", help="print a JSON object")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pneumatic-unload``."""
    ap = ArgumentParser(
        prog="pneumatic-unload",
        description="Sonic conductance of pneumatic components from tank discharges "
                    "(unloading-time method with model-based bias correction).")
    sub = ap.add_subparsers(dest="command", required=True)

    an = sub.add_parser(
        "analyze", help="estimate C, b and tau_exp from a bag or a CSV log",
        epilog="exit status: " + "; ".join(f"{k}: {v}" for k, v in EXIT_STATUS.items()))
    an.add_argument("path", help="rosbag2 directory, .mcap file or .csv log")
    adapters.add_options(an, EstimatorSettings)
    add_input_options(an)
    an.add_argument("--plot", metavar="FILE.png", help="write a plot of the analysis")
    an.set_defaults(func=cmd_analyze)

    si = sub.add_parser("simulate", help="write a simulated run as a rosbag2/MCAP bag")
    si.add_argument("--out", required=True, help="bag directory to create")
    si.add_argument("--no-estimate", action="store_true",
                    help="do not record the estimator's results in the bag")
    si.add_argument("--json", action="store_true", help="print a JSON summary")
    add_config_options(si)
    si.set_defaults(func=cmd_simulate)

    rc = sub.add_parser("recover", help="repair a bag whose writer was killed")
    rc.add_argument("bag", help="bag directory")
    rc.set_defaults(func=cmd_recover)

    add_discrepancy_parser(sub)
    batch_cli.add_parsers(sub, add_input_options)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pneumatic-unload``; returns the exit status."""
    ap = build_parser()
    args, extra = ap.parse_known_args(argv)
    if extra:
        sub = ap._subparsers._group_actions[0].choices if ap._subparsers else {}
        ap_cmd = sub.get(getattr(args, "command", None), ap)
        ap_cmd.error(unrecognized_message(ap_cmd, extra))
    try:
        return int(args.func(args))
    except (CliError, batch_cli.BatchCliError) as exc:
        print(f"pneumatic-unload: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
