# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The test-line commands of ``pneumatic-unload``: ``batch`` and ``results``.

batch PATH...        analyse many bags and CSV logs (on Dask), keep every result in the
                     results database, one row per unload and one per part, pass/fail
                     against a specification
results export       the database's unloads (or parts) as CSV or Parquet
results parts        the parts table of the database
report               one self-contained HTML page of the database for a quality engineer

Exit status of ``batch``: 0 when every input gave a C and no part failed its
specification; 1 when an input gave no C or a part failed (each row says why); 2 on bad
options, an unusable database or scheduler; 130 when interrupted (Ctrl-C: what was done is
kept, a rerun continues). SI units (C in m^3/(s Pa); the text tables also in dm^3/(s bar)).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pneumatic_unload.config import ConfigError, adapters
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings

if TYPE_CHECKING:
    from pneumatic_unload.testline import InputOptions

# The test line (pneumatic_unload.testline: Dask, SQLAlchemy, the report) is imported by the
# commands that use it, not with this module: the CLI builds these parsers for every
# command, and SQLAlchemy alone took 0.11 s of the 0.74 s of ``analyze BAG --json`` (bench
# 1 of bench/bench_engine.py, whose target is half the time of a raw iteration of the bag).

CSV_OPTIONS = ("time_column", "pressure_column", "temperature_column", "pressure_unit",
               "time_unit", "temperature_unit")


#: --db of the reading commands.
DB_HELP = ("results database: a SQLite file, or a PostgreSQL server's "
           "postgresql://USER@HOST:PORT/DB (password: PGPASSWORD or ~/.pgpass)")


class BatchCliError(Exception):
    """Bad options of a test-line command (exit status 2)."""


def _settings_file(path: str) -> dict[str, Any]:
    from pneumatic_unload.testline.spec import SpecError, read_file_data

    try:
        data = read_file_data(path)
    except SpecError as exc:  # unreadable or not YAML/JSON: one line, no traceback
        raise BatchCliError(f"--settings {exc}") from exc
    if not isinstance(data, dict):
        raise BatchCliError(f"--settings {path}: expected a mapping of estimator settings")
    try:
        return adapters.from_mapping(EstimatorSettings, data)
    except (ConfigError, EstimationError, TypeError) as exc:
        raise BatchCliError(f"--settings {path}: {exc}") from exc


def options_from(args: argparse.Namespace) -> InputOptions:
    """The batch's :class:`InputOptions` from its command line."""
    from pneumatic_unload.testline import InputOptions, SpecError, load_spec

    settings = _settings_file(args.settings) if args.settings else {}
    settings.update(adapters.given_options(args, EstimatorSettings))
    barometer = settings.get("atmosphere")
    try:
        zero = adapters.gauge_inputs(bool(args.gauge), barometer, bool(args.atmosphere_auto),
                                     settings)
    except ConfigError as exc:
        raise BatchCliError(str(exc)) from exc
    csv: dict[str, Any] = {k: getattr(args, k) for k in CSV_OPTIONS
                           if getattr(args, k) is not None}
    csv["hints"] = "cli"  # a CSV's error hints name the command line's options
    if zero is not None:
        csv["gauge"] = True
        csv["atmosphere"] = zero
    try:
        spec = load_spec(args.spec) if args.spec else None
    except SpecError as exc:
        raise BatchCliError(str(exc)) from exc
    return InputOptions(settings=settings, csv=csv, topic=args.topic,
                        part_regex=args.part_regex or "", spec=spec,
                        override=bool(getattr(args, "override", False)))


def _fmt_c(c: Any) -> str:
    """C [m^3/(s Pa)] in dm^3/(s bar), four significant digits; '-' when there is none."""
    from pneumatic_unload.analysis.output import c_dm3

    return "-" if c is None else c_dm3(c)


def _fmt_s(s: Any) -> str:
    """A standard deviation of C [m^3/(s Pa)] in dm^3/(s bar), two significant digits."""
    from pneumatic_unload.analysis.output import DM3_PER_S_BAR, two_digits

    return "-" if s is None else two_digits(s / DM3_PER_S_BAR)


def parts_text(parts: list[dict[str, Any]]) -> str:
    """The parts table as text (C in dm^3/(s bar))."""
    lines = [f"{'part':24s} {'type':14s} {'n':>3s} {'C mean':>9s} {'s(C)':>9s} verdict",
             f"{'':24s} {'':14s} {'':3s} {'dm3/(s bar)':>9s} {'':>9s}"]
    for p in parts:
        v = p["verdict"] or "-"
        why = f" ({p['verdict_reason']})" if p["verdict"] == "fail" else ""
        lines.append(f"{p['part_id'][:24]:24s} {p['part_type'][:14]:14s} {p['n']:3d} "
                     f"{_fmt_c(p['conductance_mean']):>9s} "
                     f"{_fmt_s(p['conductance_std']):>9s} {v}{why}")
    return "\n".join(lines)


