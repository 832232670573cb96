# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Batch analysis of many inputs on Dask, results kept in the results database.

:func:`run_batch` reads the content hashes the database holds for these options (one
query), then runs :func:`~.job.analyze_chunk` on consecutive chunks of the inputs (large
first, shrinking towards the end) - in this process, on a local cluster of worker processes
(``dask.distributed.LocalCluster``, the default with ``workers`` > 1; one thread each, BLAS
pools of one thread, Dask's profiler off and its monitors slowed: :data:`CLUSTER_CONFIG`)
or on a running ``dask.distributed`` scheduler (``scheduler`` address): each input is
hashed where it is read, skipped when analysed before (unless ``force``), analysed
otherwise. The done inputs are written in the order given, many per transaction (each input
whole: a batch killed at any instant leaves whole inputs, and a rerun skips them), at least
every :data:`FLUSH_SECONDS`. The result lists the inputs in the order given, whatever the
number of workers or the order of completion: the numbers of an input do not depend on
where it ran. Ctrl-C (KeyboardInterrupt) stops the batch and writes what was done. The
result says where the CPU time went (:mod:`~.accounting`: the analysis, the workers' start
and housekeeping, this process's threads; the workers' idle time).

:func:`part_summary` gives one row per part: the mean recommended C, the repeatability
standard deviation of its unloads and their number, and the verdict against the
specification. SI units: m^3/(s Pa).
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneumatic_unload.estimation.types import ESTIMATE_STATUSES
from pneumatic_unload.testline.accounting import (
    Accounting,
    cpu_delta,
    thread_cpu,
    timed_chunk,
    worker_snapshot,
)
from pneumatic_unload.testline.db import (
    FileRecord,
    ResultsDBError,
    known_contents,
    open_db,
    write_files,
)
from pneumatic_unload.testline.job import InputOptions, options_hash

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
        Inputs already in the database with the same content and options (when the
        batch started, or written by another batch or bench while it ran).
    interrupted : bool
        The batch was stopped (Ctrl-C); what was written stays.
    workers : int
        Worker processes used (0: this process).
    cluster_seconds : float
        Time spent starting and closing the local cluster (or connecting to the
        scheduler) [s]; 0 in this process.
    worker_peak_rss : dict
        Peak resident memory of each worker process at the end of the batch [MiB].
    accounting : Accounting
        Where the batch's CPU time and the workers' idle time went [s].
    """

    records: list[FileRecord] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    interrupted: bool = False
    workers: int = 0
    cluster_seconds: float = 0.0
    worker_peak_rss: dict[str, float] = field(default_factory=dict)
    accounting: Accounting = field(default_factory=Accounting)


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
        bags = {c for c in cands if c.is_dir() and is_bag_dir(c)}
        for c in cands:
            if any(b in bags for b in c.parents):  # a set: linear in the inputs
                continue  # a bag folder's own files
            if c in bags or (c.is_file() and c.suffix.lower() in INPUT_SUFFIXES):
                found.append(c)
        out += [str(c) for c in found]
    return list(dict.fromkeys(out))


#: Environment of a local cluster's worker processes, set before they start (numpy's
#: BLAS and OpenMP pools: one thread per worker, which runs one task at a time).
WORKER_ENV = {"OMP_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1, "MKL_NUM_THREADS": 1}
#: Dask's default worker environment left out: a fixed malloc trim threshold (64 KiB) turns
#: off glibc's adaptive one, so that each large numpy array of an analysis is mapped and
#: unmapped again (about 8 times the page faults of a plain process).
NOT_IN_WORKER_ENV = ("MALLOC_TRIM_THRESHOLD_",)
#: Dask settings of a batch's own local cluster (not of a scheduler given by address): the
#: housekeeping of the scheduler, nannies and workers that takes CPU from the analysis on a
#: small machine, made rare. No statistical profiler (it samples the task thread's stack
#: every 10 ms on the worker's event loop, holding the GIL); the event-loop tick, the
#: system monitor and the memory monitors (worker, nanny) wake every second or so instead
#: of every 20-500 ms; no work stealing (the tasks wait on the scheduler until a worker is
#: free, so nothing is left to steal).
CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.system-monitor.disk": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing": False,
}
#: Most done inputs written in one database transaction [-] (one commit, one disk sync).
FLUSH_FILES = 64
#: Longest a done input waits to be written [s].
FLUSH_SECONDS = 1.0
#: A task takes at most 1 / (TASKS_PER_WORKER x workers) of the inputs left [-]: the inputs
#: of a task run one after the other on one worker (fewer scheduler round trips), and the
#: tasks shrink towards the end so that the last ones still balance.
TASKS_PER_WORKER = 4
#: Most inputs per task [-].
CHUNK_MAX = 16


def start_client(workers: int, scheduler: str) -> tuple[Any, Any]:
    """A Dask client of the scheduler at ``scheduler``, or of a new local cluster of
    ``workers`` processes (one thread each, :data:`WORKER_ENV`, :data:`CLUSTER_CONFIG`);
    returns (client, cluster or None).

    Raises
    ------
    BatchError
        No scheduler at that address.
    """
    import dask  # local: distributed costs ~1 s to import
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=30), None
        except OSError as exc:
            raise BatchError(f"no Dask scheduler at {scheduler}: {exc}") from exc
    env = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ", {}).items()
           if k not in NOT_IN_WORKER_ENV}
    env.update(WORKER_ENV)
    with dask.config.set({**CLUSTER_CONFIG, "distributed.nanny.pre-spawn-environ": env}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=40)
    return Client(cluster), cluster


def chunks(items: Sequence[tuple[int, str]], workers: int
           ) -> list[Sequence[tuple[int, str]]]:
    """The inputs cut into consecutive tasks, each at most 1 / (:data:`TASKS_PER_WORKER` x
    ``workers``) of the inputs left and at most :data:`CHUNK_MAX` inputs: large tasks
    first (fewer round trips), then smaller and smaller ones down to one input, so that
    the workers finish together (a short tail)."""
    out: list[Sequence[tuple[int, str]]] = []
    j, share = 0, max(1, workers * TASKS_PER_WORKER)
    while j < len(items):
        size = max(1, min(CHUNK_MAX, (len(items) - j) // share))
        out.append(items[j:j + size])
        j += size
    return out


class _Writer:
    """Done inputs written to the database in the order given, many per transaction: the
    first at once, then when :data:`FLUSH_FILES` are ready in order or
    :data:`FLUSH_SECONDS` have passed; the rest (in the order given) by :meth:`flush` with
    ``everything`` (the end, or Ctrl-C)."""

    def __init__(self, con: Any, n: int, replace: bool,
                 on_done: Callable[[FileRecord], None] | None) -> None:
        self.con, self.n, self.replace, self.on_done = con, n, replace, on_done
        self.ready: dict[int, FileRecord | None] = {}  # None: skipped
        self.pos = 0  # inputs before it are written (or skipped)
        self.written: dict[int, FileRecord] = {}
        self.skipped: set[int] = set()
        self.last = -math.inf  # the first input done is written at once

    def add(self, k: int, rec: FileRecord | None) -> None:
        self.ready[k] = rec
        if rec is None:
            self.skipped.add(k)
        elif self.on_done is not None:
            self.on_done(rec)
        in_order = 0
        while self.pos + in_order < self.n and self.pos + in_order in self.ready:
            in_order += 1
        if in_order >= FLUSH_FILES or time.monotonic() - self.last >= FLUSH_SECONDS:
            self.flush()

    def flush(self, everything: bool = False) -> None:
        ks: list[int] = []
        pos = self.pos
        while pos < self.n and pos in self.ready:
            ks.append(pos)
            pos += 1
        if everything:
            ks += sorted(k for k in self.ready if k >= pos)
        recs = [(k, r) for k in ks if (r := self.ready[k]) is not None]
        done = write_files(self.con, [r for _k, r in recs], replace=self.replace)
        for (k, rec), new in zip(recs, done, strict=True):  # state kept if interrupted
            if new:
                self.written[k] = rec
            else:  # written meanwhile by another batch or bench: there once, skipped here
                self.skipped.add(k)
        for k in ks:
            self.ready.pop(k)
        self.pos = pos
        self.last = time.monotonic()


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
        The results database: a SQLite file (created when missing) or a PostgreSQL URL
        (``postgresql://USER@HOST:PORT/DB``; see :mod:`~.schema`).
    workers : int
        Worker processes of a local cluster; 1 (or 0): this process, no Dask.
    scheduler : str
        Address of a running ``dask.distributed`` scheduler (overrides ``workers``).
    force : bool
        Analyse and replace inputs already in the database.
    on_done : callable, optional
        Called with each analysed input's record as it completes (a progress bar); it is
        written within :data:`FLUSH_SECONDS`.

    Raises
    ------
    BatchError, ResultsDBError
        No inputs; the database or the scheduler cannot be used.
    """
    if not paths:
        raise BatchError("no inputs to analyse")
    con = open_db(db_path)
    known = known_contents(con, options_hash(options)) if not force else frozenset()
    items = list(enumerate(paths))
    out = _Writer(con, len(items), force, on_done)
    res = BatchResult()
    acc = res.accounting
    cpu0 = thread_cpu()
    db_failed = False
    try:
        try:
            if workers <= 1 and not scheduler:
                acc.ready = time.time()
                for k, path in items:
                    done, stamp = timed_chunk([(k, path)], options, known, force)
                    acc.tasks.append(stamp)
                    for j, rec in done:
                        out.add(j, rec)
                acc.done = time.time()
                acc.client = cpu_delta(cpu0, thread_cpu())
            else:
                _on_dask(items, options, known, force, workers, scheduler, out.add, res)
        except ResultsDBError:
            db_failed = True  # the database's error stands; no second wait on it below
            raise
        finally:
            if not db_failed:
                out.flush(everything=True)
    except KeyboardInterrupt:
        res.interrupted = True
    finally:
        con.close()
    res.records = [out.written[k] for k in sorted(out.written)]
    res.skipped = [paths[k] for k in sorted(out.skipped)]
    return res


def _on_dask(items: list[tuple[int, str]], options: InputOptions, known: frozenset[str],
             force: bool, workers: int, scheduler: str,
             add: Callable[[int, FileRecord | None], None], res: BatchResult) -> None:
    """Run the batch's chunks on Dask, passing each input's outcome to ``add`` as its
    chunk completes; sets the workers, the cluster's time and the workers' memory in
    ``res``."""
    from distributed import as_completed

    t0 = time.perf_counter()
    cpu0 = thread_cpu()
    client, cluster = start_client(workers, scheduler)
    res.cluster_seconds = time.perf_counter() - t0
    acc = res.accounting
    acc.ready = time.time()
    try:
        n_workers = res.workers = len(client.scheduler_info().get("workers", {}))
        # the hashes of the inputs done are sent once to every worker, not with each task
        known_arg: Any = client.scatter([known], broadcast=True)[0] if known else known
        futs = {client.submit(timed_chunk, chunk, options, known_arg, force, pure=False):
                chunk for chunk in chunks(items, n_workers or workers)}
        running = as_completed(futs)
        for fut in running:
            try:
                done, stamp = fut.result()
                acc.tasks.append(stamp)
            except Exception as exc:  # the task failed (its worker died)
                if len(futs[fut]) > 1:  # each input again alone: only the culprit fails
                    for one in futs[fut]:
                        again = client.submit(timed_chunk, [one], options, known_arg, force,
                                              pure=False)
                        futs[again] = [one]
                        running.add(again)
                    continue
                ohash = options_hash(options)
                done = [(k, FileRecord(
                    path=path, content_hash=f"failed:{k}", settings_hash=ohash, part_id="",
                    status="error", reason=f"worker failed: {type(exc).__name__}: {exc}"))
                    for k, path in futs[fut]]
            for k, rec in done:
                add(k, rec)
        acc.done = time.time()
        snaps = client.run(worker_snapshot)
        res.worker_peak_rss = {a: s["peak_rss_mib"] for a, s in snaps.items()}
        acc.workers = {s["pid"]: s["threads"] for s in snaps.values()}
        acc.client = cpu_delta(cpu0, thread_cpu())
    finally:
        t1 = time.perf_counter()
        client.close()
        if cluster is not None:
            cluster.close()
        res.cluster_seconds += time.perf_counter() - t1


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
              and u.get("status") in ESTIMATE_STATUSES]
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
                    "verdict": verdict, "verdict_reason": why,
                    "by_direction": by_direction(us)})
    return out


