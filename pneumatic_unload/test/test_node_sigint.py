# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Every node stops on SIGINT at any moment of its start (issue "Two commands on any machine":
the simulator given SIGINT within about 0.5 s of its start never exited).

Each node runs as its own process (``python -m pneumatic_unload.nodes.<node> --ros-args ...``,
on its own ROS_DOMAIN_ID) and is sent SIGINT at several instants after the process start, which
under load mostly fall in the imports (one run compiles the model's C kernel on first use, in
an empty kernel folder), and at moments of its start seen from outside: once ``rclpy.init``
has made the DDS participant (the node being built: the estimator's warm-up) and once the node
has printed its start line (its first spins). Every run must end within :data:`STOP_TIMEOUT`
with exit status 0, 130 or -2; once the package's code runs (its imports under way: see
:func:`_imports_under_way`) without a traceback; a recorder leaves no bag or a complete one
(``metadata.yaml`` written).

The instants are run twice: with SIGINT at its default, and with SIGINT inherited *ignored*,
as every background job of a shell script (``node &``) has it; that is the case that hung
(Python keeps an ignored SIGINT ignored, the signal was lost until ``rclpy.init`` took it
over). A signal that comes before the interpreter reaches the package's code cannot be seen
by it when SIGINT is ignored, so those runs wait for the imports to be under way.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pneumatic_unload.app.launch import free_domain_id, ros_args

NODES = ("simulator", "estimator", "recorder", "replay", "opcua")
#: The start line of each node (printed when it is built; the replay prints none).
READY = {"simulator": "rig at ", "estimator": "estimating on ", "recorder": "recording to ",
         "opcua": "OPC UA server on "}
#: Instants of the SIGINT after the process start [s], SIGINT at its default.
INSTANTS = (0.05, 0.3, 1.0, 1.5)
#: Instants of the SIGINT after the process start [s], SIGINT inherited ignored; the one of
#: :data:`FRESH_AT` in an empty kernel folder (the model is compiled on first use).
INSTANTS_IGNORED = (0.3, 0.6, 1.2)
FRESH_AT = 0.6
#: Longest time from the SIGINT to the exit [s] (then the node is killed: a failure).
STOP_TIMEOUT = 15.0
#: After this time from the process start a SIGINT waiting for a moment of the start goes
#: anyway (that moment was not seen: another RMW than Fast DDS, a very slow machine) [s].
LATE = 8.0
#: Processes of one node run at a time [-].
PARALLEL = 4
#: Exit statuses of a node stopped by SIGINT: done, 128 + SIGINT, killed by SIGINT.
STOPPED = (0, 128 + signal.SIGINT, -signal.SIGINT)


@dataclass
class Run:
    """One process of a node, interrupted ``at`` [s] after its start."""

    node: str
    at: float  #: instant of the SIGINT after the process start [s]
    ignored: bool  #: SIGINT inherited ignored
    when: str  #: and not before: '' (no condition), 'init' (rclpy.init ran), 'ready'
    fresh: bool  #: the model's C kernel compiled (empty kernel folder)
    params: dict[str, Any]
    log: Path
    proc: subprocess.Popen[bytes] | None = None
    t0: float = 0.0  #: process start [s, monotonic]
    sent: float | None = None  #: the SIGINT [s, monotonic]
    under_way: bool = False  #: the imports were under way at the SIGINT
    returncode: int | None = None
    stop_time: float = float("nan")  #: from the SIGINT to the exit [s]
    failure: str = ""

    def label(self) -> str:
        """What the run was, for the failure messages."""
        when = {"": f"at {self.at:g} s", "init": "once rclpy.init ran",
                "ready": "once started"}[self.when]
        return (f"{self.node} SIGINT {when}{' (inherited ignored)' if self.ignored else ''}"
                f"{' (kernel compiled)' if self.fresh else ''}")

    def output(self) -> str:
        """Everything the node printed."""
        return self.log.read_text(errors="replace") if self.log.exists() else ""


