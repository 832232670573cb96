"""A minimal process launcher for the nodes (what a ROS 2 launch file does, without ROS).

There is no ``ros2 launch`` on a PyPI-only machine, so ``make demo``, the benchmarks and the
tests start each node as its own process: ``python -m pneumatic_unload.nodes.<name>
--ros-args -p name:=value ...``. This module never imports rclpy; it only runs processes.
Each process writes its output to a log file (a pipe could fill up and block the node).
"""

from __future__ import annotations

import functools
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

#: Domain ids tried by :func:`free_domain_id` (0 is everybody's default).
DOMAIN_RANGE = (1, 101)


def _domain_looks_free(domain_id: int) -> bool:
    """True when no DDS participant on this host holds the domain's discovery ports."""
    base = 7400 + 250 * domain_id
    for port in (base, base + 10):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("", port))  # no SO_REUSEADDR: fails while a participant holds it
            except OSError:
                return False
    return True


def free_domain_id() -> int:
    """A ROS_DOMAIN_ID that no other DDS participant on this host uses (best effort)."""
    lo, hi = DOMAIN_RANGE
    span = hi - lo + 1
    start = (os.getpid() + random.SystemRandom().randrange(span)) % span
    candidates = [lo + (start + k) % span for k in range(span)]
    return next((d for d in candidates if _domain_looks_free(d)), candidates[0])


def ros_args(params: dict[str, Any]) -> list[str]:
    """``-p name:=value`` arguments (bools as true/false, lists as YAML lists)."""
    out: list[str] = []
    for k, v in params.items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, (list, tuple)):
            v = "[" + ",".join(repr(x) for x in v) + "]"
        out += ["-p", f"{k}:={v}"]
    return out


@functools.cache
def _env_resets_signals() -> bool:
    """The system's ``env`` has ``--default-signal`` (coreutils 8.31 and later)."""
    if shutil.which("env") is None:
        return False
    try:
        return subprocess.run(["env", "--default-signal=INT,TERM", "true"],
                              capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


class NodeProcess:
    """A node of this package in its own process, its output in a log file.

    Parameters
    ----------
    name : str
        Node module: simulator, estimator, recorder or replay.
    params : dict
        ROS parameters.
    log_dir : Path
        Folder of the log file.
    extra : list of str
        More ``--ros-args`` arguments (e.g. ``--params-file FILE``).
    env : dict
        Environment (default: this process's).
    """

    def __init__(self, name: str, params: dict[str, Any] | None = None,
                 log_dir: Path | None = None, extra: list[str] | None = None,
                 env: dict[str, str] | None = None) -> None:
        args = [sys.executable, "-m", f"pneumatic_unload.nodes.{name}", "--ros-args",
                *ros_args(params or {}), *(extra or [])]
        if _env_resets_signals():
            # SIGINT and SIGTERM at their defaults in the node (a launcher run as a shell's
            # background job has SIGINT ignored, which a child inherits: a stop in the
            # node's first ~50 ms, before its own handler, would be lost)
            args = ["env", "--default-signal=INT,TERM", *args]
        self.name = name
        log_dir = log_dir or Path("/tmp")
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / f"{name}-{os.getpid()}-{time.time_ns()}.log"
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                     env=env if env is not None else os.environ.copy())
        self.returncode: int | None = None

    def output(self) -> str:
        """Everything the node printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait_output(self, pattern: str, timeout: float) -> re.Match[str]:
        """Wait until the output matches ``pattern`` (regex); AssertionError after timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = re.search(pattern, self.output())
            if m:
                return m
            if self.proc.poll() is not None:
                m = re.search(pattern, self.output())
                if m:
                    return m
                break
            time.sleep(0.05)
        raise AssertionError(f"{self.name}: no {pattern!r} within {timeout} s; output:\n"
                             f"{self.output()[-3000:]}")

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """Send ``sig`` and wait for the exit code (AssertionError and kill after timeout)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                raise AssertionError(f"{self.name} did not stop on {sig!r}:\n"
                                     f"{self.output()[-3000:]}") from None
        self.returncode = self.proc.returncode
        if not self._log.closed:
            self._log.close()
        return self.returncode
