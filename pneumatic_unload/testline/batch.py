"""Batch analysis of many inputs on Dask, results kept in the results database.

:func:`run_batch` hashes each input, skips those already in the database with the same
content and options (unless ``force``), analyses the rest with
:func:`~.job.analyze_file` - in this process, on a local cluster of worker processes
(``dask.distributed.LocalCluster``, the default with ``workers`` > 1) or on a running
``dask.distributed`` scheduler (``scheduler`` address) - and writes each input's rows in
one transaction as it completes. The result lists the inputs in the order given, whatever
the number of workers or the order of completion: the numbers of an input do not depend on
where it ran. Ctrl-C (KeyboardInterrupt) stops the batch and keeps what was written.

:func:`part_summary` gives one row per part: the mean recommended C, the repeatability
standard deviation of its unloads and their number, and the verdict against the
specification. SI units: m^3/(s Pa).
"""

from __future__ import annotations

import math
import statistics
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneumatic_unload.testline.db import FileRecord, has_file, open_db, write_file
from pneumatic_unload.testline.job import InputOptions, analyze_file, content_hash, options_hash

#: Suffixes of the inputs a batch picks up in a folder (plus bag folders).
INPUT_SUFFIXES = (".mcap", ".csv", ".txt")


class BatchError(Exception):
    """A batch that cannot start (a one-line message): no inputs, no scheduler."""


@dataclass
class BatchResult:
    """What a batch did.

    Attributes
    ----------
    records : list of FileRecord
        The inputs analysed now, in the order given.
    skipped : list of str
        Inputs already in the database with the same content and options.
    interrupted : bool
        The batch was stopped (Ctrl-C); what was written stays.
    workers : int
        Worker processes used (0: this process).
    """

    records: list[FileRecord] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    interrupted: bool = False
    workers: int = 0


def is_bag_dir(p: Path) -> bool:
    """True for a rosbag2 folder (a metadata.yaml or an .mcap file in it)."""
    return p.is_dir() and ((p / "metadata.yaml").exists() or any(p.glob("*.mcap")))


def discover(paths: Sequence[str | Path], pattern: str = "") -> list[str]:
    """The inputs of a batch, sorted within each folder given, duplicates removed.

    A file is taken as given; a bag folder is one input; another folder is searched
    (recursively, or by the glob ``pattern`` relative to it) for bag folders and files
    with a suffix of :data:`INPUT_SUFFIXES` (an .mcap inside a bag folder belongs to the
    bag).

    Raises
    ------
    BatchError
        A path that does not exist.
    """
    out: list[str] = []
    for raw in paths:
        p = Path(raw)
        if not p.exists():
            raise BatchError(f"{p}: no such file or directory")
        if p.is_file() or is_bag_dir(p):
            out.append(str(p))
            continue
        found: list[Path] = []
        cands = sorted(p.glob(pattern) if pattern else p.rglob("*"))
        bags = [c for c in cands if is_bag_dir(c)]
        for c in cands:
            if any(b in c.parents for b in bags):
                continue  # a bag folder's own files
            if c in bags or (c.is_file() and c.suffix.lower() in INPUT_SUFFIXES):
                found.append(c)
        out += [str(c) for c in found]
    return list(dict.fromkeys(out))


def _client(workers: int, scheduler: str) -> tuple[Any, Any]:
    from distributed import Client, LocalCluster  # local: distributed costs ~1 s to import

    if scheduler:
        try:
            return Client(scheduler, timeout=30), None
        except OSError as exc:
            raise BatchError(f"no Dask scheduler at {scheduler}: {exc}") from exc
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=40)
    return Client(cluster), cluster