def cmd_batch(args: argparse.Namespace) -> int:
    """Run a batch (see the module doc); prints the parts table or JSON."""
    from pneumatic_unload.analysis.output import json_default
    from pneumatic_unload.testline import (
        BatchError,
        ResultsDBError,
        discover,
        open_db,
        part_summary,
        progress_bar,
        run_batch,
        unload_rows,
        write_table,
    )
    from pneumatic_unload.testline.batch import PART_COLUMNS
    from pneumatic_unload.testline.db import EXPORT_COLUMNS, file_rows, hide_password

    options = options_from(args)
    try:
        paths = discover(args.paths, args.glob or "")
    except BatchError as exc:
        raise BatchCliError(str(exc)) from exc
    if not paths:
        raise BatchCliError("no inputs found (bags, .mcap, .csv, .txt) under "
                            + ", ".join(args.paths))
    bar = progress_bar(len(paths), True if args.progress else None)
    try:
        res = run_batch(paths, options, db_path=args.db, workers=args.workers,
                        scheduler=args.scheduler or "", force=args.force,
                        on_done=lambda _r: bar.update(1))
    except (BatchError, ResultsDBError) as exc:
        raise BatchCliError(str(exc)) from exc
    finally:
        bar.close()
    try:
        with open_db(args.db) as con:
            rows = unload_rows(con)
            frows = file_rows(con)
    except ResultsDBError as exc:
        raise BatchCliError(str(exc)) from exc
    mine = {r.content_hash for r in res.records}
    this = [u for u in rows if u["content_hash"] in mine or u["path"] in res.skipped]
    files = [f for f in frows if f["content_hash"] in mine or f["path"] in res.skipped]
    parts = part_summary(this, files)
    if args.out:
        write_table(this, Path(args.out), EXPORT_COLUMNS)
        stem = Path(args.out)
        write_table(parts, stem.with_name(f"{stem.stem}_parts{stem.suffix}"), PART_COLUMNS)
    failed = [r for r in res.records if r.status != "ok"]
    if args.json:
        out = {"db": hide_password(args.db), "inputs": len(paths), "analysed": len(res.records),
               "skipped": res.skipped, "interrupted": res.interrupted,
               "workers": res.workers,
               "files": [{"path": r.path, "part_id": r.part_id, "status": r.status,
                          "reason": r.reason, "n_unloads": len(r.unloads),
                          "settings_notes": r.settings_notes}
                         for r in res.records],
               "parts": parts}
        print(json.dumps(out, indent=2, allow_nan=False, default=json_default))
    else:
        print(f"{len(paths)} input(s): {len(res.records)} analysed, {len(res.skipped)} "
              f"already in {hide_password(args.db)}" + (", interrupted" if res.interrupted else ""))
        for r in failed:
            print(f"  {r.path}: {r.status}: {r.reason}")
        for r in res.records:
            if r.settings_notes:
                print(f"  {r.path}: settings: {r.settings_notes}")
        print(parts_text(parts))
    for r in failed:
        print(f"pneumatic-unload: {r.path}: {r.status}: {r.reason}", file=sys.stderr)
    if res.interrupted:
        print("pneumatic-unload: interrupted: the inputs done are in the database; run the "
              "same command again to continue", file=sys.stderr)
        return 130
    return 1 if failed or any(p["verdict"] == "fail" for p in parts) else 0


def _existing_db(db: str) -> None:
    """A SQLite file that is not there is an error of a reading command (a server's URL
    is tried when opened)."""
    if "://" not in db and not Path(db).is_file():
        raise BatchCliError(f"--db {db}: no such database")