def _imports_under_way(pid: int) -> bool:
    """True once the process has loaded numpy (every node's imports load it soon after the
    package's ``__init__``, which holds SIGINT, ran): the package's code runs; before, the
    interpreter itself starts."""
    try:
        return "numpy" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _ros_initialised(pid: int) -> bool:
    """True once the process has a DDS participant (the threads ``dds.*`` of Fast DDS, the
    RMW of the tests: conftest.py): ``rclpy.init`` ran, the node is being built or runs."""
    for comm in Path(f"/proc/{pid}/task").glob("*/comm"):
        try:
            if comm.read_text().startswith("dds."):
                return True
        except OSError:
            continue
    return False


def _due(run: Run, now: float) -> bool:
    """True when the SIGINT of ``run`` is due."""
    assert run.proc is not None
    if now < run.t0 + run.at:
        return False
    if now > run.t0 + LATE:
        return True
    if run.when == "init":
        return _ros_initialised(run.proc.pid)
    if run.when == "ready":
        return READY[run.node] in run.output()
    # an ignored SIGINT cannot reach the interpreter's own start (see the module docstring)
    return not run.ignored or _imports_under_way(run.proc.pid)


def _domains(n: int) -> list[int]:
    """``n`` distinct ROS domain ids that no participant on this host uses, none the test
    run's own (best effort: :func:`pneumatic_unload.app.launch.free_domain_id`)."""
    used = {int(os.environ.get("ROS_DOMAIN_ID", "0"))}
    out: list[int] = []
    for _ in range(50 * n):
        if len(out) == n:
            break
        d = free_domain_id()
        if d not in used:
            used.add(d)
            out.append(d)
    return out + [out[-1]] * (n - len(out))


def _start(run: Run, domain: int, tmp_path: Path) -> None:
    """Start the node of ``run`` (SIGINT ignored through a shell's ``trap '' INT``, which
    ``exec`` keeps)."""
    cmd = [sys.executable, "-m", f"pneumatic_unload.nodes.{run.node}", "--ros-args",
           *ros_args(run.params)]
    if run.ignored:
        cmd = ["/bin/sh", "-c", "trap '' INT; exec \"$0\" \"$@\"", *cmd]
    else:
        # the normal setup whatever this test runs under (a shell's background job, as a
        # CI harness may be, hands its children SIGINT ignored, and a SIGINT before the
        # node's own handler would then be lost): SIGINT and SIGTERM at their defaults
        cmd = ["env", "--default-signal=INT,TERM", *cmd]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    if run.fresh:
        kernel_dir = tmp_path / f"kernel-{run.log.stem}"
        kernel_dir.mkdir()
        env["PNEUMATIC_UNLOAD_KERNEL_DIR"] = str(kernel_dir)
    with open(run.log, "wb") as log:
        run.t0 = time.monotonic()
        run.proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)


def _step(run: Run, now: float) -> bool:
    """Advance ``run`` (send its SIGINT when due, see it exit, kill it after the timeout);
    True when it is over."""
    proc = run.proc
    assert proc is not None
    if run.sent is None:
        if proc.poll() is not None:
            run.failure = f"exited with {proc.returncode} before the SIGINT"
            return True
        if not _due(run, now):
            return False
        run.under_way = _imports_under_way(proc.pid)
        proc.send_signal(signal.SIGINT)
        run.sent = now
        return False
    if proc.poll() is not None:
        run.returncode = proc.returncode
        run.stop_time = now - run.sent
        return True
    if now - run.sent > STOP_TIMEOUT:
        proc.kill()
        proc.wait()
        run.failure = f"did not stop within {STOP_TIMEOUT:g} s of the SIGINT"
        return True
    return False


def _run_all(runs: list[Run], tmp_path: Path) -> None:
    """Run every process, at most :data:`PARALLEL` at a time; none is left running."""
    domains = _domains(len(runs))
    waiting = list(zip(runs, domains, strict=True))
    active: list[Run] = []
    try:
        while waiting or active:
            while waiting and len(active) < PARALLEL:
                run, domain = waiting.pop(0)
                _start(run, domain, tmp_path)
                active.append(run)
            now = time.monotonic()
            active = [r for r in active if not _step(r, now)]
            time.sleep(0.002)
    finally:
        for r in runs:
            if r.proc is not None and r.proc.poll() is None:
                r.proc.kill()
                r.proc.wait()