def by_direction(unloads: Sequence[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """A part's C per flow direction ('discharge', 'charge'; rows of older databases
    without one are discharges): the n, the inverse-variance weighted mean of the
    recommended C and its standard uncertainty [m^3/(s Pa)] of the unloads with a C and a
    finite, positive uncertainty."""
    out: dict[str, dict[str, float]] = {}
    for d in ("discharge", "charge"):
        cs = [(u["recommended_conductance"], u["recommended_std"]) for u in unloads
              if (u.get("direction") or "discharge") == d
              and u.get("status") in ESTIMATE_STATUSES
              and u.get("recommended_conductance") is not None
              and u.get("recommended_std") is not None
              and math.isfinite(u["recommended_conductance"])
              and math.isfinite(u["recommended_std"]) and u["recommended_std"] > 0]
        if cs:
            w = [1.0 / s**2 for _c, s in cs]
            out[d] = {"n": len(cs), "conductance": sum(c * x for (c, _s), x in zip(
                cs, w, strict=True)) / sum(w), "std": math.sqrt(1.0 / sum(w))}
    return out


def progress_bar(total: int, enabled: bool | None = None) -> Any:
    """A tqdm bar on stderr (rate and ETA) for ``total`` inputs; ``enabled`` None: only
    when stderr is a terminal."""
    from tqdm import tqdm

    if enabled is None:
        enabled = sys.stderr.isatty()
    return tqdm(total=total, unit="file", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True)
