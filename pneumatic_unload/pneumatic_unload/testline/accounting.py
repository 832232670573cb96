# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""CPU-time accounting of a batch: where the CPU seconds and the idle time of a batch go.

A wall-clock speed-up measured on a shared machine says little; CPU seconds do not depend
on the load. A batch records (in :class:`Accounting`):

* per task (:func:`timed_chunk`, the job a worker runs): its wall start and end, the CPU
  time of its thread spent in the inputs' analysis, and the process's CPU time when the
  task starts (on a worker's first task: what starting the worker and importing the
  package cost);
* per process at the end of the batch (:func:`thread_cpu`): its CPU time by thread name
  (a Dask worker's event loop, its task thread, its profiler...; this process's main
  thread, the local cluster's event loop with the scheduler and the nannies...);
* the serial run: the same per-task figures in this process.

Times [s]: CPU seconds (user + system) and wall stamps of ``time.time()`` (one clock for
every process of the machine). A process's and its threads' CPU times come in clock ticks
(10 ms on Linux); a task's (``time.thread_time``) to the nanosecond: a difference of the
two may be off by a few ticks.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from pneumatic_unload.testline.db import FileRecord
from pneumatic_unload.testline.job import InputOptions, analyze_chunk


@dataclass(frozen=True)
class TaskStamp:
    """One task of a batch, timed where it ran.

    Attributes
    ----------
    pid : int
        Process that ran it.
    start, end : float
        Wall stamps around the task's inputs (``time.time()``) [s].
    cpu : float
        CPU time of the task's thread in the inputs' analysis (hash, read, fit, judge) [s].
    process_cpu : float
        CPU time of the whole process when the task started [s].
    n : int
        Inputs of the task.
    """

    pid: int
    start: float
    end: float
    cpu: float
    process_cpu: float
    n: int


def timed_chunk(items: Sequence[tuple[int, str]], options: InputOptions,
                known: frozenset[str] = frozenset(), force: bool = False
                ) -> tuple[list[tuple[int, FileRecord | None]], TaskStamp]:
    """:func:`~.job.analyze_chunk` and its :class:`TaskStamp` (the same records)."""
    p0, t0, c0 = time.process_time(), time.time(), time.thread_time()
    done = analyze_chunk(items, options, known, force)
    stamp = TaskStamp(os.getpid(), t0, time.time(), time.thread_time() - c0, p0, len(items))
    return done, stamp


def thread_cpu() -> dict[str, float]:
    """CPU time of this process [s]: 'process' (all of it, since it started), each live
    thread's by its name (threads of one name summed), and 'ended threads' (the threads
    that ended, and any thread Python does not know)."""
    import psutil  # a dependency of distributed

    names = {t.native_id: t.name for t in threading.enumerate()}
    proc = psutil.Process()
    total = sum(proc.cpu_times()[:2])
    out: dict[str, float] = {"process": total}
    live = 0.0
    for th in proc.threads():
        cpu = th.user_time + th.system_time
        live += cpu
        name = names.get(th.id, "other (not Python)")
        name = name.split("-")[0] if name.startswith("Dask-") else name
        out[name] = out.get(name, 0.0) + cpu
    out["ended threads"] = max(0.0, total - live)
    return out


def worker_snapshot() -> dict[str, Any]:
    """What a worker reports at the end of a batch: its pid, :func:`thread_cpu` [s] and
    its peak resident memory [MiB]."""
    import resource

    return {"pid": os.getpid(), "threads": thread_cpu(),
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


@dataclass
class Accounting:
    """Where a batch's time went (see the module doc).

    Attributes
    ----------
    tasks : list of TaskStamp
        Every task, in the order completed.
    workers : dict
        Per worker process (pid): :func:`thread_cpu` at the end of the batch [s].
    client : dict
        This process: :func:`thread_cpu` at the end of the batch minus at its start [s]
        (threads started during the batch count from 0).
    ready, done : float
        Wall stamps: the workers are ready (cluster started), the last result is in [s].
    """

    tasks: list[TaskStamp] = field(default_factory=list)
    workers: dict[int, dict[str, float]] = field(default_factory=dict)
    client: dict[str, float] = field(default_factory=dict)
    ready: float = 0.0
    done: float = 0.0

    def analysis_cpu(self) -> float:
        """CPU time of the inputs' analysis, all tasks [s]."""
        return sum(t.cpu for t in self.tasks)

    def idle(self) -> dict[int, dict[str, float]]:
        """Per process that ran tasks [s]: 'before' (ready to first task), 'between'
        (gaps between its tasks), 'after' (its last task to the batch's last result),
        'busy' (in tasks) and 'start_cpu' (its CPU time before its first task)."""
        out: dict[int, dict[str, float]] = {}
        for pid in dict.fromkeys(t.pid for t in self.tasks):
            ts = sorted((t for t in self.tasks if t.pid == pid), key=lambda t: t.start)
            busy = sum(t.end - t.start for t in ts)
            between = sum(max(0.0, b.start - a.end) for a, b in itertools.pairwise(ts))
            out[pid] = {"before": max(0.0, ts[0].start - self.ready), "between": between,
                        "after": max(0.0, self.done - ts[-1].end), "busy": busy,
                        "start_cpu": ts[0].process_cpu}
        return out


    def components(self) -> dict[str, float]:
        """The batch's CPU time by component [s] (see the module doc): the analysis; the
        workers' start (spawn, imports: their CPU before their first task) and the rest of
        their time (event loop, comms, (de)serialisation, monitors); this process's main
        thread (writing the database, waiting; minus the analysis when it ran here), its
        Dask event loop (the local cluster's scheduler and nannies, the client's comms) and
        its other threads; 'total': all of it."""
        analysis = self.analysis_cpu()
        here = os.getpid()
        starts = {pid: i["start_cpu"] for pid, i in self.idle().items() if pid != here}
        worker_rest = sum(th["process"] for th in self.workers.values()) - analysis \
            if self.workers else 0.0
        main = self.client.get("MainThread", 0.0) - (0.0 if self.workers else analysis)
        loop = self.client.get("IO loop", 0.0)
        out = {"analysis": analysis,
               "worker start": sum(starts.values()),
               "worker rest": worker_rest - sum(starts.values()),
               "client main thread": main,
               "client event loop": loop,
               "client other threads": self.client.get("process", 0.0) - main - loop
               - (0.0 if self.workers else analysis)}
        out["total"] = sum(out.values())
        return out


def cpu_delta(before: dict[str, float], after: dict[str, float]) -> dict[str, float]:
    """``after`` minus ``before``, key by key (a key missing before counts from 0) [s]."""
    return {k: v - before.get(k, 0.0) for k, v in after.items()}