def _bag(path: Path) -> Path:
    """A 1 s record of 1 kHz pressures (Pa) for the replay."""
    from pneumatic_unload.io.bag import BagRecorder

    t_ns = 1_700_000_000_000_000_000 + np.arange(1000, dtype=np.int64) * 1_000_000
    with BagRecorder(path) as rec:
        rec.write_pressures(t_ns, np.full(1000, 6e5))
    return path


def _params(node: str, tmp_path: Path, k: int) -> dict[str, Any]:
    """Minimal valid parameters of ``node``'s k-th run."""
    if node == "simulator":
        return {"volume": 1e-3, "conductance": 8e-9}
    if node == "estimator":
        return {"volume": 1e-3}
    if node == "recorder":
        return {"output": str(tmp_path / f"rec-{k}")}
    if node == "opcua":  # a port of the system's choice: the runs overlap
        return {"endpoint": "opc.tcp://127.0.0.1:0/pneumatic_unload/"}
    bag = tmp_path / "replayed"  # looped: a replay that ignored the SIGINT would not end
    return {"bag": str(bag if bag.exists() else _bag(bag)), "rate": 1.0, "loop": True}


def _problems(run: Run) -> list[str]:
    """What is wrong with a finished run (nothing: [])."""
    if run.failure:
        return [run.failure]
    out = run.output()
    problems = []
    code = run.returncode
    # a SIGINT during the interpreter's own start (the site import, or runpy's before
    # ``-m`` runs the node's module: "Could not import runpy module") ends it with status
    # 1, before any of the node's code exists to handle it
    if code not in STOPPED and not (code == 1 and not run.under_way and (
            "init_import_site" in out or "Could not import runpy module" in out)):
        problems.append(f"exit status {code}")
    if run.under_way and "Traceback" in out:
        problems.append("a traceback")
    bag = Path(run.params.get("output", "/nonexistent"))
    if run.node == "recorder" and bag.exists():
        from pneumatic_unload.io.bag import bag_summary

        if not (bag / "metadata.yaml").exists():
            problems.append(f"an incomplete bag {bag} (no metadata.yaml)")
        else:
            bag_summary(bag)  # readable
    return problems


rclpy = pytest.importorskip("rclpy")
#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = [pytest.mark.serial,
              pytest.mark.skipif(not Path("/proc/self/task").is_dir(),
                                 reason="the moments of a start are read from /proc")]


@pytest.mark.parametrize("node", NODES)
def test_node_stops_on_sigint_during_its_start(node: str, tmp_path: Path) -> None:
    """SIGINT at each instant of :data:`INSTANTS` (SIGINT at its default) and of
    :data:`INSTANTS_IGNORED` (inherited ignored) after the start, once rclpy.init ran (both
    ways) and once the node printed its start line: the node exits within
    :data:`STOP_TIMEOUT` [s], cleanly."""
    plan = [(at, False, "") for at in INSTANTS] + [(at, True, "") for at in INSTANTS_IGNORED]
    plan += [(0.0, False, "init"), (0.0, True, "init")]
    plan += [(0.0, False, "ready")] if node in READY else []
    runs = [Run(node, at, ignored, when, fresh=ignored and at == FRESH_AT,
                params=_params(node, tmp_path, k), log=tmp_path / f"{node}-{k}.log")
            for k, (at, ignored, when) in enumerate(plan)]
    _run_all(runs, tmp_path)
    bad = {r.label(): (p, r.output()[-1500:]) for r in runs if (p := _problems(r))}
    assert not bad, "\n\n".join(f"{label}: {', '.join(p)}; output:\n{out}"
                                for label, (p, out) in bad.items())


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-v"]))
