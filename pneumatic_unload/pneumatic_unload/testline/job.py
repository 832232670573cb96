# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""One input of a batch: read it, analyse it, judge it against the part's specification.

:func:`analyze_file` is what a batch worker runs (a plain function of picklable values,
so it runs the same in this process or on any Dask worker): it never raises for a bad
input; an unreadable file or one without an estimate is a :class:`~.db.FileRecord` with
the reason. SI units: m^3/(s Pa), s, Pa.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneumatic_unload import __version__
from pneumatic_unload.analysis.output import finite_or_none, unload_json
from pneumatic_unload.analysis.records import RecordError, analyze_input, open_record
from pneumatic_unload.config import ConfigError, TankSpec, adapters
from pneumatic_unload.config.estimator import EstimationError, EstimatorSettings
from pneumatic_unload.estimation.types import ESTIMATE_STATUSES
from pneumatic_unload.testline.db import FileRecord
from pneumatic_unload.testline.spec import Spec


@dataclass(frozen=True)
class InputOptions:
    """How a batch reads and analyses its inputs (the same for every file).

    Attributes
    ----------
    settings : dict
        Estimator settings given for every input [SI]: a CSV log's (it needs at least
        ``volume``); a bag's own recorded value wins over one of these unless
        ``override`` (see :func:`settings_given`).
    csv : dict
        CSV reading options (columns, units, gauge, atmosphere [Pa]) of
        :func:`~pneumatic_unload.analysis.records.open_record`.
    topic : str
        Pressure topic of a bag.
    part_regex : str
        Regular expression on the file's path whose first group (or whole match) is the
        part id; '' takes the file name without its suffix.
    spec : Spec or None
        Specification the unloads are judged against (and per-file settings, which win
        over a bag's recorded ones).
    override : bool
        ``settings`` win over the values a bag records (``--override``).
    """

    settings: dict[str, Any] = field(default_factory=dict)
    csv: dict[str, Any] = field(default_factory=dict)
    topic: str = "/tank/pressure"
    part_regex: str = ""
    spec: Spec | None = None
    override: bool = False