def run_batch(paths: Sequence[str], options: InputOptions, *, db_path: str | Path,
              workers: int = 1, scheduler: str = "", force: bool = False,
              on_done: Callable[[FileRecord], None] | None = None) -> BatchResult:
    """Analyse ``paths`` and write them to the results database (see the module doc).

    Parameters
    ----------
    paths : sequence of str
        Inputs (files or bag folders; see :func:`discover`).
    options : InputOptions
        Reading, settings, part id and specification, the same for every input.
    db_path : str or Path
        The results database (created when missing).
    workers : int
        Worker processes of a local cluster; 1 (or 0): this process, no Dask.
    scheduler : str
        Address of a running ``dask.distributed`` scheduler (overrides ``workers``).
    force : bool
        Analyse and replace inputs already in the database.
    on_done : callable, optional
        Called with each input's record as it is written (a progress bar).

    Raises
    ------
    BatchError, ResultsDBError
        No inputs; the database or the scheduler cannot be used.
    """
    if not paths:
        raise BatchError("no inputs to analyse")
    con = open_db(db_path)
    ohash = options_hash(options)
    todo: list[tuple[int, str, str | None]] = []
    res = BatchResult()
    for k, path in enumerate(paths):
        try:
            chash: str | None = content_hash(path)
        except OSError:
            chash = None  # the job reports it as an unreadable input
        if chash is not None and not force and has_file(con, chash, ohash):
            res.skipped.append(path)
            continue
        todo.append((k, path, chash))
    done: dict[int, FileRecord] = {}

    def keep(k: int, rec: FileRecord) -> None:
        write_file(con, rec, replace=force)
        done[k] = rec
        if on_done is not None:
            on_done(rec)

    try:
        if (workers <= 1 and not scheduler) or not todo:
            for k, path, chash in todo:
                keep(k, analyze_file(path, options, chash))
        else:
            from distributed import as_completed

            client, cluster = _client(workers, scheduler)
            res.workers = len(client.scheduler_info().get("workers", {}))
            try:
                futs = {client.submit(analyze_file, path, options, chash, pure=False,
                                      key=f"analyze-{k}-{ohash[:8]}-{chash or k}"): k
                        for k, path, chash in todo}
                for fut in as_completed(futs):
                    k = futs[fut]
                    try:
                        rec = fut.result()
                    except Exception as exc:  # a worker died: the input's row says so
                        rec = FileRecord(path=todo_path(todo, k), content_hash=f"failed:{k}",
                                         settings_hash=ohash, part_id="", status="error",
                                         reason=f"worker failed: {type(exc).__name__}: {exc}")
                    keep(k, rec)
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    except KeyboardInterrupt:
        res.interrupted = True
    finally:
        con.close()
    res.records = [done[k] for k in sorted(done)]
    return res


def todo_path(todo: list[tuple[int, str, str | None]], k: int) -> str:
    """The path of job k of a batch's list."""
    return next(p for j, p, _h in todo if j == k)


PART_COLUMNS = ("part_id", "part_type", "n", "conductance_mean", "conductance_std",
                "conductance_min", "conductance_max", "verdict", "verdict_reason")


def part_summary(unloads: Sequence[dict[str, Any]],
                 files: Sequence[dict[str, Any]] = ()) -> list[dict[str, Any]]:
    """One row per part (in order of first appearance) from unload rows (each with
    part_id, part_type, recommended_conductance, verdict, verdict_reason): n, mean and
    repeatability standard deviation (n - 1) of the recommended C [m^3/(s Pa)], its range,
    and the verdict: 'pass' when every unload passes, 'fail' (with the unloads' reasons)
    otherwise, None without a specification. ``files`` (rows with part_id, part_type,
    status, reason, path): a part whose inputs gave no unload is a row with n = 0 and the
    inputs' reasons (a 'fail' when it has a part type)."""
    parts: dict[str, list[dict[str, Any]]] = {}
    for u in unloads:
        parts.setdefault(str(u["part_id"]), []).append(u)
    out = []
    for f in files:
        pid = str(f["part_id"])
        if pid in parts or any(o["part_id"] == pid for o in out):
            continue
        bad = [g for g in files if str(g["part_id"]) == pid]
        why = "; ".join(f"{g['path']}: {g['status']}: {g['reason']}" for g in bad)
        out.append({"part_id": pid, "part_type": f.get("part_type") or "", "n": 0,
                    "conductance_mean": None, "conductance_std": None,
                    "conductance_min": None, "conductance_max": None,
                    "verdict": "fail" if f.get("part_type") else None,
                    "verdict_reason": f"no unload: {why}"})
    for pid, us in parts.items():
        cs = [u["recommended_conductance"] for u in us
              if u.get("recommended_conductance") is not None
              and math.isfinite(u["recommended_conductance"])
              and u.get("status") in ("ok", "aborted_sse", "not_choked")]
        verdicts = [u.get("verdict") for u in us]
        if all(v is None for v in verdicts):
            verdict, why = None, None
        elif all(v == "pass" for v in verdicts):
            verdict, why = "pass", f"all {len(us)} unloads within specification"
        else:
            verdict = "fail"
            why = "; ".join(f"unload {k}: {u.get('verdict_reason')}"
                            for k, u in enumerate(us) if u.get("verdict") != "pass")
        out.append({"part_id": pid, "part_type": us[0].get("part_type") or "",
                    "n": len(cs),
                    "conductance_mean": statistics.fmean(cs) if cs else None,
                    "conductance_std": statistics.stdev(cs) if len(cs) > 1 else None,
                    "conductance_min": min(cs) if cs else None,
                    "conductance_max": max(cs) if cs else None,
                    "verdict": verdict, "verdict_reason": why})
    return out


def progress_bar(total: int, enabled: bool | None = None) -> Any:
    """A tqdm bar on stderr (rate and ETA) for ``total`` inputs; ``enabled`` None: only
    when stderr is a terminal."""
    from tqdm import tqdm

    if enabled is None:
        enabled = sys.stderr.isatty()
    return tqdm(total=total, unit="file", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True)