def cmd_results(args: argparse.Namespace) -> int:
    """``results export`` / ``results parts`` (see the module doc)."""
    from pneumatic_unload.analysis.output import json_default
    from pneumatic_unload.testline import (
        ResultsDBError,
        export,
        open_db,
        part_summary,
        unload_rows,
        write_table,
    )
    from pneumatic_unload.testline.batch import PART_COLUMNS
    from pneumatic_unload.testline.db import file_rows

    _existing_db(args.db)
    if args.action == "export" and not args.out:
        raise BatchCliError("results export needs --out FILE (.csv or .parquet)")
    try:
        con = open_db(args.db, create=False)
        try:
            rows = unload_rows(con)
            frows = file_rows(con)
            if args.action == "export":
                if args.parts:
                    write_table(part_summary(rows, frows), Path(args.out), PART_COLUMNS)
                    n = len({r["part_id"] for r in rows})
                else:
                    n = export(con, args.out)
                print(f"{n} row(s) written to {args.out}")
            else:
                parts = part_summary(rows, frows)
                if args.json:
                    print(json.dumps(parts, indent=2, allow_nan=False, default=json_default))
                else:
                    print(parts_text(parts))
        finally:
            con.close()
    except ResultsDBError as exc:
        raise BatchCliError(str(exc)) from exc
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """``report``: the database as one self-contained HTML page."""
    from pneumatic_unload.testline import ResultsDBError
    from pneumatic_unload.testline.report import html_report

    _existing_db(args.db)
    if not Path(args.out).parent.is_dir():
        raise BatchCliError(f"--out {args.out}: folder {Path(args.out).parent} does not exist")
    try:
        n = html_report(args.db, args.out, title=args.title or "")
    except (ResultsDBError, OSError) as exc:
        raise BatchCliError(str(exc)) from exc
    print(f"{args.out}: {n['parts']} part(s) ({n['failing_parts']} failing), "
          f"{n['unloads']} unload(s) from {n['files']} input(s)")
    return 0


def add_parsers(sub: Any, add_input_options: Callable[[argparse.ArgumentParser], None]
                ) -> None:
    """Add ``batch`` and ``results`` to the subcommands ``sub`` (``add_input_options``:
    the CLI's reading options, shared with ``analyze``)."""
    ba = sub.add_parser("batch", help="analyse many bags and CSV logs into the results "
                                      "database (Dask), pass/fail against a specification",
                        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ba.add_argument("paths", nargs="+", metavar="PATH",
                    help="bags (folders or .mcap), CSV logs, or folders searched for them")
    ba.add_argument("--glob", help="pattern of the inputs inside each folder given "
                                   "(e.g. '*/run*.mcap'; default: every bag and log below)")
    ba.add_argument("--db", default="results.sqlite", metavar="FILE|URL",
                    help="results database: a SQLite file (created when missing) or a "
                         "PostgreSQL server's postgresql://USER@HOST:PORT/DB")
    ba.add_argument("--out", metavar="FILE", help="also write the unloads of this batch "
                    "(.csv or .parquet) and its parts to FILE_parts")
    ba.add_argument("--spec", metavar="YAML", help="specification of the part types")
    ba.add_argument("--settings", metavar="YAML",
                    help="estimator settings for inputs that carry none (CSV logs): "
                         "volume, initial_temperature, ... [SI]")
    ba.add_argument("--override", action="store_true",
                    help="the settings given (options, --settings) win over the values a "
                         "bag records (default: the bag's win, and the output says where "
                         "they differ)")
    ba.add_argument("--part-regex", metavar="REGEX",
                    help="part id: the first group of REGEX on each path (default: the "
                         "file name without its suffix)")
    ba.add_argument("--workers", type=int, default=2,
                    help="worker processes of a local Dask cluster (1: no Dask)")
    ba.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running dask.distributed scheduler (tcp://host:8786)")
    ba.add_argument("--force", action="store_true",
                    help="analyse inputs already in the database again (replacing them)")
    ba.add_argument("--progress", action="store_true",
                    help="progress bar on stderr even when it is not a terminal")
    adapters.add_options(ba, EstimatorSettings)
    add_input_options(ba)
    ba.set_defaults(func=cmd_batch)

    rs = sub.add_parser("results", help="the results database: export, parts table")
    rs.add_argument("action", choices=("export", "parts"))
    rs.add_argument("--db", default="results.sqlite", metavar="FILE|URL", help=DB_HELP)
    rs.add_argument("--out", metavar="FILE", help="export: .csv or .parquet")
    rs.add_argument("--parts", action="store_true", help="export the parts table instead")
    rs.add_argument("--json", action="store_true", help="parts: print JSON")
    rs.set_defaults(func=cmd_results)

    rp = sub.add_parser("report", help="the results database as one self-contained HTML page")
    rp.add_argument("--db", default="results.sqlite", metavar="FILE|URL", help=DB_HELP)
    rp.add_argument("--out", default="report.html", help="HTML file to write")
    rp.add_argument("--title", help="title of the page")
    rp.set_defaults(func=cmd_report)