def content_hash(path: str | Path) -> str:
    """SHA-256 of an input's bytes (a bag directory: of its files' names and bytes) [hex].

    Raises
    ------
    OSError
        The input cannot be read.
    """
    p = Path(path)
    h = hashlib.sha256()
    files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    for q in files:
        if p.is_dir():
            h.update(str(q.relative_to(p)).encode() + b"\0")
        with q.open("rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
    return h.hexdigest()


def part_id(path: str | Path, regex: str = "") -> str:
    """The part an input measured: ``regex``'s first group (or whole match) on the path,
    else the file name without its suffix."""
    p = Path(path)
    if regex:
        m = re.search(regex, str(p))
        if m:
            return m.group(1) if m.groups() and m.group(1) is not None else m.group(0)
    return p.name[: -len(p.suffix)] if p.suffix and not p.is_dir() else p.name


def options_hash(options: InputOptions) -> str:
    """SHA-256 of what, besides an input's bytes, makes its numbers: the settings and
    reading options given, the specification and the package version (new code: new
    numbers) [hex]. A batch skips an input whose content and options hashes are in the
    database."""
    spec = options.spec.to_dict() if options.spec is not None else None
    blob = json.dumps({"settings": options.settings, "csv": options.csv,
                       "topic": options.topic, "part_regex": options.part_regex,
                       "spec": spec, "version": __version__,
                       **({"override": True} if options.override else {})},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


def recorded_settings(cfg: dict[str, Any]) -> dict[str, Any]:
    """The estimator settings an input records [SI]: a bag's live estimator settings when
    it has them, else its rig configuration's tank and gas (see
    :func:`~pneumatic_unload.analysis.records.settings_for`); a CSV log: none."""
    live = cfg.get("estimator_settings")
    if isinstance(live, dict):
        return adapters.from_mapping(EstimatorSettings, live, strict=False)
    return TankSpec.fields_of(cfg)


def _same(a: Any, b: Any) -> bool:
    """Equal settings values (numbers to a relative 1e-9: a unit conversion's rounding)."""
    if isinstance(a, bool) or isinstance(b, bool) or not (
            isinstance(a, int | float) and isinstance(b, int | float)):
        return bool(a == b)
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=0.0)


def _shown(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def settings_given(cfg: dict[str, Any], options: InputOptions, path: str
                   ) -> tuple[dict[str, Any], list[str]]:
    """The settings to apply over what the input records, and a note per setting where a
    given value meets another recorded one.

    The bag's recorded value wins over the command line's (``options.settings``) unless
    ``options.override``; the specification's per-file settings for ``path`` win over
    both. A note names the setting, both values and which one was used.
    """
    recorded = recorded_settings(cfg)
    per_file = options.spec.file_settings(path) if options.spec is not None else {}
    given = {**options.settings, **per_file}
    notes: list[str] = []
    for k in sorted(given):
        if k not in recorded or _same(recorded[k], given[k]):
            continue
        mine, theirs = _shown(given[k]), _shown(recorded[k])
        if k in per_file:
            notes.append(f"{k}: the specification's files entry {mine} used over the "
                         f"bag's {theirs}")
        elif options.override:
            notes.append(f"{k}: the command line's {mine} used over the bag's {theirs} "
                         "(--override)")
        else:
            notes.append(f"{k}: the bag's {theirs} used, not the command line's {mine} "
                         "(--override uses the command line's)")
            del given[k]
    return given, notes


def settings_json(s: EstimatorSettings) -> dict[str, Any]:
    """The settings as JSON-ready values (SI; non-finite as None)."""
    return finite_or_none(dataclasses.asdict(s))


def result_row(r: Any) -> dict[str, Any]:
    """A result as a row of the results database: its JSON (:func:`~pneumatic_unload.
    output.unload_json`) with the recommended C and its standard uncertainty as columns
    [m^3/(s Pa)]."""
    u = unload_json(r)
    u["recommended_conductance"] = u["recommended"]["conductance"]
    u["recommended_std"] = u["recommended"]["std"]
    return u


#: Points of the pressure curve kept with each unload for the report [-].
CURVE_POINTS = 200


def unload_curve(t: Any, p: Any, t_start: float, t_end: float) -> dict[str, list[float]]:
    """The unload's pressure curve for the report: at most :data:`CURVE_POINTS` samples
    from 10 % of the unload's length before its start to its end; times relative to the
    start [s], pressures [Pa absolute] (empty when unknown)."""
    import numpy as np

    if not (math.isfinite(t_start) and math.isfinite(t_end) and t_end > t_start):
        return {"t": [], "p": []}
    lo = t_start - 0.1 * (t_end - t_start)
    k = np.flatnonzero((t >= lo) & (t <= t_end))
    if k.size > CURVE_POINTS:
        k = k[np.linspace(0, k.size - 1, CURVE_POINTS).astype(int)]
    return {"t": [round(float(x - t_start), 6) for x in t[k]],
            "p": [round(float(x), 1) for x in p[k]]}


def no_estimate(unloads: list[dict[str, Any]]) -> str:
    """Why a record whose unloads were found gives no C ('' when one does)."""
    if any(u["status"] in ESTIMATE_STATUSES and u["recommended"]["conductance"] is not None
           for u in unloads):
        return ""
    return "; ".join(f"unload {k}: {u['status']}: {u['status_text']}"
                     for k, u in enumerate(unloads)) or "no unload"


def analyze_file(path: str, options: InputOptions, chash: str | None = None
                 ) -> FileRecord:
    """Analyse one input (a bag or a CSV log) as ``pneumatic-unload analyze`` does, and
    judge its unloads against the specification of its part type.

    Never raises for a bad input: the record's ``status`` is 'error' (unreadable, invalid
    settings: ``reason`` says which; an unexpected exception: its type and message) or
    'no_estimate' (``reason`` says why), so that one bad input is one row of a batch.

    Parameters
    ----------
    path : str
        The input.
    options : InputOptions
        Reading, settings, part id and specification.
    chash : str, optional
        The input's :func:`content_hash` when the caller has it.
    """
    pid = part_id(path, options.part_regex)
    ptype = options.spec.part_type(pid) if options.spec is not None else ""
    shash = options_hash(options)
    base = {"path": str(path), "part_id": pid, "part_type": ptype or "",
            "package_version": __version__, "settings_hash": shash}
    try:
        return _analyze_file(path, options, chash, pid, base)
    except Exception as exc:  # a fault of this input's analysis: its row says which
        return FileRecord(content_hash=chash or f"failed:{path}", status="error",
                          reason=f"{path}: the analysis failed: {type(exc).__name__}: "
                                 f"{exc}", **base)


def _analyze_file(path: str, options: InputOptions, chash: str | None, pid: str,
                  base: dict[str, Any]) -> FileRecord:
    """:func:`analyze_file`'s work (which turns what it raises into an error row)."""
    if chash is None:
        try:
            chash = content_hash(path)
        except OSError as exc:
            return FileRecord(content_hash=f"unreadable:{path}", status="error",
                              reason=f"{path}: {exc}", **base)
    notes: list[str] = []
    try:
        rec = open_record(path, topic=options.topic, **options.csv)
        given, notes = settings_given(rec.cfg, options, str(path))
        ana = analyze_input(rec, given)
    except (RecordError, EstimationError, ConfigError) as exc:
        return FileRecord(content_hash=chash, status="error", reason=str(exc),
                          settings_notes="; ".join(notes), **base)
    sj = settings_json(ana.settings)
    run, results, problem = ana.run, ana.unloads, ana.input_problem
    unloads = [result_row(r) for r in results]
    t_all, p_all = run.overview.arrays()
    for u, r in zip(unloads, results, strict=True):
        u["curve"] = unload_curve(t_all, p_all, r.t_start, r.t_end if math.isfinite(r.t_end)
                                  else r.t_start + 4.0 * r.tau_exp)
    for u in unloads:
        verdict = options.spec.judge(pid, u) if options.spec is not None else None
        u["verdict"], u["verdict_reason"] = verdict if verdict is not None else (None, None)
    if ana.no_unload is not None:
        status, reason = "no_estimate", ana.no_unload
    elif problem is not None:
        status, reason = "no_estimate", problem
    else:
        reason = no_estimate(unloads)
        status = "no_estimate" if reason else "ok"
    return FileRecord(content_hash=chash, status=status, reason=reason, unloads=unloads,
                      settings=sj, settings_notes="; ".join(notes), **base)


def analyze_chunk(items: Sequence[tuple[int, str]], options: InputOptions,
                  known: frozenset[str] = frozenset(), force: bool = False
                  ) -> list[tuple[int, FileRecord | None]]:
    """A batch's job on some inputs (k, path): each hashed where it is read (on the worker,
    not on the batch's client) and analysed with :func:`analyze_file`, unless its content
    hash is in ``known`` (analysed before with these options) and not ``force``: then
    (k, None). Never raises for a bad input (see :func:`analyze_file`)."""
    out: list[tuple[int, FileRecord | None]] = []
    for k, path in items:
        try:
            chash: str | None = content_hash(path)
        except OSError:
            chash = None  # analyze_file reports it as an unreadable input
        if chash is not None and chash in known and not force:
            out.append((k, None))
        else:
            out.append((k, analyze_file(path, options, chash)))
    return out
